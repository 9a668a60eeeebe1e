//! The lumen surface: its triangles as read ([`TriangleSurface`]) and the geometric queries on
//! them ([`LumenSurface`]): first ray hit and exact closest point, both through parry's
//! bounding-volume hierarchy in double precision.
//!
//! The meshing algorithms only see [`LumenSurface`]; parry's types stay in this file.

use crate::data::error::{Error, Result};
use crate::geometry::vector::any_perpendicular;
use crate::geometry::winding::WindingTree;
use nalgebra::{Point3, Vector3};
use parry3d_f64::math::Vector as PVec;
use parry3d_f64::query::PointQuery;
use parry3d_f64::query::Ray;
use parry3d_f64::shape::{CompositeShapeRef, TriMesh, TriMeshFlags};
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Mutex, OnceLock};

/// A triangulated lumen surface, lengths in millimetres.
#[derive(Debug, Clone)]
pub struct TriangleSurface {
    pub vertices: Vec<Point3<f64>>,
    /// Triangles as 0-based vertex indices (polygons with more than three points are fanned).
    pub triangles: Vec<[u32; 3]>,
    /// Per-triangle integer tag when the file carries one (e.g. SimVascular's `ModelFaceID`).
    pub triangle_tags: Option<(String, Vec<i64>)>,
    /// The file it came from (for messages).
    pub source: PathBuf,
}

/// Where a ray meets the surface.
#[derive(Debug, Clone, Copy)]
pub struct RayHit {
    pub point: Point3<f64>,
    /// Distance from the ray origin.
    pub distance: f64,
    pub triangle: u32,
}

/// The closest point of the surface to a query point.
#[derive(Debug, Clone, Copy)]
pub struct Closest {
    pub point: Point3<f64>,
    pub distance: f64,
    pub triangle: u32,
}

/// A triangulated surface ready for queries.
pub struct LumenSurface {
    trimesh: TriMesh,
    pub vertices: Vec<Point3<f64>>,
    pub triangles: Vec<[u32; 3]>,
    /// Unit normal of each triangle, as wound in the file (may face in or out).
    pub normals: Vec<Vector3<f64>>,
    pub source: PathBuf,
    /// The winding numbers computed so far, by point (its coordinates' bits): a vessel meshed
    /// again another way (the pipeline's retries) is probed at the same centerline points again.
    windings: Mutex<HashMap<[u64; 3], f64>>,
    /// The triangles' cluster tree for winding numbers, built when one is first asked.
    winding_tree: OnceLock<WindingTree>,
}

/// Relative (and, times the coordinates' size, absolute) slack of [`LumenSurface::closest_near`]'s
/// bound over the distance to its point on the surface: far above the rounding of a projected
/// point (a point on a triangle may lie 1e-16 of its coordinates off it), far below any step.
const NEAR_MARGIN: f64 = 1e-6;

fn to_p(v: &Point3<f64>) -> PVec {
    PVec::new(v.x, v.y, v.z)
}
fn to_pv(v: &Vector3<f64>) -> PVec {
    PVec::new(v.x, v.y, v.z)
}

impl LumenSurface {
    pub fn new(surface: &TriangleSurface) -> Result<Self> {
        Self::from_parts(surface.vertices.clone(), surface.triangles.clone(), surface.source.clone())
    }

