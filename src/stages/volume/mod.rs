//! Volume mesh of the lumen (core + lateral blocks) and of the three-layer wall, from the
//! projected sections of a branch.
//!
//! Node layout per station (station-major, so neighbouring stations are close in memory):
//! the (N+1)^2 core nodes, then ring levels 1..=R of the lumen (level R is the lumen surface,
//! shared with the wall), then the wall levels. Ring level 0 is the core boundary. Elements are
//! ordered lumen, intima, media, adventitia, each station interval by station interval.

mod elements;
pub mod node_optimisation;
mod numbering;
pub mod surface_smoothing;
pub mod wall_directions;

use crate::data::config::WallGrowth;
use crate::geometry::mesh::{sets, Hex, Region, VesselMesh, WallLayer, HEX_EDGES};
use crate::geometry::quality::Validity;
use crate::geometry::surface::LumenSurface;
use crate::stages::junction::blocks::SectionTemplate;
use crate::stages::junction::JunctionGeometry;
use crate::stages::projection::ProjectedBranch;
use crate::stages::volume::node_optimisation::{optimise_nodes, Freedom, PYRAMID_TARGET};
use crate::stages::volume::surface_smoothing::{smooth_on_surface, RayNode, SmoothedNode};
use crate::stages::volume::wall_directions::{surface_normals, SurfaceGraph, JUNCTION_SMOOTHING_PASSES};
use elements::{
    add_lumen_elements, add_wall_elements, lumen_surface_quads, vessel_end_names, vessel_end_sets, vessel_end_tangents,
    Elements,
};
use indexmap::IndexMap;
use nalgebra::{Point3, Vector3};
use numbering::{place_lumen_nodes, LumenNodes, Numbering};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::HashMap;

/// Radial structure shared by all stations.
#[derive(Debug, Clone)]
pub struct RadialLevels {
    /// Lumen: relative positions from the core boundary (0) to the surface (1), R + 1 values.
    pub lumen: Vec<f64>,
    /// Wall: relative positions from the lumen surface (0) to the outer surface (1).
    pub wall: Vec<f64>,
    /// Region of each wall element layer (wall.len() - 1 entries).
    pub wall_regions: Vec<Region>,
}

impl RadialLevels {
    pub fn new(lumen_levels: Vec<f64>, layers: &[WallLayer]) -> Self {
        let mut wall = vec![0.0];
        let mut wall_regions = vec![];
        let mut base = 0.0;
        for layer in layers {
            for e in 1..=layer.radial_elements {
                wall.push(base + layer.thickness_fraction * e as f64 / layer.radial_elements as f64);
                wall_regions.push(layer.region);
            }
            base += layer.thickness_fraction;
        }
        *wall.last_mut().unwrap() = 1.0;
        RadialLevels { lumen: lumen_levels, wall, wall_regions }
    }
    fn lumen_cells(&self) -> usize {
        self.lumen.len() - 1
    }
    fn wall_cells(&self) -> usize {
        self.wall.len() - 1
    }
}

/// What the volume is built from: the projected branches and the settings of the mesh.
pub struct VolumeInputs<'a> {
    pub projected: &'a [ProjectedBranch],
    /// Each branch's cross-section template, by branch.
    pub templates: &'a [SectionTemplate],
    pub junctions: &'a [JunctionGeometry],
    pub levels: &'a RadialLevels,
    pub layers: &'a [WallLayer],
    pub wall_thickness: &'a (dyn Fn(f64) -> f64 + Sync),
    pub wall_growth: WallGrowth,
    pub branch_names: &'a [String],
    pub surface: &'a LumenSurface,
}

