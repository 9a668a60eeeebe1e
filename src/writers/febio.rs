//! FEBio 4.0 decks (`febio_spec version="4.0"`): the layered wall alone and a monolithic
//! fluid-structure model of lumen and wall.
//!
//! * `febio/wall.feb` (format `febio`, Module `solid`): the wall elements, one `<Elements>` block
//!   per layer (`intima`, `media`, `adventitia`), a Holzapfel-Gasser-Ogden material per layer, a
//!   per-element `mat_axis` (`a` = e_circ, `d` = e_long, so FEBio's fibres lie at +-gamma from the
//!   circumferential direction in the circumferential-longitudinal plane), the lumen pressure ramped
//!   to [`FebioConfig::lumen_pressure_mmhg`], end rings held axially and the in-plane rigid modes
//!   removed on symmetry lines of the end rings. `hex8` by default; `[febio] element = "hex20"`
//!   writes 20-node bricks (corners, then the mid-edge nodes in FEBio's order, which is C3D20's:
//!   edges 1-2, 2-3, 3-4, 4-1, 5-6, 6-7, 7-8, 8-5, 1-5, 2-6, 3-7, 4-8) with `quad8` facets, the
//!   mid-edge nodes and their labels shared with the CalculiX and Abaqus C3D20 decks
//!   ([`MidEdges`]); node sets then include the mid-edge nodes of their rings and surfaces.
//! * `febio/fsi.feb` (format `febio-fsi`, Module `fluid-FSI`): the lumen as a `fluid-FSI` domain
//!   (blood) and the three layers as solid domains sharing the interface nodes; `fluid-FSI
//!   traction` and no-slip on the interface, a parabolic inlet velocity, outlet pressure with
//!   backflow stabilization, a dynamic analysis whose loads ramp over [`FsiControl::ramp_s`].
//!   Always hex8 (hex20 is refused: FEBio's fluid-FSI needs lumen and wall to share every
//!   interface node, and FORMATS.md 2b documents it on hex8 only). One inlet surface carries the
//!   inflow; every outlet end gets its own pressure and backflow surface.
//!
//! Wall materials: the shared per-layer constants of `[material]`
//! ([`WallMaterial`](crate::data::config::material::WallMaterial), the same as the .inp decks'), the fibre angle
//! `gamma` from the mesh's layers.
//!
//! Both decks follow the reader rules of `FORMATS.md` 2b and the structure of the two decks FEBio
//! 4.11 ran to normal termination (`docs/examples/febio_*_tube.feb`). Labels are the mesh's:
//! node id = node index + 1, element id = element index + 1 (as in every other deck), so ids are
//! strictly increasing; `wall.feb` writes only the nodes its elements use (FEBio builds a
//! node-id lookup table, gaps are allowed). FEBio's log numbers the rows of its node data by a
//! node's position in `<Nodes>`, not by its id (FEBio 4.11 runs, `tests/febio_run.rs`): in
//! `wall.feb` the two differ, and the deck says so; `fsi.feb` writes every node in id order, so
//! there they agree. Facets are the mesh's face sets wound with
//! [`HEX_FACES`](crate::geometry::mesh::HEX_FACES), outward from the element they belong to: the wall's lumen
//! facets point into the lumen, so a positive pressure inflates the wall.
//!
//! Material blocks and the `<Control>` sections come from `templates/febio/*.xml` (compiled in),
//! whose `{{placeholders}}` are filled by [`fill_template`]; an unknown or unused placeholder is an
//! error. Constants are kept in the config in physiological units (kPa, kg/m^3, Pa s, mmHg, m/s)
//! and converted to the deck's consistent system, stated in a comment at the top of each deck:
//! length = the output unit, time s, force N, hence mm -> tonne and MPa, m -> kg and Pa.

use super::inp::MidEdges;
use super::text::{text_of, write_items, Text};
use super::{write_atomic, WriteOptions};
pub use crate::data::config::febio::{BloodConstants, FebioConfig, FebioElement, FsiControl};
use crate::data::config::material::WallMaterial;
use crate::data::error::{Error, Result};
use crate::data::units::MechanicalUnits;
use crate::geometry::mesh::{face_nodes, sets, ElementFace, Region, VesselEnd, VesselMesh};
use std::fmt::Write as _;
use std::io;
use std::path::{Path, PathBuf};

/// Path of the wall deck under the output folder.
pub const WALL_DECK: &str = "febio/wall.feb";
/// Path of the fluid-FSI deck under the output folder.
pub const FSI_DECK: &str = "febio/fsi.feb";

const TEMPLATE_HGO: (&str, &str) = ("hgo_material.xml", include_str!("../../templates/febio/hgo_material.xml"));
const TEMPLATE_BLOOD: (&str, &str) =
    ("fluid_fsi_material.xml", include_str!("../../templates/febio/fluid_fsi_material.xml"));
const TEMPLATE_CONTROL_STATIC: (&str, &str) =
    ("control_static.xml", include_str!("../../templates/febio/control_static.xml"));
const TEMPLATE_CONTROL_FSI: (&str, &str) = ("control_fsi.xml", include_str!("../../templates/febio/control_fsi.xml"));

/// One mmHg in Pa.
const MMHG_PA: f64 = 133.322387415;

// ------------------------------------------------------------------------------------------------
// Units
// ------------------------------------------------------------------------------------------------

/// The deck's unit system: the crate's one ([`MechanicalUnits`]), so FEBio and CalculiX decks
/// written in the same length unit agree.
pub type DeckUnits = MechanicalUnits;

// ------------------------------------------------------------------------------------------------
// Templates and XML text
// ------------------------------------------------------------------------------------------------

/// Fills the `{{name}}` placeholders of a built-in XML template with XML-escaped values; every
/// value must be used ([`super::template::render_all`]).
pub fn fill_template(label: &str, template: &str, values: &[(&str, String)]) -> Result<String> {
    let escaped: Vec<(&str, String)> =
        values.iter().map(|(k, v)| (*k, quick_xml::escape::escape(v.as_str()).into_owned())).collect();
    super::template::render_all(label, template, &escaped)
}

