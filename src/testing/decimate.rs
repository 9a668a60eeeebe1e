//! Quadric-error edge collapse (Garland & Heckbert, "Surface simplification using quadric error
//! metrics", SIGGRAPH 1997): what mesh tools do when a user asks for fewer triangles, so the
//! mutation suite can write a vessel as such a tool would. Each vertex carries the sum of the
//! squared distances to its triangles' planes (area-weighted) and, on an open boundary, to
//! planes through the boundary edges across the surface (heavily weighted, so open ends keep
//! their rims); the cheapest edge is collapsed to the point of least error, unless the collapse
//! would pinch the surface (the link condition), join two boundaries, or turn a triangle over.
//!
//! No maintained crate does this with Rust alone (the well-kept simplifiers are C++), and test
//! support does not justify a C++ build; this is the textbook algorithm, short.

use nalgebra::{Matrix3, Matrix4, Point3, Vector3, Vector4};
use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};

/// A boundary edge's plane counts this many times a triangle's of the same size.
const BOUNDARY_WEIGHT: f64 = 1e3;
/// A collapse may turn no remaining triangle by more than this (cosine of about 78 degrees).
const MIN_NORMAL_COS: f64 = 0.2;

/// A candidate collapse: its error, its edge and the versions of its vertices when it was
/// costed (a stale entry is skipped). The least error pops first, ties by edge.
struct Candidate {
    cost: f64,
    edge: (u32, u32),
    versions: (u32, u32),
}

impl PartialEq for Candidate {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Candidate {}
impl Ord for Candidate {
    fn cmp(&self, o: &Self) -> Ordering {
        o.cost.total_cmp(&self.cost).then(o.edge.cmp(&self.edge))
    }
}
impl PartialOrd for Candidate {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// The surface in the middle of its simplification.
struct Simplifier {
    vertices: Vec<Point3<f64>>,
    triangles: Vec<[u32; 3]>,
    alive: Vec<bool>,
    /// The live triangles at each vertex.
    at: Vec<Vec<u32>>,
    quadric: Vec<Matrix4<f64>>,
    boundary: Vec<bool>,
    version: Vec<u32>,
    heap: BinaryHeap<Candidate>,
}

/// The surface simplified to at most `target` triangles (fewer when no collapse is left that
/// keeps it a surface, as many as given when it has no more): vertices renumbered in their
/// order, triangles in theirs.
pub fn decimate(vertices: &[Point3<f64>], triangles: &[[u32; 3]], target: usize) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
    let mut s = Simplifier::new(vertices, triangles);
    let mut live = triangles.len();
    while live > target {
        let Some(c) = s.heap.pop() else { break };
        let (a, b) = c.edge;
        if (s.version[a as usize], s.version[b as usize]) != c.versions {
            continue;
        }
        if let Some(removed) = s.collapse(a, b) {
            live -= removed;
        }
    }
    s.compact()
}

impl Simplifier {
    fn new(vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> Simplifier {
        let n = vertices.len();
        let mut at = vec![vec![]; n];
        for (t, tri) in triangles.iter().enumerate() {
            tri.iter().for_each(|&v| at[v as usize].push(t as u32));
        }
        let mut edge_count: HashMap<(u32, u32), (u32, u32)> = HashMap::new();
        for (t, tri) in triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                edge_count.entry((a.min(b), a.max(b))).or_insert((0, t as u32)).0 += 1;
            }
        }
        let mut quadric = vec![Matrix4::zeros(); n];
        for tri in triangles {
            let [p, q, r] = tri.map(|i| vertices[i as usize]);
            let normal = (q - p).cross(&(r - p));
            let area = 0.5 * normal.norm();
            if let Some(u) = normal.try_normalize(0.0) {
                let k = plane_quadric(&u, &p) * area;
                tri.iter().for_each(|&v| quadric[v as usize] += k);
            }
        }
        let mut boundary = vec![false; n];
        let mut edges: Vec<(u32, u32)> = edge_count.keys().copied().collect();
        edges.sort_unstable();
        for e in &edges {
            let (count, t) = edge_count[e];
            if count != 1 {
                continue;
            }
            let (a, b) = *e;
            boundary[a as usize] = true;
            boundary[b as usize] = true;
            let [p, q, r] = triangles[t as usize].map(|i| vertices[i as usize]);
            let along = vertices[b as usize] - vertices[a as usize];
            if let Some(u) = along.cross(&(q - p).cross(&(r - p))).try_normalize(0.0) {
                let k = plane_quadric(&u, &vertices[a as usize]) * (BOUNDARY_WEIGHT * along.norm_squared());
                quadric[a as usize] += k;
                quadric[b as usize] += k;
            }
        }
        let mut s = Simplifier {
            vertices: vertices.to_vec(),
            triangles: triangles.to_vec(),
            alive: vec![true; triangles.len()],
            at,
            quadric,
            boundary,
            version: vec![0; n],
            heap: BinaryHeap::new(),
        };
        for (a, b) in edges {
            s.push(a, b);
        }
        s
    }

