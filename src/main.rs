//! The `vesselhex` command: parses arguments and dispatches to the library, nothing else.

use clap::{Args, Parser, Subcommand};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::inlets::InletMark;
use vesselhex::pipeline::{run, MeshRequest};
use vesselhex::report::Warning;
use vesselhex::units::LengthUnit;

#[derive(Parser)]
#[command(
    name = "vesselhex",
    version,
    about = "Structured hexahedral meshes of blood vessels: lumen O-grid and three-layer wall, with fibres, quality and solver decks"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Mesh a vessel: lumen (core + four lateral blocks per section) and a three-layer wall.
    #[command(long_about = MESH_HELP)]
    Mesh(MeshArgs),
    /// Compute centerlines from the lumen surface: one polyline from the inlet to every outlet,
    /// with MaximumInscribedSphereRadius and CenterlineIds (VMTK-compatible .vtp, in --units).
    Centerlines(CenterlinesArgs),
    /// Write the synthetic test vessels into a folder: the unbranched ones (STL + CSV centerline)
    /// and the branching ones (STL + VTP centerlines); with --random-tree, random vessel trees
    /// with their truth instead, with --random-network random networks with loops and several
    /// inlets, with --circle-of-willis the circle of Willis.
    Fixtures(FixturesArgs),
    /// Mesh every case of a manifest (CSV or JSON), N at a time, each in a process of its own,
    /// with a summary table (summary.csv, summary.json).
    #[command(long_about = vesselhex::batch::command::BATCH_HELP)]
    Batch(vesselhex::batch::command::BatchArgs),
    /// One case of `vesselhex batch`, handed over on standard input (run by the batch itself).
    #[command(hide = true)]
    BatchCase,
}

#[derive(Args)]
#[command(group(clap::ArgGroup::new("generated").args(["random_tree", "random_network", "circle_of_willis"])))]
struct FixturesArgs {
    /// Folder to write into (created if needed).
    #[arg(long)]
    output: PathBuf,
    /// Write the random tree of this seed, or of every seed of a range FIRST-LAST, instead of
    /// the bundled fixtures: tree_SEED.stl (or .vtp), its manifest tree_SEED.json (every end,
    /// vessel, junction, stenosis, aneurysm, hairpin and near pass, and the tree's bins) and
    /// its centerlines tree_SEED_centerlines.vtp. The same seed gives the same bytes.
    #[arg(long, value_name = "SEED", value_parser = parse_seeds)]
    random_tree: Option<(u64, u64)>,
    /// Write the random network (a ring fed by 2-3 inlets, a graft on its host, or a circle of
    /// Willis) of this seed, or of every seed of a range FIRST-LAST: network_SEED.stl (or .vtp),
    /// its manifest network_SEED.json (ends with their inlet or outlet role, junctions,
    /// segments, loops, every draw) and its centerlines network_SEED_centerlines.vtp (one
    /// polyline per segment). The same seed gives the same bytes.
    #[arg(long, value_name = "SEED", value_parser = parse_seeds)]
    random_network: Option<(u64, u64)>,
    /// Write the circle of Willis (both carotids and the basilar feeding a ring of seven
    /// segments, six cerebral arteries leaving it), drawn from seed 0: circle_of_willis.stl (or
    /// .vtp), .json and _centerlines.vtp.
    #[arg(long)]
    circle_of_willis: bool,
    /// Format of a random tree's or network's surface: stl (binary, f32) or vtp (f64) [default: stl].
    #[arg(long, value_parser = ["stl", "vtp"], requires = "generated")]
    format: Option<String>,
    /// No progress display and no summary.
    #[arg(long)]
    quiet: bool,
}