/// A number as FEBio reads it back exactly: the shortest representation that round-trips (17
/// significant digits at most), in exponent form only for very small or very large magnitudes.
pub fn num(x: f64) -> String {
    text_of(|t| {
        push_num(t, x);
    })
}

/// [`num`] appended to a text.
fn push_num(t: &mut Text, x: f64) -> &mut Text {
    if x == 0.0 {
        t.byte(b'0')
    } else if (1e-4..1e15).contains(&x.abs()) {
        t.display(x)
    } else {
        t.exp(x)
    }
}

/// A material constant, load or time: [`num`] of the value rounded to 12 significant digits, so
/// unit conversions print as 0.0023632 rather than 0.0023631999999999998 (coordinates and axes
/// keep every digit).
pub fn param(x: f64) -> String {
    match format!("{x:.11e}").parse::<f64>() {
        Ok(r) if x.is_finite() => num(r),
        _ => num(x),
    }
}

/// Indented XML text with escaped attributes and text, streamed to a writer: the text goes out
/// in pieces of [`XML_PIECE`] bytes, long lists through [`Xml::items`]. The first write error is
/// kept and returned by [`Xml::finish`].
struct Xml<'w> {
    out: String,
    depth: usize,
    sink: &'w mut dyn io::Write,
    error: Option<io::Error>,
}

/// Bytes of XML text gathered before they are written.
const XML_PIECE: usize = 1 << 16;

impl<'w> Xml<'w> {
    fn new(sink: &'w mut dyn io::Write) -> Self {
        Xml { out: String::with_capacity(2 * XML_PIECE), depth: 0, sink, error: None }
    }
    fn flush(&mut self) {
        if self.error.is_none() {
            self.error = self.sink.write_all(self.out.as_bytes()).err();
        }
        self.out.clear();
    }
    fn finish(mut self) -> io::Result<()> {
        self.flush();
        self.error.map_or(Ok(()), Err)
    }
    /// One line per item `0..n` at the current depth, formatted in blocks on every core.
    fn items(&mut self, n: usize, item: impl Fn(&mut Text, usize) + Sync) {
        self.flush();
        let indent = "  ".repeat(self.depth);
        if self.error.is_none() {
            self.error = write_items(self.sink, n, |t, i| {
                t.str(&indent);
                item(t, i);
                t.byte(b'\n');
            })
            .err();
        }
    }
    fn indent(&mut self) {
        if self.out.len() >= XML_PIECE {
            self.flush();
        }
        for _ in 0..self.depth {
            self.out.push_str("  ");
        }
    }
    fn tag_start(&mut self, tag: &str, attrs: &[(&str, &str)]) {
        self.indent();
        self.out.push('<');
        self.out.push_str(tag);
        for (k, v) in attrs {
            let _ = write!(self.out, " {k}=\"{}\"", quick_xml::escape::escape(*v));
        }
    }
    fn open(&mut self, tag: &str, attrs: &[(&str, &str)]) {
        self.tag_start(tag, attrs);
        self.out.push_str(">\n");
        self.depth += 1;
    }
    fn close(&mut self, tag: &str) {
        self.depth -= 1;
        self.indent();
        let _ = writeln!(self.out, "</{tag}>");
    }
    fn empty(&mut self, tag: &str, attrs: &[(&str, &str)]) {
        self.tag_start(tag, attrs);
        self.out.push_str("/>\n");
    }
    /// `<tag attrs>text</tag>`; `text` is escaped.
    fn leaf(&mut self, tag: &str, attrs: &[(&str, &str)], text: &str) {
        self.tag_start(tag, attrs);
        let _ = writeln!(self.out, ">{}</{tag}>", quick_xml::escape::escape(text));
    }
    /// `<tag attrs>a,b,c</tag>` (numbers need no escaping).
    fn leaf_list(&mut self, tag: &str, attrs: &[(&str, &str)], labels: &[u64]) {
        self.tag_start(tag, attrs);
        self.out.push('>');
        let mut t = Text::with_capacity(labels.len() * 8);
        t.uints(labels.iter().copied(), ",");
        self.out.push_str(std::str::from_utf8(&t.bytes).expect("ascii"));
        let _ = writeln!(self.out, "</{tag}>");
    }
    /// A comment; `--` is not allowed inside XML comments and is replaced.
    fn comment(&mut self, lines: &[String]) {
        self.indent();
        self.out.push_str("<!--\n");
        for l in lines {
            self.indent();
            let _ = writeln!(self.out, "  {}", l.replace("--", "- -"));
        }
        self.indent();
        self.out.push_str("-->\n");
    }
    /// A filled template, each line indented to the current depth.
    fn fragment(&mut self, text: &str) {
        for line in text.lines() {
            self.indent();
            self.out.push_str(line);
            self.out.push('\n');
        }
    }
}

/// `x,y,z` of a vector.
fn push_vector<'t>(t: &'t mut Text, v: &nalgebra::Vector3<f64>) -> &'t mut Text {
    push_num(t, v.x).byte(b',');
    push_num(t, v.y).byte(b',');
    push_num(t, v.z)
}

// ------------------------------------------------------------------------------------------------
// Deck pieces shared by both decks
// ------------------------------------------------------------------------------------------------

fn header(xml: &mut Xml, lines: &[String], module: &str) {
    xml.out.push_str("<?xml version=\"1.0\" encoding=\"ISO-8859-1\"?>\n");
    xml.comment(lines);
    xml.open("febio_spec", &[("version", "4.0")]);
    xml.empty("Module", &[("type", module)]);
}

fn control(xml: &mut Xml, template: (&str, &str), time_steps: usize, step_size: f64, dtmin: f64) -> Result<()> {
    let text = fill_template(
        template.0,
        template.1,
        &[("time_steps", time_steps.to_string()), ("step_size", param(step_size)), ("dtmin", param(dtmin))],
    )?;
    xml.fragment(&text);
    Ok(())
}

