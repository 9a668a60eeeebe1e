//! The real-vessel cohort meshed from the bare surface (issue 20): every case of
//! `../shared/vessels/manifest.json` (read through `VESSELHEX_VESSELS`) through `vesselhex mesh`
//! with no hint, at the coarse and the medium preset. Prints a table (hexes, minimum scaled
//! Jacobian, wall mean, lumen skew, smallest face pyramid, ends meshed, seconds) and asserts
//! what every case must give: a mesh with no inverted element whose every end is meshed (one
//! of them as an opening in the side of the mesh, [`SIDE_ENDS`]) and whose interface nodes lie
//! on the surface,
//! within the bars as `report.json` says, warning where part of the surface is left out, or
//! else a one-line refusal naming the surface. The cases that
//! mesh within every bar today ([`WITHIN_BARS`], at both presets) must go on doing so.
//! A tree's OpenFOAM case of lumen and wall (`openfoam-fsi`) must pass OpenFOAM's checkMesh.
//! Under CI a missing folder or case, or a missing checkMesh, is a failure.

mod common;

use common::*;
use std::time::Instant;

/// The cases meshed within every bar (minimum scaled Jacobian 0.2, wall mean 0.85, lumen skew
/// 0.35, every face pyramid positive) at both presets; a change that loses one fails here.
/// palabos_cerebral_aneurysm, whose sac holds the bifurcation, is meshed with the sac as the
/// junction (it was refused: its outlets curl back past the junction, and its branches leave it
/// like the legs of a tripod). openlb_aortoiliac_capped's stub is meshed with its neighbour's
/// lumen, its end opened in the side of the mesh (see [`SIDE_ENDS`]).
const WITHIN_BARS: [&str; 18] = [
    "vmtk_aortoiliac",
    "openlb_cerebral_aneurysm_tree",
    "palabos_cerebral_aneurysm",
    "vmtk_abdominal_aorta_segment",
    "aneurisk_C0092_ica_segment",
    "gmsh_carotid_bifurcation",
    "simvascular_demo_aortoiliac",
    "gmsh_aortic_arch",
    "gmsh_cerebral_aneurysm",
    "gmsh_aortic_arch_cm",
    "gmsh_bifurcation",
    "xra_coronary_phantom_tree",
    "dfemtoolz_stenosed_coronary",
    "aneupy_aaa",
    "medlib_voxel_aorta",
    "sphinxsys_pulmonary_bifurcation",
    "sphinxsys_aortic_arch",
    "openlb_aortoiliac_capped",
];

/// The cases whose junctions are meshed at the coarse preset's spacing at the medium preset,
/// said by a `junction_spacing` warning: the three arches, each with two junctions merged as
/// their blocks would overlap (the SPHinXsys arch's bridge along the arch had 285 elements
/// inverted at 0.3 radii). Every other case's junctions are spaced as the preset asks.
const JUNCTIONS_COARSENED: [&str; 3] = ["gmsh_aortic_arch", "gmsh_aortic_arch_cm", "sphinxsys_aortic_arch"];

/// The cases whose mesh leaves part of the surface out, said by a `surface_not_meshed` warning:
/// none since a saccular aneurysm's sac is meshed as a blind branch closed by a dome.
const SURFACE_LEFT_OUT: [&str; 0] = [];

/// The cases whose sac is meshed: a branch named `sac` closed by a dome (outlet end `dome`),
/// and an end of kind `sac` in `report.json`, meshed.
const SACS: [&str; 1] = ["gmsh_cerebral_aneurysm"];

/// The cases whose sac holds a junction (a bifurcation aneurysm), meshed as that junction: its
/// elements in the sac are counted in `report.json` (`sac_elements`), and no other junction's.
/// The OpenLB tree's aneurysm holds one of its junctions since its surface is wound and numbered
/// canonically (issue 45: its centerlines moved with the medial axis's samples), every bar held.
const SAC_JUNCTIONS: [&str; 2] = ["palabos_cerebral_aneurysm", "openlb_cerebral_aneurysm_tree"];

