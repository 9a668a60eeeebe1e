//! Drawing a tree: the tree-level draws, the root, then places (daughters leaving a host) added
//! one at a time until the tree has its ends (see the module documentation of
//! [`crate::synthetic_tree`] for the distributions).

use super::centerline::{direction_from, insert_sample, sample_at, PathBuilder, Sample};
use super::model::{vessel_pieces, Finish, Piece, PieceIndex, Place, Sac, Vessel};
use super::rng::SeededRng;
use nalgebra::{Point3, Vector3};

/// Grid cells per smallest lumen radius of a tree (the radius of its thinnest vessel or
/// stenosis throat): the voxel size of the segmentation the tree stands for.
pub const CELLS_PER_SMALLEST_RADIUS: f64 = 3.5;
/// Surface area budget of a tree, in grid cells² (about 3 triangles per cell²: 270,000).
pub const AREA_BUDGET_CELLS: f64 = 90_000.0;
/// Largest share of the area budget the root may take.
pub const ROOT_SHARE: f64 = 0.55;
/// Smallest gap between two vessel walls that do not blend, in cells (a segmentation cannot
/// keep two vessels apart closer than about two voxels).
pub const GAP_MIN_CELLS: f64 = 2.0;
/// How far each free end's tube continues past its end plane before the cut, in cells.
pub const EXTENSION_CELLS: f64 = 4.0;
/// Branches at one place: 3 to 8, with these weights.
pub const BRANCH_WEIGHTS: [f64; 6] = [0.40, 0.20, 0.13, 0.10, 0.09, 0.08];

/// The tree-level draws (recorded in the manifest).
#[derive(Debug, Clone, PartialEq)]
pub struct TreeDraws {
    pub target_ends: usize,
    /// Largest / smallest radius allowed in the tree (the root's start radius over the floor).
    pub radius_range: f64,
    /// Smallest radius of any lumen of the tree, mm.
    pub smallest_radius: f64,
    /// "open", "capped" or "mixed" (each end capped with probability 1/2).
    pub end_style: &'static str,
    pub stenoses: usize,
    /// Area reduction of each stenosis drawn, fraction in [0.5, 0.9].
    pub stenosis_areas: Vec<f64>,
    pub aneurysms: usize,
    pub near_passes: usize,
}

impl TreeDraws {
    pub fn draw(rng: &mut SeededRng) -> Self {
        let target_ends = if rng.chance(0.05) { 2 } else { (rng.log_range(3.0, 41.0).floor() as usize).clamp(3, 40) };
        let radius_range = rng.log_range(1.5, 7.0);
        let smallest_radius = rng.log_range(0.3, 15.0 / radius_range);
        let end_style = ["open", "capped", "mixed"][rng.weighted(&[0.5, 0.3, 0.2])];
        let stenoses = rng.weighted(&[0.35, 0.35, 0.2, 0.1]);
        let stenosis_areas = (0..stenoses).map(|_| rng.range(0.5, 0.9)).collect();
        let aneurysms = rng.weighted(&[0.5, 0.35, 0.15]);
        let near_passes = rng.weighted(&[0.3, 0.4, 0.2, 0.1]);
        TreeDraws {
            target_ends,
            radius_range,
            smallest_radius,
            end_style,
            stenoses,
            stenosis_areas,
            aneurysms,
            near_passes,
        }
    }
}

/// A stenosis: the radius reduced by a raised-cosine notch, the centerline shifted towards the
/// spared wall by `eccentricity` of the lost radius.
#[derive(Debug, Clone, PartialEq)]
pub struct Stenosis {
    pub vessel: usize,
    pub s: f64,
    pub half_length: f64,
    /// Lumen area lost at the throat, fraction.
    pub area_reduction: f64,
    pub eccentricity: f64,
    /// Unit direction of the spared wall.
    pub spared: Vector3<f64>,
    pub throat_radius: f64,
}

/// A hairpin bend: the centerline turns by `angle` over `length` (an arc).
#[derive(Debug, Clone, PartialEq)]
pub struct Hairpin {
    pub vessel: usize,
    pub s: f64,
    pub length: f64,
    pub angle: f64,
    pub radius: f64,
}

/// A near pass steered on purpose: vessel `vessel` passes vessel `other` at `gap` (wall to
/// wall) at `point` on its centerline.
#[derive(Debug, Clone, PartialEq)]
pub struct SteeredPass {
    pub vessel: usize,
    pub other: usize,
    pub gap: f64,
    pub crossing_angle: f64,
}

