//! Turning polydata or STL triangles into a [`TriangleSurface`]: fan polygons, split strips,
//! drop degenerate triangles, keep a per-triangle tag.

use super::polydata::{PolyData, Values};
use super::SurfaceReadReport;
use nalgebra::Point3;

/// Triangles and their tag values, before degenerate ones are removed.
pub(crate) struct Triangles {
    pub vertices: Vec<Point3<f64>>,
    pub triangles: Vec<[usize; 3]>,
    pub tags: Option<(String, Vec<i64>)>,
}

/// Triangles of the polys (fanned) and strips of `pd`; verts and lines are ignored. The tag is the
/// first one-component integer cell array, taken from each triangle's source cell.
pub(crate) fn from_polydata(pd: PolyData, report: &mut SurfaceReadReport) -> Triangles {
    let tag_array = pd
        .cell_data
        .iter()
        .find(|a| a.components == 1 && matches!(a.values, Values::Int(_)))
        .map(|a| (a.name.clone(), a.values.as_int().unwrap_or_default().to_vec()));
    let mut triangles = Vec::with_capacity(pd.polys.len());
    let mut source_cell = Vec::with_capacity(pd.polys.len());
    for (i, poly) in pd.polys.iter().enumerate() {
        if poly.len() > 3 {
            report.polygons_fanned += 1;
        }
        for k in 1..poly.len().saturating_sub(1) {
            triangles.push([poly[0], poly[k], poly[k + 1]]);
            source_cell.push(pd.poly_base() + i);
        }
    }
    for (i, strip) in pd.strips.iter().enumerate() {
        report.strips_converted += 1;
        for k in 0..strip.len().saturating_sub(2) {
            // Every other strip triangle is flipped so all keep the strip's orientation.
            let t = if k % 2 == 0 {
                [strip[k], strip[k + 1], strip[k + 2]]
            } else {
                [strip[k + 1], strip[k], strip[k + 2]]
            };
            triangles.push(t);
            source_cell.push(pd.strip_base() + i);
        }
    }
    let tags = tag_array.map(|(name, values)| (name, source_cell.iter().map(|&c| values[c]).collect()));
    Triangles { vertices: pd.points, triangles, tags }
}

/// Removes triangles that use a vertex twice (they have no area and no normal) and their tags.
pub(crate) fn drop_degenerate(t: &mut Triangles, report: &mut SurfaceReadReport) {
    let keep: Vec<bool> = t.triangles.iter().map(|&[a, b, c]| a != b && b != c && a != c).collect();
    report.degenerate_triangles_dropped += keep.iter().filter(|&&k| !k).count();
    let mut flags = keep.iter();
    t.triangles.retain(|_| *flags.next().unwrap_or(&true));
    if let Some((_, tags)) = &mut t.tags {
        let mut flags = keep.iter();
        tags.retain(|_| *flags.next().unwrap_or(&true));
    }
}
