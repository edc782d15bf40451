//! `sensor_tilt`: the top accelerometer is fixed to the body and turns with it, so it senses
//! gravity along its tilted axis: a = a_x cos θ − (a_z + g) sin θ, with (a_x, a_z) the sensor
//! point's kinematic acceleration in world axes; lying on its side after an overturn it reads
//! −s(a_v + g). The rotation the camera sees fixes the tilt; what is fitted is where on the
//! body the sensor is: an accelerometer fixed to the unit is seldom exactly at the top centre
//! the equipment file assumes (a bracket on a side panel, a shelf below the top), and its point
//! sets the kinematic part of what it reads (mis-stated seeds 3301 case_04 and 3303 case_04: a
//! sensor 0.77–0.84 H high and 0.03–0.13 m off the centre line, which the top centre's tilt left
//! `unexplained`). Its parameters: the offset from the centre line (toward +x) and the depth
//! below the top, so the point stays put on the unit while a joint search moves its height.

use super::{Case, Effect, Prediction};
use crate::physics::error::PhysicsError;
use crate::physics::rocking::{EventKind, Options};

pub struct SensorTilt;

/// Where the equipment file puts the sensor: its stated height, or the top.
fn stated_height(case: &Case) -> f64 {
    case.sensor_height_m.unwrap_or(case.block.height_m)
}

/// The lowest a top accelerometer is looked for, as a share of the unit's height.
const LOWEST: f64 = 0.5;
/// A mount point this close (m) to where the equipment file puts it is said to be there.
const MOUNT_TOLERANCE_M: f64 = 0.005;

impl Effect for SensorTilt {
    fn name(&self) -> &'static str {
        "sensor_tilt"
    }

    fn parameter_names(&self) -> &'static [&'static str] {
        &["offset_m", "below_top_m"]
    }

    /// The mount point moves what the sensor reads, linearly (a rigid body's accelerations are
    /// affine in the point, the tilt rotates them), not the motion.
    fn affine(&self) -> bool {
        true
    }

    fn bounds(&self, case: &Case, _: (f64, f64)) -> Vec<(f64, f64)> {
        let (b, h) = (case.block.half_base_m, case.block.height_m);
        vec![(-b, b), (0.0, (1.0 - LOWEST) * h)]
    }

    /// Where the equipment file says the sensor is, the top centre: the fit solves the point
    /// from there ([`Effect::affine`]).
    fn grid(&self, _: &Case, _: (f64, f64)) -> Vec<Vec<f64>> {
        vec![vec![0.0, 0.0]]
    }

    fn predict(&self, case: &Case, params: &[f64]) -> Result<Prediction, PhysicsError> {
        // The depth below where the equipment file puts the sensor (the top), not the height:
        // the point stays where it is on the unit while a joint search moves the unit's height.
        let height = stated_height(case) - params[1];
        let options = Options { sensor_offset_m: params[0], sensor_height_m: Some(height), ..case.nominal_options() };
        let (response, mut prediction) = case.simulate(&case.block, &options)?;
        let g = case.block.g_mps2;
        prediction.top_ax_mps2 = (0..response.theta_rad.len())
            .map(|k| {
                let (sin, cos) = response.theta_rad[k].sin_cos();
                response.sensor_ax_mps2[k] * cos - (response.sensor_az_mps2[k] + g) * sin
            })
            .collect();
        Ok(prediction)
    }

    fn explain(&self, case: &Case, params: &[f64]) -> String {
        let [offset, depth] = [params[0], params[1]];
        let stated = stated_height(case);
        let height = stated - depth;
        let below = case.block.height_m - height;
        let tilt = "the top accelerometer turns with the unit and senses g·sin θ as it tilts (about 1 m/s^2 at 6°), and g itself once the unit lies on its side";
        // Within 5 mm of where the equipment file puts it: there.
        if depth < MOUNT_TOLERANCE_M && offset.abs() < MOUNT_TOLERANCE_M {
            return format!(
                "{tilt}; it is where the equipment file puts it, {stated:.2} m above the base on the centre line"
            );
        }
        let side = if offset > 0.0 { "+" } else { "−" };
        format!(
            "{tilt}; it reads as if mounted {height:.2} m above the base ({}) and {} (the equipment file puts it {stated:.2} m above the base on the centre line)",
            if below >= MOUNT_TOLERANCE_M { format!("{below:.2} m below the top") } else { "at the top".into() },
            if offset.abs() >= MOUNT_TOLERANCE_M {
                format!("{:.2} m off the centre line toward {side}x", offset.abs())
            } else {
                "on the centre line".into()
            }
        )
    }

    fn onset(&self, _params: &[f64], prediction: &Prediction) -> Option<f64> {
        prediction.first(&[EventKind::Uplift])
    }
}
