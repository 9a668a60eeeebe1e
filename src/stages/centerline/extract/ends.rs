//! Finding a vessel's ends: flat caps (tagged by a cell array, or found as planar discs with a
//! sharp rim), open boundary loops, and points given by the user.

use crate::io::input::topology::{boundary_loops, loop_centre_and_area, triangle_neighbours, BOUNDARY, NON_MANIFOLD};
use crate::io::input::NamedCap;
use nalgebra::{Point3, Vector3};
use std::collections::BTreeMap;

/// How an end was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EndKind {
    /// An open boundary loop of the surface.
    Open,
    /// A flat cap, removed before the centerlines were traced; `tag` is its cell-array value.
    Cap { tag: Option<i64> },
    /// A point given by the user (`--ends`), snapped to the surface.
    Given,
    /// A rounded or blunt closed end, found as the far tip of a vessel the other ends' paths
    /// do not reach (see `rounded`).
    Dome,
    /// The dome of a saccular aneurysm beside the vessels (see `rounded::sac_ends`): not a
    /// vessel end, but meshed as a blind branch.
    Sac,
    /// An end of centerlines given with the surface (nothing was looked for).
    Centerline,
}

impl EndKind {
    /// The kind's name in messages and report.json.
    pub fn name(&self) -> &'static str {
        match self {
            EndKind::Open => "open",
            EndKind::Cap { tag: Some(_) } => "tagged cap",
            EndKind::Cap { tag: None } => "flat cap",
            EndKind::Given => "given",
            EndKind::Dome => "dome",
            EndKind::Sac => "sac",
            EndKind::Centerline => "centerline",
        }
    }
}

/// One end of the vessel, in millimetres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VesselEnd {
    /// Where the centerline starts or stops: the loop's length-weighted centre (VMTK's cap
    /// centre; a blunt face's too), or for a given point or a dome the centre of the inscribed
    /// ball under it.
    pub centre: Point3<f64>,
    /// Equivalent radius sqrt(area / pi) of the end section (for a given point, a dome or a
    /// blunt face: the radius of the inscribed ball under it).
    pub radius: f64,
    pub kind: EndKind,
}

/// A cap must be flat to this fraction of its equivalent radius ...
const CAP_FLATNESS: f64 = 0.02;
/// ... beyond its rim's own distance from its plane, for a cap a sharp rim bounds, when that
/// rim lies within this fraction of the radius of a plane. A cap closes the rim it is given:
/// a rim of twenty points on a tube cut by hand strays from a plane by a few percent of the
/// radius, and a cap's triangles strung across it cannot be flatter than it.
const RIM_FLATNESS: f64 = 0.1;
/// A cap must be round enough: isoperimetric quotient 4 pi A / L^2 above this (1 for a circle).
const CAP_ROUNDNESS: f64 = 0.5;

/// How flat a disc must be: within [`CAP_FLATNESS`] of a plane, or of its rim (see
/// [`RIM_FLATNESS`]).
#[derive(Clone, Copy)]
enum Flatness {
    Plane,
    AsItsRim,
}

/// Triangles grown into one planar region have normals within this angle (cosine).
const REGION_COS: f64 = 0.9994; // 2 degrees

/// A flat region is a cap when its equivalent radius is at least this fraction of the
/// inscribed ball at its centre (the vessel's radius there); lower than [`END_SPAN`] since a
/// blunt end's flat part stops short of its rounded rim, and a short stub may narrow to its cap.
pub const CAP_SPAN: f64 = 0.4;
/// A cut cap's rim is sharp: every rim edge turns by more than 30 degrees (cosine).
const RIM_COS: f64 = 0.866;
/// A cap found by its rim alone, whatever the lean of its triangles, is bounded by edges that
/// turn by at least 60 degrees (cosine): a vessel cut square turns by about 90 degrees all round,
/// while the creases of a rough wall, which may enclose a few flat-looking triangles, turn less.
/// (A cap cut obliquely, whose rim turns less in places, is found as a planar region.)
const CUT_RIM_COS: f64 = 0.5;

/// A flat region that may close a vessel: its triangles, the end it would make, and whether
/// its rim is sharp all around (a cut) or rounded (a blunt end).
#[derive(Debug, Clone)]
pub struct Cap {
    pub triangles: Vec<u32>,
    pub end: VesselEnd,
    pub sharp_rim: bool,
}

