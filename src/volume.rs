//! Volume mesh of the lumen (core + lateral blocks) and of the three-layer wall, from the
//! projected sections of a branch.
//!
//! Node layout per station (station-major, so neighbouring stations are close in memory):
//! the (N+1)^2 core nodes, then ring levels 1..=R of the lumen (level R is the lumen surface,
//! shared with the wall), then the wall levels. Ring level 0 is the core boundary. Elements are
//! ordered lumen, intima, media, adventitia, each station interval by station interval.

use crate::blocks::SectionTemplate;
use crate::config::WallGrowth;
use crate::junction::{FoldKey, JunctionGeometry};
use crate::mesh::{
    sets, ElementFace, Hex, Region, VesselEnd, VesselMesh, WallLayer, FACE_DOWNSTREAM, FACE_INNER, FACE_OUTER,
    FACE_UPSTREAM, HEX_EDGES,
};
use crate::node_optimisation::{optimise_nodes, Freedom, PYRAMID_TARGET};
use crate::projection::{BranchEnd, ProjectedBranch};
use crate::quality::Validity;
use crate::surface::LumenSurface;
use crate::surface_smoothing::{smooth_on_surface, RayNode, SmoothedNode};
use crate::wall_directions::{surface_normals, SurfaceGraph, JUNCTION_SMOOTHING_PASSES};
use indexmap::IndexMap;
use nalgebra::{Point3, Vector3};
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

/// Node numbering of one branch: for each station, its core nodes then its lumen ring levels
/// 1..=R (level R is the lumen surface). Ring level 0 is the core boundary.
struct BranchNodes {
    /// Per station: (N+1)^2 core ids then R * ring ids.
    stations: Vec<Vec<u32>>,
    /// A dome's top grid (see [`crate::projection::DomeTop`]): per lumen level 0..=R, the ids of
    /// the core grid's nodes; level 0 is the last station's core, the boundary of level l its
    /// ring level l.
    dome_top: Option<Vec<Vec<u32>>>,
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
/// unbranched vessel). Triads, fibres and quality are filled in by [`crate::annotate`].
///
/// Nodes of a folded end section are shared between the branches of a junction through their
/// [`FoldKey`]; the wall grows from the lumen-surface nodes once per node, so the junction's
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
    let VolumeInputs {
        projected,
        templates,
        junctions,
        levels,
        layers,
        wall_thickness,
        wall_growth,
        branch_names,
        surface,
    } = *inputs;
    assert!(!junction_walls.is_empty(), "at least one wall is asked for");
    assert_eq!(templates.len(), projected.len(), "one template per branch");
    // Ring length of each branch.
    let ring_len = |b: usize| templates[b].ring_len();
    let r_cells = levels.lumen_cells();
    let w_cells = levels.wall_cells();

