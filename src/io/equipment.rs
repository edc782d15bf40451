//! Equipment description files: the geometry and mass of a rocking unit, in the form of the
//! cases' `equipment.yaml` (`shape`, `B_m`, `H_m`, `f`, `mass_kg`; `B1_m`, `B2_m` for a
//! trapezoid). Descriptive sections those files carry (sensors, conventions, derived values) are
//! accepted and ignored; any other key is an error, so a misspelt dimension is never dropped.
//!
//! Both kinds of file may carry an `uncertainty` block: one standard deviation of each stated
//! value's error, per nominal-parameter key, `{sd: X}` (absolute; each element of a list) or
//! `{rel_sd: X}` (relative to the stated value). Which keys are nominal parameters is the unit
//! model's to say (`diagnose::calibration::UnitModel`); [`uncertainty_key_position`] gives the
//! line of a key it refuses.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;

use crate::declare::Declared;

use crate::diagnose::calibration::Spread;
use crate::error::UserError;
use crate::io::records::{decode, read_bytes};
use crate::io::yaml::yaml_refusal;

crate::choice! {
    /// A block's `shape` (an equipment file's and the rocking stages' parameter).
    pub enum ShapeChoice { Rectangular = "rectangular", Trapezoidal = "trapezoidal" }
}

crate::stage_params! {
    /// A rocking block's geometry and mass: the model keys of an equipment file, and the same
    /// parameters of the rocking stages (`simulate_toppling`, `toppling_fragility` flatten it), where
    /// they override a preset and the equipment file.
    #[derive(Clone, Default, PartialEq)]
    pub struct RockingGeometry {
        /// block shape; overrides preset and equipment file
        pub shape: Option<ShapeChoice> [default = null],
        /// rectangle: base width B (in the shaking plane)
        #[serde(rename = "B_m")]
        pub b_m: Option<f64> [default = null, unit = "m", range = (1e-6, 1e3)],
        /// height H
        #[serde(rename = "H_m")]
        pub h_m: Option<f64> [default = null, unit = "m", range = (1e-6, 1e3)],
        /// rectangle: centre of mass above mid-height, as a fraction of H (Table 5's f)
        pub f: Option<f64> [default = null, range = (-0.5, 0.5)],
        /// trapezoid: base (short side) B1
        #[serde(rename = "B1_m")]
        pub b1_m: Option<f64> [default = null, unit = "m", range = (1e-6, 1e3)],
        /// trapezoid: top B2
        #[serde(rename = "B2_m")]
        pub b2_m: Option<f64> [default = null, unit = "m", range = (1e-6, 1e3)],
        /// mass (the rocking response does not depend on it; reported)
        pub mass_kg: Option<f64> [default = null, unit = "kg", range = (1e-9, 1e9)],
        /// gravity; null: the equipment file's g_mps2, else standard gravity 9.80665
        pub g_mps2: Option<f64> [default = null, unit = "m/s^2", range = (0.1, 100.0)],
    }
}

impl RockingGeometry {
    /// Each value of `self`, else the one of `under` (the layer below: a preset under a file
    /// under the stage's own values).
    pub fn over(self, under: RockingGeometry) -> RockingGeometry {
        RockingGeometry {
            shape: self.shape.or(under.shape),
            b_m: self.b_m.or(under.b_m),
            h_m: self.h_m.or(under.h_m),
            f: self.f.or(under.f),
            b1_m: self.b1_m.or(under.b1_m),
            b2_m: self.b2_m.or(under.b2_m),
            mass_kg: self.mass_kg.or(under.mass_kg),
            g_mps2: self.g_mps2.or(under.g_mps2),
        }
    }
}

/// A rocking unit's equipment file: the block, and what the file says besides.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RockingEquipment {
    pub geometry: RockingGeometry,
    pub about: EquipmentAbout,
}

/// The keys of a rocking equipment file besides the block's.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
pub struct EquipmentAbout {
    /// One sd of each stated value's error, by key (`diagnose` calibrates these).
    pub uncertainty: Option<BTreeMap<String, Spread>>,
    // Descriptive: read so that case files load as they are, not used by the model.
    pub name: Option<String>,
    pub description: Option<String>,
    pub e_formula: Option<f64>,
    pub derived: Option<serde_yaml::Value>,
    pub sensors: Option<serde_yaml::Value>,
    pub conventions: Option<serde_yaml::Value>,
}

const ABOUT_KEYS: [&str; 7] = ["uncertainty", "name", "description", "e_formula", "derived", "sensors", "conventions"];

pub fn read_rocking_equipment(path: &Path) -> Result<RockingEquipment, UserError> {
    parse_rocking_equipment(path, &read_equipment_text(path)?)
}

