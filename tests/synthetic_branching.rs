//! Checks of the branching fixtures (`vesselhex::synthetic_branching`): the committed
//! `fixtures/y_bifurcation*` and `fixtures/t_junction*`, and a sweep of angles and radius ratios
//! generated into temporary folders as the mesher's tests do. Regenerate the committed files with
//! `cargo test --release --test synthetic_branching regenerate_branching_fixtures -- --ignored`
//! (or `vesselhex fixtures --output fixtures`).

mod common;

use common::{assert_same_as_committed, fixtures_dir, ScratchDir};
use nalgebra::{Point3, Vector3};
use std::collections::{HashMap, HashSet};
use std::fs;
use std::path::Path;
use std::sync::OnceLock;
use std::time::Instant;
use vesselhex::input::{read_centerlines, read_surface_with_report, Centerlines};
use vesselhex::surface::LumenSurface;
use vesselhex::synthetic_branching::{
    branching_fixture_paths, default_branching_fixtures, min_angle_deg, write_all_branching_fixtures,
    write_branching_fixture, BranchingFixture, BranchingSurface, Opening, TJunction, YBifurcation,
};
use vesselhex::units::LengthUnit;
use vesselhex::Error;

/// A surface as the mesher reads it (binary STL through `vesselhex::input`, f32 vertices welded).
struct Mesh {
    vertices: Vec<Point3<f64>>,
    triangles: Vec<[u32; 3]>,
}

fn read_stl(path: &Path) -> Mesh {
    let bytes = fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let (surface, report) = read_surface_with_report(path, LengthUnit::Mm).unwrap();
    assert_eq!(bytes.len(), 84 + 50 * surface.triangles.len(), "{}: not a binary STL", path.display());
    assert_eq!(report.degenerate_triangles_dropped, 0, "{}", path.display());
    Mesh { vertices: surface.vertices, triangles: surface.triangles }
}

/// The committed fixtures as the mesher reads them: each default fixture with its STL and VTP.
fn committed_fixtures() -> Vec<(BranchingFixture, Mesh, Centerlines)> {
    default_branching_fixtures()
        .unwrap()
        .into_iter()
        .map(|fixture| {
            let (stl, vtp) = branching_fixture_paths(&fixture.name, &fixtures_dir());
            let (mesh, centerlines) = (read_stl(&stl), read_centerlines(&vtp, LengthUnit::Mm).unwrap());
            (fixture, mesh, centerlines)
        })
        .collect()
}

/// The default fixtures with their surfaces as generated (f64), generated once for all the tests
/// of this file.
fn generated_fixtures() -> &'static [(BranchingFixture, BranchingSurface)] {
    static GENERATED: OnceLock<Vec<(BranchingFixture, BranchingSurface)>> = OnceLock::new();
    GENERATED.get_or_init(|| {
        default_branching_fixtures()
            .unwrap()
            .into_iter()
            .map(|fixture| {
                let surface = fixture.generate_surface().unwrap();
                (fixture, surface)
            })
            .collect()
    })
}

/// Largest distance f32 storage can move a vertex at `p`: half an ulp per coordinate.
fn f32_rounding(p: &Point3<f64>) -> f64 {
    3f64.sqrt() * p.coords.amax().max(1.0) * f64::from(f32::EPSILON) / 2.0
}

/// Topology of a triangle mesh, computed here independently of the generator's own checks.
struct Topology {
    /// Undirected edge -> number of triangles.
    edges: HashMap<(u32, u32), usize>,
    /// Boundary loops, each in order.
    loops: Vec<Vec<u32>>,
}

