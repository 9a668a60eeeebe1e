//! The `mesh` job: read, model the centerline, project the blocks, build the volume, annotate,
//! measure and write. One function per stage boundary, data flowing forward only.

use crate::accuracy::surface_accuracy;
use crate::annotate::annotate;
use crate::blocks::{graded_levels, growth_ratio_for_first_cell, SectionTemplate};
use crate::centerline::{Branch, CenterlineSample};
use crate::centerline::{CenterlineTree, ForcedMerge};
use crate::centerline_extract::names_of_ends;
use crate::centerline_extract::{EndKind, VesselEnd};
use crate::config::{MeshConfig, WallGrowth};
use crate::end_names::{mesh_ends_at, name_mesh_ends};
use crate::end_planes::EndCaps;
use crate::error::{Error, Result};
use crate::input::{
    clean_surface, read_centerlines_within, read_surface_parts, read_surface_within, surface_files, Centerlines,
    HygieneReport, NamedCap, ReadLimits, TriangleSurface,
};
use crate::junction::{
    allowed_turns, analyse_junctions, check_junction_spacing, find_junction_overlap, keep_fold_cores_inside,
    signed_angle, twist_frames, unanalysable_close_junction, FoldEnd, JunctionGeometry, LayoutPolicy,
};
use crate::junction_finish::{finish_junctions, FinishQuality};
use crate::mesh::VesselMesh;
use crate::output::OutputFolder;
use crate::progress::Progress;
use crate::projection::{clear_transition_length, project_branch, JunctionEnd, ProjectedBranch, ProjectionSetup};
use crate::quality::Stats;
use crate::report::{
    bar_warnings, lumen_report, wall_report, BranchReport, EndReport, InputReport, JunctionReport, Report, Warning,
};
use crate::resources::short;
use crate::side_ends::SideOpening;
use crate::surface::LumenSurface;
use crate::units::LengthUnit;
use crate::volume::{JunctionWall, RadialLevels, VolumeInputs};
use crate::writers::{self, WriteOptions};
use nalgebra::Point3;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

pub use crate::meshed::Meshed;

/// A branch ready for projection: its frames turned to meet its junctions' folds, and what
/// lies at each end (junction, fold, transition length).
struct BranchPlan {
    branch: Branch,
    /// The flat caps its end sections were turned into.
    caps: EndCaps,
    start: Option<(usize, FoldEnd, f64)>,
    end: Option<(usize, FoldEnd, f64)>,
}

/// The median of a branch's inscribed radii: its radius near a cap, where the inscribed ball
/// is cut by the cap.
fn median_radius(branch: &Branch) -> f64 {
    let mut radii: Vec<f64> = branch.samples.iter().map(|s| s.radius).collect();
    radii.sort_by(f64::total_cmp);
    radii[radii.len() / 2]
}

/// Turns every branch's frames so that its template lies on the folds of its junctions: a
/// constant turn when one end meets a junction; between two junctions, the nearest quarter turn
/// at the downstream one and the rest spread linearly along the branch.
///
/// `setup_of(b)` is branch b's projection set-up (its own template).
fn plan_branches<'a>(
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
            let caps = crate::end_planes::turn_to_caps(&mut branch, setup.surface, radius);
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

/// Least stretch of ordinary sections between two junctions' transitions, in end radii (the
/// sum of the branch's two end radii); less, and the branch is a bridge.
const MIN_ORDINARY_STRETCH: f64 = 0.25;

/// Radius and surface distance must agree to within this factor, or the units differ.
const UNIT_MISMATCH_FACTOR: f64 = 8.0;

/// Checks that the centerline radius matches the distance from the centerline to the surface;
/// a factor of 10, 100 or 1000 means the two files are in different units.
fn check_units(surface: &LumenSurface, tree: &CenterlineTree, centerline_source: &Path) -> Result<()> {
    let samples: Vec<(Point3<f64>, f64)> = tree
        .branches
        .iter()
        .flat_map(|b| b.samples.iter().step_by((b.samples.len() / 50).max(1)))
        .map(|s| (s.point, s.radius))
        .collect();
    check_radius_against_surface(surface, &samples, centerline_source)
}

/// [`check_units`] and a coarse [`check_inside`] on the centerline file's own points, before
/// the tree is built: a branched vessel's junctions are analysed with the tree, and centerlines
/// in the wrong units (or another vessel's) would be refused there for a junction's shape, not
/// for what is wrong.
fn check_centerline_file(surface: &LumenSurface, centerlines: &Centerlines) -> Result<()> {
    let source = &centerlines.source;
    // Points from the middle four fifths of each polyline (open ends may lie outside).
    let probes: Vec<(Point3<f64>, Option<f64>)> = centerlines
        .polylines
        .iter()
        .flat_map(|l| {
            let n = l.points.len();
            (1..=8).map(move |k| {
                let i = (n - 1) * (1 + k) / 10;
                (l.points[i], l.radii.as_ref().map(|r| r[i]))
            })
        })
        .collect();
    let step = (probes.len() / 64).max(1);
    let probes: Vec<_> = probes.into_iter().step_by(step).collect();
    let samples: Vec<(Point3<f64>, f64)> =
        probes.iter().filter_map(|(p, r)| r.filter(|r| *r > 0.0).map(|r| (*p, r))).collect();
    if !samples.is_empty() {
        check_radius_against_surface(surface, &samples, source)?;
    }
    let outside: Vec<&Point3<f64>> = probes
        .par_iter()
        .filter(|(p, _)| surface.winding_number(p).abs() < INSIDE_WINDING)
        .map(|(p, _)| p)
        .collect::<Vec<_>>();
    if 2 * outside.len() > probes.len() {
        check_winding(surface)?;
        let p = outside[0];
        let points = centerlines.polylines.iter().flat_map(|l| l.points.iter());
        let spans = extent(points) / extent(surface.vertices.iter());
        let scale = if !(0.25..=4.0).contains(&spans) {
            format!(" (it spans {} times the surface's extent)", short(spans))
        } else {
            String::new()
        };
        return Err(Error::input(
            source,
            format!(
                "most of the centerline lies outside the lumen surface {} ({} of {} points probed, e.g. ({:.3}, \
                 {:.3}, {:.3}) mm){scale}: the files are in different units or coordinate systems (--units, \
                 --centerline-units), or the centerline is not this vessel's",
                surface.source.display(),
                outside.len(),
                probes.len(),
                p.x,
                p.y,
                p.z
            ),
        ));
    }
    Ok(())
}

