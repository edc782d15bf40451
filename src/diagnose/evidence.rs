//! The observations a prediction is judged against: each sensor's samples placed on the floor's
//! time base, weighed by the sensor's noise, with what no model here predicts masked out.

use super::verdict::{clustered, span, Misfit, ACCEL_CLUSTER, CAMERA_CLUSTER};
use super::{Case, Prediction};
use crate::signal::toppling::{detect_toppling, DetectOptions};

/// The overturn impact rings for tens of ms; no rigid model predicts it.
const SPIKE_MASK_S: (f64, f64) = (0.05, 0.3);
/// A sample is solver-sensitive when the nominal model's prediction moves by more than this
/// under other solver settings (micro-rocking chatter ends at slightly different times).
const SENSITIVE_ACCEL_MPS2: f64 = 0.1;
const SENSITIVE_THETA_RAD: f64 = 0.005;

/// A twin run's spread up to this is a linear one (±, symmetric about the prediction); beyond
/// it the twin has taken another branch (an impact more or less, an overturn or not), and the
/// truth may lie anywhere between the two runs but not beyond both.
const LINEAR_SPREAD_RAD: f64 = 0.05;
const LINEAR_SPREAD_MPS2: f64 = 1.0;

/// What a prediction admits at one sample besides the sensor noise.
struct Spread {
    /// The twin run's value, when there is one.
    twin: Option<f64>,
    /// Other uncertainty (standard deviation): micro-rocking, an overturn's timing.
    other: f64,
    /// The largest spread still taken as linear.
    linear: f64,
}

