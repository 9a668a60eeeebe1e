//! The real-vessel cohort from the bare surface (issue 19): every case of
//! `../shared/vessels/manifest.json` (read through `VESSELHEX_VESSELS`), centerlines computed
//! with no hint. Prints a table (case, ends found / true ends, distance to the case's own
//! centerline over the radius where it ships one, the reference's depth where the two differ
//! most, seconds) and asserts the floor: every true end found, at most two extra, one path per
//! outlet, every path point inside the lumen (away from the end points), agreement with VMTK's
//! centerlines of the same surface, and no reference more central than ours where they differ
//! most. Under CI a missing folder or case is a failure.

mod common;

use common::*;
use nalgebra::Point3;
use std::time::Instant;
use vesselhex::centerline_extract::{extract_centerlines, EndKind, ExtractOptions, Extraction};
use vesselhex::input::{clean_surface, read_centerlines, read_surface, topology, CenterlinePolyline, TriangleSurface};
use vesselhex::surface::LumenSurface;

/// The centerline each case ships, where it has one.
const REFERENCES: [(&str, &str); 6] = [
    ("vmtk_aortoiliac", "aorta-centerline.vtp"),
    ("aneurisk_C0092_ica_segment", "C0092_clip1_mesh1_0.95_ratio_centerline.vtp"),
    ("gmsh_carotid_bifurcation", "centerlinesCAROTID.vtk"),
    ("simvascular_demo_aortoiliac", "demo-centerlines.vtp"),
    ("gmsh_aortic_arch", "centerlinesAORTA.vtk"),
    ("xra_coronary_phantom_tree", "centerlines.vtk"),
];

/// Where the reference was computed by VMTK on this very surface, ours must agree with it to the
/// issue's bar: median distance 2 % and 95th percentile 10 % of the radius. The ICA's reference
/// is VMTK's too, its radius this surface's distance to 0.3 % (median). (The others were
/// computed on a smoothed surface or another reconstruction, or by another tool; their figures
/// are printed.)
const SAME_SURFACE_REFERENCES: [&str; 3] =
    ["vmtk_aortoiliac", "simvascular_demo_aortoiliac", "aneurisk_C0092_ica_segment"];

/// Where ours and the reference differ most (their distance at or above its 95th percentile),
/// the reference's point is not the more central one: the median of its distance to the wall
/// over ours is at most this. (Before the paths were centred on the depth's ridge, the ICA's
/// was 1.010 and the VMTK aorta's 1.017: ours ran beside the deepest points.)
const MOST_DIFFERENT_DEPTH_RATIO: f64 = 1.01;

/// The point of the polylines' segments closest to `p`.
/// The cases with a saccular aneurysm beside the vessels whose sac is found as one (an end of
/// kind sac): palabos_cerebral_aneurysm's sac holds the junction itself, and is not a pocket
/// of the tree.
const SACS: [&str; 1] = ["gmsh_cerebral_aneurysm"];

fn closest_on_polylines(p: &Point3<f64>, lines: &[CenterlinePolyline]) -> Point3<f64> {
    let segment = |a: &Point3<f64>, b: &Point3<f64>| {
        let ab = b - a;
        let t = if ab.norm_squared() > 0.0 { ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0) } else { 0.0 };
        a + ab * t
    };
    let points = lines.iter().flat_map(|l| l.points.windows(2).map(|w| segment(&w[0], &w[1])));
    points.min_by(|a, b| (a - p).norm().total_cmp(&(b - p).norm())).unwrap()
}

fn percentile(values: &mut [f64], q: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    values[((values.len() - 1) as f64 * q).round() as usize]
}

/// The surface closed by a fan on each boundary loop, facing out: a point is inside the lumen
/// when its generalised winding number (`LumenSurface::winding_number`) is above one half.
/// Unlike a normal's sign at the closest point, this does not depend on which triangle is
/// closest.
fn closed(surface: &TriangleSurface) -> LumenSurface {
    let loops = topology::boundary_loops(&surface.triangles);
    // Hygiene wound the triangles outward (a positive signed volume).
    let (vertices, triangles) = topology::close_with_caps(&surface.vertices, &surface.triangles, &loops, -1.0);
    LumenSurface::from_parts(vertices, triangles, surface.source.clone()).unwrap()
}

