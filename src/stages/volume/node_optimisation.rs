//! Moves free nodes of a hexahedral mesh to untangle and improve the elements around them, as
//! Mesquite-style local optimisers do: one smooth objective over the free nodes' elements,
//! minimised node by node (a Gauss-Seidel sweep of steepest-descent steps with backtracking),
//! each node kept where its kind of freedom allows (free, on the lumen surface, or across its
//! wall's growth direction).
//!
//! The objective is a penalty on the nine terms of Verdict's scaled Jacobian (eight corners
//! and the centroid, see [`crate::geometry::quality`]) and on the six face pyramids that OpenFOAM builds
//! ([`crate::geometry::quality::face_pyramids`]): every term below its target costs its shortfall
//! squared, and a negative corner ten times more. It is smooth (where edges do not vanish) and zero
//! on elements already past the target, so untangling comes first (an inverted corner costs
//! most) and then shape, every poor corner at once. A max-min objective, raised one node at a
//! time, stalls where two poor elements share nodes that each wants elsewhere.

use crate::geometry::mesh::{Hex, HEX_CORNER_NEIGHBOURS};
use crate::geometry::quality::Validity;
use crate::geometry::surface::LumenSurface;
use nalgebra::{Point3, Vector3};

/// Scaled-Jacobian terms below this are penalised: above the bar (0.2) with a margin, so that
/// the optimised elements clear it.
pub const TARGET: f64 = 0.3;
/// Weight of an inverted term's determinant (over the element's size cubed).
const INVERTED_WEIGHT: f64 = 10.0;
/// At most this many sweeps over the free nodes.
const MAX_SWEEPS: usize = 60;
/// The sweeps stop when the objective falls by less than this share over a sweep.
const STALLED_SHARE: f64 = 1e-3;
/// Largest step, as a share of the node's shortest edge.
const MAX_STEP: f64 = 0.25;
/// Finite-difference step of the face pyramids' share of the gradient, as a share of the node's
/// shortest edge.
const GRADIENT_STEP: f64 = 1e-5;
/// Face-pyramid ratios below this are penalised (a sixth of the volume is 1; over the cohort,
/// healthy cells reach a few hundredths where a wall layer tapers into a crotch).
pub const PYRAMID_TARGET: f64 = 0.03;
/// Face pyramids below this count as this in the penalty: as the cell's volume vanishes its
/// pyramids over it grow without bound (-10^4 in a crotch's wall), and would swamp every other
/// term; the corners' terms see such a cell anyway.
const LEAST_PYRAMID: f64 = -2.0;
/// Halvings of the step before a node is left where it is.
const BACKTRACKS: usize = 6;

/// How an optimised node may move.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Freedom {
    Fixed,
    /// Anywhere.
    Free,
    /// On the lumen surface: moved, then put back onto the nearest point of the triangles.
    OnSurface,
    /// Across a wall's growth direction (unit), so the wall keeps its thickness.
    Across(Vector3<f64>),
}

/// The penalty of one element (see the module's documentation): its corners' and, when
/// `validity` asks, its face pyramids'. `size` is a length of the element, fixed while it is
/// optimised (the centroid term's axes span twice the element, so they count a quarter).
pub fn element_penalty(c: &[Point3<f64>; 8], size: f64, validity: Validity) -> f64 {
    element_penalty_and_gradient(c, size, validity, 0, 0.0).0
}

