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

/// Σ a[i]·b[i] in four partial sums: lets the compiler keep four multiply-adds in flight (an
/// in-order sum cannot be vectorised).
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let (a4, b4) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = a4.remainder().iter().zip(b4.remainder()).map(|(x, y)| x * y).sum();
    for (x, y) in a4.zip(b4) {
        for i in 0..4 {
            acc[i] += x[i] * y[i];
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}
