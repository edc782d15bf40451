//! `restitution`: the impacts lose a different share of the rocking energy than Eq. 24 says
//! (a soft or sticky contact, a base that is not a flat rigid line): one coefficient e.

use super::{linspace, Case, Effect, Prediction};
use crate::physics::error::PhysicsError;
use crate::physics::rocking::EventKind;
use crate::physics::rocking::Options;

pub struct Restitution;

impl Effect for Restitution {
    fn name(&self) -> &'static str {
        "restitution"
    }

    fn parameter_names(&self) -> &'static [&'static str] {
        &["e"]
    }

    fn bounds(&self, _: &Case, _: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.05, 1.0)]
    }

    fn grid(&self, _: &Case, _: (f64, f64)) -> Vec<Vec<f64>> {
        linspace(0.05, 1.0, 39).into_iter().map(|e| vec![e]).collect()
    }

    fn predict(&self, case: &Case, params: &[f64]) -> Result<Prediction, PhysicsError> {
        let options = Options { restitution: Some(params[0]), ..case.nominal_options() };
        Ok(case.simulate(&case.block, &options)?.1)
    }

    fn explain(&self, case: &Case, params: &[f64]) -> String {
        let e = params[0];
        let eq24 = case.block.restitution_eq24;
        format!(
            "the impacts keep a fraction e = {e:.3} of the angular velocity (Eq. 24 says {eq24:.3}): each impact {} {:.0} % of the rocking energy",
            if e < eq24 { "dissipates" } else { "dissipates only" },
            100.0 * (1.0 - e * e)
        )
    }

    /// Eq. 24: a coefficient the dimensions' uncertainty could give is no other contact
    /// (mis-stated seed 3301 case_07, a mass change: e = 0.784 where Eq. 24 gives 0.785 on the
    /// same values, fitted only through the chaos it perturbs).
    fn nominal_counterpart(&self, case: &Case) -> Option<(usize, f64)> {
        Some((0, case.block.restitution_eq24))
    }

    /// The first impact the block rebounds from (a touch-down from micro-rocking that ends in
    /// rest is not one: no restitution law changes it).
    fn onset(&self, _params: &[f64], prediction: &Prediction) -> Option<f64> {
        prediction.first(&[EventKind::Impact])
    }
}
