//! Abaqus/Standard deck (`abaqus/model.inp`) of the layered wall: the model of [`super::inp`]
//! in the Abaqus dialect.
//!
//! Differences from the CalculiX dialect: hybrid elements (C3D8H by default, for the
//! near-incompressible tissue), a model-level `*DISTRIBUTION TABLE` of two `COORD3D` columns
//! referenced by the per-layer `*DISTRIBUTION`s, `*ORIENTATION ..., LOCAL DIRECTIONS=2` whose two
//! direction lines are the fibre families (cos beta, +-sin beta, 0) in the element's local
//! (circumferential, longitudinal) plane, and `*ANISOTROPIC HYPERELASTIC, HOLZAPFEL, LOCAL
//! DIRECTIONS=2` materials (C10, D, k1, k2, kappa) from `templates/abaqus/material_hgo.inp`.
//! The deck is flat (no parts), which Abaqus accepts as it is.

use super::inp::{write_inp, Dialect};
use super::WriteOptions;
use crate::data::error::Result;
use crate::geometry::mesh::VesselMesh;
use std::path::{Path, PathBuf};

/// Writes `abaqus/model.inp` under `dir`.
pub fn write_abaqus(mesh: &VesselMesh, options: &WriteOptions, dir: &Path) -> Result<Vec<PathBuf>> {
    write_inp(mesh, options, Dialect::Abaqus, dir)
}
