//! Per-channel calibration of raw DAQ data (NEES `Unprocessed_Data`: volts or counts): a
//! sensitivity table, CSV with a header row `channel,sensitivity,unit,offset`, one row a channel.
//!
//! A channel's value in `unit` is `(raw − offset) / sensitivity`: the sensitivity is in raw units
//! per `unit` (V/g, counts/(in/s²)), the offset in raw units (the output at zero).

use super::{char_column, numbered_lines, offset_in, read_bytes, record_text, ParseError};
use serde::{Deserialize, Serialize};
use std::path::Path;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// The file's column name.
    pub channel: String,
    /// Raw units per `unit` (V/g, counts per m/s², ...).
    pub sensitivity: f64,
    /// The physical unit the sensitivity refers to (a unit of `src/units.rs`).
    pub unit: String,
    /// Raw output at zero, in raw units.
    pub offset: f64,
    /// 1-based line of the table the row is on.
    pub line: usize,
}

impl Calibration {
    /// The channel's raw value in `self.unit`.
    pub fn apply(&self, raw: f64) -> f64 {
        (raw - self.offset) / self.sensitivity
    }
}

const COLUMNS: [&str; 4] = ["channel", "sensitivity", "unit", "offset"];

pub fn read_calibration(path: &Path) -> Result<Vec<Calibration>, ParseError> {
    parse_calibration(path, &read_bytes(path)?)
}

/// The rows of a sensitivity table; blank lines and lines starting with `#` are skipped.
pub fn parse_calibration(path: &Path, bytes: &[u8]) -> Result<Vec<Calibration>, ParseError> {
    let text = record_text(path, bytes, "a header row `channel,sensitivity,unit,offset` and one row a channel")?;
    let mut lines = numbered_lines(&text).filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let Some((header_line, header)) = lines.next() else {
        return Err(ParseError::new(
            path,
            None,
            None,
            "the table has no rows",
            "add a header row and one row a channel",
        ));
    };
    let names: Vec<String> = header.split(',').map(|c| c.trim().to_ascii_lowercase()).collect();
    if names != COLUMNS {
        return Err(ParseError::new(
            path,
            Some(header_line),
            Some(1),
            format!("the header row reads `{}`", header.trim()),
            "a sensitivity table starts with the row `channel,sensitivity,unit,offset`",
        ));
    }
    let mut rows: Vec<Calibration> = Vec::new();
    for (number, line) in lines {
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.len() != COLUMNS.len() {
            return Err(ParseError::new(
                path,
                Some(number),
                None,
                format!("line {number} has {} cell(s), not 4 (channel, sensitivity, unit, offset)", cells.len()),
                "one row a channel: name, sensitivity (raw units per unit), unit, offset (raw units)",
            ));
        }
        let at = |i: usize| Some(char_column(line, offset_in(line, cells[i])));
        let number_in = |i: usize| -> Result<f64, ParseError> {
            cells[i].parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| {
                ParseError::new(
                    path,
                    Some(number),
                    at(i),
                    format!("the {} `{}` of channel `{}` is not a number", COLUMNS[i], cells[i], cells[0]),
                    "write plain numbers with a '.' decimal point",
                )
            })
        };
        let (sensitivity, offset) = (number_in(1)?, number_in(3)?);
        if sensitivity == 0.0 {
            return Err(ParseError::new(
                path,
                Some(number),
                at(1),
                format!("the sensitivity of channel `{}` is zero", cells[0]),
                "the sensitivity is raw units per physical unit (e.g. 1.02 for 1.02 V/g); it divides the data",
            ));
        }
        if crate::units::conversion(cells[2]).is_none() {
            return Err(ParseError::new(
                path,
                Some(number),
                at(2),
                format!("unknown unit `{}` for channel `{}`", cells[2], cells[0]),
                format!("known units: {}", crate::units::known_units().join(", ")),
            ));
        }
        if let Some(first) = rows.iter().find(|r| r.channel == cells[0]) {
            return Err(ParseError::new(
                path,
                Some(number),
                at(0),
                format!("channel `{}` is calibrated twice (lines {} and {number})", cells[0], first.line),
                "keep one row per channel",
            ));
        }
        if cells[0].is_empty() {
            return Err(ParseError::new(
                path,
                Some(number),
                at(0),
                "a row without a channel name",
                "name the file's column",
            ));
        }
        rows.push(Calibration {
            channel: cells[0].to_string(),
            sensitivity,
            unit: cells[2].to_string(),
            offset,
            line: number,
        });
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Vec<Calibration>, ParseError> {
        parse_calibration(Path::new("sens.csv"), text.as_bytes())
    }

    #[test]
    fn rows_are_read_and_applied() {
        let rows = parse("# DAQ 1\nchannel,sensitivity,unit,offset\nA1, 1.25, g, 0.5\n\nD1,0.2,in,-0.1\n").unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!((rows[0].channel.as_str(), rows[0].line, rows[1].line), ("A1", 3, 5));
        // (3.0 − 0.5) / 1.25 = 2 g exactly.
        assert_eq!(rows[0].apply(3.0), 2.0);
        assert_eq!(rows[1].apply(0.1), (0.1 + 0.1) / 0.2);
    }

    #[test]
    fn bad_rows_name_line_and_column() {
        let err = parse("channel,sensitivity,unit,offset\nA1,1.0,furlong,0\n").unwrap_err();
        assert_eq!((err.line, err.column), (Some(2), Some(8)), "{err}");
        assert!(err.message.contains("unknown unit `furlong`"), "{err}");
        let err = parse("channel,sensitivity,unit,offset\nA1,x,g,0\n").unwrap_err();
        assert_eq!((err.line, err.column), (Some(2), Some(4)), "{err}");
        let err = parse("channel,sensitivity,unit,offset\nA1,0,g,0\n").unwrap_err();
        assert!(err.message.contains("is zero"), "{err}");
        let err = parse("channel,sensitivity,unit,offset\nA1,1,g\n").unwrap_err();
        assert!(err.message.contains("has 3 cell(s)"), "{err}");
        let err = parse("channel,sensitivity,unit,offset\nA1,1,g,0\nA1,2,g,0\n").unwrap_err();
        assert!(err.message.contains("twice (lines 2 and 3)"), "{err}");
        let err = parse("name,gain\n").unwrap_err();
        assert_eq!(err.line, Some(1), "{err}");
    }
}
