//! The FSI coupling package: the interface map read back against the written OpenFOAM and
//! CalculiX files, the preCICE names cross-checked between the configuration files, the
//! preCICE config checker (PyPI `precice-config-check`) and the FSI deck in the real `ccx`.
//!
//! External programs missing: "skipped" outside CI, failure under `CI=true`.

mod common;

use common::{fixture, mesh_cli, temp_dir, under_ci};
use nalgebra::{Point3, Vector3};
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::process::Command;
use vesselhex::config::MeshConfig;
use vesselhex::mesh::{face_nodes, quad_area_vector, VesselMesh};
use vesselhex::testing::straight_tube_mesh;
use vesselhex::units::LengthUnit;
use vesselhex::writers::inp::ElementType;
use vesselhex::writers::openfoam::read_polymesh;
use vesselhex::writers::{calculix, fsi, openfoam, WriteOptions};

fn tube() -> VesselMesh {
    let mut c = MeshConfig::default();
    c.lumen.core_elements = 2;
    c.lumen.radial_elements = 2;
    c.lumen.axial_spacing_mm = Some(3.0);
    c.wall.thickness_mm = Some(0.6);
    c.wall.intima.elements = 1;
    c.wall.media.elements = 1;
    c.wall.adventitia.elements = 1;
    straight_tube_mesh(&c).expect("tube meshes").mesh
}

/// Writes openfoam, calculix and fsi for `mesh` in `unit` under a fresh folder.
fn write_all(mesh: &VesselMesh, unit: LengthUnit, tag: &str) -> (PathBuf, WriteOptions) {
    let dir = temp_dir(&format!("fsi-{tag}"));
    let options = WriteOptions { length_unit: unit, ..Default::default() };
    openfoam::write_openfoam(mesh, &options, &dir).unwrap();
    calculix::write_calculix(mesh, &options, &dir).unwrap();
    let files = fsi::write_fsi(mesh, &options, &dir).unwrap();
    for f in &files {
        assert!(dir.join(f).is_file(), "{} listed but missing", f.display());
    }
    (dir, options)
}

fn csv_rows(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    (header, lines.map(|l| l.split(',').map(String::from).collect()).collect())
}

/// An .inp deck read back: nodes, elements (label -> 8 corner labels), node sets.
struct Deck {
    nodes: HashMap<u64, Point3<f64>>,
    elements: HashMap<u64, Vec<u64>>,
    nsets: HashMap<String, Vec<u64>>,
}

fn read_deck(path: &Path) -> Deck {
    let text = std::fs::read_to_string(path).unwrap();
    let (mut nodes, mut elements, mut nsets) = (HashMap::new(), HashMap::new(), HashMap::<String, Vec<u64>>::new());
    let mut section = String::new();
    let mut pending: Vec<u64> = vec![];
    for line in text.lines() {
        if line.starts_with("**") {
            continue;
        }
        if let Some(card) = line.strip_prefix('*') {
            let upper = card.to_ascii_uppercase();
            section = if upper.starts_with("NODE") && !upper.starts_with("NODE ") {
                "node".into()
            } else if upper.starts_with("ELEMENT") {
                "element".into()
            } else if let Some(rest) = upper.strip_prefix("NSET, NSET=") {
                nsets.entry(rest.trim().to_string()).or_default();
                format!("nset:{}", rest.trim())
            } else {
                String::new()
            };
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).filter(|s| !s.is_empty()).collect();
        match section.as_str() {
            "node" => {
                let v: Vec<f64> = fields[1..].iter().map(|s| s.parse().unwrap()).collect();
                nodes.insert(fields[0].parse().unwrap(), Point3::new(v[0], v[1], v[2]));
            }
            "element" => {
                pending.extend(fields.iter().map(|s| s.parse::<u64>().unwrap()));
                if !line.trim_end().ends_with(',') {
                    elements.insert(pending[0], pending[1..].to_vec());
                    pending.clear();
                }
            }
            s if s.starts_with("nset:") => {
                nsets.get_mut(&s[5..]).unwrap().extend(fields.iter().map(|s| s.parse::<u64>().unwrap()));
            }
            _ => {}
        }
    }
    Deck { nodes, elements, nsets }
}

/// The canonical face table in 0-based corner positions (S{f+1} = row f).
fn solid_face_corners(deck: &Deck, element: u64, label: &str) -> [u64; 4] {
    let f: usize = label.strip_prefix('S').unwrap().parse::<usize>().unwrap() - 1;
    let corners = &deck.elements[&element];
    let hex: [u32; 8] = std::array::from_fn(|i| corners[i] as u32);
    face_nodes(&hex, f).map(|n| n as u64)
}

