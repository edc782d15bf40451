//! Deterministic synthetic ground motions and band-limited resampling.
//!
//! Everything here is pure numerics: a seeded PRNG (SplitMix64 + Box–Muller), Kanai–Tajimi
//! filtered white noise with a Clough–Penzien high-pass, a Jennings-style time envelope,
//! band-limited white noise, a frequency-domain filter helper and cubic (4-point Lagrange)
//! interpolation for sampling a finely simulated signal at a DAQ's rate and clock offset.
//!
//! Filtering is circular over the whole record. That is deliberate: zeroing the DC bin then makes
//! the sample sum of the acceleration exactly zero (up to round-off), i.e. no final velocity. The
//! callers keep a quiet margin before and after the envelope so the wrap-around is negligible.
//! The scalar FFT planner is used so results do not depend on the CPU's SIMD features.

use rustfft::num_complex::Complex64;
use rustfft::FftPlannerScalar;
use std::f64::consts::PI;

/// SplitMix64 PRNG: tiny, fast, well mixed, and bit-identical on every platform.
#[derive(Clone, Debug)]
pub struct SplitMix64 {
    state: u64,
    spare_normal: Option<f64>,
}

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        Self { state: seed, spare_normal: None }
    }

    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }

    /// +1.0 or -1.0 with equal probability.
    pub fn sign(&mut self) -> f64 {
        if self.next_u64() >> 63 == 0 {
            1.0
        } else {
            -1.0
        }
    }

    /// Standard normal via Box–Muller; the second variate of each pair is cached.
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare_normal.take() {
            return z;
        }
        // 1 - U lies in (0, 1], so the logarithm is finite.
        let u1 = 1.0 - self.next_f64();
        let u2 = self.next_f64();
        let r = (-2.0 * u1.ln()).sqrt();
        let theta = 2.0 * PI * u2;
        self.spare_normal = Some(r * theta.sin());
        r * theta.cos()
    }
}

/// Stable 64-bit seed from a text label (FNV-1a, then a SplitMix64 round to spread the bits).
pub fn seed_from_label(label: &str) -> u64 {
    let mut h: u64 = 0xCBF2_9CE4_8422_2325;
    for b in label.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01B3);
    }
    SplitMix64::new(h).next_u64()
}

/// Jennings-type envelope: zero before `start_s`, quadratic rise to 1 at `rise_end_s`, constant
/// strong phase until `strong_end_s`, exponential decay with `decay_tau_s`, and a cosine taper over
/// the last `end_taper_s` seconds before `end_s` so the motion stops exactly (no step at the end).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Envelope {
    pub start_s: f64,
    pub rise_end_s: f64,
    pub strong_end_s: f64,
    pub decay_tau_s: f64,
    pub end_s: f64,
    pub end_taper_s: f64,
}

impl Envelope {
    pub fn value(&self, t: f64) -> f64 {
        if t <= self.start_s || t >= self.end_s {
            return 0.0;
        }
        let shape = if t < self.rise_end_s {
            let x = (t - self.start_s) / (self.rise_end_s - self.start_s);
            x * x
        } else if t <= self.strong_end_s {
            1.0
        } else {
            (-(t - self.strong_end_s) / self.decay_tau_s).exp()
        };
        let taper_start = self.end_s - self.end_taper_s;
        if t > taper_start {
            shape * 0.5 * (1.0 + (PI * (t - taper_start) / self.end_taper_s).cos())
        } else {
            shape
        }
    }
}

/// Kanai–Tajimi soil filter times a Clough–Penzien high-pass, with a cosine roll-off to zero
/// between `f_pass_hz` and `f_stop_hz` so the result is band-limited for the DAQ rates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroundFilter {
    pub fg_hz: f64,
    pub zeta_g: f64,
    pub fc_hz: f64,
    pub zeta_c: f64,
    pub f_pass_hz: f64,
    pub f_stop_hz: f64,
}

