//! `caster_brake`: at t0 one caster's wheel locks and drags: it no longer spins, and the floor
//! resists its slide along the heading with μ N tanh(v/ε) instead of rolling resistance.
//! Parameters: the caster, t0, μ.

use super::{caster, linspace, onset_bounds, onsets_at, product, Effect, RollingCase, Track};
use crate::physics::rolling::{Alteration, Brake};

pub struct CasterBrake;

/// Onsets tried (s from the window's start): a locked wheel shows within a few samples, a pad
/// whose drag builds up over some tenths of a second shows once the drag is strong.
const ONSETS: [f64; 6] = [-0.4, -0.2, -0.1, -0.05, -0.02, 0.0];

impl Effect for CasterBrake {
    fn name(&self) -> &'static str {
        "caster_brake"
    }

    fn parameter_names(&self) -> &'static [&'static str] {
        &["caster_index", "t0_s", "mu_drag"]
    }

    fn discrete(&self) -> &'static [bool] {
        &[true, false, false]
    }

    fn bounds(&self, case: &RollingCase, _: &Track, window: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.0, 3.0), onset_bounds(case, window, 1.0, 0.1), (0.02, 1.0)]
    }

    fn grid(&self, case: &RollingCase, _: &Track, window: (f64, f64)) -> Vec<Vec<f64>> {
        product(&[linspace(0.0, 3.0, 4), onsets_at(case, window, &ONSETS), vec![0.2, 0.5]])
    }

    fn alteration(&self, _: &RollingCase, _: &Track, p: &[f64]) -> Result<(Alteration, f64), String> {
        Ok((Alteration { brake: Some(Brake { caster: caster(p[0]), mu: p[2] }), ..Alteration::default() }, p[1]))
    }

    fn explain(&self, _: &RollingCase, _: &Track, p: &[f64]) -> String {
        format!(
            "at {:.2} s the wheel of caster {} locks and drags with a friction coefficient of {:.3}",
            p[1],
            caster(p[0]) + 1,
            p[2]
        )
    }
}
