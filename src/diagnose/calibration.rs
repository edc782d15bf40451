//! Calibration of the nominal parameters a user knows only roughly, for any unit model.
//!
//! An equipment file's `uncertainty` block gives one standard deviation of each stated value's
//! error (`{sd: X}` absolute, each element of a list; `{rel_sd: X}` relative to the stated
//! value). Before a mismatch is judged, those parameters are fitted to the records with
//! Gaussian priors of that sd centred on the stated values, bounded to ±[`BOUND_SD`] sd (and
//! to what the model can take): the objective is χ²(records) + Σ ((v − stated)/sd)², the
//! negative double log-posterior. A physics is then fitted on top of the calibrated unit and the
//! uncertain parameters recalibrated with it, so a physics is named only for what no calibration
//! within the stated uncertainty explains.
//!
//! Generic over the unit model ([`UnitModel`]: the rocking block and the rolling cart name their
//! parameters by the equipment file's keys); the model's simulation and its misfit come in as a
//! closure. Pure numerics.

use argmin::core::{CostFunction, Error, Executor, State};
use argmin::solver::neldermead::NelderMead;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::error::{ParameterError, SpreadError};
use super::memo::Memo;

/// Calibrated values are kept within this many sd of the stated value.
pub const BOUND_SD: f64 = 5.0;
/// A fitted value farther than this many sd from the stated one is a finding (`within: false`).
pub const WITHIN_SD: f64 = 3.0;
/// Nelder–Mead iterations per horizon.
const MAX_ITERATIONS: u64 = 80;
/// Grid points a local search starts from.
const STARTS: usize = 3;
/// Fresh simplices per horizon at most.
const RESTARTS: usize = 3;
/// Starts whose optima after a horizon lie within this many sd of each other (every parameter)
/// go on as one.
const MERGE_SD: f64 = 0.1;

/// One standard deviation of a stated value's error, as the `uncertainty` block gives it:
/// exactly one of `sd` (absolute, in the key's unit) and `rel_sd` (relative to the stated value).
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Spread {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sd: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rel_sd: Option<f64>,
}

impl Spread {
    /// Why the spread is not usable, if it is not.
    pub fn check(&self) -> Result<(), SpreadError> {
        match (self.sd, self.rel_sd) {
            (Some(v), None) | (None, Some(v)) if v.is_finite() && v > 0.0 => Ok(()),
            (Some(_), None) | (None, Some(_)) => Err(SpreadError::NotPositive),
            (Some(_), Some(_)) => Err(SpreadError::Both),
            (None, None) => Err(SpreadError::Neither),
        }
    }

    /// The standard deviation of a stated value (absolute).
    pub fn sd_of(&self, stated: f64) -> f64 {
        match (self.sd, self.rel_sd) {
            (Some(sd), _) => sd,
            (None, Some(rel)) => rel * stated.abs(),
            (None, None) => 0.0,
        }
    }
}

/// A unit model whose nominal parameters are read and set by their equipment-file keys.
pub trait UnitModel: Clone + Sync {
    /// The nominal parameters an `uncertainty` block may name, with their number of elements
    /// (4 for `steer0_deg`, else 1).
    fn nominal_keys(&self) -> Vec<(&'static str, usize)>;
    /// The stated value of one element of a key.
    fn parameter(&self, key: &str, index: usize) -> Option<f64>;
    /// The same unit with one element of a key set to `value`, or why the model cannot take it.
    fn set_parameter(&mut self, key: &str, index: usize, value: f64) -> Result<(), ParameterError>;
    /// The values the model can take at all (a length is positive, a friction coefficient too).
    fn physical_range(&self, key: &str) -> (f64, f64);
    /// Whether the model's predictions depend on the key at all (a rocking block's mass does
    /// not): a key they do not depend on keeps its stated value, and the report says why.
    fn constrains(&self, _key: &str) -> bool {
        true
    }
}

/// One element of a nominal parameter treated as uncertain.
#[derive(Debug, Clone, PartialEq)]
pub struct Uncertain {
    pub key: String,
    /// The element of a list (`steer0_deg`); None for a scalar.
    pub index: Option<usize>,
    pub stated: f64,
    pub sd: f64,
    /// Where calibration may move it: ±[`BOUND_SD`] sd within the model's physical range.
    pub bounds: (f64, f64),
}

impl Uncertain {
    /// `H_m`, `steer0_deg[2]`.
    pub fn label(&self) -> String {
        match self.index {
            Some(i) => format!("{}[{i}]", self.key),
            None => self.key.clone(),
        }
    }

