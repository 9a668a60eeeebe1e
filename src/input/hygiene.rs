//! Surface hygiene: what segmentation tools really write, made fit for meshing before anything
//! else looks at it. Each step is counted in a [`HygieneReport`] (report.json `input.hygiene`).
//!
//! * coincident vertices (within 1e-9 of the bounding box's diagonal) are welded, so that the
//!   triangles of a file that repeats its vertices per triangle share their edges;
//! * triangles with no area (a repeated or collinear vertex) and repeated triangles are dropped;
//! * the triangles are wound consistently across every manifold edge, facing out of the lumen
//!   (edges shared by three or more triangles are tolerated and counted);
//! * small disconnected fragments (less than [`FRAGMENT`] of the surface's area: stray
//!   triangles, specks of a segmentation) are dropped; a second large piece is refused by name,
//!   since a file should hold one vessel;
//! * a voxel staircase (a marching-cubes or cuberille surface straight from a label map, whose
//!   triangles face a handful of directions) is smoothed with Taubin's lambda-mu filter, which
//!   removes the steps without shrinking the vessel.

use super::topology::{boundary_loops, orient_consistently, signed_volume6, triangle_neighbours, NON_MANIFOLD};
use super::TriangleSurface;
use crate::error::{Error, Result};
use nalgebra::{Point3, Vector3};
use serde::Serialize;
use std::collections::HashMap;

/// A piece smaller than this fraction of the surface's area is a fragment, dropped.
const FRAGMENT: f64 = 0.01;
/// A second piece larger than this fraction of the largest is a second vessel, refused.
const SECOND_VESSEL: f64 = 0.1;
/// Vertices closer than this fraction of the bounding box's diagonal are one.
const WELD: f64 = 1e-9;
/// A surface with at least this share of its area facing one of a few directions is a voxel
/// staircase ...
const STAIRCASE_SHARE: f64 = 0.9;
/// ... a few: this many distinct directions (to 0.01 in each component of |n|).
const STAIRCASE_DIRECTIONS: usize = 13;
/// ... and at least this share of its edges' length is a crease (measured: a voxel aorta 0.21;
/// smooth real surfaces at most 0.02, cut caps' rims included; a coarse capped tube 0.005).
const STAIRCASE_CREASES: f64 = 0.1;
/// A crease: the normals of the two triangles differ by more than 30 degrees (cosine).
const CREASE_COS: f64 = 0.866;
/// Taubin smoothing of a staircase: this many lambda-mu pairs with these factors (Taubin 1995:
/// mu slightly larger than lambda in magnitude, so the pair neither shrinks nor grows).
const TAUBIN_PAIRS: usize = 30;
const TAUBIN_LAMBDA: f64 = 0.5;
const TAUBIN_MU: f64 = -0.53;

/// What hygiene changed.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct HygieneReport {
    pub vertices_welded: usize,
    pub degenerate_triangles_dropped: usize,
    pub duplicate_triangles_dropped: usize,
    pub triangles_flipped: usize,
    pub non_manifold_edges: usize,
    pub fragments_dropped: usize,
    pub fragment_triangles_dropped: usize,
    /// Taubin passes (lambda-mu pairs) applied to a voxel staircase; 0 for a smooth surface.
    pub staircase_smoothing_passes: usize,
    pub boundary_loops: usize,
    /// Whether the file's triangles faced into the lumen (they face out after hygiene).
    pub wound_inward: bool,
}

impl HygieneReport {
    /// One line per step that changed something, for the user.
    pub fn notes(&self) -> Vec<String> {
        let mut out = vec![];
        let mut say = |n: usize, what: &str| {
            if n > 0 {
                out.push(format!("{n} {what}"));
            }
        };
        say(self.vertices_welded, "coincident vertices welded");
        say(self.degenerate_triangles_dropped, "triangles without area dropped");
        say(self.duplicate_triangles_dropped, "repeated triangles dropped");
        say(self.triangles_flipped, "triangles wound against their neighbours flipped");
        say(self.non_manifold_edges, "edges shared by three or more triangles (tolerated)");
        if self.fragments_dropped > 0 {
            out.push(format!(
                "{} small disconnected pieces ({} triangles, less than {}% of the area each) dropped",
                self.fragments_dropped,
                self.fragment_triangles_dropped,
                FRAGMENT * 100.0
            ));
        }
        if self.staircase_smoothing_passes > 0 {
            out.push(format!(
                "the surface is a voxel staircase: smoothed with {} Taubin passes (the mesh follows the smoothed \
                 surface); smooth it yourself to control this",
                self.staircase_smoothing_passes
            ));
        }
        out
    }
}