    // Lumen nodes, branch by branch and station by station; folded sections through the pool.
    let mut nodes: Vec<Point3<f64>> = Vec::new();
    let mut pool: HashMap<FoldKey, u32> = HashMap::new();
    // Per node: the section radius and ray direction it was placed with (surface nodes only).
    let mut node_radius: Vec<f64> = Vec::new();
    // Nodes of junction sections, whose wall directions get extra smoothing.
    let mut junction_node: Vec<bool> = Vec::new();
    let mut node_ray: Vec<Vector3<f64>> = Vec::new();
    // How each node may move in the junction optimisation.
    let mut movable: Vec<Freedom> = Vec::new();
    // How each node may move when it is near a poor element (see `improve_poor`).
    let mut poor_mobility: Vec<Freedom> = Vec::new();
    let mut branch_nodes: Vec<BranchNodes> = Vec::with_capacity(projected.len());
    // The transitions' surface nodes (the pages' rims too), each with its ray's ring nodes.
    let mut smoothed_columns: IndexMap<u32, Vec<RayNode>> = IndexMap::new();
    for (pb, template) in projected.iter().zip(templates) {
        let (nx, m, core_count) = (template.nx, template.ring_len(), template.core_len());
        let last = pb.sections.len() - 1;
        let mut stations = Vec::with_capacity(pb.sections.len());
        for (i, sec) in pb.sections.iter().enumerate() {
            let fold = match (i, pb.start, pb.end) {
                (0, BranchEnd::Fold(f), _) => Some(f),
                (i, _, BranchEnd::Fold(f)) if i == last => Some(f),
                _ => None,
            };
            let mut ids = Vec::with_capacity(core_count + r_cells * m);
            // A folded section's nodes are the pages' (pooled: one node whichever slot adds it,
            // with the same mobility), so moving them keeps the junction conformal.
            let inner_movable = sec.in_junction && (fold.is_none() || optimisation.move_pages);
            // A vessel end's section stays as it is (its nodes are the end's sets and plane).
            let vessel_end = (i == 0 && matches!(pb.start, BranchEnd::Vessel { .. }))
                || (i == last && matches!(pb.end, BranchEnd::Vessel { .. }));
            let surface_movable = optimisation.slide_surface_nodes && inner_movable && !vessel_end;
            let in_junction = sec.in_junction;
            let (poor_inner, poor_surface) =
                if vessel_end { (Freedom::Fixed, Freedom::Fixed) } else { (Freedom::Free, Freedom::OnSurface) };
            let mut add = |key: Option<FoldKey>,
                           p: Point3<f64>,
                           radius: f64,
                           ray: Vector3<f64>,
                           free: Freedom,
                           poor: Freedom|
             -> u32 {
                if let Some(key) = key {
                    if let Some(&id) = pool.get(&key) {
                        return id;
                    }
                }
                let id = nodes.len() as u32;
                nodes.push(p);
                node_radius.push(radius);
                junction_node.push(in_junction);
                node_ray.push(ray);
                movable.push(free);
                poor_mobility.push(poor);
                if let Some(key) = key {
                    pool.insert(key, id);
                }
                id
            };
            let key = |c: usize, level: usize| {
                fold.map(|f| FoldKey::new(&junctions[f.junction], &f, template, c % (nx + 1), c / (nx + 1), level))
            };
            for (c, p) in sec.core.iter().enumerate() {
                let free = if inner_movable { Freedom::Free } else { Freedom::Fixed };
                ids.push(add(key(c, 0), *p, sec.station.radius, Vector3::zeros(), free, poor_inner));
            }
            for (level, &rho) in levels.lumen.iter().enumerate().skip(1) {
                for k in 0..m {
                    let (a, b) = (sec.origins[k], sec.surface[k]);
                    // The surface level is the hit point itself, bit for bit.
                    let p = if rho == 1.0 { b } else { a + (b - a) * rho };
                    let free = if inner_movable && level < r_cells {
                        Freedom::Free
                    } else if surface_movable && level == r_cells {
                        Freedom::OnSurface
                    } else {
                        Freedom::Fixed
                    };
                    let poor = if level < r_cells { poor_inner } else { poor_surface };
                    ids.push(add(
                        key(template.ring_core_index[k], level),
                        p,
                        sec.station.radius,
                        sec.dirs[k],
                        free,
                        poor,
                    ));
                }
            }
            if in_junction && !vessel_end {
                add_columns(&mut smoothed_columns, &ids, template, sec, levels);
            }
            stations.push(ids);
        }
        // A dome's top: new nodes on the top rays, the last station's where they meet it.
        let dome_top = pb.dome.as_ref().map(|dome| {
            let last = &stations[stations.len() - 1];
            let mut ring_point = vec![None; core_count];
            for (k, &c) in template.ring_core_index.iter().enumerate() {
                ring_point[c] = Some(k);
            }
            let radius = pb.sections[pb.sections.len() - 1].station.radius;
            let mut top = vec![last[..core_count].to_vec()];
            for (level, &rho) in levels.lumen.iter().enumerate().skip(1) {
                let mut ids = Vec::with_capacity(core_count);
                for (c, k) in ring_point.iter().enumerate() {
                    if let Some(k) = k {
                        ids.push(last[core_count + (level - 1) * m + k]);
                        continue;
                    }
                    let (a, b) = (dome.origins[c], dome.surface[c]);
                    ids.push(nodes.len() as u32);
                    nodes.push(if rho == 1.0 { b } else { a + (b - a) * rho });
                    node_radius.push(radius);
                    junction_node.push(false);
                    node_ray.push(dome.dirs[c]);
                    movable.push(Freedom::Fixed);
                    poor_mobility.push(if level < r_cells { Freedom::Free } else { Freedom::OnSurface });
                }
                top.push(ids);
            }
            top
        });
        branch_nodes.push(BranchNodes { stations, dome_top });
    }
    // A hex of a dome's top between two of its levels over core quad `q`, in the canonical order
    // (radial = from `below` to `above`, circumferential along the quad's first edge, axial
    // along its last: on the top, the radial direction is the tangent's, and t x n = b).
    let top_hex = |below: &[u32], above: &[u32], q: &[usize; 4]| -> Hex {
        [below[q[0]], above[q[0]], above[q[1]], below[q[1]], below[q[3]], above[q[3]], above[q[2]], below[q[2]]]
    };
    let lumen_ring = |b: usize, i: usize, level: usize, k: usize| -> u32 {
        let st = &branch_nodes[b].stations[i];
        let template = &templates[b];
        let m = template.ring_len();
        let k = k % m;
        if level == 0 {
            st[template.ring_core_index[k]]
        } else {
            st[template.core_len() + (level - 1) * m + k]
        }
    };

