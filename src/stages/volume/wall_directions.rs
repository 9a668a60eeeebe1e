//! The directions the wall grows along from the lumen surface: the surface's normals, smoothed
//! over a length set by the wall's thickness rather than by the mesh's spacing.
//!
//! Why the length matters: an outer wall node sits a thickness `t` along its direction, so two
//! neighbours whose directions differ by an angle `a` shear the element between them by about
//! `t a / h`, `h` being their spacing. The facets of a segmented surface turn the normal by a few
//! degrees at every facet edge. Smoothed over a fixed number of neighbours, that turn is spread
//! over a few spacings, and the shear grows as the axial step shrinks: C0092 at 0.03 mm per
//! station (3 M hexes) had a wall mean scaled Jacobian of 0.950 against 0.995 at 0.11 mm, and
//! 60,831 wall elements below the bar at 0.0087 mm (10 M). Smoothed over a share of the
//! thickness, the shear is bounded whatever the spacing.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use std::collections::HashMap;

/// The lumen surface's quad mesh as a graph: its nodes (sorted ids) and, by position in that
/// list, each node's edge neighbours (sorted, each once).
pub(crate) struct SurfaceGraph {
    pub nodes: Vec<u32>,
    /// Position in `nodes` of every mesh node, `usize::MAX` off the surface.
    pub position: Vec<usize>,
    pub neighbours: Vec<Vec<usize>>,
}

impl SurfaceGraph {
    pub fn new(quads: &[[u32; 4]], node_count: usize) -> Self {
        let mut nodes: Vec<u32> = quads.iter().flatten().copied().collect();
        nodes.sort_unstable();
        nodes.dedup();
        let mut position = vec![usize::MAX; node_count];
        for (i, &s) in nodes.iter().enumerate() {
            position[s as usize] = i;
        }
        let mut neighbours: Vec<Vec<usize>> = vec![Vec::new(); nodes.len()];
        for q in quads {
            for c in 0..4 {
                let nb = &mut neighbours[position[q[c] as usize]];
                nb.push(position[q[(c + 1) % 4] as usize]);
                nb.push(position[q[(c + 3) % 4] as usize]);
            }
        }
        for nb in &mut neighbours {
            nb.sort_unstable();
            nb.dedup();
        }
        SurfaceGraph { nodes, position, neighbours }
    }
}

/// Passes of neighbour averaging of the wall directions: enough to calm the voxel ripples of
/// segmented surfaces, few enough to keep the shape.
const NORMAL_SMOOTHING_PASSES: usize = 3;
/// Further passes over the nodes of junction transitions (`JunctionWall::SmoothedNormal`).
pub(crate) const JUNCTION_SMOOTHING_PASSES: usize = 30;
/// Length over which the directions are smoothed at the least (the spread of the smoothing along
/// each surface direction), as a share of the wall thickness. C0092 at 3 M and 10 M hexes, the
/// adventitia's minimum / mean scaled Jacobian and the intima's mean:
///
/// | reach | 3 M | 10 M | intima mean |
/// |---|---|---|---|
/// | 0.35 | 0.465 / 0.9927 | 0.400 / 0.9925 | 0.9971 |
/// | 0.5 | 0.564 / 0.9937 | 0.404 / 0.9936 | 0.9970 |
/// | 0.7 | 0.609 / 0.9944 | 0.442 / 0.9943 | 0.9966 |
/// | 1.0 | 0.729 / 0.9947 | 0.545 / 0.9946 | 0.9958 |
///
/// Three passes at 0.8 M gave 0.493 / 0.9916. Past a half the outer layer gains what the inner
/// loses: the directions leave the normal where the section is not round.
const SMOOTHING_REACH: f64 = 0.5;

