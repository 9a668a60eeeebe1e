//! Centring a smoothed path on the ridge of the lumen's depth, section by section.
//!
//! The least-cost path through the medial balls follows the widest lumen, but where the depth
//! (distance to the wall) is nearly flat across a section, along a bend or where a section
//! flattens, the balls within a few per cent of the largest are all nearly as cheap, and which
//! one the path takes is set by the medial graph's edges, not by the lumen: on the tortuous ICA
//! (aneurisk_C0092) the path ran 0.17 r beside the deepest point of its normal sections over
//! 1.5 radii, the same wherever the surface was sampled (0.35 r to 0.2 r). Here each point is
//! moved, within its normal plane, to the deepest point near it: the centre of the largest ball
//! centred in that section, a definition that does not depend on the graph.
//!
//! Only where the section is the vessel's own: near a junction, a sac or an open end, the normal
//! plane runs into another vessel or out of the lumen, and its deepest point belongs to that.

use crate::geometry::surface::{Closest, LumenSurface};
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

/// A section is the vessel's own when, seen from the path, the lumen in the normal plane ends
/// within this many radii in every direction: a round section 1, an oval of 1.3:1 with the path
/// 0.15 r off its centre about 1.45; the plane through a junction or an open end reaches 2 or
/// more, or out of the lumen.
const OWN_SECTION_REACH: f64 = 1.6;
/// Directions sounded in the normal plane.
const RAYS: usize = 16;
/// No point moves farther than this fraction of its radius (a flat ridge is wider than the
/// path's own error, the next vessel is farther).
const MAX_SHIFT: f64 = 0.3;
/// The search in the plane starts with steps of this fraction of the radius ...
const FIRST_STEP: f64 = 0.04;
/// ... halved until this fraction.
const LAST_STEP: f64 = 0.005;
/// The deepest point is looked for at every this many path points (0.4 r apart, the shift
/// varies over a radius or more); the shifts in between are interpolated.
const EVERY: usize = 4;
/// Moves and step halvings of one search, at most (about 15 are needed).
const MAX_MOVES: usize = 100;

/// The shift of each of `points` (arc length `s`, tangents from their neighbours) to the deepest
/// point of its normal section: zero where the section is not the vessel's own, ramped in over
/// a radius from either end of the path, whose end points stay put (branch nodes and vessel
/// ends, shared with other paths or fixed by the end).
pub fn ridge_shifts(points: &[Point3<f64>], s: &[f64], lumen: &LumenSurface) -> Vec<Vector3<f64>> {
    let n = points.len();
    if n < 3 {
        return vec![Vector3::zeros(); n];
    }
    let length = s[n - 1];
    let keys: Vec<usize> = (1..n - 1).step_by(EVERY).chain([n - 1]).collect();
    let key_shifts: Vec<Vector3<f64>> = keys
        .par_iter()
        .map(|&i| {
            if i + 1 >= n {
                return Vector3::zeros();
            }
            let tangent = points[i + 1] - points[i - 1];
            let wall = lumen.closest(&points[i]);
            let radius = wall.distance;
            if !(radius > 0.0 && radius.is_finite()) {
                return Vector3::zeros();
            }
            let ramp = (s[i].min(length - s[i]) / radius).min(1.0);
            deepest_in_section(&points[i], &tangent, &wall, lumen) * ramp
        })
        .collect();
    interpolate(&keys, &key_shifts, s)
}

/// The shifts at every point, linear in arc length between the key points' (zero at the first).
fn interpolate(keys: &[usize], key_shifts: &[Vector3<f64>], s: &[f64]) -> Vec<Vector3<f64>> {
    let mut shifts = vec![Vector3::zeros(); s.len()];
    let (mut from, mut from_shift) = (0, Vector3::zeros());
    for (&to, &to_shift) in keys.iter().zip(key_shifts) {
        for i in from..=to {
            let w = if s[to] > s[from] { (s[i] - s[from]) / (s[to] - s[from]) } else { 1.0 };
            shifts[i] = from_shift * (1.0 - w) + to_shift * w;
        }
        (from, from_shift) = (to, to_shift);
    }
    shifts
}

