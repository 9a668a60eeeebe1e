//! The lumen's nodes, placed branch by branch and station by station, and the numbering that
//! finds every node again by its place: a station's core and ring nodes, a dome's top grid, and
//! the wall nodes above each lumen-surface node.

use super::{add_columns, JunctionOptimisation, RadialLevels};
use crate::geometry::mesh::Hex;
use crate::stages::junction::blocks::SectionTemplate;
use crate::stages::junction::{FoldKey, JunctionGeometry};
use crate::stages::projection::{BranchEnd, DomeTop, ProjectedBranch};
use crate::stages::volume::node_optimisation::Freedom;
use crate::stages::volume::surface_smoothing::RayNode;
use indexmap::IndexMap;
use nalgebra::{Point3, Vector3};
use std::collections::HashMap;

/// The lumen's nodes, each with what the stages after its placement need of it.
#[derive(Default)]
pub(super) struct LumenNodes {
    pub nodes: Vec<Point3<f64>>,
    /// The radius of the section it was placed on (the wall's nominal thickness follows it).
    pub radius: Vec<f64>,
    /// Whether it lies on a junction's section (its wall direction gets extra smoothing).
    pub in_junction: Vec<bool>,
    /// The ray it was placed on (zero for a core node).
    pub ray: Vec<Vector3<f64>>,
    /// How it may move in the junction optimisation.
    pub movable: Vec<Freedom>,
    /// How it may move when it is near a poor element (see `improve_poor`).
    pub poor_mobility: Vec<Freedom>,
    /// The transitions' surface nodes (the pages' rims too), each with its ray's ring nodes.
    pub smoothed_columns: IndexMap<u32, Vec<RayNode>>,
    /// A folded section's nodes by key: one node whichever slot of the junction adds it.
    pool: HashMap<FoldKey, u32>,
}

/// A node to place and what it carries (see [`LumenNodes`]).
struct NewNode {
    point: Point3<f64>,
    radius: f64,
    in_junction: bool,
    ray: Vector3<f64>,
    movable: Freedom,
    poor_mobility: Freedom,
}

impl LumenNodes {
    /// The node's id: a new one, or the pooled node of its fold key.
    fn add(&mut self, key: Option<FoldKey>, node: NewNode) -> u32 {
        if let Some(&id) = key.as_ref().and_then(|key| self.pool.get(key)) {
            return id;
        }
        let id = self.nodes.len() as u32;
        self.nodes.push(node.point);
        self.radius.push(node.radius);
        self.in_junction.push(node.in_junction);
        self.ray.push(node.ray);
        self.movable.push(node.movable);
        self.poor_mobility.push(node.poor_mobility);
        if let Some(key) = key {
            self.pool.insert(key, id);
        }
        id
    }
}

/// Node numbering of one branch: for each station, its core nodes then its lumen ring levels
/// 1..=R (level R is the lumen surface). Ring level 0 is the core boundary.
pub(super) struct BranchNodes {
    /// Per station: (N+1)^2 core ids then R * ring ids.
    pub stations: Vec<Vec<u32>>,
    /// A dome's top grid (see [`crate::stages::projection::DomeTop`]): per lumen level 0..=R, the ids of
    /// the core grid's nodes; level 0 is the last station's core, the boundary of level l its
    /// ring level l.
    pub dome_top: Option<Vec<Vec<u32>>>,
}

/// Places the lumen's nodes, branch by branch and station by station (a dome's top after its
/// branch's last station); folded sections through the pool, so a junction's pages are shared.
pub(super) fn place_lumen_nodes(
    projected: &[ProjectedBranch],
    templates: &[SectionTemplate],
    junctions: &[JunctionGeometry],
    levels: &RadialLevels,
    optimisation: &JunctionOptimisation,
) -> (LumenNodes, Vec<BranchNodes>) {
    let mut lumen = LumenNodes::default();
    let mut branches = Vec::with_capacity(projected.len());
    for (pb, template) in projected.iter().zip(templates) {
        let stations: Vec<Vec<u32>> = (0..pb.sections.len())
            .map(|i| place_station(&mut lumen, pb, i, template, junctions, levels, optimisation))
            .collect();
        let dome_top = pb.dome.as_ref().map(|dome| place_dome_top(&mut lumen, dome, pb, &stations, template, levels));
        branches.push(BranchNodes { stations, dome_top });
    }
    (lumen, branches)
}

