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
//!
//! With uncertain nominal parameters the search is joint: their values join the effect's
//! parameters in every local search (the local grids stay over the effect's own), and every
//! objective adds their priors. A physics that acts from the first uplift (a flexible mount)
//! trades off against the block's dimensions, and a physics fitted on fixed dimensions stops in
//! the wrong basin (mis-stated seed 3303 case_01: a 5.37 Hz mount fitted as 4.93 Hz at the
//! damping bound on a block whose centre of mass was stated 0.9 sd high).
//!
//! An effect whose prediction is affine in its parameters (a tilting sensor's mount point) has
//! them solved, not searched: held at the grid's point while the unit's values are searched,
//! then solved over the whole record by one Newton step ([`solve_quadratic`]). Such an effect
//! reads the block's rotation itself, so its joint search grows the horizon in short steps
//! ([`AFFINE_HORIZONS`]).

use std::sync::atomic::{AtomicUsize, Ordering};

use argmin::core::{CostFunction, Error, Executor, State};
use argmin::solver::neldermead::NelderMead;
use rayon::prelude::*;

use super::calibration::{self, Uncertain, UnitModel};
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
/// Horizons after the nominal unit's first uplift (s), as [`HORIZONS`], where a joint search
/// has seen nothing of the uncertain dimensions before it.
const UPLIFT_HORIZONS: [(f64, f64, usize); 2] = [(1.5, 0.01, 3), (4.0, 0.003, 2)];
/// Each zoom shrinks the local grid to this fraction.
const ZOOM: f64 = 0.4;
/// The first simplex's step along an uncertain nominal parameter, in sd.
const JOINT_STEP_SD: f64 = 0.5;
/// An affine effect's horizons after the start of the disagreement (s), besides [`HORIZONS`]:
/// its unit's values are followed along a valley that narrows as the horizon grows, so the
/// horizon grows in small steps (see [`fit`]).
const AFFINE_HORIZONS: [f64; 22] = [
    0.5, 1.0, 2.0, 2.5, 3.0, 3.5, 5.0, 6.0, 7.0, 8.0, 9.0, 11.0, 12.5, 14.0, 16.0, 18.0, 20.0, 23.0, 26.0, 30.0, 35.0,
    40.0,
];
/// The central differences' step of [`solve_quadratic`], as a share of each range (any
/// step is exact on a quadratic; a wide one steps over the rounding of χ²).
const AFFINE_STEP: f64 = 0.05;

pub struct Fit {
    pub params: Vec<f64>,
    /// The uncertain nominal parameters' values fitted with it (the search's `joint` ones, in
    /// their order; empty when there are none).
    pub values: Vec<f64>,
    pub misfit: Misfit,
    pub prediction: Prediction,
    pub evaluations: usize,
}

struct Objective<'a> {
    effect: &'a dyn Effect,
    case: &'a Case,
    evidence: &'a Evidence,
    /// The uncertain nominal parameters searched with the effect's: a point is the effect's
    /// parameters followed by their values.
    joint: &'a [Uncertain],
    /// The misfits already computed, by parameters and horizon: a search asks again for points
    /// it has seen (a simplex's start, a zoom's centre), and a run is deterministic.
    seen: Memo<f64>,
}

impl Objective<'_> {
    /// The effect's parameters of a point, and the case with its nominal values.
    fn split<'p>(&self, point: &'p [f64]) -> Option<(&'p [f64], Case)> {
        let (params, values) = point.split_at(point.len() - self.joint.len());
        Some((params, calibration::with_values(self.case, self.joint, values).ok()?))
    }

    /// The priors' share of a point's objective.
    fn prior(&self, point: &[f64]) -> f64 {
        calibration::prior_chi2(self.joint, &point[point.len() - self.joint.len()..])
    }

    /// χ² of the records up to `until` under the effect at `point`, from a run cut shortly after
    /// `until` ([`Case::until`]), plus the priors of its nominal values.
    fn chi2(&self, point: &[f64], until: f64) -> f64 {
        self.seen.get_or(point, until, || {
            let Some((params, case)) = self.split(point) else { return f64::INFINITY };
            match self.effect.predict(&case.until(until), params) {
                Ok(prediction) => self.evidence.misfit_until(&prediction, until).chi2 + self.prior(point),
                Err(_) => f64::INFINITY,
            }
        })
    }
}

/// Where a local search moves: the continuous parameters, within their bounds; a local grid
/// covers the effect's own (`zoomed`), a simplex all of them, starting `steps` apart (in [0, 1]
/// coordinates; 0: the search's step).
struct Space<'a> {
    objective: &'a Objective<'a>,
    bounds: &'a [(f64, f64)],
    continuous: &'a [usize],
    zoomed: &'a [usize],
    steps: &'a [f64],
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

