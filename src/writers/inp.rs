//! The wall model shared by the Abaqus and CalculiX decks: one model, two dialects.
//!
//! # What a deck holds
//! Only the wall (intima, media, adventitia) is written: its nodes, its hexahedra per layer,
//! sets, element-face surfaces, per-layer `*DISTRIBUTION` + `*ORIENTATION` carrying each
//! element's e_circ (local 1) and e_long (local 2, so local 3 = e_rad points outward), the
//! layer materials and an inflation step, both from `templates/<dialect>/`.
//!
//! * Labels: node label = 0-based node index + 1, element label = element index + 1, in every
//!   deck (so files of different formats refer to each other without a table). Lumen nodes are
//!   not written, so node labels have gaps. Quadratic elements (C3D20*) get one mid-edge node per
//!   wall edge, shared by the elements around it, numbered after every corner node in the order
//!   in which the wall elements (ascending) and their edges (canonical edge table) meet them,
//!   placed at the edge midpoint. A mid-edge node belongs to a node set when both corners of its
//!   edge do.
//! * Sets: ELSETs `INTIMA`, `MEDIA`, `ADVENTITIA`, `WALL`; NSETs of every mesh node set made of
//!   wall nodes only (`WALL_INLET`, `WALL_OUTLET`, `LUMEN_WALL_INTERFACE`, `OUTER_WALL`) plus
//!   `LUMEN_RING` (the interface nodes of the middle cross-section, for `*NODE PRINT`); a
//!   `*SURFACE, TYPE=ELEMENT` for every face set of wall elements (`WALL_LUMEN`: the pressure
//!   surface, `WALL_OUTER`, `WALL_INLET`, `WALL_OUTLET`), faces labelled S1..S6 from the
//!   canonical face table ([`crate::geometry::mesh::abaqus_face_label`]). Names are upper case, `[A-Z0-9_]`,
//!   at most 80 characters.
//! * Boundary conditions: every end ring gets a cylindrical `*TRANSFORM` about the end's axis
//!   (local 1 radial, 2 circumferential, 3 axial) and has local dofs 2 and 3 fixed. The axial
//!   fix holds the ends axially (plane strain for a straight tube); the circumferential fix
//!   removes the remaining rigid-body modes (translation across the axis and rotation about it)
//!   without restraining the radial expansion. For a straight tube under pressure u_theta = 0
//!   everywhere by symmetry, so the extra constraint does not change the solution. The FSI deck
//!   ([`super::fsi`]) removes the same motions with `*EQUATION`s in global axes instead
//!   ([`EndHold::Equations`]), so that no node it loads is under a `*TRANSFORM`. Every end of
//!   the mesh (`inlet`, `outlet` or `outlet_1`, `outlet_2`, ... of a branched vessel) gets its
//!   own ring set `WALL_<END>`, held about its own centre and normal.
//! * Load: `*DSLOAD` pressure `P` on `WALL_LUMEN` (faces S6 of the innermost wall elements):
//!   positive pressure acts into the face, i.e. pushes the wall outward. The CalculiX deck ramps
//!   it in two steps, first to [`TOE_SHARE`] of the pressure in increments of at most 1 % of it,
//!   then on to the full pressure: its fibre law stops the job when a Newton iterate
//!   overstretches a fibre, so the increments stay small while the wall is softest.
//!
//! # Units
//! Mesh lengths are mm; the deck uses `WriteOptions::length_unit` and the consistent system
//! below. The layer constants are the shared [`WallMaterial`](crate::data::config::material::WallMaterial)
//! (kPa, kg/m^3; C10 = c/2, D = 2/K), converted:
//!
//! | length | force | stress | mass  | 100 mmHg       |
//! |--------|-------|--------|-------|----------------|
//! | um     | uN    | MPa    | kg    | 0.0133322      |
//! | mm     | N     | MPa    | tonne | 0.0133322      |
//! | cm     | dyn   | Ba (0.1 Pa) | g | 133322       |
//! | m      | N     | Pa     | kg    | 13332.2        |
//!
//! # Numbers
//! Coordinates and direction components are written `{:.12e}` (13 significant digits, at most
//! 20 characters: ccx 2.20 rejects node fields of 22 characters); constants with the shortest
//! representation that reads back exactly (at most 20 characters: ccx reads `*USER MATERIAL`
//! constants in 20-character fields). At most 16 entries per data
//! line (C3D20 elements continue on a second line).

use super::text::{text_of, write_items, Text};
use super::{write_atomic, WriteOptions};
pub use crate::data::config::fe::{ElementType, FeConfig, MaterialModel};
use crate::data::error::{Error, Result};
use crate::data::units::MechanicalUnits;
use crate::geometry::mesh::{abaqus_face_label, sets, ElementFace, Region, VesselMesh, FACE_INNER, HEX_EDGES};
use nalgebra::Point3;
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};

/// 1 mmHg in MPa (133.322 Pa).
pub const MMHG_IN_MPA: f64 = 133.322e-6;

/// Share of the lumen pressure reached by the CalculiX deck's first, finely incremented step
/// (`TOE_PRESSURE` of `step_inflation.inp`): the toe of the fibre wall's response, where it is
/// softest. On the bundled Y bifurcation (coarse preset, the softer default material of earlier
/// versions: HGO 2000 with c and k1 x10) the largest displacement per 1 % of the pressure falls
/// from 0.12 mm at the start to 0.03 mm at a tenth of it; increments of 2.25 % at 3.5 % of the pressure crush a 0.036 mm intima element of the flow
/// divider in a Newton iterate, and ccx's fibre law then stops the job.
pub const TOE_SHARE: f64 = 0.1;