/// Builds nodes, hexes, regions and sets of a vessel from its projected branches (one for an
/// unbranched vessel). Triads, fibres and quality are filled in by [`crate::stages::annotation::annotate`].
///
/// Nodes of a folded end section are shared between the branches of a junction through their
/// [`crate::stages::junction::FoldKey`]; the wall grows from the lumen-surface nodes once per node, so the junction's
/// lumen and wall are conformal by construction.
///
/// The junction optimisation moves lumen nodes only, so one optimised lumen carries every wall
/// asked for in `junction_walls` (how the wall grows from junction nodes): one mesh per entry,
/// in that order, differing only in the wall nodes' places. The elements' junctions
/// (`None` outside transitions) are the same for all.
pub fn build_volume(
    inputs: &VolumeInputs,
    optimisation: JunctionOptimisation,
    junction_walls: &[JunctionWall],
) -> (Vec<VesselMesh>, Vec<Option<usize>>) {
    let VolumeInputs { projected, templates, junctions, levels, layers, surface, .. } = *inputs;
    assert!(!junction_walls.is_empty(), "at least one wall is asked for");
    assert_eq!(templates.len(), projected.len(), "one template per branch");

    let (lumen, branch_nodes) = place_lumen_nodes(projected, templates, junctions, levels, &optimisation);
    let mut numbering = Numbering::new(&branch_nodes, templates, levels);
    let quads = lumen_surface_quads(projected, &numbering);
    let graph = SurfaceGraph::new(&quads, lumen.nodes.len());
    let LumenNodes { mut nodes, radius, in_junction, ray, movable, poor_mobility, smoothed_columns, .. } = lumen;
    // The lumen's elements before the smoothing, which keeps them valid.
    let ends = vessel_end_names(projected);
    let mut elements = Elements::new(&ends);
    add_lumen_elements(&mut elements, projected, &numbering, levels, &ends);
    if optimisation.smooth_surface {
        smooth_transition_surface(&mut nodes, smoothed_columns, &graph, &quads, &elements.hexes, surface);
    }
    // The wall nodes' ids now; their places once the junction optimisation has settled the surface.
    numbering.add_wall_nodes(&mut nodes, &graph.nodes, levels);
    let wall = WallLayout {
        inputs,
        quads: &quads,
        graph: &graph,
        ray: &ray,
        in_junction: &in_junction,
        end_tangent: vessel_end_tangents(projected, &numbering),
        nominal: graph.nodes.iter().map(|&s| (inputs.wall_thickness)(radius[s as usize])).collect(),
        numbering: &numbering,
    };

    let by_corners = vec![Validity::Corners; elements.hexes.len()];
    improve_junction_nodes(&mut nodes, &elements.hexes, &movable, surface, optimisation.pattern_search, &by_corners);
    // The lumen is OpenFOAM's mesh: its poor elements are judged with the face pyramids too, and
    // optimised with them in the objective. By the corners alone, the optimisation flattened a
    // crotch cell of gmsh_bifurcation (medium) until its centre left its wall face's plane.
    improve_poor(&mut nodes, &elements.hexes, &poor_mobility, surface, Validity::CornersAndPyramids);
    // A lumen still inverted here makes a finish that cannot be the mesh (the wall's
    // optimisation never moves a lumen node, and a mesh with an inverted element is refused), so
    // its walls are grown but not optimised: that optimisation is most of a finish's time (the
    // SPHinXsys arch at coarse, both finishes of its first round inverted: 2.0 s -> 1.25 s).
    let lumen_valid = !elements.hexes.par_iter().any(|h| {
        let q = crate::geometry::quality::scaled_jacobian(&h.map(|n| nodes[n as usize]));
        q.is_nan() || q <= 0.0
    });
    // The wall grows from the surface where its nodes ended up (they may have slid).
    let first_dirs = wall.lay(&mut nodes, junction_walls[0]);
    add_wall_elements(&mut elements, projected, &numbering, levels, &ends);
    let wall_hexes: Vec<Hex> =
        (0..elements.hexes.len()).filter(|&e| elements.regions[e].is_wall()).map(|e| elements.hexes[e]).collect();
    if lumen_valid {
        wall.improve(&mut nodes, &first_dirs, &wall_hexes);
    }

    // Node sets: the interface, the outer wall, and each end's lumen and wall nodes.
    let mut node_sets: IndexMap<String, Vec<u32>> = IndexMap::new();
    node_sets.insert(sets::INTERFACE_NODES.into(), graph.nodes.clone());
    node_sets.insert(
        sets::OUTER_WALL_NODES.into(),
        graph.nodes.iter().map(|&s| numbering.above(s, levels.wall_cells())).collect(),
    );
    let vessel_ends = vessel_end_sets(&mut node_sets, projected, &numbering, levels, &ends);
    for v in node_sets.values_mut() {
        v.sort_unstable();
        v.dedup();
    }
    let Elements { hexes, regions, branch_of, junction_of, mut face_sets } = elements;
    for v in face_sets.values_mut() {
        v.sort_unstable();
    }

    let sac = branch_of.iter().map(|&b| crate::geometry::mesh::is_sac(&inputs.branch_names[b as usize])).collect();
    let mesh = VesselMesh {
        nodes,
        hexes,
        regions,
        branch_of,
        sac,
        triads: Vec::new(),
        fibres: Vec::new(),
        quality: Vec::new(),
        layers: layers.to_vec(),
        ends: vessel_ends,
        node_sets,
        face_sets,
        branch_names: inputs.branch_names.to_vec(),
    };
    let mut meshes = Vec::with_capacity(junction_walls.len());
    for &junction_wall in &junction_walls[1..] {
        let mut other = mesh.clone();
        let dirs = wall.lay(&mut other.nodes, junction_wall);
        if lumen_valid {
            wall.improve(&mut other.nodes, &dirs, &wall_hexes);
        }
        meshes.push(other);
    }
    meshes.insert(0, mesh);
    (meshes, junction_of)
}

/// Smooths the transitions' lumen-surface quads on the triangles (see
/// [`crate::stages::volume::surface_smoothing`]), their rays' ring nodes following.
fn smooth_transition_surface(
    nodes: &mut [Point3<f64>],
    mut columns: IndexMap<u32, Vec<RayNode>>,
    graph: &SurfaceGraph,
    quads: &[[u32; 4]],
    lumen: &[Hex],
    surface: &LumenSurface,
) {
    let mut quads_of: HashMap<u32, Vec<[u32; 4]>> = HashMap::new();
    for q in quads {
        for &n in q {
            if columns.contains_key(&n) {
                quads_of.entry(n).or_default().push(*q);
            }
        }
    }
    // The lumen elements each smoothed node moves: those of the node and of its column.
    let mut mover_of: HashMap<u32, u32> = HashMap::new();
    for (&node, column) in &columns {
        mover_of.insert(node, node);
        for r in column {
            mover_of.insert(r.node, node);
        }
    }
    let mut elements_of: HashMap<u32, Vec<u32>> = HashMap::new();
    for (e, h) in lumen.iter().enumerate() {
        let mut movers: Vec<u32> = h.iter().filter_map(|n| mover_of.get(n).copied()).collect();
        movers.sort_unstable();
        movers.dedup();
        for m in movers {
            elements_of.entry(m).or_default().push(e as u32);
        }
    }
    // In node order, so the Gauss-Seidel passes do not depend on the branches' order.
    columns.sort_keys();
    let smoothed: Vec<SmoothedNode> = columns
        .into_iter()
        .map(|(node, column)| {
            let around = &graph.neighbours[graph.position[node as usize]];
            let neighbours = around.iter().map(|&j| graph.nodes[j]).collect();
            let quads = quads_of.remove(&node).unwrap_or_default();
            SmoothedNode { node, neighbours, quads, elements: elements_of.remove(&node).unwrap_or_default(), column }
        })
        .collect();
    smooth_on_surface(nodes, &smoothed, lumen, surface);
}