    /// How many sd `value` lies from the stated value.
    pub fn z(&self, value: f64) -> f64 {
        (value - self.stated) / self.sd
    }
}

/// The uncertain parameters of `model` that `block` names (key, spread), in the block's order;
/// an error names a key that is not one of the model's nominal parameters.
pub fn uncertain_parameters<M: UnitModel>(
    model: &M,
    block: &[(String, Spread)],
) -> Result<Vec<Uncertain>, ParameterError> {
    let keys = model.nominal_keys();
    let mut out = Vec::new();
    for (key, spread) in block {
        let Some(&(name, count)) = keys.iter().find(|(k, _)| *k == key.as_str()) else {
            let known: Vec<&str> = keys.iter().map(|k| k.0).collect();
            return Err(ParameterError::NotNominal { key: key.clone(), known: known.join(", ") });
        };
        spread.check().map_err(|spread| ParameterError::Spread { key: key.clone(), spread })?;
        let (lo, hi) = model.physical_range(name);
        for i in 0..count {
            let stated = model.parameter(name, i).ok_or_else(|| ParameterError::NoStatedValue { key: key.clone() })?;
            let sd = spread.sd_of(stated);
            if !(sd.is_finite() && sd > 0.0) {
                return Err(ParameterError::RelativeOfZero { key: key.clone() });
            }
            let bounds = ((stated - BOUND_SD * sd).max(lo), (stated + BOUND_SD * sd).min(hi));
            out.push(Uncertain { key: name.to_string(), index: (count > 1).then_some(i), stated, sd, bounds });
        }
    }
    Ok(out)
}

/// `model` with the uncertain parameters set to `values`.
pub fn with_values<M: UnitModel>(model: &M, parameters: &[Uncertain], values: &[f64]) -> Result<M, ParameterError> {
    let mut m = model.clone();
    for (p, &v) in parameters.iter().zip(values) {
        m.set_parameter(&p.key, p.index.unwrap_or(0), v)?;
    }
    Ok(m)
}

/// The standard deviation the uncertain `parameters` give `value(model)`: each moved by its sd,
/// central differences (one-sided where a step leaves what the model can take) summed in
/// quadrature. None when nothing uncertain moves it (or the model takes no step).
pub fn propagated_sd<M: UnitModel>(
    model: &M,
    parameters: &[Uncertain],
    value: impl Fn(&M) -> Option<f64>,
) -> Option<f64> {
    let here = value(model)?;
    let variance: f64 = parameters
        .iter()
        .filter(|p| model.constrains(&p.key))
        .filter_map(|p| {
            let v = model.parameter(&p.key, p.index.unwrap_or(0))?;
            let at = |v: f64| value(&with_values(model, std::slice::from_ref(p), &[v]).ok()?);
            let change = match (at(v + p.sd), at(v - p.sd)) {
                (Some(up), Some(down)) => (up - down) / 2.0,
                (Some(up), None) => up - here,
                (None, Some(down)) => here - down,
                (None, None) => return None,
            };
            Some(change * change)
        })
        .sum();
    (variance > 0.0).then(|| variance.sqrt())
}

/// The priors' share of −2 log-posterior: Σ ((v − stated)/sd)².
pub fn prior_chi2(parameters: &[Uncertain], values: &[f64]) -> f64 {
    parameters.iter().zip(values).map(|(p, &v)| p.z(v).powi(2)).sum()
}

/// The result of a calibration: the uncertain parameters and their fitted values.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Calibration {
    pub parameters: Vec<Uncertain>,
    pub fitted: Vec<f64>,
    /// Model runs it spent.
    pub evaluations: usize,
    /// The best values after each horizon (horizon in s, values as `fitted`), shortest first:
    /// what the records up to each horizon alone say.
    pub steps: Vec<(f64, Vec<f64>)>,
}

/// One key of the `calibration` contract: scalars, or lists element-wise.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Entry {
    Scalar { stated: f64, fitted: f64, sd: f64, within: bool },
    List { stated: Vec<f64>, fitted: Vec<f64>, sd: Vec<f64>, within: Vec<bool> },
}

