//! The Python package's tests (pytest, `python/tests`) run from `cargo test`, so the README's one
//! test command covers the package too. They need a Python that imports the wheel built from this
//! checkout and pytest: `VESSELHEX_PYTHON` names it (`.ci/run` sets its venv's), else `python3`.
//! Missing: "skipped" outside CI, a failure under `CI=true`. The command they compare against is
//! the one cargo built for this test run.

mod common;

use common::{crate_dir, under_ci};
use std::process::Command;

/// The command docs/guide/testing.md shows; the interpreter is replaced by `VESSELHEX_PYTHON`.
const PYTEST: &str = "python3 -m pytest python/tests";

#[test]
fn python_package_tests_pass() {
    let python = std::env::var("VESSELHEX_PYTHON").unwrap_or_else(|_| "python3".into());
    // Where the interpreter finds the package's Python half, so a wheel built from another
    // checkout (or an older one of this) is caught instead of tested.
    let probe = Command::new(&python).args(["-c", "import pytest, vesselhex; print(vesselhex.__file__)"]).output();
    let installed = match probe {
        Ok(o) if o.status.success() => String::from_utf8_lossy(&o.stdout).trim().to_string(),
        _ => {
            let why = format!(
                "{python} cannot import vesselhex and pytest (build and install the wheel: docs/python.md; \
                 pip install pytest meshio matplotlib pyvista \"dask[distributed]\" pandas; or set VESSELHEX_PYTHON)"
            );
            assert!(!under_ci(), "CI=true but {why}");
            eprintln!("skipped: {why}");
            return;
        }
    };
    let ours = std::fs::read(crate_dir().join("python/vesselhex/__init__.py")).unwrap();
    let theirs = std::fs::read(&installed).unwrap_or_default();
    assert!(
        ours == theirs,
        "the vesselhex {python} imports ({installed}) is not this checkout's: rebuild and reinstall the wheel (docs/python.md)"
    );

    let mut words = PYTEST.split_whitespace().skip(1);
    let out = Command::new(&python)
        .args(words.by_ref())
        // -p no:cacheprovider: no .pytest_cache left in the checkout; -rs: skips named.
        .args(["-q", "-rs", "-p", "no:cacheprovider"])
        .current_dir(crate_dir())
        .env("VESSELHEX_BIN", env!("CARGO_BIN_EXE_vesselhex"))
        .output()
        .expect("run pytest");
    let stdout = String::from_utf8_lossy(&out.stdout);
    // pytest's summary, e.g. "45 passed in 80.1s", shown with --nocapture
    println!("{}", stdout.lines().last().unwrap_or(""));
    assert!(
        out.status.success(),
        "pytest failed ({}):\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
}
