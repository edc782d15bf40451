//! Least-squares polynomial baseline (the study's cubic), fitted in scaled time.
//!
//! Fitting in x = (t − c)/s ∈ [−1, 1] with Householder QR keeps the problem well conditioned on
//! records of any length; raw-seconds monomials of a 120 s record would square a condition
//! number of ~10⁷ in the normal equations.

use super::dot;

/// p(t) = Σ coefficients[k] · ((t − center)/half_span)^k
#[derive(Debug, Clone, PartialEq)]
pub struct ScaledPolynomial {
    pub center: f64,
    pub half_span: f64,
    pub coefficients: Vec<f64>,
}

impl ScaledPolynomial {
    pub fn eval(&self, t: f64) -> f64 {
        self.eval_scaled((t - self.center) / self.half_span)
    }

    /// p at scaled time x = (t − center)/half_span.
    pub fn eval_scaled(&self, x: f64) -> f64 {
        self.coefficients.iter().rev().fold(0.0, |acc, &c| acc * x + c)
    }

    /// Coefficients in seconds, highest power first: the `numpy.polyfit` convention.
    pub fn monomial_coefficients(&self) -> Vec<f64> {
        let order = self.coefficients.len() - 1;
        let mut out = vec![0.0; order + 1]; // out[j] multiplies t^j
        for (k, &a) in self.coefficients.iter().enumerate() {
            let scale = a / self.half_span.powi(k as i32);
            for (j, slot) in out.iter_mut().enumerate().take(k + 1) {
                *slot += scale * binomial(k, j) * (-self.center).powi((k - j) as i32);
            }
        }
        out.reverse();
        out
    }
}

fn binomial(n: usize, k: usize) -> f64 {
    (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64)
}

/// Fits a polynomial of `order` to (t, y) by least squares. Needs more samples than coefficients.
pub fn fit_polynomial(t: &[f64], y: &[f64], order: usize) -> ScaledPolynomial {
    PolynomialBasis::new(t, order).fit(y)
}

/// Subtracts the fitted polynomial; returns the corrected values and the fit.
pub fn remove_polynomial(t: &[f64], y: &[f64], order: usize) -> (Vec<f64>, ScaledPolynomial) {
    PolynomialBasis::new(t, order).remove(y)
}

/// The QR factorisation of the scaled-monomial design matrix of one time base: every channel
/// of a record shares it, so each further fit costs one pass of the reflectors over its values.
pub struct PolynomialBasis {
    center: f64,
    half_span: f64,
    /// Scaled time x = (t − center)/half_span.
    x: Vec<f64>,
    /// Column-major R above the diagonal and the Householder vectors on and below it.
    reflectors: Vec<Vec<f64>>,
    /// R's diagonal.
    diag: Vec<f64>,
    /// ‖v_k‖² of each Householder vector.
    norms2: Vec<f64>,
}

impl PolynomialBasis {
    /// Needs more samples than coefficients.
    pub fn new(t: &[f64], order: usize) -> Self {
        let n = t.len();
        let m = order + 1;
        assert!(n >= m, "{n} samples cannot determine {m} polynomial coefficients");
        let (lo, hi) = t.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        let center = 0.5 * (lo + hi);
        let half_span = if hi > lo { 0.5 * (hi - lo) } else { 1.0 };
        let x: Vec<f64> = t.iter().map(|&ti| (ti - center) / half_span).collect();
        // Column-major design matrix of scaled monomials, x^k = x^(k−1)·x.
        let mut reflectors = vec![vec![1.0; n]];
        for k in 1..m {
            let next = reflectors[k - 1].iter().zip(&x).map(|(p, xi)| p * xi).collect();
            reflectors.push(next);
        }
        let (mut diag, mut norms2) = (vec![0.0; m], vec![0.0; m]);
        for k in 0..m {
            let a = &mut reflectors;
            let norm = dot(&a[k][k..], &a[k][k..]).sqrt();
            let alpha = if a[k][k] > 0.0 { -norm } else { norm };
            diag[k] = alpha;
            a[k][k] -= alpha; // v = x − alpha e1, stored in place
            norms2[k] = dot(&a[k][k..], &a[k][k..]);
            let (done, rest) = a.split_at_mut(k + 1);
            for column in rest.iter_mut() {
                reflect(&done[k][k..], norms2[k], &mut column[k..]);
            }
        }
        PolynomialBasis { center, half_span, x, reflectors, diag, norms2 }
    }

