//! Projection of the O-grid onto the lumen surface, and the choice of where the mesh starts and
//! ends along a branch.
//!
//! Every centerline sample is probed with the rays of its section. A section is *clean* when
//! every ray meets the surface from the inside and no hit triangle faces along the axis (a cap
//! would). The mesh runs between the first and the last clean sections, a margin away from a
//! closed end, so no lumen node lands on a cap or beyond an open end; every section in between
//! must at least be *valid* (every ray hits from the inside), otherwise the run stops with the
//! place and the cause.

use crate::blocks::SectionTemplate;
use crate::centerline::{Branch, CenterlineSample};
use crate::error::{Error, Result};
use crate::surface::LumenSurface;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

/// Hit triangles whose normal is within this cosine of the axis mark a cap (about 70 degrees
/// from the wall direction of a tube).
const CAP_NORMAL_COS: f64 = 0.35;
/// How far beyond the outer block surface a ray may still meet the surface (ray lengths).
const RAY_SLACK: f64 = 1.5;
/// Distance kept from a closed end, relative to the local radius.
const CLOSED_END_MARGIN: f64 = 0.5;

/// The projected rays of one station.
#[derive(Debug, Clone)]
pub struct ProjectedSection {
    pub station: CenterlineSample,
    /// Ray origins on the core square boundary, one per ring point.
    pub origins: Vec<Point3<f64>>,
    /// Unit ray directions (towards the outer block surface).
    pub dirs: Vec<Vector3<f64>>,
    /// Lumen-surface nodes: where each ray meets the surface.
    pub surface: Vec<Point3<f64>>,
}

/// A branch's stations, all projected.
#[derive(Debug, Clone)]
pub struct ProjectedBranch {
    pub sections: Vec<ProjectedSection>,
    /// Arc lengths where the mesh starts and ends.
    pub s_start: f64,
    pub s_end: f64,
    /// Whether each end of the surface was found closed (capped) rather than open.
    pub inlet_closed: bool,
    pub outlet_closed: bool,
    /// Whether the surface's triangles face out of the lumen (they may face in).
    pub normals_outward: bool,
}

/// What the rays of one section found.
#[derive(Debug, Clone, Default)]
struct Probe {
    misses: usize,
    /// Hits on a triangle seen from outside the lumen.
    from_outside: usize,
    /// Largest |normal . tangent| over the hit triangles.
    axial_normal: f64,
}

impl Probe {
    fn valid(&self) -> bool {
        self.misses == 0 && self.from_outside == 0
    }
    fn clean(&self) -> bool {
        self.valid() && self.axial_normal < CAP_NORMAL_COS
    }
}

fn where_(s: &CenterlineSample) -> String {
    format!(
        "at ({:.3}, {:.3}, {:.3}) mm, {:.2} mm along the centerline",
        s.point.x, s.point.y, s.point.z, s.s
    )
}

/// Casts the rays of one station. `orientation` is +1 when triangle normals face out of the
/// lumen, -1 when they face in.
fn cast_section(
    template: &SectionTemplate,
    surface: &LumenSurface,
    station: &CenterlineSample,
    orientation: f64,
) -> (Probe, ProjectedSection) {
    let m = template.ring_len();
    let mut probe = Probe::default();
    let mut section = ProjectedSection {
        station: *station,
        origins: Vec::with_capacity(m),
        dirs: Vec::with_capacity(m),
        surface: Vec::with_capacity(m),
    };
    for k in 0..m {
        let (origin, dir, len) = template.ray(station, k);
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
                section.surface.push(origin + dir * len);
            }
        }
        section.origins.push(origin);
        section.dirs.push(dir);
    }
    (probe, section)
}

/// Finds the meshable part of a branch and projects its stations.
pub fn project_branch(
    branch: &Branch,
    template: &SectionTemplate,
    surface: &LumenSurface,
    spacing: &(dyn Fn(&CenterlineSample) -> f64 + Sync),
    trim_inlet: f64,
    trim_outlet: f64,
    normals_outward: bool,
) -> Result<ProjectedBranch> {
    let samples = &branch.samples;
    let orient = if normals_outward { 1.0 } else { -1.0 };
    let probes: Vec<Probe> = samples.par_iter().map(|s| cast_section(template, surface, s, orient).0).collect();

    let first_clean = probes.iter().position(Probe::clean);
    let last_clean = probes.iter().rposition(Probe::clean);
    let (i0, i1) = match (first_clean, last_clean) {
        (Some(a), Some(b)) if a < b => (a, b),
        _ => {
            let mid = &samples[samples.len() / 2];
            let p = &probes[samples.len() / 2];
            return Err(Error::Geometry(format!(
                "{}: no cross-section of the vessel has all its rays meeting the lumen wall from inside (in the \
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
    if let Some(bad) = (i0..=i1).find(|&i| !probes[i].valid()) {
        let p = &probes[bad];
        return Err(Error::Geometry(format!(
            "{}: the cross-section {} does not close: {} of {} rays miss the lumen surface and {} meet it from \
             outside. The surface may have a hole there, or the centerline leaves the lumen; repair the surface \
             or smooth the centerline (centerline.smoothing_passes)",
            surface.source.display(),
            where_(&samples[bad]),
            p.misses,
            template.ring_len(),
            p.from_outside
        )));
    }
    // A closed end (every ray of the end sample hits): keep a margin from the cap.
    let inlet_closed = probes[0].valid();
    let outlet_closed = probes[probes.len() - 1].valid();
    let r0 = samples[i0].radius;
    let r1 = samples[i1].radius;
    let s_start = samples[i0].s + r0 * (trim_inlet + if inlet_closed { CLOSED_END_MARGIN } else { 0.0 });
    let s_end = samples[i1].s - r1 * (trim_outlet + if outlet_closed { CLOSED_END_MARGIN } else { 0.0 });
    if s_end - s_start < 0.5 * (r0 + r1) {
        return Err(Error::Geometry(format!(
            "{}: only {:.3} mm of the centerline (from {:.2} to {:.2} mm) has clean cross-sections, too short to \
             mesh; reduce centerline.trim_inlet/trim_outlet or check the surface's ends",
            surface.source.display(),
            (s_end - s_start).max(0.0),
            s_start,
            s_end
        )));
    }

    let positions = crate::blocks::station_positions(s_start, s_end, |s| spacing(&branch.at(s)));
    let sections: Vec<(Probe, ProjectedSection)> =
        positions.par_iter().map(|&s| cast_section(template, surface, &branch.at(s), orient)).collect();
    let mut out = Vec::with_capacity(sections.len());
    for (probe, section) in sections {
        if !probe.valid() {
            return Err(Error::Geometry(format!(
                "{}: ray cast failed for the station {}: {} rays miss the surface, {} meet it from outside",
                surface.source.display(),
                where_(&section.station),
                probe.misses,
                probe.from_outside
            )));
        }
        out.push(section);
    }
    Ok(ProjectedBranch { sections: out, s_start, s_end, inlet_closed, outlet_closed, normals_outward })
}
