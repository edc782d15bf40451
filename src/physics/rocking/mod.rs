//! The study's 2D toppling model: a rigid block on a moving floor that stays at rest, rocks on
//! alternate base corners, or overturns (Housner 1963; Yim, Chopra & Penzien 1980; Makris &
//! Roussos 2000; SEED-SUMMARY.md Eqs. 20–25 with the errata applied).
//!
//! Sign convention (the demo cases' `equipment.yaml`): x is the in-plane horizontal floor axis,
//! z is up; θ > 0 is a rotation about the +x base corner with the top moving toward +x. A floor
//! accelerating toward +x throws the block toward −x, so it uplifts with θ < 0. "Side" is the
//! sign of θ: the corner the block pivots on and the way it overturns.
//!
//! Regimes, each exact where it can be:
//! - **rest**: θ = θ̇ = 0 exactly, no integration. Uplift toward side s starts when
//!   −s·a_x > (g + a_v)·tan α (Eq. 20/21); with the floor linear between samples this is the
//!   root of a linear function, found in closed form.
//! - **rocking** about corner s (Eq. 22): θ̈ = −(mR/I₀)[(g + a_v) sin(sα − θ) + a_x cos(sα − θ)],
//!   integrated by an adaptive Dormand–Prince 5(4) (or the study's RK4) with events located on
//!   the dense output.
//! - **impact** at θ = 0: the pivot moves to the other corner and θ̇ is multiplied by the
//!   restitution e (Eq. 24: e = 1 − (mRB/I₀) sin α, B the base width, or a given e). When the
//!   rebound can no longer lift the block (it would rock less than `rest_amplitude_rad`, or the
//!   floor pushes it straight back) it returns to rest. Without this, impacts accumulate
//!   geometrically (ratio e) toward a finite time; micro-radian rocking is below what a real
//!   contact resolves, so the model ends it there.
//! - **overturned**: θ reaches the angle at which the block lies on its side (π/2 for a
//!   rectangle); it stays there.
//!
//! The model is mass-independent (only I₀/m enters); the mass is kept for reports.

use crate::physics::error::PhysicsError;
use crate::physics::hybrid::{self, Clock, Hybrid, Segment};
use crate::physics::ode::{Dopri5, Either, Rk4, Stats, Stepper};
use crate::physics::sdof::Sdof;

mod coupled;
mod rigid;
mod sliding;

/// Geometry as the cases' `equipment.yaml` states it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// Width B, height H, centre of mass raised by f·H above mid-height (Table 5, Eq. 21).
    Rectangular { b_m: f64, h_m: f64, f: f64 },
    /// Base (short side) B₁, top B₂, height H; uniform lamina (Eq. 20).
    Trapezoidal { b1_m: f64, b2_m: f64, h_m: f64 },
}

/// A rigid block with the derived quantities of the rocking equations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Block {
    pub shape: Shape,
    pub mass_kg: f64,
    pub g_mps2: f64,
    /// Half the base width: horizontal distance from the centre of mass to a pivot corner.
    pub half_base_m: f64,
    /// Height of the centre of mass above the base (Z_c).
    pub cm_height_m: f64,
    pub height_m: f64,
    /// Pivot-to-centre-of-mass distance R.
    pub r_m: f64,
    /// Critical angle α (θ_c) = atan(half base / CM height).
    pub alpha_rad: f64,
    /// I₀/m: moment of inertia about a pivot corner per unit mass.
    pub i0_per_kg: f64,
    /// Frequency parameter p = √(gR m/I₀).
    pub p_radps: f64,
    /// Eq. 24: e = 1 − (mRB/I₀) sin α.
    pub restitution_eq24: f64,
    /// Angle at which the block lies on its side after overturning.
    pub lie_angle_rad: f64,
}

impl Block {
    pub fn new(shape: Shape, mass_kg: f64, g_mps2: f64) -> Result<Self, PhysicsError> {
        let positive = |name: &'static str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(PhysicsError::NotPositive { name, value: v })
            }
        };
        positive("mass_kg", mass_kg)?;
        positive("g", g_mps2)?;
        let (half_base, cm_height, height, icm_per_kg, lie) = match shape {
            Shape::Rectangular { b_m, h_m, f } => {
                positive("B_m", b_m)?;
                positive("H_m", h_m)?;
                let hc = h_m * (0.5 + f);
                if !(hc > 0.0 && hc < h_m) {
                    return Err(PhysicsError::Parameter(format!(
                        "f = {f} puts the centre of mass outside the block (0 < H/2 + fH < H)"
                    )));
                }
                // Centroidal inertia of the uniform rectangle; f shifts the CM, not the inertia
                // (the convention of the study's Table 5 and of the demo cases).
                (0.5 * b_m, hc, h_m, (b_m * b_m + h_m * h_m) / 12.0, std::f64::consts::FRAC_PI_2)
            }
            Shape::Trapezoidal { b1_m, b2_m, h_m } => {
                positive("B1_m", b1_m)?;
                positive("B2_m", b2_m)?;
                positive("H_m", h_m)?;
                let (zc, icm) = trapezoid_centroid_and_inertia(b1_m, b2_m, h_m);
                // The side face leans out by atan((B2 − B1)/2H); it meets the floor at π/2 − lean.
                let lean = ((b2_m - b1_m) / (2.0 * h_m)).atan();
                (0.5 * b1_m, zc, h_m, icm, std::f64::consts::FRAC_PI_2 - lean)
            }
        };
        let r = half_base.hypot(cm_height);
        let alpha = half_base.atan2(cm_height);
        let i0_per_kg = icm_per_kg + r * r;
        let p = (g_mps2 * r / i0_per_kg).sqrt();
        let restitution = 1.0 - r * 2.0 * half_base / i0_per_kg * alpha.sin();
        Ok(Block {
            shape,
            mass_kg,
            g_mps2,
            half_base_m: half_base,
            cm_height_m: cm_height,
            height_m: height,
            r_m: r,
            alpha_rad: alpha,
            i0_per_kg,
            p_radps: p,
            restitution_eq24: restitution,
            lie_angle_rad: lie,
        })
    }

    /// Floor acceleration that uplifts the block at rest, for a vertical acceleration a_v.
    pub fn uplift_threshold_mps2(&self, vertical_mps2: f64) -> f64 {
        (self.g_mps2 + vertical_mps2) * self.alpha_rad.tan()
    }
}

