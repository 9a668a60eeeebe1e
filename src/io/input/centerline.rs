//! Turning polydata line cells into [`CenterlinePolyline`]s, with VMTK's point and cell arrays.

use super::polydata::{NamedArray, PolyData};
use super::CenterlinePolyline;
use indexmap::IndexMap;
use nalgebra::Vector3;
use std::collections::BTreeMap;

const RADIUS: &str = "MaximumInscribedSphereRadius";
const NORMALS: &str = "ParallelTransportNormals";

/// One polyline per LINES cell; a file made only of two-node segments sharing points (gmsh's
/// centerlines) is first chained into maximal polylines.
pub(crate) fn from_polydata(pd: &PolyData) -> Result<Vec<CenterlinePolyline>, String> {
    if pd.lines.len() == 0 {
        return Err("has no line cells (LINES): it holds no centerline polylines".into());
    }
    let radii = point_radii(pd)?;
    let normals = point_normals(pd)?;
    let chained = is_segment_soup(pd);
    let cells: Vec<(Vec<usize>, Option<usize>)> = if chained {
        chain_segments(pd.lines.iter()).into_iter().map(|c| (c, None)).collect()
    } else {
        pd.lines.iter().enumerate().map(|(i, c)| (c.to_vec(), Some(pd.line_base() + i))).collect()
    };
    cells
        .into_iter()
        .enumerate()
        .map(|(k, (ids, cell))| {
            if ids.len() < 2 {
                return Err(format!("polyline {k} has {} point; a centerline needs at least 2", ids.len()));
            }
            Ok(CenterlinePolyline {
                points: ids.iter().map(|&i| pd.points[i]).collect(),
                radii: radii.as_ref().map(|r| ids.iter().map(|&i| r[i]).collect()),
                normals: normals.as_ref().map(|n| ids.iter().map(|&i| n[i]).collect()),
                cell_tags: cell.map(|c| cell_tags(pd, c)).unwrap_or_default(),
            })
        })
        .collect()
}

fn single_component<'a>(pd: &'a PolyData, name: &str, comps: usize) -> Result<Option<&'a NamedArray>, String> {
    match pd.point_array(name) {
        Some(a) if a.components != comps => {
            Err(format!("point array '{name}' has {} components, expected {comps}", a.components))
        }
        other => Ok(other),
    }
}

/// The radius array, which must be finite and non-negative where present.
fn point_radii(pd: &PolyData) -> Result<Option<Vec<f64>>, String> {
    let Some(array) = single_component(pd, RADIUS, 1)? else { return Ok(None) };
    let r = array.values.to_f64();
    if let Some(i) = r.iter().position(|v| !v.is_finite() || *v < 0.0) {
        return Err(format!(
            "{RADIUS} of point {i} is {}; radii must be finite and non-negative (recompute the centerlines)",
            r[i]
        ));
    }
    Ok(Some(r))
}

/// The parallel-transport normals, normalised to unit length.
fn point_normals(pd: &PolyData) -> Result<Option<Vec<Vector3<f64>>>, String> {
    let Some(array) = single_component(pd, NORMALS, 3)? else { return Ok(None) };
    array
        .values
        .to_f64()
        .chunks_exact(3)
        .enumerate()
        .map(|(i, c)| {
            Vector3::new(c[0], c[1], c[2])
                .try_normalize(1e-300)
                .filter(|n| n.iter().all(|v| v.is_finite()))
                .ok_or_else(|| format!("{NORMALS} of point {i} is ({}, {}, {}), not a direction", c[0], c[1], c[2]))
        })
        .collect::<Result<_, _>>()
        .map(Some)
}

/// Integer one-component cell arrays of cell `cell`.
fn cell_tags(pd: &PolyData, cell: usize) -> IndexMap<String, i64> {
    pd.cell_data
        .iter()
        .filter(|a| a.components == 1)
        .filter_map(|a| Some((a.name.clone(), *a.values.as_int()?.get(cell)?)))
        .collect()
}

/// True when every line is a two-node segment and some point is shared by two segments.
fn is_segment_soup(pd: &PolyData) -> bool {
    if pd.lines.len() < 2 || pd.lines.iter().any(|c| c.len() != 2) {
        return false;
    }
    let mut seen = std::collections::HashSet::new();
    pd.lines.iter().flatten().any(|&p| !seen.insert(p))
}

/// Chains segments into maximal polylines that stop at points of degree != 2; closed loops are
/// returned with their first point repeated at the end. Deterministic: starts in point-id order.
fn chain_segments<'a>(segments: impl Iterator<Item = &'a [usize]>) -> Vec<Vec<usize>> {
    let edges: Vec<[usize; 2]> = segments.map(|s| [s[0], s[1]]).filter(|[a, b]| a != b).collect();
    let mut incident: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (e, [a, b]) in edges.iter().enumerate() {
        incident.entry(*a).or_default().push(e);
        incident.entry(*b).or_default().push(e);
    }
    let mut used = vec![false; edges.len()];
    let mut chains = Vec::new();
    let ends: Vec<usize> = incident.iter().filter(|(_, es)| es.len() != 2).map(|(&p, _)| p).collect();
    let loops: Vec<usize> = incident.keys().copied().collect();
    for start in ends.into_iter().chain(loops) {
        while let Some(&e) = incident[&start].iter().find(|&&e| !used[e]) {
            chains.push(walk(start, e, &edges, &incident, &mut used));
        }
    }
    chains
}

/// Follows unused edges from `start` through degree-2 points.
fn walk(
    start: usize,
    first: usize,
    edges: &[[usize; 2]],
    incident: &BTreeMap<usize, Vec<usize>>,
    used: &mut [bool],
) -> Vec<usize> {
    let mut chain = vec![start];
    let (mut at, mut edge) = (start, first);
    loop {
        used[edge] = true;
        let [a, b] = edges[edge];
        at = if a == at { b } else { a };
        chain.push(at);
        let next = incident[&at].iter().copied().find(|&e| !used[e]);
        match next {
            Some(e) if incident[&at].len() == 2 => edge = e,
            _ => return chain,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain(segs: &[[usize; 2]]) -> Vec<Vec<usize>> {
        chain_segments(segs.iter().map(|s| &s[..]))
    }

    #[test]
    fn chains_split_at_branch_points() {
        // A Y: 0-1-2 and branch 2-3, 2-4-5, unordered and reversed.
        let c = chain(&[[4, 5], [1, 2], [2, 3], [1, 0], [2, 4]]);
        assert_eq!(c, vec![vec![0, 1, 2], vec![2, 3], vec![2, 4, 5]]);
    }

    #[test]
    fn closed_loop() {
        let c = chain(&[[0, 1], [1, 2], [2, 0]]);
        assert_eq!(c, vec![vec![0, 1, 2, 0]]);
    }
}
