//! The real unbranched vessels of `../shared/vessels` (folder from `VESSELHEX_VESSELS`), at the
//! coarse and medium presets: quality bars, surface fidelity, triads.

mod common;

use nalgebra::{Point3, Vector3};
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::input::{read_centerlines, read_surface, Centerlines, TriangleSurface};
use vesselhex::mesh::Region;
use vesselhex::pipeline::{mesh_vessel, Meshed};
use vesselhex::progress::Progress;
use vesselhex::units::LengthUnit;

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
            let nearest =
                branch.samples.iter().min_by(|a, b| (a.point - c).norm().total_cmp(&(b.point - c).norm())).unwrap();
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
    let cl = common::derive_straight_centerline(&surface, 2.0);
    check("vmtk_abdominal_aorta_segment", &surface, &cl);
}