/// How the wall is laid over the lumen surface: along which direction and how thick at every
/// surface node, the wall nodes above it at their levels.
struct WallLayout<'a> {
    inputs: &'a VolumeInputs<'a>,
    quads: &'a [[u32; 4]],
    graph: &'a SurfaceGraph,
    /// Per lumen node: the ray it was placed on.
    ray: &'a [Vector3<f64>],
    /// Per lumen node: whether it lies on a junction's section.
    in_junction: &'a [bool],
    /// The vessel ends' surface nodes, with their sections' tangents.
    end_tangent: HashMap<u32, Vector3<f64>>,
    /// The nominal thickness at each surface node (in the graph's order).
    nominal: Vec<f64>,
    numbering: &'a Numbering<'a>,
}

impl WallLayout<'_> {
    /// Growth direction and thickness at every surface node, from the surface as it stands.
    fn growth(&self, nodes: &[Point3<f64>], junction_wall: JunctionWall) -> (Vec<Vector3<f64>>, Vec<f64>) {
        let graph = self.graph;
        let dirs: Vec<Vector3<f64>> = match self.inputs.wall_growth {
            WallGrowth::Ray => graph.nodes.iter().map(|&s| self.ray[s as usize]).collect(),
            WallGrowth::Normal => {
                let junction_passes = match junction_wall {
                    JunctionWall::Normal => 0,
                    _ => JUNCTION_SMOOTHING_PASSES,
                };
                let mut dirs = surface_normals(
                    nodes,
                    self.quads,
                    graph,
                    self.ray,
                    &self.end_tangent,
                    self.in_junction,
                    junction_passes,
                    &self.nominal,
                );
                // Along the rays in junction transitions, where asked: the caller keeps whichever
                // wall is better (see `build_volume`'s caller).
                if junction_wall == JunctionWall::Ray {
                    for (d, &s) in dirs.iter_mut().zip(&graph.nodes) {
                        if self.in_junction[s as usize] && !self.end_tangent.contains_key(&s) {
                            *d = self.ray[s as usize].normalize();
                        }
                    }
                }
                dirs
            }
        };
        let branched = !self.inputs.junctions.is_empty();
        let thickness = crotch_limited_thickness(nodes, graph, &dirs, self.inputs.surface, &self.nominal, branched);
        (dirs, thickness)
    }

    /// Places the wall's nodes above the surface nodes where they stand; the growth directions.
    fn lay(&self, nodes: &mut [Point3<f64>], junction_wall: JunctionWall) -> Vec<Vector3<f64>> {
        let (dirs, thickness) = self.growth(nodes, junction_wall);
        for ((&s, dir), t) in self.graph.nodes.iter().zip(&dirs).zip(&thickness) {
            let p = nodes[s as usize];
            for (w, &tau) in self.inputs.levels.wall[1..].iter().enumerate() {
                nodes[self.numbering.above(s, w + 1) as usize] = p + dir * (t * tau);
            }
        }
        dirs
    }

    /// Where the wall has an element below the bar (the lumen's optimisation does not see the
    /// wall), the wall nodes around it move across their growth directions `dirs`, so the wall
    /// keeps its thickness. gmsh_aortic_arch at medium: a junction's wall 0.116 -> 0.216;
    /// gmsh_cerebral_aneurysm at medium: an intima element inverted (-0.147) where the wall
    /// grows over the sac's neck. Walls above the bar stay as grown (raising their worst
    /// element costs their mean a little).
    fn improve(&self, nodes: &mut [Point3<f64>], dirs: &[Vector3<f64>], wall_hexes: &[Hex]) {
        let mut wall_movable = vec![Freedom::Fixed; nodes.len()];
        for (&s, d) in self.graph.nodes.iter().zip(dirs) {
            if !self.end_tangent.contains_key(&s) {
                for w in 1..=self.inputs.levels.wall_cells() {
                    wall_movable[self.numbering.above(s, w) as usize] = Freedom::Across(*d);
                }
            }
        }
        // By the corners alone: a wall node moves only across its growth direction, which cannot
        // thicken a cell, and the wall's crotch cells whose pyramids fail are thin ones (judged
        // with the pyramids, gmsh_carotid_bifurcation at medium kept them at -1 through every
        // round and took 2.7 times the CPU time). A finish whose wall fails a pyramid loses to one
        // whose wall does not (see `junction_finish::judge`).
        improve_poor(nodes, wall_hexes, &wall_movable, self.inputs.surface, Validity::Corners);
    }
}

/// Sweeps of the junction node optimisation.
const OPTIMISATION_SWEEPS: usize = 10;
/// Where an element stays below [`QUALITY_BAR_SJ`] after those, the optimisation goes on up
/// to this many sweeps (or until no node moves, or the worst element stalls): gmsh_aortic_arch's
/// left common carotid, a fifth of its junction's radius, funnels into a fold the whole spine
/// high; after ten sweeps its funnel is inverted at the medium preset wherever the junction is
/// centred, after thirty it is valid (lumen min 0.201; at the coarse preset 0.173 -> 0.207), and
/// from the arch's own centerlines it needs thirty-five (0.177 after thirty, 0.203 after
/// thirty-five). With thirty, what stays below the bar is left to `improve_poor`, which raises
/// it but leaves one face of the arch (its given centerlines, medium) past checkMesh's skewness
/// bar (4.6 against 4; 2.3 with eighty).
const MAX_OPTIMISATION_SWEEPS: usize = 80;
/// Past [`OPTIMISATION_SWEEPS`], the sweeps stop when the worst element has gained less than
/// [`STALLED_GAIN`] over the last this many: a funnel the moves cannot untangle stays inverted
/// (on the bare arch at medium, half of the finishes tried), while one being untangled gains
/// steadily.
const STALLED_SWEEPS: usize = 10;
const STALLED_GAIN: f64 = 0.01;
/// The bar on the scaled Jacobian: below it, junctions get more sweeps and (when asked)
/// their walls are optimised.
pub(crate) const QUALITY_BAR_SJ: f64 = crate::geometry::quality::Bars::MIN_SCALED_JACOBIAN;
/// The bar on the wall's mean scaled Jacobian (FEA practice wants a mean above 0.8).
pub(crate) const WALL_MEAN_BAR_SJ: f64 = crate::geometry::quality::Bars::WALL_MEAN_SCALED_JACOBIAN;

