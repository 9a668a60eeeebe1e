//! The FEBio decks' settings (case file section `[febio]`): element type, blood, loads and
//! controls.

use crate::data::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// Element type of the FEBio wall deck.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum FebioElement {
    /// Trilinear brick.
    #[default]
    Hex8,
    /// 20-node serendipity brick: the corners and one node per edge midpoint, the mid-edge nodes
    /// and their labels shared with the CalculiX/Abaqus C3D20 decks; surfaces are
    /// `quad8` facets. `wall.feb` only: `fsi.feb` refuses it.
    Hex20,
}

impl FebioElement {
    pub fn name(self) -> &'static str {
        match self {
            FebioElement::Hex8 => "hex8",
            FebioElement::Hex20 => "hex20",
        }
    }
    /// The facet tag of the element's faces.
    pub fn facet(self) -> &'static str {
        match self {
            FebioElement::Hex8 => "quad4",
            FebioElement::Hex20 => "quad8",
        }
    }
}

/// Blood as FEBio's `fluid-FSI` material.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BloodConstants {
    /// kg/m^3.
    pub density_kg_m3: f64,
    /// Bulk modulus of the (slightly compressible) fluid, Pa.
    pub bulk_modulus_pa: f64,
    /// Newtonian dynamic viscosity, Pa s.
    pub viscosity_pa_s: f64,
}

impl Default for BloodConstants {
    /// Density 1060 kg/m^3 and viscosity 3.5 mPa s (the usual Newtonian blood of large-artery
    /// CFD); bulk modulus 2.2 GPa (water), as in FEBio's fluid-FSI verification problems
    /// (`FORMATS.md` 2b: 1.06e-9 tonne/mm^3, k = 2.2e3 MPa, mu = 3.5e-9 MPa s).
    fn default() -> Self {
        BloodConstants { density_kg_m3: 1060.0, bulk_modulus_pa: 2.2e9, viscosity_pa_s: 3.5e-3 }
    }
}

/// Loads and time stepping of the fluid-FSI deck.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FsiControl {
    /// Mean inlet velocity at the end of the ramp (parabolic profile), m/s.
    pub inlet_mean_velocity_m_s: f64,
    /// Outlet pressure at the end of the ramp, mmHg.
    pub outlet_pressure_mmhg: f64,
    /// Duration of the linear ramp of inflow and outlet pressure, s.
    pub ramp_s: f64,
    /// Time step, s.
    pub step_size_s: f64,
    /// Number of time steps.
    pub time_steps: usize,
    /// Backflow stabilization coefficient on the outlets.
    pub backflow_beta: f64,
}

impl Default for FsiControl {
    /// 0.1 m/s mean inflow and 100 mmHg at the outlet, ramped over 0.1 s in steps of 1 ms; the
    /// run covers the ramp (100 steps). The verified example ran 5 such steps.
    fn default() -> Self {
        FsiControl {
            inlet_mean_velocity_m_s: 0.1,
            outlet_pressure_mmhg: 100.0,
            ramp_s: 0.1,
            step_size_s: 1e-3,
            time_steps: 100,
            backflow_beta: 1.0,
        }
    }
}

/// The `[febio]` section of the case file: element type, loads and controls. The wall's layer
/// constants are the shared `[material]` ([`super::material::WallMaterial`]), the same as the
/// CalculiX and Abaqus decks'.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FebioConfig {
    /// Element of `wall.feb`: `hex8` (default) or `hex20`.
    pub element: FebioElement,
    /// Lumen pressure at the end of the static ramp of `wall.feb`, mmHg.
    pub lumen_pressure_mmhg: f64,
    /// Steps of the static ramp of `wall.feb` (the load reaches its value at t = 1).
    pub static_steps: usize,
    pub blood: BloodConstants,
    pub fsi: FsiControl,
}

impl Default for FebioConfig {
    fn default() -> Self {
        FebioConfig {
            element: FebioElement::Hex8,
            lumen_pressure_mmhg: 100.0,
            static_steps: 10,
            blood: BloodConstants::default(),
            fsi: FsiControl::default(),
        }
    }
}

impl FebioConfig {
    /// Checks ranges; a bad value is named with its key.
    pub fn validate(&self) -> Result<()> {
        let bad = |key: &str, why: &str| Err(Error::Config(format!("febio.{key}: {why}")));
        let positive = |x: f64| x > 0.0 && x.is_finite();
        let non_negative = |x: f64| x >= 0.0 && x.is_finite();
        let b = &self.blood;
        if !positive(b.density_kg_m3) || !positive(b.bulk_modulus_pa) || !positive(b.viscosity_pa_s) {
            return bad("blood", "density, bulk modulus and viscosity must be positive");
        }
        if !self.lumen_pressure_mmhg.is_finite() || self.static_steps == 0 {
            return bad("lumen_pressure_mmhg/static_steps", "need a finite pressure and at least one step");
        }
        let f = &self.fsi;
        if !positive(f.ramp_s) || !positive(f.step_size_s) || f.time_steps == 0 {
            return bad("fsi", "ramp_s and step_size_s must be positive and time_steps at least 1");
        }
        if !f.inlet_mean_velocity_m_s.is_finite()
            || !f.outlet_pressure_mmhg.is_finite()
            || !non_negative(f.backflow_beta)
        {
            return bad("fsi", "inlet velocity and outlet pressure must be finite, backflow_beta not negative");
        }
        Ok(())
    }
}
