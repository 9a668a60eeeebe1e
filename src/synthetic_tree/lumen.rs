//! The implicit lumen of a tree and its triangulation.
//!
//! Each vessel is the union of the tapered capsules of its centerline's segments, `f_v(p) =
//! |p - c(t)| - r(t)` with `c(t)` the foot of `p` on the nearest segment and `r` linear along it
//! (a plain minimum along the vessel: consecutive segments turn by 6° at most); each sac is a
//! ball. Components are folded in the order they were laid (every host before its daughters,
//! the sacs last):
//!
//! ```text
//! F = f_0,   F <- smin_{k_c(p)}(F, f_c)   for c = 1, 2, ...
//! ```
//!
//! with the C² cubic smooth minimum of [`smooth_min_varying`] whose width `k_c(p)` is the
//! component's blend width inside its zone (around its junction's contact, or its sac's neck)
//! and falls smoothly to 0 outside: a daughter is filleted into its host and siblings at the
//! junction only, and walls that merely pass each other (at least two cells apart, checked when
//! the tree is laid) meet as a plain minimum, so they never fuse. A component may have several
//! zones (a network's graft joins its host at both ends, [`crate::synthetic_network`]): the
//! widest at a point acts there.
//!
//! Evaluation is local: segments are bucketed in the grid's bricks, each brick holding the
//! segments that come within `band` of it (four cells plus 2.2 blend widths past their radius);
//! `F` is exact wherever it is within a few cells of 0, and has the right sign elsewhere. Bricks
//! whose centre is far from the surface (by a Lipschitz bound) are held as one value, so only a
//! narrow band of the grid is sampled.

use super::layout::Layout;
use super::model::{Finish, Zone};
use crate::implicit_surface::{
    cap_ends, check_surface_of_genus, clip_open_end, compact, smooth_min_varying, triangulate, BrickValues, EndCircle,
    ImplicitFunction, SampledGrid, SurfaceDefect, SurfaceStats, TriangulatedSurface, BRICK,
};
use nalgebra::{Point3, Vector3};
use std::collections::HashMap;

/// One tapered capsule (a ball when its axis is zero).
#[derive(Debug, Clone, Copy)]
struct Segment {
    comp: u32,
    a: Point3<f64>,
    axis: Vector3<f64>,
    inv_len2: f64,
    ra: f64,
    dr: f64,
}

impl Segment {
    fn new(comp: usize, a: Point3<f64>, b: Point3<f64>, ra: f64, rb: f64) -> Self {
        let axis = b - a;
        let len2 = axis.norm_squared();
        Segment { comp: comp as u32, a, axis, inv_len2: if len2 > 0.0 { 1.0 / len2 } else { 0.0 }, ra, dr: rb - ra }
    }

    fn value_gradient(&self, p: &Point3<f64>) -> (f64, Vector3<f64>) {
        let w = p - self.a;
        let raw = w.dot(&self.axis) * self.inv_len2;
        let t = raw.clamp(0.0, 1.0);
        let d = w - self.axis * t;
        let n = d.norm();
        let mut g = if n > 0.0 { d / n } else { Vector3::zeros() };
        if raw > 0.0 && raw < 1.0 {
            g -= self.axis * (self.dr * self.inv_len2);
        }
        (n - (self.ra + self.dr * t), g)
    }

    fn value(&self, p: &Point3<f64>) -> f64 {
        let w = p - self.a;
        let t = (w.dot(&self.axis) * self.inv_len2).clamp(0.0, 1.0);
        (w - self.axis * t).norm() - (self.ra + self.dr * t)
    }

    fn bounds(&self, pad: f64) -> (Point3<f64>, Point3<f64>) {
        let b = self.a + self.axis;
        let r = self.ra.max(self.ra + self.dr) + pad;
        (self.a.inf(&b) - Vector3::repeat(r), self.a.sup(&b) + Vector3::repeat(r))
    }
}

