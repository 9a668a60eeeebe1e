//! The centerline model: a tree of branches, each resampled, smoothed and equipped with
//! twist-free frames.
//!
//! Frames are *parallel-transport* (rotation-minimising) frames, computed with the double
//! reflection method of Wang, Juttler, Zheng and Liu (ACM TOG 27(1), 2008). Frenet frames are
//! never used: they are undefined on straight parts and flip at inflection points, which would
//! twist the O-grid blocks and shear the elements.

use crate::config::CenterlineConfig;
use crate::error::{Error, Result};
use crate::input::{CenterlinePolyline, Centerlines};
use nalgebra::{Point3, Vector3};

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

/// A deterministic unit vector perpendicular to `t`: the projection of the world axis least
/// aligned with it.
pub fn any_perpendicular(t: &Vector3<f64>) -> Vector3<f64> {
    let axis = if t.x.abs() <= t.y.abs() && t.x.abs() <= t.z.abs() {
        Vector3::x()
    } else if t.y.abs() <= t.z.abs() {
        Vector3::y()
    } else {
        Vector3::z()
    };
    (axis - t * axis.dot(t)).normalize()
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
}

impl Branch {
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
}

impl CenterlineTree {
    /// Builds the tree from the polylines of a centerline file.
    ///
    /// Today a single inlet-to-outlet polyline is supported; its first point is the inlet (the
    /// VMTK convention: centerlines run from the source to the targets).
    pub fn build(centerlines: &Centerlines, config: &CenterlineConfig) -> Result<CenterlineTree> {
        let path = &centerlines.source;
        match centerlines.polylines.len() {
            0 => return Err(Error::input(path, "the centerline file holds no polyline")),
            1 => {}
            n => {
                return Err(Error::input(
                    path,
                    format!(
                        "the centerline file holds {n} polylines: branching vessels are not supported yet; \
                         give one polyline from the inlet to the outlet"
                    ),
                ))
            }
        }
        let branch = build_branch("branch_0", &centerlines.polylines[0], config, path)?;
        Ok(CenterlineTree { branches: vec![branch], junctions: vec![] })
    }
}

/// Resamples, smooths and frames one polyline.
fn build_branch(
    name: &str,
    line: &CenterlinePolyline,
    config: &CenterlineConfig,
    path: &std::path::Path,
) -> Result<Branch> {
    let radii = line.radii.as_ref().ok_or_else(|| {
        Error::input(
            path,
            "the centerline has no radius: a MaximumInscribedSphereRadius point array (VTK) or an `r` column \
             (CSV) is required",
        )
    })?;
    // Drop repeated points (VMTK writes some), keep radii aligned.
    let mut pts: Vec<Point3<f64>> = Vec::with_capacity(line.points.len());
    let mut rad: Vec<f64> = Vec::with_capacity(line.points.len());
    for (k, (p, r)) in line.points.iter().zip(radii).enumerate() {
        if !(p.coords.iter().all(|c| c.is_finite()) && r.is_finite()) {
            return Err(Error::input(path, format!("centerline point {k} has a non-finite coordinate or radius")));
        }
        if *r <= 0.0 {
            return Err(Error::input(path, format!("centerline point {k} has radius {r}: radii must be positive")));
        }
        if pts.last().is_some_and(|q| (q - p).norm() < 1e-9) {
            continue;
        }
        pts.push(*p);
        rad.push(*r);
    }
    if pts.len() < 2 {
        return Err(Error::input(path, "the centerline has fewer than two distinct points"));
    }
    let mut sorted = rad.clone();
    sorted.sort_by(f64::total_cmp);
    let median_radius = sorted[sorted.len() / 2];
    let step = config.resample_step * median_radius;

    let (mut pts, mut rad) = resample(&pts, &rad, step);
    smooth(&mut pts, config.smoothing_passes);
    smooth_scalar(&mut rad, config.radius_smoothing_passes);

    let tangents = tangents(&pts);
    let hint = line
        .normals
        .as_ref()
        .and_then(|n| n.first().copied())
        .filter(|n| n.iter().all(|c| c.is_finite()) && n.norm() > 0.0)
        .unwrap_or_else(|| any_perpendicular(&tangents[0]));
    let frames = parallel_transport(&pts, &tangents, Frame::from_tangent_and_hint(tangents[0], hint));

    let mut s = 0.0;
    let samples = (0..pts.len())
        .map(|i| {
            if i > 0 {
                s += (pts[i] - pts[i - 1]).norm();
            }
            CenterlineSample { s, point: pts[i], radius: rad[i], frame: frames[i] }
        })
        .collect();
    Ok(Branch { name: name.to_string(), parent: None, daughters: vec![], samples, start_junction: None, end_junction: None })
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

/// The same smoothing for a scalar; the ends are free (mirrored) because end radii of image
/// based centerlines are the least reliable values.
fn smooth_scalar(v: &mut [f64], passes: usize) {
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
            (prev.normal - v1 * (2.0 / c1) * v1.dot(&prev.normal), prev.tangent - v1 * (2.0 / c1) * v1.dot(&prev.tangent))
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
        let tree = CenterlineTree::build(&cl, &config).unwrap();
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
    fn missing_radius_and_several_polylines_are_clear_errors() {
        let mut l = helix(10);
        l.radii = None;
        let cl = Centerlines { polylines: vec![l], source: "cl.vtp".into() };
        let e = CenterlineTree::build(&cl, &CenterlineConfig::default()).unwrap_err().to_string();
        assert!(e.contains("cl.vtp") && e.contains("MaximumInscribedSphereRadius"), "{e}");
        let cl = Centerlines { polylines: vec![helix(10), helix(10)], source: "cl.vtp".into() };
        let e = CenterlineTree::build(&cl, &CenterlineConfig::default()).unwrap_err().to_string();
        assert!(e.contains("2 polylines"), "{e}");
    }
}