/// The flat regions that may close a vessel: the tag values whose triangles form a flat disc
/// (tagged caps, taken as they are, with a sharp rim), or, without such tags, regions that form
/// a flat, round disc (see [`flat_disc`]): those a sharp rim bounds, then planar ones among the
/// rest, their rims sharp or rounded. Which of them are ends is for the caller to judge against
/// the vessel behind them.
pub fn find_caps(vertices: &[Point3<f64>], triangles: &[[u32; 3]], tags: Option<&[i64]>) -> Vec<Cap> {
    let disc = |tris: &[u32], tag: Option<i64>, sharp_rim: bool, rim: Flatness| -> Option<Cap> {
        let (centre, radius) = flat_disc(vertices, triangles, tris, rim)?;
        let end = VesselEnd { centre, radius, kind: EndKind::Cap { tag } };
        Some(Cap { triangles: tris.to_vec(), end, sharp_rim })
    };
    if let Some(tags) = tags.filter(|t| t.len() == triangles.len()) {
        let mut groups: BTreeMap<i64, Vec<u32>> = BTreeMap::new();
        tags.iter().enumerate().for_each(|(t, &g)| groups.entry(g).or_default().push(t as u32));
        let caps: Vec<Cap> = groups
            .into_iter()
            .filter(|(_, g)| 2 * g.len() < triangles.len())
            .filter_map(|(tag, g)| disc(&g, Some(tag), true, Flatness::Plane))
            .collect();
        if !caps.is_empty() {
            return caps;
        }
    }
    // A cut cap first: the region its sharp rim bounds, however its triangles lean within it (a
    // fine cap over a rim that is not quite planar bends by more than the planar regions' 2
    // degrees near the rim, and would fall apart into pieces none of which spans the vessel).
    let surface = RegionSurface::new(vertices, triangles);
    let mut taken = vec![false; triangles.len()];
    let mut caps: Vec<(u32, Cap)> = vec![];
    let candidates = |regions: Vec<(Vec<u32>, bool)>| {
        regions.into_iter().filter(|(r, _)| 2 * r.len() < triangles.len()).collect::<Vec<_>>()
    };
    for (r, _) in candidates(surface.regions(&taken, |_, t, u| surface.smooth_edge(t, u))) {
        if let Some(cap) = disc(&r, None, true, Flatness::AsItsRim) {
            r.iter().for_each(|&t| taken[t as usize] = true);
            caps.push((r[0], cap));
        }
    }
    // Then a cap with no point inside its rim (a fan of slivers, an ear-clipped polygon: what
    // hole-filling tools leave), whose triangles may crease one another where the rim is not
    // quite planar, and whose rim may turn by less than a cut's where the cut is oblique: the
    // triangles with every corner on a sharp edge (a wall triangle beside the rim has a corner
    // off it, see [`RegionSurface::corners_off_creases`]), kept when the rim is sharp all round
    // and no corner lies inside it (a patch of a rough wall whose corners all lie on creases
    // has a softer edge or a point inside).
    let mut excluded = surface.corners_off_creases(vertices.len(), triangles);
    excluded.iter_mut().zip(&taken).for_each(|(off, &t)| *off |= t);
    for (r, sharp) in candidates(surface.regions(&excluded, |_, _, _| true)) {
        if !sharp || !every_corner_on_its_rim(triangles, &r) {
            continue;
        }
        if let Some(cap) = disc(&r, None, true, Flatness::AsItsRim) {
            r.iter().for_each(|&t| taken[t as usize] = true);
            caps.push((r[0], cap));
        }
    }
    // Then planar regions (a blunt end's face, its rim rounded), among the triangles left.
    for (r, sharp) in candidates(surface.regions(&taken, |seed, _, u| surface.planar_with(seed, u))) {
        caps.extend(disc(&r, None, sharp, Flatness::Plane).map(|cap| (r[0], cap)));
    }
    // In the order of their first triangles, whichever way each was found.
    caps.sort_by_key(|(first, _)| *first);
    caps.into_iter().map(|(_, cap)| cap).collect()
}

