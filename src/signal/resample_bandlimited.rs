//! Band-limited resampling and interpolation at arbitrary times.
//!
//! # Method
//! Every output value is a Kaiser-windowed-sinc interpolation of the input
//! evaluated at an arbitrary (real-valued) time:
//!
//! ```text
//! y(t) = Σ_n x[n] · c · sinc(c·(u − n)) · w((u − n)/H),   u = t·fs_in,  c = 2·f_c/fs_in
//! ```
//!
//! where `sinc(z) = sin(πz)/(πz)`, `f_c` is the cut-off (middle of the transition band),
//! `w` a Kaiser window of half-width `H` input samples.  The kernel is symmetric, so the
//! result is zero-phase (no group delay to compensate): output sample `k` of
//! [`resample_to_rate`] is the band-limited value of the input at time `k/fs_out`.
//! One routine therefore serves both rate conversion between arbitrary (also irrational)
//! rate ratios and fractional-delay shifting (needed for clock alignment anyway).
//! A rational polyphase FIR (`resample_poly`) is the same filter evaluated only at the
//! phases `k·down/up`; evaluating the continuous kernel directly avoids needing a small
//! rational ratio (e.g. 256 → 199.98 Hz after a drift correction).
//!
//! The Kaiser design follows the standard formulas (Kaiser 1974; Oppenheim & Schafer):
//! for stop-band attenuation `A` dB and transition width `Δω` rad/sample (at the input rate)
//! `β = 0.1102·(A − 8.7)` (A > 50), taps `L = (A − 8)/(2.285·Δω) + 1`, `H = L/2`.
//! Pass-band ripple equals stop-band ripple, `10^(−A/20)` (1e-5 for the default 100 dB).
//!
//! # Defaults
//! * [`resample_to_rate`] uses [`RESAMPLE_SPEC`]: pass band to `0.8·f_N`, stop band from
//!   `0.9·f_N`, where `f_N` is the Nyquist frequency of the *lower* of the two rates.
//!   256 → 200 Hz: flat (±1e-5) to 80 Hz, ≥ 100 dB rejection from 90 Hz, which also kills
//!   everything that would alias.  The top 10 % of the output band (90–100 Hz) is removed
//!   on purpose rather than passed with a sloped, non-flat response.
//! * [`sample_at`] / [`super::sync::shift`] (no rate change) use [`INTERP_SPEC`]: flat to
//!   `0.8·f_N`, stop band from `f_N` (images of content below `0.8·f_N` are rejected).
//!
//! # Edges
//! * Times outside `[0, (n−1)/fs]` (tolerance 1e-9 sample) give `NaN`: no extrapolation.
//! * Inside the record, kernel taps that fall before the first / after the last sample use an
//!   odd (point-symmetric) reflection about the end sample, `x[−k] = 2x[0] − x[k]`
//!   (repeated for records shorter than the kernel),
//!   which keeps value and slope continuous and limits edge ringing (cf. scipy's
//!   `filtfilt(padtype="odd")`).  The first/last `H` samples (≈ 0.3–0.5 s at the
//!   default specs) are therefore less accurate than the interior.

use super::dot;
use std::f64::consts::PI;
use std::sync::{Arc, Mutex};

/// Filter specification.  Frequencies are fractions of a Nyquist frequency (see the
/// function using it for which one).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KernelSpec {
    /// Upper edge of the flat pass band, fraction of Nyquist (0 < pass_frac < stop_frac).
    pub pass_frac: f64,
    /// Lower edge of the stop band, fraction of Nyquist (stop_frac ≤ 1).
    pub stop_frac: f64,
    /// Stop-band attenuation (and pass-band ripple, 10^(−A/20)) in dB.
    pub atten_db: f64,
}

/// Default anti-aliasing spec for rate conversion (fractions of the lower Nyquist).
pub const RESAMPLE_SPEC: KernelSpec = KernelSpec { pass_frac: 0.8, stop_frac: 0.9, atten_db: 100.0 };
/// Default spec for interpolation at the native rate (fractions of the record's Nyquist).
pub const INTERP_SPEC: KernelSpec = KernelSpec { pass_frac: 0.8, stop_frac: 1.0, atten_db: 100.0 };

