//! COSMOS Strong-Motion Data Format v1.20 (the US exchange format, CESMD): `.v0c` raw counts,
//! `.V1c` uncorrected and `.V2c` corrected records, one or more channels one after another.
//!
//! Per channel: a text header whose first line says how many text lines it has, an integer and a
//! real header each announced by a line with its count and Fortran format, comment lines, a
//! data line with the count, units and format, the values, and optionally `End-of-data`.

use super::fixed::{after, fortran_format, is_blank, leading_count, Lines, Values};
use super::{quote, read_bytes, record_text, ParseError, RawChannel, RawRecord};
use std::collections::BTreeMap;
use std::path::Path;

/// The value COSMOS headers use for "unknown", unless line 13 says otherwise.
const UNKNOWN: f64 = -999.0;

pub fn read_cosmos(path: &Path) -> Result<RawRecord, ParseError> {
    parse_cosmos(path, &read_bytes(path)?)
}

/// [`read_cosmos`] of a file's bytes (read once and hashed by `load`); `path` only names the file in errors.
pub fn parse_cosmos(path: &Path, bytes: &[u8]) -> Result<RawRecord, ParseError> {
    cosmos(path, bytes, Values::Parse)
}

/// `validate`'s check that the file holds the values its header announces: the reader with
/// its data blocks counted, not parsed.
pub(super) fn count_cosmos(path: &Path, bytes: &[u8]) -> Result<(), ParseError> {
    cosmos(path, bytes, Values::Count).map(drop)
}

fn cosmos(path: &Path, bytes: &[u8], values: Values) -> Result<RawRecord, ParseError> {
    let text = record_text(path, bytes, "a COSMOS record (text header, integer and real headers, data)")?;
    let lines = Lines::new(path, &text, values);
    let mut header = BTreeMap::new();
    let mut channels: Vec<RawChannel> = Vec::new();
    let mut dt: Option<(f64, usize)> = None;
    let mut i = 0;
    while i < lines.count() {
        if lines.get(i).is_some_and(is_blank) {
            i += 1;
            continue;
        }
        let channel = read_channel(&lines, i, channels.len() + 1, &mut header)?;
        match dt {
            None => dt = Some((channel.dt, i)),
            Some((first, _)) if first != channel.dt => return Err(lines.error(
                i,
                None,
                format!("channel {} is sampled every {} s, the first every {first} s", channels.len() + 1, channel.dt),
                "one table needs one sampling: split the file per channel, or read each channel with its own source",
            )),
            Some(_) => {}
        }
        let mut raw = channel.raw;
        if channels.iter().any(|c| c.name == raw.name) {
            raw.name = format!("{}_{}", raw.name, channels.len() + 1);
        }
        for (key, value) in channel.meta {
            header.insert(format!("channel.{}.{key}", raw.name), value);
        }
        channels.push(raw);
        i = channel.next;
    }
    header.insert("channels".into(), channels.len().to_string());
    Ok(RawRecord { format: "cosmos", dt: dt.map(|d| d.0), time: None, channels, header })
}

