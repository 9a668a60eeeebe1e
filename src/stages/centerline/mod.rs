//! The centerline model: a tree of branches, each resampled, smoothed and equipped with
//! twist-free frames.
//!
//! Frames are *parallel-transport* (rotation-minimising) frames, computed with the double
//! reflection method of Wang, Juttler, Zheng and Liu (ACM TOG 27(1), 2008). Frenet frames are
//! never used: they are undefined on straight parts and flip at inflection points, which would
//! twist the O-grid blocks and shear the elements.

mod bend;
pub mod extract;
mod junction_centre;
mod rooted;
pub(crate) mod skeleton;

use crate::data::config::CenterlineConfig;
use crate::data::error::{Error, Result};
use crate::geometry::surface::LumenSurface;
use crate::geometry::vector::any_perpendicular;
use crate::io::input::Centerlines;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
pub(crate) use rooted::ForcedMerge;
use rooted::{hang, RootedTree};
use skeleton::{Line, Skeleton};

/// Right-handed orthonormal frame: `normal x binormal = tangent`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    pub tangent: Vector3<f64>,
    pub normal: Vector3<f64>,
    pub binormal: Vector3<f64>,
}

impl Frame {
    /// The frame with the given tangent whose normal is the projection of `normal_hint`.
    pub fn from_tangent_and_hint(tangent: Vector3<f64>, normal_hint: Vector3<f64>) -> Frame {
        let t = tangent.normalize();
        let mut n = normal_hint - t * normal_hint.dot(&t);
        if n.norm() < 1e-9 {
            n = any_perpendicular(&t);
        }
        let n = n.normalize();
        Frame { tangent: t, normal: n, binormal: t.cross(&n) }
    }
}

/// One point of a branch after resampling and smoothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CenterlineSample {
    /// Arc length from the branch start, mm.
    pub s: f64,
    pub point: Point3<f64>,
    /// Maximal inscribed sphere radius, mm.
    pub radius: f64,
    pub frame: Frame,
}

/// A branch: from its start (the inlet, or a junction) to its end (an outlet, or a junction).
/// Samples run in the direction of the flow (inlet towards outlets). A branch that ends at a
/// junction ends exactly at the junction's centre; a branch that starts at one starts there.
#[derive(Debug, Clone)]
pub struct Branch {
    pub name: String,
    /// The branch upstream (None for the inlet branch).
    pub parent: Option<usize>,
    /// The branches that leave this one's downstream end.
    pub daughters: Vec<usize>,
    pub samples: Vec<CenterlineSample>,
    /// Junction at the upstream end (None: the vessel's inlet).
    pub start_junction: Option<usize>,
    /// Junction at the downstream end (None: an outlet).
    pub end_junction: Option<usize>,
}

/// Where a parent branch splits into two or more daughters.
#[derive(Debug, Clone)]
pub struct Junction {
    /// Centre of the junction: the point shared by the parent's last and the daughters' first
    /// samples, mm.
    pub centre: Point3<f64>,
    /// Maximal inscribed sphere radius at the centre, mm.
    pub radius: f64,
    /// The branch that ends here.
    pub parent: usize,
    /// The branches that start here, in a stable order.
    pub daughters: Vec<usize>,
    /// The branches besides the parent that end here: where a loop of a network closes (see
    /// [`crate::data::config::CenterlineConfig::loop_cuts_mm`]). Empty in a tree.
    pub arriving: Vec<usize>,
}

impl Branch {
    /// The one branch of an unbranched vessel, from its inlet to its outlet.
    pub fn lone(samples: Vec<CenterlineSample>) -> Branch {
        Branch {
            name: "branch_0".into(),
            parent: None,
            daughters: vec![],
            samples,
            start_junction: None,
            end_junction: None,
        }
    }

    pub fn length(&self) -> f64 {
        self.samples.last().map_or(0.0, |s| s.s)
    }

