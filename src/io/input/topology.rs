//! Connectivity of a triangle soup: edge neighbours, consistent winding, boundary loops, the
//! sign of the enclosed volume and area-weighted vertex normals.

use nalgebra::{Point3, Vector3};

/// Neighbour slot value: the edge has one incident triangle (an open boundary).
pub const BOUNDARY: u32 = u32::MAX;
/// Neighbour slot value: the edge has three or more incident triangles.
pub const NON_MANIFOLD: u32 = u32::MAX - 1;

/// For each triangle and each edge k (from vertex k to vertex k+1), the triangle across it, or
/// [`BOUNDARY`] / [`NON_MANIFOLD`].
pub fn triangle_neighbours(triangles: &[[u32; 3]]) -> Vec<[u32; 3]> {
    // The edges bucketed by their lower vertex (a counting sort: a vertex has a handful of
    // edges), each bucket sorted by the upper vertex: a sort of all 3n edges at once was a
    // tenth of a random tree's surface hygiene, which asks for the neighbours a dozen times.
    let vertices = triangles.iter().flatten().map(|&v| v as usize + 1).max().unwrap_or(0);
    if vertices > SPARSE_VERTICES * triangles.len() {
        return triangle_neighbours(&compact_vertices(triangles));
    }
    let mut start = vec![0u32; vertices + 1];
    for tri in triangles {
        for k in 0..3 {
            start[tri[k].min(tri[(k + 1) % 3]) as usize + 1] += 1;
        }
    }
    for v in 0..vertices {
        start[v + 1] += start[v];
    }
    let mut next = start.clone();
    let mut edges: Vec<(u32, u32, u8)> = vec![(0, 0, 0); triangles.len() * 3];
    for (t, tri) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            let slot = &mut next[a.min(b) as usize];
            edges[*slot as usize] = (a.max(b), t as u32, k as u8);
            *slot += 1;
        }
    }
    let mut out = vec![[BOUNDARY; 3]; triangles.len()];
    for v in 0..vertices {
        let bucket = &mut edges[start[v] as usize..start[v + 1] as usize];
        bucket.sort_unstable();
        for group in bucket.chunk_by(|x, y| x.0 == y.0) {
            if group.len() == 2 {
                out[group[0].1 as usize][group[0].2 as usize] = group[1].1;
                out[group[1].1 as usize][group[1].2 as usize] = group[0].1;
            } else if group.len() > 2 {
                group.iter().for_each(|e| out[e.1 as usize][e.2 as usize] = NON_MANIFOLD);
            }
        }
    }
    out
}

/// Triangles whose vertex numbers span more than this many per triangle are renumbered before
/// their edges are bucketed: the buckets cost one slot per vertex number, and a cap candidate's
/// few triangles, numbered among the whole surface's vertices, made each call cost the whole
/// surface (random tree 1: a fifth of the run's CPU samples, every cap candidate of `find_caps`).
const SPARSE_VERTICES: usize = 8;

/// The triangles with their vertices renumbered 0.. in the order of their old numbers: the same
/// edges between the same triangles.
fn compact_vertices(triangles: &[[u32; 3]]) -> Vec<[u32; 3]> {
    let mut used: Vec<u32> = triangles.iter().flatten().copied().collect();
    used.sort_unstable();
    used.dedup();
    let new = |v: u32| used.binary_search(&v).expect("a vertex of the triangles") as u32;
    triangles.iter().map(|t| t.map(new)).collect()
}

/// What [`orient`] found: the triangles' connected pieces across manifold edges, how many it
/// flipped, and an edge that no choice of windings can make consistent, if any.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Orientation {
    /// Triangles flipped.
    pub flipped: usize,
    /// Each triangle's piece (triangles joined across manifold edges), numbered by their first
    /// triangle's order.
    pub piece: Vec<u32>,
    /// The manifold edges (their two vertices, lower first) whose two triangles still run them
    /// the same way once the rest of their piece is consistent: the piece is not orientable (it
    /// holds a Moebius band), so no winding faces one side of all of it. Empty when every piece
    /// is orientable.
    pub conflicts: Vec<[u32; 2]>,
}