/// Parses a seed or a range of seeds FIRST-LAST.
fn parse_seeds(text: &str) -> Result<(u64, u64), String> {
    let number = |t: &str| {
        t.trim().parse::<u64>().map_err(|_| format!("'{text}' is not a seed (a whole number) or a range FIRST-LAST"))
    };
    match text.split_once('-') {
        Some((a, b)) => {
            let (a, b) = (number(a)?, number(b)?);
            if a > b {
                return Err(format!("the range {text} is empty: write FIRST-LAST with FIRST <= LAST"));
            }
            Ok((a, b))
        }
        None => number(text).map(|n| (n, n)),
    }
}

/// `vesselhex fixtures`: the bundled fixtures, random trees, or random networks.
fn fixtures(args: FixturesArgs) -> vesselhex::Result<()> {
    use vesselhex::synthetic_tree::{write_random_tree, SurfaceFormat};
    let format = if args.format.as_deref() == Some("vtp") { SurfaceFormat::Vtp } else { SurfaceFormat::Stl };
    if args.random_network.is_some() || args.circle_of_willis {
        return network_fixtures(&args, format);
    }
    let Some((first, last)) = args.random_tree else {
        vesselhex::synthetic::write_all_fixtures(&args.output)?;
        vesselhex::synthetic_branching::write_all_branching_fixtures(&args.output)?;
        return Ok(());
    };
    let mut progress = vesselhex::progress::Progress::new(args.quiet, 4 * (last - first + 1));
    for seed in first..=last {
        let written = write_random_tree(seed, &args.output, format, &mut progress)?;
        if !args.quiet {
            progress.suspend(|| {
                let t = &written.tree;
                let redrawn = if t.redrawn.is_empty() {
                    String::new()
                } else {
                    format!(
                        " (drawn {} times: {})",
                        t.attempt + 1,
                        t.redrawn.iter().map(|r| r.reason.as_str()).collect::<Vec<_>>().join("; ")
                    )
                };
                eprintln!(
                    "vesselhex: random tree {seed}: {} ends, {} triangles{redrawn}; written to {}, {}, {}",
                    t.ends.len(),
                    t.surface.triangles.len(),
                    written.surface.display(),
                    written.manifest.display(),
                    written.centerlines.display()
                );
            });
        }
    }
    progress.finish();
    Ok(())
}

/// `vesselhex fixtures --random-network` or `--circle-of-willis`.
fn network_fixtures(args: &FixturesArgs, format: vesselhex::synthetic_tree::SurfaceFormat) -> vesselhex::Result<()> {
    use vesselhex::synthetic_network::{draw::Shape, write_random_network};
    // The circle of Willis is drawn from seed 0's streams.
    let (first, last, forced) = match args.random_network {
        Some((first, last)) => (first, last, None),
        None => (0, 0, Some(Shape::CircleOfWillis)),
    };
    let mut progress = vesselhex::progress::Progress::new(args.quiet, 4 * (last - first + 1));
    for seed in first..=last {
        let written = write_random_network(seed, forced, &args.output, format, &mut progress)?;
        if !args.quiet {
            progress.suspend(|| {
                let n = &written.network;
                let inlets = n.network.ends.iter().filter(|e| e.inlet).count();
                eprintln!(
                    "vesselhex: {} ({}): {} inlets, {} outlets, {} loops, {} triangles, drawn {} times; written to {}, {}, {}",
                    n.name,
                    n.network.shape,
                    inlets,
                    n.network.ends.len() - inlets,
                    n.loops.len(),
                    n.surface.triangles.len(),
                    n.attempt + 1,
                    written.surface.display(),
                    written.manifest.display(),
                    written.centerlines.display()
                );
            });
        }
    }
    progress.finish();
    Ok(())
}

const MESH_HELP: &str = "Mesh a vessel: lumen (core + four lateral blocks per cross-section, rays cast from the core \
to an outer circle and intersected with the surface, graded towards the wall) and a three-layer wall (intima, media, \
adventitia) grown from the lumen surface along its normal (or along the rays), with per-element triads, collagen fibres and quality figures.

