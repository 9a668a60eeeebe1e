//! Refinement before or after projection (De Santis et al. 2011, Appendix A.2) on a coarsely
//! triangulated tube, the vessel analogue of the paper's 80-triangle sphere: before projection
//! every new surface node is cast onto the triangles (the facets show), after projection only
//! the coarse nodes are and the new ones follow the smooth shape. Measured against the exact
//! cylinder both ways (mesh nodes to cylinder, cylinder points to the meshed surface) and
//! against the triangles; every quality bar held.

mod common;

use common::{fixture, mesh_cli, temp_dir};
use nalgebra::Point3;
use vesselhex::config::MeshConfig;
use vesselhex::finishing::Additions;
use vesselhex::mesh::{face_nodes, sets, VesselMesh};
use vesselhex::pipeline::mesh_finished;
use vesselhex::quality::Bars;
use vesselhex::report::{lumen_report, wall_report};
use vesselhex::surface::LumenSurface;
use vesselhex::testing::{straight_tube_centerline, straight_tube_surface};

const RADIUS: f64 = 2.0;
const LENGTH: f64 = 20.0;
/// Triangles around the tube: as many as the coarse mesh's lumen-surface nodes around (16), so
/// the coarse nodes land near the triangles' vertices, which lie on the exact cylinder, as the
/// paper's coarse blocks' vertices land on its sphere's.
const AROUND: usize = 16;

/// The tube meshed with refinement `before` x `after`, and what the refinement reported.
fn refined(before: usize, after: usize) -> (VesselMesh, Additions, LumenSurface) {
    let surface = straight_tube_surface(RADIUS, LENGTH, AROUND, 20);
    let mut config = MeshConfig::default();
    config.refinement.before_projection = before;
    config.refinement.after_projection = after;
    let (meshed, additions) =
        mesh_finished(&surface, &straight_tube_centerline(RADIUS, LENGTH), &config, u64::MAX).unwrap();
    (meshed.mesh, additions, LumenSurface::new(&surface).unwrap())
}

/// Mean and max of distances.
fn mean_max(d: &[f64]) -> (f64, f64) {
    (d.iter().sum::<f64>() / d.len() as f64, d.iter().cloned().fold(0.0, f64::max))
}

/// Distances of the lumen-surface nodes from the exact cylinder.
fn nodes_to_cylinder(mesh: &VesselMesh) -> Vec<f64> {
    let nodes = &mesh.node_sets[sets::INTERFACE_NODES];
    nodes.iter().map(|&n| (mesh.nodes[n as usize].coords.xy().norm() - RADIUS).abs()).collect()
}

/// Distances of the lumen-surface nodes from the input triangles.
fn nodes_to_triangles(mesh: &VesselMesh, surface: &LumenSurface) -> Vec<f64> {
    let nodes = &mesh.node_sets[sets::INTERFACE_NODES];
    nodes.iter().map(|&n| surface.closest(&mesh.nodes[n as usize]).distance).collect()
}

/// Distances from points of the exact cylinder (64 around, every 0.25 mm over the middle
/// 16 mm, away from the ends) to the meshed lumen surface (its quads as two triangles each).
fn cylinder_to_mesh(mesh: &VesselMesh) -> Vec<f64> {
    let mut tris = Vec::new();
    for f in &mesh.face_sets[sets::LUMEN_WALL_FACES] {
        let q = face_nodes(&mesh.hexes[f.element as usize], f.face as usize);
        tris.extend([[q[0], q[1], q[2]], [q[0], q[2], q[3]]]);
    }
    let meshed = LumenSurface::from_parts(mesh.nodes.clone(), tris, "meshed".into()).unwrap();
    let points = (0..=64).flat_map(|j| {
        (0..64).map(move |i| {
            let a = std::f64::consts::TAU * i as f64 / 64.0;
            Point3::new(RADIUS * a.cos(), RADIUS * a.sin(), 2.0 + 0.25 * j as f64)
        })
    });
    points.map(|p| meshed.closest(&p).distance).collect()
}

/// Every quality bar, and no inverted element.
fn assert_bars(mesh: &VesselMesh, case: &str) {
    let worst = mesh.quality.iter().map(|q| q.scaled_jacobian).fold(f64::INFINITY, f64::min);
    assert!(worst >= Bars::MIN_SCALED_JACOBIAN, "{case}: worst scaled Jacobian {worst}");
    let wall = wall_report(mesh).all.scaled_jacobian.mean;
    assert!(wall >= Bars::WALL_MEAN_SCALED_JACOBIAN, "{case}: wall mean scaled Jacobian {wall}");
    let skew = lumen_report(mesh).equiangle_skew.mean;
    assert!(skew <= Bars::LUMEN_MEAN_SKEW, "{case}: lumen mean skew {skew}");
}

