//! Camera calibration from known 3D ↔ 2D pairs: the normalised DLT (Hartley & Zisserman,
//! Alg. 7.1) for a start, then Levenberg–Marquardt on the reprojection error over the
//! physical parameters (fx, fy, skew, cx, cy, rotation, translation[, k₁[, k₂]]), which span the
//! same cameras as a free P when there is no distortion.
//!
//! Skew may be held at zero (OpenCV's model, one parameter fewer).
//!
//! Reported: the study's objective (Eq. 2, mean reprojection distance) and the RMS distance,
//! whose expectation under Gaussian pixel noise σ is σ√2·√(1 − d/2n) for d parameters.

use super::camera::{Camera, Intrinsics};
use super::linalg;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlPoint {
    pub world: [f64; 3],
    pub pixel: [f64; 2],
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Distortion {
    None,
    K1,
    K1K2,
}

/// What the calibration fits: the study's free P (11 parameters, skew included), or P with zero
/// skew (10, as OpenCV's model), each optionally with radial distortion.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Model {
    pub distortion: Distortion,
    pub zero_skew: bool,
}

impl Model {
    /// The study's: a free projection matrix, no distortion.
    pub const PINHOLE: Model = Model { distortion: Distortion::None, zero_skew: false };

    pub fn parameters(self) -> usize {
        let distortion = match self.distortion {
            Distortion::None => 0,
            Distortion::K1 => 1,
            Distortion::K1K2 => 2,
        };
        11 + distortion - usize::from(self.zero_skew)
    }
}

/// Control points closer to a plane than this fraction of their spread are refused: P is then
/// not determined (a plane only fixes a homography).
pub const COPLANAR_RATIO: f64 = 0.01;
/// Below this, the calibration works but is poorly conditioned: a warning.
pub const THIN_RATIO: f64 = 0.05;
/// The study's rule (its Eq. 1 needs n ≥ 8; 6 is the algebraic minimum for 11 unknowns).
pub const MIN_POINTS: usize = 8;
/// A flagged residual is at least this large (px), however good the fit.
pub const MIN_OUTLIER_PX: f64 = 0.5;

#[derive(Debug, Clone, PartialEq)]
pub enum CalibrationError {
    TooFewPoints(usize),
    /// RMS distance of the points from their best plane, and their RMS spread in that plane.
    Coplanar {
        off_plane: f64,
        spread: f64,
    },
    Degenerate(String),
    /// Index of a point the DLT camera sees behind itself.
    BehindCamera(usize),
}

impl std::fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CalibrationError::TooFewPoints(n) => {
                write!(f, "{n} control point(s): at least {MIN_POINTS} are needed (the study's rule; 11 unknowns need 6 at the very least)")
            }
            CalibrationError::Coplanar { off_plane, spread } => write!(
                f,
                "the control points are coplanar: they lie within {off_plane:.3} (RMS) of one plane while spreading {spread:.1} across it, so the camera is not determined"
            ),
            CalibrationError::Degenerate(why) => write!(f, "degenerate control points: {why}"),
            CalibrationError::BehindCamera(i) => {
                write!(f, "control point {} lies behind the camera the points imply", i + 1)
            }
        }
    }
}

#[derive(Debug, Clone)]
pub struct Calibration {
    pub camera: Camera,
    /// Observed minus reprojected pixel, per point.
    pub residuals: Vec<[f64; 2]>,
    /// Eq. 2: mean reprojection distance.
    pub mean_distance_px: f64,
    pub rms_px: f64,
    /// Eq. 2 for the DLT start (before the nonlinear refinement).
    pub dlt_mean_distance_px: f64,
    pub iterations: usize,
    pub model: Model,
    pub parameters: usize,
    /// Distance of each point from its prediction by the camera fitted without it (px).
    pub leave_one_out_px: Vec<f64>,
    /// Leave-one-out distances above this are outliers.
    pub outlier_threshold_px: f64,
    pub outliers: Vec<bool>,
    /// Ratio of the points' RMS distance from their best plane to their spread (≥ COPLANAR_RATIO).
    pub thickness_ratio: f64,
    pub warnings: Vec<String>,
}

