//! The wall over a junction is as thick as its branches' walls, not as the junction's ball:
//! palabos_cerebral_aneurysm's sac holds its bifurcation, a junction of radius 17.4 mm between
//! vessels whose sections next to it have radii of at most 8.6 mm, and its transitions, widened
//! to the junction's radius, once carried a wall up to twice the branches'.

mod common;

use vesselhex::accuracy::meshed_lumen_surface;
use vesselhex::centerline_extract::ExtractOptions;
use vesselhex::mesh::sets;
use vesselhex::pipeline::{mesh_surface, CenterlineSource};
use vesselhex::progress::Progress;
use vesselhex::units::LengthUnit;

/// Every outer wall node over the sac junction lies within the wall thickness of the widest
/// branch meeting there (at its ordinary section next to the junction: thickness_ratio times
/// its radius, with a quarter more for growth directions that lean) of the meshed lumen
/// surface; the sac's own ball is twice as wide.
#[test]
fn a_sac_junctions_wall_is_as_thick_as_its_branches() {
    let Some(vessels) = common::vessels_dir() else { return };
    let path = vessels.join("palabos_cerebral_aneurysm/aneurysm.stl");
    let surface = vesselhex::input::read_surface(&path, LengthUnit::M).unwrap();
    let settings = common::coarse_settings();
    let ratio = settings.config.wall.thickness_ratio;
    let vessel = mesh_surface(
        surface,
        CenterlineSource::Extract(ExtractOptions::default()),
        settings,
        &mut Progress::new(true, 0),
    )
    .unwrap();
    let meshed = &vessel.meshed;
    let mesh = &meshed.mesh;
    let sac_junction = (0..mesh.hexes.len())
        .find_map(|e| if mesh.sac[e] { meshed.junction_of[e] } else { None })
        .expect("the sac holds a junction");
    let junction = &meshed.junctions[sac_junction];
    // Each branch's wall where it enters its transition: its ordinary section next to the junction.
    let widest_branch = junction
        .slots
        .iter()
        .map(|slot| {
            let ordinary: Vec<f64> = meshed.projected[slot.branch]
                .sections
                .iter()
                .filter(|x| !x.in_junction)
                .map(|x| x.station.radius)
                .collect();
            if slot.is_parent {
                ordinary[ordinary.len() - 1]
            } else {
                ordinary[0]
            }
        })
        .fold(0.0, f64::max);
    assert!(junction.radius > 2.0 * widest_branch, "junction radius {} vs branches {widest_branch}", junction.radius);
    let lumen = meshed_lumen_surface(mesh).unwrap();
    let outer: std::collections::HashSet<u32> = mesh.node_sets[sets::OUTER_WALL_NODES].iter().copied().collect();
    let mut sac_outer: Vec<u32> = (0..mesh.hexes.len())
        .filter(|&e| mesh.sac[e] && mesh.regions[e].is_wall())
        .flat_map(|e| mesh.hexes[e].iter().copied().filter(|n| outer.contains(n)).collect::<Vec<_>>())
        .collect();
    sac_outer.sort_unstable();
    sac_outer.dedup();
    assert!(sac_outer.len() > 50, "{} outer nodes over the sac", sac_outer.len());
    let thickest = sac_outer.iter().map(|&n| lumen.closest(&mesh.nodes[n as usize]).distance).fold(0.0, f64::max);
    println!(
        "sac junction radius {:.2} mm, widest branch {widest_branch:.2} mm, thickest wall over the sac {thickest:.3} mm",
        junction.radius
    );
    assert!(thickest <= 1.25 * ratio * widest_branch, "a wall {thickest:.3} mm thick over the sac");
}
