//! Input readers on the real vessel files (from `VESSELHEX_VESSELS`, default `../shared/vessels`)
//! and on synthetic bad inputs.

use nalgebra::Point3;
use std::path::{Path, PathBuf};
use vesselhex::input::{read_centerlines, read_surface, read_surface_with_report, Centerlines, TriangleSurface};
use vesselhex::units::LengthUnit;
use vesselhex::Error;

/// The vessels folder, or `None` (test skipped) when it is missing outside CI.
fn vessels() -> Option<PathBuf> {
    let dir = std::env::var_os("VESSELHEX_VESSELS")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/vessels"));
    if dir.is_dir() {
        return Some(dir);
    }
    assert!(std::env::var("CI").as_deref() != Ok("true"), "vessels folder not found at {}", dir.display());
    println!("skipped: vessels folder not found");
    None
}

fn bbox(points: impl IntoIterator<Item = Point3<f64>>) -> (Point3<f64>, Point3<f64>) {
    let mut lo = Point3::from([f64::INFINITY; 3]);
    let mut hi = Point3::from([f64::NEG_INFINITY; 3]);
    for p in points {
        lo = lo.inf(&p);
        hi = hi.sup(&p);
    }
    (lo, hi)
}

fn diagonal(points: impl IntoIterator<Item = Point3<f64>>) -> f64 {
    let (lo, hi) = bbox(points);
    (hi - lo).norm()
}

/// Structural checks every surface must pass.
fn check_surface(s: &TriangleSurface) {
    let n = s.vertices.len() as u32;
    assert!(s.triangles.iter().flatten().all(|&i| i < n), "{}: index out of range", s.source.display());
    assert!(s.triangles.iter().all(|&[a, b, c]| a != b && b != c && a != c));
    assert!(s.vertices.iter().all(|p| p.iter().all(|c| c.is_finite())));
    if let Some((_, tags)) = &s.triangle_tags {
        assert_eq!(tags.len(), s.triangles.len());
    }
}

/// Structural checks every centerline set must pass; radii are compared with the surface size.
fn check_centerlines(c: &Centerlines, surface_diagonal: Option<f64>) {
    for p in &c.polylines {
        assert!(p.points.len() >= 2);
        if let Some(r) = &p.radii {
            assert_eq!(r.len(), p.points.len());
            assert!(r.iter().all(|&r| r > 0.0), "{}: non-positive radius", c.source.display());
            if let Some(d) = surface_diagonal {
                assert!(r.iter().all(|&r| r < 0.25 * d), "{}: radius too large vs surface", c.source.display());
            }
        }
        if let Some(n) = &p.normals {
            assert_eq!(n.len(), p.points.len());
            assert!(n.iter().all(|v| (v.norm() - 1.0).abs() < 1e-9));
        }
    }
}

fn stl_header_count(path: &Path) -> usize {
    let bytes = std::fs::read(path).unwrap();
    if bytes.len() == 84 + 50 * u32::from_le_bytes(bytes[80..84].try_into().unwrap()) as usize {
        u32::from_le_bytes(bytes[80..84].try_into().unwrap()) as usize
    } else {
        String::from_utf8(bytes).unwrap().lines().filter(|l| l.trim() == "endloop").count()
    }
}

#[test]
fn real_stl_surfaces() {
    let Some(dir) = vessels() else { return };
    for (file, unit, expect_diag_mm) in [
        ("vmtk_abdominal_aorta_segment/aorta-surface-segment-2.stl", LengthUnit::Mm, (100.0, 300.0)),
        ("vmtk_aortoiliac/aorta-surface-open-ends.stl", LengthUnit::Mm, (50.0, 400.0)),
        ("vmtk_aortoiliac/aorta-surface.stl", LengthUnit::Mm, (50.0, 400.0)),
        ("gmsh_carotid_bifurcation/carotid.stl", LengthUnit::M, (20.0, 200.0)),
        ("gmsh_aortic_arch/aorta.stl", LengthUnit::M, (50.0, 500.0)),
        ("palabos_cerebral_aneurysm/aneurysm.stl", LengthUnit::Mm, (0.01, 1.0)),
    ] {
        let path = dir.join(file);
        let (s, report) = read_surface_with_report(&path, unit).unwrap();
        check_surface(&s);
        let announced = stl_header_count(&path);
        assert_eq!(s.triangles.len() + report.degenerate_triangles_dropped, announced, "{file}");
        // A closed or open triangulated tube has about half as many vertices as triangles.
        let ratio = s.vertices.len() as f64 / s.triangles.len() as f64;
        assert!((0.45..0.6).contains(&ratio), "{file}: vertices were not merged ({ratio})");
        let d = diagonal(s.vertices.iter().copied());
        assert!(d > expect_diag_mm.0 && d < expect_diag_mm.1, "{file}: diagonal {d} mm");
        println!(
            "{file}: {} vertices, {} triangles, {} degenerate dropped, diagonal {d:.4} mm",
            s.vertices.len(),
            s.triangles.len(),
            report.degenerate_triangles_dropped
        );
    }
}

