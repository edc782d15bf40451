//! A diagnosis case folder: `equipment.yaml` (geometry, mass, sensors and their noise),
//! `floor.csv` (time_s, ax_mps2, ay_mps2, az_mps2), `observed_accel.csv` (time_s, top_ax_mps2)
//! and `observed_cpt.csv` (time_s, theta_rad; empty or NaN cells are camera dropouts).

use std::path::Path;

use crate::diagnose::calibration::{uncertain_parameters, Spread, Uncertain, UnitModel};
use crate::diagnose::rolling::{Camera, RollingCase};
use crate::diagnose::{Case, Observed};
use crate::error::UserError;
use crate::io::equipment::{
    declared_model, parse_rocking_equipment, parse_rolling_equipment, read_equipment_text, uncertainty_key_position,
    ShapeChoice,
};
use crate::io::records::{read_delimited, DelimitedOptions};
use crate::physics::rocking::{Block, Shape};
use crate::physics::rolling::{self, Cart, Friction, FrictionLaw, Options, Stribeck};

pub const EQUIPMENT: &str = "equipment.yaml";
pub const FLOOR: &str = "floor.csv";
pub const ACCEL: &str = "observed_accel.csv";
pub const CAMERA: &str = "observed_cpt.csv";

/// Noise assumed when the equipment file does not state it (the demo cases' sensors).
const DEFAULT_ACCEL_NOISE_MPS2: f64 = 0.02;
const DEFAULT_CAMERA_NOISE_RAD: f64 = 0.002;

const LAYOUT_HINT: &str = "a case folder holds equipment.yaml, floor.csv (time_s, ax_mps2, ay_mps2, az_mps2), observed_accel.csv (time_s, top_ax_mps2) and observed_cpt.csv (time_s, theta_rad)";

/// The named columns of a CSV file, each as read (NaN for empty cells).
fn columns(path: &Path, wanted: &[&str], required: bool) -> Result<Option<Vec<Vec<f64>>>, UserError> {
    if !path.is_file() {
        return if required {
            Err(UserError::new(format!("`{}` is missing", path.display())).hint(LAYOUT_HINT))
        } else {
            Ok(None)
        };
    }
    let record = read_delimited(path, &DelimitedOptions { delimiter: Some(b','), ..DelimitedOptions::default() })
        .map_err(|e| UserError::new(e.message.clone()).in_file(&e.path).at(e.line.zip(e.column)).hint(e.hint))?;
    wanted
        .iter()
        .map(|name| {
            record.channels.iter().find(|c| c.name == *name).map(|c| c.values.clone()).ok_or_else(|| {
                let found: Vec<&str> = record.channels.iter().map(|c| c.name.as_str()).collect();
                UserError::new(format!("no column `{name}`; the file has {}", found.join(", ")))
                    .in_file(path)
                    .at(Some((1, 1)))
                    .hint(LAYOUT_HINT)
            })
        })
        .collect::<Result<Vec<_>, _>>()
        .map(Some)
}

/// A number under `sensors.<sensor>.<key>` in the equipment file, when stated.
fn sensor_number(sensors: Option<&serde_yaml::Value>, sensor: &str, key: &str) -> Option<f64> {
    sensors?.get(sensor)?.get(key)?.as_f64()
}

/// [`read_case`], then the folder hashed again: a case whose files changed since the run hashed
/// them when it was planned (`expected_hash`; empty: unchecked) is refused, so the diagnosis
/// holds what its provenance names.
pub fn read_case_unchanged(dir: &Path, expected_hash: &str) -> Result<Case, UserError> {
    let case = read_case(dir)?;
    if expected_hash.is_empty() {
        return Ok(case);
    }
    let now = crate::io::hash::hash_dir(dir).map_err(|e| UserError::new(format!("{e:#}")).in_file(dir))?.0;
    if now != expected_hash {
        return Err(UserError::new(format!("`{}` changed while this run was reading it", dir.display()))
            .hint("another program is writing into the case folder; rerun when it is no longer being written"));
    }
    Ok(case)
}

