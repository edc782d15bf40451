//! `restitution`: the impacts lose a different share of the rocking energy than Eq. 24 says
//! (a soft or sticky contact, a base that is not a flat rigid line): one coefficient e.

use super::{linspace, Case, Effect, Prediction};
use crate::diagnose::calibration::{self, Uncertain, UnitModel};
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

    /// Eq. 24's value on `case`, as uncertain as the uncertain values make it (each moved by its
    /// sd, central differences summed in quadrature): a coefficient the dimensions' uncertainty
    /// could give is no other contact (mis-stated seed 3301 case_07, a mass change: e = 0.784
    /// where Eq. 24 gives 0.785 on the same values, fitted only through the chaos it perturbs).
    fn nominal_distance_sd(&self, case: &Case, params: &[f64]) -> Option<f64> {
        let eq24 = |p: &Uncertain, v: f64| -> Option<f64> {
            Some(calibration::with_values(case, std::slice::from_ref(p), &[v]).ok()?.block.restitution_eq24)
        };
        let variance: f64 = case
            .uncertain
            .iter()
            .filter(|p| case.constrains(&p.key))
            .filter_map(|p| {
                let v = case.parameter(&p.key, p.index.unwrap_or(0))?;
                Some(((eq24(p, v + p.sd)? - eq24(p, v - p.sd)?) / 2.0).powi(2))
            })
            .sum();
        (variance > 0.0).then(|| (params[0] - case.block.restitution_eq24).abs() / variance.sqrt())
    }

    /// The first impact the block rebounds from (a touch-down from micro-rocking that ends in
    /// rest is not one: no restitution law changes it).
    fn onset(&self, _params: &[f64], prediction: &Prediction) -> Option<f64> {
        prediction.first(&[EventKind::Impact])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::tests::rocking_case;

    #[test]
    fn a_coefficient_the_dimensions_uncertainty_could_give_is_eq_24_s_own() {
        let mut case = rocking_case();
        let (b, h) = (0.5, 1.5);
        let eq24 = case.block.restitution_eq24;
        assert_eq!(Restitution.nominal_distance_sd(&case, &[0.5]), None, "nothing is uncertain");
        // H uncertain by 2 cm: e = 1 − 1.5 B²/(B² + H²) moves by 3B²H/(B² + H²)² per metre of H.
        let sd_h = 0.02;
        case.uncertain = vec![Uncertain { key: "H_m".into(), index: None, stated: h, sd: sd_h, bounds: (1.4, 1.6) }];
        let sd_e = 3.0 * b * b * h / (b * b + h * h).powi(2) * sd_h;
        for shift in [0.0, 0.5, 4.0, -4.0] {
            let z = Restitution.nominal_distance_sd(&case, &[eq24 + shift * sd_e]).unwrap();
            assert!((z - f64::abs(shift)).abs() < 1e-3 * f64::abs(shift).max(1.0), "{shift} sd: {z}");
        }
    }
}
