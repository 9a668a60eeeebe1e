//! The whole mutation suite (issue 45): `cargo bench --bench mutations` writes every case of
//! `../shared/vessels/manifest.json` (or `VESSELHEX_VESSELS`) every way of
//! [`vesselhex::testing::mutations::Mutation`], meshes each from the bare surface at the coarse
//! preset through `vesselhex mesh`, and prints the case x mutation table (exit, ends meshed,
//! minimum scaled Jacobian, wall mean, lumen skew, seconds, verdict), then the pass rate and
//! every failure with its one-line cause. `VESSELHEX_MUTATION_CASES` and `VESSELHEX_MUTATIONS`
//! (comma-separated names) run part of it; `VESSELHEX_MUTATION_KEEP=DIR` writes the inputs
//! and outputs into DIR and keeps them; `VESSELHEX_MUTATION_BIN=FILE` meshes with another build of
//! `vesselhex` (a baseline); `VESSELHEX_MUTATION_WRITE_ONLY=1` with `..._KEEP` only writes the inputs.

use std::path::{Path, PathBuf};
use vesselhex::testing::mutations::{cohort_cases, Base, Mutation};
use vesselhex::testing::suite::{header, mesh, row, verdict};

fn vessels() -> PathBuf {
    std::env::var_os("VESSELHEX_VESSELS")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/vessels"))
}

/// The names a comma-separated variable lists, or None when it is not set.
fn listed(variable: &str) -> Option<Vec<String>> {
    std::env::var(variable).ok().map(|v| v.split(',').map(|s| s.trim().to_string()).collect())
}

fn main() {
    let vessels = vessels();
    let Ok(cases) = cohort_cases(&vessels) else {
        println!("mutation suite: no manifest in {} (set VESSELHEX_VESSELS)", vessels.display());
        return;
    };
    let only_cases = listed("VESSELHEX_MUTATION_CASES");
    let mutations: Vec<Mutation> = match listed("VESSELHEX_MUTATIONS") {
        Some(names) => names.iter().filter_map(|n| Mutation::from_name(n)).collect(),
        None => Mutation::ALL.to_vec(),
    };
    let binary = std::env::var_os("VESSELHEX_MUTATION_BIN")
        .map_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_vesselhex")), PathBuf::from);
    let binary = binary.as_path();
    let scratch = tempfile::tempdir().expect("a temporary folder");
    let keep = std::env::var_os("VESSELHEX_MUTATION_KEEP").map(PathBuf::from);
    let root = keep.clone().unwrap_or_else(|| scratch.path().to_path_buf());
    println!("{}", header());
    // Runs that failed, and cases or mutations that could not be prepared or written (no run).
    let (mut runs, mut failures, mut unrun) = (0, vec![], vec![]);
    for case in cases.iter().filter(|c| only_cases.as_ref().is_none_or(|o| o.contains(&c.name))) {
        let base = match Base::new(case) {
            Ok(base) => base,
            Err(e) => {
                println!("{:<32} cannot be prepared: {e}", case.name);
                unrun.push(format!("{}: cannot be prepared: {e}", case.name));
                continue;
            }
        };
        let mut reference = None;
        for &mutation in &mutations {
            let dir = root.join(&case.name).join(mutation.name());
            let written = match base.write(mutation, &dir.join("input")) {
                Ok(Some(w)) => w,
                Ok(None) => continue,
                Err(e) => {
                    unrun.push(format!("{} {}: cannot be written: {e}", case.name, mutation.name()));
                    continue;
                }
            };
            if std::env::var_os("VESSELHEX_MUTATION_WRITE_ONLY").is_some() {
                println!("{} {}: {}", case.name, mutation.name(), written.args().join(" "));
                continue;
            }
            let run = mesh(binary, &written, &dir.join("out"), "coarse", &[]);
            let judged = verdict(&run, reference.as_ref(), case, &written);
            println!("{}", row(&case.name, mutation.name(), &run, &judged));
            runs += 1;
            if let Some(why) = &judged {
                failures.push(format!("{} {}: {why}", case.name, mutation.name()));
            }
            if mutation == Mutation::AsGiven {
                reference = Some(run);
            }
            if keep.is_none() {
                let _ = std::fs::remove_dir_all(&dir);
            }
        }
        // Without the case as given in the list, the others are judged against its true ends.
    }
    let passed = runs - failures.len();
    println!(
        "\nmutation suite at coarse: {passed} of {runs} runs pass ({:.1} %); {} failures:",
        100.0 * passed as f64 / runs.max(1) as f64,
        failures.len()
    );
    for f in &failures {
        println!("  [{}] {f}", vesselhex::testing::suite::stage_of(f));
    }
    for u in &unrun {
        println!("  not run: {u}");
    }
}
