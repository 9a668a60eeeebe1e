//! The elements of the lumen and of the wall's regions, each with its region, branch and
//! junction, the face and node sets, and the lumen surface they share.

use super::numbering::{top_hex, Numbering};
use super::RadialLevels;
use crate::geometry::mesh::{
    sets, ElementFace, Hex, Region, VesselEnd, FACE_DOWNSTREAM, FACE_INNER, FACE_OUTER, FACE_UPSTREAM,
};
use crate::stages::projection::{BranchEnd, ProjectedBranch};
use indexmap::IndexMap;
use nalgebra::Vector3;
use std::collections::HashMap;

/// A vessel end of the mesh: the inlet, or an outlet ("outlet", or "outlet_1", "outlet_2", ...
/// in branch order when there are several).
pub(super) struct EndName {
    branch: usize,
    is_inlet: bool,
    name: String,
}

/// The vessel ends: the inlet, then the outlets in branch order.
pub(super) fn vessel_end_names(projected: &[ProjectedBranch]) -> Vec<EndName> {
    let outlets = projected.iter().filter(|p| matches!(p.end, BranchEnd::Vessel { .. })).count();
    let mut names = Vec::new();
    let mut outlet_no = 0;
    for (b, pb) in projected.iter().enumerate() {
        if matches!(pb.start, BranchEnd::Vessel { .. }) {
            names.push(EndName { branch: b, is_inlet: true, name: "inlet".to_string() });
        }
        if matches!(pb.end, BranchEnd::Vessel { .. }) {
            outlet_no += 1;
            let name = if outlets == 1 { "outlet".to_string() } else { format!("outlet_{outlet_no}") };
            names.push(EndName { branch: b, is_inlet: false, name });
        }
    }
    names
}

fn end_name(ends: &[EndName], b: usize, inlet: bool) -> Option<&str> {
    ends.iter().find(|e| e.branch == b && e.is_inlet == inlet).map(|e| e.name.as_str())
}

/// The ends' face sets an interval's element lies on: (set's end, face) at the branch's first
/// interval (`i == 0`) and its last.
fn end_faces(ends: &[EndName], b: usize, i: usize, last: usize) -> Vec<(&str, usize)> {
    [(i == 0, true, FACE_UPSTREAM), (i == last, false, FACE_DOWNSTREAM)]
        .into_iter()
        .filter_map(|(here, inlet, face)| if here { end_name(ends, b, inlet).map(|n| (n, face)) } else { None })
        .collect()
}

/// The elements as they are assembled, with what each one is, and the face sets.
pub(super) struct Elements {
    pub hexes: Vec<Hex>,
    pub regions: Vec<Region>,
    pub branch_of: Vec<u32>,
    /// The junction of each element of a transition interval, for the report.
    pub junction_of: Vec<Option<usize>>,
    pub face_sets: IndexMap<String, Vec<ElementFace>>,
}

impl Elements {
    /// No elements yet; the face sets declared: lumen-wall interface, outer wall, each end's.
    pub fn new(ends: &[EndName]) -> Self {
        let mut face_sets = IndexMap::new();
        for key in [sets::LUMEN_WALL_FACES, sets::WALL_LUMEN_FACES, sets::WALL_OUTER_FACES] {
            face_sets.insert(key.into(), vec![]);
        }
        for end in ends {
            face_sets.insert(sets::lumen_end(&end.name), vec![]);
            face_sets.insert(sets::wall_end(&end.name), vec![]);
        }
        Elements { hexes: vec![], regions: vec![], branch_of: vec![], junction_of: vec![], face_sets }
    }

    /// Adds an element; its index.
    fn push(&mut self, hex: Hex, region: Region, branch: usize, junction: Option<usize>) -> usize {
        self.hexes.push(hex);
        self.regions.push(region);
        self.branch_of.push(branch as u32);
        self.junction_of.push(junction);
        self.hexes.len() - 1
    }

    fn add_face(&mut self, set: &str, element: usize, face: usize) {
        let face = ElementFace { element: element as u32, face: face as u8 };
        self.face_sets.get_mut(set).expect("declared in Elements::new").push(face);
    }

