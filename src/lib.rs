//! vesselhex: structured hexahedral meshes of blood vessels.
pub mod error;
pub mod input;
pub mod mesh;
pub mod synthetic;
pub mod units;

pub use error::{Error, Result};
