//! Small in-memory vessels for unit tests and benchmarks of the later stages (writers, quality),
//! so those do not depend on files. The shipped fixtures (`fixtures/`) are the end-to-end inputs.

use crate::config::MeshConfig;
use crate::error::Result;
use crate::input::{CenterlinePolyline, Centerlines, TriangleSurface};
use crate::pipeline::{mesh_vessel, Meshed};
use crate::progress::Progress;
use indexmap::IndexMap;
use nalgebra::Point3;

/// An open straight tube along +z: `around` points per ring, `rings` + 1 rings, outward normals.
pub fn straight_tube_surface(radius: f64, length: f64, around: usize, rings: usize) -> TriangleSurface {
    let mut vertices = Vec::with_capacity(around * (rings + 1));
    for j in 0..=rings {
        let z = length * j as f64 / rings as f64;
        for i in 0..around {
            let a = std::f64::consts::TAU * i as f64 / around as f64;
            vertices.push(Point3::new(radius * a.cos(), radius * a.sin(), z));
        }
    }
    let mut triangles = Vec::with_capacity(2 * around * rings);
    for j in 0..rings {
        for i in 0..around {
            let a = (j * around + i) as u32;
            let b = (j * around + (i + 1) % around) as u32;
            let (c, d) = (a + around as u32, b + around as u32);
            triangles.push([a, b, d]);
            triangles.push([a, d, c]);
        }
    }
    TriangleSurface { vertices, triangles, triangle_tags: None, source: "straight-tube (in memory)".into() }
}

/// The exact centerline of [`straight_tube_surface`].
pub fn straight_tube_centerline(radius: f64, length: f64) -> Centerlines {
    let n = 60;
    let points: Vec<Point3<f64>> = (0..=n).map(|i| Point3::new(0.0, 0.0, length * i as f64 / n as f64)).collect();
    Centerlines {
        polylines: vec![CenterlinePolyline {
            radii: Some(vec![radius; points.len()]),
            points,
            normals: None,
            cell_tags: IndexMap::new(),
        }],
        source: "straight-tube centerline (in memory)".into(),
    }
}

/// A meshed straight tube (radius 2 mm, 30 mm long) with the given parameters.
pub fn straight_tube_mesh(config: &MeshConfig) -> Result<Meshed> {
    let surface = straight_tube_surface(2.0, 30.0, 96, 120);
    let centerlines = straight_tube_centerline(2.0, 30.0);
    mesh_vessel(&surface, &centerlines, config, &mut Progress::new(true, 9))
}

/// A synthetic fixture as in-memory inputs: its exact triangulation (at the fixture's
/// resolution) and its exact centerline, without going through files.
pub fn fixture_inputs(name: &str) -> Option<(TriangleSurface, Centerlines)> {
    use crate::synthetic::{centerline_abscissae, fixture_by_name, triangulate};
    let v = fixture_by_name(name)?;
    let res = v.resolution();
    let (vertices, triangles) = triangulate(v.as_ref(), res.circumferential, res.axial_step_mm);
    let surface = TriangleSurface { vertices, triangles, triangle_tags: None, source: format!("{name} (in memory)").into() };
    let s = centerline_abscissae(v.as_ref());
    let centerlines = Centerlines {
        polylines: vec![CenterlinePolyline {
            points: s.iter().map(|&s| v.point(s)).collect(),
            radii: Some(s.iter().map(|&s| v.radius(s)).collect()),
            normals: None,
            cell_tags: IndexMap::new(),
        }],
        source: format!("{name} centerline (in memory)").into(),
    };
    Some((surface, centerlines))
}
