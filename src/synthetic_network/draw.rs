//! The three shapes' draws (see the module documentation of [`crate::synthetic_network`]) and
//! their laying: a ring fed by inlets (random, or the circle of Willis), a graft on its host.

use super::model::{Network, Tube};
use super::shapes::{branch_direction, ring, BranchSpec};
use crate::synthetic_tree::centerline::{direction_from, sample_at, PathBuilder, MIN_CURVATURE_RADII};
use crate::synthetic_tree::layout::{taper_profile, tortuous_body};
use crate::synthetic_tree::rng::SeededRng;
use crate::synthetic_tree::separation::junction_reach;
use nalgebra::{Point3, Vector3};
use serde_json::{json, Map, Value};
use std::f64::consts::{PI, TAU};

/// Which network a seed draws.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    Ring,
    Graft,
    CircleOfWillis,
}

impl Shape {
    /// A ring with probability 0.55, a graft 0.3, a circle of Willis 0.15.
    pub fn draw(rng: &mut SeededRng) -> Self {
        [Shape::Ring, Shape::Graft, Shape::CircleOfWillis][rng.weighted(&[0.55, 0.3, 0.15])]
    }

    pub fn name(&self) -> &'static str {
        match self {
            Shape::Ring => "ring",
            Shape::Graft => "graft",
            Shape::CircleOfWillis => "circle_of_willis",
        }
    }
}

/// Where a ring's branch leaves: a ring vertex, or the middle of an inlet (a side branch).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Attach {
    Vertex(usize),
    Inlet(usize),
}

/// Where an outlet splits into two (a side-branch tree of two ends): each daughter's radius
/// over the outlet's end radius, branch angle from the outlet's tangent (radians), on opposite
/// sides at `azimuth`; their tortuosity and body lengths in radii.
#[derive(Debug, Clone)]
pub struct SplitPlan {
    pub ratios: [f64; 2],
    pub angles: [f64; 2],
    pub azimuth: f64,
    pub tortuosity: [f64; 2],
    pub body_radii: [f64; 2],
}

impl SplitPlan {
    /// Daughters of 0.7 to 0.95 of the outlet's end radius at 30° to 70° from it, bodies of 3 to
    /// 8 radii (each uniform).
    fn draw(rng: &mut SeededRng) -> Self {
        SplitPlan {
            ratios: [rng.range(0.7, 0.95), rng.range(0.7, 0.95)],
            angles: [rng.range(30.0f64, 70.0).to_radians(), rng.range(30.0f64, 70.0).to_radians()],
            azimuth: rng.range(0.0, TAU),
            tortuosity: [rng.uniform(), rng.uniform()],
            body_radii: [rng.range(3.0, 8.0), rng.range(3.0, 8.0)],
        }
    }
}

/// One branch of a ring: where, its radius over its host's there, branch angle and azimuth
/// (radians; the azimuth about the host's tangent from the ring's outward radial towards its
/// up), taper, tortuosity, body length in radii, a label, and whether it splits.
#[derive(Debug, Clone)]
pub struct BranchPlan {
    pub at: Attach,
    pub ratio: f64,
    pub theta: f64,
    pub phi: f64,
    pub taper: f64,
    pub tortuosity: f64,
    pub body_radii: f64,
    pub label: &'static str,
    pub split: Option<SplitPlan>,
}

/// A ring's draws: its vertices (counter-clockwise about the up of its branches' azimuths), radii
/// at them and mid-arc, its inlets and outlets.
#[derive(Debug, Clone)]
pub struct RingPlan {
    pub shape: Shape,
    pub vertices: Vec<Point3<f64>>,
    pub radii: Vec<f64>,
    pub middles: Vec<f64>,
    pub inlets: Vec<BranchPlan>,
    pub outlets: Vec<BranchPlan>,
}

/// The tree generator's end styles: all open (0.5), all capped (0.3), mixed (0.2).
pub fn draw_end_style(rng: &mut SeededRng) -> &'static str {
    ["open", "capped", "mixed"][rng.weighted(&[0.5, 0.3, 0.2])]
}

/// `n` distinct indices below `total`, drawn uniformly.
fn choose(rng: &mut SeededRng, total: usize, n: usize) -> Vec<usize> {
    let mut pool: Vec<usize> = (0..total).collect();
    (0..n.min(total)).map(|_| pool.remove(rng.index(pool.len()))).collect()
}

