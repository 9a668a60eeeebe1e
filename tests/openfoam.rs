//! The OpenFOAM writer judged by OpenFOAM itself (v1912, Debian `openfoam`): checkMesh on ASCII
//! and binary cases, splitMeshRegions on the FSI mesh, and a laminar Poiseuille run.
//!
//! Without OpenFOAM the tests print "skipped"; with `CI=true` they fail instead. Set
//! `VESSELHEX_KEEP=1` to keep the cases under the temporary folder.

use std::path::{Path, PathBuf};
use std::process::Command;
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::mesh::VesselMesh;
use vesselhex::writers::openfoam::{self, read_polymesh, PolyMesh};
use vesselhex::writers::WriteOptions;

const FOAM_DIR: &str = "/usr/share/openfoam";

/// True when OpenFOAM's binaries are on the PATH; panics when they are not and CI=true.
fn openfoam_available(test: &str) -> bool {
    let found = Command::new("sh").args(["-c", "command -v checkMesh"]).output().is_ok_and(|o| o.status.success());
    if !found {
        if std::env::var("CI").is_ok_and(|v| v == "true") {
            panic!("{test}: OpenFOAM (checkMesh) is not installed but CI=true: apt-get install -y --no-install-recommends openfoam");
        }
        eprintln!("{test}: skipped (OpenFOAM's checkMesh not found)");
    }
    found
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("vesselhex-openfoam-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn cleanup(dir: &Path) {
    if std::env::var_os("VESSELHEX_KEEP").is_none() {
        let _ = std::fs::remove_dir_all(dir);
    } else {
        eprintln!("kept {}", dir.display());
    }
}

/// Runs an OpenFOAM program; returns its output (stdout + stderr) and panics when it fails.
fn foam(program: &str, args: &[&str], case: &Path) -> String {
    let wm = std::env::var("WM_PROJECT_DIR").unwrap_or_else(|_| FOAM_DIR.into());
    let out = Command::new(program)
        .args(["-case", case.to_str().unwrap()])
        .args(args)
        .env("WM_PROJECT_DIR", wm)
        .env("OMP_NUM_THREADS", "1")
        .output()
        .unwrap_or_else(|e| panic!("cannot run {program}: {e}"));
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{program} {args:?} on {} failed:\n{text}", case.display());
    text
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}

/// checkMesh on a copy of the case (it writes sets into the case it checks). Pass = `Mesh OK.`
/// and no line starting with `***` (its exit code is always 0). Returns the summary: mesh
/// statistics and the patch table, which must not depend on the file format.
fn check_mesh(case: &Path, extra: &[&str]) -> Vec<String> {
    let copy = case.with_file_name(format!("{}-checkMesh", case.file_name().unwrap().to_str().unwrap()));
    let _ = std::fs::remove_dir_all(&copy);
    copy_dir(case, &copy);
    let mut args = vec!["-noFunctionObjects"];
    args.extend_from_slice(extra);
    let log = foam("checkMesh", &args, &copy);
    let _ = std::fs::remove_dir_all(&copy);
    let failed: Vec<&str> = log.lines().filter(|l| l.trim_start().starts_with("***")).collect();
    assert!(failed.is_empty(), "checkMesh on {}: {failed:?}\n{log}", case.display());
    assert!(log.lines().any(|l| l.trim() == "Mesh OK."), "checkMesh on {} did not say Mesh OK.:\n{log}", case.display());
    let mut summary = Vec::new();
    let mut section = "";
    for line in log.lines() {
        let t = line.trim();
        if t.starts_with("Mesh stats") || t.starts_with("Checking patch topology") || t.starts_with("Checking geometry") {
            section = t;
            continue;
        }
        if section.starts_with("Mesh stats") && t.contains(':') {
            summary.push(t.split_whitespace().collect::<Vec<_>>().join(" "));
        }
        if section.starts_with("Checking patch topology") && !t.is_empty() && !t.starts_with("Patch") {
            summary.push(t.split_whitespace().collect::<Vec<_>>().join(" "));
        }
    }
    summary
}

/// Counts of the summary lines, e.g. "cells: 2240".
fn stat(summary: &[String], key: &str) -> usize {
    summary
        .iter()
        .find_map(|l| l.strip_prefix(&format!("{key}: ")))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no '{key}' in {summary:?}"))
}

fn write(mesh: &VesselMesh, format: &str, options: &WriteOptions, dir: &Path) -> PathBuf {
    let writer = vesselhex::writers::writer(format).unwrap();
    let files = writer(mesh, options, dir).unwrap();
    assert!(files.iter().all(|f| f.starts_with(format)), "{files:?}");
    dir.join(format)
}

fn assert_rules(poly: &PolyMesh, what: &str) {
    let errors = poly.verify();
    assert!(errors.is_empty(), "{what}: {} violations, first: {:?}", errors.len(), &errors[..errors.len().min(5)]);
}

fn tube(config: &MeshConfig) -> VesselMesh {
    vesselhex::testing::straight_tube_mesh(config).unwrap().mesh
}

fn check_ascii_and_binary(mesh: &VesselMesh, name: &str) {
    let dir = scratch(name);
    let mut summaries = Vec::new();
    for binary in [false, true] {
        let options = WriteOptions { foam_binary: binary, ..Default::default() };
        let case = write(mesh, "openfoam", &options, &dir.join(if binary { "binary" } else { "ascii" }));
        // What checkMesh misses, on the files as written.
        let poly = read_polymesh(&case).unwrap();
        assert_rules(&poly, name);
        let expected = openfoam::lumen_polymesh(mesh).unwrap();
        assert_eq!(poly.points, expected.points, "{name}: points do not read back bit for bit");
        assert_eq!((poly.faces.len(), poly.n_internal(), poly.n_cells), (expected.faces.len(), expected.n_internal(), expected.n_cells));
        let s = check_mesh(&case, &[]);
        assert_eq!(stat(&s, "cells"), poly.n_cells, "{s:?}");
        assert_eq!(stat(&s, "hexahedra"), poly.n_cells, "{s:?}");
        assert_eq!(stat(&s, "faces"), poly.faces.len(), "{s:?}");
        assert_eq!(stat(&s, "internal faces"), poly.n_internal(), "{s:?}");
        assert_eq!(stat(&s, "points"), poly.points.len(), "{s:?}");
        for p in &poly.patches {
            let row = s.iter().find(|l| l.split(' ').next() == Some(p.name.as_str())).unwrap_or_else(|| panic!("no patch {} in {s:?}", p.name));
            assert_eq!(row.split(' ').nth(1), Some(p.size.to_string().as_str()), "{row}");
        }
        eprintln!("{name} {}: checkMesh Mesh OK; {}", if binary { "binary" } else { "ascii" }, s.join("; "));
        summaries.push(s);
    }
    assert_eq!(summaries[0], summaries[1], "{name}: ASCII and binary give different checkMesh summaries");
    cleanup(&dir);
}

#[test]
fn checkmesh_accepts_the_straight_tube_ascii_and_binary() {
    if !openfoam_available("checkmesh_accepts_the_straight_tube_ascii_and_binary") {
        return;
    }
    for preset in [Preset::Coarse, Preset::Medium] {
        check_ascii_and_binary(&tube(&MeshConfig::preset(preset)), &format!("tube-{preset:?}"));
    }
    // An odd core and a graded boundary layer.
    let mut c = MeshConfig::preset(Preset::Coarse);
    c.lumen.core_elements = 3;
    c.lumen.radial_elements = 6;
    c.lumen.first_cell_height = Some(0.05);
    check_ascii_and_binary(&tube(&c), "tube-odd-core");
}
