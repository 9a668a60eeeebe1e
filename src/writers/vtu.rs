//! VTK XML unstructured grid (`mesh.vtu`) of lumen and wall for ParaView.
//!
//! Cell data: `region` (0 lumen, 1 intima, 2 media, 3 adventitia), `branch` (the element's branch
//! index, 0 for an unbranched vessel; names in `report.json`), `scaled_jacobian`,
//! `equiangle_skew`, `e_long`, `e_circ`, `e_rad`, `fibre1`, `fibre2` (zero for lumen cells).
//! Points are Float64 in the output length unit; the mesh's canonical hex order is VTK's.
//! Connectivity and offsets are Int64, as VTK itself writes them (meshio reads UInt64
//! connectivity as floating point).
//!
//! The arrays are stored as appended raw binary data (`<AppendedData encoding="raw">`, a UInt64
//! byte count before each array), written straight from the mesh in blocks: no copy of an array
//! and no base64 text is ever held in memory, and the file is a third smaller than base64.

use super::text::write_binary;
use super::{write_atomic, WriteOptions};
use crate::data::error::{Error, Result};
use crate::geometry::mesh::VesselMesh;
use nalgebra::Vector3;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// VTK_HEXAHEDRON.
const VTK_HEXAHEDRON: u8 = 12;

/// Appends the little-endian bytes of a range of tuples to a buffer.
type Encode<'a> = Box<dyn Fn(std::ops::Range<usize>, &mut Vec<u8>) + 'a>;

/// One array of the appended data: its XML attributes and how to write its values.
struct Array<'a> {
    vtk_type: &'static str,
    name: &'static str,
    components: usize,
    /// Number of tuples.
    len: usize,
    /// Bytes per component.
    width: usize,
    encode: Encode<'a>,
}

impl Array<'_> {
    fn bytes(&self) -> u64 {
        (self.len * self.components * self.width) as u64
    }
    fn tag(&self, offset: u64) -> String {
        let components =
            if self.components > 1 { format!(" NumberOfComponents=\"{}\"", self.components) } else { String::new() };
        format!(
            "<DataArray type=\"{}\" Name=\"{}\"{components} format=\"appended\" offset=\"{offset}\"/>",
            self.vtk_type, self.name
        )
    }
}

fn f64_array<'a>(name: &'static str, len: usize, value: impl Fn(usize) -> f64 + 'a) -> Array<'a> {
    Array {
        vtk_type: "Float64",
        name,
        components: 1,
        len,
        width: 8,
        encode: Box::new(move |r, out| r.for_each(|i| out.extend_from_slice(&value(i).to_le_bytes()))),
    }
}

fn i32_array<'a>(name: &'static str, len: usize, value: impl Fn(usize) -> i32 + 'a) -> Array<'a> {
    Array {
        vtk_type: "Int32",
        name,
        components: 1,
        len,
        width: 4,
        encode: Box::new(move |r, out| r.for_each(|i| out.extend_from_slice(&value(i).to_le_bytes()))),
    }
}

fn vector_array<'a>(name: &'static str, len: usize, value: impl Fn(usize) -> Vector3<f64> + 'a) -> Array<'a> {
    Array {
        vtk_type: "Float64",
        name,
        components: 3,
        len,
        width: 8,
        encode: Box::new(move |r, out| {
            for i in r {
                let v = value(i);
                for x in [v.x, v.y, v.z] {
                    out.extend_from_slice(&x.to_le_bytes());
                }
            }
        }),
    }
}