/// How a branched vessel's junctions are finished; the caller builds the variants and keeps
/// the best (see `junction_finish::finish_junctions`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct JunctionVariant {
    pub wall: JunctionWall,
    pub optimisation: JunctionOptimisation,
}

/// How the wall grows from the lumen-surface nodes of junction transitions when it grows along
/// the normals ([`WallGrowth::Normal`]; along the rays it does so everywhere). The caller
/// builds each on the same lumen and keeps the best (see `junction_finish::finish_junctions`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum JunctionWall {
    /// Along the normals smoothed further over the junction: across a flow divider the normal
    /// turns fast, and grown along it the outer layers shear.
    #[default]
    SmoothedNormal,
    /// Along the normals smoothed only as elsewhere in the vessel: in a small branch's funnel,
    /// whose surface turns from the parent's wall to the branch's within a few sections, the
    /// further smoothed normals tilt along the funnel and shear every wall element there
    /// (gmsh_aortic_arch at coarse, its left common carotid's funnel: wall mean 0.833 -> 0.852).
    Normal,
    /// Along the projection rays: in an acute crotch the smoothed normals converge while the
    /// rays, aimed past the crotch, do not.
    Ray,
}

/// How the junction optimisation may move lumen nodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct JunctionOptimisation {
    /// The lumen-surface nodes of transitions slide on the triangles too.
    pub slide_surface_nodes: bool,
    /// Where a move towards the centroid does not help a node, small moves along the axes are
    /// probed.
    pub pattern_search: bool,
    /// The pages' nodes (folded sections, spine included) move too; their rims slide on the
    /// triangles when `slide_surface_nodes` is set. Flat pages fold every slot across the
    /// junction's whole spine; bent ones give room to the branch that needs it.
    pub move_pages: bool,
    /// The transitions' lumen-surface quads are smoothed on the triangles first
    /// ([`crate::stages::volume::surface_smoothing`]): it lifts the wall's mean, but can lower the worst element.
    pub smooth_surface: bool,
}

