//! `mass_change`: at t0 a point mass dm is lost (dm < 0: it leaves with its own velocity) or
//! gained (dm > 0: captured at rest on the floor, sharing momentum) at a body offset (dx, dy)
//! from the platform centre: the platform's mass, yaw inertia, centre of mass and wheel loads
//! change. Parameters: t0, dm, its moments dm·dx and dm·dy about the platform centre, and the
//! ramp: the change happens at once (0) or spreads linearly over that time (bottles falling off
//! one by one, a load slid off), a staircase of small changes each entered as the step one is.
//!
//! The moments, not the offsets, are fitted: the wheel loads, which steer the cart, are linear
//! in (dm, dm·dx, dm·dy), so the misfit's long valley along dm·dx = const (a larger mass nearer
//! the centre) lies along an axis the search can follow. The explanation gives the offsets.
//!
//! What the records can tell apart: friction scales with the loads, so a change at the centre
//! alters the motion only through the wheels' and casters' own inertia, which stay the same
//! (a few per cent of the platform's) and through the yaw inertia; an offset change shifts the
//! loads between wheels, which turns the cart. A small centred change is therefore often
//! indistinguishable from none, and dm trades off against the offset.

use super::{onset_bounds, onsets_at, product, Effect, RollingCase, Track};
use crate::diagnose::error::Unphysical;
use crate::physics::rolling::{Alteration, MassChange as Change};

pub struct MassChange;

/// Onsets tried (s from the window's start): a large or far off-centre change shows at once
/// (the accelerometer sees the wheel loads jump), a small, centred or gradual one seconds later.
const ONSETS: [f64; 7] = [-3.0, -2.0, -1.2, -0.6, -0.3, -0.1, 0.0];
/// How long before the window's start a change may begin (s): a gradual loss near the centre
/// has shown up to 3.7 s after it began.
const EARLIEST_S: f64 = 4.0;
/// Largest offset as a fraction of the half-length and half-width.
const REACH: f64 = 0.95;
/// Offsets the grid tries, as fractions of the half-length and half-width: the centre, and the
/// four quadrants half-way and near the edge (dm trades off against the offset, but a start in
/// the wrong quadrant or at half the offset is a local optimum the search does not leave).
const OFFSETS: [(f64, f64); 9] = [
    (0.0, 0.0),
    (0.5, 0.5),
    (-0.5, 0.5),
    (-0.5, -0.5),
    (0.5, -0.5),
    (0.85, 0.85),
    (-0.85, 0.85),
    (-0.85, -0.85),
    (0.85, -0.85),
];
/// Longest ramp (s), and the ramps the grid tries besides a step.
const MAX_RAMP_S: f64 = 2.0;
const GRID_RAMPS_S: [f64; 2] = [0.6, 1.2];
/// Onsets tried for a gradual change (s from the window's start): it shows part-way through.
const RAMP_ONSETS: [f64; 5] = [-3.0, -2.0, -1.2, -0.6, -0.3];

impl Effect for MassChange {
    fn name(&self) -> &'static str {
        "mass_change"
    }

    fn parameter_names(&self) -> &'static [&'static str] {
        &["t0_s", "dm_kg", "moment_x_kgm", "moment_y_kgm", "ramp_s"]
    }

    fn held_at_zero(&self) -> Option<usize> {
        Some(4)
    }

    fn bounds(&self, case: &RollingCase, _: &Track, window: (f64, f64)) -> Vec<(f64, f64)> {
        let (m, a, b) = (case.cart.platform_mass_kg, 0.5 * case.cart.length_m, 0.5 * case.cart.width_m);
        vec![
            onset_bounds(case, window, EARLIEST_S, 0.1),
            (-0.7 * m, 1.0 * m),
            (-REACH * a * m, REACH * a * m),
            (-REACH * b * m, REACH * b * m),
            (0.0, MAX_RAMP_S),
        ]
    }

    fn grid(&self, case: &RollingCase, _: &Track, window: (f64, f64)) -> Vec<Vec<f64>> {
        let (m, a, b) = (case.cart.platform_mass_kg, 0.5 * case.cart.length_m, 0.5 * case.cart.width_m);
        let steps =
            product(&[onsets_at(case, window, &ONSETS), vec![-0.4 * m, -0.15 * m, 0.2 * m, 0.5 * m], vec![0.0]]);
        let ramps = product(&[onsets_at(case, window, &RAMP_ONSETS), vec![-0.4 * m, -0.15 * m], GRID_RAMPS_S.to_vec()]);
        steps
            .into_iter()
            .chain(ramps)
            .flat_map(|p| OFFSETS.iter().map(move |(x, y)| vec![p[0], p[1], p[1] * x * a, p[1] * y * b, p[2]]))
            .collect()
    }

    fn alteration(&self, case: &RollingCase, _: &Track, p: &[f64]) -> Result<(Alteration, f64), Unphysical> {
        let at_m = offset(p);
        if p[1] == 0.0 && (p[2] != 0.0 || p[3] != 0.0) {
            return Err(Unphysical::MomentsWithoutMass { x: p[2], y: p[3] });
        }
        if at_m[0].abs() > REACH * 0.5 * case.cart.length_m || at_m[1].abs() > REACH * 0.5 * case.cart.width_m {
            return Err(Unphysical::OffPlatform { dm_kg: p[1], x: p[2], y: p[3] });
        }
        let mass = Some(Change { dm_kg: p[1], at_m });
        Ok((Alteration { mass, ramp_s: p[4], ..Alteration::default() }, p[0]))
    }

    fn explain(&self, case: &RollingCase, _: &Track, p: &[f64]) -> String {
        let [dx, dy] = offset(p);
        format!(
            "{} {:.2} s {:.1} kg ({:.0} % of the platform) is {} at ({:+.2} m, {:+.2} m) from the platform centre (body axes), moving the centre of mass to ({:+.3} m, {:+.3} m)",
            if p[4] > 0.0 { format!("over {:.2} s from", p[4]) } else { "at".to_string() },
            p[0],
            p[1].abs(),
            100.0 * p[1].abs() / case.cart.platform_mass_kg,
            if p[1] < 0.0 { "lost" } else { "added" },
            dx,
            dy,
            p[2] / (case.cart.platform_mass_kg + p[1]),
            p[3] / (case.cart.platform_mass_kg + p[1]),
        )
    }
}

/// The change's offset (dx, dy) from the platform centre (m) from its mass and moments: the
/// centre when no mass changes.
fn offset(p: &[f64]) -> [f64; 2] {
    if p[1] == 0.0 {
        [0.0, 0.0]
    } else {
        [p[2] / p[1], p[3] / p[1]]
    }
}
