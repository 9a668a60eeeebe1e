//! Block topology at a junction: the "book of pages" of BRANCHING.md §1, built from the lumen
//! surface and the centerline tree, without manual input.
//!
//! A straight *spine* crosses the junction through its centre X along an axis `a` normal to the
//! (best-fit) plane of the branch directions. The k branches, ordered counter-clockwise about
//! `a`, are separated by k half-plane *pages* hanging on the spine; each page is shared by the
//! two branches on either side of it. The O-grid of every branch is swept from its last ordinary
//! cross-section to a *folded* end section: the half of its template left of the grid line
//! x = 0 is laid on one page, the right half on the other, and x = 0 on the spine. A page's
//! nodes are computed once and given to both branches, so the junction is conformal by
//! construction, and every hex of the junction belongs to exactly one branch.
//!
//! Choices, defended in the README:
//! * the axis maximises the smallest angular gap between the branch directions projected on the
//!   plane normal to it (start: the best-fit plane's normal);
//! * a page sits between its two branches at an angle split in proportion to their radii, so a
//!   small side branch gets a narrow wedge and the large vessel keeps its cells;
//! * the folded section is scaled by the distances from X to the wall along each page and along
//!   the spine, so rays on a page stay inside it and are star-shaped from the spine;
//! * each node of the transition follows a cubic Hermite curve from its place in the last
//!   ordinary section (leaving along the centerline) to its place on the page (arriving across
//!   the page), and the rays that find the lumen wall follow the same interpolation.

use crate::blocks::SectionTemplate;
use crate::centerline::{Branch, CenterlineSample, CenterlineTree, Frame};
use crate::error::{Error, Result};
use crate::surface::LumenSurface;
use nalgebra::{Matrix3, Point3, Vector2, Vector3};
use std::f64::consts::{PI, TAU};

/// Branches whose projected directions are closer than this about the spine cannot share a
/// junction (BRANCHING.md §4.1).
const MIN_ANGULAR_GAP_DEG: f64 = 25.0;
/// The spine's axis is chosen among those every branch leaves at least this far off, where
/// any is (see [`spine_axis`]).
const AXIS_CLEARANCE_DEG: f64 = 25.0;
/// Largest number of branches (parent included) at one junction.
const MAX_BRANCHES: usize = 5;

/// One branch as seen from a junction.
#[derive(Debug, Clone)]
pub struct JunctionSlot {
    pub branch: usize,
    /// The branch that ends at the junction (the others start there).
    pub is_parent: bool,
    /// Unit direction from the centre into the branch, projected normal to the axis.
    pub direction: Vector3<f64>,
    /// Angle of `direction` about the axis from the reference direction, radians in [0, 2 pi).
    pub angle: f64,
    /// Branch radius near the junction, mm.
    pub radius: f64,
}

/// A half-plane hanging on the spine.
#[derive(Debug, Clone)]
pub struct Page {
    /// Unit direction in the page, normal to the spine.
    pub dir: Vector3<f64>,
    pub angle: f64,
    /// Distance from the centre to the lumen wall along `dir`, mm (the page's length scale).
    pub depth: f64,
    /// Core cells across the page, from the spine to the rim.
    pub cells: usize,
}

/// The geometry of one junction.
#[derive(Debug, Clone)]
pub struct JunctionGeometry {
    pub index: usize,
    pub centre: Point3<f64>,
    pub radius: f64,
    /// Spine axis (unit).
    pub axis: Vector3<f64>,
    /// Angle origin about the axis (unit, normal to it): the parent's direction.
    pub reference: Vector3<f64>,
    /// Branches counter-clockwise about the axis.
    pub slots: Vec<JunctionSlot>,
    /// Page i lies between slot i and slot i + 1 (cyclically).
    pub pages: Vec<Page>,
    /// Distances from the centre to the wall along +axis and -axis, mm.
    pub spine_up: f64,
    pub spine_down: f64,
    /// Core cells along the spine.
    pub spine_cells: usize,
    /// Scale of the folds' core about the centre (1 unless [`keep_fold_cores_inside`] shrank it).
    pub core_scale: f64,
}

fn describe_point(p: &Point3<f64>) -> String {
    format!("({:.3}, {:.3}, {:.3}) mm", p.x, p.y, p.z)
}

impl JunctionGeometry {
    /// Where the junction is, for messages.
    pub fn describe(&self, tree: &CenterlineTree) -> String {
        let names: Vec<&str> = self.slots.iter().map(|s| tree.branches[s.branch].name.as_str()).collect();
        format!("the junction at {} (branches {})", describe_point(&self.centre), names.join(", "))
    }

    pub fn slot_of(&self, branch: usize) -> usize {
        self.slots.iter().position(|s| s.branch == branch).expect("branch belongs to the junction")
    }

    /// Pages on the +x and -x sides of a slot's template. The template's x axis is the frame
    /// normal = binormal x tangent = axis x tangent at the fold; a daughter's tangent leaves the
    /// centre, so +x is the counter-clockwise page; the parent's arrives, so +x is clockwise.
    pub fn side_pages(&self, slot: usize) -> (usize, usize) {
        let k = self.slots.len();
        let ccw = slot;
        let cw = (slot + k - 1) % k;
        if self.slots[slot].is_parent {
            (cw, ccw)
        } else {
            (ccw, cw)
        }
    }

    /// Unit bisector of a slot's wedge (between its two pages), pointing into the slot.
    pub fn wedge_bisector(&self, slot: usize) -> Vector3<f64> {
        let k = self.slots.len();
        let (lo, hi) = (self.pages[(slot + k - 1) % k].angle, self.pages[slot].angle);
        let width = (hi - lo).rem_euclid(TAU);
        self.direction_at(lo + 0.5 * width)
    }

    fn direction_at(&self, angle: f64) -> Vector3<f64> {
        let side = self.axis.cross(&self.reference);
        self.reference * angle.cos() + side * angle.sin()
    }

    /// The folded end section of a slot: a template point (x, y), in radius units and already
    /// turned by the branch's quarter turns, on its page. The spine cuts the template at
    /// `cut` (x = 0 for a fold split down the middle).
    pub fn fold(&self, slot: usize, p: &Vector2<f64>, cut: &SpineCut) -> Point3<f64> {
        let x = cut.across(p.x);
        let page = &self.pages[self.page_of(slot, x)];
        let along = if p.y >= 0.0 { self.spine_up } else { self.spine_down };
        // The core scales (ray targets, beyond it, do not).
        let in_core = x.abs().max(p.y.abs()) <= cut.core_size * (1.0 + 1e-12);
        let scale = if in_core { self.core_scale } else { 1.0 };
        self.centre + self.axis * (scale * p.y * along) + page.dir * (scale * x.abs() * page.depth)
    }