/// Centroid height and centroidal polar inertia per unit mass of a uniform trapezoidal lamina
/// with base b1, top b2 and height h (width linear in height).
fn trapezoid_centroid_and_inertia(b1: f64, b2: f64, h: f64) -> (f64, f64) {
    let area = 0.5 * h * (b1 + b2);
    let first_moment = h * h * (b1 / 2.0 + (b2 - b1) / 3.0);
    let zc = first_moment / area;
    // ∫ w(z)³/12 dz with w linear: h (b1+b2)(b1²+b2²)/4 /12.
    let ixx = h * (b1 + b2) * (b1 * b1 + b2 * b2) / 48.0;
    let izz = h.powi(3) * (b1 / 3.0 + (b2 - b1) / 4.0);
    let i_origin = (ixx + izz) / area;
    (zc, i_origin - zc * zc)
}

/// Named blocks of the study: Table 5 (rectangular and trapezoidal equivalents of PS2 and PB1,
/// masses from Table 2) and the free-standing wire shelving WSU1 (Table 2: 0.66 m deep in the
/// shaking direction, 1.88 m tall, 43.6 kg, centre of mass at mid-height).
pub fn preset(name: &str) -> Option<(Shape, f64)> {
    Some(match name {
        "PS2" => (Shape::Rectangular { b_m: 0.349, h_m: 1.082, f: 0.0850 }, 150.0),
        "PS2_trapezoid" => (Shape::Trapezoidal { b1_m: 0.349, b2_m: 1.082, h_m: 1.082 }, 150.0),
        "PB1" => (Shape::Rectangular { b_m: 0.705, h_m: 1.500, f: 0.0526 }, 259.0),
        "PB1_trapezoid" => (Shape::Trapezoidal { b1_m: 0.705, b2_m: 1.335, h_m: 1.500 }, 259.0),
        "WSU1" => (Shape::Rectangular { b_m: 0.66, h_m: 1.88, f: 0.0 }, 43.6),
        _ => return None,
    })
}

pub const PRESETS: &[&str] = &["PS2", "PS2_trapezoid", "PB1", "PB1_trapezoid", "WSU1"];

/// Tension anchors at both base corners (after Makris & Zhang 2001): each is slack in
/// compression, elastic in tension up to its strength F (at the yield uplift of the heel),
/// perfectly plastic up to a total elongation of μ times the yield elongation, then fractured.
/// Plastic elongation is permanent: an anchor that yielded is slack until the heel lifts past it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Anchorage {
    /// F/W: anchor strength over the block's weight.
    pub strength_ratio: f64,
    /// μ: elongation at fracture over elongation at yield.
    pub ductility: f64,
    /// Block rotation at which an anchor, loaded from slack, yields (θ_y; δ_y = B sin θ_y).
    pub yield_rotation_rad: f64,
}

/// Linear isolation under the block: a base on an isolator of period T_b and damping ξ (both
/// referred to the base and block together).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IsolatedBase {
    pub period_s: f64,
    pub damping_ratio: f64,
    /// m_b/m, the base's mass over the block's: the base carries the block's reaction and
    /// impacts conserve the system's momentum (`coupled`). None: the limit m_b ≫ m, where the
    /// base moves as a prescribed SDOF that the block does not load back.
    pub mass_ratio: Option<f64>,
}

/// Coulomb friction between the block's base and the floor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Friction {
    /// μ_s: the contact slips when the horizontal force it must carry exceeds μ_s times the normal.
    pub static_mu: f64,
    /// μ_k ≤ μ_s: the friction of a slipping contact, opposing the slip.
    pub kinetic_mu: f64,
    /// true: the sliding–rocking block (a rocking pivot slips, a sliding block rocks only when
    /// friction tips it). false: the *uncoupled* simplification common in practice: the base
    /// slides only while the block is flat, rocking starts from the floor's acceleration alone
    /// (Eq. 20/21, also out of a slide, whose slip velocity it drops) and its pivot never slips.
    pub coupled: bool,
}

