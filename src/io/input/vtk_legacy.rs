//! Legacy VTK (`.vtk`) ASCII reader for POLYDATA and UNSTRUCTURED_GRID made of surface or line
//! cells (gmsh writes its centerlines as an unstructured grid of two-node lines).
//!
//! Our own small parser rather than vtkio: it reports the line of a bad token and cannot panic.

use super::polydata::{CellArray, NamedArray, PolyData, Values};
use nalgebra::Point3;

/// Parses a legacy ASCII VTK file into polydata.
pub(crate) fn parse(text: &str) -> Result<PolyData, String> {
    let mut lines = text.lines();
    let first = lines.next().unwrap_or_default();
    if !first.trim_start().starts_with("# vtk DataFile") {
        return Err("does not start with '# vtk DataFile Version': it is not a legacy VTK file".into());
    }
    let _title = lines.next();
    match lines.next().map(|l| l.trim().to_ascii_uppercase()).as_deref() {
        Some("ASCII") => {}
        Some("BINARY") => {
            return Err("is a binary legacy VTK file, which is not supported; save it as ASCII or as .vtp".into())
        }
        _ => return Err("line 3 must be ASCII or BINARY".into()),
    }
    let mut tokens = Tokens::new(text, 3);
    Parser::default().run(&mut tokens)
}

/// Whitespace-separated tokens with their 1-based line numbers; `METADATA` blocks (VTK 9), which
/// end at a blank line, are skipped here.
struct Tokens<'a> {
    items: Vec<(&'a str, usize)>,
    at: usize,
}

impl<'a> Tokens<'a> {
    fn new(text: &'a str, skip_lines: usize) -> Self {
        let mut items = Vec::new();
        let mut in_metadata = false;
        for (i, line) in text.lines().enumerate().skip(skip_lines) {
            let trimmed = line.trim();
            if in_metadata {
                in_metadata = !trimmed.is_empty();
                continue;
            }
            if trimmed.eq_ignore_ascii_case("METADATA") {
                in_metadata = true;
                continue;
            }
            items.extend(trimmed.split_ascii_whitespace().map(|t| (t, i + 1)));
        }
        Tokens { items, at: 0 }
    }

    fn peek(&self) -> Option<&'a str> {
        self.items.get(self.at).map(|t| t.0)
    }

    fn line(&self) -> usize {
        self.items.get(self.at.min(self.items.len().saturating_sub(1))).map_or(0, |t| t.1)
    }

    fn next(&mut self, what: &str) -> Result<&'a str, String> {
        let t =
            self.items.get(self.at).ok_or_else(|| format!("ends early: {what} expected (the file is truncated)"))?;
        self.at += 1;
        Ok(t.0)
    }

    fn number<T: std::str::FromStr>(&mut self, what: &str) -> Result<T, String> {
        let line = self.line();
        let t = self.next(what)?;
        t.parse().map_err(|_| format!("line {line}: '{t}' is not a valid {what}"))
    }

    /// `n` values of a legacy data type (`float`, `double`, `int`, `vtkIdType`, ...).
    fn values(&mut self, n: usize, ty: &str, what: &str) -> Result<Values, String> {
        let ty = ty.to_ascii_lowercase();
        let remaining = self.items.len() - self.at;
        if n > remaining {
            return Err(format!(
                "{what} announces {n} values but only {remaining} numbers follow: the file is truncated"
            ));
        }
        if ty == "float" || ty == "double" {
            (0..n).map(|_| self.number::<f64>(what)).collect::<Result<_, _>>().map(Values::Float)
        } else if ty == "string" || ty == "utf8_string" {
            Err(format!("line {}: {what} has string values, which are not supported", self.line()))
        } else {
            (0..n).map(|_| self.number::<i64>(what)).collect::<Result<_, _>>().map(Values::Int)
        }
    }

    fn ints(&mut self, n: usize, what: &str) -> Result<Vec<i64>, String> {
        match self.values(n, "int", what)? {
            Values::Int(v) => Ok(v),
            Values::Float(_) => unreachable!("integer type requested"),
        }
    }
}

/// Which attribute section the data arrays belong to.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Target {
    None,
    Point(usize),
    Cell(usize),
}

/// Collects sections as they come; unstructured grids are turned into polydata at the end.
struct Parser {
    pd: PolyData,
    unstructured: bool,
    cells: Option<CellArray>,
    cell_types: Option<Vec<i64>>,
    target: Target,
}

impl Default for Parser {
    fn default() -> Self {
        Parser { pd: PolyData::default(), unstructured: false, cells: None, cell_types: None, target: Target::None }
    }
}

impl Parser {
    fn run(mut self, t: &mut Tokens) -> Result<PolyData, String> {
        if !t.next("DATASET")?.eq_ignore_ascii_case("DATASET") {
            return Err(format!("line {}: DATASET expected", t.line()));
        }
        match t.next("dataset type")?.to_ascii_uppercase().as_str() {
            "POLYDATA" => {}
            "UNSTRUCTURED_GRID" => self.unstructured = true,
            other => {
                return Err(format!("is a legacy {other} dataset; only POLYDATA and UNSTRUCTURED_GRID are supported"))
            }
        }
        while let Some(keyword) = t.peek() {
            let line = t.line();
            t.next("keyword")?;
            self.section(&keyword.to_ascii_uppercase(), line, t)?;
        }
        self.finish()
    }

