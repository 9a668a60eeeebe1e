//! The in-memory polydata both VTK readers (XML `.vtp` and legacy `.vtk`) produce, so that the
//! surface and centerline builders are written once, whatever the file format.
//!
//! Errors inside the readers are plain `String`s; `input::mod` attaches the file path.

use nalgebra::Point3;

/// Numbers of one data array: integers stay integers so tags survive exactly.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Values {
    Int(Vec<i64>),
    Float(Vec<f64>),
}

impl Values {
    pub fn len(&self) -> usize {
        match self {
            Values::Int(v) => v.len(),
            Values::Float(v) => v.len(),
        }
    }

    /// Every value as `f64` (integers convert exactly up to 2^53, far beyond any mesh index).
    pub fn to_f64(&self) -> Vec<f64> {
        match self {
            Values::Int(v) => v.iter().map(|&x| x as f64).collect(),
            Values::Float(v) => v.clone(),
        }
    }

    /// Integer values, or `None` for a floating-point array.
    pub fn as_int(&self) -> Option<&[i64]> {
        match self {
            Values::Int(v) => Some(v),
            Values::Float(_) => None,
        }
    }
}

/// A named point or cell array with `components` values per tuple.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct NamedArray {
    pub name: String,
    pub components: usize,
    pub values: Values,
}

/// Cells as point-index lists, stored flat: cell `i` is `connectivity[offsets[i]..offsets[i+1]]`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct CellArray {
    offsets: Vec<usize>,
    connectivity: Vec<usize>,
}

impl Default for CellArray {
    fn default() -> Self {
        CellArray::new()
    }
}

impl CellArray {
    pub fn new() -> Self {
        CellArray { offsets: vec![0], connectivity: Vec::new() }
    }

    /// From VTK XML `offsets` and `connectivity`. VTK files before format 2.0 store one end offset
    /// per cell; newer ones add a leading 0. Both are accepted.
    pub fn from_offsets(offsets: &[i64], connectivity: &[i64], ncells: usize) -> Result<Self, String> {
        let with_zero: Vec<i64> = if offsets.len() == ncells + 1 && offsets.first() == Some(&0) {
            offsets.to_vec()
        } else if offsets.len() == ncells {
            std::iter::once(0).chain(offsets.iter().copied()).collect()
        } else {
            return Err(format!("has {} offsets for {ncells} cells", offsets.len()));
        };
        let mut cells = CellArray::new();
        for pair in with_zero.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            if a < 0 || b < a || b as usize > connectivity.len() {
                return Err(format!(
                    "has cell offsets {a}..{b} outside the connectivity of {} entries",
                    connectivity.len()
                ));
            }
            cells.push(&to_indices(&connectivity[a as usize..b as usize])?);
        }
        Ok(cells)
    }

    /// From the legacy layout `n p0 p1 .. p(n-1)` repeated `ncells` times.
    pub fn from_counted(data: &[i64], ncells: usize) -> Result<Self, String> {
        let mut cells = CellArray::new();
        let mut at = 0usize;
        for cell in 0..ncells {
            let n = *data.get(at).ok_or_else(|| format!("ends before cell {cell}"))?;
            let end = usize::try_from(n)
                .ok()
                .and_then(|n| (at + 1).checked_add(n))
                .filter(|&end| end <= data.len())
                .ok_or_else(|| format!("cell {cell} announces {n} points, more than the list holds"))?;
            cells.push(&to_indices(&data[at + 1..end])?);
            at = end;
        }
        if at != data.len() {
            return Err(format!("has {} numbers but its {ncells} cells use {at}", data.len()));
        }
        Ok(cells)
    }

    pub fn push(&mut self, cell: &[usize]) {
        self.connectivity.extend_from_slice(cell);
        self.offsets.push(self.connectivity.len());
    }

    pub fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    pub fn cell(&self, i: usize) -> &[usize] {
        &self.connectivity[self.offsets[i]..self.offsets[i + 1]]
    }

    pub fn iter(&self) -> impl Iterator<Item = &[usize]> + '_ {
        (0..self.len()).map(move |i| self.cell(i))
    }

    fn max_index(&self) -> Option<usize> {
        self.connectivity.iter().copied().max()
    }
}

