//! Annotation, the last stage of every mesh: per element its triad, fibres and quality
//! ([`annotate`]), a sac's elements marked ([`sacs`]), the vessel's ends named ([`end_names`]),
//! the ends flowed into marked ([`inlets`]), the surface's fidelity measured ([`accuracy`]); [`Meshed`] holds the result with what was
//! learnt on the way.

pub mod accuracy;
pub mod annotate;
pub mod end_names;
pub mod inlets;
pub mod meshed;
pub mod sacs;

pub use meshed::Meshed;
