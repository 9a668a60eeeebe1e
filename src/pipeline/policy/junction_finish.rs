//! How a branched vessel's junctions are finished: the volume is built with each finish of a
//! round (how the junction optimisation may move the lumen's nodes, and how the junction's wall
//! grows), each judged on its junctions' elements and its wall. The best finish is kept, with
//! each junction's own nodes taken from the finish best for that junction (see [`compose`]); a
//! round after the first is built only while no such mesh meets the bars, and a round after the
//! second only while no junction's lumen is folded in every finish (see `UNFOLDING_ROUNDS`).

use crate::data::config::WallGrowth;
use crate::geometry::mesh::VesselMesh;
use crate::stages::volume::{
    build_volume, JunctionOptimisation, JunctionVariant, JunctionWall, VolumeInputs, QUALITY_BAR_SJ, WALL_MEAN_BAR_SJ,
};
use rayon::prelude::*;

/// A volume built with junction finishes: the mesh, the junction of each element, each
/// junction's finish, each element's validity (infinite for a lumen element outside every
/// junction: the same in every finish) and the figures.
#[derive(Clone)]
struct FinishedVolume {
    mesh: VesselMesh,
    junction_of: Vec<Option<usize>>,
    variants: Vec<JunctionVariant>,
    validity: Vec<f64>,
    quality: FinishQuality,
}

/// What a branched vessel's finish is judged by: its worst junction element, its worst junction
/// wall element and its wall's mean scaled Jacobian.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FinishQuality {
    worst: f64,
    worst_wall: f64,
    wall_mean: f64,
}

impl FinishQuality {
    /// A whole mesh's figures (its quality annotated).
    pub(crate) fn of_mesh(mesh: &VesselMesh) -> FinishQuality {
        let validity: Vec<f64> = mesh
            .quality
            .iter()
            .map(|q| crate::geometry::quality::validity_from(q.scaled_jacobian, q.face_pyramid))
            .collect();
        FinishQuality::of(mesh, &validity, |_| true)
    }

    /// The figures from each element's validity (its scaled Jacobian while its face pyramids are
    /// positive, see [`crate::geometry::quality::validity`]: a finish whose wall has a cell that checkMesh
    /// fails loses as one with an inverted cell would): the worst of the elements `judged`, the
    /// worst of those in the wall, the mean over the wall (summed in element order, whatever the
    /// thread count).
    fn of(mesh: &VesselMesh, validity: &[f64], judged: impl Fn(usize) -> bool) -> FinishQuality {
        let judged = (0..validity.len()).filter(|&e| judged(e));
        FinishQuality::over(mesh, validity, judged, mesh.wall_range(), 0.0)
    }

    /// The figures of some elements alone (one junction's): their worst, the worst of those in
    /// the wall, and the mean over those in the wall (1 when none is).
    fn of_elements(mesh: &VesselMesh, validity: &[f64], elements: &[usize]) -> FinishQuality {
        let in_wall = elements.iter().copied().filter(|&e| mesh.regions[e].is_wall());
        FinishQuality::over(mesh, validity, elements.iter().copied(), in_wall, 1.0)
    }

    /// The worst validity of the elements `judged`, the worst of those in the wall, and the mean
    /// of the `averaged` ones, each floored at -1 (summed in the order given; `empty` when there
    /// are none).
    fn over(
        mesh: &VesselMesh,
        validity: &[f64],
        judged: impl Iterator<Item = usize> + Clone,
        averaged: impl Iterator<Item = usize> + Clone,
        empty: f64,
    ) -> FinishQuality {
        let worst = |in_wall: bool| {
            judged
                .clone()
                .filter(|&e| !in_wall || mesh.regions[e].is_wall())
                .map(|e| validity[e])
                .fold(f64::INFINITY, f64::min)
        };
        let count = averaged.clone().count();
        let wall_mean =
            if count == 0 { empty } else { averaged.map(|e| validity[e].max(-1.0)).sum::<f64>() / count as f64 };
        FinishQuality { worst: worst(false), worst_wall: worst(true), wall_mean }
    }

