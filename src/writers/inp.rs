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
//!   canonical face table ([`crate::mesh::abaqus_face_label`]). Names are upper case, `[A-Z0-9_]`,
//!   at most 80 characters.
//! * Boundary conditions: every end ring gets a cylindrical `*TRANSFORM` about the end's axis
//!   (local 1 radial, 2 circumferential, 3 axial) and has local dofs 2 and 3 fixed. The axial
//!   fix holds the ends axially (plane strain for a straight tube); the circumferential fix
//!   removes the remaining rigid-body modes (translation across the axis and rotation about it)
//!   without restraining the radial expansion. For a straight tube under pressure u_theta = 0
//!   everywhere by symmetry, so the extra constraint does not change the solution.
//! * Load: `*DSLOAD` pressure `P` on `WALL_LUMEN` (faces S6 of the innermost wall elements):
//!   positive pressure acts into the face, i.e. pushes the wall outward.
//!
//! # Units
//! Mesh lengths are mm; the deck uses `WriteOptions::length_unit` and the consistent system
//! below. Material constants in [`FeConfig`] are given in MPa (stress) and tonne/mm^3
//! (density) and converted:
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

use super::{write_atomic, WriteOptions};
use crate::error::{Error, Result};
use crate::mesh::{abaqus_face_label, sets, ElementFace, Region, VesselMesh, FACE_INNER, HEX_EDGES};
use crate::units::MechanicalUnits;
use nalgebra::Point3;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};

/// 1 mmHg in MPa (133.322 Pa).
pub const MMHG_IN_MPA: f64 = 133.322e-6;

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

/// Continuum element types.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum ElementType {
    C3D8,
    C3D8H,
    C3D8R,
    C3D8I,
    C3D20,
    C3D20H,
    C3D20R,
    C3D20RH,
}

impl ElementType {
    pub fn name(self) -> &'static str {
        match self {
            ElementType::C3D8 => "C3D8",
            ElementType::C3D8H => "C3D8H",
            ElementType::C3D8R => "C3D8R",
            ElementType::C3D8I => "C3D8I",
            ElementType::C3D20 => "C3D20",
            ElementType::C3D20H => "C3D20H",
            ElementType::C3D20R => "C3D20R",
            ElementType::C3D20RH => "C3D20RH",
        }
    }
    /// 20-node serendipity brick.
    pub fn is_quadratic(self) -> bool {
        matches!(self, ElementType::C3D20 | ElementType::C3D20H | ElementType::C3D20R | ElementType::C3D20RH)
    }
    /// CalculiX has no hybrid elements.
    pub fn in_calculix(self) -> bool {
        !matches!(self, ElementType::C3D8H | ElementType::C3D20H | ElementType::C3D20RH)
    }
}

/// Which material template the decks use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaterialModel {
    /// Holzapfel-Gasser-Ogden with two fibre families at +-beta (Abaqus `*ANISOTROPIC
    /// HYPERELASTIC, HOLZAPFEL`; CalculiX `ELASTIC_FIBER` user material).
    Hgo,
    /// Isotropic linear elastic (`*ELASTIC`), e.g. to compare with Lame's solution.
    LinearElastic,
}

impl MaterialModel {
    fn template(self) -> &'static str {
        match self {
            MaterialModel::Hgo => "material_hgo.inp",
            MaterialModel::LinearElastic => "material_linear_elastic.inp",
        }
    }
}

/// Material constants of one layer, in MPa and tonne/mm^3 (converted to the deck's units).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayerMaterial {
    /// Neo-Hookean ground matrix, C10 = c/2 (MPa).
    pub c10: f64,
    /// Compressibility D = 2/K (1/MPa): Abaqus `D`, CalculiX `D1`.
    pub d: f64,
    /// Fibre stiffness k1 (MPa).
    pub k1: f64,
    /// Fibre exponent k2 (dimensionless).
    pub k2: f64,
    /// Dispersion kappa in [0, 1/3] (Abaqus only; CalculiX's ELASTIC_FIBER has none).
    pub kappa: f64,
    /// Linear-elastic template: Young's modulus (MPa).
    pub youngs_modulus: f64,
    /// Linear-elastic template: Poisson's ratio.
    pub poisson_ratio: f64,
    /// Density (tonne/mm^3).
    pub density: f64,
}

