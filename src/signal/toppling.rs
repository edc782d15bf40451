//! Toppling detection from an equipment-top accelerometer (horizontal, E-W).
//!
//! When a unit topples, its top hits the floor: the top accelerometer shows a spike far above
//! the preceding shaking, and afterwards (the unit now lies on its side, the sensitive axis is
//! vertical) it records the floor's *vertical* motion, roughly 1/10 of the horizontal amplitude,
//! often on top of a ±g offset (gravity now projects onto the axis). Ordinary strong shaking and
//! rocking impacts also produce spikes, but they are not followed by a lasting drop.
//!
//! Method (`detect_toppling`):
//! 1. Clean-up: non-finite samples are ignored everywhere (NaN gaps); no global filtering. All
//!    RMS values are computed per window after removing a least-squares line, so DC offsets,
//!    slow drift and the ±g step after toppling do not count as motion; pre- and post-impact
//!    windows have the same length so the line removes the same low-frequency content. A running median (1 s)
//!    gives a detrended copy used only for the record's peak.
//! 2. Candidates: a classic STA/LTA trigger (ObsPy `classic_sta_lta`, here with a *preceding*,
//!    non-overlapping LTA window) on the squared lag difference d(t) = a(t) − a(t − 5 ms), a
//!    high-pass that emphasises the impact's sudden change. Each run of sqrt(STA/LTA) ≥
//!    `sta_lta_on` is one trigger, located at the steepest step |d| in the run.
//!    Triggers whose spike (peak |a − local median level| within 60 ms) is below
//!    `min_peak_fraction` of the record's largest detrended peak are dropped ("among the largest
//!    peaks of the record"); triggers closer than `skip_s` are merged (largest spike kept).
//! 3. Impact time: the middle of the first step of the spike's leading edge that reaches 75 % of
//!    the spike's steepest step (sign-agnostic, at most 60 ms before it). For a step-like
//!    impact (a jump between two samples) the true impact lies in that interval, so the midpoint
//!    is within dt/2; for a smooth pulse (e.g. an alpha pulse t·e^(1−t/τ), steepest at its start)
//!    it is within a few ms of the start (the 75 % rule keeps shaking superposed on the falling
//!    edge from winning). The peak itself comes 10-20 ms later for smooth pulses,
//!    which is why the peak is not used.
//! 4. Confirmation: pre-impact RMS over `pre_window_s` ending `pre_gap_s` before the impact;
//!    post-impact RMS over `post_window_s` starting `skip_s` after it (skipping the impact
//!    ringing); both are RMS about a least-squares line over their window. Toppled iff
//!    sqrt(STA/LTA) ≥ `sta_lta_on`, spike/pre-RMS ≥ `spike_ratio`, post/pre ≤ `drop_ratio`, and the drop
//!    persists (every `block_s` block stays ≤ `drop_ratio` × pre-RMS) for `min_drop_s`, or to the
//!    end of the record if that leaves at least `min_tail_s`.
//! 5. Confidence: each piece of evidence is mapped to 0..1 on a log scale, 0.5 at its threshold
//!    and 1 at a "clear" level (spike and STA/LTA 4× their thresholds, post/pre RMS 0.1, persistence 2.5× `min_drop_s`).
//!    Toppled: geometric mean of spike, drop and persistence scores, raised (up to +60 % of the
//!    remaining gap) when the post-impact RMS matches the floor vertical RMS over the same window
//!    (within `floor_agreement_factor`). Not toppled: 1 − (best candidate's weakest score), so
//!    ≥ 0.5; 0.98 with no candidate at all. A spike with less than `min_tail_s` of record after
//!    the skip cannot be confirmed: toppled = false, confidence 0.5 ("undecided"), and the
//!    candidate is named in the explanation.
//!
//! Not implemented: a log-variance change point to refine the onset (the leading-edge rule is
//! already at sample precision on the test data), and use of the floor record's clock (the floor
//! vertical must already be resampled onto `time_s`).
//!
//! Time samples must be nondecreasing; non-finite times are treated as missing samples.
//! Sample rates of 100-1000 Hz are handled (all windows are in seconds).

use super::running_median::{median, running_median};

