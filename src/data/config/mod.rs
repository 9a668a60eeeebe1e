//! Every meshing parameter, its preset values and the TOML case file that overrides them.
//!
//! Precedence: preset < case file < command line. Lengths marked "relative" are multiples of
//! the local maximal inscribed sphere radius of the centerline; lengths ending in `_mm` are
//! absolute, in the *output* length unit's millimetre equivalent (internally mm).

use crate::data::error::{Error, Result};
use crate::data::region::{Region, WallLayer};
use crate::data::units::LengthUnit;
use indexmap::IndexMap;
use serde::{Deserialize, Serialize};

pub mod fe;
pub mod febio;
pub mod material;

/// Resolution presets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// A few thousand hexes on a short artery: tests and quick looks.
    #[default]
    Coarse,
    /// Everyday simulations.
    Medium,
    /// Thesis quality: fine boundary layer, several elements per wall layer.
    Fine,
}

impl std::str::FromStr for Preset {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "coarse" => Ok(Preset::Coarse),
            "medium" => Ok(Preset::Medium),
            "fine" => Ok(Preset::Fine),
            o => Err(format!("unknown preset '{o}' (use coarse, medium or fine)")),
        }
    }
}

/// How the centerline is resampled and smoothed before frames are built.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct CenterlineConfig {
    /// Resampling step, relative to the median radius.
    pub resample_step: f64,
    /// Passes of Laplacian smoothing of the points (end points fixed). Smoothing removes the
    /// voxel staircase of image-based centerlines, whose kinks would tilt neighbouring
    /// cross-sections against each other until they cross inside the wall. With the default
    /// step, 200 passes smooth over about one radius (standard deviation step * sqrt(passes/2)):
    /// a lumen cannot bend more tightly than that anyway.
    pub smoothing_passes: usize,
    /// Passes of smoothing of the radius (the radius only scales the blocks).
    pub radius_smoothing_passes: usize,
    /// Extra length cut from the inlet end, relative to the local radius (on top of what the
    /// automatic end detection removes).
    pub trim_inlet: f64,
    /// Extra length cut from the outlet end, relative to the local radius.
    pub trim_outlet: f64,
    /// Two junctions whose centres are closer than this many radii (of the upstream junction's
    /// inscribed sphere) are merged into one junction with all their daughters. 1.0 merges the
    /// aortic arch's first two supra-aortic branches (about 0.55 R apart) and keeps the third
    /// (about 2.4 R further) apart; 0 never merges.
    pub junction_merge_radii: f64,
    /// Two daughters whose lumens are still fused where their junction's transitions would end
    /// (each path within the other's inscribed tube past the junction's sphere) share a trunk to
    /// where they part: the junction becomes a cascade of bifurcations. Off, only paths running
    /// side by side (within a quarter radius for a radius) share one. A vessel refused, or short
    /// of a bar, with it off is meshed again with it on, when that changes its tree.
    pub split_fused_daughters: bool,
    /// The inlet of a branching tree, millimetres: the vessel end nearest this point. Without
    /// it: the first point of a single polyline, or the end of largest radius of a tree.
    pub inlet_mm: Option<[f64; 3]>,
    /// Domes of saccular aneurysms, millimetres: a branch that ends within its end radius of one
    /// of these points is a blind branch closed by a dome of hexes (no end face), not an outlet.
    /// Filled from the ends of kind "sac" when the centerlines are computed from the surface.
    pub sacs_mm: Vec<[f64; 3]>,
    /// Where a network's loops were cut open, millimetres: the two branches that end within
    /// twice their end radius of one of these points, one from either side, are one vessel, meshed as
    /// one branch from junction to junction. Filled from the cuts the extraction made when the
    /// centerlines are computed from a surface with loops; given, it joins centerlines that a
    /// file gives cut open.
    pub loop_cuts_mm: Vec<[f64; 3]>,
}

impl Default for CenterlineConfig {
    fn default() -> Self {
        CenterlineConfig {
            resample_step: 0.1,
            smoothing_passes: 200,
            radius_smoothing_passes: 200,
            trim_inlet: 0.0,
            trim_outlet: 0.0,
            junction_merge_radii: 1.0,
            split_fused_daughters: false,
            inlet_mm: None,
            sacs_mm: Vec::new(),
            loop_cuts_mm: Vec::new(),
        }
    }
}