/// Resample `x` (rate `fs_in`, first sample at t = 0) to `fs_out`.
/// Output sample `k` is at time `k/fs_out`; the output covers `[0, (n−1)/fs_in]`, i.e.
/// `floor((n−1)·fs_out/fs_in) + 1` samples.  Equal rates return a copy.  Uses
/// [`RESAMPLE_SPEC`].  Panics if a rate is not finite and positive.
pub fn resample_to_rate(x: &[f64], fs_in: f64, fs_out: f64) -> Vec<f64> {
    resample_to_rate_with(x, fs_in, fs_out, &RESAMPLE_SPEC)
}

/// [`resample_to_rate`] with an explicit spec (fractions of the Nyquist of min(fs_in, fs_out)).
pub fn resample_to_rate_with(x: &[f64], fs_in: f64, fs_out: f64, spec: &KernelSpec) -> Vec<f64> {
    Resampler::with_spec(fs_in, fs_out, spec).resample(x)
}

/// A conversion from rate `fs_in` to `fs_out`, optionally with a time shift, for the channels of
/// one record: its filter is built once for several calls (e.g. a record's sync channel first,
/// then all its channels), the kernel's window and, for rates whose phases never repeat, its
/// phase table. Different rates use [`RESAMPLE_SPEC`], equal ones [`INTERP_SPEC`] (a
/// fractional delay, as [`sample_grid`]).
pub struct Resampler {
    kernel: Kernel,
    fs_in: f64,
    fs_out: f64,
}

impl Resampler {
    pub fn new(fs_in: f64, fs_out: f64) -> Resampler {
        Resampler::with_spec(fs_in, fs_out, if fs_in == fs_out { &INTERP_SPEC } else { &RESAMPLE_SPEC })
    }

    /// `spec` in fractions of the Nyquist of min(fs_in, fs_out). Panics if a rate is not finite
    /// and positive.
    fn with_spec(fs_in: f64, fs_out: f64, spec: &KernelSpec) -> Resampler {
        assert!(fs_in.is_finite() && fs_in > 0.0, "fs_in must be finite and > 0");
        assert!(fs_out.is_finite() && fs_out > 0.0, "fs_out must be finite and > 0");
        Resampler { kernel: Kernel::new(fs_in, 0.5 * fs_in.min(fs_out), spec), fs_in, fs_out }
    }

    /// How many output samples cover a record of `n` input samples, `[0, (n−1)/fs_in]`:
    /// `floor((n−1)·fs_out/fs_in) + 1` (none for an empty record).
    pub fn output_len(&self, n: usize) -> usize {
        if n == 0 {
            return 0;
        }
        let t_last = (n - 1) as f64 / self.fs_in;
        (t_last * self.fs_out + 1e-9).floor() as usize + 1
    }

    /// The whole record at the output rate, sample k at time k/fs_out ([`resample_to_rate`]);
    /// a copy when the rates are equal.
    pub fn resample(&self, x: &[f64]) -> Vec<f64> {
        if self.fs_in == self.fs_out {
            return x.to_vec();
        }
        self.grid(&[x], 0.0, self.output_len(x.len())).pop().expect("one channel in, one out")
    }

    /// The channels (rate `fs_in`, same length, first sample at t = 0) at the times
    /// `t0 + k/fs_out`, k < n: a rate conversion and a time shift in one filter (cascading two
    /// interpolations would filter twice). Times outside the record give `NaN`.
    pub fn grid(&self, channels: &[&[f64]], t0: f64, n: usize) -> Vec<Vec<f64>> {
        if common_length(channels) == 0 {
            return vec![vec![f64::NAN; n]; channels.len()];
        }
        self.kernel.eval_grid(channels, t0 * self.fs_in, self.fs_in / self.fs_out, n)
    }
}