impl RingPlan {
    /// A random ring (see the module documentation).
    pub fn draw(rng: &mut SeededRng) -> Self {
        let n = 3 + rng.index(4);
        let inlet_count = (2 + rng.index(2)).min(n);
        let r_ring = rng.log_range(0.5, 4.0);
        let radii: Vec<f64> = (0..n).map(|_| r_ring * rng.range(0.85, 1.15)).collect();
        let middles = (0..n).map(|i| 0.5 * (radii[i] + radii[(i + 1) % n]) * rng.range(0.8, 1.0)).collect();
        let chord = rng.range(12.0, 18.0) * r_ring;
        let big_r = chord / (2.0 * (PI / n as f64).sin());
        let lift = rng.range(0.0, 0.25) * big_r;
        let rotation = rng.rotation();
        let vertices = (0..n)
            .map(|i| {
                let a = TAU * (i as f64 + rng.range(-0.15, 0.15)) / n as f64;
                let local = Vector3::new(big_r * a.cos(), big_r * a.sin(), lift * rng.range(-1.0, 1.0));
                Point3::from(rotation * local)
            })
            .collect();
        let inlet_vertices = choose(rng, n, inlet_count);
        let inlets = inlet_vertices.iter().map(|&v| Self::draw_inlet(rng, v)).collect();
        let free: Vec<usize> = (0..n).filter(|v| !inlet_vertices.contains(v)).collect();
        let outlet_count = free.len().max(1) + rng.index(6 - free.len().max(1) + 1);
        let mut slots: Vec<Attach> = inlet_vertices.iter().map(|&v| Attach::Vertex(v)).collect();
        slots.extend((0..inlet_count).map(Attach::Inlet));
        let extra = (outlet_count - free.len()).min(slots.len());
        let mut at: Vec<Attach> = free.iter().map(|&v| Attach::Vertex(v)).collect();
        at.extend(choose(rng, slots.len(), extra).into_iter().map(|i| slots[i]));
        let outlets = at.into_iter().map(|a| Self::draw_outlet(rng, a)).collect();
        RingPlan { shape: Shape::Ring, vertices, radii, middles, inlets, outlets }
    }

    /// An inlet: 1 to 1.3 of its vertex's radius at the ring, widening by a taper of 0-30 %
    /// towards its free end, coming from below the ring.
    fn draw_inlet(rng: &mut SeededRng, vertex: usize) -> BranchPlan {
        BranchPlan {
            at: Attach::Vertex(vertex),
            ratio: rng.range(1.0, 1.3),
            theta: rng.range(60.0f64, 120.0).to_radians(),
            phi: rng.range(-110.0f64, -50.0).to_radians(),
            taper: rng.range(0.0, 0.3),
            tortuosity: rng.uniform(),
            body_radii: rng.range(6.0, 14.0),
            label: "",
            split: None,
        }
    }

    /// An outlet: 0.5 to 0.9 of its host's radius, above the ring at a vertex (splitting into
    /// two with probability 0.25), anywhere round an inlet at 30-80° from its flow.
    fn draw_outlet(rng: &mut SeededRng, at: Attach) -> BranchPlan {
        let (theta, phi) = match at {
            Attach::Vertex(_) => (rng.range(60.0f64, 120.0), rng.range(10.0f64, 80.0)),
            Attach::Inlet(_) => (rng.range(30.0f64, 80.0), rng.range(0.0f64, 360.0)),
        };
        BranchPlan {
            at,
            ratio: rng.range(0.5, 0.9),
            theta: theta.to_radians(),
            phi: phi.to_radians(),
            taper: rng.range(0.0, 0.3),
            tortuosity: rng.uniform(),
            body_radii: rng.range(4.0, 12.0),
            label: "",
            split: match at {
                Attach::Vertex(_) if rng.chance(0.25) => Some(SplitPlan::draw(rng)),
                _ => None,
            },
        }
    }