    // The lumen surface as quads, each wound so that its normal leaves the lumen: circumferential
    // x axial, the ring running counter-clockwise about each branch's flow direction.
    let mut quads: Vec<[u32; 4]> = Vec::new();
    for (b, pb) in projected.iter().enumerate() {
        for i in 0..pb.sections.len() - 1 {
            for k in 0..ring_len(b) {
                quads.push([
                    lumen_ring(b, i, r_cells, k),
                    lumen_ring(b, i, r_cells, k + 1),
                    lumen_ring(b, i + 1, r_cells, k + 1),
                    lumen_ring(b, i + 1, r_cells, k),
                ]);
            }
        }
        if let Some(top) = &branch_nodes[b].dome_top {
            let surface = &top[r_cells];
            quads.extend(
                templates[b].core_quads().iter().map(|q| [surface[q[0]], surface[q[1]], surface[q[2]], surface[q[3]]]),
            );
        }
    }
    // Vessel-end stations: their wall nodes stay in the end planes.
    let mut end_tangent: HashMap<u32, Vector3<f64>> = HashMap::new();
    for (b, pb) in projected.iter().enumerate() {
        let last = pb.sections.len() - 1;
        for (i, is_end) in
            [(0, matches!(pb.start, BranchEnd::Vessel { .. })), (last, matches!(pb.end, BranchEnd::Vessel { .. }))]
        {
            if is_end {
                for k in 0..ring_len(b) {
                    end_tangent.insert(lumen_ring(b, i, r_cells, k), pb.sections[i].station.frame.tangent);
                }
            }
        }
    }
    // Wall nodes: W levels above every lumen-surface node, in surface-node order.
    let graph = SurfaceGraph::new(&quads, nodes.len());
    if optimisation.smooth_surface {
        // In node order, so the Gauss-Seidel passes do not depend on the branches' order.
        smoothed_columns.sort_keys();
        let smoothed: Vec<SmoothedNode> = smoothed_columns
            .into_iter()
            .map(|(node, column)| {
                let around = &graph.neighbours[graph.position[node as usize]];
                SmoothedNode { node, neighbours: around.iter().map(|&j| graph.nodes[j]).collect(), column }
            })
            .collect();
        smooth_on_surface(&mut nodes, &smoothed, surface);
    }
    let surface_nodes = &graph.nodes;
    let nominal: Vec<f64> = surface_nodes.iter().map(|&s| wall_thickness(node_radius[s as usize])).collect();
    // Growth direction and thickness at every surface node, from the surface as it stands.
    let growth = |nodes: &[Point3<f64>], junction_wall: JunctionWall| -> (Vec<Vector3<f64>>, Vec<f64>) {
        let dirs: Vec<Vector3<f64>> = match wall_growth {
            WallGrowth::Ray => graph.nodes.iter().map(|&s| node_ray[s as usize]).collect(),
            WallGrowth::Normal => {
                let junction_passes = match junction_wall {
                    JunctionWall::Normal => 0,
                    _ => JUNCTION_SMOOTHING_PASSES,
                };
                let mut dirs = surface_normals(
                    nodes,
                    &quads,
                    &graph,
                    &node_ray,
                    &end_tangent,
                    &junction_node,
                    junction_passes,
                    &nominal,
                );
                // Along the rays in junction transitions, where asked: the caller keeps whichever
                // wall is better (see `build_volume`'s caller).
                if junction_wall == JunctionWall::Ray {
                    for (d, &s) in dirs.iter_mut().zip(&graph.nodes) {
                        if junction_node[s as usize] && !end_tangent.contains_key(&s) {
                            *d = node_ray[s as usize].normalize();
                        }
                    }
                }
                dirs
            }
        };
        let thickness = crotch_limited_thickness(nodes, &graph, &dirs, surface, &nominal, !junctions.is_empty());
        (dirs, thickness)
    };
    // Their ids now; their places once the junction optimisation has settled the surface.
    let mut wall_base = vec![u32::MAX; nodes.len()];
    for &s in surface_nodes {
        wall_base[s as usize] = nodes.len() as u32;
        let p = nodes[s as usize];
        nodes.extend(levels.wall[1..].iter().map(|_| p));
    }
    let ring = |b: usize, i: usize, level: usize, k: usize| -> u32 {
        if level <= r_cells {
            lumen_ring(b, i, level, k)
        } else {
            wall_base[lumen_ring(b, i, r_cells, k) as usize] + (level - r_cells - 1) as u32
        }
    };
    // Hex between stations i, i+1, ring levels level, level+1 and ring points k, k+1; canonical
    // order: radial x circumferential = axial, so the Jacobian is positive.
    let ring_hex = |b: usize, i: usize, level: usize, k: usize| -> Hex {
        [
            ring(b, i, level, k),
            ring(b, i, level + 1, k),
            ring(b, i, level + 1, k + 1),
            ring(b, i, level, k + 1),
            ring(b, i + 1, level, k),
            ring(b, i + 1, level + 1, k),
            ring(b, i + 1, level + 1, k + 1),
            ring(b, i + 1, level, k + 1),
        ]
    };

