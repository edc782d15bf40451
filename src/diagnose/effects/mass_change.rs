//! `mass_change`: part of the mass leaves at t0 (contents thrown, as WSU1's water bottles):
//! from then on the unit rocks with a different centre of mass, hence different R, α, I0, p
//! and Eq. 24 restitution. Parameters: t0 and the new centre-of-mass offset f (Table 5's f).

use super::{linspace, product, Case, Effect, Prediction};
use crate::physics::error::PhysicsError;
use crate::physics::rocking::{Block, MassChange as Change, Options, Shape};

pub struct MassChange;

/// The unit after the change: same outline, centre of mass at H(0.5 + f).
fn after(case: &Case, f: f64) -> Result<Block, PhysicsError> {
    let (b, h) = match case.block.shape {
        Shape::Rectangular { b_m, h_m, .. } => (b_m, h_m),
        // A trapezoid's rocking is set by its base and CM: its rectangle equivalent (Table 5).
        Shape::Trapezoidal { b1_m, h_m, .. } => (b1_m, h_m),
    };
    Block::new(Shape::Rectangular { b_m: b, h_m: h, f }, case.block.mass_kg, case.block.g_mps2)
}

fn nominal_f(case: &Case) -> f64 {
    case.block.cm_height_m / case.block.height_m - 0.5
}

impl Effect for MassChange {
    fn name(&self) -> &'static str {
        "mass_change"
    }

    fn parameter_names(&self) -> &'static [&'static str] {
        &["t0_s", "f_after"]
    }

    fn bounds(&self, case: &Case, window: (f64, f64)) -> Vec<(f64, f64)> {
        let f = nominal_f(case);
        vec![((window.0 - 3.0).max(case.t0_s), window.0 + 0.3), ((f - 0.35).max(-0.45), (f + 0.25).min(0.45))]
    }

    fn grid(&self, case: &Case, window: (f64, f64)) -> Vec<Vec<f64>> {
        let bounds = self.bounds(case, window);
        let onsets = linspace(bounds[0].0, bounds[0].1, ((bounds[0].1 - bounds[0].0) / 0.05).round() as usize + 1);
        product(&[onsets, linspace(bounds[1].0, bounds[1].1, 13)])
    }

    fn predict(&self, case: &Case, params: &[f64]) -> Result<Prediction, PhysicsError> {
        let options = Options {
            mass_change: Some(Change { time_s: params[0], after: after(case, params[1])? }),
            ..case.nominal_options()
        };
        Ok(case.simulate(&case.block, &options)?.1)
    }

    fn explain(&self, case: &Case, params: &[f64]) -> String {
        let Ok(new) = after(case, params[1]) else { return "a change of the unit's mass".into() };
        format!(
            "at {:.2} s part of the mass leaves and the centre of mass {} from {:.3} m to {:.3} m (f {:+.3} → {:+.3}; α {:.3} → {:.3} rad)",
            params[0],
            if new.cm_height_m < case.block.cm_height_m { "drops" } else { "rises" },
            case.block.cm_height_m,
            new.cm_height_m,
            nominal_f(case),
            params[1],
            case.block.alpha_rad,
            new.alpha_rad
        )
    }

    fn onset(&self, params: &[f64], _prediction: &Prediction) -> Option<f64> {
        Some(params[0])
    }
}
