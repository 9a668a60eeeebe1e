//! `vesselhex batch` (issue 48): the cases of a manifest meshed N at a time, each in a process
//! of its own, with `summary.csv` and `summary.json`. On the bundled fixtures: a broken row is one
//! failed row with its cause while the others are meshed, each mesh byte for byte the one
//! `vesselhex mesh` writes alone; a rerun skips what is done, meshes again what a changed setting
//! touches, and `--force` everything; the memory plan is said. On every real vessel of
//! `../shared/vessels` (`VESSELHEX_VESSELS`) with `--jobs 2` at the coarse preset: 18 rows, each
//! the figures of its case's `report.json`, a rerun that skips all 18, and a broken row added
//! to them failing alone. Under CI a missing vessels folder is a failure.

mod common;

use common::*;
use serde_json::Value;
use std::path::Path;
use std::process::Output;

fn batch(manifest: &Path, output: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["batch", path_str(manifest), "--output", path_str(output)];
    args.extend_from_slice(extra);
    vesselhex(&args)
}

fn summary_json(output: &Path) -> Vec<Value> {
    let text = std::fs::read_to_string(output.join("summary.json")).expect("summary.json");
    serde_json::from_str::<Value>(&text).unwrap().as_array().expect("a list of rows").clone()
}

/// The rows of summary.csv as (column, field) maps.
fn summary_csv(output: &Path) -> Vec<Vec<(String, String)>> {
    let mut reader = csv::Reader::from_path(output.join("summary.csv")).expect("summary.csv");
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    reader.records().map(|r| header.iter().cloned().zip(r.unwrap().iter().map(String::from)).collect()).collect()
}

fn row_of<'a>(rows: &'a [Value], case: &str) -> &'a Value {
    rows.iter().find(|r| r["case"] == case).unwrap_or_else(|| panic!("no row for {case}"))
}

/// The row's figures are those of the case's report.json, read here on their own.
fn assert_row_is_the_report(row: &Value, output: &Path) {
    let case = row["case"].as_str().unwrap();
    let text = std::fs::read_to_string(output.join(case).join("report.json")).unwrap();
    let report: Value = serde_json::from_str(&text).unwrap();
    let ends = report["ends"].as_array().unwrap();
    let meshed = ends.iter().filter(|e| e["meshed"] == true).count();
    let min =
        report_number(&report, "/lumen/scaled_jacobian/min").min(report_number(&report, "/wall/scaled_jacobian/min"));
    let expected = [
        ("ends_found", Value::from(ends.len())),
        ("ends_meshed", Value::from(meshed)),
        ("exit", Value::from(if meshed == ends.len() { 0 } else { 3 })),
        ("hexes", report["elements"].clone()),
        ("min_scaled_jacobian", Value::from(min)),
        ("wall_mean_scaled_jacobian", report["wall"]["scaled_jacobian"]["mean"].clone()),
        ("lumen_mean_skew", report["lumen"]["equiangle_skew"]["mean"].clone()),
        ("node_to_surface_max_um", report["surface_accuracy"]["node_to_surface_um"]["max"].clone()),
        ("surface_to_mesh_max_um", report["surface_accuracy"]["surface_to_mesh_um"]["max"].clone()),
        ("within_bars", report["within_bars"].clone()),
    ];
    for (column, value) in expected {
        assert_eq!(row[column], value, "{case}: {column} in the summary is not report.json's");
    }
    assert!(row["seconds"].as_f64().unwrap() > 0.0, "{case}: no seconds");
    assert!(row["peak_memory_mib"].as_f64().unwrap() > 1.0, "{case}: no peak memory");
    assert!(row["fingerprint"].as_str().is_some_and(|f| f.len() == 16), "{case}: no fingerprint");
}

/// summary.csv says what summary.json says, row for row.
fn assert_csv_is_the_json(output: &Path) {
    let json = summary_json(output);
    let csv = summary_csv(output);
    assert_eq!(csv.len(), json.len());
    for (c, j) in csv.iter().zip(&json) {
        for (column, field) in c {
            let value = &j[column.as_str()];
            let same = match value {
                Value::Null => field.is_empty(),
                Value::String(s) => s == field,
                Value::Number(n) => field.parse::<f64>().ok() == n.as_f64(),
                other => *field == other.to_string(),
            };
            assert!(same, "{}: {column} is '{field}' in summary.csv but {value} in summary.json", j["case"]);
        }
    }
}

