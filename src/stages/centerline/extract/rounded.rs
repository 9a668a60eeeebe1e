//! Ends without a boundary: rounded (dome) or blunt caps, found as the parts of the lumen that
//! the centerlines found so far do not reach.
//!
//! The balls of a centerline tree cover its lumen up to the wall. What they leave uncovered is
//! either a vessel not yet followed (a tube running on beyond them, ending in a dome) or a
//! pocket of the wall (a bulb, an ostium, a sac, a voxel step). The two differ by how far the
//! uncovered part reaches compared with its own width: a vessel reaches several of its radii
//! beyond the balls, a pocket about one. So, repeatedly: take the uncovered region reaching
//! farthest in its own radii; if it is a vessel, its end is the ball under its tip on its axis
//! (the inscribed ball under a dome, VMTK's pole of the tip; see [`deepest_tip_ball`]), and the
//! path to it joins the tree.

use super::medial::{BallGraph, Entry};
use nalgebra::Point3;
use std::collections::BinaryHeap;

/// An uncovered region is a vessel when its lumen reaches at least this many of its widest
/// ball's radii beyond the covered lumen (a bulb or sac reaches one to two). Measured on the
/// cohort: true rounded ends reach 4.3 (the synthetic AAA's domes) to 31; the pockets that came
/// closest, a sac and two blebs of the OpenLB cerebral tree, 3.0 to 3.2 ...
pub const VESSEL_REACH: f64 = 3.5;
/// ... or this many on a surface whose other vessels are cut open: segmentation tools clip
/// every vessel they follow, so a closed tip there is more likely a sac or a bleb (an elongated
/// sac reaches three).
pub const VESSEL_REACH_BESIDE_OPEN_ENDS: f64 = 4.0;
/// ... and when its end ball is at least this fraction of the covered ball it leaves from (a
/// step of a voxel surface, or a crease, holds only tiny balls).
const VESSEL_WIDTH: f64 = 0.25;
/// How far a region reaches is the reach of its largest ball among those reaching within this
/// fraction of its widest ball's radius of the farthest reach (where its end lies is
/// [`deepest_tip_ball`]'s answer).
const TIP_TOLERANCE: f64 = 0.25;
/// At most this many rounded ends are looked for (a bound on the work, far above real trees).
const MAX_ENDS: usize = 64;

/// The end nodes of the vessels that `tree` (nodes of the centerlines found so far, or a single
/// node to start from) does not reach, farthest first.
///
/// With no end to start from (`start_alone`: `tree` is a single node of the lumen, not an end),
/// the first end found (the farthest from that node) becomes the start, and the search begins
/// again from it alone: the node may lie near another end, whose tip it would hide.
pub fn rounded_ends(
    graph: &BallGraph,
    tree: &[u32],
    start_alone: bool,
    beside_open_ends: bool,
    clearance: Clearance,
) -> Vec<u32> {
    let reach = if beside_open_ends { VESSEL_REACH_BESIDE_OPEN_ENDS } else { VESSEL_REACH };
    let n = graph.nodes.len();
    let mut in_tree = vec![false; n];
    tree.iter().for_each(|&t| in_tree[t as usize] = true);
    let mut ends = vec![];
    while ends.len() < MAX_ENDS {
        let gap = gaps(graph, &in_tree);
        let Some((end, path)) = farthest_uncovered(graph, &gap, reach, clearance) else { break };
        if start_alone && ends.is_empty() {
            in_tree.iter_mut().for_each(|t| *t = false);
            in_tree[end as usize] = true;
        } else {
            path.iter().for_each(|&p| in_tree[p as usize] = true);
        }
        ends.push(end);
    }
    ends
}