/// Flips triangles so that every two triangles sharing a manifold edge traverse it in opposite
/// directions, whatever share of them the file wound the other way: each piece (triangles
/// joined across manifold edges) is walked breadth-first from its lowest-indexed triangle,
/// which keeps its winding, and every triangle reached is wound against the one it was reached
/// from. Edges are compared by their vertices, as the file gave them, so a flip decided on the
/// way does not change which edge is which.
pub fn orient(triangles: &mut [[u32; 3]]) -> Orientation {
    let neighbours = triangle_neighbours(triangles);
    let n = triangles.len();
    // Whether each triangle is to be flipped; u8::MAX: not reached yet.
    let mut flip = vec![u8::MAX; n];
    let mut piece = vec![u32::MAX; n];
    let mut conflicts = vec![];
    let mut queue = std::collections::VecDeque::new();
    let mut pieces = 0;
    for start in 0..n {
        if flip[start] != u8::MAX {
            continue;
        }
        flip[start] = 0;
        piece[start] = pieces;
        queue.push_back(start);
        while let Some(t) = queue.pop_front() {
            for k in 0..3 {
                let u = neighbours[t][k];
                if u >= NON_MANIFOLD {
                    continue;
                }
                let (a, b) = (triangles[t][k], triangles[t][(k + 1) % 3]);
                let other = triangles[u as usize];
                let same_direction = (0..3).any(|m| other[m] == a && other[(m + 1) % 3] == b);
                // Run the same way in the file, the two must end up flipped differently.
                let wanted = flip[t] ^ u8::from(same_direction);
                match flip[u as usize] {
                    u8::MAX => {
                        flip[u as usize] = wanted;
                        piece[u as usize] = pieces;
                        queue.push_back(u as usize);
                    }
                    // Each conflicting edge once, from its lower-indexed triangle.
                    f if f != wanted && (u as usize) > t => conflicts.push([a.min(b), a.max(b)]),
                    _ => {}
                }
            }
        }
        pieces += 1;
    }
    let mut flipped = 0;
    for (t, f) in triangles.iter_mut().zip(&flip) {
        if *f == 1 {
            t.swap(1, 2);
            flipped += 1;
        }
    }
    Orientation { flipped, piece, conflicts }
}

/// [`orient`], returning only the number of triangles flipped.
pub fn orient_consistently(triangles: &mut [[u32; 3]]) -> usize {
    orient(triangles).flipped
}

/// Closed boundary loops of a consistently wound triangle set, each as a vertex sequence in the
/// direction the triangles traverse their boundary edges. Deterministic: loops start at their
/// lowest free edge. Open chains (non-manifold boundary vertices that do not close) are dropped.
pub fn boundary_loops(triangles: &[[u32; 3]]) -> Vec<Vec<u32>> {
    let neighbours = triangle_neighbours(triangles);
    let mut edges: Vec<(u32, u32)> = vec![];
    for (t, tri) in triangles.iter().enumerate() {
        for k in 0..3 {
            if neighbours[t][k] == BOUNDARY {
                edges.push((tri[k], tri[(k + 1) % 3]));
            }
        }
    }
    edges.sort_unstable();
    let mut used = vec![false; edges.len()];
    let mut loops = vec![];
    for first in 0..edges.len() {
        if used[first] {
            continue;
        }
        used[first] = true;
        let start = edges[first].0;
        let mut chain = vec![start];
        let mut at = edges[first].1;
        let closed = loop {
            if at == start {
                break true;
            }
            chain.push(at);
            let from = edges.partition_point(|e| e.0 < at);
            match (from..edges.len()).take_while(|&e| edges[e].0 == at).find(|&e| !used[e]) {
                Some(e) => {
                    used[e] = true;
                    at = edges[e].1;
                }
                None => break false,
            }
        };
        if closed && chain.len() >= 3 {
            loops.push(chain);
        }
    }
    loops
}

