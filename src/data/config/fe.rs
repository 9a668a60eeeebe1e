//! The Abaqus and CalculiX decks' settings (case file section `[fe]`): element types, the
//! material template, the inflation step's pressure.

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Continuum element types.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum ElementType {
    C3D8,
    C3D8H,
    C3D8R,
    C3D8I,
    C3D20,
    C3D20H,
    C3D20R,
    C3D20RH,
}

impl ElementType {
    pub fn name(self) -> &'static str {
        match self {
            ElementType::C3D8 => "C3D8",
            ElementType::C3D8H => "C3D8H",
            ElementType::C3D8R => "C3D8R",
            ElementType::C3D8I => "C3D8I",
            ElementType::C3D20 => "C3D20",
            ElementType::C3D20H => "C3D20H",
            ElementType::C3D20R => "C3D20R",
            ElementType::C3D20RH => "C3D20RH",
        }
    }
    /// 20-node serendipity brick.
    pub fn is_quadratic(self) -> bool {
        matches!(self, ElementType::C3D20 | ElementType::C3D20H | ElementType::C3D20R | ElementType::C3D20RH)
    }
    /// CalculiX has no hybrid elements.
    pub fn in_calculix(self) -> bool {
        !matches!(self, ElementType::C3D8H | ElementType::C3D20H | ElementType::C3D20RH)
    }
}

/// Which material template the decks use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaterialModel {
    /// Holzapfel-Gasser-Ogden with two fibre families at +-beta (Abaqus `*ANISOTROPIC
    /// HYPERELASTIC, HOLZAPFEL`; CalculiX `ELASTIC_FIBER` user material).
    Hgo,
    /// Isotropic linear elastic (`*ELASTIC`), e.g. to compare with Lame's solution.
    LinearElastic,
}

/// Settings of the Abaqus and CalculiX decks (case file section `[fe]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FeConfig {
    /// Element type of the Abaqus deck: C3D8H (default, hybrid for near-incompressible
    /// tissue), C3D8, C3D8R, C3D8I, C3D20, C3D20H, C3D20R or C3D20RH.
    pub abaqus_element: ElementType,
    /// Element type of the CalculiX deck: C3D8I (default), C3D8, C3D8R, C3D20 or C3D20R.
    pub calculix_element: ElementType,
    /// Material template: `hgo` (default) or `linear_elastic`.
    pub material: MaterialModel,
    /// Folder whose `abaqus/` and `calculix/` files replace the built-in templates of the same
    /// name (`material_hgo.inp`, `material_linear_elastic.inp`, `step_inflation.inp`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub template_dir: Option<PathBuf>,
    /// Lumen pressure of the inflation step, mmHg.
    pub pressure_mmhg: f64,
}

impl Default for FeConfig {
    fn default() -> Self {
        FeConfig {
            abaqus_element: ElementType::C3D8H,
            calculix_element: ElementType::C3D8I,
            material: MaterialModel::Hgo,
            template_dir: None,
            pressure_mmhg: 100.0,
        }
    }
}