/// For each node, how far its centre lies outside the union of the tree's balls (negative
/// inside); `INFINITY` when farther than the largest tree ball's diameter from every tree node.
fn gaps(graph: &BallGraph, in_tree: &[bool]) -> Vec<f64> {
    use kiddo::{ImmutableKdTree, SquaredEuclidean};
    use rayon::prelude::*;
    let members: Vec<usize> = (0..in_tree.len()).filter(|&i| in_tree[i]).collect();
    let points: Vec<[f64; 3]> = members.iter().map(|&i| graph.nodes[i].centre.into()).collect();
    let Ok(kd) = ImmutableKdTree::<f64, 3>::new_from_slice(&points) else { return vec![f64::INFINITY; in_tree.len()] };
    let widest = members.iter().map(|&i| graph.nodes[i].radius).fold(0.0, f64::max);
    let reach = 2.0 * widest;
    let gap_to = |b: &super::medial::Ball, item: u32| {
        let t = graph.nodes[members[item as usize]];
        (t.centre - b.centre).norm() - t.radius
    };
    graph
        .nodes
        .par_iter()
        .map(|b| {
            // The nearest centre bounds the gap; only balls centred within that bound plus the
            // widest radius can close it further.
            let nearest = kd.query(&b.centre.into()).nearest_one::<SquaredEuclidean<f64>>().execute();
            if nearest.distance > reach * reach {
                return f64::INFINITY;
            }
            let bound = gap_to(b, nearest.item) + widest;
            let within = bound.min(reach);
            kd.query(&b.centre.into())
                .within::<SquaredEuclidean<f64>>(within * within)
                .unsorted()
                .execute()
                .iter()
                .map(|h| gap_to(b, h.item))
                .fold(gap_to(b, nearest.item), f64::min)
        })
        .collect()
}

/// A part of the lumen the tree's balls leave uncovered, judged by its far tip.
struct Pocket {
    /// The ball under the far tip (see [`deepest_tip_ball`]).
    end: u32,
    /// How far the pocket's lumen reaches beyond the covered lumen (mm).
    tip: f64,
    /// Radius of the pocket's widest ball (mm).
    widest: f64,
    /// The covered node the path to `end` leaves from.
    root: u32,
    /// The path from `end` back to `root`.
    path: Vec<u32>,
}

impl Pocket {
    /// How far it reaches, in its own widest radii: a vessel reaches several (see
    /// [`VESSEL_REACH`]).
    fn significance(&self) -> f64 {
        self.tip / self.widest
    }
}

/// Every uncovered part of the lumen next to the covered one (`gap`, see [`gaps`]), in order of
/// its first node.
fn pockets(graph: &BallGraph, gap: &[f64], clearance: Clearance) -> Vec<Pocket> {
    let n = graph.nodes.len();
    let covered: Vec<bool> = gap.iter().map(|&g| g < 0.0).collect();
    // Distance along the lumen from the covered lumen (the union of the tree's balls): a node
    // next to it starts at its own gap, the others add straight links through uncovered nodes.
    let (mut dist, mut prev, mut root) = (vec![f64::INFINITY; n], vec![u32::MAX; n], vec![u32::MAX; n]);
    let mut heap = BinaryHeap::new();
    for u in (0..n).filter(|&u| covered[u]) {
        for &(v, _) in graph.links(u) {
            let v = v as usize;
            if !covered[v] && gap[v] < dist[v] {
                dist[v] = gap[v];
                prev[v] = u as u32;
                root[v] = u as u32;
                heap.push(Entry(gap[v], v as u32));
            }
        }
    }
    while let Some(Entry(d, u)) = heap.pop() {
        if d > dist[u as usize] {
            continue;
        }
        for &(v, _) in graph.links(u as usize) {
            if covered[v as usize] {
                continue;
            }
            let nd = d + (graph.nodes[v as usize].centre - graph.nodes[u as usize].centre).norm();
            if nd < dist[v as usize] {
                dist[v as usize] = nd;
                prev[v as usize] = u;
                root[v as usize] = root[u as usize];
                heap.push(Entry(nd, v));
            }
        }
    }
    let reach = |v: usize| dist[v] + graph.nodes[v].radius;
    let path_to = |end: usize| {
        let mut path = vec![end as u32];
        while let Some(&last) = path.last() {
            match prev[last as usize] {
                u32::MAX => break,
                p => path.push(p),
            }
        }
        path
    };
    // Uncovered regions as connected groups (by the covered node each was reached from and
    // the links between them), each judged by its farthest tip.
    regions(graph, &covered, &dist)
        .into_iter()
        .filter_map(|region| {
            let tip = region.iter().map(|&v| reach(v)).fold(f64::NEG_INFINITY, f64::max);
            let widest = region.iter().map(|&v| graph.nodes[v].radius).fold(0.0, f64::max);
            // How far the pocket reaches, as the thresholds above were measured: the reach of
            // the largest ball reaching within a quarter of the widest radius of the tip.
            let reached = region
                .iter()
                .copied()
                .filter(|&v| reach(v) >= tip - TIP_TOLERANCE * widest)
                .max_by(|&a, &b| graph.nodes[a].radius.total_cmp(&graph.nodes[b].radius).then(b.cmp(&a)))
                .map(reach)?;
            let end = deepest_tip_ball(graph, &region, &dist, clearance)?;
            Some(Pocket { end: end as u32, tip: reached, widest, root: root[end], path: path_to(end) })
        })
        .collect()
}

