//! The `mesh` job, stage by stage: read ([`crate::io::input`]), clean and find the centerlines
//! ([`crate::stages::centerline`]), lay out the junctions and blocks ([`crate::stages::junction`]),
//! project ([`crate::stages::projection`]), build the volume ([`crate::stages::volume`]),
//! annotate ([`crate::stages::annotation`]), add what is asked
//! ([`crate::stages::additions`], run by [`finishing`]) and write ([`crate::writers`], with
//! [`report`]). Data flows forward only. What is tried again when a stage refuses or falls short
//! of a quality bar is in [`policy`]; the checks on inputs and result in `checks`, the vessel's
//! ends in `ends`.

mod checks;
mod ends;
pub mod estimate;
pub mod finishing;
pub mod policy;
pub mod progress;
pub mod report;

use crate::data::config::MeshConfig;
use crate::data::diagnostics::Warning;
use crate::data::error::{Error, Result};
use crate::geometry::surface::{LumenSurface, TriangleSurface};
use crate::io::input::{
    clean_surface, read_centerlines_within, read_surface_parts, read_surface_within, surface_files, Centerlines,
    HygieneReport, NamedCap, ReadLimits,
};
use crate::io::output::OutputFolder;
use crate::pipeline::policy::junction_finish::finish_junctions;
use crate::pipeline::progress::Progress;
use crate::pipeline::report::Report;
use crate::stages::additions::side_ends::SideOpening;
use crate::stages::annotation::accuracy::surface_accuracy;
use crate::stages::annotation::annotate::annotate;
use crate::stages::annotation::end_names::name_mesh_ends;
use crate::stages::annotation::inlets::{inlet_ends, mark_inlets, InletMark};
use crate::stages::annotation::sacs::mark_junction_sacs;
use crate::stages::centerline::extract::{names_of_ends, VesselEnd};
use crate::stages::centerline::{Branch, CenterlineTree};
use crate::stages::junction::blocks::{graded_levels, growth_ratio_for_first_cell};
use crate::stages::junction::LayoutPolicy;
use crate::stages::projection::plan::{project_tree, ProjectedTree};
use crate::stages::volume::{RadialLevels, VolumeInputs};
use crate::writers::{self, WriteOptions};
use std::path::{Path, PathBuf};

pub use crate::stages::annotation::meshed::Meshed;
pub use report::vessel_report;

/// Everything `vesselhex mesh` was asked.
#[derive(Debug, Clone)]
pub struct MeshRequest {
    /// The surface: a file, or a folder of the wall and its caps (see [`crate::io::input::surface_files`]).
    pub surface: PathBuf,
    /// Caps in files of their own (`--cap NAME=FILE`), each naming its end.
    pub caps: Vec<(String, PathBuf)>,
    pub centerlines: Option<PathBuf>,
    /// Unit of the centerline file when it differs from the surface's.
    pub centerline_units: Option<crate::data::units::LengthUnit>,
    /// How to compute the centerlines when none are given (inlet, extra ends).
    pub extraction: crate::stages::centerline::extract::ExtractOptions,
    pub config: MeshConfig,
    /// The case file the configuration came from, if any (an input like the others: never in a
    /// folder the run replaces).
    pub case_file: Option<PathBuf>,
    pub output: PathBuf,
    /// Replace an output folder vesselhex did not write (see [`crate::io::output`]).
    pub force: bool,
    /// The memory the run may plan to use: a mesh estimated to need more is refused before it
    /// is built, and files larger than a tenth of it are not read.
    pub max_memory: u64,
    pub quiet: bool,
    /// Zero the timings so that report.json is byte-identical between runs.
    pub reproducible: bool,
    /// Warnings found before the run (on the command line's settings), reported with the rest.
    pub warnings: Vec<Warning>,
    /// Ends the user flags as inlets besides the one the tree is built from (see
    /// [`crate::stages::annotation::inlets`]).
    pub inlets: Vec<InletMark>,
}

