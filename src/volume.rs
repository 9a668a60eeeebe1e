//! Volume mesh of the lumen (core + lateral blocks) and of the three-layer wall, from the
//! projected sections of a branch.
//!
//! Node layout per station (station-major, so neighbouring stations are close in memory):
//! the (N+1)^2 core nodes, then ring levels 1..=R of the lumen (level R is the lumen surface,
//! shared with the wall), then the wall levels. Ring level 0 is the core boundary. Elements are
//! ordered lumen, intima, media, adventitia, each station interval by station interval.

use crate::blocks::SectionTemplate;
use crate::config::WallGrowth;
use crate::mesh::{
    sets, ElementFace, Hex, Region, VesselEnd, VesselMesh, WallLayer, FACE_DOWNSTREAM, FACE_INNER, FACE_OUTER,
    FACE_UPSTREAM,
};
use crate::projection::ProjectedBranch;
use indexmap::IndexMap;
use nalgebra::Vector3;

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

/// Index arithmetic of the structured node grid of one branch.
struct Grid<'a> {
    t: &'a SectionTemplate,
    lumen_cells: usize,
    wall_cells: usize,
}

impl Grid<'_> {
    fn core_count(&self) -> usize {
        (self.t.n + 1) * (self.t.n + 1)
    }
    fn per_station(&self) -> usize {
        self.core_count() + self.t.ring_len() * (self.lumen_cells + self.wall_cells)
    }
    /// Node at station `i`, ring level `level` (0 = core boundary, R = surface, R + m = wall
    /// level m) and ring point `k` (taken modulo the ring).
    fn ring(&self, i: usize, level: usize, k: usize) -> u32 {
        let m = self.t.ring_len();
        let k = k % m;
        let local = if level == 0 {
            self.t.ring_core_index[k]
        } else {
            self.core_count() + (level - 1) * m + k
        };
        (i * self.per_station() + local) as u32
    }
    fn core(&self, i: usize, c: usize) -> u32 {
        (i * self.per_station() + c) as u32
    }
    /// Hex between stations i, i+1 spanning ring levels level, level+1 and ring points k, k+1;
    /// canonical order: radial x circumferential = axial, so the Jacobian is positive.
    fn ring_hex(&self, i: usize, level: usize, k: usize) -> Hex {
        [
            self.ring(i, level, k),
            self.ring(i, level + 1, k),
            self.ring(i, level + 1, k + 1),
            self.ring(i, level, k + 1),
            self.ring(i + 1, level, k),
            self.ring(i + 1, level + 1, k),
            self.ring(i + 1, level + 1, k + 1),
            self.ring(i + 1, level, k + 1),
        ]
    }
}

