//! The annotated hexahedral mesh: the single type every writer reads.
//!
//! # Canonical hexahedron
//! Node order is the one shared by VTK, Abaqus, CalculiX and FEBio for the eight corners: nodes
//! 0-3 go counter-clockwise around the *bottom* face seen from the top, nodes 4-7 lie above them
//! (4 over 0, ...). A valid element has a positive Jacobian in this order.
//!
//! [`HEX_FACES`] lists the six faces with their nodes wound so that the right-hand-rule normal
//! points **out of** the element. Face `f` is Abaqus/CalculiX face label `S{f+1}` (whose own
//! listing is the reverse winding: Abaqus lists S-faces with inward normals). Every format derives
//! its winding from this one table: FEBio facets and OpenFOAM boundary faces use it as is,
//! Abaqus surfaces use the label [`abaqus_face_label`].
//!
//! In meshes built by vesselhex the element axes have a fixed meaning:
//! * face 0 (S1) is the inlet-side (upstream) face, face 1 (S2) the outlet-side face;
//! * face 2 (S3) and face 4 (S5) are the two circumferential sides, face 4 in the direction
//!   of increasing angle;
//! * face 5 (S6) is the inner (centerline-side) face, face 3 (S4) the outer (wall-side) face.

pub use crate::data::region::{Region, WallLayer};
use indexmap::IndexMap;
use nalgebra::{Point3, Vector3};
use serde::Serialize;

/// Eight 0-based node indices in canonical order.
pub type Hex = [u32; 8];

/// Faces of the canonical hexahedron, outward winding; index f is Abaqus label S{f+1}.
pub const HEX_FACES: [[usize; 4]; 6] = [
    [0, 3, 2, 1], // S1: bottom (inlet side)
    [4, 5, 6, 7], // S2: top (outlet side)
    [0, 1, 5, 4], // S3: circumferential side, lower angle
    [1, 2, 6, 5], // S4: outer side (towards the wall / adventitia)
    [2, 3, 7, 6], // S5: circumferential side, higher angle
    [3, 0, 4, 7], // S6: inner side (towards the centerline)
];

/// The face of the canonical hexahedron opposite to each face.
pub const OPPOSITE_FACE: [usize; 6] = [1, 0, 4, 5, 2, 3];

/// Local face index of the inlet-side face.
pub const FACE_UPSTREAM: usize = 0;
/// Local face index of the outlet-side face.
pub const FACE_DOWNSTREAM: usize = 1;
/// Local face index of the outer (radially outward) face.
pub const FACE_OUTER: usize = 3;
/// Local face index of the inner (radially inward) face.
pub const FACE_INNER: usize = 5;
/// Local face index of the circumferential side at the lower angle.
pub const FACE_CIRC_LOW: usize = 2;
/// Local face index of the circumferential side at the higher angle.
pub const FACE_CIRC_HIGH: usize = 4;

/// The 12 edges of the canonical hexahedron.
pub const HEX_EDGES: [[usize; 2]; 12] =
    [[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4], [0, 4], [1, 5], [2, 6], [3, 7]];

/// For each corner, its three neighbours ordered so that (n1-c, n2-c, n3-c) is right-handed
/// in a valid element. Used by the scaled Jacobian.
pub const HEX_CORNER_NEIGHBOURS: [[usize; 3]; 8] =
    [[1, 3, 4], [2, 0, 5], [3, 1, 6], [0, 2, 7], [7, 5, 0], [4, 6, 1], [5, 7, 2], [6, 4, 3]];

/// Abaqus/CalculiX face label ("S1".."S6") of canonical face `f`.
pub fn abaqus_face_label(f: usize) -> &'static str {
    ["S1", "S2", "S3", "S4", "S5", "S6"][f]
}

/// The four node indices of face `f` of `hex`, outward winding.
pub fn face_nodes(hex: &Hex, f: usize) -> [u32; 4] {
    let t = HEX_FACES[f];
    [hex[t[0]], hex[t[1]], hex[t[2]], hex[t[3]]]
}

/// Face `f` of `hex` as a key: its nodes sorted, the same whichever of its two elements lists it.
pub fn face_key(hex: &Hex, f: usize) -> [u32; 4] {
    let mut k = face_nodes(hex, f);
    k.sort_unstable();
    k
}

