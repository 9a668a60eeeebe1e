//! Medial balls of the surface vertices (the shrinking-ball algorithm) and the graph of
//! overlapping balls on which the centerlines are shortest paths.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::num::NonZeroUsize;

/// Balls are computed for at most about this many vertices (every k-th vertex beyond it): a
/// ball query near the axis meets a whole ring of nearly equidistant vertices, so each costs
/// far more than a usual nearest-neighbour query, and dense rings give the same centres anyway.
const BALL_BUDGET: usize = 20_000;
/// Iterations of the shrinking ball (it converges in a handful on vessel surfaces).
const SHRINK_ITERATIONS: usize = 40;
/// Balls whose centres lie within this fraction of the larger radius are merged into one node.
const MERGE_FRACTION: f64 = 0.1;
/// Each node is linked to (at most) this many nearest nodes whose balls overlap enough.
const NEIGHBOURS: usize = 24;
/// Two balls are linked when their centres are closer than this fraction of the smaller radius:
/// the segment between the centres then lies in their union, inside the lumen, and is short
/// enough not to cut corners in bends (a chord of 0.5 r sags by r^2 / 32 Rb).
const LINK_REACH: f64 = 0.5;
/// An end that no ball holds is linked to nearby balls it overlaps by this fraction of the sum
/// of the radii.
const OVERLAP: f64 = 0.9;

fn arr(p: &Point3<f64>) -> [f64; 3] {
    [p.x, p.y, p.z]
}

/// A maximal ball: empty of surface vertices, touching the surface at its vertex.
#[derive(Debug, Clone, Copy)]
pub struct Ball {
    pub centre: Point3<f64>,
    pub radius: f64,
}

/// The surface vertices that block balls (those with a normal: vertices of removed caps have
/// none) in a k-d tree.
struct Blockers<'a> {
    vertices: &'a [Point3<f64>],
    used: Vec<usize>,
    tree: ImmutableKdTree<f64, 3>,
    max_radius: f64,
}

impl<'a> Blockers<'a> {
    fn new(vertices: &'a [Point3<f64>], inward: &[Vector3<f64>], max_radius: f64) -> Option<Self> {
        let used: Vec<usize> = (0..vertices.len()).filter(|&i| inward[i] != Vector3::zeros()).collect();
        let pts: Vec<[f64; 3]> = used.iter().map(|&i| arr(&vertices[i])).collect();
        let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&pts).ok()?;
        Some(Blockers { vertices, used, tree, max_radius })
    }

    /// The shrinking ball tangent at `p` on the side of the unit vector `n`: start from a ball
    /// of radius `max_radius`, and while it holds a vertex other than `p`, shrink it to the ball
    /// tangent at `p` through that vertex. `None` when the ball never closes (`p` faces an
    /// opening larger than `max_radius`) or a vertex lies on the wrong side of the tangent plane.
    fn shrink(&self, p: Point3<f64>, n: Vector3<f64>) -> Option<Ball> {
        let two = NonZeroUsize::new(2).expect("2 > 0");
        let tol = 1e-9 * self.max_radius;
        let mut r = self.max_radius;
        for _ in 0..SHRINK_ITERATIONS {
            let c = p + n * r;
            let near = self.tree.query(&arr(&c)).nearest_n::<SquaredEuclidean<f64>>(two).execute();
            let q = near.iter().map(|h| self.vertices[self.used[h.item as usize]]).find(|q| (q - p).norm() > tol)?;
            if (q - c).norm() >= r - tol {
                return (r < self.max_radius).then_some(Ball { centre: c, radius: r });
            }
            let d = q - p;
            let along = d.dot(&n);
            if along <= 0.0 {
                return None;
            }
            let shrunk = d.norm_squared() / (2.0 * along);
            if shrunk >= r - tol {
                return Some(Ball { centre: c, radius: r });
            }
            r = shrunk;
        }
        Some(Ball { centre: p + n * r, radius: r })
    }
}

/// The shrinking-ball medial ball of every vertex (Ma, Bae, Bhatt & Lee 2012), tangent at the
/// vertex on its inner side (see [`Blockers::shrink`]). `None` where the normal is undefined or
/// the ball never closes. Vertices with a zero normal (not on any kept triangle) neither get nor
/// block a ball; on dense surfaces only every k-th vertex gets one (see [`BALL_BUDGET`]).
pub fn shrinking_balls(vertices: &[Point3<f64>], inward: &[Vector3<f64>], max_radius: f64) -> Vec<Option<Ball>> {
    let Some(blockers) = Blockers::new(vertices, inward, max_radius) else {
        return vec![None; vertices.len()];
    };
    let stride = blockers.used.len().div_ceil(BALL_BUDGET).max(1);
    (0..vertices.len())
        .into_par_iter()
        .map(|i| {
            let n = inward[i];
            if n == Vector3::zeros() || i % stride != 0 {
                return None;
            }
            blockers.shrink(vertices[i], n)
        })
        .collect()
}

