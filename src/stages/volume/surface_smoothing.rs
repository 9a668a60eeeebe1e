//! Smoothing of the lumen surface's quads in junction transitions, on the triangles.
//!
//! Why: a wall element grows from one lumen-surface quad, so its scaled Jacobian is about the
//! sine of the quad's worst corner times the cosine of the growth direction's tilt from the
//! quad's normal. On gmsh_aortic_arch at coarse the wall's mean was 0.864 = 0.903 (quads) x
//! 0.956 (tilt): two thirds of the shortfall were the quads of the junction transitions, whose
//! nodes are where the transitions' rays happen to hit the surface, crowded and sheared around
//! the crotch. Evening them out on the surface raises the wall's mean and the lumen's near-wall
//! cells with it (their outer faces are the same quads), so the first junction finish meets the
//! bars where a search over a dozen finishes used to be needed (see `junction_finish::finish_junctions`).
//!
//! Evening out (Laplacian smoothing) spaces the nodes but leaves corners sheared where the
//! quads' valences are irregular (around the pages' rims), so a shape optimisation on the
//! triangles follows: the quads' corner sines and the near-wall lumen cells' skew
//! (`shape_objective`), the lumen's cells kept valid. The wall's mean at coarse:
//! gmsh_aortic_arch 0.870 -> 0.884, gmsh_aortic_arch_cm 0.857 -> 0.875,
//! palabos_cerebral_aneurysm 0.889 -> 0.898, sphinxsys_aortic_arch 0.832 -> 0.840.

use crate::geometry::mesh::Hex;
use crate::geometry::surface::LumenSurface;
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
    /// The lumen surface's quads it is a corner of.
    pub quads: Vec<[u32; 4]>,
    /// The lumen elements it and its column are corners of (indices into the lumen's).
    pub elements: Vec<u32>,
    /// The ring nodes on its ray: they stay at their shares of the re-aimed ray, so the
    /// lumen's thin near-wall cells are not sheared by the surface node's move.
    pub column: Vec<RayNode>,
}

/// Moves each node, in the order given, part of the way to the centroid of its surface
/// neighbours and back onto the triangles (Laplacian smoothing on the surface), carrying its
/// column along; then squares the quads' corners by steepest descent on `shape_objective`,
/// on the triangles, never taking a lumen element below its floor (`LUMEN_FLOOR`). The
/// nodes not listed (the sections outside the transitions, the vessel ends) hold the smoothed
/// patch in place. `lumen` holds the elements the nodes' `elements` index. Deterministic: one
/// order, no threads.
pub fn smooth_on_surface(nodes: &mut [Point3<f64>], smoothed: &[SmoothedNode], lumen: &[Hex], surface: &LumenSurface) {
    for _ in 0..SMOOTHING_PASSES {
        for s in smoothed {
            if s.neighbours.is_empty() {
                continue;
            }
            let sum = s.neighbours.iter().fold(Vector3::zeros(), |acc, &j| acc + nodes[j as usize].coords);
            let centroid = Point3::from(sum / s.neighbours.len() as f64);
            let old = nodes[s.node as usize];
            let new = surface.closest_near(&(old + (centroid - old) * RELAXATION), &old).point;
            place(nodes, s, new);
        }
    }
    let mut shaping = Shaping { lumen, scaled_jacobian: vec![f64::NAN; lumen.len()], surface };
    // Each node's first trial step (a share of its shortest edge), carried from its last step.
    let mut first_steps = vec![FIRST_STEP; smoothed.len()];
    for _ in 0..SHAPE_PASSES {
        let (mut before, mut after) = (0.0, 0.0);
        for (s, first_step) in smoothed.iter().zip(&mut first_steps) {
            // Measured again: a neighbour's move changed this node's quads and elements.
            let f0 = shape_objective(nodes, s, lumen);
            before += f0;
            after += shaping.step(nodes, s, f0, first_step);
        }
        if before - after <= SHAPE_STALLED_SHARE * before {
            break;
        }
    }
}

/// Passes of the shape optimisation after the smoothing: at most this many, and they stop when
/// a pass lowers the objective by less than [`SHAPE_STALLED_SHARE`] of it (the coronary tree at
/// medium: after 12 or 13 passes, 0.66 s for its 2,239 nodes; all twenty took 1.1 s, and the
/// cohort's bars did not gain from them: with 1e-3, palabos_cerebral_aneurysm at medium fell
/// to 0.189).
const SHAPE_PASSES: usize = 20;
const SHAPE_STALLED_SHARE: f64 = 3e-3;
/// Weight of the near-wall lumen elements' skew against the quads' corners in the shape
/// objective. The corners alone raise the wall's mean most but shear those elements, whose
/// inner rings stay: on sphinxsys_aortic_arch at coarse (wall mean 0.832, lumen skew 0.346
/// before), 0.848 and 0.360 with the corners alone, 0.836 and 0.343 with a weight of 1, 0.844
/// and 0.334 with 0.5 (measured with the whole column's skew), 0.840 and 0.349 as built.
const SKEW_WEIGHT: f64 = 0.5;
/// A move of the shape optimisation may not take a lumen element's scaled Jacobian below this,
/// or below where it stood if it was lower: the objective does not see the elements' validity
/// (palabos_cerebral_aneurysm at coarse, unguarded: a lumen cell of the sac's junction
/// inverted, and the vessel was refused).
const LUMEN_FLOOR: f64 = crate::stages::volume::node_optimisation::TARGET;
/// The shape optimisation's difference step, first trial step and largest step, as shares of
/// the node's shortest surface edge, and its halvings of the step before a node stays.
const GRADIENT_STEP: f64 = 1e-6;
const FIRST_STEP: f64 = 0.1;
const MAX_STEP: f64 = 0.25;
const BACKTRACKS: usize = 6;