/// The cases whose mesh stops well short of a vessel end, said by an `end_cut_short` warning:
/// none since sections may meet a wall leaning up to 40 degrees into a dome (the voxel aorta's
/// outlet dome was left 50 mm short), and none again since a rounded end is found on its axis
/// (the pulmonary bifurcation's blunt end, found in a corner of its face once its surface was
/// wound and numbered canonically, was left short).
const ENDS_CUT_SHORT: [&str; 0] = [];

/// The cases with a branch too short for its junction's transition, meshed with its
/// neighbour's lumen and its end opened in the side of the mesh, said by a `side_end` warning
/// (and in `report.json`'s `side_ends`, the opening's faces covering at least
/// [`SIDE_END_COVER`] of its cap): the capped aorto-iliac's stub, 10.1 mm of branch where the
/// transition needs 15 mm, fused with an iliac all along. Its end was left out before (exit 3).
const SIDE_ENDS: [&str; 1] = ["openlb_aortoiliac_capped"];

/// An opening's faces cover at least this share of its cap's area (the staircase of the mesh's
/// faces inside the cap's rim, less the faces too skewed to be a boundary). The capped
/// aorto-iliac's stub: 0.76-0.77 until its surface was wound and numbered canonically (issue 45),
/// 0.54 since, at coarse and medium (the mesh moved with the medial axis's samples).
const SIDE_END_COVER: f64 = 0.5;

/// Interface nodes must lie on the lumen surface to this (um).
const ON_SURFACE_UM: f64 = 1.0;

