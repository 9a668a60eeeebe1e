//! Synthetic vessels with an exact (analytic) lumen, used as test fixtures.
//!
//! Each fixture is a tube swept along a smooth centerline `c(s)`, parametrised by **arc length**
//! `s ∈ [0, L]` from the inlet (`s = 0`) to the outlet (`s = L`), with a lumen radius `r(s)`.
//! The lateral ("tube") wall is the union of the circles of radius `r(s)` centred on `c(s)` in
//! the plane normal to the tangent `t(s)`:
//!
//! ```text
//! q(s, θ) = c(s) + r(s) (cos θ u(s) + sin θ v(s)),     v = t × u,
//! ```
//!
//! where `(u, v)` is the **rotation-minimising** (parallel-transport) frame, given in closed form
//! for every shape, so that a surface swept with it has no twist. At the inlet of the
//! straight-axis fixtures and of the arc `u(0) = +x`, `v(0) = +y`, `t(0) = +z`.
//!
//! The fixtures, each exercising one thing (all lengths in millimetres):
//!
//! | name       | centerline                                   | radius r(s)       | ends                | normals |
//! |------------|----------------------------------------------|-------------------|---------------------|---------|
//! | `straight` | segment along +z, 30                         | 2                 | open                | outward |
//! | `curved`   | arc in the x-z plane, bend radius 15, 120°   | 2                 | open                | outward |
//! | `tapered`  | segment along +z, 40                         | 3 → 2, linear     | flat caps           | inward  |
//! | `helical`  | helix about z, radius 6, pitch 20, 1.25 turns | 1.5              | open                | outward |
//! | `aaa`      | segment along +z, 120                        | 10, sac up to 25  | hemispherical domes | outward |
//!
//! [`triangulate`] samples the surface at vertices that lie exactly (to f64 rounding) on it;
//! [`write_fixture`] writes the binary STL and the centerline CSV that the mesher's tests read,
//! and [`AnalyticVessel::distance_to_wall`] gives the exact distance those tests compare against.

use crate::data::error::{Error, Result};
use crate::writers::write_atomic;
use nalgebra::{Point3, Vector3};
use std::f64::consts::{FRAC_PI_2, PI, TAU};
use std::fmt;
use std::fs;
use std::path::{Path, PathBuf};

/// Spacing of the centerline points written to `<name>_centerline.csv` (the actual spacing is
/// `L / ceil(L / 0.5)`, i.e. uniform and at most this).
pub const CENTERLINE_SPACING_MM: f64 = 0.5;

/// Spacing of the coarse scan that brackets the closest point in
/// [`AnalyticVessel::closest_wall_point`].
const SCAN_SPACING_MM: f64 = 0.5;

/// How the surface is closed at the two ends of the tube part.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EndCaps {
    /// No cap: the surface has two boundary loops (the end rings).
    Open,
    /// A flat disk in the end's normal plane, radius `r(0)` resp. `r(L)`.
    Flat,
    /// A hemisphere of radius `r(0)` resp. `r(L)` centred on the end point of the centerline,
    /// bulging away from the tube (needs `r'(0) = r'(L) = 0` to be tangent-continuous).
    Hemispherical,
}

/// Which way the triangle normals (right-hand rule of the vertex order) point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Facing {
    /// Away from the lumen (the usual STL convention).
    Outward,
    /// Into the lumen (some segmentation tools write this; the reader must cope).
    Inward,
}

impl fmt::Display for Facing {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Facing::Outward => "outward",
            Facing::Inward => "inward",
        })
    }
}

/// Resolution of a triangulation: points around each ring and (maximum) axial spacing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resolution {
    pub circumferential: usize,
    pub axial_step_mm: f64,
}

/// The closest point of the lateral wall to a query point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WallPoint {
    /// Arc-length abscissa of the generating circle that holds the closest point, in `[0, L]`.
    pub s: f64,
    /// The closest point on the wall.
    pub point: Point3<f64>,
    /// Distance to `point`, negative when the query point is on the lumen side of the wall
    /// (sign of the offset along the wall's outward normal at `point`).
    pub signed_distance: f64,
}

/// A vessel with an analytic lumen: centerline, radius, ends and normal facing.
///
/// Implementors give the differential geometry in closed form; the provided methods do the
/// exact closest-point computation and the cap geometry.
pub trait AnalyticVessel {
    /// Short name, used for the file names (`<name>.stl`, `<name>_centerline.csv`).
    fn name(&self) -> &'static str;
    /// Arc length `L` of the centerline of the tube part (caps not included), mm.
    fn length(&self) -> f64;
    /// Centerline point `c(s)`.
    fn point(&self, s: f64) -> Point3<f64>;
    /// Unit tangent `t(s) = c'(s)`, pointing from inlet to outlet.
    fn tangent(&self, s: f64) -> Vector3<f64>;
    /// Curvature vector `t'(s) = κ(s) N(s)` (zero on straight parts).
    fn curvature_vector(&self, s: f64) -> Vector3<f64>;
    /// First vector `u(s)` of the rotation-minimising frame: unit, normal to `t(s)`, with
    /// `u'(s)` parallel to `t(s)` (no rotation about the tangent).
    fn frame_normal(&self, s: f64) -> Vector3<f64>;
    /// Lumen radius `r(s)`.
    fn radius(&self, s: f64) -> f64;
    /// `r'(s)`.
    fn radius_derivative(&self, s: f64) -> f64;
    /// An upper bound of the absolute principal curvatures of the whole surface (caps
    /// included), 1/mm. Used by [`chordal_tolerance`].
    fn max_principal_curvature(&self) -> f64;
    /// How the ends are closed.
    fn caps(&self) -> EndCaps;
    /// Which way the triangles of the fixture face.
    fn facing(&self) -> Facing;
    /// Resolution used for the committed fixture.
    fn resolution(&self) -> Resolution;

    /// Second frame vector `v(s) = t(s) × u(s)`.
    fn frame_binormal(&self, s: f64) -> Vector3<f64> {
        self.tangent(s).cross(&self.frame_normal(s))
    }