    /// The smallest radius the ring's lumen has anywhere (an outlet's after its taper).
    pub fn floor(&self) -> f64 {
        let ring = self.radii.iter().chain(&self.middles).copied().fold(f64::INFINITY, f64::min);
        let host = |b: &BranchPlan| match b.at {
            Attach::Vertex(v) => self.radii[v],
            Attach::Inlet(i) => self.radii[vertex_of(&self.inlets[i])] * self.inlets[i].ratio,
        };
        let outlets = self.outlets.iter().map(|b| {
            let daughters = b.split.as_ref().map_or(1.0, |sp| sp.ratios[0].min(sp.ratios[1]));
            host(b) * b.ratio * (1.0 - b.taper) * daughters
        });
        outlets.fold(ring, f64::min)
    }

    /// The draws for the manifest.
    pub fn draws(&self, end_style: &str) -> Map<String, Value> {
        let branch = |b: &BranchPlan| {
            json!({
                "at": match b.at { Attach::Vertex(v) => json!({"vertex": v}), Attach::Inlet(i) => json!({"inlet": i + 1}) },
                "radius_ratio": b.ratio,
                "branch_angle_deg": b.theta.to_degrees(),
                "azimuth_deg": b.phi.to_degrees(),
                "taper": b.taper,
                "tortuosity": b.tortuosity,
                "body_radii": b.body_radii,
                "split": b.split.as_ref().map(|sp| json!({
                    "radius_ratios": sp.ratios,
                    "branch_angles_deg": sp.angles.map(f64::to_degrees),
                    "azimuth_deg": sp.azimuth.to_degrees(),
                    "tortuosity": sp.tortuosity,
                    "body_radii": sp.body_radii,
                })),
            })
        };
        let mut m = Map::new();
        m.insert("shape".into(), json!(self.shape.name()));
        m.insert("end_style".into(), json!(end_style));
        m.insert("ring_vertices".into(), json!(self.vertices.iter().map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>()));
        m.insert("ring_vertex_radii_mm".into(), json!(self.radii));
        m.insert("ring_mid_arc_radii_mm".into(), json!(self.middles));
        m.insert("inlets".into(), json!(self.inlets.iter().map(branch).collect::<Vec<_>>()));
        m.insert("outlets".into(), json!(self.outlets.iter().map(branch).collect::<Vec<_>>()));
        m
    }
}

fn vertex_of(b: &BranchPlan) -> usize {
    match b.at {
        Attach::Vertex(v) | Attach::Inlet(v) => v,
    }
}

/// Lays a ring plan: the ring (one closed tube, a junction at each vertex), its inlets, the
/// outlets at vertices, then the side branches off the inlets. `Err` says what clashed.
pub fn lay_ring(rng: &mut SeededRng, plan: &RingPlan, end_style: &str) -> Result<Network, String> {
    let mut net = Network::new(plan.shape.name(), plan.floor(), plan.draws(end_style));
    let (samples, at) = ring(&plan.vertices, &plan.radii, &plan.middles)
        .ok_or_else(|| "a ring arc bends tighter than 1.5 radii".to_string())?;
    let centre =
        Point3::from(plan.vertices.iter().map(|p| p.coords).sum::<Vector3<f64>>() / plan.vertices.len() as f64);
    net.tubes.push(Tube {
        name: "ring".into(),
        samples,
        closed: true,
        start_end: None,
        end_end: None,
        zones: Vec::new(),
        side_anchor: None,
        draws: Map::new(),
    });
    for s in &at {
        let q = sample_at(&net.tubes[0].samples, *s);
        net.add_junction(0, &q);
    }
    let mut inlet_tubes = Vec::new();
    for (i, b) in plan.inlets.iter().enumerate() {
        let side = plan.outlets.iter().any(|o| o.at == Attach::Inlet(i));
        let name = format!("inlet_vessel_{}", i + 1);
        inlet_tubes.push(lay_at_vertex(rng, &mut net, &centre, b, name, (true, side, false))?);
    }
    for (k, b) in plan.outlets.iter().enumerate() {
        let name = format!("outlet_vessel_{}", k + 1);
        match b.at {
            Attach::Vertex(_) => {
                let id = lay_at_vertex(rng, &mut net, &centre, b, name.clone(), (false, false, b.split.is_none()))?;
                if let Some(sp) = &b.split {
                    lay_split(rng, &mut net, id, sp, &name)?;
                }
            }
            Attach::Inlet(i) => lay_side_branch(rng, &mut net, inlet_tubes[i], b, name)?,
        }
    }
    net.settle_host_reaches();
    Ok(net)
}

