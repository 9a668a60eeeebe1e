//! The stages after the volume that De Santis et al. 2011 describe and a default run does not
//! take: refinement before or after projection ([`crate::stages::additions::refinement`]), walls from segmented
//! surfaces ([`crate::stages::additions::wall_surfaces`]) and flow extensions ([`crate::stages::additions::extensions`]), in that order
//! (the extensions are swept from the finished vessel, whose labels they keep). Each runs only
//! when its settings ask for it: the default mesh is the volume stage's, untouched. Before the
//! extensions, the ends of branches too short to mesh are opened in the side of the mesh when
//! the pipeline asks ([`crate::stages::additions::side_ends`]).

use crate::data::config::MeshConfig;
use crate::data::error::Result;
use crate::geometry::mesh::VesselMesh;
use crate::geometry::surface::LumenSurface;
use crate::io::input::{ReadLimits, TriangleSurface};
use crate::pipeline::progress::Progress;
use crate::stages::additions::extensions::ExtensionReport;
use crate::stages::additions::refinement::{Placement, RefinementReport};
use crate::stages::additions::side_ends::{open_side_end, SideEndReport, SideOpening};
use crate::stages::additions::wall_surfaces::{WallSurface, WallSurfacesReport};
use crate::stages::annotation::meshed::Meshed;
use serde::Serialize;
use std::borrow::Cow;

/// What the added stages did, for report.json (flattened into it; nothing when none ran).
#[derive(Debug, Clone, Default, Serialize)]
pub struct Additions {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refinement: Option<RefinementReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wall_surfaces: Option<WallSurfacesReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub extensions: Option<Vec<ExtensionReport>>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub side_ends: Vec<SideEndReport>,
}

impl Additions {
    /// Lengths from mm into the output unit.
    pub fn scaled(mut self, scale: f64) -> Additions {
        if let Some(w) = &mut self.wall_surfaces {
            for s in [&mut w.grown_thickness, &mut w.thickness] {
                (s.min, s.mean, s.max) = (s.min * scale, s.mean * scale, s.max * scale);
            }
        }
        for e in self.extensions.iter_mut().flatten() {
            e.length *= scale;
            e.radius *= scale;
            e.blend_length *= scale;
            e.end_centre = e.end_centre.map(|x| x * scale);
        }
        self.side_ends = self.side_ends.into_iter().map(|s| s.scaled(scale)).collect();
        self
    }
}

/// Whether any added stage is asked for.
pub fn asked(config: &MeshConfig) -> bool {
    let r = &config.refinement;
    r.before_projection > 1 || r.after_projection > 1 || config.wall.surface.is_some() || config.extensions.is_on()
}

/// How many added stages are asked for (for the progress display).
pub fn stages(config: &MeshConfig) -> u64 {
    let r = &config.refinement;
    [r.before_projection > 1 || r.after_projection > 1, config.wall.surface.is_some(), config.extensions.is_on()]
        .iter()
        .filter(|&&s| s)
        .count() as u64
}

/// Runs the added stages asked for on a finished mesh of `surface`, opening `side_ends` before
/// the extensions (an opening no lumen face lies on is left out of `Additions::side_ends`).
pub fn finish(
    meshed: &mut Meshed,
    surface: &TriangleSurface,
    config: &MeshConfig,
    limits: &ReadLimits,
    progress: &mut Progress,
    side_ends: &[SideOpening],
) -> Result<Additions> {
    check_wall_surfaces(config)?;
    let mut additions = Additions::default();
    let r = &config.refinement;
    if r.before_projection > 1 || r.after_projection > 1 || config.wall.surface.is_some() {
        let lumen = LumenSurface::new(surface)?;
        if r.before_projection > 1 || r.after_projection > 1 {
            progress.stage("refinement");
            additions.refinement = Some(refine_stage(meshed, &lumen, config)?);
        }
        if let Some(outer) = &config.wall.surface {
            progress.stage("wall surfaces");
            additions.wall_surfaces = Some(wall_stage(meshed, &lumen, outer, config, limits)?);
        }
    }
    additions.side_ends = side_ends.iter().filter_map(|o| open_side_end(meshed, o)).collect();
    if config.extensions.is_on() {
        progress.stage("flow extensions");
        let reports = crate::stages::additions::extensions::extend(&mut meshed.mesh, &config.extensions)?;
        meshed.junction_of.resize(meshed.mesh.hexes.len(), None);
        additions.extensions = Some(reports);
    }
    Ok(additions)
}

