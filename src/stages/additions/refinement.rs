//! Refinement of a finished mesh, before or after projection (De Santis et al. 2011, §2.4 and
//! Appendix A.2): every hexahedron is split k-fold in each of its three directions.
//!
//! The split is conformal by construction: a new node on a coarse edge or face is made once,
//! keyed by that edge or face (its corner nodes), at the trilinear (there: linear or bilinear)
//! place every element around it agrees on; node and element labels of the coarse mesh are
//! kept for its nodes (new nodes follow), each coarse element's k^3 children take its place in
//! the element order, with its region, branch and local axes. A new node is in a node set when
//! every corner of the coarse edge or face it lies on is; a child face is in a face set when its
//! coarse face is.
//!
//! Then the new lumen-surface nodes are put on the vessel's surface, one of two ways:
//! * **before projection**: each is cast onto the input triangles along the line from its
//!   column's core-boundary node through its place on the coarse mesh (the paper's rays from the
//!   refined inner blocks): every lumen-surface node of the refined mesh is projected, and the
//!   mesh follows the triangles, their facets included;
//! * **after projection**: each lies on a smooth surface through the coarse mesh's (projected)
//!   lumen-surface nodes: every coarse surface edge becomes a cubic Hermite curve whose end
//!   tangents are the chord turned into the tangent plane at each end (the plane normal to the
//!   coarse surface's averaged normal there; in the end plane at a vessel end), and every coarse
//!   surface face a Coons patch of its four curves. Only the coarse nodes are projected; the
//!   smooth shape is kept (a circle of 16 nodes: the Hermite midpoint is 0.01903 r from the
//!   chord, the arc's sagitta 0.01921 r).
//!
//! After projection keeps the coarse mesh's shape, not the triangles' details: where the input
//! is finer than the coarse mesh the new nodes leave it (measured, k = 2 at the coarse preset:
//! the curved fixture 13.7 um at most; the vmtk aorto-iliac 0.48 mm at most, at the junction's
//! crotch, where the coarse surface folds; every quality bar held). Refine before projection
//! where the triangles are to be followed.
//!
//! Either way a surface node's move carries its column along: the lumen nodes below it in
//! proportion to their distance from the core boundary (so they stay on the straight ray from the
//! core boundary to the new surface node), the wall nodes above it in full (the wall keeps its
//! interpolated thickness and direction).

use crate::data::error::{Error, Result};
use crate::geometry::mesh::{sets, ElementFace, Hex, Region, VesselMesh};
use crate::geometry::surface::LumenSurface;
use indexmap::IndexMap;
use nalgebra::{Point3, Vector3};
use serde::Serialize;
use std::collections::HashMap;

/// How the new lumen-surface nodes are placed.
#[derive(Clone, Copy)]
pub enum Placement<'a> {
    /// Cast onto these triangles.
    BeforeProjection(&'a LumenSurface),
    /// On the smooth surface through the coarse surface nodes.
    AfterProjection,
}

/// What the refinement did, for report.json.
#[derive(Debug, Clone, Serialize)]
pub struct RefinementReport {
    pub before_projection: usize,
    pub after_projection: usize,
    /// Elements before and after.
    pub coarse_elements: usize,
    pub elements: usize,
    /// Lumen-surface nodes of the refined mesh, and how many of them were projected onto the
    /// input triangles (the rest lie on the smooth surface through those).
    pub surface_nodes: usize,
    pub projected_points: usize,
}

/// Where a new node lies on the coarse mesh.
#[derive(Debug, Clone, Copy)]
enum OnCoarse {
    /// On the edge `ends` (lower label first), `m` k-ths of the way from `ends[0]`.
    Edge { ends: [u32; 2], m: u16 },
    /// On a face: its corners in a canonical cycle (the lowest label first, then its lower
    /// neighbour), at (s, t) k-ths along corners[0]->corners[1] and corners[0]->corners[3].
    Face { corners: [u32; 4], s: u16, t: u16 },
    /// Inside an element.
    Cell,
}

/// The unit-cube corner of canonical hex node `i` (see [`crate::geometry::mesh::unit_cube`]).
fn corner_of(i: usize) -> [usize; 3] {
    let (x, y) = [(0, 0), (1, 0), (1, 1), (0, 1)][i % 4];
    [x, y, i / 4]
}