/// The surface made fit for meshing (see the module's doc), and what was done.
pub fn clean_surface(mut surface: TriangleSurface) -> Result<(TriangleSurface, HygieneReport)> {
    let mut report = HygieneReport { vertices_welded: weld(&mut surface), ..Default::default() };
    drop_degenerate_and_repeated(&mut surface, &mut report);
    drop_fragments(&mut surface, &mut report)?;
    report.triangles_flipped = orient_consistently(&mut surface.triangles);
    let loops = boundary_loops(&surface.triangles);
    report.wound_inward = signed_volume6(&surface.vertices, &surface.triangles, &loops) < 0.0;
    if report.wound_inward {
        surface.triangles.iter_mut().for_each(|t| t.swap(1, 2));
    }
    report.boundary_loops = loops.len();
    report.non_manifold_edges = count_non_manifold(&surface.triangles);
    if is_staircase(&surface) {
        taubin(&mut surface);
        report.staircase_smoothing_passes = TAUBIN_PAIRS;
    }
    Ok((surface, report))
}

fn diagonal(vertices: &[Point3<f64>]) -> f64 {
    let Some(first) = vertices.first() else { return 0.0 };
    let (lo, hi) = vertices.iter().fold((*first, *first), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
    (hi - lo).norm()
}

/// Welds vertices within [`WELD`] of the diagonal (the first of a group is kept, in index
/// order) and drops the vertices no triangle uses; returns how many were merged.
pub fn weld(surface: &mut TriangleSurface) -> usize {
    let tol = WELD * diagonal(&surface.vertices);
    if tol <= 0.0 {
        return 0;
    }
    let key = |p: &Point3<f64>| (p / tol).map(|c| c.floor() as i64);
    let mut cells: HashMap<(i64, i64, i64), Vec<u32>> = HashMap::new();
    let mut target: Vec<u32> = (0..surface.vertices.len() as u32).collect();
    let mut merged = 0;
    for (i, p) in surface.vertices.iter().enumerate() {
        let k = key(p);
        let near = (-1..=1)
            .flat_map(|a| (-1..=1).flat_map(move |b| (-1..=1).map(move |c| (k.x + a, k.y + b, k.z + c))))
            .filter_map(|c| cells.get(&c))
            .flatten()
            .find(|&&j| (surface.vertices[j as usize] - p).norm() <= tol)
            .copied();
        match near {
            Some(j) => {
                target[i] = j;
                merged += 1;
            }
            None => cells.entry((k.x, k.y, k.z)).or_default().push(i as u32),
        }
    }
    if merged > 0 {
        surface.triangles.iter_mut().for_each(|t| *t = t.map(|v| target[v as usize]));
    }
    merged
}

/// Drops triangles with a repeated vertex or no area, and any triangle repeating an earlier one
/// (the same three vertices in any order); their tags go with them.
fn drop_degenerate_and_repeated(surface: &mut TriangleSurface, report: &mut HygieneReport) {
    let v = &surface.vertices;
    let mut seen = std::collections::HashSet::new();
    let keep: Vec<bool> = surface
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| v[i as usize]);
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || (b - a).cross(&(c - a)).norm() == 0.0 {
                report.degenerate_triangles_dropped += 1;
                return false;
            }
            let mut sorted = *t;
            sorted.sort_unstable();
            if !seen.insert(sorted) {
                report.duplicate_triangles_dropped += 1;
                return false;
            }
            true
        })
        .collect();
    retain_triangles(surface, &keep);
}

