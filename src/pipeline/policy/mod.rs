//! The retry and fallback policies of the pipeline, in one place. Each meshes the vessel again,
//! another way, when the first is refused or short of a quality bar, and keeps the better mesh
//! (the first of equals), judged as a junction's finishes are ([`FinishQuality`]):
//!
//! - **books, then sectors** ([`books_then_sectors`]): a junction of four or more branches is
//!   laid out as a book first, then in sectors;
//! - **merged junctions' centres** ([`mesh_vessel_laid_out`], [`MERGED_CENTRE_AT`]): two
//!   junctions whose blocks would overlap become one, centred at each place in turn;
//! - **coarser junction spacing** ([`coarser_junctions`]): a vessel with merged junctions, or one
//!   refused as asked, has its junctions spaced as at the coarse preset;
//! - **recentring close merges** ([`recentre_close_merges`], [`mesh_vessel_laid_out`]):
//!   junctions merged for being close are centred elsewhere when their mesh is refused or short
//!   of a bar, with an overlapping pair's places where one is merged;
//! - **close junctions apart** ([`merged_then_apart`]): a vessel refused or short of a bar with
//!   close junctions merged is meshed again with only overlapping junctions merged;
//! - **a cascade for fused daughters** ([`apart_then_cascaded`]): a vessel refused or short of
//!   a bar whose daughters leave some junction fused is meshed again with each such pair on a
//!   trunk of its own to where it parts;
//! - **finishes** ([`junction_finish`]): the volume built with several junction optimisations
//!   and walls, the best kept, with each junction's own nodes from the finish best for it;
//! - **a sac deeper** ([`mesh_deepened_sac`]): a sac found on the surface that opens too close
//!   to its junction for its dome to close it from its largest ball's centre is meshed with its
//!   last section further into it, a lower dome closing it;
//! - **leaving out what cannot be meshed** ([`mesh_dropping_what_fails`]): a sac found on the
//!   surface that still fails, or a branch too short for its junction, is left out and said, the
//!   rest meshed.

pub mod junction_finish;

use crate::data::config::MeshConfig;
use crate::data::diagnostics::Warning;
use crate::data::error::{Error, Result};
use crate::geometry::surface::{LumenSurface, TriangleSurface};
use crate::io::input::Centerlines;
use crate::pipeline::checks::name_winding;
use crate::pipeline::progress::Progress;
use crate::pipeline::{mesh_tree, mesh_vessel_on};
use crate::stages::annotation::Meshed;
use crate::stages::centerline::{CenterlineTree, ForcedMerge};
use crate::stages::junction::{analyse_junctions, find_junction_overlap, unanalysable_close_junction, LayoutPolicy};
use junction_finish::FinishQuality;
use nalgebra::Point3;

/// Meshes a vessel with its close junctions merged (see
/// `CenterlineConfig::junction_merge_radii`), books then sectors ([`books_then_sectors`]). A
/// vessel refused so, or short of a bar, that had junctions merged for lying close is meshed
/// again with only the junctions whose blocks overlap merged, and the better mesh kept (the
/// first of equals; judged as a junction's finishes are).
///
/// The two trees differ in more than the merges: a junction merged for lying close sits at the
/// upstream one's centre, and is moved along the merged branches ([`recentre_close_merges`],
/// or with an overlapping pair's places in [`mesh_vessel_laid_out`]) only when that mesh
/// fails; one merged for overlapping is centred along them from the start
/// ([`MERGED_CENTRE_AT`]). Random tree 50 has three bifurcations within 0.6 mm, a third of their
/// radius: merged as close, the tree is refused with them at the first centre and at each place
/// tried with a pair overlapping elsewhere; merged as overlapping, 0.17 mm along, they mesh.
/// Most trees need the close merges (random trees 1-100 at coarse, merged only where blocks
/// overlap: 8 of the 81 that mesh with them fail, 6 refused and 2 with a branch left out), so
/// they come first.
pub(crate) fn merged_then_apart(
    surface: &TriangleSurface,
    lumen_surface: &LumenSurface,
    centerlines: &Centerlines,
    config: &MeshConfig,
    progress: &mut Progress,
) -> Result<Meshed> {
    let merged = books_then_sectors(surface, lumen_surface, centerlines, config, progress);
    let within_bars = merged.as_ref().is_ok_and(|m| FinishQuality::of_mesh(&m.mesh).meets_bars());
    if within_bars || config.centerline.junction_merge_radii == 0.0 {
        return merged;
    }
    let merged_close = CenterlineTree::build(centerlines, &config.centerline, Some(lumen_surface))
        .is_ok_and(|tree| !tree.close_merges.is_empty());
    if !merged_close {
        return merged;
    }
    let apart = MeshConfig {
        centerline: crate::data::config::CenterlineConfig { junction_merge_radii: 0.0, ..config.centerline.clone() },
        ..config.clone()
    };
    let retry = books_then_sectors(surface, lumen_surface, centerlines, &apart, progress);
    keep_better_noting_retry(merged, retry, "junctions_apart", |merged_was| {
        format!(
            "junctions closer than centerline.junction_merge_radii ({}) are meshed apart, merged only where their \
             blocks overlap: merged, {merged_was}",
            config.centerline.junction_merge_radii
        )
    })
}

