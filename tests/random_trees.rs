//! The random-tree generator (issue 46): a sample of seeds (one with every end open, one with
//! every end capped, one mixed) checked from the outside: the same seed gives the same bytes
//! whatever the thread count, the surface is one genus-0 piece, manifold and outward (closed
//! where every end is capped, one boundary loop per open end otherwise), every true end of the
//! manifest lies on its boundary loop or on its flat cap, and the command line writes the three
//! files or refuses a bad seed in one line. The population is `cargo bench --bench trees`.

mod common;

use common::{path_str, temp_dir, vesselhex};
use nalgebra::{Point3, Vector3};
use std::collections::HashMap;
use std::process::Command;
use vesselhex::input::{read_centerlines, read_surface};
use vesselhex::progress::Progress;
use vesselhex::synthetic_tree::{write_random_tree, RandomTree, SurfaceFormat};
use vesselhex::units::LengthUnit;

/// Every end open (12), every end capped (6), some of each (10).
const SEEDS: [u64; 3] = [12, 6, 10];

fn generate(seed: u64) -> RandomTree {
    RandomTree::generate(seed, &mut Progress::new(true, 0)).unwrap_or_else(|e| panic!("seed {seed}: {e}"))
}

/// The boundary loops of a triangle surface after checking that it is an oriented manifold:
/// every directed edge used once, and the triangles around each vertex one fan (one cycle, or
/// one path for a vertex on the boundary).
fn boundary_loops(triangles: &[[u32; 3]]) -> Vec<Vec<u32>> {
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
fn pieces(vertex_count: usize, triangles: &[[u32; 3]]) -> usize {
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
fn closed_volume6(vertices: &[Point3<f64>], triangles: &[[u32; 3]], loops: &[Vec<u32>]) -> f64 {
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

#[test]
fn each_tree_is_one_outward_genus_0_manifold_with_its_ends_where_the_truth_says() {
    for seed in SEEDS {
        let tree = generate(seed);
        let s = &tree.surface;
        let manifest = serde_json::to_value(tree.manifest("s", "c")).unwrap();
        let ends = manifest["ends"].as_array().unwrap();
        assert_eq!(ends.len(), tree.ends.len());
        assert!(ends.len() >= 2, "seed {seed}: {} ends", ends.len());
        let open: Vec<&serde_json::Value> = ends.iter().filter(|e| e["kind"] == "open").collect();
        let loops = boundary_loops(&s.triangles);
        assert_eq!(loops.len(), open.len(), "seed {seed}: boundary loops vs open ends");
        assert_eq!(pieces(s.vertices.len(), &s.triangles), 1, "seed {seed}");
        let edges = (3 * s.triangles.len() + loops.iter().map(Vec::len).sum::<usize>()) / 2;
        let chi = s.vertices.len() as i64 - edges as i64 + s.triangles.len() as i64;
        assert_eq!(chi, 2 - loops.len() as i64, "seed {seed}: Euler characteristic (genus 0)");
        assert!(closed_volume6(&s.vertices, &s.triangles, &loops) > 0.0, "seed {seed}: triangles face inwards");
        let h = manifest["grid"]["cell_size_mm"].as_f64().unwrap();
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
                    (0..loops.len()).filter(|&l| loops[l].iter().all(|&i| in_plane(&s.vertices[i as usize]))).collect();
                assert_eq!(on.len(), 1, "seed {seed}: end {} has {} boundary loops in its plane", end["id"], on.len());
                loop_used[on[0]] = true;
                for &i in &loops[on[0]] {
                    let d = radial(&s.vertices[i as usize]);
                    assert!(
                        (d - r).abs() < h,
                        "seed {seed}: end {}: a loop vertex {d} mm from the centre, radius {r}",
                        end["id"]
                    );
                }
            } else {
                // A flat disc facing along the outward normal, of the circle's area.
                let mut area = 0.0;
                for t in &s.triangles {
                    let [a, b, q] = t.map(|i| s.vertices[i as usize]);
                    if [a, b, q].iter().all(|p| in_plane(p) && radial(p) < r + h) {
                        let normal = (b - a).cross(&(q - a));
                        assert!(normal.dot(&n) > 0.0, "seed {seed}: end {}: a cap triangle faces in", end["id"]);
                        area += normal.norm() / 2.0;
                    }
                }
                let disc = std::f64::consts::PI * r * r;
                assert!(
                    (area / disc - 1.0).abs() < 0.1,
                    "seed {seed}: end {}: cap area {area}, circle {disc}",
                    end["id"]
                );
            }
        }
        assert!(loop_used.iter().all(|&u| u), "seed {seed}: a boundary loop belongs to no end");
    }
}

#[test]
fn the_cli_writes_the_same_bytes_as_the_library_whatever_the_thread_count() {
    let seed = 3;
    let (cli, lib) = (temp_dir("tree-cli"), temp_dir("tree-lib"));
    let out = Command::new(env!("CARGO_BIN_EXE_vesselhex"))
        .args(["fixtures", "--random-tree", "3", "--quiet", "--output", path_str(&cli)])
        .env("RAYON_NUM_THREADS", "1")
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let written = write_random_tree(seed, &lib, SurfaceFormat::Stl, &mut Progress::new(true, 0)).unwrap();
    let names = ["tree_3.stl", "tree_3.json", "tree_3_centerlines.vtp"];
    let mut listed: Vec<String> =
        std::fs::read_dir(&cli).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    listed.sort();
    let mut expected: Vec<String> = names.iter().map(|n| n.to_string()).collect();
    expected.sort();
    assert_eq!(listed, expected);
    for name in names {
        assert!(std::fs::read(cli.join(name)).unwrap() == std::fs::read(lib.join(name)).unwrap(), "{name} differs");
    }
    // The files read back as the mesher reads them: the surface's triangles, a centerline per outlet.
    let surface = read_surface(&cli.join(names[0]), LengthUnit::Mm).unwrap();
    assert_eq!(surface.triangles.len(), written.tree.surface.triangles.len());
    let centerlines = read_centerlines(&cli.join(names[2]), LengthUnit::Mm).unwrap();
    assert_eq!(centerlines.polylines.len(), written.tree.ends.len() - 1);
    let manifest: serde_json::Value = serde_json::from_slice(&std::fs::read(cli.join(names[1])).unwrap()).unwrap();
    assert_eq!(manifest["seed"], 3);
    assert_eq!(manifest["files"]["surface"], names[0]);
}

#[test]
fn a_bad_seed_is_refused_in_one_line_and_nothing_is_written() {
    let dir = temp_dir("tree-bad");
    for bad in ["abc", "5-2", "-3", "1-x"] {
        let out_dir = dir.join(format!("out-{bad}"));
        let out = vesselhex(&["fixtures", "--random-tree", bad, "--output", path_str(&out_dir)]);
        assert!(!out.status.success(), "{bad}: accepted");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(stderr.trim_end().lines().count(), 1, "{bad}: {stderr}");
        assert!(stderr.starts_with("vesselhex: error:") && stderr.contains(bad), "{bad}: {stderr}");
        assert!(!out_dir.exists(), "{bad}: the output folder was created");
    }
}
