//! The one driver of the hybrid models (the rocking block, the sliding block, the block on a
//! coupled isolated base, the caster cart): continuous equations inside a regime, discrete
//! transitions between regimes.
//!
//! The floor is sampled data, linear between samples, so the driver advances one sample interval
//! at a time and every sample time is a step end: outputs land on the input time base. Inside an
//! interval a model is asked what its regime does from the current instant ([`Course`]): hold
//! still, switch at once or at a time it knows in closed form, or integrate its equations with a
//! shared stepper (`physics::ode`) until one of its event functions reaches zero. A transition
//! resets the stepper and is applied by the model, which logs its own events. A model that keeps
//! switching inside one interval (impact or stick-slip chatter) is stopped with its own error.
//!
//! A model supplies its regimes and transitions as enums: the event functions of a regime come
//! with the transition each one stands for ([`Equations::transition`]), never as bare indices.

use crate::physics::ode::{Advance, Stats, Stepper};

/// The sample times of a record: `t0_s + k·dt_s`, k < `samples`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clock {
    pub t0_s: f64,
    pub dt_s: f64,
    pub samples: usize,
}

impl Clock {
    pub fn time(&self, k: usize) -> f64 {
        self.t0_s + k as f64 * self.dt_s
    }

    /// The forcing over sample interval k, linear from sample k to k + 1 (constant over the last
    /// sample), from the `C` channels `at(k)` gives.
    pub fn segment<const C: usize>(&self, k: usize, at: impl Fn(usize) -> [f64; C]) -> Segment<C> {
        let k1 = (k + 1).min(self.samples - 1);
        let (a0, a1) = (at(k), at(k1));
        Segment { t0: self.time(k), a0, rate: std::array::from_fn(|i| (a1[i] - a0[i]) / self.dt_s) }
    }
}

/// The forcing inside one sample interval: `C` channels linear in time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment<const C: usize> {
    pub t0: f64,
    pub a0: [f64; C],
    pub rate: [f64; C],
}

impl<const C: usize> Segment<C> {
    pub fn at(&self, t: f64) -> [f64; C] {
        let s = t - self.t0;
        std::array::from_fn(|i| self.a0[i] + self.rate[i] * s)
    }
}

/// A regime's equations over one segment: y' = f(t, y) and `M` event functions, positive while
/// nothing happens (see [`Stepper`]); each stands for a transition of the model.
pub trait Equations<const N: usize, const M: usize> {
    type Transition: Copy;
    fn rhs(&self, t: f64, y: &[f64; N]) -> [f64; N];
    fn events(&self, t: f64, y: &[f64; N]) -> [f64; M];
    /// The transition event function `index` stands for.
    fn transition(&self, index: usize) -> Self::Transition;
}

/// What a regime does from the current instant up to the interval's limit.
pub enum Course<T, E> {
    /// Nothing changes until the limit (a state at rest, or a block lying on its side).
    Hold,
    /// The transition happens at `at` (the current instant or later, known in closed form).
    Switch { at: f64, transition: T },
    /// Integrate these equations, stopping at their first event.
    Integrate(E),
}

/// Where the driver stands inside sample interval `k`: at time `t`, the phase ending by `limit`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Now {
    pub k: usize,
    pub t: f64,
    pub limit: f64,
}

/// A hybrid model driven by [`drive`]: its regime and everything it records live in the model.
pub trait Hybrid<const N: usize, const M: usize> {
    type Transition: Copy;
    type Equations: Equations<N, M, Transition = Self::Transition>;
    type Error;

    /// Where the current phase must end within an interval ending at `t_end` (a scheduled change).
    fn limit(&self, t: f64, t_end: f64) -> f64 {
        let _ = t;
        t_end
    }
    /// The regime's course from `now` (state `y`) to its limit.
    fn course(&mut self, now: Now, y: &[f64; N]) -> Result<Course<Self::Transition, Self::Equations>, Self::Error>;
    /// Applies a transition at time `t` in sample interval k: `y` is the state there,
    /// `immediate` says the event fired at the very start of the integration (the trajectory
    /// could not leave its boundary). Returns the state after it.
    fn apply(&mut self, k: usize, transition: Self::Transition, t: f64, y: [f64; N], immediate: bool) -> [f64; N];
    /// A transition due at the end of sample interval k, after its integration (none by default).
    fn settle(&mut self, k: usize, t_end: f64, y: &[f64; N]) -> Option<Self::Transition> {
        let _ = (k, t_end, y);
        None
    }
    /// Refuses the state reached at the end of an interval (default: accepts it).
    fn check(&self, t_end: f64, y: &[f64; N], stats: &Stats) -> Result<(), Self::Error> {
        let _ = (t_end, y, stats);
        Ok(())
    }
    /// The error of a run that switched more than its limit of times within the interval
    /// containing `t`.
    fn chatter(&self, t: f64, stats: &Stats) -> Self::Error;
    /// Records sample k with state `y`.
    fn record(&mut self, k: usize, y: &[f64; N]);
}

/// Runs the model over the samples of `clock` from state `y` (sample 0) and returns the
/// stepper's work. More than `max_transitions` transitions within one sample interval are the
/// model's chatter error.
pub fn drive<const N: usize, const M: usize, H, S>(
    model: &mut H,
    clock: Clock,
    max_transitions: usize,
    mut y: [f64; N],
    mut stepper: S,
) -> Result<Stats, H::Error>
where
    H: Hybrid<N, M>,
    S: Stepper<N>,
{
    model.record(0, &y);
    for k in 0..clock.samples - 1 {
        let t_end = clock.time(k + 1);
        let mut t = clock.time(k);
        let mut transitions = 0;
        while t < t_end {
            transitions += 1;
            if transitions > max_transitions {
                return Err(model.chatter(t, &stepper.stats()));
            }
            let limit = model.limit(t, t_end);
            let (at, transition, state, immediate) = match model.course(Now { k, t, limit }, &y)? {
                Course::Hold => {
                    t = limit;
                    continue;
                }
                Course::Switch { at, transition } => (at, transition, y, false),
                Course::Integrate(eq) => {
                    let outcome = stepper.advance(&|s, v| eq.rhs(s, v), t, y, limit, &|s, v| eq.events(s, v));
                    match outcome {
                        Advance::Reached(y1) => {
                            y = y1;
                            t = limit;
                            continue;
                        }
                        Advance::Event { index, t: te, y: ye } => (te, eq.transition(index), ye, te <= t),
                    }
                }
            };
            t = at;
            stepper.reset();
            y = model.apply(k, transition, at, state, immediate);
        }
        if let Some(transition) = model.settle(k, t_end, &y) {
            stepper.reset();
            y = model.apply(k, transition, t_end, y, false);
        }
        model.check(t_end, &y, &stepper.stats())?;
        model.record(k + 1, &y);
    }
    Ok(stepper.stats())
}

/// The impact-or-rest decision: after a contact the body rebounds at speed `after` unless the
/// contact came at the very start of an integration (`immediate`: it could not leave the
/// boundary) or the rebound carries less than the rest energy (`after² < rest_speed_squared`).
pub fn rebounds(after: f64, immediate: bool, rest_speed_squared: f64) -> bool {
    !(immediate || after * after < rest_speed_squared)
}
