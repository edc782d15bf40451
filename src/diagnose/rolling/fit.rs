//! Fitting a rolling effect's few parameters: the strategy of the rocking fit ([`crate::diagnose::fit`])
//! for a cart whose runs start where the effect begins: a grid judged over a short horizon past
//! the window's start, Nelder–Mead (argmin) from the best grid points over growing horizons, in
//! coordinates scaled to the ranges with the discrete parameters (a caster, a side) held, as is a
//! step's ramp (a step is searched as a step, a gradual change from the grid's ramps), every
//! optimum judged on the whole record, and the best refined over the span where the nominal
//! cart is predictable (kept if it fits the whole record better).
//!
//! A fit spends a bounded number of the cart's right-hand-side evaluations, counted in runs of
//! the record's length at the nominal cart's cost per sample, at most [`UNIT_PER_SAMPLE`]
//! evaluations per sample (a cart that crawls through stiff sticking costs more, and is fitted
//! within the same absolute bound): [`GRID_RUNS`] shared by a grid's points, at least
//! [`GRID_POINT_RUNS`] each (a point runs over a short horizon), [`SEARCH_RUNS`] for each
//! start's searches, spent in their order, [`JUDGE_RUNS`] for each optimum's whole-record
//! run, and [`REFINE_RUNS`] for the refinement. A run past its allowance fails; one that fails
//! otherwise is charged what it spent. A case whose parameters make stiff runs is so fitted in
//! bounded time, and the same on every machine: the allowance is counted, never timed.

use std::sync::atomic::{AtomicUsize, Ordering};

use argmin::core::{CostFunction, Error, Executor, State};
use argmin::solver::neldermead::NelderMead;
use rayon::prelude::*;

use super::effects::Effect;
use super::evidence::Evidence;
use super::{early_within_allowance, flagged_early, RollingCase, Track};
use crate::diagnose::memo::Memo;
use crate::diagnose::verdict::Misfit;

/// Grid points a local search starts from (the best; and the best of a family, a step or a
/// gradual change, that none of them is in).
const STARTS: usize = 3;
/// Horizon past the window's start (s) of the grid, then of the successive searches.
const GRID_HORIZON: f64 = 1.0;
const HORIZONS: [f64; 2] = [1.5, 4.0];
const MAX_ITERATIONS: u64 = 30;
/// What a grid may spend, shared by its points, each of which may spend at least
/// [`GRID_POINT_RUNS`] (a grid point spans a few seconds of a record of tens); what each
/// start's searches and each optimum's whole-record run may spend; in runs of the record's length.
const GRID_RUNS: f64 = 40.0;
const GRID_POINT_RUNS: f64 = 0.3;
const SEARCH_RUNS: f64 = 20.0;
const JUDGE_RUNS: f64 = 10.0;
/// What the best optimum's refinement over the predictable records may spend, in the same runs.
const REFINE_RUNS: f64 = 20.0;
/// The most a run of the record's length is counted at, per sample: the nominal cart of the
/// study's units costs 10 to 20 on a record that moves it (Dopri5 at the default tolerances).
const UNIT_PER_SAMPLE: f64 = 25.0;

/// Right-hand-side evaluations a part of the fit may still spend. One allowance is spent by
/// one sequence of runs (a grid point, a start's searches), so what it allows is deterministic.
struct Allowance(AtomicUsize);

impl Allowance {
    fn new(case: &RollingCase, nominal: &Track, runs: f64) -> Allowance {
        let samples = case.samples() as f64;
        let run = (nominal.evaluations as f64).min(UNIT_PER_SAMPLE * samples);
        Allowance(AtomicUsize::new((runs * run) as usize))
    }

    fn left(&self) -> usize {
        self.0.load(Ordering::Relaxed)
    }

    fn spend(&self, evaluations: usize) {
        self.0.store(self.left().saturating_sub(evaluations), Ordering::Relaxed);
    }
}

pub struct Fit {
    pub params: Vec<f64>,
    pub misfit: Misfit,
    pub track: Track,
    pub evaluations: usize,
}