/// The canonical hex node at unit-cube corner (x, y, z).
fn node_at(c: [usize; 3]) -> usize {
    let xy = match (c[0], c[1]) {
        (0, 0) => 0,
        (1, 0) => 1,
        (1, 1) => 2,
        _ => 3,
    };
    xy + 4 * c[2]
}

/// The new nodes of a split, each made once: keyed by the coarse edge or face it lies on.
struct NewNodes {
    k: usize,
    nodes: Vec<Point3<f64>>,
    on_coarse: Vec<OnCoarse>,
    edges: HashMap<(u32, u32, u16), u32>,
    faces: HashMap<([u32; 3], u16, u16), u32>,
}

/// The trilinear place of lattice point `p` (k-ths along each axis) in an element.
fn lattice_place(corners: &[Point3<f64>; 8], p: [usize; 3], k: usize) -> Point3<f64> {
    let x = p.map(|x| x as f64 / k as f64);
    let weight = |i: usize| {
        let c = corner_of(i);
        (0..3).map(|a| if c[a] == 1 { x[a] } else { 1.0 - x[a] }).product::<f64>()
    };
    Point3::from((0..8).fold(Vector3::zeros(), |acc, i| acc + corners[i].coords * weight(i)))
}

impl NewNodes {
    fn push(&mut self, place: Point3<f64>, at: OnCoarse) -> u32 {
        self.nodes.push(place);
        self.on_coarse.push(at);
        self.nodes.len() as u32 - 1
    }

    /// The node at lattice point `p` of element `hex` (corners `corners`), made if new.
    fn at(&mut self, hex: &Hex, corners: &[Point3<f64>; 8], p: [usize; 3]) -> u32 {
        let k = self.k;
        let unit = |p: [usize; 3]| hex[node_at(p.map(|x| x / k))];
        let inner: Vec<usize> = (0..3).filter(|&a| p[a] != 0 && p[a] != k).collect();
        match inner.as_slice() {
            [] => unit(p),
            [a] => {
                let (mut lo, mut hi) = (p, p);
                (lo[*a], hi[*a]) = (0, k);
                let (na, nb) = (unit(lo), unit(hi));
                let (ends, m) = if na < nb { ([na, nb], p[*a]) } else { ([nb, na], k - p[*a]) };
                let key = (ends[0], ends[1], m as u16);
                match self.edges.get(&key) {
                    Some(&id) => id,
                    None => {
                        let id = self.push(lattice_place(corners, p, k), OnCoarse::Edge { ends, m: m as u16 });
                        *self.edges.entry(key).or_insert(id)
                    }
                }
            }
            [a, b] => self.face_node(hex, corners, p, (*a, *b)),
            _ => self.push(lattice_place(corners, p, k), OnCoarse::Cell),
        }
    }

    /// The node at lattice point `p` inside the face spanned by axes `a` and `b`: keyed by the
    /// face's corners in a canonical cycle (lowest label first, then its lower neighbour).
    fn face_node(&mut self, hex: &Hex, corners: &[Point3<f64>; 8], p: [usize; 3], (a, b): (usize, usize)) -> u32 {
        let k = self.k;
        let cycle: [[usize; 3]; 4] = [(0, 0), (k, 0), (k, k), (0, k)].map(|(x, y)| {
            let mut c = p;
            (c[a], c[b]) = (x, y);
            c
        });
        let labels = cycle.map(|c| hex[node_at(c.map(|x| x / k))]);
        let first = (0..4).min_by_key(|&i| labels[i]).expect("four corners");
        let step = if labels[(first + 1) % 4] < labels[(first + 3) % 4] { 1 } else { 3 };
        let order = [0, 1, 2, 3].map(|j| (first + j * step) % 4);
        let face = order.map(|i| labels[i]);
        let along = |to: usize| -> u16 {
            let (o, t) = (cycle[order[0]], cycle[order[to]]);
            ((0..3).map(|d| (p[d] as i64 - o[d] as i64) * (t[d] as i64 - o[d] as i64)).sum::<i64>() / k as i64) as u16
        };
        let (s, t) = (along(1), along(3));
        let key = ([face[0], face[1], face[3]], s, t);
        match self.faces.get(&key) {
            Some(&id) => id,
            None => {
                let id = self.push(lattice_place(corners, p, k), OnCoarse::Face { corners: face, s, t });
                *self.faces.entry(key).or_insert(id)
            }
        }
    }
}