/// The lumen O-grid.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct LumenConfig {
    /// Elements along one side of the core square; the circumference has four times as many.
    pub core_elements: usize,
    /// Half-side of the core square, relative to the local radius.
    pub core_size: f64,
    /// Elements between the core square and the wall (boundary layer direction).
    pub radial_elements: usize,
    /// Ratio of consecutive radial element heights, from the wall inwards (>= 1).
    pub growth_ratio: f64,
    /// Height of the first element at the wall, relative to the ray length from the core to
    /// the wall. When set, it replaces `growth_ratio` (which is then solved for).
    pub first_cell_height: Option<f64>,
    /// Axial element length, relative to the local radius.
    pub axial_spacing: f64,
    /// Axial element length in mm; when set, replaces `axial_spacing`.
    pub axial_spacing_mm: Option<f64>,
    /// Axial element length in a junction's transitions and in the bridges between close
    /// junctions, relative to the local radius; unset, the spacing above. Their sections are
    /// swept between curved folds, so thin ones cross where a plane section would not (see
    /// `crate::pipeline::mesh_vessel`, which, unset, spaces them at the coarse preset's where
    /// junctions were merged or the spacing above was refused).
    pub junction_axial_spacing: Option<f64>,
    /// Distance of the outer block surface (the ray targets) from the centerline, relative to
    /// the local radius. Far targets make rays nearly radial.
    pub ray_reach: f64,
}

impl Default for LumenConfig {
    fn default() -> Self {
        LumenConfig {
            core_elements: 4,
            core_size: 0.45,
            radial_elements: 4,
            growth_ratio: 1.2,
            first_cell_height: None,
            axial_spacing: 0.5,
            axial_spacing_mm: None,
            junction_axial_spacing: None,
            ray_reach: 4.0,
        }
    }
}

/// One wall layer in the case file.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LayerConfig {
    /// Fraction of the wall thickness (the three fractions are normalised to sum to 1).
    pub fraction: f64,
    /// Elements across the layer.
    pub elements: usize,
    /// Collagen fibre angle beta from the circumferential direction, degrees.
    pub fibre_angle_deg: f64,
}

/// The direction the wall grows in from each lumen-surface node.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum WallGrowth {
    /// Along the meshed lumen surface's normal (smoothed): wall elements stay orthogonal and
    /// valid where rays meet a rippled real surface at a grazing angle.
    #[default]
    Normal,
    /// Along the projection ray, as De Santis et al. 2011 do.
    Ray,
}

/// The three-layer wall.
///
/// Defaults and their sources (`../shared/docs/FORMATS.md` section 4):
/// * layer split intima/media/adventitia 0.27/0.36/0.37 of the wall: Holzapfel et al. 2005,
///   Am J Physiol Heart 289:H2048 (human coronary, non-atherosclerotic intimal thickening);
/// * fibre angles: media 29 deg and adventitia 62 deg from Holzapfel, Gasser, Ogden 2000
///   (J Elasticity 61:1-48, rabbit carotid); intima taken equal to the media, as is common when
///   the intima is not characterised separately;
/// * thickness 0.2 of the lumen radius: wall-to-radius ratios of systemic arteries lie around
///   0.1-0.3 (aorta ~2 mm on r ~10 mm, carotid ~0.8 mm on r ~3 mm); set `thickness_mm` or
///   `thickness_ratio` for your vessel.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct WallConfig {
    /// Wall thickness relative to the local radius (tapering wall).
    pub thickness_ratio: f64,
    /// Constant wall thickness in mm; when set, replaces `thickness_ratio`.
    pub thickness_mm: Option<f64>,
    /// Direction of growth: "normal" (default) or "ray".
    pub growth: WallGrowth,
    pub intima: LayerConfig,
    pub media: LayerConfig,
    pub adventitia: LayerConfig,
    /// The segmented outer wall surface (`--wall-surface`; a case file's path is relative to
    /// its folder): the wall then runs from the lumen to it along each node's growth direction,
    /// its thickness as segmented (see [`crate::stages::additions::wall_surfaces`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub surface: Option<std::path::PathBuf>,
    /// Segmented surfaces between the layers, from the inside out (intima|media, then
    /// media|adventitia); they need `surface`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub surfaces: Vec<std::path::PathBuf>,
}

