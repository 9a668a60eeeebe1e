//! Shared helpers of the integration tests.
#![allow(dead_code)]

pub mod topology;

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

/// The settings `vesselhex mesh --preset coarse` meshes with, nothing else asked.
pub fn coarse_settings() -> vesselhex::pipeline::MeshSettings {
    vesselhex::pipeline::MeshSettings {
        config: vesselhex::config::MeshConfig::preset(vesselhex::config::Preset::Coarse),
        centerline_units: None,
        max_memory: vesselhex::io::memory::default_max_memory(),
        warnings: vec![],
        caps: vec![],
        inlets: vec![],
    }
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

// ------------------------------------------------------------------------------------------------
// Solver runs and what they show, shared by tests/calculix.rs and tests/febio_run.rs
// ------------------------------------------------------------------------------------------------

use std::collections::{HashMap, HashSet};
use vesselhex::mesh::sets;
use vesselhex::writers::WriteOptions;

/// Nodal displacements by deck label (vesselhex node index + 1, as every deck numbers nodes).
pub type Displacements = HashMap<u64, [f64; 3]>;

/// Whether `ccx` is installed: without it, "skipped" outside CI and a failure under CI.
pub fn ccx_available() -> bool {
    let found = Command::new("ccx").arg("-v").output().is_ok();
    if !found {
        assert!(!under_ci(), "ccx is not installed but CI=true: install calculix-ccx");
        eprintln!("skipped: ccx is not installed");
    }
    found
}

/// What one ccx run left behind; its scratch directory goes when the run is dropped, unless a
/// check failed.
pub struct CcxRun {
    pub dir: PathBuf,
    pub log: String,
}

impl Drop for CcxRun {
    fn drop(&mut self) {
        if std::thread::panicking() {
            eprintln!("kept for a look: {}", self.dir.display());
        } else if let Some(scratch) = self.dir.parent() {
            let _ = std::fs::remove_dir_all(scratch);
        }
    }
}

/// Writes the CalculiX deck of `mesh` and runs ccx on it; requires `Job finished`, exit 0, no
/// warning, and both steps (toe, then on to the full pressure) run to their end.
pub fn solve_calculix(mesh: &VesselMesh, options: &WriteOptions, name: &str) -> CcxRun {
    let dir = temp_dir(&format!("ccx-{name}"));
    let files = vesselhex::writers::calculix::write_calculix(mesh, options, &dir).unwrap();
    assert_eq!(files, vec![PathBuf::from("calculix/model.inp")]);
    let job = dir.join("calculix");
    let started = std::time::Instant::now();
    let out = Command::new("ccx").args(["-i", "model"]).current_dir(&job).env("OMP_NUM_THREADS", "1").output().unwrap();
    let log = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    let sta = std::fs::read_to_string(job.join("model.sta")).unwrap_or_default();
    eprintln!(
        "{name}: ccx exit {:?} in {:.1} s; {} wall elements\n{}\n{}",
        out.status.code(),
        started.elapsed().as_secs_f64(),
        mesh.wall_range().len(),
        log.lines()
            .filter(|l| l.contains("Job finished") || l.contains("Total CalculiX Time") || l.contains("increment"))
            .collect::<Vec<_>>()
            .join("\n"),
        sta
    );
    assert!(out.status.success(), "{name}: ccx failed:\n{log}");
    assert!(log.contains("Job finished"), "{name}: no 'Job finished':\n{log}");
    let warnings: Vec<&str> = log.lines().filter(|l| l.contains("*WARNING") || l.contains("*ERROR")).collect();
    assert!(warnings.is_empty(), "{name}: ccx warned:\n{}", warnings.join("\n"));
    // The last converged increment is step 2's, at step time 1.
    let last: Vec<f64> = sta
        .lines()
        .filter_map(|l| l.split_whitespace().map(|f| f.parse::<f64>()).collect::<Result<Vec<f64>, _>>().ok())
        .rfind(|f| f.len() == 7)
        .unwrap_or_else(|| panic!("{name}: no converged increment in the .sta:\n{sta}"));
    assert!(
        last[0] == 2.0 && (last[5] - 1.0).abs() < 1e-9,
        "{name}: the step did not end at the full pressure:\n{sta}"
    );
    CcxRun { dir: job, log }
}

/// Displacements of the last increment in ccx's ASCII .frd.
pub fn frd_displacements(dir: &Path) -> Displacements {
    let text = std::fs::read_to_string(dir.join("model.frd")).unwrap();
    let mut last = HashMap::new();
    let mut current: Option<Displacements> = None;
    for line in text.lines() {
        if line.starts_with(" -4") {
            current = line.contains("DISP").then(HashMap::new);
        } else if line.starts_with(" -3") {
            if let Some(c) = current.take() {
                last = c;
            }
        } else if let (Some(c), true) = (current.as_mut(), line.starts_with(" -1")) {
            let node: u64 = line[3..13].trim().parse().unwrap();
            let v: Vec<f64> = (0..3).map(|k| line[13 + 12 * k..25 + 12 * k].trim().parse().unwrap()).collect();
            c.insert(node, [v[0], v[1], v[2]]);
        }
    }
    assert!(!last.is_empty(), "no DISP block in the .frd");
    last
}

/// A straight tube along z from z = 0 to 30 mm: the mean radial displacement and mean radius of
/// the interface nodes away from the ends (5 < z < 25), and the least radial displacement of any.
pub fn inner_radial(mesh: &VesselMesh, disp: &Displacements) -> (f64, f64, f64) {
    let interface = &mesh.node_sets[sets::INTERFACE_NODES];
    let (mut sum_u, mut sum_r, mut min_u, mut n) = (0.0, 0.0, f64::INFINITY, 0.0);
    for &i in interface {
        let p = mesh.nodes[i as usize];
        let r = p.x.hypot(p.y);
        let u = disp[&(i as u64 + 1)];
        let ur = (u[0] * p.x + u[1] * p.y) / r;
        min_u = min_u.min(ur);
        if p.z > 5.0 && p.z < 25.0 {
            sum_u += ur;
            sum_r += r;
            n += 1.0;
        }
    }
    (sum_u / n, sum_r / n, min_u)
}

/// Every lumen-surface node off the end rings with its displacement along the lumen surface's
/// outward normal there (from the lumen elements' outer faces), in node order.
pub fn lumen_normal_motion(mesh: &VesselMesh, disp: &Displacements) -> Vec<(u32, f64)> {
    let mut normal: HashMap<u32, Vector3<f64>> = Default::default();
    for f in &mesh.face_sets[sets::LUMEN_WALL_FACES] {
        let q = vesselhex::mesh::face_nodes(&mesh.hexes[f.element as usize], f.face as usize);
        let a = vesselhex::mesh::quad_area_vector(q.map(|n| mesh.nodes[n as usize]));
        for n in q {
            *normal.entry(n).or_insert_with(Vector3::zeros) += a;
        }
    }
    let ends: HashSet<u32> =
        mesh.ends.iter().flat_map(|e| mesh.node_sets[&sets::wall_end(&e.name)].iter().copied()).collect();
    mesh.node_sets[sets::INTERFACE_NODES]
        .iter()
        .filter(|i| !ends.contains(i))
        .map(|&i| (i, Vector3::from(disp[&(i as u64 + 1)]).dot(&normal[&i].normalize())))
        .collect()
}

/// A branched vessel opens without ballooning: in every branch the lumen surface's mean motion
/// along its outward normal is positive, and every lumen-surface face stretches in area by more
/// than 0.9 and less than 1.5 (the default wall stretches a straight tube's by 1.06).
pub fn assert_lumen_opens(case: &str, mesh: &VesselMesh, disp: &Displacements) {
    let motion = lumen_normal_motion(mesh, disp);
    // The branch of each lumen-surface node: that of an intima element on it.
    let mut branch_of_node = HashMap::new();
    for e in mesh.region_range(vesselhex::mesh::Region::Intima) {
        for n in mesh.hexes[e] {
            branch_of_node.entry(n).or_insert(mesh.branch_of[e] as usize);
        }
    }
    let mut per_branch = vec![(0.0, 0usize); mesh.branch_names.len()];
    for &(i, un) in &motion {
        let b = &mut per_branch[branch_of_node[&i]];
        b.0 += un;
        b.1 += 1;
    }
    let inward = motion.iter().filter(|m| m.1 <= 0.0).count();
    // Area stretch of every lumen-surface face (the intima's inner faces).
    let moved = |n: u32| mesh.nodes[n as usize] + Vector3::from(disp[&(n as u64 + 1)]);
    let mut stretch: Vec<f64> = mesh.face_sets[sets::WALL_LUMEN_FACES]
        .iter()
        .map(|f| {
            let q = vesselhex::mesh::face_nodes(&mesh.hexes[f.element as usize], f.face as usize);
            let before = vesselhex::mesh::quad_area_vector(q.map(|n| mesh.nodes[n as usize])).norm();
            vesselhex::mesh::quad_area_vector(q.map(moved)).norm() / before
        })
        .collect();
    stretch.sort_by(f64::total_cmp);
    let (least, median, most) = (stretch[0], stretch[stretch.len() / 2], stretch[stretch.len() - 1]);
    eprintln!(
        "{case}: {} lumen nodes, {inward} move inwards; mean u.n per branch {:?} mm; lumen face area \
         stretch {least:.3} / {median:.3} / {most:.3} (least / median / most)",
        motion.len(),
        per_branch.iter().map(|b| format!("{:.3e}", b.0 / b.1 as f64)).collect::<Vec<_>>(),
    );
    for (b, (sum, count)) in per_branch.iter().enumerate() {
        assert!(*count > 0 && *sum > 0.0, "{case}: branch {} does not open", mesh.branch_names[b]);
    }
    assert!(median > 1.0, "{case}: the lumen surface does not stretch");
    assert!(least > 0.9 && most < 1.5, "{case}: lumen face area stretch from {least:.3} to {most:.3}");
}

/// A case of `../shared/vessels/manifest.json`.
pub struct Case {
    pub name: String,
    /// The file name of its surface in its folder.
    pub surface: String,
    pub unit: LengthUnit,
    /// Its true number of vessel ends.
    pub ends: usize,
}

/// Every case of the manifest, in its order.
pub fn manifest(vessels: &Path) -> Vec<Case> {
    let text = std::fs::read_to_string(vessels.join("manifest.json")).expect("manifest.json");
    let json: serde_json::Value = serde_json::from_str(&text).expect("manifest.json is JSON");
    json["cases"]
        .as_array()
        .expect("manifest cases")
        .iter()
        .map(|c| {
            let unit = c["unit"].as_str().unwrap();
            // "unitless (treat as m)": the manifest's own advice.
            let unit = if unit.starts_with("unitless") { "m" } else { unit };
            Case {
                name: c["name"].as_str().unwrap().to_string(),
                surface: c["primary_surface"].as_str().unwrap().to_string(),
                unit: unit.parse().unwrap_or_else(|e| panic!("{}: unit {unit}: {e}", c["name"])),
                ends: c["ends"].as_u64().unwrap() as usize,
            }
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// OpenFOAM

pub const FOAM_DIR: &str = "/usr/share/openfoam";

/// True when OpenFOAM's binaries are on the PATH; panics when they are not and CI=true.
pub fn openfoam_available(test: &str) -> bool {
    let found = Command::new("sh").args(["-c", "command -v checkMesh"]).output().is_ok_and(|o| o.status.success());
    if !found {
        if under_ci() {
            panic!("{test}: OpenFOAM (checkMesh) is not installed but CI=true: apt-get install -y --no-install-recommends openfoam");
        }
        eprintln!("{test}: skipped (OpenFOAM's checkMesh not found)");
    }
    found
}

/// Runs an OpenFOAM program; returns its output (stdout + stderr) and panics when it fails.
pub fn foam(program: &str, args: &[&str], case: &Path) -> String {
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

pub fn copy_dir(from: &Path, to: &Path) {
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
pub fn check_mesh(case: &Path, extra: &[&str]) -> Vec<String> {
    let copy = case.with_file_name(format!("{}-checkMesh", case.file_name().unwrap().to_str().unwrap()));
    let _ = std::fs::remove_dir_all(&copy);
    copy_dir(case, &copy);
    let mut args = vec!["-noFunctionObjects"];
    args.extend_from_slice(extra);
    let log = foam("checkMesh", &args, &copy);
    let _ = std::fs::remove_dir_all(&copy);
    let failed: Vec<&str> = log.lines().filter(|l| l.trim_start().starts_with("***")).collect();
    assert!(failed.is_empty(), "checkMesh on {}: {failed:?}\n{log}", case.display());
    assert!(
        log.lines().any(|l| l.trim() == "Mesh OK."),
        "checkMesh on {} did not say Mesh OK.:\n{log}",
        case.display()
    );
    let mut summary = Vec::new();
    let mut section = "";
    for line in log.lines() {
        let t = line.trim();
        if t.starts_with("Mesh stats") || t.starts_with("Checking patch topology") || t.starts_with("Checking geometry")
        {
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

/// Every face of every hex is shared by exactly two hexes, except the boundary faces, which
/// are exactly the outer wall and the end faces; lumen and wall meet face to face.
pub fn assert_conformal(name: &str, mesh: &VesselMesh) {
    let mut count: std::collections::HashMap<[u32; 4], usize> = std::collections::HashMap::new();
    for h in &mesh.hexes {
        for f in 0..6 {
            let mut q = vesselhex::mesh::face_nodes(h, f);
            q.sort_unstable();
            *count.entry(q).or_default() += 1;
        }
    }
    assert!(count.values().all(|&c| c <= 2), "{name}: a face is shared by more than two hexes");
    let boundary = count.values().filter(|&&c| c == 1).count();
    let mut expected = mesh.face_sets[vesselhex::mesh::sets::WALL_OUTER_FACES].len();
    for end in &mesh.ends {
        expected += mesh.face_sets[&vesselhex::mesh::sets::lumen_end(&end.name)].len()
            + mesh.face_sets[&vesselhex::mesh::sets::wall_end(&end.name)].len();
    }
    assert_eq!(boundary, expected, "{name}: boundary faces are not exactly the outer wall and the ends");
    let key = |f: &vesselhex::mesh::ElementFace| {
        let mut q = vesselhex::mesh::face_nodes(&mesh.hexes[f.element as usize], f.face as usize);
        q.sort_unstable();
        q
    };
    let mut lumen: Vec<[u32; 4]> = mesh.face_sets[vesselhex::mesh::sets::LUMEN_WALL_FACES].iter().map(key).collect();
    let mut wall: Vec<[u32; 4]> = mesh.face_sets[vesselhex::mesh::sets::WALL_LUMEN_FACES].iter().map(key).collect();
    lumen.sort_unstable();
    wall.sort_unstable();
    assert_eq!(lumen, wall, "{name}: the lumen and wall do not meet face to face");
    // No duplicate nodes: conformity is by shared nodes, never by coincident ones.
    let mut coords: Vec<[i64; 3]> =
        mesh.nodes.iter().map(|p| [(p.x * 1e7) as i64, (p.y * 1e7) as i64, (p.z * 1e7) as i64]).collect();
    coords.sort_unstable();
    let before = coords.len();
    coords.dedup();
    assert_eq!(coords.len(), before, "{name}: coincident nodes");
}

/// `cli` holds exactly the files `names`, each byte-identical to its namesake in `lib` (a
/// generator's command line against its library).
pub fn assert_same_files(cli: &Path, lib: &Path, names: &[&str]) {
    let mut listed: Vec<String> =
        std::fs::read_dir(cli).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    listed.sort();
    let mut expected: Vec<String> = names.iter().map(|n| n.to_string()).collect();
    expected.sort();
    assert_eq!(listed, expected);
    for name in names {
        assert!(std::fs::read(cli.join(name)).unwrap() == std::fs::read(lib.join(name)).unwrap(), "{name} differs");
    }
}

/// A generated tree written into a folder of its own and meshed from its bare surface as
/// `vesselhex mesh --preset coarse` meshes it: the folder, the tree's truth, its surface and
/// the meshed vessel.
pub struct MeshedTree {
    pub seed: u64,
    pub dir: PathBuf,
    pub truth: serde_json::Value,
    pub surface: TriangleSurface,
    pub vessel: vesselhex::pipeline::MeshedVessel,
}

/// Writes random tree `seed` into a temporary folder named after `tag` and meshes it from its
/// bare surface at coarse; a refusal fails the test, naming the tree.
pub fn mesh_random_tree(seed: u64, tag: &str) -> MeshedTree {
    use vesselhex::synthetic_tree::{write_random_tree, SurfaceFormat};
    let dir = temp_dir(&format!("{tag}-{seed}"));
    let written = write_random_tree(seed, &dir, SurfaceFormat::Stl, &mut Progress::new(true, 0)).unwrap();
    let truth = serde_json::to_value(written.tree.manifest("", "")).unwrap();
    let surface = read_surface(&written.surface, LengthUnit::Mm).unwrap();
    let vessel = vesselhex::pipeline::mesh_surface(
        surface.clone(),
        vesselhex::pipeline::CenterlineSource::Extract(vesselhex::centerline_extract::ExtractOptions::default()),
        coarse_settings(),
        &mut Progress::new(true, 0),
    )
    .unwrap_or_else(|e| panic!("tree {seed}: {e}"));
    MeshedTree { seed, dir, truth, surface, vessel }
}

impl MeshedTree {
    /// Asserts the mesh has every true end and no element below the minimum scaled Jacobian bar
    /// (0.2); gives that minimum.
    pub fn assert_every_end_and_min_sj(&self) -> f64 {
        let (seed, mesh) = (self.seed, &self.vessel.meshed.mesh);
        assert_eq!(mesh.ends.len(), self.truth["ends"].as_array().unwrap().len(), "tree {seed}: ends");
        let min_sj = mesh.quality.iter().map(|q| q.scaled_jacobian).fold(f64::INFINITY, f64::min);
        assert!(min_sj >= 0.2, "tree {seed}: min scaled Jacobian {min_sj}");
        min_sj
    }
}