struct Objective<'a> {
    effect: &'a dyn Effect,
    case: &'a RollingCase,
    nominal: &'a Track,
    evidence: &'a Evidence,
    /// Whole-record runs (the objective's are counted by `seen`).
    evaluations: &'a AtomicUsize,
    /// The misfits of the runs already made, with what each spent (None: it failed): asked
    /// again, a run that succeeded within less than what the allowance has left would succeed
    /// again, identically, and is charged what it spent then.
    seen: Memo<Option<(f64, usize)>>,
}

impl Objective<'_> {
    /// The effect's run until `until`, within `allowance` (None: failed, or nothing left).
    fn track(&self, params: &[f64], until: f64, allowance: &Allowance) -> Option<Track> {
        if allowance.left() > 0 {
            self.evaluations.fetch_add(1, Ordering::Relaxed);
        }
        self.run(params, until, allowance)
    }

    fn run(&self, params: &[f64], until: f64, allowance: &Allowance) -> Option<Track> {
        let left = allowance.left();
        if left == 0 {
            return None;
        }
        let (alteration, onset) = self.effect.alteration(self.case, self.nominal, params).ok()?;
        let run = self.case.altered(self.nominal, &alteration, onset, until, Some(left));
        allowance.spend(run.as_ref().map_or_else(|s| s.spent, |t| t.evaluations));
        let mut track = run.ok()?;
        track.accel_unseen = self.effect.accel_unseen(self.case, self.nominal, params, &track);
        Some(track)
    }

    fn chi2(&self, params: &[f64], until: f64, allowance: &Allowance) -> f64 {
        let left = allowance.left();
        if let Some(Some((chi2, spent))) = self.seen.get(params, until) {
            if spent < left {
                allowance.spend(spent);
                return chi2;
            }
        }
        if left == 0 {
            return f64::INFINITY;
        }
        let track = self.run(params, until, allowance);
        let chi2 = track.map(|t| self.evidence.misfit_between(&t, f64::NEG_INFINITY, until).chi2);
        self.seen.insert(params, until, chi2.map(|c| (c, left - allowance.left())));
        chi2.unwrap_or(f64::INFINITY)
    }
}

/// Nelder–Mead's view: the continuous parameters in [0, 1] coordinates of their bounds.
struct Scaled<'a> {
    objective: &'a Objective<'a>,
    bounds: &'a [(f64, f64)],
    continuous: &'a [usize],
    template: &'a [f64],
    until: f64,
    allowance: &'a Allowance,
}

impl Scaled<'_> {
    fn params(&self, u: &[f64]) -> Vec<f64> {
        let mut p = self.template.to_vec();
        for (&i, &ui) in self.continuous.iter().zip(u) {
            let (lo, hi) = self.bounds[i];
            p[i] = lo + ui.clamp(0.0, 1.0) * (hi - lo);
        }
        p
    }
}

impl CostFunction for Scaled<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, u: &Vec<f64>) -> Result<f64, Error> {
        let outside: f64 = u.iter().map(|v| (v - v.clamp(0.0, 1.0)).abs()).sum();
        Ok(self.objective.chi2(&self.params(u), self.until, self.allowance) * (1.0 + outside))
    }
}

fn search(
    objective: &Objective<'_>,
    bounds: &[(f64, f64)],
    continuous: &[usize],
    start: &[f64],
    until: f64,
    allowance: &Allowance,
) -> Vec<f64> {
    if continuous.is_empty() {
        return start.to_vec();
    }
    let problem = Scaled { objective, bounds, continuous, template: start, until, allowance };
    let u0: Vec<f64> = continuous
        .iter()
        .map(|&i| {
            let (lo, hi) = bounds[i];
            if hi > lo {
                (start[i] - lo) / (hi - lo)
            } else {
                0.0
            }
        })
        .collect();
    let mut simplex = vec![u0.clone()];
    for d in 0..u0.len() {
        let mut v = u0.clone();
        v[d] += if v[d] > 0.5 { -0.05 } else { 0.05 };
        simplex.push(v);
    }
    let start_cost = objective.chi2(start, until, allowance);
    let Ok(solver) = NelderMead::new(simplex).with_sd_tolerance(1e-6 * start_cost.max(1.0)) else {
        return start.to_vec();
    };
    let found = Executor::new(problem, solver)
        .configure(|s| s.max_iters(MAX_ITERATIONS))
        .run()
        .ok()
        .and_then(|r| Some((r.state().get_best_cost(), r.state().get_best_param()?.clone())));
    match found {
        Some((cost, u)) if cost < start_cost => {
            Scaled { objective, bounds, continuous, template: start, until, allowance }.params(&u)
        }
        _ => start.to_vec(),
    }
}

