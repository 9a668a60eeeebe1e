//! The manifest of a batch: one row per case, as CSV or JSON, read into [`Case`]s.
//!
//! - CSV: a header naming the columns ([`KEYS`]; `surface` is required), then one case per row.
//!   Empty fields are unset; lines starting with `#` are comments.
//! - JSON: `{"cases": [...]}` or a bare list of objects with the same keys. A row holding
//!   `primary_surface` is in the shape of the real vessels' `manifest.json`: its surface is
//!   `<manifest's folder>/<name>/<primary_surface>` and its unit `unit`; its other keys
//!   (`units`, `centerlines`, `anatomy`...) describe the case in words and are not read, except
//!   the per-case settings.
//!
//! Relative paths are taken from the manifest's folder.

use crate::data::config::Preset;
use crate::data::error::{Error, Result};
use crate::data::units::LengthUnit;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};
use std::path::{Path, PathBuf};

/// One vessel of a batch: its inputs and the settings it overrides.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Case {
    /// The case's name, its folder under the batch's output.
    pub name: String,
    pub surface: PathBuf,
    pub centerlines: Option<PathBuf>,
    pub units: Option<LengthUnit>,
    pub centerline_units: Option<LengthUnit>,
    /// A case file (TOML), in place of the batch's.
    pub config: Option<PathBuf>,
    pub preset: Option<Preset>,
    pub formats: Option<Vec<String>>,
    pub output_units: Option<LengthUnit>,
    /// Points near the inlets (in `units`), as `--inlet` given once per point: without
    /// centerlines the first is the end they start from; every one is an inlet.
    pub inlets: Vec<[f64; 3]>,
    /// Without centerlines: points on ends and sacs (in `units`).
    pub ends: Vec<[f64; 3]>,
    pub sacs: Vec<[f64; 3]>,
    pub wall_surface: Option<PathBuf>,
}

/// Every column (key) a manifest may have.
pub const KEYS: [&str; 13] = [
    "case",
    "surface",
    "centerlines",
    "units",
    "centerline_units",
    "config",
    "preset",
    "formats",
    "output_units",
    "inlet",
    "ends",
    "sacs",
    "wall_surface",
];

/// The keys read in a row in the shape of the vessels' manifest besides its name, surface and
/// unit (its `ends` is the number of the vessel's ends, its `centerlines` and `units` words).
const SETTINGS: [&str; 8] =
    ["centerline_units", "config", "preset", "formats", "output_units", "inlet", "sacs", "wall_surface"];

/// Largest manifest read.
const MAX_MANIFEST_BYTES: u64 = 64 << 20;

/// Folder and file names a case may not take (the batch's own files).
const RESERVED: [&str; 2] = ["summary.csv", "summary.json"];

/// Reads a manifest: JSON when it ends in `.json` or starts with `{` or `[`, else CSV.
pub fn read_manifest(path: &Path) -> Result<Vec<Case>> {
    let bytes = crate::io::input::read_regular_file(path, MAX_MANIFEST_BYTES, "cannot read the manifest")?;
    let text = crate::io::input::text_of(bytes).map_err(|e| Error::input(path, e))?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let json =
        path.extension().is_some_and(|e| e.eq_ignore_ascii_case("json")) || text.trim_start().starts_with(['{', '[']);
    let rows = if json { json_rows(text, path)? } else { csv_rows(text, path)? };
    cases_from_rows(&rows, base, path)
}

/// The rows of a JSON manifest: `{"cases": [...]}` or a list of objects.
fn json_rows(text: &str, path: &Path) -> Result<Vec<Map<String, Value>>> {
    let value: Value = serde_json::from_str(text)
        .map_err(|e| Error::input(path, format!("not valid JSON: {}", crate::data::error::one_line(&e.to_string()))))?;
    let list = match value {
        Value::Object(mut o) if o.contains_key("cases") => o.remove("cases").unwrap_or_default(),
        other => other,
    };
    let Value::Array(items) = list else {
        return Err(Error::input(path, "must be a list of cases, or an object whose `cases` is one"));
    };
    items
        .into_iter()
        .enumerate()
        .map(|(i, item)| match item {
            Value::Object(o) => Ok(o),
            _ => Err(Error::input(path, format!("case {}: not an object of keys ({})", i + 1, KEYS.join(", ")))),
        })
        .collect()
}

