//! Surface hygiene: what segmentation tools really write, made fit for meshing before anything
//! else looks at it. Each step is counted in a [`HygieneReport`] (report.json `input.hygiene`).
//!
//! * coincident vertices (within 1e-9 of the diagonal of the bounding box of the points the
//!   triangles use) are welded, so that the triangles of a file that repeats its vertices per
//!   triangle share their edges; points no triangle uses are dropped;
//! * triangles with no area (a repeated or collinear vertex) and repeated triangles are dropped;
//! * small pieces (triangles joined across edges of exactly two triangles; less than
//!   [`FRAGMENT`] of the surface's area: stray triangles, specks of a segmentation, scraps
//!   hanging off an edge of the wall) are dropped; an edge still shared by three or more
//!   triangles (a fin, two sheets meeting) is refused by name, and so is a second large piece,
//!   since a file should hold one vessel;
//! * the triangles are wound consistently and facing out, in one canonical form whatever the
//!   file's winding (see `orientation`);
//! * a voxel staircase (a marching-cubes or cuberille surface straight from a label map, whose
//!   triangles face a handful of directions) is smoothed with Taubin's lambda-mu filter, which
//!   removes the steps without shrinking the vessel.

use super::orientation::wind_outward;
use super::topology::{boundary_loops, triangle_neighbours, NON_MANIFOLD};
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
    pub fragments_dropped: usize,
    pub fragment_triangles_dropped: usize,
    /// Taubin passes (lambda-mu pairs) applied to a voxel staircase; 0 for a smooth surface.
    pub staircase_smoothing_passes: usize,
    pub boundary_loops: usize,
    /// Whether the file's triangles faced into the lumen (they face out after hygiene).
    pub wound_inward: bool,
    /// Edges of strips twisted between holes at a ragged rim, where no winding is consistent:
    /// left as they are (see `orientation`).
    pub twisted_rim_edges: usize,
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
        say(
            self.twisted_rim_edges,
            "edges of a strip twisted between holes at a rim (not orientable there) left as they are",
        );
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
    let winding = wind_outward(&mut surface)?;
    report.triangles_flipped = winding.flipped;
    report.wound_inward = winding.inward;
    report.twisted_rim_edges = winding.twisted_edges;
    report.boundary_loops = boundary_loops(&surface.triangles).len();
    if is_staircase(&surface) {
        taubin(&mut surface);
        report.staircase_smoothing_passes = TAUBIN_PAIRS;
    }
    Ok((surface, report))
}

/// The diagonal of the bounding box of the points the triangles use.
fn diagonal(surface: &TriangleSurface) -> f64 {
    let mut used = surface.triangles.iter().flatten().map(|&v| surface.vertices[v as usize]);
    let Some(first) = used.next() else { return 0.0 };
    let (lo, hi) = used.fold((first, first), |(lo, hi), p| (lo.inf(&p), hi.sup(&p)));
    (hi - lo).norm()
}

/// Welds vertices within [`WELD`] of the diagonal of the points in use (the first of a group
/// is kept, in index order) and drops the points no triangle uses (the others keep their
/// order); returns how many were merged. A tolerance relative to the surface's size holds at
/// any scale and unit.
pub fn weld(surface: &mut TriangleSurface) -> usize {
    let tol = WELD * diagonal(surface);
    let merged = if tol > 0.0 { merge_coincident(surface, tol) } else { 0 };
    drop_unused_points(surface);
    merged
}

/// Drops the points no triangle uses, the others renumbered in their order.
fn drop_unused_points(surface: &mut TriangleSurface) {
    let mut index = vec![u32::MAX; surface.vertices.len()];
    surface.triangles.iter().flatten().for_each(|&v| index[v as usize] = 0);
    let mut kept = 0;
    for (i, slot) in index.iter_mut().enumerate() {
        if *slot == 0 {
            *slot = kept;
            surface.vertices[kept as usize] = surface.vertices[i];
            kept += 1;
        }
    }
    surface.vertices.truncate(kept as usize);
    surface.triangles.iter_mut().for_each(|t| *t = t.map(|v| index[v as usize]));
}