/// Runs the whole job and returns the report (also written as report.json). The outputs are
/// written beside `--output` and put in its place in one rename at the end (see
/// [`crate::io::output`]); on any error, nothing is left behind.
pub fn run(request: &MeshRequest) -> Result<Report> {
    let config = &request.config;
    checks::check_settings(config)?;
    formats_to_write(config)?;
    let inputs: Vec<&Path> = [Some(&request.surface), request.centerlines.as_ref(), request.case_file.as_ref()]
        .into_iter()
        .flatten()
        .chain(request.caps.iter().map(|(_, file)| file))
        .map(PathBuf::as_path)
        .collect();
    let files = surface_files(&request.surface, &request.caps)?;
    crate::pipeline::finishing::check_wall_surfaces(config)?;
    let output = claim_output(&request.output, &inputs, config, request.force)?;
    let limits = ReadLimits::within(request.max_memory);
    // The stages of `mesh_finished`, and surface hygiene, and the extraction when no centerlines are given.
    let stages = 10 + u64::from(request.centerlines.is_none()) + crate::pipeline::finishing::stages(config);
    let mut progress = Progress::new(request.quiet, stages);
    progress.stage("reading");
    let (surface, caps) = if files.caps.is_empty() && files.walls.len() == 1 {
        (read_surface_within(&files.walls[0], config.units, &limits)?.0, vec![])
    } else {
        let (surface, _, caps) = read_surface_parts(&files, config.units, &limits)?;
        (surface, caps)
    };
    let centerline_units = request.centerline_units.unwrap_or(config.units);
    let centerlines = match &request.centerlines {
        Some(path) => CenterlineSource::Given(read_centerlines_within(path, centerline_units, &limits)?),
        None => CenterlineSource::Extract(request.extraction.clone()),
    };
    let settings = MeshSettings {
        config: config.clone(),
        centerline_units: request.centerline_units,
        max_memory: request.max_memory,
        warnings: request.warnings.clone(),
        caps,
        inlets: request.inlets.clone(),
    };
    let vessel = mesh_surface(surface, centerlines, settings, &mut progress)?;
    write_vessel(&vessel, config, output, request.reproducible, &mut progress)
}

