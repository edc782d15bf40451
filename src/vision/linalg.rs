//! Small dense linear algebra for the camera model: 3×3 helpers, rotations, RQ, a one-sided
//! Jacobi SVD (the DLT's null vector) and a pivoted linear solve (Levenberg–Marquardt steps).
//!
//! Sizes here are at most a few hundred rows by 13 columns, so clarity beats blocking; every
//! routine is sequential, hence bit-identical from run to run.

pub type Mat3 = [[f64; 3]; 3];
pub type Vec3 = [f64; 3];

pub fn mat3_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    out
}

pub fn mat3_vec(a: &Mat3, v: &Vec3) -> Vec3 {
    [0, 1, 2].map(|i| a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2])
}

pub fn transpose3(a: &Mat3) -> Mat3 {
    [0, 1, 2].map(|i| [a[0][i], a[1][i], a[2][i]])
}

pub fn det3(a: &Mat3) -> f64 {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

pub fn inverse3(a: &Mat3) -> Option<Mat3> {
    let det = det3(a);
    if !det.is_finite() || det == 0.0 {
        return None;
    }
    let c = |r0: usize, c0: usize, r1: usize, c1: usize| a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0];
    let adjugate = [
        [c(1, 1, 2, 2), -c(0, 1, 2, 2), c(0, 1, 1, 2)],
        [-c(1, 0, 2, 2), c(0, 0, 2, 2), -c(0, 0, 1, 2)],
        [c(1, 0, 2, 1), -c(0, 0, 2, 1), c(0, 0, 1, 1)],
    ];
    Some(adjugate.map(|row| row.map(|v| v / det)))
}

pub fn dot3(a: &Vec3, b: &Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn cross3(a: &Vec3, b: &Vec3) -> Vec3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

pub fn norm3(a: &Vec3) -> f64 {
    dot3(a, a).sqrt()
}

/// Rotation matrix of a Rodrigues vector (axis × angle), as OpenCV's `Rodrigues`.
pub fn rodrigues(r: &Vec3) -> Mat3 {
    let theta = norm3(r);
    let k = [[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]];
    let k2 = mat3_mul(&k, &k);
    // sin θ/θ and (1 − cos θ)/θ², by series near zero where the quotients lose digits.
    let (a, b) = if theta < 1e-4 {
        let t2 = theta * theta;
        (1.0 - t2 / 6.0, 0.5 - t2 / 24.0)
    } else {
        (theta.sin() / theta, (1.0 - theta.cos()) / (theta * theta))
    };
    let mut out = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = f64::from(u8::from(i == j)) + a * k[i][j] + b * k2[i][j];
        }
    }
    out
}

/// Rodrigues vector of a rotation matrix (inverse of [`rodrigues`]), robust near 0 and π.
pub fn rodrigues_from_matrix(r: &Mat3) -> Vec3 {
    let trace = r[0][0] + r[1][1] + r[2][2];
    let cos = ((trace - 1.0) / 2.0).clamp(-1.0, 1.0);
    let theta = cos.acos();
    let axis_sin = [r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]];
    if theta < 1e-6 {
        return axis_sin.map(|v| v / 2.0);
    }
    if std::f64::consts::PI - theta > 1e-4 {
        let scale = theta / (2.0 * theta.sin());
        return axis_sin.map(|v| v * scale);
    }
    // Near π: the axis is the dominant column of (R + I)/2 = a aᵀ.
    let b = [0, 1, 2].map(|i| [0, 1, 2].map(|j| (r[i][j] + f64::from(u8::from(i == j))) / 2.0));
    let i = (0..3).max_by(|&x, &y| b[x][x].total_cmp(&b[y][y])).expect("three candidates");
    let mut axis = b[i];
    let n = norm3(&axis);
    axis = axis.map(|v| v / n);
    // Sign: match the (small) antisymmetric part when there is one.
    if dot3(&axis, &axis_sin) < 0.0 {
        axis = axis.map(|v| -v);
    }
    axis.map(|v| v * theta)
}

/// RQ decomposition M = K R with K upper triangular (positive diagonal) and R orthonormal.
/// Needs det(M) > 0 for R to be a rotation; callers fix the sign of P first.
pub fn rq3(m: &Mat3) -> (Mat3, Mat3) {
    // Gram–Schmidt on the rows from the bottom up: M = K R ⇔ rows of M are combinations of R's rows.
    let r3 = m[2].map(|v| v / norm3(&m[2]));
    let k23 = dot3(&m[1], &r3);
    let r2u = [0, 1, 2].map(|j| m[1][j] - k23 * r3[j]);
    let k22 = norm3(&r2u);
    let r2 = r2u.map(|v| v / k22);
    let k13 = dot3(&m[0], &r3);
    let k12 = dot3(&m[0], &r2);
    let r1u = [0, 1, 2].map(|j| m[0][j] - k12 * r2[j] - k13 * r3[j]);
    let k11 = norm3(&r1u);
    let r1 = r1u.map(|v| v / k11);
    let k33 = norm3(&m[2]);
    let k = [[k11, k12, k13], [0.0, k22, k23], [0.0, 0.0, k33]];
    (k, [r1, r2, r3])
}

