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
//! * a voxel staircase (a marching-cubes or cuberille surface straight from a label map, creased
//!   all over by its steps, convex and concave alike) is smoothed with Taubin's lambda-mu filter,
//!   which removes the steps without shrinking the vessel.

use super::orientation::wind_outward;
use super::topology::{boundary_loops, triangle_neighbours, NON_MANIFOLD};
use super::TriangleSurface;
use crate::data::error::{Error, Result};
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::HashMap;

/// A piece smaller than this fraction of the surface's area is a fragment, dropped.
const FRAGMENT: f64 = 0.01;
/// A second piece larger than this fraction of the largest is a second vessel, refused.
const SECOND_VESSEL: f64 = 0.1;
/// Vertices closer than this fraction of the bounding box's diagonal are one.
const WELD: f64 = 1e-9;
/// A surface is a voxel staircase when at least this share of its edges' length is a crease
/// (measured: a voxel aorta 0.21, 0.10 subdivided, 0.33 decimated to 3,000 triangles; smooth
/// real surfaces at most 0.06, cut caps' rims included; coarse real surfaces of 2,600-3,000
/// triangles 0.11-0.14; a coarse capped tube 0.005) ...
const STAIRCASE_CREASES: f64 = 0.1;
/// ... and at least this share of the creases' length is concave. A staircase's steps
/// alternate, a riser's foot concave and its top convex, so on a vessel (convex around, its
/// terraces following it) somewhat less than half is concave: the voxel aorta 0.42 as given,
/// rotated, noisy, subdivided; 0.38 decimated. A smooth vessel triangulated coarsely is creased
/// convex around its tubes and concave only in its saddles (the junctions' crotches): the
/// cohort's coarse surfaces 0.10-0.30, whatever the mutation. A third lies between the two; it
/// needs no direction, so a rotated or noisy staircase is one too.
const STAIRCASE_CONCAVE: f64 = 1.0 / 3.0;
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

/// Whether the surface is a voxel staircase: its steps crease it all over
/// ([`STAIRCASE_CREASES`]), convex and concave alike ([`STAIRCASE_CONCAVE`]). Both are needed:
/// a coarse polygonal tube is creased at its caps' rims, convex; a coarse real surface is
/// creased convex around its tubes; a smooth surface is creased nowhere. Neither figure depends
/// on the surface's orientation in space, its unit or a little noise (an earlier test, most of
/// the area facing a dozen directions, missed the voxel aorta written with noise or decimated,
/// and depended on the axes).
fn is_staircase(surface: &TriangleSurface) -> bool {
    let creases = creases(surface);
    creases.share >= STAIRCASE_CREASES && creases.concave >= STAIRCASE_CONCAVE
}

/// Twice the triangle's area along its normal.
fn area_vector(v: &[Point3<f64>], t: &[u32; 3]) -> Vector3<f64> {
    let [a, b, c] = t.map(|i| v[i as usize]);
    (b - a).cross(&(c - a))
}

/// How a surface is creased: the share of its manifold edges' length along which it turns by
/// more than 30 degrees, and the share of that length that is concave (seen from outside).
struct Creases {
    share: f64,
    concave: f64,
}

