//! Channels by role: which of a record's channels is `x`, `y` or `z`, from the orientation its
//! header states (`channel.<name>.orientation`: an azimuth in degrees, `up`, `down`,
//! `vertical` or `unknown`) or, for formats that give only a label (PEER AT2's `180`,
//! `090 (CUE)`, `UP`, `HNE`), from the label.
//!
//! The frame is east–north–up: the vertical is `z`; of two horizontals, the one nearer east–west
//! is `x` and the other `y` (the first in the file is `x` when they are equally near). Values
//! are not rotated nor sign-flipped: the stated azimuth goes with them in the metadata. A
//! record with a single horizontal gives it as `x`, or as the axis asked for.

use super::fixed::compass_azimuth;
use super::{RawChannel, RawRecord};

/// Where a channel points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Orientation {
    Vertical,
    /// Degrees clockwise from north.
    Azimuth(f64),
    /// Horizontal (or assumed so) with no stated azimuth.
    Horizontal,
}

/// A channel's orientation: the header's, else read from its name.
pub fn orientation(raw: &RawRecord, channel: &RawChannel) -> Orientation {
    match raw.header.get(&format!("channel.{}.orientation", channel.name)).map(String::as_str) {
        Some("up" | "down" | "vertical") => Orientation::Vertical,
        Some(a) => a.parse::<f64>().map_or(Orientation::Horizontal, Orientation::Azimuth),
        None => from_label(&channel.name),
    }
}

/// `180`, `090 (CUE)`, `360` → azimuth; `UP`, `UD`, `U-D`, `V`, `VERT`, `DWN`, `HNZ` → vertical;
/// `HNE`/`EW`/`E-W` → 90, `HNN`/`NS`/`N-S` → 0, `N10E` → 10; anything else horizontal.
pub fn from_label(label: &str) -> Orientation {
    let upper = label.trim().to_ascii_uppercase();
    let word = upper.split(|c: char| c.is_whitespace() || c == '(').next().unwrap_or("");
    if let Ok(a) = word.parse::<f64>() {
        if (0.0..=360.0).contains(&a) {
            return Orientation::Azimuth(a);
        }
    }
    match word {
        "UD" | "U-D" => return Orientation::Vertical,
        "EW" | "E-W" => return Orientation::Azimuth(90.0),
        "NS" | "N-S" => return Orientation::Azimuth(0.0),
        _ => {}
    }
    let last = word.rsplit(['-', '_', '.']).next().unwrap_or(word);
    match last {
        "UP" | "UD" | "V" | "VER" | "VERT" | "VERTICAL" | "DWN" | "DOWN" | "DN" | "Z" => return Orientation::Vertical,
        "EW" | "E" => return Orientation::Azimuth(90.0),
        "NS" | "N" => return Orientation::Azimuth(0.0),
        _ => {}
    }
    if word.len() == 3 && word.chars().all(|c| c.is_ascii_alphanumeric()) {
        match word.as_bytes()[2] {
            b'Z' => return Orientation::Vertical,
            b'E' => return Orientation::Azimuth(90.0),
            b'N' => return Orientation::Azimuth(0.0),
            _ => {}
        }
    }
    compass_azimuth(word).map_or(Orientation::Horizontal, Orientation::Azimuth)
}

/// Why a record's channels have no unambiguous axes: the channels at fault, by name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AxesError {
    #[error("the record has {} vertical channels ({}): only one can be `z`", .0.len(), .0.join(", "))]
    Verticals(Vec<String>),
    #[error("the record has {} horizontal channels ({}): only two can be `x` and `y`", .0.len(), .0.join(", "))]
    Horizontals(Vec<String>),
}

