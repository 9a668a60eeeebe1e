//! Finding a vessel's ends: flat caps (tagged by a cell array, or found as planar discs with a
//! sharp rim), open boundary loops, and points given by the user.

use super::medial::Ball;
use super::topology::{boundary_loops, loop_centre_and_area, triangle_neighbours, BOUNDARY, NON_MANIFOLD};
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
}

/// One end of the vessel, in millimetres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VesselEnd {
    /// Where the centerline starts or stops: the loop's length-weighted centre (VMTK's cap
    /// centre), or for a given point the centre of the inscribed ball under it.
    pub centre: Point3<f64>,
    /// Equivalent radius sqrt(area / pi) of the end section (for a given point: the radius of
    /// that inscribed ball).
    pub radius: f64,
    pub kind: EndKind,
}

/// A cap must be flat to this fraction of its equivalent radius.
const CAP_FLATNESS: f64 = 0.02;
/// ... and round enough: isoperimetric quotient 4 pi A / L^2 above this (1 for a circle).
const CAP_ROUNDNESS: f64 = 0.5;
/// Triangles grown into one planar region have normals within this angle (cosine).
const REGION_COS: f64 = 0.9994; // 2 degrees
/// A found (untagged) cap's rim is sharp: the wall meets it at more than this angle (cosine).
const RIM_COS: f64 = 0.866; // 30 degrees

/// Triangle index sets of the flat caps: the tag values whose triangles form a flat disc, or,
/// without such tags, planar regions bounded by one sharp rim.
pub fn find_caps(
    vertices: &[Point3<f64>],
    triangles: &[[u32; 3]],
    tags: Option<&[i64]>,
) -> Vec<(Option<i64>, Vec<u32>)> {
    if let Some(tags) = tags.filter(|t| t.len() == triangles.len()) {
        let mut groups: BTreeMap<i64, Vec<u32>> = BTreeMap::new();
        tags.iter().enumerate().for_each(|(t, &g)| groups.entry(g).or_default().push(t as u32));
        let caps: Vec<(Option<i64>, Vec<u32>)> = groups
            .into_iter()
            .filter(|(_, g)| 2 * g.len() < triangles.len() && is_flat_disc(vertices, triangles, g))
            .map(|(tag, g)| (Some(tag), g))
            .collect();
        if !caps.is_empty() {
            return caps;
        }
    }
    planar_regions(vertices, triangles)
        .into_iter()
        .filter(|r| 2 * r.len() < triangles.len() && is_flat_disc(vertices, triangles, r))
        .map(|r| (None, r))
        .collect()
}

fn unit_normal(vertices: &[Point3<f64>], t: &[u32; 3]) -> Vector3<f64> {
    let [a, b, c] = t.map(|i| vertices[i as usize]);
    (b - a).cross(&(c - a)).try_normalize(0.0).unwrap_or_default()
}

/// Regions grown across manifold edges from each unvisited triangle (in index order) while the
/// normals stay within 2 degrees of the seed's, kept when at least 4 triangles and bounded
/// only by sharp edges (no open edge).
fn planar_regions(vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> Vec<Vec<u32>> {
    let neighbours = triangle_neighbours(triangles);
    let normals: Vec<Vector3<f64>> = triangles.iter().map(|t| unit_normal(vertices, t)).collect();
    let mut region_of = vec![u32::MAX; triangles.len()];
    let mut regions = vec![];
    for seed in 0..triangles.len() {
        if region_of[seed] != u32::MAX || normals[seed] == Vector3::zeros() {
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
                    && normals[u as usize].dot(&normals[seed]) > REGION_COS
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
        .filter(|(id, r)| {
            r.len() >= 4
                && r.iter().all(|&t| {
                    (0..3).all(|k| {
                        let u = neighbours[t as usize][k];
                        u != BOUNDARY
                            && (u == NON_MANIFOLD
                                || region_of[u as usize] == *id as u32
                                || normals[u as usize].dot(&normals[t as usize]).abs() < RIM_COS)
                    })
                })
        })
        .map(|(_, r)| r)
        .collect()
}

/// Whether the triangles form a flat, roughly round disc bounded by a single loop.
fn is_flat_disc(vertices: &[Point3<f64>], triangles: &[[u32; 3]], subset: &[u32]) -> bool {
    let tris: Vec<[u32; 3]> = subset.iter().map(|&t| triangles[t as usize]).collect();
    let loops = boundary_loops(&tris);
    let [lp] = loops.as_slice() else { return false };
    let (centre, vector_area) = loop_centre_and_area(vertices, lp);
    let area = vector_area.norm();
    let Some(normal) = vector_area.try_normalize(0.0) else {
        return false;
    };
    let radius = (area / std::f64::consts::PI).sqrt();
    let perimeter: f64 =
        (0..lp.len()).map(|i| (vertices[lp[(i + 1) % lp.len()] as usize] - vertices[lp[i] as usize]).norm()).sum();
    let flat =
        tris.iter().flatten().all(|&v| (vertices[v as usize] - centre).dot(&normal).abs() <= CAP_FLATNESS * radius);
    flat && 4.0 * std::f64::consts::PI * area >= CAP_ROUNDNESS * perimeter * perimeter
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

/// The centre of every loop and the unit normal of its plane pointing into the lumen (`lumen_side` = +1 when the loop's right-hand normal does, i.e. when
/// the triangles face out of the lumen).
pub fn loop_planes(vertices: &[Point3<f64>], loops: &[Vec<u32>], lumen_side: f64) -> Vec<(Point3<f64>, Vector3<f64>)> {
    loops
        .iter()
        .map(|lp| {
            let (centre, area) = loop_centre_and_area(vertices, lp);
            (centre, area.try_normalize(0.0).unwrap_or_default() * lumen_side)
        })
        .collect()
}

/// The ends given by boundary loops, labelled as caps when every loop vertex belonged to a
/// removed cap, and the loops left out as holes (see [`END_SPAN`]). `balls` holds, for every
/// loop, the maximal ball tangent at its centre on the lumen's side; a loop without one cannot be
/// judged and is kept as an end.
pub fn loop_ends(
    vertices: &[Point3<f64>],
    loops: &[Vec<u32>],
    cap_tag_of_vertex: &BTreeMap<u32, Option<i64>>,
    balls: &[Option<Ball>],
) -> (Vec<VesselEnd>, Vec<Hole>) {
    let (mut ends, mut holes) = (vec![], vec![]);
    for (lp, ball) in loops.iter().zip(balls) {
        let (centre, area) = loop_centre_and_area(vertices, lp);
        let tags: Vec<Option<&Option<i64>>> = lp.iter().map(|v| cap_tag_of_vertex.get(v)).collect();
        let kind = match tags.first() {
            Some(Some(tag)) if tags.iter().all(|t| t.is_some()) => EndKind::Cap { tag: **tag },
            _ => EndKind::Open,
        };
        let radius = (area.norm() / std::f64::consts::PI).sqrt();
        if let Some(b) = ball {
            if radius < END_SPAN * b.radius {
                holes.push(Hole { centre, radius, vessel_radius: b.radius });
                continue;
            }
        }
        ends.push(VesselEnd { centre, radius, kind });
    }
    (ends, holes)
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
    (0..ends.len()).min_by(|&a, &b| key(&ends[a]).total_cmp(&key(&ends[b])).then(a.cmp(&b))).unwrap_or(0)
}