fn check_map(mesh: &VesselMesh, unit: LengthUnit, tag: &str) {
    let (dir, _) = write_all(mesh, unit, tag);
    let to_m = unit.in_metres();
    let poly = read_polymesh(&dir.join("openfoam")).unwrap();
    let deck = read_deck(&dir.join("calculix/model.inp"));
    let size = mesh.nodes.iter().fold(0.0f64, |a, p| a.max(p.coords.amax())) * unit.from_mm();

    // interface_nodes.csv against the OpenFOAM points (m) and the CalculiX nodes (FE unit).
    let (header, rows) = csv_rows(&dir.join("fsi/interface_nodes.csv"));
    assert_eq!(header, ["fluid_point", "solid_node", "x", "y", "z"]);
    let mut worst = 0.0f64;
    let mut fluid_col = BTreeSet::new();
    let mut solid_col = BTreeSet::new();
    for r in &rows {
        let fp: usize = r[0].parse().unwrap();
        let sn: u64 = r[1].parse().unwrap();
        let x = Point3::new(r[2].parse::<f64>().unwrap(), r[3].parse().unwrap(), r[4].parse().unwrap());
        assert!(fluid_col.insert(fp), "fluid point {fp} twice");
        assert!(solid_col.insert(sn), "solid node {sn} twice");
        worst = worst.max((poly.points[fp] / to_m - x).norm());
        worst = worst.max((deck.nodes[&sn] - x).norm());
    }
    eprintln!(
        "{tag}: {} interface nodes, max coordinate mismatch {worst:.3e} {} (model size {size:.3e})",
        rows.len(),
        unit.name()
    );
    assert!(worst <= 1e-9 * size, "{tag}: mismatch {worst:e}");

    // The wall patch points and the solid interface NSET are exactly the two columns.
    let wall = poly.patch("wall").unwrap();
    let patch_points: BTreeSet<usize> = wall.range().flat_map(|f| poly.faces[f]).map(|p| p as usize).collect();
    assert_eq!(patch_points, fluid_col, "{tag}: wall patch points");
    let nset: BTreeSet<u64> = deck.nsets["LUMEN_WALL_INTERFACE"].iter().copied().collect();
    assert_eq!(nset, solid_col, "{tag}: LUMEN_WALL_INTERFACE");
    let fsi_deck = read_deck(&dir.join("fsi/calculix/fsi.inp"));
    let n_patch: BTreeSet<u64> = fsi_deck.nsets["NLUMEN_WALL"].iter().copied().collect();
    assert_eq!(n_patch, solid_col, "{tag}: NLUMEN_WALL");
    let pair: HashMap<usize, u64> = rows.iter().map(|r| (r[0].parse().unwrap(), r[1].parse().unwrap())).collect();

    // Every wall face once, its solid face on the same four points, equal total areas.
    let (header, rows) = csv_rows(&dir.join("fsi/interface_faces.csv"));
    assert_eq!(header, ["patch_face", "face", "solid_element", "solid_face", "area"]);
    assert_eq!(rows.len(), wall.size);
    let mut seen = BTreeSet::new();
    let (mut fluid_area, mut solid_area, mut listed_area) = (0.0, 0.0, 0.0);
    for r in &rows {
        let k: usize = r[0].parse().unwrap();
        let face: usize = r[1].parse().unwrap();
        assert_eq!(face, wall.start + k);
        assert!(seen.insert(face), "face {face} twice");
        let solid = solid_face_corners(&deck, r[2].parse().unwrap(), &r[3]);
        let mut a: Vec<u64> = poly.faces[face].iter().map(|p| pair[&(*p as usize)]).collect();
        let mut b = solid.to_vec();
        a.sort_unstable();
        b.sort_unstable();
        assert_eq!(a, b, "{tag}: face {face} vs {} {}", r[2], r[3]);
        // Opposite orientation: the fluid face points into the wall, the solid face into the lumen.
        let fa = poly.face_area(face) / (to_m * to_m);
        let sa = quad_area_vector(solid.map(|n| deck.nodes[&n]));
        assert!(fa.dot(&sa) < 0.0);
        fluid_area += fa.norm();
        solid_area += sa.norm();
        listed_area += r[4].parse::<f64>().unwrap();
    }
    let rel = |a: f64, b: f64| ((a - b) / b).abs();
    eprintln!(
        "{tag}: {} faces, area fluid {fluid_area:.12e} solid {solid_area:.12e} listed {listed_area:.12e} {}^2 (rel. diff {:.2e}, {:.2e})",
        rows.len(),
        unit.name(),
        rel(fluid_area, solid_area),
        rel(listed_area, solid_area)
    );
    assert!(rel(fluid_area, solid_area) < 1e-9 && rel(listed_area, solid_area) < 1e-9);

    // Force lumping: four nodes of each face, weight 1/4.
    let (header, rows) = csv_rows(&dir.join("fsi/force_lumping.csv"));
    assert_eq!(header, ["patch_face", "solid_node", "weight"]);
    assert_eq!(rows.len(), 4 * wall.size);
    let mut per_face: BTreeMap<usize, (BTreeSet<u64>, f64)> = BTreeMap::new();
    for r in &rows {
        let e = per_face.entry(r[0].parse().unwrap()).or_default();
        e.0.insert(r[1].parse().unwrap());
        e.1 += r[2].parse::<f64>().unwrap();
    }
    for (k, (nodes, w)) in per_face {
        let f = wall.start + k;
        let expected: BTreeSet<u64> = poly.faces[f].iter().map(|p| pair[&(*p as usize)]).collect();
        assert_eq!(nodes, expected);
        assert_eq!(w, 1.0);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn interface_map_matches_the_written_meshes_in_mm_and_m() {
    let mesh = tube();
    check_map(&mesh, LengthUnit::Mm, "mm");
    check_map(&mesh, LengthUnit::M, "m");
    check_map(&mesh, LengthUnit::Cm, "cm");
}

#[test]
fn interface_map_of_the_curved_fixture() {
    let (stl, csv) = fixture("curved");
    let mesh = common::mesh_files(&stl, &csv, &MeshConfig::default());
    check_map(&mesh, LengthUnit::Mm, "curved");
}

// ---------------------------------------------------------------------------------------------
// preCICE names

/// Names in precice-config.xml: data, meshes, participants and what each participant does.
#[derive(Default, Debug)]
struct PreciceNames {
    data: BTreeSet<String>,
    meshes: BTreeMap<String, BTreeSet<String>>,
    participants: BTreeMap<String, Vec<(String, String, String)>>,
    exchanges: Vec<(String, String, String, String)>,
}

fn parse_precice(path: &Path) -> PreciceNames {
    use quick_xml::events::Event;
    let text = std::fs::read_to_string(path).unwrap();
    let mut reader = quick_xml::Reader::from_str(&text);
    let mut names = PreciceNames::default();
    let (mut mesh, mut participant) = (None::<String>, None::<String>);
    let mut depth = 0i32;
    loop {
        let ev = reader.read_event().unwrap_or_else(|e| panic!("precice-config.xml is not well-formed: {e}"));
        let (start, empty) = match &ev {
            Event::Start(s) => (Some(s.clone()), false),
            Event::Empty(s) => (Some(s.clone()), true),
            Event::End(e) => {
                depth -= 1;
                let n = e.name().as_ref().to_string();
                if n == "mesh" {
                    mesh = None;
                } else if n == "participant" {
                    participant = None;
                }
                continue;
            }
            Event::Eof => break,
            _ => continue,
        };
        let s = start.unwrap();
        if !empty {
            depth += 1;
        }
        let tag = s.name().as_ref().to_string();
        let attrs: HashMap<String, String> = s
            .attributes()
            .map(|a| {
                let a = a.unwrap();
                (
                    a.key.as_ref().to_string(),
                    a.normalized_value(quick_xml::XmlVersion::Explicit1_0).unwrap().into_owned(),
                )
            })
            .collect();
        let attr = |k: &str| attrs.get(k).cloned().unwrap_or_default();
        match tag.as_str() {
            t if t.starts_with("data:") => {
                names.data.insert(attr("name"));
            }
            "mesh" => {
                names.meshes.insert(attr("name"), BTreeSet::new());
                if !empty {
                    mesh = Some(attr("name"));
                }
            }
            "use-data" => {
                names.meshes.get_mut(mesh.as_ref().unwrap()).unwrap().insert(attr("name"));
            }
            "participant" => {
                names.participants.insert(attr("name"), vec![]);
                participant = Some(attr("name"));
            }
            "provide-mesh" | "receive-mesh" | "write-data" | "read-data" => {
                let p = participant.as_ref().unwrap();
                let what =
                    if tag.ends_with("mesh") { attr("name") } else { format!("{}@{}", attr("name"), attr("mesh")) };
                names.participants.get_mut(p).unwrap().push((tag.clone(), what, attr("from")));
            }
            t if t.starts_with("mapping:") => {
                let p = participant.as_ref().unwrap();
                names.participants.get_mut(p).unwrap().push((
                    format!("{t}:{}:{}", attr("direction"), attr("constraint")),
                    format!("{}->{}", attr("from"), attr("to")),
                    String::new(),
                ));
            }
            "exchange" => names.exchanges.push((attr("data"), attr("mesh"), attr("from"), attr("to"))),
            _ => {}
        }
    }
    assert_eq!(depth, 0);
    names
}

/// `key value;` or `key (a b);` entries of an OpenFOAM dictionary block named `block`.
fn foam_block(text: &str, block: &str) -> HashMap<String, String> {
    let start = text.find(&format!("{block}\n")).unwrap_or_else(|| panic!("no block {block}"));
    let body = &text[start..];
    let open = body.find('{').unwrap();
    let close = body.find('}').unwrap();
    body[open + 1..close]
        .lines()
        .map(|l| l.split("//").next().unwrap().trim())
        .filter(|l| !l.is_empty())
        .map(|l| {
            let (k, v) = l.split_once(char::is_whitespace).unwrap();
            (k.to_string(), v.trim().trim_end_matches(';').trim_matches(|c| c == '(' || c == ')').trim().to_string())
        })
        .collect()
}

fn foam_entry(text: &str, key: &str) -> String {
    let line = text
        .lines()
        .find(|l| l.starts_with(key) && l[key.len()..].starts_with(char::is_whitespace))
        .unwrap_or_else(|| panic!("no entry {key}"));
    line[key.len()..].trim().trim_end_matches(';').trim().trim_matches('"').to_string()
}

#[test]
fn precice_names_agree_between_the_configuration_files() {
    let mesh = tube();
    let (dir, _) = write_all(&mesh, LengthUnit::Mm, "names");
    let fsi_dir = dir.join("fsi");
    let n = parse_precice(&fsi_dir.join("precice-config.xml"));
    eprintln!("{n:#?}");

    // preciceDict (fluid side).
    let dict = std::fs::read_to_string(fsi_dir.join("openfoam/system/preciceDict")).unwrap();
    let fluid = foam_entry(&dict, "participant");
    assert_eq!(foam_entry(&dict, "preciceConfig"), "../precice-config.xml");
    let i1 = foam_block(&dict, "    Interface1");
    let i2 = foam_block(&dict, "    Interface2");
    assert_eq!(i1["locations"], "faceCenters");
    assert_eq!(i2["locations"], "faceNodes");
    let poly = read_polymesh(&dir.join("openfoam")).unwrap();
    for i in [&i1, &i2] {
        assert!(poly.patch(&i["patches"]).is_some(), "patch {} not in the polyMesh", i["patches"]);
    }
    let (faces_mesh, nodes_mesh) = (i1["mesh"].clone(), i2["mesh"].clone());
    let (force, displacement) = (i1["writeData"].clone(), i2["readData"].clone());
    assert!(i1["readData"].is_empty() && i2["writeData"].is_empty());
    assert!(force.starts_with("Force") && displacement.starts_with("Displacement"));

    // config.yml (solid side).
    let yml = std::fs::read_to_string(fsi_dir.join("calculix/config.yml")).unwrap();
    let value = |key: &str| -> String {
        let l = yml.lines().find(|l| l.trim_start().trim_start_matches("- ").starts_with(key)).unwrap();
        l.split_once(':').unwrap().1.trim().trim_matches(|c| c == '[' || c == ']').to_string()
    };
    let solid = yml
        .lines()
        .skip_while(|l| !l.starts_with("participants:"))
        .nth(1)
        .unwrap()
        .trim()
        .trim_end_matches(':')
        .to_string();
    let solid_mesh = value("nodes-mesh");
    assert_eq!(value("read-data"), force);
    assert_eq!(value("write-data"), displacement);
    assert_eq!(value("precice-config-file"), "../precice-config.xml");
    let patch = value("patch");
    let fsi_deck = read_deck(&fsi_dir.join("calculix/fsi.inp"));
    let nset = format!("N{}", patch.to_ascii_uppercase());
    assert!(fsi_deck.nsets.contains_key(&nset), "no NSET {nset} in fsi.inp");
    let deck_text = std::fs::read_to_string(fsi_dir.join("calculix/fsi.inp")).unwrap();
    for dof in 1..=3 {
        assert!(deck_text.contains(&format!("{nset}, {dof}, 0.")), "no zero *CLOAD on {nset} dof {dof}");
    }
    assert!(deck_text.contains("*DYNAMIC"));

    // Exactly these names in precice-config.xml, used as the adapters use them.
    let set = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<BTreeSet<String>>();
    assert_eq!(n.data, set(&[&force, &displacement]));
    assert_eq!(n.meshes.keys().cloned().collect::<BTreeSet<_>>(), set(&[&faces_mesh, &nodes_mesh, &solid_mesh]));
    assert_eq!(n.meshes[&faces_mesh], set(&[&force]));
    assert_eq!(n.meshes[&nodes_mesh], set(&[&displacement]));
    assert_eq!(n.meshes[&solid_mesh], set(&[&force, &displacement]));
    assert_eq!(n.participants.keys().cloned().collect::<BTreeSet<_>>(), set(&[&fluid, &solid]));
    let has = |p: &str, tag: &str, what: &str| n.participants[p].iter().any(|(t, w, _)| t == tag && w == what);
    assert!(has(&fluid, "provide-mesh", &faces_mesh) && has(&fluid, "provide-mesh", &nodes_mesh));
    assert!(n.participants[&fluid]
        .iter()
        .any(|(t, w, from)| t == "receive-mesh" && *w == solid_mesh && *from == solid));
    assert!(has(&fluid, "write-data", &format!("{force}@{faces_mesh}")));
    assert!(has(&fluid, "read-data", &format!("{displacement}@{nodes_mesh}")));
    assert!(has(&fluid, "mapping:nearest-neighbor:write:conservative", &format!("{faces_mesh}->{solid_mesh}")));
    assert!(has(&fluid, "mapping:nearest-neighbor:read:consistent", &format!("{solid_mesh}->{nodes_mesh}")));
    assert!(has(&solid, "provide-mesh", &solid_mesh));
    assert!(has(&solid, "write-data", &format!("{displacement}@{solid_mesh}")));
    assert!(has(&solid, "read-data", &format!("{force}@{solid_mesh}")));
    assert!(n.exchanges.contains(&(force.clone(), solid_mesh.clone(), fluid.clone(), solid.clone())));
    assert!(n.exchanges.contains(&(displacement.clone(), solid_mesh.clone(), solid.clone(), fluid.clone())));
    let xml = std::fs::read_to_string(fsi_dir.join("precice-config.xml")).unwrap();
    assert!(xml.contains("<acceleration:IQN-ILS>") && xml.contains("-implicit>"));
    // Allrun runs the solid participant under the configured name.
    let allrun = std::fs::read_to_string(fsi_dir.join("Allrun")).unwrap();
    assert!(allrun.contains(&format!("-precice-participant {solid}")));

    // The preCICE config checker from PyPI, when installed.
    let checker = std::env::var("VESSELHEX_PRECICE_CONFIG_CHECK").unwrap_or_else(|_| "precice-config-check".into());
    match Command::new(&checker).arg(fsi_dir.join("precice-config.xml")).output() {
        Ok(out) => {
            let log = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
            eprintln!("precice-config-check:\n{log}");
            assert!(out.status.success(), "precice-config-check failed:\n{log}");
            // It exits 0 even when it reports errors: read its verdict.
            assert!(log.contains("No issues found"), "precice-config-check reports issues:\n{log}");
            assert!(!log.to_ascii_lowercase().contains("error"), "precice-config-check reports an error:\n{log}");
        }
        Err(_) => {
            assert!(
                !under_ci(),
                "CI=true but precice-config-check is not installed (pip install precice-config-check)"
            );
            eprintln!("skipped: precice-config-check not installed");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

// ---------------------------------------------------------------------------------------------
// ccx

fn ccx_available() -> bool {
    let found = Command::new("ccx").arg("-v").output().is_ok();
    if !found {
        assert!(!under_ci(), "ccx is not installed but CI=true: install calculix-ccx");
        eprintln!("skipped: ccx is not installed");
    }
    found
}

/// The FSI deck with the coupling replaced by a fixed load: the zero *CLOAD becomes the nodal
/// forces of a uniform lumen pressure lumped with force_lumping.csv; two coupling windows.
#[test]
fn fsi_deck_runs_in_ccx_with_a_fixed_load() {
    if !ccx_available() {
        return;
    }
    let mesh = tube();
    let (dir, _) = write_all(&mesh, LengthUnit::Mm, "ccx");
    let job = dir.join("fsi/calculix");
    let text = std::fs::read_to_string(job.join("fsi.inp")).unwrap();
    // Lumped forces (SI: the deck is in metres) of 1 mmHg = 133.322 Pa pushing the wall out,
    // applied at once (a dynamic step has no ramp; a full 100 mmHg step load in one increment
    // overstretches the soft HGO 2000 fibres in the first Newton iterate).
    let p = 133.322;
    let (_, faces) = csv_rows(&dir.join("fsi/interface_faces.csv"));
    let (_, lumping) = csv_rows(&dir.join("fsi/force_lumping.csv"));
    let mut force: BTreeMap<u64, Vector3<f64>> = BTreeMap::new();
    for r in &lumping {
        let k: usize = r[0].parse().unwrap();
        let element: usize = faces[k][2].parse::<usize>().unwrap() - 1;
        let f: usize = faces[k][3][1..].parse::<usize>().unwrap() - 1;
        let corners = face_nodes(&mesh.hexes[element], f).map(|n| mesh.nodes[n as usize] * 1e-3);
        // The wall face points into the lumen; the pressure pushes against it.
        let fa = -quad_area_vector(corners) * p;
        *force.entry(r[1].parse().unwrap()).or_insert_with(Vector3::zeros) += fa * r[2].parse::<f64>().unwrap();
    }
    let total: Vector3<f64> = force.values().sum();
    let magnitude: f64 = force.values().map(|f| f.norm()).sum();
    assert!(total.norm() < 1e-9 * magnitude.max(1e-300) + 1e-12, "closed tube: forces balance radially, got {total:?}");
    let mut cload = String::from("*CLOAD\n");
    for (n, f) in &force {
        for (dof, v) in [f.x, f.y, f.z].iter().enumerate() {
            cload.push_str(&format!("{n}, {}, {}\n", dof + 1, vesselhex::writers::inp::fmt_coord(*v)));
        }
    }
    let start = text.find("*CLOAD\n").unwrap();
    let end = text[start..].find("*NODE FILE").unwrap() + start;
    let mut deck = format!("{}{}{}", &text[..start], cload, &text[end..]);
    // Two windows: the *DYNAMIC data line becomes "dt, 2 dt".
    let d = deck.find("*DYNAMIC\n").unwrap() + "*DYNAMIC\n".len();
    let line_end = deck[d..].find('\n').unwrap() + d;
    let dt: f64 = deck[d..line_end].split(',').next().unwrap().trim().parse().unwrap();
    deck.replace_range(d..line_end, &format!("{dt:e}, {:e}", 2.0 * dt));
    std::fs::write(job.join("fixed.inp"), &deck).unwrap();

    let started = std::time::Instant::now();
    let out = Command::new("ccx").args(["-i", "fixed"]).current_dir(&job).env("OMP_NUM_THREADS", "1").output().unwrap();
    let log = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    let sta = std::fs::read_to_string(job.join("fixed.sta")).unwrap_or_default();
    eprintln!(
        "ccx fixed-load FSI deck: exit {:?} in {:.1} s, dt {dt:e}\n{sta}",
        out.status.code(),
        started.elapsed().as_secs_f64()
    );
    assert!(out.status.success(), "ccx failed:\n{log}");
    assert!(log.contains("Job finished"), "no 'Job finished':\n{log}");
    let warnings: Vec<&str> = log.lines().filter(|l| l.contains("*WARNING")).collect();
    assert!(warnings.is_empty(), "ccx warned:\n{}", warnings.join("\n"));
    assert!(sta.lines().filter(|l| l.trim_start().starts_with('1')).count() >= 1, "no increment in the .sta:\n{sta}");

    // The wall moved outward at the middle ring (nodal displacement read from the .frd).
    let frd = std::fs::read_to_string(job.join("fixed.frd")).unwrap();
    let mut disp: HashMap<u64, [f64; 3]> = HashMap::new();
    let mut in_disp = false;
    for line in frd.lines() {
        if line.starts_with(" -4") {
            in_disp = line.contains("DISP");
        } else if line.starts_with(" -3") {
            in_disp = false;
        } else if in_disp && line.starts_with(" -1") {
            let node: u64 = line[3..13].trim().parse().unwrap();
            let v: Vec<f64> = (0..3).map(|k| line[13 + 12 * k..25 + 12 * k].trim().parse().unwrap()).collect();
            disp.insert(node, [v[0], v[1], v[2]]);
        }
    }
    let mut ur = vec![];
    for &n in &mesh.node_sets[vesselhex::mesh::sets::INTERFACE_NODES] {
        let x = mesh.nodes[n as usize];
        if x.z > 10.0 && x.z < 20.0 {
            let u = disp[&(n as u64 + 1)];
            ur.push((u[0] * x.x + u[1] * x.y) / x.x.hypot(x.y));
        }
    }
    let mean = ur.iter().sum::<f64>() / ur.len() as f64;
    eprintln!("mean radial displacement of the middle interface nodes after 2 windows: {mean:e} m");
    assert!(mean > 0.0, "the wall did not move outward: {mean:e}");
    // The end rings (interface nodes among them, loaded in all three global dofs) moved only
    // radially in their end planes: the equations hold in ccx's solution.
    let largest = disp.values().map(|u| Vector3::from(*u).norm()).fold(0.0, f64::max);
    let mut worst: f64 = 0.0;
    for end in &mesh.ends {
        for &i in &mesh.node_sets[&vesselhex::mesh::sets::wall_end(&end.name)] {
            let u = Vector3::from(disp[&(i as u64 + 1)]);
            let d = mesh.nodes[i as usize] - end.centre;
            let radial = (d - end.outward_normal * d.dot(&end.outward_normal)).normalize();
            worst = worst.max(u.dot(&end.outward_normal).abs()).max((u - radial * u.dot(&radial)).norm());
        }
    }
    eprintln!("end rings: largest non-radial displacement {worst:e} m (largest displacement {largest:e} m)");
    assert!(worst <= 1e-9 * largest, "an end-ring node moved off its radial line: {worst:e} m");
    let _ = std::fs::remove_dir_all(&dir);
}

// ---------------------------------------------------------------------------------------------
// Pipeline and the fluid case

#[test]
fn formats_fsi_implies_openfoam_and_calculix() {
    let (stl, csv) = fixture("straight");
    let out = temp_dir("fsi-cli");
    let _ = std::fs::remove_dir_all(&out);
    let report = mesh_cli(&stl, &csv, &out, &["--formats", "fsi", "--preset", "coarse"]);
    let outputs: Vec<String> =
        report["outputs"].as_array().unwrap().iter().map(|v| v.as_str().unwrap().to_string()).collect();
    for f in [
        "openfoam/constant/polyMesh/points",
        "calculix/model.inp",
        "fsi/interface_nodes.csv",
        "fsi/calculix/fsi.inp",
        "fsi/precice-config.xml",
    ] {
        assert!(outputs.iter().any(|o| o == f), "{f} not in the outputs: {outputs:?}");
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let _ = std::fs::remove_dir_all(&out);
}

fn openfoam_available() -> bool {
    let found = Command::new("sh").args(["-c", "command -v pimpleFoam"]).output().is_ok_and(|o| o.status.success());
    if !found {
        assert!(!under_ci(), "CI=true but OpenFOAM (pimpleFoam) is not in the PATH");
        eprintln!("skipped: OpenFOAM not found");
    }
    found
}

/// The assembled fluid case (Allrun setup) runs two time steps of pimpleFoam on the dynamic mesh
/// without the adapter (function objects off).
#[test]
fn assembled_fluid_case_runs_two_steps_without_the_adapter() {
    if !openfoam_available() {
        return;
    }
    let mesh = tube();
    let (dir, _) = write_all(&mesh, LengthUnit::Mm, "foam");
    let fsi_dir = dir.join("fsi");
    let sh = |cmd: &str, cwd: &Path| {
        let out = Command::new("sh")
            .args(["-c", cmd])
            .current_dir(cwd)
            .env("WM_PROJECT_DIR", std::env::var("WM_PROJECT_DIR").unwrap_or_else(|_| "/usr/share/openfoam".into()))
            .env("OMP_NUM_THREADS", "1")
            .output()
            .unwrap();
        let log = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        assert!(out.status.success(), "{cmd} failed:\n{log}");
        log
    };
    sh("./Allrun setup", &fsi_dir);
    let fluid = fsi_dir.join("fluid");
    let control = std::fs::read_to_string(fluid.join("system/controlDict")).unwrap();
    let dt: f64 = foam_entry(&control, "deltaT").parse().unwrap();
    sh(&format!("foamDictionary -entry endTime -set {:e} system/controlDict", 2.0 * dt), &fluid);
    let log = sh("pimpleFoam -noFunctionObjects 2>&1", &fluid);
    assert!(log.contains("\nEnd"), "pimpleFoam did not finish:\n{log}");
    assert!(!log.contains("FOAM FATAL"), "{log}");
    assert!(log.contains("cellDisplacement") || log.contains("Mesh"), "no mesh motion solve:\n{log}");
    eprintln!("pimpleFoam: {} time steps on the dynamic mesh", log.matches("\nTime = ").count());
    let _ = std::fs::remove_dir_all(&dir);
}

// ---------------------------------------------------------------------------------------------
// End constraints of the FSI deck

/// `*TRANSFORM` node sets and `*EQUATION` terms of an .inp deck: per node label the equations it
/// appears in as rows (coefficients of u_x, u_y, u_z), and the dependent (first) term of each.
struct Constraints {
    transformed_sets: Vec<String>,
    rows: BTreeMap<u64, Vec<Vector3<f64>>>,
    dependents: Vec<(u64, usize)>,
    boundary_lines: Vec<String>,
}

fn read_constraints(text: &str) -> Constraints {
    let mut c =
        Constraints { transformed_sets: vec![], rows: BTreeMap::new(), dependents: vec![], boundary_lines: vec![] };
    let mut card = String::new();
    for line in text.lines().filter(|l| !l.starts_with("**")) {
        if let Some(k) = line.strip_prefix('*') {
            card = k.to_ascii_uppercase();
            if let Some(set) = card.strip_prefix("TRANSFORM, NSET=") {
                c.transformed_sets.push(set.split(',').next().unwrap().trim().to_string());
            }
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).filter(|s| !s.is_empty()).collect();
        if card == "EQUATION" && fields.len() > 1 {
            // one equation on one line: label, dof, coefficient per term, all terms on one node here
            let mut row = Vector3::zeros();
            let node: u64 = fields[0].parse().unwrap();
            for t in fields.chunks(3) {
                assert_eq!(t[0].parse::<u64>().unwrap(), node, "an end equation ties two nodes: {line}");
                row[t[1].parse::<usize>().unwrap() - 1] += t[2].parse::<f64>().unwrap();
            }
            c.dependents.push((node, fields[1].parse().unwrap()));
            c.rows.entry(node).or_default().push(row);
        } else if card.starts_with("BOUNDARY") {
            c.boundary_lines.push(line.to_string());
        }
    }
    c
}

#[test]
fn fsi_deck_holds_the_end_rings_by_equations_in_global_axes() {
    check_end_equations(&tube(), "ends-tube");
}

/// The curved fixture's outlet is oblique (its normal 120 deg from the inlet's, in the x-z plane).
#[test]
fn fsi_deck_holds_oblique_end_rings_by_their_normal() {
    let (stl, csv) = fixture("curved");
    let mesh = common::mesh_files(&stl, &csv, &MeshConfig::default());
    let outlet = mesh.ends.iter().find(|e| !e.is_inlet).unwrap();
    assert!(outlet.outward_normal.iter().filter(|c| c.abs() > 0.1).count() >= 2, "{:?}", outlet.outward_normal);
    check_end_equations(&mesh, "ends-curved");
}

fn check_end_equations(mesh: &VesselMesh, tag: &str) {
    let (dir, _) = write_all(mesh, LengthUnit::Mm, tag);
    let text = std::fs::read_to_string(dir.join("fsi/calculix/fsi.inp")).unwrap();
    let deck = read_deck(&dir.join("fsi/calculix/fsi.inp"));
    let c = read_constraints(&text);
    // (a) no interface node is under a *TRANSFORM (there is none at all)
    let interface: BTreeSet<u64> = deck.nsets["NLUMEN_WALL"].iter().copied().collect();
    for set in &c.transformed_sets {
        let under: BTreeSet<u64> = deck.nsets[set].iter().copied().collect();
        assert!(under.is_disjoint(&interface), "{set} puts interface nodes in local axes");
    }
    assert!(c.transformed_sets.is_empty(), "{:?}", c.transformed_sets);
    // ... while the inflation deck keeps its cylindrical systems
    let inflation = read_constraints(&std::fs::read_to_string(dir.join("calculix/model.inp")).unwrap());
    assert_eq!(inflation.transformed_sets.len(), mesh.ends.len());
    // (b) every end-ring node: exactly two equations whose only free motion is the in-plane radial
    // direction, so the displacement along the end's outward normal (and the circumferential one)
    // is removed
    let mut ring_nodes = BTreeSet::new();
    let mut end_ring_interface = 0;
    for end in &mesh.ends {
        let n = end.outward_normal;
        for &i in &mesh.node_sets[&vesselhex::mesh::sets::wall_end(&end.name)] {
            let label = i as u64 + 1;
            assert!(ring_nodes.insert(label), "node {label} in two rings");
            end_ring_interface += interface.contains(&label) as usize;
            let rows = c.rows.get(&label).unwrap_or_else(|| panic!("{} node {label} has no equation", end.name));
            assert_eq!(rows.len(), 2, "{} node {label}", end.name);
            let free = rows[0].cross(&rows[1]);
            assert!(free.norm() > 0.1, "{} node {label}: the two equations are dependent", end.name);
            let free = free.normalize();
            let d = mesh.nodes[i as usize] - end.centre;
            let radial = (d - n * d.dot(&n)).normalize();
            assert!(free.dot(&n).abs() < 1e-12, "{} node {label}: normal motion {} left free", end.name, free.dot(&n));
            assert!(
                free.cross(&radial).norm() < 1e-12,
                "{} node {label}: free motion {free:?} is not radial",
                end.name
            );
            // the normal itself is a combination of the rows: n . u = 0 follows from the equations
            let (a, b) = (rows[0], rows[1]);
            let gram = nalgebra::Matrix2::new(a.dot(&a), a.dot(&b), a.dot(&b), b.dot(&b));
            let coef = gram.try_inverse().unwrap() * nalgebra::Vector2::new(a.dot(&n), b.dot(&n));
            assert!((a * coef[0] + b * coef[1] - n).norm() < 1e-12, "{} node {label}", end.name);
        }
    }
    assert!(end_ring_interface > 0, "the test tube's rings hold no interface node: the case is not covered");
    assert_eq!(c.rows.keys().copied().collect::<BTreeSet<_>>(), ring_nodes, "equations on nodes outside the end rings");
    // a dof is eliminated once, and none is also fixed by *BOUNDARY
    let unique: BTreeSet<_> = c.dependents.iter().collect();
    assert_eq!(unique.len(), c.dependents.len(), "a dof is the dependent term of two equations");
    assert!(c.boundary_lines.is_empty(), "{:?}", c.boundary_lines);
    eprintln!(
        "{tag} fsi.inp: {} end-ring nodes ({} of them interface nodes) held by {} equations, no *TRANSFORM",
        ring_nodes.len(),
        end_ring_interface,
        c.dependents.len()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The FSI deck's ends rely on ccx carrying a force on an eliminated dof (the adapter loads all
/// three dofs of every interface node) over to the free one: a unit cube held at the bottom, its
/// top corner (1, 1, 1) tied by u_x = u_y, loaded once on the eliminated u_x and once on the free
/// u_y, must move the same by the mirror symmetry x <-> y.
#[test]
fn ccx_carries_a_force_on_an_eliminated_dof_over() {
    if !ccx_available() {
        return;
    }
    let dir = temp_dir("fsi-eq-force");
    let mut moved = vec![];
    for dof in [1, 2] {
        let deck = format!(
            "*NODE\n1, 0., 0., 0.\n2, 1., 0., 0.\n3, 1., 1., 0.\n4, 0., 1., 0.\n5, 0., 0., 1.\n6, 1., 0., 1.\n\
             7, 1., 1., 1.\n8, 0., 1., 1.\n*ELEMENT, TYPE=C3D8, ELSET=E\n1, 1, 2, 3, 4, 5, 6, 7, 8\n\
             *NSET, NSET=BOTTOM\n1, 2, 3, 4\n*NSET, NSET=TOP\n7\n*BOUNDARY\nBOTTOM, 1, 3\n*EQUATION\n2\n7, 1, 1., 7, 2, -1.\n\
             *MATERIAL, NAME=M\n*ELASTIC\n1000., 0.3\n*DENSITY\n1.\n*SOLID SECTION, ELSET=E, MATERIAL=M\n\
             *STEP, NLGEOM, INC=100\n*DYNAMIC\n0.1, 0.2\n*CLOAD\n7, {dof}, 1.\n*NODE PRINT, NSET=TOP\nU\n*END STEP\n"
        );
        let job = format!("load{dof}");
        std::fs::write(dir.join(format!("{job}.inp")), deck).unwrap();
        let out =
            Command::new("ccx").args(["-i", &job]).current_dir(&dir).env("OMP_NUM_THREADS", "1").output().unwrap();
        let log = String::from_utf8_lossy(&out.stdout).to_string();
        assert!(out.status.success() && log.contains("Job finished") && !log.contains("*WARNING"), "{log}");
        let dat = std::fs::read_to_string(dir.join(format!("{job}.dat"))).unwrap();
        let line = dat.lines().rfind(|l| l.split_whitespace().next() == Some("7")).unwrap().to_string();
        let u: Vec<f64> = line.split_whitespace().skip(1).map(|s| s.parse().unwrap()).collect();
        moved.push(u);
    }
    eprintln!("u of the tied corner, load on u_x (eliminated): {:?}; on u_y (free): {:?}", moved[0], moved[1]);
    assert!(moved[0][0] > 1e-4, "the force on the eliminated dof did nothing");
    for k in 0..3 {
        assert!((moved[0][k] - moved[1][k]).abs() <= 1e-6 * moved[1][0].abs(), "{k}: {:?} vs {:?}", moved[0], moved[1]);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// C3D20 has mid-edge nodes on the interface that the map cannot serve: refused with the key.
#[test]
fn quadratic_calculix_elements_are_refused_by_the_fsi_package() {
    let mesh = tube();
    let dir = temp_dir("fsi-c3d20");
    let mut options = WriteOptions::default();
    for element in [ElementType::C3D20, ElementType::C3D20R] {
        options.fe.calculix_element = element;
        let e = fsi::write_fsi(&mesh, &options, &dir).unwrap_err().to_string();
        assert!(e.contains("fe.calculix_element") && e.contains(element.name()) && e.contains("C3D8I"), "{e}");
    }
    assert!(!dir.join("fsi/interface_nodes.csv").exists(), "a refused package left files");
    // and before any meshing when the fsi format is asked for
    let mut config = MeshConfig { formats: vec!["fsi".into()], ..Default::default() };
    config.fe.calculix_element = ElementType::C3D20;
    let e = config.validate().unwrap_err().to_string();
    assert!(e.contains("fe.calculix_element") && e.contains("fsi"), "{e}");
    config.formats = vec!["calculix".into()];
    config.validate().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

// ---------------------------------------------------------------------------------------------
// Several outlets

/// The names of the entries of an OpenFOAM field file's `boundaryField` (one level deep).
fn boundary_field_entries(text: &str) -> Vec<String> {
    let body = &text[text.find("boundaryField").unwrap()..];
    let (mut names, mut depth, mut word) = (vec![], 0, String::new());
    for line in body.lines().map(|l| l.split("//").next().unwrap().trim()) {
        match line {
            "{" => {
                depth += 1;
                if depth == 2 {
                    names.push(word.clone());
                }
            }
            "}" => depth -= 1,
            w if depth == 1 && !w.is_empty() => word = w.to_string(),
            _ => {}
        }
    }
    names
}

/// The FSI package of a mesh with an inlet and five outlets (three disjoint tubes, two oblique):
/// the maps read back exactly, the end rings of all six ends are held by their own equations, and
/// the fluid overlay has an entry for every end patch.
#[test]
fn fsi_package_of_a_multi_outlet_mesh() {
    let mut c = MeshConfig::default();
    c.lumen.core_elements = 2;
    c.lumen.radial_elements = 2;
    c.lumen.axial_spacing_mm = Some(3.0);
    c.wall.thickness_mm = Some(0.6);
    let mesh = vesselhex::testing::multi_outlet_mesh(&c).unwrap();
    assert_eq!(mesh.ends.len(), 6);
    check_map(&mesh, LengthUnit::Mm, "multi");
    check_end_equations(&mesh, "ends-multi");
    let (dir, _) = write_all(&mesh, LengthUnit::Mm, "multi-overlay");
    let ends: Vec<String> = mesh.ends.iter().map(|e| e.name.clone()).collect();
    let u = boundary_field_entries(&std::fs::read_to_string(dir.join("fsi/openfoam/0/U")).unwrap());
    let mut want = ends.clone();
    want.push("wall".into());
    assert_eq!(u, want, "fsi/openfoam/0/U");
    let d = boundary_field_entries(&std::fs::read_to_string(dir.join("fsi/openfoam/0/pointDisplacement")).unwrap());
    let mut want = vec!["wall".to_string()];
    want.extend(ends.iter().cloned());
    assert_eq!(d, want, "fsi/openfoam/0/pointDisplacement");
    let _ = std::fs::remove_dir_all(&dir);
}