/// The equipment described by the text of an equipment file; `path` only names it in errors.
/// The block and the rest are read apart (each keeps serde_yaml's position of a bad value), then
/// every top-level key must be one of theirs.
pub fn parse_rocking_equipment(path: &Path, text: &str) -> Result<RockingEquipment, UserError> {
    let refuse = |message: String, position: Option<(usize, usize)>, hint: String| {
        UserError::new(format!("not a valid equipment file: {message}")).in_file(path).at(position).hint(hint)
    };
    let keys_hint = "keys: shape (rectangular|trapezoidal), B_m, H_m, f, mass_kg, B1_m, B2_m, g_mps2, \
             uncertainty ({key: {sd: X}} or {key: {rel_sd: X}}) (plus the descriptive name, description, e_formula, derived, sensors, conventions)";
    let yaml = |e: serde_yaml::Error| {
        let position = e.location().map(|l| (l.line(), l.column()));
        let (message, hint) = yaml_refusal(&e, keys_hint);
        refuse(message, position, hint)
    };
    let geometry: RockingGeometry = serde_yaml::from_str(text).map_err(yaml)?;
    let about: EquipmentAbout = serde_yaml::from_str(text).map_err(yaml)?;
    let keys: serde_yaml::Mapping = serde_yaml::from_str(text).map_err(yaml)?;
    let allowed: Vec<&str> = RockingGeometry::specs().iter().map(|s| s.name).chain(ABOUT_KEYS).collect();
    for key in keys.keys() {
        let name = key.as_str().map_or_else(|| format!("{key:?}"), str::to_string);
        if !allowed.contains(&name.as_str()) {
            let listed: Vec<String> = allowed.iter().map(|k| format!("`{k}`")).collect();
            let line = text
                .lines()
                .position(|l| l.strip_prefix(name.as_str()).is_some_and(|r| r.trim_start().starts_with(':')));
            return Err(refuse(
                format!("unknown field `{name}`, expected one of {}", listed.join(", ")),
                line.map(|l| (l + 1, 1)),
                keys_hint.to_string(),
            ));
        }
    }
    Ok(RockingEquipment { geometry, about })
}

/// A rolling unit's equipment file (`model: rolling`): the nominal 4WMC parameters under the keys
/// of `simulate_rolling`, plus the descriptive `name`, `description`, `sensors`, `conventions`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RollingEquipment {
    pub model: String,
    pub length_m: f64,
    pub width_m: f64,
    pub platform_mass_kg: f64,
    pub wheel_diameter_m: f64,
    pub wheel_width_m: f64,
    pub wheel_mass_kg: f64,
    pub yaw0_deg: f64,
    pub steer0_deg: [f64; 4],
    pub mu_s_roll: f64,
    pub mu_s_swivel: f64,
    pub mu_k_roll: f64,
    pub mu_k_swivel: f64,
    pub beta_spm: f64,
    pub gamma_n: f64,
    pub p: Option<f64>,
    pub trail_m: Option<f64>,
    pub swivel_arm_m: Option<f64>,
    pub friction_eps: Option<f64>,
    pub friction_eps_swivel: Option<f64>,
    pub g_mps2: Option<f64>,
    /// One sd of each stated value's error, by key (`diagnose` calibrates these).
    pub uncertainty: Option<BTreeMap<String, Spread>>,
    pub name: Option<String>,
    pub description: Option<String>,
    pub sensors: Option<serde_yaml::Value>,
    pub conventions: Option<serde_yaml::Value>,
}

/// The `model:` an equipment file declares (`rolling`), if any: rocking files have none.
pub fn declared_model(text: &str) -> Option<String> {
    let value: serde_yaml::Value = serde_yaml::from_str(text).ok()?;
    value.get("model")?.as_str().map(str::to_string)
}

pub fn read_equipment_text(path: &Path) -> Result<String, UserError> {
    let bytes = read_bytes(path)
        .map_err(|e| UserError::new(format!("cannot read the equipment file: {}", e.message)).in_file(path))?;
    decode(path, &bytes).map(|t| t.to_string()).map_err(|e| {
        UserError::new(format!("not an equipment file: {}", e.message))
            .in_file(path)
            .at(e.line.map(|l| (l, 1)))
            .hint(e.hint)
    })
}

/// The rolling unit described by the text of an equipment file; `path` only names it in errors.
pub fn parse_rolling_equipment(path: &Path, text: &str) -> Result<RollingEquipment, UserError> {
    serde_yaml::from_str(text).map_err(|e| {
        let position = e.location().map(|l| (l.line(), l.column()));
        let (message, hint) = yaml_refusal(
            &e,
            "keys: model (rolling), length_m, width_m, platform_mass_kg, wheel_diameter_m, wheel_width_m, \
             wheel_mass_kg, yaw0_deg, steer0_deg (4 values), mu_s_roll, mu_s_swivel, mu_k_roll, mu_k_swivel, \
             beta_spm, gamma_n, p, trail_m, swivel_arm_m, friction_eps, friction_eps_swivel, g_mps2, \
             uncertainty ({key: {sd: X}} or {key: {rel_sd: X}}) (plus the descriptive name, description, sensors, conventions)",
        );
        UserError::new(format!("not a valid rolling equipment file: {message}")).in_file(path).at(position).hint(hint)
    })
}

