//! Shared helpers of the integration tests.
#![allow(dead_code)]

use indexmap::IndexMap;
use nalgebra::{Matrix3, Point3, Vector3};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use vesselhex::config::MeshConfig;
use vesselhex::input::{read_centerlines, read_surface, CenterlinePolyline, Centerlines, TriangleSurface};
use vesselhex::mesh::VesselMesh;
use vesselhex::progress::Progress;
use vesselhex::surface::LumenSurface;
use vesselhex::units::LengthUnit;

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
    let mut args = vec!["--centerlines", path_str(centerlines)];
    args.extend_from_slice(extra);
    mesh_surface_cli(surface, out, &args)
}

/// Runs `vesselhex mesh --surface SURFACE --output OUT --quiet` with `extra` arguments (without
/// `--centerlines`, vesselhex computes them) and returns the parsed report; panics with stderr
/// on failure.
pub fn mesh_surface_cli(surface: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["mesh", "--surface", path_str(surface), "--output", path_str(out), "--quiet"];
    args.extend_from_slice(extra);
    let o = vesselhex(&args);
    assert!(o.status.success(), "{}: vesselhex failed: {}", surface.display(), String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(out.join("report.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// The committed fixtures.
pub fn fixtures_dir() -> PathBuf {
    crate_dir().join("fixtures")
}

/// A scratch directory removed on drop (not created: the writers under test create it).
pub struct ScratchDir(pub PathBuf);

impl ScratchDir {
    pub fn new(tag: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("vesselhex-scratch-{}-{tag}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        ScratchDir(dir)
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Every freshly generated fixture file equals the committed file of the same name, byte for byte.
pub fn assert_same_as_committed(written: &[PathBuf]) {
    for path in written {
        let committed = fixtures_dir().join(path.file_name().unwrap());
        let fresh = std::fs::read(path).unwrap();
        let old = std::fs::read(&committed).unwrap_or_else(|e| panic!("{}: {e}", committed.display()));
        assert!(fresh == old, "{} differs from a fresh generation", committed.display());
    }
}

/// Every writer, as `--formats` names them.
pub const EVERY_FORMAT: &str = "vtu,calculix,abaqus,febio,febio-fsi,openfoam,openfoam-fsi,fsi";

/// Runs `vesselhex mesh --surface SURFACE` (centerlines computed by vesselhex) with `extra`
/// arguments through every writer into `out`, checks that each writer's main file is there, and
/// returns the parsed report; panics with stderr on failure.
pub fn mesh_surface_through_every_writer(surface: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["--formats", EVERY_FORMAT];
    args.extend_from_slice(extra);
    let report = mesh_surface_cli(surface, out, &args);
    for f in [
        "mesh.vtu",
        "calculix/model.inp",
        "abaqus/model.inp",
        "febio/wall.feb",
        "febio/fsi.feb",
        "openfoam/constant/polyMesh/faces",
        "fsi/interface_nodes.csv",
    ] {
        assert!(out.join(f).is_file(), "{}: {f} missing", surface.display());
    }
    report
}

/// A number of a report, by JSON pointer; panics naming the pointer when it is missing.
pub fn report_number(report: &serde_json::Value, pointer: &str) -> f64 {
    report.pointer(pointer).and_then(|v| v.as_f64()).unwrap_or_else(|| panic!("report has no {pointer}"))
}

/// A Python interpreter with `module` importable, or None outside CI (skipped); under CI a
/// missing module is a failure.
pub fn python_with(module: &str) -> Option<String> {
    for py in ["python3", "python"] {
        let ok = Command::new(py)
            .args(["-c", &format!("import {module}")])
            .output()
            .map(|o| o.status.success())
            .unwrap_or(false);
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

/// A centerline for a nearly straight vessel without one (vmtk_abdominal_aorta_segment): the
/// principal axis of the vertices, sliced every `step` mm; each slice's vertex centroid is a
/// centerline point and its distance to the surface the inscribed radius.
pub fn derive_straight_centerline(surface: &TriangleSurface, step: f64) -> Centerlines {
    let n = surface.vertices.len() as f64;
    let mean = surface.vertices.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let cov = surface.vertices.iter().fold(Matrix3::zeros(), |a, p| {
        let d = p.coords - mean;
        a + d * d.transpose()
    }) / n;
    let eig = cov.symmetric_eigen();
    let k = eig.eigenvalues.imax();
    let axis: Vector3<f64> = eig.eigenvectors.column(k).into();
    let t: Vec<f64> = surface.vertices.iter().map(|p| (p.coords - mean).dot(&axis)).collect();
    let (lo, hi) = t.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    let bins = ((hi - lo) / step).ceil() as usize;
    let mut sums = vec![(Vector3::zeros(), 0usize); bins];
    for (p, &x) in surface.vertices.iter().zip(&t) {
        let b = (((x - lo) / step) as usize).min(bins - 1);
        sums[b].0 += p.coords;
        sums[b].1 += 1;
    }
    let index = LumenSurface::new(surface).unwrap();
    let mut points = vec![];
    let mut radii = vec![];
    for (sum, count) in sums {
        if count >= 20 {
            let c = Point3::from(sum / count as f64);
            radii.push(index.closest(&c).distance);
            points.push(c);
        }
    }
    Centerlines {
        polylines: vec![CenterlinePolyline { points, radii: Some(radii), normals: None, cell_tags: IndexMap::new() }],
        source: "derived centerline".into(),
    }
}

/// Meshes a surface file with a centerline file (both mm).
pub fn mesh_files(surface: &Path, centerlines: &Path, config: &MeshConfig) -> VesselMesh {
    mesh_files_in(surface, centerlines, LengthUnit::Mm, config)
}

/// A surface and its centerlines in `unit`, meshed with `config`.
pub fn mesh_files_in(surface: &Path, centerlines: &Path, unit: LengthUnit, config: &MeshConfig) -> VesselMesh {
    let s = read_surface(surface, unit).unwrap();
    let c = read_centerlines(centerlines, unit).unwrap();
    vesselhex::pipeline::mesh_vessel(&s, &c, config, &mut Progress::new(true, 9))
        .unwrap_or_else(|e| panic!("{}: {e}", surface.display()))
        .mesh
}

/// The real bifurcations that mesh with their own centerlines (folder, surface, centerlines,
/// unit of both files), as issue 7 names them; gmsh_aortic_arch does not mesh yet.
pub const REAL_BIFURCATIONS: [(&str, &str, &str, LengthUnit); 3] = [
    ("vmtk_aortoiliac", "aorta-surface-open-ends.stl", "aorta-centerline.vtp", LengthUnit::Mm),
    ("simvascular_demo_aortoiliac", "demo.vtp", "demo-centerlines.vtp", LengthUnit::Cm),
    ("gmsh_carotid_bifurcation", "carotid.stl", "centerlinesCAROTID.vtk", LengthUnit::M),
];

/// gmsh_aortic_arch: (case, surface, centerlines, unit), as in [`REAL_BIFURCATIONS`] (its two
/// junctions overlap and are merged, see tests/branching.rs).
pub const GMSH_AORTIC_ARCH: (&str, &str, &str, LengthUnit) =
    ("gmsh_aortic_arch", "aorta.stl", "centerlinesAORTA.vtk", LengthUnit::M);

/// The real unbranched vessels meshed with `config`: aneurisk_C0092 with its centerline and
/// vmtk_abdominal_aorta_segment with a derived one.
pub fn real_unbranched_meshes(vessels: &Path, config: &MeshConfig) -> Vec<(&'static str, VesselMesh)> {
    let d = vessels.join("aneurisk_C0092_ica_segment");
    let c0092 =
        mesh_files(&d.join("C0092_clip1_0.vtp"), &d.join("C0092_clip1_mesh1_0.95_ratio_centerline.vtp"), config);
    let aorta = read_surface(&vessels.join("vmtk_abdominal_aorta_segment/aorta-surface-segment-2.stl"), LengthUnit::Mm)
        .unwrap();
    let cl = derive_straight_centerline(&aorta, 2.0);
    let aorta = vesselhex::pipeline::mesh_vessel(&aorta, &cl, config, &mut Progress::new(true, 9)).unwrap().mesh;
    vec![("aneurisk_C0092_ica_segment", c0092), ("vmtk_abdominal_aorta_segment", aorta)]
}
