//! The skeleton hung from its inlet: edges oriented with the flow, nodes that only join two
//! edges removed, junctions closer than the merge distance merged, branches put in order.

use super::skeleton::{Edge, Node, Skeleton};
use crate::error::{Error, Result};
use std::path::Path;

/// Junction-to-junction segments shorter than this many radii are always merged away, whatever
/// the configured merge distance: a branch needs some length to carry a frame.
const DEGENERATE_SEGMENT: f64 = 1e-6;

/// The tree as edges (future branches) between nodes, oriented from the inlet.
#[derive(Debug, Clone)]
pub(crate) struct RootedTree {
    pub nodes: Vec<Node>,
    /// Every edge of the skeleton; only those in `order` are still part of the tree.
    pub edges: Vec<Edge>,
    /// Edges leaving each node, sorted by the file order of the first outlet they lead to.
    pub children: Vec<Vec<usize>>,
    /// The edge arriving at each node (None at the inlet).
    pub parent: Vec<Option<usize>>,
    /// Live edges, parents before daughters, a junction's daughters next to each other.
    pub order: Vec<usize>,
}

/// Orients the skeleton from node `inlet`, joins pass-through nodes, merges junctions whose
/// centres are closer than `merge_radii` times the upstream junction's radius, and orders the
/// branches.
pub(crate) fn hang(skeleton: Skeleton, inlet: usize, merge_radii: f64, source: &Path) -> Result<RootedTree> {
    let Skeleton { nodes, mut edges, .. } = skeleton;
    let mut incident: Vec<Vec<usize>> = vec![vec![]; nodes.len()];
    for (i, e) in edges.iter().enumerate() {
        incident[e.ends[0]].push(i);
        incident[e.ends[1]].push(i);
    }
    let mut children: Vec<Vec<usize>> = vec![vec![]; nodes.len()];
    let mut parent: Vec<Option<usize>> = vec![None; nodes.len()];
    let mut seen = vec![false; nodes.len()];
    let mut used = vec![false; edges.len()];
    let mut bfs = vec![inlet];
    seen[inlet] = true;
    let mut next = 0;
    while next < bfs.len() {
        let u = bfs[next];
        next += 1;
        for &e in &incident[u] {
            if used[e] {
                continue;
            }
            used[e] = true;
            if edges[e].ends[1] == u {
                edges[e].line = edges[e].line.reversed();
                edges[e].ends.swap(0, 1);
            }
            let v = edges[e].ends[1];
            if seen[v] {
                let p = nodes[v].point;
                return Err(Error::input(
                    source,
                    format!(
                        "the centerlines form a closed loop: polyline {} reaches ({:.3}, {:.3}, {:.3}) mm, which the \
                         tree already reaches another way from the inlet; a vessel tree has no loops, remove one \
                         polyline of the loop",
                        edges[e].source, p.x, p.y, p.z
                    ),
                ));
            }
            seen[v] = true;
            parent[v] = Some(e);
            children[u].push(e);
            bfs.push(v);
        }
    }
    if let Some(lost) = (0..edges.len()).find(|&e| !used[e]) {
        let line = &edges[lost].line;
        let gap = |p| {
            (0..edges.len())
                .filter(|&e| used[e])
                .map(|e| edges[e].line.closest(p).0)
                .fold(f64::INFINITY, f64::min)
        };
        let (a, b) = (line.points[0], line.points[line.points.len() - 1]);
        return Err(Error::input(
            source,
            format!(
                "polyline {} (from ({:.3}, {:.3}, {:.3}) to ({:.3}, {:.3}, {:.3}) mm) does not connect to the others: \
                 its ends are {:.3} and {:.3} mm from the nearest other polyline. Polylines must meet at a shared \
                 point (or all start at the inlet)",
                edges[lost].source,
                a.x,
                a.y,
                a.z,
                b.x,
                b.y,
                b.z,
                gap(&a),
                gap(&b)
            ),
        ));
    }

    // A node between exactly two edges is no junction: join the edges.
    for &v in &bfs {
        if v == inlet || children[v].len() != 1 {
            continue;
        }
        let (into, out) = (parent[v].expect("a non-inlet node has a parent"), children[v][0]);
        let tail = edges[out].clone();
        edges[into].line.extend(&tail.line);
        edges[into].ends[1] = tail.ends[1];
        parent[tail.ends[1]] = Some(into);
        children[v].clear();
    }

    // Merge junctions into the upstream one when their centres are close.
    for &j in &bfs {
        if children[j].len() < 2 {
            continue;
        }
        let reach = merge_radii * nodes[j].radius;
        loop {
            let close = children[j].iter().position(|&e| {
                let k = edges[e].ends[1];
                children[k].len() >= 2
                    && ((nodes[k].point - nodes[j].point).norm() < reach
                        || edges[e].line.length() < DEGENERATE_SEGMENT * nodes[j].radius)
            });
            let Some(at) = close else { break };
            let e = children[j][at];
            let k = edges[e].ends[1];
            let absorbed = std::mem::take(&mut children[k]);
            for &f in &absorbed {
                let mut line = edges[e].line.clone();
                line.extend(&edges[f].line);
                edges[f].line = line;
                edges[f].ends[0] = j;
            }
            children[j].splice(at..=at, absorbed);
        }
    }

    // Daughters in the file order of their first outlet.
    let mut key: Vec<i64> = nodes.iter().map(|n| n.key).collect();
    for &v in bfs.iter().rev() {
        if let Some(k) = children[v].iter().map(|&e| key[edges[e].ends[1]]).min() {
            key[v] = k;
        }
    }
    for c in children.iter_mut() {
        c.sort_by_key(|&e| (key[edges[e].ends[1]], e));
    }
    for &e in children.iter().flatten() {
        parent[edges[e].ends[1]] = Some(e);
    }
    let mut order = children[inlet].clone();
    let mut next = 0;
    while next < order.len() {
        let e = order[next];
        next += 1;
        order.extend(children[edges[e].ends[1]].iter().copied());
    }
    Ok(RootedTree {
        nodes,
        edges,
        children,
        parent,
        order,
    })
}
