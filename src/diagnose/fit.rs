//! Fitting an effect's few parameters to the records: a grid over the plausible ranges, then
//! argmin's Nelder–Mead from the best grid points, in coordinates scaled to the ranges, with the
//! discrete parameters held at their grid values.
//!
//! A rocking block is an inverted pendulum between impacts: two trajectories that start a hair
//! apart separate like e^(pt), so a misfit over the whole record is a rugged landscape where a
//! nearly right parameter scores as badly as a wrong one. The fit therefore grows its horizon:
//! the grid and the first search only look at the records up to shortly after the disagreement
//! begins (where the effect first acts and chaos has not yet amplified anything), and each
//! later search extends the horizon, starting from the previous optimum.

use std::sync::atomic::{AtomicUsize, Ordering};

use argmin::core::{CostFunction, Error, Executor, State};
use argmin::solver::neldermead::NelderMead;
use rayon::prelude::*;

use super::effects::Effect;
use super::evidence::Evidence;
use super::{Case, Prediction};
use crate::diagnose::memo::Memo;
use crate::diagnose::verdict::Misfit;

/// Grid points a local search starts from.
const STARTS: usize = 4;
const MAX_ITERATIONS: u64 = 60;
/// Fresh simplices per horizon at most.
const RESTARTS: usize = 4;
/// Horizons after the start of the disagreement (s), the last the whole record, each with the
/// half-width of the first local grid (a fraction of the ranges) and how many times it zooms in:
/// coarse while the landscape is smooth, fine once a longer horizon makes it rugged.
const HORIZONS: [(f64, f64, usize); 4] = [(1.5, 0.05, 4), (4.0, 0.01, 3), (10.0, 0.003, 2), (f64::INFINITY, 0.001, 2)];
/// Each zoom shrinks the local grid to this fraction.
const ZOOM: f64 = 0.4;

pub struct Fit {
    pub params: Vec<f64>,
    pub misfit: Misfit,
    pub prediction: Prediction,
    pub evaluations: usize,
}

struct Objective<'a> {
    effect: &'a dyn Effect,
    case: &'a Case,
    evidence: &'a Evidence,
    /// The misfits already computed, by parameters and horizon: a search asks again for points
    /// it has seen (a simplex's start, a zoom's centre), and a run is deterministic.
    seen: Memo<f64>,
}

impl Objective<'_> {
    /// χ² of the records up to `until` under the effect with `params`, from a run cut shortly
    /// after `until` ([`Case::until`]).
    fn chi2(&self, params: &[f64], until: f64) -> f64 {
        self.seen.get_or(params, until, || match self.effect.predict(&self.case.until(until), params) {
            Ok(prediction) => self.evidence.misfit_until(&prediction, until).chi2,
            Err(_) => f64::INFINITY,
        })
    }
}

/// Where a local search moves: the continuous parameters, within their bounds.
struct Space<'a> {
    objective: &'a Objective<'a>,
    bounds: &'a [(f64, f64)],
    continuous: &'a [usize],
}

/// Nelder–Mead's view of a search: the continuous parameters in [0, 1] coordinates of their
/// bounds, judged on the records up to `until`, the others held at `template`'s values.
struct Scaled<'a> {
    space: &'a Space<'a>,
    until: f64,
    template: &'a [f64],
}

impl Scaled<'_> {
    fn params(&self, u: &[f64]) -> Vec<f64> {
        let mut p = self.template.to_vec();
        for (&i, &ui) in self.space.continuous.iter().zip(u) {
            let (lo, hi) = self.space.bounds[i];
            p[i] = lo + ui.clamp(0.0, 1.0) * (hi - lo);
        }
        p
    }

    fn unit(&self) -> Vec<f64> {
        self.space
            .continuous
            .iter()
            .map(|&i| {
                let (lo, hi) = self.space.bounds[i];
                if hi > lo {
                    (self.template[i] - lo) / (hi - lo)
                } else {
                    0.0
                }
            })
            .collect()
    }
}

impl CostFunction for Scaled<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, u: &Vec<f64>) -> Result<f64, Error> {
        // Outside the box: the boundary's misfit plus a penalty that leads back inside.
        let outside: f64 = u.iter().map(|v| (v - v.clamp(0.0, 1.0)).abs()).sum();
        Ok(self.space.objective.chi2(&self.params(u), self.until) * (1.0 + outside))
    }
}

