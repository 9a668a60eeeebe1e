//! Annotation of the volume mesh: per element triads, collagen fibres and quality.
//!
//! Triads follow De Santis et al. 2011: directions from the centres of opposite faces. The
//! radial direction joins the inner face (S6) to the outer face (S4); the longitudinal one
//! joins the upstream face (S1) to the downstream face (S2), made orthogonal to the radial one;
//! the circumferential one completes the right-handed triad, e_circ = e_long x e_rad, so that
//! e_circ x e_long = e_rad. Fibres lie in the circumferential-longitudinal plane at +-beta from
//! e_circ (Holzapfel, Gasser, Ogden 2000): cos(beta) e_circ +- sin(beta) e_long.

use crate::geometry::mesh::{
    face_centre, ElementQuality, Region, Triad, VesselMesh, FACE_DOWNSTREAM, FACE_INNER, FACE_OUTER, FACE_UPSTREAM,
};
use crate::geometry::quality::element_quality;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

/// The triad of an element from its corners.
pub fn element_triad(c: &[Point3<f64>; 8]) -> Triad {
    let e_rad = (face_centre(c, FACE_OUTER) - face_centre(c, FACE_INNER)).normalize();
    let l = face_centre(c, FACE_DOWNSTREAM) - face_centre(c, FACE_UPSTREAM);
    let e_long = (l - e_rad * l.dot(&e_rad)).normalize();
    let e_circ = e_long.cross(&e_rad);
    Triad { e_circ, e_long, e_rad }
}

/// The two fibre families at +-beta (degrees) from circumferential.
pub fn fibre_directions(t: &Triad, beta_deg: f64) -> [Vector3<f64>; 2] {
    let (s, c) = beta_deg.to_radians().sin_cos();
    [t.e_circ * c + t.e_long * s, t.e_circ * c - t.e_long * s]
}

/// Fills triads, fibres and quality of every element.
pub fn annotate(mesh: &mut VesselMesh) {
    let beta = |r: Region| mesh.layers.iter().find(|l| l.region == r).map(|l| l.fibre_angle_deg);
    let betas: Vec<Option<f64>> = Region::ALL.iter().map(|r| beta(*r)).collect();
    // Filled in place: no per-element tuples copied into the three arrays afterwards.
    let n = mesh.hexes.len();
    let zero = Vector3::zeros();
    let mut triads = vec![Triad { e_circ: zero, e_long: zero, e_rad: zero }; n];
    let mut fibres = vec![[zero; 2]; n];
    let mut quality = vec![ElementQuality::default(); n];
    let m = &*mesh;
    triads.par_iter_mut().zip(fibres.par_iter_mut()).zip(quality.par_iter_mut()).enumerate().for_each(
        |(e, ((triad, fibre), q))| {
            let c = m.corners(e);
            *triad = element_triad(&c);
            if let (true, Some(&Some(b))) = (m.regions[e].is_wall(), betas.get(m.regions[e] as usize)) {
                *fibre = fibre_directions(triad, b);
            }
            *q = element_quality(&c);
        },
    );
    mesh.triads = triads;
    mesh.fibres = fibres;
    mesh.quality = quality;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triad_of_a_unit_cube_and_fibres_at_beta() {
        let c = crate::geometry::mesh::unit_cube();
        let t = element_triad(&c);
        assert!((t.e_rad - Vector3::x()).norm() < 1e-12);
        assert!((t.e_long - Vector3::z()).norm() < 1e-12);
        assert!((t.e_circ - Vector3::y()).norm() < 1e-12);
        assert!((t.e_circ.cross(&t.e_long) - t.e_rad).norm() < 1e-12);
        let f = fibre_directions(&t, 30.0);
        assert!((f[0].dot(&t.e_circ) - 30f64.to_radians().cos()).abs() < 1e-12);
        assert!((f[1].dot(&t.e_long) + 0.5).abs() < 1e-12);
        assert!(f[0].dot(&t.e_rad).abs() < 1e-15);
    }
}