pub fn calibrate(points: &[ControlPoint], model: Model, outlier_sigma: f64) -> Result<Calibration, CalibrationError> {
    let n = points.len();
    if n < MIN_POINTS {
        return Err(CalibrationError::TooFewPoints(n));
    }
    let thickness_ratio = check_not_coplanar(points)?;
    let mut warnings = Vec::new();
    if thickness_ratio < THIN_RATIO {
        warnings.push(format!(
            "the control points are nearly coplanar (off-plane RMS {:.1} % of their spread): add points off that plane for a well-conditioned calibration",
            100.0 * thickness_ratio
        ));
    }
    let dlt = dlt(points)?;
    if let Some(i) = points.iter().position(|p| dlt.project(&p.world).is_none()) {
        return Err(CalibrationError::BehindCamera(i));
    }
    let dlt_mean_distance_px = distances(&dlt, points).iter().sum::<f64>() / n as f64;
    let (camera, iterations) = refine(points, &dlt, model);
    let residuals: Vec<[f64; 2]> = points
        .iter()
        .map(|p| {
            let [u, v] = camera.project(&p.world).unwrap_or([f64::NAN; 2]);
            [p.pixel[0] - u, p.pixel[1] - v]
        })
        .collect();
    let d: Vec<f64> = residuals.iter().map(|r| r[0].hypot(r[1])).collect();
    let mean_distance_px = d.iter().sum::<f64>() / n as f64;
    let rms_px = (d.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
    // A gross error spreads over every residual of a least-squares fit, so outliers are judged
    // by leave-one-out prediction errors: each point against the camera fitted without it.
    let leave_one_out: Vec<f64> = (0..n)
        .map(|i| {
            let others: Vec<ControlPoint> =
                points.iter().enumerate().filter(|(j, _)| *j != i).map(|(_, p)| *p).collect();
            let (without, _) = refine(&others, &camera, model);
            without
                .project(&points[i].world)
                .map_or(f64::INFINITY, |[u, v]| (points[i].pixel[0] - u).hypot(points[i].pixel[1] - v))
        })
        .collect();
    // Robust noise scale: the median of a 2D Gaussian's distance (Rayleigh) is σ√(2 ln 2).
    let mut sorted = leave_one_out.clone();
    sorted.sort_by(f64::total_cmp);
    let median = if n % 2 == 1 { sorted[n / 2] } else { 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]) };
    let sigma = median / (2.0 * std::f64::consts::LN_2).sqrt();
    let outlier_threshold_px = (outlier_sigma * sigma).max(MIN_OUTLIER_PX);
    let outliers: Vec<bool> = leave_one_out.iter().map(|&x| !(x <= outlier_threshold_px)).collect();
    if camera.k1 != 0.0 || camera.k2 != 0.0 {
        let worst = points
            .iter()
            .filter_map(|p| camera.project(&p.world))
            .filter(|[u, v]| camera.normalised_of_pixel(*u, *v).is_none())
            .count();
        if worst > 0 {
            warnings.push(format!(
                "{worst} control point(s) lie beyond the radius where the fitted distortion can be inverted"
            ));
        }
    }
    Ok(Calibration {
        camera,
        residuals,
        mean_distance_px,
        rms_px,
        dlt_mean_distance_px,
        iterations,
        model,
        parameters: model.parameters(),
        leave_one_out_px: leave_one_out,
        outlier_threshold_px,
        outliers,
        thickness_ratio,
        warnings,
    })
}

/// The expected RMS reprojection distance of a maximum-likelihood fit of `parameters` unknowns
/// to `n` points with Gaussian pixel noise `sigma` per coordinate (HZ Result 5.2, per point).
pub fn expected_rms_px(sigma: f64, n: usize, parameters: usize) -> f64 {
    sigma * 2f64.sqrt() * (1.0 - parameters as f64 / (2.0 * n as f64)).max(0.0).sqrt()
}