/// The shrinking balls tangent at arbitrary points (not vertices), each on the side of its unit
/// vector; blocked by the vertices with a nonzero `inward` normal as in [`shrinking_balls`].
pub fn tangent_balls(
    vertices: &[Point3<f64>],
    inward: &[Vector3<f64>],
    at: &[(Point3<f64>, Vector3<f64>)],
    max_radius: f64,
) -> Vec<Option<Ball>> {
    let Some(blockers) = Blockers::new(vertices, inward, max_radius) else {
        return vec![None; at.len()];
    };
    at.iter().map(|&(p, n)| blockers.shrink(p, n)).collect()
}

/// Nodes (merged balls) and the links between overlapping ones.
pub struct BallGraph {
    pub nodes: Vec<Ball>,
    links: Vec<Vec<(u32, f64)>>,
}

impl BallGraph {
    /// Merges the balls (largest first; a ball absorbs the unmerged ones whose centres lie within
    /// [`MERGE_FRACTION`] of its radius, the node being their mean) and links every node to its
    /// nearest overlapping nodes, with cost length x mean(1/R) (VMTK's 1/R cost).
    pub fn new(balls: &[Option<Ball>]) -> BallGraph {
        let ids: Vec<usize> = (0..balls.len()).filter(|&i| balls[i].is_some()).collect();
        let get = |i: usize| balls[i].expect("filtered");
        let mut node_of_vertex = vec![None; balls.len()];
        let mut nodes = vec![];
        if !ids.is_empty() {
            let pts: Vec<[f64; 3]> = ids.iter().map(|&i| arr(&get(i).centre)).collect();
            let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&pts).expect("not empty");
            let mut order: Vec<usize> = (0..ids.len()).collect();
            order.sort_by(|&a, &b| get(ids[b]).radius.total_cmp(&get(ids[a]).radius).then(a.cmp(&b)));
            for k in order {
                if node_of_vertex[ids[k]].is_some() {
                    continue;
                }
                let ball = get(ids[k]);
                let reach = MERGE_FRACTION * ball.radius;
                let mut members: Vec<usize> = tree
                    .query(&pts[k])
                    .within::<SquaredEuclidean<f64>>(reach * reach)
                    .execute()
                    .iter()
                    .map(|h| ids[h.item as usize])
                    .filter(|&v| node_of_vertex[v].is_none())
                    .collect();
                members.push(ids[k]);
                members.sort_unstable();
                members.dedup();
                let id = nodes.len() as u32;
                let (mut c, mut r) = (Vector3::zeros(), 0.0);
                for &v in &members {
                    node_of_vertex[v] = Some(id);
                    c += get(v).centre.coords;
                    r += get(v).radius;
                }
                let m = members.len() as f64;
                nodes.push(Ball { centre: Point3::from(c / m), radius: r / m });
            }
        }
        let mut graph = BallGraph { nodes, links: vec![] };
        graph.links = graph.link_all();
        graph
    }

    /// Sizes of the connected components, largest first (diagnostics).
    pub fn component_sizes(&self) -> Vec<usize> {
        let n = self.nodes.len();
        let mut comp = vec![u32::MAX; n];
        let mut sizes = vec![];
        for s in 0..n {
            if comp[s] != u32::MAX {
                continue;
            }
            let id = sizes.len() as u32;
            let mut stack = vec![s];
            comp[s] = id;
            let mut size = 0;
            while let Some(u) = stack.pop() {
                size += 1;
                for &(v, _) in &self.links[u] {
                    if comp[v as usize] == u32::MAX {
                        comp[v as usize] = id;
                        stack.push(v as usize);
                    }
                }
            }
            sizes.push(size);
        }
        sizes.sort_unstable_by(|a, b| b.cmp(a));
        sizes
    }

    /// The inscribed ball at a point of the surface or of the lumen: the largest ball that
    /// holds it or comes within `reach` of it (or within a tenth of its own radius), else the
    /// ball reaching nearest to it. Its radius is the vessel's there, whatever the surface's
    /// triangles; `reach` (half a patch's radius, say) keeps a small crease at the point from
    /// hiding the vessel around it.
    pub fn pole(&self, p: &Point3<f64>, reach: f64) -> Ball {
        let gap = |b: &Ball| (b.centre - p).norm() - b.radius;
        let near =
            self.nodes.iter().filter(|b| gap(b) <= reach.max(0.1 * b.radius)).max_by(|a, b| a.radius.total_cmp(&b.radius));
        near.or_else(|| self.nodes.iter().min_by(|a, b| gap(a).total_cmp(&gap(b))))
            .copied()
            .unwrap_or(Ball { centre: *p, radius: 0.0 })
    }

    /// The links of node `n`: (other node, cost).
    pub fn links(&self, n: usize) -> &[(u32, f64)] {
        &self.links[n]
    }

    /// A graph of the given balls and links (both ways, cost per link).
    pub fn from_parts(nodes: Vec<Ball>, links: Vec<Vec<(u32, f64)>>) -> BallGraph {
        BallGraph { nodes, links }
    }

    fn link_all(&self) -> Vec<Vec<(u32, f64)>> {
        let mut links = vec![vec![]; self.nodes.len()];
        if self.nodes.is_empty() {
            return links;
        }
        let pts: Vec<[f64; 3]> = self.nodes.iter().map(|b| arr(&b.centre)).collect();
        let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&pts).expect("not empty");
        let k = NonZeroUsize::new(NEIGHBOURS + 1).expect("> 0");
        let found: Vec<Vec<u32>> = (0..self.nodes.len())
            .into_par_iter()
            .map(|i| {
                tree.query(&pts[i]).nearest_n::<SquaredEuclidean<f64>>(k).execute().iter().map(|h| h.item).collect()
            })
            .collect();
        for (i, near) in found.iter().enumerate() {
            for &j in near {
                if j as usize != i {
                    if let Some(cost) = self.cost(i, j as usize) {
                        links[i].push((j, cost));
                        links[j as usize].push((i as u32, cost));
                    }
                }
            }
        }
        for l in &mut links {
            l.sort_by_key(|e| e.0);
            l.dedup_by_key(|e| e.0);
        }
        links
    }

    fn cost(&self, i: usize, j: usize) -> Option<f64> {
        let (a, b) = (self.nodes[i], self.nodes[j]);
        let d = (a.centre - b.centre).norm();
        (d < LINK_REACH * a.radius.min(b.radius)).then(|| d * 0.5 * (1.0 / a.radius + 1.0 / b.radius))
    }

    /// Adds an end node: a point on the closed surface (a cap's centre, with the section's
    /// radius) or inside the lumen (the inscribed ball under a rounded end). It is linked to
    /// every node whose ball holds it; an end on the surface, which no empty ball holds, to the
    /// largest ball through it (VMTK's seed: the largest internal tetrahedron at the cap centre),
    /// or failing that to the ball reaching deepest past it.
    pub fn add_end(&mut self, end: Ball) -> u32 {
        let id = self.nodes.len() as u32;
        let gap = |n: usize| (self.nodes[n].centre - end.centre).norm() - self.nodes[n].radius;
        let holding: Vec<usize> = (0..self.nodes.len()).filter(|&n| gap(n) < 0.0).collect();
        let chosen = if holding.is_empty() {
            let touch = 1e-6 * end.radius;
            let through = (0..self.nodes.len())
                .filter(|&n| gap(n) <= touch)
                .max_by(|&a, &b| self.nodes[a].radius.total_cmp(&self.nodes[b].radius).then(b.cmp(&a)));
            let deepest = || (0..self.nodes.len()).min_by(|&a, &b| gap(a).total_cmp(&gap(b)).then(a.cmp(&b)));
            through.or_else(deepest).into_iter().collect()
        } else {
            holding
        };
        let links: Vec<(u32, f64)> = chosen
            .iter()
            .map(|&n| {
                let length = (self.nodes[n].centre - end.centre).norm();
                (n as u32, length * 0.5 * (1.0 / end.radius + 1.0 / self.nodes[n].radius))
            })
            .collect();
        self.nodes.push(end);
        self.links.push(vec![]);
        for (n, cost) in links {
            self.links[id as usize].push((n, cost));
            self.links[n as usize].push((id, cost));
        }
        id
    }

    /// Dijkstra from `source`: the predecessor of every reached node (`u32::MAX` for the source
    /// and unreached nodes) and the cost to reach it.
    pub fn shortest_paths(&self, source: u32) -> (Vec<u32>, Vec<f64>) {
        #[derive(PartialEq)]
        struct Entry(f64, u32);
        impl Eq for Entry {}
        impl Ord for Entry {
            fn cmp(&self, o: &Self) -> Ordering {
                o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
            }
        }
        impl PartialOrd for Entry {
            fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
                Some(self.cmp(o))
            }
        }
        let n = self.nodes.len();
        let (mut prev, mut dist) = (vec![u32::MAX; n], vec![f64::INFINITY; n]);
        let mut heap = BinaryHeap::new();
        dist[source as usize] = 0.0;
        heap.push(Entry(0.0, source));
        while let Some(Entry(d, u)) = heap.pop() {
            if d > dist[u as usize] {
                continue;
            }
            for &(v, w) in &self.links[u as usize] {
                let nd = d + w;
                if nd < dist[v as usize] {
                    dist[v as usize] = nd;
                    prev[v as usize] = u;
                    heap.push(Entry(nd, v));
                }
            }
        }
        (prev, dist)
    }
}
