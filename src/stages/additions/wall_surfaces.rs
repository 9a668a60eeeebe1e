//! Walls from segmented surfaces (De Santis et al. 2011, §2.5): when the outer wall is
//! segmented (CT, MRI), or each layer's surface is (intravascular ultrasound), the wall follows
//! it instead of a thickness rule.
//!
//! The wall vesselhex grows stands on the lumen-surface nodes, a straight column of nodes along
//! each node's growth direction (`wall.growth`: the smoothed normal, or the projection ray). Each
//! column's line is continued to the segmented surfaces: the outer wall's node is where the line
//! meets the outer surface, each layer boundary's where it meets that layer's surface (given),
//! or at its thickness fraction of the wall (not given); the nodes inside a layer keep their
//! share of it. The columns, and so the layers' topology, stay as they are: lumen and wall stay
//! conformal, and the wall's thickness varies as segmented.
//!
//! A line that meets a surface nowhere within [`REACH`] wall thicknesses, meets it from
//! outside (the lumen node lies outside that surface), meets the layers' surfaces in the wrong
//! order, or runs through the lumen before it reaches the outer surface (the crotch of a
//! junction, where the outer surface lies beyond the other branch) stops the run with a
//! message naming the place.

use crate::data::error::{Error, Result};
use crate::geometry::mesh::{sets, VesselMesh};
use crate::geometry::quality::Stats;
use crate::geometry::surface::LumenSurface;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use serde::Serialize;

/// How far a column's line is followed to its surfaces, in the grown wall's thicknesses.
pub const REACH: f64 = 20.0;

/// What the segmented surfaces did, for report.json (lengths in mm until converted).
#[derive(Debug, Clone, Serialize)]
pub struct WallSurfacesReport {
    /// The outer wall surface and the layer boundaries' (inside out), as given.
    pub outer: String,
    pub layers: Vec<String>,
    /// Wall columns placed (one per lumen-surface node).
    pub columns: usize,
    /// The wall's thickness along the columns, before (grown) and after (segmented).
    pub grown_thickness: Stats,
    pub thickness: Stats,
}

/// A segmented surface ready for queries, with the sense of its triangles.
pub struct WallSurface {
    pub surface: LumenSurface,
    /// +1 when the triangles face out of the region it encloses, -1 when they face in.
    orientation: f64,
}

impl WallSurface {
    /// Indexes `surface` and finds which way its triangles face from `inside`, a point of the
    /// lumen, which every wall surface must enclose.
    pub fn new(surface: LumenSurface, inside: &Point3<f64>) -> Result<WallSurface> {
        let w = surface.winding_number(inside);
        if w.abs() < 0.5 {
            return Err(Error::input(
                &surface.source,
                format!(
                    "this wall surface does not enclose the lumen: its winding number about the lumen point ({:.3}, \
                     {:.3}, {:.3}) mm is {w:.2} (about +-1 inside); check that it is the vessel's wall, in the units \
                     of the lumen surface",
                    inside.x, inside.y, inside.z
                ),
            ));
        }
        Ok(WallSurface { surface, orientation: w.signum() })
    }
}

/// The lumen-surface node of a column, its wall nodes from the inside out and its direction.
struct Column {
    base: u32,
    wall: Vec<u32>,
}

/// The wall columns of a mesh: above every lumen-surface node, the wall nodes along its
/// elements' radial edges (canonical axis 0 -> 1), inside out.
fn columns(mesh: &VesselMesh) -> Vec<Column> {
    let mut outward = vec![u32::MAX; mesh.nodes.len()];
    for (h, r) in mesh.hexes.iter().zip(&mesh.regions) {
        if r.is_wall() {
            for (inner, outer) in [(0, 1), (3, 2), (4, 5), (7, 6)] {
                outward[h[inner] as usize] = h[outer];
            }
        }
    }
    mesh.node_sets[sets::INTERFACE_NODES]
        .iter()
        .map(|&base| {
            let mut wall = Vec::new();
            let mut n = outward[base as usize];
            while n != u32::MAX {
                wall.push(n);
                n = outward[n as usize];
            }
            Column { base, wall }
        })
        .collect()
}

fn at(p: &Point3<f64>) -> String {
    format!("({:.3}, {:.3}, {:.3}) mm", p.x, p.y, p.z)
}