/// The implicit lumen of a tree (see the module documentation).
pub struct TreeLumen {
    segments: Vec<Segment>,
    /// Per segment: how far past its radius it is evaluated (four cells plus 2.2 times the
    /// largest blend width of the zones that can act near it).
    bands: Vec<f64>,
    /// Per component, its blend zones (the widest at a point acts there).
    zones: Vec<Vec<Zone>>,
    origin: Point3<f64>,
    h: f64,
    cells: [usize; 3],
    /// The value where no segment is near (outside).
    far: f64,
    buckets: HashMap<[usize; 3], Vec<u32>>,
}

/// One component of a lumen before it is folded in: the tapered capsules `(a, b, r_a, r_b)` of
/// its axis (a ball when `a == b`) and the zones where it blends with the components before it
/// (none for a component that only meets the others as a plain minimum).
#[derive(Debug, Clone)]
pub struct LumenPart {
    pub capsules: Vec<(Point3<f64>, Point3<f64>, f64, f64)>,
    pub zones: Vec<Zone>,
}

impl TreeLumen {
    /// The lumen of a tree: each vessel (the root's inlet and every free end extended past
    /// their planes), then each sac.
    pub fn new(layout: &Layout) -> Self {
        let ext = layout.extension;
        let mut parts = Vec::new();
        for (id, v) in layout.vessels.iter().enumerate() {
            let mut capsules = Vec::new();
            if id == 0 {
                let q = v.first();
                capsules.push((q.p - q.t * ext, q.p, q.r, q.r));
            }
            capsules.extend(v.samples.windows(2).map(|w| (w[0].p, w[1].p, w[0].r, w[1].r)));
            if v.finish == Finish::Free {
                let q = v.last();
                capsules.push((q.p, q.p + q.t * ext, q.r, q.r));
            }
            parts.push(LumenPart { capsules, zones: v.zone.iter().cloned().collect() });
        }
        for sac in &layout.sacs {
            parts.push(LumenPart {
                capsules: vec![(sac.centre, sac.centre, sac.radius, sac.radius)],
                zones: vec![sac.zone.clone()],
            });
        }
        TreeLumen::from_parts(layout.h, parts)
    }

    /// The lumen of `parts` folded in their order (see the module documentation) on a grid of
    /// cell `h`.
    pub fn from_parts(h: f64, parts: Vec<LumenPart>) -> Self {
        let mut segments = Vec::new();
        let mut zones = Vec::new();
        for (id, part) in parts.into_iter().enumerate() {
            segments.extend(part.capsules.iter().map(|&(a, b, ra, rb)| Segment::new(id, a, b, ra, rb)));
            zones.push(part.zones);
        }
        let largest_blend = zones.iter().flatten().map(|z| z.k).fold(0.0, f64::max);
        let widest = 4.0 * h + 2.2 * largest_blend;
        let bands = segments
            .iter()
            .map(|s| {
                let reach = s.ra.max(s.ra + s.dr) + widest;
                let near = zones.iter().flatten().filter(|z| {
                    crate::implicit_surface::segment_distance(&s.a, &(s.a + s.axis), &z.a, &z.b) <= reach + z.outer
                });
                4.0 * h + 2.2 * near.map(|z| z.k).fold(0.0, f64::max)
            })
            .collect();
        let mut lo = Point3::from([f64::INFINITY; 3]);
        let mut hi = Point3::from([f64::NEG_INFINITY; 3]);
        for s in &segments {
            let (a, b) = s.bounds(2.0 * h);
            lo = lo.inf(&a);
            hi = hi.sup(&b);
        }
        // Nodes at (m + 1/2) h, as the fixtures' grids.
        let origin = lo.map(|x| ((x / h).floor() - 0.5) * h);
        let cells = [0, 1, 2].map(|k| ((hi[k] - origin[k]) / h).ceil() as usize);
        let mut lumen = TreeLumen { segments, bands, zones, origin, h, cells, far: widest, buckets: HashMap::new() };
        lumen.fill_buckets();
        lumen
    }

