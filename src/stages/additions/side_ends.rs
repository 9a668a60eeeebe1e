//! A vessel end that opens in the side of the mesh: the flat cap of a branch too short for a
//! junction's transition (openlb_aortoiliac_capped's stub, 10 mm long and fused with an iliac
//! for all of it, capped by a flat face in the crotch).
//!
//! Such a branch is meshed as part of its neighbour's lumen, whose nodes lie on the surface
//! there, the stub's flat cap included. The cap is then a patch of the lumen surface: its lumen
//! faces become the end's face set (a CFD outlet) in place of the lumen-wall interface, and the
//! wall's columns over them are taken away, so the wall is open over the end as at any cut end;
//! the faces of the wall left around the opening are the end's wall ring.
//!
//! The patch follows the mesh's faces, so its rim is a staircase around the cap's: its area is
//! reported next to the cap's.

use crate::geometry::mesh::{
    face_centre, face_key, face_nodes, quad_area_vector, sets, ElementFace, Region, VesselEnd, VesselMesh, WallColumns,
};
use crate::geometry::quality::boundary_face_skewness;
use crate::io::input::TriangleSurface;
use crate::stages::annotation::meshed::Meshed;
use nalgebra::{Point3, Vector3};
use serde::Serialize;
use std::collections::HashMap;

/// The surface triangles whose centroids lie within this many of a cap's radii of its centre
/// give its plane (the rest of a flat cap's rim may lean into the wall).
const PLANE_SAMPLE: f64 = 0.7;
/// A lumen-surface face is on the cap when its centre lies within this many of the cap's
/// (equivalent) radii of the cap's centre ...
const CAP_REACH: f64 = 1.1;
/// ... within this many radii of the cap's plane ...
const PLANE_TOLERANCE: f64 = 0.25;
/// ... and it faces out along the cap's normal (cosine of the largest angle: 30 degrees).
const FACING_COS: f64 = 0.85;
/// The opening's faces, lumen and wall, become boundary faces, which OpenFOAM judges by their
/// own cell alone: checkMesh fails a boundary face whose skewness exceeds 4 (see
/// [`boundary_face_skewness`]). A wall element beside the opening may be long and sheared
/// across it (openlb_aortoiliac_capped at coarse: 5 mm long, its face 0.9 mm wide, skewness 4.7),
/// so the opening keeps its faces within this, with a margin.
const MAX_SKEWNESS: f64 = 3.0;

/// A vessel end to open in the side of the mesh: its cap's centre and equivalent radius (mm),
/// and the unit normal of its plane (either sense).
#[derive(Debug, Clone, Copy)]
pub struct SideOpening {
    pub centre: Point3<f64>,
    pub radius: f64,
    pub plane_normal: Vector3<f64>,
}

impl SideOpening {
    /// The opening of the flat cap centred at `centre` with equivalent radius `radius` on
    /// `surface`: its plane from the triangles near its centre. None when no triangle lies
    /// there (an open end: a hole in the surface, not a face).
    pub fn of_cap(surface: &TriangleSurface, centre: Point3<f64>, radius: f64) -> Option<SideOpening> {
        let area_vector = |t: &[u32; 3]| {
            let [a, b, c] = t.map(|v| surface.vertices[v as usize]);
            ((b - a).cross(&(c - a)) * 0.5, Point3::from((a.coords + b.coords + c.coords) / 3.0))
        };
        let near: Vec<Vector3<f64>> = surface
            .triangles
            .iter()
            .map(area_vector)
            .filter(|(_, centroid)| (centroid - centre).norm() <= PLANE_SAMPLE * radius)
            .map(|(a, _)| a)
            .collect();
        // Summed in the sense of the largest, whatever the winding.
        let largest = near.iter().copied().max_by(|a, b| a.norm().total_cmp(&b.norm()))?;
        let sum: Vector3<f64> = near.iter().map(|a| if a.dot(&largest) < 0.0 { -a } else { *a }).sum();
        let plane_normal = sum.try_normalize(1e-12)?;
        Some(SideOpening { centre, radius, plane_normal })
    }
}

