//! What the population benchmarks share (`trees`, `networks`): the seeds an environment variable
//! names, a generator's true ends, a run judged against them, and the failures grouped by cause.

use nalgebra::Point3;
use std::collections::BTreeMap;
use vesselhex::testing::suite::{bar_missed, shorten, Run};

/// The seeds the environment variable `var` names (FIRST-LAST or a comma-separated list), or
/// `default`'s.
pub fn seeds(var: &str, default: &str) -> Vec<u64> {
    let text = std::env::var(var).unwrap_or_else(|_| default.to_string());
    let number = |t: &str| t.trim().parse::<u64>().unwrap_or_else(|_| panic!("{var}: '{t}' is not a seed"));
    match text.split_once('-') {
        Some((a, b)) => (number(a)..=number(b)).collect(),
        None => text.split(',').map(number).collect(),
    }
}

/// The true ends of a manifest: centre and radius (mm).
pub fn true_ends(manifest: &serde_json::Value) -> Vec<(Point3<f64>, f64)> {
    let ends = manifest["ends"].as_array().cloned().unwrap_or_default();
    ends.iter()
        .map(|e| {
            let c = |k: usize| e["centre"][k].as_f64().unwrap_or(f64::NAN);
            (Point3::new(c(0), c(1), c(2)), e["radius_mm"].as_f64().unwrap_or(f64::NAN))
        })
        .collect()
}

/// Judges a run against the truth: (ends found, found and meshed, the cause of a failure).
pub fn judge(run: &Run, truth: &[(Point3<f64>, f64)]) -> (usize, usize, Option<String>) {
    let (mut found, mut meshed, mut missing) = (0, 0, None);
    for (k, (centre, radius)) in truth.iter().enumerate() {
        let nearest = run.ends.iter().min_by(|a, b| (a.centre - centre).norm().total_cmp(&(b.centre - centre).norm()));
        match nearest.filter(|e| (e.centre - centre).norm() <= *radius) {
            Some(e) => {
                found += 1;
                meshed += usize::from(e.meshed);
            }
            None => {
                let d = nearest.map_or(f64::INFINITY, |e| (e.centre - centre).norm());
                missing.get_or_insert(format!(
                    "true end {k} at ({:.2}, {:.2}, {:.2}) not found (nearest end {d:.2} mm, radius {radius:.2} mm)",
                    centre.x, centre.y, centre.z
                ));
            }
        }
    }
    let cause = if run.exit != Some(0) {
        let code = run.exit.map_or("a signal".to_string(), |c| c.to_string());
        Some(format!("exit {code}: {}", shorten(run.error.trim_start_matches("vesselhex: error: "), 200)))
    } else if let Some(m) = missing {
        Some(m)
    } else if meshed < truth.len() || run.ends.iter().any(|e| !e.meshed) {
        Some(format!("{meshed} of {} true ends meshed ({} ends in the report)", truth.len(), run.ends.len()))
    } else {
        bar_missed(run)
    };
    (found, meshed, cause)
}

/// `text` with each number (sign, digits, decimal point) written `#`.
fn numbers_blanked(text: &str) -> String {
    let chars: Vec<char> = text.chars().collect();
    let digit_at = |k: usize| chars.get(k).is_some_and(char::is_ascii_digit);
    let (mut out, mut k) = (String::new(), 0);
    while k < chars.len() {
        if digit_at(k) || (chars[k] == '-' && digit_at(k + 1)) {
            k += 1;
            while digit_at(k) || (chars.get(k) == Some(&'.') && digit_at(k + 1)) {
                k += 1;
            }
            out.push('#');
        } else {
            out.push(chars[k]);
            k += 1;
        }
    }
    out
}

/// The failures (seed, cause) grouped by the start of their cause with its numbers blanked.
pub fn print_causes(failures: &[(u64, &str)]) {
    let mut groups: BTreeMap<String, Vec<(u64, &str)>> = BTreeMap::new();
    for &(seed, cause) in failures {
        groups.entry(shorten(&numbers_blanked(cause), 60)).or_default().push((seed, cause));
    }
    let mut groups: Vec<_> = groups.into_iter().collect();
    groups.sort_by_key(|g| std::cmp::Reverse(g.1.len()));
    for (key, members) in groups {
        let seeds: Vec<String> = members.iter().map(|m| m.0.to_string()).collect();
        println!("  {:>3} x {key}\n        seeds {}; e.g. {}", members.len(), seeds.join(", "), members[0].1);
    }
}

/// Runs `each` on every seed, two at a time (CI machines and the reference farm have 2 cores),
/// in a folder of its own under `root` named `name_SEED` (removed after unless `keep`); prints
/// each row as it comes (`line`) and returns them all.
pub fn run_seeds<R: Send>(
    seeds: &[u64],
    root: &std::path::Path,
    name: &str,
    keep: bool,
    each: impl Fn(u64, &std::path::Path) -> Vec<R> + Sync,
    line: impl Fn(&R) -> String + Sync,
) -> Vec<R> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let next = AtomicUsize::new(0);
    let rows = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..2 {
            scope.spawn(|| {
                while let Some(&seed) = seeds.get(next.fetch_add(1, Ordering::SeqCst)) {
                    let dir = root.join(format!("{name}_{seed}"));
                    let done = each(seed, &dir);
                    if !keep {
                        let _ = std::fs::remove_dir_all(&dir);
                    }
                    let mut rows = rows.lock().unwrap_or_else(|e| e.into_inner());
                    done.iter().for_each(|r| println!("{}", line(r)));
                    rows.extend(done);
                }
            });
        }
    });
    rows.into_inner().unwrap_or_else(|e| e.into_inner())
}

/// The presets `{prefix}_PRESETS` names (comma-separated, default coarse), the `vesselhex` to
/// mesh with (`{prefix}_BIN`, default this build's) and the folder to keep the runs in
/// (`{prefix}_KEEP`), as the population benchmarks read them.
pub fn settings(prefix: &str) -> (Vec<String>, std::path::PathBuf, Option<std::path::PathBuf>) {
    let presets = std::env::var(format!("{prefix}_PRESETS"))
        .unwrap_or_else(|_| "coarse".to_string())
        .split(',')
        .map(|s| s.trim().to_string())
        .collect();
    let binary = std::env::var_os(format!("{prefix}_BIN"))
        .map_or_else(|| std::path::PathBuf::from(env!("CARGO_BIN_EXE_vesselhex")), std::path::PathBuf::from);
    (presets, binary, std::env::var_os(format!("{prefix}_KEEP")).map(std::path::PathBuf::from))
}