impl LayerMaterial {
    /// Media (and intima) defaults: the constants of Holzapfel, Gasser, Ogden 2000 (J Elasticity
    /// 61:1-48, rabbit carotid media: c = 3.0 kPa, k1 = 2.3632 kPa, k2 = 0.8393, also CalculiX's
    /// ELASTIC_FIBER example) with c and k1 multiplied by 10. The published values describe a
    /// thick carotid wall (thickness ~0.55 r) with residual stresses; on a stress-free wall of
    /// 0.2 r they cannot hold 100 mmHg (ccx 2.20 stops with "fiber extension is too large"),
    /// while the scaled set converges (ccx: the 2 mm tube with a 0.4 mm wall opens by 47 % of
    /// its radius at 100 mmHg: still a soft, rabbit-like wall; override for your tissue). The intima takes the
    /// media's values (as the fibre angles do in [`crate::config::WallConfig`]).
    /// D = 2/K with K = 100 mu (initial Poisson ratio 0.495); kappa = 0 (HGO 2000 has no
    /// dispersion). Density 1.2e-9 tonne/mm^3 (1200 kg/m^3). The linear-elastic constants
    /// (E = 1 MPa, nu = 0.45) are round illustrative values, not literature data.
    pub fn hgo2000_media() -> Self {
        let c10 = 1.5e-2;
        LayerMaterial {
            c10,
            d: 2.0 / (100.0 * 2.0 * c10),
            k1: 2.3632e-2,
            k2: 0.8393,
            kappa: 0.0,
            youngs_modulus: 1.0,
            poisson_ratio: 0.45,
            density: 1.2e-9,
        }
    }
    /// HGO 2000 adventitia (c = 0.3 kPa, k1 = 0.562 kPa, k2 = 0.7112), c and k1 times 10 as
    /// for the media.
    pub fn hgo2000_adventitia() -> Self {
        let c10 = 1.5e-3;
        LayerMaterial { c10, d: 2.0 / (100.0 * 2.0 * c10), k1: 5.62e-3, k2: 0.7112, ..Self::hgo2000_media() }
    }
    fn check(&self, layer: &str) -> Result<()> {
        let bad = |key: &str, why: &str| Err(Error::Config(format!("fe.{layer}.{key}: {why}")));
        let positive = [("c10", self.c10), ("k1", self.k1), ("k2", self.k2), ("youngs_modulus", self.youngs_modulus), ("density", self.density)];
        for (key, v) in positive {
            if !(v > 0.0 && v.is_finite()) {
                return bad(key, "must be positive");
            }
        }
        if !(self.d >= 0.0 && self.d.is_finite()) {
            return bad("d", "must be zero (incompressible, Abaqus hybrid elements only) or positive");
        }
        if !(0.0..=1.0 / 3.0).contains(&self.kappa) {
            return bad("kappa", "must be between 0 and 1/3");
        }
        if !(self.poisson_ratio > -1.0 && self.poisson_ratio < 0.5) {
            return bad("poisson_ratio", "must be between -1 and 0.5");
        }
        Ok(())
    }
}

/// Settings of the Abaqus and CalculiX decks (case file section `[fe]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FeConfig {
    /// Element type of the Abaqus deck: C3D8H (default, hybrid for near-incompressible
    /// tissue), C3D8, C3D8R, C3D8I, C3D20, C3D20H, C3D20R or C3D20RH.
    pub abaqus_element: ElementType,
    /// Element type of the CalculiX deck: C3D8I (default), C3D8, C3D8R, C3D20 or C3D20R.
    pub calculix_element: ElementType,
    /// Material template: `hgo` (default) or `linear_elastic`.
    pub material: MaterialModel,
    /// Folder whose `abaqus/` and `calculix/` files replace the built-in templates of the same
    /// name (`material_hgo.inp`, `material_linear_elastic.inp`, `step_inflation.inp`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub template_dir: Option<PathBuf>,
    /// Lumen pressure of the inflation step, mmHg.
    pub pressure_mmhg: f64,
    pub intima: LayerMaterial,
    pub media: LayerMaterial,
    pub adventitia: LayerMaterial,
}