    /// Index i of the sample interval [i, i+1] containing arc length s.
    fn interval(&self, s: f64) -> (usize, f64) {
        let n = self.samples.len();
        let i = self.samples.partition_point(|q| q.s <= s).clamp(1, n - 1) - 1;
        let (a, b) = (&self.samples[i], &self.samples[i + 1]);
        let w = if b.s > a.s { ((s - a.s) / (b.s - a.s)).clamp(0.0, 1.0) } else { 0.0 };
        (i, w)
    }

    /// The centerline at arc length `s` (clamped to the branch), interpolated linearly; the frame
    /// is re-orthonormalised so it stays exactly orthonormal.
    pub fn at(&self, s: f64) -> CenterlineSample {
        let (i, w) = self.interval(s);
        let (a, b) = (&self.samples[i], &self.samples[i + 1]);
        let point = a.point + (b.point - a.point) * w;
        let radius = a.radius + (b.radius - a.radius) * w;
        let t = a.frame.tangent * (1.0 - w) + b.frame.tangent * w;
        let n = a.frame.normal * (1.0 - w) + b.frame.normal * w;
        CenterlineSample { s: a.s + (b.s - a.s) * w, point, radius, frame: Frame::from_tangent_and_hint(t, n) }
    }
}

/// All branches of a vessel and the junctions between them. Branch 0 starts at the inlet;
/// a parent always comes before its daughters.
#[derive(Debug, Clone)]
pub struct CenterlineTree {
    pub branches: Vec<Branch>,
    pub junctions: Vec<Junction>,
    /// Per branch, the skeleton edge it was built from (the same on every build from the same
    /// file and settings), to name a branch to [`CenterlineTree::build_merging`].
    pub(crate) segments: Vec<usize>,
    /// The skeleton edges whose far junction was merged into the upstream one because it lay
    /// close (see `CenterlineConfig::junction_merge_radii`), the merged junction kept at the
    /// upstream centre; [`CenterlineTree::build_merging`] can centre it along them instead.
    pub(crate) close_merges: Vec<usize>,
}

impl CenterlineTree {
    /// Builds the tree from the polylines of a centerline file.
    ///
    /// Any layout users bring is accepted (see [`skeleton`]): one polyline from the inlet to the
    /// outlet; overlapping inlet-to-outlet paths (VMTK, gmsh, our own extraction); the same
    /// split into tracts with GroupIds/Blanking; polylines meeting at shared end points. Points
    /// without a radius get the distance to `surface` (required then).
    ///
    /// The inlet: the end nearest `config.inlet_mm` when given; else, for a single polyline, its
    /// first point (VMTK's convention: source to target); else the end of largest radius (the
    /// median over about four radii of vessel next to the end, as end radii of image-based
    /// centerlines are the least reliable), because arterial trees narrow downstream. When the
    /// two largest ends differ by less than [`AMBIGUOUS_INLET`], the file's own start wins if
    /// it is one of them.
    pub fn build(
        centerlines: &Centerlines,
        config: &CenterlineConfig,
        surface: Option<&LumenSurface>,
    ) -> Result<CenterlineTree> {
        Self::build_merging(centerlines, config, surface, &[])
    }

