//! Block topology at a junction, built from the lumen surface and the centerline tree without
//! manual input: every branch's O-grid is swept from its last ordinary cross-section to a
//! *folded* end section laid on radial half-planes around the junction's centre X, which it
//! shares with its neighbours, so the junction is conformal by construction and every hex of it
//! belongs to exactly one branch.
//!
//! A fold lays the branch's square core onto four planar *sectors* around X, one per quadrant:
//! the quadrant between the template's +x and +y half-axes onto the sector between the fold's
//! +x and +y *spokes* (radial lines from X to the wall), and so on round. A template point
//! (x, y) of that quadrant goes to `X + |y| depth_V dir_V + |x| depth_U dir_U`, U and V the
//! spokes its signs pick, each spoke's depth its distance from X to the wall, so rays stay in
//! their sector and reach the wall between the two branches sharing it. A sector's nodes are
//! computed once and given to both branches.
//!
//! Two arrangements of the spokes (see [`Arrangement`]):
//! * the *book of pages* (BRANCHING.md §1): a straight spine through X along an axis `a`
//!   normal to the (best-fit) plane of the branch directions, its two ends spokes shared by
//!   every branch; the k branches, ordered counter-clockwise about `a`, separated by k
//!   half-plane pages, each holding one more spoke in its middle. Used wherever the branches
//!   can be ordered about an axis (at least 25 degrees apart, none within 25 degrees of it),
//!   and for every bifurcation (three branches admit no other arrangement);
//! * *sectors* ([`layout`]): the spokes of the branches' spherical Delaunay triangulation, for
//!   a junction whose branches leave in every direction (a non-planar junction, six branches at
//!   one place), where a shared straight spine would run down one of them.
//!
//! Choices, defended in the README:
//! * a page sits between its two branches at an angle split in proportion to their radii, so a
//!   small side branch gets a narrow wedge and the large vessel keeps its cells;
//! * each node of the transition follows a cubic Hermite curve from its place in the last
//!   ordinary section (leaving along the centerline) to its place on the fold (arriving across
//!   its sector), and the rays that find the lumen wall follow the same interpolation.

pub mod blocks;
pub mod layout;

use crate::data::error::{Error, Result};
use crate::geometry::surface::LumenSurface;
use crate::stages::centerline::{Branch, CenterlineSample, CenterlineTree, Frame};
use crate::stages::junction::blocks::SectionTemplate;
use nalgebra::{Matrix3, Point3, Vector2, Vector3};
use std::f64::consts::{PI, TAU};

/// A book's branches whose projected directions are closer than this about the spine would fold
/// onto narrow pages (BRANCHING.md §4.1): such a junction of four or more branches is laid out in
/// sectors where they fold better.
const MIN_ANGULAR_GAP_DEG: f64 = 25.0;
/// The spine's axis is chosen among those every branch leaves at least this far off, where
/// any is (see [`spine_axis`]).
const AXIS_CLEARANCE_DEG: f64 = 25.0;

/// Which arrangements the analysis may use (see [`analyse_junctions`]).
#[derive(Debug, Default)]
pub struct LayoutPolicy {
    /// Sectors at every junction of four or more branches that has a sector layout; otherwise
    /// books only, and a junction no book orders is refused.
    pub sectors: bool,
    /// Set, with `sectors` off, when a junction of four or more branches has a sector layout,
    /// or a book was refused: meshing again with sectors allowed gives another mesh.
    pub sectors_differ: std::cell::Cell<bool>,
    /// Two junctions whose blocks are predicted to overlap (see [`check_junction_spacing`]) are
    /// meshed apart all the same, their elements judged as any: set only after the two merged
    /// into one were refused at every place.
    pub overlaps_meshed: bool,
}

impl LayoutPolicy {
    pub fn books_only() -> Self {
        LayoutPolicy::default()
    }

    pub fn with_sectors() -> Self {
        LayoutPolicy { sectors: true, ..LayoutPolicy::default() }
    }

    /// This policy with overlapping junctions meshed apart (see `overlaps_meshed`).
    pub fn meshing_overlaps(&self) -> Self {
        LayoutPolicy { sectors: self.sectors, sectors_differ: self.sectors_differ.clone(), overlaps_meshed: true }
    }
}

/// Largest number of branches a book takes (pages of 72 degrees at most, a spine shared by ten
/// sectors).
const MAX_BOOK_BRANCHES: usize = 5;

/// One branch as seen from a junction.
#[derive(Debug, Clone)]
pub struct JunctionSlot {
    pub branch: usize,
    /// The branch that ends at the junction (the others start there).
    pub is_parent: bool,
    /// Unit direction from the centre into the branch: in a book, projected normal to the
    /// spine; in sectors, as it leaves.
    pub direction: Vector3<f64>,
    /// In a book, the angle of `direction` about the spine from the reference direction,
    /// radians in [0, 2 pi); 0 in sectors.
    pub angle: f64,
    /// Branch radius near the junction, mm.
    pub radius: f64,
}