    pub fn from_parts(vertices: Vec<Point3<f64>>, triangles: Vec<[u32; 3]>, source: PathBuf) -> Result<Self> {
        if triangles.is_empty() {
            return Err(Error::input(&source, "the surface has no triangles"));
        }
        let normals = triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| vertices[i as usize]);
                let n = (b - a).cross(&(c - a));
                let len = n.norm();
                if len > 0.0 {
                    n / len
                } else {
                    Vector3::zeros()
                }
            })
            .collect();
        let pv = vertices.iter().map(to_p).collect();
        let trimesh = TriMesh::new(pv, triangles.clone())
            .map_err(|e| Error::input(&source, format!("cannot index the surface triangles: {e:?}")))?;
        Ok(LumenSurface {
            trimesh,
            vertices,
            triangles,
            normals,
            source,
            windings: Mutex::default(),
            winding_tree: OnceLock::new(),
        })
    }

    /// The first intersection of the ray `origin + t dir` (|dir| = 1) with the surface for
    /// 0 <= t <= max_distance.
    ///
    /// A ray through a shared edge or vertex can slip between the triangles' individual tests
    /// (seen on watertight fixtures with rays along their vertex rings), so a miss is retried
    /// from origins shifted sideways by a nanometre-scale amount, far below any real hole.
    pub fn first_hit(&self, origin: &Point3<f64>, dir: &Vector3<f64>, max_distance: f64) -> Option<RayHit> {
        self.cast(origin, dir, max_distance).or_else(|| {
            let u = any_perpendicular(dir);
            let v = dir.cross(&u);
            let eps = 1e-9 * max_distance.max(1.0);
            [u, v, -u, -v].iter().find_map(|side| self.cast(&(origin + side * eps), dir, max_distance))
        })
    }

    fn cast(&self, origin: &Point3<f64>, dir: &Vector3<f64>, max_distance: f64) -> Option<RayHit> {
        let ray = Ray::new(to_p(origin), to_pv(dir));
        let (tri, hit) = CompositeShapeRef(&self.trimesh).cast_local_ray_and_get_normal(&ray, max_distance, false)?;
        Some(RayHit { point: origin + dir * hit.time_of_impact, distance: hit.time_of_impact, triangle: tri })
    }

    /// Exact closest point on the triangles (not the nearest vertex).
    pub fn closest(&self, p: &Point3<f64>) -> Closest {
        let q = to_p(p);
        match CompositeShapeRef(&self.trimesh).project_local_point_and_get_feature(q, f64::MAX) {
            Some((tri, proj, _)) => {
                let c = Point3::new(proj.point.x, proj.point.y, proj.point.z);
                Closest { point: c, distance: (c - p).norm(), triangle: tri }
            }
            None => Closest { point: *p, distance: f64::INFINITY, triangle: u32::MAX },
        }
    }

    /// [`Self::closest`] for a point `p` moved from `near`, a point on (or close to) the
    /// surface: the same answer, found faster. The search starts bounded by the distance to
    /// `near` (a little more), which the closest point cannot exceed, so the bounding-volume
    /// hierarchy skips every box farther away from the start instead of narrowing down from
    /// the first triangle it reaches. The traversal visits the boxes nearer than the bound in
    /// the same order as the unbounded one (its best-so-far below the bound is the same at every
    /// step), so the triangle found, ties included, is the same; when no triangle lies within
    /// the bound (`near` off the surface), the unbounded search answers.
    pub fn closest_near(&self, p: &Point3<f64>, near: &Point3<f64>) -> Closest {
        let bound = (p - near).norm();
        let reach = bound * (1.0 + NEAR_MARGIN) + NEAR_MARGIN * (1.0 + near.coords.amax());
        let q = to_p(p);
        match CompositeShapeRef(&self.trimesh).project_local_point_and_get_feature(q, reach) {
            Some((tri, proj, _)) => {
                let c = Point3::new(proj.point.x, proj.point.y, proj.point.z);
                Closest { point: c, distance: (c - p).norm(), triangle: tri }
            }
            None => self.closest(p),
        }
    }

    /// Generalised winding number of the surface around `p` (Jacobson et al. 2013): the sum of
    /// the triangles' signed solid angles over 4 pi. About +1 inside a closed surface whose
    /// normals face out, -1 if they face in, 0 outside; an open tube seen from its axis gives
    /// nearly +-1 away from its open ends. Robust to small holes and stray triangles, unlike ray
    /// parity.
    pub fn winding_number(&self, p: &Point3<f64>) -> f64 {
        let key = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
        let known = self.windings.lock().ok().and_then(|w| w.get(&key).copied());
        known.unwrap_or_else(|| {
            let w = self.winding_number_of(p);
            if let Ok(mut windings) = self.windings.lock() {
                windings.insert(key, w);
            }
            w
        })
    }

    /// [`Self::winding_number`] computed (see [`crate::geometry::winding`]): the same value
    /// whenever asked.
    fn winding_number_of(&self, p: &Point3<f64>) -> f64 {
        let tree = self.winding_tree.get_or_init(|| WindingTree::new(&self.vertices, &self.triangles));
        tree.winding_number(&self.vertices, &self.triangles, p)
    }

    /// The triangles that may cross the plane through `centre` normal to `normal` (unit) within
    /// the box of half-width `reach` about `centre`: those whose bounding boxes meet both, in
    /// increasing order.
    pub fn triangles_near_plane(&self, centre: &Point3<f64>, normal: &Vector3<f64>, reach: f64) -> Vec<u32> {
        let (lo, hi) = (centre.coords.add_scalar(-reach), centre.coords.add_scalar(reach));
        let meets = |mins: PVec, maxs: PVec| {
            let inside_box = (0..3).all(|k| mins[k] <= hi[k] && maxs[k] >= lo[k]);
            // The box's extent along the normal against its centre's distance from the plane.
            let half: f64 = (0..3).map(|k| 0.5 * (maxs[k] - mins[k]) * normal[k].abs()).sum();
            let mid: f64 = (0..3).map(|k| (0.5 * (maxs[k] + mins[k]) - centre[k]) * normal[k]).sum();
            inside_box && mid.abs() <= half
        };
        let mut found: Vec<u32> = self.trimesh.bvh().leaves(|node| meets(node.mins(), node.maxs())).collect();
        found.sort_unstable();
        found
    }

    /// Axis-aligned bounding box (min, max).
    pub fn bounding_box(&self) -> (Point3<f64>, Point3<f64>) {
        let mut lo = Point3::from([f64::INFINITY; 3]);
        let mut hi = Point3::from([f64::NEG_INFINITY; 3]);
        for v in &self.vertices {
            for k in 0..3 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
        (lo, hi)
    }
}