    /// The page of a slot's fold that a point lies on, from its signed distance `x` across the
    /// fold from the spine ([`SpineCut::across`]): the +x page from the spine on.
    fn page_of(&self, slot: usize, x: f64) -> usize {
        let (right, left) = self.side_pages(slot);
        if x >= 0.0 {
            right
        } else {
            left
        }
    }

    /// Angle between two slots' directions about the spine, radians in [0, pi].
    pub fn angle_between(&self, a: usize, b: usize) -> f64 {
        let d = (self.slots[b].angle - self.slots[a].angle).rem_euclid(TAU);
        d.min(TAU - d)
    }

    /// Why a transition of this junction folds, measured, for the message that refuses an
    /// inverted hex in it: the branch's radius against the junction's and the angle to its
    /// nearest neighbour about the spine. Every branch's folded end spans the whole spine, so a
    /// small or acute branch funnels into it; on the synthetic sweep (tests/branching.rs) finer
    /// meshes and thinner walls did not remove such folds.
    pub fn fold_cause(&self, tree: &CenterlineTree, branch: usize) -> String {
        let k = self.slots.len();
        let slot = self.slot_of(branch);
        let me = &self.slots[slot];
        let nearest = [(slot + 1) % k, (slot + k - 1) % k]
            .iter()
            .map(|&o| self.angle_between(slot, o))
            .fold(f64::INFINITY, f64::min);
        format!(
            "the transition of {} folds there: its radius is {:.2} mm, 1/{:.1} of the junction's {:.2} mm, and it \
             leaves {:.0} degrees from its nearest neighbour about the spine. Every branch's folded end spans the \
             junction's whole spine, so a small or acute branch funnels into it; vesselhex does not yet give small \
             side branches thin pages of their own (BRANCHING.md §4.3), and a finer mesh or a thinner wall seldom \
             removes such a fold",
            tree.branches[branch].name,
            me.radius,
            self.radius / me.radius,
            self.radius,
            nearest.to_degrees()
        )
    }

    /// Unit normal of a page, pointing to the side of the given slot.
    fn page_normal_towards(&self, page: usize, slot: usize) -> Vector3<f64> {
        let n = self.axis.cross(&self.pages[page].dir);
        if n.dot(&self.wedge_bisector(slot)) >= 0.0 {
            n
        } else {
            -n
        }
    }

    /// Direction in which the transition curve of a template point arrives at the fold, seen
    /// from the slot's side: along the wedge bisector at the spine, turning towards the page's
    /// normal away from it so that hexes meet the page at a good angle.
    pub fn arrival(&self, slot: usize, p: &Vector2<f64>, cut: &SpineCut) -> Vector3<f64> {
        let x = cut.across(p.x);
        let page = self.page_of(slot, x);
        let w = -self.wedge_bisector(slot);
        let n = -self.page_normal_towards(page, slot);
        let beta = 0.5 * (x.abs() / cut.core_size).min(1.0);
        (w * (1.0 - beta) + n * beta).normalize()
    }
}

/// Signed angle from `from` to `to` about the unit `axis` (both normal to it), radians.
pub fn signed_angle(from: &Vector3<f64>, to: &Vector3<f64>, axis: &Vector3<f64>) -> f64 {
    from.cross(to).dot(axis).atan2(from.dot(to))
}

/// Distance from a point along a direction to the lumen wall, or an error naming the junction.
fn wall_distance(
    surface: &LumenSurface,
    from: &Point3<f64>,
    dir: &Vector3<f64>,
    reach: f64,
    what: &dyn Fn() -> String,
) -> Result<f64> {
    surface.first_hit(from, dir, reach).map(|h| h.distance).ok_or_else(|| {
        Error::Geometry(format!(
            "{}: {}: a ray from the junction centre along ({:.3}, {:.3}, {:.3}) does not meet the lumen wall \
             within {:.2} mm; the junction centre may lie outside the lumen (check the centerlines)",
            surface.source.display(),
            what(),
            dir.x,
            dir.y,
            dir.z,
            reach
        ))
    })
}

/// The smallest angular gap between consecutive sorted angles (cyclic).
fn min_gap(angles: &mut [f64]) -> f64 {
    angles.sort_by(f64::total_cmp);
    let k = angles.len();
    (0..k).map(|i| (angles[(i + 1) % k] - angles[i]).rem_euclid(TAU)).fold(TAU, f64::min)
}

/// Branch direction leaving a junction: from the centre to the branch's centerline point at
/// `r_centre + r_branch` along it (where the branch leaves the junction's inscribed sphere).
fn leaving_direction(branch: &Branch, from_end: bool, reach: f64) -> (Vector3<f64>, f64) {
    let len = branch.length();
    let s = if from_end { (len - reach).max(0.0) } else { reach.min(len) };
    let q = branch.at(s);
    let c = if from_end { branch.samples.last().unwrap().point } else { branch.samples[0].point };
    ((q.point - c).normalize(), q.radius)
}

/// Analyses every junction of the tree.
pub fn analyse_junctions(tree: &CenterlineTree, surface: &LumenSurface) -> Result<Vec<JunctionGeometry>> {
    tree.junctions.iter().enumerate().map(|(j, _)| analyse_junction(tree, j, surface)).collect()
}

/// A junction whose analysis fails (its branches cannot be ordered about any axis, say) though
/// it lies within [`CLOSE_JUNCTIONS`] of its own radius from another junction: the two are one
/// junction in fact (a wide vessel whose side branches leave close together, the paths to them
/// parting inside its lumen), to be merged along the branch between them, as overlapping ones
/// are. The branch joining them (the shortest, if several) and the failure.
pub fn unanalysable_close_junction(tree: &CenterlineTree, surface: &LumenSurface) -> Option<JunctionOverlap> {
    for (j, junction) in tree.junctions.iter().enumerate() {
        let Err(error) = analyse_junction(tree, j, surface) else { continue };
        let joining = tree
            .branches
            .iter()
            .enumerate()
            .filter(|(_, b)| b.start_junction.zip(b.end_junction).is_some_and(|(s, e)| s == j || e == j))
            .filter(|(_, b)| b.length() < CLOSE_JUNCTIONS * junction.radius)
            .min_by(|a, b| a.1.length().total_cmp(&b.1.length()).then(a.0.cmp(&b.0)));
        if let Some((b, branch)) = joining {
            let (s, e) = (branch.start_junction.expect("joins two"), branch.end_junction.expect("joins two"));
            let place = format!(
                "the junctions at {} and {}",
                describe_point(&tree.junctions[s].centre),
                describe_point(&tree.junctions[e].centre)
            );
            return Some(JunctionOverlap { branch: b, place, error });
        }
    }
    None
}