/// Longest name Abaqus and CalculiX accept.
pub const MAX_NAME: usize = 80;

/// Most entries on one data line.
pub const MAX_ENTRIES: usize = 16;

/// The two dialects of the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dialect {
    Abaqus,
    Calculix,
}

impl Dialect {
    fn folder(self) -> &'static str {
        match self {
            Dialect::Abaqus => "abaqus",
            Dialect::Calculix => "calculix",
        }
    }
}

/// The material template of the decks' model.
fn material_template(model: MaterialModel) -> &'static str {
    match model {
        MaterialModel::Hgo => "material_hgo.inp",
        MaterialModel::LinearElastic => "material_linear_elastic.inp",
    }
}

/// A real number for a data line: 13 significant digits, at most 20 characters.
pub fn fmt_coord(x: f64) -> String {
    text_of(|t| {
        coord(t, x);
    })
}

/// [`fmt_coord`] appended to a text.
fn coord(t: &mut Text, x: f64) -> &mut Text {
    t.exp12(if x == 0.0 { 0.0 } else { x }) // no "-0"
}

/// A constant: the shortest text that reads back exactly, or `{:.12e}` when that is longer
/// than 20 characters (ccx 2.20 reads `*USER MATERIAL` constants in fields of 20 characters:
/// `6.123233995736766e-17`, 21 characters, is read as 0.61).
pub fn fmt_const(x: f64) -> String {
    let s = format!("{x:?}");
    if s.len() <= 20 {
        s
    } else {
        fmt_coord(x)
    }
}

/// Upper case, `[A-Z0-9_]`, starting with a letter, at most [`MAX_NAME`] characters.
pub fn sanitize_name(name: &str) -> String {
    let mut s: String =
        name.chars().map(|c| if c.is_ascii_alphanumeric() { c.to_ascii_uppercase() } else { '_' }).collect();
    if !s.starts_with(|c: char| c.is_ascii_alphabetic()) {
        s.insert_str(0, "S_");
    }
    s.truncate(MAX_NAME);
    s
}

/// A template filled by [`super::template::render`], ending with a newline.
pub fn render(template: &str, source: &str, values: &[(&str, String)]) -> Result<String> {
    let mut out = super::template::render(source, template, values)?;
    if !out.ends_with('\n') {
        out.push('\n');
    }
    Ok(out)
}

fn builtin_template(dialect: Dialect, file: &str) -> Option<&'static str> {
    Some(match (dialect, file) {
        (Dialect::Abaqus, "material_hgo.inp") => include_str!("../../templates/abaqus/material_hgo.inp"),
        (Dialect::Abaqus, "material_linear_elastic.inp") => {
            include_str!("../../templates/abaqus/material_linear_elastic.inp")
        }
        (Dialect::Abaqus, "step_inflation.inp") => include_str!("../../templates/abaqus/step_inflation.inp"),
        (Dialect::Calculix, "material_hgo.inp") => include_str!("../../templates/calculix/material_hgo.inp"),
        (Dialect::Calculix, "material_linear_elastic.inp") => {
            include_str!("../../templates/calculix/material_linear_elastic.inp")
        }
        (Dialect::Calculix, "step_inflation.inp") => include_str!("../../templates/calculix/step_inflation.inp"),
        _ => return None,
    })
}

/// The text of a template and where it came from: the user's folder first, then the built-in.
fn template(fe: &FeConfig, dialect: Dialect, file: &str) -> Result<(String, String)> {
    if let Some(dir) = &fe.template_dir {
        let rel = Path::new(dialect.folder()).join(file);
        if let Some(found) = crate::io::templates::read_user_template(dir, &rel)? {
            return Ok(found);
        }
    }
    let text = builtin_template(dialect, file).ok_or_else(|| Error::Config(format!("no template {file}")))?;
    Ok((text.to_string(), format!("templates/{}/{file} (built in)", dialect.folder())))
}

/// Local-system components (x, y) of a fibre at `beta` degrees, such that a reader computing
/// z = sqrt(1 - x^2 - y^2) (CalculiX) never takes the root of a negative number.
pub fn fibre_local(beta_deg: f64) -> (f64, f64) {
    let (s, c) = beta_deg.to_radians().sin_cos();
    let (mut x, mut y) = (c.abs(), s.abs());
    if x < 1e-12 {
        (x, y) = (0.0, 1.0);
    }
    if y < 1e-12 {
        (x, y) = (1.0, 0.0);
    }
    while x > 0.0 && (1.0 - x * x - y * y < 0.0 || 1.0 - (x * x + y * y) < 0.0) {
        x = f64::from_bits(x.to_bits() - 1);
    }
    (x, y)
}

/// Mid-edge nodes of the wall's quadratic elements (C3D20 here, FEBio `hex20`): one node per
/// wall edge, shared by the elements around it, numbered in the order in which the wall elements
/// (ascending) and their edges ([`HEX_EDGES`]) meet them, labelled after every mesh node
/// ([`MidEdges::label`]) and placed at the edge midpoint. C3D20 and FEBio hex20 list them after
/// the corners in the same edge order (FORMATS.md 2a; FEBio `FEHex20::shape_fnc`), so one table
/// serves both, and the decks share their labels.
pub struct MidEdges {
    /// Corner pair of each mid-edge node (index = mid-edge number), lower node index first.
    edges: Vec<[u32; 2]>,
    /// Mid-edge numbers of each wall element, in canonical edge order.
    of_element: Vec<[u32; 12]>,
    /// First wall element.
    wall_start: usize,
}