fn topology(mesh: &Mesh) -> Topology {
    let mut directed = HashSet::new();
    let mut edges = HashMap::new();
    for t in &mesh.triangles {
        assert!(t[0] != t[1] && t[1] != t[2] && t[2] != t[0], "degenerate triangle {t:?}");
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            assert!(directed.insert((a, b)), "edge {a}-{b} wound the same way twice (flipped or non-manifold)");
            *edges.entry((a.min(b), a.max(b))).or_insert(0usize) += 1;
        }
    }
    assert!(edges.values().all(|&n| n <= 2), "an edge is shared by more than two triangles");
    // Boundary edges, directed as their single triangle winds them.
    let mut next = HashMap::new();
    for &(a, b) in &directed {
        if !directed.contains(&(b, a)) {
            assert!(next.insert(a, b).is_none(), "vertex {a} starts two boundary edges (pinched boundary)");
        }
    }
    let mut starts: Vec<u32> = next.keys().copied().collect();
    starts.sort_unstable();
    let mut seen = HashSet::new();
    let mut loops = Vec::new();
    for s in starts {
        if seen.contains(&s) {
            continue;
        }
        let mut lp = vec![s];
        seen.insert(s);
        let mut v = next[&s];
        while v != s {
            assert!(seen.insert(v), "boundary walk revisits {v}");
            lp.push(v);
            v = next[&v];
        }
        loops.push(lp);
    }
    Topology { edges, loops }
}

/// Each vertex's triangles form one fan (a disc inside, a half-disc on the boundary).
fn assert_vertex_fans(mesh: &Mesh) {
    let mut link: Vec<Vec<(u32, u32)>> = vec![Vec::new(); mesh.vertices.len()];
    for t in &mesh.triangles {
        for k in 0..3 {
            link[t[k] as usize].push((t[(k + 1) % 3], t[(k + 2) % 3]));
        }
    }
    for (v, pairs) in link.iter().enumerate() {
        assert!(!pairs.is_empty(), "vertex {v} is in no triangle");
        let next: HashMap<u32, u32> = pairs.iter().copied().collect();
        let targets: HashSet<u32> = pairs.iter().map(|p| p.1).collect();
        let open: Vec<u32> = next.keys().filter(|k| !targets.contains(k)).copied().collect();
        assert!(open.len() <= 1, "vertex {v}: {} fans meet there", open.len());
        let start = open.first().copied().unwrap_or(pairs[0].0);
        let (mut x, mut steps) = (start, 0);
        while let Some(&y) = next.get(&x) {
            steps += 1;
            x = y;
            if x == start || steps > pairs.len() {
                break;
            }
        }
        assert_eq!(steps, pairs.len(), "vertex {v}: its triangles do not form one fan");
    }
}

/// Which opening a boundary loop closes: all its vertices on that end plane and circle.
fn loop_opening(mesh: &Mesh, lp: &[u32], openings: &[Opening]) -> Option<usize> {
    openings.iter().position(|o| {
        lp.iter().all(|&v| {
            let p = mesh.vertices[v as usize];
            let tol = 2.0 * f32_rounding(&p);
            (p - o.centre).dot(&o.outward).abs() <= tol && ((p - o.centre).norm() - o.radius).abs() <= tol
        })
    })
}

/// Closed except one boundary loop per opening, each a full ring on its end circle; genus 0.
fn assert_open_ends_only(name: &str, mesh: &Mesh, openings: &[Opening]) {
    let topo = topology(mesh);
    assert_vertex_fans(mesh);
    assert_eq!(topo.loops.len(), openings.len(), "{name}: boundary loops");
    let mut matched = vec![0; openings.len()];
    for lp in &topo.loops {
        let i =
            loop_opening(mesh, lp, openings).unwrap_or_else(|| panic!("{name}: a boundary loop off every end circle"));
        matched[i] += 1;
        // The loop goes once around its circle: its angles add up to one turn.
        let o = &openings[i];
        let u = o
            .outward
            .cross(&Vector3::y())
            .try_normalize(1e-9)
            .unwrap_or_else(|| o.outward.cross(&Vector3::x()).normalize());
        let w = o.outward.cross(&u);
        let angle = |v: u32| {
            let d = mesh.vertices[v as usize] - o.centre;
            d.dot(&w).atan2(d.dot(&u))
        };
        let mut turn = 0.0;
        for k in 0..lp.len() {
            let mut step = angle(lp[(k + 1) % lp.len()]) - angle(lp[k]);
            step -= std::f64::consts::TAU * (step / std::f64::consts::TAU).round();
            assert!(step.abs() < 0.5, "{name}: loop vertices jump by {step} rad");
            turn += step;
        }
        assert!((turn.abs() - std::f64::consts::TAU).abs() < 1e-9, "{name}: loop turns by {turn}");
    }
    assert!(matched.iter().all(|&n| n == 1), "{name}: loops per opening {matched:?}");
    let euler = mesh.vertices.len() as i64 - topo.edges.len() as i64 + mesh.triangles.len() as i64;
    assert_eq!(euler, 2 - openings.len() as i64, "{name}: not a sphere with {} holes", openings.len());
}

