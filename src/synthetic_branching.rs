//! Synthetic branching vessels with an analytic lumen: a Y-bifurcation and a T-junction (side
//! branch), used as test fixtures for junction meshing.
//!
//! A fixture is a set of straight tubes. Tube 0 is the parent; every other tube (a daughter or a
//! side branch) starts at its *anchor*, a point of the parent's axis. Each tube `i` contributes
//! the distance function of a capsule (the segment of its axis, extended a little beyond open
//! ends) minus its radius, `f_i(p) = |p - seg_i| - r_i`, and the lumen is
//!
//! ```text
//! F(p) = smin_k(... smin_k(smin_k(f_0, f_1), f_2) ...) < 0,
//! smin_k(a, b) = min(a, b) - k h³ / 6,   h = max(k - |a - b|, 0) / k,
//! ```
//!
//! the C² cubic smooth minimum of blend width `k`: where two tubes come within `k` of each other
//! (`|f_i - f_j| < k`) the union is filled by a fillet, so the crotch is rounded as in real vessels
//! (on the bisector of a crotch the surface stands `k / 6` off the sharp intersection, and the
//! fillet meets each tube where the other is `k` away); everywhere else `F` is exactly the
//! nearest tube's function, so far from the junction the lumen is an exact cylinder.
//!
//! The parent of a Y ends at the junction point with the capsule's hemispherical dome, which
//! fills the crotch between the daughters; where they part widely (half-angles past about 50° for
//! 0.8 R daughters) the top of the dome shows between them, blended into both.
//!
//! The surface `F = 0` is triangulated by naive surface nets on a uniform grid of cell
//! `cell_size` (f64 throughout; nodes half a cell off the coordinate planes through the junction),
//! every vertex is moved onto the exact zero level set by Newton steps on `F`, three passes of
//! tangential relaxation (each followed by the same projection) even out the vertex spacing, and
//! each open end is cut by the plane normal to its tube's axis: vertices within
//! a quarter cell of the plane are first slid along the axis onto it (which keeps them on the
//! cylinder), then the triangles crossing the plane are split, so every end is an open boundary
//! loop of vertices on the exact end circle, without slivers. [`BranchingFixture::generate_surface`]
//! checks the result (manifold, one boundary loop per open end, genus 0, outward normals, no
//! degenerate triangle) and refuses with the place and the fix when a check fails.
//!
//! Lengths are chosen from the geometry: each open end lies `free_length_radii` of its tube's
//! radii beyond the tube's *separation* distance from the anchor, the distance past which the
//! tube's cross-sections are clear of every other tube by twice the blend width (so the surface
//! there is exactly the tube, whatever the angle).
//!
//! Centerlines follow VMTK's convention: one polyline per outlet, from the inlet (the parent's
//! free upstream end) along the parent's axis to the branch's anchor, then along the branch's
//! axis to its outlet (paths overlap along the parent and have a corner at the anchor). The
//! point array `MaximumInscribedSphereRadius` is the true distance from the point to the analytic
//! surface `F = 0` (closest point found from the nearest mesh vertex and refined on the implicit
//! surface), which is the tube radius wherever the point is past its tube's separation distance,
//! and never less than the tube radius near the junction (larger where a branch's axis runs
//! through the parent; exactly R at the anchor of a right-angle T, whose far wall is straight).

use crate::data::error::{Error, Result};
use crate::geometry::mesh::closest_on_segment;
use crate::io::input::{CenterlinePolyline, Centerlines};
use crate::synthetic::write_binary_stl;
use crate::writers::centerlines::write_vtp;
use indexmap::IndexMap;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// How one end of a tube's axis is finished.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TubeEnd {
    /// An open end `length` from the anchor: the lumen is cut by the plane normal to the axis
    /// there, leaving a boundary loop.
    Open { length: f64 },
    /// The tube's capsule stops `length` from the anchor, inside the junction (0 for a tube that
    /// starts at the junction point; its rounded end is hidden in, or blended into, the union).
    Junction { length: f64 },
}

impl TubeEnd {
    pub fn length(&self) -> f64 {
        match *self {
            TubeEnd::Open { length } | TubeEnd::Junction { length } => length,
        }
    }
    pub fn is_open(&self) -> bool {
        matches!(self, TubeEnd::Open { .. })
    }
}

/// One straight tube of a branching fixture.
#[derive(Debug, Clone, PartialEq)]
pub struct Tube {
    /// "parent", "daughter 1", "branch", ... (used in messages).
    pub name: String,
    /// Point of the axis where the tube meets the junction (on the parent's axis).
    pub anchor: Point3<f64>,
    /// Unit axis direction, downstream (away from the inlet).
    pub direction: Vector3<f64>,
    pub radius: f64,
    /// Upstream end, `anchor - length * direction`.
    pub back: TubeEnd,
    /// Downstream end, `anchor + length * direction`.
    pub front: TubeEnd,
}

impl Tube {
    pub fn back_point(&self) -> Point3<f64> {
        self.anchor - self.direction * self.back.length()
    }
    pub fn front_point(&self) -> Point3<f64> {
        self.anchor + self.direction * self.front.length()
    }
}

/// An open end of the lumen: a circle in the plane normal to its tube's axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Opening {
    /// Index of the tube in [`BranchingFixture::tubes`].
    pub tube: usize,
    /// Centre of the end circle (the end of the centerline).
    pub centre: Point3<f64>,
    /// Unit normal of the end plane, pointing out of the vessel (along the axis).
    pub outward: Vector3<f64>,
    pub radius: f64,
    /// Distance from the tube's anchor along the axis past which the surface is exactly the
    /// tube's cylinder (its cross-sections clear every other tube by twice the blend width).
    pub separation: f64,
    /// Distance from the anchor to the end plane.
    pub length: f64,
}

/// A branching vessel of analytic tubes; build it with [`YBifurcation::fixture`] or
/// [`TJunction::fixture`].
#[derive(Debug, Clone, PartialEq)]
pub struct BranchingFixture {
    /// File stem: `<name>.stl`, `<name>_centerlines.vtp`.
    pub name: String,
    /// Tube 0 is the parent (its back end is the inlet); the others start at anchors on its axis.
    pub tubes: Vec<Tube>,
    /// Width `k` of the smooth-minimum band (fillet at the crotch), mm.
    pub blend_width: f64,
    /// Edge of the surface-nets grid cells (about the triangle size), mm.
    pub cell_size: f64,
    /// Largest spacing of the centerline points, mm.
    pub centerline_spacing: f64,
    /// Free length of each tube past its separation distance, in its radii.
    pub free_length_radii: f64,
    /// Separation distance of each open end, in the order of [`BranchingFixture::openings`].
    separations: Vec<f64>,
}

/// Parameters of a Y-bifurcation: the parent runs along +z from the inlet to the junction point
/// at the origin, the two daughters leave the origin in the x-z plane, daughter 1 towards +x and
/// daughter 2 towards -x, each at its half-angle from the +z axis. Lengths in mm.
#[derive(Debug, Clone, PartialEq)]
pub struct YBifurcation {
    pub parent_radius: f64,
    pub daughter_radii: [f64; 2],
    /// Angle of each daughter from the parent's axis, degrees, in [5, 90].
    pub half_angles_deg: [f64; 2],
    /// Free length of each tube past its separation distance, in its own radii (at least 2).
    pub free_length_radii: f64,
    /// Blend width `k` (default: half the smallest radius).
    pub blend_width: Option<f64>,
    /// Grid cell (default: the smaller of R/8 and a fifth of the smallest radius), rounded
    /// down to divide the parent radius.
    pub cell_size: Option<f64>,
}

impl Default for YBifurcation {
    /// The committed `y_bifurcation`: R = 2 mm, daughters 0.8 R = 1.6 mm at ±30°.
    fn default() -> Self {
        YBifurcation {
            parent_radius: 2.0,
            daughter_radii: [1.6, 1.6],
            half_angles_deg: [30.0, 30.0],
            free_length_radii: 6.0,
            blend_width: None,
            cell_size: None,
        }
    }
}

impl YBifurcation {
    /// A symmetric Y: parent radius 2 mm, both daughters `2 / ratio` at `half_angle_deg`.
    pub fn symmetric(half_angle_deg: f64, ratio: f64) -> Self {
        YBifurcation {
            daughter_radii: [2.0 / ratio, 2.0 / ratio],
            half_angles_deg: [half_angle_deg, half_angle_deg],
            ..YBifurcation::default()
        }
    }

