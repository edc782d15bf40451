//! `lateral_impact`: the platform strikes a wall or a neighbour across one floor axis (±X, ±Y)
//! at some distance, and rebounds with a restitution e: a spring–dashpot contact at each corner
//! past the wall, scaled by the corner's effective mass so that a contact lasts a fitted
//! duration (a stiff frame some milliseconds, a neighbour's mattress or bumper a few tenths of a
//! second) and rebounds with e; or, the discrete `neighbour` variant, a compliant neighbour whose
//! stiffness and damping are its own (fixed, with the cart's mass), pushing only. The distance is fitted as the time the nominal cart's corner
//! first reaches it (the farthest the corners have gone toward that side by then): the fit then
//! moves in time, where the records located the disagreement. Parameters: side, contact time,
//! e, contact duration, neighbour (0: wall, 1: compliant neighbour).

use super::{linspace, onset_bounds, onsets_at, product, Effect, RollingCase, Track};
use crate::physics::rolling::{Alteration, Wall};

pub struct LateralImpact;

/// Contact durations (s) the grid tries: a stiff frame; a compliant neighbour.
const WALL_S: f64 = 0.02;
const NEIGHBOUR_S: [f64; 2] = [0.05, 0.15];

/// (axis, side) of side index 0..3: +X, −X, +Y, −Y.
fn side(param: f64) -> (usize, f64) {
    match param.round().clamp(0.0, 3.0) as usize {
        0 => (0, 1.0),
        1 => (0, -1.0),
        2 => (1, 1.0),
        _ => (1, -1.0),
    }
}

/// The platform's farthest corner toward (axis, side) at sample k, in the displacement frame.
fn reach(case: &RollingCase, nominal: &Track, axis: usize, sign: f64, k: usize) -> f64 {
    let (a, b) = (0.5 * case.cart.length_m, 0.5 * case.cart.width_m);
    let (s, c) = nominal.yaw_rad[k].sin_cos();
    let centre = [nominal.x_m[k], nominal.y_m[k]][axis];
    [(a, b), (-a, b), (-a, -b), (a, -b)]
        .iter()
        .map(|&(px, py)| sign * (centre + [c * px - s * py, s * px + c * py][axis]))
        .fold(f64::NEG_INFINITY, f64::max)
}

/// The wall (its coordinate) that the nominal cart first touches at time t, and when it does.
fn wall_for(case: &RollingCase, nominal: &Track, axis: usize, sign: f64, t: f64) -> (f64, f64) {
    let k_end = (((t - case.t0_s) / case.dt_s).round().max(0.0) as usize).min(case.samples() - 1);
    let farthest = (0..=k_end).map(|k| reach(case, nominal, axis, sign, k)).fold(f64::NEG_INFINITY, f64::max);
    let first = (0..=k_end).find(|&k| reach(case, nominal, axis, sign, k) >= farthest).unwrap_or(k_end);
    // Placed a hair beyond: the corner touches it between sample `first` − 1 and `first`.
    (sign * farthest, case.t0_s + first.saturating_sub(1) as f64 * case.dt_s)
}

impl Effect for LateralImpact {
    fn name(&self) -> &'static str {
        "lateral_impact"
    }

    fn parameter_names(&self) -> &'static [&'static str] {
        &["side_index", "contact_s", "restitution", "contact_duration_s", "neighbour"]
    }

    fn discrete(&self) -> &'static [bool] {
        &[true, false, false, false, true]
    }

    fn bounds(&self, case: &RollingCase, _: &Track, window: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.0, 3.0), onset_bounds(case, window, 1.0, 0.2), (0.05, 0.95), (0.005, 0.4), (0.0, 1.0)]
    }

    fn grid(&self, case: &RollingCase, _: &Track, window: (f64, f64)) -> Vec<Vec<f64>> {
        // A soft impact (low e, low speed) may show only some tenths of a second after the contact.
        let sides_and_times =
            product(&[linspace(0.0, 3.0, 4), onsets_at(case, window, &[-0.6, -0.4, -0.25, -0.12, -0.05, 0.0])]);
        let wall = product(&[vec![0.2, 0.5, 0.8], vec![WALL_S], vec![0.0]]);
        let neighbour = product(&[vec![0.3, 0.7], NEIGHBOUR_S.to_vec(), vec![1.0]]);
        sides_and_times
            .iter()
            .flat_map(|p| wall.iter().chain(&neighbour).map(move |q| [p.as_slice(), q].concat()))
            .collect()
    }

    fn alteration(&self, case: &RollingCase, nominal: &Track, p: &[f64]) -> Result<(Alteration, f64), String> {
        let (axis, sign) = side(p[0]);
        let (position, onset) = wall_for(case, nominal, axis, sign, p[1]);
        let wall =
            Wall { axis, side: sign, position_m: position, restitution: p[2], contact_s: p[3], neighbour: p[4] >= 0.5 };
        Ok((Alteration { wall: Some(wall), ..Alteration::default() }, onset))
    }

    fn explain(&self, case: &RollingCase, nominal: &Track, p: &[f64]) -> String {
        let (axis, sign) = side(p[0]);
        let (position, onset) = wall_for(case, nominal, axis, sign, p[1]);
        format!(
            "at {:.2} s a corner of the platform strikes {} across {}{} at {:.3} m from the platform centre's start (its nearest corner was {:.3} m from it), rebounding with a restitution of {:.2} after a contact of {:.0} ms",
            onset + case.dt_s,
            if p[4] >= 0.5 { "a compliant neighbour" } else { "a wall" },
            if sign > 0.0 { "+" } else { "−" },
            ["X", "Y"][axis],
            position.abs(),
            sign * position - reach(case, nominal, axis, sign, 0),
            p[2],
            1e3 * p[3]
        )
    }
}
