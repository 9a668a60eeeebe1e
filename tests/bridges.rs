//! Bridges that bow out of the straight line between their junctions or bend within it, meshed
//! from the bare surface: a branch between two junctions too close for ordinary sections is
//! swept straight from fold to fold; where that sweep misses the wall, on whichever folds least
//! of the same carried onto the branch's own centerline and the two folds carried along it and
//! blended. A branch with too little room between its two transitions for ordinary sections is
//! a bridge.

mod common;

use vesselhex::pipeline::Meshed;
use vesselhex::projection::{BranchEnd, ProjectedBranch};

/// The meshed branches swept from fold to fold, with no ordinary section.
fn bridges(meshed: &Meshed) -> Vec<&ProjectedBranch> {
    meshed
        .projected
        .iter()
        .filter(|p| matches!((&p.start, &p.end), (BranchEnd::Fold(_), BranchEnd::Fold(_))) && p.s_start == p.s_end)
        .collect()
}

/// Random tree 32 (9 ends): its bridge between two junctions (54 mm of centerline between
/// centres 42 mm apart, radii 9.2 and 4.3 mm) bows out of the chord between them, and its
/// straight sweep had 12 of 16 rays outside the wall 60 % of the way along; the tree was refused.
/// It meshes with every end, every bar held, and a bridge of several sections whose every
/// lumen node lies inside or on the lumen surface.
#[test]
fn a_bridge_bowing_out_of_its_chord_follows_its_centerline() {
    let tree = common::mesh_random_tree(32, "bridge");
    tree.assert_every_end_and_min_sj();
    let (seed, meshed) = (tree.seed, &tree.vessel.meshed);
    let bridges = bridges(meshed);
    assert!(!bridges.is_empty(), "tree {seed}: no bridge");
    let lumen = vesselhex::surface::LumenSurface::new(&tree.surface).unwrap();
    for bridge in bridges {
        assert!(bridge.sections.len() >= 4, "tree {seed}: a bridge of {} sections", bridge.sections.len());
        for section in &bridge.sections {
            for p in section.core.iter().chain(&section.surface) {
                let inside = lumen.winding_number(p).abs() >= 0.5 || lumen.closest(p).distance <= 1e-6;
                assert!(inside, "tree {seed}: a bridge node at {p:?} lies outside the lumen");
            }
        }
    }
    let _ = std::fs::remove_dir_all(&tree.dir);
}

/// Random tree 23 (12 ends): a branch 21 mm long between two junctions turns 116 degrees in its
/// middle (a hairpin on a radius of curvature of about 1.5 vessel radii), so no section near
/// either junction is followed by a clear run and the branch is a bridge. Its straight sweep
/// misses the wall, and the sweep moved onto the centerline lays its middle sections along the
/// bend: the tree was refused, its lumen inverted there. Each fold carried along the
/// centerline in the branch's frames and blended from one to the other keeps the sections
/// across the vessel: the tree meshes with every end and every bar held.
#[test]
fn a_bridge_around_a_hairpin_carries_its_folds_along_its_centerline() {
    let tree = common::mesh_random_tree(23, "bridge");
    tree.assert_every_end_and_min_sj();
    let (seed, mesh) = (tree.seed, &tree.vessel.meshed.mesh);
    let wall_mean = vesselhex::report::wall_report(mesh).all.scaled_jacobian.mean;
    assert!(wall_mean >= 0.85, "tree {seed}: wall mean scaled Jacobian {wall_mean}");
    let skew = vesselhex::report::lumen_report(mesh).equiangle_skew.mean;
    assert!(skew <= 0.35, "tree {seed}: lumen mean equi-angle skew {skew}");
    assert!(!bridges(&tree.vessel.meshed).is_empty(), "tree {seed}: no bridge");
    let _ = std::fs::remove_dir_all(&tree.dir);
}

/// Random tree 66 (4 capped ends): branch_1 runs 8.4 mm between two junctions, their
/// transitions leaving 1.3 mm between them for a vessel of radius 2.4 mm. That was more room
/// than made a bridge (a quarter of the two end radii) and less than ordinary sections were
/// meshed in (half of them): neither, the tree was refused as "too short to mesh". One least
/// stretch holds for both: the branch is a bridge, and the tree meshes with every end.
#[test]
fn a_branch_too_short_for_ordinary_sections_between_two_transitions_is_a_bridge() {
    let tree = common::mesh_random_tree(66, "bridge");
    tree.assert_every_end_and_min_sj();
    let seed = tree.seed;
    let bridges = bridges(&tree.vessel.meshed);
    let tree_branches = &tree.vessel.meshed.tree.branches;
    assert!(
        bridges.iter().any(|b| tree_branches[b.branch].name == "branch_1"),
        "tree {seed}: branch_1 is not a bridge"
    );
    let _ = std::fs::remove_dir_all(&tree.dir);
}