    pub fn fixture(&self, name: &str) -> Result<BranchingFixture> {
        let what = format!("Y bifurcation '{name}'");
        check_range(&what, "parent radius (mm)", self.parent_radius, 1e-6, 1e6)?;
        for (i, (&r, &a)) in self.daughter_radii.iter().zip(&self.half_angles_deg).enumerate() {
            check_range(&what, &format!("radius of daughter {} (mm)", i + 1), r, 1e-6, 1e6)?;
            check_range(&what, &format!("half-angle of daughter {} (degrees)", i + 1), a, 5.0, 90.0)?;
        }
        let directions =
            [daughter_direction(self.half_angles_deg[0], 1.0), daughter_direction(self.half_angles_deg[1], -1.0)];
        let mut tubes = vec![parent_tube(self.parent_radius, TubeEnd::Junction { length: 0.0 })];
        for (i, (d, r)) in directions.iter().zip(self.daughter_radii).enumerate() {
            tubes.push(Tube {
                name: format!("daughter {}", i + 1),
                anchor: Point3::origin(),
                direction: *d,
                radius: r,
                back: TubeEnd::Junction { length: 0.0 },
                front: TubeEnd::Open { length: 0.0 },
            });
        }
        BranchingFixture::assemble(name, tubes, self.free_length_radii, self.blend_width, self.cell_size)
    }
}

/// Parameters of a T-junction (side branch): the parent runs straight along +z through the
/// junction point at the origin, the branch leaves the origin in the x-z plane towards +x at
/// `branch_angle_deg` from the parent's downstream axis (90° is a right angle). Lengths in mm.
#[derive(Debug, Clone, PartialEq)]
pub struct TJunction {
    pub parent_radius: f64,
    pub branch_radius: f64,
    /// Angle between the branch and the parent's downstream axis, degrees, in [10, 170].
    pub branch_angle_deg: f64,
    /// Free length of each tube end past its separation distance, in its own radii (at least 2).
    pub free_length_radii: f64,
    /// Blend width `k` (default: half the smallest radius).
    pub blend_width: Option<f64>,
    /// Grid cell (default: the smaller of R/8 and a fifth of the smallest radius), rounded
    /// down to divide the parent radius.
    pub cell_size: Option<f64>,
}

impl Default for TJunction {
    /// The committed `t_junction`: R = 2 mm, branch 1 mm (2:1) at 90°.
    fn default() -> Self {
        TJunction {
            parent_radius: 2.0,
            branch_radius: 1.0,
            branch_angle_deg: 90.0,
            free_length_radii: 6.0,
            blend_width: None,
            cell_size: None,
        }
    }
}

impl TJunction {
    /// Parent radius 2 mm, branch `2 / ratio` at `angle_deg`.
    pub fn with(angle_deg: f64, ratio: f64) -> Self {
        TJunction { branch_radius: 2.0 / ratio, branch_angle_deg: angle_deg, ..TJunction::default() }
    }

    pub fn fixture(&self, name: &str) -> Result<BranchingFixture> {
        let what = format!("T junction '{name}'");
        check_range(&what, "parent radius (mm)", self.parent_radius, 1e-6, 1e6)?;
        check_range(&what, "branch radius (mm)", self.branch_radius, 1e-6, self.parent_radius)?;
        check_range(&what, "branch angle (degrees)", self.branch_angle_deg, 10.0, 170.0)?;
        let tubes = vec![
            parent_tube(self.parent_radius, TubeEnd::Open { length: 0.0 }),
            Tube {
                name: "branch".into(),
                anchor: Point3::origin(),
                direction: daughter_direction(self.branch_angle_deg, 1.0),
                radius: self.branch_radius,
                back: TubeEnd::Junction { length: 0.0 },
                front: TubeEnd::Open { length: 0.0 },
            },
        ];
        BranchingFixture::assemble(name, tubes, self.free_length_radii, self.blend_width, self.cell_size)
    }
}

/// Parameters of a straight vessel with two side branches close together (as the arch's
/// branches leave the aorta): the parent runs along +z, branch `i` leaves its axis at
/// `z = (i - 1/2) spacing_radii R` (the first upstream of the origin, the second downstream), at
/// `angles_deg[i]` from the parent's downstream axis and `azimuths_deg[i]` about it from +x.
/// Lengths in mm.
#[derive(Debug, Clone, PartialEq)]
pub struct SideBranches {
    pub parent_radius: f64,
    pub branch_radii: [f64; 2],
    /// Angle between each branch and the parent's downstream axis, degrees, in [10, 170].
    pub angles_deg: [f64; 2],
    /// Azimuth of each branch about the parent's axis, degrees (0: towards +x).
    pub azimuths_deg: [f64; 2],
    /// Distance between the two branch anchors on the parent's axis, in parent radii.
    pub spacing_radii: f64,
    /// Free length of each tube end past its separation distance, in its own radii (at least 2).
    pub free_length_radii: f64,
}

impl SideBranches {
    /// Parent radius 2 mm, both branches `2 / ratio` at right angles, the second turned by
    /// `azimuth_deg` about the parent from the first, their anchors `spacing_radii` parent
    /// radii apart.
    pub fn with(spacing_radii: f64, ratio: f64, azimuth_deg: f64) -> Self {
        SideBranches {
            parent_radius: 2.0,
            branch_radii: [2.0 / ratio, 2.0 / ratio],
            angles_deg: [90.0, 90.0],
            azimuths_deg: [0.0, azimuth_deg],
            spacing_radii,
            free_length_radii: 6.0,
        }
    }

    pub fn fixture(&self, name: &str) -> Result<BranchingFixture> {
        let branches = (0..2)
            .map(|i| SideBranch {
                radius: self.branch_radii[i],
                angle_deg: self.angles_deg[i],
                azimuth_deg: self.azimuths_deg[i],
                anchor_radii: (i as f64 - 0.5) * self.spacing_radii,
            })
            .collect();
        let fan =
            SideBranchFan { parent_radius: self.parent_radius, branches, free_length_radii: self.free_length_radii };
        check_range(&format!("side branches '{name}'"), "anchor spacing (parent radii)", self.spacing_radii, 0.0, 1e3)?;
        fan.fixture(name)
    }
}

/// One side branch of a [`SideBranchFan`].
#[derive(Debug, Clone, PartialEq)]
pub struct SideBranch {
    pub radius: f64,
    /// Angle between the branch and the parent's downstream axis, degrees, in [10, 170].
    pub angle_deg: f64,
    /// Azimuth about the parent's axis, degrees (0: towards +x).
    pub azimuth_deg: f64,
    /// Where it leaves the parent's axis: z, in parent radii.
    pub anchor_radii: f64,
}

/// Side branches leaving one parent close together, as an abdominal aorta's coeliac trunk,
/// superior mesenteric and renal arteries do: the parent runs along +z (open at both ends),
/// each branch leaves its axis at its anchor, at its angle from the downstream axis and its
/// azimuth about it. Lengths in mm.
#[derive(Debug, Clone, PartialEq)]
pub struct SideBranchFan {
    pub parent_radius: f64,
    pub branches: Vec<SideBranch>,
    /// Free length of each tube end past its separation distance, in its own radii (at least 2).
    pub free_length_radii: f64,
}

impl SideBranchFan {
    pub fn fixture(&self, name: &str) -> Result<BranchingFixture> {
        let what = format!("side branches '{name}'");
        check_range(&what, "parent radius (mm)", self.parent_radius, 1e-6, 1e6)?;
        let mut tubes = vec![parent_tube(self.parent_radius, TubeEnd::Open { length: 0.0 })];
        for (i, b) in self.branches.iter().enumerate() {
            let branch = format!("branch {}", i + 1);
            check_range(&what, &format!("radius of {branch} (mm)"), b.radius, 1e-6, self.parent_radius)?;
            check_range(&what, &format!("angle of {branch} (degrees)"), b.angle_deg, 10.0, 170.0)?;
            check_range(&what, &format!("anchor of {branch} (parent radii)"), b.anchor_radii, -1e3, 1e3)?;
            let (a, phi) = (b.angle_deg.to_radians(), b.azimuth_deg.to_radians());
            // Exact zeros where the branch is grid-aligned (as `daughter_direction` does).
            let snap = |v: f64| if v.abs() < 1e-12 { 0.0 } else { v };
            tubes.push(Tube {
                name: branch,
                anchor: Point3::new(0.0, 0.0, b.anchor_radii * self.parent_radius),
                direction: Vector3::new(snap(a.sin() * phi.cos()), snap(a.sin() * phi.sin()), snap(a.cos())),
                radius: b.radius,
                back: TubeEnd::Junction { length: 0.0 },
                front: TubeEnd::Open { length: 0.0 },
            });
        }
        BranchingFixture::assemble(name, tubes, self.free_length_radii, None, None)
    }
}

