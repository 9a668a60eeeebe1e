//! Laying one daughter: its straight stretch out of the junction, its body (tortuous, with a
//! hairpin, or steered past another vessel for a near pass), its straight end, the zone where it
//! blends with its host and siblings, and the clearance checks that keep every other pair of
//! walls apart.

use super::centerline::{sample_at, PathBuilder, Sample};
use super::layout::{taper_profile, tortuous_body, Hairpin, Layout, PlaceSpec, SteeredPass};
use super::model::{vessel_pieces, Finish, Piece, Vessel, Zone};
use super::rng::SeededRng;
use super::separation::junction_reach;
use nalgebra::Vector3;

/// Blend widths of a junction in cells, at least and at most: the cubic blend fuses walls
/// closer than a third of its width, so at 6 cells every gap within a junction is either fused
/// or at least the two cells the grid resolves (a segmentation at this voxel size fuses them
/// too).
pub const BLEND_CELLS: (f64, f64) = (6.0, 8.0);
/// Blend width of a sac's neck in cells, at least and at most.
pub const NECK_BLEND_CELLS: (f64, f64) = (2.5, 6.0);
/// Body length of a daughter, in its radii (before the area budget).
const BODY_RADII: (f64, f64) = (4.0, 12.0);
/// Longest straight stretch out of a junction, in (host + daughter) radii: a daughter that needs
/// more to clear its host and siblings runs along them, and is drawn again.
const MAX_JUNCTION_STRETCH: f64 = 8.0;

impl Layout {
    /// Blend width of a daughter of radius `r`: r / 2 within [`BLEND_CELLS`].
    pub fn blend_width(&self, r: f64) -> f64 {
        (0.5 * r).clamp(BLEND_CELLS.0 * self.h, BLEND_CELLS.1 * self.h)
    }

    /// Lays daughter `i` of `spec` from `anchor` on `host` along `direction`; tries four bodies.
    /// Returns its id, or `None` when each clashes.
    #[allow(clippy::too_many_arguments)]
    pub fn lay_daughter(
        &mut self,
        rng: &mut SeededRng,
        host: usize,
        place: usize,
        anchor: &Sample,
        direction: Vector3<f64>,
        radius: f64,
        siblings: &[usize],
        spec: &PlaceSpec,
        i: usize,
    ) -> Option<usize> {
        let k = self.blend_width(radius);
        let stretch = self.junction_stretch(anchor, &direction, radius, k, siblings)?;
        let reach = junction_reach(anchor.r, radius, k, self.gap_min, direction.angle(&anchor.t));
        let mut partners = vec![host];
        partners.extend_from_slice(siblings);
        let taper = rng.range(0.0, 0.3);
        let tortuosity = rng.uniform();
        let capped = self.draw_capped(rng);
        for body_try in 0..4 {
            let normal =
                rng.perpendicular(&direction, &anchor.t.cross(&direction).try_normalize(1e-9).unwrap_or(anchor.n));
            let mut b = PathBuilder::new(anchor.p, direction, normal, radius, radius);
            b.straight(stretch);
            let body_start = b.length();
            let left = (self.area_budget() - self.area).max(0.0)
                / self.draws.target_ends.saturating_sub(self.end_count()).max(1) as f64;
            let budget_length = left / (std::f64::consts::TAU * radius) - stretch - 2.0 * radius;
            let length = (rng.range(BODY_RADII.0, BODY_RADII.1) * radius).min(budget_length).max(3.0 * radius);
            let mut steered = None;
            let mut bend = None;
            // Two tries steered past a neighbour, two plain (a steer that clashes does not sink
            // the place).
            if spec.steer[i] && body_try < 2 {
                steered = self.steer_body(rng, &mut b, radius, &partners);
            }
            if steered.is_none() {
                bend = tortuous_body(rng, &mut b, radius, length, tortuosity, spec.hairpins[i]);
            }
            let body_end = b.length();
            b.straight(2.0 * radius);
            let floor = self.floor();
            let samples = b.finish(|s| taper_profile(s, body_start, body_end, radius, taper, floor));
            let id = self.vessels.len();
            let bound = stretch.min(reach);
            let Some(zone) = self.contact_zone(id, &samples, &partners, k, bound, anchor) else { continue };
            let body = (zone_end(&samples, &zone).max(stretch) + radius, body_end);
            let vessel = Vessel {
                parent: Some(host),
                place: Some(place),
                samples,
                finish: Finish::Free,
                zone: Some(zone),
                radius0: radius,
                taper,
                tortuosity,
                body,
                busy: Vec::new(),
                reach,
            };
            if !self.clear(id, &vessel) {
                continue;
            }
            if let Some(mut pass) = steered {
                pass.vessel = id;
                self.steered.push(pass);
            }
            let id = self.commit_vessel(vessel, capped, bend);
            self.stenosis_on_new_vessel(rng, id);
            return Some(id);
        }
        None
    }

