//! What a tree is made of while it is drawn: vessels (centerlines with radii), the places where
//! daughters leave their host, sacs, the blend zones, and the index of centerline segments that
//! keeps vessels apart.

use super::centerline::Sample;
use crate::implicit_surface::segment_closest;
use nalgebra::{Point3, Vector3};
use std::collections::HashMap;

/// How a vessel's downstream end is finished.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Finish {
    /// A free end (an outlet), open or capped.
    Free,
    /// It ends at a place where its daughters leave (a terminal junction: a Y, a trifurcation).
    Place(usize),
}

/// Where a component blends with the ones before it: within `inner` of the segment `a`-`b` the
/// smooth minimum has width `k`, falling to 0 (a plain minimum) at `outer`.
#[derive(Debug, Clone, PartialEq)]
pub struct Zone {
    pub a: Point3<f64>,
    pub b: Point3<f64>,
    pub inner: f64,
    pub outer: f64,
    pub k: f64,
    /// Components it may touch within the zone: its host and its siblings at the same place.
    pub partners: Vec<usize>,
}

impl Zone {
    /// Distance from `p` to the zone's segment.
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        (crate::mesh::closest_on_segment(p, &self.a, &self.b) - p).norm()
    }

    /// The blend width at `p` and its gradient: `k` within `inner`, a smoothstep down to 0 at
    /// `outer`.
    pub fn width(&self, p: &Point3<f64>) -> (f64, Vector3<f64>) {
        let foot = crate::mesh::closest_on_segment(p, &self.a, &self.b);
        let d = (p - foot).norm();
        if d <= self.inner {
            return (self.k, Vector3::zeros());
        }
        if d >= self.outer {
            return (0.0, Vector3::zeros());
        }
        let x = (d - self.inner) / (self.outer - self.inner);
        let w = 1.0 - x * x * (3.0 - 2.0 * x);
        let dw = -6.0 * x * (1.0 - x) / (self.outer - self.inner);
        (self.k * w, (p - foot) / d * (self.k * dw))
    }
}

/// A vessel: a centerline from its start (the inlet for the root, an anchor on its host's
/// centerline for a daughter) to its end.
#[derive(Debug, Clone)]
pub struct Vessel {
    pub parent: Option<usize>,
    pub place: Option<usize>,
    pub samples: Vec<Sample>,
    pub finish: Finish,
    pub zone: Option<Zone>,
    /// Radius at the start, the fraction lost by taper along the body, tortuosity in [0, 1].
    pub radius0: f64,
    pub taper: f64,
    pub tortuosity: f64,
    /// Arc lengths of the body (where places and features may go): after the junction's
    /// straight stretch and zone, before the straight stretch of the end.
    pub body: (f64, f64),
    /// Arc-length intervals already taken (places, hairpins, stenoses, sacs).
    pub busy: Vec<(f64, f64)>,
    /// Length along it, from its anchor, of its junction blend zone: the only part of it that
    /// may touch its host or its siblings ([`super::separation::junction_reach`]; 0 for the
    /// root).
    pub reach: f64,
}

impl Vessel {
    pub fn length(&self) -> f64 {
        self.samples.last().map_or(0.0, |q| q.s)
    }

    pub fn first(&self) -> &Sample {
        &self.samples[0]
    }

    pub fn last(&self) -> &Sample {
        self.samples.last().expect("a vessel has samples")
    }

    /// Largest radius along the vessel.
    pub fn max_radius(&self) -> f64 {
        self.samples.iter().map(|q| q.r).fold(0.0, f64::max)
    }

    /// A random position `s` such that `[s - margin, s + length + margin]` lies within the body
    /// and off every busy interval, drawn uniformly over the room there is; `None` without room.
    pub fn free_position(&self, length: f64, margin: f64, u: f64) -> Option<f64> {
        let (lo, hi) = self.body;
        let mut busy = self.busy.clone();
        busy.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut room = Vec::new();
        let mut from = lo;
        for (a, b) in busy.iter().copied().chain([(hi, hi)]) {
            let (start, end) = (from + margin, a.min(hi) - margin - length);
            if end > start {
                room.push((start, end));
            }
            from = from.max(b);
        }
        let total: f64 = room.iter().map(|(a, b)| b - a).sum();
        if total <= 0.0 {
            return None;
        }
        let mut x = u * total;
        for (a, b) in &room {
            if x <= b - a {
                return Some(a + x);
            }
            x -= b - a;
        }
        room.last().map(|r| r.1)
    }
}