/// The better of a first attempt and a retry of one vessel ([`better_of`]); a retry kept says
/// so in a warning of `kind`, its message from `why` given how the first attempt fell short.
/// Both refused: the first refusal.
fn keep_better_noting_retry(
    first: Result<Meshed>,
    retry: Result<Meshed>,
    kind: &'static str,
    why: impl FnOnce(&str) -> String,
) -> Result<Meshed> {
    let first_was = match &first {
        Ok(_) => "the mesh was short of a quality bar".to_string(),
        Err(e) => format!("the vessel was refused: {e}"),
    };
    match better_of(first, retry) {
        Ok((meshed, Kept::First)) => Ok(meshed),
        Ok((mut meshed, Kept::Second)) => {
            meshed.notes.push(Warning::new(kind, why(&first_was)));
            Ok(meshed)
        }
        Err((first, _)) => Err(first),
    }
}

/// Meshes a vessel as [`merged_then_apart`] does; when it is refused or short of a bar, and
/// some junction's daughters leave it fused (their lumens still one where the junction's
/// transitions end: `CenterlineConfig::split_fused_daughters`), it is meshed again with each
/// such pair on a trunk of its own to where the two part, and the better mesh kept (the first
/// of equals). A junction's pages are laid across its centre; a pair fused past them has its
/// two transitions funnel into one lumen, their folds a few degrees apart, and the pair's
/// own bifurcation, where its lumens part, is where pages can separate them.
///
/// The cascade is the retry, not the first attempt, although it measured better where it
/// moves a junction (random trees 1-30 at coarse, cascade first: in each of the 10 whose tree
/// it changes, the worst lumen element as good or better and the lumen skew lower; the trees
/// refused as found skip that attempt, 1016 s -> 476 s over the 30). First, it changed the
/// branches of 5 of the 269 meshes of the mutation suite that met the bars: whether an
/// arch's pair of daughters counts as fused flips between writings of one surface (6 branches
/// where the surface as given has 7), where as a retry it is only taken where the tree as
/// found fails. It also lowered the worst element of cohort vessels that meet the bars as
/// found (sphinxsys_pulmonary_bifurcation 0.419 -> 0.383, sphinxsys_aortic_arch 0.280 -> 0.250).
pub(crate) fn apart_then_cascaded(
    surface: &TriangleSurface,
    lumen_surface: &LumenSurface,
    centerlines: &Centerlines,
    config: &MeshConfig,
    progress: &mut Progress,
) -> Result<Meshed> {
    let first = merged_then_apart(surface, lumen_surface, centerlines, config, progress);
    let within_bars = first.as_ref().is_ok_and(|m| FinishQuality::of_mesh(&m.mesh).meets_bars());
    if within_bars || config.centerline.split_fused_daughters {
        return first;
    }
    let cascaded = MeshConfig {
        centerline: crate::data::config::CenterlineConfig { split_fused_daughters: true, ..config.centerline.clone() },
        ..config.clone()
    };
    let build = |c: &MeshConfig| CenterlineTree::build(centerlines, &c.centerline, Some(lumen_surface)).ok();
    let (Some(plain), Some(split)) = (build(config), build(&cascaded)) else { return first };
    if !junctions_differ(&plain, &split) {
        return first;
    }
    let retry = merged_then_apart(surface, lumen_surface, centerlines, &cascaded, progress);
    keep_better_noting_retry(first, retry, "junctions_cascaded", |first_was| {
        format!(
            "daughters leaving a junction fused are meshed on a trunk of their own to where they part, a cascade of \
             bifurcations ({} junctions where {} were found; centerline.split_fused_daughters): without it, \
             {first_was}",
            split.junctions.len(),
            plain.junctions.len()
        )
    })
}

