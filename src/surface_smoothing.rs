//! Smoothing of the lumen surface's quads in junction transitions, on the triangles.
//!
//! Why: a wall element grows from one lumen-surface quad, so its scaled Jacobian is about the
//! sine of the quad's worst corner times the cosine of the growth direction's tilt from the
//! quad's normal. On gmsh_aortic_arch at coarse the wall's mean was 0.864 = 0.903 (quads) x
//! 0.956 (tilt): two thirds of the shortfall were the quads of the junction transitions, whose
//! nodes are where the transitions' rays happen to hit the surface, crowded and sheared around
//! the crotch. Evening them out on the surface raises the wall's mean and the lumen's near-wall
//! cells with it (their outer faces are the same quads), so the first junction finish meets the
//! bars where a search over a dozen finishes used to be needed (see `pipeline::mesh_tree`).

use crate::surface::LumenSurface;
use nalgebra::{Point3, Vector3};

/// Gauss-Seidel passes of the smoothing. Measured on the cohort at coarse, from the bare surface:
/// with 15, every meshed case is within the bars with the first finish; with 30, the nodes
/// drift far enough from where the rays put them that gmsh_bifurcation falls below (min scaled
/// Jacobian 0.159, lumen skew 0.351); with 10 and the pages' rims held, the arches still need
/// the later finishes (wall mean 0.82-0.84).
pub const SMOOTHING_PASSES: usize = 15;
/// Share of the way to the neighbours' centroid a node moves in one pass.
const RELAXATION: f64 = 0.5;

/// A lumen ring node below a surface node, on its ray.
#[derive(Debug, Clone, Copy)]
pub struct RayNode {
    pub node: u32,
    /// The ray's origin, on the core's boundary.
    pub origin: Point3<f64>,
    /// The node's share of the way from the origin to the surface node.
    pub share: f64,
}

/// A lumen-surface node that the smoothing moves, with what moves along with it.
#[derive(Debug, Clone)]
pub struct SmoothedNode {
    pub node: u32,
    /// Its edge neighbours on the lumen surface's quads (moving or not).
    pub neighbours: Vec<u32>,
    /// The ring nodes on its ray: they stay at their shares of the re-aimed ray, so the
    /// lumen's thin near-wall cells are not sheared by the surface node's move.
    pub column: Vec<RayNode>,
}

/// Moves each node, in the order given, part of the way to the centroid of its surface
/// neighbours and back onto the triangles (Laplacian smoothing on the surface), carrying its
/// column along. The nodes not listed (the sections outside the transitions, the vessel
/// ends) hold the smoothed patch in place. Deterministic: one order, no threads.
pub fn smooth_on_surface(nodes: &mut [Point3<f64>], smoothed: &[SmoothedNode], surface: &LumenSurface) {
    for _ in 0..SMOOTHING_PASSES {
        for s in smoothed {
            if s.neighbours.is_empty() {
                continue;
            }
            let sum = s.neighbours.iter().fold(Vector3::zeros(), |acc, &j| acc + nodes[j as usize].coords);
            let centroid = Point3::from(sum / s.neighbours.len() as f64);
            let old = nodes[s.node as usize];
            let new = surface.closest(&(old + (centroid - old) * RELAXATION)).point;
            nodes[s.node as usize] = new;
            for r in &s.column {
                nodes[r.node as usize] = r.origin + (new - r.origin) * r.share;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rings of 16 nodes on a tube of radius 1 along z, one apart, each with a column node at
    /// half the radius under it, interleaved: surface node then column node.
    const AROUND: usize = 16;
    fn tube_grid(rings: usize) -> Vec<Point3<f64>> {
        let mut nodes = Vec::new();
        for j in 0..rings {
            for k in 0..AROUND {
                let a = std::f64::consts::TAU * k as f64 / AROUND as f64;
                nodes.push(Point3::new(a.cos(), a.sin(), j as f64));
                nodes.push(Point3::new(0.5 * a.cos(), 0.5 * a.sin(), j as f64));
            }
        }
        nodes
    }

    /// The surface node of ring j at k (any k, modulo the ring) and its column node.
    fn at(j: usize, k: usize) -> (u32, u32) {
        let i = 2 * (j * AROUND + k % AROUND);
        (i as u32, i as u32 + 1)
    }

    #[test]
    fn a_shifted_node_returns_between_its_neighbours_on_the_surface_and_its_column_follows() {
        let around = AROUND;
        let surface = LumenSurface::new(&crate::testing::straight_tube_surface(1.0, 4.0, 256, 8)).expect("a tube");
        let mut nodes = tube_grid(5);
        for p in nodes.iter_mut().step_by(2) {
            *p = surface.closest(p).point;
        }
        // The middle ring is smoothed; one of its nodes starts 0.4 of a spacing downstream.
        let (moved, _) = at(2, 3);
        let regular = nodes[moved as usize];
        nodes[moved as usize] = surface.closest(&(regular + Vector3::new(0.0, 0.0, 0.4))).point;
        let smoothed: Vec<SmoothedNode> = (0..around)
            .map(|k| {
                let (node, below) = at(2, k);
                let neighbours = vec![at(1, k).0, at(3, k).0, at(2, k + around - 1).0, at(2, k + 1).0];
                let column = vec![RayNode { node: below, origin: Point3::new(0.0, 0.0, 2.0), share: 0.5 }];
                SmoothedNode { node, neighbours, column }
            })
            .collect();
        smooth_on_surface(&mut nodes, &smoothed, &surface);
        let back = nodes[moved as usize];
        assert!((back.z - 2.0).abs() < 0.02, "the shifted node is back between its rings: z = {}", back.z);
        for s in &smoothed {
            let p = nodes[s.node as usize];
            assert!(surface.closest(&p).distance < 1e-9, "smoothed nodes stay on the triangles");
            let below = nodes[s.column[0].node as usize];
            let expected = Point3::new(0.0, 0.0, 2.0) + (p - Point3::new(0.0, 0.0, 2.0)) * 0.5;
            assert!((below - expected).norm() < 1e-12, "the column stays at its share of the ray");
        }
        // An undisturbed ring on the tube stays where it was (to the facets' sag).
        let (k0, _) = at(2, 8);
        assert!((nodes[k0 as usize] - Point3::new(-1.0, 0.0, 2.0)).norm() < 0.01);
    }
}