/// The wall's columns: the wall element standing on each face (by [`face_key`]), each one on
/// the lumen's face or on the outer face of the one below it.
pub struct WallColumns {
    standing_on: std::collections::HashMap<[u32; 4], usize>,
}

impl WallColumns {
    pub fn new(mesh: &VesselMesh) -> WallColumns {
        WallColumns { standing_on: mesh.wall_range().map(|e| (face_key(&mesh.hexes[e], FACE_INNER), e)).collect() }
    }

    /// The wall elements standing on `face` (a [`face_key`]), from the intima outwards.
    pub fn above<'a>(&'a self, mesh: &'a VesselMesh, face: [u32; 4]) -> impl Iterator<Item = usize> + 'a {
        std::iter::successors(self.standing_on.get(&face).copied(), move |&e| {
            self.standing_on.get(&face_key(&mesh.hexes[e], FACE_OUTER)).copied()
        })
    }
}

/// Whether a branch of this name is a saccular aneurysm's sac, closed by a dome (the pipeline
/// names them "sac", or "sac_1", "sac_2", ...).
pub fn is_sac(branch_name: &str) -> bool {
    branch_name == "sac" || branch_name.strip_prefix("sac_").is_some_and(|k| k.parse::<usize>().is_ok())
}

/// One face of one element: `element` is a 0-based element index, `face` a canonical face index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub struct ElementFace {
    pub element: u32,
    pub face: u8,
}

/// Orthonormal local frame of an element: e_circ x e_long = e_rad, e_rad pointing from the lumen
/// towards the adventitia, e_long from inlet to outlet.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Triad {
    pub e_circ: Vector3<f64>,
    pub e_long: Vector3<f64>,
    pub e_rad: Vector3<f64>,
}

/// Per-element quality figures (definitions in [`crate::geometry::quality`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct ElementQuality {
    pub scaled_jacobian: f64,
    pub equiangle_skew: f64,
    /// The smallest face pyramid over a sixth of the volume ([`crate::geometry::quality::face_pyramid_ratio`]).
    pub face_pyramid: f64,
}

/// A vessel end: where flow enters or leaves.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VesselEnd {
    /// `inlet`, `outlet` or `outlet_1`, `outlet_2`, ...
    pub name: String,
    pub is_inlet: bool,
    /// Branch the end belongs to.
    pub branch: usize,
    /// Centre of the end section and its unit normal pointing out of the vessel.
    pub centre: Point3<f64>,
    pub outward_normal: Vector3<f64>,
    /// Whether the end opens in the side of the mesh (see [`crate::stages::additions::side_ends`]): its lumen
    /// faces are a patch of the lumen surface on the vessel's cap, not a cross-section, so no
    /// flow extension is swept from it.
    pub side: bool,
}

/// Well-known node-set names (always present in a mesh built by vesselhex).
pub mod sets {
    /// Lumen nodes on the lumen surface = wall nodes on its inner surface (shared).
    pub const INTERFACE_NODES: &str = "lumen_wall_interface";
    /// Wall nodes on the outer (adventitial) surface.
    pub const OUTER_WALL_NODES: &str = "outer_wall";
    /// Lumen faces (lumen elements, outward) on the lumen-wall interface.
    pub const LUMEN_WALL_FACES: &str = "lumen_wall";
    /// Wall faces (wall elements, outward = into the lumen) on the interface.
    pub const WALL_LUMEN_FACES: &str = "wall_lumen";
    /// Wall faces on the outer surface.
    pub const WALL_OUTER_FACES: &str = "wall_outer";
    /// Lumen nodes of an end section: `lumen_<end>`; wall nodes of an end ring: `wall_<end>`.
    pub fn lumen_end(end: &str) -> String {
        format!("lumen_{end}")
    }
    pub fn wall_end(end: &str) -> String {
        format!("wall_{end}")
    }
    /// Flow-extension faces (and nodes) on the extension's rigid wall.
    pub const EXTENSION_WALL: &str = "extension_wall";
    /// A flow extension's elements.
    pub const EXTENSION: &str = "extension";
    /// Where the vessel meets the flow extension of an end: the lumen nodes of the vessel's own
    /// end section and the faces of its lumen elements there (internal to the fluid).
    pub fn cut(end: &str) -> String {
        format!("cut_{end}")
    }
}