impl Default for WallConfig {
    fn default() -> Self {
        WallConfig {
            thickness_ratio: 0.2,
            thickness_mm: None,
            growth: WallGrowth::Normal,
            intima: LayerConfig { fraction: 0.27, elements: 1, fibre_angle_deg: 29.0 },
            media: LayerConfig { fraction: 0.36, elements: 1, fibre_angle_deg: 29.0 },
            adventitia: LayerConfig { fraction: 0.37, elements: 1, fibre_angle_deg: 62.0 },
            surface: None,
            surfaces: Vec::new(),
        }
    }
}

impl WallConfig {
    /// The layers in radial order with normalised fractions.
    pub fn layers(&self) -> Vec<WallLayer> {
        let total = self.intima.fraction + self.media.fraction + self.adventitia.fraction;
        [(Region::Intima, &self.intima), (Region::Media, &self.media), (Region::Adventitia, &self.adventitia)]
            .into_iter()
            .map(|(region, l)| WallLayer {
                region,
                thickness_fraction: l.fraction / total,
                radial_elements: l.elements,
                fibre_angle_deg: l.fibre_angle_deg,
            })
            .collect()
    }
}

/// The shape of a flow extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum ExtensionShape {
    /// The end's own section blended over `blend_length` into a circle of the end's mean
    /// (area-equivalent) radius, then a cylinder: the inlet and outlets are circular.
    #[default]
    Cylinder,
    /// The end's own section, unchanged all along.
    Section,
}

/// The vessel ends a flow extension is added to: `"all"`, or a list of end names.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ExtendedEnds {
    /// `"all"` (or `"none"`).
    Keyword(String),
    /// End names as in the mesh: `inlet`, `outlet`, `outlet_1`, ...
    Names(Vec<String>),
}

impl Default for ExtendedEnds {
    fn default() -> Self {
        ExtendedEnds::Names(Vec::new())
    }
}

/// Flow extensions (section `[extensions]`, see [`crate::stages::additions::extensions`]): every chosen vessel end
/// is extended along its axis so that the flow develops before it leaves and the inlet and
/// outlets are circular; the extensions' fluid is region `extension`, without a wall.
///
/// Defaults: 5 radii at the inlet and 10 at the outlets. vesselhex's inflow is already
/// developed (parabolic), so the inlet's extension only has to carry it onto the vessel's own
/// section; at an outlet the extension keeps the zero-gradient outflow condition away from the
/// disturbed flow leaving a bend, a bulge or a junction, which settles over about 0.05 Re
/// diameters (Re = 100-200 at the default inflow: 10-20 radii).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExtensionsConfig {
    /// `"all"`, or the names of the ends to extend; none by default.
    pub ends: ExtendedEnds,
    /// Length of the inlet's extension, relative to the end's mean radius.
    pub inlet_length: f64,
    /// Length of each outlet's extension, relative to the end's mean radius.
    pub outlet_length: f64,
    /// Per-end lengths (relative), overriding the two above: `[extensions.length] outlet_2 = 8`.
    pub length: indexmap::IndexMap<String, f64>,
    pub shape: ExtensionShape,
    /// Length over which the end's section blends into the circle, relative to the mean radius.
    pub blend_length: f64,
    /// Whether the FE decks holding fluid (FEBio's fluid-FSI deck) take the extensions too, as
    /// rigid-walled fluid; by default they model the vessel alone.
    pub fe_decks: bool,
}

impl Default for ExtensionsConfig {
    fn default() -> Self {
        ExtensionsConfig {
            ends: ExtendedEnds::default(),
            inlet_length: 5.0,
            outlet_length: 10.0,
            length: indexmap::IndexMap::new(),
            shape: ExtensionShape::Cylinder,
            blend_length: 2.0,
            fe_decks: false,
        }
    }
}

/// Longest flow extension, in radii.
const MAX_EXTENSION_RADII: f64 = 1000.0;

