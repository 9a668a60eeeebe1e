//! The summary of a batch: one [`Row`] per case, built from the case's `report.json` (or from
//! its failure), written as `summary.csv` and `summary.json` in the batch's output folder.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::path::Path;

/// What became of a case.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Meshed by this run.
    Meshed,
    /// Meshed by an earlier run with the same inputs and settings (see [`super::fingerprint`]).
    Skipped,
    /// Refused, or its process ended without a mesh.
    Failed,
}

/// One case's line of the summary. The figures are `report.json`'s (empty for a failed case).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    pub case: String,
    pub status: Status,
    /// The exit code `vesselhex mesh` gives the case: 0 meshed, 3 meshed with an end not meshed,
    /// 1 refused; 128 + the signal's number when its process was killed.
    pub exit: i32,
    pub ends_found: Option<usize>,
    pub ends_meshed: Option<usize>,
    pub hexes: Option<usize>,
    /// The least scaled Jacobian of the lumen and the wall.
    pub min_scaled_jacobian: Option<f64>,
    pub wall_mean_scaled_jacobian: Option<f64>,
    pub lumen_mean_skew: Option<f64>,
    /// Surface fidelity: the farthest lumen-surface node from the input surface, and the
    /// farthest input vertex from the meshed lumen surface (micrometres).
    pub node_to_surface_max_um: Option<f64>,
    pub surface_to_mesh_max_um: Option<f64>,
    pub within_bars: Option<bool>,
    /// Wall-clock seconds of the case's process.
    pub seconds: f64,
    /// The most memory the case's process held (its peak resident set), MiB.
    pub peak_memory_mib: Option<f64>,
    /// Why the case failed, or which end was not meshed, on one line; empty otherwise.
    pub cause: String,
    /// The inputs and settings the mesh was made from (see [`super::fingerprint`]).
    pub fingerprint: Option<String>,
}

/// The warnings that say an end was not meshed (exit code 3).
const NOT_MESHED: [&str; 3] = ["end_not_meshed", "branch_not_meshed", "sac_not_meshed"];

impl Row {
    /// The row of a case meshed into a folder whose `report.json` is `report`.
    pub fn of_report(case: &str, status: Status, report: &Value) -> Row {
        let number = |pointer: &str| report.pointer(pointer).and_then(Value::as_f64);
        let ends = report.get("ends").and_then(Value::as_array);
        let ends_meshed = ends.map(|e| e.iter().filter(|e| e["meshed"].as_bool() == Some(true)).count());
        let ends_found = ends.map(Vec::len);
        let all_meshed = ends_found.is_some() && ends_meshed == ends_found;
        let min_sj = [number("/lumen/scaled_jacobian/min"), number("/wall/scaled_jacobian/min")];
        let cause = report
            .get("warnings")
            .and_then(Value::as_array)
            .into_iter()
            .flatten()
            .find(|w| NOT_MESHED.contains(&w["kind"].as_str().unwrap_or_default()))
            .and_then(|w| w["message"].as_str())
            .map(|m| if all_meshed { String::new() } else { crate::error::one_line(m) });
        Row {
            case: case.to_string(),
            status,
            exit: if all_meshed { 0 } else { super::EXIT_ENDS_NOT_MESHED },
            ends_found,
            ends_meshed,
            hexes: report.get("elements").and_then(Value::as_u64).map(|n| n as usize),
            min_scaled_jacobian: min_sj.into_iter().flatten().reduce(f64::min),
            wall_mean_scaled_jacobian: number("/wall/scaled_jacobian/mean"),
            lumen_mean_skew: number("/lumen/equiangle_skew/mean"),
            node_to_surface_max_um: number("/surface_accuracy/node_to_surface_um/max"),
            surface_to_mesh_max_um: number("/surface_accuracy/surface_to_mesh_um/max"),
            within_bars: report.get("within_bars").and_then(Value::as_bool),
            seconds: 0.0,
            peak_memory_mib: None,
            cause: cause.unwrap_or_default(),
            fingerprint: None,
        }
    }

    /// The row of a case that failed with `exit` for `cause`.
    pub fn failed(case: &str, exit: i32, cause: &str) -> Row {
        Row {
            case: case.to_string(),
            status: Status::Failed,
            exit,
            ends_found: None,
            ends_meshed: None,
            hexes: None,
            min_scaled_jacobian: None,
            wall_mean_scaled_jacobian: None,
            lumen_mean_skew: None,
            node_to_surface_max_um: None,
            surface_to_mesh_max_um: None,
            within_bars: None,
            seconds: 0.0,
            peak_memory_mib: None,
            cause: crate::error::one_line(cause),
            fingerprint: None,
        }
    }