/// Options of [`detect_toppling`]. All times in seconds.
#[derive(Clone, Debug, PartialEq)]
pub struct DetectOptions {
    /// Lag of the difference a(t) − a(t − lag) used as the STA/LTA characteristic function
    /// (at least one sample). Default 0.005 s: one sample at 200-256 Hz, five at 1 kHz.
    pub diff_lag_s: f64,
    /// Short-term average window. Default 0.02 s (a few samples: an impact lasts 10-50 ms).
    pub sta_s: f64,
    /// Long-term average window, immediately preceding the STA window. Default 5 s.
    pub lta_s: f64,
    /// Trigger threshold on sqrt(STA/LTA) (amplitude ratio). Default 8. In the test data,
    /// impact-free shaking (including strong-motion onsets of FB-1..FB-6) stays ≤ 6.8, toppling
    /// impacts reach 15 (6 g impact inside 1.5 g-RMS shaking) to 500 (demo cases).
    pub sta_lta_on: f64,
    /// Minimum spike amplitude (peak |a − local level|) over the pre-impact RMS. Default 2:
    /// inside the strongest shaking a 6 g impact is only 2.6× the preceding RMS (archive FB-5
    /// PS2), so amplitude alone does not separate impacts from shaking peaks (shaking onsets
    /// reach 6×); impulsiveness (STA/LTA) and the drop do.
    pub spike_ratio: f64,
    /// A candidate's spike must be at least this fraction of the record's largest detrended
    /// peak. Default 0.3.
    pub min_peak_fraction: f64,
    /// At most this many candidates (largest spikes first) are examined. Default 10.
    pub max_candidates: usize,
    /// Gap between the pre-impact window and the impact. Default 0.05 s.
    pub pre_gap_s: f64,
    /// Pre-impact RMS window. Default 2 s (several cycles of a 1-5 Hz equipment response).
    pub pre_window_s: f64,
    /// Skipped after the impact (ringing, bounce). Also the merge distance of triggers.
    /// Default 0.4 s.
    pub skip_s: f64,
    /// Post-impact RMS window (after the skip). Default 2 s.
    pub post_window_s: f64,
    /// Block length of the persistence check. Default 1 s.
    pub block_s: f64,
    /// Post/pre RMS ratio at or below which the amplitude counts as dropped. Default 0.35
    /// (toppling gives ~0.1 since vertical floor motion is ~1/10 of horizontal).
    pub drop_ratio: f64,
    /// Minimum duration of the drop (from `skip_s` after the impact). Default 2 s.
    pub min_drop_s: f64,
    /// If the record ends during the drop, at least this much post-skip record is needed to
    /// confirm. Default 1 s.
    pub min_tail_s: f64,
    /// Post-impact RMS and floor vertical RMS "agree" when their ratio is within this factor.
    /// Default 3.
    pub floor_agreement_factor: f64,
}

impl Default for DetectOptions {
    fn default() -> Self {
        Self {
            diff_lag_s: 0.005,
            sta_s: 0.02,
            lta_s: 5.0,
            sta_lta_on: 8.0,
            spike_ratio: 2.0,
            min_peak_fraction: 0.3,
            max_candidates: 10,
            pre_gap_s: 0.05,
            pre_window_s: 2.0,
            skip_s: 0.4,
            post_window_s: 2.0,
            block_s: 1.0,
            drop_ratio: 0.35,
            min_drop_s: 2.0,
            min_tail_s: 1.0,
            floor_agreement_factor: 3.0,
        }
    }
}

/// Result of [`detect_toppling`].
#[derive(Clone, Debug, PartialEq)]
pub struct TopplingEvent {
    pub toppled: bool,
    /// Impact time (same clock as `time_s`); `None` unless toppled.
    pub impact_time_s: Option<f64>,
    /// Toppled: the impact spike's amplitude above the local pre-impact level. Otherwise: the
    /// record's largest |a − running median (1 s)|.
    pub peak_mps2: f64,
    /// Toppled: confidence that it toppled; otherwise confidence that it did not (0..1).
    pub confidence: f64,
    /// RMS (line removed) before the impact of the reported/most toppling-like candidate; with no
    /// candidate, the whole record's detrended RMS (then equal to `post_rms_mps2`).
    pub pre_rms_mps2: f64,
    /// RMS (line removed per block) after the impact (after the skip); see `pre_rms_mps2`.
    pub post_rms_mps2: f64,
    pub explanation: String,
}

/// Why a time column cannot carry an analysis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum TimeBaseError {
    #[error("time is not nondecreasing or has fewer than two finite values")]
    NotNondecreasing,
    #[error("no positive time step")]
    NoPositiveStep,
}

/// A record's time column prepared once for all of its channels: gaps filled, median step.
pub struct TimeBase<'a> {
    time_s: &'a [f64],
    filled: Vec<f64>,
    dt: f64,
}