/// Lays branch `b` from its ring vertex: its direction from the ring's tangent there and its
/// outward radial (from the ring's centre) and up; `(inlet, side_room, free_end)` as
/// [`BranchSpec`]'s.
fn lay_at_vertex(
    rng: &mut SeededRng,
    net: &mut Network,
    centre: &Point3<f64>,
    b: &BranchPlan,
    name: String,
    (inlet, side_room, free_end): (bool, bool, bool),
) -> Result<usize, String> {
    let v = vertex_of(b);
    let host = sample_at(&net.tubes[0].samples, net.junctions[v].on[0].1);
    let radial = host.p - centre;
    let u = (radial - host.t * host.t.dot(&radial)).normalize();
    let spec = BranchSpec {
        radius: b.ratio * host.r,
        direction: branch_direction(&host.t, &u, b.theta, b.phi),
        taper: b.taper,
        tortuosity: b.tortuosity,
        body_radii: b.body_radii,
        inlet,
        side_room,
        free_end,
        label: b.label,
        name,
    };
    let what = spec.name.clone();
    net.lay_branch(rng, v, &host, spec).ok_or_else(|| format!("{what} cannot clear its junction"))
}

/// Lays outlet `b` off the middle of the straight stretch laid for it on inlet tube `inlet`.
fn lay_side_branch(
    rng: &mut SeededRng,
    net: &mut Network,
    inlet: usize,
    b: &BranchPlan,
    name: String,
) -> Result<(), String> {
    let s = net.tubes[inlet].side_anchor.ok_or_else(|| format!("{name}: its inlet has no room"))?;
    let host = sample_at(&net.tubes[inlet].samples, s);
    let j = net.add_junction(inlet, &host);
    let spec = BranchSpec {
        radius: b.ratio * host.r,
        direction: direction_from(&host.t, &host.n, b.theta, b.phi),
        taper: b.taper,
        tortuosity: b.tortuosity,
        body_radii: b.body_radii,
        inlet: false,
        side_room: false,
        free_end: true,
        label: b.label,
        name,
    };
    let what = spec.name.clone();
    net.lay_branch(rng, j, &host, spec).map(|_| ()).ok_or_else(|| format!("{what} cannot clear its junction"))
}

/// Splits outlet tube `parent` at its end into the two daughters of `sp` (a terminal junction,
/// as a tree's Y).
fn lay_split(rng: &mut SeededRng, net: &mut Network, parent: usize, sp: &SplitPlan, name: &str) -> Result<(), String> {
    let samples = &net.tubes[parent].samples;
    let q = samples[samples.len() - 1];
    let j = net.add_junction(parent, &q);
    for i in 0..2 {
        let spec = BranchSpec {
            radius: sp.ratios[i] * q.r,
            direction: direction_from(&q.t, &q.n, sp.angles[i], sp.azimuth + i as f64 * PI),
            taper: 0.0,
            tortuosity: sp.tortuosity[i],
            body_radii: sp.body_radii[i],
            inlet: false,
            side_room: false,
            free_end: true,
            label: "",
            name: format!("{name}.{}", i + 1),
        };
        net.lay_branch(rng, j, &q, spec).ok_or_else(|| format!("{name}.{}: cannot clear its junction", i + 1))?;
    }
    Ok(())
}

