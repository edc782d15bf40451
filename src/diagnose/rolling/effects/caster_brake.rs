//! `caster_brake`: at t0 one caster's wheel locks and drags: it no longer spins, and the floor
//! resists its slide along the heading with μ N tanh(v/ε) instead of rolling resistance; or a
//! pad whose drag builds up linearly to μ N over a ramp (0: the wheel locks at once). Parameters:
//! the caster, t0, μ, the ramp. (A dragging pad may leave the wheel spinning; its spin inertia,
//! m_w/2 of a disc, is a fraction of a per cent of the cart's mass and is not told apart.)

use super::{caster, linspace, onset_bounds, onsets_at, product, Effect, RollingCase, Track};
use crate::diagnose::error::Unphysical;
use crate::physics::rolling::{Alteration, Brake};

pub struct CasterBrake;

/// Onsets tried (s from the window's start): a locked wheel shows within a few samples while
/// the cart moves, a second or more later if it locks while the cart stands nearly still; a pad
/// whose drag builds up over some tenths of a second shows once the drag is strong.
const ONSETS: [f64; 8] = [-1.3, -0.8, -0.4, -0.2, -0.1, -0.05, -0.02, 0.0];
/// How long before the window's start a wheel may have locked (s).
const EARLIEST_S: f64 = 1.5;
/// Longest ramp (s), and the ramp the grid tries besides a lock.
const MAX_RAMP_S: f64 = 0.8;
const GRID_RAMP_S: f64 = 0.25;
/// Onsets tried for a building drag (s from the window's start): it shows part-way up.
const RAMP_ONSETS: [f64; 3] = [-0.4, -0.2, -0.1];

impl Effect for CasterBrake {
    fn name(&self) -> &'static str {
        "caster_brake"
    }

    fn parameter_names(&self) -> &'static [&'static str] {
        &["caster_index", "t0_s", "mu_drag", "ramp_s"]
    }

    fn discrete(&self) -> &'static [bool] {
        &[true, false, false, false]
    }

    fn searched_apart(&self) -> Option<usize> {
        Some(0)
    }

    fn held_at_zero(&self) -> Option<usize> {
        Some(3)
    }

    fn bounds(&self, case: &RollingCase, _: &Track, window: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.0, 3.0), onset_bounds(case, window, EARLIEST_S, 0.1), (0.02, 1.0), (0.0, MAX_RAMP_S)]
    }

    fn grid(&self, case: &RollingCase, _: &Track, window: (f64, f64)) -> Vec<Vec<f64>> {
        let casters = linspace(0.0, 3.0, 4);
        let locked = product(&[casters.clone(), onsets_at(case, window, &ONSETS), vec![0.2, 0.5], vec![0.0]]);
        let ramped = product(&[casters, onsets_at(case, window, &RAMP_ONSETS), vec![0.2, 0.5], vec![GRID_RAMP_S]]);
        locked.into_iter().chain(ramped).collect()
    }

    fn alteration(&self, _: &RollingCase, _: &Track, p: &[f64]) -> Result<(Alteration, f64), Unphysical> {
        let brake = Some(Brake { caster: caster(p[0]), mu: p[2] });
        Ok((Alteration { brake, ramp_s: p[3], ..Alteration::default() }, p[1]))
    }

    fn explain(&self, _: &RollingCase, _: &Track, p: &[f64]) -> String {
        format!(
            "at {:.2} s the wheel of caster {} {} a friction coefficient of {:.3}{}",
            p[1],
            caster(p[0]) + 1,
            if p[3] > 0.0 { "is braked by a pad whose drag builds up to" } else { "locks and drags with" },
            p[2],
            if p[3] > 0.0 { format!(" over {:.2} s", p[3]) } else { String::new() }
        )
    }
}