impl<'a> TimeBase<'a> {
    /// Err: why no channel on this time column can be analysed.
    pub fn new(time_s: &'a [f64]) -> Result<TimeBase<'a>, TimeBaseError> {
        let filled = fill_time(time_s).ok_or(TimeBaseError::NotNondecreasing)?;
        let dt = median_step(&filled).ok_or(TimeBaseError::NoPositiveStep)?;
        Ok(TimeBase { time_s, filled, dt })
    }
}

fn length_mismatch(time_s: &[f64], top_ax_mps2: &[f64]) -> Option<TopplingEvent> {
    (time_s.len() != top_ax_mps2.len())
        .then(|| not_analysed(format!("time has {} samples, acceleration {}", time_s.len(), top_ax_mps2.len())))
}

fn not_analysed(why: String) -> TopplingEvent {
    TopplingEvent {
        toppled: false,
        impact_time_s: None,
        peak_mps2: 0.0,
        confidence: 0.0,
        pre_rms_mps2: 0.0,
        post_rms_mps2: 0.0,
        explanation: format!("not analysed: {why}"),
    }
}

/// Detects a toppling impact in an equipment-top horizontal acceleration record (m/s²).
///
/// `floor_vertical_mps2`, if given, must be sampled at `time_s` (same length); it is only used
/// to compare the post-impact level with the floor's vertical motion (confidence).
pub fn detect_toppling(
    time_s: &[f64],
    top_ax_mps2: &[f64],
    floor_vertical_mps2: Option<&[f64]>,
    opts: &DetectOptions,
) -> TopplingEvent {
    // Lengths before the time column: a record wrong in both reports its lengths.
    if let Some(mismatch) = length_mismatch(time_s, top_ax_mps2) {
        return mismatch;
    }
    match TimeBase::new(time_s) {
        Ok(base) => detect_toppling_on(&base, top_ax_mps2, floor_vertical_mps2, opts),
        Err(why) => not_analysed(why.to_string()),
    }
}

/// [`detect_toppling`] on a time column shared by several channels of one record, prepared once.
pub fn detect_toppling_on(
    base: &TimeBase<'_>,
    top_ax_mps2: &[f64],
    floor_vertical_mps2: Option<&[f64]>,
    opts: &DetectOptions,
) -> TopplingEvent {
    let (time_s, t, dt) = (base.time_s, &base.filled, base.dt);
    if let Some(mismatch) = length_mismatch(time_s, top_ax_mps2) {
        return mismatch;
    }
    let x: Vec<f64> = top_ax_mps2
        .iter()
        .zip(time_s)
        .map(|(&v, &ts)| if v.is_finite() && ts.is_finite() { v } else { f64::NAN })
        .collect();
    let n = x.len();
    let record = Record { t, x: &x, dt };
    let n_valid = x.iter().filter(|v| v.is_finite()).count();
    if (n_valid as f64) * dt < 1.0 || n_valid < 16 {
        return not_analysed(format!("only {n_valid} valid samples"));
    }

    // Detrended copy for the record's peak and RMS.
    let base = running_median(&x, (1.0 / dt).round().max(3.0) as usize, (0.05 / dt).round().max(1.0) as usize);
    let (mut record_peak, mut ss, mut cnt) = (0.0_f64, 0.0, 0usize);
    for (v, b) in x.iter().zip(&base) {
        let r = v - b;
        if r.is_finite() {
            record_peak = record_peak.max(r.abs());
            ss += r * r;
            cnt += 1;
        }
    }
    let record_rms = if cnt > 0 { (ss / cnt as f64).sqrt() } else { 0.0 };

    // STA/LTA on the lag difference.
    let lag = ((opts.diff_lag_s / dt).round() as usize).max(1);
    let d: Vec<f64> = (0..n).map(|i| if i >= lag { x[i] - x[i - lag] } else { f64::NAN }).collect();
    let ratio = sta_lta(&d, dt, opts);

    // Trigger runs -> candidate impacts.
    let n_sta = ((opts.sta_s / dt).round() as usize).max(1);
    let mut cands: Vec<Candidate> = Vec::new();
    let mut i = 0;
    while i < n {
        if ratio[i] >= opts.sta_lta_on {
            let start = i;
            let mut best_ratio = ratio[i];
            while i + 1 < n && ratio[i + 1] >= opts.sta_lta_on {
                i += 1;
                best_ratio = best_ratio.max(ratio[i]);
            }
            let end = i;
            let mut j_best = None;
            let mut d_best = 0.0;
            for (j, dj) in d.iter().enumerate().take(end + 1).skip(start.saturating_sub(n_sta)) {
                if dj.is_finite() && dj.abs() > d_best {
                    d_best = dj.abs();
                    j_best = Some(j);
                }
            }
            if let Some(j) = j_best {
                if let Some(c) = make_candidate(&record, &d, j, lag, best_ratio, opts) {
                    cands.push(c);
                }
            }
        }
        i += 1;
    }
    let n_triggers = cands.len();
    cands.retain(|c| c.peak_amp >= opts.min_peak_fraction * record_peak);
    // Merge triggers closer than skip_s (keep the largest spike).
    cands.sort_by(|a, b| a.t_imp.total_cmp(&b.t_imp));
    let mut merged: Vec<Candidate> = Vec::new();
    let mut first_t = f64::NEG_INFINITY;
    for c in cands {
        match merged.last_mut() {
            Some(last) if c.t_imp - first_t <= opts.skip_s => {
                if c.peak_amp > last.peak_amp {
                    *last = c;
                }
            }
            _ => {
                first_t = c.t_imp;
                merged.push(c);
            }
        }
    }
    merged.sort_by(|a, b| b.peak_amp.total_cmp(&a.peak_amp));
    merged.truncate(opts.max_candidates);

    let t_end = last_valid_time(t, &x);
    let evals: Vec<Evaluation> =
        merged.iter().map(|c| evaluate(&record, floor_vertical_mps2, c, t_end, opts)).collect();

    // Confirmed: highest confidence, then earliest.
    let best_confirmed = evals
        .iter()
        .filter(|e| e.confirmed)
        .max_by(|a, b| a.confidence.total_cmp(&b.confidence).then(b.cand.t_imp.total_cmp(&a.cand.t_imp)));
    if let Some(e) = best_confirmed {
        return TopplingEvent {
            toppled: true,
            impact_time_s: Some(e.cand.t_imp),
            peak_mps2: e.cand.peak_amp,
            confidence: e.confidence,
            pre_rms_mps2: e.cand.pre_rms,
            post_rms_mps2: e.post_rms,
            explanation: format!("toppled: {}", e.text),
        };
    }
    let most_like = evals.iter().max_by(|a, b| a.weakest.total_cmp(&b.weakest));
    match most_like {
        None => TopplingEvent {
            toppled: false,
            impact_time_s: None,
            peak_mps2: record_peak,
            confidence: 0.98,
            pre_rms_mps2: record_rms,
            post_rms_mps2: record_rms,
            explanation: format!(
                "no toppling: {n_triggers} STA/LTA trigger(s) ≥ {:.1}, none with a spike ≥ {:.0} % of the record peak {:.2} m/s²",
                opts.sta_lta_on,
                100.0 * opts.min_peak_fraction,
                record_peak
            ),
        },
        Some(e) => TopplingEvent {
            toppled: false,
            impact_time_s: None,
            peak_mps2: record_peak,
            confidence: (1.0 - e.weakest).clamp(0.0, 1.0),
            pre_rms_mps2: e.cand.pre_rms,
            post_rms_mps2: e.post_rms,
            explanation: format!(
                "no toppling: {} candidate spike(s); most toppling-like: {}",
                evals.len(),
                e.text
            ),
        },
    }
}

/// A step of the leading edge counts if it reaches this fraction of the steepest step.
const EDGE_FRACTION: f64 = 0.75;

#[derive(Clone, Debug)]
struct Candidate {
    t_imp: f64,
    sta_lta: f64,
    peak_amp: f64,
    pre_rms: f64,
}

#[derive(Clone, Debug)]
struct Evaluation {
    cand: Candidate,
    confirmed: bool,
    confidence: f64,
    /// Smallest of the evidence scores (how toppling-like an unconfirmed candidate is).
    weakest: f64,
    post_rms: f64,
    text: String,
}

/// The analysed record: filled time, acceleration (NaN where missing) and its median time step,
/// found once (the candidates' checks need it).
struct Record<'a> {
    t: &'a [f64],
    x: &'a [f64],
    dt: f64,
}