Parameters come from the preset, then the case file (--config, TOML), then these flags. Case-file keys (docs/guide/case-file.md):
  preset, units, output_units, formats
  [centerline] resample_step, smoothing_passes, radius_smoothing_passes, trim_inlet, trim_outlet,
               junction_merge_radii, split_fused_daughters, inlet_mm, sacs_mm, loop_cuts_mm
  [lumen] core_elements, core_size, radial_elements, growth_ratio, first_cell_height, axial_spacing,
          axial_spacing_mm, junction_axial_spacing, ray_reach
  [wall] thickness_ratio, thickness_mm, growth, surface, surfaces; [wall.intima] / [wall.media] /
          [wall.adventitia]: fraction, elements, fibre_angle_deg
  [extensions] ends, inlet_length, outlet_length, [extensions.length], shape, blend_length, fe_decks
  [refinement] before_projection, after_projection
  [openfoam] mean_velocity, flow_rate_ml_s, inlet_flow_rates_ml_s, profile, solver, nu, iterations, end_time, binary
  [fe] abaqus_element, calculix_element, material, template_dir, pressure_mmhg
  [febio] element, lumen_pressure_mmhg, static_steps, [febio.blood], [febio.fsi]
  [material.<layer>] c_kpa, k1_kpa, k2, kappa, bulk_kpa, density_kg_m3, youngs_modulus_kpa, poisson_ratio

Formats (--formats): vtu, calculix, abaqus, febio, febio-fsi, openfoam, openfoam-fsi, fsi (implies openfoam and calculix).
Outputs in --output: the formats' files and report.json (counts, quality, surface accuracy, timings), written beside \
it and put in its place in one rename: the folder holds the old result or the new one, never a mix. vesselhex \
replaces only a folder that is empty or that it wrote (its report.json lists every file); --force replaces any.

Exit codes: 0 success (warnings on stderr and in report.json), 1 error (nothing written), 2 usage error, \
130/143/129 interrupted by SIGINT/SIGTERM/SIGHUP (nothing written).";

/// Most worker threads: beyond a few per core they only cost (their start-up grows with their
/// number: 1000 threads took 3.4 s on the AAA fixture, 256 took 0.1 s).
const MAX_THREADS: i64 = 256;

