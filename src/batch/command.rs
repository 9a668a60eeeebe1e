//! `vesselhex batch MANIFEST --output DIR`: the cases of a manifest meshed N at a time, each in
//! a child process (`vesselhex batch-case`), with a progress bar over the cases on a terminal
//! and the summary in `DIR/summary.csv` and `DIR/summary.json`.

use super::{Batch, ChildCommand, Event, Row, Settings, Status};
use crate::config::Preset;
use crate::units::LengthUnit;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::PathBuf;
use std::process::ExitCode;

pub const BATCH_HELP: &str =
    "Mesh every case of a manifest, each into DIR/<case>/ (the files `vesselhex mesh` writes for it \
alone, byte for byte) by a process of its own, --jobs at a time; a case that fails does not stop the others.

MANIFEST: CSV with a header, or JSON (a list of objects, or {\"cases\": [...]}; rows in the shape of the real vessels' \
manifest.json, name + primary_surface + unit, are read too). Keys: case, surface (required), centerlines, units, \
centerline_units, config, preset, formats, output_units, inlet, ends, sacs, wall_surface; relative paths are taken \
from the manifest's folder. A row's settings override the batch's flags.

DIR/summary.csv and DIR/summary.json: one row per case (case, status, exit, ends found and meshed, hexes, minimum \
scaled Jacobian, wall mean, lumen skew, surface fidelity, within_bars, seconds, peak memory, cause, fingerprint).
A rerun skips a case meshed before from the same input files and settings (its fingerprint in summary.json, its \
report.json present), unless --force.

Memory: with --max-memory SIZE, each case plans within SIZE and no more jobs run at once than fit in the memory \
available; without it, the jobs share the memory available.

Exit codes: 0 every case meshed, 3 every case meshed but some with an end not meshed, 4 some case failed (the \
others meshed, the summary written), 1 the batch could not start (nothing meshed), 2 usage error.";

#[derive(clap::Args)]
pub struct BatchArgs {
    /// The cases: a CSV or JSON manifest (see above).
    manifest: PathBuf,
    /// Output folder: each case in a folder of its own, and the summary.
    #[arg(long)]
    output: PathBuf,
    /// Cases meshed at once, each in its own process [default: the cores].
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=1024))]
    jobs: Option<u16>,
    /// Mesh every case again, replacing its folder even if it holds files vesselhex did not write.
    #[arg(long)]
    force: bool,
    /// Memory each case may plan to use, e.g. 4G: a case estimated to need more is refused
    /// before it is built, and no more jobs run at once than fit in the memory available
    /// [default: the memory available, shared among the jobs].
    #[arg(long, value_name = "SIZE", value_parser = crate::resources::parse_size)]
    max_memory: Option<u64>,
    /// Resolution preset of the cases that set none: coarse, medium, fine.
    #[arg(long)]
    preset: Option<Preset>,
    /// Case file (TOML) of the cases that give none.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Output formats of the cases that set none, comma-separated [default: vtu].
    #[arg(long, value_delimiter = ',')]
    formats: Option<Vec<String>>,
    /// Length unit of the input files of the cases that set none [default: mm].
    #[arg(long)]
    units: Option<LengthUnit>,
    /// Length unit of the written meshes of the cases that set none [default: mm].
    #[arg(long)]
    output_units: Option<LengthUnit>,
    /// Worker threads of each case's process [default: the cores shared among the jobs]. The
    /// output does not depend on it.
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=256))]
    threads: Option<u16>,
    /// No progress bar and no closing line.
    #[arg(long)]
    quiet: bool,
    /// Write zero timings into every report.json (the summary keeps the seconds measured).
    #[arg(long)]
    reproducible: bool,
}

/// Runs `vesselhex batch` and gives its exit code.
pub fn run_command(args: BatchArgs) -> ExitCode {
    match run(args) {
        Ok(code) => ExitCode::from(code),
        Err(e) => {
            eprintln!("vesselhex: error: {}", crate::error::one_line(&e.to_string()));
            ExitCode::from(super::EXIT_ERROR as u8)
        }
    }
}

/// Runs `vesselhex batch-case`: one case, handed over on standard input by `vesselhex batch`.
pub fn run_child() -> ExitCode {
    ExitCode::from(super::child::child_main().clamp(0, 255) as u8)
}

fn run(args: BatchArgs) -> crate::Result<u8> {
    let cases = super::read_manifest(&args.manifest)?;
    let settings = Settings {
        preset: args.preset,
        config: args.config,
        config_table: None,
        units: args.units,
        output_units: args.output_units,
        formats: args.formats,
        max_memory: args.max_memory,
        reproducible: args.reproducible,
        threads: args.threads.map(usize::from),
        force: args.force,
    };
    let batch = Batch::open(cases, settings, &args.output)?;
    let child = ChildCommand::this_command()
        .map_err(|e| crate::Error::Config(format!("cannot find the vesselhex command to run the cases: {e}")))?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let jobs = args.jobs.map_or(cores, usize::from);
    let plan = batch.plan_memory(jobs);
    if !args.quiet && batch.pending().next().is_some() {
        eprintln!("vesselhex: {}", plan.message);
    }
    let bar = progress_bar(args.quiet, batch.planned.len());
    let mut running: Vec<String> = vec![];
    let rows = batch.run_local(&plan, &child, &mut |event| match event {
        Event::Started(case) => {
            running.push(case.name.clone());
            bar.set_message(running.join(", "));
        }
        Event::Finished(row) => {
            running.retain(|n| *n != row.case);
            bar.set_message(running.join(", "));
            bar.inc(1);
            if row.status == Status::Failed {
                bar.suspend(|| eprintln!("vesselhex: case {} failed: {}", row.case, row.cause));
            }
        }
    })?;
    bar.finish_and_clear();
    if !args.quiet {
        eprintln!("vesselhex: {}", closing_line(&rows, &args.output));
    }
    Ok(exit_code(&rows))
}

fn progress_bar(quiet: bool, cases: usize) -> ProgressBar {
    let target = if quiet { ProgressDrawTarget::hidden() } else { ProgressDrawTarget::stderr() };
    let bar = ProgressBar::with_draw_target(Some(cases as u64), target);
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} cases {wide_msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.enable_steady_tick(std::time::Duration::from_millis(120));
    bar
}

/// "18 cases: 16 meshed, 1 skipped (done before), 1 failed; summary in DIR/summary.csv".
fn closing_line(rows: &[Row], output: &std::path::Path) -> String {
    let count = |s: Status| rows.iter().filter(|r| r.status == s).count();
    let short = rows.iter().filter(|r| r.exit == super::EXIT_ENDS_NOT_MESHED).count();
    let short = if short > 0 { format!(" ({short} with an end not meshed)") } else { String::new() };
    format!(
        "{} cases: {} meshed{short}, {} skipped (done before), {} failed; summary in {}",
        rows.len(),
        count(Status::Meshed),
        count(Status::Skipped),
        count(Status::Failed),
        output.join(super::summary::SUMMARY_CSV).display()
    )
}

/// 0 every case meshed, 3 some with an end not meshed, 4 some case failed.
fn exit_code(rows: &[Row]) -> u8 {
    if rows.iter().any(|r| r.status == Status::Failed) {
        super::EXIT_CASE_FAILED as u8
    } else if rows.iter().any(|r| r.exit == super::EXIT_ENDS_NOT_MESHED) {
        super::EXIT_ENDS_NOT_MESHED as u8
    } else {
        0
    }
}
