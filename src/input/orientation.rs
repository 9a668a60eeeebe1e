//! Winding a surface consistently and outward, whatever share of it the file wound the other
//! way, and writing it in one canonical form, so that nothing downstream depends on how the
//! file wound it: a file with its normals into the lumen and the same file with them out of it
//! give the same surface, triangle for triangle, and so the same mesh.
//!
//! 1. Each piece (triangles joined across manifold edges) is wound consistently by walking it
//!    from its first triangle ([`orient`]).
//! 2. A piece that cannot be (it is not orientable: a Moebius band lies in it) is refused by
//!    an edge where its windings clash, unless every such edge touches an open boundary: a strip
//!    twisted between two holes at a ragged rim (a segmentation's scrap) is cut there, the
//!    clash becoming part of the hole, and the vessel's wall is wound as one.
//! 3. Each piece is turned to face out of the region it encloses, closed by a fan on each of
//!    its boundary loops (the sign of that volume; open ends are so handled).
//! 4. The points are numbered in the order the triangles first use them, each triangle's taken
//!    in the order of their coordinates (not of its winding), and each triangle is rotated to
//!    start at its lowest point: the file's winding, which an STL reader's numbering follows,
//!    leaves no trace. (The triangles keep the file's order: the medial axis's sampling thins
//!    the points in their order, and the cohort's surfaces were measured so; sorting them was
//!    tried, and moved five of the eighteen vessels off the bars' side.)

use super::topology::{boundary_loops, orient, signed_volume6, triangle_neighbours, BOUNDARY};
use super::TriangleSurface;
use crate::error::{Error, Result};
use nalgebra::Point3;

/// How the triangles were wound, against the file.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Winding {
    /// Triangles wound against the rest of their piece in the file (flipped).
    pub flipped: usize,
    /// Whether most triangles faced into the enclosed region in the file.
    pub inward: bool,
    /// Edges of twisted strips at a rim, left with their two triangles running them alike.
    pub twisted_edges: usize,
}

/// Winds the surface's triangles consistently and outward, canonically (see the module's doc);
/// refuses a surface that is not orientable away from its boundary.
pub(crate) fn wind_outward(surface: &mut TriangleSurface) -> Result<Winding> {
    let file = surface.triangles.clone();
    let found = orient(&mut surface.triangles);
    let on_boundary = boundary_vertices(&surface.triangles, surface.vertices.len());
    let inner = found.conflicts.iter().find(|e| !on_boundary[e[0] as usize] && !on_boundary[e[1] as usize]);
    if let Some(&[a, b]) = inner {
        return Err(Error::input(&surface.source, not_orientable(&surface.vertices, a, b, found.conflicts.len())));
    }
    let pieces = found.piece.iter().max().map_or(0, |&p| p as usize + 1);
    let outward = outward_pieces(&surface.vertices, &surface.triangles, &found.piece, pieces);
    for (t, p) in surface.triangles.iter_mut().zip(&found.piece) {
        if !outward[*p as usize] {
            t.swap(1, 2);
        }
    }
    // Against the file, per piece: the minority flipped, the majority (if any) faced inward.
    let mut against = vec![(0usize, 0usize); pieces];
    for ((t, f), p) in surface.triangles.iter().zip(&file).zip(&found.piece) {
        let e = &mut against[*p as usize];
        e.0 += usize::from(!same_winding(t, f));
        e.1 += 1;
    }
    let flipped = against.iter().map(|(k, n)| (*k).min(n - k)).sum();
    let inward: usize = against.iter().filter(|(k, n)| 2 * k > *n).map(|(_, n)| n).sum();
    renumber(surface);
    Ok(Winding { flipped, inward: 2 * inward > file.len(), twisted_edges: found.conflicts.len() })
}

/// Whether two triangles on the same vertices run them the same way round.
fn same_winding(a: &[u32; 3], b: &[u32; 3]) -> bool {
    (0..3).any(|r| [b[r], b[(r + 1) % 3], b[(r + 2) % 3]] == *a)
}

/// Numbers the points in the order the triangles first use them, each triangle's points taken
/// by their coordinates (x, then y, then z), not by its winding; points no triangle uses go
/// last, in their order.
fn renumber(surface: &mut TriangleSurface) {
    let v = &surface.vertices;
    let by_coordinates = |a: &u32, b: &u32| {
        let (p, q) = (v[*a as usize], v[*b as usize]);
        p.x.total_cmp(&q.x).then(p.y.total_cmp(&q.y)).then(p.z.total_cmp(&q.z)).then(a.cmp(b))
    };
    let mut index = vec![u32::MAX; v.len()];
    let mut order = Vec::with_capacity(v.len());
    for t in &surface.triangles {
        let mut corners = *t;
        corners.sort_by(by_coordinates);
        for c in corners {
            if index[c as usize] == u32::MAX {
                index[c as usize] = order.len() as u32;
                order.push(c);
            }
        }
    }
    for (i, slot) in index.iter_mut().enumerate() {
        if *slot == u32::MAX {
            *slot = order.len() as u32;
            order.push(i as u32);
        }
    }
    surface.vertices = order.iter().map(|&i| v[i as usize]).collect();
    surface.triangles.iter_mut().for_each(|t| {
        *t = t.map(|c| index[c as usize]);
        canonical(t);
    });
}

/// The triangle rotated (not reflected) to start at its lowest vertex.
fn canonical(t: &mut [u32; 3]) {
    let r = (0..3).min_by_key(|&k| t[k]).unwrap_or(0);
    t.rotate_left(r);
}

fn boundary_vertices(triangles: &[[u32; 3]], n: usize) -> Vec<bool> {
    let mut on = vec![false; n];
    for (tri, nb) in triangles.iter().zip(triangle_neighbours(triangles)) {
        for k in 0..3 {
            if nb[k] == BOUNDARY {
                on[tri[k] as usize] = true;
                on[tri[(k + 1) % 3] as usize] = true;
            }
        }
    }
    on
}

/// Whether each piece (consistently wound) already faces out of the region it encloses when
/// closed by a fan on each of its boundary loops.
fn outward_pieces(vertices: &[Point3<f64>], triangles: &[[u32; 3]], piece: &[u32], pieces: usize) -> Vec<bool> {
    if pieces == 1 {
        let loops = boundary_loops(triangles);
        return vec![signed_volume6(vertices, triangles, &loops) >= 0.0];
    }
    (0..pieces as u32)
        .map(|p| {
            let own: Vec<[u32; 3]> = triangles.iter().zip(piece).filter(|(_, q)| **q == p).map(|(t, _)| *t).collect();
            let loops = boundary_loops(&own);
            signed_volume6(vertices, &own, &loops) >= 0.0
        })
        .collect()
}

fn not_orientable(vertices: &[Point3<f64>], a: u32, b: u32, clashes: usize) -> String {
    let (p, q) = (vertices[a as usize], vertices[b as usize]);
    format!(
        "is not orientable: its triangles cannot all face one side of the wall (a twisted strip, or two sheets \
         stitched back to front); at the edge from ({:.4}, {:.4}, {:.4}) to ({:.4}, {:.4}, {:.4}) mm the two \
         triangles wind against each other whichever way the rest is wound ({clashes} such edge(s)): repair the \
         surface there in your segmentation tool and save it again",
        p.x, p.y, p.z, q.x, q.y, q.z
    )
}