    // Vessel ends: the inlet, then the outlets in branch order.
    let outlets = projected.iter().filter(|p| matches!(p.end, BranchEnd::Vessel { .. })).count();
    let mut end_names: Vec<(usize, bool, String)> = Vec::new(); // (branch, is_inlet, name)
    let mut outlet_no = 0;
    for (b, pb) in projected.iter().enumerate() {
        if matches!(pb.start, BranchEnd::Vessel { .. }) {
            end_names.push((b, true, "inlet".to_string()));
        }
        if matches!(pb.end, BranchEnd::Vessel { .. }) {
            outlet_no += 1;
            let name = if outlets == 1 { "outlet".to_string() } else { format!("outlet_{outlet_no}") };
            end_names.push((b, false, name));
        }
    }
    let end_name = |b: usize, inlet: bool| -> Option<&str> {
        end_names.iter().find(|e| e.0 == b && e.1 == inlet).map(|e| e.2.as_str())
    };

    let ef = |element: usize, face: usize| ElementFace { element: element as u32, face: face as u8 };
    let mut node_sets: IndexMap<String, Vec<u32>> = IndexMap::new();
    let mut face_sets: IndexMap<String, Vec<ElementFace>> = IndexMap::new();
    for key in [sets::LUMEN_WALL_FACES, sets::WALL_LUMEN_FACES, sets::WALL_OUTER_FACES] {
        face_sets.insert(key.into(), vec![]);
    }
    for (_, _, name) in &end_names {
        face_sets.insert(sets::lumen_end(name), vec![]);
        face_sets.insert(sets::wall_end(name), vec![]);
    }
    let mut add_face =
        |set: &str, e: usize, face: usize| face_sets.get_mut(set).expect("declared above").push(ef(e, face));

