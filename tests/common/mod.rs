//! Shared helpers of the integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn crate_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

pub fn fixture(name: &str) -> (PathBuf, PathBuf) {
    let dir = crate_dir().join("fixtures");
    (dir.join(format!("{name}.stl")), dir.join(format!("{name}_centerline.csv")))
}

/// A fresh empty folder under the system temp dir, unique per test.
pub fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vesselhex-test-{}-{tag}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Whether we run under CI, where every external program and data folder must be present.
pub fn under_ci() -> bool {
    std::env::var("CI").map(|v| v == "true" || v == "1").unwrap_or(false)
}

/// The real vessels folder, or None (with a "skipped" line) outside CI when it is missing.
pub fn vessels_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("VESSELHEX_VESSELS")
        .map(PathBuf::from)
        .unwrap_or_else(|| crate_dir().join("../shared/vessels"));
    if dir.join("README.md").exists() {
        return Some(dir);
    }
    assert!(!under_ci(), "CI=true but the vessels folder {} is missing", dir.display());
    eprintln!("skipped: vessels folder {} not found (set VESSELHEX_VESSELS)", dir.display());
    None
}

/// Runs `vesselhex` with arguments.
pub fn vesselhex(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vesselhex")).args(args).output().expect("run vesselhex")
}

pub fn path_str(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Runs `vesselhex mesh` and returns the parsed report; panics with stderr on failure.
pub fn mesh_cli(surface: &Path, centerlines: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["mesh", "--surface", path_str(surface), "--centerlines", path_str(centerlines), "--output", path_str(out), "--quiet"];
    args.extend_from_slice(extra);
    let o = vesselhex(&args);
    assert!(o.status.success(), "vesselhex failed: {}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(out.join("report.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// A Python interpreter with `module` importable, or None outside CI (skipped); under CI a
/// missing module is a failure.
pub fn python_with(module: &str) -> Option<String> {
    for py in ["python3", "python"] {
        let ok = Command::new(py).args(["-c", &format!("import {module}")]).output().map(|o| o.status.success()).unwrap_or(false);
        if ok {
            return Some(py.to_string());
        }
    }
    assert!(!under_ci(), "CI=true but python module {module} is not installed");
    eprintln!("skipped: python module {module} not installed");
    None
}

/// Lists every file under a folder (recursively).
pub fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = vec![];
    if let Ok(rd) = std::fs::read_dir(dir) {
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                out.extend(files_under(&p));
            } else {
                out.push(p);
            }
        }
    }
    out
}