    /// [`CenterlineTree::build`], with the junctions at the ends of the `forced` segments merged
    /// into their upstream neighbours, whatever their distance.
    pub(crate) fn build_merging(
        centerlines: &Centerlines,
        config: &CenterlineConfig,
        surface: Option<&LumenSurface>,
        forced: &[ForcedMerge],
    ) -> Result<CenterlineTree> {
        let path = &centerlines.source;
        if centerlines.polylines.is_empty() {
            return Err(Error::input(path, "the centerline file holds no polyline"));
        }
        let mut lines = clean_lines(centerlines, surface)?;
        let inlet_point = config.inlet_mm.map(Point3::from);
        if lines.len() == 1 {
            let mut line = lines.remove(0);
            if let Some(p) = inlet_point {
                if (line.points[line.points.len() - 1] - p).norm() < (line.points[0] - p).norm() {
                    line = line.reversed();
                }
            }
            let samples = build_samples(&line, config, FirstFrame::Hint, false)?;
            let branch = Branch::lone(samples);
            return Ok(CenterlineTree {
                branches: vec![branch],
                junctions: vec![],
                segments: vec![0],
                close_merges: vec![],
            });
        }
        let tags: Vec<_> = centerlines.polylines.iter().map(|l| l.cell_tags.clone()).collect();
        let skeleton = Skeleton::from_lines(lines, &tags, path)?;
        let inlet = choose_inlet(&skeleton, inlet_point, path)?;
        let mut rooted =
            hang(skeleton, inlet, config.junction_merge_radii, forced, config.split_fused_daughters, path)?;
        if let Some(surface) = surface {
            junction_centre::centre_junctions(&mut rooted, surface);
        }
        assemble(&rooted, config, path)
    }
}

/// Two largest ends closer in radius than this ratio: the file's own start is preferred.
pub const AMBIGUOUS_INLET: f64 = 0.9;

/// Checks the polylines (finite, positive radii, at least two distinct points), drops repeated
/// points and fills missing radii with the distance to the surface.
fn clean_lines(centerlines: &Centerlines, surface: Option<&LumenSurface>) -> Result<Vec<Line>> {
    let path = &centerlines.source;
    let several = centerlines.polylines.len() > 1;
    let place = |line: usize, point: usize| {
        if several {
            format!("point {point} of polyline {line}")
        } else {
            format!("centerline point {point}")
        }
    };
    let mut out = Vec::with_capacity(centerlines.polylines.len());
    for (k, line) in centerlines.polylines.iter().enumerate() {
        if let Some(i) = line.points.iter().position(|p| !p.coords.iter().all(|c| c.is_finite())) {
            return Err(Error::input(path, format!("{} has a non-finite coordinate", place(k, i))));
        }
        let radii =
            match (&line.radii, surface) {
                (Some(r), _) => r.clone(),
                (None, Some(s)) => radii_from_surface(line, s, k, path)?,
                (None, None) => return Err(Error::input(
                    path,
                    "the centerline has no radius: a MaximumInscribedSphereRadius point array (VTK) or an `r` column \
                     (CSV) is required, or the lumen surface to measure it on",
                )),
            };
        let mut clean = Line { points: vec![], radii: vec![], normals: line.normals.as_ref().map(|_| vec![]) };
        for (i, (p, r)) in line.points.iter().zip(&radii).enumerate() {
            if !r.is_finite() {
                return Err(Error::input(path, format!("{} has a non-finite coordinate or radius", place(k, i))));
            }
            if *r <= 0.0 {
                return Err(Error::input(path, format!("{} has radius {r}: radii must be positive", place(k, i))));
            }
            if clean.points.last().is_some_and(|q| (q - p).norm() < 1e-9) {
                continue;
            }
            clean.points.push(*p);
            clean.radii.push(*r);
            if let (Some(n), Some(all)) = (&mut clean.normals, &line.normals) {
                n.push(all[i]);
            }
        }
        if clean.points.len() < 2 {
            let what = if several { format!("polyline {k}") } else { "the centerline".to_string() };
            return Err(Error::input(path, format!("{what} has fewer than two distinct points")));
        }
        out.push(clean);
    }
    Ok(out)
}

/// Winding numbers below this (in magnitude) mean a point is outside the lumen.
const INSIDE_WINDING: f64 = 0.5;

