//! A rigid block that slides and rocks on a floor with Coulomb friction (Shenton 1996; Shenton &
//! Jones 1991; Makris & Konstantinidis 2003; Bao & Konstantinidis 2020). Derivation in
//! docs/models/toppling.md, "Sliding and rocking".
//!
//! Four regimes besides the overturn, with u the slip of the base's contact relative to the floor
//! and, on side s, (A, B) = R(cos φ, sin φ), φ = sα − θ, the centre of mass relative to the pivot
//! (A its height, B its horizontal distance toward −s):
//! - **stick** (rest): θ = u̇ = 0. The floor must supply F = m a_g horizontally and N = m(g + a_v):
//!   the base slips when |a_g| > μ_s(g + a_v), the block uplifts toward s when
//!   −s a_g > (g + a_v) tan α, whichever comes first (so μ_s < tan α slides, μ_s > tan α rocks).
//! - **slide**: θ = 0, ü = −a_g − σμ_k(g + a_v), σ = sign u̇; it sticks when u̇ returns to 0
//!   and the floor's pull is within static friction, else it slides back. A sliding block only
//!   tips if μ_k > tan α (the friction's moment about the centre of mass beats the weight's).
//! - **rock** (pivot sticks): Eq. 22, θ̈ = −(1/i₀)[(g + a_v)B + a_g A], i₀ = I₀/m. The pivot
//!   carries F/m = a_g + Aθ̈ + Bθ̇² and N/m = g + a_v + Bθ̈ − Aθ̇²; it slips when |F| > μ_s N
//!   (a slide-rock mode, from rest too when the floor jumps past the uplift threshold).
//! - **slide-rock**: the pivot slides with F = −σμ_k N: with w = ü the pivot's acceleration
//!   relative to the floor, i₀θ̈ + Aw = −(g + a_v)B − a_g A (moments about the accelerating pivot)
//!   and (A + σμ_k B)θ̈ + w = −a_g − Bθ̇² − σμ_k(g + a_v − Aθ̇²) (horizontal balance), a 2 × 2
//!   system. The slip stops when u̇ = 0: rocking resumes if static friction holds the pivot.
//!
//! Impacts (θ = 0) multiply θ̇ by the rocking restitution (Eq. 24 or the given e) and keep the
//! base's slip velocity: the model assumes the impact's horizontal impulse within friction. A
//! rebound too small to lift the block ends rocking: it slides on if it slips, else it sticks.
//! Free flight (N < 0) is outside the model and refused with the time.

use super::{
    chatter, initial_side, most_negative, sensor_acceleration, Block, EventKind, Excitation, Friction, Options, Phase,
    Response, Run,
};
use crate::physics::error::PhysicsError;
use crate::physics::hybrid::{rebounds, Course, Equations, Hybrid, Now, Segment};
use crate::physics::ode::{Stats, Stepper};

#[derive(Clone, Copy, Debug, PartialEq)]
enum Regime {
    Stick,
    /// Sliding flat on the floor with slip velocity of sign `dir`.
    Slide {
        dir: i8,
    },
    /// Rocking on `side`, the pivot stuck.
    Rock {
        side: i8,
    },
    /// Rocking on `side` with the pivot sliding in direction `dir`.
    SlideRock {
        side: i8,
        dir: i8,
    },
    Overturned,
}

/// The equations, per unit mass. State: [θ, θ̇, u, u̇].
#[derive(Clone, Copy)]
struct Model<'a> {
    block: &'a Block,
    friction: Friction,
    /// Coupled friction above tan α: a block sliding flat tips at once.
    tips_while_sliding: bool,
}

