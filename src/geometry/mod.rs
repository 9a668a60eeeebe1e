//! Geometry and the mesh type: the lumen surface and its queries (ray casts, closest points,
//! winding numbers over a tree of clusters ([`winding`]), a plane's cut), the one hexahedral mesh every stage builds and every writer
//! reads, with its canonical node order and face table, and the quality of its elements.
//! Imports only [`crate::data`].

pub mod mesh;
pub mod plane_cut;
pub mod quality;
pub mod surface;
pub mod surface_cut;
pub mod vector;
pub mod winding;
