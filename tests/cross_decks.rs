//! The same wall in the CalculiX deck and in the FEBio deck: same nodes (labels and
//! coordinates), same elements per layer (labels and connectivity), same end-ring and interface
//! node sets, and the same material axes (CalculiX *DISTRIBUTION a, b = FEBio mat_axis a, d); the
//! hex20 and C3D20 decks share their mid-edge nodes; and the CalculiX, Abaqus and FEBio decks carry
//! the same wall constants (`[material]`) for every layer.

use quick_xml::events::Event;
use std::collections::{BTreeMap, BTreeSet};
use vesselhex::config::material::WallMaterial;
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::mesh::Region;
use vesselhex::units::{LengthUnit, MechanicalUnits};
use vesselhex::writers::febio::FebioElement;
use vesselhex::writers::inp::ElementType;
use vesselhex::writers::{abaqus, calculix, febio, WriteOptions};

type Axes = BTreeMap<u32, [f64; 6]>;

#[derive(Default, Debug)]
struct Model {
    nodes: BTreeMap<u32, [f64; 3]>,
    /// layer -> element label -> connectivity
    elements: BTreeMap<String, BTreeMap<u32, Vec<u32>>>,
    node_sets: BTreeMap<String, BTreeSet<u32>>,
    /// layer -> element label -> (a, b)
    axes: BTreeMap<String, Axes>,
}

fn numbers(line: &str) -> Vec<f64> {
    line.split(',').map(|x| x.trim()).filter(|x| !x.is_empty()).map(|x| x.parse::<f64>().unwrap()).collect()
}

fn param<'a>(keyword_line: &'a str, key: &str) -> Option<&'a str> {
    keyword_line.split(',').map(|p| p.trim()).find_map(|p| {
        let (k, v) = p.split_once('=')?;
        k.trim().eq_ignore_ascii_case(key).then_some(v.trim())
    })
}

fn parse_calculix(text: &str) -> Model {
    let mut m = Model::default();
    let mut block: (String, String) = (String::new(), String::new());
    let mut pending: Vec<f64> = Vec::new();
    for line in text.lines() {
        if line.starts_with("**") {
            continue;
        }
        if let Some(kw) = line.strip_prefix('*') {
            let name = kw.split(',').next().unwrap().trim().to_ascii_uppercase();
            let arg = match name.as_str() {
                "ELEMENT" => param(line, "ELSET").unwrap_or("").to_ascii_lowercase(),
                "NSET" => format!(
                    "{}{}",
                    param(line, "NSET").unwrap().to_ascii_lowercase(),
                    if line.to_ascii_uppercase().contains("GENERATE") { "#gen" } else { "" }
                ),
                "DISTRIBUTION" => param(line, "NAME").unwrap().trim_start_matches("TRIAD_").to_ascii_lowercase(),
                _ => String::new(),
            };
            block = (name, arg);
            continue;
        }
        match block.0.as_str() {
            "NODE" => {
                let v = numbers(line);
                m.nodes.insert(v[0] as u32, [v[1], v[2], v[3]]);
            }
            "ELEMENT" => {
                // a C3D20 record continues on a second line after a trailing comma
                pending.extend(numbers(line));
                if !line.trim_end().ends_with(',') {
                    let v = std::mem::take(&mut pending);
                    m.elements
                        .entry(block.1.clone())
                        .or_default()
                        .insert(v[0] as u32, v[1..].iter().map(|x| *x as u32).collect());
                }
            }
            "NSET" => {
                let v = numbers(line);
                let set = m.node_sets.entry(block.1.trim_end_matches("#gen").to_string()).or_default();
                if block.1.ends_with("#gen") {
                    let (a, b, s) = (v[0] as u32, v[1] as u32, v[2] as usize);
                    set.extend((a..=b).step_by(s));
                } else {
                    set.extend(v.iter().map(|x| *x as u32));
                }
            }
            "DISTRIBUTION" if !line.trim_start().starts_with(',') => {
                let v = numbers(line);
                m.axes.entry(block.1.clone()).or_default().insert(v[0] as u32, [v[1], v[2], v[3], v[4], v[5], v[6]]);
            }
            _ => {}
        }
    }
    m
}