/// (line, column), 1-based, of `key` inside the top-level `uncertainty` block of an equipment
/// file's text (block or flow style); the block's own line when the key is not found there.
pub fn uncertainty_key_position(text: &str, key: &str) -> Option<(usize, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let start = lines.iter().position(|l| l.starts_with("uncertainty:"))?;
    for (i, line) in lines.iter().enumerate().skip(start) {
        let body = line.split('#').next().unwrap_or("");
        if i > start && !body.trim().is_empty() && !line.starts_with([' ', '\t']) {
            break;
        }
        let from = if i == start { "uncertainty:".len() } else { 0 };
        let bytes = body.as_bytes();
        let found = body[from.min(body.len())..].match_indices(key).map(|(k, _)| k + from).find(|&k| {
            let before = k == 0 || !(bytes[k - 1].is_ascii_alphanumeric() || bytes[k - 1] == b'_');
            let rest = body[k + key.len()..].trim_start_matches(['"', '\'']).trim_start();
            before && rest.starts_with(':')
        });
        if let Some(k) = found {
            return Some((i + 1, k + 1));
        }
    }
    Some((start + 1, 1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_a_case_file_and_names_a_misspelt_key_with_its_line() {
        let dir = crate::tempdir::tempdir().unwrap();
        let good = dir.path().join("good.yaml");
        std::fs::write(&good, "name: PS2\nshape: rectangular\nB_m: 0.349\nH_m: 1.082\nf: 0.085\nmass_kg: 150\nsensors:\n  accelerometer: {rate_hz: 200}\n").unwrap();
        let e = read_rocking_equipment(&good).unwrap().geometry;
        assert_eq!((e.b_m, e.h_m, e.f, e.mass_kg), (Some(0.349), Some(1.082), Some(0.085), Some(150.0)));
        assert_eq!(e.shape, Some(ShapeChoice::Rectangular));
        let bad = dir.path().join("bad.yaml");
        std::fs::write(&bad, "shape: rectangular\nB_m: 0.349\nH_M: 1.082\n").unwrap();
        let err = read_rocking_equipment(&bad).unwrap_err();
        assert_eq!(err.line, Some(3), "{err}");
        assert!(err.to_string().contains("unknown field `H_M`, expected one of `shape`, `B_m`"), "{err}");
        // A value of the wrong kind, and a shape that is none, keep their line too.
        std::fs::write(&bad, "shape: rectangular\nB_m: wide\n").unwrap();
        assert_eq!(read_rocking_equipment(&bad).unwrap_err().line, Some(2));
        std::fs::write(&bad, "name: x\nshape: round\n").unwrap();
        let err = read_rocking_equipment(&bad).unwrap_err();
        assert_eq!(err.line, Some(2), "{err}");
        assert!(err.to_string().contains("unknown variant `round`"), "{err}");
    }

    #[test]
    fn an_uncertainty_block_is_read_and_a_key_is_found_at_its_line() {
        let text = "shape: rectangular\nB_m: 0.349\nH_m: 1.082\nuncertainty:\n  f:\n    sd: 0.03\n  H_m: {rel_sd: 0.01}\nsensors: {}\n";
        let e = parse_rocking_equipment(Path::new("e.yaml"), text).unwrap();
        let u = e.about.uncertainty.unwrap();
        assert_eq!(u["f"], Spread { sd: Some(0.03), rel_sd: None });
        assert_eq!(u["H_m"], Spread { sd: None, rel_sd: Some(0.01) });
        assert_eq!(uncertainty_key_position(text, "H_m"), Some((7, 3)));
        assert_eq!(uncertainty_key_position(text, "f"), Some((5, 3)));
        // Flow style: the key on the block's line; a key it does not hold: the block's line.
        let flow = "B_m: 1\nuncertainty: {f: {sd: 0.03}, mu_k: {rel_sd: 0.2}}\n";
        assert_eq!(uncertainty_key_position(flow, "mu_k"), Some((2, 30)));
        assert_eq!(uncertainty_key_position(flow, "H_m"), Some((2, 1)));
        // A misspelt spread is refused by the parser, with its line.
        let bad = "B_m: 1\nH_m: 2\nuncertainty:\n  H_m: {rel: 0.01}\n";
        let err = parse_rocking_equipment(Path::new("e.yaml"), bad).unwrap_err();
        assert_eq!(err.line, Some(4), "{err}");
    }
}
