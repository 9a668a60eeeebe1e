//! Whether a tree's truth matches its surface where vessels meet: every pair of vessels either
//! keeps its walls apart by the gap the grid resolves, or is fused only at a junction the two
//! genuinely share, and only within that junction's blend zone.
//!
//! A daughter's junction blend zone is the stretch of it, from its anchor, within which its wall
//! may still touch its host's: a daughter of radius `r` leaving a host of radius `R` at the
//! branch angle θ has its axis `s sin θ` off the host's axis at `s` along it, so its wall clears
//! the host's by the blend width `k` and the gap once `s sin θ >= R + r + k + gap`; the zone is
//! that length plus one radius ([`junction_reach`]). A daughter fused to its host past its zone
//! runs along it; two daughters of one place (siblings) fused where either has left its zone run
//! along each other: in both cases the surface has a junction, or a fused pair, the truth does
//! not list. Any other pair (a near pass, steered or met by chance) must keep the gap
//! everywhere: two walls closer than two grid cells ([`super::layout::GAP_MIN_CELLS`]) may join
//! in the sampled surface even when the tubes do not touch (a grid cell, √3 cells across, can
//! then hold both walls).

use super::centerline::sample_at;
use super::layout::Layout;
use super::model::{vessel_pieces, Contact, NearPass, Piece};
use crate::implicit_surface::ImplicitFunction;
use nalgebra::Point3;

/// Floor of the sine of the branch angle in [`junction_reach`] (a daughter is never drawn within
/// 10° of its host's axis, so this only guards against division by zero).
const MIN_BRANCH_SINE: f64 = 0.1;

/// Length along a daughter, from its anchor, of its junction blend zone: where its wall clears
/// its host's by the blend width and the gap at its branch angle, plus one radius.
pub fn junction_reach(host_radius: f64, radius: f64, blend: f64, gap: f64, branch_angle: f64) -> f64 {
    (host_radius + radius + blend + gap) / branch_angle.sin().max(MIN_BRANCH_SINE) + radius
}

/// How two vessels are related.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Relation {
    /// Daughters of one place.
    Siblings,
    /// A daughter and the host it leaves.
    ParentDaughter,
    /// A near pass drawn on purpose (a daughter steered past the other).
    SteeredPass,
    /// Anything else.
    Unrelated,
}

impl Relation {
    pub fn name(&self) -> &'static str {
        match self {
            Relation::Siblings => "siblings at a shared place",
            Relation::ParentDaughter => "daughter along its parent",
            Relation::SteeredPass => "near pass steered too close",
            Relation::Unrelated => "unrelated vessels",
        }
    }
}

/// Two vessels whose walls come closer than the gap outside their junction's blend zone.
#[derive(Debug, Clone, PartialEq)]
pub struct FusedRun {
    pub a: usize,
    pub b: usize,
    pub relation: Relation,
    /// Smallest wall gap outside the blend zone, mm (negative: the tubes overlap).
    pub min_gap: f64,
    /// Length of centerline along which the walls are closer than the gap, outside the blend
    /// zone, mm (the larger of the two vessels' measures).
    pub length: f64,
    /// The same in the smaller start radius of the two.
    pub length_radii: f64,
    /// Where the gap is smallest (on `a`'s centerline).
    pub at: Point3<f64>,
}

impl std::fmt::Display for FusedRun {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "vessels {} and {} ({}) fused over {:.2} mm ({:.1} radii), gap down to {:.3} mm, at ({:.2}, {:.2}, {:.2})",
            self.a,
            self.b,
            self.relation.name(),
            self.length,
            self.length_radii,
            self.min_gap,
            self.at.x,
            self.at.y,
            self.at.z
        )
    }
}

/// Per vessel: its place's host, its anchor's arc length on the host, and its junction reach
/// (none for the root).
fn junction_zones(layout: &Layout) -> Vec<Option<(usize, f64, f64)>> {
    let mut out = vec![None; layout.vessels.len()];
    for place in &layout.places {
        let host = &layout.vessels[place.host].samples;
        for (&d, &s) in place.daughters.iter().zip(&place.anchors) {
            let at = sample_at(host, s);
            let first = layout.vessels[d].first();
            let angle = first.t.angle(&at.t);
            let reach = junction_reach(at.r, first.r, layout.blend_width(first.r), layout.gap_min, angle);
            out[d] = Some((place.host, s, reach));
        }
    }
    out
}

fn relation(layout: &Layout, a: usize, b: usize) -> Relation {
    let (va, vb) = (&layout.vessels[a], &layout.vessels[b]);
    if va.parent == Some(b) || vb.parent == Some(a) {
        Relation::ParentDaughter
    } else if va.place.is_some() && va.place == vb.place {
        Relation::Siblings
    } else if layout.steered.iter().any(|p| (p.vessel, p.other) == (a, b) || (p.vessel, p.other) == (b, a)) {
        Relation::SteeredPass
    } else {
        Relation::Unrelated
    }
}

