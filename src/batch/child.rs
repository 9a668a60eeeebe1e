//! Each case in a process of its own: a crash, a panic or the kernel's out-of-memory killer in
//! one case ends that process only, and the process's peak memory is the case's.
//!
//! The parent writes a [`Job`] as JSON on the child's standard input; the child
//! ([`child_main`]: `vesselhex batch-case`, or `python -m vesselhex._case`) meshes it and
//! writes its [`Row`] as JSON on its standard output. The parent measures the seconds and reads
//! the peak resident set from `wait4`; a child that ends without a row gets a failed row naming
//! how it ended and the last thing it said.

use super::manifest::Case;
use super::summary::Row;
use super::Settings;
use serde::{Deserialize, Serialize};
use std::io::{Read, Write};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Instant;

/// What a child is asked to do.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Job {
    pub case: Case,
    pub settings: Settings,
    /// The batch's output folder (the case goes into its own folder under it).
    pub output: PathBuf,
}

/// The program that runs a [`Job`]: the `vesselhex` command (`batch-case`) or a Python
/// interpreter (`-m vesselhex._case`).
#[derive(Debug, Clone)]
pub struct ChildCommand {
    pub program: PathBuf,
    pub args: Vec<String>,
}

impl ChildCommand {
    /// This very `vesselhex` command.
    pub fn this_command() -> std::io::Result<ChildCommand> {
        Ok(ChildCommand { program: std::env::current_exe()?, args: vec!["batch-case".into()] })
    }
}

/// How a child process ended.
struct Ended {
    /// Its exit code, or 128 + the signal that killed it.
    exit: i32,
    /// The signal that killed it, if one did.
    signal: Option<i32>,
    /// Its peak resident set (bytes), where the system tells it.
    peak_bytes: Option<u64>,
}

/// Runs `job` in a child process and returns its row, with the fingerprint given, the
/// seconds the process took and its peak memory.
pub fn run_case_in_child(command: &ChildCommand, job: &Job, fingerprint: Option<String>) -> Row {
    let clock = Instant::now();
    let mut row = match run(command, job) {
        Ok((ended, stdout, stderr)) => match serde_json::from_slice::<Row>(&stdout) {
            Ok(row) if ended.signal.is_none() => Row { peak_memory_mib: mib(ended.peak_bytes), ..row },
            _ => Row {
                peak_memory_mib: mib(ended.peak_bytes),
                ..Row::failed(&job.case.name, ended.exit, &cause(&ended, &stderr))
            },
        },
        Err(e) => Row::failed(
            &job.case.name,
            super::EXIT_ERROR,
            &format!("cannot run {} for the case: {e}", command.program.display()),
        ),
    };
    row.seconds = clock.elapsed().as_secs_f64();
    row.fingerprint = fingerprint;
    row
}

fn mib(bytes: Option<u64>) -> Option<f64> {
    bytes.map(|b| (b as f64 / 1048576.0 * 10.0).round() / 10.0)
}

/// Starts the child, hands it the job, collects what it writes and waits for it.
fn run(command: &ChildCommand, job: &Job) -> std::io::Result<(Ended, Vec<u8>, Vec<u8>)> {
    let input = serde_json::to_vec(job).map_err(std::io::Error::other)?;
    let mut process = Command::new(&command.program);
    process.args(&command.args).stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(Stdio::piped());
    end_with_parent(&mut process);
    let mut child = process.spawn()?;
    let mut stdin = child.stdin.take().expect("piped");
    let mut stderr = child.stderr.take().expect("piped");
    let mut stdout = child.stdout.take().expect("piped");
    let said = std::thread::spawn(move || {
        let mut text = vec![];
        let _ = stderr.read_to_end(&mut text);
        text
    });
    // A child that dies before reading its job closes the pipe: its end is reported below.
    let _ = stdin.write_all(&input);
    drop(stdin);
    let mut out = vec![];
    let _ = stdout.read_to_end(&mut out);
    let ended = wait(child)?;
    let err = said.join().unwrap_or_default();
    Ok((ended, out, err))
}

