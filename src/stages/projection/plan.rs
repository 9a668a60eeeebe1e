//! The projection stage as a whole: a tree's junctions laid out and its branches planned
//! (frames turned to meet the junctions' folds, end sections turned into flat caps), then each
//! branch's sections projected onto the surface ([`project_tree`]).

use crate::data::config::MeshConfig;
use crate::data::error::{Error, Result};
use crate::geometry::surface::LumenSurface;
use crate::stages::centerline::{Branch, CenterlineSample, CenterlineTree};
use crate::stages::junction::blocks::SectionTemplate;
use crate::stages::junction::{
    allowed_turns, analyse_junctions, check_junction_spacing, keep_fold_cores_inside, signed_angle, twist_frames,
    FoldEnd, JunctionGeometry, LayoutPolicy,
};
use crate::stages::projection::end_planes::EndCaps;
use crate::stages::projection::{
    clear_transition_length, project_branch, JunctionEnd, ProjectedBranch, ProjectionSetup, MIN_ORDINARY_STRETCH,
};
use nalgebra::Point3;

/// A branch ready for projection: its frames turned to meet its junctions' folds, and what
/// lies at each end (junction, fold, transition length).
pub struct BranchPlan {
    pub branch: Branch,
    /// The flat caps its end sections were turned into.
    pub caps: EndCaps,
    pub start: Option<(usize, FoldEnd, f64)>,
    pub end: Option<(usize, FoldEnd, f64)>,
}

/// The median of a branch's inscribed radii: its radius near a cap, where the inscribed ball
/// is cut by the cap.
pub fn median_radius(branch: &Branch) -> f64 {
    let mut radii: Vec<f64> = branch.samples.iter().map(|s| s.radius).collect();
    radii.sort_by(f64::total_cmp);
    radii[radii.len() / 2]
}