#[derive(Args)]
struct MeshArgs {
    /// Lumen surface: STL (ASCII or binary), VTP or legacy VTK polydata; or a folder of the wall
    /// and its caps, one file each (SimVascular's mesh-surfaces/, snappyHexMesh's triSurface/):
    /// the wall is walls_combined.*, else the files named wall*, else the largest; every other
    /// file is a cap named after it.
    #[arg(long)]
    surface: PathBuf,
    /// A cap in a file of its own, NAME=FILE (repeatable): it closes (or covers) one end of
    /// --surface, which takes its name (the OpenFOAM patch, the FEBio surface, the Abaqus and
    /// CalculiX sets, report.json's end). A cap named inlet is the inlet.
    #[arg(long, value_name = "NAME=FILE", value_parser = parse_cap)]
    cap: Vec<(String, PathBuf)>,
    /// Centerline: VMTK .vtp/.vtk with MaximumInscribedSphereRadius, or CSV with header x,y,z,r.
    #[arg(long)]
    centerlines: Option<PathBuf>,
    /// Length unit of the input files: um, mm, cm or m [default: mm].
    #[arg(long)]
    units: Option<LengthUnit>,
    /// Length unit of the centerline file, when it differs from --units.
    #[arg(long)]
    centerline_units: Option<LengthUnit>,
    /// Length unit of the written meshes (OpenFOAM is always in metres) [default: mm].
    #[arg(long)]
    output_units: Option<LengthUnit>,
    /// Resolution preset: coarse (a few thousand hexes), medium, fine (thesis quality).
    #[arg(long)]
    preset: Option<Preset>,
    /// TOML case file setting any parameter (overrides the preset).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Output formats, comma-separated [default: vtu].
    #[arg(long, value_delimiter = ',')]
    formats: Option<Vec<String>>,
    /// OpenFOAM polyMesh file format: ascii or binary [default: ascii, or the case file's openfoam.binary].
    #[arg(long, value_parser = ["ascii", "binary"])]
    foam_format: Option<String>,
    /// Output folder (created if needed; replaced as a whole, see --force).
    #[arg(long)]
    output: PathBuf,
    /// Replace --output even if it holds files vesselhex did not write (they are deleted).
    #[arg(long)]
    force: bool,
    /// Memory the run may plan to use, e.g. 8G or 512M: a mesh estimated to need more is refused
    /// before it is built, and no input file larger than a tenth of it is read [default: three
    /// quarters of the machine's memory].
    #[arg(long, value_name = "SIZE", value_parser = vesselhex::io::memory::parse_size)]
    max_memory: Option<u64>,
    /// No progress display.
    #[arg(long)]
    quiet: bool,
    /// Write zero timings so that report.json is byte-identical from run to run.
    #[arg(long)]
    reproducible: bool,
    /// Worker threads, 1 to 256 (0 or none: all cores). The output does not depend on it.
    #[arg(long, value_parser = clap::value_parser!(u16).range(0..=MAX_THREADS))]
    threads: Option<u16>,
    /// The inlet: auto (the cap named inlet, else the largest cap named inlet_<x>, else the
    /// largest end), x,y,z (the end nearest this point, in --units) or the NAME of a cap.
    /// Repeatable: every end so given is an inlet, the first the one the centerlines start from
    /// (with --centerlines, theirs); several inlets are named inlet_1, inlet_2, ... unless their
    /// caps name them, and each is its own OpenFOAM inlet patch.
    #[arg(long, default_value = "auto", value_name = "auto|x,y,z|NAME")]
    inlet: Vec<String>,
    /// Without --centerlines: points x,y,z (in --units) near ends, overriding those found (every
    /// end, rounded caps included, is found without them).
    #[arg(long, num_args = 1..)]
    ends: Vec<String>,
    /// Without --centerlines: points x,y,z (in --units) near the domes of saccular aneurysms not
    /// found as such: each sac is meshed as a blind branch closed by a dome, not as an outlet.
    #[arg(long, num_args = 1..)]
    sacs: Vec<String>,
    /// The segmented outer wall surface (STL, VTP or VTK, in --units): the wall runs from the
    /// lumen to it, its thickness as segmented (also wall.surface in the case file).
    #[arg(long, value_name = "FILE")]
    wall_surface: Option<PathBuf>,
}

#[derive(Args)]
struct CenterlinesArgs {
    /// Lumen surface: STL (ASCII or binary), VTP or legacy VTK polydata.
    #[arg(long)]
    surface: PathBuf,
    /// Length unit of the surface, the points given and the output: um, mm, cm or m [default: mm].
    #[arg(long)]
    units: Option<LengthUnit>,
    /// The inlet: auto (the largest end) or x,y,z (the end nearest this point).
    #[arg(long, default_value = "auto")]
    inlet: String,
    /// A point near an end, overriding the end found there (every end, rounded caps included, is
    /// found without it): x,y,z, repeatable.
    #[arg(long, num_args = 1..)]
    ends: Vec<String>,
    /// Output file (.vtp).
    #[arg(long)]
    output: PathBuf,
    /// Also write the branch-split variant (.vtp, VMTK's vmtkbranchextractor layout): one tract
    /// per branch and junction region of each path, with CenterlineIds, TractIds, Blanking and
    /// GroupIds.
    #[arg(long, value_name = "FILE")]
    branch_split: Option<PathBuf>,
    /// No messages.
    #[arg(long)]
    quiet: bool,
}

/// Parses `--cap NAME=FILE`.
fn parse_cap(text: &str) -> Result<(String, PathBuf), String> {
    let (name, file) =
        text.split_once('=').ok_or_else(|| format!("'{text}' is not NAME=FILE (e.g. inlet=inlet.stl)"))?;
    vesselhex::input::check_end_name(name)?;
    if file.is_empty() {
        return Err(format!("'{text}' names no file after '='"));
    }
    Ok((name.to_string(), PathBuf::from(file)))
}

