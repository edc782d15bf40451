//! ESM (Engineering Strong-Motion database, ORFEUS) ASCII records: one component per file.
//!
//! `KEY: value` header lines (64 in the DYNA 1.2 header: `NDATA`, `SAMPLING_INTERVAL_S`,
//! `UNITS`, `STREAM`, `PGA_CM/S^2`, ...), then the values, one or more to a line. Every header
//! key is kept (lower-cased); the AFAD-derived files' other date layouts are kept as written.

use super::fixed::{is_blank, Lines, Values};
use super::{quote, read_bytes, record_text, ParseError, RawChannel, RawRecord};
use std::collections::BTreeMap;
use std::path::Path;

pub fn read_esm(path: &Path) -> Result<RawRecord, ParseError> {
    parse_esm(path, &read_bytes(path)?)
}

/// [`read_esm`] of a file's bytes (read once and hashed by `load`); `path` only names the file in errors.
pub fn parse_esm(path: &Path, bytes: &[u8]) -> Result<RawRecord, ParseError> {
    esm(path, bytes, Values::Parse)
}

/// `validate`'s check that the file holds the values its header announces: the reader with
/// its data blocks counted, not parsed.
pub(super) fn count_esm(path: &Path, bytes: &[u8]) -> Result<(), ParseError> {
    esm(path, bytes, Values::Count).map(drop)
}

fn esm(path: &Path, bytes: &[u8], values: Values) -> Result<RawRecord, ParseError> {
    let text = record_text(path, bytes, "an ESM ASCII record (KEY: value header lines, then values)")?;
    let lines = Lines::new(path, &text, values);
    let mut keys: BTreeMap<String, (String, usize)> = BTreeMap::new();
    let mut k = 0;
    while let Some(line) = lines.get(k) {
        let Some((key, value)) = line.split_once(':') else { break };
        let key = key.trim();
        if key.is_empty() || key.contains(' ') || key.parse::<f64>().is_ok() {
            break;
        }
        keys.insert(key.to_ascii_uppercase(), (value.trim().to_string(), k));
        k += 1;
    }
    let data_start = k;
    let get = |key: &str| -> Result<(&str, usize), ParseError> {
        keys.get(key).map(|(v, k)| (v.as_str(), *k)).filter(|(v, _)| !v.is_empty()).ok_or_else(|| {
            lines.error(
                data_start.saturating_sub(1),
                None,
                format!("the ESM header has no {key}"),
                "ESM headers state NDATA, SAMPLING_INTERVAL_S and UNITS; this file is damaged or not an ESM record",
            )
        })
    };
    let (ndata, ndata_line) = get("NDATA")?;
    let npts: usize = ndata.parse().ok().filter(|n| *n > 0).ok_or_else(|| {
        lines.error(
            ndata_line,
            Some(8),
            format!("cannot read NDATA '{ndata}' as a positive whole number"),
            "the header line was damaged",
        )
    })?;
    let (interval, dt_line) = get("SAMPLING_INTERVAL_S")?;
    let dt: f64 = interval.parse().ok().filter(|v: &f64| v.is_finite() && *v > 0.0).ok_or_else(|| {
        lines.error(
            dt_line,
            Some(21),
            format!("cannot read SAMPLING_INTERVAL_S '{interval}' as a positive time step"),
            "the header line was damaged",
        )
    })?;
    let (units, units_line) = get("UNITS")?;
    let unit = match units.to_ascii_lowercase().replace(' ', "").as_str() {
        "cm/s^2" | "cm/s2" | "cm/s/s" | "gal" => "cm/s^2",
        "cm/s" => "cm/s",
        "cm" => "cm",
        "m/s^2" | "m/s2" => "m/s^2",
        "g" => "g",
        _ => {
            return Err(lines.error(
                units_line,
                Some(8),
                format!("unknown ESM units '{units}'"),
                "ESM records come in cm/s^2, cm/s or cm; give `unit:` on the source if this one is known",
            ))
        }
    };
    if lines.get(data_start).is_none() {
        return Err(lines.error(
            data_start.saturating_sub(1),
            None,
            format!("no data after the header (NDATA = {npts})"),
            "the file was cut short",
        ));
    }
    if let Some(line) = lines.get(data_start).filter(|l| l.contains(':')) {
        return Err(lines.error(
            data_start,
            None,
            format!("cannot read this header line: {}", quote(line)),
            "ESM header lines are KEY: value, with no blank in KEY",
        ));
    }
    let (values, next) = lines.free(ndata_line, data_start, npts, "acceleration")?;
    if let Some(k) = (next..lines.count()).find(|&k| lines.get(k).is_some_and(|l| !is_blank(l))) {
        return Err(lines.error(
            k,
            None,
            format!("more values than NDATA = {npts} (line {})", ndata_line + 1),
            "NDATA is wrong or two records were joined",
        ));
    }

    let mut header: BTreeMap<String, String> = keys
        .iter()
        .filter(|(_, (v, _))| !v.is_empty())
        .map(|(k, (v, _))| (k.to_ascii_lowercase(), v.clone()))
        .collect();
    let stream = keys.get("STREAM").map_or("", |(v, _)| v.as_str()).to_string();
    let name = if stream.is_empty() { "accel".to_string() } else { stream.clone() };
    let orientation = match stream.chars().last() {
        Some('E') => "90",
        Some('N') => "0",
        Some('Z') => "up",
        _ => "unknown",
    };
    header.insert("station".into(), keys.get("STATION_CODE").map_or("", |(v, _)| v.as_str()).to_string());
    header.insert("npts".into(), npts.to_string());
    header.insert("dt_s".into(), dt.to_string());
    header.insert(format!("channel.{name}.orientation"), orientation.into());
    header.insert(format!("channel.{name}.label"), stream);
    if let Some((pga, _)) = keys.get("PGA_CM/S^2") {
        header.insert(format!("channel.{name}.peak"), pga.clone());
    }
    Ok(RawRecord {
        format: "esm",
        dt: Some(dt),
        time: None,
        channels: vec![RawChannel { name, unit: unit.into(), values, first_data_line: Some(data_start + 1) }],
        header,
    })
}