/// Band-limited interpolation of `x` (rate `fs`, first sample at t = 0) at arbitrary
/// `times` (seconds).  Times outside `[0, (n−1)/fs]` give `NaN`.  Uses [`INTERP_SPEC`].
pub fn sample_at(x: &[f64], fs: f64, times: &[f64]) -> Vec<f64> {
    sample_at_with(x, fs, times, &INTERP_SPEC)
}

/// [`sample_at`] with an explicit spec (fractions of the Nyquist of `fs`).
pub fn sample_at_with(x: &[f64], fs: f64, times: &[f64], spec: &KernelSpec) -> Vec<f64> {
    assert!(fs.is_finite() && fs > 0.0, "fs must be finite and > 0");
    if x.is_empty() {
        return vec![f64::NAN; times.len()];
    }
    let kernel = Kernel::new(fs, 0.5 * fs, spec);
    let mut weights = Vec::new();
    times.iter().map(|&t| kernel.value_at(x, t * fs, &mut weights)).collect()
}

/// [`sample_at`] of several channels (rate `fs`, same length) on the uniform grid
/// `t0 + k/fs`, k < n: a fractional delay, so one set of filter weights serves every sample.
pub fn sample_grid(channels: &[&[f64]], fs: f64, t0: f64, n: usize) -> Vec<Vec<f64>> {
    Resampler::new(fs, fs).grid(channels, t0, n)
}

fn common_length(channels: &[&[f64]]) -> usize {
    let n = channels.first().map_or(0, |x| x.len());
    assert!(channels.iter().all(|x| x.len() == n), "channels of one record must have the same length");
    n
}

/// Zeroth-order modified Bessel function of the first kind (power series; converges
/// fast for the β ≤ ~20 used here).
fn bessel_i0(x: f64) -> f64 {
    let q = 0.25 * x * x;
    let mut term = 1.0;
    let mut sum = 1.0;
    let mut k = 1.0;
    while term > 1e-17 * sum {
        term *= q / (k * k);
        sum += term;
        k += 1.0;
    }
    sum
}

/// Number of table intervals for the Kaiser window over |d|/H ∈ [0, 1].  Linear
/// interpolation error ≈ |w''|·δ²/8 ≲ 1e-9 (relative to the window peak).
const WIN_TABLE: usize = 16384;

/// The Kaiser window of shape `beta` tabulated over |d|/H ∈ [0, 1]. It depends on the
/// attenuation alone, not on the rates, and costs ~3 ms (16 386 Bessel series): built once per
/// process and shape, not once per record.
fn window_table(beta: f64) -> Arc<[f64]> {
    static TABLES: Mutex<Vec<(u64, Arc<[f64]>)>> = Mutex::new(Vec::new());
    let cached =
        |tables: &[(u64, Arc<[f64]>)]| tables.iter().find(|(b, _)| *b == beta.to_bits()).map(|(_, t)| t.clone());
    if let Some(table) = cached(&TABLES.lock().expect("no panics while holding the lock")) {
        return table;
    }
    let i0b = bessel_i0(beta);
    let table: Arc<[f64]> = (0..=WIN_TABLE + 1)
        .map(|i| {
            let r = (i as f64 / WIN_TABLE as f64).min(1.0);
            bessel_i0(beta * (1.0 - r * r).max(0.0).sqrt()) / i0b
        })
        .collect();
    let mut tables = TABLES.lock().expect("no panics while holding the lock");
    // Another thread may have built it meanwhile: the same values, either copy serves.
    if let Some(table) = cached(&tables) {
        return table;
    }
    tables.push((beta.to_bits(), table.clone()));
    table
}

/// Kaiser-windowed sinc kernel, in units of input samples.
struct Kernel {
    /// c = 2·f_c/fs_in (cut-off relative to the input sampling rate, ≤ 1).
    c: f64,
    /// Half-width in input samples.
    half: f64,
    /// Kaiser window tabulated at |d|/half = i/WIN_TABLE.
    win: Arc<[f64]>,
    /// Weights per phase, built on first use by a step whose phases never repeat.
    phases: std::sync::OnceLock<PhaseTable>,
}