impl MidEdges {
    pub fn new(mesh: &VesselMesh) -> Self {
        let wall = mesh.wall_range();
        let wall_start = wall.start;
        let mut index: HashMap<(u32, u32), u32> = HashMap::with_capacity(wall.len() * 3);
        let mut edges = Vec::with_capacity(wall.len() * 3);
        let mut of_element = Vec::with_capacity(wall.len());
        for h in &mesh.hexes[wall] {
            let ids: [u32; 12] = std::array::from_fn(|k| {
                let (a, b) = (h[HEX_EDGES[k][0]], h[HEX_EDGES[k][1]]);
                let key = (a.min(b), a.max(b));
                *index.entry(key).or_insert_with(|| {
                    edges.push([key.0, key.1]);
                    (edges.len() - 1) as u32
                })
            });
            of_element.push(ids);
        }
        MidEdges { edges, of_element, wall_start }
    }
    /// Number of mid-edge nodes.
    pub fn len(&self) -> usize {
        self.edges.len()
    }
    pub fn is_empty(&self) -> bool {
        self.edges.is_empty()
    }
    /// 1-based label of mid-edge node `m`: after every mesh node, so labels stay unique and
    /// increasing.
    pub fn label(&self, mesh: &VesselMesh, m: u32) -> u64 {
        mesh.nodes.len() as u64 + 1 + m as u64
    }
    /// The two corner nodes (0-based mesh indices) of mid-edge node `m`.
    pub fn corners(&self, m: u32) -> [u32; 2] {
        self.edges[m as usize]
    }
    /// Position of mid-edge node `m` (mesh unit, mm): the midpoint of its edge.
    pub fn position(&self, mesh: &VesselMesh, m: u32) -> Point3<f64> {
        let [a, b] = self.edges[m as usize];
        Point3::from((mesh.nodes[a as usize].coords + mesh.nodes[b as usize].coords) * 0.5)
    }
    /// Mid-edge nodes of wall element `e` (mesh element index), in [`HEX_EDGES`] order: the
    /// nodes 9..20 of C3D20 and FEBio hex20.
    pub fn of_element(&self, e: usize) -> [u32; 12] {
        self.of_element[e - self.wall_start]
    }
    /// Mid-edge nodes of face `f` of wall element `e`, in the order of the face's edges
    /// (corner 0-1, 1-2, 2-3, 3-0 of [`crate::geometry::mesh::HEX_FACES`]): the nodes 5..8 of a quad8 facet.
    pub fn of_face(&self, e: usize, f: usize) -> [u32; 4] {
        let corners = crate::geometry::mesh::HEX_FACES[f];
        let mids = self.of_element(e);
        std::array::from_fn(|i| {
            let (a, b) = (corners[i], corners[(i + 1) % 4]);
            let k = HEX_EDGES
                .iter()
                .position(|ed| (ed[0] == a && ed[1] == b) || (ed[0] == b && ed[1] == a))
                .expect("a face edge is a hex edge");
            mids[k]
        })
    }
    /// The mid-edge nodes whose two corners are both in `members` (sorted 0-based node
    /// indices), ascending: the quadratic completion of a node set (a ring, a surface's nodes).
    pub fn completing(&self, mesh: &VesselMesh, members: &[u32]) -> Vec<u32> {
        let mut in_set = vec![false; mesh.nodes.len()];
        for &n in members {
            in_set[n as usize] = true;
        }
        (0..self.edges.len() as u32).filter(|&m| self.edges[m as usize].iter().all(|&n| in_set[n as usize])).collect()
    }
}

/// How a deck holds its end rings (both remove the same motions: the displacement along the end's
/// normal and the circumferential one; the radial expansion stays free).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EndHold {
    /// A cylindrical `*TRANSFORM` about each end's axis and local dofs 2 (circumferential) and 3
    /// (axial) fixed: the inflation decks.
    Transform,
    /// `*EQUATION`s in global axes, no `*TRANSFORM`: every ring node moves only along its radial
    /// direction in the end plane, r = (x - c) - ((x - c).n) n normalised (c the end's centre, n
    /// its outward normal, both from the mesh, so oblique ends of branches work). Per node, with
    /// f the global dof of the largest |r_f|, two equations u_p - (r_p/r_f) u_f = 0 for the other
    /// two dofs p (dependent, eliminated). For the FSI deck: the CalculiX adapter writes its
    /// `*CLOAD` forces in global axes, which ccx would read in local axes on a node under a
    /// `*TRANSFORM`; a force on an eliminated dof is carried over to the free one.
    Equations,
}

/// One end ring of the deck.
struct EndRing {
    /// Node set name in the deck.
    set: String,
    /// Labels of the ring's nodes (corners and, for quadratic elements, mid-edge nodes).
    labels: Vec<u64>,
    /// Centre and outward unit normal (mesh unit).
    centre: Point3<f64>,
    normal: nalgebra::Vector3<f64>,
    /// [`EndHold::Equations`]: per ring node its label and in-plane radial unit direction.
    radial: Vec<(u64, nalgebra::Vector3<f64>)>,
}

/// The two equations of an [`EndHold::Equations`] ring node: (dependent dof, free dof, coefficient
/// of the free dof), dofs 1-based, for u_dependent + coefficient u_free = 0.
pub fn radial_equations(r: &nalgebra::Vector3<f64>) -> [(usize, usize, f64); 2] {
    let f = (0..3).max_by(|a, b| r[*a].abs().total_cmp(&r[*b].abs())).unwrap_or(0);
    let mut others = (0..3).filter(|k| *k != f);
    let (p, q) = (others.next().unwrap_or(0), others.next().unwrap_or(0));
    [(p + 1, f + 1, -r[p] / r[f]), (q + 1, f + 1, -r[q] / r[f])]
}

/// One wall layer of the deck.
struct LayerBlock {
    region: Region,
    name: String,
    range: std::ops::Range<usize>,
    beta_deg: f64,
    material_name: String,
    material_text: String,
}

