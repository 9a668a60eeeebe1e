//! `report.json`: element counts, quality per region, surface fidelity and timings.

use crate::data::config::{MeshConfig, WallGrowth};
pub use crate::data::diagnostics::Warning;
use crate::data::units::LengthUnit;
use crate::geometry::mesh::{Region, VesselMesh};
use crate::geometry::quality::{Bars, Stats};
use crate::geometry::surface::TriangleSurface;
use crate::io::input::HygieneReport;
pub use crate::pipeline::ends::EndReport;
use crate::pipeline::ends::{end_reports, ends_cut_short, ends_left_out, ends_not_meshed};
use crate::pipeline::MeshedVessel;
use crate::stages::annotation::accuracy::SurfaceAccuracy;
use crate::stages::annotation::end_names::mesh_ends_at;
use crate::stages::annotation::Meshed;
use crate::stages::volume::JunctionWall;
use indexmap::IndexMap;
use serde::Serialize;
use std::path::Path;

#[derive(Debug, Clone, Serialize)]
pub struct RegionReport {
    pub elements: usize,
    pub nodes: usize,
    pub scaled_jacobian: Stats,
    pub equiangle_skew: Stats,
    /// OpenFOAM's face pyramids ([`crate::geometry::quality::face_pyramid_ratio`]): checkMesh fails a mesh
    /// whose minimum is not positive.
    pub face_pyramid: Stats,
}

#[derive(Debug, Clone, Serialize)]
pub struct LayerReport {
    pub name: &'static str,
    pub elements: usize,
    pub radial_elements: usize,
    pub thickness_fraction: f64,
    pub fibre_angle_deg: f64,
    pub scaled_jacobian: Stats,
    pub equiangle_skew: Stats,
}

#[derive(Debug, Clone, Serialize)]
pub struct WallReport {
    #[serde(flatten)]
    pub all: RegionReport,
    pub layers: Vec<LayerReport>,
}

#[derive(Debug, Clone, Serialize)]
pub struct BranchReport {
    pub name: String,
    /// Length of the centerline, and the meshed stretch along it (output unit).
    pub centerline_length: f64,
    pub meshed_from: f64,
    pub meshed_to: f64,
    pub stations: usize,
    pub circumferential_elements: usize,
    /// "open", "closed" (a vessel end) or "junction".
    pub inlet_end: &'static str,
    pub outlet_end: &'static str,
    /// Elements of the branch (lumen and wall, its junction transitions included).
    pub elements: usize,
    pub scaled_jacobian: Stats,
}

/// Quality at one junction: the elements of its branches' transitions.
#[derive(Debug, Clone, Serialize)]
pub struct JunctionReport {
    /// Centre and radius (output unit).
    pub centre: [f64; 3],
    pub radius: f64,
    /// Branches counter-clockwise about the spine (a book), or the parent first (sectors).
    pub branches: Vec<String>,
    /// How the branches' folds meet: `book` (pages about a straight spine) or `sectors`
    /// (around a non-planar junction; see docs/guide/junctions.md).
    pub arrangement: &'static str,
    /// The book's spine (null for sectors).
    pub spine_axis: Option<[f64; 3]>,
    /// How the wall grew from the junction's lumen-surface nodes: `smoothed_normal`, `normal`
    /// or `ray` (the best of them, see docs/guide/junctions.md).
    pub wall_growth: crate::stages::volume::JunctionWall,
    /// Whether the transitions' lumen-surface nodes were slid on the triangles to raise the
    /// worst element (see docs/guide/junctions.md).
    pub surface_nodes_slid: bool,
    /// Whether the optimisation also ran its pattern search (tried when the worst junction
    /// element is below 0.3).
    pub pattern_search: bool,
    /// Whether the pages' nodes moved in the optimisation too (tried with the pattern search).
    pub pages_moved: bool,
    /// Whether the transitions' lumen-surface quads were smoothed on the triangles (tried when
    /// the finishes as projected are short of a bar).
    pub surface_smoothed: bool,
    pub elements: usize,
    /// Elements (lumen and wall) in the sac of a saccular aneurysm that holds the junction (0
    /// where none does; see docs/guide/outputs.md).
    pub sac_elements: usize,
    pub scaled_jacobian: Stats,
    pub lumen_equiangle_skew: Stats,
}

#[derive(Debug, Clone, Serialize)]
pub struct InputReport {
    pub surface: String,
    pub centerlines: String,
    pub units: LengthUnit,
    pub surface_triangles: usize,
    /// +1: the surface triangles face out of the lumen; -1: into it.
    pub surface_orientation: &'static str,
    /// What surface hygiene changed before meshing.
    pub hygiene: crate::io::input::HygieneReport,
}