/// Builds nodes, hexes, regions and sets of an unbranched vessel. Triads, fibres and quality
/// are filled in by [`crate::annotate`].
pub fn build_volume(
    projected: &ProjectedBranch,
    template: &SectionTemplate,
    levels: &RadialLevels,
    layers: &[WallLayer],
    wall_thickness: &dyn Fn(f64) -> f64,
    wall_growth: WallGrowth,
) -> VesselMesh {
    let grid = Grid { t: template, lumen_cells: levels.lumen_cells(), wall_cells: levels.wall_cells() };
    let stations = projected.sections.len();
    let m = template.ring_len();
    let r_cells = grid.lumen_cells;

    // Nodes, station by station: core, lumen rings, then the wall grown from the surface nodes.
    let growth: Vec<Vec<Vector3<f64>>> = match wall_growth {
        WallGrowth::Ray => projected.sections.iter().map(|s| s.dirs.clone()).collect(),
        WallGrowth::Normal => surface_normals(projected),
    };
    let mut nodes = Vec::with_capacity(stations * grid.per_station());
    for (sec, dirs) in projected.sections.iter().zip(&growth) {
        for c in &template.core {
            nodes.push(template.place(&sec.station, c));
        }
        for &rho in &levels.lumen[1..] {
            for (a, b) in sec.origins.iter().zip(&sec.surface) {
                // The surface level is the hit point itself, bit for bit.
                nodes.push(if rho == 1.0 { *b } else { a + (b - a) * rho });
            }
        }
        let thickness = wall_thickness(sec.station.radius);
        for &tau in &levels.wall[1..] {
            for (b, d) in sec.surface.iter().zip(dirs) {
                nodes.push(b + d * (thickness * tau));
            }
        }
    }

    // Elements: lumen (core + lateral), then each wall region.
    let mut hexes: Vec<Hex> = Vec::new();
    let mut regions = Vec::new();
    let core_quads = template.core_quads();
    for i in 0..stations - 1 {
        for q in &core_quads {
            hexes.push([
                grid.core(i, q[0]),
                grid.core(i, q[1]),
                grid.core(i, q[2]),
                grid.core(i, q[3]),
                grid.core(i + 1, q[0]),
                grid.core(i + 1, q[1]),
                grid.core(i + 1, q[2]),
                grid.core(i + 1, q[3]),
            ]);
        }
        for level in 0..r_cells {
            for k in 0..m {
                hexes.push(grid.ring_hex(i, level, k));
            }
        }
    }
    regions.resize(hexes.len(), Region::Lumen);
    let lumen_per_interval = core_quads.len() + m * r_cells;
    // first element index of each wall cell layer, by interval: computed while pushing
    let mut wall_layer_start: Vec<usize> = vec![0; grid.wall_cells];
    for region in Region::WALL {
        for i in 0..stations - 1 {
            for (w, r) in levels.wall_regions.iter().enumerate() {
                if *r != region {
                    continue;
                }
                if i == 0 {
                    wall_layer_start[w] = hexes.len();
                }
                for k in 0..m {
                    hexes.push(grid.ring_hex(i, r_cells + w, k));
                    regions.push(region);
                }
            }
        }
    }
    // Within a region, elements go interval by interval, each interval holding the region's
    // cell layers in order; the index of (interval i, wall cell layer w, ring k):
    let cells_in_region = |r: Region| levels.wall_regions.iter().filter(|x| **x == r).count();
    let wall_elem = |i: usize, w: usize, k: usize| -> u32 {
        let r = levels.wall_regions[w];
        let first_w = levels.wall_regions.iter().position(|x| *x == r).unwrap();
        (wall_layer_start[first_w] + (i * cells_in_region(r) + (w - first_w)) * m + k) as u32
    };
    let lumen_elem = |i: usize, level: usize, k: usize| -> u32 {
        (i * lumen_per_interval + core_quads.len() + level * m + k) as u32
    };

    // Sets.
    let last = stations - 1;
    let ef = |element: u32, face: usize| ElementFace { element, face: face as u8 };
    let mut node_sets: IndexMap<String, Vec<u32>> = IndexMap::new();
    let mut face_sets: IndexMap<String, Vec<ElementFace>> = IndexMap::new();
    let interface: Vec<u32> = (0..stations).flat_map(|i| (0..m).map(move |k| (i, k))).map(|(i, k)| grid.ring(i, r_cells, k)).collect();
    let outer: Vec<u32> = (0..stations)
        .flat_map(|i| (0..m).map(move |k| (i, k)))
        .map(|(i, k)| grid.ring(i, r_cells + grid.wall_cells, k))
        .collect();
    node_sets.insert(sets::INTERFACE_NODES.into(), interface);
    node_sets.insert(sets::OUTER_WALL_NODES.into(), outer);
    face_sets.insert(
        sets::LUMEN_WALL_FACES.into(),
        (0..stations - 1).flat_map(|i| (0..m).map(move |k| (i, k))).map(|(i, k)| ef(lumen_elem(i, r_cells - 1, k), FACE_OUTER)).collect(),
    );
    face_sets.insert(
        sets::WALL_LUMEN_FACES.into(),
        (0..stations - 1).flat_map(|i| (0..m).map(move |k| (i, k))).map(|(i, k)| ef(wall_elem(i, 0, k), FACE_INNER)).collect(),
    );
    face_sets.insert(
        sets::WALL_OUTER_FACES.into(),
        (0..stations - 1)
            .flat_map(|i| (0..m).map(move |k| (i, k)))
            .map(|(i, k)| ef(wall_elem(i, grid.wall_cells - 1, k), FACE_OUTER))
            .collect(),
    );

    let mut ends = Vec::new();
    for (name, is_inlet, i, interval, face) in
        [("inlet", true, 0, 0, FACE_UPSTREAM), ("outlet", false, last, last - 1, FACE_DOWNSTREAM)]
    {
        let station = &projected.sections[i].station;
        let base = (i * grid.per_station()) as u32;
        let lumen_nodes: Vec<u32> = (base..base + (grid.core_count() + m * r_cells) as u32).collect();
        let wall_nodes: Vec<u32> = (r_cells..=r_cells + grid.wall_cells).flat_map(|l| (0..m).map(move |k| (l, k))).map(|(l, k)| grid.ring(i, l, k)).collect();
        node_sets.insert(sets::lumen_end(name), lumen_nodes);
        node_sets.insert(sets::wall_end(name), sorted(wall_nodes));
        let lumen_faces = (0..lumen_per_interval).map(|e| ef((interval * lumen_per_interval + e) as u32, face)).collect();
        face_sets.insert(sets::lumen_end(name), lumen_faces);
        let wall_faces = (0..grid.wall_cells).flat_map(|w| (0..m).map(move |k| (w, k))).map(|(w, k)| ef(wall_elem(interval, w, k), face)).collect();
        face_sets.insert(sets::wall_end(name), sorted(wall_faces));
        let t = station.frame.tangent;
        ends.push(VesselEnd {
            name: name.into(),
            is_inlet,
            branch: 0,
            centre: station.point,
            outward_normal: if is_inlet { -t } else { t },
        });
    }
    for v in node_sets.values_mut() {
        v.sort_unstable();
    }
    for v in face_sets.values_mut() {
        v.sort_unstable();
    }

    let n_el = hexes.len();
    VesselMesh {
        nodes,
        hexes,
        regions,
        branch_of: vec![0; n_el],
        triads: Vec::new(),
        fibres: Vec::new(),
        quality: Vec::new(),
        layers: layers.to_vec(),
        ends,
        node_sets,
        face_sets,
        branch_names: vec!["branch_0".into()],
    }
}

