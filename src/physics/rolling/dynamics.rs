//! Equations of motion of the caster cart, in the floor frame (which only translates, so the
//! floor's acceleration ü enters as the inertial load −m ü on every mass).
//!
//! State layout shared by both models: y[0..3] = (x, y, θ), y[3..7] = δ₁..δ₄ (unwrapped),
//! y[7..10] = ν = (ẋ, ẏ, ω). The lateral-slip model adds y[10..14] = ψ̇₁..ψ̇₄.
//!
//! Per caster i (4WMC-NOTES.md): pivot rᵢ = R(θ)pᵢ from the platform centre, heading
//! eᵢ = (cos ψᵢ, sin ψᵢ), nᵢ = k × eᵢ, aᵢ = [eᵢ; rᵢ×eᵢ], bᵢ = [nᵢ; rᵢ×nᵢ], so that e·v_pivot = aᵢᵀν
//! and n·v_pivot = bᵢᵀν. Without lateral slip the wheel centre moves along eᵢ at aᵢᵀν, the wheel
//! spins at aᵢᵀν/r and the caster yaws at ψ̇ᵢ = bᵢᵀν/d; Kane's equations (generalised speeds ν)
//! give M(q)ν̇ = Q_floor + Q_friction − Σ Jᵀm J̇ν with
//! M = diag(m_p, m_p, I_p) + Σ (m_w + I_s/r²) aᵢaᵢᵀ + (I_z/d²) bᵢbᵢᵀ and, with ėᵢ = ψ̇ᵢnᵢ and
//! ṙᵢ = ω k×rᵢ, ȧᵢᵀν = (bᵢᵀν)²/d − ω²(rᵢ·eᵢ), ḃᵢᵀν = −(aᵢᵀν)(bᵢᵀν)/d − ω²(rᵢ·nᵢ).

use super::{Cart, Friction, LateralSlip, PIVOT_SIGNS};
use crate::physics::error::PhysicsError;

/// What the nominal cart leaves out: the diagnosis's rolling effects, each a physics added to
/// the no-slip model ([`NoSlip::altered`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Alteration {
    pub mass: Option<MassChange>,
    pub brake: Option<Brake>,
    /// A caster whose swivel no longer turns, or turns only against a lock's friction.
    pub jam: Option<Jam>,
    pub wall: Option<Wall>,
    /// The mass change and the brake's drag build up linearly over this time (s) from the
    /// alteration's start (0: at once): bottles falling off one by one, a pad whose drag grows.
    /// [`simulate_altered`](super::simulate_altered) runs it as a staircase of constant pieces.
    pub ramp_s: f64,
}

impl Alteration {
    /// The alteration with its mass change and brake drag at `fraction` of their full size (the
    /// jam and the wall are not ramped).
    pub fn scaled(&self, fraction: f64) -> Alteration {
        Alteration {
            mass: self.mass.map(|m| MassChange { dm_kg: fraction * m.dm_kg, ..m }),
            brake: self.brake.map(|b| Brake { mu: fraction * b.mu, ..b }),
            ..*self
        }
    }

    /// Whether anything builds up over `ramp_s`.
    pub fn ramped(&self) -> bool {
        self.ramp_s > 0.0 && (self.mass.is_some() || self.brake.is_some())
    }
}

/// A point mass `dm_kg` (negative: lost) at body offset `at_m` from the platform centre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MassChange {
    pub dm_kg: f64,
    pub at_m: [f64; 2],
}

/// A jammed swivel (caster 0-based): rigid (`mu` None: δ̇ ≡ 0, a constraint on the platform's
/// motion) or a friction lock (`mu` Some(μ): a swivel torque μ N ρ tanh(δ̇/[`JAM_EPS_RADPS`]) in
/// place of the swivel's own friction, which holds the caster until the platform's pull on it
/// exceeds μ N ρ, then lets it slip: a bent or fouled swivel rather than a seized one).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Jam {
    pub caster: usize,
    pub mu: Option<f64>,
}

/// A friction lock's regularisation (rad/s): stiff enough to hold, finite so that it can slip
/// (the swivel's own ε, `friction_eps_swivel`, is as small as 1e-3 rad/s and would make every
/// fitted lock a stiff run).
pub const JAM_EPS_RADPS: f64 = 0.02;

/// The least regularisation of a locked wheel's drag (m/s). A wheel that rolls crosses zero
/// speed only at reversals; a locked one drags through every reversal, and at the rolling law's
/// ε (1e-4 m/s in the study's tables) each crossing is a stiff stretch that costs an explicit
/// integrator some 40 times the nominal cart's work. At 2e-3 m/s a held wheel creeps at most
/// 2 mm/s under a pull just short of μ N, about the camera's noise per second, and the run costs
/// about what the nominal one does.
pub const BRAKE_EPS_MPS: f64 = 2e-3;

