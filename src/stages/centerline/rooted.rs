//! The skeleton hung from its inlet: edges oriented with the flow, nodes that only join two
//! edges removed, junctions closer than the merge distance merged, branches put in order.

use super::skeleton::{Edge, Line, Node, Skeleton, APART};
use crate::data::error::{Error, Result};
use nalgebra::Point3;
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
    /// Nodes placed where two daughters sharing a trunk part ([`split_shared_trunks`]): on the
    /// medial axis by construction, so they are not moved to a larger ball.
    pub parted: Vec<bool>,
    /// The segments whose far junction was merged because it lay close (not forced), each kept
    /// at the upstream junction's centre.
    pub close_merges: Vec<usize>,
}

/// A junction merged into its upstream neighbour whatever their distance: the one at the end of
/// skeleton edge `segment` (a branch between two junctions), because the two junctions' block
/// patterns would overlap (see `junction::find_junction_overlap`). The merged junction is
/// centred on the segment, the fraction `at` of its length from the upstream end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ForcedMerge {
    pub segment: usize,
    pub at: f64,
}

/// Orients the skeleton from node `inlet`, joins pass-through nodes, merges junctions whose
/// centres are closer than `merge_radii` times the upstream junction's radius (or that `forced`
/// names), and orders the branches. `cascade`: daughters still fused past their junction's
/// sphere share a trunk to where they part ([`Parting::Fused`]).
pub(crate) fn hang(
    skeleton: Skeleton,
    inlet: usize,
    merge_radii: f64,
    forced: &[ForcedMerge],
    cascade: bool,
    source: &Path,
) -> Result<RootedTree> {
    let Skeleton { mut nodes, mut edges, .. } = skeleton;
    let (mut children, mut parent) = orient_from_inlet(&nodes, &mut edges, inlet, source)?;

    let first_parted = nodes.len();
    let parting = if cascade { Parting::Fused } else { Parting::SideBySide };
    split_shared_trunks(&mut nodes, &mut edges, &mut children, &mut parent, inlet, parting);
    let mut parted: Vec<bool> = (0..nodes.len()).map(|v| v >= first_parted).collect();
    let bfs = descendants(&children, &edges, inlet);

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
    let mut close_merges = vec![];
    for &j in &bfs {
        if children[j].len() < 2 {
            continue;
        }
        let reach = merge_radii * nodes[j].radius;
        let mut recentre: Option<(usize, f64)> = None;
        let degenerate = DEGENERATE_SEGMENT * nodes[j].radius;
        loop {
            let close = children[j].iter().position(|&e| {
                let k = edges[e].ends[1];
                children[k].len() >= 2
                    && ((nodes[k].point - nodes[j].point).norm() < reach
                        || edges[e].line.length() < DEGENERATE_SEGMENT * nodes[j].radius
                        || forced.iter().any(|f| f.segment == e))
            });
            let Some(at) = close else { break };
            let e = children[j][at];
            let k = edges[e].ends[1];
            if !forced.iter().any(|f| f.segment == e) && edges[e].line.length() >= degenerate {
                close_merges.push(e);
            }
            let absorbed = std::mem::take(&mut children[k]);
            for &f in &absorbed {
                let mut line = edges[e].line.clone();
                line.extend(&edges[f].line);
                edges[f].line = line;
                edges[f].ends[0] = j;
            }
            if recentre.is_none() {
                recentre = forced.iter().find(|f| f.segment == e).map(|f| (e, f.at));
            }
            children[j].splice(at..=at, absorbed);
        }
        if let (Some((segment, at)), Some(into)) = (recentre, parent[j]) {
            recentre_merged(&mut nodes[j], &mut edges, into, &children[j], segment, at);
            // On the segment by construction: not to be moved to a larger ball.
            parted[j] = true;
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
    Ok(RootedTree { nodes, edges, children, parent, order, parted, close_merges })
}

/// Orients every edge away from node `inlet` (a breadth-first walk): each node's edges out and
/// the edge into it. A loop, or an edge the walk does not reach, is an error naming the polyline.
fn orient_from_inlet(
    nodes: &[Node],
    edges: &mut [Edge],
    inlet: usize,
    source: &Path,
) -> Result<(Vec<Vec<usize>>, Vec<Option<usize>>)> {
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
        let gap =
            |p| (0..edges.len()).filter(|&e| used[e]).map(|e| edges[e].line.closest(p).0).fold(f64::INFINITY, f64::min);
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
    Ok((children, parent))
}

/// Moves a merged junction `node` onto the segment it absorbed, the fraction `at` of its length
/// along: the edge `into` it (from upstream) runs on along the segment to the new centre, the
/// daughters that came through the segment start there, and the others bend to it over a few
/// radii. Where two junctions overlap, the middle of the merged one lies between them (on the
/// aortic arch, the brachiocephalic-carotid trunk's arch-side crotch lies past its far end).
fn recentre_merged(node: &mut Node, edges: &mut [Edge], into: usize, daughters: &[usize], segment: usize, at: f64) {
    let line = edges[segment].line.clone();
    let arcs = line.arcs();
    let target = at.clamp(0.0, 1.0) * arcs[arcs.len() - 1];
    let k = (1..arcs.len()).find(|&k| arcs[k] > target).unwrap_or(arcs.len() - 1);
    let t = ((target - arcs[k - 1]) / (arcs[k] - arcs[k - 1])).clamp(0.0, 1.0);
    let mut centre = line.points[k - 1] + (line.points[k] - line.points[k - 1]) * t;
    let radius = line.radii[k - 1] + (line.radii[k] - line.radii[k - 1]) * t;
    // A centre on a point of the segment is that point (no repeated point either side of the cut).
    let on_previous = (centre - line.points[k - 1]).norm() <= SAME_POINT_MM;
    let on_next = !on_previous && (line.points[k] - centre).norm() <= SAME_POINT_MM;
    if on_previous {
        centre = line.points[k - 1];
    } else if on_next {
        centre = line.points[k];
    }
    // The segment up to the centre, and from it.
    let mut head = Line { points: line.points[..k].to_vec(), radii: line.radii[..k].to_vec(), normals: None };
    if !on_previous {
        head.points.push(centre);
        head.radii.push(radius);
    }
    let skip = if on_next { k + 1 } else { k };
    let shift = centre - node.point;
    let blend = (super::bend::BLEND_MOVES * shift.norm()).max(2.0 * node.radius);
    for &d in daughters {
        let l = &mut edges[d].line;
        if l.points.len() >= line.points.len() && l.points[..line.points.len()] == line.points[..] {
            // Came through the segment: starts at the centre.
            l.points.splice(0..skip, [centre]);
            l.radii.splice(0..skip, [radius]);
            l.normals = None;
        } else {
            super::bend::bend_end(&mut l.points, &mut l.radii, true, shift, radius, blend);
        }
    }
    if head.points.len() >= 2 {
        edges[into].line.extend(&head);
    }
    node.point = centre;
    node.radius = radius;
}

/// Points closer than this (mm) are one (as the centerline reader drops repeated points).
const SAME_POINT_MM: f64 = 1e-9;

/// Two daughters of a node that run together (within [`APART`] radii of each other) for at
/// least this many radii from it share a trunk.
const SHARED_TRUNK: f64 = 1.0;

/// Nodes in breadth-first order from `inlet` along the children lists.
fn descendants(children: &[Vec<usize>], edges: &[Edge], inlet: usize) -> Vec<usize> {
    let mut order = vec![inlet];
    let mut next = 0;
    while next < order.len() {
        let u = order[next];
        next += 1;
        order.extend(children[u].iter().map(|&e| edges[e].ends[1]));
    }
    order
}

/// When two daughters of a node share a trunk.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Parting {
    /// Their paths run side by side: within [`APART`] radii of each other for at least
    /// [`SHARED_TRUNK`] radii (paths drawn separately to two outlets through one vessel).
    SideBySide,
    /// Their lumens are still fused where the junction's transitions end: each path lies
    /// within the other's inscribed tube (no farther from it than the larger of their radii,
    /// VMTK's criterion for splitting branches) beyond the junction's sphere plus the
    /// daughter's radius. A junction there would lay its pages across one lumen; the two share
    /// a trunk to where they part, and the junction becomes a cascade of bifurcations. As
    /// narrow as 12 degrees apart, two daughters of one radius part about five radii out.
    Fused,
}

/// Where two lines from a node (radius `node_radius`) at their common first point part, as
/// `rule` says: the index of `a`'s first point apart from `b`, when the two share a trunk
/// before it and `a` goes on after it.
fn parting(a: &Line, b: &Line, node_radius: f64, rule: Parting) -> Option<usize> {
    let arcs = a.arcs();
    let radius_of_b = |p: &Point3<f64>| {
        let (_, seg, t) = b.closest(p);
        b.radii[seg] * (1.0 - t) + b.radii[seg + 1] * t
    };
    let apart = |k: usize| {
        let gap = b.closest(&a.points[k]).0;
        match rule {
            Parting::SideBySide => gap > APART * a.radii[k],
            Parting::Fused => gap > a.radii[k].max(radius_of_b(&a.points[k])),
        }
    };
    let k = (1..a.points.len()).find(|&k| apart(k))?;
    let shared = match rule {
        Parting::SideBySide => arcs[k] >= SHARED_TRUNK * a.radii[k],
        Parting::Fused => arcs[k] >= node_radius + a.radii[k],
    };
    (k >= 2 && k + 1 < a.points.len() && shared).then_some(k)
}

/// Daughters that leave a node side by side and part only later (paths drawn separately to two
/// outlets through one common vessel, as gmsh's centerlines of the arch run to the
/// brachiocephalic and left carotid arteries through their common origin) become a trunk, the
/// mean of the two up to where they part, and a junction there. Without this the two would
/// leave the upstream junction in the same direction, which no book of pages can order. Under
/// [`Parting::Fused`] so do daughters whose lumens are still fused past the node's sphere.
fn split_shared_trunks(
    nodes: &mut Vec<Node>,
    edges: &mut Vec<Edge>,
    children: &mut Vec<Vec<usize>>,
    parent: &mut Vec<Option<usize>>,
    inlet: usize,
    rule: Parting,
) {
    let mut work = vec![inlet];
    while let Some(u) = work.pop() {
        'again: loop {
            for (i, j) in pairs_to_part(&children[u], edges, nodes[u].radius, rule) {
                let (ea, eb) = (children[u][i], children[u][j]);
                let Some(k) = parting(&edges[ea].line, &edges[eb].line, nodes[u].radius, rule) else { continue };
                let Some((trunk, tail_a, tail_b)) = part_lines(&edges[ea].line, &edges[eb].line, k) else {
                    continue;
                };
                let w = nodes.len();
                let last = trunk.points.len() - 1;
                nodes.push(Node { point: trunk.points[last], radius: trunk.radii[last], key: i64::MAX });
                let t = edges.len();
                edges.push(Edge { ends: [u, w], line: trunk, source: edges[ea].source });
                edges[ea].line = tail_a;
                edges[ea].ends[0] = w;
                edges[eb].line = tail_b;
                edges[eb].ends[0] = w;
                children[u].retain(|&e| e != ea && e != eb);
                children[u].push(t);
                children.push(vec![ea, eb]);
                parent.push(Some(t));
                continue 'again;
            }
            break;
        }
        work.extend(children[u].iter().map(|&e| edges[e].ends[1]));
    }
}

