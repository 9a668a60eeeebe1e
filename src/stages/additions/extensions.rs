//! Flow extensions (De Santis et al. 2011, §2.1 and §2.3; VMTK's `vmtkflowextensions`): each
//! chosen vessel end is extended along its axis, so that the flow develops before it leaves and
//! the inlet and outlets are circular, and the extensions' fluid is kept apart as region
//! [`Region::Extension`], to be separated from the real domain in post-processing.
//!
//! The extension is swept from the finished mesh's own end section, not from a surface meshed
//! again: its nodes lie on stations along the end's outward normal, each the end section blended
//! towards a circle of the end's mean radius (area-equivalent: the mean velocity does not change
//! along the blend) over `blend_length` radii, then a cylinder. Every end section of vesselhex is
//! planar and its lumen-surface nodes are star-shaped about the centerline point, so each node
//! moves along its own direction from the centre, scaled by the ratio of the circle's radius to
//! the section's boundary in that direction. The extension shares the end section's nodes and
//! carries its O-grid on, so the fluid is conformal; no wall grows around it (its wall is
//! rigid), and the vessel itself is the mesh vesselhex builds without extensions, bit for bit.
//!
//! Numbering: the extensions' nodes and elements come after the vessel's (the elements of
//! region `extension` last), so the vessel keeps its node and element labels and the FE decks,
//! which model the vessel alone ([`without_extensions`]), are the ones written without
//! extensions. Sets of an extended end `E`:
//! * `lumen_E` (nodes and faces): the extended end, where the CFD patches lie;
//! * `cut_E` (nodes and faces): the vessel's own end section and its lumen elements' faces there,
//!   which were `lumen_E` before (internal faces of the fluid);
//! * `extension_wall` (nodes and faces): the extensions' rigid wall (the end rings at the cuts
//!   stay in `lumen_wall_interface`).
//!
//! The `VesselEnd` keeps the vessel's own end: its centre and normal are the cut's.

use crate::data::config::{ExtensionShape, ExtensionsConfig};
use crate::data::error::{Error, Result};
use crate::geometry::mesh::{sets, ElementFace, Hex, Region, VesselEnd, VesselMesh, FACE_DOWNSTREAM, FACE_OUTER};
use crate::geometry::quality::{element_quality, Stats};
use crate::geometry::vector::smoothstep;
use crate::stages::annotation::annotate::element_triad;
use nalgebra::{Point3, Vector2, Vector3};
use serde::Serialize;
use std::borrow::Cow;

/// What one end's extension is, for report.json (lengths in the output unit).
#[derive(Debug, Clone, Serialize)]
pub struct ExtensionReport {
    pub end: String,
    /// Length along the end's outward normal, and relative to the mean radius.
    pub length: f64,
    pub length_radii: f64,
    /// The mean (area-equivalent) radius of the end section: the cylinder's radius.
    pub radius: f64,
    /// Length over which the section blends into the cylinder (0 for `shape = "section"`).
    pub blend_length: f64,
    /// Stations beyond the vessel's end, and the elements between them.
    pub stations: usize,
    pub elements: usize,
    /// Centre of the extended end (the CFD patch); the `VesselEnd` keeps the vessel's own.
    pub end_centre: [f64; 3],
    pub scaled_jacobian: Stats,
    pub equiangle_skew: Stats,
}

/// The end section of one vessel end, as the extension needs it.
struct EndSection {
    /// Lumen nodes of the section, sorted (its `lumen_E` node set).
    nodes: Vec<u32>,
    /// The lumen elements' faces on it (its `lumen_E` face set).
    faces: Vec<ElementFace>,
    centre: Point3<f64>,
    /// Outward unit normal and an in-plane basis.
    normal: Vector3<f64>,
    basis: [Vector3<f64>; 2],
    /// The section's boundary (its lumen-surface nodes), in-plane about the centre, by angle.
    boundary: Vec<(f64, Vector2<f64>)>,
    /// Mean (area-equivalent) radius.
    radius: f64,
    /// Mean axial length of the lumen elements at the end.
    element_length: f64,
}

