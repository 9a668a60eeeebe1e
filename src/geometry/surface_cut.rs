//! Cutting a tube of a surface open across: what turns a network with loops into a tree whose
//! centerlines can be found as any tree's (see `centerline::extract::loops`).
//!
//! A plane across a vessel cuts its wall in one closed loop around the centerline (see
//! [`crate::geometry::plane_cut`]). Splitting the triangles along that loop, and along a second
//! one a `gap` further on, and taking out the thin band between, opens the vessel there: two
//! open ends face each other across the gap, and the surface has one loop fewer. The band is
//! taken out, not left at zero width, because the ends are then closed by caps for the medial
//! axis, and two caps on one plane would give it coincident samples of opposite sides.

use crate::geometry::plane_cut::{plane_loops, Plane};
use crate::geometry::surface::{LumenSurface, TriangleSurface};
use nalgebra::{Point3, Vector3};
use std::collections::HashMap;

/// The share of the surface's triangles the band between the two cuts may hold at most: more,
/// and the second cut did not close around the vessel (the band would be the rest of it).
const MOST_BAND_SHARE: f64 = 0.1;

/// The surface opened across the vessel through `origin` along `normal`: split along the plane's
/// loop around `origin` and along the one a `gap` further (both found within `reach`), the
/// triangles between taken out. `None` when either plane meets the surface in no closed loop
/// around the vessel there.
pub fn cut_across(
    surface: &TriangleSurface,
    origin: &Point3<f64>,
    normal: &Vector3<f64>,
    reach: f64,
    gap: f64,
) -> Option<TriangleSurface> {
    let n = normal.normalize();
    let (first, [_, below_first]) = split_along(surface, &(origin + n * (0.5 * gap)), &n, reach)?;
    let (second, [above_second, _]) = split_along(&first, &(origin - n * (0.5 * gap)), &n, reach)?;
    let band_side: std::collections::HashSet<u32> = below_first.into_iter().chain(above_second).collect();
    without_band(second, &band_side)
}

/// The plane through `origin` normal to `n` (unit), with 2D axes of its own (see [`Plane`]).
pub fn plane_through(origin: &Point3<f64>, n: &Vector3<f64>) -> Plane {
    let helper = if n.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let x = n.cross(&helper).normalize();
    Plane { origin: *origin, x, y: n.cross(&x) }
}

/// The surface split along the loop where the plane cuts it around `origin`: the triangles the
/// loop crosses cut in two, the pieces on either side given their own copy of each crossing
/// point, so that the surface comes apart there (two boundary loops in place of none). Also the
/// copies of the crossing points above the plane, and those below.
fn split_along(
    surface: &TriangleSurface,
    origin: &Point3<f64>,
    n: &Vector3<f64>,
    reach: f64,
) -> Option<(TriangleSurface, [Vec<u32>; 2])> {
    let lumen =
        LumenSurface::from_parts(surface.vertices.clone(), surface.triangles.clone(), surface.source.clone()).ok()?;
    let plane = plane_through(origin, n);
    let around = plane_loops(&lumen, &plane, reach).into_iter().find(|l| l.contains(&nalgebra::Vector2::zeros()))?;
    // The same rule as `plane_loops`: a vertex on the plane counts as above it.
    let above = |v: u32| (surface.vertices[v as usize] - origin).dot(n) >= 0.0;
    let mut vertices = surface.vertices.clone();
    // The two copies (above, below) of each crossing point, by the edge it lies on.
    let mut copies: HashMap<(u32, u32), [u32; 2]> = HashMap::new();
    let mut crossing = |a: u32, b: u32, vertices: &mut Vec<Point3<f64>>| {
        let key = (a.min(b), a.max(b));
        *copies.entry(key).or_insert_with(|| {
            let (pa, pb) = (vertices[key.0 as usize], vertices[key.1 as usize]);
            let (da, db) = ((pa - origin).dot(n), (pb - origin).dot(n));
            let p = pa + (pb - pa) * (da / (da - db));
            vertices.push(p);
            vertices.push(p);
            [vertices.len() as u32 - 2, vertices.len() as u32 - 1]
        })
    };
    let cut: std::collections::HashSet<u32> = around.triangles.iter().copied().collect();
    let mut triangles = Vec::with_capacity(surface.triangles.len() + 2 * cut.len());
    let mut tags = surface.triangle_tags.as_ref().map(|(name, _)| (name.clone(), vec![]));
    for (t, tri) in surface.triangles.iter().enumerate() {
        let tag = surface.triangle_tags.as_ref().map(|(_, v)| v[t]);
        let pieces = if cut.contains(&(t as u32)) {
            // Rotate so the vertex alone on its side comes first; the winding is kept.
            let side = tri.map(above);
            let lone = (0..3).find(|&k| side[k] != side[(k + 1) % 3] && side[k] != side[(k + 2) % 3])?;
            let (a, b, c) = (tri[lone], tri[(lone + 1) % 3], tri[(lone + 2) % 3]);
            let (ab, ca) = (crossing(a, b, &mut vertices), crossing(c, a, &mut vertices));
            let (mine, theirs) = if side[lone] { (0, 1) } else { (1, 0) };
            vec![[a, ab[mine], ca[mine]], [ab[theirs], b, c], [ab[theirs], c, ca[theirs]]]
        } else {
            vec![*tri]
        };
        if let (Some((_, out)), Some(tag)) = (&mut tags, tag) {
            out.extend(std::iter::repeat_n(tag, pieces.len()));
        }
        triangles.extend(pieces);
    }
    let sides = [0, 1].map(|k| copies.values().map(|c| c[k]).collect());
    Some((TriangleSurface { vertices, triangles, triangle_tags: tags, source: surface.source.clone() }, sides))
}

