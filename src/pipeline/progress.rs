//! Progress on a terminal (indicatif): one line per stage. Quiet with `--quiet`, and silent when
//! standard error is not a terminal (indicatif's stderr target hides itself then).

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::time::Instant;

/// Called with the name of each stage as it starts.
pub type StageListener = Box<dyn FnMut(&str) + Send>;

pub struct Progress {
    bar: ProgressBar,
    /// Told the name of each stage as it starts (the Python package's progress callback).
    listener: Option<StageListener>,
    stage_start: Instant,
    stage: String,
    /// Finished stages and their durations, in order.
    pub timings: Vec<(String, f64)>,
}

impl Progress {
    pub fn new(quiet: bool, stages: u64) -> Self {
        let target = if quiet { ProgressDrawTarget::hidden() } else { ProgressDrawTarget::stderr() };
        let bar = ProgressBar::with_draw_target(Some(stages), target);
        bar.set_style(
            ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar.enable_steady_tick(std::time::Duration::from_millis(120));
        Progress { bar, listener: None, stage_start: Instant::now(), stage: String::new(), timings: Vec::new() }
    }

    /// Progress that tells `listener` the name of each stage as it starts, with no display.
    pub fn with_listener(listener: StageListener) -> Self {
        let mut progress = Progress::new(true, 0);
        progress.listener = Some(listener);
        progress
    }

    /// Ends the current stage (recording its time) and starts `name`.
    pub fn stage(&mut self, name: &str) {
        self.finish_stage();
        self.stage = name.to_string();
        self.stage_start = Instant::now();
        self.bar.set_message(name.to_string());
        if let Some(listener) = &mut self.listener {
            listener(name);
        }
    }

    fn finish_stage(&mut self) {
        if !self.stage.is_empty() {
            self.timings.push((std::mem::take(&mut self.stage), self.stage_start.elapsed().as_secs_f64()));
            self.bar.inc(1);
        }
    }

    /// Runs `f` (which may print to standard error) with the bar hidden.
    pub fn suspend<R>(&self, f: impl FnOnce() -> R) -> R {
        self.bar.suspend(f)
    }

    pub fn finish(&mut self) {
        self.finish_stage();
        self.bar.finish_and_clear();
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}