/// The mesh split `k`-fold per direction, new nodes where the coarse mesh puts them, and where
/// each new node lies on the coarse mesh (by new node, from the coarse node count on).
fn split(mesh: &VesselMesh, k: usize) -> (VesselMesh, Vec<OnCoarse>) {
    let n = k + 1;
    let mut new =
        NewNodes { k, nodes: mesh.nodes.clone(), on_coarse: Vec::new(), edges: HashMap::new(), faces: HashMap::new() };
    let mut hexes: Vec<Hex> = Vec::with_capacity(mesh.hexes.len() * k * k * k);
    let mut lattice = vec![0u32; n * n * n];
    for (e, hex) in mesh.hexes.iter().enumerate() {
        let corners = mesh.corners(e);
        for (index, id) in lattice.iter_mut().enumerate() {
            *id = new.at(hex, &corners, [index % n, (index / n) % n, index / (n * n)]);
        }
        for child in 0..k * k * k {
            let (x, y, z) = (child % k, (child / k) % k, child / (k * k));
            hexes.push(std::array::from_fn(|i| {
                let c = corner_of(i);
                lattice[(x + c[0]) + (y + c[1]) * n + (z + c[2]) * n * n]
            }));
        }
    }
    let cubes = k * k * k;
    let refined = VesselMesh {
        nodes: new.nodes,
        hexes,
        regions: mesh.regions.iter().flat_map(|r| std::iter::repeat_n(*r, cubes)).collect(),
        branch_of: mesh.branch_of.iter().flat_map(|b| std::iter::repeat_n(*b, cubes)).collect(),
        sac: mesh.sac.iter().flat_map(|s| std::iter::repeat_n(*s, cubes)).collect(),
        triads: Vec::new(),
        fibres: Vec::new(),
        quality: Vec::new(),
        layers: mesh
            .layers
            .iter()
            .map(|l| crate::geometry::mesh::WallLayer { radial_elements: l.radial_elements * k, ..l.clone() })
            .collect(),
        ends: mesh.ends.clone(),
        node_sets: refined_node_sets(mesh, &new.on_coarse),
        face_sets: refined_face_sets(mesh, k),
        branch_names: mesh.branch_names.clone(),
    };
    (refined, new.on_coarse)
}

/// Node sets of the split mesh: a new node belongs to a set when every corner of the coarse edge
/// or face it lies on does.
fn refined_node_sets(mesh: &VesselMesh, on_coarse: &[OnCoarse]) -> IndexMap<String, Vec<u32>> {
    let first_new = mesh.nodes.len() as u32;
    mesh.node_sets
        .iter()
        .map(|(name, set)| {
            let mut member = vec![false; mesh.nodes.len()];
            set.iter().for_each(|&n| member[n as usize] = true);
            let mut refined = set.clone();
            refined.extend(on_coarse.iter().enumerate().filter_map(|(i, at)| {
                let inside = match at {
                    OnCoarse::Edge { ends, .. } => ends.iter().all(|&c| member[c as usize]),
                    OnCoarse::Face { corners, .. } => corners.iter().all(|&c| member[c as usize]),
                    OnCoarse::Cell => false,
                };
                inside.then_some(first_new + i as u32)
            }));
            (name.clone(), refined)
        })
        .collect()
}

/// Face sets of the split mesh: each coarse face's k^2 child faces.
fn refined_face_sets(mesh: &VesselMesh, k: usize) -> IndexMap<String, Vec<ElementFace>> {
    // Which child cell (x, y, z) touches each canonical face.
    let touches = |f: u8, x: usize, y: usize, z: usize| match f {
        0 => z == 0,
        1 => z == k - 1,
        2 => y == 0,
        3 => x == k - 1,
        4 => y == k - 1,
        _ => x == 0,
    };
    let cubes = k * k * k;
    mesh.face_sets
        .iter()
        .map(|(name, set)| {
            let mut refined: Vec<ElementFace> = set
                .iter()
                .flat_map(|f| {
                    (0..cubes)
                        .filter(move |&c| touches(f.face, c % k, (c / k) % k, c / (k * k)))
                        .map(move |c| ElementFace { element: (f.element as usize * cubes + c) as u32, face: f.face })
                })
                .collect();
            refined.sort_unstable();
            (name.clone(), refined)
        })
        .collect()
}

