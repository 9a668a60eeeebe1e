//! The output folder of `vesselhex mesh`: claimed, staged, committed in one rename, and cleaned
//! up when the run fails or is interrupted.
//!
//! - Claim: the folder `--output` names is locked (an advisory lock on the folder itself, held
//!   for the whole run), so a second run into it is refused instead of mixing two vessels.
//! - Ownership: vesselhex replaces only a folder that is empty, that it creates, or that it wrote
//!   before: its `report.json` lists every file written (`outputs`), and any other entry (a
//!   user's file, a solver's results) makes the folder foreign, refused without `--force`.
//! - Staging: everything is written into a fresh folder beside the output (`.NAME.vesselhex-XXXXXXXX`,
//!   a random name created by mkdir, which never follows a link), never into the output itself.
//! - Commit: the staging folder and the output folder swap names in one `renameat2` exchange and
//!   the old content is removed, so a reader sees the old result or the new one, never a mix,
//!   and formats the new run did not write go with the old content. Where the exchange is not
//!   available, two renames (the output is briefly absent, still never mixed).
//! - Interruption: SIGINT, SIGTERM and SIGHUP remove what the run created (staging folder,
//!   partial files, an output folder it created) and exit with 128 + the signal number.

use crate::data::error::{Error, Result};
use std::ffi::OsString;
use std::fs::File;
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicI32, Ordering};
use std::sync::{Mutex, MutexGuard};

/// The name of the file that marks a folder as vesselhex's (it lists every file written).
pub const MARKER: &str = "report.json";

/// Largest `report.json` read to decide whether a folder is vesselhex's.
const MAX_MARKER_BYTES: u64 = 64 << 20;

/// What an interruption must remove, registered as the run creates it.
struct Undo {
    /// Folders removed with their content (staging folders).
    trees: Vec<PathBuf>,
    /// Files (partial files written outside a staging folder).
    files: Vec<PathBuf>,
    /// Folders this run created, removed when empty (deepest last).
    created: Vec<PathBuf>,
    /// While set, the writers are filling the staging folder: a signal only raises the flag and
    /// the run stops at its next write (removing the folder under a writer that creates
    /// subfolders would let it create them again).
    writing: bool,
}

impl Undo {
    fn remove_all(&mut self) {
        for dir in self.trees.drain(..) {
            let _ = std::fs::remove_dir_all(dir);
        }
        for file in self.files.drain(..) {
            let _ = std::fs::remove_file(file);
        }
        for dir in self.created.drain(..).rev() {
            let _ = std::fs::remove_dir(dir);
        }
    }
}

static UNDO: Mutex<Undo> = Mutex::new(Undo { trees: vec![], files: vec![], created: vec![], writing: false });

/// The signal that interrupted the run (0: none).
static SIGNAL: AtomicI32 = AtomicI32::new(0);

fn undo() -> MutexGuard<'static, Undo> {
    UNDO.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// The signal that interrupted the run, if one did.
pub fn interrupted_by() -> Option<i32> {
    match SIGNAL.load(Ordering::SeqCst) {
        0 => None,
        s => Some(s),
    }
}

/// The exit code of a run interrupted by `signal`: 128 + its number (130 SIGINT, 143 SIGTERM,
/// 129 SIGHUP), as shells report it.
pub fn exit_code_of(signal: i32) -> u8 {
    (128 + signal).clamp(0, 255) as u8
}

/// The signal's name, for the message.
pub fn signal_name(signal: i32) -> &'static str {
    match signal {
        1 => "SIGHUP",
        2 => "SIGINT",
        15 => "SIGTERM",
        _ => "a signal",
    }
}

/// The one line printed when `signal` interrupts a run.
pub fn interruption(signal: i32) -> String {
    format!("interrupted by {}: what the run had begun to write was removed", signal_name(signal))
}

/// An error when the run was interrupted, to stop a writer at its next write.
pub(crate) fn check_interrupted() -> std::io::Result<()> {
    match interrupted_by() {
        None => Ok(()),
        Some(s) => Err(std::io::Error::other(format!("interrupted by {}", signal_name(s)))),
    }
}

