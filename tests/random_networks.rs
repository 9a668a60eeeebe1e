//! The random-network generator (issue 49): a sample of seeds (rings with every end open and a
//! side branch off an inlet, every end capped and an outlet split in two, some of each and two
//! outlets split; grafts capped and mixed; the circle of Willis) checked from the outside: the surface is one outward oriented
//! manifold whose genus, computed here from V, E, F and its boundary loops, is the truth's loop
//! count (at least one); every true end lies on its boundary loop or on its flat cap; rings
//! have at least two inlets; the truth's segment graph has a cycle rank E - V + 1 equal to its
//! loop count and each listed loop is a closed cycle; the same seed gives the same bytes
//! whatever the thread count; the command line writes the files and refuses a bad seed in one
//! line. Networks mesh with their loops closed.

mod common;

use common::topology::{boundary_loops, closed_volume6, ends_where_the_truth_says, pieces};
use common::{path_str, temp_dir, vesselhex};
use serde_json::Value;
use std::collections::{HashMap, HashSet};
use std::process::Command;
use vesselhex::input::{read_centerlines, CenterlinePolyline};
use vesselhex::progress::Progress;
use vesselhex::synthetic_network::draw::Shape;
use vesselhex::synthetic_network::{write_random_network, RandomNetwork};
use vesselhex::synthetic_tree::SurfaceFormat;
use vesselhex::units::LengthUnit;

/// Rings: every end open, a side branch off an inlet (54); capped, an outlet split (46); mixed,
/// two outlets split (74). Grafts: capped (21); mixed, drawn twice (6).
const SEEDS: [u64; 5] = [54, 46, 74, 21, 6];

fn generate(seed: u64, forced: Option<Shape>) -> RandomNetwork {
    RandomNetwork::generate(seed, forced, &mut Progress::new(true, 0)).unwrap_or_else(|e| panic!("seed {seed}: {e}"))
}

/// A node of the manifest's graph as a key.
fn node(v: &Value) -> String {
    v.to_string()
}

/// Checks the manifest's graph: its cycle rank E - V + 1 (the graph being connected) equals the
/// loop count, and each loop's segments form one closed cycle (every node met twice, connected).
fn graph_matches_loops(what: &str, manifest: &Value) -> usize {
    let segments = manifest["segments"].as_array().unwrap();
    let mut nodes: HashSet<String> = HashSet::new();
    let mut parent: HashMap<String, String> = HashMap::new();
    fn root(parent: &mut HashMap<String, String>, x: &str) -> String {
        let mut x = x.to_string();
        while let Some(p) = parent.get(&x).cloned() {
            if p == x {
                break;
            }
            x = p;
        }
        x
    }
    for s in segments {
        let (a, b) = (node(&s["from"]), node(&s["to"]));
        for n in [&a, &b] {
            nodes.insert(n.clone());
            parent.entry(n.clone()).or_insert_with(|| n.clone());
        }
        let (ra, rb) = (root(&mut parent, &a), root(&mut parent, &b));
        parent.insert(ra, rb);
    }
    let roots: HashSet<String> = nodes.iter().map(|n| root(&mut parent, n)).collect();
    assert_eq!(roots.len(), 1, "{what}: the segment graph is in {} pieces", roots.len());
    let rank = segments.len() as i64 - nodes.len() as i64 + 1;
    let loops = manifest["loops"]["segments"].as_array().unwrap();
    assert_eq!(manifest["loops"]["count"].as_u64().unwrap() as usize, loops.len());
    assert_eq!(rank, loops.len() as i64, "{what}: cycle rank E - V + 1 vs the loops listed");
    for l in loops {
        let mut degree: HashMap<String, usize> = HashMap::new();
        for id in l.as_array().unwrap() {
            let s = &segments[id.as_u64().unwrap() as usize];
            *degree.entry(node(&s["from"])).or_default() += 1;
            *degree.entry(node(&s["to"])).or_default() += 1;
        }
        assert!(degree.values().all(|&d| d == 2), "{what}: loop {l} is not a cycle: {degree:?}");
    }
    loops.len()
}

