//! Writing centerlines as VMTK-compatible ASCII VTK XML polydata: one line cell per polyline,
//! point data `MaximumInscribedSphereRadius` (and `ParallelTransportNormals` when every polyline
//! has normals), every integer cell tag (`CenterlineIds`, `GroupIds`...) as cell data.

use crate::data::error::Result;
use crate::io::atomic::write_atomic;
use crate::io::input::Centerlines;
use crate::stages::centerline::extract::{branch_split, Extraction};
use crate::stages::centerline::CenterlineTree;
use std::path::Path;

/// Writes `centerlines` (millimetres) to `path`, lengths multiplied by `scale` (1 for mm).
pub fn write_vtp(centerlines: &Centerlines, scale: f64, path: &Path) -> Result<()> {
    let lines = &centerlines.polylines;
    let points = lines.iter().map(|l| l.points.len()).sum::<usize>();
    let keys: Vec<&String> = lines.first().map(|l| l.cell_tags.keys().collect()).unwrap_or_default();
    write_atomic(path, |w| {
        writeln!(w, r#"<?xml version="1.0"?>"#)?;
        writeln!(w, r#"<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">"#)?;
        writeln!(w, "  <PolyData>")?;
        writeln!(
            w,
            r#"    <Piece NumberOfPoints="{points}" NumberOfVerts="0" NumberOfLines="{}" NumberOfStrips="0" NumberOfPolys="0">"#,
            lines.len()
        )?;
        writeln!(w, r#"      <PointData Scalars="MaximumInscribedSphereRadius">"#)?;
        writeln!(w, r#"        <DataArray type="Float64" Name="MaximumInscribedSphereRadius" format="ascii">"#)?;
        for l in lines {
            for i in 0..l.points.len() {
                let r = l.radii.as_ref().and_then(|r| r.get(i)).copied().unwrap_or(0.0);
                writeln!(w, "          {:e}", r * scale)?;
            }
        }
        writeln!(w, "        </DataArray>")?;
        if lines.iter().all(|l| l.normals.is_some()) {
            writeln!(
                w,
                r#"        <DataArray type="Float64" Name="ParallelTransportNormals" NumberOfComponents="3" format="ascii">"#
            )?;
            for n in lines.iter().flat_map(|l| l.normals.iter().flatten()) {
                writeln!(w, "          {:e} {:e} {:e}", n.x, n.y, n.z)?;
            }
            writeln!(w, "        </DataArray>")?;
        }
        writeln!(w, "      </PointData>\n      <CellData>")?;
        for key in &keys {
            let values: Vec<String> =
                lines.iter().map(|l| l.cell_tags.get(*key).copied().unwrap_or(-1).to_string()).collect();
            writeln!(
                w,
                r#"        <DataArray type="Int64" Name="{key}" format="ascii">{}</DataArray>"#,
                values.join(" ")
            )?;
        }
        writeln!(w, "      </CellData>\n      <Points>")?;
        writeln!(w, r#"        <DataArray type="Float64" Name="Points" NumberOfComponents="3" format="ascii">"#)?;
        for p in lines.iter().flat_map(|l| &l.points) {
            writeln!(w, "          {:e} {:e} {:e}", p.x * scale, p.y * scale, p.z * scale)?;
        }
        writeln!(w, "        </DataArray>\n      </Points>\n      <Lines>")?;
        writeln!(w, r#"        <DataArray type="Int64" Name="connectivity" format="ascii">"#)?;
        let mut offset = 0;
        let mut offsets = vec![];
        for l in lines {
            let ids: Vec<String> = (offset..offset + l.points.len()).map(|i| i.to_string()).collect();
            writeln!(w, "          {}", ids.join(" "))?;
            offset += l.points.len();
            offsets.push(offset.to_string());
        }
        writeln!(w, "        </DataArray>")?;
        writeln!(
            w,
            r#"        <DataArray type="Int64" Name="offsets" format="ascii">{}</DataArray>"#,
            offsets.join(" ")
        )?;
        writeln!(w, "      </Lines>\n    </Piece>\n  </PolyData>\n</VTKFile>")
    })
}

/// Builds the centerline tree of `extraction` (its inlet is the paths' common start) and writes
/// the tree's branch-split variant ([`super::branch_split`]) to `path`, lengths multiplied by
/// `scale`. Returns the tree.
pub fn write_branch_split(extraction: &Extraction, scale: f64, path: &Path) -> Result<CenterlineTree> {
    let start = extraction.centerlines.polylines.first().map(|l| l.points[0]);
    let config =
        crate::data::config::CenterlineConfig { inlet_mm: start.map(|p| p.coords.into()), ..Default::default() };
    let tree = CenterlineTree::build(&extraction.centerlines, &config, None)?;
    write_vtp(&branch_split(&tree, path), scale, path)?;
    Ok(tree)
}
