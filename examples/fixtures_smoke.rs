//! Meshes every synthetic fixture in memory (no file reading) and prints its figures.
use indexmap::IndexMap;
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::input::{CenterlinePolyline, Centerlines, TriangleSurface};
use vesselhex::progress::Progress;
use vesselhex::synthetic::{all_fixtures, centerline_abscissae, triangulate};

fn main() -> vesselhex::Result<()> {
    for v in all_fixtures() {
        let res = v.resolution();
        let (vertices, triangles) = triangulate(v.as_ref(), res.circumferential, res.axial_step_mm);
        // f32 like the STL
        let vertices = vertices.iter().map(|p| p.map(|c| c as f32 as f64)).collect();
        let surface = TriangleSurface { vertices, triangles, triangle_tags: None, source: v.name().into() };
        let s = centerline_abscissae(v.as_ref());
        let cl = Centerlines {
            polylines: vec![CenterlinePolyline {
                points: s.iter().map(|&s| v.point(s)).collect(),
                radii: Some(s.iter().map(|&s| v.radius(s)).collect()),
                normals: None,
                cell_tags: IndexMap::new(),
            }],
            source: "cl".into(),
        };
        for p in [Preset::Coarse, Preset::Medium] {
            let mut pr = Progress::new(true, 9);
            match vesselhex::pipeline::mesh_vessel(&surface, &cl, &MeshConfig::preset(p), &mut pr) {
                Ok(m) => {
                    let l = vesselhex::report::lumen_report(&m.mesh);
                    let w = vesselhex::report::wall_report(&m.mesh);
                    let exact = m.mesh.node_sets["lumen_wall_interface"].iter().map(|&n| v.distance_to_wall(&m.mesh.nodes[n as usize]).abs()).fold(0.0, f64::max);
                    println!(
                        "{:9} {p:?}: lumen {:6} wall {:6} | SJ lumen min {:.3} mean {:.3} | wall min {:.3} mean {:.3} | skew lumen mean {:.3} max {:.3} | node->surf max {:.2e} um | surf->mesh mean {:.1} max {:.1} um | exact max {:.1} um | s {:.2}..{:.2} closed {} {}",
                        v.name(), l.elements, w.all.elements, l.scaled_jacobian.min, l.scaled_jacobian.mean, w.all.scaled_jacobian.min, w.all.scaled_jacobian.mean,
                        l.equiangle_skew.mean, l.equiangle_skew.max, m.accuracy.node_to_surface_um.max, m.accuracy.surface_to_mesh_um.mean, m.accuracy.surface_to_mesh_um.max, exact*1e3,
                        m.projected[0].s_start, m.projected[0].s_end, m.projected[0].inlet_closed, m.projected[0].outlet_closed
                    );
                }
                Err(e) => println!("{:9} {p:?}: ERROR {e}", v.name()),
            }
        }
    }
    Ok(())
}