    /// Costs the collapse of edge a-b and files it.
    fn push(&mut self, a: u32, b: u32) {
        let (a, b) = (a.min(b), a.max(b));
        let (_, cost) = self.target(a, b);
        let versions = (self.version[a as usize], self.version[b as usize]);
        self.heap.push(Candidate { cost, edge: (a, b), versions });
    }

    /// The point edge a-b collapses to (least summed error; the better end or the middle when the
    /// quadric is singular or its minimum worse) and its error.
    fn target(&self, a: u32, b: u32) -> (Point3<f64>, f64) {
        let q = self.quadric[a as usize] + self.quadric[b as usize];
        let error = |p: &Point3<f64>| {
            let h = Vector4::new(p.x, p.y, p.z, 1.0);
            (h.transpose() * q * h)[0].max(0.0)
        };
        let (pa, pb) = (self.vertices[a as usize], self.vertices[b as usize]);
        let mut candidates = vec![pa, pb, Point3::from((pa.coords + pb.coords) * 0.5)];
        let m: Matrix3<f64> = q.fixed_view::<3, 3>(0, 0).into();
        let rhs = -Vector3::new(q[(0, 3)], q[(1, 3)], q[(2, 3)]);
        if let Some(p) = m.lu().solve(&rhs).filter(|p| p.iter().all(|c| c.is_finite())) {
            // Far off the edge, the minimum of a nearly flat quadric is noise.
            let mid = (pa.coords + pb.coords) * 0.5;
            if (p - mid).norm() <= 2.0 * (pb - pa).norm() {
                candidates.insert(0, Point3::from(p));
            }
        }
        candidates.into_iter().map(|p| (p, error(&p))).min_by(|x, y| x.1.total_cmp(&y.1)).expect("three candidates")
    }

    /// The vertices sharing a live triangle with `v`.
    fn ring(&self, v: u32) -> Vec<u32> {
        let mut r: Vec<u32> =
            self.at[v as usize].iter().flat_map(|&t| self.triangles[t as usize]).filter(|&u| u != v).collect();
        r.sort_unstable();
        r.dedup();
        r
    }

