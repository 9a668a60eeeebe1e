//! Tight and eccentric stenoses meshed from the bare surface: generated trees whose narrowing
//! once left a cross-section that "does not close" (rays from the centerline of a fixed reach
//! missed the spared side of the plaque), now meshed on the plane's cut through the surface.

mod common;

use common::temp_dir;
use nalgebra::Point3;
use vesselhex::accuracy::meshed_lumen_surface;
use vesselhex::centerline_extract::ExtractOptions;
use vesselhex::mesh::Region;
use vesselhex::pipeline::{mesh_surface, CenterlineSource};
use vesselhex::progress::Progress;
use vesselhex::synthetic_tree::{write_random_tree, SurfaceFormat};

/// Random trees 31 (a 73 % stenosis whose throat sits at the plaque's side, eccentricity 0.98)
/// and 51 (87 %, eccentricity 0.36), two ends each: both were refused ("the cross-section ...
/// does not close"). Each meshes with both ends, no element inverted, every bar held, and the
/// mesh follows the narrowing: every surface vertex within 1.5 reference radii of the throat
/// lies within 10 % of the reference radius of the meshed lumen surface. The coarse mesh's
/// chords leave about 5 % there (a 16-gon's 2 % round, the rest along the narrowing's curved
/// profile); a section cut short of the plaque's spared side would leave the plaque's offset
/// (tree 31's throat sits 0.98 of the way to the wall).
#[test]
fn tight_and_eccentric_stenoses_mesh_and_follow_the_narrowing() {
    for seed in [31, 51] {
        let dir = temp_dir(&format!("stenosis-{seed}"));
        let written = write_random_tree(seed, &dir, SurfaceFormat::Stl, &mut Progress::new(true, 0)).unwrap();
        let truth = serde_json::to_value(written.tree.manifest("", "")).unwrap();
        let stenosis = &truth["stenoses"][0];
        let number = |v: &serde_json::Value| v.as_f64().unwrap();
        let throat =
            Point3::new(number(&stenosis["centre"][0]), number(&stenosis["centre"][1]), number(&stenosis["centre"][2]));
        let reference = number(&stenosis["reference_radius_mm"]);
        let surface = vesselhex::input::read_surface(&written.surface, vesselhex::units::LengthUnit::Mm).unwrap();
        let vessel = mesh_surface(
            surface.clone(),
            CenterlineSource::Extract(ExtractOptions::default()),
            common::coarse_settings(),
            &mut Progress::new(true, 0),
        )
        .unwrap_or_else(|e| panic!("tree {seed}: {e}"));
        let mesh = &vessel.meshed.mesh;
        assert_eq!(mesh.ends.len(), truth["ends"].as_array().unwrap().len(), "tree {seed}: ends");
        let min_sj = mesh.quality.iter().map(|q| q.scaled_jacobian).fold(f64::INFINITY, f64::min);
        assert!(min_sj >= 0.2, "tree {seed}: min scaled Jacobian {min_sj}");
        let lumen = mesh.region_range(Region::Lumen).count();
        assert!(lumen > 0, "tree {seed}: no lumen elements");
        let meshed = meshed_lumen_surface(mesh).unwrap();
        let near: Vec<&Point3<f64>> =
            surface.vertices.iter().filter(|v| (*v - throat).norm() <= 1.5 * reference).collect();
        assert!(near.len() > 50, "tree {seed}: {} vertices near the throat", near.len());
        let worst = near.iter().map(|v| meshed.closest(v).distance).fold(0.0, f64::max);
        println!("tree {seed}: {} vertices near the throat, farthest {worst:.4} mm from the mesh (reference radius {reference:.3} mm), min SJ {min_sj:.3}", near.len());
        assert!(worst <= 0.1 * reference, "tree {seed}: the surface lies {worst:.3} mm from the mesh at the stenosis");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
