//! Writers: one module per format, each reading only the annotated [`VesselMesh`].
//!
//! `--formats` names rows of [`WRITERS`]; adding a solver is one module and one row.

use crate::error::Result;
use crate::mesh::VesselMesh;
use crate::units::LengthUnit;
use std::path::{Path, PathBuf};

pub mod abaqus;
pub mod calculix;
pub mod febio;
pub mod fsi;
pub mod inp;
pub mod material;
pub mod openfoam;
pub mod schedule;
mod sink;
pub mod template;
pub mod text;
pub mod vtu;

/// What every writer may need besides the mesh.
#[derive(Debug, Clone, Default)]
pub struct WriteOptions {
    /// Length unit of FE outputs (OpenFOAM is always in metres).
    pub length_unit: LengthUnit,
    /// The OpenFOAM case settings (inflow, profile, solver, ASCII or binary).
    pub openfoam: crate::config::OpenFoamConfig,
    /// Materials, loads and controls of the FEBio decks (`[febio]` in the case file).
    pub febio: febio::FebioConfig,
    /// Elements, material template and step of the Abaqus and CalculiX decks (`[fe]`).
    pub fe: inp::FeConfig,
    /// Per-layer wall constants shared by every FE deck (`[material]`).
    pub material: material::WallMaterial,
}

impl WriteOptions {
    /// The writers' share of a configuration.
    pub fn from_config(config: &crate::config::MeshConfig) -> Self {
        WriteOptions {
            length_unit: config.output_units,
            openfoam: config.openfoam.clone(),
            febio: config.febio.clone(),
            fe: config.fe.clone(),
            material: config.material.clone(),
        }
    }
}

/// A writer puts its files under `dir` (a staging folder) and returns their paths relative to it.
pub type WriterFn = fn(&VesselMesh, &WriteOptions, &Path) -> Result<Vec<PathBuf>>;

/// The format table: name, what it writes, writer.
pub const WRITERS: &[(&str, &str, WriterFn)] = &[
    ("vtu", "mesh.vtu: VTK XML unstructured grid for ParaView", vtu::write_vtu),
    (
        "openfoam",
        "openfoam/: polyMesh of the lumen (metres) and a laminar blood-flow case with Allrun",
        openfoam::write_openfoam,
    ),
    (
        "openfoam-fsi",
        "openfoam-fsi/: lumen and wall in one polyMesh, cellZones per layer, interface faceZone, for splitMeshRegions",
        openfoam::write_openfoam_fsi,
    ),
    (
        "febio",
        "febio/wall.feb: FEBio 4.0 wall, HGO layers with per-element fibre axes, lumen pressure",
        febio::write_wall,
    ),
    ("febio-fsi", "febio/fsi.feb: FEBio 4.0 monolithic fluid-FSI model of lumen and wall", febio::write_fsi),
    ("abaqus", "abaqus/model.inp: Abaqus deck of the wall, HGO layers, inflation step", abaqus::write_abaqus),
    (
        "calculix",
        "calculix/model.inp: CalculiX deck of the wall, ELASTIC_FIBER layers, inflation step",
        calculix::write_calculix,
    ),
    (
        "fsi",
        "fsi/: exact fluid-solid interface maps and preCICE files for OpenFOAM + CalculiX (implies openfoam, calculix)",
        fsi::write_fsi,
    ),
];

/// Settings that a requested format cannot write, found before any meshing (the writers check
/// them again when called directly): hex20 in `febio-fsi`, a quadratic CalculiX element in `fsi`,
/// a fibre dispersion in the CalculiX decks (`calculix`, `fsi`).
pub fn check_format_settings(config: &crate::config::MeshConfig) -> Result<()> {
    use crate::error::Error;
    let wants = |f: &str| config.formats.iter().any(|x| x == f);
    if wants("febio-fsi") && config.febio.element == febio::FebioElement::Hex20 {
        return Err(Error::Config(
            "febio.element = \"hex20\" with format febio-fsi: the fluid-FSI deck is hex8 only (lumen and wall share \
             every interface node); write febio-fsi in a run with element = \"hex8\""
                .into(),
        ));
    }
    if wants("fsi") && config.fe.calculix_element.is_quadratic() {
        return Err(Error::Config(format!(
            "fe.calculix_element = {} with format fsi: the FSI package couples bilinear faces only; use C3D8I, C3D8 \
             or C3D8R",
            config.fe.calculix_element.name()
        )));
    }
    if (wants("calculix") || wants("fsi")) && config.fe.material == inp::MaterialModel::Hgo {
        for region in crate::mesh::Region::WALL {
            let kappa = config.material.layer(region).kappa;
            if kappa != 0.0 {
                return Err(Error::Config(format!(
                    "material.{}.kappa = {kappa}: CalculiX's fibre material has no dispersion; set kappa = 0 or \
                     leave out the calculix and fsi formats",
                    region.name()
                )));
            }
        }
    }
    Ok(())
}

/// The writer of a format name.
pub fn writer(name: &str) -> Option<WriterFn> {
    WRITERS.iter().find(|w| w.0 == name).map(|w| w.2)
}

/// Names of all formats, for messages.
pub fn format_names() -> Vec<&'static str> {
    WRITERS.iter().map(|w| w.0).collect()
}

/// Writes a text file at `dir/rel` (creating its folders) through [`write_atomic`]; `executable`
/// makes it runnable (scripts such as `Allrun`).
pub fn write_text_file(dir: &Path, rel: &str, text: &str, executable: bool) -> Result<()> {
    use crate::error::Error;
    let path = dir.join(rel);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, "cannot create the folder", e))?;
    }
    write_atomic(&path, |w| w.write_all(text.as_bytes()))?;
    #[cfg(unix)]
    if executable {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755))
            .map_err(|e| Error::io(&path, "cannot make executable", e))?;
    }
    #[cfg(not(unix))]
    let _ = executable;
    Ok(())
}

/// Writes a file through a temporary file beside it (a fresh random name, created exclusively,
/// so a link planted there is never followed) renamed over `path` when complete and synced: an
/// interrupted write never leaves a half-written file under the final name, and a signal removes
/// the temporary file (see [`crate::output`]); a write after the signal fails. The bytes go
/// through a [`sink::Sink`]: whole buffers past the page cache where the system allows it.
pub fn write_atomic(path: &Path, write: impl FnOnce(&mut dyn std::io::Write) -> std::io::Result<()>) -> Result<()> {
    use crate::error::Error;
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let mut prefix = std::ffi::OsString::from(".");
    prefix.push(path.file_name().unwrap_or_default());
    prefix.push(".");
    let tmp = crate::output::create_partial(|| {
        let mut builder = tempfile::Builder::new();
        builder.prefix(&prefix).suffix(".partial");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            builder.permissions(std::fs::Permissions::from_mode(0o666)); // less the umask, as any file
        }
        builder.tempfile_in(parent)
    })
    .map_err(|e| Error::io(path, "cannot write", e))?;
    let tmp_path = tmp.path().to_path_buf();
    let result = (|| {
        let mut w = sink::Sink::new(tmp.as_file());
        write(&mut w)?;
        w.finish()?;
        tmp.as_file().sync_all()?;
        crate::output::check_interrupted()?;
        tmp.persist(path).map(|_| ()).map_err(|e| e.error)
    })();
    crate::output::forget_partial(&tmp_path);
    result.map_err(|e| Error::io(path, "cannot write", e))
}
