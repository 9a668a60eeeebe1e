//! `mesh.vtu` read back by VTK and by meshio: integer connectivity and offsets (Int64, as VTK
//! writes them: meshio reads the UInt64 of earlier versions as floating point), the mesh's own
//! points, cells and cell arrays, bit for bit. The branched Y fixture at the coarse preset, so
//! that `branch` takes several values.
//!
//! Without Python's `vtk` or `meshio` the tests print "skipped"; with `CI=true` they fail.

mod common;

use std::process::Command;
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::mesh::VesselMesh;
use vesselhex::writers::{vtu::write_vtu, WriteOptions};

/// The Y fixture meshed and written; returns the mesh and the file.
fn written(tag: &str) -> (VesselMesh, std::path::PathBuf) {
    let fixtures = common::fixtures_dir();
    let mesh = common::mesh_files(
        &fixtures.join("y_bifurcation.stl"),
        &fixtures.join("y_bifurcation_centerlines.vtp"),
        &MeshConfig::preset(Preset::Coarse),
    );
    let dir = common::temp_dir(tag);
    write_vtu(&mesh, &WriteOptions::default(), &dir).unwrap();
    (mesh, dir.join("mesh.vtu"))
}

/// Runs a Python script on the file; its standard output is one JSON object.
fn python_json(py: &str, script: &str, file: &std::path::Path) -> serde_json::Value {
    let out = Command::new(py).args(["-c", script, common::path_str(file)]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

fn ints(v: &serde_json::Value, key: &str) -> Vec<i64> {
    v[key].as_array().unwrap_or_else(|| panic!("no {key}")).iter().map(|x| x.as_i64().unwrap()).collect()
}

/// Floats sent as Python's repr (exact; JSON numbers are not read back bit for bit).
fn floats(v: &serde_json::Value, key: &str) -> Vec<f64> {
    let list = v[key].as_array().unwrap_or_else(|| panic!("no {key}"));
    list.iter().map(|x| x.as_str().unwrap().parse().unwrap()).collect()
}

/// Equal lists, or a panic naming the first difference (not the whole lists).
fn assert_same<T: PartialEq + std::fmt::Debug>(read: &[T], ours: &[T], what: &str) {
    assert_eq!(read.len(), ours.len(), "{what}: lengths");
    if let Some(i) = (0..read.len()).find(|&i| read[i] != ours[i]) {
        panic!("{what}: entry {i} read back as {:?}, written {:?}", read[i], ours[i]);
    }
}

/// What both readers must give back: connectivity, offsets, points, region, branch.
fn assert_same_as_mesh(v: &serde_json::Value, mesh: &VesselMesh, reader: &str) {
    let connectivity: Vec<i64> = mesh.hexes.iter().flatten().map(|&n| n as i64).collect();
    assert_same(&ints(v, "connectivity"), &connectivity, &format!("{reader}: connectivity"));
    let points: Vec<f64> = mesh.nodes.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    assert_same(&floats(v, "points"), &points, &format!("{reader}: points"));
    let region: Vec<i64> = mesh.regions.iter().map(|r| r.code() as i64).collect();
    assert_same(&ints(v, "region"), &region, &format!("{reader}: region"));
    let branch: Vec<i64> = mesh.branch_of.iter().map(|&b| b as i64).collect();
    assert_same(&ints(v, "branch"), &branch, &format!("{reader}: branch"));
    assert!(branch.iter().max() > Some(&0), "the Y has several branches");
    let sj: Vec<f64> = mesh.quality.iter().map(|q| q.scaled_jacobian).collect();
    assert_same(&floats(v, "scaled_jacobian"), &sj, &format!("{reader}: scaled_jacobian"));
}

#[test]
fn vtk_reads_int64_connectivity_and_offsets_and_the_mesh_back() {
    let Some(py) = common::python_with("vtkmodules.vtkIOXML") else { return };
    let (mesh, file) = written("vtu-vtk");
    let script = r#"
import sys, json
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader
from vtkmodules.util.numpy_support import vtk_to_numpy
r = vtkXMLUnstructuredGridReader(); r.SetFileName(sys.argv[1]); r.Update()
g = r.GetOutput(); cells = g.GetCells(); data = g.GetCellData()
conn, offs = cells.GetConnectivityArray(), cells.GetOffsetsArray()
print(json.dumps({
    "connectivity_type": conn.GetDataTypeAsString(), "offsets_type": offs.GetDataTypeAsString(),
    "connectivity": vtk_to_numpy(conn).tolist(), "offsets": vtk_to_numpy(offs).tolist(),
    "types": sorted(set(vtk_to_numpy(g.GetCellTypesArray()).tolist())),
    "points": [repr(x) for x in vtk_to_numpy(g.GetPoints().GetData()).ravel().tolist()],
    "region": vtk_to_numpy(data.GetArray("region")).tolist(),
    "branch": vtk_to_numpy(data.GetArray("branch")).tolist(),
    "scaled_jacobian": [repr(x) for x in vtk_to_numpy(data.GetArray("scaled_jacobian")).tolist()],
}))
"#;
    let v = python_json(&py, script, &file);
    // VTK's Int64 arrays: "long long" (vtkTypeInt64Array), or its id type, 64-bit as well.
    for key in ["connectivity_type", "offsets_type"] {
        let t = v[key].as_str().unwrap();
        assert!(["long long", "long", "idtype"].contains(&t), "{key}: {t}");
    }
    let offsets: Vec<i64> = (0..=mesh.hexes.len() as i64).map(|i| 8 * i).collect();
    assert_same(&ints(&v, "offsets"), &offsets, "VTK's offsets (it keeps a leading 0)");
    assert_eq!(ints(&v, "types"), [12], "hexahedra only");
    assert_same_as_mesh(&v, &mesh, "VTK");
}

#[test]
fn meshio_reads_integer_connectivity_and_the_mesh_back() {
    let Some(py) = common::python_with("meshio") else { return };
    let (mesh, file) = written("vtu-meshio");
    let script = r#"
import sys, json, meshio
m = meshio.read(sys.argv[1])
assert len(m.cells) == 1, [c.type for c in m.cells]
c = m.cells[0]
d = {k: v[0] for k, v in m.cell_data.items()}
print(json.dumps({
    "type": c.type, "connectivity_kind": c.data.dtype.kind, "region_kind": d["region"].dtype.kind,
    "connectivity": c.data.ravel().tolist(), "points": [repr(x) for x in m.points.ravel().tolist()],
    "region": d["region"].tolist(), "branch": d["branch"].tolist(),
    "scaled_jacobian": [repr(x) for x in d["scaled_jacobian"].tolist()],
}))
"#;
    let v = python_json(&py, script, &file);
    assert_eq!(v["type"], "hexahedron");
    assert_eq!(v["connectivity_kind"], "i", "meshio reads the connectivity as integers");
    assert_eq!(v["region_kind"], "i");
    assert_same_as_mesh(&v, &mesh, "meshio");
}
