//! Signal processing on plain slices: no files, no pipeline.

pub mod baseline;
pub mod resample;
pub mod resample_bandlimited;
pub mod sync;
pub mod synthetic_motion;
pub mod toppling;
pub mod welch;

#[cfg(test)]
pub(crate) mod test_support;
