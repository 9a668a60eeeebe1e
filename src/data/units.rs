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

/// The consistent system of mechanical units of a solver deck written in a length unit (time in
/// seconds): mm -> N, MPa, tonne; m -> N, Pa, kg; cm -> dyn, Ba, g (CGS); um -> uN, MPa, kg.
/// Every FE writer converts through it, so decks written in the same unit agree.
///
/// Length = 10^a m and mass = 10^b kg; conversions multiply or divide by exact powers of ten, so
/// 1060 kg/m^3 becomes exactly the double nearest 1.06e-9 tonne/mm^3.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MechanicalUnits {
    pub length: LengthUnit,
    length_exp: i32,
    mass_exp: i32,
}

/// x * 10^e, by one correctly rounded operation (10^|e| is exact for |e| <= 22).
fn scale10(x: f64, e: i32) -> f64 {
    if e >= 0 {
        x * 10f64.powi(e)
    } else {
        x / 10f64.powi(-e)
    }
}

impl MechanicalUnits {
    pub fn of(length: LengthUnit) -> Self {
        let (length_exp, mass_exp) = match length {
            LengthUnit::Um => (-6, 0),
            LengthUnit::Mm => (-3, 3),
            LengthUnit::Cm => (-2, -3),
            LengthUnit::M => (0, 0),
        };
        MechanicalUnits { length, length_exp, mass_exp }
    }
    /// A stress (or pressure, or modulus) in Pa, in deck units.
    pub fn stress(&self, pa: f64) -> f64 {
        scale10(pa, self.length_exp - self.mass_exp)
    }
    /// A stress in kPa, in deck units.
    pub fn stress_from_kpa(&self, kpa: f64) -> f64 {
        scale10(kpa, self.length_exp - self.mass_exp + 3)
    }
    /// A stress in MPa, in deck units.
    pub fn stress_from_mpa(&self, mpa: f64) -> f64 {
        scale10(mpa, self.length_exp - self.mass_exp + 6)
    }
    /// A density in kg/m^3, in deck units.
    pub fn density(&self, kg_m3: f64) -> f64 {
        scale10(kg_m3, 3 * self.length_exp - self.mass_exp)
    }
    /// A density in tonne/mm^3, in deck units.
    pub fn density_from_tonne_mm3(&self, t_mm3: f64) -> f64 {
        scale10(t_mm3, 3 * self.length_exp - self.mass_exp + 12)
    }
    /// A dynamic viscosity in Pa s, in deck units.
    pub fn viscosity(&self, pa_s: f64) -> f64 {
        scale10(pa_s, self.length_exp - self.mass_exp)
    }
    /// A velocity in m/s, in deck units.
    pub fn velocity(&self, m_s: f64) -> f64 {
        scale10(m_s, -self.length_exp)
    }
    fn names(&self) -> (&'static str, &'static str, &'static str) {
        match self.length {
            LengthUnit::Um => ("uN", "MPa", "kg"),
            LengthUnit::Mm => ("N", "MPa", "tonne"),
            LengthUnit::Cm => ("dyn", "Ba (0.1 Pa)", "g"),
            LengthUnit::M => ("N", "Pa", "kg"),
        }
    }
    /// "length mm, force N, stress MPa, mass tonne, time s".
    pub fn describe(&self) -> String {
        let (force, stress, mass) = self.names();
        format!("length {}, force {force}, stress {stress}, mass {mass}, time s", self.length)
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

    #[test]
    fn mechanical_units_are_consistent_and_exact() {
        let mm = MechanicalUnits::of(LengthUnit::Mm);
        assert_eq!(mm.density(1060.0), 1.06e-9);
        assert_eq!(mm.stress(2.2e9), 2200.0);
        assert_eq!(mm.stress_from_mpa(0.0133322), 0.0133322);
        assert_eq!(mm.stress_from_kpa(23.632), 0.023632);
        assert_eq!(mm.velocity(0.1), 100.0);
        let cm = MechanicalUnits::of(LengthUnit::Cm);
        assert_eq!(cm.stress(1.0), 10.0); // 1 Pa = 10 dyn/cm^2
        assert_eq!(cm.density(1060.0), 1.06); // g/cm^3
        assert_eq!(cm.viscosity(3.5e-3), 3.5e-2); // poise
        let m = MechanicalUnits::of(LengthUnit::M);
        assert_eq!(m.stress_from_mpa(1.0), 1e6);
        assert_eq!(m.density_from_tonne_mm3(1.2e-9), 1200.0);
        let um = MechanicalUnits::of(LengthUnit::Um);
        assert_eq!(um.stress(1e6), 1.0);
        assert_eq!(um.density_from_tonne_mm3(1.0), 1e-6);
        // force = stress * length^2 in every system: 1 N at 1 Pa over 1 m^2
        for u in [um, mm, cm, m] {
            let l = u.length.in_metres();
            let force_unit = u.stress(1.0).recip() * l * l; // N per deck force unit
            assert!(force_unit > 0.0);
        }
    }
}
