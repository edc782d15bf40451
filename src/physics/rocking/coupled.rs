//! A block on a seismically isolated base as one coupled system (after Vassiliou & Makris 2012;
//! derivation in docs/models/toppling.md).
//!
//! The base (mass m_b = γm) rides on a linear isolator of period T_b and damping ξ, both referred
//! to the total mass m + m_b, so that while the block rests on it the base is exactly the SDOF of
//! the decoupled model. With u the base's displacement relative to the floor, ẍ_b = ü + a_g its
//! absolute acceleration, φ = sα − θ on side s and μ = m/(m + m_b):
//! - block (Eq. 22 on the base): θ̈ = −(R/i₀)[(g + a_v) sin φ + ẍ_b cos φ], i₀ = I₀/m;
//! - base, carrying the block's horizontal reaction m ẍ_cm:
//!   ẍ_b + μR(θ̈ cos φ + θ̇² sin φ) = −ω_b² u − 2ξω_b u̇;
//! - impact at θ = 0: the block's angular momentum about the new pivot and the system's
//!   horizontal momentum are conserved: θ̇₂ = e θ̇₁ with e = 1 − 2b²/(i₀ − μh_c²) (Eq. 24 at
//!   μ = 0), and u̇₂ = u̇₁ − μh_c(θ̇₂ − θ̇₁).
//!
//! As γ → ∞ (μ → 0) the base no longer feels the block and the model is the prescribed-base one.

use super::{
    chatter, initial_side, sensor_acceleration, Block, EventKind, Excitation, IsolatedBase, Options, Phase, Response,
    Run,
};
use crate::physics::error::PhysicsError;
use crate::physics::hybrid::{rebounds, Course, Equations, Hybrid, Now, Segment};
use crate::physics::ode::{Stats, Stepper};

#[derive(Clone, Copy, Debug, PartialEq)]
enum Regime {
    Rest,
    Rocking { side: i8 },
    Overturned,
}

/// The coupled equations with the quantities they need.
#[derive(Clone, Copy)]
struct System<'a> {
    block: &'a Block,
    /// ω_b² and 2ξω_b.
    k: f64,
    c: f64,
    /// μ = m/(m + m_b).
    mu: f64,
}

impl System<'_> {
    /// The base's absolute acceleration while the block rests on it (or lies on it).
    fn base_at_rest(&self, y: &[f64; 4]) -> f64 {
        -self.k * y[2] - self.c * y[3]
    }

    /// (θ̈, ẍ_b) while rocking on `side`.
    fn rocking(&self, side: i8, y: &[f64; 4], av: f64) -> (f64, f64) {
        let b = self.block;
        let (sin, cos) = (f64::from(side) * b.alpha_rad - y[0]).sin_cos();
        let kr = b.r_m / b.i0_per_kg;
        // ẍ_b + c θ̈ = rhs_base, d ẍ_b + θ̈ = rhs_block.
        let rhs_base = self.base_at_rest(y) - self.mu * b.r_m * sin * y[1] * y[1];
        let rhs_block = -kr * (b.g_mps2 + av) * sin;
        let (c, d) = (self.mu * b.r_m * cos, kr * cos);
        let base = (rhs_base - c * rhs_block) / (1.0 - c * d);
        (rhs_block - d * base, base)
    }

    fn rhs(&self, regime: Regime, seg: &Segment<2>, t: f64, y: &[f64; 4]) -> [f64; 4] {
        let [ag, av] = seg.at(t);
        match regime {
            Regime::Rocking { side } => {
                let (theta_ddot, base) = self.rocking(side, y, av);
                [y[1], theta_ddot, y[3], base - ag]
            }
            Regime::Rest | Regime::Overturned => [0.0, 0.0, y[3], self.base_at_rest(y) - ag],
        }
    }

    /// Positive while the block stays at rest: uplift toward +x, toward −x.
    fn uplift_margins(&self, seg: &Segment<2>, t: f64, y: &[f64; 4]) -> [f64; 2] {
        let [_, av] = seg.at(t);
        let hold = (self.block.g_mps2 + av) * self.block.alpha_rad.tan();
        let base = self.base_at_rest(y);
        [hold + base, hold - base]
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Transition {
    /// The base already accelerates past the uplift threshold: the block uplifts at once.
    UpliftNow(i8),
    /// The base's acceleration reaches the uplift threshold toward this side.
    Uplift(i8),
    /// θ back to 0: rebound onto the other corner, or rest; the system's momentum is kept.
    Impact,
    Overturn,
}

/// What the event functions of each integrated regime stand for, in their order.
const REST_EVENTS: [Transition; 2] = [Transition::Uplift(1), Transition::Uplift(-1)];
const ROCKING_EVENTS: [Transition; 2] = [Transition::Impact, Transition::Overturn];

impl Equations<4, 2> for Phase<System<'_>, Regime> {
    type Transition = Transition;

    fn rhs(&self, t: f64, y: &[f64; 4]) -> [f64; 4] {
        self.model.rhs(self.regime, &self.seg, t, y)
    }

    fn events(&self, t: f64, state: &[f64; 4]) -> [f64; 2] {
        match self.regime {
            Regime::Rest => self.model.uplift_margins(&self.seg, t, state),
            Regime::Rocking { side } => {
                let s = f64::from(side);
                [s * state[0], self.model.block.lie_angle_rad - s * state[0]]
            }
            // The base carries the lying block on: nothing ends that (positive, never fires).
            Regime::Overturned => [1.0; 2],
        }
    }

    fn transition(&self, index: usize) -> Transition {
        match self.regime {
            Regime::Rest => REST_EVENTS[index],
            Regime::Rocking { .. } => ROCKING_EVENTS[index],
            Regime::Overturned => unreachable!("a lying block has no events"),
        }
    }
}

