//! `sliding`: the base slides on the floor under Coulomb friction (static μ_s, kinetic μ_k ≤ μ_s):
//! the sliding–rocking block of `physics::rocking` (stick, slide, rock, slide-rock). Below
//! tan α the unit slides instead of rocking; above it, it rocks and its pivot slips where the
//! contact cannot carry the horizontal force (short, sparse slips, as PS2's 1 cm slip).
//!
//! Two variants, a discrete parameter (`coupled`, 1 or 0): the block above, and the *uncoupled*
//! simplification (the base slides only while flat, rocking starts from the floor's acceleration
//! as if the base held and its pivot never slips), which is how sliding is often modelled and
//! what a block does whose slips are too short to disturb its rocking much: it rocks as the
//! nominal model says *and* slides between rocking phases, which the coupled block, sliding
//! instead of rocking below tan α, cannot fit.
//!
//! The evidence is mostly the top accelerometer: while the base slips flat, the unit's
//! acceleration is the friction, a plateau at μ_k(g + a_v) where the floor goes beyond it. The
//! starting grid therefore includes the plateau levels the records show (accelerometer readings
//! well below the floor's at the same instant), besides an even grid over μ_s.

use super::{linspace, product, Case, Effect, Prediction};
use crate::physics::error::PhysicsError;
use crate::physics::rocking::EventKind;
use crate::physics::rocking::{Friction, Options};

pub struct Sliding;

/// A reading this many noise deviations below the floor's is a candidate friction plateau.
const PLATEAU_SIGMA: f64 = 5.0;
/// Plateau levels added to the grid at most.
const PLATEAU_LEVELS: usize = 8;

/// μ_k candidates from the records: |top|/(g + a_v) where the top reads clearly less than the
/// floor (a unit that sticks or rocks little reads about the floor), inside the window.
fn plateau_levels(case: &Case, window: (f64, f64)) -> Vec<f64> {
    let Some(accel) = &case.accel else { return Vec::new() };
    let sigma = PLATEAU_SIGMA * case.accel_noise_mps2;
    let n = case.floor_ax_mps2.len();
    let mut levels: Vec<f64> = accel
        .time_s
        .iter()
        .zip(&accel.value)
        .filter(|(t, v)| **t >= window.0 - 0.5 && **t <= window.1 && v.is_finite())
        .filter_map(|(t, v)| {
            let k = ((t - case.t0_s) / case.dt_s).round();
            if !(k >= 0.0 && (k as usize) < n) {
                return None;
            }
            let (ax, az) = (case.floor_ax_mps2[k as usize], case.floor_az_mps2[k as usize]);
            (ax.abs() - v.abs() > sigma && v.abs() > sigma && v * ax > 0.0).then(|| v.abs() / (case.block.g_mps2 + az))
        })
        .collect();
    levels.sort_by(f64::total_cmp);
    if levels.is_empty() {
        return levels;
    }
    (0..PLATEAU_LEVELS).map(|i| levels[i * (levels.len() - 1) / (PLATEAU_LEVELS - 1)]).collect()
}

impl Effect for Sliding {
    fn name(&self) -> &'static str {
        "sliding"
    }

    fn parameter_names(&self) -> &'static [&'static str] {
        &["mu_s", "mu_k_over_mu_s", "coupled"]
    }

    fn discrete(&self) -> &'static [bool] {
        &[false, false, true]
    }

    fn bounds(&self, case: &Case, _: (f64, f64)) -> Vec<(f64, f64)> {
        // Slips during rocking need μ_s above tan α but below Shenton's critical value, which
        // grows with the floor's acceleration: the range reaches well past tan α.
        vec![(0.02, 2.5 * case.block.alpha_rad.tan()), (0.5, 1.0), (0.0, 1.0)]
    }

    fn grid(&self, case: &Case, window: (f64, f64)) -> Vec<Vec<f64>> {
        let bounds = self.bounds(case, window);
        let (lo, hi) = bounds[0];
        let tan = case.block.alpha_rad.tan();
        let mut points = product(&[linspace(lo, hi, 30), vec![0.7, 0.85, 1.0], vec![1.0]]);
        // Uncoupled: above tan α the block rocks before it slides, as the nominal model.
        points.extend(product(&[linspace(lo, tan, 16), vec![0.85, 1.0], vec![0.0]]));
        for level in plateau_levels(case, window) {
            for ratio in [1.0, 0.85, 0.7] {
                let mu_s = level / ratio;
                if mu_s > lo && mu_s < hi {
                    points.push(vec![mu_s, ratio, 1.0]);
                    if mu_s < tan && ratio > 0.8 {
                        points.push(vec![mu_s, ratio, 0.0]);
                    }
                }
            }
        }
        points
    }

    fn predict(&self, case: &Case, params: &[f64]) -> Result<Prediction, PhysicsError> {
        let friction = Friction { static_mu: params[0], kinetic_mu: params[0] * params[1], coupled: params[2] >= 0.5 };
        let options = Options { friction: Some(friction), ..case.nominal_options() };
        Ok(case.simulate(&case.block, &options)?.1)
    }

    fn explain(&self, case: &Case, params: &[f64]) -> String {
        let tan = case.block.alpha_rad.tan();
        let how = if params[2] < 0.5 {
            "uncoupled: the base slides while the block is flat, and rocking starts from the floor's acceleration on a pivot that holds"
        } else if params[0] < tan {
            "below tan α: the unit slides where the nominal model has it rock"
        } else {
            "above tan α: it rocks, and its pivot slips where the contact cannot carry the floor's pull"
        };
        format!(
            "the base slides on the floor with Coulomb friction μ_s = {:.3}, μ_k = {:.3} ({how}, tan α = {tan:.3}); while it slips the unit cannot follow floor accelerations above {:.2} m/s^2",
            params[0],
            params[0] * params[1],
            params[0] * params[1] * case.block.g_mps2
        )
    }

    fn onset(&self, _params: &[f64], prediction: &Prediction) -> Option<f64> {
        prediction.first(&[EventKind::SlideStart])
    }
}