/// A tree being drawn, then drawn.
#[derive(Debug, Clone)]
pub struct Layout {
    pub draws: TreeDraws,
    /// Grid cell, smallest gap between walls that do not blend, extension past free ends, mm.
    pub h: f64,
    pub gap_min: f64,
    pub extension: f64,
    pub vessels: Vec<Vessel>,
    pub places: Vec<Place>,
    pub sacs: Vec<Sac>,
    pub stenoses: Vec<Stenosis>,
    pub hairpins: Vec<Hairpin>,
    pub steered: Vec<SteeredPass>,
    /// Whether the inlet is capped, and each vessel's free end.
    pub inlet_capped: bool,
    pub end_capped: Vec<bool>,
    pub index: PieceIndex,
    /// Surface area laid so far (tubes only), mm².
    pub area: f64,
    /// Places drawn but not laid (no host could take them without a clash), for the manifest.
    pub places_refused: usize,
}

/// One drawn place: everything but where it goes.
#[derive(Debug, Clone)]
pub struct PlaceSpec {
    pub terminal: bool,
    /// Distance from each anchor to the next, in host radii.
    pub spacings: Vec<f64>,
    /// Per daughter: u in [0, 1) mapped to a radius ratio over what the host allows, branch
    /// angle and out-of-plane angle (radians; the first daughter's is 0), hairpin, steered.
    pub ratio_draws: Vec<f64>,
    pub angles: Vec<f64>,
    pub out_of_plane: Vec<f64>,
    pub hairpins: Vec<bool>,
    pub steer: Vec<bool>,
}

impl PlaceSpec {
    /// A place adding at most `room` ends.
    pub fn draw(rng: &mut SeededRng, room: usize, steer_left: usize) -> Self {
        let mut branches = 3 + rng.weighted(&BRANCH_WEIGHTS);
        branches = branches.min(room + 2);
        let terminal = rng.chance(0.4);
        let daughters = if terminal { branches - 1 } else { branches - 2 };
        let spacings = (1..daughters).map(|_| if rng.chance(0.15) { 0.0 } else { rng.range(0.3, 3.0) }).collect();
        let mut ratio_draws = Vec::new();
        let mut angles = Vec::new();
        let mut out_of_plane = Vec::new();
        for i in 0..daughters {
            // The main continuation of a terminal place is at least 0.6 of its host.
            ratio_draws.push(if terminal && i == 0 { -rng.range(0.6, 1.0) } else { rng.uniform() });
            let alpha = if i == 0 { 0.0 } else { rng.range(0.0, 90.0) };
            let theta = rng.range(15f64.max(alpha), 170f64.min(180.0 - alpha));
            angles.push(theta.to_radians());
            out_of_plane.push(alpha.to_radians());
        }
        let hairpins = (0..daughters).map(|_| rng.chance(0.12)).collect();
        let steer = (0..daughters).map(|i| i < steer_left && rng.chance(0.5)).collect();
        PlaceSpec { terminal, spacings, ratio_draws, angles, out_of_plane, hairpins, steer }
    }

    pub fn branches(&self) -> usize {
        self.angles.len() + if self.terminal { 1 } else { 2 }
    }

    /// Radius ratio of daughter `i` on a host of radius `host` in a tree whose floor is
    /// `floor`: uniform over [max(0.15, floor / host), 1].
    pub fn ratio(&self, i: usize, host: f64, floor: f64) -> f64 {
        let lo = (floor / host).max(0.15).min(1.0);
        let u = self.ratio_draws[i];
        if u < 0.0 {
            (-u).max(lo)
        } else {
            lo + u * (1.0 - lo)
        }
    }
}

impl Layout {
    pub fn new(draws: TreeDraws) -> Self {
        let h = draws.smallest_radius / CELLS_PER_SMALLEST_RADIUS;
        Layout {
            h,
            gap_min: GAP_MIN_CELLS * h,
            extension: EXTENSION_CELLS * h,
            vessels: Vec::new(),
            places: Vec::new(),
            sacs: Vec::new(),
            stenoses: Vec::new(),
            hairpins: Vec::new(),
            steered: Vec::new(),
            inlet_capped: false,
            end_capped: Vec::new(),
            index: PieceIndex::new(4.0 * draws.smallest_radius * draws.radius_range.sqrt()),
            area: 0.0,
            places_refused: 0,
            draws,
        }
    }