/// A closed surface whose triangles face out, for inside tests: a point is inside when it lies
/// behind the angle-weighted pseudo-normal of its closest feature (Baerentzen and Aanaes 2005),
/// exact for a watertight, consistently oriented surface and local everywhere else (a defect
/// only misleads the points whose closest feature it is).
pub struct SolidSurface {
    trimesh: TriMesh,
}

impl SolidSurface {
    /// `triangles` must close the surface and face out of the enclosed volume.
    pub fn new(vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> Option<SolidSurface> {
        let pv = vertices.iter().map(to_p).collect();
        let trimesh = TriMesh::with_flags(pv, triangles.to_vec(), TriMeshFlags::ORIENTED).ok()?;
        Some(SolidSurface { trimesh })
    }

    /// The distance from `p` to the surface when `p` lies inside it.
    pub fn depth(&self, p: &Point3<f64>) -> Option<f64> {
        self.depth_within(p, f64::MAX)
    }

    /// [`SolidSurface::depth`] for a point known to lie within `reach` of the surface (a bound
    /// that lets the search skip every triangle farther away; `None` also when it does not).
    pub fn depth_within(&self, p: &Point3<f64>, reach: f64) -> Option<f64> {
        let q = to_p(p);
        let proj = self.trimesh.project_local_point_with_max_dist(q, false, reach)?;
        let d = (proj.point - q).length();
        proj.is_inside.then_some(d)
    }
}

/// Exact distance from a point to a triangle (Eberly's region classification), used where a
/// query is against a handful of triangles and a BVH would be overkill, and by tests as an
/// oracle independent of parry.
pub fn point_triangle_distance(p: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>, c: &Point3<f64>) -> f64 {
    (closest_point_on_triangle(p, a, b, c) - p).norm()
}

/// Closest point of triangle abc to p (Ericson, Real-Time Collision Detection, 5.1.5).
pub fn closest_point_on_triangle(p: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>, c: &Point3<f64>) -> Point3<f64> {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return *a;
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return *b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return *c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn octahedron() -> LumenSurface {
        let v = vec![
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(-1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, -1.0, 0.0),
            Point3::new(0.0, 0.0, 1.0),
            Point3::new(0.0, 0.0, -1.0),
        ];
        let t = vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
        LumenSurface::from_parts(v, t, "octahedron".into()).unwrap()
    }

    #[test]
    fn ray_from_inside_hits_the_face_it_points_at() {
        let s = octahedron();
        let d = Vector3::new(1.0, 1.0, 1.0).normalize();
        let h = s.first_hit(&Point3::origin(), &d, 10.0).unwrap();
        // plane x + y + z = 1
        assert!((h.point.x + h.point.y + h.point.z - 1.0).abs() < 1e-14);
        assert_eq!(h.triangle, 0);
        assert!(s.first_hit(&Point3::new(5.0, 5.0, 5.0), &d, 10.0).is_none());
    }

    #[test]
    fn winding_number_tells_inside_outside_and_orientation() {
        let s = octahedron();
        assert!((s.winding_number(&Point3::new(0.1, 0.2, -0.1)) - 1.0).abs() < 1e-12);
        assert!(s.winding_number(&Point3::new(2.0, 0.0, 0.0)).abs() < 1e-12);
        let flipped: Vec<[u32; 3]> = s.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect();
        let f = LumenSurface::from_parts(s.vertices.clone(), flipped, "flipped".into()).unwrap();
        assert!((f.winding_number(&Point3::origin()) + 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_winding_number_asked_again_is_the_one_computed() {
        let s = octahedron();
        let points = [Point3::new(0.1, 0.2, -0.1), Point3::new(2.0, 0.0, 0.0), Point3::new(0.3, -0.2, 0.25)];
        let first: Vec<f64> = points.iter().map(|p| s.winding_number(p)).collect();
        assert_eq!(s.windings.lock().unwrap().len(), points.len());
        for (p, w) in points.iter().zip(&first) {
            assert_eq!(s.winding_number(p).to_bits(), w.to_bits());
            assert_eq!(s.winding_number_of(p).to_bits(), w.to_bits());
        }
        assert_eq!(s.windings.lock().unwrap().len(), points.len());
    }

    #[test]
    fn closest_point_agrees_with_brute_force() {
        let s = octahedron();
        for p in [Point3::new(0.3, 0.2, 0.1), Point3::new(2.0, -1.0, 0.5), Point3::new(0.0, 0.0, 3.0)] {
            let brute = s
                .triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| s.vertices[i as usize]);
                    point_triangle_distance(&p, &a, &b, &c)
                })
                .fold(f64::INFINITY, f64::min);
            assert!((s.closest(&p).distance - brute).abs() < 1e-12);
        }
    }

    /// Searched from a nearby point on the surface (or one off it), the closest point is the
    /// unbounded search's, to the bit and with the same triangle: on a tube whose points often
    /// project onto a shared edge or vertex (ties between triangles).
    #[test]
    fn closest_near_is_the_closest_point_to_the_bit() {
        let s = LumenSurface::new(&crate::testing::straight_tube_surface(2.0, 20.0, 48, 20)).unwrap();
        let mut checked = 0;
        for k in 0..400 {
            let t = k as f64 * 0.618_034;
            let p = Point3::new(2.3 * t.cos(), 2.1 * (1.7 * t).sin(), (k % 23) as f64 * 0.9 - 0.5);
            let exact = s.closest(&p);
            let vertex = s.vertices[(k * 7) % s.vertices.len()];
            let steps = [0.0, 0.01, 0.3, 5.0];
            for near in steps.iter().map(|&d| exact.point + Vector3::new(d, -0.5 * d, 0.2 * d)).chain([vertex, p]) {
                let found = s.closest_near(&p, &near);
                assert_eq!(found.triangle, exact.triangle, "point {p:?} from {near:?}");
                assert_eq!(found.point.coords.map(f64::to_bits), exact.point.coords.map(f64::to_bits));
                assert_eq!(found.distance.to_bits(), exact.distance.to_bits());
                checked += 1;
            }
        }
        assert_eq!(checked, 2400);
    }
}