/// Installs the handlers of SIGINT, SIGTERM and SIGHUP: a thread that removes what the run
/// created and exits with 128 + the signal number (or, while the writers fill the staging
/// folder, raises the flag the writers stop on; the run then cleans up and exits the same way).
#[cfg(unix)]
pub fn install_signal_handlers() -> Result<()> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP])
        .map_err(|e| Error::Config(format!("internal: cannot install the signal handlers: {e}")))?;
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            for signal in signals.forever() {
                let _ = SIGNAL.compare_exchange(0, signal, Ordering::SeqCst, Ordering::SeqCst);
                let mut undo = undo();
                if !undo.writing {
                    undo.remove_all();
                    eprintln!("vesselhex: {}", interruption(signal));
                    // Exits with the lock held: no other thread creates a file after the removal.
                    std::process::exit(exit_code_of(signal) as i32);
                }
            }
        })
        .map_err(|e| Error::Config(format!("internal: cannot start the signal thread: {e}")))?;
    Ok(())
}

#[cfg(not(unix))]
pub fn install_signal_handlers() -> Result<()> {
    Ok(())
}

/// Creates a file that a signal removes until [`forget_partial`] is called: created with the
/// lock held, so a signal either sees it registered or exits before it exists.
pub(crate) fn create_partial(
    create: impl FnOnce() -> std::io::Result<tempfile::NamedTempFile>,
) -> std::io::Result<tempfile::NamedTempFile> {
    let mut undo = undo();
    check_interrupted()?;
    let file = create()?;
    undo.files.push(file.path().to_path_buf());
    Ok(file)
}

/// The partial file is renamed or removed: a signal has nothing more to do with it.
pub(crate) fn forget_partial(path: &Path) {
    undo().files.retain(|p| p != path);
}

/// `--output`, claimed for this run: locked, checked to be vesselhex's (or empty, or new), with
/// the staging folder beside it. Dropped without [`OutputFolder::commit`], it removes the
/// staging folder and every folder the claim created.
pub struct OutputFolder {
    /// The output folder (its parent made absolute, links in the parent resolved).
    path: PathBuf,
    staging: PathBuf,
    /// The locked folder (the lock lasts as long as the handle).
    _lock: Locked,
    /// Folders created by the claim (the output's missing parents and the output), outermost first.
    created: Vec<PathBuf>,
    done: bool,
}

/// How many times a claim retries when the folder is replaced while it locks it.
const CLAIM_ATTEMPTS: usize = 20;

impl OutputFolder {
    /// Claims `output`. `inputs` are the files the run reads (never inside a folder it may
    /// replace); `force` lets it replace a folder vesselhex did not write.
    pub fn claim(output: &Path, inputs: &[&Path], force: bool) -> Result<OutputFolder> {
        let (parent, name) = split_output(output)?;
        let path = parent.join(&name);
        refuse_dangerous(output, &path, inputs)?;
        // With the lock held, so that a signal sees every folder created here.
        let mut undo = undo();
        check_interrupted().map_err(|e| Error::io(output, "stopped", e))?;
        let mut created = create_missing(&parent)?;
        let claimed = (|| {
            let lock = lock_folder(output, &path, &mut created)?;
            check_owned(output, &path, force)?;
            remove_stale_staging(&parent, &name);
            let staging = fresh_folder(&parent, &name)
                .map_err(|e| Error::io(&parent, "cannot create the staging folder beside the output folder", e))?;
            Ok((lock, staging))
        })();
        let (lock, staging) = match claimed {
            Ok(c) => c,
            Err(e) => {
                remove_created(&created);
                return Err(e);
            }
        };
        undo.trees.push(staging.clone());
        undo.created.extend(created.iter().cloned());
        Ok(OutputFolder { path, staging, _lock: lock, created, done: false })
    }

    /// Where the writers put their files.
    pub fn staging(&self) -> &Path {
        &self.staging
    }

    /// The writers start: from now on a signal stops them at their next write and the run
    /// cleans up (see [`Undo::writing`]). Refused if a signal came already.
    pub fn begin_writing(&self) -> Result<()> {
        let mut undo = undo();
        check_interrupted().map_err(|e| Error::io(&self.path, "stopped", e))?;
        undo.writing = true;
        Ok(())
    }