/// The parent of a fixture: along +z from its inlet through the origin, finished at the front
/// as given (open for a vessel running on, at the junction for a Y's parent).
fn parent_tube(radius: f64, front: TubeEnd) -> Tube {
    Tube {
        name: "parent".into(),
        anchor: Point3::origin(),
        direction: Vector3::z(),
        radius,
        back: TubeEnd::Open { length: 0.0 },
        front,
    }
}

/// Unit vector in the x-z plane at `angle_deg` from +z, towards `side` × x.
fn daughter_direction(angle_deg: f64, side: f64) -> Vector3<f64> {
    let a = angle_deg.to_radians();
    if angle_deg == 90.0 {
        // Exactly along x, so the branch is grid-aligned (no 6e-17 z component).
        return Vector3::new(side, 0.0, 0.0);
    }
    Vector3::new(side * a.sin(), 0.0, a.cos())
}

fn check_range(what: &str, name: &str, value: f64, lo: f64, hi: f64) -> Result<()> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(Error::Config(format!("{what}: {name} is {value}, it must lie in [{lo}, {hi}]")))
    }
}

// ---------------------------------------------------------------------------------------------
// Geometry helpers
// ---------------------------------------------------------------------------------------------

/// Distance between segments [p0, p1] and [q0, q1]: the distance between the lines' closest
/// points when both fall inside, else the smallest endpoint-to-segment distance (exact for
/// segments, since the minimum is either interior to both or at an endpoint of one).
fn segment_distance(p0: &Point3<f64>, p1: &Point3<f64>, q0: &Point3<f64>, q1: &Point3<f64>) -> f64 {
    let mut best = [
        (closest_on_segment(p0, q0, q1) - p0).norm(),
        (closest_on_segment(p1, q0, q1) - p1).norm(),
        (closest_on_segment(q0, p0, p1) - q0).norm(),
        (closest_on_segment(q1, p0, p1) - q1).norm(),
    ]
    .into_iter()
    .fold(f64::INFINITY, f64::min);
    let (d1, d2, r) = (p1 - p0, q1 - q0, p0 - q0);
    let (a, e, b, c, f) = (d1.dot(&d1), d2.dot(&d2), d1.dot(&d2), d1.dot(&r), d2.dot(&r));
    let denom = a * e - b * b;
    if denom > 1e-14 * a * e {
        let s = (b * f - c * e) / denom;
        let t = (a * f - b * c) / denom;
        if (0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&t) {
            best = best.min(((p0 + d1 * s) - (q0 + d2 * t)).norm());
        }
    }
    best
}

/// Shape quality of a triangle, 4√3 area / Σ edge² (1 for equilateral, 0 for degenerate).
fn triangle_quality(a: &Point3<f64>, b: &Point3<f64>, c: &Point3<f64>) -> f64 {
    let twice_area = (b - a).cross(&(c - a)).norm();
    let sum = (b - a).norm_squared() + (c - b).norm_squared() + (a - c).norm_squared();
    if sum > 0.0 {
        2.0 * 3f64.sqrt() * twice_area / sum
    } else {
        0.0
    }
}

/// Smallest angle of a triangle, degrees.
pub fn min_angle_deg(a: &Point3<f64>, b: &Point3<f64>, c: &Point3<f64>) -> f64 {
    let angle = |p: &Point3<f64>, q: &Point3<f64>, r: &Point3<f64>| {
        let (u, v) = (q - p, r - p);
        u.cross(&v).norm().atan2(u.dot(&v)).to_degrees()
    };
    angle(a, b, c).min(angle(b, c, a)).min(angle(c, a, b))
}

/// The two triangles of quad `q` (in order) split along the diagonal that gives the better
/// worse triangle; ties keep the 0-2 diagonal.
fn split_quad(q: [u32; 4], vertices: &[Point3<f64>]) -> [[u32; 3]; 2] {
    let p = q.map(|i| vertices[i as usize]);
    let along_02 = triangle_quality(&p[0], &p[1], &p[2]).min(triangle_quality(&p[0], &p[2], &p[3]));
    let along_13 = triangle_quality(&p[0], &p[1], &p[3]).min(triangle_quality(&p[1], &p[2], &p[3]));
    if along_13 > along_02 {
        [[q[0], q[1], q[3]], [q[1], q[2], q[3]]]
    } else {
        [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    }
}

// ---------------------------------------------------------------------------------------------
// The implicit lumen
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Clone, Copy)]
struct Capsule {
    a: Point3<f64>,
    axis: Vector3<f64>,
    inv_len2: f64,
    radius: f64,
}

impl Capsule {
    fn new(a: Point3<f64>, b: Point3<f64>, radius: f64) -> Self {
        let axis = b - a;
        let len2 = axis.norm_squared();
        Capsule { a, axis, inv_len2: if len2 > 0.0 { 1.0 / len2 } else { 0.0 }, radius }
    }

    /// `|p - segment| - r` and its gradient (zero on the axis itself, never near the surface).
    fn value_gradient(&self, p: &Point3<f64>) -> (f64, Vector3<f64>) {
        let w = p - self.a;
        let t = (w.dot(&self.axis) * self.inv_len2).clamp(0.0, 1.0);
        let d = w - self.axis * t;
        let n = d.norm();
        (n - self.radius, if n > 0.0 { d / n } else { Vector3::zeros() })
    }
}

/// Cubic smooth minimum (C²) of two values with their gradients.
fn smooth_min(a: (f64, Vector3<f64>), b: (f64, Vector3<f64>), k: f64) -> (f64, Vector3<f64>) {
    let (lo, hi) = if a.0 <= b.0 { (a, b) } else { (b, a) };
    let h = (k - (hi.0 - lo.0)).max(0.0) / k;
    if h == 0.0 {
        return lo;
    }
    let w = 0.5 * h * h;
    (lo.0 - k * h * h * h / 6.0, lo.1 * (1.0 - w) + hi.1 * w)
}

/// The lumen's implicit function `F` (negative inside) with its gradient, and projections onto
/// its zero level set.
#[derive(Debug, Clone)]
pub struct LumenFunction {
    capsules: Vec<Capsule>,
    blend_width: f64,
    /// Length scale for the step cap of the Newton iterations (the grid cell).
    step_cap: f64,
}

/// Newton iterations allowed to land a point on `F = 0`.
const NEWTON_ITERATIONS: usize = 100;

impl LumenFunction {
    pub fn value_gradient(&self, p: &Point3<f64>) -> (f64, Vector3<f64>) {
        let mut acc = self.capsules[0].value_gradient(p);
        for c in &self.capsules[1..] {
            acc = smooth_min(acc, c.value_gradient(p), self.blend_width);
        }
        acc
    }

    pub fn value(&self, p: &Point3<f64>) -> f64 {
        self.value_gradient(p).0
    }

    /// First-order distance estimate `|F| / |∇F|` (exact on the surface to first order; used to
    /// measure how far a vertex is from `F = 0`).
    pub fn distance_estimate(&self, p: &Point3<f64>) -> f64 {
        let (f, g) = self.value_gradient(p);
        f.abs() / g.norm()
    }

    /// Moves `p` onto `F = 0` by Newton steps along the gradient (each capped at a grid cell),
    /// until a step is below 1e-15 of the coordinates; `None` if that does not happen.
    pub fn project(&self, p: &Point3<f64>) -> Option<Point3<f64>> {
        self.newton(p, None)
    }

    /// Like [`LumenFunction::project`] but moving only within the plane through `origin` normal
    /// to the unit vector `normal` (lands on the curve where the plane cuts the surface).
    pub fn project_in_plane(
        &self,
        p: &Point3<f64>,
        origin: &Point3<f64>,
        normal: &Vector3<f64>,
    ) -> Option<Point3<f64>> {
        let start = p - normal * (p - origin).dot(normal);
        let x = self.newton(&start, Some(normal))?;
        Some(x - normal * (x - origin).dot(normal))
    }

