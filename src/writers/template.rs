//! Solver-case templates (`templates/`, or the user's `fe.template_dir`, read by
//! [`crate::io::templates`]): `{{name}}` placeholders filled by the writers.
//!
//! Strict, so a template and its writer cannot drift apart silently: a placeholder without a
//! value and an unclosed `{{` are errors naming the template; [`render_all`] also refuses a value
//! that no placeholder uses (for built-in templates, where every value must land somewhere).

use crate::data::error::{Error, Result};

/// Fills the placeholders of `text` (named `label` in messages). Whitespace inside the braces is
/// ignored: `{{ name }}` = `{{name}}`.
pub fn render(label: &str, text: &str, values: &[(&str, String)]) -> Result<String> {
    fill(label, text, values).map(|(out, _)| out)
}

/// As [`render`], and every value must be used.
pub fn render_all(label: &str, text: &str, values: &[(&str, String)]) -> Result<String> {
    let (out, used) = fill(label, text, values)?;
    match used.iter().position(|u| !u) {
        Some(i) => Err(Error::Config(format!("template {label}: no placeholder for value '{}'", values[i].0))),
        None => Ok(out),
    }
}

fn fill(label: &str, text: &str, values: &[(&str, String)]) -> Result<(String, Vec<bool>)> {
    let mut out = String::with_capacity(text.len() + 256);
    let mut used = vec![false; values.len()];
    let mut rest = text;
    while let Some(start) = rest.find("{{") {
        out.push_str(&rest[..start]);
        let after = &rest[start + 2..];
        let end = after.find("}}").ok_or_else(|| Error::Config(format!("template {label}: unclosed '{{{{'")))?;
        let key = after[..end].trim();
        let i = values.iter().position(|(k, _)| *k == key).ok_or_else(|| {
            let known: Vec<&str> = values.iter().map(|(k, _)| *k).collect();
            Error::Config(format!("template {label}: unknown placeholder {{{{{key}}}}} (known: {})", known.join(", ")))
        })?;
        used[i] = true;
        out.push_str(&values[i].1);
        rest = &after[end + 2..];
    }
    out.push_str(rest);
    Ok((out, used))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn placeholders_are_strict() {
        let v = [("A", "1".to_string()), ("B", "2".to_string())];
        assert_eq!(render("t", "x {{A}} {{ A }} {{B}}", &v).unwrap(), "x 1 1 2");
        let e = render("t.inp", "{{C}}", &v).unwrap_err().to_string();
        assert!(e.contains("t.inp") && e.contains("{{C}}") && e.contains("A, B"), "{e}");
        assert!(render("t", "{{A", &v).is_err());
        assert!(render("t", "{{A}}", &v).is_ok());
        let e = render_all("t", "{{A}}", &v).unwrap_err().to_string();
        assert!(e.contains("'B'"), "{e}");
    }
}