/// On Linux the child is sent SIGTERM when the thread that started it ends (the batch killed):
/// it then removes what it had begun to write, as `vesselhex mesh` does when interrupted.
#[cfg(target_os = "linux")]
fn end_with_parent(command: &mut Command) {
    use std::os::unix::process::CommandExt;
    // SAFETY: prctl is async-signal-safe and touches no memory of the parent.
    unsafe {
        command.pre_exec(|| {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
}

#[cfg(not(target_os = "linux"))]
fn end_with_parent(_command: &mut Command) {}

/// Waits for the child with `wait4`, which gives its own resource use (its peak resident set).
#[cfg(unix)]
fn wait(child: std::process::Child) -> std::io::Result<Ended> {
    let pid = child.id() as libc::pid_t;
    let mut status: libc::c_int = 0;
    // SAFETY: an all-zero rusage is a valid value for wait4 to fill.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    loop {
        // SAFETY: status and usage are valid for writes; pid is our own child, not yet waited for.
        let r = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
        if r == pid {
            break;
        }
        let e = std::io::Error::last_os_error();
        if e.kind() != std::io::ErrorKind::Interrupted {
            return Err(e);
        }
    }
    // Reaped here: the Child must not be waited for again (dropping it does not wait).
    drop(child);
    // Linux and the BSDs give ru_maxrss in KiB (macOS in bytes).
    let unit = if cfg!(target_os = "macos") { 1 } else { 1024 };
    let peak_bytes = Some(usage.ru_maxrss as u64 * unit);
    let (exit, signal) = if libc::WIFSIGNALED(status) {
        let s = libc::WTERMSIG(status);
        (128 + s, Some(s))
    } else {
        (libc::WEXITSTATUS(status), None)
    };
    Ok(Ended { exit, signal, peak_bytes })
}

#[cfg(not(unix))]
fn wait(mut child: std::process::Child) -> std::io::Result<Ended> {
    let status = child.wait()?;
    Ok(Ended { exit: status.code().unwrap_or(super::EXIT_ERROR), signal: None, peak_bytes: None })
}

/// The one line saying how a child that gave no row ended: its signal or exit code, and the
/// last thing it wrote on standard error (a panic's message, an allocation that failed).
fn cause(ended: &Ended, stderr: &[u8]) -> String {
    let how = match ended.signal {
        Some(9) => {
            "its process was killed (SIGKILL: the system's out-of-memory killer, or a scheduler's limit)".to_string()
        }
        Some(s) => format!("its process was killed by signal {s} ({})", signal_name(s)),
        None => format!("its process ended with exit code {} without a result", ended.exit),
    };
    let text = String::from_utf8_lossy(stderr);
    let said: Vec<&str> =
        text.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with("note: run with")).collect();
    match said.len() {
        0 => how,
        n => format!("{how}: {}", said[n.saturating_sub(2)..].join(" ")),
    }
}

fn signal_name(signal: i32) -> &'static str {
    match signal {
        4 => "SIGILL",
        6 => "SIGABRT: an abort, e.g. memory that could not be allocated",
        7 => "SIGBUS",
        11 => "SIGSEGV: a crash",
        s => crate::output::signal_name(s),
    }
}

/// The body of the child process: reads a [`Job`] on standard input, meshes its case with
/// `threads` worker threads (its `settings.threads`), writes the [`Row`] on standard output and
/// returns the exit code `vesselhex mesh` would give the case.
pub fn child_main() -> i32 {
    let job = match read_job() {
        Ok(job) => job,
        Err(e) => {
            eprintln!("vesselhex: error: {e} (batch-case is run by `vesselhex batch`, not by hand)");
            return super::EXIT_ERROR;
        }
    };
    if let Some(n) = job.settings.threads.filter(|&n| n > 0) {
        // A fresh process: its pool is not built yet.
        let _ = rayon::ThreadPoolBuilder::new().num_threads(n).build_global();
    }
    let row = super::case::mesh_case(&job.case, &job.settings, &job.output);
    match serde_json::to_string(&row) {
        Ok(line) => println!("{line}"),
        Err(e) => eprintln!("vesselhex: error: internal: cannot encode the row: {e}"),
    }
    row.exit
}

fn read_job() -> std::result::Result<Job, String> {
    let mut input = vec![];
    std::io::stdin().read_to_end(&mut input).map_err(|e| format!("cannot read the job on standard input: {e}"))?;
    serde_json::from_slice(&input).map_err(|e| format!("the job on standard input is not one: {e}"))
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    fn shell(script: &str) -> ChildCommand {
        ChildCommand { program: "/bin/sh".into(), args: vec!["-c".into(), script.into()] }
    }

    fn job() -> Job {
        Job { case: Case { name: "c".into(), ..Default::default() }, settings: Settings::default(), output: ".".into() }
    }

    #[test]
    fn a_killed_child_is_one_failed_row_naming_how_it_ended() {
        let row = run_case_in_child(
            &shell("cat >/dev/null; echo 'memory allocation of 8 bytes failed' >&2; kill -9 $$"),
            &job(),
            None,
        );
        assert_eq!((row.case.as_str(), row.exit, row.status), ("c", 137, super::super::Status::Failed));
        assert!(
            row.cause.contains("SIGKILL") && row.cause.contains("memory allocation of 8 bytes failed"),
            "{}",
            row.cause
        );
        assert!(row.peak_memory_mib.is_some() && row.seconds > 0.0);
        let row = run_case_in_child(
            &shell("echo \"thread 'main' panicked at x.rs:1:2:\" >&2; echo boom >&2; exit 101"),
            &job(),
            None,
        );
        assert_eq!(row.exit, 101);
        assert!(
            row.cause.contains("exit code 101") && row.cause.ends_with("panicked at x.rs:1:2: boom"),
            "{}",
            row.cause
        );
    }

    #[test]
    fn a_childs_row_comes_back_with_its_memory_and_fingerprint() {
        let line = serde_json::to_string(&Row::failed("c", 1, "refused")).unwrap();
        let row =
            run_case_in_child(&shell(&format!("cat >/dev/null; echo '{line}'; exit 1")), &job(), Some("f".into()));
        assert_eq!((row.exit, row.cause.as_str(), row.fingerprint.as_deref()), (1, "refused", Some("f")));
        assert!(row.peak_memory_mib.unwrap() > 0.0);
        let missing = ChildCommand { program: "/nonexistent/vesselhex".into(), args: vec![] };
        assert!(run_case_in_child(&missing, &job(), None).cause.starts_with("cannot run /nonexistent/vesselhex"));
    }
}