    /// Puts the staging folder in place of the output folder in one rename and removes the old
    /// content.
    pub fn commit(mut self) -> Result<()> {
        check_interrupted().map_err(|e| Error::io(&self.path, "not committed", e))?;
        exchange(&self.staging, &self.path)?;
        self.done = true;
        // The staging name now holds the old content (or nothing, after the fallback).
        let _ = std::fs::remove_dir_all(&self.staging);
        forget(&self.staging, &self.created);
        Ok(())
    }
}

impl Drop for OutputFolder {
    fn drop(&mut self) {
        if !self.done {
            let _ = std::fs::remove_dir_all(&self.staging);
            remove_created(&self.created);
            forget(&self.staging, &self.created);
        }
    }
}

/// Unregisters a staging folder and the claim's folders, and ends the writing phase.
fn forget(staging: &Path, created: &[PathBuf]) {
    let mut undo = undo();
    undo.trees.retain(|p| p != staging);
    undo.created.retain(|p| !created.contains(p));
    undo.writing = false;
}

fn remove_created(created: &[PathBuf]) {
    for dir in created.iter().rev() {
        let _ = std::fs::remove_dir(dir);
    }
}

/// Random characters of the staging folder's name.
const STAGING_RANDOM: usize = 8;

/// A new empty folder `.NAME.vesselhex-XXXXXXXX` in `parent` (created by mkdir, which fails
/// rather than follow a link planted at the name).
fn fresh_folder(parent: &Path, name: &std::ffi::OsStr) -> std::io::Result<PathBuf> {
    let prefix = staging_prefix(name);
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).rand_bytes(STAGING_RANDOM).disable_cleanup(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o777)); // less the umask, as any folder
    }
    Ok(builder.tempdir_in(parent)?.keep())
}

fn staging_prefix(name: &std::ffi::OsStr) -> OsString {
    let mut prefix = OsString::from(".");
    prefix.push(name);
    prefix.push(".vesselhex-");
    prefix
}

/// The output's parent (absolute, links resolved where it exists) and its name.
fn split_output(output: &Path) -> Result<(PathBuf, OsString)> {
    let refuse = |why: &str| Err(Error::input(output, why));
    if output.as_os_str().is_empty() {
        return refuse("empty path; name the folder to write into");
    }
    let absolute = std::path::absolute(output).map_err(|e| Error::io(output, "cannot resolve the output folder", e))?;
    // "x/.." and "." name a folder by its relation to another: resolve them first.
    let absolute = match absolute.components().next_back() {
        Some(Component::Normal(_)) => absolute,
        _ => absolute.canonicalize().map_err(|e| Error::io(output, "cannot resolve the output folder", e))?,
    };
    let (Some(parent), Some(name)) = (absolute.parent(), absolute.file_name()) else {
        return refuse("is the root folder; name a folder of its own for the outputs");
    };
    let mut parent = parent.to_path_buf();
    // Resolve the parent's links where it exists (the part that does not is created).
    let existing = parent.ancestors().find(|a| std::fs::symlink_metadata(a).is_ok()).map(Path::to_path_buf);
    if let Some(existing) = existing {
        if !existing.is_dir() {
            return Err(Error::input(
                output,
                format!("{} is a file, not a folder; choose another --output", existing.display()),
            ));
        }
        if let Ok(real) = existing.canonicalize() {
            let rest = parent.strip_prefix(&existing).map(Path::to_path_buf).unwrap_or_default();
            parent = if rest.as_os_str().is_empty() { real } else { real.join(rest) };
        }
    }
    Ok((parent, name.to_os_string()))
}

/// Creates the missing folders of `dir`, one at a time; returns them, outermost first.
fn create_missing(dir: &Path) -> Result<Vec<PathBuf>> {
    let missing: Vec<PathBuf> =
        dir.ancestors().take_while(|a| std::fs::symlink_metadata(a).is_err()).map(Path::to_path_buf).collect();
    let mut created = vec![];
    for d in missing.into_iter().rev() {
        match std::fs::create_dir(&d) {
            Ok(()) => created.push(d),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && d.is_dir() => {}
            Err(e) => {
                remove_created(&created);
                return Err(Error::io(&d, "cannot create the output folder's parent (choose another --output)", e));
            }
        }
    }
    Ok(created)
}

