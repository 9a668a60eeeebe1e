//! The layout of a junction whose branches cannot share one straight spine: which radial lines
//! from the centre (*spokes*) the branches' folded end sections meet on, and which four spokes
//! each branch's fold takes.
//!
//! A fold is a branch's square core laid onto four planar *sectors* around the centre, one per
//! quadrant of the square: the quadrant between the template's +x and +y half-axes lies in the
//! sector between the fold's +x spoke and its +y spoke, and so on round. Each sector is shared
//! by exactly two branches (it is the wall between their transitions), so the junction is
//! conformal by construction, as the book of pages is: the book is the layout whose spokes are
//! the spine's two ends (shared by every branch) and one spoke in the middle of each page
//! (shared by the two branches beside it).
//!
//! On the sphere of directions around the centre, a layout is a partition into one
//! quadrilateral face per branch: the face's four corners are the branch's spokes, its four
//! sides the sectors it shares. The dual of that partition is a planar multigraph on the
//! branches' directions in which every branch has degree four (one edge per sector; two edges
//! between the same two branches where they share two sectors, as the two halves of a book's
//! page are). Any such multigraph drawn without crossings is a layout, and each of its faces is
//! a spoke. We draw it on the edges of the branches' spherical Delaunay triangulation (the
//! convex hull of their unit directions): keeping every edge once gives triangular faces
//! (spokes of valence three, at the Voronoi vertices between three branches), dropping an edge
//! merges two triangles into one spoke, doubling one inserts a spoke between its two branches.
//! The degrees are met by a search over the edges' multiplicities, and of the layouts found the
//! one whose folds are best shaped is kept: each branch's four spokes spread around it, each
//! sector's two spokes far from parallel, no spoke near a branch's own direction. Six branches
//! leaving along the axes of a cube take the cube's eight corners; four leaving like the legs
//! of a tetrahedron, two doubled edges and four triangles.

use nalgebra::Vector3;
use std::f64::consts::FRAC_PI_2;

/// The spokes of a junction and each branch's four.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// Unit directions of the spokes from the junction's centre.
    pub spokes: Vec<Vector3<f64>>,
    /// How many sectors meet on each spoke.
    pub valence: Vec<usize>,
    /// Per branch (in the order of the directions given): its four spokes, counter-clockwise
    /// about its direction.
    pub corners: Vec<[usize; 4]>,
    /// Per branch: the branches it shares each of its four sectors with (the sector between
    /// corners i and i + 1 first).
    pub sector_neighbours: Vec<[usize; 4]>,
    /// The shape of the worst fold, in (0, 1] (see [`score`]).
    pub score: f64,
}

/// Largest number of branches searched for a layout: past it the search's cost grows fast and
/// no real junction we know has more branches at one place.
pub const MAX_BRANCHES: usize = 12;

/// Largest number of complete degree assignments scored in one search.
const MAX_LAYOUTS: usize = 50_000;

/// The best layout for branches leaving along the unit directions `dirs` with the given radii,
/// or `None` when their directions do not span a triangulation (fewer than four branches, two
/// leaving the same way) or no assignment of degrees four exists on it.
pub fn sector_layout(dirs: &[Vector3<f64>], radii: &[f64]) -> Option<Layout> {
    let k = dirs.len();
    if !(4..=MAX_BRANCHES).contains(&k) {
        return None;
    }
    let hull = Hull::of(dirs)?;
    let mut best: Option<Layout> = None;
    let mut multiplicity = vec![0u8; hull.edges.len()];
    let mut need = vec![4usize; k];
    let mut scored = 0;
    search(&hull, dirs, radii, 0, &mut multiplicity, &mut need, &mut best, &mut scored);
    best
}

/// The spherical Delaunay triangulation of unit directions: their convex hull's faces, each
/// counter-clockwise seen from outside, and its edges.
struct Hull {
    faces: Vec<[usize; 3]>,
    /// Undirected edges (a < b).
    edges: Vec<(usize, usize)>,
    /// Per node, its edges in counter-clockwise order about it, each with the face that
    /// follows it counter-clockwise (the face between it and the next edge).
    around: Vec<Vec<(usize, usize)>>,
}

