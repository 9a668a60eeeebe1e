//! The medial axis as the inner Voronoi diagram of points sampled on the closed surface, VMTK's
//! construction: the Delaunay tetrahedra of the samples have empty circumspheres, so their
//! circumcentres (the Voronoi vertices) that lie inside the surface are centres of balls empty of
//! samples, and two tetrahedra sharing a face give a Voronoi edge between their centres. Where
//! the lumen is sampled finely enough for its width, these centres and edges form a connected
//! graph wherever the lumen is connected: the property the centerline paths need, and the one a
//! graph of nearby balls lacks where balls are sparse (narrow branches, coarse triangles).
//!
//! The Delaunay tessellation comes from Qhull's C library (see `qhull`), whose exact
//! arithmetic handles the near-degenerate, nearly cospherical rings of points that structured
//! vessel surfaces are made of.

use super::medial::{Ball, BallGraph};
use super::qhull::{delaunay, Delaunay};
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

/// The circumcentre of a tetrahedron, or `None` for a flat one (its circumcentre is not defined
/// to any useful precision).
fn circumcentre(p: [Point3<f64>; 4]) -> Option<Point3<f64>> {
    let (u, v, w) = (p[1] - p[0], p[2] - p[0], p[3] - p[0]);
    let det = u.dot(&v.cross(&w));
    let scale = u.norm().max(v.norm()).max(w.norm());
    // A flat (or non-finite) tetrahedron has no circumcentre worth keeping.
    if det.abs().partial_cmp(&(1e-12 * scale.powi(3))) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let num = v.cross(&w) * u.norm_squared() + w.cross(&u) * v.norm_squared() + u.cross(&v) * w.norm_squared();
    Some(p[0] + num / (2.0 * det))
}

/// Whether `centre` lies on the inner side of the tangent plane of every corner (VMTK's test
/// for an internal tetrahedron, `vtkvmtkInternalTetrahedraExtractor`): the circumcentre of a
/// tetrahedron spanning the lumen does, one spanning a gap outside the surface (between two
/// branches, in a bend) does not.
fn inside_every_tangent_plane(
    centre: &Point3<f64>,
    corners: &[u32; 4],
    samples: &[Point3<f64>],
    normals: &[Vector3<f64>],
) -> bool {
    corners.iter().all(|&i| (centre - samples[i as usize]).dot(&normals[i as usize]) < 0.0)
}

/// Whether a tetrahedron's corners spread over its circumsphere (two of them at least a radius
/// apart, 60 degrees seen from the centre), as those of a tetrahedron spanning the lumen do. A
/// nearly flat tetrahedron of points on one side (on a flat cap, or along a wall) has a huge
/// circumsphere whose centre may lie anywhere, inside the surface or far beyond it.
fn spans_its_ball(corners: &[Point3<f64>; 4], radius: f64) -> bool {
    (0..4).any(|i| (i + 1..4).any(|j| (corners[i] - corners[j]).norm() >= radius))
}

/// The inner Voronoi graph of the samples of the closed surface: a node per Delaunay
/// tetrahedron whose circumcentre is internal ([`inside_every_tangent_plane`]), its ball the
/// circumsphere (empty of samples: VMTK's MaximumInscribedSphereRadius); a link per shared face
/// whose two balls overlap, so the segment between the centres lies in their union, inside the
/// lumen. Link cost: length x mean(1/R), VMTK's 1/R cost.
///
/// Those links are kept inside the lumen, but they may leave a connected lumen in parts: the
/// tessellation and each tetrahedron's node (`u32::MAX`: none) come back too, to join the parts
/// that hold the vessel's ends through the lumen (see `bridges`).
pub fn medial_graph(
    samples: &[Point3<f64>],
    normals: &[Vector3<f64>],
) -> Result<(BallGraph, Delaunay, Vec<u32>), String> {
    let dt = delaunay(samples)?;
    let balls: Vec<Option<Ball>> = dt
        .tets
        .par_iter()
        .map(|t| {
            let corners = t.map(|i| samples[i as usize]);
            let centre = circumcentre(corners)?;
            let radius = (centre - corners[0]).norm();
            (spans_its_ball(&corners, radius) && inside_every_tangent_plane(&centre, t, samples, normals))
                .then_some(Ball { centre, radius })
        })
        .collect();
    let mut node_of = vec![u32::MAX; balls.len()];
    let mut nodes = vec![];
    for (t, b) in balls.iter().enumerate() {
        if let Some(b) = b {
            node_of[t] = nodes.len() as u32;
            nodes.push(*b);
        }
    }
    let mut links = vec![vec![]; nodes.len()];
    for (t, adjacent) in dt.adjacent.iter().enumerate() {
        let i = node_of[t];
        if i == u32::MAX {
            continue;
        }
        for &u in adjacent {
            let j = node_of[u as usize];
            if j == u32::MAX || j <= i {
                continue;
            }
            let (a, b) = (nodes[i as usize], nodes[j as usize]);
            let length = (a.centre - b.centre).norm();
            if length < a.radius + b.radius {
                let cost = length * 0.5 * (1.0 / a.radius + 1.0 / b.radius);
                links[i as usize].push((j, cost));
                links[j as usize].push((i, cost));
            }
        }
    }
    Ok((BallGraph::from_parts(nodes, links), dt, node_of))
}
