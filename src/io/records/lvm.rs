//! LabVIEW Measurement files (`.lvm`, NI's text format, Writer_Version 0.92–2).
//!
//! A file header (`LabVIEW Measurement`, then `Key<sep>value` lines: `Separator Tab|Comma`,
//! `Decimal_Separator .|,`, `X_Columns No|One|Multi`, `Time_Pref Relative|Absolute`, ...) closed by
//! `***End_of_Header***`; then one or more segments, each a header (`Channels`, `Samples`,
//! `Y_Unit_Label`, `X0`, `Delta_X` with one cell per channel, closed by `***End_of_Header***`), a
//! column-name row (`X_Value`, the channels, `Comment`) and rows of numbers. The segments of one
//! file are one record: their channels must agree, their rows follow one another in time.

use super::{char_column, numbered_lines, offset_in, read_bytes, record_text, ParseError, RawChannel, RawRecord};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::Path;

const END: &str = "***End_of_Header***";

pub fn read_lvm(path: &Path) -> Result<RawRecord, ParseError> {
    parse_lvm(path, &read_bytes(path)?)
}

/// [`read_lvm`] of a file's bytes; `path` only names the file in errors.
pub fn parse_lvm(path: &Path, bytes: &[u8]) -> Result<RawRecord, ParseError> {
    let text = record_text(path, bytes, "a LabVIEW Measurement file")?;
    let lines: Vec<(usize, &str)> = numbered_lines(&text).collect();
    let error = |line: usize, column: Option<usize>, message: String, hint: &str| {
        ParseError::new(path, Some(line), column, message, hint)
    };
    if !lines[0].1.trim_start().starts_with("LabVIEW Measurement") {
        return Err(error(1, Some(1), "the first line is not `LabVIEW Measurement`".into(), "this is not an LVM file"));
    }
    // The separator decides how every other line splits: find it first.
    let separator = match lines.iter().take_while(|(_, l)| !l.starts_with(END)).find_map(|(n, l)| {
        let rest = l.strip_prefix("Separator")?;
        Some((*n, rest.trim_matches(|c| c == '\t' || c == ',' || c == ' ')))
    }) {
        None | Some((_, "Tab")) => '\t',
        Some((_, "Comma")) => ',',
        Some((n, other)) => {
            return Err(error(n, None, format!("unknown Separator `{other}`"), "LabVIEW writes `Tab` or `Comma`"))
        }
    };
    let mut header = BTreeMap::new();
    let mut k = 1;
    while k < lines.len() && !lines[k].1.starts_with(END) {
        let cells = split(lines[k].1, separator);
        if cells.len() >= 2 && !cells[0].is_empty() {
            header.insert(cells[0].to_ascii_lowercase(), cells[1].to_string());
        }
        k += 1;
    }
    if k == lines.len() {
        return Err(error(lines.len(), None, format!("the file header has no `{END}` line"), "the file is truncated"));
    }
    let decimal_comma = match header.get("decimal_separator").map(String::as_str) {
        None | Some(".") => false,
        Some(",") if separator == '\t' => true,
        Some(other) => {
            let line = lines.iter().find(|(_, l)| l.starts_with("Decimal_Separator")).map_or(1, |(n, _)| *n);
            return Err(error(
                line,
                None,
                format!(
                    "Decimal_Separator `{other}` with a {} separator",
                    if separator == '\t' { "tab" } else { "comma" }
                ),
                "LabVIEW writes `.` or `,` (a comma only with tab-separated columns)",
            ));
        }
    };
    let x_columns = header.get("x_columns").map_or("One", String::as_str);
    let has_x = match x_columns {
        "One" => true,
        "No" => false,
        other => {
            let line = lines.iter().find(|(_, l)| l.starts_with("X_Columns")).map_or(1, |(n, _)| *n);
            return Err(error(
                line,
                None,
                format!("X_Columns `{other}` is not read"),
                "export the file with one X column (X_Columns One) or none",
            ));
        }
    };
    let number = |cell: &str| -> Option<f64> {
        let cell: Cow<'_, str> = if decimal_comma { Cow::Owned(cell.replace(',', ".")) } else { Cow::Borrowed(cell) };
        fast_float2::parse::<f64, _>(cell.as_ref()).ok().filter(|v: &f64| v.is_finite())
    };

    let mut names: Vec<String> = Vec::new();
    let mut units: Vec<(String, usize, usize)> = Vec::new();
    let mut time: Vec<f64> = Vec::new();
    let mut values: Vec<Vec<f64>> = Vec::new();
    let mut first_data_line = None;
    let mut segments = 0;
    k += 1;
    loop {
        while k < lines.len() && lines[k].1.trim().is_empty() {
            k += 1;
        }
        if k == lines.len() {
            break;
        }
        segments += 1;
        // The segment header.
        let mut keys: BTreeMap<&str, (Vec<&str>, usize)> = BTreeMap::new();
        while k < lines.len() && !lines[k].1.starts_with(END) {
            let cells = split(lines[k].1, separator);
            keys.insert(cells[0], (cells[1..].to_vec(), k));
            k += 1;
        }
        if k == lines.len() {
            return Err(error(
                lines.len(),
                None,
                format!("segment {segments}'s header has no `{END}` line"),
                "the file is truncated, or its data do not follow a segment header",
            ));
        }
        let (channels_cells, channels_k) = keys.get("Channels").cloned().ok_or_else(|| {
            error(
                lines[k].0,
                None,
                format!("segment {segments}'s header has no `Channels` line"),
                "the file is damaged",
            )
        })?;
        let n: usize = channels_cells.first().and_then(|c| c.parse().ok()).filter(|&n| n > 0).ok_or_else(|| {
            error(lines[channels_k].0, None, "cannot read the number of Channels".into(), "the header line is damaged")
        })?;
        k += 1;
        // The column-name row.
        let Some(&(names_line, names_text)) = lines.get(k) else {
            return Err(error(
                lines.len(),
                None,
                format!("segment {segments} ends after its header"),
                "the file is truncated",
            ));
        };
        let cells = split(names_text, separator);
        // Without X columns LabVIEW still heads the rows `X_Value` (and leaves that cell of each
        // row empty), as lvm_read expects; a file without the heading starts with the channels.
        let lead = usize::from(has_x || cells.first() == Some(&"X_Value"));
        let expected = lead + n;
        if cells.len() < expected {
            return Err(error(
                names_line,
                None,
                format!(
                    "the column-name row has {} cell(s); {n} channel(s){} need {expected}",
                    cells.len(),
                    if has_x { " and X_Value" } else { "" }
                ),
                "the Channels count of the segment header and the columns disagree: the file is damaged",
            ));
        }
        let segment_names: Vec<String> = cells[lead..expected].iter().map(|c| c.to_string()).collect();
        let comment = cells.get(expected).is_some_and(|c| c.eq_ignore_ascii_case("Comment"));
        if segments == 1 {
            names = segment_names;
            values = vec![Vec::new(); n];
            if let Some((labels, label_k)) = keys.get("Y_Unit_Label") {
                let line = lines[*label_k].1;
                units = labels
                    .iter()
                    .map(|l| (l.to_string(), lines[*label_k].0, char_column(line, offset_in(line, l))))
                    .collect();
            }
        } else if segment_names != names {
            return Err(error(
                names_line,
                None,
                format!(
                    "segment {segments} has the channels {}, segment 1 {}",
                    segment_names.join(", "),
                    names.join(", ")
                ),
                "the segments of one file must record the same channels; split the file",
            ));
        }
        let (dt, x0) = if has_x {
            (None, None)
        } else {
            let first = |key: &str| -> Result<f64, ParseError> {
                let (cells, at) = keys.get(key).ok_or_else(|| {
                    error(
                        lines[k - 1].0,
                        None,
                        format!("segment {segments} has no {key}, and no X column"),
                        "the file is damaged",
                    )
                })?;
                cells.first().and_then(|c| number(c)).ok_or_else(|| {
                    error(lines[*at].0, None, format!("cannot read {key} as a number"), "the header line is damaged")
                })
            };
            (Some(first("Delta_X")?), Some(first("X0")?))
        };
        k += 1;
        // Rows, up to a blank line or the next segment's header.
        let rows_before = values[0].len();
        while let Some(&(number_of_line, line)) = lines.get(k) {
            if line.trim().is_empty() || line.starts_with("Channels") {
                break;
            }
            let cells: Vec<&str> = line.split(separator).collect();
            let data = cells.len().min(expected);
            let extra = &cells[data..];
            let extra_ok = extra.is_empty() || (extra.len() == 1 && (comment || extra[0].trim().is_empty()));
            if data < expected || !extra_ok {
                let last = k + 1 == lines.len() || lines[k + 1..].iter().all(|(_, l)| l.trim().is_empty());
                let message =
                    format!("line {number_of_line} has {} cell(s), the segment has {expected} columns", cells.len());
                let hint = if last {
                    "this is the last line: the file is truncated; delete the partial row or re-export"
                } else {
                    "every row needs X_Value (when present) and one value a channel"
                };
                return Err(error(number_of_line, None, message, hint));
            }
            first_data_line.get_or_insert(number_of_line);
            for (i, cell) in cells[..expected].iter().enumerate() {
                if !has_x && i < lead && cell.trim().is_empty() {
                    continue;
                }
                let v = number(cell.trim()).ok_or_else(|| {
                    error(
                        number_of_line,
                        Some(char_column(line, offset_in(line, cell))),
                        format!("cannot read '{}' as a number", cell.trim()),
                        if decimal_comma {
                            "the file declares Decimal_Separator `,`: numbers look like 0,25"
                        } else {
                            "numbers use the file's Decimal_Separator `.`"
                        },
                    )
                })?;
                match (has_x, i < lead) {
                    (true, true) => time.push(v),
                    (false, true) => {
                        return Err(error(
                            number_of_line,
                            Some(char_column(line, offset_in(line, cell))),
                            format!("a value '{}' under X_Value, but the file declares X_Columns No", cell.trim()),
                            "export the file again, or set X_Columns to One in its header",
                        ))
                    }
                    (_, false) => values[i - lead].push(v),
                }
            }
            if let (Some(dt), Some(x0)) = (dt, x0) {
                time.push(x0 + (values[0].len() - rows_before - 1) as f64 * dt);
            }
            k += 1;
        }
        let rows = values[0].len() - rows_before;
        if let Some((samples, at)) = keys.get("Samples") {
            if let Some(stated) = samples.first().and_then(|s| s.parse::<usize>().ok()) {
                if stated != rows {
                    return Err(error(
                        lines[*at].0,
                        None,
                        format!("segment {segments} states {stated} samples but has {rows} rows"),
                        "the file is truncated or damaged",
                    ));
                }
            }
        }
    }
    if segments == 0 || values.first().is_none_or(Vec::is_empty) {
        return Err(error(
            lines.len(),
            None,
            "no data rows".into(),
            "the file holds headers only: the export did not finish",
        ));
    }
    // Absolute times count seconds since 1904: the record starts at zero, the start is kept.
    if header.get("time_pref").is_some_and(|p| p == "Absolute") {
        let start = time[0];
        header.insert("start_time_s_since_1904".to_string(), start.to_string());
        time.iter_mut().for_each(|t| *t -= start);
    }
    header.insert("segments".to_string(), segments.to_string());
    header.insert("npts".to_string(), values[0].len().to_string());
    let channels = names
        .into_iter()
        .zip(values)
        .enumerate()
        .map(|(i, (name, values))| {
            let unit = units.get(i).map_or(String::new(), |(u, line, column)| {
                header.insert(format!("channel.{name}.units"), u.clone());
                header.insert(format!("channel.{name}.units_at"), format!("{line}:{column}"));
                u.clone()
            });
            RawChannel { name, unit, values, first_data_line }
        })
        .collect();
    Ok(RawRecord { format: "lvm", dt: None, time: Some(time), channels, header })
}

