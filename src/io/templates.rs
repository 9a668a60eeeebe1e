//! The user's solver templates (`fe.template_dir`): a folder of `abaqus/` and `calculix/`
//! files that replace the built-in ones of the same name, read here and filled by
//! [`crate::writers::template`].

use crate::data::error::{Error, Result};
use std::path::Path;

/// Largest template read from a user's folder.
const MAX_TEMPLATE_BYTES: u64 = 1 << 20;

/// Checks `fe.template_dir`: a folder holding an `abaqus/` or a `calculix/` folder of templates
/// (a missing or misspelt folder would otherwise fall back to the built-in templates unseen).
pub fn check_template_dir(dir: &Path) -> Result<()> {
    let bad = |why: &str| Err(Error::Config(format!("fe.template_dir: {} {why}", dir.display())));
    match std::fs::metadata(dir) {
        Err(_) => bad("does not exist; give the folder of your templates (relative to the case file)"),
        Ok(m) if !m.is_dir() => bad("is not a folder; give the folder holding abaqus/ and calculix/"),
        Ok(_) if !["abaqus", "calculix"].iter().any(|d| dir.join(d).is_dir()) => {
            bad("holds neither an abaqus/ nor a calculix/ folder of templates (see templates/ for the names)")
        }
        Ok(_) => {
            for sub in ["abaqus", "calculix"] {
                let Ok(entries) = std::fs::read_dir(dir.join(sub)) else { continue };
                for entry in entries.flatten() {
                    user_template_path(dir, &Path::new(sub).join(entry.file_name()))?;
                }
            }
            Ok(())
        }
    }
}

/// The real path of the user's template `dir/rel`, which must be a regular file inside `dir`
/// (a link leading out of it, to `/etc/shadow` say, is refused, never copied into a deck).
fn user_template_path(dir: &Path, rel: &Path) -> Result<std::path::PathBuf> {
    let path = dir.join(rel);
    let real_dir = dir.canonicalize().map_err(|e| Error::io(dir, "cannot read the template folder", e))?;
    let real = path.canonicalize().map_err(|e| Error::io(&path, "cannot read the template", e))?;
    if !real.starts_with(&real_dir) {
        return Err(Error::input(
            &path,
            format!(
                "is a link leading out of the template folder (to {}); copy the template into {}",
                real.display(),
                dir.display()
            ),
        ));
    }
    if !real.is_file() {
        return Err(Error::input(&path, "is not a regular file; a template is a text file"));
    }
    Ok(real)
}

/// The text of the user's template `dir/rel` and its name for messages, or `None` when the
/// folder has no such file (the built-in one is used). A template must be a regular file inside
/// the folder: a link leading out of it (to `/etc/shadow`, say) is refused, not copied into a deck.
pub fn read_user_template(dir: &Path, rel: &Path) -> Result<Option<(String, String)>> {
    let path = dir.join(rel);
    match std::fs::symlink_metadata(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(Error::io(&path, "cannot read the template", e)),
        Ok(_) => {}
    }
    let real = user_template_path(dir, rel)?;
    let bytes = crate::io::input::read_regular_file(&real, MAX_TEMPLATE_BYTES, "cannot read the template")?;
    let text = String::from_utf8(bytes).map_err(|_| Error::input(&path, "is not UTF-8 text"))?;
    Ok(Some((text, path.display().to_string())))
}