/// From `p` (its nearest wall point `near`, at a positive depth) to the deepest point of its
/// section normal to `tangent`, within [`MAX_SHIFT`] radii; zero when the section is not the
/// vessel's own. A pattern search: the depth is not smooth on the ridge (a cone's apex in a
/// round section), where gradient steps would zig-zag.
fn deepest_in_section(p: &Point3<f64>, tangent: &Vector3<f64>, near: &Closest, lumen: &LumenSurface) -> Vector3<f64> {
    let radius = near.distance;
    let Some(t) = tangent.try_normalize(0.0) else { return Vector3::zeros() };
    let e1 = crate::geometry::vector::any_perpendicular(&t);
    let e2 = t.cross(&e1);
    let direction = |k: usize| {
        let a = std::f64::consts::TAU * k as f64 / RAYS as f64;
        e1 * a.cos() + e2 * a.sin()
    };
    let own_section = (0..RAYS).all(|k| lumen.first_hit(p, &direction(k), OWN_SECTION_REACH * radius).is_some());
    if !own_section {
        return Vector3::zeros();
    }
    // The depth and the direction away from the nearest wall point, the depth's gradient where
    // it is smooth and one side of its ridge where it is not; and that wall point, near which a
    // trial a step away finds its own (the same point, found faster: see `closest_near`).
    let away_from = |q: Point3<f64>, near: &Closest| (q - near.point) / near.distance.max(f64::MIN_POSITIVE);
    let sound = |shift: Vector3<f64>, wall: &Point3<f64>| {
        let q = p + shift;
        let near = lumen.closest_near(&q, wall);
        (near.distance, away_from(q, &near), shift, near.point)
    };
    let (mut deepest, mut away, mut at, mut wall) = (radius, away_from(*p, near), Vector3::zeros(), near.point);
    let mut step = FIRST_STEP * radius;
    // Every move deepens; the cap only bounds the work on a pathological surface.
    for _ in 0..MAX_MOVES {
        if step < LAST_STEP * radius {
            break;
        }
        // The depth is semiconcave: a step of length h against `away` by more than h / radius
        // (the wall's bend within the lumen) cannot deepen, so it is not sounded.
        let ahead = |u: &Vector3<f64>| u.dot(&away) >= -step / radius;
        let best = (0..RAYS)
            .map(direction)
            .filter(ahead)
            .map(|u| at + u * step)
            .filter(|c| c.norm() <= MAX_SHIFT * radius)
            .map(|c| sound(c, &wall))
            .max_by(|a, b| a.0.total_cmp(&b.0));
        match best {
            Some((d, u, c, w)) if d > deepest => (deepest, away, at, wall) = (d, u, c, w),
            _ => step *= 0.5,
        }
    }
    at
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An open tube along z, 20 long, of elliptic section (semi-axes `a` along x, `b` along y).
    fn elliptic_tube(a: f64, b: f64) -> LumenSurface {
        let (around, along) = (96, 80);
        let vertices = (0..=along)
            .flat_map(|j| {
                (0..around).map(move |i| {
                    let phi = std::f64::consts::TAU * i as f64 / around as f64;
                    Point3::new(a * phi.cos(), b * phi.sin(), 20.0 * j as f64 / along as f64)
                })
            })
            .collect();
        let at = |i: usize, j: usize| (j * around + i % around) as u32;
        let triangles = (0..along)
            .flat_map(|j| {
                (0..around).flat_map(move |i| {
                    [[at(i, j), at(i + 1, j), at(i + 1, j + 1)], [at(i, j), at(i + 1, j + 1), at(i, j + 1)]]
                })
            })
            .collect();
        LumenSurface::from_parts(vertices, triangles, Default::default()).unwrap()
    }

    /// A straight path along the tube, `off` from its axis, at the spacing of the extraction.
    fn path(off: Vector3<f64>) -> (Vec<Point3<f64>>, Vec<f64>) {
        let s: Vec<f64> = (0..=200).map(|k| 0.1 * k as f64).collect();
        (s.iter().map(|&z| Point3::new(0.0, 0.0, z) + off).collect(), s)
    }

    #[test]
    fn an_oval_sections_path_moves_to_its_centre_and_its_ends_stay() {
        // An oval of 1.3 : 1: the depth's ridge is flat along x (its medial segment), steep along
        // y; the path lies along the ridge, a little off it, as the medial graph's does.
        let lumen = elliptic_tube(1.3, 1.0);
        let off = Vector3::new(0.15, 0.05, 0.0);
        let (points, s) = path(off);
        let shifts = ridge_shifts(&points, &s, &lumen);
        for (k, (p, d)) in points.iter().zip(&shifts).enumerate() {
            if s[k] > 2.0 && s[k] < 18.0 {
                let moved = p + d;
                assert!(moved.x.hypot(moved.y) < 0.03, "at z {:.1}: moved to {moved:?}", s[k]);
            }
        }
        assert_eq!(shifts[0], Vector3::zeros());
        assert_eq!(shifts[shifts.len() - 1], Vector3::zeros());
    }

    #[test]
    fn a_section_reaching_beyond_the_vessel_is_left_alone() {
        // 2.5 : 1, as the plane through a junction: it reaches 2.5 radii from the path.
        let lumen = elliptic_tube(2.5, 1.0);
        let (points, s) = path(Vector3::new(0.0, 0.15, 0.0));
        assert!(ridge_shifts(&points, &s, &lumen).iter().all(|d| *d == Vector3::zeros()));
    }
}
