//! Checks of the committed synthetic fixtures in `fixtures/` against their analytic definitions
//! (`vesselhex::synthetic`). Regenerate them with
//! `cargo test --test synthetic regenerate_fixtures -- --ignored`.

mod common;

use common::{assert_same_as_committed, fixtures_dir, ScratchDir};
use nalgebra::{Point3, Vector3};
use std::collections::HashMap;
use std::fs;
use vesselhex::synthetic::{
    all_fixtures, centerline_abscissae, chordal_tolerance, fixture_paths, write_all_fixtures, AnalyticVessel, Facing,
};

/// The committed STL of a fixture, read by `stl_io` (vertices welded by exact f32 equality).
fn read_committed_stl(v: &dyn AnalyticVessel) -> stl_io::IndexedMesh {
    let (stl, _) = fixture_paths(v.name(), &fixtures_dir());
    let bytes = fs::read(&stl).unwrap_or_else(|e| panic!("{}: {e}", stl.display()));
    let mesh = stl_io::read_stl(&mut std::io::Cursor::new(&bytes)).unwrap();
    assert_eq!(bytes.len(), 84 + 50 * mesh.faces.len(), "{}: not a binary STL", stl.display());
    mesh
}

fn vertex(mesh: &stl_io::IndexedMesh, i: usize) -> Point3<f64> {
    let p = mesh.vertices[i].0;
    Point3::new(p[0].into(), p[1].into(), p[2].into())
}

fn corners(mesh: &stl_io::IndexedMesh, face: usize) -> [Point3<f64>; 3] {
    mesh.faces[face].vertices.map(|i| vertex(mesh, i))
}

fn winding_normal(c: &[Point3<f64>; 3]) -> Vector3<f64> {
    (c[1] - c[0]).cross(&(c[2] - c[0])).normalize()
}

#[test]
fn regenerated_fixtures_are_byte_identical_to_the_committed_ones() {
    let scratch = ScratchDir::new("regen");
    let written = write_all_fixtures(&scratch.0).unwrap();
    assert_eq!(written.len(), 2 * all_fixtures().len());
    assert_same_as_committed(&written);
    let left: Vec<_> = fs::read_dir(&scratch.0).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left.len(), 2 * all_fixtures().len(), "temporary files left behind: {left:?}");
}

#[test]
fn files_stay_small() {
    for v in all_fixtures() {
        let (stl, csv) = fixture_paths(v.name(), &fixtures_dir());
        let size = fs::metadata(&stl).unwrap().len();
        assert!(size < 600_000, "{}: {size} bytes", stl.display());
        assert!(fs::metadata(&csv).unwrap().len() < 100_000);
    }
}

#[test]
fn stl_vertices_lie_on_the_analytic_surface() {
    for v in all_fixtures() {
        let mesh = read_committed_stl(v.as_ref());
        let mut worst: f64 = 0.0;
        for i in 0..mesh.vertices.len() {
            let p = vertex(&mesh, i);
            let relative = v.distance_to_surface(&p) / p.coords.norm().max(1.0);
            worst = worst.max(relative);
        }
        assert!(worst < 1e-6, "{}: a vertex is {worst:e} (relative) off the surface", v.name());
    }
}

#[test]
fn stl_stays_within_the_chordal_tolerance() {
    for v in all_fixtures() {
        let res = v.resolution();
        let tol = chordal_tolerance(v.as_ref(), res.circumferential, res.axial_step_mm);
        let mesh = read_committed_stl(v.as_ref());
        for f in 0..mesh.faces.len() {
            let [a, b, c] = corners(&mesh, f).map(|p| p.coords);
            for (wa, wb) in [(1.0, 0.0), (1.0 / 3.0, 1.0 / 3.0), (0.5, 0.5), (0.0, 0.5)] {
                let p = Point3::from(a * wa + b * wb + c * (1.0 - wa - wb));
                let d = v.distance_to_surface(&p);
                assert!(d <= tol, "{} triangle {f}: {d} > tolerance {tol}", v.name());
            }
        }
    }
}

