//! `flexibility`: the unit is not rigid. A flexible mode between the floor and the rocking body
//! (frame, legs, casters: the 2–5 Hz modes of the study's Table 3) filters the floor motion the
//! block feels and the top accelerometer records: a linear oscillator of frequency f_n and
//! damping ζ carries the block.

use super::{linspace, product, Case, Effect, Prediction};
use crate::physics::error::PhysicsError;
use crate::physics::rocking::{IsolatedBase, Options};

pub struct Flexibility;

impl Effect for Flexibility {
    fn name(&self) -> &'static str {
        "flexibility"
    }

    fn parameter_names(&self) -> &'static [&'static str] {
        &["frequency_hz", "damping_ratio"]
    }

    fn bounds(&self, _: &Case, _: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.8, 15.0), (0.003, 0.4)]
    }

    fn grid(&self, _: &Case, _: (f64, f64)) -> Vec<Vec<f64>> {
        let frequencies: Vec<f64> = linspace(0.8f64.ln(), 15f64.ln(), 30).into_iter().map(f64::exp).collect();
        product(&[frequencies, vec![0.01, 0.025, 0.05, 0.1, 0.2]])
    }

    fn predict(&self, case: &Case, params: &[f64]) -> Result<Prediction, PhysicsError> {
        let options = Options {
            isolated_base: Some(IsolatedBase { period_s: 1.0 / params[0], damping_ratio: params[1], mass_ratio: None }),
            ..case.nominal_options()
        };
        Ok(case.simulate(&case.block, &options)?.1)
    }

    fn explain(&self, _: &Case, params: &[f64]) -> String {
        format!(
            "the unit is not rigid: a flexible mode at {:.2} Hz with {:.1} % damping between the floor and the rocking body shapes what it feels and what its top accelerometer records",
            params[0],
            100.0 * params[1]
        )
    }
}
