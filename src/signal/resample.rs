//! Gap filling and resampling onto a uniform grid (linear: exact for the piecewise-linear
//! signal the samples define, and it never invents overshoot at a gap).

/// Replaces NaN runs by straight lines between their finite neighbours (edges: nearest value).
/// Returns how many samples were filled; an all-NaN series is left as it is.
pub fn fill_gaps_linear(values: &mut [f64]) -> usize {
    let finite: Vec<usize> = (0..values.len()).filter(|&i| values[i].is_finite()).collect();
    let (Some(&first), Some(&last)) = (finite.first(), finite.last()) else { return 0 };
    let mut filled = 0;
    for i in 0..first {
        values[i] = values[first];
        filled += 1;
    }
    for i in last + 1..values.len() {
        values[i] = values[last];
        filled += 1;
    }
    for pair in finite.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        for i in a + 1..b {
            let w = (i - a) as f64 / (b - a) as f64;
            values[i] = values[a] * (1.0 - w) + values[b] * w;
            filled += 1;
        }
    }
    filled
}

/// Linear interpolation of (t, y) at `t0 + k·dt`, k < n; `t` must be increasing.
pub fn resample_linear(t: &[f64], y: &[f64], t0: f64, dt: f64, n: usize) -> Vec<f64> {
    let mut j = 0;
    (0..n)
        .map(|k| {
            let tk = t0 + k as f64 * dt;
            while j + 2 < t.len() && t[j + 1] < tk {
                j += 1;
            }
            let (ta, tb) = (t[j], t[j + 1]);
            let w = ((tk - ta) / (tb - ta)).clamp(0.0, 1.0);
            y[j] * (1.0 - w) + y[j + 1] * w
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fills_interior_and_edge_gaps() {
        let mut v = [f64::NAN, 1.0, f64::NAN, f64::NAN, 4.0, f64::NAN];
        assert_eq!(fill_gaps_linear(&mut v), 4);
        assert_eq!(v, [1.0, 1.0, 2.0, 3.0, 4.0, 4.0]);
    }

    #[test]
    fn resampling_a_line_is_exact() {
        let t = [0.0, 0.1, 0.25, 0.3, 0.5];
        let y: Vec<f64> = t.iter().map(|x| 2.0 * x + 1.0).collect();
        let r = resample_linear(&t, &y, 0.0, 0.05, 11);
        for (k, v) in r.iter().enumerate() {
            assert!((v - (2.0 * 0.05 * k as f64 + 1.0)).abs() < 1e-12);
        }
    }
}