/// The volume mesh of lumen and wall with everything a writer needs.
///
/// Nodes are shared between lumen and wall on the interface (the mesh is conformal). Lengths are
/// in millimetres. Elements are ordered lumen first, then intima, media, adventitia; within a
/// region by branch, then along the branch. Node and element labels in FE decks are the 0-based
/// index + 1, in every deck, so that files refer to each other without a table.
#[derive(Debug, Clone, Serialize)]
pub struct VesselMesh {
    pub nodes: Vec<Point3<f64>>,
    pub hexes: Vec<Hex>,
    pub regions: Vec<Region>,
    /// Branch index of each element (0 for an unbranched vessel).
    pub branch_of: Vec<u32>,
    /// Whether each element lies in a saccular aneurysm's sac: a sac meshed as a blind branch
    /// (see [`is_sac`]), or the part of a junction that a sac holds (see [`crate::stages::annotation::sacs`]).
    pub sac: Vec<bool>,
    /// Per element local frame (lumen elements too: radial from the centerline side to the wall).
    pub triads: Vec<Triad>,
    /// Per element the two collagen fibre directions (zero vectors for lumen elements).
    pub fibres: Vec<[Vector3<f64>; 2]>,
    pub quality: Vec<ElementQuality>,
    pub layers: Vec<WallLayer>,
    pub ends: Vec<VesselEnd>,
    /// Named node sets, sorted ascending, 0-based.
    pub node_sets: IndexMap<String, Vec<u32>>,
    /// Named face sets (element, canonical face), sorted ascending.
    pub face_sets: IndexMap<String, Vec<ElementFace>>,
    /// Name of each branch (index = branch id).
    pub branch_names: Vec<String>,
}

impl VesselMesh {
    /// Indices of the elements of one region (contiguous by construction).
    pub fn region_range(&self, region: Region) -> std::ops::Range<usize> {
        let start = self.regions.partition_point(|r| *r < region);
        let end = self.regions.partition_point(|r| *r <= region);
        start..end
    }
    pub fn count(&self, region: Region) -> usize {
        self.region_range(region).len()
    }
    /// Wall elements: intima, media and adventitia together (contiguous).
    pub fn wall_range(&self) -> std::ops::Range<usize> {
        self.region_range(Region::Intima).start..self.region_range(Region::Adventitia).end
    }
    pub fn lumen_range(&self) -> std::ops::Range<usize> {
        self.region_range(Region::Lumen)
    }
    /// The flow extensions' elements (empty without extensions).
    pub fn extension_range(&self) -> std::ops::Range<usize> {
        self.region_range(Region::Extension)
    }
    /// Sorted nodes of the fluid: the lumen's and the flow extensions'.
    pub fn fluid_nodes(&self) -> Vec<u32> {
        let mut nodes = self.nodes_of(self.lumen_range());
        if !self.extension_range().is_empty() {
            nodes.extend(self.nodes_of(self.extension_range()));
            nodes.sort_unstable();
            nodes.dedup();
        }
        nodes
    }
    /// Whether element `e` lies in a saccular aneurysm's sac (see [`VesselMesh::sac`]).
    pub fn in_sac(&self, e: usize) -> bool {
        self.sac[e]
    }
    /// Corner coordinates of element `e`.
    pub fn corners(&self, e: usize) -> [Point3<f64>; 8] {
        let h = &self.hexes[e];
        std::array::from_fn(|i| self.nodes[h[i] as usize])
    }
    /// Sorted list of the nodes used by the elements in `range`.
    pub fn nodes_of(&self, range: std::ops::Range<usize>) -> Vec<u32> {
        let mut used = vec![false; self.nodes.len()];
        for h in &self.hexes[range] {
            for &n in h {
                used[n as usize] = true;
            }
        }
        used.iter().enumerate().filter(|(_, u)| **u).map(|(i, _)| i as u32).collect()
    }
    pub fn inlet(&self) -> Option<&VesselEnd> {
        self.ends.iter().find(|e| e.is_inlet)
    }
    pub fn outlets(&self) -> impl Iterator<Item = &VesselEnd> {
        self.ends.iter().filter(|e| !e.is_inlet)
    }
    /// Bytes the mesh holds on the heap (its arrays and sets, as allocated): the memory a run
    /// needs for the mesh itself, whatever the writers add.
    pub fn heap_bytes(&self) -> usize {
        fn bytes<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        let sets: usize = self.node_sets.iter().map(|(k, v)| k.capacity() + bytes(v)).sum::<usize>()
            + self.face_sets.iter().map(|(k, v)| k.capacity() + bytes(v)).sum::<usize>();
        bytes(&self.nodes)
            + bytes(&self.hexes)
            + bytes(&self.regions)
            + bytes(&self.branch_of)
            + bytes(&self.sac)
            + bytes(&self.triads)
            + bytes(&self.fibres)
            + bytes(&self.quality)
            + sets
    }
}

