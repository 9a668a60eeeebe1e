//! A blind branch (the sac of a saccular aneurysm) closed by a dome of hexes, so the sac is
//! meshed to its tip with no end face: the sac is lumen wall all over, not an outlet.
//!
//! The last ordinary section's O-grid is closed as a half-ball O-grid is. Its core square is
//! extruded towards the tip into a box of `q` layers; each layer is a section whose rays run from
//! the box's side to the surface, rising from the section's plane towards the tip; the box's top
//! is a core grid whose rays fan over the tip. On the surface this lays the flat O-grid of a disc
//! over the dome: the section's ring, `q` rings rising from it, and the core grid on top. Every
//! node is placed as a section's are: on a ray from the box to the surface, at the lumen's radial
//! levels, so the dome's lumen is graded to the wall and its wall grows like the rest.
//!
//! In the section's frame (normal, binormal, tangent), with r the section's radius and H the
//! distance from its centre to the surface along the tangent, the rays aim at an ellipsoid of
//! half-axes `ray_reach` (r, r, H): a side ray of ring point k at elevation phi from the plane,
//! a top ray at angle psi from the tangent, psi growing with the core node's square ring (its
//! Chebyshev distance from the centre) up to the side rings' last elevation. So cells are about
//! as tall as wide on a hemispherical dome.

use super::{cast_rays, cast_section, ProjectedSection};
use crate::geometry::surface::LumenSurface;
use crate::stages::centerline::CenterlineSample;
use crate::stages::junction::blocks::SectionTemplate;
use nalgebra::{Point3, Vector2, Vector3};
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4};

/// The core grid on top of a dome: for every core node of the template, its ray from the box's
/// top to the surface.
#[derive(Debug, Clone)]
pub struct DomeTop {
    /// The box's top nodes (template order), where the rays start.
    pub origins: Vec<Point3<f64>>,
    /// Unit ray directions.
    pub dirs: Vec<Vector3<f64>>,
    /// Where each ray meets the surface.
    pub surface: Vec<Point3<f64>>,
}

/// The box's layers beyond the last section, for a core of nx x ny: about half the core's
/// elements across, so the box's cells are about cubes.
fn dome_layers(template: &SectionTemplate) -> usize {
    ((template.nx + template.ny) / 4).max(1)
}

/// A dome taller than this many of its base's radii is reached by straight sections first: over
/// a tall dome the rays rise steeply from the box, and its corner cells shear (a tube ending in a
/// half-ellipsoid 1.6 radii tall, closed from one radius short of it: minimum scaled Jacobian
/// 0.284 without them).
const TALLEST_DOME: f64 = 1.2;

/// The sections and the dome beyond `last` (the branch's last ordinary section): sections along
/// its tangent while the dome ahead is taller than [`TALLEST_DOME`] (`spacing` apart), then the
/// box's layers as sections (rays rising towards the tip), and the top grid. Err names what
/// failed (a ray missing the surface, or meeting it from outside) for the caller's message.
pub fn project_dome(
    template: &SectionTemplate,
    surface: &LumenSurface,
    last: &ProjectedSection,
    spacing: &(dyn Fn(&CenterlineSample) -> f64 + Sync),
    orientation: f64,
) -> Result<(Vec<ProjectedSection>, DomeTop), String> {
    let mut sections = Vec::new();
    let mut height = height_ahead(surface, &last.station, template)?;
    loop {
        let base = sections.last().unwrap_or(last).station;
        // Steps of the branch's spacing, the last no shorter than half of it.
        let (excess, spacing) = (height - TALLEST_DOME * base.radius, spacing(&base));
        if excess < 0.5 * spacing {
            break;
        }
        let step = spacing.min(excess);
        let mut station = base;
        station.point += base.frame.tangent * step;
        station.s += step;
        // Its radius: its rays' mean reach, cast with the last radius first.
        let probe = cast_section(template, surface, &station, orientation).1;
        station.radius =
            probe.surface.iter().map(|p| (p - station.point).norm()).sum::<f64>() / probe.surface.len() as f64;
        let (probe, section) = cast_section(template, surface, &station, orientation);
        if !probe.valid() {
            return Err(format!(
                "{} of the {} rays of a section {:.3} mm beyond it miss the surface or meet it from outside",
                probe.misses + probe.from_outside,
                template.ring_len(),
                station.s - last.station.s
            ));
        }
        height -= step;
        sections.push(section);
    }
    let last = sections.last().unwrap_or(last).clone();
    let station = &last.station;
    let (t, n, b) = (station.frame.tangent, station.frame.normal, station.frame.binormal);
    let (c0, r) = (station.point, station.radius);
    let q = dome_layers(template);
    let across = 0.5 * (template.nx + template.ny) as f64;
    // The side rings' last elevation: q rings up to it, `across` top cells over the rest of the
    // half-circle, both of one angular step.
    let top_elevation = FRAC_PI_2 * q as f64 / (q as f64 + 0.5 * across);
    let box_top = template.core_size * height;
    let target = |psi: f64, theta: f64| -> Point3<f64> {
        c0 + (((n * theta.cos() + b * theta.sin()) * (r * psi.sin())) + t * (height * psi.cos())) * template.ray_reach
    };
    for j in 1..=q {
        let lift = t * (box_top * j as f64 / q as f64);
        let core: Vec<Point3<f64>> = last.core.iter().map(|p| p + lift).collect();
        let psi = FRAC_PI_2 - top_elevation * j as f64 / q as f64;
        let targets: Vec<Point3<f64>> = template.target_dir.iter().map(|d| target(psi, d.y.atan2(d.x))).collect();
        let mut layer_station = *station;
        layer_station.point = station.point + lift;
        let (probe, section) = cast_rays(template, surface, &layer_station, core, &targets, orientation);
        if !probe.valid() {
            return Err(format!(
                "{} of the {} rays of the dome's layer {j} of {q} miss the surface or meet it from outside",
                probe.misses + probe.from_outside,
                template.ring_len()
            ));
        }
        sections.push(section);
    }
    let top_core = &sections[sections.len() - 1].core;
    let mut top = DomeTop { origins: top_core.clone(), dirs: Vec::new(), surface: Vec::new() };
    for (c, xy) in template.core.iter().enumerate() {
        let (chebyshev, theta) = square_polar(xy, template.core_size);
        let aim = target((FRAC_PI_2 - top_elevation) * chebyshev, theta);
        let origin = top_core[c];
        let d = aim - origin;
        let dir = d / d.norm();
        let hit = surface.first_hit(&origin, &dir, d.norm() * super::RAY_SLACK);
        match hit {
            Some(hit) if surface.normals[hit.triangle as usize].dot(&dir) * orientation > 0.0 => {
                top.surface.push(hit.point);
                top.dirs.push(dir);
            }
            _ => return Err("a ray of the dome's top misses the surface or meets it from outside".to_string()),
        }
    }
    Ok((sections, top))
}