/// The wall's growth direction at every surface node (by position in `graph`): the outward
/// normal of the quads around it, averaged over its neighbours [`NORMAL_SMOOTHING_PASSES`] times,
/// diffused further where those passes fall short of [`SMOOTHING_REACH`] (see
/// [`heat_smoothing`]), averaged more in junction transitions where asked
/// (`junction_passes`), and in the end planes at vessel ends (`end_tangent`). `thickness` is the
/// wall's at each node.
#[allow(clippy::too_many_arguments)]
pub(crate) fn surface_normals(
    nodes: &[Point3<f64>],
    quads: &[[u32; 4]],
    graph: &SurfaceGraph,
    rays: &[Vector3<f64>],
    end_tangent: &HashMap<u32, Vector3<f64>>,
    junction_node: &[bool],
    junction_passes: usize,
    thickness: &[f64],
) -> Vec<Vector3<f64>> {
    let mut normal = vec![Vector3::zeros(); graph.nodes.len()];
    for q in quads {
        let p = q.map(|i| nodes[i as usize]);
        // circumferential x axial = outward
        let a = (p[1] - p[0]) + (p[2] - p[3]);
        let b = (p[3] - p[0]) + (p[2] - p[1]);
        let v = a.cross(&b);
        for c in 0..4 {
            normal[graph.position[q[c] as usize]] += v;
        }
    }
    for (v, &s) in normal.iter_mut().zip(&graph.nodes) {
        *v = unit(*v, rays[s as usize]);
    }
    // One pass of neighbour averaging over the nodes listed.
    let smooth = |normal: &mut Vec<Vector3<f64>>, selected: &[usize]| {
        let averaged: Vec<Vector3<f64>> = selected
            .iter()
            .map(|&i| {
                let nb = &graph.neighbours[i];
                let mut sum = normal[i] * own_weight(nb.len());
                for &j in nb {
                    sum += normal[j];
                }
                unit(sum, normal[i])
            })
            .collect();
        for (&i, v) in selected.iter().zip(averaged) {
            normal[i] = v;
        }
    };
    let all: Vec<usize> = (0..graph.nodes.len()).collect();
    for _ in 0..NORMAL_SMOOTHING_PASSES {
        smooth(&mut normal, &all);
    }
    let into_end_plane = |normal: &mut [Vector3<f64>], id: u32, t: &Vector3<f64>| {
        let i = graph.position[id as usize];
        let v = normal[i];
        normal[i] = unit(v - t * v.dot(t), rays[id as usize]);
    };
    let reach: Vec<f64> = thickness.iter().map(|t| SMOOTHING_REACH * t).collect();
    if passes_fall_short(nodes, graph, &reach) {
        let mut end = vec![false; graph.nodes.len()];
        for (&id, t) in end_tangent {
            into_end_plane(&mut normal, id, t);
            end[graph.position[id as usize]] = true;
        }
        normal = heat_smoothing(nodes, graph, &normal, &reach, &end);
        for (v, &s) in normal.iter_mut().zip(&graph.nodes) {
            *v = unit(*v, rays[s as usize]);
        }
    }
    // Across a flow divider the normal turns fast; grown along it unsmoothed, the outer wall
    // layers shear. Junction nodes get more passes where asked.
    let in_junction: Vec<usize> = all.iter().copied().filter(|&i| junction_node[graph.nodes[i] as usize]).collect();
    for _ in 0..junction_passes {
        smooth(&mut normal, &in_junction);
    }
    for (&id, t) in end_tangent {
        into_end_plane(&mut normal, id, t);
    }
    normal
}

/// A node's own weight in an averaging pass, its neighbours' being one each: two, and one more
/// for each neighbour it lacks of four (a vessel end's ring), so a pass moves a direction as far
/// everywhere.
fn own_weight(neighbours: usize) -> f64 {
    2.0 + 4usize.saturating_sub(neighbours) as f64
}

fn unit(v: Vector3<f64>, fallback: Vector3<f64>) -> Vector3<f64> {
    if v.norm() > 0.0 {
        v.normalize()
    } else {
        fallback
    }
}