/// Adds the flow extensions asked for to a finished (annotated) mesh; returns what was built,
/// in mesh units (mm). Without extensions asked for, the mesh is left as it is.
pub fn extend(mesh: &mut VesselMesh, config: &ExtensionsConfig) -> Result<Vec<ExtensionReport>> {
    if !config.is_on() {
        return Ok(Vec::new());
    }
    check_end_names(mesh, config)?;
    // `ends = "all"` passes over the side ends: they have no cross-section to sweep from.
    let ends: Vec<VesselEnd> = mesh.ends.iter().filter(|e| config.extends(&e.name) && !e.side).cloned().collect();
    let mut reports = Vec::new();
    let mut wall = ExtensionWall::default();
    for end in &ends {
        let section = end_section(mesh, end)?;
        let length = config.length_of(&end.name, end.is_inlet) * section.radius;
        let first = mesh.hexes.len();
        let (stations, end_centre) = sweep(mesh, end, &section, length, config, &mut wall);
        let elements = first..mesh.hexes.len();
        if let Some(e) = elements.clone().find(|&e| {
            let sj = mesh.quality[e].scaled_jacobian;
            sj.is_nan() || sj <= 0.0 // NaN: a degenerate element
        }) {
            return Err(Error::Geometry(format!(
                "flow extension of {}: element {} is inverted (scaled Jacobian {:.3}): the end section is not \
                 star-shaped about its centre, so it cannot blend into a circle; use extensions.shape = \"section\" \
                 or a longer extensions.blend_length",
                end.name,
                e + 1,
                mesh.quality[e].scaled_jacobian
            )));
        }
        let quality = &mesh.quality[elements.clone()];
        reports.push(ExtensionReport {
            end: end.name.clone(),
            length,
            length_radii: length / section.radius,
            radius: section.radius,
            blend_length: match config.shape {
                ExtensionShape::Cylinder => (config.blend_length * section.radius).min(length),
                ExtensionShape::Section => 0.0,
            },
            stations,
            elements: elements.len(),
            end_centre: end_centre.into(),
            scaled_jacobian: Stats::of(quality.iter().map(|q| q.scaled_jacobian)),
            equiangle_skew: Stats::of(quality.iter().map(|q| q.equiangle_skew)),
        });
    }
    wall.nodes.sort_unstable();
    wall.faces.sort_unstable();
    mesh.node_sets.insert(sets::EXTENSION_WALL.into(), wall.nodes);
    mesh.face_sets.insert(sets::EXTENSION_WALL.into(), wall.faces);
    Ok(reports)
}

/// Refuses end names the mesh does not have (in `ends` or `[extensions.length]`), listing those
/// it has, and ends that open in the side of the mesh (no cross-section to sweep from).
fn check_end_names(mesh: &VesselMesh, config: &ExtensionsConfig) -> Result<()> {
    let known: Vec<&str> = mesh.ends.iter().map(|e| e.name.as_str()).collect();
    let named = match &config.ends {
        crate::data::config::ExtendedEnds::Names(n) => n.iter().map(|n| ("extensions.ends", n)).collect(),
        crate::data::config::ExtendedEnds::Keyword(_) => Vec::new(),
    };
    for (key, name) in named.into_iter().chain(config.length.keys().map(|n| ("extensions.length", n))) {
        let Some(end) = mesh.ends.iter().find(|e| e.name == *name) else {
            return Err(Error::Config(format!(
                "{key}: the mesh has no end named '{name}'; its ends are {}",
                known.join(", ")
            )));
        };
        if end.side {
            return Err(Error::Config(format!(
                "{key}: end '{name}' opens in the side of the mesh (a short capped branch meshed with its \
                 neighbour), with no cross-section to sweep a flow extension from; leave it out of {key}"
            )));
        }
    }
    Ok(())
}