/// What every written surface must be: [`assert_open_ends_only`], and no triangle angle under 5°.
/// Returns the smallest angle (degrees).
fn assert_sound_surface(name: &str, mesh: &Mesh, openings: &[Opening]) -> f64 {
    assert_open_ends_only(name, mesh, openings);
    let worst = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
            min_angle_deg(&a, &b, &c)
        })
        .fold(f64::INFINITY, f64::min);
    assert!(worst > 5.0, "{name}: a triangle angle of {worst}°");
    worst
}

/// The mesh closed by a fan over each boundary loop (to its centroid), as a LumenSurface.
fn capped(mesh: &Mesh) -> LumenSurface {
    let topo = topology(mesh);
    let mut vertices = mesh.vertices.clone();
    let mut triangles = mesh.triangles.clone();
    for lp in &topo.loops {
        let centre = lp.iter().map(|&v| vertices[v as usize].coords).sum::<Vector3<f64>>() / lp.len() as f64;
        vertices.push(Point3::from(centre));
        let c = (vertices.len() - 1) as u32;
        // The loop runs as its triangles wind it; the cap must wind it the other way.
        for k in 0..lp.len() {
            triangles.push([lp[(k + 1) % lp.len()], lp[k], c]);
        }
    }
    LumenSurface::from_parts(vertices, triangles, "capped".into()).unwrap()
}

fn signed_volume(s: &LumenSurface) -> f64 {
    s.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| s.vertices[i as usize].coords);
            a.dot(&b.cross(&c)) / 6.0
        })
        .sum()
}

/// Volume of {F < 0} inside every end plane, by the midpoint rule on a grid of spacing `step`.
fn numerical_volume(fixture: &BranchingFixture, step: f64) -> f64 {
    let f = fixture.lumen_function();
    let openings = fixture.openings();
    let mut lo = Point3::from([f64::INFINITY; 3]);
    let mut hi = Point3::from([f64::NEG_INFINITY; 3]);
    for t in &fixture.tubes {
        for p in [t.back_point(), t.front_point()] {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k] - 1.5 * t.radius);
                hi[k] = hi[k].max(p[k] + 1.5 * t.radius);
            }
        }
    }
    let n = [0, 1, 2].map(|k| ((hi[k] - lo[k]) / step).ceil() as usize);
    let mut count = 0usize;
    for i in 0..n[0] {
        for j in 0..n[1] {
            for k in 0..n[2] {
                let p = lo + Vector3::new(i as f64 + 0.5, j as f64 + 0.5, k as f64 + 0.5) * step;
                if openings.iter().all(|o| (p - o.centre).dot(&o.outward) < 0.0) && f.value(&p) < 0.0 {
                    count += 1;
                }
            }
        }
    }
    count as f64 * step.powi(3)
}

#[test]
fn regenerated_fixtures_are_byte_identical_to_the_committed_ones() {
    let scratch = ScratchDir::new("regen");
    let written = write_all_branching_fixtures(&scratch.0).unwrap();
    assert_eq!(written.len(), 2 * default_branching_fixtures().unwrap().len());
    assert_same_as_committed(&written);
    let leftovers: Vec<_> = fs::read_dir(&scratch.0).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(leftovers.len(), 4, "temporary files left behind: {leftovers:?}");
}