    pub fn floor(&self) -> f64 {
        self.draws.smallest_radius
    }

    pub fn area_budget(&self) -> f64 {
        AREA_BUDGET_CELLS * self.h * self.h
    }

    /// Free ends so far: the inlet and every vessel's free end.
    pub fn end_count(&self) -> usize {
        1 + self.vessels.iter().filter(|v| v.finish == Finish::Free).count()
    }

    /// Whether a new free end is capped, by the tree's end style.
    pub fn draw_capped(&self, rng: &mut SeededRng) -> bool {
        match self.draws.end_style {
            "capped" => true,
            "mixed" => rng.chance(0.5),
            _ => false,
        }
    }

    /// The root: from the inlet at the origin, in a direction uniform over the sphere, a
    /// straight stretch of 2 radii, a tortuous body of 6 to 14 radii (within [`ROOT_SHARE`] of
    /// the area budget), a straight stretch of 2 radii to its end.
    pub fn lay_root(&mut self, rng: &mut SeededRng) {
        let radius = self.floor() * self.draws.radius_range;
        let rotation = rng.rotation();
        let (t, n) = (rotation * Vector3::z(), rotation * Vector3::x());
        let mut b = PathBuilder::new(Point3::origin(), t, n, radius, radius);
        b.straight(2.0 * radius);
        let max_body = ROOT_SHARE * self.area_budget() / (std::f64::consts::TAU * radius) - 4.0 * radius;
        let body_length = (rng.range(6.0, 14.0) * radius).min(max_body).max(3.0 * radius);
        let tortuosity = rng.uniform();
        let taper = rng.range(0.0, 0.3);
        let hairpin = rng.chance(0.2);
        let body_start = b.length();
        let bend = tortuous_body(rng, &mut b, radius, body_length, tortuosity, hairpin);
        let body_end = b.length();
        b.straight(2.0 * radius);
        let floor = self.floor();
        let samples = b.finish(|s| taper_profile(s, body_start, body_end, radius, taper, floor));
        self.inlet_capped = self.draw_capped(rng);
        let capped = self.draw_capped(rng);
        let vessel = Vessel {
            parent: None,
            place: None,
            samples,
            finish: Finish::Free,
            zone: None,
            radius0: radius,
            taper,
            tortuosity,
            body: (body_start + radius, body_end),
            busy: Vec::new(),
            reach: 0.0,
        };
        let id = self.commit_vessel(vessel, capped, bend);
        self.stenosis_on_new_vessel(rng, id);
    }

    /// Adds a vessel (its pieces to the index, its area, its hairpin).
    pub fn commit_vessel(&mut self, mut vessel: Vessel, capped: bool, hairpin: Option<Hairpin>) -> usize {
        let id = self.vessels.len();
        for piece in vessel_pieces(id, &vessel.samples) {
            self.index.insert(piece);
        }
        self.area += tube_area(&vessel.samples);
        if let Some(mut bend) = hairpin {
            bend.vessel = id;
            vessel.busy.push((bend.s - bend.radius, bend.s + bend.length + bend.radius));
            self.hairpins.push(bend);
        }
        self.vessels.push(vessel);
        self.end_capped.push(capped);
        id
    }

    /// Adds places until the tree has its ends, the area budget is spent, or 30 drawn places in
    /// a row found no host (each tried at 8 positions).
    pub fn grow(&mut self, rng: &mut SeededRng) {
        let mut refused_in_a_row = 0;
        while self.end_count() < self.draws.target_ends && refused_in_a_row < 30 && self.area < self.area_budget() {
            let steer_left = self.draws.near_passes.saturating_sub(self.steered.len());
            let spec = PlaceSpec::draw(rng, self.draws.target_ends - self.end_count(), steer_left);
            if (0..8).any(|_| self.try_place(rng, &spec)) {
                refused_in_a_row = 0;
            } else {
                refused_in_a_row += 1;
                self.places_refused += 1;
            }
        }
    }