    /// The wall point `q(s, θ) = c(s) + r(s) (cos θ u(s) + sin θ v(s))`.
    fn wall_point(&self, s: f64, theta: f64) -> Point3<f64> {
        let e = self.frame_normal(s) * theta.cos() + self.frame_binormal(s) * theta.sin();
        self.point(s) + e * self.radius(s)
    }

    /// Whether the fixture's surface is closed (has caps).
    fn is_closed(&self) -> bool {
        self.caps() != EndCaps::Open
    }

    /// Closest point of the lateral wall (the tube part `s ∈ [0, L]`, caps excluded) to `p`.
    ///
    /// Exact: the wall is the union of the generating circles, and the distance from `p` to
    /// the circle at `s` is known in closed form, `g(s) = a² + (ρ - r)²` with
    /// `a = (p - c)·t` and `ρ = |p - c - a t|`. `g` is scanned every 0.5 mm, each local
    /// minimum of the scan is refined by golden-section search and then by bisection on the
    /// stationarity condition `g'(s)/2 = -a (1 - r u·t') - (ρ - r) r' = 0` (analytic
    /// derivative) down to the last bits of `s`, and the smallest of these and of the two ends
    /// wins. For points within `r` of the wall the result is exact to floating-point rounding
    /// (about 1e-12 mm); far from the wall it relies on the global minimum's basin being wider
    /// than the 0.5 mm scan, true for every fixture here.
    fn closest_wall_point(&self, p: &Point3<f64>) -> WallPoint {
        closest_wall_point(self, p)
    }

    /// Signed distance from `p` to the lateral wall (negative on the lumen side); see
    /// [`AnalyticVessel::closest_wall_point`] for how exact it is.
    fn distance_to_wall(&self, p: &Point3<f64>) -> f64 {
        self.closest_wall_point(p).signed_distance
    }

    /// Abscissa `s ∈ [0, L]` of the generating circle holding the wall point closest to `p`.
    fn closest_abscissa(&self, p: &Point3<f64>) -> f64 {
        self.closest_wall_point(p).s
    }

    /// Unsigned distance from `p` to the whole analytic surface: the lateral wall and, for
    /// closed fixtures, the two caps (flat disks or hemispheres, exact closed forms).
    fn distance_to_surface(&self, p: &Point3<f64>) -> f64 {
        let mut d = self.distance_to_wall(p).abs();
        for (s, away) in [(0.0, -1.0), (self.length(), 1.0)] {
            let centre = self.point(s);
            let axis = self.tangent(s) * away; // points out of the vessel
            let big_r = self.radius(s);
            let w = p - centre;
            let a = w.dot(&axis);
            let rho = (w - axis * a).norm();
            let cap = match self.caps() {
                EndCaps::Open => continue,
                EndCaps::Flat => a.hypot((rho - big_r).max(0.0)),
                EndCaps::Hemispherical if a >= 0.0 => (w.norm() - big_r).abs(),
                // Behind the dome's base plane: the closest dome point is on its rim.
                EndCaps::Hemispherical => a.hypot(rho - big_r),
            };
            d = d.min(cap);
        }
        d
    }
}

/// Distance data of `p` to the generating circle at `s`.
struct CircleOffset {
    /// Axial offset `(p - c)·t`.
    a: f64,
    /// Offset from the axis in the normal plane.
    rho: f64,
    /// Unit radial direction of `p` in the normal plane (`u(s)` when `p` is on the axis).
    dir: Vector3<f64>,
    r: f64,
}

fn circle_offset<V: AnalyticVessel + ?Sized>(v: &V, p: &Point3<f64>, s: f64) -> CircleOffset {
    let d = p - v.point(s);
    let t = v.tangent(s);
    let a = d.dot(&t);
    let perp = d - t * a;
    let rho = perp.norm();
    let dir = if rho > 0.0 { perp / rho } else { v.frame_normal(s) };
    CircleOffset { a, rho, dir, r: v.radius(s) }
}

/// Squared distance from `p` to the generating circle at `s`.
fn circle_dist2<V: AnalyticVessel + ?Sized>(v: &V, p: &Point3<f64>, s: f64) -> f64 {
    let o = circle_offset(v, p, s);
    o.a * o.a + (o.rho - o.r) * (o.rho - o.r)
}

/// Half the derivative of [`circle_dist2`] with respect to `s`.
fn circle_dist2_half_derivative<V: AnalyticVessel + ?Sized>(v: &V, p: &Point3<f64>, s: f64) -> f64 {
    let o = circle_offset(v, p, s);
    let uk = o.dir.dot(&v.curvature_vector(s));
    -o.a * (1.0 - o.r * uk) - (o.rho - o.r) * v.radius_derivative(s)
}

/// Local minimum of `g` in `[lo, hi]` by golden-section search, then polished by bisection on
/// the analytic derivative when it changes sign around the estimate.
fn refine_minimum<V: AnalyticVessel + ?Sized>(v: &V, p: &Point3<f64>, lo: f64, hi: f64) -> f64 {
    let g = |s: f64| circle_dist2(v, p, s);
    let inv_phi = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (lo, hi);
    let mut x1 = b - inv_phi * (b - a);
    let mut x2 = a + inv_phi * (b - a);
    let (mut g1, mut g2) = (g(x1), g(x2));
    for _ in 0..200 {
        if b - a <= 1e-9 * (1.0 + b.abs()) {
            break;
        }
        if g1 <= g2 {
            b = x2;
            x2 = x1;
            g2 = g1;
            x1 = b - inv_phi * (b - a);
            g1 = g(x1);
        } else {
            a = x1;
            x1 = x2;
            g1 = g2;
            x2 = a + inv_phi * (b - a);
            g2 = g(x2);
        }
    }
    let estimate = 0.5 * (a + b);
    let window = 1e-6 * (1.0 + estimate.abs());
    let (mut a, mut b) = ((estimate - window).max(lo), (estimate + window).min(hi));
    let dg = |s: f64| circle_dist2_half_derivative(v, p, s);
    if !(dg(a) <= 0.0 && dg(b) >= 0.0) {
        return estimate;
    }
    for _ in 0..200 {
        let m = 0.5 * (a + b);
        if m <= a || m >= b {
            break;
        }
        if dg(m) <= 0.0 {
            a = m;
        } else {
            b = m;
        }
    }
    if g(a) <= g(b) {
        a
    } else {
        b
    }
}

