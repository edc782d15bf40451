//! Signal processing on plain slices: no files, no pipeline.

pub mod baseline;
pub mod resample;
pub mod synthetic_motion;