/// The end section of `end`: its nodes and faces, plane, boundary and sizes.
fn end_section(mesh: &VesselMesh, end: &VesselEnd) -> Result<EndSection> {
    let missing = |what: &str| Error::Geometry(format!("flow extension of {}: the mesh has no {what}", end.name));
    let set = sets::lumen_end(&end.name);
    let nodes = mesh.node_sets.get(&set).ok_or_else(|| missing(&format!("node set {set}")))?.clone();
    let faces = mesh.face_sets.get(&set).ok_or_else(|| missing(&format!("face set {set}")))?.clone();
    let interface = mesh.node_sets.get(sets::INTERFACE_NODES).ok_or_else(|| missing("lumen-wall interface"))?;
    let normal = end.outward_normal.normalize();
    let e1 = crate::geometry::vector::any_perpendicular(&normal).normalize();
    let basis = [e1, normal.cross(&e1)];
    let centre = end.centre;
    let in_plane = |p: &Point3<f64>| Vector2::new((p - centre).dot(&basis[0]), (p - centre).dot(&basis[1]));
    let mut boundary: Vec<(f64, Vector2<f64>)> = nodes
        .iter()
        .filter(|n| interface.binary_search(n).is_ok())
        .map(|&n| {
            let q = in_plane(&mesh.nodes[n as usize]);
            (q.y.atan2(q.x), q)
        })
        .collect();
    boundary.sort_by(|a, b| a.0.total_cmp(&b.0));
    if boundary.len() < 3 {
        return Err(Error::Geometry(format!(
            "flow extension of {}: its end section has {} lumen-surface nodes",
            end.name,
            boundary.len()
        )));
    }
    let area: f64 = (0..boundary.len())
        .map(|k| {
            let (a, b) = (boundary[k].1, boundary[(k + 1) % boundary.len()].1);
            0.5 * (a.x * b.y - b.x * a.y)
        })
        .sum();
    // The opposite face of each end face lies one element inwards.
    let lengths: Vec<f64> = faces
        .iter()
        .map(|f| {
            let c = mesh.corners(f.element as usize);
            let opposite = crate::geometry::mesh::OPPOSITE_FACE[f.face as usize];
            (crate::geometry::mesh::face_centre(&c, f.face as usize) - crate::geometry::mesh::face_centre(&c, opposite))
                .dot(&normal)
        })
        .collect();
    let element_length = lengths.iter().sum::<f64>() / lengths.len().max(1) as f64;
    if !(area > 0.0 && element_length > 0.0) {
        return Err(Error::Geometry(format!(
            "flow extension of {}: its end section is degenerate (area {area:.3e} mm^2, element length \
             {element_length:.3e} mm)",
            end.name
        )));
    }
    let radius = (area / std::f64::consts::PI).sqrt();
    Ok(EndSection { nodes, faces, centre, normal, basis, boundary, radius, element_length })
}

impl EndSection {
    /// Distance from the centre to the section's boundary (the polygon of its surface nodes) in
    /// the in-plane direction of `q`.
    fn boundary_distance(&self, q: &Vector2<f64>) -> f64 {
        let phi = q.y.atan2(q.x);
        let n = self.boundary.len();
        // The boundary edge whose angular span holds phi (the last wraps round).
        let k = self.boundary.partition_point(|(a, _)| *a <= phi);
        let (a, b) = (self.boundary[(k + n - 1) % n].1, self.boundary[k % n].1);
        let u = q.normalize();
        // Centre + t u on the segment a + s (b - a): t from the 2D cross products.
        let e = b - a;
        let denom = u.x * e.y - u.y * e.x;
        if denom.abs() <= f64::EPSILON * e.norm() {
            return a.norm().max(b.norm());
        }
        (a.x * e.y - a.y * e.x) / denom
    }

    /// The in-plane offset of a node on the circle section: its offset scaled by the circle's
    /// radius over the boundary's distance in its direction.
    fn on_circle(&self, q: &Vector2<f64>) -> Vector2<f64> {
        if q.norm() <= 1e-12 * self.radius {
            return *q;
        }
        q * (self.radius / self.boundary_distance(q))
    }
}

/// The extension's sets gathered over every end: its wall's nodes and faces.
#[derive(Default)]
struct ExtensionWall {
    nodes: Vec<u32>,
    faces: Vec<ElementFace>,
}

/// Sweeps the extension of one end onto the mesh: its nodes, elements (annotated), sets. Returns
/// the stations added and the centre of the extended end.
fn sweep(
    mesh: &mut VesselMesh,
    end: &VesselEnd,
    section: &EndSection,
    length: f64,
    config: &ExtensionsConfig,
    wall: &mut ExtensionWall,
) -> (usize, Point3<f64>) {
    let stations = ((length / section.element_length).round() as usize).max(1);
    let new_ids = station_nodes(mesh, section, length, stations, config, wall);
    let end_faces = station_elements(mesh, section, &new_ids, wall);
    let mut end_nodes: Vec<u32> = new_ids[stations - 1].clone();
    end_nodes.sort_unstable();
    // The end's sets move to the extended end; the vessel's own end section becomes `cut_E`.
    let set = sets::lumen_end(&end.name);
    let cut_nodes = std::mem::replace(mesh.node_sets.get_mut(&set).expect("read above"), end_nodes);
    mesh.node_sets.insert(sets::cut(&end.name), cut_nodes);
    let cut_faces = std::mem::replace(mesh.face_sets.get_mut(&set).expect("read above"), end_faces);
    mesh.face_sets.insert(sets::cut(&end.name), cut_faces);
    (stations, section.centre + section.normal * length)
}