fn cohort_at(preset: &str) {
    let Some(vessels) = vessels_dir() else { return };
    let cases = manifest(&vessels);
    assert!(cases.len() >= 18, "the manifest lists {} cases", cases.len());
    let root = temp_dir(&format!("cohort-{preset}"));
    let foam = openfoam_available(&format!("cohort at {preset}"));
    println!(
        "{preset}: {:<32} {:>8} {:>7} {:>7} {:>7} {:>7} {:>6} {:>6}  result",
        "case", "hexes", "min SJ", "wall", "skew", "pyramid", "ends", "s"
    );
    let mut failures = vec![];
    let expected_within = |name: &str| WITHIN_BARS.contains(&name);
    for case in &cases {
        let surface = vessels.join(&case.name).join(&case.surface);
        assert!(surface.exists(), "{}: {} is missing", case.name, surface.display());
        let out = root.join(&case.name);
        let unit = case.unit.to_string();
        let args = ["mesh", "--surface", path_str(&surface), "--units", &unit, "--preset", preset];
        let clock = Instant::now();
        // A tree's OpenFOAM case, lumen and wall, goes to checkMesh (below).
        let tree = case.ends > 2;
        let formats = if tree { "vtu,openfoam-fsi" } else { "vtu" };
        let o = vesselhex(&[&args[..], &["--formats", formats, "--output", path_str(&out), "--quiet"]].concat());
        let seconds = clock.elapsed().as_secs_f64();
        let stderr = String::from_utf8_lossy(&o.stderr);
        if o.status.code() == Some(1) {
            // A refusal: one line, naming the surface.
            let error = stderr.lines().find(|l| l.starts_with("vesselhex: error:")).unwrap_or_default();
            println!("{preset}: {:<32} {:>61.1}  refused: {}", case.name, seconds, error);
            if !error.contains(&case.surface) || expected_within(&case.name) {
                failures.push(format!("{}: {error}", case.name));
            }
            continue;
        }
        if o.status.code() != Some(0) {
            failures.push(format!("{}: exit {:?} (expected 0): {stderr}", case.name, o.status.code()));
            continue;
        }
        let report: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
        let number = |pointer: &str| report_number(&report, pointer);
        let min_sj = number("/lumen/scaled_jacobian/min").min(number("/wall/scaled_jacobian/min"));
        let (wall_mean, skew) = (number("/wall/scaled_jacobian/mean"), number("/lumen/equiangle_skew/mean"));
        // OpenFOAM's face pyramids (checkMesh fails a mesh with one not positive).
        let pyramid = number("/lumen/face_pyramid/min").min(number("/wall/face_pyramid/min"));
        let ends = report["ends"].as_array().unwrap();
        let meshed = ends.iter().filter(|e| e["meshed"] == true).count();
        let within = report["within_bars"] == true;
        println!(
            "{preset}: {:<32} {:>8} {min_sj:>7.3} {wall_mean:>7.3} {skew:>7.3} {pyramid:>7.3} {:>6} {seconds:>6.1}  {}",
            case.name,
            number("/elements") as usize,
            format!("{meshed}/{}", ends.len()),
            if within { "within the bars" } else { "below a bar" }
        );
        let bars_hold = min_sj >= 0.2 && wall_mean >= 0.85 && skew <= 0.35 && pyramid > 0.0;
        let warned = |kind: &str| report["warnings"].as_array().unwrap().iter().any(|w| w["kind"] == kind);
        let (left_out, cut_short) = (warned("surface_not_meshed"), warned("end_cut_short"));
        let coarsened = warned("junction_spacing");
        let sac_end = ends.iter().any(|e| e["kind"] == "sac" && e["meshed"] == true);
        let sac_branch =
            report["branches"].as_array().unwrap().iter().any(|b| b["name"] == "sac" && b["outlet_end"] == "dome");
        let has_sac = sac_end && sac_branch;
        let side_ends = report["side_ends"].as_array().cloned().unwrap_or_default();
        let side_end = SIDE_ENDS.contains(&case.name.as_str());
        let side_covered = side_ends.iter().all(|s| {
            s["area"].as_f64().unwrap() >= SIDE_END_COVER * s["cap_area"].as_f64().unwrap()
                && s["faces"].as_u64() > Some(0)
        });
        let sac_junctions =
            report["junctions"].as_array().unwrap().iter().filter(|j| j["sac_elements"].as_u64() > Some(0)).count();
        let checks = [
            (min_sj > 0.0, format!("an inverted element (min scaled Jacobian {min_sj:.3})")),
            (meshed == ends.len() && ends.len() >= case.ends, format!("{meshed} of {} ends meshed", ends.len())),
            (!warned("branch_not_meshed") && !warned("end_not_meshed"), "an end or a branch not meshed".to_string()),
            (
                warned("side_end") == side_end && side_ends.len() == side_end as usize,
                format!("{} side ends, side_end warned: {}", side_ends.len(), warned("side_end")),
            ),
            (side_covered, format!("a side end covers less than {SIDE_END_COVER} of its cap: {side_ends:?}")),
            (
                number("/surface_accuracy/node_to_surface_um/max") < ON_SURFACE_UM,
                "interface nodes off the surface".to_string(),
            ),
            (within == bars_hold, format!("within_bars is {within} for these figures")),
            (within || !expected_within(&case.name), "no longer within the bars".to_string()),
            (
                left_out == SURFACE_LEFT_OUT.contains(&case.name.as_str()),
                format!("surface_not_meshed warned: {left_out}"),
            ),
            (cut_short == ENDS_CUT_SHORT.contains(&case.name.as_str()), format!("end_cut_short warned: {cut_short}")),
            (
                coarsened == (preset == "medium" && JUNCTIONS_COARSENED.contains(&case.name.as_str())),
                format!("junction_spacing warned: {coarsened}"),
            ),
            (has_sac == SACS.contains(&case.name.as_str()), format!("a sac meshed: {has_sac}")),
            (
                sac_junctions == SAC_JUNCTIONS.contains(&case.name.as_str()) as usize,
                format!("{sac_junctions} junctions holding a sac"),
            ),
        ];
        failures.extend(checks.into_iter().filter(|c| !c.0).map(|c| format!("{}: {}", case.name, c.1)));
        if tree && foam {
            check_mesh(&out.join("openfoam-fsi"), &[]);
        }
    }
    let _ = std::fs::remove_dir_all(&root);
    assert!(failures.is_empty(), "{preset}:\n{}", failures.join("\n"));
}

#[test]
fn every_real_surface_meshes_or_is_refused_by_name_at_coarse() {
    cohort_at("coarse");
}

#[test]
fn every_real_surface_meshes_or_is_refused_by_name_at_medium() {
    cohort_at("medium");
}