/// The grid points (indices into `scored`, the grid with its misfits) searches start from: the
/// [`STARTS`] best; the best of a family (a step, a gradual change) they all miss; and the best
/// of each value of a parameter searched apart (a caster) that none of them has. Best first.
fn starts(effect: &dyn Effect, scored: &[(f64, Vec<f64>)]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..scored.len()).collect();
    order.sort_by(|&a, &b| scored[a].0.total_cmp(&scored[b].0).then(a.cmp(&b)));
    let family = |p: &[f64]| effect.held_at_zero().map(|i| p[i] == 0.0);
    let mut picked: Vec<usize> = order.iter().copied().take(STARTS).collect();
    if let Some(&i) = order.iter().find(|&&i| picked.iter().all(|&j| family(&scored[j].1) != family(&scored[i].1))) {
        picked.push(i);
    }
    if let Some(k) = effect.searched_apart() {
        for &i in &order {
            if picked.iter().all(|&j| scored[j].1[k] != scored[i].1[k]) {
                picked.push(i);
            }
        }
    }
    picked
}

pub fn fit(
    effect: &dyn Effect,
    case: &RollingCase,
    nominal: &Track,
    evidence: &Evidence,
    window: (f64, f64),
    refine_until: f64,
) -> Fit {
    let evaluations = AtomicUsize::new(0);
    let objective = Objective { effect, case, nominal, evidence, evaluations: &evaluations, seen: Memo::default() };
    let bounds = effect.bounds(case, nominal, window);
    let discrete = effect.discrete();
    let continuous: Vec<usize> = (0..bounds.len()).filter(|&i| !discrete.get(i).copied().unwrap_or(false)).collect();
    let first = window.0 + GRID_HORIZON;
    let grid = effect.grid(case, nominal, window);
    let per_point = (GRID_RUNS / grid.len().max(1) as f64).max(GRID_POINT_RUNS);
    let scored: Vec<(f64, Vec<f64>)> = grid
        .into_par_iter()
        .map(|p| (objective.chi2(&p, first, &Allowance::new(case, nominal, per_point)), p))
        .collect();
    let picked = starts(effect, &scored);
    let starts: Vec<Vec<f64>> = picked.iter().map(|&i| scored[i].1.clone()).collect();
    // What a search from `p` moves: a step is searched as a step, its ramp staying at zero.
    let free = |p: &[f64]| -> Vec<usize> {
        let held = effect.held_at_zero().filter(|&i| p[i] == 0.0);
        continuous.iter().copied().filter(|&i| Some(i) != held).collect()
    };
    let optima: Vec<Vec<f64>> = starts
        .into_par_iter()
        .flat_map_iter(|start| {
            let (free, allowance) = (free(&start), Allowance::new(case, nominal, SEARCH_RUNS));
            let mut params = start;
            for h in HORIZONS {
                params = search(&objective, &bounds, &free, &params, window.0 + h, &allowance);
            }
            std::iter::once(params)
        })
        .collect();
    let end = case.end_s();
    let judged: Vec<(f64, Vec<f64>, Track)> = optima
        .into_par_iter()
        .filter_map(|params| {
            let track = objective.track(&params, end, &Allowance::new(case, nominal, JUDGE_RUNS))?;
            Some((evidence.misfit(&track).chi2, params, track))
        })
        .collect();
    let (chi2, params, track) = judged.into_iter().reduce(|a, b| if b.0 < a.0 { b } else { a }).unwrap_or_else(|| {
        let params = picked.first().map_or_else(|| vec![0.0; bounds.len()], |&i| scored[i].1.clone());
        (f64::INFINITY, params, failed(case))
    });
    // The best optimum, refined over all the records the nominal cart is predictable on: some
    // effects show their size only seconds past the last horizon (a pad's drag once the cart
    // moves fast enough to slide the wheel). Kept if it fits the whole record better and leaves
    // no more disagreement right after the window's start than acceptance allows, or than
    // before: a later fit bought with a worse start must not turn a pass into a failure.
    let (params, track) = if chi2.is_finite() && refine_until > window.0 + HORIZONS[HORIZONS.len() - 1] {
        let early = |t: &Track| flagged_early(evidence, t, window);
        let allowance = Allowance::new(case, nominal, REFINE_RUNS);
        let refined = search(&objective, &bounds, &free(&params), &params, refine_until, &allowance);
        // A search that found nothing better returns its start: no run to judge.
        let better = (refined != params)
            .then(|| objective.track(&refined, end, &Allowance::new(case, nominal, JUDGE_RUNS)))
            .flatten();
        match better {
            Some(better)
                if evidence.misfit(&better).chi2 < chi2
                    && (early(&better) <= early(&track) || early_within_allowance(early(&better), early(nominal))) =>
            {
                (refined, better)
            }
            _ => (params, track),
        }
    } else {
        (params, track)
    };
    let misfit = evidence.misfit(&track);
    let evaluations = evaluations.load(Ordering::Relaxed) + objective.seen.runs();
    Fit { params, misfit, track, evaluations }
}