/// Turns every branch's frames so that its template lies on the folds of its junctions: a
/// constant turn when one end meets a junction; between two junctions, the nearest quarter turn
/// at the downstream one and the rest spread linearly along the branch.
///
/// `setup_of(b)` is branch b's projection set-up (its own template).
pub fn plan_branches<'a>(
    tree: &CenterlineTree,
    junctions: &[JunctionGeometry],
    setup_of: &dyn Fn(usize) -> ProjectionSetup<'a>,
) -> Result<Vec<BranchPlan>> {
    tree.branches
        .iter()
        .enumerate()
        .map(|(b, branch)| {
            let setup = &setup_of(b);
            let mut branch = branch.clone();
            let radius = median_radius(&branch);
            let caps = crate::stages::projection::end_planes::turn_to_caps(&mut branch, setup.surface, radius);
            let len = branch.length();
            let at_junction = |j: Option<usize>, at_start: bool| -> Result<Option<(usize, usize, Option<f64>)>> {
                j.map(|j| {
                    let g = &junctions[j];
                    let slot = g.slot_of(b);
                    Ok((j, slot, clear_transition_length(g, slot, &branch, at_start, setup)?))
                })
                .transpose()
            };
            let mut start = at_junction(branch.start_junction, true)?;
            let mut end = at_junction(branch.end_junction, false)?;
            // A bridge (no clear section near one of its junctions, or too little room left
            // between the two for ordinary sections): each junction takes half the branch and
            // projection sweeps it from fold to fold.
            if let (Some(a), Some(b)) = (&mut start, &mut end) {
                let room = match (a.2, b.2) {
                    (Some(x), Some(y)) => len - x - y,
                    _ => 0.0,
                };
                let ends = branch.samples[0].radius + branch.samples[branch.samples.len() - 1].radius;
                if room < MIN_ORDINARY_STRETCH * ends {
                    (a.2, b.2) = (Some(0.5 * len), Some(0.5 * len));
                }
            }
            let start =
                start.map(|(j, slot, l)| (j, slot, l.expect("only a branch between two junctions is a bridge")));
            let end = end.map(|(j, slot, l)| (j, slot, l.expect("only a branch between two junctions is a bridge")));
            let turn_needed = |s: f64, j: usize, q: u8| {
                let f = branch.at(s).frame;
                let want = junctions[j].fold_normal(junctions[j].slot_of(b), &f.tangent, q);
                signed_angle(&f.normal, &want, &f.tangent)
            };
            let s0 = start.map_or(0.0, |(_, _, l)| l);
            let s1 = end.map_or(len, |(_, _, l)| len - l);
            let phi0 = start.map(|(j, _, _)| turn_needed(s0, j, 0));
            let (phi1, q_end) = match end {
                None => (None, 0),
                Some((j, _, _)) => {
                    let base = phi0.unwrap_or(0.0);
                    let q = if phi0.is_some() {
                        allowed_turns(setup.template)
                            .iter()
                            .copied()
                            .min_by(|&a, &b| {
                                let d = |q| {
                                    (turn_needed(s1, j, q) - base + std::f64::consts::PI)
                                        .rem_euclid(std::f64::consts::TAU)
                                        - std::f64::consts::PI
                                };
                                d(a).abs().total_cmp(&d(b).abs())
                            })
                            .unwrap()
                    } else {
                        0
                    };
                    let raw = turn_needed(s1, j, q);
                    let unwrapped = base + (raw - base + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                        - std::f64::consts::PI;
                    (Some(unwrapped), q)
                }
            };
            match (phi0, phi1) {
                (Some(a), Some(e)) => twist_frames(&mut branch, s0, a, s1, e),
                (Some(a), None) => twist_frames(&mut branch, s0, a, s1, a),
                (None, Some(e)) => twist_frames(&mut branch, s0, e, s1, e),
                (None, None) => {}
            }
            Ok(BranchPlan {
                branch,
                caps,
                start: start.map(|(j, slot, l)| (j, FoldEnd::at(&junctions[j], slot, 0), l)),
                end: end.map(|(j, slot, l)| (j, FoldEnd::at(&junctions[j], slot, q_end), l)),
            })
        })
        .collect()
}

/// Which branches end blind in a saccular aneurysm's sac (see [`ends_in_sac`]), each renamed
/// for it: "sac", or "sac_1", "sac_2", ... when there are several (see [`crate::geometry::mesh::is_sac`]).
pub fn name_sacs(tree: &mut CenterlineTree, sacs_mm: &[[f64; 3]]) -> Vec<bool> {
    let sacs: Vec<bool> = tree.branches.iter().map(|b| ends_in_sac(b, sacs_mm)).collect();
    let count = sacs.iter().filter(|&&s| s).count();
    for (k, b) in (0..sacs.len()).filter(|&b| sacs[b]).enumerate() {
        tree.branches[b].name = if count == 1 { "sac".to_string() } else { format!("sac_{}", k + 1) };
    }
    sacs
}

/// Whether a branch ends blind in a saccular aneurysm's sac: no junction at its end, which lies
/// within its radius of one of the sacs' points (see [`crate::data::config::CenterlineConfig::sacs_mm`]).
pub fn ends_in_sac(branch: &crate::stages::centerline::Branch, sacs_mm: &[[f64; 3]]) -> bool {
    let Some(last) = branch.samples.last() else { return false };
    branch.end_junction.is_none() && sacs_mm.iter().any(|p| (Point3::from(*p) - last.point).norm() <= last.radius)
}

/// A tree's blocks projected onto the surface: its junctions, each branch's cross-section
/// template, its plan (frames turned to meet its junctions' folds) and its projected sections.
pub struct ProjectedTree {
    pub junctions: Vec<JunctionGeometry>,
    pub templates: Vec<SectionTemplate>,
    pub plans: Vec<BranchPlan>,
    pub projected: Vec<ProjectedBranch>,
}

/// Analyses a tree's junctions and projects its branches' sections onto the surface (the
/// branches ending in a sac renamed for it). `steep_short_branches`: see
/// [`ProjectionSetup::steep_short_branches`].
pub fn project_tree(
    tree: &mut CenterlineTree,
    lumen_surface: &LumenSurface,
    config: &MeshConfig,
    normals_outward: bool,
    steep_short_branches: bool,
    policy: &LayoutPolicy,
) -> Result<ProjectedTree> {
    let l = &config.lumen;
    let mut junctions = analyse_junctions(tree, lumen_surface, policy)?;
    if !policy.overlaps_meshed {
        check_junction_spacing(tree, &junctions, lumen_surface)?;
    }
    if !junctions.is_empty() && !l.core_elements.is_multiple_of(2) {
        return Err(Error::Config(format!(
            "lumen.core_elements = {} is odd: a branching vessel needs an even number (the junction's spine runs \
             along the middle grid line of the core); use {}",
            l.core_elements,
            l.core_elements + 1
        )));
    }
    // Every fold splits the square O-grid of the settings along its middle row and column.
    keep_fold_cores_inside(&mut junctions, l.core_size, lumen_surface);
    let templates: Vec<SectionTemplate> = (0..tree.branches.len())
        .map(|_| SectionTemplate::rect(l.core_elements, l.core_elements, l.core_size, l.ray_reach))
        .collect();
    let sacs = name_sacs(tree, &config.centerline.sacs_mm);
    let spacing = |s: &CenterlineSample| l.axial_spacing_mm.unwrap_or(l.axial_spacing * s.radius);
    let junction_spacing = |s: &CenterlineSample| l.junction_axial_spacing.map_or_else(|| spacing(s), |k| k * s.radius);
    let setup_of = |b: usize| ProjectionSetup {
        template: &templates[b],
        surface: lumen_surface,
        spacing: &spacing,
        junction_spacing: &junction_spacing,
        trim_inlet: config.centerline.trim_inlet,
        trim_outlet: config.centerline.trim_outlet,
        normals_outward,
        steep_short_branches,
        dome_end: sacs[b],
    };
    let plans = plan_branches(tree, &junctions, &setup_of)?;
    let projected: Vec<ProjectedBranch> = plans
        .iter()
        .enumerate()
        .map(|(b, plan)| {
            let end = |e: &Option<(usize, FoldEnd, f64)>| {
                e.map(|(j, fold, length)| JunctionEnd { geometry: &junctions[j], fold, transition_length: length })
            };
            let (start, finish) = (end(&plan.start), end(&plan.end));
            project_branch(&plan.branch, &plan.caps, b, &setup_of(b), start.as_ref(), finish.as_ref())
        })
        .collect::<Result<_>>()?;
    Ok(ProjectedTree { junctions, templates, plans, projected })
}