    /// Length of the straight stretch out of the junction: far enough for the daughter's wall
    /// to clear its host's and its siblings' by the blend and the gap, at its branch angle from
    /// each (at least a tenth of a turn's sine), plus a radius; `None` past
    /// [`MAX_JUNCTION_STRETCH`].
    fn junction_stretch(
        &self,
        anchor: &Sample,
        direction: &Vector3<f64>,
        radius: f64,
        k: f64,
        siblings: &[usize],
    ) -> Option<f64> {
        let clearance = |other: f64, sine: f64| (other + radius + k + self.gap_min) / sine.max(0.2);
        let mut stretch = clearance(anchor.r, anchor.t.cross(direction).norm());
        for &u in siblings {
            let first = self.vessels[u].first();
            let apart = (first.p - anchor.p).norm();
            stretch = stretch.max(clearance(first.r, first.t.cross(direction).norm()) + apart);
        }
        let stretch = stretch + radius;
        (stretch <= MAX_JUNCTION_STRETCH * (anchor.r + radius)).then_some(stretch)
    }

    /// The daughter's blend zone: the segment from its anchor to the last point of its
    /// centerline whose wall comes within the blend and the gap of a partner's; `None` when that
    /// point lies past `reach_along` along it (the straight stretch out of the junction, and never
    /// past its junction reach: the daughter runs along a partner, or comes back to it), when
    /// the point it comes that close to lies more than `reach_along` along its host from the anchor or
    /// past a sibling's own junction reach (it runs along the host, or along a sibling that has
    /// left the junction), when it touches a sibling after having parted from it
    /// somewhere outside their host's lumen, or its host at places not joined along the host
    /// to its anchor (across a bend): each would close a loop around a hole (a handle).
    fn contact_zone(
        &self,
        id: usize,
        samples: &[Sample],
        partners: &[usize],
        k: f64,
        reach_along: f64,
        anchor: &Sample,
    ) -> Option<Zone> {
        let reach = self.gap_min + k;
        let host = partners[0];
        let mut last_contact: f64 = 0.0;
        let mut on_host = vec![anchor.s];
        // Walls closer than a third of the blend width are fused. Along the daughter and along
        // each sibling, fused contacts out of the host's lumen must follow on from the start
        // without a break (a break is an open hole between them).
        let fused = k / 3.0;
        let mut parted = vec![false; partners.len()];
        let mut along_sibling: Vec<Vec<(f64, bool)>> = vec![Vec::new(); partners.len()];
        for piece in vessel_pieces(id, samples) {
            let mut nearest = vec![f64::INFINITY; partners.len()];
            let mut wall = vec![piece.a; partners.len()];
            for j in self.index.near(&piece, reach) {
                let other = &self.index.pieces[j as usize];
                if let Some(slot) = partners.iter().position(|&p| p == other.comp) {
                    let c = piece.gap_to(other);
                    if c.gap < nearest[slot] {
                        nearest[slot] = c.gap;
                        wall[slot] = c.wall_point();
                    }
                    if c.gap < reach {
                        last_contact = last_contact.max(c.sp);
                        let beyond = if slot == 0 {
                            (c.sq - anchor.s).abs() > reach_along
                        } else {
                            c.sq > self.vessels[other.comp].reach
                        };
                        if beyond {
                            return None;
                        }
                        if slot == 0 {
                            on_host.push(c.sq);
                        }
                    }
                    if slot > 0 && c.gap < fused {
                        along_sibling[slot].push((c.sq, !self.within_host(host, &c.wall_point())));
                    }
                }
            }
            for (slot, gap) in nearest.iter().enumerate().skip(1) {
                if *gap >= fused {
                    parted[slot] = true;
                } else if parted[slot] && !self.within_host(host, &wall[slot]) {
                    return None;
                }
            }
        }
        for (slot, contacts) in along_sibling.iter_mut().enumerate().skip(1) {
            let r_sibling = self.vessels[partners[slot]].radius0;
            contacts.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut reached = r_sibling + fused;
            for &(s, outside) in contacts.iter() {
                if outside && s > reached {
                    return None;
                }
                reached = reached.max(s + 2.0 * samples[0].r + r_sibling);
            }
        }
        let radius = samples[0].r;
        if last_contact > reach_along {
            return None;
        }
        // The host's wall it touches: one stretch along the host around the anchor (contact
        // points at most two daughter radii plus the host's radius apart).
        on_host.sort_by(f64::total_cmp);
        if on_host.windows(2).any(|w| w[1] - w[0] > 2.0 * radius + anchor.r) {
            return None;
        }
        let inner = radius + k + self.gap_min;
        Some(Zone {
            a: samples[0].p,
            b: sample_at(samples, last_contact.max(0.5 * radius)).p,
            inner,
            outer: inner + radius.max(2.0 * self.h),
            k,
            partners: partners.to_vec(),
        })
    }