/// Undirected edge -> number of triangles using it; also checks that no directed edge repeats
/// (consistent orientation).
fn edge_counts(mesh: &stl_io::IndexedMesh) -> HashMap<(usize, usize), usize> {
    let mut directed = HashMap::new();
    let mut undirected = HashMap::new();
    for face in &mesh.faces {
        let t = face.vertices;
        assert!(t[0] != t[1] && t[1] != t[2] && t[2] != t[0], "degenerate triangle {t:?}");
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *directed.entry((a, b)).or_insert(0usize) += 1;
            *undirected.entry((a.min(b), a.max(b))).or_insert(0usize) += 1;
        }
    }
    assert!(directed.values().all(|&n| n == 1), "inconsistently oriented triangles");
    undirected
}

/// Connected loops formed by the boundary edges.
fn boundary_loops(edges: &HashMap<(usize, usize), usize>) -> Vec<Vec<usize>> {
    let mut adjacency: HashMap<usize, Vec<usize>> = HashMap::new();
    for (&(a, b), _) in edges.iter().filter(|(_, &n)| n == 1) {
        adjacency.entry(a).or_default().push(b);
        adjacency.entry(b).or_default().push(a);
    }
    assert!(adjacency.values().all(|n| n.len() == 2), "boundary is not a set of simple loops");
    let mut seen = std::collections::HashSet::new();
    let mut loops = Vec::new();
    let mut starts: Vec<usize> = adjacency.keys().copied().collect();
    starts.sort_unstable();
    for start in starts {
        if !seen.insert(start) {
            continue;
        }
        let mut lp = vec![start];
        let mut stack = vec![start];
        while let Some(x) = stack.pop() {
            for &y in &adjacency[&x] {
                if seen.insert(y) {
                    lp.push(y);
                    stack.push(y);
                }
            }
        }
        loops.push(lp);
    }
    loops
}

#[test]
fn closed_fixtures_are_watertight_and_open_ones_have_two_end_loops() {
    for v in all_fixtures() {
        let mesh = read_committed_stl(v.as_ref());
        let edges = edge_counts(&mesh);
        assert!(edges.values().all(|&n| n <= 2), "{}: non-manifold edge", v.name());
        let euler = mesh.vertices.len() as i64 - edges.len() as i64 + mesh.faces.len() as i64;
        let loops = boundary_loops(&edges);
        if v.is_closed() {
            assert!(loops.is_empty(), "{}: {} boundary loops", v.name(), loops.len());
            assert_eq!(euler, 2, "{}: not a sphere", v.name());
        } else {
            assert_eq!(loops.len(), 2, "{}", v.name());
            assert_eq!(euler, 0, "{}: not an annulus", v.name());
            // One loop is the inlet ring, the other the outlet ring, each a full ring.
            let mut ends: Vec<f64> = loops
                .iter()
                .map(|lp| {
                    assert_eq!(lp.len(), v.resolution().circumferential, "{}", v.name());
                    let s: Vec<f64> = lp.iter().map(|&i| v.closest_abscissa(&vertex(&mesh, i))).collect();
                    assert!(s.iter().all(|x| (x - s[0]).abs() < 1e-5), "{}: {s:?}", v.name());
                    s[0]
                })
                .collect();
            ends.sort_by(f64::total_cmp);
            assert!(ends[0].abs() < 1e-5 && (ends[1] - v.length()).abs() < 1e-5, "{ends:?}");
        }
    }
}