impl Model<'_> {
    /// (A, B): the centre of mass relative to the pivot on `side` (height, distance toward −s).
    fn arm(&self, side: i8, theta: f64) -> (f64, f64) {
        let b = self.block;
        let (sin, cos) = (f64::from(side) * b.alpha_rad - theta).sin_cos();
        (b.r_m * cos, b.r_m * sin)
    }

    /// θ̈ about a pivot accelerating horizontally by `pivot_ax` (Eq. 22).
    fn rocking(&self, side: i8, y: &[f64; 4], pivot_ax: f64, av: f64) -> f64 {
        let (a, b) = self.arm(side, y[0]);
        -((self.block.g_mps2 + av) * b + pivot_ax * a) / self.block.i0_per_kg
    }

    /// Horizontal and normal contact force per unit mass under a pivot accelerating by `pivot_ax`.
    fn contact(&self, side: i8, y: &[f64; 4], theta_ddot: f64, pivot_ax: f64, av: f64) -> (f64, f64) {
        let (a, b) = self.arm(side, y[0]);
        let w2 = y[1] * y[1];
        (pivot_ax + a * theta_ddot + b * w2, self.block.g_mps2 + av + b * theta_ddot - a * w2)
    }

    /// (θ̈, ü) while rocking on `side` with the pivot sliding toward `dir`.
    fn slide_rocking(&self, side: i8, dir: i8, y: &[f64; 4], ag: f64, av: f64) -> (f64, f64) {
        let (a, b) = self.arm(side, y[0]);
        let g = self.block.g_mps2 + av;
        let sm = f64::from(dir) * self.friction.kinetic_mu;
        let w2 = y[1] * y[1];
        let c = a + sm * b;
        let r1 = -g * b - ag * a;
        let r2 = -ag - b * w2 - sm * (g - a * w2);
        let theta_ddot = (r1 - a * r2) / (self.block.i0_per_kg - a * c);
        (theta_ddot, r2 - c * theta_ddot)
    }

    fn rhs(&self, regime: Regime, seg: &Segment<2>, t: f64, y: &[f64; 4]) -> [f64; 4] {
        let [ag, av] = seg.at(t);
        match regime {
            Regime::Stick | Regime::Overturned => [0.0; 4],
            Regime::Slide { dir } => {
                [0.0, 0.0, y[3], -ag - f64::from(dir) * self.friction.kinetic_mu * (self.block.g_mps2 + av)]
            }
            Regime::Rock { side } => [y[1], self.rocking(side, y, ag, av), 0.0, 0.0],
            Regime::SlideRock { side, dir } => {
                let (theta_ddot, w) = self.slide_rocking(side, dir, y, ag, av);
                [y[1], theta_ddot, y[3], w]
            }
        }
    }

    /// Positive while the block sticks at rest: uplift toward +x, toward −x; slip toward −x
    /// (the floor pulls harder toward +x than static friction holds), toward +x.
    fn stick_margins(&self, seg: &Segment<2>, t: f64) -> [f64; 4] {
        let [ag, av] = seg.at(t);
        let g = self.block.g_mps2 + av;
        let hold = g * self.block.alpha_rad.tan();
        let grip = self.friction.static_mu * g;
        [hold + ag, hold - ag, grip - ag, grip + ag]
    }

    /// Uncoupled friction only: positive while the floor's acceleration cannot uplift the block
    /// (toward +x, toward −x), whether it sticks or slides (Eq. 20/21).
    fn uplift_margins(&self, seg: &Segment<2>, t: f64) -> [f64; 2] {
        let m = self.stick_margins(seg, t);
        [m[0], m[1]]
    }

    /// Positive while the rocking pivot sticks: μ_s N ∓ F (slip toward −x, toward +x).
    fn grip_margins(&self, side: i8, seg: &Segment<2>, t: f64, y: &[f64; 4]) -> [f64; 2] {
        if !self.friction.coupled {
            return [f64::INFINITY; 2];
        }
        let [ag, av] = seg.at(t);
        let theta_ddot = self.rocking(side, y, ag, av);
        let (f, n) = self.contact(side, y, theta_ddot, ag, av);
        let grip = self.friction.static_mu * n;
        [grip - f, grip + f]
    }
}

/// The slip direction that a contact needing horizontal force `f` takes when friction gives way.
fn slip_direction(f: f64) -> i8 {
    if f > 0.0 {
        -1
    } else {
        1
    }
}

/// A way out of a stick: the new regime, its event and the event's side (pivot side or slip
/// direction).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Exit {
    to: Regime,
    kind: EventKind,
    side: i8,
}

/// The exits of a stick, in the order of [`Model::stick_margins`]: uplift onto +x, onto −x;
/// slip toward −x, toward +x.
const STICK_EXITS: [Exit; 4] = [
    Exit { to: Regime::Rock { side: 1 }, kind: EventKind::Uplift, side: 1 },
    Exit { to: Regime::Rock { side: -1 }, kind: EventKind::Uplift, side: -1 },
    Exit { to: Regime::Slide { dir: -1 }, kind: EventKind::SlideStart, side: -1 },
    Exit { to: Regime::Slide { dir: 1 }, kind: EventKind::SlideStart, side: 1 },
];

#[derive(Clone, Copy, Debug, PartialEq)]
enum Transition {
    /// The stick ends.
    Leave(Exit),
    /// The floor uplifts a sliding block (uncoupled friction): rocking on a stuck pivot, the
    /// slide's velocity dropped.
    Uplift(Exit),
    /// The slide stops.
    Stop,
    /// Kinetic friction beyond tan α tips the sliding block onto its leading corner.
    Tip,
    /// The rocking pivot starts to slip toward this direction.
    Slip(i8),
    /// The sliding pivot stops slipping.
    Grip,
    /// θ back to 0: rebound onto the other corner, or flat.
    Impact,
    Overturn,
}