fn retain_triangles(surface: &mut TriangleSurface, keep: &[bool]) {
    let mut k = keep.iter();
    surface.triangles.retain(|_| *k.next().unwrap_or(&true));
    if let Some((_, tags)) = &mut surface.triangle_tags {
        let mut k = keep.iter();
        tags.retain(|_| *k.next().unwrap_or(&true));
    }
}

/// Triangles joined across shared edges (manifold or not) into pieces: the index of each
/// triangle's piece, pieces numbered by their first triangle.
fn pieces(triangles: &[[u32; 3]]) -> Vec<u32> {
    let mut parent: Vec<u32> = (0..triangles.len() as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    let mut edges: Vec<(u32, u32, u32)> = triangles
        .iter()
        .enumerate()
        .flat_map(|(t, tri)| {
            (0..3).map(move |k| (tri[k].min(tri[(k + 1) % 3]), tri[k].max(tri[(k + 1) % 3]), t as u32))
        })
        .collect();
    edges.sort_unstable();
    for w in edges.windows(2) {
        if (w[0].0, w[0].1) == (w[1].0, w[1].1) {
            let (a, b) = (find(&mut parent, w[0].2), find(&mut parent, w[1].2));
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    (0..triangles.len() as u32).map(|t| find(&mut parent, t)).collect()
}

/// Keeps the largest piece (by area); drops pieces under [`FRAGMENT`] of the total area;
/// refuses a second piece over [`SECOND_VESSEL`] of the largest.
fn drop_fragments(surface: &mut TriangleSurface, report: &mut HygieneReport) -> Result<()> {
    let piece = pieces(&surface.triangles);
    let v = &surface.vertices;
    let area_of = |t: &[u32; 3]| {
        let [a, b, c] = t.map(|i| v[i as usize]);
        0.5 * (b - a).cross(&(c - a)).norm()
    };
    let mut area: HashMap<u32, f64> = HashMap::new();
    let mut count: HashMap<u32, usize> = HashMap::new();
    for (t, &p) in surface.triangles.iter().zip(&piece) {
        *area.entry(p).or_default() += area_of(t);
        *count.entry(p).or_default() += 1;
    }
    if area.len() < 2 {
        return Ok(());
    }
    let total: f64 = area.values().sum();
    let mut by_area: Vec<(u32, f64)> = area.iter().map(|(&p, &a)| (p, a)).collect();
    by_area.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    let largest = by_area[0].1;
    if let Some(&(second, a)) = by_area.get(1).filter(|(_, a)| *a > SECOND_VESSEL * largest) {
        let t = piece.iter().position(|&p| p == second).expect("a piece has triangles");
        let c = surface.triangles[t].map(|i| v[i as usize]);
        let centre = Point3::from((c[0].coords + c[1].coords + c[2].coords) / 3.0);
        return Err(Error::input(
            &surface.source,
            format!(
                "holds {} separate pieces; a second one of {} triangles ({:.0}% of the largest's area) lies near \
                 ({:.3}, {:.3}, {:.3}) mm: give one vessel per file (split or join the pieces in your segmentation \
                 tool)",
                area.len(),
                count[&second],
                100.0 * a / largest,
                centre.x,
                centre.y,
                centre.z
            ),
        ));
    }
    let dropped: Vec<u32> = by_area[1..].iter().filter(|(_, a)| *a < FRAGMENT * total).map(|(p, _)| *p).collect();
    let keep: Vec<bool> = piece.iter().map(|p| !dropped.contains(p)).collect();
    report.fragments_dropped = dropped.len();
    report.fragment_triangles_dropped = keep.iter().filter(|k| !**k).count();
    retain_triangles(surface, &keep);
    Ok(())
}

fn count_non_manifold(triangles: &[[u32; 3]]) -> usize {
    let mut edges: Vec<(u32, u32)> = triangles
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]))))
        .collect();
    edges.sort_unstable();
    let mut n = 0;
    let mut i = 0;
    while i < edges.len() {
        let j = edges[i..].iter().take_while(|e| **e == edges[i]).count();
        if j > 2 {
            n += 1;
        }
        i += j;
    }
    n
}