/// Whether the averaging passes spread a direction over less than `reach` at the median node,
/// along its shortest spacing. A pass moves a share 1 / (own weight + neighbours) of a direction
/// to each neighbour, so along a line of spacing `h` [`NORMAL_SMOOTHING_PASSES`] passes spread it
/// over a variance of passes x 2 h^2 / 6: `h^2` for three passes on an even grid.
fn passes_fall_short(nodes: &[Point3<f64>], graph: &SurfaceGraph, reach: &[f64]) -> bool {
    let mut shortfall: Vec<f64> = graph
        .nodes
        .par_iter()
        .zip(&graph.neighbours)
        .zip(reach)
        .filter_map(|((&s, nb), reach)| {
            let p = nodes[s as usize];
            let shortest_squared =
                nb.iter().map(|&j| (nodes[graph.nodes[j] as usize] - p).norm_squared()).fold(f64::INFINITY, f64::min);
            let weights = own_weight(nb.len()) + nb.len() as f64;
            let variance = NORMAL_SMOOTHING_PASSES as f64 * 2.0 * shortest_squared / weights;
            (shortest_squared.is_finite() && shortest_squared > 0.0).then(|| reach * reach / variance)
        })
        .collect();
    if shortfall.is_empty() {
        return false;
    }
    let middle = shortfall.len() / 2;
    let (_, median, _) = shortfall.select_nth_unstable_by(middle, f64::total_cmp);
    *median > 1.0
}

/// The surface's Laplacian by inverse squared distances, in compressed rows: on an even grid of
/// either spacing a row is the continuous Laplacian's difference quotient, so diffusion spreads
/// as far along the axis as around it whatever the two spacings.
struct Laplacian {
    row_start: Vec<usize>,
    column: Vec<u32>,
    weight: Vec<f64>,
    /// Sum of each row's weights.
    diagonal: Vec<f64>,
}

impl Laplacian {
    fn new(nodes: &[Point3<f64>], graph: &SurfaceGraph) -> Self {
        let mut row_start = Vec::with_capacity(graph.nodes.len() + 1);
        let (mut column, mut weight) = (Vec::new(), Vec::new());
        let mut diagonal = Vec::with_capacity(graph.nodes.len());
        row_start.push(0);
        for (&s, nb) in graph.nodes.iter().zip(&graph.neighbours) {
            let p = nodes[s as usize];
            let mut sum = 0.0;
            for &j in nb {
                let d2 = (nodes[graph.nodes[j] as usize] - p).norm_squared();
                if d2 > 0.0 {
                    column.push(j as u32);
                    weight.push(1.0 / d2);
                    sum += 1.0 / d2;
                }
            }
            diagonal.push(sum);
            row_start.push(column.len());
        }
        Laplacian { row_start, column, weight, diagonal }
    }

    /// Row `i` of `L x`.
    fn row(&self, x: &[Vector3<f64>], i: usize) -> Vector3<f64> {
        let (a, b) = (self.row_start[i], self.row_start[i + 1]);
        let off = (a..b).fold(Vector3::zeros(), |sum, k| sum + x[self.column[k] as usize] * self.weight[k]);
        x[i] * self.diagonal[i] - off
    }
}