#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub vesselhex_version: &'static str,
    pub length_unit: LengthUnit,
    pub length_unit_in_m: f64,
    pub input: InputReport,
    pub elements: usize,
    pub nodes: usize,
    pub lumen: RegionReport,
    pub wall: WallReport,
    pub surface_accuracy: SurfaceAccuracy,
    /// Every vessel end, meshed or not (a vessel is never dropped in silence).
    pub ends: Vec<EndReport>,
    /// Refinement, segmented walls and flow extensions, when asked for (nothing otherwise).
    #[serde(flatten)]
    pub additions: crate::pipeline::finishing::Additions,
    pub branches: Vec<BranchReport>,
    pub junctions: Vec<JunctionReport>,
    /// Whether the mesh meets every quality bar ([`Bars`]); when not, `warnings` names the bar
    /// and the place.
    pub within_bars: bool,
    /// What the user should know about a result that was still written: a bar missed, an input
    /// repaired, a doubt about units. Each is also printed on stderr.
    pub warnings: Vec<Warning>,
    /// Seconds per stage (zeros with `--reproducible`, so the report is byte-identical).
    pub timings_s: IndexMap<String, f64>,
    pub outputs: Vec<String>,
    pub config: crate::data::config::MeshConfig,
}

/// One warning per quality bar ([`Bars`]) the mesh misses, naming the figure and, for the
/// worst element, where it is.
pub fn bar_warnings(mesh: &VesselMesh) -> Vec<Warning> {
    let mut out = vec![];
    let lumen = lumen_report(mesh);
    let wall = wall_report(mesh);
    if let Some((e, q)) = mesh
        .quality
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.scaled_jacobian.total_cmp(&b.1.scaled_jacobian))
        .filter(|(_, q)| q.scaled_jacobian < Bars::MIN_SCALED_JACOBIAN)
    {
        let below = mesh.quality.iter().filter(|q| q.scaled_jacobian < Bars::MIN_SCALED_JACOBIAN).count();
        let c = crate::geometry::mesh::element_centre(&mesh.corners(e));
        out.push(Warning::new(
            "quality_bar",
            format!(
                "minimum scaled Jacobian {:.3} is below the bar {}: element {} ({}, branch {}) near ({:.3}, {:.3}, \
                 {:.3}) mm, {below} element(s) below",
                q.scaled_jacobian,
                Bars::MIN_SCALED_JACOBIAN,
                e + 1,
                mesh.regions[e].name(),
                mesh.branch_of[e],
                c.x,
                c.y,
                c.z
            ),
        ));
    }
    out.extend(pyramid_warning(mesh));
    if wall.all.elements > 0 && wall.all.scaled_jacobian.mean < Bars::WALL_MEAN_SCALED_JACOBIAN {
        out.push(Warning::new(
            "quality_bar",
            format!(
                "wall mean scaled Jacobian {:.3} is below the bar {}",
                wall.all.scaled_jacobian.mean,
                Bars::WALL_MEAN_SCALED_JACOBIAN
            ),
        ));
    }
    if lumen.elements > 0 && lumen.equiangle_skew.mean > Bars::LUMEN_MEAN_SKEW {
        out.push(Warning::new(
            "quality_bar",
            format!(
                "lumen mean equi-angle skew {:.3} is above the bar {}",
                lumen.equiangle_skew.mean,
                Bars::LUMEN_MEAN_SKEW
            ),
        ));
    }
    out
}

/// The warning for elements whose face pyramids are not all positive: OpenFOAM's checkMesh fails
/// such a mesh ("Error in face pyramids") whatever its scaled Jacobians, so it is not within the
/// bars.
fn pyramid_warning(mesh: &VesselMesh) -> Option<Warning> {
    let (e, q) = mesh.quality.iter().enumerate().min_by(|a, b| a.1.face_pyramid.total_cmp(&b.1.face_pyramid))?;
    if q.face_pyramid > Bars::MIN_FACE_PYRAMID {
        return None;
    }
    let below =
        mesh.quality.iter().filter(|q| q.face_pyramid.is_nan() || q.face_pyramid <= Bars::MIN_FACE_PYRAMID).count();
    let c = crate::geometry::mesh::element_centre(&mesh.corners(e));
    Some(Warning::new(
        "quality_bar",
        format!(
            "element {} ({}, branch {}) near ({:.3}, {:.3}, {:.3}) mm has a face pyramid of {:.3} (a sixth of its volume \
             is 1): OpenFOAM's checkMesh fails a cell whose centre lies outside a face's plane; {below} element(s) so",
            e + 1,
            mesh.regions[e].name(),
            mesh.branch_of[e],
            c.x,
            c.y,
            c.z,
            q.face_pyramid
        ),
    ))
}

