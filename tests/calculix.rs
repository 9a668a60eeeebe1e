//! The CalculiX deck, solved by the real `ccx` (2.20, Debian `calculix-ccx`).
//!
//! Without `ccx` the solver tests print "skipped" and pass, unless `CI=true`, where they fail.

mod common;

use common::{ccx_available, frd_displacements, inner_radial, lumen_normal_motion, solve_calculix};
use std::path::{Path, PathBuf};
use vesselhex::config::MeshConfig;
use vesselhex::mesh::{sets, VesselMesh};
use vesselhex::testing::straight_tube_mesh;
use vesselhex::units::LengthUnit;
use vesselhex::writers::inp::{ElementType, MaterialModel, MMHG_IN_MPA};
use vesselhex::writers::{calculix::write_calculix, WriteOptions};

/// A straight tube r = 2 mm, 30 mm long: `around` elements around, axial elements of
/// `axial` mm, wall `thickness` mm with `per_layer` elements in each layer.
fn tube(around: usize, axial: f64, thickness: f64, per_layer: usize, betas: Option<[f64; 3]>) -> VesselMesh {
    let mut c = MeshConfig::default();
    c.lumen.core_elements = around / 4;
    c.lumen.radial_elements = 2;
    c.lumen.axial_spacing_mm = Some(axial);
    c.wall.thickness_mm = Some(thickness);
    c.wall.intima.elements = per_layer;
    c.wall.media.elements = per_layer;
    c.wall.adventitia.elements = per_layer;
    if let Some(b) = betas {
        c.wall.intima.fibre_angle_deg = b[0];
        c.wall.media.fibre_angle_deg = b[1];
        c.wall.adventitia.fibre_angle_deg = b[2];
    }
    straight_tube_mesh(&c).expect("tube meshes").mesh
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("vesselhex-ccx-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn default_fibre_deck_runs_and_every_lumen_node_moves_outward() {
    if !ccx_available() {
        return;
    }
    // 48 around x 30 axial x 3 layers = 4320 wall elements.
    let mesh = tube(48, 1.0, 0.4, 1, None);
    let options = WriteOptions::default();
    let run = solve_calculix(&mesh, &options, "default");
    assert!(run.log.contains("Job finished"));
    let disp = frd_displacements(&run.dir);
    let interface = &mesh.node_sets[sets::INTERFACE_NODES];
    let mut min_ur = f64::INFINITY;
    for &i in interface {
        let p = mesh.nodes[i as usize];
        let u = disp.get(&(i as u64 + 1)).unwrap_or_else(|| panic!("node {} has no displacement", i + 1));
        let ur = (u[0] * p.x + u[1] * p.y) / p.x.hypot(p.y);
        min_ur = min_ur.min(ur);
        assert!(ur > 0.0, "lumen node {} moves inward: u_r = {ur}", i + 1);
    }
    let (mean, r, _) = inner_radial(&mesh, &disp);
    eprintln!(
        "default HGO deck: {} lumen nodes, u_r min {min_ur:.5} mm, mean {mean:.5} mm at r = {r:.4} mm",
        interface.len()
    );
    // The end rings hold axially.
    for end in ["wall_inlet", "wall_outlet"] {
        for &i in &mesh.node_sets[end] {
            assert!(disp[&(i as u64 + 1)][2].abs() < 1e-9, "{end} node {} moves axially", i + 1);
        }
    }
    // The dat file has the lumen ring.
    let dat = std::fs::read_to_string(run.dir.join("model.dat")).unwrap();
    assert!(dat.contains("LUMEN_RING"), "{dat}");
}

#[test]
fn linear_elastic_tube_matches_lame() {
    if !ccx_available() {
        return;
    }
    // Thick wall: a = 2, b = 3 mm, 48 around, 6 elements across, 15 axial: 4320 elements.
    let mesh = tube(48, 2.0, 1.0, 2, None);
    let mut options = WriteOptions::default();
    options.fe.material = MaterialModel::LinearElastic;
    options.fe.calculix_element = ElementType::C3D8I;
    let (e, nu) = (100.0, 0.3);
    for l in [&mut options.material.intima, &mut options.material.media, &mut options.material.adventitia] {
        l.youngs_modulus_kpa = 1e3 * e;
        l.poisson_ratio = nu;
    }
    let run = solve_calculix(&mesh, &options, "lame");
    let disp = frd_displacements(&run.dir);
    let (got, a, _) = inner_radial(&mesh, &disp);
    let outer = &mesh.node_sets[sets::OUTER_WALL_NODES];
    let b = outer.iter().map(|&i| mesh.nodes[i as usize].x.hypot(mesh.nodes[i as usize].y)).sum::<f64>()
        / outer.len() as f64;
    let p = 100.0 * MMHG_IN_MPA;
    // Plane strain (ends held axially): u(a) = (1 + nu) p a / (E (b^2 - a^2)) ((1 - 2 nu) a^2 + b^2).
    let expected = (1.0 + nu) * p * a / (e * (b * b - a * a)) * ((1.0 - 2.0 * nu) * a * a + b * b);
    let error = (got - expected) / expected;
    eprintln!("Lame: a = {a:.5}, b = {b:.5} mm, p = {p} MPa, E = {e}, nu = {nu}: expected u(a) = {expected:.6e} mm, got {got:.6e} mm, error {:.3} %", 100.0 * error);
    assert!(error.abs() < 0.02, "Lame: expected {expected}, got {got}");
}

#[test]
fn circumferential_fibres_stiffen_the_inflation_more_than_axial_ones() {
    if !ccx_available() {
        return;
    }
    let mut options = WriteOptions::default();
    // Stiff enough ground matrix that the tube also holds 100 mmHg with axial fibres (which
    // carry no hoop load under plane strain): a neo-Hookean tube cannot hold more than about
    // mu ln(b/a) = 0.2 ln(1.2) = 0.036 MPa.
    for l in [&mut options.material.intima, &mut options.material.media, &mut options.material.adventitia] {
        l.c_kpa = 200.0;
        l.bulk_kpa = 100.0 * 200.0;
        l.k1_kpa = 100.0;
        l.k2 = 2.0;
    }
    let mut increase = Vec::new();
    for beta in [0.0, 90.0] {
        // 32 around x 30 axial x 3 layers = 2880 wall elements.
        let mesh = tube(32, 1.0, 0.4, 1, Some([beta; 3]));
        let run = solve_calculix(&mesh, &options, &format!("beta{beta}"));
        let disp = frd_displacements(&run.dir);
        let (u, r, min_u) = inner_radial(&mesh, &disp);
        eprintln!(
            "beta = {beta} deg: mean inner radius increase {u:.6} mm ({:.3} % of {r:.4} mm), min {min_u:.6}",
            100.0 * u / r
        );
        assert!(min_u > 0.0);
        increase.push(u);
    }
    assert!(increase[0] < increase[1], "beta 0 gives {} mm, beta 90 gives {} mm", increase[0], increase[1]);
}

#[test]
fn deck_is_deterministic_and_within_field_limits() {
    let mesh = tube(16, 3.0, 0.4, 1, None);
    let mut options = WriteOptions::default();
    let a = scratch("det-a");
    let b = scratch("det-b");
    for element in [ElementType::C3D8I, ElementType::C3D20] {
        options.fe.calculix_element = element;
        write_calculix(&mesh, &options, &a).unwrap();
        write_calculix(&mesh, &options, &b).unwrap();
        let ta = std::fs::read(a.join("calculix/model.inp")).unwrap();
        let tb = std::fs::read(b.join("calculix/model.inp")).unwrap();
        assert!(ta == tb, "not byte-identical");
        let text = String::from_utf8(ta).unwrap();
        let mut in_node = false;
        // Data lines after the title line of *HEADING.
        for line in text.lines().skip(2) {
            if line.starts_with('*') {
                in_node = line.starts_with("*NODE") && !line.starts_with("*NODE ");
                assert!(!line.contains("C3D8H"));
                continue;
            }
            let fields: Vec<&str> = line.split(',').collect();
            assert!(fields.len() <= 16 || (fields.len() == 17 && fields[16].trim().is_empty()), "{line}");
            for f in &fields {
                assert!(f.trim().len() <= 21, "field too wide: {line}");
            }
            if in_node {
                for f in &fields[1..] {
                    let mantissa = f.trim().split('e').next().unwrap().replace(['-', '.'], "");
                    assert!(mantissa.len() >= 12, "{line}");
                }
            }
        }
        if element == ElementType::C3D20 {
            // Element records continue: 16 entries then 5.
            let start = text.find("*ELEMENT, TYPE=C3D20").unwrap();
            let mut lines = text[start..].lines().skip(1);
            assert_eq!(lines.next().unwrap().split(',').count(), 17);
            assert_eq!(lines.next().unwrap().split(',').count(), 5);
        }
    }
    // Two steps: the toe to a tenth of the pressure, then the full pressure (MPa in mm decks).
    let text = std::fs::read_to_string(a.join("calculix/model.inp")).unwrap();
    let loads: Vec<f64> = text
        .lines()
        .filter(|l| l.starts_with("WALL_LUMEN, P, "))
        .map(|l| l.rsplit(',').next().unwrap().trim().parse().unwrap())
        .collect();
    let full = options.fe.pressure_mmhg * MMHG_IN_MPA;
    assert_eq!(loads.len(), 2, "{loads:?}");
    assert!((loads[0] - 0.1 * full).abs() < 1e-12 * full && (loads[1] - full).abs() < 1e-12 * full, "{loads:?}");
    assert_eq!(text.matches("*STEP").count(), 2);
    // C3D8H is refused in the CalculiX dialect.
    options.fe.calculix_element = ElementType::C3D8H;
    assert!(write_calculix(&mesh, &options, &a).unwrap_err().to_string().contains("hybrid"));
    std::fs::remove_dir_all(&a).ok();
    std::fs::remove_dir_all(&b).ok();
}

#[test]
fn quadratic_deck_runs() {
    if !ccx_available() {
        return;
    }
    // 16 around x 10 axial x 3 layers = 480 C3D20.
    let mesh = tube(16, 3.0, 0.4, 1, None);
    let mut options = WriteOptions::default();
    options.fe.calculix_element = ElementType::C3D20;
    options.fe.material = MaterialModel::LinearElastic;
    let run = solve_calculix(&mesh, &options, "c3d20");
    let disp = frd_displacements(&run.dir);
    let (_, _, min_u) = inner_radial(&mesh, &disp);
    assert!(min_u > 0.0);
}

/// A mesh with an inlet and five outlets (three disjoint tubes, two tilted by 35 and -50 deg):
/// every end ring is a set with its own cylindrical system about its own axis (centre, outward
/// normal from the mesh), and ccx, inflating the three tubes, moves every ring node only radially
/// in its end plane while each tube opens.
#[test]
fn multi_outlet_deck_holds_every_end_about_its_own_axis() {
    let mut c = MeshConfig::default();
    c.lumen.core_elements = 4;
    c.lumen.radial_elements = 2;
    c.lumen.axial_spacing_mm = Some(3.0);
    c.wall.thickness_mm = Some(0.4);
    let mesh = vesselhex::testing::multi_outlet_mesh(&c).unwrap();
    let mut options = WriteOptions::default();
    options.fe.material = MaterialModel::LinearElastic;
    let dir = scratch("multi-deck");
    write_calculix(&mesh, &options, &dir).unwrap();
    let text = std::fs::read_to_string(dir.join("calculix/model.inp")).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    for end in &mesh.ends {
        let set = format!("WALL_{}", end.name.to_ascii_uppercase());
        // the ring's node set
        let start = lines.iter().position(|l| *l == format!("*NSET, NSET={set}")).unwrap_or_else(|| panic!("no {set}"));
        let labels: Vec<u64> = lines[start + 1..]
            .iter()
            .take_while(|l| !l.starts_with('*'))
            .flat_map(|l| l.split(',').filter(|s| !s.trim().is_empty()).map(|s| s.trim().parse::<u64>().unwrap()))
            .collect();
        let want: Vec<u64> =
            mesh.node_sets[&vesselhex::mesh::sets::wall_end(&end.name)].iter().map(|&n| n as u64 + 1).collect();
        assert_eq!(labels, want, "{set}");
        // its cylindrical system: axis through the end's centre along its normal
        let t = lines
            .iter()
            .position(|l| *l == format!("*TRANSFORM, NSET={set}, TYPE=C"))
            .unwrap_or_else(|| panic!("{set}"));
        let v: Vec<f64> = lines[t + 1].split(',').map(|s| s.trim().parse().unwrap()).collect();
        let (a, b) = (nalgebra::Point3::new(v[0], v[1], v[2]), nalgebra::Point3::new(v[3], v[4], v[5]));
        assert!((a - end.centre).norm() < 1e-9, "{set}: axis point {a:?}");
        assert!(((b - a).normalize() - end.outward_normal).norm() < 1e-9, "{set}: axis {:?}", b - a);
        assert!(lines.iter().any(|l| *l == format!("{set}, 2, 3")), "{set}: local dofs 2, 3 not held");
    }
    std::fs::remove_dir_all(&dir).ok();
    if !ccx_available() {
        return;
    }
    let run = solve_calculix(&mesh, &options, "multi");
    let disp = frd_displacements(&run.dir);
    let largest = disp.values().map(|u| nalgebra::Vector3::from(*u).norm()).fold(0.0, f64::max);
    let mut worst: f64 = 0.0;
    for end in &mesh.ends {
        for &i in &mesh.node_sets[&vesselhex::mesh::sets::wall_end(&end.name)] {
            let u = nalgebra::Vector3::from(disp[&(i as u64 + 1)]);
            let d = mesh.nodes[i as usize] - end.centre;
            let radial = (d - end.outward_normal * d.dot(&end.outward_normal)).normalize();
            worst = worst.max((u - radial * u.dot(&radial)).norm());
        }
    }
    eprintln!(
        "multi-outlet ccx: largest displacement {largest:.4e} mm, largest non-radial end-ring motion {worst:.3e} mm"
    );
    // (the .frd prints 6 significant digits: rounding leaves about 1e-6 of the largest motion)
    assert!(worst <= 2e-5 * largest, "an end ring moved off its radial lines: {worst:e}");
    // every tube opens: its middle lumen nodes move away from its axis
    for branch in 0..mesh.branch_names.len() {
        let ends: Vec<_> = mesh.ends.iter().filter(|e| e.branch == branch).collect();
        let (p0, p1) = (ends[0].centre, ends[1].centre);
        let axis = (p1 - p0).normalize();
        let mut moved = vec![];
        for &i in &mesh.node_sets[sets::INTERFACE_NODES] {
            let d = mesh.nodes[i as usize] - p0;
            let s = d.dot(&axis) / (p1 - p0).norm();
            let off_axis = d - axis * d.dot(&axis);
            // this tube's nodes (radius 2 mm; the others are 12 mm and more away)
            if (0.3..0.7).contains(&s) && off_axis.norm() < 3.0 {
                let radial = off_axis.normalize();
                moved.push(nalgebra::Vector3::from(disp[&(i as u64 + 1)]).dot(&radial));
            }
        }
        let min = moved.iter().copied().fold(f64::INFINITY, f64::min);
        eprintln!("branch {branch}: {} middle lumen nodes, u_r min {min:.4e} mm", moved.len());
        assert!(!moved.is_empty() && min > 0.0, "branch {branch} does not open");
    }
}

/// Mean distance of an end's lumen ring from the end's centre.
fn lumen_radius_at(mesh: &VesselMesh, end: &vesselhex::mesh::VesselEnd) -> f64 {
    let ring: Vec<u32> = mesh.node_sets[&sets::wall_end(&end.name)]
        .iter()
        .copied()
        .filter(|n| mesh.node_sets[sets::INTERFACE_NODES].binary_search(n).is_ok())
        .collect();
    ring.iter().map(|&n| (mesh.nodes[n as usize] - end.centre).norm()).sum::<f64>() / ring.len() as f64
}

/// A branched vessel (the bundled Y-bifurcation) inflates in ccx with the default fibre material
/// to the default 100 mmHg: the deck solves (both steps, no error line) and the lumen surface
/// moves out of the lumen along its outward normal, but for the daughters' medial walls next to
/// the bifurcation plane: the junction widens across that plane and pulls those walls, each into
/// its own daughter, apart (a few per cent of the lumen nodes, by a fraction of the mean outward
/// motion); they are counted, bounded and located.
#[test]
fn branched_y_bifurcation_deck_solves_and_inflates() {
    if !ccx_available() {
        return;
    }
    let dir = common::crate_dir().join("fixtures");
    let mesh = common::mesh_files(
        &dir.join("y_bifurcation.stl"),
        &dir.join("y_bifurcation_centerlines.vtp"),
        &MeshConfig::preset(vesselhex::config::Preset::Coarse),
    );
    let options = WriteOptions::default();
    assert_eq!(options.fe.material, MaterialModel::Hgo);
    assert_eq!(options.fe.pressure_mmhg, 100.0);
    let run = solve_calculix(&mesh, &options, "y-bifurcation");
    let disp = frd_displacements(&run.dir);
    // The bifurcation plane: through the three end centres.
    let c: Vec<nalgebra::Point3<f64>> = mesh.ends.iter().map(|e| e.centre).collect();
    assert_eq!(c.len(), 3);
    let plane_normal = (c[1] - c[0]).cross(&(c[2] - c[0])).normalize();
    let inlet_radius = lumen_radius_at(&mesh, mesh.inlet().unwrap());
    let motion = lumen_normal_motion(&mesh, &disp);
    let checked = motion.len();
    let mean_un = motion.iter().map(|m| m.1).sum::<f64>() / checked as f64;
    let min_un = motion.iter().map(|m| m.1).fold(f64::INFINITY, f64::min);
    let inward_nodes: Vec<u32> = motion.iter().filter(|m| m.1 <= 0.0).map(|m| m.0).collect();
    let inward = inward_nodes.len();
    let farthest_inward_from_plane =
        inward_nodes.iter().map(|&i| (mesh.nodes[i as usize] - c[0]).dot(&plane_normal).abs()).fold(0.0, f64::max);
    eprintln!(
        "y-bifurcation: {checked} lumen nodes, {inward} move inwards (min u.n {min_un:.3e} mm, at most \
         {farthest_inward_from_plane:.3} mm from the bifurcation plane; inlet radius {inlet_radius:.3} mm), \
         mean u.n {mean_un:.4e} mm"
    );
    assert!(mean_un > 0.0);
    assert!(inward * 100 <= 8 * checked, "{inward} of {checked} lumen nodes move into the lumen");
    assert!(-min_un < 0.5 * mean_un, "a node moves inwards by {min_un:.2e} mm");
    assert!(
        farthest_inward_from_plane < 0.65 * inlet_radius,
        "a node {farthest_inward_from_plane} mm off the bifurcation plane moves inwards"
    );
}

/// The real branched vessels of issue 7 (their own centerlines, coarse preset, every default:
/// fibre material, 100 mmHg) give CalculiX decks that ccx solves to the full pressure, and the
/// vessel opens without ballooning: in every branch the lumen surface's mean motion along its
/// outward normal is positive, and every lumen-surface face stretches in area by more than 0.9
/// and less than 1.5 (the default wall stretches a straight tube's by 1.06; a junction that
/// balloons, as with the softer default material of earlier versions, fails here or in ccx).
/// Displacements themselves are not bounded: long curved branches swing about their held end
/// rings (simvascular_demo_aortoiliac's iliacs by several millimetres), so many lumen nodes
/// move inwards along their normal without any change of shape.
#[test]
fn real_branched_vessels_decks_solve() {
    if !ccx_available() {
        return;
    }
    let Some(v) = common::vessels_dir() else { return };
    for (case, surface, centerlines, unit) in common::REAL_BIFURCATIONS {
        assert_branched_deck_solves(&v, case, surface, centerlines, unit);
    }
}

/// gmsh_aortic_arch (its merged junction of four branches, its wall along the normals in the
/// carotid's funnel) likewise.
#[test]
fn aortic_arch_deck_solves() {
    if !ccx_available() {
        return;
    }
    let Some(v) = common::vessels_dir() else { return };
    let (case, surface, centerlines, unit) = common::GMSH_AORTIC_ARCH;
    assert_branched_deck_solves(&v, case, surface, centerlines, unit);
}

fn assert_branched_deck_solves(vessels: &Path, case: &str, surface: &str, centerlines: &str, unit: LengthUnit) {
    let d = vessels.join(case);
    let mesh = common::mesh_files_in(
        &d.join(surface),
        &d.join(centerlines),
        unit,
        &MeshConfig::preset(vesselhex::config::Preset::Coarse),
    );
    assert!(mesh.ends.len() >= 3, "{case}: not branched");
    let run = solve_calculix(&mesh, &WriteOptions::default(), case);
    common::assert_lumen_opens(case, &mesh, &frd_displacements(&run.dir));
}