/// One `Holzapfel-Gasser-Ogden` material per wall layer, ids from `first_id`, named as the layer,
/// with the shared wall constants and the layer's fibre angle as `gamma`.
fn wall_materials(
    xml: &mut Xml,
    mesh: &VesselMesh,
    material: &WallMaterial,
    u: DeckUnits,
    first_id: usize,
) -> Result<()> {
    for (i, region) in Region::WALL.into_iter().enumerate() {
        let layer = mesh.layers.iter().find(|l| l.region == region).ok_or_else(|| {
            Error::Geometry(format!("FEBio: the mesh has no {} layer (its fibre angle is needed)", region.name()))
        })?;
        let m = material.layer(region);
        m.check(region.name())?;
        let text = fill_template(
            TEMPLATE_HGO.0,
            TEMPLATE_HGO.1,
            &[
                ("id", (first_id + i).to_string()),
                ("name", region.name().to_string()),
                ("density", param(m.density(&u))),
                ("c", param(m.c(&u))),
                ("k1", param(m.k1(&u))),
                ("k2", param(m.k2)),
                ("kappa", param(m.kappa)),
                ("gamma", param(layer.fibre_angle_deg)),
                ("k", param(m.bulk(&u))),
            ],
        )?;
        xml.fragment(&text);
    }
    Ok(())
}

/// `<Nodes>` with the given (sorted) node indices, labelled index + 1, then the mid-edge nodes
/// of a hex20 deck (labelled after every mesh node, so ids keep increasing).
fn nodes(xml: &mut Xml, mesh: &VesselMesh, name: &str, which: &[u32], mids: Option<&MidEdges>, u: DeckUnits) {
    let s = u.length.from_mm();
    xml.open("Nodes", &[("name", name)]);
    let node = |t: &mut Text, label: u64, p: nalgebra::Point3<f64>| {
        t.str("<node id=\"").uint(label).str("\">");
        push_num(t, p.x * s).byte(b',');
        push_num(t, p.y * s).byte(b',');
        push_num(t, p.z * s).str("</node>");
    };
    xml.items(which.len(), |t, i| node(t, which[i] as u64 + 1, mesh.nodes[which[i] as usize]));
    if let Some(m) = mids {
        xml.items(m.len(), |t, k| node(t, m.label(mesh, k as u32), m.position(mesh, k as u32)));
    }
    xml.close("Nodes");
}

/// `<Elements>` of one region, named as the region, labelled index + 1: `hex8`, or `hex20` with
/// the twelve mid-edge nodes after the corners.
fn elements(xml: &mut Xml, mesh: &VesselMesh, region: Region, mids: Option<&MidEdges>) {
    let kind = if mids.is_some() { FebioElement::Hex20 } else { FebioElement::Hex8 };
    xml.open("Elements", &[("type", kind.name()), ("name", region.name())]);
    let range = mesh.region_range(region);
    xml.items(range.len(), |t, i| {
        let e = range.start + i;
        t.str("<elem id=\"").uint(e as u64 + 1).str("\">");
        t.uints(mesh.hexes[e].iter().map(|&n| n as u64 + 1), ",");
        if let Some(m) = mids {
            t.byte(b',').uints(m.of_element(e).iter().map(|&k| m.label(mesh, k)), ",");
        }
        t.str("</elem>");
    });
    xml.close("Elements");
}

/// Labels of mesh nodes (0-based, sorted) with their quadratic completion in a hex20 deck (the
/// mid-edge nodes whose two corners are members: the ring or surface the set describes).
fn set_labels(mesh: &VesselMesh, mids: Option<&MidEdges>, members: &[u32]) -> Vec<u64> {
    let mut labels: Vec<u64> = members.iter().map(|&n| n as u64 + 1).collect();
    if let Some(m) = mids {
        labels.extend(m.completing(mesh, members).into_iter().map(|k| m.label(mesh, k)));
    }
    labels
}

/// A `<NodeSet>` of mesh nodes (0-based, sorted), completed in a hex20 deck ([`set_labels`]).
fn node_set(xml: &mut Xml, mesh: &VesselMesh, mids: Option<&MidEdges>, name: &str, members: &[u32]) {
    node_set_labels(xml, name, &set_labels(mesh, mids, members));
}

fn node_set_labels(xml: &mut Xml, name: &str, labels: &[u64]) {
    xml.leaf_list("NodeSet", &[("name", name)], labels);
}

/// `<Surface>` of facets, each wound outward from its element: `quad4`, or `quad8` (corners, then
/// the mid-edge nodes of the edges 1-2, 2-3, 3-4, 4-1, as FEBio's hex20 faces list them).
fn surface(xml: &mut Xml, mesh: &VesselMesh, name: &str, faces: &[ElementFace], mids: Option<&MidEdges>) {
    let kind = if mids.is_some() { FebioElement::Hex20 } else { FebioElement::Hex8 };
    xml.open("Surface", &[("name", name)]);
    let tag = kind.facet();
    xml.items(faces.len(), |t, i| {
        let f = faces[i];
        let corners = face_nodes(&mesh.hexes[f.element as usize], f.face as usize).map(|n| n as u64 + 1);
        t.byte(b'<').str(tag).str(" id=\"").uint(i as u64 + 1).str("\">").uints(corners, ",");
        if let Some(m) = mids {
            t.byte(b',').uints(m.of_face(f.element as usize, f.face as usize).map(|k| m.label(mesh, k)), ",");
        }
        t.str("</").str(tag).byte(b'>');
    });
    xml.close("Surface");
}

fn mesh_domains(xml: &mut Xml, domains: &[(&str, &str)]) {
    xml.open("MeshDomains", &[]);
    for (name, mat) in domains {
        xml.empty("SolidDomain", &[("name", name), ("mat", mat)]);
    }
    xml.close("MeshDomains");
}