fn region_report(mesh: &VesselMesh, range: std::ops::Range<usize>) -> RegionReport {
    RegionReport {
        elements: range.len(),
        nodes: mesh.nodes_of(range.clone()).len(),
        scaled_jacobian: Stats::of(mesh.quality[range.clone()].iter().map(|q| q.scaled_jacobian)),
        equiangle_skew: Stats::of(mesh.quality[range.clone()].iter().map(|q| q.equiangle_skew)),
        face_pyramid: Stats::of(mesh.quality[range].iter().map(|q| q.face_pyramid)),
    }
}

pub fn lumen_report(mesh: &VesselMesh) -> RegionReport {
    region_report(mesh, mesh.lumen_range())
}

pub fn wall_report(mesh: &VesselMesh) -> WallReport {
    let layers = mesh
        .layers
        .iter()
        .map(|l| {
            let r = region_report(mesh, mesh.region_range(l.region));
            LayerReport {
                name: l.region.name(),
                elements: r.elements,
                radial_elements: l.radial_elements,
                thickness_fraction: l.thickness_fraction,
                fibre_angle_deg: l.fibre_angle_deg,
                scaled_jacobian: r.scaled_jacobian,
                equiangle_skew: r.equiangle_skew,
            }
        })
        .collect();
    WallReport { all: region_report(mesh, mesh.wall_range()), layers }
}

/// Quality of a region, for callers that need one figure.
pub fn region_quality(mesh: &VesselMesh, region: Region) -> Stats {
    Stats::of(mesh.quality[mesh.region_range(region)].iter().map(|q| q.scaled_jacobian))
}

fn end_kind(end: &crate::stages::projection::BranchEnd) -> &'static str {
    match end {
        crate::stages::projection::BranchEnd::Vessel { closed: true } => "closed",
        crate::stages::projection::BranchEnd::Vessel { closed: false } => "open",
        crate::stages::projection::BranchEnd::Fold(_) => "junction",
        crate::stages::projection::BranchEnd::Dome => "dome",
    }
}

fn build_report(
    meshed: &Meshed,
    surface: &TriangleSurface,
    centerline_path: &Path,
    config: &MeshConfig,
    timings: &[(String, f64)],
    mut warnings: Vec<Warning>,
) -> Report {
    let mesh = &meshed.mesh;
    let unit = config.output_units;
    let scale = unit.from_mm();
    let branches = meshed
        .tree
        .branches
        .iter()
        .zip(&meshed.projected)
        .map(|(b, p)| BranchReport {
            name: b.name.clone(),
            centerline_length: b.length() * scale,
            meshed_from: p.s_start * scale,
            meshed_to: p.s_end * scale,
            stations: p.sections.len(),
            circumferential_elements: meshed.templates[p.branch].ring_len(),
            inlet_end: end_kind(&p.start),
            outlet_end: end_kind(&p.end),
            elements: mesh.branch_of.iter().filter(|&&x| x as usize == p.branch).count(),
            scaled_jacobian: Stats::of(
                (0..mesh.hexes.len())
                    .filter(|&e| mesh.branch_of[e] as usize == p.branch)
                    .map(|e| mesh.quality[e].scaled_jacobian),
            ),
        })
        .collect();
    let junctions = meshed
        .junctions
        .iter()
        .map(|g| {
            let elements: Vec<usize> =
                (0..mesh.hexes.len()).filter(|&e| meshed.junction_of[e] == Some(g.index)).collect();
            JunctionReport {
                centre: (g.centre.coords * scale).into(),
                radius: g.radius * scale,
                branches: g.slots.iter().map(|s| meshed.tree.branches[s.branch].name.clone()).collect(),
                arrangement: g.arrangement_name(),
                spine_axis: g.spine_axis().map(Into::into),
                wall_growth: match config.wall.growth {
                    WallGrowth::Ray => JunctionWall::Ray,
                    WallGrowth::Normal => meshed.junction_variants[g.index].wall,
                },
                surface_nodes_slid: meshed.junction_variants[g.index].optimisation.slide_surface_nodes,
                pattern_search: meshed.junction_variants[g.index].optimisation.pattern_search,
                pages_moved: meshed.junction_variants[g.index].optimisation.move_pages,
                surface_smoothed: meshed.junction_variants[g.index].optimisation.smooth_surface,
                elements: elements.len(),
                // A sac branch's transition is the junction's too, but the sac is the branch's.
                sac_elements: if crate::stages::annotation::sacs::holds_sac(g) {
                    elements.iter().filter(|&&e| mesh.sac[e]).count()
                } else {
                    0
                },
                scaled_jacobian: Stats::of(elements.iter().map(|&e| mesh.quality[e].scaled_jacobian)),
                lumen_equiangle_skew: Stats::of(
                    elements.iter().filter(|&&e| !mesh.regions[e].is_wall()).map(|&e| mesh.quality[e].equiangle_skew),
                ),
            }
        })
        .collect();
    let normals_outward = meshed.projected.first().is_none_or(|p| p.normals_outward);
    let bars = bar_warnings(mesh);
    let within_bars = bars.is_empty();
    warnings.extend(bars);
    warnings.extend(meshed.accuracy.unmeshed_warning().map(|w| Warning::new("surface_not_meshed", w)));
    Report {
        vesselhex_version: env!("CARGO_PKG_VERSION"),
        length_unit: unit,
        length_unit_in_m: unit.in_metres(),
        input: InputReport {
            surface: surface.source.display().to_string(),
            centerlines: centerline_path.display().to_string(),
            units: config.units,
            surface_triangles: surface.triangles.len(),
            surface_orientation: if normals_outward { "outward" } else { "inward" },
            hygiene: HygieneReport::default(),
        },
        elements: mesh.hexes.len(),
        nodes: mesh.nodes.len(),
        lumen: lumen_report(mesh),
        wall: wall_report(mesh),
        surface_accuracy: meshed.accuracy.clone(),
        ends: vec![],
        additions: Default::default(),
        branches,
        junctions,
        within_bars,
        warnings,
        timings_s: stage_totals(timings),
        outputs: vec![],
        config: config.clone(),
    }
}

