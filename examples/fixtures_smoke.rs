//! Meshes every synthetic fixture in memory (no file reading) at the coarse and medium presets
//! and prints its figures: a quick look while tuning parameters.
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::progress::Progress;
use vesselhex::synthetic::all_fixtures;

fn main() -> vesselhex::Result<()> {
    for v in all_fixtures() {
        let (surface, cl) = vesselhex::testing::fixture_inputs(v.name()).expect("fixture");
        for p in [Preset::Coarse, Preset::Medium] {
            match vesselhex::pipeline::mesh_vessel(&surface, &cl, &MeshConfig::preset(p), &mut Progress::new(true, 9)) {
                Ok(m) => {
                    let l = vesselhex::report::lumen_report(&m.mesh);
                    let w = vesselhex::report::wall_report(&m.mesh);
                    println!(
                        "{:9} {p:?}: lumen {:6} wall {:6} | SJ lumen min {:.3} mean {:.3} | wall min {:.3} mean {:.3} | \
                         lumen skew mean {:.3} | node->surface max {:.1e} um | surface->mesh mean {:.1} max {:.1} um",
                        v.name(),
                        l.elements,
                        w.all.elements,
                        l.scaled_jacobian.min,
                        l.scaled_jacobian.mean,
                        w.all.scaled_jacobian.min,
                        w.all.scaled_jacobian.mean,
                        l.equiangle_skew.mean,
                        m.accuracy.node_to_surface_um.max,
                        m.accuracy.surface_to_mesh_um.mean,
                        m.accuracy.surface_to_mesh_um.max
                    );
                }
                Err(e) => println!("{:9} {p:?}: ERROR {e}", v.name()),
            }
        }
    }
    Ok(())
}
