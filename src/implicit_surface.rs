//! Triangulated surfaces of implicit functions, the machinery shared by the synthetic branching
//! fixtures ([`crate::synthetic_branching`]) and the random trees ([`crate::synthetic_tree`]).
//!
//! A lumen is `{F < 0}` for an implicit function `F` ([`ImplicitFunction`]: a value and its
//! gradient, negative inside). Its surface `F = 0` is triangulated in five steps:
//!
//! 1. `F` is sampled on a uniform grid stored in bricks of [`BRICK`]³ nodes ([`SampledGrid`]);
//!    a caller may sample every brick (a small fixture) or only those near the surface, the
//!    others held as one value of the right sign (a narrow band, for large trees).
//! 2. Naive surface nets ([`surface_nets`]): one vertex per grid cell the surface crosses (the mean
//!    of the crossings of its edges), one outward quad per grid edge with a sign change. Vertices
//!    come in the order of their cells' linear index and quads in the order of their edges', so
//!    the result does not depend on how the grid was split into bricks nor on the thread count.
//! 3. Every vertex is moved onto `F = 0` by Newton steps ([`ImplicitFunction::project`]), then
//!    [`SMOOTHING_PASSES`] passes of tangential relaxation ([`relax_on_surface`]) even out the
//!    vertex spacing, each followed by the same projection; quads are split along their better
//!    diagonal ([`split_quad`]).
//! 4. Each open end is cut by its end plane ([`clip_open_end`]): vertices within a quarter cell
//!    of the plane are slid onto it, then the triangles crossing it are split, so every end is
//!    an open boundary loop of vertices on the exact end circle, without slivers. A capped end is
//!    then closed by a flat disc of rings ([`cap_end`]).
//! 5. [`check_surface`] checks the result: manifold (edges and vertex fans), one piece, one
//!    boundary loop per open end lying on its circle, none elsewhere, flat caps in their plane,
//!    genus 0 (Euler characteristic `2 - open ends`), triangles facing out of the lumen, no
//!    triangle angle below [`MIN_ANGLE_DEG`].
//!
//! Errors are [`SurfaceDefect`]s (a place and what is wrong there); the callers turn them into
//! messages naming their fixture.

use crate::mesh::closest_on_segment;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};

/// What is wrong with a generated surface, and where.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceDefect {
    pub at: Point3<f64>,
    pub what: String,
}

impl SurfaceDefect {
    fn new(at: Point3<f64>, what: impl Into<String>) -> Self {
        SurfaceDefect { at, what: what.into() }
    }
}

// ---------------------------------------------------------------------------------------------
// Implicit functions
// ---------------------------------------------------------------------------------------------

/// Newton iterations allowed to land a point on `F = 0`.
const NEWTON_ITERATIONS: usize = 100;

/// An implicit lumen `{F < 0}`: `F` with its gradient, and projections onto `F = 0`.
pub trait ImplicitFunction: Sync {
    /// `F(p)` and `∇F(p)`.
    fn value_gradient(&self, p: &Point3<f64>) -> (f64, Vector3<f64>);

    /// Length scale capping the Newton steps (the grid cell).
    fn step_cap(&self) -> f64;

    fn value(&self, p: &Point3<f64>) -> f64 {
        self.value_gradient(p).0
    }

    /// First-order distance estimate `|F| / |∇F|` (exact on the surface to first order; used to
    /// measure how far a vertex is from `F = 0`).
    fn distance_estimate(&self, p: &Point3<f64>) -> f64 {
        let (f, g) = self.value_gradient(p);
        f.abs() / g.norm()
    }

    /// Moves `p` onto `F = 0` by Newton steps along the gradient (each capped at a grid cell),
    /// until a step is below 1e-15 of the coordinates; `None` if that does not happen.
    fn project(&self, p: &Point3<f64>) -> Option<Point3<f64>> {
        newton(self, p, None)
    }

    /// Like [`ImplicitFunction::project`] but moving only within the plane through `origin`
    /// normal to the unit vector `normal` (lands on the curve where the plane cuts the surface).
    fn project_in_plane(&self, p: &Point3<f64>, origin: &Point3<f64>, normal: &Vector3<f64>) -> Option<Point3<f64>> {
        let start = p - normal * (p - origin).dot(normal);
        let x = newton(self, &start, Some(normal))?;
        Some(x - normal * (x - origin).dot(normal))
    }