/// Puts a smoothed node at `p` and its column on the re-aimed ray.
fn place(nodes: &mut [Point3<f64>], s: &SmoothedNode, p: Point3<f64>) {
    nodes[s.node as usize] = p;
    for r in &s.column {
        nodes[r.node as usize] = r.origin + (p - r.origin) * r.share;
    }
}

/// The sines of a quad's corners, signed about its normal (`mesh::quad_area_vector`): a wall
/// element grown from the quad has about its worst corner's sine as scaled Jacobian. A corner
/// with an edge of no length, or a quad with no area, counts as flat (0).
fn corner_sines(q: &[Point3<f64>; 4]) -> [f64; 4] {
    let normal = crate::geometry::mesh::quad_area_vector(*q);
    let n = normal.norm();
    if n <= f64::MIN_POSITIVE {
        return [0.0; 4];
    }
    let normal = normal / n;
    std::array::from_fn(|i| {
        let a = q[(i + 1) % 4] - q[i];
        let b = q[(i + 3) % 4] - q[i];
        let l = a.norm() * b.norm();
        if l <= f64::MIN_POSITIVE {
            0.0
        } else {
            a.cross(&b).dot(&normal) / l
        }
    })
}

/// The shortfall of a quad's corners from right angles: the sum over its corners of one minus
/// the corner's sine, squared.
fn corner_shortfall(q: &[Point3<f64>; 4]) -> f64 {
    corner_sines(q).iter().map(|sine| (1.0 - sine) * (1.0 - sine)).sum()
}

/// What the shape optimisation lowers around a smoothed node: its quads' corner shortfalls
/// and [`SKEW_WEIGHT`] times the squared equi-angle skews of the lumen elements it is a corner
/// of (the column's deeper elements shear as those do).
fn shape_objective(nodes: &[Point3<f64>], s: &SmoothedNode, lumen: &[Hex]) -> f64 {
    let quads: f64 = s.quads.iter().map(|q| corner_shortfall(&q.map(|n| nodes[n as usize]))).sum();
    let skew: f64 = s
        .elements
        .iter()
        .map(|&e| &lumen[e as usize])
        .filter(|h| h.contains(&s.node))
        .map(|h| crate::geometry::quality::equiangle_skew(&h.map(|n| nodes[n as usize])).powi(2))
        .sum();
    quads + SKEW_WEIGHT * skew
}

/// The shape optimisation's view of the lumen: its elements and the scaled Jacobian of each as
/// it stands (NaN until measured). Every element a move changes is one of the moved node's
/// `elements`, measured for the move, so the figures stay current without being measured
/// again.
struct Shaping<'a> {
    lumen: &'a [Hex],
    scaled_jacobian: Vec<f64>,
    surface: &'a LumenSurface,
}