pub fn read_case(dir: &Path) -> Result<Case, UserError> {
    if !dir.is_dir() {
        return Err(UserError::new(format!("`{}` is not a folder", dir.display())).hint(LAYOUT_HINT));
    }
    let equipment_path = dir.join(EQUIPMENT);
    if !equipment_path.is_file() {
        return Err(UserError::new(format!("`{}` is missing", equipment_path.display())).hint(LAYOUT_HINT));
    }
    let text = read_equipment_text(&equipment_path)?;
    let equipment = parse_rocking_equipment(&equipment_path, &text)?;
    let number = |value: Option<f64>, key: &str| {
        value
            .ok_or_else(|| UserError::new(format!("the equipment file does not give `{key}`")).in_file(&equipment_path))
    };
    let geometry = &equipment.geometry;
    let shape = match geometry.shape.unwrap_or(ShapeChoice::Rectangular) {
        ShapeChoice::Rectangular => Shape::Rectangular {
            b_m: number(geometry.b_m, "B_m")?,
            h_m: number(geometry.h_m, "H_m")?,
            f: geometry.f.unwrap_or(0.0),
        },
        ShapeChoice::Trapezoidal => Shape::Trapezoidal {
            b1_m: number(geometry.b1_m, "B1_m")?,
            b2_m: number(geometry.b2_m, "B2_m")?,
            h_m: number(geometry.h_m, "H_m")?,
        },
    };
    let block = Block::new(shape, geometry.mass_kg.unwrap_or(1.0), geometry.g_mps2.unwrap_or(crate::units::G0))
        .map_err(|e| UserError::new(format!("invalid unit: {e}")).in_file(&equipment_path))?;
    let floor_path = dir.join(FLOOR);
    let floor = columns(&floor_path, &["time_s", "ax_mps2", "az_mps2"], true)?.expect("required");
    let time = &floor[0];
    if time.len() < 2 {
        return Err(UserError::new("the floor record has fewer than 2 samples").in_file(&floor_path));
    }
    let dt = crate::table::uniform_step(time).map_err(|i| {
        UserError::new(format!("time is not uniformly sampled after t = {} s", time[i]))
            .in_file(&floor_path)
            .at(Some((i + 2, 1)))
    })?;
    for (name, values) in [("ax_mps2", &floor[1]), ("az_mps2", &floor[2])] {
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(UserError::new(format!("`{name}` has a missing or non-finite value"))
                .in_file(&floor_path)
                .at(Some((i + 2, 1)))
                .hint("the floor record must be complete: fill the gap before diagnosing"));
        }
    }
    let observed = |file: &str, column: &str| -> Result<Option<Observed>, UserError> {
        Ok(columns(&dir.join(file), &["time_s", column], false)?
            .map(|mut c| Observed { value: c.pop().expect("two columns"), time_s: c.pop().expect("two columns") }))
    };
    let accel = observed(ACCEL, "top_ax_mps2")?;
    let camera = observed(CAMERA, "theta_rad")?;
    if accel.is_none() && camera.is_none() {
        return Err(UserError::new(format!(
            "`{}` has neither {ACCEL} nor {CAMERA}: there is nothing to compare the model with",
            dir.display()
        ))
        .hint(LAYOUT_HINT));
    }
    let sensors = equipment.about.sensors.as_ref();
    let mut case = Case {
        name: dir.file_name().map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned()),
        block,
        sensor_height_m: None,
        t0_s: time[0],
        dt_s: dt,
        floor_ax_mps2: floor[1].clone(),
        floor_az_mps2: floor[2].clone(),
        accel,
        camera,
        accel_noise_mps2: sensor_number(sensors, "accelerometer", "noise_sd_mps2").unwrap_or(DEFAULT_ACCEL_NOISE_MPS2),
        camera_noise_rad: sensor_number(sensors, "camera", "noise_sd_rad").unwrap_or(DEFAULT_CAMERA_NOISE_RAD),
        uncertain: Vec::new(),
    };
    case.uncertain = uncertain(&case, equipment.about.uncertainty.as_ref(), &equipment_path, &text)?;
    Ok(case)
}

