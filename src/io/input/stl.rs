//! STL reader (binary and ASCII). STL repeats each vertex in every triangle; identical vertices
//! are merged here so the surface is an indexed mesh the rest of the pipeline can walk.
//!
//! Our own parser rather than stl_io: it decides binary vs ASCII by the file size (binary files
//! often begin with "solid" too), names the line of a malformed ASCII record and never panics.

use nalgebra::Point3;
use std::collections::HashMap;

/// Triangles with the vertices they index, straight from the file (units untouched).
#[derive(Debug, Default)]
pub(crate) struct StlMesh {
    pub vertices: Vec<Point3<f64>>,
    pub triangles: Vec<[usize; 3]>,
    /// Vertex records that were merged into an earlier identical one.
    pub merged: usize,
}

const BINARY_HEADER: usize = 84;
const BINARY_RECORD: usize = 50;

/// Parses an STL file, binary or ASCII.
pub(crate) fn parse(bytes: &[u8]) -> Result<StlMesh, String> {
    if let Some(n) = binary_triangle_count(bytes) {
        if BINARY_HEADER as u64 + BINARY_RECORD as u64 * n as u64 == bytes.len() as u64 {
            return parse_binary(&bytes[BINARY_HEADER..], n);
        }
    }
    // A byte-order mark (some editors write one) is not part of the text.
    let text = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let text_start = text.iter().position(|b| !b.is_ascii_whitespace()).unwrap_or(text.len());
    if text[text_start..].starts_with(b"solid") {
        // A binary file whose header begins with "solid" is not text; if it is, it is ASCII.
        if let Ok(text) = std::str::from_utf8(text) {
            return parse_ascii(text);
        }
    }
    match binary_triangle_count(bytes) {
        Some(n) => {
            let needed = BINARY_HEADER as u64 + BINARY_RECORD as u64 * n as u64;
            let verdict = if (bytes.len() as u64) < needed {
                "the file is truncated; re-export it"
            } else {
                "the file has trailing bytes or a corrupt header; re-export it"
            };
            Err(format!(
                "file is {} bytes but its header announces {n} triangles, which needs {needed} bytes: {verdict}",
                bytes.len()
            ))
        }
        None => Err(format!(
            "is {} bytes: too short for a binary STL (84-byte header) and not an ASCII STL (text starting with 'solid')",
            bytes.len()
        )),
    }
}

fn binary_triangle_count(bytes: &[u8]) -> Option<u32> {
    let count = bytes.get(80..84)?;
    Some(u32::from_le_bytes([count[0], count[1], count[2], count[3]]))
}

fn parse_binary(records: &[u8], n: u32) -> Result<StlMesh, String> {
    let mut merger = Merger::default();
    for (t, record) in records.chunks_exact(BINARY_RECORD).enumerate() {
        let mut corners = [0usize; 3];
        for (k, corner) in corners.iter_mut().enumerate() {
            // Each record: normal (12 bytes), three vertices (12 bytes each), attribute (2 bytes).
            let at = 12 + 12 * k;
            let f = |i: usize| {
                let b = &record[at + 4 * i..at + 4 * i + 4];
                f32::from_le_bytes([b[0], b[1], b[2], b[3]])
            };
            let xyz = [f(0), f(1), f(2)];
            if !xyz.iter().all(|c| c.is_finite()) {
                return Err(format!(
                    "triangle {t} (of {n}), vertex {}: non-finite coordinate {xyz:?}; repair or re-export the file",
                    k + 1
                ));
            }
            *corner = merger.index(xyz);
        }
        merger.mesh.triangles.push(corners);
    }
    Ok(merger.finish())
}