/// Volume enclosed by a straight-axis fixture: ∫ π r² ds (Simpson) plus the domes.
fn analytic_volume(v: &dyn AnalyticVessel) -> f64 {
    let (n, len) = (4000, v.length());
    let h = len / n as f64;
    let area = |s: f64| std::f64::consts::PI * v.radius(s).powi(2);
    let mut sum = area(0.0) + area(len);
    for i in 1..n {
        sum += area(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    let mut volume = sum * h / 3.0;
    if v.caps() == vesselhex::synthetic::EndCaps::Hemispherical {
        let dome = |r: f64| 2.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        volume += dome(v.radius(0.0)) + dome(v.radius(len));
    }
    volume
}

#[test]
fn normals_face_the_documented_way() {
    for v in all_fixtures() {
        let mesh = read_committed_stl(v.as_ref());
        let sign = if v.facing() == Facing::Outward { 1.0 } else { -1.0 };
        // The stored normals agree with the winding.
        for (f, face) in mesh.faces.iter().enumerate() {
            let n = face.normal.0;
            let stored = Vector3::new(n[0].into(), n[1].into(), n[2].into());
            assert!(stored.dot(&winding_normal(&corners(&mesh, f))) > 0.999, "{} {f}", v.name());
        }
        if v.is_closed() {
            let signed_volume: f64 = (0..mesh.faces.len())
                .map(|f| {
                    let [a, b, c] = corners(&mesh, f).map(|p| p.coords);
                    a.dot(&b.cross(&c)) / 6.0
                })
                .sum();
            let expected = analytic_volume(v.as_ref());
            assert!(signed_volume * sign > 0.0, "{}: volume {signed_volume}", v.name());
            let rel = (signed_volume.abs() - expected).abs() / expected;
            assert!(rel < 0.02, "{}: volume {signed_volume} vs {expected}", v.name());
        } else {
            for f in 0..mesh.faces.len() {
                let c = corners(&mesh, f);
                let centroid = Point3::from((c[0].coords + c[1].coords + c[2].coords) / 3.0);
                let s = v.closest_abscissa(&centroid);
                let t = v.tangent(s);
                let offset = centroid - v.point(s);
                let radial = (offset - t * offset.dot(&t)).normalize();
                let cos = winding_normal(&c).dot(&radial) * sign;
                assert!(cos > 0.95, "{} triangle {f}: normal·radial = {cos}", v.name());
            }
        }
    }
}

#[test]
fn csv_is_the_exact_centerline() {
    for v in all_fixtures() {
        let (_, csv) = fixture_paths(v.name(), &fixtures_dir());
        let text = fs::read_to_string(&csv).unwrap();
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some("x,y,z,r"));
        let rows: Vec<[f64; 4]> = lines
            .map(|l| {
                let fields: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
                assert_eq!(fields.len(), 4, "{}: {l}", csv.display());
                [fields[0], fields[1], fields[2], fields[3]]
            })
            .collect();
        let abscissae = centerline_abscissae(v.as_ref());
        assert_eq!(rows.len(), abscissae.len(), "{}", v.name());
        assert_eq!((abscissae[0], *abscissae.last().unwrap()), (0.0, v.length()));
        for (row, &s) in rows.iter().zip(&abscissae) {
            let p = Point3::new(row[0], row[1], row[2]);
            assert!((p - v.point(s)).norm() < 1e-12, "{} s={s}: {p:?}", v.name());
            assert!((row[3] - v.radius(s)).abs() < 1e-12, "{} s={s}: r={}", v.name(), row[3]);
        }
        for pair in rows.windows(2) {
            let step = (Point3::new(pair[1][0], pair[1][1], pair[1][2])
                - Point3::new(pair[0][0], pair[0][1], pair[0][2]))
            .norm();
            assert!(step <= 0.5 + 1e-9 && step > 0.4, "{}: step {step}", v.name());
        }
    }
}

/// Writes the fixtures into `fixtures/` (run on purpose only).
#[test]
#[ignore = "rewrites the committed fixtures"]
fn regenerate_fixtures() {
    for path in write_all_fixtures(&fixtures_dir()).unwrap() {
        println!("{} ({} bytes)", path.display(), fs::metadata(&path).unwrap().len());
    }
}
