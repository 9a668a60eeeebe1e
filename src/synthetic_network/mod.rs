//! Random vessel networks with loops and several inlets (issue 49): `vesselhex fixtures
//! --random-network SEED` writes one, with its truth; `--circle-of-willis` writes the circle of
//! Willis.
//!
//! A seed maps to a network, drawn as tubes (centerlines with radii) that meet at junctions
//! ([`draw`], [`shapes`]). Its lumen, surface, checks and files are the tree generator's
//! ([`crate::synthetic_tree`]): the lumen is the smooth union of the tubes
//! ([`crate::synthetic_tree::lumen::TreeLumen::from_parts`]), each tube blended into the ones
//! laid before it only in the zones round the junctions it joins (a graft has one at each of its
//! two ends), on a grid of the smallest radius / 3.5; the surface is triangulated, its ends cut
//! open or capped flat, and checked as a tree's (manifold, one piece, outward, one boundary loop
//! per open end on its circle, flat caps in their planes, no angle below 5°) except for its
//! genus, which must equal the number of independent loops of the network's graph (with `b`
//! open ends, V - E + F = 2 - 2 g - b). Before meshing, the walls of tubes not joined at a
//! junction must keep two cells apart everywhere (plus a third of any blend width acting there),
//! and tubes joined at one may touch only within their junction reach of it
//! ([`crate::synthetic_tree::separation::junction_reach`]); each free end's clip zone must stay
//! clear. A draw failing any of this is drawn again from the seed's next stream (the manifest
//! says which attempts failed and why); a network is never written broken.
//!
//! The graph's segments are the tubes cut at their junctions; its nodes are the junctions and
//! the ends. Its loops are a cycle basis (one cycle per segment off a breadth-first spanning
//! tree), as many as E - V + 1.
//!
//! # Distributions (per seed; the manifest records every draw)
//!
//! * Shape: a ring (0.55), a graft (0.3), a circle of Willis (0.15). Ends: all open (0.5), all
//!   capped flat (0.3) or each capped with probability 1/2 (0.2), as trees.
//! * Ring: 3 to 6 vertices (uniform), counter-clockwise round a random axis on a circle whose
//!   chord between neighbours averages 12 to 18 ring radii, each vertex's angle jittered by
//!   ±0.15 of the mean step and lifted out of the plane by up to 0.25 of the circle's radius
//!   times a uniform draw in [-1, 1] (non-planar). Arcs are cubic Hermite curves with
//!   Catmull-Rom tangents (C¹ through the vertices; a draw bending an arc tighter than 1.5 radii
//!   is refused). Ring radius log-uniform in [0.5, 4] mm, each vertex's 0.85 to 1.15 of it, each
//!   arc's middle 0.8 to 1 of its vertices' mean (linear in between).
//! * Inlets: 2 or 3 (uniform, at most the vertices) at distinct vertices drawn uniformly; each
//!   1 to 1.3 of its vertex's radius at the ring, widening by a taper uniform in [0, 30 %]
//!   towards its free end, at a branch angle uniform in [60°, 120°] from the ring's tangent and
//!   an azimuth uniform in [-110°, -50°] (below the ring: 0° is the ring's outward radial, 90°
//!   its up); a body of 6 to 14 radii (the tree's root range), tortuosity uniform in [0, 1].
//! * Outlets: uniform between max(1, vertices without an inlet) and 6, capped at the vertices
//!   plus the inlets; one at each vertex without an inlet, the others at distinct places drawn
//!   among the inlets' vertices and the inlets' middles (a side branch, at 30° to 80° from the
//!   inlet's flow, any azimuth). Each 0.5 to 0.9 of its host's radius, tapering by up to 30 %,
//!   at a vertex at a branch angle uniform in [60°, 120°] and an azimuth in [10°, 80°] (above
//!   the ring); a body of 4 to 12 radii (the tree's daughters'), tortuosity uniform in [0, 1].
//!   An outlet at a vertex splits at its end into two with probability 0.25 (a side-branch
//!   tree of two ends, as a tree's Y): daughters of 0.7 to 0.95 of its end radius, at 30° to
//!   70° from it on opposite sides, bodies of 3 to 8 radii, no taper. So a ring has 1 to 6
//!   outlet branches and up to 12 outlets. One loop.
//! * Graft: a host from its inlet (radius log-uniform in [0.5, 4] mm, taper uniform in [0,
//!   30 %]): 2 straight radii, a tortuous body of 3 to 8 radii, a straight stretch holding both
//!   anchors, a tortuous body of 3 to 8 radii, 2 straight radii to its outlet. The graft (0.5 to
//!   0.9 of the host's radius) leaves at 25° to 60° and arrives at 25° to 60° (each uniform), on
//!   a side uniform round the host, straight out of each junction until its wall clears the
//!   host's by the blend and the gap, a Hermite arch between; the anchors are that far apart
//!   along the host plus 2 to 8 host radii. One inlet, one outlet, one loop.
//! * Circle of Willis: seven vertices (both A1/A2 junctions, both carotid termini, both P1/P2
//!   junctions, the basilar tip) at anatomical places scaled by 0.9 to 1.2 and jittered by up
//!   to 0.8 mm (1 mm vertically), radii of 0.9 to 1.3 mm (communicating arteries 0.7 to 0.75)
//!   scaled by 0.9 to 1.15; the ring's seven arcs are the anterior communicating, both A1s, both
//!   posterior communicating and both P1s. Inlets: both internal carotids and the basilar from
//!   below; outlets: the anterior (forward and up, diverging), middle (lateral) and posterior
//!   cerebral arteries, left and right. Angles within 8° of their anatomical values, tapers 5 to
//!   20 %, tortuosity up to 0.6, bodies of 8 to 12 radii. One loop. The ends carry their
//!   anatomical labels.

