//! The medial axis as the inner Voronoi diagram of points sampled on the closed surface, VMTK's
//! construction: the Delaunay tetrahedra of the samples have empty circumspheres, so their
//! circumcentres (the Voronoi vertices) that lie inside the surface are centres of balls empty of
//! samples, and two tetrahedra sharing a face give a Voronoi edge between their centres. Where
//! the lumen is sampled finely enough for its width, these centres and edges form a connected
//! graph wherever the lumen is connected: the property the centerline paths need, and the one a
//! graph of nearby balls lacks where balls are sparse (narrow branches, coarse triangles).
//!
//! The Delaunay tessellation comes from Qhull (through the `qhull` crate), whose exact
//! arithmetic handles the near-degenerate, nearly cospherical rings of points that structured
//! vessel surfaces are made of.

use super::medial::{Ball, BallGraph};
use nalgebra::{Point3, Vector3};
use qhull::QhBuilder;
use rayon::prelude::*;

/// The Delaunay tetrahedra of a point set: corner indices and, per tetrahedron, the
/// tetrahedra it shares a face with.
pub struct Delaunay {
    pub tets: Vec<[u32; 4]>,
    pub adjacent: Vec<Vec<u32>>,
}

/// The Delaunay tetrahedralisation of `points` (at least five, not all coplanar); `Err` with
/// Qhull's own words when it cannot be built.
pub fn delaunay(points: &[Point3<f64>]) -> Result<Delaunay, String> {
    // The points are lifted to the paraboloid w = |x|^2, whose lower convex hull projects to the
    // Delaunay tessellation (Qhull's 'd'); centred on their centroid and scaled uniformly (a
    // non-uniform scale would change the tessellation), so that the lift stays well conditioned
    // for vessels far from the origin.
    let n = points.len().max(1) as f64;
    let centroid = points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let scale = points.iter().map(|p| (p.coords - centroid).amax()).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    let coords: Vec<f64> = points
        .iter()
        .flat_map(|p| {
            let q = (p.coords - centroid) / scale;
            [q.x, q.y, q.z, q.norm_squared()]
        })
        .collect();
    // 'QJ' joggles the input by a tiny deterministic amount (Qhull's fixed seed): sections of
    // cospherical points (every ring of a straight tube's vertices) then give proper tetrahedra
    // linked across each ring, where 'Qt' would leave flat ones that break the chain.
    let qh = QhBuilder::default()
        .qhull_args(["QJ"])
        .map_err(|e| format!("Qhull options: {e:?}"))?
        .delaunay(true)
        .scale_last(true)
        .build_managed(4, coords)
        .map_err(|e| format!("Qhull could not tessellate the surface points: {e:?}"))?;
    let mut index_of_id = std::collections::HashMap::new();
    let mut tets = vec![];
    let mut neighbour_ids = vec![];
    for facet in qh.facets() {
        if facet.upper_delaunay() {
            continue;
        }
        let Some(vertices) = facet.vertices() else { continue };
        let corners: Vec<u32> = vertices.iter().filter_map(|v| v.index(&qh)).map(|i| i as u32).collect();
        let [a, b, c, d] = corners[..] else { continue };
        index_of_id.insert(facet.id(), tets.len() as u32);
        tets.push([a, b, c, d]);
        neighbour_ids.push(facet.neighbors().map(|n| n.iter().map(|f| f.id()).collect::<Vec<_>>()).unwrap_or_default());
    }
    let adjacent =
        neighbour_ids.iter().map(|ids| ids.iter().filter_map(|id| index_of_id.get(id).copied()).collect()).collect();
    Ok(Delaunay { tets, adjacent })
}

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
pub fn medial_graph(samples: &[Point3<f64>], normals: &[Vector3<f64>]) -> Result<BallGraph, String> {
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
    let graph = BallGraph::from_parts(nodes, links);
    Ok(graph)
}
