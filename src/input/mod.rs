//! Reading what users bring: lumen surfaces (STL, VTP) and centerlines (VMTK .vtp, legacy .vtk,
//! CSV). Everything leaves this module in millimetres (see [`crate::units`]).

mod arrays;
mod centerline;
mod csv;
mod hygiene;
mod orientation;
mod parts;
mod polydata;
mod stl;
mod surface;
pub mod topology;
mod vtk_legacy;
mod vtp;

use crate::error::{Error, Result};
use crate::resources::short;
pub use crate::resources::ReadLimits;
use crate::units::LengthUnit;
pub use arrays::{centerlines_from_arrays, surface_from_arrays, PolylineArrays};
pub use hygiene::{clean_surface, weld, HygieneReport};
use indexmap::IndexMap;
use nalgebra::{Point3, Vector3};
pub use parts::{
    check_end_name, end_name_of_file, read_surface_parts, surface_files, NamedCap, SurfaceFiles, CAP_TAGS,
};
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
    read_surface_within(path, units, &ReadLimits::default())
}

/// [`read_surface_with_report`] within `limits` (file size, decoded size).
pub fn read_surface_within(
    path: &Path,
    units: LengthUnit,
    limits: &ReadLimits,
) -> Result<(TriangleSurface, SurfaceReadReport)> {
    let bad = |message: String| Error::input(path, message);
    let mut report = SurfaceReadReport::default();
    let triangles = match extension(path).as_str() {
        "stl" => {
            let mesh = stl::parse(&read_bytes(path, limits)?).map_err(bad)?;
            report.stl_vertices_merged = mesh.merged;
            surface::Triangles { vertices: mesh.vertices, triangles: mesh.triangles, tags: None }
        }
        "vtp" | "vtk" => surface::from_polydata(read_polydata(path, limits)?, &mut report),
        other => return Err(bad(unknown_extension(other, SURFACE_FORMATS))),
    };
    Ok((checked_surface(triangles, units, path, &mut report)?, report))
}

/// The surface of `triangles` (in `units`) in millimetres, its degenerate triangles dropped
/// (counted in `report`); refused when nothing is left, or a vertex is out of reach.
fn checked_surface(
    mut triangles: surface::Triangles,
    units: LengthUnit,
    path: &Path,
    report: &mut SurfaceReadReport,
) -> Result<TriangleSurface> {
    let bad = |message: String| Error::input(path, message);
    surface::drop_degenerate(&mut triangles, report);
    if triangles.triangles.is_empty() {
        let dropped = report.degenerate_triangles_dropped;
        let why = if dropped > 0 { format!(" (all {dropped} were degenerate)") } else { String::new() };
        return Err(bad(format!("contains no triangles{why}: it is not a surface mesh")));
    }
    if triangles.vertices.len() > u32::MAX as usize {
        return Err(bad(format!("has {} vertices, more than 2^32", triangles.vertices.len())));
    }
    let scale = units.to_mm();
    if let Some((i, p)) = triangles.vertices.iter().enumerate().find(|(_, p)| !within_reach(&(*p * scale))) {
        return Err(bad(format!(
            "vertex {i} is at ({}, {}, {}) {units}, beyond 1e7 mm (10 km) from the origin: a corrupt file or the \
             wrong --units",
            short(p.x),
            short(p.y),
            short(p.z)
        )));
    }
    let surface = TriangleSurface {
        vertices: triangles.vertices.iter().map(|p| p * scale).collect(),
        triangles: triangles.triangles.iter().map(|t| t.map(|i| i as u32)).collect(),
        triangle_tags: triangles.tags,
        source: path.to_path_buf(),
    };
    Ok(surface)
}

/// Reads centerlines (VMTK .vtp, legacy .vtk or CSV) and converts lengths to millimetres.
/// Radii may be absent (`None`); the caller decides whether that is acceptable.
pub fn read_centerlines(path: &Path, units: LengthUnit) -> Result<Centerlines> {
    read_centerlines_within(path, units, &ReadLimits::default())
}