    fn newton(&self, p: &Point3<f64>, plane_normal: Option<&Vector3<f64>>) -> Option<Point3<f64>> {
        let mut x = *p;
        for _ in 0..NEWTON_ITERATIONS {
            let (f, mut g) = self.value_gradient(&x);
            if let Some(n) = plane_normal {
                g -= n * g.dot(n);
            }
            let g2 = g.norm_squared();
            if g2.is_nan() || g2 <= 1e-20 || !f.is_finite() {
                return None;
            }
            // Converged when F is at its rounding level; where the gradient is weak (several
            // tubes blending) the step itself never gets that small.
            if f.abs() <= 1e-15 * (1.0 + x.coords.norm()) {
                return Some(x);
            }
            let mut step = g * (f / g2);
            let len = step.norm();
            if len > self.step_cap {
                step *= self.step_cap / len;
            }
            x -= step;
            if len <= 1e-15 * (1.0 + x.coords.norm()) {
                return Some(x);
            }
        }
        None
    }

    /// The point of `F = 0` closest to `p`, found from `seed` (a surface point near it) by
    /// moving along the tangent plane towards the foot of `p` (at most a grid cell at a time)
    /// and projecting back onto the surface, accepting only moves that bring the point nearer
    /// to `p` (halving the move otherwise), until a move is below 1e-13 of the coordinates.
    pub fn closest_point(&self, p: &Point3<f64>, seed: &Point3<f64>) -> Option<Point3<f64>> {
        let mut x = self.project(seed)?;
        let mut scale: f64 = 1.0;
        for _ in 0..2000 {
            let n = self.value_gradient(&x).1.normalize();
            let d = p - x;
            let mut tangential = (d - n * d.dot(&n)) * scale;
            let len = tangential.norm();
            if len > self.step_cap {
                tangential *= self.step_cap / len;
            }
            let tolerance = 1e-13 * (1.0 + x.coords.norm());
            if tangential.norm() <= tolerance {
                break;
            }
            match self.project(&(x + tangential)) {
                Some(next) if (p - next).norm() <= (p - x).norm() + 1e-15 => {
                    let moved = (next - x).norm();
                    x = next;
                    scale = (2.0 * scale).min(1.0);
                    if moved <= tolerance {
                        break;
                    }
                }
                _ => {
                    scale *= 0.5;
                    if scale < 1e-12 {
                        break;
                    }
                }
            }
        }
        Some(x)
    }
}

// ---------------------------------------------------------------------------------------------
// The fixture
// ---------------------------------------------------------------------------------------------

/// Length used for "unbounded" tubes while the real lengths are being found.
const UNBOUNDED: f64 = 1e4;

impl BranchingFixture {
    /// Completes `tubes` (open lengths 0) with their lengths, and checks that each open end is
    /// clear of the other tubes.
    fn assemble(
        name: &str,
        mut tubes: Vec<Tube>,
        free_length_radii: f64,
        blend_width: Option<f64>,
        cell_size: Option<f64>,
    ) -> Result<Self> {
        let what = format!("branching fixture '{name}'");
        check_range(&what, "free length (tube radii)", free_length_radii, 2.0, 1e3)?;
        let parent_radius = tubes[0].radius;
        let smallest = tubes.iter().map(|t| t.radius).fold(f64::INFINITY, f64::min);
        let blend_width = blend_width.unwrap_or(0.5 * smallest);
        check_range(&what, "blend width (mm)", blend_width, 1e-3 * smallest, 2.0 * smallest)?;
        let requested = cell_size.unwrap_or((parent_radius / 8.0).min(smallest / 5.0));
        check_range(&what, "cell size (mm)", requested, smallest / 40.0, smallest / 2.0)?;
        // A whole number of cells per parent radius (see `sample_grid`).
        let cell_size = parent_radius / (parent_radius / requested).ceil();

        // Separation distance of every open end against the other tubes taken unbounded.
        let unbounded: Vec<(Point3<f64>, Point3<f64>)> = tubes
            .iter()
            .map(|t| {
                let reach = |e: &TubeEnd| if e.is_open() { UNBOUNDED } else { e.length() };
                (t.anchor - t.direction * reach(&t.back), t.anchor + t.direction * reach(&t.front))
            })
            .collect();
        let mut separations = Vec::new();
        for i in 0..tubes.len() {
            for forward in [false, true] {
                let end = if forward { tubes[i].front } else { tubes[i].back };
                if !end.is_open() {
                    continue;
                }
                let dir = if forward { tubes[i].direction } else { -tubes[i].direction };
                let mut separation: f64 = 0.0;
                for (j, (a, b)) in unbounded.iter().enumerate() {
                    if j != i {
                        let clearance = tubes[i].radius + tubes[j].radius + 2.0 * blend_width;
                        let g = |s: f64| {
                            (closest_on_segment(&(tubes[i].anchor + dir * s), a, b) - (tubes[i].anchor + dir * s))
                                .norm()
                                - clearance
                        };
                        separation = separation.max(last_root_of_convex(g, UNBOUNDED));
                    }
                }
                let length = separation + free_length_radii * tubes[i].radius;
                if forward {
                    tubes[i].front = TubeEnd::Open { length };
                } else {
                    tubes[i].back = TubeEnd::Open { length };
                }
                separations.push(separation);
            }
        }
        let spacing = smallest / 4.0;
        let fixture = BranchingFixture {
            name: name.to_string(),
            tubes,
            blend_width,
            cell_size,
            centerline_spacing: spacing,
            free_length_radii,
            separations,
        };
        fixture.check_structure()?;
        Ok(fixture)
    }

    /// Every branch anchored on the parent's axis, and each open end's neighbourhood (where the
    /// cut happens) clear of all other tubes.
    fn check_structure(&self) -> Result<()> {
        let parent = &self.tubes[0];
        if !parent.back.is_open() {
            return Err(Error::Config(format!("{}: the parent's upstream end must be open (the inlet)", self.name)));
        }
        for t in &self.tubes[1..] {
            let on_axis = closest_on_segment(&t.anchor, &parent.back_point(), &parent.front_point());
            if (on_axis - t.anchor).norm() > 1e-9 * parent.radius || !t.front.is_open() {
                return Err(Error::Config(format!(
                    "{}: {} must start on the parent's axis and end open",
                    self.name, t.name
                )));
            }
        }
        let h = self.cell_size;
        for o in self.openings() {
            // The clip zone: around the axis, from 3 cells before the end plane to the capsule end.
            let zone_start = o.centre - o.outward * (3.0 * h);
            let zone_end = o.centre + o.outward * (self.extension() + o.radius);
            for (j, (a, b)) in self.capsule_segments().iter().enumerate() {
                if j == o.tube {
                    continue;
                }
                let gap = segment_distance(&zone_start, &zone_end, a, b);
                let needed = o.radius + 3.0 * h + self.tubes[j].radius + 2.0 * self.blend_width;
                if gap < needed {
                    return Err(Error::Config(format!(
                        "{}: {} comes within {gap:.3} mm of the open end of {} at ({:.3}, {:.3}, {:.3}), which needs \
                         {needed:.3} mm to be cut cleanly; lengthen the tubes (free_length_radii) or widen the angle",
                        self.name, self.tubes[j].name, self.tubes[o.tube].name, o.centre.x, o.centre.y, o.centre.z
                    )));
                }
            }
        }
        Ok(())
    }

    /// How far each capsule continues past an open end plane (so the surface is an exact
    /// cylinder where it is cut).
    fn extension(&self) -> f64 {
        4.0 * self.cell_size
    }

    /// Axis segment of each tube's capsule (open ends extended by [`Self::extension`]).
    fn capsule_segments(&self) -> Vec<(Point3<f64>, Point3<f64>)> {
        let ext = self.extension();
        self.tubes
            .iter()
            .map(|t| {
                let back = t.back.length() + if t.back.is_open() { ext } else { 0.0 };
                let front = t.front.length() + if t.front.is_open() { ext } else { 0.0 };
                (t.anchor - t.direction * back, t.anchor + t.direction * front)
            })
            .collect()
    }

    /// The analytic lumen.
    pub fn lumen_function(&self) -> LumenFunction {
        LumenFunction {
            capsules: self
                .capsule_segments()
                .iter()
                .zip(&self.tubes)
                .map(|((a, b), t)| Capsule::new(*a, *b, t.radius))
                .collect(),
            blend_width: self.blend_width,
            step_cap: self.cell_size,
        }
    }

    /// The open ends: first the inlet (the parent's back end), then the outlets (the parent's
    /// front end if open, then each branch's front end, in tube order).
    pub fn openings(&self) -> Vec<Opening> {
        let mut out = Vec::new();
        for (i, t) in self.tubes.iter().enumerate() {
            for (end, sign) in [(t.back, -1.0), (t.front, 1.0)] {
                if let TubeEnd::Open { length } = end {
                    out.push(Opening {
                        tube: i,
                        centre: t.anchor + t.direction * (sign * length),
                        outward: t.direction * sign,
                        radius: t.radius,
                        separation: self.separations.get(out.len()).copied().unwrap_or(0.0),
                        length,
                    });
                }
            }
        }
        out
    }