fn attr(e: &quick_xml::events::BytesStart, key: &str) -> Option<String> {
    e.attributes()
        .flatten()
        .find(|a| a.key.as_ref() == key)
        .map(|a| a.normalized_value(quick_xml::XmlVersion::Explicit1_0).unwrap().into_owned())
}

fn parse_febio(text: &str) -> Model {
    let mut m = Model::default();
    let mut reader = quick_xml::Reader::from_str(text);
    let mut path: Vec<String> = vec![];
    let (mut layer, mut set, mut data_set) = (String::new(), String::new(), String::new());
    let (mut id, mut lid) = (0u32, 0usize);
    let mut a = [0.0; 3];
    loop {
        match reader.read_event().unwrap() {
            Event::Start(e) => {
                let name = e.name().as_ref().to_string();
                match name.as_str() {
                    "Elements" => layer = attr(&e, "name").unwrap(),
                    "NodeSet" => set = attr(&e, "name").unwrap(),
                    "ElementData" => data_set = attr(&e, "elem_set").unwrap_or_default(),
                    "node" | "elem" | "e" => {
                        // element data entries are <e lid=..> or <elem lid=..>
                        id = attr(&e, "id").map_or(0, |v| v.parse().unwrap());
                        lid = attr(&e, "lid").map_or(0, |v| v.parse().unwrap());
                    }
                    _ => {}
                }
                path.push(name);
            }
            Event::Text(t) => {
                let text = t.xml10_content().trim().to_string();
                match path.last().map(|s| s.as_str()) {
                    Some("node") if path.iter().any(|p| p == "Nodes") => {
                        let v = numbers(&text);
                        m.nodes.insert(id, [v[0], v[1], v[2]]);
                    }
                    Some("elem") if path.iter().any(|p| p == "Elements") => {
                        m.elements
                            .entry(layer.clone())
                            .or_default()
                            .insert(id, numbers(&text).iter().map(|x| *x as u32).collect());
                    }
                    Some("NodeSet") => {
                        m.node_sets.insert(set.clone(), numbers(&text).iter().map(|x| *x as u32).collect());
                    }
                    Some("a") if path.iter().any(|p| p == "ElementData") => {
                        let v = numbers(&text);
                        a = [v[0], v[1], v[2]];
                    }
                    Some("d") if path.iter().any(|p| p == "ElementData") => {
                        let v = numbers(&text);
                        // lid is the 1-based position in the layer's element block
                        let label = *m.elements[&data_set].keys().nth(lid - 1).unwrap();
                        m.axes.entry(data_set.clone()).or_default().insert(label, [a[0], a[1], a[2], v[0], v[1], v[2]]);
                    }
                    _ => {}
                }
            }
            Event::End(_) => {
                path.pop();
            }
            Event::Eof => break,
            _ => {}
        }
    }
    m
}

