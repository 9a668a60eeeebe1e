//! The FEBio 4.0 decks, read back with quick-xml and held to the reader rules of FORMATS.md 2b
//! and to the two silent errors of VALIDATION.md (a missing mat_axis entry, lumen facets wound
//! the wrong way). The checks are plain functions returning `Err(reason)`, run on our decks, on
//! deliberately broken copies (so they can fail) and on the example decks FEBio 4.11 ran.

mod common;

use nalgebra::{Point3, Vector3};
use quick_xml::events::Event;
use quick_xml::Reader;
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::PathBuf;
use std::sync::OnceLock;
use vesselhex::config::MeshConfig;
use vesselhex::mesh::{sets, Region, VesselMesh};
use vesselhex::units::LengthUnit;
use vesselhex::writers::febio::{end_supports, fsi_deck, wall_deck};
use vesselhex::writers::{writer, WriteOptions};

// ------------------------------------------------------------------------------------------------
// A small DOM
// ------------------------------------------------------------------------------------------------

#[derive(Debug, Clone, Default)]
struct El {
    name: String,
    attrs: Vec<(String, String)>,
    text: String,
    children: Vec<El>,
}

impl El {
    fn attr(&self, k: &str) -> Option<&str> {
        self.attrs.iter().find(|(a, _)| a == k).map(|(_, v)| v.as_str())
    }
    fn all<'a>(&'a self, name: &str) -> impl Iterator<Item = &'a El> + 'a {
        let name = name.to_string();
        self.children.iter().filter(move |c| c.name == name)
    }
    fn one(&self, name: &str) -> Result<&El, String> {
        let mut it = self.all(name);
        let first = it.next().ok_or_else(|| format!("<{}> has no <{name}>", self.name))?;
        if it.next().is_some() {
            return Err(format!("<{}> has more than one <{name}>", self.name));
        }
        Ok(first)
    }
    fn child_names(&self) -> Vec<&str> {
        self.children.iter().map(|c| c.name.as_str()).collect()
    }
}

fn parse(text: &str) -> Result<El, String> {
    let mut reader = Reader::from_str(text);
    let mut stack: Vec<El> = vec![El::default()];
    let element = |e: &quick_xml::events::BytesStart| -> Result<El, String> {
        let mut el = El { name: e.name().as_ref().to_string(), ..Default::default() };
        for a in e.attributes() {
            let a = a.map_err(|e| e.to_string())?;
            let v = a.normalized_value(quick_xml::XmlVersion::Explicit1_0).map_err(|e| e.to_string())?.into_owned();
            el.attrs.push((a.key.as_ref().to_string(), v));
        }
        Ok(el)
    };
    loop {
        match reader.read_event().map_err(|e| format!("XML error at {}: {e}", reader.buffer_position()))? {
            Event::Start(e) => stack.push(element(&e)?),
            Event::Empty(e) => {
                let el = element(&e)?;
                stack.last_mut().unwrap().children.push(el);
            }
            Event::End(e) => {
                let el = stack.pop().unwrap();
                if el.name.as_str() != e.name().as_ref() {
                    return Err(format!("mismatched </{}>", el.name));
                }
                stack.last_mut().ok_or("unbalanced end tag")?.children.push(el);
            }
            Event::Text(t) => stack.last_mut().unwrap().text.push_str(t.xml10_content().trim()),
            Event::GeneralRef(r) => {
                let s = match r.as_ref() {
                    "amp" => "&",
                    "lt" => "<",
                    "gt" => ">",
                    "quot" => "\"",
                    "apos" => "'",
                    other => return Err(format!("unexpected entity {other}")),
                };
                stack.last_mut().unwrap().text.push_str(s);
            }
            Event::Eof => break,
            _ => {}
        }
    }
    let mut doc = stack.pop().ok_or("empty document")?;
    if !stack.is_empty() {
        return Err("unclosed elements".into());
    }
    let root = doc.children.pop().ok_or("no root element")?;
    if root.name != "febio_spec" {
        return Err(format!("root is <{}>, not <febio_spec>", root.name));
    }
    Ok(root)
}

fn ints(text: &str) -> Result<Vec<u32>, String> {
    text.split(',').map(|s| s.trim().parse::<u32>().map_err(|_| format!("not an id list: '{text}'"))).collect()
}

fn vec3(text: &str) -> Result<Vector3<f64>, String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|s| s.trim().parse::<f64>().map_err(|_| format!("not a vector: '{text}'")))
        .collect::<Result<_, _>>()?;
    if v.len() != 3 {
        return Err(format!("not a 3-vector: '{text}'"));
    }
    Ok(Vector3::new(v[0], v[1], v[2]))
}

// ------------------------------------------------------------------------------------------------
// The deck as FEBio would see it
// ------------------------------------------------------------------------------------------------

/// FEBio's own hex8 face table (FEElement::GetFace, FORMATS.md 2b), written out independently of
/// vesselhex's.
const FEBIO_HEX8_FACES: [[usize; 4]; 6] =
    [[0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7], [0, 3, 2, 1], [4, 5, 6, 7]];
/// For each corner, three neighbours forming a right-handed frame in a valid hex8.
const CORNER_FRAMES: [[usize; 3]; 8] =
    [[1, 3, 4], [2, 0, 5], [3, 1, 6], [0, 2, 7], [7, 5, 0], [4, 6, 1], [5, 7, 2], [6, 4, 3]];
const SECTIONS_4_0: [&str; 18] = [
    "Module",
    "Globals",
    "Control",
    "Material",
    "Mesh",
    "MeshDomains",
    "MeshData",
    "MeshAdaptor",
    "Initial",
    "Boundary",
    "Loads",
    "Contact",
    "Constraints",
    "Rigid",
    "Discrete",
    "LoadData",
    "Output",
    "Step",
];

#[derive(Debug)]
struct Block {
    name: String,
    elems: Vec<(u32, Vec<u32>)>,
}

#[derive(Debug)]
struct Deck {
    root: El,
    nodes: BTreeMap<u32, Point3<f64>>,
    blocks: Vec<Block>,
    /// material name -> type
    materials: HashMap<String, String>,
    /// domain name -> material name
    domains: Vec<(String, String)>,
}