fn check_not_coplanar(points: &[ControlPoint]) -> Result<f64, CalibrationError> {
    let n = points.len() as f64;
    let mean = [0, 1, 2].map(|k| points.iter().map(|p| p.world[k]).sum::<f64>() / n);
    let centred: Vec<f64> = points.iter().flat_map(|p| [0, 1, 2].map(|k| p.world[k] - mean[k])).collect();
    let (s, _) = linalg::svd_right(&centred, points.len(), 3);
    let spread = s[0] / n.sqrt();
    let off_plane = s[2] / n.sqrt();
    if !(spread > 0.0) {
        return Err(CalibrationError::Degenerate("all control points are at the same 3D position".into()));
    }
    let ratio = off_plane / spread;
    if ratio < COPLANAR_RATIO {
        return Err(CalibrationError::Coplanar { off_plane, spread });
    }
    Ok(ratio)
}

/// Similarity that moves points to their centroid and scales their RMS distance to √dim.
fn normalising(coords: &[Vec<f64>]) -> (Vec<f64>, f64) {
    let dim = coords[0].len();
    let n = coords.len() as f64;
    let mean: Vec<f64> = (0..dim).map(|k| coords.iter().map(|c| c[k]).sum::<f64>() / n).collect();
    let rms = (coords.iter().map(|c| (0..dim).map(|k| (c[k] - mean[k]).powi(2)).sum::<f64>()).sum::<f64>() / n).sqrt();
    (mean, (dim as f64).sqrt() / rms)
}

/// Normalised DLT (HZ Alg. 7.1): the null vector of the 2n × 12 system in normalised
/// coordinates, denormalised.
fn dlt(points: &[ControlPoint]) -> Result<Camera, CalibrationError> {
    let world: Vec<Vec<f64>> = points.iter().map(|p| p.world.to_vec()).collect();
    let image: Vec<Vec<f64>> = points.iter().map(|p| p.pixel.to_vec()).collect();
    let (wm, ws) = normalising(&world);
    let (im, is) = normalising(&image);
    let mut a = Vec::with_capacity(points.len() * 24);
    for p in points {
        let x = [(p.world[0] - wm[0]) * ws, (p.world[1] - wm[1]) * ws, (p.world[2] - wm[2]) * ws, 1.0];
        let u = (p.pixel[0] - im[0]) * is;
        let v = (p.pixel[1] - im[1]) * is;
        a.extend(x.iter().map(|_| 0.0));
        a.extend(x.iter().map(|c| -c));
        a.extend(x.iter().map(|c| v * c));
        a.extend(x);
        a.extend(x.iter().map(|_| 0.0));
        a.extend(x.iter().map(|c| -u * c));
    }
    let (s, v) = linalg::svd_right(&a, 2 * points.len(), 12);
    if !(s[10] > 1e-9 * s[0]) {
        return Err(CalibrationError::Degenerate(
            "the 3D ↔ 2D pairs do not determine a camera (repeated points or a degenerate arrangement)".into(),
        ));
    }
    let pn = &v[11];
    // P = T⁻¹ P̃ U with U = [[ws I, −ws m], [0, 1]] and T⁻¹ = [[I/is, im], [0, 1]].
    let mut p = [[0.0; 4]; 3];
    for r in 0..3 {
        let row = &pn[4 * r..4 * r + 4];
        let shift = row[0] * wm[0] + row[1] * wm[1] + row[2] * wm[2];
        p[r] = [row[0] * ws, row[1] * ws, row[2] * ws, row[3] - ws * shift];
    }
    let third = p[2];
    for (row, centre) in [(0, im[0]), (1, im[1])] {
        for (v, t) in p[row].iter_mut().zip(third) {
            *v = *v / is + centre * t;
        }
    }
    Camera::from_projection(&p, 0.0, 0.0)
        .ok_or_else(|| CalibrationError::Degenerate("the DLT camera has a singular 3×3 block".into()))
}

fn distances(camera: &Camera, points: &[ControlPoint]) -> Vec<f64> {
    points
        .iter()
        .map(|p| camera.project(&p.world).map_or(f64::INFINITY, |[u, v]| (p.pixel[0] - u).hypot(p.pixel[1] - v)))
        .collect()
}

