//! The rolling physics library: one file per effect the nominal 4WMC cart leaves out, each an
//! [`Alteration`] of `physics::rolling`'s no-slip model from the moment it begins.

use super::{RollingCase, Track};
use crate::diagnose::error::Unphysical;
use crate::physics::rolling::Alteration;

mod caster_brake;
mod lateral_impact;
mod mass_change;
mod swivel_jam;

pub use crate::diagnose::effects::{linspace, product};

/// The accelerometer dates an abrupt change (a brake, a jam, an impact) to within a few samples.
const SHARP: [f64; 4] = [-0.1, -0.05, -0.02, 0.0];

/// A hypothesis: the nominal cart plus one physical effect with a few parameters.
pub trait Effect: Sync {
    /// The verdict this effect stands for.
    fn name(&self) -> &'static str;
    fn parameter_names(&self) -> &'static [&'static str];
    /// Parameters that take a few discrete values (a caster, a side): fitted by the grid only.
    fn discrete(&self) -> &'static [bool] {
        &[]
    }
    /// A parameter that a search holds at zero when it starts there: a ramp, so that a step is
    /// searched as a step (and a gradual change, started from the grid's ramps, as one).
    fn held_at_zero(&self) -> Option<usize> {
        None
    }
    /// A discrete parameter each of whose values gets a search from its best grid point (a
    /// caster: a brake or a jam on another caster can fit the grid's first second better).
    fn searched_apart(&self) -> Option<usize> {
        None
    }
    /// Plausible ranges, given the case, the nominal cart and where the mismatch was found.
    fn bounds(&self, case: &RollingCase, nominal: &Track, window: (f64, f64)) -> Vec<(f64, f64)>;
    /// Starting points covering the ranges.
    fn grid(&self, case: &RollingCase, nominal: &Track, window: (f64, f64)) -> Vec<Vec<f64>>;
    /// The physics, and the time it begins.
    fn alteration(&self, case: &RollingCase, nominal: &Track, params: &[f64]) -> Result<(Alteration, f64), Unphysical>;
    /// Floor samples of `track` (this effect's run) whose accelerometer reading the effect
    /// cannot predict (see [`Track::accel_unseen`]); empty: every one.
    fn accel_unseen(&self, _case: &RollingCase, _nominal: &Track, _params: &[f64], _track: &Track) -> Vec<bool> {
        Vec::new()
    }
    /// One clause for the explanation, with the fitted values in engineering terms.
    fn explain(&self, case: &RollingCase, nominal: &Track, params: &[f64]) -> String;
}

pub fn library() -> &'static [&'static dyn Effect] {
    &[&lateral_impact::LateralImpact, &mass_change::MassChange, &caster_brake::CasterBrake, &swivel_jam::SwivelJam]
}

pub fn onset_bounds(case: &RollingCase, window: (f64, f64), before: f64, after: f64) -> (f64, f64) {
    ((window.0 - before).max(case.t0_s), (window.0 + after).min(case.end_s() - case.dt_s))
}

/// Onsets of an abrupt change: just before the window's start.
pub fn sharp_onsets(case: &RollingCase, window: (f64, f64)) -> Vec<f64> {
    onsets_at(case, window, &SHARP)
}

/// Onset times at these offsets (s) from the window's start, inside the record.
pub fn onsets_at(case: &RollingCase, window: (f64, f64), offsets: &[f64]) -> Vec<f64> {
    offsets.iter().map(|d| (window.0 + d).clamp(case.t0_s, case.end_s() - case.dt_s)).collect()
}

/// Caster numbers as the equipment file counts them (1..4) from a 0-based index parameter.
pub fn caster(param: f64) -> usize {
    (param.round().clamp(0.0, 3.0)) as usize
}
