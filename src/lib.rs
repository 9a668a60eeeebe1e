//! vesselhex: structured hexahedral meshes of blood vessels (lumen O-grid + three-layer wall)
//! for Abaqus, CalculiX, FEBio, OpenFOAM and FSI, after De Santis et al. 2011.
//!
//! Data flows one way, one stage a module:
//! [`input`] -> [`centerline`] -> [`blocks`] -> [`projection`] (over [`surface`]) -> [`volume`]
//! -> [`annotate`] ([`quality`], [`accuracy`]) -> [`writers`] and [`report`]; [`pipeline`] runs
//! them in order. [`finishing`] adds, when asked, refinement before or after projection
//! ([`refinement`]), walls from segmented surfaces ([`wall_surfaces`]) and flow extensions
//! ([`extensions`]) to the annotated mesh. [`batch`] meshes many vessels, each in a process of
//! its own, with a table of results.
pub mod accuracy;
pub mod annotate;
pub mod batch;
pub mod blocks;
pub mod centerline;
pub mod centerline_extract;
pub mod config;
pub mod end_names;
pub mod end_planes;
pub mod error;
pub mod extensions;
pub mod finishing;
pub mod implicit_surface;
pub mod input;
pub mod junction;
pub mod junction_finish;
pub mod mesh;
pub mod meshed;
pub mod node_optimisation;
pub mod output;
pub mod pipeline;
pub mod progress;
pub mod projection;
pub mod quality;
pub mod refinement;
pub mod report;
pub mod resources;
pub mod sacs;
pub mod side_ends;
pub mod surface;
pub mod surface_smoothing;
pub mod synthetic;
pub mod synthetic_branching;
pub mod synthetic_tree;
pub mod testing;
pub mod units;
pub mod volume;
pub mod wall_directions;
pub mod wall_surfaces;
pub mod writers;

pub use error::{Error, Result};