/// Whether two trees of one vessel have their junctions in different places (or a different
/// number of them).
fn junctions_differ(a: &CenterlineTree, b: &CenterlineTree) -> bool {
    a.junctions.len() != b.junctions.len()
        || a.junctions.iter().zip(&b.junctions).any(|(x, y)| (x.centre - y.centre).norm() > 1e-9)
}

/// Which of two meshes of one vessel [`better_of`] kept.
enum Kept {
    First,
    Second,
}

/// The better of two attempts at meshing one vessel, and which it was (the first of equals;
/// judged as a junction's finishes are); both refusals when neither meshed.
fn better_of(first: Result<Meshed>, second: Result<Meshed>) -> std::result::Result<(Meshed, Kept), (Error, Error)> {
    match (first, second) {
        (Ok(a), Ok(b)) => Ok(if FinishQuality::of_mesh(&b.mesh).better_than(&FinishQuality::of_mesh(&a.mesh)) {
            (b, Kept::Second)
        } else {
            (a, Kept::First)
        }),
        (Ok(a), Err(_)) => Ok((a, Kept::First)),
        (Err(_), Ok(b)) => Ok((b, Kept::Second)),
        (Err(a), Err(b)) => Err((a, b)),
    }
}

/// Meshes a vessel with its junctions laid out as books first: a straight spine shared by
/// every branch is the best-shaped fold where it orders the branches. A vessel refused so, or
/// short of a bar, with a junction of four or more branches is meshed again with that junction
/// in sectors, and the better mesh kept (the first of equals; judged as a junction's finishes
/// are).
fn books_then_sectors(
    surface: &TriangleSurface,
    lumen_surface: &LumenSurface,
    centerlines: &Centerlines,
    config: &MeshConfig,
    progress: &mut Progress,
) -> Result<Meshed> {
    let books = LayoutPolicy::books_only();
    let meshed = mesh_vessel_laid_out(surface, lumen_surface, centerlines, config, &books, progress);
    let within_bars = |m: &Meshed| FinishQuality::of_mesh(&m.mesh).meets_bars();
    if meshed.as_ref().is_ok_and(within_bars) || !books.sectors_differ.get() {
        return meshed;
    }
    let sectors = LayoutPolicy::with_sectors();
    let laid_out = mesh_vessel_laid_out(surface, lumen_surface, centerlines, config, &sectors, progress);
    better_of(meshed, laid_out).map(|(meshed, _)| meshed).map_err(|(_, sectors)| sectors)
}