    /// The centerline polylines (points only), one per outlet in [`Self::openings`] order after
    /// the inlet: inlet → (along the parent) → anchor → (along the branch) → outlet. Straight
    /// pieces are sampled uniformly at most [`Self::centerline_spacing`] apart; the shared
    /// pieces are sampled identically, and the anchor is a point of every branch path.
    pub fn centerline_paths(&self) -> Vec<Vec<Point3<f64>>> {
        let inlet = self.tubes[0].back_point();
        let piece = |from: Point3<f64>, to: Point3<f64>, out: &mut Vec<Point3<f64>>| {
            let len = (to - from).norm();
            let n = ((len / self.centerline_spacing).ceil() as usize).max(1);
            for i in 1..=n {
                out.push(if i == n { to } else { from + (to - from) * (i as f64 / n as f64) });
            }
        };
        self.openings()
            .iter()
            .skip(1)
            .map(|o| {
                let mut path = vec![inlet];
                if o.tube == 0 {
                    piece(inlet, o.centre, &mut path);
                } else {
                    let anchor = self.tubes[o.tube].anchor;
                    piece(inlet, anchor, &mut path);
                    piece(anchor, o.centre, &mut path);
                }
                path
            })
            .collect()
    }
}

/// Largest root of a convex function `g` on [0, reach] with `g(reach) > 0` (0 if `g` is never
/// negative): golden-section search of the minimum, then bisection between it and `reach`.
fn last_root_of_convex(g: impl Fn(f64) -> f64, reach: f64) -> f64 {
    let inv_phi = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (0.0, reach);
    for _ in 0..200 {
        let x1 = b - inv_phi * (b - a);
        let x2 = a + inv_phi * (b - a);
        if g(x1) <= g(x2) {
            b = x2;
        } else {
            a = x1;
        }
    }
    let mut lo = 0.5 * (a + b);
    if g(lo) >= 0.0 {
        return 0.0;
    }
    let mut hi = reach;
    for _ in 0..200 {
        let m = 0.5 * (lo + hi);
        if m <= lo || m >= hi {
            break;
        }
        if g(m) < 0.0 {
            lo = m;
        } else {
            hi = m;
        }
    }
    hi
}

// ---------------------------------------------------------------------------------------------
// Triangulation
// ---------------------------------------------------------------------------------------------

/// Figures of a generated surface.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SurfaceStats {
    /// Grid cells per axis of the surface-nets grid.
    pub grid: [usize; 3],
    /// Smallest angle of any triangle, degrees.
    pub min_angle_deg: f64,
    /// Shortest and longest edge, mm.
    pub min_edge: f64,
    pub max_edge: f64,
    /// Largest `|F| / |∇F|` over the vertices, mm.
    pub max_vertex_offset: f64,
    /// Vertices slid onto an end plane, and vertices within a quarter cell of a plane that could
    /// neither be slid onto it nor pushed away from it (their triangles are then cut close to
    /// them; none in any fixture so far).
    pub snapped: usize,
    pub unsnapped: usize,
}

/// The triangulated lumen of a fixture: f64 vertices on `F = 0`, triangles wound outward (right-
/// hand rule normals point out of the lumen), one open boundary loop per end.
#[derive(Debug, Clone, PartialEq)]
pub struct BranchingSurface {
    pub vertices: Vec<Point3<f64>>,
    pub triangles: Vec<[u32; 3]>,
    pub stats: SurfaceStats,
}

/// Surface nets on the fixture's grid: one vertex per cell that the surface crosses (the mean of
/// the crossings of its edges, linearly interpolated), one outward quad per grid edge with a
/// sign change (around the edge, counter-clockwise seen from the outside end of the edge).
struct Grid {
    origin: Point3<f64>,
    h: f64,
    cells: [usize; 3],
    values: Vec<f64>,
}

impl Grid {
    fn node_count(&self) -> [usize; 3] {
        self.cells.map(|c| c + 1)
    }
    fn node_index(&self, i: usize, j: usize, k: usize) -> usize {
        let n = self.node_count();
        i + n[0] * (j + n[1] * k)
    }
    fn node_point(&self, i: usize, j: usize, k: usize) -> Point3<f64> {
        self.origin + Vector3::new(i as f64, j as f64, k as f64) * self.h
    }
    fn cell_index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.cells[0] * (j + self.cells[1] * k)
    }
}

fn sample_grid(fixture: &BranchingFixture, f: &LumenFunction) -> Grid {
    let h = fixture.cell_size;
    let mut lo = Point3::from([f64::INFINITY; 3]);
    let mut hi = Point3::from([f64::NEG_INFINITY; 3]);
    for ((a, b), t) in fixture.capsule_segments().iter().zip(&fixture.tubes) {
        let pad = t.radius + 2.0 * h;
        for p in [a, b] {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k] - pad);
                hi[k] = hi[k].max(p[k] + pad);
            }
        }
    }
    // Nodes at (m + 1/2) h: the grid does not depend on the bounding box's last bits, it is
    // symmetric like the fixture about the coordinate planes through the junction, and planes
    // tangent to the tubes at multiples of h (the flanks at ±R, where two equal tubes touch
    // tangentially and the blend leaves a lens thinner than a cell) fall half-way between nodes.
    let origin = lo.map(|x| ((x / h).floor() - 0.5) * h);
    let cells = [0, 1, 2].map(|k| ((hi[k] - origin[k]) / h).ceil() as usize);
    let mut grid = Grid { origin, h, cells, values: Vec::new() };
    let n = grid.node_count();
    let total = n[0] * n[1] * n[2];
    grid.values = (0..total)
        .into_par_iter()
        .map(|idx| {
            let (i, j, k) = (idx % n[0], (idx / n[0]) % n[1], idx / (n[0] * n[1]));
            f.value(&grid.node_point(i, j, k))
        })
        .collect();
    grid
}

/// Cube corner `c` (bits x, y, z) as offsets.
fn corner_offset(c: usize) -> (usize, usize, usize) {
    (c & 1, (c >> 1) & 1, (c >> 2) & 1)
}

fn surface_nets(grid: &Grid) -> (Vec<Point3<f64>>, Vec<[u32; 4]>) {
    let h = grid.h;
    // Values at least a tenth of a cell away from zero, sign kept, so crossings stay a tenth of
    // an edge away from the nodes (surface nets' short edges come from crossings at the nodes).
    let floor = 0.1 * h;
    let clamp = |v: f64| if v < 0.0 { v.min(-floor) } else { v.max(floor) };
    let inside = |v: f64| v < 0.0;
    let [cx, cy, cz] = grid.cells;
    let mut cell_vertex = vec![u32::MAX; cx * cy * cz];
    let mut positions = Vec::new();
    for k in 0..cz {
        for j in 0..cy {
            for i in 0..cx {
                let mut v = [0.0; 8];
                let mut mask = 0u8;
                for (c, value) in v.iter_mut().enumerate() {
                    let (dx, dy, dz) = corner_offset(c);
                    *value = grid.values[grid.node_index(i + dx, j + dy, k + dz)];
                    if inside(*value) {
                        mask |= 1 << c;
                    }
                }
                if mask == 0 || mask == 255 {
                    continue;
                }
                let mut sum = Vector3::zeros();
                let mut count = 0.0;
                for c in 0..8 {
                    for bit in [1, 2, 4] {
                        let d = c | bit;
                        if c & bit != 0 || inside(v[c]) == inside(v[d]) {
                            continue;
                        }
                        let (a, b) = (clamp(v[c]), clamp(v[d]));
                        let t = a / (a - b);
                        let (p, q) = (corner_offset(c), corner_offset(d));
                        let pa = Vector3::new(p.0 as f64, p.1 as f64, p.2 as f64);
                        let pb = Vector3::new(q.0 as f64, q.1 as f64, q.2 as f64);
                        sum += pa + (pb - pa) * t;
                        count += 1.0;
                    }
                }
                cell_vertex[grid.cell_index(i, j, k)] = positions.len() as u32;
                positions.push(grid.node_point(i, j, k) + sum * (h / count));
            }
        }
    }
    let n = grid.node_count();
    let mut quads = Vec::new();
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                let node = [i, j, k];
                let here = inside(grid.values[grid.node_index(i, j, k)]);
                for d in 0..3 {
                    let (u, w) = ((d + 1) % 3, (d + 2) % 3);
                    if node[d] + 1 >= n[d]
                        || node[u] == 0
                        || node[w] == 0
                        || node[u] >= grid.cells[u]
                        || node[w] >= grid.cells[w]
                    {
                        continue;
                    }
                    let mut next = node;
                    next[d] += 1;
                    if inside(grid.values[grid.node_index(next[0], next[1], next[2])]) == here {
                        continue;
                    }
                    let cell = |du: usize, dw: usize| {
                        let mut c = node;
                        c[u] -= du;
                        c[w] -= dw;
                        cell_vertex[grid.cell_index(c[0], c[1], c[2])]
                    };
                    // Counter-clockwise about +d: (-,-), (+,-), (+,+), (-,+) in (u, w).
                    let quad = [cell(1, 1), cell(0, 1), cell(0, 0), cell(1, 0)];
                    quads.push(if here { quad } else { [quad[3], quad[2], quad[1], quad[0]] });
                }
            }
        }
    }
    (positions, quads)
}

