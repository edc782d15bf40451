//! `swivel_jam`: at t0 one caster's swivel stops turning: rigidly (δ̇ ≡ 0: the caster becomes a
//! fixed wheel, a constraint on the platform's motion; it stops at once, with the least loss of
//! kinetic energy, an impulse along the constraint), or against a friction lock (a swivel torque
//! μ N ρ that holds the caster until the platform pulls harder, then lets it slip: a bent or
//! fouled swivel). Parameters: the caster, t0, the lock (0: rigid, 1: friction) and its μ.
//!
//! What the records can tell apart: a lock far stronger than the platform's pull on the caster
//! behaves as the rigid jam, so a rigid verdict means "at least that strong"; a weak lock (μ
//! below a few times the cart's own swivel friction) leaves no trace.

use super::{caster, linspace, onset_bounds, product, sharp_onsets, Effect, RollingCase, Track};
use crate::diagnose::error::Unphysical;
use crate::physics::rolling::{Alteration, Jam};

pub struct SwivelJam;

/// The range of a friction lock's μ, and the values the grid tries.
const MU_RANGE: (f64, f64) = (0.05, 4.0);
const GRID_MU: [f64; 2] = [0.3, 1.5];

impl Effect for SwivelJam {
    fn name(&self) -> &'static str {
        "swivel_jam"
    }

    fn parameter_names(&self) -> &'static [&'static str] {
        &["caster_index", "t0_s", "friction_lock", "mu_lock"]
    }

    fn discrete(&self) -> &'static [bool] {
        &[true, false, true, false]
    }

    fn searched_apart(&self) -> Option<usize> {
        Some(0)
    }

    fn bounds(&self, case: &RollingCase, _: &Track, window: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.0, 3.0), onset_bounds(case, window, 1.0, 0.1), (0.0, 1.0), MU_RANGE]
    }

    fn grid(&self, case: &RollingCase, _: &Track, window: (f64, f64)) -> Vec<Vec<f64>> {
        let rigid = product(&[linspace(0.0, 3.0, 4), sharp_onsets(case, window), vec![0.0], vec![MU_RANGE.1]]);
        let lock = product(&[linspace(0.0, 3.0, 4), sharp_onsets(case, window), vec![1.0], GRID_MU.to_vec()]);
        rigid.into_iter().chain(lock).collect()
    }

    fn alteration(&self, _: &RollingCase, _: &Track, p: &[f64]) -> Result<(Alteration, f64), Unphysical> {
        let mu = (p[2] >= 0.5).then_some(p[3]);
        Ok((Alteration { jam: Some(Jam { caster: caster(p[0]), mu }), ..Alteration::default() }, p[1]))
    }

    fn explain(&self, _: &RollingCase, _: &Track, p: &[f64]) -> String {
        if p[2] >= 0.5 {
            format!(
                "at {:.2} s the swivel of caster {} is held by a friction lock (μ = {:.2}, a torque μ N ρ) that lets it turn only when the platform pulls harder",
                p[1],
                caster(p[0]) + 1,
                p[3]
            )
        } else {
            format!(
                "at {:.2} s the swivel of caster {} jams and the caster no longer turns relative to the platform",
                p[1],
                caster(p[0]) + 1
            )
        }
    }
}