/// Point `i` of `n` uniform steps over `[0, len]`, exactly `len` at `i = n`.
fn uniform(len: f64, n: usize, i: usize) -> f64 {
    if i == n {
        len
    } else {
        len * i as f64 / n as f64
    }
}

fn closest_wall_point<V: AnalyticVessel + ?Sized>(v: &V, p: &Point3<f64>) -> WallPoint {
    let len = v.length();
    let n = ((len / SCAN_SPACING_MM).ceil() as usize).max(16);
    let samples: Vec<f64> = (0..=n).map(|i| uniform(len, n, i)).collect();
    let values: Vec<f64> = samples.iter().map(|&s| circle_dist2(v, p, s)).collect();
    let mut best = (0.0, values[0]);
    let mut consider = |s: f64| {
        let g = circle_dist2(v, p, s);
        if g < best.1 {
            best = (s, g);
        }
    };
    consider(len);
    for i in 0..=n {
        let left = if i > 0 { values[i - 1] } else { f64::INFINITY };
        let right = if i < n { values[i + 1] } else { f64::INFINITY };
        if values[i] <= left && values[i] <= right {
            let lo = samples[i.saturating_sub(1)];
            let hi = samples[(i + 1).min(n)];
            consider(refine_minimum(v, p, lo, hi));
        }
    }
    let s = best.0;
    let o = circle_offset(v, p, s);
    let point = v.point(s) + o.dir * o.r;
    // Offset along the outward normal ∝ (1 - r u·t') u - r' t decides the side.
    let side = (o.rho - o.r) * (1.0 - o.r * o.dir.dot(&v.curvature_vector(s))) - o.a * v.radius_derivative(s);
    let distance = best.1.max(0.0).sqrt();
    WallPoint { s, point, signed_distance: if side < 0.0 { -distance } else { distance } }
}

// ---------------------------------------------------------------------------------------------
// The five fixtures
// ---------------------------------------------------------------------------------------------

/// Straight tube along +z from the origin: the baseline (no curvature, no torsion, constant
/// radius, open ends, outward normals). Default: r = 2 mm, L = 30 mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Straight {
    pub radius: f64,
    pub length: f64,
}

impl Default for Straight {
    fn default() -> Self {
        Straight { radius: 2.0, length: 30.0 }
    }
}

impl AnalyticVessel for Straight {
    fn name(&self) -> &'static str {
        "straight"
    }
    fn length(&self) -> f64 {
        self.length
    }
    fn point(&self, s: f64) -> Point3<f64> {
        Point3::new(0.0, 0.0, s)
    }
    fn tangent(&self, _s: f64) -> Vector3<f64> {
        Vector3::z()
    }
    fn curvature_vector(&self, _s: f64) -> Vector3<f64> {
        Vector3::zeros()
    }
    fn frame_normal(&self, _s: f64) -> Vector3<f64> {
        Vector3::x()
    }
    fn radius(&self, _s: f64) -> f64 {
        self.radius
    }
    fn radius_derivative(&self, _s: f64) -> f64 {
        0.0
    }
    fn max_principal_curvature(&self) -> f64 {
        1.0 / self.radius
    }
    fn caps(&self) -> EndCaps {
        EndCaps::Open
    }
    fn facing(&self) -> Facing {
        Facing::Outward
    }
    fn resolution(&self) -> Resolution {
        Resolution { circumferential: 48, axial_step_mm: 0.5 }
    }
}

/// Circular arc in the x-z plane, starting at the origin along +z and bending towards +x:
/// constant **curvature** (1 / bend radius), no torsion, constant radius, open ends, outward
/// normals. `c(s) = R (1 - cos(s/R), 0, sin(s/R))`. Default: bend radius 15 mm, 120°, r = 2 mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurvedArc {
    pub bend_radius: f64,
    pub angle_deg: f64,
    pub radius: f64,
}

impl Default for CurvedArc {
    fn default() -> Self {
        CurvedArc { bend_radius: 15.0, angle_deg: 120.0, radius: 2.0 }
    }
}

impl AnalyticVessel for CurvedArc {
    fn name(&self) -> &'static str {
        "curved"
    }
    fn length(&self) -> f64 {
        self.bend_radius * self.angle_deg.to_radians()
    }
    fn point(&self, s: f64) -> Point3<f64> {
        let (sin, cos) = (s / self.bend_radius).sin_cos();
        Point3::new(self.bend_radius * (1.0 - cos), 0.0, self.bend_radius * sin)
    }
    fn tangent(&self, s: f64) -> Vector3<f64> {
        let (sin, cos) = (s / self.bend_radius).sin_cos();
        Vector3::new(sin, 0.0, cos)
    }
    fn curvature_vector(&self, s: f64) -> Vector3<f64> {
        let (sin, cos) = (s / self.bend_radius).sin_cos();
        Vector3::new(cos, 0.0, -sin) / self.bend_radius
    }
    /// For a planar curve the in-plane normal is rotation-minimising (the binormal, +y, is
    /// constant).
    fn frame_normal(&self, s: f64) -> Vector3<f64> {
        let (sin, cos) = (s / self.bend_radius).sin_cos();
        Vector3::new(cos, 0.0, -sin)
    }
    fn radius(&self, _s: f64) -> f64 {
        self.radius
    }
    fn radius_derivative(&self, _s: f64) -> f64 {
        0.0
    }
    fn max_principal_curvature(&self) -> f64 {
        let kappa = 1.0 / self.bend_radius;
        (1.0 / self.radius).max(kappa / (1.0 - self.radius * kappa))
    }
    fn caps(&self) -> EndCaps {
        EndCaps::Open
    }
    fn facing(&self) -> Facing {
        Facing::Outward
    }
    fn resolution(&self) -> Resolution {
        Resolution { circumferential: 48, axial_step_mm: 0.5 }
    }
}

