//! One case of a batch: its settings merged with the batch's, its fingerprint, and its meshing
//! into `<output>/<case>/` as `vesselhex mesh` would mesh it alone, giving its summary [`Row`].

use super::manifest::Case;
use super::summary::{Row, Status};
use super::Settings;
use crate::data::config::MeshConfig;
use crate::data::error::{Error, Result};
use crate::pipeline::MeshRequest;
use crate::stages::annotation::inlets::InletMark;
use crate::stages::centerline::extract::{ExtractOptions, InletChoice};
use std::hash::Hasher;
use std::path::{Path, PathBuf};

/// The case's configuration: the preset (the case's, else the batch's), under the case file
/// (the case's, else the batch's), under the case's and then the batch's units, output units,
/// formats and wall surface: the precedence of `vesselhex mesh`'s flags over its case file.
pub fn effective_config(case: &Case, settings: &Settings) -> Result<MeshConfig> {
    let preset = case.preset.or(settings.preset);
    let mut config = match (&case.config, &settings.config, &settings.config_table) {
        (Some(path), _, _) | (None, Some(path), _) => MeshConfig::from_case_file(path, preset)?,
        (None, None, Some(table)) => MeshConfig::from_case_table(table.clone(), Path::new("config"), preset)?,
        (None, None, None) => MeshConfig::preset(preset.unwrap_or_default()),
    };
    if let Some(u) = case.units.or(settings.units) {
        config.units = u;
    }
    if let Some(u) = case.output_units.or(settings.output_units) {
        config.output_units = u;
    }
    if let Some(f) = case.formats.as_ref().or(settings.formats.as_ref()) {
        config.formats = f.clone();
    }
    if let Some(path) = &case.wall_surface {
        config.wall.surface = Some(path.clone());
    }
    config.validate()?;
    Ok(config)
}

/// What `vesselhex mesh` is asked for the case.
fn request(case: &Case, settings: &Settings, config: MeshConfig, output: &Path) -> MeshRequest {
    let mm = |p: &[f64; 3]| nalgebra::Point3::from(*p) * config.units.to_mm();
    MeshRequest {
        surface: case.surface.clone(),
        // A case's caps come with its surface as a folder of the wall and its caps.
        caps: vec![],
        centerlines: case.centerlines.clone(),
        centerline_units: case.centerline_units,
        extraction: ExtractOptions {
            inlet: case.inlets.first().map_or(InletChoice::Largest, |p| InletChoice::Nearest(mm(p))),
            ends: case.ends.iter().map(mm).collect(),
            sacs: case.sacs.iter().map(mm).collect(),
            caps: vec![],
            inlet_names: vec![],
        },
        case_file: case.config.clone().or(settings.config.clone()),
        output: output.join(&case.name),
        force: settings.force,
        max_memory: settings.max_memory.unwrap_or_else(crate::io::memory::default_max_memory),
        quiet: true,
        reproducible: settings.reproducible,
        warnings: vec![],
        inlets: case.inlets.iter().map(|p| InletMark::Point(mm(p))).collect(),
        config,
    }
}

/// Meshes the case into `<output>/<case>/` (the same files `vesselhex mesh` writes for it) and
/// returns its row: its report's figures, or its failure's one line. Seconds and memory are
/// left for the process running it to measure.
pub fn mesh_case(case: &Case, settings: &Settings, output: &Path) -> Row {
    let report = effective_config(case, settings)
        .and_then(|config| crate::pipeline::run(&request(case, settings, config, output)))
        .and_then(|report| {
            serde_json::to_value(&report).map_err(|e| Error::Config(format!("internal: the report: {e}")))
        });
    match report {
        Ok(report) => Row::of_report(&case.name, Status::Meshed, &report),
        Err(e) => Row::failed(&case.name, super::EXIT_ERROR, &e.to_string()),
    }
}