/// Meshes a surface already read (millimetres) as `vesselhex mesh` does: the surface cleaned
/// (see [`clean_surface`]), centerlines computed when not given, the settings' lengths and the
/// vessel's units checked, the memory estimated before meshing, the vessel meshed (leaving out,
/// and saying, what cannot be: [`policy::mesh_dropping_what_fails`]), its ends named, then the
/// added stages asked for. The caller's current progress stage (reading) lasts until meshing
/// starts.
pub fn mesh_surface(
    surface: TriangleSurface,
    centerlines: CenterlineSource,
    mut settings: MeshSettings,
    progress: &mut Progress,
) -> Result<MeshedVessel> {
    let config = &settings.config;
    checks::check_settings(config)?;
    check_inlet_caps(&settings.inlets, &settings.caps)?;
    let inlet_flagged = !settings.inlets.is_empty()
        || settings.caps.iter().any(|c| crate::stages::centerline::extract::is_inlet_name(&c.name))
        || match &centerlines {
            CenterlineSource::Extract(o) => {
                o.inlet != crate::stages::centerline::extract::InletChoice::Largest || !o.inlet_names.is_empty()
            }
            CenterlineSource::Given(_) => true,
        };
    crate::pipeline::finishing::check_wall_surfaces(config)?;
    settings.warnings.extend(checks::settings_warnings(config));
    progress.stage("surface hygiene");
    let (surface, hygiene) = clean_surface(surface)?;
    settings.warnings.extend(hygiene.notes().into_iter().map(|n| Warning::new("surface_repaired", n)));
    let loops = checks::surface_loops(&surface);
    let found = centerlines_of(&surface, centerlines, &settings.caps, &settings.inlets, progress)
        .map_err(|e| checks::blame_loops(e, loops))?;
    settings.warnings.extend(found.notes.iter().map(|n| Warning::new("centerlines", n.clone())));
    let Found { centerlines, source: centerline_source, ends: found_ends, mut names, loop_cuts, .. } = found;
    check_size(&surface, &centerlines, &centerline_source, &mut settings)?;
    let config = &settings.config;
    let tree_config = ends::keep_extracted_ends(config, found_ends.as_ref(), &loop_cuts);
    let (mut meshed, centerlines, short_branches) = policy::mesh_dropping_what_fails(
        &surface,
        centerlines,
        &tree_config,
        found_ends.is_some(),
        &mut settings.warnings,
        progress,
    )
    .map_err(|e| checks::blame_loops(e, loops))?;
    settings.warnings.append(&mut meshed.notes);
    let joined = meshed.tree.junctions.iter().map(|j| j.arriving.len()).sum();
    settings.warnings.extend(checks::loop_warning(&surface, loops, joined));
    // The ends named by caps: found on the surface, or the given centerlines' ends.
    let (ends, inlet) = found_ends.clone().unwrap_or_else(|| ends::tree_ends(&meshed.tree));
    if found_ends.is_none() {
        names = names_of_ends(&ends, &settings.caps).map_err(|e| Error::input(&surface.source, e))?;
    }
    name_mesh_ends(&mut meshed.mesh, &ends, &names);
    let inlets = inlet_ends(&ends, &names, inlet, &settings.inlets).map_err(Error::Config)?;
    mark_inlets(&mut meshed.mesh, &ends, &inlets, &names);
    if !inlet_flagged {
        settings.warnings.extend(checks::lone_inlet_warning(&surface, joined, &ends, inlet));
    }
    let openings = ends::side_openings(&surface, found_ends.as_ref().map_or(&[][..], |(e, _)| e), &short_branches);
    let limits = ReadLimits::within(settings.max_memory);
    let asked: Vec<SideOpening> = openings.iter().flatten().copied().collect();
    let mut additions = crate::pipeline::finishing::finish(&mut meshed, &surface, config, &limits, progress, &asked)?;
    // An end opened in the side of the mesh is named as the others.
    for (old, new) in name_mesh_ends(&mut meshed.mesh, &ends, &names) {
        additions.side_ends.iter_mut().filter(|s| s.end == old).for_each(|s| s.end = new.clone());
    }
    let left_out_mm = ends::short_branch_warnings(short_branches, &openings, &additions, &mut settings.warnings);
    names.resize(ends.len(), None);
    Ok(MeshedVessel {
        meshed,
        surface,
        centerline_source,
        centerlines,
        ends,
        inlet,
        inlets,
        end_names: names,
        hygiene,
        additions,
        settings,
        left_out_mm,
    })
}

/// Before anything is computed: every cap the user flags as an inlet by name is given.
fn check_inlet_caps(marks: &[InletMark], caps: &[NamedCap]) -> Result<()> {
    let given: Vec<&str> = caps.iter().map(|c| c.name.as_str()).collect();
    for mark in marks {
        if let InletMark::Cap(name) = mark {
            if !given.contains(&name.as_str()) {
                let given = if given.is_empty() { "none".to_string() } else { given.join(", ") };
                return Err(Error::Config(format!(
                    "--inlet {name}: no cap of that name is given (caps: {given}); name a cap given with --cap NAME=FILE \
                     or in the surface's folder, or give a point x,y,z near the end"
                )));
            }
        }
    }
    Ok(())
}

/// A vessel's centerlines, as given or extracted from its surface, with what the extraction
/// found: the ends and the inlet, the names caps gave them, and its notes.
struct Found {
    centerlines: Centerlines,
    /// Where the centerlines came from (a file, or `(computed from the surface)`).
    source: PathBuf,
    ends: Option<(Vec<VesselEnd>, usize)>,
    names: Vec<Option<String>>,
    notes: Vec<String>,
    /// Where the extraction cut the surface's loops open (mm; see
    /// [`crate::data::config::CenterlineConfig::loop_cuts_mm`]).
    loop_cuts: Vec<[f64; 3]>,
}