/// The layers' surfaces (`wall.surfaces`) need the outer wall's (`--wall-surface` or
/// `wall.surface`), which the command line may give after the case file is read.
pub fn check_wall_surfaces(config: &MeshConfig) -> Result<()> {
    if !config.wall.surfaces.is_empty() && config.wall.surface.is_none() {
        return Err(crate::data::error::Error::Config(
            "wall.surfaces: the layers' surfaces need the outer wall's too: give --wall-surface or wall.surface".into(),
        ));
    }
    Ok(())
}

/// Refines the mesh before projection, then after, as `config.refinement` asks; re-measures
/// the surface fidelity.
fn refine_stage(meshed: &mut Meshed, lumen: &LumenSurface, config: &MeshConfig) -> Result<RefinementReport> {
    let r = &config.refinement;
    let coarse_elements = meshed.mesh.hexes.len();
    let mut radial_cells = config.lumen.radial_elements;
    // Projected: the coarse mesh's surface nodes, or the mesh's after refinement before projection.
    let mut projected = crate::stages::additions::refinement::surface_nodes(&meshed.mesh);
    for (k, placement) in
        [(r.before_projection, Placement::BeforeProjection(lumen)), (r.after_projection, Placement::AfterProjection)]
    {
        if k > 1 {
            refine_meshed(meshed, k, placement, radial_cells)?;
            radial_cells *= k;
            if matches!(placement, Placement::BeforeProjection(_)) {
                projected = crate::stages::additions::refinement::surface_nodes(&meshed.mesh);
            }
        }
    }
    meshed.accuracy = crate::stages::annotation::accuracy::surface_accuracy(
        &meshed.mesh,
        lumen,
        &meshed.tree.branches,
        &meshed.projected,
    )?;
    Ok(RefinementReport {
        before_projection: r.before_projection,
        after_projection: r.after_projection,
        coarse_elements,
        elements: meshed.mesh.hexes.len(),
        surface_nodes: crate::stages::additions::refinement::surface_nodes(&meshed.mesh),
        projected_points: projected,
    })
}

/// Reads the segmented wall surfaces (within `limits`) and moves the wall onto them.
fn wall_stage(
    meshed: &mut Meshed,
    lumen: &LumenSurface,
    outer: &std::path::Path,
    config: &MeshConfig,
    limits: &ReadLimits,
) -> Result<WallSurfacesReport> {
    // A point of the lumen, which every wall surface must enclose.
    let lumen_elements = meshed.mesh.lumen_range();
    let inside =
        crate::geometry::mesh::element_centre(&meshed.mesh.corners(lumen_elements.start + lumen_elements.len() / 2));
    let read = |path: &std::path::Path| -> Result<WallSurface> {
        let (s, _) = crate::io::input::read_surface_within(path, config.units, limits)?;
        WallSurface::new(LumenSurface::new(&s)?, &inside)
    };
    let layers = config.wall.surfaces.iter().map(|p| read(p)).collect::<Result<Vec<_>>>()?;
    let outer = read(outer)?;
    crate::stages::additions::wall_surfaces::place(&mut meshed.mesh, lumen, &layers, &outer)
}

/// Refines the mesh of `meshed` (its junction of each element follows).
fn refine_meshed(meshed: &mut Meshed, k: usize, placement: Placement, radial_cells: usize) -> Result<()> {
    meshed.mesh = crate::stages::additions::refinement::refine(&meshed.mesh, k, placement, radial_cells)?;
    let cubes = k * k * k;
    meshed.junction_of = meshed.junction_of.iter().flat_map(|j| std::iter::repeat_n(*j, cubes)).collect();
    Ok(())
}

/// The mesh a format's writer gets: the FE decks model the vessel alone, without its flow
/// extensions (whose walls are not modelled), unless `extensions.fe_decks` gives the fluid-FSI
/// deck the extensions too; the CFD meshes, the VTU and the FSI package (whose fluid is the
/// OpenFOAM case) get everything.
pub fn mesh_for_format<'a>(mesh: &'a VesselMesh, format: &str, config: &MeshConfig) -> Cow<'a, VesselMesh> {
    let vessel_alone = match format {
        "calculix" | "abaqus" | "febio" => true,
        "febio-fsi" => !config.extensions.fe_decks,
        _ => false,
    };
    if vessel_alone {
        crate::stages::additions::extensions::without_extensions(mesh)
    } else {
        Cow::Borrowed(mesh)
    }
}

/// A refined mesh holds k^3 times the elements and nodes, and the coarse one is held while the
/// refined one is built.
pub fn scale_estimate(estimate: &mut crate::pipeline::estimate::MeshEstimate, config: &MeshConfig) {
    let k = (config.refinement.before_projection * config.refinement.after_projection) as f64;
    if k > 1.0 {
        let cubes = k * k * k;
        estimate.hexes *= cubes;
        estimate.nodes *= cubes;
        estimate.bytes *= 1.0 + cubes;
    }
}
