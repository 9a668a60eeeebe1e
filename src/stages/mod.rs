//! The meshing stages, in the order data flows through them; each may import the stages
//! before it, never one after:
//!
//! 1. [`centerline`]: the centerlines (given, or extracted from the surface) as a tree of
//!    branches and junctions, with frames;
//! 2. [`junction`]: the blocks: each section's O-grid template and the layout of every junction;
//! 3. [`projection`]: the blocks' nodes cast onto the lumen surface, section by section;
//! 4. [`volume`]: the hexahedra of lumen and wall, their nodes optimised;
//! 5. [`annotation`]: triads, fibres, quality, sacs, end names and the surface's fidelity;
//! 6. [`additions`]: what a run adds when asked (refinement, segmented walls, flow extensions,
//!    ends opened in the side of the mesh).
//!
//! The stages read no files and write none; [`crate::pipeline`] runs them.

pub mod additions;
pub mod annotation;
pub mod centerline;
pub mod junction;
pub mod projection;
pub mod volume;