/// Right singular vectors and singular values of an `rows × cols` row-major matrix
/// (one-sided Jacobi, Hestenes): values in decreasing order, V's columns matching.
/// Accurate for the small, possibly ill-conditioned DLT systems (no AᵀA squaring).
pub fn svd_right(a: &[f64], rows: usize, cols: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    assert_eq!(a.len(), rows * cols);
    // Work on columns: u[j] is column j of A·V.
    let mut u: Vec<Vec<f64>> = (0..cols).map(|j| (0..rows).map(|i| a[i * cols + j]).collect()).collect();
    let mut v: Vec<Vec<f64>> = (0..cols).map(|j| (0..cols).map(|i| f64::from(u8::from(i == j))).collect()).collect();
    for _sweep in 0..60 {
        let mut rotated = false;
        for p in 0..cols {
            for q in p + 1..cols {
                let alpha: f64 = u[p].iter().map(|x| x * x).sum();
                let beta: f64 = u[q].iter().map(|x| x * x).sum();
                let gamma: f64 = u[p].iter().zip(&u[q]).map(|(x, y)| x * y).sum();
                if gamma.abs() <= 1e-15 * (alpha * beta).sqrt() || gamma == 0.0 {
                    continue;
                }
                rotated = true;
                let zeta = (beta - alpha) / (2.0 * gamma);
                let t = zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
                let t = if zeta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (1.0 + t * t).sqrt();
                let s = c * t;
                rotate(&mut u, p, q, c, s);
                rotate(&mut v, p, q, c, s);
            }
        }
        if !rotated {
            break;
        }
    }
    let mut order: Vec<(f64, usize)> = (0..cols).map(|j| (u[j].iter().map(|x| x * x).sum::<f64>().sqrt(), j)).collect();
    order.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    (order.iter().map(|o| o.0).collect(), order.iter().map(|o| v[o.1].clone()).collect())
}

/// Plane rotation of vectors p < q: (x, y) → (c x − s y, s x + c y), element-wise.
fn rotate(vectors: &mut [Vec<f64>], p: usize, q: usize, c: f64, s: f64) {
    let (left, right) = vectors.split_at_mut(q);
    for (x, y) in left[p].iter_mut().zip(right[0].iter_mut()) {
        let (a, b) = (*x, *y);
        *x = c * a - s * b;
        *y = s * a + c * b;
    }
}

/// Solves `a x = b` (n × n, row-major) by Gaussian elimination with partial pivoting; None
/// when the matrix is singular to working precision.
pub fn solve(a: &[f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut m = a.to_vec();
    let mut x = b.to_vec();
    let scale = m.iter().fold(0.0_f64, |acc, v| acc.max(v.abs()));
    for col in 0..n {
        let pivot = (col..n).max_by(|&i, &j| m[i * n + col].abs().total_cmp(&m[j * n + col].abs()))?;
        if !(m[pivot * n + col].abs() > 1e-14 * scale) {
            return None;
        }
        if pivot != col {
            for k in 0..n {
                m.swap(col * n + k, pivot * n + k);
            }
            x.swap(col, pivot);
        }
        for row in col + 1..n {
            let f = m[row * n + col] / m[col * n + col];
            for k in col..n {
                m[row * n + k] -= f * m[col * n + k];
            }
            x[row] -= f * x[col];
        }
    }
    for col in (0..n).rev() {
        let tail: f64 = (col + 1..n).map(|k| m[col * n + k] * x[k]).sum();
        x[col] = (x[col] - tail) / m[col * n + col];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rodrigues_round_trips_including_near_pi() {
        for r in [[0.1, -0.2, 0.3], [1e-9, 0.0, 2e-9], [0.0, 3.1, 0.0], [2.0, -1.0, 1.5]] {
            let m = rodrigues(&r);
            let back = rodrigues_from_matrix(&m);
            let m2 = rodrigues(&back);
            for i in 0..3 {
                for j in 0..3 {
                    assert!((m[i][j] - m2[i][j]).abs() < 1e-9, "{r:?}");
                }
            }
            assert!((det3(&m) - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn rq_recovers_k_and_r() {
        let k = [[1400.0, 2.0, 960.0], [0.0, 1390.0, 540.0], [0.0, 0.0, 1.0]];
        let r = rodrigues(&[0.3, -0.2, 0.1]);
        let m = mat3_mul(&k, &r).map(|row| row.map(|v| v * 0.37));
        let (k2, r2) = rq3(&m);
        for i in 0..3 {
            for j in 0..3 {
                assert!((k2[i][j] / k2[2][2] - k[i][j]).abs() < 1e-9 * 1400.0);
                assert!((r2[i][j] - r[i][j]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn svd_finds_the_null_vector() {
        // Rows orthogonal to x = (1, 2, -1, 0.5)/|·|, plus a well-conditioned rest.
        let rows = [
            [2.0, -1.0, 0.0, 0.0],
            [1.0, 0.0, 1.0, 0.0],
            [0.0, 1.0, 2.0, 0.0],
            [1.0, 0.0, 0.0, -2.0],
            [3.0, -1.0, 1.0, 0.0],
        ];
        let a: Vec<f64> = rows.iter().flatten().copied().collect();
        let (s, v) = svd_right(&a, 5, 4);
        assert!(s[3] < 1e-12 * s[0], "{s:?}");
        let x = &v[3];
        let ratio = x[1] / x[0];
        assert!((ratio - 2.0).abs() < 1e-12 && (x[2] / x[0] + 1.0).abs() < 1e-12 && (x[3] / x[0] - 0.5).abs() < 1e-12);
    }

    #[test]
    fn solve_matches_a_known_system_and_refuses_singular() {
        let a = [4.0, 1.0, 0.0, 1.0, 3.0, 1.0, 0.0, 1.0, 2.0];
        let x = solve(&a, &[1.0, 2.0, 3.0], 3).unwrap();
        let back: Vec<f64> = (0..3).map(|i| (0..3).map(|j| a[i * 3 + j] * x[j]).sum()).collect();
        assert!(back.iter().zip([1.0, 2.0, 3.0]).all(|(b, e)| (b - e).abs() < 1e-14));
        assert!(solve(&[1.0, 2.0, 2.0, 4.0], &[1.0, 1.0], 2).is_none());
    }
}
