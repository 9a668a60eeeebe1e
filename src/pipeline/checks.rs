//! The checks a run makes on its inputs and its result: settings (ranges, the files they name,
//! what to warn about), units and coordinate systems (the centerline against the surface), the
//! surface's winding, and no inverted element in the mesh.

use crate::data::config::MeshConfig;
use crate::data::diagnostics::{short, Warning};
use crate::data::error::{Error, Result};
use crate::data::region::Region;
use crate::data::units::LengthUnit;
use crate::geometry::mesh::VesselMesh;
use crate::geometry::surface::{LumenSurface, TriangleSurface};
use crate::io::input::Centerlines;
use crate::stages::centerline::CenterlineTree;
use crate::stages::junction::JunctionGeometry;
use nalgebra::Point3;
use rayon::prelude::*;
use std::path::Path;

/// The settings checked as a run starts: their ranges ([`MeshConfig::validate`]) and the folder
/// of solver templates they name, which must exist and hold templates (a misspelt folder would
/// otherwise give the built-in templates unseen).
pub(super) fn check_settings(config: &MeshConfig) -> Result<()> {
    config.validate()?;
    match &config.fe.template_dir {
        Some(dir) => crate::io::templates::check_template_dir(dir),
        None => Ok(()),
    }
}

/// What a user should know about settings that were accepted: fractions normalised, no format
/// asked for.
pub(super) fn settings_warnings(config: &MeshConfig) -> Vec<Warning> {
    let mut out = vec![];
    let w = &config.wall;
    let fractions = [w.intima.fraction, w.media.fraction, w.adventitia.fraction];
    let total: f64 = fractions.iter().sum();
    if (total - 1.0).abs() > 1e-9 {
        let normalised: Vec<String> = fractions.iter().map(|f| format!("{:.3}", f / total)).collect();
        out.push(Warning::new(
            "settings",
            format!(
                "the wall layer fractions {}/{}/{} (intima/media/adventitia) sum to {total}; they were normalised \
                 to {}",
                fractions[0],
                fractions[1],
                fractions[2],
                normalised.join("/")
            ),
        ));
    }
    if config.formats.is_empty() {
        out.push(Warning::new(
            "settings",
            "formats is empty (formats = []): no mesh is written, only report.json; name the formats wanted, e.g. \
             formats = [\"vtu\"] in the case file or --formats vtu",
        ));
    }
    out
}

/// Radius and surface distance must agree to within this factor, or the units differ.
pub(super) const UNIT_MISMATCH_FACTOR: f64 = 8.0;

/// Checks that the centerline radius matches the distance from the centerline to the surface;
/// a factor of 10, 100 or 1000 means the two files are in different units.
/// A warning when the (cleaned) surface has more loops ([`crate::io::input::topology::handles`])
/// than the mesh closes (`joined`, the loops its tree joins again: see
/// [`crate::stages::centerline::Junction::arriving`]): centerlines given as a tree, or cut open
/// elsewhere, leave the rest of each loop out, and the mesh ends on either side as at a vessel end.
pub(super) fn loop_warning(surface: &TriangleSurface, loops: usize, joined: usize) -> Option<Warning> {
    (loops > joined).then(|| {
        Warning::new(
            "surface_loops",
            format!(
                "{}: the surface has {loops} loop(s) (a ring of vessels such as a circle of Willis, a graft rejoining \
                 its host, or two vessels fused where they touch) and the mesh closes {joined}: a stretch of each other \
                 loop is left out, and the mesh ends on either side of it as at a vessel end. Let vesselhex find the \
                 centerlines, or give centerline.loop_cuts_mm where your centerlines are cut open",
                surface.source.display()
            ),
        )
    })
}