/// Whether the surface is a staircase: most of its area faces a handful of directions (see
/// [`STAIRCASE_SHARE`]) and its steps make creases all over it (see [`STAIRCASE_CREASES`]).
/// Both are needed: a coarse polygonal tube also faces few directions (a 48-sided one faces
/// 12 up to sign) but is creased only at its caps' rims; a smooth surface is creased nowhere.
fn is_staircase(surface: &TriangleSurface) -> bool {
    let normals: Vec<Vector3<f64>> = surface.triangles.iter().map(|t| area_vector(&surface.vertices, t)).collect();
    few_directions(&normals) && crease_share(surface, &normals) >= STAIRCASE_CREASES
}

/// Twice the triangle's area along its normal.
fn area_vector(v: &[Point3<f64>], t: &[u32; 3]) -> Vector3<f64> {
    let [a, b, c] = t.map(|i| v[i as usize]);
    (b - a).cross(&(c - a))
}

/// Whether [`STAIRCASE_SHARE`] of the area faces at most [`STAIRCASE_DIRECTIONS`] directions.
fn few_directions(area_vectors: &[Vector3<f64>]) -> bool {
    let mut by_direction: HashMap<[i64; 3], f64> = HashMap::new();
    let mut total = 0.0;
    for n in area_vectors {
        let area = n.norm();
        if area == 0.0 {
            continue;
        }
        let key = (n / area).map(|x| (x.abs() * 100.0).round() as i64);
        *by_direction.entry([key.x, key.y, key.z]).or_default() += area;
        total += area;
    }
    let mut shares: Vec<f64> = by_direction.into_values().collect();
    shares.sort_by(|a, b| b.total_cmp(a));
    total > 0.0 && shares.iter().take(STAIRCASE_DIRECTIONS).sum::<f64>() >= STAIRCASE_SHARE * total
}

/// The share of the manifold edges' length along which the surface turns by more than 30
/// degrees.
fn crease_share(surface: &TriangleSurface, area_vectors: &[Vector3<f64>]) -> f64 {
    let v = &surface.vertices;
    let neighbours = triangle_neighbours(&surface.triangles);
    let (mut creased, mut total) = (0.0, 0.0);
    for (t, tri) in surface.triangles.iter().enumerate() {
        for k in 0..3 {
            let u = neighbours[t][k];
            // Each manifold edge once, from its lower-indexed triangle.
            if u >= NON_MANIFOLD || (u as usize) < t {
                continue;
            }
            let length = (v[tri[(k + 1) % 3] as usize] - v[tri[k] as usize]).norm();
            let (a, b) = (area_vectors[t], area_vectors[u as usize]);
            total += length;
            if a.dot(&b) < CREASE_COS * a.norm() * b.norm() {
                creased += length;
            }
        }
    }
    if total > 0.0 {
        creased / total
    } else {
        0.0
    }
}

/// Taubin's lambda-mu smoothing with uniform weights over each vertex's neighbours; vertices on
/// an open boundary stay put (a cut end keeps its plane).
fn taubin(surface: &mut TriangleSurface) {
    let n = surface.vertices.len();
    let mut neighbours: Vec<Vec<u32>> = vec![vec![]; n];
    for t in &surface.triangles {
        for k in 0..3 {
            neighbours[t[k] as usize].extend([t[(k + 1) % 3], t[(k + 2) % 3]]);
        }
    }
    neighbours.iter_mut().for_each(|l| {
        l.sort_unstable();
        l.dedup();
    });
    let mut fixed = vec![false; n];
    boundary_loops(&surface.triangles).iter().flatten().for_each(|&v| fixed[v as usize] = true);
    for _ in 0..TAUBIN_PAIRS {
        for factor in [TAUBIN_LAMBDA, TAUBIN_MU] {
            let moved: Vec<Point3<f64>> = (0..n)
                .map(|i| {
                    let p = surface.vertices[i];
                    if fixed[i] || neighbours[i].is_empty() {
                        return p;
                    }
                    let mean =
                        neighbours[i].iter().fold(Vector3::zeros(), |a, &j| a + surface.vertices[j as usize].coords)
                            / neighbours[i].len() as f64;
                    p + (mean - p.coords) * factor
                })
                .collect();
            surface.vertices = moved;
        }
    }
}
