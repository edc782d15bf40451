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
    sensor_acceleration, Block, Event, EventKind, Excitation, IsolatedBase, Options, Response, Segment,
    MAX_TRANSITIONS_PER_SAMPLE,
};
use crate::physics::ode::{Advance, Stepper};

#[derive(Clone, Copy, Debug, PartialEq)]
enum Regime {
    Rest,
    Rocking { side: i8 },
    Overturned,
}

/// The coupled equations with the quantities they need.
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

    fn rhs(&self, regime: Regime, seg: &Segment, t: f64, y: &[f64; 4]) -> [f64; 4] {
        let (ag, av) = seg.at(t);
        match regime {
            Regime::Rocking { side } => {
                let (theta_ddot, base) = self.rocking(side, y, av);
                [y[1], theta_ddot, y[3], base - ag]
            }
            Regime::Rest | Regime::Overturned => [0.0, 0.0, y[3], self.base_at_rest(y) - ag],
        }
    }

    /// Positive while the block stays at rest: uplift toward +x, toward −x.
    fn uplift_margins(&self, seg: &Segment, t: f64, y: &[f64; 4]) -> [f64; 2] {
        let (_, av) = seg.at(t);
        let hold = (self.block.g_mps2 + av) * self.block.alpha_rad.tan();
        let base = self.base_at_rest(y);
        [hold + base, hold - base]
    }
}