/// The surfaces a column meets, inside out, each with the wall level (nodes from the lumen,
/// the lumen-surface node being 0) that lands on it.
type Boundaries<'a> = Vec<(usize, &'a WallSurface)>;

/// Moves the wall's nodes onto the segmented surfaces: `layers` are the surfaces between the
/// layers, inside out (none, or one fewer than the mesh's layers), `outer` the outer wall's;
/// `lumen` is the lumen surface (a column's line must not run through it). Re-annotates the mesh.
pub fn place(
    mesh: &mut VesselMesh,
    lumen: &LumenSurface,
    layers: &[WallSurface],
    outer: &WallSurface,
) -> Result<WallSurfacesReport> {
    let boundaries = boundaries(mesh, layers, outer)?;
    let columns = columns(mesh);
    let nodes = &mesh.nodes;
    let placed: Vec<Result<Placed>> = columns.par_iter().map(|c| place_column(nodes, c, &boundaries, lumen)).collect();
    let (mut grown, mut thickness) = (Vec::with_capacity(columns.len()), Vec::with_capacity(columns.len()));
    for (c, result) in columns.iter().zip(placed) {
        let placed = result?;
        for (&n, p) in c.wall.iter().zip(placed.points) {
            mesh.nodes[n as usize] = p;
        }
        grown.push(placed.grown);
        thickness.push(placed.thickness);
    }
    crate::stages::annotation::annotate::annotate(mesh);
    check_not_inverted(mesh, outer)?;
    Ok(WallSurfacesReport {
        outer: outer.surface.source.display().to_string(),
        layers: layers.iter().map(|s| s.surface.source.display().to_string()).collect(),
        columns: columns.len(),
        grown_thickness: Stats::of(grown),
        thickness: Stats::of(thickness),
    })
}

/// Which wall level lands on which surface: each layer surface at the outer level of its layer,
/// the outer surface at the wall's outermost level.
fn boundaries<'a>(mesh: &VesselMesh, layers: &'a [WallSurface], outer: &'a WallSurface) -> Result<Boundaries<'a>> {
    let cells: Vec<usize> = mesh.layers.iter().map(|l| l.radial_elements).collect();
    if !layers.is_empty() && layers.len() + 1 != cells.len() {
        return Err(Error::Config(format!(
            "wall.surfaces: {} surfaces given for the {} boundaries between the {} layers",
            layers.len(),
            cells.len() - 1,
            cells.len()
        )));
    }
    let mut boundaries = Vec::new();
    let mut level = 0;
    for (l, surface) in layers.iter().enumerate() {
        level += cells[l];
        boundaries.push((level, surface));
    }
    boundaries.push((cells.iter().sum(), outer));
    Ok(boundaries)
}

/// A column's wall nodes on the segmented surfaces, and its wall thickness before and after.
struct Placed {
    points: Vec<Point3<f64>>,
    grown: f64,
    thickness: f64,
}

/// Places one column's wall nodes: the line from its lumen-surface node through its grown outer
/// node is continued to each surface; each node between two surfaces keeps its share of the
/// layer between them.
fn place_column(nodes: &[Point3<f64>], c: &Column, boundaries: &Boundaries, lumen: &LumenSurface) -> Result<Placed> {
    let base = nodes[c.base as usize];
    let total = boundaries[boundaries.len() - 1].0;
    if c.wall.len() != total {
        return Err(Error::Geometry(format!(
            "wall surfaces: the lumen-surface node at {} has {} wall nodes above it, not {total}",
            at(&base),
            c.wall.len()
        )));
    }
    let top = nodes[c.wall[total - 1] as usize];
    let grown = (top - base).norm();
    let dir = (top - base) / grown;
    // Distance of each wall node from the base, as grown.
    let depth: Vec<f64> = c.wall.iter().map(|&n| (nodes[n as usize] - base).dot(&dir)).collect();
    let hits =
        boundaries.iter().map(|(_, s)| hit(s, &base, &dir, grown)).collect::<Result<Vec<(f64, Point3<f64>)>>>()?;
    check_order(&hits, boundaries, &base)?;
    check_clear_of_lumen(lumen, &base, &dir, hits[hits.len() - 1].0, grown)?;
    let mut points = Vec::with_capacity(total);
    let (mut from_level, mut from_depth, mut from_new) = (0usize, 0.0, 0.0);
    for ((to_level, _), (to_new, point)) in boundaries.iter().zip(&hits) {
        let to_depth = depth[to_level - 1];
        for j in from_level + 1..*to_level {
            let share = (depth[j - 1] - from_depth) / (to_depth - from_depth);
            points.push(base + dir * (from_new + share * (to_new - from_new)));
        }
        points.push(*point);
        (from_level, from_depth, from_new) = (*to_level, to_depth, *to_new);
    }
    Ok(Placed { points, grown, thickness: hits[hits.len() - 1].0 })
}