impl GroundFilter {
    /// Complex response at signed frequency `f_hz`; H(-f) = conj(H(f)) so real input stays real.
    pub fn response(&self, f_hz: f64) -> Complex64 {
        let w = 2.0 * PI * f_hz;
        let wg = 2.0 * PI * self.fg_hz;
        let wc = 2.0 * PI * self.fc_hz;
        let i = Complex64::new(0.0, 1.0);
        let kt = (wg * wg + 2.0 * self.zeta_g * wg * w * i) / (wg * wg - w * w + 2.0 * self.zeta_g * wg * w * i);
        // Clough–Penzien: ω² / (ωc² − ω² + 2iζcωcω) → zero at DC, so no drift in velocity.
        let cp = Complex64::new(w * w, 0.0) / (wc * wc - w * w + 2.0 * self.zeta_c * wc * w * i);
        kt * cp * low_pass_gain(f_hz.abs(), self.f_pass_hz, self.f_stop_hz)
    }
}

/// 1 below `f_pass`, 0 above `f_stop`, raised-cosine in between.
fn low_pass_gain(f: f64, f_pass: f64, f_stop: f64) -> f64 {
    if f <= f_pass {
        1.0
    } else if f >= f_stop {
        0.0
    } else {
        0.5 * (1.0 + (PI * (f - f_pass) / (f_stop - f_pass)).cos())
    }
}

/// Frequency (Hz, signed) of FFT bin `k` of an `n`-point transform at sample step `dt`.
fn bin_frequency(k: usize, n: usize, dt: f64) -> f64 {
    let k = if k <= n / 2 { k as f64 } else { k as f64 - n as f64 };
    k / (n as f64 * dt)
}

/// Multiply the spectrum of `x` (circular, length `x.len()`) by `h(f_hz)` in place.
/// `h` must satisfy h(-f) = conj(h(f)); the (round-off) imaginary part of the result is dropped.
pub fn apply_frequency_response(x: &mut [f64], dt: f64, h: impl Fn(f64) -> Complex64) {
    let n = x.len();
    if n == 0 {
        return;
    }
    let mut planner = FftPlannerScalar::<f64>::new();
    let mut buf: Vec<Complex64> = x.iter().map(|&v| Complex64::new(v, 0.0)).collect();
    planner.plan_fft_forward(n).process(&mut buf);
    for (k, c) in buf.iter_mut().enumerate() {
        *c *= h(bin_frequency(k, n, dt));
    }
    planner.plan_fft_inverse(n).process(&mut buf);
    let inv_n = 1.0 / n as f64;
    for (v, c) in x.iter_mut().zip(&buf) {
        *v = c.re * inv_n;
    }
}

/// Zero-phase raised-cosine low-pass (pass below `f_pass_hz`, nothing above `f_stop_hz`).
pub fn low_pass(x: &mut [f64], dt: f64, f_pass_hz: f64, f_stop_hz: f64) {
    apply_frequency_response(x, dt, |f| Complex64::new(low_pass_gain(f.abs(), f_pass_hz, f_stop_hz), 0.0));
}

/// Scale `x` so that max |x| equals `peak` (no-op on an all-zero signal).
pub fn scale_to_peak(x: &mut [f64], peak: f64) {
    let m = x.iter().fold(0.0_f64, |a, &v| a.max(v.abs()));
    if m > 0.0 {
        let s = peak / m;
        x.iter_mut().for_each(|v| *v *= s);
    }
}

/// Enveloped white noise through `filter`, unscaled. `n` samples at step `dt`.
pub fn filtered_noise(seed: u64, n: usize, dt: f64, filter: &GroundFilter, envelope: &Envelope) -> Vec<f64> {
    let mut rng = SplitMix64::new(seed);
    // Envelope before filtering: the filter then zeroes the DC of the final signal exactly.
    let mut x: Vec<f64> = (0..n).map(|i| rng.normal() * envelope.value(i as f64 * dt)).collect();
    apply_frequency_response(&mut x, dt, |f| filter.response(f));
    x
}

