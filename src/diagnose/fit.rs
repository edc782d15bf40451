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
use super::evidence::{Evidence, Misfit};
use super::{Case, Prediction};

/// Grid points a local search starts from.
const STARTS: usize = 4;
const MAX_ITERATIONS: u64 = 60;
/// Horizons after the start of the disagreement (s), the last the whole record, each with the
/// size of the first simplex (a fraction of the ranges): coarse while the landscape is smooth,
/// fine once a longer horizon makes it rugged.
const HORIZONS: [(f64, f64); 4] = [(1.5, 0.04), (4.0, 0.008), (10.0, 0.002), (f64::INFINITY, 0.0005)];

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
    evaluations: &'a AtomicUsize,
}

impl Objective<'_> {
    fn chi2(&self, params: &[f64], until: f64) -> f64 {
        self.evaluations.fetch_add(1, Ordering::Relaxed);
        match self.effect.predict(self.case, params) {
            Ok(prediction) => self.evidence.misfit_until(&prediction, until).chi2,
            Err(_) => f64::INFINITY,
        }
    }
}

/// Nelder–Mead over the continuous parameters, in [0, 1] coordinates of their bounds.
struct Scaled<'a> {
    objective: &'a Objective<'a>,
    until: f64,
    bounds: &'a [(f64, f64)],
    /// The full parameter vector; the continuous entries are replaced from the search point.
    template: &'a [f64],
    continuous: &'a [usize],
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
        // Outside the box: the boundary's misfit plus a penalty that leads back inside.
        let outside: f64 = u.iter().map(|v| (v - v.clamp(0.0, 1.0)).abs()).sum();
        Ok(self.objective.chi2(&self.params(u), self.until) * (1.0 + outside))
    }
}

pub fn fit(effect: &dyn Effect, case: &Case, evidence: &Evidence, window: (f64, f64)) -> Fit {
    let evaluations = AtomicUsize::new(0);
    let objective = Objective { effect, case, evidence, evaluations: &evaluations };
    let bounds = effect.bounds(case, window);
    let horizons = HORIZONS.map(|(h, step)| (window.0 + h, step));
    let grid = effect.grid(case, window);
    let scored: Vec<(f64, Vec<f64>)> = grid.into_par_iter().map(|p| (objective.chi2(&p, horizons[0].0), p)).collect();
    let mut order: Vec<usize> = (0..scored.len()).collect();
    order.sort_by(|&a, &b| scored[a].0.total_cmp(&scored[b].0).then(a.cmp(&b)));
    let discrete = effect.discrete();
    let continuous: Vec<usize> = (0..bounds.len()).filter(|&i| !discrete.get(i).copied().unwrap_or(false)).collect();
    let starts: Vec<Vec<f64>> = order.iter().take(STARTS).map(|&i| scored[i].1.clone()).collect();
    // Every start leaves its optimum after each horizon: long horizons can trade the exact
    // parameters for a lucky match of chaotic late rocking, so all of them compete at the end.
    let optima: Vec<Vec<f64>> = starts
        .into_par_iter()
        .flat_map_iter(|start| {
            let mut params = start;
            let mut found = vec![params.clone()];
            if !continuous.is_empty() {
                for &(until, step) in &horizons {
                    params = search(&objective, &bounds, &continuous, &params, until, step).unwrap_or(params);
                    found.push(params.clone());
                }
            }
            found
        })
        .collect();
    // Judged on the whole record with each prediction's chaotic sensitivity as its uncertainty.
    let judged: Vec<(f64, Vec<f64>, Prediction)> = optima
        .into_par_iter()
        .filter_map(|params| {
            evaluations.fetch_add(2, Ordering::Relaxed);
            let prediction = case.with_sensitivity(|c| effect.predict(c, &params)).ok()?;
            Some((evidence.misfit(&prediction).chi2, params, prediction))
        })
        .collect();
    let (_, params, prediction) = judged
        .into_iter()
        .reduce(|a, b| if b.0 < a.0 { b } else { a })
        .unwrap_or_else(|| (f64::INFINITY, scored[order[0]].1.clone(), failed(case)));
    let misfit = evidence.misfit(&prediction);
    Fit { params, misfit, prediction, evaluations: evaluations.into_inner() }
}

/// Nelder–Mead from `start` over the continuous parameters, judged on the records up to `until`.
fn search(
    objective: &Objective<'_>,
    bounds: &[(f64, f64)],
    continuous: &[usize],
    start: &[f64],
    until: f64,
    step: f64,
) -> Option<Vec<f64>> {
    let problem = Scaled { objective, until, bounds, template: start, continuous };
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
        let mut vertex = u0.clone();
        vertex[d] = if vertex[d] > 0.5 { vertex[d] - step } else { vertex[d] + step };
        simplex.push(vertex);
    }
    let start_cost = objective.chi2(start, until);
    let solver = NelderMead::new(simplex).with_sd_tolerance(1e-6 * start_cost.max(1.0)).ok()?;
    let result = Executor::new(problem, solver).configure(|s| s.max_iters(MAX_ITERATIONS)).run().ok()?;
    let state = result.state();
    let u = state.get_best_param()?.clone();
    (state.get_best_cost() <= start_cost)
        .then(|| Scaled { objective, until, bounds, template: start, continuous }.params(&u))
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
    }
}