    // Elements: lumen (core + lateral) of every branch, then each wall region.
    let mut hexes: Vec<Hex> = Vec::new();
    let mut regions = Vec::new();
    let mut branch_of = Vec::new();
    // The junction each element belongs to (transition intervals), for the report.
    let mut junction_of: Vec<Option<usize>> = Vec::new();
    let interval_junction = |pb: &ProjectedBranch, i: usize| -> Option<usize> {
        if !(pb.sections[i].in_junction || pb.sections[i + 1].in_junction) {
            return None;
        }
        // The nearer end's junction first (a branch between two junctions has both).
        let ends = if i < pb.sections.len() / 2 { [pb.start, pb.end] } else { [pb.end, pb.start] };
        ends.iter().find_map(|e| match e {
            BranchEnd::Fold(f) => Some(f.junction),
            BranchEnd::Vessel { .. } | BranchEnd::Dome => None,
        })
    };
    let core_quads: Vec<Vec<[usize; 4]>> = templates.iter().map(|t| t.core_quads()).collect();
    for (b, pb) in projected.iter().enumerate() {
        let last = pb.sections.len() - 2;
        for i in 0..=last {
            let st = (&branch_nodes[b].stations[i], &branch_nodes[b].stations[i + 1]);
            let first_of_interval = hexes.len();
            for q in &core_quads[b] {
                hexes.push([
                    st.0[q[0]], st.0[q[1]], st.0[q[2]], st.0[q[3]], st.1[q[0]], st.1[q[1]], st.1[q[2]], st.1[q[3]],
                ]);
            }
            for level in 0..r_cells {
                for k in 0..ring_len(b) {
                    if level == r_cells - 1 {
                        add_face(sets::LUMEN_WALL_FACES, hexes.len(), FACE_OUTER);
                    }
                    hexes.push(ring_hex(b, i, level, k));
                }
            }
            for (cond, inlet, face) in [(i == 0, true, FACE_UPSTREAM), (i == last, false, FACE_DOWNSTREAM)] {
                if let (true, Some(name)) = (cond, end_name(b, inlet)) {
                    for e in first_of_interval..hexes.len() {
                        add_face(&sets::lumen_end(name), e, face);
                    }
                }
            }
            branch_of.resize(hexes.len(), b as u32);
            junction_of.resize(hexes.len(), interval_junction(pb, i));
        }
        if let Some(top) = &branch_nodes[b].dome_top {
            for level in 0..r_cells {
                for q in &core_quads[b] {
                    if level == r_cells - 1 {
                        add_face(sets::LUMEN_WALL_FACES, hexes.len(), FACE_OUTER);
                    }
                    hexes.push(top_hex(&top[level], &top[level + 1], q));
                }
            }
            branch_of.resize(hexes.len(), b as u32);
            junction_of.resize(hexes.len(), None);
        }
    }
    regions.resize(hexes.len(), Region::Lumen);
    let by_corners = vec![Validity::Corners; hexes.len()];
    improve_junction_nodes(&mut nodes, &hexes, &movable, surface, optimisation.pattern_search, &by_corners);
    // The lumen is OpenFOAM's mesh: its poor elements are judged with the face pyramids too, and
    // optimised with them in the objective. By the corners alone, the optimisation flattened a
    // crotch cell of gmsh_bifurcation (medium) until its centre left its wall face's plane.
    improve_poor(&mut nodes, &hexes, &poor_mobility, surface, Validity::CornersAndPyramids);
    // The wall grows from the surface where its nodes ended up (they may have slid).
    let lay_wall = |nodes: &mut [Point3<f64>], junction_wall: JunctionWall| -> Vec<Vector3<f64>> {
        let (dirs, thickness) = growth(nodes, junction_wall);
        for ((&s, dir), t) in surface_nodes.iter().zip(&dirs).zip(&thickness) {
            let p = nodes[s as usize];
            for (w, &tau) in levels.wall[1..].iter().enumerate() {
                nodes[wall_base[s as usize] as usize + w] = p + dir * (t * tau);
            }
        }
        dirs
    };
    let first_dirs = lay_wall(&mut nodes, junction_walls[0]);
    for region in Region::WALL {
        for (b, pb) in projected.iter().enumerate() {
            let last = pb.sections.len() - 2;
            for i in 0..=last {
                for (w, r) in levels.wall_regions.iter().enumerate() {
                    if *r != region {
                        continue;
                    }
                    for k in 0..ring_len(b) {
                        let e = hexes.len();
                        if w == 0 {
                            add_face(sets::WALL_LUMEN_FACES, e, FACE_INNER);
                        }
                        if w == w_cells - 1 {
                            add_face(sets::WALL_OUTER_FACES, e, FACE_OUTER);
                        }
                        for (cond, inlet, face) in [(i == 0, true, FACE_UPSTREAM), (i == last, false, FACE_DOWNSTREAM)]
                        {
                            if let (true, Some(name)) = (cond, end_name(b, inlet)) {
                                add_face(&sets::wall_end(name), e, face);
                            }
                        }
                        hexes.push(ring_hex(b, i, r_cells + w, k));
                        regions.push(region);
                        branch_of.push(b as u32);
                        junction_of.push(interval_junction(pb, i));
                    }
                }
            }
            let Some(top) = &branch_nodes[b].dome_top else { continue };
            let wall_level = |w: usize| -> Vec<u32> {
                top[r_cells].iter().map(|&s| if w == 0 { s } else { wall_base[s as usize] + (w - 1) as u32 }).collect()
            };
            for (w, r) in levels.wall_regions.iter().enumerate() {
                if *r != region {
                    continue;
                }
                let (below, above) = (wall_level(w), wall_level(w + 1));
                for q in &core_quads[b] {
                    let e = hexes.len();
                    if w == 0 {
                        add_face(sets::WALL_LUMEN_FACES, e, FACE_INNER);
                    }
                    if w == w_cells - 1 {
                        add_face(sets::WALL_OUTER_FACES, e, FACE_OUTER);
                    }
                    hexes.push(top_hex(&below, &above, q));
                    regions.push(region);
                    branch_of.push(b as u32);
                    junction_of.push(None);
                }
            }
        }
    }

