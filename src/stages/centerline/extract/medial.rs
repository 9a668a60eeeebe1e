//! The medial balls of the lumen and the graph linking them, on which the centerlines are
//! least-cost paths (the balls come from the Voronoi diagram, see `voronoi`).

use nalgebra::Point3;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// A maximal ball: empty of the surface, touching it.
#[derive(Debug, Clone, Copy)]
pub struct Ball {
    pub centre: Point3<f64>,
    pub radius: f64,
}

/// A heap entry of Dijkstra's search: the nearest (then the lowest node) pops first, so the
/// search is deterministic.
#[derive(PartialEq)]
pub(super) struct Entry(pub f64, pub u32);
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

/// [`BallGraph::pole`] over `nodes`, given the `near` ones in increasing order (every ball
/// that can reach the point; any superset will do): the same ball whichever superset.
fn pole_among<'a>(nodes: &[Ball], near: impl Iterator<Item = &'a Ball>, p: &Point3<f64>, reach: f64) -> Ball {
    let gap = |b: &Ball| (b.centre - p).norm() - b.radius;
    let reaching = near.filter(|b| gap(b) <= reach.max(0.1 * b.radius)).max_by(|a, b| a.radius.total_cmp(&b.radius));
    reaching
        .or_else(|| nodes.iter().min_by(|a, b| gap(a).total_cmp(&gap(b))))
        .copied()
        .unwrap_or(Ball { centre: *p, radius: 0.0 })
}

/// The balls of a graph filed by centre, for many [`BallGraph::pole`] queries (one per boundary
/// loop and per flat-cap candidate: thousands on a marching-cubes surface, each a scan of every
/// ball without it). Answers exactly as `pole` does on the graph's balls when it was made.
pub struct PoleIndex<'a> {
    nodes: &'a [Ball],
    tree: Option<kiddo::ImmutableKdTree<f64, 3>>,
    widest: f64,
}

impl<'a> PoleIndex<'a> {
    pub fn new(graph: &'a BallGraph) -> PoleIndex<'a> {
        let centres: Vec<[f64; 3]> = graph.nodes.iter().map(|b| b.centre.into()).collect();
        let all_finite = centres.iter().flatten().all(|x| x.is_finite());
        let tree = all_finite.then(|| kiddo::ImmutableKdTree::new_from_slice(&centres).ok()).flatten();
        let widest = graph.nodes.iter().map(|b| b.radius).fold(0.0, f64::max);
        PoleIndex { nodes: &graph.nodes, tree, widest }
    }

    /// [`BallGraph::pole`]: a ball reaches the point only if its centre lies within its radius
    /// plus `reach` or a tenth of its radius, so within 1.1 x the widest radius plus `reach`.
    pub fn pole(&self, p: &Point3<f64>, reach: f64) -> Ball {
        let bound = 1.1 * self.widest + if reach.is_finite() { reach.max(0.0) } else { 0.0 };
        let (Some(tree), true) = (&self.tree, reach < f64::INFINITY && bound.is_finite()) else {
            return pole_among(self.nodes, self.nodes.iter(), p, reach);
        };
        // A little slack: the tree's squared distances round differently from `norm`.
        let within = bound * (1.0 + 1e-9) + 1e-12;
        let mut near: Vec<usize> = tree
            .query(&[p.x, p.y, p.z])
            .within::<kiddo::SquaredEuclidean<f64>>(within * within)
            .unsorted()
            .execute()
            .iter()
            .map(|h| h.item as usize)
            .collect();
        near.sort_unstable();
        pole_among(self.nodes, near.iter().map(|&i| &self.nodes[i]), p, reach)
    }
}

/// A path through the lumen from node `from` to node `to` of another part of the graph,
/// through `balls` (see `bridges`).
#[derive(Debug, Clone)]
pub struct Chain {
    pub from: u32,
    pub to: u32,
    pub balls: Vec<Ball>,
}

/// Balls (nodes) and the links between overlapping ones, each with its cost.
pub struct BallGraph {
    pub nodes: Vec<Ball>,
    links: Vec<Vec<(u32, f64)>>,
}

impl BallGraph {
    /// A graph of the given balls and links (both ways, cost per link).
    pub fn from_parts(nodes: Vec<Ball>, links: Vec<Vec<(u32, f64)>>) -> BallGraph {
        BallGraph { nodes, links }
    }