/// The surface's creases ([`Creases`]), its triangles wound outward.
fn creases(surface: &TriangleSurface) -> Creases {
    let v = &surface.vertices;
    let area_vectors: Vec<Vector3<f64>> = surface.triangles.iter().map(|t| area_vector(v, t)).collect();
    let neighbours = triangle_neighbours(&surface.triangles);
    let (mut creased, mut concave, mut total) = (0.0, 0.0, 0.0);
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
                // Concave: the neighbour's far corner lies outside this triangle's plane.
                let far = surface.triangles[u as usize].into_iter().find(|c| !tri.contains(c));
                if far.is_some_and(|c| (v[c as usize] - v[tri[k] as usize]).dot(&a) > 0.0) {
                    concave += length;
                }
            }
        }
    }
    let share = |part: f64, whole: f64| if whole > 0.0 { part / whole } else { 0.0 };
    Creases { share: share(creased, total), concave: share(concave, creased) }
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
            // Each vertex from the previous positions alone: the same whatever the thread count.
            let moved: Vec<Point3<f64>> = (0..n)
                .into_par_iter()
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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Unit};
    use std::path::PathBuf;

    fn surface(vertices: Vec<Point3<f64>>, triangles: Vec<[u32; 3]>) -> TriangleSurface {
        TriangleSurface { vertices, triangles, triangle_tags: None, source: PathBuf::from("test.stl") }
    }

    /// A closed tube of unit voxels as a label map's cuberille gives it: the faces between the
    /// voxels whose centres lie within `radius` of the z axis (for `length` voxels) and the
    /// others, wound outward.
    fn cuberille_tube(radius: f64, length: i64) -> TriangleSurface {
        let n = radius.ceil() as i64 + 1;
        let inside =
            |i: i64, j: i64, k: i64| (0..length).contains(&k) && (i as f64 + 0.5).hypot(j as f64 + 0.5) < radius;
        let mut index: HashMap<[i64; 3], u32> = HashMap::new();
        let mut vertices = Vec::new();
        let mut corner = |c: [i64; 3]| {
            *index.entry(c).or_insert_with(|| {
                vertices.push(Point3::new(c[0] as f64, c[1] as f64, c[2] as f64));
                (vertices.len() - 1) as u32
            })
        };
        let mut triangles = Vec::new();
        for i in -n..n {
            for j in -n..n {
                for k in 0..length {
                    if !inside(i, j, k) {
                        continue;
                    }
                    for axis in 0..3 {
                        for side in [0i64, 1] {
                            let mut next = [i, j, k];
                            next[axis] += 2 * side - 1;
                            if inside(next[0], next[1], next[2]) {
                                continue;
                            }
                            // The face's corners, counter-clockwise seen from outside.
                            let (u, w) = ((axis + 1) % 3, (axis + 2) % 3);
                            let mut base = [i, j, k];
                            base[axis] += side;
                            let at = |du: i64, dw: i64| {
                                let mut c = base;
                                c[u] += du;
                                c[w] += dw;
                                c
                            };
                            let mut quad = [at(0, 0), at(1, 0), at(1, 1), at(0, 1)].map(&mut corner);
                            if side == 0 {
                                quad.reverse();
                            }
                            triangles.push([quad[0], quad[1], quad[2]]);
                            triangles.push([quad[0], quad[2], quad[3]]);
                        }
                    }
                }
            }
        }
        surface(vertices, triangles)
    }

    /// A closed prism with `sides` faces around, flat caps fanned from their centres.
    fn prism(sides: usize, radius: f64, length: f64) -> TriangleSurface {
        let ring = |z: f64| {
            (0..sides).map(move |s| {
                let a = std::f64::consts::TAU * s as f64 / sides as f64;
                Point3::new(radius * a.cos(), radius * a.sin(), z)
            })
        };
        let mut vertices: Vec<Point3<f64>> = ring(0.0).chain(ring(length)).collect();
        vertices.extend([Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, length)]);
        let (m, bottom, top) = (sides as u32, 2 * sides as u32, 2 * sides as u32 + 1);
        let mut triangles = Vec::new();
        for s in 0..m {
            let t = (s + 1) % m;
            triangles.extend([[s, t, t + m], [s, t + m, s + m], [bottom, t, s], [top, s + m, t + m]]);
        }
        surface(vertices, triangles)
    }

    #[test]
    fn a_voxel_staircase_is_found_however_it_lies_and_a_coarse_prism_is_not() {
        let tube = cuberille_tube(6.3, 30);
        let steps = creases(&tube);
        assert!(
            steps.share >= STAIRCASE_CREASES && steps.concave >= STAIRCASE_CONCAVE,
            "{:.3} {:.3}",
            steps.share,
            steps.concave
        );
        assert!(steps.concave < 0.5, "a convex tube's steps: fewer concave than convex ({:.3})", steps.concave);
        assert!(is_staircase(&tube));
        // Turned off the axes, written in metres and moved by a tenth of a voxel at random: still one.
        let turn = Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::new(0.3, -0.7, 0.5)), 0.9);
        let mut seed = 12345u64;
        let mut jitter = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.2
        };
        let moved: Vec<Point3<f64>> =
            tube.vertices.iter().map(|p| (turn * p + Vector3::new(jitter(), jitter(), jitter())) * 1e-3).collect();
        assert!(is_staircase(&surface(moved, tube.triangles.clone())));
        // A ten-sided prism is creased along every edge around it (36 degrees), all convex.
        let coarse = prism(10, 5.0, 30.0);
        let facets = creases(&coarse);
        assert!(
            facets.share > 3.0 * STAIRCASE_CREASES && facets.concave == 0.0,
            "{:.3} {:.3}",
            facets.share,
            facets.concave
        );
        assert!(!is_staircase(&coarse));
        // Finely faceted (a hundred sides), it is creased only at its caps' rims.
        assert!(creases(&prism(100, 5.0, 30.0)).share < STAIRCASE_CREASES);
    }

    /// Taubin's smoothing takes a staircase's steps off without shrinking it: the creases all
    /// but gone, the tube's mean radius within a few percent.
    #[test]
    fn the_smoothed_staircase_keeps_its_size() {
        let mut tube = cuberille_tube(6.3, 30);
        let mean_radius = |s: &TriangleSurface| {
            let middle: Vec<f64> =
                s.vertices.iter().filter(|p| (8.0..22.0).contains(&p.z)).map(|p| p.x.hypot(p.y)).collect();
            middle.iter().sum::<f64>() / middle.len() as f64
        };
        let before = mean_radius(&tube);
        taubin(&mut tube);
        assert!(creases(&tube).share < 0.5 * STAIRCASE_CREASES);
        let after = mean_radius(&tube);
        assert!((after / before - 1.0).abs() < 0.05, "mean radius {before:.3} -> {after:.3}");
    }
}
