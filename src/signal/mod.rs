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

/// Σ a[i]·b[i] in eight partial sums, so multiply-adds overlap and vectorise (an in-order sum
/// cannot be vectorised). With AVX the same partial sums run four lanes wide: multiplies and
/// adds stay separate (no FMA), so every machine gets the same bits.
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX (checked just above).
        return unsafe { dot_avx(a, b) };
    }
    dot_lanes(a, b)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn dot_avx(a: &[f64], b: &[f64]) -> f64 {
    dot_lanes(a, b)
}

#[inline(always)]
fn dot_lanes(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0; 8];
    let (a8, b8) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = a8.remainder().iter().zip(b8.remainder()).map(|(x, y)| x * y).sum();
    for (x, y) in a8.zip(b8) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

#[cfg(test)]
mod dot_tests {
    #[test]
    fn dot_is_the_sum_of_products_at_every_length() {
        // Integers: exact in any summation order, so any lost or doubled term shows.
        for n in 0..40 {
            let a: Vec<f64> = (0..n).map(|i| (i * 7 % 11) as f64 - 5.0).collect();
            let b: Vec<f64> = (0..n).map(|i| (i * 3 % 13) as f64 - 6.0).collect();
            let expected: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
            assert_eq!(super::dot(&a, &b), expected, "length {n}");
            assert_eq!(super::dot_lanes(&a, &b), expected, "length {n}");
        }
    }
}
