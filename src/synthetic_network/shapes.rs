//! Drawing a network: a ring fed by inlets, a graft on its host, or a circle of Willis (see the
//! module documentation of [`crate::synthetic_network`] for the distributions).

use super::model::{End, Junction, Network, Tube};
use crate::synthetic_tree::centerline::{direction_from, sample_at, PathBuilder, Sample, MIN_CURVATURE_RADII};
use crate::synthetic_tree::daughters::BLEND_CELLS;
use crate::synthetic_tree::layout::{
    taper_profile, tortuous_body, CELLS_PER_SMALLEST_RADIUS, EXTENSION_CELLS, GAP_MIN_CELLS,
};
use crate::synthetic_tree::model::Zone;
use crate::synthetic_tree::rng::SeededRng;
use crate::synthetic_tree::separation::junction_reach;
use nalgebra::{Point3, Vector3};
use serde_json::{json, Map, Value};

/// Longest straight stretch out of a junction, in (host + branch) radii, as for a tree's
/// daughters: a branch that needs more runs along its neighbours and the network is redrawn.
const MAX_JUNCTION_STRETCH: f64 = 8.0;

/// A branch to lay from a junction: its radius there, its direction, and how its radius goes
/// from there (`grows`: an inlet, widening by `taper` towards its free end; else narrowing).
pub struct BranchSpec {
    pub name: String,
    pub label: &'static str,
    pub radius: f64,
    pub direction: Vector3<f64>,
    pub taper: f64,
    pub tortuosity: f64,
    pub body_radii: f64,
    pub inlet: bool,
    /// Lay a straight stretch of four radii in the middle of the body, to take a side branch.
    pub side_room: bool,
    /// Its far end is a free end (else a junction where the branch splits).
    pub free_end: bool,
}

impl Network {
    /// An empty network whose smallest radius is `floor`.
    pub fn new(shape: &'static str, floor: f64, draws: Map<String, Value>) -> Self {
        let h = floor / CELLS_PER_SMALLEST_RADIUS;
        Network {
            shape,
            h,
            gap_min: GAP_MIN_CELLS * h,
            extension: EXTENSION_CELLS * h,
            tubes: Vec::new(),
            junctions: Vec::new(),
            ends: Vec::new(),
            draws,
        }
    }

    /// The blend width of a branch of radius `r` at its junction, as a tree's daughter's.
    pub fn blend_width(&self, r: f64) -> f64 {
        (0.5 * r).clamp(BLEND_CELLS.0 * self.h, BLEND_CELLS.1 * self.h)
    }

    /// Whether a new free end is capped, by the network's end style.
    fn draw_capped(&self, rng: &mut SeededRng) -> bool {
        match self.draws.get("end_style").and_then(Value::as_str) {
            Some("capped") => true,
            Some("mixed") => rng.chance(0.5),
            _ => false,
        }
    }

    /// Adds a free end of tube `tube`.
    pub fn add_end(
        &mut self,
        rng: &mut SeededRng,
        tube: usize,
        at_start: bool,
        inlet: bool,
        label: &'static str,
    ) -> usize {
        let capped = self.draw_capped(rng);
        let count = self.ends.iter().filter(|e| e.inlet == inlet).count();
        let name = format!("{}_{}", if inlet { "inlet" } else { "outlet" }, count + 1);
        self.ends.push(End { tube, at_start, inlet, capped, name, label });
        self.ends.len() - 1
    }

    /// Straight length out of junction `junction` for a branch of radius `r` along `d`: its wall
    /// clear of the host's and of every branch already there by the blend and the gap, plus a
    /// radius; `None` past [`MAX_JUNCTION_STRETCH`].
    fn junction_stretch(&self, junction: usize, host: &Sample, d: &Vector3<f64>, r: f64) -> Option<f64> {
        let k = self.blend_width(r);
        let clearance = |other: f64, sine: f64| (other + r + k + self.gap_min) / sine.max(0.2);
        let mut stretch = clearance(host.r, host.t.cross(d).norm());
        for &(tube, s, _) in self.junctions[junction].on.iter().skip(1) {
            let q = sample_at(&self.tubes[tube].samples, s);
            // An inlet's samples run towards the junction: its direction out of it is -t.
            let out = if s > 0.0 { -q.t } else { q.t };
            stretch = stretch.max(clearance(q.r, out.cross(d).norm()));
        }
        let stretch = stretch + r;
        (stretch <= MAX_JUNCTION_STRETCH * (host.r + r)).then_some(stretch)
    }