/// Synthetic ground acceleration with peak |a| = `pga` (same units as `pga`).
pub fn synthetic_ground_motion(
    seed: u64,
    n: usize,
    dt: f64,
    filter: &GroundFilter,
    envelope: &Envelope,
    pga: f64,
) -> Vec<f64> {
    let mut x = filtered_noise(seed, n, dt, filter, envelope);
    scale_to_peak(&mut x, pga);
    x
}

/// Band-limited white noise between `f_lo_hz` and `f_hi_hz` (raised-cosine edges 0.2 Hz wide
/// below `f_lo_hz` and 2 Hz wide above `f_hi_hz`), enveloped, scaled to peak |x| = `peak`.
pub fn band_limited_white_noise(
    seed: u64,
    n: usize,
    dt: f64,
    f_lo_hz: f64,
    f_hi_hz: f64,
    envelope: &Envelope,
    peak: f64,
) -> Vec<f64> {
    let mut rng = SplitMix64::new(seed);
    let mut x: Vec<f64> = (0..n).map(|i| rng.normal() * envelope.value(i as f64 * dt)).collect();
    let edge_lo = 0.2_f64.min(f_lo_hz);
    apply_frequency_response(&mut x, dt, |f| {
        let f = f.abs();
        let hp = 1.0 - low_pass_gain(f, f_lo_hz - edge_lo, f_lo_hz);
        Complex64::new(hp * low_pass_gain(f, f_hi_hz, f_hi_hz + 2.0), 0.0)
    });
    scale_to_peak(&mut x, peak);
    x
}

/// Value of the signal `x` (samples at i·dt) at time `t` by 4-point cubic Lagrange interpolation.
/// Samples beyond either end are taken as the end values. Error for a sinusoid of frequency f is
/// at most (2π f dt)^4 · 9/384 relative, e.g. 1.4e-5 for 25 Hz on a 1 kHz grid.
pub fn cubic_interpolate(x: &[f64], dt: f64, t: f64) -> f64 {
    let n = x.len();
    if n == 0 {
        return 0.0;
    }
    let s = t / dt;
    let i = s.floor();
    let u = s - i;
    let i = i as i64;
    let at = |k: i64| x[k.clamp(0, n as i64 - 1) as usize];
    let (p0, p1, p2, p3) = (at(i - 1), at(i), at(i + 1), at(i + 2));
    // Lagrange basis on nodes -1, 0, 1, 2.
    let w0 = -u * (u - 1.0) * (u - 2.0) / 6.0;
    let w1 = (u + 1.0) * (u - 1.0) * (u - 2.0) / 2.0;
    let w2 = -(u + 1.0) * u * (u - 2.0) / 2.0;
    let w3 = (u + 1.0) * u * (u - 1.0) / 6.0;
    w0 * p0 + w1 * p1 + w2 * p2 + w3 * p3
}