/// The loops of a manifold triangle surface, summed over its pieces: the genus g of each piece,
/// from its Euler characteristic V - E + F = 2 - 2g - b (b its boundary loops). A vessel tree
/// has none; a ring of vessels (a circle of Willis, a graft rejoining its host) has one per ring,
/// and so have two vessels fused where they touch. None when an edge has three or more
/// triangles or a boundary does not close (no genus to speak of).
pub fn handles(triangles: &[[u32; 3]]) -> Option<usize> {
    let neighbours = triangle_neighbours(triangles);
    if neighbours.iter().flatten().any(|&n| n == NON_MANIFOLD) {
        return None;
    }
    let vertices = triangles.iter().flatten().map(|&v| v as usize + 1).max().unwrap_or(0);
    let mut piece: Vec<usize> = (0..vertices).collect();
    fn root(piece: &mut [usize], mut v: usize) -> usize {
        while piece[v] != v {
            piece[v] = piece[piece[v]];
            v = piece[v];
        }
        v
    }
    for t in triangles {
        for k in 1..3 {
            let (a, b) = (root(&mut piece, t[0] as usize), root(&mut piece, t[k] as usize));
            piece[a.max(b)] = a.min(b);
        }
    }
    let mut used = vec![false; vertices];
    triangles.iter().flatten().for_each(|&v| used[v as usize] = true);
    let v = used.iter().filter(|&&u| u).count() as i64;
    let pieces = (0..vertices).filter(|&x| used[x] && root(&mut piece, x) == x).count() as i64;
    let boundary_edges = neighbours.iter().flatten().filter(|&&n| n == BOUNDARY).count() as i64;
    let f = triangles.len() as i64;
    let e = (3 * f + boundary_edges) / 2;
    let loops = boundary_loops(triangles);
    if loops.iter().map(|l| l.len() as i64).sum::<i64>() != boundary_edges {
        return None;
    }
    // Summed over the pieces: V - E + F = 2 pieces - 2 g - b.
    let twice_g = 2 * pieces - loops.len() as i64 - (v - e + f);
    Some((twice_g.max(0) / 2) as usize)
}

/// Centre of a loop weighted by edge length (VMTK's cap centre), and its vector area (the
/// area of the fan from that centre, as a vector along the loop's right-hand normal).
pub fn loop_centre_and_area(vertices: &[Point3<f64>], lp: &[u32]) -> (Point3<f64>, Vector3<f64>) {
    let n = lp.len();
    let mut sum = Vector3::zeros();
    let mut length = 0.0;
    for i in 0..n {
        let (a, b) = (vertices[lp[i] as usize], vertices[lp[(i + 1) % n] as usize]);
        let l = (b - a).norm();
        sum += (a.coords + b.coords) * (0.5 * l);
        length += l;
    }
    let centre = if length > 0.0 { Point3::from(sum / length) } else { vertices[lp[0] as usize] };
    let area = (0..n)
        .map(|i| (vertices[lp[i] as usize] - centre).cross(&(vertices[lp[(i + 1) % n] as usize] - centre)) * 0.5)
        .sum();
    (centre, area)
}

/// Six times the signed volume enclosed by the triangles closed with a fan on every boundary
/// loop: positive when the triangles face out of the enclosed region.
pub fn signed_volume6(vertices: &[Point3<f64>], triangles: &[[u32; 3]], loops: &[Vec<u32>]) -> f64 {
    let det = |a: &Point3<f64>, b: &Point3<f64>, c: &Point3<f64>| a.coords.dot(&b.coords.cross(&c.coords));
    let shift = vertices.first().map(|p| p.coords).unwrap_or_default();
    let at = |i: u32| Point3::from(vertices[i as usize].coords - shift);
    let mut v: f64 = triangles.iter().map(|t| det(&at(t[0]), &at(t[1]), &at(t[2]))).sum();
    for lp in loops {
        let (c, _) = loop_centre_and_area(vertices, lp);
        let c = Point3::from(c.coords - shift);
        // The fan runs each boundary edge backwards, closing the surface consistently.
        v += (0..lp.len()).map(|i| det(&at(lp[(i + 1) % lp.len()]), &at(lp[i]), &c)).sum::<f64>();
    }
    v
}

/// The surface closed by a fan on every boundary loop (from its length-weighted centre, a new
/// vertex), wound so that every triangle faces out (`inward_sign` is -1 when the given triangles
/// already do, +1 when they face in).
pub fn close_with_caps(
    vertices: &[Point3<f64>],
    triangles: &[[u32; 3]],
    loops: &[Vec<u32>],
    inward_sign: f64,
) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
    let mut all = vertices.to_vec();
    let mut closed = triangles.to_vec();
    for lp in loops {
        let (centre, _) = loop_centre_and_area(vertices, lp);
        let c = all.len() as u32;
        all.push(centre);
        let n = lp.len();
        closed.extend((0..n).map(|i| [lp[(i + 1) % n], lp[i], c]));
    }
    if inward_sign > 0.0 {
        closed.iter_mut().for_each(|t| t.swap(1, 2));
    }
    (all, closed)
}