    /// Lays `spec` on a host drawn by radius, at a free position, with its daughters; undoes
    /// everything and returns false on a clash.
    fn try_place(&mut self, rng: &mut SeededRng, spec: &PlaceSpec) -> bool {
        let weights: Vec<f64> = self
            .vessels
            .iter()
            .map(|v| if spec.terminal && v.finish != Finish::Free { 0.0 } else { v.radius0 })
            .collect();
        if weights.iter().all(|w| *w == 0.0) {
            return false;
        }
        let host = rng.weighted(&weights);
        let span_radii: f64 = spec.spacings.iter().sum();
        let r_host = self.vessels[host].radius0;
        let u = rng.uniform();
        let first = if spec.terminal {
            let v = &self.vessels[host];
            let last = v.body.1;
            let first = last - span_radii * r_host;
            let clear = first - r_host >= v.body.0 && v.busy.iter().all(|(a, b)| *b <= first - r_host || *a >= last);
            if !clear {
                return false;
            }
            first
        } else {
            match self.vessels[host].free_position(span_radii * r_host, r_host, u) {
                Some(s) => s,
                None => return false,
            }
        };
        let host_radius = sample_at(&self.vessels[host].samples, first).r;
        let mut anchors = vec![first];
        for d in &spec.spacings {
            anchors.push(anchors.last().copied().unwrap_or(first) + d * host_radius);
        }
        if spec.terminal {
            // The host ends exactly at the last anchor.
            let end = self.vessels[host].body.1;
            let shift = end - anchors.last().copied().unwrap_or(end);
            anchors.iter_mut().for_each(|a| *a += shift);
        }
        // The place's least area (each daughter's junction stretch and five radii) must fit in
        // what is left of the budget.
        let least: f64 = (0..anchors.len())
            .map(|i| {
                let r_host = sample_at(&self.vessels[host].samples, anchors[i]).r;
                let r = (spec.ratio(i, r_host, self.floor()) * r_host).max(self.floor());
                let stretch = (r_host + r + self.blend_width(r) + self.gap_min) / spec.angles[i].sin().max(0.2) + r;
                std::f64::consts::TAU * r * (stretch + 5.0 * r)
            })
            .sum();
        if self.area + least > self.area_budget() {
            return false;
        }
        let saved = (
            self.vessels.len(),
            self.vessels[host].clone(),
            self.index.clone(),
            self.area,
            self.hairpins.len(),
            self.stenoses.len(),
        );
        let place = self.places.len();
        if spec.terminal {
            self.truncate_host(host, *anchors.last().unwrap_or(&first));
            self.vessels[host].finish = Finish::Place(place);
        }
        let frame = sample_at(&self.vessels[host].samples, anchors[0]);
        let azimuth0 = rng.range(0.0, std::f64::consts::TAU);
        let mut daughters = Vec::new();
        for (i, &s) in anchors.iter().enumerate() {
            let anchor = sample_at(&self.vessels[host].samples, s);
            let azimuth = azimuth0 + azimuth_offset(rng, spec.angles[i], spec.out_of_plane[i]);
            let direction = direction_from(&frame.t, &frame.n, spec.angles[i], azimuth);
            let radius = (spec.ratio(i, anchor.r, self.floor()) * anchor.r).max(self.floor());
            let laid = self.lay_daughter(rng, host, place, &anchor, direction, radius, &daughters, spec, i);
            match laid {
                Some(id) => daughters.push(id),
                None => {
                    let (count, host_vessel, index, area, hairpins, stenoses) = saved;
                    self.vessels.truncate(count);
                    self.end_capped.truncate(count);
                    self.vessels[host] = host_vessel;
                    self.index = index;
                    self.area = area;
                    self.hairpins.truncate(hairpins);
                    self.stenoses.truncate(stenoses);
                    self.steered.retain(|p| p.vessel < count);
                    return false;
                }
            }
        }
        let v = &mut self.vessels[host];
        for &s in &anchors {
            insert_sample(&mut v.samples, s);
        }
        let last = *anchors.last().unwrap_or(&first);
        v.busy.push((anchors[0] - host_radius, last + host_radius));
        if spec.terminal {
            v.finish = Finish::Place(place);
            v.body.1 = anchors[0] - host_radius;
        }
        self.places.push(Place { host, terminal: spec.terminal, daughters, anchors });
        true
    }

    /// Cuts the host's centerline at `s` (its end now a junction): its pieces past `s` leave the
    /// index, its free end's area goes.
    fn truncate_host(&mut self, host: usize, s: f64) {
        let v = &mut self.vessels[host];
        let before = tube_area(&v.samples);
        let i = insert_sample(&mut v.samples, s);
        v.samples.truncate(i + 1);
        self.area += tube_area(&v.samples) - before;
        self.index.kill(host, false);
        for piece in vessel_pieces(host, &self.vessels[host].samples) {
            self.index.insert(piece);
        }
    }