/// What the event functions of each integrated regime stand for, in their order.
const STICK_EVENTS: [Transition; 4] = [
    Transition::Leave(STICK_EXITS[0]),
    Transition::Leave(STICK_EXITS[1]),
    Transition::Leave(STICK_EXITS[2]),
    Transition::Leave(STICK_EXITS[3]),
];
const SLIDE_EVENTS: [Transition; 3] =
    [Transition::Stop, Transition::Uplift(STICK_EXITS[0]), Transition::Uplift(STICK_EXITS[1])];
const ROCK_EVENTS: [Transition; 4] =
    [Transition::Impact, Transition::Overturn, Transition::Slip(-1), Transition::Slip(1)];
const SLIDE_ROCK_EVENTS: [Transition; 3] = [Transition::Impact, Transition::Overturn, Transition::Grip];

/// An event slot a regime does not use: positive, so it never fires.
const UNUSED: f64 = 1.0;

impl Equations<4, 4> for Phase<Model<'_>, Regime> {
    type Transition = Transition;

    fn rhs(&self, t: f64, y: &[f64; 4]) -> [f64; 4] {
        self.model.rhs(self.regime, &self.seg, t, y)
    }

    fn events(&self, t: f64, state: &[f64; 4]) -> [f64; 4] {
        let (model, seg) = (&self.model, &self.seg);
        let lie = model.block.lie_angle_rad;
        match self.regime {
            Regime::Stick => model.stick_margins(seg, t),
            Regime::Slide { dir } => {
                // Uncoupled friction: the floor's acceleration uplifts a sliding block too.
                let u = if model.friction.coupled { [f64::INFINITY; 2] } else { model.uplift_margins(seg, t) };
                [f64::from(dir) * state[3], u[0], u[1], UNUSED]
            }
            Regime::Rock { side } => {
                let s = f64::from(side);
                let grip = model.grip_margins(side, seg, t, state);
                [s * state[0], lie - s * state[0], grip[0], grip[1]]
            }
            Regime::SlideRock { side, dir } => {
                let s = f64::from(side);
                [s * state[0], lie - s * state[0], f64::from(dir) * state[3], UNUSED]
            }
            Regime::Overturned => [UNUSED; 4],
        }
    }

    fn transition(&self, index: usize) -> Transition {
        let table: &[Transition] = match self.regime {
            Regime::Stick => &STICK_EVENTS,
            Regime::Slide { .. } => &SLIDE_EVENTS,
            Regime::Rock { .. } => &ROCK_EVENTS,
            Regime::SlideRock { .. } => &SLIDE_ROCK_EVENTS,
            Regime::Overturned => &[],
        };
        table[index]
    }
}

pub(super) fn simulate<S: Stepper<4>>(
    block: &Block,
    excitation: &Excitation<'_>,
    options: &Options,
    friction: Friction,
    stepper: S,
) -> Result<Response, PhysicsError> {
    let y = [options.initial_theta_rad, options.initial_theta_dot_radps, 0.0, 0.0];
    let tips_while_sliding = friction.coupled && friction.kinetic_mu > block.alpha_rad.tan();
    let model = Model { block, friction, tips_while_sliding };
    let regime = initial_side(y[0], y[1]).map_or(Regime::Stick, |side| Regime::Rock { side });
    let restitution = options.restitution.unwrap_or(block.restitution_eq24);
    Run::new(block, model, regime, restitution, (excitation, options), true).drive(y, stepper)
}

/// The sliding block's run between transitions, and what it records.
type Sliding<'a> = Run<'a, Model<'a>, Regime>;

impl Sliding<'_> {
    /// A decision at the current instant, before integrating: a regime whose own condition is
    /// already violated gives way at once.
    fn at_once(&self, seg: &Segment<2>, t: f64, y: &[f64; 4]) -> Option<Transition> {
        let model = &self.model;
        match self.regime {
            Regime::Stick => most_negative(&model.stick_margins(seg, t)).map(|i| Transition::Leave(STICK_EXITS[i])),
            Regime::Slide { .. } if !model.friction.coupled => {
                most_negative(&model.uplift_margins(seg, t)).map(|i| Transition::Uplift(STICK_EXITS[i]))
            }
            Regime::Slide { .. } if model.tips_while_sliding => Some(Transition::Tip),
            Regime::Rock { side } => {
                let m = model.grip_margins(side, seg, t, y);
                (m[0] < 0.0 || m[1] < 0.0).then(|| {
                    let [ag, av] = seg.at(t);
                    let (f, _) = model.contact(side, y, model.rocking(side, y, ag, av), ag, av);
                    Transition::Slip(slip_direction(f))
                })
            }
            _ => None,
        }
    }

    /// θ back to 0 at speed `before`: the block rebounds onto the other corner, or lies flat
    /// (still slipping if it was).
    fn impact(&mut self, t: f64, y: [f64; 4], immediate: bool) -> [f64; 4] {
        let before = y[1];
        let after = self.restitution * before;
        let (side, dir) = match self.regime {
            Regime::SlideRock { side, dir } => (side, Some(dir)),
            Regime::Rock { side } => (side, None),
            _ => unreachable!("only a rocking block impacts"),
        };
        let mut y = [0.0, after, y[2], dir.map_or(0.0, |_| y[3])];
        if rebounds(after, immediate, self.rest_speed_squared) {
            self.regime = match dir {
                Some(dir) => Regime::SlideRock { side: -side, dir },
                None => Regime::Rock { side: -side },
            };
            self.response.log(t, EventKind::Impact, -side, before, after);
        } else {
            y[1] = 0.0;
            self.regime = dir.map_or(Regime::Stick, |dir| Regime::Slide { dir });
            self.response.log(t, EventKind::Rest, 0, before, 0.0);
        }
        y
    }
}