/// Refuses an output folder that holds the current folder or an input file.
fn refuse_dangerous(output: &Path, path: &Path, inputs: &[&Path]) -> Result<()> {
    let refuse = |why: String| Err(Error::input(output, why));
    let own_folder = "vesselhex replaces the whole output folder, so name a folder of its own (e.g. out/vessel)";
    if path.components().filter(|c| matches!(c, Component::Normal(_))).count() < 2 {
        return refuse(format!("is a top-level folder; {own_folder}"));
    }
    for (what, dir) in [("the current folder", std::env::current_dir().ok()), ("the home folder", std::env::home_dir())]
    {
        if dir.and_then(|d| d.canonicalize().ok()).is_some_and(|d| d.starts_with(path)) {
            return refuse(format!("is {what} or holds it; {own_folder}"));
        }
    }
    for input in inputs {
        if let Ok(real) = input.canonicalize() {
            if real.starts_with(path) {
                return refuse(format!(
                    "holds the input {}; vesselhex replaces the whole output folder, so write elsewhere or move \
                     the input out",
                    input.display()
                ));
            }
        }
    }
    Ok(())
}

/// Creates the output folder if it is missing and locks it; refuses a link, a file, and a
/// folder another run holds.
fn lock_folder(output: &Path, path: &Path, created: &mut Vec<PathBuf>) -> Result<Locked> {
    let refuse = |why: &str| Err(Error::input(output, why));
    for _ in 0..CLAIM_ATTEMPTS {
        match std::fs::symlink_metadata(path) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => match std::fs::create_dir(path) {
                Ok(()) => created.push(path.to_path_buf()),
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                Err(e) => return Err(Error::io(path, "cannot create the output folder (choose another --output)", e)),
            },
            Err(e) => return Err(Error::io(path, "cannot read the output folder", e)),
            Ok(m) if m.file_type().is_symlink() => {
                return refuse("is a symbolic link; give the folder it points to, or another name")
            }
            Ok(m) if !m.is_dir() => return refuse("is a file, not a folder; choose another --output"),
            Ok(_) => {}
        }
        match lock(path) {
            Ok(Some(lock)) => return Ok(lock),
            Ok(None) => continue, // replaced while locking: look again
            Err(LockError::Held) => {
                return refuse(
                    "another vesselhex run is writing into this folder; wait for it to finish or choose another \
                     --output",
                )
            }
            Err(LockError::Io(e)) => return Err(Error::io(path, "cannot lock the output folder", e)),
        }
    }
    refuse("the folder keeps changing while vesselhex claims it; is another program writing there?")
}

/// The lock on the output folder, held as long as this value lives.
#[allow(dead_code)] // held, never read
enum Locked {
    Folder(File),
    /// Where folders cannot be locked.
    Unsupported,
}

enum LockError {
    Held,
    Io(std::io::Error),
}

/// Locks the folder at `path` without following a link; `None` when what was locked is no
/// longer the folder at `path` (another run replaced it meanwhile).
#[cfg(unix)]
fn lock(path: &Path) -> std::result::Result<Option<Locked>, LockError> {
    use rustix::fs::OFlags;
    use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
    let handle = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags((OFlags::DIRECTORY | OFlags::NOFOLLOW).bits() as i32)
        .open(path)
        .map_err(LockError::Io)?;
    match handle.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => return Err(LockError::Held),
        Err(std::fs::TryLockError::Error(e)) => return Err(LockError::Io(e)),
    }
    let locked = handle.metadata().map_err(LockError::Io)?;
    let now = match std::fs::symlink_metadata(path) {
        Ok(m) => m,
        Err(_) => return Ok(None),
    };
    Ok((locked.dev() == now.dev() && locked.ino() == now.ino()).then_some(Locked::Folder(handle)))
}

#[cfg(not(unix))]
fn lock(_path: &Path) -> std::result::Result<Option<Locked>, LockError> {
    Ok(Some(Locked::Unsupported))
}