/// A side end as opened, for report.json (lengths in mm until scaled).
#[derive(Debug, Clone, Serialize)]
pub struct SideEndReport {
    /// The end's name in the mesh (its face and node sets `lumen_<end>`, `wall_<end>`).
    pub end: String,
    pub centre: [f64; 3],
    /// Lumen faces on the cap, and their area next to the cap's (pi r^2 of its equivalent radius).
    pub faces: usize,
    pub area: f64,
    pub cap_area: f64,
    /// Wall elements taken away over the opening.
    pub wall_elements_removed: usize,
}

impl SideEndReport {
    pub fn scaled(mut self, scale: f64) -> SideEndReport {
        self.centre = self.centre.map(|x| x * scale);
        self.area *= scale * scale;
        self.cap_area *= scale * scale;
        self
    }
}

/// Opens `opening` in the side of the mesh as a new outlet (see the module's documentation);
/// None, the mesh untouched, when no lumen-surface face lies on the cap.
pub fn open_side_end(meshed: &mut Meshed, opening: &SideOpening) -> Option<SideEndReport> {
    let mesh = &meshed.mesh;
    let (patch, removed, rim) = opening_within_skewness(mesh, faces_on_cap(mesh, opening))?;
    let area_vectors: Vec<Vector3<f64>> = patch.iter().map(|f| face_area_vector(mesh, f)).collect();
    let outward = area_vectors.iter().sum::<Vector3<f64>>().normalize();
    // The next outlet number no end has taken ("outlet" alone stays as it is).
    let name = (mesh.outlets().count() + 1..)
        .map(|k| format!("outlet_{k}"))
        .find(|n| mesh.ends.iter().all(|e| e.name != *n))
        .expect("an unbounded range has an unused name");
    let end = VesselEnd {
        name: name.clone(),
        is_inlet: false,
        branch: most_common_branch(mesh, &patch),
        centre: opening.centre,
        outward_normal: outward,
        side: true,
    };
    let report = SideEndReport {
        end: name.clone(),
        centre: opening.centre.into(),
        faces: patch.len(),
        area: area_vectors.iter().map(|a| a.norm()).sum(),
        cap_area: std::f64::consts::PI * opening.radius * opening.radius,
        wall_elements_removed: removed.iter().filter(|&&r| r).count(),
    };

    let mesh = &mut meshed.mesh;
    let lumen_wall = mesh.face_sets.get_mut(sets::LUMEN_WALL_FACES).expect("every mesh has the interface");
    lumen_wall.retain(|f| patch.binary_search(f).is_err());
    let nodes_of = |mesh: &VesselMesh, faces: &[ElementFace]| {
        let mut nodes: Vec<u32> =
            faces.iter().flat_map(|f| face_nodes(&mesh.hexes[f.element as usize], f.face as usize)).collect();
        nodes.sort_unstable();
        nodes.dedup();
        nodes
    };
    mesh.node_sets.insert(sets::lumen_end(&name), nodes_of(mesh, &patch));
    mesh.node_sets.insert(sets::wall_end(&name), nodes_of(mesh, &rim));
    mesh.face_sets.insert(sets::lumen_end(&name), patch);
    mesh.face_sets.insert(sets::wall_end(&name), rim);
    mesh.ends.push(end);
    remove_elements(meshed, &removed);
    Some(report)
}

fn face_area_vector(mesh: &VesselMesh, f: &ElementFace) -> Vector3<f64> {
    quad_area_vector(face_nodes(&mesh.hexes[f.element as usize], f.face as usize).map(|n| mesh.nodes[n as usize]))
}

/// The lumen-wall faces on the cap (sorted, as the face sets are).
fn faces_on_cap(mesh: &VesselMesh, opening: &SideOpening) -> Vec<ElementFace> {
    let (c, r, n) = (opening.centre, opening.radius, opening.plane_normal);
    let on_cap = |f: &&ElementFace| {
        let centre = face_centre(&mesh.corners(f.element as usize), f.face as usize);
        let a = face_area_vector(mesh, f);
        (centre - c).norm() <= CAP_REACH * r
            && (centre - c).dot(&n).abs() <= PLANE_TOLERANCE * r
            && a.dot(&n).abs() >= FACING_COS * a.norm()
    };
    mesh.face_sets[sets::LUMEN_WALL_FACES].iter().filter(on_cap).copied().collect()
}