/// Straight tube along +z from the origin with a linear **taper** (3 → 2 mm over 40 mm by
/// default), closed by **flat caps** whose triangles, like all others, face **into the lumen**
/// (inward normals): exercises cap removal and orientation repair in the reader.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tapered {
    pub inlet_radius: f64,
    pub outlet_radius: f64,
    pub length: f64,
}

impl Default for Tapered {
    fn default() -> Self {
        Tapered { inlet_radius: 3.0, outlet_radius: 2.0, length: 40.0 }
    }
}

impl AnalyticVessel for Tapered {
    fn name(&self) -> &'static str {
        "tapered"
    }
    fn length(&self) -> f64 {
        self.length
    }
    fn point(&self, s: f64) -> Point3<f64> {
        Point3::new(0.0, 0.0, s)
    }
    fn tangent(&self, _s: f64) -> Vector3<f64> {
        Vector3::z()
    }
    fn curvature_vector(&self, _s: f64) -> Vector3<f64> {
        Vector3::zeros()
    }
    fn frame_normal(&self, _s: f64) -> Vector3<f64> {
        Vector3::x()
    }
    fn radius(&self, s: f64) -> f64 {
        self.inlet_radius + (self.outlet_radius - self.inlet_radius) * (s / self.length)
    }
    fn radius_derivative(&self, _s: f64) -> f64 {
        (self.outlet_radius - self.inlet_radius) / self.length
    }
    fn max_principal_curvature(&self) -> f64 {
        1.0 / self.inlet_radius.min(self.outlet_radius)
    }
    fn caps(&self) -> EndCaps {
        EndCaps::Flat
    }
    fn facing(&self) -> Facing {
        Facing::Inward
    }
    fn resolution(&self) -> Resolution {
        Resolution { circumferential: 48, axial_step_mm: 0.5 }
    }
}

/// Circular helix around the z axis, `c(φ) = (a cos φ, a sin φ, b φ)` with `b = pitch / 2π`
/// and arc length `s = φ √(a² + b²)`, starting at `(a, 0, 0)`: constant **curvature and
/// torsion**, so the rotation-minimising frame differs from the Frenet frame by a rotation
/// `-τ s` (tests twist-free sweeping). Open ends, outward normals. Default: helix radius 6 mm,
/// pitch 20 mm, 1.25 turns, r = 1.5 mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Helical {
    pub helix_radius: f64,
    pub pitch: f64,
    pub turns: f64,
    pub radius: f64,
}

impl Default for Helical {
    fn default() -> Self {
        Helical { helix_radius: 6.0, pitch: 20.0, turns: 1.25, radius: 1.5 }
    }
}

impl Helical {
    fn rise(&self) -> f64 {
        self.pitch / TAU
    }
    /// Arc length per radian of the helix angle φ.
    fn speed(&self) -> f64 {
        self.helix_radius.hypot(self.rise())
    }
    /// Curvature `a / (a² + b²)`.
    pub fn curvature(&self) -> f64 {
        self.helix_radius / self.speed().powi(2)
    }
    /// Torsion `b / (a² + b²)`.
    pub fn torsion(&self) -> f64 {
        self.rise() / self.speed().powi(2)
    }
}

impl AnalyticVessel for Helical {
    fn name(&self) -> &'static str {
        "helical"
    }
    fn length(&self) -> f64 {
        TAU * self.turns * self.speed()
    }
    fn point(&self, s: f64) -> Point3<f64> {
        let phi = s / self.speed();
        let (sin, cos) = phi.sin_cos();
        Point3::new(self.helix_radius * cos, self.helix_radius * sin, self.rise() * phi)
    }
    fn tangent(&self, s: f64) -> Vector3<f64> {
        let phi = s / self.speed();
        let (sin, cos) = phi.sin_cos();
        Vector3::new(-self.helix_radius * sin, self.helix_radius * cos, self.rise()) / self.speed()
    }
    fn curvature_vector(&self, s: f64) -> Vector3<f64> {
        let (sin, cos) = (s / self.speed()).sin_cos();
        Vector3::new(-cos, -sin, 0.0) * self.curvature()
    }
    /// `u = cos(τ s) N - sin(τ s) B` with the Frenet normal `N = (-cos φ, -sin φ, 0)` and
    /// binormal `B = (b sin φ, -b cos φ, a) / √(a² + b²)`.
    fn frame_normal(&self, s: f64) -> Vector3<f64> {
        let phi = s / self.speed();
        let (sin, cos) = phi.sin_cos();
        let normal = Vector3::new(-cos, -sin, 0.0);
        let binormal = Vector3::new(self.rise() * sin, -self.rise() * cos, self.helix_radius) / self.speed();
        let (sin_t, cos_t) = (self.torsion() * s).sin_cos();
        normal * cos_t - binormal * sin_t
    }
    fn radius(&self, _s: f64) -> f64 {
        self.radius
    }
    fn radius_derivative(&self, _s: f64) -> f64 {
        0.0
    }
    fn max_principal_curvature(&self) -> f64 {
        let kappa = self.curvature();
        (1.0 / self.radius).max(kappa / (1.0 - self.radius * kappa))
    }
    fn caps(&self) -> EndCaps {
        EndCaps::Open
    }
    fn facing(&self) -> Facing {
        Facing::Outward
    }
    fn resolution(&self) -> Resolution {
        Resolution { circumferential: 48, axial_step_mm: 0.5 }
    }
}

/// Fusiform abdominal aortic aneurysm: straight axis along +z from the origin, neck radius
/// 10 mm, widening in the middle to a sac of radius 25 mm by a raised cosine over 60 mm
/// (`r = r_n + (r_s - r_n)(1 + cos(2π (s - L/2) / w)) / 2` for `|s - L/2| < w/2`; C¹, large
/// radius change and a concave/convex meridian), closed by **hemispherical domes** of radius
/// 10 mm beyond both ends of the 120 mm axis (so the surface spans z ∈ [-10, 130]); outward
/// normals. Exercises large radius variation and rounded caps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aaa {
    pub length: f64,
    pub neck_radius: f64,
    pub sac_radius: f64,
    pub sac_length: f64,
}

impl Default for Aaa {
    fn default() -> Self {
        Aaa { length: 120.0, neck_radius: 10.0, sac_radius: 25.0, sac_length: 60.0 }
    }
}

