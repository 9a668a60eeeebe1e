//! Projection of the O-grid onto the lumen surface, and the choice of where the mesh starts and
//! ends along a branch.
//!
//! Every centerline sample is probed with the rays of its section. A section is *clean* when
//! every ray meets the surface from the inside and no hit triangle faces along the axis (a cap
//! would). The mesh runs between the first and the last clean sections, a margin away from a
//! closed end, so no lumen node lands on a cap or beyond an open end; every section in between
//! must at least be *valid* (every ray hits from the inside): cast from the centerline, from a
//! point deeper in the lumen, or built on the closed loop where the section's plane cuts the
//! surface ([`cut`]); otherwise the run stops with the place and the cause.

use crate::data::error::{Error, Result};
use crate::geometry::mesh::closest_on_segment;
use crate::geometry::surface::LumenSurface;
use crate::geometry::vector::smoothstep;
use crate::stages::centerline::{Branch, CenterlineSample};
use crate::stages::junction::blocks::SectionTemplate;
use crate::stages::junction::{transition_points, FoldEnd, JunctionGeometry, TransitionPoints};
use crate::stages::projection::end_planes::EndCaps;
use nalgebra::{Point3, Rotation3, Vector2, Vector3};
use rayon::prelude::*;

mod cut;
mod dome;
pub mod end_planes;
pub mod plan;
pub use dome::DomeTop;

/// Least stretch of ordinary sections a branch is meshed with, in end radii (the sum of the
/// stretch's two end radii: half of it is one mean radius). Between two junctions' transitions,
/// less and the branch is a bridge; [`project_branch`] holds every stretch to the same, so no
/// branch falls between the two (random trees 47 and 66, 1.0 and 1.3 mm between transitions,
/// tree 66's for radii of 2.35 mm, were above the bridges' old 0.25 and below the sections' 0.5:
/// refused as too short to mesh).
pub const MIN_ORDINARY_STRETCH: f64 = 0.5;
/// Hit triangles whose normal is within this cosine of the axis mark a cap (about 70 degrees
/// from the wall direction of a tube) ...
const CAP_NORMAL_COS: f64 = 0.35;
/// ... or, in the half of a branch that ends closed but not in a turned flat cap (a dome, or a
/// vessel tapering into one), within this cosine (about 50 degrees): a section there meets a
/// wall leaning up to 40 degrees into the dome. The pulmonary bifurcation's daughters taper at
/// about 24 degrees into their domes, and with the tighter limit one kept no ordinary section;
/// the voxel aorta's outlet dome was left 50 mm short (now 5.5 mm, minimum scaled Jacobian at
/// medium 0.243 -> 0.275). A limit of 0.7 took that aorta to 0.205 at medium.
const DOME_NORMAL_COS: f64 = 0.65;
/// How far beyond the outer block surface a ray may still meet the surface (ray lengths).
const RAY_SLACK: f64 = 1.5;
/// Distance kept from a closed end, relative to the local radius.
const CLOSED_END_MARGIN: f64 = 0.5;

/// The projected rays of one station.
#[derive(Debug, Clone)]
pub struct ProjectedSection {
    pub station: CenterlineSample,
    /// Every core grid node (template order).
    pub core: Vec<Point3<f64>>,
    /// Ray origins on the core square boundary, one per ring point.
    pub origins: Vec<Point3<f64>>,
    /// Unit ray directions (towards the outer block surface).
    pub dirs: Vec<Vector3<f64>>,
    /// Lumen-surface nodes: where each ray meets the surface.
    pub surface: Vec<Point3<f64>>,
    /// A section of a junction's transition (its inner nodes may be moved to raise quality).
    pub in_junction: bool,
}

/// What lies at one end of a meshed branch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BranchEnd {
    /// An inlet or outlet of the vessel, closed (capped) or open.
    Vessel { closed: bool },
    /// A junction: the end section is folded onto the junction's pages.
    Fold(FoldEnd),
    /// A blind branch's end (a saccular aneurysm's sac) closed by a dome of hexes: the branch's
    /// last sections are the dome's layers, its top grid is [`ProjectedBranch::dome`].
    Dome,
}

/// A branch's stations, all projected, in the direction of the flow.
#[derive(Debug, Clone)]
pub struct ProjectedBranch {
    /// Index of the branch in the centerline tree.
    pub branch: usize,
    pub sections: Vec<ProjectedSection>,
    /// Arc lengths where the ordinary sections start and end (at a junction, where the
    /// transition towards the folded section begins).
    pub s_start: f64,
    pub s_end: f64,
    pub start: BranchEnd,
    pub end: BranchEnd,
    /// Whether each end of the surface was found closed (capped) rather than open.
    pub inlet_closed: bool,
    pub outlet_closed: bool,
    /// Whether the surface's triangles face out of the lumen (they may face in).
    pub normals_outward: bool,
    /// The top of the dome closing a blind branch (its end is [`BranchEnd::Dome`]).
    pub dome: Option<DomeTop>,
}

/// A junction end of a branch, as the projection needs it.
#[derive(Clone, Copy)]
pub struct JunctionEnd<'a> {
    pub geometry: &'a JunctionGeometry,
    pub fold: FoldEnd,
    /// Arc length between the junction centre and the last ordinary section, mm.
    pub transition_length: f64,
}

/// What the rays of one section found.
#[derive(Debug, Clone, Default)]
struct Probe {
    misses: usize,
    /// The rays that met no wall.
    missed: Vec<usize>,
    /// Hits on a triangle seen from outside the lumen.
    from_outside: usize,
    /// Largest |normal . tangent| over the hit triangles.
    axial_normal: f64,
}

impl Probe {
    fn valid(&self) -> bool {
        self.misses == 0 && self.from_outside == 0
    }
}

fn where_(s: &CenterlineSample) -> String {
    format!("at ({:.3}, {:.3}, {:.3}) mm, {:.2} mm along the centerline", s.point.x, s.point.y, s.point.z, s.s)
}

/// Casts rays from the core boundary of a section towards their targets. `orientation` is +1
/// when triangle normals face out of the lumen, -1 when they face in.
fn cast_rays(
    template: &SectionTemplate,
    surface: &LumenSurface,
    station: &CenterlineSample,
    core: Vec<Point3<f64>>,
    targets: &[Point3<f64>],
    orientation: f64,
) -> (Probe, ProjectedSection) {
    let m = template.ring_len();
    let mut probe = Probe::default();
    let mut section = ProjectedSection {
        station: *station,
        origins: Vec::with_capacity(m),
        dirs: Vec::with_capacity(m),
        surface: Vec::with_capacity(m),
        core,
        in_junction: false,
    };
    for (k, target) in targets.iter().enumerate() {
        let origin = section.core[template.ring_core_index[k]];
        let d = target - origin;
        let len = d.norm();
        let dir = d / len;
        match surface.first_hit(&origin, &dir, len * RAY_SLACK) {
            Some(hit) => {
                let n = surface.normals[hit.triangle as usize];
                if orientation != 0.0 && n.dot(&dir) * orientation <= 0.0 {
                    probe.from_outside += 1;
                }
                probe.axial_normal = probe.axial_normal.max(n.dot(&station.frame.tangent).abs());
                section.surface.push(hit.point);
            }
            None => {
                probe.misses += 1;
                probe.missed.push(k);
                section.surface.push(origin + dir * len);
            }
        }
        section.origins.push(origin);
        section.dirs.push(dir);
    }
    (probe, section)
}

/// Casts the rays of an ordinary station.
fn cast_section(
    template: &SectionTemplate,
    surface: &LumenSurface,
    station: &CenterlineSample,
    orientation: f64,
) -> (Probe, ProjectedSection) {
    let core = template.core.iter().map(|c| template.place(station, c)).collect();
    let targets: Vec<Point3<f64>> =
        template.target_dir.iter().map(|d| template.place(station, &(d * template.ray_reach))).collect();
    cast_rays(template, surface, station, core, &targets, orientation)
}

/// Rays cast from a section's centre over its plane to find its wall (per template target
/// direction), and the candidates searched for a centre inside the lumen.
const RECENTRE_RINGS: usize = 4;
const RECENTRE_SPOKES: usize = 12;

/// Whether a point lies inside the lumen: the first wall met along a few directions is seen
/// from inside (a consistently wound surface's first hit from inside faces away).
fn inside_lumen(surface: &LumenSurface, p: &Point3<f64>, orientation: f64, reach: f64) -> bool {
    [Vector3::x(), Vector3::y(), Vector3::z(), -Vector3::x()].iter().all(|d| {
        surface.first_hit(p, d, reach).is_some_and(|h| surface.normals[h.triangle as usize].dot(d) * orientation > 0.0)
    })
}