fn make_candidate(
    record: &Record,
    d: &[f64],
    j0: usize,
    lag: usize,
    sta_lta: f64,
    o: &DetectOptions,
) -> Option<Candidate> {
    let (t, x) = (record.t, record.x);
    // Steepest step near the trigger, then the earliest step of the spike's leading edge: the
    // first step, at most 60 ms earlier, reaching EDGE_FRACTION of the steepest one.
    let steep = |a: usize, b: usize| {
        (a..b.min(d.len())).filter(|&i| d[i].is_finite()).max_by(|&i, &k| d[i].abs().total_cmp(&d[k].abs()))
    };
    let jmax = steep(idx_at(t, t[j0] - 0.06).max(lag), idx_at(t, t[j0] + 0.06).max(j0 + 1))?;
    let dmax = d[jmax].abs();
    if dmax <= 0.0 {
        return None;
    }
    let j = (idx_at(t, t[jmax] - 0.06).max(lag)..=jmax)
        .find(|&i| d[i].is_finite() && d[i].abs() >= EDGE_FRACTION * dmax)?;
    let t_imp = 0.5 * (t[j] + t[j - lag]);
    // Local level just before the rise; spike = largest excursion from it within 60 ms.
    let mut lv = values_in(t, x, t_imp - 0.3, t_imp - 0.02);
    if lv.is_empty() {
        lv = values_in(t, x, t_imp - 0.3, t_imp);
    }
    let level = median(&mut lv)?;
    let (a, b) = (j - lag, idx_at(t, t_imp + 0.06).max(j + 1).min(x.len()));
    let peak_amp = x[a..b].iter().filter(|v| v.is_finite()).map(|v| (v - level).abs()).fold(0.0, f64::max);
    let (pre_ss, pre_n) = detrended_ss(t, x, t_imp - o.pre_gap_s - o.pre_window_s, t_imp - o.pre_gap_s);
    let dt_pre = (t_imp - o.pre_gap_s - t[0]).min(o.pre_window_s);
    // Need at least 0.25 s of pre-impact data.
    if pre_n < 3 || dt_pre < 0.25 || (pre_n as f64) < 0.25 / record.dt {
        return None;
    }
    Some(Candidate { t_imp, sta_lta, peak_amp, pre_rms: (pre_ss / pre_n as f64).sqrt() })
}

