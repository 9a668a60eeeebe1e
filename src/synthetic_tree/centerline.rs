//! A vessel's centerline: a C¹ curve of straight pieces, circular arcs and cubic Hermite pieces,
//! sampled into a polyline with a parallel-transported frame, and its radius along it.

use nalgebra::{Point3, Rotation3, Unit, Vector3};

/// A point of a vessel's centerline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    pub p: Point3<f64>,
    /// Unit tangent (downstream).
    pub t: Vector3<f64>,
    /// Unit normal, transported along the curve without twist (the frame's first normal).
    pub n: Vector3<f64>,
    /// Arc length from the vessel's start, mm.
    pub s: f64,
    /// Lumen radius, mm.
    pub r: f64,
}

impl Sample {
    /// The frame's second normal `t × n`.
    pub fn b(&self) -> Vector3<f64> {
        self.t.cross(&self.n)
    }
}

/// Smallest curvature radius of a tortuous piece, in the vessel's radii (a hairpin may go to
/// [`HAIRPIN_MIN_CURVATURE_RADII`]).
pub const MIN_CURVATURE_RADII: f64 = 1.5;
/// Smallest curvature radius of a hairpin bend, in the vessel's radii: the tube's inner wall
/// keeps a fifth of a radius of curvature.
pub const HAIRPIN_MIN_CURVATURE_RADII: f64 = 1.2;

/// Builds a centerline piece by piece; every piece starts where and as the last one ended (C¹).
/// Points are `spacing` apart at most on straight pieces and a tenth of the curvature radius on
/// curved ones (a turn of at most 5.7° between samples).
#[derive(Debug, Clone)]
pub struct PathBuilder {
    pub samples: Vec<Sample>,
    spacing: f64,
}

impl PathBuilder {
    /// A path starting at `p` along the unit `t`, with frame normal `n` (made perpendicular).
    pub fn new(p: Point3<f64>, t: Vector3<f64>, n: Vector3<f64>, radius: f64, spacing: f64) -> Self {
        let n = (n - t * t.dot(&n)).normalize();
        PathBuilder { samples: vec![Sample { p, t, n, s: 0.0, r: radius }], spacing }
    }

    pub fn last(&self) -> &Sample {
        self.samples.last().expect("a path has a first point")
    }

    pub fn length(&self) -> f64 {
        self.last().s
    }

    fn push(&mut self, p: Point3<f64>, t: Vector3<f64>, ds: f64) {
        let last = *self.last();
        // Parallel transport: the rotation taking the last tangent to the new one.
        let n = match Rotation3::rotation_between(&last.t, &t) {
            Some(rot) => rot * last.n,
            None => last.n,
        };
        let n = (n - t * t.dot(&n)).normalize();
        self.samples.push(Sample { p, t, n, s: last.s + ds, r: last.r });
    }

    pub fn straight(&mut self, length: f64) {
        if length <= 0.0 {
            return;
        }
        let start = *self.last();
        let steps = (length / self.spacing).ceil().max(1.0) as usize;
        for i in 1..=steps {
            let d = length * i as f64 / steps as f64;
            self.push(start.p + start.t * d, start.t, length / steps as f64);
        }
    }

    /// A circular arc of `length` turning the tangent by `angle` (radians) towards the unit
    /// `towards` (perpendicular to the current tangent).
    pub fn arc(&mut self, length: f64, angle: f64, towards: &Vector3<f64>) {
        if angle.abs() < 1e-12 {
            self.straight(length);
            return;
        }
        let start = *self.last();
        let m = (towards - start.t * start.t.dot(towards)).normalize();
        let rho = length / angle;
        let steps = (length / self.spacing.min(0.1 * rho)).ceil().max(1.0) as usize;
        for i in 1..=steps {
            let a = angle * i as f64 / steps as f64;
            let p = start.p + start.t * (rho * a.sin()) + m * (rho * (1.0 - a.cos()));
            let t = start.t * a.cos() + m * a.sin();
            self.push(p, t, length / steps as f64);
        }
    }

    /// A cubic Hermite piece to `target` arriving along the unit `tangent`; returns its smallest
    /// curvature radius (the piece is added whatever it is; the caller judges).
    pub fn hermite(&mut self, target: &Point3<f64>, tangent: &Vector3<f64>) -> f64 {
        let start = *self.last();
        let chord = (target - start.p).norm();
        let (m0, m1) = (start.t * chord, tangent * chord);
        let point = |u: f64| {
            let (u2, u3) = (u * u, u * u * u);
            start.p.coords * (2.0 * u3 - 3.0 * u2 + 1.0)
                + m0 * (u3 - 2.0 * u2 + u)
                + target.coords * (-2.0 * u3 + 3.0 * u2)
                + m1 * (u3 - u2)
        };
        let d1 = |u: f64| {
            let u2 = u * u;
            start.p.coords * (6.0 * u2 - 6.0 * u)
                + m0 * (3.0 * u2 - 4.0 * u + 1.0)
                + target.coords * (-6.0 * u2 + 6.0 * u)
                + m1 * (3.0 * u2 - 2.0 * u)
        };
        let d2 = |u: f64| {
            start.p.coords * (12.0 * u - 6.0)
                + m0 * (6.0 * u - 4.0)
                + target.coords * (-12.0 * u + 6.0)
                + m1 * (6.0 * u - 2.0)
        };
        // Dense parameter samples, then points about `spacing` (or a tenth of the local
        // curvature radius) apart.
        let fine = 400;
        // Arc length runs along the polyline (the chord from the last point), as `sample_at`
        // interpolates it.
        let mut min_rho = f64::INFINITY;
        for i in 1..=fine {
            let u = i as f64 / fine as f64;
            let (v, a) = (d1(u), d2(u));
            let speed = v.norm();
            let rho = speed.powi(3) / v.cross(&a).norm().max(1e-300);
            min_rho = min_rho.min(rho);
            let p = Point3::from(point(u));
            let chord = (p - self.last().p).norm();
            if chord >= self.spacing.min(0.1 * rho) || i == fine {
                let t = if i == fine { *tangent } else { v / speed };
                self.push(p, t, chord);
            }
        }
        min_rho
    }