impl Calibration {
    /// Nothing calibrated: the stated values.
    pub fn stated(parameters: Vec<Uncertain>) -> Calibration {
        let fitted = parameters.iter().map(|p| p.stated).collect();
        Calibration { parameters, fitted, evaluations: 0, steps: Vec::new() }
    }

    pub fn is_empty(&self) -> bool {
        self.parameters.is_empty()
    }

    pub fn prior_chi2(&self) -> f64 {
        prior_chi2(&self.parameters, &self.fitted)
    }

    /// `model` with the fitted values.
    pub fn apply<M: UnitModel>(&self, model: &M) -> Result<M, ParameterError> {
        with_values(model, &self.parameters, &self.fitted)
    }

    /// The contract's `calibration`: per key `{stated, fitted, sd, within}` (lists element-wise),
    /// in the order the block names them.
    pub fn entries(&self) -> Vec<(String, Entry)> {
        let mut out: Vec<(String, Entry)> = Vec::new();
        for (p, &v) in self.parameters.iter().zip(&self.fitted) {
            let within = p.z(v).abs() <= WITHIN_SD;
            match (p.index, out.last_mut()) {
                (Some(i), Some((key, Entry::List { stated, fitted, sd, within: w }))) if i > 0 && *key == p.key => {
                    stated.push(p.stated);
                    fitted.push(v);
                    sd.push(p.sd);
                    w.push(within);
                }
                (Some(_), _) => out.push((
                    p.key.clone(),
                    Entry::List { stated: vec![p.stated], fitted: vec![v], sd: vec![p.sd], within: vec![within] },
                )),
                (None, _) => out.push((p.key.clone(), Entry::Scalar { stated: p.stated, fitted: v, sd: p.sd, within })),
            }
        }
        out
    }

    /// The parameters that had to move beyond [`WITHIN_SD`] sd: (label, stated, fitted, z).
    pub fn beyond(&self) -> Vec<(String, f64, f64, f64)> {
        self.parameters
            .iter()
            .zip(&self.fitted)
            .filter(|(p, v)| p.z(**v).abs() > WITHIN_SD)
            .map(|(p, &v)| (p.label(), p.stated, v, p.z(v)))
            .collect()
    }

    /// What calibration did, for the explanation (empty without uncertain parameters): the
    /// fitted values beside the stated ones (`alone`: and that they explain the records), and
    /// each value that had to move beyond [`WITHIN_SD`] sd, a finding: the stated value is
    /// wrong, or the model lacks something that value stands in for.
    pub fn note(&self, alone: bool) -> String {
        if self.is_empty() {
            return String::new();
        }
        let mut text = format!(
            " Calibrated within the stated uncertainty first (priors of the stated sd): {}{}.",
            self.describe(),
            if alone { "; calibration alone explains the records" } else { "" }
        );
        for (label, stated, fitted, z) in self.beyond() {
            text.push_str(&format!(
                " {label} had to move {:.1} sd from its stated {} (to {}), beyond the {WITHIN_SD} sd the stated uncertainty allows: check that value, or what it stands in for.",
                z.abs(),
                short(stated),
                short(fitted),
            ));
        }
        text
    }

