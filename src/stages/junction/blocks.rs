//! Block topology of one cross-section: an O-grid made of a core square block and four lateral
//! blocks, and the rays that project it onto the lumen surface.
//!
//! In the section plane, with coordinates (x, y) along the frame's (normal, binormal) and lengths
//! relative to the local radius:
//! * the core square [-a, a]^2 carries an (N+1) x (N+1) grid of nodes, a = `core_size`;
//! * its boundary has 4N *ring points*, numbered counter-clockwise from the corner (a, -a);
//! * ring point k casts a ray towards its *target* on the outer block surface, a circle of
//!   radius `ray_reach` at angle -45 deg + k 360/4N. The lumen-surface node of ring point k is where
//!   that ray meets the surface (the paper's source-to-target rays, which keep the blocks'
//!   orientation where surface normals would cross).
//!
//! The lateral blocks fill the space between the core boundary and the surface nodes with
//! `radial_elements` layers, graded towards the wall; the wall grows beyond the surface along
//! the same rays.

use crate::stages::centerline::CenterlineSample;
use nalgebra::{Point3, Vector2, Vector3};

/// The 2D O-grid of one cross-section, shared by every station of a branch.
///
/// The core grid may have different numbers of elements across (`nx`) and up (`ny`): a small
/// side branch's core is meant to get fewer columns than its spine has rows (thin pages,
/// BRANCHING.md §4.3). Every branch is meshed with the square core of `lumen.core_elements`
/// today.
#[derive(Debug, Clone, PartialEq)]
pub struct SectionTemplate {
    /// Elements along the core's x side (across the pages at a fold).
    pub nx: usize,
    /// Elements along the core's y side (along a junction's spine at a fold).
    pub ny: usize,
    pub core_size: f64,
    pub ray_reach: f64,
    /// Core grid nodes (i, j) at index j * (nx+1) + i, in radius units.
    pub core: Vec<Vector2<f64>>,
    /// For each of the 2(nx+ny) ring points: index of its core grid node.
    pub ring_core_index: Vec<usize>,
    /// For each ring point: unit direction of its target on the outer circle.
    pub target_dir: Vec<Vector2<f64>>,
}

impl SectionTemplate {
    /// The square O-grid: an n x n core and 4n ring points.
    pub fn new(n: usize, core_size: f64, ray_reach: f64) -> Self {
        Self::rect(n, n, core_size, ray_reach)
    }

    /// An nx x ny core grid over the core square [-a, a]^2 and 2(nx+ny) ring points, numbered
    /// counter-clockwise from the corner (a, -a): up the side x = a (ny), left along the top
    /// (nx), down x = -a (ny), right along the bottom (nx). Each side's targets are spread
    /// evenly over its quarter of the circle, from -45 degrees, so the corners' rays lie on
    /// the diagonals. (Scaled Jacobian and skew do not mind the 2:1 cells of an 8 x 4 grid on
    /// a square core; the rays and targets keep the lateral blocks square to the wall.)
    pub fn rect(nx: usize, ny: usize, core_size: f64, ray_reach: f64) -> Self {
        let a = core_size;
        let core = (0..=ny)
            .flat_map(|j| (0..=nx).map(move |i| (i, j)))
            .map(|(i, j)| Vector2::new(-a + 2.0 * a * i as f64 / nx as f64, -a + 2.0 * a * j as f64 / ny as f64))
            .collect();
        let idx = |i: usize, j: usize| j * (nx + 1) + i;
        let ring = 2 * (nx + ny);
        let ring_core_index = (0..ring)
            .map(|k| match k {
                k if k < ny => idx(nx, k),
                k if k < ny + nx => idx(nx - (k - ny), ny),
                k if k < 2 * ny + nx => idx(0, ny - (k - ny - nx)),
                k => idx(k - 2 * ny - nx, 0),
            })
            .collect();
        use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, TAU};
        // Each side's ring points aim at its own quarter of the circle, so the corners' rays
        // stay on the diagonals; a square grid keeps the single even spacing (the same bits).
        let side_and_fraction = |k: usize| -> (usize, f64) {
            let sides = [ny, nx, ny, nx];
            let (mut side, mut rest) = (0, k);
            while rest >= sides[side] {
                rest -= sides[side];
                side += 1;
            }
            (side, rest as f64 / sides[side] as f64)
        };
        let target_dir = (0..ring)
            .map(|k| {
                let theta = if nx == ny {
                    -FRAC_PI_4 + TAU * k as f64 / ring as f64
                } else {
                    let (side, fraction) = side_and_fraction(k);
                    -FRAC_PI_4 + FRAC_PI_2 * (side as f64 + fraction)
                };
                Vector2::new(theta.cos(), theta.sin())
            })
            .collect();
        SectionTemplate { nx, ny, core_size, ray_reach, core, ring_core_index, target_dir }
    }

    /// Number of ring points (= circumferential elements).
    pub fn ring_len(&self) -> usize {
        2 * (self.nx + self.ny)
    }

    /// Number of core grid nodes.
    pub fn core_len(&self) -> usize {
        (self.nx + 1) * (self.ny + 1)
    }

    /// Core quads as corner indices into `core`, counter-clockwise in (x, y).
    pub fn core_quads(&self) -> Vec<[usize; 4]> {
        let (nx, ny) = (self.nx, self.ny);
        let idx = |i: usize, j: usize| j * (nx + 1) + i;
        (0..ny)
            .flat_map(|j| (0..nx).map(move |i| (i, j)))
            .map(|(i, j)| [idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)])
            .collect()
    }

    /// The ray of ring point `k` at a station: origin on the core square and unit direction
    /// towards its target.
    pub fn ray(&self, station: &CenterlineSample, k: usize) -> (Point3<f64>, Vector3<f64>, f64) {
        let origin = self.place(station, &self.core[self.ring_core_index[k]]);
        let target = self.place(station, &(self.target_dir[k] * self.ray_reach));
        let d = target - origin;
        let len = d.norm();
        (origin, d / len, len)
    }

    /// A point of the section plane given in radius units.
    pub fn place(&self, station: &CenterlineSample, xy: &Vector2<f64>) -> Point3<f64> {
        let f = &station.frame;
        station.point + (f.normal * xy.x + f.binormal * xy.y) * station.radius
    }
}

