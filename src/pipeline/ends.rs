//! The vessel's ends: which the mesh reaches, which were left out or cut short (a warning each),
//! where a short branch's cap may open in the side of the mesh, and the inlet and sacs the
//! centerline extraction found, kept for the tree.

use crate::data::config::MeshConfig;
use crate::data::diagnostics::Warning;
use crate::data::units::LengthUnit;
use crate::geometry::surface::TriangleSurface;
use crate::pipeline::finishing::Additions;
use crate::stages::additions::side_ends::SideOpening;
use crate::stages::annotation::Meshed;
use crate::stages::centerline::extract::{EndKind, VesselEnd};
use crate::stages::centerline::{CenterlineSample, CenterlineTree};
use nalgebra::Point3;
use serde::Serialize;

/// One vessel end: found on the surface (or given), and whether the mesh reaches it.
#[derive(Debug, Clone, Serialize)]
pub struct EndReport {
    /// The end's name in the mesh (its OpenFOAM patch, its sets `lumen_<name>` and
    /// `wall_<name>`): `inlet`, `outlet` or `outlet_1`, ..., or the name of the cap given for it;
    /// for an end not meshed, the cap's name or null.
    pub name: Option<String>,
    /// Centre of the end (output unit): a loop's or cap's centre, a dome's inscribed ball, a
    /// given point's ball, or a given centerline's end point.
    pub position: [f64; 3],
    /// Radius of the end section (output unit).
    pub radius: f64,
    /// `open` (a boundary loop), `flat cap`, `tagged cap`, `dome` (a rounded or blunt closed
    /// end), `given` (`--ends`) or `centerline` (an end of the centerlines given).
    pub kind: &'static str,
    pub inlet: bool,
    /// Whether a meshed branch ends there.
    pub meshed: bool,
}

/// The ends of a tree built on centerlines given: its inlet (the start of the branch with no
/// junction upstream) and each leaf branch's last sample. Read from the tree rather than the
/// file, whose polylines may be overlapping paths, branch-split tracts or two-node segments.
pub(super) fn tree_ends(tree: &CenterlineTree) -> (Vec<VesselEnd>, usize) {
    let end = |s: &CenterlineSample| VesselEnd { centre: s.point, radius: s.radius, kind: EndKind::Centerline };
    (tree_terminals(tree).map(end).collect(), 0)
}

/// The tree's vessel ends: the first sample of the branch with no junction upstream (the
/// inlet), then the last sample of each leaf branch.
pub(super) fn tree_terminals(tree: &CenterlineTree) -> impl Iterator<Item = &CenterlineSample> {
    let inlets = tree.branches.iter().filter(|b| b.start_junction.is_none()).filter_map(|b| b.samples.first());
    let outlets = tree.branches.iter().filter(|b| b.end_junction.is_none()).filter_map(|b| b.samples.last());
    inlets.chain(outlets)
}

/// A meshed branch ends within this many of the end's radii of its centre (a dome's mesh stops
/// short of its tip, inside it) ...
pub(super) const MESHED_END_REACH: f64 = 2.0;

/// ... or this many of the branch's own radii there (an end given as a bare point).
pub(super) const MESHED_END_BRANCH_RADII: f64 = 1.0;

/// Every end with whether a branch of the mesh ends at it (see [`MESHED_END_REACH`]) or it
/// opens in the side of the mesh (`side_ends`: their centres, mm), in the output unit (`scale`
/// per mm).
pub(super) fn end_reports(
    ends: &[VesselEnd],
    inlets: &[bool],
    tree: &CenterlineTree,
    side_ends: &[[f64; 3]],
    scale: f64,
) -> Vec<EndReport> {
    let terminals: Vec<&CenterlineSample> = tree_terminals(tree).collect();
    ends.iter()
        .enumerate()
        .map(|(k, e)| EndReport {
            name: None,
            position: (e.centre.coords * scale).into(),
            radius: e.radius * scale,
            kind: e.kind.name(),
            inlet: inlets[k],
            meshed: side_ends.contains(&e.centre.into())
                || terminals.iter().any(|t| {
                    (t.point - e.centre).norm() <= (MESHED_END_REACH * e.radius).max(MESHED_END_BRANCH_RADII * t.radius)
                }),
        })
        .collect()
}

/// One warning per end no meshed branch reaches; `left_out[k]` when end k's branch was found but
/// left out, too short for its junction (see `branch_not_meshed` in [`mesh_surface`]): pointing
/// the centerlines at it would not help there.
pub(super) fn ends_not_meshed(ends: &[EndReport], left_out: &[bool], unit: LengthUnit) -> Vec<Warning> {
    ends.iter()
        .zip(left_out.iter().chain(std::iter::repeat(&false)))
        .filter(|(e, _)| !e.meshed)
        .map(|(e, &short)| {
            let [x, y, z] = e.position;
            let why = if short {
                "its branch ends too close to its junction for the junction's transition (branch_not_meshed); a \
                 longer stretch of the vessel there would let it be meshed"
            } else {
                "no branch of the mesh reaches it; give centerlines that reach it (--centerlines) or a point near it \
                 (--ends)"
            };
            Warning::new(
                "end_not_meshed",
                format!(
                    "the {} end at ({x:.3}, {y:.3}, {z:.3}) {unit} (radius {:.3} {unit}) is not meshed: {why}",
                    e.kind, e.radius
                ),
            )
        })
        .collect()
}

