//! The branch-split variant of a centerline tree, in the layout of VMTK's
//! `vmtkbranchextractor`: one polyline per tract, cell data `CenterlineIds` (the inlet-outlet
//! path), `TractIds` (0, 1, 2 ... along it), `Blanking` (1 on the junction regions) and
//! `GroupIds` (one id per branch and per junction region, shared by every path through it).
//!
//! Each inlet-outlet path (one per outlet, outlets depth first) is cut at every
//! junction it crosses into: the branch up to where it enters the junction's maximal sphere, the
//! junction region (the last part of the parent inside the sphere and the first part of the
//! daughter inside it, joined at the centre; blanked), the daughter from where it leaves the
//! sphere, and so on. Consecutive tracts share their joint point, as VMTK's do. The sphere is
//! the region VMTK blanks (from the touching sphere to the tube exit) to within a fraction of a
//! radius, and it keeps the centre inside the blanked tract, so a reader can find it again.

use crate::io::input::{CenterlinePolyline, Centerlines};
use crate::stages::centerline::{Branch, CenterlineTree};
use indexmap::IndexMap;
use std::path::Path;

/// The tracts of `tree` as polylines with CenterlineIds, TractIds, Blanking and GroupIds, radii
/// and parallel-transport normals (millimetres).
pub fn branch_split(tree: &CenterlineTree, source: &Path) -> Centerlines {
    // Where each branch's own tract starts and ends (sample indices), leaving room for the
    // junction regions at either end.
    let cuts: Vec<(usize, usize)> = tree.branches.iter().map(|b| own_part(tree, b)).collect();
    let mut group_of_branch = vec![None; tree.branches.len()];
    let mut group_of_junction = vec![None; tree.junctions.len()];
    let mut next_group = 0;
    let mut group = |slot: &mut Option<i64>| {
        *slot.get_or_insert_with(|| {
            next_group += 1;
            next_group - 1
        })
    };
    let mut polylines = vec![];
    // Outlets depth first, daughters in order: a reader numbering outlets by CenterlineIds
    // finds every subtree's outlets together and the daughters in the same order.
    let mut outlets = vec![];
    let mut stack = vec![0];
    while let Some(b) = stack.pop() {
        let daughters = &tree.branches[b].daughters;
        if daughters.is_empty() {
            outlets.push(b);
        }
        stack.extend(daughters.iter().rev());
    }
    for (centerline, &outlet) in outlets.iter().enumerate() {
        let mut chain = vec![outlet];
        while let Some(p) = tree.branches[chain[chain.len() - 1]].parent {
            chain.push(p);
        }
        chain.reverse();
        let mut tract = 0;
        let mut push = |samples: Vec<&crate::stages::centerline::CenterlineSample>, blanked: bool, group: i64| {
            let mut cell_tags = IndexMap::new();
            cell_tags.insert("CenterlineIds".to_string(), centerline as i64);
            cell_tags.insert("TractIds".to_string(), tract);
            cell_tags.insert("Blanking".to_string(), blanked as i64);
            cell_tags.insert("GroupIds".to_string(), group);
            tract += 1;
            polylines.push(CenterlinePolyline {
                points: samples.iter().map(|s| s.point).collect(),
                radii: Some(samples.iter().map(|s| s.radius).collect()),
                normals: Some(samples.iter().map(|s| s.frame.normal).collect()),
                cell_tags,
            });
        };
        for (n, &b) in chain.iter().enumerate() {
            let branch = &tree.branches[b];
            let (head, tail) = cuts[b];
            let g = group(&mut group_of_branch[b]);
            push(branch.samples[head..=tail].iter().collect(), false, g);
            if let (Some(j), Some(&d)) = (branch.end_junction, chain.get(n + 1)) {
                let daughter = &tree.branches[d];
                let region: Vec<_> =
                    branch.samples[tail..].iter().chain(daughter.samples[1..=cuts[d].0].iter()).collect();
                let g = group(&mut group_of_junction[j]);
                push(region, true, g);
            }
        }
    }
    Centerlines { polylines, source: source.to_path_buf() }
}

/// The sample range of a branch outside the maximal spheres of its junctions: at least one
/// sample of the branch on each side goes to a junction region, and the range keeps at least
/// two samples.
fn own_part(tree: &CenterlineTree, branch: &Branch) -> (usize, usize) {
    let s = &branch.samples;
    let n = s.len();
    let mut head = 0;
    if let Some(j) = branch.start_junction {
        let j = &tree.junctions[j];
        head = s.iter().position(|q| (q.point - j.centre).norm() >= j.radius).unwrap_or(n - 1).max(1);
    }
    let mut tail = n - 1;
    if let Some(j) = branch.end_junction {
        let j = &tree.junctions[j];
        tail = s.iter().rposition(|q| (q.point - j.centre).norm() >= j.radius).unwrap_or(0).min(n - 2);
    }
    if tail <= head {
        // A branch shorter than its junctions' spheres: split it in the middle.
        let lo = usize::from(branch.start_junction.is_some());
        head = ((head + tail) / 2).clamp(lo, n - 2);
        tail = head + 1;
    }
    (head, tail)
}
