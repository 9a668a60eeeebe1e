//! Joins the parts of the ball graph that the lumen connects but the medial balls do not.
//!
//! The ball graph (see `voronoi`) links two Delaunay tetrahedra only when both have an internal
//! circumcentre that spans its ball and their balls overlap. Those tests keep every link inside
//! the lumen, but they are not a test of connectivity: where the samples lie in a pattern the
//! tests reject (the flat facets of a decimated surface, the coplanar midpoints of a subdivided
//! one, the staircase of a marching-cubes surface, a narrow branch only a few samples across),
//! one layer of rejected tetrahedra cuts a connected lumen into parts, and the ends beyond the
//! cut are "not connected to the inlet". Generated tree 1 falls in two large parts (21,700 and
//! 14,300 balls) cut by four tetrahedra whose corners do not span their ball; the coronary tree
//! subdivided (each triangle into four) by three; the aorta subdivided, a voxel staircase, in
//! seven parts of 100 balls or more. And where a branch is decimated to triangles longer than
//! it is wide, no ball at all may lie within tens of its radii of its end (see
//! [`BallGraph::add_end`]): the end is a part of its own.
//!
//! Connectivity is decided here by the tetrahedra themselves: the Delaunay tetrahedra of points
//! on a closed surface fill its convex hull, and those whose centroid lies inside the surface
//! fill the lumen. Two such tetrahedra sharing a face are joined by the segment between their
//! centroids, which crosses the shared face and stays in the two tetrahedra: inside the lumen.
//! With samples a third of the local radius apart (see `sampling`), every cross-section of the
//! lumen holds such tetrahedra, so they are connected wherever the lumen is, and only where it
//! is: across a pinch or between two pieces no tetrahedron has its centroid inside, and the
//! parts stay apart (the end beyond is refused as before).
//!
//! Only what the ends need is joined: nothing when one part holds every end (the graph, and so
//! the centerlines, are then exactly what they were), else the cheapest chains between the
//! parts that hold ends (see [`join_ends`]). A path between two balls of one part never runs
//! through a chain, so the centerlines within a part do not change. Each chain node carries the
//! distance from its centroid to the surface as its radius, the radius of the ball empty of the
//! surface there, so the cost 1/R of a chain is that of the lumen it runs through.

use super::medial::{Ball, BallGraph, Chain, Entry};
use super::qhull::Delaunay;
use crate::geometry::surface::SolidSurface;
use nalgebra::Point3;
use rayon::prelude::*;
use std::collections::{BinaryHeap, HashMap};

/// Union-find over the parts of the graph, smallest index as the root (deterministic).
struct Parts(Vec<u32>);

impl Parts {
    fn find(&mut self, mut a: u32) -> u32 {
        while self.0[a as usize] != a {
            let up = self.0[self.0[a as usize] as usize];
            self.0[a as usize] = up;
            a = up;
        }
        a
    }

    /// Joins the parts of `a` and `b`; false when they were one already.
    fn join(&mut self, a: u32, b: u32) -> bool {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra == rb {
            return false;
        }
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        self.0[hi as usize] = lo;
        true
    }
}

/// The Delaunay tetrahedra of the closed surface's samples (`node_of`: each one's ball node in
/// the graph, `u32::MAX` for none) and the closed surface, facing out.
pub struct LumenTets {
    tessellation: Delaunay,
    node_of: Vec<u32>,
    samples: Vec<Point3<f64>>,
    solid: SolidSurface,
    /// Per tetrahedron, the depth of its centroid (see [`centroid_depths`]), once needed.
    depth: std::cell::OnceCell<Vec<Option<f64>>>,
}

impl LumenTets {
    pub fn new(tessellation: Delaunay, node_of: Vec<u32>, samples: Vec<Point3<f64>>, solid: SolidSurface) -> Self {
        LumenTets { tessellation, node_of, samples, solid, depth: Default::default() }
    }
}

