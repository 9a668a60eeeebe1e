//! The random-tree generator's truth matches its surface where vessels meet (issue 46): over a
//! sample of seeds, no pair of truth vessels is fused (walls closer than the two grid cells the
//! surface resolves) outside the blend zone of a junction the two share, so the mesher finds no
//! junction the truth does not list; and the sample still spans the issue's ranges (branches at
//! one place, out-of-plane angle, daughter spacing, radius ratio, branch angle, stenosis, near
//! passes within 0.3 radii that do not touch). The layouts checked are every seed's first draw,
//! without its surface (a seed's tree is its first draw whose surface passes, so a property of
//! every draw holds for every tree). The whole population is `VESSELHEX_TREE_SEPARATION=1 cargo
//! bench --bench trees`.

use vesselhex::synthetic_tree::draw_layout;
use vesselhex::synthetic_tree::layout::Layout;
use vesselhex::synthetic_tree::separation::fused_runs;
use vesselhex::synthetic_tree::truth::junctions;

/// Seeds checked for fused pairs.
const SEEDS: std::ops::RangeInclusive<u64> = 1..=30;
/// Seeds whose spans are checked: more, as 7 and 8 branches at one place are drawn at one
/// place in six and mostly refused where the tree is crowded (none in seeds 1-30).
const RANGE_SEEDS: std::ops::RangeInclusive<u64> = 1..=80;

fn layouts(seeds: std::ops::RangeInclusive<u64>) -> Vec<(u64, Layout)> {
    seeds.map(|seed| (seed, draw_layout(seed, 0))).collect()
}

#[test]
fn no_pair_of_vessels_is_fused_outside_the_blend_zone_of_a_junction_they_share() {
    let mut fused = Vec::new();
    for (seed, layout) in layouts(SEEDS) {
        for r in fused_runs(&layout) {
            fused.push(format!("seed {seed}: {r} (the grid resolves {:.3} mm)", layout.gap_min));
        }
    }
    assert!(fused.is_empty(), "{} fused pairs:\n{}", fused.len(), fused.join("\n"));
}

/// Smallest and largest of a sample.
fn span(values: impl Iterator<Item = f64>) -> (f64, f64) {
    values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)))
}

/// The issue's ranges, each reached near both ends. A near pass's gap is in the larger vessel's
/// radii: the grid (3.5 cells per smallest radius) resolves two cells, 0.57 smallest radii, so
/// "within 0.3 radii without touching" is only possible measured against a vessel at least
/// twice the smallest.
#[test]
fn the_sample_spans_the_issues_ranges() {
    let (mut branches, mut out_of_plane, mut spacing, mut ratio, mut angle) = (vec![], vec![], vec![], vec![], vec![]);
    let (mut stenosis, mut passes, mut ends, mut radii) = (vec![], vec![], vec![], vec![]);
    for (_, mut layout) in layouts(RANGE_SEEDS) {
        for j in junctions(&layout) {
            branches.push(j.branches as f64);
            out_of_plane.extend(j.out_of_plane_deg);
            spacing.extend(j.spacing_parent_radii);
            ratio.extend(j.radius_ratios);
            angle.extend(j.branch_angles_deg);
        }
        stenosis.extend(layout.stenoses.iter().map(|s| 100.0 * s.area_reduction));
        ends.push(layout.end_count() as f64);
        radii.extend(layout.vessels.iter().flat_map(|v| v.samples.iter().map(|q| q.r)));
        let count = layout.vessels.len();
        // Vessel to vessel passes (a sac's passes are the sac's).
        for p in layout.survey_near_passes().into_iter().filter(|p| p.b < count) {
            passes.push((p.gap, p.gap / p.radius_a.max(p.radius_b)));
        }
    }
    let report = |name: &str, v: &[f64]| {
        let (lo, hi) = span(v.iter().copied());
        eprintln!("{name}: {} values in [{lo:.3}, {hi:.3}]", v.len());
        (lo, hi)
    };
    let mut missed = Vec::new();
    let mut check = |holds: bool, what: String| {
        if !holds {
            missed.push(what);
        }
    };
    let (lo, hi) = report("branches at one place", &branches);
    check(lo == 3.0 && hi >= 7.0, format!("branches at one place span {lo}..{hi}, the issue asks 3..8"));
    let (lo, hi) = report("out-of-plane angle (deg)", &out_of_plane);
    check(lo < 15.0 && hi > 75.0, format!("out-of-plane angles span {lo:.1}..{hi:.1}°, the issue asks 0..90"));
    let nonzero: Vec<f64> = spacing.iter().copied().filter(|s| *s > 0.0).collect();
    let (lo, hi) = report("daughter spacing (host radii), nonzero", &nonzero);
    check(spacing.contains(&0.0), "no two daughters leave one point".to_string());
    check(lo < 0.6 && hi > 2.4, format!("daughter spacings span {lo:.2}..{hi:.2} host radii, the issue asks 0.3..3"));
    let (lo, hi) = report("radius ratio", &ratio);
    check(lo < 0.3 && hi > 0.9, format!("radius ratios span {lo:.2}..{hi:.2}, the issue asks 0.15..1"));
    let (lo, hi) = report("branch angle (deg)", &angle);
    check(lo < 30.0 && hi > 150.0, format!("branch angles span {lo:.1}..{hi:.1}°, the issue asks 15..170"));
    let (lo, hi) = report("stenosis (area %)", &stenosis);
    check(lo < 65.0 && hi > 80.0, format!("stenoses span {lo:.1}..{hi:.1} %, the issue asks 50..90"));
    let (lo, hi) = report("ends", &ends);
    check(lo <= 3.0 && hi >= 25.0, format!("ends span {lo}..{hi}, the issue asks 2..40"));
    let (lo, hi) = report("radius (mm)", &radii);
    check(lo < 1.0 && hi > 7.5, format!("radii span {lo:.2}..{hi:.2} mm, the issue asks 0.3..15"));
    let (gap, smaller) = report("near-pass gap (mm)", &passes.iter().map(|p| p.0).collect::<Vec<_>>());
    let (close, _) = report("near-pass gap (larger radii)", &passes.iter().map(|p| p.1).collect::<Vec<_>>());
    check(gap > 0.0, format!("a near pass touches (gap {gap:.3} mm, up to {smaller:.3})"));
    check(close < 0.3, format!("no near pass within 0.3 radii (closest {close:.2}), the issue asks for them"));
    assert!(missed.is_empty(), "the sample misses the issue's ranges:\n{}", missed.join("\n"));
}
