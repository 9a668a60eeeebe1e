//! What a network is made of: tubes (sampled centerlines with radii, the ring a closed one),
//! the junctions where they meet, the free ends; and the pieces of each tube that keep the walls
//! of tubes not joined at a junction apart.

use crate::implicit_surface::EndCircle;
use crate::synthetic_tree::centerline::Sample;
use crate::synthetic_tree::model::{vessel_pieces, Piece, Zone};
use crate::synthetic_tree::truth::Node;
use nalgebra::Point3;
use serde_json::{Map, Value};

/// A vessel of the network: one tube of the lumen, joined to others at junctions along it or
/// at its ends.
#[derive(Debug, Clone)]
pub struct Tube {
    pub name: String,
    pub samples: Vec<Sample>,
    /// The ring: its last sample is its first point (no ends).
    pub closed: bool,
    /// The end (index into the network's ends) at its first and at its last sample, if free.
    pub start_end: Option<usize>,
    pub end_end: Option<usize>,
    /// Where it blends with the tubes laid before it (one per junction it joins).
    pub zones: Vec<Zone>,
    /// Arc length of the middle of the straight stretch laid to take a side branch, if any.
    pub side_anchor: Option<f64>,
    /// Its draws, for the manifest.
    pub draws: Map<String, Value>,
}

impl Tube {
    pub fn length(&self) -> f64 {
        self.samples.last().map_or(0.0, |q| q.s)
    }

    /// Distance along the tube between arc lengths `a` and `b` (the shorter way round a ring).
    pub fn along(&self, a: f64, b: f64) -> f64 {
        let d = (a - b).abs();
        if self.closed {
            d.min(self.length() - d)
        } else {
            d
        }
    }
}

/// A place where tubes meet: each tube's arc length there and the length along it, from there,
/// within which its wall may touch the others' ([`crate::synthetic_tree::separation::junction_reach`]).
#[derive(Debug, Clone)]
pub struct Junction {
    pub point: Point3<f64>,
    /// (tube, arc length, reach), the host (the tube going through, or the first laid) first.
    pub on: Vec<(usize, f64, f64)>,
}

/// A free end: an inlet or an outlet, at the first or last sample of its tube.
#[derive(Debug, Clone)]
pub struct End {
    pub tube: usize,
    pub at_start: bool,
    pub inlet: bool,
    pub capped: bool,
    pub name: String,
    /// An anatomical label (the circle of Willis), else empty.
    pub label: &'static str,
}

/// A laid network.
#[derive(Debug, Clone)]
pub struct Network {
    pub shape: &'static str,
    /// Grid cell, smallest gap between walls not joined at a junction, extension past free ends, mm.
    pub h: f64,
    pub gap_min: f64,
    pub extension: f64,
    pub tubes: Vec<Tube>,
    pub junctions: Vec<Junction>,
    pub ends: Vec<End>,
    /// Network-level draws, for the manifest.
    pub draws: Map<String, Value>,
}

/// A segment of the network's graph: a stretch of a tube between two nodes (junctions or ends).
#[derive(Debug, Clone)]
pub struct GraphSegment {
    pub tube: usize,
    pub from: Node,
    pub to: Node,
    /// Arc lengths along the tube (`s1 > length` wraps round a ring).
    pub s0: f64,
    pub s1: f64,
}

impl Network {
    /// The end's circle in its plane, with the clip zone the tree generator gives its ends.
    pub fn end_circle(&self, end: &End) -> EndCircle {
        let tube = &self.tubes[end.tube];
        let (q, sign) = if end.at_start {
            (tube.samples[0], -1.0)
        } else {
            (*tube.samples.last().unwrap_or(&tube.samples[0]), 1.0)
        };
        EndCircle {
            centre: q.p,
            outward: q.t * sign,
            radius: q.r,
            capped: end.capped,
            beyond: self.extension + q.r + 2.0 * self.h,
        }
    }

    pub fn end_circles(&self) -> Vec<EndCircle> {
        self.ends.iter().map(|e| self.end_circle(e)).collect()
    }

    /// The junctions on tube `id`: (junction, arc length), by arc length.
    pub fn junctions_on(&self, id: usize) -> Vec<(usize, f64)> {
        let mut out: Vec<(usize, f64)> = self
            .junctions
            .iter()
            .enumerate()
            .flat_map(|(j, junction)| junction.on.iter().filter(|o| o.0 == id).map(move |o| (j, o.1)))
            .collect();
        out.sort_by(|a, b| a.1.total_cmp(&b.1));
        out
    }

    /// The graph's segments: each tube cut at its junctions, in tube order, along each tube.
    pub fn segments(&self) -> Vec<GraphSegment> {
        let mut out = Vec::new();
        for (id, tube) in self.tubes.iter().enumerate() {
            let on = self.junctions_on(id);
            let mut nodes: Vec<(Node, f64)> = on.iter().map(|&(j, s)| (Node::Junction(j), s)).collect();
            if tube.closed {
                // Round the ring back to its first junction.
                if let Some(&(node, s)) = nodes.first() {
                    nodes.push((node, s + tube.length()));
                }
            } else {
                if let Some(e) = tube.start_end {
                    nodes.insert(0, (Node::End(e), 0.0));
                }
                if let Some(e) = tube.end_end {
                    nodes.push((Node::End(e), tube.length()));
                }
            }
            for w in nodes.windows(2) {
                out.push(GraphSegment { tube: id, from: w[0].0, to: w[1].0, s0: w[0].1, s1: w[1].1 });
            }
        }
        out
    }

    /// The axis pieces of tube `id`, and at each free end its clip guard (from three cells
    /// before the end plane to the end of the cut's zone past it), which nothing else may enter.
    pub fn pieces(&self, id: usize) -> Vec<Piece> {
        let tube = &self.tubes[id];
        let mut pieces = vessel_pieces(id, &tube.samples);
        for end in self.ends.iter().filter(|e| e.tube == id) {
            let o = self.end_circle(end);
            let s = if end.at_start { 0.0 } else { tube.length() };
            pieces.push(Piece {
                comp: id,
                a: o.centre - o.outward * (3.0 * self.h),
                b: o.centre + o.outward * o.beyond,
                ra: o.radius,
                rb: o.radius,
                sa: s,
                sb: s,
            });
        }
        pieces
    }
}