#[test]
fn committed_files_are_small_and_read_back() {
    for (fixture, _, centerlines) in committed_fixtures() {
        let (stl, vtp) = branching_fixture_paths(&fixture.name, &fixtures_dir());
        for path in [&stl, &vtp] {
            let size = fs::metadata(path).unwrap().len();
            assert!(size < 2_000_000, "{}: {size} bytes", path.display());
        }
        let openings = fixture.openings();
        assert_eq!(centerlines.polylines.len(), openings.len() - 1, "{}: one path per outlet", fixture.name);
        for (id, line) in centerlines.polylines.iter().enumerate() {
            assert_eq!(line.cell_tags.get("CenterlineIds"), Some(&(id as i64)));
            let radii = line.radii.as_ref().expect("MaximumInscribedSphereRadius");
            assert_eq!(radii.len(), line.points.len());
            // Inlet to outlet: the parent's free end to this path's end circle, exactly.
            assert!((line.points[0] - openings[0].centre).norm() < 1e-12, "{}: path {id} start", fixture.name);
            let end = *line.points.last().unwrap();
            assert!((end - openings[id + 1].centre).norm() < 1e-12, "{}: path {id} end", fixture.name);
            for pair in line.points.windows(2) {
                let step = (pair[1] - pair[0]).norm();
                assert!(
                    step > 0.0 && step <= fixture.centerline_spacing * (1.0 + 1e-12),
                    "{}: step {step}",
                    fixture.name
                );
            }
        }
        // The paths overlap along the parent up to the branch's anchor.
        let [a, b] = [&centerlines.polylines[0], &centerlines.polylines[1]];
        let shared = a.points.iter().zip(&b.points).take_while(|(p, q)| p == q).count();
        let anchor = fixture.tubes[openings[2].tube].anchor;
        assert!(
            (a.points[shared - 1] - anchor).norm() < 1e-12,
            "{}: paths part at {:?}",
            fixture.name,
            a.points[shared - 1]
        );
    }
}

#[test]
fn vertices_lie_on_the_analytic_surface() {
    for ((fixture, surface), (_, mesh, _)) in generated_fixtures().iter().zip(committed_fixtures()) {
        let f = fixture.lumen_function();
        // In f64, as generated: on F = 0 to 1e-12 relative (first-order distance |F| / |∇F|).
        let worst =
            surface.vertices.iter().map(|p| f.distance_estimate(p) / p.coords.norm().max(1.0)).fold(0.0, f64::max);
        assert!(worst < 1e-12, "{}: a vertex is {worst:e} (relative) off the surface", fixture.name);
        // As committed: within f32 rounding of it.
        for p in &mesh.vertices {
            let d = f.distance_estimate(p);
            assert!(d <= f32_rounding(p), "{}: stored vertex {p:?} is {d:e} mm off", fixture.name);
        }
        println!("{}: worst relative vertex offset in f64 {worst:.1e}", fixture.name);
    }
}