impl Kernel {
    fn new(fs_in: f64, f_nyq: f64, spec: &KernelSpec) -> Kernel {
        assert!(
            spec.pass_frac > 0.0 && spec.pass_frac < spec.stop_frac && spec.stop_frac <= 1.0,
            "invalid KernelSpec: need 0 < pass_frac < stop_frac <= 1"
        );
        assert!(spec.atten_db > 21.0, "invalid KernelSpec: atten_db must be > 21");
        let f_pass = spec.pass_frac * f_nyq;
        let f_stop = spec.stop_frac * f_nyq;
        let f_c = 0.5 * (f_pass + f_stop);
        let c = (2.0 * f_c / fs_in).min(1.0);
        let dw = 2.0 * PI * (f_stop - f_pass) / fs_in; // rad / input sample
        let a = spec.atten_db;
        let beta = if a > 50.0 { 0.1102 * (a - 8.7) } else { 0.5842 * (a - 21.0).powf(0.4) + 0.07886 * (a - 21.0) };
        let taps = (a - 8.0) / (2.285 * dw) + 1.0;
        let half = (0.5 * taps).ceil().max(2.0);
        Kernel { c, half, win: window_table(beta), phases: std::sync::OnceLock::new() }
    }

    #[inline]
    fn window(&self, d_abs: f64) -> f64 {
        let p = d_abs / self.half * WIN_TABLE as f64;
        let i = p as usize;
        if i >= WIN_TABLE {
            return if d_abs <= self.half { self.win[WIN_TABLE] } else { 0.0 };
        }
        let f = p - i as f64;
        self.win[i] + f * (self.win[i + 1] - self.win[i])
    }

    /// Filter weights for the value at `u` (input-sample units, inside the record): fills
    /// `weights` with the taps for samples `n0, n0+1, …` and returns `n0`.
    fn taps(&self, u: f64, weights: &mut Vec<f64>) -> isize {
        let pc = PI * self.c;
        let (sd, cd) = pc.sin_cos(); // rotation by one sample
        let n0 = (u - self.half).ceil() as isize;
        let n1 = (u + self.half).floor() as isize;
        // θ_k = π c (u − k); sin/cos advanced by the recurrence θ_{k+1} = θ_k − πc.
        let (mut s, mut co) = (pc * (u - n0 as f64)).sin_cos();
        weights.clear();
        for k in n0..=n1 {
            let d = u - k as f64;
            let sinc = if d.abs() < 1e-9 { 1.0 } else { s / (pc * d) };
            weights.push(self.c * sinc * self.window(d.abs()));
            let s_new = s * cd - co * sd;
            co = co * cd + s * sd;
            s = s_new;
        }
        n0
    }

    /// `u` checked against the record `[0, n−1]` (1e-9 sample tolerance, then clamped).
    fn inside(u: f64, n: usize) -> Option<f64> {
        let last = (n - 1) as f64;
        (u.is_finite() && u >= -1e-9 && u <= last + 1e-9).then(|| u.clamp(0.0, last))
    }

    fn value_at(&self, x: &[f64], u: f64, weights: &mut Vec<f64>) -> f64 {
        let Some(u) = Self::inside(u, x.len()) else { return f64::NAN };
        let n0 = self.taps(u, weights);
        apply(x, n0, weights)
    }

