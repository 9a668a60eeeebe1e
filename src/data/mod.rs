//! Plain data, at the bottom of the house: units, errors, warnings, the vessel's regions and
//! the configuration. Nothing here reads a file, draws on the terminal or knows a stage; every
//! other layer may import it.

pub mod config;
pub mod diagnostics;
pub mod error;
pub mod region;
pub mod units;