pub(super) fn simulate<S: Stepper<4>>(
    block: &Block,
    excitation: &Excitation<'_>,
    options: &Options,
    iso: &IsolatedBase,
    mass_ratio: f64,
    stepper: S,
) -> Result<Response, PhysicsError> {
    let omega = std::f64::consts::TAU / iso.period_s;
    let system = System { block, k: omega * omega, c: 2.0 * iso.damping_ratio * omega, mu: 1.0 / (1.0 + mass_ratio) };
    let restitution = options
        .restitution
        .unwrap_or(1.0 - 2.0 * block.half_base_m.powi(2) / (block.i0_per_kg - system.mu * block.cm_height_m.powi(2)));
    let y = [options.initial_theta_rad, options.initial_theta_dot_radps, 0.0, 0.0];
    let regime = initial_side(y[0], y[1]).map_or(Regime::Rest, |side| Regime::Rocking { side });
    Run::new(block, system, regime, restitution, (excitation, options), false).drive(y, stepper)
}

/// The coupled system's run between transitions, and what it records.
type Coupled<'a> = Run<'a, System<'a>, Regime>;

impl<'a> Hybrid<4, 2> for Coupled<'a> {
    type Transition = Transition;
    type Equations = Phase<System<'a>, Regime>;
    type Error = PhysicsError;

    fn course(&mut self, now: Now, y: &[f64; 4]) -> Result<Course<Transition, Self::Equations>, PhysicsError> {
        let (k, t) = (now.k, now.t);
        let seg = self.excitation.segment(k);
        if self.regime == Regime::Rest {
            let now = self.model.uplift_margins(&seg, t, y);
            // A base accelerating toward −x (margin 0 spent) throws the block onto its +x
            // corner, and the other way round.
            let side_now = if now[0] <= 0.0 && now[0] <= now[1] {
                Some(1)
            } else if now[1] <= 0.0 {
                Some(-1)
            } else {
                None
            };
            if let Some(side) = side_now {
                return Ok(Course::Switch { at: t, transition: Transition::UpliftNow(side) });
            }
        }
        Ok(Course::Integrate(Phase { model: self.model, regime: self.regime, seg }))
    }

    fn apply(&mut self, _: usize, transition: Transition, t: f64, y: [f64; 4], immediate: bool) -> [f64; 4] {
        let block = self.model.block;
        match (transition, self.regime) {
            (Transition::UpliftNow(side), _) => {
                self.regime = Regime::Rocking { side };
                self.response.log(t, EventKind::Uplift, side, 0.0, 0.0);
                y
            }
            (Transition::Uplift(side), _) => {
                self.regime = Regime::Rocking { side };
                self.response.log(t, EventKind::Uplift, side, 0.0, 0.0);
                [0.0, 0.0, y[2], y[3]]
            }
            (Transition::Impact, Regime::Rocking { side }) => {
                let before = y[1];
                let mut after = self.restitution * before;
                if rebounds(after, immediate, self.rest_speed_squared) {
                    self.regime = Regime::Rocking { side: -side };
                    self.response.log(t, EventKind::Impact, -side, before, after);
                } else {
                    after = 0.0;
                    self.regime = Regime::Rest;
                    self.response.log(t, EventKind::Rest, 0, before, 0.0);
                }
                // The system's horizontal momentum is conserved through the impact.
                [0.0, after, y[2], y[3] - self.model.mu * block.cm_height_m * (after - before)]
            }
            (Transition::Overturn, Regime::Rocking { side }) => {
                // The block lies on the base, which carries it on as a rigid mass.
                self.regime = Regime::Overturned;
                self.response.overturn = Some((t, side));
                self.response.log(t, EventKind::Overturn, side, y[1], 0.0);
                [f64::from(side) * block.lie_angle_rad, 0.0, y[2], y[3]]
            }
            (_, regime) => unreachable!("{transition:?} in {regime:?}"),
        }
    }