/// The unit cube [0,1]^3 in canonical order: the reference element of the face and corner tables.
pub fn unit_cube() -> [Point3<f64>; 8] {
    std::array::from_fn(|i| {
        let (x, y) = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)][i % 4];
        Point3::new(x, y, (i / 4) as f64)
    })
}

/// Centre (mean of the corners) of an element.
pub fn element_centre(corners: &[Point3<f64>; 8]) -> Point3<f64> {
    Point3::from(corners.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / 8.0)
}

/// Closest point of the segment [a, b] to p (a, for a segment of no length).
pub fn closest_on_segment(p: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>) -> Point3<f64> {
    let ab = b - a;
    let len2 = ab.norm_squared();
    if len2 == 0.0 {
        return *a;
    }
    let t = ((p - a).dot(&ab) / len2).clamp(0.0, 1.0);
    a + ab * t
}

/// Centre of face `f` of an element given its corners.
pub fn face_centre(corners: &[Point3<f64>; 8], f: usize) -> Point3<f64> {
    let t = HEX_FACES[f];
    let s = corners[t[0]].coords + corners[t[1]].coords + corners[t[2]].coords + corners[t[3]].coords;
    Point3::from(s / 4.0)
}

/// Area vector of a (possibly non-planar) quad: half the cross product of its diagonals; its
/// direction is the right-hand-rule normal of the winding.
pub fn quad_area_vector(p: [Point3<f64>; 4]) -> Vector3<f64> {
    (p[2] - p[0]).cross(&(p[3] - p[1])) * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faces_point_outward_on_unit_cube() {
        let c = unit_cube();
        let centre = Point3::new(0.5, 0.5, 0.5);
        let expected = [
            Vector3::new(0.0, 0.0, -1.0), // S1 bottom
            Vector3::new(0.0, 0.0, 1.0),  // S2 top
            Vector3::new(0.0, -1.0, 0.0), // S3 y = 0
            Vector3::new(1.0, 0.0, 0.0),  // S4 x = 1
            Vector3::new(0.0, 1.0, 0.0),  // S5 y = 1
            Vector3::new(-1.0, 0.0, 0.0), // S6 x = 0
        ];
        for f in 0..6 {
            let p = HEX_FACES[f].map(|i| c[i]);
            let a = quad_area_vector(p);
            assert!((a - expected[f]).norm() < 1e-12, "face {f}: {a:?}");
            assert!((face_centre(&c, f) - centre).dot(&a) > 0.0);
        }
    }

    #[test]
    fn opposite_faces_share_no_node_and_edges_cover_faces() {
        for f in 0..6 {
            let o = OPPOSITE_FACE[f];
            assert_eq!(OPPOSITE_FACE[o], f);
            for n in HEX_FACES[f] {
                assert!(!HEX_FACES[o].contains(&n));
            }
        }
        // every face edge is a hex edge
        for f in HEX_FACES {
            for k in 0..4 {
                let (a, b) = (f[k], f[(k + 1) % 4]);
                assert!(HEX_EDGES.iter().any(|e| (e[0] == a && e[1] == b) || (e[0] == b && e[1] == a)));
            }
        }
    }

    #[test]
    fn corner_neighbours_are_right_handed_on_unit_cube() {
        let c = unit_cube();
        for (i, nb) in HEX_CORNER_NEIGHBOURS.iter().enumerate() {
            let a = c[nb[0]] - c[i];
            let b = c[nb[1]] - c[i];
            let d = c[nb[2]] - c[i];
            assert!((a.cross(&b).dot(&d) - 1.0).abs() < 1e-12, "corner {i}");
        }
    }
}
