//! Fitting a rolling effect's few parameters: the strategy of the rocking fit ([`crate::diagnose::fit`])
//! for a cart whose runs start where the effect begins: a grid judged over a short horizon past
//! the window's start, Nelder–Mead (argmin) from the best grid points over growing horizons, in
//! coordinates scaled to the ranges with the discrete parameters (a caster, a side) held, as is a
//! step's ramp (a step is searched as a step, a gradual change from the grid's ramps), and
//! every optimum judged on the whole record.
//!
//! A fit spends a bounded number of the cart's right-hand-side evaluations, counted in runs of
//! the record's length at the nominal cart's cost per sample, at most [`UNIT_PER_SAMPLE`]
//! evaluations per sample (a cart that crawls through stiff sticking costs more, and is fitted
//! within the same absolute bound): [`GRID_RUNS`] shared by a grid's points, at least
//! [`GRID_POINT_RUNS`] each (a point runs over a short horizon), [`SEARCH_RUNS`] for each
//! start's searches, spent in their order, and [`JUDGE_RUNS`] for each optimum's whole-record
//! run. A run past its allowance fails; one that fails otherwise is charged what it spent. A
//! case whose parameters make stiff runs is so fitted in bounded time, and the same on every
//! machine: the allowance is counted, never timed.

use std::sync::atomic::{AtomicUsize, Ordering};

use argmin::core::{CostFunction, Error, Executor, State};
use argmin::solver::neldermead::NelderMead;
use rayon::prelude::*;

use super::effects::Effect;
use super::evidence::{Evidence, Misfit};
use super::{RollingCase, Track};

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
    evaluations: &'a AtomicUsize,
}

impl Objective<'_> {
    /// The effect's run until `until`, within `allowance` (None: failed, or nothing left).
    fn track(&self, params: &[f64], until: f64, allowance: &Allowance) -> Option<Track> {
        let left = allowance.left();
        if left == 0 {
            return None;
        }
        self.evaluations.fetch_add(1, Ordering::Relaxed);
        let (alteration, onset) = self.effect.alteration(self.case, self.nominal, params).ok()?;
        let run = self.case.altered(self.nominal, &alteration, onset, until, Some(left));
        allowance.spend(run.as_ref().map_or_else(|(_, spent)| *spent, |t| t.evaluations));
        let mut track = run.ok()?;
        track.accel_unseen = self.effect.accel_unseen(self.case, self.nominal, params, &track);
        Some(track)
    }

    fn chi2(&self, params: &[f64], until: f64, allowance: &Allowance) -> f64 {
        self.track(params, until, allowance)
            .map_or(f64::INFINITY, |t| self.evidence.misfit_between(&t, f64::NEG_INFINITY, until).chi2)
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

pub fn fit(effect: &dyn Effect, case: &RollingCase, nominal: &Track, evidence: &Evidence, window: (f64, f64)) -> Fit {
    let evaluations = AtomicUsize::new(0);
    let objective = Objective { effect, case, nominal, evidence, evaluations: &evaluations };
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
    let mut order: Vec<usize> = (0..scored.len()).collect();
    order.sort_by(|&a, &b| scored[a].0.total_cmp(&scored[b].0).then(a.cmp(&b)));
    // The best grid points, and the best of a family (a step, a gradual change) they all miss.
    let family = |p: &[f64]| effect.held_at_zero().map(|i| p[i] == 0.0);
    let mut picked: Vec<usize> = order.iter().copied().take(STARTS).collect();
    if let Some(&i) = order.iter().find(|&&i| picked.iter().all(|&j| family(&scored[j].1) != family(&scored[i].1))) {
        picked.push(i);
    }
    let starts: Vec<Vec<f64>> = picked.iter().map(|&i| scored[i].1.clone()).collect();
    let optima: Vec<Vec<f64>> = starts
        .into_par_iter()
        .flat_map_iter(|start| {
            // A step is searched as a step: its ramp stays at zero.
            let held = effect.held_at_zero().filter(|&i| start[i] == 0.0);
            let free: Vec<usize> = continuous.iter().copied().filter(|&i| Some(i) != held).collect();
            let (mut params, allowance) = (start, Allowance::new(case, nominal, SEARCH_RUNS));
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
    let (_, params, track) = judged.into_iter().reduce(|a, b| if b.0 < a.0 { b } else { a }).unwrap_or_else(|| {
        let params = order.first().map_or_else(|| vec![0.0; bounds.len()], |&i| scored[i].1.clone());
        (f64::INFINITY, params, failed(case))
    });
    let misfit = evidence.misfit(&track);
    Fit { params, misfit, track, evaluations: evaluations.into_inner() }
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