/// A radial line from the junction's centre to its wall on which sectors meet.
#[derive(Debug, Clone)]
pub struct Spoke {
    /// Unit direction from the centre.
    pub dir: Vector3<f64>,
    /// Distance from the centre to the lumen wall along `dir`, mm.
    pub depth: f64,
    /// How many sectors meet on it (a book's spine ends: every branch's two; a page's middle:
    /// two).
    pub valence: usize,
}

/// How a junction's spokes are arranged.
#[derive(Debug, Clone)]
pub enum Arrangement {
    /// Spokes 0 and 1 are the spine's ends (+axis, -axis), spoke 2 + i the middle of page i,
    /// which lies between slot i and slot i + 1 (cyclically); slots counter-clockwise about
    /// the axis.
    Book {
        /// Spine axis (unit).
        axis: Vector3<f64>,
        /// Angle origin about the axis (unit, normal to it): the parent's direction.
        reference: Vector3<f64>,
        /// Each page's angle about the axis from the reference, radians in [0, 2 pi).
        page_angles: Vec<f64>,
    },
    /// Spokes from the branches' spherical Delaunay triangulation ([`layout`]).
    Sectors {
        /// Per slot, the slots it shares each of its fold's four sectors with (the sector
        /// between its +x and +y spokes first, counter-clockwise on the template).
        neighbours: Vec<[usize; 4]>,
    },
}

/// The geometry of one junction.
#[derive(Debug, Clone)]
pub struct JunctionGeometry {
    pub index: usize,
    pub centre: Point3<f64>,
    pub radius: f64,
    pub arrangement: Arrangement,
    /// The branches meeting here (in a book, counter-clockwise about the spine).
    pub slots: Vec<JunctionSlot>,
    pub spokes: Vec<Spoke>,
    /// Per slot, the spokes its fold lays the template's +x, +y, -x and -y half-axes on.
    pub folds: Vec<[usize; 4]>,
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

    /// The spine's axis of a book, `None` for sectors.
    pub fn spine_axis(&self) -> Option<Vector3<f64>> {
        match &self.arrangement {
            Arrangement::Book { axis, .. } => Some(*axis),
            Arrangement::Sectors { .. } => None,
        }
    }

