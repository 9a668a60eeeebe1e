//! Centerline trees (branches and junctions) from every layout of centerline file users have:
//! VMTK's overlapping paths, VMTK's and SimVascular's branch-split files, gmsh's segments
//! without radius, our own extraction and its branch-split output, and analytic Y's built here.
//!
//! Every tree is checked against the contract the junction mesher relies on
//! ([`check_contract`]); the real files also against their anatomy.

mod common;

use common::*;
use indexmap::IndexMap;
use nalgebra::{Point3, Vector3};
use std::path::Path;
use std::time::Instant;
use vesselhex::centerline::{CenterlineTree, Junction};
use vesselhex::centerline_extract::{branch_split, extract_centerlines};
use vesselhex::config::CenterlineConfig;
use vesselhex::input::{clean_surface, read_centerlines, read_surface, CenterlinePolyline, Centerlines};
use vesselhex::surface::LumenSurface;
use vesselhex::units::LengthUnit;
use vesselhex::writers::centerlines::write_vtp;

/// Angle between two directions, radians.
fn angle(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.cross(b).norm().atan2(a.dot(b))
}

/// The contract: branch 0 from the inlet, parents first, names in order; every branch ending at
/// a junction ends exactly at its centre and every daughter starts exactly there; at least two
/// daughters; positive radii; orthonormal right-handed frames; a daughter's first frame is the
/// parent's last carried by the smallest rotation (so its normal turns by no more than the
/// tangent does), and its first tangent points away from the centre.
fn check_contract(name: &str, tree: &CenterlineTree) {
    let b0 = &tree.branches[0];
    assert!(b0.parent.is_none() && b0.start_junction.is_none(), "{name}: branch 0 starts at the inlet");
    for (i, b) in tree.branches.iter().enumerate() {
        assert_eq!(b.name, format!("branch_{i}"), "{name}");
        assert!(b.samples.len() >= 3, "{name}: {} has {} samples", b.name, b.samples.len());
        if let Some(p) = b.parent {
            assert!(p < i, "{name}: parent {p} of branch {i} comes after it");
            assert!(tree.branches[p].daughters.contains(&i), "{name}: {i} not among its parent's daughters");
            assert_eq!(b.start_junction, tree.branches[p].end_junction, "{name}: branch {i}");
        }
        for s in &b.samples {
            assert!(s.radius > 0.0 && s.radius.is_finite(), "{name}: radius {} in {}", s.radius, b.name);
            let f = s.frame;
            assert!((f.tangent.norm() - 1.0).abs() < 1e-12 && (f.normal.norm() - 1.0).abs() < 1e-12);
            assert!(f.tangent.dot(&f.normal).abs() < 1e-12, "{name}: frame not orthogonal");
            assert!((f.normal.cross(&f.binormal) - f.tangent).norm() < 1e-12, "{name}: frame not right-handed");
        }
        assert_eq!(b.daughters.is_empty(), b.end_junction.is_none(), "{name}: branch {i}");
    }
    for (j, junction) in tree.junctions.iter().enumerate() {
        assert!(junction.daughters.len() >= 2, "{name}: junction {j} has {} daughters", junction.daughters.len());
        assert!(junction.radius > 0.0);
        let parent = &tree.branches[junction.parent];
        assert_eq!(parent.end_junction, Some(j));
        assert_eq!(parent.daughters, junction.daughters);
        let last = parent.samples[parent.samples.len() - 1];
        assert_eq!(last.point, junction.centre, "{name}: parent of junction {j} does not end at its centre");
        assert_eq!(last.radius, junction.radius, "{name}: parent of junction {j} ends with another radius");
        for &d in &junction.daughters {
            let daughter = &tree.branches[d];
            assert_eq!(daughter.parent, Some(junction.parent));
            assert_eq!(daughter.start_junction, Some(j));
            let first = daughter.samples[0];
            assert_eq!(first.point, junction.centre, "{name}: daughter {d} does not start at junction {j}");
            assert_eq!(first.radius, junction.radius, "{name}: daughter {d} starts with another radius");
            let away = daughter.samples[1].point - junction.centre;
            assert!(first.frame.tangent.dot(&away) > 0.0, "{name}: daughter {d} starts towards the centre");
            let turn_t = angle(&last.frame.tangent, &first.frame.tangent);
            let turn_n = angle(&last.frame.normal, &first.frame.normal);
            assert!(
                turn_n <= turn_t + 1e-9,
                "{name}: daughter {d}'s first normal turns {turn_n:.4} rad from the parent's, its tangent only {turn_t:.4}"
            );
            // No spin about the parent's tangent or the daughter's: the normal stays in the
            // plane it shared with the tangent, rotated about t_parent x t_daughter.
            let axis = last.frame.tangent.cross(&first.frame.tangent);
            if axis.norm() > 1e-9 {
                let rotation = nalgebra::Rotation3::new(axis.normalize() * turn_t);
                let carried = rotation * last.frame.normal;
                assert!(
                    angle(&carried, &first.frame.normal) < 1e-9,
                    "{name}: daughter {d}'s normal is not transported"
                );
            }
        }
    }
}