impl ExtensionsConfig {
    /// Whether any end is extended.
    pub fn is_on(&self) -> bool {
        match &self.ends {
            ExtendedEnds::Keyword(k) => k == "all",
            ExtendedEnds::Names(n) => !n.is_empty(),
        }
    }
    /// Whether the section is left out of report.json's configuration (as it is by default).
    fn is_default(&self) -> bool {
        *self == ExtensionsConfig::default()
    }
    /// Whether the end named `end` is extended.
    pub fn extends(&self, end: &str) -> bool {
        match &self.ends {
            ExtendedEnds::Keyword(k) => k == "all",
            ExtendedEnds::Names(n) => n.iter().any(|x| x == end),
        }
    }
    /// The length of an end's extension, relative to its radius.
    pub fn length_of(&self, end: &str, is_inlet: bool) -> f64 {
        self.length.get(end).copied().unwrap_or(if is_inlet { self.inlet_length } else { self.outlet_length })
    }
    pub fn validate(&self) -> Result<()> {
        let bad = |key: &str, why: String| Err(Error::Config(format!("extensions.{key}: {why}")));
        if let ExtendedEnds::Keyword(k) = &self.ends {
            if k != "all" && k != "none" {
                return bad("ends", format!("\"{k}\" is neither \"all\", \"none\" nor a list of end names"));
            }
        }
        let lengths =
            [("inlet_length".to_string(), self.inlet_length), ("outlet_length".to_string(), self.outlet_length)]
                .into_iter()
                .chain(self.length.iter().map(|(end, l)| (format!("length.{end}"), *l)));
        for (key, l) in lengths {
            if !(l > 0.0 && l <= MAX_EXTENSION_RADII) {
                return bad(
                    &key,
                    format!("{l} must be between 0 and {MAX_EXTENSION_RADII} (relative to the end's radius)"),
                );
            }
            if self.shape == ExtensionShape::Cylinder && self.blend_length > l {
                return bad(
                    "blend_length",
                    format!("{} is longer than {key} = {l}: the section would not reach the circle", self.blend_length),
                );
            }
        }
        if !(0.0..=MAX_EXTENSION_RADII).contains(&self.blend_length) {
            return bad(
                "blend_length",
                format!("must be between 0 and {MAX_EXTENSION_RADII} (relative to the radius)"),
            );
        }
        Ok(())
    }
}

/// Refinement of the whole mesh (section `[refinement]`, see [`crate::stages::additions::refinement`]): every hex
/// split k-fold in each direction, before projection (every new lumen-surface node cast onto the
/// triangles: the mesh follows the triangles, facets and all) or after it (new nodes on a smooth
/// surface through the projected ones: the smooth shape is kept with few projected points). De
/// Santis et al. 2011, Appendix A.2.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RefinementConfig {
    /// Splits per direction before projection (1: none).
    pub before_projection: usize,
    /// Splits per direction after projection (1: none).
    pub after_projection: usize,
}

impl Default for RefinementConfig {
    fn default() -> Self {
        RefinementConfig { before_projection: 1, after_projection: 1 }
    }
}

/// Most splits per direction, both refinements together (each multiplies the elements by k^3).
const MAX_REFINEMENT: usize = 8;

impl RefinementConfig {
    fn is_default(&self) -> bool {
        *self == RefinementConfig::default()
    }
    pub fn validate(&self) -> Result<()> {
        for (key, k) in [("before_projection", self.before_projection), ("after_projection", self.after_projection)] {
            if !(1..=MAX_REFINEMENT).contains(&k) {
                return Err(Error::Config(format!(
                    "refinement.{key}: {k} must be between 1 (no refinement) and {MAX_REFINEMENT}"
                )));
            }
        }
        let total = self.before_projection * self.after_projection;
        if total > MAX_REFINEMENT {
            return Err(Error::Config(format!(
                "refinement.after_projection: {} x {} = {total} splits per direction (elements x {}); at most \
                 {MAX_REFINEMENT} together",
                self.before_projection,
                self.after_projection,
                total.pow(3)
            )));
        }
        Ok(())
    }
}

/// Inlet velocity profile of the OpenFOAM case.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum InletProfile {
    /// Developed (Poiseuille-like) profile, zero at the wall, precomputed per inlet face.
    #[default]
    Parabolic,
    /// Uniform velocity over the inlet.
    Plug,
}

