//! Scale benchmark: a real surface (`aneurisk_C0092_ica_segment` of `../shared/vessels`, a tortuous
//! internal carotid) meshed with the counts of `../shared/bench/c0092_800k.toml` (80 elements
//! around, 10 radial in the lumen, wall 2/3/2) at axial steps giving about 0.8 M and 3 M hexes,
//! and 10 M on request, every format written.
//!
//! `cargo bench --bench scale` runs 0.8 M and 3 M; `cargo bench --bench scale -- scale10m` runs
//! 10 M (about a minute on two cores, 6 GB of output); `-- scale800k`, `-- scale3m` one size.
//!
//! Per size it prints, from one process: seconds per stage, the mesh's own bytes
//! ([`VesselMesh::heap_bytes`]) and the resident memory after meshing, then per writer the
//! seconds, the bytes written and the peak resident memory above the mesh (the kernel's high-water
//! mark, reset before each writer). Then the whole command (`vesselhex mesh --formats <every
//! format>`) in a process of its own, and, when Gmsh's Python module is installed, Gmsh building
//! the same counts on an analytic tube (`../shared/bench/gmsh_tube.py`, `.inp` and `.msh`), both
//! timed with `/usr/bin/time` (wall seconds and peak resident memory). `GMSH_PYTHON` names the
//! Python that has `gmsh` (default `python3`).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;
use vesselhex::config::MeshConfig;
use vesselhex::input::{read_centerlines, read_surface};
use vesselhex::pipeline::mesh_vessel;
use vesselhex::progress::Progress;
use vesselhex::units::LengthUnit;
use vesselhex::writers::{WriteOptions, WRITERS};

/// A size: label (the filter), axial step (mm), stations of the Gmsh tube with the same counts
/// per section (1760 hexes per station).
const SIZES: [(&str, f64, usize); 3] =
    [("scale800k", 0.1105, 450), ("scale3m", 0.02915, 1705), ("scale10m", 0.008745, 5682)];

const SURFACE: &str = "aneurisk_C0092_ica_segment/C0092_clip1_0.vtp";
const CENTERLINES: &str = "aneurisk_C0092_ica_segment/C0092_clip1_mesh1_0.95_ratio_centerline.vtp";

fn crate_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn shared() -> PathBuf {
    crate_dir().join("../shared")
}

fn vessels() -> PathBuf {
    std::env::var_os("VESSELHEX_VESSELS").map(PathBuf::from).unwrap_or_else(|| shared().join("vessels"))
}

/// A field of /proc/self/status in bytes (VmRSS, VmHWM).
fn status_bytes(field: &str) -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find(|l| l.starts_with(field))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|kb| kb.parse::<u64>().ok())
        .map_or(0, |kb| kb * 1024)
}

/// Resets the peak resident memory (VmHWM) to the current one.
fn reset_peak() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1u64 << 20) as f64
}

fn dir_size(p: &Path) -> u64 {
    if p.is_dir() {
        std::fs::read_dir(p).map(|rd| rd.flatten().map(|e| dir_size(&e.path())).sum()).unwrap_or(0)
    } else {
        std::fs::metadata(p).map(|m| m.len()).unwrap_or(0)
    }
}

/// The case file of the size: the shared 800k case with its axial step replaced.
fn case_text(step: f64) -> String {
    let text =
        std::fs::read_to_string(shared().join("bench/c0092_800k.toml")).expect("../shared/bench/c0092_800k.toml");
    text.lines()
        .map(|l| if l.starts_with("axial_spacing_mm") { format!("axial_spacing_mm = {step}") } else { l.to_string() })
        .collect::<Vec<_>>()
        .join("\n")
}

/// Runs a command under `/usr/bin/time`: (wall seconds, peak resident MiB), or the wall time
/// alone when `/usr/bin/time` is missing.
fn timed(program: &str, args: &[&str]) -> Option<(f64, Option<f64>)> {
    let time = Path::new("/usr/bin/time");
    let t = Instant::now();
    let output = if time.exists() {
        Command::new(time).args(["-f", "TIME %e %M"]).arg(program).args(args).output()
    } else {
        Command::new(program).args(args).output()
    }
    .ok()?;
    let wall = t.elapsed().as_secs_f64();
    if !output.status.success() {
        eprintln!("  {program} failed: {}", String::from_utf8_lossy(&output.stderr));
        return None;
    }
    let stderr = String::from_utf8_lossy(&output.stderr);
    let peak = stderr
        .lines()
        .rev()
        .find_map(|l| l.strip_prefix("TIME "))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|kb| kb.parse::<f64>().ok())
        .map(|kb| kb / 1024.0);
    Some((wall, peak))
}

