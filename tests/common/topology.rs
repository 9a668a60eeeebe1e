//! Topology of a triangle surface checked from the outside (the random trees' and networks'
//! tests): oriented manifold and boundary loops, pieces, enclosed volume.

use nalgebra::{Point3, Vector3};
use std::collections::HashMap;

/// The boundary loops of a triangle surface after checking that it is an oriented manifold:
/// every directed edge used once, and the triangles around each vertex one fan (one cycle, or
/// one path for a vertex on the boundary).
pub fn boundary_loops(triangles: &[[u32; 3]]) -> Vec<Vec<u32>> {
    let mut directed = HashMap::new();
    for (t, tri) in triangles.iter().enumerate() {
        for k in 0..3 {
            let e = (tri[k], tri[(k + 1) % 3]);
            assert!(directed.insert(e, t).is_none(), "directed edge {e:?} used twice (non-manifold or misoriented)");
        }
    }
    // Around vertex v, triangle (v, a, b) leads from a to b.
    let mut fans: HashMap<u32, HashMap<u32, u32>> = HashMap::new();
    for tri in triangles {
        for k in 0..3 {
            fans.entry(tri[k]).or_default().insert(tri[(k + 1) % 3], tri[(k + 2) % 3]);
        }
    }
    for (v, fan) in &fans {
        let starts: Vec<u32> = fan.keys().filter(|a| !fan.values().any(|b| b == *a)).copied().collect();
        assert!(starts.len() <= 1, "vertex {v}: its triangles form {} fans", starts.len());
        // Walk from the fan's open side (or anywhere on a closed fan) until it ends or closes.
        let first = starts.first().copied().unwrap_or_else(|| *fan.keys().min().unwrap());
        let (mut at, mut walked) = (first, 0);
        while let Some(&next) = fan.get(&at) {
            walked += 1;
            at = next;
            if at == first || walked > fan.len() {
                break;
            }
        }
        assert_eq!(walked, fan.len(), "vertex {v}: its triangles are not one fan");
    }
    // Boundary edges: a directed edge whose reverse is not used.
    let mut next: HashMap<u32, u32> = HashMap::new();
    for &(a, b) in directed.keys() {
        if !directed.contains_key(&(b, a)) {
            assert!(next.insert(a, b).is_none(), "vertex {a} starts two boundary edges");
        }
    }
    let mut loops = vec![];
    let mut starts: Vec<u32> = next.keys().copied().collect();
    starts.sort_unstable();
    let mut seen = std::collections::HashSet::new();
    for s in starts {
        if !seen.insert(s) {
            continue;
        }
        let mut lp = vec![s];
        let mut at = next[&s];
        while at != s {
            assert!(seen.insert(at), "boundary walk from {s} does not close");
            lp.push(at);
            at = next[&at];
        }
        loops.push(lp);
    }
    loops
}

/// Number of pieces (triangles joined through shared vertices).
pub fn pieces(vertex_count: usize, triangles: &[[u32; 3]]) -> usize {
    let mut parent: Vec<usize> = (0..vertex_count).collect();
    fn root(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    for tri in triangles {
        for k in 1..3 {
            let (a, b) = (root(&mut parent, tri[0] as usize), root(&mut parent, tri[k] as usize));
            parent[a] = b;
        }
    }
    let used: std::collections::HashSet<usize> = triangles.iter().flatten().map(|&v| v as usize).collect();
    used.iter().map(|&v| root(&mut parent, v)).collect::<std::collections::HashSet<_>>().len()
}

/// Six times the volume enclosed by the surface with each boundary loop closed by a fan to its
/// centroid (positive when the triangles face out).
pub fn closed_volume6(vertices: &[Point3<f64>], triangles: &[[u32; 3]], loops: &[Vec<u32>]) -> f64 {
    let tet = |a: &Point3<f64>, b: &Point3<f64>, c: &Point3<f64>| a.coords.dot(&b.coords.cross(&c.coords));
    let mut v: f64 = triangles
        .iter()
        .map(|t| tet(&vertices[t[0] as usize], &vertices[t[1] as usize], &vertices[t[2] as usize]))
        .sum();
    for lp in loops {
        let c = Point3::from(lp.iter().map(|&i| vertices[i as usize].coords).sum::<Vector3<f64>>() / lp.len() as f64);
        // A boundary edge a -> b of the surface is closed by the triangle (b, a, c).
        for k in 0..lp.len() {
            let (a, b) = (vertices[lp[k] as usize], vertices[lp[(k + 1) % lp.len()] as usize]);
            v += tet(&b, &a, &c);
        }
    }
    v
}

/// Asserts that each end of a manifest's `ends` (centre, outward normal, radius, open or capped)
/// is where the surface says: an open end has exactly one boundary loop in its plane, on its
/// circle to within a cell `h`; a capped end a flat disc of its circle's area facing along its
/// normal; and that every boundary loop belongs to an end. `what` names the surface in messages.
pub fn ends_where_the_truth_says(
    what: &str,
    vertices: &[Point3<f64>],
    triangles: &[[u32; 3]],
    loops: &[Vec<u32>],
    ends: &[serde_json::Value],
    h: f64,
) {
    let mut loop_used = vec![false; loops.len()];
    for end in ends {
        let v = |k: &str| {
            let a = end[k].as_array().unwrap();
            Vector3::new(a[0].as_f64().unwrap(), a[1].as_f64().unwrap(), a[2].as_f64().unwrap())
        };
        let (c, n, r) = (Point3::from(v("centre")), v("outward_normal"), end["radius_mm"].as_f64().unwrap());
        let in_plane = |p: &Point3<f64>| (p - c).dot(&n).abs() < 1e-9 * (1.0 + c.coords.norm());
        let radial = |p: &Point3<f64>| ((p - c) - n * (p - c).dot(&n)).norm();
        if end["kind"] == "open" {
            // One boundary loop, all in the end's plane on its circle (within a cell).
            let on: Vec<usize> =
                (0..loops.len()).filter(|&l| loops[l].iter().all(|&i| in_plane(&vertices[i as usize]))).collect();
            assert_eq!(on.len(), 1, "{what}: end {} has {} boundary loops in its plane", end["id"], on.len());
            loop_used[on[0]] = true;
            for &i in &loops[on[0]] {
                let d = radial(&vertices[i as usize]);
                assert!(
                    (d - r).abs() < h,
                    "{what}: end {}: a loop vertex {d} mm from the centre, radius {r}",
                    end["id"]
                );
            }
        } else {
            // A flat disc facing along the outward normal, of the circle's area.
            let mut area = 0.0;
            for t in triangles {
                let [a, b, q] = t.map(|i| vertices[i as usize]);
                if [a, b, q].iter().all(|p| in_plane(p) && radial(p) < r + h) {
                    let normal = (b - a).cross(&(q - a));
                    assert!(normal.dot(&n) > 0.0, "{what}: end {}: a cap triangle faces in", end["id"]);
                    area += normal.norm() / 2.0;
                }
            }
            let disc = std::f64::consts::PI * r * r;
            assert!((area / disc - 1.0).abs() < 0.1, "{what}: end {}: cap area {area}, circle {disc}", end["id"]);
        }
    }
    assert!(loop_used.iter().all(|&u| u), "{what}: a boundary loop belongs to no end");
}
