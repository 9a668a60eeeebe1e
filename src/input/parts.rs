//! A vessel's surface in several files, as CFD users keep it: the wall and one file per cap
//! (snappyHexMesh's `constant/triSurface/*.stl`, SimVascular's `mesh-surfaces/` with `wall.vtp`
//! or `walls_combined.vtp` and `cap_*.vtp`, dfemtoolz's `BC0.stl` ... `BC6.stl`), named on the
//! command line (`--surface wall.stl --cap inlet=inlet.stl ...`) or by their files (`--surface
//! DIR`). The caps fix the ends and name them: a cap whose rim is the wall's is joined to it, its
//! triangles tagged (see [`CAP_TAGS`]), and closes that end; a cap that does not touch the wall
//! names the open end it covers. Either way the end takes the cap's name, which becomes the
//! OpenFOAM patch, the FEBio surface, the Abaqus/CalculiX sets and the key of the FSI maps.

use super::topology::{boundary_loops, loop_centre_and_area, orient_consistently};
use super::{extension, read_surface_within, ReadLimits, SurfaceReadReport, TriangleSurface};
use crate::error::{Error, Result};
use crate::units::LengthUnit;
use nalgebra::Point3;
use std::path::{Path, PathBuf};

/// The cell array the joined surface tags its triangles with: 0 on the wall, k + 1 on the k-th
/// cap joined.
pub const CAP_TAGS: &str = "vesselhex_cap";

/// A cap's rim point lies on the wall when a wall point is this close (a fraction of the wall's
/// bounding box diagonal, as hygiene welds).
const ON_RIM: f64 = 1e-9;

/// The surface formats a folder's files may have.
const SURFACE_EXTENSIONS: [&str; 3] = ["stl", "vtp", "vtk"];

/// Names the mesh gives its own sets and patches: an end may not take them.
const RESERVED: [&str; 8] = ["wall", "lumen", "intima", "media", "adventitia", "extension", "lumen_wall", "outer_wall"];

/// A cap in a file of its own.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedCap {
    /// The end's name.
    pub name: String,
    pub file: PathBuf,
    /// Its triangles' value of [`CAP_TAGS`] in the joined surface; None when its rim is not the
    /// wall's (it was not joined: it names the open end it covers).
    pub tag: Option<i64>,
    /// Its rim's centre (length-weighted, mm) and equivalent radius sqrt(area / pi).
    pub centre: Point3<f64>,
    pub radius: f64,
}

/// The files of a surface given in parts.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SurfaceFiles {
    /// The wall, in one file or several (joined); empty when the wall is the file of `caps`
    /// with the most triangles (a folder with no file named wall*).
    pub walls: Vec<PathBuf>,
    /// Each cap's name and file.
    pub caps: Vec<(String, PathBuf)>,
}

/// Whether an end may take this name: a letter, then letters, digits and underscores (what
/// OpenFOAM patches and Abaqus sets accept), not a name the mesh uses for itself.
pub fn check_end_name(name: &str) -> std::result::Result<(), String> {
    let mut chars = name.chars();
    let valid = chars.next().is_some_and(|c| c.is_ascii_alphabetic())
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
        && name.len() <= 64;
    if !valid {
        return Err(format!(
            "'{name}' cannot name an end: use a letter, then letters, digits or underscores (at most 64), as OpenFOAM \
             patches and Abaqus sets need"
        ));
    }
    let taken =
        RESERVED.contains(&name) || ["lumen_", "wall_", "cut_", "extension_"].iter().any(|p| name.starts_with(p));
    if taken {
        return Err(format!(
            "'{name}' cannot name an end: the mesh names its own sets and patches so (wall, lumen, the layers, and \
             lumen_*, wall_*, cut_*, extension_*); choose another name"
        ));
    }
    Ok(())
}

/// An end's name from a file's name: its stem, every character other than a letter, a digit
/// or an underscore made an underscore, `cap_` put before one that does not start with a
/// letter or that names the mesh's own sets (`wall_left.stl` in a folder with a wall.stl is a
/// cap named `cap_wall_left`).
pub fn end_name_of_file(path: &Path) -> String {
    let stem = path.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
    let clean: String = stem.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' }).collect();
    let clean: String = clean.chars().take(60).collect();
    if check_end_name(&clean).is_ok() {
        clean
    } else {
        format!("cap_{clean}")
    }
}