fn run(label: &str, step: f64, gmsh_stations: usize) {
    let dir = std::env::temp_dir().join(format!("vesselhex-scale-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let case = dir.join("case.toml");
    std::fs::write(&case, case_text(step)).expect("case file");
    let config = MeshConfig::from_case_file(&case, None).expect("case file");
    let (surface_path, centerline_path) = (vessels().join(SURFACE), vessels().join(CENTERLINES));

    reset_peak();
    let t0 = Instant::now();
    let mut progress = Progress::new(true, 9);
    progress.stage("reading");
    let surface = read_surface(&surface_path, LengthUnit::Mm).expect("surface");
    let centerlines = read_centerlines(&centerline_path, LengthUnit::Mm).expect("centerlines");
    let meshed = mesh_vessel(&surface, &centerlines, &config, &mut progress).expect("mesh");
    progress.finish();
    let meshing = t0.elapsed().as_secs_f64();
    let mesh = &meshed.mesh;
    let n = mesh.hexes.len();
    let mesh_bytes = mesh.heap_bytes() as u64;
    println!(
        "\n{label}: C0092, axial step {step} mm: {} lumen + {} wall = {n} hexes, {} nodes; meshed in {meshing:.2} s",
        mesh.lumen_range().len(),
        mesh.wall_range().len(),
        mesh.nodes.len()
    );
    for (stage, t) in &progress.timings {
        println!("  {stage:18} {t:8.3} s");
    }
    let resident = status_bytes("VmRSS");
    println!(
        "  mesh {:.1} MiB ({:.0} bytes/hex); resident {:.1} MiB after meshing, peak {:.1} MiB while meshing",
        mib(mesh_bytes),
        mesh_bytes as f64 / n as f64,
        mib(resident),
        mib(status_bytes("VmHWM"))
    );
    let options = WriteOptions::from_config(&config);
    let out = dir.join("in-process");
    let mut total = 0.0;
    for (format, _, write) in WRITERS {
        std::fs::create_dir_all(&out).expect("output dir");
        reset_peak();
        let before = status_bytes("VmRSS");
        let t = Instant::now();
        let files = write(mesh, &options, &out).expect("write");
        let dt = t.elapsed().as_secs_f64();
        total += dt;
        let bytes: u64 = files.iter().map(|f| dir_size(&out.join(f))).sum();
        let extra = status_bytes("VmHWM").saturating_sub(before);
        println!(
            "  write {format:12} {dt:7.3} s  {:8.1} MB  {:6.0} MB/s  peak +{:6.1} MiB",
            bytes as f64 / 1e6,
            bytes as f64 / 1e6 / dt,
            mib(extra)
        );
        let _ = std::fs::remove_dir_all(&out);
    }
    println!("  writers together {total:.2} s; meshing + writing {:.2} s", meshing + total);
    drop(meshed);

    let formats: Vec<&str> = WRITERS.iter().map(|w| w.0).collect();
    let formats = formats.join(",");
    let out_cli = dir.join("cli");
    let args = [
        "mesh",
        "--surface",
        surface_path.to_str().expect("utf-8 path"),
        "--centerlines",
        centerline_path.to_str().expect("utf-8 path"),
        "--config",
        case.to_str().expect("utf-8 path"),
        "--formats",
        &formats,
        "--output",
        out_cli.to_str().expect("utf-8 path"),
        "--quiet",
    ];
    let ours = timed(env!("CARGO_BIN_EXE_vesselhex"), &args);
    let written = dir_size(&out_cli);
    let _ = std::fs::remove_dir_all(&out_cli);
    let show = |(wall, peak): (f64, Option<f64>)| match peak {
        Some(p) => format!("{wall:.2} s, peak {p:.0} MiB"),
        None => format!("{wall:.2} s (no /usr/bin/time: peak not measured)"),
    };
    if let Some(r) = ours {
        println!("  whole command, every format ({:.0} MB written): {}", written as f64 / 1e6, show(r));
    }
    let python = std::env::var("GMSH_PYTHON").unwrap_or_else(|_| "python3".into());
    let has_gmsh = Command::new(&python).args(["-c", "import gmsh"]).output().is_ok_and(|o| o.status.success());
    if !has_gmsh {
        println!("  Gmsh: not installed ({python} cannot import gmsh; `pip install gmsh`, or set GMSH_PYTHON)");
    } else {
        let script = shared().join("bench/gmsh_tube.py");
        let prefix = dir.join("gmsh/x");
        let stations = gmsh_stations.to_string();
        let gmsh = timed(
            &python,
            &[
                script.to_str().expect("utf-8 path"),
                "--preset",
                "800k",
                "--axial",
                &stations,
                "--out-prefix",
                prefix.to_str().expect("utf-8 path"),
            ],
        );
        if let Some(g) = gmsh {
            println!("  Gmsh tube, {} hexes, .inp + .msh: {}", 1760 * gmsh_stations, show(g));
            if let Some(o) = ours {
                println!("  time ratio vesselhex (every format) / Gmsh: {:.2}", o.0 / g.0);
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

fn main() {
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    if !vessels().join(SURFACE).exists() {
        println!("scale: skipped ({} not found; set VESSELHEX_VESSELS)", vessels().join(SURFACE).display());
        return;
    }
    for (label, step, stations) in SIZES {
        let wanted = match filter.as_deref() {
            None => label != "scale10m",
            Some(f) => (label == "scale10m" && f == label) || (label != "scale10m" && label.contains(f)),
        };
        if wanted {
            run(label, step, stations);
        }
    }
}
