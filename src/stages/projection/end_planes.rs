//! Sections at a flat cap that is not square to the centerline turn into the cap's plane.
//!
//! Segmentation tools clip vessels where the user or the image decides, seldom square to the
//! centerline. A cross-section square to the centerline meets a cap tilted by `a` on a vessel of
//! radius `r` until it lies `r tan a` from the cap, and such a section is not clean (see
//! `projection`): that length of vessel is lost. Turning the end's sections into the cap's
//! plane, and back square over two radii, keeps the mesh up to the cap, with end faces in its
//! plane (where a solver's inlet or outlet condition is set). On
//! sphinxsys_pulmonary_bifurcation, whose trunk has a radius of 15 mm, is 19 mm long and is
//! capped 11 degrees off square, the 2.5 mm lost were nearly all of the 3 mm the trunk had left
//! beside its junction.

use crate::geometry::surface::LumenSurface;
use crate::geometry::vector::smoothstep;
use crate::stages::centerline::{Branch, Frame};
use nalgebra::{Point3, Vector3};

/// Rays cast along the centerline towards a cap, from this fraction of the vessel's radius off
/// the centerline, find its plane ...
const PROBE_OFFSET: f64 = 0.5;
/// ... this many rays around the centerline ...
const PROBES: usize = 8;
/// ... from this fraction of the turning length away from the end.
const PROBE_DEPTH: f64 = 0.25;
/// The triangles the rays meet make a flat cap when their normals agree within this cosine
/// (about 5 degrees) ...
const FLAT_COS: f64 = 0.996;
/// ... and the sections turn when the cap is off square by more than this (radians, 3 degrees;
/// a square cap leaves the sections as they are) ...
const LEAST_TILT: f64 = 0.052;
/// ... and by at most this (radians, 45 degrees): a face that steep is a wall, not a cap.
const MOST_TILT: f64 = 0.785;
/// Length over which the sections turn back square to the centerline, in vessel radii ...
const TURN_RADII: f64 = 2.0;
/// ... and at most this share of the branch (a junction's transition may start beyond).
const TURN_SHARE: f64 = 0.4;
/// A ray's hit lies on the cap when it is within this fraction of the vessel's radius of the
/// cap's plane (the flatness `centerline_extract` asks of a cap).
const ON_CAP: f64 = 0.02;

/// The flat cap a branch end's sections were turned into.
#[derive(Debug, Clone, Copy)]
pub struct CapPlane {
    /// A point of the cap and its unit normal, facing out of the vessel.
    pub point: Point3<f64>,
    pub normal: Vector3<f64>,
    /// The arc length from the end over which the sections were turned.
    pub reach: f64,
    /// Distance from the plane within which a point lies on the cap.
    pub tolerance: f64,
}

impl CapPlane {
    /// Whether `p` lies on the cap's plane (to its flatness).
    pub fn holds(&self, p: &Point3<f64>) -> bool {
        (p - self.point).dot(&self.normal).abs() <= self.tolerance
    }
}

/// The caps a branch's end sections were turned into, at its start and its end.
#[derive(Debug, Clone, Copy, Default)]
pub struct EndCaps {
    pub start: Option<CapPlane>,
    pub end: Option<CapPlane>,
}

impl EndCaps {
    /// The cap whose turned sections reach arc length `s` of a branch `length` long.
    pub fn turning_at(&self, s: f64, length: f64) -> Option<&CapPlane> {
        let start = self.start.as_ref().filter(|c| s < c.reach);
        start.or(self.end.as_ref().filter(|c| length - s < c.reach))
    }
}

