//! The truth that comes with a tree: its manifest (every end, vessel, junction, stenosis,
//! aneurysm, hairpin and near pass, the tree's bins) and its centerlines.
//!
//! The manifest describes a graph: each vessel runs from a node to a node, a node being an end
//! (`{"end": id}`) or a junction (`{"junction": id}`), and each end says whether it is an inlet.
//! A tree has one inlet and no cycle; a network with loops and several inlets fits the same
//! description.

use super::centerline::{sample_at, Sample};
use super::layout::Layout;
use super::model::Finish;
use super::model::NearPass;
use crate::implicit_surface::{EndCircle, ImplicitFunction, TriangulatedSurface};
use crate::input::{CenterlinePolyline, Centerlines};
use indexmap::IndexMap;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use serde::Serialize;
use std::path::PathBuf;

/// Version of the generator: a tree is the same tree for a seed within a version.
pub const GENERATOR_VERSION: u32 = 2;

fn xyz(p: &Point3<f64>) -> [f64; 3] {
    [p.x, p.y, p.z]
}

fn vec3(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// A node of the vessel graph.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
#[serde(rename_all = "lowercase")]
pub enum Node {
    End(usize),
    Junction(usize),
}

/// A component of the lumen: a vessel or an aneurysm's sac.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
#[serde(rename_all = "lowercase")]
pub enum Component {
    Vessel(usize),
    Aneurysm(usize),
}

#[derive(Debug, Clone, Serialize)]
pub struct EndTruth {
    pub id: usize,
    pub vessel: usize,
    /// "inlet" or "outlet".
    pub role: &'static str,
    /// "open" (a boundary loop on the end circle) or "capped" (a flat disc).
    pub kind: &'static str,
    pub centre: [f64; 3],
    pub outward_normal: [f64; 3],
    pub radius_mm: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct VesselTruth {
    pub id: usize,
    pub parent: Option<usize>,
    pub start: Node,
    pub end: Node,
    pub radius_start_mm: f64,
    pub radius_end_mm: f64,
    pub smallest_radius_mm: f64,
    /// Fraction of the start radius lost along the body.
    pub taper: f64,
    /// In [0, 1]: 0 straight, 1 arcs turning up to 75° every 1.5 to 4 radii.
    pub tortuosity: f64,
    pub length_mm: f64,
    /// Where the vessel blends with its host and siblings (absent for the root): the segment
    /// and the distance within which the blend is full.
    pub blend_zone: Option<BlendZone>,
    /// x, y, z, lumen radius (mm) along the centerline, from the start.
    pub centerline: Vec<[f64; 4]>,
}

#[derive(Debug, Clone, Serialize)]
pub struct BlendZone {
    pub from: [f64; 3],
    pub to: [f64; 3],
    pub radius_mm: f64,
    pub blend_width_mm: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct JunctionTruth {
    pub id: usize,
    pub host_vessel: usize,
    /// "terminal" (the host ends here) or "side" (the host goes on).
    pub kind: &'static str,
    /// The host's centerline point half-way between the first and the last anchor.
    pub centre: [f64; 3],
    /// Branches at this place: the host in, the host out when it goes on, and each daughter.
    pub branches: usize,
    pub daughters: Vec<usize>,
    pub anchors: Vec<[f64; 3]>,
    pub anchor_arclength_mm: Vec<f64>,
    /// Distance between consecutive anchors along the host, in host radii (at the first).
    pub spacing_parent_radii: Vec<f64>,
    /// Each daughter's start radius over the host's radius at its anchor.
    pub radius_ratios: Vec<f64>,
    /// Angle between each daughter's direction and the host's downstream tangent at its anchor.
    pub branch_angles_deg: Vec<f64>,
    /// Angle of each daughter after the first out of the plane of the host's tangent (at the
    /// first anchor) and the first daughter.
    pub out_of_plane_deg: Vec<f64>,
    pub out_of_plane_max_deg: Option<f64>,
    pub min_spacing_parent_radii: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct StenosisTruth {
    pub vessel: usize,
    pub centre: [f64; 3],
    pub arclength_mm: f64,
    pub area_reduction_percent: f64,
    pub length_mm: f64,
    pub reference_radius_mm: f64,
    pub throat_radius_mm: f64,
    /// 0: concentric; 1: the spared wall stays where it was.
    pub eccentricity: f64,
    pub spared_wall_direction: [f64; 3],
}

#[derive(Debug, Clone, Serialize)]
pub struct AneurysmTruth {
    pub id: usize,
    pub vessel: usize,
    pub arclength_mm: f64,
    pub neck_centre: [f64; 3],
    pub sac_centre: [f64; 3],
    pub dome_tip: [f64; 3],
    pub direction: [f64; 3],
    pub sac_radius_mm: f64,
    pub neck_radius_mm: f64,
    /// From the vessel's wall to the dome's tip, in the vessel's radii.
    pub height_vessel_radii: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct HairpinTruth {
    pub vessel: usize,
    pub start: [f64; 3],
    pub end: [f64; 3],
    pub arclength_mm: f64,
    pub turn_deg: f64,
    pub arc_length_radii: f64,
    pub curvature_radius_radii: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct NearPassTruth {
    pub between: [Component; 2],
    pub points: [[f64; 3]; 2],
    pub gap_mm: f64,
    pub gap_smaller_radii: f64,
    pub gap_larger_radii: f64,
    /// Drawn on purpose (a daughter steered past the vessel), or met by chance.
    pub steered: bool,
}

/// The tree's bins (issue 46's table) and the values behind them.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Bins {
    pub branches_at_one_place: String,
    pub out_of_plane_deg: String,
    pub daughter_spacing_radii: String,
    pub radius_ratio: String,
    pub stenosis_area_percent: String,
    pub near_pass_smaller_radii: String,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Extremes {
    pub max_branches_at_one_place: Option<usize>,
    pub max_out_of_plane_deg: Option<f64>,
    pub min_daughter_spacing_radii: Option<f64>,
    pub min_radius_ratio: Option<f64>,
    pub min_branch_angle_deg: Option<f64>,
    pub max_branch_angle_deg: Option<f64>,
    pub max_stenosis_area_percent: Option<f64>,
    pub min_near_pass_smaller_radii: Option<f64>,
    pub smallest_radius_mm: f64,
    pub largest_radius_mm: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Redraw {
    pub attempt: u32,
    pub reason: String,
}

#[derive(Debug, Clone, Serialize)]
pub struct Manifest {
    pub format: &'static str,
    pub generator_version: u32,
    pub seed: u64,
    /// The draw that passed its checks; earlier ones failed for the reasons in `redrawn`.
    pub attempt: u32,
    pub redrawn: Vec<Redraw>,
    pub units: &'static str,
    pub files: IndexMap<&'static str, String>,
    pub draws: IndexMap<&'static str, serde_json::Value>,
    pub grid: IndexMap<&'static str, f64>,
    pub surface: IndexMap<&'static str, serde_json::Value>,
    pub bins: Bins,
    pub extremes: Extremes,
    pub ends: Vec<EndTruth>,
    pub vessels: Vec<VesselTruth>,
    pub junctions: Vec<JunctionTruth>,
    pub stenoses: Vec<StenosisTruth>,
    pub aneurysms: Vec<AneurysmTruth>,
    pub hairpins: Vec<HairpinTruth>,
    pub near_passes: Vec<NearPassTruth>,
}

/// The ends of a laid tree in their order: the inlet (the root's start), then each vessel's
/// free end in vessel order; with the vessel of each.
pub fn end_circles(layout: &Layout) -> Vec<(usize, EndCircle)> {
    let beyond = |q: &Sample| layout.extension + q.r + 2.0 * layout.h;
    let mut out = Vec::new();
    let root = layout.vessels[0].first();
    out.push((
        0,
        EndCircle {
            centre: root.p,
            outward: -root.t,
            radius: root.r,
            capped: layout.inlet_capped,
            beyond: beyond(root),
        },
    ));
    for (id, v) in layout.vessels.iter().enumerate() {
        if v.finish == Finish::Free {
            let q = v.last();
            let capped = layout.end_capped[id];
            out.push((id, EndCircle { centre: q.p, outward: q.t, radius: q.r, capped, beyond: beyond(q) }));
        }
    }
    out
}

/// The junctions' measured figures.
pub fn junctions(layout: &Layout) -> Vec<JunctionTruth> {
    layout
        .places
        .iter()
        .enumerate()
        .map(|(id, place)| {
            let host = &layout.vessels[place.host].samples;
            let at = |s: f64| sample_at(host, s);
            let first = at(place.anchors[0]);
            let last = *place.anchors.last().unwrap_or(&place.anchors[0]);
            let starts: Vec<Sample> = place.daughters.iter().map(|&d| *layout.vessels[d].first()).collect();
            let ratios = starts.iter().zip(&place.anchors).map(|(q, &s)| q.r / at(s).r).collect();
            let angles =
                starts.iter().zip(&place.anchors).map(|(q, &s)| q.t.angle(&at(s).t).to_degrees()).collect::<Vec<f64>>();
            let plane = first.t.cross(&starts[0].t).try_normalize(1e-12);
            let out_of_plane: Vec<f64> = starts[1..]
                .iter()
                .map(|q| plane.map_or(90.0, |n| q.t.dot(&n).abs().clamp(0.0, 1.0).asin().to_degrees()))
                .collect();
            let spacing: Vec<f64> = place.anchors.windows(2).map(|w| (w[1] - w[0]) / first.r).collect();
            JunctionTruth {
                id,
                host_vessel: place.host,
                kind: if place.terminal { "terminal" } else { "side" },
                centre: xyz(&at(0.5 * (place.anchors[0] + last)).p),
                branches: place.daughters.len() + if place.terminal { 1 } else { 2 },
                daughters: place.daughters.clone(),
                anchors: place.anchors.iter().map(|&s| xyz(&at(s).p)).collect(),
                anchor_arclength_mm: place.anchors.clone(),
                out_of_plane_max_deg: out_of_plane.iter().copied().reduce(f64::max),
                min_spacing_parent_radii: spacing.iter().copied().reduce(f64::min),
                spacing_parent_radii: spacing,
                radius_ratios: ratios,
                branch_angles_deg: angles,
                out_of_plane_deg: out_of_plane,
            }
        })
        .collect()
}

fn bin(value: Option<f64>, edges: &[(f64, &str)], last: &str) -> String {
    match value {
        None => "none".into(),
        Some(v) => edges.iter().find(|(edge, _)| v < *edge).map_or(last, |(_, name)| name).to_string(),
    }
}

/// The tree's extremes and bins: per tree the hardest value of each (most branches at one
/// place, largest out-of-plane angle, closest daughters, smallest radius ratio, tightest
/// stenosis, closest near pass).
pub fn bins(layout: &Layout, junctions: &[JunctionTruth], passes: &[NearPassTruth]) -> (Bins, Extremes) {
    let fold = |it: &mut dyn Iterator<Item = f64>, max: bool| it.reduce(if max { f64::max } else { f64::min });
    let radii = layout.vessels.iter().flat_map(|v| v.samples.iter().map(|q| q.r));
    let (smallest, largest) = radii.fold((f64::INFINITY, 0.0f64), |(a, b), r| (a.min(r), b.max(r)));
    let e = Extremes {
        max_branches_at_one_place: junctions.iter().map(|j| j.branches).max(),
        max_out_of_plane_deg: fold(&mut junctions.iter().filter_map(|j| j.out_of_plane_max_deg), true),
        min_daughter_spacing_radii: fold(&mut junctions.iter().filter_map(|j| j.min_spacing_parent_radii), false),
        min_radius_ratio: fold(&mut junctions.iter().flat_map(|j| j.radius_ratios.iter().copied()), false),
        min_branch_angle_deg: fold(&mut junctions.iter().flat_map(|j| j.branch_angles_deg.iter().copied()), false),
        max_branch_angle_deg: fold(&mut junctions.iter().flat_map(|j| j.branch_angles_deg.iter().copied()), true),
        max_stenosis_area_percent: fold(&mut layout.stenoses.iter().map(|s| 100.0 * s.area_reduction), true),
        min_near_pass_smaller_radii: fold(&mut passes.iter().map(|p| p.gap_smaller_radii), false),
        smallest_radius_mm: smallest,
        largest_radius_mm: largest,
    };
    let b = Bins {
        branches_at_one_place: e.max_branches_at_one_place.map_or("none".into(), |n| n.to_string()),
        out_of_plane_deg: bin(e.max_out_of_plane_deg, &[(15.0, "0-15"), (30.0, "15-30"), (60.0, "30-60")], "60-90"),
        daughter_spacing_radii: bin(
            e.min_daughter_spacing_radii,
            &[(1e-9, "0"), (0.3, "0-0.3"), (1.0, "0.3-1"), (2.0, "1-2")],
            "2-3",
        ),
        radius_ratio: bin(e.min_radius_ratio, &[(0.3, "0.15-0.3"), (0.5, "0.3-0.5"), (0.75, "0.5-0.75")], "0.75-1"),
        stenosis_area_percent: bin(e.max_stenosis_area_percent, &[(70.0, "50-70"), (80.0, "70-80")], "80-90"),
        near_pass_smaller_radii: bin(e.min_near_pass_smaller_radii, &[(0.3, "0-0.3"), (0.5, "0.3-0.5")], "0.5-1"),
    };
    (b, e)
}

/// The near passes for the manifest, with whether each was steered.
pub fn near_passes(layout: &Layout, passes: &[NearPass]) -> Vec<NearPassTruth> {
    let count = layout.vessels.len();
    let component = |c: usize| if c < count { Component::Vessel(c) } else { Component::Aneurysm(c - count) };
    passes
        .iter()
        .map(|p| {
            let steered =
                layout.steered.iter().any(|s| (s.vessel, s.other) == (p.a, p.b) || (s.vessel, s.other) == (p.b, p.a));
            NearPassTruth {
                between: [component(p.a), component(p.b)],
                points: [xyz(&p.point_a), xyz(&p.point_b)],
                gap_mm: p.gap,
                gap_smaller_radii: p.gap / p.radius_a.min(p.radius_b),
                gap_larger_radii: p.gap / p.radius_a.max(p.radius_b),
                steered,
            }
        })
        .collect()
}

/// Every vessel: its graph nodes, radii, shape draws and centerline.
pub fn vessels(layout: &Layout, ends: &[(usize, EndCircle)]) -> Vec<VesselTruth> {
    layout
        .vessels
        .iter()
        .enumerate()
        .map(|(id, v)| {
            let free_end = ends.iter().skip(1).position(|(vessel, _)| *vessel == id).map(|i| i + 1);
            VesselTruth {
                id,
                parent: v.parent,
                start: match v.place {
                    Some(p) => Node::Junction(p),
                    None => Node::End(0),
                },
                end: match v.finish {
                    Finish::Place(p) => Node::Junction(p),
                    Finish::Free => Node::End(free_end.unwrap_or(0)),
                },
                radius_start_mm: v.first().r,
                radius_end_mm: v.last().r,
                smallest_radius_mm: v.samples.iter().map(|q| q.r).fold(f64::INFINITY, f64::min),
                taper: v.taper,
                tortuosity: v.tortuosity,
                length_mm: v.length(),
                blend_zone: v.zone.as_ref().map(|z| BlendZone {
                    from: xyz(&z.a),
                    to: xyz(&z.b),
                    radius_mm: z.inner,
                    blend_width_mm: z.k,
                }),
                centerline: v.samples.iter().map(|q| [q.p.x, q.p.y, q.p.z, q.r]).collect(),
            }
        })
        .collect()
}

/// Stenoses, aneurysms and hairpins for the manifest.
pub fn features(layout: &Layout) -> (Vec<StenosisTruth>, Vec<AneurysmTruth>, Vec<HairpinTruth>) {
    let stenoses = layout
        .stenoses
        .iter()
        .map(|st| {
            let q = sample_at(&layout.vessels[st.vessel].samples, st.s);
            StenosisTruth {
                vessel: st.vessel,
                centre: xyz(&q.p),
                arclength_mm: st.s,
                area_reduction_percent: 100.0 * st.area_reduction,
                length_mm: 2.0 * st.half_length,
                reference_radius_mm: st.throat_radius / (1.0 - st.area_reduction).sqrt(),
                throat_radius_mm: st.throat_radius,
                eccentricity: st.eccentricity,
                spared_wall_direction: vec3(&st.spared),
            }
        })
        .collect();
    let aneurysms = layout
        .sacs
        .iter()
        .enumerate()
        .map(|(id, sac)| {
            let q = sample_at(&layout.vessels[sac.host].samples, sac.s);
            let tip = sac.centre + sac.direction * sac.radius;
            AneurysmTruth {
                id,
                vessel: sac.host,
                arclength_mm: sac.s,
                neck_centre: xyz(&(q.p + sac.direction * q.r)),
                sac_centre: xyz(&sac.centre),
                dome_tip: xyz(&tip),
                direction: vec3(&sac.direction),
                sac_radius_mm: sac.radius,
                neck_radius_mm: sac.neck_radius,
                height_vessel_radii: ((tip - q.p).norm() - q.r) / q.r,
            }
        })
        .collect();
    let hairpins = layout
        .hairpins
        .iter()
        .map(|hp| {
            let samples = &layout.vessels[hp.vessel].samples;
            let r = sample_at(samples, hp.s).r;
            HairpinTruth {
                vessel: hp.vessel,
                start: xyz(&sample_at(samples, hp.s).p),
                end: xyz(&sample_at(samples, hp.s + hp.length).p),
                arclength_mm: hp.s,
                turn_deg: hp.angle.to_degrees(),
                arc_length_radii: hp.length / r,
                curvature_radius_radii: hp.radius / r,
            }
        })
        .collect();
    (stenoses, aneurysms, hairpins)
}

/// The radius of each point of `lines` (points with their arc lengths, as [`dense_points`]
/// gives them): its distance to the lumen surface `F = 0`, found from the nearest surface vertex
/// off the flat caps; `None` when a point has no closest surface point.
pub fn surface_radii(
    f: &(impl ImplicitFunction + ?Sized),
    surface: &TriangulatedSurface,
    lines: &[Vec<(Point3<f64>, f64)>],
) -> Option<Vec<Vec<f64>>> {
    use kiddo::{ImmutableKdTree, SquaredEuclidean};
    // Seeds on F = 0 only (a flat cap's vertices lie inside the tube it closes).
    let on_lumen: Vec<Point3<f64>> =
        surface.vertices.iter().filter(|p| f.distance_estimate(p) <= 1e-9 * (1.0 + p.coords.norm())).copied().collect();
    let points: Vec<[f64; 3]> = on_lumen.iter().map(|p| [p.x, p.y, p.z]).collect();
    let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&points).ok()?;
    let radii: Vec<Option<Vec<f64>>> = lines
        .par_iter()
        .map(|pts| {
            pts.iter()
                .map(|(p, _)| {
                    let nearest = tree.query(&[p.x, p.y, p.z]).nearest_one::<SquaredEuclidean<f64>>().execute();
                    let seed = on_lumen[nearest.item as usize];
                    f.closest_point(p, &seed).map(|q| (q - p).norm())
                })
                .collect()
        })
        .collect();
    radii.into_iter().collect()
}

/// The points of a vessel's centerline for the centerlines file: its samples with points added
/// so that none is more than half the local radius from the next.
pub fn dense_points(samples: &[Sample]) -> Vec<(Point3<f64>, f64)> {
    let mut out = vec![(samples[0].p, samples[0].s)];
    for w in samples.windows(2) {
        let n = ((w[1].s - w[0].s) / (0.5 * w[0].r.min(w[1].r))).ceil().max(1.0) as usize;
        for i in 1..=n {
            let u = i as f64 / n as f64;
            out.push((if i == n { w[1].p } else { w[0].p + (w[1].p - w[0].p) * u }, w[0].s + (w[1].s - w[0].s) * u));
        }
    }
    out
}

/// VMTK-style centerlines: one polyline per outlet from the inlet (along each host up to the
/// next vessel's anchor, then along that vessel; shared stretches sampled identically), with
/// `MaximumInscribedSphereRadius` the distance to the lumen surface `F = 0` (found from the
/// nearest surface vertex off the flat caps; at a capped end, the tube's radius, not the cap's
/// zero distance) and `CenterlineIds`.
pub fn centerlines(
    layout: &Layout,
    f: &(impl ImplicitFunction + ?Sized),
    surface: &TriangulatedSurface,
    ends: &[(usize, EndCircle)],
    name: &str,
) -> Option<Centerlines> {
    let per_vessel: Vec<Vec<(Point3<f64>, f64)>> = layout.vessels.iter().map(|v| dense_points(&v.samples)).collect();
    let radii = surface_radii(f, surface, &per_vessel)?;
    let mut polylines = Vec::new();
    for (id, (vessel, _)) in ends.iter().enumerate().skip(1) {
        let mut chain = vec![*vessel];
        while let Some(parent) = layout.vessels[*chain.last().unwrap_or(vessel)].parent {
            chain.push(parent);
        }
        chain.reverse();
        let (mut pts, mut rs) = (Vec::new(), Vec::new());
        for (k, &v) in chain.iter().enumerate() {
            let until = chain.get(k + 1).map(|&next| {
                let place = &layout.places[layout.vessels[next].place.unwrap_or(0)];
                place.anchors[place.daughters.iter().position(|&d| d == next).unwrap_or(0)]
            });
            for (i, (p, s)) in per_vessel[v].iter().enumerate() {
                if (k > 0 && i == 0) || until.is_some_and(|u| *s > u + 1e-9) {
                    continue;
                }
                pts.push(*p);
                rs.push(radii[v][i]);
            }
        }
        let mut cell_tags = IndexMap::new();
        cell_tags.insert("CenterlineIds".to_string(), (id - 1) as i64);
        polylines.push(CenterlinePolyline { points: pts, radii: Some(rs), normals: None, cell_tags });
    }
    Some(Centerlines { polylines, source: PathBuf::from(format!("{name} (synthetic)")) })
}
