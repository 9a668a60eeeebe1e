//! Generalised winding numbers of a triangle surface in time logarithmic in its size (Barill et
//! al. 2018, "Fast winding numbers for soups and clouds"): the triangles are grouped in a tree of
//! clusters; a cluster far from the point adds its far-field expansion (its area-weighted normal,
//! a dipole, and the normals' first moment about its centre) instead of each triangle's solid
//! angle, and only the clusters near the point are summed triangle by triangle.
//!
//! Why: the winding number decides what lies inside the lumen (the centerline's probes, the
//! medial axis's candidate points), and summed over every triangle it cost a fifth of a
//! 37-ended random tree's run (probes along 73 branches against 234,403 triangles; its
//! centerline stage 5.6 -> 2.1 s).
//!
//! Accuracy: a cluster of radius `r` is expanded only from beyond `FAR_FIELD` times `r`, where
//! the neglected terms are of order `(r / d)^3` of its solid angle. Measured against the exact
//! sum around a tube of 20,000 triangles, open and closed (4,200 points inside, outside, within
//! 0.001 radii of the wall, past the open rims), the difference is at most 1.3e-3 (7.8e-3 from
//! beyond two radii, 2.7e-4 from beyond four, 5e-5 from beyond five, at about the same speed
//! on a random tree); the callers compare with 0.5. The cohort's 36 meshes are byte-identical
//! to those of the exact sum.
//!
//! Memory: a cluster takes about 300 bytes and a tree holds one for every six triangles (leaves
//! of up to `LEAF_TRIANGLES`); a surface's tree is built when its first winding number is
//! asked. Random tree 41 (234,403 triangles) peaks at 514 MB against 483 MB without; with leaves
//! of eight and the second moments stored whole, 565 MB.
//!
//! The sum runs in a fixed order, so the value does not depend on the thread count.

use nalgebra::{Matrix3, Point3, Vector3};

/// A cluster is expanded when the point lies farther from its centre than this many radii.
const FAR_FIELD: f64 = 3.0;
/// At most this many triangles in a leaf cluster.
const LEAF_TRIANGLES: usize = 16;

/// One cluster: its triangles (a range of [`WindingTree::order`]), its children, and its
/// far-field expansion.
#[derive(Debug, Clone)]
struct Cluster {
    start: u32,
    end: u32,
    /// Indices of the two children in [`WindingTree::clusters`]; none for a leaf.
    children: Option<[u32; 2]>,
    /// Area-weighted centroid of the triangles.
    centre: Point3<f64>,
    /// Largest distance from the centre to a corner of the triangles.
    radius: f64,
    /// Sum of the triangles' area vectors (half the cross product of two edges, as wound).
    area: Vector3<f64>,
    /// Sum over the triangles of area vector times (centroid - centre), transposed: entry (j, k)
    /// is the sum of area_j * offset_k.
    moment: Matrix3<f64>,
    /// Second moments: `[j]` holds the symmetric (k, l) entries (see [`pack`]) of the sum over
    /// the triangles of area_j times the mean of offset_k offset_l over the triangle.
    second: [[f64; 6]; 3],
}

/// The cluster tree of a triangle surface.
#[derive(Debug, Clone)]
pub struct WindingTree {
    clusters: Vec<Cluster>,
    /// The triangles' indices, each cluster's a contiguous range.
    order: Vec<u32>,
}

