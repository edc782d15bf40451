//! The rolling unit's records a prediction is judged against: the camera's platform
//! displacement and yaw (~30 Hz, NaN dropouts) and the accelerometer's absolute X acceleration
//! (200 Hz), each placed on the floor's time base and divided by its sensor's noise.

use super::{RollingCase, Track};
use crate::diagnose::verdict::{clustered, first_cluster, span, Misfit, ACCEL_CLUSTER, CAMERA_CLUSTER};

#[derive(Debug, Clone, Copy)]
struct Sample {
    t: f64,
    /// Left floor-grid index and the right neighbour's weight.
    k: usize,
    w: f64,
    /// Observed values (x, y, yaw for the camera; a_x in slot 0 for the accelerometer).
    value: [f64; 3],
    valid: bool,
}

#[derive(Debug, Clone)]
pub struct Evidence {
    pub exceedance_sigma: f64,
    accel: Vec<Sample>,
    camera: Vec<Sample>,
    accel_sigma: f64,
    camera_sigma: [f64; 3],
}

fn at(series: &[f64], s: &Sample) -> f64 {
    let a = series[s.k];
    if s.w == 0.0 {
        a
    } else {
        a + s.w * (series[(s.k + 1).min(series.len() - 1)] - a)
    }
}

impl Evidence {
    pub fn new(case: &RollingCase, exceedance_sigma: f64) -> Evidence {
        let n = case.floor_ax_mps2.len();
        let end = case.t0_s + (n - 1) as f64 * case.dt_s;
        let place = |t: f64| {
            let x = ((t - case.t0_s) / case.dt_s).clamp(0.0, (n - 1) as f64);
            let k = (x.floor() as usize).min(n.saturating_sub(2));
            let w = x - k as f64;
            // Samples on the floor's grid (within rounding of the printed times) are read exactly.
            if w.abs() < 1e-6 {
                (k, 0.0)
            } else if (1.0 - w).abs() < 1e-6 {
                (k + 1, 0.0)
            } else {
                (k, w)
            }
        };
        let inside = |t: f64| t >= case.t0_s - 1e-9 && t <= end + 1e-9;
        let accel = case.accel.as_ref().map_or_else(Vec::new, |o| {
            o.time_s
                .iter()
                .zip(&o.value)
                .filter(|(t, _)| inside(**t))
                .map(|(&t, &v)| {
                    let (k, w) = place(t);
                    Sample { t, k, w, value: [v, 0.0, 0.0], valid: v.is_finite() }
                })
                .collect()
        });
        let camera = case.camera.as_ref().map_or_else(Vec::new, |c| {
            (0..c.time_s.len())
                .filter(|&i| inside(c.time_s[i]))
                .map(|i| {
                    let (k, w) = place(c.time_s[i]);
                    let value = [c.x_m[i], c.y_m[i], c.yaw_rad[i]];
                    Sample { t: c.time_s[i], k, w, value, valid: value.iter().all(|v| v.is_finite()) }
                })
                .collect()
        });
        Evidence {
            exceedance_sigma,
            accel,
            camera,
            accel_sigma: case.accel_noise_mps2,
            camera_sigma: [case.camera_noise_m, case.camera_noise_m, case.camera_noise_rad],
        }
    }

    /// Whether `p` predicts what the accelerometer read at `s` (see [`Track::accel_unseen`]).
    fn accel_seen(p: &Track, s: &Sample) -> bool {
        let unseen = |k: usize| p.accel_unseen.get(k).copied().unwrap_or(false);
        !(unseen(s.k) || (s.w > 0.0 && unseen(s.k + 1)))
    }

    fn accel_z(&self, p: &Track, s: &Sample) -> f64 {
        (s.value[0] - at(&p.ax_abs_mps2, s)) / self.accel_sigma
    }

    fn camera_z(&self, p: &Track, s: &Sample) -> [f64; 3] {
        let predicted = [at(&p.x_m, s), at(&p.y_m, s), at(&p.yaw_rad, s)];
        std::array::from_fn(|i| (s.value[i] - predicted[i]) / self.camera_sigma[i])
    }

    /// Every compared normalised residual with its time, in time order per sensor.
    fn residuals<'a>(&'a self, p: &'a Track, from: f64, until: f64) -> impl Iterator<Item = f64> + 'a {
        let keep = move |s: &&Sample| s.valid && s.t >= from && s.t <= until;
        // A sample the prediction cannot speak for counts as noise (z = 1, its expected square):
        // neither a penalty nor a gain against predictions that judge it.
        let accel =
            self.accel.iter().filter(keep).map(|s| if Self::accel_seen(p, s) { self.accel_z(p, s) } else { 1.0 });
        let camera = self.camera.iter().filter(keep).flat_map(|s| self.camera_z(p, s));
        accel.chain(camera)
    }

    /// The misfit over the records from `from` to `until` (s). A residual the prediction cannot
    /// give (NaN: a run that ended early or failed) counts as a large one.
    pub fn misfit_between(&self, p: &Track, from: f64, until: f64) -> Misfit {
        let mut m = Misfit { chi2: 0.0, samples: 0 };
        for z in self.residuals(p, from, until) {
            m.chi2 += if z.is_finite() { z * z } else { 1e12 };
            m.samples += 1;
        }
        m
    }

    pub fn misfit(&self, p: &Track) -> Misfit {
        self.misfit_between(p, f64::NEG_INFINITY, f64::INFINITY)
    }