/// Whether the section at `station`, `probe` cast from its centerline point, closes: from there,
/// or from inside the lumen (see [`recentred_section`]), or on the plane's cut (see [`cut`]).
fn section_closes(
    probe: &Probe,
    template: &SectionTemplate,
    surface: &LumenSurface,
    station: &CenterlineSample,
    orientation: f64,
) -> bool {
    probe.valid()
        || recentred_section(template, surface, station, orientation).0.valid()
        || cut::cut_section(template, surface, station, orientation).is_some_and(|c| c.0.valid())
}

/// A section cast from the lumen itself rather than from the centerline's point: where the
/// ordinary section's rays do not all meet the wall from inside (a tight or eccentric stenosis,
/// a kink, a lumen whose smoothed centerline runs near one side), the section's centre moves,
/// within its plane, to the point of it furthest inside the lumen near the centerline, the rays
/// from there find the section's wall (a closed loop around an inside point: every ray meets
/// it from inside), and the core shrinks until its boundary lies within [`CORE_REACH`] of that
/// wall. The plane and the frame are the station's, so the section stays one of the branch's.
fn recentred_section(
    template: &SectionTemplate,
    surface: &LumenSurface,
    station: &CenterlineSample,
    orientation: f64,
) -> (Probe, ProjectedSection) {
    let f = &station.frame;
    let r = station.radius;
    let reach = RAY_SLACK * template.ray_reach * r * 2.0;
    let depth = |p: &Point3<f64>| -> Option<f64> {
        inside_lumen(surface, p, orientation, reach).then(|| surface.closest(p).distance)
    };
    // The deepest of a polar grid of candidates within the section's radius.
    let mut best: Option<(f64, Point3<f64>)> = depth(&station.point).map(|d| (d, station.point));
    for ring in 1..=RECENTRE_RINGS {
        for k in 0..RECENTRE_SPOKES {
            let phi = std::f64::consts::TAU * k as f64 / RECENTRE_SPOKES as f64;
            let rho = r * ring as f64 / RECENTRE_RINGS as f64;
            let p = station.point + (f.normal * phi.cos() + f.binormal * phi.sin()) * rho;
            if let Some(d) = depth(&p) {
                if best.is_none_or(|(b, _)| d > b) {
                    best = Some((d, p));
                }
            }
        }
    }
    let Some((_, centre)) = best else {
        return cast_section(template, surface, station, orientation);
    };
    let moved = CenterlineSample { point: centre, ..*station };
    // The wall along each ray direction, from the centre.
    let wall: Vec<Option<f64>> = template
        .target_dir
        .iter()
        .map(|d| {
            let dir = f.normal * d.x + f.binormal * d.y;
            surface.first_hit(&centre, &dir, reach).map(|h| h.distance)
        })
        .collect();
    if wall.iter().any(Option::is_none) {
        return cast_section(template, surface, &moved, orientation);
    }
    // The core shrunk about the centre until each ring node lies within CORE_REACH of the way
    // to the wall in its direction.
    let mut shrink: f64 = 1.0;
    for (k, w) in wall.iter().enumerate() {
        let c = template.core[template.ring_core_index[k]];
        let along = c.norm() * r;
        if along > 0.0 {
            let dir = template.target_dir[k];
            let cos = (c.dot(&dir) / c.norm()).max(0.1);
            shrink = shrink.min(CORE_REACH * w.expect("checked") * cos / along);
        }
    }
    let core: Vec<Point3<f64>> = template.core.iter().map(|c| template.place(&moved, &(c * shrink))).collect();
    let targets: Vec<Point3<f64>> = template
        .target_dir
        .iter()
        .zip(&wall)
        .map(|(d, w)| centre + (f.normal * d.x + f.binormal * d.y) * (w.expect("checked") / RAY_SLACK * 0.999))
        .collect();
    cast_rays(template, surface, &moved, core, &targets, orientation)
}

/// An ordinary section: cast from the centerline, or recentred in the lumen where that does not
/// close (see [`recentred_section`]), or built on the plane's cut through the surface where
/// neither does (see [`cut`]).
fn ordinary_section(
    template: &SectionTemplate,
    surface: &LumenSurface,
    station: &CenterlineSample,
    orientation: f64,
) -> (Probe, ProjectedSection) {
    let cast = cast_section(template, surface, station, orientation);
    if cast.0.valid() {
        return cast;
    }
    let recentred = recentred_section(template, surface, station, orientation);
    if recentred.0.valid() {
        return recentred;
    }
    match cut::cut_section(template, surface, station, orientation) {
        Some(cut) if cut.0.valid() => cut,
        _ => cast,
    }
}

/// Everything `project_branch` needs besides the branch.
pub struct ProjectionSetup<'a> {
    pub template: &'a SectionTemplate,
    pub surface: &'a LumenSurface,
    pub spacing: &'a (dyn Fn(&CenterlineSample) -> f64 + Sync),
    /// The axial spacing of a junction's transitions and bridges (see
    /// [`crate::data::config::LumenConfig::junction_axial_spacing`]).
    pub junction_spacing: &'a (dyn Fn(&CenterlineSample) -> f64 + Sync),
    pub trim_inlet: f64,
    pub trim_outlet: f64,
    pub normals_outward: bool,
    /// A branch shorter than its junction's transition estimate may take a clear section nearer
    /// the junction (see [`clear_transition_length`]). Off while a merged junction's centre is
    /// searched: a centring that leaves a branch too short is left to the next one.
    pub steep_short_branches: bool,
    /// The branch ends blind (a saccular aneurysm's sac): its end is closed by a dome of hexes.
    pub dome_end: bool,
}

/// Finds the meshable part of a branch and projects its stations: ordinary sections between
/// the vessel's ends (trimmed as the surface requires) or the transitions towards junctions,
/// then the transition sections down to each folded end. `caps` are the flat caps its end
/// sections were turned into (see [`crate::stages::projection::end_planes`]).
pub fn project_branch(
    branch: &Branch,
    caps: &EndCaps,
    index: usize,
    setup: &ProjectionSetup,
    start_junction: Option<&JunctionEnd>,
    end_junction: Option<&JunctionEnd>,
) -> Result<ProjectedBranch> {
    let ProjectionSetup { template, surface, spacing, trim_inlet, trim_outlet, normals_outward, .. } = *setup;
    let samples = &branch.samples;
    let orient = if normals_outward { 1.0 } else { -1.0 };
    let length = branch.length();
    let lo = start_junction.map_or(0.0, |j| j.transition_length);
    let hi = end_junction.map_or(length, |j| length - j.transition_length);
    let name = &branch.name;
    if let (Some(a), Some(b)) = (start_junction, end_junction) {
        if is_bridge(lo, hi, length) {
            return Ok(ProjectedBranch {
                branch: index,
                sections: bridge(a, b, &branch.at(lo), setup, branch)?,
                s_start: lo,
                s_end: lo,
                start: BranchEnd::Fold(a.fold),
                end: BranchEnd::Fold(b.fold),
                inlet_closed: false,
                outlet_closed: false,
                normals_outward,
                dome: None,
            });
        }
    }
    // A sac's transition may run to its end, the centre of the sac's largest ball (see
    // `clear_transition_length`): its last section stands there, the dome beyond.
    let sac = setup.dome_end && start_junction.is_some() && end_junction.is_none();
    // Whether the sections past a transition suffice is decided below, on the clean ones.
    if hi <= lo && !(sac && lo <= length) {
        return Err(Error::Geometry(format!(
            "{}: branch {name} ({length:.2} mm long) ends within its junction's transition ({:.2} mm): mesh a longer \
             stretch of the vessel",
            surface.source.display(),
            lo.max(length - hi)
        )));
    }
    let Probed { probes, clean, inlet_closed, outlet_closed, dome_start, dome_end } =
        probe_branch(branch, caps, setup, (lo, hi), start_junction.is_some(), end_junction.is_some());
    let (i0, i1) = clean_span(branch, setup, &probes, &clean, start_junction.is_some(), end_junction.is_some())?;
    let closes = |i: usize, p: &Probe| section_closes(p, template, surface, &samples[i], orient);
    // A closed end keeps a margin from its cap, unless the sections were turned into the cap's
    // plane (they run parallel to it, clear of it).
    let r0 = samples[i0].radius;
    let r1 = samples[i1].radius;
    let s_start = match start_junction {
        Some(_) => lo,
        None => samples[i0].s + r0 * (trim_inlet + if dome_start { CLOSED_END_MARGIN } else { 0.0 }),
    };
    let s_end = match end_junction {
        Some(_) => hi,
        None => samples[i1].s - r1 * (trim_outlet + if dome_end { CLOSED_END_MARGIN } else { 0.0 }),
    };
    // A sac's branch ends at the centre of the sac's largest ball, its dome a ball's radius
    // ahead: a hemisphere, the dome's own case (see `dome::project_dome`), which needs no margin
    // from the tip. A compact sac, a ball on its vessel's side whose centre lies a vessel radius
    // or two from the axis (random tree 3: 3.2 mm out of a vessel of 1.2 mm), leaves no room for
    // the margin past its junction's transition, so its last section stands at the ball's centre.
    let s_end = match end_junction {
        None if setup.dome_end && s_end - s_start < MIN_ORDINARY_STRETCH * (r0 + r1) => samples[i1].s,
        _ => s_end,
    };
    // Between the ends, a section that does not close from the centerline may from inside the
    // lumen (see `recentred_section`).
    if let Some((bad, p)) = probes.iter().find(|(i, p)| {
        samples[*i].s >= samples[i0].s.min(s_start) && samples[*i].s <= samples[i1].s.max(s_end) && !closes(*i, p)
    }) {
        return Err(Error::Geometry(format!(
            "{}: the cross-section of branch {name} {} does not close: {} of {} rays miss the lumen surface and {} \
             meet it from outside, and its plane cuts the surface in no closed loop around the centerline. The \
             surface may have a hole there, or the plane leans out through an open vessel end nearby; repair the \
             surface, clip the end square across, or smooth the centerline (centerline.smoothing_passes)",
            surface.source.display(),
            where_(&samples[*bad]),
            p.misses,
            template.ring_len(),
            p.from_outside
        )));
    }
    // A vessel end too close to its junction for a stretch of ordinary sections (a short branch
    // clipped obliquely): the transition runs on to the end's section, the only ordinary one.
    let stub = start_junction.is_some() != end_junction.is_some()
        && (s_end > s_start || sac && s_end >= s_start)
        && s_end - s_start < MIN_ORDINARY_STRETCH * (r0 + r1);
    if s_end - s_start < MIN_ORDINARY_STRETCH * (r0 + r1) && !stub {
        return Err(Error::Geometry(format!(
            "{}: only {:.3} mm of branch {name} (from {:.2} to {:.2} mm) has clean cross-sections, too short to \
             mesh; reduce centerline.trim_inlet/trim_outlet or check the surface's ends",
            surface.source.display(),
            (s_end - s_start).max(0.0),
            s_start,
            s_end
        )));
    }

    let (s_start, s_end) = match (stub, start_junction.is_some()) {
        (false, _) => (s_start, s_end),
        (true, true) => (s_end, s_end),
        (true, false) => (s_start, s_start),
    };
    let start_junction = start_junction
        .map(|j| JunctionEnd { transition_length: if stub { s_start } else { j.transition_length }, ..*j });
    let end_junction = end_junction
        .map(|j| JunctionEnd { transition_length: if stub { length - s_end } else { j.transition_length }, ..*j });
    let positions = if stub {
        vec![s_start]
    } else {
        crate::stages::junction::blocks::station_positions(s_start, s_end, |s| spacing(&branch.at(s)))
    };
    let ordinary = ordinary_sections(branch, setup, &positions)?;

    let (out, start, end, dome) = join_ends(
        branch,
        setup,
        ordinary,
        start_junction.as_ref(),
        end_junction.as_ref(),
        inlet_closed,
        outlet_closed,
    )?;
    Ok(ProjectedBranch {
        branch: index,
        sections: out,
        s_start,
        s_end,
        start,
        end,
        inlet_closed,
        outlet_closed,
        normals_outward,
        dome,
    })
}