/// Flow solver the OpenFOAM case is set up for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum FoamSolver {
    /// Steady laminar SIMPLEC (`simpleFoam`).
    #[default]
    #[serde(rename = "simpleFoam")]
    SimpleFoam,
    /// Transient laminar PIMPLE (`pimpleFoam`), adaptive time step.
    #[serde(rename = "pimpleFoam")]
    PimpleFoam,
}

/// The OpenFOAM case written with the `openfoam` format (section `[openfoam]` of the case file).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct OpenFoamConfig {
    /// Mean inlet velocity, m/s.
    pub mean_velocity: f64,
    /// Inlet volume flow rate, mL/s; when set, replaces `mean_velocity`. A vessel fed through
    /// several inlets: their flow together, shared by area among the inlets not in
    /// `inlet_flow_rates_ml_s`.
    pub flow_rate_ml_s: Option<f64>,
    /// Flow rate of each inlet named (mL/s), as report.json names the ends (`inlet_1 = 2.5`).
    pub inlet_flow_rates_ml_s: IndexMap<String, f64>,
    pub profile: InletProfile,
    pub solver: FoamSolver,
    /// Kinematic viscosity, m2/s (Newtonian blood: 3.5e-6).
    pub nu: f64,
    /// simpleFoam: maximum iterations (the run stops earlier on the residual criteria).
    pub iterations: usize,
    /// pimpleFoam: simulated time, s; by default two lumen volumes flow through.
    pub end_time: Option<f64>,
    /// Binary polyMesh files instead of ASCII (`--foam-format binary`).
    pub binary: bool,
}

impl Default for OpenFoamConfig {
    fn default() -> Self {
        OpenFoamConfig {
            mean_velocity: 0.1,
            flow_rate_ml_s: None,
            inlet_flow_rates_ml_s: IndexMap::new(),
            profile: InletProfile::Parabolic,
            solver: FoamSolver::SimpleFoam,
            nu: 3.5e-6,
            iterations: 2000,
            end_time: None,
            binary: false,
        }
    }
}

impl OpenFoamConfig {
    pub fn validate(&self) -> Result<()> {
        let bad = |key: &str, why: &str| Err(Error::Config(format!("openfoam.{key}: {why}")));
        if !(self.mean_velocity > 0.0 && self.mean_velocity.is_finite()) {
            return bad("mean_velocity", "must be a positive velocity in m/s");
        }
        if let Some(q) = self.flow_rate_ml_s {
            if !(q > 0.0 && q.is_finite()) {
                return bad("flow_rate_ml_s", "must be a positive flow rate in mL/s");
            }
        }
        if let Some((name, _)) = self.inlet_flow_rates_ml_s.iter().find(|(_, q)| !(**q > 0.0 && q.is_finite())) {
            return bad(&format!("inlet_flow_rates_ml_s.{name}"), "must be a positive flow rate in mL/s");
        }
        if !(self.nu > 0.0 && self.nu.is_finite()) {
            return bad("nu", "must be a positive kinematic viscosity in m2/s");
        }
        if !(1..=10_000_000).contains(&self.iterations) {
            return bad("iterations", "must be between 1 and 10000000");
        }
        if let Some(t) = self.end_time {
            if !(t > 0.0 && t.is_finite()) {
                return bad("end_time", "must be a positive time in s");
            }
        }
        Ok(())
    }
}

/// Everything `vesselhex mesh` needs besides the input files.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct MeshConfig {
    pub preset: Preset,
    /// Length unit of the input files.
    pub units: LengthUnit,
    /// Length unit of the written meshes (OpenFOAM is always in metres).
    pub output_units: LengthUnit,
    /// Output formats, e.g. ["vtu"].
    pub formats: Vec<String>,
    pub centerline: CenterlineConfig,
    pub lumen: LumenConfig,
    pub wall: WallConfig,
    /// The OpenFOAM case (`openfoam` format): inflow, profile, solver, file format.
    #[serde(default)]
    pub openfoam: OpenFoamConfig,
    /// FEBio materials, loads and controls.
    #[serde(default)]
    pub febio: febio::FebioConfig,
    /// Abaqus and CalculiX decks (`[fe]`).
    #[serde(default)]
    pub fe: fe::FeConfig,
    /// Per-layer wall constants of every FE deck (`[material]`).
    #[serde(default)]
    pub material: material::WallMaterial,
    /// Flow extensions at the vessel's ends (`[extensions]`; none by default).
    #[serde(default, skip_serializing_if = "ExtensionsConfig::is_default")]
    pub extensions: ExtensionsConfig,
    /// Refinement before or after projection (`[refinement]`; none by default).
    #[serde(default, skip_serializing_if = "RefinementConfig::is_default")]
    pub refinement: RefinementConfig,
}