/// The ids of station `i`'s nodes: its core, then its ring levels 1..=R.
fn place_station(
    lumen: &mut LumenNodes,
    pb: &ProjectedBranch,
    i: usize,
    template: &SectionTemplate,
    junctions: &[JunctionGeometry],
    levels: &RadialLevels,
    optimisation: &JunctionOptimisation,
) -> Vec<u32> {
    let (nx, m, r_cells) = (template.nx, template.ring_len(), levels.lumen_cells());
    let sec = &pb.sections[i];
    let last = pb.sections.len() - 1;
    let fold = match (i, pb.start, pb.end) {
        (0, BranchEnd::Fold(f), _) => Some(f),
        (i, _, BranchEnd::Fold(f)) if i == last => Some(f),
        _ => None,
    };
    // A folded section's nodes are the pages' (pooled: one node whichever slot adds it, with
    // the same mobility), so moving them keeps the junction conformal.
    let inner_movable = sec.in_junction && (fold.is_none() || optimisation.move_pages);
    // A vessel end's section stays as it is (its nodes are the end's sets and plane).
    let vessel_end = (i == 0 && matches!(pb.start, BranchEnd::Vessel { .. }))
        || (i == last && matches!(pb.end, BranchEnd::Vessel { .. }));
    let surface_movable = optimisation.slide_surface_nodes && inner_movable && !vessel_end;
    let (poor_inner, poor_surface) =
        if vessel_end { (Freedom::Fixed, Freedom::Fixed) } else { (Freedom::Free, Freedom::OnSurface) };
    let key = |c: usize, level: usize| {
        fold.map(|f| FoldKey::new(&junctions[f.junction], &f, template, c % (nx + 1), c / (nx + 1), level))
    };
    let node = |point: Point3<f64>, ray: Vector3<f64>, movable: Freedom, poor_mobility: Freedom| NewNode {
        point,
        radius: sec.station.radius,
        in_junction: sec.in_junction,
        ray,
        movable,
        poor_mobility,
    };
    let mut ids = Vec::with_capacity(template.core_len() + r_cells * m);
    for (c, p) in sec.core.iter().enumerate() {
        let free = if inner_movable { Freedom::Free } else { Freedom::Fixed };
        ids.push(lumen.add(key(c, 0), node(*p, Vector3::zeros(), free, poor_inner)));
    }
    for (level, &rho) in levels.lumen.iter().enumerate().skip(1) {
        for k in 0..m {
            let p = on_ray(sec.origins[k], sec.surface[k], rho);
            let free = if inner_movable && level < r_cells {
                Freedom::Free
            } else if surface_movable && level == r_cells {
                Freedom::OnSurface
            } else {
                Freedom::Fixed
            };
            let poor = if level < r_cells { poor_inner } else { poor_surface };
            ids.push(lumen.add(key(template.ring_core_index[k], level), node(p, sec.dirs[k], free, poor)));
        }
    }
    if sec.in_junction && !vessel_end {
        add_columns(&mut lumen.smoothed_columns, &ids, template, sec, levels);
    }
    ids
}

/// The node at radial level `rho` (0 at the core, 1 at the surface) of a ray from `origin` to
/// its `hit` on the surface: the surface level is the hit point itself, bit for bit.
fn on_ray(origin: Point3<f64>, hit: Point3<f64>, rho: f64) -> Point3<f64> {
    if rho == 1.0 {
        hit
    } else {
        origin + (hit - origin) * rho
    }
}

/// A dome's top grid (see [`BranchNodes::dome_top`]): new nodes on the top rays, the last
/// station's where they meet it.
fn place_dome_top(
    lumen: &mut LumenNodes,
    dome: &DomeTop,
    pb: &ProjectedBranch,
    stations: &[Vec<u32>],
    template: &SectionTemplate,
    levels: &RadialLevels,
) -> Vec<Vec<u32>> {
    let (m, core_count, r_cells) = (template.ring_len(), template.core_len(), levels.lumen_cells());
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
            let node = NewNode {
                point: on_ray(dome.origins[c], dome.surface[c], rho),
                radius,
                in_junction: false,
                ray: dome.dirs[c],
                movable: Freedom::Fixed,
                poor_mobility: if level < r_cells { Freedom::Free } else { Freedom::OnSurface },
            };
            ids.push(lumen.add(None, node));
        }
        top.push(ids);
    }
    top
}