/// Meshes the vessel; when it is refused, leaves out what the centerline extraction found and
/// cannot be meshed, and meshes the rest (`extracted`: the centerlines were found on the
/// surface, not given): the sacs (a `sac_not_meshed` warning in `warnings`), or a branch that
/// ends too close to its junction for the junction's transition (returned with its far end, mm,
/// and the refusal, for its cap to be opened in the side of the mesh). A refusal of a surface
/// wound inconsistently names the winding. Returns the mesh, the centerlines it was built on and
/// the short branches left out.
#[allow(clippy::type_complexity)]
pub(crate) fn mesh_dropping_what_fails(
    surface: &TriangleSurface,
    centerlines: Centerlines,
    tree_config: &MeshConfig,
    extracted: bool,
    warnings: &mut Vec<Warning>,
    progress: &mut Progress,
) -> Result<(Meshed, Centerlines, Vec<([f64; 3], String)>)> {
    let mut short_branches = vec![];
    // The surface indexed once for every attempt (else each indexes it, and fails, as the first).
    let index = LumenSurface::new(surface).ok();
    let index = index.as_ref();
    let attempt = mesh_vessel_on(surface, index, &centerlines, tree_config, progress);
    let (meshed, centerlines) = match attempt {
        Ok(meshed) => (meshed, centerlines),
        // Sacs found on the surface never cost the vessel: refused with them, it is meshed
        // without the one that fails (or all), and each left out is said not meshed (a warning,
        // report.json's ends, exit 3).
        Err(e) if extracted && !tree_config.centerline.sacs_mm.is_empty() => {
            match mesh_deepened_sac(surface, index, &centerlines, tree_config, &e, progress) {
                Some(deepened) => deepened,
                None => mesh_leaving_out_sacs(surface, index, centerlines, tree_config, &e, warnings, progress)?,
            }
        }
        // A branch found on the surface that ends too close to its junction for the junction's
        // transition (a short capped stub in an aorto-iliac's crotch) does not cost the rest: the
        // vessel is meshed without it, its stretch meshed with its neighbour's lumen, and its
        // cap opened in the side of the mesh (see `crate::stages::additions::side_ends`).
        Err(Error::ShortBranch { message, end_mm }) if extracted && centerlines.polylines.len() > 2 => {
            let centerlines = without_paths_to(&centerlines, &[end_mm]);
            short_branches.push((end_mm, message));
            let meshed = mesh_vessel_on(surface, index, &centerlines, tree_config, progress)
                .map_err(|e| name_winding(e, surface))?;
            (meshed, centerlines)
        }
        Err(e) => return Err(name_winding(e, surface)),
    };
    Ok((meshed, centerlines, short_branches))
}

/// How far past the centre of a sac's largest ball (radius R) its dome's base may stand, in R,
/// when the sac opens too close to its junction for it to stand at the centre. There the dome
/// closing the sac is a hemisphere; at this depth it is 0.58 as tall as it is wide, and the
/// section's rim meets the sac's wall at 60 degrees (a ball's wall a chord of depth d from its
/// centre meets at acos(d / R)), the ring cells at the wall sheared by 30 degrees at most.
const SAC_DEEPENING: f64 = 0.5;

/// The vessel refused (`refusal`) because a sac opens too close to its junction (no section of
/// its branch between the junction's folded end and the centre of the sac's largest ball is
/// clear; see `Error::ShortBranch`), meshed with that sac's path run on past the ball's centre
/// ([`deepen_path`]), so that its last section may stand in the sac and a lower dome close it
/// (random tree 30: at the ball's centre the fold's wall lay 0.15 mm ahead of the section, where
/// a quarter of the vessel's radius, 0.32 mm, is asked; tree 46 likewise, 2.29 mm asked). `None`
/// when the refusal is another, or the vessel is refused so too. Returns the mesh and its
/// centerlines.
fn mesh_deepened_sac(
    surface: &TriangleSurface,
    index: Option<&LumenSurface>,
    centerlines: &Centerlines,
    tree_config: &MeshConfig,
    refusal: &Error,
    progress: &mut Progress,
) -> Option<(Meshed, Centerlines)> {
    let Error::ShortBranch { end_mm, .. } = refusal else { return None };
    let end = Point3::from(*end_mm);
    let (k, gap) = path_to(centerlines, end_mm)?;
    let radius = *centerlines.polylines[k].radii.as_ref()?.last()?;
    // The refusal names a sac's path only when a sac point lies within its end's ball.
    let is_sac = tree_config.centerline.sacs_mm.iter().any(|p| (Point3::from(*p) - end).norm() <= radius);
    if gap > radius || !is_sac {
        return None;
    }
    let mut deepened = centerlines.clone();
    deepen_path(&mut deepened.polylines[k], SAC_DEEPENING * radius);
    let mut meshed = mesh_vessel_on(surface, index, &deepened, tree_config, progress).ok()?;
    meshed.notes.push(Warning::new(
        "sac_deepened",
        format!(
            "the sac at ({:.3}, {:.3}, {:.3}) mm opens too close to its junction for its dome to close it from the \
         centre of its largest ball: the dome's base stands up to {:.3} mm further in, and a lower dome closes it",
            end.x,
            end.y,
            end.z,
            SAC_DEEPENING * radius
        ),
    ));
    Some((meshed, deepened))
}

