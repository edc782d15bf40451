//! Lognormal fragility curves fitted by maximum likelihood to overturn / no-overturn outcomes
//! (Baker 2015, "Efficient analytical fragility function fitting using dynamic structural
//! analysis", Earthquake Spectra 31(1)): P(overturn | IM) = Φ(ln(IM/θ)/β).
//!
//! The fit is a probit regression on ln IM, P = Φ(a + b ln IM), solved by Newton's method with
//! step halving (the log-likelihood is concave in (a, b)); then θ = exp(−a/b), β = 1/b.

/// Standard normal cumulative distribution.
pub fn normal_cdf(x: f64) -> f64 {
    0.5 * libm::erfc(-x / std::f64::consts::SQRT_2)
}

fn normal_pdf(x: f64) -> f64 {
    (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt()
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LognormalFit {
    /// θ: the intensity with a 50 % probability of overturning.
    pub median: f64,
    /// β: the logarithmic standard deviation.
    pub beta: f64,
    pub log_likelihood: f64,
    pub iterations: usize,
}

impl LognormalFit {
    pub fn probability(&self, im: f64) -> f64 {
        normal_cdf((im / self.median).ln() / self.beta)
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FitOutcome {
    Fitted(LognormalFit),
    /// Every run overturned, or none did: the data say nothing about the curve.
    AllOverturned,
    NoneOverturned,
    /// Every overturn happened above every survival: β → 0, the median lies in (below, above].
    Separated {
        highest_survival: f64,
        lowest_overturn: f64,
    },
}

/// Log-likelihood of the probit model with η = a + b·ln IM, its gradient and Hessian in (a, b).
fn probit_terms(x: &[f64], y: &[bool], a: f64, b: f64) -> (f64, [f64; 2], [[f64; 2]; 2]) {
    let (mut ll, mut g, mut h) = (0.0, [0.0; 2], [[0.0; 2]; 2]);
    for (&xi, &yi) in x.iter().zip(y) {
        let eta = a + b * xi;
        // For a failure, d ln Φ(η)/dη = φ(η)/Φ(η) = m and d²/dη² = −m(m + η); for a survival the
        // same with η → −η. The ratio is computed where Φ is not vanishingly small.
        let (sign, p) = if yi { (1.0, normal_cdf(eta)) } else { (-1.0, normal_cdf(-eta)) };
        let z = sign * eta;
        let m = if p > 1e-300 { normal_pdf(z) / p } else { -z };
        ll += p.max(1e-300).ln();
        let d1 = sign * m;
        let d2 = -m * (m + z);
        g[0] += d1;
        g[1] += d1 * xi;
        h[0][0] += d2;
        h[0][1] += d2 * xi;
        h[1][1] += d2 * xi * xi;
    }
    h[1][0] = h[0][1];
    (ll, g, h)
}

pub fn fit_lognormal(im: &[f64], overturned: &[bool]) -> FitOutcome {
    assert_eq!(im.len(), overturned.len(), "one outcome per intensity");
    assert!(im.iter().all(|&v| v > 0.0 && v.is_finite()), "intensities must be positive");
    let failures = overturned.iter().filter(|&&o| o).count();
    if failures == 0 {
        return FitOutcome::NoneOverturned;
    }
    if failures == im.len() {
        return FitOutcome::AllOverturned;
    }
    let highest_survival = im.iter().zip(overturned).filter(|(_, &o)| !o).map(|(&v, _)| v).fold(0.0, f64::max);
    let lowest_overturn = im.iter().zip(overturned).filter(|(_, &o)| o).map(|(&v, _)| v).fold(f64::INFINITY, f64::min);
    if highest_survival < lowest_overturn {
        return FitOutcome::Separated { highest_survival, lowest_overturn };
    }
    let x: Vec<f64> = im.iter().map(|v| v.ln()).collect();
    // Start from the log-midpoint of the overlap and β = 0.5.
    let center = 0.5 * (highest_survival.ln() + lowest_overturn.ln());
    let (mut a, mut b) = (-center / 0.5, 1.0 / 0.5);
    let (mut ll, mut g, mut h) = probit_terms(&x, overturned, a, b);
    let mut iterations = 0;
    for _ in 0..200 {
        iterations += 1;
        let det = h[0][0] * h[1][1] - h[0][1] * h[1][0];
        // Newton step on a concave function: −H⁻¹ g.
        let (da, db) = ((-h[1][1] * g[0] + h[0][1] * g[1]) / det, (h[1][0] * g[0] - h[0][0] * g[1]) / det);
        let mut step = 1.0;
        loop {
            let (na, nb) = (a + step * da, b + step * db);
            if nb > 0.0 {
                let (nll, ng, nh) = probit_terms(&x, overturned, na, nb);
                if nll >= ll - 1e-12 * ll.abs() {
                    let done = (na - a).abs() < 1e-12 * (1.0 + a.abs()) && (nb - b).abs() < 1e-12 * (1.0 + b.abs());
                    (a, b, ll, g, h) = (na, nb, nll, ng, nh);
                    if done {
                        return FitOutcome::Fitted(LognormalFit {
                            median: (-a / b).exp(),
                            beta: 1.0 / b,
                            log_likelihood: ll,
                            iterations,
                        });
                    }
                    break;
                }
            }
            step *= 0.5;
            if step < 1e-12 {
                return FitOutcome::Fitted(LognormalFit {
                    median: (-a / b).exp(),
                    beta: 1.0 / b,
                    log_likelihood: ll,
                    iterations,
                });
            }
        }
    }
    FitOutcome::Fitted(LognormalFit { median: (-a / b).exp(), beta: 1.0 / b, log_likelihood: ll, iterations })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_cdf_matches_tabulated_values() {
        // Abramowitz & Stegun Table 26.1.
        assert!((normal_cdf(0.0) - 0.5).abs() < 1e-16);
        assert!((normal_cdf(1.0) - 0.841_344_746_068_543).abs() < 1e-15);
        assert!((normal_cdf(-2.5) - 0.006_209_665_325_776_13).abs() < 1e-16);
    }

    #[test]
    fn recovers_the_curve_that_generated_the_outcomes() {
        // Outcomes drawn from θ = 3, β = 0.4 at 40 levels × 50 runs: the MLE lands within a few
        // standard errors (≈ 0.02 in ln θ and β here).
        let mut rng = crate::signal::synthetic_motion::SplitMix64::new(7);
        let (mut im, mut y) = (Vec::new(), Vec::new());
        for level in 0..40 {
            let v = 1.0 + 0.1 * level as f64;
            for _ in 0..50 {
                im.push(v);
                y.push(rng.next_f64() < normal_cdf((v / 3.0).ln() / 0.4));
            }
        }
        let FitOutcome::Fitted(fit) = fit_lognormal(&im, &y) else { panic!("expected a fit") };
        assert!((fit.median.ln() - 3f64.ln()).abs() < 0.05, "{fit:?}");
        assert!((fit.beta - 0.4).abs() < 0.06, "{fit:?}");
    }

    #[test]
    fn degenerate_outcomes_are_named_not_fitted() {
        assert_eq!(fit_lognormal(&[1.0, 2.0], &[false, false]), FitOutcome::NoneOverturned);
        assert_eq!(fit_lognormal(&[1.0, 2.0], &[true, true]), FitOutcome::AllOverturned);
        assert_eq!(
            fit_lognormal(&[1.0, 2.0, 3.0], &[false, true, true]),
            FitOutcome::Separated { highest_survival: 1.0, lowest_overturn: 2.0 }
        );
    }
}