/// Parses "x,y,z" into a point, scaled to millimetres.
fn parse_point(text: &str, scale: f64) -> vesselhex::Result<nalgebra::Point3<f64>> {
    let v: Vec<f64> = text.split(',').map(|t| t.trim().parse::<f64>()).collect::<Result<_, _>>().unwrap_or_default();
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(nalgebra::Point3::new(*x, *y, *z) * scale),
        _ => Err(vesselhex::Error::Config(format!("'{text}' is not a point x,y,z (three numbers, comma-separated)"))),
    }
}

/// The `--inlet` values: `auto` (alone: no mark), points x,y,z (in the input unit, `scale` to
/// mm) and cap names.
fn parse_inlets(values: &[String], scale: f64) -> vesselhex::Result<Vec<InletMark>> {
    if values.iter().any(|v| v == "auto") {
        return match values {
            [_] => Ok(vec![]),
            _ => Err(vesselhex::Error::Config(
                "--inlet auto cannot be given with other --inlet values: give the inlets as points or cap names".into(),
            )),
        };
    }
    values
        .iter()
        .map(
            |v| {
                if v.contains(',') {
                    parse_point(v, scale).map(InletMark::Point)
                } else {
                    Ok(InletMark::Cap(v.clone()))
                }
            },
        )
        .collect()
}

fn centerlines(args: CenterlinesArgs) -> vesselhex::Result<()> {
    use vesselhex::centerline_extract::{extract_centerlines, ExtractOptions, InletChoice};
    use vesselhex::writers::centerlines::write_vtp;
    let units = args.units.unwrap_or(LengthUnit::Mm);
    let scale = units.to_mm();
    let inlet = match args.inlet.as_str() {
        "auto" => InletChoice::Largest,
        point => InletChoice::Nearest(parse_point(point, scale)?),
    };
    let ends = args.ends.iter().map(|e| parse_point(e, scale)).collect::<vesselhex::Result<Vec<_>>>()?;
    check_output_file("--output", &args.output, &[("--surface", &args.surface)])?;
    if let Some(split) = &args.branch_split {
        check_output_file("--branch-split", split, &[("--surface", &args.surface), ("--output", &args.output)])?;
    }
    let (surface, hygiene) = vesselhex::input::clean_surface(vesselhex::input::read_surface(&args.surface, units)?)?;
    let extraction = extract_centerlines(&surface, &ExtractOptions { inlet, ends, ..Default::default() })?;
    write_vtp(&extraction.centerlines, units.from_mm(), &args.output)?;
    let split_tree = match &args.branch_split {
        Some(path) => {
            Some((vesselhex::writers::centerlines::write_branch_split(&extraction, units.from_mm(), path)?, path))
        }
        None => None,
    };
    if !args.quiet {
        for note in hygiene.notes().iter().chain(&extraction.notes) {
            eprintln!("vesselhex: note: {note}");
        }
        for (k, e) in extraction.ends.iter().enumerate() {
            let c = e.centre * units.from_mm();
            let role = if k == extraction.inlet { "inlet" } else { "outlet" };
            eprintln!(
                "vesselhex: end {k} ({role}, {}): centre ({:.4}, {:.4}, {:.4}) {units}, radius {:.4} {units}",
                e.kind.name(),
                c.x,
                c.y,
                c.z,
                e.radius * units.from_mm()
            );
        }
        eprintln!(
            "vesselhex: {} centerlines written to {}",
            extraction.centerlines.polylines.len(),
            args.output.display()
        );
        if let Some((tree, path)) = split_tree {
            eprintln!(
                "vesselhex: {} branches and {} junctions written as tracts to {}",
                tree.branches.len(),
                tree.junctions.len(),
                path.display()
            );
        }
    }
    Ok(())
}