    /// "H_m 1.096 → 1.083 (−1.2 sd), f 0.059 → 0.082 (+0.8 sd)".
    pub fn describe(&self) -> String {
        self.parameters
            .iter()
            .zip(&self.fitted)
            .map(|(p, &v)| format!("{} {} → {} ({:+.1} sd)", p.label(), short(p.stated), short(v), p.z(v)))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// A value with four significant digits.
fn short(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (3 - v.abs().log10().floor() as i32).max(0) as usize;
    format!("{v:.digits$}")
}

/// The objective of a calibration: χ² of the records up to a horizon (s) for trial values.
pub type Objective<'a> = dyn Fn(&[f64], f64) -> f64 + Sync + 'a;

/// Fits `parameters` from their stated values: minimises `chi2(values, horizon)` plus the
/// priors over each horizon in turn (a growing horizon keeps a chaotic model's landscape smooth
/// while the parameters are still rough), the last the whole record. `start` (None: the stated
/// values) is where the search begins; with `explore` a coarse grid over ±2 sd picks the starts.
pub fn calibrate(
    parameters: &[Uncertain],
    start: Option<&[f64]>,
    horizons: &[f64],
    explore: bool,
    chi2: &Objective<'_>,
) -> Calibration {
    let seen = Memo::default();
    let dim = parameters.len();
    if dim == 0 {
        return Calibration::default();
    }
    // The search runs in z = (v − stated)/sd, clamped to the bounds.
    let to_values = |z: &[f64]| -> Vec<f64> {
        parameters.iter().zip(z).map(|(p, &z)| (p.stated + z * p.sd).clamp(p.bounds.0, p.bounds.1)).collect()
    };
    let posterior = |z: &[f64], until: f64| -> f64 {
        seen.get_or(z, until, || {
            let values = to_values(z);
            let outside: f64 = parameters.iter().zip(z).zip(&values).map(|((p, &z), &v)| (z - p.z(v)).abs()).sum();
            let c = chi2(&values, until);
            if c.is_finite() {
                c + prior_chi2(parameters, &values) + outside * outside * 100.0
            } else {
                f64::INFINITY
            }
        })
    };
    let first = *horizons.first().unwrap_or(&f64::INFINITY);
    let initial: Vec<f64> = start.map_or(vec![0.0; dim], |s| parameters.iter().zip(s).map(|(p, &v)| p.z(v)).collect());
    let mut starts = vec![initial.clone()];
    if explore {
        let grid = coarse_grid(dim, &initial);
        let mut scored: Vec<(f64, Vec<f64>)> = grid.into_par_iter().map(|z| (posterior(&z, first), z)).collect();
        scored.sort_by(|a, b| a.0.total_cmp(&b.0));
        starts = scored.into_iter().take(STARTS).map(|s| s.1).collect();
        if !starts.contains(&initial) {
            starts.push(initial);
        }
    }
    let mut optima = starts;
    let mut steps = Vec::with_capacity(horizons.len());
    for &until in horizons {
        optima = optima
            .into_par_iter()
            .map(|mut z| {
                // Restarted with a fresh simplex while it keeps improving: a shrunken one stalls
                // in a curved valley (a block's height and centre of mass trade off).
                let mut cost = posterior(&z, until);
                for _ in 0..RESTARTS {
                    let Some(found) = simplex(&posterior, &z, until) else { break };
                    let found_cost = posterior(&found, until);
                    if found_cost >= cost - 1e-9 * cost.abs().max(1.0) {
                        break;
                    }
                    (z, cost) = (found, found_cost);
                }
                z
            })
            .collect();
        // Starts that met in one optimum go on as one: the longer horizons cost the most.
        let costs: Vec<f64> = optima.iter().map(|z| posterior(z, until)).collect();
        optima = distinct(optima, &costs);
        if let Some(best) = optima.first() {
            steps.push((until, best.clone()));
        }
    }
    // Every horizon's best competes on the last one: a longer horizon can lose a basin that a
    // shorter one found (a change late in the record pulls the search away from the values the
    // records before it support).
    let last = *horizons.last().unwrap_or(&f64::INFINITY);
    let finalists: Vec<Vec<f64>> = optima.into_iter().chain(steps.iter().map(|s| s.1.clone())).collect();
    let steps = steps.into_iter().map(|(until, z)| (until, to_values(&z))).collect();
    let best = finalists
        .into_iter()
        .map(|z| (posterior(&z, last), z))
        .reduce(|a, b| if b.0 < a.0 { b } else { a })
        .map(|b| b.1)
        .unwrap_or_else(|| vec![0.0; dim]);
    Calibration { parameters: parameters.to_vec(), fitted: to_values(&best), evaluations: seen.runs(), steps }
}

/// [`calibrate`] of a unit model: the parameters its predictions depend on are fitted
/// (`chi2(model with trial values, horizon)`), the others keep their stated values.
pub fn calibrate_model<M: UnitModel>(
    model: &M,
    parameters: &[Uncertain],
    start: Option<&[f64]>,
    horizons: &[f64],
    explore: bool,
    chi2: &(dyn Fn(&M, f64) -> f64 + Sync),
) -> Calibration {
    let fitted: Vec<usize> = (0..parameters.len()).filter(|&i| model.constrains(&parameters[i].key)).collect();
    let subset: Vec<Uncertain> = fitted.iter().map(|&i| parameters[i].clone()).collect();
    let base = match start {
        Some(s) => with_values(model, parameters, s),
        None => Ok(model.clone()),
    };
    let Ok(base) = base else { return Calibration::stated(parameters.to_vec()) };
    let sub_start: Option<Vec<f64>> = start.map(|s| fitted.iter().map(|&i| s[i]).collect());
    let objective = |values: &[f64], until: f64| match with_values(&base, &subset, values) {
        Ok(m) => chi2(&m, until),
        Err(_) => f64::INFINITY,
    };
    let found = calibrate(&subset, sub_start.as_deref(), horizons, explore, &objective);
    let mut all = Calibration::stated(parameters.to_vec());
    if let Some(s) = start {
        all.fitted = s.to_vec();
    }
    let place = |values: &[f64]| {
        let mut full = all.fitted.clone();
        for (&i, &v) in fitted.iter().zip(values) {
            full[i] = v;
        }
        full
    };
    all.steps = found.steps.iter().map(|(until, values)| (*until, place(values))).collect();
    all.fitted = place(&found.fitted);
    all.evaluations = found.evaluations;
    all
}

/// The points (in sd) farther than [`MERGE_SD`] from every point of lower cost (the earlier on a
/// tie), cheapest first: of starts that met in one optimum the best goes on alone.
fn distinct(points: Vec<Vec<f64>>, costs: &[f64]) -> Vec<Vec<f64>> {
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| costs[a].total_cmp(&costs[b]).then(a.cmp(&b)));
    let mut kept: Vec<Vec<f64>> = Vec::new();
    for i in order {
        let near = |k: &Vec<f64>| k.iter().zip(&points[i]).all(|(a, b)| (a - b).abs() <= MERGE_SD);
        if !kept.iter().any(near) {
            kept.push(points[i].clone());
        }
    }
    kept
}

/// Starting points over ±2 sd around `centre`: a full grid while it stays small, else each axis
/// alone (the others at the centre).
fn coarse_grid(dim: usize, centre: &[f64]) -> Vec<Vec<f64>> {
    let steps = [-2.0, -1.0, 0.0, 1.0, 2.0];
    if dim <= 3 {
        let axes: Vec<Vec<f64>> = centre.iter().map(|c| steps.iter().map(|s| c + s).collect()).collect();
        return super::effects::product(&axes);
    }
    let mut points = vec![centre.to_vec()];
    for d in 0..dim {
        for s in steps.iter().filter(|s| **s != 0.0) {
            let mut p = centre.to_vec();
            p[d] += s;
            points.push(p);
        }
    }
    points
}

struct Posterior<'a> {
    f: &'a (dyn Fn(&[f64], f64) -> f64 + Sync),
    until: f64,
}

