//! Networks with loops (a circle of Willis, a graft rejoining its host): where to cut each loop
//! open so that the surface becomes a tree whose centerlines are found as any tree's.
//!
//! Dijkstra from the inlet through the ball graph spreads around a loop from where the loop is
//! entered both ways, and the two fronts meet on the far side: there, links join nodes whose
//! paths back to the inlet part only where the loop was entered, a long way round. Links whose
//! paths part within a few radii are the medial axis's own small cycles (a tube's medial balls
//! form a thin sheet, not a line). Each place where long cycles close is one loop; it is cut
//! across its vessel where the cut is clean (one closed loop of the surface around the
//! centerline, the planes a radius on either side clean too: no junction there), the cleanest
//! place nearest where the fronts met. Every cut is checked on the surface: it must take one
//! loop off (its genus, [`topology::handles`]); a cut that does not is not kept.
//!
//! The two ends a cut opens are no vessel ends: the mesh joins the two branches that end there
//! into one branch from junction to junction (see
//! [`crate::data::config::CenterlineConfig::loop_cuts_mm`]), so the surface's loop is the mesh's.

use super::medial::BallGraph;
use crate::geometry::plane_cut::plane_loops;
use crate::geometry::surface::{LumenSurface, TriangleSurface};
use crate::geometry::surface_cut::{cut_across, plane_through};
use crate::io::input::topology;
use nalgebra::{Point3, Vector2, Vector3};

/// Where a loop was cut open: a point on the centerline, the vessel's direction there, and the
/// radius of its ball (mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopCut {
    pub centre: Point3<f64>,
    pub normal: Vector3<f64>,
    pub radius: f64,
}

/// A link closes a long cycle when the paths of its two nodes back to the inlet part more than
/// this many radii (of the larger ball) back from it.
const LONG_CYCLE: f64 = 4.0;
/// Links closing long cycles within this many radii of each other close the same loop.
const SAME_MEETING: f64 = 3.0;
/// A cut is clean where the plane's loop around the centre stays within this many of its
/// equivalent radii of its centroid: an oblique section of a vessel (an ellipse of axes 1.5 : 1
/// reaches 1.22) but not a junction's section, which reaches into its branches, nor one
/// around two vessels that touch (two equal circles side by side reach 1.41) ...
const CLEAN_SPAN: f64 = 1.3;
/// ... and the planes this many radii on either side along the loop are clean too.
const CLEAN_ALONG: f64 = 1.0;
/// The gap between the two ends of a cut, in ball radii: wider than an end's radius, the reach
/// within which an end is linked to the medial ball nearest it (see `BallGraph::add_end`), so
/// that no end is linked to the other side's balls (the path to it would come the other way
/// round the loop, and the vessel between would be taken for a blind end).
const CUT_GAP: f64 = 1.5;
/// The two ends a cut opens lie half its gap (0.75 radii) either side of it, a little further
/// where the section is not round (beside a junction): an end within this many of the cut's
/// radii of it is one of them.
const CUT_END_REACH: f64 = 2.0;
/// Clean cuts tried along one cycle before the next: a cut that does not open the loop (a
/// section around two vessels that touch) is seldom followed by one that does so near it.
const CUT_TRIES: usize = 8;

/// The surface opened at one cut per loop (`loops` of them, its genus), and the cuts; an error
/// names the loops that could not be cut open.
pub(super) fn open_loops(
    surface: &TriangleSurface,
    graph: &BallGraph,
    inlet: u32,
    lumen: &LumenSurface,
    loops: usize,
) -> Result<(TriangleSurface, Vec<LoopCut>), String> {
    let (prev, dist) = graph.shortest_paths(inlet);
    let cycles = long_cycles(graph, &prev, &dist);
    let mut opened = surface.clone();
    let mut cuts: Vec<LoopCut> = vec![];
    let mut left = loops;
    for cycle in &cycles {
        if left == 0 {
            break;
        }
        for cut in clean_cuts(graph, cycle, lumen).take(CUT_TRIES) {
            let Some(next) = cut_across(&opened, &cut.centre, &cut.normal, 3.0 * cut.radius, CUT_GAP * cut.radius)
            else {
                continue;
            };
            if topology::handles(&next.triangles) == Some(left - 1) {
                opened = next;
                cuts.push(cut);
                left -= 1;
                break;
            }
        }
    }
    if left > 0 {
        return Err(format!(
            "the surface has {loops} loop(s) (its genus) and {left} of them could not be cut open across a vessel \
             (found {} place(s) where paths from the inlet meet around a loop, and no clean cross-section that opens \
             the loop near them): give centerlines cut open on a vessel of each loop, with the cut points as \
             centerline.loop_cuts_mm",
            cycles.len()
        ));
    }
    Ok((opened, cuts))
}