#[test]
fn calculix_and_febio_decks_describe_the_same_wall() {
    let meshed = vesselhex::testing::straight_tube_mesh(&MeshConfig::preset(Preset::Coarse)).unwrap();
    let mesh = &meshed.mesh;
    let dir = std::env::temp_dir().join(format!("vesselhex-cross-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let options = WriteOptions::default();
    let ccx_files = calculix::write_calculix(mesh, &options, &dir).unwrap();
    let feb_files = febio::write_wall(mesh, &options, &dir).unwrap();
    let ccx = parse_calculix(&std::fs::read_to_string(dir.join(&ccx_files[0])).unwrap());
    let feb = parse_febio(&std::fs::read_to_string(dir.join(&feb_files[0])).unwrap());

    // Nodes: the same labels, the same coordinates (to the decks' printed precision).
    assert_eq!(ccx.nodes.keys().collect::<Vec<_>>(), feb.nodes.keys().collect::<Vec<_>>());
    assert_eq!(ccx.nodes.len(), mesh.nodes_of(mesh.wall_range()).len());
    for (label, p) in &ccx.nodes {
        let q = feb.nodes[label];
        let exact = mesh.nodes[*label as usize - 1];
        for k in 0..3 {
            assert!((p[k] - q[k]).abs() <= 1e-9 * (1.0 + p[k].abs()), "node {label}");
            assert!((p[k] - exact[k]).abs() <= 1e-9 * (1.0 + p[k].abs()), "node {label} vs the mesh");
        }
    }
    // Elements per layer: same labels and connectivity.
    for layer in ["intima", "media", "adventitia"] {
        assert_eq!(ccx.elements[layer], feb.elements[layer], "{layer}");
        assert_eq!(
            ccx.elements[layer].len(),
            mesh.count(mesh.layers.iter().find(|l| l.region.name() == layer).unwrap().region)
        );
    }
    // Sets both decks name the same way.
    for set in ["wall_inlet", "wall_outlet", "lumen_wall_interface"] {
        let a = &ccx.node_sets[set];
        let b = &feb.node_sets[set];
        assert_eq!(a, b, "node set {set}");
        assert!(!a.is_empty());
    }
    // Axes: CalculiX (a, b) and FEBio (a, d) are both (e_circ, e_long) of each element.
    for layer in ["intima", "media", "adventitia"] {
        let (x, y) = (&ccx.axes[layer], &feb.axes[layer]);
        assert_eq!(x.len(), ccx.elements[layer].len(), "every {layer} element has CalculiX axes");
        assert_eq!(x.keys().collect::<Vec<_>>(), y.keys().collect::<Vec<_>>());
        for (label, u) in x {
            let v = y[label];
            let t = mesh.triads[*label as usize - 1];
            for k in 0..3 {
                assert!((u[k] - v[k]).abs() < 1e-9 && (u[3 + k] - v[3 + k]).abs() < 1e-9, "{layer} element {label}");
                assert!((u[k] - t.e_circ[k]).abs() < 1e-9 && (u[3 + k] - t.e_long[k]).abs() < 1e-9);
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The hex20 FEBio deck and the C3D20 CalculiX deck: the same nodes (corner and mid-edge labels,
/// coordinates) and the same 20-node connectivity, since FEBio's hex20 order is C3D20's.
#[test]
fn hex20_and_c3d20_decks_share_nodes_and_connectivity() {
    let mut config = MeshConfig::preset(Preset::Coarse);
    config.lumen.axial_spacing_mm = Some(3.0);
    let meshed = vesselhex::testing::straight_tube_mesh(&config).unwrap();
    let mesh = &meshed.mesh;
    let dir = std::env::temp_dir().join(format!("vesselhex-cross20-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut options = WriteOptions::default();
    options.fe.calculix_element = ElementType::C3D20;
    options.febio.element = FebioElement::Hex20;
    let ccx_files = calculix::write_calculix(mesh, &options, &dir).unwrap();
    let feb_files = febio::write_wall(mesh, &options, &dir).unwrap();
    let ccx = parse_calculix(&std::fs::read_to_string(dir.join(&ccx_files[0])).unwrap());
    let feb = parse_febio(&std::fs::read_to_string(dir.join(&feb_files[0])).unwrap());
    assert_eq!(ccx.nodes.keys().collect::<Vec<_>>(), feb.nodes.keys().collect::<Vec<_>>());
    assert!(ccx.nodes.len() > mesh.nodes_of(mesh.wall_range()).len(), "no mid-edge nodes");
    for (label, p) in &ccx.nodes {
        let q = feb.nodes[label];
        for k in 0..3 {
            assert!((p[k] - q[k]).abs() <= 1e-9 * (1.0 + p[k].abs()), "node {label}");
        }
    }
    for layer in ["intima", "media", "adventitia"] {
        assert!(ccx.elements[layer].values().all(|c| c.len() == 20), "{layer}");
        assert_eq!(ccx.elements[layer], feb.elements[layer], "{layer}");
    }
    for set in ["wall_inlet", "wall_outlet", "lumen_wall_interface"] {
        assert_eq!(ccx.node_sets[set], feb.node_sets[set], "node set {set}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

// ------------------------------------------------------------------------------------------------
// Material constants

/// Keyword blocks of an .inp deck: the keyword line (upper case) and its data lines' fields.
fn inp_blocks(text: &str) -> Vec<(String, Vec<Vec<String>>)> {
    let mut blocks: Vec<(String, Vec<Vec<String>>)> = Vec::new();
    for line in text.lines().filter(|l| !l.starts_with("**")) {
        if let Some(kw) = line.strip_prefix('*') {
            blocks.push((kw.to_ascii_uppercase(), Vec::new()));
        } else if let Some(b) = blocks.last_mut() {
            b.1.push(line.split(',').map(|f| f.trim().to_string()).filter(|f| !f.is_empty()).collect());
        }
    }
    blocks
}

/// The constants of one layer, in Pa, kg/m^3 and degrees.
#[derive(Debug, Default, Clone, Copy)]
struct Constants {
    c: f64,
    bulk: f64,
    k1: f64,
    k2: f64,
    kappa: f64,
    gamma_deg: f64,
    density: f64,
}

fn f(s: &str) -> f64 {
    s.parse().unwrap_or_else(|_| panic!("not a number: {s}"))
}

/// CalculiX ELASTIC_FIBER materials: C10, D1, (x, y, k1, k2) x 2, density; deck units -> SI.
fn calculix_constants(text: &str, u: MechanicalUnits) -> BTreeMap<String, Constants> {
    let (pa, kg_m3) = (1.0 / u.stress(1.0), 1.0 / u.density(1.0));
    let blocks = inp_blocks(text);
    let mut out = BTreeMap::new();
    for (i, (kw, _)) in blocks.iter().enumerate() {
        let Some(name) = kw.strip_prefix("MATERIAL, NAME=ELASTIC_FIBER_") else { continue };
        let user = &blocks[i + 1];
        assert!(user.0.starts_with("USER MATERIAL, CONSTANTS=10"), "{}", user.0);
        let v: Vec<f64> = user.1.iter().flatten().map(|s| f(s)).collect();
        assert_eq!(v.len(), 10);
        // the two families: same k1, k2, mirrored about the circumferential axis
        assert_eq!((v[4], v[5]), (v[8], v[9]));
        assert_eq!((v[2], v[3]), (v[6], -v[7]));
        let density = &blocks[i + 2];
        assert_eq!(density.0, "DENSITY");
        out.insert(
            name.to_ascii_lowercase(),
            Constants {
                c: 2.0 * v[0] * pa,
                bulk: 2.0 / v[1] * pa,
                k1: v[4] * pa,
                k2: v[5],
                kappa: 0.0,
                gamma_deg: v[3].atan2(v[2]).to_degrees(),
                density: f(&density.1[0][0]) * kg_m3,
            },
        );
    }
    out
}

/// Abaqus HOLZAPFEL materials (C10, D, k1, k2, kappa) and the fibre directions of the layer's
/// orientation (LOCAL DIRECTIONS=2); deck units -> SI.
fn abaqus_constants(text: &str, u: MechanicalUnits) -> BTreeMap<String, Constants> {
    let (pa, kg_m3) = (1.0 / u.stress(1.0), 1.0 / u.density(1.0));
    let blocks = inp_blocks(text);
    let mut out = BTreeMap::new();
    for (i, (kw, _)) in blocks.iter().enumerate() {
        let Some(name) = kw.strip_prefix("MATERIAL, NAME=HGO_") else { continue };
        let hgo = &blocks[i + 1];
        assert!(hgo.0.starts_with("ANISOTROPIC HYPERELASTIC, HOLZAPFEL"), "{}", hgo.0);
        let v: Vec<f64> = hgo.1[0].iter().map(|s| f(s)).collect();
        let orientation = blocks
            .iter()
            .find(|(k, _)| k.starts_with(&format!("ORIENTATION, NAME=ORI_{name},")))
            .unwrap_or_else(|| panic!("no orientation of {name}"));
        let fibre = &orientation.1[2];
        out.insert(
            name.to_ascii_lowercase(),
            Constants {
                c: 2.0 * v[0] * pa,
                bulk: 2.0 / v[1] * pa,
                k1: v[2] * pa,
                k2: v[3],
                kappa: v[4],
                gamma_deg: f(&fibre[1]).atan2(f(&fibre[0])).to_degrees(),
                density: f(&blocks[i + 2].1[0][0]) * kg_m3,
            },
        );
    }
    out
}

/// FEBio Holzapfel-Gasser-Ogden materials (c, k1, k2, kappa, gamma, k, density); deck units -> SI.
fn febio_constants(text: &str, u: MechanicalUnits) -> BTreeMap<String, Constants> {
    let (pa, kg_m3) = (1.0 / u.stress(1.0), 1.0 / u.density(1.0));
    let mut reader = quick_xml::Reader::from_str(text);
    let mut out: BTreeMap<String, Constants> = BTreeMap::new();
    let (mut material, mut tag) = (None::<String>, String::new());
    loop {
        match reader.read_event().unwrap() {
            Event::Start(e) => {
                let name = e.name().as_ref().to_string();
                if name == "material" && attr(&e, "type").as_deref() == Some("Holzapfel-Gasser-Ogden") {
                    material = attr(&e, "name");
                }
                tag = name;
            }
            Event::Text(t) if material.is_some() => {
                let text = t.xml10_content().trim().to_string();
                if text.is_empty() {
                    continue;
                }
                let c = out.entry(material.clone().unwrap()).or_default();
                let v = f(&text);
                match tag.as_str() {
                    "c" => c.c = v * pa,
                    "k1" => c.k1 = v * pa,
                    "k2" => c.k2 = v,
                    "kappa" => c.kappa = v,
                    "gamma" => c.gamma_deg = v,
                    "k" => c.bulk = v * pa,
                    "density" => c.density = v * kg_m3,
                    other => panic!("unexpected HGO parameter {other}"),
                }
            }
            Event::End(e) if e.name().as_ref() == "material" => material = None,
            Event::Eof => break,
            _ => {}
        }
    }
    out
}

/// The CalculiX, Abaqus and FEBio decks, written in different units, carry the same wall
/// constants for every layer (after unit conversion), namely `[material]`'s, with the layer's
/// fibre angle; and a kappa CalculiX cannot represent is refused rather than dropped.
#[test]
fn all_decks_carry_the_same_material_constants() {
    let meshed = vesselhex::testing::straight_tube_mesh(&MeshConfig::preset(Preset::Coarse)).unwrap();
    let mesh = &meshed.mesh;
    let dir = std::env::temp_dir().join(format!("vesselhex-cross-material-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut options = WriteOptions::default();
    // a non-default set, different per layer, so that a deck reading the wrong layer or an old
    // default fails
    options.material.intima.c_kpa = 41.0;
    options.material.intima.k1_kpa = 12.5;
    options.material.media.k2 = 1.7;
    options.material.media.bulk_kpa = 5123.0;
    options.material.adventitia.density_kg_m3 = 1100.0;
    let read = |options: &WriteOptions, unit: LengthUnit| {
        let mut o = options.clone();
        o.length_unit = unit;
        o
    };
    let (ccx_unit, abq_unit, feb_unit) = (LengthUnit::Mm, LengthUnit::Cm, LengthUnit::M);
    let ccx_files = calculix::write_calculix(mesh, &read(&options, ccx_unit), &dir).unwrap();
    let abq_files = abaqus::write_abaqus(mesh, &read(&options, abq_unit), &dir).unwrap();
    let feb_files = febio::write_wall(mesh, &read(&options, feb_unit), &dir).unwrap();
    let text = |f: &std::path::PathBuf| std::fs::read_to_string(dir.join(f)).unwrap();
    let ccx = calculix_constants(&text(&ccx_files[0]), MechanicalUnits::of(ccx_unit));
    let abq = abaqus_constants(&text(&abq_files[0]), MechanicalUnits::of(abq_unit));
    let feb = febio_constants(&text(&feb_files[0]), MechanicalUnits::of(feb_unit));
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs().max(1e-300);
    for region in Region::WALL {
        let layer = region.name();
        let want = options.material.layer(region);
        let beta = mesh.layers.iter().find(|l| l.region == region).unwrap().fibre_angle_deg;
        let (c, a, b) = (ccx[layer], abq[layer], feb[layer]);
        eprintln!("{layer}: calculix {c:?}\n  abaqus {a:?}\n  febio {b:?}");
        for (deck, x) in [("calculix", c), ("abaqus", a), ("febio", b)] {
            assert!(close(x.c, want.c_kpa * 1e3), "{deck} {layer}: c {} Pa", x.c);
            assert!(close(x.k1, want.k1_kpa * 1e3), "{deck} {layer}: k1 {} Pa", x.k1);
            assert!(close(x.k2, want.k2), "{deck} {layer}: k2 {}", x.k2);
            assert!(close(x.bulk, want.bulk_kpa * 1e3), "{deck} {layer}: K {} Pa", x.bulk);
            assert!(close(x.density, want.density_kg_m3), "{deck} {layer}: density {}", x.density);
            assert_eq!(x.kappa, want.kappa, "{deck} {layer}: kappa");
            assert!((x.gamma_deg - beta).abs() < 1e-9, "{deck} {layer}: fibre angle {} vs {beta}", x.gamma_deg);
        }
    }
    // the documented default: HGO 2000 with c and k1 x 100, the intima as the media
    let d = WallMaterial::default();
    assert_eq!((d.media.c_kpa, d.media.k1_kpa, d.media.k2), (300.0, 236.32, 0.8393));
    assert_eq!((d.adventitia.c_kpa, d.adventitia.k1_kpa, d.adventitia.k2), (30.0, 56.2, 0.7112));
    assert_eq!(d.intima, d.media);
    // dispersion: Abaqus and FEBio write it, CalculiX refuses it with the key
    options.material.media.kappa = 0.1;
    let e = calculix::write_calculix(mesh, &options, &dir).unwrap_err().to_string();
    assert!(e.contains("material.media.kappa"), "{e}");
    abaqus::write_abaqus(mesh, &options, &dir).unwrap();
    febio::write_wall(mesh, &options, &dir).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// The per-layer tables that [fe] and [febio] had are refused with the new key.
#[test]
fn removed_material_keys_name_the_new_section() {
    let dir = std::env::temp_dir().join(format!("vesselhex-cross-keys-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let case = dir.join("case.toml");
    for (text, key) in
        [("[fe.media]\nc10 = 0.02\n", "[fe.media]"), ("[febio.adventitia]\nk2 = 0.7\n", "[febio.adventitia]")]
    {
        std::fs::write(&case, text).unwrap();
        let e = MeshConfig::from_case_file(&case, None).unwrap_err().to_string();
        assert!(e.contains(key) && e.contains("[material.") && e.contains("case.toml"), "{e}");
    }
    std::fs::write(&case, "[material.media]\nk1_kpa = 50.0\n").unwrap();
    let c = MeshConfig::from_case_file(&case, None).unwrap();
    assert_eq!(c.material.media.k1_kpa, 50.0);
    assert_eq!(c.material.media.c_kpa, WallMaterial::default().media.c_kpa, "the rest keeps the default");
    let _ = std::fs::remove_dir_all(&dir);
}