/// Sample `x` (step `dt`) at times `t0 + k / rate_hz`, k = 0..n_out.
pub fn resample(x: &[f64], dt: f64, t0: f64, rate_hz: f64, n_out: usize) -> Vec<f64> {
    (0..n_out).map(|k| cubic_interpolate(x, dt, t0 + k as f64 / rate_hz)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test_envelope() -> Envelope {
        Envelope { start_s: 2.0, rise_end_s: 6.0, strong_end_s: 20.0, decay_tau_s: 4.0, end_s: 35.0, end_taper_s: 3.0 }
    }

    fn test_filter() -> GroundFilter {
        GroundFilter { fg_hz: 2.5, zeta_g: 0.6, fc_hz: 0.2, zeta_c: 0.7, f_pass_hz: 20.0, f_stop_hz: 25.0 }
    }

    #[test]
    fn prng_is_reproducible_and_normal_has_unit_moments() {
        let mut a = SplitMix64::new(42);
        let mut b = SplitMix64::new(42);
        for _ in 0..100 {
            assert_eq!(a.next_u64(), b.next_u64());
        }
        let mut r = SplitMix64::new(seed_from_label("FB-4"));
        let n = 200_000;
        let z: Vec<f64> = (0..n).map(|_| r.normal()).collect();
        let mean = z.iter().sum::<f64>() / n as f64;
        let var = z.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n as f64;
        // Standard errors are 1/sqrt(n) ≈ 0.0022 and sqrt(2/n) ≈ 0.0032; allow ~5 sigma.
        assert!(mean.abs() < 0.011, "mean {mean}");
        assert!((var - 1.0).abs() < 0.016, "var {var}");
        assert_ne!(seed_from_label("FB-4"), seed_from_label("FB-5"));
    }

    #[test]
    fn ground_motion_hits_pga_and_has_no_final_velocity() {
        let dt = 0.001;
        let n = 45_000;
        let pga = 0.26;
        let a = synthetic_ground_motion(7, n, dt, &test_filter(), &test_envelope(), pga);
        let peak = a.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!((peak - pga).abs() <= 1e-6 * pga, "peak {peak}");
        // Trapezoidal velocity. The DC bin is zeroed, so the sample sum is zero to round-off
        // (~1e-16 · n · pga); the trapezoid's end corrections vanish because the record ends
        // quiet. 1e-6 of the peak velocity is far above round-off and far below any real drift.
        let mut v = 0.0;
        let mut vmax = 0.0_f64;
        for w in a.windows(2) {
            v += 0.5 * dt * (w[0] + w[1]);
            vmax = vmax.max(v.abs());
        }
        println!("final velocity {v:e} (g·s), peak velocity {vmax:e} (g·s)");
        assert!(v.abs() <= 1e-6 * vmax, "final velocity {v} vs peak {vmax}");
        // Quiet before the envelope starts (only wrap-around leakage).
        let pre = a[..1500].iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        assert!(pre < 0.02 * pga, "pre-event {pre}");
    }

    #[test]
    fn white_noise_is_band_limited_and_scaled() {
        let dt = 0.001;
        let n = 60_000;
        let env = Envelope {
            start_s: 1.0,
            rise_end_s: 3.0,
            strong_end_s: 56.0,
            decay_tau_s: 1.0,
            end_s: 59.0,
            end_taper_s: 2.0,
        };
        let x = band_limited_white_noise(3, n, dt, 0.5, 25.0, &env, 0.04);
        let peak = x.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!((peak - 0.04).abs() < 1e-12);
        let mut buf: Vec<Complex64> = x.iter().map(|&v| Complex64::new(v, 0.0)).collect();
        FftPlannerScalar::<f64>::new().plan_fft_forward(n).process(&mut buf);
        let (mut inside, mut above) = (0.0, 0.0);
        for (k, c) in buf.iter().enumerate().take(n / 2) {
            let f = bin_frequency(k, n, dt);
            if (0.5..=25.0).contains(&f) {
                inside += c.norm_sqr();
            } else if f > 27.0 {
                above += c.norm_sqr();
            }
        }
        assert!(above < 1e-20 * inside, "energy above 27 Hz {above} vs band {inside}");
    }

    #[test]
    fn cubic_interpolation_is_accurate_for_band_limited_signals() {
        let dt = 0.001;
        let f = 25.0;
        let x: Vec<f64> = (0..2000).map(|i| (2.0 * PI * f * i as f64 * dt).sin()).collect();
        let mut worst = 0.0_f64;
        for k in 0..300 {
            let t = 0.1 + k as f64 * 0.003_217;
            worst = worst.max((cubic_interpolate(&x, dt, t) - (2.0 * PI * f * t).sin()).abs());
        }
        assert!(worst < 2e-5, "worst interpolation error {worst}");
    }
}