/// The nodes of every station (1 to `stations`) beyond the end section, by station and by
/// position in `section.nodes`; the extension wall's among them gathered in `wall`.
fn station_nodes(
    mesh: &mut VesselMesh,
    section: &EndSection,
    length: f64,
    stations: usize,
    config: &ExtensionsConfig,
    wall: &mut ExtensionWall,
) -> Vec<Vec<u32>> {
    let blend = match config.shape {
        ExtensionShape::Cylinder => config.blend_length * section.radius,
        ExtensionShape::Section => f64::INFINITY,
    };
    let weight = |t: f64| if blend == 0.0 { 1.0 } else { smoothstep(t / blend) };
    let (c, d) = (section.centre, section.normal);
    let on_surface: Vec<bool> = {
        let interface = &mesh.node_sets[sets::INTERFACE_NODES];
        section.nodes.iter().map(|n| interface.binary_search(n).is_ok()).collect()
    };
    let mut new_ids: Vec<Vec<u32>> = Vec::with_capacity(stations);
    for j in 1..=stations {
        let t = length * j as f64 / stations as f64;
        let w = weight(t);
        let mut ids = Vec::with_capacity(section.nodes.len());
        for (&n, &surface) in section.nodes.iter().zip(&on_surface) {
            let p = mesh.nodes[n as usize];
            let q = Vector2::new((p - c).dot(&section.basis[0]), (p - c).dot(&section.basis[1]));
            let shift = if w == 0.0 { Vector2::zeros() } else { (section.on_circle(&q) - q) * w };
            let id = mesh.nodes.len() as u32;
            mesh.nodes.push(p + d * t + section.basis[0] * shift.x + section.basis[1] * shift.y);
            if surface {
                wall.nodes.push(id);
            }
            ids.push(id);
        }
        new_ids.push(ids);
    }
    new_ids
}

/// The extension's elements, station by station, each continuing the end element below it (same
/// local axes, one station further), annotated; their wall faces gathered in `wall`. Returns
/// the faces of the extended end.
fn station_elements(
    mesh: &mut VesselMesh,
    section: &EndSection,
    new_ids: &[Vec<u32>],
    wall: &mut ExtensionWall,
) -> Vec<ElementFace> {
    let at = |j: usize, node: u32| -> u32 {
        if j == 0 {
            return node;
        }
        new_ids[j - 1][section.nodes.binary_search(&node).expect("an end face's node is in its end section")]
    };
    let lumen_faces = &mesh.face_sets[sets::LUMEN_WALL_FACES];
    let outer: Vec<bool> = section
        .faces
        .iter()
        .map(|f| lumen_faces.binary_search(&ElementFace { element: f.element, face: FACE_OUTER as u8 }).is_ok())
        .collect();
    let stations = new_ids.len();
    let mut end_faces = Vec::new();
    for j in 1..=stations {
        for (f, &on_wall) in section.faces.iter().zip(&outer) {
            let h = mesh.hexes[f.element as usize];
            // Downstream end: the end face is the top (4-7), the new element stands on it;
            // upstream: it is the bottom (0-3), the new element lies below it.
            let hex: Hex = if f.face as usize == FACE_DOWNSTREAM {
                std::array::from_fn(|i| at(j - 1 + i / 4, h[4 + i % 4]))
            } else {
                std::array::from_fn(|i| at(j - i / 4, h[i % 4]))
            };
            let e = push_element(mesh, hex, mesh.branch_of[f.element as usize]);
            if on_wall {
                wall.faces.push(ElementFace { element: e, face: FACE_OUTER as u8 });
            }
            if j == stations {
                end_faces.push(ElementFace { element: e, face: f.face });
            }
        }
    }
    end_faces
}