    fn chatter(&self, t: f64, _: &Stats) -> PhysicsError {
        chatter("impact", t, self.options.rest_amplitude_rad)
    }

    fn record(&mut self, k: usize, y: &[f64; 4]) {
        let (system, block) = (&self.model, self.model.block);
        let av = self.excitation.vertical(k);
        let (theta_ddot, base, sensor) = match self.regime {
            Regime::Rocking { side } => {
                let (theta_ddot, base) = system.rocking(side, y, av);
                let sensor = sensor_acceleration(block, side, [y[0], y[1], theta_ddot], self.sensor, base, av);
                (theta_ddot, base, sensor)
            }
            Regime::Rest | Regime::Overturned => {
                let base = system.base_at_rest(y);
                (0.0, base, (base, av))
            }
        };
        self.response.record_motion([y[0], y[1]], theta_ddot, sensor, self.regime == Regime::Overturned, av);
        self.response.base_ax_mps2.push(base);
    }
}

#[cfg(test)]
mod tests {
    use super::super::{simulate, Excitation, Friction, IsolatedBase, Method, Options, Shape};
    use super::*;
    use crate::physics::sdof::Sdof;

    const G: f64 = 9.80665;

    fn slender() -> Block {
        Block::new(Shape::Rectangular { b_m: 1.52, h_m: 10.33, f: 0.0 }, 1.0, G).unwrap()
    }

    fn isolated(mass_ratio: Option<f64>) -> Options {
        Options {
            isolated_base: Some(IsolatedBase { period_s: 3.0, damping_ratio: 0.1, mass_ratio }),
            ..Options::default()
        }
    }

    /// Two cycles of a sine at the isolator's period (3 s), then quiet.
    fn pulse(n: usize, dt: f64, amplitude: f64) -> Vec<f64> {
        (0..n)
            .map(|k| {
                let t = k as f64 * dt;
                if t < 6.0 {
                    amplitude * (std::f64::consts::TAU * t / 3.0).sin()
                } else {
                    0.0
                }
            })
            .collect()
    }

    #[test]
    fn impacts_keep_the_coupled_restitution() {
        // Free rocking from a tilt on a base that carries the block: every impact multiplies θ̇
        // by e = 1 − 2b²/(I₀/m − μh_c²), μ = m/(m + m_b) (docs/models/toppling.md).
        let block = slender();
        let floor = vec![0.0; 3000];
        for ratio in [0.5, 2.0, 20.0] {
            let options = Options { initial_theta_rad: 0.5 * block.alpha_rad, ..isolated(Some(ratio)) };
            let r = simulate(
                &block,
                &Excitation { t0_s: 0.0, dt_s: 0.01, horizontal_mps2: &floor, vertical_mps2: None },
                &options,
            )
            .unwrap();
            let mu = 1.0 / (1.0 + ratio);
            let e = 1.0 - 2.0 * block.half_base_m.powi(2) / (block.i0_per_kg - mu * block.cm_height_m.powi(2));
            let impacts: Vec<_> = r.events.iter().filter(|e| e.kind == EventKind::Impact).collect();
            assert!(impacts.len() >= 3, "γ = {ratio}: {:?}", r.events);
            for i in impacts {
                assert!((i.theta_dot_after / i.theta_dot_before - e).abs() < 1e-12, "γ = {ratio}: {i:?}, e = {e}");
            }
            assert!(e < block.restitution_eq24, "a moving base takes more of the energy at each impact");
        }
    }

