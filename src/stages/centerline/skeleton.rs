//! The shape of a centerline file as a graph: nodes (vessel ends and junctions) joined by edges
//! (polylines with a radius at every point), whatever the file's layout.
//!
//! Three layouts are recognised:
//!
//! * **Overlapping paths** (VMTK's `vmtkcenterlines`, our own extraction, gmsh's centerlines):
//!   one polyline per outlet, all from one common end, coinciding up to where they separate.
//!   Where two paths separate is found geometrically ([`separation`]); the paths are grouped by
//!   single linkage on those separation points (a maximum spanning tree cut at its weakest
//!   link), which gives the branching order even when the paths differ by a little noise.
//! * **Branch-split paths** (`vmtkbranchextractor`: CenterlineIds, TractIds, GroupIds,
//!   Blanking): the tracts of each centerline are joined back into its path; the sequence of
//!   unblanked groups along each path gives the branching order exactly (two centerlines are on
//!   the same branch as long as they are in the same group), and the junction is placed by the
//!   same geometric rule as for overlapping paths, so a VMTK file and its branch-split version
//!   give the same tree.
//! * **A network**: polylines that meet at their end points (or an end point lying on another
//!   polyline), as a user or a tool that writes one polyline per branch produces. Ends shared by
//!   three or more polylines are junctions.
//!
//! A junction's centre, for paths, is the point where the paths separate: the last point of the
//! shared part, found by walking back from where one path has left the other by
//! [`APART`] radii to where they were still within [`TOGETHER`] radii. On Voronoi-based paths
//! (VMTK) this is the vertex where the medial axis branches: the paths are identical up to it
//! (measured on `vmtk_aortoiliac`: distance 0 up to 31 mm, then growing steadily). The
//! alternative suggested in BRANCHING.md, the largest inscribed sphere of the junction region, is
//! not well defined there: through the aorto-iliac junction the radius falls monotonically
//! (7.0 mm at the separation to 5.3 mm where the iliacs leave each other's tubes), so the
//! largest sphere is wherever the region is made to start.

use crate::data::error::{Error, Result};
use indexmap::IndexMap;
use nalgebra::{Point3, Vector3};
use std::path::Path;

/// End points closer than this many radii are one point.
pub(crate) const SAME_POINT: f64 = 0.05;
/// A path has left another when it is this many radii (its own) away from it.
pub(crate) const APART: f64 = 0.25;
/// ... and the separation is placed where they were last this close,
pub(crate) const TOGETHER: f64 = 0.02;
/// ... looking back at most this many radii.
const WALK_BACK: f64 = 2.0;
/// Segments searched either side of the last closest one while two paths run together.
const NEAR: usize = 16;
/// Polylines from a common end are overlapping paths when two of them run together for at
/// least this many radii of that end.
const OVERLAP: f64 = 0.5;

/// A polyline with a positive radius at every point and no repeated points.
#[derive(Debug, Clone)]
pub(crate) struct Line {
    pub points: Vec<Point3<f64>>,
    pub radii: Vec<f64>,
    pub normals: Option<Vec<Vector3<f64>>>,
}

impl Line {
    pub fn reversed(&self) -> Line {
        let mut l = self.clone();
        l.points.reverse();
        l.radii.reverse();
        if let Some(n) = &mut l.normals {
            n.reverse();
        }
        l
    }

    /// Cumulative arc length at every point.
    pub fn arcs(&self) -> Vec<f64> {
        let mut s = Vec::with_capacity(self.points.len());
        s.push(0.0);
        for w in self.points.windows(2) {
            s.push(s[s.len() - 1] + (w[1] - w[0]).norm());
        }
        s
    }

    pub fn length(&self) -> f64 {
        self.points.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
    }

    fn first(&self) -> Point3<f64> {
        self.points[0]
    }

    fn last(&self) -> Point3<f64> {
        self.points[self.points.len() - 1]
    }

    /// Appends `other`, whose first point is this line's last (dropped).
    pub fn extend(&mut self, other: &Line) {
        self.points.extend_from_slice(&other.points[1..]);
        self.radii.extend_from_slice(&other.radii[1..]);
        self.normals = match (self.normals.take(), &other.normals) {
            (Some(mut a), Some(b)) => {
                a.extend_from_slice(&b[1..]);
                Some(a)
            }
            _ => None,
        };
    }

