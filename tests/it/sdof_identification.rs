//! SDOF identification, low-coherence flag, edge cases and timing.
//!
//! Source of the "truth": a base-excited SDOF (fn = 3.1 Hz, ζ = 3 %)
//! integrated with the exact first-order-hold discretisation (state
//! transition via a 4×4 matrix exponential, i.e. exact for base acceleration
//! varying linearly between samples, the assumption of Nigam–Jennings),
//! driven by deterministic white noise (SplitMix64 + Box–Muller) at 200 Hz
//! for 300 s (12 seeds). Output: absolute acceleration of the mass.
//!
//! Tolerances (justified in the test bodies):
//! * frequency: |f − 3.1| ≤ 0.02 Hz (brief). The |H1| peak of the
//!   absolute-acceleration transmissibility lies at
//!   fn·sqrt(sqrt(1+8ζ²)−1)/(2ζ) = 3.0972 Hz, 2.8 mHz below fn.
//! * damping: |ζ − 0.03| ≤ 12 % per record, ≤ 5 % for the mean of 12
//!   records; budget in `sdof_identification`.

use shakeflow::signal::welch::{csd, identify_peak, transfer_function, welch, Detrend, WelchOptions, Window};

const FS: f64 = 200.0;
const FN: f64 = 3.1;
const ZETA: f64 = 0.03;

/// Deterministic standard-normal generator (SplitMix64 + Box–Muller).
struct Gauss {
    state: u64,
    spare: Option<f64>,
}

impl Gauss {
    fn new(seed: u64) -> Self {
        Gauss { state: seed, spare: None }
    }
    fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn uniform(&mut self) -> f64 {
        // (0, 1]
        ((self.next_u64() >> 11) as f64 + 1.0) / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        let (u1, u2) = (self.uniform(), self.uniform());
        let r = (-2.0 * u1.ln()).sqrt();
        let t = 2.0 * std::f64::consts::PI * u2;
        self.spare = Some(r * t.sin());
        r * t.cos()
    }
    fn vec(&mut self, n: usize) -> Vec<f64> {
        (0..n).map(|_| self.normal()).collect()
    }
}

type M4 = [[f64; 4]; 4];

fn matmul(a: &M4, b: &M4) -> M4 {
    let mut c = [[0.0; 4]; 4];
    for i in 0..4 {
        for j in 0..4 {
            for k in 0..4 {
                c[i][j] += a[i][k] * b[k][j];
            }
        }
    }
    c
}

/// Matrix exponential by scaling and squaring with a 24-term Taylor series.
fn expm(m: &M4) -> M4 {
    let norm = m.iter().map(|r| r.iter().map(|v| v.abs()).sum::<f64>()).fold(0.0, f64::max);
    let mut s = 0;
    while norm / 2f64.powi(s) > 0.25 {
        s += 1;
    }
    let scale = 2f64.powi(-s);
    let a: M4 = m.map(|r| r.map(|v| v * scale));
    let mut result = [[0.0; 4]; 4];
    let mut term = [[0.0; 4]; 4];
    for i in 0..4 {
        result[i][i] = 1.0;
        term[i][i] = 1.0;
    }
    for k in 1..=24 {
        term = matmul(&term, &a).map(|r| r.map(|v| v / k as f64));
        for i in 0..4 {
            for j in 0..4 {
                result[i][j] += term[i][j];
            }
        }
    }
    for _ in 0..s {
        result = matmul(&result, &result);
    }
    result
}

/// Absolute acceleration of the mass of a base-excited SDOF,
/// u'' + 2ζω u' + ω² u = −a_g(t), a_abs = u'' + a_g = −2ζω u' − ω² u,
/// with a_g linear between samples (exact first-order-hold discretisation).
fn sdof_abs_accel(ag: &[f64], fs: f64, f_n: f64, zeta: f64) -> Vec<f64> {
    let w = 2.0 * std::f64::consts::PI * f_n;
    let dt = 1.0 / fs;
    // augmented state [u, v, p, q], p = a_g, p' = q, q' = 0
    let m: M4 =
        [[0.0, dt, 0.0, 0.0], [-w * w * dt, -2.0 * zeta * w * dt, -dt, 0.0], [0.0, 0.0, 0.0, dt], [0.0, 0.0, 0.0, 0.0]];
    let e = expm(&m);
    let (mut u, mut v) = (0.0, 0.0);
    let mut out = Vec::with_capacity(ag.len());
    out.push(-2.0 * zeta * w * v - w * w * u);
    for i in 0..ag.len() - 1 {
        let p = ag[i];
        let q = (ag[i + 1] - ag[i]) / dt;
        let un = e[0][0] * u + e[0][1] * v + e[0][2] * p + e[0][3] * q;
        let vn = e[1][0] * u + e[1][1] * v + e[1][2] * p + e[1][3] * q;
        u = un;
        v = vn;
        out.push(-2.0 * zeta * w * v - w * w * u);
    }
    out
}