/// Merges every vertex within `tol` of an earlier one into it; how many were merged.
fn merge_coincident(surface: &mut TriangleSurface, tol: f64) -> usize {
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

/// Triangles joined across manifold edges (edges of exactly two triangles) into pieces: the
/// index of each triangle's piece, pieces numbered by their first triangle. A scrap hanging off
/// an edge of the wall (three triangles on that edge) is a piece of its own.
fn pieces(triangles: &[[u32; 3]]) -> Vec<u32> {
    let mut parent: Vec<u32> = (0..triangles.len() as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    for (t, nb) in triangle_neighbours(triangles).iter().enumerate() {
        for &u in nb.iter().filter(|&&u| u < NON_MANIFOLD) {
            let (a, b) = (find(&mut parent, t as u32), find(&mut parent, u));
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    (0..triangles.len() as u32).map(|t| find(&mut parent, t)).collect()
}

/// Keeps the largest piece (by area); drops pieces under [`FRAGMENT`] of the total area;
/// refuses an edge still shared by three or more triangles, then a second piece over
/// [`SECOND_VESSEL`] of the largest.
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
    let total: f64 = area.values().sum();
    let mut by_area: Vec<(u32, f64)> = area.iter().map(|(&p, &a)| (p, a)).collect();
    by_area.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    let dropped: Vec<u32> = by_area.iter().skip(1).filter(|(_, a)| *a < FRAGMENT * total).map(|(p, _)| *p).collect();
    let keep: Vec<bool> = piece.iter().map(|p| !dropped.contains(p)).collect();
    report.fragments_dropped = dropped.len();
    report.fragment_triangles_dropped = keep.iter().filter(|k| !**k).count();
    retain_triangles(surface, &keep);
    refuse_non_manifold(surface)?;
    let large = |(p, a): &&(u32, f64)| *a > SECOND_VESSEL * by_area[0].1 && !dropped.contains(p);
    let Some(&(second, a)) = by_area.get(1).filter(large) else { return Ok(()) };
    let t = piece.iter().position(|&p| p == second).expect("a piece has triangles");
    let c = surface.triangles[keep[..t].iter().filter(|k| **k).count()].map(|i| surface.vertices[i as usize]);
    let centre = Point3::from((c[0].coords + c[1].coords + c[2].coords) / 3.0);
    Err(Error::input(
        &surface.source,
        format!(
            "holds {} separate pieces; a second one of {} triangles ({:.0}% of the largest's area) lies near ({:.3}, \
             {:.3}, {:.3}) mm: give one vessel per file (split or join the pieces in your segmentation tool)",
            area.len() - dropped.len(),
            count[&second],
            100.0 * a / by_area[0].1,
            centre.x,
            centre.y,
            centre.z
        ),
    ))
}

/// Refuses edges shared by three or more triangles, naming the first few: a fin or a second
/// sheet on the wall leaves the lumen's inside undefined there.
fn refuse_non_manifold(surface: &TriangleSurface) -> Result<()> {
    let mut edges: Vec<[u32; 2]> = vec![];
    for (tri, nb) in surface.triangles.iter().zip(triangle_neighbours(&surface.triangles)) {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            if nb[k] == NON_MANIFOLD {
                edges.push([a.min(b), a.max(b)]);
            }
        }
    }
    edges.sort_unstable();
    edges.dedup();
    if edges.is_empty() {
        return Ok(());
    }
    let at = |v: u32| {
        let p = surface.vertices[v as usize];
        format!("({:.4}, {:.4}, {:.4})", p.x, p.y, p.z)
    };
    let named: Vec<String> = edges.iter().take(3).map(|[a, b]| format!("{} to {}", at(*a), at(*b))).collect();
    Err(Error::input(
        &surface.source,
        format!(
            "has {} non-manifold edge(s), each shared by three or more triangles (a fin or a second sheet on the wall): \
             {}{} mm. Remove the extra triangles (e.g. MeshLab's Select Non Manifold Edges, then Delete) and save the \
             surface again",
            edges.len(),
            named.join("; "),
            if edges.len() > 3 { "; ..." } else { "" }
        ),
    ))
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
