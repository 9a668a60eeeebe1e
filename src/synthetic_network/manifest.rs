//! A network's manifest: its draws, grid and surface figures, loops, ends, junctions, segments
//! and vessels (tubes), as JSON.

use super::{RandomNetwork, GENERATOR_VERSION};
use crate::synthetic_tree::layout::CELLS_PER_SMALLEST_RADIUS;
use crate::synthetic_tree::truth::Node;
use indexmap::IndexMap;
use serde_json::{json, Value};

impl RandomNetwork {
    /// The manifest, naming the surface and centerline files (its keys in this order).
    pub fn manifest(&self, surface_file: &str, centerlines_file: &str) -> IndexMap<&'static str, Value> {
        let net = &self.network;
        let s = &self.surface;
        let open = net.ends.iter().filter(|e| !e.capped).count() as i64;
        let genus = self.loops.len() as i64;
        let mut m: IndexMap<&'static str, Value> = IndexMap::new();
        m.insert("format", json!("vesselhex random network"));
        m.insert("generator_version", json!(GENERATOR_VERSION));
        m.insert("seed", json!(self.seed));
        m.insert("shape", json!(net.shape));
        m.insert("attempt", json!(self.attempt));
        m.insert("redrawn", json!(self.redrawn));
        m.insert("units", json!("mm"));
        m.insert("files", json!({"surface": surface_file, "centerlines": centerlines_file}));
        m.insert("draws", Value::Object(net.draws.clone()));
        m.insert(
            "grid",
            json!({
                "cell_size_mm": net.h,
                "cells_per_smallest_radius": CELLS_PER_SMALLEST_RADIUS,
                "gap_min_mm": net.gap_min,
                "extension_mm": net.extension,
            }),
        );
        m.insert(
            "surface",
            json!({
                "triangles": s.triangles.len(),
                "vertices": s.vertices.len(),
                "open_ends": open,
                "capped_ends": net.ends.len() as i64 - open,
                "euler_characteristic": 2 - 2 * genus - open,
                "genus": genus,
                "pieces": 1,
                "grid_cells": s.stats.grid,
                "min_angle_deg": s.stats.min_angle_deg,
                "min_edge_mm": s.stats.min_edge,
                "max_edge_mm": s.stats.max_edge,
                "max_vertex_offset_mm": s.stats.max_vertex_offset,
            }),
        );
        m.insert("loops", json!({"count": self.loops.len(), "segments": self.loops}));
        m.insert("ends", self.ends_json());
        m.insert("junctions", self.junctions_json());
        m.insert("segments", self.segments_json());
        m.insert("vessels", self.vessels_json());
        m
    }

    /// The segment that ends at free end `e`.
    fn segment_of_end(&self, e: usize) -> Option<usize> {
        self.segments.iter().position(|g| g.from == Node::End(e) || g.to == Node::End(e))
    }

    fn ends_json(&self) -> Value {
        let net = &self.network;
        let ends = net.ends.iter().enumerate().map(|(id, e)| {
            let c = net.end_circle(e);
            json!({
                "id": id,
                "name": e.name,
                "label": e.label,
                "role": if e.inlet { "inlet" } else { "outlet" },
                "kind": if e.capped { "capped" } else { "open" },
                "centre": [c.centre.x, c.centre.y, c.centre.z],
                "outward_normal": [c.outward.x, c.outward.y, c.outward.z],
                "radius_mm": c.radius,
                "vessel": e.tube,
                "segment": self.segment_of_end(id),
            })
        });
        json!(ends.collect::<Vec<_>>())
    }

    fn junctions_json(&self) -> Value {
        let net = &self.network;
        let junctions = net.junctions.iter().enumerate().map(|(id, j)| {
            let node = Node::Junction(id);
            let segments: Vec<usize> = (0..self.segments.len())
                .filter(|&i| self.segments[i].from == node || self.segments[i].to == node)
                .collect();
            let on: Vec<Value> =
                j.on.iter()
                    .map(|&(tube, s, reach)| json!({"vessel": tube, "arc_length_mm": s, "reach_mm": reach}))
                    .collect();
            json!({"id": id, "centre": [j.point.x, j.point.y, j.point.z], "vessels": on, "segments": segments})
        });
        json!(junctions.collect::<Vec<_>>())
    }

    fn segments_json(&self) -> Value {
        let net = &self.network;
        let in_loop = |i: usize| self.loops.iter().any(|l| l.contains(&i));
        let segments = self.segments.iter().enumerate().map(|(id, g)| {
            let samples = self.segment_samples(g);
            let (first, last) = (samples[0], samples[samples.len() - 1]);
            json!({
                "id": id,
                "vessel": g.tube,
                "vessel_name": net.tubes[g.tube].name,
                "from": g.from,
                "to": g.to,
                "length_mm": g.s1 - g.s0,
                "radius_start_mm": first.r,
                "radius_end_mm": last.r,
                "in_loop": in_loop(id),
            })
        });
        json!(segments.collect::<Vec<_>>())
    }

    fn vessels_json(&self) -> Value {
        let vessels = self.network.tubes.iter().enumerate().map(|(id, t)| {
            json!({
                "id": id,
                "name": t.name,
                "closed": t.closed,
                "length_mm": t.length(),
                "draws": t.draws,
            })
        });
        json!(vessels.collect::<Vec<_>>())
    }
}
