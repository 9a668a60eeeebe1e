//! The random-tree population (issue 46): `cargo bench --bench trees` writes each generated tree
//! of a range of seeds ([`vesselhex::synthetic_tree`]), meshes it from the bare surface through
//! `vesselhex mesh --surface tree_SEED.stl --units mm --preset P --quiet --reproducible` (a child
//! process per tree and preset, two at a time, so a crash is one failed row) and compares the
//! mesh with the tree's truth. A run passes when it exits 0, every true end is meshed (an end
//! of report.json within the true end's radius of its centre, meshed) and every bar holds
//! (minimum scaled Jacobian >= 0.2, wall mean >= 0.85, lumen mean equi-angle skew <= 0.35,
//! interface sub-micron). It prints a row per run, then the pass rate by bin (branches at one
//! place, out-of-plane angle, daughter spacing, radius ratio, stenosis, near pass), the
//! failures grouped by cause and the meshing seconds per end.
//!
//! `VESSELHEX_TREE_SEEDS=FIRST-LAST` (default 1-200) or a comma-separated list;
//! `VESSELHEX_TREE_PRESETS` (comma-separated, default coarse); `VESSELHEX_TREE_BIN=FILE`
//! meshes with another build of `vesselhex`; `VESSELHEX_TREE_KEEP=DIR` writes the trees and
//! meshes into DIR and keeps them.
//!
//! `VESSELHEX_TREE_SEPARATION=1` meshes nothing: it generates each tree and prints the pairs of
//! vessels fused outside a shared junction's blend zone
//! ([`vesselhex::synthetic_tree::separation`]) by cause, the near passes whose gap the
//! triangulated surface closes where the implicit lumen keeps it open, and the trees per bin.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;
use vesselhex::progress::Progress;
use vesselhex::synthetic_tree::{write_random_tree, SurfaceFormat};
use vesselhex::testing::mutations::Written;
use vesselhex::testing::suite::{mesh, Run};

mod population;
use population::{judge, print_causes, run_seeds, seeds, settings, true_ends};
use vesselhex::units::LengthUnit;

/// The bins of the population table, as the manifest names them.
const BINS: [(&str, &str); 6] = [
    ("branches_at_one_place", "branches at one place"),
    ("out_of_plane_deg", "out-of-plane angle (deg)"),
    ("daughter_spacing_radii", "daughter spacing (parent radii)"),
    ("radius_ratio", "radius ratio"),
    ("stenosis_area_percent", "stenosis (area %)"),
    ("near_pass_smaller_radii", "near pass (smaller radii)"),
];

/// One tree meshed at one preset.
struct Row {
    seed: u64,
    preset: String,
    run: Option<Run>,
    true_ends: usize,
    found: usize,
    meshed: usize,
    generation_seconds: f64,
    bins: Vec<String>,
    /// Why it fails; nothing when it passes.
    cause: Option<String>,
}

/// Writes tree `seed` into `dir` and meshes it at every preset.
fn run_seed(seed: u64, dir: &Path, binary: &Path, presets: &[String]) -> Vec<Row> {
    let clock = Instant::now();
    let written = write_random_tree(seed, &dir.join("input"), SurfaceFormat::Stl, &mut Progress::new(true, 0));
    let generation_seconds = clock.elapsed().as_secs_f64();
    let row = |preset: &str| Row {
        seed,
        preset: preset.to_string(),
        run: None,
        true_ends: 0,
        found: 0,
        meshed: 0,
        generation_seconds,
        bins: vec![String::new(); BINS.len()],
        cause: None,
    };
    let written = match written {
        Ok(w) => w,
        Err(e) => {
            return presets.iter().map(|p| Row { cause: Some(format!("generation: {e}")), ..row(p) }).collect();
        }
    };
    let manifest = serde_json::to_value(written.tree.manifest("", "")).unwrap_or_default();
    let truth = true_ends(&manifest);
    let bins: Vec<String> = BINS.iter().map(|(k, _)| manifest["bins"][k].as_str().unwrap_or("?").to_string()).collect();
    let input =
        Written { surface: written.surface, caps: vec![], unit: LengthUnit::Mm, rotation: None, end_names: vec![] };
    presets
        .iter()
        .map(|preset| {
            let run = mesh(binary, &input, &dir.join(preset), preset, &["--reproducible"]);
            let (found, meshed, cause) = judge(&run, &truth);
            // Messages name the surface by its path: the tree's folder is noise in the table.
            let cause = cause.map(|c| c.replace(&format!("{}/", dir.join("input").display()), ""));
            Row { run: Some(run), true_ends: truth.len(), found, meshed, bins: bins.clone(), cause, ..row(preset) }
        })
        .collect()
}

