//! Flow extensions (De Santis et al. 2011, §2.1 and §2.3): every open end of every fixture and of
//! the real bifurcations extended; the extensions in their own region (VTU `region`, OpenFOAM
//! cellZone `extension`, the FSI fluid), the CFD patches at the extended ends, circular, checkMesh
//! `Mesh OK.`; the FE decks the same bytes as without extensions; and a short simpleFoam run on
//! the Y-bifurcation whose outlet profiles are developed (measured against Poiseuille).
//!
//! Without OpenFOAM the OpenFOAM parts print "skipped"; with `CI=true` they fail instead.

mod common;

use common::{check_mesh, files_under, fixture, mesh_cli, openfoam_available, path_str, temp_dir};
use nalgebra::{Point3, Vector3};
use std::path::Path;
use std::process::Command;
use vesselhex::config::{ExtendedEnds, MeshConfig};
use vesselhex::extensions::{fluid_view, ExtensionReport};
use vesselhex::input::{read_centerlines, read_surface};
use vesselhex::mesh::{quad_area_vector, sets, ElementFace, Region, VesselMesh};
use vesselhex::quality::Bars;
use vesselhex::units::LengthUnit;
use vesselhex::writers::openfoam::read_polymesh;
use vesselhex::writers::WriteOptions;

/// Every end extended, the lengths and shape at their defaults.
fn all_ends() -> MeshConfig {
    let mut config = MeshConfig::default();
    config.extensions.ends = ExtendedEnds::Keyword("all".into());
    config
}

/// A surface and centerline file meshed and extended.
fn extended(surface: &Path, centerlines: &Path, unit: LengthUnit) -> (VesselMesh, Vec<ExtensionReport>) {
    let s = read_surface(surface, unit).unwrap();
    let c = read_centerlines(centerlines, unit).unwrap();
    let (meshed, additions) = vesselhex::pipeline::mesh_finished(&s, &c, &all_ends(), u64::MAX)
        .unwrap_or_else(|e| panic!("{}: {e}", surface.display()));
    (meshed.mesh, additions.extensions.expect("extensions reported"))
}

/// The bundled fixtures and the real bifurcations (when the vessels folder is there).
fn cases() -> Vec<(String, std::path::PathBuf, std::path::PathBuf, LengthUnit)> {
    let mut cases: Vec<_> = ["straight", "curved", "helical", "tapered", "aaa"]
        .into_iter()
        .map(|n| {
            let (s, c) = fixture(n);
            (n.to_string(), s, c, LengthUnit::Mm)
        })
        .collect();
    let dir = common::fixtures_dir();
    for n in ["y_bifurcation", "t_junction"] {
        let (s, c) = (dir.join(format!("{n}.stl")), dir.join(format!("{n}_centerlines.vtp")));
        cases.push((n.to_string(), s, c, LengthUnit::Mm));
    }
    if let Some(v) = common::vessels_dir() {
        for (case, surface, centerlines, unit) in common::REAL_BIFURCATIONS {
            cases.push((case.to_string(), v.join(case).join(surface), v.join(case).join(centerlines), unit));
        }
    }
    cases
}

/// The extension region: after the vessel, no inverted element, within the bars, as reported.
fn assert_region(name: &str, mesh: &VesselMesh, reports: &[ExtensionReport]) {
    let ext = mesh.extension_range();
    assert_eq!(ext.end, mesh.hexes.len(), "{name}: the extensions come last");
    assert_eq!(ext.len(), reports.iter().map(|r| r.elements).sum::<usize>(), "{name}");
    assert_eq!(reports.len(), mesh.ends.len(), "{name}: every end extended");
    let worst = mesh.quality[ext.clone()].iter().map(|q| q.scaled_jacobian).fold(f64::INFINITY, f64::min);
    assert!(worst >= Bars::MIN_SCALED_JACOBIAN, "{name}: worst extension scaled Jacobian {worst}");
    assert!(mesh.regions[ext].iter().all(|r| *r == Region::Extension));
}

