//! CSMIP/CGS (formerly CDMG, "DMG") Volume 1 (`.V1`, `.RAW`, uncorrected, in g) and Volume 2
//! (`.V2`, corrected: accel, veloc and displ blocks per channel) accelerograms, three channels
//! per file, possibly of different lengths.
//!
//! Per channel: text lines (one starts `Chan  1: 360 Deg`), an integer header (16I5) and a real
//! header (8F10) whose fields touch, then a data line such as
//! `13200 Accelerogram points at 200 pts/sec in units of g . Format: (8f9.6)` or
//! `12000 points of accel data equally spaced at .005 sec, in cm/sec2. (8f10.6)`, the values,
//! and an end line `/&`. The headers are located by content, not by fixed line counts, so the
//! Vol.1 and Vol.2 layouts (13 or 25 text lines) and older upper-case files read alike.

use super::fixed::{after, fortran_format, leading_count, Lines};
use super::{empty_file_error, load, quote, ParseError, RawChannel, RawRecord};
use std::collections::BTreeMap;
use std::path::Path;

/// The most lines a channel's headers take before its first data line (Vol.2: 25 + 7 + 13).
const MAX_HEADER_LINES: usize = 80;

pub fn read_dmg(path: &Path) -> Result<RawRecord, ParseError> {
    let text = load(path)?;
    if text.trim().is_empty() {
        return Err(empty_file_error(path, "a CSMIP/DMG Vol.1 or Vol.2 record"));
    }
    let lines = Lines::new(path, &text);
    let mut header = BTreeMap::new();
    let mut channels: Vec<RawChannel> = Vec::new();
    let mut dt: Option<f64> = None;
    let mut i = 0;
    while i < lines.count() {
        if lines.get(i).is_some_and(|l| l.trim().is_empty()) {
            i += 1;
            continue;
        }
        let channel = read_channel(&lines, i, channels.len() + 1, &mut header)?;
        if let Some(first) = dt.filter(|d| *d != channel.dt) {
            return Err(lines.error(
                channel.data_line,
                None,
                format!("this channel is sampled every {} s, the first every {first} s", channel.dt),
                "one table needs one sampling: read each channel with its own source",
            ));
        }
        dt = Some(channel.dt);
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
    Ok(RawRecord { format: "dmg", dt, time: None, channels, header })
}

struct Channel {
    raw: RawChannel,
    dt: f64,
    data_line: usize,
    meta: Vec<(&'static str, String)>,
    next: usize,
}

fn read_channel(
    lines: &Lines<'_>,
    start: usize,
    number: usize,
    header: &mut BTreeMap<String, String>,
) -> Result<Channel, ParseError> {
    let first = lines.line(start, "a CSMIP channel header")?;
    let upper = first.to_ascii_uppercase();
    let volume = if upper.contains("UNCORRECTED ACCELEROGRAM") {
        "V1"
    } else if upper.contains("CORRECTED ACCELEROGRAM") {
        "V2"
    } else {
        return Err(lines.error(
            start,
            None,
            format!("expected a CSMIP channel header ('Uncorrected Accelerogram Data' or 'Corrected accelerogram'), found {}", quote(first)),
            if number == 1 {
                "this is not a CSMIP/DMG Vol.1/Vol.2 file (Vol.3 spectra are not records)".to_string()
            } else {
                format!("channel {} has more values than its data line announced, or the file was edited", number - 1)
            },
        ));
    };
    let end = (start + MAX_HEADER_LINES).min(lines.count());
    let data_at = (start + 1..end)
        .find(|&k| lines.get(k).is_some_and(is_data_line))
        .ok_or_else(|| {
            lines.error(
                start,
                None,
                format!("no data line ('N Accelerogram points at ...' or 'N points of accel data ...') within {MAX_HEADER_LINES} lines of this channel header"),
                "the file is truncated or not a CSMIP/DMG record",
            )
        })?;
    let text: Vec<&str> = (start..data_at).filter_map(|k| lines.get(k)).collect();
    let data_line = lines.line(data_at, "the data line")?;
    let npts = leading_count(data_line).unwrap_or(0);
    let dt = sampling(data_line).ok_or_else(|| {
        lines.error(
            data_at,
            None,
            format!("cannot find the sampling ('at 200 pts/sec' or 'spaced at .005 sec') on {}", quote(data_line)),
            "CSMIP data lines state the sampling rate or interval",
        )
    })?;
    let unit = units(data_line).or_else(|| text.iter().find_map(|l| units(l))).ok_or_else(|| {
        lines.error(
            data_at,
            None,
            format!("cannot find the units (g or cm/sec2) on {}", quote(data_line)),
            "give `unit:` on the source if you know them",
        )
    })?;
    let (values, mut next) = match fortran_format(data_line) {
        Some((per_line, width)) => lines.fixed(data_at, data_at + 1, npts, per_line, width, "acceleration")?,
        None => lines.free(data_at, data_at + 1, npts, "acceleration")?,
    };
    // Vol.2: the velocity and displacement blocks follow; skip them by their own counts.
    while let Some(line) =
        lines.get(next).filter(|l| leading_count(l).is_some() && l.to_ascii_uppercase().contains("POINTS OF"))
    {
        let count = leading_count(line).unwrap_or(0);
        next = match fortran_format(line) {
            Some((per_line, width)) => lines.fixed(next, next + 1, count, per_line, width, "velocity/displacement")?.1,
            None => lines.free(next, next + 1, count, "velocity/displacement")?.1,
        };
    }
    match lines.get(next) {
        Some(l) if l.trim_start().starts_with("/&") => next += 1,
        Some(l) if !l.trim().is_empty() && !l.to_ascii_uppercase().contains("ACCELEROGRAM") => {
            return Err(lines.error(
                next,
                Some(1),
                format!("expected the end-of-channel line '/&' after {npts} values, found {}", quote(l)),
                format!("the count on line {} ({npts}) is smaller than the values that follow", data_at + 1),
            ));
        }
        _ => {}
    }

    let chan_line = text.iter().find(|l| l.trim_start().to_ascii_uppercase().starts_with("CHAN"));
    let (chan_number, label) = chan_line
        .and_then(|l| l.trim_start()[4..].split_once(':'))
        .map(|(n, rest)| (n.trim().to_string(), rest.trim().to_string()))
        .unwrap_or_else(|| (number.to_string(), String::new()));
    let name = format!("chan{chan_number}");
    let mut meta = vec![
        ("label", label.clone()),
        ("orientation", orientation(&label)),
        ("npts", npts.to_string()),
        ("dt_s", dt.to_string()),
        ("units", unit.clone()),
    ];
    let peak = if volume == "V2" {
        text.iter().find_map(|l| after(l, "Peak acceleration =")).and_then(|v| v.split_whitespace().next())
    } else {
        text.iter()
            .find_map(|l| after(l, "Max  =").or_else(|| after(l, "Max =")))
            .and_then(|v| v.split_whitespace().next())
    };
    if let Some(peak) = peak {
        meta.push(("peak", peak.to_string()));
    }
    for (key, prefix) in [("peak_velocity", "Peak   velocity   ="), ("peak_displacement", "Peak displacement =")] {
        if let Some(v) = text.iter().find_map(|l| after(l, prefix)).and_then(|v| v.split_whitespace().next()) {
            meta.push((key, v.to_string()));
        }
    }

    if number == 1 {
        let put = |h: &mut BTreeMap<String, String>, k: &str, v: &str| {
            if !v.trim().is_empty() {
                h.insert(k.to_string(), v.trim().to_string());
            }
        };
        put(header, "process_level", volume);
        put(header, "record_type", first.get(..40).unwrap_or(first));
        let find = |prefixes: &[&str]| -> Option<usize> {
            text.iter().position(|l| {
                let u = l.trim_start().to_ascii_uppercase();
                prefixes.iter().any(|p| u.starts_with(p))
            })
        };
        if let Some(k) = find(&["STATION NO", "STATION ID", "STATION"]) {
            let line = text[k];
            put(header, "station_line", line);
            let id = line.split(['.', ':']).nth(1).and_then(|s| s.split_whitespace().next()).unwrap_or("");
            put(header, "station", id);
            put(header, "station_name", text.get(k + 1).map_or("", |l| l.get(..40).unwrap_or(l)));
            put(
                header,
                "network",
                text.get(k + 1).and_then(|l| l.get(40..)).and_then(|s| s.split_whitespace().next()).unwrap_or(""),
            );
        }
        if let Some(k) = find(&["RECORD OF", "RCRD OF"]) {
            put(header, "event", text[k].get(..46).unwrap_or(text[k]));
        }
        if let Some(start_time) = text.iter().find_map(|l| after(l, "Start time:")) {
            put(header, "record_start", start_time);
        }
        if let Some(k) = find(&["HYPOCENTER"]) {
            put(header, "hypocenter", text[k]);
        }
        if let Some(instr) = text.iter().find_map(|l| after(l, "Instr Period")) {
            put(header, "instrument", &format!("Instr Period {instr}"));
        }
    }

    Ok(Channel {
        raw: RawChannel { name, unit, values, first_data_line: Some(data_at + 2) },
        dt,
        data_line: data_at,
        meta,
        next,
    })
}

fn is_data_line(line: &str) -> bool {
    let upper = line.to_ascii_uppercase();
    leading_count(line).is_some() && (upper.contains("ACCELEROGRAM POINTS") || upper.contains("POINTS OF ACCEL"))
}

/// `at 200 pts/sec` → 0.005; `spaced at .005 sec` → 0.005.
fn sampling(line: &str) -> Option<f64> {
    if let Some(rest) = after(line, "spaced at") {
        let dt: f64 = rest.split_whitespace().next()?.trim_end_matches(',').parse().ok()?;
        return (dt > 0.0).then_some(dt);
    }
    let upper = line.to_ascii_uppercase();
    let at = upper.find("PTS/SEC").or_else(|| upper.find("SAMPLES/SEC"))?;
    let rate: f64 = line[..at].split_whitespace().last()?.parse().ok()?;
    (rate > 0.0).then(|| 1.0 / rate)
}

/// The units a data or text line states: `in units of g`, `in cm/sec2`, `(UNITS: CM/SEC/SEC)`.
fn units(line: &str) -> Option<String> {
    let upper = line.to_ascii_uppercase().replace(' ', "");
    if upper.contains("CM/SEC2") || upper.contains("CM/SEC/SEC") || upper.contains("CM/S2") {
        Some("cm/s^2".into())
    } else if upper.contains("UNITSOFG.")
        || upper.ends_with("UNITSOFG")
        || upper.contains("UNITS:G)")
        || upper.contains("SECANDG")
    {
        Some("g".into())
    } else {
        None
    }
}

/// `360 Deg` → "360", `Up` → "up", `Down` → "down"; anything else "unknown".
fn orientation(label: &str) -> String {
    let upper = label.trim().to_ascii_uppercase();
    if upper.starts_with("UP") {
        return "up".into();
    }
    if upper.starts_with("DOWN") || upper.starts_with("DN") {
        return "down".into();
    }
    match upper.split_whitespace().next().and_then(|t| t.parse::<f64>().ok()) {
        Some(a) if (0.0..=360.0).contains(&a) => format!("{a}"),
        _ => "unknown".into(),
    }
}