    /// √(χ²/N) inside the window (the whole record without one): 1 is pure sensor noise.
    pub fn window_rmse(&self, p: &Track, window: Option<(f64, f64)>) -> f64 {
        let (a, b) = window.unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
        let m = self.misfit_between(p, a, b);
        (m.chi2 / m.samples.max(1) as f64).sqrt()
    }

    /// Times of samples whose residuals exceed the threshold in clusters (either sensor).
    fn flagged_times(&self, p: &Track) -> Vec<f64> {
        let mut flagged = Vec::new();
        let accel: Vec<f64> = self
            .accel
            .iter()
            .filter(|s| s.valid && Self::accel_seen(p, s) && !(self.accel_z(p, s).abs() <= self.exceedance_sigma))
            .map(|s| s.t)
            .collect();
        let camera: Vec<f64> = self
            .camera
            .iter()
            .filter(|s| s.valid && !self.camera_z(p, s).iter().all(|z| z.abs() <= self.exceedance_sigma))
            .map(|s| s.t)
            .collect();
        for (exceeding, needed) in [(accel, ACCEL_CLUSTER), (camera, CAMERA_CLUSTER)] {
            flagged.extend(clustered(&exceeding, needed));
        }
        flagged
    }

    pub fn flagged(&self, p: &Track) -> usize {
        self.flagged_times(p).len()
    }

    /// Flagged samples from `from` to `until` (s).
    pub fn flagged_between(&self, p: &Track, from: f64, until: f64) -> usize {
        self.flagged_times(p).into_iter().filter(|t| *t >= from && *t <= until).count()
    }

    /// From the first to the last flagged sample.
    pub fn window(&self, p: &Track) -> Option<(f64, f64)> {
        span(&self.flagged_times(p))
    }

    /// The first time two predictions differ as much as a disagreement with the records would
    /// be flagged (beyond the exceedance threshold at 2 camera samples or 5 accelerometer samples
    /// within 0.1 s), at the samples the records have: where the records could tell them apart.
    pub fn parting(&self, a: &Track, b: &Track) -> Option<f64> {
        let camera: Vec<f64> = self
            .camera
            .iter()
            .filter(|s| {
                let (za, zb) = (self.camera_z(a, s), self.camera_z(b, s));
                s.valid && !(0..3).all(|i| (za[i] - zb[i]).abs() <= self.exceedance_sigma)
            })
            .map(|s| s.t)
            .collect();
        let accel: Vec<f64> = self
            .accel
            .iter()
            .filter(|s| s.valid && !((self.accel_z(a, s) - self.accel_z(b, s)).abs() <= self.exceedance_sigma))
            .map(|s| s.t)
            .collect();
        match (first_cluster(&camera, CAMERA_CLUSTER), first_cluster(&accel, ACCEL_CLUSTER)) {
            (Some(x), Some(y)) => Some(x.min(y)),
            (x, y) => x.or(y),
        }
    }

    /// The largest residual inside `window` per sensor, by the contract's key: the camera's
    /// position (m) and yaw (rad), the accelerometer (m/s^2).
    pub fn largest(&self, p: &Track, window: (f64, f64)) -> [(&'static str, f64); 3] {
        let inside = |s: &&Sample| s.valid && s.t >= window.0 && s.t <= window.1;
        let mut position: f64 = 0.0;
        let mut yaw: f64 = 0.0;
        for s in self.camera.iter().filter(inside) {
            let z = self.camera_z(p, s);
            position = position.max((z[0] * self.camera_sigma[0]).hypot(z[1] * self.camera_sigma[1]));
            yaw = yaw.max((z[2] * self.camera_sigma[2]).abs());
        }
        let accel = self
            .accel
            .iter()
            .filter(inside)
            .filter(|s| Self::accel_seen(p, s))
            .map(|s| (self.accel_z(p, s) * self.accel_sigma).abs())
            .fold(0.0, f64::max);
        [("camera_m", position), ("camera_rad", yaw), ("accel_mps2", accel)]
    }

    /// "the camera by up to 0.41 m and 0.12 rad and the accelerometer by up to 1.3 m/s^2".
    pub fn describe_disagreement(&self, p: &Track, window: (f64, f64)) -> String {
        let [(_, position), (_, yaw), (_, accel)] = self.largest(p, window);
        format!("the camera by up to {position:.3} m and {yaw:.3} rad and the accelerometer by up to {accel:.2} m/s^2")
    }

    /// (time, observed, predicted, residual) of the accelerometer; NaN where not compared.
    pub fn accel_series(&self, p: &Track) -> Vec<(f64, f64, f64, f64)> {
        self.accel
            .iter()
            .map(|s| {
                let predicted = at(&p.ax_abs_mps2, s);
                let residual = if s.valid && Self::accel_seen(p, s) { s.value[0] - predicted } else { f64::NAN };
                (s.t, s.value[0], predicted, residual)
            })
            .collect()
    }

    /// Per camera sample: time, observed (x, y, yaw), predicted (x, y, yaw).
    pub fn camera_series(&self, p: &Track) -> Vec<(f64, [f64; 3], [f64; 3])> {
        self.camera.iter().map(|s| (s.t, s.value, [at(&p.x_m, s), at(&p.y_m, s), at(&p.yaw_rad, s)])).collect()
    }
}