/// Appends an extension element, annotated; its index.
fn push_element(mesh: &mut VesselMesh, hex: Hex, branch: u32) -> u32 {
    let e = mesh.hexes.len() as u32;
    mesh.hexes.push(hex);
    mesh.regions.push(Region::Extension);
    mesh.branch_of.push(branch);
    mesh.sac.push(false);
    let corners = mesh.corners(e as usize);
    mesh.triads.push(element_triad(&corners));
    mesh.fibres.push([Vector3::zeros(); 2]);
    mesh.quality.push(element_quality(&corners));
    e
}

/// The mesh without its flow extensions: the vessel as vesselhex meshes it without them, with
/// the same node and element labels (the extensions' come last) and its end sets back at the
/// vessel's ends. Borrowed when there is no extension.
pub fn without_extensions(mesh: &VesselMesh) -> Cow<'_, VesselMesh> {
    let extension = mesh.extension_range();
    if extension.is_empty() {
        return Cow::Borrowed(mesh);
    }
    let elements = extension.start;
    let nodes = mesh.hexes[..elements].iter().flatten().map(|&n| n as usize + 1).max().unwrap_or(0);
    let mut node_sets = mesh.node_sets.clone();
    let mut face_sets = mesh.face_sets.clone();
    for end in &mesh.ends {
        let cut = sets::cut(&end.name);
        if let Some(v) = node_sets.shift_remove(&cut) {
            node_sets.insert(sets::lumen_end(&end.name), v);
        }
        if let Some(v) = face_sets.shift_remove(&cut) {
            face_sets.insert(sets::lumen_end(&end.name), v);
        }
    }
    node_sets.shift_remove(sets::EXTENSION_WALL);
    face_sets.shift_remove(sets::EXTENSION_WALL);
    Cow::Owned(VesselMesh {
        nodes: mesh.nodes[..nodes].to_vec(),
        hexes: mesh.hexes[..elements].to_vec(),
        regions: mesh.regions[..elements].to_vec(),
        branch_of: mesh.branch_of[..elements].to_vec(),
        sac: mesh.sac[..elements].to_vec(),
        triads: mesh.triads[..elements].to_vec(),
        fibres: mesh.fibres[..elements].to_vec(),
        quality: mesh.quality[..elements].to_vec(),
        layers: mesh.layers.clone(),
        ends: mesh.ends.clone(),
        node_sets,
        face_sets,
        branch_names: mesh.branch_names.clone(),
    })
}

/// The mesh's fluid alone, its elements contiguous: the lumen's, then the flow extensions'
/// (the wall's left out, face sets renumbered; nodes as they are). Borrowed when there is no
/// extension (the lumen's elements come first).
pub fn fluid_view(mesh: &VesselMesh) -> Cow<'_, VesselMesh> {
    let (lumen, extension) = (mesh.lumen_range(), mesh.extension_range());
    if extension.is_empty() {
        return Cow::Borrowed(mesh);
    }
    let elements: Vec<usize> = lumen.clone().chain(extension.clone()).collect();
    let shift = (extension.start - lumen.end) as u32;
    let face_sets = mesh
        .face_sets
        .iter()
        .map(|(name, faces)| {
            let kept = faces
                .iter()
                .filter_map(|f| {
                    let e = f.element as usize;
                    let element = if lumen.contains(&e) {
                        f.element
                    } else if extension.contains(&e) {
                        f.element - shift
                    } else {
                        return None;
                    };
                    Some(ElementFace { element, face: f.face })
                })
                .collect();
            (name.clone(), kept)
        })
        .collect();
    Cow::Owned(VesselMesh {
        nodes: mesh.nodes.clone(),
        hexes: elements.iter().map(|&e| mesh.hexes[e]).collect(),
        regions: elements.iter().map(|&e| mesh.regions[e]).collect(),
        branch_of: elements.iter().map(|&e| mesh.branch_of[e]).collect(),
        sac: elements.iter().map(|&e| mesh.sac[e]).collect(),
        triads: elements.iter().map(|&e| mesh.triads[e]).collect(),
        fibres: elements.iter().map(|&e| mesh.fibres[e]).collect(),
        quality: elements.iter().map(|&e| mesh.quality[e]).collect(),
        layers: mesh.layers.clone(),
        ends: mesh.ends.clone(),
        node_sets: mesh.node_sets.clone(),
        face_sets,
        branch_names: mesh.branch_names.clone(),
    })
}