    /// Lays a branch from `junction` (on its host's sample `host`): a straight stretch out of the
    /// junction, a tortuous body, two straight radii; an inlet's samples are then reversed, so
    /// that they run from its free end to the junction. Returns the tube's id, or `None` when it
    /// cannot clear the junction.
    pub fn lay_branch(
        &mut self,
        rng: &mut SeededRng,
        junction: usize,
        host: &Sample,
        spec: BranchSpec,
    ) -> Option<usize> {
        let r = spec.radius;
        let stretch = self.junction_stretch(junction, host, &spec.direction, r)?;
        let (samples, side_anchor) = self.branch_path(rng, host, &spec, stretch);
        let k = self.blend_width(r);
        let zone = self.junction_zone(host.p, host.p + spec.direction * stretch, r);
        let reach = junction_reach(host.r, r, k, self.gap_min, spec.direction.angle(&host.t)).max(stretch);
        let id = self.tubes.len();
        let at = if spec.inlet { samples.last().map_or(0.0, |q| q.s) } else { 0.0 };
        self.junctions[junction].on.push((id, at, reach));
        let mut draws = Map::new();
        draws.insert("radius_at_junction_mm".into(), json!(r));
        draws.insert("taper".into(), json!(spec.taper));
        draws.insert("tortuosity".into(), json!(spec.tortuosity));
        draws.insert("body_radii".into(), json!(spec.body_radii));
        draws.insert("angle_to_host_deg".into(), json!(spec.direction.angle(&host.t).to_degrees()));
        if !spec.label.is_empty() {
            draws.insert("label".into(), json!(spec.label));
        }
        let (start_end, end_end) = (None, None);
        let zones = vec![zone];
        self.tubes.push(Tube {
            name: spec.name,
            samples,
            closed: false,
            start_end,
            end_end,
            zones,
            side_anchor,
            draws,
        });
        if spec.inlet {
            self.tubes[id].start_end = Some(self.add_end(rng, id, true, true, spec.label));
        } else if spec.free_end {
            self.tubes[id].end_end = Some(self.add_end(rng, id, false, false, spec.label));
        }
        Some(id)
    }

    /// A branch's centerline from its host's sample: straight for `stretch`, its body (halved
    /// round a straight stretch of four radii when it is to take a side branch), two straight
    /// radii; its radius tapering away from the junction (an outlet) or widening (an inlet,
    /// whose samples are then reversed). With the arc length of the side branch's anchor.
    fn branch_path(
        &self,
        rng: &mut SeededRng,
        host: &Sample,
        spec: &BranchSpec,
        stretch: f64,
    ) -> (Vec<Sample>, Option<f64>) {
        let r = spec.radius;
        let normal = rng.perpendicular(&spec.direction, &host.t);
        let mut b = PathBuilder::new(host.p, spec.direction, normal, r, r);
        b.straight(stretch);
        let body_start = b.length();
        let body = spec.body_radii * r;
        let mut side_anchor = None;
        if spec.side_room {
            tortuous_body(rng, &mut b, r, 0.5 * body, spec.tortuosity, false);
            side_anchor = Some(b.length() + 2.0 * r);
            b.straight(4.0 * r);
            tortuous_body(rng, &mut b, r, 0.5 * body, spec.tortuosity, false);
        } else {
            tortuous_body(rng, &mut b, r, body, spec.tortuosity, false);
        }
        let body_end = b.length();
        b.straight(2.0 * r);
        let floor = self.h * CELLS_PER_SMALLEST_RADIUS;
        let (taper, length) = (spec.taper, b.length());
        if !spec.inlet {
            return (b.finish(|s| taper_profile(s, body_start, body_end, r, taper, floor)), side_anchor);
        }
        // Widening away from the junction: the profile read from the free end.
        let r_free = r / (1.0 - taper);
        let samples =
            b.finish(|s| taper_profile(length - s, length - body_end, length - body_start, r_free, taper, floor));
        (reversed(&samples), side_anchor.map(|s| length - s))
    }