/// Joins the parts of `graph` that hold `ends` by the cheapest chains through the lumen between
/// them, when they are apart; the graph is left as it is when one part holds every end (or the
/// lumen joins none of the parts that hold them).
///
/// The chains found span every part the lumen connects (see [`lumen_chains`]); a part that holds
/// no end and meets the others through one chain only is pruned, repeatedly, as from a spanning
/// tree of terminals: the parts left are those on the way between ends. A fragment of the medial
/// axis that holds no end (a few balls in a crease of the wall) stays apart, as before: joined
/// through the thin lumen at the wall, it would read as a thin vessel to the search for rounded
/// ends. A part that holds an end is a stretch of the lumen the centerlines must cross.
pub fn join_ends(graph: &mut BallGraph, tets: &LumenTets, ends: &[u32]) {
    let parts_of = |graph: &BallGraph| {
        let mut parts = Parts((0..graph.nodes.len() as u32).collect());
        for a in 0..graph.nodes.len() {
            for &(b, _) in graph.links(a) {
                parts.join(a as u32, b);
            }
        }
        parts
    };
    let mut parts = parts_of(graph);
    let mut holding: Vec<u32> = ends.iter().map(|&e| parts.find(e)).collect();
    holding.sort_unstable();
    holding.dedup();
    if holding.len() < 2 {
        return;
    }
    let lone: Vec<u32> = ends.iter().copied().filter(|&e| graph.links(e as usize).is_empty()).collect();
    let chains = lumen_chains(tets, parts_of(graph), &end_seeds(tets, graph, &lone));
    let sides: Vec<(u32, u32)> = chains.iter().map(|c| (parts.find(c.from), parts.find(c.to))).collect();
    let mut kept = vec![true; chains.len()];
    loop {
        let mut degree: HashMap<u32, usize> = HashMap::new();
        for &(a, b) in sides.iter().zip(&kept).filter(|(_, k)| **k).map(|(s, _)| s) {
            *degree.entry(a).or_default() += 1;
            *degree.entry(b).or_default() += 1;
        }
        let leaf = |p: u32| degree[&p] == 1 && holding.binary_search(&p).is_err();
        let pruned: Vec<usize> =
            (0..chains.len()).filter(|&k| kept[k] && (leaf(sides[k].0) || leaf(sides[k].1))).collect();
        if pruned.is_empty() {
            break;
        }
        pruned.into_iter().for_each(|k| kept[k] = false);
    }
    for (chain, _) in chains.into_iter().zip(kept).filter(|(_, k)| *k) {
        graph.add_chain(chain);
    }
}

/// The chains that join the parts of the graph (`parts`) the lumen connects, cheapest first:
/// each from a ball of one part through tetrahedron centroids (with their depth in the closed
/// surface as radius) to a ball of another, together a spanning forest over the parts.
///
/// Each part grows through the lumen's tetrahedra by least cost (VMTK's `length x mean(1/R)`,
/// from all parts at once); where two parts' regions meet is a candidate join, costing the
/// two paths and the step between them, and the cheapest joins that connect parts apart are
/// taken (Kruskal's order; Mehlhorn's spanning tree of terminals). So a chain runs where the
/// lumen between the parts is widest, as a centerline would, not along its wall.
fn lumen_chains(tets: &LumenTets, mut parts: Parts, lone_ends: &[(u32, Vec<u32>)]) -> Vec<Chain> {
    let LumenTets { tessellation: dt, node_of, samples, solid, .. } = tets;
    let depth = tets.depth.get_or_init(|| centroid_depths(dt, samples, solid));
    let step = |t: usize, u: usize| match (depth[t], depth[u]) {
        (Some(a), Some(b)) => {
            let length = (centroid(dt, samples, t) - centroid(dt, samples, u)).norm();
            Some(length * 0.5 * (1.0 / a + 1.0 / b))
        }
        _ => None,
    };
    let centroid_ball =
        |t: u32| Ball { centre: centroid(dt, samples, t as usize), radius: depth[t as usize].unwrap_or(0.0) };
    let Grown { seed, from, cost } = grow(dt, node_of, depth, &step);
    let mut chains = vec![];
    // An end no ball holds joins the region around it, by the cheapest of its tetrahedra, as a
    // leaf: a chain from it, none through it (a path must end at an end, not pass one).
    for (end, entry) in lone_ends {
        let reached = entry.iter().filter(|&&t| seed[t as usize] != u32::MAX);
        let Some(&t) = reached.min_by(|&&a, &&b| cost[a as usize].total_cmp(&cost[b as usize]).then(a.cmp(&b))) else {
            continue;
        };
        parts.join(*end, seed[t as usize]);
        let balls = trail(&from, t).iter().map(|&tet| centroid_ball(tet)).collect();
        chains.push(Chain { from: *end, to: seed[t as usize], balls });
    }
    // Every face where two parts' regions meet, cheapest first (then by tetrahedra: a fixed order).
    let mut meetings = vec![];
    for (t, adjacent) in dt.adjacent.iter().enumerate() {
        for &u in adjacent.iter().filter(|&&u| (u as usize) > t) {
            let (a, b) = (seed[t], seed[u as usize]);
            if a == u32::MAX || b == u32::MAX || parts.find(a) == parts.find(b) {
                continue;
            }
            if let Some(w) = step(t, u as usize) {
                meetings.push((cost[t] + w + cost[u as usize], t as u32, u));
            }
        }
    }
    meetings.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
    for (_, t, u) in meetings {
        if !parts.join(seed[t as usize], seed[u as usize]) {
            continue;
        }
        // The chain: the ball t grew from, the centroids back to t, those on to u, the ball u
        // grew from.
        let mut path = trail(&from, t);
        path.reverse();
        path.extend(trail(&from, u));
        let balls = path.iter().map(|&tet| centroid_ball(tet)).collect();
        chains.push(Chain { from: seed[t as usize], to: seed[u as usize], balls });
    }
    chains
}

