//! The Abaqus deck, checked structurally (no Abaqus here) and read back by meshio.
//!
//! Without meshio the read-back prints "skipped" and passes, unless `CI=true`, where it fails.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::PathBuf;
use std::process::Command;
use vesselhex::config::MeshConfig;
use vesselhex::mesh::VesselMesh;
use vesselhex::testing::straight_tube_mesh;
use vesselhex::units::LengthUnit;
use vesselhex::writers::inp::ElementType;
use vesselhex::writers::{abaqus::write_abaqus, WriteOptions};

fn tube() -> VesselMesh {
    let mut c = MeshConfig::default();
    c.lumen.core_elements = 4;
    c.lumen.radial_elements = 2;
    c.lumen.axial_spacing_mm = Some(2.0);
    c.wall.thickness_mm = Some(0.4);
    c.wall.media.elements = 2;
    straight_tube_mesh(&c).expect("tube meshes").mesh
}

fn write(mesh: &VesselMesh, options: &WriteOptions, name: &str) -> (PathBuf, String) {
    let dir = std::env::temp_dir().join(format!("vesselhex-abaqus-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let files = write_abaqus(mesh, options, &dir).unwrap();
    assert_eq!(files, vec![PathBuf::from("abaqus/model.inp")]);
    let path = dir.join("abaqus/model.inp");
    let text = std::fs::read_to_string(&path).unwrap();
    (path, text)
}

/// A keyword block: the keyword line's parameters and its data lines (records joined across
/// continuation lines).
struct Block {
    keyword: String,
    params: BTreeMap<String, String>,
    records: Vec<Vec<String>>,
}

fn parse(text: &str) -> Vec<Block> {
    let mut blocks: Vec<Block> = Vec::new();
    let mut pending: Vec<String> = Vec::new();
    for line in text.lines() {
        if line.starts_with("**") {
            continue;
        }
        if let Some(k) = line.strip_prefix('*') {
            let mut parts = k.split(',');
            let keyword = parts.next().unwrap().trim().to_uppercase();
            let params = parts
                .map(|p| {
                    let mut kv = p.splitn(2, '=');
                    (kv.next().unwrap().trim().to_uppercase(), kv.next().unwrap_or("").trim().to_string())
                })
                .collect();
            blocks.push(Block { keyword, params, records: Vec::new() });
            continue;
        }
        let b = blocks.last_mut().expect("data before any keyword");
        let fields: Vec<String> = line.split(',').map(|f| f.trim().to_string()).collect();
        assert!(fields.len() <= 17, "more than 16 entries: {line}");
        let continues = line.trim_end().ends_with(',') && b.keyword == "ELEMENT";
        pending.extend(fields.into_iter().filter(|f| !(continues && f.is_empty())));
        if !continues {
            b.records.push(std::mem::take(&mut pending));
        }
    }
    blocks
}

fn pressure(text: &str) -> f64 {
    let key = "WALL_LUMEN, P, ";
    let i = text.find(key).unwrap() + key.len();
    text[i..].lines().next().unwrap().trim().parse().unwrap()
}

fn check_structure(text: &str, mesh: &VesselMesh, element: ElementType) {
    let blocks = parse(text);
    let mut nodes: BTreeSet<u64> = BTreeSet::new();
    let mut elements: BTreeSet<u64> = BTreeSet::new();
    let mut elsets: HashMap<String, BTreeSet<u64>> = HashMap::new();
    let mut nsets: HashMap<String, BTreeSet<u64>> = HashMap::new();
    let mut distributions: HashMap<String, BTreeSet<u64>> = HashMap::new();
    let mut surfaces = BTreeSet::new();
    let mut orientations = BTreeSet::new();
    let nodes_per_element = if element == ElementType::C3D20H { 20 } else { 8 };
    for b in &blocks {
        let name = |key: &str| b.params.get(key).cloned().unwrap_or_else(|| panic!("*{} without {key}", b.keyword));
        for v in b.params.values() {
            assert!(v.len() <= 80 && !v.contains(','), "{v}");
        }
        match b.keyword.as_str() {
            "NODE" => {
                for r in &b.records {
                    assert_eq!(r.len(), 4);
                    assert!(nodes.insert(r[0].parse().unwrap()), "node {} twice", r[0]);
                }
            }
            "ELEMENT" => {
                assert_eq!(name("TYPE"), element.name());
                let set = elsets.entry(name("ELSET")).or_default();
                for r in &b.records {
                    assert_eq!(r.len(), 1 + nodes_per_element, "{r:?}");
                    let label: u64 = r[0].parse().unwrap();
                    assert!(elements.insert(label));
                    set.insert(label);
                    for n in &r[1..] {
                        assert!(nodes.contains(&n.parse().unwrap()), "element {label}: node {n} not defined");
                    }
                }
            }
            "ELSET" => {
                let r = &b.records[0];
                assert!(b.params.contains_key("GENERATE"));
                let (a, z): (u64, u64) = (r[0].parse().unwrap(), r[1].parse().unwrap());
                let set: BTreeSet<u64> = (a..=z).collect();
                assert!(set.is_subset(&elements), "ELSET {} refers to undefined elements", name("ELSET"));
                elsets.insert(name("ELSET"), set);
            }
            "NSET" => {
                let set: BTreeSet<u64> =
                    b.records.iter().flatten().filter(|f| !f.is_empty()).map(|f| f.parse().unwrap()).collect();
                assert!(set.is_subset(&nodes), "NSET {} refers to undefined nodes", name("NSET"));
                nsets.insert(name("NSET"), set);
            }
            "SURFACE" => {
                assert_eq!(name("TYPE"), "ELEMENT");
                for r in &b.records {
                    assert!(elements.contains(&r[0].parse().unwrap()), "SURFACE {}: element {}", name("NAME"), r[0]);
                    assert!(["S1", "S2", "S3", "S4", "S5", "S6"].contains(&r[1].as_str()));
                }
                surfaces.insert(name("NAME"));
            }
            "DISTRIBUTION" => {
                assert_eq!(name("LOCATION"), "ELEMENT");
                assert_eq!(b.records[0][0], "", "first line must be the default");
                let mut set = BTreeSet::new();
                for r in &b.records[1..] {
                    let label: u64 = r[0].parse().unwrap();
                    assert!(elements.contains(&label), "DISTRIBUTION {}: element {label}", name("NAME"));
                    let v: Vec<f64> = r[1..].iter().map(|f| f.parse().unwrap()).collect();
                    assert_eq!(v.len(), 6);
                    let (a, c) = (nalgebra::Vector3::new(v[0], v[1], v[2]), nalgebra::Vector3::new(v[3], v[4], v[5]));
                    assert!((a.norm() - 1.0).abs() < 1e-9 && (c.norm() - 1.0).abs() < 1e-9 && a.dot(&c).abs() < 1e-9);
                    // local 1 = e_circ, local 2 = e_long of that element.
                    let t = mesh.triads[label as usize - 1];
                    assert!((a - t.e_circ).norm() < 1e-9 && (c - t.e_long).norm() < 1e-9);
                    set.insert(label);
                }
                distributions.insert(name("NAME"), set);
            }
            "ORIENTATION" => {
                assert_eq!(name("LOCAL DIRECTIONS"), "2");
                assert!(distributions.contains_key(&b.records[0][0]), "ORIENTATION refers to {}", b.records[0][0]);
                assert_eq!(b.records[1], vec!["3", "0."]);
                assert_eq!(b.records.len(), 4);
                for r in &b.records[2..] {
                    let v: Vec<f64> = r.iter().map(|f| f.parse().unwrap()).collect();
                    assert_eq!(v[2], 0.0, "local direction out of the 1-2 plane");
                    assert!((v[0].hypot(v[1]) - 1.0).abs() < 1e-12, "local direction not a unit vector");
                }
                orientations.insert(name("NAME"));
            }
            "SOLID SECTION" => {
                assert!(elsets.contains_key(&name("ELSET")));
                assert!(orientations.contains(&name("ORIENTATION")));
            }
            "MATERIAL" => assert!(name("NAME").starts_with("HGO_")),
            "ANISOTROPIC HYPERELASTIC" => {
                assert!(b.params.contains_key("HOLZAPFEL"));
                assert_eq!(name("LOCAL DIRECTIONS"), "2");
                assert_eq!(b.records[0].len(), 5);
            }
            "BOUNDARY" | "TRANSFORM" => {
                let set = b.params.get("NSET").cloned().unwrap_or_else(|| b.records[0][0].clone());
                if b.keyword == "BOUNDARY" {
                    for r in &b.records {
                        assert!(nsets.contains_key(&r[0]), "BOUNDARY on unknown set {}", r[0]);
                    }
                } else {
                    assert!(nsets.contains_key(&set));
                }
            }
            "DSLOAD" => {
                assert!(surfaces.contains(&b.records[0][0]));
                assert_eq!(b.records[0][1], "P");
            }
            "NODE PRINT" => assert!(nsets.contains_key(&name("NSET"))),
            _ => {}
        }
    }
    // Every wall element in exactly one distribution; the layers partition the wall.
    let wall: BTreeSet<u64> = mesh.wall_range().map(|e| e as u64 + 1).collect();
    assert_eq!(elements, wall);
    let mut seen = BTreeSet::new();
    for set in distributions.values() {
        for e in set {
            assert!(seen.insert(*e), "element {e} in two distributions");
        }
    }
    assert_eq!(seen, wall, "not every wall element has a distribution");
    assert_eq!(elsets["WALL"], wall);
    for s in ["WALL_INLET", "WALL_OUTLET", "LUMEN_WALL_INTERFACE", "OUTER_WALL", "LUMEN_RING"] {
        assert!(nsets.contains_key(s), "no NSET {s}");
    }
    for s in ["WALL_LUMEN", "WALL_OUTER", "WALL_INLET", "WALL_OUTLET"] {
        assert!(surfaces.contains(s), "no SURFACE {s}");
    }
    assert_eq!(orientations.len(), 3);
}

#[test]
fn abaqus_deck_is_consistent() {
    let mesh = tube();
    let options = WriteOptions::default();
    let (_, text) = write(&mesh, &options, "c3d8h");
    assert!(text.contains("*ANISOTROPIC HYPERELASTIC, HOLZAPFEL, LOCAL DIRECTIONS=2"));
    assert!(text.contains("*DISTRIBUTION TABLE, NAME=TRIAD_TABLE\nCOORD3D, COORD3D\n"));
    assert!(text.contains("*STEP, NAME=INFLATION, NLGEOM=YES"));
    assert!((pressure(&text) - 0.0133322).abs() < 1e-12, "100 mmHg in MPa");
    check_structure(&text, &mesh, ElementType::C3D8H);
    // Byte-identical when written again.
    let (_, again) = write(&mesh, &options, "c3d8h-again");
    assert!(text == again);
}

#[test]
fn quadratic_abaqus_deck_is_consistent() {
    let mesh = tube();
    let mut options = WriteOptions::default();
    options.fe.abaqus_element = ElementType::C3D20H;
    let (_, text) = write(&mesh, &options, "c3d20h");
    check_structure(&text, &mesh, ElementType::C3D20H);
    // Mid-edge nodes are labelled after every corner node and sit at edge midpoints.
    let first_mid = mesh.nodes.len() as u64 + 1;
    assert!(text.contains(&format!("\n{first_mid}, ")));
}

#[test]
fn metres_scale_lengths_and_stresses_together() {
    let mesh = tube();
    let mut options = WriteOptions { length_unit: LengthUnit::M, ..Default::default() };
    options.fe.pressure_mmhg = 100.0;
    let (_, text) = write(&mesh, &options, "metres");
    assert!(text.contains("Units: length m, force N, stress Pa, mass kg"));
    assert!((pressure(&text) - 13332.2).abs() < 1e-8, "100 mmHg in Pa");
    // C10 of the media: c / 2 of the default, in Pa; density 1200 kg/m^3.
    let c10_pa = 0.5 * options.material.media.c_kpa * 1e3;
    let after = |key: &str| -> f64 {
        let i = text.find(key).unwrap() + key.len();
        text[i..].split([',', '\n']).next().unwrap().trim().parse().unwrap()
    };
    assert!(
        (after("*MATERIAL, NAME=HGO_MEDIA\n*ANISOTROPIC HYPERELASTIC, HOLZAPFEL, LOCAL DIRECTIONS=2\n") - c10_pa).abs()
            < 1e-6
    );
    assert!((after("*DENSITY\n") - 1200.0).abs() < 1e-9);
    // A node of the tube (r = 2 mm) is at about 0.002 m.
    let p = mesh.nodes[mesh.nodes_of(mesh.wall_range())[0] as usize];
    assert!(text.contains(&format!("{:.12e}", p.x * 1e-3)));
}

#[test]
fn meshio_reads_the_abaqus_deck() {
    let mesh = tube();
    let (path, _) = write(&mesh, &WriteOptions::default(), "meshio");
    let script = "import sys, meshio\n\
m = meshio.read(sys.argv[1], file_format='abaqus')\n\
print(sum(len(c.data) for c in m.cells))\n\
print(' '.join(sorted(m.point_sets)))\n\
print(' '.join(sorted(m.cell_sets)))\n\
print(len(m.points))\n";
    let out = match Command::new("python3").args(["-c", script, path.to_str().unwrap()]).output() {
        Ok(o) => o,
        Err(e) => {
            assert!(std::env::var("CI").map(|v| v != "true").unwrap_or(true), "python3 missing and CI=true: {e}");
            eprintln!("skipped: no python3");
            return;
        }
    };
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() && stderr.contains("No module named 'meshio'") {
        assert!(
            std::env::var("CI").map(|v| v != "true").unwrap_or(true),
            "meshio missing and CI=true: pip install meshio"
        );
        eprintln!("skipped: meshio is not installed");
        return;
    }
    assert!(out.status.success(), "meshio failed: {stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines[0].parse::<usize>().unwrap(), mesh.wall_range().len());
    for s in ["LUMEN_RING", "LUMEN_WALL_INTERFACE", "OUTER_WALL", "WALL_INLET", "WALL_OUTLET"] {
        assert!(lines[1].split(' ').any(|x| x == s), "point set {s} missing: {}", lines[1]);
    }
    for s in ["ADVENTITIA", "INTIMA", "MEDIA", "WALL"] {
        assert!(lines[2].split(' ').any(|x| x == s), "cell set {s} missing: {}", lines[2]);
    }
    assert_eq!(lines[3].parse::<usize>().unwrap(), mesh.nodes_of(mesh.wall_range()).len());
}
