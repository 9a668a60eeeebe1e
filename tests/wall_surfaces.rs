//! Walls from segmented surfaces (De Santis et al. 2011, §2.5): a straight lumen of radius 2 mm
//! inside an outer wall surface whose radius varies round and along the vessel (the wall 0.25 to
//! 0.65 mm thick) and two layer surfaces between, all known exactly (their triangles are the
//! surfaces, written as legacy VTK in full precision). Every wall node lands on its surface, the
//! lumen and the layers' topology stay as they were, ccx solves the deck, and a surface in the
//! wrong order or one that a ray misses is a clear one-line error naming the file and the place.

mod common;

use common::{path_str, temp_dir, vesselhex};
use std::f64::consts::TAU;
use std::path::{Path, PathBuf};
use vesselhex::config::MeshConfig;
use vesselhex::input::read_surface;
use vesselhex::mesh::{sets, VesselMesh};
use vesselhex::quality::Bars;
use vesselhex::surface::LumenSurface;
use vesselhex::testing::{straight_tube_centerline, straight_tube_surface};
use vesselhex::units::LengthUnit;
use vesselhex::writers::WriteOptions;

const RADIUS: f64 = 2.0;
const LENGTH: f64 = 15.0;

/// Wall thickness at angle `a` and height `z`: 0.25 to 0.65 mm.
fn thickness(a: f64, z: f64) -> f64 {
    0.45 + 0.12 * a.cos() + 0.08 * (TAU * z / LENGTH).sin()
}

/// The surface at `fraction` of the wall from the lumen (1: the outer wall), a tube of 64 x 60
/// quads (each two triangles) from 2 mm below the lumen's start to 2 mm beyond its end, its
/// triangles facing out; written to `path` as legacy VTK with every digit of each coordinate.
fn write_wall_surface(path: &Path, fraction: f64, z: (f64, f64)) {
    let (around, rings) = (64, 60);
    let mut text = format!(
        "# vtk DataFile Version 3.0\nwall surface at {fraction}\nASCII\nDATASET POLYDATA\nPOINTS {} double\n",
        around * (rings + 1)
    );
    for j in 0..=rings {
        let zj = z.0 + (z.1 - z.0) * j as f64 / rings as f64;
        for i in 0..around {
            let a = TAU * i as f64 / around as f64;
            let r = RADIUS + fraction * thickness(a, zj);
            text += &format!("{:e} {:e} {:e}\n", r * a.cos(), r * a.sin(), zj);
        }
    }
    text += &format!("POLYGONS {} {}\n", 2 * around * rings, 8 * around * rings);
    for j in 0..rings {
        for i in 0..around {
            let (a, b) = (j * around + i, j * around + (i + 1) % around);
            text += &format!("3 {a} {b} {}\n3 {a} {} {}\n", b + around, b + around, a + around);
        }
    }
    std::fs::write(path, text).unwrap();
}

/// The outer wall and the two layer surfaces (intima|media at 0.2, media|adventitia at 0.7 of the
/// wall, other fractions than the thickness rule's 0.27 and 0.63, so the layers move).
fn write_surfaces(dir: &Path, z: (f64, f64)) -> (PathBuf, [PathBuf; 2]) {
    let path = |name: &str| dir.join(format!("{name}.vtk"));
    write_wall_surface(&path("outer"), 1.0, z);
    write_wall_surface(&path("intima_media"), 0.2, z);
    write_wall_surface(&path("media_adventitia"), 0.7, z);
    (path("outer"), [path("intima_media"), path("media_adventitia")])
}

/// The tube meshed with `config` (and its added stages), and without them.
fn meshed(config: &MeshConfig) -> (VesselMesh, VesselMesh) {
    let surface = straight_tube_surface(RADIUS, LENGTH, 96, 60);
    let centerline = straight_tube_centerline(RADIUS, LENGTH);
    let with = vesselhex::pipeline::mesh_finished(&surface, &centerline, config, u64::MAX).unwrap().0.mesh;
    let plain = vesselhex::pipeline::mesh_finished(&surface, &centerline, &MeshConfig::default(), u64::MAX);
    (with, plain.unwrap().0.mesh)
}