impl<'a> Hybrid<4, 4> for Sliding<'a> {
    type Transition = Transition;
    type Equations = Phase<Model<'a>, Regime>;
    type Error = PhysicsError;

    fn course(&mut self, now: Now, y: &[f64; 4]) -> Result<Course<Transition, Self::Equations>, PhysicsError> {
        let (k, t) = (now.k, now.t);
        let seg = self.excitation.segment(k);
        if let Some(transition) = self.at_once(&seg, t, y) {
            return Ok(Course::Switch { at: t, transition });
        }
        if let Regime::SlideRock { side, dir } = self.regime {
            let [ag, av] = seg.at(t);
            let (theta_ddot, w) = self.model.slide_rocking(side, dir, y, ag, av);
            let (_, normal) = self.model.contact(side, y, theta_ddot, ag + w, av);
            if normal < 0.0 {
                return Err(PhysicsError::Stopped(format!(
                    "at t = {t:.4} s the block would leave the floor (free flight), which the sliding model does not cover"
                )));
            }
        }
        Ok(match self.regime {
            Regime::Overturned => Course::Hold,
            regime => Course::Integrate(Phase { model: self.model, regime, seg }),
        })
    }

    fn apply(&mut self, _: usize, transition: Transition, t: f64, y: [f64; 4], immediate: bool) -> [f64; 4] {
        let regime = self.regime;
        let (side, s) = match regime {
            Regime::Rock { side } | Regime::SlideRock { side, .. } => (side, f64::from(side)),
            _ => (0, 0.0),
        };
        match transition {
            Transition::Leave(exit) | Transition::Uplift(exit) => {
                self.regime = exit.to;
                self.response.log(t, exit.kind, exit.side, 0.0, 0.0);
                match transition {
                    Transition::Uplift(_) => [0.0, 0.0, y[2], 0.0],
                    _ => y,
                }
            }
            Transition::Stop => {
                self.regime = Regime::Stick;
                self.response.log(t, EventKind::Stick, 0, 0.0, 0.0);
                [0.0, 0.0, y[2], 0.0]
            }
            Transition::Tip => {
                let Regime::Slide { dir } = regime else { unreachable!("only a sliding block tips") };
                self.regime = Regime::SlideRock { side: dir, dir };
                self.response.log(t, EventKind::Uplift, dir, 0.0, 0.0);
                y
            }
            Transition::Slip(dir) => {
                self.regime = Regime::SlideRock { side, dir };
                self.response.log(t, EventKind::SlideStart, dir, y[1], y[1]);
                y
            }
            Transition::Grip => {
                // The slip stops; the decision at the next instant lets it slide back if static
                // friction cannot hold the pivot.
                self.regime = Regime::Rock { side };
                self.response.log(t, EventKind::Stick, 0, y[1], y[1]);
                [y[0], y[1], y[2], 0.0]
            }
            Transition::Impact => self.impact(t, y, immediate),
            Transition::Overturn => {
                self.regime = Regime::Overturned;
                self.response.overturn = Some((t, side));
                self.response.log(t, EventKind::Overturn, side, y[1], 0.0);
                [s * self.model.block.lie_angle_rad, 0.0, y[2], 0.0]
            }
        }
    }

    fn chatter(&self, t: f64, _: &Stats) -> PhysicsError {
        chatter("impact or stick-slip", t, self.options.rest_amplitude_rad)
    }

    fn record(&mut self, k: usize, y: &[f64; 4]) {
        let (model, regime) = (&self.model, self.regime);
        let (ag, av) = (self.excitation.horizontal_mps2[k], self.excitation.vertical(k));
        let (theta_ddot, base) = match regime {
            Regime::Stick | Regime::Overturned => (0.0, ag),
            Regime::Slide { dir } => (0.0, -f64::from(dir) * model.friction.kinetic_mu * (model.block.g_mps2 + av)),
            Regime::Rock { side } => (model.rocking(side, y, ag, av), ag),
            Regime::SlideRock { side, dir } => {
                let (theta_ddot, w) = model.slide_rocking(side, dir, y, ag, av);
                (theta_ddot, ag + w)
            }
        };
        let sensor = match regime {
            Regime::Rock { side } | Regime::SlideRock { side, .. } => {
                sensor_acceleration(model.block, side, [y[0], y[1], theta_ddot], self.sensor, base, av)
            }
            _ => (base, av),
        };
        self.response.record_motion([y[0], y[1]], theta_ddot, sensor, regime == Regime::Overturned, av);
        self.response.base_ax_mps2.push(base);
        self.response.slip_m.push(y[2]);
    }
}