/// No wall element may be inverted once the wall follows the surfaces.
fn check_not_inverted(mesh: &VesselMesh, outer: &WallSurface) -> Result<()> {
    let Some(e) = mesh.wall_range().find(|&e| {
        let sj = mesh.quality[e].scaled_jacobian;
        sj.is_nan() || sj <= 0.0 // NaN: a degenerate element
    }) else {
        return Ok(());
    };
    let c = crate::geometry::mesh::element_centre(&mesh.corners(e));
    Err(Error::Geometry(format!(
        "wall surfaces: wall element {} ({}) near {} is inverted (scaled Jacobian {:.3}) once the wall follows {}: \
         the segmented surfaces turn faster there than the lumen's columns can follow (try wall.growth = \
         \"ray\", or smooth the surfaces)",
        e + 1,
        mesh.regions[e].name(),
        at(&c),
        mesh.quality[e].scaled_jacobian,
        outer.surface.source.display()
    )))
}

/// Where the line from a lumen-surface node meets a wall surface, leaving it: distance and point.
fn hit(surface: &WallSurface, base: &Point3<f64>, dir: &Vector3<f64>, grown: f64) -> Result<(f64, Point3<f64>)> {
    let name = surface.surface.source.display();
    let found = surface.surface.first_hit(base, dir, REACH * grown).ok_or_else(|| {
        Error::input(
            &surface.surface.source,
            format!(
                "the wall's line from the lumen-surface node at {} (direction ({:.3}, {:.3}, {:.3})) meets this surface \
                 nowhere within {:.3} mm ({REACH} grown wall thicknesses): it does not enclose the lumen there (it \
                 ends short of the vessel's end, or has a hole)",
                at(base),
                dir.x,
                dir.y,
                dir.z,
                REACH * grown
            ),
        )
    })?;
    let leaving = surface.surface.normals[found.triangle as usize].dot(dir) * surface.orientation;
    if leaving <= 0.0 {
        return Err(Error::input(
            &surface.surface.source,
            format!(
                "the lumen-surface node at {} lies outside this surface: the wall's line from it enters {name} at {} \
                 instead of leaving it (the surface cuts into the lumen there)",
                at(base),
                at(&found.point)
            ),
        ));
    }
    Ok((found.distance, found.point))
}

/// The surfaces must be met inside out, each beyond the lumen.
fn check_order(hits: &[(f64, Point3<f64>)], boundaries: &Boundaries, base: &Point3<f64>) -> Result<()> {
    for i in 0..hits.len() {
        let before = if i == 0 { 0.0 } else { hits[i - 1].0 };
        if hits[i].0 <= before {
            let inner =
                if i == 0 { "the lumen".to_string() } else { boundaries[i - 1].1.surface.source.display().to_string() };
            return Err(Error::input(
                &boundaries[i].1.surface.source,
                format!(
                    "the layers' surfaces are out of order at the lumen-surface node {}: the wall's line meets this \
                     surface {:.4} mm out, not beyond {inner} ({before:.4} mm); list wall.surfaces inside out and check \
                     that the surfaces do not cross",
                    at(base),
                    hits[i].0
                ),
            ));
        }
    }
    Ok(())
}

/// The wall's line must not run through the lumen on its way to the outer surface.
fn check_clear_of_lumen(
    lumen: &LumenSurface,
    base: &Point3<f64>,
    dir: &Vector3<f64>,
    length: f64,
    grown: f64,
) -> Result<()> {
    let start = 1e-6 * grown;
    if let Some(h) = lumen.first_hit(&(base + dir * start), dir, length - start) {
        return Err(Error::Geometry(format!(
            "wall surfaces: the wall's line from the lumen-surface node at {} runs through the lumen again at {} \
             before it reaches the outer wall {length:.3} mm out: the outer surface lies beyond another part of \
             the vessel there (a junction's crotch), so the wall cannot follow it",
            at(base),
            at(&h.point)
        )));
    }
    Ok(())
}