pub mod draw;
pub mod graph;
mod manifest;
pub mod model;
pub mod shapes;

use crate::error::{Error, Result};
use crate::implicit_surface::TriangulatedSurface;
use crate::input::{CenterlinePolyline, Centerlines};
use crate::progress::Progress;
use crate::synthetic_tree::centerline::{sample_at, Sample};
use crate::synthetic_tree::lumen::{mesh_lumen, LumenPart, TreeLumen};
use crate::synthetic_tree::rng::SeededRng;
use crate::synthetic_tree::truth::{dense_points, surface_radii, Redraw};
use crate::synthetic_tree::{write_surface_vtp, SurfaceFormat, MAX_ATTEMPTS};
use draw::{draw_end_style, lay_graft, lay_ring, willis_plan, GraftPlan, RingPlan, Shape};
use indexmap::IndexMap;
use model::{GraphSegment, Network};
use std::path::{Path, PathBuf};

/// Version of the network generator: a network is the same network for a seed within a version.
pub const GENERATOR_VERSION: u32 = 1;

/// A generated network: its draw (the truth), graph, checked surface and lumen.
pub struct RandomNetwork {
    pub seed: u64,
    /// The file stem: `network_<seed>`, or `circle_of_willis`.
    pub name: String,
    pub attempt: u32,
    pub redrawn: Vec<Redraw>,
    pub network: Network,
    pub segments: Vec<GraphSegment>,
    pub loops: Vec<Vec<usize>>,
    pub surface: TriangulatedSurface,
    pub lumen: TreeLumen,
}

/// Draws seed `seed`'s `attempt`-th network (the shape `forced` if given), or says what clashed.
pub fn draw_network(seed: u64, attempt: u32, forced: Option<Shape>) -> std::result::Result<Network, String> {
    let mut rng = SeededRng::new(seed, attempt);
    let shape = forced.unwrap_or(Shape::draw(&mut rng));
    let end_style = draw_end_style(&mut rng);
    let net = match shape {
        Shape::Ring => {
            let plan = RingPlan::draw(&mut rng);
            lay_ring(&mut rng, &plan, end_style)?
        }
        Shape::CircleOfWillis => {
            let plan = willis_plan(&mut rng);
            lay_ring(&mut rng, &plan, end_style)?
        }
        Shape::Graft => {
            let plan = GraftPlan::draw(&mut rng);
            lay_graft(&mut rng, &plan, end_style)?
        }
    };
    match net.clearance_defect() {
        Some(defect) => Err(defect),
        None => Ok(net),
    }
}

/// The lumen's parts: each tube in the order laid, extended past its free ends.
fn lumen_parts(net: &Network) -> Vec<LumenPart> {
    let ext = net.extension;
    net.tubes
        .iter()
        .map(|t| {
            let mut capsules = Vec::new();
            if t.start_end.is_some() {
                let q = t.samples[0];
                capsules.push((q.p - q.t * ext, q.p, q.r, q.r));
            }
            capsules.extend(t.samples.windows(2).map(|w| (w[0].p, w[1].p, w[0].r, w[1].r)));
            if let (Some(_), Some(q)) = (t.end_end, t.samples.last()) {
                capsules.push((q.p, q.p + q.t * ext, q.r, q.r));
            }
            LumenPart { capsules, zones: t.zones.clone() }
        })
        .collect()
}