/// The circle of Willis (see the module documentation): seven ring vertices counter-clockwise
/// seen from above (x to the left, y anterior, z superior), both carotids and the basilar
/// feeding it, six cerebral arteries leaving it.
pub fn willis_plan(rng: &mut SeededRng) -> RingPlan {
    // Vertex, position (mm), radius (mm), radius in the middle of the arc to the next vertex.
    let ring: [(&str, [f64; 3], f64, f64); 7] = [
        ("right A1/A2", [-2.0, 14.0, 0.0], 0.9, 1.0),
        ("right carotid terminus", [-8.0, 6.0, -1.0], 1.3, 0.7),
        ("right P1/P2", [-7.0, -6.0, 0.5], 0.95, 1.0),
        ("basilar tip", [0.0, -9.0, 0.0], 1.2, 1.0),
        ("left P1/P2", [7.0, -6.0, 0.5], 0.95, 0.7),
        ("left carotid terminus", [8.0, 6.0, -1.0], 1.3, 1.0),
        ("left A1/A2", [2.0, 14.0, 0.0], 0.9, 0.75),
    ];
    let (scale, radius_scale) = (rng.range(0.9, 1.2), rng.range(0.9, 1.15));
    let vertices = ring
        .iter()
        .map(|(_, p, _, _)| {
            let jitter = Vector3::new(rng.range(-0.8, 0.8), rng.range(-0.8, 0.8), rng.range(-1.0, 1.0));
            Point3::from(Vector3::from(*p) * scale + jitter)
        })
        .collect();
    let radii = ring.iter().map(|r| r.2 * radius_scale).collect();
    let middles = ring.iter().map(|r| r.3 * radius_scale).collect();
    // (vertex, ratio to the vertex's radius, branch angle, azimuth, label): inlets from below,
    // the middle cerebrals lateral, the anterior cerebrals forward and up, diverging.
    let mut branch = |v: usize, ratio: f64, theta: f64, phi: f64, label: &'static str| BranchPlan {
        at: Attach::Vertex(v),
        ratio: ratio * rng.range(0.95, 1.05),
        theta: (theta + rng.range(-8.0, 8.0)).to_radians(),
        phi: (phi + rng.range(-8.0, 8.0)).to_radians(),
        taper: rng.range(0.05, 0.2),
        tortuosity: rng.range(0.0, 0.6),
        body_radii: rng.range(8.0, 12.0),
        label,
        split: None,
    };
    let inlets = vec![
        branch(1, 1.15, 90.0, -75.0, "right internal carotid artery"),
        branch(3, 1.1, 90.0, -85.0, "basilar artery"),
        branch(5, 1.15, 90.0, -75.0, "left internal carotid artery"),
    ];
    let outlets = vec![
        branch(0, 1.1, 70.0, 55.0, "right anterior cerebral artery"),
        branch(1, 1.0, 90.0, 10.0, "right middle cerebral artery"),
        branch(2, 1.0, 90.0, 15.0, "right posterior cerebral artery"),
        branch(4, 1.0, 90.0, 15.0, "left posterior cerebral artery"),
        branch(5, 1.0, 90.0, 10.0, "left middle cerebral artery"),
        branch(6, 1.1, 110.0, 55.0, "left anterior cerebral artery"),
    ];
    RingPlan { shape: Shape::CircleOfWillis, vertices, radii, middles, inlets, outlets }
}

/// A graft's draws: the host's radius and taper, the graft's radius ratio, its two angles to the
/// host, its azimuth, the host's tortuosity and bodies, the span between the anchors beyond what
/// the two junctions need.
#[derive(Debug, Clone)]
pub struct GraftPlan {
    pub radius: f64,
    pub taper: f64,
    pub ratio: f64,
    pub angles: [f64; 2],
    pub azimuth: f64,
    pub tortuosity: f64,
    pub bodies_radii: [f64; 2],
    pub extra_span_radii: f64,
}

impl GraftPlan {
    pub fn draw(rng: &mut SeededRng) -> Self {
        GraftPlan {
            radius: rng.log_range(0.5, 4.0),
            taper: rng.range(0.0, 0.3),
            ratio: rng.range(0.5, 0.9),
            angles: [rng.range(25.0f64, 60.0).to_radians(), rng.range(25.0f64, 60.0).to_radians()],
            azimuth: rng.range(0.0, TAU),
            tortuosity: rng.uniform(),
            bodies_radii: [rng.range(3.0, 8.0), rng.range(3.0, 8.0)],
            extra_span_radii: rng.range(2.0, 8.0),
        }
    }

    fn draws(&self, end_style: &str) -> Map<String, Value> {
        let mut m = Map::new();
        m.insert("shape".into(), json!("graft"));
        m.insert("end_style".into(), json!(end_style));
        m.insert("host_radius_mm".into(), json!(self.radius));
        m.insert("host_taper".into(), json!(self.taper));
        m.insert("graft_radius_ratio".into(), json!(self.ratio));
        m.insert("graft_angles_deg".into(), json!(self.angles.map(f64::to_degrees)));
        m.insert("graft_azimuth_deg".into(), json!(self.azimuth.to_degrees()));
        m.insert("host_tortuosity".into(), json!(self.tortuosity));
        m.insert("host_bodies_radii".into(), json!(self.bodies_radii));
        m.insert("extra_span_radii".into(), json!(self.extra_span_radii));
        m
    }
}