/// Two junctions this many radii apart (of the one that cannot be analysed alone), or closer,
/// are one junction in fact.
const CLOSE_JUNCTIONS: f64 = 2.0;

/// The angular gaps about an axis between consecutive projected directions, the smallest
/// (radians); 0 when a direction lies within 11.5 degrees of the axis (its projection is too
/// short to order).
fn axis_gap(dirs: &[Vector3<f64>], a: &Vector3<f64>) -> f64 {
    let reference = dirs[0] - a * dirs[0].dot(a);
    if reference.norm() < 1e-9 {
        return 0.0;
    }
    let reference = reference.normalize();
    let mut angles: Vec<f64> = dirs
        .iter()
        .map(|d| {
            let p = d - a * d.dot(a);
            if p.norm() < 0.2 {
                return f64::NAN;
            }
            signed_angle(&reference, &p.normalize(), a).rem_euclid(TAU)
        })
        .collect();
    if angles.iter().any(|v| v.is_nan()) {
        return 0.0;
    }
    min_gap(&mut angles)
}

/// The spine's axis for branches leaving a junction along `dirs` (unit), and its smallest
/// angular gap (radians): of the best-fit plane's normal and the normals of the planes of pairs
/// of directions, the one that separates the projected directions best (the first of equals).
/// Where that axis is not acceptable (a gap under [`MIN_ANGULAR_GAP_DEG`], or a branch within
/// [`AXIS_CLEARANCE_DEG`] of it: it would fold onto pages that hold its own direction), the
/// best acceptable one of them, or else the directions' mean if acceptable. The mean is the
/// axis of a junction whose branches leave like the legs of a tripod, where no plane fits them
/// and the normal of a pair lies along the third (palabos_cerebral_aneurysm: the parent rising
/// into a sac, the daughters leaving it level 46 degrees apart, each about 90 degrees from the
/// parent; the best of the planes' normals lay 19 degrees off the parent, whose fold's rays ran
/// down it and out of the inlet at medium; about the mean, the gaps are 84 degrees or more and
/// every branch stands 29 degrees off).
fn spine_axis(dirs: &[Vector3<f64>]) -> (Vector3<f64>, f64) {
    let mut scatter = Matrix3::zeros();
    for d in dirs {
        scatter += d * d.transpose();
    }
    let eig = scatter.symmetric_eigen();
    let mut candidates = vec![eig.eigenvectors.column(eig.eigenvalues.imin()).into_owned()];
    for i in 0..dirs.len() {
        for j in i + 1..dirs.len() {
            let c = dirs[i].cross(&dirs[j]);
            if c.norm() > 1e-6 {
                candidates.push(c.normalize());
            }
        }
    }
    // Each candidate with its smallest gap; the best of some, the first of equals.
    let scored: Vec<(Vector3<f64>, f64)> = candidates.iter().map(|c| (*c, axis_gap(dirs, c))).collect();
    let best_of = |scored: &mut dyn Iterator<Item = &(Vector3<f64>, f64)>| {
        scored.fold(None, |best: Option<(Vector3<f64>, f64)>, &(c, g)| match best {
            Some(b) if g <= b.1 + 1e-9 => Some(b),
            _ => Some((c, g)),
        })
    };
    let clearance = AXIS_CLEARANCE_DEG.to_radians().sin();
    let acceptable = |(a, gap): &(Vector3<f64>, f64)| {
        gap.to_degrees() >= MIN_ANGULAR_GAP_DEG && dirs.iter().all(|d| (d - a * d.dot(a)).norm() >= clearance)
    };
    let best = best_of(&mut scored.iter()).expect("the best-fit plane's normal is a candidate");
    if acceptable(&best) {
        return best;
    }
    let mean: Vector3<f64> = dirs.iter().sum();
    let by_mean = (mean.norm() > 1e-6).then(|| (mean.normalize(), axis_gap(dirs, &mean.normalize())));
    best_of(&mut scored.iter().filter(|s| acceptable(s))).or(by_mean.filter(acceptable)).unwrap_or(best)
}

fn analyse_junction(tree: &CenterlineTree, index: usize, surface: &LumenSurface) -> Result<JunctionGeometry> {
    let junction = &tree.junctions[index];
    let x = junction.centre;
    let r_x = junction.radius;
    let mut members: Vec<(usize, bool)> = vec![(junction.parent, true)];
    members.extend(junction.daughters.iter().map(|&d| (d, false)));
    let where_ = || format!("the junction at {}", describe_point(&x));
    if members.len() > MAX_BRANCHES {
        return Err(Error::Geometry(format!(
            "{}: {} has {} branches; at most {MAX_BRANCHES} can share one junction. Split the centerlines so \
             that branches leave at least one radius apart",
            surface.source.display(),
            where_(),
            members.len()
        )));
    }
    let dirs: Vec<(Vector3<f64>, f64)> = members
        .iter()
        .map(|&(b, parent)| {
            let br = &tree.branches[b];
            let reach = r_x + br.at(if parent { br.length() } else { 0.0 }).radius;
            leaving_direction(br, parent, reach)
        })
        .collect();

    let directions: Vec<Vector3<f64>> = dirs.iter().map(|(d, _)| *d).collect();
    let (mut axis, gap) = spine_axis(&directions);
    // A deterministic sign: the largest component positive.
    let imax = axis.iamax();
    if axis[imax] < 0.0 {
        axis = -axis;
    }
    if gap.to_degrees() < MIN_ANGULAR_GAP_DEG {
        return Err(Error::Geometry(format!(
            "{}: {}: the branches cannot be ordered around a common axis (the best axis leaves only {:.1} degrees \
             between two branches, at least {MIN_ANGULAR_GAP_DEG} are needed): the junction is strongly non-planar. \
             Check the centerlines there, or smooth them (centerline.smoothing_passes)",
            surface.source.display(),
            where_(),
            gap.to_degrees()
        )));
    }
    let reference = (dirs[0].0 - axis * dirs[0].0.dot(&axis)).normalize();
    let mut slots: Vec<JunctionSlot> = members
        .iter()
        .zip(&dirs)
        .map(|(&(branch, is_parent), (d, r))| {
            let p = (d - axis * d.dot(&axis)).normalize();
            JunctionSlot {
                branch,
                is_parent,
                direction: p,
                angle: signed_angle(&reference, &p, &axis).rem_euclid(TAU),
                radius: *r,
            }
        })
        .collect();
    slots.sort_by(|a, b| a.angle.total_cmp(&b.angle));

    let k = slots.len();
    let mut geometry = JunctionGeometry {
        index,
        centre: x,
        radius: r_x,
        axis,
        reference,
        slots,
        pages: vec![],
        spine_up: 0.0,
        spine_down: 0.0,
        spine_cells: 0,
        core_scale: 1.0,
    };
    let reach = 20.0 * r_x;
    for i in 0..k {
        let (a, b) = (&geometry.slots[i], &geometry.slots[(i + 1) % k]);
        let width = (b.angle - a.angle).rem_euclid(TAU);
        let width = if width == 0.0 { TAU } else { width };
        let angle = a.angle + width * a.radius / (a.radius + b.radius);
        let dir = geometry.direction_at(angle);
        let depth = wall_distance(surface, &x, &dir, reach, &where_)?;
        geometry.pages.push(Page { dir, angle: angle.rem_euclid(TAU), depth, cells: 0 });
    }
    geometry.spine_up = wall_distance(surface, &x, &axis, reach, &where_)?;
    geometry.spine_down = wall_distance(surface, &x, &(-axis), reach, &where_)?;
    Ok(geometry)
}