fn parse_ascii(text: &str) -> Result<StlMesh, String> {
    let mut merger = Merger::default();
    let mut loop_vertices: Vec<usize> = Vec::with_capacity(3);
    for (i, line) in text.lines().enumerate() {
        let lineno = i + 1;
        let mut words = line.split_ascii_whitespace();
        let Some(keyword) = words.next() else { continue };
        match keyword {
            "vertex" => {
                let xyz = vertex_coords(words).map_err(|e| format!("line {lineno}: {e}: '{}'", line.trim()))?;
                if loop_vertices.len() == 3 {
                    return Err(format!("line {lineno}: a facet has more than 3 vertices; triangulate the surface"));
                }
                loop_vertices.push(merger.index(xyz));
            }
            "endloop" => {
                if loop_vertices.len() != 3 {
                    return Err(format!("line {lineno}: a facet has {} vertices instead of 3", loop_vertices.len()));
                }
                merger.mesh.triangles.push([loop_vertices[0], loop_vertices[1], loop_vertices[2]]);
                loop_vertices.clear();
            }
            "solid" | "endsolid" | "facet" | "outer" | "endfacet" => {}
            other => {
                return Err(format!(
                    "line {lineno}: unexpected word '{other}' (malformed ASCII STL): '{}'",
                    line.trim()
                ))
            }
        }
    }
    if !loop_vertices.is_empty() {
        return Err("ends inside a facet: the file is truncated; re-export it".into());
    }
    Ok(merger.finish())
}

fn vertex_coords<'a>(mut words: impl Iterator<Item = &'a str>) -> Result<[f32; 3], String> {
    let mut xyz = [0f32; 3];
    for c in &mut xyz {
        let w = words.next().ok_or("a vertex needs 3 coordinates")?;
        *c = w.parse().map_err(|_| format!("'{w}' is not a number"))?;
        if !c.is_finite() {
            return Err(format!("non-finite coordinate '{w}'"));
        }
    }
    if words.next().is_some() {
        return Err("a vertex has more than 3 coordinates".into());
    }
    Ok(xyz)
}

/// Merges vertices with exactly equal coordinates (the f32 values as stored; `-0.0` equals `0.0`).
#[derive(Default)]
struct Merger {
    index_of: HashMap<[u32; 3], usize>,
    mesh: StlMesh,
}

impl Merger {
    fn index(&mut self, xyz: [f32; 3]) -> usize {
        // Adding 0.0 turns -0.0 into +0.0 and leaves every other value unchanged.
        let key = xyz.map(|c| (c + 0.0).to_bits());
        let next = self.mesh.vertices.len();
        let id = *self.index_of.entry(key).or_insert(next);
        if id == next {
            self.mesh.vertices.push(Point3::new(xyz[0] as f64, xyz[1] as f64, xyz[2] as f64));
        } else {
            self.mesh.merged += 1;
        }
        id
    }

    fn finish(self) -> StlMesh {
        self.mesh
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn binary(header: &[u8; 80], tris: &[[[f32; 3]; 3]]) -> Vec<u8> {
        let mut out = header.to_vec();
        out.extend((tris.len() as u32).to_le_bytes());
        for t in tris {
            out.extend([0u8; 12]);
            for v in t {
                out.extend(v.iter().flat_map(|c| c.to_le_bytes()));
            }
            out.extend([0u8; 2]);
        }
        out
    }

    const QUAD: [[[f32; 3]; 3]; 2] =
        [[[0., 0., 0.], [1., 0., 0.], [1., 1., 0.]], [[0., 0., 0.], [1., 1., 0.], [-0., 1., 0.]]];

    #[test]
    fn binary_starting_with_solid_is_binary() {
        let mut header = [b' '; 80];
        header[..5].copy_from_slice(b"solid");
        let m = parse(&binary(&header, &QUAD)).unwrap();
        assert_eq!(m.vertices.len(), 4);
        assert_eq!(m.merged, 2);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn truncated_binary() {
        let bytes = binary(&[0; 80], &QUAD);
        let e = parse(&bytes[..bytes.len() - 7]).unwrap_err();
        assert!(e.contains("announces 2 triangles, which needs 184 bytes") && e.contains("truncated"), "{e}");
    }

    #[test]
    fn ascii_and_its_errors() {
        let good = "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid x\n";
        let m = parse(good.as_bytes()).unwrap();
        assert_eq!((m.vertices.len(), m.triangles.len()), (3, 1));
        let e = parse(good.replace("vertex 1 0 0", "vertex 1 0").as_bytes()).unwrap_err();
        assert!(e.starts_with("line 5:"), "{e}");
        let e = parse(good.replace("vertex 1 0 0", "vertex 1 nan 0").as_bytes()).unwrap_err();
        assert!(e.starts_with("line 5:") && e.contains("non-finite"), "{e}");
        let e = parse(good.replace("endloop", "").as_bytes()).unwrap_err();
        assert!(e.contains("truncated") || e.contains("more than 3"), "{e}");
    }
}