/// How far a point lies from the lumen surface (mm).
pub type Clearance<'a> = &'a dyn Fn(&Point3<f64>) -> f64;

/// The end ball of an uncovered region: the ball whose distance along the lumen from the
/// covered lumen (`dist`) plus twice its radius is greatest, its radius taken no larger than
/// its centre's clearance from the surface (the first of equals).
///
/// The farthest-reaching ball alone is not the tip. Under a blunt end, a flat face meeting the
/// side in rounded corners, the balls in the corners reach farther than the tube's ball against
/// the face, by up to sqrt(2) - 1 of the tube's radius for a square corner (their path turns off
/// the axis), and which corner the farthest lies in is the triangulation's whim: the abdominal
/// aorta segment written as polygons in place of triangles moved its end 12 mm across a face
/// 20 mm wide. Counting each ball's radius once more outweighs that excess, so the tube's ball
/// wins, on the axis whatever the corners; on a dome every ball under the tip reaches as far,
/// and the dome's centre ball, the largest, wins; a tube narrowing to its tip by less than a
/// radius per two radii of length keeps its end at the tip. A face sampled sparsely (a
/// decimated surface's end face, a few large triangles) leaves balls whose spheres cross it;
/// their clearance, not their radius, is what they hold.
fn deepest_tip_ball(graph: &BallGraph, region: &[usize], dist: &[f64], clearance: Clearance) -> Option<usize> {
    let depth = |v: usize, r: f64| dist[v] + 2.0 * r;
    let bound = |v: usize| depth(v, graph.nodes[v].radius);
    let held = |v: usize| depth(v, graph.nodes[v].radius.min(clearance(&graph.nodes[v].centre)));
    // The radius bounds the clearance: the ball deepest by its radius sets a floor (its depth by
    // what it holds), and only balls deeper than that by their radii may beat it, so only
    // theirs are measured (a few at a tip, not the region).
    let top = region.iter().copied().max_by(|&a, &b| bound(a).total_cmp(&bound(b)).then(b.cmp(&a)))?;
    let floor = held(top);
    region
        .iter()
        .copied()
        .filter(|&v| bound(v) >= floor)
        .map(|v| (held(v), v))
        .max_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)))
        .map(|(_, v)| v)
}

/// The most far-reaching uncovered vessel: its end node and the path from the covered lumen to
/// it, or `None` when every uncovered region is a pocket (reaching less than `vessel_reach` of
/// its widest radius, see [`VESSEL_REACH`]).
fn farthest_uncovered(
    graph: &BallGraph,
    gap: &[f64],
    vessel_reach: f64,
    clearance: Clearance,
) -> Option<(u32, Vec<u32>)> {
    let is_vessel = |p: &Pocket| {
        let (r, from) = (graph.nodes[p.end as usize].radius, graph.nodes[p.root as usize].radius);
        p.significance() >= vessel_reach && r >= VESSEL_WIDTH * from
    };
    let vessels = pockets(graph, gap, clearance).into_iter().filter(is_vessel);
    let best = vessels.fold(None, |best: Option<Pocket>, p| match best {
        Some(b) if b.significance() >= p.significance() => Some(b),
        _ => Some(p),
    })?;
    Some((best.end, best.path))
}