/// Whether `p` is near one of `cuts` (see [`CUT_END_REACH`]): an end there is one of the two
/// the cut opened.
pub(super) fn near_a_cut(cuts: &[LoopCut], p: &Point3<f64>) -> bool {
    cuts.iter().any(|c| (p - c.centre).norm() < CUT_END_REACH * c.radius)
}

/// A long cycle of the ball graph: its nodes from where it leaves the inlet's tree round to
/// where it comes back, and the index where the two fronts met.
struct Cycle {
    nodes: Vec<u32>,
    meeting: usize,
}

/// The shortest-path tree from the inlet: each node's parent (`u32::MAX` at the inlet and at
/// nodes not reached), and its arc length and number of links from the inlet.
struct PathTree<'a> {
    prev: &'a [u32],
    arc: Vec<f64>,
    depth: Vec<usize>,
}

impl PathTree<'_> {
    fn new<'a>(graph: &BallGraph, prev: &'a [u32], dist: &[f64]) -> (PathTree<'a>, Vec<u32>) {
        // In order of cost: a parent before its child.
        let mut order: Vec<u32> = (0..graph.nodes.len() as u32).filter(|&n| dist[n as usize].is_finite()).collect();
        order.sort_by(|&a, &b| dist[a as usize].total_cmp(&dist[b as usize]).then(a.cmp(&b)));
        let mut tree = PathTree { prev, arc: vec![0.0; graph.nodes.len()], depth: vec![0; graph.nodes.len()] };
        for &n in &order {
            if let Some(p) = tree.parent(n) {
                let step = (graph.nodes[n as usize].centre - graph.nodes[p as usize].centre).norm();
                tree.arc[n as usize] = tree.arc[p as usize] + step;
                tree.depth[n as usize] = tree.depth[p as usize] + 1;
            }
        }
        (tree, order)
    }

    fn parent(&self, n: u32) -> Option<u32> {
        (self.prev[n as usize] != u32::MAX).then_some(self.prev[n as usize])
    }

    /// The last node the paths to `u` and `v` share (None when they share none).
    fn common(&self, mut u: u32, mut v: u32) -> Option<u32> {
        while u != v {
            let deeper = if self.depth[u as usize] >= self.depth[v as usize] { &mut u } else { &mut v };
            *deeper = self.parent(*deeper)?;
        }
        Some(u)
    }

    /// Whether the paths to `u` and `v` part further back than `reach` of arc length.
    fn part_beyond(&self, u: u32, v: u32, reach: f64) -> bool {
        let floor = self.arc[u as usize].min(self.arc[v as usize]) - reach;
        let (mut a, mut b) = (u, v);
        while a != b {
            let deeper = if self.depth[a as usize] >= self.depth[b as usize] { &mut a } else { &mut b };
            match self.parent(*deeper) {
                Some(p) if self.arc[p as usize] >= floor => *deeper = p,
                _ => return true,
            }
        }
        false
    }

    /// The length of the cycle the link `u`-`v` closes.
    fn cycle_length(&self, u: u32, v: u32) -> f64 {
        let common = self.common(u, v).map_or(0.0, |c| self.arc[c as usize]);
        self.arc[u as usize] + self.arc[v as usize] - 2.0 * common
    }

    /// The cycle the link `u`-`v` closes: from the two paths' last common node to `u`, then from
    /// `v` back to it.
    fn cycle_through(&self, u: u32, v: u32) -> Cycle {
        let common = self.common(u, v);
        let path = |mut n: u32| {
            let mut out = vec![n];
            while Some(n) != common {
                match self.parent(n) {
                    Some(p) => n = p,
                    None => break,
                }
                out.push(n);
            }
            out
        };
        let (to_u, to_v) = (path(u), path(v));
        let mut nodes: Vec<u32> = to_u.iter().rev().copied().collect();
        let meeting = nodes.len() - 1;
        nodes.extend_from_slice(&to_v[..to_v.len() - 1]);
        Cycle { nodes, meeting }
    }
}