/// Smallest wall gap between two centerline polylines with radii: each point of one against
/// each edge of the other (radius interpolated along the edge).
fn wall_gap(a: &CenterlinePolyline, b: &CenterlinePolyline) -> f64 {
    let (ra, rb) = (a.radii.as_ref().unwrap(), b.radii.as_ref().unwrap());
    let mut gap = f64::INFINITY;
    for (p, r) in a.points.iter().zip(ra) {
        for k in 0..b.points.len() - 1 {
            let (q0, q1) = (b.points[k], b.points[k + 1]);
            let e = q1 - q0;
            let t = ((p - q0).dot(&e) / e.norm_squared().max(1e-300)).clamp(0.0, 1.0);
            let rq = rb[k] + (rb[k + 1] - rb[k]) * t;
            gap = gap.min((p - (q0 + e * t)).norm() - r - rq);
        }
    }
    gap
}

/// The walls of two segments that share no node (junction or end) keep at least two grid cells
/// apart: measured on the centerlines, whose radii are distances to the surface.
fn walls_apart_unless_joined(what: &str, net: &RandomNetwork, manifest: &Value, h: f64) {
    let lines = net.centerlines().unwrap().polylines;
    let segments = manifest["segments"].as_array().unwrap();
    let nodes = |s: &Value| [node(&s["from"]), node(&s["to"])];
    for a in 0..segments.len() {
        for b in a + 1..segments.len() {
            let (na, nb) = (nodes(&segments[a]), nodes(&segments[b]));
            if na.iter().any(|n| nb.contains(n)) {
                continue;
            }
            let gap = wall_gap(&lines[a], &lines[b]);
            assert!(gap >= 2.0 * h * (1.0 - 1e-6), "{what}: segments {a} and {b}: walls {gap} mm apart, cell {h} mm");
        }
    }
}

#[test]
fn each_network_is_one_outward_manifold_whose_genus_is_its_loop_count_with_its_ends_where_the_truth_says() {
    let sample = SEEDS.iter().map(|&s| (s, None)).chain([(0, Some(Shape::CircleOfWillis))]);
    for (seed, forced) in sample {
        let net = generate(seed, forced);
        let what = format!("{} (seed {seed})", net.name);
        let s = &net.surface;
        let manifest = serde_json::to_value(net.manifest("s", "c")).unwrap();
        let ends = manifest["ends"].as_array().unwrap();
        let open = ends.iter().filter(|e| e["kind"] == "open").count();
        let loops = boundary_loops(&s.triangles);
        assert_eq!(loops.len(), open, "{what}: boundary loops vs open ends");
        assert_eq!(pieces(s.vertices.len(), &s.triangles), 1, "{what}");
        let edges = (3 * s.triangles.len() + loops.iter().map(Vec::len).sum::<usize>()) / 2;
        let chi = s.vertices.len() as i64 - edges as i64 + s.triangles.len() as i64;
        // V - E + F = 2 - 2g - b.
        let twice_genus = 2 - loops.len() as i64 - chi;
        assert_eq!(twice_genus % 2, 0, "{what}: odd 2g");
        let graph_loops = graph_matches_loops(&what, &manifest);
        assert!(graph_loops >= 1, "{what}: no loop");
        assert_eq!(twice_genus / 2, graph_loops as i64, "{what}: the surface's genus vs the truth's loops");
        assert!(closed_volume6(&s.vertices, &s.triangles, &loops) > 0.0, "{what}: triangles face inwards");
        let h = manifest["grid"]["cell_size_mm"].as_f64().unwrap();
        ends_where_the_truth_says(&what, &s.vertices, &s.triangles, &loops, ends, h);
        walls_apart_unless_joined(&what, &net, &manifest, h);
        let inlets = ends.iter().filter(|e| e["role"] == "inlet").count();
        let outlets = ends.len() - inlets;
        match manifest["shape"].as_str().unwrap() {
            // 1 to 6 outlet branches, each splitting into two at most.
            "ring" => assert!((2..=3).contains(&inlets) && (1..=12).contains(&outlets), "{what}: {inlets}, {outlets}"),
            "graft" => assert_eq!((inlets, outlets), (1, 1), "{what}"),
            "circle_of_willis" => {
                assert_eq!((inlets, outlets), (3, 6), "{what}");
                let labels: Vec<&str> = ends.iter().map(|e| e["label"].as_str().unwrap()).collect();
                for side in ["left", "right"] {
                    for artery in ["internal carotid", "anterior cerebral", "middle cerebral", "posterior cerebral"] {
                        let label = format!("{side} {artery} artery");
                        assert!(labels.contains(&label.as_str()), "{what}: no {label}");
                    }
                }
                assert!(labels.contains(&"basilar artery"), "{what}: no basilar");
            }
            other => panic!("{what}: shape {other}"),
        }
    }
}

