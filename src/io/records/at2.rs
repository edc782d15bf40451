//! PEER NGA `.AT2`: title, event line, units line, an NPTS/DT line, then
//! values, any number per line.

use super::fixed::Values;
use super::{
    char_column, numbered_lines, offset_in, parse_finite, quote, read_bytes, record_text, ParseError, RawChannel,
    RawRecord,
};
use std::collections::BTreeMap;
use std::path::Path;

const HEADER_LINES: usize = 4;
const HEADER_FORMS: &str =
    "expected 'NPTS=   8773, DT=   .0050 SEC' (NGA) or '4096    0.0100    NPTS, DT' (older PEER)";

pub fn read_at2(path: &Path) -> Result<RawRecord, ParseError> {
    parse_at2(path, &read_bytes(path)?)
}

/// [`read_at2`] of a file's bytes; `path` only names the file in errors.
pub fn parse_at2(path: &Path, bytes: &[u8]) -> Result<RawRecord, ParseError> {
    at2(path, bytes, Values::Parse)
}

/// `validate`'s check that the file holds the NPTS values its header announces: the reader
/// with the values counted, not parsed.
pub(super) fn count_at2(path: &Path, bytes: &[u8]) -> Result<(), ParseError> {
    at2(path, bytes, Values::Count).map(drop)
}

fn at2(path: &Path, bytes: &[u8], mode: Values) -> Result<RawRecord, ParseError> {
    let text = record_text(path, bytes, "a PEER AT2 record (4 header lines, then values)")?;
    let mut lines = numbered_lines(&text);
    let mut head: Vec<&str> = Vec::with_capacity(HEADER_LINES);
    for (_, line) in lines.by_ref().take(HEADER_LINES) {
        head.push(line);
    }
    if head.len() < HEADER_LINES {
        return Err(ParseError::new(
            path,
            Some(head.len()),
            None,
            format!("the file ends after {} line(s), inside the 4-line AT2 header", head.len()),
            "an AT2 file starts with a title, an event line, a units line and an NPTS/DT line",
        ));
    }

    let mut header = BTreeMap::new();
    header.insert("title".to_string(), head[0].trim().to_string());
    let component = describe_event_line(head[1], &mut header);
    let unit = units_from(head[2]);
    header.insert("units".to_string(), head[2].trim().to_string());
    let (npts, dt, filter) = parse_npts_dt(head[3]).map_err(|(col, msg)| {
        ParseError::new(
            path,
            Some(HEADER_LINES),
            col,
            msg,
            format!("{HEADER_FORMS}; line {HEADER_LINES} is {}", quote(head[3])),
        )
    })?;
    header.insert("npts".to_string(), npts.to_string());
    header.insert("dt".to_string(), dt.to_string());
    if !filter.is_empty() {
        header.insert("filter".to_string(), filter);
    }

    // Each value takes a character and a separator: a count the data has no room for is a
    // damaged header, refused before anything is allocated for it. (Without data, the file
    // holds only its header: said below.)
    let data = text.match_indices('\n').nth(HEADER_LINES - 1).map_or("", |(i, _)| &text[i + 1..]);
    let (data_bytes, room) = (data.len(), data.len() / 2 + 1);
    if npts > room && !data.trim().is_empty() {
        let column = keyed_value(&head[3].to_ascii_uppercase(), "NPTS")
            .map_or_else(|| head[3].len() - head[3].trim_start().len(), |(a, _)| a);
        return Err(ParseError::new(
            path,
            Some(HEADER_LINES),
            Some(char_column(head[3], column)),
            format!(
                "NPTS = {npts} (line {HEADER_LINES}) cannot be right: the {data_bytes} bytes after the header hold at most {room} values"
            ),
            "the NPTS on line 4 is damaged, or the file was cut short; get a fresh copy of the record",
        ));
    }
    let mut values = Vec::with_capacity(npts.min(room));
    let mut first_data_line = None;
    let mut last_data_line = HEADER_LINES;
    for (number, line) in lines {
        for token in line.split_ascii_whitespace() {
            let value = match mode {
                Values::Parse => parse_finite(token),
                Values::Count => Some(0.0),
            };
            let Some(v) = value else {
                let col = char_column(line, offset_in(line, token));
                return Err(ParseError::new(
                    path,
                    Some(number),
                    Some(col),
                    format!("cannot read '{token}' as a number (value {} of {npts})", values.len() + 1),
                    "AT2 data lines hold only numbers separated by spaces; the file may be \
                     corrupt or two files may have been joined",
                ));
            };
            values.push(v);
            first_data_line.get_or_insert(number);
            last_data_line = number;
        }
    }

    if values.is_empty() {
        return Err(ParseError::new(
            path,
            Some(HEADER_LINES),
            None,
            format!("no data values after the header (NPTS = {npts})"),
            "the file holds only the header; the export or download was probably cut short",
        ));
    }
    if values.len() < npts {
        return Err(ParseError::new(
            path,
            Some(last_data_line),
            None,
            format!(
                "NPTS = {npts} (line {HEADER_LINES}) but only {} values were found (the last on line {last_data_line})",
                values.len()
            ),
            format!(
                "{} values are missing: the file looks truncated; get a fresh copy of the record",
                npts - values.len()
            ),
        ));
    }
    if values.len() > npts {
        return Err(ParseError::new(
            path,
            Some(HEADER_LINES),
            None,
            format!(
                "NPTS = {npts} (line {HEADER_LINES}) but {} values were found ({} more, up to line {last_data_line})",
                values.len(),
                values.len() - npts
            ),
            "the NPTS on line 4 is wrong, or the file holds more than one record",
        ));
    }

    Ok(RawRecord {
        format: "at2",
        dt: Some(dt),
        time: None,
        channels: vec![RawChannel {
            name: component.unwrap_or_else(|| "accel".to_string()),
            unit,
            values,
            first_data_line,
        }],
        header,
    })
}