fn evaluate(record: &Record, floor_v: Option<&[f64]>, c: &Candidate, t_end: f64, o: &DetectOptions) -> Evaluation {
    let (t, x) = (record.t, record.x);
    let pre = c.pre_rms.max(1e-12);
    let spike_r = c.peak_amp / pre;
    // Weakest of amplitude and impulsiveness, so that "score >= 0.5" matches the thresholds.
    let spike_score =
        score(spike_r, o.spike_ratio, 4.0 * o.spike_ratio).min(score(c.sta_lta, o.sta_lta_on, 4.0 * o.sta_lta_on));
    let t0 = c.t_imp + o.skip_s;
    let avail = t_end - t0;
    let head = format!(
        "impact at {:.3} s: spike {:.2} m/s² = {:.1}× pre-impact RMS {:.3} m/s² (STA/LTA {:.1})",
        c.t_imp, c.peak_amp, spike_r, c.pre_rms, c.sta_lta
    );
    if avail < o.min_tail_s {
        // Cannot confirm: the record ends too soon after the spike.
        let weakest = spike_score.min(0.5);
        return Evaluation {
            cand: c.clone(),
            confirmed: false,
            confidence: 0.0,
            weakest,
            post_rms: f64::NAN,
            text: format!(
                "{head}; record ends {:.2} s after it (< skip {:.2} s + {:.2} s): drop cannot be confirmed",
                t_end - c.t_imp,
                o.skip_s,
                o.min_tail_s
            ),
        };
    }
    let post_rms = window_rms(t, x, t0, (t0 + o.post_window_s).min(t_end + 1e-9));
    let drop = post_rms / pre;
    let (persist, reached_end) = persistence(record, t0, t_end, o.block_s, o.drop_ratio * pre);
    let drop_score = score(1.0 / drop.max(1e-12), 1.0 / o.drop_ratio, 10.0);
    let persist_thr = if reached_end { o.min_tail_s.min(o.min_drop_s) } else { o.min_drop_s };
    let persist_score = score(persist, persist_thr, 2.5 * o.min_drop_s);
    let confirmed =
        spike_r >= o.spike_ratio && c.sta_lta >= o.sta_lta_on && drop <= o.drop_ratio && persist >= persist_thr;
    let mut confidence = (spike_score * drop_score * persist_score).cbrt();
    let weakest = spike_score.min(drop_score).min(persist_score);
    let mut text = format!(
        "{head}; RMS from +{:.2} s is {:.3} m/s² = {:.2}× before (threshold {:.2}), drop lasts {:.1} s{}",
        o.skip_s,
        post_rms,
        drop,
        o.drop_ratio,
        persist,
        if reached_end { " (to end of record)" } else { "" }
    );
    if let Some(fv) = floor_v {
        if fv.len() == t.len() {
            let f_rms = window_rms(t, fv, t0, (t0 + o.post_window_s).min(t_end + 1e-9));
            if f_rms.is_finite() && f_rms > 0.0 {
                let q = post_rms / f_rms;
                let agree = (1.0 - q.ln().abs() / o.floor_agreement_factor.ln()).clamp(0.0, 1.0);
                if confirmed {
                    if agree > 0.0 {
                        confidence += (1.0 - confidence) * 0.6 * agree;
                    } else if q > o.floor_agreement_factor {
                        confidence = (confidence * 0.85).max(0.5);
                    }
                }
                text.push_str(&format!(
                    "; floor vertical RMS {:.3} m/s² (post/floor {:.2}{})",
                    f_rms,
                    q,
                    if agree > 0.0 { ", consistent with lying on its side" } else { ", not consistent" }
                ));
            }
        } else {
            text.push_str("; floor vertical ignored (length differs from time)");
        }
    }
    Evaluation { cand: c.clone(), confirmed, confidence: confidence.clamp(0.0, 1.0), weakest, post_rms, text }
}