/// Raises the worst scaled Jacobian around the movable lumen nodes of junction transitions
/// (BRANCHING.md §4.4): each node in turn moves towards the centroid of its edge neighbours
/// (a surface node: of its neighbours along the surface, then onto the nearest point of the
/// triangles, so it stays on the surface to rounding), by the largest of a few step fractions
/// that improves the worst lumen element around it, or else (`pattern_search`) by the best of
/// small moves along the axes. Fold (page) nodes move only when `build_volume` was asked to
/// move the pages; being shared by the slots around them, they keep the junction conformal
/// either way. Sequential, so the result does not depend on the thread count. Only the elements
/// given count: the lumen's (`build_volume` grows the wall again from the surface once its
/// nodes have slid), or a junction wall's when its own nodes move ([`Freedom::Across`]).
fn improve_junction_nodes(
    nodes: &mut [Point3<f64>],
    lumen: &[Hex],
    movable: &[Freedom],
    surface: &LumenSurface,
    pattern_search: bool,
    validity: &[Validity],
) {
    let free: Vec<u32> = (0..movable.len() as u32).filter(|&i| movable[i as usize] != Freedom::Fixed).collect();
    if free.is_empty() {
        return;
    }
    let Neighbourhood { incident, neighbours, on_outer_face, corners, all_incident } =
        neighbourhood(lumen, movable, &free);
    // The worst element, each by its `validity`, or, once it is at most `floor`, some value at
    // most `floor`: a trial move is only ever compared with a floor.
    // `first`, the element that was worst before the move, is measured first: a move that
    // does not help mostly fails there. Each element's value goes to `measured`: a move that is
    // taken had every element above the floor, so measured in full (an element's measure stops
    // early only at the floor), and those values are the ones `known` would measure again.
    // Each element's term of the scaled Jacobian that decided its last measure, measured first
    // on a trial move (see `Validity::unless_below_from`: the same values above the floor).
    let mut hints: Vec<u8> = vec![0; lumen.len()];
    let worst = |nodes: &[Point3<f64>],
                 elements: &[usize],
                 first: usize,
                 floor: f64,
                 measured: &mut Vec<(usize, f64)>,
                 hints: &mut [u8]| {
        measured.clear();
        let mut min = f64::INFINITY;
        for &e in std::iter::once(&first).chain(elements.iter().filter(|&&e| e != first)) {
            let q = validity[e].unless_below_from(&lumen[e].map(|n| nodes[n as usize]), floor, &mut hints[e]);
            measured.push((e, q));
            min = min.min(q);
            if min <= floor {
                break;
            }
        }
        min
    };
    // Each element's validity, known until one of its corners moves: a node's elements are
    // measured before each trial move, mostly unchanged since the last.
    let mut known: Vec<Option<f64>> = vec![None; lumen.len()];
    let worst_cached = |known: &mut [Option<f64>], nodes: &[Point3<f64>], elements: &[usize], hints: &mut [u8]| {
        elements
            .iter()
            .map(|&e| {
                *known[e].get_or_insert_with(|| {
                    let c = lumen[e].map(|n| nodes[n as usize]);
                    validity[e].unless_below_from(&c, f64::NEG_INFINITY, &mut hints[e])
                })
            })
            .fold(f64::INFINITY, f64::min)
    };
    let mut moves: u64 = 0;
    // By node (looked up for every corner of every node tried, each sweep: a hash map's lookups
    // were a tenth of a branched vessel's volume).
    let mut moved_at: Vec<Option<u64>> = vec![None; nodes.len()];
    let mut still_since: Vec<Option<u64>> = vec![None; nodes.len()];
    // The worst element after each sweep past OPTIMISATION_SWEEPS.
    let mut worst_after: Vec<f64> = Vec::new();
    let (mut measured, mut best_measured) = (Vec::new(), Vec::new());
    for sweep in 0..MAX_OPTIMISATION_SWEEPS {
        if sweep >= OPTIMISATION_SWEEPS {
            let now = worst_cached(&mut known, nodes, &all_incident, &mut hints);
            let stalled = worst_after.len() >= STALLED_SWEEPS
                && now <= worst_after[worst_after.len() - STALLED_SWEEPS] + STALLED_GAIN;
            if now > QUALITY_BAR_SJ || stalled {
                break;
            }
            worst_after.push(now);
        }
        let moves_before = moves;
        for (slot, &n) in free.iter().enumerate() {
            if let Some(since) = still_since[n as usize] {
                if corners[slot].iter().all(|&c| moved_at[c as usize].is_none_or(|t| t <= since)) {
                    continue;
                }
            }
            let elements = &incident[slot];
            let on_surface = movable[n as usize] == Freedom::OnSurface;
            let nb = if on_surface { &on_outer_face[slot] } else { &neighbours[slot] };
            if nb.is_empty() {
                continue;
            }
            let centroid = nb.iter().fold(Vector3::zeros(), |acc, &j| acc + nodes[j as usize].coords) / nb.len() as f64;
            let old = nodes[n as usize];
            let before = worst_cached(&mut known, nodes, elements, &mut hints);
            let first = *elements
                .iter()
                .min_by(|&&a, &&b| known[a].unwrap_or(f64::INFINITY).total_cmp(&known[b].unwrap_or(f64::INFINITY)))
                .expect("a node's elements");
            let mut moved = false;
            let place = |p: Point3<f64>| match movable[n as usize] {
                Freedom::OnSurface => surface.closest_near(&p, &old).point,
                Freedom::Across(d) => p - d * (p - old).dot(&d),
                _ => p,
            };
            for step in [1.0, 0.5, 0.25] {
                nodes[n as usize] = place(old + (Point3::from(centroid) - old) * step);
                if worst(nodes, elements, first, before + 1e-9, &mut measured, &mut hints) > before + 1e-9 {
                    moved = true;
                    break;
                }
                nodes[n as usize] = old;
            }
            if !moved && pattern_search {
                // The centroid did not help: probe small moves along the axes (a pattern
                // search), a fifth and a twentieth of the shortest edge, and keep the best.
                let h = nb.iter().map(|&j| (nodes[j as usize] - old).norm()).fold(f64::INFINITY, f64::min);
                let mut best = (before, old);
                for scale in [0.2, 0.05] {
                    for d in [Vector3::x(), -Vector3::x(), Vector3::y(), -Vector3::y(), Vector3::z(), -Vector3::z()] {
                        nodes[n as usize] = place(old + d * (h * scale));
                        let q = worst(nodes, elements, first, best.0 + 1e-9, &mut measured, &mut hints);
                        if q > best.0 + 1e-9 {
                            best = (q, nodes[n as usize]);
                            std::mem::swap(&mut measured, &mut best_measured);
                        }
                    }
                }
                nodes[n as usize] = best.1;
                moved = best.1 != old;
                std::mem::swap(&mut measured, &mut best_measured);
            }
            if moved {
                moves += 1;
                moved_at[n as usize] = Some(moves);
                still_since[n as usize] = None;
                for &(e, q) in &measured {
                    known[e] = Some(q);
                }
            } else {
                still_since[n as usize] = Some(moves);
            }
        }
        if moves == moves_before {
            break;
        }
    }
}

/// The lumen around the movable nodes, as [`improve_junction_nodes`] walks it: each by the
/// node's place in the list of movable nodes.
struct Neighbourhood {
    /// Each movable node's elements.
    incident: Vec<Vec<usize>>,
    /// Each movable node's edge neighbours.
    neighbours: Vec<Vec<u32>>,
    /// A surface node's neighbours along the surface: the other corners of its outer faces
    /// that share an edge with it (none for the other nodes).
    on_outer_face: Vec<Vec<u32>>,
    /// The other corners of each movable node's elements: a node tried without moving gives
    /// the same answer again until one of them moves, so it is skipped until then (the result
    /// is the same as trying it).
    corners: Vec<Vec<u32>>,
    /// Every element with a movable corner, sorted.
    all_incident: Vec<usize>,
}

