//! The stages after the volume that De Santis et al. 2011 describe and a default run does not
//! take, each on the annotated mesh when its settings ask: [`refinement`] before or after
//! projection, walls from segmented surfaces ([`wall_surfaces`]), flow extensions
//! ([`extensions`]); and the cap of a branch too short to mesh opened in the side of the mesh
//! ([`side_ends`]). [`crate::pipeline::finishing`] runs them in order.

pub mod extensions;
pub mod refinement;
pub mod side_ends;
pub mod wall_surfaces;