impl Spread {
    /// (observed − predicted)/sd and ln(sd/σ), sd combining the noise σ and the uncertainty. A
    /// spread beyond the linear one measures the residual from the nearer of the two runs (zero
    /// between them); its price ln(sd/σ) stays that of the whole spread, so no model buys fit
    /// by being chaotic.
    fn z(&self, observed: f64, predicted: f64, sigma: f64) -> (f64, f64) {
        let spread = self.twin.map_or(0.0, |twin| (twin - predicted).abs());
        let sd = sigma.hypot(self.other.max(spread));
        let log_ratio = (sd / sigma).ln();
        match self.twin {
            Some(twin) if spread > self.linear && spread > self.other => {
                let (lo, hi) = (predicted.min(twin), predicted.max(twin));
                let outside = observed - observed.clamp(lo, hi);
                (outside / sigma.hypot(self.other.max(self.linear)), log_ratio)
            }
            _ => ((observed - predicted) / sd, log_ratio),
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Sample {
    t: f64,
    /// Position on the floor grid: left index and weight of the right neighbour.
    k: usize,
    w: f64,
    value: f64,
    /// False when missing (NaN), masked as a spike, or solver-sensitive.
    valid: bool,
}

#[derive(Debug, Clone)]
pub struct Evidence {
    pub exceedance_sigma: f64,
    accel: Vec<Sample>,
    camera: Vec<Sample>,
    accel_sigma: f64,
    camera_sigma: f64,
    /// Time spans masked for the overturn impact (observed, and predicted by the nominal model).
    pub spike_masks: Vec<(f64, f64)>,
    pub sensitive_samples: usize,
    /// Whether the records show the unit fall: the camera seeing it lie (beyond 90 % of its
    /// lying angle), or without a camera, the accelerometer's toppling impact (a hard impact of
    /// a unit that stays standing can look alike; the camera settles it).
    pub observed_overturn: bool,
}

impl Evidence {
    pub fn new(case: &Case, baseline: &Prediction, variant: &Prediction, exceedance_sigma: f64) -> Evidence {
        let n = case.floor_ax_mps2.len();
        let place = |t: f64| {
            let x = ((t - case.t0_s) / case.dt_s).clamp(0.0, (n - 1) as f64);
            let k = (x.floor() as usize).min(n.saturating_sub(2));
            (k, x - k as f64)
        };
        let samples = |observed: &Option<super::Observed>| -> Vec<Sample> {
            observed.as_ref().map_or_else(Vec::new, |o| {
                o.time_s
                    .iter()
                    .zip(&o.value)
                    .filter(|(t, _)| **t >= case.t0_s && **t <= case.t0_s + case.duration_s() + 1e-9)
                    .map(|(&t, &value)| {
                        let (k, w) = place(t);
                        Sample { t, k, w, value, valid: value.is_finite() }
                    })
                    .collect()
            })
        };
        let mut accel = samples(&case.accel);
        let mut camera = samples(&case.camera);
        let mut spike_masks = Vec::new();
        let lying = 0.9 * case.block.lie_angle_rad;
        let camera_sees = camera.iter().any(|s| s.valid);
        let mut observed_overturn = camera.iter().any(|s| s.valid && s.value.abs() > lying);
        if let Some(observed) = &case.accel {
            let times: Vec<f64> = accel.iter().map(|s| s.t).collect();
            let values: Vec<f64> = accel.iter().map(|s| if s.value.is_finite() { s.value } else { 0.0 }).collect();
            if times.len() > 2 && observed.time_s.len() == times.len() {
                let event = detect_toppling(&times, &values, None, &DetectOptions::default());
                if let Some(t) = event.impact_time_s {
                    observed_overturn |= !camera_sees;
                    spike_masks.push((t - SPIKE_MASK_S.0, t + SPIKE_MASK_S.1));
                }
            }
        }
        if let Some((t, _)) = baseline.overturn {
            // The same impact seen twice (observed and predicted) is masked once.
            if !spike_masks.iter().any(|(a, b)| t >= *a && t <= *b) {
                spike_masks.push((t - SPIKE_MASK_S.0, t + SPIKE_MASK_S.1));
            }
        }
        let mut sensitive_samples = 0;
        for s in &mut accel {
            let masked = spike_masks.iter().any(|(a, b)| s.t >= *a && s.t <= *b);
            let sensitive = (at(&baseline.top_ax_mps2, s) - at(&variant.top_ax_mps2, s)).abs() > SENSITIVE_ACCEL_MPS2;
            sensitive_samples += usize::from(sensitive && s.valid && !masked);
            s.valid &= !masked && !sensitive;
        }
        for s in &mut camera {
            let sensitive = (at(&baseline.theta_rad, s) - at(&variant.theta_rad, s)).abs() > SENSITIVE_THETA_RAD;
            sensitive_samples += usize::from(sensitive && s.valid);
            s.valid &= !sensitive;
        }
        Evidence {
            exceedance_sigma,
            accel,
            camera,
            accel_sigma: case.accel_noise_mps2,
            camera_sigma: case.camera_noise_rad,
            spike_masks,
            sensitive_samples,
            observed_overturn,
        }
    }

    /// The accelerometer's residual at a sample, normalised, and ln(sd/σ).
    fn accel_z(&self, p: &Prediction, s: &Sample) -> (f64, f64) {
        let twin = (!p.twin_top_ax_mps2.is_empty()).then(|| at(&p.twin_top_ax_mps2, s));
        let spread = Spread { twin, other: at(&p.top_ax_uncertainty_mps2, s), linear: LINEAR_SPREAD_MPS2 };
        spread.z(s.value, at(&p.top_ax_mps2, s), self.accel_sigma)
    }

    fn camera_z(&self, p: &Prediction, s: &Sample) -> (f64, f64) {
        let twin = (!p.twin_theta_rad.is_empty()).then(|| at(&p.twin_theta_rad, s));
        let spread = Spread { twin, other: at(&p.theta_uncertainty_rad, s), linear: LINEAR_SPREAD_RAD };
        spread.z(s.value, at(&p.theta_rad, s), self.camera_sigma)
    }

    /// Normalised residuals of the valid samples at times `inside` admits, as (time, z,
    /// ln(sd/σ)): a sample outside is never compared, so a prediction need not reach it.
    fn normalised<'a>(
        &'a self,
        p: &'a Prediction,
        inside: impl Fn(f64) -> bool + Copy + 'a,
    ) -> impl Iterator<Item = (f64, f64, f64)> + 'a {
        let accel = self.accel.iter().filter(move |s| s.valid && inside(s.t)).map(move |s| {
            let (z, log_ratio) = self.accel_z(p, s);
            (s.t, z, log_ratio)
        });
        let camera = self.camera.iter().filter(move |s| s.valid && inside(s.t)).map(move |s| {
            let (z, log_ratio) = self.camera_z(p, s);
            (s.t, z, log_ratio)
        });
        accel.chain(camera)
    }

    pub fn misfit(&self, p: &Prediction) -> Misfit {
        self.misfit_until(p, f64::INFINITY)
    }

    /// −2 log-likelihood (up to a constant) of the samples up to `t_end`: Σ z² plus, where the
    /// prediction admits its own uncertainty, the price of it (2 ln(sd/σ)).
    pub fn misfit_until(&self, p: &Prediction, t_end: f64) -> Misfit {
        self.misfit_between(p, f64::NEG_INFINITY, t_end)
    }

    /// The misfit ([`Evidence::misfit_until`]) of the samples from `from` to `until` (s).
    pub fn misfit_between(&self, p: &Prediction, from: f64, until: f64) -> Misfit {
        let (mut chi2, mut samples) = (0.0, 0);
        for (_, z, log_ratio) in self.normalised(p, move |t| t >= from && t <= until) {
            chi2 += z * z + 2.0 * log_ratio;
            samples += 1;
        }
        Misfit { chi2, samples }
    }

    /// Noise-normalised RMS residual inside `window` (everywhere when None); 1 is pure noise.
    pub fn window_rmse(&self, p: &Prediction, window: Option<(f64, f64)>) -> f64 {
        let inside = move |t: f64| window.is_none_or(|(a, b)| t >= a && t <= b);
        let (sum, count) = self.normalised(p, inside).fold((0.0, 0usize), |(s, c), (_, z, _)| (s + z * z, c + 1));
        if count == 0 {
            return 0.0;
        }
        (sum / count as f64).sqrt()
    }

    /// Times of the samples whose residuals exceed the threshold in clusters (both sensors).
    fn flagged_times(&self, p: &Prediction) -> Vec<f64> {
        let mut flagged = Vec::new();
        let accel_z = |s: &Sample| self.accel_z(p, s).0;
        let camera_z = |s: &Sample| self.camera_z(p, s).0;
        // Per sensor: its samples, their residual, the exceedances a cluster needs.
        type Residual<'a> = &'a dyn Fn(&Sample) -> f64;
        let sensors: [(&[Sample], Residual<'_>, usize); 2] =
            [(&self.accel, &accel_z, ACCEL_CLUSTER), (&self.camera, &camera_z, CAMERA_CLUSTER)];
        for (samples, z, needed) in sensors {
            let exceeding: Vec<f64> =
                samples.iter().filter(|s| s.valid && z(s).abs() > self.exceedance_sigma).map(|s| s.t).collect();
            flagged.extend(clustered(&exceeding, needed));
        }
        flagged
    }

    /// How many samples the prediction's residuals flag.
    pub fn flagged(&self, p: &Prediction) -> usize {
        self.flagged_times(p).len()
    }

    /// From the first to the last flagged sample: where the prediction disagrees with the records.
    pub fn window(&self, p: &Prediction) -> Option<(f64, f64)> {
        span(&self.flagged_times(p))
    }

    /// The largest residual inside `window` per sensor, by the contract's key (a sensor without
    /// a valid sample there is left out).
    pub fn largest(&self, p: &Prediction, window: (f64, f64)) -> Vec<(&'static str, f64)> {
        let worst = |samples: &[Sample], series: &[f64]| {
            samples
                .iter()
                .filter(|s| s.valid && s.t >= window.0 && s.t <= window.1)
                .map(|s| (s.value - at(series, s)).abs())
                .fold(None, |m: Option<f64>, v| Some(m.map_or(v, |m| m.max(v))))
        };
        [("accel_mps2", worst(&self.accel, &p.top_ax_mps2)), ("camera_rad", worst(&self.camera, &p.theta_rad))]
            .into_iter()
            .filter_map(|(key, v)| Some((key, v?)))
            .collect()
    }

    /// "the accelerometer by up to 3.2 m/s^2 and the camera by up to 0.12 rad".
    pub fn describe_disagreement(&self, p: &Prediction, window: (f64, f64)) -> String {
        let parts: Vec<String> = self
            .largest(p, window)
            .into_iter()
            .map(|(key, v)| match key {
                "accel_mps2" => format!("the top accelerometer by up to {v:.2} m/s^2"),
                _ => format!("the camera rotation by up to {v:.3} rad"),
            })
            .collect();
        if parts.is_empty() {
            "though no valid sample falls inside it".into()
        } else {
            format!("departing from {}", parts.join(" and "))
        }
    }

    /// What was left out of the comparison, for the explanation.
    pub fn mask_note(&self) -> String {
        let mut notes = Vec::new();
        for (a, b) in &self.spike_masks {
            notes.push(format!(
                "the overturn impact spike at {:.2} s ({:.2} s of accelerometer record)",
                a + SPIKE_MASK_S.0,
                b - a
            ));
        }
        if self.sensitive_samples > 0 {
            notes.push(format!(
                "{} samples where the nominal model itself depends on solver settings (impact chatter)",
                self.sensitive_samples
            ));
        }
        if notes.is_empty() {
            String::new()
        } else {
            format!(" Not compared: {}.", notes.join("; "))
        }
    }

    /// Per observed sample: time, observed, predicted, residual (NaN where not compared).
    pub fn accel_series(&self, p: &Prediction) -> Vec<(f64, f64, f64, f64)> {
        series(&self.accel, &p.top_ax_mps2)
    }

    pub fn camera_series(&self, p: &Prediction) -> Vec<(f64, f64, f64, f64)> {
        series(&self.camera, &p.theta_rad)
    }
}

fn series(samples: &[Sample], predicted: &[f64]) -> Vec<(f64, f64, f64, f64)> {
    samples
        .iter()
        .map(|s| {
            let p = at(predicted, s);
            (s.t, s.value, p, if s.valid { s.value - p } else { f64::NAN })
        })
        .collect()
}

/// A floor-grid series at a sample's position (linear between grid points).
fn at(series: &[f64], s: &Sample) -> f64 {
    match series.get(s.k + 1) {
        Some(next) => series[s.k] * (1.0 - s.w) + next * s.w,
        None => series[s.k],
    }
}