/// Distance from a section's centre to the surface along its tangent.
fn height_ahead(surface: &LumenSurface, station: &CenterlineSample, template: &SectionTemplate) -> Result<f64, String> {
    let reach = 2.0 * station.radius + 4.0 * template.ray_reach * station.radius;
    surface
        .first_hit(&station.point, &station.frame.tangent, reach)
        .map(|h| (h.point - station.point).norm())
        .ok_or_else(|| "the surface does not close beyond it along the centerline".to_string())
}

/// A point of the core square [-a, a]^2 as its square ring (max(|x|, |y|) / a, 0 at the centre,
/// 1 on the boundary) and its angle: the angle the template gives the ring point at the same
/// place of the boundary (each side's quarter of the circle, evenly along the side; see
/// [`SectionTemplate::rect`]), so the top's boundary rays are the last side ring's.
fn square_polar(xy: &Vector2<f64>, a: f64) -> (f64, f64) {
    let chebyshev = xy.x.abs().max(xy.y.abs());
    if chebyshev <= 1e-12 * a {
        return (0.0, 0.0);
    }
    let (u, v) = (xy.x / chebyshev, xy.y / chebyshev);
    // The side the point's square ring meets first, and how far along it (0 to 1) the point is,
    // counter-clockwise from the corner (1, -1).
    let sides = [(u, (v + 1.0) / 2.0), (v, (1.0 - u) / 2.0), (-u, (1.0 - v) / 2.0), (-v, (u + 1.0) / 2.0)];
    let side = (0..4).fold(0, |best, s| if sides[s].0 > sides[best].0 + 1e-12 { s } else { best });
    (chebyshev / a, -FRAC_PI_4 + FRAC_PI_2 * (side as f64 + sides[side].1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_square_rings_boundary_angles_are_the_templates() {
        for (nx, ny) in [(4, 4), (8, 4), (6, 6)] {
            let template = SectionTemplate::rect(nx, ny, 0.45, 1.3);
            for (k, dir) in template.target_dir.iter().enumerate() {
                let (ring, theta) = square_polar(&template.core[template.ring_core_index[k]], 0.45);
                assert!((ring - 1.0).abs() < 1e-12);
                let expected = dir.y.atan2(dir.x);
                let turn = (theta - expected).rem_euclid(std::f64::consts::TAU);
                assert!(turn.min(std::f64::consts::TAU - turn) < 1e-9, "{nx}x{ny}, ring point {k}");
            }
        }
        assert_eq!(square_polar(&Vector2::zeros(), 0.45).0, 0.0);
        let (ring, theta) = square_polar(&Vector2::new(0.0, 0.225), 0.45);
        assert!((ring - 0.5).abs() < 1e-12 && (theta - FRAC_PI_2).abs() < 1e-12);
    }
}
