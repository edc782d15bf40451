//! Clock synchronisation of two records of the same motion (e.g. a shake-table floor
//! channel on one DAQ and an equipment accelerometer, or another DAQ's copy of the floor
//! channel, on another).
//!
//! Convention: the *target* lags the *reference* by `lag` seconds,
//! `target(t) ≈ a · reference(t − lag)` (a: unknown gain, may be negative for a flipped
//! sensor).  Both records must be at the same rate: resample first with
//! [`super::resample_bandlimited::resample_to_rate`].
//!
//! # Lag estimation ([`estimate_lag`])
//! 1. Means removed; inputs validated (empty, non-finite, constant, lag range).
//! 2. Raw cross-correlation `c[m] = Σ_j g[j]·r[j−m]` (g = target, r = reference) by FFT,
//!    zero-padded to a 2/3/5-smooth length `N ≥ n_r + n_g − 1`, so there is no circular
//!    wrap-around.  `c` peaks at `m ≈ lag·fs`.
//! 3. Integer peak: largest `|c[m]|` for `|m| ≤ M` (`M = floor(max_lag_s·fs)`).  Taking
//!    `|c|` makes the estimate insensitive to polarity; the sign is reported in
//!    `correlation`.
//! 4. Sub-sample refinement (default [`Refinement::BandLimitedNewton`]): the correlation of
//!    two band-limited sequences is itself band-limited and is exactly represented by its
//!    zero-padded spectrum `C_k = G_k·conj(R_k)`:
//!    `c(τ) = (1/N) Σ_k C_k e^{iω_k τ}`, `c'(τ)`, `c''(τ)` likewise (ω_k = 2πk/N, signed).
//!    The peak is the root of `c'(τ)` in `[m0−1, m0+1]`, found by safeguarded Newton
//!    (bisection fallback) started from the parabolic estimate; converged to 1e-10 sample.
//!    `c(τ)` at fractional τ equals `Σ_j g[j]·r(j−τ)` with r shifted by an exact
//!    FFT phase shift, i.e. the estimator maximises the correlation with a band-limited
//!    fractionally delayed reference.  The 3-point parabola through `c[m0−1..=m0+1]` is
//!    biased (the correlation peak is not a parabola; the bias depends on the offset and
//!    grows with the signal bandwidth relative to fs).  Measured on the noiseless real
//!    records at 200 Hz: parabolic max |bias| 0.7e-3–3e-3 sample (up to 15 µs), Newton
//!    ≤ 7e-6 sample (35 ns).  The parabola is kept as [`Refinement::Parabolic`] for
//!    comparison.
//! 5. Normalised correlation coefficient at the refined lag over the overlap:
//!    `ρ = Σ g[j]·r_s[j] / sqrt(Σ g[j]² · Σ r_s[j]²)`, `r_s[j] = r(j − τ̂)` (band-limited
//!    shift), sums over the samples `j` where both records exist; `ρ ∈ [−1, 1]`.
//! 6. Uncertainty (linearised error propagation with a noise spectrum estimated from the
//!    data, a "sandwich"/HAC estimate): near the true lag `τ̂ − τ ≈ −c'_noise(τ)/c''(τ)`
//!    and `c'_noise ≈ −Σ_j e[j]·w[j]`, where `e = g − a·r_s` is the residual of the gain
//!    fit (`a = Σ g r_s / Σ r_s²`) and `w[j] = ŝ'(j)` the derivative of the signal estimate
//!    `ŝ = (g + a·r_s)/(2a)` (averaging both channels halves the noise in `w`, so that the
//!    noise×noise part of `Var(c')` is counted once rather than twice).  For a stationary
//!    residual,
//!    `Var(c') = Σ_k R_e(k)·ρ_w(k)` with `R_e(k) = (1/N_ov) Σ_j e[j]e[j+k]` and
//!    `ρ_w(k) = Σ_j w[j]w[j+k]` (computed with one zero-padded FFT as
//!    `(1/(N_ov·L)) Σ_f |E_f|²|W_f|²`), hence
//!    ```text
//!    σ_τ = sqrt( Σ_k R_e(k) ρ_w(k) ) / |c''(τ̂)| / fs      [s]
//!    ```
//!    For white residual noise of variance σ_e² this reduces to the Cramér–Rao-type
//!    expression `σ_τ² = σ_e² / (a · Σ s'²)` (samples²), i.e.
//!    `1/(SNR · N_eff · (2π f_rms/fs)²)`.  The autocovariance form stays valid for coloured
//!    residuals (e.g. noise low-passed by the anti-aliasing filter, or model mismatch).
//!    It ignores edge effects and assumes the residual is independent of the signal.
//!    Measured on real records with 5 % and 30 % noise on both channels: the empirical
//!    std is ≈ 0.8 × the reported value (slightly conservative).
//!
//! # Errors
//! `Err(LagError)` for empty or too short (< 4 samples) inputs, non-finite values, constant
//! signals, invalid `fs`, a negative/non-finite `max_lag_s`, or `max_lag_s·fs` not smaller
//! than the shorter record (the lag range would be larger than the records).
//! `max_lag_s = None` searches `|lag| ≤ (min(n_r, n_g)/2)/fs` (at least half of the shorter
//! record overlaps at every candidate lag).  A peak on the edge of the search range is
//! returned as is (refinement is confined to the range); widen `max_lag_s` if `|lag_s|`
//! equals the limit.