impl CostFunction for Posterior<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, z: &Vec<f64>) -> Result<f64, Error> {
        Ok((self.f)(z, self.until))
    }
}

/// Nelder–Mead from `start` (a simplex of 0.5 sd), judged up to `until`.
fn simplex(f: &(dyn Fn(&[f64], f64) -> f64 + Sync), start: &[f64], until: f64) -> Option<Vec<f64>> {
    let mut vertices = vec![start.to_vec()];
    for d in 0..start.len() {
        let mut v = start.to_vec();
        v[d] += 0.5;
        vertices.push(v);
    }
    let start_cost = f(start, until);
    let solver = NelderMead::new(vertices).with_sd_tolerance(1e-4).ok()?;
    let result = Executor::new(Posterior { f, until }, solver).configure(|s| s.max_iters(MAX_ITERATIONS)).run().ok()?;
    let state = result.state();
    let z = state.get_best_param()?.clone();
    (state.get_best_cost() <= start_cost).then_some(z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Clone)]
    struct Line {
        slope: f64,
        offsets: [f64; 2],
    }

    impl UnitModel for Line {
        fn nominal_keys(&self) -> Vec<(&'static str, usize)> {
            vec![("slope", 1), ("offsets", 2)]
        }
        fn parameter(&self, key: &str, index: usize) -> Option<f64> {
            match key {
                "slope" => Some(self.slope),
                "offsets" => self.offsets.get(index).copied(),
                _ => None,
            }
        }
        fn set_parameter(&mut self, key: &str, index: usize, value: f64) -> Result<(), ParameterError> {
            match key {
                "slope" => self.slope = value,
                _ => self.offsets[index] = value,
            }
            Ok(())
        }
        fn physical_range(&self, key: &str) -> (f64, f64) {
            if key == "slope" {
                (0.0, f64::INFINITY)
            } else {
                (f64::NEG_INFINITY, f64::INFINITY)
            }
        }
    }

    fn block(entries: &[(&str, Spread)]) -> Vec<(String, Spread)> {
        entries.iter().map(|(k, s)| (k.to_string(), *s)).collect()
    }

    #[test]
    fn a_block_names_nominal_parameters_only_and_lists_count_element_wise() {
        let line = Line { slope: 2.0, offsets: [1.0, -1.0] };
        let abs = Spread { sd: Some(0.1), rel_sd: None };
        let rel = Spread { sd: None, rel_sd: Some(0.1) };
        let p = uncertain_parameters(&line, &block(&[("slope", rel), ("offsets", abs)])).unwrap();
        assert_eq!(p.iter().map(Uncertain::label).collect::<Vec<_>>(), ["slope", "offsets[0]", "offsets[1]"]);
        assert!((p[0].sd - 0.2).abs() < 1e-15 && p[1].sd == 0.1);
        // The slope's bounds stop at its physical range, 5 sd = 1 away from 2: [1, 3].
        assert!((p[0].bounds.0 - 1.0).abs() < 1e-12 && (p[0].bounds.1 - 3.0).abs() < 1e-12);
        let err = uncertain_parameters(&line, &block(&[("intercept", abs)])).unwrap_err().to_string();
        assert!(err.contains("`intercept` is not a nominal parameter") && err.contains("slope, offsets"), "{err}");
        let both = Spread { sd: Some(0.1), rel_sd: Some(0.1) };
        assert_eq!(
            uncertain_parameters(&line, &block(&[("slope", both)])),
            Err(ParameterError::Spread { key: "slope".into(), spread: SpreadError::Both })
        );
        let none = Spread::default();
        assert!(uncertain_parameters(&line, &block(&[("slope", none)])).is_err());
    }

    /// Data y = 2.3 x + 0.5 at x = 0..10 with unit noise sd 0.1; stated slope 2.0 (sd 0.2) and
    /// offset 0 (sd 1): the posterior mode has a closed form (weighted least squares with the
    /// priors as two more observations), which the calibration must find.
    #[test]
    fn calibration_finds_the_posterior_mode_of_a_linear_model() {
        let line = Line { slope: 2.0, offsets: [0.0, 0.0] };
        let abs = |sd| Spread { sd: Some(sd), rel_sd: None };
        let p = uncertain_parameters(&line, &block(&[("slope", abs(0.2)), ("offsets", abs(1.0))])).unwrap();
        let xs: Vec<f64> = (0..=10).map(f64::from).collect();
        let chi2 = |v: &[f64], _until: f64| -> f64 {
            xs.iter().map(|x| ((2.3 * x + 0.5 - (v[0] * x + v[1])) / 0.1).powi(2)).sum::<f64>()
        };
        let c = calibrate(&p, None, &[f64::INFINITY], true, &chi2);
        // Normal equations of [x 1] rows weighted by 1/0.1² plus priors (1/0.2², 1/1²); offsets[1]
        // is unconstrained by the data and stays at its prior mean.
        let (mut a, mut b) = ([[1.0 / 0.04, 0.0], [0.0, 1.0]], [2.0 / 0.04, 0.0]);
        for x in &xs {
            let y = 2.3 * x + 0.5;
            let w = 100.0;
            a[0][0] += w * x * x;
            a[0][1] += w * x;
            a[1][0] += w * x;
            a[1][1] += w;
            b[0] += w * x * y;
            b[1] += w * y;
        }
        let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
        let slope = (b[0] * a[1][1] - a[0][1] * b[1]) / det;
        let offset = (a[0][0] * b[1] - a[1][0] * b[0]) / det;
        assert!((c.fitted[0] - slope).abs() < 1e-3, "{} vs {slope}", c.fitted[0]);
        assert!((c.fitted[1] - offset).abs() < 1e-2, "{} vs {offset}", c.fitted[1]);
        assert!(c.fitted[2].abs() < 1e-2);
        // The slope moved 1.5 sd: within; a list is reported element-wise.
        let entries = c.entries();
        assert_eq!(entries.len(), 2);
        assert!(matches!(entries[0].1, Entry::Scalar { within: true, .. }));
        let Entry::List { ref fitted, ref within, .. } = entries[1].1 else { panic!("offsets is a list") };
        assert_eq!((fitted.len(), within.as_slice()), (2, &[true, true][..]));
        assert!(c.beyond().is_empty());
    }

    /// Optima within 0.1 sd of a cheaper one (every parameter) are dropped, cheapest first;
    /// one 0.1 sd off on one axis but 0.2 on another stays, and so does a far one.
    #[test]
    fn starts_that_met_in_one_optimum_go_on_as_one() {
        let points = vec![vec![0.0, 0.0], vec![0.05, -0.1], vec![2.0, 1.0], vec![0.1, 0.2], vec![2.0, 1.0]];
        let costs = [5.0, 4.0, 1.0, 3.0, 1.0];
        let kept = distinct(points, &costs);
        assert_eq!(kept, [vec![2.0, 1.0], vec![0.1, 0.2], vec![0.05, -0.1]]);
    }

    /// The records up to 1 s want v = 1; up to 2 s (a change begins) only v = 3; over the whole
    /// record v = 1 is best (χ² 0) but v = 3 keeps a local well (χ² 50; prior sd 1). The search
    /// carried from horizon to horizon ends in the well; the first horizon's optimum, judged on
    /// the whole record too, wins. Each horizon's best is kept in `steps`.
    #[test]
    fn every_horizons_optimum_competes_on_the_whole_record() {
        let line = Line { slope: 0.0, offsets: [0.0, 0.0] };
        let p = uncertain_parameters(&line, &block(&[("offsets", Spread { sd: Some(1.0), rel_sd: None })])).unwrap();
        let p = &p[..1];
        let chi2 = |v: &[f64], until: f64| match until {
            u if u <= 1.0 => 100.0 * (v[0] - 1.0).powi(2),
            u if u <= 2.0 => 100.0 * (v[0] - 3.0).powi(2),
            _ => (100.0 * (v[0] - 1.0).powi(2)).min(50.0 + 10.0 * (v[0] - 3.0).powi(2)),
        };
        let c = calibrate(p, None, &[1.0, 2.0, f64::INFINITY], false, &chi2);
        let steps: Vec<f64> = c.steps.iter().map(|s| s.0).collect();
        assert_eq!(steps, [1.0, 2.0, f64::INFINITY]);
        // The posterior modes with the prior v² added: 100/101 and 300/101, then 30/11 in the well.
        assert!((c.steps[0].1[0] - 100.0 / 101.0).abs() < 1e-2, "{:?}", c.steps);
        assert!((c.steps[1].1[0] - 300.0 / 101.0).abs() < 1e-2, "{:?}", c.steps);
        assert!((c.steps[2].1[0] - 30.0 / 11.0).abs() < 1e-2, "the carried search stays in the well: {:?}", c.steps);
        assert!((c.fitted[0] - 100.0 / 101.0).abs() < 1e-2, "{}", c.fitted[0]);
    }

    #[test]
    fn a_value_that_must_move_beyond_three_sd_is_reported_but_stays_within_the_bounds() {
        let line = Line { slope: 2.0, offsets: [0.0, 0.0] };
        let p = uncertain_parameters(&line, &block(&[("slope", Spread { sd: Some(0.05), rel_sd: None })])).unwrap();
        // The data want slope 2.4 (8 sd): the fit stops at the bound, 5 sd, and says so.
        let chi2 = |v: &[f64], _: f64| (0..=10).map(|x| ((2.4 - v[0]) * f64::from(x) / 0.01).powi(2)).sum::<f64>();
        let c = calibrate(&p, None, &[f64::INFINITY], true, &chi2);
        assert!((c.fitted[0] - 2.25).abs() < 1e-4, "{}", c.fitted[0]);
        let beyond = c.beyond();
        assert_eq!(beyond.len(), 1);
        assert!((beyond[0].3 - 5.0).abs() < 1e-2);
        assert!(matches!(c.entries()[0].1, Entry::Scalar { within: false, .. }));
    }
}
