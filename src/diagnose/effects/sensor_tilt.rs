//! `sensor_tilt`: the top accelerometer is fixed to the body and turns with it, so it senses
//! gravity along its tilted axis: a = a_x cos θ − (a_z + g) sin θ, with (a_x, a_z) the sensor
//! point's kinematic acceleration in world axes; lying on its side after an overturn it reads
//! −s(a_v + g). No parameter: the rotation the camera sees fixes it.

use super::{Case, Effect, Prediction};
use crate::physics::error::PhysicsError;
use crate::physics::rocking::EventKind;

pub struct SensorTilt;

impl Effect for SensorTilt {
    fn name(&self) -> &'static str {
        "sensor_tilt"
    }

    fn parameter_names(&self) -> &'static [&'static str] {
        &[]
    }

    fn bounds(&self, _: &Case, _: (f64, f64)) -> Vec<(f64, f64)> {
        Vec::new()
    }

    fn grid(&self, _: &Case, _: (f64, f64)) -> Vec<Vec<f64>> {
        vec![Vec::new()]
    }

    fn predict(&self, case: &Case, _: &[f64]) -> Result<Prediction, PhysicsError> {
        let (response, mut prediction) = case.simulate(&case.block, &case.nominal_options())?;
        let g = case.block.g_mps2;
        prediction.top_ax_mps2 = (0..response.theta_rad.len())
            .map(|k| {
                let (sin, cos) = response.theta_rad[k].sin_cos();
                response.sensor_ax_mps2[k] * cos - (response.sensor_az_mps2[k] + g) * sin
            })
            .collect();
        Ok(prediction)
    }

    fn explain(&self, _: &Case, _: &[f64]) -> String {
        "the top accelerometer turns with the unit and senses g·sin θ as it tilts (about 1 m/s^2 at 6°), and g itself once the unit lies on its side".into()
    }

    fn onset(&self, _params: &[f64], prediction: &Prediction) -> Option<f64> {
        prediction.first(&[EventKind::Uplift])
    }
}