fn to_indices(ids: &[i64]) -> Result<Vec<usize>, String> {
    ids.iter().map(|&i| usize::try_from(i).map_err(|_| format!("has a negative point index {i}"))).collect()
}

/// VTK polydata. Cell data run over all cells in VTK's order: verts, lines, polys, strips.
#[derive(Debug, Clone, Default)]
pub(crate) struct PolyData {
    pub points: Vec<Point3<f64>>,
    pub verts: CellArray,
    pub lines: CellArray,
    pub polys: CellArray,
    pub strips: CellArray,
    pub point_data: Vec<NamedArray>,
    pub cell_data: Vec<NamedArray>,
}

impl PolyData {
    pub fn cell_count(&self) -> usize {
        self.verts.len() + self.lines.len() + self.polys.len() + self.strips.len()
    }

    /// Global cell index (for cell data) of the first line, poly and strip.
    pub fn line_base(&self) -> usize {
        self.verts.len()
    }
    pub fn poly_base(&self) -> usize {
        self.verts.len() + self.lines.len()
    }
    pub fn strip_base(&self) -> usize {
        self.poly_base() + self.polys.len()
    }

    pub fn point_array(&self, name: &str) -> Option<&NamedArray> {
        self.point_data.iter().find(|a| a.name == name)
    }

    /// Checks what every consumer relies on: finite coordinates, point indices in range and
    /// array lengths matching the point and cell counts.
    pub fn validate(&self) -> Result<(), String> {
        if let Some(i) = self.points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            let p = self.points[i];
            return Err(format!(
                "point {i} has a non-finite coordinate ({}, {}, {}); repair or re-export the file",
                p.x, p.y, p.z
            ));
        }
        let n = self.points.len();
        for (what, cells) in
            [("verts", &self.verts), ("lines", &self.lines), ("polys", &self.polys), ("strips", &self.strips)]
        {
            if let Some(max) = cells.max_index().filter(|&m| m >= n) {
                return Err(format!("{what} use point index {max} but there are only {n} points"));
            }
        }
        check_lengths("point", &self.point_data, n)?;
        check_lengths("cell", &self.cell_data, self.cell_count())
    }
}

fn check_lengths(kind: &str, arrays: &[NamedArray], tuples: usize) -> Result<(), String> {
    for a in arrays {
        if a.components == 0 || a.values.len() != tuples * a.components {
            return Err(format!(
                "{kind} array '{}' has {} values, expected {tuples} tuples of {} components",
                a.name,
                a.values.len(),
                a.components
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_with_and_without_leading_zero_agree() {
        let conn = [0, 1, 2, 2, 3, 0, 4];
        let a = CellArray::from_offsets(&[3, 7], &conn, 2).unwrap();
        let b = CellArray::from_offsets(&[0, 3, 7], &conn, 2).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.cell(1), &[2, 3, 0, 4]);
        assert!(CellArray::from_offsets(&[3, 9], &conn, 2).is_err());
        assert!(CellArray::from_offsets(&[0], &[], 0).unwrap().len() == 0);
        assert!(CellArray::from_offsets(&[], &[], 0).unwrap().len() == 0);
    }

    #[test]
    fn counted_layout() {
        let c = CellArray::from_counted(&[2, 5, 6, 3, 1, 2, 3], 2).unwrap();
        assert_eq!(c.cell(0), &[5, 6]);
        assert_eq!(c.cell(1), &[1, 2, 3]);
        assert!(CellArray::from_counted(&[4, 1, 2], 1).is_err());
        assert!(CellArray::from_counted(&[-1, 1, 2], 1).is_err());
        assert!(CellArray::from_counted(&[1, 1, 2], 1).is_err());
    }
}