/// The directions diffused as by the heat equation `dn/dt = -D L n` for a time `t` at which the
/// spread along each surface direction is `reach` at every node (`D` scales the time node by
/// node, `reach^2 = 2 t D`): a Gaussian of that spread on an even grid, the averaging passes'
/// limit. The passes would need `(reach / spacing)^2` sweeps (C0092 at 10 M hexes: 970, 3.1 s);
/// the heat operator `exp(-t D L)` is applied as its Chebyshev series over the spectrum of
/// `D L` (bounded by Gershgorin's circles), whose terms fall off past about `7 sqrt(a)`,
/// `a = t lambda_max / 2`: a number of sweeps that grows as reach / spacing (at 10 M, 252 sweeps
/// in 0.67 s; conjugate gradients on the implicit step took 551 iterations and 2.7 s, and its
/// cusped kernel needed a longer reach for the same wall). The nodes in
/// `fixed` (the vessel ends' directions, in their planes) keep theirs, so the directions next to
/// an end turn into its plane over the reach. The result is not normalised.
fn heat_smoothing(
    nodes: &[Point3<f64>],
    graph: &SurfaceGraph,
    normal: &[Vector3<f64>],
    reach: &[f64],
    fixed: &[bool],
) -> Vec<Vector3<f64>> {
    let laplacian = Laplacian::new(nodes, graph);
    let n = normal.len();
    // The time is set by the largest reach; D scales it down elsewhere.
    let widest = reach.iter().copied().fold(0.0, f64::max);
    let time = 0.5 * widest * widest;
    let scale: Vec<f64> =
        (0..n).map(|i| if fixed[i] || widest <= 0.0 { 0.0 } else { (reach[i] / widest).powi(2) }).collect();
    let lambda_max = (0..n).map(|i| scale[i] * 2.0 * laplacian.diagonal[i]).fold(0.0, f64::max);
    if lambda_max <= 0.0 || time <= 0.0 {
        return normal.to_vec();
    }
    let coefficients = heat_chebyshev_coefficients(0.5 * time * lambda_max);
    // y = (2 / lambda_max) D L - I maps the spectrum onto [-1, 1].
    let y = |x: &[Vector3<f64>], i: usize| laplacian.row(x, i) * (2.0 * scale[i] / lambda_max) - x[i];
    let mut previous = normal.to_vec();
    let mut current: Vec<Vector3<f64>> = (0..n).into_par_iter().map(|i| y(normal, i)).collect();
    let mut result: Vec<Vector3<f64>> = (0..n)
        .into_par_iter()
        .map(|i| normal[i] * coefficients[0] + current[i] * coefficients.get(1).copied().unwrap_or(0.0))
        .collect();
    for &c in coefficients.iter().skip(2) {
        // T_{k+1} = 2 y T_k - T_{k-1}, written over T_{k-1}, and added to the sum.
        previous.par_iter_mut().zip(result.par_iter_mut()).enumerate().for_each(|(i, (previous, result))| {
            *previous = y(&current, i) * 2.0 - *previous;
            *result += *previous * c;
        });
        std::mem::swap(&mut previous, &mut current);
    }
    result
}