/// The radius of a polyline that has none: the distance from each point to the surface. The
/// polyline must run inside the lumen (checked by winding numbers every half median radius,
/// except within two median radii of its ends, where an open end's winding number falls towards
/// 1/2).
fn radii_from_surface(
    line: &crate::io::input::CenterlinePolyline,
    surface: &LumenSurface,
    k: usize,
    path: &std::path::Path,
) -> Result<Vec<f64>> {
    let radii: Vec<f64> = line.points.par_iter().map(|p| surface.closest(p).distance).collect();
    // Ends are judged by arc length in median radii: a point outside the lumen has no radius.
    let mut sorted = radii.clone();
    sorted.sort_by(f64::total_cmp);
    let margin = 2.0 * sorted[sorted.len() / 2];
    let mut arcs = vec![0.0];
    for w in line.points.windows(2) {
        arcs.push(arcs[arcs.len() - 1] + (w[1] - w[0]).norm());
    }
    let length = arcs[arcs.len() - 1];
    let mut probes = vec![];
    let mut last_probe = f64::NEG_INFINITY;
    for (i, s) in arcs.iter().enumerate() {
        if *s > margin && *s < length - margin && s - last_probe >= 0.25 * margin {
            probes.push(i);
            last_probe = *s;
        }
    }
    let winding: Vec<f64> = probes.par_iter().map(|&i| surface.winding_number(&line.points[i])).collect();
    let outside = probes.iter().zip(&winding).find(|(_, w)| w.abs() < INSIDE_WINDING);
    let on_surface = radii.iter().position(|r| *r <= 0.0);
    if let Some((&i, w)) = outside {
        let p = line.points[i];
        return Err(Error::input(
            path,
            format!(
                "polyline {k} leaves the lumen surface {} at ({:.3}, {:.3}, {:.3}) mm (point {i}, winding number \
                 {w:.2}): the centerline is not this surface's, or the two files are in different units \
                 (--units, --centerline-units)",
                surface.source.display(),
                p.x,
                p.y,
                p.z
            ),
        ));
    }
    if let Some(i) = on_surface {
        let p = line.points[i];
        return Err(Error::input(
            path,
            format!(
                "point {i} of polyline {k} at ({:.3}, {:.3}, {:.3}) mm lies on the lumen surface {}: no radius there",
                p.x,
                p.y,
                p.z,
                surface.source.display()
            ),
        ));
    }
    Ok(radii)
}

/// The inlet node: nearest the given point, else the largest end (see [`CenterlineTree::build`]).
fn choose_inlet(skeleton: &Skeleton, point: Option<Point3<f64>>, path: &std::path::Path) -> Result<usize> {
    let degrees = skeleton.degrees();
    let ends: Vec<usize> = (0..skeleton.nodes.len()).filter(|&v| degrees[v] == 1).collect();
    if ends.len() < 2 {
        return Err(Error::input(
            path,
            format!(
                "the centerlines ({}) have {} free end(s): a vessel tree needs an inlet and an outlet",
                skeleton.layout,
                ends.len()
            ),
        ));
    }
    if let Some(p) = point {
        let nearest = ends
            .iter()
            .copied()
            .min_by(|&a, &b| (skeleton.nodes[a].point - p).norm().total_cmp(&(skeleton.nodes[b].point - p).norm()));
        return Ok(nearest.expect("ends is not empty"));
    }
    let mut sized: Vec<(f64, usize)> = ends.iter().map(|&v| (end_radius(skeleton, v), v)).collect();
    sized.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    if let Some(start) = skeleton.file_start {
        if sized[1].0 >= AMBIGUOUS_INLET * sized[0].0 && (sized[0].1 == start || sized[1].1 == start) {
            return Ok(start);
        }
    }
    Ok(sized[0].1)
}

/// The radius of the vessel at end node `v`: the median radius over the first four radii of
/// length of its edge (at most half the edge).
fn end_radius(skeleton: &Skeleton, v: usize) -> f64 {
    let Some(edge) = skeleton.edges.iter().find(|e| e.ends.contains(&v)) else {
        return 0.0;
    };
    let line = if edge.ends[0] == v { edge.line.clone() } else { edge.line.reversed() };
    let mut sorted = line.radii.clone();
    sorted.sort_by(f64::total_cmp);
    let reach = (4.0 * sorted[sorted.len() / 2]).min(0.5 * line.length());
    let arcs = line.arcs();
    let mut near: Vec<f64> = line.radii.iter().zip(&arcs).filter(|(_, s)| **s <= reach).map(|(r, _)| *r).collect();
    near.sort_by(f64::total_cmp);
    near[near.len() / 2]
}

