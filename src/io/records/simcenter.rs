//! SimCenter event JSON (as in NHERI-SimCenter R2D/EE-UQ record folders):
//! `{"dT": 0.005, "data_x": [...], "data_y": [...], "PGA_x": ..., "name": ...}`,
//! values in g by convention.

use super::{char_column, read_bytes, record_text, ParseError, RawChannel, RawRecord};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

const KEYS: [&str; 8] = ["dT", "data_x", "data_y", "data_z", "PGA_x", "PGA_y", "PGA_z", "name"];
const LAYOUT: &str = "a SimCenter record is one object like {\"dT\": 0.005, \"data_x\": [...], \"data_y\": [...]}";

#[derive(Deserialize)]
struct Event {
    #[serde(rename = "dT")]
    dt: Option<f64>,
    data_x: Option<Vec<f64>>,
    data_y: Option<Vec<f64>>,
    data_z: Option<Vec<f64>>,
    #[serde(rename = "PGA_x")]
    pga_x: Option<f64>,
    #[serde(rename = "PGA_y")]
    pga_y: Option<f64>,
    #[serde(rename = "PGA_z")]
    pga_z: Option<f64>,
    // Any JSON value: a numeric name must not make the record unreadable.
    name: Option<serde_json::Value>,
}

pub fn read_simcenter_json(path: &Path) -> Result<RawRecord, ParseError> {
    parse_simcenter_json(path, &read_bytes(path)?)
}

/// [`read_simcenter_json`] of a file's bytes; `path` only names the file in errors.
pub fn parse_simcenter_json(path: &Path, bytes: &[u8]) -> Result<RawRecord, ParseError> {
    let text = record_text(path, bytes, LAYOUT)?;
    let event: Event = serde_json::from_str(&text).map_err(|e| json_error(path, &text, &e))?;

    let Some(dt) = event.dt else {
        return Err(ParseError::new(
            path,
            None,
            None,
            "no \"dT\" (time step in seconds) in the JSON object",
            format!("{LAYOUT}; {}", keys_present(&text)),
        ));
    };
    if !(dt.is_finite() && dt > 0.0) {
        return Err(ParseError::new(
            path,
            None,
            None,
            format!("\"dT\" is {dt}, not a positive time step in seconds"),
            LAYOUT,
        ));
    }

    let mut header = BTreeMap::new();
    header.insert("dt".to_string(), dt.to_string());
    header.insert("units".to_string(), "g (SimCenter convention; not stated in the file)".to_string());
    match &event.name {
        Some(serde_json::Value::String(s)) => {
            header.insert("name".to_string(), s.clone());
        }
        Some(other) => {
            header.insert("name".to_string(), other.to_string());
        }
        None => {}
    }
    for (key, pga) in [("PGA_x", event.pga_x), ("PGA_y", event.pga_y), ("PGA_z", event.pga_z)] {
        if let Some(v) = pga {
            header.insert(key.to_string(), v.to_string());
        }
    }

    let mut channels = Vec::new();
    for (name, data) in [("x", event.data_x), ("y", event.data_y), ("z", event.data_z)] {
        let Some(values) = data else { continue };
        if values.is_empty() {
            return Err(ParseError::new(
                path,
                None,
                None,
                format!("\"data_{name}\" is an empty array"),
                "the record holds no samples for this component; the export probably failed",
            ));
        }
        header.insert(format!("npts_{name}"), values.len().to_string());
        channels.push(RawChannel { name: name.to_string(), unit: "g".to_string(), values, first_data_line: None });
    }
    if channels.is_empty() {
        return Err(ParseError::new(
            path,
            None,
            None,
            "no \"data_x\", \"data_y\" or \"data_z\" array in the JSON object",
            format!("{LAYOUT}; {}", keys_present(&text)),
        ));
    }
    if let Some(other) = channels.iter().find(|c| c.values.len() != channels[0].values.len()) {
        let first = &channels[0];
        let key = format!("\"data_{}\"", other.name);
        let line = text.find(&key).map(|at| text[..at].matches('\n').count() + 1);
        return Err(ParseError::new(
            path,
            line,
            None,
            format!(
                "\"data_{}\" has {} samples but \"data_{}\" has {}",
                other.name,
                other.values.len(),
                first.name,
                first.values.len()
            ),
            "the components of one record share one time base; the file is damaged or was edited: get a fresh copy",
        ));
    }
    Ok(RawRecord { format: "simcenter_json", dt: Some(dt), time: None, channels, header })
}

