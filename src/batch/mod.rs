//! Cohorts: many vessels meshed in one call (`vesselhex batch`, the Python package's
//! `mesh_many`), each in a process of its own, N at a time, with a table of results.
//!
//! - [`manifest`]: the cases, from a CSV or JSON manifest (or the Python package's rows).
//! - [`case`]: one case's settings, fingerprint and meshing into `<output>/<case>/` (what
//!   `vesselhex mesh` writes for it alone), giving its summary [`Row`].
//! - [`child`]: a case run in a child process, measured (seconds, peak memory), its crash a row.
//! - [`summary`]: the rows, written as `summary.csv` and `summary.json`.
//! - [`command`]: the `batch` subcommand (progress over the cases).
//!
//! A case is skipped when an earlier run meshed it from the same inputs and settings: its row
//! in the earlier `summary.json` has its mesh, the same [fingerprint](case::fingerprint), and
//! its folder's `report.json` is there (its row is built again from it).

pub mod case;
pub mod child;
pub mod command;
pub mod manifest;
pub mod summary;

pub use child::{run_case_in_child, ChildCommand, Job};
pub use manifest::{read_manifest, Case};
pub use summary::{Row, Status};

use crate::config::Preset;
use crate::error::{Error, Result};
use crate::resources::show_bytes;
use crate::units::LengthUnit;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A case's exit codes, as `vesselhex mesh` gives them: refused, and meshed with an end not meshed.
pub const EXIT_ERROR: i32 = 1;
pub const EXIT_ENDS_NOT_MESHED: i32 = 3;
/// The batch's exit code when a case failed (the others were meshed, the summary written).
pub const EXIT_CASE_FAILED: i32 = 4;

/// The batch's settings, each case's unless its row sets its own (see [`case::effective_config`]).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Settings {
    pub preset: Option<Preset>,
    /// A case file (TOML) for every case without its own.
    pub config: Option<PathBuf>,
    /// The same as a table (the Python package's `config={...}`), when no file is given.
    pub config_table: Option<toml::Table>,
    pub units: Option<LengthUnit>,
    pub output_units: Option<LengthUnit>,
    pub formats: Option<Vec<String>>,
    /// The memory each case may plan to use (bytes; see [`memory_plan`]).
    pub max_memory: Option<u64>,
    pub reproducible: bool,
    /// Worker threads of each case's process (none: the cores shared among the jobs).
    pub threads: Option<usize>,
    /// Mesh every case again, replacing its folder even if it holds files vesselhex did not write.
    pub force: bool,
}

/// A case of the batch, and its row when an earlier run already meshed it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Planned {
    pub case: Case,
    pub fingerprint: Option<String>,
    /// The case's row when it is skipped (done before with the same inputs and settings).
    pub done: Option<Row>,
}

/// How many cases run at once and with what memory each.
#[derive(Debug, Clone, PartialEq)]
pub struct MemoryPlan {
    /// The memory each case plans within (its `--max-memory`): a case estimated to need more is
    /// refused before it is built.
    pub per_job: u64,
    pub at_once: usize,
    /// What was decided, for the user.
    pub message: String,
}

/// Plans `jobs` jobs within `available` bytes: with `max_memory` per job, no more jobs at once
/// than fit in what is available (at least one); without it, the jobs share what is available.
/// Every case is refused before it is built when its estimate exceeds its share, so the
/// estimates of the cases running at once never add up to more than was available.
pub fn memory_plan(jobs: usize, max_memory: Option<u64>, available: u64) -> MemoryPlan {
    let jobs = jobs.max(1);
    let avail = show_bytes(available as f64);
    match max_memory {
        None => {
            let per_job = available / jobs as u64;
            let message = format!(
                "memory: {jobs} job(s) at a time, each case planning within {} (the {avail} available, shared; \
                 --max-memory sets it per job)",
                show_bytes(per_job as f64)
            );
            MemoryPlan { per_job, at_once: jobs, message }
        }
        Some(per_job) => {
            let fit = (available / per_job.max(1)) as usize;
            let each = show_bytes(per_job as f64);
            let message = if fit >= jobs {
                format!(
                    "memory: {jobs} job(s) at a time, each case planning within {each}, within the {avail} available"
                )
            } else if fit >= 1 {
                format!(
                    "memory: {fit} job(s) at a time, not {jobs}: only {fit} of --max-memory {each} fit in the {avail} \
                     available"
                )
            } else {
                format!("memory: one job at a time, not {jobs}: --max-memory {each} is more than the {avail} available")
            };
            MemoryPlan { per_job, at_once: fit.clamp(1, jobs), message }
        }
    }
}