fn neighbourhood(lumen: &[Hex], movable: &[Freedom], free: &[u32]) -> Neighbourhood {
    let mut slot_of = vec![u32::MAX; movable.len()];
    for (k, &n) in free.iter().enumerate() {
        slot_of[n as usize] = k as u32;
    }
    let mut incident: Vec<Vec<usize>> = vec![Vec::new(); free.len()];
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); free.len()];
    for (e, h) in lumen.iter().enumerate() {
        for (c, &n) in h.iter().enumerate() {
            if movable[n as usize] != Freedom::Fixed {
                let slot = slot_of[n as usize] as usize;
                incident[slot].push(e);
                let nb = &mut neighbours[slot];
                for &[a, b] in HEX_EDGES.iter() {
                    if a == c {
                        nb.push(h[b]);
                    } else if b == c {
                        nb.push(h[a]);
                    }
                }
            }
        }
    }
    for nb in &mut neighbours {
        nb.sort_unstable();
        nb.dedup();
    }
    let on_outer_face: Vec<Vec<u32>> = free
        .iter()
        .enumerate()
        .map(|(slot, &n)| {
            let mut nb: Vec<u32> = Vec::new();
            if movable[n as usize] != Freedom::OnSurface {
                return nb;
            }
            for &e in &incident[slot] {
                let outer = crate::geometry::mesh::face_nodes(&lumen[e], crate::geometry::mesh::FACE_OUTER);
                if let Some(at) = outer.iter().position(|&x| x == n) {
                    nb.push(outer[(at + 1) % 4]);
                    nb.push(outer[(at + 3) % 4]);
                }
            }
            nb.sort_unstable();
            nb.dedup();
            nb
        })
        .collect();
    let corners: Vec<Vec<u32>> = free
        .iter()
        .enumerate()
        .map(|(slot, &n)| {
            let mut c: Vec<u32> = incident[slot].iter().flat_map(|&e| lumen[e]).filter(|&x| x != n).collect();
            c.sort_unstable();
            c.dedup();
            c
        })
        .collect();
    let all_incident: Vec<usize> = {
        let mut v: Vec<usize> = incident.iter().flatten().copied().collect();
        v.sort_unstable();
        v.dedup();
        v
    };
    Neighbourhood { incident, neighbours, on_outer_face, corners, all_incident }
}

/// Records, for each surface node of a section, the ring nodes on its ray (once: a page's
/// nodes are added by every branch that folds onto it).
fn add_columns(
    columns: &mut IndexMap<u32, Vec<RayNode>>,
    ids: &[u32],
    template: &SectionTemplate,
    section: &crate::stages::projection::ProjectedSection,
    levels: &RadialLevels,
) {
    let (core, m, r_cells) = (template.core_len(), template.ring_len(), levels.lumen_cells());
    for k in 0..m {
        let top = ids[core + (r_cells - 1) * m + k];
        let column = columns.entry(top).or_default();
        if !column.is_empty() {
            continue;
        }
        for (level, &share) in levels.lumen.iter().enumerate().take(r_cells).skip(1) {
            column.push(RayNode { node: ids[core + (level - 1) * m + k], origin: section.origins[k], share });
        }
    }
}

/// Element layers around a poor element whose nodes [`improve_poor`] frees.
const POOR_REACH: usize = 2;
/// Rounds of [`improve_poor`]: each frees the nodes around what is still poor.
const POOR_ROUNDS: usize = 3;

/// Face-pyramid ratios below this put an element's pyramids in the optimisers' sight (see
/// [`watch_pyramids`]). A parallelepiped's are 1, and the cells of a healthy lumen are near it;
/// counting the pyramids of every element doubled the CPU time of the branched trees at medium.
const PYRAMID_WATCH: f64 = 0.5;
/// Passes of a round's optimisation after its first, each around the elements the pass before
/// took below [`PYRAMID_TARGET`] while their pyramids were out of sight.
const WATCH_PASSES: usize = 2;

/// Frees the nodes within [`POOR_REACH`] elements of every element whose validity (`judged`) is
/// below [`QUALITY_BAR_SJ`], wherever it is (a bend, a narrowing, a sac, a funnel the junction
/// optimisation left folded), as `mobility` allows, and raises the worst element among them
/// (`improve_junction_nodes`; in the lumen, inner nodes move freely, surface nodes slide on the
/// triangles, vessel-end sections stay). Untangling comes first by construction: the objective
/// is the worst element, so an inverted one (or, judged with the pyramids, one whose centre lies
/// outside a face's plane) is raised before any other. Without this, an inverted element is a
/// refused vessel (openlb_cerebral_aneurysm_tree at coarse: a small branch's funnel,
/// -0.013). A lumen within the bar is left as it is, so the others pay one pass over the
/// elements.
fn improve_poor(
    nodes: &mut [Point3<f64>],
    elements: &[Hex],
    mobility: &[Freedom],
    surface: &LumenSurface,
    judged: Validity,
) {
    let poor = |nodes: &[Point3<f64>]| -> Vec<usize> {
        (0..elements.len())
            .into_par_iter()
            .filter(|&e| {
                let q = judged.unless_below(&elements[e].map(|n| nodes[n as usize]), QUALITY_BAR_SJ);
                q.is_nan() || q <= QUALITY_BAR_SJ
            })
            .collect()
    };
    // What the optimisers count of each element: its corners, and its pyramids once watched.
    let mut validity = vec![Validity::Corners; elements.len()];
    let mut element_of: Vec<Vec<u32>> = Vec::new();
    for _ in 0..POOR_ROUNDS {
        let seeds = poor(nodes);
        if seeds.is_empty() {
            return;
        }
        if element_of.is_empty() {
            element_of = vec![Vec::new(); mobility.len()];
            for (e, h) in elements.iter().enumerate() {
                for &n in h {
                    element_of[n as usize].push(e as u32);
                }
            }
        }
        let free = nodes_near(elements, mobility, &element_of, seeds);
        let before = worst_of(nodes, elements, &free, judged);
        // The penalty untangles and lifts every poor corner at once; the max-min search after
        // it only takes moves that raise the worst element, which the penalty's sum may have
        // traded (at coarse, without it: the coronary tree 0.245 -> 0.158, the cerebral tree
        // 0.205 -> 0.070; without the penalty, gmsh_cerebral_aneurysm at medium stays inverted).
        let mut moving = free.clone();
        watch_pyramids(nodes, elements, &free, judged, PYRAMID_WATCH, &mut validity);
        for _ in 0..=WATCH_PASSES {
            optimise_nodes(nodes, elements, &moving, surface, &validity);
            improve_junction_nodes(nodes, elements, &moving, surface, true, &validity);
            // Elements the pass took below the pyramids' target out of sight: their
            // neighbourhood again, with their pyramids in sight.
            let fallen = watch_pyramids(nodes, elements, &free, judged, PYRAMID_TARGET, &mut validity);
            if fallen.is_empty() {
                break;
            }
            watch_pyramids(nodes, elements, &free, judged, PYRAMID_WATCH, &mut validity);
            moving = nodes_near(elements, &free, &element_of, fallen);
        }
        if worst_of(nodes, elements, &free, judged) <= before + STALLED_GAIN {
            return;
        }
    }
}