/// The files `--surface` (a file or a folder) and `--cap` name. In a folder: the wall is
/// `walls_combined.*` when there is one (SimVascular; its `wall_*` pieces are then left out), else
/// every file named `wall*` (joined), else the file with the most triangles; every other surface
/// file is a cap named after it. `--cap` may not be given with a folder.
pub fn surface_files(surface: &Path, caps: &[(String, PathBuf)]) -> Result<SurfaceFiles> {
    for (name, _) in caps {
        check_end_name(name).map_err(Error::Config)?;
    }
    if let Some((name, _)) = caps.iter().enumerate().find_map(|(k, c)| caps[..k].iter().find(|o| o.0 == c.0)) {
        return Err(Error::Config(format!("--cap {name} is given twice; give each cap its own name")));
    }
    if !surface.is_dir() {
        return Ok(SurfaceFiles { walls: vec![surface.to_path_buf()], caps: caps.to_vec() });
    }
    if !caps.is_empty() {
        return Err(Error::Config(format!(
            "--surface {} is a folder, whose files name the caps: give --cap with a wall file instead",
            surface.display()
        )));
    }
    let listing = std::fs::read_dir(surface).map_err(|e| Error::io(surface, "cannot list the folder", e))?;
    let mut files: Vec<PathBuf> = listing
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && SURFACE_EXTENSIONS.contains(&extension(p).as_str()))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(Error::input(
            surface,
            "is a folder with no surface file (.stl, .vtp or .vtk): give the wall and its caps there, or a surface file",
        ));
    }
    let stem = |p: &PathBuf| p.file_stem().map(|s| s.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    let combined: Vec<PathBuf> = files.iter().filter(|p| stem(p) == "walls_combined").cloned().collect();
    let walls: Vec<PathBuf> = if !combined.is_empty() {
        combined
    } else {
        files.iter().filter(|p| stem(p).starts_with("wall")).cloned().collect()
    };
    let caps = files
        .iter()
        .filter(|p| !walls.contains(p) && !(stem(p).starts_with("wall") && !walls.is_empty()))
        .map(|p| (end_name_of_file(p), p.clone()))
        .collect::<Vec<_>>();
    if let Some((name, _)) = caps.iter().enumerate().find_map(|(k, c)| caps[..k].iter().find(|o| o.0 == c.0)) {
        return Err(Error::input(surface, format!("holds two caps named {name} (from their files): rename one")));
    }
    Ok(SurfaceFiles { walls, caps })
}

/// Reads a surface given in parts, in millimetres: the walls joined (in order), then each cap
/// whose rim is the wall's joined to it and tagged ([`CAP_TAGS`]); every cap with its rim's
/// centre and radius. Refuses a cap that is not a disc (one boundary loop).
pub fn read_surface_parts(
    files: &SurfaceFiles,
    units: LengthUnit,
    limits: &ReadLimits,
) -> Result<(TriangleSurface, SurfaceReadReport, Vec<NamedCap>)> {
    let mut report = SurfaceReadReport::default();
    let mut read = |path: &Path| -> Result<TriangleSurface> {
        let (surface, r) = read_surface_within(path, units, limits)?;
        report.degenerate_triangles_dropped += r.degenerate_triangles_dropped;
        report.stl_vertices_merged += r.stl_vertices_merged;
        report.polygons_fanned += r.polygons_fanned;
        report.strips_converted += r.strips_converted;
        Ok(surface)
    };
    let mut caps: Vec<(String, PathBuf, TriangleSurface)> =
        files.caps.iter().map(|(n, p)| Ok((n.clone(), p.clone(), read(p)?))).collect::<Result<_>>()?;
    let mut walls: Vec<TriangleSurface> = files.walls.iter().map(|p| read(p)).collect::<Result<_>>()?;
    if walls.is_empty() {
        // The wall is the file with the most triangles (ties: the first).
        let k = (0..caps.len()).rev().max_by_key(|&k| caps[k].2.triangles.len()).expect("a folder has a file");
        walls.push(caps.remove(k).2);
    }
    let mut joined = walls.remove(0);
    for w in walls {
        append(&mut joined, &w, None);
    }
    joined.triangle_tags = Some((CAP_TAGS.to_string(), vec![0; joined.triangles.len()]));
    let near_wall = RimIndex::new(&joined);
    let mut named = vec![];
    for (name, file, cap) in caps {
        let (rim, centre, radius) = rim_of(&cap, &file)?;
        let on_wall = rim.iter().all(|&v| near_wall.holds(&cap.vertices[v as usize]));
        let tag = on_wall.then(|| named.iter().filter(|c: &&NamedCap| c.tag.is_some()).count() as i64 + 1);
        if let Some(t) = tag {
            append(&mut joined, &cap, Some(t));
        }
        named.push(NamedCap { name, file, tag, centre, radius });
    }
    Ok((joined, report, named))
}