/// `<MeshData>` with one `mat_axis` map per wall layer: `a` = e_circ, `d` = e_long of every
/// element, `lid` = 1-based position in the layer's element set.
fn mat_axes(xml: &mut Xml, mesh: &VesselMesh) {
    xml.open("MeshData", &[]);
    for region in Region::WALL {
        xml.open("ElementData", &[("type", "mat_axis"), ("elem_set", region.name())]);
        let range = mesh.region_range(region);
        xml.items(range.len(), |t, lid| {
            let triad = &mesh.triads[range.start + lid];
            t.str("<elem lid=\"").uint(lid as u64 + 1).str("\"><a>");
            push_vector(t, &triad.e_circ).str("</a><d>");
            push_vector(t, &triad.e_long).str("</d></elem>");
        });
        xml.close("ElementData");
    }
    xml.close("MeshData");
}

/// `zero displacement` on the dofs marked in `dofs` (x, y, z) of a node set.
fn zero_displacement(xml: &mut Xml, name: &str, set: &str, dofs: [bool; 3]) {
    xml.open("bc", &[("name", name), ("node_set", set), ("type", "zero displacement")]);
    for (tag, on) in ["x_dof", "y_dof", "z_dof"].iter().zip(dofs) {
        xml.leaf(tag, &[], if on { "1" } else { "0" });
    }
    xml.close("bc");
}

fn load_curve(xml: &mut Xml, id: usize, name: &str, interpolate: &str, points: &[(f64, f64)]) {
    xml.open("load_controller", &[("id", &id.to_string()), ("name", name), ("type", "loadcurve")]);
    xml.leaf("interpolate", &[], interpolate);
    xml.leaf("extend", &[], "CONSTANT");
    xml.open("points", &[]);
    for (t, v) in points {
        xml.leaf("pt", &[], &format!("{},{}", param(*t), param(*v)));
    }
    xml.close("points");
    xml.close("load_controller");
}

fn output(xml: &mut Xml, log_node_set: &str, vars: &[&str]) {
    xml.open("Output", &[]);
    xml.open("logfile", &[]);
    xml.empty("node_data", &[("data", "ux;uy;uz"), ("delim", ","), ("node_set", log_node_set)]);
    xml.close("logfile");
    xml.open("plotfile", &[("type", "febio")]);
    for v in vars {
        xml.empty("var", &[("type", v)]);
    }
    xml.close("plotfile");
    xml.close("Output");
}

fn node_set_of<'a>(mesh: &'a VesselMesh, name: &str) -> Result<&'a [u32]> {
    mesh.node_sets
        .get(name)
        .map(|v| v.as_slice())
        .ok_or_else(|| Error::Geometry(format!("FEBio: the mesh has no node set '{name}'")))
}

fn face_set_of<'a>(mesh: &'a VesselMesh, name: &str) -> Result<&'a [ElementFace]> {
    mesh.face_sets
        .get(name)
        .map(|v| v.as_slice())
        .ok_or_else(|| Error::Geometry(format!("FEBio: the mesh has no face set '{name}'")))
}

fn check_triads(mesh: &VesselMesh) -> Result<()> {
    if mesh.triads.len() != mesh.hexes.len() {
        return Err(Error::Geometry("FEBio: the mesh is not annotated (no per-element triads)".into()));
    }
    Ok(())
}

// ------------------------------------------------------------------------------------------------
// End supports of the wall deck
// ------------------------------------------------------------------------------------------------

/// How the wall deck holds one end ring.
#[derive(Debug, Clone, PartialEq)]
pub struct EndSupport {
    /// End name (`inlet`, `outlet`, ...); its ring is node set `wall_<end>`.
    pub end: String,
    /// Dofs (x, y, z) held on the whole ring: the axial one when the end's normal is a global
    /// axis, all three otherwise.
    pub ring_dofs: [bool; 3],
    /// For an axially held ring: the ring nodes on the two planes through the end's centre that
    /// contain the axis, by the dof they hold (nodes on the plane x = x_c hold u_x, ...). Together
    /// they remove the in-plane translations and the rotation about the axis without opposing a
    /// symmetric inflation (as the verified example does on its symmetry lines).
    pub plane_nodes: [Vec<u32>; 3],
}

/// The supports of every end. A ring is held axially only when its end normal is a global axis
/// and its ring has nodes on both symmetry planes, on both sides of the centre; otherwise it is
/// clamped (x, y and z), which also removes the rigid modes.
pub fn end_supports(mesh: &VesselMesh) -> Result<Vec<EndSupport>> {
    let mut out = Vec::new();
    for end in &mesh.ends {
        let ring = node_set_of(mesh, &sets::wall_end(&end.name))?;
        let n = end.outward_normal;
        let axis = (0..3).max_by(|a, b| n[*a].abs().total_cmp(&n[*b].abs())).unwrap_or(2);
        let mut support = EndSupport { end: end.name.clone(), ring_dofs: [true; 3], plane_nodes: Default::default() };
        if n[axis].abs() >= 1.0 - 1e-9 {
            let size = ring.iter().map(|&i| (mesh.nodes[i as usize] - end.centre).norm()).fold(0.0, f64::max);
            let tol = 1e-6 * size;
            let mut planes: [Vec<u32>; 3] = Default::default();
            let mut complete = true;
            for k in (0..3).filter(|k| *k != axis) {
                let on_plane: Vec<u32> = ring
                    .iter()
                    .copied()
                    .filter(|&i| (mesh.nodes[i as usize][k] - end.centre[k]).abs() <= tol)
                    .collect();
                // the other transverse coordinate must take both signs (a line through the axis)
                let j = 3 - axis - k;
                let side =
                    |sign: f64| on_plane.iter().any(|&i| sign * (mesh.nodes[i as usize][j] - end.centre[j]) > tol);
                complete &= side(1.0) && side(-1.0);
                planes[k] = on_plane;
            }
            if complete {
                support.ring_dofs = [false; 3];
                support.ring_dofs[axis] = true;
                support.plane_nodes = planes;
            }
        }
        out.push(support);
    }
    Ok(out)
}

// ------------------------------------------------------------------------------------------------
// The decks
// ------------------------------------------------------------------------------------------------