impl Friction {
    /// One coefficient for sticking and slipping, the sliding–rocking block.
    pub fn coulomb(mu: f64) -> Self {
        Friction { static_mu: mu, kinetic_mu: mu, coupled: true }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    /// Dormand–Prince 5(4), adaptive, events located on the dense output.
    Adaptive { rtol: f64, atol_rad: f64 },
    /// The study's classical RK4 at a fixed step, events located on a Hermite interpolant.
    Rk4 { dt_s: f64 },
}

/// A wall or neighbouring unit that stops the rotation toward one side at an angle, with a
/// rebound of its own restitution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Obstacle {
    /// The side (sign of θ) it stands on.
    pub side: i8,
    pub angle_rad: f64,
    /// θ̇ after / θ̇ before the contact, magnitudes (the rotation reverses).
    pub restitution: f64,
}

/// Part of the mass leaves at `time_s` (contents thrown): from then on the block has the
/// geometry of `after` (its centre of mass, inertia, α and p), with θ and θ̇ continuous.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MassChange {
    pub time_s: f64,
    pub after: Block,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Options {
    /// Coefficient of restitution; None uses Eq. 24.
    pub restitution: Option<f64>,
    pub anchorage: Option<Anchorage>,
    pub isolated_base: Option<IsolatedBase>,
    /// Coulomb friction between base and floor: the block sticks, slides, rocks or slides while
    /// rocking (`sliding`). None: the base never slips (the study's model).
    pub friction: Option<Friction>,
    pub obstacle: Option<Obstacle>,
    pub mass_change: Option<MassChange>,
    /// Height of the top accelerometer above the base; None: the top of the block.
    pub sensor_height_m: Option<f64>,
    /// Horizontal offset of the top accelerometer from the block's centre line, toward the corner
    /// it pivots on when rocking on side +1 (m); 0: on the centre line.
    pub sensor_offset_m: f64,
    /// After an impact whose rebound would rock the block (freely) by less than this, it is at
    /// rest again.
    pub rest_amplitude_rad: f64,
    pub initial_theta_rad: f64,
    pub initial_theta_dot_radps: f64,
    pub method: Method,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            restitution: None,
            anchorage: None,
            isolated_base: None,
            friction: None,
            obstacle: None,
            mass_change: None,
            sensor_height_m: None,
            sensor_offset_m: 0.0,
            rest_amplitude_rad: 1e-7,
            initial_theta_rad: 0.0,
            initial_theta_dot_radps: 0.0,
            // Rocking is an inverted pendulum between impacts: errors grow like e^(pt). 1e-11 keeps
            // long rocking episodes within the spread of RK4 itself at dt = 1e-4 vs 5e-5 s.
            method: Method::Adaptive { rtol: 1e-11, atol_rad: 1e-13 },
        }
    }
}