/// 0.5 at `thr`, 1 at `clear`, 0 at thr²/clear, log-linear in between.
fn score(x: f64, thr: f64, clear: f64) -> f64 {
    if x.is_nan() || x <= 0.0 {
        return 0.0;
    }
    if x.is_infinite() {
        return 1.0;
    }
    0.5 + 0.5 * ((x / thr).ln() / (clear / thr).ln()).clamp(-1.0, 1.0)
}

/// Duration (from t0) during which every block of `block_s` has detrended RMS ≤ `limit`;
/// and whether that reached the end of the record. Blocks with too few valid samples are neutral.
fn persistence(record: &Record, t0: f64, t_end: f64, block_s: f64, limit: f64) -> (f64, bool) {
    let (t, x, dt) = (record.t, record.x, record.dt);
    let mut bs = t0;
    let mut good_until = t0;
    while bs < t_end {
        let be = (bs + block_s).min(t_end + 1e-9);
        let (ss, n) = detrended_ss(t, x, bs, be);
        let enough = n >= 3 && (n as f64) >= 0.25 * block_s / dt;
        if enough && (ss / n as f64).sqrt() > limit {
            return (good_until - t0, false);
        }
        good_until = be.min(t_end);
        bs += block_s;
    }
    (good_until - t0, true)
}

/// RMS about the least-squares line over [a, b) (NaN if no valid sample).
fn window_rms(t: &[f64], x: &[f64], a: f64, b: f64) -> f64 {
    let (ss, n) = detrended_ss(t, x, a, b);
    if n == 0 {
        f64::NAN
    } else {
        (ss / n as f64).sqrt()
    }
}

/// Sum of squared residuals from a least-squares line over samples with time in [a, b),
/// ignoring non-finite values; and the number of values used. Fewer than 3 values: mean removed.
fn detrended_ss(t: &[f64], x: &[f64], a: f64, b: f64) -> (f64, usize) {
    let (i0, i1) = (idx_at(t, a), idx_at(t, b));
    let (mut n, mut st, mut sx) = (0usize, 0.0, 0.0);
    for i in i0..i1 {
        if x[i].is_finite() {
            n += 1;
            st += t[i];
            sx += x[i];
        }
    }
    if n == 0 {
        return (0.0, 0);
    }
    let (tm, xm) = (st / n as f64, sx / n as f64);
    let (mut stt, mut stx, mut sxx) = (0.0, 0.0, 0.0);
    for i in i0..i1 {
        if x[i].is_finite() {
            let (u, v) = (t[i] - tm, x[i] - xm);
            stt += u * u;
            stx += u * v;
            sxx += v * v;
        }
    }
    let ss = if n >= 3 && stt > 0.0 { (sxx - stx * stx / stt).max(0.0) } else { sxx };
    (ss, n)
}

/// sqrt(STA/LTA) of d² per sample (NaN-aware; 0 where undefined). LTA window precedes the STA
/// window; it needs at least 0.5 s of valid data.
fn sta_lta(d: &[f64], dt: f64, o: &DetectOptions) -> Vec<f64> {
    let n = d.len();
    let n_sta = ((o.sta_s / dt).round() as usize).max(1);
    let n_lta = ((o.lta_s / dt).round() as usize).max(1);
    let min_lta = ((0.5 / dt).round() as usize).clamp(1, n_lta);
    let mut s = vec![0.0; n + 1];
    let mut c = vec![0usize; n + 1];
    for i in 0..n {
        let ok = d[i].is_finite();
        s[i + 1] = s[i] + if ok { d[i] * d[i] } else { 0.0 };
        c[i + 1] = c[i] + usize::from(ok);
    }
    let eps = if c[n] > 0 { 1e-6 * s[n] / c[n] as f64 } else { 0.0 } + 1e-300;
    let mut r = vec![0.0; n];
    for i in 0..n {
        if !d[i].is_finite() || i + 1 < n_sta + min_lta {
            continue;
        }
        let (sa, sb) = (i + 1 - n_sta, i + 1);
        let la = sa.saturating_sub(n_lta);
        let (cs, cl) = (c[sb] - c[sa], c[sa] - c[la]);
        if cs == 0 || cl < min_lta {
            continue;
        }
        let sta = (s[sb] - s[sa]) / cs as f64;
        let lta = (s[sa] - s[la]) / cl as f64;
        r[i] = (sta / (lta + eps)).sqrt();
    }
    r
}

fn values_in(t: &[f64], x: &[f64], a: f64, b: f64) -> Vec<f64> {
    x[idx_at(t, a)..idx_at(t, b)].iter().copied().filter(|v| v.is_finite()).collect()
}

/// First index with t[i] >= time.
fn idx_at(t: &[f64], time: f64) -> usize {
    t.partition_point(|&v| v < time)
}