impl RandomNetwork {
    /// The network of `seed` (of shape `forced` if given): the first of its draws that clears
    /// and whose surface passes every check.
    pub fn generate(seed: u64, forced: Option<Shape>, progress: &mut Progress) -> Result<Self> {
        let name = match forced {
            Some(Shape::CircleOfWillis) => "circle_of_willis".to_string(),
            _ => format!("network_{seed}"),
        };
        let mut redrawn = Vec::new();
        for attempt in 0..MAX_ATTEMPTS {
            progress.stage(&format!("{name}: drawing (attempt {})", attempt + 1));
            let network = match draw_network(seed, attempt, forced) {
                Ok(n) => n,
                Err(reason) => {
                    redrawn.push(Redraw { attempt, reason });
                    continue;
                }
            };
            let segments = network.segments();
            let loops = graph::independent_loops(&segments);
            progress.stage(&format!("{name}: surface"));
            let lumen = TreeLumen::from_parts(network.h, lumen_parts(&network));
            match mesh_lumen(&lumen, &network.end_circles(), loops.len() as i64) {
                Ok(surface) => {
                    return Ok(RandomNetwork { seed, name, attempt, redrawn, network, segments, loops, surface, lumen })
                }
                Err(d) => redrawn.push(Redraw {
                    attempt,
                    reason: format!("{} near ({:.4}, {:.4}, {:.4}) mm", d.what, d.at.x, d.at.y, d.at.z),
                }),
            }
        }
        let last = redrawn.last().map_or(String::new(), |r| r.reason.clone());
        Err(Error::Geometry(format!(
            "random network {seed}: every one of its {MAX_ATTEMPTS} draws failed its checks (the last: {last}); \
             try another seed"
        )))
    }

    /// The samples of segment `seg` (a ring's last segment runs back to its start).
    fn segment_samples(&self, seg: &GraphSegment) -> Vec<Sample> {
        let tube = &self.network.tubes[seg.tube];
        let length = tube.length();
        let at = |s: f64| {
            let mut q = sample_at(&tube.samples, if s > length { s - length } else { s });
            q.s = s;
            q
        };
        let mut out = vec![at(seg.s0)];
        for pass in [0.0, length] {
            let inside = tube.samples.iter().map(|q| (q, q.s + pass)).filter(|(_, s)| *s > seg.s0 && *s < seg.s1);
            out.extend(inside.map(|(q, s)| Sample { s, ..*q }));
        }
        out.push(at(seg.s1));
        out.dedup_by(|b, a| (b.s - a.s).abs() < 1e-12);
        out
    }

    /// The centerlines: one polyline per segment, along its tube, with
    /// `MaximumInscribedSphereRadius` the distance to the lumen surface and `SegmentIds`.
    pub fn centerlines(&self) -> Result<Centerlines> {
        let lines: Vec<Vec<_>> = self.segments.iter().map(|s| dense_points(&self.segment_samples(s))).collect();
        let radii = surface_radii(&self.lumen, &self.surface, &lines).ok_or_else(|| {
            Error::Geometry(format!("{}: a centerline point has no closest surface point", self.name))
        })?;
        let polylines = lines
            .iter()
            .zip(radii)
            .enumerate()
            .map(|(id, (pts, rs))| {
                let mut cell_tags = IndexMap::new();
                cell_tags.insert("SegmentIds".to_string(), id as i64);
                CenterlinePolyline {
                    points: pts.iter().map(|p| p.0).collect(),
                    radii: Some(rs),
                    normals: None,
                    cell_tags,
                }
            })
            .collect();
        Ok(Centerlines { polylines, source: PathBuf::from(format!("{} (synthetic)", self.name)) })
    }
}

/// What [`write_random_network`] wrote.
pub struct WrittenNetwork {
    pub surface: PathBuf,
    pub manifest: PathBuf,
    pub centerlines: PathBuf,
    pub network: RandomNetwork,
}

/// Generates network `seed` (the circle of Willis when `forced` says so) and writes its
/// surface, manifest and centerlines into `dir` (created if needed), each file atomically and
/// only once everything is computed. The bytes do not depend on the thread count.
pub fn write_random_network(
    seed: u64,
    forced: Option<Shape>,
    dir: &Path,
    format: SurfaceFormat,
    progress: &mut Progress,
) -> Result<WrittenNetwork> {
    let network = RandomNetwork::generate(seed, forced, progress)?;
    progress.stage(&format!("{}: centerlines", network.name));
    let centerlines = network.centerlines()?;
    let [surface, manifest, centerline_path] = crate::synthetic_tree::generated_paths(&network.name, dir, format);
    let file_name = |p: &Path| p.file_name().map_or(String::new(), |n| n.to_string_lossy().into_owned());
    let text = serde_json::to_string_pretty(&network.manifest(&file_name(&surface), &file_name(&centerline_path)))
        .map_err(|e| Error::Geometry(format!("{}: the manifest cannot be written: {e}", network.name)))?;
    progress.stage(&format!("{}: writing", network.name));
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, "creating the output folder", e))?;
    let s = &network.surface;
    match format {
        SurfaceFormat::Stl => {
            let header =
                format!("vesselhex {}: mm, outward normals, {} ends", network.name, network.network.ends.len());
            crate::synthetic::write_binary_stl(&surface, &header, &s.vertices, &s.triangles)?;
        }
        SurfaceFormat::Vtp => write_surface_vtp(&surface, &s.vertices, &s.triangles)?,
    }
    crate::writers::centerlines::write_vtp(&centerlines, 1.0, &centerline_path)?;
    crate::writers::write_atomic(&manifest, |w| {
        w.write_all(text.as_bytes())?;
        w.write_all(b"\n")
    })?;
    Ok(WrittenNetwork { surface, manifest, centerlines: centerline_path, network })
}
