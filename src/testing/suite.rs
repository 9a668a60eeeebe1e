//! The mutation suite's runs (issue 45): each written mutation ([`super::mutations`]) meshed
//! from the bare surface through `vesselhex mesh`, its figures read from `report.json`, and a
//! verdict against the bars and the case as given: exit 0, every end meshed, the same ends as
//! the unmutated case's (same count, each within one of its radii) and the same number of
//! branches, minimum scaled Jacobian >= 0.2, wall mean >= 0.85, lumen mean equi-angle skew <=
//! 0.35, interface nodes within a micrometre of the surface, and ends named after the caps
//! given. The CI test runs a sample; `cargo bench --bench mutations` runs them all.

use super::mutations::{CohortCase, Written};
use nalgebra::Point3;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

/// The bars every mesh must hold (issue 45's "Done when").
pub const MIN_SCALED_JACOBIAN: f64 = 0.2;
pub const MIN_WALL_MEAN: f64 = 0.85;
pub const MAX_LUMEN_SKEW: f64 = 0.35;
pub const MAX_INTERFACE_UM: f64 = 1.0;

/// An end as a run's report gives it, in the case's own frame (mm).
#[derive(Debug, Clone)]
pub struct EndSeen {
    pub centre: Point3<f64>,
    pub radius: f64,
    pub meshed: bool,
    pub name: Option<String>,
}

/// What one run gave.
#[derive(Debug, Clone)]
pub struct Run {
    pub exit: Option<i32>,
    /// The error line of a refusal (empty otherwise).
    pub error: String,
    pub ends: Vec<EndSeen>,
    pub branches: usize,
    pub min_sj: f64,
    pub wall_mean: f64,
    pub skew: f64,
    pub interface_um: f64,
    pub seconds: f64,
}

/// Meshes a written mutation with `binary` (the `vesselhex` command) into `out` at `preset`
/// (quiet, `mesh.vtu` only, plus `extra` arguments).
pub fn mesh(binary: &Path, written: &Written, out: &Path, preset: &str, extra: &[&str]) -> Run {
    let clock = Instant::now();
    let output = Command::new(binary)
        .arg("mesh")
        .args(written.args())
        .args(["--preset", preset, "--quiet", "--force", "--output"])
        .arg(out)
        .args(extra)
        .output();
    let seconds = clock.elapsed().as_secs_f64();
    let mut run = Run {
        exit: None,
        error: String::new(),
        ends: vec![],
        branches: 0,
        min_sj: f64::NAN,
        wall_mean: f64::NAN,
        skew: f64::NAN,
        interface_um: f64::NAN,
        seconds,
    };
    let output = match output {
        Ok(o) => o,
        Err(e) => {
            run.error = format!("cannot run {}: {e}", binary.display());
            return run;
        }
    };
    run.exit = output.status.code();
    let stderr = String::from_utf8_lossy(&output.stderr);
    run.error = stderr.lines().find(|l| l.starts_with("vesselhex: error:")).unwrap_or_default().to_string();
    if run.error.is_empty() && run.exit != Some(0) && run.exit != Some(3) {
        run.error = stderr.lines().last().unwrap_or("no message").to_string();
    }
    if let Some(report) =
        std::fs::read_to_string(out.join("report.json")).ok().and_then(|t| serde_json::from_str(&t).ok())
    {
        read_report(&mut run, &report, written);
    }
    run
}

/// The run's figures from its report (lengths in mm: the default output unit).
fn read_report(run: &mut Run, report: &serde_json::Value, written: &Written) {
    let number = |pointer: &str| report.pointer(pointer).and_then(|v| v.as_f64()).unwrap_or(f64::NAN);
    run.min_sj = number("/lumen/scaled_jacobian/min").min(number("/wall/scaled_jacobian/min"));
    run.wall_mean = number("/wall/scaled_jacobian/mean");
    run.skew = number("/lumen/equiangle_skew/mean");
    run.interface_um = number("/surface_accuracy/node_to_surface_um/max");
    run.branches = report["branches"].as_array().map_or(0, |b| b.len());
    // Why an end was not meshed (exit 3), from its warning.
    let unmeshed = ["end_not_meshed", "branch_not_meshed", "sac_not_meshed"];
    let warnings = report["warnings"].as_array().into_iter().flatten();
    if let Some(w) = warnings.clone().find(|w| unmeshed.iter().any(|k| w["kind"] == *k)) {
        run.error =
            format!("{}: {}", w["kind"].as_str().unwrap_or_default(), w["message"].as_str().unwrap_or_default());
    }
    run.ends = report["ends"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|e| {
            let p = |k: usize| e["position"][k].as_f64().unwrap_or(f64::NAN);
            EndSeen {
                centre: written.to_case_frame(Point3::new(p(0), p(1), p(2))),
                radius: e["radius"].as_f64().unwrap_or(f64::NAN),
                meshed: e["meshed"] == true,
                name: e["name"].as_str().map(str::to_string),
            }
        })
        .collect();
}