/// The part of `patch` whose opening keeps every boundary face it makes within
/// [`MAX_SKEWNESS`]: the patch, the wall elements over it (by element) and the wall's rim
/// around it. A face of the patch too skewed, or whose column leaves a rim face too skewed, is
/// given back to the interface, and the rim found again, until no rim face is too skewed (the
/// patch only shrinks, so this ends). None when no face is left.
fn opening_within_skewness(
    mesh: &VesselMesh,
    mut patch: Vec<ElementFace>,
) -> Option<(Vec<ElementFace>, Vec<bool>, Vec<ElementFace>)> {
    let skewness = |f: &ElementFace| boundary_face_skewness(&mesh.corners(f.element as usize), f.face as usize);
    patch.retain(|f| skewness(f) <= MAX_SKEWNESS);
    let columns = WallColumns::new(mesh);
    loop {
        if patch.is_empty() {
            return None;
        }
        let column = wall_columns_over(mesh, &columns, &patch);
        let rim = wall_faces_around(mesh, &column);
        let mut given_back: Vec<usize> = rim
            .iter()
            .filter(|(face, _)| skewness(face) > MAX_SKEWNESS)
            .filter_map(|&(_, beside)| column[beside])
            .collect();
        if given_back.is_empty() {
            let removed = column.iter().map(Option::is_some).collect();
            return Some((patch, removed, rim.into_iter().map(|(face, _)| face).collect()));
        }
        given_back.sort_unstable();
        given_back.dedup();
        patch = patch
            .into_iter()
            .enumerate()
            .filter(|(k, _)| given_back.binary_search(k).is_err())
            .map(|(_, f)| f)
            .collect();
    }
}

/// The wall's columns over `patch` (lumen faces): for each wall element, the patch face whose
/// column it stands in, if any.
fn wall_columns_over(mesh: &VesselMesh, columns: &WallColumns, patch: &[ElementFace]) -> Vec<Option<usize>> {
    let mut column = vec![None; mesh.hexes.len()];
    for (k, f) in patch.iter().enumerate() {
        for e in columns.above(mesh, face_key(&mesh.hexes[f.element as usize], f.face as usize)) {
            column[e] = Some(k);
        }
    }
    column
}

/// The faces of the wall elements kept that a removed one (in a `column`) shared: the wall's
/// rim around the opening (sorted), each with the removed element beside it.
fn wall_faces_around(mesh: &VesselMesh, column: &[Option<usize>]) -> Vec<(ElementFace, usize)> {
    let mut removed_faces: HashMap<[u32; 4], usize> = HashMap::new();
    for e in mesh.wall_range().filter(|&e| column[e].is_some()) {
        for f in 0..6 {
            removed_faces.insert(face_key(&mesh.hexes[e], f), e);
        }
    }
    let mut rim: Vec<(ElementFace, usize)> = mesh
        .wall_range()
        .filter(|&e| column[e].is_none())
        .flat_map(|e| (0..6).map(move |f| (e, f)))
        .filter_map(|(e, f)| {
            let beside = *removed_faces.get(&face_key(&mesh.hexes[e], f))?;
            Some((ElementFace { element: e as u32, face: f as u8 }, beside))
        })
        .collect();
    rim.sort_unstable();
    rim
}

fn most_common_branch(mesh: &VesselMesh, patch: &[ElementFace]) -> usize {
    let mut count: HashMap<u32, usize> = HashMap::new();
    for f in patch {
        *count.entry(mesh.branch_of[f.element as usize]).or_default() += 1;
    }
    count.into_iter().max_by_key(|&(b, k)| (k, std::cmp::Reverse(b))).map_or(0, |(b, _)| b as usize)
}

