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
use crate::diagnose::error::Unphysical;
use crate::physics::rolling::{Alteration, Wall};

pub struct LateralImpact;

/// Contact durations (s) the grid tries: a stiff frame; a compliant neighbour.
const WALL_S: f64 = 0.02;
/// A wall's contact shorter than this many floor samples is not resolved by the accelerometer:
/// what it reads around it is the impulse through its anti-alias filter at its sampling phase
/// (a spike, or nothing between two samples), which no case describes, so it is not judged there.
const RESOLVED_SAMPLES: f64 = 5.0;
/// The most samples in a row a stiff wall leaves unjudged: its impact is over within the
/// [`RESOLVED_SAMPLES`] its contact is shorter than (plus the sensor's filter on each side); a
/// corner that stays at the wall past that rests on it, which the accelerometer resolves.
const UNSEEN_RUN: usize = 2 * RESOLVED_SAMPLES as usize + 2;
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

    fn alteration(&self, case: &RollingCase, nominal: &Track, p: &[f64]) -> Result<(Alteration, f64), Unphysical> {
        let (axis, sign) = side(p[0]);
        let (position, onset) = wall_for(case, nominal, axis, sign, p[1]);
        let wall =
            Wall { axis, side: sign, position_m: position, restitution: p[2], contact_s: p[3], neighbour: p[4] >= 0.5 };
        Ok((Alteration { wall: Some(wall), ..Alteration::default() }, onset))
    }

    /// A stiff wall's contacts: every sample interval in which a corner may touch the wall (it
    /// is past it, or within the interval's travel and a millimetre of it), widened by a sample
    /// on each side for the sensor's filter, at most [`UNSEEN_RUN`] samples in a row. (The
    /// evidence counts each unseen sample as noise, so hiding samples earns a fit nothing.)
    fn accel_unseen(&self, case: &RollingCase, nominal: &Track, p: &[f64], track: &Track) -> Vec<bool> {
        if p[4] >= 0.5 || p[3] >= RESOLVED_SAMPLES * case.dt_s {
            return Vec::new();
        }
        let (axis, sign) = side(p[0]);
        let (position, _) = wall_for(case, nominal, axis, sign, p[1]);
        let n = track.x_m.len();
        let k0 = track.onset_s.map_or(0, |t| case.index(t));
        let depth = |k: usize| reach(case, track, axis, sign, k) - sign * position;
        let mut unseen = vec![false; n];
        for k in k0..n.saturating_sub(1) {
            let (a, b) = (depth(k), depth(k + 1));
            if a.max(b) > -((b - a).abs() + 1e-3) {
                unseen[k.saturating_sub(1)..(k + 3).min(n)].iter_mut().for_each(|u| *u = true);
            }
        }
        let mut run = 0;
        for u in &mut unseen {
            run = if *u { run + 1 } else { 0 };
            *u &= run <= UNSEEN_RUN;
        }
        unseen
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::rolling::evidence::Evidence;
    use crate::diagnose::rolling::test_cart;
    use crate::diagnose::Observed;
    use crate::physics::rolling::Options;

    /// MC2 pushed along +X for `push_s` by a 2 m/s^2 floor acceleration, then coasting, for 3 s.
    fn pushed_cart(push_s: f64) -> (RollingCase, Track) {
        let dt = 0.005;
        let ax: Vec<f64> = (0..601).map(|k| if (k as f64) * dt < push_s { -2.0 } else { 0.0 }).collect();
        let options = Options {
            yaw0_rad: 0.0,
            steer0_rad: [0.0; 4],
            method: crate::diagnose::rolling::METHOD,
            ..Options::default()
        };
        let case = test_cart("pushed", ax, vec![0.0; 601], options);
        let nominal = case.nominal().expect("the nominal cart runs");
        (case, nominal)
    }

    #[test]
    fn a_stiff_walls_contact_is_not_judged_on_the_accelerometer_and_a_neighbours_is() {
        let (mut case, nominal) = pushed_cart(0.8);
        let gain = reach(&case, &nominal, 0, 1.0, 600) - reach(&case, &nominal, 0, 1.0, 0);
        assert!(gain > 0.05, "the push moves the cart {gain:.3} m along +X");
        // A stiff frame (10 ms, e = 0.5) where the nominal cart's corner is at 1.5 s.
        let wall = [0.0, 1.5, 0.5, 0.01, 0.0];
        let (alteration, onset) = LateralImpact.alteration(&case, &nominal, &wall).unwrap();
        let mut track = case.altered(&nominal, &alteration, onset, case.end_s(), None).unwrap();
        let unseen = LateralImpact.accel_unseen(&case, &nominal, &wall, &track);
        let (position, _) = wall_for(&case, &nominal, 0, 1.0, 1.5);
        let past: Vec<usize> = (0..601).filter(|&k| reach(&case, &track, 0, 1.0, k) > position).collect();
        assert!(!past.is_empty(), "a corner passes the wall at some sample");
        assert!(past.iter().all(|&k| unseen[k]), "every sample in contact is unseen");
        let count = unseen.iter().filter(|u| **u).count();
        assert!(count <= past.len() + 12, "{count} unseen samples for {} in contact", past.len());
        assert!(!unseen[..past[0] - 3].iter().any(|u| *u), "nothing is unseen well before the contact");
        // The records: what the walled cart read, and the same with a spike of 50 m/s^2 (what a
        // sensor may show of the impulse) at the contact. The two misfit the model alike.
        let time_s: Vec<f64> = (0..601).map(|k| k as f64 * case.dt_s).collect();
        let mut spiked = track.ax_abs_mps2.clone();
        spiked[past[0]] += 50.0;
        let misfit = |case: &mut RollingCase, value: Vec<f64>, track: &Track| {
            case.accel = Some(Observed { time_s: time_s.clone(), value });
            Evidence::new(case, 4.0).misfit(track).chi2
        };
        track.accel_unseen = unseen;
        let plain = misfit(&mut case, track.ax_abs_mps2.clone(), &track);
        assert_eq!(plain, misfit(&mut case, spiked.clone(), &track));
        // Against its own readings the walled cart misfits only where it is unseen, each sample
        // counted as noise (z = 1): hiding a sample earns a fit nothing.
        assert_eq!(plain, count as f64);
        // A compliant neighbour's contact lasts tenths of a second: the accelerometer sees it,
        // and judges it.
        let neighbour = [0.0, 1.5, 0.5, 0.15, 1.0];
        assert!(LateralImpact.accel_unseen(&case, &nominal, &neighbour, &track).is_empty());
        track.accel_unseen = Vec::new();
        assert!(misfit(&mut case, spiked, &track) > plain + 1e6);
    }

    #[test]
    fn a_corner_resting_on_a_stiff_wall_is_judged_past_its_impact() {
        // Pushed all along and nearly plastic (e = 0.05): after the impact the floor presses the
        // corner on the wall, within a millimetre of it; only the impact's samples go unjudged.
        let (case, nominal) = pushed_cart(3.0);
        let wall = [0.0, 1.0, 0.05, 0.01, 0.0];
        let (alteration, onset) = LateralImpact.alteration(&case, &nominal, &wall).unwrap();
        let track = case.altered(&nominal, &alteration, onset, case.end_s(), None).unwrap();
        let (position, _) = wall_for(&case, &nominal, 0, 1.0, 1.0);
        let near = (0..601).filter(|&k| reach(&case, &track, 0, 1.0, k) > position - 1e-3).count();
        assert!(near > 2 * UNSEEN_RUN, "the corner rests at the wall for {near} samples");
        let unseen = LateralImpact.accel_unseen(&case, &nominal, &wall, &track);
        let longest = unseen.split(|u| !*u).map(<[bool]>::len).max().unwrap_or(0);
        assert!((1..=UNSEEN_RUN).contains(&longest), "{longest} unseen samples in a row");
    }
}
