//! The case file: a TOML table of settings laid on top of a preset (`--config`, or the Python
//! package's `config={...}`), read, checked and resolved here so that the configuration itself
//! stays data. Errors name the file and, for a file, the line of the key.

use crate::data::config::material::check_removed_keys;
use crate::data::config::{MeshConfig, Preset};
use crate::data::error::{one_line, Error, Result};
use crate::io::input::{read_regular_file, text_of};
use std::path::Path;

/// Largest case file read.
const MAX_CASE_FILE_BYTES: u64 = 1 << 20;

impl MeshConfig {
    /// Reads a case file on top of a preset: `forced_preset` (the command line's) if given,
    /// else the one the file names, else coarse.
    ///
    /// The preset is applied first, then every key of the file, so a file can name a preset
    /// and change only what differs.
    pub fn from_case_file(path: &Path, forced_preset: Option<Preset>) -> Result<Self> {
        let bytes = read_regular_file(path, MAX_CASE_FILE_BYTES, "cannot read the case file")?;
        let text = text_of(bytes).map_err(|e| Error::input(path, e))?;
        MeshConfig::from_case_text(&text, path, forced_preset, true)
    }

    /// The settings of a case file given as a table (the Python package's `config={...}`),
    /// checked as a case file is; errors name `source` and the key, with no line (the table has
    /// none). A relative `fe.template_dir` is taken from the current folder.
    pub fn from_case_table(table: toml::Table, source: &Path, forced_preset: Option<Preset>) -> Result<Self> {
        let text = toml::to_string(&table).map_err(|e| {
            Error::input(source, format!("cannot be written as a case file: {}", one_line(&e.to_string())))
        })?;
        MeshConfig::from_case_text(&text, source, forced_preset, false)
    }

    /// A case file's text on top of a preset; errors name the line of the key when `lines`.
    fn from_case_text(text: &str, path: &Path, forced_preset: Option<Preset>, lines: bool) -> Result<Self> {
        let line_of_key = |text: &str, keys: &[&str]| if lines { line_of_key(text, keys) } else { None };
        let at = |e: &toml::de::Error| match e.span() {
            Some(span) if lines => format!("{}: ", place(text, span.start)),
            _ => String::new(),
        };
        let value: toml::Table = toml::from_str(text)
            .map_err(|e| Error::input(path, format!("{}not valid TOML: {}", at(&e), one_line(e.message()))))?;
        let mut value = value;
        check_removed_keys(&value, path)?;
        let file_preset = match value.remove("preset") {
            Some(toml::Value::String(s)) => Some(s.parse::<Preset>().map_err(|e| Error::input(path, e))?),
            Some(_) => return Err(Error::input(path, "`preset` must be a string: coarse, medium or fine")),
            None => None,
        };
        let preset = forced_preset.or(file_preset).unwrap_or_default();
        let base = toml::Value::try_from(MeshConfig::preset(preset))
            .map_err(|e| Error::Config(format!("internal: cannot serialise preset: {e}")))?;
        let merged = merge(base, toml::Value::Table(value));
        let mut config: MeshConfig = merged.try_into().map_err(|e: toml::de::Error| {
            let (table, message, field) = error_place(&e);
            let key: Vec<&str> = table.iter().chain(&field).map(String::as_str).collect();
            let at = line_of_key(text, &key).map_or(String::new(), |l| format!("line {l}: "));
            let within = match (&field, table.is_empty()) {
                (_, true) => String::new(),
                (Some(_), false) => format!(" in [{}]", table.join(".")),
                (None, false) => format!(" (`{}`)", table.join(".")),
            };
            Error::input(path, format!("{at}{message}{within}; `vesselhex mesh --help` lists the keys"))
        })?;
        config.fe.template_dir = match config.fe.template_dir.take() {
            Some(dir) => Some(resolve_template_dir(path, &dir).map_err(|message| {
                let at = line_of_key(text, &["fe", "template_dir"]).map_or(String::new(), |l| format!("line {l}: "));
                Error::input(path, format!("{at}{message}"))
            })?),
            None => None,
        };
        let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let relative_to_case = |p: &mut std::path::PathBuf| {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        };
        config.wall.surface.iter_mut().for_each(relative_to_case);
        config.wall.surfaces.iter_mut().for_each(relative_to_case);
        let template_dir = |config: &MeshConfig| match &config.fe.template_dir {
            Some(dir) => crate::io::templates::check_template_dir(dir),
            None => Ok(()),
        };
        config.validate().and_then(|()| template_dir(&config)).map_err(|e| match e {
            Error::Config(message) => {
                // Messages start with the key: "lumen.core_elements: ...", "febio.element = ...".
                let key = message.split([':', ' ', '=']).next().unwrap_or_default();
                let keys: Vec<&str> = key.split('.').collect();
                let at = line_of_key(text, &keys).map_or(String::new(), |l| format!("line {l}: "));
                Error::input(path, format!("{at}{message}"))
            }
            other => other,
        })?;
        Ok(config)
    }
}

