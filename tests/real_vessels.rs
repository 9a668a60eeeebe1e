//! The real unbranched vessels of `../shared/vessels` (folder from `VESSELHEX_VESSELS`), at the
//! coarse and medium presets: quality bars, surface fidelity, triads.

mod common;

use indexmap::IndexMap;
use nalgebra::{Matrix3, Point3, Vector3};
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::input::{read_centerlines, read_surface, CenterlinePolyline, Centerlines, TriangleSurface};
use vesselhex::mesh::Region;
use vesselhex::pipeline::{mesh_vessel, Meshed};
use vesselhex::progress::Progress;
use vesselhex::surface::LumenSurface;
use vesselhex::units::LengthUnit;

/// A centerline for a nearly straight vessel without one (vmtk_abdominal_aorta_segment): the
/// principal axis of the vertices, sliced every `step` mm; each slice's vertex centroid is a
/// centerline point and its distance to the surface the inscribed radius.
fn derive_straight_centerline(surface: &TriangleSurface, step: f64) -> Centerlines {
    let n = surface.vertices.len() as f64;
    let mean = surface.vertices.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let cov = surface.vertices.iter().fold(Matrix3::zeros(), |a, p| {
        let d = p.coords - mean;
        a + d * d.transpose()
    }) / n;
    let eig = cov.symmetric_eigen();
    let k = eig.eigenvalues.imax();
    let axis: Vector3<f64> = eig.eigenvectors.column(k).into();
    let t: Vec<f64> = surface.vertices.iter().map(|p| (p.coords - mean).dot(&axis)).collect();
    let (lo, hi) = t.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    let bins = ((hi - lo) / step).ceil() as usize;
    let mut sums = vec![(Vector3::zeros(), 0usize); bins];
    for (p, &x) in surface.vertices.iter().zip(&t) {
        let b = (((x - lo) / step) as usize).min(bins - 1);
        sums[b].0 += p.coords;
        sums[b].1 += 1;
    }
    let index = LumenSurface::new(surface).unwrap();
    let mut points = vec![];
    let mut radii = vec![];
    for (sum, count) in sums {
        if count >= 20 {
            let c = Point3::from(sum / count as f64);
            radii.push(index.closest(&c).distance);
            points.push(c);
        }
    }
    Centerlines {
        polylines: vec![CenterlinePolyline { points, radii: Some(radii), normals: None, cell_tags: IndexMap::new() }],
        source: "derived centerline".into(),
    }
}

fn check(name: &str, surface: &TriangleSurface, centerlines: &Centerlines) {
    for preset in [Preset::Coarse, Preset::Medium] {
        let m: Meshed = mesh_vessel(surface, centerlines, &MeshConfig::preset(preset), &mut Progress::new(true, 9))
            .unwrap_or_else(|e| panic!("{name} {preset:?}: {e}"));
        let mesh = &m.mesh;
        let lumen = vesselhex::report::lumen_report(mesh);
        let wall = vesselhex::report::wall_report(mesh);
        let min_sj = lumen.scaled_jacobian.min.min(wall.all.scaled_jacobian.min);
        println!(
            "{name} {preset:?}: {} lumen + {} wall hexes; SJ min {min_sj:.3}, wall mean {:.3}; lumen skew mean {:.3}; \
             node->surface mean {:.2e} max {:.2e} um; surface->mesh mean {:.1} max {:.1} um",
            lumen.elements,
            wall.all.elements,
            wall.all.scaled_jacobian.mean,
            lumen.equiangle_skew.mean,
            m.accuracy.node_to_surface_um.mean,
            m.accuracy.node_to_surface_um.max,
            m.accuracy.surface_to_mesh_um.mean,
            m.accuracy.surface_to_mesh_um.max
        );
        assert!(min_sj >= 0.3, "{name} {preset:?}: min SJ {min_sj}");
        assert!(wall.all.scaled_jacobian.mean >= 0.9, "{name} {preset:?}");
        assert!(lumen.equiangle_skew.mean <= 0.3, "{name} {preset:?}");
        assert!(m.accuracy.node_to_surface_um.max < 0.01, "{name} {preset:?}");
        assert!(m.accuracy.vertices_measured > 100);
        // triads: orthonormal, right-handed, e_rad away from the centerline
        let branch = &m.tree.branches[0];
        for e in mesh.region_range(Region::Intima).step_by(7) {
            let t = &mesh.triads[e];
            assert!((t.e_circ.cross(&t.e_long) - t.e_rad).norm() < 1e-9);
            let c = Point3::from(mesh.corners(e).iter().fold(Vector3::zeros(), |a, p| a + p.coords) / 8.0);
            let nearest = branch.samples.iter().min_by(|a, b| (a.point - c).norm().total_cmp(&(b.point - c).norm())).unwrap();
            assert!(t.e_rad.dot(&(c - nearest.point)) > 0.0, "{name}: e_rad inward at element {e}");
        }
    }
}

#[test]
fn aneurisk_c0092_internal_carotid_with_its_centerline() {
    let Some(dir) = common::vessels_dir() else { return };
    let d = dir.join("aneurisk_C0092_ica_segment");
    let surface = read_surface(&d.join("C0092_clip1_0.vtp"), LengthUnit::Mm).unwrap();
    let cl = read_centerlines(&d.join("C0092_clip1_mesh1_0.95_ratio_centerline.vtp"), LengthUnit::Mm).unwrap();
    check("aneurisk_C0092_ica_segment", &surface, &cl);
}

#[test]
fn vmtk_abdominal_aorta_segment_with_a_derived_centerline() {
    let Some(dir) = common::vessels_dir() else { return };
    let surface =
        read_surface(&dir.join("vmtk_abdominal_aorta_segment/aorta-surface-segment-2.stl"), LengthUnit::Mm).unwrap();
    let cl = derive_straight_centerline(&surface, 2.0);
    check("vmtk_abdominal_aorta_segment", &surface, &cl);
}