/// Each extended end: its section planar at the reported centre, square to the end's normal,
/// at the reported length from the vessel's own end; its rim a circle of the reported radius.
fn assert_ends(name: &str, mesh: &VesselMesh, reports: &[ExtensionReport]) {
    for (end, r) in mesh.ends.iter().zip(reports) {
        assert_eq!(end.name, r.end);
        let n = end.outward_normal.normalize();
        let centre = Point3::from(r.end_centre);
        assert!(((centre - end.centre).dot(&n) - r.length).abs() < 1e-9 * r.radius, "{name} {}", r.end);
        let rim = &mesh.node_sets[sets::EXTENSION_WALL];
        for &node in &mesh.node_sets[&sets::lumen_end(&end.name)] {
            let d = mesh.nodes[node as usize] - centre;
            assert!(d.dot(&n).abs() < 1e-9 * r.radius, "{name} {}: extended end not planar", r.end);
            if rim.binary_search(&node).is_ok() {
                let off = (d - n * d.dot(&n)).norm();
                assert!((off - r.radius).abs() < 1e-9 * r.radius, "{name} {}: rim node {off} from the axis", r.end);
            }
        }
    }
}

#[test]
fn extensions_on_every_fixture_and_real_bifurcation_pass_checkmesh() {
    let foam = openfoam_available("extensions_on_every_fixture_and_real_bifurcation_pass_checkmesh");
    for (name, surface, centerlines, unit) in cases() {
        let (mesh, reports) = extended(&surface, &centerlines, unit);
        assert_region(&name, &mesh, &reports);
        assert_ends(&name, &mesh, &reports);
        let worst = reports.iter().map(|r| r.scaled_jacobian.min).fold(f64::INFINITY, f64::min);
        println!(
            "{name}: {} extension hexes on {} ends, worst scaled Jacobian {worst:.3}",
            mesh.extension_range().len(),
            reports.len()
        );
        if foam {
            check_cases(&name, &mesh);
        }
    }
}