/// The probes of a branch's samples between `lo` and `hi` (away from its junctions), as
/// [`project_branch`] decides where its vessel ends are clean.
struct Probed {
    /// Each sample's index and probe.
    probes: Vec<(usize, Probe)>,
    /// Per sample: its section meets the vessel's wall, not its end.
    clean: Vec<bool>,
    inlet_closed: bool,
    outlet_closed: bool,
    /// A closed end whose sections were not turned into a flat cap: a dome (or a square cap).
    dome_start: bool,
    dome_end: bool,
}

fn probe_branch(
    branch: &Branch,
    caps: &EndCaps,
    setup: &ProjectionSetup,
    (lo, hi): (f64, f64),
    start_junction: bool,
    end_junction: bool,
) -> Probed {
    let ProjectionSetup { template, surface, normals_outward, .. } = *setup;
    let samples = &branch.samples;
    let orient = if normals_outward { 1.0 } else { -1.0 };
    let length = branch.length();
    // Only the samples away from junctions decide where a vessel end is clean.
    let inside: Vec<usize> = (0..samples.len()).filter(|&i| samples[i].s >= lo && samples[i].s <= hi).collect();
    // Each probe, and for a section turned into a flat cap (`end_planes`) whether a ray ends on
    // the cap's plane.
    let cast: Vec<(usize, Probe, Option<bool>)> = inside
        .par_iter()
        .map(|&i| {
            let (probe, section) = cast_section(template, surface, &samples[i], orient);
            let cap = caps.turning_at(samples[i].s, length);
            let on_cap = cap.map(|cap| section.surface.iter().any(|p| cap.holds(p)));
            (i, probe, on_cap)
        })
        .collect();
    // A closed end (every ray of the end sample hits) ...
    let inlet_closed = !start_junction && cast.first().is_some_and(|c| c.1.valid());
    let outlet_closed = !end_junction && cast.last().is_some_and(|c| c.1.valid());
    // ... whose sections were not turned into a flat cap: a dome (or a square cap).
    let dome_start = inlet_closed && caps.start.is_none();
    let dome_end = outlet_closed && caps.end.is_none();
    // A clean section meets the vessel's wall, not its end. A turned section meets the cap only
    // where a ray ends on its plane, however steeply the wall flares from the cap; the others
    // by the hit triangles' lean (see CAP_NORMAL_COS).
    let mut clean = vec![false; samples.len()];
    for (i, probe, on_cap) in &cast {
        let s = samples[*i].s;
        let limit = if (dome_start && s < 0.5 * length) || (dome_end && s >= 0.5 * length) {
            DOME_NORMAL_COS
        } else {
            CAP_NORMAL_COS
        };
        clean[*i] = probe.valid()
            && match on_cap {
                Some(on_cap) => !on_cap,
                None => probe.axial_normal < limit,
            };
    }
    let probes: Vec<(usize, Probe)> = cast.into_iter().map(|(i, p, _)| (i, p)).collect();

    Probed { probes, clean, inlet_closed, outlet_closed, dome_start, dome_end }
}

/// The first and last sample of the stretch to mesh between clean sections, stopped short of
/// a section that closes neither from the centerline nor from inside the lumen in the half of
/// the branch towards a vessel end. An error when no section of the branch is clean.
fn clean_span(
    branch: &Branch,
    setup: &ProjectionSetup,
    probes: &[(usize, Probe)],
    clean: &[bool],
    start_junction: bool,
    end_junction: bool,
) -> Result<(usize, usize)> {
    let ProjectionSetup { template, surface, normals_outward, .. } = *setup;
    let samples = &branch.samples;
    let orient = if normals_outward { 1.0 } else { -1.0 };
    let length = branch.length();
    let name = &branch.name;
    // A junction end needs no clean section (no cap can be there): every section is checked
    // valid below.
    let first_clean = probes.iter().find(|(i, _)| clean[*i] || start_junction).map(|(i, _)| *i);
    let last_clean = probes.iter().rev().find(|(i, _)| clean[*i] || end_junction).map(|(i, _)| *i);
    let (i0, i1) = match (first_clean, last_clean) {
        (Some(a), Some(b)) if a < b || (a == b && (start_junction || end_junction)) => (a, b),
        _ if setup.dome_end && start_junction && !end_junction => {
            // A sac's sections all meet its wall at a slant (the dome leaning into them) or run
            // into the junction: the pocket is no blind tube a dome could close.
            return Err(Error::Geometry(format!(
                "{}: the sac at the end of branch {name} ({length:.2} mm from its junction) cannot be meshed as a \
                 blind branch closed by a dome: none of its cross-sections meets the sac's wall square enough for a \
                 section (its wall leans into every one, as a pocket's opening into its junction does)",
                surface.source.display(),
            )));
        }
        _ => {
            let mid = &samples[samples.len() / 2];
            let p = cast_section(template, surface, mid, orient).0;
            return Err(Error::Geometry(format!(
                "{}: no cross-section of branch {name} has all its rays meeting the lumen wall from inside (in the \
                 middle of the centerline, {} {} of {} rays miss the surface and {} hit it from outside). The \
                 centerline is not inside this surface: check that both files belong to the same vessel and are \
                 in the same units (--units)",
                surface.source.display(),
                where_(mid),
                p.misses,
                template.ring_len(),
                p.from_outside
            )));
        }
    };
    // A section that closes neither from the centerline nor from inside the lumen, and whose
    // plane passes through the opening of the vessel end on its side (the vessel bends just
    // before its end), misses through that opening: the mesh stops short of it on that side, at
    // the next clean section (an end cut well short is said by its warning). Elsewhere such a
    // section misses through a hole in the wall, refused below.
    let closes = |i: usize, p: &Probe| section_closes(p, template, surface, &samples[i], orient);
    let crosses_opening = |i: usize, end: &CenterlineSample| {
        (end.point - samples[i].point).dot(&samples[i].frame.tangent).abs() <= end.radius
    };
    let (first, last) = (&samples[0], &samples[samples.len() - 1]);
    let (mut i0, mut i1) = (i0, i1);
    let half = 0.5 * length;
    if !start_junction {
        let bad = probes.iter().rev().find(|(i, p)| {
            *i >= i0 && *i <= i1 && samples[*i].s < half && !closes(*i, p) && crosses_opening(*i, first)
        });
        if let Some(next) = bad.and_then(|&(b, _)| probes.iter().find(|(i, _)| *i > b && clean[*i]).map(|c| c.0)) {
            i0 = next.min(i1);
        }
    }
    if !end_junction {
        let bad = probes.iter().find(|(i, p)| {
            *i >= i0 && *i <= i1 && samples[*i].s >= half && !closes(*i, p) && crosses_opening(*i, last)
        });
        if let Some(prev) = bad.and_then(|&(b, _)| probes.iter().rev().find(|(i, _)| *i < b && clean[*i]).map(|c| c.0))
        {
            i1 = prev.max(i0);
        }
    }
    Ok((i0, i1))
}