/// One long cycle per place where fronts meet (see the module's doc), the longest first.
fn long_cycles(graph: &BallGraph, prev: &[u32], dist: &[f64]) -> Vec<Cycle> {
    let ball = |n: u32| graph.nodes[n as usize];
    let (tree, order) = PathTree::new(graph, prev, dist);
    let mut meetings: Vec<(u32, u32)> = vec![];
    for &u in &order {
        for &(v, _) in graph.links(u as usize) {
            if v <= u || !dist[v as usize].is_finite() || prev[u as usize] == v || prev[v as usize] == u {
                continue;
            }
            if tree.part_beyond(u, v, LONG_CYCLE * ball(u).radius.max(ball(v).radius)) {
                meetings.push((u, v));
            }
        }
    }
    // Grouped by place; each place's link closing the longest cycle stands for it: beside where
    // a loop's fronts meet, two vessels running side by side (a graft leaving its host at a
    // shallow angle) close short cycles of their own, and only the longest goes round the loop.
    let mut places: Vec<((u32, u32), f64)> = vec![];
    for m in meetings {
        let r = ball(m.0).radius.max(ball(m.1).radius);
        let near = places.iter_mut().find(|(p, _)| {
            let rp = ball(p.0).radius.max(ball(p.1).radius);
            (ball(p.0).centre - ball(m.0).centre).norm() < SAME_MEETING * r.max(rp)
        });
        let length = tree.cycle_length(m.0, m.1);
        match near {
            Some(p) if length > p.1 => *p = (m, length),
            Some(_) => {}
            None => places.push((m, length)),
        }
    }
    places.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    places.into_iter().map(|((u, v), _)| tree.cycle_through(u, v)).collect()
}

/// The clean cuts along a cycle, nearest where its fronts met first.
fn clean_cuts<'a>(
    graph: &'a BallGraph,
    cycle: &'a Cycle,
    lumen: &'a LumenSurface,
) -> impl Iterator<Item = LoopCut> + 'a {
    let points: Vec<Point3<f64>> = cycle.nodes.iter().map(|&n| graph.nodes[n as usize].centre).collect();
    let mut arcs = vec![0.0];
    for w in points.windows(2) {
        arcs.push(arcs[arcs.len() - 1] + (w[1] - w[0]).norm());
    }
    let at = {
        let (points, arcs) = (points.clone(), arcs.clone());
        move |s: f64| points[arcs.partition_point(|&a| a < s).min(points.len() - 1)]
    };
    let total = arcs[arcs.len() - 1];
    let meet = arcs[cycle.meeting];
    let mut order: Vec<usize> = (0..cycle.nodes.len()).collect();
    order.sort_by(|&a, &b| (arcs[a] - meet).abs().total_cmp(&(arcs[b] - meet).abs()).then(a.cmp(&b)));
    order.into_iter().filter_map(move |i| {
        let ball = graph.nodes[cycle.nodes[i] as usize];
        let (s, r) = (arcs[i], ball.radius);
        if s < 2.0 * r || s > total - 2.0 * r {
            return None;
        }
        let normal = (at(s + r) - at(s - r)).try_normalize(1e-12)?;
        let (centre, radius) = clean_section(lumen, &ball.centre, &normal, r)?;
        let along = [s - CLEAN_ALONG * radius, s + CLEAN_ALONG * radius].map(&at);
        along.iter().all(|c| clean_section(lumen, c, &normal, radius).is_some()).then_some(LoopCut {
            centre,
            normal,
            radius,
        })
    })
}

/// The cross-section through `centre` normal to `normal` when it is clean: the plane cuts the
/// surface in a closed loop around `centre` (found within a few `radius`) that keeps within
/// [`CLEAN_SPAN`] of its equivalent radius from its centroid. Its centroid and equivalent radius
/// (of a circle of its area): the vessel's, whatever ball of the medial axis `centre` was.
fn clean_section(
    lumen: &LumenSurface,
    centre: &Point3<f64>,
    normal: &Vector3<f64>,
    radius: f64,
) -> Option<(Point3<f64>, f64)> {
    let plane = plane_through(centre, normal);
    let cut = plane_loops(lumen, &plane, 4.0 * radius).into_iter().find(|l| l.contains(&Vector2::zeros()))?;
    let area = cut.signed_area().abs();
    let equivalent = (area / std::f64::consts::PI).sqrt();
    let middle = cut.plane.iter().sum::<Vector2<f64>>() / cut.plane.len() as f64;
    let round = cut.plane.iter().all(|q| (q - middle).norm() <= CLEAN_SPAN * equivalent);
    round.then(|| (plane.to_3d(&middle), equivalent))
}