/// Which of `ends` lead to a branch left out (`left_out_mm`: the branches' far ends, mm): the
/// nearest end to each.
pub(super) fn ends_left_out(ends: &[VesselEnd], left_out_mm: &[[f64; 3]]) -> Vec<bool> {
    let mut marked = vec![false; ends.len()];
    for p in left_out_mm {
        let gap = |e: &VesselEnd| (e.centre - Point3::from(*p)).norm();
        if let Some(k) = (0..ends.len()).min_by(|&a, &b| gap(&ends[a]).total_cmp(&gap(&ends[b]))) {
            marked[k] = true;
        }
    }
    marked
}

/// A vessel end whose mesh stops more than this many radii short of it (the vessel's radius at
/// the mesh's end section) leaves a stretch of the vessel out. Across the cohort, at coarse and
/// medium, the open ends' meshes stop within 0.72 radii of them, the closed ends' within 1.98
/// (a cap's rays and the margin kept from it); the voxel aorta's irregular closed outlet stops
/// 2.92 radii short (50 mm).
pub(super) const END_CUT_SHORT_RADII: f64 = 2.25;

/// One warning per vessel end whose mesh stops well short of it (see [`END_CUT_SHORT_RADII`],
/// beyond the trim asked for): no clean cross-section lies nearer the end, so the stretch
/// beyond is not meshed. Radii are the vessel's at the mesh's end section.
pub(super) fn ends_cut_short(meshed: &Meshed, config: &MeshConfig) -> Vec<Warning> {
    let (unit, trims) = (config.output_units, [config.centerline.trim_inlet, config.centerline.trim_outlet]);
    let scale = unit.from_mm();
    let mut warnings = vec![];
    for p in &meshed.projected {
        let branch = &meshed.tree.branches[p.branch];
        let (Some(first), Some(last)) = (branch.samples.first(), branch.samples.last()) else { continue };
        let (Some(start), Some(end)) = (p.sections.first(), p.sections.last()) else { continue };
        let ends = [
            (p.start, first, p.s_start - first.s, start.station.radius, trims[0]),
            (p.end, last, last.s - p.s_end, end.station.radius, trims[1]),
        ];
        for (kind, end, gap, radius, trim) in ends {
            if !matches!(kind, crate::stages::projection::BranchEnd::Vessel { .. })
                || gap <= (END_CUT_SHORT_RADII + trim) * radius
            {
                continue;
            }
            let [x, y, z] = [end.point.x * scale, end.point.y * scale, end.point.z * scale];
            warnings.push(Warning::new(
                "end_cut_short",
                format!(
                    "the mesh of branch {} stops {:.3} {unit} ({:.1} vessel radii) short of its end at ({x:.3}, {y:.3}, \
                     {z:.3}) {unit}: no cross-section nearer the end is clean (an oblique, irregular or capped end), so \
                     that stretch of the vessel is not meshed; clip the surface square across the vessel there to \
                     mesh up to the cut",
                    branch.name,
                    gap * scale,
                    gap / radius
                ),
            ));
        }
    }
    warnings
}

/// Where each short branch's end (its far end, mm) may open in the side of the mesh (see
/// [`crate::stages::additions::side_ends`]): the end found nearest it, when that end is a flat cap.
pub(super) fn side_openings(
    surface: &TriangleSurface,
    ends: &[VesselEnd],
    short_branches: &[([f64; 3], String)],
) -> Vec<Option<SideOpening>> {
    short_branches
        .iter()
        .map(|(end_mm, _)| {
            let gap = |e: &VesselEnd| (e.centre - Point3::from(*end_mm)).norm();
            let end = ends.iter().min_by(|a, b| gap(a).total_cmp(&gap(b)))?;
            match end.kind {
                EndKind::Cap { .. } => SideOpening::of_cap(surface, end.centre, end.radius),
                _ => None,
            }
        })
        .collect()
}

