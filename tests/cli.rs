//! The `vesselhex mesh` command end to end: outputs, determinism, the independent quality check
//! by VTK, and clear errors on bad input that leave no file behind.

mod common;

use common::{crate_dir, files_under, fixture, mesh_cli, mesh_surface_cli, path_str, temp_dir, vesselhex};
use std::path::Path;

#[test]
fn outputs_and_report_keys() {
    let (stl, csv) = fixture("curved");
    let out = temp_dir("outputs");
    let r = mesh_cli(&stl, &csv, &out, &[]);
    assert!(out.join("mesh.vtu").exists());
    assert_eq!(r["length_unit"], "mm");
    assert_eq!(r["length_unit_in_m"], 0.001);
    for region in ["lumen", "wall"] {
        for key in ["elements", "nodes"] {
            assert!(r[region][key].as_u64().unwrap() > 0, "{region}.{key}");
        }
        for key in ["scaled_jacobian", "equiangle_skew"] {
            for stat in ["min", "mean", "max"] {
                assert!(r[region][key][stat].is_number(), "{region}.{key}.{stat}");
            }
        }
    }
    let layers = r["wall"]["layers"].as_array().unwrap();
    let names: Vec<&str> = layers.iter().map(|l| l["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["intima", "media", "adventitia"]);
    let total: u64 = layers.iter().map(|l| l["elements"].as_u64().unwrap()).sum();
    assert_eq!(total, r["wall"]["elements"].as_u64().unwrap());
    for l in layers {
        assert!(l["fibre_angle_deg"].is_number() && l["scaled_jacobian"]["min"].is_number());
    }
    for k in ["node_to_surface_um", "surface_to_mesh_um"] {
        assert!(r["surface_accuracy"][k]["mean"].is_number() && r["surface_accuracy"][k]["max"].is_number());
    }
    assert!(r["timings_s"].as_object().unwrap().len() >= 5);
    // nothing else left in the output folder
    let mut names: Vec<String> =
        std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    names.sort();
    assert_eq!(names, ["mesh.vtu", "report.json"]);
}

/// `report.json` `ends`: the vessel's ends, whatever the centerlines' layout. A branch-split
/// file's tracts end inside the junction too; those are not vessel ends. From the bare surface
/// the same three open ends are found, each meshed.
#[test]
fn every_end_is_reported_once_and_meshed() {
    let dir = temp_dir("ends");
    let (stl, _) = fixture("y_bifurcation");
    let split = dir.join("split.vtp");
    let o = vesselhex(&[
        "centerlines",
        "--surface",
        path_str(&stl),
        "--output",
        path_str(&dir.join("paths.vtp")),
        "--branch-split",
        path_str(&split),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let given = mesh_cli(&stl, &split, &dir.join("given"), &["--preset", "coarse"]);
    let found = mesh_surface_cli(&stl, &dir.join("found"), &["--preset", "coarse"]);
    for (report, kind) in [(&given, "centerline"), (&found, "open")] {
        let ends = report["ends"].as_array().unwrap();
        assert_eq!(ends.len(), 3, "{kind}: {ends:?}");
        assert!(ends.iter().all(|e| e["meshed"] == true && e["kind"] == kind), "{ends:?}");
        assert_eq!(ends.iter().filter(|e| e["inlet"] == true).count(), 1);
        // The inlet is the Y's trunk, at z = -17.2 mm.
        let inlet = ends.iter().find(|e| e["inlet"] == true).unwrap();
        assert!((inlet["position"][2].as_f64().unwrap() + 17.2).abs() < 0.5, "{inlet}");
    }
}

#[test]
fn output_units_scale_the_vtu_but_not_the_figures() {
    let (stl, csv) = fixture("straight");
    let mm = temp_dir("units-mm");
    let m = temp_dir("units-m");
    let a = mesh_cli(&stl, &csv, &mm, &["--reproducible"]);
    let b = mesh_cli(&stl, &csv, &m, &["--reproducible", "--output-units", "m"]);
    assert_eq!(b["length_unit"], "m");
    assert_eq!(b["length_unit_in_m"], 1.0);
    assert_eq!(a["lumen"]["elements"], b["lumen"]["elements"]);
    // The same vessel read in centimetres is ten times larger: same element counts.
    let cm = temp_dir("units-cm");
    let c = mesh_cli(&stl, &csv, &cm, &["--units", "cm"]);
    assert_eq!(a["lumen"]["elements"], c["lumen"]["elements"]);
}

#[test]
fn two_runs_are_byte_identical_whatever_the_thread_count() {
    // A branched vessel too: its junction is finished in several ways built side by side, and
    // the choice between them must not depend on the threads.
    let dir = crate_dir().join("fixtures");
    let branched = (dir.join("t_junction.stl"), dir.join("t_junction_centerlines.vtp"));
    for (name, (stl, centerlines)) in [("helical", fixture("helical")), ("t_junction", branched)] {
        let a = temp_dir(&format!("det-a-{name}"));
        let b = temp_dir(&format!("det-b-{name}"));
        mesh_cli(&stl, &centerlines, &a, &["--reproducible", "--threads", "1"]);
        mesh_cli(&stl, &centerlines, &b, &["--reproducible", "--threads", "2"]);
        for f in ["mesh.vtu", "report.json"] {
            let x = std::fs::read(a.join(f)).unwrap();
            let y = std::fs::read(b.join(f)).unwrap();
            assert!(x == y, "{name}: {f} differs between runs");
        }
    }
}

#[test]
fn vtk_mesh_quality_agrees_with_the_report() {
    let Some(py) = common::python_with("vtkmodules.vtkFiltersVerdict") else { return };
    for name in ["curved", "aaa"] {
        let (stl, csv) = fixture(name);
        let out = temp_dir(&format!("vtk-{name}"));
        let r = mesh_cli(&stl, &csv, &out, &[]);
        let script = r#"
import sys
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader
from vtkmodules.vtkFiltersVerdict import vtkMeshQuality
r = vtkXMLUnstructuredGridReader(); r.SetFileName(sys.argv[1]); r.Update()
q = vtkMeshQuality(); q.SetInputConnection(r.GetOutputPort()); q.SetHexQualityMeasureToScaledJacobian(); q.Update()
a = q.GetOutput().GetCellData().GetArray("Quality")
print(r.GetOutput().GetNumberOfCells(), min(a.GetValue(i) for i in range(a.GetNumberOfTuples())))
"#;
        let o = std::process::Command::new(&py).args(["-c", script, path_str(&out.join("mesh.vtu"))]).output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let text = String::from_utf8(o.stdout).unwrap();
        let mut it = text.split_whitespace();
        let cells: u64 = it.next().unwrap().parse().unwrap();
        let vtk_min: f64 = it.next().unwrap().parse().unwrap();
        let ours = r["lumen"]["scaled_jacobian"]["min"]
            .as_f64()
            .unwrap()
            .min(r["wall"]["scaled_jacobian"]["min"].as_f64().unwrap());
        println!("{name}: vtkMeshQuality min scaled Jacobian {vtk_min:.6}, report {ours:.6}");
        assert_eq!(cells, r["elements"].as_u64().unwrap());
        assert!((vtk_min - ours).abs() <= 0.02, "{name}: VTK {vtk_min} vs report {ours}");
    }
}

/// Runs a failing command and checks the error contract: non-zero exit, one line naming `what`,
/// no panic, nothing left in the output folder.
fn assert_clean_failure(args: &[&str], out: &Path, what: &str) -> String {
    let o = vesselhex(args);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(!o.status.success(), "expected a failure for {args:?}");
    assert!(!err.contains("panicked"), "panic: {err}");
    assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
    assert!(err.contains(what), "the error should name {what}: {err}");
    assert!(files_under(out).is_empty(), "files left behind: {:?}", files_under(out));
    err
}

fn mesh_args<'a>(surface: &'a str, cl: &'a str, out: &'a str) -> Vec<&'a str> {
    vec!["mesh", "--surface", surface, "--centerlines", cl, "--output", out, "--quiet"]
}

#[test]
fn bad_inputs_fail_clearly_and_leave_nothing() {
    let dir = temp_dir("bad");
    let (stl, csv) = fixture("straight");
    let (stl, csv) = (path_str(&stl).to_string(), path_str(&csv).to_string());
    let out = dir.join("out");
    let outs = path_str(&out).to_string();

    // truncated binary STL
    let bytes = std::fs::read(&stl).unwrap();
    let truncated = dir.join("truncated.stl");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    assert_clean_failure(&mesh_args(path_str(&truncated), &csv, &outs), &out, "truncated.stl");
    // empty STL
    let empty = dir.join("empty.stl");
    std::fs::write(&empty, b"").unwrap();
    assert_clean_failure(&mesh_args(path_str(&empty), &csv, &outs), &out, "empty.stl");
    // NaN coordinates
    let nan = dir.join("nan.stl");
    std::fs::write(&nan, "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 nan\nvertex 0 1 0\nendloop\nendfacet\nendsolid x\n").unwrap();
    assert_clean_failure(&mesh_args(path_str(&nan), &csv, &outs), &out, "nan.stl");
    // centerline without radius
    let norad = dir.join("norad.csv");
    std::fs::write(&norad, "x,y,z\n0,0,0\n0,0,30\n").unwrap();
    assert_clean_failure(&mesh_args(&stl, path_str(&norad), &outs), &out, "norad.csv");
    // centerline outside the surface: shifted sideways by 2.5 radii
    let text = std::fs::read_to_string(&csv).unwrap();
    let shifted: String = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i == 0 {
                return format!("{l}\n");
            }
            let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            format!("{},{},{},{}\n", v[0] + 5.0, v[1], v[2], v[3])
        })
        .collect();
    let outside = dir.join("outside.csv");
    std::fs::write(&outside, shifted).unwrap();
    assert_clean_failure(&mesh_args(&stl, path_str(&outside), &outs), &out, "outside");
    // centerline in metres while the surface is in mm: units off by 1000
    let metres: String = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i == 0 {
                return format!("{l}\n");
            }
            let v: Vec<f64> = l.split(',').map(|x| x.parse::<f64>().unwrap() / 1000.0).collect();
            format!("{},{},{},{}\n", v[0], v[1], v[2], v[3])
        })
        .collect();
    let m = dir.join("metres.csv");
    std::fs::write(&m, metres).unwrap();
    let e = assert_clean_failure(&mesh_args(&stl, path_str(&m), &outs), &out, "metres.csv");
    assert!(e.contains("units"), "{e}");
    // a hole in the middle of the surface: rays miss
    let holed = dir.join("holed.stl");
    write_stl_without_triangles_near(&stl, &holed, 15.0);
    let e = assert_clean_failure(&mesh_args(path_str(&holed), &csv, &outs), &out, "holed.stl");
    assert!(e.contains("miss"), "{e}");
    // unwritable output folder: its parent is a file
    let blocker = dir.join("blocker");
    std::fs::write(&blocker, b"x").unwrap();
    let bad_out = blocker.join("out");
    let o = vesselhex(&mesh_args(&stl, &csv, path_str(&bad_out)));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("output") && !err.contains("panicked"), "{err}");
    // unknown format
    let o =
        vesselhex(&["mesh", "--surface", &stl, "--centerlines", &csv, "--output", &outs, "--formats", "vtu,nastran"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("nastran"));
    assert!(files_under(&out).is_empty());
}