impl Deck {
    /// Parses and checks what the reader itself enforces while reading the mesh: strictly
    /// increasing node and element ids, node counts of the element type, known node references.
    fn read(text: &str) -> Result<Deck, String> {
        let root = parse(text)?;
        let mesh = root.one("Mesh")?;
        let mut nodes = BTreeMap::new();
        let mut last = 0u32;
        for block in mesh.all("Nodes") {
            for n in &block.children {
                if n.name != "node" {
                    return Err(format!("<Nodes> holds <{}>", n.name));
                }
                let id: u32 = n.attr("id").ok_or("node without id")?.parse().map_err(|_| "bad node id")?;
                if id <= last {
                    return Err(format!("node id {id} after {last}: ids must increase strictly"));
                }
                last = id;
                nodes.insert(id, Point3::from(vec3(&n.text)?));
            }
        }
        let mut blocks = Vec::new();
        let mut last = 0u32;
        for b in mesh.all("Elements") {
            let name = b.attr("name").ok_or("<Elements> without name")?.to_string();
            let per = match b.attr("type") {
                Some("hex8") => 8,
                Some("hex20") => 20,
                t => return Err(format!("element type {t:?} not expected")),
            };
            let mut elems = Vec::new();
            for e in &b.children {
                let id: u32 = e.attr("id").ok_or("elem without id")?.parse().map_err(|_| "bad elem id")?;
                if id <= last {
                    return Err(format!("element id {id} after {last}: ids must increase strictly"));
                }
                last = id;
                let conn = ints(&e.text)?;
                if conn.len() != per {
                    return Err(format!("element {id} has {} nodes, its type needs {per}", conn.len()));
                }
                if let Some(n) = conn.iter().find(|n| !nodes.contains_key(n)) {
                    return Err(format!("element {id} uses undefined node {n}"));
                }
                elems.push((id, conn));
            }
            blocks.push(Block { name, elems });
        }
        let mut materials = HashMap::new();
        for m in root.one("Material")?.all("material") {
            let name = m.attr("name").ok_or("material without name")?;
            if materials.insert(name.to_string(), m.attr("type").unwrap_or("").to_string()).is_some() {
                return Err(format!("material name {name} repeated"));
            }
        }
        let domains = root
            .one("MeshDomains")?
            .children
            .iter()
            .map(|d| (d.attr("name").unwrap_or("").to_string(), d.attr("mat").unwrap_or("").to_string()))
            .collect();
        Ok(Deck { root, nodes, blocks, materials, domains })
    }

    fn block(&self, name: &str) -> Option<&Block> {
        self.blocks.iter().find(|b| b.name == name)
    }
    fn is_fluid(&self, block: &str) -> bool {
        self.domains
            .iter()
            .find(|(d, _)| d == block)
            .and_then(|(_, m)| self.materials.get(m))
            .is_some_and(|t| t == "fluid-FSI")
    }
    fn solid_blocks(&self) -> Vec<&Block> {
        self.blocks.iter().filter(|b| !self.is_fluid(&b.name)).collect()
    }
    fn mesh_children(&self, kind: &str) -> Vec<&El> {
        self.root.one("Mesh").map(|m| m.all(kind).collect()).unwrap_or_default()
    }
    fn node_set(&self, name: &str) -> Option<Vec<u32>> {
        self.mesh_children("NodeSet")
            .into_iter()
            .find(|s| s.attr("name") == Some(name))
            .and_then(|s| ints(&s.text).ok())
    }
    fn surface(&self, name: &str) -> Option<&El> {
        self.mesh_children("Surface").into_iter().find(|s| s.attr("name") == Some(name))
    }
    fn point(&self, id: u32) -> Point3<f64> {
        self.nodes[&id]
    }
    fn centroid(&self, conn: &[u32]) -> Point3<f64> {
        let s = conn[..8].iter().fold(Vector3::zeros(), |a, n| a + self.point(*n).coords);
        Point3::from(s / 8.0)
    }
    /// Surfaces carrying a pressure load (where the winding decides the sign).
    fn pressure_surfaces(&self) -> Vec<String> {
        self.root
            .one("Loads")
            .map(|l| {
                l.all("surface_load")
                    .filter(|s| s.attr("type") == Some("pressure"))
                    .filter_map(|s| s.attr("surface").map(String::from))
                    .collect()
            })
            .unwrap_or_default()
    }
}

// ------------------------------------------------------------------------------------------------
// The checks
// ------------------------------------------------------------------------------------------------

fn check_sections(d: &Deck, module: &str) -> Result<(), String> {
    if d.root.attr("version") != Some("4.0") {
        return Err("febio_spec version is not 4.0".into());
    }
    let names = d.root.child_names();
    if names.first() != Some(&"Module") || d.root.children[0].attr("type") != Some(module) {
        return Err(format!("the first section must be <Module type=\"{module}\"/>"));
    }
    let mut last = 0;
    for n in &names {
        let i = SECTIONS_4_0.iter().position(|s| s == n).ok_or_else(|| format!("unknown section <{n}>"))?;
        if i < last {
            return Err(format!("section <{n}> out of order (MeshData must follow MeshDomains)"));
        }
        last = i;
    }
    let unique: BTreeSet<_> = names.iter().collect();
    if unique.len() != names.len() {
        return Err("a section appears twice".into());
    }
    Ok(())
}

/// Names resolve: domains to element blocks and materials (by name), ElementData to a single
/// domain, bcs and loads to node sets and surfaces, load curves to controllers; names unique.
fn check_names(d: &Deck) -> Result<(), String> {
    let blocks: Vec<&str> = d.blocks.iter().map(|b| b.name.as_str()).collect();
    let node_sets: Vec<&str> = d.mesh_children("NodeSet").iter().filter_map(|s| s.attr("name")).collect();
    let surfaces: Vec<&str> = d.mesh_children("Surface").iter().filter_map(|s| s.attr("name")).collect();
    let mut all = BTreeSet::new();
    for n in blocks.iter().chain(&node_sets).chain(&surfaces) {
        if !all.insert(*n) {
            return Err(format!("name '{n}' used twice in <Mesh>"));
        }
    }
    if d.domains.len() != blocks.len() {
        return Err("every <Elements> block needs exactly one domain".into());
    }
    for (name, mat) in &d.domains {
        if !blocks.contains(&name.as_str()) {
            return Err(format!("domain '{name}' names no <Elements> block"));
        }
        if !d.materials.contains_key(mat) {
            return Err(format!("domain '{name}' refers to unknown material '{mat}'"));
        }
    }
    if let Ok(md) = d.root.one("MeshData") {
        for e in &md.children {
            let set = e.attr("elem_set").unwrap_or("");
            if !blocks.contains(&set) {
                return Err(format!("ElementData on '{set}', which is not a domain"));
            }
        }
    }
    let curves: Vec<&str> = d
        .root
        .one("LoadData")
        .map(|l| l.all("load_controller").filter_map(|c| c.attr("id")).collect())
        .unwrap_or_default();
    let mut stack: Vec<&El> = ["Boundary", "Loads", "Output"].iter().filter_map(|s| d.root.one(s).ok()).collect();
    while let Some(e) = stack.pop() {
        if let Some(s) = e.attr("node_set") {
            if !node_sets.contains(&s) {
                return Err(format!("<{}> refers to unknown node set '{s}'", e.name));
            }
        }
        if let Some(s) = e.attr("surface") {
            if !surfaces.contains(&s) {
                return Err(format!("<{}> refers to unknown surface '{s}'", e.name));
            }
        }
        if let Some(lc) = e.attr("lc") {
            if !curves.contains(&lc) {
                return Err(format!("<{}> refers to unknown load curve {lc}", e.name));
            }
        }
        stack.extend(e.children.iter());
    }
    Ok(())
}