#[cfg(test)]
mod tests {
    use super::super::{simulate, Method, Shape};
    use super::*;

    const G: f64 = 9.80665;

    fn rectangle(b: f64, h: f64) -> Block {
        Block::new(Shape::Rectangular { b_m: b, h_m: h, f: 0.0 }, 100.0, G).unwrap()
    }

    fn run(block: &Block, floor: &[f64], dt: f64, friction: Friction) -> Response {
        let exc = Excitation { t0_s: 0.0, dt_s: dt, horizontal_mps2: floor, vertical_mps2: None };
        simulate(block, &exc, &Options { friction: Some(friction), ..Options::default() }).unwrap()
    }

    fn times(r: &Response, kind: EventKind) -> Vec<f64> {
        r.events.iter().filter(|e| e.kind == kind).map(|e| e.time_s).collect()
    }

    #[test]
    fn a_ramp_slips_at_mu_g_and_then_follows_the_closed_form() {
        // A stocky block (tan α = 1) under a(t) = r t with μ = 0.3: it sticks until r t* = μg,
        // then slides back with u̇ = −r(t − t*)²/2, u = −r(t − t*)³/6, its top reading +μg.
        let block = rectangle(1.0, 1.0);
        let (r, mu, dt) = (2.0, 0.3, 0.005);
        let floor: Vec<f64> = (0..1001).map(|k| r * k as f64 * dt).collect();
        let resp = run(&block, &floor, dt, Friction::coulomb(mu));
        let start = mu * G / r;
        let slides = times(&resp, EventKind::SlideStart);
        assert_eq!(slides.len(), 1, "{:?}", resp.events);
        assert!((slides[0] - start).abs() < 1e-9, "slip at {} s, closed form {start} s", slides[0]);
        assert_eq!(resp.events[0].side, -1, "the floor pulls ahead toward +x: the base slips toward −x");
        for (k, (&u, &top)) in resp.slip_m.iter().zip(&resp.top_ax_mps2).enumerate() {
            let t = k as f64 * dt;
            let exact = if t > start { -r * (t - start).powi(3) / 6.0 } else { 0.0 };
            assert!((u - exact).abs() < 1e-10 * (1.0 + exact.abs()), "t = {t}: u {u} vs {exact}");
            if t > start {
                assert!((top - mu * G).abs() < 1e-12, "t = {t}: top {top}");
            } else {
                assert_eq!(top, floor[k]);
            }
        }
        assert!(resp.theta_rad.iter().all(|&th| th == 0.0), "μ < tan α: it never tips");
    }

    #[test]
    fn uncoupled_friction_rocks_as_the_nominal_block_and_slides_while_flat() {
        // The uncoupled formulation's defining property: θ(t) is the nominal (non-slipping)
        // block's, computed by the other integrator path (no friction), while the base slides when
        // flat. A slender block (tan α = 0.25) under 0.3 g at 1 Hz with μ = 0.15: the first slip
        // starts at sin ωt = μg/A (closed form), toward −x, and the top then reads +μg.
        let block = rectangle(0.25, 1.0);
        let tan = block.alpha_rad.tan();
        let (amplitude, omega, mu, dt) = (0.3 * G, std::f64::consts::TAU, 0.6 * tan, 1e-3);
        let floor: Vec<f64> = (0..4001).map(|k| amplitude * (omega * k as f64 * dt).sin()).collect();
        let uncoupled = run(&block, &floor, dt, Friction { coupled: false, ..Friction::coulomb(mu) });
        let exc = Excitation { t0_s: 0.0, dt_s: dt, horizontal_mps2: &floor, vertical_mps2: None };
        let nominal = simulate(&block, &exc, &Options::default()).unwrap();
        let rocked = nominal.theta_rad.iter().fold(0.0f64, |m, th| m.max(th.abs()));
        assert!(rocked > 0.01, "the floor must rock the block: {rocked} rad");
        for (k, (a, b)) in uncoupled.theta_rad.iter().zip(&nominal.theta_rad).enumerate() {
            // Both integrate Eq. 22 to rtol 1e-11 from the same uplift instant.
            assert!((a - b).abs() < 1e-7, "t = {} s: θ {a} vs the nominal {b}", k as f64 * dt);
        }
        let start = (mu * G / amplitude).asin() / omega;
        let slides = times(&uncoupled, EventKind::SlideStart);
        // The floor is linear between its samples: within Aω²dt²/8 = 1.5e-5 m/s² of the sine, where
        // it rises at Aω = 18 m/s³ or more, which moves the threshold crossing by up to 2e-6 s.
        assert!((slides[0] - start).abs() < 2e-6, "first slip at {} s, closed form {start} s", slides[0]);
        let uplift = times(&uncoupled, EventKind::Uplift);
        assert!(uplift.first().is_some_and(|&t| t > slides[0]), "a slide, then rocking: {:?}", uncoupled.events);
        let k = (start / dt).ceil() as usize + 1;
        assert!((uncoupled.top_ax_mps2[k] - mu * G).abs() < 1e-12, "top {} while sliding", uncoupled.top_ax_mps2[k]);
        let slipped = uncoupled.slip_m.iter().fold(0.0f64, |m, u| m.max(u.abs()));
        assert!(slipped > 5e-4, "the base slips by {slipped} m");
        // The coupled block with the same μ < tan α slides instead of rocking.
        let coupled = run(&block, &floor, dt, Friction::coulomb(mu));
        assert!(coupled.theta_rad.iter().all(|&th| th == 0.0));
    }