impl WindingTree {
    pub fn new(vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> Self {
        let centroid = |t: u32| {
            let [a, b, c] = triangles[t as usize].map(|i| vertices[i as usize].coords);
            Point3::from((a + b + c) / 3.0)
        };
        let centroids: Vec<Point3<f64>> = (0..triangles.len() as u32).map(centroid).collect();
        let mut tree = WindingTree { clusters: Vec::new(), order: (0..triangles.len() as u32).collect() };
        if !triangles.is_empty() {
            tree.split(0, triangles.len(), vertices, triangles, &centroids);
        }
        tree
    }

    /// Adds the cluster of the triangles `order[start..end]` and, past a leaf's size, its two
    /// halves split at the median centroid along the widest axis; returns its index.
    fn split(
        &mut self,
        start: usize,
        end: usize,
        vertices: &[Point3<f64>],
        triangles: &[[u32; 3]],
        centroids: &[Point3<f64>],
    ) -> u32 {
        let index = self.clusters.len();
        self.clusters.push(cluster_of(&self.order[start..end], start, vertices, triangles, centroids));
        if end - start > LEAF_TRIANGLES {
            let part = &mut self.order[start..end];
            let (lo, hi) = part
                .iter()
                .fold((Vector3::repeat(f64::INFINITY), Vector3::repeat(f64::NEG_INFINITY)), |(lo, hi), &t| {
                    (lo.inf(&centroids[t as usize].coords), hi.sup(&centroids[t as usize].coords))
                });
            let axis = (hi - lo).imax();
            let mid = part.len() / 2;
            part.select_nth_unstable_by(mid, |&a, &b| {
                centroids[a as usize][axis].total_cmp(&centroids[b as usize][axis]).then(a.cmp(&b))
            });
            let left = self.split(start, start + mid, vertices, triangles, centroids);
            let right = self.split(start + mid, end, vertices, triangles, centroids);
            self.clusters[index].children = Some([left, right]);
        }
        index as u32
    }

    /// The winding number around `p`: the triangles' signed solid angles over 4 pi, clusters far
    /// from `p` by their expansion.
    pub fn winding_number(&self, vertices: &[Point3<f64>], triangles: &[[u32; 3]], p: &Point3<f64>) -> f64 {
        if self.clusters.is_empty() {
            return 0.0;
        }
        let mut total = 0.0;
        let mut stack = vec![0u32];
        while let Some(c) = stack.pop() {
            let cluster = &self.clusters[c as usize];
            let r = cluster.centre - p;
            let d = r.norm();
            if d > FAR_FIELD * cluster.radius {
                total += far_field(cluster, &r, d);
            } else if let Some([left, right]) = cluster.children {
                stack.push(right);
                stack.push(left);
            } else {
                total += self.order[cluster.start as usize..cluster.end as usize]
                    .iter()
                    .map(|&t| solid_angle(triangles[t as usize].map(|i| vertices[i as usize]), p))
                    .sum::<f64>();
            }
        }
        total / (4.0 * std::f64::consts::PI)
    }
}

/// The cluster of the triangles `members` (starting at `start` in the order).
fn cluster_of(
    members: &[u32],
    start: usize,
    vertices: &[Point3<f64>],
    triangles: &[[u32; 3]],
    centroids: &[Point3<f64>],
) -> Cluster {
    let area_of = |t: u32| {
        let [a, b, c] = triangles[t as usize].map(|i| vertices[i as usize]);
        0.5 * (b - a).cross(&(c - a))
    };
    let (mut weighted, mut weight, mut area) = (Vector3::zeros(), 0.0, Vector3::zeros());
    for &t in members {
        let a = area_of(t);
        weighted += centroids[t as usize].coords * a.norm();
        weight += a.norm();
        area += a;
    }
    let centre = if weight > 0.0 {
        Point3::from(weighted / weight)
    } else {
        Point3::from(members.iter().map(|&t| centroids[t as usize].coords).sum::<Vector3<f64>>() / members.len() as f64)
    };
    let (mut moment, mut second, mut radius) = (Matrix3::zeros(), [Matrix3::zeros(); 3], 0.0f64);
    for &t in members {
        let (a, c) = (area_of(t), centroids[t as usize]);
        let offset = c - centre;
        moment += a * offset.transpose();
        // The mean of x x^T over a triangle about its centroid is a twelfth of the sum over its
        // corners; about the cluster's centre, plus the centroid's offset squared.
        let corners = triangles[t as usize].map(|i| vertices[i as usize]);
        let spread = corners.iter().map(|v| (v - c) * (v - c).transpose()).sum::<Matrix3<f64>>() / 12.0;
        let mean_square = offset * offset.transpose() + spread;
        for j in 0..3 {
            second[j] += mean_square * a[j];
        }
        for v in corners {
            radius = radius.max((v - centre).norm());
        }
    }
    let end = (start + members.len()) as u32;
    let second = second.map(|m| pack(&m));
    Cluster { start: start as u32, end, children: None, centre, radius, area, moment, second }
}

/// A far cluster's solid angle seen from the point `centre - r` (`d = |r|`): the integral of
/// the kernel `f(x) = x / |x|^3` against its area vectors, the kernel expanded about the centre
/// to second order (Barill et al.'s expansion): the dipole of its area vector, the gradient
/// contracted with the first moments, half the Hessian with the second moments.
fn far_field(cluster: &Cluster, r: &Vector3<f64>, d: f64) -> f64 {
    let (d2, d3) = (d * d, d * d * d);
    let (d5, d7) = (d3 * d2, d3 * d2 * d2);
    let dipole = cluster.area.dot(r) / d3;
    let gradient = Matrix3::identity() / d3 - r * r.transpose() * (3.0 / d5);
    let first = gradient.component_mul(&cluster.moment).sum();
    // d2 f_j / dx_k dx_l = -3 (delta_jk r_l + delta_jl r_k + delta_kl r_j) / d^5
    //                      + 15 r_j r_k r_l / d^7, contracted with the symmetric second moments.
    let s = cluster.second.map(|p| unpack(&p));
    let (mut deltas, mut cubic) = (0.0, 0.0);
    for j in 0..3 {
        deltas += 2.0 * (s[j].row(j) * r)[0] + r[j] * s[j].trace();
        cubic += r[j] * (r.transpose() * s[j] * r)[0];
    }
    dipole + first + 0.5 * (-3.0 * deltas / d5 + 15.0 * cubic / d7)
}

/// A symmetric matrix's six entries (00, 11, 22, 01, 02, 12): a cluster's second moments in
/// two thirds of the memory (a tree holds about one cluster for every six triangles).
fn pack(m: &Matrix3<f64>) -> [f64; 6] {
    [m[(0, 0)], m[(1, 1)], m[(2, 2)], m[(0, 1)], m[(0, 2)], m[(1, 2)]]
}

fn unpack(p: &[f64; 6]) -> Matrix3<f64> {
    Matrix3::new(p[0], p[3], p[4], p[3], p[1], p[5], p[4], p[5], p[2])
}

/// The signed solid angle of the triangle `[a, b, c]` seen from `p` (Van Oosterom and Strackee).
fn solid_angle([a, b, c]: [Point3<f64>; 3], p: &Point3<f64>) -> f64 {
    let (a, b, c) = (a - p, b - p, c - p);
    let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
    let num = a.dot(&b.cross(&c));
    let den = la * lb * lc + a.dot(&b) * lc + a.dot(&c) * lb + b.dot(&c) * la;
    2.0 * num.atan2(den)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A closed tube (radius 1, length 10 along z, capped by fans) of `around` x `along` quads:
    /// its vertices and triangles.
    fn capped_tube(around: usize, along: usize) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
        let tube = crate::testing::capped_tube_surface(1.0, 10.0, around, along);
        (tube.vertices, tube.triangles)
    }

