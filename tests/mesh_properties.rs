//! Properties of the meshes of the synthetic fixtures, checked against the analytic shapes:
//! quality bars, surface fidelity, triads and fibres, conformity of the lumen-wall interface,
//! element counts, and the end sections staying off the caps.

mod common;

use nalgebra::Point3;
use std::collections::HashMap;
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::input::{read_centerlines, read_surface};
use vesselhex::mesh::{face_nodes, sets, Region, VesselMesh};
use vesselhex::pipeline::{mesh_vessel, Meshed};
use vesselhex::progress::Progress;
use vesselhex::surface::LumenSurface;
use vesselhex::synthetic::{fixture_by_name, AnalyticVessel};
use vesselhex::units::LengthUnit;

const FIXTURES: [&str; 5] = ["straight", "curved", "tapered", "helical", "aaa"];

fn mesh_fixture(name: &str, preset: Preset) -> (Meshed, LumenSurface, Box<dyn AnalyticVessel>) {
    let (stl, csv) = common::fixture(name);
    let surface = read_surface(&stl, LengthUnit::Mm).unwrap();
    let centerlines = read_centerlines(&csv, LengthUnit::Mm).unwrap();
    let meshed = mesh_vessel(&surface, &centerlines, &MeshConfig::preset(preset), &mut Progress::new(true, 9))
        .unwrap_or_else(|e| panic!("{name} {preset:?}: {e}"));
    (meshed, LumenSurface::new(&surface).unwrap(), fixture_by_name(name).unwrap())
}

fn centroid(mesh: &VesselMesh, e: usize) -> Point3<f64> {
    let c = mesh.corners(e);
    Point3::from(c.iter().fold(nalgebra::Vector3::zeros(), |a, p| a + p.coords) / 8.0)
}

#[test]
fn quality_and_fidelity_bars_hold_on_every_fixture() {
    for name in FIXTURES {
        for preset in [Preset::Coarse, Preset::Medium] {
            let (m, surface, shape) = mesh_fixture(name, preset);
            let mesh = &m.mesh;
            let min_sj = mesh.quality.iter().map(|q| q.scaled_jacobian).fold(f64::INFINITY, f64::min);
            let wall = vesselhex::report::wall_report(mesh);
            let lumen = vesselhex::report::lumen_report(mesh);
            println!(
                "{name} {preset:?}: {} lumen + {} wall hexes, SJ min {min_sj:.3}, wall mean {:.3}, lumen skew mean {:.3}, node->surface max {:.2e} um",
                lumen.elements, wall.all.elements, wall.all.scaled_jacobian.mean, lumen.equiangle_skew.mean,
                m.accuracy.node_to_surface_um.max
            );
            assert!(min_sj >= 0.3, "{name} {preset:?}: min scaled Jacobian {min_sj}");
            assert!(
                wall.all.scaled_jacobian.mean >= 0.9,
                "{name} {preset:?}: wall mean SJ {}",
                wall.all.scaled_jacobian.mean
            );
            assert!(lumen.equiangle_skew.mean <= 0.3, "{name} {preset:?}: lumen skew {}", lumen.equiangle_skew.mean);
            // Every lumen-surface node on the input triangles (exact point-triangle distance)...
            assert!(m.accuracy.node_to_surface_um.max < 0.01, "{name}: {:?}", m.accuracy);
            // ... checked independently of the report, and against the analytic shape within the
            // triangulation's own chordal error.
            let res = shape.resolution();
            let tol = vesselhex::synthetic::chordal_tolerance(shape.as_ref(), res.circumferential, res.axial_step_mm);
            for &n in &mesh.node_sets[sets::INTERFACE_NODES] {
                let p = mesh.nodes[n as usize];
                assert!(surface.closest(&p).distance < 1e-5);
                let d = shape.distance_to_wall(&p).abs();
                assert!(d <= tol, "{name}: node {n} is {d} mm off the analytic wall (tolerance {tol})");
            }
        }
    }
}

#[test]
fn triads_are_orthonormal_right_handed_outward_and_fibres_at_beta() {
    for name in FIXTURES {
        let (m, _, shape) = mesh_fixture(name, Preset::Coarse);
        let mesh = &m.mesh;
        for e in mesh.wall_range() {
            let t = &mesh.triads[e];
            for v in [t.e_circ, t.e_long, t.e_rad] {
                assert!((v.norm() - 1.0).abs() < 1e-9);
            }
            assert!(t.e_circ.dot(&t.e_long).abs() < 1e-9 && t.e_long.dot(&t.e_rad).abs() < 1e-9);
            assert!(t.e_circ.dot(&t.e_rad).abs() < 1e-9);
            assert!((t.e_circ.cross(&t.e_long) - t.e_rad).norm() < 1e-9, "right-handed");
            let c = centroid(mesh, e);
            let s = shape.closest_abscissa(&c);
            let axis = shape.point(s);
            assert!(t.e_rad.dot(&(c - axis)) > 0.0, "{name}: e_rad of element {e} points inward");
            assert!(t.e_long.dot(&shape.tangent(s)) > 0.0, "{name}: e_long of element {e} runs against the flow");
            let beta = mesh.layers.iter().find(|l| l.region == mesh.regions[e]).unwrap().fibre_angle_deg.to_radians();
            for (k, f) in mesh.fibres[e].iter().enumerate() {
                let sign = if k == 0 { 1.0 } else { -1.0 };
                assert!((f.norm() - 1.0).abs() < 1e-12);
                assert!(f.dot(&t.e_rad).abs() < 1e-12, "fibre in the circ-long plane");
                assert!((f.dot(&t.e_circ) - beta.cos()).abs() < 1e-12);
                assert!((f.dot(&t.e_long) - sign * beta.sin()).abs() < 1e-12);
            }
        }
        for e in mesh.lumen_range() {
            assert_eq!(mesh.fibres[e], [nalgebra::Vector3::zeros(); 2]);
        }
    }
}