/// The ordinary sections at `positions` along the branch; an error names the first that does
/// not close.
fn ordinary_sections(branch: &Branch, setup: &ProjectionSetup, positions: &[f64]) -> Result<Vec<ProjectedSection>> {
    let ProjectionSetup { template, surface, normals_outward, .. } = *setup;
    let orient = if normals_outward { 1.0 } else { -1.0 };
    let name = &branch.name;
    let sections: Vec<(Probe, ProjectedSection)> =
        positions.par_iter().map(|&s| ordinary_section(template, surface, &branch.at(s), orient)).collect();
    let mut ordinary = Vec::with_capacity(sections.len());
    for (probe, section) in sections {
        if !probe.valid() {
            return Err(Error::Geometry(format!(
                "{}: ray cast failed for the station of branch {name} {}: {} rays miss the surface, {} meet it \
                 from outside",
                surface.source.display(),
                where_(&section.station),
                probe.misses,
                probe.from_outside
            )));
        }
        ordinary.push(section);
    }

    Ok(ordinary)
}

/// The branch's sections with its ends added: the transitions down to each junction's fold,
/// and the dome closing a blind end; with what lies at each end.
fn join_ends(
    branch: &Branch,
    setup: &ProjectionSetup,
    ordinary: Vec<ProjectedSection>,
    start_junction: Option<&JunctionEnd>,
    end_junction: Option<&JunctionEnd>,
    inlet_closed: bool,
    outlet_closed: bool,
) -> Result<(Vec<ProjectedSection>, BranchEnd, BranchEnd, Option<DomeTop>)> {
    let ProjectionSetup { template, surface, spacing, normals_outward, .. } = *setup;
    let orient = if normals_outward { 1.0 } else { -1.0 };
    let name = &branch.name;
    let mut out = Vec::new();
    if let Some(j) = &start_junction {
        let mut t = transition(j, &ordinary[0], -1.0, setup, branch)?;
        t.reverse();
        out.extend(t);
    }
    out.extend(ordinary);
    if let Some(j) = &end_junction {
        let last = out[out.len() - 1].clone();
        out.extend(transition(j, &last, 1.0, setup, branch)?);
    }
    let start = match start_junction {
        Some(j) => BranchEnd::Fold(j.fold),
        None => BranchEnd::Vessel { closed: inlet_closed },
    };
    let mut dome = None;
    let end = match end_junction {
        Some(j) => BranchEnd::Fold(j.fold),
        None if setup.dome_end => {
            let last = &out[out.len() - 1];
            let (layers, top) = dome::project_dome(template, surface, last, spacing, orient).map_err(|cause| {
                Error::Geometry(format!(
                    "{}: the sac at the end of branch {name} cannot be closed by a dome beyond its last \
                     cross-section {}: {cause}. Give centerlines that reach the sac's tip (--centerlines)",
                    surface.source.display(),
                    where_(&last.station)
                ))
            })?;
            out.extend(layers);
            dome = Some(top);
            BranchEnd::Dome
        }
        None => BranchEnd::Vessel { closed: outlet_closed },
    };
    Ok((out, start, end, dome))
}

/// Whether every ray of the section at `base` meets the wall from inside within
/// [`CLEAR_REACH`] of its radius (a ray that runs further has found a neighbouring branch), at
/// each of [`CLEAR_TURNS`] turns over the O-grid's period: the frames are turned afterwards to
/// meet the junctions (a quarter turn for a square core, a half turn for a rectangular one), so
/// the section must be clear whatever the final turn.
fn rays_clear(setup: &ProjectionSetup, base: CenterlineSample) -> bool {
    let orient = if setup.normals_outward { 1.0 } else { -1.0 };
    let period =
        if setup.template.nx == setup.template.ny { std::f64::consts::FRAC_PI_2 } else { std::f64::consts::PI };
    let spacing_angle = period / CLEAR_TURNS as f64;
    (0..CLEAR_TURNS).all(|t| {
        let phi = spacing_angle * t as f64;
        let f = base.frame;
        let normal = f.normal * phi.cos() + f.binormal * phi.sin();
        let st = CenterlineSample {
            frame: crate::stages::centerline::Frame::from_tangent_and_hint(f.tangent, normal),
            ..base
        };
        let (probe, sec) = cast_section(setup.template, setup.surface, &st, orient);
        probe.valid() && sec.surface.iter().all(|p| (p - st.point).norm() <= CLEAR_REACH * st.radius)
    })
}

/// How far the centerline (`at`, by distance from a junction) strays between distances `from`
/// and `to` from the straight line between its points there, sampled every `spacing` or less.
fn bow(at: &dyn Fn(f64) -> CenterlineSample, from: f64, to: f64, spacing: f64) -> f64 {
    let (a, b) = (at(from).point, at(to).point);
    let samples = ((to - from) / spacing).ceil().max(1.0) as usize;
    (1..samples)
        .map(|k| {
            let q = at(from + (to - from) * k as f64 / samples as f64).point;
            (q - closest_on_segment(&q, &a, &b)).norm()
        })
        .fold(0.0, f64::max)
}

/// Whether a branch between two junctions is a bridge (see [`bridge`]): the plan gives each
/// junction half of it.
fn is_bridge(lo: f64, hi: f64, length: f64) -> bool {
    hi - lo <= 1e-9 * length
}

/// A section clears a junction when its rays all meet the wall from inside within this many
/// local radii of the centerline (a ray that runs further has found a neighbouring branch).
const CLEAR_REACH: f64 = 2.0;
/// Turns of the ray set tried per clear-section test, over the O-grid's period.
const CLEAR_TURNS: usize = 12;
/// A last ordinary section must be followed by this many clear ones, a quarter radius apart.
const CLEAR_RUN_STEPS: usize = 8;
/// Distance from a vessel end within which the clear run is not checked, in radii.
const FAR_END_MARGIN: f64 = 1.5;
/// Least distance between a junction's last ordinary section and a vessel end, in radii.
const OUTLET_KEEP: f64 = 0.25;
/// How far the folded end's wall points must lie ahead of the last ordinary section, in radii.
/// Merely ahead is not enough: two mutated arches whose best sections had the fold 0.06 and
/// 0.99 mm ahead (0.08 and 0.21 radii) gave 406 and 400 inverted junction elements.
const FOLD_MARGIN: f64 = 0.25;
/// Largest curvature of the centerline where ordinary sections may stand, times the radius
/// (a radius of curvature of two vessel radii).
const MAX_BEND: f64 = 0.5;
/// Largest curvature, times the radius, at which neighbouring sections of the vessel's radius do
/// not cross inside the lumen (a radius of curvature of one vessel radius): where no section
/// past a junction stands on a gentle bend, the last ordinary one may stand on one up to this.
const MAX_BEND_UNCROSSED: f64 = 1.0;
/// Farthest the centerline between the estimate of a transition's length and its last
/// ordinary section may stray from the straight line between them, in branch radii: half way
/// to the wall, a transition interpolated between its ends no longer runs along the vessel.
/// It follows a steady bend (its ends' tangents are the centerline's), which strays little
/// (random tree 34's parent, 69 degrees over two radii: 0.32), not a hairpin, which strays far
/// (random tree 73's host, a 123-degree bend on 1.5 radii: 1.47; the section found stood 52 mm
/// past the junction, the transition's sections cut across the bend and 146 elements were
/// inverted). Past such a bow, the run of sections after the last may stand on the bend at
/// which ordinary sections do not cross, as anywhere else in a vessel, and the search stops
/// short of the hairpin (17 mm). Elsewhere the gentle run is kept: it draws a funnel out over
/// more sections (tree 34's parent cut short: an intima element 0.219 -> 0.176).
const MAX_TRANSITION_BOW: f64 = 0.5;
/// Length over which the curvature is measured, in radii.
const BEND_BASE: f64 = 1.0;
/// How far beyond the estimate the search for a clear section goes, in branch radii.
const CLEAR_SEARCH: f64 = 6.0;
/// Nearest a junction's last ordinary section may stand to its centre, in branch radii.
const NEAREST_SECTION: f64 = 0.5;