/// Unit area-weighted vertex normals along the triangles' winding (zero for unused vertices).
pub fn vertex_normals(vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> Vec<Vector3<f64>> {
    let mut normals = vec![Vector3::zeros(); vertices.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| vertices[i as usize]);
        let n = (b - a).cross(&(c - a));
        t.iter().for_each(|&i| normals[i as usize] += n);
    }
    normals.iter().map(|n| n.try_normalize(0.0).unwrap_or_default()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An open square tube (4 sides, 1 ring of quads), one quad flipped.
    fn tube() -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
        let mut v = vec![];
        for z in [0.0, 1.0] {
            for (x, y) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
                v.push(Point3::new(x, y, z));
            }
        }
        let mut t = vec![];
        for i in 0..4u32 {
            let j = (i + 1) % 4;
            t.push([i, j, j + 4]);
            t.push([i, j + 4, i + 4]);
        }
        t[2].swap(1, 2);
        (v, t)
    }

    /// A torus of `m` x `n` quads (each two triangles), wound consistently.
    fn torus(m: u32, n: u32) -> Vec<[u32; 3]> {
        let at = |i: u32, j: u32| (i % m) * n + j % n;
        (0..m)
            .flat_map(|i| {
                (0..n).flat_map(move |j| {
                    [[at(i, j), at(i + 1, j), at(i + 1, j + 1)], [at(i, j), at(i + 1, j + 1), at(i, j + 1)]]
                })
            })
            .collect()
    }

    #[test]
    fn handles_count_the_loops_of_each_piece() {
        let (_, mut tube) = tube();
        orient_consistently(&mut tube);
        assert_eq!(handles(&tube), Some(0), "an open tube");
        assert_eq!(handles(&torus(8, 6)), Some(1), "a ring");
        // Two rings in one file, the second's vertices after the first's, and the tube beside them.
        let mut two: Vec<[u32; 3]> = torus(8, 6);
        two.extend(torus(5, 4).iter().map(|t| t.map(|v| v + 48)));
        two.extend(tube.iter().map(|t| t.map(|v| v + 68)));
        assert_eq!(handles(&two), Some(2));
        // A ring cut open across (one band of quads left out) is a bent tube: no loop.
        let cut: Vec<[u32; 3]> = torus(8, 6).into_iter().skip(12).collect();
        assert_eq!(handles(&cut), Some(0));
        // Three triangles on one edge: no genus to speak of.
        let mut fin = torus(8, 6);
        fin.push([0, 6, 100]);
        assert_eq!(handles(&fin), None);
    }

    #[test]
    fn patches_wound_the_other_way_are_made_consistent_whatever_their_share() {
        // A closed cylinder of 24 x 10 quads and two fans; every other band of three rings wound
        // the other way (more than half of the triangles), then the caps.
        let (around, rings) = (24u32, 10u32);
        let mut v: Vec<Point3<f64>> = (0..=rings)
            .flat_map(|j| {
                (0..around).map(move |i| {
                    let a = std::f64::consts::TAU * i as f64 / around as f64;
                    Point3::new(a.cos(), a.sin(), j as f64 * 0.3)
                })
            })
            .collect();
        let mut t = vec![];
        for j in 0..rings {
            for i in 0..around {
                let (a, b) = (j * around + i, j * around + (i + 1) % around);
                t.push([a, b, b + around]);
                t.push([a, b + around, a + around]);
            }
        }
        let (bottom, top) = (v.len() as u32, v.len() as u32 + 1);
        v.extend([Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, rings as f64 * 0.3)]);
        for i in 0..around {
            t.push([bottom, (i + 1) % around, i]);
            t.push([top, rings * around + i, rings * around + (i + 1) % around]);
        }
        let outward = t.clone();
        let mut mixed = t.clone();
        for (k, tri) in mixed.iter_mut().enumerate() {
            if (k as u32 / (2 * around)) % 2 == 1 || k % 7 == 3 {
                tri.swap(0, 1);
            }
        }
        let found = orient(&mut mixed);
        assert!(found.conflicts.is_empty());
        assert!(found.piece.iter().all(|&p| p == 0));
        // Every triangle faces as the outward one does, or every one the other way.
        let same = |a: &[u32; 3], b: &[u32; 3]| (0..3).any(|r| [a[r], a[(r + 1) % 3], a[(r + 2) % 3]] == *b);
        let agree = mixed.iter().zip(&outward).filter(|(a, b)| same(a, b)).count();
        assert!(agree == t.len() || agree == 0, "{agree} of {} agree", t.len());
    }

    #[test]
    fn a_moebius_band_is_found_not_orientable() {
        // A band of 12 quads whose ends are joined with a half twist.
        let n = 12u32;
        let mut v = vec![];
        for i in 0..n {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            let (w, c) = ((a / 2.0).cos() * 0.3, (a / 2.0).sin() * 0.3);
            let centre = Point3::new(a.cos(), a.sin(), 0.0);
            v.push(centre + Vector3::new(a.cos() * w, a.sin() * w, c));
            v.push(centre - Vector3::new(a.cos() * w, a.sin() * w, c));
        }
        let mut t = vec![];
        for i in 0..n {
            let (a0, a1) = (2 * i, 2 * i + 1);
            // The last quad joins the first pair swapped: the half twist.
            let (b0, b1) = if i + 1 == n { (1, 0) } else { (2 * i + 2, 2 * i + 3) };
            t.push([a0, b0, b1]);
            t.push([a0, b1, a1]);
        }
        let _ = &v;
        assert_eq!(orient(&mut t).conflicts.len(), 1);
    }

    #[test]
    fn winding_is_made_consistent_and_loops_found() {
        let (v, mut t) = tube();
        assert_eq!(orient_consistently(&mut t), 1);
        let loops = boundary_loops(&t);
        assert_eq!(loops.len(), 2);
        assert!(loops.iter().all(|l| l.len() == 4));
        // Outward-facing winding gives a positive volume of 1 (x6).
        assert!((signed_volume6(&v, &t, &loops) - 6.0).abs() < 1e-12);
    }

    #[test]
    fn neighbours_pair_manifold_edges_and_mark_the_rest() {
        // A torus (every edge shared by two triangles) with a fin on each of two edges (three
        // triangles there, the fins' other edges open), vertex ids shuffled: densely, and spread
        // over a range far wider than the triangles (renumbered before bucketing).
        let mut torus_with_fins = torus(6, 5);
        let fin = [torus_with_fins[0][0], torus_with_fins[0][1], 100];
        let fin2 = [torus_with_fins[7][1], torus_with_fins[7][2], 101];
        torus_with_fins.push(fin);
        torus_with_fins.push(fin2);
        let dense = |v: u32| (v * 37) % 211;
        let sparse = |v: u32| dense(v) * 1009 + 5;
        for shuffle in [&dense as &dyn Fn(u32) -> u32, &sparse] {
            let t: Vec<[u32; 3]> = torus_with_fins.iter().map(|tri| tri.map(shuffle)).collect();
            assert_neighbours_match_the_oracle(&t);
        }
    }

    fn assert_neighbours_match_the_oracle(t: &[[u32; 3]]) {
        let nb = triangle_neighbours(t);
        // The oracle: every other triangle holding the same edge, by brute force.
        let holders = |a: u32, b: u32| -> Vec<u32> {
            (0..t.len() as u32)
                .filter(|&u| {
                    (0..3).any(|k| {
                        let (x, y) = (t[u as usize][k], t[u as usize][(k + 1) % 3]);
                        (x, y) == (a, b) || (x, y) == (b, a)
                    })
                })
                .collect()
        };
        for (i, tri) in t.iter().enumerate() {
            for k in 0..3 {
                let h = holders(tri[k], tri[(k + 1) % 3]);
                let want = match h.len() {
                    1 => BOUNDARY,
                    2 => h[(h[0] == i as u32) as usize],
                    _ => NON_MANIFOLD,
                };
                assert_eq!(nb[i][k], want, "triangle {i}, edge {k}");
            }
        }
        assert_eq!(nb.iter().flatten().filter(|&&n| n == NON_MANIFOLD).count(), 6);
        assert_eq!(nb.iter().flatten().filter(|&&n| n == BOUNDARY).count(), 4);
    }
}