/// [`read_centerlines`] within `limits` (file size, decoded size).
pub fn read_centerlines_within(path: &Path, units: LengthUnit, limits: &ReadLimits) -> Result<Centerlines> {
    let bad = |message: String| Error::input(path, message);
    let polylines = match extension(path).as_str() {
        "vtp" | "vtk" => centerline::from_polydata(&read_polydata(path, limits)?).map_err(bad)?,
        "csv" => {
            let text = text_of(read_bytes(path, limits)?).map_err(bad)?;
            let line = csv::parse(&text).map_err(bad)?;
            if line.points.len() < 2 {
                return Err(bad(format!("has {} point rows; a centerline needs at least 2", line.points.len())));
            }
            vec![line]
        }
        other => return Err(bad(unknown_extension(other, CENTERLINE_FORMATS))),
    };
    checked_centerlines(polylines, units, path)
}

/// Polylines (in `units`) as centerlines in millimetres; refused when a radius is negative or
/// not finite, a point or radius is out of reach, or a polyline is a closed loop.
fn checked_centerlines(polylines: Vec<CenterlinePolyline>, units: LengthUnit, path: &Path) -> Result<Centerlines> {
    let bad = |message: String| Error::input(path, message);
    if let Some(r) = polylines.iter().flat_map(|p| p.radii.iter().flatten()).find(|r| !r.is_finite() || **r < 0.0) {
        return Err(bad(format!("has a radius {r}; radii must be finite and non-negative")));
    }
    let scale = units.to_mm();
    let polylines: Vec<CenterlinePolyline> = polylines
        .into_iter()
        .map(|mut p| {
            p.points.iter_mut().for_each(|x| *x *= scale);
            p.radii.iter_mut().flatten().for_each(|r| *r *= scale);
            p
        })
        .collect();
    for (k, line) in polylines.iter().enumerate() {
        let name = if polylines.len() == 1 { "the centerline".to_string() } else { format!("polyline {k}") };
        if let Some(i) = line.points.iter().position(|p| !within_reach(p)) {
            let p = line.points[i] / scale;
            return Err(bad(format!(
                "point {i} of {name} is at ({}, {}, {}) {units}, beyond 1e7 mm (10 km) from the origin: a mistyped \
                 value or the wrong --centerline-units",
                short(p.x),
                short(p.y),
                short(p.z)
            )));
        }
        if let Some(r) = line.radii.iter().flatten().find(|r| **r > MAX_COORDINATE_MM) {
            return Err(bad(format!(
                "{name} has a radius of {} {units}: a mistyped value or the wrong units",
                short(r / scale)
            )));
        }
        if let Some(why) = closed_loop(line) {
            return Err(bad(format!(
                "{name} is a closed loop ({why}); a centerline runs from an inlet to an outlet: cut the loop open \
                 (drop its last points) or give the vessel's own centerline"
            )));
        }
    }
    Ok(Centerlines { polylines, source: path.to_path_buf() })
}

/// Coordinates beyond this distance from the origin (10 km) are a corrupt file or a unit error;
/// further out, lengths lose the precision the mesh needs and squares overflow.
pub const MAX_COORDINATE_MM: f64 = 1e7;

fn within_reach(p: &Point3<f64>) -> bool {
    p.iter().all(|c| c.abs() <= MAX_COORDINATE_MM)
}

/// Why a polyline is a closed loop (it comes back to its start within two of its steps, after
/// at least eight), if it is one.
fn closed_loop(line: &CenterlinePolyline) -> Option<String> {
    let n = line.points.len();
    if n < 8 {
        return None;
    }
    let mut steps: Vec<f64> = line.points.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
    let length: f64 = steps.iter().sum();
    steps.sort_by(f64::total_cmp);
    let step = steps[steps.len() / 2];
    let gap = (line.points[n - 1] - line.points[0]).norm();
    (gap <= 2.0 * step && length > 8.0 * step && length > 4.0 * gap)
        .then(|| format!("its last point is {gap:.3} mm from its first, after {length:.3} mm"))
}