/// Runs a path on `depth` past its last point, straight along its direction over the last
/// ball's radius there (the path reaches the ball's centre through its neck), inside the ball:
/// each point's radius is the ball's half-chord there, sqrt(R^2 - d^2). Points every eighth of
/// the radius.
fn deepen_path(path: &mut crate::io::input::CenterlinePolyline, depth: f64) {
    let (Some(&last), Some(radius)) = (path.points.last(), path.radii.as_ref().and_then(|r| r.last().copied())) else {
        return;
    };
    // The direction from the first point a radius back along the path (or the first point).
    let mut back = path.points[0];
    let mut run = 0.0;
    for w in path.points.windows(2).rev() {
        run += (w[1] - w[0]).norm();
        back = w[0];
        if run >= radius {
            break;
        }
    }
    let Some(direction) = (last - back).try_normalize(1e-12) else { return };
    let steps = (8.0 * depth / radius).ceil().max(1.0) as usize;
    for i in 1..=steps {
        let d = depth * i as f64 / steps as f64;
        path.points.push(last + direction * d);
        if let Some(radii) = path.radii.as_mut() {
            radii.push((radius * radius - d * d).max(0.0).sqrt());
        }
        if let Some(normals) = path.normals.as_mut() {
            if let Some(&n) = normals.last() {
                normals.push(n);
            }
        }
    }
}

/// The vessel refused (`refusal`) with the sacs the extraction found, meshed without them: of
/// two or more, without each in turn first (in order; the first mesh kept), since one sac that
/// cannot be meshed should not cost the others (random tree 12: a true sac left out with a
/// stub its junction leaves, which no section clears); else without them all. A warning names
/// each sac left out and the refusal with it. Returns the mesh and its centerlines.
fn mesh_leaving_out_sacs(
    surface: &TriangleSurface,
    index: Option<&LumenSurface>,
    centerlines: Centerlines,
    tree_config: &MeshConfig,
    refusal: &Error,
    warnings: &mut Vec<Warning>,
    progress: &mut Progress,
) -> Result<(Meshed, Centerlines)> {
    let sacs = &tree_config.centerline.sacs_mm;
    let keeping = |kept: Vec<[f64; 3]>| MeshConfig {
        centerline: crate::data::config::CenterlineConfig { sacs_mm: kept, ..tree_config.centerline.clone() },
        ..tree_config.clone()
    };
    if sacs.len() > 1 {
        for (k, sac) in sacs.iter().enumerate() {
            let kept: Vec<[f64; 3]> = sacs.iter().enumerate().filter(|(j, _)| *j != k).map(|(_, p)| *p).collect();
            let without = without_paths_to(&centerlines, &[*sac]);
            if let Ok(meshed) = mesh_vessel_on(surface, index, &without, &keeping(kept), progress) {
                let [x, y, z] = *sac;
                warnings.push(Warning::new(
                    "sac_not_meshed",
                    format!(
                        "the vessel is meshed without its sac at ({x:.3}, {y:.3}, {z:.3}) mm, with its other sac(s); \
                         with it: {refusal}"
                    ),
                ));
                return Ok((meshed, without));
            }
        }
    }
    warnings
        .push(Warning::new("sac_not_meshed", format!("the vessel is meshed without its sac(s); with them: {refusal}")));
    let without = without_paths_to(&centerlines, sacs);
    let meshed =
        mesh_vessel_on(surface, index, &without, &keeping(vec![]), progress).map_err(|e| name_winding(e, surface))?;
    Ok((meshed, without))
}

