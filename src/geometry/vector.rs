//! Small vector and interpolation helpers shared by the geometry and the stages.

use nalgebra::Vector3;

/// Smooth step from 0 to 1 over [0, 1] (zero slope at both ends), 0 before and 1 after.
pub fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
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