/// Lays a graft plan: the host from its inlet (a tortuous body, a straight stretch holding both
/// anchors, a tortuous body, to its outlet), then the graft leaving it at the first anchor and
/// arriving at the second (straight out of each junction, a Hermite arch between).
pub fn lay_graft(rng: &mut SeededRng, plan: &GraftPlan, end_style: &str) -> Result<Network, String> {
    let big_r = plan.radius;
    let r = plan.ratio * big_r * (1.0 - plan.taper);
    let floor = r.min(big_r * (1.0 - plan.taper));
    let mut net = Network::new("graft", floor, plan.draws(end_style));
    let k = net.blend_width(r);
    let stretch = plan.angles.map(|a| (big_r + r + k + net.gap_min) / a.sin() + r);
    let span = stretch[0] * plan.angles[0].cos() + stretch[1] * plan.angles[1].cos() + plan.extra_span_radii * big_r;
    let rotation = rng.rotation();
    let mut b = PathBuilder::new(Point3::origin(), rotation * Vector3::z(), rotation * Vector3::x(), big_r, big_r);
    b.straight(2.0 * big_r);
    let body_start = b.length();
    tortuous_body(rng, &mut b, big_r, plan.bodies_radii[0] * big_r, plan.tortuosity, false);
    let anchors = [b.length() + 2.0 * big_r, b.length() + 2.0 * big_r + span];
    b.straight(span + 4.0 * big_r);
    tortuous_body(rng, &mut b, big_r, plan.bodies_radii[1] * big_r, plan.tortuosity, false);
    let body_end = b.length();
    b.straight(2.0 * big_r);
    let samples = b.finish(|s| taper_profile(s, body_start, body_end, big_r, plan.taper, floor));
    net.tubes.push(Tube {
        name: "host".into(),
        samples,
        closed: false,
        start_end: None,
        end_end: None,
        zones: Vec::new(),
        side_anchor: None,
        draws: Map::new(),
    });
    let inlet = net.add_end(rng, 0, true, true, "");
    let outlet = net.add_end(rng, 0, false, false, "");
    (net.tubes[0].start_end, net.tubes[0].end_end) = (Some(inlet), Some(outlet));
    lay_graft_vessel(&mut net, plan, anchors, stretch, r)?;
    net.settle_host_reaches();
    Ok(net)
}

/// The graft itself: from the host's first anchor at the first angle, an arch, into the second
/// anchor at the second angle, on the side of the drawn azimuth.
fn lay_graft_vessel(
    net: &mut Network,
    plan: &GraftPlan,
    anchors: [f64; 2],
    stretch: [f64; 2],
    r: f64,
) -> Result<(), String> {
    let host = [0, 1].map(|i| sample_at(&net.tubes[0].samples, anchors[i]));
    let out = direction_from(&host[0].t, &host[0].n, plan.angles[0], plan.azimuth);
    let side = (out - host[0].t * plan.angles[0].cos()) / plan.angles[0].sin();
    let arrive = host[1].t * plan.angles[1].cos() - side * plan.angles[1].sin();
    let mut b = PathBuilder::new(host[0].p, out, host[0].t, r, r);
    b.straight(stretch[0]);
    let rho = b.hermite(&(host[1].p - arrive * stretch[1]), &arrive);
    if rho < MIN_CURVATURE_RADII * r {
        return Err("the graft's arch bends tighter than 1.5 radii".into());
    }
    b.straight(stretch[1]);
    let samples = b.finish(|_| r);
    let k = net.blend_width(r);
    let length = samples.last().map_or(0.0, |q| q.s);
    let zones = vec![
        net.junction_zone(host[0].p, host[0].p + out * stretch[0], r),
        net.junction_zone(host[1].p, host[1].p - arrive * stretch[1], r),
    ];
    let mut draws = Map::new();
    draws.insert("radius_mm".into(), json!(r));
    net.tubes.push(Tube {
        name: "graft".into(),
        samples,
        closed: false,
        start_end: None,
        end_end: None,
        zones,
        side_anchor: None,
        draws,
    });
    for (i, s) in [0.0, length].into_iter().enumerate() {
        let reach = junction_reach(host[i].r, r, k, net.gap_min, plan.angles[i]).max(stretch[i]);
        let j = net.add_junction(0, &host[i]);
        net.junctions[j].on.push((1, s, reach));
    }
    Ok(())
}
