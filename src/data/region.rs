//! The regions of a vessel's mesh (lumen, the three wall layers, flow extensions) and a wall
//! layer's make-up: plain data, named by the settings and carried by every element.

use serde::Serialize;

/// What a hexahedron belongs to.
///
/// Elements are ordered by region in this order (the derived order), so each region's elements
/// are contiguous: a flow extension's come last, after the wall, so that the vessel's own nodes
/// and elements keep their numbers whether or not it is extended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, PartialOrd, Ord)]
#[serde(rename_all = "lowercase")]
pub enum Region {
    Lumen = 0,
    Intima = 1,
    Media = 2,
    Adventitia = 3,
    /// Fluid of an artificial flow extension beyond a vessel end (see
    /// [`crate::stages::additions::extensions`]): no wall grows around it.
    Extension = 4,
}

impl Region {
    /// The vessel's own regions (a flow extension is not one of them).
    pub const ALL: [Region; 4] = [Region::Lumen, Region::Intima, Region::Media, Region::Adventitia];
    pub const WALL: [Region; 3] = [Region::Intima, Region::Media, Region::Adventitia];
    pub fn name(self) -> &'static str {
        match self {
            Region::Lumen => "lumen",
            Region::Intima => "intima",
            Region::Media => "media",
            Region::Adventitia => "adventitia",
            Region::Extension => "extension",
        }
    }
    /// The integer written to the `region` cell array.
    pub fn code(self) -> i32 {
        self as i32
    }
    pub fn is_wall(self) -> bool {
        matches!(self, Region::Intima | Region::Media | Region::Adventitia)
    }
}

/// A wall layer as the writers need it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WallLayer {
    pub region: Region,
    /// Fraction of the wall thickness.
    pub thickness_fraction: f64,
    /// Elements across the layer.
    pub radial_elements: usize,
    /// Collagen fibre angle beta from the circumferential direction, degrees.
    pub fibre_angle_deg: f64,
}