/// The distance from a junction's centre, along a branch, of its last ordinary section: the
/// geometric estimate of [`crate::stages::junction::transition_length`], moved away from the junction
/// until the section and the next radius of the branch are clear of the other branches (or, on
/// a branch ending short of the estimate, towards the junction when `steep_short_branches`
/// allows). None when the branch runs to another junction and no section of this junction's half of it is
/// clear: the branch is then a bridge (see [`bridge`]).
pub fn clear_transition_length(
    geometry: &JunctionGeometry,
    slot: usize,
    branch: &Branch,
    at_start: bool,
    setup: &ProjectionSetup,
) -> Result<Option<f64>> {
    let r = geometry.slots[slot].radius;
    let len = branch.length();
    let far_junction = if at_start { branch.end_junction.is_some() } else { branch.start_junction.is_some() };
    // The run of clear sections need not reach beyond the branch's own part: up to its middle
    // when a junction ends it too, else short of its far end, whose sections the vessel end
    // decides (an open end's rays run out of the lumen). Towards a vessel end the last ordinary
    // section itself may stand closer: whether clean sections remain past it is decided by
    // project_branch (a short branch keeps only its end's section).
    let (run_reach, reach) =
        if far_junction { (0.5 * len, 0.5 * len) } else { (len - FAR_END_MARGIN * r, len - OUTLET_KEEP * r) };
    // A sac's branch ends at the centre of the sac's largest ball, a ball's radius short of the
    // tip, which its dome closes (see `project_branch`): its last section may stand there.
    let sac = setup.dome_end && !far_junction;
    let reach = if sac { len } else { reach };
    let before_far_end = |d: f64| if sac { d <= len } else { d < 0.9 * len };
    let estimate = crate::stages::junction::transition_length(geometry, slot);
    let at = |d: f64| branch.at(if at_start { d } else { len - d });
    // Ordinary sections are planes across the centerline: where it bends on a radius of
    // curvature near the vessel's radius (it often swings towards the junction centre in its
    // last radius or two), neighbouring sections cross on the inner side of the bend.
    let gentle_bend = |d: f64, max_bend: f64| {
        let half = 0.5 * BEND_BASE * r;
        let (a, b) = (at(d - half).frame.tangent, at(d + half).frame.tangent);
        a.angle(&b) * r / (2.0 * half) <= max_bend
    };
    // The folded end lies on the slot's two pages and the spine: where those meet the wall (the
    // crotches and the spine's ends) must lie ahead of the last ordinary section, or the
    // transition would run backwards there and fold over itself.
    let fold_wall = geometry.fold_wall(slot);
    let fold_clearance = |d: f64| {
        let st = at(d);
        let towards = if at_start { -st.frame.tangent } else { st.frame.tangent };
        fold_wall.iter().map(|w| (w - st.point).dot(&towards)).fold(f64::INFINITY, f64::min)
    };
    let fold_ahead = |d: f64| fold_clearance(d) >= FOLD_MARGIN * r;
    // The geometric test first: it costs nothing next to twelve sets of rays.
    let clear = |d: f64, max_bend: f64| gentle_bend(d, max_bend) && rays_clear(setup, at(d));
    let step = 0.25 * r;
    // The transition runs from the last ordinary section to the fold, so the fold must lie
    // ahead of that section only; the sections past it are ordinary ones and need only be
    // clear. A branch that curls back past the junction's level (palabos_cerebral_aneurysm: an
    // outlet leaving a sac 14 mm in radius turns back down by 30 mm) puts the spine's ends
    // behind its later sections, which asked of them too left no section anywhere.
    // `run_bend`: the bend the run's sections past the first may stand on.
    let last_section = |d: f64, max_bend: f64, run_bend: f64| {
        fold_ahead(d)
            && (0..=CLEAR_RUN_STEPS)
                .map(|k| d + k as f64 * step)
                .filter(|&x| x == d || x <= run_reach)
                .all(|x| clear(x, if x == d { max_bend } else { run_bend }))
    };
    let search = |max_bend: f64, run_bend: f64| {
        let mut d = estimate;
        while d < estimate + CLEAR_SEARCH * r && before_far_end(d) && d <= reach {
            if last_section(d, max_bend, run_bend) {
                return Some(d);
            }
            d += step;
        }
        None
    };
    if let Some(d) = search(MAX_BEND, MAX_BEND) {
        // Past a hairpin (see MAX_TRANSITION_BOW), the run may bend as ordinary sections do.
        let unbowed = |x: &f64| bow(&at, estimate, *x, r / 16.0) <= MAX_TRANSITION_BOW * r;
        let short = (!unbowed(&d)).then(|| search(MAX_BEND, MAX_BEND_UNCROSSED)).flatten();
        // Still past the hairpin (it begins a radius or two from the junction, before any section
        // on a gentle bend): the last section itself may stand on a bend of one vessel radius,
        // where ordinary sections do not cross, short of the hairpin, rather than past it with
        // the transition cut across the bend (random tree 1189).
        let short = match short {
            Some(x) if !unbowed(&x) => search(MAX_BEND_UNCROSSED, MAX_BEND_UNCROSSED).filter(unbowed).or(short),
            _ => short,
        };
        return Ok(Some(short.unwrap_or(d)));
    }
    // Between two junctions, no clear section in this junction's half: the branch is a bridge.
    if far_junction {
        return Ok(None);
    }
    // A branch shorter than the estimate (a wide trunk capped close to its junction): nearer the
    // junction, a clear section gives a steeper transition, but a mesh.
    // So may a sac's, when no section clears the junction between the estimate and its end.
    let mut d = reach;
    while setup.steep_short_branches && (estimate > reach || sac) && d >= NEAREST_SECTION * r {
        if last_section(d, MAX_BEND, MAX_BEND) {
            return Ok(Some(d));
        }
        d -= step;
    }
    // Still none: a stub's transition in fact runs from its end's own section (see
    // `project_branch`), past `reach`; the fold need lie ahead of that one only. (A dome's
    // section stands half a radius further in; should its transition fold, the elements say so.)
    let end_trim = if at_start { setup.trim_outlet } else { setup.trim_inlet };
    let end_section = len - end_trim * at(len).radius;
    if setup.steep_short_branches
        && estimate > reach
        && !sac
        && fold_clearance(end_section) >= FOLD_MARGIN * r
        && clear(reach, MAX_BEND)
    {
        return Ok(Some(reach));
    }
    // A bend tighter than the gentle one just past the junction, and the fold behind the
    // sections beyond it (a branch curling back): the bend that stops sections crossing inside
    // the lumen will do, and the elements decide.
    if let Some(d) = search(MAX_BEND_UNCROSSED, MAX_BEND_UNCROSSED) {
        return Ok(Some(d));
    }
    // A sac's last chance before it is left out: the section at its largest ball's centre, the
    // dome's base, on such a bend. The search steps past it and the steep one asks the gentle
    // bend, yet only the dome lies beyond it, which no later section can cross (random tree 17:
    // a sac 0.86 mm from its junction, the estimate 0.78 mm, meshes; min scaled Jacobian 0.211).
    if sac && last_section(len, MAX_BEND_UNCROSSED, MAX_BEND_UNCROSSED) {
        return Ok(Some(len));
    }
    let candidates = (0..).map(|k| estimate + k as f64 * step).take_while(|&x| before_far_end(x) && x <= reach);
    let searched = Searched {
        length: len,
        sac,
        estimate,
        reach,
        searched_to: d,
        fold_clearance: candidates.map(fold_clearance).fold(f64::NEG_INFINITY, f64::max),
        end: at(len),
    };
    Err(no_last_section(setup, branch, geometry, r, &searched))
}

/// What [`clear_transition_length`] searched, for the refusal when no section will do.
struct Searched {
    length: f64,
    sac: bool,
    /// The geometric estimate of the transition's length, and how far the last section may lie.
    estimate: f64,
    reach: f64,
    searched_to: f64,
    /// The most the fold's wall points lay ahead of any candidate section (mm).
    fold_clearance: f64,
    end: CenterlineSample,
}