/// The axis (`'x'`, `'y'`, `'z'`) of each channel, in order. `single` is the axis a lone
/// horizontal takes (default `'x'`).
pub fn axes(raw: &RawRecord, channels: &[&RawChannel], single: Option<char>) -> Result<Vec<char>, AxesError> {
    let orientations: Vec<Orientation> = channels.iter().map(|c| orientation(raw, c)).collect();
    let verticals: Vec<String> = channels
        .iter()
        .zip(&orientations)
        .filter(|(_, o)| **o == Orientation::Vertical)
        .map(|(c, _)| c.name.clone())
        .collect();
    if verticals.len() > 1 {
        return Err(AxesError::Verticals(verticals));
    }
    let horizontals: Vec<usize> = (0..channels.len()).filter(|&k| orientations[k] != Orientation::Vertical).collect();
    let mut axes = vec!['z'; channels.len()];
    match horizontals.as_slice() {
        [] => {}
        [only] => axes[*only] = single.unwrap_or('x'),
        [a, b] => {
            // Nearness to east–west: |sin(azimuth)|; unknown azimuths keep the file's order.
            let east = |k: usize| match orientations[k] {
                Orientation::Azimuth(az) => Some(az.to_radians().sin().abs()),
                _ => None,
            };
            let (x, y) = match (east(*a), east(*b)) {
                (Some(ea), Some(eb)) if eb > ea => (*b, *a),
                _ => (*a, *b),
            };
            axes[x] = 'x';
            axes[y] = 'y';
        }
        more => {
            return Err(AxesError::Horizontals(more.iter().map(|&k| channels[k].name.clone()).collect()));
        }
    }
    Ok(axes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    fn record(channels: &[(&str, Option<&str>)]) -> RawRecord {
        let mut header = BTreeMap::new();
        for (name, o) in channels {
            if let Some(o) = o {
                header.insert(format!("channel.{name}.orientation"), o.to_string());
            }
        }
        RawRecord {
            format: "test",
            dt: Some(0.01),
            time: None,
            channels: channels
                .iter()
                .map(|(name, _)| RawChannel {
                    name: name.to_string(),
                    unit: "g".into(),
                    values: vec![0.0; 2],
                    first_data_line: None,
                })
                .collect(),
            header,
        }
    }

    fn axes_of(raw: &RawRecord, single: Option<char>) -> Result<String, AxesError> {
        let channels: Vec<&RawChannel> = raw.channels.iter().collect();
        axes(raw, &channels, single).map(|a| a.into_iter().collect())
    }

    /// The messages users read, as they were when these errors were strings.
    #[test]
    fn axes_errors_name_the_channels_at_fault() {
        let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect();
        assert_eq!(
            AxesError::Verticals(names(&["UP", "HNZ"])).to_string(),
            "the record has 2 vertical channels (UP, HNZ): only one can be `z`"
        );
        assert_eq!(
            AxesError::Horizontals(names(&["a", "b", "c"])).to_string(),
            "the record has 3 horizontal channels (a, b, c): only two can be `x` and `y`"
        );
    }

    #[test]
    fn labels_give_orientations() {
        assert_eq!(from_label("180"), Orientation::Azimuth(180.0));
        assert_eq!(from_label("090 (CUE)"), Orientation::Azimuth(90.0));
        assert_eq!(from_label("UP"), Orientation::Vertical);
        assert_eq!(from_label("HNZ"), Orientation::Vertical);
        assert_eq!(from_label("BHE"), Orientation::Azimuth(90.0));
        assert_eq!(from_label("BH1"), Orientation::Horizontal);
        assert_eq!(from_label("E-W"), Orientation::Azimuth(90.0));
        assert_eq!(from_label("TCU078-E"), Orientation::Azimuth(90.0));
        assert_eq!(from_label("N10E"), Orientation::Azimuth(10.0));
    }

    #[test]
    fn three_components_map_to_east_north_up() {
        // CSMIP order: 360, Up, 90.
        let raw = record(&[("chan1", Some("360")), ("chan2", Some("up")), ("chan3", Some("90"))]);
        assert_eq!(axes_of(&raw, None).unwrap(), "yzx");
        // GeoNet: S16W (196), S74E (106), Up: S74E is nearer east-west.
        let raw = record(&[("S16W", Some("196")), ("S74E", Some("106")), ("Up", Some("up"))]);
        assert_eq!(axes_of(&raw, None).unwrap(), "yxz");
        // Unknown azimuths keep the file's order.
        let raw = record(&[("H1", Some("unknown")), ("H2", Some("unknown"))]);
        assert_eq!(axes_of(&raw, None).unwrap(), "xy");
    }

    #[test]
    fn a_lone_horizontal_takes_the_asked_axis() {
        let raw = record(&[("180", None)]);
        assert_eq!(axes_of(&raw, None).unwrap(), "x");
        assert_eq!(axes_of(&raw, Some('y')).unwrap(), "y");
        let raw = record(&[("UP", None)]);
        assert_eq!(axes_of(&raw, Some('y')).unwrap(), "z");
    }

    #[test]
    fn ambiguous_records_are_refused() {
        let raw = record(&[("a", Some("0")), ("b", Some("90")), ("c", Some("45"))]);
        assert_eq!(axes_of(&raw, None).unwrap_err(), AxesError::Horizontals(vec!["a".into(), "b".into(), "c".into()]));
        let raw = record(&[("a", Some("up")), ("b", Some("down"))]);
        assert_eq!(axes_of(&raw, None).unwrap_err(), AxesError::Verticals(vec!["a".into(), "b".into()]));
    }
}