    /// The name of the arrangement, as report.json gives it.
    pub fn arrangement_name(&self) -> &'static str {
        match self.arrangement {
            Arrangement::Book { .. } => "book",
            Arrangement::Sectors { .. } => "sectors",
        }
    }

    /// Unit direction into a slot's share of the junction (a book: the bisector of its wedge
    /// between its two pages; sectors: its direction).
    pub fn bisector(&self, slot: usize) -> Vector3<f64> {
        match &self.arrangement {
            Arrangement::Book { axis, reference, page_angles } => {
                let k = self.slots.len();
                let (lo, hi) = (page_angles[(slot + k - 1) % k], page_angles[slot]);
                let width = (hi - lo).rem_euclid(TAU);
                direction_about(axis, reference, lo + 0.5 * width)
            }
            Arrangement::Sectors { .. } => self.slots[slot].direction,
        }
    }

    /// The spokes of a slot's fold a template point (turned to the fold) lies towards: the one
    /// its x picks (+x or -x) and the one its y picks.
    fn spokes_of(&self, slot: usize, p: &Vector2<f64>) -> (usize, usize) {
        let f = &self.folds[slot];
        (if p.x >= 0.0 { f[0] } else { f[2] }, if p.y >= 0.0 { f[1] } else { f[3] })
    }

    /// The folded end section of a slot: a template point (x, y), in radius units and already
    /// turned by the branch's quarter turns, on its sector.
    pub fn fold(&self, slot: usize, p: &Vector2<f64>, core_size: f64) -> Point3<f64> {
        let (u, v) = self.spokes_of(slot, p);
        let (u, v) = (&self.spokes[u], &self.spokes[v]);
        // The core scales (ray targets, beyond it, do not).
        let in_core = p.x.abs().max(p.y.abs()) <= core_size * (1.0 + 1e-12);
        let scale = if in_core { self.core_scale } else { 1.0 };
        self.centre + v.dir * (scale * p.y.abs() * v.depth) + u.dir * (scale * p.x.abs() * u.depth)
    }

    /// Angle between two slots' directions, radians in [0, pi] (in a book, about the spine).
    pub fn angle_between(&self, a: usize, b: usize) -> f64 {
        match &self.arrangement {
            Arrangement::Book { .. } => {
                let d = (self.slots[b].angle - self.slots[a].angle).rem_euclid(TAU);
                d.min(TAU - d)
            }
            Arrangement::Sectors { .. } => self.slots[a].direction.angle(&self.slots[b].direction),
        }
    }

    /// The slots a slot shares a sector with (in a book, the two beside it about the spine).
    pub fn neighbours(&self, slot: usize) -> Vec<usize> {
        match &self.arrangement {
            Arrangement::Book { .. } => {
                let k = self.slots.len();
                vec![(slot + 1) % k, (slot + k - 1) % k]
            }
            Arrangement::Sectors { neighbours } => {
                let mut n = neighbours[slot].to_vec();
                n.sort_unstable();
                n.dedup();
                n
            }
        }
    }

    /// The slots whose folds take a spoke.
    pub fn slots_at(&self, spoke: usize) -> Vec<usize> {
        (0..self.slots.len()).filter(|&s| self.folds[s].contains(&spoke)).collect()
    }

    /// Where a slot's fold meets the wall: its four spokes' wall points.
    pub fn fold_wall(&self, slot: usize) -> [Point3<f64>; 4] {
        self.folds[slot].map(|s| self.centre + self.spokes[s].dir * self.spokes[s].depth)
    }

    /// The spokes of a slot's fold that run to crotches between it and its neighbours: the +x
    /// and -x ones (in a book its pages; the +y and -y ones are the spine's ends).
    pub fn crotch_spokes(&self, slot: usize) -> [usize; 2] {
        [self.folds[slot][0], self.folds[slot][2]]
    }

    /// Why a transition of this junction folds, measured, for the message that refuses an
    /// inverted hex in it: the branch's radius against the junction's and the angle to its
    /// nearest neighbour. A small branch's fold spans as much of the junction as a large one's
    /// (in a book the whole spine), so a small or acute branch funnels into it; on the synthetic
    /// sweep (tests/branching.rs) finer meshes and thinner walls did not remove such folds.
    pub fn fold_cause(&self, tree: &CenterlineTree, branch: usize) -> String {
        let slot = self.slot_of(branch);
        let me = &self.slots[slot];
        let nearest = self.neighbours(slot).iter().map(|&o| self.angle_between(slot, o)).fold(f64::INFINITY, f64::min);
        let spans = match self.arrangement {
            Arrangement::Book { .. } => "the junction's whole spine",
            Arrangement::Sectors { .. } => "four sectors reaching across the junction",
        };
        format!(
            "the transition of {} folds there: its radius is {:.2} mm, 1/{:.1} of the junction's {:.2} mm, and it \
             leaves {:.0} degrees from its nearest neighbour. Every branch's folded end spans {spans}, so a small or \
             acute branch funnels into it, and a finer mesh or a thinner wall seldom removes such a fold",
            tree.branches[branch].name,
            me.radius,
            self.radius / me.radius,
            self.radius,
            nearest.to_degrees()
        )
    }

    /// Unit normal of the sector between spokes `u` and `v`, pointing to the side of the given
    /// slot.
    fn sector_normal_towards(&self, u: usize, v: usize, slot: usize) -> Vector3<f64> {
        let n = self.spokes[u].dir.cross(&self.spokes[v].dir);
        if n.dot(&self.bisector(slot)) >= 0.0 {
            n
        } else {
            -n
        }
    }

    /// Direction in which the transition curve of a template point arrives at the fold, seen
    /// from the slot's side: along the slot's bisector next to a spoke that three or more
    /// sectors share (a book's spine), turning towards the sector's normal away from it so that
    /// hexes meet the sector at a good angle.
    pub fn arrival(&self, slot: usize, p: &Vector2<f64>, core_size: f64) -> Vector3<f64> {
        let (u, v) = self.spokes_of(slot, p);
        let w = -self.bisector(slot);
        let n = -self.sector_normal_towards(u, v, slot);
        // Distance from the shared spokes: |x| from the +y/-y one, |y| from the +x/-x one.
        let shared = |s: usize| self.spokes[s].valence >= 3;
        let from_shared = match (shared(v), shared(u)) {
            (true, true) => p.x.abs().min(p.y.abs()),
            (true, false) => p.x.abs(),
            (false, true) => p.y.abs(),
            (false, false) => core_size,
        };
        let beta = 0.5 * (from_shared / core_size).min(1.0);
        (w * (1.0 - beta) + n * beta).normalize()
    }

    /// The frame normal a branch must have at its transition station for its template, turned
    /// by q quarter turns, to lie on its fold: y towards the fold's +y spoke and away from its
    /// -y one (in a book, along the spine), x = y x tangent.
    pub fn fold_normal(&self, slot: usize, tangent: &Vector3<f64>, q: u8) -> Vector3<f64> {
        let f = &self.folds[slot];
        fold_normal(&(self.spokes[f[1]].dir - self.spokes[f[3]].dir), tangent, q)
    }
}