/// Whether the region's triangles have every corner on its boundary (one loop, or none).
fn every_corner_on_its_rim(triangles: &[[u32; 3]], region: &[u32]) -> bool {
    let tris: Vec<[u32; 3]> = region.iter().map(|&t| triangles[t as usize]).collect();
    let rim: std::collections::HashSet<u32> = boundary_loops(&tris).into_iter().flatten().collect();
    tris.iter().flatten().all(|v| rim.contains(v))
}

fn unit_normal(vertices: &[Point3<f64>], t: &[u32; 3]) -> Vector3<f64> {
    let [a, b, c] = t.map(|i| vertices[i as usize]);
    (b - a).cross(&(c - a)).try_normalize(0.0).unwrap_or_default()
}

/// The triangles' normals and neighbours, for growing regions across manifold edges.
struct RegionSurface {
    neighbours: Vec<[u32; 3]>,
    normals: Vec<Vector3<f64>>,
}

impl RegionSurface {
    fn new(vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> RegionSurface {
        let neighbours = triangle_neighbours(triangles);
        let normals = triangles.iter().map(|t| unit_normal(vertices, t)).collect();
        RegionSurface { neighbours, normals }
    }

    /// Whether `u`'s normal lies within 2 degrees of the region's seed's.
    fn planar_with(&self, seed: usize, u: usize) -> bool {
        self.normals[u].dot(&self.normals[seed]) > REGION_COS
    }

    /// Whether the edge between neighbours `t` and `u` turns by less than a cut's rim (see
    /// [`CUT_RIM_COS`]; a degenerate triangle, with no normal, goes with its neighbours).
    fn smooth_edge(&self, t: usize, u: usize) -> bool {
        let (a, b) = (self.normals[t], self.normals[u]);
        a == Vector3::zeros() || b == Vector3::zeros() || a.dot(&b) > CUT_RIM_COS
    }

    /// Whether each triangle has a corner on no sharp edge (one turning by more than 30
    /// degrees, see [`RIM_COS`]). A cap triangulated without points inside has every corner on
    /// its rim, which is sharp; the wall's triangles beside the rim reach off it into the
    /// smooth wall, so they do not join the cap.
    fn corners_off_creases(&self, vertices: usize, triangles: &[[u32; 3]]) -> Vec<bool> {
        let mut on_crease = vec![false; vertices];
        for (t, tri) in triangles.iter().enumerate() {
            for (k, &u) in self.neighbours[t].iter().enumerate() {
                if u < NON_MANIFOLD && self.normals[t].dot(&self.normals[u as usize]) < RIM_COS {
                    on_crease[tri[k] as usize] = true;
                    on_crease[tri[(k + 1) % 3] as usize] = true;
                }
            }
        }
        triangles.iter().map(|tri| tri.iter().any(|&v| !on_crease[v as usize])).collect()
    }

    /// Regions grown across manifold edges from each triangle neither taken nor yet in a region
    /// (in index order, so a region's first triangle is its seed), joining a neighbour `u` of a
    /// member `t` when `joins(seed, t, u)`; kept when at least 4 triangles and bounded by no
    /// open edge, each with whether every rim edge is sharp (see [`RIM_COS`]).
    fn regions(&self, taken: &[bool], joins: impl Fn(usize, usize, usize) -> bool) -> Vec<(Vec<u32>, bool)> {
        let (neighbours, normals) = (&self.neighbours, &self.normals);
        let mut region_of = vec![u32::MAX; normals.len()];
        let mut regions = vec![];
        for seed in 0..normals.len() {
            if region_of[seed] != u32::MAX || taken[seed] || normals[seed] == Vector3::zeros() {
                continue;
            }
            let id = regions.len() as u32;
            let mut members = vec![seed as u32];
            region_of[seed] = id;
            let mut k = 0;
            while k < members.len() {
                let t = members[k] as usize;
                k += 1;
                for &u in &neighbours[t] {
                    if u < NON_MANIFOLD
                        && region_of[u as usize] == u32::MAX
                        && !taken[u as usize]
                        && joins(seed, t, u as usize)
                    {
                        region_of[u as usize] = id;
                        members.push(u);
                    }
                }
            }
            regions.push(members);
        }
        regions
            .into_iter()
            .enumerate()
            .filter(|(_, r)| r.len() >= 4 && r.iter().all(|&t| neighbours[t as usize].iter().all(|&u| u != BOUNDARY)))
            .map(|(id, r)| {
                let sharp = r.iter().all(|&t| {
                    neighbours[t as usize].iter().all(|&u| {
                        u == NON_MANIFOLD
                            || region_of[u as usize] == id as u32
                            || normals[u as usize].dot(&normals[t as usize]).abs() < RIM_COS
                    })
                });
                (r, sharp)
            })
            .collect()
    }
}

/// The caps given in files of their own and joined to the wall (their triangles tagged, see
/// [`crate::io::input::CAP_TAGS`]), each an end at its rim's centre whatever its shape.
pub fn tagged_caps(vertices: &[Point3<f64>], triangles: &[[u32; 3]], tags: &[i64], given: &[NamedCap]) -> Vec<Cap> {
    given
        .iter()
        .filter_map(|cap| {
            let tag = cap.tag?;
            let own: Vec<u32> = (0..triangles.len() as u32).filter(|&t| tags.get(t as usize) == Some(&tag)).collect();
            let tris: Vec<[u32; 3]> = own.iter().map(|&t| triangles[t as usize]).collect();
            let loops = boundary_loops(&tris);
            let [rim] = loops.as_slice() else { return None };
            let (centre, area) = loop_centre_and_area(vertices, rim);
            let radius = (area.norm() / std::f64::consts::PI).sqrt();
            let end = VesselEnd { centre, radius, kind: EndKind::Cap { tag: Some(tag) } };
            Some(Cap { triangles: own, end, sharp_rim: true })
        })
        .collect()
}

/// The name of each end that a cap given names: the end nearest the cap's rim centre, within
/// [`NAMED_END_REACH`] of the larger of their radii. A cap that names no end, or an end named by
/// two caps, is refused (the message names the cap's file).
pub fn names_of_ends(ends: &[VesselEnd], caps: &[NamedCap]) -> Result<Vec<Option<String>>, String> {
    let mut names: Vec<Option<String>> = vec![None; ends.len()];
    for cap in caps {
        let gap = |e: &VesselEnd| (e.centre - cap.centre).norm();
        let nearest = (0..ends.len())
            .filter(|&k| ends[k].kind != EndKind::Sac)
            .min_by(|&a, &b| gap(&ends[a]).total_cmp(&gap(&ends[b])));
        let Some(k) = nearest.filter(|&k| gap(&ends[k]) <= NAMED_END_REACH * ends[k].radius.max(cap.radius)) else {
            let c = cap.centre;
            return Err(format!(
                "the cap {} ({}) at ({:.3}, {:.3}, {:.3}) mm closes no end of the surface: give the caps of this wall \
                 (in the same units and frame)",
                cap.name,
                cap.file.display(),
                c.x,
                c.y,
                c.z
            ));
        };
        if let Some(other) = &names[k] {
            return Err(format!(
                "the caps {other} and {} ({}) both close the end at ({:.3}, {:.3}, {:.3}) mm: give one cap per end",
                cap.name,
                cap.file.display(),
                ends[k].centre.x,
                ends[k].centre.y,
                ends[k].centre.z
            ));
        }
        names[k] = Some(cap.name.clone());
    }
    Ok(names)
}

/// A cap names the end within this many radii (its own or the end's) of its rim's centre.
const NAMED_END_REACH: f64 = 1.0;

/// The centre and equivalent radius of the triangles when they form a flat, roughly round disc
/// bounded by a single loop.
fn flat_disc(
    vertices: &[Point3<f64>],
    triangles: &[[u32; 3]],
    subset: &[u32],
    rim: Flatness,
) -> Option<(Point3<f64>, f64)> {
    let tris: Vec<[u32; 3]> = subset.iter().map(|&t| triangles[t as usize]).collect();
    let loops = boundary_loops(&tris);
    let [lp] = loops.as_slice() else { return None };
    let (centre, vector_area) = loop_centre_and_area(vertices, lp);
    let area = vector_area.norm();
    let normal = vector_area.try_normalize(0.0)?;
    let radius = (area / std::f64::consts::PI).sqrt();
    let perimeter: f64 =
        (0..lp.len()).map(|i| (vertices[lp[(i + 1) % lp.len()] as usize] - vertices[lp[i] as usize]).norm()).sum();
    let off_plane = |v: &u32| (vertices[*v as usize] - centre).dot(&normal).abs();
    let tolerance = match rim {
        Flatness::Plane => CAP_FLATNESS * radius,
        Flatness::AsItsRim => {
            let rim_off = lp.iter().map(off_plane).fold(0.0, f64::max);
            (rim_off <= RIM_FLATNESS * radius).then_some(rim_off + CAP_FLATNESS * radius)?
        }
    };
    let flat = tris.iter().flatten().all(|v| off_plane(v) <= tolerance);
    (flat && 4.0 * std::f64::consts::PI * area >= CAP_ROUNDNESS * perimeter * perimeter).then_some((centre, radius))
}

/// A boundary loop is a vessel end when it spans the vessel: its equivalent radius is at least
/// this fraction of the local vessel radius, the radius of the maximal ball tangent to the loop's
/// plane at its centre, on the lumen's side. At a vessel's end that ball is the end section's own
/// inscribed ball (ratio about 1; more for an oblique cut). Behind a hole punched in a wall it is
/// the ball of the vessel around the hole, much larger than the hole; a side branch cut at least
/// one of its radii from its parent keeps its own ball and stays an end.
pub const END_SPAN: f64 = 0.5;

/// A boundary loop left out as a hole in the wall, with the figures that decided it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hole {
    pub centre: Point3<f64>,
    /// Equivalent radius sqrt(area / pi) of the loop.
    pub radius: f64,
    /// Radius of the maximal ball tangent at its centre (the local vessel radius).
    pub vessel_radius: f64,
}