/// The report of a meshed vessel as `write_vessel` would write it with `config`, without
/// writing anything (no outputs listed); timings as given.
pub fn vessel_report(vessel: &MeshedVessel, config: &MeshConfig, timings: &[(String, f64)]) -> Report {
    let mut warnings = vessel.settings.warnings.clone();
    let side_ends: Vec<[f64; 3]> = vessel.additions.side_ends.iter().map(|s| s.centre).collect();
    let mut ends =
        end_reports(&vessel.ends, &vessel.inlets, &vessel.meshed.tree, &side_ends, config.output_units.from_mm());
    let mesh = &vessel.meshed.mesh;
    for ((report, at), given) in ends.iter_mut().zip(mesh_ends_at(mesh, &vessel.ends)).zip(&vessel.end_names) {
        report.name = at.map(|m| mesh.ends[m].name.clone()).or_else(|| given.clone());
    }
    let left_out = ends_left_out(&vessel.ends, &vessel.left_out_mm);
    warnings.extend(ends_not_meshed(&ends, &left_out, config.output_units));
    warnings.extend(ends_cut_short(&vessel.meshed, config));
    let mut report =
        build_report(&vessel.meshed, &vessel.surface, &vessel.centerline_source, config, timings, warnings);
    report.ends = ends;
    report.input.hygiene = vessel.hygiene.clone();
    report.additions = vessel.additions.clone().scaled(config.output_units.from_mm());
    report
}

/// Seconds per stage, summed over every time the stage ran: a vessel meshed again (a junction
/// laid out in sectors after books, a sac or a stub left out, a merged junction centred
/// elsewhere) runs its stages again, and each run counts (keeping the last alone hid most of a
/// large tree's time: random tree 65 reported 12 of its 127 s).
fn stage_totals(timings: &[(String, f64)]) -> IndexMap<String, f64> {
    let mut totals: IndexMap<String, f64> = IndexMap::new();
    for (stage, seconds) in timings {
        *totals.entry(stage.clone()).or_default() += seconds;
    }
    totals
}

#[cfg(test)]
mod tests {
    use super::stage_totals;

    #[test]
    fn a_stage_run_again_counts_every_run_in_first_run_order() {
        let runs = [("projection", 1.0), ("volume", 2.0), ("projection", 0.5), ("writing", 0.25)];
        let timings: Vec<(String, f64)> = runs.iter().map(|(s, t)| (s.to_string(), *t)).collect();
        let totals = stage_totals(&timings);
        let got: Vec<(&str, f64)> = totals.iter().map(|(s, t)| (s.as_str(), *t)).collect();
        assert_eq!(got, vec![("projection", 1.5), ("volume", 2.0), ("writing", 0.25)]);
    }
}