/// Why no last ordinary section of a branch will do at a junction: a sac opening too close, a
/// branch too short for the transition, the fold reaching past every section, or no section
/// clear of the other branches.
fn no_last_section(
    setup: &ProjectionSetup,
    branch: &Branch,
    geometry: &JunctionGeometry,
    r: f64,
    s: &Searched,
) -> Error {
    let Searched { length: len, estimate, reach, searched_to: d, fold_clearance: best_clearance, .. } = *s;
    let place = format!(
        "{}: branch {} ({len:.1} mm long) at the junction at ({:.3}, {:.3}, {:.3}) mm",
        setup.surface.source.display(),
        branch.name,
        geometry.centre.x,
        geometry.centre.y,
        geometry.centre.z
    );
    if s.sac {
        // The sac's far end is its dome, not an opening a longer stretch of surface would move.
        return Error::ShortBranch {
            message: format!(
                "{place}: the sac cannot be meshed as a blind branch closed by a dome: no cross-section of the branch \
                 up to the centre of the sac's largest ball ({len:.2} mm from the junction, radius {:.2} mm) lies \
                 past the junction's folded end and clear of the other branches (the junction's transition needs \
                 {estimate:.2} mm): the sac opens too close to the junction",
                s.end.radius
            ),
            end_mm: s.end.point.into(),
        };
    }
    if estimate > reach {
        return Error::ShortBranch {
            message: format!(
                "{place}: the junction's transition needs {estimate:.1} mm of it, more than the branch leaves before \
                 its end ({reach:.1} mm): the branch ends too close to the junction. Mesh a longer stretch of the vessel"
            ),
            end_mm: s.end.point.into(),
        };
    }
    // The fold lying ahead of every candidate section, named when it is what no candidate met.
    if best_clearance.is_finite() && best_clearance < FOLD_MARGIN * r {
        return Error::Geometry(format!(
            "{place}: no cross-section of the branch up to {reach:.1} mm from the junction lies behind the \
             junction's folded end (laid out as {}): where its pages or sectors meet the wall lies at best \
             {best_clearance:.2} mm ahead of a section, {:.2} mm ({FOLD_MARGIN} radii) are needed. The fold spans the \
             junction along this branch: a branch leaving out of the others' plane, or bending within its first \
             radii. Give the surface a longer stretch of this branch, or cut the smallest branches at this junction \
             off the surface",
            if geometry.arrangement_name() == "book" { "a book" } else { "sectors" },
            FOLD_MARGIN * r
        ));
    }
    Error::Geometry(format!(
        "{place}: no cross-section within {d:.1} mm of the junction is clear of the other branches (every ray \
         meeting this branch's wall within {CLEAR_REACH} radii, on a gently bending centerline, behind the \
         junction's crotches). The branch may be too short, or its centerline leaves the lumen near the junction"
    ))
}

/// Largest share of the way from a transition section's centre to its wall that the core
/// may take.
const CORE_REACH: f64 = 0.7;

/// The factor (at most 1) by which a transition core must shrink about its centre so that each
/// boundary node lies at most CORE_REACH of the way from the centre to the wall in its direction.
fn wall_clearance_shrink(surface: &LumenSurface, p: &TransitionPoints, template: &SectionTemplate) -> f64 {
    template
        .ring_core_index
        .iter()
        .map(|&c| {
            let o = p.core[c] - p.centre;
            let along = o.norm();
            if along == 0.0 {
                return 1.0;
            }
            match surface.first_hit(&p.centre, &(o / along), along / CORE_REACH) {
                Some(hit) => CORE_REACH * hit.distance / along,
                None => 1.0,
            }
        })
        .fold(1.0, f64::min)
}

/// Rays of a transition section may run this many times the distance to their guide point.
const GUIDE_SLACK: f64 = 3.0;

/// Shrinks a transition core about its centre until every boundary node lies at most
/// CORE_REACH of the way from the centre to its guide point and to the wall in its direction:
/// where the branch is much narrower than the junction, or the centerline hugs one side of the
/// lumen, the interpolated core would otherwise come close to the wall or cross it.
fn keep_core_off_the_wall(
    p: &mut TransitionPoints,
    guide_at: &[Point3<f64>],
    template: &SectionTemplate,
    surface: &LumenSurface,
) {
    let shrink = (0..template.ring_len())
        .map(|k| {
            let o = p.core[template.ring_core_index[k]] - p.centre;
            let g = guide_at[k] - p.centre;
            let along = o.dot(&g) / g.norm();
            if along > 0.0 {
                CORE_REACH * g.norm() / along
            } else {
                1.0
            }
        })
        .fold(1.0, f64::min)
        .min(wall_clearance_shrink(surface, p, template));
    if shrink < 1.0 {
        for c in p.core.iter_mut() {
            *c = p.centre + (*c - p.centre) * shrink;
        }
    }
}

/// Ray targets of a transition section: from each core boundary node through its guide point,
/// far enough that a guide inside the lumen (a bulb) does not stop the ray short of the wall.
fn guided_targets(
    p: &TransitionPoints,
    guide_at: &[Point3<f64>],
    template: &SectionTemplate,
    junction_radius: f64,
) -> Vec<Point3<f64>> {
    guide_at
        .iter()
        .enumerate()
        .map(|(k, guide)| {
            let origin = p.core[template.ring_core_index[k]];
            let reach = (guide - origin).norm().max(template.ray_reach * junction_radius) * GUIDE_SLACK;
            origin + (guide - origin).normalize() * (reach / RAY_SLACK)
        })
        .collect()
}

/// Why a transition section failed, naming the junction and the branch.
fn transition_failure(setup: &ProjectionSetup, branch: &Branch, g: &JunctionGeometry, u: f64, probe: &Probe) -> Error {
    Error::Geometry(format!(
        "{}: branch {} at the junction at ({:.3}, {:.3}, {:.3}) mm: in the transition section {:.0} % of the way to \
         the junction, {} of {} rays miss the lumen wall and {} meet it from outside. The branches leave the \
         junction at a shape the book of pages cannot follow (a bulb or a stenosis at the junction); smooth the \
         centerlines or lengthen the transition (mesh the junction finer)",
        setup.surface.source.display(),
        branch.name,
        g.centre.x,
        g.centre.y,
        g.centre.z,
        u * 100.0,
        probe.misses,
        setup.template.ring_len(),
        probe.from_outside
    ))
}

/// A transition widens from its branch's radius to its junction's, and its sections are spaced
/// as a section of their mean radius would be (`lumen.axial_spacing` of it; a spacing set in mm
/// stays), at least as the branch's and at most this many times that. Spaced as the branch's,
/// a transition into a wider junction has rings crowded against one another where the wall
/// flares: the cerebral tree's inflow into its aneurysm (radius 1.1 -> 3.5 mm) at medium had
/// 25 lumen cells of that transition inverted (and 2 beside it) and the tree was refused; so
/// spaced, it meshes within the bars, and the SPHinXsys arch at coarse does too (wall mean
/// 0.840 -> 0.860). The cap keeps a sac's surface: on palabos_cerebral_aneurysm at medium,
/// whose sac (radius 17 mm) is its junction, the largest surface-to-mesh distance is 0.57 mm as
/// the branch's, 0.88 mm with this cap, 1.08 mm with twice the branch's spacing.
const TRANSITION_SPACING_GROWTH: f64 = 1.5;

/// A transition's folded end, cast, and the core points of the sections before it.
struct FoldCast {
    /// Parameters of the sections from the ordinary section (0, excluded) to the fold (1, excluded).
    params: Vec<f64>,
    points: Vec<TransitionPoints>,
    fold: ProjectedSection,
}

/// The station of a transition section at parameter `u` from `station` towards the junction.
fn transition_sample(
    j: &JunctionEnd,
    station: &CenterlineSample,
    sense: f64,
    u: f64,
    centre: Point3<f64>,
) -> CenterlineSample {
    CenterlineSample {
        s: station.s + sense * j.transition_length * u,
        point: centre,
        radius: station.radius + (j.geometry.radius - station.radius) * u,
        frame: station.frame,
    }
}

/// Casts the folded end of a transition leaving `station` (`sense` +1 when the junction lies
/// downstream of it) and places the cores of the sections in between.
fn cast_fold(
    j: &JunctionEnd,
    station: &CenterlineSample,
    sense: f64,
    setup: &ProjectionSetup,
    branch: &Branch,
) -> Result<FoldCast> {
    let template = setup.template;
    let towards = station.frame.tangent * sense;
    let branch_spacing = (setup.junction_spacing)(station);
    let halfway = transition_sample(j, station, sense, 0.5, station.point);
    let h = (setup.junction_spacing)(&halfway).clamp(branch_spacing, TRANSITION_SPACING_GROWTH * branch_spacing);
    let cells = ((j.transition_length / h).round() as usize).max(2);
    let mut params: Vec<f64> = (1..=cells).map(|i| i as f64 / cells as f64).collect();
    let mut points = transition_points(j.geometry, &j.fold, template, station, &towards, &params);
    params.pop();
    let orient = if setup.normals_outward { 1.0 } else { -1.0 };
    let fold_points = points.pop().expect("at least two transition sections");
    let at_fold = transition_sample(j, station, sense, 1.0, j.geometry.centre);
    let (mut probe, mut fold) =
        cast_rays(template, setup.surface, &at_fold, fold_points.core, &fold_points.targets, orient);
    land_missed_fold_rays(&mut probe, &mut fold, setup.surface);
    if !probe.valid() {
        return Err(transition_failure(setup, branch, j.geometry, 1.0, &probe));
    }
    Ok(FoldCast { params, points, fold: ProjectedSection { in_junction: true, ..fold } })
}