/// A locked wheel (caster 0-based): it slides along its heading with friction μ N tanh(v/ε),
/// ε at least [`BRAKE_EPS_MPS`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Brake {
    pub caster: usize,
    pub mu: f64,
}

/// A wall across floor axis `axis` (0 = X, 1 = Y) at `position_m` (the platform-centre
/// displacement frame: 0 is the centre's start), on side `side` (+1: beyond, −1: before), struck
/// by the platform's corners: a contact of duration `contact_s` with restitution `restitution`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wall {
    pub axis: usize,
    pub side: f64,
    pub position_m: f64,
    pub restitution: f64,
    pub contact_s: f64,
    /// false: a stiff wall, its spring and dashpot scaled by the striking corner's effective mass
    /// (the rebound is e whatever the pose). true: a compliant neighbour (a bed's frame or
    /// mattress), a Kelvin–Voigt contact of fixed stiffness k = m ω² and damping c = 2ζωm with m
    /// the cart's mass, that only pushes (the force is clamped at zero as the corner leaves).
    pub neighbour: bool,
}

/// What a model offers the simulation driver.
pub trait Dynamics<const N: usize> {
    /// dy/dt under the floor acceleration `floor` = (ü_X, ü_Y).
    fn rhs(&self, y: &[f64; N], floor: [f64; 2]) -> [f64; N];
    fn kinetic_energy(&self, y: &[f64; N]) -> f64;
    /// Power of the floor's inertial loads and of friction (negative: dissipated).
    fn power(&self, y: &[f64; N], floor: [f64; 2]) -> Power;
    /// δ̇ of each caster.
    fn swivel_rates(&self, y: &[f64; N]) -> [f64; 4];
    /// The forces on the cart at rest, for its exact stick; None when the model cannot stick exactly.
    fn rest_forces(&self, y: &[f64; N]) -> Option<RestForces>;
    fn derived(&self) -> &Derived;
}

/// At rest: the generalised force of the floor's inertial load as a 3×2 map of ü, and the
/// static-friction generators (each a friction element's force direction times its capacity).
pub type RestForces = ([[f64; 2]; 3], [[f64; 3]; 8]);

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Power {
    pub floor_w: f64,
    pub friction_w: f64,
}

/// Constants the equations use.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Derived {
    pub half_length_m: f64,
    pub half_width_m: f64,
    pub wheel_radius_m: f64,
    pub trail_m: f64,
    pub swivel_arm_m: f64,
    pub platform_mass_kg: f64,
    pub wheel_mass_kg: f64,
    /// Platform yaw inertia m_p(a² + b²)/3.
    pub platform_inertia: f64,
    /// Wheel spin inertia ½ m_w r².
    pub spin_inertia: f64,
    /// Wheel inertia about a vertical diameter m_w(3r² + w²)/12.
    pub yaw_inertia: f64,
    /// Normal load per wheel (m_w + m_p/4) g, as in the study.
    pub normal_n: f64,
    pub total_mass_kg: f64,
    /// Pivots in body coordinates, wheel order 1..4.
    pub pivots: [[f64; 2]; 4],
}

impl Derived {
    pub fn new(cart: &Cart, g_mps2: f64) -> Self {
        let (a, b) = (0.5 * cart.length_m, 0.5 * cart.width_m);
        let r = 0.5 * cart.wheel_diameter_m;
        let (m_p, m_w) = (cart.platform_mass_kg, cart.wheel_mass_kg);
        Derived {
            half_length_m: a,
            half_width_m: b,
            wheel_radius_m: r,
            trail_m: cart.trail_m,
            swivel_arm_m: cart.swivel_arm_m,
            platform_mass_kg: m_p,
            wheel_mass_kg: m_w,
            platform_inertia: m_p * (a * a + b * b) / 3.0,
            spin_inertia: 0.5 * m_w * r * r,
            yaw_inertia: m_w * (3.0 * r * r + cart.wheel_width_m * cart.wheel_width_m) / 12.0,
            normal_n: (m_w + 0.25 * m_p) * g_mps2,
            total_mass_kg: m_p + 4.0 * m_w,
            pivots: PIVOT_SIGNS.map(|(sx, sy)| [sx * a, sy * b]),
        }
    }
}

/// One caster's kinematic frame at the current pose.
#[derive(Clone, Copy, Debug)]
struct Frame {
    e: [f64; 2],
    n: [f64; 2],
    r: [f64; 2],
    r_cross_e: f64,
    r_cross_n: f64,
    r_dot_e: f64,
    r_dot_n: f64,
}

impl Frame {
    fn a(&self) -> [f64; 3] {
        [self.e[0], self.e[1], self.r_cross_e]
    }
    fn b(&self) -> [f64; 3] {
        [self.n[0], self.n[1], self.r_cross_n]
    }
}