impl Hull {
    /// The hull of the directions, each moved by a tiny fixed amount so that four on one circle
    /// give one triangulation (whichever: both are Delaunay); `None` when it is not a closed
    /// triangulated sphere (two directions the same).
    fn of(dirs: &[Vector3<f64>]) -> Option<Hull> {
        let k = dirs.len();
        let p: Vec<Vector3<f64>> = dirs
            .iter()
            .enumerate()
            .map(|(i, d)| {
                let t = i as f64 + 1.0;
                (d + Vector3::new((1.3 * t).sin(), (2.1 * t).cos(), (0.7 * t).sin()) * 1e-9).normalize()
            })
            .collect();
        let mut faces = vec![];
        for a in 0..k {
            for b in a + 1..k {
                for c in b + 1..k {
                    let n = (p[b] - p[a]).cross(&(p[c] - p[a]));
                    if n.norm() < 1e-14 {
                        continue;
                    }
                    let side: Vec<f64> = (0..k).filter(|m| ![a, b, c].contains(m)).map(|m| n.dot(&(p[m] - p[a]))).collect();
                    if side.iter().all(|&s| s < 0.0) {
                        faces.push([a, b, c]);
                    } else if side.iter().all(|&s| s > 0.0) {
                        faces.push([a, c, b]);
                    }
                }
            }
        }
        if faces.len() != 2 * k - 4 {
            return None;
        }
        // Per node: the face after each of its edges, counter-clockwise. Face (v, a, b) lies
        // between edge v-a and edge v-b.
        let mut next_of: Vec<Vec<(usize, usize, usize)>> = vec![vec![]; k];
        for (f, t) in faces.iter().enumerate() {
            for r in 0..3 {
                let (v, a, b) = (t[r], t[(r + 1) % 3], t[(r + 2) % 3]);
                next_of[v].push((a, b, f));
            }
        }
        let mut edges: Vec<(usize, usize)> =
            faces.iter().flat_map(|t| (0..3).map(move |r| (t[r].min(t[(r + 1) % 3]), t[r].max(t[(r + 1) % 3])))).collect();
        edges.sort_unstable();
        edges.dedup();
        if edges.len() != 3 * k - 6 {
            return None;
        }
        let edge_index = |a: usize, b: usize| edges.binary_search(&(a.min(b), a.max(b))).expect("a hull edge");
        let mut around = vec![];
        for (v, next) in next_of.iter().enumerate() {
            // Follow the faces round the node from its lowest neighbour.
            let start = next.iter().map(|&(a, _, _)| a).min()?;
            let mut ring = vec![];
            let mut a = start;
            loop {
                let &(_, b, f) = next.iter().find(|&&(x, _, _)| x == a)?;
                ring.push((edge_index(v, a), f));
                a = b;
                if a == start || ring.len() > next.len() {
                    break;
                }
            }
            if ring.len() != next.len() {
                return None;
            }
            around.push(ring);
        }
        Some(Hull { faces, edges, around })
    }
}

/// Gives each edge from `e` on a multiplicity (0, 1 or 2) so that every node's `need` is met,
/// scoring each complete assignment into `best`.
#[allow(clippy::too_many_arguments)]
fn search(
    hull: &Hull,
    dirs: &[Vector3<f64>],
    radii: &[f64],
    e: usize,
    multiplicity: &mut [u8],
    need: &mut [usize],
    best: &mut Option<Layout>,
    scored: &mut usize,
) {
    if *scored >= MAX_LAYOUTS {
        return;
    }
    if e == hull.edges.len() {
        if need.iter().all(|&n| n == 0) {
            *scored += 1;
            if let Some(layout) = build(hull, dirs, radii, multiplicity) {
                if best.as_ref().is_none_or(|b| layout.score > b.score) {
                    *best = Some(layout);
                }
            }
        }
        return;
    }
    let (a, b) = hull.edges[e];
    // What the edges after this one can still give each endpoint.
    let later = |v: usize| 2 * hull.edges[e + 1..].iter().filter(|&&(x, y)| x == v || y == v).count();
    for m in [1u8, 2, 0] {
        let m_us = m as usize;
        if need[a] < m_us || need[b] < m_us {
            continue;
        }
        if need[a] - m_us > later(a) || need[b] - m_us > later(b) {
            continue;
        }
        need[a] -= m_us;
        need[b] -= m_us;
        multiplicity[e] = m;
        search(hull, dirs, radii, e + 1, multiplicity, need, best, scored);
        need[a] += m_us;
        need[b] += m_us;
    }
    multiplicity[e] = 0;
}