fn statuses(output: &Path) -> Vec<String> {
    summary_json(output).iter().map(|r| r["status"].as_str().unwrap().to_string()).collect()
}

#[test]
fn a_broken_row_fails_alone_and_a_rerun_meshes_only_what_changed() {
    let dir = temp_dir("batch-fixtures");
    let fixtures = fixtures_dir();
    let (aaa, aaa_cl) = (fixtures.join("aaa.stl"), fixtures.join("aaa_centerline.csv"));
    let y = fixtures.join("y_bifurcation.stl");
    let write_manifest = |aaa_formats: &str| {
        let manifest = dir.join("cases.csv");
        let text = format!(
            "case,surface,centerlines,formats\nbroken,missing/nothing.stl,,\naaa,{},{},{aaa_formats}\ny,{},,\n",
            aaa.display(),
            aaa_cl.display(),
            y.display()
        );
        std::fs::write(&manifest, text).unwrap();
        manifest
    };
    let manifest = write_manifest("");
    let out = dir.join("out");
    let o = batch(&manifest, &out, &["--jobs", "2", "--quiet"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(4), "a failed case: exit 4; {stderr}");
    let rows = summary_json(&out);
    let names: Vec<&str> = rows.iter().map(|r| r["case"].as_str().unwrap()).collect();
    assert_eq!(names, ["broken", "aaa", "y"], "the manifest's order");
    let broken = row_of(&rows, "broken");
    assert_eq!((broken["status"].as_str(), broken["exit"].as_i64()), (Some("failed"), Some(1)));
    let cause = broken["cause"].as_str().unwrap();
    assert!(
        cause.contains(&format!("{}", dir.join("missing/nothing.stl").display())),
        "the cause names the file: {cause}"
    );
    assert!(!cause.contains('\n') && broken["hexes"].is_null() && !out.join("broken").exists());
    assert!(
        stderr.contains("case broken failed: ") && stderr.contains("nothing.stl"),
        "said even when quiet: {stderr}"
    );
    for case in ["aaa", "y"] {
        let row = row_of(&rows, case);
        assert_eq!(row["status"], "meshed");
        assert_row_is_the_report(row, &out);
    }
    assert_csv_is_the_json(&out);
    // Each mesh is the one `vesselhex mesh` writes alone.
    let alone = dir.join("alone");
    mesh_cli(&aaa, &aaa_cl, &alone.join("aaa"), &[]);
    mesh_surface_cli(&y, &alone.join("y"), &[]);
    for case in ["aaa", "y"] {
        let (a, b) = (
            std::fs::read(out.join(case).join("mesh.vtu")).unwrap(),
            std::fs::read(alone.join(case).join("mesh.vtu")).unwrap(),
        );
        assert!(a == b, "{case}: the batch's mesh.vtu differs from vesselhex mesh's");
    }

    // A rerun skips what is done (the figures as before), and tries the broken row again.
    let o = batch(&manifest, &out, &["--jobs", "2", "--quiet"]);
    assert_eq!(o.status.code(), Some(4));
    assert_eq!(statuses(&out), ["failed", "skipped", "skipped"]);
    for (before, after) in rows.iter().zip(summary_json(&out)).skip(1) {
        for column in ["hexes", "min_scaled_jacobian", "within_bars", "seconds", "peak_memory_mib", "fingerprint"] {
            assert_eq!(before[column], after[column], "{}: {column}", before["case"]);
        }
    }
    // A case's folder meshed again by hand with other settings is not done any more.
    mesh_surface_cli(&y, &out.join("y"), &["--formats", "vtu,abaqus"]);
    batch(&manifest, &out, &["--jobs", "2", "--quiet"]);
    assert_eq!(statuses(&out), ["failed", "skipped", "meshed"]);
    assert!(!out.join("y/abaqus").exists());
    // A setting changed on one row meshes that case again, and only it.
    let manifest = write_manifest("vtu;calculix");
    batch(&manifest, &out, &["--jobs", "2", "--quiet"]);
    assert_eq!(statuses(&out), ["failed", "meshed", "skipped"]);
    assert!(out.join("aaa/calculix/model.inp").is_file());
    // --force meshes everything again; with --max-memory beyond the machine, one at a time, said.
    let o = batch(&manifest, &out, &["--jobs", "2", "--force", "--max-memory", "1000T"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(statuses(&out), ["failed", "meshed", "meshed"]);
    assert!(stderr.contains("memory: one job at a time, not 2: --max-memory 1000.0 TiB is more than the"), "{stderr}");
    assert!(stderr.contains("3 cases: 2 meshed, 0 skipped (done before), 1 failed"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_manifest_that_cannot_be_read_is_one_line_and_nothing_is_meshed() {
    let dir = temp_dir("batch-bad-manifest");
    let manifest = dir.join("cases.csv");
    std::fs::write(&manifest, "case,surface,colour\na,a.stl,red\n").unwrap();
    let o = batch(&manifest, &dir.join("out"), &[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.contains("cases.csv: the header names the column 'colour', which is not a setting"), "{stderr}");
    assert!(!dir.join("out").exists(), "nothing written");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every real vessel in one batch: 18 rows, each its report.json's figures; a rerun skips all;
/// a broken row added to them (in a CSV naming the same files) fails alone.
#[test]
fn every_real_vessel_in_one_batch_with_two_jobs() {
    let Some(vessels) = vessels_dir() else { return };
    let cases = manifest(&vessels);
    let dir = temp_dir("batch-vessels");
    let out = dir.join("out");
    let o = batch(&vessels.join("manifest.json"), &out, &["--jobs", "2", "--preset", "coarse", "--quiet"]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let rows = summary_json(&out);
    assert_eq!(rows.len(), cases.len());
    assert_eq!(rows.len(), 18);
    println!("{:<34} {:>7} {:>6} {:>7} {:>8}", "case", "hexes", "min SJ", "s", "MiB");
    for (row, case) in rows.iter().zip(&cases) {
        assert_eq!(row["case"], case.name.as_str());
        assert_eq!(row["status"], "meshed");
        assert_row_is_the_report(row, &out);
        println!(
            "{:<34} {:>7} {:>6.3} {:>7.2} {:>8.1}",
            case.name,
            row["hexes"],
            row["min_scaled_jacobian"].as_f64().unwrap(),
            row["seconds"].as_f64().unwrap(),
            row["peak_memory_mib"].as_f64().unwrap()
        );
    }
    assert_csv_is_the_json(&out);
    // A sample meshed alone: the same bytes (the Python test compares all 18 with mesh_many's).
    for case in cases.iter().filter(|c| {
        ["vmtk_aortoiliac", "palabos_cerebral_aneurysm", "sphinxsys_aortic_arch"].contains(&c.name.as_str())
    }) {
        let alone = dir.join("alone").join(&case.name);
        let surface = vessels.join(&case.name).join(&case.surface);
        mesh_surface_cli(&surface, &alone, &["--units", case.unit.name(), "--preset", "coarse"]);
        let same = std::fs::read(alone.join("mesh.vtu")).unwrap()
            == std::fs::read(out.join(&case.name).join("mesh.vtu")).unwrap();
        assert!(same, "{}: the batch's mesh.vtu differs from vesselhex mesh's", case.name);
    }

    let o = batch(&vessels.join("manifest.json"), &out, &["--jobs", "2", "--preset", "coarse", "--quiet"]);
    assert_eq!(o.status.code(), Some(0));
    assert!(statuses(&out).iter().all(|s| s == "skipped"), "{:?}", statuses(&out));

    // The same files named in a CSV, with a broken row among them.
    let mut csv = String::from("case,surface,units\n");
    for case in &cases[..9] {
        csv += &format!("{},{},{}\n", case.name, vessels.join(&case.name).join(&case.surface).display(), case.unit);
    }
    csv += "broken,nowhere/lumen.stl,mm\n";
    for case in &cases[9..] {
        csv += &format!("{},{},{}\n", case.name, vessels.join(&case.name).join(&case.surface).display(), case.unit);
    }
    let manifest = dir.join("cases.csv");
    std::fs::write(&manifest, csv).unwrap();
    let o = batch(&manifest, &out, &["--jobs", "2", "--preset", "coarse", "--quiet"]);
    assert_eq!(o.status.code(), Some(4));
    let rows = summary_json(&out);
    assert_eq!(rows.len(), 19);
    let failed: Vec<&Value> = rows.iter().filter(|r| r["status"] == "failed").collect();
    assert_eq!(failed.len(), 1);
    assert_eq!(failed[0]["case"], "broken");
    assert!(failed[0]["cause"].as_str().unwrap().contains("nowhere/lumen.stl"), "{}", failed[0]["cause"]);
    assert_eq!(rows.iter().filter(|r| r["status"] == "skipped").count(), 18);
    let _ = std::fs::remove_dir_all(&dir);
}
