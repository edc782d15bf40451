//! The physics library of the diagnosis: one file per effect the nominal rigid-block model
//! leaves out. Adding one is a new file implementing [`Effect`] and a line in [`library`].

use super::{Case, Prediction};
use crate::physics::error::PhysicsError;

mod flexibility;
mod mass_change;
mod obstacle_impact;
mod restitution;
mod sensor_tilt;
mod sliding;

/// A hypothesis: the nominal model plus one physical effect with a few parameters.
pub trait Effect: Sync {
    /// The verdict this effect stands for (the diagnosis vocabulary).
    fn name(&self) -> &'static str;
    fn parameter_names(&self) -> &'static [&'static str];
    /// Parameters that take a few discrete values (a side): fitted by the grid only.
    fn discrete(&self) -> &'static [bool] {
        &[]
    }
    /// True when the prediction is affine in the effect's continuous parameters (they change
    /// what a sensor reads, not the motion): χ² is then quadratic in them but for the small
    /// share they have in the weights, and the fit holds them at the grid's point while it
    /// searches the unit's values and solves them over the whole record, instead of searching
    /// them.
    fn affine(&self) -> bool {
        false
    }
    /// Plausible ranges, given the case and where the mismatch was found.
    fn bounds(&self, case: &Case, window: (f64, f64)) -> Vec<(f64, f64)>;
    /// Starting points covering the ranges.
    fn grid(&self, case: &Case, window: (f64, f64)) -> Vec<Vec<f64>>;
    fn predict(&self, case: &Case, params: &[f64]) -> Result<Prediction, PhysicsError>;
    /// One clause for the explanation, with the fitted values in engineering terms.
    fn explain(&self, case: &Case, params: &[f64]) -> String;
    /// When the effect first acts in this prediction; None when it acts all along.
    fn onset(&self, _params: &[f64], _prediction: &Prediction) -> Option<f64> {
        None
    }
    /// The parameter (its index) for which the nominal model itself has a value, and that value
    /// on `case` (`restitution`'s e: Eq. 24); None when the effect has none. That value is as
    /// uncertain as the case's uncertain values make it: an effect whose parameter lies within
    /// [`NOMINAL_SD`] standard deviations of it is the nominal model within what the user knows,
    /// however well it fits.
    fn nominal_counterpart(&self, _case: &Case) -> Option<(usize, f64)> {
        None
    }
}

/// See [`Effect::nominal_counterpart`].
pub const NOMINAL_SD: f64 = 3.0;

pub fn library() -> &'static [&'static dyn Effect] {
    &[
        &sliding::Sliding,
        &mass_change::MassChange,
        &restitution::Restitution,
        &flexibility::Flexibility,
        &obstacle_impact::ObstacleImpact,
        &sensor_tilt::SensorTilt,
    ]
}

/// The library's effect of that name (a candidate's `effect`).
pub fn named(name: &str) -> Option<&'static dyn Effect> {
    library().iter().copied().find(|e| e.name() == name)
}

/// `count` values from `lo` to `hi`, evenly spaced.
pub fn linspace(lo: f64, hi: f64, count: usize) -> Vec<f64> {
    (0..count).map(|i| lo + (hi - lo) * i as f64 / (count.max(2) - 1) as f64).collect()
}

/// Every combination of the axes' values.
pub fn product(axes: &[Vec<f64>]) -> Vec<Vec<f64>> {
    axes.iter().fold(vec![Vec::new()], |points, axis| {
        points.iter().flat_map(|p| axis.iter().map(move |v| [p.as_slice(), &[*v]].concat())).collect()
    })
}