    /// Whether a new vessel `id` keeps clear of everything laid (see [`Layout::clear_pieces`]),
    /// its free end's guard clear of every other wall, and its zone clear of every end.
    pub fn clear(&self, id: usize, v: &Vessel) -> bool {
        let mut pieces = vessel_pieces(id, &v.samples);
        let last = v.last();
        pieces.push(Piece {
            a: last.p,
            b: last.p + last.t * self.extension,
            sa: last.s,
            sb: last.s + self.extension,
            ..pieces[pieces.len() - 1]
        });
        if !self.clear_pieces(&pieces, v.zone.as_ref()) {
            return false;
        }
        // Its own far parts: no closer than the gap beyond 2.5 (r + r') of arc length.
        for (a, x) in pieces.iter().enumerate() {
            for y in pieces.iter().skip(a + 2) {
                let c = x.gap_to(y);
                if (c.sp - c.sq).abs() > 2.5 * (c.rp + c.rq) && c.gap < self.gap_min {
                    return false;
                }
            }
        }
        let guard = self.guard(id, last, 1.0);
        let guard_clear = 4.0 * self.h;
        // Its end's guard against every other wall and its own far parts.
        for j in self.index.near(&guard, guard_clear) {
            if guard.gap_to(&self.index.pieces[j as usize]).gap < guard_clear {
                return false;
            }
        }
        for x in &pieces {
            let c = guard.gap_to(x);
            if (last.s - c.sq) > 2.5 * (last.r + c.rq) + 3.0 * self.h && c.gap < guard_clear {
                return false;
            }
        }
        // Every other end's guard against it; its zone against every end, its end against every zone.
        let k = v.zone.as_ref().map_or(0.0, |z| z.k);
        for (_, other) in self.end_guards() {
            if pieces.iter().any(|x| x.gap_to(&other).gap < guard_clear + k) {
                return false;
            }
        }
        let zones = self.vessels.iter().filter_map(|w| w.zone.as_ref()).chain(v.zone.as_ref());
        let ends: Vec<Piece> = self.end_guards().into_iter().map(|(_, g)| g).chain([guard]).collect();
        for z in zones {
            for g in &ends {
                let d = crate::implicit_surface::segment_distance(&g.a, &g.b, &z.a, &z.b);
                if d < z.outer + g.ra {
                    return false;
                }
            }
        }
        true
    }

    /// Whether `pieces` of a new component (the last in the blend order) keep every other wall
    /// at the gap, at the gap plus its blend width where its zone blends, except its partners
    /// within its zone's inner part.
    pub fn clear_pieces(&self, pieces: &[Piece], zone: Option<&Zone>) -> bool {
        let k = zone.map_or(0.0, |z| z.k);
        let reach = self.gap_min + k;
        for x in pieces {
            for j in self.index.near(x, reach) {
                let y = &self.index.pieces[j as usize];
                if y.comp == x.comp {
                    continue;
                }
                let c = x.gap_to(y);
                if c.gap >= reach {
                    continue;
                }
                if let Some(z) = zone {
                    if z.partners.contains(&y.comp) && z.distance(&c.wall_point()) <= z.inner {
                        continue;
                    }
                    let blends = z.distance(&c.p) < z.outer || z.distance(&c.q) < z.outer;
                    if c.gap < self.gap_min + if blends { k } else { 0.0 } {
                        return false;
                    }
                } else if c.gap < self.gap_min {
                    return false;
                }
            }
        }
        true
    }