/// Everything of a deck that can fail, computed before the file is opened.
struct Deck<'a> {
    mesh: &'a VesselMesh,
    dialect: Dialect,
    element: ElementType,
    scale: f64,
    units: MechanicalUnits,
    nodes: Vec<u32>,
    mids: Option<MidEdges>,
    node_sets: Vec<(String, Vec<u64>)>,
    surfaces: Vec<(String, Vec<ElementFace>)>,
    hold: EndHold,
    ends: Vec<EndRing>,
    layers: Vec<LayerBlock>,
    step: String,
}

/// The interface nodes of the middle cross-section: walk downstream from the inlet ring along
/// the wall's lumen faces (S6: corner 0 -> 4 and 3 -> 7 go downstream). `None` if the mesh
/// does not have that structure.
fn middle_lumen_ring(mesh: &VesselMesh) -> Option<Vec<u32>> {
    let inlet = mesh.inlet()?;
    let ring_set = mesh.node_sets.get(&sets::wall_end(&inlet.name))?;
    let interface = mesh.node_sets.get(sets::INTERFACE_NODES)?;
    let faces = mesh.face_sets.get(sets::WALL_LUMEN_FACES)?;
    let mut next: HashMap<u32, u32> = HashMap::with_capacity(faces.len() * 2);
    for f in faces.iter().filter(|f| f.face as usize == FACE_INNER) {
        let h = &mesh.hexes[f.element as usize];
        next.insert(h[0], h[4]);
        next.insert(h[3], h[7]);
    }
    let mut ring: Vec<u32> = ring_set.iter().copied().filter(|n| interface.binary_search(n).is_ok()).collect();
    if ring.is_empty() {
        return None;
    }
    let mut rings = vec![ring.clone()];
    while ring.iter().all(|n| next.contains_key(n)) && rings.len() <= mesh.nodes.len() {
        ring = ring.iter().map(|n| next[n]).collect();
        rings.push(ring.clone());
    }
    let mut mid = rings.swap_remove(rings.len() / 2);
    mid.sort_unstable();
    Some(mid)
}

/// The deck's node sets: those of the mesh made of wall nodes only, plus the middle lumen ring
/// (`lumen_ring`, the interface when the lumen has no ring), as labels (with the mid-edge nodes
/// they complete, for quadratic elements), sorted.
fn wall_node_sets(mesh: &VesselMesh, nodes: &[u32], mids: Option<&MidEdges>) -> Vec<(String, Vec<u64>)> {
    let mut is_wall_node = vec![false; mesh.nodes.len()];
    for &n in nodes {
        is_wall_node[n as usize] = true;
    }
    let mut raw_sets: Vec<(String, Vec<u32>)> = mesh
        .node_sets
        .iter()
        .filter(|(_, v)| !v.is_empty() && v.iter().all(|&n| is_wall_node[n as usize]))
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    let ring = middle_lumen_ring(mesh).or_else(|| mesh.node_sets.get(sets::INTERFACE_NODES).cloned());
    if let Some(ring) = ring {
        raw_sets.push(("lumen_ring".into(), ring));
    }
    let mut node_sets = Vec::with_capacity(raw_sets.len());
    for (name, members) in raw_sets {
        let mut labels: Vec<u64> = members.iter().map(|&n| n as u64 + 1).collect();
        if let Some(m) = mids {
            labels.extend(m.completing(mesh, &members).into_iter().map(|k| m.label(mesh, k)));
        }
        labels.sort_unstable();
        node_sets.push((sanitize_name(&name), labels));
    }
    node_sets
}

/// The end rings to hold: each end's wall ring (its set in `node_sets`), with, for
/// [`EndHold::Equations`], each node's radial direction in the end plane.
fn end_rings(
    mesh: &VesselMesh,
    node_sets: &[(String, Vec<u64>)],
    mids: Option<&MidEdges>,
    hold: EndHold,
) -> Result<Vec<EndRing>> {
    let mut ends = Vec::new();
    for end in &mesh.ends {
        let name = sanitize_name(&sets::wall_end(&end.name));
        let Some((_, labels)) = node_sets.iter().find(|s| s.0 == name) else {
            continue;
        };
        let normal = end.outward_normal.normalize();
        let mut radial = Vec::new();
        if hold == EndHold::Equations {
            for &label in labels {
                let p = label_position(mesh, mids, label);
                let d = p - end.centre;
                let r = d - normal * d.dot(&normal);
                let on_axis = r.norm() <= 1e-9 * d.norm();
                if on_axis || !r.norm().is_finite() {
                    return Err(Error::Geometry(format!(
                        "end '{}': ring node {label} lies on the end's axis, so it has no radial direction to move in",
                        end.name
                    )));
                }
                radial.push((label, r.normalize()));
            }
        }
        ends.push(EndRing { set: name, labels: labels.clone(), centre: end.centre, normal, radial });
    }
    if ends.is_empty() {
        return Err(Error::Geometry("the mesh has no end rings to hold: the inflation would be ill-posed".into()));
    }

    Ok(ends)
}

