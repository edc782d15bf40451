//! Signal processing on plain slices: no files, no pipeline.

pub mod baseline;
pub mod resample;
pub mod resample_bandlimited;
mod running_median;
pub mod sync;
pub mod synthetic_motion;
pub mod toppling;
pub mod welch;

#[cfg(test)]
pub(crate) mod test_support;

/// Σ a[i]·b[i] in sixteen partial sums, so multiply-adds overlap and vectorise (an in-order sum
/// cannot be vectorised). With AVX the partial sums are four registers of four lanes, written
/// out with intrinsics: the compiler's own vectorisation of the lanes loop used 2-lane registers
/// and shuffles, at a third of the speed in the resampler's 166-tap dot products. Multiplies and
/// adds stay separate (no FMA) and both paths add in the same order, so every machine gets the
/// same bits.
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX (checked just above).
        return unsafe { dot_avx(a, b) };
    }
    dot_lanes(a, b)
}

const LANES: usize = 16;

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn dot_avx(a: &[f64], b: &[f64]) -> f64 {
    use std::arch::x86_64::{
        __m256d, _mm256_add_pd, _mm256_loadu_pd, _mm256_mul_pd, _mm256_setzero_pd, _mm256_storeu_pd,
    };
    let n = a.len().min(b.len());
    let mut acc: [__m256d; 4] = [_mm256_setzero_pd(); 4];
    for start in (0..n - n % LANES).step_by(LANES) {
        for (r, sum) in acc.iter_mut().enumerate() {
            let i = start + 4 * r;
            // SAFETY: i + 4 <= n - n % LANES <= both lengths; loadu has no alignment requirement.
            let (x, y) = unsafe { (_mm256_loadu_pd(a.as_ptr().add(i)), _mm256_loadu_pd(b.as_ptr().add(i))) };
            *sum = _mm256_add_pd(*sum, _mm256_mul_pd(x, y));
        }
    }
    let mut sums = [0.0; LANES];
    for (r, sum) in acc.iter().enumerate() {
        // SAFETY: sums[4r..4r + 4] is in bounds; storeu has no alignment requirement.
        unsafe { _mm256_storeu_pd(sums.as_mut_ptr().add(4 * r), *sum) };
    }
    reduce(&sums, &a[n - n % LANES..n], &b[n - n % LANES..n])
}

fn dot_lanes(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let mut sums = [0.0; LANES];
    let (a16, b16) = (a[..n].chunks_exact(LANES), b[..n].chunks_exact(LANES));
    let (a_tail, b_tail) = (a16.remainder(), b16.remainder());
    for (x, y) in a16.zip(b16) {
        for i in 0..LANES {
            sums[i] += x[i] * y[i];
        }
    }
    reduce(&sums, a_tail, b_tail)
}

/// The partial sums and the tail, added in one fixed order.
#[inline(always)]
fn reduce(sums: &[f64; LANES], a_tail: &[f64], b_tail: &[f64]) -> f64 {
    let tail: f64 = a_tail.iter().zip(b_tail).map(|(x, y)| x * y).sum();
    let mut half = [0.0; 8];
    for i in 0..8 {
        half[i] = sums[i] + sums[i + 8];
    }
    ((half[0] + half[4]) + (half[1] + half[5])) + ((half[2] + half[6]) + (half[3] + half[7])) + tail
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

    #[test]
    fn avx_and_portable_paths_add_in_the_same_order() {
        // Non-integers, where the order of additions shows in the last bits. On a machine
        // without AVX both calls take the portable path and the test holds trivially.
        for n in [1, 15, 16, 17, 31, 166, 333] {
            let a: Vec<f64> = (0..n).map(|i| (i as f64 * 0.731).sin() * 1e3).collect();
            let b: Vec<f64> = (0..n).map(|i| (i as f64 * 1.37).cos() / 7.0).collect();
            assert_eq!(super::dot(&a, &b).to_bits(), super::dot_lanes(&a, &b).to_bits(), "length {n}");
        }
    }
}
