//! The `vesselhex` command: parses arguments and dispatches to the library, nothing else.

use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::pipeline::{run, MeshRequest};
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
    /// and the branching ones (STL + VTP centerlines).
    Fixtures {
        /// Folder to write into.
        #[arg(long)]
        output: PathBuf,
    },
}

const MESH_HELP: &str = "Mesh a vessel: lumen (core + four lateral blocks per cross-section, rays cast from the core \
to an outer circle and intersected with the surface, graded towards the wall) and a three-layer wall (intima, media, \
adventitia) grown from the lumen surface along its normal (or along the rays), with per-element triads, collagen fibres and quality figures.

Parameters come from the preset, then the case file (--config, TOML), then these flags. Case-file keys (see README):
  preset, units, output_units, formats
  [centerline] resample_step, smoothing_passes, radius_smoothing_passes, trim_inlet, trim_outlet,
               junction_merge_radii, inlet_mm
  [lumen] core_elements, core_size, radial_elements, growth_ratio, first_cell_height, axial_spacing,
          axial_spacing_mm, ray_reach
  [wall] thickness_ratio, thickness_mm, growth; [wall.intima] / [wall.media] / [wall.adventitia]:
          fraction, elements, fibre_angle_deg
  [openfoam] mean_velocity, flow_rate_ml_s, profile, solver, nu, iterations, end_time, binary
  [fe] abaqus_element, calculix_element, material, template_dir, pressure_mmhg
  [febio] element, lumen_pressure_mmhg, static_steps, [febio.blood], [febio.fsi]
  [material.<layer>] c_kpa, k1_kpa, k2, kappa, bulk_kpa, density_kg_m3, youngs_modulus_kpa, poisson_ratio

Formats (--formats): vtu, calculix, abaqus, febio, febio-fsi, openfoam, openfoam-fsi, fsi (implies openfoam and calculix).
Outputs in --output: the formats' files and report.json (counts, quality, surface accuracy, timings).";

#[derive(Args)]
struct MeshArgs {
    /// Lumen surface: STL (ASCII or binary), VTP or legacy VTK polydata.
    #[arg(long)]
    surface: PathBuf,
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
    /// Output folder (created if needed).
    #[arg(long)]
    output: PathBuf,
    /// No progress display.
    #[arg(long)]
    quiet: bool,
    /// Write zero timings so that report.json is byte-identical from run to run.
    #[arg(long)]
    reproducible: bool,
    /// Worker threads (default: all cores). The output does not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// Without --centerlines: the inlet of the computed centerlines, auto (the largest end) or
    /// x,y,z (the end nearest this point, in --units).
    #[arg(long, default_value = "auto")]
    inlet: String,
    /// Without --centerlines: extra end points x,y,z (in --units), for rounded caps.
    #[arg(long, num_args = 1..)]
    ends: Vec<String>,
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
    /// A point near an end that has no boundary loop or flat cap (rounded caps): x,y,z, repeatable.
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

/// Parses "x,y,z" into a point, scaled to millimetres.
fn parse_point(text: &str, scale: f64) -> vesselhex::Result<nalgebra::Point3<f64>> {
    let v: Vec<f64> = text.split(',').map(|t| t.trim().parse::<f64>()).collect::<Result<_, _>>().unwrap_or_default();
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(nalgebra::Point3::new(*x, *y, *z) * scale),
        _ => Err(vesselhex::Error::Config(format!("'{text}' is not a point x,y,z (three numbers, comma-separated)"))),
    }
}

fn centerlines(args: CenterlinesArgs) -> vesselhex::Result<()> {
    use vesselhex::centerline_extract::{extract_centerlines, write_vtp, ExtractOptions, InletChoice};
    let units = args.units.unwrap_or(LengthUnit::Mm);
    let scale = units.to_mm();
    let inlet = match args.inlet.as_str() {
        "auto" => InletChoice::Largest,
        point => InletChoice::Nearest(parse_point(point, scale)?),
    };
    let ends = args.ends.iter().map(|e| parse_point(e, scale)).collect::<vesselhex::Result<Vec<_>>>()?;
    let (surface, hygiene) = vesselhex::input::clean_surface(vesselhex::input::read_surface(&args.surface, units)?)?;
    let extraction = extract_centerlines(&surface, &ExtractOptions { inlet, ends })?;
    write_vtp(&extraction.centerlines, units.from_mm(), &args.output)?;
    let split_tree = match &args.branch_split {
        Some(path) => {
            Some((vesselhex::centerline_extract::write_branch_split(&extraction, units.from_mm(), path)?, path))
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
                "vesselhex: end {k} ({role}, {:?}): centre ({:.4}, {:.4}, {:.4}) {units}, radius {:.4} {units}",
                e.kind,
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

fn mesh(args: MeshArgs) -> vesselhex::Result<()> {
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
    if let Some(n) = args.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| vesselhex::Error::Config(format!("--threads {n}: {e}")))?;
    }
    let scale = config.units.to_mm();
    let extraction = vesselhex::centerline_extract::ExtractOptions {
        inlet: match args.inlet.as_str() {
            "auto" => vesselhex::centerline_extract::InletChoice::Largest,
            point => vesselhex::centerline_extract::InletChoice::Nearest(parse_point(point, scale)?),
        },
        ends: args.ends.iter().map(|e| parse_point(e, scale)).collect::<vesselhex::Result<Vec<_>>>()?,
    };
    let request = MeshRequest {
        surface: args.surface,
        centerlines: args.centerlines,
        extraction,
        centerline_units: args.centerline_units,
        config,
        output: args.output.clone(),
        quiet: args.quiet,
        reproducible: args.reproducible,
    };
    let report = run(&request)?;
    for w in &report.warnings {
        eprintln!("vesselhex: warning: {}", w.message);
    }
    if !args.quiet {
        eprintln!(
            "vesselhex: {} lumen + {} wall hexes; scaled Jacobian min {:.3} (wall mean {:.3}); lumen skew mean {:.3}; \
             surface nodes within {:.2e} um; written to {}",
            report.lumen.elements,
            report.wall.all.elements,
            report.lumen.scaled_jacobian.min.min(report.wall.all.scaled_jacobian.min),
            report.wall.all.scaled_jacobian.mean,
            report.lumen.equiangle_skew.mean,
            report.surface_accuracy.node_to_surface_um.max,
            args.output.display()
        );
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Mesh(args) => mesh(args),
        Command::Centerlines(args) => centerlines(args),
        Command::Fixtures { output } => vesselhex::synthetic::write_all_fixtures(&output)
            .and_then(|_| vesselhex::synthetic_branching::write_all_branching_fixtures(&output))
            .map(|_| ()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("vesselhex: error: {e}");
            ExitCode::FAILURE
        }
    }
}