impl Aaa {
    /// Phase `2π (s - L/2) / w` of the raised cosine, `None` outside the sac.
    fn phase(&self, s: f64) -> Option<f64> {
        let x = s - 0.5 * self.length;
        (x.abs() < 0.5 * self.sac_length).then(|| TAU * x / self.sac_length)
    }
    fn bulge(&self) -> f64 {
        self.sac_radius - self.neck_radius
    }
}

impl AnalyticVessel for Aaa {
    fn name(&self) -> &'static str {
        "aaa"
    }
    fn length(&self) -> f64 {
        self.length
    }
    fn point(&self, s: f64) -> Point3<f64> {
        Point3::new(0.0, 0.0, s)
    }
    fn tangent(&self, _s: f64) -> Vector3<f64> {
        Vector3::z()
    }
    fn curvature_vector(&self, _s: f64) -> Vector3<f64> {
        Vector3::zeros()
    }
    fn frame_normal(&self, _s: f64) -> Vector3<f64> {
        Vector3::x()
    }
    fn radius(&self, s: f64) -> f64 {
        match self.phase(s) {
            Some(phase) => self.neck_radius + 0.5 * self.bulge() * (1.0 + phase.cos()),
            None => self.neck_radius,
        }
    }
    fn radius_derivative(&self, s: f64) -> f64 {
        match self.phase(s) {
            Some(phase) => -self.bulge() * PI / self.sac_length * phase.sin(),
            None => 0.0,
        }
    }
    fn max_principal_curvature(&self) -> f64 {
        // Parallels: 1/(r √(1 + r'²)) ≤ 1/r_neck (also the domes); meridian: |r''| ≤
        // bulge · 2π² / w².
        let meridian = self.bulge() * 2.0 * PI * PI / (self.sac_length * self.sac_length);
        (1.0 / self.neck_radius).max(meridian)
    }
    fn caps(&self) -> EndCaps {
        EndCaps::Hemispherical
    }
    fn facing(&self) -> Facing {
        Facing::Outward
    }
    fn resolution(&self) -> Resolution {
        Resolution { circumferential: 64, axial_step_mm: 2.0 }
    }
}

/// The five fixtures with their default dimensions, in a fixed order.
pub fn all_fixtures() -> Vec<Box<dyn AnalyticVessel>> {
    vec![
        Box::new(Straight::default()),
        Box::new(CurvedArc::default()),
        Box::new(Tapered::default()),
        Box::new(Helical::default()),
        Box::new(Aaa::default()),
    ]
}

/// The fixture called `name`, if any.
pub fn fixture_by_name(name: &str) -> Option<Box<dyn AnalyticVessel>> {
    all_fixtures().into_iter().find(|v| v.name() == name)
}

// ---------------------------------------------------------------------------------------------
// Triangulation
// ---------------------------------------------------------------------------------------------

/// One row of the sweep: a circle sampled at the ring angles, or a single pole vertex.
#[derive(Clone, Copy)]
enum Row {
    Circle { centre: Point3<f64>, u: Vector3<f64>, w: Vector3<f64>, radius: f64 },
    Pole(Point3<f64>),
}

/// Triangulation plus, per triangle, whether it lies in a flat cap (exactly planar, zero
/// chordal error).
struct Sweep {
    vertices: Vec<Point3<f64>>,
    triangles: Vec<[u32; 3]>,
    flat: Vec<bool>,
}

/// Number of steps between the rim and the pole of a cap.
fn cap_divisions(caps: EndCaps, radius: f64, step: f64) -> usize {
    match caps {
        EndCaps::Open => 0,
        EndCaps::Flat => ((radius / step).ceil() as usize).max(1),
        EndCaps::Hemispherical => ((FRAC_PI_2 * radius / step).ceil() as usize).max(2),
    }
}

/// The rows of the cap at abscissa `s` (an end), from the first one after the rim (which is the
/// tube's end ring) to the pole. `away` is +1 at the outlet, -1 at the inlet.
fn cap_rows<V: AnalyticVessel + ?Sized>(v: &V, s: f64, away: f64, step: f64) -> Vec<Row> {
    let end = v.point(s);
    let axis = v.tangent(s) * away;
    let (u, w) = (v.frame_normal(s), v.frame_binormal(s));
    let big_r = v.radius(s);
    let k = cap_divisions(v.caps(), big_r, step);
    let mut rows: Vec<Row> = (1..k)
        .map(|i| {
            let frac = i as f64 / k as f64;
            let (along, radius) = match v.caps() {
                EndCaps::Flat => (0.0, big_r * (1.0 - frac)),
                _ => {
                    let (sin, cos) = (FRAC_PI_2 * frac).sin_cos();
                    (big_r * sin, big_r * cos)
                }
            };
            Row::Circle { centre: end + axis * along, u, w, radius }
        })
        .collect();
    rows.push(Row::Pole(match v.caps() {
        EndCaps::Flat => end,
        _ => end + axis * big_r,
    }));
    rows
}