impl Default for FeConfig {
    fn default() -> Self {
        FeConfig {
            abaqus_element: ElementType::C3D8H,
            calculix_element: ElementType::C3D8I,
            material: MaterialModel::Hgo,
            template_dir: None,
            pressure_mmhg: 100.0,
            intima: LayerMaterial::hgo2000_media(),
            media: LayerMaterial::hgo2000_media(),
            adventitia: LayerMaterial::hgo2000_adventitia(),
        }
    }
}

impl FeConfig {
    pub fn layer(&self, region: Region) -> &LayerMaterial {
        match region {
            Region::Intima => &self.intima,
            Region::Media => &self.media,
            _ => &self.adventitia,
        }
    }
}

/// A real number for a data line: 13 significant digits, at most 20 characters.
pub fn fmt_coord(x: f64) -> String {
    let x = if x == 0.0 { 0.0 } else { x }; // no "-0"
    format!("{x:.12e}")
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
    let mut s: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c.to_ascii_uppercase() } else { '_' })
        .collect();
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
        (Dialect::Abaqus, "material_linear_elastic.inp") => include_str!("../../templates/abaqus/material_linear_elastic.inp"),
        (Dialect::Abaqus, "step_inflation.inp") => include_str!("../../templates/abaqus/step_inflation.inp"),
        (Dialect::Calculix, "material_hgo.inp") => include_str!("../../templates/calculix/material_hgo.inp"),
        (Dialect::Calculix, "material_linear_elastic.inp") => include_str!("../../templates/calculix/material_linear_elastic.inp"),
        (Dialect::Calculix, "step_inflation.inp") => include_str!("../../templates/calculix/step_inflation.inp"),
        _ => return None,
    })
}