#[test]
fn units_scale_the_carotid() {
    let Some(dir) = vessels() else { return };
    let path = dir.join("gmsh_carotid_bifurcation/carotid.stl");
    let metres = read_surface(&path, LengthUnit::M).unwrap();
    let raw = read_surface(&path, LengthUnit::Mm).unwrap();
    let (lo, hi) = bbox(metres.vertices.iter().copied());
    let extent = hi - lo;
    assert!(extent.max() > 10.0 && extent.max() < 100.0, "carotid extent {extent:?} mm");
    assert!((metres.vertices[5] - raw.vertices[5] * 1000.0).norm() < 1e-9);
}

#[test]
fn real_vtp_surfaces() {
    let Some(dir) = vessels() else { return };
    let path = dir.join("aneurisk_C0092_ica_segment/C0092_clip1_0.vtp");
    let (s, report) = read_surface_with_report(&path, LengthUnit::Mm).unwrap();
    check_surface(&s);
    assert_eq!(s.vertices.len(), 13005);
    assert_eq!(report.polygons_fanned, 62);
    assert!(s.triangles.len() > 25772, "the 62 polygons add fan triangles");
    assert!(s.triangle_tags.is_none());
    println!("C0092_clip1_0.vtp: {} points, {} triangles, {report:?}", s.vertices.len(), s.triangles.len());

    let path = dir.join("simvascular_demo_aortoiliac/demo.vtp");
    let (s, report) = read_surface_with_report(&path, LengthUnit::Cm).unwrap();
    check_surface(&s);
    assert_eq!(s.vertices.len(), 7319);
    assert_eq!(s.triangles.len() + report.degenerate_triangles_dropped, 14634);
    let (name, tags) = s.triangle_tags.as_ref().expect("ModelFaceID");
    assert_eq!(name, "ModelFaceID");
    let mut ids: Vec<i64> = tags.clone();
    ids.sort_unstable();
    ids.dedup();
    assert_eq!(ids, vec![1, 2, 3, 4, 5]);
    let d = diagonal(s.vertices.iter().copied());
    assert!(d > 100.0 && d < 400.0, "demo diagonal {d} mm");
    println!("demo.vtp: {} points, {} triangles, diagonal {d:.1} mm", s.vertices.len(), s.triangles.len());
}