/// The unit direction at `angle` about `axis` from `reference` (both unit, normal).
fn direction_about(axis: &Vector3<f64>, reference: &Vector3<f64>, angle: f64) -> Vector3<f64> {
    let side = axis.cross(reference);
    reference * angle.cos() + side * angle.sin()
}

/// Signed angle from `from` to `to` about the unit `axis` (both normal to it), radians.
pub fn signed_angle(from: &Vector3<f64>, to: &Vector3<f64>, axis: &Vector3<f64>) -> f64 {
    from.cross(to).dot(axis).atan2(from.dot(to))
}

/// A spoke that runs out of the vessel through an open end (between two branches leaving a few
/// degrees apart, the ray finds no crotch before an end) reaches this many junction radii.
const OPEN_SPOKE_REACH: f64 = 3.0;

/// Distance from a point along a direction to the lumen wall; where the ray leaves through an
/// open end from a centre inside the lumen, [`OPEN_SPOKE_REACH`] junction radii (`reach` is 20
/// of them); an error naming the junction when the centre lies outside.
fn wall_distance(
    surface: &LumenSurface,
    from: &Point3<f64>,
    dir: &Vector3<f64>,
    reach: f64,
    what: &dyn Fn() -> String,
) -> Result<f64> {
    let hit = surface.first_hit(from, dir, reach).map(|h| h.distance);
    if hit.is_none() && surface.winding_number(from).abs() >= 0.5 {
        return Ok(OPEN_SPOKE_REACH * reach / 20.0);
    }
    hit.ok_or_else(|| {
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

/// Analyses every junction of the tree: a book where one orders its branches; where none does,
/// sectors if `policy` allows them (a bifurcation's book, else), or else a refusal naming the
/// junction (recorded in the policy).
pub fn analyse_junctions(
    tree: &CenterlineTree,
    surface: &LumenSurface,
    policy: &LayoutPolicy,
) -> Result<Vec<JunctionGeometry>> {
    tree.junctions.iter().enumerate().map(|(j, _)| analyse_junction(tree, j, surface, policy)).collect()
}

/// A junction whose analysis fails (its branches cannot be ordered about any axis, say) though
/// it lies within [`CLOSE_JUNCTIONS`] of its own radius from another junction: the two are one
/// junction in fact (a wide vessel whose side branches leave close together, the paths to them
/// parting inside its lumen), to be merged along the branch between them, as overlapping ones
/// are. The branch joining them (the shortest, if several) and the failure.
pub fn unanalysable_close_junction(tree: &CenterlineTree, surface: &LumenSurface) -> Option<JunctionOverlap> {
    for (j, junction) in tree.junctions.iter().enumerate() {
        let Err(error) = analyse_junction(tree, j, surface, &LayoutPolicy::books_only()) else { continue };
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

/// The spine's axis for branches leaving a junction along `dirs` (unit), its smallest angular
/// gap (radians) and whether it is acceptable: of the best-fit plane's normal and the normals of the planes of pairs
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
fn spine_axis(dirs: &[Vector3<f64>]) -> (Vector3<f64>, f64, bool) {
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
        return (best.0, best.1, true);
    }
    let mean: Vector3<f64> = dirs.iter().sum();
    let by_mean = (mean.norm() > 1e-6).then(|| (mean.normalize(), axis_gap(dirs, &mean.normalize())));
    match best_of(&mut scored.iter().filter(|s| acceptable(s))).or(by_mean.filter(acceptable)) {
        Some((axis, gap)) => (axis, gap, true),
        None => (best.0, best.1, false),
    }
}

fn analyse_junction(
    tree: &CenterlineTree,
    index: usize,
    surface: &LumenSurface,
    policy: &LayoutPolicy,
) -> Result<JunctionGeometry> {
    let junction = &tree.junctions[index];
    let x = junction.centre;
    let r_x = junction.radius;
    let mut members: Vec<(usize, bool)> = vec![(junction.parent, true)];
    members.extend(junction.arriving.iter().map(|&b| (b, true)));
    members.extend(junction.daughters.iter().map(|&d| (d, false)));
    let where_ = || format!("the junction at {}", describe_point(&x));
    let dirs: Vec<(Vector3<f64>, f64)> = members
        .iter()
        .map(|&(b, parent)| {
            let br = &tree.branches[b];
            let reach = r_x + br.at(if parent { br.length() } else { 0.0 }).radius;
            leaving_direction(br, parent, reach)
        })
        .collect();
    let directions: Vec<Vector3<f64>> = dirs.iter().map(|(d, _)| *d).collect();
    let radii: Vec<f64> = dirs.iter().map(|(_, r)| *r).collect();
    let (mut axis, gap, _) = spine_axis(&directions);
    // Four or more branches may be laid out in sectors (three admit no other arrangement than
    // the book).
    let sectors = if members.len() >= 4 { layout::sector_layout(&directions, &radii) } else { None };
    if sectors.is_some() && !policy.sectors {
        policy.sectors_differ.set(true);
    }
    if let Some(sectors) = sectors.filter(|_| policy.sectors) {
        return sectors_geometry(index, x, r_x, &members, &directions, &radii, &sectors, surface, &where_);
    }
    if members.len() > MAX_BOOK_BRANCHES {
        policy.sectors_differ.set(true);
        return Err(Error::Geometry(format!(
            "{}: {} has {} branches; at most {MAX_BOOK_BRANCHES} can share one book of pages",
            surface.source.display(),
            where_(),
            members.len()
        )));
    }
    // With sectors allowed, a book no sectors replace (a bifurcation's: there is no other
    // arrangement of three branches) is meshed however narrow its pages, and the elements decide.
    if gap.to_degrees() < MIN_ANGULAR_GAP_DEG && !policy.sectors {
        policy.sectors_differ.set(true);
        return Err(Error::Geometry(format!(
            "{}: {}: the branches cannot be ordered around a common axis (the best axis leaves only {:.1} degrees \
             between two branches, at least {MIN_ANGULAR_GAP_DEG} are needed): the junction is strongly non-planar",
            surface.source.display(),
            where_(),
            gap.to_degrees()
        )));
    }
    // A deterministic sign: the largest component positive.
    let imax = axis.iamax();
    if axis[imax] < 0.0 {
        axis = -axis;
    }
    book_geometry(index, x, r_x, &members, &dirs, axis, surface, &where_)
}

/// A junction laid out as a book about `axis`: its slots ordered about it, a page between each
/// two, the spine's ends and the pages' middles measured to the wall.
#[allow(clippy::too_many_arguments)]
fn book_geometry(
    index: usize,
    x: Point3<f64>,
    r_x: f64,
    members: &[(usize, bool)],
    dirs: &[(Vector3<f64>, f64)],
    axis: Vector3<f64>,
    surface: &LumenSurface,
    where_: &dyn Fn() -> String,
) -> Result<JunctionGeometry> {
    let reference = (dirs[0].0 - axis * dirs[0].0.dot(&axis)).normalize();
    let mut slots: Vec<JunctionSlot> = members
        .iter()
        .zip(dirs)
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
    let reach = 20.0 * r_x;
    let up = wall_distance(surface, &x, &axis, reach, where_)?;
    let down = wall_distance(surface, &x, &(-axis), reach, where_)?;
    let mut spokes = vec![Spoke { dir: axis, depth: up, valence: k }, Spoke { dir: -axis, depth: down, valence: k }];
    let mut page_angles = vec![];
    for i in 0..k {
        let (a, b) = (&slots[i], &slots[(i + 1) % k]);
        let width = (b.angle - a.angle).rem_euclid(TAU);
        let width = if width == 0.0 { TAU } else { width };
        let angle = a.angle + width * a.radius / (a.radius + b.radius);
        let dir = direction_about(&axis, &reference, angle);
        let depth = wall_distance(surface, &x, &dir, reach, where_)?;
        spokes.push(Spoke { dir, depth, valence: 2 });
        page_angles.push(angle.rem_euclid(TAU));
    }
    // Page i lies between slot i and slot i + 1. The template's x axis is the frame normal =
    // binormal x tangent = axis x tangent at the fold; a daughter's tangent leaves the centre,
    // so its +x is the counter-clockwise page; the parent's arrives, so its +x is clockwise.
    let folds = (0..k)
        .map(|s| {
            let (ccw, cw) = (2 + s, 2 + (s + k - 1) % k);
            let (right, left) = if slots[s].is_parent { (cw, ccw) } else { (ccw, cw) };
            [right, 0, left, 1]
        })
        .collect();
    Ok(JunctionGeometry {
        index,
        centre: x,
        radius: r_x,
        arrangement: Arrangement::Book { axis, reference, page_angles },
        slots,
        spokes,
        folds,
        core_scale: 1.0,
    })
}

/// A junction laid out in sectors: each slot's fold takes its layout corners, ordered so that
/// the template's axes turn counter-clockwise about the branch's tangent at the fold (a
/// daughter's leaves the centre, the parent's arrives) and its +y and -y spokes are the pair
/// further apart across the branch.
#[allow(clippy::too_many_arguments)]
fn sectors_geometry(
    index: usize,
    x: Point3<f64>,
    r_x: f64,
    members: &[(usize, bool)],
    directions: &[Vector3<f64>],
    radii: &[f64],
    layout: &layout::Layout,
    surface: &LumenSurface,
    where_: &dyn Fn() -> String,
) -> Result<JunctionGeometry> {
    let reach = 20.0 * r_x;
    let spokes = layout
        .spokes
        .iter()
        .zip(&layout.valence)
        .map(|(dir, &valence)| Ok(Spoke { dir: *dir, depth: wall_distance(surface, &x, dir, reach, where_)?, valence }))
        .collect::<Result<Vec<Spoke>>>()?;
    let mut folds = vec![];
    let mut neighbours = vec![];
    for (v, &(_, is_parent)) in members.iter().enumerate() {
        let (c, n) = (layout.corners[v], layout.sector_neighbours[v]);
        // Counter-clockwise about the tangent: as given for a daughter, reversed for the parent
        // (sector i lies between corners i and i + 1 either way).
        let (mut c, mut n) = if is_parent { ([c[0], c[3], c[2], c[1]], [n[3], n[2], n[1], n[0]]) } else { (c, n) };
        let d = directions[v];
        let across = |a: usize, b: usize| {
            let w = spokes[a].dir - spokes[b].dir;
            (w - d * w.dot(&d)).norm()
        };
        if across(c[0], c[2]) > across(c[1], c[3]) {
            c.rotate_left(1);
            n.rotate_left(1);
        }
        folds.push(c);
        neighbours.push(n);
    }
    let slots = members
        .iter()
        .zip(directions.iter().zip(radii))
        .map(|(&(branch, is_parent), (d, r))| JunctionSlot { branch, is_parent, direction: *d, angle: 0.0, radius: *r })
        .collect();
    Ok(JunctionGeometry {
        index,
        centre: x,
        radius: r_x,
        arrangement: Arrangement::Sectors { neighbours },
        slots,
        spokes,
        folds,
        core_scale: 1.0,
    })
}

/// Largest share of the way from a junction's centre to the wall that the boundary of a fold's
/// core may take once [`keep_fold_cores_inside`] has shrunk it.
const FOLD_CORE_REACH: f64 = 0.8;
/// Points sampled along each side of a page's half of the core's boundary.
const FOLD_CORE_SAMPLES: usize = 8;

/// Shrinks a junction's fold core (all its sectors' and spokes' core nodes, about the centre)
/// where its boundary would leave the lumen, until it lies within [`FOLD_CORE_REACH`] of the
/// wall; a junction whose core lies inside keeps it as it is. The core is placed by the spokes'
/// depths, each measured in one direction from the centre: between them, where the lumen of a
/// junction of many branches is not convex, a corner of the core can lie outside it, and its
/// rays then miss the wall (sphinxsys_aortic_arch, where the brachiocephalic trunk and two
/// arteries leave the arch within a radius of one another).
pub fn keep_fold_cores_inside(junctions: &mut [JunctionGeometry], core_size: f64, surface: &LumenSurface) {
    for g in junctions.iter_mut() {
        let n = FOLD_CORE_SAMPLES;
        let side = |i: usize| core_size * i as f64 / n as f64;
        // Half a fold's core boundary (x >= 0): its rim (x = core_size) and its two ends
        // (y = +-core_size).
        let boundary: Vec<(f64, f64)> = (0..=2 * n)
            .map(|i| (core_size, side(i) - core_size))
            .chain((0..n).flat_map(|i| [(side(i), core_size), (side(i), -core_size)]))
            .collect();
        let mut scale: f64 = 1.0;
        for fold in &g.folds {
            for u in [fold[0], fold[2]] {
                let u = &g.spokes[u];
                for &(x, y) in &boundary {
                    let v = &g.spokes[if y >= 0.0 { fold[1] } else { fold[3] }];
                    let offset = v.dir * (y.abs() * v.depth) + u.dir * (x * u.depth);
                    let distance = offset.norm();
                    if let Some(hit) = surface.first_hit(&g.centre, &(offset / distance), distance) {
                        scale = scale.min(FOLD_CORE_REACH * hit.distance / distance);
                    }
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
            for spoke in here.crotch_spokes(slot) {
                let p = &here.spokes[spoke];
                let along = (p.dir * p.depth).dot(&chord) / apart;
                if along <= apart {
                    continue;
                }
                let beside: Vec<&str> =
                    here.slots_at(spoke).iter().map(|&s| tree.branches[here.slots[s].branch].name.as_str()).collect();
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
                    "{}: {} and {} overlap: the crotch between {} lies {:.1} mm from the first junction's centre \
                     along {}, past the second junction ({:.1} mm away, where {} meet). {} has no length of its \
                     own on that side: {} (ending at {}) leaves from that crotch. Merged into one, such junctions \
                     mesh; these could not be (they still overlap after merging, or too many pairs do); with {} \
                     clipped from the surface and the centerlines, the two junctions no longer meet",
                    surface.source.display(),
                    here.describe(tree),
                    there.describe(tree),
                    beside.join(" and "),
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
}

impl FoldEnd {
    pub fn at(geometry: &JunctionGeometry, slot: usize, quarter_turns: u8) -> FoldEnd {
        FoldEnd { junction: geometry.index, slot, quarter_turns }
    }
}

/// The frame normal a branch must have at a junction's transition station for its template,
/// turned by q quarter turns, to lie on a fold whose +y spoke lies along `up` from its -y one
/// (a book's spine: x -> axis x tangent, y -> axis).
pub fn fold_normal(up: &Vector3<f64>, tangent: &Vector3<f64>, q: u8) -> Vector3<f64> {
    let a = (up - tangent * up.dot(tangent)).normalize();
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
    let me = &geometry.slots[slot];
    let mut length: f64 = geometry.radius + 0.5 * me.radius;
    for other in geometry.neighbours(slot) {
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
    let a = template.core_size;
    let curve = |xy: &Vector2<f64>| {
        let p0 = template.place(station, xy);
        let turned = turn(fold.quarter_turns, xy);
        let p1 = geometry.fold(fold.slot, &turned, a);
        let chord = (p1 - p0).norm();
        let t0 = towards_junction * chord;
        let t1 = geometry.arrival(fold.slot, &turned, a) * chord;
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

/// Where a node of a folded end section lies, the same for every slot that places it: the
/// centre, a spoke (at some core columns from the centre), or a sector between two spokes
/// (the lower-numbered first, with the node's columns along each).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum FoldPlace {
    Centre,
    Spoke { spoke: u32, along: u32 },
    Sector { first: u32, second: u32, along_first: u32, along_second: u32 },
}

/// Key of a node of a folded end section, the same for the slots sharing it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct FoldKey {
    pub junction: u32,
    pub place: FoldPlace,
    /// 0: the core node; 1..: ring levels (lumen, then wall) of the ray that starts there.
    pub level: u32,
}

impl FoldKey {
    /// The key of core grid node (i, j) of a slot's template (before turning) at ring level.
    /// Folds split the square core along its middle row and column.
    pub fn new(
        geometry: &JunctionGeometry,
        fold: &FoldEnd,
        template: &SectionTemplate,
        i: usize,
        j: usize,
        level: usize,
    ) -> FoldKey {
        let (ti, tj) = turn_core_index(template.nx, template.ny, fold.quarter_turns, i, j);
        let half = (template.nx / 2) as isize;
        let (dx, dy) = (ti as isize - half, tj as isize - half);
        let f = &geometry.folds[fold.slot];
        let (u, v) = (if dx >= 0 { f[0] } else { f[2] } as u32, if dy >= 0 { f[1] } else { f[3] } as u32);
        let (along_u, along_v) = (dx.unsigned_abs() as u32, dy.unsigned_abs() as u32);
        let place = match (along_u, along_v) {
            (0, 0) => FoldPlace::Centre,
            (0, along) => FoldPlace::Spoke { spoke: v, along },
            (along, 0) => FoldPlace::Spoke { spoke: u, along },
            _ if u < v => FoldPlace::Sector { first: u, second: v, along_first: along_u, along_second: along_v },
            _ => FoldPlace::Sector { first: v, second: u, along_first: along_v, along_second: along_u },
        };
        FoldKey { junction: geometry.index as u32, place, level: level as u32 }
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
        let (axis, gap, acceptable) = spine_axis(&dirs);
        assert!(acceptable);
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
        let (axis, gap, acceptable) = spine_axis(&dirs);
        assert!(acceptable);
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

    /// A book of three slots about the z axis (the parent at 0 degrees, daughters at 120 and
    /// 240), pages at 60, 180 and 300 degrees of depths 2, 3 and 4, the spine 2.5 up and 1.5
    /// down.
    fn three_pages() -> JunctionGeometry {
        let at = |deg: f64| Vector3::new(deg.to_radians().cos(), deg.to_radians().sin(), 0.0);
        let slot = |branch: usize, angle_deg: f64| JunctionSlot {
            branch,
            is_parent: branch == 0,
            direction: at(angle_deg),
            angle: angle_deg.to_radians(),
            radius: 1.0,
        };
        let spoke = |dir: Vector3<f64>, depth: f64, valence: usize| Spoke { dir, depth, valence };
        let spokes = vec![
            spoke(Vector3::z(), 2.5, 3),
            spoke(-Vector3::z(), 1.5, 3),
            spoke(at(60.0), 2.0, 2),
            spoke(at(180.0), 3.0, 2),
            spoke(at(300.0), 4.0, 2),
        ];
        JunctionGeometry {
            index: 0,
            centre: Point3::origin(),
            radius: 2.0,
            arrangement: Arrangement::Book {
                axis: Vector3::z(),
                reference: Vector3::x(),
                page_angles: vec![60f64.to_radians(), 180f64.to_radians(), 300f64.to_radians()],
            },
            slots: vec![slot(0, 0.0), slot(1, 120.0), slot(2, 240.0)],
            spokes,
            // The parent's +x is its clockwise page (page 2), a daughter's its counter-clockwise one.
            folds: vec![[4, 0, 2, 1], [3, 0, 2, 1], [4, 0, 3, 1]],
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
        g.spokes.iter_mut().for_each(|s| s.depth = 2.0);
        let mut wide = [g.clone()];
        keep_fold_cores_inside(&mut wide, 0.8, &surface);
        assert!((wide[0].core_scale - 0.5_f64.sqrt()).abs() < 0.01, "scale {}", wide[0].core_scale);
        let mut narrow = [g.clone()];
        keep_fold_cores_inside(&mut narrow, 0.6, &surface);
        assert_eq!(narrow[0].core_scale, 1.0);

        let (corner, target) = (Vector2::new(0.8, 0.8), Vector2::new(1.6, 1.6));
        let out = |g: &JunctionGeometry, p: &Vector2<f64>| g.fold(1, p, 0.8) - g.centre;
        let s = wide[0].core_scale;
        assert!((out(&wide[0], &corner) - out(&g, &corner) * s).norm() < 1e-12, "the core scales");
        assert!((out(&wide[0], &target) - out(&g, &target)).norm() < 1e-12, "the targets stay");
        assert!(out(&wide[0], &corner).norm() < 0.81 * 2.0, "the corner lies inside the dome");
    }

    /// Every slot that places a node of a fold places it at the same point under the same key,
    /// and every sector node is placed by exactly the two slots sharing its sector.
    fn assert_folds_agree(g: &JunctionGeometry) {
        let template = SectionTemplate::new(8, 0.5, 2.0);
        let mut placed: std::collections::HashMap<FoldKey, Vec<(usize, Point3<f64>)>> = Default::default();
        for slot in 0..g.slots.len() {
            for q in [0u8, 1] {
                let fold = FoldEnd::at(g, slot, q);
                for j in 0..=8 {
                    for i in 0..=8 {
                        let key = FoldKey::new(g, &fold, &template, i, j, 0);
                        let p = g.fold(slot, &turn(q, &template.core[j * 9 + i]), 0.5);
                        let seen = placed.entry(key).or_default();
                        if let Some(&(_, first)) = seen.first() {
                            assert!((p - first).norm() < 1e-12, "{key:?}: {p} vs {first}");
                        }
                        if q == 0 {
                            seen.push((slot, p));
                        }
                    }
                }
            }
        }
        for (key, by) in &placed {
            if let FoldPlace::Sector { .. } = key.place {
                let mut slots: Vec<usize> = by.iter().map(|b| b.0).collect();
                slots.dedup();
                assert_eq!(slots.len(), 2, "sector node {key:?} placed by {slots:?}");
            }
        }
    }

    #[test]
    fn a_books_pages_are_shared_by_the_slots_beside_them() {
        let g = three_pages();
        assert_folds_agree(&g);
        // The spine's core nodes are every slot's, a page's two slots'.
        assert_eq!(g.slots_at(0), vec![0, 1, 2]);
        assert_eq!(g.slots_at(2), vec![0, 1], "page 0 lies between slots 0 and 1");
    }

    /// Six branches along the axes, laid out in sectors about the cube's corners (no spine).
    #[test]
    fn sectors_of_six_branches_are_shared_by_the_slots_beside_them() {
        let dirs = [-Vector3::z(), Vector3::x(), -Vector3::x(), Vector3::y(), -Vector3::y(), Vector3::z()];
        let layout = layout::sector_layout(&dirs, &[1.0; 6]).unwrap();
        let surface = LumenSurface::new(&crate::testing::straight_tube_surface(3.0, 20.0, 48, 20)).unwrap();
        let members: Vec<(usize, bool)> = (0..6).map(|b| (b, b == 0)).collect();
        let centre = Point3::new(0.0, 0.0, 10.0);
        let g =
            sectors_geometry(0, centre, 2.0, &members, &dirs, &[1.0; 6], &layout, &surface, &|| "x".into()).unwrap();
        assert_folds_agree(&g);
        for slot in 0..6 {
            // Counter-clockwise about the tangent (out of the centre for a daughter, into it
            // for the parent).
            let f = g.folds[slot];
            let t = if slot == 0 { -dirs[0] } else { dirs[slot] };
            let (x, y) = (g.spokes[f[0]].dir, g.spokes[f[1]].dir);
            assert!(x.cross(&y).dot(&t) > 0.0, "slot {slot}: +x then +y turn counter-clockwise");
            assert_eq!(g.neighbours(slot).len(), 4, "each face of a cube has four neighbours");
        }
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