/// Refuses an output file that is a folder or the same file as another path given (an input it
/// would overwrite, or another output).
fn check_output_file(flag: &str, path: &Path, others: &[(&str, &Path)]) -> vesselhex::Result<()> {
    let refuse = |why: String| Err(vesselhex::Error::Config(format!("{flag} {}: {why}", path.display())));
    if path.is_dir() || path.file_name().is_none() {
        return refuse("is a folder; name the .vtp file to write".into());
    }
    let real = |p: &Path| -> Option<PathBuf> {
        match p.canonicalize() {
            Ok(r) => Some(r),
            Err(_) => {
                let parent = p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
                Some(parent.canonicalize().ok()?.join(p.file_name()?))
            }
        }
    };
    for (other_flag, other) in others {
        if real(path).is_some_and(|a| real(other).is_some_and(|b| a == b)) {
            return refuse(format!("is the same file as {other_flag}; name another file"));
        }
    }
    Ok(())
}

/// What a mesh run ended with, short of an error.
enum MeshOutcome {
    /// Every vessel end meshed.
    Complete,
    /// The mesh was written, but some ends are not meshed (named in the warnings).
    EndsNotMeshed,
}

fn mesh(args: MeshArgs) -> vesselhex::Result<MeshOutcome> {
    let mut config = match &args.config {
        Some(path) => MeshConfig::from_case_file(path, args.preset)?,
        None => MeshConfig::preset(args.preset.unwrap_or_default()),
    };
    if let Some(u) = args.units {
        config.units = u;
    }
    if let Some(u) = args.output_units {
        config.output_units = u;
    }
    if let Some(f) = args.formats {
        config.formats = f;
    }
    if let Some(f) = &args.foam_format {
        config.openfoam.binary = f == "binary";
    }
    if let Some(path) = args.wall_surface {
        config.wall.surface = Some(path);
    }
    let mut warnings = vec![];
    if let Some(n) = args.threads {
        if n == 0 {
            let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
            warnings.push(Warning::new("settings", format!("--threads 0 means all cores: {cores} threads")));
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n as usize)
            .build_global()
            .map_err(|e| vesselhex::Error::Config(format!("--threads {n}: {e}")))?;
    }
    let scale = config.units.to_mm();
    let inlet_marks = parse_inlets(&args.inlet, scale)?;
    let extraction = vesselhex::centerline_extract::ExtractOptions {
        inlet: match inlet_marks.first() {
            Some(InletMark::Point(p)) => vesselhex::centerline_extract::InletChoice::Nearest(*p),
            _ => vesselhex::centerline_extract::InletChoice::Largest,
        },
        inlet_names: inlet_marks
            .iter()
            .filter_map(|m| if let InletMark::Cap(name) = m { Some(name.clone()) } else { None })
            .collect(),
        ends: args.ends.iter().map(|e| parse_point(e, scale)).collect::<vesselhex::Result<Vec<_>>>()?,
        sacs: args.sacs.iter().map(|e| parse_point(e, scale)).collect::<vesselhex::Result<Vec<_>>>()?,
        caps: vec![],
    };
    let request = MeshRequest {
        surface: args.surface,
        caps: args.cap,
        centerlines: args.centerlines,
        extraction,
        centerline_units: args.centerline_units,
        config,
        case_file: args.config.clone(),
        output: args.output.clone(),
        force: args.force,
        max_memory: args.max_memory.unwrap_or_else(vesselhex::io::memory::default_max_memory),
        quiet: args.quiet,
        reproducible: args.reproducible,
        warnings,
        inlets: inlet_marks,
    };
    let report = run(&request)?;
    for w in &report.warnings {
        eprintln!("vesselhex: warning: {}", w.message);
    }
    let meshed_ends = report.ends.iter().filter(|e| e.meshed).count();
    let ends = if meshed_ends < report.ends.len() {
        format!("{meshed_ends} of {} ends meshed; ", report.ends.len())
    } else {
        String::new()
    };
    if !args.quiet {
        eprintln!(
            "vesselhex: {ends}{}; scaled Jacobian min {:.3} (wall mean {:.3}); lumen skew mean {:.3}; surface nodes \
             within {:.2e} um; written to {}",
            hex_counts(&report),
            report.lumen.scaled_jacobian.min.min(report.wall.all.scaled_jacobian.min),
            report.wall.all.scaled_jacobian.mean,
            report.lumen.equiangle_skew.mean,
            report.surface_accuracy.node_to_surface_um.max,
            args.output.display()
        );
    }
    Ok(if ends.is_empty() { MeshOutcome::Complete } else { MeshOutcome::EndsNotMeshed })
}