    #[test]
    fn at_rest_the_base_is_the_isolators_sdof() {
        // Below uplift the block rides the base as a rigid mass: the base's acceleration is the
        // SDOF of period T_b (on the total mass), whatever the mass ratio.
        let block = slender();
        let dt = 0.01;
        let floor = pulse(1000, dt, 0.2);
        let exact = Sdof::new(1.0 / 3.0, 0.1).absolute_acceleration(&floor, dt);
        let r = simulate(
            &block,
            &Excitation { t0_s: 0.0, dt_s: dt, horizontal_mps2: &floor, vertical_mps2: None },
            &isolated(Some(1.0)),
        )
        .unwrap();
        assert!(r.events.is_empty(), "{:?}", r.events);
        let worst = r.base_ax_mps2.iter().zip(&exact).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-8, "max |Δ base acceleration| = {worst} m/s²");
    }

    #[test]
    fn a_heavy_base_is_the_prescribed_base_motion() {
        // γ → ∞: the coupled model becomes the decoupled one (the base does not feel the block).
        let block = slender();
        // Sampled finely, so that the decoupled base's interpolation error stays small.
        let dt = 0.001;
        let floor = pulse(20000, dt, 0.5);
        let exc = Excitation { t0_s: 0.0, dt_s: dt, horizontal_mps2: &floor, vertical_mps2: None };
        let decoupled = simulate(&block, &exc, &isolated(None)).unwrap();
        let heavy = simulate(&block, &exc, &isolated(Some(1e12))).unwrap();
        let kinds = |r: &Response| r.events.iter().map(|e| (e.kind, e.side)).collect::<Vec<_>>();
        assert!(decoupled.count(EventKind::Impact) >= 2, "{:?}", decoupled.events);
        assert_eq!(kinds(&decoupled), kinds(&heavy));
        // The decoupled base is the SDOF's exact discretisation, linear between samples; the
        // coupled one integrates the SDOF itself: they differ by that interpolation (O(ω²dt²)),
        // which the rocking amplifies (at dt = 0.01 s: events 8.5 ms and θ 0.013 rad apart; at
        // 0.001 s: 0.09 ms and 1.4e-4 rad).
        let times =
            decoupled.events.iter().zip(&heavy.events).map(|(a, b)| (a.time_s - b.time_s).abs()).fold(0.0, f64::max);
        let before = (decoupled.overturn.unwrap().0 / dt) as usize - 1;
        let worst =
            decoupled.theta_rad[..before].iter().zip(&heavy.theta_rad).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(times < 5e-4 && worst < 5e-4, "event times within {times} s, θ within {worst} rad before the overturn");
        // A light base is a different system: here the block overturns on the heavy base and
        // survives on the light one (the scipy peer finds the same).
        assert!(decoupled.overturn.is_some());
        let light = simulate(&block, &exc, &isolated(Some(1.0))).unwrap();
        assert!(light.overturn.is_none() && light.count(EventKind::Impact) > 50, "{:?}", light.overturn);
    }

    #[test]
    fn adaptive_and_rk4_agree() {
        let block = slender();
        let dt = 0.01;
        let floor = pulse(2000, dt, 0.5);
        let exc = Excitation { t0_s: 0.0, dt_s: dt, horizontal_mps2: &floor, vertical_mps2: None };
        let adaptive = simulate(&block, &exc, &isolated(Some(2.0))).unwrap();
        let rk4 =
            simulate(&block, &exc, &Options { method: Method::Rk4 { dt_s: 1e-4 }, ..isolated(Some(2.0)) }).unwrap();
        let kinds = |r: &Response| r.events.iter().map(|e| (e.kind, e.side)).collect::<Vec<_>>();
        assert_eq!(kinds(&adaptive), kinds(&rk4));
        let worst = adaptive.theta_rad.iter().zip(&rk4.theta_rad).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-6, "max |Δθ| = {worst} rad");
    }

    #[test]
    fn features_the_coupled_base_lacks_are_refused() {
        let block = slender();
        let floor = vec![0.0; 10];
        let exc = Excitation { t0_s: 0.0, dt_s: 0.01, horizontal_mps2: &floor, vertical_mps2: None };
        let with_friction = Options { friction: Some(Friction::coulomb(0.3)), ..isolated(Some(1.0)) };
        let message = simulate(&block, &exc, &with_friction).unwrap_err().to_string();
        assert!(message.contains("does not combine with an isolated base"), "{message}");
        let message = simulate(&block, &exc, &isolated(Some(-1.0))).unwrap_err().to_string();
        assert!(message.contains("mass ratio"), "{message}");
    }
}