/// The rows of a CSV manifest, each field a string (empty ones left out).
fn csv_rows(text: &str, path: &Path) -> Result<Vec<Map<String, Value>>> {
    let mut reader = csv::ReaderBuilder::new().comment(Some(b'#')).trim(csv::Trim::All).from_reader(text.as_bytes());
    let bad =
        |e: csv::Error| Error::input(path, format!("not valid CSV: {}", crate::data::error::one_line(&e.to_string())));
    let header: Vec<String> = reader.headers().map_err(bad)?.iter().map(|h| h.to_ascii_lowercase()).collect();
    if let Some(unknown) = header.iter().find(|h| !KEYS.contains(&h.as_str())) {
        return Err(Error::input(
            path,
            format!(
                "the header names the column '{unknown}', which is not a setting; the columns are {}",
                KEYS.join(", ")
            ),
        ));
    }
    let mut rows = vec![];
    for record in reader.records() {
        let record = record.map_err(bad)?;
        let fields = header.iter().zip(record.iter()).filter(|(_, v)| !v.is_empty());
        rows.push(fields.map(|(k, v)| (k.clone(), Value::String(v.to_string()))).collect());
    }
    Ok(rows)
}

/// Cases from rows of keys (a manifest's, or the Python package's dicts): relative paths taken
/// from `base`; `source` names the rows in messages.
pub fn cases_from_rows(rows: &[Map<String, Value>], base: &Path, source: &Path) -> Result<Vec<Case>> {
    if rows.is_empty() {
        return Err(Error::input(source, "lists no case; give one row per case with at least its surface"));
    }
    let cases = rows
        .iter()
        .enumerate()
        .map(|(i, row)| case_of_row(row, base).map_err(|e| Error::input(source, format!("case {}: {e}", i + 1))))
        .collect::<Result<Vec<Case>>>()?;
    for (i, case) in cases.iter().enumerate() {
        if let Some(j) = cases[..i].iter().position(|c| c.name == case.name) {
            return Err(Error::input(
                source,
                format!(
                    "cases {} and {} are both named '{}' (one folder each under the output): give each its own `case`",
                    j + 1,
                    i + 1,
                    case.name
                ),
            ));
        }
    }
    Ok(cases)
}

fn case_of_row(row: &Map<String, Value>, base: &Path) -> std::result::Result<Case, String> {
    let vessels_shape = row.contains_key("primary_surface");
    if !vessels_shape {
        if let Some(unknown) = row.keys().find(|k| !KEYS.contains(&k.as_str()) && k.as_str() != "name") {
            return Err(format!("'{unknown}' is not a setting; the keys are {}", KEYS.join(", ")));
        }
    }
    let text = |key: &str| -> std::result::Result<Option<String>, String> {
        match row.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(Value::String(s)) if s.trim().is_empty() => Ok(None),
            Some(Value::String(s)) => Ok(Some(s.trim().to_string())),
            Some(other) => Err(format!("{key}: {other} is not text")),
        }
    };
    let name = text("case")?.or(text("name")?);
    let path = |p: String| base.join(p);
    let (surface, units) = if vessels_shape {
        let name = name.clone().ok_or("a row with `primary_surface` needs its `name` (its folder)")?;
        let file = text("primary_surface")?.ok_or("primary_surface: empty")?;
        (base.join(&name).join(file), unit(text("unit")?.map(|u| unit_named(&u)), "unit")?)
    } else {
        let surface = text("surface")?.ok_or("has no surface; every case needs its `surface` file")?;
        (path(surface), unit(text("units")?, "units")?)
    };
    let name = match name {
        Some(n) => n,
        None => surface.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
    };
    check_name(&name)?;
    let read = |key: &str| row.get(key).filter(|_| !vessels_shape || SETTINGS.contains(&key));
    let setting = |key: &str| if read(key).is_some() { text(key) } else { Ok(None) };
    let centerlines = if vessels_shape { None } else { text("centerlines")?.map(path) };
    let preset = setting("preset")?.map(|p| p.parse::<Preset>()).transpose().map_err(|e| format!("preset: {e}"))?;
    let formats = match read("formats") {
        Some(Value::Array(items)) => Some(
            items
                .iter()
                .map(|f| f.as_str().map(str::to_string).ok_or(format!("formats: {f} is not a format name")))
                .collect::<std::result::Result<Vec<_>, _>>()?,
        ),
        _ => setting("formats")?.map(|f| words(&f).map(str::to_string).collect()),
    };
    Ok(Case {
        name,
        surface,
        centerlines,
        units,
        centerline_units: unit(setting("centerline_units")?, "centerline_units")?,
        config: setting("config")?.map(path),
        preset,
        formats,
        output_units: unit(setting("output_units")?, "output_units")?,
        inlets: points(read("inlet"), "inlet")?,
        ends: points(read("ends"), "ends")?,
        sacs: points(read("sacs"), "sacs")?,
        wall_surface: setting("wall_surface")?.map(path),
    })
}

