//! Test helpers: PEER AT2 reader, deterministic noise, independent Fourier resampler.
//! Compiled for tests only.

use rustfft::num_complex::Complex;
use rustfft::FftPlanner;
use std::f64::consts::PI;
use std::path::PathBuf;

/// Ground-motion folder relative to CARGO_MANIFEST_DIR: `../shared` beside the project root.
pub const GROUND_MOTIONS_REL: &str = "../shared/data/ground_motions";

pub struct At2 {
    pub dt: f64,
    pub acc: Vec<f64>,
}

pub fn ground_motion_path(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(GROUND_MOTIONS_REL);
    if !dir.is_dir() {
        panic!(
            "real ground-motion records not found: {} does not exist (expected the shared data folder \
             ../shared/data/ground_motions beside the project root)",
            dir.display()
        );
    }
    dir.join(name)
}

/// A shared PEER AT2 record through shakeflow's own reader (tested against SOURCES.md).
pub fn read_at2(name: &str) -> At2 {
    let path = ground_motion_path(name);
    let raw = crate::io::records::read_at2(&path).unwrap_or_else(|e| panic!("{e}"));
    At2 { dt: raw.dt.expect("AT2 headers state DT"), acc: raw.channels[0].values.clone() }
}

/// Deterministic noise for the tests.
pub use crate::signal::synthetic_motion::SplitMix64 as Rng;

pub fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

pub fn add_noise(x: &mut [f64], sigma: f64, rng: &mut Rng) {
    for v in x.iter_mut() {
        *v += sigma * rng.normal();
    }
}

fn is_smooth(mut n: usize) -> bool {
    for p in [2, 3, 5, 7] {
        while n.is_multiple_of(p) {
            n /= p;
        }
    }
    n == 1
}

/// Independent reference resampler (classical FFT / Fourier-series method, as
/// scipy.signal.resample), used to build test signals without the code under test.
///
/// The "physical signal" is the band-limited periodic interpolant of `x` zero-padded to
/// P ≥ `min_pad` samples (Nyquist bin dropped).  Returns `y[k] = x(k/fs_out − delay_s)`
/// for `k = 0..=floor((n−1)·fs_out/fs_in)`: the same physical signal, delayed by
/// `delay_s` and sampled at `fs_out`.  `fs_out/fs_in` must be rational with denominator
/// ≤ 10000.
pub fn fourier_resample_delayed(x: &[f64], fs_in: f64, fs_out: f64, delay_s: f64, min_pad: usize) -> Vec<f64> {
    let ratio = fs_out / fs_in;
    let q = (1..=10000usize)
        .find(|&q| ((ratio * q as f64) - (ratio * q as f64).round()).abs() < 1e-9)
        .expect("rate ratio not rational");
    let mut p = min_pad.max(x.len() + (delay_s.abs() * fs_in).ceil() as usize + 16);
    p = p.div_ceil(q) * q;
    while !is_smooth(p) || (p / q) % 2 == 1 {
        p += q;
    }
    let qn = (p as f64 * ratio).round() as usize;
    let mut planner = FftPlanner::<f64>::new();
    let mut buf: Vec<Complex<f64>> = (0..p).map(|i| Complex::new(if i < x.len() { x[i] } else { 0.0 }, 0.0)).collect();
    planner.plan_fft_forward(p).process(&mut buf);
    let mut out = vec![Complex::new(0.0, 0.0); qn];
    let kmax = p.min(qn) / 2; // exclusive: the Nyquist bin is dropped
    for j in 0..kmax {
        let f = j as f64 * fs_in / p as f64;
        let ph = Complex::from_polar(1.0, -2.0 * PI * f * delay_s);
        out[j] = buf[j] * ph;
        if j > 0 {
            out[qn - j] = buf[p - j] * ph.conj();
        }
    }
    planner.plan_fft_inverse(qn).process(&mut out);
    let n_out = ((x.len() - 1) as f64 * ratio + 1e-9).floor() as usize + 1;
    out[..n_out].iter().map(|c| c.re / p as f64).collect()
}

/// Least-squares fit of x(t) ≈ s sin(Ωt) + c cos(Ωt) over samples `range`; returns (amplitude,
/// phase) with x ≈ A sin(Ωt + φ). Steady-state checks against closed forms.
pub fn fit_harmonic(x: &[f64], dt: f64, omega: f64, range: std::ops::Range<usize>) -> (f64, f64) {
    let (mut ss, mut sc, mut cc, mut xs, mut xc) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for i in range {
        let (s, c) = (omega * i as f64 * dt).sin_cos();
        ss += s * s;
        sc += s * c;
        cc += c * c;
        xs += x[i] * s;
        xc += x[i] * c;
    }
    let det = ss * cc - sc * sc;
    let a = (xs * cc - xc * sc) / det;
    let b = (xc * ss - xs * sc) / det;
    (a.hypot(b), b.atan2(a))
}