    /// The blend zone of a branch of radius `r` at a junction: round the segment from the
    /// junction's point `a` on its host's axis to `b`, where its straight stretch out of the
    /// junction ends, as a tree's daughter's.
    pub fn junction_zone(&self, a: Point3<f64>, b: Point3<f64>, r: f64) -> Zone {
        let k = self.blend_width(r);
        let inner = r + k + self.gap_min;
        Zone { a, b, inner, outer: inner + r.max(2.0 * self.h), k, partners: Vec::new() }
    }

    /// A junction at the sample `at` of tube `host` (its reach there grows with its branches').
    pub fn add_junction(&mut self, host: usize, at: &Sample) -> usize {
        self.junctions.push(Junction { point: at.p, on: vec![(host, at.s, 0.0)] });
        self.junctions.len() - 1
    }

    /// Sets each junction's host reach to its branches' largest.
    pub fn settle_host_reaches(&mut self) {
        for j in &mut self.junctions {
            let widest = j.on.iter().skip(1).map(|o| o.2).fold(0.0, f64::max);
            if let Some(host) = j.on.first_mut() {
                host.2 = host.2.max(widest);
            }
        }
    }
}

/// A centerline run the other way: from its last sample to its first.
pub fn reversed(samples: &[Sample]) -> Vec<Sample> {
    let length = samples.last().map_or(0.0, |q| q.s);
    samples.iter().rev().map(|q| Sample { p: q.p, t: -q.t, n: q.n, s: length - q.s, r: q.r }).collect()
}

/// The direction at branch angle `theta` from the unit tangent `t`, at azimuth `phi` about it
/// from the unit `u` (perpendicular to `t`) towards `u × t` (radians).
pub fn branch_direction(t: &Vector3<f64>, u: &Vector3<f64>, theta: f64, phi: f64) -> Vector3<f64> {
    direction_from(t, u, theta, -phi)
}

/// A closed ring through `vertices` (at least three), C¹: cubic Hermite arcs whose tangents at
/// each vertex are along the chord of its two neighbours (Catmull-Rom); the radius runs linearly
/// from each vertex's to its arc's middle radius and on to the next vertex's. Returns the
/// samples and each vertex's arc length, or `None` when an arc bends tighter than
/// [`MIN_CURVATURE_RADII`] radii.
pub fn ring(vertices: &[Point3<f64>], radii: &[f64], middles: &[f64]) -> Option<(Vec<Sample>, Vec<f64>)> {
    let n = vertices.len();
    let tangent = |i: usize| (vertices[(i + 1) % n] - vertices[(i + n - 1) % n]).normalize();
    let spacing = radii.iter().chain(middles).copied().fold(f64::INFINITY, f64::min);
    let up = (vertices[1] - vertices[0]).cross(&(vertices[2] - vertices[0]));
    let mut b = PathBuilder::new(vertices[0], tangent(0), up, radii[0], spacing);
    let mut at = vec![0.0];
    for i in 1..=n {
        let rho = b.hermite(&vertices[i % n], &tangent(i % n));
        if rho < MIN_CURVATURE_RADII * radii[i % n].max(radii[i - 1]) {
            return None;
        }
        at.push(b.length());
    }
    let knots: Vec<(f64, f64)> = (0..n)
        .flat_map(|i| [(at[i], radii[i]), (0.5 * (at[i] + at[i + 1]), middles[i])])
        .chain([(at[n], radii[0])])
        .collect();
    let samples = b.finish(|s| {
        let k = knots.windows(2).position(|w| s <= w[1].0).unwrap_or(knots.len() - 2);
        let (a, c) = (knots[k], knots[k + 1]);
        a.1 + (c.1 - a.1) * ((s - a.0) / (c.0 - a.0)).clamp(0.0, 1.0)
    });
    at.truncate(n);
    Some((samples, at))
}