    /// A wall element, on the interface's and the outer wall's face sets when it is the first or
    /// the last of the wall's `w_cells` layers.
    fn push_wall(
        &mut self,
        hex: Hex,
        region: Region,
        b: usize,
        junction: Option<usize>,
        w: usize,
        w_cells: usize,
    ) -> usize {
        let e = self.push(hex, region, b, junction);
        if w == 0 {
            self.add_face(sets::WALL_LUMEN_FACES, e, FACE_INNER);
        }
        if w == w_cells - 1 {
            self.add_face(sets::WALL_OUTER_FACES, e, FACE_OUTER);
        }
        e
    }
}

/// The junction an element between sections i and i+1 belongs to: that of the nearer folded
/// end when either section lies in a transition.
fn interval_junction(pb: &ProjectedBranch, i: usize) -> Option<usize> {
    if !(pb.sections[i].in_junction || pb.sections[i + 1].in_junction) {
        return None;
    }
    // The nearer end's junction first (a branch between two junctions has both).
    let ends = if i < pb.sections.len() / 2 { [pb.start, pb.end] } else { [pb.end, pb.start] };
    ends.iter().find_map(|e| match e {
        BranchEnd::Fold(f) => Some(f.junction),
        BranchEnd::Vessel { .. } | BranchEnd::Dome => None,
    })
}

/// The lumen's elements, branch by branch: each station interval's core, then its ring levels;
/// a dome's top after its branch.
pub(super) fn add_lumen_elements(
    elements: &mut Elements,
    projected: &[ProjectedBranch],
    numbering: &Numbering,
    levels: &RadialLevels,
    ends: &[EndName],
) {
    let r_cells = levels.lumen_cells();
    for (b, pb) in projected.iter().enumerate() {
        let core_quads = numbering.core_quads(b);
        let last = pb.sections.len() - 2;
        for i in 0..=last {
            let st = (&numbering.branches[b].stations[i], &numbering.branches[b].stations[i + 1]);
            let junction = interval_junction(pb, i);
            let first_of_interval = elements.hexes.len();
            for q in &core_quads {
                let hex =
                    [st.0[q[0]], st.0[q[1]], st.0[q[2]], st.0[q[3]], st.1[q[0]], st.1[q[1]], st.1[q[2]], st.1[q[3]]];
                elements.push(hex, Region::Lumen, b, junction);
            }
            for level in 0..r_cells {
                for k in 0..numbering.ring_len(b) {
                    let e = elements.push(numbering.ring_hex(b, i, level, k), Region::Lumen, b, junction);
                    if level == r_cells - 1 {
                        elements.add_face(sets::LUMEN_WALL_FACES, e, FACE_OUTER);
                    }
                }
            }
            for (name, face) in end_faces(ends, b, i, last) {
                for e in first_of_interval..elements.hexes.len() {
                    elements.add_face(&sets::lumen_end(name), e, face);
                }
            }
        }
        let Some(top) = &numbering.branches[b].dome_top else { continue };
        for level in 0..r_cells {
            for q in &core_quads {
                let e = elements.push(top_hex(&top[level], &top[level + 1], q), Region::Lumen, b, None);
                if level == r_cells - 1 {
                    elements.add_face(sets::LUMEN_WALL_FACES, e, FACE_OUTER);
                }
            }
        }
    }
}

