//! A diagnosis case folder: `equipment.yaml` (geometry, mass, sensors and their noise),
//! `floor.csv` (time_s, ax_mps2, ay_mps2, az_mps2), `observed_accel.csv` (time_s, top_ax_mps2)
//! and `observed_cpt.csv` (time_s, theta_rad; empty or NaN cells are camera dropouts).

use std::path::Path;

use crate::diagnose::{Case, Observed};
use crate::error::UserError;
use crate::io::equipment::read_rocking_equipment;
use crate::io::records::{read_delimited, DelimitedOptions};
use crate::physics::rocking::{Block, Shape};

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
    let equipment = read_rocking_equipment(&equipment_path)?;
    let number = |value: Option<f64>, key: &str| {
        value
            .ok_or_else(|| UserError::new(format!("the equipment file does not give `{key}`")).in_file(&equipment_path))
    };
    let shape = match equipment.shape.as_deref().unwrap_or("rectangular") {
        "rectangular" => Shape::Rectangular {
            b_m: number(equipment.b_m, "B_m")?,
            h_m: number(equipment.h_m, "H_m")?,
            f: equipment.f.unwrap_or(0.0),
        },
        "trapezoidal" => Shape::Trapezoidal {
            b1_m: number(equipment.b1_m, "B1_m")?,
            b2_m: number(equipment.b2_m, "B2_m")?,
            h_m: number(equipment.h_m, "H_m")?,
        },
        other => {
            return Err(UserError::new(format!("unknown shape `{other}`"))
                .in_file(&equipment_path)
                .hint("shape is rectangular or trapezoidal"))
        }
    };
    let block = Block::new(shape, equipment.mass_kg.unwrap_or(1.0), equipment.g_mps2.unwrap_or(crate::units::G0))
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
    let sensors = equipment.sensors.as_ref();
    Ok(Case {
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
    })
}
