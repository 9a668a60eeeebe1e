//! The network's graph and its checks before meshing: the independent loops (a cycle basis of
//! the segment graph, whose size is the genus the surface must have), and the walls' clearance.

use super::model::{GraphSegment, Network};
use crate::synthetic_tree::model::{Contact, Piece};
use crate::synthetic_tree::truth::Node;
use std::collections::{HashMap, VecDeque};

/// A node as a hashable key: (0, end) or (1, junction).
type NodeKey = (u8, usize);

fn node_key(n: Node) -> NodeKey {
    match n {
        Node::End(i) => (0, i),
        Node::Junction(i) => (1, i),
    }
}

/// A basis of the graph's cycles: a breadth-first spanning tree from the first node, and for
/// each segment off it the cycle it closes (the segment, then the tree paths from its two nodes
/// to where they meet), as segment indices. Its size is E - V + 1 for a connected graph.
pub fn independent_loops(segments: &[GraphSegment]) -> Vec<Vec<usize>> {
    let mut adjacent: HashMap<NodeKey, Vec<(usize, NodeKey)>> = HashMap::new();
    for (i, s) in segments.iter().enumerate() {
        let (a, b) = (node_key(s.from), node_key(s.to));
        adjacent.entry(a).or_default().push((i, b));
        adjacent.entry(b).or_default().push((i, a));
    }
    let Some(root) = segments.first().map(|s| node_key(s.from)) else { return Vec::new() };
    // Per node reached: the segment to its parent and the parent.
    let mut parent: HashMap<NodeKey, Option<(usize, NodeKey)>> = HashMap::from([(root, None)]);
    let mut in_tree = vec![false; segments.len()];
    let mut queue = VecDeque::from([root]);
    while let Some(n) = queue.pop_front() {
        for &(seg, m) in &adjacent[&n] {
            if let std::collections::hash_map::Entry::Vacant(e) = parent.entry(m) {
                e.insert(Some((seg, n)));
                in_tree[seg] = true;
                queue.push_back(m);
            }
        }
    }
    let path_up = |mut n: NodeKey| {
        let mut out = Vec::new();
        while let Some(Some((seg, up))) = parent.get(&n) {
            out.push((*seg, *up));
            n = *up;
        }
        out
    };
    let mut loops = Vec::new();
    for (i, s) in segments.iter().enumerate().filter(|(i, _)| !in_tree[*i]) {
        let (up_a, up_b) = (path_up(node_key(s.from)), path_up(node_key(s.to)));
        // Drop the common part of the two paths to the root.
        let common = up_a.iter().rev().zip(up_b.iter().rev()).take_while(|(x, y)| x == y).count();
        let mut cycle = vec![i];
        cycle.extend(up_a[..up_a.len() - common].iter().map(|x| x.0));
        cycle.extend(up_b[..up_b.len() - common].iter().rev().map(|x| x.0));
        loops.push(cycle);
    }
    loops
}

impl Network {
    /// Whether a contact between tubes `a` and `b` lies where a junction they share lets their
    /// walls meet: within each one's reach of it, along each.
    fn joined_at(&self, a: usize, b: usize, c: &Contact) -> bool {
        self.junctions.iter().any(|j| {
            let on_a = j.on.iter().find(|o| o.0 == a);
            let on_b = j.on.iter().find(|o| o.0 == b);
            match (on_a, on_b) {
                (Some(&(_, sa, ra)), Some(&(_, sb, rb))) => {
                    self.tubes[a].along(c.sp, sa) <= ra && self.tubes[b].along(c.sq, sb) <= rb
                }
                _ => false,
            }
        })
    }

    /// The gap the walls need at a contact: two cells, plus a third of the width of any blend
    /// zone of either tube acting between the walls there (the cubic blend fuses walls closer
    /// than that).
    fn needed_gap(&self, a: usize, b: usize, c: &Contact) -> f64 {
        let towards = (c.p - c.q).try_normalize(1e-300).unwrap_or_else(nalgebra::Vector3::zeros);
        let between = nalgebra::center(&c.wall_point(), &(c.q + towards * c.rq));
        let zones = self.tubes[a].zones.iter().chain(&self.tubes[b].zones);
        let acting = zones.filter(|z| z.distance(&between) < z.outer);
        self.gap_min + acting.map(|z| z.k / 3.0).fold(0.0, f64::max)
    }

    /// The first pair of walls too close that no shared junction joins, described; `None` when
    /// every pair keeps its gap (end guards included).
    pub fn clearance_defect(&self) -> Option<String> {
        let pieces: Vec<Vec<Piece>> = (0..self.tubes.len()).map(|i| self.pieces(i)).collect();
        let largest_blend = self.tubes.iter().flat_map(|t| &t.zones).map(|z| z.k).fold(0.0, f64::max);
        let pad = self.gap_min + largest_blend / 3.0;
        for a in 0..pieces.len() {
            for b in a + 1..pieces.len() {
                for x in &pieces[a] {
                    for y in &pieces[b] {
                        if !near(x, y, pad) {
                            continue;
                        }
                        let c = x.gap_to(y);
                        if c.gap < self.needed_gap(a, b, &c) && !self.joined_at(a, b, &c) {
                            return Some(format!(
                                "the walls of {} and {} come within {:.3} mm at ({:.4}, {:.4}, {:.4}) mm",
                                self.tubes[a].name, self.tubes[b].name, c.gap, c.p.x, c.p.y, c.p.z
                            ));
                        }
                    }
                }
            }
        }
        None
    }
}

/// Whether the bounding boxes of two pieces' tubes, padded by `pad`, overlap.
fn near(x: &Piece, y: &Piece, pad: f64) -> bool {
    let (rx, ry) = (x.ra.max(x.rb) + pad, y.ra.max(y.rb) + pad);
    (0..3).all(|k| {
        let (lx, hx) = (x.a[k].min(x.b[k]) - rx, x.a[k].max(x.b[k]) + rx);
        let (ly, hy) = (y.a[k].min(y.b[k]) - ry, y.a[k].max(y.b[k]) + ry);
        lx <= hy && ly <= hx
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(from: Node, to: Node) -> GraphSegment {
        GraphSegment { tube: 0, from, to, s0: 0.0, s1: 1.0 }
    }

    #[test]
    fn a_ring_with_spokes_has_one_loop_through_its_ring_segments() {
        let j = Node::Junction;
        let segments = vec![
            seg(Node::End(0), j(0)),
            seg(j(0), j(1)),
            seg(j(1), j(2)),
            seg(j(2), j(0)),
            seg(j(1), Node::End(1)),
            seg(j(2), Node::End(2)),
        ];
        let loops = independent_loops(&segments);
        assert_eq!(loops.len(), 1);
        let mut ring = loops[0].clone();
        ring.sort_unstable();
        assert_eq!(ring, vec![1, 2, 3]);
    }
}