/// A folded section's ray that meets no wall within its reach (its sector runs out down a
/// branch leaving a few degrees from its neighbour) lands on the wall point nearest its ray at
/// the mean distance its two neighbours in the ring met the wall.
fn land_missed_fold_rays(probe: &mut Probe, fold: &mut ProjectedSection, surface: &LumenSurface) {
    if probe.misses == 0 || probe.from_outside > 0 {
        return;
    }
    let m = fold.surface.len();
    let missed = std::mem::take(&mut probe.missed);
    let hit = |k: usize| !missed.contains(&k);
    for &k in &missed {
        let (a, b) = ((k + m - 1) % m, (k + 1) % m);
        if !(hit(a) && hit(b)) {
            probe.missed.push(k);
            continue;
        }
        let reach = 0.5 * ((fold.surface[a] - fold.origins[a]).norm() + (fold.surface[b] - fold.origins[b]).norm());
        let landed = surface.closest(&(fold.origins[k] + fold.dirs[k] * reach)).point;
        let d = landed - fold.origins[k];
        if d.norm() > 0.0 {
            fold.surface[k] = landed;
            fold.dirs[k] = d.normalize();
            probe.misses -= 1;
        } else {
            probe.missed.push(k);
        }
    }
}

/// Direction in which a transition arrives at the fold at the template point `xy`.
fn fold_arrival(j: &JunctionEnd, template: &SectionTemplate, xy: &Vector2<f64>) -> Vector3<f64> {
    j.geometry.arrival(j.fold.slot, &crate::stages::junction::turn(j.fold.quarter_turns, xy), template.core_size)
}

/// A guide curve (Hermite end points and tangents) for each ring node.
type GuideCurve = (Point3<f64>, Vector3<f64>, Point3<f64>, Vector3<f64>);

fn on_guide(c: &GuideCurve, u: f64) -> Point3<f64> {
    crate::stages::junction::hermite(&c.0, &c.1, &c.2, &c.3, u)
}

/// Casts one transition section: the core kept off the wall, each ray aimed through its guide point.
fn guided_section(
    mut p: TransitionPoints,
    guide_at: &[Point3<f64>],
    sample: CenterlineSample,
    j: &JunctionEnd,
    setup: &ProjectionSetup,
) -> (Probe, ProjectedSection) {
    let orient = if setup.normals_outward { 1.0 } else { -1.0 };
    keep_core_off_the_wall(&mut p, guide_at, setup.template, setup.surface);
    let targets = guided_targets(&p, guide_at, setup.template, j.geometry.radius);
    let (mut probe, mut section) = cast_rays(
        setup.template,
        setup.surface,
        &CenterlineSample { point: p.centre, ..sample },
        p.core,
        &targets,
        orient,
    );
    land_missed_rays_near_guides(&mut probe, &mut section, guide_at, setup);
    (probe, ProjectedSection { in_junction: true, ..section })
}

/// A transition's ray that meets no wall (aimed through its guide point, it runs out down a
/// neighbour's lumen where the junction's surface turns sharply) lands on the wall point nearest
/// its guide point, which lies between its wall nodes on the ordinary and on the folded section:
/// the node then keeps its place between them, and the elements around it are judged (and
/// optimised) as any.
fn land_missed_rays_near_guides(
    probe: &mut Probe,
    section: &mut ProjectedSection,
    guide_at: &[Point3<f64>],
    setup: &ProjectionSetup,
) {
    if probe.misses == 0 || probe.from_outside > 0 {
        return;
    }
    for k in std::mem::take(&mut probe.missed) {
        let origin = section.origins[k];
        let landed = setup.surface.closest(&guide_at[k]).point;
        let d = landed - origin;
        if d.norm() > 0.0 {
            section.surface[k] = landed;
            section.dirs[k] = d.normalize();
            probe.misses -= 1;
        } else {
            probe.missed.push(k);
        }
    }
}

/// The sections strictly between `station` and the fold, each ray aimed at `guide(k, u)`.
///
/// Where the branch's centerline bends close to the junction, the Hermite sections may cut
/// through the wall; the second attempt moves them onto the centerline, less and less towards
/// the fold (where the section is fixed).
fn transition_sections(
    j: &JunctionEnd,
    station: &CenterlineSample,
    sense: f64,
    cast: &FoldCast,
    guide: &(dyn Fn(usize, f64) -> Point3<f64> + Sync),
    setup: &ProjectionSetup,
    branch: &Branch,
) -> Result<Vec<ProjectedSection>> {
    let length = branch.length();
    let attempt = |follow_centerline: bool| -> Result<Vec<ProjectedSection>> {
        cast.params
            .iter()
            .zip(&cast.points)
            .map(|(&u, p)| {
                let shift = if follow_centerline {
                    let s = (station.s + sense * j.transition_length * u).clamp(0.0, length);
                    (branch.at(s).point - p.centre) * (1.0 - u)
                } else {
                    Vector3::zeros()
                };
                let moved = TransitionPoints {
                    core: p.core.iter().map(|c| c + shift).collect(),
                    targets: vec![],
                    centre: p.centre + shift,
                };
                let guide_at: Vec<Point3<f64>> = (0..setup.template.ring_len()).map(|k| guide(k, u) + shift).collect();
                let (probe, section) =
                    guided_section(moved, &guide_at, transition_sample(j, station, sense, u, p.centre), j, setup);
                if !probe.valid() {
                    return Err(transition_failure(setup, branch, j.geometry, u, &probe));
                }
                Ok(section)
            })
            .collect()
    };
    match attempt(false) {
        Ok(out) => Ok(out),
        Err(first) => attempt(true).map_err(|_| first),
    }
}

/// How a bridge's sections are placed: on the straight sweep from fold to fold, on the same
/// carried onto the branch's centerline (see [`onto_centerline`]), or on its two folds carried
/// along the centerline in the branch's frames and blended (see [`carried_blend`]).
#[derive(Clone, Copy, PartialEq)]
enum BridgeSweep {
    Straight,
    OntoCenterline,
    CarriedFolds,
}

/// A point of two sections blended after each is carried to the centerline sample `along`: each
/// section's point `q`, taken relative to its `anchor` in its own sample's frame, is placed
/// relative to `base` in the frame of `along`; the two are blended by `h` (0: the first).
fn carried_blend(
    along: &CenterlineSample,
    base: Point3<f64>,
    first: (&CenterlineSample, Point3<f64>, Point3<f64>),
    second: (&CenterlineSample, Point3<f64>, Point3<f64>),
    h: f64,
) -> Point3<f64> {
    let carry = |(from, anchor, q): (&CenterlineSample, Point3<f64>, Point3<f64>)| {
        base + frame_matrix(along) * frame_matrix(from).transpose() * (q - anchor)
    };
    Point3::from(carry(first).coords * (1.0 - h) + carry(second).coords * h)
}

/// A sample's frame as the rotation from the world's axes to its normal, binormal and tangent.
fn frame_matrix(sample: &CenterlineSample) -> nalgebra::Matrix3<f64> {
    let f = &sample.frame;
    nalgebra::Matrix3::from_columns(&[f.normal, f.binormal, f.tangent])
}