/// Past each tube's separation distance the surface is the exact tube: every vertex there is at
/// the tube's radius from its axis (a check of the implicit function against plain geometry).
#[test]
fn far_from_the_junction_the_surface_is_the_exact_tube() {
    for (fixture, surface) in generated_fixtures() {
        let mut checked = 0;
        for o in fixture.openings() {
            let t = &fixture.tubes[o.tube];
            for p in &surface.vertices {
                let along = (p - t.anchor).dot(&o.outward);
                let radial = (p - t.anchor) - t.direction * (p - t.anchor).dot(&t.direction);
                // Other tubes stay at least r + 2k from the axis there (the separation's
                // definition), so what is nearer belongs to this tube.
                if along > o.separation + 1e-9
                    && along <= o.length + 1e-9
                    && radial.norm() < t.radius + fixture.blend_width
                {
                    assert!(
                        (radial.norm() - t.radius).abs() < 1e-12 * (1.0 + p.coords.norm()),
                        "{} {p:?}",
                        fixture.name
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > surface.vertices.len() / 2, "{}: only {checked} vertices past the separations", fixture.name);
    }
}

#[test]
fn committed_surfaces_are_manifold_with_one_open_loop_per_end() {
    for (fixture, mesh, _) in committed_fixtures() {
        let worst = assert_sound_surface(&fixture.name, &mesh, &fixture.openings());
        println!(
            "{}: {} triangles, {} vertices, smallest angle {worst:.1}°",
            fixture.name,
            mesh.triangles.len(),
            mesh.vertices.len()
        );
    }
}

#[test]
fn normals_point_out_of_the_lumen_and_the_volume_matches() {
    for (fixture, mesh, _) in committed_fixtures() {
        let f = fixture.lumen_function();
        // Every triangle faces the way F grows.
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
            let normal = (b - a).cross(&(c - a)).normalize();
            let centroid = Point3::from((a.coords + b.coords + c.coords) / 3.0);
            let outward = f.value_gradient(&centroid).1.normalize();
            assert!(normal.dot(&outward) > 0.5, "{}: triangle {t:?} faces {normal:?}", fixture.name);
        }
        // Closed by flat caps, the surface bounds the lumen with a positive volume.
        let volume = signed_volume(&capped(&mesh));
        let expected = numerical_volume(&fixture, 0.05);
        let rel = (volume - expected) / expected;
        assert!(volume > 0.0 && rel.abs() < 0.01, "{}: volume {volume} vs {expected} ({rel:+.4})", fixture.name);
        // Sanity of the reference: the blended union holds at least the plain tubes' volume
        // minus their overlap, bounded by the sum of the tubes.
        let tubes: f64 = fixture
            .tubes
            .iter()
            .map(|t| std::f64::consts::PI * t.radius * t.radius * (t.back.length() + t.front.length()))
            .sum();
        assert!(expected < tubes * 1.02 && expected > tubes * 0.9, "{}: {expected} vs tubes {tubes}", fixture.name);
        println!("{}: volume {volume:.3} mm³, grid {expected:.3} ({rel:+.2e}), tubes {tubes:.3}", fixture.name);
    }
}

/// How far a winding number may lie from 1 inside and 0 outside a closed surface: they are
/// summed with far clusters expanded (`vesselhex::geometry::winding`, within 1.3e-3 of the
/// exact sum as measured there).
const WINDING_TOLERANCE: f64 = 2e-3;

#[test]
fn centerline_points_are_inside_and_radii_match_the_surface() {
    for (fixture, mesh, centerlines) in committed_fixtures() {
        let closed = capped(&mesh);
        let open = LumenSurface::from_parts(mesh.vertices.clone(), mesh.triangles.clone(), "open".into()).unwrap();
        let openings = fixture.openings();
        let longest_edge = mesh
            .triangles
            .iter()
            .flat_map(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
            .map(|(a, b)| (mesh.vertices[a as usize] - mesh.vertices[b as usize]).norm())
            .fold(0.0, f64::max);
        let smallest_radius = fixture.tubes.iter().map(|t| t.radius).fold(f64::INFINITY, f64::min);
        let sag_bound = longest_edge.powi(2) / (8.0 * smallest_radius);
        let (mut worst_far, mut far_points, mut worst_any): (f64, usize, f64) = (0.0, 0, 0.0);
        for line in &centerlines.polylines {
            let radii = line.radii.as_ref().unwrap();
            let n = line.points.len();
            for (k, (p, &r)) in line.points.iter().zip(radii).enumerate() {
                let w = closed.winding_number(p);
                if k == 0 || k == n - 1 {
                    // On a cap (at its fan's centre, where the winding number is undefined):
                    // inside just before it, outside just past it.
                    let o = openings.iter().find(|o| (o.centre - p).norm() < 1e-12).expect("an end circle centre");
                    let before = closed.winding_number(&(p - o.outward * 0.01));
                    let past = closed.winding_number(&(p + o.outward * 0.01));
                    assert!(
                        (before - 1.0).abs() < WINDING_TOLERANCE && past.abs() < WINDING_TOLERANCE,
                        "{}: end {p:?}: {before}, {past}",
                        fixture.name
                    );
                } else {
                    assert!((w - 1.0).abs() < WINDING_TOLERANCE, "{}: point {p:?} winding {w}", fixture.name);
                }
                // The radius is the distance to the analytic surface. Vertices lie on it, so it
                // is never more than the distance to the nearest vertex; the triangles are chords
                // of it, at most their sag nearer: e² / 8ρ for edges up to e on a surface of
                // curvature radius ρ >= the smallest tube radius (the fillets are flatter).
                let to_triangles = open.closest(p).distance;
                let to_vertex = mesh.vertices.iter().map(|v| (v - p).norm()).fold(f64::INFINITY, f64::min);
                assert!(r <= to_vertex + 1e-6, "{}: radius {r} > vertex distance {to_vertex}", fixture.name);
                assert!((r - to_triangles).abs() < sag_bound, "{}: radius {r} vs {to_triangles}", fixture.name);
                worst_any = worst_any.max((r - to_triangles).abs() / r);
                // Far from the junction: exactly the tube radius, and where the lumen is convex the
                // triangles are inside it (nearer by their sag).
                let far = openings.iter().skip(1).find_map(|o| {
                    let t = &fixture.tubes[o.tube];
                    let along = (p - t.anchor).dot(&o.outward);
                    let on_axis = ((p - t.anchor) - o.outward * along).norm() < 1e-9;
                    (on_axis && along > o.separation + t.radius && along < o.length - t.radius).then_some(t.radius)
                });
                let far = far.or_else(|| {
                    let o = &openings[0];
                    let along = (p - o.centre).dot(&o.outward);
                    (-along > o.radius && -along < o.length - o.separation - o.radius).then_some(o.radius)
                });
                if let Some(tube_radius) = far {
                    assert!(
                        (r - tube_radius).abs() < 1e-9 * tube_radius,
                        "{}: radius {r} vs tube {tube_radius}",
                        fixture.name
                    );
                    let sag = r - to_triangles;
                    assert!(
                        sag > -1e-6 && sag < longest_edge.powi(2) / (8.0 * tube_radius),
                        "{}: at {p:?} radius {r} vs distance to the triangles {to_triangles}",
                        fixture.name
                    );
                    worst_far = worst_far.max(sag / r);
                    far_points += 1;
                }
            }
        }
        assert!(far_points > 40, "{}: {far_points} far points", fixture.name);
        println!(
            "{}: radius vs distance to the triangles (longest edge {longest_edge:.3} mm): far from the junction \
             (n = {far_points}) {worst_far:.1e}, anywhere {worst_any:.1e} (relative)",
            fixture.name
        );
    }
}

/// Near the junction the radius is the inscribed sphere's, never below the tube radius and
/// above the branch's radius where the branch's axis runs through the junction.
#[test]
fn junction_radius_is_the_inscribed_sphere() {
    for (fixture, surface) in generated_fixtures() {
        let lines = fixture.centerlines(surface).unwrap();
        let openings = fixture.openings();
        for (line, o) in lines.polylines.iter().zip(&openings[1..]) {
            let radii = line.radii.as_ref().unwrap();
            let t = &fixture.tubes[o.tube];
            for (p, &r) in line.points.iter().zip(radii) {
                assert!(
                    r >= t.radius.min(fixture.tubes[0].radius) * (1.0 - 1e-12),
                    "{}: radius {r} at {p:?}",
                    fixture.name
                );
            }
            if o.tube != 0 {
                let k = line.points.iter().position(|p| *p == t.anchor).expect("anchor on the path");
                let widest = radii[k..].iter().copied().fold(0.0, f64::max);
                assert!(
                    widest > 1.1 * t.radius,
                    "{}: {} is never wider than its radius ({widest})",
                    fixture.name,
                    t.name
                );
            }
        }
    }
}

#[test]
fn a_sweep_of_angles_and_ratios_gives_manifold_outward_surfaces() {
    let scratch = ScratchDir::new("sweep");
    println!("{:<14} {:>9} {:>9} {:>10} {:>9}", "fixture", "triangles", "vertices", "min angle", "time (s)");
    for angle in [30.0, 45.0, 60.0, 90.0] {
        for ratio in [1.0, 2.0, 4.0] {
            let cases = [
                YBifurcation::symmetric(angle, ratio).fixture(&format!("y_{angle}_{ratio}")).unwrap(),
                TJunction::with(angle, ratio).fixture(&format!("t_{angle}_{ratio}")).unwrap(),
            ];
            for fixture in cases {
                let start = Instant::now();
                let written = write_branching_fixture(&fixture, &scratch.0).unwrap();
                let seconds = start.elapsed().as_secs_f64();
                let mesh = read_stl(&written.stl);
                let openings = fixture.openings();
                let worst = assert_sound_surface(&fixture.name, &mesh, &openings);
                let volume = signed_volume(&capped(&mesh));
                assert!(volume > 0.0, "{}: volume {volume}", fixture.name);
                // Each tube is at least free_length_radii of its radii long past its separation.
                for o in &openings {
                    assert!(o.length - o.separation >= fixture.free_length_radii * o.radius - 1e-9);
                }
                let lines = read_centerlines(&written.centerlines, LengthUnit::Mm).unwrap();
                assert_eq!(lines.polylines.len(), openings.len() - 1);
                println!(
                    "{:<14} {:>9} {:>9} {:>9.1}° {:>9.2}",
                    fixture.name,
                    mesh.triangles.len(),
                    mesh.vertices.len(),
                    worst,
                    seconds
                );
            }
        }
    }
}

#[test]
fn bad_parameters_are_refused_with_the_parameter_named() {
    let refused = |r: vesselhex::Result<BranchingFixture>, what: &str| match r {
        Err(Error::Config(message)) => assert!(message.contains(what), "{message}"),
        other => panic!("{what}: expected a refusal, got {other:?}"),
    };
    refused(
        YBifurcation { half_angles_deg: [0.0, 30.0], ..YBifurcation::default() }.fixture("y"),
        "half-angle of daughter 1",
    );
    refused(
        YBifurcation { half_angles_deg: [30.0, 95.0], ..YBifurcation::default() }.fixture("y"),
        "half-angle of daughter 2",
    );
    refused(
        YBifurcation { daughter_radii: [1.0, -1.0], ..YBifurcation::default() }.fixture("y"),
        "radius of daughter 2",
    );
    refused(YBifurcation { parent_radius: f64::NAN, ..YBifurcation::default() }.fixture("y"), "parent radius");
    refused(TJunction { branch_radius: 3.0, ..TJunction::default() }.fixture("t"), "branch radius");
    refused(TJunction { branch_angle_deg: 5.0, ..TJunction::default() }.fixture("t"), "branch angle");
    refused(TJunction { cell_size: Some(1.0), ..TJunction::default() }.fixture("t"), "cell size");
    refused(TJunction { free_length_radii: 1.0, ..TJunction::default() }.fixture("t"), "free length");
    refused(TJunction { blend_width: Some(0.0), ..TJunction::default() }.fixture("t"), "blend width");
}

/// Writes the branching fixtures into `fixtures/` (run on purpose only).
#[test]
#[ignore = "rewrites the committed fixtures"]
fn regenerate_branching_fixtures() {
    for fixture in default_branching_fixtures().unwrap() {
        let start = Instant::now();
        let w = write_branching_fixture(&fixture, &fixtures_dir()).unwrap();
        println!(
            "{}: {} triangles, {} vertices, {:.2} s; {} ({} bytes), {} ({} bytes)",
            fixture.name,
            w.surface.triangles.len(),
            w.surface.vertices.len(),
            start.elapsed().as_secs_f64(),
            w.stl.display(),
            fs::metadata(&w.stl).unwrap().len(),
            w.centerlines.display(),
            fs::metadata(&w.centerlines).unwrap().len()
        );
    }
}

/// Same surface and centerlines with one worker thread as with the default pool.
#[test]
fn output_does_not_depend_on_the_thread_count() {
    let fixture = TJunction::with(60.0, 2.0).fixture("t_60_2").unwrap();
    let surface = fixture.generate_surface().unwrap();
    let lines = fixture.centerlines(&surface).unwrap();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let (single, single_lines) = pool.install(|| {
        let s = fixture.generate_surface().unwrap();
        let l = fixture.centerlines(&s).unwrap();
        (s, l)
    });
    assert!(surface == single, "the surface depends on the thread count");
    for (a, b) in lines.polylines.iter().zip(&single_lines.polylines) {
        assert!(a.points == b.points && a.radii == b.radii, "the centerlines depend on the thread count");
    }
}