/// Branches and junctions from the rooted tree, in its order; frames carried across junctions.
/// The two leaf edges that end at each of `config.loop_cuts_mm` are one branch (see
/// [`loop_pairs`]): the first's, run on through the second reversed to the second's junction,
/// where it arrives beside that junction's parent (see [`Junction::arriving`]).
fn assemble(rooted: &RootedTree, config: &CenterlineConfig, source: &std::path::Path) -> Result<CenterlineTree> {
    let pairs = loop_pairs(rooted, &config.loop_cuts_mm, source)?;
    let joined_to: std::collections::HashMap<usize, usize> = pairs.iter().copied().collect();
    let order: Vec<usize> = rooted.order.iter().copied().filter(|e| !pairs.iter().any(|p| p.1 == *e)).collect();
    let mut branch_of_edge = vec![usize::MAX; rooted.edges.len()];
    for (b, &e) in order.iter().enumerate() {
        branch_of_edge[e] = b;
    }
    let mut junction_of_node = vec![usize::MAX; rooted.nodes.len()];
    let mut branches: Vec<Branch> = Vec::with_capacity(order.len());
    let mut junctions: Vec<Junction> = vec![];
    for (b, &e) in order.iter().enumerate() {
        let edge = &rooted.edges[e];
        let [from, to] = edge.ends;
        let parent = rooted.parent[from].map(|p| branch_of_edge[p]);
        let first = match parent {
            None => FirstFrame::Hint,
            Some(p) => FirstFrame::Carried(branches[p].samples[branches[p].samples.len() - 1].frame),
        };
        let daughters: Vec<usize> =
            rooted.children[to].iter().map(|&d| branch_of_edge[d]).filter(|&d| d != usize::MAX).collect();
        let line = match joined_to.get(&e) {
            Some(&other) => {
                let mut line = edge.line.clone();
                line.extend(&rooted.edges[other].line.reversed());
                line
            }
            None => edge.line.clone(),
        };
        let samples = build_samples(&line, config, first, !daughters.is_empty() || joined_to.contains_key(&e))?;
        let end_junction = if daughters.is_empty() {
            None
        } else {
            let j = junctions.len();
            junction_of_node[to] = j;
            let node = &rooted.nodes[to];
            junctions.push(Junction {
                centre: node.point,
                radius: node.radius,
                parent: b,
                daughters: daughters.clone(),
                arriving: vec![],
            });
            Some(j)
        };
        branches.push(Branch {
            name: format!("branch_{b}"),
            parent,
            daughters,
            samples,
            start_junction: parent.map(|_| junction_of_node[from]),
            end_junction,
        });
    }
    for &(a, other) in &pairs {
        let j = junction_of_node[rooted.edges[other].ends[0]];
        let b = branch_of_edge[a];
        branches[b].end_junction = Some(j);
        junctions[j].arriving.push(b);
    }
    Ok(CenterlineTree { branches, junctions, segments: order, close_merges: rooted.close_merges.clone() })
}

/// A branch ends at a loop cut when its end lies within this many of its end radii of the cut:
/// the extraction opens a loop with a gap of 1.5 vessel radii (see `extract::loops`), each
/// end's centre half of it from the cut, and the radius at an open end is the least along the
/// branch.
const CUT_END_RADII: f64 = 2.0;