    /// Collapses b into a when that keeps a surface; the number of triangles removed.
    fn collapse(&mut self, a: u32, b: u32) -> Option<usize> {
        let shared: Vec<u32> =
            self.at[a as usize].iter().copied().filter(|t| self.triangles[*t as usize].contains(&b)).collect();
        if shared.is_empty() || shared.len() > 2 {
            return None;
        }
        // The link condition: the two rings meet only at the shared triangles' third corners.
        let (ra, rb) = (self.ring(a), self.ring(b));
        let common = ra.iter().filter(|v| rb.binary_search(v).is_ok()).count();
        let boundary_edge = shared.len() == 1;
        if common != shared.len() || (self.boundary[a as usize] && self.boundary[b as usize] && !boundary_edge) {
            return None;
        }
        let (p, _) = self.target(a, b);
        let moved = |tri: [u32; 3], vertices: &[Point3<f64>]| {
            tri.map(|v| if v == a || v == b { p } else { vertices[v as usize] })
        };
        for &t in self.at[a as usize].iter().chain(&self.at[b as usize]) {
            if shared.contains(&t) {
                continue;
            }
            let tri = self.triangles[t as usize];
            let [x, y, z] = tri.map(|v| self.vertices[v as usize]);
            let before = (y - x).cross(&(z - x));
            let [x, y, z] = moved(tri, &self.vertices);
            let after = (y - x).cross(&(z - x));
            if before.dot(&after) <= MIN_NORMAL_COS * before.norm() * after.norm() {
                return None;
            }
        }
        shared.iter().for_each(|&t| self.alive[t as usize] = false);
        let from_b = std::mem::take(&mut self.at[b as usize]);
        for &t in &from_b {
            if self.alive[t as usize] {
                self.triangles[t as usize].iter_mut().filter(|v| **v == b).for_each(|v| *v = a);
            }
        }
        let mut live: Vec<u32> =
            self.at[a as usize].iter().chain(&from_b).copied().filter(|&t| self.alive[t as usize]).collect();
        live.sort_unstable();
        live.dedup();
        for &c in &shared {
            for v in self.triangles[c as usize] {
                self.at[v as usize].retain(|&t| t != c);
            }
        }
        self.at[a as usize] = live;
        self.vertices[a as usize] = p;
        let qb = self.quadric[b as usize];
        self.quadric[a as usize] += qb;
        self.boundary[a as usize] |= self.boundary[b as usize];
        self.version[a as usize] += 1;
        self.version[b as usize] += 1;
        for n in self.ring(a) {
            self.push(a, n);
        }
        Some(shared.len())
    }

    /// The live triangles and the vertices they use, renumbered in order.
    fn compact(self) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
        let mut index = vec![u32::MAX; self.vertices.len()];
        let mut vertices = vec![];
        let mut triangles = vec![];
        for (tri, _) in self.triangles.iter().zip(&self.alive).filter(|(_, a)| **a) {
            triangles.push(tri.map(|v| {
                if index[v as usize] == u32::MAX {
                    index[v as usize] = vertices.len() as u32;
                    vertices.push(self.vertices[v as usize]);
                }
                index[v as usize]
            }));
        }
        (vertices, triangles)
    }
}

/// The quadric of the squared distance to the plane through `p` with unit normal `u`.
fn plane_quadric(u: &Vector3<f64>, p: &Point3<f64>) -> Matrix4<f64> {
    let h = Vector4::new(u.x, u.y, u.z, -u.dot(&p.coords));
    h * h.transpose()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::topology::{boundary_loops, triangle_neighbours, NON_MANIFOLD};

    #[test]
    fn a_fine_tube_decimated_keeps_its_shape_its_ends_and_its_winding() {
        let tube = crate::testing::straight_tube_surface(2.0, 20.0, 64, 80);
        let (v, t) = decimate(&tube.vertices, &tube.triangles, 1000);
        assert!(t.len() <= 1000 && t.len() > 900, "{} triangles", t.len());
        // Still an open tube: two boundary loops, no edge shared by three triangles, and every
        // vertex on the cylinder (the quadrics keep it) within 2 % of the radius.
        assert_eq!(boundary_loops(&t).len(), 2);
        assert!(triangle_neighbours(&t).iter().flatten().all(|&n| n != NON_MANIFOLD));
        assert!(v.iter().all(|p| (p.x.hypot(p.y) - 2.0).abs() < 0.04), "a vertex left the cylinder");
        let (low, high) = v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| (l.min(p.z), h.max(p.z)));
        assert!(low.abs() < 1e-9 && (high - 20.0).abs() < 1e-9, "an end moved: z from {low} to {high}");
        // Facing out still: the normal at every triangle points away from the axis.
        for tri in &t {
            let [a, b, c] = tri.map(|i| v[i as usize]);
            let centre = (a.coords + b.coords + c.coords) / 3.0;
            let radial = Vector3::new(centre.x, centre.y, 0.0);
            assert!((b - a).cross(&(c - a)).dot(&radial) > 0.0, "a triangle turned over");
        }
    }
}