/// The sweep whose blocks fold least among those cast (the first on a tie), else the first's
/// failure. `blocks` gives a sweep's block Jacobians (see [`block_jacobians`]); their sign is
/// the majority's over every sweep cast, so the ring's sense does not matter and a sweep turned
/// inside out throughout does not pass for a good one.
fn best_sweep(
    attempts: impl IntoIterator<Item = Result<Vec<ProjectedSection>>>,
    blocks: impl Fn(&[ProjectedSection]) -> Vec<f64>,
) -> Result<Vec<ProjectedSection>> {
    let mut cast = Vec::new();
    let mut first_error = None;
    for attempt in attempts {
        match attempt {
            Ok(sections) => {
                let jacobians = blocks(&sections);
                cast.push((jacobians, sections));
            }
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    let (negative, all) =
        cast.iter().fold((0, 0), |(n, a), (j, _)| (n + j.iter().filter(|&&q| q < 0.0).count(), a + j.len()));
    let sign = if 2 * negative > all { -1.0 } else { 1.0 };
    let worst = |j: &[f64]| j.iter().map(|q| if q.is_nan() { -1.0 } else { sign * q }).fold(f64::INFINITY, f64::min);
    let mut best: Option<(f64, Vec<ProjectedSection>)> = None;
    for (jacobians, sections) in cast {
        let w = worst(&jacobians);
        if best.as_ref().is_none_or(|(b, _)| w > *b) {
            best = Some((w, sections));
        }
    }
    match best {
        Some((_, sections)) => Ok(sections),
        None => Err(first_error.expect("at least one sweep was cast")),
    }
}

/// The scaled Jacobians of a run of sections' blocks: between two neighbouring sections, each
/// ring cell's block from the core's edge to the wall (the lumen's O-grid elements of that cell,
/// whole). A sweep that cuts a bend makes neighbouring sections cross, and the block between
/// them turns inside out.
fn block_jacobians(sections: &[&ProjectedSection], template: &SectionTemplate) -> Vec<f64> {
    let m = template.ring_len();
    let mut jacobians = Vec::with_capacity(m * sections.len());
    for pair in sections.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        for k in 0..m {
            let next = (k + 1) % m;
            let (ci, cn) = (template.ring_core_index[k], template.ring_core_index[next]);
            let corners = [
                a.core[ci],
                a.surface[k],
                a.surface[next],
                a.core[cn],
                b.core[ci],
                b.surface[k],
                b.surface[next],
                b.core[cn],
            ];
            jacobians.push(crate::geometry::quality::scaled_jacobian(&corners));
        }
    }
    jacobians
}

/// The sections of a transition from an ordinary section (excluded) to the folded end
/// (included), in that order. `sense` is +1 when the junction lies downstream of the section.
///
/// The folded section's rays stay in their pages. In between, a ray aimed at its target could
/// cross the still-common lumen into the neighbouring branch; so each ray is aimed instead at a
/// guide point on a Hermite curve between its surface nodes on the ordinary and on the folded
/// section (leaving along the branch, arriving as the fold's core does), which keeps it on its
/// own branch's side of the crotch.
fn transition(
    j: &JunctionEnd,
    ordinary: &ProjectedSection,
    sense: f64,
    setup: &ProjectionSetup,
    branch: &Branch,
) -> Result<Vec<ProjectedSection>> {
    let station = &ordinary.station;
    let towards = station.frame.tangent * sense;
    let cast = cast_fold(j, station, sense, setup, branch)?;
    let guides: Vec<GuideCurve> = (0..setup.template.ring_len())
        .map(|k| {
            let (p0, p1) = (ordinary.surface[k], cast.fold.surface[k]);
            let chord = (p1 - p0).norm();
            let xy = setup.template.core[setup.template.ring_core_index[k]];
            (p0, towards * chord, p1, fold_arrival(j, setup.template, &xy) * chord)
        })
        .collect();
    let mut out = transition_sections(j, station, sense, &cast, &|k, u| on_guide(&guides[k], u), setup, branch)?;
    out.push(cast.fold);
    Ok(out)
}

/// A branch between two junctions too close for a transition and ordinary sections each (two
/// side branches a couple of radii apart, the aortic arch between its branches): a *bridge*,
/// swept straight from the upstream fold to the downstream one, with no ordinary section. Each
/// core node follows a Hermite curve from its place on one fold to its place on the other
/// (leaving and arriving across the pages), and each ray is aimed at a guide point on the same
/// kind of curve between its wall nodes on the two folds: the whole bridge lies in the
/// junctions' common lumen, where a plain ray would escape into a branch. `station` (the
/// branch's middle) gives the sections their frame. Sections from the upstream fold to the
/// downstream one.
fn bridge(
    start: &JunctionEnd,
    end: &JunctionEnd,
    station: &CenterlineSample,
    setup: &ProjectionSetup,
    branch: &Branch,
) -> Result<Vec<ProjectedSection>> {
    let template = setup.template;
    let up = cast_fold(start, station, -1.0, setup, branch)?;
    let down = cast_fold(end, station, 1.0, setup, branch)?;
    // From a point of the upstream fold to its place on the downstream one: leaving the first
    // as the transition arrives there, reversed, and arriving at the second.
    let curve = |p0: Point3<f64>, p1: Point3<f64>, xy: &Vector2<f64>| -> GuideCurve {
        let chord = (p1 - p0).norm();
        (p0, -fold_arrival(start, template, xy) * chord, p1, fold_arrival(end, template, xy) * chord)
    };
    let cores: Vec<GuideCurve> =
        template.core.iter().enumerate().map(|(c, xy)| curve(up.fold.core[c], down.fold.core[c], xy)).collect();
    let guides: Vec<GuideCurve> = (0..template.ring_len())
        .map(|k| curve(up.fold.surface[k], down.fold.surface[k], &template.core[template.ring_core_index[k]]))
        .collect();
    let centre = curve(start.geometry.centre, end.geometry.centre, &Vector2::zeros());
    let length = branch.length();
    let cells = ((length / (setup.junction_spacing)(station)).round() as usize).max(2);
    // The straight sweep wherever its rays all meet the wall. Where they do not, two sweeps, the
    // one whose blocks fold least kept (see [`best_sweep`]): the same moved onto the branch's
    // own centerline (the branch bows out, or turns back through a wide junction); and each
    // fold carried along the centerline in the branch's frames and blended from one to the
    // other (a hairpin between two junctions, where the moved sweep lays its middle sections
    // along the bend). The straight sweep is not ranked with them: its blocks span the lumen's
    // whole depth before the junction's nodes are optimised, and on generated tree 30 a bridge
    // whose straight blocks were inverted (-0.64) meshed valid, where the carried sweep with
    // better blocks (-0.43) left 43 lumen elements inverted.
    let ends = (branch.at(0.0), branch.at(length));
    let carried = |q_up: Point3<f64>, q_down: Point3<f64>, v: f64| {
        let along = branch.at(v * length);
        let base =
            along.point + (start.geometry.centre - ends.0.point) * (1.0 - v) + (end.geometry.centre - ends.1.point) * v;
        let up = (&ends.0, start.geometry.centre, q_up);
        carried_blend(&along, base, up, (&ends.1, end.geometry.centre, q_down), smoothstep(v))
    };
    let attempt = |sweep: BridgeSweep| -> Result<Vec<ProjectedSection>> {
        (1..cells)
            .map(|i| {
                let v = i as f64 / cells as f64;
                let place = |c: &GuideCurve| match sweep {
                    BridgeSweep::Straight => on_guide(c, v),
                    BridgeSweep::OntoCenterline => onto_centerline(branch, &centre, v, on_guide(c, v)),
                    BridgeSweep::CarriedFolds => carried(c.0, c.2, v),
                };
                let p = TransitionPoints {
                    core: cores.iter().map(place).collect(),
                    targets: vec![],
                    centre: place(&centre),
                };
                let guide_at: Vec<Point3<f64>> = guides.iter().map(place).collect();
                let sample = CenterlineSample {
                    s: v * length,
                    point: p.centre,
                    radius: start.geometry.radius + (end.geometry.radius - start.geometry.radius) * v,
                    frame: station.frame,
                };
                let (probe, section) = guided_section(p, &guide_at, sample, start, setup);
                if !probe.valid() {
                    return Err(transition_failure(setup, branch, start.geometry, v, &probe));
                }
                Ok(section)
            })
            .collect()
    };
    let judged = |inner: &[ProjectedSection]| {
        let all: Vec<&ProjectedSection> =
            std::iter::once(&up.fold).chain(inner).chain(std::iter::once(&down.fold)).collect();
        block_jacobians(&all, template)
    };
    let inner = match attempt(BridgeSweep::Straight) {
        Ok(straight) => straight,
        Err(first) => best_sweep([BridgeSweep::OntoCenterline, BridgeSweep::CarriedFolds].map(attempt), judged)
            .map_err(|_| first)?,
    };
    let mut out = vec![up.fold];
    out.extend(inner);
    out.push(down.fold);
    Ok(out)
}

/// A point `q` of a bridge's straight sweep at parameter `v` (whose centre curve is `centre`),
/// carried onto the branch's centerline: moved with the sweep's centre to the centerline's point
/// at the same share of the branch, and turned as the sweep's direction turns onto the
/// centerline's there. The centerline lies in the lumen wherever the straight chord between the
/// junctions does not (a branch bowing out, or turning back through a wide junction: random trees
/// 23, 30 and 32 had 7-9 of 16 rays of a bridge section outside the wall); at the two folds both
/// curves meet the junctions' centres (the centerline's ends moved onto them, in proportion), so
/// the bridge still ends on its folds.
fn onto_centerline(branch: &Branch, centre: &GuideCurve, v: f64, q: Point3<f64>) -> Point3<f64> {
    const STEP: f64 = 1e-4;
    let length = branch.length();
    let along = branch.at(v * length);
    let ends_off = (centre.0 - branch.at(0.0).point) * (1.0 - v) + (centre.2 - branch.at(length).point) * v;
    let sweep = on_guide(centre, (v + STEP).min(1.0)) - on_guide(centre, (v - STEP).max(0.0));
    let turn = Rotation3::rotation_between(&sweep, &along.frame.tangent).unwrap_or_else(Rotation3::identity);
    along.point + ends_off + turn * (q - on_guide(centre, v))
}