/// The two leaf edges ending at each loop cut (mm; see [`CUT_END_RADII`]), the earlier in the
/// tree's order first. Each must leave a junction, and not the same one.
fn loop_pairs(rooted: &RootedTree, cuts: &[[f64; 3]], source: &std::path::Path) -> Result<Vec<(usize, usize)>> {
    let mut pairs = vec![];
    for cut in cuts {
        let cut = Point3::from(*cut);
        let at_cut: Vec<usize> = rooted
            .order
            .iter()
            .copied()
            .filter(|&e| {
                let edge = &rooted.edges[e];
                let last = edge.line.points.len() - 1;
                rooted.children[edge.ends[1]].is_empty()
                    && (edge.line.points[last] - cut).norm() < CUT_END_RADII * edge.line.radii[last]
            })
            .collect();
        let from = |e: usize| rooted.edges[e].ends[0];
        match at_cut[..] {
            [a, b] if rooted.parent[from(a)].is_some() && rooted.parent[from(b)].is_some() && from(a) != from(b) => {
                pairs.push((a, b))
            }
            _ => {
                return Err(Error::input(
                    source,
                    format!(
                    "the loop cut open at ({:.3}, {:.3}, {:.3}) mm (centerline.loop_cuts_mm) cannot be joined again: \
                         {} vessel end(s) there, and two are needed, each on a branch from a different junction",
                    cut.x,
                    cut.y,
                    cut.z,
                    at_cut.len()
                ),
                ))
            }
        }
    }
    Ok(pairs)
}

/// How a branch's first frame is found.
#[derive(Debug, Clone, Copy)]
enum FirstFrame {
    /// The inlet branch: the file's normal at its first point if any, else any perpendicular.
    Hint,
    /// A daughter: the parent's last frame carried to the daughter's first tangent.
    Carried(Frame),
}

/// The frame turned by the smallest rotation that takes its tangent to `tangent` (the normal
/// keeps its angle to the plane of the two tangents: no spin about either).
pub fn carry_frame(frame: &Frame, tangent: &Vector3<f64>) -> Frame {
    let t = tangent.normalize();
    let axis = frame.tangent.cross(&t);
    let (sin, cos) = (axis.norm(), frame.tangent.dot(&t));
    let normal = if sin > 1e-12 {
        nalgebra::Rotation3::new(axis / sin * sin.atan2(cos)) * frame.normal
    } else {
        // Same direction, or reversed: a half turn about the normal keeps it.
        frame.normal
    };
    Frame::from_tangent_and_hint(t, normal)
}

/// Resamples, smooths and frames one polyline (its end points stay exactly where they are). The
/// radius is held at a junction end (`first` carried from a parent, or `ends_at_junction`),
/// where it is the junction's inscribed radius, and free at the vessel's ends.
fn build_samples(
    line: &Line,
    config: &CenterlineConfig,
    first: FirstFrame,
    ends_at_junction: bool,
) -> Result<Vec<CenterlineSample>> {
    let mut sorted = line.radii.clone();
    sorted.sort_by(f64::total_cmp);
    let median_radius = sorted[sorted.len() / 2];
    let step = config.resample_step * median_radius;

    let (mut pts, mut rad) = resample(&line.points, &line.radii, step);
    smooth(&mut pts, config.smoothing_passes);
    let starts_at_junction = matches!(first, FirstFrame::Carried(_));
    smooth_scalar(&mut rad, config.radius_smoothing_passes, [starts_at_junction, ends_at_junction]);

    let tangents = tangents(&pts);
    let first = match first {
        FirstFrame::Hint => {
            let hint = line
                .normals
                .as_ref()
                .and_then(|n| n.first().copied())
                .filter(|n| n.iter().all(|c| c.is_finite()) && n.norm() > 0.0)
                .unwrap_or_else(|| any_perpendicular(&tangents[0]));
            Frame::from_tangent_and_hint(tangents[0], hint)
        }
        FirstFrame::Carried(parent) => carry_frame(&parent, &tangents[0]),
    };
    let frames = parallel_transport(&pts, &tangents, first);

    let mut s = 0.0;
    Ok((0..pts.len())
        .map(|i| {
            if i > 0 {
                s += (pts[i] - pts[i - 1]).norm();
            }
            CenterlineSample { s, point: pts[i], radius: rad[i], frame: frames[i] }
        })
        .collect())
}

