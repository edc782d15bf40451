//! GeoNet (GNS Science, New Zealand) `.V1A` (uncorrected) and `.V2A` (processed) records, three
//! components per file, in mm/s².
//!
//! Per component: 16 text lines (line 13 `Component S16W ...`), 4 lines of 10 integers (I8),
//! 6 lines of 10 reals (F8), then the acceleration, 10 values to a line in 8-character
//! fields. I(34), I(35), I(36) count the acceleration, velocity and displacement values and
//! R(26) is the sampling interval; a V2A follows each acceleration block with its velocity and
//! displacement blocks, which the reader skips.

use super::fixed::{after, compass_azimuth, is_blank, Lines, Values};
use super::{quote, read_bytes, record_text, ParseError, RawChannel, RawRecord};
use std::collections::BTreeMap;
use std::path::Path;

const TEXT_LINES: usize = 16;
const INT_LINES: usize = 4;
const REAL_LINES: usize = 6;

pub fn read_geonet(path: &Path) -> Result<RawRecord, ParseError> {
    parse_geonet(path, &read_bytes(path)?)
}

/// [`read_geonet`] of a file's bytes (read once and hashed by `load`); `path` only names the file in errors.
pub fn parse_geonet(path: &Path, bytes: &[u8]) -> Result<RawRecord, ParseError> {
    geonet(path, bytes, Values::Parse)
}

/// `validate`'s check that the file holds the values its header announces: the reader with
/// its data blocks counted, not parsed.
pub(super) fn count_geonet(path: &Path, bytes: &[u8]) -> Result<(), ParseError> {
    geonet(path, bytes, Values::Count).map(drop)
}

fn geonet(path: &Path, bytes: &[u8], values: Values) -> Result<RawRecord, ParseError> {
    let text = record_text(path, bytes, "a GeoNet V1A/V2A record")?;
    let lines = Lines::new(path, &text, values);
    let mut header = BTreeMap::new();
    let mut channels: Vec<RawChannel> = Vec::new();
    let mut dt: Option<f64> = None;
    let mut i = 0;
    while i < lines.count() {
        if lines.get(i).is_some_and(is_blank) {
            i += 1;
            continue;
        }
        let first = lines.line(i, "a GeoNet component header")?;
        if !first.to_ascii_uppercase().contains("ACCELEROGRAM") {
            return Err(lines.error(
                i,
                Some(1),
                format!("expected a GeoNet component header ('Corrected accelerogram ...'), found {}", quote(first)),
                if channels.is_empty() {
                    "this is not a GeoNet V1A/V2A file".to_string()
                } else {
                    "the previous component holds more values than its header announces".to_string()
                },
            ));
        }
        let text: Vec<&str> =
            (i..i + TEXT_LINES).map(|k| lines.line(k, "the 16-line GeoNet text header")).collect::<Result<_, _>>()?;
        let (ints, _) = lines.fixed_parsed(i + TEXT_LINES, i + TEXT_LINES, 40, 10, 8, "GeoNet integer-header")?;
        let (reals, _) = lines.fixed_parsed(
            i + TEXT_LINES + INT_LINES,
            i + TEXT_LINES + INT_LINES,
            60,
            10,
            8,
            "GeoNet real-header",
        )?;
        let int_line = i + TEXT_LINES + 3;
        let count = |k: usize| -> Result<usize, ParseError> {
            let v = ints[k - 1];
            if v < 0.0 || v.fract() != 0.0 {
                return Err(lines.error(
                    int_line,
                    None,
                    format!("integer {k} ({v}) is not a point count"),
                    "the header was damaged",
                ));
            }
            Ok(v as usize)
        };
        let (n_acc, n_vel, n_disp) = (count(34)?, count(35)?, count(36)?);
        let step = reals[25];
        if step.is_nan() || step <= 0.0 {
            return Err(lines.error(
                i + TEXT_LINES + INT_LINES + 2,
                None,
                format!("the sampling interval (real 26) is {step}"),
                "GeoNet headers give the interval in seconds in real 26",
            ));
        }
        if let Some(first_dt) = dt.filter(|d| *d != step) {
            return Err(lines.error(
                i,
                None,
                format!("this component is sampled every {step} s, the first every {first_dt} s"),
                "read each component with its own source",
            ));
        }
        dt = Some(step);
        let data_start = i + TEXT_LINES + INT_LINES + REAL_LINES;
        let (values, mut next) = lines.fixed(int_line, data_start, n_acc, 10, 8, "acceleration")?;
        let corrected = !first.to_ascii_uppercase().contains("UNCORRECTED");
        if corrected {
            next = lines.fixed(int_line, next, n_vel, 10, 8, "velocity")?.1;
            next = lines.fixed(int_line, next, n_disp, 10, 8, "displacement")?.1;
        }

        let component =
            after(text[12], "Component").and_then(|c| c.split_whitespace().next()).unwrap_or("").to_string();
        let mut name = if component.is_empty() { format!("comp{}", channels.len() + 1) } else { component.clone() };
        if channels.iter().any(|c| c.name == name) {
            name = format!("{name}_{}", channels.len() + 1);
        }
        let orientation = match component.to_ascii_uppercase().as_str() {
            "UP" => "up".to_string(),
            "DOWN" => "down".to_string(),
            c => compass_azimuth(c).map_or("unknown".to_string(), |a| format!("{a}")),
        };
        let mut put = |k: String, v: &str| {
            if !v.trim().is_empty() {
                header.insert(k, v.trim().to_string());
            }
        };
        put(format!("channel.{name}.orientation"), &orientation);
        put(format!("channel.{name}.label"), text[12]);
        put(format!("channel.{name}.npts"), &n_acc.to_string());
        if let Some(peak) = after(text[13], "peak").and_then(|p| p.split_whitespace().next()) {
            put(format!("channel.{name}.peak"), peak);
        }
        if channels.is_empty() {
            put("process_level".into(), if corrected { "V2" } else { "V1" });
            put("record_type".into(), text[0]);
            put("station".into(), text[1].split_whitespace().nth(1).unwrap_or(""));
            put("site".into(), text[1]);
            put("station_name".into(), text[2]);
            put("instrument".into(), text[3]);
            put("event".into(), text[6]);
            put("event_date".into(), text[7]);
            put("epicentre".into(), text[8]);
            put("units".into(), "mm/s^2");
            put("dt_s".into(), &step.to_string());
            put("network".into(), "GeoNet");
        }
        channels.push(RawChannel { name, unit: "mm/s^2".into(), values, first_data_line: Some(data_start + 1) });
        i = next;
    }
    header.insert("channels".into(), channels.len().to_string());
    Ok(RawRecord { format: "geonet", dt, time: None, channels, header })
}
