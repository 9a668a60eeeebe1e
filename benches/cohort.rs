//! Cohort benchmark (issue 20's time bars): `cargo bench --bench cohort` meshes every case of
//! `../shared/vessels/manifest.json` (or `VESSELHEX_VESSELS`) from its bare surface through
//! `vesselhex mesh`, at the coarse and the medium preset, writing `mesh.vtu` only, and prints
//! the wall-clock seconds of the whole run (reading and the centerlines' computation included)
//! beside the bars: 2 s at coarse, 8 s at medium. One run per case: the work is deterministic,
//! the machine's load is not, so read the figures on a quiet machine.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Seconds per case the issue asks for, by preset.
const BARS: [(&str, f64); 2] = [("coarse", 2.0), ("medium", 8.0)];

fn vessels() -> PathBuf {
    std::env::var_os("VESSELHEX_VESSELS")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/vessels"))
}

/// (name, surface file, unit) of every manifest case.
fn cases(vessels: &Path) -> Vec<(String, String, String)> {
    let text = std::fs::read_to_string(vessels.join("manifest.json")).expect("the cohort's manifest");
    let manifest: serde_json::Value = serde_json::from_str(&text).expect("a JSON manifest");
    let text_of = |c: &serde_json::Value, key: &str| c[key].as_str().unwrap_or_default().to_string();
    manifest["cases"]
        .as_array()
        .expect("a list of cases")
        .iter()
        .map(|c| {
            // The manifest's unitless case is in metres (its README says so).
            let unit = if text_of(c, "unit").starts_with("unitless") { "m".to_string() } else { text_of(c, "unit") };
            (text_of(c, "name"), text_of(c, "primary_surface"), unit)
        })
        .collect()
}

fn main() {
    let vessels = vessels();
    if !vessels.join("manifest.json").exists() {
        println!("cohort benchmark: no manifest in {} (set VESSELHEX_VESSELS)", vessels.display());
        return;
    }
    let out = tempfile::tempdir().expect("a temporary folder");
    for (preset, bar) in BARS {
        println!("\n{preset} (bar {bar} s): case, seconds, result");
        let (mut within_time, mut meshed) = (0, 0);
        let all = cases(&vessels);
        for (name, surface, unit) in &all {
            let folder = out.path().join(format!("{preset}-{name}"));
            let surface = vessels.join(name).join(surface);
            let clock = Instant::now();
            let output = Command::new(env!("CARGO_BIN_EXE_vesselhex"))
                .args(["mesh", "--surface"])
                .arg(&surface)
                .args(["--units", unit, "--preset", preset, "--formats", "vtu", "--quiet", "--output"])
                .arg(&folder)
                .output()
                .expect("vesselhex runs");
            let seconds = clock.elapsed().as_secs_f64();
            let result = match output.status.code() {
                Some(0) => {
                    meshed += 1;
                    "meshed"
                }
                // Written with a vessel end left out (a stub too short for its junction).
                Some(3) => {
                    meshed += 1;
                    "meshed, an end left out"
                }
                Some(1) => "refused",
                _ => "other exit",
            };
            within_time += usize::from(seconds <= bar);
            let mark = if seconds <= bar { "" } else { "  (over the bar)" };
            println!("{preset}: {name:<34} {seconds:>7.2} s  {result}{mark}");
            let _ = std::fs::remove_dir_all(&folder);
        }
        println!("{preset}: {meshed} of {} meshed; {within_time} of {} within {bar} s", all.len(), all.len());
    }
}
