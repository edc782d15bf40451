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

use super::fixed::{after, fortran_format, is_blank, leading_count, Lines, Values};
use super::{quote, read_bytes, record_text, ParseError, RawChannel, RawRecord};
use std::collections::BTreeMap;
use std::path::Path;

/// The most lines a channel's headers take before its first data line (Vol.2: 25 + 7 + 13).
const MAX_HEADER_LINES: usize = 80;

pub fn read_dmg(path: &Path) -> Result<RawRecord, ParseError> {
    parse_dmg(path, &read_bytes(path)?)
}

/// [`read_dmg`] of a file's bytes (read once and hashed by `load`); `path` only names the file in errors.
pub fn parse_dmg(path: &Path, bytes: &[u8]) -> Result<RawRecord, ParseError> {
    dmg(path, bytes, Values::Parse)
}

/// `validate`'s check that the file holds the values its header announces: the reader with
/// its data blocks counted, not parsed.
pub(super) fn count_dmg(path: &Path, bytes: &[u8]) -> Result<(), ParseError> {
    dmg(path, bytes, Values::Count).map(drop)
}

fn dmg(path: &Path, bytes: &[u8], values: Values) -> Result<RawRecord, ParseError> {
    let text = record_text(path, bytes, "a CSMIP/DMG Vol.1 or Vol.2 record")?;
    let lines = Lines::new(path, &text, values);
    let mut header = BTreeMap::new();
    let mut channels: Vec<RawChannel> = Vec::new();
    let mut dt: Option<f64> = None;
    let mut times: Vec<Option<Vec<f64>>> = Vec::new();
    let mut i = 0;
    while i < lines.count() {
        if lines.get(i).is_some_and(is_blank) {
            i += 1;
            continue;
        }
        let channel = read_channel(&lines, i, channels.len() + 1, &mut header)?;
        if times.first().is_some_and(|t: &Option<Vec<f64>>| t != &channel.time) {
            return Err(lines.error(
                channel.data_line + 1,
                None,
                "this channel's time column differs from the first channel's, and they are not uniform",
                "a digitised record whose channels have their own times: extract each channel to a file of its own",
            ));
        }
        times.push(channel.time.clone());
        if let Some(first) = dt.filter(|d| (d - channel.dt).abs() > channel.dt_tolerance) {
            return Err(lines.error(
                channel.data_line,
                None,
                format!("this channel is sampled every {} s, the first every {first} s", channel.dt),
                "one table needs one sampling: read each channel with its own source",
            ));
        }
        dt = dt.or(Some(channel.dt));
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
    // Non-uniform times (all channels share them) go to `load`, which refuses or resamples them.
    let time = times.into_iter().next().flatten();
    if time.is_some() {
        header.insert("time_column".into(), "non-uniform (digitised record)".into());
    }
    Ok(RawRecord { format: "dmg", dt: if time.is_some() { None } else { dt }, time, channels, header })
}

struct Channel {
    raw: RawChannel,
    dt: f64,
    /// How far this channel's dt may be from the others' (time columns printed to 1 ms).
    dt_tolerance: f64,
    time: Option<Vec<f64>>,
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
    let found = (start + 1..end).find(|&k| lines.get(k).is_some_and(is_data_line));
    let data = match found {
        Some(data_at) => stated_block(lines, start, data_at)?,
        // Older Vol.1 files: no data line, (time, accel) pairs after fixed-size headers.
        None if volume == "V1" => time_value_pairs(lines, start)?,
        None => {
            return Err(lines.error(
                start,
                None,
                format!("no data line ('N Accelerogram points at ...' or 'N points of accel data ...') within {MAX_HEADER_LINES} lines of this channel header"),
                "the file is truncated or not a CSMIP/DMG record",
            ))
        }
    };
    let Block { data_at, npts, dt, dt_tolerance, time, unit, values, mut next } = data;
    let text: Vec<&str> = (start..data_at).filter_map(|k| lines.get(k)).collect();
    // Vol.2: the velocity and displacement blocks follow; skip them by their own counts.
    while let Some(line) =
        lines.get(next).filter(|l| leading_count(l).is_some() && l.to_ascii_uppercase().contains("POINTS OF"))
    {
        let count = leading_count(line).unwrap_or(0);
        next = block(lines, next, count, "velocity/displacement")?.1;
    }
    match lines.get(next) {
        Some(l) if l.trim_start().starts_with("/&") => next += 1,
        Some(l) if !is_blank(l) && !l.to_ascii_uppercase().contains("ACCELEROGRAM") => {
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
        // A time column with several pairs to a line has no one line per sample.
        raw: RawChannel { name, unit, values, first_data_line: time.is_none().then_some(data_at + 2) },
        dt,
        dt_tolerance,
        time,
        data_line: data_at,
        meta,
        next,
    })
}

/// A channel's data: where its block starts (the data line, or the first pair line), the count,
/// sampling, unit, values and the line after them.
struct Block {
    data_at: usize,
    npts: usize,
    dt: f64,
    dt_tolerance: f64,
    /// The time column of a digitised record whose times are not uniform.
    time: Option<Vec<f64>>,
    unit: String,
    values: Vec<f64>,
    next: usize,
}

/// The data line states count, sampling, units and (usually) the format.
fn stated_block(lines: &Lines<'_>, start: usize, data_at: usize) -> Result<Block, ParseError> {
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
    let unit =
        units(data_line).or_else(|| (start..data_at).find_map(|k| lines.get(k).and_then(units))).ok_or_else(|| {
            lines.error(
                data_at,
                None,
                format!("cannot find the units (g or cm/sec2) on {}", quote(data_line)),
                "give `unit:` on the source if you know them",
            )
        })?;
    let (values, next) = block(lines, data_at, npts, "acceleration")?;
    Ok(Block { data_at, npts, dt, dt_tolerance: 0.0, time: None, unit, values, next })
}

/// Older Vol.1 (digitised analog records): 13 text lines, 7 lines of integers, 7 of reals, then
/// (time, accel) pairs, 5 to a line, times printed to 1 ms. `NO. OF POINTS =` gives the count.
/// The times must lie on a uniform grid within their print resolution; its step is the dt.
fn time_value_pairs(lines: &Lines<'_>, start: usize) -> Result<Block, ParseError> {
    const HEADER: usize = 13 + 7 + 7;
    let data_at = start + HEADER;
    let count_at = (start..start + 13).find(|&k| lines.get(k).is_some_and(|l| after(l, "NO. OF POINTS =").is_some()));
    let npts = count_at
        .and_then(|k| lines.get(k))
        .and_then(|l| after(l, "NO. OF POINTS ="))
        .and_then(leading_count)
        .ok_or_else(|| {
            lines.error(
                start,
                None,
                "neither a data line ('N Accelerogram points at ...') nor 'NO. OF POINTS =' in this channel's header",
                "the file is truncated or not a CSMIP/DMG record",
            )
        })?;
    if npts < 2 {
        return Err(lines.error(
            count_at.unwrap_or(start),
            None,
            format!("NO. OF POINTS = {npts}: a record needs at least 2"),
            "the header was damaged",
        ));
    }
    let count_at = count_at.unwrap_or(start);
    let unit = (start..data_at).find_map(|k| lines.get(k).and_then(units)).ok_or_else(|| {
        lines.error(
            count_at + 1,
            None,
            "cannot find the units ('UNITS OF UNCOR ACCEL ARE SEC AND G/10')",
            "give `unit:` on the source if you know them",
        )
    })?;
    let first = lines.get(data_at).map_or(0, |l| l.trim_end().len());
    let pairs = npts.saturating_mul(2);
    // The time column gives the sampling: parsed even when counting.
    let (both, next) = if first > 0 && first.is_multiple_of(10) {
        lines.fixed_parsed(count_at, data_at, pairs, 10, first / 10, "(time, accel)")?
    } else {
        lines.free_parsed(count_at, data_at, pairs, "(time, accel)")?
    };
    let time: Vec<f64> = both.iter().step_by(2).copied().collect();
    let values: Vec<f64> = both.iter().skip(1).step_by(2).copied().collect();
    let dt = (time[npts - 1] - time[0]) / (npts - 1) as f64;
    if dt.is_nan() || dt <= 0.0 {
        return Err(lines.error(data_at, None, "the time column does not increase", "the file is damaged"));
    }
    // On a uniform grid within the print resolution: that grid. Otherwise (hand-digitised
    // film) the time column itself, for `load`'s `non_uniform` policy.
    let uniform = time.iter().enumerate().all(|(k, t)| (t - (time[0] + k as f64 * dt)).abs() <= 0.0006);
    let time = (!uniform).then_some(time);
    // `data_at` is the line before the first value, as for a block with a data line.
    Ok(Block { data_at: data_at - 1, npts, dt, dt_tolerance: 0.002 / (npts - 1) as f64, time, unit, values, next })
}

/// The `count` values after the block line `at`: in the Fortran format it states, else 8 to a
/// line in fields as wide as the first line's eighth (older files give no format, and their
/// fields can touch: `-9.643590-13.350390`), else separated by blanks.
fn block(lines: &Lines<'_>, at: usize, count: usize, what: &str) -> Result<(Vec<f64>, usize), ParseError> {
    if let Some((per_line, width)) = lines.get(at).and_then(fortran_format) {
        return lines.fixed(at, at + 1, count, per_line, width, what);
    }
    let first = lines.get(at + 1).map_or(0, |l| l.trim_end().len());
    if count >= 8 && first > 0 && first.is_multiple_of(8) {
        return lines.fixed(at, at + 1, count, 8, first / 8, what);
    }
    lines.free(at, at + 1, count, what)
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
    } else if upper.contains("G/10") {
        Some("g/10".into())
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
