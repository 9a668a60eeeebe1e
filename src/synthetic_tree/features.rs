//! Features put on a laid tree: stenoses (which only narrow a lumen, so they cannot bring walls
//! together), saccular aneurysms (balls that must clear every other wall), and the survey of
//! the near passes, steered or not.

use super::centerline::{insert_sample, sample_at};
use super::layout::{Layout, Stenosis};
use super::model::{vessel_pieces, Finish, NearPass, Piece, PieceIndex, Sac, Zone};
use super::rng::SeededRng;

impl Layout {
    /// Rebuilds the index from the vessels' samples (after stenoses changed them) and the sacs.
    pub fn rebuild_index(&mut self) {
        let mut index = PieceIndex::new(4.0 * self.floor() * self.draws.radius_range.sqrt());
        for (id, v) in self.vessels.iter().enumerate() {
            for piece in vessel_pieces(id, &v.samples) {
                index.insert(piece);
            }
        }
        for (i, sac) in self.sacs.iter().enumerate() {
            index.insert(sac_piece(self.vessels.len() + i, sac));
        }
        self.index = index;
    }

    /// Stenoses still to place: the tree's drawn area reductions not yet used.
    fn pending_stenosis(&self) -> Option<f64> {
        self.draws.stenosis_areas.get(self.stenoses.len()).copied()
    }

    /// With probability 1/2, the next pending stenosis on the body of vessel `id` just laid (its
    /// body is still free of places), if its throat stays at or above the tree's smallest
    /// radius.
    pub fn stenosis_on_new_vessel(&mut self, rng: &mut SeededRng, id: usize) {
        if let Some(area) = self.pending_stenosis() {
            if rng.chance(0.5) {
                self.try_stenosis(rng, id, area);
            }
        }
    }

    /// A stenosis of `area_reduction` on `vessel`: a raised-cosine notch 2 to 5 radii long, an
    /// eccentricity uniform in [0, 1] towards a random wall, at a free place of the body;
    /// false (nothing drawn past the length) when the throat would be thinner than the tree's
    /// smallest radius or there is no room.
    fn try_stenosis(&mut self, rng: &mut SeededRng, vessel: usize, area_reduction: f64) -> bool {
        let keep = (1.0 - area_reduction).sqrt();
        let v = &self.vessels[vessel];
        let r = v.radius0;
        let half_length = rng.range(1.0, 2.5) * r;
        let thinnest = v.samples.iter().filter(|q| q.s >= v.body.0 && q.s <= v.body.1).map(|q| q.r);
        if thinnest.fold(f64::INFINITY, f64::min) * keep < self.floor() {
            return false;
        }
        let (eccentricity, u) = (rng.uniform(), rng.uniform());
        let Some(start) = v.free_position(2.0 * half_length, 0.5 * r, u) else { return false };
        let centre = start + half_length;
        let q = sample_at(&v.samples, centre);
        let spared = rng.perpendicular(&q.t, &q.n);
        let throat_radius = q.r * keep;
        let stenosis = Stenosis { vessel, s: centre, half_length, area_reduction, eccentricity, spared, throat_radius };
        self.apply_stenosis(&stenosis);
        self.stenoses.push(stenosis);
        true
    }