/// The OpenFOAM lumen and FSI cases of an extended mesh: checkMesh `Mesh OK.`, the extension
/// cellZone and patches as the mesh has them.
fn check_cases(name: &str, mesh: &VesselMesh) {
    let dir = temp_dir(&format!("ext-{name}"));
    for format in ["openfoam", "openfoam-fsi"] {
        vesselhex::writers::writer(format).unwrap()(mesh, &WriteOptions::default(), &dir).unwrap();
        check_mesh(&dir.join(format), &[]);
    }
    let poly = read_polymesh(&dir.join("openfoam")).unwrap();
    let zones = std::fs::read_to_string(dir.join("openfoam/constant/polyMesh/cellZones")).unwrap();
    let zone = |z: &str| cell_zone_size(&zones, z);
    assert_eq!(zone("extension"), Some(mesh.extension_range().len()), "{name}");
    assert_eq!(zone("lumen"), Some(mesh.lumen_range().len()), "{name}");
    assert_eq!(poly.n_cells, mesh.lumen_range().len() + mesh.extension_range().len(), "{name}");
    let size = |p: &str| poly.patch(p).map(|p| p.size);
    assert_eq!(size("extension_wall"), Some(mesh.face_sets[sets::EXTENSION_WALL].len()), "{name}");
    for end in &mesh.ends {
        assert_eq!(size(&end.name), Some(mesh.face_sets[&sets::lumen_end(&end.name)].len()), "{name}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The number of cells of zone `name` in an ASCII cellZones file (`name { ... cellLabels
/// List<label> N ( ... ) }`).
fn cell_zone_size(text: &str, name: &str) -> Option<usize> {
    let mut lines = text.lines().skip_while(|l| l.trim() != name);
    lines.find_map(|l| l.trim().strip_prefix("cellLabels List<label> ")).and_then(|n| n.trim().parse().ok())
}

/// The FE decks are the same bytes with extensions as without (they model the vessel alone);
/// the VTU holds the extensions as `region` 4; one thread writes the same files.
#[test]
fn fe_decks_are_unchanged_by_extensions() {
    let dir = common::fixtures_dir();
    let (stl, vtp) = (dir.join("y_bifurcation.stl"), dir.join("y_bifurcation_centerlines.vtp"));
    let out = temp_dir("ext-fe-decks");
    let case = out.join("case.toml");
    std::fs::write(&case, "[extensions]\nends = \"all\"\n").unwrap();
    let formats = ["--formats", "vtu,calculix,abaqus,febio,febio-fsi"];
    mesh_cli(&stl, &vtp, &out.join("plain"), &formats);
    let mut args = vec!["--config", path_str(&case)];
    args.extend(formats);
    let report = mesh_cli(&stl, &vtp, &out.join("extended"), &args);
    assert_eq!(report["extensions"].as_array().map(Vec::len), Some(3));
    // Determinism: one thread writes the same files.
    args.extend(["--threads", "1"]);
    mesh_cli(&stl, &vtp, &out.join("one-thread"), &args);
    for path in files_under(&out.join("extended")).iter().filter(|p| !p.ends_with("report.json")) {
        let rel = path.strip_prefix(out.join("extended")).unwrap();
        let one = std::fs::read(out.join("one-thread").join(rel)).unwrap();
        assert!(std::fs::read(path).unwrap() == one, "{} differs with one thread", rel.display());
    }
    for deck in ["calculix", "abaqus", "febio"] {
        for path in files_under(&out.join("plain").join(deck)) {
            let rel = path.strip_prefix(out.join("plain")).unwrap();
            let with = std::fs::read(out.join("extended").join(rel)).unwrap();
            assert!(std::fs::read(&path).unwrap() == with, "{} differs with extensions", rel.display());
        }
    }
    if let Some(regions) = vtu_regions(&out.join("extended/mesh.vtu")) {
        let extension = regions.iter().filter(|&&r| r == Region::Extension.code() as i64).count() as u64;
        let reported = report["extensions"].as_array().unwrap().iter().map(|e| e["elements"].as_u64().unwrap());
        assert_eq!(extension, reported.sum::<u64>(), "VTU cells of region {}", Region::Extension.code());
        assert_eq!(regions.last(), Some(&(Region::Extension.code() as i64)), "the extensions come last");
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// The `region` cell array of a VTU file as meshio reads it (None without meshio, outside CI).
fn vtu_regions(path: &Path) -> Option<Vec<i64>> {
    let py = common::python_with("meshio")?;
    let script = "import sys, meshio; print(' '.join(map(str, meshio.read(sys.argv[1]).cell_data['region'][0])))";
    let out = Command::new(py).args(["-c", script, path_str(path)]).output().unwrap();
    assert!(out.status.success(), "meshio: {}", String::from_utf8_lossy(&out.stderr));
    Some(String::from_utf8(out.stdout).unwrap().split_whitespace().map(|r| r.parse().unwrap()).collect())
}

/// A short simpleFoam run (laminar, parabolic inflow, converged by the case's residual control
/// in about 150 iterations) on the Y-bifurcation with every end extended. Each outlet's flow
/// leaves the junction skewed; measured at the vessel's own end (the cells at `cut_<end>`) and
/// at the extended end (the last cells of the extension): the axial velocity against the
/// Poiseuille profile of the same flow rate and area, the cross-flow, and, along the last two
/// radii of the extension, how much the axial profile still changes. Developed: at the extended
/// end the axial profile changes by less than 1 % of the mean velocity over two radii, the
/// cross-flow is below 1 % and a tenth of the vessel end's, and the profile is Poiseuille's within
/// 5 % (RMS) and closer to it than at the vessel's end. (The comparison with Poiseuille has a
/// floor of about 2 % at the coarse preset: cell-centre values of a 16-sided O-grid section
/// against the analytic parabola of the circle with the same area.)
#[test]
fn extended_outlets_carry_developed_profiles() {
    if !openfoam_available("extended_outlets_carry_developed_profiles") {
        return;
    }
    let dir = common::fixtures_dir();
    let (stl, vtp) = (dir.join("y_bifurcation.stl"), dir.join("y_bifurcation_centerlines.vtp"));
    let (mesh, reports) = extended(&stl, &vtp, LengthUnit::Mm);
    let out = temp_dir("ext-simplefoam");
    vesselhex::writers::writer("openfoam").unwrap()(&mesh, &WriteOptions::default(), &out).unwrap();
    let case = out.join("openfoam");
    let started = std::time::Instant::now();
    let log = run("sh", &[path_str(&case.join("Allrun"))]);
    let seconds = started.elapsed().as_secs_f64();
    let solver = std::fs::read_to_string(case.join("log.simpleFoam")).unwrap();
    assert!(solver.contains("SIMPLE solution converged"), "simpleFoam did not converge: {log}");
    let fluid = fluid_view(&mesh);
    let u = cell_vectors(&latest_time(&case).join("U"), fluid.hexes.len());
    println!("y_bifurcation extended: {} fluid cells, simpleFoam {seconds:.1} s", fluid.hexes.len());
    let mut first = mesh.lumen_range().len();
    for r in &reports {
        let end = mesh.ends.iter().find(|e| e.name == r.end).unwrap();
        let faces = &fluid.face_sets[&sets::lumen_end(&end.name)];
        let (per_station, this) = (faces.len(), first);
        let last_station = |back: usize| -> Vec<ElementFace> {
            let start = this + (r.stations - 1 - back) * per_station;
            (0..per_station).map(|i| ElementFace { element: (start + i) as u32, face: faces[i].face }).collect()
        };
        first += r.elements;
        if end.is_inlet {
            continue;
        }
        let n = end.outward_normal.normalize();
        let own = Profile::of(&fluid, &u, &fluid.face_sets[&sets::cut(&end.name)], &end.centre, &n);
        let extended = Profile::of(&fluid, &u, &last_station(0), &Point3::from(r.end_centre), &n);
        let back = (2.0 * r.radius / (r.length / r.stations as f64)).round() as usize;
        let upstream = Profile::of(&fluid, &u, &last_station(back), &Point3::from(r.end_centre), &n);
        let change = extended.change_from(&upstream);
        println!(
            "{}: Re {:.0}; vessel end: Poiseuille RMS {:.2} %, cross-flow max {:.2} %; extended end ({:.1} radii): \
             Poiseuille RMS {:.2} %, cross-flow max {:.2} %, change over the last {back} cells ({:.1} radii) {:.3} %",
            end.name,
            extended.reynolds(r.radius),
            100.0 * own.poiseuille_rms,
            100.0 * own.cross_flow,
            r.length_radii,
            100.0 * extended.poiseuille_rms,
            100.0 * extended.cross_flow,
            back as f64 * r.length / r.stations as f64 / r.radius,
            100.0 * change
        );
        assert!(extended.poiseuille_rms < 0.05 && extended.poiseuille_rms < own.poiseuille_rms, "{}", end.name);
        assert!(extended.cross_flow < 0.01 && extended.cross_flow < 0.1 * own.cross_flow, "{}", end.name);
        assert!(change < 0.01, "{}: the profile still changes by {change} over two radii", end.name);
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// The flow through one layer of cells next to a section (the cells of `faces`), relative to
/// its mean velocity.
struct Profile {
    /// Axial velocity of each cell, its distance from the axis and its face's area.
    cells: Vec<(f64, f64, f64)>,
    mean: f64,
    /// RMS (area-weighted) of the axial velocity minus Poiseuille's 2 U (1 - r^2 / R^2), R the
    /// radius of the section's area.
    poiseuille_rms: f64,
    /// Largest velocity across the axis.
    cross_flow: f64,
}

impl Profile {
    fn of(
        mesh: &VesselMesh,
        u: &[Vector3<f64>],
        faces: &[ElementFace],
        centre: &Point3<f64>,
        n: &Vector3<f64>,
    ) -> Profile {
        let mut cells = Vec::new();
        let mut cross: f64 = 0.0;
        for f in faces {
            let corners = mesh.corners(f.element as usize);
            let area = quad_area_vector(vesselhex::mesh::HEX_FACES[f.face as usize].map(|i| corners[i])).norm();
            let d = vesselhex::mesh::element_centre(&corners) - centre;
            let v = u[f.element as usize];
            cells.push((v.dot(n), (d - n * d.dot(n)).norm(), area));
            cross = cross.max((v - n * v.dot(n)).norm());
        }
        let total: f64 = cells.iter().map(|c| c.2).sum();
        let mean = cells.iter().map(|c| c.0 * c.2).sum::<f64>() / total;
        let r2 = total / std::f64::consts::PI;
        let sq: f64 = cells.iter().map(|(ua, r, a)| (ua - 2.0 * mean * (1.0 - r * r / r2)).powi(2) * a).sum();
        Profile { poiseuille_rms: (sq / total).sqrt() / mean, cross_flow: cross / mean, mean, cells }
    }

    /// Largest change of the axial velocity, cell by cell, from another layer of the same cells.
    fn change_from(&self, other: &Profile) -> f64 {
        self.cells.iter().zip(&other.cells).map(|(a, b)| (a.0 - b.0).abs()).fold(0.0, f64::max) / self.mean
    }

    /// The Reynolds number 2 R U / nu (U in m/s, R in mm, nu = 3.5e-6 m^2/s as written).
    fn reynolds(&self, radius_mm: f64) -> f64 {
        2.0 * radius_mm * 1e-3 * self.mean / 3.5e-6
    }
}

/// The latest time folder of a case.
fn latest_time(case: &Path) -> std::path::PathBuf {
    let times = std::fs::read_dir(case).unwrap().filter_map(|e| {
        let e = e.ok()?;
        Some((e.file_name().to_str()?.parse::<f64>().ok()?, e.path()))
    });
    times.max_by(|a, b| a.0.total_cmp(&b.0)).unwrap().1
}

/// The internal field of an ASCII volVectorField (`nonuniform List<vector> N ( (x y z) ... )`).
fn cell_vectors(path: &Path, n: usize) -> Vec<Vector3<f64>> {
    let text = std::fs::read_to_string(path).unwrap();
    let lines = text.lines().skip_while(|l| !l.starts_with("internalField")).skip(3).take(n);
    let v: Vec<Vector3<f64>> = lines
        .map(|l| {
            let x: Vec<f64> =
                l.trim_matches(|c| c == '(' || c == ')').split_whitespace().map(|t| t.parse().unwrap()).collect();
            Vector3::new(x[0], x[1], x[2])
        })
        .collect();
    assert_eq!(v.len(), n, "{}: {} cell values, not {n}", path.display(), v.len());
    v
}

// ---------------------------------------------------------------------------------------------
// OpenFOAM

/// Runs an OpenFOAM program (or a case's Allrun with `-case` left out); its output.
fn run(program: &str, args: &[&str]) -> String {
    let wm = std::env::var("WM_PROJECT_DIR").unwrap_or_else(|_| "/usr/share/openfoam".into());
    let out = Command::new(program).args(args).env("WM_PROJECT_DIR", wm).env("OMP_NUM_THREADS", "1").output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{program} {args:?} failed:\n{text}");
    text
}

/// An end the vessel does not have, or a length out of range, is a one-line error naming the key.
#[test]
fn unknown_ends_and_bad_lengths_are_clear_errors() {
    let (stl, csv) = fixture("straight");
    let dir = temp_dir("ext-errors");
    for (case, words) in [
        (
            "[extensions]\nends = [\"outlet_9\"]\n",
            "extensions.ends: the mesh has no end named 'outlet_9'; its ends are inlet, outlet",
        ),
        ("[extensions]\nends = \"all\"\noutlet_length = -1.0\n", "extensions.outlet_length"),
        ("[extensions]\nends = \"some\"\n", "extensions.ends"),
    ] {
        let file = dir.join("case.toml");
        std::fs::write(&file, case).unwrap();
        let out = dir.join("out");
        let args = ["mesh", "--surface", path_str(&stl), "--centerlines", path_str(&csv), "--output", path_str(&out)];
        let o = common::vesselhex(&[&args[..], &["--quiet", "--config", path_str(&file)]].concat());
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && stderr.lines().count() == 1 && stderr.contains(words), "{case}: {stderr}");
        assert!(!out.join("report.json").exists());
    }
    let _ = std::fs::remove_dir_all(&dir);
}