/// Largest share of the way from a junction's centre to the wall that the boundary of a fold's
/// core may take once [`keep_fold_cores_inside`] has shrunk it.
const FOLD_CORE_REACH: f64 = 0.8;
/// Points sampled along each side of a page's half of the core's boundary.
const FOLD_CORE_SAMPLES: usize = 8;

/// Shrinks a junction's fold core (all its pages' and the spine's core nodes, about the centre)
/// where its boundary would leave the lumen, until it lies within [`FOLD_CORE_REACH`] of the
/// wall; a junction whose core lies inside keeps it as it is. The core is placed by the pages'
/// depths and the spine's lengths, each measured in one direction from the centre: between
/// them, where the lumen of a junction of many branches is not convex, a corner of the core
/// can lie outside it, and its rays then miss the wall (sphinxsys_aortic_arch, where the
/// brachiocephalic trunk and two arteries leave the arch within a radius of one another).
pub fn keep_fold_cores_inside(junctions: &mut [JunctionGeometry], core_size: f64, surface: &LumenSurface) {
    for g in junctions.iter_mut() {
        let n = FOLD_CORE_SAMPLES;
        let side = |i: usize| core_size * i as f64 / n as f64;
        // A page's half of the core's boundary: its rim (x = core_size) and its two ends along
        // the spine (y = +-core_size).
        let boundary: Vec<(f64, f64)> = (0..=2 * n)
            .map(|i| (core_size, side(i) - core_size))
            .chain((0..n).flat_map(|i| [(side(i), core_size), (side(i), -core_size)]))
            .collect();
        let mut scale: f64 = 1.0;
        for page in &g.pages {
            for &(x, y) in &boundary {
                let along = if y >= 0.0 { g.spine_up } else { g.spine_down };
                let offset = g.axis * (y * along) + page.dir * (x * page.depth);
                let distance = offset.norm();
                if let Some(hit) = surface.first_hit(&g.centre, &(offset / distance), distance) {
                    scale = scale.min(FOLD_CORE_REACH * hit.distance / distance);
                }
            }
        }
        g.core_scale = scale;
    }
}

/// Checks that the junctions at the two ends of every branch leave it a length of its own on
/// every side. A page's rim is the crotch between its two branches; when the crotch beside a
/// branch lies further along the branch than the junction at its other end, another branch
/// leaves from that crotch, the branch has no wall of its own on that side, and the two
/// junctions' block patterns would have to overlap there (their hexes invert; finer meshes or a
/// thinner wall do not help). Measured on the aortic arch (BRANCHING.md §3): its
/// brachiocephalic-carotid trunk, whose arch-side crotch lies 1.22 times as far along it as the
/// junction where it divides. Refusing here names the cause before any ray is cast.
pub fn check_junction_spacing(
    tree: &CenterlineTree,
    junctions: &[JunctionGeometry],
    surface: &LumenSurface,
) -> Result<()> {
    match find_junction_overlap(tree, junctions, surface) {
        Some(overlap) => Err(overlap.error),
        None => Ok(()),
    }
}

/// Two junctions whose block patterns would overlap, at the two ends of `branch`.
#[derive(Debug)]
pub struct JunctionOverlap {
    pub branch: usize,
    /// The two junctions, as errors name them.
    pub place: String,
    /// What [`check_junction_spacing`] reports: both junctions, the distances, the branch that
    /// leaves from the crotch.
    pub error: Error,
}

/// The first branch whose junctions overlap (see [`check_junction_spacing`]), if any.
pub fn find_junction_overlap(
    tree: &CenterlineTree,
    junctions: &[JunctionGeometry],
    surface: &LumenSurface,
) -> Option<JunctionOverlap> {
    for (b, branch) in tree.branches.iter().enumerate() {
        let (Some(ja), Some(jb)) = (branch.start_junction, branch.end_junction) else { continue };
        for (here, there) in [(&junctions[ja], &junctions[jb]), (&junctions[jb], &junctions[ja])] {
            let chord = there.centre - here.centre;
            let apart = chord.norm();
            let slot = here.slot_of(b);
            let (right, left) = here.side_pages(slot);
            for page in [right, left] {
                let p = &here.pages[page];
                let along = (p.dir * p.depth).dot(&chord) / apart;
                if along <= apart {
                    continue;
                }
                let k = here.slots.len();
                let name = |s: usize| tree.branches[here.slots[s % k].branch].name.as_str();
                let others: Vec<usize> = there.slots.iter().map(|s| s.branch).filter(|&o| o != b).collect();
                let names: Vec<&str> = others.iter().map(|&o| tree.branches[o].name.as_str()).collect();
                // The branch leaving from the crotch: the one whose tube passes nearest to it.
                let crotch = here.centre + p.dir * p.depth;
                let gap = |o: usize| {
                    tree.branches[o]
                        .samples
                        .iter()
                        .map(|s| (s.point - crotch).norm() - s.radius)
                        .fold(f64::INFINITY, f64::min)
                };
                let culprit = &tree.branches[*others
                    .iter()
                    .min_by(|&&x, &&y| gap(x).total_cmp(&gap(y)))
                    .expect("a junction has other branches")];
                let outlet = culprit.samples.last().expect("branches have samples").point;
                let error = Error::Geometry(format!(
                    "{}: {} and {} overlap: the crotch between {} and {} lies {:.1} mm from the first junction's \
                     centre along {}, past the second junction ({:.1} mm away, where {} meet). {} has no length \
                     of its own on that side: {} (ending at {}) leaves from that crotch. Merged into one, such \
                     junctions mesh; these could not be (they still overlap after merging, or too many pairs \
                     do: pages of unequal depth would be needed, BRANCHING.md §4.3); with {} clipped from the \
                     surface and the centerlines, the two junctions no longer meet",
                    surface.source.display(),
                    here.describe(tree),
                    there.describe(tree),
                    name(page),
                    name(page + 1),
                    along,
                    branch.name,
                    apart,
                    names.join(", "),
                    branch.name,
                    culprit.name,
                    describe_point(&outlet),
                    culprit.name,
                ));
                let place = format!("{} and {}", here.describe(tree), there.describe(tree));
                return Some(JunctionOverlap { branch: b, place, error });
            }
        }
    }
    None
}