pub fn fit(effect: &dyn Effect, case: &Case, evidence: &Evidence, window: (f64, f64)) -> Fit {
    // Whole-record runs, besides the objective's.
    let evaluations = AtomicUsize::new(0);
    let objective = Objective { effect, case, evidence, seen: Memo::default() };
    let bounds = effect.bounds(case, window);
    let horizons = HORIZONS.map(|(h, span, levels)| (window.0 + h, span, levels));
    let grid = effect.grid(case, window);
    let scored: Vec<(f64, Vec<f64>)> = grid.into_par_iter().map(|p| (objective.chi2(&p, horizons[0].0), p)).collect();
    let mut order: Vec<usize> = (0..scored.len()).collect();
    order.sort_by(|&a, &b| scored[a].0.total_cmp(&scored[b].0).then(a.cmp(&b)));
    let discrete = effect.discrete();
    let continuous: Vec<usize> = (0..bounds.len()).filter(|&i| !discrete.get(i).copied().unwrap_or(false)).collect();
    let space = Space { objective: &objective, bounds: &bounds, continuous: &continuous };
    let starts: Vec<Vec<f64>> = order.iter().take(STARTS).map(|&i| scored[i].1.clone()).collect();
    // Every start leaves its optimum after each horizon: long horizons can trade the exact
    // parameters for a lucky match of chaotic late rocking, so all of them compete at the end.
    let optima: Vec<Vec<f64>> = starts
        .into_par_iter()
        .flat_map_iter(|start| {
            let mut params = start;
            let mut found = vec![params.clone()];
            if !continuous.is_empty() {
                for &(until, span, levels) in &horizons {
                    params = space.zoom(&params, until, span, levels);
                    params = space.search(&params, until, span * ZOOM.powi(levels as i32)).unwrap_or(params);
                    found.push(params.clone());
                }
            }
            found
        })
        .collect();
    // Each distinct optimum once (the first of equals wins a tie either way).
    let optima = optima.into_iter().fold(Vec::new(), |mut distinct: Vec<Vec<f64>>, o| {
        if !distinct.contains(&o) {
            distinct.push(o);
        }
        distinct
    });
    // Judged on the whole record with each prediction's chaotic sensitivity as its uncertainty.
    let judged: Vec<(f64, Vec<f64>, Prediction)> = optima
        .into_par_iter()
        .filter_map(|params| {
            let predict = |c: &Case| {
                evaluations.fetch_add(1, Ordering::Relaxed);
                effect.predict(c, &params)
            };
            let prediction = case.with_sensitivity(evidence, predict(case).ok()?, predict).ok()?;
            Some((evidence.misfit(&prediction).chi2, params, prediction))
        })
        .collect();
    let (_, params, prediction) = judged
        .into_iter()
        .reduce(|a, b| if b.0 < a.0 { b } else { a })
        .unwrap_or_else(|| (f64::INFINITY, scored[order[0]].1.clone(), failed(case)));
    let misfit = evidence.misfit(&prediction);
    Fit { params, misfit, prediction, evaluations: evaluations.into_inner() + objective.seen.runs() }
}

impl Space<'_> {
    /// A local grid around `start` (±`span` of each range, 5 points per parameter, 9 for one),
    /// moved to its best point and shrunk, `levels` times: unlike a simplex, it steps over the
    /// small jumps an impact that happens or not puts into the misfit.
    fn zoom(&self, start: &[f64], until: f64, span: f64, levels: usize) -> Vec<f64> {
        let mut best = (self.objective.chi2(start, until), start.to_vec());
        let per_axis = if self.continuous.len() == 1 { 9 } else { 5 };
        let mut span = span;
        for _ in 0..levels {
            let axes: Vec<Vec<f64>> = self
                .continuous
                .iter()
                .map(|&i| {
                    let (lo, hi) = self.bounds[i];
                    super::effects::linspace(-span, span, per_axis)
                        .into_iter()
                        .map(|d| (best.1[i] + d * (hi - lo)).clamp(lo, hi))
                        .collect()
                })
                .collect();
            let points: Vec<Vec<f64>> = super::effects::product(&axes)
                .into_iter()
                .map(|values| {
                    let mut p = best.1.clone();
                    for (&i, v) in self.continuous.iter().zip(values) {
                        p[i] = v;
                    }
                    p
                })
                .collect();
            let scored: Vec<(f64, Vec<f64>)> =
                points.into_par_iter().map(|p| (self.objective.chi2(&p, until), p)).collect();
            for candidate in scored {
                if candidate.0 < best.0 {
                    best = candidate;
                }
            }
            span *= ZOOM;
        }
        best.1
    }

    /// Nelder–Mead from `start`, restarted with a fresh simplex while it keeps improving: a
    /// simplex that has shrunk inside a narrow curved valley (angle and restitution of an
    /// obstacle trade off) stalls, a new one walks on.
    fn search(&self, start: &[f64], until: f64, step: f64) -> Option<Vec<f64>> {
        let mut best = (self.objective.chi2(start, until), start.to_vec());
        for _ in 0..RESTARTS {
            let Some(found) = self.simplex(&best.1, until, step) else { break };
            if found.0 >= best.0 * (1.0 - 1e-6) {
                break;
            }
            best = found;
        }
        (best.1 != start).then_some(best.1)
    }

    /// One Nelder–Mead run from a simplex of `step` (in [0, 1] coordinates) around `start`.
    fn simplex(&self, start: &[f64], until: f64, step: f64) -> Option<(f64, Vec<f64>)> {
        let problem = Scaled { space: self, until, template: start };
        let u0 = problem.unit();
        let mut simplex = vec![u0.clone()];
        for d in 0..u0.len() {
            let mut vertex = u0.clone();
            vertex[d] = if vertex[d] > 0.5 { vertex[d] - step } else { vertex[d] + step };
            simplex.push(vertex);
        }
        let start_cost = self.objective.chi2(start, until);
        let solver = NelderMead::new(simplex).with_sd_tolerance(1e-6 * start_cost.max(1.0)).ok()?;
        let result = Executor::new(problem, solver).configure(|s| s.max_iters(MAX_ITERATIONS)).run().ok()?;
        let state = result.state();
        let u = state.get_best_param()?.clone();
        let cost = state.get_best_cost();
        (cost <= start_cost).then(|| (cost, Scaled { space: self, until, template: start }.params(&u)))
    }
}

/// What a model that cannot run predicts: nothing (every residual is NaN, never accepted).
fn failed(case: &Case) -> Prediction {
    let n = case.floor_ax_mps2.len();
    Prediction {
        top_ax_mps2: vec![f64::NAN; n],
        theta_rad: vec![f64::NAN; n],
        overturn: None,
        top_ax_uncertainty_mps2: vec![0.0; n],
        theta_uncertainty_rad: vec![0.0; n],
        twin_top_ax_mps2: Vec::new(),
        twin_theta_rad: Vec::new(),
        events: Vec::new(),
    }
}