fn sorted<T: Ord>(mut v: Vec<T>) -> Vec<T> {
    v.sort_unstable();
    v
}

/// Passes of neighbour averaging of the wall directions: enough to calm the voxel ripples of
/// segmented surfaces, few enough to keep the shape.
const NORMAL_SMOOTHING_PASSES: usize = 3;

/// Outward unit normals of the meshed lumen surface at its nodes, per station and ring point:
/// the average of the adjacent quads' normals, smoothed over the structured grid. At the end
/// stations the axial component is removed so the wall's end rings stay in the end planes.
fn surface_normals(projected: &ProjectedBranch) -> Vec<Vec<Vector3<f64>>> {
    let secs = &projected.sections;
    let (n, m) = (secs.len(), secs[0].surface.len());
    let s = |i: usize, k: usize| secs[i].surface[k % m];
    let mut normals = vec![vec![Vector3::zeros(); m]; n];
    for i in 0..n - 1 {
        for k in 0..m {
            // circumferential x axial = outward (the ring runs counter-clockwise about the tangent)
            let a = (s(i, k + 1) - s(i, k)) + (s(i + 1, k + 1) - s(i + 1, k));
            let b = (s(i + 1, k) - s(i, k)) + (s(i + 1, k + 1) - s(i, k + 1));
            let q = a.cross(&b);
            for (ii, kk) in [(i, k), (i, k + 1), (i + 1, k), (i + 1, k + 1)] {
                normals[ii][kk % m] += q;
            }
        }
    }
    let unit = |v: Vector3<f64>, fallback: Vector3<f64>| if v.norm() > 0.0 { v.normalize() } else { fallback };
    for (i, row) in normals.iter_mut().enumerate() {
        for (k, v) in row.iter_mut().enumerate() {
            *v = unit(*v, secs[i].dirs[k]);
        }
    }
    for _ in 0..NORMAL_SMOOTHING_PASSES {
        let prev = normals.clone();
        for i in 0..n {
            for k in 0..m {
                let mut sum = prev[i][k] * 2.0 + prev[i][(k + 1) % m] + prev[i][(k + m - 1) % m];
                sum += prev[i.saturating_sub(1)][k] + prev[(i + 1).min(n - 1)][k];
                normals[i][k] = unit(sum, prev[i][k]);
            }
        }
    }
    for i in [0, n - 1] {
        let t = secs[i].station.frame.tangent;
        for (v, d) in normals[i].iter_mut().zip(&secs[i].dirs) {
            *v = unit(*v - t * v.dot(&t), *d);
        }
    }
    normals
}
