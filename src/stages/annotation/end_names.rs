//! The names of a mesh's vessel ends. The volume names them by role (`inlet`, then `outlet` or
//! `outlet_1`, `outlet_2`, ... in branch order); where the user named an end (a cap given in a
//! file of its own, see [`crate::io::input::read_surface_parts`]), the mesh end there takes that
//! name, with its sets (`lumen_<end>`, `wall_<end>`, `cut_<end>`), so that every writer, which
//! reads names from the mesh alone, follows: OpenFOAM patches, FEBio surfaces, Abaqus and
//! CalculiX sets, the FSI maps' keys. report.json names every end as the mesh does.

use crate::geometry::mesh::{sets, VesselMesh};
use crate::stages::centerline::extract::VesselEnd;

/// A mesh end belongs to the end found on the surface nearest its centre within this many of
/// that end's radii (a dome's mesh stops inside its tip).
const SAME_END_RADII: f64 = 2.0;

/// For each end found on the surface, the index of the mesh end at it, if one is: each mesh
/// end belongs to the found end nearest its centre (within [`SAME_END_RADII`]).
pub fn mesh_ends_at(mesh: &VesselMesh, ends: &[VesselEnd]) -> Vec<Option<usize>> {
    let mut at = vec![None; ends.len()];
    for (m, end) in mesh.ends.iter().enumerate() {
        let gap = |k: usize| (ends[k].centre - end.centre).norm();
        let nearest = (0..ends.len()).min_by(|&a, &b| gap(a).total_cmp(&gap(b)));
        if let Some(k) = nearest.filter(|&k| gap(k) <= SAME_END_RADII * ends[k].radius) {
            at[k].get_or_insert(m);
        }
    }
    at
}

/// Gives each mesh end at a named end (`names`, parallel to `ends`) that name, its sets renamed
/// with it; an end of the volume's holding a name so given (`outlet_2`) takes a free one of the
/// volume's pattern. Returns the names changed (old, new), in mesh order.
pub fn name_mesh_ends(mesh: &mut VesselMesh, ends: &[VesselEnd], names: &[Option<String>]) -> Vec<(String, String)> {
    let n = mesh.ends.len();
    let mut finals: Vec<String> = mesh.ends.iter().map(|e| e.name.clone()).collect();
    let mut named = vec![false; n];
    for (m, name) in mesh_ends_at(mesh, ends).into_iter().zip(names) {
        if let (Some(m), Some(name)) = (m, name) {
            finals[m] = name.clone();
            named[m] = true;
        }
    }
    for m in 0..n {
        if !named[m] && (0..n).any(|o| named[o] && finals[o] == finals[m]) {
            finals[m] = (1..).map(|k| format!("outlet_{k}")).find(|f| !finals.contains(f)).expect("a free name");
        }
    }
    rename_ends(mesh, &finals)
}

/// Gives each mesh end its name in `finals` (parallel to `mesh.ends`), its sets renamed with
/// it. Returns the names changed (old, new), in mesh order.
pub(super) fn rename_ends(mesh: &mut VesselMesh, finals: &[String]) -> Vec<(String, String)> {
    let changed: Vec<(String, String)> =
        mesh.ends.iter().zip(finals).filter(|(e, f)| e.name != **f).map(|(e, f)| (e.name.clone(), f.clone())).collect();
    // In two steps, through names no end has, so that a name may pass from one end to another.
    let parked: Vec<(String, String)> =
        changed.iter().enumerate().map(|(k, (old, _))| (old.clone(), format!("\u{1}renaming_{k}"))).collect();
    rename(mesh, &parked);
    let settled: Vec<(String, String)> =
        parked.iter().zip(&changed).map(|((_, parked), (_, new))| (parked.clone(), new.clone())).collect();
    rename(mesh, &settled);
    changed
}

/// Renames ends and their sets, each (old, new) pair in turn.
fn rename(mesh: &mut VesselMesh, pairs: &[(String, String)]) {
    for (old, new) in pairs {
        for end in mesh.ends.iter_mut().filter(|e| e.name == *old) {
            end.name = new.clone();
        }
        for (from, to) in [
            (sets::lumen_end(old), sets::lumen_end(new)),
            (sets::wall_end(old), sets::wall_end(new)),
            (sets::cut(old), sets::cut(new)),
        ] {
            rename_key(&mut mesh.node_sets, &from, &to);
            rename_key(&mut mesh.face_sets, &from, &to);
        }
    }
}

/// Renames a key of an ordered map in place (its position kept).
fn rename_key<V>(map: &mut indexmap::IndexMap<String, V>, from: &str, to: &str) {
    if let Some(i) = map.get_index_of(from) {
        let (_, value) = map.shift_remove_index(i).expect("the index was just found");
        map.shift_insert(i, to.to_string(), value);
    }
}
