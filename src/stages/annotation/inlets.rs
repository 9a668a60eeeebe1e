//! Vessels fed through several ends (issue 49): the vertebral arteries joining into the
//! basilar, the venae cavae of a cavopulmonary connection, a graft's second inflow. The tree
//! stays rooted at one end, the inlet the volume was built from; flagging more ends as inlets
//! changes what flows in, not how the mesh is built, so it is done on the finished mesh: the
//! mesh ends at the flagged vessel ends become inlets and the ends are named by role.
//!
//! An end is an inlet when the user points at it (`--inlet x,y,z`, repeatable), names its cap
//! (`--inlet NAME`), or gives it a cap whose name is `inlet` or starts with `inlet_` (a
//! snappyHexMesh `triSurface/inlet_svc.stl`, a SimVascular `cap_...` renamed so). With one inlet
//! nothing changes: the ends keep the volume's names (`inlet`, `outlet` or `outlet_1`, ...).
//! With several, the unnamed inlets are `inlet_1`, `inlet_2`, ... and the unnamed outlets
//! `outlet_1`, `outlet_2`, ... (`outlet` when one is left), in mesh order, the root's first;
//! ends named by their caps keep their names.

use super::end_names::{mesh_ends_at, rename_ends};
use crate::geometry::mesh::VesselMesh;
use crate::stages::centerline::extract::{is_inlet_name, EndKind, VesselEnd};
use nalgebra::Point3;

/// An end the user flags as an inlet.
#[derive(Debug, Clone, PartialEq)]
pub enum InletMark {
    /// The end whose centre is nearest this point (mm).
    Point(Point3<f64>),
    /// The end closed by the cap of this name.
    Cap(String),
}

/// Which of `ends` are inlets (parallel to `ends`): `root`, the end the tree was built from,
/// every end a mark flags and every end named as an inlet (`names`, parallel to `ends`). Fails
/// naming the mark when a cap name closes no end (a point flags the nearest end that is no sac).
pub fn inlet_ends(
    ends: &[VesselEnd],
    names: &[Option<String>],
    root: usize,
    marks: &[InletMark],
) -> Result<Vec<bool>, String> {
    let mut inlet: Vec<bool> = (0..ends.len())
        .map(|k| k == root || names.get(k).and_then(|n| n.as_deref()).is_some_and(is_inlet_name))
        .collect();
    for mark in marks {
        inlet[end_of_mark(ends, names, mark)?] = true;
    }
    Ok(inlet)
}

/// The end a mark flags: the nearest vessel end to a point (a sac is no inlet), or the end a
/// cap of that name closes.
fn end_of_mark(ends: &[VesselEnd], names: &[Option<String>], mark: &InletMark) -> Result<usize, String> {
    match mark {
        InletMark::Point(p) => {
            let gap = |k: usize| (ends[k].centre - p).norm();
            (0..ends.len())
                .filter(|&k| ends[k].kind != EndKind::Sac)
                .min_by(|&a, &b| gap(a).total_cmp(&gap(b)))
                .ok_or_else(|| "--inlet: the vessel has no end an inlet could be".to_string())
        }
        InletMark::Cap(name) => names.iter().position(|n| n.as_deref() == Some(name.as_str())).ok_or_else(|| {
            let known: Vec<&str> = names.iter().flatten().map(String::as_str).collect();
            let known = if known.is_empty() { "none".to_string() } else { known.join(", ") };
            format!(
                "--inlet {name}: no cap of that name closes an end of the surface (caps given: {known}); name a cap \
                 given with --cap or in the surface's folder, or give a point x,y,z near the end"
            )
        }),
    }
}

/// Makes the mesh ends at the inlet ends (`inlet`, parallel to `ends`) inlets and, when there
/// are several, names the ends by role (see the module documentation); the ends named by their
/// caps (`names`, parallel to `ends`) keep their names. Returns the names changed (old, new).
pub fn mark_inlets(
    mesh: &mut VesselMesh,
    ends: &[VesselEnd],
    inlet: &[bool],
    names: &[Option<String>],
) -> Vec<(String, String)> {
    let mut named = vec![false; mesh.ends.len()];
    for (k, m) in mesh_ends_at(mesh, ends).into_iter().enumerate() {
        if let Some(m) = m {
            mesh.ends[m].is_inlet |= inlet[k];
            named[m] = names.get(k).is_some_and(Option::is_some);
        }
    }
    if mesh.ends.iter().filter(|e| e.is_inlet).count() < 2 {
        return Vec::new();
    }
    let finals = names_by_role(mesh, &named);
    rename_ends(mesh, &finals)
}

/// The ends' names when several are inlets: the ends `named` by their caps keep theirs, the
/// others are numbered by role in mesh order, skipping the names the named ends hold.
fn names_by_role(mesh: &VesselMesh, named: &[bool]) -> Vec<String> {
    let taken: Vec<&str> = mesh.ends.iter().zip(named).filter(|(_, &n)| n).map(|(e, _)| e.name.as_str()).collect();
    let unnamed_outlets = mesh.ends.iter().zip(named).filter(|(e, &n)| !n && !e.is_inlet).count();
    let mut counters = [0usize; 2];
    mesh.ends
        .iter()
        .zip(named)
        .map(|(e, &n)| {
            if n {
                return e.name.clone();
            }
            let (role, counter) = if e.is_inlet { ("inlet", &mut counters[0]) } else { ("outlet", &mut counters[1]) };
            if !e.is_inlet && unnamed_outlets == 1 && !taken.contains(&"outlet") {
                return "outlet".to_string();
            }
            loop {
                *counter += 1;
                let name = format!("{role}_{counter}");
                if !taken.contains(&name.as_str()) {
                    return name;
                }
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn end(x: f64, radius: f64, kind: EndKind) -> VesselEnd {
        VesselEnd { centre: Point3::new(x, 0.0, 0.0), radius, kind }
    }

    #[test]
    fn marks_flag_the_nearest_vessel_end_or_the_named_cap() {
        let ends = [end(0.0, 2.0, EndKind::Open), end(10.0, 1.0, EndKind::Sac), end(20.0, 1.0, EndKind::Open)];
        let names = [None, None, Some("lica".to_string())];
        // A point nearest the sac flags the nearest end that is not one.
        let marks = [InletMark::Point(Point3::new(12.0, 0.0, 0.0))];
        assert_eq!(inlet_ends(&ends, &names, 0, &marks).unwrap(), [true, false, true]);
        let by_name = inlet_ends(&ends, &names, 0, &[InletMark::Cap("lica".into())]).unwrap();
        assert_eq!(by_name, [true, false, true]);
        let unknown = inlet_ends(&ends, &names, 0, &[InletMark::Cap("rica".into())]).unwrap_err();
        assert!(unknown.contains("rica") && unknown.contains("lica"), "{unknown}");
        // A cap named inlet_<x> is an inlet without a mark.
        let names = [None, None, Some("inlet_b".to_string())];
        assert_eq!(inlet_ends(&ends, &names, 0, &[]).unwrap(), [true, false, true]);
    }
}
