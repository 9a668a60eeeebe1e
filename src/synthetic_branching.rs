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
use crate::implicit_surface::{
    check_surface, clip_open_end, compact, segment_distance, smooth_min, triangulate, EndCircle, ImplicitFunction,
    SampledGrid, SurfaceStats, TriangulatedSurface,
};
use crate::io::input::{CenterlinePolyline, Centerlines};
use crate::synthetic::write_binary_stl;
use crate::writers::centerlines::write_vtp;
use indexmap::IndexMap;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

pub use crate::implicit_surface::{min_angle_deg, MIN_ANGLE_DEG};

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

impl Opening {
    /// The end circle, open.
    pub fn circle(&self) -> EndCircle {
        EndCircle {
            centre: self.centre,
            outward: self.outward,
            radius: self.radius,
            capped: false,
            beyond: f64::INFINITY,
        }
    }
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

/// The lumen's implicit function `F` (negative inside) with its gradient, and projections onto
/// its zero level set.
#[derive(Debug, Clone)]
pub struct LumenFunction {
    capsules: Vec<Capsule>,
    blend_width: f64,
    /// Length scale for the step cap of the Newton iterations (the grid cell).
    step_cap: f64,
}

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

    /// See [`ImplicitFunction::distance_estimate`].
    pub fn distance_estimate(&self, p: &Point3<f64>) -> f64 {
        ImplicitFunction::distance_estimate(self, p)
    }

    /// See [`ImplicitFunction::project`].
    pub fn project(&self, p: &Point3<f64>) -> Option<Point3<f64>> {
        ImplicitFunction::project(self, p)
    }

    /// See [`ImplicitFunction::project_in_plane`].
    pub fn project_in_plane(
        &self,
        p: &Point3<f64>,
        origin: &Point3<f64>,
        normal: &Vector3<f64>,
    ) -> Option<Point3<f64>> {
        ImplicitFunction::project_in_plane(self, p, origin, normal)
    }

    /// See [`ImplicitFunction::closest_point`].
    pub fn closest_point(&self, p: &Point3<f64>, seed: &Point3<f64>) -> Option<Point3<f64>> {
        ImplicitFunction::closest_point(self, p, seed)
    }
}

impl ImplicitFunction for LumenFunction {
    fn value_gradient(&self, p: &Point3<f64>) -> (f64, Vector3<f64>) {
        LumenFunction::value_gradient(self, p)
    }
    fn step_cap(&self) -> f64 {
        self.step_cap
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

/// The triangulated lumen of a fixture: f64 vertices on `F = 0`, triangles wound outward (right-
/// hand rule normals point out of the lumen), one open boundary loop per end.
pub type BranchingSurface = TriangulatedSurface;

/// The grid of a fixture: cells of `cell_size` over the capsules' bounding box padded by two
/// cells, nodes at `(m + 1/2) h`, every node sampled.
fn sample_grid(fixture: &BranchingFixture, f: &LumenFunction) -> SampledGrid {
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
    SampledGrid::sample_all(origin, h, cells, f)
}

impl BranchingFixture {
    /// Triangulates the lumen (see the module documentation) and checks it.
    pub fn generate_surface(&self) -> Result<BranchingSurface> {
        let f = self.lumen_function();
        let h = self.cell_size;
        let mut grid = sample_grid(self, &f);
        let (mut vertices, mut triangles, flipped) = triangulate(&f, &mut grid).map_err(|d| {
            let fix = if d.what.contains("non-manifold") {
                "a smaller cell size or a wider blend"
            } else {
                "a smaller cell size"
            };
            self.geometry_error(&d.at, &d.what, fix)
        })?;
        let mut stats = SurfaceStats { grid: grid.cells, flipped, ..SurfaceStats::default() };
        let ends: Vec<EndCircle> = self.openings().iter().map(Opening::circle).collect();
        for o in &ends {
            triangles = clip_open_end(&f, o, h, &mut vertices, triangles, &mut stats)
                .map_err(|d| self.geometry_error(&d.at, &d.what, "a smaller cell size"))?;
        }
        let (vertices, triangles) = compact(vertices, triangles);
        let mut surface = BranchingSurface { vertices, triangles, stats };
        check_surface(&f, &mut surface, &ends)
            .map_err(|d| self.geometry_error(&d.at, &d.what, "a smaller cell size"))?;
        Ok(surface)
    }

    fn geometry_error(&self, at: &Point3<f64>, what: &str, fix: &str) -> Error {
        Error::Geometry(format!(
            "synthetic fixture '{}': {what} near ({:.4}, {:.4}, {:.4}) mm with cell size {} mm; try {fix}",
            self.name, at.x, at.y, at.z, self.cell_size
        ))
    }
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