fn last_valid_time(t: &[f64], x: &[f64]) -> f64 {
    x.iter().rposition(|v| v.is_finite()).map_or(t[0], |i| t[i])
}

fn median_step(t: &[f64]) -> Option<f64> {
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).filter(|v| *v > 0.0).collect();
    median(&mut d)
}

/// Non-finite times are filled by linear interpolation between finite neighbours (the samples
/// themselves are treated as missing). None if the finite times decrease or are fewer than two.
fn fill_time(time: &[f64]) -> Option<Vec<f64>> {
    let fin: Vec<usize> = (0..time.len()).filter(|&i| time[i].is_finite()).collect();
    if fin.len() < 2 || fin.windows(2).any(|w| time[w[1]] < time[w[0]]) {
        return None;
    }
    let mut t = time.to_vec();
    let (f0, f1) = (fin[0], fin[1]);
    let slope0 = (time[f1] - time[f0]) / (f1 - f0) as f64;
    for (i, v) in t.iter_mut().enumerate().take(f0) {
        *v = time[f0] - slope0 * (f0 - i) as f64;
    }
    for w in fin.windows(2) {
        let (a, b) = (w[0], w[1]);
        for (i, v) in t.iter_mut().enumerate().take(b).skip(a + 1) {
            *v = time[a] + (time[b] - time[a]) * (i - a) as f64 / (b - a) as f64;
        }
    }
    let (la, lb) = (fin[fin.len() - 2], fin[fin.len() - 1]);
    let slope1 = (time[lb] - time[la]) / (lb - la) as f64;
    for (i, v) in t.iter_mut().enumerate().skip(lb + 1) {
        *v = time[lb] + slope1 * (i - lb) as f64;
    }
    Some(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic normal noise (SplitMix64 + Box-Muller).
    struct Rng(u64);
    impl Rng {
        fn uniform(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        }
        fn normal(&mut self) -> f64 {
            let (u, v) = (self.uniform().max(1e-300), self.uniform());
            (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
        }
    }

    /// Strong "equipment" shaking: a few 1.5-6 Hz sines with a 2-20 s envelope, RMS ≈ `rms`.
    fn shaking(t: &[f64], rms: f64, seed: u64) -> Vec<f64> {
        let mut r = Rng(seed);
        let comps: Vec<(f64, f64)> =
            (0..6).map(|_| (1.5 + 4.5 * r.uniform(), std::f64::consts::TAU * r.uniform())).collect();
        t.iter()
            .map(|&s| {
                let env = ((s - 1.0) / 2.0).clamp(0.0, 1.0);
                let v: f64 = comps.iter().map(|(f, p)| (std::f64::consts::TAU * f * s + p).sin()).sum();
                rms * env * v / 3f64.sqrt() + 0.01 * r.normal()
            })
            .collect()
    }

    fn times(fs: f64, dur: f64) -> Vec<f64> {
        (0..(fs * dur) as usize).map(|k| k as f64 / fs).collect()
    }

    /// Alpha pulse (t/τ)e^(1−t/τ), τ = 12 ms, starting at t0.
    fn alpha(s: f64, t0: f64, peak: f64) -> f64 {
        if s < t0 {
            0.0
        } else {
            let x = (s - t0) / 0.012;
            peak * x * (1.0 - x).exp()
        }
    }

    /// Shaking, then at t0 an impact pulse and ~1/10 amplitude (10 Hz "vertical") on a −g offset.
    fn toppling_record(fs: f64, t0: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let t = times(fs, 30.0);
        let sh = shaking(&t, 3.0, seed);
        let x = t
            .iter()
            .zip(&sh)
            .map(|(&s, &v)| {
                if s < t0 {
                    v
                } else {
                    -9.80665 + 0.1 * v * (std::f64::consts::TAU * 10.0 * s).sin() + alpha(s, t0, 50.0)
                }
            })
            .collect();
        (t, x)
    }

    #[test]
    fn synthetic_toppling_found_at_100_to_1000_hz() {
        for (k, fs) in [100.0, 200.0, 256.0, 500.0, 1000.0].into_iter().enumerate() {
            let t0 = 12.3456;
            let (t, x) = toppling_record(fs, t0, 7 + k as u64);
            let ev = detect_toppling(&t, &x, None, &DetectOptions::default());
            assert!(ev.toppled, "{fs} Hz: {ev:?}");
            let err = ev.impact_time_s.unwrap() - t0;
            println!(
                "synthetic {fs:>6} Hz: impact {:.4} s (truth {t0}), error {err:+.4} s, confidence {:.3}",
                ev.impact_time_s.unwrap(),
                ev.confidence
            );
            assert!(err.abs() <= 0.012, "{fs} Hz: error {err} s ({ev:?})");
            assert!(ev.confidence > 0.8 && ev.confidence <= 1.0, "{fs} Hz: {ev:?}");
            assert!(ev.post_rms_mps2 < 0.35 * ev.pre_rms_mps2);
        }
    }

    #[test]
    fn strong_shaking_with_isolated_spike_is_not_toppling() {
        let t = times(200.0, 30.0);
        let mut x = shaking(&t, 8.0, 3);
        for (v, &s) in x.iter_mut().zip(&t) {
            *v += alpha(s, 15.0, 80.0);
        }
        let ev = detect_toppling(&t, &x, None, &DetectOptions::default());
        assert!(!ev.toppled, "{ev:?}");
        assert!(ev.impact_time_s.is_none());
        assert!(ev.confidence >= 0.5, "{ev:?}");
        assert!(ev.explanation.contains("15.0"), "the spike should be named: {}", ev.explanation);
        assert!(ev.peak_mps2 > 50.0, "record peak includes the spike: {ev:?}");
    }

    #[test]
    fn shaking_that_stops_abruptly_without_impact_is_not_toppling() {
        let t = times(200.0, 30.0);
        let x: Vec<f64> =
            shaking(&t, 5.0, 4).iter().zip(&t).map(|(&v, &s)| if s < 15.0 { v } else { 0.05 * v }).collect();
        let ev = detect_toppling(&t, &x, None, &DetectOptions::default());
        assert!(!ev.toppled, "{ev:?}");
    }

    #[test]
    fn truncated_after_spike_is_undecided() {
        let (t, x) = toppling_record(200.0, 20.0, 5);
        let n = t.partition_point(|&s| s <= 20.3);
        let ev = detect_toppling(&t[..n], &x[..n], None, &DetectOptions::default());
        assert!(!ev.toppled && ev.impact_time_s.is_none(), "{ev:?}");
        assert!((ev.confidence - 0.5).abs() < 1e-12, "{ev:?}");
        assert!(ev.explanation.contains("cannot be confirmed"), "{}", ev.explanation);
    }

    #[test]
    fn nan_gaps_and_floor_vertical() {
        let (t, mut x) = toppling_record(256.0, 14.0, 6);
        for (k, v) in x.iter_mut().enumerate() {
            let s = k as f64 / 256.0;
            if (10.0..11.0).contains(&s) || (15.0..16.0).contains(&s) || k % 23 == 0 {
                *v = f64::NAN;
            }
        }
        // Floor vertical: the same 10 Hz motion the toppled sensor sees.
        let sh = shaking(&t, 3.0, 6);
        let fv: Vec<f64> =
            t.iter().zip(&sh).map(|(&s, &v)| 0.1 * v * (std::f64::consts::TAU * 10.0 * s).sin()).collect();
        let without = detect_toppling(&t, &x, None, &DetectOptions::default());
        let with = detect_toppling(&t, &x, Some(&fv), &DetectOptions::default());
        for ev in [&without, &with] {
            assert!(ev.toppled && (ev.impact_time_s.unwrap() - 14.0).abs() < 0.01, "{ev:?}");
        }
        assert!(with.confidence >= without.confidence, "{} < {}", with.confidence, without.confidence);
        assert!(with.explanation.contains("consistent with lying on its side"), "{}", with.explanation);
    }

    #[test]
    fn quiet_or_degenerate_records_do_not_panic() {
        let o = DetectOptions::default();
        let t = times(200.0, 10.0);
        let zeros = vec![0.0; t.len()];
        let ev = detect_toppling(&t, &zeros, None, &o);
        assert!(!ev.toppled && ev.confidence > 0.9, "{ev:?}");
        let nans = vec![f64::NAN; t.len()];
        let ev = detect_toppling(&t, &nans, None, &o);
        assert!(!ev.toppled && ev.confidence == 0.0 && ev.explanation.starts_with("not analysed"), "{ev:?}");
        let ev = detect_toppling(&t[..10], &zeros, None, &o);
        assert!(!ev.toppled && ev.explanation.starts_with("not analysed"), "{ev:?}");
        let back: Vec<f64> = t.iter().rev().copied().collect();
        let ev = detect_toppling(&back, &zeros, None, &o);
        assert!(!ev.toppled && ev.explanation.starts_with("not analysed"), "{ev:?}");
        let ev = detect_toppling(&[], &[], None, &o);
        assert!(!ev.toppled, "{ev:?}");
    }

    #[test]
    fn score_is_half_at_threshold() {
        assert!((score(4.0, 4.0, 12.0) - 0.5).abs() < 1e-12);
        assert!((score(12.0, 4.0, 12.0) - 1.0).abs() < 1e-12);
        assert_eq!(score(0.0, 4.0, 12.0), 0.0);
        assert_eq!(score(f64::NAN, 4.0, 12.0), 0.0);
    }
}