/// Uniform resampling by arc length with a step close to `step`.
fn resample(pts: &[Point3<f64>], rad: &[f64], step: f64) -> (Vec<Point3<f64>>, Vec<f64>) {
    let mut cum = vec![0.0];
    for w in pts.windows(2) {
        cum.push(cum.last().unwrap() + (w[1] - w[0]).norm());
    }
    let total = *cum.last().unwrap();
    let n = ((total / step).ceil() as usize).max(2);
    let mut out_p = Vec::with_capacity(n + 1);
    let mut out_r = Vec::with_capacity(n + 1);
    let mut j = 0;
    for i in 0..=n {
        let s = total * i as f64 / n as f64;
        while j + 2 < cum.len() && cum[j + 1] < s {
            j += 1;
        }
        let seg = cum[j + 1] - cum[j];
        let w = if seg > 0.0 { ((s - cum[j]) / seg).clamp(0.0, 1.0) } else { 0.0 };
        out_p.push(pts[j] + (pts[j + 1] - pts[j]) * w);
        out_r.push(rad[j] + (rad[j + 1] - rad[j]) * w);
    }
    // Exactly the given ends: a branch must end bit for bit at its junction's centre.
    out_p[0] = pts[0];
    out_p[n] = pts[pts.len() - 1];
    out_r[0] = rad[0];
    out_r[n] = rad[rad.len() - 1];
    (out_p, out_r)
}

/// Laplacian smoothing with fixed end points (weights 1/4, 1/2, 1/4).
fn smooth(pts: &mut [Point3<f64>], passes: usize) {
    let n = pts.len();
    if n < 3 {
        return;
    }
    let mut next = pts.to_vec();
    for _ in 0..passes {
        for i in 1..n - 1 {
            next[i] = Point3::from((pts[i - 1].coords + pts[i].coords * 2.0 + pts[i + 1].coords) * 0.25);
        }
        pts.copy_from_slice(&next);
    }
}

/// The same smoothing for a scalar. A free end is mirrored, because end radii of image based
/// centerlines are the least reliable values; a `fixed` end keeps its value (a junction's
/// inscribed radius, which the branches meeting there share).
fn smooth_scalar(v: &mut [f64], passes: usize, fixed: [bool; 2]) {
    let n = v.len();
    if n < 3 {
        return;
    }
    let mut next = v.to_vec();
    for _ in 0..passes {
        for i in 0..n {
            let a = v[i.saturating_sub(1)];
            let b = v[(i + 1).min(n - 1)];
            next[i] = 0.25 * a + 0.5 * v[i] + 0.25 * b;
        }
        if fixed[0] {
            next[0] = v[0];
        }
        if fixed[1] {
            next[n - 1] = v[n - 1];
        }
        v.copy_from_slice(&next);
    }
}

/// Unit tangents by central differences (one-sided at the ends).
fn tangents(pts: &[Point3<f64>]) -> Vec<Vector3<f64>> {
    let n = pts.len();
    (0..n)
        .map(|i| {
            let a = pts[i.saturating_sub(1)];
            let b = pts[(i + 1).min(n - 1)];
            (b - a).normalize()
        })
        .collect()
}

