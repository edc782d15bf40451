//! The cart as a hybrid model run by the shared driver (`physics::hybrid`): its regimes (exact
//! rest, moving), its transitions (caster flips, the first motion, and with exact stick the
//! moment the cart slows enough to stick or the floor breaks it away) and what it records at each
//! sample; the floor is linear between samples, so every output lands on the input time base.

use crate::physics::error::{PhysicsError, RunStopped};
use std::f64::consts::PI;

use super::dynamics::{Alteration, Dynamics, NoSlip, Slip};
use super::holding::HoldingSet;
use super::{Cart, Friction, FrictionLaw, Method, Options};
use crate::physics::hybrid::{self, Clock, Course, Equations, Hybrid, Now, Segment};
use crate::physics::ode::{Dopri5, Either, Rk4, Stats, Stepper};

/// Floor acceleration sampled at a constant step, two horizontal components (floor X, Y).
#[derive(Clone, Copy, Debug)]
pub struct Excitation<'a> {
    pub t0_s: f64,
    pub dt_s: f64,
    pub ax_mps2: &'a [f64],
    pub ay_mps2: &'a [f64],
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EventKind {
    /// The cart starts to move: it leaves exact rest (stick-slip), or its speed √(2T/m) first
    /// exceeds 1 mm/s (regularised friction, where "rest" is a creep below that).
    Breakaway,
    /// The cart sticks (stick-slip law only).
    Rest,
    /// A caster swings around: its steering angle passes 135° from the body direction it was
    /// last aligned with, ending within 45° of the opposite one.
    Flip,
}

impl EventKind {
    pub fn name(self) -> &'static str {
        match self {
            EventKind::Breakaway => "breakaway",
            EventKind::Rest => "rest",
            EventKind::Flip => "flip",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Event {
    pub time_s: f64,
    pub kind: EventKind,
    /// 0-based caster index for flips.
    pub caster: Option<usize>,
    /// The state at the event: x, y, θ, δ₁..δ₄.
    pub pose: [f64; 7],
}

/// Time series on the input time base, and the events.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Response {
    pub x_m: Vec<f64>,
    pub y_m: Vec<f64>,
    pub yaw_rad: Vec<f64>,
    pub delta_rad: [Vec<f64>; 4],
    pub vx_mps: Vec<f64>,
    pub vy_mps: Vec<f64>,
    pub yaw_rate_radps: Vec<f64>,
    /// Wheel-centre speed along the wheel heading (rolling speed × r).
    pub roll_speed_mps: [Vec<f64>; 4],
    pub swivel_rate_radps: [Vec<f64>; 4],
    /// Absolute acceleration of the platform centre (floor + relative), floor X and Y.
    pub ax_abs_mps2: Vec<f64>,
    pub ay_abs_mps2: Vec<f64>,
    pub kinetic_energy_j: Vec<f64>,
    pub resting: Vec<bool>,
    pub events: Vec<Event>,
    pub stats: Stats,
    /// The full state at every sample, when asked for ([`simulate_altered`]): where a later
    /// run may start from.
    pub states: Vec<Vec<f64>>,
}

impl Response {
    /// Largest distance of the platform centre from its start, and the sample where it occurs.
    pub fn peak_displacement(&self) -> (f64, usize) {
        let (x0, y0) = (self.x_m[0], self.y_m[0]);
        peak(self.x_m.iter().zip(&self.y_m).map(|(x, y)| (x - x0).hypot(y - y0)))
    }

    /// Largest |θ − θ₀| and its sample.
    pub fn peak_yaw(&self) -> (f64, usize) {
        let yaw0 = self.yaw_rad[0];
        peak(self.yaw_rad.iter().map(|y| (y - yaw0).abs()))
    }

    pub fn flips(&self) -> [usize; 4] {
        std::array::from_fn(|i| self.events.iter().filter(|e| e.kind == EventKind::Flip && e.caster == Some(i)).count())
    }

    pub fn count(&self, kind: EventKind) -> usize {
        self.events.iter().filter(|e| e.kind == kind).count()
    }

