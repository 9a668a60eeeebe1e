//! The 3D Delaunay tessellation of a point set, by Qhull's reentrant C library (vendor/qhull_r,
//! compiled by build.rs with the `cc` crate) through a shim of our own (csrc/delaunay.c) that
//! runs the whole tessellation under Qhull's setjmp error handling and hands back plain arrays.
//! Nothing is written to a file or to the terminal: Qhull's messages are kept in memory and come
//! back in the error.
//!
//! Qhull runs with 'QJ', which joggles the input by a tiny deterministic amount (Qhull's fixed
//! seed): sections of cospherical points (every ring of a straight tube's vertices) then give
//! proper tetrahedra linked across each ring, where 'Qt' would leave flat ones that break the
//! chain. The options and the order the tetrahedra are read in are those the `qhull` crate used
//! before (csrc/delaunay.c says which), so the centerlines did not change by a bit.

use nalgebra::{Point3, Vector3};
use std::ffi::{c_char, c_int, CStr};

/// The Delaunay tetrahedra of a point set: corner indices and, per tetrahedron, the
/// tetrahedra it shares a face with.
pub struct Delaunay {
    pub tets: Vec<[u32; 4]>,
    pub adjacent: Vec<Vec<u32>>,
}

/// The shim's result (`vh_tessellation` in csrc/delaunay.c): `count` tetrahedra of four corners
/// and four neighbours each (-1: no tetrahedron across that face), or a message.
#[repr(C)]
struct Tessellation {
    corners: *mut i32,
    neighbours: *mut i32,
    count: usize,
    message: *mut c_char,
}

extern "C" {
    /// The lower hull of `count` points lifted to 4D (x, y, z, w): 0, or non-zero with `message`.
    fn vh_delaunay(lifted: *mut f64, count: i32, out: *mut Tessellation) -> c_int;
    /// Frees what `vh_delaunay` allocated in `out`, on success or failure.
    fn vh_tessellation_free(out: *mut Tessellation);
}

/// The Delaunay tetrahedralisation of `points` (at least five, not all coplanar); `Err` with
/// Qhull's own words when it cannot be built.
pub fn delaunay(points: &[Point3<f64>]) -> Result<Delaunay, String> {
    let count = i32::try_from(points.len()).map_err(|_| format!("{} points: too many for Qhull", points.len()))?;
    let mut lifted = lift(points);
    let mut out = Tessellation {
        corners: std::ptr::null_mut(),
        neighbours: std::ptr::null_mut(),
        count: 0,
        message: std::ptr::null_mut(),
    };
    // SAFETY: `lifted` holds `count` points of four coordinates and outlives the call; `out` is
    // filled by the shim and freed below by the shim's own function, once.
    let failed = unsafe { vh_delaunay(lifted.as_mut_ptr(), count, &mut out) } != 0;
    let result = if failed {
        let said = if out.message.is_null() {
            "no message".to_string()
        } else {
            // SAFETY: the shim sets a NUL-terminated message (or none) on failure.
            let text = unsafe { CStr::from_ptr(out.message) }.to_string_lossy();
            // Qhull's first line says what went wrong; the rest lists its options and state.
            text.lines().map(str::trim).find(|l| !l.is_empty()).unwrap_or("no message").to_string()
        };
        Err(format!("Qhull could not tessellate the surface points: {said}"))
    } else {
        // SAFETY: on success the shim sets `count` tetrahedra of four corners and neighbours.
        let (corners, neighbours) = unsafe {
            (
                std::slice::from_raw_parts(out.corners, 4 * out.count),
                std::slice::from_raw_parts(out.neighbours, 4 * out.count),
            )
        };
        let tets = corners.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]].map(|i| i as u32)).collect();
        let adjacent =
            neighbours.chunks_exact(4).map(|n| n.iter().filter(|&&t| t >= 0).map(|&t| t as u32).collect()).collect();
        Ok(Delaunay { tets, adjacent })
    };
    // SAFETY: `out` came from vh_delaunay and is freed once.
    unsafe { vh_tessellation_free(&mut out) };
    result
}