/// The words of a list written in one field: separated by commas, semicolons or spaces.
fn words(text: &str) -> impl Iterator<Item = &str> {
    text.split([',', ';', ' ']).map(str::trim).filter(|w| !w.is_empty())
}

fn unit(text: Option<String>, key: &str) -> std::result::Result<Option<LengthUnit>, String> {
    text.map(|u| u.parse::<LengthUnit>().map_err(|e| format!("{key}: {e}"))).transpose()
}

/// The unit a vessels' manifest's `unit` names among its words (`unitless (treat as m)`: m);
/// the text itself when it names none, or more than one.
fn unit_named(text: &str) -> String {
    let mut named: Vec<LengthUnit> =
        text.split(|c: char| !c.is_ascii_alphabetic()).filter_map(|w| w.parse::<LengthUnit>().ok()).collect();
    named.dedup();
    match named.as_slice() {
        [one] => one.name().to_string(),
        _ => text.to_string(),
    }
}

/// Points given as `x,y,z` (several separated by `;`), as `[x, y, z]` or as a list of them.
fn points(value: Option<&Value>, key: &str) -> std::result::Result<Vec<[f64; 3]>, String> {
    let bad = |what: &str| format!("{key}: '{what}' is not a point x,y,z (several separated by ';')");
    let point = |numbers: Vec<Option<f64>>, what: &str| match numbers.as_slice() {
        [Some(x), Some(y), Some(z)] if [x, y, z].iter().all(|c| c.is_finite()) => Ok([*x, *y, *z]),
        _ => Err(bad(what)),
    };
    match value {
        None | Some(Value::Null) => Ok(vec![]),
        Some(Value::String(s)) => s
            .split(';')
            .filter(|p| !p.trim().is_empty())
            .map(|p| point(p.split(',').map(|c| c.trim().parse().ok()).collect(), p))
            .collect(),
        Some(Value::Array(items)) if items.iter().all(Value::is_number) => {
            Ok(vec![point(items.iter().map(Value::as_f64).collect(), &Value::Array(items.clone()).to_string())?])
        }
        Some(Value::Array(items)) => items
            .iter()
            .flat_map(|item| match points(Some(item), key) {
                Ok(p) => p.into_iter().map(Ok).collect::<Vec<_>>(),
                Err(e) => vec![Err(e)],
            })
            .collect(),
        Some(other) => Err(bad(&other.to_string())),
    }
}