    /// A body steered past another vessel: a cubic to a point at `gap` from that vessel's wall
    /// (a gap drawn between two cells and half the larger radius), arriving perpendicular to the
    /// line between the centerlines at a crossing angle with the other vessel drawn in [0°, 90°]
    /// (0: side by side), then straight on for 2 to 5 radii. The other vessel is drawn among
    /// those with room on their body, by radius over the squared distance from the daughter;
    /// six targets are tried, each with four arrival directions, the cubic kept only if it
    /// bends no tighter than 1.5 radii. `None` (nothing added) when none works.
    fn steer_body(
        &self,
        rng: &mut SeededRng,
        b: &mut PathBuilder,
        radius: f64,
        partners: &[usize],
    ) -> Option<SteeredPass> {
        let start = *b.last();
        let weights: Vec<f64> = (0..self.vessels.len())
            .map(|u| {
                let v = &self.vessels[u];
                if partners.contains(&u) || v.free_position(0.0, v.radius0, 0.5).is_none() {
                    return 0.0;
                }
                let d = v.samples.iter().map(|q| (q.p - start.p).norm()).fold(f64::INFINITY, f64::min);
                v.radius0 / (d + v.radius0).powi(2)
            })
            .collect();
        if weights.iter().all(|w| *w == 0.0) {
            return None;
        }
        for _ in 0..6 {
            let other = rng.weighted(&weights);
            let target = &self.vessels[other];
            let s = target.free_position(0.0, target.radius0, rng.uniform())?;
            let x = sample_at(&target.samples, s);
            let towards = start.p - x.p;
            let Some(m) = (towards - x.t * towards.dot(&x.t)).try_normalize(1e-9) else { continue };
            let largest = x.r.max(radius);
            let gap = if 0.5 * largest > self.gap_min { rng.range(self.gap_min, 0.5 * largest) } else { self.gap_min };
            let waypoint = x.p + m * (x.r + radius + gap);
            if (waypoint - start.p).norm() < 4.0 * radius {
                continue;
            }
            let run = rng.range(2.0, 5.0) * radius;
            let mut feasible = Vec::new();
            for _ in 0..4 {
                let crossing = rng.range(0.0, 90.0f64).to_radians();
                let along = if rng.chance(0.5) { x.t } else { -x.t };
                let across = if rng.chance(0.5) { m.cross(&along) } else { -m.cross(&along) };
                let tangent = (along * crossing.cos() + across * crossing.sin()).normalize();
                let mut trial = b.clone();
                if trial.hermite(&waypoint, &tangent) >= super::centerline::MIN_CURVATURE_RADII * radius {
                    trial.straight(run);
                    feasible.push((trial, crossing));
                }
            }
            if feasible.is_empty() {
                continue;
            }
            let (trial, crossing_angle) = feasible.swap_remove(rng.index(feasible.len()));
            *b = trial;
            return Some(SteeredPass { vessel: 0, other, gap, crossing_angle });
        }
        None
    }

    /// Whether `p` lies within the lumen of vessel `host`, a gap deep (its tube alone).
    fn within_host(&self, host: usize, p: &nalgebra::Point3<f64>) -> bool {
        let probe = Piece { comp: usize::MAX, a: *p, b: *p, ra: 0.0, rb: 0.0, sa: 0.0, sb: 0.0 };
        self.index.near(&probe, 0.0).into_iter().any(|j| {
            let other = &self.index.pieces[j as usize];
            other.comp == host && probe.gap_to(other).gap < -self.gap_min
        })
    }

    /// A hairpin record for a vessel laid (kept for the truth).
    pub fn hairpin_of(&self, vessel: usize) -> Option<&Hairpin> {
        self.hairpins.iter().find(|h| h.vessel == vessel)
    }
}

/// Arc length along `samples` where the zone's inner part ends (the last sample within it).
fn zone_end(samples: &[Sample], zone: &Zone) -> f64 {
    samples.iter().filter(|q| zone.distance(&q.p) <= zone.outer).map(|q| q.s).fold(0.0, f64::max)
}