/// Passes of [`relax_on_surface`] applied to the surface-nets vertices.
const SMOOTHING_PASSES: usize = 3;

/// One pass of tangential Laplacian relaxation over the quad mesh: each vertex moves half-way
/// towards the mean of its quad-edge neighbours, within its tangent plane, then back onto
/// `F = 0` (surface nets places vertices unevenly where the surface is oblique to the grid). A
/// vertex whose projection fails keeps its place.
fn relax_on_surface(f: &LumenFunction, vertices: &[Point3<f64>], quads: &[[u32; 4]]) -> Vec<Point3<f64>> {
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); vertices.len()];
    for q in quads {
        for e in 0..4 {
            let (a, b) = (q[e], q[(e + 1) % 4]);
            neighbours[a as usize].push(b);
            neighbours[b as usize].push(a);
        }
    }
    neighbours
        .into_par_iter()
        .enumerate()
        .map(|(v, mut around)| {
            let p = vertices[v];
            around.sort_unstable();
            around.dedup();
            if around.is_empty() {
                return p;
            }
            let mean = around.iter().map(|&u| vertices[u as usize].coords).sum::<Vector3<f64>>() / around.len() as f64;
            let normal = f.value_gradient(&p).1.normalize();
            let d = mean - p.coords;
            f.project(&(p + (d - normal * d.dot(&normal)) * 0.5)).unwrap_or(p)
        })
        .collect()
}

/// Directed-edge map of a triangle list; `Err` with the first repeated directed edge (two
/// triangles wound the same way along it, or a non-manifold edge).
fn directed_edges(triangles: &[[u32; 3]]) -> std::result::Result<HashMap<(u32, u32), u32>, (u32, u32)> {
    let mut map = HashMap::with_capacity(3 * triangles.len());
    for (t, tri) in triangles.iter().enumerate() {
        for e in 0..3 {
            if map.insert((tri[e], tri[(e + 1) % 3]), t as u32).is_some() {
                return Err((tri[e], tri[(e + 1) % 3]));
            }
        }
    }
    Ok(map)
}

/// For each vertex, the triangles that use it.
fn incident_triangles(triangles: &[[u32; 3]], vertex_count: usize) -> Vec<Vec<u32>> {
    let mut out = vec![Vec::new(); vertex_count];
    for (t, tri) in triangles.iter().enumerate() {
        for &v in tri {
            out[v as usize].push(t as u32);
        }
    }
    out
}

impl BranchingFixture {
    /// Triangulates the lumen (see the module documentation) and checks it.
    pub fn generate_surface(&self) -> Result<BranchingSurface> {
        let f = self.lumen_function();
        let h = self.cell_size;
        let grid = sample_grid(self, &f);
        let (raw, quads) = surface_nets(&grid);
        let projected: Vec<Option<Point3<f64>>> = raw.par_iter().map(|p| f.project(p)).collect();
        let mut vertices = Vec::with_capacity(raw.len());
        for (p, q) in raw.iter().zip(projected) {
            vertices.push(q.ok_or_else(|| {
                self.geometry_error(
                    p,
                    "a surface-nets vertex could not be moved onto the surface",
                    "a smaller cell size",
                )
            })?);
        }
        for _ in 0..SMOOTHING_PASSES {
            vertices = relax_on_surface(&f, &vertices, &quads);
        }
        let mut triangles: Vec<[u32; 3]> = quads.iter().flat_map(|q| split_quad(*q, &vertices)).collect();
        // Before the cut the surface must be closed and manifold: surface nets joins two sheets
        // that pass through one cell, which happens only where the grid is too coarse.
        if let Err((a, _)) = directed_edges(&triangles) {
            return Err(self.geometry_error(
                &vertices[a as usize],
                "two sheets of the surface pass through one grid cell (non-manifold edge)",
                "a smaller cell size or a wider blend",
            ));
        }
        let mut stats = SurfaceStats { grid: grid.cells, ..SurfaceStats::default() };
        for o in self.openings() {
            triangles = clip_open_end(&f, &o, h, &mut vertices, triangles, &mut stats)
                .map_err(|(p, what)| self.geometry_error(&p, &what, "a smaller cell size"))?;
        }
        let (vertices, triangles) = compact(vertices, triangles);
        let mut surface = BranchingSurface { vertices, triangles, stats };
        self.check_surface(&f, &mut surface)?;
        Ok(surface)
    }

    fn geometry_error(&self, at: &Point3<f64>, what: &str, fix: &str) -> Error {
        Error::Geometry(format!(
            "synthetic fixture '{}': {what} near ({:.4}, {:.4}, {:.4}) mm with cell size {} mm; try {fix}",
            self.name, at.x, at.y, at.z, self.cell_size
        ))
    }