    /// Appends a run that starts where this one ends (its first sample, the shared one, is
    /// dropped; its first-motion event too, which only says that the piece began moving).
    fn continue_with(&mut self, next: Response) {
        fn tail<T: Clone>(to: &mut Vec<T>, from: &[T]) {
            to.extend_from_slice(from.get(1..).unwrap_or_default());
        }
        tail(&mut self.x_m, &next.x_m);
        tail(&mut self.y_m, &next.y_m);
        tail(&mut self.yaw_rad, &next.yaw_rad);
        tail(&mut self.vx_mps, &next.vx_mps);
        tail(&mut self.vy_mps, &next.vy_mps);
        tail(&mut self.yaw_rate_radps, &next.yaw_rate_radps);
        for i in 0..4 {
            tail(&mut self.delta_rad[i], &next.delta_rad[i]);
            tail(&mut self.roll_speed_mps[i], &next.roll_speed_mps[i]);
            tail(&mut self.swivel_rate_radps[i], &next.swivel_rate_radps[i]);
        }
        tail(&mut self.ax_abs_mps2, &next.ax_abs_mps2);
        tail(&mut self.ay_abs_mps2, &next.ay_abs_mps2);
        tail(&mut self.kinetic_energy_j, &next.kinetic_energy_j);
        tail(&mut self.resting, &next.resting);
        tail(&mut self.states, &next.states);
        self.events.extend(next.events.into_iter().filter(|e| e.kind != EventKind::Breakaway));
        self.stats.accepted += next.stats.accepted;
        self.stats.rejected += next.stats.rejected;
        self.stats.rhs_evals += next.stats.rhs_evals;
        self.stats.events += next.stats.events;
    }
}

impl Response {
    fn log<const N: usize>(&mut self, time_s: f64, kind: EventKind, caster: Option<usize>, y: &[f64; N]) {
        self.events.push(Event { time_s, kind, caster, pose: std::array::from_fn(|i| y[i]) });
    }
}

fn peak(values: impl Iterator<Item = f64>) -> (f64, usize) {
    values.enumerate().fold((0.0, 0), |(best, at), (k, v)| if v > best { (v, k) } else { (best, at) })
}

/// Speed below which a regularised cart counts as not moving (its creep stays below it).
const MOVING_SPEED_MPS: f64 = 1e-3;
/// A caster's flip index changes when δ passes this far from its last aligned direction.
const FLIP_ANGLE: f64 = 0.75 * PI;
/// Events and regime changes allowed within one sample interval before the run is declared stuck.
const MAX_TRANSITIONS_PER_SAMPLE: usize = 1000;

/// Simulates the cart under the floor motion; outputs are on the input time base.
pub fn simulate(
    cart: &Cart,
    friction: &Friction,
    excitation: &Excitation<'_>,
    options: &Options,
) -> Result<Response, PhysicsError> {
    let n = excitation.ax_mps2.len();
    if n < 2 {
        return Err(PhysicsError::TooFewSamples(n));
    }
    if excitation.ay_mps2.len() != n {
        return Err(PhysicsError::Floor(format!(
            "the X and Y floor records differ in length ({n} vs {})",
            excitation.ay_mps2.len()
        )));
    }
    if !(excitation.dt_s.is_finite() && excitation.dt_s > 0.0) {
        return Err(PhysicsError::SampleInterval(excitation.dt_s));
    }
    if let Some(k) = (0..n).find(|&k| !(excitation.ax_mps2[k].is_finite() && excitation.ay_mps2[k].is_finite())) {
        return Err(PhysicsError::NotFinite { sample: k, t_s: excitation.t0_s + k as f64 * excitation.dt_s });
    }
    cart.check(options.lateral_slip.is_some())?;
    friction.check()?;
    let mut y0 = [0.0; 14];
    y0[2] = options.yaw0_rad;
    y0[3..7].copy_from_slice(&options.steer0_rad);
    match options.lateral_slip {
        None => {
            let model = NoSlip::new(cart, friction, options.g_mps2);
            let y: [f64; 10] = std::array::from_fn(|i| y0[i]);
            dispatch(&model, y, excitation, friction, options.method)
        }
        Some(lateral) => {
            if friction.law == FrictionLaw::StickSlip {
                return Err(PhysicsError::Parameter("the exact stick-slip law is available for the no-slip model only; use the regularised law with lateral slip".into()));
            }
            if !(lateral.mu.is_finite() && lateral.mu > 0.0 && lateral.eps_mps.is_finite() && lateral.eps_mps > 0.0) {
                return Err(PhysicsError::Parameter(format!(
                    "lateral slip needs a positive friction coefficient and ε, got μ = {}, ε = {}",
                    lateral.mu, lateral.eps_mps
                )));
            }
            let model = Slip::new(cart, friction, &lateral, options.g_mps2);
            dispatch(&model, y0, excitation, friction, options.method)
        }
    }
}

/// Constant pieces a ramped alteration ([`Alteration::ramp_s`]) is run as: each at the ramp's
/// value at the piece's middle (the midpoint rule: the drag's impulse and the mass's history are
/// off by O(1/pieces²) of the ramp's effect).
const RAMP_PIECES: usize = 16;

/// The no-slip cart with an [`Alteration`] from sample `start` to sample `end` (inclusive), its
/// states kept: from the cart's initial pose at rest when `start` is None (the alteration acts
/// from the first sample), else from `start = (k, y)`, the nominal cart's state `y` at sample k,
/// which the alteration changes as it begins ([`NoSlip::enter`]). Outputs cover samples k..=end.
/// A ramped alteration runs as `RAMP_PIECES` constant pieces over its ramp (at most one per
/// sample), each entered from the one before (a captured mass shares the momentum piece by
/// piece; a lost one leaves with its own velocity), then the full alteration.
/// `budget` caps the right-hand-side evaluations of the whole run (an error past it): a fit
/// tries parameters whose cart crawls through a stiff stick (a locked wheel holding it) and
/// would otherwise take minutes to say it fits badly.
/// Regularised friction only (an alteration has no exact stick).
#[allow(clippy::too_many_arguments)]
pub fn simulate_altered(
    cart: &Cart,
    friction: &Friction,
    excitation: &Excitation<'_>,
    options: &Options,
    alteration: &Alteration,
    start: Option<(usize, &[f64])>,
    end: usize,
    budget: Option<usize>,
) -> Result<Response, RunStopped> {
    let n = excitation.ax_mps2.len();
    let refused = |error: PhysicsError| RunStopped { error, spent: 0 };
    if friction.law != FrictionLaw::Regularised || options.lateral_slip.is_some() {
        return Err(refused(PhysicsError::Parameter(
            "an altered cart runs the no-slip model with regularised friction only".into(),
        )));
    }
    let k0 = start.map_or(0, |s| s.0);
    if !(k0 < end && end < n) || excitation.ay_mps2.len() != n {
        return Err(refused(PhysicsError::Floor(format!(
            "cannot simulate samples {k0}..={end} of a {n}-sample floor record"
        ))));
    }
    cart.check(false).map_err(refused)?;
    friction.check().map_err(refused)?;
    // Checks the full alteration (a ramp's pieces are smaller versions of it).
    NoSlip::altered(cart, friction, options.g_mps2, alteration).map_err(refused)?;
    let mut before = NoSlip::new(cart, friction, options.g_mps2);
    let mut y = match start {
        None => {
            let mut y = [0.0; 10];
            y[2] = options.yaw0_rad;
            y[3..7].copy_from_slice(&options.steer0_rad);
            y
        }
        Some((_, state)) => state.try_into().map_err(|_| {
            refused(PhysicsError::Parameter(format!("a cart state has 10 values, got {}", state.len())))
        })?,
    };
    let mut response: Option<Response> = None;
    let mut used = 0;
    for (first, last, piece) in pieces(alteration, k0, end, excitation.dt_s) {
        let model = NoSlip::altered(cart, friction, options.g_mps2, &piece)
            .map_err(|error| RunStopped { error, spent: used })?;
        if start.is_some() || first > k0 {
            y = model.enter(&before, &y);
        }
        let part = Excitation {
            t0_s: excitation.t0_s + first as f64 * excitation.dt_s,
            dt_s: excitation.dt_s,
            ax_mps2: &excitation.ax_mps2[first..=last],
            ay_mps2: &excitation.ay_mps2[first..=last],
        };
        let mut run = Run::new(&model, &part, friction.law, friction.eps_mps);
        run.keep_states = true;
        run.budget = budget.map(|b| b.saturating_sub(used));
        let next = run
            .run(stepper(options.method, excitation.dt_s, run.budget), y)
            .map_err(|s| RunStopped { spent: used + s.spent, ..s })?;
        let stopped = |what: &str| RunStopped { error: PhysicsError::Stopped(what.into()), spent: used };
        let state = next.states.last().ok_or_else(|| stopped("an altered run kept no state"))?;
        y = state.as_slice().try_into().map_err(|_| stopped("an altered run kept a malformed state"))?;
        used += next.stats.rhs_evals;
        match response.as_mut() {
            None => response = Some(next),
            Some(r) => r.continue_with(next),
        }
        before = model;
    }
    response.ok_or(RunStopped { error: PhysicsError::Stopped("an altered run covered no samples".into()), spent: used })
}

/// The constant pieces (first sample, last sample, alteration) of an altered run over k0..=end.
fn pieces(alteration: &Alteration, k0: usize, end: usize, dt_s: f64) -> Vec<(usize, usize, Alteration)> {
    if !alteration.ramped() {
        return vec![(k0, end, *alteration)];
    }
    let ramp = ((alteration.ramp_s / dt_s).round() as usize).max(1);
    let count = RAMP_PIECES.min(ramp);
    let mut starts: Vec<(usize, Alteration)> =
        (0..count).map(|j| (k0 + j * ramp / count, alteration.scaled((j as f64 + 0.5) / count as f64))).collect();
    starts.push((k0 + ramp, *alteration));
    starts.retain(|(k, _)| *k < end);
    (0..starts.len()).map(|i| (starts[i].0, starts.get(i + 1).map_or(end, |s| s.0), starts[i].1)).collect()
}

fn dispatch<const N: usize, D: Dynamics<N>>(
    model: &D,
    y0: [f64; N],
    excitation: &Excitation<'_>,
    friction: &Friction,
    method: Method,
) -> Result<Response, PhysicsError> {
    let run = Run::new(model, excitation, friction.law, friction.eps_mps);
    run.run(stepper(method, excitation.dt_s, None), y0).map_err(|s| s.error)
}

/// The stepper `method` asks for, giving up past `budget` evaluations (adaptive only).
fn stepper<const N: usize>(method: Method, dt_s: f64, budget: Option<usize>) -> Either<N> {
    match method {
        Method::Adaptive { rtol, atol } => {
            // Positions and angles to `atol`, velocities to 10·atol per second.
            let tolerances: [f64; N] = std::array::from_fn(|i| if i < 7 { atol } else { 10.0 * atol });
            Either::Dopri5(Dopri5::new(rtol, tolerances, dt_s).with_max_evals(budget))
        }
        Method::Rk4 { dt_s } => Either::Rk4(Rk4::new(dt_s)),
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Regime {
    /// Exactly at rest (stick-slip law): velocities zero, pose fixed.
    Rest,
    /// Rolling. `snap_armed`: whether slowing below the rest speed triggers a stick check; it is
    /// disarmed after a failed check until the cart speeds up again, so the check cannot repeat
    /// at one instant.
    Moving { snap_armed: bool },
}

struct Run<'a, const N: usize, D: Dynamics<N>> {
    model: &'a D,
    excitation: &'a Excitation<'a>,
    /// Exact stick of the whole cart (the stick-slip law).
    stick: bool,
    /// Kinetic energies that stand for the speeds √(2T/m_total) of the thresholds: the first
    /// motion of a regularised cart, and the speed (2ε) below which a stick-slip cart may stick.
    energy_moving: f64,
    energy_rest: f64,
    /// Keep the full state of every sample in the response.
    keep_states: bool,
    /// Right-hand-side evaluations allowed (None: no limit).
    budget: Option<usize>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Transition {
    /// The cart at rest starts to move: the floor's load leaves the set static friction holds.
    Breakaway,
    /// Caster i's steering passes 135° from the direction it was last aligned with.
    Flip(usize),
    /// The cart slowed below the rest speed: it sticks if static friction holds it.
    Snap,
    /// The cart sped up again: the stick check is armed.
    Rearm,
    /// A regularised cart first exceeds the moving speed.
    FirstMotion,
    /// A slow cart that the floor no longer pushes beyond static friction sticks at the end of
    /// a sample, though it never sped up enough to re-arm the located check.
    Settle,
}

/// What the event functions of a moving cart stand for, in their order
/// ([`Moving::events`]).
const MOVING_EVENTS: [Transition; 7] = [
    Transition::Flip(0),
    Transition::Flip(1),
    Transition::Flip(2),
    Transition::Flip(3),
    Transition::Snap,
    Transition::Rearm,
    Transition::FirstMotion,
];
const EVENTS: usize = MOVING_EVENTS.len();
const SNAP: usize = 4;
const REARM: usize = 5;
const FIRST_MOTION: usize = 6;

/// The moving cart's equations over one floor segment, with the event functions' switches.
struct Moving<'r, 'a, const N: usize, D: Dynamics<N>> {
    run: &'r Run<'a, N, D>,
    seg: Segment<2>,
    flip_index: [f64; 4],
    snap_armed: bool,
    moved: bool,
}

impl<const N: usize, D: Dynamics<N>> Equations<N, EVENTS> for Moving<'_, '_, N, D> {
    type Transition = Transition;

    fn rhs(&self, t: f64, y: &[f64; N]) -> [f64; N] {
        self.run.model.rhs(y, self.seg.at(t))
    }

    /// Positive while nothing happens: 0..4 caster flips, then the stick check, its re-arming,
    /// the first motion ([`MOVING_EVENTS`]).
    fn events(&self, _: f64, y: &[f64; N]) -> [f64; EVENTS] {
        let run = self.run;
        let mut g = [1.0; EVENTS];
        for i in 0..4 {
            let centre = self.flip_index[i] * PI;
            g[i] = (y[3 + i] - (centre - FLIP_ANGLE)).min(centre + FLIP_ANGLE - y[3 + i]);
        }
        let needs_energy = run.stick || !self.moved;
        if needs_energy {
            let energy = run.model.kinetic_energy(y);
            if run.stick {
                if self.snap_armed {
                    g[SNAP] = energy - run.energy_rest;
                } else {
                    g[REARM] = 4.0 * run.energy_rest - energy;
                }
            }
            if !self.moved {
                g[FIRST_MOTION] = run.energy_moving - energy;
            }
        }
        g
    }

    fn transition(&self, index: usize) -> Transition {
        MOVING_EVENTS[index]
    }
}

/// A run's state between transitions, and what it records.
struct Rolling<'r, 'a, const N: usize, D: Dynamics<N>> {
    run: &'r Run<'a, N, D>,
    regime: Regime,
    /// The multiple of π each caster was last aligned with.
    flip_index: [f64; 4],
    moved: bool,
    /// What static friction holds while the cart is at rest.
    holding: Option<HoldingSet>,
    response: Response,
}

impl<const N: usize, D: Dynamics<N>> Rolling<'_, '_, N, D> {
    /// The cart stops if static friction holds it against the floor at `floor`.
    fn stick_if_held(&mut self, t: f64, y: [f64; N], floor: [f64; 2]) -> Option<[f64; N]> {
        let set = self.run.holding_set(&y);
        if !set.holds(&self.run.load(&y, floor)) {
            return None;
        }
        let mut y = y;
        self.run.stop(&mut y);
        self.holding = Some(set);
        self.regime = Regime::Rest;
        self.response.log(t, EventKind::Rest, None, &y);
        Some(y)
    }
}

impl<'r, 'a, const N: usize, D: Dynamics<N>> Hybrid<N, EVENTS> for Rolling<'r, 'a, N, D> {
    type Transition = Transition;
    type Equations = Moving<'r, 'a, N, D>;
    type Error = RunStopped;

    fn course(&mut self, now: Now, y: &[f64; N]) -> Result<Course<Transition, Self::Equations>, RunStopped> {
        let Now { k, t, limit } = now;
        let run = self.run;
        let seg = run.segment(k);
        Ok(match self.regime {
            Regime::Rest => {
                let set = self.holding.get_or_insert_with(|| run.holding_set(y));
                let (q0, q1) = (run.load(y, seg.at(t)), run.load_rate(y, &seg));
                match set.exit_time(&q0, &q1, limit - t) {
                    None => Course::Hold,
                    Some(s) => Course::Switch { at: t + s, transition: Transition::Breakaway },
                }
            }
            Regime::Moving { snap_armed } => {
                Course::Integrate(Moving { run, seg, flip_index: self.flip_index, snap_armed, moved: self.moved })
            }
        })
    }

    fn apply(&mut self, k: usize, transition: Transition, t: f64, y: [f64; N], _: bool) -> [f64; N] {
        match transition {
            Transition::Breakaway => {
                self.regime = Regime::Moving { snap_armed: false };
                self.holding = None;
                self.moved = true;
                self.response.log(t, EventKind::Breakaway, None, &y);
            }
            Transition::Flip(i) => {
                self.flip_index[i] += if y[3 + i] > self.flip_index[i] * PI { 1.0 } else { -1.0 };
                self.response.log(t, EventKind::Flip, Some(i), &y);
            }
            Transition::Snap => {
                let floor = self.run.segment(k).at(t);
                match self.stick_if_held(t, y, floor) {
                    Some(stopped) => return stopped,
                    None => self.regime = Regime::Moving { snap_armed: false },
                }
            }
            Transition::Rearm => self.regime = Regime::Moving { snap_armed: true },
            Transition::FirstMotion => {
                self.moved = true;
                self.response.log(t, EventKind::Breakaway, None, &y);
            }
            Transition::Settle => {
                let floor = self.run.segment(k).at(t);
                return self.stick_if_held(t, y, floor).expect("settle checked that the cart is held");
            }
        }
        y
    }

    fn settle(&mut self, k: usize, t_end: f64, y: &[f64; N]) -> Option<Transition> {
        let run = self.run;
        let slow = run.stick && self.regime != Regime::Rest && run.model.kinetic_energy(y) < run.energy_rest;
        (slow && run.holding_set(y).holds(&run.load(y, run.segment(k).at(t_end)))).then_some(Transition::Settle)
    }

    fn check(&self, t_end: f64, y: &[f64; N], stats: &Stats) -> Result<(), RunStopped> {
        if let Some(budget) = self.run.budget.filter(|b| stats.rhs_evals > *b) {
            return Err(RunStopped {
                error: PhysicsError::Stopped(format!(
                    "the run needs more than {budget} evaluations by t = {t_end:.3} s (too stiff)"
                )),
                spent: stats.rhs_evals,
            });
        }
        if !y.iter().all(|v| v.is_finite()) {
            return Err(RunStopped {
                error: PhysicsError::Stopped(format!(
                    "the cart's state is no longer a number at t = {t_end:.3} s: the run diverged (too stiff a friction law or too large a change)"
                )),
                spent: stats.rhs_evals,
            });
        }
        Ok(())
    }

    fn chatter(&self, t: f64, stats: &Stats) -> RunStopped {
        RunStopped {
            error: PhysicsError::Stopped(format!(
                "more than {MAX_TRANSITIONS_PER_SAMPLE} events within the sample at t = {t:.4} s: the run does not settle (raise friction_eps)"
            )),
            spent: stats.rhs_evals,
        }
    }

    fn record(&mut self, k: usize, y: &[f64; N]) {
        self.run.record(&mut self.response, k, self.regime, y);
    }
}

impl<'a, const N: usize, D: Dynamics<N>> Run<'a, N, D> {
    fn new(model: &'a D, excitation: &'a Excitation<'a>, law: FrictionLaw, eps_mps: f64) -> Self {
        let mass = model.derived().total_mass_kg;
        let rest_speed = 2.0 * eps_mps;
        Run {
            model,
            excitation,
            stick: law == FrictionLaw::StickSlip,
            energy_moving: 0.5 * mass * MOVING_SPEED_MPS * MOVING_SPEED_MPS,
            energy_rest: 0.5 * mass * rest_speed * rest_speed,
            keep_states: false,
            budget: None,
        }
    }

    fn clock(&self) -> Clock {
        let exc = self.excitation;
        Clock { t0_s: exc.t0_s, dt_s: exc.dt_s, samples: exc.ax_mps2.len() }
    }

    fn segment(&self, k: usize) -> Segment<2> {
        let exc = self.excitation;
        self.clock().segment(k, |j| [exc.ax_mps2[j], exc.ay_mps2[j]])
    }

    /// The run, or why it failed with the evaluations it had spent.
    fn run<S: Stepper<N>>(&self, stepper: S, y: [f64; N]) -> Result<Response, RunStopped> {
        let t0 = self.excitation.t0_s;
        let mut rolling = Rolling {
            run: self,
            regime: Regime::Moving { snap_armed: false },
            flip_index: std::array::from_fn(|i| (y[3 + i] / PI).round()),
            moved: false,
            holding: None,
            response: Response::default(),
        };
        if self.stick {
            let set = self.holding_set(&y);
            if set.holds(&self.load(&y, self.segment(0).at(t0))) {
                rolling.regime = Regime::Rest;
                rolling.holding = Some(set);
            } else {
                rolling.moved = true;
                rolling.response.log(t0, EventKind::Breakaway, None, &y);
            }
        }
        let stats = hybrid::drive(&mut rolling, self.clock(), MAX_TRANSITIONS_PER_SAMPLE, y, stepper)?;
        rolling.response.stats = stats;
        Ok(rolling.response)
    }
    fn holding_set(&self, y: &[f64; N]) -> HoldingSet {
        let (_, generators) = self.model.rest_forces(y).expect("only models that can stick reach here");
        HoldingSet::new(&generators)
    }

    /// The floor's inertial load on the resting cart, as a generalised force.
    fn load(&self, y: &[f64; N], floor: [f64; 2]) -> [f64; 3] {
        let (map, _) = self.model.rest_forces(y).expect("only models that can stick reach here");
        map.map(|row| row[0] * floor[0] + row[1] * floor[1])
    }

    fn load_rate(&self, y: &[f64; N], seg: &Segment<2>) -> [f64; 3] {
        let (map, _) = self.model.rest_forces(y).expect("only models that can stick reach here");
        map.map(|row| row[0] * seg.rate[0] + row[1] * seg.rate[1])
    }

    fn stop(&self, y: &mut [f64; N]) {
        for v in &mut y[7..] {
            *v = 0.0;
        }
    }

    fn record(&self, response: &mut Response, k: usize, regime: Regime, y: &[f64; N]) {
        let exc = self.excitation;
        let floor = [exc.ax_mps2[k], exc.ay_mps2[k]];
        let acc = match regime {
            Regime::Rest => [0.0, 0.0],
            Regime::Moving { .. } => {
                let ydot = self.model.rhs(y, floor);
                [ydot[7], ydot[8]]
            }
        };
        response.x_m.push(y[0]);
        response.y_m.push(y[1]);
        response.yaw_rad.push(y[2]);
        response.vx_mps.push(y[7]);
        response.vy_mps.push(y[8]);
        response.yaw_rate_radps.push(y[9]);
        let swivel = self.model.swivel_rates(y);
        let (s_th, c_th) = y[2].sin_cos();
        for i in 0..4 {
            response.delta_rad[i].push(y[3 + i]);
            response.swivel_rate_radps[i].push(swivel[i]);
            let psi = y[2] + y[3 + i];
            let (s_psi, c_psi) = psi.sin_cos();
            let [px, py] = self.model.derived().pivots[i];
            let r = [c_th * px - s_th * py, s_th * px + c_th * py];
            let pivot = [y[7] - y[9] * r[1], y[8] + y[9] * r[0]];
            response.roll_speed_mps[i].push(c_psi * pivot[0] + s_psi * pivot[1]);
        }
        response.ax_abs_mps2.push(floor[0] + acc[0]);
        response.ay_abs_mps2.push(floor[1] + acc[1]);
        response.kinetic_energy_j.push(self.model.kinetic_energy(y));
        response.resting.push(regime == Regime::Rest);
        if self.keep_states {
            response.states.push(y.to_vec());
        }
    }
}
