//! Camera control points: a CSV with a header row naming `X_mm, Y_mm, Z_mm, u_px, v_px` (any
//! order, any case; an optional `point` column names them), one point per row. `#` lines are
//! comments. Errors name the file, line and column.

use std::path::Path;

use crate::error::UserError;
use crate::io::records::{decode, printable, read_bytes, unchanged, ParseError};
use crate::vision::calibrate::ControlPoint;

pub const COLUMNS: [&str; 5] = ["X_mm", "Y_mm", "Z_mm", "u_px", "v_px"];

#[derive(Debug, Clone, PartialEq)]
pub struct NamedControlPoint {
    pub name: String,
    pub point: ControlPoint,
    pub line: usize,
}

/// Reads the control points of `path` from one read of its bytes, which must hash to
/// `expected_hash` (the hash the run took when it was planned; empty: unchecked).
pub fn read_control_points(path: &Path, expected_hash: &str) -> Result<Vec<NamedControlPoint>, UserError> {
    let as_user_error = |e: ParseError| {
        UserError::new(e.message).in_file(path).at(e.line.map(|l| (l, e.column.unwrap_or(1)))).hint(e.hint)
    };
    let bytes = read_bytes(path).map_err(as_user_error)?;
    unchanged(path, expected_hash, &bytes).map_err(as_user_error)?;
    let text = decode(path, &bytes).map_err(as_user_error)?;
    parse(path, &text).map_err(|mut e| {
        // Messages quote the file's cells and names.
        e.message = printable(&e.message).into_owned();
        e
    })
}

/// The control points in the text of a control-point file; `path` only names it in errors.
pub fn parse(path: &Path, text: &str) -> Result<Vec<NamedControlPoint>, UserError> {
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end_matches('\r')))
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let expected = format!("a header row naming {} (and optionally `point`)", COLUMNS.join(", "));
    let Some((header_line, header)) = lines.next() else {
        return Err(UserError::new("the control-point file is empty").in_file(path).hint(expected));
    };
    let delimiter = if header.contains(',') {
        ','
    } else if header.contains(';') {
        ';'
    } else {
        '\t'
    };
    let names: Vec<String> = header.split(delimiter).map(|c| c.trim().to_string()).collect();
    let find = |wanted: &str| names.iter().position(|n| n.eq_ignore_ascii_case(wanted));
    let mut indices = [0usize; 5];
    for (slot, column) in indices.iter_mut().zip(COLUMNS) {
        *slot = find(column).ok_or_else(|| {
            UserError::new(format!("the header has no `{column}` column (it has: {})", names.join(", ")))
                .in_file(path)
                .at(Some((header_line, 1)))
                .hint(expected.clone())
        })?;
    }
    let name_column = find("point").or_else(|| find("name"));
    let mut out = Vec::new();
    for (line, row) in lines {
        let cells: Vec<&str> = row.split(delimiter).collect();
        if cells.len() != names.len() {
            return Err(UserError::new(format!(
                "the row has {} cells but the header names {}",
                cells.len(),
                names.len()
            ))
            .in_file(path)
            .at(Some((line, 1)))
            .hint("every row needs a value for every column"));
        }
        let mut values = [0.0; 5];
        for (k, &index) in indices.iter().enumerate() {
            let cell = cells[index].trim();
            values[k] = cell.parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| {
                let column = cells[..index].iter().map(|c| c.chars().count() + 1).sum::<usize>() + 1;
                UserError::new(format!("cannot read '{cell}' as a number ({})", COLUMNS[k]))
                    .in_file(path)
                    .at(Some((line, column)))
                    .hint("control points are numbers: world coordinates in mm, pixel coordinates in px")
            })?;
        }
        let name = name_column.map_or_else(|| format!("C{}", out.len() + 1), |i| cells[i].trim().to_string());
        out.push(NamedControlPoint {
            name,
            point: ControlPoint { world: [values[0], values[1], values[2]], pixel: [values[3], values[4]] },
            line,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_named_points_and_points_at_bad_cells() {
        let dir = crate::tempdir::tempdir().unwrap();
        let path = dir.path().join("cp.csv");
        std::fs::write(&path, "# surveyed\npoint,X_mm,Y_mm,Z_mm,u_px,v_px\nA,0,0,0,10.5,20\nB,100,0,0,110,21\n")
            .unwrap();
        let points = read_control_points(&path, "").unwrap();
        assert_eq!(points.len(), 2);
        assert_eq!((points[1].name.as_str(), points[1].point.world[0], points[1].line), ("B", 100.0, 4));
        std::fs::write(&path, "X_mm,Y_mm,Z_mm,u_px,v_px\n0,0,0,1,2\n1,2,x3,4,5\n").unwrap();
        let err = read_control_points(&path, "").unwrap_err();
        assert_eq!((err.line, err.column), (Some(3), Some(5)), "{err}");
        std::fs::write(&path, "X_mm,Y_mm,u_px,v_px\n").unwrap();
        assert!(read_control_points(&path, "").unwrap_err().message.contains("no `Z_mm` column"));
    }
}