impl Default for MeshConfig {
    fn default() -> Self {
        MeshConfig::preset(Preset::Coarse)
    }
}

impl MeshConfig {
    /// The parameters of a preset.
    pub fn preset(preset: Preset) -> Self {
        let mut c = MeshConfig {
            preset,
            units: LengthUnit::Mm,
            output_units: LengthUnit::Mm,
            formats: vec!["vtu".into()],
            centerline: CenterlineConfig::default(),
            lumen: LumenConfig::default(),
            wall: WallConfig::default(),
            openfoam: OpenFoamConfig::default(),
            febio: Default::default(),
            fe: Default::default(),
            material: Default::default(),
            extensions: Default::default(),
            refinement: Default::default(),
        };
        match preset {
            Preset::Coarse => {}
            Preset::Medium => {
                c.lumen.core_elements = 6;
                c.lumen.radial_elements = 7;
                c.lumen.growth_ratio = 1.15;
                c.lumen.axial_spacing = 0.3;
                c.wall.media.elements = 2;
            }
            Preset::Fine => {
                c.lumen.core_elements = 10;
                c.lumen.radial_elements = 12;
                c.lumen.growth_ratio = 1.12;
                c.lumen.axial_spacing = 0.18;
                c.wall.intima.elements = 2;
                c.wall.media.elements = 3;
                c.wall.adventitia.elements = 2;
            }
        }
        c
    }