/// NodeSets are leaves holding a comma list of defined node ids; facets have the node count of
/// their tag and defined nodes.
fn check_sets_and_facets(d: &Deck) -> Result<(), String> {
    for s in d.mesh_children("NodeSet") {
        if !s.children.is_empty() {
            return Err(format!("NodeSet {:?} is not a leaf (4.0 wants a comma list)", s.attr("name")));
        }
        let ids = ints(&s.text)?;
        let unique: BTreeSet<_> = ids.iter().collect();
        if ids.is_empty() || unique.len() != ids.len() {
            return Err(format!("NodeSet {:?} is empty or repeats a node", s.attr("name")));
        }
        if let Some(n) = ids.iter().find(|n| !d.nodes.contains_key(n)) {
            return Err(format!("NodeSet {:?} names undefined node {n}", s.attr("name")));
        }
    }
    for s in d.mesh_children("Surface") {
        for f in &s.children {
            let want = match f.name.as_str() {
                "tri3" => 3,
                "quad4" => 4,
                "tri6" => 6,
                "tri7" => 7,
                "quad8" => 8,
                "quad9" => 9,
                t => return Err(format!("unknown facet tag <{t}>")),
            };
            let n = ints(&f.text)?;
            if n.len() != want {
                return Err(format!("facet <{}> with {} nodes", f.name, n.len()));
            }
            if let Some(x) = n.iter().find(|x| !d.nodes.contains_key(x)) {
                return Err(format!("facet uses undefined node {x}"));
            }
        }
    }
    Ok(())
}

/// Every solid element has exactly one mat_axis entry in its domain's map, lid = 1-based
/// position; `a`, `d` unit and orthogonal to `tol`.
fn check_mat_axis(d: &Deck, tol: f64) -> Result<(), String> {
    let md = d.root.one("MeshData")?;
    for b in d.solid_blocks() {
        let maps: Vec<&El> = md
            .all("ElementData")
            .filter(|e| e.attr("type") == Some("mat_axis") && e.attr("elem_set") == Some(&b.name))
            .collect();
        if maps.len() != 1 {
            return Err(format!("domain {} has {} mat_axis maps", b.name, maps.len()));
        }
        let mut seen = vec![0usize; b.elems.len()];
        for e in &maps[0].children {
            let lid: usize = e.attr("lid").ok_or("mat_axis entry without lid")?.parse().map_err(|_| "bad lid")?;
            if lid == 0 || lid > b.elems.len() {
                return Err(format!("{}: lid {lid} outside 1..={}", b.name, b.elems.len()));
            }
            seen[lid - 1] += 1;
            let a = vec3(&e.one("a")?.text)?;
            let dd = vec3(&e.one("d")?.text)?;
            if (a.norm() - 1.0).abs() > tol || (dd.norm() - 1.0).abs() > tol || a.dot(&dd).abs() > tol {
                return Err(format!("{} lid {lid}: a, d not orthonormal", b.name));
            }
        }
        if let Some(i) = seen.iter().position(|c| *c != 1) {
            return Err(format!(
                "{}: element lid {} (id {}) has {} mat_axis entries (a missing one keeps the global axes)",
                b.name,
                i + 1,
                b.elems[i].0,
                seen[i]
            ));
        }
    }
    for b in d.blocks.iter().filter(|b| d.is_fluid(&b.name)) {
        if md.all("ElementData").any(|e| e.attr("elem_set") == Some(&b.name)) {
            return Err(format!("mat_axis on fluid domain {} (ignored by FEBio)", b.name));
        }
    }
    Ok(())
}

fn face_key(n: &[u32]) -> [u32; 4] {
    let mut k = [n[0], n[1], n[2], n[3]];
    k.sort_unstable();
    k
}

/// Elements owning each face (by sorted node quadruple) among `blocks`.
fn face_owners<'a>(blocks: &[&'a Block]) -> HashMap<[u32; 4], Vec<&'a (u32, Vec<u32>)>> {
    let mut map: HashMap<[u32; 4], Vec<&(u32, Vec<u32>)>> = HashMap::new();
    for b in blocks {
        for e in &b.elems {
            for f in FEBIO_HEX8_FACES {
                map.entry(face_key(&f.map(|i| e.1[i]))).or_default().push(e);
            }
        }
    }
    map
}

fn area_vector(d: &Deck, n: &[u32]) -> Vector3<f64> {
    let p: Vec<Point3<f64>> = n[..4].iter().map(|i| d.point(*i)).collect();
    (p[2] - p[0]).cross(&(p[3] - p[1])) * 0.5
}

fn facet_centre(d: &Deck, n: &[u32]) -> Point3<f64> {
    Point3::from(n[..4].iter().fold(Vector3::zeros(), |a, i| a + d.point(*i).coords) / 4.0)
}

/// Every facet of `surface` is a face of exactly one element of `owners` and its normal points
/// away from that element (FEBio: positive pressure acts against the normal).
fn check_outward(d: &Deck, surface: &str, owners: &[&Block]) -> Result<(), String> {
    let s = d.surface(surface).ok_or_else(|| format!("no surface {surface}"))?;
    let map = face_owners(owners);
    for f in &s.children {
        let n = ints(&f.text)?;
        let own = map.get(&face_key(&n)).map(|v| v.as_slice()).unwrap_or(&[]);
        if own.len() != 1 {
            return Err(format!("{surface} facet {:?} bounds {} elements, not 1", f.attr("id"), own.len()));
        }
        let out = facet_centre(d, &n) - d.centroid(&own[0].1);
        if area_vector(d, &n).dot(&out) <= 0.0 {
            return Err(format!("{surface} facet {:?} points into its element {}", f.attr("id"), own[0].0));
        }
    }
    Ok(())
}

/// Positive Jacobian at every corner of every hex.
fn check_jacobians(d: &Deck) -> Result<(), String> {
    for b in &d.blocks {
        for (id, conn) in &b.elems {
            for (c, nb) in CORNER_FRAMES.iter().enumerate() {
                let o = d.point(conn[c]);
                let [e1, e2, e3] = nb.map(|i| d.point(conn[i]) - o);
                if e1.cross(&e2).dot(&e3) <= 0.0 {
                    return Err(format!("element {id}: non-positive Jacobian at corner {c}"));
                }
            }
        }
    }
    Ok(())
}

fn nodes_of(blocks: &[&Block]) -> BTreeSet<u32> {
    blocks.iter().flat_map(|b| b.elems.iter().flat_map(|e| e.1.iter().copied())).collect()
}

/// Everything FEBio checks while reading, plus the two silent errors.
fn check_all(text: &str, module: &str) -> Result<Deck, String> {
    check_all_with(text, module, 1e-9)
}

/// [`check_all`] with a tolerance on the unit length and orthogonality of the axes.
fn check_all_with(text: &str, module: &str, axis_tol: f64) -> Result<Deck, String> {
    let d = Deck::read(text)?;
    check_sections(&d, module)?;
    check_names(&d)?;
    check_sets_and_facets(&d)?;
    check_mat_axis(&d, axis_tol)?;
    check_jacobians(&d)?;
    for s in d.pressure_surfaces() {
        check_outward(&d, &s, &d.solid_blocks())?;
    }
    Ok(d)
}

// ------------------------------------------------------------------------------------------------
// Fixtures
// ------------------------------------------------------------------------------------------------

fn tube() -> &'static VesselMesh {
    static MESH: OnceLock<VesselMesh> = OnceLock::new();
    MESH.get_or_init(|| vesselhex::testing::straight_tube_mesh(&MeshConfig::default()).expect("straight tube").mesh)
}