/// [`element_penalty`] and its gradient with respect to the corners in `corners` (a bit per
/// corner: those where one node stands) moved together. The corners' terms are differentiated
/// exactly, those that do not move skipped; the pyramids' (a sum over faces through the cell's
/// centre) by forward differences of step `step`. A node's gradient costs about one evaluation
/// of its elements' penalties, where forward differences of the whole penalty cost three. With
/// no corner moved, the penalty alone (its gradient zero).
fn element_penalty_and_gradient(
    c: &[Point3<f64>; 8],
    size: f64,
    validity: Validity,
    corners: u8,
    step: f64,
) -> (f64, Vector3<f64>) {
    let volume = size * size * size;
    let moved = |k: usize| corners & (1 << k) != 0;
    let sum = |idx: [usize; 4]| idx.iter().fold(Vector3::zeros(), |acc, &i| acc + c[i].coords);
    let [(ap, am), (bp, bm), (dp, dm)] = CENTROID_AXES;
    let (mut total, axes) = term(sum(ap) - sum(am), sum(bp) - sum(bm), sum(dp) - sum(dm), volume * 64.0, corners != 0);
    let mut gradient = Vector3::zeros();
    for k in (0..8).filter(|&k| moved(k)) {
        for (g, (plus, _)) in axes.iter().zip(&CENTROID_AXES) {
            gradient += if plus.contains(&k) { *g } else { -*g };
        }
    }
    for (i, nb) in HEX_CORNER_NEIGHBOURS.iter().enumerate() {
        let wanted = moved(i) || nb.iter().any(|&j| moved(j));
        let (value, edges) = term(c[nb[0]] - c[i], c[nb[1]] - c[i], c[nb[2]] - c[i], volume, wanted);
        total += value;
        if moved(i) {
            gradient -= edges[0] + edges[1] + edges[2];
        }
        for (g, &j) in edges.iter().zip(nb) {
            if moved(j) {
                gradient += g;
            }
        }
    }
    if validity == Validity::CornersAndPyramids {
        let p0 = pyramid_penalty(c);
        total += p0;
        for axis in (0..3).filter(|_| corners != 0) {
            let mut shifted = *c;
            for (k, p) in shifted.iter_mut().enumerate() {
                if moved(k) {
                    p[axis] += step;
                }
            }
            gradient[axis] += (pyramid_penalty(&shifted) - p0) / step;
        }
    }
    (total, gradient)
}

/// The corners on the positive and on the negative side of each of the centroid term's three
/// axes.
const CENTROID_AXES: [([usize; 4], [usize; 4]); 3] =
    [([1, 2, 5, 6], [0, 3, 4, 7]), ([2, 3, 6, 7], [0, 1, 4, 5]), ([4, 5, 6, 7], [0, 1, 2, 3])];

/// A scaled-Jacobian term on axes `a`, `b`, `d` as [`element_penalty`] counts it (its shortfall
/// below [`TARGET`] squared, plus [`INVERTED_WEIGHT`] times its negative determinant over
/// `volume`) and, when `with_gradient`, its gradient with respect to the three axes (else zero).
#[inline]
fn term(
    a: Vector3<f64>,
    b: Vector3<f64>,
    d: Vector3<f64>,
    volume: f64,
    with_gradient: bool,
) -> (f64, [Vector3<f64>; 3]) {
    let (na, nb, nd) = (a.norm(), b.norm(), d.norm());
    let l = na * nb * nd;
    let axb = a.cross(&b);
    let det = axb.dot(&d);
    let sigma = if l <= f64::MIN_POSITIVE { 0.0 } else { det / l };
    let short = (TARGET - sigma).max(0.0);
    let value = short * short + INVERTED_WEIGHT * (-det / volume).max(0.0);
    let mut gradient = [Vector3::zeros(); 3];
    if !with_gradient || (short == 0.0 && det >= 0.0) {
        return (value, gradient);
    }
    // d det / d(a, b, d) = (b x d, d x a, a x b); a degenerate corner (an edge of no length)
    // has no gradient of its ratio.
    let ddet = [b.cross(&d), d.cross(&a), axb];
    if short > 0.0 && l > f64::MIN_POSITIVE {
        let k = -2.0 * short;
        for (g, (dd, (e, ne))) in gradient.iter_mut().zip(ddet.iter().zip([(a, na), (b, nb), (d, nd)])) {
            *g += (dd / l - e * (sigma / (ne * ne))) * k;
        }
    }
    if det < 0.0 {
        for (g, dd) in gradient.iter_mut().zip(&ddet) {
            *g -= dd * (INVERTED_WEIGHT / volume);
        }
    }
    (value, gradient)
}