#[test]
fn interface_is_conformal_and_counts_follow_the_topology() {
    for name in FIXTURES {
        let config = MeshConfig::preset(Preset::Coarse);
        let (m, _, _) = mesh_fixture(name, Preset::Coarse);
        let mesh = &m.mesh;
        // Each wall face on the lumen is a lumen face on the wall: same four nodes, reversed
        // winding (both outward from their own element), one to one.
        let key = |q: [u32; 4]| {
            let mut k = q;
            k.sort_unstable();
            k
        };
        let lumen_faces: HashMap<[u32; 4], [u32; 4]> = mesh.face_sets[sets::LUMEN_WALL_FACES]
            .iter()
            .map(|f| {
                let q = face_nodes(&mesh.hexes[f.element as usize], f.face as usize);
                (key(q), q)
            })
            .collect();
        let wall_faces = &mesh.face_sets[sets::WALL_LUMEN_FACES];
        assert_eq!(lumen_faces.len(), wall_faces.len());
        for f in wall_faces {
            assert!(mesh.regions[f.element as usize] == Region::Intima);
            let q = face_nodes(&mesh.hexes[f.element as usize], f.face as usize);
            let l = lumen_faces.get(&key(q)).unwrap_or_else(|| panic!("{name}: wall face {f:?} has no lumen twin"));
            let la = vesselhex::mesh::quad_area_vector(l.map(|n| mesh.nodes[n as usize]));
            let wa = vesselhex::mesh::quad_area_vector(q.map(|n| mesh.nodes[n as usize]));
            assert!(la.dot(&wa) < 0.0, "twins face each other");
        }
        // The interface node set is exactly the nodes shared by lumen and wall elements.
        let lumen_nodes = mesh.nodes_of(mesh.lumen_range());
        let wall_nodes = mesh.nodes_of(mesh.wall_range());
        let shared: Vec<u32> = lumen_nodes.iter().filter(|n| wall_nodes.binary_search(n).is_ok()).cloned().collect();
        assert_eq!(shared, mesh.node_sets[sets::INTERFACE_NODES]);
        // Counts: per station interval N^2 core + 4N R lateral lumen hexes, 4N M wall hexes.
        let n = config.lumen.core_elements;
        let r = config.lumen.radial_elements;
        let mw: usize = config.wall.layers().iter().map(|l| l.radial_elements).sum();
        let intervals = m.projected[0].sections.len() - 1;
        assert_eq!(mesh.count(Region::Lumen), intervals * (n * n + 4 * n * r));
        assert_eq!(mesh.wall_range().len(), intervals * 4 * n * mw);
        for layer in config.wall.layers() {
            assert_eq!(mesh.count(layer.region), intervals * 4 * n * layer.radial_elements);
        }
        assert_eq!(mesh.node_sets[sets::INTERFACE_NODES].len(), (intervals + 1) * 4 * n);
        // End sets: inlet faces all upstream, at the first station.
        assert_eq!(mesh.face_sets["lumen_inlet"].len(), n * n + 4 * n * r);
        assert_eq!(mesh.face_sets["wall_outlet"].len(), 4 * n * mw);
        assert!(mesh.quality.iter().all(|q| q.scaled_jacobian > 0.0));
    }
}

#[test]
fn capped_ends_are_avoided() {
    // tapered has flat caps, aaa hemispherical domes: no lumen node may land on a cap.
    for name in ["tapered", "aaa"] {
        let (m, surface, shape) = mesh_fixture(name, Preset::Coarse);
        let mesh = &m.mesh;
        let len = shape.length();
        for &n in &mesh.node_sets[sets::INTERFACE_NODES] {
            let p = mesh.nodes[n as usize];
            let s = shape.closest_abscissa(&p);
            assert!(s > 0.0 && s < len, "{name}: node {n} beyond the tube part (s = {s})");
            // the triangle it lies on belongs to the tube, not to a cap
            let tri = surface.triangles[surface.closest(&p).triangle as usize];
            let c = Point3::from(
                tri.iter().fold(nalgebra::Vector3::zeros(), |a, &v| a + surface.vertices[v as usize].coords) / 3.0,
            );
            assert!((c - shape.point(0.0)).dot(&shape.tangent(0.0)) > 0.0, "{name}: node {n} on the inlet cap");
            assert!((c - shape.point(len)).dot(&shape.tangent(len)) < 0.0, "{name}: node {n} on the outlet cap");
        }
        assert!(m.projected[0].inlet_closed && m.projected[0].outlet_closed, "{name}: ends detected as closed");
    }
}