    /// The bars first (a finish meeting them beats one that does not, however much
    /// better the other's worst element: what the user is promised), then the worst junction
    /// element, the worst junction wall element and the wall mean. On every vessel measured
    /// (the real ones, the arch from either centerlines, the sweep) the finish kept is the one
    /// the worst elements alone would pick; the bars decide where a finish with a slightly
    /// better worst element has its wall mean below 0.85.
    fn key(&self) -> [f64; 6] {
        [
            self.worst.min(QUALITY_BAR_SJ),
            self.worst_wall.min(QUALITY_BAR_SJ),
            self.wall_mean.min(WALL_MEAN_BAR_SJ),
            self.worst,
            self.worst_wall,
            self.wall_mean,
        ]
    }

    pub(crate) fn meets_bars(&self) -> bool {
        self.worst >= QUALITY_BAR_SJ && self.wall_mean >= WALL_MEAN_BAR_SJ
    }

    /// Strictly better (so the first of equals is kept).
    pub(crate) fn better_than(&self, other: &FinishQuality) -> bool {
        self.key().partial_cmp(&other.key()) == Some(std::cmp::Ordering::Greater)
    }
}

/// The lumen optimisations of each round, in the order tried (the first of equals is kept).
/// A vessel without junctions has one finish. Otherwise:
/// 1. as projected, the transitions' inner nodes moving, and their surface nodes sliding on
///    the triangles too: that frees the lumen where the inner nodes alone cannot (a small
///    branch's funnel: the synthetic Y at 45 degrees and 4:1 goes from 0.121 to 0.205), but in
///    an acute crotch it can cost the wall more than it gives the lumen;
/// 2. the same on the transitions' surface quads smoothed first: the wall's mean rises
///    (gmsh_aortic_arch at coarse: 0.80-0.83 after round 1, 0.870 with this one, within the
///    bars where all three rounds were needed, and all three merged centres for the arch in
///    cm), but the worst element can fall (the synthetic Y at 90 degrees and 1:1, within the
///    bars either way: 0.50 -> 0.23), so a finish as projected that meets the bars is kept;
/// 3. the same again with the slower pattern search (the synthetic Y at 30 degrees and 4:1:
///    0.190 -> 0.293; it can also lose, hence both are kept in the running);
/// 4. with the pages moving as well (their rims sliding), which gives a small branch's fold
///    room where flat pages span the whole spine (the synthetic Y at 60 degrees and 4:1 goes
///    from 0.234 to 0.350). Only then: bent pages reshape the crotch's lumen faces, which
///    inflate unevenly (simvascular_demo_aortoiliac at coarse, whose junction the pattern
///    search already takes past the target: a crotch face's area shrank by 24 % under
///    pressure).
///
/// Every finish has had its poor elements optimised (`build_volume`), so the later rounds are
/// for a vessel still short of a bar, not for a better finish within them: each costs about
/// the time of the first.
fn rounds(has_junctions: bool) -> Vec<Vec<JunctionOptimisation>> {
    let projected = JunctionOptimisation::default();
    if !has_junctions {
        return vec![vec![projected]];
    }
    let first = [projected, JunctionOptimisation { slide_surface_nodes: true, ..projected }];
    let smoothed = first.map(|o| JunctionOptimisation { smooth_surface: true, ..o });
    let searched = smoothed.map(|o| JunctionOptimisation { pattern_search: true, ..o });
    let pages = [false, true].map(|pattern_search| JunctionOptimisation {
        slide_surface_nodes: true,
        pattern_search,
        move_pages: true,
        smooth_surface: true,
    });
    vec![first.to_vec(), smoothed.to_vec(), searched.to_vec(), pages.to_vec()]
}

/// Rounds built while a junction's lumen is folded in every finish: past them, the rounds
/// refine (pattern search in moves of a fifth and a twentieth of an edge, pages moving), which
/// lifts valid elements past a bar but does not unfold a folded transition. Measured over the
/// cohort at coarse and medium and 23 random trees at coarse (59 vessels, 102 meshes of them,
/// retries included): of the 43 meshes whose lumen was folded in every finish after the first
/// two rounds, none met the bars after all four; two lumens came out valid, at 0.012 and 0.015.
/// A tree whose layout folds is meshed again another way (see [`super`]); while each attempt
/// built every round, random tree 65 at coarse built 42 volumes for its one mesh.
const UNFOLDING_ROUNDS: usize = 2;

