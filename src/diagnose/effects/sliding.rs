//! `sliding`: the base slides on the floor (Coulomb friction μ, stick-slip) whenever the floor
//! accelerates harder than μ(g + a_v) while the unit is not rocking; sliding caps the unit's own
//! acceleration at μ(g + a_v), which its top accelerometer shows as flat-topped peaks.

use super::{linspace, Case, Effect, Prediction};
use crate::physics::rocking::EventKind;
use crate::physics::rocking::Options;

pub struct Sliding;

impl Effect for Sliding {
    fn name(&self) -> &'static str {
        "sliding"
    }

    fn parameter_names(&self) -> &'static [&'static str] {
        &["mu"]
    }

    fn bounds(&self, case: &Case, _: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.02, 1.2 * case.block.alpha_rad.tan())]
    }

    fn grid(&self, case: &Case, window: (f64, f64)) -> Vec<Vec<f64>> {
        let (lo, hi) = self.bounds(case, window)[0];
        linspace(lo, hi, 40).into_iter().map(|mu| vec![mu]).collect()
    }

    fn predict(&self, case: &Case, params: &[f64]) -> Result<Prediction, String> {
        let options = Options { friction: Some(params[0]), ..case.nominal_options() };
        Ok(case.simulate(&case.block, &options)?.1)
    }

    fn explain(&self, case: &Case, params: &[f64]) -> String {
        format!(
            "the base slides on the floor with a friction coefficient μ = {:.3} (below tan α = {:.3}), so between rocking phases the unit cannot follow floor accelerations above {:.2} m/s^2",
            params[0],
            case.block.alpha_rad.tan(),
            params[0] * case.block.g_mps2
        )
    }

    fn onset(&self, _params: &[f64], prediction: &Prediction) -> Option<f64> {
        prediction.first(&[EventKind::SlideStart])
    }
}