fn options(unit: LengthUnit) -> WriteOptions {
    WriteOptions { length_unit: unit, ..Default::default() }
}

fn wall_text() -> &'static str {
    static T: OnceLock<String> = OnceLock::new();
    T.get_or_init(|| wall_deck(tube(), &options(LengthUnit::Mm)).unwrap())
}

fn fsi_text() -> &'static str {
    static T: OnceLock<String> = OnceLock::new();
    T.get_or_init(|| fsi_deck(tube(), &options(LengthUnit::Mm)).unwrap())
}

/// The verified example decks, found above the crate (shared/docs/examples) or in
/// $VESSELHEX_DOCS/examples.
fn example(name: &str) -> Option<String> {
    let mut candidates: Vec<PathBuf> =
        std::env::var_os("VESSELHEX_DOCS").map(|d| vec![PathBuf::from(d)]).unwrap_or_default();
    candidates.extend(common::crate_dir().ancestors().map(|a| a.join("shared/docs")));
    for dir in candidates {
        let p = dir.join("examples").join(name);
        if let Ok(t) = std::fs::read_to_string(&p) {
            return Some(t);
        }
    }
    assert!(!common::under_ci(), "CI=true but the example deck {name} is missing");
    eprintln!("skipped: example deck {name} not found (set VESSELHEX_DOCS)");
    None
}

// ------------------------------------------------------------------------------------------------
// Tests
// ------------------------------------------------------------------------------------------------

#[test]
fn wall_deck_obeys_the_reader_rules() {
    let mesh = tube();
    let d = check_all(wall_text(), "solid").unwrap();
    let names: Vec<&str> = d.blocks.iter().map(|b| b.name.as_str()).collect();
    assert_eq!(names, ["intima", "media", "adventitia"]);
    for (b, r) in d.blocks.iter().zip(Region::WALL) {
        let range = mesh.region_range(r);
        assert_eq!(b.elems.len(), range.len());
        for ((id, conn), e) in b.elems.iter().zip(range) {
            assert_eq!(*id as usize, e + 1);
            assert_eq!(conn, &mesh.hexes[e].map(|n| n + 1).to_vec());
        }
        assert_eq!(d.materials[r.name()], "Holzapfel-Gasser-Ogden");
    }
    // only wall nodes, labelled index + 1, coordinates exact
    assert_eq!(d.nodes.len(), mesh.nodes_of(mesh.wall_range()).len());
    for (id, p) in &d.nodes {
        assert_eq!(*p, mesh.nodes[*id as usize - 1]);
    }
    // lumen pressure on the wall's lumen faces; end rings as node sets
    assert_eq!(d.pressure_surfaces(), [sets::WALL_LUMEN_FACES]);
    for end in ["inlet", "outlet"] {
        let want: Vec<u32> = mesh.node_sets[&sets::wall_end(end)].iter().map(|n| n + 1).collect();
        assert_eq!(d.node_set(&sets::wall_end(end)).unwrap(), want);
    }
    check_outward(&d, sets::WALL_OUTER_FACES, &d.solid_blocks()).unwrap();
}

#[test]
fn lumen_facets_point_into_the_lumen() {
    // away from the wall element (checked above) and towards the lumen element on the other side
    let mesh = tube();
    let d = Deck::read(wall_text()).unwrap();
    let lumen: HashMap<[u32; 4], usize> = mesh
        .lumen_range()
        .flat_map(|e| (0..6).map(move |f| (e, f)))
        .map(|(e, f)| (face_key(&vesselhex::mesh::face_nodes(&mesh.hexes[e], f).map(|n| n + 1)), e))
        .collect();
    let s = d.surface(sets::WALL_LUMEN_FACES).unwrap();
    assert_eq!(s.children.len(), mesh.face_sets[sets::WALL_LUMEN_FACES].len());
    for f in &s.children {
        let n = ints(&f.text).unwrap();
        let e = lumen[&face_key(&n)];
        let c = mesh.corners(e);
        let centre = Point3::from(c.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / 8.0);
        assert!(area_vector(&d, &n).dot(&(centre - facet_centre(&d, &n))) > 0.0);
        // straight tube along z: the normal points towards the axis
        let p = facet_centre(&d, &n);
        assert!(area_vector(&d, &n).dot(&Vector3::new(p.x, p.y, 0.0)) < 0.0);
    }
}

#[test]
fn mat_axes_are_the_element_triads() {
    let mesh = tube();
    let d = Deck::read(wall_text()).unwrap();
    let md = d.root.one("MeshData").unwrap();
    for r in Region::WALL {
        let map = md.all("ElementData").find(|e| e.attr("elem_set") == Some(r.name())).unwrap();
        let range = mesh.region_range(r);
        assert_eq!(map.children.len(), range.len());
        for (entry, e) in map.children.iter().zip(range) {
            assert_eq!(entry.name, "elem");
            let t = &mesh.triads[e];
            assert_eq!(vec3(&entry.one("a").unwrap().text).unwrap(), t.e_circ);
            assert_eq!(vec3(&entry.one("d").unwrap().text).unwrap(), t.e_long);
        }
    }
    // FEBio's basis e3 = a x d is the outward radial direction: the frame is right-handed
    for e in mesh.wall_range() {
        let t = &mesh.triads[e];
        assert!((t.e_circ.cross(&t.e_long) - t.e_rad).norm() < 1e-9);
    }
}