/// Gives every junction the default cell counts of an n x n core: n along the spine and n/2
/// across each page, so every branch keeps the square core folded down its middle.
pub fn equal_cells(junctions: &mut [JunctionGeometry], n: usize) {
    for g in junctions {
        g.spine_cells = n;
        for page in &mut g.pages {
            page.cells = n / 2;
        }
    }
}

/// The core grid (columns, rows) a slot's fold asks of its branch: the cells of its two pages
/// across, the spine's along.
pub fn fold_dims(geometry: &JunctionGeometry, slot: usize) -> (usize, usize) {
    let (right, left) = geometry.side_pages(slot);
    (geometry.pages[right].cells + geometry.pages[left].cells, geometry.spine_cells)
}

/// Each branch's core grid (nx, ny), from the cells of the junctions at its ends: a branch
/// takes its first junction's fold dimensions (an unbranched vessel's, `n` x `n`); a branch
/// between two junctions must find the same at the other (a square core in any turn, a
/// rectangular one with its rows along both spines), or the junctions' cell counts cannot be
/// joined along it.
pub fn branch_core_dims(
    tree: &CenterlineTree,
    junctions: &[JunctionGeometry],
    n: usize,
    surface: &LumenSurface,
) -> Result<Vec<(usize, usize)>> {
    tree.branches
        .iter()
        .enumerate()
        .map(|(b, branch)| {
            let ends: Vec<&JunctionGeometry> =
                [branch.start_junction, branch.end_junction].into_iter().flatten().map(|j| &junctions[j]).collect();
            let Some(first) = ends.first() else { return Ok((n, n)) };
            let dims = fold_dims(first, first.slot_of(b));
            for other in &ends[1..] {
                let there = fold_dims(other, other.slot_of(b));
                if there != dims {
                    return Err(Error::Geometry(format!(
                        "{}: {} joins {} and {}, whose folds ask for core grids of {} x {} and {} x {} cells: \
                         the junctions' page cells cannot be joined along it",
                        surface.source.display(),
                        branch.name,
                        first.describe(tree),
                        other.describe(tree),
                        dims.0,
                        dims.1,
                        there.0,
                        there.1
                    )));
                }
            }
            Ok(dims)
        })
        .collect()
}

/// Quarter turns of the template as index maps on its nx x ny core grid: turning by 90
/// degrees counter-clockwise sends (x, y) to (-y, x), so grid node (i, j) goes to (ny - j, i)
/// of the turned ny x nx grid (see [`turned_dims`]).
pub fn turn_core_index(nx: usize, ny: usize, q: u8, i: usize, j: usize) -> (usize, usize) {
    let (mut i, mut j, mut rows, mut cols) = (i, j, ny, nx);
    for _ in 0..q % 4 {
        (i, j) = (rows - j, i);
        (cols, rows) = (rows, cols);
    }
    (i, j)
}

/// The (columns, rows) of an nx x ny core grid after q quarter turns.
pub fn turned_dims(nx: usize, ny: usize, q: u8) -> (usize, usize) {
    if q.is_multiple_of(2) {
        (nx, ny)
    } else {
        (ny, nx)
    }
}

/// The quarter turns a branch's template may take at a fold: any for a square core; for a
/// rectangular one only those that keep its rows along the spine (the junction's spine cells
/// are its rows at both ends).
pub fn allowed_turns(template: &SectionTemplate) -> &'static [u8] {
    if template.nx == template.ny {
        &[0, 1, 2, 3]
    } else {
        &[0, 2]
    }
}

/// A template point turned by q quarter turns.
pub fn turn(q: u8, p: &Vector2<f64>) -> Vector2<f64> {
    let mut p = *p;
    for _ in 0..q % 4 {
        p = Vector2::new(-p.y, p.x);
    }
    p
}

/// How a branch end meets a junction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FoldEnd {
    pub junction: usize,
    pub slot: usize,
    /// Quarter turns from the branch's template to the fold's.
    pub quarter_turns: u8,
    /// The core grid column of the turned template that lies on the spine: the columns on
    /// either side of it go to the two pages (the middle one today; a small branch's thin
    /// pages, BRANCHING.md §4.3, are to move it).
    pub split: usize,
}

impl FoldEnd {
    /// The fold of a slot: the turned template's columns left of the spine go to the slot's
    /// -x page, as many as that page has cells.
    pub fn at(geometry: &JunctionGeometry, slot: usize, quarter_turns: u8, template: &SectionTemplate) -> FoldEnd {
        let (right, left) = geometry.side_pages(slot);
        let split = geometry.pages[left].cells;
        debug_assert_eq!(
            turned_dims(template.nx, template.ny, quarter_turns),
            (split + geometry.pages[right].cells, geometry.spine_cells),
            "the template fits the fold"
        );
        FoldEnd { junction: geometry.index, slot, quarter_turns, split }
    }

    /// Where the spine cuts the turned template.
    pub fn spine_cut(&self, template: &SectionTemplate) -> SpineCut {
        let columns = turned_dims(template.nx, template.ny, self.quarter_turns).0;
        let a = template.core_size;
        // Exactly 0 down the middle, whatever the rounding of the grid's x.
        let x = if 2 * self.split == columns { 0.0 } else { -a + 2.0 * a * self.split as f64 / columns as f64 };
        SpineCut { x, core_size: a }
    }
}

/// Where the spine cuts a turned template (x, radius units) and the core's half-width.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpineCut {
    pub x: f64,
    pub core_size: f64,
}