    /// Each segment into the bricks its band reaches (segments in order, so each bucket's list
    /// is sorted by component, then along it).
    fn fill_buckets(&mut self) {
        let size = BRICK as f64 * self.h;
        let bricks = self.cells.map(|c| (c + 1).div_ceil(BRICK));
        let key = |x: f64, k: usize| (((x - self.origin[k]) / size).floor().max(0.0) as usize).min(bricks[k] - 1);
        let mut buckets: HashMap<[usize; 3], Vec<u32>> = HashMap::new();
        // A brick takes a segment whose axis comes within its radius, the band and the brick's
        // half-diagonal of the brick's centre.
        let half_diagonal = 0.5 * size * 3f64.sqrt();
        for (id, (s, band)) in self.segments.iter().zip(&self.bands).enumerate() {
            let (lo, hi) = s.bounds(*band);
            let (a, b) = ([0, 1, 2].map(|k| key(lo[k], k)), [0, 1, 2].map(|k| key(hi[k], k)));
            let reach = s.ra.max(s.ra + s.dr) + band + half_diagonal;
            for z in a[2]..=b[2] {
                for y in a[1]..=b[1] {
                    for x in a[0]..=b[0] {
                        let centre = self.origin + Vector3::new(x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5) * size;
                        let foot = crate::mesh::closest_on_segment(&centre, &s.a, &(s.a + s.axis));
                        if (centre - foot).norm() <= reach {
                            buckets.entry([x, y, z]).or_default().push(id as u32);
                        }
                    }
                }
            }
        }
        self.buckets = buckets;
    }

    /// `F` and its gradient at `p` from the segments `candidates` (sorted by component).
    fn evaluate(&self, candidates: &[u32], p: &Point3<f64>) -> (f64, Vector3<f64>) {
        let mut acc: Option<(f64, Vector3<f64>)> = None;
        let mut i = 0;
        while i < candidates.len() {
            let comp = self.segments[candidates[i] as usize].comp;
            let (mut nearest, mut value) = (candidates[i], f64::INFINITY);
            while i < candidates.len() && self.segments[candidates[i] as usize].comp == comp {
                let v = self.segments[candidates[i] as usize].value(p);
                if v < value {
                    (nearest, value) = (candidates[i], v);
                }
                i += 1;
            }
            let f = self.segments[nearest as usize].value_gradient(p);
            acc = Some(match acc {
                None => f,
                Some(a) => match blend_width(&self.zones[comp as usize], p) {
                    Some((k, grad_k)) => smooth_min_varying(a, f, k, &grad_k),
                    None if f.0 < a.0 => f,
                    None => a,
                },
            });
        }
        acc.unwrap_or((self.far, Vector3::zeros()))
    }

    /// `F` alone (as [`TreeLumen::evaluate`], without gradients).
    fn evaluate_value(&self, candidates: &[u32], p: &Point3<f64>) -> f64 {
        let mut acc: Option<f64> = None;
        let mut i = 0;
        while i < candidates.len() {
            let comp = self.segments[candidates[i] as usize].comp;
            let mut f = f64::INFINITY;
            while i < candidates.len() && self.segments[candidates[i] as usize].comp == comp {
                f = f.min(self.segments[candidates[i] as usize].value(p));
                i += 1;
            }
            acc = Some(match (acc, blend_width(&self.zones[comp as usize], p)) {
                (None, _) => f,
                (Some(a), Some((k, _))) => {
                    let h = if k > 0.0 { (k - (a - f).abs()).max(0.0) / k } else { 0.0 };
                    a.min(f) - k * h * h * h / 6.0
                }
                (Some(a), None) => a.min(f),
            });
        }
        acc.unwrap_or(self.far)
    }