impl Options {
    /// Where the top accelerometer is in the block's frame: (offset from the centre line, height).
    fn sensor_point(&self, block: &Block) -> [f64; 2] {
        [self.sensor_offset_m, self.sensor_height_m.unwrap_or(block.height_m)]
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EventKind {
    Uplift,
    Impact,
    Rest,
    AnchorYield,
    AnchorFracture,
    /// The rotation hit the obstacle and rebounded.
    WallImpact,
    /// The block came to lean on the obstacle, or left it.
    WallLean,
    WallRelease,
    SlideStart,
    Stick,
    MassChange,
    Overturn,
}

impl EventKind {
    pub fn name(self) -> &'static str {
        match self {
            EventKind::Uplift => "uplift",
            EventKind::Impact => "impact",
            EventKind::Rest => "rest",
            EventKind::AnchorYield => "anchor_yield",
            EventKind::AnchorFracture => "anchor_fracture",
            EventKind::WallImpact => "wall_impact",
            EventKind::WallLean => "wall_lean",
            EventKind::WallRelease => "wall_release",
            EventKind::SlideStart => "slide_start",
            EventKind::Stick => "stick",
            EventKind::MassChange => "mass_change",
            EventKind::Overturn => "overturn",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Event {
    pub time_s: f64,
    pub kind: EventKind,
    /// Side (sign of θ) the block rocks on after the event (before it, for an overturn).
    pub side: i8,
    /// θ̇ just before and just after (equal except at impacts).
    pub theta_dot_before: f64,
    pub theta_dot_after: f64,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Response {
    pub theta_rad: Vec<f64>,
    pub theta_dot_radps: Vec<f64>,
    pub theta_ddot_radps2: Vec<f64>,
    /// Absolute horizontal acceleration of the top sensor point; after an overturn the sensor
    /// lies along the vertical and records the floor's vertical acceleration (as PS2's did).
    pub top_ax_mps2: Vec<f64>,
    /// Absolute kinematic acceleration of the sensor point in world axes (horizontal, vertical
    /// up), without gravity: what a sensor that turns with the body is built from.
    pub sensor_ax_mps2: Vec<f64>,
    pub sensor_az_mps2: Vec<f64>,
    /// The horizontal acceleration under the block (the floor, or the isolated base; a sliding
    /// block's base).
    pub base_ax_mps2: Vec<f64>,
    /// The base's slip relative to the floor (m) at every sample; empty without friction.
    pub slip_m: Vec<f64>,
    pub events: Vec<Event>,
    pub overturn: Option<(f64, i8)>,
    pub stats: Stats,
}

impl Response {
    pub fn count(&self, kind: EventKind) -> usize {
        self.events.iter().filter(|e| e.kind == kind).count()
    }

    pub fn max_abs_theta(&self) -> f64 {
        self.theta_rad.iter().fold(0.0, |m, t| m.max(t.abs()))
    }
}

/// Floor motion sampled at a constant step: horizontal (in-plane) and optional vertical.
#[derive(Clone, Copy, Debug)]
pub struct Excitation<'a> {
    pub t0_s: f64,
    pub dt_s: f64,
    pub horizontal_mps2: &'a [f64],
    pub vertical_mps2: Option<&'a [f64]>,
}

impl Excitation<'_> {
    fn clock(&self) -> Clock {
        Clock { t0_s: self.t0_s, dt_s: self.dt_s, samples: self.horizontal_mps2.len() }
    }

    fn vertical(&self, k: usize) -> f64 {
        self.vertical_mps2.map_or(0.0, |v| v[k])
    }

    /// The floor over sample interval k, horizontal then vertical.
    fn segment(&self, k: usize) -> Segment<2> {
        self.clock().segment(k, |j| [self.horizontal_mps2[j], self.vertical(j)])
    }
}

impl Response {
    /// An empty response for `n` samples; `slip` keeps room for the base's slip.
    fn with_capacity(n: usize, slip: bool) -> Self {
        Response {
            theta_rad: Vec::with_capacity(n),
            theta_dot_radps: Vec::with_capacity(n),
            theta_ddot_radps2: Vec::with_capacity(n),
            top_ax_mps2: Vec::with_capacity(n),
            sensor_ax_mps2: Vec::with_capacity(n),
            sensor_az_mps2: Vec::with_capacity(n),
            base_ax_mps2: Vec::with_capacity(n),
            slip_m: if slip { Vec::with_capacity(n) } else { Vec::new() },
            events: Vec::new(),
            overturn: None,
            stats: Stats::default(),
        }
    }

    fn log(&mut self, time_s: f64, kind: EventKind, side: i8, before: f64, after: f64) {
        self.events.push(Event { time_s, kind, side, theta_dot_before: before, theta_dot_after: after });
    }

    /// Records the block's motion at one sample: θ, θ̇, θ̈ and the sensor's acceleration; an
    /// overturned block's top sensor reads the vertical floor `av`.
    fn record_motion(&mut self, y: [f64; 2], theta_ddot: f64, sensor: (f64, f64), overturned: bool, av: f64) {
        self.theta_rad.push(y[0]);
        self.theta_dot_radps.push(y[1]);
        self.theta_ddot_radps2.push(theta_ddot);
        self.top_ax_mps2.push(if overturned { av } else { sensor.0 });
        self.sensor_ax_mps2.push(sensor.0);
        self.sensor_az_mps2.push(sensor.1);
    }
}

impl Block {
    /// Free rocking from θ = 0 at speed w rises to w²/(2p² sin α) (small angles): the squared
    /// rebound speed below which a block rocks less than `rest_amplitude_rad` and is at rest.
    fn rest_speed_squared(&self, rest_amplitude_rad: f64) -> f64 {
        2.0 * self.p_radps.powi(2) * self.alpha_rad.sin() * rest_amplitude_rad
    }
}

/// The side a block starting at (θ, θ̇) rocks on, None when it starts at rest.
fn initial_side(theta: f64, theta_dot: f64) -> Option<i8> {
    match (theta, theta_dot) {
        (th, _) if th != 0.0 => Some(th.signum() as i8),
        (_, w) if w != 0.0 => Some(w.signum() as i8),
        _ => None,
    }
}

/// One regime's equations over one floor segment: those of `model` in `regime` (the sliding
/// and the coupled models).
struct Phase<Mo, R> {
    model: Mo,
    regime: R,
    seg: Segment<2>,
}

/// A run of the sliding or the coupled model: its equations `model` (the part of a [`Phase`]
/// that stays), its `regime`, what it reads and the response it records. Each model's
/// `Hybrid` impl on it decides the transitions; [`Run::drive`] runs it.
struct Run<'a, Mo, R> {
    model: Mo,
    excitation: &'a Excitation<'a>,
    options: &'a Options,
    restitution: f64,
    rest_speed_squared: f64,
    /// The top accelerometer in the block's frame: (offset from the centre line, height).
    sensor: [f64; 2],
    regime: R,
    response: Response,
}

impl<'a, Mo, R> Run<'a, Mo, R> {
    /// A run from `regime` (`slip`: the response records the base's slip).
    fn new(
        block: &Block,
        model: Mo,
        regime: R,
        restitution: f64,
        (excitation, options): (&'a Excitation<'a>, &'a Options),
        slip: bool,
    ) -> Self {
        Run {
            model,
            excitation,
            options,
            restitution,
            rest_speed_squared: block.rest_speed_squared(options.rest_amplitude_rad),
            sensor: options.sensor_point(block),
            regime,
            response: Response::with_capacity(excitation.horizontal_mps2.len(), slip),
        }
    }

    /// The response from the state `y` at the record's start, its solver's figures included.
    fn drive<const E: usize>(mut self, y: [f64; 4], stepper: impl Stepper<4>) -> Result<Response, PhysicsError>
    where
        Self: Hybrid<4, E, Error = PhysicsError>,
    {
        let clock = self.excitation.clock();
        self.response.stats = hybrid::drive(&mut self, clock, MAX_TRANSITIONS_PER_SAMPLE, y, stepper)?;
        Ok(self.response)
    }
}

/// The error of a run whose `what` (impacts, stick-slip) kept switching near `t`.
fn chatter(what: &'static str, t_s: f64, rest_amplitude_rad: f64) -> PhysicsError {
    PhysicsError::Chatter { what, t_s, rest_amplitude_rad }
}

/// The most negative of `margins` (a condition that no longer holds), if any is negative.
fn most_negative(margins: &[f64]) -> Option<usize> {
    (0..margins.len()).filter(|&i| margins[i] < 0.0).min_by(|&a, &b| margins[a].total_cmp(&margins[b]))
}

/// Absolute acceleration (horizontal, vertical) of a sensor at `point` (offset d from the
/// centre line, height h) of the block while it rocks on `side` with θ, θ̇, θ̈ over a base
/// accelerating by (ax, av).
fn sensor_acceleration(block: &Block, side: i8, motion: [f64; 3], point: [f64; 2], ax: f64, av: f64) -> (f64, f64) {
    let [theta, theta_dot, acc] = motion;
    let [d, h] = point;
    let (sin, cos) = theta.sin_cos();
    // The pivot's distance from the sensor along the block's base.
    let sb = f64::from(side) * block.half_base_m - d;
    let w2 = theta_dot * theta_dot;
    // The sensor relative to the pivot: x = −sb cos θ + h sin θ, z = sb sin θ + h cos θ.
    let ax_rel = (sb * sin + h * cos) * acc + (sb * cos - h * sin) * w2;
    let az_rel = (sb * cos - h * sin) * acc - (sb * sin + h * cos) * w2;
    (ax + ax_rel, av + az_rel)
}

/// The stepper `method` asks for, with absolute tolerances `scale` × `atol_rad` per state.
fn stepper<const N: usize>(method: Method, scale: [f64; N], dt_s: f64) -> Either<N> {
    match method {
        Method::Adaptive { rtol, atol_rad } => {
            Either::Dopri5(Dopri5::new(rtol, std::array::from_fn(|i| atol_rad * scale[i]), dt_s))
        }
        Method::Rk4 { dt_s } => Either::Rk4(Rk4::new(dt_s)),
    }
}

/// Simulates the block under the floor motion; outputs are on the input time base.
pub fn simulate(block: &Block, excitation: &Excitation<'_>, options: &Options) -> Result<Response, PhysicsError> {
    check_floor(block, excitation)?;
    let dt = excitation.dt_s;
    if let Some(e) = options.restitution {
        if !(0.0..=1.0).contains(&e) {
            return Err(PhysicsError::Parameter(format!(
                "the coefficient of restitution must be within 0..1, got {e}"
            )));
        }
    }
    if let Some(f) = options.friction {
        check_friction(&f, options)?;
        // Slip and slip velocity to the same absolute tolerance (m, m/s).
        let p = block.p_radps;
        return sliding::simulate(block, excitation, options, f, stepper(options.method, [1.0, p, 1.0, p], dt));
    }
    if let Some(o) = options.obstacle {
        if !(o.side.abs() == 1
            && o.angle_rad > 0.0
            && o.angle_rad < block.lie_angle_rad
            && (0.0..=1.0).contains(&o.restitution))
        {
            return Err(PhysicsError::Parameter(format!("the obstacle needs side ±1, an angle between 0 and the lying angle and a restitution in 0..1, got {o:?}")));
        }
    }
    let base_ax = match options.isolated_base {
        Some(iso) => {
            if let Some(ratio) = check_isolated_base(&iso, options)? {
                // Base displacement and velocity to the same absolute tolerance (m, m/s).
                let scale = [1.0, block.p_radps, 1.0, 1.0];
                return coupled::simulate(block, excitation, options, &iso, ratio, stepper(options.method, scale, dt));
            }
            Sdof::new(1.0 / iso.period_s, iso.damping_ratio).absolute_acceleration(excitation.horizontal_mps2, dt)
        }
        None => excitation.horizontal_mps2.to_vec(),
    };
    rigid::simulate(block, excitation, &base_ax, options, stepper(options.method, [1.0, block.p_radps], dt))
}

/// Refuses a floor record the models cannot run on.
fn check_floor(block: &Block, excitation: &Excitation<'_>) -> Result<(), PhysicsError> {
    let n = excitation.horizontal_mps2.len();
    let dt = excitation.dt_s;
    if n < 2 {
        return Err(PhysicsError::TooFewSamples(n));
    }
    if !(dt.is_finite() && dt > 0.0) {
        return Err(PhysicsError::SampleInterval(dt));
    }
    if let Some(v) = excitation.vertical_mps2 {
        if v.len() != n {
            return Err(PhysicsError::Floor(format!(
                "horizontal and vertical records differ in length ({n} vs {})",
                v.len()
            )));
        }
    }
    for k in 0..n {
        let (ax, av) = (excitation.horizontal_mps2[k], excitation.vertical(k));
        if !ax.is_finite() || !av.is_finite() {
            return Err(PhysicsError::NotFinite { sample: k, t_s: excitation.t0_s + k as f64 * dt });
        }
        if block.g_mps2 + av <= 0.0 {
            return Err(PhysicsError::Floor(format!(
                "at t = {} s the floor falls faster than gravity (vertical {av} m/s^2): the block would fly, which the model does not cover",
                excitation.t0_s + k as f64 * dt
            )));
        }
    }
    Ok(())
}

/// Refuses friction coefficients out of order and what the sliding block does not combine with.
fn check_friction(f: &Friction, options: &Options) -> Result<(), PhysicsError> {
    if !(f.static_mu.is_finite() && f.kinetic_mu > 0.0 && f.kinetic_mu <= f.static_mu) {
        return Err(PhysicsError::Parameter(format!(
            "friction needs 0 < μ_k ≤ μ_s (finite), got μ_s = {}, μ_k = {}",
            f.static_mu, f.kinetic_mu
        )));
    }
    let other = [
        (options.anchorage.is_some(), "anchorage"),
        (options.isolated_base.is_some(), "an isolated base"),
        (options.obstacle.is_some(), "an obstacle"),
        (options.mass_change.is_some(), "a mass change"),
    ];
    if let Some((_, what)) = other.iter().find(|(given, _)| *given) {
        return Err(PhysicsError::Parameter(format!("the sliding block (friction) does not combine with {what}")));
    }
    Ok(())
}

/// Checks the isolated base; returns its mass ratio when the base is coupled to the block.
fn check_isolated_base(iso: &IsolatedBase, options: &Options) -> Result<Option<f64>, PhysicsError> {
    if !(iso.period_s > 0.0 && (0.0..1.0).contains(&iso.damping_ratio)) {
        return Err(PhysicsError::Parameter(format!(
            "the isolated base needs a positive period and a damping ratio in [0, 1), got T_b = {} s, ξ = {}",
            iso.period_s, iso.damping_ratio
        )));
    }
    let Some(ratio) = iso.mass_ratio else { return Ok(None) };
    if !(ratio.is_finite() && ratio > 0.0) {
        return Err(PhysicsError::Parameter(format!(
            "the base's mass ratio m_b/m must be a positive number, got {ratio}"
        )));
    }
    let other = [
        (options.anchorage.is_some(), "anchorage"),
        (options.obstacle.is_some(), "an obstacle"),
        (options.mass_change.is_some(), "a mass change"),
    ];
    if let Some((_, what)) = other.iter().find(|(given, _)| *given) {
        return Err(PhysicsError::Parameter(format!(
            "the coupled isolated base (a base mass ratio) does not combine with {what}; leave the mass ratio out for a prescribed base motion"
        )));
    }
    Ok(Some(ratio))
}

/// Impacts and regime changes allowed within one sample interval before the run is declared
/// stuck (impact chatter that the rest criterion should have ended).
const MAX_TRANSITIONS_PER_SAMPLE: usize = 10_000;

#[cfg(test)]
mod tests {
    use super::*;

    const G: f64 = 9.81;

    fn rectangle(b: f64, h: f64, f: f64) -> Block {
        Block::new(Shape::Rectangular { b_m: b, h_m: h, f }, 100.0, G).unwrap()
    }

    fn quiet_floor(n: usize) -> Vec<f64> {
        vec![0.0; n]
    }

    #[test]
    fn derived_quantities_match_the_demo_cases_equipment_files() {
        // ../shared/cases/demo/demo_01/equipment.yaml (PS2, written by an independent generator):
        // hc 0.63297, alpha 0.269002, R 0.656583, I0 80.8218 kg m^2 (150 kg), p 3.45749, e 0.886973.
        let b = Block::new(Shape::Rectangular { b_m: 0.349, h_m: 1.082, f: 0.085 }, 150.0, G).unwrap();
        assert!((b.cm_height_m - 0.63297).abs() < 5e-6);
        assert!((b.alpha_rad - 0.269002).abs() < 5e-7);
        assert!((b.r_m - 0.656583).abs() < 5e-7);
        assert!((b.i0_per_kg * 150.0 - 80.8218).abs() < 5e-5);
        assert!((b.p_radps - 3.45749).abs() < 5e-6);
        assert!((b.restitution_eq24 - 0.886973).abs() < 5e-7);
        // A centred rectangle: e = 1 − 1.5 sin²α (SEED-SUMMARY.md, Eq. 24).
        let c = rectangle(0.66, 1.88, 0.0);
        assert!((c.restitution_eq24 - (1.0 - 1.5 * c.alpha_rad.sin().powi(2))).abs() < 1e-14);
    }

    #[test]
    fn trapezoids_reduce_to_rectangles_and_match_table_5_equivalents() {
        let square = Block::new(Shape::Trapezoidal { b1_m: 0.5, b2_m: 0.5, h_m: 1.5 }, 1.0, G).unwrap();
        let rect = rectangle(0.5, 1.5, 0.0);
        assert!((square.i0_per_kg - rect.i0_per_kg).abs() < 1e-14);
        assert!((square.cm_height_m - rect.cm_height_m).abs() < 1e-15);
        assert_eq!(square.lie_angle_rad, std::f64::consts::FRAC_PI_2);
        // Table 5 gives each trapezoid a rectangle with the same base, height and CM height
        // (f printed to 3 digits): Z_c = H (0.5 + f) within that rounding (0.3 %).
        for (trap, rect) in [("PS2_trapezoid", "PS2"), ("PB1_trapezoid", "PB1")] {
            let (ts, m) = preset(trap).unwrap();
            let (rs, _) = preset(rect).unwrap();
            let (t, r) = (Block::new(ts, m, G).unwrap(), Block::new(rs, m, G).unwrap());
            let rel = (t.cm_height_m - r.cm_height_m).abs() / r.cm_height_m;
            assert!(rel < 3e-3, "{trap}: Z_c {} vs {} ({rel})", t.cm_height_m, r.cm_height_m);
            assert_eq!(t.half_base_m, r.half_base_m);
        }
    }

    /// Housner (1963): free rocking from rest at θ₀ reaches θ = 0 after
    /// t = ∫₀^θ₀ dθ / √(2p²[cos(α − θ) − cos(α − θ₀)]) (energy conservation), which for slender
    /// blocks is acosh(1/(1 − θ₀/α))/p.
    fn housner_quarter_period(p: f64, alpha: f64, theta0: f64) -> f64 {
        // θ = θ₀ − w² removes the endpoint singularity; composite Gauss–Legendre on w.
        let integrand = |w: f64| {
            let th = theta0 - w * w;
            let d = (alpha - theta0).cos() - (alpha - th).cos();
            if w == 0.0 {
                2.0 / (2.0 * p * p * (alpha - theta0).sin()).sqrt()
            } else {
                2.0 * w / (2.0 * p * p * d).sqrt()
            }
        };
        let (nodes, weights) = (
            [-0.906179845938664, -0.538469310105683, 0.0, 0.538469310105683, 0.906179845938664],
            [0.236926885056189, 0.478628670499366, 0.568888888888889, 0.478628670499366, 0.236926885056189],
        );
        let (a, b, panels) = (0.0, theta0.sqrt(), 400);
        let h = (b - a) / panels as f64;
        (0..panels)
            .map(|i| {
                let mid = a + (i as f64 + 0.5) * h;
                nodes.iter().zip(&weights).map(|(x, w)| w * integrand(mid + 0.5 * h * x)).sum::<f64>() * 0.5 * h
            })
            .sum()
    }

    #[test]
    fn free_rocking_matches_housner_and_loses_eq24_velocity_at_each_impact() {
        for (b, h, f, ratio) in [(0.349, 1.082, 0.085, 0.5), (0.2, 4.0, 0.0, 0.8), (0.66, 1.88, 0.0, 0.3)] {
            let block = rectangle(b, h, f);
            let theta0 = ratio * block.alpha_rad;
            let dt = 0.005;
            let floor = quiet_floor(2000);
            let options = Options { initial_theta_rad: theta0, ..Options::default() };
            let r = simulate(
                &block,
                &Excitation { t0_s: 0.0, dt_s: dt, horizontal_mps2: &floor, vertical_mps2: None },
                &options,
            )
            .unwrap();
            let impacts: Vec<&Event> = r.events.iter().filter(|e| e.kind == EventKind::Impact).collect();
            assert!(impacts.len() >= 3, "{:?}", r.events);
            let expected = housner_quarter_period(block.p_radps, block.alpha_rad, theta0);
            assert!(
                (impacts[0].time_s - expected).abs() < 1e-8,
                "first impact at {} s, Housner {expected} s",
                impacts[0].time_s
            );
            if block.alpha_rad < 0.06 {
                // The slender-block closed form holds to O(α²).
                let linear = (1.0 / (1.0 - ratio)).acosh() / block.p_radps;
                assert!((impacts[0].time_s - linear).abs() / linear < block.alpha_rad.powi(2));
            }
            for e in &impacts {
                let measured = e.theta_dot_after / e.theta_dot_before;
                assert!((measured - block.restitution_eq24).abs() < 1e-12, "velocity ratio {measured}");
                // θ̇ keeps its sign through the impact: the block swings on onto the other corner.
                assert!(e.theta_dot_before * f64::from(e.side) > 0.0);
            }
            assert!(r.overturn.is_none());
        }
    }

    #[test]
    fn below_the_uplift_threshold_the_block_never_moves() {
        let block = rectangle(0.349, 1.082, 0.085);
        let threshold = block.uplift_threshold_mps2(0.0);
        let n = 4000;
        let floor: Vec<f64> = (0..n).map(|k| 0.999 * threshold * (k as f64 * 0.01).sin()).collect();
        let r = simulate(
            &block,
            &Excitation { t0_s: 0.0, dt_s: 0.005, horizontal_mps2: &floor, vertical_mps2: None },
            &Options::default(),
        )
        .unwrap();
        assert!(r.theta_rad.iter().chain(&r.theta_dot_radps).all(|&v| v == 0.0));
        assert_eq!(r.top_ax_mps2, floor, "at rest the top moves with the floor");
        assert!(r.events.is_empty());
        // Just above, it uplifts exactly where the linear floor crosses the threshold.
        let floor: Vec<f64> = (0..n).map(|k| -1.001 * threshold * (k as f64 * 0.01).sin()).collect();
        let r = simulate(
            &block,
            &Excitation { t0_s: 0.0, dt_s: 0.005, horizontal_mps2: &floor, vertical_mps2: None },
            &Options::default(),
        )
        .unwrap();
        let first = r.events[0];
        assert_eq!((first.kind, first.side), (EventKind::Uplift, 1));
        let k = (first.time_s / 0.005).floor() as usize;
        assert!(-floor[k] <= threshold && -floor[k + 1] > threshold);
    }

    #[test]
    fn mirrored_floor_gives_a_mirrored_response() {
        let block = rectangle(0.8, 4.0, 0.03);
        let n = 3000;
        // Two seconds of 3 Hz shaking at 1.5 times the uplift threshold, then free rocking.
        let floor: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 * 0.005;
                if t < 2.0 {
                    3.0 * (6.0 * std::f64::consts::PI * t).sin() + 0.5 * (23.0 * t).sin()
                } else {
                    0.0
                }
            })
            .collect();
        let vertical: Vec<f64> = (0..n).map(|k| 0.8 * (11.0 * k as f64 * 0.005).sin()).collect();
        let mirrored: Vec<f64> = floor.iter().map(|v| -v).collect();
        let run = |h: &[f64]| {
            simulate(
                &block,
                &Excitation { t0_s: 0.0, dt_s: 0.005, horizontal_mps2: h, vertical_mps2: Some(&vertical) },
                &Options::default(),
            )
            .unwrap()
        };
        let (a, b) = (run(&floor), run(&mirrored));
        assert!(a.count(EventKind::Impact) > 3, "{:?}", a.events);
        for (x, y) in a.theta_rad.iter().zip(&b.theta_rad) {
            assert!((x + y).abs() < 1e-12, "{x} vs {y}");
        }
        assert_eq!(a.events.len(), b.events.len());
    }

    #[test]
    fn an_accelerometer_off_the_centre_line_reads_its_point_s_second_derivative() {
        // Free rocking on a still floor: the pivot stays put, so a body point (d, h) is at
        // (s·b, 0) + ((d − s·b) cos θ + h sin θ, −(d − s·b) sin θ + h cos θ) while the block rocks
        // on side s = sign θ. Its acceleration by central differences of the recorded θ must be
        // what the model reports.
        let block = rectangle(0.6, 1.5, 0.0);
        let (dt, n) = (1e-3, 3000);
        let floor = quiet_floor(n);
        let exc = Excitation { t0_s: 0.0, dt_s: dt, horizontal_mps2: &floor, vertical_mps2: None };
        let (d, h) = (-0.12, 1.1);
        let options = Options {
            initial_theta_rad: 0.2,
            sensor_offset_m: d,
            sensor_height_m: Some(h),
            rest_amplitude_rad: 1e-9,
            ..Options::default()
        };
        let r = simulate(&block, &exc, &options).unwrap();
        assert!(r.count(EventKind::Impact) >= 2, "the block should rock across sides: {:?}", r.events);
        let b = block.half_base_m;
        let at = |k: usize, s: f64| {
            let (sin, cos) = r.theta_rad[k].sin_cos();
            [s * b + (d - s * b) * cos + h * sin, -(d - s * b) * sin + h * cos]
        };
        let mut checked = 0;
        for k in 1..n - 1 {
            if r.theta_rad[k] == 0.0 {
                continue;
            }
            let s = r.theta_rad[k].signum();
            let near_impact = r.events.iter().any(|e| (e.time_s - k as f64 * dt).abs() < 3.0 * dt);
            if near_impact || r.theta_rad[k - 1].signum() != s || r.theta_rad[k + 1].signum() != s {
                continue;
            }
            let (before, now, after) = (at(k - 1, s), at(k, s), at(k + 1, s));
            for (axis, reported) in [(0, r.sensor_ax_mps2[k]), (1, r.sensor_az_mps2[k])] {
                let differenced = (before[axis] - 2.0 * now[axis] + after[axis]) / (dt * dt);
                assert!(
                    (differenced - reported).abs() < 1e-3,
                    "t {:.3} s axis {axis}: {differenced} vs {reported}",
                    k as f64 * dt
                );
            }
            checked += 1;
        }
        assert!(checked > n / 2, "only {checked} samples checked");
    }

    #[test]
    fn adaptive_and_rk4_agree() {
        let block = rectangle(0.349, 1.082, 0.085);
        let n = 4000;
        let floor: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 * 0.005;
                4.5 * (3.0 * t).sin() * (-0.1 * t).exp()
            })
            .collect();
        let exc = Excitation { t0_s: 0.0, dt_s: 0.005, horizontal_mps2: &floor, vertical_mps2: None };
        let adaptive = simulate(&block, &exc, &Options::default()).unwrap();
        let rk4 =
            simulate(&block, &exc, &Options { method: Method::Rk4 { dt_s: 1e-4 }, ..Options::default() }).unwrap();
        let kinds = |r: &Response| r.events.iter().map(|e| (e.kind, e.side)).collect::<Vec<_>>();
        assert_eq!(kinds(&adaptive), kinds(&rk4));
        let max_diff = adaptive.theta_rad.iter().zip(&rk4.theta_rad).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(max_diff < 1e-6, "max |Δθ| = {max_diff}");
        assert!(adaptive.stats.rhs_evals * 20 < rk4.stats.rhs_evals, "{:?} vs {:?}", adaptive.stats, rk4.stats);
    }

    #[test]
    fn a_strong_pulse_overturns_toward_the_side_it_throws_the_block() {
        let block = rectangle(0.349, 1.082, 0.085);
        let n = 1000;
        // A long push toward +x throws the block toward −x.
        let floor: Vec<f64> = (0..n).map(|k| if k < 200 { 8.0 } else { 0.0 }).collect();
        let r = simulate(
            &block,
            &Excitation { t0_s: 0.0, dt_s: 0.005, horizontal_mps2: &floor, vertical_mps2: None },
            &Options::default(),
        )
        .unwrap();
        let (time, side) = r.overturn.expect("overturns");
        assert_eq!(side, -1);
        assert!(time > 0.0 && time < 5.0);
        let last = *r.theta_rad.last().unwrap();
        assert_eq!(last, -std::f64::consts::FRAC_PI_2);
        assert_eq!(*r.top_ax_mps2.last().unwrap(), 0.0, "after overturn the sensor reads the (zero) vertical floor");
    }
}
