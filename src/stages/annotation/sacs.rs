//! The sac of a saccular aneurysm that holds a junction (a bifurcation aneurysm, such as
//! palabos_cerebral_aneurysm's): the vessels' centerlines run through it, so it is meshed as
//! the junction, and its elements are marked as the sac's in the mesh (`sac` in `mesh.vtu`,
//! `sac_elements` of the junction in `report.json`). A sac that bulges beside the vessels is a
//! blind branch instead (see [`crate::geometry::mesh::is_sac`]).
//!
//! The sac is the part of the junction's lumen outside its branches' own tubes (each branch's
//! radius where it leaves the junction, about its centerline, which runs on to the junction's
//! centre), and the wall over it.

use crate::geometry::mesh::{closest_on_segment, face_key, VesselMesh, WallColumns, FACE_OUTER};
use crate::stages::centerline::CenterlineTree;
use crate::stages::junction::JunctionGeometry;
use nalgebra::{Point3, Vector3};
use std::collections::HashMap;

/// A junction holds a sac when its largest inscribed ball is at least this many times as wide
/// as its widest branch where the branches leave it. On the cohort: 2.63 at
/// palabos_cerebral_aneurysm's sac, at most 1.26 at every other junction.
pub const SAC_JUNCTION_RATIO: f64 = 1.8;

/// Whether a junction holds a saccular aneurysm's sac (see [`SAC_JUNCTION_RATIO`]).
pub fn holds_sac(junction: &JunctionGeometry) -> bool {
    let widest = junction.slots.iter().map(|s| s.radius).fold(0.0, f64::max);
    junction.radius >= SAC_JUNCTION_RATIO * widest
}

/// Distance from `p` to a polyline.
fn distance_to_polyline(p: &Point3<f64>, points: &[Point3<f64>]) -> f64 {
    if points.len() == 1 {
        return (p - points[0]).norm();
    }
    points.windows(2).map(|w| (p - closest_on_segment(p, &w[0], &w[1])).norm()).fold(f64::INFINITY, f64::min)
}

/// A branch's own tube at a junction: its radius where it leaves, about its centerline.
struct Tube {
    centerline: Vec<Point3<f64>>,
    radius: f64,
}

impl Tube {
    fn holds(&self, p: &Point3<f64>) -> bool {
        distance_to_polyline(p, &self.centerline) <= self.radius
    }
}

/// Marks the elements of the sacs that junctions hold in `mesh.sac` (`junction_of`: each
/// element's junction, as built): a lumen element of such a junction whose centroid lies
/// outside every one of its branches' tubes, and the wall elements stacked on a marked one.
pub fn mark_junction_sacs(
    mesh: &mut VesselMesh,
    junction_of: &[Option<usize>],
    junctions: &[JunctionGeometry],
    tree: &CenterlineTree,
) {
    // Each junction's branch tubes, for the junctions that hold a sac.
    let tubes_of: HashMap<usize, Vec<Tube>> = junctions
        .iter()
        .filter(|j| holds_sac(j))
        .map(|j| {
            let tubes = j
                .slots
                .iter()
                .map(|s| Tube {
                    centerline: tree.branches[s.branch].samples.iter().map(|x| x.point).collect(),
                    radius: s.radius,
                })
                .collect();
            (j.index, tubes)
        })
        .collect();
    if tubes_of.is_empty() {
        return;
    }
    let mut marked = Vec::new();
    for e in mesh.lumen_range() {
        let Some(tubes) = junction_of[e].and_then(|j| tubes_of.get(&j)) else { continue };
        let centroid = Point3::from(mesh.corners(e).iter().map(|c| c.coords).sum::<Vector3<f64>>() / 8.0);
        if !tubes.iter().any(|t| t.holds(&centroid)) {
            marked.push(e);
        }
    }
    // Up through the wall, over the outer face of each marked lumen element.
    let columns = WallColumns::new(mesh);
    let in_sac: Vec<usize> = marked
        .iter()
        .flat_map(|&e| std::iter::once(e).chain(columns.above(mesh, face_key(&mesh.hexes[e], FACE_OUTER))))
        .collect();
    for e in in_sac {
        mesh.sac[e] = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_distance_to_a_polyline_is_to_its_nearest_segment() {
        let line = [Point3::origin(), Point3::new(10.0, 0.0, 0.0), Point3::new(10.0, 10.0, 0.0)];
        assert!((distance_to_polyline(&Point3::new(5.0, 3.0, 4.0), &line) - 5.0).abs() < 1e-12);
        assert!((distance_to_polyline(&Point3::new(13.0, 4.0, 0.0), &line) - 3.0).abs() < 1e-12);
        assert!((distance_to_polyline(&Point3::new(-3.0, 0.0, 4.0), &line) - 5.0).abs() < 1e-12);
        assert!((distance_to_polyline(&Point3::new(1.0, 1.0, 1.0), &line[..1]) - 3f64.sqrt()).abs() < 1e-12);
    }
}
