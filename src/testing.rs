//! Small in-memory vessels for unit tests and benchmarks of the later stages (writers, quality),
//! so those do not depend on files. The shipped fixtures (`fixtures/`) are the end-to-end inputs.
//! The mutation suite (issue 45) lives in [`mutations`] (the real vessels written the ways
//! users' tools write them) and [`suite`] (each meshed and judged).

pub mod decimate;
pub mod mutations;
pub mod suite;

use crate::data::config::MeshConfig;
use crate::data::error::Result;
use crate::geometry::mesh::{sets, ElementFace, Region, Triad, VesselEnd, VesselMesh};
use crate::io::input::{CenterlinePolyline, Centerlines, TriangleSurface};
use crate::pipeline::progress::Progress;
use crate::pipeline::{mesh_vessel, Meshed};
use indexmap::IndexMap;
use nalgebra::{Point3, Rotation3, Vector3};

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

/// [`straight_tube_surface`] closed at both ends by flat caps fanned from the axis, outward
/// normals.
pub fn capped_tube_surface(radius: f64, length: f64, around: usize, rings: usize) -> TriangleSurface {
    let mut tube = straight_tube_surface(radius, length, around, rings);
    let id = |i: usize, j: usize| (j * around + i % around) as u32;
    let (bottom, top) = (tube.vertices.len() as u32, tube.vertices.len() as u32 + 1);
    tube.vertices.push(Point3::new(0.0, 0.0, 0.0));
    tube.vertices.push(Point3::new(0.0, 0.0, length));
    for i in 0..around {
        tube.triangles.push([bottom, id(i + 1, 0), id(i, 0)]);
        tube.triangles.push([top, id(i, rings), id(i + 1, rings)]);
    }
    tube.source = "capped-tube (in memory)".into();
    tube
}

/// A tube of radius `radius` along +z, from a flat cap in the plane z = x tan(`tilt`) (fanned
/// from its centre at the origin) to z = `length` (open): a vessel clipped off square.
pub fn tilted_cap_tube_surface(radius: f64, length: f64, tilt: f64) -> TriangleSurface {
    let around = 48;
    let mut tube = straight_tube_surface(radius, length, around, 40);
    // Each ring's share of the length kept, measured from the cap's plane instead of z = 0.
    for p in &mut tube.vertices {
        let z0 = p.x * tilt.tan();
        p.z = z0 + (length - z0) * p.z / length;
    }
    let centre = tube.vertices.len() as u32;
    tube.vertices.push(Point3::origin());
    tube.triangles.extend((0..around as u32).map(|i| [centre, (i + 1) % around as u32, i]));
    tube.source = "tilted-cap tube (in memory)".into();
    tube
}

