//! `swivel_jam`: at t0 one caster's swivel stops turning (δ̇ ≡ 0): the caster becomes a fixed
//! wheel, a constraint on the platform's motion; it stops at once, with the least loss of
//! kinetic energy (an impulse along the constraint). Parameters: the caster, t0.

use super::{caster, linspace, onset_bounds, product, sharp_onsets, Effect, RollingCase, Track};
use crate::physics::rolling::Alteration;

pub struct SwivelJam;

impl Effect for SwivelJam {
    fn name(&self) -> &'static str {
        "swivel_jam"
    }

    fn parameter_names(&self) -> &'static [&'static str] {
        &["caster_index", "t0_s"]
    }

    fn discrete(&self) -> &'static [bool] {
        &[true, false]
    }

    fn bounds(&self, case: &RollingCase, _: &Track, window: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.0, 3.0), onset_bounds(case, window, 1.0, 0.1)]
    }

    fn grid(&self, case: &RollingCase, _: &Track, window: (f64, f64)) -> Vec<Vec<f64>> {
        product(&[linspace(0.0, 3.0, 4), sharp_onsets(case, window)])
    }

    fn alteration(&self, _: &RollingCase, _: &Track, p: &[f64]) -> Result<(Alteration, f64), String> {
        Ok((Alteration { jam: Some(caster(p[0])), ..Alteration::default() }, p[1]))
    }

    fn explain(&self, _: &RollingCase, nominal: &Track, p: &[f64]) -> String {
        let _ = nominal;
        format!(
            "at {:.2} s the swivel of caster {} jams and the caster no longer turns relative to the platform",
            p[1],
            caster(p[0]) + 1
        )
    }
}