    /// The stenoses still pending once the tree is laid: each on a vessel drawn by radius
    /// times body length among those that can take it (ten tries); when none can take its
    /// area reduction, the largest any vessel can (if at least 50 %).
    pub fn add_stenoses(&mut self, rng: &mut SeededRng) {
        while let Some(drawn) = self.pending_stenosis() {
            let thinnest = |v: &super::model::Vessel| {
                v.samples
                    .iter()
                    .filter(|q| q.s >= v.body.0 && q.s <= v.body.1)
                    .map(|q| q.r)
                    .fold(f64::INFINITY, f64::min)
            };
            let feasible = self.vessels.iter().map(|v| 1.0 - (self.floor() / thinnest(v)).powi(2)).fold(0.0, f64::max);
            let area = drawn.min(feasible);
            let weights: Vec<f64> = self
                .vessels
                .iter()
                .map(|v| {
                    if 1.0 - (self.floor() / thinnest(v)).powi(2) >= area {
                        v.radius0 * (v.body.1 - v.body.0).max(0.0)
                    } else {
                        0.0
                    }
                })
                .collect();
            let placed = area >= 0.5
                && weights.iter().any(|w| *w > 0.0)
                && (0..10).any(|_| {
                    let vessel = rng.weighted(&weights);
                    self.try_stenosis(rng, vessel, area)
                });
            if !placed {
                break;
            }
        }
    }

    fn apply_stenosis(&mut self, st: &Stenosis) {
        let v = &mut self.vessels[st.vessel];
        let steps = 16;
        for i in 0..=steps {
            insert_sample(&mut v.samples, st.s - st.half_length + 2.0 * st.half_length * i as f64 / steps as f64);
        }
        let depth = 1.0 - (1.0 - st.area_reduction).sqrt();
        for q in &mut v.samples {
            let x = (q.s - st.s) / st.half_length;
            if x.abs() < 1.0 {
                let base = q.r;
                q.r = base * (1.0 - depth * 0.5 * (1.0 + (std::f64::consts::PI * x).cos()));
                q.p += st.spared * (st.eccentricity * (base - q.r));
            }
        }
        v.busy.push((st.s - st.half_length - v.radius0, st.s + st.half_length + v.radius0));
    }

    /// Saccular aneurysms: a ball of 0.8 to 2 vessel radii (at least 1.2 times the tree's
    /// smallest radius) whose neck is 0.45 to 0.8 of the ball's radius (at most 0.9 of the
    /// vessel's), on a vessel drawn by radius, at a free place of its body, towards a random
    /// side; kept only if clear of every other wall and end (24 tries each).
    pub fn add_sacs(&mut self, rng: &mut SeededRng) {
        self.rebuild_index();
        for _ in 0..self.draws.aneurysms {
            for _ in 0..24 {
                let weights: Vec<f64> = self.vessels.iter().map(|v| v.radius0).collect();
                let host = rng.weighted(&weights);
                let r = self.vessels[host].radius0;
                let radius = (rng.range(0.8, 2.0) * r).max(1.2 * self.floor());
                let neck_radius = (rng.range(0.45, 0.8) * radius).min(0.9 * r);
                let u = rng.uniform();
                let Some(s) = self.vessels[host].free_position(0.0, radius + 2.0 * r, u) else { continue };
                let q = sample_at(&self.vessels[host].samples, s);
                let direction = rng.perpendicular(&q.t, &q.n);
                let centre = q.p + direction * (q.r + (radius * radius - neck_radius * neck_radius).sqrt());
                let k = (0.5 * neck_radius).clamp(
                    super::daughters::NECK_BLEND_CELLS.0 * self.h,
                    super::daughters::NECK_BLEND_CELLS.1 * self.h,
                );
                let inner = neck_radius + k + self.gap_min;
                let zone = Zone {
                    a: q.p,
                    b: centre,
                    inner,
                    outer: inner + neck_radius.max(2.0 * self.h),
                    k,
                    partners: vec![host],
                };
                let sac = Sac { host, s, centre, radius, direction, neck_radius, zone };
                if self.sac_is_clear(&sac, q.r) {
                    let id = self.vessels.len() + self.sacs.len();
                    self.index.insert(sac_piece(id, &sac));
                    self.vessels[host].busy.push((s - radius - 2.0 * r, s + radius + 2.0 * r));
                    self.sacs.push(sac);
                    break;
                }
            }
        }
    }