/// Coefficients `c_k` of `exp(-a (y + 1)) = sum c_k T_k(y)` on [-1, 1]: `e^-a I_0(a)`, then
/// `2 (-1)^k e^-a I_k(a)`, the modified Bessel functions by Miller's downward recurrence
/// normalised by `I_0 + 2 sum I_k = e^a`; cut where the terms fall below 1e-12.
fn heat_chebyshev_coefficients(a: f64) -> Vec<f64> {
    let top = (a + 12.0 * a.sqrt() + 40.0).ceil() as usize;
    let mut bessel = vec![0.0; top + 2];
    bessel[top] = 1e-300;
    for k in (1..=top).rev() {
        bessel[k - 1] = 2.0 * k as f64 / a * bessel[k] + bessel[k + 1];
        if bessel[k - 1] > 1e250 {
            bessel.iter_mut().for_each(|b| *b *= 1e-250);
        }
    }
    let total = bessel[0] + 2.0 * bessel[1..].iter().sum::<f64>();
    let mut coefficients = vec![bessel[0] / total];
    for (k, b) in bessel.iter().enumerate().skip(1) {
        let c = 2.0 * b / total;
        if c < 1e-12 && k as f64 > a.sqrt() {
            break;
        }
        coefficients.push(if k % 2 == 1 { -c } else { c });
    }
    coefficients
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cylinder of radius `r` with `around` nodes per ring and `stations` rings `step` apart,
    /// its quads circumferential x axial outward, its radius a zigzag of amplitude `ripple` and
    /// period 0.4 along the axis (the facets of a segmented surface, whose edges turn the normal
    /// at a point whatever the mesh's step).
    fn rippled_tube(
        r: f64,
        around: usize,
        stations: usize,
        step: f64,
        ripple: f64,
    ) -> (Vec<Point3<f64>>, Vec<[u32; 4]>) {
        let mut nodes = Vec::new();
        for i in 0..stations {
            let phase = (i as f64 * step / 0.4).fract();
            let radius = r + ripple * (1.0 - 4.0 * (phase - 0.5).abs());
            for k in 0..around {
                let phi = std::f64::consts::TAU * k as f64 / around as f64;
                nodes.push(Point3::new(radius * phi.cos(), radius * phi.sin(), i as f64 * step));
            }
        }
        let id = |i: usize, k: usize| (i * around + k % around) as u32;
        let quads = (0..stations - 1)
            .flat_map(|i| (0..around).map(move |k| [id(i, k), id(i, k + 1), id(i + 1, k + 1), id(i + 1, k)]))
            .collect();
        (nodes, quads)
    }

    /// The largest angle between the directions of axial neighbours away from the ends.
    fn axial_turn(normal: &[Vector3<f64>], graph: &SurfaceGraph, around: usize, stations: usize) -> f64 {
        let at = |i: usize, k: usize| graph.position[i * around + k];
        (2..stations - 3)
            .flat_map(|i| (0..around).map(move |k| (i, k)))
            .map(|(i, k)| normal[at(i, k)].angle(&normal[at(i + 1, k)]))
            .fold(0.0, f64::max)
    }

    fn normals(step: f64, stations: usize, thickness: f64, ripple: f64) -> (Vec<Vector3<f64>>, SurfaceGraph) {
        let (around, r) = (40, 1.0);
        let (nodes, quads) = rippled_tube(r, around, stations, step, ripple);
        let graph = SurfaceGraph::new(&quads, nodes.len());
        let rays: Vec<Vector3<f64>> = nodes.iter().map(|p| Vector3::new(p.x, p.y, 0.0).normalize()).collect();
        let t = vec![thickness; graph.nodes.len()];
        let n = surface_normals(&nodes, &quads, &graph, &rays, &HashMap::new(), &vec![false; nodes.len()], 0, &t);
        (n, graph)
    }

    #[test]
    fn the_wall_shear_from_a_ripple_does_not_grow_as_the_axial_step_shrinks() {
        // The shear of a wall element between axial neighbours is thickness x turn / step.
        let thickness = 0.2;
        let shear = |step: f64, stations: usize| {
            let (n, graph) = normals(step, stations, thickness, 0.004);
            thickness * axial_turn(&n, &graph, 40, stations) / step
        };
        // Three passes at every step (before): 0.52 at 0.01, 2.08 at 0.0025.
        let (fine, finer) = (shear(0.01, 400), shear(0.0025, 1600));
        assert!(finer < 1.2 * fine, "shear at a quarter of the step: {finer:.4} against {fine:.4}");
    }

    #[test]
    fn only_a_step_short_against_the_wall_is_smoothed_further() {
        let short = |step: f64| {
            let (nodes, quads) = rippled_tube(1.0, 40, 10, step, 0.0);
            let graph = SurfaceGraph::new(&quads, nodes.len());
            passes_fall_short(&nodes, &graph, &vec![0.1; graph.nodes.len()])
        };
        // Three passes spread a direction over the shortest spacing (0.157 around, the step
        // along); the reach is 0.1.
        assert!(!short(0.16));
        assert!(!short(0.11));
        assert!(short(0.09));
        assert!(short(0.016));
    }

    #[test]
    fn the_heat_series_sums_to_the_exponential_across_the_spectrum() {
        for a in [0.3, 4.0, 60.0, 900.0] {
            let c = heat_chebyshev_coefficients(a);
            for y in [-1.0f64, -0.9, -0.3, 0.0, 0.5, 1.0] {
                // T_k(cos u) = cos(k u)
                let u = y.acos();
                let sum: f64 = c.iter().enumerate().map(|(k, c)| c * (k as f64 * u).cos()).sum();
                let exact = (-a * (y + 1.0)).exp();
                assert!((sum - exact).abs() < 1e-9, "a {a}, y {y}: {sum} against {exact}");
            }
            assert!(c.len() < 12 + (8.0 * a.sqrt()) as usize, "a {a}: {} terms", c.len());
        }
    }

    #[test]
    fn a_cylinders_directions_stay_radial() {
        let (n, graph) = normals(0.01, 60, 0.2, 0.0);
        for (i, v) in n.iter().enumerate() {
            let k = graph.nodes[i] as usize % 40;
            let phi = std::f64::consts::TAU * k as f64 / 40.0;
            assert!(v.angle(&Vector3::new(phi.cos(), phi.sin(), 0.0)) < 1e-3, "node {i}: {v:?}");
        }
    }
}