/// The effect's parameters fitted on `case` from the records around `window`, jointly with the
/// `joint` nominal parameters (from `case`'s values, with their priors; none: the case as it is).
pub fn fit(effect: &dyn Effect, case: &Case, evidence: &Evidence, window: (f64, f64), joint: &[Uncertain]) -> Fit {
    // Whole-record runs, besides the objective's.
    let evaluations = AtomicUsize::new(0);
    let objective = Objective { effect, case, evidence, joint, seen: Memo::default() };
    let k = effect.parameter_names().len();
    let start: Vec<f64> =
        joint.iter().map(|p| case.parameter(&p.key, p.index.unwrap_or(0)).unwrap_or(p.stated)).collect();
    let mut bounds = effect.bounds(case, window);
    bounds.extend(joint.iter().map(|p| p.bounds));
    let mut horizons: Vec<(f64, f64, usize)> = HORIZONS.map(|(h, span, levels)| (window.0 + h, span, levels)).to_vec();
    // The block's dimensions show only once it rocks: a physics seen long before the first
    // uplift (a flexible mount) is searched with them from there too.
    if let Some(uplift) = case.first_uplift().filter(|u| !joint.is_empty() && *u > window.0 + HORIZONS[0].0) {
        horizons.extend(UPLIFT_HORIZONS.map(|(h, span, levels)| (uplift + h, span, levels)));
    }
    // An affine effect reads the block's rotation itself (a tilting sensor reads g sin θ), so
    // the records pin the unit's critical angle and frequency to a valley that a few more
    // seconds of rocking make far narrower: from the optimum of 1.5 s, the next horizon's
    // misfit is flat around it and the search is lost (mis-stated seed 3303 case_08: H 0.01 m,
    // 0.55 sd, off the truth costs 1000 times the misfit 0.5 s after the first uplift, and a
    // point in the valley at 1.5 s costs 330 times the truth's at 4 s). Its horizon grows in
    // steps short enough for each search to start inside the next valley.
    if effect.affine() && !joint.is_empty() {
        let end = case.t0_s + case.duration_s();
        horizons.extend(AFFINE_HORIZONS.iter().map(|h| (window.0 + h, 0.0, 0)).filter(|h| h.0 < end));
    }
    horizons.sort_by(|a, b| a.0.total_cmp(&b.0));
    let grid: Vec<Vec<f64>> = effect.grid(case, window).into_iter().map(|p| [p, start.clone()].concat()).collect();
    let scored: Vec<(f64, Vec<f64>)> = grid.into_par_iter().map(|p| (objective.chi2(&p, horizons[0].0), p)).collect();
    let mut order: Vec<usize> = (0..scored.len()).collect();
    order.sort_by(|&a, &b| scored[a].0.total_cmp(&scored[b].0).then(a.cmp(&b)));
    let free = free_parameters(effect);
    // An affine effect's own parameters stay at the grid's point while the unit's values are
    // searched, and are solved over the whole record. Searched with the values, or solved over a
    // short horizon, where a few rocking cycles hardly constrain them, they stand in for the
    // values and lead the search astray (fresh seed 3305 case_09: a sensor at the top centre
    // fitted at the base's corner, on a block 0.6–3 sd too short).
    let zoomed: Vec<usize> = if effect.affine() { Vec::new() } else { free.clone() };
    let continuous: Vec<usize> = zoomed.iter().copied().chain(k..k + joint.len()).collect();
    let steps: Vec<f64> = (0..k)
        .map(|_| 0.0)
        .chain(joint.iter().map(|p| JOINT_STEP_SD * p.sd / (p.bounds.1 - p.bounds.0).max(f64::MIN_POSITIVE)))
        .collect();
    let space =
        Space { objective: &objective, bounds: &bounds, continuous: &continuous, zoomed: &zoomed, steps: &steps };
    // Over the whole record the nominal values stay where the shorter horizons left them: each
    // of its runs is the longest, and the recalibration with the physics in place fits them there.
    let own = Space { continuous: &zoomed, ..space };
    let starts: Vec<Vec<f64>> = order.iter().take(STARTS).map(|&i| scored[i].1.clone()).collect();
    // Every start leaves its optimum after each horizon: long horizons can trade the exact
    // parameters for a lucky match of chaotic late rocking, so all of them compete at the end.
    let optima: Vec<Vec<f64>> = starts
        .into_par_iter()
        .flat_map_iter(|start| {
            let mut params = start;
            let mut found = vec![params.clone()];
            if continuous.is_empty() && !effect.affine() {
                return found;
            }
            for &(until, span, levels) in &horizons {
                let space = if until.is_finite() { &space } else { &own };
                if !space.continuous.is_empty() {
                    params = space.zoom(&params, until, span, levels);
                    params = space.search(&params, until, span * ZOOM.powi(levels as i32)).unwrap_or(params);
                }
                if effect.affine() && !until.is_finite() {
                    params = solve_quadratic(&params, &free, &bounds, |p| objective.chi2(p, until));
                }
                found.push(params.clone());
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
        .filter_map(|point| {
            let (params, unit) = objective.split(&point)?;
            let predict = |c: &Case| {
                evaluations.fetch_add(1, Ordering::Relaxed);
                effect.predict(c, params)
            };
            let prediction = unit.with_sensitivity(evidence, predict(&unit).ok()?, predict).ok()?;
            Some((evidence.misfit(&prediction).chi2 + objective.prior(&point), point, prediction))
        })
        .collect();
    let (_, point, prediction) = judged
        .into_iter()
        .reduce(|a, b| if b.0 < a.0 { b } else { a })
        .unwrap_or_else(|| (f64::INFINITY, scored[order[0]].1.clone(), failed(case)));
    let misfit = evidence.misfit(&prediction);
    let (params, values) = point.split_at(k);
    Fit {
        params: params.to_vec(),
        values: values.to_vec(),
        misfit,
        prediction,
        evaluations: evaluations.into_inner() + objective.seen.runs(),
    }
}

/// The parameters of an effect whose prediction is affine in them ([`Effect::affine`]) solved
/// on `case` over the whole record, from `params`: after the unit's values were fitted again
/// with them fixed, where they are best has moved a little.
pub fn solve_affine(
    effect: &dyn Effect,
    case: &Case,
    evidence: &Evidence,
    window: (f64, f64),
    params: &[f64],
) -> Vec<f64> {
    let chi2 =
        |p: &[f64]| effect.predict(case, p).map_or(f64::INFINITY, |prediction| evidence.misfit(&prediction).chi2);
    solve_quadratic(params, &free_parameters(effect), &effect.bounds(case, window), chi2)
}

/// The indices of the effect's parameters that are not discrete.
fn free_parameters(effect: &dyn Effect) -> Vec<usize> {
    let discrete = effect.discrete();
    (0..effect.parameter_names().len()).filter(|&i| !discrete.get(i).copied().unwrap_or(false)).collect()
}

/// Where `chi2`, (nearly) quadratic along `axes` of the point, is least, from `start`: one Newton step
/// from central differences. A simplex only nears the minimum of a narrow valley (a tilting
/// sensor's mount point once the block rocks hard: mis-stated seed 3301 case_04, misfit 6.5
/// where the minimum holds 1.0). Kept within `bounds`, and only where it lowers χ² (a mask the
/// prediction moves breaks the quadratic).
fn solve_quadratic(start: &[f64], axes: &[usize], bounds: &[(f64, f64)], chi2: impl Fn(&[f64]) -> f64) -> Vec<f64> {
    let f0 = chi2(start);
    let step: Vec<f64> = axes.iter().map(|&i| AFFINE_STEP * (bounds[i].1 - bounds[i].0)).collect();
    let at = |moves: &[(usize, f64)]| {
        let mut p = start.to_vec();
        for &(a, by) in moves {
            p[axes[a]] += by * step[a];
        }
        chi2(&p)
    };
    let n = axes.len();
    let plus: Vec<f64> = (0..n).map(|a| at(&[(a, 1.0)])).collect();
    let minus: Vec<f64> = (0..n).map(|a| at(&[(a, -1.0)])).collect();
    // Gradient and Hessian in steps (the step of each axis as its unit).
    let gradient: Vec<f64> = (0..n).map(|a| (plus[a] - minus[a]) / 2.0).collect();
    let mut hessian = vec![vec![0.0; n]; n];
    for a in 0..n {
        hessian[a][a] = plus[a] - 2.0 * f0 + minus[a];
        for b in 0..a {
            let cross = at(&[(a, 1.0), (b, 1.0)]) - plus[a] - plus[b] + f0;
            (hessian[a][b], hessian[b][a]) = (cross, cross);
        }
    }
    let Some(newton) = solve(hessian, gradient.iter().map(|g| -g).collect()) else { return start.to_vec() };
    let mut solved = start.to_vec();
    for (a, &i) in axes.iter().enumerate() {
        let (lo, hi) = bounds[i];
        solved[i] = (start[i] + newton[a] * step[a]).clamp(lo, hi);
    }
    if solved.iter().all(|v| v.is_finite()) && chi2(&solved) < f0 {
        solved
    } else {
        start.to_vec()
    }
}

impl Space<'_> {
    /// A local grid around `start` (±`span` of each range, 5 points per parameter, 9 for one),
    /// moved to its best point and shrunk, `levels` times: unlike a simplex, it steps over the
    /// small jumps an impact that happens or not puts into the misfit.
    fn zoom(&self, start: &[f64], until: f64, span: f64, levels: usize) -> Vec<f64> {
        let mut best = (self.objective.chi2(start, until), start.to_vec());
        let per_axis = if self.zoomed.len() == 1 { 9 } else { 5 };
        let mut span = span;
        for _ in 0..levels {
            let axes: Vec<Vec<f64>> = self
                .zoomed
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
                    for (&i, v) in self.zoomed.iter().zip(values) {
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
        for (d, &i) in self.continuous.iter().enumerate() {
            let step = step.max(self.steps[i]);
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

/// `m x = v` for a symmetric `m` by Gaussian elimination without row exchanges; None unless
/// `m` is positive definite (every pivot positive), so that the quadratic it stands for has a
/// minimum, not a saddle.
fn solve(mut m: Vec<Vec<f64>>, mut v: Vec<f64>) -> Option<Vec<f64>> {
    let n = v.len();
    for col in 0..n {
        if m[col][col] <= 0.0 || !m[col][col].is_finite() {
            return None;
        }
        let pivot_row = m[col].clone();
        for row in col + 1..n {
            let factor = m[row][col] / pivot_row[col];
            for (x, p) in m[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= factor * p;
            }
            v[row] -= factor * v[col];
        }
    }
    let mut x = vec![0.0; n];
    for row in (0..n).rev() {
        let tail: f64 = (row + 1..n).map(|c| m[row][c] * x[c]).sum();
        x[row] = (v[row] - tail) / m[row][row];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::calibration::{uncertain_parameters, Spread};
    use crate::diagnose::effects;
    use crate::diagnose::{nominal_evidence, tests::rocking_case, Observed, Settings};
    use crate::physics::rocking::{Block, Shape};

    /// Records of a block on a 3 Hz mount (5 % damping) whose centre of mass lies 6 cm above
    /// what its equipment file states (f 0.04 against a stated 0.0, sd 0.03): noise-free top
    /// accelerometer and camera.
    fn flexibility() -> &'static dyn Effect {
        effects::named("flexibility").unwrap()
    }

    fn mounted_block_stated_low() -> (Case, Vec<f64>) {
        let truth = [3.0, 0.05];
        let mut case = rocking_case();
        let stated_block = case.block;
        case.block = Block::new(Shape::Rectangular { b_m: 0.5, h_m: 1.5, f: 0.04 }, 100.0, 9.81).unwrap();
        let observed = flexibility().predict(&case, &truth).unwrap();
        assert!(observed.overturn.is_none() && observed.theta_rad.iter().any(|t| t.abs() > 0.02), "it rocks, standing");
        let time_s = case.time_s();
        case.accel = Some(Observed { time_s: time_s.clone(), value: observed.top_ax_mps2 });
        case.camera = Some(Observed { time_s, value: observed.theta_rad });
        case.block = stated_block;
        let block = [("f".to_string(), Spread { sd: Some(0.03), rel_sd: None })];
        case.uncertain = uncertain_parameters(&case, &block).unwrap();
        (case, truth.to_vec())
    }

    #[test]
    fn a_tilting_sensor_s_mount_point_is_solved_in_one_step_and_found_by_the_fit() {
        let tilt = effects::named("sensor_tilt").unwrap();
        let truth = [0.1, 0.3];
        let mut case = rocking_case();
        let observed = tilt.predict(&case, &truth).unwrap();
        let time_s = case.time_s();
        case.accel = Some(Observed { time_s: time_s.clone(), value: observed.top_ax_mps2 });
        case.camera = Some(Observed { time_s, value: observed.theta_rad });
        let (evidence, nominal) = nominal_evidence(&case, &Settings::default()).unwrap();
        let window = evidence.window(&nominal).expect("the tilted sensor leaves the nominal model");
        // From the top centre the equipment file assumes, one step lands on the mount point.
        let solved = solve_affine(tilt, &case, &evidence, window, &[0.0, 0.0]);
        assert!(solved.iter().zip(&truth).all(|(s, t)| (s - t).abs() < 1e-6), "{solved:?} against {truth:?}");
        let fitted = fit(tilt, &case, &evidence, window, &[]);
        assert!(fitted.params.iter().zip(&truth).all(|(s, t)| (s - t).abs() < 1e-6), "{:?}", fitted.params);
    }

    #[test]
    fn a_tilting_sensor_on_a_block_stated_off_is_followed_to_the_block_s_dimensions() {
        let tilt = effects::named("sensor_tilt").unwrap();
        let mut case = rocking_case();
        // A decaying shake that rocks the block hard (θ up to 0.27 rad) without toppling it.
        let dt = case.dt_s;
        case.floor_ax_mps2 = (0..case.floor_ax_mps2.len())
            .map(|k| {
                let t = k as f64 * dt;
                4.5 * (2.0 * std::f64::consts::PI * 1.2 * t).sin() * (-0.1 * t).exp()
                    + 1.5 * (2.0 * std::f64::consts::PI * 2.9 * t).sin()
            })
            .collect();
        let observed = tilt.predict(&case, &[0.0, 0.0]).unwrap();
        assert!(observed.overturn.is_none(), "it stands");
        let time_s = case.time_s();
        case.accel = Some(Observed { time_s, value: observed.top_ax_mps2 });
        // The accelerometer only, its sensor at the top centre; the block stated 1 sd too
        // short, its centre of mass 0.7 sd low and its base 1.4 sd wide (mis-stated seed 3303
        // case_08's misstatement). Grown from 1.5 s to 4 s and 10 s, the search ends 1.4 sd
        // and 2.2 sd off in the base and the height.
        case.block =
            Block::new(Shape::Rectangular { b_m: 0.5 * 1.014, h_m: 1.5 * 0.99, f: -0.021 }, 100.0, 9.81).unwrap();
        let block = [
            ("B_m".to_string(), Spread { sd: None, rel_sd: Some(0.01) }),
            ("H_m".to_string(), Spread { sd: None, rel_sd: Some(0.01) }),
            ("f".to_string(), Spread { sd: Some(0.03), rel_sd: None }),
        ];
        case.uncertain = uncertain_parameters(&case, &block).unwrap();
        let (evidence, nominal) = nominal_evidence(&case, &Settings::default()).unwrap();
        let window = evidence.window(&nominal).expect("the tilted sensor leaves the nominal model");
        let fitted = fit(tilt, &case, &evidence, window, &case.uncertain);
        let truth = |key: &str| match key {
            "B_m" => 0.5,
            "H_m" => 1.5,
            _ => 0.0,
        };
        let off: Vec<f64> =
            case.uncertain.iter().zip(&fitted.values).map(|(p, v)| (v - truth(&p.key)) / p.sd).collect();
        assert!(off.iter().all(|z| z.abs() < 0.1), "{:?} is {off:?} sd from the truth", fitted.values);
        assert!(fitted.misfit.chi2 < 2.0 * fitted.misfit.samples as f64, "{:?}", fitted.misfit);
    }

    #[test]
    fn a_newton_step_is_taken_to_a_minimum_only() {
        let x = solve(vec![vec![4.0, 1.0], vec![1.0, 3.0]], vec![1.0, 2.0]).unwrap();
        assert!((4.0 * x[0] + x[1] - 1.0).abs() < 1e-12 && (x[0] + 3.0 * x[1] - 2.0).abs() < 1e-12, "{x:?}");
        // Positive curvature along each axis, a saddle across them: no minimum.
        assert!(solve(vec![vec![1.0, 2.0], vec![2.0, 1.0]], vec![1.0, 0.0]).is_none());
    }

    #[test]
    fn a_physics_searched_with_the_uncertain_dimensions_finds_both() {
        let (case, truth) = mounted_block_stated_low();
        let (evidence, nominal) = nominal_evidence(&case, &Settings::default()).unwrap();
        let window = evidence.window(&nominal).expect("the records leave the stated rigid block");
        let fixed = fit(flexibility(), &case, &evidence, window, &[]);
        let joint = fit(flexibility(), &case, &evidence, window, &case.uncertain);
        assert!(fixed.values.is_empty() && joint.values.len() == 1);
        let off = |fit: &Fit| (fit.params[0] / truth[0] - 1.0).abs();
        assert!(off(&joint) < 0.01, "joint: {:?} against {truth:?}", joint.params);
        assert!((joint.values[0] - 0.04).abs() < 0.3 * 0.03, "f fitted {} against 0.04", joint.values[0]);
        // On the stated block the mount is fitted to what it cannot explain.
        assert!(
            joint.misfit.chi2 * 10.0 < fixed.misfit.chi2,
            "joint χ² {} against {} with the stated block ({:?})",
            joint.misfit.chi2,
            fixed.misfit.chi2,
            fixed.params
        );
    }
}
