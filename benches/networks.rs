//! The random-network population (issue 49): `cargo bench --bench networks` writes each
//! generated network of a range of seeds ([`vesselhex::synthetic_network`]: rings fed by two or
//! three inlets, grafts rejoining their host, circles of Willis), meshes it from the bare
//! surface through `vesselhex mesh --surface network_SEED.stl --preset P --inlet ...` with an
//! `--inlet` at each true inlet (a child process per network and preset, two at a time) and
//! compares the mesh with the network's truth. A run passes when it exits 0, every true end is
//! meshed, every loop is closed in the mesh (no `surface_loops` warning) and every bar holds
//! (minimum scaled Jacobian >= 0.2, wall mean >= 0.85, lumen mean equi-angle skew <= 0.35,
//! interface sub-micron). It prints a row per run, then the pass rate by shape and by inlet
//! count, the failures grouped by cause and the meshing seconds per end.
//!
//! `VESSELHEX_NETWORK_SEEDS=FIRST-LAST` (default 1-100) or a comma-separated list;
//! `VESSELHEX_NETWORK_PRESETS` (comma-separated, default coarse); `VESSELHEX_NETWORK_BIN=FILE`
//! meshes with another build of `vesselhex`; `VESSELHEX_NETWORK_KEEP=DIR` keeps the networks and
//! meshes in DIR.

use std::collections::BTreeMap;
use std::path::Path;
use vesselhex::progress::Progress;
use vesselhex::synthetic_network::write_random_network;
use vesselhex::synthetic_tree::SurfaceFormat;
use vesselhex::testing::mutations::Written;
use vesselhex::testing::suite::{mesh, Run};
use vesselhex::units::LengthUnit;

mod population;
use population::{judge, print_causes, run_seeds, seeds, settings, true_ends};

/// One network meshed at one preset.
struct Row {
    seed: u64,
    preset: String,
    shape: String,
    inlets: usize,
    run: Option<Run>,
    true_ends: usize,
    meshed: usize,
    /// Why it fails; nothing when it passes.
    cause: Option<String>,
}

/// Writes network `seed` into `dir` and meshes it at every preset.
fn run_seed(seed: u64, dir: &Path, binary: &Path, presets: &[String]) -> Vec<Row> {
    let row = |preset: &str| Row {
        seed,
        preset: preset.to_string(),
        shape: "?".into(),
        inlets: 0,
        run: None,
        true_ends: 0,
        meshed: 0,
        cause: None,
    };
    let written =
        match write_random_network(seed, None, &dir.join("input"), SurfaceFormat::Stl, &mut Progress::new(true, 0)) {
            Ok(w) => w,
            Err(e) => {
                return presets.iter().map(|p| Row { cause: Some(format!("generation: {e}")), ..row(p) }).collect()
            }
        };
    let manifest: serde_json::Value =
        std::fs::read_to_string(&written.manifest).ok().and_then(|t| serde_json::from_str(&t).ok()).unwrap_or_default();
    let truth = true_ends(&manifest);
    let ends = manifest["ends"].as_array().cloned().unwrap_or_default();
    let inlet_args: Vec<String> = ends
        .iter()
        .filter(|e| e["role"] == "inlet")
        .map(|e| {
            let c: Vec<String> = (0..3).map(|k| e["centre"][k].as_f64().unwrap_or(f64::NAN).to_string()).collect();
            format!("--inlet={}", c.join(","))
        })
        .collect();
    let mut extra = vec!["--reproducible"];
    extra.extend(inlet_args.iter().map(String::as_str));
    let shape = manifest["shape"].as_str().unwrap_or("?").to_string();
    let input =
        Written { surface: written.surface, caps: vec![], unit: LengthUnit::Mm, rotation: None, end_names: vec![] };
    presets
        .iter()
        .map(|preset| {
            let out = dir.join(preset);
            let run = mesh(binary, &input, &out, preset, &extra);
            let (_, meshed, cause) = judge(&run, &truth);
            let cause = cause.or_else(|| loop_left_open(&out));
            let cause = cause.map(|c| c.replace(&format!("{}/", dir.join("input").display()), ""));
            Row {
                shape: shape.clone(),
                inlets: inlet_args.len(),
                run: Some(run),
                true_ends: truth.len(),
                meshed,
                cause,
                ..row(preset)
            }
        })
        .collect()
}