/// Our points against the reference, away from the ends (within a radius of an end the two stop
/// at different places by construction): the median and 95th percentile of the distance over
/// our radius, and where that distance is at or above its 95th percentile, the median of the
/// reference point's depth in `lumen` over our radius.
fn against_reference(ex: &Extraction, reference: &[CenterlinePolyline], lumen: &LumenSurface) -> (f64, f64, f64) {
    let near_end = |p: &Point3<f64>, r: f64| ex.ends.iter().any(|e| (p - e.centre).norm() < e.radius.max(r));
    let pairs: Vec<(f64, f64)> = ex
        .centerlines
        .polylines
        .iter()
        .flat_map(|l| l.points.iter().zip(l.radii.as_ref().unwrap()))
        .filter(|(p, r)| !near_end(p, **r))
        .map(|(p, r)| {
            let q = closest_on_polylines(p, reference);
            ((q - p).norm() / r, lumen.closest(&q).distance / r)
        })
        .collect();
    let mut d: Vec<f64> = pairs.iter().map(|x| x.0).collect();
    let (median, p95) = (percentile(&mut d, 0.5), percentile(&mut d, 0.95));
    let mut depth: Vec<f64> = pairs.iter().filter(|x| x.0 >= p95).map(|x| x.1).collect();
    (median, p95, percentile(&mut depth, 0.5))
}

#[test]
fn every_real_surface_gives_every_end_and_paths_inside_the_lumen() {
    let Some(vessels) = vessels_dir() else { return };
    let cases = manifest(&vessels);
    assert!(cases.len() >= 18, "the manifest lists {} cases", cases.len());
    println!(
        "{:<34} {:>11} {:>8} {:>8} {:>8} {:>8} {:>7}",
        "case", "ends/true", "inside", "d/r med", "d/r p95", "depth95", "s"
    );
    let mut failures = vec![];
    for case in &cases {
        let dir = vessels.join(&case.name);
        let path = dir.join(&case.surface);
        assert!(path.exists(), "{}: {} is missing", case.name, path.display());
        let (surface, _) = clean_surface(read_surface(&path, case.unit).unwrap()).unwrap();
        let clock = Instant::now();
        let extraction = extract_centerlines(&surface, &ExtractOptions::default());
        let seconds = clock.elapsed().as_secs_f64();
        let ex = match extraction {
            Ok(ex) => ex,
            Err(e) => {
                println!("{:<34} failed: {e}", case.name);
                failures.push(format!("{}: {e}", case.name));
                continue;
            }
        };
        let lines = &ex.centerlines.polylines;
        let closed = closed(&surface);
        // Inside, away from the end points themselves (an open end's centre lies in its loop).
        let (mut interior, mut in_lumen) = (0usize, 0usize);
        for l in lines {
            let radii = l.radii.as_ref().unwrap();
            for (p, r) in l.points.iter().zip(radii) {
                let near_end = ex.ends.iter().any(|e| (p - e.centre).norm() < e.radius.max(*r));
                if !near_end {
                    interior += 1;
                    in_lumen += usize::from(closed.winding_number(p) > 0.5);
                }
            }
        }
        let (mut median, mut p95, mut depth_ratio) = (f64::NAN, f64::NAN, f64::NAN);
        if let Some((_, file)) = REFERENCES.iter().find(|(n, _)| *n == case.name) {
            let reference = read_centerlines(&dir.join(file), case.unit).unwrap();
            (median, p95, depth_ratio) =
                against_reference(&ex, &reference.polylines, &LumenSurface::new(&surface).unwrap());
        }
        let figure = |x: f64| if x.is_nan() { "-".to_string() } else { format!("{x:.3}") };
        // A saccular aneurysm's sac is an end of the tree, not a vessel end.
        let sacs = ex.ends.iter().filter(|e| e.kind == EndKind::Sac).count();
        let vessel_ends = ex.ends.len() - sacs;
        println!(
            "{:<34} {:>5} / {:<3} {:>8} {:>8} {:>8} {:>8} {seconds:>7.2}{}",
            case.name,
            vessel_ends,
            case.ends,
            format!("{in_lumen}/{interior}"),
            figure(median),
            figure(p95),
            figure(depth_ratio),
            if sacs > 0 { format!("  + {sacs} sac") } else { String::new() }
        );
        if vessel_ends < case.ends || vessel_ends > case.ends + 2 {
            failures.push(format!("{}: {vessel_ends} vessel ends found, {} true", case.name, case.ends));
        }
        if sacs != usize::from(SACS.contains(&case.name.as_str())) {
            failures.push(format!("{}: {sacs} sac(s) found", case.name));
        }
        if lines.len() + 1 != ex.ends.len() {
            failures.push(format!("{}: {} paths for {} ends", case.name, lines.len(), ex.ends.len()));
        }
        if in_lumen < interior {
            failures.push(format!(
                "{}: {} of {interior} path points outside the lumen",
                case.name,
                interior - in_lumen
            ));
        }
        if SAME_SURFACE_REFERENCES.contains(&case.name.as_str()) && !(median <= 0.02 && p95 <= 0.10) {
            failures.push(format!("{}: d/r median {median:.3} p95 {p95:.3} against its VMTK centerline", case.name));
        }
        if depth_ratio > MOST_DIFFERENT_DEPTH_RATIO {
            failures.push(format!(
                "{}: where ours and the reference differ most, the reference lies deeper ({depth_ratio:.3} of our \
                 radius)",
                case.name
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