fn write_grid(w: &mut dyn Write, mesh: &VesselMesh, points: &Array, cells: &[Array], data: &[Array]) -> io::Result<()> {
    let mut offset = 0u64;
    let mut tag = |a: &Array| {
        let t = a.tag(offset);
        offset += 8 + a.bytes();
        t
    };
    writeln!(w, "<?xml version=\"1.0\"?>")?;
    writeln!(
        w,
        "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">"
    )?;
    writeln!(w, "  <UnstructuredGrid>")?;
    writeln!(w, "    <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">", mesh.nodes.len(), mesh.hexes.len())?;
    writeln!(w, "      <Points>\n        {}\n      </Points>", tag(points))?;
    writeln!(w, "      <Cells>")?;
    for a in cells {
        writeln!(w, "        {}", tag(a))?;
    }
    writeln!(w, "      </Cells>")?;
    writeln!(w, "      <CellData Scalars=\"region\" Vectors=\"e_long\">")?;
    for a in data {
        writeln!(w, "        {}", tag(a))?;
    }
    writeln!(w, "      </CellData>\n    </Piece>\n  </UnstructuredGrid>")?;
    // The data starts after the underscore; the newline after the last array closes it.
    write!(w, "  <AppendedData encoding=\"raw\">\n   _")?;
    for a in std::iter::once(points).chain(cells).chain(data) {
        w.write_all(&a.bytes().to_le_bytes())?;
        write_binary(w, a.len, &a.encode)?;
    }
    writeln!(w, "\n  </AppendedData>\n</VTKFile>")
}

pub fn write_vtu(mesh: &VesselMesh, options: &WriteOptions, dir: &Path) -> Result<Vec<PathBuf>> {
    let n = mesh.hexes.len();
    let per_element = [mesh.branch_of.len(), mesh.triads.len(), mesh.fibres.len(), mesh.quality.len()];
    if per_element.iter().any(|&k| k != n) {
        return Err(Error::Geometry(format!(
            "VTU writer: {n} elements but {} branch indices, {} triads, {} fibre pairs and {} quality figures: the \
             mesh is not annotated",
            per_element[0], per_element[1], per_element[2], per_element[3]
        )));
    }
    let scale = options.length_unit.from_mm();
    let points = vector_array("Points", mesh.nodes.len(), |i| mesh.nodes[i].coords * scale);
    let cells = [
        Array {
            vtk_type: "Int64",
            name: "connectivity",
            components: 1,
            len: n * 8,
            width: 8,
            encode: Box::new(|r, out| {
                r.for_each(|i| out.extend_from_slice(&(mesh.hexes[i / 8][i % 8] as i64).to_le_bytes()))
            }),
        },
        Array {
            vtk_type: "Int64",
            name: "offsets",
            components: 1,
            len: n,
            width: 8,
            encode: Box::new(|r, out| r.for_each(|i| out.extend_from_slice(&(8 * (i as i64 + 1)).to_le_bytes()))),
        },
        Array {
            vtk_type: "UInt8",
            name: "types",
            components: 1,
            len: n,
            width: 1,
            encode: Box::new(|r, out| out.extend(r.map(|_| VTK_HEXAHEDRON))),
        },
    ];
    let data = [
        i32_array("region", n, |e| mesh.regions[e].code()),
        i32_array("branch", n, |e| mesh.branch_of[e] as i32),
        // The sac of a saccular aneurysm, 1 (CFD users look at it on its own), else 0.
        i32_array("sac", n, |e| mesh.in_sac(e) as i32),
        f64_array("scaled_jacobian", n, |e| mesh.quality[e].scaled_jacobian),
        f64_array("equiangle_skew", n, |e| mesh.quality[e].equiangle_skew),
        vector_array("e_long", n, |e| mesh.triads[e].e_long),
        vector_array("e_circ", n, |e| mesh.triads[e].e_circ),
        vector_array("e_rad", n, |e| mesh.triads[e].e_rad),
        vector_array("fibre1", n, |e| mesh.fibres[e][0]),
        vector_array("fibre2", n, |e| mesh.fibres[e][1]),
    ];
    let name = PathBuf::from("mesh.vtu");
    write_atomic(&dir.join(&name), |w| write_grid(w, mesh, &points, &cells, &data))?;
    Ok(vec![name])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::config::MeshConfig;

    /// The arrays of a file this module writes, read back by name: (type, little-endian bytes).
    /// (vtkio reads only base64 appended data; VTK and meshio read the file in tests/vtu.rs.)
    fn read_arrays(bytes: &[u8]) -> Vec<(String, String, Vec<u8>)> {
        let marker = b"<AppendedData encoding=\"raw\">";
        let at = bytes.windows(marker.len()).position(|w| w == marker).expect("appended data");
        let data = at + marker.len() + bytes[at + marker.len()..].iter().position(|&b| b == b'_').unwrap() + 1;
        let head = String::from_utf8(bytes[..at].to_vec()).unwrap();
        let attr = |tag: &str, key: &str| -> String {
            let from = tag.find(&format!("{key}=\"")).unwrap() + key.len() + 2;
            tag[from..from + tag[from..].find('"').unwrap()].to_string()
        };
        head.split("<DataArray ")
            .skip(1)
            .map(|tag| {
                let offset: usize = attr(tag, "offset").parse().unwrap();
                let start = data + offset;
                let len = u64::from_le_bytes(bytes[start..start + 8].try_into().unwrap()) as usize;
                (attr(tag, "Name"), attr(tag, "type"), bytes[start + 8..start + 8 + len].to_vec())
            })
            .collect()
    }

    /// Points, Int64 connectivity and offsets, `branch` (each element's branch on a mesh with
    /// three branches), `region` and a vector array read back bit for bit.
    #[test]
    fn arrays_read_back() {
        let mut c = MeshConfig::default();
        c.lumen.core_elements = 2;
        c.lumen.radial_elements = 2;
        c.lumen.axial_spacing_mm = Some(3.0);
        let mesh = crate::testing::multi_outlet_mesh(&c).unwrap();
        let dir = std::env::temp_dir().join(format!("vesselhex-vtu-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        write_vtu(&mesh, &WriteOptions::default(), &dir).unwrap();
        let arrays = read_arrays(&std::fs::read(dir.join("mesh.vtu")).unwrap());
        let array = |name: &str, vtk_type: &str| -> Vec<u8> {
            let (_, t, bytes) = arrays.iter().find(|a| a.0 == name).unwrap_or_else(|| panic!("no array {name}"));
            assert_eq!(t, vtk_type, "{name}");
            bytes.clone()
        };
        let i32s = |name: &str| -> Vec<i32> {
            array(name, "Int32").chunks_exact(4).map(|c| i32::from_le_bytes(c.try_into().unwrap())).collect()
        };
        let i64s = |name: &str| -> Vec<i64> {
            array(name, "Int64").chunks_exact(8).map(|c| i64::from_le_bytes(c.try_into().unwrap())).collect()
        };
        let f64s = |name: &str| -> Vec<f64> {
            array(name, "Float64").chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect()
        };
        let branch = i32s("branch");
        assert_eq!(branch, mesh.branch_of.iter().map(|&b| b as i32).collect::<Vec<_>>());
        assert_eq!(branch.iter().max(), Some(&2));
        assert_eq!(i32s("region"), mesh.regions.iter().map(|r| r.code()).collect::<Vec<_>>());
        let e_rad: Vec<f64> = mesh.triads.iter().flat_map(|t| [t.e_rad.x, t.e_rad.y, t.e_rad.z]).collect();
        assert_eq!(f64s("e_rad"), e_rad);
        assert_eq!(f64s("Points"), mesh.nodes.iter().flat_map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>());
        assert_eq!(i64s("connectivity"), mesh.hexes.iter().flatten().map(|&n| n as i64).collect::<Vec<_>>());
        assert_eq!(i64s("offsets"), (1..=mesh.hexes.len() as i64).map(|i| 8 * i).collect::<Vec<_>>());
        assert_eq!(array("types", "UInt8"), vec![VTK_HEXAHEDRON; mesh.hexes.len()]);
        std::fs::remove_dir_all(&dir).ok();
    }
}