    /// Manifold, one boundary loop per opening lying on its end circle, genus 0, outward and
    /// non-degenerate triangles; fills the stats.
    fn check_surface(&self, f: &LumenFunction, s: &mut BranchingSurface) -> Result<()> {
        let openings = self.openings();
        let edges = directed_edges(&s.triangles).map_err(|(a, _)| {
            self.geometry_error(
                &s.vertices[a as usize],
                "an edge is shared by more than two triangles or mis-wound",
                "a smaller cell size",
            )
        })?;
        // Boundary edges: directed edges without their twin.
        let mut next_on_boundary: HashMap<u32, u32> = HashMap::new();
        let mut boundary_starts = Vec::new();
        for &(a, b) in edges.keys() {
            if !edges.contains_key(&(b, a)) {
                if next_on_boundary.insert(a, b).is_some() {
                    return Err(self.geometry_error(
                        &s.vertices[a as usize],
                        "a vertex is on two boundary loops",
                        "a smaller cell size",
                    ));
                }
                boundary_starts.push(a);
            }
        }
        boundary_starts.sort_unstable();
        let mut seen = std::collections::HashSet::new();
        let mut loops_per_opening = vec![0usize; openings.len()];
        for &start in &boundary_starts {
            if !seen.insert(start) {
                continue;
            }
            let mut v = start;
            let mut members = vec![start];
            loop {
                v = next_on_boundary[&v];
                if v == start {
                    break;
                }
                seen.insert(v);
                members.push(v);
            }
            let p = s.vertices[start as usize];
            let which = openings.iter().position(|o| {
                members.iter().all(|&m| {
                    let q = s.vertices[m as usize];
                    let scale = 1.0 + q.coords.norm();
                    (q - o.centre).dot(&o.outward).abs() <= 1e-12 * scale
                        && ((q - o.centre).norm() - o.radius).abs() <= 1e-12 * scale
                })
            });
            match which {
                Some(i) => loops_per_opening[i] += 1,
                None => {
                    return Err(self.geometry_error(
                        &p,
                        "a boundary loop is not an end circle (a hole in the surface)",
                        "a smaller cell size",
                    ))
                }
            }
        }
        if let Some(i) = loops_per_opening.iter().position(|&n| n != 1) {
            let o = &openings[i];
            return Err(self.geometry_error(
                &o.centre,
                &format!("the open end has {} boundary loops, not 1", loops_per_opening[i]),
                "a smaller cell size",
            ));
        }
        // Each vertex's triangles form one fan (no two surface sheets touching at a vertex).
        let incident = incident_triangles(&s.triangles, s.vertices.len());
        for (v, tris) in incident.iter().enumerate() {
            let v = v as u32;
            let mut link: HashMap<u32, u32> = HashMap::new();
            for &t in tris {
                let tri = s.triangles[t as usize];
                let k = tri.iter().position(|&x| x == v).unwrap_or(0);
                link.insert(tri[(k + 1) % 3], tri[(k + 2) % 3]);
            }
            let targets: std::collections::HashSet<u32> = link.values().copied().collect();
            let mut start = *link.keys().min().unwrap_or(&0);
            if let Some(&open) = link.keys().filter(|k| !targets.contains(k)).min() {
                start = open;
            }
            let mut walked = 0;
            let mut x = start;
            while let Some(&y) = link.get(&x) {
                walked += 1;
                x = y;
                if x == start || walked > link.len() {
                    break;
                }
            }
            if walked != link.len() {
                return Err(self.geometry_error(
                    &s.vertices[v as usize],
                    "surface sheets touch at a vertex",
                    "a smaller cell size",
                ));
            }
        }
        let euler = s.vertices.len() as i64 - (edges.len() as i64 + boundary_starts.len() as i64) / 2
            + s.triangles.len() as i64;
        if euler != 2 - openings.len() as i64 {
            return Err(Error::Geometry(format!(
                "synthetic fixture '{}': the surface has Euler characteristic {euler}, not {} (a handle or a separate \
                 piece); try a smaller cell size",
                self.name,
                2 - openings.len() as i64
            )));
        }
        let mut min_angle = f64::INFINITY;
        let (mut min_edge, mut max_edge) = (f64::INFINITY, 0.0f64);
        for tri in &s.triangles {
            let [a, b, c] = tri.map(|i| s.vertices[i as usize]);
            let normal = (b - a).cross(&(c - a));
            let centroid = Point3::from((a.coords + b.coords + c.coords) / 3.0);
            let outward = f.value_gradient(&centroid).1;
            if normal.dot(&outward).is_nan() || normal.dot(&outward) <= 0.0 {
                return Err(self.geometry_error(&centroid, "a triangle faces into the lumen", "a smaller cell size"));
            }
            min_angle = min_angle.min(min_angle_deg(&a, &b, &c));
            for (p, q) in [(a, b), (b, c), (c, a)] {
                let e = (q - p).norm();
                min_edge = min_edge.min(e);
                max_edge = max_edge.max(e);
            }
        }
        if min_angle.is_nan() || min_angle < MIN_ANGLE_DEG {
            return Err(Error::Geometry(format!(
                "synthetic fixture '{}': a triangle has an angle of {min_angle:.2}° (below {MIN_ANGLE_DEG}°); try a \
                 smaller cell size",
                self.name
            )));
        }
        s.stats.min_angle_deg = min_angle;
        s.stats.min_edge = min_edge;
        s.stats.max_edge = max_edge;
        s.stats.max_vertex_offset = s.vertices.iter().map(|p| f.distance_estimate(p)).fold(0.0, f64::max);
        Ok(())
    }
}

/// Smallest triangle angle a generated surface may have.
pub const MIN_ANGLE_DEG: f64 = 5.0;

/// Cuts the surface at the end plane of `o`, keeping the lumen side. Only vertices in the clip
/// zone (near the tube's axis line, from 3 cells before the plane on) are considered, so the
/// (infinite) plane never touches another tube. Vertices within a quarter cell of the plane are
/// slid along the axis onto it when that keeps their triangles well oriented and creates no
/// triangle lying in the plane (else pushed a quarter cell away from it); the triangles crossing
/// the plane are then split, new vertices landing on the end circle.
fn clip_open_end(
    f: &LumenFunction,
    o: &Opening,
    h: f64,
    vertices: &mut Vec<Point3<f64>>,
    triangles: Vec<[u32; 3]>,
    stats: &mut SurfaceStats,
) -> std::result::Result<Vec<[u32; 3]>, (Point3<f64>, String)> {
    let n = o.outward;
    let zone_radius = o.radius + 3.0 * h;
    let offset = |p: &Point3<f64>| {
        let w = p - o.centre;
        let a = w.dot(&n);
        if a > -3.0 * h && (w - n * a).norm() < zone_radius {
            a
        } else {
            f64::NEG_INFINITY
        }
    };
    let mut s: Vec<f64> = vertices.iter().map(offset).collect();
    let mut on_plane = vec![false; vertices.len()];
    let incident = incident_triangles(&triangles, vertices.len());
    let delta = 0.25 * h;
    // Whether moving vertex v to q keeps its triangles facing out (not folded over) and, if
    // `onto_plane`, leaves none with all three corners on the plane.
    let acceptable = |v: usize, q: &Point3<f64>, onto_plane: bool, vertices: &[Point3<f64>], on_plane: &[bool]| {
        incident[v].iter().all(|&t| {
            let tri = triangles[t as usize];
            if onto_plane && tri.iter().all(|&x| x as usize == v || on_plane[x as usize]) {
                return false;
            }
            let p = tri.map(|x| if x as usize == v { *q } else { vertices[x as usize] });
            let normal = (p[1] - p[0]).cross(&(p[2] - p[0]));
            let centroid = Point3::from((p[0].coords + p[1].coords + p[2].coords) / 3.0);
            let outward = f.value_gradient(&centroid).1;
            let len = normal.norm() * outward.norm();
            len > 0.0 && normal.dot(&outward) > 0.2 * len && triangle_quality(&p[0], &p[1], &p[2]) > 0.05
        })
    };
    for v in 0..vertices.len() {
        if s[v].abs() >= delta {
            continue;
        }
        let onto = f.project_in_plane(&(vertices[v] - n * s[v]), &o.centre, &n);
        if let Some(q) = onto.filter(|q| acceptable(v, q, true, vertices, &on_plane)) {
            vertices[v] = q;
            s[v] = 0.0;
            on_plane[v] = true;
            stats.snapped += 1;
            continue;
        }
        let away = f.project(&(vertices[v] + n * (delta.copysign(s[v]) - s[v])));
        if let Some(q) = away.filter(|q| acceptable(v, q, false, vertices, &on_plane)) {
            vertices[v] = q;
            s[v] = offset(&q);
        } else {
            stats.unsnapped += 1;
        }
    }
    // -1 lumen side, 0 on the plane, +1 beyond.
    let side = |v: u32| {
        if on_plane[v as usize] || s[v as usize] == 0.0 {
            0
        } else if s[v as usize] < 0.0 {
            -1
        } else {
            1
        }
    };
    let mut cut_points: HashMap<(u32, u32), u32> = HashMap::new();
    let mut out = Vec::with_capacity(triangles.len());
    for tri in &triangles {
        let sides = tri.map(side);
        if !sides.contains(&-1) {
            continue;
        }
        if !sides.contains(&1) {
            out.push(*tri);
            continue;
        }
        // Sutherland-Hodgman against the plane, keeping the winding.
        let mut polygon = Vec::with_capacity(4);
        for e in 0..3 {
            let (a, b) = (tri[e], tri[(e + 1) % 3]);
            if sides[e] != 1 {
                polygon.push(a);
            }
            if sides[e] * sides[(e + 1) % 3] == -1 {
                let key = (a.min(b), a.max(b));
                let id = match cut_points.get(&key) {
                    Some(&id) => id,
                    None => {
                        let (pa, pb) = (vertices[key.0 as usize], vertices[key.1 as usize]);
                        let (sa, sb) = (s[key.0 as usize], s[key.1 as usize]);
                        let crossing = pa + (pb - pa) * (sa / (sa - sb));
                        let q = f
                            .project_in_plane(&crossing, &o.centre, &n)
                            .ok_or((crossing, "a cut point could not be moved onto the end circle".to_string()))?;
                        vertices.push(q);
                        let id = (vertices.len() - 1) as u32;
                        cut_points.insert(key, id);
                        id
                    }
                };
                polygon.push(id);
            }
        }
        match polygon.len() {
            3 => out.push([polygon[0], polygon[1], polygon[2]]),
            4 => out.extend(split_quad([polygon[0], polygon[1], polygon[2], polygon[3]], vertices)),
            _ => return Err((vertices[tri[0] as usize], "a triangle was cut into an odd shape".into())),
        }
    }
    Ok(out)
}

/// Drops unused vertices, keeping the order of the others.
fn compact(vertices: Vec<Point3<f64>>, triangles: Vec<[u32; 3]>) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
    let mut new_index = vec![u32::MAX; vertices.len()];
    for tri in &triangles {
        for &v in tri {
            new_index[v as usize] = 0;
        }
    }
    let mut kept = Vec::new();
    for (i, p) in vertices.into_iter().enumerate() {
        if new_index[i] == 0 {
            new_index[i] = kept.len() as u32;
            kept.push(p);
        }
    }
    let triangles = triangles.into_iter().map(|t| t.map(|v| new_index[v as usize])).collect();
    (kept, triangles)
}