/// The layout of one assignment of multiplicities, if it is one: the kept edges connect every
/// branch and each branch's four corners are four different spokes.
fn build(hull: &Hull, dirs: &[Vector3<f64>], radii: &[f64], multiplicity: &[u8]) -> Option<Layout> {
    let k = dirs.len();
    if !connected(k, &hull.edges, multiplicity) {
        return None;
    }
    // Spokes: the clusters of hull faces joined across dropped edges, then one per doubled edge.
    let mut cluster: Vec<usize> = (0..hull.faces.len()).collect();
    fn root(c: &mut [usize], mut f: usize) -> usize {
        while c[f] != f {
            c[f] = c[c[f]];
            f = c[f];
        }
        f
    }
    for ring in &hull.around {
        for i in 0..ring.len() {
            // Edge i lies between the face after edge i - 1 and its own.
            let before = ring[(i + ring.len() - 1) % ring.len()].1;
            let (edge, after) = ring[i];
            if multiplicity[edge] == 0 {
                let (x, y) = (root(&mut cluster, before), root(&mut cluster, after));
                cluster[x.max(y)] = x.min(y);
            }
        }
    }
    let mut spoke_of_cluster = vec![usize::MAX; hull.faces.len()];
    let mut spokes: Vec<Vector3<f64>> = vec![];
    let mut sums: Vec<Vector3<f64>> = vec![];
    for f in 0..hull.faces.len() {
        let r = root(&mut cluster, f);
        if spoke_of_cluster[r] == usize::MAX {
            spoke_of_cluster[r] = sums.len();
            sums.push(Vector3::zeros());
        }
        let t = hull.faces[f];
        // The face's circumcentre on the sphere: the outward normal of its plane.
        let n = (dirs[t[1]] - dirs[t[0]]).cross(&(dirs[t[2]] - dirs[t[0]]));
        if n.norm() > 0.0 {
            sums[spoke_of_cluster[r]] += n.normalize();
        }
    }
    for s in &sums {
        if s.norm() < 1e-9 {
            return None;
        }
        spokes.push(s.normalize());
    }
    let mut digon_of_edge = vec![usize::MAX; hull.edges.len()];
    for (e, &(a, b)) in hull.edges.iter().enumerate() {
        if multiplicity[e] == 2 {
            digon_of_edge[e] = spokes.len();
            spokes.push(between(&dirs[a], &dirs[b], radii[a] / (radii[a] + radii[b]))?);
        }
    }
    let mut valence = vec![0usize; spokes.len()];
    let mut corners = Vec::with_capacity(k);
    let mut sector_neighbours = Vec::with_capacity(k);
    for (v, ring) in hull.around.iter().enumerate() {
        // The kept darts counter-clockwise, each followed by the spoke after it.
        let mut c = vec![];
        let mut n = vec![];
        for (i, &(e, _)) in ring.iter().enumerate() {
            let (a, b) = hull.edges[e];
            let other = if a == v { b } else { a };
            if multiplicity[e] == 2 {
                c.push(digon_of_edge[e]);
                n.push(other);
            }
            if multiplicity[e] >= 1 {
                // The spoke after the edge's last copy: the cluster of the faces that follow
                // it up to the next kept edge.
                let f = ring[i].1;
                c.push(spoke_of_cluster[root(&mut cluster, f)]);
                n.push(other);
            }
        }
        if c.len() != 4 {
            return None;
        }
        let mut distinct = c.clone();
        distinct.sort_unstable();
        distinct.dedup();
        if distinct.len() != 4 {
            return None;
        }
        for &s in &c {
            valence[s] += 1;
        }
        // c[i] follows the sector shared with n[i]: the sector between corners i - 1 and i.
        let corner = [c[0], c[1], c[2], c[3]];
        let shared = [n[1], n[2], n[3], n[0]];
        corners.push(corner);
        sector_neighbours.push(shared);
    }
    // Each spoke is met by as many sectors as branches have it for a corner.
    let mut layout = Layout { spokes, valence, corners, sector_neighbours, score: 0.0 };
    layout.score = score(&layout, dirs);
    Some(layout)
}