/// A tube of radius `radius` along +z, open at z = 0, closed beyond z = `length` by a dome of
/// height `dome_height` (half an ellipsoid; a hemisphere when it equals the radius): a blind
/// branch, a sac's shape at its simplest.
pub fn domed_tube_surface(radius: f64, length: f64, dome_height: f64) -> TriangleSurface {
    let around = 64;
    let mut tube = straight_tube_surface(radius, length, around, 60);
    let dome_rings = 24;
    for j in 1..dome_rings {
        let psi = std::f64::consts::FRAC_PI_2 * (1.0 - j as f64 / dome_rings as f64);
        for i in 0..around {
            let a = std::f64::consts::TAU * i as f64 / around as f64;
            let p = Point3::new(
                radius * psi.sin() * a.cos(),
                radius * psi.sin() * a.sin(),
                length + dome_height * psi.cos(),
            );
            tube.vertices.push(p);
        }
    }
    let first = (tube.vertices.len() - (dome_rings - 1) * around - around) as u32;
    let ring = |j: usize, i: usize| first + (j * around + i % around) as u32;
    for j in 0..dome_rings - 1 {
        for i in 0..around {
            tube.triangles.push([ring(j, i), ring(j, i + 1), ring(j + 1, i + 1)]);
            tube.triangles.push([ring(j, i), ring(j + 1, i + 1), ring(j + 1, i)]);
        }
    }
    let pole = tube.vertices.len() as u32;
    tube.vertices.push(Point3::new(0.0, 0.0, length + dome_height));
    tube.triangles.extend((0..around).map(|i| [ring(dome_rings - 1, i), ring(dome_rings - 1, i + 1), pole]));
    tube.source = "domed tube (in memory)".into();
    tube
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
    let surface =
        TriangleSurface { vertices, triangles, triangle_tags: None, source: format!("{name} (in memory)").into() };
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

/// A rigid motion of a meshed vessel: `rotation` about the origin, then `shift` (mm). Nodes, end
/// centres and normals, triads and fibres move with it; quality figures do not change.
pub fn moved(mut mesh: VesselMesh, rotation: Rotation3<f64>, shift: Vector3<f64>) -> VesselMesh {
    for p in &mut mesh.nodes {
        *p = rotation * *p + shift;
    }
    for t in &mut mesh.triads {
        *t = Triad { e_circ: rotation * t.e_circ, e_long: rotation * t.e_long, e_rad: rotation * t.e_rad };
    }
    for f in &mut mesh.fibres {
        *f = f.map(|v| rotation * v);
    }
    for e in &mut mesh.ends {
        e.centre = rotation * e.centre + shift;
        e.outward_normal = rotation * e.outward_normal;
    }
    mesh
}

/// Joins vessel meshes into one [`VesselMesh`] with several outlets, the way a branched mesh
/// names its ends: the first inlet keeps the name `inlet`, every other end (the other parts'
/// inlets included) becomes an outlet `outlet_1`, `outlet_2`, ... in part order, and the end's
/// node and face sets (`lumen_<end>`, `wall_<end>`) are renamed with it. Each part's branches
/// follow the previous part's (`branch_of`, `branch_names` `part<k>_<name>`); elements are
/// ordered region by region (lumen, intima, media, adventitia), within a region part by part, as
/// the mesh invariants want; nodes part by part. Sets of the same name are merged and sorted.
///
/// The parts stay disjoint, so the result is no vessel to simulate (a flow solver sees separate
/// regions, and the renamed inlets carry no inflow): it exercises the writers' per-end and
/// per-branch bookkeeping on a mesh with several outlets, several branches and oblique ends.
pub fn join_disjoint(parts: Vec<VesselMesh>) -> VesselMesh {
    let layers = parts.first().map(|p| p.layers.clone()).unwrap_or_default();
    let mut node_offset = Vec::with_capacity(parts.len());
    let mut nodes = Vec::new();
    for p in &parts {
        node_offset.push(nodes.len() as u32);
        nodes.extend_from_slice(&p.nodes);
    }
    // New element index of every part's elements: region-major, then part.
    let mut new_index: Vec<Vec<u32>> = parts.iter().map(|p| vec![0; p.hexes.len()]).collect();
    let (mut hexes, mut regions, mut branch_of, mut sac) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut triads, mut fibres, mut quality) = (Vec::new(), Vec::new(), Vec::new());
    let mut branch_offset = Vec::with_capacity(parts.len());
    let mut branch_names = Vec::new();
    for (k, p) in parts.iter().enumerate() {
        branch_offset.push(branch_names.len() as u32);
        branch_names.extend(p.branch_names.iter().map(|n| format!("part{k}_{n}")));
    }
    for region in Region::ALL {
        for (k, p) in parts.iter().enumerate() {
            for e in p.region_range(region) {
                new_index[k][e] = hexes.len() as u32;
                hexes.push(p.hexes[e].map(|n| n + node_offset[k]));
                regions.push(region);
                branch_of.push(p.branch_of[e] + branch_offset[k]);
                sac.push(p.sac[e]);
                triads.push(p.triads[e]);
                fibres.push(p.fibres[e]);
                quality.push(p.quality[e]);
            }
        }
    }
    let mut ends = Vec::new();
    let mut node_sets: IndexMap<String, Vec<u32>> = IndexMap::new();
    let mut face_sets: IndexMap<String, Vec<ElementFace>> = IndexMap::new();
    let mut outlets = 0;
    for (k, p) in parts.iter().enumerate() {
        let mut rename: Vec<(String, String)> = Vec::new();
        for end in &p.ends {
            let mut end = end.clone();
            let name = if end.is_inlet && !ends.iter().any(|e: &VesselEnd| e.is_inlet) {
                "inlet".to_string()
            } else {
                outlets += 1;
                end.is_inlet = false;
                format!("outlet_{outlets}")
            };
            rename.push((sets::lumen_end(&end.name), sets::lumen_end(&name)));
            rename.push((sets::wall_end(&end.name), sets::wall_end(&name)));
            end.name = name;
            end.branch += branch_offset[k] as usize;
            ends.push(end);
        }
        let renamed =
            |set: &str| rename.iter().find(|(old, _)| old == set).map_or(set.to_string(), |(_, new)| new.clone());
        for (name, members) in &p.node_sets {
            node_sets.entry(renamed(name)).or_default().extend(members.iter().map(|n| n + node_offset[k]));
        }
        for (name, faces) in &p.face_sets {
            face_sets
                .entry(renamed(name))
                .or_default()
                .extend(faces.iter().map(|f| ElementFace { element: new_index[k][f.element as usize], face: f.face }));
        }
    }
    for v in node_sets.values_mut() {
        v.sort_unstable();
    }
    for v in face_sets.values_mut() {
        v.sort_unstable();
    }
    VesselMesh {
        nodes,
        hexes,
        regions,
        branch_of,
        sac,
        triads,
        fibres,
        quality,
        layers,
        ends,
        node_sets,
        face_sets,
        branch_names,
    }
}