/// The connected groups of reachable uncovered nodes, each sorted, in order of their first node.
fn regions(graph: &BallGraph, covered: &[bool], dist: &[f64]) -> Vec<Vec<usize>> {
    let n = graph.nodes.len();
    let mut seen = vec![false; n];
    let mut out = vec![];
    for s in 0..n {
        if covered[s] || seen[s] || !dist[s].is_finite() {
            continue;
        }
        seen[s] = true;
        let mut stack = vec![s];
        let mut region = vec![];
        while let Some(u) = stack.pop() {
            region.push(u);
            for &(v, _) in graph.links(u) {
                let v = v as usize;
                if !covered[v] && !seen[v] {
                    seen[v] = true;
                    stack.push(v);
                }
            }
        }
        region.sort_unstable();
        out.push(region);
    }
    out
}

/// An uncovered pocket is a saccular aneurysm when its lumen reaches at least this many radii
/// of the vessel it opens from beyond the tree's balls. Measured on the cohort once every end is
/// found: gmsh_cerebral_aneurysm's sac reaches 3.7; every other pocket at most 1.3 (bulbs,
/// blebs, ostia, voxel steps, the rim of a capped stub).
pub const SAC_REACH: f64 = 2.5;

/// The far ends of the saccular aneurysms beside the tree (`tree`: the nodes of the centerlines
/// to every end), each the ball under its dome (see [`deepest_tip_ball`]): pockets too short
/// for a vessel (see [`VESSEL_REACH`]) but reaching far beyond the vessel they open from (see
/// [`SAC_REACH`]), whose end ball's centre lies in the lumen (`in_lumen`).
/// Farthest-reaching first; each sac's path joins the tree before the next is looked for.
///
/// The medial graph holds balls outside the lumen too, beyond its open ends: the fan closing an
/// open end is sampled as sparsely as the lumen is deep behind it (the sampling's local radius
/// is half the way across the lumen along the normal, which on a cap runs along the vessel), and
/// the Voronoi diagram of the rim's samples escapes through it, with balls wider than the
/// section centred beyond the cut (random tree 3: a ball of 4.2 mm, 3.4 mm past an open end of
/// radius 2.2 mm, taken for a sac reaching 2.5 vessel radii). No part of the lumen lies there,
/// let alone a sac, whatever the shape of the vessel.
pub fn sac_ends(
    graph: &BallGraph,
    tree: &[u32],
    in_lumen: &dyn Fn(&Point3<f64>) -> bool,
    clearance: Clearance,
) -> Vec<u32> {
    let mut in_tree = vec![false; graph.nodes.len()];
    let mut members = tree.to_vec();
    tree.iter().for_each(|&t| in_tree[t as usize] = true);
    // The vessel a pocket opens from: the tree ball holding its root most deeply.
    let vessel_radius = |members: &[u32], root: u32| {
        let c = graph.nodes[root as usize].centre;
        let depth = |t: &u32| {
            let b = graph.nodes[*t as usize];
            b.radius - (b.centre - c).norm()
        };
        members
            .iter()
            .max_by(|a, b| depth(a).total_cmp(&depth(b)).then(b.cmp(a)))
            .map(|&t| graph.nodes[t as usize].radius)
    };
    let mut ends = vec![];
    while ends.len() < MAX_ENDS {
        let gap = gaps(graph, &in_tree);
        let reach_in_vessel_radii = |p: &Pocket| vessel_radius(&members, p.root).map_or(0.0, |r| p.tip / r);
        let sac = pockets(graph, &gap, clearance)
            .into_iter()
            .map(|p| (reach_in_vessel_radii(&p), p))
            .filter(|(reach, p)| {
                let (r, from) = (graph.nodes[p.end as usize].radius, graph.nodes[p.root as usize].radius);
                *reach >= SAC_REACH && r >= VESSEL_WIDTH * from && in_lumen(&graph.nodes[p.end as usize].centre)
            })
            .fold(None, |best: Option<(f64, Pocket)>, (reach, p)| match best {
                Some(b) if b.0 >= reach => Some(b),
                _ => Some((reach, p)),
            });
        let Some((_, sac)) = sac else { break };
        for &n in &sac.path {
            if !in_tree[n as usize] {
                in_tree[n as usize] = true;
                members.push(n);
            }
        }
        ends.push(sac.end);
    }
    ends
}