/// Whether the edges of non-zero multiplicity connect all `k` nodes.
fn connected(k: usize, edges: &[(usize, usize)], multiplicity: &[u8]) -> bool {
    let mut seen = vec![false; k];
    let mut stack = vec![0];
    seen[0] = true;
    while let Some(v) = stack.pop() {
        for (e, &(a, b)) in edges.iter().enumerate() {
            if multiplicity[e] == 0 || (a != v && b != v) {
                continue;
            }
            let w = if a == v { b } else { a };
            if !seen[w] {
                seen[w] = true;
                stack.push(w);
            }
        }
    }
    seen.iter().all(|&s| s)
}

/// The unit direction a fraction `t` of the way along the great circle from `a` to `b`.
fn between(a: &Vector3<f64>, b: &Vector3<f64>, t: f64) -> Option<Vector3<f64>> {
    let angle = a.angle(b);
    if angle < 1e-9 {
        return None;
    }
    let axis = a.cross(b);
    if axis.norm() < 1e-12 {
        return None;
    }
    let ortho = axis.normalize().cross(a);
    Some(a * (t * angle).cos() + ortho * (t * angle).sin())
}

/// The shape of a layout's worst fold, in (0, 1]: the least of, over every branch, its four
/// spokes' smallest angular gap about its direction over a quarter turn (each fold's core is a
/// square split into quadrants), the sine of every sector's angle between its two spokes (the
/// quadrant's core cells are parallelograms of that angle), and every spoke's angle from a
/// branch it bounds over 45 degrees (a spoke closer to the branch's own direction runs down
/// its lumen rather than to the wall beside it).
pub fn score(layout: &Layout, dirs: &[Vector3<f64>]) -> f64 {
    let mut worst: f64 = 1.0;
    for (v, corners) in layout.corners.iter().enumerate() {
        let d = dirs[v];
        let reference = any_perpendicular(&d);
        let side = d.cross(&reference);
        let angles: Vec<f64> = corners
            .iter()
            .map(|&s| {
                let p = layout.spokes[s] - d * layout.spokes[s].dot(&d);
                p.dot(&side).atan2(p.dot(&reference))
            })
            .collect();
        for i in 0..4 {
            let gap = (angles[(i + 1) % 4] - angles[i]).rem_euclid(std::f64::consts::TAU);
            worst = worst.min(gap / FRAC_PI_2);
            let (a, b) = (layout.spokes[corners[i]], layout.spokes[corners[(i + 1) % 4]]);
            worst = worst.min(a.cross(&b).norm());
            worst = worst.min(layout.spokes[corners[i]].angle(&d) / (0.5 * FRAC_PI_2));
        }
    }
    worst.max(0.0)
}