/// Each node's freedom within [`POOR_REACH`] elements of the `seeds` (as `mobility` allows),
/// fixed elsewhere.
fn nodes_near(elements: &[Hex], mobility: &[Freedom], element_of: &[Vec<u32>], seeds: Vec<usize>) -> Vec<Freedom> {
    let mut near = vec![false; mobility.len()];
    let mut front: Vec<usize> = seeds;
    for _ in 0..POOR_REACH {
        let mut next = Vec::new();
        for e in front {
            for &n in &elements[e] {
                if !std::mem::replace(&mut near[n as usize], true) {
                    next.extend(element_of[n as usize].iter().map(|&e| e as usize));
                }
            }
        }
        front = next;
    }
    near.iter().zip(mobility).map(|(&near, &m)| if near { m } else { Freedom::Fixed }).collect()
}

/// Puts the face pyramids of the elements with a `free` node whose smallest pyramid is `below`
/// in `validity` (when `judged` counts pyramids); returns those that were not there yet. Those
/// below [`PYRAMID_WATCH`] are watched before a pass: an element far above it is not pushed to a
/// pyramid that is not positive within one (a node moves by at most a quarter of its shortest
/// edge per sweep); one that still falls below the penalty's target ([`PYRAMID_TARGET`]) out of
/// sight gets a pass around it.
fn watch_pyramids(
    nodes: &[Point3<f64>],
    elements: &[Hex],
    free: &[Freedom],
    judged: Validity,
    below: f64,
    validity: &mut [Validity],
) -> Vec<usize> {
    if judged == Validity::Corners {
        return Vec::new();
    }
    let mut newly = Vec::new();
    for (e, h) in elements.iter().enumerate() {
        if validity[e] != judged
            && h.iter().any(|&n| free[n as usize] != Freedom::Fixed)
            && crate::geometry::quality::face_pyramid_ratio(&h.map(|n| nodes[n as usize])) < below
        {
            validity[e] = judged;
            newly.push(e);
        }
    }
    newly
}

/// The worst validity (`judged`) of the elements with a movable node.
fn worst_of(nodes: &[Point3<f64>], elements: &[Hex], movable: &[Freedom], judged: Validity) -> f64 {
    elements
        .iter()
        .filter(|h| h.iter().any(|&n| movable[n as usize] != Freedom::Fixed))
        .map(|h| judged.unless_below(&h.map(|n| nodes[n as usize]), f64::NEG_INFINITY))
        .fold(f64::INFINITY, f64::min)
}

/// Where the wall, grown outwards from one side of a crotch, would reach the lumen on the other
/// side within this many nominal thicknesses, the thickness is limited.
const CROTCH_PROBE: f64 = 2.5;
/// The limited thickness is this fraction of the distance across the crotch, so the two walls
/// that meet in the flow divider each take less than half of it and the grown normals, which
/// converge there, do not cross.
const CROTCH_SHARE: f64 = 0.4;
/// Share of the distance at which converging growth directions meet that the wall may take.
const CONVERGENCE_SHARE: f64 = 0.15;

