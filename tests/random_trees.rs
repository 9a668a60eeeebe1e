//! The random-tree generator (issue 46): a sample of seeds (one with every end open, one with
//! every end capped, one mixed) checked from the outside: the same seed gives the same bytes
//! whatever the thread count, the surface is one genus-0 piece, manifold and outward (closed
//! where every end is capped, one boundary loop per open end otherwise), every true end of the
//! manifest lies on its boundary loop or on its flat cap, and the command line writes the three
//! files or refuses a bad seed in one line. The population is `cargo bench --bench trees`.

mod common;

use common::topology::{boundary_loops, closed_volume6, ends_where_the_truth_says, pieces};
use common::{path_str, temp_dir, vesselhex};
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
        ends_where_the_truth_says(&format!("seed {seed}"), &s.vertices, &s.triangles, &loops, ends, h);
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
    common::assert_same_files(&cli, &lib, &names);
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