fn to_params(camera: &Camera, distortion: Distortion) -> Vec<f64> {
    let k = &camera.intrinsics;
    let r = linalg::rodrigues_from_matrix(&camera.rotation);
    let t = camera.translation;
    let mut params = vec![k.fx, k.fy, k.skew, k.cx, k.cy, r[0], r[1], r[2], t[0], t[1], t[2]];
    match distortion {
        Distortion::None => {}
        Distortion::K1 => params.push(camera.k1),
        Distortion::K1K2 => params.extend([camera.k1, camera.k2]),
    }
    params
}

fn from_params(params: &[f64]) -> Camera {
    let k = Intrinsics { fx: params[0], fy: params[1], skew: params[2], cx: params[3], cy: params[4] };
    let rotation = linalg::rodrigues(&[params[5], params[6], params[7]]);
    let k1 = params.get(11).copied().unwrap_or(0.0);
    let k2 = params.get(12).copied().unwrap_or(0.0);
    Camera::new(k, rotation, [params[8], params[9], params[10]], k1, k2)
}

/// Residuals (observed − projected), 2 per point; points behind the camera get a large
/// penalty so the search stays where the scene is visible.
fn residuals(params: &[f64], points: &[ControlPoint], out: &mut Vec<f64>) {
    let camera = from_params(params);
    out.clear();
    for p in points {
        match camera.project(&p.world) {
            Some([u, v]) => out.extend([p.pixel[0] - u, p.pixel[1] - v]),
            None => out.extend([1e6, 1e6]),
        }
    }
}