    /// The least-squares polynomial through (t, y).
    pub fn fit(&self, y: &[f64]) -> ScaledPolynomial {
        assert_eq!(self.x.len(), y.len(), "time and values differ in length");
        let m = self.diag.len();
        let mut b = y.to_vec();
        for k in 0..m {
            reflect(&self.reflectors[k][k..], self.norms2[k], &mut b[k..]);
        }
        let mut c = vec![0.0; m];
        for k in (0..m).rev() {
            let s: f64 = (k + 1..m).map(|j| self.reflectors[j][k] * c[j]).sum();
            c[k] = (b[k] - s) / self.diag[k];
        }
        ScaledPolynomial { center: self.center, half_span: self.half_span, coefficients: c }
    }

    /// `y` minus its fitted polynomial, and the fit.
    pub fn remove(&self, y: &[f64]) -> (Vec<f64>, ScaledPolynomial) {
        let fit = self.fit(y);
        let corrected = self.x.iter().zip(y).map(|(&x, &yi)| yi - fit.eval_scaled(x)).collect();
        (corrected, fit)
    }
}

/// Applies the Householder reflection I − 2vvᵀ/‖v‖² to `column` (a zero `v` is the identity).
fn reflect(v: &[f64], vnorm2: f64, column: &mut [f64]) {
    if vnorm2 == 0.0 {
        return;
    }
    let f = 2.0 * dot(v, column) / vnorm2;
    column.iter_mut().zip(v).for_each(|(c, vi)| *c -= f * vi);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_an_exact_cubic_on_a_long_record() {
        // 150 s at 200 Hz: raw-seconds normal equations would lose ~14 digits here.
        let t: Vec<f64> = (0..30_000).map(|i| i as f64 * 0.005).collect();
        let truth = [2.0e-6, -3.0e-4, 0.02, -0.7]; // numpy order
        let y: Vec<f64> = t.iter().map(|&x| ((truth[0] * x + truth[1]) * x + truth[2]) * x + truth[3]).collect();
        let (corrected, fit) = remove_polynomial(&t, &y, 3);
        for (got, want) in fit.monomial_coefficients().iter().zip(truth) {
            assert!((got - want).abs() <= 1e-9 * want.abs(), "{got} vs {want}");
        }
        assert!(corrected.iter().all(|r| r.abs() < 1e-12));
    }

    #[test]
    fn residual_is_orthogonal_to_the_basis() {
        let t: Vec<f64> = (0..1000).map(|i| 3.0 + i as f64 * 0.01).collect();
        let y: Vec<f64> = t.iter().map(|x| (7.0 * x).sin() + 0.1 * x).collect();
        let (r, fit) = remove_polynomial(&t, &y, 3);
        for k in 0..4 {
            let dot: f64 = t.iter().zip(&r).map(|(ti, ri)| ((ti - fit.center) / fit.half_span).powi(k) * ri).sum();
            assert!(dot.abs() < 1e-10, "k={k} dot={dot}");
        }
    }

    #[test]
    fn order_zero_is_the_mean() {
        let t = [0.0, 1.0, 2.0, 3.0];
        let y = [1.0, 2.0, 3.0, 6.0];
        let fit = fit_polynomial(&t, &y, 0);
        assert!((fit.monomial_coefficients()[0] - 3.0).abs() < 1e-15);
    }
}