/// The hexes of the summary line by part, adding up to the mesh's: lumen, wall, and the flow
/// extensions' when there are any.
fn hex_counts(report: &vesselhex::report::Report) -> String {
    let extension: usize = report.additions.extensions.iter().flatten().map(|e| e.elements).sum();
    let (lumen, wall) = (report.lumen.elements, report.wall.all.elements);
    if extension == 0 {
        format!("{lumen} lumen + {wall} wall hexes")
    } else {
        format!("{lumen} lumen + {wall} wall + {extension} extension hexes")
    }
}

/// Exit codes (docs/guide/command-line.md): 0 success, 1 error, 2 usage error (clap's), 3 written but some
/// vessel ends not meshed (report.json `ends`), 128 + the signal number when interrupted (130
/// SIGINT, 143 SIGTERM, 129 SIGHUP).
const EXIT_ERROR: u8 = 1;
const EXIT_ENDS_NOT_MESHED: u8 = 3;

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return usage_error(e),
    };
    if let Err(e) = vesselhex::output::install_signal_handlers() {
        eprintln!("vesselhex: error: {e}");
        return ExitCode::from(EXIT_ERROR);
    }
    let result = match cli.command {
        Command::Mesh(args) => mesh(args),
        Command::Centerlines(args) => centerlines(args).map(|_| MeshOutcome::Complete),
        Command::Batch(args) => return vesselhex::batch::command::run_command(args),
        Command::BatchCase => return vesselhex::batch::command::run_child(),
        Command::Fixtures(args) => fixtures(args).map(|_| MeshOutcome::Complete),
    };
    if let Some(signal) = vesselhex::output::interrupted_by() {
        eprintln!("vesselhex: {}", vesselhex::output::interruption(signal));
        return ExitCode::from(vesselhex::output::exit_code_of(signal));
    }
    match result {
        Ok(MeshOutcome::Complete) => ExitCode::SUCCESS,
        Ok(MeshOutcome::EndsNotMeshed) => ExitCode::from(EXIT_ENDS_NOT_MESHED),
        Err(e) => {
            eprintln!("vesselhex: error: {}", vesselhex::error::one_line(&e.to_string()));
            ExitCode::from(EXIT_ERROR)
        }
    }
}

/// Prints clap's error on one line, `vesselhex: error: ...`, keeping its tip and usage; help and
/// version are printed as clap prints them.
fn usage_error(e: clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        e.exit();
    }
    let text = e.render().to_string();
    let mut parts: Vec<String> = vec![];
    for line in text.lines().map(str::trim).filter(|l| !l.is_empty()) {
        if line.starts_with("For more information") {
            continue;
        }
        let line = line.strip_prefix("error: ").unwrap_or(line);
        match parts.last_mut() {
            // A list under a heading ("...were not provided:") continues its line.
            Some(last) if last.ends_with(':') => {
                last.push(' ');
                last.push_str(line);
            }
            _ => parts.push(line.to_string()),
        }
    }
    eprintln!("vesselhex: error: {} (--help for more)", parts.join("; "));
    ExitCode::from(e.exit_code().clamp(0, 255) as u8)
}