    /// The ball keeps every wall but its host's near the neck at the gap plus its blend width,
    /// every end's guard at four cells plus it, and its zone off every end.
    fn sac_is_clear(&self, sac: &Sac, host_radius: f64) -> bool {
        let piece = sac_piece(usize::MAX, sac);
        let needed = self.gap_min + sac.zone.k;
        let window = sac.radius + 2.0 * host_radius;
        for j in self.index.near(&piece, needed) {
            let y = &self.index.pieces[j as usize];
            let c = piece.gap_to(y);
            if y.comp == sac.host && (c.sq - sac.s).abs() <= window {
                continue;
            }
            if c.gap < needed {
                return false;
            }
        }
        for (_, guard) in self.end_guards() {
            if piece.gap_to(&guard).gap < 4.0 * self.h + sac.zone.k {
                return false;
            }
            let d = crate::implicit_surface::segment_distance(&guard.a, &guard.b, &sac.zone.a, &sac.zone.b);
            if d < sac.zone.outer + guard.ra {
                return false;
            }
        }
        true
    }

    /// Every pair of walls (of different components, or of one vessel more than 2.5 (r + r')
    /// apart along it) that comes within the smaller radius without blending: partners within
    /// the later one's zone and a sac's host at its neck are not passes. One per pair, the
    /// closest.
    pub fn survey_near_passes(&mut self) -> Vec<NearPass> {
        self.rebuild_index();
        let count = self.vessels.len();
        let zone_of =
            |c: usize| if c < count { self.vessels[c].zone.as_ref() } else { Some(&self.sacs[c - count].zone) };
        let mut best: std::collections::BTreeMap<(usize, usize), NearPass> = Default::default();
        let largest = self.vessels.iter().map(|v| v.max_radius()).fold(0.0, f64::max);
        for (i, x) in self.index.pieces.iter().enumerate() {
            for j in self.index.near(x, largest) {
                let y = &self.index.pieces[j as usize];
                if (j as usize) <= i || (y.comp == x.comp && x.comp >= count) {
                    continue;
                }
                let (x, y) = if x.comp <= y.comp { (x, y) } else { (y, x) };
                let c = x.gap_to(y);
                if c.gap >= c.rp.min(c.rq) {
                    continue;
                }
                if x.comp == y.comp && (c.sp - c.sq).abs() <= 2.5 * (c.rp + c.rq) {
                    continue;
                }
                // The later component's zone: partner contacts within it are junctions, and a
                // sac's host at its neck is its neck.
                if x.comp != y.comp {
                    let d = c.p - c.q;
                    let wall = if d.norm() > 0.0 { c.q + d * (c.rq / d.norm()) } else { c.q };
                    if zone_of(y.comp).is_some_and(|z| z.partners.contains(&x.comp) && z.distance(&wall) <= z.inner) {
                        continue;
                    }
                    if y.comp >= count {
                        let sac = &self.sacs[y.comp - count];
                        if x.comp == sac.host && (c.sp - sac.s).abs() <= sac.radius + 2.0 * c.rp {
                            continue;
                        }
                    }
                }
                let pass = NearPass {
                    a: x.comp,
                    b: y.comp,
                    gap: c.gap,
                    point_a: c.p,
                    point_b: c.q,
                    radius_a: c.rp,
                    radius_b: c.rq,
                };
                let entry = best.entry((x.comp, y.comp)).or_insert_with(|| pass.clone());
                if pass.gap < entry.gap {
                    *entry = pass;
                }
            }
        }
        best.into_values().collect()
    }

    /// Whether vessel `v`'s downstream end is free.
    pub fn is_free(&self, v: usize) -> bool {
        self.vessels[v].finish == Finish::Free
    }
}

/// The axis piece of a sac: its centre, its radius.
pub fn sac_piece(comp: usize, sac: &Sac) -> Piece {
    Piece { comp, a: sac.centre, b: sac.centre, ra: sac.radius, rb: sac.radius, sa: 0.0, sb: 0.0 }
}