    /// Every channel at `u_k = u0 + k·step` (input-sample units), k < n.  When the step is a
    /// ratio p/q of small integers (256 → 200 Hz: 32/25; a fractional delay: 1/1) the phase
    /// of `u_k` repeats every q outputs, so only q sets of weights are computed.
    fn eval_grid(&self, channels: &[&[f64]], u0: f64, step: f64, n: usize) -> Vec<Vec<f64>> {
        let last = (channels[0].len() - 1) as f64;
        let mut out: Vec<Vec<f64>> = channels.iter().map(|_| Vec::with_capacity(n)).collect();
        let mut emit = |u: f64, n0: isize, weights: &[f64], scratch: &mut Vec<f64>| {
            for (x, y) in channels.iter().zip(out.iter_mut()) {
                // Within the tolerance of an end (clamped) or outside (NaN): rare, one by one.
                y.push(if (0.0..=last).contains(&u) { apply(x, n0, weights) } else { self.value_at(x, u, scratch) });
            }
        };
        let mut scratch = Vec::new();
        let period = (1..=MAX_PERIOD).find(|&q| {
            let span = q as f64 * step;
            (span - span.round()).abs() < 1e-9
        });
        if let Some(period) = period {
            let jump = (period as f64 * step).round();
            let phases: Vec<(f64, isize, Vec<f64>)> = (0..period.min(n))
                .map(|r| {
                    let base = u0 + r as f64 * step;
                    let mut weights = Vec::new();
                    let n0 = self.taps(base, &mut weights);
                    (base, n0, weights)
                })
                .collect();
            for k in 0..n {
                let (base, n0, weights) = &phases[k % period];
                // Shifting u by a whole number of samples shifts the taps and keeps the weights.
                let whole = (k / period) as f64 * jump;
                emit(base + whole, n0 + whole as isize, weights, &mut scratch);
            }
        } else {
            // A ratio that never repeats (a drifting clock): weights interpolated from a table.
            let table = self.phases.get_or_init(|| PhaseTable::new(self));
            let mut weights = Vec::new();
            for k in 0..n {
                let u = u0 + k as f64 * step;
                let n0 = if (0.0..=last).contains(&u) { table.taps(u, &mut weights) } else { 0 };
                emit(u, n0, &weights, &mut scratch);
            }
        }
        out
    }

    /// The kernel's weight for a sample `d` input samples before the evaluation point.
    fn weight(&self, d: f64) -> f64 {
        let z = PI * self.c * d;
        let sinc = if d.abs() < 1e-9 { 1.0 } else { z.sin() / z };
        self.c * sinc * self.window(d.abs())
    }
}

/// Phases tabulated per input sample by [`PhaseTable`]: with cubic interpolation between them
/// the weights differ from the kernel's by < 1e-8, the accuracy of the kernel's own tabulated
/// window (test `phase_table_matches_kernel`).
const PHASES: usize = 128;

/// The kernel's 2H weights tabulated at the fractional positions i/PHASES (i = 0..=PHASES) of
/// the evaluation point between two samples. Weights at any other position come from a cubic
/// (Lagrange) interpolation of four neighbouring rows: ~4·2H multiply-adds instead of 2H sines,
/// divisions and window look-ups, the cost of [`Kernel::taps`] when phases never repeat.
struct PhaseTable {
    half: usize,
    /// Row i: weights of samples floor(u) − H + 1 + j (j < 2H) for u − floor(u) = i/PHASES.
    rows: Vec<f64>,
}

impl PhaseTable {
    fn new(kernel: &Kernel) -> PhaseTable {
        let half = kernel.half as usize;
        let rows = (0..=PHASES)
            .flat_map(|i| {
                let frac = i as f64 / PHASES as f64;
                (0..2 * half).map(move |j| frac + (half - 1) as f64 - j as f64)
            })
            .map(|d| kernel.weight(d))
            .collect();
        PhaseTable { half, rows }
    }

    /// Like [`Kernel::taps`] (same weights to 1e-8, always 2H of them).
    fn taps(&self, u: f64, weights: &mut Vec<f64>) -> isize {
        let width = 2 * self.half;
        let whole = u.floor();
        let p = (u - whole) * PHASES as f64;
        // Four rows around p, shifted inward at the ends so the stencil stays in [0, PHASES]:
        // each row's weight is a smooth function of the phase only inside one sample.
        let first = (p.floor() as usize).saturating_sub(1).min(PHASES - 3);
        let s = p - first as f64;
        let l = [
            -(s - 1.0) * (s - 2.0) * (s - 3.0) / 6.0,
            s * (s - 2.0) * (s - 3.0) / 2.0,
            -s * (s - 1.0) * (s - 3.0) / 2.0,
            s * (s - 1.0) * (s - 2.0) / 6.0,
        ];
        let row = |m: usize| &self.rows[(first + m) * width..(first + m + 1) * width];
        weights.clear();
        weights.extend(
            row(0)
                .iter()
                .zip(row(1))
                .zip(row(2).iter().zip(row(3)))
                .map(|((a, b), (c, d))| l[0] * a + l[1] * b + l[2] * c + l[3] * d),
        );
        whole as isize - self.half as isize + 1
    }
}