/// Appends `part`'s points and triangles to `surface` (its triangles tagged `tag`, when the
/// surface is tagged).
fn append(surface: &mut TriangleSurface, part: &TriangleSurface, tag: Option<i64>) {
    let offset = surface.vertices.len() as u32;
    surface.vertices.extend_from_slice(&part.vertices);
    surface.triangles.extend(part.triangles.iter().map(|t| t.map(|v| v + offset)));
    if let Some((_, tags)) = &mut surface.triangle_tags {
        tags.extend(std::iter::repeat_n(tag.unwrap_or(0), part.triangles.len()));
    }
}

/// A cap's rim (its one boundary loop), its centre and equivalent radius.
fn rim_of(cap: &TriangleSurface, file: &Path) -> Result<(Vec<u32>, Point3<f64>, f64)> {
    let mut triangles = cap.triangles.clone();
    orient_consistently(&mut triangles);
    let mut loops = boundary_loops(&triangles);
    if loops.len() != 1 {
        return Err(Error::input(
            file,
            format!(
                "is given as a cap but has {} boundary loops: a cap is a disc closing one end of the vessel (one rim); \
                 give the wall in its own file",
                loops.len()
            ),
        ));
    }
    let rim = loops.remove(0);
    let (centre, area) = loop_centre_and_area(&cap.vertices, &rim);
    Ok((rim, centre, (area.norm() / std::f64::consts::PI).sqrt()))
}

/// The wall's points filed in a grid of cells [`ON_RIM`] of its diagonal wide: whether a point
/// lies on one of them.
struct RimIndex {
    cells: std::collections::HashMap<[i64; 3], Vec<Point3<f64>>>,
    tolerance: f64,
}

impl RimIndex {
    fn new(wall: &TriangleSurface) -> RimIndex {
        let (lo, hi) = wall
            .vertices
            .iter()
            .fold((Point3::from([f64::MAX; 3]), Point3::from([f64::MIN; 3])), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
        let tolerance = (ON_RIM * (hi - lo).norm()).max(f64::MIN_POSITIVE);
        let mut cells: std::collections::HashMap<[i64; 3], Vec<Point3<f64>>> = Default::default();
        for p in &wall.vertices {
            cells.entry(cell(p, tolerance)).or_default().push(*p);
        }
        RimIndex { cells, tolerance }
    }

    fn holds(&self, p: &Point3<f64>) -> bool {
        let c = cell(p, self.tolerance);
        (-1..=1)
            .flat_map(|a| (-1..=1).flat_map(move |b| (-1..=1).map(move |d| [c[0] + a, c[1] + b, c[2] + d])))
            .filter_map(|k| self.cells.get(&k))
            .flatten()
            .any(|q| (q - p).norm() <= self.tolerance)
    }
}

fn cell(p: &Point3<f64>, size: f64) -> [i64; 3] {
    [(p.x / size).floor() as i64, (p.y / size).floor() as i64, (p.z / size).floor() as i64]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn end_names_are_checked_and_made_from_file_names() {
        assert!(check_end_name("outlet_lica").is_ok());
        for bad in ["", "1st", "a b", "wall", "wall_left", "lumen_x", "é"] {
            assert!(check_end_name(bad).is_err(), "{bad}");
        }
        assert_eq!(end_name_of_file(Path::new("dir/cap_aorta.vtp")), "cap_aorta");
        assert_eq!(end_name_of_file(Path::new("outlet-1.stl")), "outlet_1");
        assert_eq!(end_name_of_file(Path::new("BC0.stl")), "BC0");
        assert_eq!(end_name_of_file(Path::new("0.stl")), "cap_0");
        assert_eq!(end_name_of_file(Path::new("wall_left.stl")), "cap_wall_left");
    }
}