/// The centerline stage's first half: the centerlines given, or extracted from the (cleaned)
/// surface with the caps given in files of their own.
fn centerlines_of(
    surface: &TriangleSurface,
    centerlines: CenterlineSource,
    caps: &[NamedCap],
    inlets: &[InletMark],
    progress: &mut Progress,
) -> Result<Found> {
    Ok(match centerlines {
        CenterlineSource::Given(centerlines) => {
            let source = centerlines.source.clone();
            Found { centerlines, source, ends: None, names: vec![], notes: vec![], loop_cuts: vec![] }
        }
        CenterlineSource::Extract(mut options) => {
            progress.stage("centerline extraction");
            if options.caps.is_empty() {
                options.caps = caps.to_vec();
            }
            if options.inlet_names.is_empty() {
                let named =
                    inlets.iter().filter_map(|m| if let InletMark::Cap(n) = m { Some(n.clone()) } else { None });
                options.inlet_names = named.collect();
            }
            let extraction = crate::stages::centerline::extract::extract_centerlines(surface, &options)?;
            Found {
                centerlines: extraction.centerlines,
                source: PathBuf::from("(computed from the surface)"),
                ends: Some((extraction.ends, extraction.inlet)),
                names: extraction.end_names,
                notes: extraction.notes,
                loop_cuts: extraction.loop_cuts.iter().map(|c| c.centre.coords.into()).collect(),
            }
        }
    })
}

/// Before anything large is built: the settings' lengths against the vessel's median radius, a
/// warning when the radius is implausible in the units given, and the mesh's estimated size
/// against the memory budget.
fn check_size(
    surface: &TriangleSurface,
    centerlines: &Centerlines,
    centerline_source: &Path,
    settings: &mut MeshSettings,
) -> Result<()> {
    let config = &settings.config;
    let radius = estimate::median_radius(centerlines, surface);
    checks::check_lengths_against_radius(config, radius)?;
    settings.warnings.extend(checks::unit_warning(radius, config.units, settings.centerline_units));
    let mut estimate = estimate::estimate_mesh(centerlines, radius, config, surface.triangles.len());
    finishing::scale_estimate(&mut estimate, config);
    estimate::check_fits(&estimate, settings.max_memory, centerline_source)
}

/// Where a vessel's centerlines come from.
pub enum CenterlineSource {
    /// Read from a file or handed over (millimetres).
    Given(Centerlines),
    /// Computed from the surface (see [`crate::stages::centerline::extract`]).
    Extract(crate::stages::centerline::extract::ExtractOptions),
}

/// The settings of one meshing besides its inputs.
#[derive(Debug, Clone)]
pub struct MeshSettings {
    pub config: MeshConfig,
    /// Unit of the centerlines when it differs from the surface's (`config.units`): named in
    /// the unit warning.
    pub centerline_units: Option<crate::data::units::LengthUnit>,
    /// The memory the run may plan to use: a mesh estimated to need more is refused before it
    /// is built.
    pub max_memory: u64,
    /// Warnings found before the run, reported with the rest.
    pub warnings: Vec<Warning>,
    /// Caps given in files of their own (see [`crate::io::input::read_surface_parts`]): each names
    /// the end it closes or covers.
    pub caps: Vec<NamedCap>,
    /// Ends the user flags as inlets besides the one the tree is built from (see
    /// [`crate::stages::annotation::inlets`]).
    pub inlets: Vec<InletMark>,
}

/// A vessel meshed and not yet written: the mesh and what its report needs. What `run` writes,
/// and what the Python package holds.
pub struct MeshedVessel {
    pub meshed: Meshed,
    pub surface: TriangleSurface,
    /// Where the centerlines came from (a file, or `(computed from the surface)`).
    pub centerline_source: PathBuf,
    /// The centerlines the mesh was built on (millimetres).
    pub centerlines: Centerlines,
    /// The vessel's ends (found on the surface, or the given centerlines' ends) and which is
    /// the inlet.
    pub ends: Vec<VesselEnd>,
    pub inlet: usize,
    /// Whether each end is an inlet (parallel to `ends`): `inlet` and the ends flagged as inlets.
    pub inlets: Vec<bool>,
    /// The name each end was given by a cap (parallel to `ends`).
    pub end_names: Vec<Option<String>>,
    /// What surface hygiene changed.
    pub hygiene: HygieneReport,
    /// Refinement, segmented walls and flow extensions done after meshing (millimetres).
    pub additions: crate::pipeline::finishing::Additions,
    pub settings: MeshSettings,
    /// The far ends (mm) of branches found on the surface and left out, too short for their
    /// junction (a `branch_not_meshed` warning each).
    pub left_out_mm: Vec<[f64; 3]>,
}