#[test]
fn the_cli_writes_the_same_bytes_as_the_library_whatever_the_thread_count() {
    let seed = 54;
    let (cli, lib) = (temp_dir("network-cli"), temp_dir("network-lib"));
    let out = Command::new(env!("CARGO_BIN_EXE_vesselhex"))
        .args(["fixtures", "--random-network", "54", "--quiet", "--output", path_str(&cli)])
        .env("RAYON_NUM_THREADS", "1")
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let written = write_random_network(seed, None, &lib, SurfaceFormat::Stl, &mut Progress::new(true, 0)).unwrap();
    let names = ["network_54.stl", "network_54.json", "network_54_centerlines.vtp"];
    common::assert_same_files(&cli, &lib, &names);
    // One centerline polyline per segment, its ends at the segment's nodes.
    let centerlines = read_centerlines(&cli.join(names[2]), LengthUnit::Mm).unwrap();
    assert_eq!(centerlines.polylines.len(), written.network.segments.len());
    let manifest: Value = serde_json::from_slice(&std::fs::read(cli.join(names[1])).unwrap()).unwrap();
    assert_eq!(manifest["seed"], 54);
    assert_eq!(manifest["files"]["surface"], names[0]);
    for (line, seg) in centerlines.polylines.iter().zip(manifest["segments"].as_array().unwrap()) {
        let length: f64 = line.points.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        let truth = seg["length_mm"].as_f64().unwrap();
        assert!(
            (length - truth).abs() <= 1e-6 * truth.max(1.0) + 0.02 * truth,
            "segment {}: {length} vs {truth}",
            seg["id"]
        );
        for (k, at) in [("from", line.points[0]), ("to", *line.points.last().unwrap())] {
            let centre = match seg[k].get("junction") {
                Some(j) => &manifest["junctions"][j.as_u64().unwrap() as usize]["centre"],
                None => &manifest["ends"][seg[k]["end"].as_u64().unwrap() as usize]["centre"],
            };
            let c: Vec<f64> = centre.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
            let d = ((at.x - c[0]).powi(2) + (at.y - c[1]).powi(2) + (at.z - c[2]).powi(2)).sqrt();
            assert!(d < 1e-9 * (1.0 + c[0].abs() + c[1].abs() + c[2].abs()), "segment {}: {k} {d} mm off", seg["id"]);
        }
    }
}