/// The points lifted to the paraboloid w = |x|^2, whose lower convex hull projects to the
/// Delaunay tessellation (Qhull's 'd'); centred on their centroid and scaled uniformly (a
/// non-uniform scale would change the tessellation), so that the lift stays well conditioned
/// for vessels far from the origin.
fn lift(points: &[Point3<f64>]) -> Vec<f64> {
    let n = points.len().max(1) as f64;
    let centroid = points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let scale = points.iter().map(|p| (p.coords - centroid).amax()).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    points
        .iter()
        .flat_map(|p| {
            let q = (p.coords - centroid) / scale;
            [q.x, q.y, q.z, q.norm_squared()]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    /// Points of a small deterministic pseudo-random cloud in the unit cube, far from the origin
    /// (as a vessel in scanner coordinates is).
    fn cloud(n: usize, seed: u64) -> Vec<Point3<f64>> {
        let mut state = seed;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..n).map(|_| Point3::new(100.0 + next(), -50.0 + next(), 20.0 + next())).collect()
    }

    fn volume(p: [Point3<f64>; 4]) -> f64 {
        (p[1] - p[0]).dot(&(p[2] - p[0]).cross(&(p[3] - p[0]))) / 6.0
    }

    #[test]
    fn tetrahedra_fill_the_hull_with_empty_circumspheres_and_neighbours_share_faces() {
        let points = cloud(300, 7);
        let dt = delaunay(&points).unwrap();
        assert!(dt.tets.len() > points.len(), "{} tetrahedra", dt.tets.len());
        for (t, corners) in dt.tets.iter().enumerate() {
            let p = corners.map(|i| points[i as usize]);
            assert!(volume(p).abs() > 1e-12, "tetrahedron {t} is flat");
            // The circumsphere holds no other point (up to the joggle, ~1e-11 of the extent).
            let (u, v, w) = (p[1] - p[0], p[2] - p[0], p[3] - p[0]);
            let num = v.cross(&w) * u.norm_squared() + w.cross(&u) * v.norm_squared() + u.cross(&v) * w.norm_squared();
            let centre = p[0] + num / (2.0 * u.dot(&v.cross(&w)));
            let radius = (centre - p[0]).norm();
            let inside = points.iter().filter(|q| (*q - centre).norm() < radius * (1.0 - 1e-6)).count();
            assert_eq!(inside, 0, "tetrahedron {t}: {inside} points inside its circumsphere");
            for &u in &dt.adjacent[t] {
                assert!(dt.adjacent[u as usize].contains(&(t as u32)), "{t} -> {u} but not back");
                let shared = corners.iter().filter(|c| dt.tets[u as usize].contains(c)).count();
                assert_eq!(shared, 3, "tetrahedra {t} and {u} share {shared} corners");
            }
        }
        // Together they fill the convex hull: every point is a corner, and the total volume is
        // that of the hull of the cloud (bounded by its box).
        let total: f64 = dt.tets.iter().map(|c| volume(c.map(|i| points[i as usize])).abs()).sum();
        assert!(total > 0.5 && total < 1.0, "total volume {total}");
        let mut used = vec![false; points.len()];
        dt.tets.iter().flatten().for_each(|&i| used[i as usize] = true);
        assert!(used.iter().all(|&u| u), "a point is no tetrahedron's corner");
    }

    #[test]
    fn parallel_runs_give_the_same_tetrahedra() {
        let points = cloud(500, 11);
        let first = delaunay(&points).unwrap();
        let runs: Vec<Delaunay> = (0..8).into_par_iter().map(|_| delaunay(&points).unwrap()).collect();
        for run in runs {
            assert_eq!(run.tets, first.tets);
            assert_eq!(run.adjacent, first.adjacent);
        }
    }

    #[test]
    fn too_few_points_are_an_error_in_qhulls_words_not_a_panic() {
        // Four points lift to four in 4D: too few for the hull's first simplex (five).
        let points = cloud(4, 3);
        let err = delaunay(&points).err().expect("four points have no lower hull in 4D");
        assert!(err.starts_with("Qhull could not tessellate the surface points: QH6214"), "{err}");
        assert!(!err.contains('\n'), "one line: {err}");
    }
}
