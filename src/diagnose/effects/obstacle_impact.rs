//! `obstacle_impact`: an adjacent wall or unit stops the rotation toward one side at an angle
//! θ_w and throws it back with its own restitution e_w (the study's lateral impacts, MC2 on PB1,
//! WSU1 on PS1).

use super::{linspace, product, Case, Effect, Prediction};
use crate::physics::error::PhysicsError;
use crate::physics::rocking::EventKind;
use crate::physics::rocking::{Obstacle, Options};

pub struct ObstacleImpact;

impl Effect for ObstacleImpact {
    fn name(&self) -> &'static str {
        "obstacle_impact"
    }

    fn parameter_names(&self) -> &'static [&'static str] {
        &["side", "angle_rad", "restitution"]
    }

    fn discrete(&self) -> &'static [bool] {
        &[true, false, false]
    }

    fn bounds(&self, case: &Case, _: (f64, f64)) -> Vec<(f64, f64)> {
        let alpha = case.block.alpha_rad;
        vec![(-1.0, 1.0), (0.1 * alpha, (1.5 * alpha).min(case.block.lie_angle_rad - 0.05)), (0.0, 0.95)]
    }

    fn grid(&self, case: &Case, window: (f64, f64)) -> Vec<Vec<f64>> {
        let bounds = self.bounds(case, window);
        product(&[vec![-1.0, 1.0], linspace(bounds[1].0, bounds[1].1, 15), linspace(0.1, 0.9, 5)])
    }

    fn predict(&self, case: &Case, params: &[f64]) -> Result<Prediction, PhysicsError> {
        let side = if params[0] < 0.0 { -1 } else { 1 };
        let options = Options {
            obstacle: Some(Obstacle { side, angle_rad: params[1], restitution: params[2] }),
            ..case.nominal_options()
        };
        Ok(case.simulate(&case.block, &options)?.1)
    }

    fn explain(&self, case: &Case, params: &[f64]) -> String {
        format!(
            "an obstacle on the {} side (θ {}) stops the rotation at {:.3} rad ({:.0} % of the critical angle α) and throws it back with a restitution of {:.2}",
            if params[0] < 0.0 { "−x" } else { "+x" },
            if params[0] < 0.0 { "< 0" } else { "> 0" },
            params[1],
            100.0 * params[1] / case.block.alpha_rad,
            params[2]
        )
    }

    fn onset(&self, _params: &[f64], prediction: &Prediction) -> Option<f64> {
        prediction.first(&[EventKind::WallImpact, EventKind::WallLean])
    }
}