/// A place where daughters leave their host.
#[derive(Debug, Clone)]
pub struct Place {
    pub host: usize,
    /// The host ends here (a Y or an n-furcation) rather than going on (side branches).
    pub terminal: bool,
    pub daughters: Vec<usize>,
    /// Arc length of each daughter's anchor on the host, in the daughters' order.
    pub anchors: Vec<f64>,
}

/// A saccular aneurysm: a ball blended into its host's side.
#[derive(Debug, Clone)]
pub struct Sac {
    pub host: usize,
    /// Arc length of the neck's centre on the host's centerline.
    pub s: f64,
    pub centre: Point3<f64>,
    pub radius: f64,
    /// Unit direction from the host's centerline to the sac's centre.
    pub direction: Vector3<f64>,
    pub neck_radius: f64,
    pub zone: Zone,
}

/// A piece of a component's axis for clearance: a segment with radii at its ends.
#[derive(Debug, Clone, Copy)]
pub struct Piece {
    pub comp: usize,
    pub a: Point3<f64>,
    pub b: Point3<f64>,
    pub ra: f64,
    pub rb: f64,
    /// Arc lengths of `a` and `b` along the component.
    pub sa: f64,
    pub sb: f64,
}

impl Piece {
    pub fn from_samples(comp: usize, x: &Sample, y: &Sample) -> Self {
        Piece { comp, a: x.p, b: y.p, ra: x.r, rb: y.r, sa: x.s, sb: y.s }
    }

    /// The closest points of two pieces: gap between the tubes (distance less the radii there),
    /// the points on each axis, their radii and arc lengths.
    pub fn gap_to(&self, other: &Piece) -> Contact {
        let (d, u, v) = segment_closest(&self.a, &self.b, &other.a, &other.b);
        let (ra, rb) = (self.ra + (self.rb - self.ra) * u, other.ra + (other.rb - other.ra) * v);
        Contact {
            gap: d - ra - rb,
            p: self.a + (self.b - self.a) * u,
            q: other.a + (other.b - other.a) * v,
            rp: ra,
            rq: rb,
            sp: self.sa + (self.sb - self.sa) * u,
            sq: other.sa + (other.sb - other.sa) * v,
        }
    }

    fn bounds(&self, pad: f64) -> (Point3<f64>, Point3<f64>) {
        let r = self.ra.max(self.rb) + pad;
        let lo = self.a.inf(&self.b) - Vector3::repeat(r);
        let hi = self.a.sup(&self.b) + Vector3::repeat(r);
        (lo, hi)
    }
}

/// Where two tubes come closest.
#[derive(Debug, Clone, Copy)]
pub struct Contact {
    pub gap: f64,
    pub p: Point3<f64>,
    pub q: Point3<f64>,
    pub rp: f64,
    pub rq: f64,
    pub sp: f64,
    pub sq: f64,
}

impl Contact {
    /// The point of the first tube's wall facing the second.
    pub fn wall_point(&self) -> Point3<f64> {
        let d = self.q - self.p;
        let len = d.norm();
        if len > 0.0 {
            self.p + d * (self.rp / len)
        } else {
            self.p
        }
    }
}

/// Axis pieces of every component laid so far, in buckets of a uniform grid.
#[derive(Debug, Clone)]
pub struct PieceIndex {
    cell: f64,
    pub pieces: Vec<Piece>,
    pub alive: Vec<bool>,
    buckets: HashMap<[i64; 3], Vec<u32>>,
    /// Largest radius of any piece (pads the queries).
    max_radius: f64,
}

impl PieceIndex {
    pub fn new(cell: f64) -> Self {
        PieceIndex { cell, pieces: Vec::new(), alive: Vec::new(), buckets: HashMap::new(), max_radius: 0.0 }
    }

    fn key(&self, p: &Point3<f64>) -> [i64; 3] {
        [0, 1, 2].map(|k| (p[k] / self.cell).floor() as i64)
    }

