//! Files written whole or not at all: each through a temporary file beside it, renamed over
//! the final name when complete (see [`crate::io::output`] for the folder they go in).

use crate::data::error::{Error, Result};
use crate::io::sink::Sink;
use std::path::Path;

/// Writes a text file at `dir/rel` (creating its folders) through [`write_atomic`]; `executable`
/// makes it runnable (scripts such as `Allrun`).
pub fn write_text_file(dir: &Path, rel: &str, text: &str, executable: bool) -> Result<()> {
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
/// the temporary file (see [`crate::io::output`]); a write after the signal fails. The bytes go
/// through a [`Sink`]: whole buffers past the page cache where the system allows it.
pub fn write_atomic(path: &Path, write: impl FnOnce(&mut dyn std::io::Write) -> std::io::Result<()>) -> Result<()> {
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let mut prefix = std::ffi::OsString::from(".");
    prefix.push(path.file_name().unwrap_or_default());
    prefix.push(".");
    let tmp = crate::io::output::create_partial(|| {
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
        let mut w = Sink::new(tmp.as_file());
        write(&mut w)?;
        w.finish()?;
        tmp.as_file().sync_all()?;
        crate::io::output::check_interrupted()?;
        tmp.persist(path).map(|_| ()).map_err(|e| e.error)
    })();
    crate::io::output::forget_partial(&tmp_path);
    result.map_err(|e| Error::io(path, "cannot write", e))
}