/// The diagonal of the points' bounding box.
fn extent<'a>(points: impl Iterator<Item = &'a Point3<f64>>) -> f64 {
    let (mut lo, mut hi) = (Point3::from([f64::INFINITY; 3]), Point3::from([f64::NEG_INFINITY; 3]));
    for p in points {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    (hi - lo).norm()
}

/// The median of distance to the surface over radius at `samples` (point, radius) must be
/// within [`UNIT_MISMATCH_FACTOR`] of 1.
fn check_radius_against_surface(
    surface: &LumenSurface,
    samples: &[(Point3<f64>, f64)],
    centerline_source: &Path,
) -> Result<()> {
    let mut ratios: Vec<f64> = samples.par_iter().map(|(p, r)| surface.closest(p).distance / r).collect();
    ratios.sort_by(f64::total_cmp);
    let median = ratios[ratios.len() / 2];
    if !(median < UNIT_MISMATCH_FACTOR && median > 1.0 / UNIT_MISMATCH_FACTOR) {
        let factor = if median >= 1.0 { median } else { 1.0 / median };
        return Err(Error::input(
            centerline_source,
            format!(
                "the centerline radius and the distance from the centerline to the surface {} differ by a factor of \
                 about {:.0} (median distance/radius = {median:.3e}): the two files are not in the same units, or \
                 the centerline is not this vessel's. Give each file's unit (--units for the surface, \
                 --centerline-units for the centerline)",
                surface.source.display(),
                factor
            ),
        ));
    }
    Ok(())
}

/// Winding numbers below this (in magnitude) mean a point is outside the lumen.
const INSIDE_WINDING: f64 = 0.5;

/// Checks that the centerline runs inside the lumen and finds which way the surface's triangles
/// face (true: out of the lumen), from winding numbers at points along the centerline. The
/// first and last tenth of each branch and a radius next to an open end are left out: near an
/// open end the winding number drops towards 1/2 (measured on the gmsh arch: 0.25 at the end
/// point, 0.5 about 0.7 radius inside).
fn check_inside(surface: &LumenSurface, tree: &CenterlineTree, centerline_source: &Path) -> Result<bool> {
    // Also at least a radius from an open end (a short wide branch's tenth is not enough).
    let tenths = tree
        .branches
        .iter()
        .flat_map(|b| (0..=20).map(move |i| (b, &b.samples[(b.samples.len() - 1) * (2 + i * 16 / 20) / 20])));
    let away = |(b, s): &(&crate::centerline::Branch, &crate::centerline::CenterlineSample)| {
        (b.start_junction.is_some() || s.s > s.radius) && (b.end_junction.is_some() || b.length() - s.s > s.radius)
    };
    let mut probes: Vec<&crate::centerline::CenterlineSample> = tenths.clone().filter(away).map(|(_, s)| s).collect();
    if probes.is_empty() {
        probes = tenths.map(|(_, s)| s).collect();
    }
    let w: Vec<f64> = probes.par_iter().map(|s| surface.winding_number(&s.point)).collect();
    let total: f64 = w.iter().sum();
    if let Some((k, wk)) = w.iter().enumerate().find(|(_, x)| x.abs() < INSIDE_WINDING) {
        let outside = w.iter().filter(|x| x.abs() < INSIDE_WINDING).count();
        check_winding(surface)?;
        let p = probes[k];
        return Err(Error::input(
            centerline_source,
            format!(
                "the centerline lies outside the lumen surface {} at ({:.3}, {:.3}, {:.3}) mm, {:.2} mm along it \
                 (winding number {wk:.2}; {outside} of {} probed points are outside): check that the centerline \
                 belongs to this surface and that both are in the same units and coordinate system",
                surface.source.display(),
                p.point.x,
                p.point.y,
                p.point.z,
                p.s,
                w.len()
            ),
        ));
    }
    Ok(total > 0.0)
}

/// Refuses a surface whose triangles are not wound consistently: its winding numbers cannot
/// tell inside from outside, so a centerline found "outside" may not be.
fn check_winding(surface: &LumenSurface) -> Result<()> {
    match winding_fault(&surface.triangles) {
        Some((fault, _)) => Err(Error::input(&surface.source, fault)),
        None => Ok(()),
    }
}

/// What is wrong with the triangles' winding, and the share of shared edges it concerns, if
/// some shared edges are run the same way by both their triangles.
fn winding_fault(triangles: &[[u32; 3]]) -> Option<(String, f64)> {
    let (misoriented, shared) = misoriented_edges(triangles);
    (misoriented > 0).then(|| {
        let fault = format!(
            "the surface's triangles are not wound consistently ({misoriented} of its {shared} shared edges are run \
             the same way by both their triangles), so vesselhex cannot tell the lumen's inside from its outside: \
             orient the triangles consistently (e.g. ParaView's Generate Surface Normals with Consistency on, or \
             MeshLab's Re-Orient all faces coherently) and save again"
        );
        (fault, misoriented as f64 / shared as f64)
    })
}

/// Share of a surface's shared edges run the same way by both triangles beyond which a failed
/// run is put down to the winding (a few are non-manifold fins, as in some real surfaces).
const MISWOUND_SHARE: f64 = 0.01;

/// A meshing error on a surface whose triangles are wound inconsistently names the winding
/// first: rays then meet the wall "from outside" and winding numbers mislead, whatever stage
/// stops.
fn name_winding(error: Error, surface: &TriangleSurface) -> Error {
    if matches!(error, Error::Config(_)) {
        return error;
    }
    match winding_fault(&surface.triangles) {
        Some((fault, share)) if share > MISWOUND_SHARE => {
            Error::input(&surface.source, format!("{fault} (meshing stopped: {error})"))
        }
        _ => error,
    }
}

/// Edges of the triangles run the same way by two of them (each triangle of a consistently
/// wound surface runs a shared edge against its neighbour), and the edges two triangles share.
fn misoriented_edges(triangles: &[[u32; 3]]) -> (usize, usize) {
    let mut directed: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
    for t in triangles {
        for k in 0..3 {
            *directed.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
        }
    }
    let misoriented = directed.values().filter(|&&n| n > 1).count();
    let shared = directed.keys().filter(|(a, b)| a < b && directed.contains_key(&(*b, *a))).count() + misoriented;
    (misoriented, shared)
}

/// Meshes a vessel from its surface and centerlines (both already in mm). Two junctions whose
/// blocks would overlap are merged; a vessel with merged junctions, or one refused as asked,
/// has its junctions spaced as at the coarse preset when a finer spacing was asked and none set
/// for them ([`coarser_junctions`]), said in [`Meshed::notes`].
pub fn mesh_vessel(
    surface: &TriangleSurface,
    centerlines: &Centerlines,
    config: &MeshConfig,
    progress: &mut Progress,
) -> Result<Meshed> {
    config.validate()?;
    progress.stage("surface index");
    let lumen_surface = LumenSurface::new(surface)?;
    check_centerline_file(&lumen_surface, centerlines)?;
    // Books first: a straight spine shared by every branch is the best-shaped fold where it
    // orders the branches. A vessel refused so, or short of a bar, with a junction of four or
    // more branches is meshed again with that junction in sectors, and the better mesh kept
    // (the first of equals; judged as a junction's finishes are).
    let books = LayoutPolicy::books_only();
    let meshed = mesh_vessel_laid_out(surface, &lumen_surface, centerlines, config, &books, progress);
    let within_bars = |m: &Meshed| FinishQuality::of_mesh(&m.mesh).meets_bars();
    if meshed.as_ref().is_ok_and(within_bars) || !books.sectors_differ.get() {
        return meshed;
    }
    let sectors = LayoutPolicy::with_sectors();
    let laid_out = mesh_vessel_laid_out(surface, &lumen_surface, centerlines, config, &sectors, progress);
    match (meshed, laid_out) {
        (Ok(a), Ok(b)) => {
            Ok(if FinishQuality::of_mesh(&b.mesh).better_than(&FinishQuality::of_mesh(&a.mesh)) { b } else { a })
        }
        (Ok(a), Err(_)) => Ok(a),
        (Err(_), Ok(b)) => Ok(b),
        (Err(_), Err(e)) => Err(e),
    }
}

/// [`mesh_vessel`] with the junctions' arrangements `policy` allows.
fn mesh_vessel_laid_out(
    surface: &TriangleSurface,
    lumen_surface: &LumenSurface,
    centerlines: &Centerlines,
    config: &MeshConfig,
    policy: &LayoutPolicy,
    progress: &mut Progress,
) -> Result<Meshed> {
    progress.stage("centerline");
    let tree = CenterlineTree::build(centerlines, &config.centerline, Some(lumen_surface))?;
    // A junction no book orders and another within two of its radii are one junction in fact:
    // merged (with sectors allowed too, where the merged junction may be laid out in them).
    let overlap = match analyse_junctions(&tree, lumen_surface, policy) {
        Ok(junctions) => policy
            .sectors
            .then(|| unanalysable_close_junction(&tree, lumen_surface))
            .flatten()
            .or_else(|| find_junction_overlap(&tree, &junctions, lumen_surface)),
        Err(e) => Some(unanalysable_close_junction(&tree, lumen_surface).ok_or(e)?),
    };
    let coarser = coarser_junctions(config, centerlines);
    let Some(overlap) = overlap else {
        let close_merges = tree.close_merges.clone();
        let meshed =
            mesh_tree_recentred(surface, lumen_surface, tree, centerlines, config, &close_merges, policy, progress);
        let (Err(Error::Geometry(refusal)), Some(coarser)) = (&meshed, coarser) else { return meshed };
        let tree = CenterlineTree::build(centerlines, &config.centerline, Some(lumen_surface))?;
        let mut retried =
            mesh_tree_recentred(surface, lumen_surface, tree, centerlines, &coarser, &close_merges, policy, progress)
                .map_err(|_| Error::Geometry(refusal.clone()))?;
        retried.notes.push(junction_spacing_note(
            config,
            &format!("at {} they were refused: {refusal}", config.lumen.axial_spacing),
        ));
        return Ok(retried);
    };
    // Two junctions overlap: they become one, centred on the branch between them. Where along
    // it depends on the branches around (the middle of the merged junction is neither end), so
    // each place of MERGED_CENTRE_AT is meshed and the best mesh kept (judged as a junction's
    // finishes are, on the whole mesh), the first of equals. Its transitions sweep between two
    // junctions' folds, so they are spaced as at the coarse preset (see `coarser_junctions`).
    let merged_config = coarser.as_ref().unwrap_or(config);
    let segment = tree.segments[overlap.branch];
    let mut best: Option<(Meshed, FinishQuality)> = None;
    let mut first_error = None;
    for at in MERGED_CENTRE_AT {
        let attempt = merged_tree(centerlines, merged_config, lumen_surface, segment, at, policy).and_then(|tree| {
            mesh_tree(surface, lumen_surface, tree, &centerlines.source, merged_config, false, policy, progress)
        });
        match attempt {
            Ok(meshed) => {
                let quality = FinishQuality::of_mesh(&meshed.mesh);
                let meets_bars = quality.meets_bars();
                if best.as_ref().is_none_or(|(_, b)| quality.better_than(b)) {
                    best = Some((meshed, quality));
                }
                // The first place within the bars is kept: each costs a whole mesh.
                if meets_bars {
                    break;
                }
            }
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    match (best, first_error) {
        (Some((mut meshed, _)), _) => {
            if coarser.is_some() {
                let why = format!(
                    "{} were merged into one junction, as their blocks would overlap, and a merged junction's \
                     transitions sweep between both junctions' folds, where thinner sections cross (set \
                     lumen.junction_axial_spacing to space them otherwise)",
                    overlap.place
                );
                meshed.notes.push(junction_spacing_note(config, &why));
            }
            Ok(meshed)
        }
        (None, Some(e)) => {
            let tried = format!(
                "(vesselhex merged {} into one junction there, as their blocks would overlap, and tried centring it \
                 {} of the way along the branch between them; none meshed)",
                overlap.place,
                MERGED_CENTRE_AT.map(|a| a.to_string()).join(", ")
            );
            Err(match e {
                Error::ShortBranch { message, end_mm } => {
                    Error::ShortBranch { message: format!("{message} {tried}"), end_mm }
                }
                e => Error::Geometry(format!("{e} {tried}")),
            })
        }
        (None, None) => unreachable!("every place was tried"),
    }
}

/// The coarse preset's axial spacing, relative to the radius: what [`coarser_junctions`] spaces
/// the junctions at.
const COARSE_JUNCTION_SPACING: f64 = 0.5;

/// The settings with a branched vessel's junction transitions and bridges spaced at the coarse
/// preset's spacing (the rest as asked), when they ask a finer spacing relative to the radius
/// and none for the junctions; None otherwise. [`mesh_vessel`] meshes with them a vessel whose
/// junctions were merged (their transitions sweep between two junctions' folds over a spine up
/// to twice as long) and one refused with the settings as given. A transition's sections are
/// swept between curved folds, not cut by planes, and thin ones cross each other:
/// sphinxsys_aortic_arch at medium (0.3 radii) had 285 elements inverted around its arch's
/// bridge, and 0.4 and 0.45 were refused too; at 0.5 it meets the bars, and the two Gmsh arches
/// (merged junctions too) stay within them in about half the time (0.90 -> 0.43 s, 2.25 -> 1.28 s).
fn coarser_junctions(config: &MeshConfig, centerlines: &Centerlines) -> Option<MeshConfig> {
    let l = &config.lumen;
    let finer = centerlines.polylines.len() > 1
        && l.junction_axial_spacing.is_none()
        && l.axial_spacing_mm.is_none()
        && l.axial_spacing < COARSE_JUNCTION_SPACING;
    finer.then(|| {
        let lumen = crate::config::LumenConfig { junction_axial_spacing: Some(COARSE_JUNCTION_SPACING), ..l.clone() };
        MeshConfig { lumen, ..config.clone() }
    })
}

/// The `junction_spacing` warning: the junctions spaced at the coarse preset's spacing, `why`.
fn junction_spacing_note(config: &MeshConfig, why: &str) -> Warning {
    Warning::new(
        "junction_spacing",
        format!(
            "the junctions' transitions and bridges are spaced at {COARSE_JUNCTION_SPACING} radii (the coarse \
             preset's; lumen.junction_axial_spacing), the rest of the vessel at {} as asked: {why}",
            config.lumen.axial_spacing
        ),
    )
}

/// A tree meshed ([`mesh_tree`]); one whose close junctions were merged and whose mesh is short
/// of a bar or refused is meshed again with them centred elsewhere ([`recentre_close_merges`]).
fn mesh_tree_recentred(
    surface: &TriangleSurface,
    lumen_surface: &LumenSurface,
    tree: CenterlineTree,
    centerlines: &Centerlines,
    config: &MeshConfig,
    close_merges: &[usize],
    policy: &LayoutPolicy,
    progress: &mut Progress,
) -> Result<Meshed> {
    let meshed = mesh_tree(surface, lumen_surface, tree, &centerlines.source, config, true, policy, progress);
    if close_merges.is_empty() || meshed.as_ref().is_ok_and(|m| FinishQuality::of_mesh(&m.mesh).meets_bars()) {
        return meshed;
    }
    recentre_close_merges(surface, lumen_surface, centerlines, config, meshed, close_merges, policy, progress)
}

/// Which branches end blind in a saccular aneurysm's sac (see [`ends_in_sac`]), each renamed
/// for it: "sac", or "sac_1", "sac_2", ... when there are several (see [`crate::mesh::is_sac`]).
fn name_sacs(tree: &mut CenterlineTree, sacs_mm: &[[f64; 3]]) -> Vec<bool> {
    let sacs: Vec<bool> = tree.branches.iter().map(|b| ends_in_sac(b, sacs_mm)).collect();
    let count = sacs.iter().filter(|&&s| s).count();
    for (k, b) in (0..sacs.len()).filter(|&b| sacs[b]).enumerate() {
        tree.branches[b].name = if count == 1 { "sac".to_string() } else { format!("sac_{}", k + 1) };
    }
    sacs
}

/// Whether a branch ends blind in a saccular aneurysm's sac: no junction at its end, which lies
/// within its radius of one of the sacs' points (see [`crate::config::CenterlineConfig::sacs_mm`]).
fn ends_in_sac(branch: &crate::centerline::Branch, sacs_mm: &[[f64; 3]]) -> bool {
    let Some(last) = branch.samples.last() else { return false };
    branch.end_junction.is_none() && sacs_mm.iter().any(|p| (Point3::from(*p) - last.point).norm() <= last.radius)
}

/// A tree whose close junctions were merged (see `CenterlineConfig::junction_merge_radii`),
/// short of a bar or refused with the merged junctions at their upstream centres: each place of
/// [`MERGED_CENTRE_AT`] along the merged segments is meshed, and the best mesh kept (`meshed`,
/// the first, wins ties), as for overlapping junctions. gmsh_cerebral_aneurysm at medium, its
/// sac leaving where a side branch does: 0.187 at the upstream centre, 0.240 at 5/8.
fn recentre_close_merges(
    surface: &TriangleSurface,
    lumen_surface: &LumenSurface,
    centerlines: &Centerlines,
    config: &MeshConfig,
    meshed: Result<Meshed>,
    close_merges: &[usize],
    policy: &LayoutPolicy,
    progress: &mut Progress,
) -> Result<Meshed> {
    let mut best = meshed.as_ref().ok().map(|m| FinishQuality::of_mesh(&m.mesh));
    let mut kept = meshed;
    for at in MERGED_CENTRE_AT {
        let forced: Vec<ForcedMerge> = close_merges.iter().map(|&segment| ForcedMerge { segment, at }).collect();
        let attempt = CenterlineTree::build_merging(centerlines, &config.centerline, Some(lumen_surface), &forced)
            .and_then(|tree| {
                mesh_tree(surface, lumen_surface, tree, &centerlines.source, config, false, policy, progress)
            });
        let Ok(meshed) = attempt else { continue };
        let quality = FinishQuality::of_mesh(&meshed.mesh);
        if best.as_ref().is_none_or(|b| quality.better_than(b)) {
            let meets_bars = quality.meets_bars();
            (best, kept) = (Some(quality), Ok(meshed));
            // The first place within the bars is kept: each costs a whole mesh.
            if meets_bars {
                break;
            }
        }
    }
    kept
}

/// Where the junction merged from two overlapping ones is centred: fractions of the branch
/// between them from the upstream one. Measured on gmsh_aortic_arch (the brachiocephalic-carotid
/// trunk, whose arch-side crotch lies past its far end): all three mesh at the coarse preset,
/// only 7/8 at the medium one, 1/2 at neither.
const MERGED_CENTRE_AT: [f64; 3] = [0.625, 0.75, 0.875];

/// At most this many pairs of overlapping junctions are merged in one vessel.
const MAX_FORCED_MERGES: usize = 4;

/// The tree with the junction at the end of `segment` merged into the upstream one (centred
/// the fraction `at` along it), and any pair that overlaps after that merged too.
fn merged_tree(
    centerlines: &Centerlines,
    config: &MeshConfig,
    surface: &LumenSurface,
    segment: usize,
    at: f64,
    policy: &LayoutPolicy,
) -> Result<CenterlineTree> {
    let mut forced = vec![ForcedMerge { segment, at }];
    loop {
        let tree = CenterlineTree::build_merging(centerlines, &config.centerline, Some(surface), &forced)?;
        let junctions = analyse_junctions(&tree, surface, policy)?;
        let Some(overlap) = find_junction_overlap(&tree, &junctions, surface) else { return Ok(tree) };
        let next = tree.segments[overlap.branch];
        if forced.len() >= MAX_FORCED_MERGES || forced.iter().any(|f| f.segment == next) {
            return Err(overlap.error);
        }
        forced.push(ForcedMerge { segment: next, at });
    }
}

/// A tree's blocks projected onto the surface: its junctions, each branch's cross-section
/// template, its plan (frames turned to meet its junctions' folds) and its projected sections.
struct ProjectedTree {
    junctions: Vec<JunctionGeometry>,
    templates: Vec<SectionTemplate>,
    plans: Vec<BranchPlan>,
    projected: Vec<ProjectedBranch>,
}

/// Analyses a tree's junctions and projects its branches' sections onto the surface (the
/// branches ending in a sac renamed for it). `steep_short_branches`: see
/// [`ProjectionSetup::steep_short_branches`].
fn project_tree(
    tree: &mut CenterlineTree,
    lumen_surface: &LumenSurface,
    config: &MeshConfig,
    normals_outward: bool,
    steep_short_branches: bool,
    policy: &LayoutPolicy,
) -> Result<ProjectedTree> {
    let l = &config.lumen;
    let mut junctions = analyse_junctions(tree, lumen_surface, policy)?;
    check_junction_spacing(tree, &junctions, lumen_surface)?;
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
    let spacing = |s: &crate::centerline::CenterlineSample| l.axial_spacing_mm.unwrap_or(l.axial_spacing * s.radius);
    let junction_spacing =
        |s: &crate::centerline::CenterlineSample| l.junction_axial_spacing.map_or_else(|| spacing(s), |k| k * s.radius);
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

/// Meshes a vessel from its indexed surface and its centerline tree (both in mm).
/// `steep_short_branches`: see [`ProjectionSetup::steep_short_branches`].
pub fn mesh_tree(
    surface: &TriangleSurface,
    lumen_surface: &LumenSurface,
    mut tree: CenterlineTree,
    centerline_source: &Path,
    config: &MeshConfig,
    steep_short_branches: bool,
    policy: &LayoutPolicy,
    progress: &mut Progress,
) -> Result<Meshed> {
    check_units(lumen_surface, &tree, centerline_source)?;
    let normals_outward = check_inside(lumen_surface, &tree, centerline_source)?;

    progress.stage("projection");
    let ProjectedTree { junctions, templates, plans, projected } =
        project_tree(&mut tree, lumen_surface, config, normals_outward, steep_short_branches, policy)?;

    progress.stage("volume");
    let l = &config.lumen;
    let ratio = match l.first_cell_height {
        Some(h) => growth_ratio_for_first_cell(l.radial_elements, h),
        None => l.growth_ratio,
    };
    let layers = config.wall.layers();
    let levels = RadialLevels::new(graded_levels(l.radial_elements, ratio), &layers);
    let w = &config.wall;
    let thickness = |r: f64| w.thickness_mm.unwrap_or(w.thickness_ratio * r);
    let names: Vec<String> = tree.branches.iter().map(|b| b.name.clone()).collect();
    let inputs = VolumeInputs {
        projected: &projected,
        templates: &templates,
        junctions: &junctions,
        levels: &levels,
        layers: &layers,
        wall_thickness: &thickness,
        wall_growth: w.growth,
        branch_names: &names,
        surface: lumen_surface,
    };
    let (mut mesh, junction_of, junction_variant) = finish_junctions(&inputs);

    progress.stage("annotation");
    annotate(&mut mesh);
    crate::sacs::mark_junction_sacs(&mut mesh, &junction_of, &junctions, &tree);
    refuse_inverted(&mesh, &junction_of, &junctions, &tree, surface)?;

    progress.stage("surface accuracy");
    let aligned: Vec<Branch> = plans.into_iter().map(|p| p.branch).collect();
    let accuracy = surface_accuracy(&mesh, lumen_surface, &aligned, &projected)?;
    Ok(Meshed { mesh, tree, projected, accuracy, templates, junctions, junction_of, junction_variant, notes: vec![] })
}

/// Refuses a mesh with an inverted element, naming the worst (a degenerate one first), where
/// it is (its junction, and why a junction folds) and how many are inverted in all: the first
/// by number can be a near miss beside a fold hundreds of elements wide.
fn refuse_inverted(
    mesh: &VesselMesh,
    junction_of: &[Option<usize>],
    junctions: &[JunctionGeometry],
    tree: &CenterlineTree,
    surface: &TriangleSurface,
) -> Result<()> {
    let inverted = |q: f64| q.is_nan() || q <= 0.0;
    let count = mesh.quality.iter().filter(|q| inverted(q.scaled_jacobian)).count();
    let rank = |q: f64| if q.is_nan() { f64::NEG_INFINITY } else { q };
    if let Some((e, q)) = mesh
        .quality
        .iter()
        .enumerate()
        .filter(|(_, q)| inverted(q.scaled_jacobian))
        .min_by(|a, b| rank(a.1.scaled_jacobian).total_cmp(&rank(b.1.scaled_jacobian)))
    {
        let c = crate::mesh::face_centre(&mesh.corners(e), 0);
        let (place, cause) = match junction_of[e] {
            Some(j) => (
                format!(", in {},", junctions[j].describe(tree)),
                junctions[j].fold_cause(tree, mesh.branch_of[e] as usize),
            ),
            None => (
                String::new(),
                "the vessel bends too sharply for the cross-sections, or the wall is too thick there. Increase \
                 centerline.smoothing_passes, reduce wall.thickness_ratio or lumen.axial_spacing"
                    .to_string(),
            ),
        };
        return Err(Error::Geometry(format!(
            "{}: element {} ({}) near ({:.3}, {:.3}, {:.3}) mm{place} is inverted (scaled Jacobian {:.3}; {count} \
             inverted in all): {cause}",
            surface.source.display(),
            e + 1,
            mesh.regions[e].name(),
            c.x,
            c.y,
            c.z,
            q.scaled_jacobian
        )));
    }
    Ok(())
}

/// Everything `vesselhex mesh` was asked.
#[derive(Debug, Clone)]
pub struct MeshRequest {
    /// The surface: a file, or a folder of the wall and its caps (see [`crate::input::surface_files`]).
    pub surface: PathBuf,
    /// Caps in files of their own (`--cap NAME=FILE`), each naming its end.
    pub caps: Vec<(String, PathBuf)>,
    pub centerlines: Option<PathBuf>,
    /// Unit of the centerline file when it differs from the surface's.
    pub centerline_units: Option<crate::units::LengthUnit>,
    /// How to compute the centerlines when none are given (inlet, extra ends).
    pub extraction: crate::centerline_extract::ExtractOptions,
    pub config: MeshConfig,
    /// The case file the configuration came from, if any (an input like the others: never in a
    /// folder the run replaces).
    pub case_file: Option<PathBuf>,
    pub output: PathBuf,
    /// Replace an output folder vesselhex did not write (see [`crate::output`]).
    pub force: bool,
    /// The memory the run may plan to use: a mesh estimated to need more is refused before it
    /// is built, and files larger than a tenth of it are not read.
    pub max_memory: u64,
    pub quiet: bool,
    /// Zero the timings so that report.json is byte-identical between runs.
    pub reproducible: bool,
    /// Warnings found before the run (on the command line's settings), reported with the rest.
    pub warnings: Vec<Warning>,
}

/// The formats to write, in writing order (those `fsi` implies first), all known.
fn formats_to_write(config: &MeshConfig) -> Result<Vec<&str>> {
    let mut formats: Vec<&str> = config.formats.iter().map(|s| s.as_str()).collect();
    // The FSI package refers to the openfoam and calculix outputs: write them first.
    if let Some(i) = formats.iter().position(|f| *f == "fsi") {
        for implied in ["calculix", "openfoam"] {
            if !formats.contains(&implied) {
                formats.insert(i, implied);
            }
        }
    }
    for f in &formats {
        if writers::writer(f).is_none() {
            return Err(Error::Config(format!(
                "unknown format '{f}' in --formats (known: {})",
                writers::format_names().join(", ")
            )));
        }
    }
    Ok(formats)
}

/// Runs the whole job and returns the report (also written as report.json). The outputs are
/// written beside `--output` and put in its place in one rename at the end (see
/// [`crate::output`]); on any error, nothing is left behind.
pub fn run(request: &MeshRequest) -> Result<Report> {
    let config = &request.config;
    config.validate()?;
    formats_to_write(config)?;
    let inputs: Vec<&Path> = [Some(&request.surface), request.centerlines.as_ref(), request.case_file.as_ref()]
        .into_iter()
        .flatten()
        .chain(request.caps.iter().map(|(_, file)| file))
        .map(PathBuf::as_path)
        .collect();
    let files = surface_files(&request.surface, &request.caps)?;
    crate::finishing::check_wall_surfaces(config)?;
    let output = claim_output(&request.output, &inputs, config, request.force)?;
    let limits = ReadLimits::within(request.max_memory);
    // The stages of `mesh_finished`, and surface hygiene, and the extraction when no centerlines are given.
    let stages = 10 + u64::from(request.centerlines.is_none()) + crate::finishing::stages(config);
    let mut progress = Progress::new(request.quiet, stages);
    progress.stage("reading");
    let (surface, caps) = if files.caps.is_empty() && files.walls.len() == 1 {
        (read_surface_within(&files.walls[0], config.units, &limits)?.0, vec![])
    } else {
        let (surface, _, caps) = read_surface_parts(&files, config.units, &limits)?;
        (surface, caps)
    };
    let centerline_units = request.centerline_units.unwrap_or(config.units);
    let centerlines = match &request.centerlines {
        Some(path) => CenterlineSource::Given(read_centerlines_within(path, centerline_units, &limits)?),
        None => CenterlineSource::Extract(request.extraction.clone()),
    };
    let settings = MeshSettings {
        config: config.clone(),
        centerline_units: request.centerline_units,
        max_memory: request.max_memory,
        warnings: request.warnings.clone(),
        caps,
    };
    let vessel = mesh_surface(surface, centerlines, settings, &mut progress)?;
    write_vessel(&vessel, config, output, request.reproducible, &mut progress)
}

/// Vessel radii (mm) outside which the units are probably wrong: a 50 um arteriole to a 30 mm
/// aneurysm.
const PLAUSIBLE_RADIUS_MM: (f64, f64) = (0.05, 30.0);

/// A warning when the vessel's median radius (mm) is implausible in the units given, naming the
/// unit that would make it plausible.
fn unit_warning(
    radius: f64,
    units: crate::units::LengthUnit,
    centerline_units: Option<crate::units::LengthUnit>,
) -> Option<Warning> {
    use crate::units::LengthUnit;
    let (low, high) = PLAUSIBLE_RADIUS_MM;
    if !radius.is_finite() || (low..=high).contains(&radius) {
        return None;
    }
    let flag = match centerline_units {
        Some(c) if c != units => format!("--units {units} and --centerline-units {c}"),
        _ => format!("--units {units}"),
    };
    // The unit under which the radius is nearest a typical 3 mm artery.
    let in_file = radius / units.to_mm();
    let likely = [LengthUnit::Um, LengthUnit::Mm, LengthUnit::Cm, LengthUnit::M]
        .into_iter()
        .filter(|u| (low..=high).contains(&(in_file * u.to_mm())))
        .min_by(|a, b| {
            let off = |u: &LengthUnit| (in_file * u.to_mm() / 3.0).ln().abs();
            off(a).total_cmp(&off(b))
        });
    let hint = match likely {
        Some(u) => {
            format!("; if the files are in {u}, give --units {u} (a radius of {} mm)", short(in_file * u.to_mm()))
        }
        None => String::new(),
    };
    Some(Warning::new(
        "units",
        format!(
            "the vessel's median radius is {} mm with {flag}, outside the {low}-{high} mm of blood vessels{hint}",
            short(radius)
        ),
    ))
}

/// Refuses absolute lengths out of proportion with the vessel (the relative settings' bounds,
/// applied to the median radius): a wall thicker than twice the radius or thinner than a
/// thousandth of it, an axial spacing below a thousandth of the radius or above ten radii.
fn check_lengths_against_radius(config: &MeshConfig, radius: f64) -> Result<()> {
    if !(radius > 0.0 && radius.is_finite()) {
        return Ok(());
    }
    let check = |key: &str, value: Option<f64>, (low, high): (f64, f64), relative: &str| match value {
        Some(v) if !(v >= low * radius && v <= high * radius) => Err(Error::Config(format!(
            "{key} = {v} mm is {} times the vessel's median radius ({} mm); it must be between {low} and {high} \
             times it (as {relative} is): give it in mm, or check the input's units",
            short(v / radius),
            short(radius)
        ))),
        _ => Ok(()),
    };
    check("wall.thickness_mm", config.wall.thickness_mm, (0.001, 2.0), "wall.thickness_ratio")?;
    let spacing = (crate::config::MIN_AXIAL_SPACING, 10.0);
    check("lumen.axial_spacing_mm", config.lumen.axial_spacing_mm, spacing, "lumen.axial_spacing")
}

fn end_kind(end: &crate::projection::BranchEnd) -> &'static str {
    match end {
        crate::projection::BranchEnd::Vessel { closed: true } => "closed",
        crate::projection::BranchEnd::Vessel { closed: false } => "open",
        crate::projection::BranchEnd::Fold(_) => "junction",
        crate::projection::BranchEnd::Dome => "dome",
    }
}

/// The ends of a tree built on centerlines given: its inlet (the start of the branch with no
/// junction upstream) and each leaf branch's last sample. Read from the tree rather than the
/// file, whose polylines may be overlapping paths, branch-split tracts or two-node segments.
fn tree_ends(tree: &CenterlineTree) -> (Vec<VesselEnd>, usize) {
    let end = |s: &CenterlineSample| VesselEnd { centre: s.point, radius: s.radius, kind: EndKind::Centerline };
    (tree_terminals(tree).map(end).collect(), 0)
}

/// The tree's vessel ends: the first sample of the branch with no junction upstream (the
/// inlet), then the last sample of each leaf branch.
fn tree_terminals(tree: &CenterlineTree) -> impl Iterator<Item = &CenterlineSample> {
    let inlets = tree.branches.iter().filter(|b| b.start_junction.is_none()).filter_map(|b| b.samples.first());
    let outlets = tree.branches.iter().filter(|b| b.daughters.is_empty()).filter_map(|b| b.samples.last());
    inlets.chain(outlets)
}

/// A meshed branch ends within this many of the end's radii of its centre (a dome's mesh stops
/// short of its tip, inside it) ...
const MESHED_END_REACH: f64 = 2.0;
/// ... or this many of the branch's own radii there (an end given as a bare point).
const MESHED_END_BRANCH_RADII: f64 = 1.0;

/// Every end with whether a branch of the mesh ends at it (see [`MESHED_END_REACH`]) or it
/// opens in the side of the mesh (`side_ends`: their centres, mm), in the output unit (`scale`
/// per mm).
fn end_reports(
    ends: &[VesselEnd],
    inlet: usize,
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
            inlet: k == inlet,
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
fn ends_not_meshed(ends: &[EndReport], left_out: &[bool], unit: LengthUnit) -> Vec<Warning> {
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
fn ends_left_out(ends: &[VesselEnd], left_out_mm: &[[f64; 3]]) -> Vec<bool> {
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
const END_CUT_SHORT_RADII: f64 = 2.25;

/// One warning per vessel end whose mesh stops well short of it (see [`END_CUT_SHORT_RADII`],
/// beyond the trim asked for): no clean cross-section lies nearer the end, so the stretch
/// beyond is not meshed. Radii are the vessel's at the mesh's end section.
fn ends_cut_short(meshed: &Meshed, config: &MeshConfig) -> Vec<Warning> {
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
            if !matches!(kind, crate::projection::BranchEnd::Vessel { .. })
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

fn build_report(
    meshed: &Meshed,
    surface: &TriangleSurface,
    centerline_path: &Path,
    config: &MeshConfig,
    timings: &[(String, f64)],
    mut warnings: Vec<Warning>,
) -> Report {
    let mesh = &meshed.mesh;
    let unit = config.output_units;
    let scale = unit.from_mm();
    let branches = meshed
        .tree
        .branches
        .iter()
        .zip(&meshed.projected)
        .map(|(b, p)| BranchReport {
            name: b.name.clone(),
            centerline_length: b.length() * scale,
            meshed_from: p.s_start * scale,
            meshed_to: p.s_end * scale,
            stations: p.sections.len(),
            circumferential_elements: meshed.templates[p.branch].ring_len(),
            inlet_end: end_kind(&p.start),
            outlet_end: end_kind(&p.end),
            elements: mesh.branch_of.iter().filter(|&&x| x as usize == p.branch).count(),
            scaled_jacobian: Stats::of(
                (0..mesh.hexes.len())
                    .filter(|&e| mesh.branch_of[e] as usize == p.branch)
                    .map(|e| mesh.quality[e].scaled_jacobian),
            ),
        })
        .collect();
    let junctions = meshed
        .junctions
        .iter()
        .map(|g| {
            let elements: Vec<usize> =
                (0..mesh.hexes.len()).filter(|&e| meshed.junction_of[e] == Some(g.index)).collect();
            JunctionReport {
                centre: (g.centre.coords * scale).into(),
                radius: g.radius * scale,
                branches: g.slots.iter().map(|s| meshed.tree.branches[s.branch].name.clone()).collect(),
                arrangement: g.arrangement_name(),
                spine_axis: g.spine_axis().map(Into::into),
                wall_growth: match config.wall.growth {
                    WallGrowth::Ray => JunctionWall::Ray,
                    WallGrowth::Normal => meshed.junction_variant.wall,
                },
                surface_nodes_slid: meshed.junction_variant.optimisation.slide_surface_nodes,
                pattern_search: meshed.junction_variant.optimisation.pattern_search,
                pages_moved: meshed.junction_variant.optimisation.move_pages,
                surface_smoothed: meshed.junction_variant.optimisation.smooth_surface,
                elements: elements.len(),
                // A sac branch's transition is the junction's too, but the sac is the branch's.
                sac_elements: if crate::sacs::holds_sac(g) {
                    elements.iter().filter(|&&e| mesh.sac[e]).count()
                } else {
                    0
                },
                scaled_jacobian: Stats::of(elements.iter().map(|&e| mesh.quality[e].scaled_jacobian)),
                lumen_equiangle_skew: Stats::of(
                    elements.iter().filter(|&&e| !mesh.regions[e].is_wall()).map(|&e| mesh.quality[e].equiangle_skew),
                ),
            }
        })
        .collect();
    let normals_outward = meshed.projected.first().is_none_or(|p| p.normals_outward);
    let bars = bar_warnings(mesh);
    let within_bars = bars.is_empty();
    warnings.extend(bars);
    warnings.extend(meshed.accuracy.unmeshed_warning().map(|w| Warning::new("surface_not_meshed", w)));
    Report {
        vesselhex_version: env!("CARGO_PKG_VERSION"),
        length_unit: unit,
        length_unit_in_m: unit.in_metres(),
        input: InputReport {
            surface: surface.source.display().to_string(),
            centerlines: centerline_path.display().to_string(),
            units: config.units,
            surface_triangles: surface.triangles.len(),
            surface_orientation: if normals_outward { "outward" } else { "inward" },
            hygiene: HygieneReport::default(),
        },
        elements: mesh.hexes.len(),
        nodes: mesh.nodes.len(),
        lumen: lumen_report(mesh),
        wall: wall_report(mesh),
        surface_accuracy: meshed.accuracy.clone(),
        ends: vec![],
        additions: Default::default(),
        branches,
        junctions,
        within_bars,
        warnings,
        timings_s: timings.iter().cloned().collect(),
        outputs: vec![],
        config: config.clone(),
    }
}

/// Meshes a vessel (both inputs in mm) and runs the added stages its settings ask for: what
/// `vesselhex mesh` builds, without writing it (wall surfaces are read within `max_memory`).
pub fn mesh_finished(
    surface: &TriangleSurface,
    centerlines: &crate::input::Centerlines,
    config: &MeshConfig,
    max_memory: u64,
) -> Result<(Meshed, crate::finishing::Additions)> {
    let mut progress = Progress::new(true, 9 + crate::finishing::stages(config));
    let mut meshed = mesh_vessel(surface, centerlines, config, &mut progress)?;
    let additions =
        crate::finishing::finish(&mut meshed, surface, config, &ReadLimits::within(max_memory), &mut progress, &[])?;
    Ok((meshed, additions))
}

/// Where a vessel's centerlines come from.
pub enum CenterlineSource {
    /// Read from a file or handed over (millimetres).
    Given(Centerlines),
    /// Computed from the surface (see [`crate::centerline_extract`]).
    Extract(crate::centerline_extract::ExtractOptions),
}

/// The settings of one meshing besides its inputs.
#[derive(Debug, Clone)]
pub struct MeshSettings {
    pub config: MeshConfig,
    /// Unit of the centerlines when it differs from the surface's (`config.units`): named in
    /// the unit warning.
    pub centerline_units: Option<crate::units::LengthUnit>,
    /// The memory the run may plan to use: a mesh estimated to need more is refused before it
    /// is built.
    pub max_memory: u64,
    /// Warnings found before the run, reported with the rest.
    pub warnings: Vec<Warning>,
    /// Caps given in files of their own (see [`crate::input::read_surface_parts`]): each names
    /// the end it closes or covers.
    pub caps: Vec<NamedCap>,
}

/// A vessel meshed and not yet written: the mesh and what its report needs. What `run` writes,
/// and what the Python package holds.
pub struct MeshedVessel {
    pub meshed: Meshed,
    pub surface: TriangleSurface,
    /// Where the centerlines came from (a file, or `(computed from the surface)`).
    pub centerline_source: PathBuf,
    /// The centerlines the mesh was built on (millimetres).
    pub centerlines: Centerlines,
    /// The vessel's ends (found on the surface, or the given centerlines' ends) and which is
    /// the inlet.
    pub ends: Vec<VesselEnd>,
    pub inlet: usize,
    /// The name each end was given by a cap (parallel to `ends`).
    pub end_names: Vec<Option<String>>,
    /// What surface hygiene changed.
    pub hygiene: HygieneReport,
    /// Refinement, segmented walls and flow extensions done after meshing (millimetres).
    pub additions: crate::finishing::Additions,
    pub settings: MeshSettings,
    /// The far ends (mm) of branches found on the surface and left out, too short for their
    /// junction (a `branch_not_meshed` warning each).
    pub left_out_mm: Vec<[f64; 3]>,
}

/// Meshes a surface already read (millimetres) as `vesselhex mesh` does: the surface cleaned
/// (see [`clean_surface`]), centerlines computed when not given, the settings' lengths and the vessel's units checked, the memory estimated
/// before meshing. The caller's current progress stage (reading) lasts until meshing starts.
pub fn mesh_surface(
    surface: TriangleSurface,
    centerlines: CenterlineSource,
    mut settings: MeshSettings,
    progress: &mut Progress,
) -> Result<MeshedVessel> {
    let config = &settings.config;
    config.validate()?;
    crate::finishing::check_wall_surfaces(config)?;
    settings.warnings.extend(config.warnings());
    progress.stage("surface hygiene");
    let (surface, hygiene) = clean_surface(surface)?;
    settings.warnings.extend(hygiene.notes().into_iter().map(|n| Warning::new("surface_repaired", n)));
    let mut found_names = vec![];
    let (centerlines, centerline_source, found_ends) = match centerlines {
        CenterlineSource::Given(centerlines) => {
            let source = centerlines.source.clone();
            (centerlines, source, None)
        }
        CenterlineSource::Extract(mut options) => {
            progress.stage("centerline extraction");
            if options.caps.is_empty() {
                options.caps = settings.caps.clone();
            }
            let extraction = crate::centerline_extract::extract_centerlines(&surface, &options)?;
            settings.warnings.extend(extraction.notes.iter().map(|n| Warning::new("centerlines", n.clone())));
            found_names = extraction.end_names;
            let ends = Some((extraction.ends, extraction.inlet));
            (extraction.centerlines, PathBuf::from("(computed from the surface)"), ends)
        }
    };
    let radius = crate::resources::median_radius(&centerlines, &surface);
    check_lengths_against_radius(config, radius)?;
    settings.warnings.extend(unit_warning(radius, config.units, settings.centerline_units));
    let mut estimate = crate::resources::estimate_mesh(&centerlines, radius, config, surface.triangles.len());
    crate::finishing::scale_estimate(&mut estimate, config);
    crate::resources::check_fits(&estimate, settings.max_memory, &centerline_source)?;
    let tree_config = keep_extracted_ends(config, found_ends.as_ref());
    let mut short_branches = vec![];
    let attempt = mesh_vessel(&surface, &centerlines, &tree_config, progress);
    let (mut meshed, centerlines) = match attempt {
        Ok(meshed) => (meshed, centerlines),
        // Sacs found on the surface never cost the vessel: refused with them, it is meshed
        // without them, and each is said not meshed (a warning, report.json's ends, exit 3).
        Err(e) if found_ends.is_some() && !tree_config.centerline.sacs_mm.is_empty() => {
            let sacs = &tree_config.centerline.sacs_mm;
            settings.warnings.push(Warning::new(
                "sac_not_meshed",
                format!("the vessel is meshed without its sac(s); with them: {e}"),
            ));
            let centerlines = without_paths_to(&centerlines, sacs);
            let config = MeshConfig {
                centerline: crate::config::CenterlineConfig { sacs_mm: vec![], ..tree_config.centerline.clone() },
                ..tree_config.clone()
            };
            let meshed =
                mesh_vessel(&surface, &centerlines, &config, progress).map_err(|e| name_winding(e, &surface))?;
            (meshed, centerlines)
        }
        // A branch found on the surface that ends too close to its junction for the junction's
        // transition (a short capped stub in an aorto-iliac's crotch) does not cost the rest: the
        // vessel is meshed without it, its stretch meshed with its neighbour's lumen, and its
        // cap opened in the side of the mesh (see `crate::side_ends`).
        Err(Error::ShortBranch { message, end_mm }) if found_ends.is_some() && centerlines.polylines.len() > 2 => {
            let centerlines = without_paths_to(&centerlines, &[end_mm]);
            short_branches.push((end_mm, message));
            let meshed =
                mesh_vessel(&surface, &centerlines, &tree_config, progress).map_err(|e| name_winding(e, &surface))?;
            (meshed, centerlines)
        }
        Err(e) => return Err(name_winding(e, &surface)),
    };
    settings.warnings.append(&mut meshed.notes);
    // The ends named by caps: found on the surface, or the given centerlines' ends.
    let (ends, inlet) = found_ends.clone().unwrap_or_else(|| tree_ends(&meshed.tree));
    if found_ends.is_none() {
        found_names = names_of_ends(&ends, &settings.caps).map_err(|e| Error::input(&surface.source, e))?;
    }
    name_mesh_ends(&mut meshed.mesh, &ends, &found_names);
    let openings = side_openings(&surface, found_ends.as_ref().map_or(&[][..], |(e, _)| e), &short_branches);
    let limits = ReadLimits::within(settings.max_memory);
    let asked: Vec<SideOpening> = openings.iter().flatten().copied().collect();
    let mut additions = crate::finishing::finish(&mut meshed, &surface, config, &limits, progress, &asked)?;
    // An end opened in the side of the mesh is named as the others.
    for (old, new) in name_mesh_ends(&mut meshed.mesh, &ends, &found_names) {
        additions.side_ends.iter_mut().filter(|s| s.end == old).for_each(|s| s.end = new.clone());
    }
    let mut left_out_mm = vec![];
    for ((end_mm, message), opening) in short_branches.into_iter().zip(&openings) {
        let [x, y, z] = end_mm;
        let opened = opening.and_then(|o| additions.side_ends.iter().find(|s| s.centre == <[f64; 3]>::from(o.centre)));
        settings.warnings.push(match opened {
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
    found_names.resize(ends.len(), None);
    Ok(MeshedVessel {
        meshed,
        surface,
        centerline_source,
        centerlines,
        ends,
        inlet,
        end_names: found_names,
        hygiene,
        additions,
        settings,
        left_out_mm,
    })
}

/// Where each short branch's end (its far end, mm) may open in the side of the mesh (see
/// [`crate::side_ends`]): the end found nearest it, when that end is a flat cap.
fn side_openings(
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

/// The centerlines without the paths to `points`: for each point, the polyline whose last point
/// lies nearest it (the extraction's paths end at their ends' centres).
fn without_paths_to(centerlines: &Centerlines, points: &[[f64; 3]]) -> Centerlines {
    let lines = &centerlines.polylines;
    let gap = |k: usize, p: &[f64; 3]| lines[k].points.last().map_or(f64::INFINITY, |q| (q - Point3::from(*p)).norm());
    let dropped: Vec<usize> =
        points.iter().filter_map(|p| (0..lines.len()).min_by(|&a, &b| gap(a, p).total_cmp(&gap(b, p)))).collect();
    Centerlines {
        polylines: (0..lines.len()).filter(|k| !dropped.contains(k)).map(|k| lines[k].clone()).collect(),
        source: centerlines.source.clone(),
    }
}

/// `config` with the inlet the centerline extraction chose (the largest end section, or the end
/// `--inlet` names) as the centerline tree's, unless the configuration names one, and the sacs it
/// found as the domes to close (unless the configuration names them). Left to choose
/// again, the tree would take the end with the widest vessel next to it, a daughter wider than a
/// short trunk (sphinxsys_pulmonary_bifurcation), and report and mesh would disagree on the inlet.
fn keep_extracted_ends(config: &MeshConfig, found_ends: Option<&(Vec<VesselEnd>, usize)>) -> MeshConfig {
    let mut config = config.clone();
    if let (Some((ends, _)), true) = (found_ends, config.centerline.sacs_mm.is_empty()) {
        config.centerline.sacs_mm =
            ends.iter().filter(|e| e.kind == EndKind::Sac).map(|e| e.centre.coords.into()).collect();
    }
    if let (Some((ends, inlet)), None) = (found_ends, config.centerline.inlet_mm) {
        config.centerline.inlet_mm = Some(ends[*inlet].centre.coords.into());
    }
    config
}

/// Claims the output folder for writing `config`'s formats: `inputs` (and the case file's
/// template folder) must not lie in it (see [`OutputFolder::claim`]).
pub fn claim_output(output: &Path, inputs: &[&Path], config: &MeshConfig, force: bool) -> Result<OutputFolder> {
    let inputs: Vec<&Path> = inputs
        .iter()
        .copied()
        .chain(config.fe.template_dir.as_deref())
        .chain(config.wall.surface.iter().chain(&config.wall.surfaces).map(PathBuf::as_path))
        .collect();
    OutputFolder::claim(output, &inputs, force)
}

/// Writes `config`'s formats of a meshed vessel into the claimed output folder, then
/// report.json (listing every file), and puts the folder in place; returns the report.
/// `config` is the vessel's own, or one that differs only in what the writers read (formats,
/// output units, solver settings). `reproducible` zeroes the timings.
pub fn write_vessel(
    vessel: &MeshedVessel,
    config: &MeshConfig,
    output: OutputFolder,
    reproducible: bool,
    progress: &mut Progress,
) -> Result<Report> {
    config.validate()?;
    let formats = formats_to_write(config)?;
    progress.stage("writing");
    output.begin_writing()?;
    let options = WriteOptions::from_config(config);
    let mesh_for = |f: &str| crate::finishing::mesh_for_format(&vessel.meshed.mesh, f, config);
    let mut outputs = writers::schedule::write_formats(&formats, &mesh_for, &options, output.staging())?;
    progress.finish();
    let mut report = vessel_report(vessel, config, &progress.timings);
    if reproducible {
        report.timings_s.values_mut().for_each(|t| *t = 0.0);
    }
    // report.json lists every file written: it is also what marks the folder as vesselhex's.
    outputs.push(PathBuf::from(crate::output::MARKER));
    report.outputs = outputs.iter().map(|p| p.display().to_string()).collect();
    let json = serde_json::to_string_pretty(&report)
        .map_err(|e| Error::Config(format!("internal: cannot encode the report: {e}")))?;
    writers::write_atomic(&output.staging().join(crate::output::MARKER), |w| w.write_all(json.as_bytes()))?;
    output.commit()?;
    Ok(report)
}

/// The report of a meshed vessel as `write_vessel` would write it with `config`, without
/// writing anything (no outputs listed); timings as given.
pub fn vessel_report(vessel: &MeshedVessel, config: &MeshConfig, timings: &[(String, f64)]) -> Report {
    let mut warnings = vessel.settings.warnings.clone();
    let side_ends: Vec<[f64; 3]> = vessel.additions.side_ends.iter().map(|s| s.centre).collect();
    let mut ends =
        end_reports(&vessel.ends, vessel.inlet, &vessel.meshed.tree, &side_ends, config.output_units.from_mm());
    let mesh = &vessel.meshed.mesh;
    for ((report, at), given) in ends.iter_mut().zip(mesh_ends_at(mesh, &vessel.ends)).zip(&vessel.end_names) {
        report.name = at.map(|m| mesh.ends[m].name.clone()).or_else(|| given.clone());
    }
    let left_out = ends_left_out(&vessel.ends, &vessel.left_out_mm);
    warnings.extend(ends_not_meshed(&ends, &left_out, config.output_units));
    warnings.extend(ends_cut_short(&vessel.meshed, config));
    let mut report =
        build_report(&vessel.meshed, &vessel.surface, &vessel.centerline_source, config, timings, warnings);
    report.ends = ends;
    report.input.hygiene = vessel.hygiene.clone();
    report.additions = vessel.additions.clone().scaled(config.output_units.from_mm());
    report
}

#[cfg(test)]
mod tests {
    use super::{end_reports, ends_not_meshed};
    use crate::centerline::CenterlineTree;
    use crate::centerline_extract::{EndKind, VesselEnd};
    use crate::config::MeshConfig;
    use crate::input::{CenterlinePolyline, Centerlines};
    use crate::units::LengthUnit;
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
        let reports = end_reports(&ends, 0, &tree, &[], 1.0);
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

