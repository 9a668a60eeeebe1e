//! What vesselhex tells the user besides the mesh: warnings (notes on a result that was still
//! written) and the numbers and sizes their messages show. A leaf: it imports nothing of the
//! crate, so every layer may report through it.

use serde::Serialize;

/// A note on a result that was still written (the `warnings` of report.json).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Warning {
    /// What kind of note, stable for scripts: `quality_bar`, `surface_repaired`, `units`, ...
    pub kind: &'static str,
    /// One line naming the figure, the place and, where there is one, the fix.
    pub message: String,
}

impl Warning {
    pub fn new(kind: &'static str, message: impl Into<String>) -> Warning {
        Warning { kind, message: message.into() }
    }
}

/// A size for messages: "1.5 GiB".
pub fn show_bytes(bytes: f64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut x = bytes;
    let mut u = 0;
    while x >= 1024.0 && u + 1 < units.len() {
        x /= 1024.0;
        u += 1;
    }
    if x.is_finite() {
        format!("{x:.1} {}", units[u])
    } else {
        "more than any machine has".into()
    }
}

/// A number for messages: four significant digits, in exponent form when very small or large.
pub fn short(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 || (1e-3..1e6).contains(&a) {
        let digits = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
        let text = format!("{x:.digits$}");
        let text = if text.contains('.') { text.trim_end_matches('0').trim_end_matches('.').to_string() } else { text };
        text
    } else {
        format!("{x:.3e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_numbers_keep_four_digits() {
        assert_eq!(short(10.0), "10");
        assert_eq!(short(1.4589e-3), "0.001459");
        assert_eq!(short(12345.678), "12346");
        assert_eq!(short(1e-9), "1.000e-9");
        assert_eq!(short(-2.5), "-2.5");
        assert_eq!(short(0.0), "0");
    }
}