/// The face pyramids' share of [`element_penalty`]: each pyramid ratio
/// ([`crate::geometry::quality::face_pyramids`]) below [`PYRAMID_TARGET`] costs its shortfall, scaled so
/// that a flat pyramid costs as much as a flat corner, squared. Without it the corners' terms,
/// blind to an element's thickness, flatten a poor element until its centre leaves a face's
/// plane (gmsh_bifurcation at medium: a lumen cell at the wall went from a scaled Jacobian of
/// 0.05 to 0.30 and from 16-91 um thick to 0.3-43 um, with a pyramid of -1.02). The margin over
/// OpenFOAM's zero keeps the max-min search that follows, which refuses only a pyramid that is
/// not positive, away from it.
fn pyramid_penalty(c: &[Point3<f64>; 8]) -> f64 {
    // A cell without positive volume costs the most on every face, so that turning its volume
    // positive never costs (its corners' terms untangle it).
    let pyramids = crate::geometry::quality::face_pyramids_of_positive_volume(c).unwrap_or([LEAST_PYRAMID; 6]);
    pyramids
        .iter()
        .map(|r| {
            let short = TARGET * (1.0 - r.max(LEAST_PYRAMID) / PYRAMID_TARGET).max(0.0);
            short * short
        })
        .sum()
}

/// Minimises the summed penalty of `elements` (each by its `validity`'s terms) over the nodes whose
/// `freedom` is not [`Freedom::Fixed`] (nodes beyond `freedom`'s length are fixed). Sequential,
/// in node order, so the result does not depend on the thread count.
pub fn optimise_nodes(
    nodes: &mut [Point3<f64>],
    elements: &[Hex],
    freedom: &[Freedom],
    surface: &LumenSurface,
    validity: &[Validity],
) {
    let is_free = |n: u32| freedom.get(n as usize).is_some_and(|f| *f != Freedom::Fixed);
    let mut incident: Vec<Vec<u32>> = vec![Vec::new(); freedom.len()];
    for (e, h) in elements.iter().enumerate() {
        for &n in h {
            if is_free(n) && incident[n as usize].last() != Some(&(e as u32)) {
                incident[n as usize].push(e as u32);
            }
        }
    }
    let free: Vec<u32> = (0..freedom.len() as u32).filter(|&n| !incident[n as usize].is_empty()).collect();
    if free.is_empty() {
        return;
    }
    // Each element's size: its mean edge length as it was.
    let mut size = vec![0.0; elements.len()];
    for &n in &free {
        for &e in &incident[n as usize] {
            if size[e as usize] == 0.0 {
                let h = &elements[e as usize];
                size[e as usize] = crate::geometry::mesh::HEX_EDGES
                    .iter()
                    .map(|&[a, b]| (nodes[h[a] as usize] - nodes[h[b] as usize]).norm())
                    .sum::<f64>()
                    / 12.0;
            }
        }
    }
    let measure = |nodes: &[Point3<f64>], e: u32| {
        element_penalty(&elements[e as usize].map(|m| nodes[m as usize]), size[e as usize], validity[e as usize])
    };
    // The objective around node `n`, each element's penalty put in `values` (in the order of
    // `incident`).
    let local = |nodes: &[Point3<f64>], n: u32, values: &mut Vec<f64>| -> f64 {
        values.clear();
        incident[n as usize]
            .iter()
            .map(|&e| {
                let value = measure(nodes, e);
                values.push(value);
                value
            })
            .sum()
    };
    // Each element's penalty, known until one of its corners moves (NaN: to be measured): a
    // node's objective at the start of its visit is mostly of elements unchanged since they
    // were last measured, and summed in the same order the same values give the same sum.
    let mut penalty = vec![f64::NAN; elements.len()];
    let mut values = Vec::new();
    // The objective around node `n` and its gradient there (`step`: the pyramids' difference).
    // The objective's gradient around node `n` (`step`: the pyramids' difference), from each
    // element's penalty (`penalty`, measured where the nodes stand). An element judged by its
    // corners alone with no penalty has every term past its target and none inverted, so each
    // term's gradient is zero (as `term` returns it): it adds a zero without being measured.
    let gradient_at = |nodes: &[Point3<f64>], n: u32, step: f64, penalty: &[f64]| -> Vector3<f64> {
        incident[n as usize].iter().fold(Vector3::zeros(), |g, &e| {
            if penalty[e as usize] == 0.0 && validity[e as usize] == Validity::Corners {
                return g + Vector3::zeros();
            }
            let h = &elements[e as usize];
            let corners = (0..8).filter(|&k| h[k] == n).fold(0u8, |mask, k| mask | (1 << k));
            let (_, ge) = element_penalty_and_gradient(
                &h.map(|m| nodes[m as usize]),
                size[e as usize],
                validity[e as usize],
                corners,
                step,
            );
            g + ge
        })
    };
    // The shortest edge at each free node, from the start (the step's scale).
    let scale: Vec<f64> = free.iter().map(|&n| shortest_edge(nodes, elements, &incident[n as usize], n)).collect();
    // Each node's first trial step, carried from its last descent (see [`descend`]).
    let mut first_step: Vec<f64> = scale.iter().map(|h| MAX_STEP * h).collect();
    // A node is visited while it or a node of its elements moved in the sweep before (at first,
    // every node): otherwise its objective and gradient are the same as when it last stayed.
    let mut active = vec![false; freedom.len()];
    for &n in &free {
        active[n as usize] = true;
    }
    for _ in 0..MAX_SWEEPS {
        let (mut before, mut after) = (0.0, 0.0);
        let mut next = vec![false; freedom.len()];
        for ((&n, &h), first_step) in free.iter().zip(&scale).zip(&mut first_step) {
            if !active[n as usize] {
                continue;
            }
            // The gradient only where the node has something to gain (most of a sweep's nodes
            // stand among elements already past the target).
            let f0: f64 = incident[n as usize]
                .iter()
                .map(|&e| {
                    let known = &mut penalty[e as usize];
                    if known.is_nan() {
                        *known = measure(nodes, e);
                    }
                    *known
                })
                .sum();
            before += f0;
            let f = if f0 > 0.0 && h > 0.0 {
                let gradient = gradient_at(nodes, n, GRADIENT_STEP * h, &penalty);
                let start = Start { f0, gradient, h, first_step };
                descend(nodes, n, start, freedom[n as usize], &mut |nodes, n| local(nodes, n, &mut values), surface)
            } else {
                f0
            };
            after += f;
            if f < f0 {
                // The node moved: its elements as measured where it stands now.
                for (&e, &value) in incident[n as usize].iter().zip(&values) {
                    penalty[e as usize] = value;
                }
                for &e in &incident[n as usize] {
                    for &m in &elements[e as usize] {
                        if is_free(m) {
                            next[m as usize] = true;
                        }
                    }
                }
            }
        }
        active = next;
        if before == 0.0 || before - after <= STALLED_SHARE * before {
            break;
        }
    }
}

