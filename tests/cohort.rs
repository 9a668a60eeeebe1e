//! The real-vessel cohort from the bare surface (issue 19): every case of
//! `../shared/vessels/manifest.json` (read through `VESSELHEX_VESSELS`), centerlines computed
//! with no hint. Prints a table (case, ends found / true ends, distance to the case's own
//! centerline over the radius where it ships one, seconds) and asserts the floor: every true end
//! found, at most two extra, one path per outlet, every path point inside the lumen (away from
//! the end points). Under CI a
//! missing folder or case is a failure.

mod common;

use common::*;
use nalgebra::Point3;
use std::time::Instant;
use vesselhex::centerline_extract::{extract_centerlines, ExtractOptions};
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
/// issue's bar: median distance 2 % and 95th percentile 10 % of the radius. (The others were
/// computed on a smoothed surface or another reconstruction; their figures are printed.)
const SAME_SURFACE_REFERENCES: [&str; 2] = ["vmtk_aortoiliac", "simvascular_demo_aortoiliac"];

/// Distance from `p` to the polylines (mm).
fn to_polylines(p: &Point3<f64>, lines: &[CenterlinePolyline]) -> f64 {
    let segment = |a: &Point3<f64>, b: &Point3<f64>| {
        let ab = b - a;
        let t = if ab.norm_squared() > 0.0 { ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0) } else { 0.0 };
        (a + ab * t - p).norm()
    };
    lines.iter().flat_map(|l| l.points.windows(2).map(|w| segment(&w[0], &w[1]))).fold(f64::INFINITY, f64::min)
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

#[test]
fn every_real_surface_gives_every_end_and_paths_inside_the_lumen() {
    let Some(vessels) = vessels_dir() else { return };
    let cases = manifest(&vessels);
    assert!(cases.len() >= 18, "the manifest lists {} cases", cases.len());
    println!("{:<34} {:>11} {:>8} {:>8} {:>8} {:>7}", "case", "ends/true", "inside", "d/r med", "d/r p95", "s");
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
        let (mut median, mut p95) = (f64::NAN, f64::NAN);
        if let Some((_, file)) = REFERENCES.iter().find(|(n, _)| *n == case.name) {
            let reference = read_centerlines(&dir.join(file), case.unit).unwrap();
            // Our points against the reference, away from the ends (within a radius of an end
            // the two stop at different places by construction).
            let mut d: Vec<f64> = lines
                .iter()
                .flat_map(|l| l.points.iter().zip(l.radii.as_ref().unwrap()))
                .filter(|(p, r)| !ex.ends.iter().any(|e| (*p - e.centre).norm() < e.radius.max(**r)))
                .map(|(p, r)| to_polylines(p, &reference.polylines) / r)
                .collect();
            (median, p95) = (percentile(&mut d, 0.5), percentile(&mut d, 0.95));
        }
        let figure = |x: f64| if x.is_nan() { "-".to_string() } else { format!("{x:.3}") };
        println!(
            "{:<34} {:>5} / {:<3} {:>8} {:>8} {:>8} {seconds:>7.2}",
            case.name,
            ex.ends.len(),
            case.ends,
            format!("{in_lumen}/{interior}"),
            figure(median),
            figure(p95)
        );
        if ex.ends.len() < case.ends || ex.ends.len() > case.ends + 2 {
            failures.push(format!("{}: {} ends found, {} true", case.name, ex.ends.len(), case.ends));
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
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
