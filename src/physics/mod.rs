//! Linear structural models used to synthesise floor and equipment responses.
pub mod sdof;
pub mod shear_building;

/// Least-squares fit of x(t) ≈ s sin(Ωt) + c cos(Ωt) over the samples from `start`;
/// returns (amplitude, phase) with x ≈ A sin(Ωt + φ). Steady-state checks against closed forms.
#[cfg(test)]
pub(crate) fn fit_harmonic(x: &[f64], dt: f64, omega: f64, start: usize) -> (f64, f64) {
    let (mut ss, mut sc, mut cc, mut xs, mut xc) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (i, &v) in x.iter().enumerate().skip(start) {
        let (s, c) = (omega * i as f64 * dt).sin_cos();
        ss += s * s;
        sc += s * c;
        cc += c * c;
        xs += v * s;
        xc += v * c;
    }
    let det = ss * cc - sc * sc;
    let a = (xs * cc - xc * sc) / det;
    let b = (xc * ss - xs * sc) / det;
    (a.hypot(b), b.atan2(a))
}
