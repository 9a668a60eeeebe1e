//! Meshing benchmark: `cargo bench` meshes synthetic vessels at the fine preset and at about
//! 800,000 hexes (the size of the paper's fine aortic arch: 537,750 lumen + 256,500 wall hexes,
//! remeshed in 132 s) and prints, per stage, seconds and elements per second, then the writers'
//! throughput; then the bundled Y and T junctions at the medium preset. Timings are measured once per case (the stages are deterministic and long enough
//! for one run to be representative), on the threads rayon gives (all cores by default).

use std::time::Instant;
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::input::{read_centerlines, read_surface, Centerlines, TriangleSurface};
use vesselhex::pipeline::mesh_vessel;
use vesselhex::progress::Progress;
use vesselhex::units::LengthUnit;
use vesselhex::writers::{WriteOptions, WRITERS};

/// A case's inputs: an unbranched analytic fixture in memory, or a bundled branched fixture
/// (`fixtures/NAME.stl` and `fixtures/NAME_centerlines.vtp`).
fn inputs(name: &str) -> (TriangleSurface, Centerlines) {
    if let Some(inputs) = vesselhex::testing::fixture_inputs(name) {
        return inputs;
    }
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let surface = read_surface(&dir.join(format!("{name}.stl")), LengthUnit::Mm).expect("bundled fixture");
    let cl = read_centerlines(&dir.join(format!("{name}_centerlines.vtp")), LengthUnit::Mm).expect("its centerlines");
    (surface, cl)
}

fn run(label: &str, name: &str, config: &MeshConfig) {
    let (surface, cl) = inputs(name);
    let mut progress = Progress::new(true, 9);
    let t0 = Instant::now();
    let meshed = mesh_vessel(&surface, &cl, config, &mut progress).expect("mesh");
    progress.finish();
    let total = t0.elapsed().as_secs_f64();
    let mesh = &meshed.mesh;
    let n = mesh.hexes.len() as f64;
    println!(
        "\n{label}: {name}, {} lumen + {} wall = {} hexes, {} nodes, {} triangles in the surface; meshing {:.3} s ({:.0} hexes/s)",
        mesh.lumen_range().len(),
        mesh.wall_range().len(),
        mesh.hexes.len(),
        mesh.nodes.len(),
        surface.triangles.len(),
        total,
        n / total
    );
    for (stage, t) in &progress.timings {
        println!("  {stage:18} {t:9.4} s  {:>14.0} hexes/s", n / t.max(1e-9));
    }
    let dir = std::env::temp_dir().join(format!("vesselhex-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let options = WriteOptions::from_config(config);
    for (format, _, write) in WRITERS {
        let t = Instant::now();
        let files = write(mesh, &options, &dir).expect("write");
        let dt = t.elapsed().as_secs_f64();
        let bytes: u64 = files.iter().map(|f| dir_size(&dir.join(f))).sum();
        println!(
            "  write {format:12} {dt:9.4} s  {:>14.0} hexes/s  {:8.1} MB  {:7.1} MB/s",
            n / dt,
            bytes as f64 / 1e6,
            bytes as f64 / 1e6 / dt
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

fn dir_size(p: &std::path::Path) -> u64 {
    if p.is_dir() {
        std::fs::read_dir(p).map(|rd| rd.flatten().map(|e| dir_size(&e.path())).sum()).unwrap_or(0)
    } else {
        std::fs::metadata(p).map(|m| m.len()).unwrap_or(0)
    }
}

/// Centerline extraction from a bare surface of about 100,000 triangles (the helical fixture's
/// shape at a fine resolution).
fn centerlines_case() {
    use vesselhex::centerline_extract::{extract_centerlines, ExtractOptions};
    let v = vesselhex::synthetic::fixture_by_name("helical").expect("fixture");
    let (vertices, triangles) = vesselhex::synthetic::triangulate(v.as_ref(), 144, 0.16);
    let surface =
        vesselhex::input::TriangleSurface { vertices, triangles, triangle_tags: None, source: "fine helix".into() };
    let t = Instant::now();
    let ex = extract_centerlines(&surface, &ExtractOptions::default()).expect("centerlines");
    println!(
        "\ncenterlines: {} triangles -> {} paths in {:.3} s",
        surface.triangles.len(),
        ex.centerlines.polylines.len(),
        t.elapsed().as_secs_f64()
    );
}

fn main() {
    // `cargo bench -- <filter>` runs the cases whose label contains the filter.
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    let fine = MeshConfig::preset(Preset::Fine);
    let mut big = MeshConfig::preset(Preset::Fine);
    // helical at the fine preset with a shorter axial step: about 800,000 hexes
    big.lumen.axial_spacing_mm = Some(0.0569);
    let medium = MeshConfig::preset(Preset::Medium);
    // The branched fixtures at the medium preset: their junctions are finished several ways
    // (README, Branching vessels), the volume stage's cost.
    let cases: [(&str, &str, &MeshConfig); 5] = [
        ("fine preset", "aaa", &fine),
        ("fine preset", "helical", &fine),
        ("800k hexes", "helical", &big),
        ("junctions, medium preset", "y_bifurcation", &medium),
        ("junctions, medium preset", "t_junction", &medium),
    ];
    if filter.as_deref().is_none_or(|f| "centerlines".contains(f)) {
        centerlines_case();
    }
    for (label, name, config) in cases {
        if filter.as_deref().is_none_or(|f| label.contains(f) || name.contains(f)) {
            run(label, name, config);
        }
    }
}