    // Where the wall has an element below the bar (the lumen's optimisation does not see the
    // wall), the wall nodes around it move across their growth directions, so the wall keeps
    // its thickness.
    // gmsh_aortic_arch at medium: a junction's wall 0.116 -> 0.216; gmsh_cerebral_aneurysm at
    // medium: an intima element inverted (-0.147) where the wall grows over the sac's neck.
    // Walls above the bar stay as grown (raising their worst element costs their mean a little).
    let wall_hexes: Vec<Hex> = (0..hexes.len()).filter(|&e| regions[e].is_wall()).map(|e| hexes[e]).collect();
    let improve_wall = |nodes: &mut [Point3<f64>], dirs: &[Vector3<f64>]| {
        let mut wall_movable = vec![Freedom::Fixed; nodes.len()];
        for (&s, d) in surface_nodes.iter().zip(dirs) {
            if !end_tangent.contains_key(&s) {
                for w in 0..w_cells {
                    wall_movable[wall_base[s as usize] as usize + w] = Freedom::Across(*d);
                }
            }
        }
        // By the corners alone: a wall node moves only across its growth direction, which cannot
        // thicken a cell, and the wall's crotch cells whose pyramids fail are thin ones (judged
        // with the pyramids, gmsh_carotid_bifurcation at medium kept them at -1 through every
        // round and took 2.7 times the CPU time). A finish whose wall fails a pyramid loses to one
        // whose wall does not (see `pipeline::mesh_tree`'s judge).
        improve_poor(nodes, &wall_hexes, &wall_movable, surface, Validity::Corners);
    };
    improve_wall(&mut nodes, &first_dirs);

    // Node sets: the interface, the outer wall, and each end's lumen and wall nodes.
    node_sets.insert(sets::INTERFACE_NODES.into(), surface_nodes.clone());
    node_sets.insert(
        sets::OUTER_WALL_NODES.into(),
        surface_nodes.iter().map(|&s| wall_base[s as usize] + (w_cells - 1) as u32).collect(),
    );
    let mut ends = Vec::new();
    for (b, is_inlet, name) in &end_names {
        let pb = &projected[*b];
        let i = if *is_inlet { 0 } else { pb.sections.len() - 1 };
        node_sets.insert(sets::lumen_end(name), branch_nodes[*b].stations[i].clone());
        let wall: Vec<u32> = (r_cells..=r_cells + w_cells)
            .flat_map(|l| (0..ring_len(*b)).map(move |k| (l, k)))
            .map(|(l, k)| ring(*b, i, l, k))
            .collect();
        node_sets.insert(sets::wall_end(name), wall);
        let station = &pb.sections[i].station;
        let t = station.frame.tangent;
        ends.push(VesselEnd {
            name: name.clone(),
            is_inlet: *is_inlet,
            branch: *b,
            centre: station.point,
            outward_normal: if *is_inlet { -t } else { t },
        });
    }
    for v in node_sets.values_mut() {
        v.sort_unstable();
        v.dedup();
    }
    for v in face_sets.values_mut() {
        v.sort_unstable();
    }

    let mesh = VesselMesh {
        nodes,
        hexes,
        regions,
        branch_of,
        triads: Vec::new(),
        fibres: Vec::new(),
        quality: Vec::new(),
        layers: layers.to_vec(),
        ends,
        node_sets,
        face_sets,
        branch_names: branch_names.to_vec(),
    };
    let mut meshes = Vec::with_capacity(junction_walls.len());
    for &junction_wall in &junction_walls[1..] {
        let mut other = mesh.clone();
        let dirs = lay_wall(&mut other.nodes, junction_wall);
        improve_wall(&mut other.nodes, &dirs);
        meshes.push(other);
    }
    meshes.insert(0, mesh);
    (meshes, junction_of)
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
pub(crate) const QUALITY_BAR_SJ: f64 = crate::quality::Bars::MIN_SCALED_JACOBIAN;
/// The bar on the wall's mean scaled Jacobian (FEA practice wants a mean above 0.8).
pub(crate) const WALL_MEAN_BAR_SJ: f64 = crate::quality::Bars::WALL_MEAN_SCALED_JACOBIAN;

/// How a branched vessel's junctions are finished; the caller builds the variants and keeps
/// the best (see `pipeline::mesh_tree`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct JunctionVariant {
    pub wall: JunctionWall,
    pub optimisation: JunctionOptimisation,
}