// ---------------------------------------------------------------------------------------------
// Centerlines and files
// ---------------------------------------------------------------------------------------------

impl BranchingFixture {
    /// VMTK-style centerlines (mm): one polyline per outlet ([`Self::centerline_paths`]), point
    /// radius `MaximumInscribedSphereRadius` = distance to the analytic surface, cell tag
    /// `CenterlineIds` = 0, 1, ... `surface` supplies the starting points of the closest-point
    /// searches (its nearest vertex).
    pub fn centerlines(&self, surface: &BranchingSurface) -> Result<Centerlines> {
        let f = self.lumen_function();
        let mut polylines = Vec::new();
        for (id, points) in self.centerline_paths().into_iter().enumerate() {
            let radii: Vec<Option<f64>> = points
                .par_iter()
                .map(|p| {
                    let seed = surface
                        .vertices
                        .iter()
                        .min_by(|a, b| (*a - p).norm_squared().total_cmp(&(*b - p).norm_squared()))?;
                    f.closest_point(p, seed).map(|q| (q - p).norm())
                })
                .collect();
            let radii = points
                .iter()
                .zip(radii)
                .map(|(p, r)| {
                    r.ok_or_else(|| {
                        self.geometry_error(p, "no closest surface point for a centerline point", "a smaller cell size")
                    })
                })
                .collect::<Result<Vec<f64>>>()?;
            let mut cell_tags = IndexMap::new();
            cell_tags.insert("CenterlineIds".to_string(), id as i64);
            polylines.push(CenterlinePolyline { points, radii: Some(radii), normals: None, cell_tags });
        }
        Ok(Centerlines { polylines, source: PathBuf::from(format!("{} (synthetic)", self.name)) })
    }
}

/// Paths of the two files of a branching fixture in `dir`: `<name>.stl`, `<name>_centerlines.vtp`.
pub fn branching_fixture_paths(name: &str, dir: &Path) -> (PathBuf, PathBuf) {
    (dir.join(format!("{name}.stl")), dir.join(format!("{name}_centerlines.vtp")))
}

/// What [`write_branching_fixture`] wrote.
#[derive(Debug, Clone)]
pub struct WrittenFixture {
    pub stl: PathBuf,
    pub centerlines: PathBuf,
    pub surface: BranchingSurface,
    pub centerline_data: Centerlines,
}

/// Generates `fixture` and writes `<name>.stl` (binary) and `<name>_centerlines.vtp` into `dir`
/// (created if needed), each atomically. Deterministic: same bytes on every run and thread count.
pub fn write_branching_fixture(fixture: &BranchingFixture, dir: &Path) -> Result<WrittenFixture> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, "creating fixture directory", e))?;
    let surface = fixture.generate_surface()?;
    let centerline_data = fixture.centerlines(&surface)?;
    let (stl, centerlines) = branching_fixture_paths(&fixture.name, dir);
    let header = format!(
        "vesselhex synthetic fixture {}: mm, outward normals, {} open ends",
        fixture.name,
        fixture.openings().len()
    );
    write_binary_stl(&stl, &header, &surface.vertices, &surface.triangles)?;
    write_vtp(&centerline_data, 1.0, &centerlines)?;
    Ok(WrittenFixture { stl, centerlines, surface, centerline_data })
}

/// The committed branching fixtures: `y_bifurcation` ([`YBifurcation::default`]) and
/// `t_junction` ([`TJunction::default`]).
pub fn default_branching_fixtures() -> Result<Vec<BranchingFixture>> {
    Ok(vec![YBifurcation::default().fixture("y_bifurcation")?, TJunction::default().fixture("t_junction")?])
}

/// Writes every fixture of [`default_branching_fixtures`] into `dir`; returns the files written
/// (STL then VTP for each).
pub fn write_all_branching_fixtures(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    for fixture in default_branching_fixtures()? {
        let w = write_branching_fixture(&fixture, dir)?;
        written.push(w.stl);
        written.push(w.centerlines);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smooth_min_is_the_minimum_outside_the_band_and_its_gradient_is_consistent() {
        let k = 0.5;
        let (ga, gb) = (Vector3::x(), Vector3::y());
        assert_eq!(smooth_min((1.0, ga), (1.6, gb), k), (1.0, ga));
        assert_eq!(smooth_min((1.6, ga), (1.0, gb), k), (1.0, gb));
        // At a = b the surface moves out by k / 6 and both gradients weigh one half.
        let (v, g) = smooth_min((1.0, ga), (1.0, gb), k);
        assert!((v - (1.0 - k / 6.0)).abs() < 1e-15 && (g - (ga + gb) * 0.5).norm() < 1e-15);
        // d smin / da and d smin / db by central differences, across the band.
        let h = 1e-6;
        for i in 0..=40 {
            let b = 1.0 - 0.6 + 1.2 * i as f64 / 40.0;
            let (_, g) = smooth_min((1.0, ga), (b, gb), k);
            let da = (smooth_min((1.0 + h, ga), (b, gb), k).0 - smooth_min((1.0 - h, ga), (b, gb), k).0) / (2.0 * h);
            let db = (smooth_min((1.0, ga), (b + h, gb), k).0 - smooth_min((1.0, ga), (b - h, gb), k).0) / (2.0 * h);
            assert!((g.x - da).abs() < 1e-8 && (g.y - db).abs() < 1e-8, "b = {b}: {g:?} vs {da}, {db}");
        }
    }

    #[test]
    fn segment_distance_matches_dense_sampling() {
        let segments = [
            (
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(0.0, 0.0, 5.0),
                Point3::new(1.0, -2.0, 2.0),
                Point3::new(1.0, 2.0, 3.0),
            ),
            (
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(3.0, 1.0, 0.0),
                Point3::new(5.0, 1.0, 0.0),
            ),
            (
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(2.0, 0.0, 0.0),
                Point3::new(0.0, 1.0, 0.0),
                Point3::new(2.0, 1.0, 0.0),
            ),
        ];
        for (p0, p1, q0, q1) in segments {
            let n = 2000;
            let brute = (0..=n)
                .map(|i| {
                    let p = p0 + (p1 - p0) * (i as f64 / n as f64);
                    (closest_on_segment(&p, &q0, &q1) - p).norm()
                })
                .fold(f64::INFINITY, f64::min);
            let d = segment_distance(&p0, &p1, &q0, &q1);
            assert!(d <= brute + 1e-12 && brute - d < 1e-5, "{d} vs {brute}");
        }
    }

    #[test]
    fn last_root_of_a_convex_function() {
        assert!((last_root_of_convex(|s| (s - 3.0).powi(2) - 4.0, 100.0) - 5.0).abs() < 1e-9);
        assert!((last_root_of_convex(|s| s - 2.5, 100.0) - 2.5).abs() < 1e-9);
        assert_eq!(last_root_of_convex(|s| s + 1.0, 100.0), 0.0);
    }

    #[test]
    fn separation_of_a_right_angle_t_is_the_sum_of_the_radii_and_blends() {
        let t = TJunction::default().fixture("t").unwrap();
        let k = t.blend_width;
        let o = t.openings();
        assert_eq!(o.len(), 3);
        // Parent both ways and the branch: clear once the branch's (resp. parent's) tube is r + 2k away.
        for opening in &o {
            assert!((opening.separation - (2.0 + 1.0 + 2.0 * k)).abs() < 1e-9, "{opening:?}");
            assert!((opening.length - opening.separation - 6.0 * opening.radius).abs() < 1e-9);
        }
    }

    #[test]
    fn projection_lands_on_the_surface_and_closest_point_on_a_tube_is_radial() {
        let fixture = YBifurcation::default().fixture("y").unwrap();
        let f = fixture.lumen_function();
        let q = f.project(&Point3::new(2.3, 0.4, -9.0)).unwrap();
        assert!(f.value(&q).abs() < 1e-14 && (q.x.hypot(q.y) - 2.0).abs() < 1e-14, "{q:?}");
        let c = f.closest_point(&Point3::new(0.5, 0.0, -9.0), &Point3::new(0.0, 2.0, -8.8)).unwrap();
        assert!((c - Point3::new(2.0, 0.0, -9.0)).norm() < 1e-9, "{c:?}");
    }
}
