//! A centerline's end bent to a junction centre that moved: the junction's own move
//! ([`super::junction_centre`]) and a merged junction's daughters ([`super::rooted`]) bend the
//! same way.

use crate::geometry::vector::smoothstep;
use nalgebra::{Point3, Vector3};

/// Length over which a branch bends to the moved centre, in multiples of the move (at least
/// twice the junction radius); a merged junction's daughters bend the same way.
pub(super) const BLEND_MOVES: f64 = 3.0;

/// Moves the points of a polyline within `blend` (arc length) of one end by a smoothly fading
/// share of `shift`, the end itself exactly by `shift`, and eases the radii towards `radius`
/// there. The other end never moves (the blend stops short of mid-line).
pub(super) fn bend_end(
    points: &mut [Point3<f64>],
    radii: &mut [f64],
    at_start: bool,
    shift: Vector3<f64>,
    radius: f64,
    blend: f64,
) {
    let n = points.len();
    let order: Vec<usize> = if at_start { (0..n).collect() } else { (0..n).rev().collect() };
    let total: f64 = points.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
    let blend = blend.min(0.5 * total);
    let end_radius = radii[order[0]];
    let mut s = 0.0;
    for (k, &i) in order.iter().enumerate() {
        if k > 0 {
            s += (points[i] - points[order[k - 1]]).norm();
        }
        if s >= blend || k == n - 1 {
            break;
        }
        let w = smoothstep(1.0 - s / blend);
        points[i] += shift * w;
        radii[i] += (radius - end_radius) * w;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bent_end_moves_exactly_and_the_far_end_stays() {
        let mut points: Vec<Point3<f64>> = (0..=20).map(|i| Point3::new(0.0, 0.0, i as f64)).collect();
        let mut radii = vec![1.0; points.len()];
        let far = points[20];
        let shift = Vector3::new(0.5, 0.0, 0.0);
        bend_end(&mut points, &mut radii, true, shift, 1.5, 6.0);
        assert_eq!(points[0], Point3::new(0.5, 0.0, 0.0));
        assert_eq!(radii[0], 1.5);
        assert_eq!(points[20], far);
        assert!(points[6..].iter().all(|p| p.x == 0.0));
        // The share of the move fades monotonically along the blend.
        assert!(points[..7].windows(2).all(|w| w[0].x >= w[1].x));
        bend_end(&mut points, &mut radii, false, -shift, 0.5, 6.0);
        assert_eq!(points[20], far - shift);
        assert_eq!(points[0], Point3::new(0.5, 0.0, 0.0));
    }
}