/// Whether some junction has a lumen element folded (validity not positive) in every finish
/// built: no composition of them unfolds it.
fn folded_in_every_finish(built: &[FinishedVolume], junctions: usize) -> bool {
    let mut folded_everywhere = vec![true; junctions];
    for finish in built {
        let mut folded = vec![false; junctions];
        for (e, j) in finish.junction_of.iter().enumerate() {
            if let Some(j) = *j {
                if !finish.mesh.regions[e].is_wall() && finish.validity[e] <= 0.0 {
                    folded[j] = true;
                }
            }
        }
        folded_everywhere.iter_mut().zip(&folded).for_each(|(all, &f)| *all &= f);
    }
    !built.is_empty() && folded_everywhere.contains(&true)
}

/// The walls each optimised lumen carries (the wall does not change the optimisation). In an
/// acute crotch the smoothed normals converge and shear the outer wall layers while the rays,
/// aimed past the crotch, do not; on real surfaces the normals mostly give the better wall.
/// The last, along the normals smoothed only as elsewhere, waits in reserve (see
/// [`finish_junctions`]).
fn walls(has_junctions: bool, growth: WallGrowth) -> Vec<JunctionWall> {
    if has_junctions && growth == WallGrowth::Normal {
        vec![JunctionWall::SmoothedNormal, JunctionWall::Ray, JunctionWall::Normal]
    } else {
        vec![JunctionWall::SmoothedNormal]
    }
}

/// Each element's validity in a finish: its junctions' elements and its wall (the rest is the
/// same in every finish, infinite here).
fn validities(mesh: &VesselMesh, junction_of: &[Option<usize>]) -> Vec<f64> {
    (0..mesh.hexes.len())
        .into_par_iter()
        .map(|e| {
            if junction_of[e].is_none() && !mesh.regions[e].is_wall() {
                return f64::INFINITY;
            }
            element_validity(mesh, e)
        })
        .collect()
}

/// The finishes of one round, built side by side; the choice is made in their fixed order, so
/// it does not depend on the thread count.
fn build_round(inputs: &VolumeInputs, round: &[JunctionOptimisation], walls: &[JunctionWall]) -> Vec<FinishedVolume> {
    let built: Vec<_> =
        round.par_iter().map(|&optimisation| (optimisation, build_volume(inputs, optimisation, walls))).collect();
    let junctions = inputs.junctions.len();
    built
        .into_iter()
        .flat_map(|(optimisation, (meshes, junction_of))| {
            meshes.into_iter().zip(walls).map(move |(mesh, &wall)| {
                let validity = validities(&mesh, &junction_of);
                let quality = FinishQuality::of(&mesh, &validity, |e| junction_of[e].is_some());
                let variants = vec![JunctionVariant { wall, optimisation }; junctions];
                FinishedVolume { mesh, junction_of: junction_of.clone(), variants, validity, quality }
            })
        })
        .collect()
}

/// The index of the best finish (see [`FinishQuality::better_than`]), the first of equals.
fn best_of(built: &[FinishedVolume]) -> usize {
    (1..built.len()).fold(0, |best, i| if built[i].quality.better_than(&built[best].quality) { i } else { best })
}

/// For each node, the junction whose elements are the only ones to hold it (`None`: a node of
/// an element outside every junction, or of two junctions' elements).
fn owned_nodes(mesh: &VesselMesh, junction_of: &[Option<usize>]) -> Vec<Option<usize>> {
    // usize::MAX: not yet seen; None: shared.
    let mut owner = vec![Some(usize::MAX); mesh.nodes.len()];
    for (hex, junction) in mesh.hexes.iter().zip(junction_of) {
        for &n in hex {
            let o = &mut owner[n as usize];
            if *o == Some(usize::MAX) {
                *o = *junction;
            } else if o != junction {
                *o = None;
            }
        }
    }
    owner.into_iter().map(|o| o.filter(|&j| j != usize::MAX)).collect()
}

