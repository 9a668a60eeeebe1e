//! Errors are values: every failure a user can cause names the file, the place and the fix.

use std::path::PathBuf;

/// The library's error type. `Display` gives the one line the CLI prints.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be opened, read or written.
    #[error("{path}: {what}: {source}")]
    Io {
        path: PathBuf,
        what: &'static str,
        #[source]
        source: std::io::Error,
    },
    /// A file was read but its content is not what the format or the method needs.
    #[error("{path}: {message}")]
    Input { path: PathBuf, message: String },
    /// A parameter (command line or case file) is out of range or inconsistent.
    #[error("invalid setting: {0}")]
    Config(String),
    /// The geometry defeats the method at a known place (a ray that misses, an inverted element).
    #[error("{0}")]
    Geometry(String),
    /// A branch ends too close to its junction for the junction's transition: a geometry
    /// refusal that names the vessel end (mm) it leaves unmeshed, so the vessel can be meshed
    /// without that branch (see `crate::pipeline::mesh_surface`).
    #[error("{message}")]
    ShortBranch { message: String, end_mm: [f64; 3] },
}

impl Error {
    pub fn input(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Error::Input { path: path.into(), message: message.into() }
    }
    pub fn io(path: impl Into<PathBuf>, what: &'static str, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), what, source }
    }
}

pub type Result<T> = std::result::Result<T, Error>;

/// A message on one line (messages from dependencies may span several): the form the command
/// line prints and the Python package raises.
pub fn one_line(text: &str) -> String {
    text.lines().map(str::trim).filter(|l| !l.is_empty()).collect::<Vec<_>>().join(" ")
}
