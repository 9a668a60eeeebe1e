//! Surfaces and centerlines handed over as arrays (the Python package: a VMTK or PyVista
//! pipeline's points and triangles), checked as the readers check a file's.

use super::{checked_centerlines, checked_surface, surface, CenterlinePolyline, Centerlines, Result};
use super::{SurfaceReadReport, TriangleSurface};
use crate::data::error::Error;
use crate::data::units::LengthUnit;
use indexmap::IndexMap;
use nalgebra::Point3;
use std::path::Path;

/// A surface from vertex coordinates and triangles (0-based vertex indices), lengths in `units`;
/// `source` names it in messages. Degenerate triangles are dropped (counted in the report), an
/// index out of range, a coordinate that is not finite or no triangle at all is refused.
pub fn surface_from_arrays(
    vertices: &[[f64; 3]],
    triangles: &[[i64; 3]],
    units: LengthUnit,
    source: &Path,
) -> Result<(TriangleSurface, SurfaceReadReport)> {
    let bad = |message: String| Error::input(source, message);
    if let Some(i) = vertices.iter().position(|v| v.iter().any(|c| !c.is_finite())) {
        let v = vertices[i];
        return Err(bad(format!("point {i} is ({}, {}, {}): every coordinate must be finite", v[0], v[1], v[2])));
    }
    let n = vertices.len() as i64;
    if let Some((t, corners)) = triangles.iter().enumerate().find(|(_, t)| t.iter().any(|&i| !(0..n).contains(&i))) {
        return Err(bad(format!(
            "triangle {t} is {corners:?}, but the {n} points are numbered 0 to {}: give 0-based point indices",
            n - 1
        )));
    }
    let triangles = surface::Triangles {
        vertices: vertices.iter().map(|v| Point3::from(*v)).collect(),
        triangles: triangles.iter().map(|t| t.map(|i| i as usize)).collect(),
        tags: None,
    };
    let mut report = SurfaceReadReport::default();
    Ok((checked_surface(triangles, units, source, &mut report)?, report))
}

/// A polyline's points and, when known, its maximal inscribed sphere radius at each point.
pub type PolylineArrays = (Vec<[f64; 3]>, Option<Vec<f64>>);

/// Centerlines from polylines, lengths in `units`; `source` names them in messages.
pub fn centerlines_from_arrays(
    polylines: Vec<PolylineArrays>,
    units: LengthUnit,
    source: &Path,
) -> Result<Centerlines> {
    let bad = |message: String| Error::input(source, message);
    if polylines.is_empty() {
        return Err(bad("holds no polyline; give at least one line of points from the inlet".into()));
    }
    let mut lines = Vec::with_capacity(polylines.len());
    for (k, (points, radii)) in polylines.into_iter().enumerate() {
        if points.len() < 2 {
            return Err(bad(format!("polyline {k} has {} points; a centerline needs at least 2", points.len())));
        }
        if let Some(i) = points.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
            return Err(bad(format!("point {i} of polyline {k} is not finite")));
        }
        if let Some(r) = &radii {
            if r.len() != points.len() {
                return Err(bad(format!("polyline {k} has {} points but {} radii", points.len(), r.len())));
            }
        }
        lines.push(CenterlinePolyline {
            points: points.into_iter().map(Point3::from).collect(),
            radii,
            normals: None,
            cell_tags: IndexMap::new(),
        });
    }
    checked_centerlines(lines, units, source)
}