/// The best finish with each junction's own nodes ([`owned_nodes`]) taken from the finish best
/// for that junction's elements, when that makes the mesh better; `None` otherwise.
///
/// Why: a tree's junctions differ (a wide Y, a small side branch, a crotch against a
/// neighbour), and the finish one needs can spoil another. Chosen for the whole vessel, the best
/// finish of a tree of twenty junctions had some junction short of a bar in every round, so every
/// round was built (most of a large tree's time). The finishes share their elements and nodes,
/// and a junction's own nodes move only its own elements: the other elements keep their figures,
/// and a junction's elements are judged again with its new nodes beside the kept ones (a junction
/// whose mixed elements are not better stays as it was).
fn compose(built: &[FinishedVolume], junctions: usize) -> Option<FinishedVolume> {
    let base = &built[best_of(built)];
    let alike = |f: &FinishedVolume| f.mesh.hexes == base.mesh.hexes && f.junction_of == base.junction_of;
    if junctions == 0 || built.len() < 2 || !built.iter().all(alike) {
        return None;
    }
    let mut elements_of: Vec<Vec<usize>> = vec![vec![]; junctions];
    for (e, j) in base.junction_of.iter().enumerate() {
        if let Some(j) = *j {
            elements_of[j].push(e);
        }
    }
    let local = |j: usize, validity: &[f64]| FinishQuality::of_elements(&base.mesh, validity, &elements_of[j]);
    // Per junction, the first finish best for its elements, where it beats the best finish's.
    let choices: Vec<(usize, usize, FinishQuality)> = (0..junctions)
        .filter_map(|j| {
            let kept = local(j, &base.validity);
            let best = (0..built.len()).fold(None::<(usize, FinishQuality)>, |best, i| {
                let q = local(j, &built[i].validity);
                match best {
                    Some((_, b)) if !q.better_than(&b) => best,
                    _ => Some((i, q)),
                }
            });
            best.filter(|(_, q)| q.better_than(&kept)).map(|(i, _)| (j, i, kept))
        })
        .collect();
    if choices.is_empty() {
        return None;
    }
    let mut nodes_of: Vec<Vec<usize>> = vec![vec![]; junctions];
    for (n, j) in owned_nodes(&base.mesh, &base.junction_of).into_iter().enumerate() {
        if let Some(j) = j {
            nodes_of[j].push(n);
        }
    }
    let (mut mesh, mut validity, mut variants) = (base.mesh.clone(), base.validity.clone(), base.variants.clone());
    let mut changed = false;
    for (j, i, kept) in choices {
        for &n in &nodes_of[j] {
            mesh.nodes[n] = built[i].mesh.nodes[n];
        }
        let mixed: Vec<f64> = elements_of[j].par_iter().map(|&e| element_validity(&mesh, e)).collect();
        elements_of[j].iter().zip(&mixed).for_each(|(&e, &q)| validity[e] = q);
        if local(j, &validity).better_than(&kept) {
            variants[j] = built[i].variants[j];
            changed = true;
        } else {
            for &n in &nodes_of[j] {
                mesh.nodes[n] = base.mesh.nodes[n];
            }
            elements_of[j].iter().for_each(|&e| validity[e] = base.validity[e]);
        }
    }
    let junction_of = base.junction_of.clone();
    let quality = FinishQuality::of(&mesh, &validity, |e| junction_of[e].is_some());
    (changed && quality.better_than(&base.quality)).then_some(FinishedVolume {
        mesh,
        junction_of,
        variants,
        validity,
        quality,
    })
}

/// The best of the finishes built and their composition.
fn best_quality(built: &[FinishedVolume], composed: &Option<FinishedVolume>) -> FinishQuality {
    composed.as_ref().map_or(built[best_of(built)].quality, |c| c.quality)
}

