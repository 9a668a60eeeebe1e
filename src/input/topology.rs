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
    let mut edges: Vec<(u32, u32, u32, u8)> = Vec::with_capacity(triangles.len() * 3);
    for (t, tri) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            edges.push((a.min(b), a.max(b), t as u32, k as u8));
        }
    }
    edges.sort_unstable();
    let mut out = vec![[BOUNDARY; 3]; triangles.len()];
    let mut i = 0;
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && edges[j].0 == edges[i].0 && edges[j].1 == edges[i].1 {
            j += 1;
        }
        let group = &edges[i..j];
        if group.len() == 2 {
            out[group[0].2 as usize][group[0].3 as usize] = group[1].2;
            out[group[1].2 as usize][group[1].3 as usize] = group[0].2;
        } else if group.len() > 2 {
            group.iter().for_each(|e| out[e.2 as usize][e.3 as usize] = NON_MANIFOLD);
        }
        i = j;
    }
    out
}

/// Flips triangles so that every two triangles sharing a manifold edge traverse it in opposite
/// directions (breadth-first over each connected component, the lowest-indexed triangle of a
/// component keeping its winding). Returns the number of triangles flipped.
pub fn orient_consistently(triangles: &mut [[u32; 3]]) -> usize {
    let neighbours = triangle_neighbours(triangles);
    let mut seen = vec![false; triangles.len()];
    let mut flipped = 0;
    let mut queue = std::collections::VecDeque::new();
    for start in 0..triangles.len() {
        if seen[start] {
            continue;
        }
        seen[start] = true;
        queue.push_back(start);
        while let Some(t) = queue.pop_front() {
            for k in 0..3 {
                let u = neighbours[t][k];
                if u >= NON_MANIFOLD || seen[u as usize] {
                    continue;
                }
                let (a, b) = (triangles[t][k], triangles[t][(k + 1) % 3]);
                let other = triangles[u as usize];
                let same_direction = (0..3).any(|m| other[m] == a && other[(m + 1) % 3] == b);
                if same_direction {
                    triangles[u as usize].swap(1, 2);
                    flipped += 1;
                }
                seen[u as usize] = true;
                queue.push_back(u as usize);
            }
        }
    }
    flipped
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
}