/// The flat cap met by rays cast along `outward` from around `centre` (in `frame`'s plane), as
/// a point on it and its normal facing along `outward`; None when a ray runs out of the surface
/// (an open end) or the faces met do not share one plane (a dome, a wall).
fn cap_ahead(
    surface: &LumenSurface,
    centre: &Point3<f64>,
    frame: &Frame,
    outward: &Vector3<f64>,
    radius: f64,
) -> Option<(Point3<f64>, Vector3<f64>)> {
    let mut normals = Vec::with_capacity(PROBES);
    let mut points = Vec::with_capacity(PROBES);
    for k in 0..PROBES {
        let phi = std::f64::consts::TAU * k as f64 / PROBES as f64;
        let off = (frame.normal * phi.cos() + frame.binormal * phi.sin()) * (PROBE_OFFSET * radius);
        let hit = surface.first_hit(&(centre + off), outward, 2.0 * radius)?;
        let n = surface.normals[hit.triangle as usize];
        normals.push(if n.dot(outward) < 0.0 { -n } else { n });
        points.push(hit.point.coords);
    }
    let normal = normals.iter().sum::<Vector3<f64>>().try_normalize(1e-12)?;
    let point = Point3::from(points.iter().sum::<Vector3<f64>>() / PROBES as f64);
    normals.iter().all(|n| n.dot(&normal) >= FLAT_COS).then_some((point, normal))
}