    /// The samples with radii from `radius(s)`.
    pub fn finish(mut self, radius: impl Fn(f64) -> f64) -> Vec<Sample> {
        for q in &mut self.samples {
            q.r = radius(q.s);
        }
        self.samples
    }
}

/// Direction at `angle` (radians) from the unit `t`, at azimuth `azimuth` about it measured from
/// the unit normal `n` towards `t × n`.
pub fn direction_from(t: &Vector3<f64>, n: &Vector3<f64>, angle: f64, azimuth: f64) -> Vector3<f64> {
    let radial = n * azimuth.cos() + t.cross(n) * azimuth.sin();
    (t * angle.cos() + radial * angle.sin()).normalize()
}

/// The point, tangent, frame and radius at arc length `s` of a sampled centerline (linear
/// between samples; the tangent and frame of the sample before).
pub fn sample_at(samples: &[Sample], s: f64) -> Sample {
    let i = samples.partition_point(|q| q.s <= s).clamp(1, samples.len().max(2) - 1);
    let (a, b) = (&samples[i - 1], &samples[i]);
    let u = if b.s > a.s { ((s - a.s) / (b.s - a.s)).clamp(0.0, 1.0) } else { 0.0 };
    Sample { p: a.p + (b.p - a.p) * u, t: a.t, n: a.n, s, r: a.r + (b.r - a.r) * u }
}

/// Inserts a sample at arc length `s` (on the segment containing it: the polyline is unchanged);
/// returns its index (an existing sample's when one lies within 1e-9 of `s`).
pub fn insert_sample(samples: &mut Vec<Sample>, s: f64) -> usize {
    if let Some(i) = samples.iter().position(|q| (q.s - s).abs() <= 1e-9 * (1.0 + s.abs())) {
        return i;
    }
    let q = sample_at(samples, s);
    let i = samples.partition_point(|x| x.s < s);
    samples.insert(i, q);
    i
}

/// Rotates a unit vector about a unit axis by `angle` radians.
pub fn rotate(v: &Vector3<f64>, axis: &Vector3<f64>, angle: f64) -> Vector3<f64> {
    Rotation3::from_axis_angle(&Unit::new_normalize(*axis), angle) * v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_arc_turns_by_its_angle_over_its_length_and_keeps_the_frame_normal() {
        let mut b = PathBuilder::new(Point3::origin(), Vector3::z(), Vector3::x(), 1.0, 0.5);
        b.straight(2.0);
        b.arc(3.0, 2.0, &Vector3::y());
        let samples = b.finish(|_| 1.0);
        let last = samples.last().unwrap();
        assert!((last.s - 5.0).abs() < 1e-12);
        assert!((last.t.dot(&Vector3::z()) - 2f64.cos()).abs() < 1e-12, "{:?}", last.t);
        // The bend is in the y-z plane, so the transported normal stays along x.
        assert!((last.n - Vector3::x()).norm() < 1e-9, "{:?}", last.n);
        // Arc end: rho (sin a, 1 - cos a) from the arc's start.
        let rho = 1.5;
        let expected = Point3::new(0.0, rho * (1.0 - 2f64.cos()), 2.0 + rho * 2f64.sin());
        assert!((last.p - expected).norm() < 1e-12);
        for w in samples.windows(2) {
            assert!(w[1].t.angle(&w[0].t) <= 0.1 + 1e-12 && w[1].s > w[0].s);
        }
    }

    #[test]
    fn a_hermite_piece_ends_at_its_target_along_its_tangent() {
        let mut b = PathBuilder::new(Point3::origin(), Vector3::z(), Vector3::x(), 1.0, 0.25);
        let target = Point3::new(4.0, 0.0, 6.0);
        let rho = b.hermite(&target, &Vector3::x());
        let last = *b.last();
        assert!((last.p - target).norm() < 1e-12 && (last.t - Vector3::x()).norm() < 1e-12);
        assert!(rho > 1.0 && rho < 10.0, "{rho}");
        let arc: f64 = b.samples.windows(2).map(|w| (w[1].p - w[0].p).norm()).sum();
        assert!((arc - last.s).abs() < 1e-9);
    }

    #[test]
    fn inserting_a_sample_keeps_the_polyline() {
        let mut b = PathBuilder::new(Point3::origin(), Vector3::z(), Vector3::x(), 1.0, 1.0);
        b.straight(3.0);
        let mut samples = b.finish(|s| 2.0 - 0.1 * s);
        let i = insert_sample(&mut samples, 1.25);
        assert_eq!(samples.len(), 5);
        assert!((samples[i].p - Point3::new(0.0, 0.0, 1.25)).norm() < 1e-15);
        assert!((samples[i].r - (2.0 - 0.125)).abs() < 1e-15);
        assert_eq!(insert_sample(&mut samples, 2.0), 3);
    }
}