/// Copies a binary STL, dropping the triangles whose centroid lies within 1 mm of z = `z`.
/// Writes `src` less its triangles within 1 mm of height `z` on the +x side: a hole in one
/// side of the wall (a band all around would cut the vessel in two pieces, refused as such).
fn write_stl_without_triangles_near(src: &str, dst: &Path, z: f64) {
    let b = std::fs::read(src).unwrap();
    let n = u32::from_le_bytes(b[80..84].try_into().unwrap()) as usize;
    let mut kept = vec![];
    for t in 0..n {
        let rec = &b[84 + 50 * t..84 + 50 * (t + 1)];
        let mean = |axis: usize| {
            (0..3)
                .map(|v| {
                    let at = 12 + 12 * v + 4 * axis;
                    f32::from_le_bytes(rec[at..at + 4].try_into().unwrap()) as f64
                })
                .sum::<f64>()
                / 3.0
        };
        if (mean(2) - z).abs() > 1.0 || mean(0) < 0.0 {
            kept.extend_from_slice(rec);
        }
    }
    let mut out = b[..80].to_vec();
    out.extend_from_slice(&((kept.len() / 50) as u32).to_le_bytes());
    out.extend_from_slice(&kept);
    std::fs::write(dst, out).unwrap();
}

/// The hex counts of the summary line ("N lumen + N wall + N extension hexes"), by part.
fn summary_counts(stderr: &str) -> Vec<(String, u64)> {
    let line = stderr.lines().find(|l| l.contains(" lumen + ")).unwrap_or_else(|| panic!("no summary line: {stderr}"));
    let counts = line.trim_start_matches("vesselhex: ").split(';').next().unwrap().trim_end_matches(" hexes");
    counts
        .split(" + ")
        .map(|part| {
            let (n, name) = part.split_once(' ').unwrap_or_else(|| panic!("{part:?} in {line}"));
            (name.to_string(), n.parse().unwrap_or_else(|_| panic!("{n:?} in {line}")))
        })
        .collect()
}