/// The uncertain parameters an `uncertainty` block names for `model`; a key that is not one of
/// its nominal parameters (or a spread it cannot use) is an error at the key's line.
fn uncertain<M: UnitModel>(
    model: &M,
    block: Option<&std::collections::BTreeMap<String, Spread>>,
    path: &Path,
    text: &str,
) -> Result<Vec<Uncertain>, UserError> {
    let Some(block) = block else { return Ok(Vec::new()) };
    let mut out = Vec::new();
    for (key, spread) in block {
        let found = uncertain_parameters(model, &[(key.clone(), *spread)]).map_err(|e| {
            UserError::new(format!("invalid `uncertainty` block: {e}"))
                .in_file(path)
                .at(uncertainty_key_position(text, key))
                .hint("each key of `uncertainty` is a nominal parameter of the unit, with {sd: X} (absolute, each element of a list) or {rel_sd: X} (relative to the stated value); see docs/models/diagnosis.md")
        })?;
        out.extend(found);
    }
    Ok(out)
}

const ROLLING_HINT: &str = "a rolling case folder holds equipment.yaml (model: rolling), floor.csv (time_s, ax_mps2, ay_mps2), observed_accel.csv (time_s, top_ax_mps2) and observed_cpt.csv (time_s, x_m, y_m, yaw_rad)";

/// Default camera noise of a rolling case whose equipment file does not state it (m).
const DEFAULT_CAMERA_NOISE_M: f64 = 0.002;

/// The `model:` the case folder's equipment file declares (`rolling`; None for a rocking unit).
pub fn case_model(dir: &Path) -> Result<Option<String>, UserError> {
    let path = dir.join(EQUIPMENT);
    if !path.is_file() {
        return Ok(None);
    }
    Ok(declared_model(&read_equipment_text(&path)?))
}