/// How the wall grows from the lumen-surface nodes of junction transitions when it grows along
/// the normals ([`WallGrowth::Normal`]; along the rays it does so everywhere). The caller
/// builds each on the same lumen and keeps the best (see `pipeline::mesh_tree`).
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
    /// ([`crate::surface_smoothing`]): it lifts the wall's mean, but can lower the worst element.
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
    let mut incident: HashMap<u32, Vec<usize>> = HashMap::new();
    let mut neighbours: HashMap<u32, Vec<u32>> = HashMap::new();
    for (e, h) in lumen.iter().enumerate() {
        for (c, &n) in h.iter().enumerate() {
            if movable[n as usize] != Freedom::Fixed {
                incident.entry(n).or_default().push(e);
                let nb = neighbours.entry(n).or_default();
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
    for nb in neighbours.values_mut() {
        nb.sort_unstable();
        nb.dedup();
    }
    // A surface node's neighbours along the surface: the other corners of its outer faces
    // that share an edge with it.
    let on_outer_face: HashMap<u32, Vec<u32>> = free
        .iter()
        .filter(|&&n| movable[n as usize] == Freedom::OnSurface)
        .map(|&n| {
            let mut nb: Vec<u32> = Vec::new();
            for &e in &incident[&n] {
                let outer = crate::mesh::face_nodes(&lumen[e], crate::mesh::FACE_OUTER);
                if let Some(at) = outer.iter().position(|&x| x == n) {
                    nb.push(outer[(at + 1) % 4]);
                    nb.push(outer[(at + 3) % 4]);
                }
            }
            nb.sort_unstable();
            nb.dedup();
            (n, nb)
        })
        .collect();
    // The worst element, each by its `validity`, or, once it is at most `floor`, some value at
    // most `floor`: a trial move is only ever compared with a floor.
    // `first`, the element that was worst before the move, is measured first: a move that
    // does not help mostly fails there.
    let worst = |nodes: &[Point3<f64>], elements: &[usize], first: usize, floor: f64| -> f64 {
        let mut min = f64::INFINITY;
        for &e in std::iter::once(&first).chain(elements.iter().filter(|&&e| e != first)) {
            min = min.min(validity[e].unless_below(&lumen[e].map(|n| nodes[n as usize]), floor));
            if min <= floor {
                break;
            }
        }
        min
    };
    // Each element's validity, known until one of its corners moves: a node's elements are
    // measured before each trial move, mostly unchanged since the last.
    let mut known: Vec<Option<f64>> = vec![None; lumen.len()];
    let worst_cached = |known: &mut [Option<f64>], nodes: &[Point3<f64>], elements: &[usize]| -> f64 {
        elements
            .iter()
            .map(|&e| {
                *known[e].get_or_insert_with(|| {
                    validity[e].unless_below(&lumen[e].map(|n| nodes[n as usize]), f64::NEG_INFINITY)
                })
            })
            .fold(f64::INFINITY, f64::min)
    };
    // A node tried without moving gives the same answer again until a corner of one of its
    // elements moves, so it is skipped until then (the result is the same as trying it).
    let corners: HashMap<u32, Vec<u32>> = free
        .iter()
        .map(|&n| {
            let mut c: Vec<u32> = incident[&n].iter().flat_map(|&e| lumen[e]).filter(|&x| x != n).collect();
            c.sort_unstable();
            c.dedup();
            (n, c)
        })
        .collect();
    let mut moves: u64 = 0;
    let mut moved_at: HashMap<u32, u64> = HashMap::new();
    let mut still_since: HashMap<u32, u64> = HashMap::new();
    let all_incident: Vec<usize> = {
        let mut v: Vec<usize> = incident.values().flatten().copied().collect();
        v.sort_unstable();
        v.dedup();
        v
    };
    // The worst element after each sweep past OPTIMISATION_SWEEPS.
    let mut worst_after: Vec<f64> = Vec::new();
    for sweep in 0..MAX_OPTIMISATION_SWEEPS {
        if sweep >= OPTIMISATION_SWEEPS {
            let now = worst_cached(&mut known, nodes, &all_incident);
            let stalled = worst_after.len() >= STALLED_SWEEPS
                && now <= worst_after[worst_after.len() - STALLED_SWEEPS] + STALLED_GAIN;
            if now > QUALITY_BAR_SJ || stalled {
                break;
            }
            worst_after.push(now);
        }
        let moves_before = moves;
        for &n in &free {
            if let Some(&since) = still_since.get(&n) {
                if corners[&n].iter().all(|c| moved_at.get(c).is_none_or(|&t| t <= since)) {
                    continue;
                }
            }
            let elements = &incident[&n];
            let on_surface = movable[n as usize] == Freedom::OnSurface;
            let nb = if on_surface { &on_outer_face[&n] } else { &neighbours[&n] };
            if nb.is_empty() {
                continue;
            }
            let centroid = nb.iter().fold(Vector3::zeros(), |acc, &j| acc + nodes[j as usize].coords) / nb.len() as f64;
            let old = nodes[n as usize];
            let before = worst_cached(&mut known, nodes, elements);
            let first = *elements
                .iter()
                .min_by(|&&a, &&b| known[a].unwrap_or(f64::INFINITY).total_cmp(&known[b].unwrap_or(f64::INFINITY)))
                .expect("a node's elements");
            let mut moved = false;
            let place = |p: Point3<f64>| match movable[n as usize] {
                Freedom::OnSurface => surface.closest(&p).point,
                Freedom::Across(d) => p - d * (p - old).dot(&d),
                _ => p,
            };
            for step in [1.0, 0.5, 0.25] {
                nodes[n as usize] = place(old + (Point3::from(centroid) - old) * step);
                if worst(nodes, elements, first, before + 1e-9) > before + 1e-9 {
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
                        let q = worst(nodes, elements, first, best.0 + 1e-9);
                        if q > best.0 + 1e-9 {
                            best = (q, nodes[n as usize]);
                        }
                    }
                }
                nodes[n as usize] = best.1;
                moved = best.1 != old;
            }
            if moved {
                moves += 1;
                moved_at.insert(n, moves);
                still_since.remove(&n);
                elements.iter().for_each(|&e| known[e] = None);
            } else {
                still_since.insert(n, moves);
            }
        }
        if moves == moves_before {
            break;
        }
    }
}

/// Records, for each surface node of a section, the ring nodes on its ray (once: a page's
/// nodes are added by every branch that folds onto it).
fn add_columns(
    columns: &mut IndexMap<u32, Vec<RayNode>>,
    ids: &[u32],
    template: &SectionTemplate,
    section: &crate::projection::ProjectedSection,
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
            && crate::quality::face_pyramid_ratio(&h.map(|n| nodes[n as usize])) < below
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
    use crate::blocks::graded_levels;

    /// Only elements with a free node and a pyramid ratio below the threshold are put in sight,
    /// each once, and only when pyramids are judged.
    #[test]
    fn pyramids_are_watched_where_they_are_low_and_a_node_is_free() {
        let thin = crate::quality::tests::warped_slab(0.1, [0.03, 0.001, 0.001, 0.001]);
        let square = crate::quality::tests::warped_slab(0.0, [1.0; 4]);
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
    use crate::centerline::CenterlineTree;
    use crate::config::MeshConfig;
    use crate::projection::{project_branch, ProjectionSetup};
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
        let spacing = |_: &crate::centerline::CenterlineSample| 1.0;
        let templates = [SectionTemplate::new(4, 0.5, 3.0), SectionTemplate::rect(4, 2, 0.5, 3.0)];
        let projected: Vec<ProjectedBranch> = templates
            .iter()
            .enumerate()
            .map(|(b, template)| {
                let setup = ProjectionSetup {
                    template,
                    surface: &surface,
                    spacing: &spacing,
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
            let q = crate::quality::scaled_jacobian(&mesh.corners(e));
            assert!(q > 0.2, "element {e} of branch {} has scaled Jacobian {q}", mesh.branch_of[e]);
        }
        let interface = &mesh.node_sets[crate::mesh::sets::INTERFACE_NODES];
        let per_branch: usize = templates.iter().zip(&projected).map(|(t, p)| t.ring_len() * p.sections.len()).sum();
        assert_eq!(interface.len(), per_branch);
        for &n in interface {
            let p = mesh.nodes[n as usize];
            let off_axis = (p.x * p.x + p.y * p.y).sqrt();
            assert!((off_axis - radius).abs() < 0.02 * radius, "interface node {n} at {off_axis} mm from the axis");
        }
    }
}