/// Finds a mesh's nodes by their place: ring level `level` (0 the core's boundary, R the lumen
/// surface, beyond it the wall's levels) of ring point `k` on station `i` of branch `b`.
pub(super) struct Numbering<'a> {
    pub branches: &'a [BranchNodes],
    templates: &'a [SectionTemplate],
    r_cells: usize,
    /// The first of the wall nodes above each lumen-surface node (`u32::MAX` elsewhere): they
    /// follow one another, innermost first.
    wall_base: Vec<u32>,
}

impl<'a> Numbering<'a> {
    pub fn new(branches: &'a [BranchNodes], templates: &'a [SectionTemplate], levels: &RadialLevels) -> Self {
        Numbering { branches, templates, r_cells: levels.lumen_cells(), wall_base: Vec::new() }
    }

    /// Gives the wall's nodes their ids, above each surface node in turn (placed on it, until
    /// the wall is laid).
    pub fn add_wall_nodes(&mut self, nodes: &mut Vec<Point3<f64>>, surface_nodes: &[u32], levels: &RadialLevels) {
        self.wall_base = vec![u32::MAX; nodes.len()];
        for &s in surface_nodes {
            self.wall_base[s as usize] = nodes.len() as u32;
            let p = nodes[s as usize];
            nodes.extend(levels.wall[1..].iter().map(|_| p));
        }
    }

    pub fn ring_len(&self, b: usize) -> usize {
        self.templates[b].ring_len()
    }

    /// The core's quads of branch `b`'s template (corner indices into a station's core).
    pub fn core_quads(&self, b: usize) -> Vec<[usize; 4]> {
        self.templates[b].core_quads()
    }

    /// A lumen node: `level` at most R.
    pub fn lumen_ring(&self, b: usize, i: usize, level: usize, k: usize) -> u32 {
        let st = &self.branches[b].stations[i];
        let template = &self.templates[b];
        let m = template.ring_len();
        let k = k % m;
        if level == 0 {
            st[template.ring_core_index[k]]
        } else {
            st[template.core_len() + (level - 1) * m + k]
        }
    }

    /// A lumen-surface node (ring level R).
    pub fn surface(&self, b: usize, i: usize, k: usize) -> u32 {
        self.lumen_ring(b, i, self.r_cells, k)
    }

    /// The lumen-surface nodes of branch `b`'s dome top, if it has one (core grid order).
    pub fn dome_surface(&self, b: usize) -> Option<&[u32]> {
        self.branches[b].dome_top.as_ref().map(|top| top[self.r_cells].as_slice())
    }

    /// The wall node `w` levels above the lumen-surface node `s` (`s` itself for 0).
    pub fn above(&self, s: u32, w: usize) -> u32 {
        if w == 0 {
            s
        } else {
            self.wall_base[s as usize] + (w - 1) as u32
        }
    }

    /// Any node of a ring, in the lumen or the wall.
    pub fn ring(&self, b: usize, i: usize, level: usize, k: usize) -> u32 {
        if level <= self.r_cells {
            self.lumen_ring(b, i, level, k)
        } else {
            self.above(self.lumen_ring(b, i, self.r_cells, k), level - self.r_cells)
        }
    }

    /// Hex between stations i, i+1, ring levels level, level+1 and ring points k, k+1; canonical
    /// order: radial x circumferential = axial, so the Jacobian is positive.
    pub fn ring_hex(&self, b: usize, i: usize, level: usize, k: usize) -> Hex {
        [
            self.ring(b, i, level, k),
            self.ring(b, i, level + 1, k),
            self.ring(b, i, level + 1, k + 1),
            self.ring(b, i, level, k + 1),
            self.ring(b, i + 1, level, k),
            self.ring(b, i + 1, level + 1, k),
            self.ring(b, i + 1, level + 1, k + 1),
            self.ring(b, i + 1, level, k + 1),
        ]
    }
}

/// A hex of a dome's top between two of its levels over core quad `q`, in the canonical order
/// (radial = from `below` to `above`, circumferential along the quad's first edge, axial along
/// its last: on the top, the radial direction is the tangent's, and t x n = b).
pub(super) fn top_hex(below: &[u32], above: &[u32], q: &[usize; 4]) -> Hex {
    [below[q[0]], above[q[0]], above[q[1]], below[q[1]], below[q[3]], above[q[3]], above[q[2]], below[q[2]]]
}