/// The ends given by boundary loops, and the loops left out as holes (see [`END_SPAN`]);
/// `vessel_radius(centre, radius)` is the inscribed ball's radius at a loop's centre.
pub fn loop_ends(
    vertices: &[Point3<f64>],
    loops: &[Vec<u32>],
    vessel_radius: impl Fn(&Point3<f64>, f64) -> f64,
) -> (Vec<VesselEnd>, Vec<Hole>) {
    let (mut ends, mut holes) = (vec![], vec![]);
    for lp in loops {
        let (centre, area) = loop_centre_and_area(vertices, lp);
        let radius = (area.norm() / std::f64::consts::PI).sqrt();
        let vessel = vessel_radius(&centre, radius);
        if radius < END_SPAN * vessel {
            holes.push(Hole { centre, radius, vessel_radius: vessel });
        } else {
            ends.push(VesselEnd { centre, radius, kind: EndKind::Open });
        }
    }
    (ends, holes)
}

/// An end whose centre lies within this many radii of a larger end's centre is a piece of it.
const NESTED: f64 = 1.5;

/// The ends less those whose centre lies near a larger end's (see [`NESTED`]): pieces
/// of one end (a cap slightly bent into several flat regions, a loop beside its cap) are one
/// end, the largest piece. Order kept. Ends `at_cut` (where a loop was cut open: two ends facing
/// each other across a small gap) are kept whatever their neighbours.
pub fn merge_nested(ends: Vec<VesselEnd>, at_cut: impl Fn(&VesselEnd) -> bool) -> Vec<VesselEnd> {
    let inside_larger = |e: &VesselEnd| {
        !at_cut(e) && ends.iter().any(|o| o.radius > e.radius && (o.centre - e.centre).norm() < NESTED * o.radius)
    };
    ends.iter().filter(|e| !inside_larger(e)).copied().collect()
}

