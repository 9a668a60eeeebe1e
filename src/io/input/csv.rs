//! Centerline CSV: a header naming at least `x,y,z,r` (any order, extra columns ignored), then
//! one point per row. The whole file is one polyline.

use super::CenterlinePolyline;
use indexmap::IndexMap;
use nalgebra::Point3;

/// Parses the CSV text into one polyline (units untouched).
pub(crate) fn parse(text: &str) -> Result<CenterlinePolyline, String> {
    // A byte-order mark (spreadsheets write one) is not part of the first column's name.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut rows = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let (header_idx, header) = rows.next().ok_or("has no header line; the first line must be x,y,z,r")?;
    let names: Vec<String> = header.split(',').map(|s| s.trim().to_ascii_lowercase()).collect();
    let column = |want: &str| {
        names.iter().position(|n| n == want).ok_or_else(|| {
            format!(
                "line {}: the header '{}' has no '{want}' column; the first line must name the columns x,y,z,r",
                header_idx + 1,
                header.trim()
            )
        })
    };
    let cols = [column("x")?, column("y")?, column("z")?, column("r")?];
    let mut points = Vec::new();
    let mut radii = Vec::new();
    for (i, line) in rows {
        let [x, y, z, r] = row(line, &cols, names.len()).map_err(|e| format!("line {}: {e}", i + 1))?;
        points.push(Point3::new(x, y, z));
        radii.push(r);
    }
    Ok(CenterlinePolyline { points, radii: Some(radii), normals: None, cell_tags: IndexMap::new() })
}

fn row(line: &str, cols: &[usize; 4], width: usize) -> Result<[f64; 4], String> {
    let fields: Vec<&str> = line.split(',').map(str::trim).collect();
    if fields.len() != width {
        return Err(format!("has {} fields but the header has {width}", fields.len()));
    }
    let mut out = [0.0f64; 4];
    for (v, &c) in out.iter_mut().zip(cols) {
        *v = fields[c].parse().map_err(|_| format!("'{}' is not a number", fields[c]))?;
        if !v.is_finite() {
            return Err(format!("'{}' is not a finite number", fields[c]));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_by_name() {
        let p = parse("id, r ,x,y,z\n\n1,0.5,0,0,0\n2,0.6,1,0,0\n").unwrap();
        assert_eq!(p.points[1], Point3::new(1.0, 0.0, 0.0));
        assert_eq!(p.radii.unwrap(), vec![0.5, 0.6]);
    }

    #[test]
    fn errors_name_the_line() {
        assert!(parse("0,0,0,1\n").unwrap_err().contains("header"));
        assert!(parse("x,y,z,r\n0,0,0,1\n1,0,0\n").unwrap_err().starts_with("line 3:"));
        assert!(parse("x,y,z,r\n0,0,0,1\n1,a,0,1\n").unwrap_err().starts_with("line 3:"));
        assert!(parse("").unwrap_err().contains("header"));
    }
}