/// Junction figures against the surface: inside (winding number), radius vs distance to the
/// surface. Returns the worst relative radius error.
fn check_junctions_in_lumen(name: &str, tree: &CenterlineTree, lumen: &LumenSurface) -> f64 {
    let mut worst: f64 = 0.0;
    for (j, Junction { centre, radius, parent, daughters, arriving }) in tree.junctions.iter().enumerate() {
        // A tree's junctions have their parent as their one arriving branch (only a loop's
        // closing branch arrives beside it).
        assert!(arriving.is_empty(), "{name}: junction {j} has branches {arriving:?} arriving beside its parent");
        let distance = lumen.closest(centre).distance;
        let winding = lumen.winding_number(centre);
        let error = (radius - distance).abs() / distance;
        println!(
            "  {name} junction {j}: centre ({:.3}, {:.3}, {:.3}) mm, radius {radius:.3} mm, distance to the surface \
             {distance:.3} mm ({:+.1} %), winding {winding:.3}, branch {parent} -> {daughters:?}",
            centre.x,
            centre.y,
            centre.z,
            100.0 * (radius - distance) / distance
        );
        assert!(winding.abs() > 0.5, "{name}: junction {j} lies outside the lumen (winding {winding})");
        assert!(distance < *radius * 1.25, "{name}: junction {j}: distance {distance} to the surface, radius {radius}");
        assert!(error < 0.25, "{name}: junction {j}: radius {radius} vs distance to the surface {distance}");
        worst = worst.max(error);
    }
    worst
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn median_radius(tree: &CenterlineTree, b: usize) -> f64 {
    median(tree.branches[b].samples.iter().map(|s| s.radius).collect())
}

/// (case, surface, centerlines, unit, branches, junctions)
const REAL: [(&str, &str, &str, LengthUnit, usize, usize); 5] = [
    ("vmtk_aortoiliac", "aorta-surface-open-ends.stl", "aorta-centerline.vtp", LengthUnit::Mm, 3, 1),
    ("vmtk_aortoiliac", "aorta-surface-open-ends.stl", "aorta-centerline-attribute-branches.vtp", LengthUnit::Mm, 3, 1),
    ("gmsh_carotid_bifurcation", "carotid.stl", "centerlinesCAROTID.vtk", LengthUnit::M, 3, 1),
    ("simvascular_demo_aortoiliac", "demo.vtp", "demo-centerlines.vtp", LengthUnit::Cm, 3, 1),
    // Ascending aorta -> arch + brachiocephalic-carotid trunk; trunk -> brachiocephalic + left
    // common carotid; arch -> left subclavian + descending aorta (see `aortic_arch_...` below).
    ("gmsh_aortic_arch", "aorta.stl", "centerlinesAORTA.vtk", LengthUnit::M, 7, 3),
];

fn load(vessels: &Path, case: &str, surface: &str, centerlines: &str, unit: LengthUnit) -> (LumenSurface, Centerlines) {
    let dir = vessels.join(case);
    let lumen = LumenSurface::new(&read_surface(&dir.join(surface), unit).unwrap()).unwrap();
    (lumen, read_centerlines(&dir.join(centerlines), unit).unwrap())
}

fn build(centerlines: &Centerlines, config: &CenterlineConfig, lumen: Option<&LumenSurface>) -> CenterlineTree {
    CenterlineTree::build(centerlines, config, lumen).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn real_centerline_files_give_their_trees() {
    let Some(vessels) = vessels_dir() else { return };
    for (case, surface, file, unit, n_branches, n_junctions) in REAL {
        let (lumen, centerlines) = load(&vessels, case, surface, file, unit);
        let t0 = Instant::now();
        let tree = build(&centerlines, &CenterlineConfig::default(), Some(&lumen));
        let time = t0.elapsed().as_secs_f64();
        let name = format!("{case}/{file}");
        println!(
            "{name}: {} polylines -> {} branches, {} junctions in {time:.3} s",
            centerlines.polylines.len(),
            tree.branches.len(),
            tree.junctions.len()
        );
        assert_eq!(tree.branches.len(), n_branches, "{name}: branches");
        assert_eq!(tree.junctions.len(), n_junctions, "{name}: junctions");
        check_contract(&name, &tree);
        check_junctions_in_lumen(&name, &tree, &lumen);
        // The inlet is the largest vessel and every tree narrows downstream.
        for j in &tree.junctions {
            for &d in &j.daughters {
                assert!(
                    median_radius(&tree, d) < median_radius(&tree, j.parent),
                    "{name}: daughter {d} wider than its parent {}",
                    j.parent
                );
            }
        }
        let again = build(&centerlines, &CenterlineConfig::default(), Some(&lumen));
        assert_eq!(format!("{tree:?}"), format!("{again:?}"), "{name}: not deterministic");
    }
}

/// The VMTK paths and VMTK's own branch split of them give the same junction.
#[test]
fn vmtk_paths_and_their_branch_split_agree() {
    let Some(vessels) = vessels_dir() else { return };
    let (lumen, paths) =
        load(&vessels, "vmtk_aortoiliac", "aorta-surface-open-ends.stl", "aorta-centerline.vtp", LengthUnit::Mm);
    let split =
        read_centerlines(&vessels.join("vmtk_aortoiliac/aorta-centerline-attribute-branches.vtp"), LengthUnit::Mm)
            .unwrap();
    let a = build(&paths, &CenterlineConfig::default(), Some(&lumen));
    let b = build(&split, &CenterlineConfig::default(), Some(&lumen));
    // Without Blanking, the bifurcation tracts are one more group shared by both centerlines,
    // and the split is after it.
    let mut unblanked = split.clone();
    unblanked.polylines.iter_mut().for_each(|l| {
        l.cell_tags.shift_remove("Blanking");
    });
    let c = build(&unblanked, &CenterlineConfig::default(), Some(&lumen));
    check_contract("aortoiliac branch split without Blanking", &c);
    assert_eq!((c.branches.len(), c.junctions.len()), (3, 1));
    let ja = &a.junctions[0];
    for (what, other) in [("branch split", &b), ("branch split without Blanking", &c)] {
        let gap = (ja.centre - other.junctions[0].centre).norm() / ja.radius;
        println!("vmtk_aortoiliac: junction from the paths and from the {what} {gap:.4} r apart");
        assert!(gap < 0.1, "{what}: junctions {gap} r apart");
    }
    // The aorta is the inlet: the file's common start, radius 5.3 mm there, the iliacs 2.8-3.4.
    assert_eq!(a.branches[0].samples[0].point, paths.polylines[0].points[0]);
    // Daughters in the order of the file's outlets.
    let outlet = |tree: &CenterlineTree, b: usize| tree.branches[b].samples.last().unwrap().point;
    for (k, &d) in a.junctions[0].daughters.iter().enumerate() {
        let line = &paths.polylines[k].points;
        assert!((outlet(&a, d) - line[line.len() - 1]).norm() < 1e-9, "daughter {k} is not outlet {k}");
    }
}

/// gmsh's carotid paths start at the internal carotid's end; the tree starts at the common
/// carotid (the largest end, 2.5 mm against 1.3-1.4 mm), unless told otherwise.
#[test]
fn carotid_tree_starts_at_the_common_carotid_unless_told() {
    let Some(vessels) = vessels_dir() else { return };
    let (lumen, cl) =
        load(&vessels, "gmsh_carotid_bifurcation", "carotid.stl", "centerlinesCAROTID.vtk", LengthUnit::M);
    let tree = build(&cl, &CenterlineConfig::default(), Some(&lumen));
    let first = tree.branches[0].samples[0].point;
    let cca_end = *cl.polylines[0].points.last().unwrap();
    assert!((first - cca_end).norm() < 1e-9, "inlet at {first:?}, not the common carotid's end {cca_end:?}");
    let parent = median_radius(&tree, 0);
    let daughters: Vec<f64> = tree.junctions[0].daughters.iter().map(|&d| median_radius(&tree, d)).collect();
    println!("carotid: common carotid median radius {parent:.3} mm, daughters {daughters:.3?} mm");
    assert!(daughters.iter().all(|&r| r < 0.8 * parent));
    // The file's own start as inlet, by a point near it.
    let start = cl.polylines[0].points[0];
    let config = CenterlineConfig { inlet_mm: Some([start.x + 0.5, start.y, start.z]), ..Default::default() };
    let told = build(&cl, &config, Some(&lumen));
    assert_eq!(told.branches[0].samples[0].point, start);
    check_contract("carotid rooted at the file's start", &told);
    assert_eq!((told.branches.len(), told.junctions.len()), (3, 1));
}

/// The gmsh arch: 4 paths from the ascending aorta (the common end of the file's segments,
/// radius 15.9 mm by the distance to the surface: the largest end), stored upside down (the
/// supra-aortic branches point to -z). The brachiocephalic (BCT) and left common carotid (LCC)
/// paths leave the arch's path together and run within a quarter radius of each other for
/// about 20 mm: a trunk, with its own junction where they part, more than a radius from the
/// arch's; the left subclavian leaves 27.5 mm (2 R) further along the arch. The merge distance
/// changes nothing: the file's own node where the two paths start, 3.7 mm from the arch's, is
/// only a point of the trunk.
#[test]
fn aortic_arch_from_segments_without_radius() {
    let Some(vessels) = vessels_dir() else { return };
    let (lumen, cl) = load(&vessels, "gmsh_aortic_arch", "aorta.stl", "centerlinesAORTA.vtk", LengthUnit::M);
    assert!(cl.polylines.iter().all(|l| l.radii.is_none()));
    let tree = build(&cl, &CenterlineConfig::default(), Some(&lumen));
    let ascending = tree.branches[0].samples[0];
    println!(
        "arch: inlet ({:.1}, {:.1}, {:.1}) mm, radius {:.2} mm",
        ascending.point.x, ascending.point.y, ascending.point.z, ascending.radius
    );
    let ends: Vec<Point3<f64>> =
        cl.polylines.iter().flat_map(|l| [l.points[0], l.points[l.points.len() - 1]]).collect();
    let common = ends.iter().filter(|p| ends.iter().filter(|q| (*q - *p).norm() < 1e-9).count() == 4).count();
    assert_eq!(common, 4, "the four paths share one end");
    assert!(ends.iter().any(|p| (p - ascending.point).norm() < 1e-9));
    let outlets: Vec<usize> = (0..tree.branches.len()).filter(|&b| tree.branches[b].daughters.is_empty()).collect();
    assert_eq!(outlets.len(), 4);
    // Supra-aortic outlets point away from the arch, down in this file (-z).
    let top = |b: usize| tree.branches[b].samples.last().unwrap().point.z;
    let supra: Vec<usize> = outlets.iter().copied().filter(|&b| top(b) < ascending.point.z - 50.0).collect();
    let descending: Vec<usize> = outlets.iter().copied().filter(|&b| top(b) > ascending.point.z).collect();
    assert_eq!((supra.len(), descending.len()), (3, 1), "outlets {outlets:?}");
    assert_eq!(tree.junctions.len(), 3);
    let j0 = &tree.junctions[0];
    assert_eq!(j0.parent, 0);
    assert_eq!(j0.daughters.len(), 2, "the arch and the trunk");
    let ends_at = |b: usize| &tree.junctions[tree.branches[b].end_junction.expect("both lead to a junction")];
    let (trunk, arch): (Vec<usize>, Vec<usize>) =
        j0.daughters.iter().partition(|&&d| ends_at(d).daughters.iter().all(|x| supra.contains(x)));
    assert_eq!((trunk.len(), arch.len()), (1, 1), "one trunk to two supra-aortic outlets, one arch");
    let (jt, j1) = (ends_at(trunk[0]), ends_at(arch[0]));
    assert_eq!(jt.daughters.len(), 2, "brachiocephalic and left common carotid");
    assert_eq!(j1.daughters.len(), 2, "left subclavian and descending aorta");
    assert!(j1.daughters.contains(&descending[0]));
    for (what, j) in [("trunk", jt), ("arch", j1)] {
        let apart = (j.centre - j0.centre).norm() / j0.radius;
        println!("arch: the {what}'s junction {apart:.2} R from the first");
        assert!(apart > 1.0, "{what}: {apart:.2} R");
    }
    // The trunk is the middle of the two paths: inside the lumen, nearer the middle than the wall.
    for s in &tree.branches[trunk[0]].samples {
        assert!(lumen.winding_number(&s.point).abs() > 0.5, "trunk point {:?} outside the lumen", s.point);
    }

    let unmerged = build(&cl, &CenterlineConfig { junction_merge_radii: 0.0, ..Default::default() }, Some(&lumen));
    check_contract("arch, unmerged", &unmerged);
    assert_eq!((unmerged.branches.len(), unmerged.junctions.len()), (7, 3));
    for (a, b) in unmerged.junctions.iter().zip(&tree.junctions) {
        assert!((a.centre - b.centre).norm() < 1e-9, "merging changes nothing");
    }
}

/// Our own extraction on the open aortoiliac surface gives the same tree as VMTK's paths.
#[test]
fn extracted_paths_give_the_vmtk_tree() {
    let Some(vessels) = vessels_dir() else { return };
    let dir = vessels.join("vmtk_aortoiliac");
    let surface = read_surface(&dir.join("aorta-surface-open-ends.stl"), LengthUnit::Mm).unwrap();
    let lumen = LumenSurface::new(&surface).unwrap();
    let ours = extract_centerlines(&surface, &Default::default()).unwrap();
    let t0 = Instant::now();
    let tree = build(&ours.centerlines, &CenterlineConfig::default(), Some(&lumen));
    println!("vmtk_aortoiliac, our paths: tree in {:.3} s", t0.elapsed().as_secs_f64());
    check_contract("aortoiliac, our paths", &tree);
    check_junctions_in_lumen("aortoiliac, our paths", &tree, &lumen);
    let vmtk =
        build(&read_centerlines(&dir.join("aorta-centerline.vtp"), LengthUnit::Mm).unwrap(), &Default::default(), None);
    assert_eq!((tree.branches.len(), tree.junctions.len()), (3, 1));
    let gap = (tree.junctions[0].centre - vmtk.junctions[0].centre).norm() / vmtk.junctions[0].radius;
    println!("vmtk_aortoiliac: our junction {gap:.3} r from VMTK's");
    assert!(gap < 0.25, "{gap}");
}

/// The pulmonary bifurcation's main artery is a trunk about one radius long closed by a blunt
/// face (flat, with a rounded rim): its end lies on the face, and the tree keeps the trunk from it
/// to the junction, with the two pulmonary arteries leaving there. (With the end at the inscribed
/// ball under the face, a radius inside it, both paths parted at the inlet and the trunk was lost.)
#[test]
fn a_short_trunk_closed_by_a_blunt_face_is_kept() {
    let Some(vessels) = vessels_dir() else { return };
    let path = vessels.join("sphinxsys_pulmonary_bifurcation/PA.stl");
    let (surface, _) = clean_surface(read_surface(&path, LengthUnit::Mm).unwrap()).unwrap();
    let lumen = LumenSurface::new(&surface).unwrap();
    let ours = extract_centerlines(&surface, &Default::default()).unwrap();
    let inlet = ours.ends[ours.inlet];
    let config = CenterlineConfig { inlet_mm: Some(inlet.centre.coords.into()), ..Default::default() };
    let tree = build(&ours.centerlines, &config, Some(&lumen));
    check_contract("pulmonary bifurcation, our paths", &tree);
    let trunk = &tree.branches[0];
    let junction = &tree.junctions[0];
    println!(
        "pulmonary bifurcation: inlet {:.3} mm off the surface, trunk {:.1} mm to a junction of radius {:.1} mm",
        lumen.closest(&inlet.centre).distance,
        trunk.length(),
        junction.radius
    );
    assert_eq!(ours.ends.len(), 3);
    // On the face, as flat as a cap is (2 % of its radius).
    assert!(lumen.closest(&inlet.centre).distance < 0.02 * inlet.radius, "the inlet lies on its face");
    assert_eq!((tree.branches.len(), tree.junctions.len()), (3, 1));
    assert!((trunk.samples[0].point - inlet.centre).norm() < 0.02 * inlet.radius, "the tree starts at the inlet");
    assert_eq!(trunk.end_junction, Some(0));
    assert!(trunk.length() > 0.5 * junction.radius, "trunk {:.2} mm", trunk.length());
}

/// Branch-split output read back gives the same tree: on our extraction (one junction) and on
/// the arch (a merged junction with three daughters).
#[test]
fn branch_split_round_trip() {
    let Some(vessels) = vessels_dir() else { return };
    let dir = temp_dir("tree-split");
    let aortoiliac =
        read_surface(&vessels.join("vmtk_aortoiliac/aorta-surface-open-ends.stl"), LengthUnit::Mm).unwrap();
    let extracted = extract_centerlines(&aortoiliac, &Default::default()).unwrap();
    let (arch_lumen, arch) = load(&vessels, "gmsh_aortic_arch", "aorta.stl", "centerlinesAORTA.vtk", LengthUnit::M);
    let cases = [("aortoiliac (ours)", extracted.centerlines, None), ("arch (gmsh)", arch, Some(&arch_lumen))];
    for (name, centerlines, lumen) in cases {
        let tree = build(&centerlines, &CenterlineConfig::default(), lumen);
        let split = branch_split(&tree, Path::new("split.vtp"));
        let path = dir.join("split.vtp");
        write_vtp(&split, 1e-3, &path).unwrap();
        let back = read_centerlines(&path, LengthUnit::M).unwrap();
        // VMTK's layout: every tract is tagged; the tracts of one path follow each other; a
        // group is either blanked or not; the inlet branch is one group shared by every path.
        let tag = |l: &CenterlinePolyline, k: &str| l.cell_tags[k];
        let paths = tree.branches.iter().filter(|b| b.daughters.is_empty()).count();
        let ids: std::collections::BTreeSet<i64> = back.polylines.iter().map(|l| tag(l, "CenterlineIds")).collect();
        assert_eq!(ids.len(), paths, "{name}: one centerline per outlet");
        let blanked: std::collections::BTreeSet<i64> =
            back.polylines.iter().filter(|l| tag(l, "Blanking") == 1).map(|l| tag(l, "GroupIds")).collect();
        let open: std::collections::BTreeSet<i64> =
            back.polylines.iter().filter(|l| tag(l, "Blanking") == 0).map(|l| tag(l, "GroupIds")).collect();
        assert!(blanked.is_disjoint(&open), "{name}: a group is both blanked and not");
        assert_eq!(blanked.len(), tree.junctions.len(), "{name}: one blanked group per junction");
        assert_eq!(open.len(), tree.branches.len(), "{name}: one group per branch");
        let first_groups: std::collections::BTreeSet<i64> =
            back.polylines.iter().filter(|l| tag(l, "TractIds") == 0).map(|l| tag(l, "GroupIds")).collect();
        assert_eq!(first_groups.len(), 1, "{name}: the inlet branch is one group");
        for w in back.polylines.windows(2) {
            if tag(&w[0], "CenterlineIds") == tag(&w[1], "CenterlineIds") {
                assert_eq!(tag(&w[1], "TractIds"), tag(&w[0], "TractIds") + 1);
                assert!((w[1].points[0] - w[0].points[w[0].points.len() - 1]).norm() < 1e-9);
            }
        }

        let again = build(&back, &CenterlineConfig::default(), None);
        check_contract(&format!("{name}, read back"), &again);
        assert_eq!(again.branches.len(), tree.branches.len(), "{name}: branches");
        assert_eq!(again.junctions.len(), tree.junctions.len(), "{name}: junctions");
        for (a, b) in tree.junctions.iter().zip(&again.junctions) {
            let gap = (a.centre - b.centre).norm() / a.radius;
            println!(
                "{name}: junction read back {gap:.4} r from the original (radius {:.3} vs {:.3} mm)",
                a.radius, b.radius
            );
            assert!(gap < 0.1, "{name}: junction moved by {gap} r");
            assert!(
                (a.radius - b.radius).abs() < 0.02 * a.radius,
                "{name}: junction radius {} read back as {}",
                a.radius,
                b.radius
            );
            assert_eq!(a.daughters.len(), b.daughters.len());
        }
        for (a, b) in tree.branches.iter().zip(&again.branches) {
            assert_eq!((a.parent, &a.daughters), (b.parent, &b.daughters), "{name}: {}", a.name);
            let end = |x: &vesselhex::centerline::Branch| x.samples.last().unwrap().point;
            assert!(
                (end(a) - end(b)).norm() < 0.1 * a.samples.last().unwrap().radius,
                "{name}: {} ends elsewhere",
                a.name
            );
            assert!(
                (a.length() - b.length()).abs() < 0.05 * a.length().max(a.samples[0].radius),
                "{name}: {} length",
                a.name
            );
        }
    }
}

/// A path of points every `step` from `a` to `b` (b included), radius `r`.
fn segment(a: Point3<f64>, b: Point3<f64>, step: f64, r: f64) -> (Vec<Point3<f64>>, Vec<f64>) {
    let n = ((b - a).norm() / step).ceil() as usize;
    ((1..=n).map(|i| a + (b - a) * (i as f64 / n as f64)).collect(), vec![r; n])
}

/// An inlet-outlet path through the given corners, starting at `start`.
fn path(start: Point3<f64>, corners: &[(Point3<f64>, f64)], step: f64, offset: Vector3<f64>) -> CenterlinePolyline {
    let mut points = vec![start];
    let mut radii = vec![corners[0].1];
    for &(c, r) in corners {
        let (p, q) = segment(points[points.len() - 1], c, step, r);
        points.extend(p);
        radii.extend(q);
    }
    // A small sideways offset after the first point: two tools never give identical points.
    let points = points.iter().enumerate().map(|(i, p)| if i == 0 { *p } else { p + offset }).collect();
    CenterlinePolyline { points, radii: Some(radii), normals: None, cell_tags: IndexMap::new() }
}

/// Two overlapping paths of an analytic Y (parent radius 2 along z to (0, 0, 20), daughters of
/// radius 1.5 at +-`half_angle` from it), with different point spacings and a 0.005 r offset.
fn analytic_y(half_angle: f64) -> (Centerlines, Point3<f64>) {
    let o = Point3::origin();
    let j = Point3::new(0.0, 0.0, 20.0);
    let d = |sign: f64| j + Vector3::new(sign * half_angle.sin(), 0.0, half_angle.cos()) * 25.0;
    let a = path(o, &[(j, 2.0), (d(1.0), 1.5)], 0.2, Vector3::zeros());
    let b = path(o, &[(j, 2.0), (d(-1.0), 1.5)], 0.17, Vector3::new(0.0, 0.01, 0.0));
    (Centerlines { polylines: vec![a, b], source: "analytic Y".into() }, j)
}

#[test]
fn analytic_y_from_two_overlapping_paths() {
    for degrees in [15.0, 30.0, 45.0, 60.0, 90.0] {
        let (cl, j) = analytic_y(f64::to_radians(degrees));
        let tree = build(&cl, &CenterlineConfig::default(), None);
        let name = format!("Y {degrees} deg");
        check_contract(&name, &tree);
        assert_eq!((tree.branches.len(), tree.junctions.len()), (3, 1), "{name}");
        let junction = &tree.junctions[0];
        let off = (junction.centre - j).norm() / 2.0;
        println!("{name}: junction {off:.4} r from the exact branch point, radius {:.3}", junction.radius);
        assert!(off < 0.1, "{name}: junction {off} r from the branch point");
        assert!((junction.radius - 2.0).abs() < 1e-9 || (junction.radius - 1.5).abs() < 1e-9);
        // Daughters in the order of the outlets: +x first.
        let end_x = |b: usize| tree.branches[b].samples.last().unwrap().point.x;
        assert!(end_x(junction.daughters[0]) > 0.0 && end_x(junction.daughters[1]) < 0.0);
        // Each daughter leaves the centre towards its own side.
        for (&d, sign) in junction.daughters.iter().zip([1.0, -1.0]) {
            let b = &tree.branches[d];
            let far = b.at(3.0).point - junction.centre;
            assert!(far.x * sign > 0.0, "{name}: daughter {d} leaves to the wrong side");
        }
    }
}

#[test]
fn analytic_y_as_three_polylines_or_a_t_connection() {
    let (cl, j) = analytic_y(f64::to_radians(30.0));
    let paths = build(&cl, &CenterlineConfig::default(), None);
    // The same Y as a parent and two daughters meeting at the branch point (daughters given
    // from their outlets, parent from its inlet: orientation does not matter).
    let cut = |l: &CenterlinePolyline, from_junction: bool| {
        let k = l.points.iter().position(|p| (p - j).norm() < 1e-9).unwrap();
        let (points, radii) = if from_junction {
            (
                l.points[k..].iter().rev().copied().collect(),
                l.radii.as_ref().unwrap()[k..].iter().rev().copied().collect(),
            )
        } else {
            (l.points[..=k].to_vec(), l.radii.as_ref().unwrap()[..=k].to_vec())
        };
        CenterlinePolyline { points, radii: Some(radii), normals: None, cell_tags: IndexMap::new() }
    };
    let a = &cl.polylines[0];
    let three = Centerlines {
        polylines: vec![cut(a, false), cut(a, true), cut(&analytic_y_exact(), true)],
        source: "three polylines".into(),
    };
    let tree = build(&three, &CenterlineConfig::default(), None);
    check_contract("three polylines", &tree);
    assert_eq!((tree.branches.len(), tree.junctions.len()), (3, 1));
    assert_eq!(tree.junctions[0].centre, j);
    let gap = (tree.junctions[0].centre - paths.junctions[0].centre).norm() / 2.0;
    assert!(gap < 0.1, "{gap}");
    // A side branch starting on the interior of a straight vessel.
    let (main, mr) = segment(Point3::new(0.0, 0.0, -1.0), Point3::new(0.0, 0.0, 60.0), 0.5, 3.0);
    let (side, sr) = segment(Point3::new(0.0, 0.0, 30.0), Point3::new(20.0, 0.0, 45.0), 0.5, 1.0);
    let line = |p: Vec<Point3<f64>>, r: Vec<f64>| CenterlinePolyline {
        points: p,
        radii: Some(r),
        normals: None,
        cell_tags: IndexMap::new(),
    };
    let mut side_points = vec![Point3::new(0.0, 0.0, 30.0)];
    side_points.extend(side);
    let mut side_radii = vec![1.0];
    side_radii.extend(sr);
    let t = Centerlines { polylines: vec![line(main, mr), line(side_points, side_radii)], source: "T".into() };
    let tree = build(&t, &CenterlineConfig::default(), None);
    check_contract("side branch", &tree);
    assert_eq!((tree.branches.len(), tree.junctions.len()), (3, 1));
    assert_eq!(tree.junctions[0].centre, Point3::new(0.0, 0.0, 30.0));
    assert!(tree.branches[0].samples[0].point.z < 0.0, "inlet: the wide vessel's first end");
}

/// The -x daughter of the analytic Y, exactly at the branch point (no offset).
fn analytic_y_exact() -> CenterlinePolyline {
    let a = f64::to_radians(30.0);
    let j = Point3::new(0.0, 0.0, 20.0);
    path(Point3::origin(), &[(j, 2.0), (j + Vector3::new(-a.sin(), 0.0, a.cos()) * 25.0, 1.5)], 0.2, Vector3::zeros())
}

/// Three paths whose two junctions are 0.5 r apart merge into one with three daughters; 3 r
/// apart they stay two; with merging off, always two.
#[test]
fn close_junctions_merge() {
    let o = Point3::origin();
    for (gap, merged) in [(1.0, true), (6.0, false)] {
        let j1 = Point3::new(0.0, 0.0, 20.0);
        let j2 = Point3::new(0.0, 0.0, 20.0 + gap);
        let end = |x: f64, y: f64, from: Point3<f64>| from + Vector3::new(x, y, 1.0).normalize() * 25.0;
        let cl = Centerlines {
            polylines: vec![
                path(o, &[(j1, 2.0), (j2, 2.0), (end(0.0, 0.0, j2), 2.0)], 0.2, Vector3::zeros()),
                path(o, &[(j1, 2.0), (end(1.0, 0.0, j1), 1.0)], 0.2, Vector3::zeros()),
                path(o, &[(j1, 2.0), (j2, 2.0), (end(0.0, 1.0, j2), 1.0)], 0.2, Vector3::zeros()),
            ],
            source: "two junctions".into(),
        };
        let tree = build(&cl, &CenterlineConfig::default(), None);
        check_contract(&format!("gap {gap}"), &tree);
        if merged {
            assert_eq!((tree.branches.len(), tree.junctions.len()), (4, 1), "gap {gap}");
            assert_eq!(tree.junctions[0].daughters, vec![1, 2, 3]);
        } else {
            assert_eq!((tree.branches.len(), tree.junctions.len()), (5, 2), "gap {gap}");
        }
        let off = build(&cl, &CenterlineConfig { junction_merge_radii: 0.0, ..Default::default() }, None);
        assert_eq!(off.junctions.len(), 2, "gap {gap}, merging off");
        check_contract("merging off", &off);
    }
}

#[test]
fn bad_trees_are_clear_errors() {
    let line = |pts: &[[f64; 3]]| {
        let points: Vec<Point3<f64>> = pts.iter().map(|p| Point3::from(*p)).collect();
        let n = points.len();
        CenterlinePolyline { points, radii: Some(vec![1.0; n]), normals: None, cell_tags: IndexMap::new() }
    };
    let err = |polylines: Vec<CenterlinePolyline>| {
        let cl = Centerlines { polylines, source: "cl.vtk".into() };
        CenterlineTree::build(&cl, &CenterlineConfig::default(), None).unwrap_err().to_string()
    };
    // A loop: a triangle with a tail.
    let e = err(vec![
        line(&[[0.0, 0.0, 0.0], [0.0, 0.0, 10.0]]),
        line(&[[0.0, 0.0, 10.0], [10.0, 0.0, 10.0]]),
        line(&[[10.0, 0.0, 10.0], [5.0, 8.0, 10.0]]),
        line(&[[5.0, 8.0, 10.0], [0.0, 0.0, 10.0]]),
    ]);
    assert!(e.contains("cl.vtk") && e.contains("loop") && e.contains("mm"), "{e}");
    // A polyline far from the others.
    let e = err(vec![
        line(&[[0.0, 0.0, 0.0], [0.0, 0.0, 10.0]]),
        line(&[[0.0, 0.0, 10.0], [5.0, 0.0, 20.0]]),
        line(&[[0.0, 0.0, 10.0], [-5.0, 0.0, 20.0]]),
        line(&[[50.0, 0.0, 0.0], [50.0, 0.0, 10.0]]),
    ]);
    assert!(e.contains("polyline 3") && e.contains("does not connect") && e.contains("(50.000, 0.000, 0.000)"), "{e}");
    // Overlapping paths where one ends inside the other.
    let e = err(vec![
        line(&[[0.0, 0.0, 0.0], [0.0, 0.0, 5.0], [0.0, 0.0, 10.0], [0.0, 0.0, 15.0], [0.0, 0.0, 20.0]]),
        line(&[[0.0, 0.0, 0.0], [0.0, 0.0, 5.0], [0.0, 0.0, 10.0]]),
        line(&[[0.0, 0.0, 0.0], [0.0, 0.0, 5.0], [0.0, 0.0, 10.0], [5.0, 0.0, 15.0]]),
    ]);
    assert!(e.contains("centerline 1 ends") && e.contains("inside another path"), "{e}");
    // No radius and no surface to measure it on.
    let mut l = line(&[[0.0, 0.0, 0.0], [0.0, 0.0, 10.0]]);
    l.radii = None;
    let e =
        err(vec![l.clone(), line(&[[0.0, 0.0, 10.0], [0.0, 5.0, 20.0]]), line(&[[0.0, 0.0, 10.0], [0.0, -5.0, 20.0]])]);
    assert!(e.contains("no radius") && e.contains("surface"), "{e}");
}

/// A centerline without radius that leaves the lumen: named with the place.
#[test]
fn a_path_outside_the_lumen_is_named() {
    let Some(vessels) = vessels_dir() else { return };
    let (lumen, mut cl) = load(&vessels, "gmsh_aortic_arch", "aorta.stl", "centerlinesAORTA.vtk", LengthUnit::M);
    // Bend the end of the third path 40 mm sideways, out of its vessel.
    let p = &mut cl.polylines[2].points;
    let n = p.len();
    for (k, q) in p.iter_mut().enumerate().take(n / 3) {
        q.x += 40.0 * (1.0 - k as f64 / (n / 3) as f64).min(0.8) / 0.8;
    }
    let e = CenterlineTree::build(&cl, &CenterlineConfig::default(), Some(&lumen)).unwrap_err().to_string();
    assert!(
        e.contains("centerlinesAORTA.vtk") && e.contains("polyline 2 leaves the lumen") && e.contains("aorta.stl"),
        "{e}"
    );
}

/// A single polyline stays one branch; a point near its last end makes that the inlet.
#[test]
fn single_polyline_and_its_inlet() {
    let (cl, _) = analytic_y(0.5);
    let one = Centerlines { polylines: vec![cl.polylines[0].clone()], source: "one".into() };
    let tree = build(&one, &CenterlineConfig::default(), None);
    assert_eq!((tree.branches.len(), tree.junctions.len()), (1, 0));
    assert_eq!(tree.branches[0].samples[0].point, one.polylines[0].points[0]);
    let last = *one.polylines[0].points.last().unwrap();
    let config = CenterlineConfig { inlet_mm: Some([last.x, last.y, last.z + 1.0]), ..Default::default() };
    let reversed = build(&one, &config, None);
    assert_eq!(reversed.branches[0].samples[0].point, last);
    check_contract("single", &reversed);
}