fn frames(derived: &Derived, theta: f64, deltas: &[f64]) -> [Frame; 4] {
    let (s_th, c_th) = theta.sin_cos();
    std::array::from_fn(|i| {
        let (s_d, c_d) = deltas[i].sin_cos();
        // ψ = θ + δ by the angle-sum formulas: one sin_cos per caster instead of two.
        let e = [c_th * c_d - s_th * s_d, s_th * c_d + c_th * s_d];
        let n = [-e[1], e[0]];
        let [px, py] = derived.pivots[i];
        let r = [c_th * px - s_th * py, s_th * px + c_th * py];
        Frame {
            e,
            n,
            r,
            r_cross_e: r[0] * e[1] - r[1] * e[0],
            r_cross_n: r[0] * n[1] - r[1] * n[0],
            r_dot_e: r[0] * e[0] + r[1] * e[1],
            r_dot_n: r[0] * n[0] + r[1] * n[1],
        }
    })
}

fn dot3(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Friction with its regularised sign: coefficient(speed) × capacity × tanh(x), signed like x,
/// where x is the motion over its regularisation scale (v/ε, or δ̇/ε_sw for the swivel).
fn friction_force(law: &super::Stribeck, normal_n: f64, speed: f64, x: f64) -> f64 {
    // tanh|x| = −expm1(−2|x|)/(2 + expm1(−2|x|)): one call, exact near zero, odd by copysign.
    let m = (-2.0 * x.abs()).exp_m1();
    law.coefficient(speed) * normal_n * (-m / (2.0 + m)).copysign(x)
}

impl super::Friction {
    /// Rolling-resistance force at wheel speed v and swivel torque at swivel rate δ̇ (arm ρ).
    fn roll_and_swivel(&self, normal_n: f64, rho: f64, roll_speed: f64, swivel_rate: f64) -> (f64, f64) {
        (
            friction_force(&self.roll, normal_n, roll_speed, roll_speed / self.eps_mps),
            rho * friction_force(&self.swivel, normal_n, rho * swivel_rate, swivel_rate / self.eps_swivel_radps),
        )
    }
}

/// The constrained model: no lateral slip, 3 platform DOF, 10 states.
#[derive(Clone, Copy, Debug)]
pub struct NoSlip {
    pub derived: Derived,
    pub friction: Friction,
    /// Per caster, m_w + I_s/r²: the inertia a caster adds along its heading (m_w alone for a
    /// locked wheel, which does not spin).
    k_roll: [f64; 4],
    /// I_z/d²: the caster's yaw inertia seen by the pivot's sideways speed.
    k_yaw: f64,
    /// What the nominal cart leaves out (nothing for [`NoSlip::new`]).
    alteration: Alteration,
    /// Normal load per wheel (all `derived.normal_n` unless a mass change moved the centre of mass).
    loads: [f64; 4],
    /// Σ m ρ of the platform about its centre, body frame (zero: the centre of mass is the centre).
    first_moment: [f64; 2],
}

impl NoSlip {
    pub fn new(cart: &Cart, friction: &Friction, g_mps2: f64) -> Self {
        let derived = Derived::new(cart, g_mps2);
        let r = derived.wheel_radius_m;
        let d = derived.trail_m;
        NoSlip {
            derived,
            friction: *friction,
            k_roll: [derived.wheel_mass_kg + derived.spin_inertia / (r * r); 4],
            k_yaw: derived.yaw_inertia / (d * d),
            alteration: Alteration::default(),
            loads: [derived.normal_n; 4],
            first_moment: [0.0; 2],
        }
    }

    /// The cart with an [`Alteration`]: a point mass added (or removed) at a body offset, which
    /// changes the platform's mass, yaw inertia about its centre, centre of mass and the wheel
    /// loads (a rigid platform on four equal supports: Nᵢ = m_w g + W/4 (1 + c_x sᵢₓ/a + c_y sᵢᵧ/b));
    /// one wheel locked (it drags with μ Nᵢ and no longer spins); one swivel jammed (δ̇ⱼ ≡ 0, a
    /// constraint on ν, or held by a friction lock); a wall struck by the platform's corners.
    pub fn altered(
        cart: &Cart,
        friction: &Friction,
        g_mps2: f64,
        alteration: &Alteration,
    ) -> Result<Self, PhysicsError> {
        let mut model = NoSlip::new(cart, friction, g_mps2);
        model.alteration = *alteration;
        let dv = &mut model.derived;
        if let Some(change) = alteration.mass {
            let m = dv.platform_mass_kg + change.dm_kg;
            let inertia = dv.platform_inertia + change.dm_kg * (change.at_m[0].powi(2) + change.at_m[1].powi(2));
            if !(m > 0.0 && inertia > 0.0 && change.at_m.iter().all(|v| v.is_finite())) {
                return Err(PhysicsError::Parameter(format!(
                    "a mass change of {} kg at ({}, {}) m leaves no platform",
                    change.dm_kg, change.at_m[0], change.at_m[1]
                )));
            }
            model.first_moment = change.at_m.map(|v| change.dm_kg * v);
            let centre = model.first_moment.map(|s| s / m);
            for (i, (sx, sy)) in super::PIVOT_SIGNS.iter().enumerate() {
                let share = 0.25 * (1.0 + centre[0] * sx / dv.half_length_m + centre[1] * sy / dv.half_width_m);
                model.loads[i] = (dv.wheel_mass_kg + m * share) * g_mps2;
                if model.loads[i] <= 0.0 {
                    return Err(PhysicsError::Parameter(format!(
                        "the centre of mass at ({}, {}) m lifts wheel {}",
                        centre[0],
                        centre[1],
                        i + 1
                    )));
                }
            }
            dv.platform_mass_kg = m;
            dv.platform_inertia = inertia;
            dv.total_mass_kg = m + 4.0 * dv.wheel_mass_kg;
        }
        if let Some(brake) = alteration.brake {
            if brake.caster > 3 || !(brake.mu.is_finite() && brake.mu >= 0.0) {
                return Err(PhysicsError::Parameter(format!(
                    "a brake needs a caster 0..3 and μ ≥ 0, got {} and {}",
                    brake.caster, brake.mu
                )));
            }
            model.k_roll[brake.caster] = dv.wheel_mass_kg;
        }
        if let Some(jam) = alteration.jam {
            if jam.caster > 3 || jam.mu.is_some_and(|mu| !(mu.is_finite() && mu > 0.0)) {
                return Err(PhysicsError::Parameter(format!(
                    "a jammed swivel needs a caster 0..3 and a lock's μ > 0, got {} and {:?}",
                    jam.caster, jam.mu
                )));
            }
        }
        if !(alteration.ramp_s.is_finite() && alteration.ramp_s >= 0.0) {
            return Err(PhysicsError::Parameter(format!("a ramp lasts 0 s or more, got {} s", alteration.ramp_s)));
        }
        if let Some(wall) = alteration.wall {
            if wall.axis > 1 || !(wall.restitution > 0.0 && wall.restitution <= 1.0 && wall.contact_s > 0.0) {
                return Err(PhysicsError::Parameter(format!(
                    "a wall needs axis 0 or 1, 0 < e ≤ 1 and a positive contact time, got {}, {}, {}",
                    wall.axis, wall.restitution, wall.contact_s
                )));
            }
        }
        Ok(model)
    }

    /// Rolling-friction force and swivel-friction torque opposing the motion of caster i.
    fn caster_friction(&self, i: usize, roll_speed: f64, swivel_rate: f64) -> (f64, f64) {
        let load = self.loads[i];
        let (roll, torque) = self.friction.roll_and_swivel(load, self.derived.swivel_arm_m, roll_speed, swivel_rate);
        let roll = match self.alteration.brake {
            Some(b) if b.caster == i => {
                let eps = self.friction.eps_mps.max(BRAKE_EPS_MPS);
                friction_force(&super::Stribeck::coulomb(b.mu), load, roll_speed, roll_speed / eps)
            }
            _ => roll,
        };
        let torque = match self.alteration.jam {
            // A rigid jam's torque is the constraint's reaction, not friction.
            Some(Jam { caster, mu: None }) if caster == i => 0.0,
            Some(Jam { caster, mu: Some(mu) }) if caster == i => {
                let rho = self.derived.swivel_arm_m;
                rho * friction_force(
                    &super::Stribeck::coulomb(mu),
                    load,
                    rho * swivel_rate,
                    swivel_rate / JAM_EPS_RADPS,
                )
            }
            _ => torque,
        };
        (roll, torque)
    }

    /// The normal load of each wheel.
    pub fn wheel_loads(&self) -> [f64; 4] {
        self.loads
    }

    /// The generalised mass matrix M(q).
    pub fn mass_matrix(&self, y: &[f64; 10]) -> [[f64; 3]; 3] {
        self.assemble(y, [0.0; 2]).0
    }

    /// The rigidly jammed swivel's constraint row c (cᵀν = δ̇ⱼ) and ċᵀν.
    fn jam_row(&self, y: &[f64; 10]) -> Option<([f64; 3], f64)> {
        let j = self.alteration.jam.filter(|j| j.mu.is_none())?.caster;
        let d = self.derived.trail_m;
        let f = frames(&self.derived, y[2], &y[3..7])[j];
        let nu = [y[7], y[8], y[9]];
        let (va, vb) = (dot3(&f.a(), &nu), dot3(&f.b(), &nu));
        let b = f.b();
        Some(([b[0] / d, b[1] / d, b[2] / d - 1.0], (-va * vb / d - nu[2] * nu[2] * f.r_dot_n) / d))
    }

    /// The state just after the alteration begins, from the nominal cart's state: a captured
    /// mass (dm > 0, at rest on the floor) shares the generalised momentum (ν⁺ = M⁺⁻¹ M⁻ ν⁻); a
    /// lost one leaves with its own velocity (ν unchanged); a rigidly jamming swivel stops at
    /// once, with the least kinetic energy change (ν projected onto cᵀν = 0 in the metric of M;
    /// a friction lock acts through its torque, with no impulse).
    pub fn enter(&self, before: &NoSlip, y: &[f64; 10]) -> [f64; 10] {
        let mut out = *y;
        let nu = [y[7], y[8], y[9]];
        let mut nu1 = nu;
        if self.alteration.mass.is_some_and(|m| m.dm_kg > 0.0) {
            let mb = before.mass_matrix(y);
            let p: [f64; 3] = std::array::from_fn(|i| dot3(&mb[i], &nu));
            nu1 = solve3(&self.mass_matrix(y), &p);
        }
        if let Some((c, _)) = self.jam_row(y) {
            let minv_c = solve3(&self.mass_matrix(y), &c);
            let scale = dot3(&c, &nu1) / dot3(&c, &minv_c);
            nu1 = std::array::from_fn(|i| nu1[i] - scale * minv_c[i]);
        }
        out[7..10].copy_from_slice(&nu1);
        out
    }

    /// The wall's contact force on each corner that has passed it, as a generalised force: a
    /// spring and dashpot scaled by the corner's effective mass m_c = 1/(Jᵀ M⁻¹ J), so that a
    /// contact lasts `contact_s` and rebounds with the restitution e whatever the pose.
    fn wall_force(&self, y: &[f64; 10], m: &[[f64; 3]; 3]) -> [f64; 3] {
        let mut q = [0.0; 3];
        let Some(wall) = self.alteration.wall else { return q };
        let (s_th, c_th) = y[2].sin_cos();
        let ln_e = wall.restitution.ln();
        let zeta = -ln_e / (std::f64::consts::PI.powi(2) + ln_e * ln_e).sqrt();
        let omega = std::f64::consts::PI / (wall.contact_s * (1.0 - zeta * zeta).sqrt());
        for [px, py] in self.derived.pivots {
            let r = [c_th * px - s_th * py, s_th * px + c_th * py];
            let position = [y[0] + r[0], y[1] + r[1]][wall.axis];
            let penetration = wall.side * (position - wall.position_m);
            if penetration <= 0.0 {
                continue;
            }
            // J maps ν to the corner's speed into the wall.
            let lever = [-r[1], r[0]][wall.axis];
            let mut jac = [0.0; 3];
            jac[wall.axis] = wall.side;
            jac[2] = wall.side * lever;
            let speed = dot3(&jac, &[y[7], y[8], y[9]]);
            let force = if wall.neighbour {
                let mass = self.derived.total_mass_kg;
                (mass * (omega * omega * penetration + 2.0 * zeta * omega * speed)).max(0.0)
            } else {
                let mass = 1.0 / dot3(&jac, &solve3(m, &jac));
                mass * (omega * omega * penetration + 2.0 * zeta * omega * speed)
            };
            for (qj, jj) in q.iter_mut().zip(jac) {
                *qj -= force * jj;
            }
        }
        q
    }

    /// Mass matrix, the right-hand side Q − Σ Jᵀm J̇ν, and δ̇.
    fn assemble(&self, y: &[f64; 10], floor: [f64; 2]) -> ([[f64; 3]; 3], [f64; 3], [f64; 4]) {
        let dv = &self.derived;
        let d = dv.trail_m;
        let nu = [y[7], y[8], y[9]];
        let w = nu[2];
        let fr = frames(dv, y[2], &y[3..7]);
        let m_p = dv.platform_mass_kg;
        // The platform's first moment in the floor frame: zero for the nominal cart.
        let (s_th, c_th) = y[2].sin_cos();
        let [sx, sy] = self.first_moment;
        let s = [c_th * sx - s_th * sy, s_th * sx + c_th * sy];
        let mut m = [[m_p, 0.0, -s[1]], [0.0, m_p, s[0]], [-s[1], s[0], dv.platform_inertia]];
        let mut q = [-m_p * floor[0] + w * w * s[0], -m_p * floor[1] + w * w * s[1], s[1] * floor[0] - s[0] * floor[1]];
        let mut delta_dot = [0.0; 4];
        for (i, f) in fr.iter().enumerate() {
            let (a, b) = (f.a(), f.b());
            let (va, vb) = (dot3(&a, &nu), dot3(&b, &nu));
            delta_dot[i] = vb / d - w;
            let a_dot_nu = vb * vb / d - w * w * f.r_dot_e;
            let b_dot_nu = -va * vb / d - w * w * f.r_dot_n;
            let (roll, torque) = self.caster_friction(i, va, delta_dot[i]);
            // The wheel's inertial load along its heading; the sideways part goes into the floor.
            let floor_along = f.e[0] * floor[0] + f.e[1] * floor[1];
            let along_a = -self.k_roll[i] * a_dot_nu - dv.wheel_mass_kg * floor_along - roll;
            // The swivel torque acts on the caster (yaw rate bᵀν/d) and back on the platform (ω).
            let along_b = -self.k_yaw * b_dot_nu - torque / d;
            q[2] += torque;
            for j in 0..3 {
                q[j] += along_a * a[j] + along_b * b[j];
                for k in 0..3 {
                    m[j][k] += self.k_roll[i] * a[j] * a[k] + self.k_yaw * b[j] * b[k];
                }
            }
        }
        (m, q, delta_dot)
    }
}

impl Dynamics<10> for NoSlip {
    fn rhs(&self, y: &[f64; 10], floor: [f64; 2]) -> [f64; 10] {
        let (m, mut q, mut delta_dot) = self.assemble(y, floor);
        if self.alteration.wall.is_some() {
            let wall = self.wall_force(y, &m);
            for j in 0..3 {
                q[j] += wall[j];
            }
        }
        let mut acc = solve3(&m, &q);
        if let Some((c, c_dot_nu)) = self.jam_row(y) {
            // M ν̇ = Q + c λ with cᵀν̇ + ċᵀν = 0.
            let minv_c = solve3(&m, &c);
            let lambda = -(dot3(&c, &acc) + c_dot_nu) / dot3(&c, &minv_c);
            acc = std::array::from_fn(|i| acc[i] + lambda * minv_c[i]);
            // The jammed caster turns with the platform only.
            delta_dot[self.alteration.jam.expect("a jam row").caster] = 0.0;
        }
        [y[7], y[8], y[9], delta_dot[0], delta_dot[1], delta_dot[2], delta_dot[3], acc[0], acc[1], acc[2]]
    }

    fn kinetic_energy(&self, y: &[f64; 10]) -> f64 {
        let dv = &self.derived;
        let nu = [y[7], y[8], y[9]];
        let mut t = dv.platform_mass_kg * (nu[0] * nu[0] + nu[1] * nu[1]) + dv.platform_inertia * nu[2] * nu[2];
        if self.first_moment != [0.0; 2] {
            let (s_th, c_th) = y[2].sin_cos();
            let [sx, sy] = self.first_moment;
            // ω (S_x v_y − S_y v_x), S = R(θ) s the platform's first moment in the floor frame.
            t += 2.0 * nu[2] * ((c_th * sx - s_th * sy) * nu[1] - (s_th * sx + c_th * sy) * nu[0]);
        }
        for (i, f) in frames(dv, y[2], &y[3..7]).iter().enumerate() {
            let (va, vb) = (dot3(&f.a(), &nu), dot3(&f.b(), &nu));
            t += self.k_roll[i] * va * va + self.k_yaw * vb * vb;
        }
        0.5 * t
    }

    fn power(&self, y: &[f64; 10], floor: [f64; 2]) -> Power {
        let dv = &self.derived;
        let nu = [y[7], y[8], y[9]];
        let mut p = Power { floor_w: -dv.platform_mass_kg * (floor[0] * nu[0] + floor[1] * nu[1]), friction_w: 0.0 };
        if self.first_moment != [0.0; 2] {
            // The offset mass moves at v + ω k×ρ: the floor's load on it also works through ω.
            let (s_th, c_th) = y[2].sin_cos();
            let [sx, sy] = self.first_moment;
            let s = [c_th * sx - s_th * sy, s_th * sx + c_th * sy];
            p.floor_w -= nu[2] * (-floor[0] * s[1] + floor[1] * s[0]);
        }
        for (i, f) in frames(dv, y[2], &y[3..7]).iter().enumerate() {
            let (va, vb) = (dot3(&f.a(), &nu), dot3(&f.b(), &nu));
            let delta_dot = vb / dv.trail_m - nu[2];
            p.floor_w -= dv.wheel_mass_kg * va * (f.e[0] * floor[0] + f.e[1] * floor[1]);
            let (roll, torque) = self.caster_friction(i, va, delta_dot);
            p.friction_w -= roll * va + torque * delta_dot;
        }
        p
    }

    fn swivel_rates(&self, y: &[f64; 10]) -> [f64; 4] {
        let nu = [y[7], y[8], y[9]];
        frames(&self.derived, y[2], &y[3..7]).map(|f| dot3(&f.b(), &nu) / self.derived.trail_m - nu[2])
    }

    fn rest_forces(&self, y: &[f64; 10]) -> Option<RestForces> {
        let dv = &self.derived;
        let (m_p, m_w, d) = (dv.platform_mass_kg, dv.wheel_mass_kg, dv.trail_m);
        let mut load = [[-m_p, 0.0], [0.0, -m_p], [0.0, 0.0]];
        let mut generators = [[0.0; 3]; 8];
        for (i, f) in frames(dv, y[2], &y[3..7]).iter().enumerate() {
            let roll_capacity = self.friction.roll.mu_s * self.loads[i];
            let swivel_capacity = self.friction.swivel.mu_s * self.loads[i] * dv.swivel_arm_m;
            let (a, b) = (f.a(), f.b());
            for j in 0..3 {
                load[j][0] -= m_w * a[j] * f.e[0];
                load[j][1] -= m_w * a[j] * f.e[1];
            }
            generators[2 * i] = a.map(|v| v * roll_capacity);
            generators[2 * i + 1] = [b[0] / d, b[1] / d, b[2] / d - 1.0].map(|v| v * swivel_capacity);
        }
        Some((load, generators))
    }

    fn derived(&self) -> &Derived {
        &self.derived
    }
}

/// The lateral-slip model: each caster's heading rate ψ̇ᵢ is a degree of freedom (14 states),
/// and the floor resists the wheel's sideways slip n·v_wheel with a regularised Coulomb force.
#[derive(Clone, Copy, Debug)]
pub struct Slip {
    pub derived: Derived,
    pub friction: Friction,
    pub lateral: LateralSlip,
}

impl Slip {
    pub fn new(cart: &Cart, friction: &Friction, lateral: &LateralSlip, g_mps2: f64) -> Self {
        Slip { derived: Derived::new(cart, g_mps2), friction: *friction, lateral: *lateral }
    }

    /// Rolling force, swivel torque and sideways force opposing caster i's motion.
    fn caster_friction(&self, roll_speed: f64, swivel_rate: f64, side_speed: f64) -> (f64, f64, f64) {
        let n = self.derived.normal_n;
        let (roll, torque) = self.friction.roll_and_swivel(n, self.derived.swivel_arm_m, roll_speed, swivel_rate);
        (roll, torque, self.lateral.mu * n * (side_speed / self.lateral.eps_mps).tanh())
    }

    /// Per caster: its frame, wheel-centre velocity, rolling, sideways and swivel speeds.
    fn kinematics(&self, y: &[f64; 14]) -> [(Frame, [f64; 2], f64, f64, f64); 4] {
        let dv = &self.derived;
        let w = y[9];
        let fr = frames(dv, y[2], &y[3..7]);
        std::array::from_fn(|i| {
            let f = fr[i];
            let psi_dot = y[10 + i];
            let pivot = [y[7] - w * f.r[1], y[8] + w * f.r[0]];
            let centre = [pivot[0] - dv.trail_m * psi_dot * f.n[0], pivot[1] - dv.trail_m * psi_dot * f.n[1]];
            let roll = f.e[0] * pivot[0] + f.e[1] * pivot[1];
            let side = f.n[0] * centre[0] + f.n[1] * centre[1];
            (f, centre, roll, side, psi_dot - w)
        })
    }
}

impl Dynamics<14> for Slip {
    fn rhs(&self, y: &[f64; 14], floor: [f64; 2]) -> [f64; 14] {
        let dv = &self.derived;
        let (d, m_w) = (dv.trail_m, dv.wheel_mass_kg);
        let w = y[9];
        let k_spin = dv.spin_inertia / (dv.wheel_radius_m * dv.wheel_radius_m);
        let mut m = [[0.0; 7]; 7];
        m[0][0] = dv.platform_mass_kg;
        m[1][1] = dv.platform_mass_kg;
        m[2][2] = dv.platform_inertia;
        let mut q = [0.0; 7];
        q[0] = -dv.platform_mass_kg * floor[0];
        q[1] = -dv.platform_mass_kg * floor[1];
        let mut out = [0.0; 14];
        out[..3].copy_from_slice(&y[7..10]);
        let nu3 = [y[7], y[8], w];
        for (i, (f, _, roll_speed, side_speed, delta_dot)) in self.kinematics(y).into_iter().enumerate() {
            let psi_dot = y[10 + i];
            out[3 + i] = delta_dot;
            let col = 3 + i;
            // Wheel centre: v_C = J_C u with columns (1,0), (0,1), k×r, −d n (at ψ̇ᵢ).
            let jc = [[1.0, 0.0], [0.0, 1.0], [-f.r[1], f.r[0]], [-d * f.n[0], -d * f.n[1]]];
            let idx = [0, 1, 2, col];
            // J̇_C u = −ω² r + d ψ̇² e; the wheel's inertial load is −m_w(ü + J̇_C u).
            let bias =
                [-w * w * f.r[0] + d * psi_dot * psi_dot * f.e[0], -w * w * f.r[1] + d * psi_dot * psi_dot * f.e[1]];
            let load = [-m_w * (floor[0] + bias[0]), -m_w * (floor[1] + bias[1])];
            for (jj, cj) in idx.iter().zip(&jc) {
                q[*jj] += cj[0] * load[0] + cj[1] * load[1];
                for (kk, ck) in idx.iter().zip(&jc) {
                    m[*jj][*kk] += m_w * (cj[0] * ck[0] + cj[1] * ck[1]);
                }
            }
            // Spin about the axle at e·v_C / r; ė = ψ̇ n gives ȧᵀu = ψ̇ (bᵀν) − ω² (r·e).
            let (a, b) = (f.a(), f.b());
            let a_dot_u = psi_dot * dot3(&b, &nu3) - w * w * f.r_dot_e;
            let (roll, torque, side) = self.caster_friction(roll_speed, delta_dot, side_speed);
            let along_a = -k_spin * a_dot_u - roll;
            for j in 0..3 {
                q[j] += along_a * a[j] - side * b[j];
                for k in 0..3 {
                    m[j][k] += k_spin * a[j] * a[k];
                }
            }
            // The sideways force acts at the contact, a trail d behind the pivot: ℓ = [n; r×n; −d].
            q[col] += side * d - torque;
            q[2] += torque;
            m[col][col] += dv.yaw_inertia;
        }
        let acc = cholesky_solve(m, q);
        out[7..14].copy_from_slice(&acc);
        out
    }

    fn kinetic_energy(&self, y: &[f64; 14]) -> f64 {
        let dv = &self.derived;
        let k_spin = dv.spin_inertia / (dv.wheel_radius_m * dv.wheel_radius_m);
        let mut t = dv.platform_mass_kg * (y[7] * y[7] + y[8] * y[8]) + dv.platform_inertia * y[9] * y[9];
        for (i, (_, centre, roll_speed, _, _)) in self.kinematics(y).into_iter().enumerate() {
            t += dv.wheel_mass_kg * (centre[0] * centre[0] + centre[1] * centre[1])
                + k_spin * roll_speed * roll_speed
                + dv.yaw_inertia * y[10 + i] * y[10 + i];
        }
        0.5 * t
    }

    fn power(&self, y: &[f64; 14], floor: [f64; 2]) -> Power {
        let dv = &self.derived;
        let mut p = Power { floor_w: -dv.platform_mass_kg * (floor[0] * y[7] + floor[1] * y[8]), friction_w: 0.0 };
        for (_, centre, roll_speed, side_speed, delta_dot) in self.kinematics(y) {
            p.floor_w -= dv.wheel_mass_kg * (floor[0] * centre[0] + floor[1] * centre[1]);
            let (roll, torque, side) = self.caster_friction(roll_speed, delta_dot, side_speed);
            p.friction_w -= roll * roll_speed + torque * delta_dot + side * side_speed;
        }
        p
    }

    fn swivel_rates(&self, y: &[f64; 14]) -> [f64; 4] {
        std::array::from_fn(|i| y[10 + i] - y[9])
    }

    fn rest_forces(&self, _: &[f64; 14]) -> Option<RestForces> {
        None
    }

    fn derived(&self) -> &Derived {
        &self.derived
    }
}

/// Solves the symmetric positive-definite 3×3 system by Cramer's rule (fixed operation order).
fn solve3(m: &[[f64; 3]; 3], q: &[f64; 3]) -> [f64; 3] {
    let c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
    let c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    let c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
    let det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02;
    let inv = [
        [c00, m[0][2] * m[2][1] - m[0][1] * m[2][2], m[0][1] * m[1][2] - m[0][2] * m[1][1]],
        [c01, m[0][0] * m[2][2] - m[0][2] * m[2][0], m[0][2] * m[1][0] - m[0][0] * m[1][2]],
        [c02, m[0][1] * m[2][0] - m[0][0] * m[2][1], m[0][0] * m[1][1] - m[0][1] * m[1][0]],
    ];
    std::array::from_fn(|i| (inv[i][0] * q[0] + inv[i][1] * q[1] + inv[i][2] * q[2]) / det)
}

/// Solves a symmetric positive-definite system by Cholesky factorisation.
fn cholesky_solve<const K: usize>(mut m: [[f64; K]; K], mut q: [f64; K]) -> [f64; K] {
    for j in 0..K {
        let mut diag = m[j][j];
        for v in &m[j][..j] {
            diag -= v * v;
        }
        let diag = diag.sqrt();
        m[j][j] = diag;
        for i in j + 1..K {
            let mut v = m[i][j];
            for (a, b) in m[i][..j].iter().zip(&m[j][..j]) {
                v -= a * b;
            }
            m[i][j] = v / diag;
        }
    }
    for i in 0..K {
        for k in 0..i {
            q[i] -= m[i][k] * q[k];
        }
        q[i] /= m[i][i];
    }
    for i in (0..K).rev() {
        for k in i + 1..K {
            q[i] -= m[k][i] * q[k];
        }
        q[i] /= m[i][i];
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_solvers_invert_a_known_system() {
        let m = [[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]];
        let x = [1.0, -2.0, 0.5];
        let q: [f64; 3] = std::array::from_fn(|i| (0..3).map(|k| m[i][k] * x[k]).sum());
        for (got, want) in solve3(&m, &q).iter().zip(&x) {
            assert!((got - want).abs() < 1e-14);
        }
        for (got, want) in cholesky_solve(m, q).iter().zip(&x) {
            assert!((got - want).abs() < 1e-14);
        }
    }
}