/// Each wall layer's block: its elements, fibre angle and material, rendered from the
/// dialect's template.
fn layer_blocks(
    mesh: &VesselMesh,
    options: &WriteOptions,
    dialect: Dialect,
    units: &MechanicalUnits,
) -> Result<Vec<LayerBlock>> {
    let fe = &options.fe;
    let (mat_text, mat_source) = template(fe, dialect, material_template(fe.material))?;
    let mut layers = Vec::new();
    for region in Region::WALL {
        let range = mesh.region_range(region);
        if range.is_empty() {
            continue;
        }
        let layer_name = sanitize_name(region.name());
        let beta_deg = mesh.layers.iter().find(|l| l.region == region).map(|l| l.fibre_angle_deg).unwrap_or(0.0);
        let m = options.material.layer(region);
        m.check(region.name())?;
        if dialect == Dialect::Calculix && fe.material == MaterialModel::Hgo && m.kappa != 0.0 {
            return Err(Error::Config(format!(
                "material.{}.kappa = {}: CalculiX's fibre material (ELASTIC_FIBER) has no dispersion, so its deck \
                 would differ from the Abaqus and FEBio ones; set kappa = 0 or leave out the calculix and fsi formats",
                region.name(),
                m.kappa
            )));
        }
        let material_name = match (dialect, fe.material) {
            (Dialect::Calculix, MaterialModel::Hgo) => format!("ELASTIC_FIBER_{layer_name}"),
            (Dialect::Abaqus, MaterialModel::Hgo) => format!("HGO_{layer_name}"),
            (_, MaterialModel::LinearElastic) => format!("LINEAR_{layer_name}"),
        };
        let (fx, fy) = fibre_local(beta_deg);
        let values = [
            ("LAYER", layer_name.clone()),
            ("MATERIAL", material_name.clone()),
            ("C10", fmt_const(m.c10(units))),
            ("D", fmt_const(m.d(units))),
            ("K1", fmt_const(m.k1(units))),
            ("K2", fmt_const(m.k2)),
            ("KAPPA", fmt_const(m.kappa)),
            ("FIBRE1_X", fmt_const(fx)),
            ("FIBRE1_Y", fmt_const(fy)),
            ("FIBRE2_X", fmt_const(fx)),
            ("FIBRE2_Y", fmt_const(-fy)),
            ("BETA_DEG", fmt_const(beta_deg)),
            ("E", fmt_const(m.youngs_modulus(units))),
            ("NU", fmt_const(m.poisson_ratio)),
            ("DENSITY", fmt_const(m.density(units))),
            ("UNITS", units.describe()),
        ];
        let material_text = render(&mat_text, &mat_source, &values)?;
        layers.push(LayerBlock { region, name: layer_name, range, beta_deg, material_name, material_text });
    }

    Ok(layers)
}

impl<'a> Deck<'a> {
    fn new(mesh: &'a VesselMesh, options: &WriteOptions, dialect: Dialect, hold: EndHold) -> Result<Self> {
        let fe = &options.fe;
        let element = match dialect {
            Dialect::Abaqus => fe.abaqus_element,
            Dialect::Calculix => fe.calculix_element,
        };
        if dialect == Dialect::Calculix && !element.in_calculix() {
            return Err(Error::Config(format!(
                "fe.calculix_element: CalculiX has no hybrid element {}; use C3D8I, C3D8, C3D8R, C3D20 or C3D20R",
                element.name()
            )));
        }
        if !(fe.pressure_mmhg.is_finite() && fe.pressure_mmhg >= 0.0) {
            return Err(Error::Config("fe.pressure_mmhg: must be zero or positive".into()));
        }
        let wall = mesh.wall_range();
        if wall.is_empty() {
            return Err(Error::Geometry(
                "the mesh has no wall elements: nothing to write to an Abaqus/CalculiX deck".into(),
            ));
        }
        let units = MechanicalUnits::of(options.length_unit);
        let scale = options.length_unit.from_mm();
        let nodes = mesh.nodes_of(wall.clone());
        let mids = element.is_quadratic().then(|| MidEdges::new(mesh));

        let node_sets = wall_node_sets(mesh, &nodes, mids.as_ref());
        let surfaces: Vec<(String, Vec<ElementFace>)> = mesh
            .face_sets
            .iter()
            .filter(|(_, v)| !v.is_empty() && v.iter().all(|f| wall.contains(&(f.element as usize))))
            .map(|(k, v)| (sanitize_name(k), v.clone()))
            .collect();
        let pressure_surface = sanitize_name(sets::WALL_LUMEN_FACES);
        if !surfaces.iter().any(|s| s.0 == pressure_surface) {
            return Err(Error::Geometry(format!(
                "the mesh has no '{}' face set: no surface to load",
                sets::WALL_LUMEN_FACES
            )));
        }
        let ends = end_rings(mesh, &node_sets, mids.as_ref(), hold)?;
        let layers = layer_blocks(mesh, options, dialect, &units)?;

        // Step.
        let (step_text, step_source) = template(fe, dialect, "step_inflation.inp")?;
        let step = render(
            &step_text,
            &step_source,
            &[
                ("PRESSURE", fmt_const(units.stress_from_mpa(fe.pressure_mmhg * MMHG_IN_MPA))),
                ("TOE_PRESSURE", fmt_const(units.stress_from_mpa(TOE_SHARE * fe.pressure_mmhg * MMHG_IN_MPA))),
                ("PRESSURE_MMHG", fmt_const(fe.pressure_mmhg)),
                ("PRESSURE_SURFACE", pressure_surface),
                ("PRINT_NSET", "LUMEN_RING".to_string()),
                ("UNITS", units.describe()),
            ],
        )?;
        Ok(Deck { mesh, dialect, element, scale, units, nodes, mids, node_sets, surfaces, hold, ends, layers, step })
    }

    fn write(&self, w: &mut dyn Write) -> std::io::Result<()> {
        self.write_model(w)?;
        w.write_all(self.step.as_bytes())
    }