    /// One slip episode of a block at rest under a(t) = A sin ωt (A > μg): it starts at
    /// sin ωt_s = μg/A toward −x with u̇(t) = (A/ω)(cos ωt − cos ωt_s) + μg(t − t_s); the stop
    /// t_e is the root of u̇ after t_s (bisection), the slip u(t_e).
    fn harmonic_episode(amplitude: f64, omega: f64, mu_g: f64) -> (f64, f64, f64) {
        let ts = (mu_g / amplitude).asin() / omega;
        let v = |t: f64| amplitude / omega * ((omega * t).cos() - (omega * ts).cos()) + mu_g * (t - ts);
        let (mut lo, mut hi) = (ts + 0.5 * std::f64::consts::PI / omega, ts + 2.0 * std::f64::consts::PI / omega);
        assert!(v(lo) < 0.0 && v(hi) > 0.0);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if v(mid) < 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let te = 0.5 * (lo + hi);
        let d = te - ts;
        let slip = amplitude / (omega * omega) * ((omega * te).sin() - (omega * ts).sin())
            - amplitude / omega * (omega * ts).cos() * d
            + 0.5 * mu_g * d * d;
        (ts, te, slip)
    }

    #[test]
    fn harmonic_stick_slip_matches_the_closed_form_every_half_cycle() {
        // 1 Hz, A = 0.5 g, μ = 0.3: every half cycle slips by the same distance, alternating in
        // direction (the slip ends before the floor reverses past μg: it starts from rest each time).
        // Sampled at 0.2 ms, the floor linear between samples is the sine within Aω²dt²/8 = 1e-6 m/s².
        let block = rectangle(1.0, 1.0);
        let (amplitude, omega, mu, dt) = (0.5 * G, std::f64::consts::TAU, 0.3, 2e-4);
        let floor: Vec<f64> = (0..30_001).map(|k| amplitude * (omega * k as f64 * dt).sin()).collect();
        let resp = run(&block, &floor, dt, Friction::coulomb(mu));
        let (ts, te, slip) = harmonic_episode(amplitude, omega, mu * G);
        let (starts, stops) = (times(&resp, EventKind::SlideStart), times(&resp, EventKind::Stick));
        assert!(starts.len() >= 10 && stops.len() >= 10, "{:?}", resp.events);
        let half = std::f64::consts::PI / omega;
        for (i, (&s, &e)) in starts.iter().zip(&stops).enumerate() {
            assert!((s - ts - i as f64 * half).abs() < 1e-7, "slip {i} starts at {s}");
            assert!(
                (e - te - i as f64 * half).abs() < 1e-7,
                "slip {i} stops at {e}, closed form {}",
                te + i as f64 * half
            );
        }
        // The slip accumulated over each episode, read at the first sample after its stop.
        let at = |t: f64| resp.slip_m[(t / dt).ceil() as usize];
        let mut before = 0.0;
        for (i, &e) in stops.iter().enumerate() {
            let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
            let moved = at(e) - before;
            // The floor linear between samples departs from the sine by up to 1e-6 m/s²: ~1e-7 m here.
            assert!((moved - sign * slip).abs() < 2e-7, "episode {i}: slipped {moved} m, closed form {}", sign * slip);
            before = at(e);
        }
    }

    #[test]
    fn a_sliding_block_sticks_at_mu_s_and_slides_at_mu_k() {
        // μ_s > μ_k: the same ramp starts the slip later (at μ_s g), and the top then reads μ_k g.
        let block = rectangle(1.0, 1.0);
        let (r, dt) = (2.0, 0.005);
        let floor: Vec<f64> = (0..401).map(|k| r * k as f64 * dt).collect();
        let resp = run(&block, &floor, dt, Friction { static_mu: 0.4, kinetic_mu: 0.25, coupled: true });
        let start = times(&resp, EventKind::SlideStart)[0];
        assert!((start - 0.4 * G / r).abs() < 1e-9);
        assert!((resp.top_ax_mps2.last().unwrap() - 0.25 * G).abs() < 1e-12);
    }