/// Levenberg–Marquardt (Marquardt's diagonal scaling) with central-difference Jacobians.
fn refine(points: &[ControlPoint], start: &Camera, model: Model) -> (Camera, usize) {
    let mut params = to_params(start, model.distortion);
    // Parameters the search moves: all but the skew (index 2) when it is held at zero.
    if model.zero_skew {
        params[2] = 0.0;
    }
    let free: Vec<usize> = (0..params.len()).filter(|&j| !(model.zero_skew && j == 2)).collect();
    let m = free.len();
    let rows = 2 * points.len();
    let mut r = Vec::with_capacity(rows);
    residuals(&params, points, &mut r);
    let mut cost: f64 = r.iter().map(|x| x * x).sum();
    let scale_of = |j: usize, value: f64| {
        let typical = match j {
            0..=4 => 1.0,
            5..=7 => 1e-3,
            8..=10 => 1.0,
            _ => 1e-3,
        };
        1e-6 * value.abs().max(typical)
    };
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let (mut plus, mut minus) = (Vec::with_capacity(rows), Vec::with_capacity(rows));
    let mut jac = vec![0.0; rows * m];
    for iteration in 1..=200 {
        iterations = iteration;
        for (column, &j) in free.iter().enumerate() {
            let h = scale_of(j, params[j]);
            let mut p = params.clone();
            p[j] = params[j] + h;
            residuals(&p, points, &mut plus);
            p[j] = params[j] - h;
            residuals(&p, points, &mut minus);
            for i in 0..rows {
                jac[i * m + column] = (plus[i] - minus[i]) / (2.0 * h);
            }
        }
        // Normal equations of r(θ + δ) ≈ r + J δ.
        let mut jtj = vec![0.0; m * m];
        let mut jtr = vec![0.0; m];
        for i in 0..rows {
            let row = &jac[i * m..(i + 1) * m];
            for a in 0..m {
                jtr[a] += row[a] * r[i];
                for b in 0..m {
                    jtj[a * m + b] += row[a] * row[b];
                }
            }
        }
        let mut improved = false;
        while lambda < 1e16 {
            let mut damped = jtj.clone();
            for a in 0..m {
                damped[a * m + a] += lambda * jtj[a * m + a].max(1e-30);
            }
            let rhs: Vec<f64> = jtr.iter().map(|v| -v).collect();
            let Some(delta) = linalg::solve(&damped, &rhs, m) else {
                lambda *= 10.0;
                continue;
            };
            let mut trial = params.clone();
            for (column, &j) in free.iter().enumerate() {
                trial[j] += delta[column];
            }
            residuals(&trial, points, &mut plus);
            let trial_cost: f64 = plus.iter().map(|x| x * x).sum();
            if trial_cost < cost {
                let relative = (cost - trial_cost) / cost.max(1e-300);
                params = trial;
                std::mem::swap(&mut r, &mut plus);
                cost = trial_cost;
                lambda = (lambda / 10.0).max(1e-12);
                improved = relative > 1e-15;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    (from_params(&params), iterations)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::signal::synthetic_motion::SplitMix64;

    pub fn test_camera(k1: f64) -> Camera {
        let k = Intrinsics { fx: 1400.0, fy: 1400.0, skew: 0.0, cx: 962.0, cy: 538.0 };
        Camera::look_at(k, [600.0, -3800.0, 2200.0], [0.0, 400.0, 600.0], k1, 0.0)
    }

    /// Points on the floor (Z = 0) and a back wall (Y = 1500) and a post, all in view.
    pub fn scene_points(camera: &Camera, n: usize, sigma: f64, seed: u64) -> Vec<ControlPoint> {
        let mut rng = SplitMix64::new(seed);
        let mut out = Vec::new();
        while out.len() < n {
            let world = match out.len() % 3 {
                0 => [rng.uniform(-1500.0, 1500.0), rng.uniform(-800.0, 1400.0), 0.0],
                1 => [rng.uniform(-1500.0, 1500.0), 1500.0, rng.uniform(100.0, 1800.0)],
                _ => [rng.uniform(-1200.0, 1200.0), rng.uniform(-500.0, 1000.0), rng.uniform(300.0, 1500.0)],
            };
            let Some([u, v]) = camera.project(&world) else { continue };
            if !(20.0..1900.0).contains(&u) || !(20.0..1060.0).contains(&v) {
                continue;
            }
            out.push(ControlPoint { world, pixel: [u + sigma * rng.normal(), v + sigma * rng.normal()] });
        }
        out
    }

    #[test]
    fn noise_free_points_give_the_camera_back() {
        for (k1, distortion) in [(0.0, Distortion::None), (-0.08, Distortion::K1)] {
            let truth = test_camera(k1);
            let points = scene_points(&truth, 12, 0.0, 3);
            let cal = calibrate(&points, Model { distortion, zero_skew: false }, 3.5).unwrap();
            assert!(cal.rms_px < 1e-6, "rms {} ({distortion:?})", cal.rms_px);
            assert!((cal.camera.intrinsics.fx - 1400.0).abs() < 1e-4, "{:?}", cal.camera.intrinsics);
            assert!((cal.camera.k1 - k1).abs() < 1e-8);
            assert!(cal.outliers.iter().all(|o| !o));
        }
    }

    #[test]
    fn coplanar_and_too_few_points_are_refused() {
        let truth = test_camera(0.0);
        let mut points = scene_points(&truth, 12, 0.5, 4);
        assert_eq!(calibrate(&points[..7], Model::PINHOLE, 3.5).unwrap_err(), CalibrationError::TooFewPoints(7));
        for p in &mut points {
            p.world[2] = 0.0;
            p.pixel = truth.project(&p.world).unwrap();
        }
        let err = calibrate(&points, Model::PINHOLE, 3.5).unwrap_err();
        assert!(matches!(err, CalibrationError::Coplanar { .. }), "{err}");
        assert!(err.to_string().contains("coplanar"));
    }

    #[test]
    fn a_gross_outlier_is_flagged() {
        let truth = test_camera(0.0);
        let mut points = scene_points(&truth, 16, 0.5, 5);
        points[6].pixel[0] += 15.0;
        let cal = calibrate(&points, Model::PINHOLE, 3.5).unwrap();
        assert!(cal.outliers[6], "residuals {:?}", cal.residuals);
        assert_eq!(cal.outliers.iter().filter(|o| **o).count(), 1, "threshold {}", cal.outlier_threshold_px);
    }
}