struct Channel {
    raw: RawChannel,
    dt: f64,
    meta: Vec<(&'static str, String)>,
    next: usize,
}

fn read_channel(
    lines: &Lines<'_>,
    start: usize,
    number: usize,
    header: &mut BTreeMap<String, String>,
) -> Result<Channel, ParseError> {
    let first = lines.line(start, "a COSMOS channel header")?;
    let Some(n_text) = after(first, "with").and_then(leading_count).filter(|n| (2..1000).contains(n)) else {
        return Err(lines.error(
            start,
            None,
            format!("expected a COSMOS header line '... (Format v01.20 with 13 text lines)', found {}", quote(first)),
            if number == 1 {
                "this is not a COSMOS file, or its first line was damaged".to_string()
            } else {
                format!("channel {} ended early or has more values than its data line announced", number - 1)
            },
        ));
    };
    let text: Vec<&str> =
        (start..start + n_text).map(|k| lines.line(k, "the COSMOS text header")).collect::<Result<_, _>>()?;
    let unknown = text
        .get(12)
        .and_then(|l| l.split(':').nth(1))
        .and_then(|v| v.split([',', ' ']).find(|t| !t.is_empty()))
        .and_then(|t| t.parse::<f64>().ok())
        .unwrap_or(UNKNOWN);
    let known = |v: f64| (v != unknown).then_some(v);

    let mut at = start + n_text;
    let (ints, next) = numeric_block(lines, at, "Integer-header")?;
    at = next;
    let (reals, next) = numeric_block(lines, at, "Real-header")?;
    at = next;
    let count_line = lines.line(at, "the COSMOS comment count line")?;
    let n_comments =
        leading_count(count_line).filter(|_| count_line.to_ascii_lowercase().contains("comment")).ok_or_else(|| {
            lines.error(
                at,
                None,
                format!("expected 'N Comment line(s) follow', found {}", quote(count_line)),
                "the real header holds more or fewer values than its line announced",
            )
        })?;
    lines.check_room(at, at + 1, n_comments, 1, "comment lines")?;
    let comments: Vec<&str> =
        (at + 1..at + 1 + n_comments).map(|k| lines.line(k, "the COSMOS comments")).collect::<Result<_, _>>()?;
    at += 1 + n_comments;

    let data_line = lines.line(at, "the COSMOS data line")?;
    let npts = leading_count(data_line).ok_or_else(|| {
        lines.error(
            at,
            None,
            format!(
                "expected the data line 'N acceleration pts, ..., units=..., Format=(...)', found {}",
                quote(data_line)
            ),
            format!("the comment count ({n_comments}) is wrong, or the data line was damaged"),
        )
    })?;
    let (per_line, width) = fortran_format(data_line).ok_or_else(|| {
        lines.error(
            at,
            None,
            format!("the data line gives no Fortran format such as (1E15.6): {}", quote(data_line)),
            "COSMOS data lines end with Format=(...)",
        )
    })?;
    let (mut values, mut next) = lines.fixed(at, at + 1, npts, per_line, width, "data")?;
    // `End-of-data for ...`, or `/&` in files written like CSMIP's.
    if lines.get(next).is_some_and(|l| {
        let l = l.trim_start().to_ascii_lowercase();
        l.starts_with("end-of-data") || l.starts_with("/&")
    }) {
        next += 1;
    }

    let int = |k: usize| ints.get(k - 1).copied().and_then(known);
    let real = |k: usize| reals.get(k - 1).copied().and_then(known);
    let dt_ms = real(62).filter(|v| *v > 0.0).ok_or_else(|| {
        lines.error(
            start + n_text + 1 + ints.len().div_ceil(10),
            None,
            "the real header gives no sampling interval (value 62, in milliseconds)",
            "COSMOS records state their sampling interval in real-header value 62",
        )
    })?;
    let dt = dt_ms / 1000.0;

    // Units: the code in the data line `units=cm/sec2(04)`, else integer-header value 3.
    let units_text = after(data_line, "units=").map(|u| u.split(",Format").next().unwrap_or(u).trim().to_string());
    let code = units_text
        .as_deref()
        .and_then(|u| u.rsplit_once('(').and_then(|(_, c)| c.trim_end_matches(')').trim().parse::<i64>().ok()))
        .or_else(|| int(3).map(|v| v as i64));
    let scnl = comments.iter().find_map(|c| after(c, "<SCNL>")).and_then(|s| s.split_whitespace().next()).unwrap_or("");
    let scnl_parts: Vec<&str> = scnl.split('.').collect();
    let seed_channel = scnl_parts.get(1).copied().unwrap_or("");

    let mut meta = Vec::new();
    let unit = match code {
        Some(2) => "g".to_string(),
        Some(4) | Some(10) => "cm/s^2".to_string(),
        Some(5) => "cm/s".to_string(),
        Some(6) => "cm".to_string(),
        Some(7) => "in/s^2".to_string(),
        Some(8) => "in/s".to_string(),
        Some(9) => "in".to_string(),
        Some(11) => "mg".to_string(),
        Some(50) => match (real(22), real(42), real(47).unwrap_or(1.0)) {
            // V0 counts: LSB (µV/count) / sensitivity (V/g) / gain, as the header states them.
            (Some(lsb), Some(sensitivity), gain) if sensitivity != 0.0 && gain != 0.0 => {
                let factor = lsb * 1e-6 / sensitivity / gain;
                for v in &mut values {
                    *v *= factor;
                }
                meta.push(("counts_to_g", factor.to_string()));
                "g".to_string()
            }
            _ => "counts".to_string(),
        },
        _ => String::new(),
    };

    let name = if seed_channel.is_empty() { format!("chan{number}") } else { seed_channel.to_string() };
    let orientation = match int(54).map(|v| v as i64) {
        Some(a @ 1..=360) => format!("{a}"),
        Some(400) => "up".into(),
        Some(401) => "down".into(),
        Some(402) => "vertical".into(),
        _ => match seed_channel.chars().last() {
            Some('Z') => "up".into(),
            Some('N') => "0".into(),
            Some('E') => "90".into(),
            _ => "unknown".into(),
        },
    };
    meta.push(("orientation", orientation));
    if let Some(label) = text.get(8) {
        meta.push(("label", label.trim().to_string()));
    }
    meta.push(("npts", npts.to_string()));
    meta.push(("dt_s", dt.to_string()));
    meta.push(("units", units_text.unwrap_or_default()));
    if let Some(peak) = real(64) {
        meta.push(("peak", peak.to_string()));
    }
    if let Some(t) = real(65) {
        meta.push(("peak_time_s", t.to_string()));
    }
    if !scnl.is_empty() {
        meta.push(("scnl", scnl.to_string()));
    }
    meta.push((
        "data_type",
        match int(2).map(|v| v as i64) {
            Some(1) => "acceleration",
            Some(2) => "velocity",
            Some(3) => "displacement",
            _ => "unknown",
        }
        .into(),
    ));

    if number == 1 {
        let put = |h: &mut BTreeMap<String, String>, k: &str, v: &str| {
            if !v.trim().is_empty() {
                h.insert(k.to_string(), v.trim().to_string());
            }
        };
        put(header, "record_type", first.split('(').next().unwrap_or(""));
        put(header, "format_version", after(first, "Format").and_then(|v| v.split_whitespace().next()).unwrap_or(""));
        let level = match int(1).map(|v| v as i64) {
            Some(0) => "V0",
            Some(1) => "V1",
            Some(2) => "V2",
            Some(3) => "V3",
            _ => "",
        };
        put(header, "process_level", level);
        put(header, "event", text.get(1).map_or("", |l| l.trim_start_matches("Record of")));
        put(header, "hypocenter", text.get(2).map_or("", |l| l.trim_start_matches("Hypocenter:")));
        put(header, "origin", text.get(3).map_or("", |l| l.trim_start_matches("Origin:")));
        put(header, "station_line", text.get(4).copied().unwrap_or(""));
        put(header, "record_start", text.get(7).and_then(|l| after(l, "Rcrd start time:")).unwrap_or(""));
        if scnl_parts.len() >= 3 {
            put(header, "station", scnl_parts[0]);
            put(header, "network", scnl_parts[2]);
        }
        if let Some(name) = text.get(4).and_then(|l| l.get(40..)) {
            put(header, "station_name", name);
        }
        for (key, k) in [("station_latitude", 1), ("station_longitude", 2), ("station_elevation_m", 3)] {
            if let Some(v) = real(k) {
                header.insert(key.into(), v.to_string());
            }
        }
        let sensor = comments.iter().find_map(|c| after(c, "Sensor:")).unwrap_or("");
        put(header, "instrument", sensor);
    }

    Ok(Channel { raw: RawChannel { name, unit, values, first_data_line: Some(at + 2) }, dt, meta, next })
}

/// A header block announced as `100 Integer-header values follow on 10 lines, Format= (10I8)`;
/// returns the values and the index of the line after the block.
fn numeric_block(lines: &Lines<'_>, at: usize, what: &str) -> Result<(Vec<f64>, usize), ParseError> {
    let line = lines.line(at, &format!("the COSMOS {what} line"))?;
    let count = leading_count(line).filter(|_| line.to_ascii_lowercase().contains(&what.to_ascii_lowercase()));
    let format = fortran_format(line);
    let (Some(count), Some((per_line, width))) = (count, format) else {
        return Err(lines.error(
            at,
            None,
            format!("expected '100 {what} values follow on N lines, Format= (...)', found {}", quote(line)),
            "the block before it holds more or fewer lines than announced, or this is not a COSMOS file",
        ));
    };
    lines.fixed_parsed(at, at + 1, count, per_line, width, &format!("{what} values"))
}
