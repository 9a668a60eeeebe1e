//! Prints the figures of an in-memory straight tube at each preset.
use vesselhex::config::{MeshConfig, Preset};

fn main() -> vesselhex::Result<()> {
    for p in [Preset::Coarse, Preset::Medium, Preset::Fine] {
        let m = vesselhex::testing::straight_tube_mesh(&MeshConfig::preset(p))?;
        let l = vesselhex::report::lumen_report(&m.mesh);
        let w = vesselhex::report::wall_report(&m.mesh);
        println!(
            "{p:?}: lumen {} wall {} | lumen SJ {:?} skew {:?} | wall SJ {:?} | {:?}",
            l.elements, w.all.elements, l.scaled_jacobian, l.equiangle_skew, w.all.scaled_jacobian, m.accuracy
        );
    }
    Ok(())
}