/// The text of a template and where it came from: the user's folder first, then the built-in.
fn template(fe: &FeConfig, dialect: Dialect, file: &str) -> Result<(String, String)> {
    if let Some(dir) = &fe.template_dir {
        let path = dir.join(dialect.folder()).join(file);
        if path.is_file() {
            let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, "cannot read the template", e))?;
            return Ok((text, path.display().to_string()));
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

/// Mid-edge nodes of the wall's quadratic elements.
struct MidEdges {
    /// Corner pair of each mid-edge node (index = mid-edge number).
    edges: Vec<[u32; 2]>,
    /// Mid-edge numbers of each wall element, in canonical edge order.
    of_element: Vec<[u32; 12]>,
}

impl MidEdges {
    fn new(mesh: &VesselMesh) -> Self {
        let wall = mesh.wall_range();
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
        MidEdges { edges, of_element }
    }
    /// 1-based label of mid-edge node `m`.
    fn label(&self, mesh: &VesselMesh, m: u32) -> u64 {
        mesh.nodes.len() as u64 + 1 + m as u64
    }
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
    /// Node set of an end ring and two points on its axis (deck units).
    ends: Vec<(String, Point3<f64>, Point3<f64>)>,
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

impl<'a> Deck<'a> {
    fn new(mesh: &'a VesselMesh, options: &WriteOptions, dialect: Dialect) -> Result<Self> {
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
            return Err(Error::Geometry("the mesh has no wall elements: nothing to write to an Abaqus/CalculiX deck".into()));
        }
        let units = MechanicalUnits::of(options.length_unit);
        let scale = options.length_unit.from_mm();
        let nodes = mesh.nodes_of(wall.clone());
        let mids = element.is_quadratic().then(|| MidEdges::new(mesh));

        // Node sets made of wall nodes only, plus the middle lumen ring.
        let mut is_wall_node = vec![false; mesh.nodes.len()];
        for &n in &nodes {
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
        let mut in_set = vec![false; mesh.nodes.len()];
        for (name, members) in raw_sets {
            let mut labels: Vec<u64> = members.iter().map(|&n| n as u64 + 1).collect();
            if let Some(m) = &mids {
                for &n in &members {
                    in_set[n as usize] = true;
                }
                for (i, e) in m.edges.iter().enumerate() {
                    if in_set[e[0] as usize] && in_set[e[1] as usize] {
                        labels.push(m.label(mesh, i as u32));
                    }
                }
                for &n in &members {
                    in_set[n as usize] = false;
                }
            }
            labels.sort_unstable();
            node_sets.push((sanitize_name(&name), labels));
        }
        let surfaces: Vec<(String, Vec<ElementFace>)> = mesh
            .face_sets
            .iter()
            .filter(|(_, v)| !v.is_empty() && v.iter().all(|f| wall.contains(&(f.element as usize))))
            .map(|(k, v)| (sanitize_name(k), v.clone()))
            .collect();
        let pressure_surface = sanitize_name(sets::WALL_LUMEN_FACES);
        if !surfaces.iter().any(|s| s.0 == pressure_surface) {
            return Err(Error::Geometry(format!("the mesh has no '{}' face set: no surface to load", sets::WALL_LUMEN_FACES)));
        }
        let mut ends = Vec::new();
        for end in &mesh.ends {
            let name = sanitize_name(&sets::wall_end(&end.name));
            if node_sets.iter().any(|s| s.0 == name) {
                let a = Point3::from(end.centre.coords * scale);
                let b = a + end.outward_normal * scale.max(1e-300);
                ends.push((name, a, b));
            }
        }
        if ends.is_empty() {
            return Err(Error::Geometry("the mesh has no end rings to hold: the inflation would be ill-posed".into()));
        }

        // Materials.
        let (mat_text, mat_source) = template(fe, dialect, fe.material.template())?;
        let mut layers = Vec::new();
        for region in Region::WALL {
            let range = mesh.region_range(region);
            if range.is_empty() {
                continue;
            }
            let layer_name = sanitize_name(region.name());
            let beta_deg = mesh.layers.iter().find(|l| l.region == region).map(|l| l.fibre_angle_deg).unwrap_or(0.0);
            let m = fe.layer(region);
            m.check(region.name())?;
            let material_name = match (dialect, fe.material) {
                (Dialect::Calculix, MaterialModel::Hgo) => format!("ELASTIC_FIBER_{layer_name}"),
                (Dialect::Abaqus, MaterialModel::Hgo) => format!("HGO_{layer_name}"),
                (_, MaterialModel::LinearElastic) => format!("LINEAR_{layer_name}"),
            };
            let (fx, fy) = fibre_local(beta_deg);
            let s = |mpa: f64| units.stress_from_mpa(mpa);
            let values = [
                ("LAYER", layer_name.clone()),
                ("MATERIAL", material_name.clone()),
                ("C10", fmt_const(s(m.c10))),
                ("D", fmt_const(1.0 / s(1.0 / m.d))),
                ("K1", fmt_const(s(m.k1))),
                ("K2", fmt_const(m.k2)),
                ("KAPPA", fmt_const(m.kappa)),
                ("FIBRE1_X", fmt_const(fx)),
                ("FIBRE1_Y", fmt_const(fy)),
                ("FIBRE2_X", fmt_const(fx)),
                ("FIBRE2_Y", fmt_const(-fy)),
                ("BETA_DEG", fmt_const(beta_deg)),
                ("E", fmt_const(s(m.youngs_modulus))),
                ("NU", fmt_const(m.poisson_ratio)),
                ("DENSITY", fmt_const(units.density_from_tonne_mm3(m.density))),
                ("UNITS", units.describe()),
            ];
            let material_text = render(&mat_text, &mat_source, &values)?;
            layers.push(LayerBlock { region, name: layer_name, range, beta_deg, material_name, material_text });
        }

        // Step.
        let (step_text, step_source) = template(fe, dialect, "step_inflation.inp")?;
        let step = render(
            &step_text,
            &step_source,
            &[
                ("PRESSURE", fmt_const(units.stress_from_mpa(fe.pressure_mmhg * MMHG_IN_MPA))),
                ("PRESSURE_MMHG", fmt_const(fe.pressure_mmhg)),
                ("PRESSURE_SURFACE", pressure_surface),
                ("PRINT_NSET", "LUMEN_RING".to_string()),
                ("UNITS", units.describe()),
            ],
        )?;
        Ok(Deck { mesh, dialect, element, scale, units, nodes, mids, node_sets, surfaces, ends, layers, step })
    }

    fn write(&self, w: &mut dyn Write) -> std::io::Result<()> {
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
        writeln!(w, "** Node label = vesselhex node index + 1; element label = element index + 1 (lumen not written).")?;
        writeln!(w, "** Local axes per element: 1 = circumferential, 2 = longitudinal (inlet to outlet), 3 = radial outward.")?;
        writeln!(w, "*NODE")?;
        for &n in &self.nodes {
            let p = mesh.nodes[n as usize].coords * self.scale;
            writeln!(w, "{}, {}, {}, {}", n as u64 + 1, fmt_coord(p.x), fmt_coord(p.y), fmt_coord(p.z))?;
        }
        if let Some(m) = &self.mids {
            for (i, e) in m.edges.iter().enumerate() {
                let p = (mesh.nodes[e[0] as usize].coords + mesh.nodes[e[1] as usize].coords) * (0.5 * self.scale);
                writeln!(w, "{}, {}, {}, {}", m.label(mesh, i as u32), fmt_coord(p.x), fmt_coord(p.y), fmt_coord(p.z))?;
            }
        }
        for layer in &self.layers {
            writeln!(w, "*ELEMENT, TYPE={}, ELSET={}", self.element.name(), layer.name)?;
            let mut entries: Vec<u64> = Vec::with_capacity(21);
            for e in layer.range.clone() {
                entries.clear();
                entries.push(e as u64 + 1);
                entries.extend(mesh.hexes[e].iter().map(|&n| n as u64 + 1));
                if let Some(m) = &self.mids {
                    entries.extend(m.of_element[e - wall.start].iter().map(|&k| m.label(mesh, k)));
                }
                write_data_lines(w, &entries)?;
            }
        }
        writeln!(w, "*ELSET, ELSET=WALL, GENERATE")?;
        writeln!(w, "{}, {}, 1", wall.start + 1, wall.end)?;
        for (name, labels) in &self.node_sets {
            writeln!(w, "*NSET, NSET={name}")?;
            write_data_lines(w, labels)?;
        }
        for (name, faces) in &self.surfaces {
            writeln!(w, "*SURFACE, NAME={name}, TYPE=ELEMENT")?;
            for f in faces {
                writeln!(w, "{}, {}", f.element as u64 + 1, abaqus_face_label(f.face as usize))?;
            }
        }
        writeln!(w, "** End rings: cylindrical systems about the end axes (1 radial, 2 circumferential, 3 axial);")?;
        writeln!(w, "** circumferential and axial motion fixed, radial expansion free.")?;
        for (name, a, b) in &self.ends {
            writeln!(w, "*TRANSFORM, NSET={name}, TYPE=C")?;
            writeln!(w, "{}, {}, {}, {}, {}, {}", fmt_coord(a.x), fmt_coord(a.y), fmt_coord(a.z), fmt_coord(b.x), fmt_coord(b.y), fmt_coord(b.z))?;
        }
        writeln!(w, "*BOUNDARY")?;
        for (name, _, _) in &self.ends {
            writeln!(w, "{name}, 2, 3")?;
        }
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
            for e in layer.range.clone() {
                let t = &mesh.triads[e];
                let (a, b) = (t.e_circ, t.e_long);
                writeln!(
                    w,
                    "{}, {}, {}, {}, {}, {}, {}",
                    e + 1,
                    fmt_coord(a.x),
                    fmt_coord(a.y),
                    fmt_coord(a.z),
                    fmt_coord(b.x),
                    fmt_coord(b.y),
                    fmt_coord(b.z)
                )?;
            }
            match self.dialect {
                Dialect::Abaqus => {
                    writeln!(w, "*ORIENTATION, NAME=ORI_{}, DEFINITION=COORDINATES, SYSTEM=RECTANGULAR, LOCAL DIRECTIONS=2", layer.name)?;
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
        for layer in &self.layers {
            writeln!(w, "** {} ({}): fibres at +-{} deg from circumferential", layer.name, layer.region.name(), fmt_const(layer.beta_deg))?;
            w.write_all(layer.material_text.as_bytes())?;
        }
        for layer in &self.layers {
            writeln!(w, "*SOLID SECTION, ELSET={}, MATERIAL={}, ORIENTATION=ORI_{}", layer.name, layer.material_name, layer.name)?;
            if self.dialect == Dialect::Abaqus {
                writeln!(w, ",")?;
            }
        }
        w.write_all(self.step.as_bytes())?;
        Ok(())
    }
}

/// Comma-separated entries, at most [`MAX_ENTRIES`] per line; a line that continues ends with a
/// comma.
fn write_data_lines(w: &mut dyn Write, entries: &[u64]) -> std::io::Result<()> {
    let chunks: Vec<&[u64]> = entries.chunks(MAX_ENTRIES).collect();
    let record_continues = |i: usize| i + 1 < chunks.len();
    for (i, chunk) in chunks.iter().enumerate() {
        let mut line = String::with_capacity(chunk.len() * 10);
        for (k, v) in chunk.iter().enumerate() {
            if k > 0 {
                line.push_str(", ");
            }
            line.push_str(&v.to_string());
        }
        if record_continues(i) {
            line.push(',');
        }
        writeln!(w, "{line}")?;
    }
    Ok(())
}

/// The deck as text in two parts: the model data (everything before the step) and the step
/// (the rendered `step_inflation.inp`, written last), so another step can follow the same model.
pub fn deck_parts(mesh: &VesselMesh, options: &WriteOptions, dialect: Dialect) -> Result<(String, String)> {
    let deck = Deck::new(mesh, options, dialect)?;
    let mut buf = Vec::new();
    deck.write(&mut buf).map_err(|e| Error::Config(format!("internal: cannot render the deck: {e}")))?;
    let text = String::from_utf8(buf).map_err(|e| Error::Config(format!("internal: deck is not UTF-8: {e}")))?;
    let model_len = text.len() - deck.step.len();
    Ok((text[..model_len].to_string(), deck.step.clone()))
}

/// Writes `<dialect>/model.inp` under `dir`.
pub fn write_inp(mesh: &VesselMesh, options: &WriteOptions, dialect: Dialect, dir: &Path) -> Result<Vec<PathBuf>> {
    let deck = Deck::new(mesh, options, dialect)?;
    let sub = PathBuf::from(dialect.folder());
    std::fs::create_dir_all(dir.join(&sub)).map_err(|e| Error::io(dir.join(&sub), "cannot create the folder", e))?;
    let name = sub.join("model.inp");
    write_atomic(&dir.join(&name), |w| deck.write(w))?;
    Ok(vec![name])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{quad_area_vector, HEX_FACES};
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
        assert!((crate::mesh::face_centre(&c, f) - centre).dot(&outward) > 0.0);
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
                    "LAYER", "MATERIAL", "C10", "D", "K1", "K2", "KAPPA", "FIBRE1_X", "FIBRE1_Y", "FIBRE2_X", "FIBRE2_Y",
                    "BETA_DEG", "E", "NU", "DENSITY", "UNITS", "PRESSURE", "PRESSURE_MMHG", "PRESSURE_SURFACE", "PRINT_NSET",
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