fn sweep<V: AnalyticVessel + ?Sized>(v: &V, circumferential: usize, axial_step_mm: f64) -> Sweep {
    assert!(circumferential >= 3, "need at least 3 points around");
    assert!(axial_step_mm > 0.0, "axial step must be positive");
    let len = v.length();
    let n = ((len / axial_step_mm).ceil() as usize).max(1);

    // Rows from the inlet (pole) to the outlet (pole); `flat_strips[k]` tells whether the strip
    // between rows k and k+1 lies in a flat cap.
    let mut rows = Vec::new();
    let mut flat_strips = Vec::new();
    let flat_caps = v.caps() == EndCaps::Flat;
    if v.is_closed() {
        let inlet = cap_rows(v, 0.0, -1.0, axial_step_mm);
        flat_strips.extend(std::iter::repeat_n(flat_caps, inlet.len()));
        rows.extend(inlet.into_iter().rev());
    }
    rows.extend((0..=n).map(|i| {
        let s = uniform(len, n, i);
        let (u, w) = (v.frame_normal(s), v.frame_binormal(s));
        Row::Circle { centre: v.point(s), u, w, radius: v.radius(s) }
    }));
    flat_strips.extend(std::iter::repeat_n(false, n));
    if v.is_closed() {
        let outlet = cap_rows(v, len, 1.0, axial_step_mm);
        flat_strips.extend(std::iter::repeat_n(flat_caps, outlet.len()));
        rows.extend(outlet);
    }
    debug_assert_eq!(flat_strips.len() + 1, rows.len());

    // Vertices: index of each row's first vertex.
    let angles: Vec<(f64, f64)> =
        (0..circumferential).map(|j| (TAU * j as f64 / circumferential as f64).sin_cos()).collect();
    let mut vertices = Vec::new();
    let mut first = Vec::with_capacity(rows.len());
    for row in &rows {
        first.push(vertices.len() as u32);
        match *row {
            Row::Circle { centre, u, w, radius } => {
                vertices.extend(angles.iter().map(|&(sin, cos)| centre + (u * cos + w * sin) * radius))
            }
            Row::Pole(p) => vertices.push(p),
        }
    }

    // Connect consecutive rows; the right-hand normal of (lower j, lower j+1, upper j+1) is
    // ∂q/∂θ × ∂q/∂s, i.e. outward.
    let mut triangles = Vec::new();
    let mut flat = Vec::new();
    let m = circumferential as u32;
    for k in 0..rows.len() - 1 {
        let before = triangles.len();
        let (l, u) = (first[k], first[k + 1]);
        for j in 0..m {
            let jn = (j + 1) % m;
            match (rows[k], rows[k + 1]) {
                (Row::Circle { .. }, Row::Circle { .. }) => {
                    triangles.push([l + j, l + jn, u + jn]);
                    triangles.push([l + j, u + jn, u + j]);
                }
                (Row::Pole(_), Row::Circle { .. }) => triangles.push([l, u + jn, u + j]),
                (Row::Circle { .. }, Row::Pole(_)) => triangles.push([l + j, l + jn, u]),
                (Row::Pole(_), Row::Pole(_)) => unreachable!("two consecutive poles"),
            }
        }
        flat.extend(std::iter::repeat_n(flat_strips[k], triangles.len() - before));
    }
    if v.facing() == Facing::Inward {
        for t in &mut triangles {
            t.swap(1, 2);
        }
    }
    Sweep { vertices, triangles, flat }
}

/// Triangulates the fixture's surface: rings of `circumferential` points swept along the
/// centerline with the rotation-minimising frame (no twist; ring point `j` is at angle
/// `θ_j = 2π j / circumferential` from `u(s)`), `ceil(L / axial_step_mm)` uniform steps in `s`,
/// each quad split along the same diagonal; caps as given by [`AnalyticVessel::caps`], made of
/// concentric rings sharing the end ring's vertices and closed by a fan around a pole vertex
/// (flat caps: radial step ≤ `axial_step_mm`; domes: latitude step ≤ `axial_step_mm` of arc).
/// Every vertex lies exactly (to f64 rounding) on the analytic surface. Triangles are wound as
/// [`AnalyticVessel::facing`] says. Closed fixtures are watertight by vertex index.
pub fn triangulate<V: AnalyticVessel + ?Sized>(
    v: &V,
    circumferential: usize,
    axial_step_mm: f64,
) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
    let s = sweep(v, circumferential, axial_step_mm);
    (s.vertices, s.triangles)
}

/// Circumradius of a triangle.
fn circumradius(a: &Point3<f64>, b: &Point3<f64>, c: &Point3<f64>) -> f64 {
    let (ab, bc, ca) = ((b - a).norm(), (c - b).norm(), (a - c).norm());
    let twice_area = (b - a).cross(&(c - a)).norm();
    ab * bc * ca / (2.0 * twice_area)
}

/// Bound on the distance between the fixture's triangulation, **as stored in an STL file**
/// (f32 coordinates), and the analytic surface, mm.
///
/// Chordal part: a triangle inscribed in a surface whose principal curvatures are at most
/// `K` deviates from it by at most about the sagitta of a sphere of radius `1/K` over the
/// triangle's circumcircle, `1/K - √(1/K² - R²)` (the worst case, a triangle inscribed in
/// that sphere, reaches it at the circumcentre); this is taken over all curved triangles
/// (those of flat caps lie exactly in the cap plane) with a safety factor of 1.5. f32 part:
/// rounding moves each vertex by at most `2⁻²⁴ |x|`, taken at the largest `|x|`. The bound is
/// checked against dense sampling of every fixture in the tests.
pub fn chordal_tolerance<V: AnalyticVessel + ?Sized>(v: &V, circumferential: usize, axial_step_mm: f64) -> f64 {
    let sw = sweep(v, circumferential, axial_step_mm);
    let sphere = 1.0 / v.max_principal_curvature();
    let mut chordal: f64 = 0.0;
    for (t, flat) in sw.triangles.iter().zip(&sw.flat) {
        if *flat {
            continue;
        }
        let [a, b, c] = t.map(|i| sw.vertices[i as usize]);
        let r = circumradius(&a, &b, &c);
        let sag = if r < sphere { sphere - (sphere * sphere - r * r).sqrt() } else { r };
        chordal = chordal.max(sag);
    }
    let largest = sw.vertices.iter().map(|p| p.coords.norm()).fold(0.0, f64::max);
    1.5 * chordal + largest * f64::from(f32::EPSILON) / 2.0
}

// ---------------------------------------------------------------------------------------------
// Files
// ---------------------------------------------------------------------------------------------

/// The abscissae of the centerline points written to the CSV: uniform, inlet to outlet, spacing
/// `L / ceil(L / 0.5 mm)`, both ends included (for closed fixtures the ends are where the caps
/// or domes begin).
pub fn centerline_abscissae<V: AnalyticVessel + ?Sized>(v: &V) -> Vec<f64> {
    let len = v.length();
    let n = ((len / CENTERLINE_SPACING_MM).ceil() as usize).max(1);
    (0..=n).map(|i| uniform(len, n, i)).collect()
}