/// A rolling unit's case folder (`model: rolling` in equipment.yaml).
pub fn read_rolling_case(dir: &Path) -> Result<RollingCase, UserError> {
    let equipment_path = dir.join(EQUIPMENT);
    if !equipment_path.is_file() {
        return Err(UserError::new(format!("`{}` is missing", equipment_path.display())).hint(ROLLING_HINT));
    }
    let text = read_equipment_text(&equipment_path)?;
    let e = parse_rolling_equipment(&equipment_path, &text)?;
    if e.model != "rolling" {
        return Err(UserError::new(format!("`model: {}` is not a rolling unit", e.model))
            .in_file(&equipment_path)
            .hint("model: rolling, or no model key for a rocking unit"));
    }
    let refuse = |message: String| UserError::new(message).in_file(&equipment_path).hint(ROLLING_HINT);
    let cart = Cart {
        length_m: e.length_m,
        width_m: e.width_m,
        platform_mass_kg: e.platform_mass_kg,
        wheel_diameter_m: e.wheel_diameter_m,
        wheel_width_m: e.wheel_width_m,
        wheel_mass_kg: e.wheel_mass_kg,
        trail_m: e.trail_m.unwrap_or_else(|| Cart::default_trail_m(e.wheel_diameter_m)),
        swivel_arm_m: e.swivel_arm_m.unwrap_or(rolling::DEFAULT_SWIVEL_ARM_M),
    };
    cart.check(false).map_err(|m| refuse(format!("invalid cart: {m}")))?;
    let p = e.p.unwrap_or(1.0);
    let law = |mu_s, mu_k| Stribeck { mu_s, mu_k, beta_spm: e.beta_spm, gamma_n: e.gamma_n, p };
    let friction = Friction {
        roll: law(e.mu_s_roll, e.mu_k_roll),
        swivel: law(e.mu_s_swivel, e.mu_k_swivel),
        eps_mps: e.friction_eps.unwrap_or(rolling::DEFAULT_FRICTION_EPS_MPS),
        eps_swivel_radps: e.friction_eps_swivel.unwrap_or(rolling::DEFAULT_FRICTION_EPS_SWIVEL_RADPS),
        law: FrictionLaw::Regularised,
    };
    friction.check().map_err(|m| refuse(format!("invalid friction: {m}")))?;
    let g = e.g_mps2.unwrap_or(crate::units::G0);
    if !(g.is_finite() && g > 0.0 && e.yaw0_deg.is_finite() && e.steer0_deg.iter().all(|v| v.is_finite())) {
        return Err(refuse("g_mps2 must be positive and the initial angles finite".into()));
    }
    let options = Options {
        yaw0_rad: e.yaw0_deg.to_radians(),
        steer0_rad: e.steer0_deg.map(f64::to_radians),
        lateral_slip: None,
        method: crate::diagnose::rolling::METHOD,
        g_mps2: g,
    };
    let floor_path = dir.join(FLOOR);
    let floor = columns(&floor_path, &["time_s", "ax_mps2", "ay_mps2"], true)?.expect("required");
    let time = &floor[0];
    if time.len() < 3 {
        return Err(UserError::new("the floor record has fewer than 3 samples").in_file(&floor_path));
    }
    let dt = crate::table::uniform_step(time).map_err(|i| {
        UserError::new(format!("time is not uniformly sampled after t = {} s", time[i]))
            .in_file(&floor_path)
            .at(Some((i + 2, 1)))
    })?;
    for (name, values) in [("ax_mps2", &floor[1]), ("ay_mps2", &floor[2])] {
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(UserError::new(format!("`{name}` has a missing or non-finite value"))
                .in_file(&floor_path)
                .at(Some((i + 2, 1)))
                .hint("the floor record must be complete: fill the gap before diagnosing"));
        }
    }
    let accel = columns(&dir.join(ACCEL), &["time_s", "top_ax_mps2"], false)?
        .map(|mut c| Observed { value: c.pop().expect("two columns"), time_s: c.pop().expect("two columns") });
    let camera = columns(&dir.join(CAMERA), &["time_s", "x_m", "y_m", "yaw_rad"], false)?.map(|mut c| {
        let yaw_rad = c.pop().expect("four columns");
        let y_m = c.pop().expect("four columns");
        let x_m = c.pop().expect("four columns");
        Camera { time_s: c.pop().expect("four columns"), x_m, y_m, yaw_rad }
    });
    if accel.is_none() && camera.is_none() {
        return Err(UserError::new(format!(
            "`{}` has neither {ACCEL} nor {CAMERA}: there is nothing to compare the model with",
            dir.display()
        ))
        .hint(ROLLING_HINT));
    }
    let sensors = e.sensors.as_ref();
    let mut case = RollingCase {
        name: dir.file_name().map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned()),
        cart,
        friction,
        options,
        t0_s: time[0],
        dt_s: dt,
        floor_ax_mps2: floor[1].clone(),
        floor_ay_mps2: floor[2].clone(),
        accel,
        camera,
        accel_noise_mps2: sensor_number(sensors, "accelerometer", "noise_sd_mps2").unwrap_or(DEFAULT_ACCEL_NOISE_MPS2),
        camera_noise_m: sensor_number(sensors, "camera", "noise_sd_m").unwrap_or(DEFAULT_CAMERA_NOISE_M),
        camera_noise_rad: sensor_number(sensors, "camera", "noise_sd_rad").unwrap_or(DEFAULT_CAMERA_NOISE_RAD),
        uncertain: Vec::new(),
    };
    case.uncertain = uncertain(&case, e.uncertainty.as_ref(), &equipment_path, &text)?;
    Ok(case)
}