fn header() -> String {
    format!(
        "{:>5} {:<7} {:>4} {:>11} {:>7} {:>6} {:>6} {:>6} {:>5}  {:<48}  cause",
        "seed", "preset", "exit", "ends t/f/m", "min SJ", "wall", "skew", "s", "gen s", "bins"
    )
}

fn format_row(r: &Row) -> String {
    let nan = f64::NAN;
    let (exit, sj, wall, skew, s) = match &r.run {
        Some(run) => {
            (run.exit.map_or("-".to_string(), |c| c.to_string()), run.min_sj, run.wall_mean, run.skew, run.seconds)
        }
        None => ("-".to_string(), nan, nan, nan, 0.0),
    };
    format!(
        "{:>5} {:<7} {exit:>4} {:>11} {sj:>7.3} {wall:>6.3} {skew:>6.3} {s:>6.1} {:>5.1}  {:<48}  {}",
        r.seed,
        r.preset,
        format!("{}/{}/{}", r.true_ends, r.found, r.meshed),
        r.generation_seconds,
        r.bins.join(" "),
        r.cause.as_deref().unwrap_or("pass")
    )
}

/// The pass rate of `rows` by each bin's value.
fn print_bins(rows: &[&Row]) {
    for (k, (_, title)) in BINS.iter().enumerate() {
        let mut by: BTreeMap<&str, (usize, usize)> = BTreeMap::new();
        for r in rows {
            let e = by.entry(r.bins[k].as_str()).or_default();
            e.0 += usize::from(r.cause.is_none());
            e.1 += 1;
        }
        let cells: Vec<String> = by.iter().map(|(v, (p, n))| format!("{v}: {p}/{n}")).collect();
        println!("  {title:<32} {}", cells.join(", "));
    }
}