    #[test]
    fn with_ample_friction_it_is_the_rocking_model() {
        let block = rectangle(0.349, 1.082);
        let dt = 0.005;
        let floor: Vec<f64> =
            (0..3000).map(|k| 4.5 * (3.0 * k as f64 * dt).sin() * (-0.1 * k as f64 * dt).exp()).collect();
        let exc = Excitation { t0_s: 0.0, dt_s: dt, horizontal_mps2: &floor, vertical_mps2: None };
        let plain = simulate(&block, &exc, &Options::default()).unwrap();
        let resp = run(&block, &floor, dt, Friction::coulomb(5.0));
        assert!(plain.count(EventKind::Uplift) >= 1 && plain.max_abs_theta() > 0.05, "{:?}", plain.events);
        let kinds = |r: &Response| r.events.iter().map(|e| (e.kind, e.side)).collect::<Vec<_>>();
        assert_eq!(kinds(&plain), kinds(&resp));
        for (a, b) in plain.events.iter().zip(&resp.events) {
            assert!((a.time_s - b.time_s).abs() < 1e-8, "{a:?} vs {b:?}");
        }
        let worst = plain.theta_rad.iter().zip(&resp.theta_rad).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-8, "max |Δθ| {worst}");
        let top = plain.top_ax_mps2.iter().zip(&resp.top_ax_mps2).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(top < 1e-6, "max |Δ top| {top}");
        assert!(resp.slip_m.iter().all(|&u| u == 0.0));
    }

    #[test]
    fn a_floor_step_past_the_uplift_threshold_starts_slide_rock_below_shenton_s_critical_mu() {
        // Shenton (1996): from rest, a floor acceleration a toward −x beyond g tan α uplifts the
        // block on its +x corner with θ̈ = −(g b + a h_c)/i₀; the pivot must carry
        // F = a + h_c θ̈ and N = g + b θ̈ per unit mass, so it slides as it uplifts when
        // μ_s < |F|/N =: μ_c(a), which grows with |a|, and rocks on a stuck pivot above. The
        // floor ramps to a₀ over the first sample interval: the slip starts where μ_c(a(t)) = μ_s.
        let block = rectangle(0.4, 1.6);
        let a0 = -1.6 * G * block.alpha_rad.tan();
        let (b, hc) = (block.half_base_m, block.cm_height_m);
        let critical = |a: f64| {
            let theta_ddot = -(G * b + a * hc) / block.i0_per_kg;
            (a + hc * theta_ddot).abs() / (G + b * theta_ddot)
        };
        assert!(critical(a0) > block.alpha_rad.tan());
        let dt = 0.005;
        let floor: Vec<f64> = (0..60).map(|k| if k == 0 { 0.0 } else { a0 }).collect();
        for (mu, slides) in [(0.99 * critical(a0), true), (1.01 * critical(a0), false)] {
            let resp = run(&block, &floor, dt, Friction::coulomb(mu));
            assert_eq!(resp.events[0].kind, EventKind::Uplift, "{:?}", resp.events);
            let uplift = resp.events[0].time_s;
            assert!((uplift - G * block.alpha_rad.tan() / a0.abs() * dt).abs() < 1e-12);
            let slip = resp.events.iter().find(|e| e.kind == EventKind::SlideStart);
            if slides {
                // μ_c(a*) = μ by bisection on the ramp's value.
                let (mut lo, mut hi) = (G * block.alpha_rad.tan(), a0.abs());
                for _ in 0..100 {
                    let mid = 0.5 * (lo + hi);
                    if critical(-mid) < mu {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                let expected = 0.5 * (lo + hi) / a0.abs() * dt;
                let slip = slip.expect("slide-rock");
                assert!(
                    (slip.time_s - expected).abs() < 2e-5,
                    "μ = {mu}: slip at {} s, Shenton {expected} s",
                    slip.time_s
                );
                assert_eq!(slip.side, 1, "the pivot slips toward +x, away from the floor's pull");
            } else {
                assert!(slip.is_none_or(|e| e.time_s > uplift + 0.01), "μ = {mu}: {:?}", resp.events);
            }
        }
    }

    #[test]
    fn agrees_with_the_independent_scipy_peer() {
        // tests/reference/sliding_scipy.py: Newton–Euler with the contact forces as unknowns,
        // solve_ivp (DOP853, rtol 1e-11) with terminal events, on floors given by formulas.
        let peer: serde_json::Value =
            serde_json::from_str(include_str!("../../../tests/reference/sliding_scipy.json")).unwrap();
        let dt = peer["dt_s"].as_f64().unwrap();
        let every = peer["every"].as_u64().unwrap() as usize;
        for case in peer["cases"].as_array().unwrap() {
            let name = case["name"].as_str().unwrap();
            let num = |key: &str| case[key].as_f64().unwrap();
            let block =
                Block::new(Shape::Rectangular { b_m: num("B_m"), h_m: num("H_m"), f: num("f") }, 100.0, G).unwrap();
            let n = case["samples"].as_u64().unwrap() as usize;
            let floor: Vec<f64> = (0..n)
                .map(|k| {
                    let t = k as f64 * dt;
                    match case["floor"].as_str().unwrap() {
                        "harmonic" => 0.5 * G * (std::f64::consts::TAU * t).sin(),
                        "decaying" => -3.5 * (4.0 * t).sin() * (-0.3 * t).exp(),
                        _ => {
                            (2.8 * (std::f64::consts::TAU * 1.3 * t).sin()
                                + 1.2 * (std::f64::consts::TAU * 3.1 * t + 0.4).sin())
                                * (t / 2.0).min(1.0)
                        }
                    }
                })
                .collect();
            let resp = run(
                &block,
                &floor,
                dt,
                Friction { static_mu: num("static_mu"), kinetic_mu: num("kinetic_mu"), coupled: true },
            );
            let events = case["events"].as_array().unwrap();
            assert_eq!(resp.events.len(), events.len(), "{name}: {:?}", resp.events);
            for (mine, theirs) in resp.events.iter().zip(events) {
                assert_eq!(mine.kind.name(), theirs["kind"].as_str().unwrap(), "{name}");
                assert_eq!(i64::from(mine.side), theirs["side"].as_i64().unwrap(), "{name}: {mine:?}");
                let t = theirs["time_s"].as_f64().unwrap();
                assert!((mine.time_s - t).abs() < 1e-6, "{name}: {mine:?} vs {t}");
            }
            let series =
                |key: &str| case[key].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect::<Vec<_>>();
            for (j, (th, u)) in series("theta_rad").iter().zip(series("slip_m")).enumerate() {
                let k = j * every;
                assert!(
                    (resp.theta_rad[k] - th).abs() < 1e-6,
                    "{name} t = {}: θ {} vs {th}",
                    k as f64 * dt,
                    resp.theta_rad[k]
                );
                assert!((resp.slip_m[k] - u).abs() < 1e-7, "{name} t = {}: u {} vs {u}", k as f64 * dt, resp.slip_m[k]);
            }
        }
    }

    #[test]
    fn adaptive_and_rk4_agree_through_slide_rock() {
        let block = rectangle(0.4, 1.6);
        let dt = 0.005;
        let floor: Vec<f64> = (0..1200)
            .map(|k| {
                let t = k as f64 * dt;
                -3.5 * (4.0 * t).sin() * (-0.3 * t).exp()
            })
            .collect();
        let friction = Friction { static_mu: 0.3, kinetic_mu: 0.27, coupled: true };
        let exc = Excitation { t0_s: 0.0, dt_s: dt, horizontal_mps2: &floor, vertical_mps2: None };
        let adaptive = run(&block, &floor, dt, friction);
        let rk4 = simulate(
            &block,
            &exc,
            &Options { friction: Some(friction), method: Method::Rk4 { dt_s: 1e-4 }, ..Options::default() },
        )
        .unwrap();
        assert!(
            adaptive.count(EventKind::SlideStart) >= 2 && adaptive.count(EventKind::Uplift) >= 1,
            "{:?}",
            adaptive.events
        );
        let kinds = |r: &Response| r.events.iter().map(|e| (e.kind, e.side)).collect::<Vec<_>>();
        assert_eq!(kinds(&adaptive), kinds(&rk4));
        let worst = adaptive.slip_m.iter().zip(&rk4.slip_m).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-6, "max |Δu| {worst} m");
    }

    #[test]
    fn bad_friction_and_combinations_are_refused() {
        let block = rectangle(0.4, 1.6);
        let floor = vec![0.0; 10];
        let exc = Excitation { t0_s: 0.0, dt_s: 0.01, horizontal_mps2: &floor, vertical_mps2: None };
        let with = |friction| Options { friction: Some(friction), ..Options::default() };
        let message = simulate(&block, &exc, &with(Friction { static_mu: 0.2, kinetic_mu: 0.3, coupled: true }))
            .unwrap_err()
            .to_string();
        assert!(message.contains("μ_k ≤ μ_s"), "{message}");
        let obstacle = Some(super::super::Obstacle { side: 1, angle_rad: 0.1, restitution: 0.5 });
        let message =
            simulate(&block, &exc, &Options { obstacle, ..with(Friction::coulomb(0.3)) }).unwrap_err().to_string();
        assert!(message.contains("does not combine with an obstacle"), "{message}");
    }
}
