//! Writers: one module per format, each reading only the annotated [`VesselMesh`]; and
//! [`centerlines`], the centerlines as VMTK-compatible polydata.
//!
//! `--formats` names rows of [`WRITERS`]; adding a solver is one module and one row.

use crate::data::error::Result;
use crate::data::units::LengthUnit;
use crate::geometry::mesh::VesselMesh;
use std::path::{Path, PathBuf};

pub use crate::io::atomic::{write_atomic, write_text_file};

pub mod abaqus;
pub mod calculix;
pub mod centerlines;
pub mod febio;
pub mod fsi;
pub mod inp;
pub mod openfoam;
pub mod schedule;
pub mod template;
pub mod text;
pub mod vtu;

/// What every writer may need besides the mesh.
#[derive(Debug, Clone, Default)]
pub struct WriteOptions {
    /// Length unit of FE outputs (OpenFOAM is always in metres).
    pub length_unit: LengthUnit,
    /// The OpenFOAM case settings (inflow, profile, solver, ASCII or binary).
    pub openfoam: crate::data::config::OpenFoamConfig,
    /// Materials, loads and controls of the FEBio decks (`[febio]` in the case file).
    pub febio: febio::FebioConfig,
    /// Elements, material template and step of the Abaqus and CalculiX decks (`[fe]`).
    pub fe: inp::FeConfig,
    /// Per-layer wall constants shared by every FE deck (`[material]`).
    pub material: crate::data::config::material::WallMaterial,
}

impl WriteOptions {
    /// The writers' share of a configuration.
    pub fn from_config(config: &crate::data::config::MeshConfig) -> Self {
        WriteOptions {
            length_unit: config.output_units,
            openfoam: config.openfoam.clone(),
            febio: config.febio.clone(),
            fe: config.fe.clone(),
            material: config.material.clone(),
        }
    }
}

/// A writer puts its files under `dir` (a staging folder) and returns their paths relative to it.
pub type WriterFn = fn(&VesselMesh, &WriteOptions, &Path) -> Result<Vec<PathBuf>>;

/// The format table: name, what it writes, writer.
pub const WRITERS: &[(&str, &str, WriterFn)] = &[
    ("vtu", "mesh.vtu: VTK XML unstructured grid for ParaView", vtu::write_vtu),
    (
        "openfoam",
        "openfoam/: polyMesh of the lumen (metres) and a laminar blood-flow case with Allrun",
        openfoam::write_openfoam,
    ),
    (
        "openfoam-fsi",
        "openfoam-fsi/: lumen and wall in one polyMesh, cellZones per layer, interface faceZone, for splitMeshRegions",
        openfoam::write_openfoam_fsi,
    ),
    (
        "febio",
        "febio/wall.feb: FEBio 4.0 wall, HGO layers with per-element fibre axes, lumen pressure",
        febio::write_wall,
    ),
    ("febio-fsi", "febio/fsi.feb: FEBio 4.0 monolithic fluid-FSI model of lumen and wall", febio::write_fsi),
    ("abaqus", "abaqus/model.inp: Abaqus deck of the wall, HGO layers, inflation step", abaqus::write_abaqus),
    (
        "calculix",
        "calculix/model.inp: CalculiX deck of the wall, ELASTIC_FIBER layers, inflation step",
        calculix::write_calculix,
    ),
    (
        "fsi",
        "fsi/: exact fluid-solid interface maps and preCICE files for OpenFOAM + CalculiX (implies openfoam, calculix)",
        fsi::write_fsi,
    ),
];

/// The writer of a format name.
pub fn writer(name: &str) -> Option<WriterFn> {
    WRITERS.iter().find(|w| w.0 == name).map(|w| w.2)
}

/// Names of all formats, for messages.
pub fn format_names() -> Vec<&'static str> {
    WRITERS.iter().map(|w| w.0).collect()
}
