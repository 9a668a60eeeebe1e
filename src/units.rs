//! Length units. Inside vesselhex every length is in millimetres; inputs are converted on reading
//! and each writer converts to its own unit (OpenFOAM: metres; FE decks: the user's choice).

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum LengthUnit {
    Um,
    #[default]
    Mm,
    Cm,
    M,
}

impl LengthUnit {
    /// Size of one unit in metres.
    pub fn in_metres(self) -> f64 {
        match self {
            LengthUnit::Um => 1e-6,
            LengthUnit::Mm => 1e-3,
            LengthUnit::Cm => 1e-2,
            LengthUnit::M => 1.0,
        }
    }
    /// Factor that turns a length in this unit into millimetres (the internal unit).
    pub fn to_mm(self) -> f64 {
        self.in_metres() / 1e-3
    }
    /// Factor that turns an internal length (mm) into this unit.
    pub fn from_mm(self) -> f64 {
        1e-3 / self.in_metres()
    }
    pub fn name(self) -> &'static str {
        match self {
            LengthUnit::Um => "um",
            LengthUnit::Mm => "mm",
            LengthUnit::Cm => "cm",
            LengthUnit::M => "m",
        }
    }
}

impl fmt::Display for LengthUnit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for LengthUnit {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "um" | "micron" | "micrometre" | "micrometer" => Ok(LengthUnit::Um),
            "mm" | "millimetre" | "millimeter" => Ok(LengthUnit::Mm),
            "cm" | "centimetre" | "centimeter" => Ok(LengthUnit::Cm),
            "m" | "metre" | "meter" => Ok(LengthUnit::M),
            other => Err(format!("unknown length unit '{other}' (use um, mm, cm or m)")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn conversions_are_consistent() {
        for u in [LengthUnit::Um, LengthUnit::Mm, LengthUnit::Cm, LengthUnit::M] {
            assert!((u.to_mm() * u.from_mm() - 1.0).abs() < 1e-15);
            assert_eq!(u.name().parse::<LengthUnit>().unwrap(), u);
        }
        assert_eq!(LengthUnit::M.to_mm(), 1000.0);
        assert_eq!(LengthUnit::Cm.to_mm(), 10.0);
    }
}