/// `line L, column C` of a byte offset in `text`.
fn place(text: &str, at: usize) -> String {
    let before = &text[..at.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    format!("line {line}, column {column}")
}

/// Where a deserialisation error is: the key path it names (`in `lumen.radial_elements``), its
/// message, and for an "unknown field" error the unknown key (in that path's table).
fn error_place(e: &toml::de::Error) -> (Vec<String>, String, Option<String>) {
    let message = one_line(e.message());
    let shown = e.to_string();
    let keys: Vec<String> = shown
        .rsplit_once("in `")
        .and_then(|(_, rest)| rest.split_once('`'))
        .map(|(path, _)| path.split('.').map(str::to_string).collect())
        .unwrap_or_default();
    let field = message.strip_prefix("unknown field `").and_then(|r| r.split_once('`')).map(|(f, _)| f.to_string());
    (keys, message, field)
}

/// The line of the key at `keys` (a table path, then the key) in the case file's text.
fn line_of_key<S: AsRef<str>>(text: &str, keys: &[S]) -> Option<usize> {
    let document = toml::de::DeTable::parse(text).ok()?;
    let mut table = document.get_ref();
    let mut span = None;
    for (i, key) in keys.iter().enumerate() {
        let (k, v) = table.get_key_value(key.as_ref())?;
        span = Some(k.span());
        if i + 1 < keys.len() {
            match v.get_ref() {
                toml::de::DeValue::Table(t) => table = t,
                _ => return None,
            }
        }
    }
    let at = span?.start;
    Some(text[..at.min(text.len())].matches('\n').count() + 1)
}

/// `fe.template_dir` as written in a case file: relative to the case file's folder, which it
/// must not leave (an absolute path is taken as given).
fn resolve_template_dir(case_file: &Path, dir: &Path) -> std::result::Result<std::path::PathBuf, String> {
    if dir.is_absolute() {
        return Ok(dir.to_path_buf());
    }
    let base = case_file.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let resolved = base.join(dir);
    let (Ok(real_base), Ok(real)) = (base.canonicalize(), resolved.canonicalize()) else {
        return Ok(resolved); // missing: validate names it
    };
    if !real.starts_with(&real_base) {
        return Err(format!(
            "fe.template_dir = \"{}\" leads out of the case file's folder (to {}); keep the templates in a folder \
             beside the case file, or give an absolute path",
            dir.display(),
            real.display()
        ));
    }
    Ok(resolved)
}

/// Recursively overlays `top` on `base` (tables merge key by key, anything else replaces).
fn merge(base: toml::Value, top: toml::Value) -> toml::Value {
    match (base, top) {
        (toml::Value::Table(mut b), toml::Value::Table(t)) => {
            for (k, v) in t {
                let merged = match b.remove(&k) {
                    Some(old) => merge(old, v),
                    None => v,
                };
                b.insert(k, merged);
            }
            toml::Value::Table(b)
        }
        (_, top) => top,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn case_file_overrides_preset_key_by_key() {
        let dir = std::env::temp_dir().join(format!("vesselhex-config-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("case.toml");
        std::fs::write(&p, "preset = \"medium\"\n[lumen]\nradial_elements = 9\n[wall.media]\nfraction = 0.5\nelements = 3\nfibre_angle_deg = 40.0\n").unwrap();
        let c = MeshConfig::from_case_file(&p, None).unwrap();
        assert_eq!(c.preset, Preset::Medium);
        assert_eq!(c.lumen.radial_elements, 9);
        assert_eq!(c.lumen.core_elements, MeshConfig::preset(Preset::Medium).lumen.core_elements);
        assert_eq!(c.wall.media.elements, 3);
        let forced = MeshConfig::from_case_file(&p, Some(Preset::Fine)).unwrap();
        assert_eq!(forced.preset, Preset::Fine);
        assert_eq!(forced.lumen.radial_elements, 9);
        assert_eq!(forced.lumen.core_elements, MeshConfig::preset(Preset::Fine).lumen.core_elements);
        std::fs::write(&p, "[lumen]\nradial_elementz = 9\n").unwrap();
        let e = MeshConfig::from_case_file(&p, None).unwrap_err().to_string();
        assert!(e.contains("radial_elementz") && e.contains("case.toml"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