/// [`crate::pipeline::mesh_vessel`] with the junctions' arrangements `policy` allows.
pub(super) fn mesh_vessel_laid_out(
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
    let Some(overlap) = overlap else {
        return mesh_unmerged(surface, lumen_surface, tree, centerlines, config, policy, progress);
    };
    let coarser = coarser_junctions(config, centerlines);
    // Two junctions overlap: they become one, centred on the branch between them. Where along
    // it depends on the branches around (the middle of the merged junction is neither end), so
    // each place of MERGED_CENTRE_AT is meshed and the best mesh kept (judged as a junction's
    // finishes are, on the whole mesh), the first of equals. Its transitions sweep between two
    // junctions' folds, so they are spaced as at the coarse preset (see `coarser_junctions`).
    let merged_config = coarser.as_ref().unwrap_or(config);
    let segment = tree.segments[overlap.branch];
    // The junctions merged for lying close stay at their upstream centres first, as where
    // nothing overlaps; where no place meets the bars so, they are centred at each place too
    // (random tree 37: refused with them at their first centres, it meets the bars with them
    // centred along too).
    // `close`: the close merges centred at each place with the overlapping pair (none: at their
    // upstream centres).
    let each_place = |close: &[usize], best, progress: &mut Progress| {
        best_at_each_place(best, |at| {
            merged_tree(centerlines, merged_config, lumen_surface, (segment, close), at, policy).and_then(|tree| {
                mesh_tree(surface, lumen_surface, tree, &centerlines.source, merged_config, false, policy, progress)
            })
        })
    };
    let (mut best, mut first_error) = each_place(&[], None, progress);
    if !tree.close_merges.is_empty() && !best.as_ref().is_some_and(|(_, q)| q.meets_bars()) {
        let (recentred, error) = each_place(&tree.close_merges, best, progress);
        best = recentred;
        first_error = first_error.or(error);
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
            if let Some(mut meshed) = overlap_apart(surface, lumen_surface, centerlines, config, policy, progress) {
                meshed.notes.push(Warning::new(
                    "junctions_overlap",
                    format!(
                        "{} were predicted to overlap (a crotch of one reaches past the other's centre), yet \
                         merged into one junction they were refused at every place tried ({e}); they are meshed \
                         apart, and their elements judged as any",
                        overlap.place
                    ),
                ));
                return Ok(meshed);
            }
            let tried = format!(
                "(vesselhex merged {} into one junction there, as their blocks would overlap, and tried centring it \
                 {} of the way along the branch between them; none meshed, nor did meshing them apart)",
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

/// The tree meshed as built, its junctions merged only for lying close ([`mesh_tree_recentred`]);
/// one refused for its geometry is meshed again with its junctions spaced as at the coarse
/// preset ([`coarser_junctions`]), where that differs.
fn mesh_unmerged(
    surface: &TriangleSurface,
    lumen_surface: &LumenSurface,
    tree: CenterlineTree,
    centerlines: &Centerlines,
    config: &MeshConfig,
    policy: &LayoutPolicy,
    progress: &mut Progress,
) -> Result<Meshed> {
    let close_merges = tree.close_merges.clone();
    let meshed =
        mesh_tree_recentred(surface, lumen_surface, tree, centerlines, config, &close_merges, policy, progress);
    let (Err(Error::Geometry(refusal)), Some(coarser)) = (&meshed, coarser_junctions(config, centerlines)) else {
        return meshed;
    };
    let tree = CenterlineTree::build(centerlines, &config.centerline, Some(lumen_surface))?;
    let mut retried =
        mesh_tree_recentred(surface, lumen_surface, tree, centerlines, &coarser, &close_merges, policy, progress)
            .map_err(|_| Error::Geometry(refusal.clone()))?;
    retried.notes.push(junction_spacing_note(
        config,
        &format!("at {} they were refused: {refusal}", config.lumen.axial_spacing),
    ));
    Ok(retried)
}

/// Two junctions predicted to overlap, whose merged junction was refused at every place,
/// meshed apart: the prediction (a crotch of one reaching past the other's centre, see
/// `junction::check_junction_spacing`) says their blocks may invert, the elements say whether
/// they do. Random trees 1011 and 1019 (of the unseen seeds) were refused merged at every place
/// and meet every bar apart. Only refused vessels take this path: none that meshed changes.
/// None when apart is refused too.
fn overlap_apart(
    surface: &TriangleSurface,
    lumen_surface: &LumenSurface,
    centerlines: &Centerlines,
    config: &MeshConfig,
    policy: &LayoutPolicy,
    progress: &mut Progress,
) -> Option<Meshed> {
    let apart_policy = policy.meshing_overlaps();
    let meshed = CenterlineTree::build(centerlines, &config.centerline, Some(lumen_surface))
        .and_then(|tree| mesh_unmerged(surface, lumen_surface, tree, centerlines, config, &apart_policy, progress));
    policy.sectors_differ.set(policy.sectors_differ.get() || apart_policy.sectors_differ.get());
    meshed.ok()
}

/// The vessel meshed (`mesh_at`) with its merged junctions centred at each place of
/// [`MERGED_CENTRE_AT`] in turn, and the best mesh kept (`best`, a mesh found before, wins
/// ties; judged as a junction's finishes are); the first within the bars ends the search, as
/// each place costs a whole mesh. Returns the best and the first refusal.
#[allow(clippy::type_complexity)]
fn best_at_each_place(
    mut best: Option<(Meshed, FinishQuality)>,
    mut mesh_at: impl FnMut(f64) -> Result<Meshed>,
) -> (Option<(Meshed, FinishQuality)>, Option<Error>) {
    let mut first_error = None;
    for at in MERGED_CENTRE_AT {
        match mesh_at(at) {
            Ok(meshed) => {
                let quality = FinishQuality::of_mesh(&meshed.mesh);
                let meets_bars = quality.meets_bars();
                if best.as_ref().is_none_or(|(_, b)| quality.better_than(b)) {
                    best = Some((meshed, quality));
                }
                if meets_bars {
                    break;
                }
            }
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    (best, first_error)
}

/// The coarse preset's axial spacing, relative to the radius: what [`coarser_junctions`] spaces
/// the junctions at.
pub(super) const COARSE_JUNCTION_SPACING: f64 = 0.5;

/// The settings with a branched vessel's junction transitions and bridges spaced at the coarse
/// preset's spacing (the rest as asked), when they ask a finer spacing relative to the radius
/// and none for the junctions; None otherwise. [`crate::pipeline::mesh_vessel`] meshes with them a vessel whose
/// junctions were merged (their transitions sweep between two junctions' folds over a spine up
/// to twice as long) and one refused with the settings as given. A transition's sections are
/// swept between curved folds, not cut by planes, and thin ones cross each other:
/// sphinxsys_aortic_arch at medium (0.3 radii) had 285 elements inverted around its arch's
/// bridge, and 0.4 and 0.45 were refused too; at 0.5 it meets the bars, and the two Gmsh arches
/// (merged junctions too) stay within them in about half the time (0.90 -> 0.43 s, 2.25 -> 1.28 s).
pub(super) fn coarser_junctions(config: &MeshConfig, centerlines: &Centerlines) -> Option<MeshConfig> {
    let l = &config.lumen;
    let finer = centerlines.polylines.len() > 1
        && l.junction_axial_spacing.is_none()
        && l.axial_spacing_mm.is_none()
        && l.axial_spacing < COARSE_JUNCTION_SPACING;
    finer.then(|| {
        let lumen =
            crate::data::config::LumenConfig { junction_axial_spacing: Some(COARSE_JUNCTION_SPACING), ..l.clone() };
        MeshConfig { lumen, ..config.clone() }
    })
}

/// The `junction_spacing` warning: the junctions spaced at the coarse preset's spacing, `why`.
pub(super) fn junction_spacing_note(config: &MeshConfig, why: &str) -> Warning {
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
pub(super) fn mesh_tree_recentred(
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

/// A tree whose close junctions were merged (see `CenterlineConfig::junction_merge_radii`),
/// short of a bar or refused with the merged junctions at their upstream centres: each place of
/// [`MERGED_CENTRE_AT`] along the merged segments is meshed, and the best mesh kept (`meshed`,
/// the first, wins ties), as for overlapping junctions. gmsh_cerebral_aneurysm at medium, its
/// sac leaving where a side branch does: 0.187 at the upstream centre, 0.240 at 5/8.
pub(super) fn recentre_close_merges(
    surface: &TriangleSurface,
    lumen_surface: &LumenSurface,
    centerlines: &Centerlines,
    config: &MeshConfig,
    meshed: Result<Meshed>,
    close_merges: &[usize],
    policy: &LayoutPolicy,
    progress: &mut Progress,
) -> Result<Meshed> {
    let (best, refused) = match meshed {
        Ok(m) => {
            let quality = FinishQuality::of_mesh(&m.mesh);
            (Some((m, quality)), None)
        }
        Err(e) => (None, Some(e)),
    };
    // A place within the bars is always better than a mesh short of them: the search ends at
    // the first as it always has.
    let (best, _) = best_at_each_place(best, |at| {
        let forced: Vec<ForcedMerge> = close_merges.iter().map(|&segment| ForcedMerge { segment, at }).collect();
        CenterlineTree::build_merging(centerlines, &config.centerline, Some(lumen_surface), &forced).and_then(|tree| {
            mesh_tree(surface, lumen_surface, tree, &centerlines.source, config, false, policy, progress)
        })
    });
    match (best, refused) {
        (Some((meshed, _)), _) => Ok(meshed),
        (None, Some(e)) => Err(e),
        (None, None) => unreachable!("a mesh given is kept"),
    }
}

/// Where the junction merged from two overlapping ones is centred: fractions of the branch
/// between them from the upstream one. Measured on gmsh_aortic_arch (the brachiocephalic-carotid
/// trunk, whose arch-side crotch lies past its far end): all three mesh at the coarse preset,
/// only 7/8 at the medium one, 1/2 at neither.
pub(super) const MERGED_CENTRE_AT: [f64; 3] = [0.625, 0.75, 0.875];

/// At most this many pairs of overlapping junctions are merged in one vessel.
pub(super) const MAX_FORCED_MERGES: usize = 4;

/// The tree with the junction at the end of `merge.0` merged into the upstream one (centred
/// the fraction `at` along it), the close merges `merge.1` centred so too, and any pair that
/// overlaps after that merged too.
pub(super) fn merged_tree(
    centerlines: &Centerlines,
    config: &MeshConfig,
    surface: &LumenSurface,
    (segment, close): (usize, &[usize]),
    at: f64,
    policy: &LayoutPolicy,
) -> Result<CenterlineTree> {
    let mut forced = vec![ForcedMerge { segment, at }];
    forced.extend(close.iter().filter(|&&c| c != segment).map(|&c| ForcedMerge { segment: c, at }));
    let close_count = forced.len() - 1;
    loop {
        let tree = CenterlineTree::build_merging(centerlines, &config.centerline, Some(surface), &forced)?;
        let junctions = analyse_junctions(&tree, surface, policy)?;
        let Some(overlap) = find_junction_overlap(&tree, &junctions, surface) else { return Ok(tree) };
        let next = tree.segments[overlap.branch];
        if forced.len() - close_count >= MAX_FORCED_MERGES || forced.iter().any(|f| f.segment == next) {
            return Err(overlap.error);
        }
        forced.push(ForcedMerge { segment: next, at });
    }
}

/// The polyline whose last point lies nearest `point` (the extraction's paths end at their
/// ends' centres; the first of equals), and that distance.
fn path_to(centerlines: &Centerlines, point: &[f64; 3]) -> Option<(usize, f64)> {
    let p = Point3::from(*point);
    let gap = |k: usize| centerlines.polylines[k].points.last().map_or(f64::INFINITY, |q| (q - p).norm());
    (0..centerlines.polylines.len()).min_by(|&a, &b| gap(a).total_cmp(&gap(b))).map(|k| (k, gap(k)))
}

/// The centerlines without the paths to `points`: for each point, the polyline whose last point
/// lies nearest it (the extraction's paths end at their ends' centres).
pub(super) fn without_paths_to(centerlines: &Centerlines, points: &[[f64; 3]]) -> Centerlines {
    let lines = &centerlines.polylines;
    let dropped: Vec<usize> = points.iter().filter_map(|p| path_to(centerlines, p).map(|(k, _)| k)).collect();
    Centerlines {
        polylines: (0..lines.len()).filter(|k| !dropped.contains(k)).map(|k| lines[k].clone()).collect(),
        source: centerlines.source.clone(),
    }
}