    /// Checks ranges; a bad value is named with its key and the accepted range.
    pub fn validate(&self) -> Result<()> {
        let l = &self.lumen;
        let bad = |key: &str, why: &str| Err(Error::Config(format!("{key}: {why}")));
        if !(1..=200).contains(&l.core_elements) {
            return bad("lumen.core_elements", "must be between 1 and 200");
        }
        if !(l.core_size > 0.05 && l.core_size < 0.7) {
            return bad("lumen.core_size", "must be between 0.05 and 0.7 (relative to the radius)");
        }
        if !(1..=200).contains(&l.radial_elements) {
            return bad("lumen.radial_elements", "must be between 1 and 200");
        }
        if !(l.growth_ratio >= 1.0 && l.growth_ratio <= 3.0) {
            return bad("lumen.growth_ratio", "must be between 1 and 3");
        }
        if let Some(h) = l.first_cell_height {
            if !(h > 0.0 && h <= 1.0 / l.radial_elements as f64) {
                return bad(
                    "lumen.first_cell_height",
                    "must be positive and at most 1/radial_elements (relative to the core-to-wall ray length)",
                );
            }
        }
        if !(l.axial_spacing >= MIN_AXIAL_SPACING && l.axial_spacing <= 10.0) {
            return bad("lumen.axial_spacing", "must be between 0.001 and 10 (relative to the radius)");
        }
        if l.junction_axial_spacing.is_some_and(|h| !(MIN_AXIAL_SPACING..=10.0).contains(&h)) {
            return bad("lumen.junction_axial_spacing", "must be between 0.001 and 10 (relative to the radius)");
        }
        if let Some(h) = l.axial_spacing_mm {
            if !(h > 0.0 && h <= MAX_LENGTH_MM) {
                return bad("lumen.axial_spacing_mm", "must be a positive length of at most 1e6 mm");
            }
        }
        if !(l.ray_reach >= 1.5 && l.ray_reach <= 50.0) {
            return bad("lumen.ray_reach", "must be between 1.5 and 50 (relative to the radius)");
        }
        let w = &self.wall;
        if !(w.thickness_ratio >= MIN_THICKNESS_RATIO && w.thickness_ratio <= 2.0) {
            return bad("wall.thickness_ratio", "must be between 0.001 and 2 (relative to the radius)");
        }
        if let Some(t) = w.thickness_mm {
            if !(t > 0.0 && t <= MAX_LENGTH_MM) {
                return bad("wall.thickness_mm", "must be a positive length of at most 1e6 mm");
            }
        }
        let total = w.intima.fraction + w.media.fraction + w.adventitia.fraction;
        for (name, layer) in [("intima", &w.intima), ("media", &w.media), ("adventitia", &w.adventitia)] {
            if !(layer.fraction > 0.0 && layer.fraction <= 1e6) {
                return bad(&format!("wall.{name}.fraction"), "must be positive (and at most 1e6)");
            }
            if layer.fraction < MIN_LAYER_SHARE * total {
                return bad(
                    &format!("wall.{name}.fraction"),
                    &format!(
                        "{} is {:.2e} of the wall once the fractions are normalised (they sum to {total}); a layer \
                         needs at least 1 % of the wall to be meshed",
                        layer.fraction,
                        layer.fraction / total
                    ),
                );
            }
            if !(1..=50).contains(&layer.elements) {
                return bad(&format!("wall.{name}.elements"), "must be between 1 and 50");
            }
            if !(0.0..=90.0).contains(&layer.fibre_angle_deg) {
                return bad(&format!("wall.{name}.fibre_angle_deg"), "must be between 0 and 90 degrees");
            }
        }
        self.openfoam.validate()?;
        let c = &self.centerline;
        if !(c.resample_step > 0.005 && c.resample_step <= 1.0) {
            return bad("centerline.resample_step", "must be between 0.005 and 1 (relative to the radius)");
        }
        for (key, passes) in [
            ("centerline.smoothing_passes", c.smoothing_passes),
            ("centerline.radius_smoothing_passes", c.radius_smoothing_passes),
        ] {
            if passes > MAX_SMOOTHING_PASSES {
                return bad(key, "must be at most 100000 (200 smooth over about a radius)");
            }
        }
        for (key, trim) in [("centerline.trim_inlet", c.trim_inlet), ("centerline.trim_outlet", c.trim_outlet)] {
            if !(0.0..=1000.0).contains(&trim) {
                return bad(key, "must be between 0 and 1000 (relative to the radius)");
            }
        }
        if !(0.0..=10.0).contains(&c.junction_merge_radii) {
            return bad("centerline.junction_merge_radii", "must be between 0 and 10 (relative to the radius)");
        }
        if c.inlet_mm.is_some_and(|p| !p.iter().all(|x| x.is_finite())) {
            return bad("centerline.inlet_mm", "must be a point [x, y, z] of finite numbers (mm)");
        }
        if c.sacs_mm.iter().any(|p| !p.iter().all(|x| x.is_finite())) {
            return bad("centerline.sacs_mm", "must be a list of points [x, y, z] of finite numbers (mm)");
        }
        if c.loop_cuts_mm.iter().any(|p| !p.iter().all(|x| x.is_finite())) {
            return bad("centerline.loop_cuts_mm", "must be a list of points [x, y, z] of finite numbers (mm)");
        }
        self.febio.validate()?;
        if self.febio.static_steps > MAX_STEPS {
            return bad("febio.static_steps", "must be at most 100000");
        }
        if self.febio.fsi.time_steps > MAX_STEPS {
            return bad("febio.fsi.time_steps", "must be at most 100000");
        }
        for (key, p) in
            [("fe.pressure_mmhg", self.fe.pressure_mmhg), ("febio.lumen_pressure_mmhg", self.febio.lumen_pressure_mmhg)]
        {
            if !(-MAX_PRESSURE_MMHG..=MAX_PRESSURE_MMHG).contains(&p) {
                return bad(key, "must be a pressure between -10000 and 10000 mmHg");
            }
        }
        self.material.validate()?;
        self.extensions.validate()?;
        self.refinement.validate()?;
        // That they need the outer wall's surface is checked when the run starts
        // (finishing::check_wall_surfaces): --wall-surface comes after the case file.
        if !w.surfaces.is_empty() && w.surfaces.len() != 2 {
            return bad(
                "wall.surfaces",
                "must list the two surfaces between the layers, inside out: intima|media, then media|adventitia",
            );
        }
        self.check_format_settings()
    }

