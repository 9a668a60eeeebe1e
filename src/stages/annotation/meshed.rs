//! A vessel meshed and not yet finished or written: the mesh and what was learnt on the way,
//! shared by the pipeline that builds it and the stages that finish it.

use crate::data::diagnostics::Warning;
use crate::geometry::mesh::VesselMesh;
use crate::stages::annotation::accuracy::SurfaceAccuracy;
use crate::stages::centerline::CenterlineTree;
use crate::stages::junction::blocks::SectionTemplate;
use crate::stages::junction::JunctionGeometry;
use crate::stages::projection::ProjectedBranch;
use crate::stages::volume::JunctionVariant;

/// A finished mesh with what was learnt on the way.
pub struct Meshed {
    pub mesh: VesselMesh,
    pub tree: CenterlineTree,
    pub projected: Vec<ProjectedBranch>,
    pub accuracy: SurfaceAccuracy,
    /// Each branch's cross-section template, by branch.
    pub templates: Vec<SectionTemplate>,
    pub junctions: Vec<JunctionGeometry>,
    /// The junction each element belongs to (its branch's transition), if any.
    pub junction_of: Vec<Option<usize>>,
    /// How each junction was finished (wall growth, surface smoothing), by junction index.
    pub junction_variants: Vec<JunctionVariant>,
    /// Where the meshing departed from the settings, and why (a `junction_spacing` warning:
    /// the junctions spaced as at the coarse preset).
    pub notes: Vec<Warning>,
}