    /// Smallest value of the tubes and balls of `candidates` at `p` (no blend), and the largest
    /// blend width of the zones among them.
    fn nearest_and_blend(&self, candidates: &[u32], p: &Point3<f64>) -> (f64, f64) {
        let mut nearest = f64::INFINITY;
        let mut blend: f64 = 0.0;
        for &c in candidates {
            let s = &self.segments[c as usize];
            nearest = nearest.min(s.value(p));
            for z in &self.zones[s.comp as usize] {
                blend = blend.max(z.k);
            }
        }
        (nearest, blend)
    }

    fn bucket_of(&self, p: &Point3<f64>) -> Option<&Vec<u32>> {
        let size = BRICK as f64 * self.h;
        let mut key = [0usize; 3];
        for k in 0..3 {
            let x = ((p[k] - self.origin[k]) / size).floor();
            if x < 0.0 {
                return None;
            }
            key[k] = x as usize;
        }
        self.buckets.get(&key)
    }

    /// The grid: every brick some segment's band reaches, sampled node by node unless a bound
    /// settles its sign with two cells to spare (so that no cell of a brick held as one value
    /// is crossed): inside when a tube's value at its centre is below minus 1.2 times its
    /// half-diagonal (`F` lies below each tube's value, which changes by at most 1.2 per unit
    /// length with its taper) and two cells; outside when the nearest tube's value there is
    /// above that plus half the largest blend width among them (three blends lower `F` by at
    /// most that) and two cells (a tube not in the brick's list is at least four cells away).
    pub fn sample_grid(&self) -> SampledGrid {
        let keys: Vec<[usize; 3]> = self.buckets.keys().copied().collect();
        let h = self.h;
        SampledGrid::sample(self.origin, h, self.cells, keys, self.far, |grid, key| {
            let candidates = &self.buckets[&key];
            let (centre, half) = grid.brick_centre(key);
            let (nearest, blend) = self.nearest_and_blend(candidates, &centre);
            if nearest < -1.2 * half - 2.0 * h {
                BrickValues::Uniform(-2.0 * h)
            } else if nearest > 1.2 * half + 0.5 * blend + 2.0 * h {
                BrickValues::Uniform(2.0 * h)
            } else {
                BrickValues::Nodes(grid.sample_brick_with(key, |p| self.evaluate_value(candidates, p)))
            }
        })
    }
}

impl ImplicitFunction for TreeLumen {
    fn value_gradient(&self, p: &Point3<f64>) -> (f64, Vector3<f64>) {
        match self.bucket_of(p) {
            Some(candidates) => self.evaluate(candidates, p),
            None => (self.far, Vector3::zeros()),
        }
    }

    fn step_cap(&self) -> f64 {
        self.h
    }
}

/// The blend width of a component's zones at `p` and its gradient: the widest zone's there
/// (`None` for a component without zones).
fn blend_width(zones: &[Zone], p: &Point3<f64>) -> Option<(f64, Vector3<f64>)> {
    let mut widths = zones.iter().map(|z| z.width(p));
    let first = widths.next()?;
    Some(widths.fold(first, |a, b| if b.0 > a.0 { b } else { a }))
}

/// Triangulates a lumen, cuts its ends, caps the capped ones, and checks the result against
/// `ends` and the genus it must have (0 for a tree, its number of independent loops for a
/// network).
pub fn mesh_lumen(f: &TreeLumen, ends: &[EndCircle], genus: i64) -> Result<TriangulatedSurface, SurfaceDefect> {
    let mut grid = f.sample_grid();
    let (mut vertices, mut triangles, flipped) = triangulate(f, &mut grid)?;
    let mut stats = SurfaceStats { grid: grid.cells, flipped, ..SurfaceStats::default() };
    for end in ends {
        triangles = clip_open_end(f, end, f.h, &mut vertices, triangles, &mut stats)?;
    }
    cap_ends(ends, &mut vertices, &mut triangles)?;
    let (vertices, triangles) = compact(vertices, triangles);
    let mut surface = TriangulatedSurface { vertices, triangles, stats };
    check_surface_of_genus(f, &mut surface, ends, genus)?;
    Ok(surface)
}