    /// Everything before the step.
    fn write_model(&self, w: &mut dyn Write) -> std::io::Result<()> {
        let mesh = self.mesh;
        let wall = mesh.wall_range();
        writeln!(w, "*HEADING")?;
        writeln!(
            w,
            "vesselhex vessel wall: {} {} elements in {} layers, inflation to the lumen pressure",
            wall.len(),
            self.element.name(),
            self.layers.len()
        )?;
        writeln!(w, "** Written by vesselhex {} ({} dialect).", env!("CARGO_PKG_VERSION"), self.dialect.folder())?;
        writeln!(w, "** Units: {}.", self.units.describe())?;
        writeln!(
            w,
            "** Node label = vesselhex node index + 1; element label = element index + 1 (lumen not written)."
        )?;
        writeln!(
            w,
            "** Local axes per element: 1 = circumferential, 2 = longitudinal (inlet to outlet), 3 = radial outward."
        )?;
        writeln!(w, "*NODE")?;
        let node_line = |t: &mut Text, label: u64, p: Point3<f64>| {
            let p = p.coords * self.scale;
            t.uint(label).str(", ");
            coord(t, p.x).str(", ");
            coord(t, p.y).str(", ");
            coord(t, p.z).byte(b'\n');
        };
        write_items(w, self.nodes.len(), |t, i| {
            let n = self.nodes[i];
            node_line(t, n as u64 + 1, mesh.nodes[n as usize]);
        })?;
        if let Some(m) = &self.mids {
            write_items(w, m.len(), |t, k| node_line(t, m.label(mesh, k as u32), m.position(mesh, k as u32)))?;
        }
        for layer in &self.layers {
            writeln!(w, "*ELEMENT, TYPE={}, ELSET={}", self.element.name(), layer.name)?;
            write_items(w, layer.range.len(), |t, i| {
                let e = layer.range.start + i;
                let mut entries = [0u64; 21];
                entries[0] = e as u64 + 1;
                for (k, &n) in mesh.hexes[e].iter().enumerate() {
                    entries[1 + k] = n as u64 + 1;
                }
                let mut count = 9;
                if let Some(m) = &self.mids {
                    for (k, &mid) in m.of_element(e).iter().enumerate() {
                        entries[9 + k] = m.label(mesh, mid);
                    }
                    count = 21;
                }
                data_record(t, &entries[..count]);
            })?;
        }
        writeln!(w, "*ELSET, ELSET=WALL, GENERATE")?;
        writeln!(w, "{}, {}, 1", wall.start + 1, wall.end)?;
        for (name, labels) in &self.node_sets {
            writeln!(w, "*NSET, NSET={name}")?;
            write_data_lines(w, labels)?;
        }
        for (name, faces) in &self.surfaces {
            writeln!(w, "*SURFACE, NAME={name}, TYPE=ELEMENT")?;
            write_items(w, faces.len(), |t, i| {
                let f = faces[i];
                t.uint(f.element as u64 + 1).str(", ").str(abaqus_face_label(f.face as usize)).byte(b'\n');
            })?;
        }
        self.write_end_holds(w)?;
        self.write_orientations(w)?;
        for layer in &self.layers {
            writeln!(
                w,
                "** {} ({}): fibres at +-{} deg from circumferential",
                layer.name,
                layer.region.name(),
                fmt_const(layer.beta_deg)
            )?;
            w.write_all(layer.material_text.as_bytes())?;
        }
        for layer in &self.layers {
            writeln!(
                w,
                "*SOLID SECTION, ELSET={}, MATERIAL={}, ORIENTATION=ORI_{}",
                layer.name, layer.material_name, layer.name
            )?;
            if self.dialect == Dialect::Abaqus {
                writeln!(w, ",")?;
            }
        }
        Ok(())
    }