/// Meshes a vessel from its surface and centerlines (both already in mm), with the retry
/// policies of [`policy::merged_then_apart`]: two junctions whose blocks would overlap are
/// merged; a vessel with merged junctions, or one refused as asked, has its junctions spaced as
/// at the coarse preset when a finer spacing was asked and none set for them, said in
/// [`Meshed::notes`].
pub fn mesh_vessel(
    surface: &TriangleSurface,
    centerlines: &Centerlines,
    config: &MeshConfig,
    progress: &mut Progress,
) -> Result<Meshed> {
    mesh_vessel_on(surface, None, centerlines, config, progress)
}

/// [`mesh_vessel`] on `index`, the surface's index when it was built already: the retries of
/// [`policy::mesh_dropping_what_fails`] share one, and what it has learnt (its winding numbers).
pub(crate) fn mesh_vessel_on(
    surface: &TriangleSurface,
    index: Option<&LumenSurface>,
    centerlines: &Centerlines,
    config: &MeshConfig,
    progress: &mut Progress,
) -> Result<Meshed> {
    checks::check_settings(config)?;
    progress.stage("surface index");
    let built;
    let lumen_surface = match index {
        Some(index) => index,
        None => {
            built = LumenSurface::new(surface)?;
            &built
        }
    };
    checks::check_centerline_file(lumen_surface, centerlines)?;
    policy::apart_then_cascaded(surface, lumen_surface, centerlines, config, progress)
}

/// Meshes a vessel from its indexed surface and its centerline tree (both in mm).
/// `steep_short_branches`: see [`crate::stages::projection::ProjectionSetup::steep_short_branches`].
pub fn mesh_tree(
    surface: &TriangleSurface,
    lumen_surface: &LumenSurface,
    mut tree: CenterlineTree,
    centerline_source: &Path,
    config: &MeshConfig,
    steep_short_branches: bool,
    policy: &LayoutPolicy,
    progress: &mut Progress,
) -> Result<Meshed> {
    checks::check_units(lumen_surface, &tree, centerline_source)?;
    let normals_outward = checks::check_inside(lumen_surface, &tree, centerline_source)?;

    progress.stage("projection");
    let ProjectedTree { junctions, templates, plans, projected } =
        project_tree(&mut tree, lumen_surface, config, normals_outward, steep_short_branches, policy)?;

    progress.stage("volume");
    let l = &config.lumen;
    let ratio = match l.first_cell_height {
        Some(h) => growth_ratio_for_first_cell(l.radial_elements, h),
        None => l.growth_ratio,
    };
    let layers = config.wall.layers();
    let levels = RadialLevels::new(graded_levels(l.radial_elements, ratio), &layers);
    let w = &config.wall;
    let thickness = |r: f64| w.thickness_mm.unwrap_or(w.thickness_ratio * r);
    let names: Vec<String> = tree.branches.iter().map(|b| b.name.clone()).collect();
    let inputs = VolumeInputs {
        projected: &projected,
        templates: &templates,
        junctions: &junctions,
        levels: &levels,
        layers: &layers,
        wall_thickness: &thickness,
        wall_growth: w.growth,
        branch_names: &names,
        surface: lumen_surface,
    };
    let (mut mesh, junction_of, junction_variants) = finish_junctions(&inputs);

    progress.stage("annotation");
    annotate(&mut mesh);
    mark_junction_sacs(&mut mesh, &junction_of, &junctions, &tree);
    checks::refuse_inverted(&mesh, &junction_of, &junctions, &tree, surface)?;

    progress.stage("surface accuracy");
    let aligned: Vec<Branch> = plans.into_iter().map(|p| p.branch).collect();
    let accuracy = surface_accuracy(&mesh, lumen_surface, &aligned, &projected)?;
    Ok(Meshed { mesh, tree, projected, accuracy, templates, junctions, junction_of, junction_variants, notes: vec![] })
}