/// Outward unit normals of the coarse lumen surface at its nodes (sum of the adjacent faces'
/// area vectors); at a vessel end's ring, turned into the end plane.
fn surface_normals(mesh: &VesselMesh) -> HashMap<u32, Vector3<f64>> {
    let mut normals: HashMap<u32, Vector3<f64>> = HashMap::new();
    for f in &mesh.face_sets[sets::LUMEN_WALL_FACES] {
        let q = crate::geometry::mesh::face_nodes(&mesh.hexes[f.element as usize], f.face as usize);
        let a = crate::geometry::mesh::quad_area_vector(q.map(|n| mesh.nodes[n as usize]));
        for n in q {
            *normals.entry(n).or_insert_with(Vector3::zeros) += a;
        }
    }
    for end in &mesh.ends {
        let t = end.outward_normal.normalize();
        for n in mesh.node_sets.get(&sets::lumen_end(&end.name)).into_iter().flatten() {
            if let Some(v) = normals.get_mut(n) {
                *v -= t * v.dot(&t);
            }
        }
    }
    normals.values_mut().for_each(|v| *v = v.normalize());
    normals
}

/// The smooth surface through the coarse lumen-surface nodes (see the module documentation).
struct SmoothSurface<'a> {
    nodes: &'a [Point3<f64>],
    normals: HashMap<u32, Vector3<f64>>,
}

impl SmoothSurface<'_> {
    /// The Hermite curve of the edge a-b at `u` from a (the same curve from either end).
    fn edge(&self, a: u32, b: u32, u: f64) -> Point3<f64> {
        let (p0, p1) = (self.nodes[a as usize], self.nodes[b as usize]);
        let chord = p1 - p0;
        let tangent = |n: u32| -> Vector3<f64> {
            let normal = self.normals.get(&n).copied().unwrap_or_else(Vector3::zeros);
            let t = chord - normal * chord.dot(&normal);
            if t.norm() > 0.0 {
                t * (chord.norm() / t.norm())
            } else {
                chord
            }
        };
        crate::stages::junction::hermite(&p0, &tangent(a), &p1, &tangent(b), u)
    }

    /// The Coons patch of the face with corners c (a cycle) at (s, t).
    fn face(&self, c: [u32; 4], s: f64, t: f64) -> Point3<f64> {
        let p = c.map(|n| self.nodes[n as usize].coords);
        let ruled = self.edge(c[0], c[1], s).coords * (1.0 - t)
            + self.edge(c[3], c[2], s).coords * t
            + self.edge(c[0], c[3], t).coords * (1.0 - s)
            + self.edge(c[1], c[2], t).coords * s;
        let bilinear =
            p[0] * ((1.0 - s) * (1.0 - t)) + p[1] * (s * (1.0 - t)) + p[2] * (s * t) + p[3] * ((1.0 - s) * t);
        Point3::from(ruled - bilinear)
    }
}

/// The radial neighbours of the split mesh: towards the centerline through the lumen's ring
/// elements, and outwards through the wall's (canonical axis 0 -> 1 is radial in both).
fn radial_maps(mesh: &VesselMesh) -> (Vec<u32>, Vec<u32>) {
    let mut inward = vec![u32::MAX; mesh.nodes.len()];
    let mut outward = vec![u32::MAX; mesh.nodes.len()];
    for (h, region) in mesh.hexes.iter().zip(&mesh.regions) {
        for (inner, outer) in [(0, 1), (3, 2), (4, 5), (7, 6)] {
            match region {
                Region::Lumen => inward[h[outer] as usize] = h[inner],
                r if r.is_wall() => outward[h[inner] as usize] = h[outer],
                _ => {}
            }
        }
    }
    (inward, outward)
}

/// The column below lumen-surface node `s` of the split mesh: it and the `steps` lumen nodes
/// down to the core boundary, outside in.
fn column_below(mesh: &VesselMesh, inward: &[u32], s: u32, steps: usize) -> Result<Vec<u32>> {
    let mut column = vec![s];
    for _ in 0..steps {
        let next = inward[*column.last().expect("one node") as usize];
        if next == u32::MAX {
            let p = mesh.nodes[s as usize];
            return Err(Error::Geometry(format!(
                "refinement: the lumen-surface node at ({:.3}, {:.3}, {:.3}) mm has no ray of {steps} lumen elements \
                 below it",
                p.x, p.y, p.z
            )));
        }
        column.push(next);
    }
    Ok(column)
}

