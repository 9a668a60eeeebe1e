//! Points for the Voronoi diagram: the closed surface resampled at a spacing proportional to
//! the local vessel radius. The medial axis needs a couple of dozen points around a section,
//! not the file's triangulation: a segmentation's fine triangles (tens of thousands on an
//! aneurysm) only slow the tessellation, and its coarse ones (a triangle longer than the
//! vessel is wide, as coarse STL exports have) leave gaps through which the Voronoi diagram of
//! the vertices alone escapes.

use crate::geometry::surface::LumenSurface;
use crate::io::input::topology::vertex_normals;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use std::collections::HashMap;

/// Target spacing of the samples, as a fraction of the local radius (about 30 around a section).
const SPACING: f64 = 0.35;
/// A candidate is dropped when a kept sample lies within this fraction of its spacing.
const THINNING: f64 = 0.6;
/// ... but never below this fraction of the bounding box's diagonal.
const MIN_SPACING: f64 = 1e-3;
/// A triangle's edges are split into at most this many parts.
const MAX_SPLITS: f64 = 64.0;

/// Points on the closed surface (`triangles` facing out) with their outward unit normals: the
/// vertices, thinned where they are denser than [`SPACING`] of the local radius, and points
/// added on triangles longer than that.
pub fn resample(vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> (Vec<Point3<f64>>, Vec<Vector3<f64>>) {
    let normals = vertex_normals(vertices, triangles);
    let (lo, hi) = bounds(vertices);
    let diagonal = (hi - lo).norm().max(f64::MIN_POSITIVE);
    // The local radius: half the distance across the lumen along the inward normal (the
    // shape-diameter idea). Unlike the shrinking ball at the vertex, it does not collapse where
    // the normals are a little noisy (fine triangulations), nor at a sharp rim.
    let Ok(solid) = LumenSurface::from_parts(vertices.to_vec(), triangles.to_vec(), Default::default()) else {
        return (vec![], vec![]);
    };
    let mut ring: Vec<Vec<u32>> = vec![vec![]; vertices.len()];
    for t in triangles {
        for k in 0..3 {
            ring[t[k] as usize].extend([t[(k + 1) % 3], t[(k + 2) % 3]]);
        }
    }
    ring.iter_mut().for_each(|r| {
        r.sort_unstable();
        r.dedup();
    });
    let radius: Vec<f64> = (0..vertices.len())
        .into_par_iter()
        .map(|v| {
            let n = normals[v];
            if n == Vector3::zeros() {
                return diagonal;
            }
            // Hits nearer than half the vertex's longest edge (a ray grazing a slightly concave
            // or noisy neighbourhood) are stepped over: the opposite wall lies farther.
            let edge = ring[v].iter().map(|&u| (vertices[u as usize] - vertices[v]).norm()).fold(0.0, f64::max);
            let mut travelled = 1e-9 * diagonal;
            for _ in 0..8 {
                let Some(hit) = solid.first_hit(&(vertices[v] - n * travelled), &-n, diagonal) else { break };
                travelled += hit.distance + 1e-9 * diagonal;
                if travelled > 0.5 * edge {
                    return 0.5 * travelled;
                }
            }
            diagonal
        })
        .collect();
    // The median over the vertex and its neighbours: one stray ray does not set the spacing.
    let mut spacing: Vec<f64> = (0..vertices.len())
        .map(|v| {
            let mut r: Vec<f64> = ring[v].iter().map(|&u| radius[u as usize]).chain([radius[v]]).collect();
            r.sort_by(f64::total_cmp);
            r[r.len() / 2]
        })
        .collect();
    let floor = MIN_SPACING * diagonal;
    spacing.iter_mut().for_each(|h| *h = (SPACING * *h).max(floor));
    let mut candidates: Vec<(Point3<f64>, Vector3<f64>, f64)> = (0..vertices.len())
        .filter(|&v| normals[v] != Vector3::zeros())
        .map(|v| (vertices[v], normals[v], spacing[v]))
        .collect();
    for t in triangles {
        let [a, b, c] = t.map(|i| vertices[i as usize]);
        let h = t.iter().map(|&i| spacing[i as usize]).fold(f64::INFINITY, f64::min);
        let longest = (b - a).norm().max((c - b).norm()).max((a - c).norm());
        let Some(n) = (b - a).cross(&(c - a)).try_normalize(0.0) else { continue };
        // Short enough, or no spacing known (NaN): left as it is.
        if longest.partial_cmp(&h) != Some(std::cmp::Ordering::Greater) {
            continue;
        }
        let k = (longest / h).ceil().min(MAX_SPLITS) as usize;
        for i in 0..=k {
            for j in 0..=(k - i) {
                if [i, j, k - i - j].contains(&k) {
                    continue; // a corner: the vertex itself
                }
                let (u, v) = (i as f64 / k as f64, j as f64 / k as f64);
                candidates.push((a + (b - a) * u + (c - a) * v, n, h));
            }
        }
    }
    thin(&candidates, lo)
}

fn bounds(points: &[Point3<f64>]) -> (Point3<f64>, Point3<f64>) {
    points.iter().fold((Point3::from([f64::MAX; 3]), Point3::from([f64::MIN; 3])), |(lo, hi), p| (lo.inf(p), hi.sup(p)))
}

/// Greedy thinning in candidate order: a candidate is kept unless a kept point lies within
/// [`THINNING`] times its spacing. Kept points are filed in hash grids of cell sizes doubling
/// from the smallest radius, so each query looks at the 27 cells of the grid whose cells are
/// just larger than its radius.
fn thin(candidates: &[(Point3<f64>, Vector3<f64>, f64)], origin: Point3<f64>) -> (Vec<Point3<f64>>, Vec<Vector3<f64>>) {
    let smallest = candidates.iter().map(|c| THINNING * c.2).fold(f64::INFINITY, f64::min).max(f64::MIN_POSITIVE);
    let largest = candidates.iter().map(|c| THINNING * c.2).fold(0.0, f64::max);
    let levels = ((largest / smallest).log2().ceil().max(0.0) as usize + 1).min(48);
    let cell = |level: usize| smallest * 2f64.powi(level as i32);
    let key = |p: &Point3<f64>, level: usize| {
        let q = (p - origin) / cell(level);
        (q.x.floor() as i64, q.y.floor() as i64, q.z.floor() as i64)
    };
    let mut grids: Vec<HashMap<(i64, i64, i64), Vec<u32>>> = vec![HashMap::new(); levels];
    let (mut points, mut normals): (Vec<Point3<f64>>, Vec<Vector3<f64>>) = (vec![], vec![]);
    for (p, n, h) in candidates {
        let reach = THINNING * h;
        let level = ((reach / smallest).log2().ceil().max(0.0) as usize).min(levels - 1);
        let (x, y, z) = key(p, level);
        let near = (-1..=1).flat_map(|i| (-1..=1).flat_map(move |j| (-1..=1).map(move |k| (x + i, y + j, z + k))));
        let crowded = near
            .filter_map(|c| grids[level].get(&c))
            .flatten()
            .any(|&q| (points[q as usize] - p).norm_squared() < reach * reach);
        if crowded {
            continue;
        }
        let id = points.len() as u32;
        points.push(*p);
        normals.push(*n);
        for (level, grid) in grids.iter_mut().enumerate() {
            grid.entry(key(p, level)).or_default().push(id);
        }
    }
    (points, normals)
}