/// Wall thickness at every lumen-surface node: the nominal one, limited in flow dividers (the
/// tissue between two branches) to a share of the distance across, and eased towards the
/// limited nodes over their neighbours so the outer wall stays smooth. The distance across is
/// probed only in branched vessels (`probe`), where the walls of two branches face each other
/// from the flow divider on down their first radii; an unbranched vessel's walls face each
/// other only where it loops onto itself, which its sections would not survive, and one ray
/// per surface node was a third of the volume stage on long vessels.
fn crotch_limited_thickness(
    nodes: &[Point3<f64>],
    graph: &SurfaceGraph,
    dirs: &[Vector3<f64>],
    surface: &LumenSurface,
    nominal: &[f64],
    probe: bool,
) -> Vec<f64> {
    let mut factor: Vec<f64> = graph
        .nodes
        .par_iter()
        .zip(dirs)
        .zip(nominal)
        .map(|((&s, d), &t)| {
            if !probe {
                return 1.0;
            }
            let p = nodes[s as usize];
            // Start a little off the surface so the node's own triangles are not hit.
            let eps = 1e-3 * t;
            match surface.first_hit(&(p + d * eps), d, CROTCH_PROBE * t) {
                Some(hit) => ((hit.distance + eps) * CROTCH_SHARE / t).min(1.0),
                None => 1.0,
            }
        })
        .collect();
    // Where neighbouring growth directions converge (a ridge seen from the lumen: the flow
    // divider), the grown lines meet at distance |dp|^2 / -(dn . dp): keep the wall well short.
    for (i, nb) in graph.neighbours.iter().enumerate() {
        let p = nodes[graph.nodes[i] as usize];
        for &j in nb {
            let dp = nodes[graph.nodes[j] as usize] - p;
            let dn = dirs[j] - dirs[i];
            let closing = -dn.dot(&dp);
            if closing > 0.0 {
                let meet = dp.norm_squared() / closing;
                factor[i] = factor[i].min(CONVERGENCE_SHARE * meet / nominal[i]);
            }
        }
    }
    for _ in 0..4 {
        let prev = factor.clone();
        for (i, nb) in graph.neighbours.iter().enumerate() {
            let mean = nb.iter().map(|&j| prev[j]).sum::<f64>() / nb.len() as f64;
            factor[i] = prev[i].min(0.5 * (prev[i] + mean));
        }
    }
    nominal.iter().zip(factor).map(|(t, f)| t * f).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::junction::blocks::graded_levels;

    /// Only elements with a free node and a pyramid ratio below the threshold are put in sight,
    /// each once, and only when pyramids are judged.
    #[test]
    fn pyramids_are_watched_where_they_are_low_and_a_node_is_free() {
        let thin = crate::geometry::quality::tests::warped_slab(0.1, [0.03, 0.001, 0.001, 0.001]);
        let square = crate::geometry::quality::tests::warped_slab(0.0, [1.0; 4]);
        let nodes: Vec<Point3<f64>> = thin.iter().chain(&square).copied().collect();
        let elements: Vec<Hex> = vec![[0, 1, 2, 3, 4, 5, 6, 7], [8, 9, 10, 11, 12, 13, 14, 15]];
        let mut free = vec![Freedom::Free; 16];
        let mut validity = vec![Validity::Corners; 2];
        let watch = |free: &[Freedom], judged, validity: &mut [Validity]| {
            watch_pyramids(&nodes, &elements, free, judged, PYRAMID_WATCH, validity)
        };
        assert!(watch(&free, Validity::Corners, &mut validity).is_empty());
        assert_eq!(watch(&free, Validity::CornersAndPyramids, &mut validity), vec![0], "the thin cell alone");
        assert_eq!(validity, [Validity::CornersAndPyramids, Validity::Corners]);
        assert!(watch(&free, Validity::CornersAndPyramids, &mut validity).is_empty(), "watched once");
        free[..8].fill(Freedom::Fixed);
        let mut fresh = vec![Validity::Corners; 2];
        assert!(watch(&free, Validity::CornersAndPyramids, &mut fresh).is_empty(), "no free node");
    }
    use crate::data::config::MeshConfig;
    use crate::stages::centerline::CenterlineTree;
    use crate::stages::projection::{project_branch, ProjectionSetup};
    use crate::testing::{straight_tube_centerline, straight_tube_surface};

    /// Two tubes side by side, one with a square core and one with a rectangular core: each
    /// branch's counts follow its own template, every hex is valid and the lumen-surface nodes
    /// lie on the tube.
    #[test]
    fn branches_take_their_own_templates() {
        let (radius, length) = (2.0, 20.0);
        let config = MeshConfig::default();
        let tube = straight_tube_surface(radius, length, 96, 40);
        let surface = LumenSurface::new(&tube).unwrap();
        let tree = CenterlineTree::build(&straight_tube_centerline(radius, length), &config.centerline, Some(&surface))
            .unwrap();
        let spacing = |_: &crate::stages::centerline::CenterlineSample| 1.0;
        let templates = [SectionTemplate::new(4, 0.5, 3.0), SectionTemplate::rect(4, 2, 0.5, 3.0)];
        let projected: Vec<ProjectedBranch> = templates
            .iter()
            .enumerate()
            .map(|(b, template)| {
                let setup = ProjectionSetup {
                    template,
                    surface: &surface,
                    spacing: &spacing,
                    junction_spacing: &spacing,
                    trim_inlet: 0.0,
                    trim_outlet: 0.0,
                    normals_outward: true,
                    steep_short_branches: false,
                    dome_end: false,
                };
                project_branch(&tree.branches[0], &Default::default(), b, &setup, None, None).unwrap()
            })
            .collect();
        let layers = config.wall.layers();
        let levels = RadialLevels::new(graded_levels(3, 1.2), &layers);
        let thickness = |r: f64| 0.1 * r;
        let names = vec!["square".to_string(), "rectangular".to_string()];
        let inputs = VolumeInputs {
            projected: &projected,
            templates: &templates,
            junctions: &[],
            levels: &levels,
            layers: &layers,
            wall_thickness: &thickness,
            wall_growth: WallGrowth::Ray,
            branch_names: &names,
            surface: &surface,
        };
        let (meshes, _) = build_volume(&inputs, JunctionOptimisation::default(), &[JunctionWall::default()]);
        let mesh = &meshes[0];
        let (r_cells, w_cells) = (levels.lumen_cells(), levels.wall_cells());
        for (b, t) in templates.iter().enumerate() {
            let intervals = projected[b].sections.len() - 1;
            let of_branch = |range: std::ops::Range<usize>| range.filter(|&e| mesh.branch_of[e] as usize == b).count();
            assert_eq!(of_branch(mesh.lumen_range()), intervals * (t.nx * t.ny + t.ring_len() * r_cells), "branch {b}");
            assert_eq!(of_branch(mesh.wall_range()), intervals * t.ring_len() * w_cells, "branch {b}");
        }
        for e in 0..mesh.hexes.len() {
            let q = crate::geometry::quality::scaled_jacobian(&mesh.corners(e));
            assert!(q > 0.2, "element {e} of branch {} has scaled Jacobian {q}", mesh.branch_of[e]);
        }
        let interface = &mesh.node_sets[crate::geometry::mesh::sets::INTERFACE_NODES];
        let per_branch: usize = templates.iter().zip(&projected).map(|(t, p)| t.ring_len() * p.sections.len()).sum();
        assert_eq!(interface.len(), per_branch);
        for &n in interface {
            let p = mesh.nodes[n as usize];
            let off_axis = (p.x * p.x + p.y * p.y).sqrt();
            assert!((off_axis - radius).abs() < 0.02 * radius, "interface node {n} at {off_axis} mm from the axis");
        }
    }
}