/// Where a node's descent starts: its objective `f0` and the objective's gradient there, its
/// scale `h` (its shortest edge at the start) and the length of its first trial step, which the
/// descent updates.
struct Start<'a> {
    f0: f64,
    gradient: Vector3<f64>,
    h: f64,
    first_step: &'a mut f64,
}

/// One steepest-descent step of node `n`, backtracking until the objective falls; the
/// objective after it (`f0` when the node stays). The first trial is twice the node's last
/// accepted step (at most [`MAX_STEP`] of its scale), or where its last failed search ended:
/// starting from a quarter edge each time, a node near its optimum halved it four or five
/// times on every visit (gmsh_aortic_arch_cm at medium: 4.3 failed trials per step, and 9.2
/// evaluations of the node's elements with the gradient's differences).
fn descend(
    nodes: &mut [Point3<f64>],
    n: u32,
    start: Start,
    freedom: Freedom,
    local: &mut impl FnMut(&[Point3<f64>], u32) -> f64,
    surface: &LumenSurface,
) -> f64 {
    let Start { f0, gradient, h, first_step } = start;
    let old = nodes[n as usize];
    let direction = match freedom {
        Freedom::Across(g) => -(gradient - g * gradient.dot(&g)),
        _ => -gradient,
    };
    let norm = direction.norm();
    if norm.is_nan() || norm <= 0.0 {
        return f0;
    }
    let mut length = *first_step;
    for _ in 0..=BACKTRACKS {
        let p = old + direction * (length / norm);
        nodes[n as usize] = match freedom {
            Freedom::OnSurface => surface.closest_near(&p, &old).point,
            _ => p,
        };
        let f = local(nodes, n);
        if f < f0 {
            *first_step = (2.0 * length).min(MAX_STEP * h);
            return f;
        }
        length *= 0.5;
    }
    *first_step = length;
    nodes[n as usize] = old;
    f0
}

