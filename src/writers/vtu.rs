//! VTK XML unstructured grid (`mesh.vtu`) of lumen and wall for ParaView, written by vtkio.
//!
//! Cell data: `region` (0 lumen, 1 intima, 2 media, 3 adventitia), `branch` (the element's branch
//! index, 0 for an unbranched vessel; names in `report.json`), `scaled_jacobian`,
//! `equiangle_skew`, `e_long`, `e_circ`, `e_rad`, `fibre1`, `fibre2` (zero for lumen cells).
//! Points are Float64 in the output length unit; the mesh's canonical hex order is VTK's.

use super::{write_atomic, WriteOptions};
use crate::error::{Error, Result};
use crate::mesh::VesselMesh;
use nalgebra::Vector3;
use std::path::{Path, PathBuf};
use vtkio::model::{
    Attribute, Attributes, ByteOrder, CellType, Cells, DataArray, DataSet, ElementType, IOBuffer,
    UnstructuredGridPiece, Version, VertexNumbers, Vtk,
};

fn vectors(name: &str, v: impl Iterator<Item = Vector3<f64>>) -> Attribute {
    let data: Vec<f64> = v.flat_map(|x| [x.x, x.y, x.z]).collect();
    Attribute::DataArray(DataArray { name: name.into(), elem: ElementType::Vectors, data: IOBuffer::F64(data) })
}

fn scalars(name: &str, data: IOBuffer) -> Attribute {
    Attribute::DataArray(DataArray {
        name: name.into(),
        elem: ElementType::Scalars { num_comp: 1, lookup_table: None },
        data,
    })
}

pub fn write_vtu(mesh: &VesselMesh, options: &WriteOptions, dir: &Path) -> Result<Vec<PathBuf>> {
    if mesh.branch_of.len() != mesh.hexes.len() {
        return Err(Error::Geometry(format!(
            "VTU writer: {} elements but {} branch indices: the mesh is not annotated",
            mesh.hexes.len(),
            mesh.branch_of.len()
        )));
    }
    let scale = options.length_unit.from_mm();
    let points: Vec<f64> = mesh.nodes.iter().flat_map(|p| [p.x * scale, p.y * scale, p.z * scale]).collect();
    let connectivity: Vec<u64> = mesh.hexes.iter().flat_map(|h| h.iter().map(|&n| n as u64)).collect();
    let offsets: Vec<u64> = (1..=mesh.hexes.len() as u64).map(|i| 8 * i).collect();
    let cell = vec![
        scalars("region", IOBuffer::I32(mesh.regions.iter().map(|r| r.code()).collect())),
        scalars("branch", IOBuffer::I32(mesh.branch_of.iter().map(|&b| b as i32).collect())),
        scalars("scaled_jacobian", IOBuffer::F64(mesh.quality.iter().map(|q| q.scaled_jacobian).collect())),
        scalars("equiangle_skew", IOBuffer::F64(mesh.quality.iter().map(|q| q.equiangle_skew).collect())),
        vectors("e_long", mesh.triads.iter().map(|t| t.e_long)),
        vectors("e_circ", mesh.triads.iter().map(|t| t.e_circ)),
        vectors("e_rad", mesh.triads.iter().map(|t| t.e_rad)),
        vectors("fibre1", mesh.fibres.iter().map(|f| f[0])),
        vectors("fibre2", mesh.fibres.iter().map(|f| f[1])),
    ];
    let vtk = Vtk {
        version: Version::new_xml(1, 0),
        title: String::new(),
        byte_order: ByteOrder::LittleEndian,
        file_path: None,
        data: DataSet::inline(UnstructuredGridPiece {
            points: IOBuffer::F64(points),
            cells: Cells {
                cell_verts: VertexNumbers::XML { connectivity, offsets },
                types: vec![CellType::Hexahedron; mesh.hexes.len()],
            },
            data: Attributes { point: vec![], cell },
        }),
    };
    let name = PathBuf::from("mesh.vtu");
    let path = dir.join(&name);
    let mut buffer = Vec::new();
    vtk.write_xml(&mut buffer).map_err(|e| Error::Geometry(format!("{}: VTU encoding failed: {e}", path.display())))?;
    write_atomic(&path, |w| w.write_all(&buffer))?;
    Ok(vec![name])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::MeshConfig;
    use vtkio::model::DataSet;

    /// The cell arrays read back with vtkio: `branch` is each element's branch on a mesh with
    /// three branches, `region` its region.
    #[test]
    fn branch_and_region_arrays_read_back() {
        let mut c = MeshConfig::default();
        c.lumen.core_elements = 2;
        c.lumen.radial_elements = 2;
        c.lumen.axial_spacing_mm = Some(3.0);
        let mesh = crate::testing::multi_outlet_mesh(&c).unwrap();
        let dir = std::env::temp_dir().join(format!("vesselhex-vtu-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        write_vtu(&mesh, &WriteOptions::default(), &dir).unwrap();
        let vtk = Vtk::import(dir.join("mesh.vtu")).unwrap();
        let DataSet::UnstructuredGrid { pieces, .. } = vtk.data else { panic!("not an unstructured grid") };
        let piece = pieces[0].load_piece_data(None).unwrap();
        let array = |name: &str| -> Vec<i32> {
            let a = piece.data.cell.iter().find_map(|a| match a {
                Attribute::DataArray(d) if d.name == name => Some(d.data.clone()),
                _ => None,
            });
            match a {
                Some(IOBuffer::I32(v)) => v,
                other => panic!("{name}: {other:?}"),
            }
        };
        let branch = array("branch");
        assert_eq!(branch, mesh.branch_of.iter().map(|&b| b as i32).collect::<Vec<_>>());
        assert_eq!(branch.iter().max(), Some(&2));
        assert_eq!(array("region"), mesh.regions.iter().map(|r| r.code()).collect::<Vec<_>>());
        std::fs::remove_dir_all(&dir).ok();
    }
}