/// The wall nodes at radial level `level` (0: on the lumen, the layers' elements counted out).
fn wall_level(mesh: &VesselMesh, level: usize) -> Vec<u32> {
    let mut outward = vec![u32::MAX; mesh.nodes.len()];
    for (h, r) in mesh.hexes.iter().zip(&mesh.regions) {
        if r.is_wall() {
            for (inner, outer) in [(0, 1), (3, 2), (4, 5), (7, 6)] {
                outward[h[inner] as usize] = h[outer];
            }
        }
    }
    let step = |n: &u32| (0..level).fold(*n, |n, _| outward[n as usize]);
    mesh.node_sets[sets::INTERFACE_NODES].iter().map(step).collect()
}

/// Largest distance from `nodes` to a surface file, relative to the lumen radius.
fn worst_distance(mesh: &VesselMesh, nodes: &[u32], path: &Path) -> f64 {
    let surface = LumenSurface::new(&read_surface(path, LengthUnit::Mm).unwrap()).unwrap();
    nodes.iter().map(|&n| surface.closest(&mesh.nodes[n as usize]).distance / RADIUS).fold(0.0, f64::max)
}

#[test]
fn every_wall_node_lands_on_its_segmented_surface_and_ccx_solves() {
    let dir = temp_dir("wall-surfaces");
    let (outer, layers) = write_surfaces(&dir, (-2.0, LENGTH + 2.0));
    let mut config = MeshConfig::default();
    config.wall.surface = Some(outer.clone());
    config.wall.surfaces = layers.to_vec();
    let (mesh, plain) = meshed(&config);
    // Lumen and topology as without the surfaces: same elements, lumen nodes unmoved.
    assert_eq!(mesh.hexes, plain.hexes);
    for n in plain.nodes_of(plain.lumen_range()) {
        assert_eq!(mesh.nodes[n as usize], plain.nodes[n as usize], "lumen node {n} moved");
    }
    let cells: Vec<usize> = mesh.layers.iter().map(|l| l.radial_elements).collect();
    let levels = [cells[0], cells[0] + cells[1], cells.iter().sum()];
    for (level, path) in levels.iter().zip([&layers[0], &layers[1], &outer]) {
        let worst = worst_distance(&mesh, &wall_level(&mesh, *level), path);
        println!(
            "{}: {} wall nodes, worst distance {worst:.2e} R",
            path.display(),
            mesh.node_sets[sets::INTERFACE_NODES].len()
        );
        assert!(worst < 1e-9, "{}: a wall node {worst:e} R off its surface", path.display());
    }
    let thick = thicknesses(&mesh, levels[2]);
    println!("wall thickness {:.3} to {:.3} mm (segmented: 0.25 to 0.65)", thick.0, thick.1);
    assert!(thick.0 > 0.25 - 0.01 && thick.0 < 0.25 + 0.03 && thick.1 > 0.65 - 0.03 && thick.1 < 0.65 + 0.01);
    let worst = mesh.quality.iter().map(|q| q.scaled_jacobian).fold(f64::INFINITY, f64::min);
    assert!(worst >= Bars::MIN_SCALED_JACOBIAN, "worst scaled Jacobian {worst}");
    if common::ccx_available() {
        common::solve_calculix(&mesh, &WriteOptions::from_config(&config), "segmented-wall");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Least and largest wall thickness along the columns (interface node to outer node).
fn thicknesses(mesh: &VesselMesh, outer_level: usize) -> (f64, f64) {
    let inner = &mesh.node_sets[sets::INTERFACE_NODES];
    let d: Vec<f64> = inner
        .iter()
        .zip(wall_level(mesh, outer_level))
        .map(|(&a, b)| (mesh.nodes[b as usize] - mesh.nodes[a as usize]).norm())
        .collect();
    (d.iter().cloned().fold(f64::INFINITY, f64::min), d.iter().cloned().fold(0.0, f64::max))
}

/// `vesselhex mesh` on the tube (written as STL) with `args`; its exit status and stderr.
fn mesh_tube(dir: &Path, args: &[&str]) -> (bool, String) {
    let stl = dir.join("tube.stl");
    write_tube_stl(&stl);
    let out = dir.join("out");
    let mut all = vec!["mesh", "--surface", path_str(&stl), "--output", path_str(&out), "--quiet", "--formats", "vtu"];
    all.extend_from_slice(args);
    let o = vesselhex(&all);
    (o.status.success(), String::from_utf8_lossy(&o.stderr).into_owned())
}

/// The lumen tube as an ASCII STL (radius 2 mm, 15 mm long, 96 around).
fn write_tube_stl(path: &Path) {
    let s = straight_tube_surface(RADIUS, LENGTH, 96, 60);
    let mut text = String::from("solid tube\n");
    for t in &s.triangles {
        let [a, b, c] = t.map(|i| s.vertices[i as usize]);
        let n = (b - a).cross(&(c - a)).normalize();
        text += &format!("facet normal {} {} {}\nouter loop\n", n.x, n.y, n.z);
        for p in [a, b, c] {
            text += &format!("vertex {:e} {:e} {:e}\n", p.x, p.y, p.z);
        }
        text += "endloop\nendfacet\n";
    }
    std::fs::write(path, text + "endsolid tube\n").unwrap();
}

#[test]
fn wall_surface_flag_reports_the_segmented_thickness() {
    let dir = temp_dir("wall-surface-flag");
    let (outer, _) = write_surfaces(&dir, (-2.0, LENGTH + 2.0));
    let (ok, stderr) = mesh_tube(&dir, &["--wall-surface", path_str(&outer)]);
    assert!(ok, "{stderr}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/report.json")).unwrap()).unwrap();
    let t = &r["wall_surfaces"]["thickness"];
    println!("report.json wall_surfaces: {}", r["wall_surfaces"]);
    assert!(t["min"].as_f64().unwrap() > 0.24 && t["max"].as_f64().unwrap() < 0.66, "{t}");
    assert_eq!(r["wall_surfaces"]["outer"].as_str(), Some(path_str(&outer)));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A one-line error (no panic) naming `file` and a lumen-surface node's place.
fn assert_clear_error(stderr: &str, file: &Path, words: &str) {
    let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "not one line:\n{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains(path_str(file)), "does not name {}: {stderr}", file.display());
    assert!(
        stderr.contains("lumen-surface node at (") || stderr.contains("lumen-surface node ("),
        "no place: {stderr}"
    );
    assert!(stderr.contains(words), "no '{words}': {stderr}");
}

#[test]
fn surfaces_in_the_wrong_order_or_missed_are_clear_errors() {
    let dir = temp_dir("wall-surface-errors");
    let (outer, layers) = write_surfaces(&dir, (-2.0, LENGTH + 2.0));
    let case = dir.join("swapped.toml");
    let list = |a: &Path, b: &Path| format!("[wall]\nsurfaces = [{:?}, {:?}]\n", path_str(a), path_str(b));
    std::fs::write(&case, list(&layers[1], &layers[0])).unwrap();
    let (ok, stderr) = mesh_tube(&dir, &["--wall-surface", path_str(&outer), "--config", path_str(&case)]);
    println!("swapped layers: {stderr}");
    assert!(!ok);
    assert_clear_error(&stderr, &layers[0], "out of order");
    // An outer surface ending 3 mm short of each end of the vessel: the end rings' rays miss it.
    let short = dir.join("short");
    std::fs::create_dir_all(&short).unwrap();
    let (outer, _) = write_surfaces(&short, (3.0, LENGTH - 3.0));
    let (ok, stderr) = mesh_tube(&dir, &["--wall-surface", path_str(&outer)]);
    println!("short outer surface: {stderr}");
    assert!(!ok);
    assert_clear_error(&stderr, &outer, "nowhere");
    assert!(!dir.join("out/report.json").exists(), "a failed run leaves no report");
    let _ = std::fs::remove_dir_all(&dir);
}