/// A warning when a network with loops meshed (`joined` of them closed) has the one inlet
/// nobody flagged: the largest end (`ends[inlet]`). Networks are often fed through several ends,
/// and which cannot be told from their size (in the generated networks, inlets and outlets
/// overlap in radius), so the user is asked, the next largest ends named.
pub(super) fn lone_inlet_warning(
    surface: &TriangleSurface,
    joined: usize,
    ends: &[crate::stages::centerline::extract::VesselEnd],
    inlet: usize,
) -> Option<Warning> {
    (joined > 0).then(|| {
        let at = |k: usize| {
            let e = &ends[k];
            format!("({:.3}, {:.3}, {:.3}) mm (radius {:.3} mm)", e.centre.x, e.centre.y, e.centre.z, e.radius)
        };
        let mut others: Vec<usize> = (0..ends.len()).filter(|&k| k != inlet).collect();
        others.sort_by(|&a, &b| ends[b].radius.total_cmp(&ends[a].radius).then(a.cmp(&b)));
        let next: Vec<String> = others.iter().take(2).map(|&k| at(k)).collect();
        Warning::new(
            "inlet_guessed",
            format!(
                "{}: the network has {joined} loop(s) and no inlet was flagged: its one inlet is the largest end, at \
                 {}, and every other end an outlet; a network is often fed through several ends (a circle of Willis: \
                 both internal carotids and the basilar artery), which their size does not tell: flag each with \
                 --inlet x,y,z (the next largest ends: {})",
                surface.source.display(),
                at(inlet),
                next.join(", ")
            ),
        )
    })
}

/// The loops of a (cleaned) surface ([`crate::io::input::topology::handles`]; none when it has
/// no genus to speak of).
pub(super) fn surface_loops(surface: &TriangleSurface) -> usize {
    crate::io::input::topology::handles(&surface.triangles).unwrap_or(0)
}

/// A refusal of a surface with loops says so: centerlines given without the loops' cuts
/// (`centerline.loop_cuts_mm`) make a path end inside another, or an end that is none.
pub(super) fn blame_loops(error: Error, loops: usize) -> Error {
    if loops == 0 {
        return error;
    }
    let why = format!(
        "; the surface has {loops} loop(s) (a ring of vessels, a graft rejoining its host, or two vessels fused where \
         they touch): vesselhex meshes a loop by cutting it open across one vessel to find the centerlines, and \
         joining that vessel again in the mesh"
    );
    match error {
        Error::Input { path, message } => Error::Input { path, message: message + &why },
        Error::Geometry(message) => Error::Geometry(message + &why),
        Error::ShortBranch { message, end_mm } => Error::ShortBranch { message: message + &why, end_mm },
        other => other,
    }
}

pub(super) fn check_units(surface: &LumenSurface, tree: &CenterlineTree, centerline_source: &Path) -> Result<()> {
    let samples: Vec<(Point3<f64>, f64)> = tree
        .branches
        .iter()
        .flat_map(|b| b.samples.iter().step_by((b.samples.len() / 50).max(1)))
        .map(|s| (s.point, s.radius))
        .collect();
    check_radius_against_surface(surface, &samples, centerline_source)
}

/// [`check_units`] and a coarse [`check_inside`] on the centerline file's own points, before
/// the tree is built: a branched vessel's junctions are analysed with the tree, and centerlines
/// in the wrong units (or another vessel's) would be refused there for a junction's shape, not
/// for what is wrong.
pub(super) fn check_centerline_file(surface: &LumenSurface, centerlines: &Centerlines) -> Result<()> {
    let source = &centerlines.source;
    // Points from the middle four fifths of each polyline (open ends may lie outside).
    let probes: Vec<(Point3<f64>, Option<f64>)> = centerlines
        .polylines
        .iter()
        .flat_map(|l| {
            let n = l.points.len();
            (1..=8).map(move |k| {
                let i = (n - 1) * (1 + k) / 10;
                (l.points[i], l.radii.as_ref().map(|r| r[i]))
            })
        })
        .collect();
    let step = (probes.len() / 64).max(1);
    let probes: Vec<_> = probes.into_iter().step_by(step).collect();
    let samples: Vec<(Point3<f64>, f64)> =
        probes.iter().filter_map(|(p, r)| r.filter(|r| *r > 0.0).map(|r| (*p, r))).collect();
    if !samples.is_empty() {
        check_radius_against_surface(surface, &samples, source)?;
    }
    let outside: Vec<&Point3<f64>> = probes
        .par_iter()
        .filter(|(p, _)| surface.winding_number(p).abs() < INSIDE_WINDING)
        .map(|(p, _)| p)
        .collect::<Vec<_>>();
    if 2 * outside.len() > probes.len() {
        check_winding(surface)?;
        let p = outside[0];
        let points = centerlines.polylines.iter().flat_map(|l| l.points.iter());
        let spans = extent(points) / extent(surface.vertices.iter());
        let scale = if !(0.25..=4.0).contains(&spans) {
            format!(" (it spans {} times the surface's extent)", short(spans))
        } else {
            String::new()
        };
        return Err(Error::input(
            source,
            format!(
                "most of the centerline lies outside the lumen surface {} ({} of {} points probed, e.g. ({:.3}, \
                 {:.3}, {:.3}) mm){scale}: the files are in different units or coordinate systems (--units, \
                 --centerline-units), or the centerline is not this vessel's",
                surface.source.display(),
                outside.len(),
                probes.len(),
                p.x,
                p.y,
                p.z
            ),
        ));
    }
    Ok(())
}