/// Why a run fails the suite (one line), or nothing when it passes. `reference` is the case
/// as given, when it meshed; without it the ends are counted against the case's true ends.
pub fn verdict(run: &Run, reference: Option<&Run>, case: &CohortCase, written: &Written) -> Option<String> {
    if run.exit != Some(0) {
        let code = run.exit.map_or("a signal".to_string(), |c| c.to_string());
        let error = run.error.trim_start_matches("vesselhex: error: ");
        return Some(format!("exit {code}: {}", shorten(error, 240)));
    }
    let meshed = run.ends.iter().filter(|e| e.meshed).count();
    if meshed < run.ends.len() {
        return Some(format!("{meshed} of {} ends meshed", run.ends.len()));
    }
    match reference.filter(|r| r.exit == Some(0)) {
        Some(r) => {
            if let Some(why) = ends_differ(run, r) {
                return Some(why);
            }
        }
        None if run.ends.len() < case.ends => {
            return Some(format!("{} ends, the case has {}", run.ends.len(), case.ends));
        }
        None => {}
    }
    if let Some(why) = bar_missed(run) {
        return Some(why);
    }
    let names: Vec<&str> = run.ends.iter().filter_map(|e| e.name.as_deref()).collect();
    let missing: Vec<&String> = written.end_names.iter().filter(|n| !names.contains(&n.as_str())).collect();
    (!missing.is_empty()).then(|| format!("no end named {missing:?} (ends named {names:?})"))
}

/// The first bar the run's mesh misses (minimum scaled Jacobian, wall mean, lumen skew,
/// interface), or nothing when it holds them all.
pub fn bar_missed(run: &Run) -> Option<String> {
    let bars = [
        (run.min_sj >= MIN_SCALED_JACOBIAN, format!("min scaled Jacobian {:.3} < {MIN_SCALED_JACOBIAN}", run.min_sj)),
        (run.wall_mean >= MIN_WALL_MEAN, format!("wall mean {:.3} < {MIN_WALL_MEAN}", run.wall_mean)),
        (run.skew <= MAX_LUMEN_SKEW, format!("lumen skew {:.3} > {MAX_LUMEN_SKEW}", run.skew)),
        (run.interface_um < MAX_INTERFACE_UM, format!("interface {:.3} um off the surface", run.interface_um)),
    ];
    bars.into_iter().find(|b| !b.0).map(|(_, why)| why)
}

/// How the run's ends differ from the reference's: their number, an end of the reference with
/// none of the run's within its radius, or the number of branches.
fn ends_differ(run: &Run, reference: &Run) -> Option<String> {
    if run.ends.len() != reference.ends.len() {
        return Some(format!("{} ends, as given {}", run.ends.len(), reference.ends.len()));
    }
    for e in &reference.ends {
        let nearest = run.ends.iter().map(|o| (o.centre - e.centre).norm()).fold(f64::INFINITY, f64::min);
        if nearest > e.radius {
            let c = e.centre;
            return Some(format!(
                "no end within {:.2} mm of ({:.2}, {:.2}, {:.2}) (nearest {nearest:.2} mm)",
                e.radius, c.x, c.y, c.z
            ));
        }
    }
    (run.branches != reference.branches).then(|| format!("{} branches, as given {}", run.branches, reference.branches))
}

/// Where a failure's cause lies, from its message: the junction mesher and the cross-sections
/// (their own refusals), or the input and the centerlines (everything else: ends, their
/// number and places, the surface's reading).
/// `cause` is shortened (see [`shorten`]), so each fragment is one that comes early in its message.
pub fn stage_of(cause: &str) -> &'static str {
    const SECTIONS: [&str; 11] = [
        "cannot be ordered around a common axis",
        "in the junction at (",
        "no cross-section of the branch up to",
        "rays miss",
        "is clear of the other branches",
        "at most 5 can share one junction",
        "the junction's transition needs",
        "has all its rays meeting the lumen wall",
        "does not close",
        "has clean cross-sections",
        "degrees where",
    ];
    if SECTIONS.iter().any(|s| cause.contains(s)) {
        "junction mesher / cross-sections"
    } else {
        "input / centerlines"
    }
}

pub fn shorten(text: &str, most: usize) -> String {
    match text.char_indices().nth(most) {
        Some((i, _)) => format!("{}...", &text[..i]),
        None => text.to_string(),
    }
}

/// The table's header and one row per run.
pub fn header() -> String {
    format!(
        "{:<32} {:<13} {:>4} {:>6} {:>7} {:>6} {:>6} {:>6}  verdict",
        "case", "mutation", "exit", "ends", "min SJ", "wall", "skew", "s"
    )
}

pub fn row(case: &str, mutation: &str, run: &Run, verdict: &Option<String>) -> String {
    let meshed = run.ends.iter().filter(|e| e.meshed).count();
    let exit = run.exit.map_or("-".to_string(), |c| c.to_string());
    format!(
        "{case:<32} {mutation:<13} {exit:>4} {:>6} {:>7.3} {:>6.3} {:>6.3} {:>6.1}  {}",
        format!("{meshed}/{}", run.ends.len()),
        run.min_sj,
        run.wall_mean,
        run.skew,
        run.seconds,
        verdict.as_deref().unwrap_or("pass")
    )
}