/// The case's fingerprint: a hash of vesselhex's version, the effective configuration, the
/// extraction's points, and the bytes of every file the case reads (surface, centerlines, wall
/// surfaces, solver templates; the case file is in the configuration). Where the files were
/// read from does not count, so a cohort moved or copied elsewhere is still done. `None` when
/// an input cannot be read: the case is meshed again, and fails with the reason.
pub fn fingerprint(case: &Case, settings: &Settings) -> Option<String> {
    let config = effective_config(case, settings).ok()?;
    let mut hash = twox_hash::XxHash64::with_seed(0);
    let mut chunk = |bytes: &[u8]| {
        hash.write(&(bytes.len() as u64).to_le_bytes());
        hash.write(bytes);
    };
    chunk(env!("CARGO_PKG_VERSION").as_bytes());
    chunk(&serde_json::to_vec(&config).ok()?);
    let points = (&case.inlets, &case.ends, &case.sacs, &case.centerline_units, settings.reproducible);
    chunk(&serde_json::to_vec(&points).ok()?);
    let mut files: Vec<PathBuf> =
        [Some(&case.surface), case.centerlines.as_ref()].into_iter().flatten().cloned().collect();
    files.extend(config.wall.surface.iter().chain(&config.wall.surfaces).cloned());
    if let Some(dir) = &config.fe.template_dir {
        let mut templates: Vec<PathBuf> = std::fs::read_dir(dir).ok()?.flatten().map(|e| e.path()).collect();
        templates.sort();
        files.extend(templates.into_iter().filter(|p| p.is_file()));
    }
    for file in files {
        hash_file(&file, &mut hash).ok()?;
    }
    Some(format!("{:016x}", hash.finish()))
}

/// Feeds a file's length and bytes to `hash`, a block at a time.
fn hash_file(path: &Path, hash: &mut impl Hasher) -> std::io::Result<()> {
    use std::io::Read;
    let mut file = std::fs::File::open(path)?;
    hash.write(&file.metadata()?.len().to_le_bytes());
    let mut block = vec![0u8; 1 << 20];
    loop {
        match file.read(&mut block)? {
            0 => return Ok(()),
            n => hash.write(&block[..n]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::config::Preset;
    use crate::data::units::LengthUnit;

    fn fixture_case() -> Case {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
        Case {
            name: "aaa".into(),
            surface: dir.join("aaa.stl"),
            centerlines: Some(dir.join("aaa_centerline.csv")),
            ..Default::default()
        }
    }

    #[test]
    fn the_case_overrides_the_batch_and_both_override_the_preset() {
        let settings = Settings { preset: Some(Preset::Medium), units: Some(LengthUnit::Cm), ..Default::default() };
        let case = Case { output_units: Some(LengthUnit::M), ..fixture_case() };
        let config = effective_config(&case, &settings).unwrap();
        assert_eq!((config.preset, config.units, config.output_units), (Preset::Medium, LengthUnit::Cm, LengthUnit::M));
        let case = Case { preset: Some(Preset::Fine), units: Some(LengthUnit::Mm), ..case };
        let config = effective_config(&case, &settings).unwrap();
        assert_eq!((config.preset, config.units), (Preset::Fine, LengthUnit::Mm));
        assert_eq!(config, MeshConfig { output_units: LengthUnit::M, ..MeshConfig::preset(Preset::Fine) });
    }

    #[test]
    fn the_fingerprint_follows_the_inputs_and_the_settings_not_their_place() {
        let settings = Settings::default();
        let case = fixture_case();
        let base = fingerprint(&case, &settings).unwrap();
        assert_eq!(fingerprint(&case, &settings).unwrap(), base);
        let coarse = Settings { preset: Some(Preset::Coarse), ..Default::default() };
        assert_eq!(fingerprint(&case, &coarse).unwrap(), base, "coarse is the default preset");
        let medium = Settings { preset: Some(Preset::Medium), ..Default::default() };
        assert_ne!(fingerprint(&case, &medium).unwrap(), base);
        assert_ne!(fingerprint(&Case { inlets: vec![[0.0; 3]], ..case.clone() }, &settings).unwrap(), base);
        let reproducible = Settings { reproducible: true, ..Default::default() };
        assert_ne!(fingerprint(&case, &reproducible).unwrap(), base);
        // The same bytes elsewhere: the same fingerprint; other bytes: another.
        let dir = tempfile::tempdir().unwrap();
        let copy = dir.path().join("copy.stl");
        std::fs::copy(&case.surface, &copy).unwrap();
        assert_eq!(fingerprint(&Case { surface: copy.clone(), ..case.clone() }, &settings).unwrap(), base);
        std::fs::OpenOptions::new().append(true).open(&copy).unwrap().set_len(1000).unwrap();
        assert_ne!(fingerprint(&Case { surface: copy, ..case.clone() }, &settings).unwrap(), base);
        assert_eq!(fingerprint(&Case { surface: dir.path().join("missing.stl"), ..case }, &settings), None);
    }
}