    pub fn insert(&mut self, piece: Piece) {
        let id = self.pieces.len() as u32;
        let (lo, hi) = piece.bounds(0.0);
        let (a, b) = (self.key(&lo), self.key(&hi));
        for x in a[0]..=b[0] {
            for y in a[1]..=b[1] {
                for z in a[2]..=b[2] {
                    self.buckets.entry([x, y, z]).or_default().push(id);
                }
            }
        }
        self.max_radius = self.max_radius.max(piece.ra).max(piece.rb);
        self.pieces.push(piece);
        self.alive.push(true);
    }

    /// Living pieces that may come within `reach` of `piece`'s tube (by bounding boxes), in
    /// index order.
    pub fn near(&self, piece: &Piece, reach: f64) -> Vec<u32> {
        let (lo, hi) = piece.bounds(reach + self.max_radius);
        let (a, b) = (self.key(&lo), self.key(&hi));
        let mut out = Vec::new();
        for x in a[0]..=b[0] {
            for y in a[1]..=b[1] {
                for z in a[2]..=b[2] {
                    if let Some(ids) = self.buckets.get(&[x, y, z]) {
                        out.extend(ids.iter().copied().filter(|&i| self.alive[i as usize]));
                    }
                }
            }
        }
        out.sort_unstable();
        out.dedup();
        out
    }

    /// Marks dead every piece of component `comp` (or of every component from `comp` on when
    /// `and_after`).
    pub fn kill(&mut self, comp: usize, and_after: bool) {
        for (piece, alive) in self.pieces.iter().zip(self.alive.iter_mut()) {
            if piece.comp == comp || (and_after && piece.comp > comp) {
                *alive = false;
            }
        }
    }
}

/// The pieces of a vessel's samples (consecutive pairs).
pub fn vessel_pieces(comp: usize, samples: &[Sample]) -> Vec<Piece> {
    samples.windows(2).map(|w| Piece::from_samples(comp, &w[0], &w[1])).collect()
}

/// Two walls that come within the smaller radius of each other without blending.
#[derive(Debug, Clone, PartialEq)]
pub struct NearPass {
    /// Components (vessels, then sacs after the last vessel), in order.
    pub a: usize,
    pub b: usize,
    /// Wall-to-wall gap, mm, and where on each centerline.
    pub gap: f64,
    pub point_a: Point3<f64>,
    pub point_b: Point3<f64>,
    pub radius_a: f64,
    pub radius_b: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_zone_blends_fully_inside_and_not_at_all_outside_with_a_consistent_gradient() {
        let z = Zone {
            a: Point3::origin(),
            b: Point3::new(0.0, 0.0, 2.0),
            inner: 1.0,
            outer: 2.0,
            k: 0.4,
            partners: vec![],
        };
        assert_eq!(z.width(&Point3::new(0.5, 0.0, 1.0)).0, 0.4);
        assert_eq!(z.width(&Point3::new(2.5, 0.0, 1.0)).0, 0.0);
        let p = Point3::new(1.3, 0.4, 1.0);
        let (_, g) = z.width(&p);
        let h = 1e-6;
        for axis in 0..3 {
            let mut e = Vector3::zeros();
            e[axis] = h;
            let fd = (z.width(&(p + e)).0 - z.width(&(p - e)).0) / (2.0 * h);
            assert!((g[axis] - fd).abs() < 1e-7);
        }
    }

    #[test]
    fn free_positions_avoid_busy_intervals() {
        let v = Vessel {
            parent: None,
            place: None,
            samples: vec![],
            finish: Finish::Free,
            zone: None,
            radius0: 1.0,
            taper: 0.0,
            tortuosity: 0.0,
            body: (0.0, 10.0),
            busy: vec![(2.0, 5.0)],
            reach: 0.0,
        };
        for i in 0..=100 {
            let s = v.free_position(1.0, 0.5, i as f64 / 100.0).unwrap();
            let (a, b) = (s - 0.5, s + 1.5);
            assert!(a >= -1e-12 && b <= 10.0 + 1e-12 && (b <= 2.0 + 1e-12 || a >= 5.0 - 1e-12), "{s}");
        }
        assert!(v.free_position(5.0, 0.5, 0.5).is_none());
    }
}