#[test]
fn before_projection_follows_the_triangles_after_projection_the_smooth_shape() {
    let (coarse, none, _) = refined(1, 1);
    assert!(none.refinement.is_none(), "no refinement asked, none reported");
    let coarse_surface_nodes = coarse.node_sets[sets::INTERFACE_NODES].len();
    let k = 2;
    let (before, before_report, triangles) = refined(k, 1);
    let (after, after_report, _) = refined(1, k);
    let (b, a) = (before_report.refinement.unwrap(), after_report.refinement.unwrap());
    // The same mesh size either way (the paper: 55,296 hexes either way), k^3 times the coarse.
    for (r, mesh) in [(&b, &before), (&a, &after)] {
        assert_eq!(r.elements, coarse.hexes.len() * k * k * k);
        assert_eq!(mesh.hexes.len(), r.elements);
        assert_eq!(r.surface_nodes, mesh.node_sets[sets::INTERFACE_NODES].len());
    }
    // Before: every surface node projected; after: only the coarse mesh's.
    assert_eq!(b.projected_points, b.surface_nodes);
    assert_eq!(a.projected_points, coarse_surface_nodes);
    assert!(a.projected_points < a.surface_nodes);

    let rows = [("coarse", &coarse), ("before", &before), ("after", &after)].map(|(name, mesh)| {
        let to_tri = mean_max(&nodes_to_triangles(mesh, &triangles));
        let to_cyl = mean_max(&nodes_to_cylinder(mesh));
        let from_cyl = mean_max(&cylinder_to_mesh(mesh));
        println!(
            "{name}: {} hexes, {} surface nodes; node->triangles mean {:.2e} max {:.2e} mm; node->cylinder mean \
             {:.2e} max {:.2e} mm; cylinder->mesh mean {:.2e} max {:.2e} mm",
            mesh.hexes.len(),
            mesh.node_sets[sets::INTERFACE_NODES].len(),
            to_tri.0,
            to_tri.1,
            to_cyl.0,
            to_cyl.1,
            from_cyl.0,
            from_cyl.1
        );
        assert_bars(mesh, name);
        (to_tri, to_cyl, from_cyl)
    });
    let [(_, coarse_cyl, _), (before_tri, before_cyl, before_from), (after_tri, after_cyl, after_from)] = rows;
    // Before: on the triangles (to rounding), so the facets show: the new nodes between the
    // coarse ones sit on the flat facets, further from the cylinder than the coarse nodes.
    assert!(before_tri.1 < 1e-9 * RADIUS, "before: a surface node {} mm off the triangles", before_tri.1);
    assert!(before_cyl.0 > 2.0 * coarse_cyl.0, "before: the facets do not show ({before_cyl:?} vs {coarse_cyl:?})");
    // After: the new nodes leave the facets for the smooth shape: off the triangles, about as
    // close to the cylinder as the coarse nodes (the Hermite edge's midpoint is within 1 % of
    // the arc's sagitta), so far closer than before, both ways.
    assert!(after_tri.0 > 10.0 * before_tri.1, "after: the new nodes are on the triangles");
    assert!(after_cyl.0 < 1.25 * coarse_cyl.0, "after: {after_cyl:?} vs coarse {coarse_cyl:?}");
    assert!(
        after_cyl.0 < 0.5 * before_cyl.0,
        "after {after_cyl:?} not closer to the cylinder than before {before_cyl:?}"
    );
    assert!(after_from.0 < before_from.0, "cylinder->mesh: after {after_from:?}, before {before_from:?}");
}

#[test]
fn refinement_counts_in_report_json_and_bars_on_a_curved_vessel() {
    let (stl, csv) = fixture("curved");
    for (key, other) in [("before_projection", "after_projection"), ("after_projection", "before_projection")] {
        let out = temp_dir(&format!("refine-{key}"));
        let case = out.join("case.toml");
        std::fs::write(&case, format!("[refinement]\n{key} = 2\n")).unwrap();
        let r = mesh_cli(&stl, &csv, &out.join("out"), &["--config", case.to_str().unwrap(), "--formats", "vtu"]);
        let refinement = &r["refinement"];
        println!("curved {key} = 2: {refinement}; surface accuracy {}", r["surface_accuracy"]);
        assert_eq!(refinement[key], 2);
        assert_eq!(refinement[other], 1);
        let count = |k: &str| refinement[k].as_u64().unwrap();
        let (surface, projected) = (count("surface_nodes"), count("projected_points"));
        assert_eq!(r["surface_accuracy"]["nodes_measured"].as_u64().unwrap(), surface);
        if key == "before_projection" {
            assert_eq!(projected, surface);
        } else {
            assert!(3 * projected < surface, "{projected} of {surface} projected");
        }
        assert_eq!(r["within_bars"], true, "{key}: {}", r["warnings"]);
        // Determinism: one thread writes the same mesh, byte for byte.
        let args = ["--config", case.to_str().unwrap(), "--formats", "vtu", "--threads", "1"];
        mesh_cli(&stl, &csv, &out.join("one"), &args);
        let vtu = |dir: &str| std::fs::read(out.join(dir).join("mesh.vtu")).unwrap();
        assert!(vtu("out") == vtu("one"), "{key}: mesh.vtu differs with one thread");
        let _ = std::fs::remove_dir_all(&out);
    }
}

/// Refinement beyond the limit (8 splits per direction, both together) or of 0 is refused.
#[test]
fn refinement_out_of_range_is_a_clear_error() {
    let (stl, csv) = fixture("straight");
    let dir = temp_dir("refine-errors");
    for (case, words) in [
        ("[refinement]\nbefore_projection = 0\n", "refinement.before_projection: 0 must be between 1"),
        ("[refinement]\nbefore_projection = 3\nafter_projection = 3\n", "3 x 3 = 9 splits per direction"),
    ] {
        let file = dir.join("case.toml");
        std::fs::write(&file, case).unwrap();
        let out = dir.join("out");
        let args = ["mesh", "--surface", stl.to_str().unwrap(), "--centerlines", csv.to_str().unwrap()];
        let o = common::vesselhex(
            &[&args[..], &["--output", out.to_str().unwrap(), "--quiet", "--config", file.to_str().unwrap()]].concat(),
        );
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && stderr.lines().count() == 1 && stderr.contains(words), "{case}: {stderr}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