    fn exact(vertices: &[Point3<f64>], triangles: &[[u32; 3]], p: &Point3<f64>) -> f64 {
        triangles.iter().map(|t| solid_angle(t.map(|i| vertices[i as usize]), p)).sum::<f64>()
            / (4.0 * std::f64::consts::PI)
    }

    /// Inside, outside, near the wall on either side and near the open rim of a tube with its
    /// caps left off: the tree's winding number is the exact sum's within 2e-3 (see the
    /// module's accuracy), and about 1 inside and 0 outside the closed tube.
    #[test]
    fn the_tree_agrees_with_the_exact_sum() {
        let (vertices, triangles) = capped_tube(64, 160);
        let open: Vec<[u32; 3]> = triangles[..64 * 160 * 2].to_vec();
        let mut points = Vec::new();
        for k in 0..200 {
            let t = k as f64 * 0.7548776662;
            let (a, z) = (std::f64::consts::TAU * (t % 1.0), -1.0 + 12.0 * ((t * 1.3247) % 1.0));
            let rho = [0.0, 0.5, 0.95, 0.999, 1.001, 1.05, 2.0, 5.0][k % 8];
            points.push(Point3::new(rho * a.cos(), rho * a.sin(), z));
        }
        for tris in [&triangles, &open] {
            let tree = WindingTree::new(&vertices, tris);
            for p in &points {
                let (fast, exact) = (tree.winding_number(&vertices, tris, p), exact(&vertices, tris, p));
                assert!((fast - exact).abs() < 2e-3, "at {p}: {fast} against {exact}");
            }
        }
        let tree = WindingTree::new(&vertices, &triangles);
        assert!((tree.winding_number(&vertices, &triangles, &Point3::new(0.2, 0.1, 5.0)) - 1.0).abs() < 2e-3);
        let outside = tree.winding_number(&vertices, &triangles, &Point3::new(3.0, 0.0, 5.0));
        assert!(outside.abs() < 2e-3, "{outside}");
    }

    /// Every triangle lies in exactly one leaf, and a cluster's range is its children's.
    #[test]
    fn the_clusters_partition_the_triangles() {
        let (vertices, triangles) = capped_tube(12, 9);
        let tree = WindingTree::new(&vertices, &triangles);
        let mut seen = vec![0; triangles.len()];
        for c in &tree.clusters {
            match c.children {
                Some([l, r]) => {
                    let (l, r) = (&tree.clusters[l as usize], &tree.clusters[r as usize]);
                    assert_eq!((l.start, l.end, r.end), (c.start, r.start, c.end));
                }
                None => {
                    assert!((c.end - c.start) as usize <= LEAF_TRIANGLES);
                    tree.order[c.start as usize..c.end as usize].iter().for_each(|&t| seen[t as usize] += 1);
                }
            }
        }
        assert!(seen.iter().all(|&n| n == 1));
    }
}