/// The vessel's volume with its junctions finished in the best way tried (see [`rounds`] and
/// [`compose`]): the mesh, each element's junction, and each junction's finish.
pub(crate) fn finish_junctions(inputs: &VolumeInputs) -> (VesselMesh, Vec<Option<usize>>, Vec<JunctionVariant>) {
    let has_junctions = !inputs.junctions.is_empty();
    let junctions = inputs.junctions.len();
    let walls = walls(has_junctions, inputs.wall_growth);
    let (mut built, mut reserve): (Vec<FinishedVolume>, Vec<FinishedVolume>) = (Vec::new(), Vec::new());
    let mut composed = None;
    for (k, round) in rounds(has_junctions).iter().enumerate() {
        if k > 0 && best_quality(&built, &composed).meets_bars() {
            break;
        }
        if k >= UNFOLDING_ROUNDS && folded_in_every_finish(&built, junctions) {
            break;
        }
        let (normal, rest): (Vec<_>, Vec<_>) = build_round(inputs, round, &walls)
            .into_iter()
            .partition(|f| f.variants.first().is_some_and(|v| v.wall == JunctionWall::Normal));
        built.extend(rest);
        reserve.extend(normal);
        composed = compose(&built, junctions);
    }
    // Still short of a bar: every finish tried with the wall along the normals smoothed only as
    // elsewhere in the vessel joins in (JunctionWall::Normal: a small branch's funnel;
    // gmsh_aortic_arch at coarse, wall mean 0.833 -> 0.852). Only then: on
    // simvascular_demo_aortoiliac at coarse, within every bar already, that wall would make a
    // finish with moved pages the best one, and its crotch inflates unevenly (CalculiX stops: a
    // fibre stretched past the exponential's range).
    if !best_quality(&built, &composed).meets_bars() && !reserve.is_empty() {
        built.append(&mut reserve);
        composed = compose(&built, junctions);
    }
    let chosen = composed.unwrap_or_else(|| built.swap_remove(best_of(&built)));
    (chosen.mesh, chosen.junction_of, chosen.variants)
}

