//! NIED K-NET and KiK-net ASCII records: one component per file (`.EW` `.NS` `.UD`; KiK-net
//! `.EW1` borehole, `.EW2` surface).
//!
//! 17 header lines `key value` (the value starts at column 19), then integer counts, 8 to a
//! line. Acceleration in gal = count × the `Scale Factor` (`7845(gal)/8223790`); the reader
//! applies it, as gmprocess does, so the channel's unit is gal. The counts keep the logger's
//! DC offset (the header's `Max. Acc.` is measured after removing the mean): that is left to a
//! baseline step. The number of values must be `Duration Time(s)` × `Sampling Freq(Hz)`.

use super::fixed::{is_blank, Lines, Values};
use super::{char_column, quote, read_bytes, record_text, ParseError, RawChannel, RawRecord};
use std::collections::BTreeMap;
use std::path::Path;

const HEADER_LINES: usize = 17;
const KEYS: [(&str, &str); HEADER_LINES] = [
    ("Origin Time", "origin_time"),
    ("Lat.", "event_latitude"),
    ("Long.", "event_longitude"),
    ("Depth. (km)", "event_depth_km"),
    ("Mag.", "magnitude"),
    ("Station Code", "station"),
    ("Station Lat.", "station_latitude"),
    ("Station Long.", "station_longitude"),
    ("Station Height(m)", "station_height_m"),
    ("Record Time", "record_start"),
    ("Sampling Freq(Hz)", "sampling_hz"),
    ("Duration Time(s)", "duration_s"),
    ("Dir.", "direction"),
    ("Scale Factor", "scale_factor"),
    ("Max. Acc. (gal)", "peak_gal"),
    ("Last Correction", "last_correction"),
    ("Memo.", "memo"),
];

pub fn read_knet(path: &Path) -> Result<RawRecord, ParseError> {
    parse_knet(path, &read_bytes(path)?)
}

/// [`read_knet`] of a file's bytes (read once and hashed by `load`); `path` only names the file in errors.
pub fn parse_knet(path: &Path, bytes: &[u8]) -> Result<RawRecord, ParseError> {
    knet(path, bytes, Values::Parse)
}

/// `validate`'s check that the file holds the values its header announces: the reader with
/// its data blocks counted, not parsed.
pub(super) fn count_knet(path: &Path, bytes: &[u8]) -> Result<(), ParseError> {
    knet(path, bytes, Values::Count).map(drop)
}

fn knet(path: &Path, bytes: &[u8], values: Values) -> Result<RawRecord, ParseError> {
    let text = record_text(path, bytes, "a K-NET/KiK-net ASCII record (17 header lines, then counts)")?;
    let lines = Lines::new(path, &text, values);
    let mut header = BTreeMap::new();
    for (k, (key, name)) in KEYS.iter().enumerate() {
        let line = lines.line(k, "the 17-line K-NET header")?;
        if !line.starts_with(key) {
            return Err(lines.error(
                k,
                Some(1),
                format!("expected the K-NET header line '{key} ...', found {}", quote(line)),
                "K-NET/KiK-net ASCII files start with 17 lines in a fixed order (Origin Time, Lat., ..., Memo.)",
            ));
        }
        let value = line.get(18..).unwrap_or("").trim();
        if !value.is_empty() {
            header.insert(name.to_string(), value.to_string());
        }
    }
    let value_of = |k: usize| lines.get(k).and_then(|l| l.get(18..)).unwrap_or("").trim();
    let number = |k: usize, text: &str| -> Result<f64, ParseError> {
        text.parse::<f64>().ok().filter(|v| v.is_finite() && *v > 0.0).ok_or_else(|| {
            lines.error(
                k,
                Some(19),
                format!("cannot read '{text}' as a positive number ({})", KEYS[k].0),
                "the header line was damaged",
            )
        })
    };
    let rate = number(10, value_of(10).trim_end_matches("Hz").trim())?;
    let duration = number(11, value_of(11))?;
    let scale_text = value_of(13);
    let scale = scale_text
        .split_once("(gal)/")
        .and_then(|(num, den)| Some((num.trim().parse::<f64>().ok()?, den.trim().parse::<f64>().ok()?)))
        .filter(|(n, d)| n.is_finite() && d.is_finite() && *d != 0.0)
        .map(|(n, d)| n / d)
        .ok_or_else(|| {
            lines.error(
                13,
                Some(19),
                format!("cannot read the scale factor '{scale_text}'"),
                "K-NET scale factors read like 7845(gal)/8223790",
            )
        })?;
    let expected = duration * rate;
    if expected.fract() != 0.0 || expected > usize::MAX as f64 {
        return Err(lines.error(
            11,
            Some(19),
            format!("duration {duration} s at {rate} Hz is not a whole number of samples"),
            "the header was damaged",
        ));
    }
    let npts = expected as usize;
    let (mut values, next) = lines.free(11, HEADER_LINES, npts, "count")?;
    if let Some((k, line)) =
        (next..lines.count()).filter_map(|k| lines.get(k).map(|l| (k, l))).find(|(_, l)| !is_blank(l))
    {
        let token = line.split_ascii_whitespace().next().unwrap_or("");
        return Err(lines.error(
            k,
            Some(char_column(line, line.find(token).unwrap_or(0))),
            format!("more values than the {npts} that duration × sampling rate ({duration} s × {rate} Hz) give"),
            "the duration on line 12 is wrong, or two records were joined",
        ));
    }
    for v in &mut values {
        *v *= scale;
    }

    let direction = value_of(12);
    let kik_net = matches!(direction, "1" | "2" | "3" | "4" | "5" | "6");
    let (name, orientation) = match direction {
        "E-W" | "5" | "2" => ("EW", "90"),
        "N-S" | "4" | "1" => ("NS", "0"),
        "U-D" | "6" | "3" => ("UD", "up"),
        _ => ("accel", "unknown"),
    };
    header.insert("network".into(), if kik_net { "KiK-net" } else { "K-NET" }.into());
    if kik_net {
        let sensor = if matches!(direction, "1" | "2" | "3") { "borehole" } else { "surface" };
        header.insert("sensor".into(), sensor.into());
    }
    header.insert("process_level".into(), "V1".into());
    header.insert("npts".into(), npts.to_string());
    header.insert("dt_s".into(), (1.0 / rate).to_string());
    header.insert("units".into(), "gal (counts × scale factor)".into());
    header.insert("scale_gal_per_count".into(), scale.to_string());
    header.insert(format!("channel.{name}.orientation"), orientation.into());
    header.insert(format!("channel.{name}.label"), direction.into());
    if let Some(peak) = header.get("peak_gal").cloned() {
        header.insert(format!("channel.{name}.peak"), peak);
    }
    Ok(RawRecord {
        format: "knet",
        dt: Some(1.0 / rate),
        time: None,
        channels: vec![RawChannel {
            name: name.into(),
            unit: "gal".into(),
            values,
            first_data_line: Some(HEADER_LINES + 1),
        }],
        header,
    })
}