/// The parts' regions of the lumen's tetrahedra: per tetrahedron the ball it grew from
/// (`u32::MAX`: none), the tetrahedron before it and the cost from that ball.
struct Grown {
    seed: Vec<u32>,
    from: Vec<u32>,
    cost: Vec<f64>,
}

/// Dijkstra from every ball whose tetrahedron lies in the lumen at once, through the lumen's
/// tetrahedra (`step`: the cost between two that share a face, `None` when one is outside).
fn grow(dt: &Delaunay, node_of: &[u32], depth: &[Option<f64>], step: &dyn Fn(usize, usize) -> Option<f64>) -> Grown {
    let n = dt.tets.len();
    let (mut seed, mut from, mut cost) = (vec![u32::MAX; n], vec![u32::MAX; n], vec![f64::INFINITY; n]);
    let mut heap = BinaryHeap::new();
    for (t, &ball) in node_of.iter().enumerate() {
        if ball != u32::MAX && depth[t].is_some() {
            seed[t] = ball;
            cost[t] = 0.0;
            heap.push(Entry(0.0, t as u32));
        }
    }
    while let Some(Entry(d, t)) = heap.pop() {
        if d > cost[t as usize] {
            continue;
        }
        for &u in &dt.adjacent[t as usize] {
            let Some(w) = step(t as usize, u as usize) else { continue };
            if d + w < cost[u as usize] {
                cost[u as usize] = d + w;
                seed[u as usize] = seed[t as usize];
                from[u as usize] = t;
                heap.push(Entry(d + w, u));
            }
        }
    }
    Grown { seed, from, cost }
}

/// Where each end (`ends`, nodes of `graph` that no ball holds, see [`BallGraph::add_end`])
/// enters the tessellation: the tetrahedra with a corner at the sample nearest to it. An end on
/// an opening or a cap lies on the closed surface, among the samples; one inside the lumen lies
/// a radius from its nearest sample, whose tetrahedra reach in to it.
fn end_seeds(tets: &LumenTets, graph: &BallGraph, ends: &[u32]) -> Vec<(u32, Vec<u32>)> {
    let nearest: Vec<u32> = ends
        .iter()
        .map(|&e| {
            let c = graph.nodes[e as usize].centre;
            let d = |i: usize| (tets.samples[i] - c).norm_squared();
            (0..tets.samples.len()).min_by(|&a, &b| d(a).total_cmp(&d(b)).then(a.cmp(&b))).unwrap_or(0) as u32
        })
        .collect();
    let mut seeds: Vec<(u32, Vec<u32>)> = ends.iter().map(|&e| (e, vec![])).collect();
    for (t, corners) in tets.tessellation.tets.iter().enumerate() {
        for (k, s) in nearest.iter().enumerate() {
            if corners.contains(s) {
                seeds[k].1.push(t as u32);
            }
        }
    }
    seeds
}

/// The tetrahedra from `t` back to the ball's tetrahedron it was reached from, both included.
fn trail(from: &[u32], t: u32) -> Vec<u32> {
    let mut path = vec![t];
    while let Some(&last) = path.last() {
        match from[last as usize] {
            u32::MAX => break,
            p => path.push(p),
        }
    }
    path
}

fn centroid(dt: &Delaunay, samples: &[Point3<f64>], t: usize) -> Point3<f64> {
    let sum = dt.tets[t].iter().fold(nalgebra::Vector3::zeros(), |s, &i| s + samples[i as usize].coords);
    Point3::from(sum / 4.0)
}

/// Per tetrahedron, the distance from its centroid to the surface when the centroid lies
/// inside it (and is not on it). The corners lie on the surface (to rounding, hence the
/// thousandth), so the nearest surface point is no farther than the nearest corner: the search
/// skips every triangle beyond it (the farthest corner, the bound before, let it visit more).
fn centroid_depths(dt: &Delaunay, samples: &[Point3<f64>], solid: &SolidSurface) -> Vec<Option<f64>> {
    (0..dt.tets.len())
        .into_par_iter()
        .map(|t| {
            let c = centroid(dt, samples, t);
            let reach = dt.tets[t].iter().map(|&i| (samples[i as usize] - c).norm()).fold(f64::INFINITY, f64::min);
            solid.depth_within(&c, 1.001 * reach).filter(|&d| d > 0.0)
        })
        .collect()
}