const DOF_NAMES: [&str; 3] = ["x", "y", "z"];

/// The text of `wall.feb`.
pub fn wall_deck(mesh: &VesselMesh, options: &WriteOptions) -> Result<String> {
    deck_text(|xml| write_wall_deck(xml, mesh, options))
}

/// The text of `fsi.feb`.
pub fn fsi_deck(mesh: &VesselMesh, options: &WriteOptions) -> Result<String> {
    deck_text(|xml| write_fsi_deck(xml, mesh, options))
}

/// A deck written into memory (for tests and tools; the writers stream to the file).
fn deck_text(deck: impl FnOnce(&mut Xml) -> Result<()>) -> Result<String> {
    let mut bytes = Vec::new();
    let mut xml = Xml::new(&mut bytes);
    deck(&mut xml)?;
    xml.finish().map_err(|e| Error::Config(format!("internal: cannot render the deck: {e}")))?;
    String::from_utf8(bytes).map_err(|e| Error::Config(format!("internal: the deck is not UTF-8: {e}")))
}

/// `wall.feb` into `xml`.
fn write_wall_deck(xml: &mut Xml, mesh: &VesselMesh, options: &WriteOptions) -> Result<()> {
    let cfg = &options.febio;
    cfg.validate()?;
    check_triads(mesh)?;
    let u = MechanicalUnits::of(options.length_unit);
    let supports = end_supports(mesh)?;
    let pressure = u.stress(cfg.lumen_pressure_mmhg * MMHG_PA);

    let mut comment = vec![
        format!(
            "vesselhex {}: FEBio 4.0 deck of the artery wall (intima, media, adventitia).",
            env!("CARGO_PKG_VERSION")
        ),
        format!("Units: {}.", u.describe()),
        "Holzapfel-Gasser-Ogden per layer; per-element mat_axis a = e_circ, d = e_long (element centroid frame),"
            .into(),
        "so the two fibre families lie at +-gamma from the circumferential direction.".into(),
        format!(
            "Static lumen pressure on surface {} ramped linearly to {} ({} mmHg) over {} steps.",
            sets::WALL_LUMEN_FACES,
            param(pressure),
            param(cfg.lumen_pressure_mmhg),
            cfg.static_steps
        ),
        "Node id = vesselhex node index + 1, element id = element index + 1 (the same labels in every deck);".into(),
        "only the nodes of wall elements are written. FEBio's log numbers the rows of node data by the".into(),
        "node's position in <Nodes> (1, 2, ...), not by these ids: logged node k is the k-th <node> below.".into(),
    ];
    for s in &supports {
        let held: Vec<&str> = (0..3).filter(|k| s.ring_dofs[*k]).map(|k| DOF_NAMES[k]).collect();
        if held.len() == 1 {
            comment.push(format!(
                "End {}: ring held axially (u_{} = 0); ring nodes on its symmetry lines hold the transverse dof.",
                s.end, held[0]
            ));
        } else {
            comment
                .push(format!("End {}: ring clamped (its normal is not a global axis or no symmetry lines).", s.end));
        }
    }
    let wall_nodes = mesh.nodes_of(mesh.wall_range());
    let mids = (cfg.element == FebioElement::Hex20).then(|| MidEdges::new(mesh));
    let mids = mids.as_ref();
    if let Some(m) = mids {
        comment.push(format!(
            "hex20: {} mid-edge nodes at the edge midpoints, labelled from {} (as in the C3D20 decks); quad8 facets.",
            m.len(),
            m.label(mesh, 0)
        ));
    }
    // Completed end by end: an axial edge from one end's plane to another's is not on either.
    let mut rigid: [Vec<u64>; 3] = Default::default();
    for s in &supports {
        for (r, p) in rigid.iter_mut().zip(&s.plane_nodes) {
            r.extend(set_labels(mesh, mids, p));
        }
    }
    for r in &mut rigid {
        r.sort_unstable();
        r.dedup();
    }

    header(xml, &comment, "solid");
    let steps = cfg.static_steps;
    control(xml, TEMPLATE_CONTROL_STATIC, steps, 1.0 / steps as f64, 1e-3 / steps as f64)?;
    xml.open("Material", &[]);
    wall_materials(xml, mesh, &options.material, u, 1)?;
    xml.close("Material");

    xml.open("Mesh", &[]);
    nodes(xml, mesh, "wall_nodes", &wall_nodes, mids, u);
    for region in Region::WALL {
        elements(xml, mesh, region, mids);
    }
    for s in &supports {
        let name = sets::wall_end(&s.end);
        node_set(xml, mesh, mids, &name, node_set_of(mesh, &name)?);
    }
    for (r, dof) in rigid.iter().zip(DOF_NAMES) {
        if !r.is_empty() {
            node_set_labels(xml, &format!("rigid_{dof}"), r);
        }
    }
    node_set(xml, mesh, mids, sets::INTERFACE_NODES, node_set_of(mesh, sets::INTERFACE_NODES)?);
    for name in [sets::WALL_LUMEN_FACES, sets::WALL_OUTER_FACES] {
        surface(xml, mesh, name, face_set_of(mesh, name)?, mids);
    }
    xml.close("Mesh");

    let domains: Vec<(&str, &str)> = Region::WALL.iter().map(|r| (r.name(), r.name())).collect();
    mesh_domains(xml, &domains);
    mat_axes(xml, mesh);

    xml.open("Boundary", &[]);
    for s in &supports {
        zero_displacement(xml, &format!("hold_{}", s.end), &sets::wall_end(&s.end), s.ring_dofs);
    }
    for (k, (r, dof)) in rigid.iter().zip(DOF_NAMES).enumerate() {
        if !r.is_empty() {
            let mut dofs = [false; 3];
            dofs[k] = true;
            zero_displacement(xml, &format!("no_rigid_{dof}"), &format!("rigid_{dof}"), dofs);
        }
    }
    xml.close("Boundary");

    xml.open("Loads", &[]);
    xml.open("surface_load", &[("name", "lumen_pressure"), ("surface", sets::WALL_LUMEN_FACES), ("type", "pressure")]);
    xml.leaf("pressure", &[("lc", "1")], &param(pressure));
    xml.leaf("symmetric_stiffness", &[], "1");
    xml.leaf("linear", &[], "0");
    xml.close("surface_load");
    xml.close("Loads");

    xml.open("LoadData", &[]);
    load_curve(xml, 1, "pressure_ramp", "LINEAR", &[(0.0, 0.0), (1.0, 1.0)]);
    xml.close("LoadData");

    output(xml, sets::INTERFACE_NODES, &["displacement", "stress"]);
    xml.close("febio_spec");
    Ok(())
}