/// The shortest edge of the given elements that meets node `n`.
fn shortest_edge(nodes: &[Point3<f64>], elements: &[Hex], incident: &[u32], n: u32) -> f64 {
    let mut shortest = f64::INFINITY;
    for &e in incident {
        let h = &elements[e as usize];
        if let Some(c) = h.iter().position(|&m| m == n) {
            for &nb in &HEX_CORNER_NEIGHBOURS[c] {
                shortest = shortest.min((nodes[h[nb] as usize] - nodes[n as usize]).norm());
            }
        }
    }
    if shortest.is_finite() {
        shortest
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::quality::scaled_jacobian;

    /// A surface the tests' nodes never slide on.
    fn surface() -> LumenSurface {
        LumenSurface::new(&crate::testing::straight_tube_surface(1.0, 1.0, 8, 2)).expect("a tube")
    }

    fn unit_cube(offset: Vector3<f64>) -> [Point3<f64>; 8] {
        [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
        ]
        .map(|p| Point3::from(Vector3::from(p) + offset))
    }

    #[test]
    fn a_cube_costs_nothing_and_an_inverted_corner_costs_most() {
        let cube = unit_cube(Vector3::zeros());
        assert_eq!(element_penalty(&cube, 1.0, Validity::CornersAndPyramids), 0.0);
        let mut folded = cube;
        folded[6] = Point3::new(0.2, 0.2, 0.2);
        assert!(scaled_jacobian(&folded) < 0.0);
        let mut sheared = cube;
        sheared[6] = Point3::new(1.6, 1.6, 1.0);
        assert!(scaled_jacobian(&sheared) > 0.0);
        let penalty = |c| element_penalty(c, 1.0, Validity::Corners);
        assert!(penalty(&folded) > penalty(&sheared));
    }

    /// The gradient matches central differences of the penalty, term by term: on corners that
    /// are poor, inverted, degenerate (two corners on one node) or fine, with and without the
    /// pyramids.
    #[test]
    fn the_penalty_gradient_matches_finite_differences() {
        let cube = unit_cube(Vector3::zeros());
        let mut sheared = cube;
        sheared[6] = Point3::new(1.7, 1.5, 0.6);
        sheared[1] = Point3::new(0.8, -0.3, 0.2);
        let mut inverted = cube;
        inverted[6] = Point3::new(0.1, 0.2, 0.15);
        let mut collapsed = sheared;
        collapsed[7] = collapsed[6];
        let slab = crate::geometry::quality::tests::warped_slab(0.1, [0.03, 0.001, 0.001, 0.001]);
        for (name, c) in
            [("cube", cube), ("sheared", sheared), ("inverted", inverted), ("collapsed", collapsed), ("slab", slab)]
        {
            for validity in [Validity::Corners, Validity::CornersAndPyramids] {
                for corners in [1u8 << 6, 1 << 1, 1 << 0, (1 << 6) | (1 << 7)] {
                    // Two corners on one node move together, or an edge of no length grows.
                    if name == "collapsed" && (corners >> 6).count_ones() == 1 {
                        continue;
                    }
                    let (value, gradient) = element_penalty_and_gradient(&c, 1.0, validity, corners, 1e-7);
                    assert_eq!(value, element_penalty(&c, 1.0, validity), "{name}");
                    let h = 1e-6;
                    for axis in 0..3 {
                        let shifted = |sign: f64| {
                            let mut m = c;
                            for (k, p) in m.iter_mut().enumerate() {
                                if corners & (1 << k) != 0 {
                                    p[axis] += sign * h;
                                }
                            }
                            element_penalty(&m, 1.0, validity)
                        };
                        let numeric = (shifted(1.0) - shifted(-1.0)) / (2.0 * h);
                        // The corners' share is exact; the pyramids' is a forward difference.
                        let share = if validity == Validity::Corners { 1e-5 } else { 1e-3 };
                        let tolerance = share * (1.0 + numeric.abs());
                        assert!(
                            (gradient[axis] - numeric).abs() <= tolerance,
                            "{name} {validity:?} corners {corners:b} axis {axis}: {} against {numeric}",
                            gradient[axis]
                        );
                    }
                }
            }
        }
    }

    /// Two cubes side by side share a face; its four nodes are pushed through the far cube's
    /// opposite face, inverting both. Free, the shared nodes go back between the two.
    #[test]
    fn free_nodes_untangle_two_inverted_cubes() {
        let a = unit_cube(Vector3::zeros());
        let b = unit_cube(Vector3::x());
        // Nodes 0..8 of a, and b's x = 2 face as nodes 8..12; b shares a's x = 1 face.
        let mut nodes: Vec<Point3<f64>> = a.to_vec();
        nodes.extend([b[1], b[2], b[5], b[6]]);
        let hexes: Vec<Hex> = vec![[0, 1, 2, 3, 4, 5, 6, 7], [1, 8, 9, 2, 5, 10, 11, 6]];
        for n in [1usize, 2, 5, 6] {
            nodes[n].x = 2.6;
        }
        let corners = |nodes: &[Point3<f64>], h: &Hex| h.map(|n| nodes[n as usize]);
        assert!(hexes.iter().any(|h| scaled_jacobian(&corners(&nodes, h)) < 0.0));
        let mut freedom = vec![Freedom::Fixed; nodes.len()];
        for n in [1usize, 2, 5, 6] {
            freedom[n] = Freedom::Free;
        }
        let surface = surface();
        optimise_nodes(&mut nodes, &hexes, &freedom, &surface, &[Validity::Corners; 2]);
        for h in &hexes {
            assert!(scaled_jacobian(&corners(&nodes, h)) > TARGET, "{:?}", corners(&nodes, h));
        }
    }

    /// A cell thinner than the warp of its faces (every scaled-Jacobian term above the target,
    /// a face pyramid negative) is put right when its outer corners are free: the pyramids are
    /// part of the objective.
    #[test]
    fn free_nodes_lift_a_negative_face_pyramid() {
        let slab = crate::geometry::quality::tests::warped_slab(0.1, [0.03, 0.001, 0.001, 0.001]);
        assert!(scaled_jacobian(&slab) > TARGET && crate::geometry::quality::face_pyramid_ratio(&slab) < 0.0);
        let mut nodes = slab.to_vec();
        let hexes: Vec<Hex> = vec![[0, 1, 2, 3, 4, 5, 6, 7]];
        let mut freedom = vec![Freedom::Fixed; 8];
        freedom[4..].fill(Freedom::Free);
        optimise_nodes(&mut nodes, &hexes, &freedom, &surface(), &[Validity::CornersAndPyramids]);
        let c = hexes[0].map(|n| nodes[n as usize]);
        let pyramids = crate::geometry::quality::face_pyramids(&c);
        assert!(crate::geometry::quality::validity(&c) > 0.2 && pyramids.iter().all(|&r| r > 0.05), "{pyramids:?}");
    }

    /// A node that may only move across a direction keeps its place along it.
    #[test]
    fn a_node_moving_across_a_direction_keeps_its_height() {
        let mut nodes = unit_cube(Vector3::zeros()).to_vec();
        nodes[6] = Point3::new(2.2, -0.2, 1.0);
        let hexes: Vec<Hex> = vec![[0, 1, 2, 3, 4, 5, 6, 7]];
        let mut freedom = vec![Freedom::Fixed; 8];
        freedom[6] = Freedom::Across(Vector3::z());
        let surface = surface();
        let before = scaled_jacobian(&hexes[0].map(|n| nodes[n as usize]));
        assert!(before < TARGET, "{before}");
        optimise_nodes(&mut nodes, &hexes, &freedom, &surface, &[Validity::Corners]);
        assert_eq!(nodes[6].z, 1.0);
        let after = scaled_jacobian(&hexes[0].map(|n| nodes[n as usize]));
        assert!(after > before, "{before} -> {after} at {:?}", nodes[6]);
    }
}