/// Where new lumen-surface node `p` goes: on the smooth surface through the coarse nodes at its
/// place on the coarse mesh, or where the ray from `origin` (its column's core-boundary node)
/// through it meets the triangles.
fn target(
    placement: Placement,
    smooth: &SmoothSurface,
    at: OnCoarse,
    k: usize,
    p: Point3<f64>,
    origin: Point3<f64>,
) -> Result<Point3<f64>> {
    let triangles = match placement {
        Placement::AfterProjection => {
            return Ok(match at {
                OnCoarse::Edge { ends, m } => smooth.edge(ends[0], ends[1], m as f64 / k as f64),
                OnCoarse::Face { corners, s, t } => smooth.face(corners, s as f64 / k as f64, t as f64 / k as f64),
                OnCoarse::Cell => p,
            })
        }
        Placement::BeforeProjection(triangles) => triangles,
    };
    let reach = (p - origin).norm();
    let hit = triangles.first_hit(&origin, &((p - origin) / reach), 3.0 * reach).ok_or_else(|| {
        let at = |q: Point3<f64>| format!("({:.3}, {:.3}, {:.3}) mm", q.x, q.y, q.z);
        Error::Geometry(format!(
            "refinement before projection: the ray from {} through the new lumen-surface node at {} meets the \
             surface {} nowhere within {:.3} mm",
            at(origin),
            at(p),
            triangles.source.display(),
            3.0 * reach
        ))
    })?;
    Ok(hit.point)
}

/// The moves a surface node's move `delta` carries along its column: the lumen nodes below in
/// proportion to their distance from the core boundary (so they stay on the straight ray to the
/// new surface node), the wall nodes above (`outward` from it) in full.
fn carried(
    mesh: &VesselMesh,
    column: &[u32],
    outward: &[u32],
    delta: Vector3<f64>,
    moves: &mut Vec<(u32, Vector3<f64>)>,
) {
    let lengths: Vec<f64> =
        column.windows(2).map(|w| (mesh.nodes[w[0] as usize] - mesh.nodes[w[1] as usize]).norm()).collect();
    let total: f64 = lengths.iter().sum();
    let mut below = total;
    for (j, &n) in column.iter().enumerate().skip(1).take(column.len() - 2) {
        below -= lengths[j - 1];
        moves.push((n, delta * (below / total)));
    }
    let mut n = outward[column[0] as usize];
    while n != u32::MAX {
        moves.push((n, delta));
        n = outward[n as usize];
    }
}

/// Splits every element `k`-fold per direction and places the new lumen-surface nodes as asked.
/// `radial_cells` is the number of lumen elements along a ray of `mesh` (`lumen.radial_elements`
/// for a mesh not refined before). The result is annotated.
pub fn refine(mesh: &VesselMesh, k: usize, placement: Placement, radial_cells: usize) -> Result<VesselMesh> {
    let first_new = mesh.nodes.len();
    let (mut refined, on_coarse) = split(mesh, k);
    let smooth = SmoothSurface { nodes: &mesh.nodes, normals: surface_normals(mesh) };
    let (inward, outward) = radial_maps(&refined);
    let surface: Vec<u32> =
        refined.node_sets[sets::INTERFACE_NODES].iter().copied().filter(|&n| n as usize >= first_new).collect();
    let mut moves: Vec<(u32, Vector3<f64>)> = Vec::with_capacity(surface.len());
    let mut targets: Vec<(u32, Point3<f64>)> = Vec::with_capacity(surface.len());
    for &s in &surface {
        let column = column_below(&refined, &inward, s, radial_cells * k)?;
        let p = refined.nodes[s as usize];
        let origin = refined.nodes[*column.last().expect("the core boundary") as usize];
        let goal = target(placement, &smooth, on_coarse[s as usize - first_new], k, p, origin)?;
        carried(&refined, &column, &outward, goal - p, &mut moves);
        targets.push((s, goal));
    }
    for (n, d) in moves {
        refined.nodes[n as usize] += d;
    }
    // The surface nodes are their targets (a hit on the triangles) bit for bit.
    for (n, p) in targets {
        refined.nodes[n as usize] = p;
    }
    crate::stages::annotation::annotate::annotate(&mut refined);
    Ok(refined)
}

/// Lumen-surface nodes of a mesh.
pub fn surface_nodes(mesh: &VesselMesh) -> usize {
    mesh.node_sets.get(sets::INTERFACE_NODES).map_or(0, Vec::len)
}