/// What the batch tells as it goes (the command's progress bar, the Python package's callback).
pub enum Event<'a> {
    Started(&'a Case),
    Finished(&'a Row),
}

/// A batch over one output folder: its cases planned (those done before found), the folder
/// locked against another batch while it lives.
pub struct Batch {
    pub output: PathBuf,
    pub settings: Settings,
    pub planned: Vec<Planned>,
    _lock: Option<std::fs::File>,
}

impl Batch {
    /// Creates and locks `output` and plans `cases` in it.
    pub fn open(cases: Vec<Case>, settings: Settings, output: &Path) -> Result<Batch> {
        std::fs::create_dir_all(output).map_err(|e| Error::io(output, "cannot create the output folder", e))?;
        let lock = lock(output)?;
        let previous = summary::read_summary(output);
        let planned = cases
            .into_iter()
            .map(|case| {
                let fingerprint = case::fingerprint(&case, &settings);
                let before = previous.iter().find(|r| r.case == case.name);
                let done = match before {
                    Some(row) if !settings.force && row.has_mesh() && fingerprint.is_some() => {
                        (row.fingerprint == fingerprint).then(|| done_row(&case, &settings, row, output)).flatten()
                    }
                    _ => None,
                };
                Planned { case, fingerprint, done }
            })
            .collect();
        Ok(Batch { output: output.to_path_buf(), settings, planned, _lock: lock })
    }

    /// The cases still to mesh.
    pub fn pending(&self) -> impl Iterator<Item = &Planned> {
        self.planned.iter().filter(|p| p.done.is_none())
    }

    /// The job of a case, with `settings` (the batch's, with its memory and threads decided).
    pub fn job(&self, planned: &Planned, settings: &Settings) -> Job {
        Job { case: planned.case.clone(), settings: settings.clone(), output: self.output.clone() }
    }

    /// The rows of every case in the manifest's order: those done before, and `ran` (the rows of
    /// the cases meshed now, any order; a case without one is a failed row saying so); writes
    /// them as the summary.
    pub fn finish(&self, ran: Vec<Row>) -> Result<Vec<Row>> {
        let row_of = |p: &Planned| {
            let ran = ran.iter().find(|r| r.case == p.case.name).cloned();
            p.done.clone().or(ran).unwrap_or_else(|| Row::failed(&p.case.name, EXIT_ERROR, "no result came back"))
        };
        let rows: Vec<Row> = self.planned.iter().map(row_of).collect();
        summary::write_summary(&rows, &self.output)?;
        Ok(rows)
    }

    /// How the pending cases run here with `jobs` jobs, in the memory available now (see
    /// [`memory_plan`]).
    pub fn plan_memory(&self, jobs: usize) -> MemoryPlan {
        let available = crate::resources::available_memory().unwrap_or_else(crate::resources::default_max_memory);
        memory_plan(jobs.min(self.pending().count()).max(1), self.settings.max_memory, available)
    }

    /// Meshes the pending cases here, each in a child process run by `child`, as `plan` says;
    /// the summary is written after each case, so an interrupted batch keeps what it finished.
    /// Returns every case's row.
    pub fn run_local(
        &self,
        plan: &MemoryPlan,
        child: &ChildCommand,
        events: &mut dyn FnMut(Event),
    ) -> Result<Vec<Row>> {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let settings = Settings {
            max_memory: Some(plan.per_job),
            threads: self.settings.threads.or(Some((cores / plan.at_once).max(1))),
            ..self.settings.clone()
        };
        let mut rows: Vec<Option<Row>> = self.planned.iter().map(|p| p.done.clone()).collect();
        rows.iter().flatten().for_each(|r| events(Event::Finished(r)));
        summary::write_summary(&rows.iter().flatten().cloned().collect::<Vec<_>>(), &self.output)?;
        let next = std::sync::atomic::AtomicUsize::new(0);
        let (tell, told) = std::sync::mpsc::channel::<(usize, Option<Row>)>();
        let todo: Vec<usize> = (0..self.planned.len()).filter(|&i| rows[i].is_none()).collect();
        std::thread::scope(|scope| -> Result<()> {
            for _ in 0..plan.at_once {
                let tell = tell.clone();
                let (todo, next, settings) = (&todo, &next, &settings);
                scope.spawn(move || {
                    while let Some(&i) = todo.get(next.fetch_add(1, std::sync::atomic::Ordering::SeqCst)) {
                        let planned = &self.planned[i];
                        if tell.send((i, None)).is_err() {
                            return;
                        }
                        let row = run_case_in_child(child, &self.job(planned, settings), planned.fingerprint.clone());
                        if tell.send((i, Some(row))).is_err() {
                            return;
                        }
                    }
                });
            }
            drop(tell);
            for (i, row) in told {
                match row {
                    None => events(Event::Started(&self.planned[i].case)),
                    Some(row) => {
                        events(Event::Finished(&row));
                        rows[i] = Some(row);
                        summary::write_summary(&rows.iter().flatten().cloned().collect::<Vec<_>>(), &self.output)?;
                    }
                }
            }
            Ok(())
        })?;
        Ok(rows.into_iter().flatten().collect())
    }
}

/// The row of a case done before: built again from its `report.json`, with the seconds and
/// memory of the run that made it; `None` when the report is missing, unreadable, or made with
/// another configuration than the case's now (the folder meshed again by hand since).
fn done_row(case: &Case, settings: &Settings, before: &Row, output: &Path) -> Option<Row> {
    let path = output.join(&case.name).join(crate::output::MARKER);
    let bytes = crate::input::read_regular_file(&path, 64 << 20, "cannot read the report").ok()?;
    let report: serde_json::Value = serde_json::from_slice(&bytes).ok()?;
    let config = serde_json::to_value(case::effective_config(case, settings).ok()?).ok()?;
    if report.get("config") != Some(&config) {
        return None;
    }
    Some(Row {
        seconds: before.seconds,
        peak_memory_mib: before.peak_memory_mib,
        fingerprint: before.fingerprint.clone(),
        ..Row::of_report(&case.name, Status::Skipped, &report)
    })
}

/// Locks the batch's output folder (an advisory lock on the folder, held while the batch runs).
#[cfg(unix)]
fn lock(output: &Path) -> Result<Option<std::fs::File>> {
    let folder = std::fs::File::open(output).map_err(|e| Error::io(output, "cannot open the output folder", e))?;
    match folder.try_lock() {
        Ok(()) => Ok(Some(folder)),
        Err(std::fs::TryLockError::WouldBlock) => Err(Error::input(
            output,
            "another vesselhex batch is writing into this folder; wait for it to finish or choose another --output",
        )),
        Err(std::fs::TryLockError::Error(e)) => Err(Error::io(output, "cannot lock the output folder", e)),
    }
}

#[cfg(not(unix))]
fn lock(_output: &Path) -> Result<Option<std::fs::File>> {
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::*;

    const GIB: u64 = 1 << 30;

    #[test]
    fn a_case_without_a_row_is_a_failed_row_and_the_folder_is_one_batchs() {
        let dir = tempfile::tempdir().unwrap();
        let case = Case { name: "a".into(), surface: dir.path().join("missing.stl"), ..Default::default() };
        let batch = Batch::open(vec![case], Settings::default(), dir.path()).unwrap();
        assert_eq!(batch.pending().count(), 1);
        assert_eq!(batch.planned[0].fingerprint, None, "an input that cannot be read has no fingerprint");
        let rows = batch.finish(vec![]).unwrap();
        assert_eq!((rows[0].status, rows[0].cause.as_str()), (Status::Failed, "no result came back"));
        assert_eq!(summary::read_summary(dir.path()), rows);
        let again = Batch::open(vec![], Settings::default(), dir.path()).err().expect("refused");
        assert!(again.to_string().contains("another vesselhex batch is writing into this folder"), "{again}");
    }

    #[test]
    fn jobs_start_only_as_many_as_fit_in_the_memory_available() {
        let plan = memory_plan(4, Some(2 * GIB), 10 * GIB);
        assert_eq!((plan.per_job, plan.at_once), (2 * GIB, 4));
        let plan = memory_plan(4, Some(3 * GIB), 10 * GIB);
        assert_eq!(plan.at_once, 3);
        assert!(plan.message.contains("3 job(s) at a time, not 4"), "{}", plan.message);
        let plan = memory_plan(2, Some(16 * GIB), 10 * GIB);
        assert_eq!(plan.at_once, 1);
        assert!(plan.message.contains("is more than the 10.0 GiB available"), "{}", plan.message);
        // Without --max-memory the jobs share what is available.
        let plan = memory_plan(4, None, 10 * GIB);
        assert_eq!((plan.per_job, plan.at_once), (10 * GIB / 4, 4));
        for (jobs, max, avail) in [(1, Some(GIB), GIB), (7, Some(GIB / 3), 5 * GIB), (3, None, 7 * GIB)] {
            let plan = memory_plan(jobs, max, avail);
            assert!(plan.at_once <= jobs && plan.at_once >= 1);
            assert!(plan.per_job * plan.at_once as u64 <= avail || plan.at_once == 1, "{plan:?}");
        }
    }
}