impl SpineCut {
    /// Signed distance across the fold from the spine of a template x: the core on each side
    /// of the cut is stretched to the core's half-width, so a page's core nodes lie where every
    /// branch sharing that page puts them; from the core's edges outwards (ray targets) x is
    /// kept.
    pub fn across(&self, x: f64) -> f64 {
        if self.x == 0.0 {
            return x;
        }
        let d = x - self.x;
        let side = if d >= 0.0 { self.core_size - self.x } else { self.core_size + self.x };
        if d.abs() <= side {
            d * self.core_size / side
        } else {
            d.signum() * (self.core_size + d.abs() - side)
        }
    }
}

/// The frame normal a branch must have at a junction's transition station for its template,
/// turned by q quarter turns, to lie on the fold: x -> axis x tangent, y -> axis.
pub fn fold_normal(axis: &Vector3<f64>, tangent: &Vector3<f64>, q: u8) -> Vector3<f64> {
    let a = (axis - tangent * axis.dot(tangent)).normalize();
    let x = a.cross(tangent);
    // Turning the template by q quarter turns counter-clockwise turns the normal the other way.
    let angle = -(q as f64) * 0.5 * PI;
    x * angle.cos() - a * angle.sin()
}

/// Rotates every frame of a branch about its tangent by an angle that varies linearly in arc
/// length, from `start` at s0 to `end` at s1 (constant outside).
pub fn twist_frames(branch: &mut Branch, s0: f64, start: f64, s1: f64, end: f64) {
    for sample in &mut branch.samples {
        let w = if s1 > s0 { ((sample.s - s0) / (s1 - s0)).clamp(0.0, 1.0) } else { 0.0 };
        let phi = start + (end - start) * w;
        let f = sample.frame;
        let n = f.normal * phi.cos() + f.binormal * phi.sin();
        sample.frame = Frame::from_tangent_and_hint(f.tangent, n);
    }
}

/// Where the ordinary sections of a branch stop at a junction: far enough from the centre that
/// the section clears the neighbouring branches (a disc of radius r at distance L along a
/// branch at angle phi from its neighbour clears it when L > r (1 + cos phi) / sin phi), and at
/// least the junction's radius plus half the branch's away: outside the junction's own tube.
/// The floor used to be 1.5 junction radii for every branch; for a small branch that drew its
/// funnel out over more sections (the sweep's quarter-radius Y at 45 degrees: 0.320 -> 0.388,
/// T at 90 degrees: 0.124 -> 0.202, wall mean 0.85-0.88 -> 0.89-0.91), while a branch as wide as
/// the junction keeps 1.5 radii.
pub fn transition_length(geometry: &JunctionGeometry, slot: usize) -> f64 {
    let k = geometry.slots.len();
    let me = &geometry.slots[slot];
    let mut length: f64 = geometry.radius + 0.5 * me.radius;
    for other in [(slot + 1) % k, (slot + k - 1) % k] {
        let o = &geometry.slots[other];
        let phi = geometry.angle_between(slot, other).clamp(0.2, PI);
        let clear = if phi < 0.5 * PI { me.radius.max(o.radius) * (1.0 + phi.cos()) / phi.sin() } else { 0.0 };
        length = length.max(clear + 0.5 * me.radius);
    }
    length
}

/// Cubic Hermite interpolation between p0 (tangent t0) and p1 (tangent t1) at u in [0, 1].
pub fn hermite(p0: &Point3<f64>, t0: &Vector3<f64>, p1: &Point3<f64>, t1: &Vector3<f64>, u: f64) -> Point3<f64> {
    let (u2, u3) = (u * u, u * u * u);
    let h00 = 2.0 * u3 - 3.0 * u2 + 1.0;
    let h10 = u3 - 2.0 * u2 + u;
    let h01 = -2.0 * u3 + 3.0 * u2;
    let h11 = u3 - u2;
    Point3::from(p0.coords * h00 + t0 * h10 + p1.coords * h01 + t1 * h11)
}

/// The template points of one transition section: core nodes and ray targets, in order.
pub struct TransitionPoints {
    pub core: Vec<Point3<f64>>,
    pub targets: Vec<Point3<f64>>,
    pub centre: Point3<f64>,
}

/// Positions of the core nodes and ray targets along a transition, from the ordinary section
/// at `station` (u = 0) to the fold (u = 1), at the given parameters.
pub fn transition_points(
    geometry: &JunctionGeometry,
    fold: &FoldEnd,
    template: &SectionTemplate,
    station: &CenterlineSample,
    towards_junction: &Vector3<f64>,
    params: &[f64],
) -> Vec<TransitionPoints> {
    let cut = fold.spine_cut(template);
    let curve = |xy: &Vector2<f64>| {
        let p0 = template.place(station, xy);
        let turned = turn(fold.quarter_turns, xy);
        let p1 = geometry.fold(fold.slot, &turned, &cut);
        let chord = (p1 - p0).norm();
        let t0 = towards_junction * chord;
        let t1 = geometry.arrival(fold.slot, &turned, &cut) * chord;
        (p0, t0, p1, t1)
    };
    let core_curves: Vec<_> = template.core.iter().map(curve).collect();
    let target_curves: Vec<_> = template.target_dir.iter().map(|d| curve(&(d * template.ray_reach))).collect();
    let centre_curve = curve(&Vector2::zeros());
    params
        .iter()
        .map(|&u| {
            let eval = |c: &(Point3<f64>, Vector3<f64>, Point3<f64>, Vector3<f64>)| hermite(&c.0, &c.1, &c.2, &c.3, u);
            TransitionPoints {
                core: core_curves.iter().map(eval).collect(),
                targets: target_curves.iter().map(eval).collect(),
                centre: eval(&centre_curve),
            }
        })
        .collect()
}

/// Key of a node of a folded end section, the same for the two branches sharing a page.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct FoldKey {
    pub junction: u32,
    /// Page index, or u32::MAX on the spine.
    pub page: u32,
    /// Core grid columns from the spine.
    pub from_spine: u32,
    /// Core grid row (along the axis).
    pub row: u32,
    /// 0: the core node; 1..: ring levels (lumen, then wall) of the ray that starts there.
    pub level: u32,
}

impl FoldKey {
    pub const SPINE: u32 = u32::MAX;