/// The `surface_loops` warning of the report in `out`, if any: a loop the mesh left open.
fn loop_left_open(out: &Path) -> Option<String> {
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).ok()?).ok()?;
    let warnings = report["warnings"].as_array()?;
    let open = warnings.iter().find(|w| w["kind"] == "surface_loops")?;
    Some(format!("loop left open: {}", open["message"].as_str().unwrap_or_default()))
}

fn format_row(r: &Row) -> String {
    let (exit, sj, wall, skew, s) = match &r.run {
        Some(run) => {
            (run.exit.map_or("-".to_string(), |c| c.to_string()), run.min_sj, run.wall_mean, run.skew, run.seconds)
        }
        None => ("-".to_string(), f64::NAN, f64::NAN, f64::NAN, 0.0),
    };
    format!(
        "{:>5} {:<7} {:<17} {:>6} {exit:>4} {:>9} {sj:>7.3} {wall:>6.3} {skew:>6.3} {s:>6.1}  {}",
        r.seed,
        r.preset,
        r.shape,
        r.inlets,
        format!("{}/{}", r.true_ends, r.meshed),
        r.cause.as_deref().unwrap_or("pass")
    )
}

/// The pass rate of `rows` by `key`.
fn print_by(title: &str, rows: &[&Row], key: impl Fn(&Row) -> String) {
    let mut by: BTreeMap<String, (usize, usize)> = BTreeMap::new();
    for r in rows {
        let e = by.entry(key(r)).or_default();
        e.0 += usize::from(r.cause.is_none());
        e.1 += 1;
    }
    let cells: Vec<String> = by.iter().map(|(v, (p, n))| format!("{v}: {p}/{n}")).collect();
    println!("  {title:<12} {}", cells.join(", "));
}

fn main() {
    let seeds = seeds("VESSELHEX_NETWORK_SEEDS", "1-100");
    let (presets, binary, keep) = settings("VESSELHEX_NETWORK");
    let scratch = tempfile::tempdir().expect("a temporary folder");
    let root = keep.clone().unwrap_or_else(|| scratch.path().to_path_buf());
    println!(
        "{:>5} {:<7} {:<17} {:>6} {:>4} {:>9} {:>7} {:>6} {:>6} {:>6}  cause",
        "seed", "preset", "shape", "inlets", "exit", "ends t/m", "min SJ", "wall", "skew", "s"
    );
    let each = |seed: u64, dir: &Path| run_seed(seed, dir, &binary, &presets);
    let mut rows = run_seeds(&seeds, &root, "network", keep.is_some(), each, format_row);
    rows.sort_by_key(|r| (presets.iter().position(|p| *p == r.preset), r.seed));
    for preset in &presets {
        let of: Vec<&Row> = rows.iter().filter(|r| &r.preset == preset).collect();
        let passed = of.iter().filter(|r| r.cause.is_none()).count();
        let ends: usize = of.iter().map(|r| r.true_ends).sum();
        let seconds: f64 = of.iter().filter_map(|r| r.run.as_ref()).map(|r| r.seconds).sum();
        println!(
            "\nrandom networks at {preset}, seeds {}..{}: {passed} of {} pass ({:.1} %); meshing {:.3} s per end \
             ({seconds:.1} s for {ends} ends)",
            seeds.first().unwrap_or(&0),
            seeds.last().unwrap_or(&0),
            of.len(),
            100.0 * passed as f64 / of.len().max(1) as f64,
            seconds / ends.max(1) as f64,
        );
        println!("pass rate by:");
        print_by("shape", &of, |r| r.shape.clone());
        print_by("inlets", &of, |r| r.inlets.to_string());
        print_by("ends", &of, |r| format!("{:02}", r.true_ends));
        println!("failures by cause:");
        let failures: Vec<(u64, &str)> = of.iter().filter_map(|r| Some((r.seed, r.cause.as_deref()?))).collect();
        print_causes(&failures);
    }
}