/// Refuses a folder holding anything vesselhex did not write, unless `force`.
fn check_owned(output: &Path, path: &Path, force: bool) -> Result<()> {
    if force {
        return Ok(());
    }
    let listed = match written_by_vesselhex(path) {
        Some(listed) => listed,
        None => {
            let mut entries =
                std::fs::read_dir(path).map_err(|e| Error::io(path, "cannot list the output folder", e))?;
            return match entries.next() {
                None => Ok(()),
                Some(entry) => Err(Error::input(
                    output,
                    format!(
                        "the output folder holds files vesselhex did not write (e.g. {}); vesselhex replaces the \
                         whole folder, so choose a new or empty folder, or give --force to replace it (its content \
                         is deleted)",
                        entry.map(|e| e.file_name().to_string_lossy().into_owned()).unwrap_or_default()
                    ),
                )),
            };
        }
    };
    if let Some(foreign) = first_unlisted(path, Path::new(""), &listed)? {
        return Err(Error::input(
            output,
            format!(
                "{} in the output folder was not written by vesselhex (its report.json does not list it); move it \
                 out, choose another --output, or give --force to replace the folder (its content is deleted)",
                foreign.display()
            ),
        ));
    }
    Ok(())
}

/// The files a folder's `report.json` says vesselhex wrote there, if it is vesselhex's.
fn written_by_vesselhex(path: &Path) -> Option<std::collections::HashSet<PathBuf>> {
    let marker = path.join(MARKER);
    let meta = std::fs::symlink_metadata(&marker).ok()?;
    if !meta.is_file() || meta.len() > MAX_MARKER_BYTES {
        return None;
    }
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&marker).ok()?).ok()?;
    report.get("vesselhex_version")?.as_str()?;
    let outputs = report.get("outputs")?.as_array()?;
    let mut listed = std::collections::HashSet::new();
    for o in outputs {
        let rel = PathBuf::from(o.as_str()?);
        if !rel.components().all(|c| matches!(c, Component::Normal(_))) {
            return None;
        }
        listed.insert(rel);
    }
    listed.insert(PathBuf::from(MARKER));
    Some(listed)
}

/// The first entry under `root/rel` that is neither a listed file nor a folder on the way to
/// one (links are entries, never followed).
fn first_unlisted(root: &Path, rel: &Path, listed: &std::collections::HashSet<PathBuf>) -> Result<Option<PathBuf>> {
    let dir = root.join(rel);
    let mut entries: Vec<_> = std::fs::read_dir(&dir)
        .map_err(|e| Error::io(&dir, "cannot list", e))?
        .filter_map(|e| e.ok())
        .map(|e| e.file_name())
        .collect();
    entries.sort();
    for name in entries {
        let entry = rel.join(&name);
        let meta =
            std::fs::symlink_metadata(root.join(&entry)).map_err(|e| Error::io(root.join(&entry), "cannot read", e))?;
        if meta.is_file() && listed.contains(&entry) {
            continue;
        }
        if meta.is_dir() && listed.iter().any(|l| l.starts_with(&entry)) {
            if let Some(found) = first_unlisted(root, &entry, listed)? {
                return Ok(Some(found));
            }
            continue;
        }
        return Ok(Some(entry));
    }
    Ok(None)
}