/// A unit vector perpendicular to `d` (unit).
fn any_perpendicular(d: &Vector3<f64>) -> Vector3<f64> {
    let helper = if d.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    d.cross(&helper).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(x: f64, y: f64, z: f64) -> Vector3<f64> {
        Vector3::new(x, y, z).normalize()
    }

    /// Every sector is shared by exactly two branches, each seeing the other across it, and its
    /// two spokes are consecutive corners of both.
    fn assert_conformal(layout: &Layout) {
        let k = layout.corners.len();
        let mut sectors = std::collections::HashMap::new();
        for v in 0..k {
            for i in 0..4 {
                let (a, b) = (layout.corners[v][i], layout.corners[v][(i + 1) % 4]);
                let key = (a.min(b), a.max(b), layout.sector_neighbours[v][i].min(v));
                *sectors.entry(key).or_insert(0) += 1;
                let w = layout.sector_neighbours[v][i];
                assert_ne!(w, v, "a sector between a branch and itself");
                let theirs = &layout.corners[w];
                let shares = (0..4).any(|j| {
                    let (c, d) = (theirs[j], theirs[(j + 1) % 4]);
                    (c, d) == (a, b) || (c, d) == (b, a)
                });
                assert!(shares, "branch {w} does not have the sector {a}-{b} of branch {v}");
            }
        }
        assert!(sectors.values().all(|&n| n == 2), "every sector shared by two branches: {sectors:?}");
        assert_eq!(sectors.len(), 2 * k, "2k sectors");
        assert_eq!(layout.spokes.len(), k + 2, "Euler: k + 2 spokes");
        assert_eq!(layout.valence.iter().sum::<usize>(), 4 * k);
    }

    #[test]
    fn six_branches_along_the_axes_take_the_cubes_corners() {
        let dirs = [
            unit(0.0, 0.0, -1.0),
            unit(1.0, 0.0, 0.0),
            unit(-1.0, 0.0, 0.0),
            unit(0.0, 1.0, 0.0),
            unit(0.0, -1.0, 0.0),
            unit(0.0, 0.0, 1.0),
        ];
        let layout = sector_layout(&dirs, &[1.0; 6]).expect("a layout");
        assert_conformal(&layout);
        assert_eq!(layout.spokes.len(), 8);
        assert!(layout.valence.iter().all(|&v| v == 3), "{:?}", layout.valence);
        for s in &layout.spokes {
            for c in [s.x, s.y, s.z] {
                assert!((c.abs() - 1.0 / 3f64.sqrt()).abs() < 1e-6, "a cube's corner: {s:?}");
            }
        }
        // Two neighbouring corners of a cube are acos(1/3) apart seen from its centre.
        assert!((layout.score - (8f64 / 9.0).sqrt()).abs() < 1e-6, "score {}", layout.score);
    }

    #[test]
    fn four_branches_like_a_tripods_legs_and_its_stem_get_a_layout() {
        // The parent rising from below, three daughters leaving 120 degrees apart and 20 above
        // the horizontal: no axis orders them 25 degrees apart that every branch stands off.
        let up = 20f64.to_radians();
        let leg = |deg: f64| unit(deg.to_radians().cos() * up.cos(), deg.to_radians().sin() * up.cos(), up.sin());
        let dirs = [unit(0.0, 0.0, -1.0), leg(0.0), leg(120.0), leg(240.0)];
        let layout = sector_layout(&dirs, &[1.0, 0.7, 0.7, 0.7]).expect("a layout");
        assert_conformal(&layout);
        assert!(layout.score > 0.3, "score {}", layout.score);
    }

    #[test]
    fn every_generic_configuration_of_four_to_eight_branches_has_a_conformal_layout() {
        // Directions from a fixed sequence, kept 30 degrees apart.
        let mut seed = 7u64;
        let mut next = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64) / ((1u64 << 53) as f64)
        };
        let mut tried = 0;
        while tried < 60 {
            let k = 4 + tried % 5;
            let mut dirs: Vec<Vector3<f64>> = vec![];
            while dirs.len() < k {
                let z = 2.0 * next() - 1.0;
                let phi = std::f64::consts::TAU * next();
                let r = (1.0 - z * z).sqrt();
                let d = Vector3::new(r * phi.cos(), r * phi.sin(), z);
                if dirs.iter().all(|e| e.angle(&d) > 30f64.to_radians()) {
                    dirs.push(d);
                }
            }
            let layout = sector_layout(&dirs, &vec![1.0; k]).unwrap_or_else(|| panic!("no layout for {dirs:?}"));
            assert_conformal(&layout);
            assert!(layout.score > 0.0, "a layout with a degenerate fold: {dirs:?}");
            tried += 1;
        }
    }

    #[test]
    fn a_branch_leaving_the_way_of_another_has_no_triangulation() {
        let dirs = [unit(0.0, 0.0, -1.0), unit(1.0, 0.0, 0.0), unit(1.0, 0.0, 0.0), unit(0.0, 1.0, 0.0)];
        assert!(sector_layout(&dirs, &[1.0; 4]).is_none());
    }
}
