//! Vessels fed through several ends (issue 49), without a solver: ends flagged as inlets by the
//! names of their caps, and the refusals of inlets that cannot be. The flow through two inlets
//! is run by OpenFOAM in tests/openfoam.rs.

mod common;

use common::{path_str, temp_dir, vesselhex};
use nalgebra::Point3;
use vesselhex::input::{clean_surface, read_surface, topology::boundary_loops};
use vesselhex::testing::mutations::write_stl;
use vesselhex::units::LengthUnit;

/// The Y fixture's open ends, each closed by a flat fan in a file of its own: (centre, file)
/// per end, the trunk's first (the lowest end: the fixture's trunk runs up the z axis).
fn capped_y(dir: &std::path::Path) -> Vec<(Point3<f64>, std::path::PathBuf)> {
    let surface = read_surface(&common::fixtures_dir().join("y_bifurcation.stl"), LengthUnit::Mm).unwrap();
    let (surface, _) = clean_surface(surface).unwrap();
    let mut caps: Vec<(Point3<f64>, std::path::PathBuf)> = boundary_loops(&surface.triangles)
        .into_iter()
        .enumerate()
        .map(|(k, lp)| {
            let mut vertices: Vec<Point3<f64>> = lp.iter().map(|&v| surface.vertices[v as usize]).collect();
            let centre =
                Point3::from(vertices.iter().map(|p| p.coords).sum::<nalgebra::Vector3<f64>>() / lp.len() as f64);
            vertices.push(centre);
            let n = lp.len() as u32;
            let fan: Vec<[u32; 3]> = (0..n).map(|i| [i, (i + 1) % n, n]).collect();
            let path = dir.join(format!("cap_{k}.stl"));
            write_stl(&path, &vertices, &fan).unwrap();
            (centre, path)
        })
        .collect();
    assert_eq!(caps.len(), 3, "the Y fixture has three open ends");
    caps.sort_by(|a, b| a.0.z.total_cmp(&b.0.z));
    caps
}

/// Caps named `inlet_<x>` are inlets without any `--inlet`: the two daughters' caps named
/// `inlet_left` and `inlet_right`, the trunk's `basilar`. Every end keeps its cap's name, the
/// two named as inlets are the inlets (the larger the one the centerlines start from), and the
/// OpenFOAM case has one patch per end under those names.
#[test]
fn caps_named_inlet_underscore_are_inlets_under_their_own_names() {
    let dir = temp_dir("inlets-caps");
    let caps = capped_y(&dir);
    let names = ["basilar", "inlet_left", "inlet_right"];
    let cap_args: Vec<String> =
        names.iter().zip(&caps).map(|(name, (_, path))| format!("--cap={name}={}", path_str(path))).collect();
    let mut extra = vec!["--preset", "coarse", "--formats", "openfoam"];
    extra.extend(cap_args.iter().map(String::as_str));
    let out = dir.join("mesh");
    let report = common::mesh_surface_cli(&common::fixtures_dir().join("y_bifurcation.stl"), &out, &extra);
    let ends = report["ends"].as_array().unwrap();
    for (name, (centre, _)) in names.iter().zip(&caps) {
        let end = ends.iter().find(|e| e["name"] == *name).unwrap_or_else(|| panic!("no end {name}: {ends:?}"));
        let at: Vec<f64> = end["position"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
        let gap = (Point3::new(at[0], at[1], at[2]) - centre).norm();
        assert!(gap < end["radius"].as_f64().unwrap(), "{name}: {gap} mm from its cap");
        assert_eq!(end["inlet"] == true, name.starts_with("inlet_"), "{name}: {end}");
        assert_eq!(end["meshed"], true, "{name}");
    }
    let boundary = std::fs::read_to_string(out.join("openfoam/constant/polyMesh/boundary")).unwrap();
    for name in names {
        assert!(boundary.lines().any(|l| l.trim() == name), "no patch {name} in\n{boundary}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Inlets that cannot be are refused in one line before anything is written: a cap name no cap
/// has (the caps given are listed), `auto` with other inlets, a flow rate for an end that is no
/// inlet.
#[test]
fn impossible_inlets_are_refused_in_one_line() {
    let dir = temp_dir("inlets-refused");
    let surface = common::fixtures_dir().join("y_bifurcation.stl");
    let config = dir.join("flows.toml");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(&config, "[openfoam]\ninlet_flow_rates_ml_s = { outlet_1 = 1.0 }\n").unwrap();
    let cases: [(&[&str], &str); 3] = [
        (&["--inlet", "rica"], "--inlet rica: no cap of that name"),
        (&["--inlet", "auto", "--inlet", "1,2,3"], "--inlet auto cannot be given with other"),
        (&["--formats", "openfoam", "--config", path_str(&config)], "no inlet named outlet_1"),
    ];
    for (k, (extra, expected)) in cases.iter().enumerate() {
        let out = dir.join(format!("out_{k}"));
        let mut args = vec!["mesh", "--surface", path_str(&surface), "--output", path_str(&out), "--quiet"];
        args.extend_from_slice(&["--preset", "coarse"]);
        args.extend_from_slice(extra);
        let o = vesselhex(&args);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && stderr.contains(expected), "{extra:?}: {stderr}");
        assert_eq!(stderr.trim().lines().count(), 1, "{extra:?}: not one line: {stderr}");
        assert!(!out.exists(), "{extra:?}: {} written", out.display());
    }
    let _ = std::fs::remove_dir_all(&dir);
}