/// One element's validity (see [`validities`]).
fn element_validity(mesh: &VesselMesh, e: usize) -> f64 {
    let q = crate::geometry::quality::validity(&mesh.corners(e));
    if q.is_nan() {
        f64::NEG_INFINITY
    } else {
        q
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::config::MeshConfig;
    use crate::testing::straight_tube_mesh;

    /// A finish of `mesh` with the given element junctions, judged.
    fn finished(mesh: VesselMesh, junction_of: &[Option<usize>], wall: JunctionWall) -> FinishedVolume {
        let validity = validities(&mesh, junction_of);
        let quality = FinishQuality::of(&mesh, &validity, |e| junction_of[e].is_some());
        let variants = vec![JunctionVariant { wall, ..Default::default() }; 2];
        FinishedVolume { mesh, junction_of: junction_of.to_vec(), variants, validity, quality }
    }

    #[test]
    fn each_junction_takes_its_nodes_from_the_finish_best_for_it() {
        let tube = straight_tube_mesh(&MeshConfig::default()).unwrap().mesh;
        let z = |e: usize| tube.corners(e).iter().map(|p| p.z).sum::<f64>() / 8.0;
        let (lo, hi) = tube.nodes.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.z), b.max(p.z)));
        let third = (hi - lo) / 3.0;
        // Two "junctions" at the tube's ends, ordinary elements between them.
        let junction_of: Vec<Option<usize>> = (0..tube.hexes.len())
            .map(|e| match z(e) - lo {
                d if d < third => Some(0),
                d if d > 2.0 * third => Some(1),
                _ => None,
            })
            .collect();
        let owner = owned_nodes(&tube, &junction_of);
        let own = |j: usize| (0..owner.len()).find(|&n| owner[n] == Some(j)).unwrap();
        // Each finish spoils the other's junction: one node pushed across the tube.
        let spoiled = |j: usize| {
            let mut m = tube.clone();
            m.nodes[own(j)].x += 40.0;
            m
        };
        let (a, b) = (spoiled(1), spoiled(0));
        let built = vec![finished(a, &junction_of, JunctionWall::Ray), finished(b, &junction_of, JunctionWall::Normal)];
        assert!(built.iter().all(|f| f.quality.worst < 0.0), "each finish alone has an inverted element");
        let composed = compose(&built, 2).expect("the composition is better than either finish");
        assert!(composed.quality.worst > 0.2, "{:?}", composed.quality);
        assert_eq!(composed.mesh.nodes, tube.nodes, "each junction kept from the finish that left it alone");
        assert_eq!(
            composed.variants.iter().map(|v| v.wall).collect::<Vec<_>>(),
            [JunctionWall::Ray, JunctionWall::Normal]
        );
        // A node shared by a junction's element and an ordinary one is nobody's own.
        for (hex, j) in tube.hexes.iter().zip(&junction_of) {
            if j.is_none() {
                assert!(hex.iter().all(|&n| owner[n as usize].is_none()));
            }
        }
        // Finishes alike in every junction: nothing to compose.
        let same = vec![finished(tube.clone(), &junction_of, JunctionWall::Ray); 2];
        assert!(compose(&same, 2).is_none());
    }

    /// A junction folded in every finish stops the rounds; two junctions each folded in one
    /// finish do not (the composition may unfold both), nor does a wall folded everywhere.
    #[test]
    fn a_junction_folded_in_every_finish_is_seen() {
        let tube = straight_tube_mesh(&MeshConfig::default()).unwrap().mesh;
        let z = |e: usize| tube.corners(e).iter().map(|p| p.z).sum::<f64>() / 8.0;
        let (lo, hi) = tube.nodes.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.z), b.max(p.z)));
        let junction_of: Vec<Option<usize>> =
            (0..tube.hexes.len()).map(|e| if z(e) - lo < (hi - lo) / 3.0 { Some(0) } else { Some(1) }).collect();
        // A node of junction j's elements in the lumen alone, or in the wall alone.
        let node_of = |j: usize, in_wall: bool| {
            let region_of = |n: u32| {
                (0..tube.hexes.len())
                    .filter(|&e| tube.hexes[e].contains(&n))
                    .map(|e| (junction_of[e], tube.regions[e].is_wall()))
                    .collect::<Vec<_>>()
            };
            (0..tube.nodes.len() as u32)
                .find(|&n| region_of(n).iter().all(|&(jn, w)| jn == Some(j) && w == in_wall))
                .unwrap() as usize
        };
        let spoiled = |j: usize, in_wall: bool| {
            let mut m = tube.clone();
            m.nodes[node_of(j, in_wall)].x += 40.0;
            finished(m, &junction_of, JunctionWall::Ray)
        };
        assert!(folded_in_every_finish(&[spoiled(0, false), spoiled(0, false)], 2));
        assert!(!folded_in_every_finish(&[spoiled(0, false), spoiled(1, false)], 2));
        assert!(!folded_in_every_finish(&[spoiled(1, true), spoiled(1, true)], 2));
        assert!(spoiled(1, true).quality.worst_wall < 0.0, "the wall is folded");
        assert!(!folded_in_every_finish(&[], 2));
    }

    fn finish(worst: f64, worst_wall: f64, wall_mean: f64) -> FinishQuality {
        FinishQuality { worst, worst_wall, wall_mean }
    }

    #[test]
    fn a_finish_meeting_the_bars_beats_one_with_a_better_worst_element() {
        let within = finish(0.21, 0.24, 0.852);
        let wall_mean_below = finish(0.30, 0.40, 0.833);
        let worst_below = finish(0.19, 0.50, 0.95);
        assert!(within.meets_bars() && !wall_mean_below.meets_bars() && !worst_below.meets_bars());
        assert!(within.better_than(&wall_mean_below) && within.better_than(&worst_below));
        assert!(!wall_mean_below.better_than(&within));
        // Both within: the worst element decides, then the worst wall element, then the mean.
        assert!(finish(0.31, 0.3, 0.86).better_than(&finish(0.30, 0.9, 0.99)));
        assert!(finish(0.30, 0.35, 0.86).better_than(&finish(0.30, 0.34, 0.99)));
        assert!(finish(0.30, 0.35, 0.87).better_than(&finish(0.30, 0.35, 0.86)));
        // Both below the same bar: the better worst element wins.
        assert!(finish(0.15, 0.3, 0.9).better_than(&finish(0.10, 0.3, 0.9)));
        // Equals: neither is better, so the first tried is kept.
        assert!(!within.better_than(&within));
    }
}