    /// The pieces of every free end's clip guard: from 3 cells before the end plane to the end of
    /// the tube's extension and its rounded tip past it, with the end's radius.
    pub fn end_guards(&self) -> Vec<(usize, Piece)> {
        let mut out = Vec::new();
        for (id, v) in self.vessels.iter().enumerate() {
            if id == 0 {
                let q = v.first();
                out.push((id, self.guard(id, q, -1.0)));
            }
            if v.finish == Finish::Free {
                out.push((id, self.guard(id, v.last(), 1.0)));
            }
        }
        out
    }

    /// The clip guard of the end at `q` facing `sign × q.t`.
    pub fn guard(&self, comp: usize, q: &Sample, sign: f64) -> Piece {
        let n = q.t * sign;
        let back = 3.0 * self.h;
        let front = self.extension + q.r + 2.0 * self.h;
        Piece { comp, a: q.p - n * back, b: q.p + n * front, ra: q.r, rb: q.r, sa: q.s, sb: q.s }
    }
}

/// Tortuous pieces of `length` (arcs of 1.5 to 4 radii turning up to `tortuosity` × 75°,
/// towards a random side, no tighter than 1.5 radii), with a hairpin somewhere along when
/// `hairpin` (60° to 130° within 1.2 θ to 3 radii, straight radius-long stretches either
/// side). Returns the hairpin laid.
pub fn tortuous_body(
    rng: &mut SeededRng,
    b: &mut PathBuilder,
    radius: f64,
    length: f64,
    tortuosity: f64,
    hairpin: bool,
) -> Option<Hairpin> {
    let start = b.length();
    let mut bend_at = if hairpin { Some(start + rng.range(0.1, 0.6) * length) } else { None };
    let mut laid = None;
    while b.length() < start + length {
        if bend_at.is_some_and(|at| b.length() >= at) {
            bend_at = None;
            let angle = rng.range(60.0f64, 130.0).to_radians();
            let arc = rng.range((super::centerline::HAIRPIN_MIN_CURVATURE_RADII * angle).max(1.5), 3.0) * radius;
            b.straight(radius);
            let s = b.length();
            let last = *b.last();
            let side = rng.perpendicular(&last.t, &last.n);
            b.arc(arc, angle, &side);
            laid = Some(Hairpin { vessel: 0, s, length: arc, angle, radius: arc / angle });
            b.straight(radius);
            continue;
        }
        let piece = rng.range(1.5, 4.0) * radius;
        let max_turn = piece / (super::centerline::MIN_CURVATURE_RADII * radius);
        let turn = (rng.range(0.0, 75.0 * tortuosity).to_radians()).min(max_turn);
        let last = *b.last();
        let side = rng.perpendicular(&last.t, &last.n);
        b.arc(piece, turn, &side);
    }
    laid
}

/// Radius along a vessel: `radius` to `body_start`, then linearly down by `taper` to
/// `body_end`, constant after (never below `floor`).
pub fn taper_profile(s: f64, body_start: f64, body_end: f64, radius: f64, taper: f64, floor: f64) -> f64 {
    let x = if body_end > body_start { ((s - body_start) / (body_end - body_start)).clamp(0.0, 1.0) } else { 0.0 };
    (radius * (1.0 - taper * x)).max(floor)
}

/// Lateral area of the tube of a sampled centerline (frustums), mm².
pub fn tube_area(samples: &[Sample]) -> f64 {
    samples.windows(2).map(|w| std::f64::consts::PI * (w[0].r + w[1].r) * (w[1].p - w[0].p).norm()).sum()
}

/// Azimuth of a daughter from the place's first one so that its out-of-plane angle from the
/// plane of the host's axis and the first daughter is `alpha` at branch angle `theta`:
/// |sin Δ| = sin α / sin θ, on a random one of the four sides.
fn azimuth_offset(rng: &mut SeededRng, theta: f64, alpha: f64) -> f64 {
    let base = (alpha.sin() / theta.sin().max(1e-12)).clamp(-1.0, 1.0).asin();
    match rng.index(4) {
        0 => base,
        1 => -base,
        2 => std::f64::consts::PI - base,
        _ => std::f64::consts::PI + base,
    }
}