/// How the inlet is chosen among the ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InletChoice {
    /// The end of largest equivalent radius (ties: the first found).
    Largest,
    /// The end whose centre is nearest this point (mm).
    Nearest(Point3<f64>),
}

/// Index of the inlet among `ends` (not empty).
pub fn choose_inlet(ends: &[VesselEnd], choice: InletChoice) -> usize {
    let key = |e: &VesselEnd| match choice {
        InletChoice::Largest => -e.radius,
        InletChoice::Nearest(p) => (e.centre - p).norm(),
    };
    // A sac is no vessel end: the flow cannot enter there.
    (0..ends.len())
        .filter(|&e| ends[e].kind != EndKind::Sac)
        .min_by(|&a, &b| key(&ends[a]).total_cmp(&key(&ends[b])).then(a.cmp(&b)))
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tube of radius 1 along z from 0 to 4, 32 points round, its rim at z = 0 waved by
    /// `wave` (a fraction of the radius) and closed by a cap of 8 rings strung from that rim to
    /// its centre, its rim at z = 4 closed by a flat cap of the same kind.
    fn tube_with_ring_caps(wave: f64) -> (Vec<Point3<f64>>, Vec<[u32; 3]>, usize) {
        let (around, along, rings) = (32usize, 10usize, 8usize);
        let angle = |i: usize| std::f64::consts::TAU * i as f64 / around as f64;
        let mut vertices = vec![];
        for j in 0..=along {
            for i in 0..around {
                let z = 4.0 * j as f64 / along as f64 + if j == 0 { wave * (3.0 * angle(i)).sin() } else { 0.0 };
                vertices.push(Point3::new(angle(i).cos(), angle(i).sin(), z));
            }
        }
        let at = |j: usize, i: usize| (j * around + i % around) as u32;
        let mut triangles = vec![];
        for j in 0..along {
            for i in 0..around {
                triangles.push([at(j, i), at(j, i + 1), at(j + 1, i + 1)]);
                triangles.push([at(j, i), at(j + 1, i + 1), at(j + 1, i)]);
            }
        }
        let mut cap = |rim_row: usize, outward: bool, triangles: &mut Vec<[u32; 3]>| {
            let mut previous: Vec<u32> = (0..around).map(|i| at(rim_row, i)).collect();
            for k in 1..=rings {
                let scale = 1.0 - k as f64 / rings as f64;
                let ring: Vec<u32> = if k == rings {
                    vertices.push(Point3::new(0.0, 0.0, 4.0 * rim_row as f64 / along as f64));
                    vec![(vertices.len() - 1) as u32; around]
                } else {
                    (0..around)
                        .map(|i| {
                            let rim = vertices[previous[i] as usize];
                            let lift = rim.z - 4.0 * rim_row as f64 / along as f64;
                            let z = rim.z - lift / (rings - k + 1) as f64;
                            vertices.push(Point3::new(scale * angle(i).cos(), scale * angle(i).sin(), z));
                            (vertices.len() - 1) as u32
                        })
                        .collect()
                };
                for i in 0..around {
                    let (a, b, c, d) = (previous[i], previous[(i + 1) % around], ring[(i + 1) % around], ring[i]);
                    let quad = if outward { [[a, c, b], [a, d, c]] } else { [[a, b, c], [a, c, d]] };
                    triangles.extend(quad.into_iter().filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2]));
                }
                previous = ring;
            }
        };
        let wall = triangles.len();
        cap(0, true, &mut triangles);
        cap(along, false, &mut triangles);
        let per_cap = (triangles.len() - wall) / 2;
        (vertices, triangles, per_cap)
    }

    #[test]
    fn a_cap_strung_across_a_rim_that_is_not_quite_planar_is_one_cap() {
        // A rim 4 % of the radius off its plane: the cap's triangles next to it lean by about
        // 15 degrees, far beyond a planar region's 2.
        let (vertices, triangles, per_cap) = tube_with_ring_caps(0.04);
        let caps = find_caps(&vertices, &triangles, None);
        assert_eq!(caps.len(), 2, "{caps:?}");
        for cap in &caps {
            assert!(cap.sharp_rim);
            assert_eq!(cap.triangles.len(), per_cap);
            assert!((cap.end.radius - 1.0).abs() < 0.05, "radius {}", cap.end.radius);
            assert!(cap.end.centre.x.abs() < 1e-9 && cap.end.centre.y.abs() < 1e-9);
        }
        let mut z: Vec<f64> = caps.iter().map(|c| c.end.centre.z).collect();
        z.sort_by(f64::total_cmp);
        assert!(z[0].abs() < 0.02 && (z[1] - 4.0).abs() < 1e-9, "{z:?}");
    }

    #[test]
    fn a_cap_whose_rim_strays_far_from_a_plane_is_not_a_flat_cap() {
        // A rim 30 % of the radius off its plane closes a vessel with a saddle, not a flat cap.
        let (vertices, triangles, _) = tube_with_ring_caps(0.3);
        let caps = find_caps(&vertices, &triangles, None);
        assert_eq!(caps.len(), 1, "{caps:?}");
        assert!((caps[0].end.centre.z - 4.0).abs() < 1e-9);
    }

    /// A tube of radius 1 along z up to 4, 32 points round, cut at its foot by a plane leaning
    /// `tilt` (its slope) and waved by `wave` (a fraction of the radius), both ends closed by
    /// fans of slivers from their rims' first points, as hole-filling tools close a hole (no
    /// point inside the rim); the foot's fan is the last triangles, how many returned.
    fn tube_with_fan_caps(tilt: f64, wave: f64) -> (Vec<Point3<f64>>, Vec<[u32; 3]>, usize) {
        let (around, along) = (32u32, 10u32);
        let angle = |i: u32| std::f64::consts::TAU * i as f64 / around as f64;
        let mut vertices = vec![];
        for j in 0..=along {
            let s = j as f64 / along as f64;
            for i in 0..around {
                let foot = tilt * angle(i).cos() + wave * (3.0 * angle(i)).sin();
                vertices.push(Point3::new(angle(i).cos(), angle(i).sin(), (1.0 - s) * foot + 4.0 * s));
            }
        }
        let at = |j: u32, i: u32| j * around + i % around;
        let mut triangles = vec![];
        for j in 0..along {
            for i in 0..around {
                triangles.push([at(j, i), at(j, i + 1), at(j + 1, i + 1)]);
                triangles.push([at(j, i), at(j + 1, i + 1), at(j + 1, i)]);
            }
        }
        triangles.extend((1..around - 1).map(|i| [at(along, 0), at(along, i), at(along, i + 1)]));
        let foot: Vec<[u32; 3]> = (1..around - 1).map(|i| [at(0, 0), at(0, i + 1), at(0, i)]).collect();
        let fan = foot.len();
        triangles.extend(foot);
        (vertices, triangles, fan)
    }

    #[test]
    fn a_fan_of_slivers_across_an_oblique_rim_that_is_not_quite_planar_is_one_cap() {
        // Cut 35 degrees off square, the rim turns by 55 degrees on one side, less than a cut
        // cap's rim (60), so its region runs into the wall; waved by 4 % of the radius, the
        // slivers lean more than a planar region's 2 degrees from one another.
        let (vertices, triangles, fan) = tube_with_fan_caps(35f64.to_radians().tan(), 0.04);
        let surface = RegionSurface::new(&vertices, &triangles);
        let foot = triangles.len() - fan..triangles.len();
        let turns = |t: usize| surface.neighbours[t].map(|u| surface.normals[t].dot(&surface.normals[u as usize]));
        let rim_turns: Vec<f64> = foot
            .clone()
            .flat_map(|t| {
                surface.neighbours[t]
                    .into_iter()
                    .zip(turns(t))
                    .filter(|(u, _)| !foot.contains(&(*u as usize)))
                    .map(|(_, c)| c)
            })
            .collect();
        assert!(rim_turns.iter().any(|&c| c > CUT_RIM_COS), "a rim edge turns by less than 60 degrees");
        assert!(rim_turns.iter().all(|&c| c < RIM_COS), "every rim edge turns by more than 30 degrees");
        let planar = foot.clone().all(|t| surface.normals[t].dot(&surface.normals[foot.start]) > REGION_COS);
        assert!(!planar, "the slivers are not within 2 degrees of one plane");
        let caps = find_caps(&vertices, &triangles, None);
        assert_eq!(caps.len(), 2, "{caps:?}");
        let cap = caps.iter().find(|c| c.end.centre.z < 2.0).expect("the foot's fan is a cap");
        assert_eq!(cap.triangles.len(), fan);
        assert!(cap.sharp_rim);
        let rim: Vec<u32> = (0..32).collect();
        let (centre, _) = loop_centre_and_area(&vertices, &rim);
        assert!((cap.end.centre - centre).norm() < 1e-9, "the cap's end at its rim's centre");
        // A rim 30 % off its plane, fanned, is no flat cap.
        let (vertices, triangles, _) = tube_with_fan_caps(0.0, 0.3);
        let caps = find_caps(&vertices, &triangles, None);
        assert_eq!(caps.len(), 1, "{caps:?}");
        assert!((caps[0].end.centre.z - 4.0).abs() < 1e-9);
    }
}