/// Reads a `.vtp` or legacy `.vtk` file into polydata.
fn read_polydata(path: &Path, limits: &ReadLimits) -> Result<PolyData> {
    let bytes = read_bytes(path, limits)?;
    let parsed = if extension(path) == "vtp" {
        vtp::parse_within(&bytes, limits.inflated_bytes)
    } else {
        text_of(bytes).and_then(|text| vtk_legacy::parse(&text))
    };
    parsed.map_err(|message| Error::input(path, message))
}

/// UTF-8 text without its byte-order mark; UTF-16 (what some editors call "Unicode") is named.
pub(crate) fn text_of(bytes: Vec<u8>) -> std::result::Result<String, String> {
    if bytes.starts_with(&[0xFF, 0xFE]) || bytes.starts_with(&[0xFE, 0xFF]) {
        return Err("is UTF-16 text; save it as UTF-8 (or ASCII)".into());
    }
    let text = String::from_utf8(bytes).map_err(|e| {
        format!("is not UTF-8 text (byte {} is not); save it as UTF-8 or ASCII", e.utf8_error().valid_up_to())
    })?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// The file's bytes; an empty file is an error here so every format reports it the same way.
fn read_bytes(path: &Path, limits: &ReadLimits) -> Result<Vec<u8>> {
    let bytes = read_regular_file(path, limits.file_bytes, "cannot read the file")?;
    if bytes.iter().all(u8::is_ascii_whitespace) {
        return Err(Error::input(path, "the file is empty"));
    }
    Ok(bytes)
}

/// The bytes of a regular file of at most `max_bytes` (through links): a named pipe, a device,
/// a folder or a socket is refused before anything is read (a pipe would block, `/dev/zero`
/// never ends), and so is a larger file. `what` says what failed when the file cannot be opened.
pub fn read_regular_file(path: &Path, max_bytes: u64, what: &'static str) -> Result<Vec<u8>> {
    use std::io::Read;
    let file = open_without_blocking(path).map_err(|e| Error::io(path, what, e))?;
    let meta = file.metadata().map_err(|e| Error::io(path, what, e))?;
    if let Some(kind) = not_a_file(&meta) {
        return Err(Error::input(path, format!("is {kind}, not a regular file; give the file itself")));
    }
    let too_big = |size: u64| {
        Error::input(
            path,
            format!(
                "is {}, more than the {} a run reads from one file (a tenth of --max-memory); if the file is \
                 genuine, raise --max-memory",
                crate::resources::show_bytes(size as f64),
                crate::resources::show_bytes(max_bytes as f64)
            ),
        )
    };
    if meta.len() > max_bytes {
        return Err(too_big(meta.len()));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(max_bytes.saturating_add(1)).read_to_end(&mut bytes).map_err(|e| Error::io(path, what, e))?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_big(bytes.len() as u64));
    }
    Ok(bytes)
}

/// Opens for reading without waiting for a writer (a named pipe would block `open` itself).
fn open_without_blocking(path: &Path) -> std::io::Result<std::fs::File> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(rustix::fs::OFlags::NONBLOCK.bits() as i32);
    }
    options.open(path)
}

/// What a file is when it is not a regular file.
fn not_a_file(meta: &std::fs::Metadata) -> Option<&'static str> {
    let t = meta.file_type();
    if t.is_file() {
        return None;
    }
    if t.is_dir() {
        return Some("a folder");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return Some("a named pipe (FIFO)");
        }
        if t.is_char_device() || t.is_block_device() {
            return Some("a device");
        }
        if t.is_socket() {
            return Some("a socket");
        }
    }
    Some("not a regular file")
}

fn extension(path: &Path) -> String {
    path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default()
}

fn unknown_extension(ext: &str, supported: &str) -> String {
    let shown = if ext.is_empty() { "no extension".to_string() } else { format!("extension '.{ext}'") };
    format!("has {shown}, which is not a supported format; use {supported}")
}
