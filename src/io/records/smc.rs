//! USGS SMC (strong-motion CD) records: one component per file, in cm/s².
//!
//! 11 text lines (line 1 starts with the type: 1 uncorrected, 2 corrected accelerogram), 48
//! integers (8I10), 50 reals (5E15.7), I(16) comment lines starting `|`, then I(17) values
//! in 10-character fields that touch (`1.5057E+0-2.2223E+0`), 8 to a line. R(2) is the
//! sampling rate. Integer I(1) and real R(1) hold the file's "unknown" markers.

use super::fixed::{after, is_blank, Lines, Values};
use super::{quote, read_bytes, record_text, ParseError, RawChannel, RawRecord};
use std::collections::BTreeMap;
use std::path::Path;

const TEXT_LINES: usize = 11;
const INT_LINES: usize = 6;
const REAL_LINES: usize = 10;

pub fn read_smc(path: &Path) -> Result<RawRecord, ParseError> {
    parse_smc(path, &read_bytes(path)?)
}

/// [`read_smc`] of a file's bytes (read once and hashed by `load`); `path` only names the file in errors.
pub fn parse_smc(path: &Path, bytes: &[u8]) -> Result<RawRecord, ParseError> {
    smc(path, bytes, Values::Parse)
}

/// `validate`'s check that the file holds the values its header announces: the reader with
/// its data blocks counted, not parsed.
pub(super) fn count_smc(path: &Path, bytes: &[u8]) -> Result<(), ParseError> {
    smc(path, bytes, Values::Count).map(drop)
}

fn smc(path: &Path, bytes: &[u8], values: Values) -> Result<RawRecord, ParseError> {
    let text = record_text(path, bytes, "a USGS SMC record")?;
    let lines = Lines::new(path, &text, values);
    let head: Vec<&str> =
        (0..TEXT_LINES).map(|k| lines.line(k, "the 11-line SMC text header")).collect::<Result<_, _>>()?;
    let kind = head[0].trim();
    let level = match kind.split_whitespace().next() {
        Some("1") => "V1",
        Some("2") => "V2",
        _ => {
            return Err(lines.error(
                0,
                Some(1),
                format!(
                "expected an SMC record type ('1 UNCORRECTED ACCELEROGRAM' or '2 CORRECTED ACCELEROGRAM'), found {}",
                quote(head[0])
            ),
                "SMC velocity and displacement files, and files without a type, are not accelerograms",
            ))
        }
    };
    if !kind.to_ascii_uppercase().contains("ACCELEROGRAM") {
        return Err(lines.error(
            0,
            None,
            format!("this SMC file is not an accelerogram: {}", quote(head[0])),
            "only SMC accelerograms are read",
        ));
    }
    let (ints, _) = lines.fixed_parsed(TEXT_LINES, TEXT_LINES, 48, 8, 10, "SMC integer-header")?;
    let (reals, _) =
        lines.fixed_parsed(TEXT_LINES + INT_LINES, TEXT_LINES + INT_LINES, 50, 5, 15, "SMC real-header")?;
    let int = |k: usize| Some(ints[k - 1]).filter(|v| *v != ints[0]);
    let real = |k: usize| Some(reals[k - 1]).filter(|v| *v != reals[0]);
    let int_line = |k: usize| TEXT_LINES + (k - 1) / 8;

    let n_comments = int(16).filter(|v| *v >= 0.0).ok_or_else(|| {
        lines.error(
            int_line(16),
            None,
            "the integer header gives no comment-line count (value 16)",
            "SMC files state their comment lines in I(16)",
        )
    })? as usize;
    let npts = int(17).filter(|v| *v > 0.0).ok_or_else(|| {
        lines.error(
            int_line(17),
            None,
            "the integer header gives no point count (value 17)",
            "SMC files state their number of points in I(17)",
        )
    })? as usize;
    let rate = real(2).filter(|v| *v > 0.0 && *v < 1e6).ok_or_else(|| {
        lines.error(
            TEXT_LINES + INT_LINES,
            None,
            "the real header gives no sampling rate (value 2, samples per second)",
            "SMC files state their sampling rate in R(2)",
        )
    })?;
    let data_start = TEXT_LINES + INT_LINES + REAL_LINES + n_comments;
    lines.check_room(int_line(16), TEXT_LINES + INT_LINES + REAL_LINES, n_comments, 1, "comment lines")?;
    for k in TEXT_LINES + INT_LINES + REAL_LINES..data_start {
        let line = lines.line(k, "the SMC comment lines")?;
        if !line.starts_with('|') {
            return Err(lines.error(
                k,
                Some(1),
                format!(
                    "expected comment line {} of {n_comments} (starting with '|'), found {}",
                    k + 1 - TEXT_LINES - INT_LINES - REAL_LINES,
                    quote(line)
                ),
                format!("the comment count on line {} (integer 16) is wrong", int_line(16) + 1),
            ));
        }
    }
    let (values, next) = lines.fixed(int_line(17), data_start, npts, 8, 10, "acceleration")?;
    if let Some(k) = (next..lines.count()).find(|&k| lines.get(k).is_some_and(|l| !is_blank(l))) {
        return Err(lines.error(
            k,
            None,
            format!("more data after the {npts} values that integer 17 announces"),
            "the point count is wrong or two records were joined",
        ));
    }

    let mut header = BTreeMap::new();
    let mut put = |k: &str, v: &str| {
        if !v.trim().is_empty() {
            header.insert(k.to_string(), v.trim().to_string());
        }
    };
    put("process_level", level);
    put("record_type", kind);
    put("station", head[2].get(..4).unwrap_or(head[2]));
    put("event", head[3]);
    put("magnitudes", head[4]);
    put("station_name", after(head[5], "station =").map_or("", |s| s.split("component").next().unwrap_or(s)));
    let component = after(head[5], "component=").unwrap_or("").to_string();
    put("component", &component);
    put("instrument", head[7].split("data source").next().unwrap_or(""));
    put("data_source", after(head[7], "data source =").unwrap_or(""));
    // `pk     =    104.4` or `pk mot = 3.534E+1`.
    let peak = after(head[6], "pk").and_then(|rest| rest.split_once('=')).map(|(_, v)| v.trim());
    put("npts", &npts.to_string());
    put("dt_s", &(1.0 / rate).to_string());
    put("units", "cm/s^2");
    for (key, k) in [("station_latitude", 11), ("station_longitude", 12), ("station_elevation_m", 13)] {
        if let Some(v) = real(k) {
            put(key, &v.to_string());
        }
    }

    // I(13) is the sensor's angle from the vertical (0 or 180: vertical), I(14) its azimuth.
    let orientation = match (int(13), int(14)) {
        (Some(v), _) if v == 0.0 || v == 180.0 => {
            if v == 0.0 {
                "up".to_string()
            } else {
                "down".to_string()
            }
        }
        (_, Some(a)) if (0.0..=360.0).contains(&a) => format!("{a}"),
        _ => "unknown".to_string(),
    };
    let name = if component.is_empty() { "accel".to_string() } else { component.clone() };
    put(&format!("channel.{name}.orientation"), &orientation);
    put(&format!("channel.{name}.label"), &component);
    if let Some(p) = peak {
        put(&format!("channel.{name}.peak"), p.split_whitespace().next().unwrap_or(""));
    }
    Ok(RawRecord {
        format: "smc",
        dt: Some(1.0 / rate),
        time: None,
        channels: vec![RawChannel { name, unit: "cm/s^2".into(), values, first_data_line: Some(data_start + 1) }],
        header,
    })
}