/// Paths of the two files of fixture `name` in `dir`: the STL and the centerline CSV.
pub fn fixture_paths(name: &str, dir: &Path) -> (PathBuf, PathBuf) {
    (dir.join(format!("{name}.stl")), dir.join(format!("{name}_centerline.csv")))
}

/// Fixed 15 decimals: absolute resolution 1e-15 mm, at least 13 significant digits for any
/// value above 1 µm; deterministic, and never `-0.000…`.
fn fmt_coord(x: f64) -> String {
    let s = format!("{x:.15}");
    match s.strip_prefix('-') {
        Some(rest) if rest.bytes().all(|b| b == b'0' || b == b'.') => rest.to_string(),
        _ => s,
    }
}

/// The text of the binary STL header (never starting with `solid`, which readers take for ASCII).
fn stl_header<V: AnalyticVessel + ?Sized>(v: &V) -> String {
    format!("vesselhex synthetic fixture {}: mm, {} normals, caps {:?}", v.name(), v.facing(), v.caps())
}

/// Writes a triangulation atomically as a binary STL (f32 little-endian): the 80-byte header
/// (`header` padded with spaces or cut), the count, then per triangle the unit normal of its
/// winding and its three vertices, and a zero attribute word. Used by the unbranched and the
/// branching fixtures alike.
pub(crate) fn write_binary_stl(
    path: &Path,
    header: &str,
    vertices: &[Point3<f64>],
    triangles: &[[u32; 3]],
) -> Result<()> {
    let mut head = [b' '; 80];
    let n = header.len().min(80);
    head[..n].copy_from_slice(&header.as_bytes()[..n]);
    write_atomic(path, |w| {
        w.write_all(&head)?;
        w.write_all(&(triangles.len() as u32).to_le_bytes())?;
        for t in triangles {
            let [a, b, c] = t.map(|i| vertices[i as usize]);
            let normal = (b - a).cross(&(c - a)).normalize();
            for x in normal.iter().chain(a.iter()).chain(b.iter()).chain(c.iter()) {
                w.write_all(&(*x as f32).to_le_bytes())?;
            }
            w.write_all(&0u16.to_le_bytes())?;
        }
        Ok(())
    })
}

/// CSV `x,y,z,r` of the exact centerline at [`centerline_abscissae`].
fn centerline_csv<V: AnalyticVessel + ?Sized>(v: &V) -> String {
    let mut out = String::from("x,y,z,r\n");
    for s in centerline_abscissae(v) {
        let p = v.point(s);
        let row = [p.x, p.y, p.z, v.radius(s)].map(fmt_coord).join(",");
        out.push_str(&row);
        out.push('\n');
    }
    out
}

/// Writes `<name>.stl` (binary, at the fixture's [`AnalyticVessel::resolution`]) and
/// `<name>_centerline.csv` (header `x,y,z,r`) into `dir`, creating it if needed.
/// The output is deterministic (same bytes on every run on a given platform).
pub fn write_fixture<V: AnalyticVessel + ?Sized>(v: &V, dir: &Path) -> Result<()> {
    fs::create_dir_all(dir).map_err(|e| Error::io(dir, "creating fixture directory", e))?;
    let res = v.resolution();
    let (vertices, triangles) = triangulate(v, res.circumferential, res.axial_step_mm);
    let (stl, csv) = fixture_paths(v.name(), dir);
    write_binary_stl(&stl, &stl_header(v), &vertices, &triangles)?;
    write_atomic(&csv, |w| w.write_all(centerline_csv(v).as_bytes()))
}