    /// Whether the case's mesh was written (every end meshed or not).
    pub fn has_mesh(&self) -> bool {
        self.status != Status::Failed
    }
}

/// The summary's file names.
pub const SUMMARY_CSV: &str = "summary.csv";
pub const SUMMARY_JSON: &str = "summary.json";

/// Largest summary read back.
const MAX_SUMMARY_BYTES: u64 = 256 << 20;

/// Writes `summary.csv` and `summary.json` into `folder` (each through a temporary file renamed
/// into place, so a reader never sees half a summary).
pub fn write_summary(rows: &[Row], folder: &Path) -> Result<()> {
    let json = serde_json::to_string_pretty(rows)
        .map_err(|e| Error::Config(format!("internal: cannot encode the summary: {e}")))?;
    crate::writers::write_atomic(&folder.join(SUMMARY_JSON), |w| w.write_all(json.as_bytes()))?;
    let mut csv = csv::Writer::from_writer(vec![]);
    for row in rows {
        csv.serialize(row).map_err(|e| Error::Config(format!("internal: cannot encode the summary: {e}")))?;
    }
    let bytes = csv.into_inner().map_err(|e| Error::Config(format!("internal: cannot encode the summary: {e}")))?;
    crate::writers::write_atomic(&folder.join(SUMMARY_CSV), |w| w.write_all(&bytes))
}

/// The rows of an earlier run's `summary.json` in `folder` (none when it is missing or not
/// one: its cases are then all meshed again).
pub fn read_summary(folder: &Path) -> Vec<Row> {
    let path = folder.join(SUMMARY_JSON);
    let Ok(bytes) = crate::input::read_regular_file(&path, MAX_SUMMARY_BYTES, "cannot read the summary") else {
        return vec![];
    };
    serde_json::from_slice(&bytes).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(ends: &[bool]) -> Value {
        serde_json::json!({
            "elements": 1200,
            "lumen": {"scaled_jacobian": {"min": 0.41, "mean": 0.9}, "equiangle_skew": {"mean": 0.21}},
            "wall": {"scaled_jacobian": {"min": 0.38, "mean": 0.93}},
            "surface_accuracy": {"node_to_surface_um": {"max": 1e-11}, "surface_to_mesh_um": {"max": 812.5}},
            "within_bars": true,
            "ends": ends.iter().map(|m| serde_json::json!({"meshed": m})).collect::<Vec<_>>(),
            "warnings": [{"kind": "units", "message": "x"}, {"kind": "end_not_meshed", "message": "the end at\n(1, 2, 3)"}],
        })
    }

    #[test]
    fn a_row_holds_the_reports_figures() {
        let row = Row::of_report("v", Status::Meshed, &report(&[true, true, false]));
        assert_eq!((row.exit, row.ends_found, row.ends_meshed, row.hexes), (3, Some(3), Some(2), Some(1200)));
        assert_eq!(row.min_scaled_jacobian, Some(0.38));
        assert_eq!((row.wall_mean_scaled_jacobian, row.lumen_mean_skew), (Some(0.93), Some(0.21)));
        assert_eq!((row.node_to_surface_max_um, row.surface_to_mesh_max_um), (Some(1e-11), Some(812.5)));
        assert_eq!(row.cause, "the end at (1, 2, 3)");
        let whole = Row::of_report("v", Status::Meshed, &report(&[true, true]));
        assert_eq!((whole.exit, whole.cause.as_str()), (0, ""));
    }

    #[test]
    fn the_summary_reads_back_as_written() {
        let dir = tempfile::tempdir().unwrap();
        let mut rows = vec![Row::of_report("a", Status::Meshed, &report(&[true, true]))];
        rows.push(Row::failed("b, \"quoted\"", 1, "b.stl: cannot read\nthe surface"));
        write_summary(&rows, dir.path()).unwrap();
        assert_eq!(read_summary(dir.path()), rows);
        let csv = std::fs::read_to_string(dir.path().join(SUMMARY_CSV)).unwrap();
        let mut reader = csv::Reader::from_reader(csv.as_bytes());
        let back: Vec<Row> = reader.deserialize().collect::<std::result::Result<_, _>>().unwrap();
        assert_eq!(back, rows);
        assert!(csv.starts_with("case,status,exit,ends_found,ends_meshed,hexes,min_scaled_jacobian,"), "{csv}");
    }
}