/// The separation survey (`VESSELHEX_TREE_SEPARATION=1`): per seed, the fused pairs and the
/// near passes the surface closes; then the counts by cause and the trees per bin.
fn survey_separation(seeds: &[u64]) {
    use vesselhex::synthetic_tree::separation::{fused_runs, passes_closed_in_surface};
    use vesselhex::synthetic_tree::RandomTree;
    let mut trees_by_cause: BTreeMap<&str, usize> = BTreeMap::new();
    let mut pairs_by_cause: BTreeMap<&str, (usize, f64)> = BTreeMap::new();
    let mut bins: BTreeMap<(usize, String), usize> = BTreeMap::new();
    let (mut fused_trees, mut closed_trees, mut passes, mut closed_passes) = (0, 0, 0, 0);
    for &seed in seeds {
        let tree = match RandomTree::generate(seed, &mut Progress::new(true, 0)) {
            Ok(tree) => tree,
            Err(e) => {
                println!("seed {seed}: {e}");
                continue;
            }
        };
        let runs = fused_runs(&tree.layout);
        let closed =
            passes_closed_in_surface(&tree.surface.vertices, &tree.surface.triangles, &tree.lumen, &tree.near_passes);
        passes += tree.near_passes.len();
        closed_passes += closed.len();
        fused_trees += usize::from(!runs.is_empty());
        closed_trees += usize::from(!closed.is_empty());
        let mut causes: Vec<&str> = runs.iter().map(|r| r.relation.name()).collect();
        causes.sort_unstable();
        causes.dedup();
        for c in causes {
            *trees_by_cause.entry(c).or_default() += 1;
        }
        for r in &runs {
            let e = pairs_by_cause.entry(r.relation.name()).or_default();
            e.0 += 1;
            e.1 = e.1.max(r.length_radii);
            println!("seed {seed}: {r}");
        }
        for (i, w) in closed {
            let p = &tree.near_passes[i];
            println!(
                "seed {seed}: near pass {} - {} (gap {:.3} mm) closed in the surface (winding {w:.2})",
                p.a, p.b, p.gap
            );
        }
        let manifest = serde_json::to_value(tree.manifest("s", "c")).unwrap_or_default();
        for (k, (name, _)) in BINS.iter().enumerate() {
            let value = manifest["bins"][name].as_str().unwrap_or("?").to_string();
            *bins.entry((k, value)).or_default() += 1;
        }
    }
    println!(
        "\nseeds {}..{}: {fused_trees} trees with a pair fused outside its junction's blend zone",
        seeds.first().unwrap_or(&0),
        seeds.last().unwrap_or(&0)
    );
    for (cause, trees) in &trees_by_cause {
        let (pairs, longest) = pairs_by_cause[cause];
        println!("  {cause}: {trees} trees, {pairs} pairs, longest run {longest:.1} radii");
    }
    println!("{closed_trees} trees with a near pass the surface closes ({closed_passes} of {passes} near passes)");
    println!("trees per bin:");
    for (k, (_, title)) in BINS.iter().enumerate() {
        let row: Vec<String> =
            bins.iter().filter(|((b, _), _)| *b == k).map(|((_, v), n)| format!("{v}: {n}")).collect();
        println!("  {title}: {}", row.join(", "));
    }
}

fn main() {
    let seeds = seeds("VESSELHEX_TREE_SEEDS", "1-200");
    if std::env::var_os("VESSELHEX_TREE_SEPARATION").is_some() {
        survey_separation(&seeds);
        return;
    }
    let (presets, binary, keep) = settings("VESSELHEX_TREE");
    let scratch = tempfile::tempdir().expect("a temporary folder");
    let root = keep.clone().unwrap_or_else(|| scratch.path().to_path_buf());
    println!("{}", header());
    let each = |seed: u64, dir: &Path| run_seed(seed, dir, &binary, &presets);
    let mut rows = run_seeds(&seeds, &root, "tree", keep.is_some(), each, format_row);
    rows.sort_by_key(|r| (presets.iter().position(|p| *p == r.preset), r.seed));
    for preset in &presets {
        let of: Vec<&Row> = rows.iter().filter(|r| &r.preset == preset).collect();
        let passed = of.iter().filter(|r| r.cause.is_none()).count();
        let ends: usize = of.iter().map(|r| r.true_ends).sum();
        let seconds: f64 = of.iter().filter_map(|r| r.run.as_ref()).map(|r| r.seconds).sum();
        let generation: f64 = of.iter().map(|r| r.generation_seconds).sum();
        println!(
            "\nrandom trees at {preset}, seeds {}..{}: {passed} of {} pass ({:.1} %); meshing {:.3} s per end \
             ({seconds:.1} s for {ends} ends), generation {:.2} s per tree",
            seeds.first().unwrap_or(&0),
            seeds.last().unwrap_or(&0),
            of.len(),
            100.0 * passed as f64 / of.len().max(1) as f64,
            seconds / ends.max(1) as f64,
            generation / of.len().max(1) as f64,
        );
        println!("pass rate by bin:");
        print_bins(&of);
        println!("failures by cause:");
        let failures: Vec<(u64, &str)> = of.iter().filter_map(|r| Some((r.seed, r.cause.as_deref()?))).collect();
        print_causes(&failures);
    }
}