#[test]
fn broken_decks_fail_the_checks() {
    let text = wall_text();
    // one lumen facet flipped
    let start = text.find(&format!("<Surface name=\"{}\">", sets::WALL_LUMEN_FACES)).unwrap();
    let open = start + text[start..].find("<quad4 id=\"1\">").unwrap() + "<quad4 id=\"1\">".len();
    let close = open + text[open..].find('<').unwrap();
    let mut ids: Vec<&str> = text[open..close].split(',').collect();
    ids.reverse();
    let flipped = format!("{}{}{}", &text[..open], ids.join(","), &text[close..]);
    let e = check_all(&flipped, "solid").unwrap_err();
    assert!(e.contains("points into its element"), "{e}");
    // one mat_axis entry dropped
    let line_start = text.find("<elem lid=\"7\">").unwrap();
    let line_end = line_start + text[line_start..].find('\n').unwrap() + 1;
    let dropped = format!("{}{}", &text[..line_start], &text[line_end..]);
    let e = check_all(&dropped, "solid").unwrap_err();
    assert!(e.contains("lid 7") && e.contains("0 mat_axis entries"), "{e}");
    // MeshData before MeshDomains
    let (md0, md1) =
        (text.find("  <MeshData>").unwrap(), text.find("  </MeshData>\n").unwrap() + "  </MeshData>\n".len());
    let doms = text.find("  <MeshDomains>").unwrap();
    let swapped = format!("{}{}{}{}", &text[..doms], &text[md0..md1], &text[doms..md0], &text[md1..]);
    assert!(check_all(&swapped, "solid").unwrap_err().contains("out of order"));
    // an element id repeated, a NodeSet as children, a material name that does not resolve
    let first = text.find("<elem id=\"").unwrap() + "<elem id=\"".len();
    let first_id = &text[first..first + text[first..].find('"').unwrap()];
    let second = first + text[first..].find("<elem id=\"").unwrap() + "<elem id=\"".len();
    let second_end = second + text[second..].find('"').unwrap();
    let repeated = format!("{}{}{}", &text[..second], first_id, &text[second_end..]);
    assert!(Deck::read(&repeated).unwrap_err().contains("increase strictly"));
    let set = text.find("<NodeSet name=\"wall_inlet\">").unwrap();
    let children = format!(
        "{}<NodeSet name=\"wall_inlet\"><n id=\"1\"/></NodeSet>\n{}",
        &text[..set],
        &text[set..].split_once('\n').unwrap().1
    );
    assert!(check_all(&children, "solid").unwrap_err().contains("not a leaf"));
    let unresolved = text.replace("mat=\"media\"", "mat=\"Media\"");
    assert!(check_all(&unresolved, "solid").unwrap_err().contains("unknown material"));
    // a wrong facet tag
    let f3 = text.find("<quad4 id=\"3\">").unwrap();
    let f3_end = f3 + text[f3..].find("</quad4>").unwrap() + "</quad4>".len();
    let tri = format!("{}{}{}", &text[..f3], text[f3..f3_end].replace("quad4", "tri3"), &text[f3_end..]);
    assert!(check_all(&tri, "solid").unwrap_err().contains("facet <tri3> with 4 nodes"));
    // an inverted element
    let e0 = text.find("<elem id=\"").unwrap();
    let o = e0 + text[e0..].find('>').unwrap() + 1;
    let c = o + text[o..].find('<').unwrap();
    let n: Vec<&str> = text[o..c].split(',').collect();
    let inverted = [n[4], n[5], n[6], n[7], n[0], n[1], n[2], n[3]].join(",");
    let inv = format!("{}{}{}", &text[..o], inverted, &text[c..]);
    assert!(check_all(&inv, "solid").unwrap_err().contains("Jacobian"));
}

#[test]
fn end_rings_are_held_axially_and_rigid_modes_removed() {
    let mesh = tube();
    let supports = end_supports(mesh).unwrap();
    assert_eq!(supports.len(), 2);
    let d = Deck::read(wall_text()).unwrap();
    let boundary = d.root.one("Boundary").unwrap();
    let dofs = |bc: &El| -> [bool; 3] { ["x_dof", "y_dof", "z_dof"].map(|t| bc.one(t).unwrap().text == "1") };
    for s in &supports {
        // the straight tube runs along z: rings hold u_z only, lines hold x and y
        assert_eq!(s.ring_dofs, [false, false, true], "{}", s.end);
        let bc = boundary.all("bc").find(|b| b.attr("node_set") == Some(&sets::wall_end(&s.end))).unwrap();
        assert_eq!(dofs(bc), [false, false, true]);
        for k in 0..2 {
            assert!(s.plane_nodes[k].len() >= 2, "{} plane {k}", s.end);
        }
    }
    // the line nodes lie on the symmetry planes through the axis, so they do not oppose inflation
    for (k, name) in [(0usize, "rigid_x"), (1, "rigid_y")] {
        let set = d.node_set(name).unwrap();
        for id in &set {
            let p = d.point(*id);
            assert!(p[k].abs() < 1e-9, "{name}: node {id} at {p:?}");
        }
        let bc = boundary.all("bc").find(|b| b.attr("node_set") == Some(name)).unwrap();
        let mut want = [false; 3];
        want[k] = true;
        assert_eq!(dofs(bc), want);
        // both sides of the axis: the rotation about z is held too
        let j = 1 - k;
        assert!(set.iter().any(|i| d.point(*i)[j] > 0.1) && set.iter().any(|i| d.point(*i)[j] < -0.1));
    }
    // pressure ramps to 100 mmHg = 0.0133322 MPa
    let p: f64 =
        d.root.one("Loads").unwrap().one("surface_load").unwrap().one("pressure").unwrap().text.parse().unwrap();
    assert!((p - 0.0133322387415).abs() < 1e-12);
}

#[test]
fn fsi_deck_obeys_the_reader_rules_and_shares_the_interface() {
    let mesh = tube();
    let d = check_all(fsi_text(), "fluid-FSI").unwrap();
    let names: Vec<&str> = d.blocks.iter().map(|b| b.name.as_str()).collect();
    assert_eq!(names, ["lumen", "intima", "media", "adventitia"]);
    assert!(d.is_fluid("lumen") && !d.is_fluid("media"));
    // all nodes, labelled index + 1
    assert_eq!(d.nodes.len(), mesh.nodes.len());
    assert_eq!(*d.nodes.keys().last().unwrap() as usize, mesh.nodes.len());
    // fluid and solid share exactly the interface nodes
    let fluid = nodes_of(&[d.block("lumen").unwrap()]);
    let solid = nodes_of(&d.solid_blocks());
    let shared: BTreeSet<u32> = fluid.intersection(&solid).copied().collect();
    let interface: BTreeSet<u32> = d.node_set(sets::INTERFACE_NODES).unwrap().into_iter().collect();
    let want: BTreeSet<u32> = mesh.node_sets[sets::INTERFACE_NODES].iter().map(|n| n + 1).collect();
    assert_eq!(shared, interface);
    assert_eq!(interface, want);
    // every traction facet lies between a fluid-FSI element and a wall element
    let owners = face_owners(&d.blocks.iter().collect::<Vec<_>>());
    let fluid_ids: BTreeSet<u32> = d.block("lumen").unwrap().elems.iter().map(|e| e.0).collect();
    let loads = d.root.one("Loads").unwrap();
    let traction = loads.all("surface_load").find(|l| l.attr("type") == Some("fluid-FSI traction")).unwrap();
    let surf = d.surface(traction.attr("surface").unwrap()).unwrap();
    assert_eq!(surf.children.len(), mesh.face_sets[sets::LUMEN_WALL_FACES].len());
    for f in &surf.children {
        let own = &owners[&face_key(&ints(&f.text).unwrap())];
        assert_eq!(own.len(), 2);
        assert_eq!(own.iter().filter(|e| fluid_ids.contains(&e.0)).count(), 1);
    }
    // no-slip on the interface nodes; inlet and outlet faces outward from the lumen
    let boundary = d.root.one("Boundary").unwrap();
    let no_slip = boundary.all("bc").find(|b| b.attr("type") == Some("zero fluid velocity")).unwrap();
    assert_eq!(no_slip.attr("node_set"), Some(sets::INTERFACE_NODES));
    let lumen = [d.block("lumen").unwrap()];
    for end in ["inlet", "outlet"] {
        check_outward(&d, &sets::lumen_end(end), &lumen).unwrap();
    }
    let inflow = loads.all("surface_load").find(|l| l.attr("type") == Some("fluid normal velocity")).unwrap();
    assert_eq!(inflow.attr("surface"), Some("lumen_inlet"));
    let v: f64 = inflow.one("velocity").unwrap().text.parse().unwrap();
    assert!((v + 100.0).abs() < 1e-12, "inflow is negative along the outward normal: {v}");
    let backflow = loads.all("surface_load").find(|l| l.attr("type") == Some("fluid backflow stabilization")).unwrap();
    assert_eq!(backflow.attr("surface"), Some("lumen_outlet"));
    let outlet_p = boundary.all("bc").find(|b| b.attr("type") == Some("fluid pressure")).unwrap();
    assert_eq!(outlet_p.attr("surface"), Some("lumen_outlet"));
    // the lumen end nodes are fixed (mesh motion) without the interface ring, which the wall holds
    for end in ["inlet", "outlet"] {
        let inner: BTreeSet<u32> = d.node_set(&format!("lumen_{end}_inner")).unwrap().into_iter().collect();
        assert!(inner.is_disjoint(&interface));
        let ring: BTreeSet<u32> = d.node_set(&sets::wall_end(end)).unwrap().into_iter().collect();
        let all: BTreeSet<u32> = mesh.node_sets[&sets::lumen_end(end)].iter().map(|n| n + 1).collect();
        assert!(all.is_subset(&inner.union(&ring).copied().collect()));
    }
    // blood in mm-tonne-s-MPa
    let blood = d.root.one("Material").unwrap().all("material").find(|m| m.attr("type") == Some("fluid-FSI")).unwrap();
    let fl = blood.one("fluid").unwrap();
    assert_eq!(fl.one("density").unwrap().text, "1.06e-9");
    assert_eq!(fl.one("viscous").unwrap().one("mu").unwrap().text, "3.5e-9");
    assert_eq!(fl.one("k").unwrap().text, "2200");
    let control = d.root.one("Control").unwrap();
    assert_eq!(control.one("analysis").unwrap().text, "DYNAMIC");
    assert_eq!(control.one("solver").unwrap().one("symmetric_stiffness").unwrap().text, "non-symmetric");
    // every wall material has a density in model units
    for m in d.root.one("Material").unwrap().all("material").filter(|m| m.attr("type") != Some("fluid-FSI")) {
        let rho: f64 = m.one("density").unwrap().text.parse().unwrap();
        assert!((rho - 1.2e-9).abs() < 1e-20);
    }
}