#[test]
fn integrator_matches_free_vibration() {
    // Check the discretisation: zero input, initial displacement via an
    // impulse-free start is not expressible, so instead check the step
    // response steady state: constant a_g = 1 → u → −1/ω², a_abs → 1.
    let ag = vec![1.0; 20_000];
    let a = sdof_abs_accel(&ag, FS, FN, ZETA);
    // analytic step response of relative displacement:
    // u(t) = −(1/ω²)[1 − e^{−ζωt}(cos ωd t + ζ/√(1−ζ²) sin ωd t)]
    let w = 2.0 * std::f64::consts::PI * FN;
    let wd = w * (1.0 - ZETA * ZETA).sqrt();
    let mut worst: f64 = 0.0;
    for (i, &ai) in a.iter().enumerate().step_by(37) {
        let t = i as f64 / FS;
        let env = (-ZETA * w * t).exp();
        // a_abs = −2ζω u' − ω² u
        let u = -(1.0 / (w * w)) * (1.0 - env * ((wd * t).cos() + ZETA / (1.0 - ZETA * ZETA).sqrt() * (wd * t).sin()));
        let du = -(1.0 / (w * w)) * env * (w * w / wd) * (wd * t).sin();
        let expect = -2.0 * ZETA * w * du - w * w * u;
        worst = worst.max((ai - expect).abs());
    }
    println!("step response max abs error vs closed form: {worst:.3e}");
    assert!(worst < 1e-9, "integrator error {worst:e}");
}

#[test]
fn sdof_identification() {
    let n = (300.0 * FS) as usize;
    let opts = WelchOptions::matlab_default(n);
    println!(
        "MATLAB defaults for n = {n}: L = {}, noverlap = {}, nfft = {}, df = {:.5} Hz",
        opts.segment_len,
        opts.overlap,
        opts.nfft(),
        FS / opts.nfft() as f64
    );
    let mut zetas = Vec::new();
    let mut max_ferr: f64 = 0.0;
    for seed in 1u64..=12 {
        let ag = Gauss::new(seed).vec(n);
        let acc = sdof_abs_accel(&ag, FS, FN, ZETA);
        let tf = transfer_function(&ag, &acc, FS, &opts).unwrap();
        let p = identify_peak(&tf, (1.0, 10.0), 0.8).expect("peak found");
        let z = p.damping_ratio.expect("half-power crossings inside band");
        println!(
            "seed {seed}: f = {:.5} Hz (err {:+.5} Hz), zeta = {:.5} (err {:+.2} %), gain {:.3}, coherence {:.5}",
            p.frequency_hz,
            p.frequency_hz - FN,
            z,
            100.0 * (z - ZETA) / ZETA,
            p.peak_gain,
            p.coherence
        );
        // Frequency: brief's tolerance.
        assert!((p.frequency_hz - FN).abs() <= 0.02, "frequency error");
        // Damping: ±12 % relative per seed (0.0264 ≤ ζ ≤ 0.0336). Budget:
        // the half-power method applied to the exact absolute-acceleration
        // transmissibility gives 0.03005 (+0.2 %); the Hamming window
        // (3 dB width ≈ 1.3·fs/L ≈ 0.02 Hz) broadens the 0.186 Hz half-power
        // band by ~1–2 %; random error of |H1| with 7 averages at
        // γ² ≈ 0.99 is sqrt(1−γ²)/(γ·sqrt(2·7)) ≈ 2–3 % per bin, which
        // becomes ≈ 3–4 % (1σ) in the interpolated bandwidth. Observed over
        // seeds 1–12: −4.0 % … +8.0 %, mean +2.2 %. 12 % ≈ bias + 3σ, and
        // still catches a √2 / factor-2 error in the bandwidth definition.
        assert!((z - ZETA).abs() <= 0.12 * ZETA, "damping {z} outside 0.03 ± 12 %");
        max_ferr = max_ferr.max((p.frequency_hz - FN).abs());
        assert!(!p.low_coherence, "noise-free SDOF must have high coherence");
        zetas.push(z);
    }
    let mean = zetas.iter().sum::<f64>() / zetas.len() as f64;
    println!(
        "over 12 seeds: max |f err| = {max_ferr:.5} Hz; mean zeta {mean:.5} ({:+.2} %)",
        100.0 * (mean - ZETA) / ZETA
    );
    // Mean over 12 independent records: bias (~+2 %) + σ/√12 (~1 %).
    assert!((mean - ZETA).abs() <= 0.05 * ZETA, "mean damping {mean}");
}

