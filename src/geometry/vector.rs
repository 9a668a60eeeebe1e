//! Small vector helpers shared by the geometry and the stages.

use nalgebra::Vector3;

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
