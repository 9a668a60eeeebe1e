//! A cross-section taken from the plane's cut through the surface: the closed loop of the cut
//! around the station, rather than rays of a fixed reach from the centerline.
//!
//! Rays cast from the centerline miss where the lumen reaches beyond them (a plane leaning
//! through a narrowing, the spared side of an eccentric plaque) or where the centerline point
//! lies outside the lumen (a tight stenosis whose smoothed centerline cuts its corner). The
//! cut's loop is closed wherever the lumen is, so a section built inside it always closes:
//! its centre is a point deep inside the loop, its core fits inside it, and every ray from the
//! core's boundary meets the loop (a ray from inside a closed curve leaves it). A neighbouring
//! vessel's loop is another loop, so it blocks nothing.

use super::{Probe, ProjectedSection, CORE_REACH, RAY_SLACK};
use crate::geometry::plane_cut::{plane_loops, CutLoop, Plane};
use crate::geometry::surface::LumenSurface;
use crate::stages::centerline::CenterlineSample;
use crate::stages::junction::blocks::SectionTemplate;
use nalgebra::Vector2;

/// Candidate centres searched inside the loop: a grid of this many per side over its box.
const CENTRE_GRID: usize = 24;
/// The station's own point stays the centre when it lies at least this share of the loop's
/// deepest point's depth inside it: sections along a branch keep their centres on its
/// centerline wherever they can.
const KEEP_CENTRE_DEPTH: f64 = 0.5;

/// The section of `station` built on the loop of the plane's cut around it, or `None` when
/// the plane cuts no closed loop there (it runs out through an open end or a hole, or beyond
/// the reach of a few radii).
pub(super) fn cut_section(
    template: &SectionTemplate,
    surface: &LumenSurface,
    station: &CenterlineSample,
    orientation: f64,
) -> Option<(Probe, ProjectedSection)> {
    let f = &station.frame;
    let plane = Plane { origin: station.point, x: f.normal, y: f.binormal };
    let reach = 2.0 * RAY_SLACK * template.ray_reach * station.radius;
    let loops = plane_loops(surface, &plane, reach);
    let own = own_loop(&loops, station.radius)?;
    let centre = section_centre(own);
    let walls: Vec<f64> =
        template.target_dir.iter().map(|d| own.first_hit(&centre, d).map(|h| h.0)).collect::<Option<_>>()?;
    let scale = core_scale(template, own, &centre, &walls, station.radius)?;
    let moved = CenterlineSample { point: plane.to_3d(&centre), ..*station };
    let core2: Vec<Vector2<f64>> = template.core.iter().map(|c| centre + c * scale).collect();
    let mut probe = Probe::default();
    let mut section = ProjectedSection {
        station: moved,
        origins: vec![],
        dirs: vec![],
        surface: vec![],
        core: core2.iter().map(|c| plane.to_3d(c)).collect(),
        in_junction: false,
    };
    for (k, (d, w)) in template.target_dir.iter().zip(&walls).enumerate() {
        let origin = core2[template.ring_core_index[k]];
        let dir = (centre + d * *w - origin).normalize();
        let (_, seg, u) = own.first_hit(&origin, &dir)?;
        let dir3 = f.normal * dir.x + f.binormal * dir.y;
        let n = surface.normals[own.triangles[seg] as usize];
        if n.dot(&dir3) * orientation <= 0.0 {
            probe.from_outside += 1;
        }
        probe.axial_normal = probe.axial_normal.max(n.dot(&f.tangent).abs());
        section.origins.push(plane.to_3d(&origin));
        section.dirs.push(dir3);
        section.surface.push(own.point_on(seg, u));
    }
    Some((probe, section))
}

/// The branch's own loop: the smallest that holds the station's point, or, when the point lies
/// outside every loop (the centerline cuts a corner of the lumen), the nearest within a radius.
fn own_loop(loops: &[CutLoop], radius: f64) -> Option<&CutLoop> {
    let origin = Vector2::zeros();
    let area = |l: &CutLoop| l.signed_area().abs();
    let holding = loops.iter().filter(|l| l.contains(&origin)).min_by(|a, b| area(a).total_cmp(&area(b)));
    holding.or_else(|| {
        loops
            .iter()
            .map(|l| (l.distance(&origin), l))
            .filter(|(d, _)| *d <= radius)
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, l)| l)
    })
}

/// The section's centre in the plane: the station's point when it lies well inside the loop,
/// else the deepest of a grid of points over the loop (the centre of its widest inscribed
/// circle, near enough).
fn section_centre(own: &CutLoop) -> Vector2<f64> {
    let (mut lo, mut hi) = (Vector2::repeat(f64::INFINITY), Vector2::repeat(f64::NEG_INFINITY));
    for p in &own.plane {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let step = (hi - lo) / CENTRE_GRID as f64;
    let grid = (0..CENTRE_GRID * CENTRE_GRID).map(|k| {
        let (i, j) = (k % CENTRE_GRID, k / CENTRE_GRID);
        lo + Vector2::new(step.x * (i as f64 + 0.5), step.y * (j as f64 + 0.5))
    });
    let deepest = grid
        .filter(|q| own.contains(q))
        .map(|q| (own.distance(&q), q))
        .fold((0.0, Vector2::zeros()), |best, c| if c.0 > best.0 { c } else { best });
    let origin = Vector2::zeros();
    if own.contains(&origin) && own.distance(&origin) >= KEEP_CENTRE_DEPTH * deepest.0 {
        origin
    } else {
        deepest.1
    }
}

/// The core's scale (mm per template unit): the station's radius, shrunk until each ring node
/// lies within [`CORE_REACH`] of the way from the centre to the wall in its target's direction
/// and inside the loop. `None` when no core fits.
fn core_scale(
    template: &SectionTemplate,
    own: &CutLoop,
    centre: &Vector2<f64>,
    walls: &[f64],
    radius: f64,
) -> Option<f64> {
    let mut scale = radius;
    for (k, w) in walls.iter().enumerate() {
        let c = template.core[template.ring_core_index[k]];
        let cos = (c.dot(&template.target_dir[k]) / c.norm()).max(0.1);
        scale = scale.min(CORE_REACH * w * cos / c.norm());
    }
    // A loop that is not star-shaped about its centre may still cut in between the rays.
    for _ in 0..8 {
        let inside = template.core.iter().all(|c| own.contains(&(centre + c * scale)));
        if inside {
            return Some(scale);
        }
        scale *= 0.7;
    }
    None
}