/// The wall's elements, region by region (intima, media, adventitia), each branch by branch:
/// station interval by interval, then a dome's top.
pub(super) fn add_wall_elements(
    elements: &mut Elements,
    projected: &[ProjectedBranch],
    numbering: &Numbering,
    levels: &RadialLevels,
    ends: &[EndName],
) {
    let (r_cells, w_cells) = (levels.lumen_cells(), levels.wall_cells());
    for region in Region::WALL {
        let layers: Vec<usize> = (0..w_cells).filter(|&w| levels.wall_regions[w] == region).collect();
        for (b, pb) in projected.iter().enumerate() {
            let last = pb.sections.len() - 2;
            for i in 0..=last {
                let junction = interval_junction(pb, i);
                for &w in &layers {
                    for k in 0..numbering.ring_len(b) {
                        let hex = numbering.ring_hex(b, i, r_cells + w, k);
                        let e = elements.push_wall(hex, region, b, junction, w, w_cells);
                        for (name, face) in end_faces(ends, b, i, last) {
                            elements.add_face(&sets::wall_end(name), e, face);
                        }
                    }
                }
            }
            let Some(surface) = numbering.dome_surface(b) else { continue };
            let wall_level = |w: usize| -> Vec<u32> { surface.iter().map(|&s| numbering.above(s, w)).collect() };
            for &w in &layers {
                let (below, above) = (wall_level(w), wall_level(w + 1));
                for q in &numbering.core_quads(b) {
                    elements.push_wall(top_hex(&below, &above, q), region, b, None, w, w_cells);
                }
            }
        }
    }
}

/// The lumen surface as quads, each wound so that its normal leaves the lumen: circumferential
/// x axial, the ring running counter-clockwise about each branch's flow direction.
pub(super) fn lumen_surface_quads(projected: &[ProjectedBranch], numbering: &Numbering) -> Vec<[u32; 4]> {
    let mut quads: Vec<[u32; 4]> = Vec::new();
    for (b, pb) in projected.iter().enumerate() {
        for i in 0..pb.sections.len() - 1 {
            for k in 0..numbering.ring_len(b) {
                quads.push([
                    numbering.surface(b, i, k),
                    numbering.surface(b, i, k + 1),
                    numbering.surface(b, i + 1, k + 1),
                    numbering.surface(b, i + 1, k),
                ]);
            }
        }
        if let Some(surface) = numbering.dome_surface(b) {
            quads.extend(
                numbering.core_quads(b).iter().map(|q| [surface[q[0]], surface[q[1]], surface[q[2]], surface[q[3]]]),
            );
        }
    }
    quads
}

/// The lumen-surface nodes of the vessel ends' sections, each with its section's tangent: their
/// wall nodes stay in the end planes.
pub(super) fn vessel_end_tangents(projected: &[ProjectedBranch], numbering: &Numbering) -> HashMap<u32, Vector3<f64>> {
    let mut end_tangent = HashMap::new();
    for (b, pb) in projected.iter().enumerate() {
        let last = pb.sections.len() - 1;
        for (i, end) in [(0, &pb.start), (last, &pb.end)] {
            if matches!(end, BranchEnd::Vessel { .. }) {
                for k in 0..numbering.ring_len(b) {
                    end_tangent.insert(numbering.surface(b, i, k), pb.sections[i].station.frame.tangent);
                }
            }
        }
    }
    end_tangent
}

/// Each vessel end's node sets (its section's lumen nodes; its wall nodes, the surface's
/// included) added to `node_sets`, and the ends as the mesh describes them.
pub(super) fn vessel_end_sets(
    node_sets: &mut IndexMap<String, Vec<u32>>,
    projected: &[ProjectedBranch],
    numbering: &Numbering,
    levels: &RadialLevels,
    ends: &[EndName],
) -> Vec<VesselEnd> {
    let (r_cells, w_cells) = (levels.lumen_cells(), levels.wall_cells());
    ends.iter()
        .map(|end| {
            let (b, pb) = (end.branch, &projected[end.branch]);
            let i = if end.is_inlet { 0 } else { pb.sections.len() - 1 };
            node_sets.insert(sets::lumen_end(&end.name), numbering.branches[b].stations[i].clone());
            let wall: Vec<u32> = (r_cells..=r_cells + w_cells)
                .flat_map(|l| (0..numbering.ring_len(b)).map(move |k| (l, k)))
                .map(|(l, k)| numbering.ring(b, i, l, k))
                .collect();
            node_sets.insert(sets::wall_end(&end.name), wall);
            let station = &pb.sections[i].station;
            let t = station.frame.tangent;
            VesselEnd {
                name: end.name.clone(),
                is_inlet: end.is_inlet,
                branch: b,
                centre: station.point,
                outward_normal: if end.is_inlet { -t } else { t },
                side: false,
            }
        })
        .collect()
}