/// Rotation-minimising frames by double reflection (Wang et al. 2008).
fn parallel_transport(pts: &[Point3<f64>], tangents: &[Vector3<f64>], first: Frame) -> Vec<Frame> {
    let mut frames = vec![first];
    for i in 0..pts.len() - 1 {
        let prev = frames[i];
        let v1 = pts[i + 1] - pts[i];
        let c1 = v1.dot(&v1);
        let (r_l, t_l) = if c1 > 0.0 {
            (
                prev.normal - v1 * (2.0 / c1) * v1.dot(&prev.normal),
                prev.tangent - v1 * (2.0 / c1) * v1.dot(&prev.tangent),
            )
        } else {
            (prev.normal, prev.tangent)
        };
        let v2 = tangents[i + 1] - t_l;
        let c2 = v2.dot(&v2);
        let r = if c2 > 0.0 { r_l - v2 * (2.0 / c2) * v2.dot(&r_l) } else { r_l };
        frames.push(Frame::from_tangent_and_hint(tangents[i + 1], r));
    }
    frames
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::input::CenterlinePolyline;
    use indexmap::IndexMap;

    fn helix(n: usize) -> CenterlinePolyline {
        let (a, c) = (6.0, 20.0 / (2.0 * std::f64::consts::PI));
        let points = (0..n)
            .map(|i| {
                let t = i as f64 / (n - 1) as f64 * 2.5 * std::f64::consts::PI;
                Point3::new(a * t.cos(), a * t.sin(), c * t)
            })
            .collect();
        CenterlinePolyline { points, radii: Some(vec![1.5; n]), normals: None, cell_tags: IndexMap::new() }
    }

    #[test]
    fn frames_are_orthonormal_right_handed_and_twist_free() {
        let cl = Centerlines { polylines: vec![helix(400)], source: "helix".into() };
        let config = CenterlineConfig { smoothing_passes: 0, ..Default::default() };
        let tree = CenterlineTree::build(&cl, &config, None).unwrap();
        let b = &tree.branches[0];
        for w in b.samples.windows(2) {
            let f = w[1].frame;
            assert!((f.normal.cross(&f.binormal) - f.tangent).norm() < 1e-12);
            assert!(f.normal.dot(&f.tangent).abs() < 1e-12);
            // Rotation-minimising: the new normal is the old one carried by the smallest
            // rotation that turns the old tangent into the new one, with no spin about it.
            let (t0, t1) = (w[0].frame.tangent, f.tangent);
            let axis = t0.cross(&t1);
            let carried = if axis.norm() > 1e-15 {
                nalgebra::Rotation3::new(axis.normalize() * t0.dot(&t1).clamp(-1.0, 1.0).acos()) * w[0].frame.normal
            } else {
                w[0].frame.normal
            };
            let twist = carried.cross(&f.normal).dot(&t1).abs();
            // A Frenet frame would spin by the torsion, 0.069 rad/mm on this helix.
            assert!(twist < 1e-3 * (w[1].s - w[0].s), "twist {twist} rad per step");
        }
    }

    #[test]
    fn resampling_keeps_length_and_interpolates_radius() {
        let pts = vec![Point3::origin(), Point3::new(0.0, 0.0, 10.0)];
        let (p, r) = resample(&pts, &[1.0, 3.0], 0.5);
        assert_eq!(p.len(), 21);
        assert!((r[10] - 2.0).abs() < 1e-12);
        assert!((p[20].z - 10.0).abs() < 1e-12);
    }

    #[test]
    fn missing_radius_and_disconnected_polylines_are_clear_errors() {
        let mut l = helix(10);
        l.radii = None;
        let cl = Centerlines { polylines: vec![l], source: "cl.vtp".into() };
        let e = CenterlineTree::build(&cl, &CenterlineConfig::default(), None).unwrap_err().to_string();
        assert!(e.contains("cl.vtp") && e.contains("MaximumInscribedSphereRadius"), "{e}");
        let mut far = helix(10);
        far.points.iter_mut().for_each(|p| p.x += 100.0);
        let cl = Centerlines { polylines: vec![helix(10), far], source: "cl.vtp".into() };
        let e = CenterlineTree::build(&cl, &CenterlineConfig::default(), None).unwrap_err().to_string();
        assert!(e.contains("cl.vtp") && e.contains("polyline 1") && e.contains("does not connect"), "{e}");
    }
}