/// Longest output period searched for repeating filter phases (the rate ratio's denominator).
const MAX_PERIOD: usize = 4096;

/// Σ weights[j]·x[n0 + j], with the record's odd reflection for taps beyond its ends.
fn apply(x: &[f64], n0: isize, weights: &[f64]) -> f64 {
    let n = x.len();
    if n0 >= 0 && n0 as usize + weights.len() <= n {
        return dot(&x[n0 as usize..n0 as usize + weights.len()], weights);
    }
    weights.iter().enumerate().map(|(j, w)| w * reflected(x, n0 + j as isize)).sum()
}

/// `x[i]` for any `i`: repeated odd (point-symmetric) reflection about the end samples, exact
/// for straight lines whatever the record length.
fn reflected(x: &[f64], i: isize) -> f64 {
    let n = x.len();
    if n == 1 {
        return x[0];
    }
    let (mut i, mut sign, mut off) = (i, 1.0, 0.0);
    let top = (n - 1) as isize;
    loop {
        if i < 0 {
            off += sign * 2.0 * x[0];
            sign = -sign;
            i = -i;
        } else if i > top {
            off += sign * 2.0 * x[n - 1];
            sign = -sign;
            i = 2 * top - i;
        } else {
            return off + sign * x[i as usize];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::*;
    use super::*;

    fn sines(freqs: &[(f64, f64, f64)], t: f64) -> f64 {
        freqs.iter().map(|&(a, f, ph)| a * (2.0 * PI * f * t + ph).sin()).sum()
    }

    /// Amplitude of a sinusoid of frequency f in y (rate fs), fitted on an interior window.
    fn fitted_amplitude(y: &[f64], fs: f64, f: f64, skip: usize) -> f64 {
        crate::signal::test_support::fit_harmonic(y, 1.0 / fs, 2.0 * PI * f, skip..y.len() - skip).0
    }

    #[test]
    fn round_trip_256_200_256_band_limited_sines() {
        // Components below 0.4·min(fs) = 80 Hz.
        let comps = [(1.0, 1.3, 0.2), (0.7, 7.9, 1.1), (0.5, 23.4, -0.4), (0.4, 51.7, 2.0), (0.3, 78.0, 0.9)];
        let (fa, fb) = (256.0, 200.0);
        let dur = 20.0;
        let x: Vec<f64> = (0..(dur * fa) as usize).map(|k| sines(&comps, k as f64 / fa)).collect();
        let y = resample_to_rate(&x, fa, fb);
        let z = resample_to_rate(&y, fb, fa);
        let edge = 1.0; // s excluded at each end
        let err_rel = |v: &[f64], fs: f64| {
            let (mut e2, mut s2) = (0.0, 0.0);
            for (k, &val) in v.iter().enumerate() {
                let t = k as f64 / fs;
                if t < edge || t > dur - 1.0 / fa - edge {
                    continue;
                }
                let truth = sines(&comps, t);
                e2 += (val - truth).powi(2);
                s2 += truth * truth;
            }
            (e2 / s2).sqrt()
        };
        let e_down = err_rel(&y, fb);
        let e_rt = err_rel(&z, fa);
        println!("256->200: rel RMS error {e_down:.2e}; 256->200->256: rel RMS error {e_rt:.2e}");
        assert_eq!(y.len(), ((x.len() - 1) as f64 * fb / fa).floor() as usize + 1);
        assert!(e_down < 1e-3, "256->200 error {e_down}");
        assert!(e_rt < 1e-3, "round-trip error {e_rt}");

        // sample_at at arbitrary times on the 200 Hz record.
        let times: Vec<f64> = (0..500).map(|i| 2.0 + i as f64 * 0.031_337).collect();
        let v = sample_at(&y, fb, &times);
        let (mut e2, mut s2) = (0.0, 0.0);
        for (t, val) in times.iter().zip(&v) {
            let tr = sines(&comps, *t);
            e2 += (val - tr).powi(2);
            s2 += tr * tr;
        }
        let e_at = (e2 / s2).sqrt();
        println!("sample_at (200 Hz, arbitrary times): rel RMS error {e_at:.2e}");
        assert!(e_at < 1e-3);
    }

    #[test]
    fn anti_aliasing_attenuation() {
        let (fa, fb) = (256.0, 200.0);
        let n = (30.0 * fa) as usize;
        let report = |f_in: f64, f_seen: f64| {
            let x: Vec<f64> = (0..n).map(|k| (2.0 * PI * f_in * k as f64 / fa).sin()).collect();
            let y = resample_to_rate(&x, fa, fb);
            let amp = fitted_amplitude(&y, fb, f_seen, 400);
            20.0 * amp.max(1e-300).log10()
        };
        let db90 = report(90.0, 90.0);
        let db110 = report(110.0, 90.0); // would alias to 90 Hz
        let db150 = report(150.0, 50.0); // would alias to 50 Hz
        let db60 = report(60.0, 60.0); // pass band
        println!(
            "256->200 Hz gain: 60 Hz {db60:.5} dB; 90 Hz {db90:.1} dB; 110 Hz (alias at 90) {db110:.1} dB; \
             150 Hz (alias at 50) {db150:.1} dB"
        );
        assert!(db60.abs() < 1e-3);
        assert!(db90 < -60.0, "90 Hz only attenuated {db90} dB");
        assert!(db110 < -60.0 && db150 < -60.0);
    }

    #[test]
    fn real_record_upsample_matches_fourier_interpolation() {
        // El Centro (100 Hz) → 200 Hz: compare to an independent FFT (Fourier) resampling.
        let rec = read_at2("RSN6_IMPVALL.I_I-ELC180.AT2");
        let fs0 = 1.0 / rec.dt;
        let reference = fourier_resample_delayed(&rec.acc, fs0, 200.0, 0.0, rec.acc.len() * 2);
        let ours = resample_to_rate_with(
            &rec.acc,
            fs0,
            200.0,
            &KernelSpec { pass_frac: 0.8, stop_frac: 1.0, atten_db: 100.0 },
        );
        let m = ours.len().min(reference.len());
        let (mut e2, mut s2) = (0.0, 0.0);
        for k in 400..m - 400 {
            e2 += (ours[k] - reference[k]).powi(2);
            s2 += reference[k].powi(2);
        }
        let rel = (e2 / s2).sqrt();
        println!("El Centro 100->200 Hz vs Fourier interpolation: rel RMS difference {rel:.2e}");
        assert!(rel < 1e-3);
    }

    #[test]
    fn phase_table_matches_kernel() {
        // The drifting-clock path's interpolated weights against the kernel evaluated directly,
        // at positions spread over a sample, including both ends of the phase range.
        for spec in [RESAMPLE_SPEC, INTERP_SPEC] {
            let kernel = Kernel::new(256.0, 100.0, &spec);
            let table = PhaseTable::new(&kernel);
            let (mut direct, mut tabulated) = (Vec::new(), Vec::new());
            let mut worst: f64 = 0.0;
            for i in 0..=1000 {
                let u = 500.0 + i as f64 / 1000.0 - if i == 1000 { 1e-12 } else { 0.0 };
                let n0 = kernel.taps(u, &mut direct);
                let m0 = table.taps(u, &mut tabulated);
                for (j, w) in tabulated.iter().enumerate() {
                    let k = m0 + j as isize;
                    let exact = usize::try_from(k - n0).ok().and_then(|i| direct.get(i)).copied().unwrap_or(0.0);
                    worst = worst.max((w - exact).abs());
                }
                // Taps the table leaves out are the window's last, negligible ones.
                let covered = m0..m0 + tabulated.len() as isize;
                for (j, w) in direct.iter().enumerate() {
                    if !covered.contains(&(n0 + j as isize)) {
                        assert!(w.abs() < 1e-5, "u {u}: left-out tap {w}");
                    }
                }
            }
            println!("{spec:?}: {} taps, largest weight difference {worst:.1e}", 2 * table.half);
            assert!(worst < 1e-8, "phase table off by {worst}");
        }
    }

    #[test]
    fn drifting_ratio_uses_the_table_within_its_accuracy() {
        // A step that never repeats (256 Hz → 200 Hz on a clock 40 ppm fast) takes the table
        // path; the same times evaluated one by one with directly computed weights agree to 1e-8
        // of the signal's amplitude (the accuracy of the kernel's tabulated window).
        let fa = 256.0;
        let x: Vec<f64> =
            (0..(20.0 * fa) as usize).map(|k| sines(&[(1.0, 3.3, 0.1), (0.5, 41.0, 1.0)], k as f64 / fa)).collect();
        let kernel = Kernel::new(fa, 100.0, &RESAMPLE_SPEC);
        let step = fa / 200.0 * (1.0 + 4e-5);
        let n = ((x.len() - 2) as f64 / step) as usize + 1;
        // Off the integers: there the direct weights include the window's other end tap too (~1e-6).
        let grid = kernel.eval_grid(&[&x], 0.3, step, n).pop().unwrap();
        let mut weights = Vec::new();
        let worst = grid
            .iter()
            .enumerate()
            .map(|(k, v)| (v - kernel.value_at(&x, 0.3 + k as f64 * step, &mut weights)).abs())
            .fold(0.0, f64::max);
        println!("table vs direct weights on a drifting grid: largest difference {worst:.1e}");
        assert!(worst < 1e-8, "{worst}");
    }

    #[test]
    fn resampler_grid_is_resampling_at_shifted_times() {
        // 256 → 200 Hz shifted by 0.1234 s in one filter equals the band-limited signal at the
        // shifted times (the sines themselves) as closely as plain resampling does.
        let (fa, fb, lag) = (256.0, 200.0, 0.1234);
        let comps = [(1.0, 1.3, 0.2), (0.5, 23.4, -0.4), (0.3, 61.0, 0.9)];
        let x: Vec<f64> = (0..(20.0 * fa) as usize).map(|k| sines(&comps, k as f64 / fa)).collect();
        let y = Resampler::new(fa, fb).grid(&[&x], lag, 4000).pop().unwrap();
        let interior = 200..3700;
        let worst = interior.clone().map(|k| (y[k] - sines(&comps, lag + k as f64 / fb)).abs()).fold(0.0, f64::max);
        println!("256 -> 200 Hz shifted {lag} s: largest error {worst:.1e}");
        assert!(worst < 1e-4, "{worst}");
        assert!(y[3999].is_nan(), "beyond the record: NaN");
        // Equal rates: the fractional delay of sample_grid.
        assert_eq!(Resampler::new(fa, fa).grid(&[&x], lag, 100), sample_grid(&[&x], fa, lag, 100));
    }

    #[test]
    fn edges_and_degenerate_inputs() {
        let x = vec![1.0, 2.0, 3.0, 4.0];
        let v = sample_at(&x, 10.0, &[-0.01, 0.0, 0.3, 0.31, f64::NAN]);
        assert!(v[0].is_nan() && v[3].is_nan() && v[4].is_nan());
        // Odd reflection reproduces a straight line exactly at the samples.
        assert!((v[1] - 1.0).abs() < 1e-4 && (v[2] - 4.0).abs() < 1e-4, "{v:?}");
        assert!(sample_at(&[], 10.0, &[0.0])[0].is_nan());
        assert!(resample_to_rate(&[], 10.0, 20.0).is_empty());
        let one = resample_to_rate(&[5.0], 10.0, 20.0);
        assert!(one.len() == 1 && (one[0] - 5.0).abs() < 1e-4);
        assert_eq!(resample_to_rate(&x, 10.0, 10.0), x);
    }
}