    /// Settings that a requested format cannot write, found before any meshing (the writers
    /// check them again when called directly): hex20 in `febio-fsi`, a quadratic CalculiX element
    /// in `fsi`, a fibre dispersion in the CalculiX decks (`calculix`, `fsi`).
    fn check_format_settings(&self) -> Result<()> {
        let wants = |f: &str| self.formats.iter().any(|x| x == f);
        if wants("febio-fsi") && self.febio.element == febio::FebioElement::Hex20 {
            return Err(Error::Config(
                "febio.element = \"hex20\" with format febio-fsi: the fluid-FSI deck is hex8 only (lumen and wall share \
                 every interface node); write febio-fsi in a run with element = \"hex8\""
                    .into(),
            ));
        }
        if wants("fsi") && self.fe.calculix_element.is_quadratic() {
            return Err(Error::Config(format!(
                "fe.calculix_element = {} with format fsi: the FSI package couples bilinear faces only; use C3D8I, C3D8 \
                 or C3D8R",
                self.fe.calculix_element.name()
            )));
        }
        if (wants("calculix") || wants("fsi")) && self.fe.material == fe::MaterialModel::Hgo {
            for region in Region::WALL {
                let kappa = self.material.layer(region).kappa;
                if kappa != 0.0 {
                    return Err(Error::Config(format!(
                        "material.{}.kappa = {kappa}: CalculiX's fibre material has no dispersion; set kappa = 0 or \
                         leave out the calculix and fsi formats",
                        region.name()
                    )));
                }
            }
        }
        Ok(())
    }
}

/// Largest length setting in mm (a kilometre).
const MAX_LENGTH_MM: f64 = 1e6;
/// Thinnest wall relative to the radius, and the least share of it a layer may have: thinner
/// gives elements flatter than a thousandth, whose Jacobians round to zero.
const MIN_THICKNESS_RATIO: f64 = 0.001;
const MIN_LAYER_SHARE: f64 = 0.01;

/// The least axial spacing, relative to the radius (and, for `axial_spacing_mm`, to the median
/// radius): a thousandth. Fine meshes go well below a hundredth (C0092 at 10 M hexes, the scale
/// benchmark of issue 22: 0.0045); what such a mesh would cost is bounded by the memory estimate
/// before meshing, not here.
pub const MIN_AXIAL_SPACING: f64 = 0.001;
/// Most smoothing passes (each costs a pass over the samples; 200 smooth over about a radius).
const MAX_SMOOTHING_PASSES: usize = 100_000;
/// Most steps of a solver deck.
const MAX_STEPS: usize = 100_000;
const MAX_PRESSURE_MMHG: f64 = 1e4;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_validate_and_grow() {
        let sizes: Vec<usize> = [Preset::Coarse, Preset::Medium, Preset::Fine]
            .iter()
            .map(|p| {
                let c = MeshConfig::preset(*p);
                c.validate().unwrap();
                c.lumen.core_elements * c.lumen.radial_elements
            })
            .collect();
        assert!(sizes[0] < sizes[1] && sizes[1] < sizes[2]);
    }

    /// The scale benchmark's 10 M-hex case steps 0.0045 radii along the vessel: a fine mesh,
    /// not a mistake; a step below a thousandth of the radius is refused.
    #[test]
    fn fine_axial_spacings_are_accepted_down_to_a_thousandth_of_the_radius() {
        let mut c = MeshConfig::preset(Preset::Medium);
        c.lumen.axial_spacing = 0.0045;
        c.validate().unwrap();
        c.lumen.axial_spacing = 0.0009;
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("lumen.axial_spacing"), "{e}");
        // The junctions' own spacing has the same range, and its refusal names it.
        c.lumen.axial_spacing = 0.3;
        for bad in [0.0009, 0.0, 11.0, f64::NAN] {
            c.lumen.junction_axial_spacing = Some(bad);
            let e = c.validate().unwrap_err().to_string();
            assert!(e.contains("lumen.junction_axial_spacing"), "{bad}: {e}");
        }
        c.lumen.junction_axial_spacing = Some(0.5);
        c.validate().unwrap();
    }

    #[test]
    fn layer_fractions_are_normalised() {
        let l = WallConfig::default().layers();
        let s: f64 = l.iter().map(|l| l.thickness_fraction).sum();
        assert!((s - 1.0).abs() < 1e-12);
        assert_eq!(l[0].region, Region::Intima);
    }
}