/// Writes every fixture of [`all_fixtures`] into `dir`; returns the files written (STL then
/// CSV for each fixture, in fixture order).
pub fn write_all_fixtures(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    for v in all_fixtures() {
        write_fixture(v.as_ref(), dir)?;
        let (stl, csv) = fixture_paths(v.name(), dir);
        written.push(stl);
        written.push(csv);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Abscissae strictly inside the tube, away from the ends.
    fn interior(v: &dyn AnalyticVessel, n: usize) -> Vec<f64> {
        let len = v.length();
        (0..n).map(|i| len * (0.1 + 0.8 * (i as f64 + 0.37) / n as f64)).collect()
    }

    #[test]
    fn frames_are_orthonormal_arc_length_and_rotation_minimising() {
        let h = 1e-5;
        for v in all_fixtures() {
            for s in interior(v.as_ref(), 23) {
                let (t, u, w) = (v.tangent(s), v.frame_normal(s), v.frame_binormal(s));
                assert!((t.norm() - 1.0).abs() < 1e-14 && (u.norm() - 1.0).abs() < 1e-14);
                assert!(t.dot(&u).abs() < 1e-14 && w.dot(&t).abs() < 1e-14);
                // c' = t (arc length), t' = curvature vector, r' matches r.
                let dc = (v.point(s + h) - v.point(s - h)) / (2.0 * h);
                assert!((dc - t).norm() < 1e-8, "{} c' at {s}", v.name());
                let dt = (v.tangent(s + h) - v.tangent(s - h)) / (2.0 * h);
                assert!((dt - v.curvature_vector(s)).norm() < 1e-8, "{} t' at {s}", v.name());
                let dr = (v.radius(s + h) - v.radius(s - h)) / (2.0 * h);
                assert!((dr - v.radius_derivative(s)).abs() < 1e-7, "{} r' at {s}", v.name());
                // Rotation-minimising: u' has no component along v.
                let du = (v.frame_normal(s + h) - v.frame_normal(s - h)) / (2.0 * h);
                assert!(du.dot(&w).abs() < 1e-9, "{} twists at {s}", v.name());
            }
        }
    }

    #[test]
    fn helix_has_constant_curvature_and_torsion() {
        let hx = Helical::default();
        let h = 1e-4;
        for s in interior(&hx, 11) {
            assert!((hx.curvature_vector(s).norm() - hx.curvature()).abs() < 1e-14);
            // Torsion from the Frenet binormal: B' = -τ N.
            let binormal = |s: f64| hx.tangent(s).cross(&hx.curvature_vector(s).normalize());
            let db = (binormal(s + h) - binormal(s - h)) / (2.0 * h);
            let tau = -db.dot(&hx.curvature_vector(s).normalize());
            assert!((tau - hx.torsion()).abs() < 1e-8);
        }
        assert!((hx.length() - 1.25 * (TAU * 6.0).hypot(20.0)).abs() < 1e-12);
    }

    #[test]
    fn distance_is_exact_along_the_wall_normal() {
        for v in all_fixtures() {
            for (k, s) in interior(v.as_ref(), 17).into_iter().enumerate() {
                let theta = 0.7 + 1.3 * k as f64;
                let (q, r) = (v.wall_point(s, theta), v.radius(s));
                let e = (q - v.point(s)) / r;
                let normal =
                    (e * (1.0 - r * e.dot(&v.curvature_vector(s))) - v.tangent(s) * v.radius_derivative(s)).normalize();
                for frac in [-0.25, -0.01, -1e-7, 0.0, 1e-7, 0.01, 0.25] {
                    let delta = frac * r;
                    let p = q + normal * delta;
                    let wp = v.closest_wall_point(&p);
                    assert!(
                        (wp.signed_distance - delta).abs() < 1e-11,
                        "{} s={s} θ={theta} δ={delta}: {}",
                        v.name(),
                        wp.signed_distance
                    );
                    assert!((wp.point - q).norm() < 1e-9, "{}: {}", v.name(), (wp.point - q).norm());
                    assert!((wp.s - s).abs() < 1e-9);
                }
                assert!(v.distance_to_wall(&q).abs() < 1e-12, "{}", v.name());
            }
        }
    }

    /// Straight-axis cones have a closed form: distance to a segment in the meridian half-plane.
    #[test]
    fn distance_matches_closed_form_for_straight_and_tapered() {
        let cases: Vec<Box<dyn AnalyticVessel>> = vec![Box::new(Straight::default()), Box::new(Tapered::default())];
        for v in cases {
            let (r0, r1, len) = (v.radius(0.0), v.radius(v.length()), v.length());
            for i in 0..200 {
                let f = i as f64;
                let p = Point3::new(
                    3.0 * (0.37 * f).sin(),
                    3.0 * (0.91 * f).cos(),
                    -5.0 + (len + 10.0) * ((0.13 * f).sin() * 0.5 + 0.5),
                );
                let (z, rho) = (p.z, p.x.hypot(p.y));
                // Segment (0, r0) -> (len, r1) in the (z, ρ) plane.
                let d = Vector3::new(len, r1 - r0, 0.0);
                let w = Vector3::new(z, rho - r0, 0.0);
                let tt = (w.dot(&d) / d.norm_squared()).clamp(0.0, 1.0);
                let expected = (w - d * tt).norm();
                let got = v.distance_to_wall(&p);
                assert!((got.abs() - expected).abs() < 1e-11, "{} {p:?}: {got} vs {expected}", v.name());
            }
        }
    }

    #[test]
    fn surface_distance_sees_caps() {
        let aaa = Aaa::default();
        // Pole of the inlet dome and a point on it off axis.
        assert!(aaa.distance_to_surface(&Point3::new(0.0, 0.0, -10.0)) < 1e-12);
        let p = Point3::new(10.0 * 0.6, 0.0, -10.0 * 0.8);
        assert!(aaa.distance_to_surface(&p) < 1e-12);
        assert!((aaa.distance_to_surface(&Point3::new(0.0, 0.0, -12.0)) - 2.0).abs() < 1e-12);
        let tap = Tapered::default();
        assert!(tap.distance_to_surface(&Point3::new(1.0, 1.0, 40.0)) < 1e-15);
        assert!((tap.distance_to_surface(&Point3::new(0.5, 0.0, 40.25)) - 0.25).abs() < 1e-12);
        // On the axis of an open tube the wall is r away.
        let st = Straight::default();
        assert!((st.distance_to_surface(&Point3::new(0.0, 0.0, 15.0)) - 2.0).abs() < 1e-12);
        assert!((st.distance_to_wall(&Point3::new(0.0, 0.0, 15.0)) + 2.0).abs() < 1e-12);
    }

    #[test]
    fn triangulation_vertices_are_on_the_surface_and_sizes_fit() {
        for v in all_fixtures() {
            let res = v.resolution();
            let (vertices, triangles) = triangulate(v.as_ref(), res.circumferential, res.axial_step_mm);
            for p in &vertices {
                let scale = p.coords.norm().max(1.0);
                assert!(v.distance_to_surface(p) < 1e-12 * scale, "{} {p:?}", v.name());
            }
            assert!(84 + 50 * triangles.len() < 600_000, "{}: {}", v.name(), triangles.len());
        }
    }

    #[test]
    fn chordal_tolerance_bounds_sampled_triangles() {
        for v in all_fixtures() {
            let res = v.resolution();
            let (vertices, triangles) = triangulate(v.as_ref(), res.circumferential, res.axial_step_mm);
            let tol = chordal_tolerance(v.as_ref(), res.circumferential, res.axial_step_mm);
            let mut worst: f64 = 0.0;
            for t in triangles.iter().step_by(3) {
                let [a, b, c] = t.map(|i| vertices[i as usize].coords);
                for (wa, wb) in [(1.0 / 3.0, 1.0 / 3.0), (0.5, 0.5), (0.5, 0.0), (0.0, 0.5)] {
                    let p = Point3::from(a * wa + b * wb + c * (1.0 - wa - wb));
                    worst = worst.max(v.distance_to_surface(&p));
                }
            }
            assert!(worst <= tol, "{}: sampled {worst} > bound {tol}", v.name());
            // The bound is conservative (3-7x here) but not uselessly so.
            assert!(worst > tol / 20.0, "{}: bound {tol} is loose (sampled {worst})", v.name());
        }
    }

    #[test]
    fn csv_numbers_keep_enough_digits() {
        assert_eq!(fmt_coord(-1e-17), "0.000000000000000");
        assert_eq!(fmt_coord(2.0), "2.000000000000000");
        assert_eq!(fmt_coord(-12.5), "-12.500000000000000");
        let x = 1.234567890123456;
        assert!((fmt_coord(x).parse::<f64>().unwrap() - x).abs() < 1e-15);
    }
}