pub(super) fn simulate<S: Stepper<4>>(
    block: &Block,
    excitation: &Excitation<'_>,
    options: &Options,
    iso: &IsolatedBase,
    mass_ratio: f64,
    mut stepper: S,
) -> Result<Response, String> {
    let n = excitation.horizontal_mps2.len();
    let dt = excitation.dt_s;
    let vertical = |k: usize| excitation.vertical_mps2.map_or(0.0, |v| v[k]);
    let omega = std::f64::consts::TAU / iso.period_s;
    let system = System { block, k: omega * omega, c: 2.0 * iso.damping_ratio * omega, mu: 1.0 / (1.0 + mass_ratio) };
    let restitution = options
        .restitution
        .unwrap_or(1.0 - 2.0 * block.half_base_m.powi(2) / (block.i0_per_kg - system.mu * block.cm_height_m.powi(2)));
    let rest_speed_squared = 2.0 * block.p_radps.powi(2) * block.alpha_rad.sin() * options.rest_amplitude_rad;
    let sensor_height = options.sensor_height_m.unwrap_or(block.height_m);
    let segment = |k: usize| {
        let k1 = (k + 1).min(n - 1);
        let h = excitation.horizontal_mps2;
        Segment {
            t0: excitation.t0_s + k as f64 * dt,
            ax0: h[k],
            ax_rate: (h[k1] - h[k]) / dt,
            av0: vertical(k),
            av_rate: (vertical(k1) - vertical(k)) / dt,
        }
    };
    let mut response = Response {
        theta_rad: Vec::with_capacity(n),
        theta_dot_radps: Vec::with_capacity(n),
        theta_ddot_radps2: Vec::with_capacity(n),
        top_ax_mps2: Vec::with_capacity(n),
        sensor_ax_mps2: Vec::with_capacity(n),
        sensor_az_mps2: Vec::with_capacity(n),
        base_ax_mps2: Vec::with_capacity(n),
        slip_m: Vec::new(),
        events: Vec::new(),
        overturn: None,
        stats: Default::default(),
    };
    let record = |response: &mut Response, k: usize, regime: Regime, y: &[f64; 4]| {
        let av = vertical(k);
        let (theta_ddot, base, sensor) = match regime {
            Regime::Rocking { side } => {
                let (theta_ddot, base) = system.rocking(side, y, av);
                let sensor = sensor_acceleration(block, side, [y[0], y[1], theta_ddot], sensor_height, base, av);
                (theta_ddot, base, sensor)
            }
            Regime::Rest | Regime::Overturned => {
                let base = system.base_at_rest(y);
                (0.0, base, (base, av))
            }
        };
        response.theta_rad.push(y[0]);
        response.theta_dot_radps.push(y[1]);
        response.theta_ddot_radps2.push(theta_ddot);
        response.top_ax_mps2.push(if regime == Regime::Overturned { av } else { sensor.0 });
        response.sensor_ax_mps2.push(sensor.0);
        response.sensor_az_mps2.push(sensor.1);
        response.base_ax_mps2.push(base);
    };
    let push = |response: &mut Response, time_s: f64, kind: EventKind, side: i8, before: f64, after: f64| {
        response.events.push(Event { time_s, kind, side, theta_dot_before: before, theta_dot_after: after });
    };
    let mut y = [options.initial_theta_rad, options.initial_theta_dot_radps, 0.0, 0.0];
    let mut regime = match (y[0], y[1]) {
        (th, _) if th != 0.0 => Regime::Rocking { side: th.signum() as i8 },
        (_, w) if w != 0.0 => Regime::Rocking { side: w.signum() as i8 },
        _ => Regime::Rest,
    };
    record(&mut response, 0, regime, &y);
    for k in 0..n - 1 {
        let seg = segment(k);
        let t_end = excitation.t0_s + (k + 1) as f64 * dt;
        let mut t = seg.t0;
        let mut transitions = 0;
        while t < t_end {
            transitions += 1;
            if transitions > MAX_TRANSITIONS_PER_SAMPLE {
                return Err(format!(
                    "impact chatter near t = {t:.4} s did not settle; raise `rest_amplitude_rad` (now {})",
                    options.rest_amplitude_rad
                ));
            }
            let f = |time: f64, state: &[f64; 4]| system.rhs(regime, &seg, time, state);
            match regime {
                Regime::Overturned => match stepper.advance(&f, t, y, t_end, &|_, _| [0.0f64; 0]) {
                    Advance::Reached(y1) | Advance::Event { y: y1, .. } => {
                        y = y1;
                        t = t_end;
                    }
                },
                Regime::Rest => {
                    let now = system.uplift_margins(&seg, t, &y);
                    // A base accelerating toward −x (margin 0 spent) throws the block onto its
                    // +x corner, and the other way round.
                    let side_now = if now[0] <= 0.0 && now[0] <= now[1] {
                        Some(1)
                    } else if now[1] <= 0.0 {
                        Some(-1)
                    } else {
                        None
                    };
                    if let Some(side) = side_now {
                        regime = Regime::Rocking { side };
                        stepper.reset();
                        push(&mut response, t, EventKind::Uplift, side, 0.0, 0.0);
                        continue;
                    }
                    match stepper.advance(&f, t, y, t_end, &|time, state| system.uplift_margins(&seg, time, state)) {
                        Advance::Reached(y1) => {
                            y = y1;
                            t = t_end;
                        }
                        Advance::Event { index, t: te, y: ye } => {
                            let side = if index == 0 { 1 } else { -1 };
                            y = [0.0, 0.0, ye[2], ye[3]];
                            t = te;
                            regime = Regime::Rocking { side };
                            stepper.reset();
                            push(&mut response, te, EventKind::Uplift, side, 0.0, 0.0);
                        }
                    }
                }
                Regime::Rocking { side } => {
                    let s = f64::from(side);
                    let events = |_: f64, state: &[f64; 4]| [s * state[0], block.lie_angle_rad - s * state[0]];
                    match stepper.advance(&f, t, y, t_end, &events) {
                        Advance::Reached(y1) => {
                            y = y1;
                            t = t_end;
                        }
                        Advance::Event { index, t: te, y: ye } => {
                            let immediate = te <= t;
                            t = te;
                            stepper.reset();
                            if index == 0 {
                                let before = ye[1];
                                let mut after = restitution * before;
                                if immediate || after * after < rest_speed_squared {
                                    after = 0.0;
                                    regime = Regime::Rest;
                                    push(&mut response, te, EventKind::Rest, 0, before, 0.0);
                                } else {
                                    regime = Regime::Rocking { side: -side };
                                    push(&mut response, te, EventKind::Impact, -side, before, after);
                                }
                                // The system's horizontal momentum is conserved through the impact.
                                y = [0.0, after, ye[2], ye[3] - system.mu * block.cm_height_m * (after - before)];
                            } else {
                                // The block lies on the base, which carries it on as a rigid mass.
                                regime = Regime::Overturned;
                                y = [s * block.lie_angle_rad, 0.0, ye[2], ye[3]];
                                response.overturn = Some((te, side));
                                push(&mut response, te, EventKind::Overturn, side, ye[1], 0.0);
                            }
                        }
                    }
                }
            }
        }
        record(&mut response, k + 1, regime, &y);
    }
    response.stats = stepper.stats();
    Ok(response)
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
        let message = simulate(&block, &exc, &with_friction).unwrap_err();
        assert!(message.contains("does not combine with an isolated base"), "{message}");
        let message = simulate(&block, &exc, &isolated(Some(-1.0))).unwrap_err();
        assert!(message.contains("mass ratio"), "{message}");
    }
}