/// The top-level keys, to show what the file holds instead (e.g. "dt" for "dT").
fn keys_present(text: &str) -> String {
    match serde_json::from_str::<serde_json::Map<String, serde_json::Value>>(text) {
        Ok(map) if map.is_empty() => "the object is empty".to_string(),
        Ok(map) => {
            let keys: Vec<String> = map.keys().map(|k| format!("\"{k}\"")).collect();
            format!("this file has the keys {} (keys are case-sensitive)", keys.join(", "))
        }
        Err(_) => "the top-level value is not an object".to_string(),
    }
}

fn json_error(path: &Path, text: &str, e: &serde_json::Error) -> ParseError {
    use serde_json::error::Category;
    // serde_json counts columns in bytes; report characters.
    let line_text = text.split('\n').nth(e.line().saturating_sub(1)).unwrap_or("");
    let col = (e.column() > 0).then(|| char_column(line_text, e.column() - 1));
    let line = (e.line() > 0).then_some(e.line());
    // serde_json's Display appends " at line L column C", which we print ourselves.
    let full = e.to_string();
    let bare = full.split(" at line ").next().unwrap_or(&full).to_string();
    let (message, hint) = match e.classify() {
        Category::Eof => (
            format!("the JSON ends early: {bare}"),
            "the file looks truncated (an unclosed array or object); get a fresh copy".to_string(),
        ),
        Category::Syntax => {
            let at = line_text.get(e.column().saturating_sub(1)..).unwrap_or("").trim_start();
            let hint = if ["NaN", "Infinity", "-Infinity"].iter().any(|w| at.starts_with(w)) {
                "NaN and Infinity are not valid JSON (Python's json.dump writes them); replace them or fix the source"
                    .to_string()
            } else {
                format!("invalid JSON syntax near {}", super::quote(at))
            };
            (format!("JSON syntax error: {bare}"), hint)
        }
        Category::Data => {
            let offset = byte_offset(text, e.line(), e.column());
            let place = locate(text, offset);
            (
                format!("{place}: {bare}"),
                "data arrays hold only numbers (null usually means a NaN was exported); \"dT\" and \"PGA_*\" are numbers"
                    .to_string(),
            )
        }
        Category::Io => (format!("cannot read the JSON: {bare}"), "check the file".to_string()),
    };
    ParseError::new(path, line, col, message, hint)
}

fn byte_offset(text: &str, line: usize, column: usize) -> usize {
    let start: usize = text.split('\n').take(line.saturating_sub(1)).map(|l| l.len() + 1).sum();
    (start + column).min(text.len())
}

/// Which key (and array index) the byte `offset` falls in, e.g. "data_x[17]",
/// found from the last known key before it. Commas inside strings could skew
/// the index, but data arrays hold only numbers.
fn locate(text: &str, offset: usize) -> String {
    let before = text.get(..offset).unwrap_or(text);
    let found = KEYS.iter().filter_map(|k| before.rfind(&format!("\"{k}\"")).map(|i| (i, *k))).max();
    let Some((at, key)) = found else {
        return "the top-level value".to_string();
    };
    let value = before[at + key.len() + 2..].trim_start().trim_start_matches(':').trim_start();
    if let Some(items) = value.strip_prefix('[') {
        let index = items.bytes().filter(|&b| b == b',').count();
        format!("\"{key}\"[{index}]")
    } else {
        format!("\"{key}\"")
    }
}