/// Three straight tubes ([`straight_tube_mesh`] with `config`) joined by [`join_disjoint`]: the
/// first along +z (ends `inlet` and `outlet_1`), the second and third tilted by 35 and -50
/// degrees about the y axis and set 12 and 24 mm apart in y (apart from each other), so that
/// their ends (`outlet_2` to `outlet_5`) are oblique. 3 branches, 6 ends, for the writers'
/// multi-outlet tests.
pub fn multi_outlet_mesh(config: &MeshConfig) -> Result<VesselMesh> {
    let tube = straight_tube_mesh(config)?.mesh;
    let parts = [(0.0f64, 0.0), (35.0, 12.0), (-50.0, 24.0)]
        .iter()
        .map(|&(angle, y)| {
            let rotation = Rotation3::from_axis_angle(&Vector3::y_axis(), angle.to_radians());
            moved(tube.clone(), rotation, Vector3::new(0.0, y, 0.0))
        })
        .collect();
    Ok(join_disjoint(parts))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The joined mesh keeps the invariants of a mesh built by vesselhex.
    #[test]
    fn multi_outlet_mesh_keeps_the_mesh_invariants() {
        let mut c = MeshConfig::default();
        c.lumen.core_elements = 2;
        c.lumen.radial_elements = 2;
        c.lumen.axial_spacing_mm = Some(3.0);
        let one = straight_tube_mesh(&c).unwrap().mesh;
        let m = multi_outlet_mesh(&c).unwrap();
        assert_eq!(m.nodes.len(), 3 * one.nodes.len());
        assert_eq!(m.hexes.len(), 3 * one.hexes.len());
        // regions contiguous in order, each three times the tube's, branches 0, 1, 2 in each
        assert!(m.regions.windows(2).all(|w| w[0] <= w[1]));
        for r in Region::ALL {
            let range = m.region_range(r);
            assert_eq!(range.len(), 3 * one.count(r));
            assert!(m.branch_of[range].windows(2).all(|w| w[0] <= w[1]));
        }
        assert_eq!(m.branch_names.len(), 3);
        let names: Vec<&str> = m.ends.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(names, ["inlet", "outlet_1", "outlet_2", "outlet_3", "outlet_4", "outlet_5"]);
        assert_eq!(m.ends.iter().filter(|e| e.is_inlet).count(), 1);
        for end in &m.ends {
            // each end's sets exist, lie in its plane, and its faces point along its normal
            for set in [sets::lumen_end(&end.name), sets::wall_end(&end.name)] {
                let nodes = &m.node_sets[&set];
                assert!(!nodes.is_empty() && nodes.windows(2).all(|w| w[0] < w[1]), "{set}");
                for &n in nodes {
                    assert!((m.nodes[n as usize] - end.centre).dot(&end.outward_normal).abs() < 1e-9, "{set}");
                }
                for f in &m.face_sets[&set] {
                    let q = crate::geometry::mesh::face_nodes(&m.hexes[f.element as usize], f.face as usize);
                    let a = crate::geometry::mesh::quad_area_vector(q.map(|n| m.nodes[n as usize]));
                    assert!(a.normalize().dot(&end.outward_normal) > 1.0 - 1e-9, "{set}");
                    assert_eq!(m.branch_of[f.element as usize] as usize, end.branch, "{set}");
                }
            }
        }
        // triads still right-handed after the rotations, and e_rad still points out of the axis
        for (e, t) in m.triads.iter().enumerate() {
            assert!((t.e_circ.cross(&t.e_long) - t.e_rad).norm() < 1e-9, "element {e}");
        }
        for s in m.node_sets.values() {
            assert!(s.windows(2).all(|w| w[0] < w[1]));
        }
        for s in m.face_sets.values() {
            assert!(s.windows(2).all(|w| w[0] < w[1]));
        }
    }
}
