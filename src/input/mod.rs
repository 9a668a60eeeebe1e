//! Reading what users bring: lumen surfaces (STL, VTP) and centerlines (VMTK .vtp, legacy .vtk,
//! CSV). Everything leaves this module in millimetres (see [`crate::units`]).

use crate::error::Result;
use crate::units::LengthUnit;
use indexmap::IndexMap;
use nalgebra::{Point3, Vector3};
use std::path::{Path, PathBuf};

/// A triangulated lumen surface, lengths in millimetres.
#[derive(Debug, Clone)]
pub struct TriangleSurface {
    pub vertices: Vec<Point3<f64>>,
    /// Triangles as 0-based vertex indices (polygons with more than three points are fanned).
    pub triangles: Vec<[u32; 3]>,
    /// Per-triangle integer tag when the file carries one (e.g. SimVascular's `ModelFaceID`).
    pub triangle_tags: Option<(String, Vec<i64>)>,
    /// The file it came from (for messages).
    pub source: PathBuf,
}

/// One centerline polyline as read, lengths in millimetres.
#[derive(Debug, Clone)]
pub struct CenterlinePolyline {
    pub points: Vec<Point3<f64>>,
    /// Maximum inscribed sphere radius per point, when the file has it.
    pub radii: Option<Vec<f64>>,
    /// Parallel-transport normals per point, when the file has them.
    pub normals: Option<Vec<Vector3<f64>>>,
    /// Integer cell arrays of the polyline's cell (CenterlineIds, GroupIds, Blanking, ...).
    pub cell_tags: IndexMap<String, i64>,
}

/// All polylines of a centerline file, in file order.
#[derive(Debug, Clone)]
pub struct Centerlines {
    pub polylines: Vec<CenterlinePolyline>,
    pub source: PathBuf,
}

pub fn read_surface(path: &Path, units: LengthUnit) -> Result<TriangleSurface> {
    let _ = (path, units);
    todo!("input helper")
}

pub fn read_centerlines(path: &Path, units: LengthUnit) -> Result<Centerlines> {
    let _ = (path, units);
    todo!("input helper")
}