/// The diagonal of the points' bounding box.
pub(super) fn extent<'a>(points: impl Iterator<Item = &'a Point3<f64>>) -> f64 {
    let (mut lo, mut hi) = (Point3::from([f64::INFINITY; 3]), Point3::from([f64::NEG_INFINITY; 3]));
    for p in points {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    (hi - lo).norm()
}

/// The median of distance to the surface over radius at `samples` (point, radius) must be
/// within [`UNIT_MISMATCH_FACTOR`] of 1.
pub(super) fn check_radius_against_surface(
    surface: &LumenSurface,
    samples: &[(Point3<f64>, f64)],
    centerline_source: &Path,
) -> Result<()> {
    let mut ratios: Vec<f64> = samples.par_iter().map(|(p, r)| surface.closest(p).distance / r).collect();
    ratios.sort_by(f64::total_cmp);
    let median = ratios[ratios.len() / 2];
    if !(median < UNIT_MISMATCH_FACTOR && median > 1.0 / UNIT_MISMATCH_FACTOR) {
        let factor = if median >= 1.0 { median } else { 1.0 / median };
        return Err(Error::input(
            centerline_source,
            format!(
                "the centerline radius and the distance from the centerline to the surface {} differ by a factor of \
                 about {:.0} (median distance/radius = {median:.3e}): the two files are not in the same units, or \
                 the centerline is not this vessel's. Give each file's unit (--units for the surface, \
                 --centerline-units for the centerline)",
                surface.source.display(),
                factor
            ),
        ));
    }
    Ok(())
}

/// Winding numbers below this (in magnitude) mean a point is outside the lumen.
pub(super) const INSIDE_WINDING: f64 = 0.5;

/// Checks that the centerline runs inside the lumen and finds which way the surface's triangles
/// face (true: out of the lumen), from winding numbers at points along the centerline. The
/// first and last tenth of each branch and a radius next to an open end are left out: near an
/// open end the winding number drops towards 1/2 (measured on the gmsh arch: 0.25 at the end
/// point, 0.5 about 0.7 radius inside).
pub(super) fn check_inside(surface: &LumenSurface, tree: &CenterlineTree, centerline_source: &Path) -> Result<bool> {
    // Also at least a radius from an open end (a short wide branch's tenth is not enough).
    let tenths = tree
        .branches
        .iter()
        .flat_map(|b| (0..=20).map(move |i| (b, &b.samples[(b.samples.len() - 1) * (2 + i * 16 / 20) / 20])));
    let away = |(b, s): &(&crate::stages::centerline::Branch, &crate::stages::centerline::CenterlineSample)| {
        (b.start_junction.is_some() || s.s > s.radius) && (b.end_junction.is_some() || b.length() - s.s > s.radius)
    };
    let mut probes: Vec<&crate::stages::centerline::CenterlineSample> =
        tenths.clone().filter(away).map(|(_, s)| s).collect();
    if probes.is_empty() {
        probes = tenths.map(|(_, s)| s).collect();
    }
    let w: Vec<f64> = probes.par_iter().map(|s| surface.winding_number(&s.point)).collect();
    let total: f64 = w.iter().sum();
    if let Some((k, wk)) = w.iter().enumerate().find(|(_, x)| x.abs() < INSIDE_WINDING) {
        let outside = w.iter().filter(|x| x.abs() < INSIDE_WINDING).count();
        check_winding(surface)?;
        let p = probes[k];
        return Err(Error::input(
            centerline_source,
            format!(
                "the centerline lies outside the lumen surface {} at ({:.3}, {:.3}, {:.3}) mm, {:.2} mm along it \
                 (winding number {wk:.2}; {outside} of {} probed points are outside): check that the centerline \
                 belongs to this surface and that both are in the same units and coordinate system",
                surface.source.display(),
                p.point.x,
                p.point.y,
                p.point.z,
                p.s,
                w.len()
            ),
        ));
    }
    Ok(total > 0.0)
}

/// Refuses a surface whose triangles are not wound consistently: its winding numbers cannot
/// tell inside from outside, so a centerline found "outside" may not be.
pub(super) fn check_winding(surface: &LumenSurface) -> Result<()> {
    match winding_fault(&surface.triangles) {
        Some((fault, _)) => Err(Error::input(&surface.source, fault)),
        None => Ok(()),
    }
}

/// What is wrong with the triangles' winding, and the share of shared edges it concerns, if
/// some shared edges are run the same way by both their triangles.
pub(super) fn winding_fault(triangles: &[[u32; 3]]) -> Option<(String, f64)> {
    let (misoriented, shared) = misoriented_edges(triangles);
    (misoriented > 0).then(|| {
        let fault = format!(
            "the surface's triangles are not wound consistently ({misoriented} of its {shared} shared edges are run \
             the same way by both their triangles), so vesselhex cannot tell the lumen's inside from its outside: \
             orient the triangles consistently (e.g. ParaView's Generate Surface Normals with Consistency on, or \
             MeshLab's Re-Orient all faces coherently) and save again"
        );
        (fault, misoriented as f64 / shared as f64)
    })
}

/// Share of a surface's shared edges run the same way by both triangles beyond which a failed
/// run is put down to the winding (a few are non-manifold fins, as in some real surfaces).
pub(super) const MISWOUND_SHARE: f64 = 0.01;

/// A meshing error on a surface whose triangles are wound inconsistently names the winding
/// first: rays then meet the wall "from outside" and winding numbers mislead, whatever stage
/// stops.
pub(super) fn name_winding(error: Error, surface: &TriangleSurface) -> Error {
    if matches!(error, Error::Config(_)) {
        return error;
    }
    match winding_fault(&surface.triangles) {
        Some((fault, share)) if share > MISWOUND_SHARE => {
            Error::input(&surface.source, format!("{fault} (meshing stopped: {error})"))
        }
        _ => error,
    }
}

/// Edges of the triangles run the same way by two of them (each triangle of a consistently
/// wound surface runs a shared edge against its neighbour), and the edges two triangles share.
pub(super) fn misoriented_edges(triangles: &[[u32; 3]]) -> (usize, usize) {
    let mut directed: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
    for t in triangles {
        for k in 0..3 {
            *directed.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
        }
    }
    let misoriented = directed.values().filter(|&&n| n > 1).count();
    let shared = directed.keys().filter(|(a, b)| a < b && directed.contains_key(&(*b, *a))).count() + misoriented;
    (misoriented, shared)
}

/// Vessel radii (mm) outside which the units are probably wrong: a 50 um arteriole to a 30 mm
/// aneurysm.
pub(super) const PLAUSIBLE_RADIUS_MM: (f64, f64) = (0.05, 30.0);

/// A warning when the vessel's median radius (mm) is implausible in the units given, naming the
/// unit that would make it plausible.
pub(super) fn unit_warning(radius: f64, units: LengthUnit, centerline_units: Option<LengthUnit>) -> Option<Warning> {
    let (low, high) = PLAUSIBLE_RADIUS_MM;
    if !radius.is_finite() || (low..=high).contains(&radius) {
        return None;
    }
    let flag = match centerline_units {
        Some(c) if c != units => format!("--units {units} and --centerline-units {c}"),
        _ => format!("--units {units}"),
    };
    // The unit under which the radius is nearest a typical 3 mm artery.
    let in_file = radius / units.to_mm();
    let likely = [LengthUnit::Um, LengthUnit::Mm, LengthUnit::Cm, LengthUnit::M]
        .into_iter()
        .filter(|u| (low..=high).contains(&(in_file * u.to_mm())))
        .min_by(|a, b| {
            let off = |u: &LengthUnit| (in_file * u.to_mm() / 3.0).ln().abs();
            off(a).total_cmp(&off(b))
        });
    let hint = match likely {
        Some(u) => {
            format!("; if the files are in {u}, give --units {u} (a radius of {} mm)", short(in_file * u.to_mm()))
        }
        None => String::new(),
    };
    Some(Warning::new(
        "units",
        format!(
            "the vessel's median radius is {} mm with {flag}, outside the {low}-{high} mm of blood vessels{hint}",
            short(radius)
        ),
    ))
}

/// Refuses absolute lengths out of proportion with the vessel (the relative settings' bounds,
/// applied to the median radius): a wall thicker than twice the radius or thinner than a
/// thousandth of it, an axial spacing below a thousandth of the radius or above ten radii.
pub(super) fn check_lengths_against_radius(config: &MeshConfig, radius: f64) -> Result<()> {
    if !(radius > 0.0 && radius.is_finite()) {
        return Ok(());
    }
    let check = |key: &str, value: Option<f64>, (low, high): (f64, f64), relative: &str| match value {
        Some(v) if !(v >= low * radius && v <= high * radius) => Err(Error::Config(format!(
            "{key} = {v} mm is {} times the vessel's median radius ({} mm); it must be between {low} and {high} \
             times it (as {relative} is): give it in mm, or check the input's units",
            short(v / radius),
            short(radius)
        ))),
        _ => Ok(()),
    };
    check("wall.thickness_mm", config.wall.thickness_mm, (0.001, 2.0), "wall.thickness_ratio")?;
    let spacing = (crate::data::config::MIN_AXIAL_SPACING, 10.0);
    check("lumen.axial_spacing_mm", config.lumen.axial_spacing_mm, spacing, "lumen.axial_spacing")
}

/// Refuses a mesh with an inverted element, naming the worst (a degenerate one first), where
/// it is (its junction, and why a junction folds) and how many are inverted in all: the first
/// by number can be a near miss beside a fold hundreds of elements wide.
pub(super) fn refuse_inverted(
    mesh: &VesselMesh,
    junction_of: &[Option<usize>],
    junctions: &[JunctionGeometry],
    tree: &CenterlineTree,
    surface: &TriangleSurface,
) -> Result<()> {
    let inverted = |q: f64| q.is_nan() || q <= 0.0;
    let count = mesh.quality.iter().filter(|q| inverted(q.scaled_jacobian)).count();
    // By region: a fold of the lumen's blocks inverts lumen and wall alike; a wall grown across
    // a crotch sharper than its thickness inverts the wall only.
    let by_region: Vec<String> = Region::ALL
        .iter()
        .map(|&r| {
            let n =
                mesh.quality.iter().zip(&mesh.regions).filter(|(q, &g)| g == r && inverted(q.scaled_jacobian)).count();
            format!("{n} {}", r.name())
        })
        .collect();
    let by_region = by_region.join(", ");
    let rank = |q: f64| if q.is_nan() { f64::NEG_INFINITY } else { q };
    if let Some((e, q)) = mesh
        .quality
        .iter()
        .enumerate()
        .filter(|(_, q)| inverted(q.scaled_jacobian))
        .min_by(|a, b| rank(a.1.scaled_jacobian).total_cmp(&rank(b.1.scaled_jacobian)))
    {
        let c = crate::geometry::mesh::face_centre(&mesh.corners(e), 0);
        let (place, cause) = match junction_of[e] {
            Some(j) => (
                format!(", in {},", junctions[j].describe(tree)),
                junctions[j].fold_cause(tree, mesh.branch_of[e] as usize),
            ),
            None => (
                String::new(),
                "the vessel bends too sharply for the cross-sections, or the wall is too thick there. Increase \
                 centerline.smoothing_passes, reduce wall.thickness_ratio or lumen.axial_spacing"
                    .to_string(),
            ),
        };
        return Err(Error::Geometry(format!(
            "{}: element {} ({}) near ({:.3}, {:.3}, {:.3}) mm{place} is inverted (scaled Jacobian {:.3}; {count} \
             inverted in all: {by_region}): {cause}",
            surface.source.display(),
            e + 1,
            mesh.regions[e].name(),
            c.x,
            c.y,
            c.z,
            q.scaled_jacobian
        )));
    }
    Ok(())
}
