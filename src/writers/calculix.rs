//! CalculiX deck (`calculix/model.inp`) of the layered wall: the model of [`super::inp`] in the
//! dialect ccx 2.20 solves as it is (`ccx -i model`).
//!
//! Differences from the Abaqus dialect: no hybrid elements (C3D8I by default; C3D8, C3D8R,
//! C3D20, C3D20R on request), the native `*DISTRIBUTION` form without a table, no `LOCAL
//! DIRECTIONS`, and the fibres through `*MATERIAL, NAME=ELASTIC_FIBER_<LAYER>` with `*USER
//! MATERIAL, CONSTANTS=10`: C10, D1, then per family x, y (components in the element's local
//! circumferential/longitudinal axes; ccx completes z = sqrt(1 - x^2 - y^2) = 0), k1, k2.
//! Results: ASCII `model.frd` (`*NODE FILE` U, `*EL FILE` S, E) and a `*NODE PRINT` of the
//! middle lumen ring in `model.dat`.

use super::inp::{write_inp, Dialect};
use super::WriteOptions;
use crate::data::error::Result;
use crate::geometry::mesh::VesselMesh;
use std::path::{Path, PathBuf};

/// Writes `calculix/model.inp` under `dir`.
pub fn write_calculix(mesh: &VesselMesh, options: &WriteOptions, dir: &Path) -> Result<Vec<PathBuf>> {
    write_inp(mesh, options, Dialect::Calculix, dir)
}