#[test]
fn the_circle_of_willis_is_written_by_its_own_flag() {
    let dir = temp_dir("network-willis");
    let out = vesselhex(&["fixtures", "--circle-of-willis", "--quiet", "--format", "vtp", "--output", path_str(&dir)]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for name in ["circle_of_willis.vtp", "circle_of_willis.json", "circle_of_willis_centerlines.vtp"] {
        assert!(dir.join(name).is_file(), "{name} not written");
    }
    let manifest: Value = serde_json::from_slice(&std::fs::read(dir.join("circle_of_willis.json")).unwrap()).unwrap();
    assert_eq!(manifest["shape"], "circle_of_willis");
    // The ring: the loop's segments all lie on the one closed vessel, one per vertex.
    let ring = manifest["loops"]["segments"][0].as_array().unwrap();
    assert!(ring.len() >= 6, "a ring of {} segments", ring.len());
    let vessels: HashSet<u64> =
        ring.iter().map(|i| manifest["segments"][i.as_u64().unwrap() as usize]["vessel"].as_u64().unwrap()).collect();
    assert_eq!(vessels.len(), 1);
}

#[test]
fn a_bad_seed_is_refused_in_one_line_and_nothing_is_written() {
    let dir = temp_dir("network-bad");
    for bad in ["abc", "5-2", "-3", "1-x"] {
        let out_dir = dir.join(format!("out-{bad}"));
        let out = vesselhex(&["fixtures", "--random-network", bad, "--output", path_str(&out_dir)]);
        assert!(!out.status.success(), "{bad}: accepted");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(stderr.trim_end().lines().count(), 1, "{bad}: {stderr}");
        assert!(stderr.starts_with("vesselhex: error:") && stderr.contains(bad), "{bad}: {stderr}");
        assert!(!out_dir.exists(), "{bad}: the output folder was created");
    }
}

/// The Euler characteristic V - E + F of the mesh's boundary: the faces only one hex has. The
/// boundary of a solid with `g` loops through it is a closed surface of genus `g`: 2 - 2g.
fn boundary_euler(mesh: &vesselhex::mesh::VesselMesh) -> i64 {
    let mut count: HashMap<[u32; 4], ([u32; 4], usize)> = HashMap::new();
    for h in &mesh.hexes {
        for f in 0..6 {
            let q = vesselhex::mesh::face_nodes(h, f);
            let mut key = q;
            key.sort_unstable();
            count.entry(key).or_insert((q, 0)).1 += 1;
        }
    }
    let faces: Vec<[u32; 4]> = count.values().filter(|(_, c)| *c == 1).map(|(q, _)| *q).collect();
    let vertices: HashSet<u32> = faces.iter().flatten().copied().collect();
    let edges: HashSet<(u32, u32)> =
        faces.iter().flat_map(|q| (0..4).map(move |k| (q[k].min(q[(k + 1) % 4]), q[k].max(q[(k + 1) % 4])))).collect();
    vertices.len() as i64 - edges.len() as i64 + faces.len() as i64
}

/// Networks mesh with their loops (issue 49): two grafts and a ring, meshed from their bare
/// surfaces at coarse with their inlets flagged where the truth has them. Each mesh is
/// conformal (no face shared by three hexes, no coincident nodes, lumen and wall face to face),
/// its boundary is a closed surface with as many loops as the truth has (Euler characteristic
/// 2 - 2 loops: a loop cut open and left so would give 2), no element is inverted, every true
/// end is a meshed end of the same role, every bar is held and nothing warns of a loop left
/// open.
#[test]
fn a_network_meshes_with_its_loops_closed() {
    use vesselhex::centerline_extract::{ExtractOptions, InletChoice};
    use vesselhex::inlets::InletMark;
    use vesselhex::pipeline::{mesh_surface, CenterlineSource};
    let dir = temp_dir("network-mesh");
    for seed in [6, 21, 54] {
        write_random_network(seed, None, &dir, SurfaceFormat::Stl, &mut Progress::new(true, 0)).unwrap();
        let truth: Value =
            serde_json::from_slice(&std::fs::read(dir.join(format!("network_{seed}.json"))).unwrap()).unwrap();
        let loops = truth["loops"]["count"].as_i64().unwrap();
        let point = |e: &Value| {
            let c: Vec<f64> = e["centre"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
            nalgebra::Point3::new(c[0], c[1], c[2])
        };
        let true_ends = truth["ends"].as_array().unwrap();
        let inlets: Vec<nalgebra::Point3<f64>> = true_ends.iter().filter(|e| e["role"] == "inlet").map(point).collect();
        let surface = vesselhex::input::read_surface(&dir.join(format!("network_{seed}.stl")), LengthUnit::Mm).unwrap();
        let mut settings = common::coarse_settings();
        settings.inlets = inlets[1..].iter().map(|p| InletMark::Point(*p)).collect();
        let options = ExtractOptions { inlet: InletChoice::Nearest(inlets[0]), ..ExtractOptions::default() };
        let vessel = mesh_surface(surface, CenterlineSource::Extract(options), settings, &mut Progress::new(true, 0))
            .unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        let what = format!("network {seed}");
        let mesh = &vessel.meshed.mesh;
        common::assert_conformal(&what, mesh);
        assert_eq!(boundary_euler(mesh), 2 - 2 * loops, "{what}: the mesh's loops");
        assert!(mesh.quality.iter().all(|q| q.scaled_jacobian > 0.0), "{what}: an inverted element");
        assert_eq!(mesh.ends.len(), true_ends.len(), "{what}: meshed ends");
        for e in true_ends {
            let (p, r) = (point(e), e["radius_mm"].as_f64().unwrap());
            let end = mesh.ends.iter().min_by(|a, b| (a.centre - p).norm().total_cmp(&(b.centre - p).norm())).unwrap();
            assert!((end.centre - p).norm() < 2.0 * r, "{what}: no meshed end at {p}");
            assert_eq!(end.is_inlet, e["role"] == "inlet", "{what}: the end at {p} is a {}", e["role"]);
        }
        let warnings = &vessel.settings.warnings;
        let loop_or_inlet =
            |w: &&vesselhex::data::diagnostics::Warning| w.kind == "surface_loops" || w.kind == "inlet_guessed";
        assert!(!warnings.iter().any(|w| loop_or_inlet(&w)), "{what}: {warnings:?}");
        let report = vesselhex::pipeline::vessel_report(&vessel, &vessel.settings.config, &[]);
        assert!(report.within_bars, "{what}: a bar is not held");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Centerlines given cut open on a loop are joined where `centerline.loop_cuts_mm` says (issue
/// 49): graft 6's centerlines as the extraction finds them (cut open on the graft), given back
/// with the cut point, mesh with the loop closed (boundary Euler characteristic 0, conformal);
/// given without it, the mesh leaves the loop open and says so (`surface_loops`), its two cut
/// ends meshed as ends.
#[test]
fn given_centerlines_cut_open_are_joined_at_the_cuts_named() {
    use vesselhex::centerline_extract::{extract_centerlines, ExtractOptions, InletChoice};
    use vesselhex::pipeline::{mesh_surface, CenterlineSource};
    let dir = temp_dir("network-given");
    write_random_network(6, None, &dir, SurfaceFormat::Stl, &mut Progress::new(true, 0)).unwrap();
    let surface = vesselhex::input::read_surface(&dir.join("network_6.stl"), LengthUnit::Mm).unwrap();
    let options = ExtractOptions { inlet: InletChoice::Nearest(nalgebra::Point3::origin()), ..Default::default() };
    let (clean, _) = vesselhex::input::clean_surface(surface.clone()).unwrap();
    let extraction = extract_centerlines(&clean, &options).unwrap();
    assert_eq!(extraction.loop_cuts.len(), 1, "graft 6 has one loop");
    let cut: [f64; 3] = extraction.loop_cuts[0].centre.coords.into();
    for (cuts, loops_left) in [(vec![cut], 0), (vec![], 1)] {
        let mut settings = common::coarse_settings();
        settings.config.centerline.loop_cuts_mm = cuts;
        let given = CenterlineSource::Given(extraction.centerlines.clone());
        let vessel = mesh_surface(surface.clone(), given, settings, &mut Progress::new(true, 0)).unwrap();
        let mesh = &vessel.meshed.mesh;
        common::assert_conformal("graft 6", mesh);
        assert_eq!(boundary_euler(mesh), 2 - 2 * (1 - loops_left), "graft 6, {loops_left} loop(s) left open");
        assert_eq!(mesh.ends.len(), 2 + 2 * loops_left as usize, "graft 6: ends");
        let warned = vessel.settings.warnings.iter().any(|w| w.kind == "surface_loops");
        assert_eq!(warned, loops_left > 0, "graft 6: {:?}", vessel.settings.warnings);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A network meshed with no inlet flagged is fed through its largest end, and the user is told
/// so (`inlet_guessed`, naming that end): graft 6 from its bare surface, no `--inlet`.
#[test]
fn a_network_with_no_inlet_flagged_says_which_end_it_took() {
    use vesselhex::pipeline::{mesh_surface, CenterlineSource};
    let dir = temp_dir("network-unflagged");
    write_random_network(6, None, &dir, SurfaceFormat::Stl, &mut Progress::new(true, 0)).unwrap();
    let surface = vesselhex::input::read_surface(&dir.join("network_6.stl"), LengthUnit::Mm).unwrap();
    let extract = CenterlineSource::Extract(Default::default());
    let vessel = mesh_surface(surface, extract, common::coarse_settings(), &mut Progress::new(true, 0)).unwrap();
    let inlets: Vec<&vesselhex::mesh::VesselEnd> = vessel.meshed.mesh.ends.iter().filter(|e| e.is_inlet).collect();
    assert_eq!(inlets.len(), 1, "one inlet");
    let warning = vessel.settings.warnings.iter().find(|w| w.kind == "inlet_guessed");
    let message = warning.map(|w| w.message.clone()).unwrap_or_default();
    // The end it names (the cap's centre) is the mesh's inlet (its end section's centre, within
    // the inlet's radius of 0.54 mm).
    let named: Vec<f64> = message
        .split_once("the largest end, at (")
        .and_then(|(_, rest)| rest.split_once(')'))
        .map(|(xyz, _)| xyz.split(", ").filter_map(|x| x.parse().ok()).collect())
        .unwrap_or_default();
    assert_eq!(named.len(), 3, "no inlet_guessed warning naming an end: {:?}", vessel.settings.warnings);
    let gap = (inlets[0].centre - nalgebra::Point3::new(named[0], named[1], named[2])).norm();
    assert!(gap < 0.5, "the warning names an end {gap} mm from the mesh's inlet: {message}");
    let _ = std::fs::remove_dir_all(&dir);
}