/// `fsi.feb` into `xml`.
fn write_fsi_deck(xml: &mut Xml, mesh: &VesselMesh, options: &WriteOptions) -> Result<()> {
    let cfg = &options.febio;
    cfg.validate()?;
    if cfg.element == FebioElement::Hex20 {
        // FORMATS.md 2b: fluid and solid must share every interface node, and FEBio's fluid-FSI
        // has only been run (and documented) on hex8; a hex20 wall on a hex8 lumen would leave its
        // mid-edge interface nodes hanging.
        return Err(Error::Config(
            "febio.element = \"hex20\": the fluid-FSI deck (format febio-fsi) is written with hex8 only, since the \
             lumen and the wall must share every interface node; write febio-fsi with element = \"hex8\" (a separate \
             run) or leave it out"
                .into(),
        ));
    }
    check_triads(mesh)?;
    let u = MechanicalUnits::of(options.length_unit);
    let f = &cfg.fsi;
    let b = &cfg.blood;
    let inlets: Vec<_> = mesh.ends.iter().filter(|e| e.is_inlet).collect();
    if inlets.is_empty() {
        return Err(Error::Geometry("FEBio FSI: the mesh has no inlet".into()));
    }
    let outlets: Vec<_> = mesh.outlets().collect();
    if outlets.is_empty() {
        return Err(Error::Geometry("FEBio FSI: the mesh has no outlet".into()));
    }
    let velocity = u.velocity(f.inlet_mean_velocity_m_s);
    let p_out = u.stress(f.outlet_pressure_mmhg * MMHG_PA);
    let interface = node_set_of(mesh, sets::INTERFACE_NODES)?;

    let comment = fsi_deck_comment(u, f, b);
    header(xml, &comment, "fluid-FSI");
    control(xml, TEMPLATE_CONTROL_FSI, f.time_steps, f.step_size_s, f.step_size_s * 1e-2)?;
    xml.open("Material", &[]);
    let blood = fill_template(
        TEMPLATE_BLOOD.0,
        TEMPLATE_BLOOD.1,
        &[
            ("id", "1".into()),
            ("name", "blood".into()),
            ("mesh_motion_modulus", param(u.stress(1e-3))),
            ("density", param(u.density(b.density_kg_m3))),
            ("bulk_modulus", param(u.stress(b.bulk_modulus_pa))),
            ("viscosity", param(u.viscosity(b.viscosity_pa_s))),
        ],
    )?;
    xml.fragment(&blood);
    wall_materials(xml, mesh, &options.material, u, 2)?;
    xml.close("Material");

    let (extended, lumen_inner_sets) = fsi_mesh(xml, mesh, u, interface)?;
    let mut domains: Vec<(&str, &str)> = vec![(Region::Lumen.name(), "blood")];
    domains.extend(Region::WALL.iter().map(|r| (r.name(), r.name())));
    if extended {
        domains.push((Region::Extension.name(), "blood"));
    }
    mesh_domains(xml, &domains);
    mat_axes(xml, mesh);

    fsi_boundary(xml, mesh, &outlets, &lumen_inner_sets, extended, p_out);
    fsi_loads(xml, &inlets, &outlets, velocity, f.backflow_beta);
    xml.open("LoadData", &[]);
    load_curve(xml, 1, "inflow_ramp", "LINEAR", &[(0.0, 0.0), (f.ramp_s, 1.0)]);
    load_curve(xml, 2, "outlet_pressure_ramp", "LINEAR", &[(0.0, 0.0), (f.ramp_s, 1.0)]);
    load_curve(xml, 3, "backflow_on", "STEP", &[(0.0, 1.0), (f.ramp_s, 1.0)]);
    xml.close("LoadData");

    output(
        xml,
        sets::INTERFACE_NODES,
        &[
            "displacement",
            "stress",
            "velocity",
            "fluid pressure",
            "fluid velocity",
            "fluid dilatation",
            "fluid stress",
            "nodal fluid velocity",
            "relative fluid velocity",
        ],
    );
    xml.close("febio_spec");
    Ok(())
}

/// The comment at the head of `fsi.feb`: what the deck models, in which units.
fn fsi_deck_comment(u: MechanicalUnits, f: &FsiControl, b: &BloodConstants) -> Vec<String> {
    vec![
        format!(
            "vesselhex {}: FEBio 4.0 monolithic fluid-structure deck (Module fluid-FSI).",
            env!("CARGO_PKG_VERSION")
        ),
        format!("Units: {}.", u.describe()),
        format!(
            "Lumen: one fluid-FSI domain (blood: density {} kg/m^3, bulk modulus {} Pa, Newtonian viscosity {} Pa s;",
            param(b.density_kg_m3),
            param(b.bulk_modulus_pa),
            param(b.viscosity_pa_s)
        ),
        "a negligible neo-Hookean solid moves the mesh). Wall: intima, media, adventitia as solid domains".into(),
        "(Holzapfel-Gasser-Ogden, per-element mat_axis a = e_circ, d = e_long) sharing the interface nodes.".into(),
        format!(
            "fluid-FSI traction on surface {} and no-slip (zero fluid velocity) on node set {}.",
            sets::LUMEN_WALL_FACES,
            sets::INTERFACE_NODES
        ),
        format!(
            "Inlet: parabolic fluid normal velocity, mean {} m/s; outlets: fluid pressure {} mmHg with backflow",
            param(f.inlet_mean_velocity_m_s),
            param(f.outlet_pressure_mmhg)
        ),
        format!(
            "stabilization (beta {}). Loads ramp linearly over {} s; dynamic run of {} steps of {} s.",
            param(f.backflow_beta),
            param(f.ramp_s),
            f.time_steps,
            param(f.step_size_s)
        ),
        "Wall end rings and lumen end faces are fixed in x, y and z (mesh motion).".into(),
        "The fluid-FSI system is non-symmetric: run with a non-symmetric linear solver (pardiso, the default".into(),
        "of MKL builds); skyline cannot factor it.".into(),
        "Node id = vesselhex node index + 1, element id = element index + 1 (the same labels in every deck).".into(),
    ]
}