    /// How the end rings are held (see [`EndHold`]).
    fn write_end_holds(&self, w: &mut dyn Write) -> std::io::Result<()> {
        match self.hold {
            EndHold::Transform => {
                writeln!(
                    w,
                    "** End rings: cylindrical systems about the end axes (1 radial, 2 circumferential, 3 axial);"
                )?;
                writeln!(w, "** circumferential and axial motion fixed, radial expansion free.")?;
                for ring in &self.ends {
                    let a = ring.centre.coords * self.scale;
                    let b = a + ring.normal * self.scale.max(1e-300);
                    writeln!(w, "*TRANSFORM, NSET={}, TYPE=C\n{}", ring.set, two_vectors(&a, &b))?;
                }
                writeln!(w, "*BOUNDARY")?;
                for ring in &self.ends {
                    writeln!(w, "{}, 2, 3", ring.set)?;
                }
            }
            EndHold::Equations => {
                writeln!(
                    w,
                    "** End rings, in global axes (no *TRANSFORM): each ring node moves only along its radial"
                )?;
                writeln!(
                    w,
                    "** direction r in the end plane (normal and circumferential motion zero). Per node, with f the"
                )?;
                writeln!(w, "** dof of the largest |r_f|, u_p - (r_p / r_f) u_f = 0 for the two other dofs p.")?;
                for ring in &self.ends {
                    let n = ring.normal;
                    writeln!(
                        w,
                        "** {}: {} nodes, end normal ({}, {}, {})",
                        ring.set,
                        ring.labels.len(),
                        fmt_coord(n.x),
                        fmt_coord(n.y),
                        fmt_coord(n.z)
                    )?;
                    writeln!(w, "*EQUATION")?;
                    for (label, r) in &ring.radial {
                        for (dependent, free, coefficient) in radial_equations(r) {
                            writeln!(w, "2\n{label}, {dependent}, 1., {label}, {free}, {}", fmt_coord(coefficient))?;
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// Each layer's per-element triads (a distribution) and the orientation built on them.
    fn write_orientations(&self, w: &mut dyn Write) -> std::io::Result<()> {
        let mesh = self.mesh;
        if self.dialect == Dialect::Abaqus {
            writeln!(w, "*DISTRIBUTION TABLE, NAME=TRIAD_TABLE")?;
            writeln!(w, "COORD3D, COORD3D")?;
        }
        for layer in &self.layers {
            let dist = format!("TRIAD_{}", layer.name);
            match self.dialect {
                Dialect::Abaqus => writeln!(w, "*DISTRIBUTION, NAME={dist}, LOCATION=ELEMENT, TABLE=TRIAD_TABLE")?,
                Dialect::Calculix => writeln!(w, "*DISTRIBUTION, NAME={dist}")?,
            }
            writeln!(w, ", 1., 0., 0., 0., 1., 0.")?;
            write_items(w, layer.range.len(), |t, i| {
                let e = layer.range.start + i;
                let triad = &mesh.triads[e];
                t.uint(e as u64 + 1).str(", ");
                vector_pair(t, &triad.e_circ, &triad.e_long).byte(b'\n');
            })?;
            match self.dialect {
                Dialect::Abaqus => {
                    writeln!(
                        w,
                        "*ORIENTATION, NAME=ORI_{}, DEFINITION=COORDINATES, SYSTEM=RECTANGULAR, LOCAL DIRECTIONS=2",
                        layer.name
                    )?;
                    writeln!(w, "{dist}")?;
                    writeln!(w, "3, 0.")?;
                    let (x, y) = fibre_local(layer.beta_deg);
                    writeln!(w, "{}, {}, 0.", fmt_coord(x), fmt_coord(y))?;
                    writeln!(w, "{}, {}, 0.", fmt_coord(x), fmt_coord(-y))?;
                }
                Dialect::Calculix => {
                    writeln!(w, "*ORIENTATION, NAME=ORI_{}, SYSTEM=RECTANGULAR", layer.name)?;
                    writeln!(w, "{dist}")?;
                }
            }
        }
        Ok(())
    }
}

/// The six components of two vectors as data-line fields, `ax, ay, az, bx, by, bz`: the two
/// points of a `*TRANSFORM` axis, the two directions of a `*DISTRIBUTION` line.
fn two_vectors(a: &nalgebra::Vector3<f64>, b: &nalgebra::Vector3<f64>) -> String {
    text_of(|t| {
        vector_pair(t, a, b);
    })
}

/// [`two_vectors`] appended to a text.
fn vector_pair<'t>(t: &'t mut Text, a: &nalgebra::Vector3<f64>, b: &nalgebra::Vector3<f64>) -> &'t mut Text {
    for (k, x) in [a.x, a.y, a.z, b.x, b.y, b.z].into_iter().enumerate() {
        if k > 0 {
            t.str(", ");
        }
        coord(t, x);
    }
    t
}

/// Position (mesh unit) of a deck node label: a mesh node or a mid-edge node.
fn label_position(mesh: &VesselMesh, mids: Option<&MidEdges>, label: u64) -> Point3<f64> {
    let n = mesh.nodes.len() as u64;
    match mids {
        Some(m) if label > n => m.position(mesh, (label - n - 1) as u32),
        _ => mesh.nodes[(label - 1) as usize],
    }
}

/// One record of comma-separated entries, at most [`MAX_ENTRIES`] per line; a line that
/// continues ends with a comma.
fn write_data_lines(w: &mut dyn Write, entries: &[u64]) -> std::io::Result<()> {
    let lines = entries.len().div_ceil(MAX_ENTRIES);
    write_items(w, lines, |t, i| data_line(t, entries, i, lines))
}

/// Line `i` of `lines` of a record ([`write_data_lines`]).
fn data_line(t: &mut Text, entries: &[u64], i: usize, lines: usize) {
    let chunk = &entries[i * MAX_ENTRIES..((i + 1) * MAX_ENTRIES).min(entries.len())];
    t.uints(chunk.iter().copied(), ", ");
    if i + 1 < lines {
        t.byte(b',');
    }
    t.byte(b'\n');
}

/// A short record ([`write_data_lines`]) appended to a text.
fn data_record(t: &mut Text, entries: &[u64]) {
    let lines = entries.len().div_ceil(MAX_ENTRIES);
    (0..lines).for_each(|i| data_line(t, entries, i, lines));
}

/// The model data of a deck (everything before its step), checked when built and written by
/// [`ModelData::write`], so that another step can follow the same model.
pub struct ModelData<'a>(Deck<'a>);

impl<'a> ModelData<'a> {
    pub fn new(mesh: &'a VesselMesh, options: &WriteOptions, dialect: Dialect, hold: EndHold) -> Result<Self> {
        Deck::new(mesh, options, dialect, hold).map(ModelData)
    }
    pub fn write(&self, w: &mut dyn Write) -> std::io::Result<()> {
        self.0.write_model(w)
    }
}

/// Writes `<dialect>/model.inp` under `dir`.
pub fn write_inp(mesh: &VesselMesh, options: &WriteOptions, dialect: Dialect, dir: &Path) -> Result<Vec<PathBuf>> {
    let deck = Deck::new(mesh, options, dialect, EndHold::Transform)?;
    let sub = PathBuf::from(dialect.folder());
    std::fs::create_dir_all(dir.join(&sub)).map_err(|e| Error::io(dir.join(&sub), "cannot create the folder", e))?;
    let name = sub.join("model.inp");
    write_atomic(&dir.join(&name), |w| deck.write(w))?;
    Ok(vec![name])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::mesh::{quad_area_vector, HEX_FACES};
    use nalgebra::Vector3;

    fn unit_cube() -> [Point3<f64>; 8] {
        [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(1.0, 1.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, 0.0, 1.0),
            Point3::new(1.0, 0.0, 1.0),
            Point3::new(1.0, 1.0, 1.0),
            Point3::new(0.0, 1.0, 1.0),
        ]
    }

    /// Abaqus' own listing of the hexahedron faces (1-based corners, inward right-hand normal).
    const ABAQUS_LISTING: [(&str, [usize; 4]); 6] = [
        ("S1", [1, 2, 3, 4]),
        ("S2", [5, 8, 7, 6]),
        ("S3", [1, 5, 6, 2]),
        ("S4", [2, 6, 7, 3]),
        ("S5", [3, 7, 8, 4]),
        ("S6", [4, 8, 5, 1]),
    ];

    fn face_check(f: usize) {
        let c = unit_cube();
        let label = abaqus_face_label(f);
        let (abq_label, abq) = ABAQUS_LISTING.iter().find(|(l, _)| *l == label).unwrap();
        assert_eq!(*abq_label, label);
        // Same corners as Abaqus' face of that label.
        let mut ours: Vec<usize> = HEX_FACES[f].iter().map(|i| i + 1).collect();
        let mut theirs = abq.to_vec();
        ours.sort_unstable();
        theirs.sort_unstable();
        assert_eq!(ours, theirs, "{label}: corners");
        // Our winding is outward, Abaqus' listing inward: opposite normals on the unit cube.
        let outward = quad_area_vector(HEX_FACES[f].map(|i| c[i]));
        let inward = quad_area_vector(abq.map(|i| c[i - 1]));
        assert!((outward + inward).norm() < 1e-12, "{label}: {outward:?} vs {inward:?}");
        // And outward means away from the cube's centre.
        let centre = Point3::new(0.5, 0.5, 0.5);
        assert!((crate::geometry::mesh::face_centre(&c, f) - centre).dot(&outward) > 0.0);
        let expected = [
            Vector3::new(0.0, 0.0, -1.0),
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::new(0.0, -1.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
            Vector3::new(-1.0, 0.0, 0.0),
        ];
        assert!((outward - expected[f]).norm() < 1e-12);
    }

    #[test]
    fn unit_cube_face_s1() {
        face_check(0);
    }
    #[test]
    fn unit_cube_face_s2() {
        face_check(1);
    }
    #[test]
    fn unit_cube_face_s3() {
        face_check(2);
    }
    #[test]
    fn unit_cube_face_s4() {
        face_check(3);
    }
    #[test]
    fn unit_cube_face_s5() {
        face_check(4);
    }
    #[test]
    fn unit_cube_face_s6() {
        face_check(5);
    }

    #[test]
    fn numbers_fit_the_field_width_with_13_digits() {
        for x in [-123.45678901234568, 1e-300, -1e300, 0.0, -0.0, 2.0f64.sqrt(), -999.999999999999] {
            let s = fmt_coord(x);
            assert!(s.len() <= 20, "{s}");
            let mantissa = s.split('e').next().unwrap().replace(['-', '.'], "");
            assert_eq!(mantissa.len(), 13, "{s}");
            let back: f64 = s.parse().unwrap();
            assert!((back - x).abs() <= 1e-12 * x.abs(), "{s}");
        }
        for x in [0.0133322, 1.2e-15, 1e22, 6.666666666666667, -3.3e-300] {
            let s = fmt_const(x);
            assert!(s.len() <= 20, "{s}");
            assert_eq!(s.parse::<f64>().unwrap(), x);
        }
    }

    #[test]
    fn render_is_strict() {
        let v = [("A", "1".to_string())];
        assert_eq!(render("x {{A}} {{ A }}", "t", &v).unwrap(), "x 1 1\n");
        let e = render("{{B}}", "t.inp", &v).unwrap_err().to_string();
        assert!(e.contains("t.inp") && e.contains("{{B}}"), "{e}");
        assert!(render("{{A", "t", &v).is_err());
    }

    #[test]
    fn builtin_templates_use_only_known_placeholders() {
        let fe = FeConfig::default();
        for dialect in [Dialect::Abaqus, Dialect::Calculix] {
            for file in ["material_hgo.inp", "material_linear_elastic.inp", "step_inflation.inp"] {
                let (text, _) = template(&fe, dialect, file).unwrap();
                let keys = [
                    "LAYER",
                    "MATERIAL",
                    "C10",
                    "D",
                    "K1",
                    "K2",
                    "KAPPA",
                    "FIBRE1_X",
                    "FIBRE1_Y",
                    "FIBRE2_X",
                    "FIBRE2_Y",
                    "BETA_DEG",
                    "E",
                    "NU",
                    "DENSITY",
                    "UNITS",
                    "PRESSURE",
                    "PRESSURE_MMHG",
                    "TOE_PRESSURE",
                    "PRESSURE_SURFACE",
                    "PRINT_NSET",
                ];
                let values: Vec<(&str, String)> = keys.iter().map(|k| (*k, "1".to_string())).collect();
                render(&text, file, &values).unwrap();
            }
        }
    }

    #[test]
    fn fibre_components_keep_the_root_real() {
        for beta in [0.0, 29.0, 45.0, 62.0, 89.999, 90.0, 1e-14] {
            let (x, y) = fibre_local(beta);
            assert!(1.0 - x * x - y * y >= 0.0 && 1.0 - (x * x + y * y) >= 0.0, "{beta}");
            assert!((x.hypot(y) - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn names_are_sanitised() {
        assert_eq!(sanitize_name("wall_inlet"), "WALL_INLET");
        assert_eq!(sanitize_name("outlet,1 a"), "OUTLET_1_A");
        assert_eq!(sanitize_name("1x"), "S_1X");
        assert_eq!(sanitize_name(&"a".repeat(200)).len(), MAX_NAME);
    }
}
