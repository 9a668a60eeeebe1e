//! Junction centres moved to the middle of the junction.
//!
//! A centerline file places a junction where its paths part. Image-based paths often part late
//! or to one side: inside a carotid bulb, gmsh's paths split at the wall of the external carotid's
//! ostium, a radius away from the middle of the bulb, and the parent's last radii swing towards
//! that point. A junction's pages hang from its centre, so such a centre leaves the parent's
//! transition hugging one wall. Where a clearly larger ball fits near the file's centre, the
//! junction moves to that ball's centre (the medial point of the junction) and the branches'
//! ends bend smoothly to it.

use super::bend::{bend_end, BLEND_MOVES};
use super::rooted::RootedTree;
use crate::geometry::surface::LumenSurface;
use nalgebra::{Point3, Vector3};

/// The centre moves only when the ball it finds is this much larger than the file's centre's.
const GAIN: f64 = 1.15;
/// The search stays within this many file radii of the file's centre.
const SEARCH_RADII: f64 = 1.5;

/// Moves every junction whose file centre sits off the middle of the lumen (see the module).
pub(crate) fn centre_junctions(tree: &mut RootedTree, surface: &LumenSurface) {
    for node in 0..tree.nodes.len() {
        if tree.children[node].is_empty() || tree.parent[node].is_none() || tree.parted[node] {
            continue;
        }
        let start = tree.nodes[node].point;
        let d0 = surface.closest(&start).distance;
        let reach = SEARCH_RADII * tree.nodes[node].radius.max(d0);
        let (centre, d) = largest_ball_near(surface, start, d0, reach);
        if d < GAIN * d0 {
            continue;
        }
        let shift = centre - start;
        tree.nodes[node].point = centre;
        tree.nodes[node].radius = d;
        let blend = (BLEND_MOVES * shift.norm()).max(2.0 * d);
        let incident: Vec<(usize, bool)> =
            tree.children[node].iter().map(|&e| (e, true)).chain(tree.parent[node].map(|e| (e, false))).collect();
        for (e, starts_here) in incident {
            let line = &mut tree.edges[e].line;
            bend_end(&mut line.points, &mut line.radii, starts_here, shift, d, blend);
        }
    }
}

/// Pattern search for the largest ball inside the lumen within `reach` of `start`. Each trial
/// step is shorter than twice the current ball's radius, so no step can cross the wall (a
/// point farther from the wall than the current one, reached through the wall, would be at
/// least two radii away).
fn largest_ball_near(surface: &LumenSurface, start: Point3<f64>, d0: f64, reach: f64) -> (Point3<f64>, f64) {
    let (mut best, mut d) = (start, d0);
    let mut step = 0.25 * d0;
    while step > 1e-3 * d0 {
        let mut moved = false;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let q = best + Vector3::new(dx as f64, dy as f64, dz as f64) * step;
                    if (q - start).norm() > reach {
                        continue;
                    }
                    let dq = surface.closest(&q).distance;
                    if dq > d {
                        (best, d) = (q, dq);
                        moved = true;
                    }
                }
            }
        }
        if !moved {
            step *= 0.5;
        }
        step = step.min(0.5 * d);
    }
    (best, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// An open cylinder of radius `r` along z from 0 to `h`.
    fn cylinder(r: f64, h: f64) -> LumenSurface {
        let (nc, nz) = (48, 40);
        let mut vertices = Vec::new();
        for j in 0..=nz {
            for i in 0..nc {
                let a = TAU * i as f64 / nc as f64;
                vertices.push(Point3::new(r * a.cos(), r * a.sin(), h * j as f64 / nz as f64));
            }
        }
        let mut triangles = Vec::new();
        for j in 0..nz {
            for i in 0..nc {
                let v = |i: usize, j: usize| (j * nc + i % nc) as u32;
                triangles.push([v(i, j), v(i + 1, j), v(i + 1, j + 1)]);
                triangles.push([v(i, j), v(i + 1, j + 1), v(i, j + 1)]);
            }
        }
        LumenSurface::from_parts(vertices, triangles, "cylinder".into()).unwrap()
    }

    #[test]
    fn the_largest_ball_near_an_off_axis_point_is_on_the_axis() {
        let r = 2.0;
        let surface = cylinder(r, 20.0);
        let start = Point3::new(1.2, 0.3, 10.0);
        let d0 = surface.closest(&start).distance;
        let (centre, d) = largest_ball_near(&surface, start, d0, 3.0);
        // The faceted cylinder's inscribed radius is r cos(pi / 48).
        assert!(d > 0.99 * r * (std::f64::consts::PI / 48.0).cos(), "ball radius {d}");
        assert!(centre.x.hypot(centre.y) < 0.02 * r, "centre {centre:?}");
        assert!(d > d0);
    }
}