impl Shaping<'_> {
    /// One steepest-descent step of a smoothed node on [`shape_objective`] (its column
    /// following; gradient by forward differences, the step put back onto the triangles),
    /// halving the step until the objective falls with no lumen element below its floor
    /// ([`LUMEN_FLOOR`]). The first trial is the node's `first_step`, which becomes twice the
    /// accepted one (at most [`MAX_STEP`]) or where a failed search ended. Returns the objective
    /// after the step (`f0` when the node stays).
    fn step(&mut self, nodes: &mut [Point3<f64>], s: &SmoothedNode, f0: f64, first_step: &mut f64) -> f64 {
        let old = nodes[s.node as usize];
        let h = s.neighbours.iter().map(|&j| (nodes[j as usize] - old).norm()).fold(f64::INFINITY, f64::min);
        if !h.is_finite() || h <= 0.0 || s.quads.is_empty() {
            return f0;
        }
        let lumen = self.lumen;
        let measure = |nodes: &[Point3<f64>], e: u32| {
            crate::geometry::quality::scaled_jacobian(&lumen[e as usize].map(|n| nodes[n as usize]))
        };
        let floor: Vec<f64> = s
            .elements
            .iter()
            .map(|&e| {
                let known = &mut self.scaled_jacobian[e as usize];
                if known.is_nan() {
                    *known = measure(nodes, e);
                }
                known.min(LUMEN_FLOOR)
            })
            .collect();
        let delta = GRADIENT_STEP * h;
        let mut gradient = Vector3::zeros();
        for axis in 0..3 {
            let mut p = old;
            p[axis] += delta;
            place(nodes, s, p);
            gradient[axis] = (shape_objective(nodes, s, lumen) - f0) / delta;
        }
        let norm = gradient.norm();
        let mut share = *first_step;
        let mut measured = vec![0.0; s.elements.len()];
        for _ in 0..(if norm > 0.0 { BACKTRACKS } else { 0 }) {
            place(nodes, s, self.surface.closest_near(&(old - gradient * (share * h / norm)), &old).point);
            let f = shape_objective(nodes, s, lumen);
            if f < f0
                && s.elements.iter().zip(&floor).zip(&mut measured).all(|((&e, least), q)| {
                    *q = measure(nodes, e);
                    *q >= *least
                })
            {
                for (&e, &q) in s.elements.iter().zip(&measured) {
                    self.scaled_jacobian[e as usize] = q;
                }
                *first_step = (2.0 * share).min(MAX_STEP);
                return f;
            }
            share *= 0.5;
        }
        *first_step = share;
        place(nodes, s, old);
        f0
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
                SmoothedNode { node, neighbours, quads: Vec::new(), elements: Vec::new(), column }
            })
            .collect();
        smooth_on_surface(&mut nodes, &smoothed, &[], &surface);
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

    /// The least corner sine of the quads around a node.
    fn least_sine(nodes: &[Point3<f64>], quads: &[[u32; 4]]) -> f64 {
        quads.iter().flat_map(|q| corner_sines(&q.map(|n| nodes[n as usize]))).fold(f64::INFINITY, f64::min)
    }

    /// A node pushed diagonally across its four quads (sheared to a corner sine below 0.85) is
    /// brought back to square corners by the shape steps alone, on the triangles, its column on
    /// its ray, its lumen elements never below their floor.
    #[test]
    fn the_shape_steps_square_a_sheared_node_s_quads() {
        let surface = LumenSurface::new(&crate::testing::straight_tube_surface(1.0, 4.0, 256, 8)).expect("a tube");
        let mut nodes = tube_grid(5);
        for p in nodes.iter_mut().step_by(2) {
            *p = surface.closest(p).point;
        }
        let (node, below) = at(2, 3);
        let spacing = (nodes[at(2, 4).0 as usize] - nodes[node as usize]).norm();
        let sheared =
            nodes[node as usize] + Vector3::new(0.0, 0.0, 0.3) + Vector3::new(-0.6, 0.8, 0.0) * (0.3 * spacing);
        nodes[node as usize] = surface.closest(&sheared).point;
        let origin = Point3::new(0.0, 0.0, 2.0);
        nodes[below as usize] = origin + (nodes[node as usize] - origin) * 0.5;
        let quads: Vec<[u32; 4]> = [(1, 2), (1, 3), (2, 2), (2, 3)]
            .iter()
            .map(|&(j, k)| [at(j, k).0, at(j, k + 1).0, at(j + 1, k + 1).0, at(j + 1, k).0])
            .collect();
        // Each quad's lumen element: the column nodes below it, then the quad, turned so that
        // the element is positive.
        let hexes: Vec<Hex> = quads
            .iter()
            .map(|q| {
                let low = q.map(|n| n + 1);
                let hex = [low[0], low[1], low[2], low[3], q[0], q[1], q[2], q[3]];
                let turned = [low[0], low[3], low[2], low[1], q[0], q[3], q[2], q[1]];
                let sj = |h: &Hex| crate::geometry::quality::scaled_jacobian(&h.map(|n| nodes[n as usize]));
                if sj(&hex) > 0.0 {
                    hex
                } else {
                    turned
                }
            })
            .collect();
        let floor: Vec<f64> = hexes
            .iter()
            .map(|h| crate::geometry::quality::scaled_jacobian(&h.map(|n| nodes[n as usize])).min(LUMEN_FLOOR))
            .collect();
        let neighbours = vec![at(1, 3).0, at(3, 3).0, at(2, 2).0, at(2, 4).0];
        let column = vec![RayNode { node: below, origin, share: 0.5 }];
        let elements = (0..hexes.len() as u32).collect();
        let s = SmoothedNode { node, neighbours, quads: quads.clone(), elements, column };
        let before = least_sine(&nodes, &quads);
        assert!(before < 0.85, "the quads start sheared: {before}");
        let mut shaping = Shaping { lumen: &hexes, scaled_jacobian: vec![f64::NAN; hexes.len()], surface: &surface };
        let mut first_step = FIRST_STEP;
        for _ in 0..60 {
            let f0 = shape_objective(&nodes, &s, &hexes);
            shaping.step(&mut nodes, &s, f0, &mut first_step);
        }
        let after = least_sine(&nodes, &quads);
        assert!(after > 0.97, "the quads end square: {before} -> {after}");
        let p = nodes[node as usize];
        assert!(surface.closest(&p).distance < 1e-9, "the node stays on the triangles");
        assert!((nodes[below as usize] - (origin + (p - origin) * 0.5)).norm() < 1e-12, "its column follows");
        for (h, least) in hexes.iter().zip(&floor) {
            assert!(crate::geometry::quality::scaled_jacobian(&h.map(|n| nodes[n as usize])) >= *least);
        }
    }
}