/// The surface without the band between two cuts: the piece (triangles joined by shared edges)
/// of the triangles that use the cuts' points on the band's side. `None` when that piece is no
/// thin band (a cut did not go all round).
fn without_band(mut surface: TriangleSurface, band_side: &std::collections::HashSet<u32>) -> Option<TriangleSurface> {
    let seeds: Vec<usize> =
        (0..surface.triangles.len()).filter(|&t| surface.triangles[t].iter().any(|v| band_side.contains(v))).collect();
    if seeds.is_empty() {
        return None;
    }
    let band = piece_of(&surface.triangles, &seeds);
    let count = band.iter().filter(|&&b| b).count();
    if count as f64 > MOST_BAND_SHARE * surface.triangles.len() as f64 {
        return None;
    }
    if let Some((_, tags)) = &mut surface.triangle_tags {
        let mut keep = band.iter().map(|b| !b);
        tags.retain(|_| keep.next().unwrap_or(true));
    }
    let mut keep = band.iter().map(|b| !b);
    surface.triangles.retain(|_| keep.next().unwrap_or(true));
    Some(surface)
}

/// The triangles joined to any of `seeds` through shared edges.
fn piece_of(triangles: &[[u32; 3]], seeds: &[usize]) -> Vec<bool> {
    let mut by_edge: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (t, tri) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            by_edge.entry((a.min(b), a.max(b))).or_default().push(t);
        }
    }
    let mut inside = vec![false; triangles.len()];
    let mut stack: Vec<usize> = seeds.to_vec();
    seeds.iter().for_each(|&s| inside[s] = true);
    while let Some(t) = stack.pop() {
        let tri = triangles[t];
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            for &u in &by_edge[&(a.min(b), a.max(b))] {
                if !inside[u] {
                    inside[u] = true;
                    stack.push(u);
                }
            }
        }
    }
    inside
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::input::topology::{boundary_loops, handles};
    use std::path::PathBuf;

    /// A torus about the z axis (tube radius 1 about a circle of radius 4).
    fn torus(m: usize, n: usize) -> TriangleSurface {
        let mut vertices = vec![];
        for i in 0..m {
            let u = std::f64::consts::TAU * i as f64 / m as f64;
            for j in 0..n {
                let v = std::f64::consts::TAU * j as f64 / n as f64;
                let r = 4.0 + v.cos();
                vertices.push(Point3::new(r * u.cos(), r * u.sin(), v.sin()));
            }
        }
        let id = |i: usize, j: usize| ((i % m) * n + j % n) as u32;
        let mut triangles = vec![];
        for i in 0..m {
            for j in 0..n {
                triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        TriangleSurface { vertices, triangles, triangle_tags: None, source: PathBuf::from("torus") }
    }

    #[test]
    fn a_ring_cut_across_is_a_tube_with_two_ends_a_gap_apart() {
        let ring = torus(64, 16);
        assert_eq!(handles(&ring.triangles), Some(1));
        // Across the tube at (4, 0, 0): the plane normal to the ring's circle there.
        let gap = 0.1;
        let open = cut_across(&ring, &Point3::new(4.0, 0.0, 0.0), &Vector3::y(), 3.0, gap).expect("cuts");
        assert_eq!(handles(&open.triangles), Some(0));
        let loops = boundary_loops(&open.triangles);
        assert_eq!(loops.len(), 2);
        for lp in &loops {
            let ys: Vec<f64> = lp.iter().map(|&v| open.vertices[v as usize].y).collect();
            let y = ys[0];
            assert!((y.abs() - 0.5 * gap).abs() < 1e-12, "a cut end lies on its plane: y = {y}");
            assert!(ys.iter().all(|v| (v - y).abs() < 1e-12));
        }
        // The far side of the ring, crossed by the same plane, is not cut.
        let far: usize = loops.iter().flatten().filter(|&&v| open.vertices[v as usize].x < 0.0).count();
        assert_eq!(far, 0);
    }

    #[test]
    fn a_plane_beside_the_tube_cuts_nothing() {
        let ring = torus(64, 16);
        assert!(cut_across(&ring, &Point3::new(0.0, 0.0, 0.0), &Vector3::y(), 1.0, 0.1).is_none());
    }
}