    /// Closest point to `p`: (distance, segment index, parameter along it).
    pub fn closest(&self, p: &Point3<f64>) -> (f64, usize, f64) {
        self.closest_on(p, 0, self.points.len() - 1)
    }

    /// The closest point among segments `lo..hi` (clamped): (distance, segment index).
    fn closest_between(&self, p: &Point3<f64>, lo: usize, hi: usize) -> (f64, usize) {
        let (d, k, _) = self.closest_on(p, lo.min(self.points.len() - 2), hi.min(self.points.len() - 1));
        (d, k)
    }

    /// The closest point among the segments between points `lo` and `hi`.
    fn closest_on(&self, p: &Point3<f64>, lo: usize, hi: usize) -> (f64, usize, f64) {
        let mut best = (f64::INFINITY, lo, 0.0);
        for (k, w) in self.points[lo..=hi.max(lo + 1)].windows(2).enumerate().map(|(k, w)| (k + lo, w)) {
            let ab = w[1] - w[0];
            let len2 = ab.norm_squared();
            let t = if len2 > 0.0 { ((p - w[0]).dot(&ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
            let d = (w[0] + ab * t - p).norm();
            if d < best.0 {
                best = (d, k, t);
            }
        }
        best
    }

    /// Radius interpolated at segment `k`, parameter `t`.
    fn radius_at(&self, k: usize, t: f64) -> f64 {
        self.radii[k] * (1.0 - t) + self.radii[(k + 1).min(self.radii.len() - 1)] * t
    }
}

/// A vessel end or a junction.
#[derive(Debug, Clone)]
pub(crate) struct Node {
    pub point: Point3<f64>,
    /// Maximal inscribed sphere radius at the point.
    pub radius: f64,
    /// Position of the end in the file (outlets are ordered by it); junctions: i64::MAX.
    pub key: i64,
}

/// A polyline between two nodes; its first point is exactly `nodes[ends[0]].point` and its
/// last exactly `nodes[ends[1]].point`.
#[derive(Debug, Clone)]
pub(crate) struct Edge {
    pub ends: [usize; 2],
    pub line: Line,
    /// The file's polyline (or centerline) it comes from, for messages.
    pub source: usize,
}

/// Nodes and edges, undirected.
#[derive(Debug, Clone)]
pub(crate) struct Skeleton {
    pub nodes: Vec<Node>,
    pub edges: Vec<Edge>,
    /// The end the file starts from (the common start of overlapping paths), if it says.
    pub file_start: Option<usize>,
    /// What the file was recognised as, for messages.
    pub layout: &'static str,
}

impl Skeleton {
    /// Recognises the layout of `lines` (with the integer cell tags of each) and builds the graph.
    pub fn from_lines(lines: Vec<Line>, tags: &[IndexMap<String, i64>], source: &Path) -> Result<Skeleton> {
        if lines.len() >= 2 && tags.iter().all(|t| t.contains_key("GroupIds")) {
            return branch_split(lines, tags, source);
        }
        if let Some(paths) = common_start(&lines) {
            let sims = similarities(&paths);
            let r0 = paths[0].radii[0];
            let overlapping = sims.iter().flatten().any(|s| *s > OVERLAP * r0);
            if overlapping {
                let members: Vec<usize> = (0..paths.len()).collect();
                let tree = cluster(&members, &sims);
                let keys: Vec<i64> = (0..paths.len() as i64).collect();
                return from_path_tree(&paths, &keys, &tree, "overlapping paths", source);
            }
        }
        network(lines, source)
    }

    /// Number of edges at each node.
    pub fn degrees(&self) -> Vec<usize> {
        let mut d = vec![0; self.nodes.len()];
        for e in &self.edges {
            d[e.ends[0]] += 1;
            d[e.ends[1]] += 1;
        }
        d
    }
}

/// The lines oriented from a common end point, if every line has an end there.
fn common_start(lines: &[Line]) -> Option<Vec<Line>> {
    if lines.len() < 2 {
        return None;
    }
    [lines[0].clone(), lines[0].reversed()].into_iter().find_map(|first| {
        let p = first.first();
        let tol = SAME_POINT * first.radii[0];
        let mut out = vec![first];
        for l in &lines[1..] {
            if (l.first() - p).norm() <= tol {
                out.push(l.clone());
            } else if (l.last() - p).norm() <= tol {
                out.push(l.reversed());
            } else {
                return None;
            }
        }
        Some(out)
    })
}

/// Where path `a` leaves path `b`, searching from point `from` of `a`: the first point of `a`
/// that is [`APART`] radii away from `b` marks that they have parted; the separation is the last
/// point before it, within [`WALK_BACK`] radii, where `a` was still within [`TOGETHER`] radii of
/// `b` (or, if none is, the closest approach there). Paths computed on the same medial graph
/// (VMTK's Voronoi diagram, our ball graph) coincide exactly up to where they part, then may run
/// side by side at a fraction of a radius before they really diverge (measured on the gmsh arch:
/// the brachiocephalic and left carotid paths jump 1.1 mm apart, then run about 1 mm apart for
/// 8 mm), so the walk back must not stop at the first local minimum of the distance. None when
/// `a` never leaves `b`.
pub(crate) fn separation(a: &Line, b: &Line, from: usize) -> Option<usize> {
    let mut dist = Vec::new();
    let mut parted = None;
    // While the paths run together the closest segment of `b` moves along with `a`: search
    // near the last one, and all of `b` only when that finds `a` apart.
    let mut near = b.closest(&a.points[from]).1;
    for k in from..a.points.len() {
        let (mut d, mut seg) = b.closest_between(&a.points[k], near.saturating_sub(NEAR), near + NEAR);
        if d > APART * a.radii[k] {
            (d, seg, _) = b.closest(&a.points[k]);
        }
        near = seg;
        dist.push(d);
        if d > APART * a.radii[k] {
            parted = Some(k);
            break;
        }
    }
    let parted = parted?;
    let reach = WALK_BACK * a.radii[parted];
    let mut closest = parted;
    let mut walked = 0.0;
    let mut k = parted;
    while k > from {
        walked += (a.points[k] - a.points[k - 1]).norm();
        if walked > reach {
            break;
        }
        k -= 1;
        if dist[k - from] <= TOGETHER * a.radii[k] {
            return Some(k);
        }
        if dist[k - from] < dist[closest - from] {
            closest = k;
        }
    }
    Some(closest)
}

/// Pairwise similarity of paths: the mean arc length at which each leaves the other
/// (infinite when one never leaves the other).
fn similarities(paths: &[Line]) -> Vec<Vec<f64>> {
    let arcs: Vec<Vec<f64>> = paths.iter().map(Line::arcs).collect();
    let n = paths.len();
    let mut sim = vec![vec![f64::INFINITY; n]; n];
    for i in 0..n {
        for j in i + 1..n {
            let a = separation(&paths[i], &paths[j], 0).map_or(f64::INFINITY, |k| arcs[i][k]);
            let b = separation(&paths[j], &paths[i], 0).map_or(f64::INFINITY, |k| arcs[j][k]);
            sim[i][j] = 0.5 * (a + b);
            sim[j][i] = sim[i][j];
        }
    }
    sim
}

/// How paths share their way: a leaf is one outlet (one path, or several identical ones); a
/// split is a junction whose children leave it.
#[derive(Debug, Clone)]
pub(crate) enum PathTree {
    Leaf(Vec<usize>),
    Split(Vec<PathTree>),
}

impl PathTree {
    fn members(&self) -> Vec<usize> {
        match self {
            PathTree::Leaf(m) => m.clone(),
            PathTree::Split(c) => c.iter().flat_map(|c| c.members()).collect(),
        }
    }

    /// The path that carries this subtree's geometry: its lowest index.
    fn rep(&self) -> usize {
        self.members().into_iter().min().unwrap_or(0)
    }
}

/// Single-linkage grouping: the maximum spanning tree of the similarities, cut at its weakest
/// link, recursively. Deterministic (ties broken by path index).
fn cluster(members: &[usize], sim: &[Vec<f64>]) -> PathTree {
    if members.len() == 1 {
        return PathTree::Leaf(members.to_vec());
    }
    let mut pairs: Vec<(f64, usize, usize)> = members
        .iter()
        .flat_map(|&i| members.iter().filter(move |&&j| j > i).map(move |&j| (sim[i][j], i, j)))
        .collect();
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let mut parent: Vec<usize> = (0..sim.len()).collect();
    fn find(p: &mut [usize], x: usize) -> usize {
        let mut r = x;
        while p[r] != r {
            r = p[r];
        }
        p[x] = r;
        r
    }
    let mut tree_links = vec![];
    for &(s, i, j) in &pairs {
        let (a, b) = (find(&mut parent, i), find(&mut parent, j));
        if a != b {
            parent[a.max(b)] = a.min(b);
            tree_links.push((s, i, j));
        }
    }
    let weakest = tree_links.len() - 1;
    if tree_links[weakest].0.is_infinite() {
        return PathTree::Leaf(members.to_vec());
    }
    let mut parent: Vec<usize> = (0..sim.len()).collect();
    for &(_, i, j) in &tree_links[..weakest] {
        let (a, b) = (find(&mut parent, i), find(&mut parent, j));
        parent[a.max(b)] = a.min(b);
    }
    let mut groups: Vec<Vec<usize>> = vec![];
    let mut roots: Vec<usize> = vec![];
    for &m in members {
        let r = find(&mut parent, m);
        match roots.iter().position(|&x| x == r) {
            Some(g) => groups[g].push(m),
            None => {
                roots.push(r);
                groups.push(vec![m]);
            }
        }
    }
    PathTree::Split(groups.iter().map(|g| cluster(g, sim)).collect())
}

/// Builds nodes and edges from paths sharing their first point and the tree of how they share
/// their way.
fn from_path_tree(
    paths: &[Line],
    keys: &[i64],
    tree: &PathTree,
    layout: &'static str,
    source: &Path,
) -> Result<Skeleton> {
    let start = Node { point: paths[0].points[0], radius: paths[0].radii[0], key: -1 };
    let mut walker = Walker { paths, arcs: paths.iter().map(Line::arcs).collect(), nodes: vec![start], edges: vec![] };
    walker.walk(tree, 0, keys, source)?;
    Ok(Skeleton { nodes: walker.nodes, edges: walker.edges, file_start: Some(0), layout })
}

struct Walker<'a> {
    paths: &'a [Line],
    arcs: Vec<Vec<f64>>,
    nodes: Vec<Node>,
    edges: Vec<Edge>,
}

impl Walker<'_> {
    /// Adds the edges of `tree`, which starts at node `from` (a point on or next to its paths).
    fn walk(&mut self, tree: &PathTree, from: usize, keys: &[i64], source: &Path) -> Result<()> {
        let r = tree.rep();
        let path = &self.paths[r];
        let from_point = self.nodes[from].point;
        let (_, seg, t) = path.closest(&from_point);
        let from_arc = self.arcs[r][seg] + t * (self.arcs[r][seg + 1] - self.arcs[r][seg]);
        match tree {
            PathTree::Leaf(members) => {
                let end = path.last();
                for &m in members {
                    let other = self.paths[m].last();
                    if (other - end).norm() > SAME_POINT * path.radii[path.radii.len() - 1] {
                        return Err(Error::input(
                            source,
                            format!(
                                "centerline {m} ends at ({:.3}, {:.3}, {:.3}) mm on centerline {r}, which goes on to \
                                 ({:.3}, {:.3}, {:.3}) mm: a path must end at a vessel end, not inside another path",
                                other.x, other.y, other.z, end.x, end.y, end.z
                            ),
                        ));
                    }
                }
                let node = self.nodes.len();
                self.nodes.push(Node { point: end, radius: path.radii[path.radii.len() - 1], key: keys[r] });
                self.add_edge(r, from, from_arc, node, path.points.len() - 1, source)
            }
            PathTree::Split(children) => {
                let mut centre: Option<usize> = None;
                for c in children.iter().filter(|c| !c.members().contains(&r)) {
                    let other = c.rep();
                    let k = separation(path, &self.paths[other], seg).ok_or_else(|| {
                        Error::input(
                            source,
                            format!(
                                "centerlines {r} and {other} are on different branches but centerline {r} never \
                                 leaves centerline {other}: check the file's GroupIds, or that the paths end at \
                                 different vessel ends"
                            ),
                        )
                    })?;
                    centre = Some(centre.map_or(k, |c: usize| c.min(k)));
                }
                let k = centre.expect("a split has a child without its representative path");
                let junction = if self.arcs[r][k] <= from_arc + 1e-9 * path.radii[k] {
                    from
                } else {
                    let node = self.nodes.len();
                    self.nodes.push(Node { point: path.points[k], radius: path.radii[k], key: i64::MAX });
                    self.add_edge(r, from, from_arc, node, k, source)?;
                    node
                };
                for c in children {
                    self.walk(c, junction, keys, source)?;
                }
                Ok(())
            }
        }
    }

    /// The edge along path `r` from node `from` (at arc length `from_arc` on it) to node `to`
    /// (point `to_index` of it).
    fn add_edge(
        &mut self,
        r: usize,
        from: usize,
        from_arc: f64,
        to: usize,
        to_index: usize,
        source: &Path,
    ) -> Result<()> {
        let path = &self.paths[r];
        let arcs = &self.arcs[r];
        let (a, b) = (&self.nodes[from], &self.nodes[to]);
        if arcs[to_index] <= from_arc {
            return Err(Error::input(
                source,
                format!(
                    "centerline {r}: the point ({:.3}, {:.3}, {:.3}) mm comes before ({:.3}, {:.3}, {:.3}) mm along it, \
                     though the tree needs it after: the paths do not run the same way",
                    b.point.x, b.point.y, b.point.z, a.point.x, a.point.y, a.point.z
                ),
            ));
        }
        let eps = 1e-9 * (1.0 + arcs[arcs.len() - 1]);
        let inner: Vec<usize> =
            (0..to_index).filter(|&i| arcs[i] > from_arc + eps && arcs[i] < arcs[to_index] - eps).collect();
        let mut line = Line {
            points: std::iter::once(a.point).chain(inner.iter().map(|&i| path.points[i])).chain([b.point]).collect(),
            radii: std::iter::once(a.radius).chain(inner.iter().map(|&i| path.radii[i])).chain([b.radius]).collect(),
            normals: None,
        };
        if let Some(n) = &path.normals {
            let first = n[inner.first().map_or(to_index, |&i| i.saturating_sub(1))];
            line.normals =
                Some(std::iter::once(first).chain(inner.iter().map(|&i| n[i])).chain([n[to_index]]).collect());
        }
        self.edges.push(Edge { ends: [from, to], line, source: r });
        Ok(())
    }
}

/// A branch-split file: tracts joined into one path per centerline, branching order from the
/// unblanked groups along each path.
fn branch_split(lines: Vec<Line>, tags: &[IndexMap<String, i64>], source: &Path) -> Result<Skeleton> {
    let tag = |k: usize, name: &str| tags[k].get(name).copied();
    if (0..lines.len()).any(|k| tag(k, "CenterlineIds").is_none()) {
        return Err(Error::input(
            source,
            "has GroupIds but no CenterlineIds cell array: a branch-split centerline file needs both to tell which \
             tracts form one path (vmtkbranchextractor writes them)",
        ));
    }
    // Tracts per centerline id (ascending), in TractIds order (file order when absent).
    let mut by_centerline: std::collections::BTreeMap<i64, Vec<(i64, usize)>> = Default::default();
    for k in 0..lines.len() {
        let cid = tag(k, "CenterlineIds").unwrap_or(0);
        by_centerline.entry(cid).or_default().push((tag(k, "TractIds").unwrap_or(k as i64), k));
    }
    let mut paths = vec![];
    let mut sequences = vec![];
    let mut centerline_ids = vec![];
    for (cid, mut tracts) in by_centerline {
        tracts.sort();
        let mut path = lines[tracts[0].1].clone();
        let mut groups: Vec<i64> = vec![];
        for (n, &(tid, k)) in tracts.iter().enumerate() {
            if n > 0 {
                let gap = (lines[k].first() - path.last()).norm();
                let next = if gap <= SAME_POINT * path.radii[path.radii.len() - 1] {
                    lines[k].clone()
                } else {
                    return Err(Error::input(
                        source,
                        format!(
                            "tract {tid} of centerline {cid} (polyline {k}) starts {gap:.3} mm from where the previous \
                             tract ends: the tracts of a centerline must follow each other"
                        ),
                    ));
                };
                // The joint point is written twice; keep the earlier copy.
                let mut joined = next;
                joined.points[0] = path.last();
                path.extend(&joined);
            }
            let blanked = tag(k, "Blanking").unwrap_or(0) != 0;
            let group = tag(k, "GroupIds").unwrap_or(-1);
            if !blanked && groups.last() != Some(&group) {
                groups.push(group);
            }
        }
        paths.push(path);
        sequences.push(groups);
        centerline_ids.push(cid);
    }
    let start = paths[0].first();
    for (i, p) in paths.iter().enumerate() {
        let gap = (p.first() - start).norm();
        if gap > SAME_POINT * paths[0].radii[0] {
            return Err(Error::input(
                source,
                format!(
                    "centerline {} starts at ({:.3}, {:.3}, {:.3}) mm, {gap:.3} mm from centerline {}'s start: the \
                     centerlines of a branch-split file must share their inlet",
                    centerline_ids[i], p.points[0].x, p.points[0].y, p.points[0].z, centerline_ids[0]
                ),
            ));
        }
    }
    if paths.len() == 1 {
        let tree = PathTree::Leaf(vec![0]);
        return from_path_tree(&paths, &[0], &tree, "branch-split centerlines", source);
    }
    let members: Vec<usize> = (0..paths.len()).collect();
    let tree = group_tree(&members, &sequences, 0, &centerline_ids, source)?;
    let keys: Vec<i64> = (0..paths.len() as i64).collect();
    from_path_tree(&paths, &keys, &tree, "branch-split centerlines", source)
}

/// The tree of shared group prefixes (a trie of the group sequences).
fn group_tree(members: &[usize], seqs: &[Vec<i64>], depth: usize, ids: &[i64], source: &Path) -> Result<PathTree> {
    let (ended, going): (Vec<usize>, Vec<usize>) = members.iter().partition(|&&m| seqs[m].len() <= depth);
    if going.is_empty() {
        return Ok(PathTree::Leaf(members.to_vec()));
    }
    if let Some(&m) = ended.first() {
        return Err(Error::input(
            source,
            format!(
                "centerline {} ends in group {} while centerline {} goes on: every branch must end at a vessel end",
                ids[m],
                seqs[m].last().copied().unwrap_or(-1),
                ids[going[0]]
            ),
        ));
    }
    if depth == 0 {
        if let Some(&m) = going.iter().find(|&&m| seqs[m][0] != seqs[going[0]][0]) {
            return Err(Error::input(
                source,
                format!(
                    "centerline {} starts in group {} and centerline {} in group {}: the centerlines must share their \
                     first (inlet) group",
                    ids[going[0]], seqs[going[0]][0], ids[m], seqs[m][0]
                ),
            ));
        }
    }
    let mut parts: Vec<(i64, Vec<usize>)> = vec![];
    for &m in &going {
        let g = seqs[m][depth];
        match parts.iter_mut().find(|(x, _)| *x == g) {
            Some((_, v)) => v.push(m),
            None => parts.push((g, vec![m])),
        }
    }
    if parts.len() == 1 {
        return group_tree(&going, seqs, depth + 1, ids, source);
    }
    let children = parts.iter().map(|(_, p)| group_tree(p, seqs, depth + 1, ids, source)).collect::<Result<_>>()?;
    Ok(PathTree::Split(children))
}

/// Polylines meeting at their end points, or with an end point on another polyline.
fn network(lines: Vec<Line>, source: &Path) -> Result<Skeleton> {
    let n = lines.len();
    let end_point = |e: usize| {
        if e.is_multiple_of(2) {
            lines[e / 2].first()
        } else {
            lines[e / 2].last()
        }
    };
    let end_radius = |e: usize| {
        let r = &lines[e / 2].radii;
        if e.is_multiple_of(2) {
            r[0]
        } else {
            r[r.len() - 1]
        }
    };
    // End points within tolerance of each other form one node (union-find, lowest index wins).
    let mut cluster: Vec<usize> = (0..2 * n).collect();
    for a in 0..2 * n {
        for b in a + 1..2 * n {
            let tol = SAME_POINT * end_radius(a).min(end_radius(b));
            if (end_point(a) - end_point(b)).norm() <= tol {
                let (ra, rb) = (root(&cluster, a), root(&cluster, b));
                cluster[ra.max(rb)] = ra.min(rb);
            }
        }
    }
    let mut node_of = vec![usize::MAX; 2 * n];
    let mut nodes: Vec<Node> = vec![];
    // A node's radius is the largest of the polylines meeting there: the inscribed sphere of the
    // widest vessel through the point.
    for e in 0..2 * n {
        let r = root(&cluster, e);
        if node_of[r] == usize::MAX {
            node_of[r] = nodes.len();
            nodes.push(Node { point: end_point(r), radius: end_radius(r), key: r as i64 });
        }
        node_of[e] = node_of[r];
        let node = &mut nodes[node_of[r]];
        node.radius = node.radius.max(end_radius(e));
    }
    let mut edges: Vec<Edge> = vec![];
    for (k, mut line) in lines.into_iter().enumerate() {
        let ends = [node_of[2 * k], node_of[2 * k + 1]];
        if ends[0] == ends[1] {
            let p = nodes[ends[0]].point;
            return Err(Error::input(
                source,
                format!(
                    "polyline {k} is a closed loop (it starts and ends at ({:.3}, {:.3}, {:.3}) mm): a vessel tree has \
                     no loops",
                    p.x, p.y, p.z
                ),
            ));
        }
        let last = line.points.len() - 1;
        line.points[0] = nodes[ends[0]].point;
        line.points[last] = nodes[ends[1]].point;
        line.radii[0] = nodes[ends[0]].radius;
        line.radii[last] = nodes[ends[1]].radius;
        edges.push(Edge { ends, line, source: k });
    }
    // An end point shared with no other polyline but lying on one splits it there.
    let mut degree = vec![0usize; nodes.len()];
    edges.iter().for_each(|e| e.ends.iter().for_each(|&v| degree[v] += 1));
    for v in 0..nodes.len() {
        if degree[v] != 1 {
            continue;
        }
        let p = nodes[v].point;
        let tol = SAME_POINT * nodes[v].radius;
        let hit = edges
            .iter()
            .enumerate()
            .filter(|(_, e)| !e.ends.contains(&v))
            .map(|(i, e)| (i, e.line.closest(&p)))
            .filter(|(_, (d, _, _))| *d <= tol)
            .min_by(|a, b| a.1 .0.total_cmp(&b.1 .0));
        if let Some((i, (_, seg, t))) = hit {
            let e = edges[i].clone();
            if (e.line.first() - p).norm() <= tol || (e.line.last() - p).norm() <= tol {
                continue;
            }
            let r = e.line.radius_at(seg, t).max(nodes[v].radius);
            nodes[v].radius = r;
            // The branch that ends here takes the node's radius too.
            for other in edges.iter_mut().filter(|x| x.ends.contains(&v)) {
                let at = if other.ends[0] == v { 0 } else { other.line.radii.len() - 1 };
                other.line.radii[at] = r;
            }
            let host = &e.line;
            let last = host.points.len() - 1;
            let normal = host.normals.as_ref().map(|n| n[seg]);
            // Host points at the split point itself are dropped (a polyline has no repeated points).
            let distinct = |j: &usize| (host.points[*j] - p).norm() > 1e-9 * r;
            let head_idx: Vec<usize> = (0..=seg).filter(|j| *j == 0 || distinct(j)).collect();
            let tail_idx: Vec<usize> = (seg + 1..=last).filter(|j| *j == last || distinct(j)).collect();
            let piece = |idx: &[usize], at_end: bool| {
                let pick = |v: &Vec<Vector3<f64>>| idx.iter().map(|&j| v[j]).collect::<Vec<_>>();
                let mut l = Line {
                    points: idx.iter().map(|&j| host.points[j]).collect(),
                    radii: idx.iter().map(|&j| host.radii[j]).collect(),
                    normals: host.normals.as_ref().map(pick),
                };
                let at = if at_end { l.points.len() } else { 0 };
                l.points.insert(at, p);
                l.radii.insert(at, r);
                if let (Some(n), Some(m)) = (&mut l.normals, normal) {
                    n.insert(at, m);
                }
                l
            };
            edges[i] = Edge { ends: [e.ends[0], v], line: piece(&head_idx, true), source: e.source };
            edges.push(Edge { ends: [v, e.ends[1]], line: piece(&tail_idx, false), source: e.source });
            degree[v] += 2;
        }
    }
    // A polyline joining two nodes already joined closes a loop.
    let mut joined: Vec<usize> = (0..nodes.len()).collect();
    for e in &edges {
        let (a, b) = (root(&joined, e.ends[0]), root(&joined, e.ends[1]));
        if a == b {
            let p = nodes[e.ends[1]].point;
            return Err(Error::input(
                source,
                format!(
                    "the centerlines form a closed loop: polyline {} ends at ({:.3}, {:.3}, {:.3}) mm, which the other \
                     polylines already connect to its start; a vessel tree has no loops, remove one polyline of the loop",
                    e.source, p.x, p.y, p.z
                ),
            ));
        }
        joined[a.max(b)] = a.min(b);
    }
    Ok(Skeleton { nodes, edges, file_start: None, layout: "polylines joined at their ends" })
}

fn root(parent: &[usize], mut x: usize) -> usize {
    while parent[x] != x {
        x = parent[x];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(points: &[[f64; 3]], r: f64) -> Line {
        Line { points: points.iter().map(|p| Point3::from(*p)).collect(), radii: vec![r; points.len()], normals: None }
    }

    /// Points every `step` from a to b (both included).
    fn straight(a: [f64; 3], b: [f64; 3], step: f64) -> Vec<[f64; 3]> {
        let (a, b) = (Point3::from(a), Point3::from(b));
        let n = ((b - a).norm() / step).ceil() as usize;
        (0..=n).map(|i| (a + (b - a) * (i as f64 / n as f64)).coords.into()).collect()
    }

    #[test]
    fn separation_is_where_paths_part() {
        let mut a = straight([0.0, 0.0, 0.0], [0.0, 0.0, 10.0], 0.1);
        a.extend(straight([0.0, 0.0, 10.0], [5.0, 0.0, 20.0], 0.1).into_iter().skip(1));
        let mut b = straight([0.0, 0.0, 0.0], [0.0, 0.0, 10.0], 0.1);
        b.extend(straight([0.0, 0.0, 10.0], [-5.0, 0.0, 20.0], 0.1).into_iter().skip(1));
        let (a, b) = (line(&a, 1.0), line(&b, 1.0));
        let k = separation(&a, &b, 0).unwrap();
        assert!((a.points[k] - Point3::new(0.0, 0.0, 10.0)).norm() < 0.15, "{:?}", a.points[k]);
        assert!(separation(&a, &a, 0).is_none());
    }

    #[test]
    fn network_splits_a_polyline_at_an_end_lying_on_it() {
        let main = line(&straight([0.0, 0.0, 0.0], [0.0, 0.0, 20.0], 1.0), 2.0);
        let side = line(&straight([0.0, 0.0, 10.0], [10.0, 0.0, 15.0], 1.0), 1.0);
        let sk = network(vec![main, side], Path::new("t")).unwrap();
        assert_eq!(sk.edges.len(), 3);
        assert_eq!(sk.degrees().iter().filter(|&&d| d == 3).count(), 1);
        let j = sk.degrees().iter().position(|&d| d == 3).unwrap();
        assert_eq!(sk.nodes[j].point, Point3::new(0.0, 0.0, 10.0));
    }
}