/// The summary line's parts add up to the mesh's hexes: the flow extensions' are counted, with
/// and without them (issue 44: "6160 lumen + 3696 wall" for a mesh of 14176).
#[test]
fn the_summary_line_counts_every_hex_extensions_included() {
    let (stl, csv) = fixture("curved");
    let out = temp_dir("summary-line");
    let case = out.join("case.toml");
    std::fs::write(&case, "[extensions]\nends = \"all\"\n").unwrap();
    for (name, extra) in [("plain", vec![]), ("extended", vec!["--config", path_str(&case)])] {
        let dir = out.join(name);
        let args = [
            &["mesh", "--surface", path_str(&stl), "--centerlines", path_str(&csv)][..],
            &extra,
            &["--output", path_str(&dir)],
        ];
        let o = vesselhex(&args.concat());
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{name}: {stderr}");
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
        let counts = summary_counts(&stderr);
        let total: u64 = counts.iter().map(|c| c.1).sum();
        assert_eq!(total, r["elements"].as_u64().unwrap(), "{name}: {counts:?}");
        let extension: u64 =
            r["extensions"].as_array().into_iter().flatten().map(|e| e["elements"].as_u64().unwrap()).sum();
        let mut expected = vec![
            ("lumen".to_string(), r["lumen"]["elements"].as_u64().unwrap()),
            ("wall".to_string(), r["wall"]["elements"].as_u64().unwrap()),
        ];
        if name == "extended" {
            assert!(extension > 0, "the extensions have hexes");
            expected.push(("extension".to_string(), extension));
        }
        assert_eq!(counts, expected, "{name}");
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// `formats = []` writes report.json alone and says so, in report.json and on stderr.
#[test]
fn an_empty_format_list_warns_that_only_the_report_is_written() {
    let (stl, csv) = fixture("straight");
    let out = temp_dir("no-formats");
    let case = out.join("case.toml");
    std::fs::write(&case, "formats = []\n").unwrap();
    let dir = out.join("mesh");
    let o = vesselhex(
        &["mesh", "--surface", path_str(&stl), "--centerlines", path_str(&csv), "--config", path_str(&case)]
            .into_iter()
            .chain(["--quiet", "--output", path_str(&dir)])
            .collect::<Vec<_>>(),
    );
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let names: Vec<String> =
        files_under(&dir).iter().map(|p| p.file_name().unwrap().to_string_lossy().into()).collect();
    assert_eq!(names, ["report.json"]);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
    let said = |w: &str| w.contains("formats is empty") && w.contains("only report.json");
    let warnings = r["warnings"].as_array().unwrap();
    assert!(
        warnings.iter().any(|w| w["kind"] == "settings" && said(w["message"].as_str().unwrap())),
        "report.json warnings: {warnings:?}"
    );
    assert!(stderr.lines().any(|l| l.starts_with("vesselhex: warning: ") && said(l)), "stderr: {stderr}");
    // Any format named: no such warning.
    std::fs::write(&case, "formats = [\"vtu\"]\n").unwrap();
    let r = mesh_cli(&stl, &csv, &out.join("vtu"), &["--config", path_str(&case)]);
    assert!(!r["warnings"].as_array().unwrap().iter().any(|w| said(w["message"].as_str().unwrap())));
    let _ = std::fs::remove_dir_all(&out);
}