    fn section(&mut self, keyword: &str, line: usize, t: &mut Tokens) -> Result<(), String> {
        match keyword {
            "POINTS" => {
                let n: usize = t.number("point count")?;
                let ty = t.next("point type")?;
                let v = t.values(n.saturating_mul(3), ty, "POINTS")?.to_f64();
                self.pd.points = v.chunks_exact(3).map(|c| Point3::new(c[0], c[1], c[2])).collect();
            }
            "VERTICES" => self.pd.verts = cell_section(t, keyword)?,
            "LINES" => self.pd.lines = cell_section(t, keyword)?,
            "POLYGONS" => self.pd.polys = cell_section(t, keyword)?,
            "TRIANGLE_STRIPS" => self.pd.strips = cell_section(t, keyword)?,
            "CELLS" => self.cells = Some(cell_section(t, keyword)?),
            "CELL_TYPES" => {
                let n: usize = t.number("cell type count")?;
                self.cell_types = Some(t.ints(n, "CELL_TYPES")?);
            }
            "POINT_DATA" => self.target = Target::Point(t.number("point data count")?),
            "CELL_DATA" => self.target = Target::Cell(t.number("cell data count")?),
            "FIELD" => {
                let _name = t.next("field name")?;
                let count: usize = t.number("field array count")?;
                for _ in 0..count {
                    self.field_array(t)?;
                }
            }
            "SCALARS" => {
                let name = t.next("array name")?.to_string();
                let ty = t.next("array type")?;
                let mut comps = 1;
                if t.peek().is_some_and(|s| s.parse::<usize>().is_ok()) {
                    comps = t.number("component count")?;
                }
                if t.peek().is_some_and(|s| s.eq_ignore_ascii_case("LOOKUP_TABLE")) {
                    t.next("LOOKUP_TABLE")?;
                    t.next("lookup table name")?;
                }
                self.attribute(t, name, ty, comps)?;
            }
            "VECTORS" | "NORMALS" | "TENSORS" => {
                let name = t.next("array name")?.to_string();
                let ty = t.next("array type")?;
                self.attribute(t, name, ty, if keyword == "TENSORS" { 9 } else { 3 })?;
            }
            "TEXTURE_COORDINATES" => {
                let name = t.next("array name")?.to_string();
                let comps = t.number("dimension")?;
                let ty = t.next("array type")?;
                self.attribute(t, name, ty, comps)?;
            }
            "COLOR_SCALARS" => {
                let name = t.next("array name")?.to_string();
                let comps = t.number("component count")?;
                self.attribute(t, name, "float", comps)?;
            }
            "LOOKUP_TABLE" => {
                t.next("lookup table name")?;
                let n: usize = t.number("lookup table size")?;
                t.values(n.saturating_mul(4), "float", "LOOKUP_TABLE")?;
            }
            other => return Err(format!("line {line}: unexpected keyword '{other}'")),
        }
        Ok(())
    }

    /// A FIELD array: `name components tuples type` then the values.
    fn field_array(&mut self, t: &mut Tokens) -> Result<(), String> {
        let name = t.next("field array name")?.to_string();
        let comps: usize = t.number("component count")?;
        let tuples: usize = t.number("tuple count")?;
        let ty = t.next("array type")?;
        let values = t.values(comps.saturating_mul(tuples), ty, &name)?;
        self.store(NamedArray { name, components: comps, values });
        Ok(())
    }

    fn attribute(&mut self, t: &mut Tokens, name: String, ty: &str, comps: usize) -> Result<(), String> {
        let tuples = match self.target {
            Target::Point(n) | Target::Cell(n) => n,
            Target::None => return Err(format!("line {}: '{name}' comes before POINT_DATA or CELL_DATA", t.line())),
        };
        let values = t.values(tuples.saturating_mul(comps), ty, &name)?;
        self.store(NamedArray { name, components: comps, values });
        Ok(())
    }

    fn store(&mut self, array: NamedArray) {
        match self.target {
            Target::Point(_) => self.pd.point_data.push(array),
            Target::Cell(_) => self.pd.cell_data.push(array),
            Target::None => {} // dataset-level field data (e.g. TIME): not needed
        }
    }

    fn finish(mut self) -> Result<PolyData, String> {
        if self.unstructured {
            let cells = self.cells.take().unwrap_or_default();
            let types = self.cell_types.take().unwrap_or_default();
            split_by_type(&mut self.pd, &cells, &types)?;
        }
        self.pd.validate()?;
        Ok(self.pd)
    }
}