    /// The key of core grid node (i, j) of a slot's template (before turning) at ring level.
    /// Folds split the core down its middle column, so the template is square.
    pub fn new(
        geometry: &JunctionGeometry,
        fold: &FoldEnd,
        template: &SectionTemplate,
        i: usize,
        j: usize,
        level: usize,
    ) -> FoldKey {
        let (ti, tj) = turn_core_index(template.nx, template.ny, fold.quarter_turns, i, j);
        let half = fold.split;
        let (right, left) = geometry.side_pages(fold.slot);
        let page = match ti.cmp(&half) {
            std::cmp::Ordering::Equal => FoldKey::SPINE,
            std::cmp::Ordering::Greater => right as u32,
            std::cmp::Ordering::Less => left as u32,
        };
        FoldKey {
            junction: geometry.index as u32,
            page,
            from_spine: ti.abs_diff(half) as u32,
            row: tj as u32,
            level: level as u32,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Smallest angle (degrees) between the axis and any of the directions.
    fn least_angle_to(axis: &Vector3<f64>, dirs: &[Vector3<f64>]) -> f64 {
        dirs.iter().map(|d| d.dot(axis).abs().acos().to_degrees()).fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn a_planar_junction_keeps_its_planes_normal_as_the_spine() {
        let at = |deg: f64| Vector3::new(deg.to_radians().cos(), deg.to_radians().sin(), 0.0);
        let dirs = [at(180.0), at(30.0), at(-30.0)];
        let (axis, gap) = spine_axis(&dirs);
        assert!(axis.z.abs() > 1.0 - 1e-9, "axis {axis:?}");
        assert!((gap.to_degrees() - 60.0).abs() < 1e-6, "gap {}", gap.to_degrees());
    }

    #[test]
    fn a_tripod_junction_gets_an_axis_every_branch_stands_off() {
        // palabos_cerebral_aneurysm's sac: the parent rises into it, the daughters leave it
        // level, 46 degrees apart (directions measured there).
        let dirs = [
            Vector3::new(-0.1302, -0.0208, -0.9913).normalize(),
            Vector3::new(0.6867, 0.7247, -0.0571).normalize(),
            Vector3::new(-0.0323, 0.9761, -0.2149).normalize(),
        ];
        // The plane that fits best and the pairs' planes each leave a branch within 25 degrees
        // of their normal, or the branches closer than 25 degrees about it.
        let (axis, gap) = spine_axis(&dirs);
        assert!(least_angle_to(&axis, &dirs) >= AXIS_CLEARANCE_DEG, "{}", least_angle_to(&axis, &dirs));
        assert!(gap.to_degrees() >= 80.0, "gap {}", gap.to_degrees());
        let mean: Vector3<f64> = dirs.iter().sum();
        assert!(axis.dot(&mean.normalize()) > 1.0 - 1e-9, "the mean is the axis: {axis:?}");
    }

    #[test]
    fn quarter_turns_of_indices_match_turns_of_points() {
        for (nx, ny) in [(4, 4), (4, 2), (2, 6)] {
            let t = SectionTemplate::rect(nx, ny, 0.5, 2.0);
            for q in 0..4u8 {
                let (tnx, tny) = turned_dims(nx, ny, q);
                // The turned template: the grid of the turned dimensions over the same square.
                let turned = SectionTemplate::rect(tnx, tny, 0.5, 2.0);
                let mut seen = std::collections::HashSet::new();
                for j in 0..=ny {
                    for i in 0..=nx {
                        let (ti, tj) = turn_core_index(nx, ny, q, i, j);
                        assert!(ti <= tnx && tj <= tny, "{nx}x{ny} q {q}: ({i}, {j}) -> ({ti}, {tj})");
                        let p = turn(q, &t.core[j * (nx + 1) + i]);
                        assert!((turned.core[tj * (tnx + 1) + ti] - p).norm() < 1e-12, "{nx}x{ny} q {q}");
                        seen.insert((ti, tj));
                    }
                }
                assert_eq!(seen.len(), t.core_len(), "a turn is one-to-one");
            }
            assert_eq!(allowed_turns(&t).len(), if nx == ny { 4 } else { 2 });
            for &q in allowed_turns(&t) {
                assert_eq!(turned_dims(nx, ny, q), (nx, ny), "allowed turns keep the rows along the spine");
            }
        }
    }

    /// A junction of three daughters-and-parent slots about the z axis, pages at 60, 180 and
    /// 300 degrees of depths 2, 3 and 4.
    fn three_pages() -> JunctionGeometry {
        let slot = |branch: usize, angle_deg: f64| JunctionSlot {
            branch,
            is_parent: branch == 0,
            direction: Vector3::new(angle_deg.to_radians().cos(), angle_deg.to_radians().sin(), 0.0),
            angle: angle_deg.to_radians(),
            radius: 1.0,
        };
        let page = |angle_deg: f64, depth: f64| Page {
            dir: Vector3::new(angle_deg.to_radians().cos(), angle_deg.to_radians().sin(), 0.0),
            angle: angle_deg.to_radians(),
            depth,
            cells: 0,
        };
        JunctionGeometry {
            index: 0,
            centre: Point3::origin(),
            radius: 2.0,
            axis: Vector3::z(),
            reference: Vector3::x(),
            slots: vec![slot(0, 0.0), slot(1, 120.0), slot(2, 240.0)],
            pages: vec![page(60.0, 2.0), page(180.0, 3.0), page(300.0, 4.0)],
            spine_up: 2.5,
            spine_down: 1.5,
            spine_cells: 8,
            core_scale: 1.0,
        }
    }

    /// In a hemispherical dome of radius 2 over a tube, a junction centred where the dome
    /// starts with its spine along the tube and pages 2 deep: a core reaching 0.8 of the way
    /// along pages and spine puts its corners 0.8 sqrt 2 radii out, beyond the dome, and is
    /// shrunk until they lie at FOLD_CORE_REACH of the way to it (about 1 / sqrt 2); a core of
    /// 0.6 lies inside (its corners 0.85 radii out) and keeps its scale. The fold's core nodes
    /// scale with it, its ray targets do not.
    #[test]
    fn a_fold_core_reaching_outside_the_lumen_is_shrunk_inside() {
        let surface = LumenSurface::new(&crate::testing::domed_tube_surface(2.0, 10.0, 2.0)).unwrap();
        let mut g = three_pages();
        g.centre = Point3::new(0.0, 0.0, 10.0);
        g.pages.iter_mut().for_each(|p| p.depth = 2.0);
        (g.spine_up, g.spine_down) = (2.0, 2.0);
        let mut wide = [g.clone()];
        keep_fold_cores_inside(&mut wide, 0.8, &surface);
        assert!((wide[0].core_scale - 0.5_f64.sqrt()).abs() < 0.01, "scale {}", wide[0].core_scale);
        let mut narrow = [g.clone()];
        keep_fold_cores_inside(&mut narrow, 0.6, &surface);
        assert_eq!(narrow[0].core_scale, 1.0);

        let cut = SpineCut { x: 0.0, core_size: 0.8 };
        let (corner, target) = (Vector2::new(0.8, 0.8), Vector2::new(1.6, 1.6));
        let out = |g: &JunctionGeometry, p: &Vector2<f64>| g.fold(1, p, &cut) - g.centre;
        let s = wide[0].core_scale;
        assert!((out(&wide[0], &corner) - out(&g, &corner) * s).norm() < 1e-12, "the core scales");
        assert!((out(&wide[0], &target) - out(&g, &target)).norm() < 1e-12, "the targets stay");
        assert!(out(&wide[0], &corner).norm() < 0.81 * 2.0, "the corner lies inside the dome");
    }

    /// A fold split down the middle keeps every template x as it is (to the bit); an
    /// off-centre split puts its column on the spine and each side's core edge at the core's
    /// half-width.
    #[test]
    fn spine_cut_measures_across_from_the_split() {
        let square = SectionTemplate::new(8, 0.5, 2.0);
        for q in 0..4u8 {
            let cut = FoldEnd { junction: 0, slot: 1, quarter_turns: q, split: 4 }.spine_cut(&square);
            for p in &square.core {
                assert_eq!(cut.across(p.x).to_bits(), p.x.to_bits());
            }
        }
        let off = FoldEnd { junction: 0, slot: 1, quarter_turns: 0, split: 6 }.spine_cut(&square);
        let x = |i: usize| square.core[i].x;
        assert!(off.across(x(6)).abs() < 1e-15, "the split column is on the spine");
        assert!((off.across(x(8)) - 0.5).abs() < 1e-15 && (off.across(x(0)) + 0.5).abs() < 1e-15);
        assert!((off.across(x(7)) - 0.25).abs() < 1e-15, "two columns share the right half-width");
        assert!((off.across(x(3)) + 0.25).abs() < 1e-15, "six columns share the left half-width");
        for x in [1.5, -1.5, 0.5, -0.5] {
            assert!((off.across(x) - x).abs() < 1e-15, "from the core's edges outwards, x is kept: {x}");
        }
    }

    /// A large branch split two columns from its right edge and a small 4-column branch split
    /// down its middle share a two-column page: both give its core nodes the same keys and
    /// the same points.
    #[test]
    fn unequal_splits_agree_on_a_shared_page() {
        let g = three_pages();
        let large = SectionTemplate::new(8, 0.5, 2.0);
        let small = SectionTemplate::rect(4, 8, 0.5, 2.0);
        let fold_large = FoldEnd { junction: 0, slot: 1, quarter_turns: 0, split: 6 };
        let fold_small = FoldEnd { junction: 0, slot: 2, quarter_turns: 0, split: 2 };
        assert_eq!(g.side_pages(1).0, g.side_pages(2).1, "slot 1's right page is slot 2's left");
        let (cut_large, cut_small) = (fold_large.spine_cut(&large), fold_small.spine_cut(&small));
        for j in 0..=8 {
            for from_spine in 0..=2 {
                let (il, is) = (6 + from_spine, 2 - from_spine);
                let kl = FoldKey::new(&g, &fold_large, &large, il, j, 0);
                let ks = FoldKey::new(&g, &fold_small, &small, is, j, 0);
                assert_eq!(kl, ks, "row {j}, {from_spine} from the spine");
                let pl = g.fold(1, &large.core[j * 9 + il], &cut_large);
                let ps = g.fold(2, &small.core[j * 5 + is], &cut_small);
                assert!((pl - ps).norm() < 1e-12, "row {j}, {from_spine} from the spine: {pl} vs {ps}");
            }
        }
    }

    /// Equal cells give every slot the square n x n fold split down its middle; thin pages
    /// beside a slot give it a rectangular core and move its neighbours' splits.
    #[test]
    fn page_cells_set_the_folds() {
        let mut g = three_pages();
        equal_cells(std::slice::from_mut(&mut g), 8);
        let square = SectionTemplate::new(8, 0.5, 2.0);
        for slot in 0..3 {
            assert_eq!(fold_dims(&g, slot), (8, 8));
            for q in 0..4u8 {
                assert_eq!(FoldEnd::at(&g, slot, q, &square).split, 4);
            }
        }
        // Slot 2 between two thin pages (pages 1 and 2), the page between slots 0 and 1 deep.
        for (page, cells) in g.pages.iter_mut().zip([6, 2, 2]) {
            page.cells = cells;
        }
        assert_eq!(fold_dims(&g, 2), (4, 8), "the small branch gets a 4 x 8 core");
        assert_eq!(fold_dims(&g, 1), (8, 8));
        assert_eq!(fold_dims(&g, 0), (8, 8));
        let (right, left) = g.side_pages(1);
        assert_eq!(FoldEnd::at(&g, 1, 0, &square).split, g.pages[left].cells);
        assert_eq!(g.pages[right].cells + g.pages[left].cells, 8);
        let small = SectionTemplate::rect(4, 8, 0.5, 2.0);
        assert_eq!(FoldEnd::at(&g, 2, 2, &small).split, 2);
    }

    #[test]
    fn fold_normal_puts_the_template_on_the_pages() {
        let axis = Vector3::z();
        let tangent = Vector3::x();
        for q in 0..4u8 {
            let n = fold_normal(&axis, &tangent, q);
            let b = tangent.cross(&n);
            // template point (1, 0) placed with this frame equals the turned point on the fold axes
            let p = turn(q, &Vector2::new(1.0, 0.0));
            let expect = axis.cross(&tangent) * p.x + axis * p.y;
            assert!((n - expect).norm() < 1e-12, "q {q}");
            let p = turn(q, &Vector2::new(0.0, 1.0));
            let expect = axis.cross(&tangent) * p.x + axis * p.y;
            assert!((b - expect).norm() < 1e-12, "q {q}");
        }
    }

    #[test]
    fn hermite_interpolates_ends_and_tangents() {
        let (p0, p1) = (Point3::origin(), Point3::new(1.0, 0.0, 0.0));
        let (t0, t1) = (Vector3::new(0.0, 1.0, 0.0), Vector3::new(1.0, 0.0, 0.0));
        assert_eq!(hermite(&p0, &t0, &p1, &t1, 0.0), p0);
        assert!((hermite(&p0, &t0, &p1, &t1, 1.0) - p1).norm() < 1e-15);
        let h = 1e-6;
        let d0 = (hermite(&p0, &t0, &p1, &t1, h) - p0) / h;
        assert!((d0 - t0).norm() < 1e-5);
    }
}