/// Top-level order and the kinds of children of every section, as in the decks FEBio ran.
fn structure(d: &Deck) -> Vec<(String, Vec<String>)> {
    d.root
        .children
        .iter()
        .map(|s| {
            // children kinds in first-appearance order, plus the type attributes that select classes
            let mut kinds: Vec<String> = Vec::new();
            for c in &s.children {
                let mut k = c.name.clone();
                if matches!(s.name.as_str(), "Material" | "Boundary" | "Loads" | "MeshData") {
                    k = format!("{}[{}]", k, c.attr("type").unwrap_or(""));
                }
                if !kinds.contains(&k) {
                    kinds.push(k);
                }
            }
            if s.name == "Output" {
                for c in &s.children {
                    for v in &c.children {
                        let k = format!("{}/{}[{}]", c.name, v.name, v.attr("type").or(v.attr("data")).unwrap_or(""));
                        if !kinds.contains(&k) {
                            kinds.push(k);
                        }
                    }
                }
            }
            (s.name.clone(), kinds)
        })
        .collect()
}

#[test]
fn decks_have_the_structure_of_the_verified_examples() {
    for (ours, name, module) in
        [(wall_text(), "febio_wall_tube.feb", "solid"), (fsi_text(), "febio_fsi_tube.feb", "fluid-FSI")]
    {
        let Some(example) = example(name) else { return };
        // the checks accept the decks FEBio ran (so they test FEBio's rules, not our habits)
        // (their axes carry 8 significant digits, ours full precision)
        let ex = check_all_with(&example, module, 1e-7).unwrap_or_else(|e| panic!("{name}: {e}"));
        let us = Deck::read(ours).unwrap();
        let (a, b) = (structure(&us), structure(&ex));
        let sections = |s: &[(String, Vec<String>)]| s.iter().map(|x| x.0.clone()).collect::<Vec<_>>();
        assert_eq!(sections(&a), sections(&b), "{name}: top-level sections");
        for ((sa, ka), (_, kb)) in a.iter().zip(&b) {
            let (mut ka, mut kb) = (ka.clone(), kb.clone());
            if sa != "Mesh" {
                ka.sort();
                kb.sort();
            }
            // the logfile of the examples also logs one element; ours logs nodes only
            kb.retain(|k| !k.starts_with("logfile/element_data"));
            assert_eq!(ka, kb, "{name}: children of <{sa}>");
        }
        // the Control blocks (from our templates) use the same parameters
        let params = |d: &Deck| {
            let mut v: Vec<String> = Vec::new();
            let mut stack = vec![("".to_string(), d.root.one("Control").unwrap())];
            while let Some((path, e)) = stack.pop() {
                for c in &e.children {
                    let p = format!("{path}/{}", c.name);
                    v.push(p.clone());
                    stack.push((p, c));
                }
            }
            v.sort();
            v
        };
        assert_eq!(params(&us), params(&ex), "{name}: Control parameters");
    }
}