/// A cell section: `n size` then either the counted layout or (format 5.x) OFFSETS/CONNECTIVITY.
fn cell_section(t: &mut Tokens, keyword: &str) -> Result<CellArray, String> {
    let n: usize = t.number("cell count")?;
    let size: usize = t.number("cell list size")?;
    let context = |e: String| format!("{keyword} {e}");
    if t.peek().is_some_and(|s| s.eq_ignore_ascii_case("OFFSETS")) {
        t.next("OFFSETS")?;
        t.next("offset type")?;
        let offsets = t.ints(n, "OFFSETS")?;
        if !t.next("CONNECTIVITY")?.eq_ignore_ascii_case("CONNECTIVITY") {
            return Err(format!("line {}: CONNECTIVITY expected", t.line()));
        }
        t.next("connectivity type")?;
        let conn = t.ints(size, "CONNECTIVITY")?;
        CellArray::from_offsets(&offsets, &conn, n.saturating_sub(1)).map_err(context)
    } else {
        let data = t.ints(size, keyword)?;
        CellArray::from_counted(&data, n).map_err(context)
    }
}

/// Sorts unstructured-grid cells into polydata sections (reordering cell data to VTK's
/// verts, lines, polys, strips order). Volume cells are refused.
fn split_by_type(pd: &mut PolyData, cells: &CellArray, types: &[i64]) -> Result<(), String> {
    if types.len() != cells.len() {
        return Err(format!("has {} CELLS but {} CELL_TYPES", cells.len(), types.len()));
    }
    let mut order: [Vec<usize>; 4] = Default::default();
    for (i, (&ty, cell)) in types.iter().zip(cells.iter()).enumerate() {
        let (section, target) = match ty {
            1 | 2 => (0, &mut pd.verts),
            3 | 4 => (1, &mut pd.lines),
            5 | 7 | 9 => (2, &mut pd.polys),
            8 if cell.len() == 4 => (2, &mut pd.polys), // pixel: make the point order cyclic
            6 => (3, &mut pd.strips),
            other => {
                return Err(format!(
                    "cell {i} has VTK cell type {other}; only vertex, line, polyline, triangle, quad, \
                     polygon and strip cells can be read"
                ))
            }
        };
        if ty == 8 {
            target.push(&[cell[0], cell[1], cell[3], cell[2]]);
        } else {
            target.push(cell);
        }
        order[section].push(i);
    }
    let order: Vec<usize> = order.concat();
    for array in &mut pd.cell_data {
        if array.values.len() != types.len() * array.components {
            continue; // reported by validate()
        }
        array.values = permute(&array.values, &order, array.components);
    }
    Ok(())
}

fn permute(values: &Values, order: &[usize], comps: usize) -> Values {
    fn pick<T: Copy>(v: &[T], order: &[usize], comps: usize) -> Vec<T> {
        order.iter().flat_map(|&i| v[i * comps..(i + 1) * comps].iter().copied()).collect()
    }
    match values {
        Values::Int(v) => Values::Int(pick(v, order, comps)),
        Values::Float(v) => Values::Float(pick(v, order, comps)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polydata_with_scalars_and_field() {
        let text = "# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 3 float\n0 0 0 1 0 0 2 0 0\n\
                    LINES 1 4\n3 0 1 2\nPOINT_DATA 3\nSCALARS r double 1\nLOOKUP_TABLE default\n1 2 3\n\
                    FIELD FieldData 1\nEdgeArray 2 3 int\n0 1 1 2 2 3\nMETADATA\nINFORMATION 0\n\n\
                    CELL_DATA 1\nSCALARS id int\nLOOKUP_TABLE default\n7\n";
        let pd = parse(text).unwrap();
        assert_eq!(pd.lines.cell(0), &[0, 1, 2]);
        assert_eq!(pd.point_array("r").unwrap().values, Values::Float(vec![1., 2., 3.]));
        assert_eq!(pd.point_array("EdgeArray").unwrap().components, 2);
        assert_eq!(pd.cell_data[0].values, Values::Int(vec![7]));
    }

    #[test]
    fn unstructured_lines_and_new_layout() {
        let text =
            "# vtk DataFile Version 5.1\nt\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 3 double\n0 0 0 1 0 0 2 0 0\n\
                    CELLS 3 4\nOFFSETS vtktypeint64\n0 2 4\nCONNECTIVITY vtktypeint64\n0 1 1 2\nCELL_TYPES 2\n3\n3\n";
        let pd = parse(text).unwrap();
        assert_eq!(pd.lines.len(), 2);
        assert_eq!(pd.lines.cell(1), &[1, 2]);
    }

    #[test]
    fn errors_name_the_line() {
        let text = "# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 2 float\n0 0 0\n1 x 0\n";
        let e = parse(text).unwrap_err();
        assert!(e.contains("line 7"), "{e}");
        let e = parse("# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 5 float\n0 0 0\n").unwrap_err();
        assert!(e.contains("truncated"), "{e}");
        let e = parse("# vtk DataFile Version 3.0\nt\nBINARY\n").unwrap_err();
        assert!(e.contains("ASCII"), "{e}");
        let e = parse("# vtk DataFile Version 3.0\nt\nASCII\nDATASET STRUCTURED_POINTS\n").unwrap_err();
        assert!(e.contains("STRUCTURED_POINTS"), "{e}");
    }
}
