//! What a physical model refuses, and why a run of it stops. The messages are the ones a user
//! reads (after the stage's prefix naming the record).

/// A model's refusal of its parameters or its floor record, or the reason its run stopped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PhysicsError {
    /// A parameter that must be a positive number.
    #[error("{name} must be a positive number, got {value}")]
    NotPositive { name: &'static str, value: f64 },
    /// A value of the named parameter the model does not take.
    #[error("{message}")]
    Invalid { parameter: &'static str, message: String },
    /// A parameter, or a combination of options, the model does not take (the message says which).
    #[error("{0}")]
    Parameter(String),
    /// A floor record shorter than two samples.
    #[error("the floor record has {0} sample(s); at least 2 are needed")]
    TooFewSamples(usize),
    /// A sample interval that is not a positive number of seconds.
    #[error("the sample interval must be positive, got {0} s")]
    SampleInterval(f64),
    /// A floor sample that is not a finite number.
    #[error("sample {sample} (t = {t_s} s) is not a finite number")]
    NotFinite { sample: usize, t_s: f64 },
    /// A floor record the model cannot run on otherwise (its components' lengths, a floor falling
    /// faster than gravity, samples it does not have).
    #[error("{0}")]
    Floor(String),
    /// Impacts or regime changes piling up within one sample interval.
    #[error(
        "{what} chatter near t = {t_s:.4} s did not settle; raise `rest_amplitude_rad` (now {rest_amplitude_rad})"
    )]
    Chatter { what: &'static str, t_s: f64, rest_amplitude_rad: f64 },
    /// A run that left what the model covers, or its solver's budget (the message says where).
    #[error("{0}")]
    Stopped(String),
}

/// A run that stopped part way, with the right-hand-side evaluations it had spent by then (a fit
/// charges them against its allowance). It reads as its [`PhysicsError`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{error}")]
pub struct RunStopped {
    pub error: PhysicsError,
    pub spent: usize,
}

impl PhysicsError {
    /// The parameter the refusal is about, where it names one.
    pub fn parameter(&self) -> Option<&'static str> {
        match self {
            PhysicsError::NotPositive { name, .. } => Some(name),
            PhysicsError::Invalid { parameter, .. } => Some(parameter),
            _ => None,
        }
    }
}

/// The numerics that still speak in messages (the diagnosis) take a model's error as its text.
impl From<PhysicsError> for String {
    fn from(e: PhysicsError) -> Self {
        e.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_read_as_before() {
        assert_eq!(
            PhysicsError::NotPositive { name: "H_m", value: -1.0 }.to_string(),
            "H_m must be a positive number, got -1"
        );
        assert_eq!(
            PhysicsError::Chatter { what: "impact", t_s: 1.23456, rest_amplitude_rad: 1e-6 }.to_string(),
            "impact chatter near t = 1.2346 s did not settle; raise `rest_amplitude_rad` (now 0.000001)"
        );
        assert_eq!(
            PhysicsError::NotFinite { sample: 3, t_s: 0.015 }.to_string(),
            "sample 3 (t = 0.015 s) is not a finite number"
        );
    }
}