#[test]
fn decks_are_deterministic_and_written_by_the_format_table() {
    let mesh = tube();
    assert_eq!(wall_deck(mesh, &options(LengthUnit::Mm)).unwrap(), wall_text());
    let dir = common::temp_dir("febio-writers");
    for (format, file, text) in [("febio", "febio/wall.feb", wall_text()), ("febio-fsi", "febio/fsi.feb", fsi_text())] {
        let files = writer(format).unwrap()(mesh, &options(LengthUnit::Mm), &dir).unwrap();
        assert_eq!(files, [PathBuf::from(file)]);
        let bytes = std::fs::read(dir.join(file)).unwrap();
        assert_eq!(bytes, text.as_bytes());
        eprintln!(
            "{file}: {} bytes, {} lines (coarse straight tube: {} nodes, {} elements)",
            bytes.len(),
            text.lines().count(),
            mesh.nodes.len(),
            mesh.hexes.len()
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn metres_give_kilograms_and_pascals() {
    let mesh = tube();
    let text = wall_deck(mesh, &options(LengthUnit::M)).unwrap();
    assert!(text.contains("Units: length m, force N, stress Pa, mass kg, time s."));
    let d = check_all(&text, "solid").unwrap();
    for (id, p) in &d.nodes {
        let q = mesh.nodes[*id as usize - 1];
        assert!((p.coords - q.coords * 1e-3).norm() <= 1e-15 * q.coords.norm().max(1.0), "{id}");
    }
    let p: f64 =
        d.root.one("Loads").unwrap().one("surface_load").unwrap().one("pressure").unwrap().text.parse().unwrap();
    assert!((p - 13332.2387415).abs() < 1e-6);
    let media = d.root.one("Material").unwrap().all("material").find(|m| m.attr("name") == Some("media")).unwrap();
    // the shared default: HGO 2000 media with c x100 = 300 kPa
    assert!((media.one("c").unwrap().text.parse::<f64>().unwrap() - 300e3).abs() < 1e-9);
    assert_eq!(media.one("gamma").unwrap().text, "29");
    let fsi = fsi_deck(mesh, &options(LengthUnit::M)).unwrap();
    let f = check_all(&fsi, "fluid-FSI").unwrap();
    let blood = f.root.one("Material").unwrap().all("material").next().unwrap();
    assert!((blood.one("fluid").unwrap().one("density").unwrap().text.parse::<f64>().unwrap() - 1060.0).abs() < 1e-9);
}

#[test]
fn coordinates_keep_full_precision() {
    let d = Deck::read(fsi_text()).unwrap();
    let mesh = tube();
    for (id, p) in &d.nodes {
        assert_eq!(*p, mesh.nodes[*id as usize - 1], "node {id}");
    }
}

// ------------------------------------------------------------------------------------------------
// hex20
// ------------------------------------------------------------------------------------------------

/// FEBio's hex20 mid-edge nodes 9..20 (0-based 8..19) and the corners of their edges, read off
/// `FEHex20::shape_fnc` (node 8 is (1 - r^2)(1 - s)(1 - t): the edge from corner 0 to 1, ...),
/// written out here independently of vesselhex's edge table.
const FEBIO_HEX20_EDGES: [[usize; 2]; 12] =
    [[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4], [0, 4], [1, 5], [2, 6], [3, 7]];
/// FEBio's hex20 faces as quad8 facets (`FEMesh::GetFace`): corners, then mid-edge nodes.
const FEBIO_HEX20_FACES: [[usize; 8]; 6] = [
    [0, 1, 5, 4, 8, 17, 12, 16],
    [1, 2, 6, 5, 9, 18, 13, 17],
    [2, 3, 7, 6, 10, 19, 14, 18],
    [3, 0, 4, 7, 11, 16, 15, 19],
    [0, 3, 2, 1, 11, 10, 9, 8],
    [4, 5, 6, 7, 12, 13, 14, 15],
];

fn hex20_options() -> WriteOptions {
    let mut o = options(LengthUnit::Mm);
    o.febio.element = vesselhex::writers::febio::FebioElement::Hex20;
    o
}

fn hex20_text() -> &'static str {
    static T: OnceLock<String> = OnceLock::new();
    T.get_or_init(|| wall_deck(tube(), &hex20_options()).unwrap())
}

fn is_midpoint(m: Point3<f64>, a: Point3<f64>, b: Point3<f64>) -> bool {
    let mid = Point3::from((a.coords + b.coords) * 0.5);
    (m - mid).norm() <= 1e-12 * mid.coords.norm().max((b - a).norm())
}

#[test]
fn hex20_wall_deck_obeys_the_reader_rules_with_midpoint_nodes() {
    let mesh = tube();
    let text = hex20_text();
    let d = check_all(text, "solid").unwrap();
    let wall = mesh.wall_range();
    let corners: BTreeSet<u32> = mesh.nodes_of(wall.clone()).iter().map(|n| n + 1).collect();
    let mut mids_seen = BTreeSet::new();
    for (b, r) in d.blocks.iter().zip(Region::WALL) {
        assert_eq!(b.elems.len(), mesh.count(r));
        for (id, conn) in &b.elems {
            // 20 distinct nodes, the 8 corners the mesh's
            assert_eq!(conn.len(), 20);
            assert_eq!(conn.iter().collect::<BTreeSet<_>>().len(), 20, "element {id}");
            assert_eq!(conn[..8], mesh.hexes[*id as usize - 1].map(|n| n + 1));
            // every mid-edge node at the midpoint of its corner edge, in FEBio's order
            for (k, [a, b]) in FEBIO_HEX20_EDGES.iter().enumerate() {
                let m = conn[8 + k];
                assert!(!corners.contains(&m), "element {id}: node {m} is a corner and a mid-edge node");
                assert!(is_midpoint(d.point(m), d.point(conn[*a]), d.point(conn[*b])), "element {id} node {}", 9 + k);
                mids_seen.insert(m);
            }
        }
        assert_eq!(d.materials[r.name()], "Holzapfel-Gasser-Ogden");
    }
    // every written node is a corner or a mid-edge node of the wall; one mid-edge node per edge
    assert_eq!(d.nodes.len(), corners.len() + mids_seen.len());
    let edges: BTreeSet<(u32, u32)> = wall
        .clone()
        .flat_map(|e| FEBIO_HEX20_EDGES.map(|[a, b]| (mesh.hexes[e][a], mesh.hexes[e][b])))
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect();
    assert_eq!(mids_seen.len(), edges.len());
    // mid-edge labels follow every mesh node: ids still increase
    assert!(mids_seen.iter().all(|m| *m as usize > mesh.nodes.len()));
    eprintln!(
        "hex20 wall.feb: {} bytes, {} lines; {} hex20, {} nodes ({} corners + {} mid-edge)",
        text.len(),
        text.lines().count(),
        wall.len(),
        d.nodes.len(),
        corners.len(),
        mids_seen.len()
    );
}

#[test]
fn hex20_facets_are_quad8_faces_of_their_element_and_point_outward() {
    let mesh = tube();
    let d = Deck::read(hex20_text()).unwrap();
    let owners = face_owners(&d.solid_blocks());
    for name in [sets::WALL_LUMEN_FACES, sets::WALL_OUTER_FACES] {
        let s = d.surface(name).unwrap();
        assert_eq!(s.children.len(), mesh.face_sets[name].len());
        for f in &s.children {
            assert_eq!(f.name, "quad8", "{name}");
            let n = ints(&f.text).unwrap();
            assert_eq!(n.len(), 8);
            // nodes 5..8 are the midpoints of the facet edges 1-2, 2-3, 3-4, 4-1
            for i in 0..4 {
                assert!(
                    is_midpoint(d.point(n[4 + i]), d.point(n[i]), d.point(n[(i + 1) % 4])),
                    "{name} {:?}",
                    f.attr("id")
                );
            }
            // and the facet is one of FEBio's hex20 faces of its element, up to the starting corner
            let own = &owners[&face_key(&n)];
            assert_eq!(own.len(), 1);
            let conn = &own[0].1;
            let matches = FEBIO_HEX20_FACES.iter().any(|face| {
                (0..4)
                    .any(|k| (0..4).all(|i| n[i] == conn[face[(i + k) % 4]] && n[4 + i] == conn[face[4 + (i + k) % 4]]))
            });
            assert!(matches, "{name} facet {:?} is no hex20 face of element {}", f.attr("id"), own[0].0);
        }
        check_outward(&d, name, &d.solid_blocks()).unwrap();
    }
    // mat_axis: one entry per element, the element's triad
    check_mat_axis(&d, 1e-9).unwrap();
    let md = d.root.one("MeshData").unwrap();
    for r in Region::WALL {
        let map = md.all("ElementData").find(|e| e.attr("elem_set") == Some(r.name())).unwrap();
        assert_eq!(map.children.len(), mesh.count(r));
    }
}

#[test]
fn hex20_node_sets_hold_the_mid_edge_nodes_of_their_rings() {
    let mesh = tube();
    let d = Deck::read(hex20_text()).unwrap();
    let corners_only = Deck::read(wall_text()).unwrap();
    for end in &mesh.ends {
        let name = sets::wall_end(&end.name);
        let ring = d.node_set(&name).unwrap();
        let ring8 = corners_only.node_set(&name).unwrap();
        assert!(ring.len() > ring8.len(), "{name}: no mid-edge nodes");
        // every node of the set, mid-edge ones included, lies in the end plane
        for id in &ring {
            let off = (d.point(*id) - end.centre).dot(&end.outward_normal);
            assert!(off.abs() < 1e-9, "{name}: node {id} is {off} off the end plane");
        }
        // the corners, plus one mid-edge node per wall edge between two of them
        assert!(ring8.iter().all(|n| ring.contains(n)));
        let members: BTreeSet<u32> = ring8.iter().map(|n| n - 1).collect();
        let ring_edges: BTreeSet<(u32, u32)> = mesh
            .wall_range()
            .flat_map(|e| FEBIO_HEX20_EDGES.map(|[a, b]| (mesh.hexes[e][a], mesh.hexes[e][b])))
            .filter(|(a, b)| members.contains(a) && members.contains(b))
            .map(|(a, b)| (a.min(b), a.max(b)))
            .collect();
        assert_eq!(ring.len(), ring8.len() + ring_edges.len(), "{name}");
    }
    let interface = d.node_set(sets::INTERFACE_NODES).unwrap();
    let lumen_facets: BTreeSet<u32> =
        d.surface(sets::WALL_LUMEN_FACES).unwrap().children.iter().flat_map(|f| ints(&f.text).unwrap()).collect();
    assert_eq!(interface.into_iter().collect::<BTreeSet<_>>(), lumen_facets, "interface = the lumen facets' nodes");
    // the rigid-mode lines: on their symmetry planes, mid-edge nodes included
    for (k, name) in [(0usize, "rigid_x"), (1, "rigid_y")] {
        let set = d.node_set(name).unwrap();
        assert!(set.len() > corners_only.node_set(name).unwrap().len());
        assert!(set.iter().all(|id| d.point(*id)[k].abs() < 1e-9), "{name}");
    }
}

#[test]
fn hex20_is_refused_by_the_fsi_deck_with_the_key() {
    let e = fsi_deck(tube(), &hex20_options()).unwrap_err().to_string();
    assert!(e.contains("febio.element") && e.contains("hex8") && e.contains("febio-fsi"), "{e}");
    // and the case file key reads
    let dir = common::temp_dir("febio-hex20-key");
    let case = dir.join("case.toml");
    std::fs::write(&case, "[febio]\nelement = \"hex20\"\n").unwrap();
    let c = MeshConfig::from_case_file(&case, None).unwrap();
    assert_eq!(c.febio.element, vesselhex::writers::febio::FebioElement::Hex20);
    // with febio-fsi requested, before any meshing
    std::fs::write(&case, "formats = [\"febio\", \"febio-fsi\"]\n[febio]\nelement = \"hex20\"\n").unwrap();
    let e = MeshConfig::from_case_file(&case, None).unwrap_err().to_string();
    assert!(e.contains("febio.element") && e.contains("febio-fsi"), "{e}");
    std::fs::write(&case, "[febio]\nelement = \"hex27\"\n").unwrap();
    let e = MeshConfig::from_case_file(&case, None).unwrap_err().to_string();
    assert!(e.contains("hex27") && e.contains("case.toml"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

// ------------------------------------------------------------------------------------------------
// Several outlets
// ------------------------------------------------------------------------------------------------

/// Both decks of a mesh with an inlet and five outlets (three disjoint tubes, two oblique): every
/// end has its ring set and its support, the inflow goes through the inlet only, and every outlet
/// has its own pressure condition and backflow stabilization on its own outward surface.
#[test]
fn every_end_of_a_multi_outlet_mesh_gets_its_sets_and_conditions() {
    let mut c = MeshConfig::default();
    c.lumen.core_elements = 2;
    c.lumen.radial_elements = 2;
    c.lumen.axial_spacing_mm = Some(3.0);
    let mesh = vesselhex::testing::multi_outlet_mesh(&c).unwrap();
    let ends: Vec<&str> = mesh.ends.iter().map(|e| e.name.as_str()).collect();
    let outlets: Vec<&str> = ends[1..].to_vec();
    assert_eq!(ends[0], "inlet");

    let wall = check_all(&wall_deck(&mesh, &options(LengthUnit::Mm)).unwrap(), "solid").unwrap();
    let boundary = wall.root.one("Boundary").unwrap();
    let supports = end_supports(&mesh).unwrap();
    assert_eq!(supports.len(), ends.len());
    for (s, end) in supports.iter().zip(&mesh.ends) {
        let set = sets::wall_end(&end.name);
        let want: Vec<u32> = mesh.node_sets[&set].iter().map(|n| n + 1).collect();
        assert_eq!(wall.node_set(&set).unwrap(), want, "{set}");
        let bc =
            boundary.all("bc").find(|b| b.attr("node_set") == Some(&set)).unwrap_or_else(|| panic!("{set} not held"));
        let held: Vec<bool> = ["x_dof", "y_dof", "z_dof"].iter().map(|t| bc.one(t).unwrap().text == "1").collect();
        // an end whose normal is a global axis is held along it; an oblique one is clamped
        let axis_aligned = end.outward_normal.iter().any(|c| c.abs() > 1.0 - 1e-9);
        assert_eq!(held.iter().filter(|h| **h).count(), if axis_aligned { 1 } else { 3 }, "{set}");
        assert_eq!(held, s.ring_dofs.to_vec());
    }

    let fsi = check_all(&fsi_deck(&mesh, &options(LengthUnit::Mm)).unwrap(), "fluid-FSI").unwrap();
    let lumen = [fsi.block("lumen").unwrap()];
    for end in &ends {
        let surface = sets::lumen_end(end);
        check_outward(&fsi, &surface, &lumen).unwrap();
        assert_eq!(fsi.surface(&surface).unwrap().children.len(), mesh.face_sets[&surface].len(), "{surface}");
        assert!(fsi.node_set(&format!("{surface}_inner")).is_some(), "{surface}_inner");
        assert!(fsi.node_set(&sets::wall_end(end)).is_some());
    }
    let loads = fsi.root.one("Loads").unwrap();
    let on = |kind: &str| -> Vec<String> {
        let mut v: Vec<String> = loads
            .all("surface_load")
            .chain(fsi.root.one("Boundary").unwrap().all("bc"))
            .filter(|l| l.attr("type") == Some(kind))
            .map(|l| l.attr("surface").unwrap().to_string())
            .collect();
        v.sort();
        v
    };
    let mut outlet_surfaces: Vec<String> = outlets.iter().map(|o| sets::lumen_end(o)).collect();
    outlet_surfaces.sort();
    assert_eq!(on("fluid normal velocity"), ["lumen_inlet"]);
    assert_eq!(on("fluid pressure"), outlet_surfaces);
    assert_eq!(on("fluid backflow stabilization"), outlet_surfaces);
    // every end is fixed for the mesh motion: wall ring and lumen face
    let fixed: BTreeSet<String> = fsi
        .root
        .one("Boundary")
        .unwrap()
        .all("bc")
        .filter(|b| b.attr("type") == Some("zero displacement"))
        .map(|b| b.attr("node_set").unwrap().to_string())
        .collect();
    for end in &ends {
        assert!(fixed.contains(&sets::wall_end(end)) && fixed.contains(&format!("lumen_{end}_inner")), "{end}");
    }
}