/// The deck's `Mesh`: nodes, elements (flow extensions as rigid-walled fluid), the wall's and
/// the lumen's end sets (the lumen's without its interface nodes), the interface and the end
/// surfaces. Returns whether the mesh has flow extensions, and each end's lumen set.
fn fsi_mesh(
    xml: &mut Xml,
    mesh: &VesselMesh,
    u: MechanicalUnits,
    interface: &[u32],
) -> Result<(bool, Vec<(String, String)>)> {
    let on_interface = {
        let mut v = vec![false; mesh.nodes.len()];
        for &n in interface {
            v[n as usize] = true;
        }
        v
    };
    xml.open("Mesh", &[]);
    let all: Vec<u32> = (0..mesh.nodes.len() as u32).collect();
    nodes(xml, mesh, "all_nodes", &all, None, u);
    // Flow extensions (when the deck is given them, `extensions.fe_decks`): rigid-walled fluid.
    let extended = !mesh.extension_range().is_empty();
    for region in Region::ALL.into_iter().chain(extended.then_some(Region::Extension)) {
        elements(xml, mesh, region, None);
    }
    let extension_wall: &[u32] = if extended { node_set_of(mesh, sets::EXTENSION_WALL)? } else { &[] };
    if extended {
        node_set(xml, mesh, None, sets::EXTENSION_WALL, extension_wall);
    }
    let mut lumen_inner_sets = Vec::new();
    for end in &mesh.ends {
        let wall = sets::wall_end(&end.name);
        node_set(xml, mesh, None, &wall, node_set_of(mesh, &wall)?);
        let inner: Vec<u32> = node_set_of(mesh, &sets::lumen_end(&end.name))?
            .iter()
            .copied()
            .filter(|&n| !on_interface[n as usize])
            .collect();
        let name = format!("{}_inner", sets::lumen_end(&end.name));
        node_set(xml, mesh, None, &name, &inner);
        lumen_inner_sets.push((end.name.clone(), name));
    }
    node_set(xml, mesh, None, sets::INTERFACE_NODES, interface);
    surface(xml, mesh, sets::LUMEN_WALL_FACES, face_set_of(mesh, sets::LUMEN_WALL_FACES)?, None);
    for end in &mesh.ends {
        let name = sets::lumen_end(&end.name);
        surface(xml, mesh, &name, face_set_of(mesh, &name)?, None);
    }
    xml.close("Mesh");

    Ok((extended, lumen_inner_sets))
}

/// The deck's `Boundary`: ends fixed (mesh motion), no slip on the interface (and on the
/// extensions' walls), the outlets' fluid pressure.
fn fsi_boundary(
    xml: &mut Xml,
    mesh: &VesselMesh,
    outlets: &[&VesselEnd],
    lumen_inner_sets: &[(String, String)],
    extended: bool,
    p_out: f64,
) {
    xml.open("Boundary", &[]);
    for end in &mesh.ends {
        zero_displacement(xml, &format!("fix_wall_{}", end.name), &sets::wall_end(&end.name), [true; 3]);
    }
    for (end, set) in lumen_inner_sets {
        zero_displacement(xml, &format!("fix_lumen_{end}"), set, [true; 3]);
    }
    let mut no_slip = vec![("no_slip", sets::INTERFACE_NODES)];
    if extended {
        zero_displacement(xml, "fix_extension_wall", sets::EXTENSION_WALL, [true; 3]);
        no_slip.push(("no_slip_extension", sets::EXTENSION_WALL));
    }
    for (name, set) in no_slip {
        xml.open("bc", &[("name", name), ("node_set", set), ("type", "zero fluid velocity")]);
        for tag in ["wx_dof", "wy_dof", "wz_dof"] {
            xml.leaf(tag, &[], "1");
        }
        xml.close("bc");
    }
    for end in outlets {
        let surf = sets::lumen_end(&end.name);
        xml.open("bc", &[("name", &format!("pressure_{}", end.name)), ("surface", &surf), ("type", "fluid pressure")]);
        xml.leaf("pressure", &[("lc", "2")], &param(p_out));
        xml.close("bc");
    }
    xml.close("Boundary");
}

/// The deck's `Loads`: the fluid-FSI traction on the interface, the inlet's parabolic
/// velocity and the outlets' backflow stabilization.
fn fsi_loads(xml: &mut Xml, inlets: &[&VesselEnd], outlets: &[&VesselEnd], velocity: f64, backflow_beta: f64) {
    xml.open("Loads", &[]);
    xml.open(
        "surface_load",
        &[("name", "fsi_traction"), ("surface", sets::LUMEN_WALL_FACES), ("type", "fluid-FSI traction")],
    );
    xml.leaf("shell_bottom", &[], "0");
    xml.close("surface_load");
    for inlet in inlets {
        let inlet_surface = sets::lumen_end(&inlet.name);
        xml.open(
            "surface_load",
            &[
                ("name", &format!("velocity_{}", inlet.name)),
                ("surface", &inlet_surface),
                ("type", "fluid normal velocity"),
            ],
        );
        // measured along the facets' outward normal: inflow is negative
        xml.leaf("velocity", &[("lc", "1")], &param(-velocity));
        xml.leaf("prescribe_nodal_velocities", &[], "1");
        xml.leaf("parabolic", &[], "1");
        xml.leaf("prescribe_rim_pressure", &[], "1");
        xml.close("surface_load");
    }
    for end in outlets {
        let surf = sets::lumen_end(&end.name);
        xml.open(
            "surface_load",
            &[
                ("name", &format!("backflow_{}", end.name)),
                ("surface", &surf),
                ("type", "fluid backflow stabilization"),
            ],
        );
        xml.leaf("beta", &[("lc", "3")], &param(backflow_beta));
        xml.close("surface_load");
    }
    xml.close("Loads");
}