/// Takes the `removed` elements and the nodes only they used out of the mesh (and out of
/// `junction_of`), every set renumbered. The interface's nodes are those a wall element still
/// stands on.
fn remove_elements(meshed: &mut Meshed, removed: &[bool]) {
    let mesh = &mut meshed.mesh;
    let mut new_element = vec![u32::MAX; mesh.hexes.len()];
    let mut kept = 0u32;
    for (e, r) in removed.iter().enumerate() {
        if !r {
            new_element[e] = kept;
            kept += 1;
        }
    }
    let keep = |e: usize| !removed[e];
    fn filter<T: Clone>(v: &mut Vec<T>, keep: impl Fn(usize) -> bool) {
        if !v.is_empty() {
            *v = v.iter().enumerate().filter(|(e, _)| keep(*e)).map(|(_, x)| x.clone()).collect();
        }
    }
    filter(&mut mesh.hexes, keep);
    filter(&mut mesh.regions, keep);
    filter(&mut mesh.branch_of, keep);
    filter(&mut mesh.sac, keep);
    filter(&mut mesh.triads, keep);
    filter(&mut mesh.fibres, keep);
    filter(&mut mesh.quality, keep);
    filter(&mut meshed.junction_of, keep);
    for faces in mesh.face_sets.values_mut() {
        faces.retain(|f| !removed[f.element as usize]);
        faces.iter_mut().for_each(|f| f.element = new_element[f.element as usize]);
    }

    let mut used = vec![false; mesh.nodes.len()];
    mesh.hexes.iter().flatten().for_each(|&n| used[n as usize] = true);
    let mut on_wall = vec![false; mesh.nodes.len()];
    for e in mesh.wall_range() {
        mesh.hexes[e].iter().for_each(|&n| on_wall[n as usize] = true);
    }
    if let Some(interface) = mesh.node_sets.get_mut(sets::INTERFACE_NODES) {
        interface.retain(|&n| on_wall[n as usize]);
    }
    let mut new_node = vec![u32::MAX; mesh.nodes.len()];
    let mut next = 0u32;
    for (n, &u) in used.iter().enumerate() {
        if u {
            new_node[n] = next;
            next += 1;
        }
    }
    filter(&mut mesh.nodes, |n| used[n]);
    mesh.hexes.iter_mut().flatten().for_each(|n| *n = new_node[*n as usize]);
    for nodes in mesh.node_sets.values_mut() {
        nodes.retain(|&n| used[n as usize]);
        nodes.iter_mut().for_each(|n| *n = new_node[*n as usize]);
    }
    debug_assert!(mesh.regions.windows(2).all(|w| w[0] <= w[1]) && mesh.count(Region::Lumen) > 0);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::config::MeshConfig;
    use std::collections::HashSet;

    fn key(mesh: &VesselMesh, f: &ElementFace) -> [u32; 4] {
        face_key(&mesh.hexes[f.element as usize], f.face as usize)
    }

    /// A flat "cap" 1 mm across on the side of a straight tube (radius 2 mm) opened as an end:
    /// the mesh stays conformal, its boundary is exactly the outer wall and the ends' faces,
    /// lumen and wall still meet face to face, every node is used, and the opening's faces are
    /// on the cap, within the skewness OpenFOAM takes.
    #[test]
    fn an_opening_in_the_side_of_a_tube_keeps_the_mesh_conformal() {
        let mut config = MeshConfig::default();
        config.lumen.axial_spacing_mm = Some(0.5);
        let mut meshed = crate::testing::straight_tube_mesh(&config).unwrap();
        let (elements, wall_cells) =
            (meshed.mesh.hexes.len(), meshed.mesh.layers.iter().map(|l| l.radial_elements).sum::<usize>());
        let opening = SideOpening { centre: Point3::new(2.0, 0.0, 15.0), radius: 1.0, plane_normal: Vector3::x() };
        let report = open_side_end(&mut meshed, &opening).expect("faces lie on the cap");
        let mesh = &meshed.mesh;
        assert_eq!(report.end, "outlet_2");
        assert!(report.faces >= 4 && report.area > 0.5 * report.cap_area, "{report:?}");
        assert_eq!(report.wall_elements_removed, report.faces * wall_cells);
        assert_eq!(mesh.hexes.len(), elements - report.wall_elements_removed);
        assert_eq!(meshed.junction_of.len(), mesh.hexes.len());
        let end = mesh.ends.last().unwrap();
        assert!(end.side && !end.is_inlet && (end.outward_normal - Vector3::x()).norm() < 0.1);

        // Conformal, and the boundary is the outer wall and the ends' faces, each once.
        let mut count: HashMap<[u32; 4], usize> = HashMap::new();
        for e in 0..mesh.hexes.len() {
            for f in 0..6 {
                *count.entry(face_key(&mesh.hexes[e], f)).or_default() += 1;
            }
        }
        assert!(count.values().all(|&c| c <= 2));
        let mut boundary: Vec<[u32; 4]> = mesh.face_sets[sets::WALL_OUTER_FACES].iter().map(|f| key(mesh, f)).collect();
        for end in &mesh.ends {
            for set in [sets::lumen_end(&end.name), sets::wall_end(&end.name)] {
                boundary.extend(mesh.face_sets[&set].iter().map(|f| key(mesh, f)));
            }
        }
        let expected: HashSet<[u32; 4]> = count.iter().filter(|(_, &c)| c == 1).map(|(k, _)| *k).collect();
        assert_eq!(boundary.len(), expected.len());
        assert_eq!(boundary.into_iter().collect::<HashSet<_>>(), expected);
        let side: HashSet<[u32; 4]> = mesh.face_sets[sets::LUMEN_WALL_FACES].iter().map(|f| key(mesh, f)).collect();
        let wall: HashSet<[u32; 4]> = mesh.face_sets[sets::WALL_LUMEN_FACES].iter().map(|f| key(mesh, f)).collect();
        assert_eq!(side, wall);

        // Every node used; the interface's nodes each under a wall element; sets within range.
        let mut used = vec![false; mesh.nodes.len()];
        mesh.hexes.iter().flatten().for_each(|&n| used[n as usize] = true);
        assert!(used.iter().all(|&u| u));
        let on_wall: HashSet<u32> = mesh.wall_range().flat_map(|e| mesh.hexes[e]).collect();
        assert!(mesh.node_sets[sets::INTERFACE_NODES].iter().all(|n| on_wall.contains(n)));
        assert!(mesh.face_sets.values().flatten().all(|f| (f.element as usize) < mesh.hexes.len()));

        // The opening's faces on the cap and within the skewness checkMesh takes.
        for f in &mesh.face_sets[&sets::lumen_end(&end.name)] {
            let c = face_centre(&mesh.corners(f.element as usize), f.face as usize);
            assert!((c - opening.centre).norm() <= CAP_REACH * opening.radius);
            assert!(mesh.regions[f.element as usize] == Region::Lumen);
        }
        for f in mesh.face_sets[&sets::lumen_end(&end.name)].iter().chain(&mesh.face_sets[&sets::wall_end(&end.name)]) {
            assert!(boundary_face_skewness(&mesh.corners(f.element as usize), f.face as usize) <= MAX_SKEWNESS);
        }
        assert!(mesh.face_sets[&sets::wall_end(&end.name)].iter().all(|f| mesh.regions[f.element as usize].is_wall()));
    }

    /// No lumen face on a cap away from the mesh: nothing opened, the mesh untouched.
    #[test]
    fn a_cap_away_from_the_mesh_opens_nothing() {
        let mut meshed = crate::testing::straight_tube_mesh(&MeshConfig::default()).unwrap();
        let before = (meshed.mesh.hexes.len(), meshed.mesh.nodes.len(), meshed.mesh.ends.len());
        let opening = SideOpening { centre: Point3::new(9.0, 0.0, 15.0), radius: 1.0, plane_normal: Vector3::x() };
        assert!(open_side_end(&mut meshed, &opening).is_none());
        assert_eq!(before, (meshed.mesh.hexes.len(), meshed.mesh.nodes.len(), meshed.mesh.ends.len()));
    }
}
