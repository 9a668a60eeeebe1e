//! vesselhex: structured hexahedral meshes of blood vessels (lumen O-grid + three-layer wall)
//! for Abaqus, CalculiX, FEBio, OpenFOAM and FSI, after De Santis et al. 2011.
//!
//! The crate is built in layers; each imports only the layers below it (docs/ARCHITECTURE.md,
//! kept by tests/architecture.rs):
//!
//! 1. [`data`]: units, errors, warnings, the vessel's regions, the configuration;
//! 2. [`geometry`]: the lumen surface and its queries, the hexahedral mesh, element quality;
//! 3. [`io`]: reading surfaces, centerlines, case files and templates; writing files whole;
//! 4. [`stages`]: centerline -> junction (blocks) -> projection -> volume -> annotation ->
//!    additions, each a function from its input to its output;
//! 5. [`writers`]: one module per format, each reading only the annotated mesh;
//! 6. [`pipeline`]: runs the stages in order, with the retry and fallback policies
//!    ([`pipeline::policy`]), the report and the memory estimate;
//! 7. on top: [`batch`] (many vessels, a process each), [`testing`] and the synthetic vessels
//!    ([`synthetic`], [`synthetic_branching`], the random trees of [`synthetic_tree`], all
//!    triangulated by [`implicit_surface`]); the command line (`main.rs`) and the Python
//!    package (`python/`) call the pipeline.
pub mod batch;
pub mod data;
pub mod geometry;
pub mod implicit_surface;
pub mod io;
pub mod pipeline;
pub mod stages;
pub mod synthetic;
pub mod synthetic_branching;
pub mod synthetic_network;
pub mod synthetic_tree;
pub mod testing;
pub mod writers;

pub use data::error::{Error, Result};

// The library's public names from before the layers (issue 47), so that `vesselhex::mesh`,
// `vesselhex::junction` and the like keep working for the command line, the Python package,
// the tests and the benchmarks. Inside the crate the layered paths are used.
pub use data::{config, error, units};
pub use geometry::{mesh, quality, surface};
pub use io::{input, output};
pub use pipeline::{finishing, progress, report};
pub use stages::additions::{extensions, refinement, side_ends, wall_surfaces};
pub use stages::annotation::{accuracy, annotate, end_names, inlets, meshed, sacs};
pub use stages::centerline::extract as centerline_extract;
pub use stages::junction::blocks;
pub use stages::projection::end_planes;
pub use stages::volume::{node_optimisation, surface_smoothing, wall_directions};
pub use stages::{centerline, junction, projection, volume};