/// The ordered pairs of a node's daughters (indices into `daughters`) to try for a shared
/// trunk: side by side, every pair in order; fused, the pair fused longest first (it parts
/// last, so its trunk is the innermost, and a third daughter fused with both parts from that
/// trunk nearer the junction), then the rest in order.
fn pairs_to_part(daughters: &[usize], edges: &[Edge], node_radius: f64, rule: Parting) -> Vec<(usize, usize)> {
    let n = daughters.len();
    let mut pairs: Vec<(usize, usize)> =
        (0..n).flat_map(|i| (0..n).map(move |j| (i, j))).filter(|(i, j)| i != j).collect();
    if rule == Parting::Fused {
        let shared = |&(i, j): &(usize, usize)| {
            let (a, b) = (&edges[daughters[i]].line, &edges[daughters[j]].line);
            parting(a, b, node_radius, rule).map_or(0.0, |k| a.arcs()[k])
        };
        let mut keyed: Vec<(f64, (usize, usize))> = pairs.iter().map(|p| (shared(p), *p)).collect();
        keyed.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
        pairs = keyed.into_iter().map(|(_, p)| p).collect();
    }
    pairs
}

/// The trunk (mean of `a` and `b` up to point `k - 1` of `a`, the last one before they part)
/// and the two tails from its end; None when either line does not go on past that point.
fn part_lines(a: &Line, b: &Line, k: usize) -> Option<(Line, Line, Line)> {
    let on_b = |p: &Point3<f64>| {
        let (_, seg, t) = b.closest(p);
        let q = b.points[seg] + (b.points[seg + 1] - b.points[seg]) * t;
        let r = b.radii[seg] * (1.0 - t) + b.radii[seg + 1] * t;
        (q, r, seg)
    };
    let normal_of = |l: &Line, i: usize| l.normals.as_ref().map(|n| n[i]);
    let mut trunk = Line { points: vec![], radii: vec![], normals: a.normals.as_ref().map(|_| vec![]) };
    for i in 0..k {
        let (q, r) = if i == 0 {
            (a.points[0], a.radii[0])
        } else {
            let (q, r, _) = on_b(&a.points[i]);
            (q, r)
        };
        let p = Point3::from((a.points[i].coords + q.coords) * 0.5);
        if trunk.points.last().is_some_and(|l: &Point3<f64>| (l - p).norm() < 1e-9) {
            continue;
        }
        trunk.points.push(p);
        trunk.radii.push(0.5 * (a.radii[i] + r));
        if let (Some(n), Some(m)) = (&mut trunk.normals, normal_of(a, i)) {
            n.push(m);
        }
    }
    let end = trunk.points[trunk.points.len() - 1];
    let end_r = trunk.radii[trunk.radii.len() - 1];
    // A tail: the trunk's end, then the line from point `from` on (the points at the trunk's
    // end itself dropped: a line has no repeated points); None when nothing is left.
    let tail = |l: &Line, from: usize, seam: usize| -> Option<Line> {
        let mut out =
            Line { points: vec![end], radii: vec![end_r], normals: l.normals.as_ref().map(|n| vec![n[seam]]) };
        for i in (from..l.points.len()).filter(|&i| (l.points[i] - end).norm() > 1e-9) {
            out.points.push(l.points[i]);
            out.radii.push(l.radii[i]);
            if let (Some(n), Some(m)) = (&mut out.normals, normal_of(l, i)) {
                n.push(m);
            }
        }
        (out.points.len() >= 2).then_some(out)
    };
    let (_, _, seg) = on_b(&a.points[k - 1]);
    Some((trunk, tail(a, k, k - 1)?, tail(b, seg + 1, seg)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(points: Vec<Point3<f64>>) -> Line {
        let n = points.len();
        Line { points, radii: vec![1.0; n], normals: None }
    }

    /// From the junction at (0, 0, 10) two paths run up the z axis 8 mm side by side (apart by
    /// 2 % of the way, well inside a quarter radius), then leave towards +x and -x.
    #[test]
    fn paths_running_together_become_a_trunk_and_a_junction_where_they_part() {
        let path = |side: f64| {
            let mut p: Vec<Point3<f64>> =
                (0..=32).map(|i| i as f64 * 0.25).map(|t| Point3::new(side * 0.01 * t, 0.0, 10.0 + t)).collect();
            p.extend((1..=20).map(|i| i as f64 * 0.25).map(|s| Point3::new(side * (0.08 + s), 0.0, 18.0 + s)));
            line(p)
        };
        let (a, b) = (path(1.0), path(-1.0));
        let node = |p: Point3<f64>| Node { point: p, radius: 1.0, key: 0 };
        let mut nodes = vec![
            node(Point3::origin()),
            node(Point3::new(0.0, 0.0, 10.0)),
            node(*a.points.last().unwrap()),
            node(*b.points.last().unwrap()),
        ];
        let inlet = line((0..=10).map(|i| Point3::new(0.0, 0.0, i as f64)).collect());
        let mut edges = vec![
            Edge { ends: [0, 1], line: inlet, source: 0 },
            Edge { ends: [1, 2], line: a, source: 1 },
            Edge { ends: [1, 3], line: b, source: 2 },
        ];
        let mut children = vec![vec![0], vec![1, 2], vec![], vec![]];
        let mut parent = vec![None, Some(0), Some(1), Some(2)];
        split_shared_trunks(&mut nodes, &mut edges, &mut children, &mut parent, 0, Parting::SideBySide);

        assert_eq!(nodes.len(), 5, "one new node");
        let w = 4;
        assert_eq!(children[1].len(), 1, "the junction keeps one daughter, the trunk");
        let trunk = &edges[children[1][0]];
        assert_eq!(trunk.ends, [1, w]);
        assert_eq!(children[w], vec![1, 2], "both paths leave the new junction");
        assert!((nodes[w].point - Point3::new(0.0, 0.0, 18.0)).norm() < 0.3, "{:?}", nodes[w].point);
        assert!(nodes[w].point.x.abs() < 1e-3, "the trunk is the mean of the two paths: {:?}", nodes[w].point);
        for e in [1, 2] {
            assert_eq!(edges[e].line.points[0], nodes[w].point, "edge {e} starts at the new junction");
            assert!(edges[e].line.points.windows(2).all(|s| (s[1] - s[0]).norm() > 1e-9));
        }
        assert_eq!(trunk.line.points[0], nodes[1].point);
        assert_eq!(*trunk.line.points.last().unwrap(), nodes[w].point);
        assert_eq!(parent[w], Some(children[1][0]));

        // Paths that part at once stay as they are.
        let mut nodes2 = nodes[..4].to_vec();
        let quick =
            |side: f64| line((0..=20).map(|i| i as f64 * 0.25).map(|s| Point3::new(side * s, 0.0, 10.0 + s)).collect());
        let mut edges2 = vec![
            edges[0].clone(),
            Edge { ends: [1, 2], line: quick(1.0), source: 1 },
            Edge { ends: [1, 3], line: quick(-1.0), source: 2 },
        ];
        let mut children2 = vec![vec![0], vec![1, 2], vec![], vec![]];
        let mut parent2 = vec![None, Some(0), Some(1), Some(2)];
        split_shared_trunks(&mut nodes2, &mut edges2, &mut children2, &mut parent2, 0, Parting::SideBySide);
        assert_eq!(nodes2.len(), 4);
        assert_eq!(children2[1], vec![1, 2]);
    }
    /// A junction at (0, 0, 10) of radius 1 with three daughters of radius 1 up z: two leave 12
    /// degrees apart (their paths a radius apart about 4.8 radii out, past the junction's sphere
    /// and a radius: fused), the third 60 degrees from them. Fused, the 12-degree pair shares a
    /// trunk to where they are a radius apart; side by side, they part at once (a quarter radius
    /// 1.2 radii out, which a close merge takes back), and the 60-degree daughter never.
    #[test]
    fn daughters_fused_past_their_junction_share_a_trunk_to_where_their_lumens_part() {
        let ray = |deg: f64| {
            let (s, c) = deg.to_radians().sin_cos();
            line((0..=60).map(|i| i as f64 * 0.2).map(|t| Point3::new(s * t, 0.0, 10.0 + c * t)).collect())
        };
        let build = |rule: Parting| {
            let node = |p: Point3<f64>| Node { point: p, radius: 1.0, key: 0 };
            let daughters = [ray(-6.0), ray(6.0), ray(66.0)];
            let mut nodes = vec![node(Point3::origin()), node(Point3::new(0.0, 0.0, 10.0))];
            nodes.extend(daughters.iter().map(|d| node(*d.points.last().unwrap())));
            let inlet = line((0..=10).map(|i| Point3::new(0.0, 0.0, i as f64)).collect());
            let mut edges = vec![Edge { ends: [0, 1], line: inlet, source: 0 }];
            edges.extend(daughters.into_iter().enumerate().map(|(i, l)| Edge {
                ends: [1, i + 2],
                line: l,
                source: i + 1,
            }));
            let mut children = vec![vec![0], vec![1, 2, 3], vec![], vec![], vec![]];
            let mut parent = vec![None, Some(0), Some(1), Some(2), Some(3)];
            split_shared_trunks(&mut nodes, &mut edges, &mut children, &mut parent, 0, rule);
            (nodes, edges, children)
        };
        let (nodes, edges, children) = build(Parting::Fused);
        assert_eq!(nodes.len(), 6, "one new junction");
        let w = 5;
        assert_eq!(children[1].len(), 2, "the junction keeps the 60-degree daughter and the trunk");
        assert!(children[1].contains(&3));
        assert_eq!(children[w], vec![1, 2], "the fused pair leaves the new junction");
        let out = nodes[w].point - nodes[1].point;
        assert!(out.x.abs() < 0.05 && (4.0..5.0).contains(&out.z), "parts about 4.8 radii out on the mean: {out:?}");
        for e in [1, 2] {
            assert_eq!(edges[e].line.points[0], nodes[w].point, "edge {e} starts at the new junction");
        }
        let gap = (edges[1].line.points[1] - edges[2].line.points[1]).norm();
        assert!(gap > 0.95, "past the new junction the pair is a radius apart: {gap}");
        let (nodes, _, children) = build(Parting::SideBySide);
        assert_eq!(nodes.len(), 6, "side by side the pair parts too");
        assert!((nodes[5].point - nodes[1].point).norm() < 1.5, "but at once: {:?}", nodes[5].point);
        assert_eq!(children[1].len(), 2);
    }

    /// A junction at (0, 0, 10) with a side branch along +x and a 6 mm trunk up z that divides
    /// at (0, 0, 16): merged with the centre put 3/4 along the trunk, the inlet runs on to
    /// (0, 0, 14.5), the trunk's daughters start there (their lines keep the trunk's last 1.5 mm),
    /// and the side branch bends to it while its far part stays.
    #[test]
    fn a_forced_merge_centres_the_junction_on_the_absorbed_segment() {
        use nalgebra::Vector3;
        let node = |p: Point3<f64>| Node { point: p, radius: 1.0, key: 0 };
        let up = |a: f64, b: f64| {
            line((0..=((b - a) * 4.0) as usize).map(|i| Point3::new(0.0, 0.0, a + 0.25 * i as f64)).collect())
        };
        let out = |from: Point3<f64>, d: Vector3<f64>| line((0..=40).map(|i| from + d * (0.25 * i as f64)).collect());
        let (j, k) = (Point3::new(0.0, 0.0, 10.0), Point3::new(0.0, 0.0, 16.0));
        let side = out(j, Vector3::x());
        let (left, right) = (out(k, Vector3::new(-0.6, 0.0, 0.8)), out(k, Vector3::new(0.6, 0.0, 0.8)));
        let nodes = vec![
            node(Point3::origin()),
            node(j),
            node(*side.points.last().unwrap()),
            node(k),
            node(*left.points.last().unwrap()),
            node(*right.points.last().unwrap()),
        ];
        let edges = vec![
            Edge { ends: [0, 1], line: up(0.0, 10.0), source: 0 },
            Edge { ends: [1, 2], line: side.clone(), source: 1 },
            Edge { ends: [1, 3], line: up(10.0, 16.0), source: 2 },
            Edge { ends: [3, 4], line: left, source: 3 },
            Edge { ends: [3, 5], line: right, source: 4 },
        ];
        let skeleton = Skeleton { nodes, edges, file_start: Some(0), layout: "test" };
        let tree = hang(skeleton, 0, 0.0, &[ForcedMerge { segment: 2, at: 0.75 }], false, Path::new("t")).unwrap();
        let centre = Point3::new(0.0, 0.0, 14.5);
        assert_eq!(tree.children[1].len(), 3, "one junction of three daughters");
        assert!((tree.nodes[1].point - centre).norm() < 1e-12, "{:?}", tree.nodes[1].point);
        assert!(tree.parted[1], "not moved again to a larger ball");
        let inlet = &tree.edges[tree.parent[1].unwrap()].line;
        assert_eq!(*inlet.points.last().unwrap(), tree.nodes[1].point);
        assert!((inlet.length() - 14.5).abs() < 1e-9, "the inlet runs on along the trunk");
        for &d in &tree.children[1] {
            let l = &tree.edges[d].line;
            assert_eq!(l.points[0], tree.nodes[1].point, "daughter {d} starts at the centre");
            assert!(l.points.windows(2).all(|s| (s[1] - s[0]).norm() > 1e-9), "no repeated point");
        }
        for d in [3, 4] {
            assert!((tree.edges[d].line.length() - 11.5).abs() < 1e-9, "1.5 mm of trunk, then 10 mm of branch");
        }
        let bent = &tree.edges[1].line;
        assert_eq!(bent.points.last(), side.points.last(), "the side branch's far end stays");
    }
}