/// Turns the sections at each vessel end of `branch` (an end without a junction) that meets a
/// flat cap off square into the cap's plane, back to square over [`TURN_RADII`] `radius` (the
/// vessel's radius near its ends), and returns the caps so turned.
pub fn turn_to_caps(branch: &mut Branch, surface: &LumenSurface, radius: f64) -> EndCaps {
    let mut caps = EndCaps::default();
    let length = branch.length();
    let reach = (TURN_RADII * radius).min(TURN_SHARE * length);
    if reach <= 0.0 {
        return caps;
    }
    for at_start in [true, false] {
        let junction = if at_start { branch.start_junction } else { branch.end_junction };
        if junction.is_some() {
            continue;
        }
        let probe = branch.at(if at_start { PROBE_DEPTH * reach } else { length - PROBE_DEPTH * reach });
        let outward = if at_start { -probe.frame.tangent } else { probe.frame.tangent };
        let Some((point, normal)) = cap_ahead(surface, &probe.point, &probe.frame, &outward, radius) else {
            continue;
        };
        if !(LEAST_TILT..=MOST_TILT).contains(&normal.angle(&outward)) {
            continue;
        }
        for sample in branch.samples.iter_mut() {
            let from_end = if at_start { sample.s } else { length - sample.s };
            if from_end >= reach {
                continue;
            }
            // The cap's plane at the end, square at `reach`, no kink at either.
            let w = 1.0 - smoothstep(from_end / reach);
            let downstream = if at_start { -normal } else { normal };
            sample.frame =
                Frame::from_tangent_and_hint(sample.frame.tangent * (1.0 - w) + downstream * w, sample.frame.normal);
        }
        let cap = CapPlane { point, normal, reach, tolerance: ON_CAP * radius };
        if at_start {
            caps.start = Some(cap);
        } else {
            caps.end = Some(cap);
        }
    }
    caps
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::centerline::CenterlineSample;

    fn capped_tube(r: f64, h: f64, tilt: f64) -> LumenSurface {
        LumenSurface::new(&crate::testing::tilted_cap_tube_surface(r, h, tilt)).unwrap()
    }

    /// The tube's centerline along z from the cap's centre, its sections square to it.
    fn axis(r: f64, h: f64) -> Branch {
        let frame = Frame { tangent: Vector3::z(), normal: Vector3::x(), binormal: Vector3::y() };
        let samples = (0..=40)
            .map(|i| {
                let s = h * i as f64 / 40.0;
                CenterlineSample { s, point: Point3::new(0.0, 0.0, s), radius: r, frame }
            })
            .collect();
        Branch::lone(samples)
    }

    #[test]
    fn sections_turn_into_a_tilted_cap_and_back_square() {
        let (r, h, tilt) = (2.0, 20.0, 12f64.to_radians());
        let surface = capped_tube(r, h, tilt);
        let mut branch = axis(r, h);
        let caps = turn_to_caps(&mut branch, &surface, r);
        let cap = caps.start.expect("the tilted cap is found");
        let square = Vector3::new(tilt.sin(), 0.0, -tilt.cos());
        assert!(cap.normal.angle(&square) < 1e-6, "cap normal {:?}", cap.normal);
        assert!(caps.end.is_none(), "the open end has no cap");
        // At the cap the sections lie in its plane; past two radii they stay square.
        assert!(branch.samples[0].frame.tangent.angle(&-square) < 1e-9);
        for sample in branch.samples.iter().filter(|s| s.s >= 2.0 * r) {
            assert!(sample.frame.tangent.angle(&Vector3::z()) < 1e-12, "at s = {}", sample.s);
        }
        // The turn is monotone, and each frame stays orthonormal.
        let angles: Vec<f64> = branch.samples.iter().map(|s| s.frame.tangent.angle(&Vector3::z())).collect();
        assert!(angles.windows(2).all(|w| w[1] <= w[0] + 1e-12));
        for s in &branch.samples {
            let f = s.frame;
            assert!((f.tangent.cross(&f.normal) - f.binormal).norm() < 1e-9);
        }
        assert!(cap.holds(&Point3::new(r * 0.5, 0.0, r * 0.5 * tilt.tan())));
        assert!(!cap.holds(&Point3::new(0.0, 0.0, 0.5)));
        assert!(caps.turning_at(0.1, h).is_some() && caps.turning_at(2.0 * r, h).is_none());
    }

    /// Meshed end to end, the tube's inlet section lies parallel to the tilted cap, next to it:
    /// the mesh reaches the cap all round (a square section spans 2 r sin(12 deg) = 0.83 mm of
    /// height above it, and a closed end's margin kept it a radius away besides).
    #[test]
    fn a_tube_clipped_off_square_is_meshed_up_to_its_cap() {
        let (r, h, tilt) = (2.0, 20.0, 12f64.to_radians());
        let surface = crate::testing::tilted_cap_tube_surface(r, h, tilt);
        let centerlines = crate::testing::straight_tube_centerline(r, h);
        let config = crate::data::config::MeshConfig::preset(crate::data::config::Preset::Coarse);
        let meshed = crate::pipeline::mesh_vessel(
            &surface,
            &centerlines,
            &config,
            &mut crate::pipeline::progress::Progress::new(true, 9),
        )
        .expect("meshed");
        let normal = Vector3::new(tilt.sin(), 0.0, -tilt.cos());
        let inlet = &meshed.mesh.node_sets[&crate::geometry::mesh::sets::lumen_end("inlet")];
        assert!(!inlet.is_empty());
        // Heights above the cap's plane: the same all round (parallel to the cap) and small (the
        // first clean section lies one centerline step in).
        let heights: Vec<f64> = inlet.iter().map(|&n| -meshed.mesh.nodes[n as usize].coords.dot(&normal)).collect();
        let (low, high) = heights.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| (a.min(h), b.max(h)));
        assert!(low > 0.0 && high - low <= ON_CAP * r, "the inlet section spans {low}..{high} mm above the cap");
        assert!(high <= 0.15 * r, "the inlet section lies {high} mm from the cap");
        let worst = meshed.mesh.quality.iter().map(|q| q.scaled_jacobian).fold(f64::INFINITY, f64::min);
        assert!(worst > 0.2, "worst scaled Jacobian {worst}");
    }

    #[test]
    fn a_square_cap_and_an_open_end_leave_the_sections_as_they_are() {
        for tilt in [0.0, 2f64.to_radians()] {
            let surface = capped_tube(2.0, 20.0, tilt);
            let mut branch = axis(2.0, 20.0);
            let caps = turn_to_caps(&mut branch, &surface, 2.0);
            assert!(caps.start.is_none() && caps.end.is_none(), "tilt {tilt}");
            assert!(branch.samples.iter().all(|s| s.frame.tangent == Vector3::z()));
        }
    }
}