/// Meshes a vessel (both inputs in mm) and runs the added stages its settings ask for: what
/// `vesselhex mesh` builds, without writing it (wall surfaces are read within `max_memory`).
pub fn mesh_finished(
    surface: &TriangleSurface,
    centerlines: &crate::io::input::Centerlines,
    config: &MeshConfig,
    max_memory: u64,
) -> Result<(Meshed, crate::pipeline::finishing::Additions)> {
    let mut progress = Progress::new(true, 9 + crate::pipeline::finishing::stages(config));
    let mut meshed = mesh_vessel(surface, centerlines, config, &mut progress)?;
    let additions = crate::pipeline::finishing::finish(
        &mut meshed,
        surface,
        config,
        &ReadLimits::within(max_memory),
        &mut progress,
        &[],
    )?;
    Ok((meshed, additions))
}

/// Claims the output folder for writing `config`'s formats: `inputs` (and the case file's
/// template folder) must not lie in it (see [`OutputFolder::claim`]).
pub fn claim_output(output: &Path, inputs: &[&Path], config: &MeshConfig, force: bool) -> Result<OutputFolder> {
    let inputs: Vec<&Path> = inputs
        .iter()
        .copied()
        .chain(config.fe.template_dir.as_deref())
        .chain(config.wall.surface.iter().chain(&config.wall.surfaces).map(PathBuf::as_path))
        .collect();
    OutputFolder::claim(output, &inputs, force)
}

/// The formats to write, in writing order (those `fsi` implies first), all known.
fn formats_to_write(config: &MeshConfig) -> Result<Vec<&str>> {
    let mut formats: Vec<&str> = config.formats.iter().map(|s| s.as_str()).collect();
    // The FSI package refers to the openfoam and calculix outputs: write them first.
    if let Some(i) = formats.iter().position(|f| *f == "fsi") {
        for implied in ["calculix", "openfoam"] {
            if !formats.contains(&implied) {
                formats.insert(i, implied);
            }
        }
    }
    for f in &formats {
        if writers::writer(f).is_none() {
            return Err(Error::Config(format!(
                "unknown format '{f}' in --formats (known: {})",
                writers::format_names().join(", ")
            )));
        }
    }
    Ok(formats)
}

/// Writes `config`'s formats of a meshed vessel into the claimed output folder, then
/// report.json (listing every file), and puts the folder in place; returns the report.
/// `config` is the vessel's own, or one that differs only in what the writers read (formats,
/// output units, solver settings). `reproducible` zeroes the timings.
pub fn write_vessel(
    vessel: &MeshedVessel,
    config: &MeshConfig,
    output: OutputFolder,
    reproducible: bool,
    progress: &mut Progress,
) -> Result<Report> {
    checks::check_settings(config)?;
    let formats = formats_to_write(config)?;
    progress.stage("writing");
    output.begin_writing()?;
    let options = WriteOptions::from_config(config);
    let mesh_for = |f: &str| crate::pipeline::finishing::mesh_for_format(&vessel.meshed.mesh, f, config);
    let mut outputs = writers::schedule::write_formats(&formats, &mesh_for, &options, output.staging())?;
    progress.finish();
    let mut report = vessel_report(vessel, config, &progress.timings);
    if reproducible {
        report.timings_s.values_mut().for_each(|t| *t = 0.0);
    }
    // report.json lists every file written: it is also what marks the folder as vesselhex's.
    outputs.push(PathBuf::from(crate::io::output::MARKER));
    report.outputs = outputs.iter().map(|p| p.display().to_string()).collect();
    let json = serde_json::to_string_pretty(&report)
        .map_err(|e| Error::Config(format!("internal: cannot encode the report: {e}")))?;
    writers::write_atomic(&output.staging().join(crate::io::output::MARKER), |w| w.write_all(json.as_bytes()))?;
    output.commit()?;
    Ok(report)
}
