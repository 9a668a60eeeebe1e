//! The same wall in the CalculiX deck and in the FEBio deck: same nodes (labels and
//! coordinates), same elements per layer (labels and connectivity), same end-ring and interface
//! node sets, and the same material axes (CalculiX *DISTRIBUTION a, b = FEBio mat_axis a, d).

use quick_xml::events::Event;
use std::collections::{BTreeMap, BTreeSet};
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::writers::{calculix, febio, WriteOptions};

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
    for line in text.lines() {
        if line.starts_with("**") {
            continue;
        }
        if let Some(kw) = line.strip_prefix('*') {
            let name = kw.split(',').next().unwrap().trim().to_ascii_uppercase();
            let arg = match name.as_str() {
                "ELEMENT" => param(line, "ELSET").unwrap_or("").to_ascii_lowercase(),
                "NSET" => format!("{}{}", param(line, "NSET").unwrap().to_ascii_lowercase(), if line.to_ascii_uppercase().contains("GENERATE") { "#gen" } else { "" }),
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
                let v = numbers(line);
                m.elements.entry(block.1.clone()).or_default().insert(v[0] as u32, v[1..].iter().map(|x| *x as u32).collect());
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
    e.attributes().flatten().find(|a| a.key.as_ref() == key).map(|a| {
        a.normalized_value(quick_xml::XmlVersion::Explicit1_0).unwrap().into_owned()
    })
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
                        m.elements.entry(layer.clone()).or_default().insert(id, numbers(&text).iter().map(|x| *x as u32).collect());
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
        assert_eq!(ccx.elements[layer].len(), mesh.count(mesh.layers.iter().find(|l| l.region.name() == layer).unwrap().region));
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