/// Removes staging folders of earlier runs into the same output that were killed (SIGKILL,
/// power loss): with the output locked, no live run owns one.
fn remove_stale_staging(parent: &Path, name: &std::ffi::OsStr) {
    let prefix = staging_prefix(name);
    let prefix = prefix.as_encoded_bytes();
    let Ok(entries) = std::fs::read_dir(parent) else { return };
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        let bytes = file_name.as_encoded_bytes();
        let stale = bytes.len() == prefix.len() + STAGING_RANDOM
            && bytes.starts_with(prefix)
            && bytes[prefix.len()..].iter().all(u8::is_ascii_alphanumeric);
        if stale && entry.file_type().is_ok_and(|t| t.is_dir()) {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

/// Swaps the names of two folders in one step (`renameat2` with `RENAME_EXCHANGE`); where the
/// system or file system cannot, moves `to` aside and `from` in its place.
fn exchange(from: &Path, to: &Path) -> Result<()> {
    #[cfg(any(target_os = "linux", target_os = "android"))]
    {
        use rustix::fs::{renameat_with, RenameFlags, CWD};
        use rustix::io::Errno;
        match renameat_with(CWD, from, CWD, to, RenameFlags::EXCHANGE) {
            Ok(()) => return Ok(()),
            // The kernel or the file system cannot exchange.
            Err(e) if [Errno::INVAL, Errno::NOSYS, Errno::NOTSUP, Errno::OPNOTSUPP].contains(&e) => {}
            Err(e) => return Err(Error::io(to, "cannot move the new outputs into place", e.into())),
        }
    }
    replace_by_two_renames(from, to)
}

/// Moves the folder `to` aside (under a fresh name: renaming a folder onto an empty one
/// replaces it), `from` in its place, and removes the old one; `to` is briefly absent.
fn replace_by_two_renames(from: &Path, to: &Path) -> Result<()> {
    let (parent, name) = (to.parent().unwrap_or(to), to.file_name().unwrap_or_default());
    let aside = fresh_folder(parent, name).map_err(|e| Error::io(to, "cannot make room for the old outputs", e))?;
    if let Err(e) = std::fs::rename(to, &aside) {
        let _ = std::fs::remove_dir(&aside);
        return Err(Error::io(to, "cannot move the old outputs aside", e));
    }
    if let Err(e) = std::fs::rename(from, to) {
        let _ = std::fs::rename(&aside, to);
        return Err(Error::io(to, "cannot move the new outputs into place", e));
    }
    let _ = std::fs::remove_dir_all(&aside);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("vesselhex-output-{}-{tag}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut n: Vec<String> =
            std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        n.sort();
        n
    }

    #[test]
    fn both_ways_of_committing_leave_the_new_content_only() {
        for (k, commit) in [exchange, replace_by_two_renames].into_iter().enumerate() {
            let d = scratch(&format!("commit-{k}"));
            let (old, new) = (d.join("out"), d.join(".out.vesselhex-abcdefgh"));
            std::fs::create_dir_all(old.join("openfoam")).unwrap();
            std::fs::write(old.join("openfoam/p"), "old").unwrap();
            std::fs::create_dir_all(&new).unwrap();
            std::fs::write(new.join("mesh.vtu"), "new").unwrap();
            commit(&new, &old).unwrap();
            let _ = std::fs::remove_dir_all(&new); // what commit() does with the old content
            assert_eq!(names(&old), ["mesh.vtu"]);
            assert_eq!(names(&d), ["out"], "nothing left beside the output");
            std::fs::remove_dir_all(&d).unwrap();
        }
    }

    #[test]
    fn a_folder_is_vesselhexs_only_with_every_entry_listed() {
        let d = scratch("owned");
        std::fs::create_dir_all(d.join("openfoam/system")).unwrap();
        for f in ["mesh.vtu", "openfoam/system/controlDict"] {
            std::fs::write(d.join(f), "x").unwrap();
        }
        let report =
            r#"{"vesselhex_version": "0", "outputs": ["mesh.vtu", "openfoam/system/controlDict", "report.json"]}"#;
        std::fs::write(d.join(MARKER), report).unwrap();
        let listed = written_by_vesselhex(&d).expect("vesselhex's");
        assert_eq!(first_unlisted(&d, Path::new(""), &listed).unwrap(), None);
        std::fs::write(d.join("openfoam/system/mine"), "x").unwrap();
        assert_eq!(first_unlisted(&d, Path::new(""), &listed).unwrap(), Some(PathBuf::from("openfoam/system/mine")));
        // A report listing a path out of the folder marks nothing.
        std::fs::write(d.join(MARKER), r#"{"vesselhex_version": "0", "outputs": ["../x"]}"#).unwrap();
        assert!(written_by_vesselhex(&d).is_none());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn the_root_is_no_output_folder() {
        assert!(split_output(Path::new("/")).is_err());
        assert!(split_output(Path::new("")).is_err());
        let (parent, name) = split_output(Path::new("a/b")).unwrap();
        assert!(parent.is_absolute() && parent.ends_with("a") && name == "b");
    }
}