#[test]
fn real_centerlines() {
    let Some(dir) = vessels() else { return };
    let surface_diag = |file: &str, unit| diagonal(read_surface(&dir.join(file), unit).unwrap().vertices);
    struct Case {
        file: &'static str,
        unit: LengthUnit,
        surface: (&'static str, LengthUnit),
        polylines: Option<usize>,
        points: Option<usize>,
        radius: bool,
    }
    let cases = [
        Case {
            file: "aneurisk_C0092_ica_segment/C0092_clip1_mesh1_0.95_ratio_centerline.vtp",
            unit: LengthUnit::Mm,
            surface: ("aneurisk_C0092_ica_segment/C0092_clip1_0.vtp", LengthUnit::Mm),
            polylines: Some(1),
            points: Some(562),
            radius: true,
        },
        Case {
            file: "vmtk_aortoiliac/aorta-centerline.vtp",
            unit: LengthUnit::Mm,
            surface: ("vmtk_aortoiliac/aorta-surface.stl", LengthUnit::Mm),
            polylines: Some(2),
            points: Some(409),
            radius: true,
        },
        Case {
            file: "vmtk_aortoiliac/aorta-centerline-attribute-branches.vtp",
            unit: LengthUnit::Mm,
            surface: ("vmtk_aortoiliac/aorta-surface.stl", LengthUnit::Mm),
            polylines: Some(6),
            points: Some(417),
            radius: true,
        },
        Case {
            file: "simvascular_demo_aortoiliac/demo-centerlines.vtp",
            unit: LengthUnit::Cm,
            surface: ("simvascular_demo_aortoiliac/demo.vtp", LengthUnit::Cm),
            polylines: Some(6),
            points: Some(2354),
            radius: true,
        },
        Case {
            file: "gmsh_carotid_bifurcation/centerlinesCAROTID.vtk",
            unit: LengthUnit::M,
            surface: ("gmsh_carotid_bifurcation/carotid.stl", LengthUnit::M),
            polylines: Some(2),
            points: Some(368),
            radius: true,
        },
        Case {
            file: "gmsh_aortic_arch/centerlinesAORTA.vtk",
            unit: LengthUnit::M,
            surface: ("gmsh_aortic_arch/aorta.stl", LengthUnit::M),
            polylines: None,
            points: None,
            radius: false,
        },
    ];
    for case in cases {
        let c = read_centerlines(&dir.join(case.file), case.unit).unwrap();
        let d = surface_diag(case.surface.0, case.surface.1);
        check_centerlines(&c, Some(d));
        let total: usize = c.polylines.iter().map(|p| p.points.len()).sum();
        if let Some(n) = case.polylines {
            assert_eq!(c.polylines.len(), n, "{}", case.file);
        }
        if let Some(n) = case.points {
            assert_eq!(total, n, "{}", case.file);
        }
        assert!(c.polylines.iter().all(|p| p.radii.is_some() == case.radius), "{}", case.file);
        // Centerlines lie inside the surface's bounding box (with a radius of slack).
        let (lo, hi) = bbox(read_surface(&dir.join(case.surface.0), case.surface.1).unwrap().vertices);
        let slack = 0.05 * d;
        assert!(c
            .polylines
            .iter()
            .flat_map(|p| &p.points)
            .all(|p| p.iter().zip(lo.iter().zip(hi.iter())).all(|(v, (l, h))| *v > l - slack && *v < h + slack)));
        let rmax = c.polylines.iter().flat_map(|p| p.radii.iter().flatten()).fold(0.0f64, |a, &b| a.max(b));
        println!(
            "{}: {} polylines, {total} points, max radius {rmax:.3} mm, tags {:?}",
            case.file,
            c.polylines.len(),
            c.polylines[0].cell_tags.keys().collect::<Vec<_>>()
        );
    }
}

#[test]
fn vmtk_branch_attributes() {
    let Some(dir) = vessels() else { return };
    let c =
        read_centerlines(&dir.join("vmtk_aortoiliac/aorta-centerline-attribute-branches.vtp"), LengthUnit::Mm).unwrap();
    for p in &c.polylines {
        for key in ["CenterlineIds", "TractIds", "Blanking", "GroupIds"] {
            assert!(p.cell_tags.contains_key(key), "missing {key}");
        }
        assert!(p.normals.is_some());
    }
    assert!(c.polylines.iter().any(|p| p.cell_tags["Blanking"] == 1));
}

#[test]
fn gmsh_segments_are_chained() {
    let Some(dir) = vessels() else { return };
    let c = read_centerlines(&dir.join("gmsh_aortic_arch/centerlinesAORTA.vtk"), LengthUnit::M).unwrap();
    let segments: usize = c.polylines.iter().map(|p| p.points.len() - 1).sum();
    assert_eq!(segments, 858, "every segment is used exactly once");
    // gmsh wrote one centerline per outlet (inlet to each of the 4 outlets), each with its own ids.
    assert_eq!(c.polylines.len(), 4, "chained into one polyline per outlet");
    assert_eq!(c.polylines.iter().map(|p| p.points.len()).sum::<usize>(), 862);
    assert!(c.polylines.iter().all(|p| p.radii.is_none() && p.normals.is_none()));
    println!(
        "centerlinesAORTA.vtk: {} polylines of {:?} points",
        c.polylines.len(),
        c.polylines.iter().map(|p| p.points.len()).collect::<Vec<_>>()
    );
}

// ---------- synthetic inputs ----------

/// Writes `bytes` to a fresh file in the temp dir and returns its path.
fn temp_file(name: &str, bytes: &[u8]) -> PathBuf {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "vesselhex-input-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// The error message for a bad input; it must be an `Error::Input` naming the file.
fn input_error<T: std::fmt::Debug>(path: &Path, result: vesselhex::Result<T>) -> String {
    match result {
        Err(e @ Error::Input { .. }) => {
            let text = e.to_string();
            assert!(text.contains(&path.display().to_string()), "message does not name the file: {text}");
            text
        }
        other => panic!("expected an input error for {}, got {other:?}", path.display()),
    }
}

fn surface_error(name: &str, bytes: &[u8]) -> String {
    let path = temp_file(name, bytes);
    input_error(&path, read_surface(&path, LengthUnit::Mm))
}

fn centerline_error(name: &str, bytes: &[u8]) -> String {
    let path = temp_file(name, bytes);
    input_error(&path, read_centerlines(&path, LengthUnit::Mm))
}

const ASCII_STL: &str = "solid t\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n   vertex 0 1 0\n  endloop\n endfacet\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 0 0 0\n   vertex 0 1 0\n  endloop\n endfacet\nendsolid t\n";

fn binary_stl(triangles: &[[[f32; 3]; 3]]) -> Vec<u8> {
    let mut out = b"solid but actually binary".to_vec();
    out.resize(80, b' ');
    out.extend((triangles.len() as u32).to_le_bytes());
    for t in triangles {
        out.extend([0u8; 12]);
        out.extend(t.iter().flatten().flat_map(|c| c.to_le_bytes()));
        out.extend([0u8; 2]);
    }
    out
}

#[test]
fn synthetic_stl_reads_and_merges() {
    let path = temp_file("two.stl", ASCII_STL.as_bytes());
    let (s, report) = read_surface_with_report(&path, LengthUnit::Cm).unwrap();
    assert_eq!((s.vertices.len(), s.triangles.len(), report.degenerate_triangles_dropped), (3, 1, 1));
    assert_eq!(s.vertices[1], Point3::new(10.0, 0.0, 0.0));

    let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let tri2 = [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
    let path = temp_file("b.stl", &binary_stl(&[tri, tri2]));
    let s = read_surface(&path, LengthUnit::Mm).unwrap();
    assert_eq!((s.vertices.len(), s.triangles.len()), (4, 2));
}

#[test]
fn bad_surfaces_are_explained() {
    let e = surface_error("empty.stl", b"");
    assert!(e.contains("empty"), "{e}");
    let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let bytes = binary_stl(&[tri; 3]);
    let e = surface_error("cut.stl", &bytes[..bytes.len() - 30]);
    assert!(e.contains("announces 3 triangles") && e.contains("truncated") && e.contains("204 bytes"), "{e}");
    let e = surface_error("bad.stl", ASCII_STL.replace("vertex 1 0 0", "vertex 1 0 zero").as_bytes());
    assert!(e.contains("line 5"), "{e}");
    let e = surface_error("nan.stl", ASCII_STL.replace("vertex 1 0 0", "vertex 1 NaN 0").as_bytes());
    assert!(e.contains("line 5") && e.contains("non-finite"), "{e}");
    let e = surface_error("inf.stl", &binary_stl(&[[[0.0, 0.0, 0.0], [f32::INFINITY, 0.0, 0.0], [0.0, 1.0, 0.0]]]));
    assert!(e.contains("triangle 0") && e.contains("vertex 2"), "{e}");
    let e = surface_error("surface.obj", b"v 0 0 0\n");
    assert!(e.contains(".obj") && e.contains(".stl") && e.contains(".vtp"), "{e}");
    let e = surface_error("degenerate.stl", ASCII_STL.replace("vertex 1 0 0", "vertex 0 0 0").as_bytes());
    assert!(e.contains("no triangles"), "{e}");
    let e = surface_error(
        "nopoints.vtp",
        br#"<VTKFile type="PolyData"><PolyData><Piece NumberOfPoints="3" NumberOfPolys="0"></Piece></PolyData></VTKFile>"#,
    );
    assert!(e.contains("Points"), "{e}");
    let e = surface_error(
        "lines.vtk",
        b"# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 2 float\n0 0 0 1 0 0\nLINES 1 3\n2 0 1\n",
    );
    assert!(e.contains("no triangles"), "{e}");
    let e = surface_error("range.vtk", b"# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n0 0 0 1 0 0 0 1 0\nPOLYGONS 1 4\n3 0 1 7\n");
    assert!(e.contains("index 7"), "{e}");
}

#[test]
fn bad_centerlines_are_explained() {
    let e = centerline_error("no_header.csv", b"0,0,0,1\n1,0,0,1\n");
    assert!(e.contains("x,y,z,r"), "{e}");
    let e = centerline_error("short_row.csv", b"x,y,z,r\n0,0,0,1\n\n1,0,0\n");
    assert!(e.contains("line 4") && e.contains("fields"), "{e}");
    let e = centerline_error("nan_row.csv", b"x,y,z,r\n0,0,0,1\n1,0,zero,1\n");
    assert!(e.contains("line 3"), "{e}");
    let e = centerline_error("one.csv", b"x,y,z,r\n0,0,0,1\n");
    assert!(e.contains("at least 2"), "{e}");
    let e = centerline_error("neg.csv", b"x,y,z,r\n0,0,0,1\n1,0,0,-1\n");
    assert!(e.contains("radius"), "{e}");
    let e = centerline_error("c.txt", b"x,y,z,r\n");
    assert!(e.contains(".csv"), "{e}");
    let legacy = "# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n0 0 0 1 0 0 2 0 0\nLINES 1 4\n3 0 1 2\n\
                  POINT_DATA 3\nSCALARS MaximumInscribedSphereRadius double 1\nLOOKUP_TABLE default\n1 nan 1\n";
    let e = centerline_error("nan_radius.vtk", legacy.as_bytes());
    assert!(e.contains("MaximumInscribedSphereRadius") && e.contains("point 1"), "{e}");
    let single = legacy.replace("LINES 1 4\n3 0 1 2", "LINES 1 2\n1 0").replace("1 nan 1", "1 1 1");
    let e = centerline_error("single.vtk", single.as_bytes());
    assert!(e.contains("at least 2"), "{e}");
    let good = centerline_error_or_ok("good.csv", b"x,y,z,r,extra\n0,0,0,1,a\n\n1,0,0,2,b\n");
    assert_eq!(good.polylines[0].radii, Some(vec![1.0, 2.0]));
}

fn centerline_error_or_ok(name: &str, bytes: &[u8]) -> Centerlines {
    read_centerlines(&temp_file(name, bytes), LengthUnit::Mm).unwrap()
}

/// Deterministic pseudo-random bytes (xorshift), so failures reproduce.
fn garbage(seed: u64, len: usize) -> Vec<u8> {
    let mut x = seed.max(1);
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
        .collect()
}

#[test]
fn garbage_never_panics() {
    let vtp_prefix = br#"<VTKFile type="PolyData" header_type="UInt64" compressor="vtkZLibDataCompressor"><PolyData><Piece NumberOfPoints="3" NumberOfPolys="1"><Points><DataArray type="Float32" NumberOfComponents="3" format="appended" offset="0"/></Points></Piece></PolyData><AppendedData encoding="raw">_"#;
    for seed in 1..40u64 {
        let noise = garbage(seed, (seed as usize * 37) % 700);
        let mut with_prefix = vtp_prefix.to_vec();
        with_prefix.extend(&noise);
        let mut fake_solid = b"solid ".to_vec();
        fake_solid.extend(&noise);
        for (name, bytes) in
            [("g.stl", &noise), ("g.vtp", &noise), ("g.vtk", &noise), ("h.vtp", &with_prefix), ("s.stl", &fake_solid)]
        {
            let path = temp_file(name, bytes);
            if !bytes.iter().all(u8::is_ascii_whitespace) {
                let _ = read_surface(&path, LengthUnit::Mm);
                let _ = read_centerlines(&path, LengthUnit::Mm);
            }
        }
    }
    // Truncations of a valid VTP never panic either.
    let Some(dir) = vessels() else { return };
    let bytes = std::fs::read(dir.join("vmtk_aortoiliac/aorta-centerline.vtp")).unwrap();
    for cut in (0..bytes.len()).step_by(997) {
        let path = temp_file("cut.vtp", &bytes[..cut]);
        assert!(read_centerlines(&path, LengthUnit::Mm).is_err());
    }
    // Raw appended data cut anywhere before its end.
    let bytes = std::fs::read(dir.join("aneurisk_C0092_ica_segment/C0092_clip1_0.vtp")).unwrap();
    for cut in (0..bytes.len() - 100).step_by(49_999) {
        let path = temp_file("cut.vtp", &bytes[..cut]);
        let e = input_error(&path, read_surface(&path, LengthUnit::Mm));
        assert!(cut < 2000 || e.contains("truncated"), "{e}");
    }
}

#[test]
fn legacy_strips_polygons_and_tags() {
    let text = "# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 5 float\n0 0 0 1 0 0 0 1 0 1 1 0 2 1 0\n\
                POLYGONS 1 5\n4 0 1 3 2\nTRIANGLE_STRIPS 1 5\n4 0 1 2 3\nCELL_DATA 2\nSCALARS face int 1\nLOOKUP_TABLE default\n7 9\n";
    let path = temp_file("strip.vtk", text.as_bytes());
    let (s, report) = read_surface_with_report(&path, LengthUnit::Mm).unwrap();
    assert_eq!(s.triangles, vec![[0, 1, 3], [0, 3, 2], [0, 1, 2], [2, 1, 3]]);
    assert_eq!(s.triangle_tags, Some(("face".to_string(), vec![7, 7, 9, 9])));
    assert_eq!((report.polygons_fanned, report.strips_converted), (1, 1));
}