use super::resample_bandlimited::sample_grid;
use rustfft::num_complex::Complex;
use rustfft::FftPlanner;
use std::f64::consts::PI;

/// Result of [`estimate_lag`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LagEstimate {
    /// Positive when the target lags the reference: `target(t) ≈ reference(t − lag)`.
    pub lag_s: f64,
    /// One-sigma uncertainty of `lag_s` (s), see the module docs for the formula.
    pub uncertainty_s: f64,
    /// Normalised correlation coefficient at the lag, over the overlap, in [−1, 1].
    pub correlation: f64,
}

/// Sub-sample peak refinement method.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refinement {
    /// Newton on the exact band-limited (spectral) interpolant of the correlation (default).
    BandLimitedNewton,
    /// 3-point parabola through the integer peak (biased; for comparison).
    Parabolic,
}

/// Why a lag cannot be estimated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LagError {
    #[error("sampling rate must be finite and > 0, got {0}")]
    SampleRate(f64),
    #[error("{0} is empty")]
    Empty(&'static str),
    #[error("{name} has {samples} samples; at least 4 are needed")]
    TooShort { name: &'static str, samples: usize },
    #[error("{name} has a non-finite value at sample {index}")]
    NotFinite { name: &'static str, index: usize },
    #[error("{0} is constant")]
    Constant(&'static str),
    #[error("max_lag_s must be finite and >= 0, got {0}")]
    MaxLag(f64),
    #[error("lag range ±{max_lag_s} s ({lags} samples) is not smaller than the shorter record ({shorter} samples = {shorter_s} s)")]
    LagRange { max_lag_s: f64, lags: f64, shorter: usize, shorter_s: f64 },
    #[error("records do not overlap at the estimated lag")]
    NoOverlap,
    #[error("a record is zero over the overlap at the estimated lag")]
    ZeroOverlap,
}

/// Estimate the lag of `target` relative to `reference` (both at rate `fs`).
/// See the module documentation for the method, conventions and errors.
pub fn estimate_lag(
    reference: &[f64],
    target: &[f64],
    fs: f64,
    max_lag_s: Option<f64>,
) -> Result<LagEstimate, LagError> {
    estimate_lag_with(reference, target, fs, max_lag_s, Refinement::BandLimitedNewton)
}

/// Return the target on the reference clock: `y[k] = x(k/fs + lag_s)` (band-limited
/// interpolation, [`super::resample_bandlimited::sample_at`]).  If `target(t) ≈ reference(t − lag)` then
/// `shift(target, fs, lag)[k] ≈ reference(k/fs)`.  Samples whose time `k/fs + lag_s`
/// falls outside the record are `NaN`.  Same length as `x`.
pub fn shift(x: &[f64], fs: f64, lag_s: f64) -> Vec<f64> {
    sample_grid(&[x], fs, lag_s, x.len()).pop().expect("one channel in, one out")
}

fn check_signal(name: &'static str, x: &[f64]) -> Result<Vec<f64>, LagError> {
    if x.is_empty() {
        return Err(LagError::Empty(name));
    }
    if x.len() < 4 {
        return Err(LagError::TooShort { name, samples: x.len() });
    }
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        return Err(LagError::NotFinite { name, index: i });
    }
    let mean = x.iter().sum::<f64>() / x.len() as f64;
    let y: Vec<f64> = x.iter().map(|v| v - mean).collect();
    let scale = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let dev = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if dev == 0.0 || dev <= 1e-12 * scale {
        return Err(LagError::Constant(name));
    }
    Ok(y)
}

/// Smallest n' ≥ n whose only prime factors are 2, 3, 5 (fast FFT sizes).
fn fast_len(n: usize) -> usize {
    let mut m = n.max(1);
    loop {
        let mut k = m;
        for p in [2, 3, 5] {
            while k.is_multiple_of(p) {
                k /= p;
            }
        }
        if k == 1 {
            return m;
        }
        m += 1;
    }
}

/// The length-`n` DFTs of two real sequences (zero-padded), from one complex transform of
/// `x + i·y`: X[k] = (Z[k] + conj Z[n−k]) / 2, Y[k] = (Z[k] − conj Z[n−k]) / 2i.
fn two_real_ffts(
    x: &[f64],
    y: &[f64],
    n: usize,
    fft: &dyn rustfft::Fft<f64>,
) -> (Vec<Complex<f64>>, Vec<Complex<f64>>) {
    let mut z = vec![Complex::new(0.0, 0.0); n];
    for (d, &v) in z.iter_mut().zip(x) {
        d.re = v;
    }
    for (d, &v) in z.iter_mut().zip(y) {
        d.im = v;
    }
    fft.process(&mut z);
    (0..n)
        .map(|k| {
            let (a, b) = (z[k], z[(n - k) % n].conj());
            ((a + b) * 0.5, (a - b) * Complex::new(0.0, -0.5))
        })
        .unzip()
}

/// The unscaled inverse transform (like rustfft's inverse plan) with a forward plan:
/// conj(F(conj(x))).
fn inverse_unscaled(forward: &dyn rustfft::Fft<f64>, buffer: &mut [Complex<f64>]) {
    buffer.iter_mut().for_each(|z| z.im = -z.im);
    forward.process(buffer);
    buffer.iter_mut().for_each(|z| z.im = -z.im);
}

/// Signed angular frequency (rad/sample) of FFT bin k of length n; the Nyquist bin is
/// taken as +π (real-signal cosine convention, consistent with taking real parts).
fn omega(k: usize, n: usize) -> f64 {
    let ks = if k <= n / 2 { k as f64 } else { k as f64 - n as f64 };
    2.0 * PI * ks / n as f64
}

/// c(τ), c'(τ), c''(τ) of the band-limited correlation from its spectrum (half spectrum
/// with Hermitian weights).
fn corr_eval(spec: &[Complex<f64>], n: usize, tau: f64) -> (f64, f64, f64) {
    let half = n / 2;
    let dphi = 2.0 * PI * tau / n as f64;
    let step = Complex::from_polar(1.0, dphi);
    let mut rot = Complex::new(1.0, 0.0);
    let (mut c0, mut c1, mut c2) = (0.0, 0.0, 0.0);
    for (k, ck) in spec.iter().enumerate().take(half + 1) {
        if k % 512 == 0 {
            rot = Complex::from_polar(1.0, dphi * k as f64); // re-sync the recurrence
        }
        let w = if k == 0 || (n.is_multiple_of(2) && k == half) { 1.0 } else { 2.0 };
        let om = 2.0 * PI * k as f64 / n as f64;
        let z = ck * rot;
        c0 += w * z.re;
        c1 -= w * om * z.im;
        c2 -= w * om * om * z.re;
        rot *= step;
    }
    let inv = 1.0 / n as f64;
    (c0 * inv, c1 * inv, c2 * inv)
}

/// [`estimate_lag`] with a choice of sub-sample refinement.
pub fn estimate_lag_with(
    reference: &[f64],
    target: &[f64],
    fs: f64,
    max_lag_s: Option<f64>,
    refinement: Refinement,
) -> Result<LagEstimate, LagError> {
    if !(fs.is_finite() && fs > 0.0) {
        return Err(LagError::SampleRate(fs));
    }
    let r = check_signal("reference", reference)?;
    let g = check_signal("target", target)?;
    let (nr, ng) = (r.len(), g.len());
    let nmin = nr.min(ng);
    let m_max: usize = match max_lag_s {
        Some(v) => {
            if !(v.is_finite() && v >= 0.0) {
                return Err(LagError::MaxLag(v));
            }
            let m = (v * fs + 1e-9).floor();
            if m >= nmin as f64 {
                return Err(LagError::LagRange { max_lag_s: v, lags: m, shorter: nmin, shorter_s: nmin as f64 / fs });
            }
            m as usize
        }
        None => nmin / 2,
    };

    // --- FFT cross-correlation, zero-padded (no wrap-around) ---
    let n = fast_len(nr + ng - 1);
    // One forward plan serves every transform here (inverses by conjugation, the uncertainty's
    // transforms at this length too): planning computes a twiddle sine per bin, and three plans
    // cost more than the transforms themselves.
    let fwd = FftPlanner::<f64>::new().plan_fft_forward(n);
    // Both records in one complex transform (reference real, target imaginary), then apart.
    let (rf, gf) = two_real_ffts(&r, &g, n, fwd.as_ref());
    let cspec: Vec<Complex<f64>> = gf.iter().zip(&rf).map(|(a, b)| a * b.conj()).collect();
    let mut cbuf = cspec.clone();
    inverse_unscaled(fwd.as_ref(), &mut cbuf);
    let c_at = |m: isize| -> f64 {
        let idx = if m >= 0 { m as usize } else { (n as isize + m) as usize };
        cbuf[idx].re / n as f64
    };

    // --- integer peak of |c| within ±M ---
    let mm = m_max as isize;
    let mut m0 = 0isize;
    let mut best = -1.0;
    for m in -mm..=mm {
        let v = c_at(m).abs();
        if v > best {
            best = v;
            m0 = m;
        }
    }
    let sgn = if c_at(m0) >= 0.0 { 1.0 } else { -1.0 };

    // --- sub-sample refinement ---
    let (ym, y0, yp) = (sgn * c_at(m0 - 1), sgn * c_at(m0), sgn * c_at(m0 + 1));
    let den = ym - 2.0 * y0 + yp;
    let para = if den < 0.0 { (0.5 * (ym - yp) / den).clamp(-1.0, 1.0) } else { 0.0 };
    let lo0 = ((m0 - 1) as f64).max(-(mm as f64));
    let hi0 = ((m0 + 1) as f64).min(mm as f64);
    let tau_para = (m0 as f64 + para).clamp(lo0, hi0);
    let half_spec = &cspec[..n / 2 + 1];
    let tau = match refinement {
        Refinement::Parabolic => tau_para,
        Refinement::BandLimitedNewton => {
            if hi0 <= lo0 {
                m0 as f64
            } else {
                let f = |t: f64| {
                    let (_, d1, d2) = corr_eval(half_spec, n, t);
                    (sgn * d1, sgn * d2)
                };
                let (flo, _) = f(lo0);
                let (fhi, _) = f(hi0);
                if !(flo > 0.0 && fhi < 0.0) {
                    // Not bracketed (peak at the edge of the search range): take the
                    // better of the parabolic estimate and the range edges.
                    let cands = [tau_para, lo0, hi0];
                    let mut bt = tau_para;
                    let mut bv = f64::NEG_INFINITY;
                    for &t in &cands {
                        let v = sgn * corr_eval(half_spec, n, t).0;
                        if v > bv {
                            bv = v;
                            bt = t;
                        }
                    }
                    bt
                } else {
                    let (mut lo, mut hi) = (lo0, hi0);
                    let mut t = tau_para.clamp(lo + 1e-6, hi - 1e-6);
                    for _ in 0..100 {
                        let (fv, fd) = f(t);
                        if fv > 0.0 {
                            lo = t;
                        } else {
                            hi = t;
                        }
                        let newton = t - fv / fd;
                        let next = if fd < 0.0 && newton > lo && newton < hi { newton } else { 0.5 * (lo + hi) };
                        let step = (next - t).abs();
                        t = next;
                        if step < 1e-10 || hi - lo < 1e-10 {
                            break;
                        }
                    }
                    t
                }
            }
        }
    };
    let (_, _, c2) = corr_eval(half_spec, n, tau);

    // --- shifted reference r_s[j] = r(j − τ) and its derivative w[j] = r'(j − τ) ---
    // r_s and r_s' are real: one inverse transform of RS + i·RD gives r_s in its real part and
    // r_s' in its imaginary part (a real signal's spectrum times i is the spectrum of i·signal).
    let mut rs_rd = vec![Complex::new(0.0, 0.0); n];
    let mut gd = vec![Complex::new(0.0, 0.0); n];
    // e^{−iω_k τ} by a rotation per bin, re-synced every 512 bins and where ω_k turns negative.
    let step = Complex::from_polar(1.0, -2.0 * PI * tau / n as f64);
    let mut rot = Complex::new(1.0, 0.0);
    for k in 0..n {
        let om = omega(k, n);
        if k % 512 == 0 || k == n / 2 + 1 {
            rot = Complex::from_polar(1.0, -om * tau);
        }
        let mut z = rf[k] * rot;
        rot *= step;
        let mut zd = z * Complex::new(0.0, om);
        if 2 * k == n {
            // The Nyquist bin of a real signal is real; the shift made it complex. Its real part
            // is what a real inverse transform keeps, and the packing needs both spectra Hermitian.
            (z.im, zd.im) = (0.0, 0.0);
        }
        rs_rd[k] = z + Complex::new(0.0, 1.0) * zd;
        gd[k] = gf[k] * Complex::new(0.0, om);
    }
    inverse_unscaled(fwd.as_ref(), &mut rs_rd);
    inverse_unscaled(fwd.as_ref(), &mut gd);
    let j0 = ((tau - 1e-9).ceil().max(0.0)) as usize;
    let j1f = ((nr - 1) as f64 + tau + 1e-9).floor().min((ng - 1) as f64);
    if j1f < j0 as f64 + 1.0 {
        return Err(LagError::NoOverlap);
    }
    let j1 = j1f as usize;
    let nov = j1 - j0 + 1;
    let scale = 1.0 / n as f64;
    let rsv: Vec<f64> = rs_rd[j0..=j1].iter().map(|z| z.re * scale).collect();
    let gv = &g[j0..=j1];
    let sgr: f64 = gv.iter().zip(&rsv).map(|(a, b)| a * b).sum();
    let sgg: f64 = gv.iter().map(|a| a * a).sum();
    let srr: f64 = rsv.iter().map(|a| a * a).sum();
    if sgg == 0.0 || srr == 0.0 {
        return Err(LagError::ZeroOverlap);
    }
    let correlation = (sgr / (sgg * srr).sqrt()).clamp(-1.0, 1.0);

    // --- uncertainty (see module docs) ---
    let a = sgr / srr;
    // w = derivative of the signal estimate (g + a·r_s)/(2a): averaging the two channels
    // halves the noise in the weights, so the noise×noise part of Var(c') is counted once.
    let wv: Vec<f64> = (j0..=j1).map(|j| (gd[j].re / a + rs_rd[j].im) * 0.5 * scale).collect();
    // Any length ≥ 2·nov − 1 gives the same sum (no wrap-around); n is one, and planned.
    debug_assert!(n >= 2 * nov - 1);
    let ev: Vec<f64> = gv.iter().zip(&rsv).map(|(g, r)| g - a * r).collect();
    let (eb, wb) = two_real_ffts(&ev, &wv, n, fwd.as_ref());
    let s: f64 = eb.iter().zip(&wb).map(|(e, w)| e.norm_sqr() * w.norm_sqr()).sum();
    let var_c1 = (s / (n as f64 * nov as f64)).max(0.0);
    let curv = sgn * c2;
    let uncertainty_s = if curv < 0.0 { var_c1.sqrt() / curv.abs() / fs } else { f64::INFINITY };

    Ok(LagEstimate { lag_s: tau / fs, uncertainty_s, correlation })
}

#[cfg(test)]
mod tests {
    use super::super::resample_bandlimited::resample_to_rate;
    use super::super::test_support::*;
    use super::*;

    const FS_REF: f64 = 200.0;
    const FS_TGT: f64 = 256.0;

    /// Reference at 200 Hz and target = same physical signal delayed by `lag` at 256 Hz,
    /// both from the independent Fourier resampler; optional white noise (fraction of the
    /// reference RMS) on both channels; the target is then brought to 200 Hz with the code
    /// under test.
    fn make_pair(acc: &[f64], dt: f64, lag: f64, noise_frac: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let fs0 = 1.0 / dt;
        let pad = 2 * acc.len() + (10.0 * fs0) as usize;
        let mut r = fourier_resample_delayed(acc, fs0, FS_REF, 0.0, pad);
        let mut t = fourier_resample_delayed(acc, fs0, FS_TGT, lag, pad);
        if noise_frac > 0.0 {
            let sigma = noise_frac * rms(&r);
            add_noise(&mut r, sigma, &mut Rng::new(seed));
            add_noise(&mut t, sigma, &mut Rng::new(seed ^ 0xDEAD_BEEF_1234_5678));
        }
        let t200 = resample_to_rate(&t, FS_TGT, FS_REF);
        (r, t200)
    }

    #[test]
    fn known_lag_recovery_real_records() {
        let records = ["RSN6_IMPVALL.I_I-ELC180.AT2", "RSN1084_NORTHR_SCS052.AT2"];
        let lags = [0.8373, -1.2917, 2.4561, 0.0421];
        let mut worst: f64 = 0.0;
        for (ri, name) in records.iter().enumerate() {
            let rec = read_at2(name);
            for (li, &lag) in lags.iter().enumerate() {
                let (r, t) = make_pair(&rec.acc, rec.dt, lag, 0.05, 1000 + (ri * 10 + li) as u64);
                let est = estimate_lag(&r, &t, FS_REF, Some(5.0)).expect("estimate_lag failed");
                let err = est.lag_s - lag;
                worst = worst.max(err.abs());
                println!(
                    "{name:<30} lag {lag:+.4} s: estimate {:+.6} s, error {:+.3e} s ({:+.4} ms), \
                     reported sigma {:.2e} s, rho {:.5}",
                    est.lag_s,
                    err,
                    err * 1e3,
                    est.uncertainty_s,
                    est.correlation
                );
                assert!(err.abs() < 1e-3, "{name} lag {lag}: error {err} s exceeds 1 ms");
                assert!(est.correlation > 0.95);
            }
        }
        println!("worst |error| over 2 records x 4 lags (5 % noise, 256->200 Hz): {:.3e} s", worst);
    }

    #[test]
    fn refinement_bias_newton_vs_parabolic() {
        // Noiseless, same rate (no resampling), fractional offsets across one sample.
        for name in ["RSN6_IMPVALL.I_I-ELC180.AT2", "RSN1084_NORTHR_SCS052.AT2"] {
            let rec = read_at2(name);
            let fs0 = 1.0 / rec.dt;
            let pad = 2 * rec.acc.len() + (10.0 * fs0) as usize;
            let r = fourier_resample_delayed(&rec.acc, fs0, FS_REF, 0.0, pad);
            let (mut max_newton, mut max_para): (f64, f64) = (0.0, 0.0);
            let mut mean_abs_para = 0.0;
            let nfrac = 10;
            for i in 0..nfrac {
                let frac = (i as f64 + 0.5) / nfrac as f64;
                let lag = (300.0 + frac) / FS_REF;
                let t = fourier_resample_delayed(&rec.acc, fs0, FS_REF, lag, pad);
                let en = estimate_lag_with(&r, &t, FS_REF, Some(5.0), Refinement::BandLimitedNewton).unwrap();
                let ep = estimate_lag_with(&r, &t, FS_REF, Some(5.0), Refinement::Parabolic).unwrap();
                let (dn, dp) = ((en.lag_s - lag) * FS_REF, (ep.lag_s - lag) * FS_REF);
                max_newton = max_newton.max(dn.abs());
                max_para = max_para.max(dp.abs());
                mean_abs_para += dp.abs() / nfrac as f64;
            }
            println!(
                "{name}: sub-sample bias (noiseless, 200 Hz): band-limited Newton max |err| {:.2e} samples \
                 ({:.2e} s); parabolic max |err| {:.2e} samples ({:.2e} s), mean |err| {:.2e} samples",
                max_newton,
                max_newton / FS_REF,
                max_para,
                max_para / FS_REF,
                mean_abs_para
            );
            assert!(max_newton < 1e-3, "Newton refinement bias {max_newton} samples");
            assert!(max_newton < max_para);
        }
    }

    #[test]
    fn uncertainty_calibration() {
        let rec = read_at2("RSN6_IMPVALL.I_I-ELC180.AT2");
        let lag = 0.8373;
        for noise in [0.05, 0.3] {
            let mut errs = Vec::new();
            let mut sig = Vec::new();
            for k in 0..20u64 {
                let (r, t) = make_pair(&rec.acc, rec.dt, lag, noise, 77 + 1000 * k);
                let est = estimate_lag(&r, &t, FS_REF, Some(5.0)).unwrap();
                errs.push(est.lag_s - lag);
                sig.push(est.uncertainty_s);
            }
            let n = errs.len() as f64;
            let mean = errs.iter().sum::<f64>() / n;
            let sd = (errs.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            let rms_err = (errs.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
            let sig_mean = sig.iter().sum::<f64>() / n;
            let ratio = sd / sig_mean;
            println!(
                "noise {:.0} %: 20 realisations: empirical std {sd:.3e} s (mean error {mean:+.2e}, RMS {rms_err:.3e}); \
                 mean reported uncertainty {sig_mean:.3e} s; std/reported = {ratio:.2}",
                noise * 100.0
            );
            // 20 realisations estimate the spread to ±16 % (one sigma): (0.5, 2) is about ±3 sigma
            // around 1 and still catches a reported uncertainty off by a factor 2 (measured: 1.10
            // at 5 % noise, 0.74 at 30 %).
            assert!(ratio > 0.5 && ratio < 2.0, "uncertainty miscalibrated: ratio {ratio}");
        }
    }

    #[test]
    fn correlation_levels_and_polarity() {
        let rec = read_at2("RSN6_IMPVALL.I_I-ELC180.AT2");
        let (r0, t0) = make_pair(&rec.acc, rec.dt, 0.8373, 0.0, 1);
        let e0 = estimate_lag(&r0, &t0, FS_REF, Some(5.0)).unwrap();
        let (r1, t1) = make_pair(&rec.acc, rec.dt, 0.8373, 0.05, 2);
        let e1 = estimate_lag(&r1, &t1, FS_REF, Some(5.0)).unwrap();
        let (r2, t2) = make_pair(&rec.acc, rec.dt, 0.8373, 0.5, 3);
        let e2 = estimate_lag(&r2, &t2, FS_REF, Some(5.0)).unwrap();
        // Unrelated: El Centro 1940 vs Loma Prieta 1989 Gilroy, both at 200 Hz.
        let other = read_at2("RSN763_LOMAP_GIL067.AT2");
        let o = resample_to_rate(&other.acc, 1.0 / other.dt, FS_REF);
        let eu = estimate_lag(&r0, &o, FS_REF, Some(10.0)).unwrap();
        // Flipped polarity.
        let tneg: Vec<f64> = t1.iter().map(|v| -v).collect();
        let en = estimate_lag(&r1, &tneg, FS_REF, Some(5.0)).unwrap();
        println!(
            "rho: noiseless {:.6} (err {:+.2e} s, sigma {:.1e}); 5 % noise {:.5}; 50 % noise {:.4}; \
             unrelated records {:.4}; flipped polarity {:.5} (lag err {:+.2e} s)",
            e0.correlation,
            e0.lag_s - 0.8373,
            e0.uncertainty_s,
            e1.correlation,
            e2.correlation,
            eu.correlation,
            en.correlation,
            en.lag_s - 0.8373
        );
        assert!(e0.correlation > 0.9999);
        assert!((e0.lag_s - 0.8373).abs() < 1e-5);
        assert!(e1.correlation < e0.correlation && e2.correlation < e1.correlation);
        assert!(e2.correlation > 0.6 && e2.correlation < 0.95);
        assert!(eu.correlation.abs() < 0.3, "unrelated correlation {}", eu.correlation);
        assert!(en.correlation < -0.99 && (en.lag_s - 0.8373).abs() < 1e-3);
    }

    #[test]
    fn shift_puts_target_on_reference_clock() {
        let rec = read_at2("RSN1084_NORTHR_SCS052.AT2");
        for lag in [0.8373, -1.2917] {
            let (r, t) = make_pair(&rec.acc, rec.dt, lag, 0.0, 5);
            let est = estimate_lag(&r, &t, FS_REF, Some(5.0)).unwrap();
            let y = shift(&t, FS_REF, est.lag_s);
            let (mut e2, mut s2, mut nan) = (0.0, 0.0, 0usize);
            for (k, (a, b)) in y.iter().zip(&r).enumerate() {
                if a.is_nan() {
                    nan += 1;
                    continue;
                }
                let tk = k as f64 / FS_REF;
                // skip 1 s near the target's record edges
                if tk + est.lag_s < 1.0 || tk + est.lag_s > (t.len() as f64 / FS_REF) - 1.0 {
                    continue;
                }
                e2 += (a - b).powi(2);
                s2 += b * b;
            }
            let rel = (e2 / s2).sqrt();
            println!("shift by {lag:+.4} s: rel RMS misfit to reference {rel:.2e}, {nan} NaN samples outside record");
            assert!(rel < 1e-3);
            let expected_nan = (lag.abs() * FS_REF).ceil() as usize;
            assert!(nan.abs_diff(expected_nan) <= 1, "{nan} NaN, expected ~{expected_nan}");
        }
    }

    #[test]
    fn errors_are_reported() {
        let x: Vec<f64> = (0..100).map(|i| (i as f64 * 0.37).sin()).collect();
        assert!(estimate_lag(&[], &x, 100.0, None).unwrap_err().to_string().contains("empty"));
        assert!(estimate_lag(&x, &[], 100.0, None).unwrap_err().to_string().contains("empty"));
        assert!(estimate_lag(&x, &[2.5; 100], 100.0, None).unwrap_err().to_string().contains("constant"));
        assert!(estimate_lag(&[1.0; 50], &x, 100.0, None).unwrap_err().to_string().contains("constant"));
        assert!(estimate_lag(&x, &x, 100.0, Some(1.0)).unwrap_err().to_string().contains("lag range"));
        assert!(estimate_lag(&x, &x, 100.0, Some(-1.0)).is_err());
        assert!(estimate_lag(&x, &x, 0.0, None).is_err());
        let mut y = x.clone();
        y[7] = f64::NAN;
        assert!(estimate_lag(&x, &y, 100.0, None).unwrap_err().to_string().contains("non-finite"));
        assert!(estimate_lag(&x, &x, 100.0, Some(0.5)).is_ok());
    }

    #[test]
    fn lag_of_two_noisy_120s_records_at_200hz_within_1ms() {
        let rec = read_at2("RSN2110_DENALI_FAIGO360.AT2"); // 234 s at 200 Hz
        let seg = &rec.acc[4000..4000 + 24000]; // 120 s
        let lag = 1.2345;
        let r = fourier_resample_delayed(seg, 200.0, 200.0, 0.0, 2 * seg.len());
        let mut t = fourier_resample_delayed(seg, 200.0, 200.0, lag, 2 * seg.len());
        add_noise(&mut t, 0.05 * rms(&r), &mut Rng::new(9));
        let est = estimate_lag(&r, &t, 200.0, Some(10.0)).unwrap();
        println!(
            "estimate_lag on 2 x 120 s @ 200 Hz (24000 samples each): lag error {:+.2e} s, sigma {:.1e} s, rho {:.4}",
            est.lag_s - lag,
            est.uncertainty_s,
            est.correlation
        );
        assert!((est.lag_s - lag).abs() < 1e-3);
    }
}