/// Line 2 is "event, date, station, component" (NGA-West2) or
/// "event date, station, component" (older); the component is the last field.
fn describe_event_line(line: &str, header: &mut BTreeMap<String, String>) -> Option<String> {
    let fields: Vec<&str> = line.split(',').map(str::trim).collect();
    header.insert("event_line".to_string(), line.trim().to_string());
    if fields.len() < 2 {
        return None;
    }
    header.insert("event".to_string(), fields[0].to_string());
    if fields.len() >= 4 {
        header.insert("date".to_string(), fields[1].to_string());
    }
    if fields.len() >= 3 {
        header.insert("station".to_string(), fields[fields.len() - 2].to_string());
    }
    let component = fields[fields.len() - 1];
    if component.is_empty() {
        return None;
    }
    header.insert("component".to_string(), component.to_string());
    Some(component.to_string())
}

/// "ACCELERATION TIME SERIES IN UNITS OF G" -> "g"; "" when not stated.
fn units_from(line: &str) -> String {
    let upper = line.to_ascii_uppercase();
    match upper.find("UNITS OF") {
        Some(i) => line[i + "UNITS OF".len()..].trim().to_lowercase(),
        None => String::new(),
    }
}

/// Parse either header form. Errors carry the 1-based column when a specific
/// token is at fault.
fn parse_npts_dt(line: &str) -> Result<(usize, f64, String), (Option<usize>, String)> {
    // ASCII upper-casing keeps byte offsets, so positions map back to `line`.
    let upper = line.to_ascii_uppercase();
    let (npts, dt, rest_at) = match (keyed_value(&upper, "NPTS"), keyed_value(&upper, "DT")) {
        (Some(n), Some(d)) => {
            let npts = parse_npts(line, n)?;
            let dt = parse_dt(line, d)?;
            // Filter description follows "SEC," after the DT value.
            let after_dt = d.1;
            let rest = upper[after_dt..].find("SEC").map_or(after_dt, |i| after_dt + i + 3);
            (npts, dt, rest)
        }
        (Some(_), None) => return Err((None, "found NPTS= but no DT= on the AT2 header line".to_string())),
        (None, Some(_)) => return Err((None, "found DT= but no NPTS= on the AT2 header line".to_string())),
        (None, None) => {
            let mut tokens = line.split_ascii_whitespace();
            let (Some(n), Some(d)) = (tokens.next(), tokens.next()) else {
                return Err((None, "cannot find NPTS and DT on the AT2 header line".to_string()));
            };
            let n_start = offset_in(line, n);
            let d_start = offset_in(line, d);
            let npts = parse_npts(line, (n_start, n_start + n.len()))?;
            let dt = parse_dt(line, (d_start, d_start + d.len()))?;
            (npts, dt, d_start + d.len())
        }
    };
    let rest = line.get(rest_at..).unwrap_or("");
    let filter = rest.trim().trim_start_matches(',').trim();
    // The older form ends in the labels "NPTS, DT", which are not a filter.
    let filter = if filter.eq_ignore_ascii_case("NPTS, DT") { "" } else { filter };
    Ok((npts, dt, filter.to_string()))
}

/// Byte span of the value in "KEY = value" (value ends at ',' or space).
/// The key must start a word, so "DT" does not match inside another word.
fn keyed_value(upper: &str, key: &str) -> Option<(usize, usize)> {
    let bytes = upper.as_bytes();
    let mut from = 0;
    while let Some(found) = upper[from..].find(key) {
        let start = from + found;
        from = start + key.len();
        if start > 0 && bytes[start - 1].is_ascii_alphanumeric() {
            continue;
        }
        let mut i = from;
        while i < bytes.len() && bytes[i] == b' ' {
            i += 1;
        }
        if i >= bytes.len() || bytes[i] != b'=' {
            continue;
        }
        i += 1;
        while i < bytes.len() && bytes[i] == b' ' {
            i += 1;
        }
        let value_start = i;
        while i < bytes.len() && bytes[i] != b',' && !bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        return Some((value_start, i));
    }
    None
}

fn parse_npts(line: &str, (a, b): (usize, usize)) -> Result<usize, (Option<usize>, String)> {
    let token = line.get(a..b).unwrap_or("");
    match token.parse::<usize>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err((
            Some(char_column(line, a)),
            format!("cannot read NPTS '{token}' as a positive whole number on the AT2 header line"),
        )),
    }
}

fn parse_dt(line: &str, (a, b): (usize, usize)) -> Result<f64, (Option<usize>, String)> {
    let token = line.get(a..b).unwrap_or("");
    match parse_finite(token) {
        Some(dt) if dt > 0.0 => Ok(dt),
        _ => Err((
            Some(char_column(line, a)),
            format!("cannot read DT '{token}' as a positive time step in seconds on the AT2 header line"),
        )),
    }
}
