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
        let gap = |b: &Ball| (b.centre - p).norm() - b.radius;
        let near = self
            .nodes
            .iter()
            .filter(|b| gap(b) <= reach.max(0.1 * b.radius))
            .max_by(|a, b| a.radius.total_cmp(&b.radius));
        near.or_else(|| self.nodes.iter().min_by(|a, b| gap(a).total_cmp(&gap(b))))
            .copied()
            .unwrap_or(Ball { centre: *p, radius: 0.0 })
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
