//! Why a diagnosis, a calibration or a fitted effect refuses what it was given. The messages are
//! the ones a user reads (after the stage's prefix naming the case folder, or the equipment
//! file's line for an `uncertainty` block).

use crate::physics::error::PhysicsError;

/// Why a case cannot be diagnosed, or a model run of it stopped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DiagnoseError {
    /// Nothing recorded to compare a model with.
    #[error("the case has neither an accelerometer nor a camera record to compare with")]
    NoRecords,
    /// A rolling case's floor record too short to run the cart on.
    #[error("the floor record needs at least 3 samples")]
    FloorTooShort,
    /// The model refuses the case's parameters or floor record, or its run stopped.
    #[error(transparent)]
    Physics(#[from] PhysicsError),
    /// A nominal parameter the calibration cannot read or set.
    #[error(transparent)]
    Parameter(#[from] ParameterError),
}

/// A nominal parameter, or its stated uncertainty, that the unit model cannot take.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParameterError {
    /// An `uncertainty` key that is not one of the unit's nominal parameters.
    #[error("`{key}` is not a nominal parameter of this unit (those are {known})")]
    NotNominal { key: String, known: String },
    /// A spread the calibration cannot use.
    #[error("`uncertainty.{key}`: {spread}")]
    Spread { key: String, spread: SpreadError },
    /// A relative sd of a value stated as 0.
    #[error("`uncertainty.{key}`: a relative sd of a stated value of 0 is 0; give `sd`")]
    RelativeOfZero { key: String },
    /// A nominal key the model lists but holds no value of.
    #[error("`{key}` has no stated value")]
    NoStatedValue { key: String },
    /// A key the unit (`block`, `cart`) does not have.
    #[error("`{key}` is not a parameter of this {unit}")]
    Unknown { key: String, unit: &'static str },
    /// An element past the end of a list parameter.
    #[error("{key} has {count} elements")]
    Element { key: &'static str, count: usize },
    /// A value the model refuses (a block with no height, a negative friction coefficient).
    #[error(transparent)]
    Refused(#[from] PhysicsError),
}

/// Why an `uncertainty` entry's spread is not usable.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SpreadError {
    #[error("the standard deviation must be a positive number")]
    NotPositive,
    #[error("give either `sd` or `rel_sd`, not both")]
    Both,
    #[error("give `sd: X` (absolute) or `rel_sd: X` (relative to the stated value)")]
    Neither,
}

/// Why a rolling effect's parameters describe no physical change (a search's trial point that
/// it skips).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum Unphysical {
    /// Moments of a mass change of zero.
    #[error("no mass cannot have moments of ({x:.1}, {y:.1}) kg m")]
    MomentsWithoutMass { x: f64, y: f64 },
    /// A mass change whose centre lies off the platform.
    #[error("{dm_kg:.1} kg cannot have moments of ({x:.1}, {y:.1}) kg m on the platform")]
    OffPlatform { dm_kg: f64, x: f64, y: f64 },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_read_as_before() {
        let spread = ParameterError::Spread { key: "H_m".into(), spread: SpreadError::Both };
        assert_eq!(spread.to_string(), "`uncertainty.H_m`: give either `sd` or `rel_sd`, not both");
        assert_eq!(
            DiagnoseError::from(ParameterError::Unknown { key: "x".into(), unit: "cart" }).to_string(),
            "`x` is not a parameter of this cart"
        );
        assert_eq!(ParameterError::Element { key: "steer0_deg", count: 4 }.to_string(), "steer0_deg has 4 elements");
        assert_eq!(
            DiagnoseError::from(PhysicsError::NotPositive { name: "H_m", value: -1.0 }).to_string(),
            "H_m must be a positive number, got -1"
        );
        assert_eq!(
            Unphysical::OffPlatform { dm_kg: 12.0, x: 3.04, y: -1.0 }.to_string(),
            "12.0 kg cannot have moments of (3.0, -1.0) kg m on the platform"
        );
    }
}