/// The cells of a header line, trimmed.
fn split(line: &str, separator: char) -> Vec<&str> {
    line.split(separator).map(str::trim).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two segments of two channels as LabVIEW 2 writes them with a decimal comma.
    const TWO_SEGMENTS: &str = "LabVIEW Measurement\t\nWriter_Version\t2\nReader_Version\t2\nSeparator\tTab\nDecimal_Separator\t,\nMulti_Headings\tYes\nX_Columns\tOne\nTime_Pref\tRelative\nOperator\tnees\nDate\t2010/05/12\nTime\t11:03:36,44\n***End_of_Header***\t\n\t\nChannels\t2\t\nSamples\t3\t3\t\nDate\t2010/05/12\t2010/05/12\t\nTime\t11:03:36,44\t11:03:36,44\t\nY_Unit_Label\tVolts\tg\t\nX_Dimension\tTime\tTime\t\nX0\t0,0000000000000000E+0\t0,0000000000000000E+0\t\nDelta_X\t0,005000\t0,005000\t\n***End_of_Header***\t\t\t\nX_Value\tA1\tA2\tComment\n0,000000\t0,125\t-1,5E-3\n0,005000\t0,250\t2,0E-3\n0,010000\t-0,375\t2,5E-3\n\nChannels\t2\t\nSamples\t2\t2\t\nY_Unit_Label\tVolts\tg\t\nX0\t1,5000000000000000E-2\t1,5000000000000000E-2\t\nDelta_X\t0,005000\t0,005000\t\n***End_of_Header***\t\t\t\nX_Value\tA1\tA2\tComment\n0,015000\t0,5\t1\n0,020000\t0,625\t-1\n";

    fn parse(text: &str) -> Result<RawRecord, ParseError> {
        parse_lvm(Path::new("run.lvm"), text.as_bytes())
    }

    #[test]
    fn segments_with_decimal_commas_join_into_one_record() {
        let rec = parse(TWO_SEGMENTS).unwrap();
        assert_eq!(rec.time.as_deref().unwrap(), [0.0, 0.005, 0.01, 0.015, 0.02]);
        assert_eq!(rec.channels[0].name, "A1");
        assert_eq!(rec.channels[0].values, [0.125, 0.25, -0.375, 0.5, 0.625]);
        assert_eq!(rec.channels[1].values, [-1.5e-3, 2.0e-3, 2.5e-3, 1.0, -1.0]);
        assert_eq!((rec.channels[0].unit.as_str(), rec.channels[1].unit.as_str()), ("Volts", "g"));
        assert_eq!(rec.channels[0].first_data_line, Some(24));
        assert_eq!(rec.header["segments"], "2");
        assert_eq!(rec.header["channel.A2.units_at"], "18:20");
    }

    #[test]
    fn without_an_x_column_time_comes_from_x0_and_delta_x() {
        let text = TWO_SEGMENTS
            .replace("X_Columns\tOne", "X_Columns\tNo")
            .replace("X_Value\t", "")
            .replace("0,000000\t", "")
            .replace("0,005000\t0,250", "0,250")
            .replace("0,010000\t", "")
            .replace("0,015000\t", "")
            .replace("0,020000\t", "");
        let rec = parse(&text).unwrap();
        let time = rec.time.unwrap();
        assert_eq!(time.len(), 5);
        assert!(time.iter().zip([0.0, 0.005, 0.01, 0.015, 0.02]).all(|(t, e)| (t - e).abs() < 1e-15), "{time:?}");
        assert_eq!(rec.channels[0].values, [0.125, 0.25, -0.375, 0.5, 0.625]);
    }

    #[test]
    fn without_x_columns_an_x_value_heading_leads_empty_cells() {
        let text = TWO_SEGMENTS
            .replace("X_Columns\tOne", "X_Columns\tNo")
            .replace("0,000000\t", "\t")
            .replace("0,005000\t0,250", "\t0,250")
            .replace("0,010000\t", "\t")
            .replace("0,015000\t", "\t")
            .replace("0,020000\t", "\t");
        let rec = parse(&text).unwrap();
        assert_eq!(rec.channels.iter().map(|c| c.name.as_str()).collect::<Vec<_>>(), ["A1", "A2"]);
        assert_eq!(rec.channels[0].values, [0.125, 0.25, -0.375, 0.5, 0.625]);
        // A value where X_Columns No says there is none is refused at its cell.
        let err = parse(&text.replacen("\n\t0,125", "\n0,5\t0,125", 1)).unwrap_err();
        assert_eq!((err.line, err.column), (Some(24), Some(1)), "{err}");
        assert!(err.message.contains("X_Columns No"), "{err}");
    }

    #[test]
    fn damaged_files_name_line_and_column() {
        // Truncated mid-row.
        let cut = &TWO_SEGMENTS[..TWO_SEGMENTS.len() - 5];
        let err = parse(cut).unwrap_err();
        assert_eq!(err.line, Some(36), "{err}");
        assert!(err.hint.contains("truncated"), "{err}");
        // A row lost: the segment's Samples disagree.
        let err = parse(&TWO_SEGMENTS.replace("0,020000\t0,625\t-1\n", "")).unwrap_err();
        assert_eq!(err.line, Some(29), "{err}");
        assert!(err.message.contains("states 2 samples but has 1 rows"), "{err}");
        // A value with a decimal point in a decimal-comma file.
        let err = parse(&TWO_SEGMENTS.replace("0,250\t", "0.2x\t")).unwrap_err();
        assert_eq!((err.line, err.column), (Some(25), Some(10)), "{err}");
        // Segments with other channels.
        let err =
            parse(&TWO_SEGMENTS.replacen("X_Value\tA1\tA2", "X_Value\tA1\tA3", 2).replacen("A3", "A2", 1)).unwrap_err();
        assert!(err.message.contains("segment 2 has the channels A1, A3"), "{err}");
        let err = parse("LabVIEW Measurement\nSeparator\tTab\n").unwrap_err();
        assert!(err.message.contains("no `***End_of_Header***`"), "{err}");
    }
}