/// A case's name is one folder name of its own: not empty, no separator, not hidden, not the
/// batch's own files.
fn check_name(name: &str) -> std::result::Result<(), String> {
    let bad = name.is_empty()
        || name.starts_with('.')
        || name.contains(['/', '\\', '\0'])
        || RESERVED.contains(&name.to_ascii_lowercase().as_str());
    if bad {
        return Err(format!(
            "'{name}' cannot name a case's folder: give a name without '/' or '\\', not starting with '.', and \
             other than {}",
            RESERVED.join(" or ")
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(json: &str) -> Vec<Map<String, Value>> {
        json_rows(json, Path::new("m.json")).unwrap()
    }

    #[test]
    fn csv_rows_take_every_key_and_leave_empty_fields_unset() {
        let text = "# a comment\ncase,surface,units,formats,inlet,ends,preset\n\
                    a, a.stl ,cm,\"vtu,calculix\",\"1,2,3\",\"4,5,6;7,8,9\",medium\nb,sub/b.vtp,,,,,\n";
        let rows = csv_rows(text, Path::new("m.csv")).unwrap();
        let cases = cases_from_rows(&rows, Path::new("/data"), Path::new("m.csv")).unwrap();
        assert_eq!(cases[0].surface, PathBuf::from("/data/a.stl"));
        assert_eq!(cases[0].units, Some(LengthUnit::Cm));
        assert_eq!(cases[0].formats, Some(vec!["vtu".to_string(), "calculix".to_string()]));
        assert_eq!(cases[0].inlets, vec![[1.0, 2.0, 3.0]]);
        assert_eq!(cases[0].ends, vec![[4.0, 5.0, 6.0], [7.0, 8.0, 9.0]]);
        assert_eq!(cases[0].preset, Some(Preset::Medium));
        assert_eq!(cases[1], Case { name: "b".into(), surface: "/data/sub/b.vtp".into(), ..Default::default() });
    }

    #[test]
    fn a_vessels_manifest_row_reads_its_surface_from_its_folder_and_its_unit() {
        let json = r#"{"cases": [{"name": "v", "primary_surface": "s.stl", "units": "mm (MISR 2-3 mm)",
            "unit": "cm", "centerlines": "yes: c.vtp", "files": {"s.stl": "x"}, "ends": 3, "preset": "fine"}]}"#;
        let cases = cases_from_rows(&rows(json), Path::new("vessels"), Path::new("m.json")).unwrap();
        assert_eq!(cases[0].surface, PathBuf::from("vessels/v/s.stl"));
        assert_eq!((cases[0].units, cases[0].centerlines.clone()), (Some(LengthUnit::Cm), None));
        assert!(cases[0].ends.is_empty(), "the manifest's ends is their number");
        assert_eq!(unit_named("unitless (treat as m)"), "m");
        assert_eq!(unit_named("mm or cm"), "mm or cm");
        assert_eq!(cases[0].preset, Some(Preset::Fine));
    }

    #[test]
    fn json_points_and_formats_come_as_lists_too() {
        let json =
            r#"[{"surface": "a.stl", "formats": ["vtu", "febio"], "inlet": [1, 2, 3], "ends": [[1, 1, 1], "2,2,2"]}]"#;
        let cases = cases_from_rows(&rows(json), Path::new("."), Path::new("m.json")).unwrap();
        assert_eq!(cases[0].name, "a");
        assert_eq!(cases[0].formats.as_deref(), Some(&["vtu".to_string(), "febio".to_string()][..]));
        assert_eq!((cases[0].inlets.clone(), cases[0].ends.clone()), (vec![[1.0, 2.0, 3.0]], vec![[1.0; 3], [2.0; 3]]));
    }

    #[test]
    fn bad_rows_are_named_with_the_fix() {
        let fails =
            |json: &str| cases_from_rows(&rows(json), Path::new("."), Path::new("m.json")).unwrap_err().to_string();
        assert!(fails(r#"[{"surface": "a.stl", "surfce": "b"}]"#).contains("case 1: 'surfce' is not a setting"));
        assert!(fails(r#"[{"case": "x"}]"#).contains("has no surface"));
        assert!(fails(r#"[{"surface": "a.stl"}, {"surface": "b/a.stl"}]"#).contains("cases 1 and 2 are both named 'a'"));
        assert!(fails(r#"[{"surface": "a.stl", "case": "../up"}]"#).contains("cannot name a case's folder"));
        assert!(fails(r#"[{"surface": "a.stl", "case": "summary.json"}]"#).contains("cannot name"));
        assert!(fails(r#"[{"surface": "a.stl", "units": "furlong"}]"#).contains("units: unknown length unit"));
        assert!(fails(r#"[{"surface": "a.stl", "ends": "1,2"}]"#).contains("ends: '1,2' is not a point"));
        assert!(fails("[]").contains("lists no case"));
        let csv = csv_rows("case,surface,colour\na,a.stl,red\n", Path::new("m.csv")).unwrap_err().to_string();
        assert!(csv.contains("m.csv: the header names the column 'colour'"), "{csv}");
    }
}