/// Relative positions (0 at the core, 1 at the wall) of the lateral nodes along a ray: `cells`
/// cells whose heights grow by `ratio` from the wall inwards.
pub fn graded_levels(cells: usize, ratio: f64) -> Vec<f64> {
    let heights: Vec<f64> = (0..cells).map(|j| ratio.powi(j as i32)).collect();
    let total: f64 = heights.iter().sum();
    // heights[j] is the j-th cell counted from the wall
    let mut levels = vec![0.0; cells + 1];
    let mut acc = 0.0;
    for j in 0..cells {
        acc += heights[j] / total;
        levels[cells - 1 - j] = 1.0 - acc;
    }
    levels[0] = 0.0;
    levels[cells] = 1.0;
    levels
}

/// The growth ratio that gives a first cell (at the wall) of relative height `first` with
/// `cells` cells, by bisection (the height is monotone in the ratio).
pub fn growth_ratio_for_first_cell(cells: usize, first: f64) -> f64 {
    let first_of = |g: f64| {
        let total: f64 = (0..cells).map(|j| g.powi(j as i32)).sum();
        1.0 / total
    };
    let (mut lo, mut hi) = (1.0, 10.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if first_of(mid) > first {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Arc-length positions of the stations between `s0` and `s1` so that each element is about
/// `spacing(s)` long, where spacing follows the local radius or is constant.
pub fn station_positions(s0: f64, s1: f64, spacing: impl Fn(f64) -> f64) -> Vec<f64> {
    // Integrate ds / h(s) on a fine grid, then invert.
    let fine = 2000;
    let ds = (s1 - s0) / fine as f64;
    let mut cum = vec![0.0];
    for i in 0..fine {
        let s = s0 + (i as f64 + 0.5) * ds;
        cum.push(cum[i] + ds / spacing(s));
    }
    let total = cum[fine];
    let count = (total.round() as usize).max(1);
    let mut out = Vec::with_capacity(count + 1);
    let mut j = 0;
    for i in 0..=count {
        let target = total * i as f64 / count as f64;
        while j + 1 < fine && cum[j + 1] < target {
            j += 1;
        }
        let w = ((target - cum[j]) / (cum[j + 1] - cum[j])).clamp(0.0, 1.0);
        out.push(s0 + (j as f64 + w) * ds);
    }
    out[0] = s0;
    out[count] = s1;
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_runs_counter_clockwise_around_the_core_boundary() {
        let t = SectionTemplate::new(3, 0.5, 4.0);
        assert_eq!(t.ring_len(), 12);
        let mut area = 0.0;
        for k in 0..12 {
            let p = t.core[t.ring_core_index[k]];
            let q = t.core[t.ring_core_index[(k + 1) % 12]];
            assert!(((q - p).norm() - 1.0 / 3.0).abs() < 1e-12, "ring points are neighbours");
            area += p.x * q.y - q.x * p.y;
        }
        assert!((area / 2.0 - 1.0).abs() < 1e-12, "signed area of the square = +1");
        // first ring point is the corner (a, -a), its target at -45 degrees
        assert_eq!(t.core[t.ring_core_index[0]], Vector2::new(0.5, -0.5));
        assert!((t.target_dir[0] - Vector2::new(1.0, -1.0).normalize()).norm() < 1e-12);
    }

    /// A rectangular grid's ring runs counter-clockwise round the core boundary through its
    /// corners, and its quads cover the core once.
    #[test]
    fn rectangular_core_ring_and_quads() {
        let (nx, ny, a) = (2, 4, 0.5);
        let t = SectionTemplate::rect(nx, ny, a, 3.0);
        let ring = t.ring_len();
        assert_eq!(ring, 12);
        assert_eq!(t.core.len(), t.core_len());
        let mut area = 0.0;
        for k in 0..ring {
            let p = t.core[t.ring_core_index[k]];
            let q = t.core[t.ring_core_index[(k + 1) % ring]];
            let step =
                if k < ny || (nx + ny..2 * ny + nx).contains(&k) { 2.0 * a / ny as f64 } else { 2.0 * a / nx as f64 };
            assert!(((q - p).norm() - step).abs() < 1e-12, "ring points {k} and {} are neighbours", k + 1);
            area += p.x * q.y - q.x * p.y;
        }
        assert!((area / 2.0 - 4.0 * a * a).abs() < 1e-12, "the ring encloses the core counter-clockwise");
        for (k, corner) in [(0, (a, -a)), (ny, (a, a)), (ny + nx, (-a, a)), (2 * ny + nx, (-a, -a))] {
            assert_eq!(t.core[t.ring_core_index[k]], Vector2::new(corner.0, corner.1), "corner at ring point {k}");
        }
        let quads = t.core_quads();
        assert_eq!(quads.len(), nx * ny);
        let covered: f64 = quads
            .iter()
            .map(|q| {
                let c: Vec<_> = q.iter().map(|&i| t.core[i]).collect();
                0.5 * (0..4).map(|k| c[k].x * c[(k + 1) % 4].y - c[(k + 1) % 4].x * c[k].y).sum::<f64>()
            })
            .inspect(|&area| assert!(area > 0.0, "quads counter-clockwise"))
            .sum();
        assert!((covered - 4.0 * a * a).abs() < 1e-12);
        // Each side's rays aim into its own quarter: the corners' on the diagonals.
        for k in 0..ring {
            let (p, d) = (t.core[t.ring_core_index[k]], t.target_dir[k]);
            let corner = p.x.abs() == a && p.y.abs() == a;
            if corner {
                assert!((d - p.normalize()).norm() < 1e-12, "corner ray {k} on the diagonal");
            } else {
                assert!(
                    d.dot(&p) > 0.0 && (d.x.abs() > d.y.abs()) == (p.x.abs() == a),
                    "ray {k} in its side's quarter"
                );
            }
        }
        // The square grid is the rectangular one with nx = ny, to the bit.
        assert_eq!(SectionTemplate::new(4, 0.4, 2.0), SectionTemplate::rect(4, 4, 0.4, 2.0));
    }

    #[test]
    fn grading_puts_the_smallest_cell_at_the_wall() {
        let l = graded_levels(5, 1.3);
        assert_eq!(l[0], 0.0);
        assert_eq!(l[5], 1.0);
        let h: Vec<f64> = l.windows(2).map(|w| w[1] - w[0]).collect();
        for w in h.windows(2) {
            assert!((w[0] / w[1] - 1.3).abs() < 1e-9);
        }
        let g = growth_ratio_for_first_cell(5, h[4]);
        assert!((g - 1.3).abs() < 1e-9);
    }

    #[test]
    fn stations_follow_a_varying_spacing() {
        let s = station_positions(0.0, 10.0, |_| 1.0);
        assert_eq!(s.len(), 11);
        let s = station_positions(0.0, 10.0, |x| if x < 5.0 { 0.5 } else { 1.0 });
        assert_eq!(s.len(), 16);
        assert!((s[10] - 5.0).abs() < 1e-2);
    }
}