/// Whether a contact at arc length `sp` on `a` and `sq` on `b` lies in the blend zone of a
/// junction the two share.
fn in_shared_zone(zones: &[Option<(usize, f64, f64)>], a: usize, b: usize, sp: f64, sq: f64) -> bool {
    match (zones[a], zones[b]) {
        (Some((host, anchor, reach)), _) if host == b => sp <= reach && (sq - anchor).abs() <= reach,
        (_, Some((host, anchor, reach))) if host == a => sq <= reach && (sp - anchor).abs() <= reach,
        (Some((_, _, ra)), Some((_, _, rb))) => sp <= ra && sq <= rb,
        _ => false,
    }
}

/// Along `a`: the length of its pieces closer than `gap` to `b` outside their shared blend
/// zone, the smallest such gap and where.
fn fused_along(
    zones: &[Option<(usize, f64, f64)>],
    (a, pa): (usize, &[Piece]),
    (b, pb): (usize, &[Piece]),
    gap: f64,
    related: bool,
) -> (f64, f64, Point3<f64>) {
    let (mut length, mut smallest, mut at) = (0.0, f64::INFINITY, Point3::origin());
    for x in pa {
        let mut fused = None;
        for y in pb {
            let c = x.gap_to(y);
            if c.gap < gap && !(related && in_shared_zone(zones, a, b, c.sp, c.sq)) {
                fused = Some(fused.map_or(c, |f: Contact| if c.gap < f.gap { c } else { f }));
            }
        }
        if let Some(c) = fused {
            length += (x.b - x.a).norm();
            if c.gap < smallest {
                (smallest, at) = (c.gap, c.p);
            }
        }
    }
    (length, smallest, at)
}

/// Every pair of vessels fused (walls closer than the tree's gap, two cells) outside the blend
/// zone of a junction they share, in pair order.
pub fn fused_runs(layout: &Layout) -> Vec<FusedRun> {
    let zones = junction_zones(layout);
    let gap = layout.gap_min;
    let pieces: Vec<Vec<Piece>> =
        layout.vessels.iter().enumerate().map(|(id, v)| vessel_pieces(id, &v.samples)).collect();
    let bounds: Vec<(Point3<f64>, Point3<f64>)> = layout
        .vessels
        .iter()
        .map(|v| {
            let pad = v.max_radius() + gap;
            let lo = v.samples.iter().fold(Point3::from([f64::INFINITY; 3]), |m, q| m.inf(&q.p));
            let hi = v.samples.iter().fold(Point3::from([f64::NEG_INFINITY; 3]), |m, q| m.sup(&q.p));
            (lo.map(|x| x - pad), hi.map(|x| x + pad))
        })
        .collect();
    let mut out = Vec::new();
    for a in 0..layout.vessels.len() {
        for b in a + 1..layout.vessels.len() {
            let ((la, ha), (lb, hb)) = (bounds[a], bounds[b]);
            if (0..3).any(|k| la[k] > hb[k] || lb[k] > ha[k]) {
                continue;
            }
            let relation = relation(layout, a, b);
            let related = matches!(relation, Relation::Siblings | Relation::ParentDaughter);
            let (len_a, gap_a, at_a) = fused_along(&zones, (a, &pieces[a]), (b, &pieces[b]), gap, related);
            let (len_b, gap_b, at_b) = fused_along(&zones, (b, &pieces[b]), (a, &pieces[a]), gap, related);
            if len_a == 0.0 && len_b == 0.0 {
                continue;
            }
            let length = len_a.max(len_b);
            let radius = layout.vessels[a].first().r.min(layout.vessels[b].first().r);
            out.push(FusedRun {
                a,
                b,
                relation,
                min_gap: gap_a.min(gap_b),
                length,
                length_radii: length / radius,
                at: if gap_a <= gap_b { at_a } else { at_b },
            });
        }
    }
    out
}

/// The near passes (by index) whose gap the triangulated surface closes although the implicit
/// lumen keeps it open: the middle of the gap between the two walls lies outside the lumen
/// (`lumen` positive there: not inside a third vessel either) but inside the surface
/// (generalised winding number above 1/2); with the winding number there.
pub fn passes_closed_in_surface(
    vertices: &[Point3<f64>],
    triangles: &[[u32; 3]],
    lumen: &impl ImplicitFunction,
    passes: &[NearPass],
) -> Vec<(usize, f64)> {
    let Ok(surface) =
        crate::surface::LumenSurface::from_parts(vertices.to_vec(), triangles.to_vec(), Default::default())
    else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for (i, p) in passes.iter().enumerate() {
        let d = p.point_b - p.point_a;
        let length = d.norm();
        if length <= p.radius_a + p.radius_b {
            continue;
        }
        let middle = p.point_a + d * ((p.radius_a + 0.5 * (length - p.radius_a - p.radius_b)) / length);
        if lumen.value_gradient(&middle).0 <= 0.0 {
            continue;
        }
        let w = surface.winding_number(&middle);
        if w > 0.5 {
            out.push((i, w));
        }
    }
    out
}