#[test]
fn low_coherence_is_flagged() {
    let n = (300.0 * FS) as usize;
    let ag = Gauss::new(11).vec(n);
    let acc = sdof_abs_accel(&ag, FS, FN, ZETA);
    let mut g = Gauss::new(12);
    // Output mostly unrelated noise: 5 % of the SDOF response + 10× white
    // noise; true coherence at the resonance ≈ (0.05·16.7)²/(0.05·16.7)²+100)
    // ≈ 0.007, elsewhere smaller.
    let y: Vec<f64> = acc.iter().map(|a| 0.05 * a + 10.0 * g.normal()).collect();
    // (1) Hann, 2048-sample segments, 50 % overlap: 57 averages, so the
    // estimator's bias for zero coherence (~1/57) is well below 0.5.
    let opts =
        WelchOptions { window: Window::Hann, segment_len: 2048, overlap: 1024, detrend: Detrend::Constant, nfft: None };
    let tf = transfer_function(&ag, &y, FS, &opts).unwrap();
    let p = identify_peak(&tf, (1.0, 10.0), 0.5).expect("a peak is always reported");
    println!(
        "low-coherence, Hann 2048 ({} segments): f = {:.4} Hz, coherence {:.4}, flagged {}",
        tf.segments, p.frequency_hz, p.coherence, p.low_coherence
    );
    assert!(p.low_coherence);
    assert!(p.coherence < 0.2);
    // (2) MATLAB defaults: only 7 averages, so the coherence estimate of an
    // unrelated pair scatters up to ~0.4 (bias ≈ 1/7); still flagged at 0.5.
    let opts = WelchOptions::matlab_default(n);
    let tf = transfer_function(&ag, &y, FS, &opts).unwrap();
    let p = identify_peak(&tf, (1.0, 10.0), 0.5).unwrap();
    println!(
        "low-coherence, MATLAB defaults ({} segments): f = {:.4} Hz, coherence {:.4}, flagged {}",
        tf.segments, p.frequency_hz, p.coherence, p.low_coherence
    );
    assert!(p.low_coherence);
}

#[test]
fn edge_cases_are_errors_not_panics() {
    let x = Gauss::new(3).vec(100);
    let hann512 =
        WelchOptions { window: Window::Hann, segment_len: 512, overlap: 256, detrend: Detrend::Constant, nfft: None };
    // input shorter than a segment
    let e = welch(&x, FS, &hann512).unwrap_err().to_string();
    assert!(e.contains("fewer than one segment"), "{e}");
    assert!(csd(&x, &x, FS, &hann512).is_err());
    assert!(transfer_function(&x, &x, FS, &hann512).is_err());
    // MATLAB defaults on tiny inputs (L = fix(n/4.5) < 2) and empty input
    for n in [0usize, 1, 5, 8] {
        let xs = vec![1.0; n];
        assert!(transfer_function(&xs, &xs, FS, &WelchOptions::matlab_default(n)).is_err(), "n = {n}");
    }
    // n = 9 is the smallest length MATLAB-default segmenting accepts
    let x9 = Gauss::new(9).vec(9);
    assert!(transfer_function(&x9, &x9, FS, &WelchOptions::matlab_default(9)).is_ok());
    let ok = WelchOptions { segment_len: 64, overlap: 32, ..hann512 };
    // length mismatch, bad overlap, bad nfft, bad fs, non-finite samples
    assert!(csd(&x, &x[..99], FS, &ok).is_err());
    assert!(welch(&x, FS, &WelchOptions { overlap: 64, ..ok }).is_err());
    assert!(welch(&x, FS, &WelchOptions { nfft: Some(32), ..ok }).is_err());
    assert!(welch(&x, 0.0, &ok).is_err());
    assert!(welch(&x, f64::NAN, &ok).is_err());
    let mut xn = x.clone();
    xn[7] = f64::NAN;
    assert!(welch(&xn, FS, &ok).is_err());
    assert!(transfer_function(&x, &xn, FS, &ok).is_err());
    assert!(welch(&x, FS, &ok).is_ok());
}

#[test]
fn constant_input_does_not_panic() {
    let n = 4096;
    let y = Gauss::new(4).vec(n);
    let c = vec![3.0; n];
    // Constant detrend removes everything: Pxx ≡ 0, so H1 = 0/0 = NaN and
    // coherence = NaN (as in scipy); identify_peak finds no finite bin.
    let opts =
        WelchOptions { window: Window::Hann, segment_len: 512, overlap: 256, detrend: Detrend::Constant, nfft: None };
    let tf = transfer_function(&c, &y, FS, &opts).unwrap();
    assert!(tf.pxx.iter().all(|&p| p == 0.0));
    assert!(tf.coherence.iter().all(|v| v.is_nan()));
    assert!(identify_peak(&tf, (1.0, 10.0), 0.5).is_none());
    // Without detrending (MATLAB defaults) a constant has finite spectra.
    let tf = transfer_function(&c, &y, FS, &WelchOptions::matlab_default(n)).unwrap();
    assert!(tf.pxx.iter().all(|p| p.is_finite()));
    let _ = identify_peak(&tf, (1.0, 10.0), 0.5); // no panic; value irrelevant
                                                  // All-zero input and output.
    let z = vec![0.0; n];
    let tf = transfer_function(&z, &z, FS, &WelchOptions::matlab_default(n)).unwrap();
    assert!(tf.coherence.iter().all(|v| v.is_nan()));
    assert!(identify_peak(&tf, (0.0, 100.0), 0.5).is_none());
    let (_, p) = welch(&z, FS, &opts).unwrap();
    assert!(p.iter().all(|&v| v == 0.0));
}