/// `config` with the inlet the centerline extraction chose (the largest end section, or the end
/// `--inlet` names) as the centerline tree's, unless the configuration names one, and the sacs it
/// found as the domes to close (unless the configuration names them). Left to choose
/// again, the tree would take the end with the widest vessel next to it, a daughter wider than a
/// short trunk (sphinxsys_pulmonary_bifurcation), and report and mesh would disagree on the inlet.
/// The loops the extraction cut open (`loop_cuts`, mm) are joined again, unless the
/// configuration names the cuts.
pub(super) fn keep_extracted_ends(
    config: &MeshConfig,
    found_ends: Option<&(Vec<VesselEnd>, usize)>,
    loop_cuts: &[[f64; 3]],
) -> MeshConfig {
    let mut config = config.clone();
    if config.centerline.loop_cuts_mm.is_empty() {
        config.centerline.loop_cuts_mm = loop_cuts.to_vec();
    }
    if let (Some((ends, _)), true) = (found_ends, config.centerline.sacs_mm.is_empty()) {
        config.centerline.sacs_mm =
            ends.iter().filter(|e| e.kind == EndKind::Sac).map(|e| e.centre.coords.into()).collect();
    }
    if let (Some((ends, inlet)), None) = (found_ends, config.centerline.inlet_mm) {
        config.centerline.inlet_mm = Some(ends[*inlet].centre.coords.into());
    }
    config
}

/// One warning per short branch left out (`short_branches`: its far end, mm, and why it could
/// not be meshed): `side_end` when its cap was opened in the side of the mesh (`openings`, as
/// asked of the added stages), else `branch_not_meshed`. Returns the far ends of the branches
/// left out unopened.
pub(super) fn short_branch_warnings(
    short_branches: Vec<([f64; 3], String)>,
    openings: &[Option<SideOpening>],
    additions: &Additions,
    warnings: &mut Vec<Warning>,
) -> Vec<[f64; 3]> {
    let mut left_out_mm = vec![];
    for ((end_mm, message), opening) in short_branches.into_iter().zip(openings) {
        let [x, y, z] = end_mm;
        let opened = opening.and_then(|o| additions.side_ends.iter().find(|s| s.centre == <[f64; 3]>::from(o.centre)));
        warnings.push(match opened {
            Some(s) => Warning::new(
                "side_end",
                format!(
                    "the end at ({x:.3}, {y:.3}, {z:.3}) mm is meshed as {}, an opening in the side of the mesh: {} \
                     lumen faces on its cap ({:.1} of its {:.1} mm2), its branch meshed with its neighbour's lumen, \
                     without an O-grid of its own, and the wall open over it. Its branch could not have its own: {message}",
                    s.end, s.faces, s.area, s.cap_area
                ),
            ),
            None => {
                left_out_mm.push(end_mm);
                Warning::new(
                    "branch_not_meshed",
                    format!(
                        "the vessel is meshed without its branch to the end at ({x:.3}, {y:.3}, {z:.3}) mm; with it: \
                         {message}"
                    ),
                )
            }
        });
    }
    left_out_mm
}

#[cfg(test)]
mod tests {
    use super::{end_reports, ends_not_meshed};
    use crate::data::config::MeshConfig;
    use crate::data::units::LengthUnit;
    use crate::io::input::{CenterlinePolyline, Centerlines};
    use crate::stages::centerline::extract::{EndKind, VesselEnd};
    use crate::stages::centerline::CenterlineTree;
    use nalgebra::Point3;

    #[test]
    fn an_end_no_branch_reaches_is_reported_and_named() {
        // A straight vessel along z from 0 to 30 (radius 2) meshed; a third end off to the side.
        let points: Vec<Point3<f64>> = (0..=60).map(|i| Point3::new(0.0, 0.0, 0.5 * i as f64)).collect();
        let line = CenterlinePolyline {
            radii: Some(vec![2.0; points.len()]),
            points,
            normals: None,
            cell_tags: Default::default(),
        };
        let centerlines = Centerlines { polylines: vec![line], source: "straight".into() };
        let tree = CenterlineTree::build(&centerlines, &MeshConfig::default().centerline, None).unwrap();
        let end = |x: f64, z: f64, kind| VesselEnd { centre: Point3::new(x, 0.0, z), radius: 2.0, kind };
        let ends = [end(0.0, 0.0, EndKind::Open), end(0.0, 31.0, EndKind::Dome), end(20.0, 15.0, EndKind::Open)];
        let reports = end_reports(&ends, &[true, false, false], &tree, &[], 1.0);
        let meshed: Vec<bool> = reports.iter().map(|e| e.meshed).collect();
        assert_eq!(meshed, [true, true, false]);
        assert!(reports[0].inlet && !reports[1].inlet && reports[1].kind == "dome");
        let warnings = ends_not_meshed(&reports, &[], LengthUnit::Mm);
        assert_eq!(warnings.len(), 1);
        assert!(warnings[0].kind == "end_not_meshed" && warnings[0].message.contains("(20.000, 0.000, 15.000) mm"));
        assert!(warnings[0].message.contains("--ends"), "{}", warnings[0].message);
        // An end whose branch was left out, too short for its junction, is said so instead.
        let left_out = super::ends_left_out(&ends, &[[19.0, 0.5, 14.0]]);
        assert_eq!(left_out, [false, false, true]);
        let warnings = ends_not_meshed(&reports, &left_out, LengthUnit::Mm);
        assert!(warnings[0].message.contains("too close to its junction"), "{}", warnings[0].message);
        assert!(!warnings[0].message.contains("--ends"), "{}", warnings[0].message);
    }
}