/// What a model that cannot run predicts: nothing (every residual is NaN, never accepted).
fn failed(case: &RollingCase) -> Track {
    let n = case.samples();
    Track {
        x_m: vec![f64::NAN; n],
        y_m: vec![f64::NAN; n],
        yaw_rad: vec![f64::NAN; n],
        ax_abs_mps2: vec![f64::NAN; n],
        states: Vec::new(),
        onset_s: None,
        evaluations: 0,
        accel_unseen: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::{fit, starts, HORIZONS};
    use crate::diagnose::rolling::cut_beyond_noise;
    use crate::diagnose::rolling::effects::{library, Effect};
    use crate::diagnose::rolling::evidence::Evidence;
    use crate::diagnose::rolling::{gentle_then_strong_floor, test_cart, Camera, RollingCase};
    use crate::diagnose::Observed;
    use crate::physics::rolling::Options;
    use crate::signal::synthetic_motion::SplitMix64 as Rng;

    fn brake() -> &'static dyn Effect {
        *library().iter().find(|e| e.name() == "caster_brake").expect("the library has a brake")
    }

    /// MC2 on a 0.8 Hz floor, gentle (0.47 m/s^2, just enough to roll it) for 6 s then strong
    /// (4 m/s^2), whose caster 1 wheel locks at 1 s and drags with μ = 0.45; the records are that
    /// cart's own with the sensors' noise (seeded).
    fn dragging_cart() -> RollingCase {
        let (dt, n) = (0.005, 2000);
        let ax = gentle_then_strong_floor(n, 6.0);
        let options = Options {
            yaw0_rad: 0.2,
            steer0_rad: [0.3, -0.2, 0.1, 0.4],
            method: crate::diagnose::rolling::METHOD,
            ..Options::default()
        };
        let ay = ax.iter().map(|a| 0.3 * a).collect();
        let mut case = test_cart("dragging", ax, ay, options);
        let nominal = case.nominal().expect("the nominal cart runs");
        let (alteration, onset) = brake().alteration(&case, &nominal, &[0.0, 1.0, 0.45, 0.0]).unwrap();
        let braked = case.altered(&nominal, &alteration, onset, case.end_s(), None).expect("the braked cart runs");
        let mut rng = Rng::new(23);
        let time_s: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let value = braked.ax_abs_mps2.iter().map(|a| a + case.accel_noise_mps2 * rng.normal()).collect();
        case.accel = Some(Observed { time_s: time_s.clone(), value });
        let frames: Vec<usize> = (0..n).step_by(7).collect();
        let mut pick = |v: &[f64], sd: f64| frames.iter().map(|&k| v[k] + sd * rng.normal()).collect();
        case.camera = Some(Camera {
            time_s: frames.iter().map(|&k| time_s[k]).collect(),
            x_m: pick(&braked.x_m, case.camera_noise_m),
            y_m: pick(&braked.y_m, case.camera_noise_m),
            yaw_rad: pick(&braked.yaw_rad, case.camera_noise_rad),
        });
        case
    }

    #[test]
    fn searches_start_from_the_best_grid_points_a_missed_family_and_every_caster() {
        // A brake's grid points (caster, t0, μ, ramp) with their misfits: the three best all
        // lock caster 1 at once.
        let scored: Vec<(f64, Vec<f64>)> = [
            (9.0, [3.0, 1.0, 0.2, 0.0]),
            (1.0, [0.0, 1.0, 0.2, 0.0]),
            (5.0, [1.0, 1.0, 0.2, 0.0]),
            (2.0, [0.0, 1.1, 0.2, 0.0]),
            (7.0, [1.0, 1.1, 0.2, 0.0]),
            (3.0, [0.0, 1.2, 0.5, 0.0]),
            (6.0, [2.0, 1.0, 0.2, 0.25]),
            (4.0, [0.0, 1.0, 0.2, 0.25]),
            (8.0, [3.0, 1.0, 0.5, 0.0]),
        ]
        .into_iter()
        .map(|(c, p)| (c, p.to_vec()))
        .collect();
        // The three best, the best gradual pad, then the best of casters 2, 3 and 4.
        assert_eq!(starts(brake(), &scored), vec![1, 3, 5, 7, 2, 6, 8]);
        // A mass change has no caster: the three best and the best of the other family.
        let mass = *library().iter().find(|e| e.name() == "mass_change").unwrap();
        let scored: Vec<(f64, Vec<f64>)> =
            scored.into_iter().map(|(c, p)| (c, vec![p[1], -10.0, 0.0, 0.0, p[3]])).collect();
        assert_eq!(starts(mass, &scored), vec![1, 3, 5, 7]);
    }

    #[test]
    fn a_drag_whose_size_shows_late_is_fitted_over_the_predictable_records() {
        let case = dragging_cart();
        let nominal = case.nominal().unwrap();
        let evidence = Evidence::new(&case, 4.0);
        let window = evidence.window(&nominal).expect("the brake shows");
        let last = window.0 + HORIZONS[HORIZONS.len() - 1];
        assert!(
            window.0 < 1.2 && last < 6.0,
            "the brake shows at once {window:?}, the last horizon ends in the gentle part"
        );
        let rmse = |f: &super::Fit| evidence.window_rmse(&f.track, Some(window));
        // In the gentle part a drag of 0.4 and one of 0.5 move the cart 0.13 sigma (RMS) from
        // the concealed one, in the strong part 7 sigma: the searches up to the last horizon
        // barely see the drag's size; the refinement over the whole record does.
        let short = fit(brake(), &case, &nominal, &evidence, window, last);
        let whole = fit(brake(), &case, &nominal, &evidence, window, case.end_s());
        let mu = |f: &super::Fit| f.params[2];
        assert!((mu(&whole) - 0.45).abs() < 0.01, "refined: μ = {:.3} for 0.45", mu(&whole));
        // Past the noise (√(RMS² − 1)), the refined fit leaves at most half what the short one does.
        let cut = cut_beyond_noise(rmse(&short), rmse(&whole));
        assert!(
            cut >= 2.0,
            "without the refinement: μ = {:.3}, RMS {:.2}; refined μ = {:.3}, RMS {:.2}: {cut:.2}× past the noise",
            mu(&short),
            rmse(&short),
            mu(&whole),
            rmse(&whole)
        );
    }
}