    /// The point of `F = 0` closest to `p`, found from `seed` (a surface point near it) by
    /// moving along the tangent plane towards the foot of `p` (at most a grid cell at a time)
    /// and projecting back onto the surface, accepting only moves that bring the point nearer
    /// to `p` (halving the move otherwise), until a move is below 1e-13 of the coordinates.
    fn closest_point(&self, p: &Point3<f64>, seed: &Point3<f64>) -> Option<Point3<f64>> {
        let step_cap = self.step_cap();
        let mut x = self.project(seed)?;
        let mut scale: f64 = 1.0;
        for _ in 0..2000 {
            let n = self.value_gradient(&x).1.normalize();
            let d = p - x;
            let mut tangential = (d - n * d.dot(&n)) * scale;
            let len = tangential.norm();
            if len > step_cap {
                tangential *= step_cap / len;
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

fn newton<F: ImplicitFunction + ?Sized>(
    f: &F,
    p: &Point3<f64>,
    plane_normal: Option<&Vector3<f64>>,
) -> Option<Point3<f64>> {
    let step_cap = f.step_cap();
    let mut x = *p;
    for _ in 0..NEWTON_ITERATIONS {
        let (v, mut g) = f.value_gradient(&x);
        if let Some(n) = plane_normal {
            g -= n * g.dot(n);
        }
        let g2 = g.norm_squared();
        if g2.is_nan() || g2 <= 1e-20 || !v.is_finite() {
            return None;
        }
        // Converged when F is at its rounding level; where the gradient is weak (several
        // tubes blending) the step itself never gets that small.
        if v.abs() <= 1e-15 * (1.0 + x.coords.norm()) {
            return Some(x);
        }
        let mut step = g * (v / g2);
        let len = step.norm();
        if len > step_cap {
            step *= step_cap / len;
        }
        x -= step;
        if len <= 1e-15 * (1.0 + x.coords.norm()) {
            return Some(x);
        }
    }
    None
}

/// Cubic smooth minimum (C²) of two values with their gradients, blend width `k`:
/// `min(a, b) - k h³ / 6` with `h = max(k - |a - b|, 0) / k`. Outside the band `|a - b| < k`
/// it is the plain minimum; on `a = b` it lies `k / 6` below it.
pub fn smooth_min(a: (f64, Vector3<f64>), b: (f64, Vector3<f64>), k: f64) -> (f64, Vector3<f64>) {
    let (lo, hi) = if a.0 <= b.0 { (a, b) } else { (b, a) };
    let h = (k - (hi.0 - lo.0)).max(0.0) / k;
    if h == 0.0 {
        return lo;
    }
    let w = 0.5 * h * h;
    (lo.0 - k * h * h * h / 6.0, lo.1 * (1.0 - w) + hi.1 * w)
}

/// [`smooth_min`] with a blend width that varies in space: `k` with its gradient `grad_k`
/// (`k = 0` is the plain minimum). The gradient includes `∂/∂k (-k h³ / 6) ∇k`.
pub fn smooth_min_varying(
    a: (f64, Vector3<f64>),
    b: (f64, Vector3<f64>),
    k: f64,
    grad_k: &Vector3<f64>,
) -> (f64, Vector3<f64>) {
    let (lo, hi) = if a.0 <= b.0 { (a, b) } else { (b, a) };
    if k <= 0.0 {
        return lo;
    }
    let h = (k - (hi.0 - lo.0)).max(0.0) / k;
    if h == 0.0 {
        return lo;
    }
    let w = 0.5 * h * h;
    // d/dk of -(k - d)³ / (6 k²) at fixed d = |a - b|.
    let d_dk = -(0.5 * h * h - h * h * h / 3.0);
    (lo.0 - k * h * h * h / 6.0, lo.1 * (1.0 - w) + hi.1 * w + grad_k * d_dk)
}

// ---------------------------------------------------------------------------------------------
// Small geometry
// ---------------------------------------------------------------------------------------------

/// Distance between segments [p0, p1] and [q0, q1]: the distance between the lines' closest
/// points when both fall inside, else the smallest endpoint-to-segment distance (exact for
/// segments, since the minimum is either interior to both or at an endpoint of one).
pub fn segment_distance(p0: &Point3<f64>, p1: &Point3<f64>, q0: &Point3<f64>, q1: &Point3<f64>) -> f64 {
    segment_closest(p0, p1, q0, q1).0
}

/// Closest points of segments [p0, p1] and [q0, q1]: (distance, s, t) with the points at
/// `p0 + s (p1 - p0)` and `q0 + t (q1 - q0)`, s and t in [0, 1] (as [`segment_distance`]).
pub fn segment_closest(p0: &Point3<f64>, p1: &Point3<f64>, q0: &Point3<f64>, q1: &Point3<f64>) -> (f64, f64, f64) {
    let param = |x: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>| {
        let ab = b - a;
        let len2 = ab.norm_squared();
        if len2 == 0.0 {
            0.0
        } else {
            ((x - a).dot(&ab) / len2).clamp(0.0, 1.0)
        }
    };
    let candidates = [
        ((closest_on_segment(p0, q0, q1) - p0).norm(), 0.0, param(p0, q0, q1)),
        ((closest_on_segment(p1, q0, q1) - p1).norm(), 1.0, param(p1, q0, q1)),
        ((closest_on_segment(q0, p0, p1) - q0).norm(), param(q0, p0, p1), 0.0),
        ((closest_on_segment(q1, p0, p1) - q1).norm(), param(q1, p0, p1), 1.0),
    ];
    let mut best = candidates[0];
    for c in &candidates[1..] {
        if c.0 < best.0 {
            best = *c;
        }
    }
    let (d1, d2, r) = (p1 - p0, q1 - q0, p0 - q0);
    let (a, e, b, c, f) = (d1.dot(&d1), d2.dot(&d2), d1.dot(&d2), d1.dot(&r), d2.dot(&r));
    let denom = a * e - b * b;
    if denom > 1e-14 * a * e {
        let s = (b * f - c * e) / denom;
        let t = (a * f - b * c) / denom;
        if (0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&t) {
            let d = ((p0 + d1 * s) - (q0 + d2 * t)).norm();
            if d < best.0 {
                best = (d, s, t);
            }
        }
    }
    best
}

/// Shape quality of a triangle, 4√3 area / Σ edge² (1 for equilateral, 0 for degenerate).
pub fn triangle_quality(a: &Point3<f64>, b: &Point3<f64>, c: &Point3<f64>) -> f64 {
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
pub fn split_quad(q: [u32; 4], vertices: &[Point3<f64>]) -> [[u32; 3]; 2] {
    let p = q.map(|i| vertices[i as usize]);
    let along_02 = triangle_quality(&p[0], &p[1], &p[2]).min(triangle_quality(&p[0], &p[2], &p[3]));
    let along_13 = triangle_quality(&p[0], &p[1], &p[3]).min(triangle_quality(&p[1], &p[2], &p[3]));
    if along_13 > along_02 {
        [[q[0], q[1], q[3]], [q[1], q[2], q[3]]]
    } else {
        [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    }
}

/// Two unit vectors completing the unit `n` to a right-handed frame (`u × w = n`).
pub fn plane_basis(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if n.x.abs() < 0.6 { Vector3::x() } else { Vector3::y() };
    let u = n.cross(&helper).normalize();
    (u, n.cross(&u))
}

// ---------------------------------------------------------------------------------------------
// The sampled grid
// ---------------------------------------------------------------------------------------------

/// Nodes per brick edge.
pub const BRICK: usize = 8;
const BRICK_NODES: usize = BRICK * BRICK * BRICK;

/// The samples of one brick.
#[derive(Debug, Clone)]
pub enum BrickValues {
    /// One value standing for every node: the brick is far enough from the surface that all its
    /// nodes have this sign, at least a cell's length from zero.
    Uniform(f64),
    /// `F` at each node, x fastest (nodes past the grid's last node are not used).
    Nodes(Vec<f64>),
}

/// `F` sampled on the nodes `origin + (i, j, k) h`, `0 <= i <= cells[0]` and so on, in bricks
/// of [`BRICK`]³ nodes; a node of a brick not stored has the value `outside` (positive).
pub struct SampledGrid {
    pub origin: Point3<f64>,
    pub h: f64,
    pub cells: [usize; 3],
    keys: Vec<[usize; 3]>,
    values: Vec<BrickValues>,
    index: HashMap<[usize; 3], usize>,
    outside: f64,
}

impl SampledGrid {
    /// Samples the bricks `keys` (brick coordinates, node `(i, j, k)` lying in brick
    /// `(i, j, k) / BRICK`) with `sample` (in parallel; the result does not depend on the
    /// thread count); nodes of other bricks are `outside`.
    pub fn sample(
        origin: Point3<f64>,
        h: f64,
        cells: [usize; 3],
        mut keys: Vec<[usize; 3]>,
        outside: f64,
        sample: impl Fn(&SampledGrid, [usize; 3]) -> BrickValues + Sync,
    ) -> SampledGrid {
        keys.sort_unstable_by_key(|k| (k[2], k[1], k[0]));
        keys.dedup();
        let mut grid = SampledGrid { origin, h, cells, keys, values: Vec::new(), index: HashMap::new(), outside };
        let values: Vec<BrickValues> = grid.keys.par_iter().map(|&key| sample(&grid, key)).collect();
        grid.values = values;
        grid.index = grid.keys.iter().enumerate().map(|(i, k)| (*k, i)).collect();
        grid
    }

    /// Samples every node with `f` (a dense grid).
    pub fn sample_all(origin: Point3<f64>, h: f64, cells: [usize; 3], f: &(impl ImplicitFunction + ?Sized)) -> Self {
        let n = cells.map(|c| c + 1);
        let bricks = n.map(|m| m.div_ceil(BRICK));
        let mut keys = Vec::with_capacity(bricks[0] * bricks[1] * bricks[2]);
        for k in 0..bricks[2] {
            for j in 0..bricks[1] {
                for i in 0..bricks[0] {
                    keys.push([i, j, k]);
                }
            }
        }
        SampledGrid::sample(origin, h, cells, keys, 1.0, |grid, key| BrickValues::Nodes(grid.sample_brick(key, f)))
    }

    /// `f` at every node of brick `key` that lies in the grid (NaN past its last node).
    pub fn sample_brick(&self, key: [usize; 3], f: &(impl ImplicitFunction + ?Sized)) -> Vec<f64> {
        self.sample_brick_with(key, |p| f.value(p))
    }

    /// `value` at every node of brick `key` that lies in the grid (NaN past its last node).
    pub fn sample_brick_with(&self, key: [usize; 3], value: impl Fn(&Point3<f64>) -> f64) -> Vec<f64> {
        let n = self.node_count();
        let mut out = vec![f64::NAN; BRICK_NODES];
        for (local, v) in out.iter_mut().enumerate() {
            let node = brick_node(key, local);
            if node[0] < n[0] && node[1] < n[1] && node[2] < n[2] {
                *v = value(&self.node_point(node[0], node[1], node[2]));
            }
        }
        out
    }

    pub fn node_count(&self) -> [usize; 3] {
        self.cells.map(|c| c + 1)
    }

    pub fn node_point(&self, i: usize, j: usize, k: usize) -> Point3<f64> {
        self.origin + Vector3::new(i as f64, j as f64, k as f64) * self.h
    }

    /// Centre and half-diagonal of brick `key`'s nodes.
    pub fn brick_centre(&self, key: [usize; 3]) -> (Point3<f64>, f64) {
        let half = 0.5 * (BRICK - 1) as f64;
        let c = key.map(|b| (b * BRICK) as f64 + half);
        (self.origin + Vector3::new(c[0], c[1], c[2]) * self.h, half * self.h * 3f64.sqrt())
    }

    /// The stored values of brick `key`, if any.
    pub fn brick_values(&self, key: [usize; 3]) -> Option<&BrickValues> {
        self.brick(key)
    }

    fn brick(&self, key: [usize; 3]) -> Option<&BrickValues> {
        self.index.get(&key).map(|&i| &self.values[i])
    }

    /// Linear index of a node (x fastest).
    fn node_linear(&self, node: [usize; 3]) -> u64 {
        let n = self.node_count();
        node[0] as u64 + n[0] as u64 * (node[1] as u64 + n[1] as u64 * node[2] as u64)
    }

    /// Linear index of a cell (x fastest).
    fn cell_linear(&self, cell: [usize; 3]) -> u64 {
        let c = self.cells;
        cell[0] as u64 + c[0] as u64 * (cell[1] as u64 + c[1] as u64 * cell[2] as u64)
    }

    /// The values of brick `key`'s nodes and of the next layer of nodes in +x, +y, +z (from the
    /// neighbouring bricks): (BRICK + 1)³ values, x fastest.
    fn with_halo(&self, key: [usize; 3]) -> Vec<f64> {
        const M: usize = BRICK + 1;
        let mut out = vec![self.outside; M * M * M];
        for dz in 0..2 {
            for dy in 0..2 {
                for dx in 0..2 {
                    let nb = [key[0] + dx, key[1] + dy, key[2] + dz];
                    let Some(values) = self.brick(nb) else { continue };
                    let range = |d: usize| if d == 0 { 0..BRICK } else { 0..1 };
                    for z in range(dz) {
                        for y in range(dy) {
                            for x in range(dx) {
                                let local = x + BRICK * (y + BRICK * z);
                                let v = match values {
                                    BrickValues::Uniform(v) => *v,
                                    BrickValues::Nodes(n) => n[local],
                                };
                                out[(x + dx * BRICK) + M * ((y + dy * BRICK) + M * (z + dz * BRICK))] = v;
                            }
                        }
                    }
                }
            }
        }
        out
    }
}

/// Whether a cube's corner signs (bit c set: corner c inside) make more than one surface patch in
/// it: its inside corners, or its outside ones, are not all joined by cube edges.
const fn ambiguous_mask(mask: u8) -> bool {
    let mut side = 0;
    while side < 2 {
        let set = if side == 0 { mask } else { !mask };
        if set != 0 {
            // Grow the component of the lowest corner of the set along cube edges.
            let mut reached = set & set.wrapping_neg();
            let mut grown = true;
            while grown {
                grown = false;
                let mut c = 0;
                while c < 8 {
                    if reached & (1 << c) != 0 {
                        let mut bit = 1;
                        while bit < 8 {
                            let d = c ^ bit;
                            if set & (1 << d) != 0 && reached & (1 << d) == 0 {
                                reached |= 1 << d;
                                grown = true;
                            }
                            bit <<= 1;
                        }
                    }
                    c += 1;
                }
            }
            if reached != set {
                return true;
            }
        }
        side += 1;
    }
    false
}

/// [`ambiguous_mask`] for every mask.
const AMBIGUOUS: [bool; 256] = {
    let mut table = [false; 256];
    let mut m = 0;
    while m < 256 {
        table[m] = ambiguous_mask(m as u8);
        m += 1;
    }
    table
};

impl SampledGrid {
    /// Removes every cell whose corner signs make more than one surface patch (a face with
    /// diagonal signs, a crotch's wedge or a gap thinner than a cell, a surface almost in a plane
    /// of nodes whose signs alternate), which naive surface nets would join into a non-manifold
    /// edge or vertex: in each such cell the outside corner nearest zero (lowest node index on a
    /// tie) goes inside, at a thousandth of a cell from zero, as a segmentation fills a gap
    /// thinner than its voxels, until no cell is ambiguous (each pass fills at least one node, so
    /// this ends). The vertices are projected onto `F = 0` afterwards anyway. Returns the nodes
    /// filled; a grid without ambiguous cells is left exactly as it was.
    pub fn resolve_ambiguities(&mut self) -> usize {
        let mut filled = 0;
        loop {
            let sampled: Vec<usize> =
                (0..self.keys.len()).filter(|&i| matches!(self.values[i], BrickValues::Nodes(_))).collect();
            let mut flips: Vec<(u64, [usize; 3])> =
                sampled.par_iter().flat_map_iter(|&i| self.ambiguous_fills(self.keys[i])).collect();
            flips.sort_unstable_by_key(|f| f.0);
            flips.dedup_by_key(|f| f.0);
            if flips.is_empty() {
                return filled;
            }
            filled += flips.len();
            for (_, node) in flips {
                let key = node.map(|x| x / BRICK);
                let local = node[0] % BRICK + BRICK * (node[1] % BRICK + BRICK * (node[2] % BRICK));
                if let Some(&b) = self.index.get(&key) {
                    if let BrickValues::Nodes(values) = &mut self.values[b] {
                        values[local] = -1e-3 * self.h;
                    }
                }
            }
        }
    }

    /// The node each ambiguous cell of brick `key` asks to fill: (linear index, node).
    fn ambiguous_fills(&self, key: [usize; 3]) -> Vec<(u64, [usize; 3])> {
        const M: usize = BRICK + 1;
        let values = self.with_halo(key);
        let mut out = Vec::new();
        for z in 0..BRICK {
            for y in 0..BRICK {
                for x in 0..BRICK {
                    let node = [key[0] * BRICK + x, key[1] * BRICK + y, key[2] * BRICK + z];
                    if node.iter().zip(&self.cells).any(|(a, c)| a >= c) {
                        continue;
                    }
                    let corner_value = |c: usize| {
                        let (dx, dy, dz) = corner_offset(c);
                        values[(x + dx) + M * ((y + dy) + M * (z + dz))]
                    };
                    let mask = (0..8).fold(0u8, |m, c| if corner_value(c) < 0.0 { m | 1 << c } else { m });
                    if !AMBIGUOUS[mask as usize] {
                        continue;
                    }
                    let fill = (0..8)
                        .filter(|&c| corner_value(c) >= 0.0)
                        .map(|c| {
                            let (dx, dy, dz) = corner_offset(c);
                            let corner = [node[0] + dx, node[1] + dy, node[2] + dz];
                            (corner_value(c), self.node_linear(corner), corner)
                        })
                        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                    if let Some((_, linear, corner)) = fill {
                        out.push((linear, corner));
                    }
                }
            }
        }
        out
    }
}

/// Node of brick `key` at local index `local` (x fastest).
fn brick_node(key: [usize; 3], local: usize) -> [usize; 3] {
    [key[0] * BRICK + local % BRICK, key[1] * BRICK + (local / BRICK) % BRICK, key[2] * BRICK + local / (BRICK * BRICK)]
}

/// Cube corner `c` (bits x, y, z) as offsets.
fn corner_offset(c: usize) -> (usize, usize, usize) {
    (c & 1, (c >> 1) & 1, (c >> 2) & 1)
}

/// What one brick contributes to the surface nets: its crossed cells' vertices and its nodes'
/// sign-changing edges (key `3 × node + axis`, whether the node is inside, the four cells).
type BrickNets = (Vec<(u64, Point3<f64>)>, Vec<(u64, bool, [u64; 4])>);

/// Surface nets (see the module documentation): vertices in the order of their cells' linear
/// index, quads in the order of their edges' (`3 × node + axis`), each counter-clockwise seen
/// from outside. `Err` if a sign change lies beside a cell that has no vertex (a grid that
/// missed the surface, which a correct narrow band never does).
pub fn surface_nets(grid: &SampledGrid) -> Result<(Vec<Point3<f64>>, Vec<[u32; 4]>), SurfaceDefect> {
    let sampled: Vec<[usize; 3]> = grid
        .keys
        .iter()
        .zip(&grid.values)
        .filter(|(_, v)| matches!(v, BrickValues::Nodes(_)))
        .map(|(k, _)| *k)
        .collect();
    let parts: Vec<BrickNets> = sampled.par_iter().map(|&key| brick_nets(grid, key)).collect();
    let mut cells: Vec<(u64, Point3<f64>)> = Vec::new();
    let mut edges: Vec<(u64, bool, [u64; 4])> = Vec::new();
    for (c, e) in parts {
        cells.extend(c);
        edges.extend(e);
    }
    cells.sort_unstable_by_key(|c| c.0);
    edges.sort_unstable_by_key(|e| e.0);
    let vertex_of = |cell: u64| cells.binary_search_by_key(&cell, |c| c.0).ok().map(|i| i as u32);
    let mut quads = Vec::with_capacity(edges.len());
    for (key, here, around) in &edges {
        let mut quad = [0u32; 4];
        for (q, &cell) in quad.iter_mut().zip(around) {
            *q = match vertex_of(cell) {
                Some(v) => v,
                None => {
                    let node = key / 3;
                    let n = grid.node_count();
                    let (i, j, k) = (
                        (node % n[0] as u64) as usize,
                        ((node / n[0] as u64) % n[1] as u64) as usize,
                        (node / (n[0] as u64 * n[1] as u64)) as usize,
                    );
                    return Err(SurfaceDefect::new(
                        grid.node_point(i, j, k),
                        "a sign change of the grid beside a cell without a vertex",
                    ));
                }
            };
        }
        // Counter-clockwise about the edge's axis: (-,-), (+,-), (+,+), (-,+).
        quads.push(if *here { quad } else { [quad[3], quad[2], quad[1], quad[0]] });
    }
    Ok((cells.into_iter().map(|c| c.1).collect(), quads))
}

fn brick_nets(grid: &SampledGrid, key: [usize; 3]) -> BrickNets {
    const M: usize = BRICK + 1;
    let h = grid.h;
    let values = grid.with_halo(key);
    let at = |x: usize, y: usize, z: usize| values[x + M * (y + M * z)];
    // Values at least a tenth of a cell away from zero, sign kept, so crossings stay a tenth of
    // an edge away from the nodes (surface nets' short edges come from crossings at the nodes).
    let floor = 0.1 * h;
    let clamp = |v: f64| if v < 0.0 { v.min(-floor) } else { v.max(floor) };
    let inside = |v: f64| v < 0.0;
    let n = grid.node_count();
    let mut cells = Vec::new();
    let mut edges = Vec::new();
    for z in 0..BRICK {
        for y in 0..BRICK {
            for x in 0..BRICK {
                let node = [key[0] * BRICK + x, key[1] * BRICK + y, key[2] * BRICK + z];
                if node.iter().zip(&n).any(|(a, b)| a >= b) {
                    continue;
                }
                let (i, j, k) = (node[0], node[1], node[2]);
                if i < grid.cells[0] && j < grid.cells[1] && k < grid.cells[2] {
                    let mut v = [0.0; 8];
                    let mut mask = 0u8;
                    for (c, value) in v.iter_mut().enumerate() {
                        let (dx, dy, dz) = corner_offset(c);
                        *value = at(x + dx, y + dy, z + dz);
                        if inside(*value) {
                            mask |= 1 << c;
                        }
                    }
                    if mask != 0 && mask != 255 {
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
                        cells.push((grid.cell_linear(node), grid.node_point(i, j, k) + sum * (h / count)));
                    }
                }
                let here = inside(at(x, y, z));
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
                    let mut next = [x, y, z];
                    next[d] += 1;
                    if inside(at(next[0], next[1], next[2])) == here {
                        continue;
                    }
                    let cell = |du: usize, dw: usize| {
                        let mut c = node;
                        c[u] -= du;
                        c[w] -= dw;
                        grid.cell_linear(c)
                    };
                    edges.push((
                        3 * grid.node_linear(node) + d as u64,
                        here,
                        [cell(1, 1), cell(0, 1), cell(0, 0), cell(1, 0)],
                    ));
                }
            }
        }
    }
    (cells, edges)
}

// ---------------------------------------------------------------------------------------------
// From quads to a clipped, checked triangulation
// ---------------------------------------------------------------------------------------------

/// Passes of [`relax_on_surface`] applied to the surface-nets vertices.
pub const SMOOTHING_PASSES: usize = 3;

/// One pass of tangential Laplacian relaxation over the quad mesh: each vertex moves half-way
/// towards the mean of its quad-edge neighbours, within its tangent plane, then back onto
/// `F = 0` (surface nets places vertices unevenly where the surface is oblique to the grid). A
/// vertex whose projection fails keeps its place.
pub fn relax_on_surface(
    f: &(impl ImplicitFunction + ?Sized),
    vertices: &[Point3<f64>],
    quads: &[[u32; 4]],
) -> Vec<Point3<f64>> {
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

/// Ambiguous cells resolved ([`SampledGrid::resolve_ambiguities`]), surface nets, projection
/// onto `F = 0`, relaxation and the split into triangles: a closed triangulation of the surface
/// in the grid (before any end is cut), and the number of grid nodes flipped. `Err` where a
/// vertex cannot be projected or the result is not manifold (two sheets through one cell that
/// the flips could not separate: the grid is too coarse there).
pub fn triangulate(
    f: &(impl ImplicitFunction + ?Sized),
    grid: &mut SampledGrid,
) -> Result<(Vec<Point3<f64>>, Vec<[u32; 3]>, usize), SurfaceDefect> {
    let flipped = grid.resolve_ambiguities();
    let (raw, quads) = surface_nets(grid)?;
    let projected: Vec<Option<Point3<f64>>> = raw.par_iter().map(|p| f.project(p)).collect();
    let mut vertices = Vec::with_capacity(raw.len());
    for (p, q) in raw.iter().zip(projected) {
        vertices.push(
            q.ok_or_else(|| SurfaceDefect::new(*p, "a surface-nets vertex could not be moved onto the surface"))?,
        );
    }
    for _ in 0..SMOOTHING_PASSES {
        vertices = relax_on_surface(f, &vertices, &quads);
    }
    let triangles: Vec<[u32; 3]> = quads.iter().flat_map(|q| split_quad(*q, &vertices)).collect();
    // Before the cut the surface must be closed and manifold: surface nets joins two sheets
    // that pass through one cell, which happens only where the grid is too coarse.
    if let Err((a, _)) = directed_edges(&triangles) {
        return Err(SurfaceDefect::new(
            vertices[a as usize],
            "two sheets of the surface pass through one grid cell (non-manifold edge)",
        ));
    }
    Ok((vertices, triangles, flipped))
}

/// Directed-edge map of a triangle list; `Err` with the first repeated directed edge (two
/// triangles wound the same way along it, or a non-manifold edge).
pub fn directed_edges(triangles: &[[u32; 3]]) -> std::result::Result<HashMap<(u32, u32), u32>, (u32, u32)> {
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
pub fn incident_triangles(triangles: &[[u32; 3]], vertex_count: usize) -> Vec<Vec<u32>> {
    let mut out = vec![Vec::new(); vertex_count];
    for (t, tri) in triangles.iter().enumerate() {
        for &v in tri {
            out[v as usize].push(t as u32);
        }
    }
    out
}

/// Drops unused vertices, keeping the order of the others.
pub fn compact(vertices: Vec<Point3<f64>>, triangles: Vec<[u32; 3]>) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
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
    /// Largest `|F| / |∇F|` over the vertices off the flat caps, mm.
    pub max_vertex_offset: f64,
    /// Vertices slid onto an end plane, and vertices within a quarter cell of a plane that could
    /// neither be slid onto it nor pushed away from it (their triangles are then cut close to
    /// them; none in any fixture so far).
    pub snapped: usize,
    pub unsnapped: usize,
    /// Grid nodes filled to remove ambiguous cells (none in the fixtures).
    pub flipped: usize,
}

/// A triangulated lumen: f64 vertices on `F = 0` (or on a flat cap), triangles wound outward
/// (right-hand rule normals point out of the lumen).
#[derive(Debug, Clone, PartialEq)]
pub struct TriangulatedSurface {
    pub vertices: Vec<Point3<f64>>,
    pub triangles: Vec<[u32; 3]>,
    pub stats: SurfaceStats,
}

/// An end of the lumen: a circle in the plane normal to its (straight) tube's axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EndCircle {
    pub centre: Point3<f64>,
    /// Unit normal of the end plane, pointing out of the vessel.
    pub outward: Vector3<f64>,
    pub radius: f64,
    /// Closed by a flat disc (else an open boundary loop).
    pub capped: bool,
    /// How far past the plane the cut may touch the surface (the end's own tube and its tip;
    /// infinite when nothing else lies beyond the end, as in the fixtures).
    pub beyond: f64,
}

impl EndCircle {
    /// Whether `q` lies on the end circle (open) or on the disc (`disc`), to 1e-12 relative.
    fn holds(&self, q: &Point3<f64>, disc: bool) -> bool {
        let scale = 1.0 + q.coords.norm();
        let w = q - self.centre;
        let in_plane = w.dot(&self.outward).abs() <= 1e-12 * scale;
        if disc {
            in_plane && w.norm() <= self.radius + 1e-12 * scale
        } else {
            in_plane && (w.norm() - self.radius).abs() <= 1e-12 * scale
        }
    }
}

/// Smallest triangle angle a generated surface may have.
pub const MIN_ANGLE_DEG: f64 = 5.0;

/// Cuts the surface at the end plane of `o`, keeping the lumen side. Only vertices in the clip
/// zone (near the tube's axis line, from 3 cells before the plane to `o.beyond` past it) are
/// considered, so the (infinite) plane never touches another tube. Vertices within a quarter cell of the plane are
/// slid along the axis onto it when that keeps their triangles well oriented and creates no
/// triangle lying in the plane (else pushed a quarter cell away from it); the triangles crossing
/// the plane are then split, new vertices landing on the end circle.
pub fn clip_open_end(
    f: &(impl ImplicitFunction + ?Sized),
    o: &EndCircle,
    h: f64,
    vertices: &mut Vec<Point3<f64>>,
    triangles: Vec<[u32; 3]>,
    stats: &mut SurfaceStats,
) -> Result<Vec<[u32; 3]>, SurfaceDefect> {
    let n = o.outward;
    let zone_radius = o.radius + 3.0 * h;
    let offset = |p: &Point3<f64>| {
        let w = p - o.centre;
        let a = w.dot(&n);
        if a > -3.0 * h && a < o.beyond && (w - n * a).norm() < zone_radius {
            a
        } else {
            f64::NEG_INFINITY
        }
    };
    let mut s: Vec<f64> = vertices.iter().map(offset).collect();
    let mut on_plane = vec![false; vertices.len()];
    let delta = 0.25 * h;
    // The triangles of each vertex that may be slid (within a quarter cell of the plane).
    let mut incident: HashMap<usize, Vec<u32>> = HashMap::new();
    for (t, tri) in triangles.iter().enumerate() {
        for &v in tri {
            if s[v as usize].abs() < delta {
                incident.entry(v as usize).or_default().push(t as u32);
            }
        }
    }
    // Whether moving vertex v to q keeps its triangles facing out (not folded over) and, if
    // `onto_plane`, leaves none with all three corners on the plane.
    let acceptable = |v: usize, q: &Point3<f64>, onto_plane: bool, vertices: &[Point3<f64>], on_plane: &[bool]| {
        incident[&v].iter().all(|&t| {
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
                        let q = f.project_in_plane(&crossing, &o.centre, &n).ok_or_else(|| {
                            SurfaceDefect::new(crossing, "a cut point could not be moved onto the end circle")
                        })?;
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
            _ => return Err(SurfaceDefect::new(vertices[tri[0] as usize], "a triangle was cut into an odd shape")),
        }
    }
    Ok(out)
}

/// The boundary loops of a triangulation, each in the order its triangles wind it, starting at
/// its smallest vertex; `Err` where a vertex starts two boundary edges.
fn boundary_loops(edges: &HashMap<(u32, u32), u32>, vertices: &[Point3<f64>]) -> Result<Vec<Vec<u32>>, SurfaceDefect> {
    let mut next_on_boundary: HashMap<u32, u32> = HashMap::new();
    let mut starts = Vec::new();
    for &(a, b) in edges.keys() {
        if !edges.contains_key(&(b, a)) {
            if next_on_boundary.insert(a, b).is_some() {
                return Err(SurfaceDefect::new(vertices[a as usize], "a vertex is on two boundary loops"));
            }
            starts.push(a);
        }
    }
    starts.sort_unstable();
    let mut seen = HashSet::new();
    let mut loops = Vec::new();
    for &start in &starts {
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
        loops.push(members);
    }
    Ok(loops)
}

/// Closes each capped end of `ends` (one boundary loop on its circle, see [`clip_open_end`])
/// with a flat disc: rings of vertices about a cell apart (the boundary loop's mean edge) from
/// the circle inwards, each zipped to the next, the last fanned to the centre. The discs'
/// triangles face along their ends' outward normals.
pub fn cap_ends(
    ends: &[EndCircle],
    vertices: &mut Vec<Point3<f64>>,
    triangles: &mut Vec<[u32; 3]>,
) -> Result<(), SurfaceDefect> {
    let edges = directed_edges(triangles)
        .map_err(|(a, _)| SurfaceDefect::new(vertices[a as usize], "non-manifold edge before capping"))?;
    let loops = boundary_loops(&edges, vertices)?;
    for o in ends.iter().filter(|o| o.capped) {
        let on_circle: Vec<&Vec<u32>> =
            loops.iter().filter(|lp| lp.iter().all(|&v| o.holds(&vertices[v as usize], false))).collect();
        let [boundary] = on_circle[..] else {
            return Err(SurfaceDefect::new(
                o.centre,
                format!("the end has {} boundary loops to cap, not 1", on_circle.len()),
            ));
        };
        cap_loop(o, boundary, vertices, triangles);
    }
    Ok(())
}

/// The disc of [`cap_ends`] over one boundary loop.
fn cap_loop(o: &EndCircle, boundary: &[u32], vertices: &mut Vec<Point3<f64>>, triangles: &mut Vec<[u32; 3]>) {
    let (u, w) = plane_basis(&o.outward);
    let angle = |p: &Point3<f64>| {
        let d = p - o.centre;
        d.dot(&w).atan2(d.dot(&u))
    };
    // The outer ring counter-clockwise about the outward normal (the cap's winding).
    let mut outer: Vec<u32> = boundary.to_vec();
    let turn: f64 = (0..outer.len())
        .map(|k| {
            let a = angle(&vertices[outer[k] as usize]);
            let b = angle(&vertices[outer[(k + 1) % outer.len()] as usize]);
            let mut step = b - a;
            step -= std::f64::consts::TAU * (step / std::f64::consts::TAU).round();
            step
        })
        .sum();
    if turn < 0.0 {
        outer.reverse();
    }
    let perimeter: f64 = (0..outer.len())
        .map(|k| (vertices[outer[(k + 1) % outer.len()] as usize] - vertices[outer[k] as usize]).norm())
        .sum();
    let edge = perimeter / outer.len() as f64;
    let rings = ((o.radius / edge).round() as usize).max(1);
    let mut ring = outer;
    let start_angle = angle(&vertices[ring[0] as usize]);
    for r in 1..rings {
        let radius = o.radius * (rings - r) as f64 / rings as f64;
        let count = ((std::f64::consts::TAU * radius / edge).round() as usize).max(3);
        // Staggered by half a step from ring to ring.
        let phase = start_angle + std::f64::consts::PI * r as f64 / count as f64;
        let mut inner = Vec::with_capacity(count);
        for i in 0..count {
            let a = phase + std::f64::consts::TAU * i as f64 / count as f64;
            vertices.push(o.centre + u * (radius * a.cos()) + w * (radius * a.sin()));
            inner.push((vertices.len() - 1) as u32);
        }
        zip_rings(&ring, &inner, vertices, triangles, &angle);
        ring = inner;
    }
    vertices.push(o.centre);
    let centre = (vertices.len() - 1) as u32;
    for k in 0..ring.len() {
        triangles.push([ring[k], ring[(k + 1) % ring.len()], centre]);
    }
}

/// Triangles between an outer and an inner ring, both counter-clockwise about the cap's normal
/// (`angle` measures about it): walking both rings once from `outer[0]` and the inner vertex
/// next to it, each step advances the ring whose next vertex comes first by angle.
fn zip_rings(
    outer: &[u32],
    inner: &[u32],
    vertices: &[Point3<f64>],
    triangles: &mut Vec<[u32; 3]>,
    angle: &dyn Fn(&Point3<f64>) -> f64,
) {
    use std::f64::consts::TAU;
    let a0 = angle(&vertices[outer[0] as usize]);
    let relative = |v: u32| {
        let a = angle(&vertices[v as usize]) - a0;
        a - TAU * (a / TAU).floor()
    };
    let j0 = (0..inner.len()).min_by(|&a, &b| relative(inner[a]).total_cmp(&relative(inner[b]))).unwrap_or(0);
    let outer_at = |i: usize| {
        (outer[i % outer.len()], relative(outer[i % outer.len()]) + if i >= outer.len() { TAU } else { 0.0 })
    };
    let inner_at = |j: usize| {
        let v = inner[(j0 + j) % inner.len()];
        (v, relative(v) + if j >= inner.len() { TAU } else { 0.0 })
    };
    let (mut i, mut j) = (0, 0);
    while i < outer.len() || j < inner.len() {
        let advance_outer = j >= inner.len() || (i < outer.len() && outer_at(i + 1).1 <= inner_at(j + 1).1);
        if advance_outer {
            triangles.push([outer_at(i).0, outer_at(i + 1).0, inner_at(j).0]);
            i += 1;
        } else {
            triangles.push([outer_at(i).0, inner_at(j + 1).0, inner_at(j).0]);
            j += 1;
        }
    }
}

/// Checks a generated lumen against its ends (see the module documentation) and fills its
/// stats: for each end, one boundary loop on its circle when open, a flat disc in its plane
/// when capped; nothing else open; one piece of genus 0; outward and non-degenerate triangles.
pub fn check_surface(
    f: &(impl ImplicitFunction + ?Sized),
    s: &mut TriangulatedSurface,
    ends: &[EndCircle],
) -> Result<(), SurfaceDefect> {
    check_surface_of_genus(f, s, ends, 0)
}

/// [`check_surface`] for a lumen of genus `genus` (a vessel network with that many independent
/// loops): with `b` open ends, V - E + F must be 2 - 2 `genus` - `b`.
pub fn check_surface_of_genus(
    f: &(impl ImplicitFunction + ?Sized),
    s: &mut TriangulatedSurface,
    ends: &[EndCircle],
    genus: i64,
) -> Result<(), SurfaceDefect> {
    let edges = directed_edges(&s.triangles).map_err(|(a, _)| {
        SurfaceDefect::new(s.vertices[a as usize], "an edge is shared by more than two triangles or mis-wound")
    })?;
    let loops = boundary_loops(&edges, &s.vertices)?;
    let mut loops_per_end = vec![0usize; ends.len()];
    for members in &loops {
        let which =
            ends.iter().position(|o| !o.capped && members.iter().all(|&m| o.holds(&s.vertices[m as usize], false)));
        match which {
            Some(i) => loops_per_end[i] += 1,
            None => {
                return Err(SurfaceDefect::new(
                    s.vertices[members[0] as usize],
                    "a boundary loop is not an end circle (a hole in the surface)",
                ))
            }
        }
    }
    if let Some(i) = (0..ends.len()).find(|&i| !ends[i].capped && loops_per_end[i] != 1) {
        return Err(SurfaceDefect::new(
            ends[i].centre,
            format!("the open end has {} boundary loops, not 1", loops_per_end[i]),
        ));
    }
    check_vertex_fans(s)?;
    let boundary_edges = loops.iter().map(Vec::len).sum::<usize>();
    let euler = s.vertices.len() as i64 - (edges.len() as i64 + boundary_edges as i64) / 2 + s.triangles.len() as i64;
    let open = ends.iter().filter(|o| !o.capped).count() as i64;
    if euler != 2 - 2 * genus - open {
        return Err(SurfaceDefect::new(
            s.vertices.first().copied().unwrap_or_else(Point3::origin),
            // The tree generator's manifests quote this reason: it stays as it was.
            format!(
                "the surface has Euler characteristic {euler}, not {} (a handle or a separate piece)",
                2 - 2 * genus - open
            ),
        ));
    }
    let pieces = connected_pieces(&s.triangles, s.vertices.len());
    if pieces != 1 {
        return Err(SurfaceDefect::new(s.vertices[0], format!("the surface is in {pieces} pieces, not 1")));
    }
    check_triangles(f, s, ends)
}

/// Each vertex's triangles form one fan (no two surface sheets touching at a vertex).
fn check_vertex_fans(s: &TriangulatedSurface) -> Result<(), SurfaceDefect> {
    let incident = incident_triangles(&s.triangles, s.vertices.len());
    for (v, tris) in incident.iter().enumerate() {
        let v = v as u32;
        let mut link: HashMap<u32, u32> = HashMap::new();
        for &t in tris {
            let tri = s.triangles[t as usize];
            let k = tri.iter().position(|&x| x == v).unwrap_or(0);
            link.insert(tri[(k + 1) % 3], tri[(k + 2) % 3]);
        }
        let targets: HashSet<u32> = link.values().copied().collect();
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
            return Err(SurfaceDefect::new(s.vertices[v as usize], "surface sheets touch at a vertex"));
        }
    }
    Ok(())
}

/// Number of edge-connected pieces of a triangulation.
fn connected_pieces(triangles: &[[u32; 3]], vertex_count: usize) -> usize {
    let mut parent: Vec<u32> = (0..vertex_count as u32).collect();
    fn root(parent: &mut [u32], mut v: u32) -> u32 {
        while parent[v as usize] != v {
            parent[v as usize] = parent[parent[v as usize] as usize];
            v = parent[v as usize];
        }
        v
    }
    for t in triangles {
        for e in 0..2 {
            let (a, b) = (root(&mut parent, t[e]), root(&mut parent, t[e + 1]));
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    let mut used = vec![false; vertex_count];
    for t in triangles {
        for &v in t {
            used[v as usize] = true;
        }
    }
    (0..vertex_count as u32).filter(|&v| used[v as usize] && root(&mut parent, v) == v).count()
}

/// Outward, non-degenerate triangles (a cap's facing along its end's normal, the others the way
/// `F` grows), no angle below [`MIN_ANGLE_DEG`]; fills the stats' angles, edges and offset.
fn check_triangles(
    f: &(impl ImplicitFunction + ?Sized),
    s: &mut TriangulatedSurface,
    ends: &[EndCircle],
) -> Result<(), SurfaceDefect> {
    let mut min_angle = f64::INFINITY;
    let (mut min_edge, mut max_edge) = (f64::INFINITY, 0.0f64);
    let mut on_cap = vec![false; s.vertices.len()];
    for o in ends.iter().filter(|o| o.capped) {
        for (v, p) in s.vertices.iter().enumerate() {
            if o.holds(p, true) {
                on_cap[v] = true;
            }
        }
    }
    for tri in &s.triangles {
        let [a, b, c] = tri.map(|i| s.vertices[i as usize]);
        let normal = (b - a).cross(&(c - a));
        let centroid = Point3::from((a.coords + b.coords + c.coords) / 3.0);
        let cap = ends.iter().find(|o| o.capped && [a, b, c].iter().all(|p| o.holds(p, true)));
        let outward = match cap {
            Some(o) => o.outward,
            None => f.value_gradient(&centroid).1,
        };
        if normal.dot(&outward).is_nan() || normal.dot(&outward) <= 0.0 {
            return Err(SurfaceDefect::new(centroid, "a triangle faces into the lumen"));
        }
        let angle = min_angle_deg(&a, &b, &c);
        if angle.is_nan() || angle < MIN_ANGLE_DEG {
            return Err(SurfaceDefect::new(
                centroid,
                format!("a triangle has an angle of {angle:.2}° (below {MIN_ANGLE_DEG}°)"),
            ));
        }
        min_angle = min_angle.min(angle);
        for (p, q) in [(a, b), (b, c), (c, a)] {
            let e = (q - p).norm();
            min_edge = min_edge.min(e);
            max_edge = max_edge.max(e);
        }
    }
    s.stats.min_angle_deg = min_angle;
    s.stats.min_edge = min_edge;
    s.stats.max_edge = max_edge;
    s.stats.max_vertex_offset = s
        .vertices
        .iter()
        .zip(&on_cap)
        .filter(|(_, cap)| !**cap)
        .map(|(p, _)| f.distance_estimate(p))
        .fold(0.0, f64::max);
    Ok(())
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
    fn varying_blend_width_gradient_matches_finite_differences() {
        // a = x, b = y, k = 0.3 + 0.2 z: the gradient in z is the k term alone.
        let f = |p: &Point3<f64>| {
            let k = 0.3 + 0.2 * p.z;
            smooth_min_varying((p.x, Vector3::x()), (p.y, Vector3::y()), k, &Vector3::new(0.0, 0.0, 0.2))
        };
        let h = 1e-6;
        for p in [Point3::new(0.1, 0.2, 0.5), Point3::new(0.3, 0.25, 0.1), Point3::new(0.0, 0.0, 0.0)] {
            let g = f(&p).1;
            for axis in 0..3 {
                let mut e = Vector3::zeros();
                e[axis] = h;
                let fd = (f(&(p + e)).0 - f(&(p - e)).0) / (2.0 * h);
                assert!((g[axis] - fd).abs() < 1e-7, "{p:?} axis {axis}: {} vs {fd}", g[axis]);
            }
        }
        // Zero width is the plain minimum.
        assert_eq!(smooth_min_varying((1.0, Vector3::x()), (1.0, Vector3::y()), 0.0, &Vector3::z()).0, 1.0);
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
            let (d, s, t) = segment_closest(&p0, &p1, &q0, &q1);
            assert!(d <= brute + 1e-12 && brute - d < 1e-5, "{d} vs {brute}");
            assert_eq!(d, segment_distance(&p0, &p1, &q0, &q1));
            let (p, q) = (p0 + (p1 - p0) * s, q0 + (q1 - q0) * t);
            assert!(((p - q).norm() - d).abs() < 1e-12);
        }
    }

    /// A sphere of radius 1 about (0.3, 0.2, 0.1).
    struct Sphere;
    impl ImplicitFunction for Sphere {
        fn value_gradient(&self, p: &Point3<f64>) -> (f64, Vector3<f64>) {
            let d = p - Point3::new(0.3, 0.2, 0.1);
            (d.norm() - 1.0, d.normalize())
        }
        fn step_cap(&self) -> f64 {
            0.1
        }
    }

    fn sphere_grid(h: f64) -> (Point3<f64>, [usize; 3]) {
        let origin = Point3::new(-1.5 + 0.5 * h, -1.5 + 0.5 * h, -1.5 + 0.5 * h);
        let cells = [0; 3].map(|_| (3.0 / h).ceil() as usize);
        (origin, cells)
    }

    #[test]
    fn a_narrow_band_gives_the_dense_grid_s_surface_exactly() {
        let h = 0.1;
        let (origin, cells) = sphere_grid(h);
        let mut dense = SampledGrid::sample_all(origin, h, cells, &Sphere);
        let all_keys = dense.keys.clone();
        // Bricks far from the surface held as one value.
        let band = SampledGrid::sample(origin, h, cells, all_keys, 1.0, |grid, key| {
            let (c, half) = grid.brick_centre(key);
            let v = Sphere.value(&c);
            if v.abs() > half + 2.0 * h {
                BrickValues::Uniform(v.signum() * 2.0 * h)
            } else {
                BrickValues::Nodes(grid.sample_brick(key, &Sphere))
            }
        });
        let a = surface_nets(&dense).unwrap();
        let b = surface_nets(&band).unwrap();
        assert!(a == b && !a.1.is_empty());
        let (vertices, triangles, flipped) = triangulate(&Sphere, &mut dense).unwrap();
        assert_eq!(flipped, 0);
        let mut s = TriangulatedSurface { vertices, triangles, stats: SurfaceStats::default() };
        check_surface(&Sphere, &mut s, &[]).unwrap();
        assert!(s.stats.max_vertex_offset < 1e-12 && s.stats.min_angle_deg > 5.0, "{:?}", s.stats);
    }

    #[test]
    fn a_capped_cut_closes_the_surface_and_an_open_one_leaves_a_loop() {
        let h = 0.08;
        let (origin, cells) = sphere_grid(h);
        let mut grid = SampledGrid::sample_all(origin, h, cells, &Sphere);
        let (vertices, triangles, _) = triangulate(&Sphere, &mut grid).unwrap();
        // The plane z = 0.1 + 0.5 cuts the sphere in a circle of radius sqrt(0.75).
        let end = EndCircle {
            centre: Point3::new(0.3, 0.2, 0.6),
            outward: Vector3::z(),
            radius: 0.75f64.sqrt(),
            capped: false,
            beyond: f64::INFINITY,
        };
        for capped in [false, true] {
            let mut v = vertices.clone();
            let mut stats = SurfaceStats::default();
            let mut t = clip_open_end(&Sphere, &end, h, &mut v, triangles.clone(), &mut stats).unwrap();
            let end = EndCircle { capped, ..end };
            cap_ends(&[end], &mut v, &mut t).unwrap();
            let (v, t) = compact(v, t);
            let mut s = TriangulatedSurface { vertices: v, triangles: t, stats };
            check_surface(&Sphere, &mut s, &[end]).unwrap();
            assert!(s.stats.min_angle_deg > 10.0, "capped {capped}: {:?}", s.stats);
            // Closed by its cap, the surface encloses the cut ball's volume.
            if capped {
                let volume: f64 = s
                    .triangles
                    .iter()
                    .map(|t| {
                        let [a, b, c] = t.map(|i| s.vertices[i as usize].coords);
                        a.dot(&b.cross(&c)) / 6.0
                    })
                    .sum();
                // Sphere minus the cap of height 0.5: 4π/3 - π 0.5² (3 - 0.5) / 3.
                let exact = 4.0 * std::f64::consts::PI / 3.0 - std::f64::consts::PI * 0.25 * 2.5 / 3.0;
                assert!((volume - exact).abs() < 0.01 * exact, "{volume} vs {exact}");
            }
        }
    }
}
