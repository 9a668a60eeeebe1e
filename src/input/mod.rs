//! Reading what users bring: lumen surfaces (STL, VTP) and centerlines (VMTK .vtp, legacy .vtk,
//! CSV). Everything leaves this module in millimetres (see [`crate::units`]).

mod centerline;
mod csv;
mod hygiene;
mod polydata;
mod stl;
mod surface;
pub mod topology;
mod vtk_legacy;
mod vtp;

use crate::error::{Error, Result};
use crate::units::LengthUnit;
pub use hygiene::{clean_surface, HygieneReport};
use indexmap::IndexMap;
use nalgebra::{Point3, Vector3};
use polydata::PolyData;
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

/// What reading a surface changed, for the caller to report (the surface itself stays clean).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SurfaceReadReport {
    /// Triangles dropped because they use the same vertex twice.
    pub degenerate_triangles_dropped: usize,
    /// STL vertex records merged into an identical earlier vertex.
    pub stl_vertices_merged: usize,
    /// Polygons of more than three points split into triangle fans.
    pub polygons_fanned: usize,
    /// Triangle strips split into triangles.
    pub strips_converted: usize,
}

const SURFACE_FORMATS: &str = ".stl (ASCII or binary), .vtp (VTK XML polydata) or .vtk (legacy ASCII polydata)";
const CENTERLINE_FORMATS: &str = ".vtp (VMTK, VTK XML polydata), .vtk (legacy ASCII) or .csv (header x,y,z,r)";

/// Reads a lumen surface (STL, VTP or legacy VTK) and converts it to millimetres.
pub fn read_surface(path: &Path, units: LengthUnit) -> Result<TriangleSurface> {
    read_surface_with_report(path, units).map(|(surface, _)| surface)
}

/// [`read_surface`], also returning what was repaired on the way.
pub fn read_surface_with_report(path: &Path, units: LengthUnit) -> Result<(TriangleSurface, SurfaceReadReport)> {
    let bad = |message: String| Error::input(path, message);
    let mut report = SurfaceReadReport::default();
    let mut triangles = match extension(path).as_str() {
        "stl" => {
            let mesh = stl::parse(&read_bytes(path)?).map_err(bad)?;
            report.stl_vertices_merged = mesh.merged;
            surface::Triangles { vertices: mesh.vertices, triangles: mesh.triangles, tags: None }
        }
        "vtp" | "vtk" => surface::from_polydata(read_polydata(path)?, &mut report),
        other => return Err(bad(unknown_extension(other, SURFACE_FORMATS))),
    };
    surface::drop_degenerate(&mut triangles, &mut report);
    if triangles.triangles.is_empty() {
        let dropped = report.degenerate_triangles_dropped;
        let why = if dropped > 0 { format!(" (all {dropped} were degenerate)") } else { String::new() };
        return Err(bad(format!("contains no triangles{why}: it is not a surface mesh")));
    }
    if triangles.vertices.len() > u32::MAX as usize {
        return Err(bad(format!("has {} vertices, more than 2^32", triangles.vertices.len())));
    }
    let scale = units.to_mm();
    let surface = TriangleSurface {
        vertices: triangles.vertices.iter().map(|p| p * scale).collect(),
        triangles: triangles.triangles.iter().map(|t| t.map(|i| i as u32)).collect(),
        triangle_tags: triangles.tags,
        source: path.to_path_buf(),
    };
    Ok((surface, report))
}

/// Reads centerlines (VMTK .vtp, legacy .vtk or CSV) and converts lengths to millimetres.
/// Radii may be absent (`None`); the caller decides whether that is acceptable.
pub fn read_centerlines(path: &Path, units: LengthUnit) -> Result<Centerlines> {
    let bad = |message: String| Error::input(path, message);
    let polylines = match extension(path).as_str() {
        "vtp" | "vtk" => centerline::from_polydata(&read_polydata(path)?).map_err(bad)?,
        "csv" => {
            let text = String::from_utf8(read_bytes(path)?).map_err(|_| bad("is not UTF-8 text".into()))?;
            let line = csv::parse(&text).map_err(bad)?;
            if line.points.len() < 2 {
                return Err(bad(format!("has {} point rows; a centerline needs at least 2", line.points.len())));
            }
            vec![line]
        }
        other => return Err(bad(unknown_extension(other, CENTERLINE_FORMATS))),
    };
    if let Some(r) = polylines.iter().flat_map(|p| p.radii.iter().flatten()).find(|r| !r.is_finite() || **r < 0.0) {
        return Err(bad(format!("has a radius {r}; radii must be finite and non-negative")));
    }
    let scale = units.to_mm();
    let polylines = polylines
        .into_iter()
        .map(|mut p| {
            p.points.iter_mut().for_each(|x| *x *= scale);
            p.radii.iter_mut().flatten().for_each(|r| *r *= scale);
            p
        })
        .collect();
    Ok(Centerlines { polylines, source: path.to_path_buf() })
}

/// Reads a `.vtp` or legacy `.vtk` file into polydata.
fn read_polydata(path: &Path) -> Result<PolyData> {
    let bytes = read_bytes(path)?;
    let parsed = if extension(path) == "vtp" {
        vtp::parse(&bytes)
    } else {
        std::str::from_utf8(&bytes)
            .map_err(|e| format!("is not ASCII text (byte {}); only ASCII legacy VTK is supported", e.valid_up_to()))
            .and_then(vtk_legacy::parse)
    };
    parsed.map_err(|message| Error::input(path, message))
}

/// The file's bytes; an empty file is an error here so every format reports it the same way.
fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, "cannot read the file", e))?;
    if bytes.iter().all(u8::is_ascii_whitespace) {
        return Err(Error::input(path, "the file is empty"));
    }
    Ok(bytes)
}

fn extension(path: &Path) -> String {
    path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default()
}

fn unknown_extension(ext: &str, supported: &str) -> String {
    let shown = if ext.is_empty() { "no extension".to_string() } else { format!("extension '.{ext}'") };
    format!("has {shown}, which is not a supported format; use {supported}")
}