    /// The chain's balls as nodes, linked in order from `from` to `to`.
    pub fn add_chain(&mut self, chain: Chain) {
        let mut at = chain.from;
        for ball in chain.balls {
            self.nodes.push(ball);
            self.links.push(vec![]);
            let id = (self.nodes.len() - 1) as u32;
            self.link(at, id);
            at = id;
        }
        self.link(at, chain.to);
    }

    /// Links `a` and `b` with VMTK's cost, length x mean(1/R).
    fn link(&mut self, a: u32, b: u32) {
        let (p, q) = (self.nodes[a as usize], self.nodes[b as usize]);
        let cost = (p.centre - q.centre).norm() * 0.5 * (1.0 / p.radius + 1.0 / q.radius);
        self.links[a as usize].push((b, cost));
        self.links[b as usize].push((a, cost));
    }

    /// The inscribed ball at a point of the surface or of the lumen: the largest ball that
    /// holds it or comes within `reach` of it (or within a tenth of its own radius), else the
    /// ball reaching nearest to it. Its radius is the vessel's there, whatever the surface's
    /// triangles; `reach` (half a patch's radius, say) keeps a small crease at the point from
    /// hiding the vessel around it.
    pub fn pole(&self, p: &Point3<f64>, reach: f64) -> Ball {
        pole_among(&self.nodes, self.nodes.iter(), p, reach)
    }

    /// The links of node `n`: (other node, cost).
    pub fn links(&self, n: usize) -> &[(u32, f64)] {
        &self.links[n]
    }

    /// Adds an end node: a point on the closed surface (a cap's centre, with the section's
    /// radius) or inside the lumen (the inscribed ball under a rounded end). It is linked to
    /// every node whose ball holds it; an end on the surface, which no empty ball holds, to the
    /// largest ball through it (VMTK's seed: the largest internal tetrahedron at the cap centre),
    /// or failing that to the ball reaching deepest past it, when it reaches within the end's
    /// radius: a ball whose sphere lies farther from the end than that is not the vessel there,
    /// and a link to it would cross the wall (a decimated branch, its triangles longer than the
    /// vessel is wide, can hold no ball for tens of its radii). With none, the end is a part of
    /// its own, joined to the others through the lumen (see `bridges`).
    pub fn add_end(&mut self, end: Ball) -> u32 {
        let id = self.nodes.len() as u32;
        let gap = |n: usize| (self.nodes[n].centre - end.centre).norm() - self.nodes[n].radius;
        let holding: Vec<usize> = (0..self.nodes.len()).filter(|&n| gap(n) < 0.0).collect();
        let chosen = if holding.is_empty() {
            let touch = 1e-6 * end.radius;
            let through = (0..self.nodes.len())
                .filter(|&n| gap(n) <= touch)
                .max_by(|&a, &b| self.nodes[a].radius.total_cmp(&self.nodes[b].radius).then(b.cmp(&a)));
            let deepest = || {
                (0..self.nodes.len())
                    .filter(|&n| gap(n) <= end.radius)
                    .min_by(|&a, &b| gap(a).total_cmp(&gap(b)).then(a.cmp(&b)))
            };
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic scatter of balls, small and large, some centred on the same point.
    fn scatter() -> BallGraph {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut nodes: Vec<Ball> = (0..2000)
            .map(|_| Ball {
                centre: Point3::new(20.0 * next(), 10.0 * next(), 5.0 * next()),
                radius: 0.05 + 2.0 * next() * next(),
            })
            .collect();
        nodes.push(Ball { centre: nodes[7].centre, radius: nodes[7].radius });
        let links = vec![vec![]; nodes.len()];
        BallGraph::from_parts(nodes, links)
    }

    #[test]
    fn the_pole_index_answers_as_the_scan_of_every_ball() {
        let graph = scatter();
        let index = PoleIndex::new(&graph);
        for i in 0..400 {
            let t = i as f64;
            let p = Point3::new((t * 0.37) % 26.0 - 3.0, (t * 0.61) % 13.0 - 1.5, (t * 0.29) % 8.0 - 1.5);
            for reach in [0.0, 0.3, 2.5, f64::INFINITY, f64::NAN] {
                let (a, b) = (graph.pole(&p, reach), index.pole(&p, reach));
                assert_eq!((a.centre, a.radius.to_bits()), (b.centre, b.radius.to_bits()), "at {p:?}, reach {reach}");
            }
        }
        for p in [Point3::new(100.0, 0.0, 0.0), Point3::new(-50.0, 40.0, 3.0)] {
            let (a, b) = (graph.pole(&p, 0.1), index.pole(&p, 0.1));
            assert_eq!(a.centre, b.centre, "far from every ball, the ball reaching nearest");
        }
    }
}
