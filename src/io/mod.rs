//! Files in and out: the readers of what users bring (surfaces, centerlines, case files,
//! solver templates), the memory budget they are read within, and the writing primitives every
//! writer shares (files written whole or not at all, the output folder put in place in one
//! rename). Imports [`crate::data`] and [`crate::geometry`] (the surfaces it reads).

pub mod atomic;
pub mod case_file;
pub mod input;
pub mod memory;
pub mod output;
pub mod sink;
pub mod templates;