/// Streams a deck into `dir/rel`. A deck that fails midway (a template, a missing set) leaves
/// no file: its error is kept and returned, the partial file removed.
fn write_deck(dir: &Path, rel: &str, deck: impl FnOnce(&mut Xml) -> Result<()>) -> Result<Vec<PathBuf>> {
    let rel = PathBuf::from(rel);
    let path = dir.join(&rel);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, "cannot create the folder", e))?;
    }
    let mut failure = None;
    let written = write_atomic(&path, |w| {
        let mut xml = Xml::new(w);
        if let Err(e) = deck(&mut xml) {
            let message = e.to_string();
            failure = Some(e);
            return Err(io::Error::other(message));
        }
        xml.finish()
    });
    match failure {
        Some(e) => Err(e),
        None => written.map(|()| vec![rel]),
    }
}

/// Writer of format `febio`: `febio/wall.feb`.
pub fn write_wall(mesh: &VesselMesh, options: &WriteOptions, dir: &Path) -> Result<Vec<PathBuf>> {
    write_deck(dir, WALL_DECK, |xml| write_wall_deck(xml, mesh, options))
}

/// Writer of format `febio-fsi`: `febio/fsi.feb`.
pub fn write_fsi(mesh: &VesselMesh, options: &WriteOptions, dir: &Path) -> Result<Vec<PathBuf>> {
    write_deck(dir, FSI_DECK, |xml| write_fsi_deck(xml, mesh, options))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::units::LengthUnit;

    #[test]
    fn templates_fill_strictly() {
        let v = |k: &'static str| (k, "1".to_string());
        assert_eq!(fill_template("t", "<a>{{x}}</a>{{ y }}", &[v("x"), v("y")]).unwrap(), "<a>1</a>1");
        let e = fill_template("t", "<a>{{x}}{{z}}</a>", &[v("x")]).unwrap_err().to_string();
        assert!(e.contains("unknown placeholder") && e.contains("z"), "{e}");
        let e = fill_template("t", "<a>{{x}}</a>", &[v("x"), v("y")]).unwrap_err().to_string();
        assert!(e.contains("no placeholder") && e.contains("y"), "{e}");
        assert!(fill_template("t", "<a>{{x</a>", &[v("x")]).is_err());
        assert_eq!(fill_template("t", "{{x}}", &[("x", "a<b&c".into())]).unwrap(), "a&lt;b&amp;c");
    }

    #[test]
    fn every_shipped_template_fills_with_its_writer_values() {
        // the decks call fill_template with exactly these keys; a drift fails here first
        let keys = |t: &str| -> Vec<String> {
            t.split("{{").skip(1).map(|s| s.split("}}").next().unwrap().trim().to_string()).collect()
        };
        let mut hgo = keys(TEMPLATE_HGO.1);
        hgo.sort();
        assert_eq!(hgo, ["c", "density", "gamma", "id", "k", "k1", "k2", "kappa", "name"]);
        for t in [TEMPLATE_CONTROL_STATIC.1, TEMPLATE_CONTROL_FSI.1] {
            let mut k = keys(t);
            k.sort();
            k.dedup();
            assert_eq!(k, ["dtmin", "step_size", "time_steps"]);
        }
    }

    #[test]
    fn numbers_round_trip_and_stay_readable() {
        for x in [0.0, 1.0, -2.5, 1.0 / 3.0, 1.2246467991473532e-16, 1.06e-9, 2200.0, 13332.2387415, 1e20] {
            let s = num(x);
            assert_eq!(s.parse::<f64>().unwrap(), x, "{s}");
            assert!(s.len() <= 24, "{s}");
        }
        assert_eq!(num(-0.0), "0");
        assert_eq!(num(0.0133), "0.0133");
        assert_eq!(num(1.06e-9), "1.06e-9");
    }

    #[test]
    fn parameters_print_without_conversion_noise() {
        assert_eq!(param(2.3632 / 1e3), "0.0023632");
        assert_eq!(param(100.0 * MMHG_PA / 1e6), "0.0133322387415");
        assert_eq!(param(0.1), "0.1");
        assert_eq!(param(-100.0), "-100");
    }

    #[test]
    fn unit_systems_are_consistent() {
        let mm = MechanicalUnits::of(LengthUnit::Mm);
        assert_eq!(mm.density(1060.0), 1.06e-9);
        assert_eq!(mm.viscosity(3.5e-3), 3.5e-9);
        assert_eq!(mm.stress(2.2e9), 2200.0);
        assert_eq!(mm.stress(3e3), 0.003);
        assert_eq!(mm.stress(1e-3), 1e-9);
        assert_eq!(mm.velocity(0.1), 100.0);
        let m = MechanicalUnits::of(LengthUnit::M);
        assert_eq!(m.stress(13332.2), 13332.2);
        assert_eq!(m.density(1060.0), 1060.0);
        assert!(mm.describe().contains("tonne") && mm.describe().contains("MPa"));
        assert!(m.describe().contains("kg") && m.describe().contains("Pa"));
    }

    #[test]
    fn default_config_is_valid_and_element_reads_from_toml() {
        FebioConfig::default().validate().unwrap();
        let c: FebioConfig = toml::from_str("element = \"hex20\"").unwrap();
        assert_eq!(c.element, FebioElement::Hex20);
        assert!(toml::from_str::<FebioConfig>("element = \"hex27\"").is_err());
    }
}
