//! The invariants and closed forms of 4WMC-NOTES.md, each with the tolerance it needs and why.

use std::f64::consts::PI;

use super::dynamics::{Dynamics, NoSlip, Slip};
use super::*;
use crate::physics::ode::{Advance, Dopri5, Stepper};

/// The notes' prototype cart: m_p = 60 kg, m_w = 1 kg, 1.0 × 0.6 m, r = 0.05 m, d = 0.03 m.
fn prototype() -> Cart {
    Cart {
        length_m: 1.0,
        width_m: 0.6,
        platform_mass_kg: 60.0,
        wheel_diameter_m: 0.1,
        wheel_width_m: 0.03,
        wheel_mass_kg: 1.0,
        trail_m: 0.03,
        swivel_arm_m: 0.02,
    }
}

fn frictionless() -> Friction {
    Friction {
        roll: Stribeck::coulomb(0.0),
        swivel: Stribeck::coulomb(0.0),
        eps_mps: DEFAULT_FRICTION_EPS_MPS,
        eps_swivel_radps: DEFAULT_FRICTION_EPS_SWIVEL_RADPS,
        law: FrictionLaw::Regularised,
    }
}

/// MC2's Table 4 friction (Stribeck on both, swivel equal to rolling).
fn table4_friction(name: &str) -> Friction {
    let t = preset(name).unwrap();
    Friction {
        roll: Stribeck { mu_s: t.mu_s_roll, mu_k: t.mu_k_roll, beta_spm: t.beta_spm, gamma_n: t.gamma_n, p: t.p },
        swivel: Stribeck { mu_s: t.mu_s_swivel, mu_k: t.mu_k_swivel, beta_spm: t.beta_spm, gamma_n: t.gamma_n, p: t.p },
        eps_mps: DEFAULT_FRICTION_EPS_MPS,
        eps_swivel_radps: DEFAULT_FRICTION_EPS_SWIVEL_RADPS,
        law: FrictionLaw::Regularised,
    }
}

fn no_events<const N: usize>(_: f64, _: &[f64; N]) -> [f64; 0] {
    []
}

/// Integrates y' = f(t, y) to t_end with tight tolerances, in 5 ms legs like the driver.
fn integrate<const N: usize>(f: impl Fn(f64, &[f64; N]) -> [f64; N], y0: [f64; N], t_end: f64, rtol: f64) -> [f64; N] {
    let mut solver = Dopri5::new(rtol, [rtol * 1e-2; N], 0.005);
    let mut y = y0;
    let legs = (t_end / 0.005).round() as usize;
    for k in 0..legs {
        let Advance::Reached(next) = solver.advance(&f, k as f64 * 0.005, y, (k + 1) as f64 * 0.005, &no_events) else {
            unreachable!()
        };
        y = next;
    }
    y
}

fn two_component_floor(n: usize, dt: f64, scale: f64) -> (Vec<f64>, Vec<f64>) {
    let t = |k: usize| k as f64 * dt;
    let ax = (0..n)
        .map(|k| {
            scale * ((2.0 * PI * 1.1 * t(k)).sin() + 0.4 * (2.0 * PI * 2.7 * t(k) + 0.3).sin()) * (1.0 - (-t(k)).exp())
        })
        .collect();
    let ay = (0..n).map(|k| scale * 0.6 * (2.0 * PI * 0.8 * t(k) + 1.0).sin() * (1.0 - (-t(k)).exp())).collect();
    (ax, ay)
}

fn run(cart: &Cart, friction: &Friction, ax: &[f64], ay: &[f64], dt: f64, options: &Options) -> Response {
    simulate(cart, friction, &Excitation { t0_s: 0.0, dt_s: dt, ax_mps2: ax, ay_mps2: ay }, options).unwrap()
}

#[test]
fn frictionless_unforced_cart_keeps_its_kinetic_energy_but_not_its_momentum() {
    // 4WMC-NOTES.md check 1: T conserved (the prototype drifted 1e-7 in 3 s with DOP853 and a
    // finite-difference J̇); the J̇ terms here are exact, so the bound is the integration
    // tolerance: 1e-11 relative at rtol 1e-11 (measured: 3e-14).
    let model = NoSlip::new(&prototype(), &frictionless(), G_MPS2);
    let y0 = [0.0, 0.0, 0.1, 0.3, -1.0, 2.0, 0.5, 0.4, 0.2, 0.5];
    let y = integrate(|_, y| model.rhs(y, [0.0, 0.0]), y0, 3.0, 1e-11);
    let (t0, t1) = (model.kinetic_energy(&y0), model.kinetic_energy(&y));
    eprintln!("check 1: relative kinetic energy drift {:.1e} over 3 s", ((t1 - t0) / t0).abs());
    assert!(((t1 - t0) / t0).abs() < 1e-11, "T {t0} → {t1}");
    // The floor pushes sideways on the wheels: the platform's velocity changes (by about 5 %
    // in the prototype), so momentum is not an invariant of this model.
    let change = ((y[7] - y0[7]).powi(2) + (y[8] - y0[8]).powi(2)).sqrt();
    assert!(change > 0.01, "platform velocity barely changed: {:?}", &y[7..]);
}

/// The no-slip state plus the floor's work and the friction work, integrated alongside.
fn energy_balance_error<const N: usize, const M: usize, D: Dynamics<N>>(model: &D, y0: [f64; N]) -> (f64, f64) {
    let floor = |t: f64| [1.2 * (2.0 * PI * 1.3 * t).sin(), 0.7 * (2.0 * PI * 0.7 * t + 0.4).cos()];
    let f = |t: f64, z: &[f64; M]| {
        let y: [f64; N] = std::array::from_fn(|i| z[i]);
        let dy = model.rhs(&y, floor(t));
        let p = model.power(&y, floor(t));
        std::array::from_fn(|i| {
            if i < N {
                dy[i]
            } else if i == N {
                p.floor_w
            } else {
                p.friction_w
            }
        })
    };
    let z0: [f64; M] = std::array::from_fn(|i| if i < N { y0[i] } else { 0.0 });
    let z = integrate(f, z0, 4.0, 1e-11);
    let y: [f64; N] = std::array::from_fn(|i| z[i]);
    let gained = model.kinetic_energy(&y) - model.kinetic_energy(&y0);
    ((gained - z[N] - z[N + 1]).abs(), -z[N + 1])
}

#[test]
fn kinetic_energy_changes_by_the_floor_work_less_the_friction_losses() {
    // Check 2: T(t) − T(0) = ∫ floor power − ∫ dissipation, to the integration tolerance
    // (rtol 1e-11 on energies of ~10 J: 1e-10 J; measured 1e-12), with MC2's friction (Table 4,
    // ρ = 0.02 m).
    let mut cart = prototype();
    cart.trail_m = 0.04;
    let model = NoSlip::new(&cart, &table4_friction("MC2"), G_MPS2);
    let (error, dissipated) =
        energy_balance_error::<10, 12, _>(&model, [0.0, 0.0, 0.2, 0.4, -0.5, 1.0, 2.0, 0.3, -0.2, 0.4]);
    eprintln!("check 2: energy balance error {error:.1e} J of {dissipated:.2} J dissipated");
    assert!(dissipated > 1.0, "friction must do real work here: {dissipated} J");
    assert!(error < 1e-10, "energy balance off by {error} J");
    let slip = Slip::new(&cart, &table4_friction("MC2"), &LateralSlip { mu: 0.6, eps_mps: 0.01 }, G_MPS2);
    let (error, dissipated) = energy_balance_error::<14, 16, _>(
        &slip,
        [0.0, 0.0, 0.2, 0.4, -0.5, 1.0, 2.0, 0.3, -0.2, 0.4, 0.0, 0.0, 0.0, 0.0],
    );
    eprintln!("check 2 (lateral slip): energy balance error {error:.1e} J of {dissipated:.2} J dissipated");
    assert!(dissipated > 1.0 && error < 1e-10, "slip model: balance off by {error} J, dissipated {dissipated} J");
}

#[test]
fn zero_input_leaves_the_cart_exactly_at_rest() {
    // Check 7: exactly, every output, for both friction laws and both models.
    let zeros = vec![0.0; 400];
    let t = preset("PS1").unwrap();
    let options = Options {
        yaw0_rad: t.yaw0_deg.to_radians(),
        steer0_rad: t.steer0_deg.map(f64::to_radians),
        ..Options::default()
    };
    let mut cart = prototype();
    cart.trail_m = 0.0;
    for (law, slip) in
        [(FrictionLaw::Regularised, false), (FrictionLaw::StickSlip, false), (FrictionLaw::Regularised, true)]
    {
        let friction = Friction { law, ..table4_friction("PS1") };
        let mut opts = options;
        let mut c = prototype();
        if slip {
            opts.lateral_slip = Some(LateralSlip { mu: 0.5, eps_mps: 1e-3 });
            c = cart;
        }
        let r = run(&c, &friction, &zeros, &zeros, 0.005, &opts);
        assert!(r.x_m.iter().chain(&r.y_m).chain(&r.vx_mps).chain(&r.ax_abs_mps2).all(|&v| v == 0.0), "{law:?}");
        assert!(r.yaw_rad.iter().all(|&v| v == options.yaw0_rad));
        for i in 0..4 {
            assert!(r.delta_rad[i].iter().all(|&v| v == options.steer0_rad[i]));
        }
        assert!(r.events.is_empty(), "{:?}", r.events);
    }
}

/// Casters aligned with body x, platform yaw 0, a constant floor acceleration along x.
fn aligned_constant_push(friction: &Friction, accel: f64, seconds: f64, method: Method) -> Response {
    let n = (seconds / 0.005) as usize + 1;
    run(&prototype(), friction, &vec![accel; n], &vec![0.0; n], 0.005, &Options { method, ..Options::default() })
}

/// Tight enough to resolve the start from rest with ε = 1e-8 m/s.
const TIGHT: Method = Method::Adaptive { rtol: 1e-10, atol: 1e-12 };

#[test]
fn below_the_static_rolling_threshold_nothing_moves() {
    // Check 3 (below): the static threshold is μ_s g exactly (4 wheels carry m_tot g).
    let mu = 0.045;
    let friction =
        Friction { roll: Stribeck { mu_s: mu, mu_k: 0.005, beta_spm: 20.0, gamma_n: 0.0, p: 1.0 }, ..frictionless() };
    let threshold = mu * G_MPS2;
    // Exact stick: not a single bit of motion at 99.9 % of the threshold.
    let stick = Friction { law: FrictionLaw::StickSlip, ..friction };
    let r = aligned_constant_push(&stick, 0.999 * threshold, 1.0, Method::default());
    assert!(r.x_m.iter().chain(&r.y_m).all(|&v| v == 0.0), "moved {:?}", r.x_m.last());
    assert!(r.resting.iter().all(|&s| s) && r.events.is_empty());
    // Just above, it breaks away at once.
    let r = aligned_constant_push(&stick, 1.001 * threshold, 1.0, Method::default());
    assert_eq!(r.events[0].kind, EventKind::Breakaway);
    assert_eq!(r.events[0].time_s, 0.0);
    assert!(*r.x_m.last().unwrap() < -1e-5);
    // Regularised: a creep at ε·atanh(load/capacity) (the notes: 1.5e-4 m in 1 s at 0.9 μg with
    // ε = 1e-4 m/s). The wheels' spin inertia makes the start-up transient negligible.
    let r = aligned_constant_push(&friction, 0.9 * threshold, 1.0, Method::default());
    let creep = DEFAULT_FRICTION_EPS_MPS * 0.9f64.atanh();
    let x = -*r.x_m.last().unwrap();
    eprintln!("check 3: regularised creep {x:.4e} m in 1 s at 0.9 μ_s g, ε·atanh(0.9)·1 s = {creep:.4e} m");
    assert!((x - creep).abs() < 0.02 * creep, "creep {x} m vs ε·atanh(0.9)·1 s = {creep} m");
    assert_eq!(r.count(EventKind::Breakaway), 0, "a creep below 1 mm/s is no breakaway");
}

#[test]
fn constant_acceleration_rolling_matches_its_closed_form() {
    // Check 3 (above): x = −½ (|a| − μ_k g) m_tot/m_eff t², m_eff = m_tot + 4 I_s/r², for Coulomb
    // friction. The regularised sign lets the cart gain ≈ ε·ln2·μg/(|a| − μg) of extra speed while
    // it starts from rest: with ε = 1e-8 m/s, 1e-8 m after 1 s.
    let mu = 0.02;
    let friction = Friction { roll: Stribeck::coulomb(mu), eps_mps: 1e-8, ..frictionless() };
    let accel = 1.5 * mu * G_MPS2;
    let r = aligned_constant_push(&friction, accel, 1.0, TIGHT);
    let cart = prototype();
    let m_tot = cart.platform_mass_kg + 4.0 * cart.wheel_mass_kg;
    // I_s/r² = ½ m_w for a uniform disc.
    let m_eff = m_tot + 4.0 * 0.5 * cart.wheel_mass_kg;
    let expected = -0.5 * (accel - mu * G_MPS2) * m_tot / m_eff;
    let x = *r.x_m.last().unwrap();
    eprintln!("check 3: constant push, x(1 s) {x:.9} m vs closed form {expected:.9} m (Δ {:.1e})", x - expected);
    assert!((x - expected).abs() < 1e-7, "x(1 s) = {x} m, closed form {expected} m");
    assert!(r.y_m.iter().chain(&r.yaw_rad).all(|&v| v == 0.0), "a symmetric push stays straight");

    // With the study's Stribeck law, the same motion solves m_eff v̇ = m_tot (|a| − g μ(v)): a
    // one-degree-of-freedom reduction, integrated here by a plain RK4 at 1 µs.
    let stribeck = Stribeck { mu_s: 0.044, mu_k: 0.0044, beta_spm: 6.05, gamma_n: 0.00044, p: 1.0 };
    let friction = Friction { roll: stribeck, eps_mps: 1e-8, ..frictionless() };
    let accel = 1.2 * stribeck.mu_s * G_MPS2;
    let r = aligned_constant_push(&friction, accel, 1.0, TIGHT);
    let vdot = |v: f64| m_tot / m_eff * (accel - G_MPS2 * stribeck.coefficient(v));
    let (mut v, mut s, h) = (0.0, 0.0, 1e-6);
    for _ in 0..1_000_000 {
        let (k1, k2) = (vdot(v), vdot(v + 0.5 * h * vdot(v)));
        let k3 = vdot(v + 0.5 * h * k2);
        let k4 = vdot(v + h * k3);
        s += h * v + h * h / 6.0 * (k1 + k2 + k3);
        v += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    }
    let x = -*r.x_m.last().unwrap();
    eprintln!("check 3 (Stribeck): {x:.9} m vs the 1-DOF reduction {s:.9} m (relative {:.1e})", (x - s).abs() / s);
    assert!((x - s).abs() < 1e-6 * s, "Stribeck: {x} m vs 1-DOF reduction {s} m");
}

#[test]
fn perpendicular_casters_break_away_where_swivel_friction_gives_in() {
    // Casters across the push (δ = 90°) roll nowhere; the push must turn them against the swivel
    // friction torque μ_δ N ρ at a lever d: m_p a = 4 μ_δ N ρ / d, i.e.
    // a* = μ_δ g ρ (m_tot/m_p) / d (the notes: "roughly μ_sw g ρ/d"). A slow ramp finds it.
    let cart = prototype();
    let mu_sw = 0.05;
    let friction = Friction {
        roll: Stribeck::coulomb(0.3),
        swivel: Stribeck::coulomb(mu_sw),
        law: FrictionLaw::StickSlip,
        ..frictionless()
    };
    let m_tot = cart.platform_mass_kg + 4.0 * cart.wheel_mass_kg;
    let critical = mu_sw * G_MPS2 * cart.swivel_arm_m * m_tot / cart.platform_mass_kg / cart.trail_m;
    let rate = 0.5; // m/s² per s
    let n = 2000;
    let ax: Vec<f64> = (0..n).map(|k| rate * k as f64 * 0.005).collect();
    let options = Options { steer0_rad: [PI / 2.0; 4], ..Options::default() };
    let r = run(&cart, &friction, &ax, &vec![0.0; n], 0.005, &options);
    let breakaway = r.events.iter().find(|e| e.kind == EventKind::Breakaway).expect("breaks away");
    eprintln!("check 3 (swivel): breakaway at {:.12} s, closed form {:.12} s", breakaway.time_s, critical / rate);
    assert!(
        (breakaway.time_s - critical / rate).abs() < 1e-9,
        "at {} s, closed form {} s",
        breakaway.time_s,
        critical / rate
    );
}

#[test]
fn a_driven_caster_self_aligns_by_the_half_angle_law() {
    // Check 4: with the pivot driven straight at speed V along χ, tan((ψ−χ)/2) decays as
    // e^(−Vt/d). A platform of 1e12 kg keeps its velocity to ~1e-13, so the law holds to the
    // integration tolerance (1e-9 rad here).
    let mut cart = prototype();
    cart.platform_mass_kg = 1e12;
    let model = NoSlip::new(&cart, &frictionless(), G_MPS2);
    let (speed, chi): (f64, f64) = (0.3, 0.4);
    let deltas = [0.0, 1.0, -2.5, 3.0];
    let y0 = [0.0, 0.0, 0.0, deltas[0], deltas[1], deltas[2], deltas[3], speed * chi.cos(), speed * chi.sin(), 0.0];
    let mut worst: f64 = 0.0;
    for t_end in [0.05, 0.2, 0.5] {
        let y = integrate(|_, y| model.rhs(y, [0.0, 0.0]), y0, t_end, 1e-12);
        for i in 0..4 {
            let expected = 2.0 * (((deltas[i] - chi) / 2.0).tan() * (-speed * t_end / cart.trail_m).exp()).atan() + chi;
            let got = y[3 + i];
            // Compare as angles: the unwrapped δ may differ from the closed form by 2π.
            let diff = (got - expected + PI).rem_euclid(2.0 * PI) - PI;
            worst = worst.max(diff.abs());
            assert!(diff.abs() < 1e-9, "t = {t_end}: caster {} at {got} rad, closed form {expected} rad", i + 1);
        }
    }
    eprintln!("check 4: self-alignment against tan((ψ−χ)/2) = tan((ψ₀−χ)/2)·e^(−Vt/d): worst {worst:.1e} rad");
}

#[test]
fn casters_flip_when_the_motion_reverses() {
    // The floor pushes the cart toward +x (casters trailing, stable), then back toward −x: the
    // four casters swing through 180°. While trailing, a caster's misalignment decays as
    // e^(−s/d) with the distance s travelled; after the reversal it grows back at the same rate,
    // so the flip comes when the distance rolled back has undone the decay (check 4's law run
    // backwards): here within 2 s of the reversal, and every caster ends aligned the other way.
    let cart = prototype();
    let friction = Friction { roll: Stribeck::coulomb(0.005), swivel: Stribeck::coulomb(0.005), ..frictionless() };
    let n = 1600;
    let ax: Vec<f64> = (0..n).map(|k| if k < 200 { -1.0 } else { 1.0 }).collect();
    let options = Options { steer0_rad: [0.01, -0.01, 0.01, -0.01], ..Options::default() };
    let r = run(&cart, &friction, &ax, &vec![0.0; n], 0.005, &options);
    assert_eq!(r.flips(), [1, 1, 1, 1], "{:?}", r.events);
    let reversal = (1..n).find(|&k| r.vx_mps[k] < 0.0).unwrap() as f64 * 0.005;
    for e in r.events.iter().filter(|e| e.kind == EventKind::Flip) {
        assert!(e.time_s > reversal && e.time_s < reversal + 2.0, "flip at {} s, reversal at {reversal} s", e.time_s);
        let caster = e.caster.unwrap();
        // At the event the caster stands at 135° from its trailing direction.
        assert!((e.pose[3 + caster].abs() - 0.75 * PI).abs() < 1e-9, "{:?}", e);
    }
    for i in 0..4 {
        let last = *r.delta_rad[i].last().unwrap();
        assert!((last.abs() - PI).abs() < 1e-3, "caster {} ends at {last} rad", i + 1);
    }
}

/// Runs the response mirrored about floor X: y, θ, δ and ü_Y change sign and casters swap
/// 1↔4, 2↔3 (pivots (+,+), (−,+), (−,−), (+,−)).
#[test]
fn mirrored_input_gives_the_mirrored_response() {
    // Check 5: to round-off, which the caster flips amplify (a flip's timing depends on the
    // logarithm of the residual misalignment, so differences grow ~e^(2.3 t) here: 1e-14 after
    // 1 s, 1e-9 after 3 s, 1e-7 after 8 s). The step sequence sees permuted sums: 3 s, 1e-8.
    let cart = prototype();
    let friction = table4_friction("MC2");
    let (ax, ay) = two_component_floor(600, 0.005, 2.0);
    let method = Method::Adaptive { rtol: 1e-10, atol: 1e-12 };
    let a = Options { yaw0_rad: 0.3, steer0_rad: [0.2, -1.0, 2.0, 0.7], method, ..Options::default() };
    let b = Options { yaw0_rad: -0.3, steer0_rad: [-0.7, -2.0, 1.0, -0.2], method, ..Options::default() };
    let ay_mirrored: Vec<f64> = ay.iter().map(|v| -v).collect();
    let (ra, rb) = (run(&cart, &friction, &ax, &ay, 0.005, &a), run(&cart, &friction, &ax, &ay_mirrored, 0.005, &b));
    assert!(ra.peak_displacement().0 > 0.05 && ra.peak_yaw().0 > 0.05, "the test must move and turn the cart");
    let swap = [3, 2, 1, 0];
    let mut worst: f64 = 0.0;
    for k in 0..ax.len() {
        worst = worst
            .max((ra.x_m[k] - rb.x_m[k]).abs())
            .max((ra.y_m[k] + rb.y_m[k]).abs())
            .max((ra.yaw_rad[k] + rb.yaw_rad[k]).abs());
        for (delta, &mirror) in ra.delta_rad.iter().zip(&swap) {
            worst = worst.max((delta[k] + rb.delta_rad[mirror][k]).abs());
        }
    }
    eprintln!("check 5: mirror mismatch {worst:.1e} over 3 s");
    assert!(worst < 1e-8, "mirror mismatch {worst}");
    assert_eq!(ra.flips(), swap.map(|i| rb.flips()[i]));
}

#[test]
fn rotating_the_floor_and_the_cart_rotates_the_response() {
    // Check 6: rotate θ₀ and the input by α; positions rotate by α, θ shifts by α, δ is unchanged.
    // Tolerances act per component, so the rotated run takes other steps (rtol 1e-10) whose
    // differences the flips amplify as in the mirror check: 3 s, 1e-7.
    let cart = prototype();
    let friction = table4_friction("MC2");
    let (ax, ay) = two_component_floor(600, 0.005, 2.0);
    let alpha: f64 = 0.7;
    let (s, c) = alpha.sin_cos();
    let axr: Vec<f64> = ax.iter().zip(&ay).map(|(x, y)| c * x - s * y).collect();
    let ayr: Vec<f64> = ax.iter().zip(&ay).map(|(x, y)| s * x + c * y).collect();
    let method = Method::Adaptive { rtol: 1e-10, atol: 1e-12 };
    let a = Options { yaw0_rad: 0.3, steer0_rad: [0.2, -1.0, 2.0, 0.7], method, ..Options::default() };
    let b = Options { yaw0_rad: 0.3 + alpha, ..a };
    let (ra, rb) = (run(&cart, &friction, &ax, &ay, 0.005, &a), run(&cart, &friction, &axr, &ayr, 0.005, &b));
    let mut worst: f64 = 0.0;
    for k in 0..ax.len() {
        let (x, y) = (c * ra.x_m[k] - s * ra.y_m[k], s * ra.x_m[k] + c * ra.y_m[k]);
        worst = worst
            .max((x - rb.x_m[k]).abs())
            .max((y - rb.y_m[k]).abs())
            .max((ra.yaw_rad[k] + alpha - rb.yaw_rad[k]).abs());
        for i in 0..4 {
            worst = worst.max((ra.delta_rad[i][k] - rb.delta_rad[i][k]).abs());
        }
    }
    eprintln!("check 6: rotation mismatch {worst:.1e} over 3 s");
    assert!(worst < 1e-7, "rotation mismatch {worst}");
}

#[test]
fn rk4_converges_to_the_adaptive_solution() {
    // Check 8 on MC2 under a strong synthetic two-component floor (10 s, 6 caster flips each):
    // reference = Dormand–Prince at rtol 1e-11. RK4 at the study's dt = 1e-4 s is off by about
    // 1 mm in peak displacement here (the regularised friction's creep mode, μg/ε ≈ 4300 s⁻¹, is
    // resolved only coarsely at that step); halving dt cuts the error by more than 8 (fourth
    // order, less near sticking), and the default adaptive tolerance beats RK4 at 1e-4 s with
    // 1/7 of the right-hand-side evaluations (the converged rtol 1e-10 / atol 1e-13: 56 577
    // against 401 950; atol 1e-12 needed 48 495, the former 1e-8 1/10; docs/convergence.md).
    let t = preset("MC2").unwrap();
    let cart = t.cart(Cart::default_trail_m(t.wheel_diameter_m), DEFAULT_SWIVEL_ARM_M);
    let (ax, ay) = two_component_floor(2000, 0.005, 2.5);
    let options = Options { yaw0_rad: t.yaw0_deg.to_radians(), ..Options::default() };
    // The swivel regularised as coarsely as ε/ρ (5e-3 rad/s): with the default ε_sw = 1e-3 rad/s
    // the swivel's creep mode is stiffer than RK4 at the study's step resolves (yaw error
    // 7.8e-3 rad, 1.7e-3 at 5e-5 s: docs/models/rolling.md), one more reason for the adaptive
    // default.
    let friction =
        Friction { eps_swivel_radps: DEFAULT_FRICTION_EPS_MPS / DEFAULT_SWIVEL_ARM_M, ..table4_friction("MC2") };
    let with = |method| run(&cart, &friction, &ax, &ay, 0.005, &Options { method, ..options });
    let reference = with(Method::Adaptive { rtol: 1e-11, atol: 1e-13 });
    let error = |r: &Response| {
        (
            (r.peak_displacement().0 - reference.peak_displacement().0).abs(),
            (r.peak_yaw().0 - reference.peak_yaw().0).abs(),
        )
    };
    let (default, rk4, rk4_half) =
        (with(Method::default()), with(Method::Rk4 { dt_s: 1e-4 }), with(Method::Rk4 { dt_s: 5e-5 }));
    assert!(
        reference.peak_displacement().0 > 0.1 && reference.flips().iter().all(|&f| f >= 5),
        "the cart must roll and flip"
    );
    let (e_default, e_rk4, e_half) = (error(&default), error(&rk4), error(&rk4_half));
    eprintln!(
        "check 8: peak displacement [m] / yaw [rad] errors against rtol 1e-11: default adaptive {:.1e} / {:.1e} ({} evaluations), RK4 1e-4 s {:.1e} / {:.1e} ({}), RK4 5e-5 s {:.1e} / {:.1e}",
        e_default.0, e_default.1, default.stats.rhs_evals, e_rk4.0, e_rk4.1, rk4.stats.rhs_evals, e_half.0, e_half.1
    );
    assert!(e_rk4.0 < 2e-3 && e_rk4.1 < 5e-3, "RK4 at 1e-4 s: {e_rk4:?}");
    assert!(e_half.0 < e_rk4.0 / 8.0 && e_half.1 < e_rk4.1 / 8.0, "RK4 {e_rk4:?} → {e_half:?} when halving dt");
    assert!(e_default.0 < e_rk4.0 && e_default.1 < e_rk4.1, "default adaptive {e_default:?} vs RK4 {e_rk4:?}");
    assert!(default.stats.rhs_evals * 7 < rk4.stats.rhs_evals, "{:?} vs {:?}", default.stats, rk4.stats);
}

#[test]
fn lateral_slip_converges_to_the_no_slip_model_and_covers_zero_trail() {
    // With a side friction far from saturation, the sideways slip speed is ~ε_lat·(load/capacity):
    // the slip model tends to the constrained one as ε_lat → 0 (the error drops ~10× per decade).
    let cart = prototype();
    let friction = table4_friction("MC2");
    let (ax, ay) = two_component_floor(200, 0.005, 2.0);
    let options = Options { yaw0_rad: 0.2, steer0_rad: [0.3, -0.4, 1.0, 0.0], ..Options::default() };
    let reference = run(&cart, &friction, &ax, &ay, 0.005, &options);
    let error = |eps: f64| {
        let slip = Options { lateral_slip: Some(LateralSlip { mu: 3.0, eps_mps: eps }), ..options };
        let r = run(&cart, &friction, &ax, &ay, 0.005, &slip);
        (0..ax.len()).map(|k| (r.x_m[k] - reference.x_m[k]).hypot(r.y_m[k] - reference.y_m[k])).fold(0.0, f64::max)
    };
    let (coarse, fine) = (error(1e-2), error(1e-3));
    assert!(reference.peak_displacement().0 > 0.01);
    assert!(
        fine < 0.2 * coarse && fine < 1e-3 * reference.peak_displacement().0.max(0.1),
        "errors {coarse} → {fine} m"
    );

    // The study's literal zero trail: nothing turns the casters (δ stays put while the platform
    // does not yaw) and the wheels skid sideways once the load exceeds μ_lat g.
    let zero_trail = Cart { trail_m: 0.0, ..cart };
    let lateral = LateralSlip { mu: 0.3, eps_mps: 1e-3 };
    let options = Options { steer0_rad: [PI / 2.0; 4], lateral_slip: Some(lateral), ..Options::default() };
    let push = vec![0.5 * G_MPS2; 200];
    let r = run(&zero_trail, &frictionless(), &push, &vec![0.0; 200], 0.005, &options);
    assert!(r.delta_rad.iter().all(|d| d.iter().all(|&v| (v - PI / 2.0).abs() < 1e-12)));
    let t = 199.0 * 0.005;
    let expected = -0.5 * (0.5 - 0.3) * G_MPS2 * t * t;
    let x = *r.x_m.last().unwrap();
    assert!((x - expected).abs() < 0.01 * expected.abs(), "skid {x} m vs {expected} m");
}

/// The alterations the rolling diagnosis adds to the no-slip cart: each with a conservation law
/// or a closed form.
mod alterations {
    use super::*;
    use crate::physics::rolling::{Alteration, Brake, Jam, MassChange, Wall};

    fn altered(alteration: Alteration, friction: &Friction) -> NoSlip {
        let mut cart = prototype();
        cart.trail_m = 0.04;
        NoSlip::altered(&cart, friction, G_MPS2, &alteration).unwrap()
    }

    #[test]
    fn energy_balance_holds_with_an_offset_mass_a_locked_wheel_and_a_jammed_swivel() {
        // Check 2 of the notes with all three alterations at once: the offset mass adds first-
        // moment terms to M, the velocity terms and the floor's load; the locked wheel drags; the
        // jammed swivel is a workless constraint. T(t) − T(0) = floor work − friction losses to the
        // integration tolerance (1e-10 J at rtol 1e-11, as for the nominal cart).
        let alteration = Alteration {
            mass: Some(MassChange { dm_kg: -15.0, at_m: [0.3, -0.1] }),
            brake: Some(Brake { caster: 1, mu: 0.3 }),
            jam: Some(Jam { caster: 2, mu: None }),
            wall: None,
            ramp_s: 0.0,
        };
        let friction = table4_friction("MC2");
        let model = altered(alteration, &friction);
        let y0 = model
            .enter(&altered(Alteration::default(), &friction), &[0.0, 0.0, 0.2, 0.4, -0.5, 1.0, 2.0, 0.3, -0.2, 0.4]);
        let (error, dissipated) = energy_balance_error::<10, 12, _>(&model, y0);
        eprintln!("altered cart: energy balance error {error:.1e} J of {dissipated:.2} J dissipated");
        assert!(dissipated > 1.0, "friction must do real work here: {dissipated} J");
        assert!(error < 1e-10, "energy balance off by {error} J");
        // The jammed caster turns with the platform only.
        let y = integrate(|_, y| model.rhs(y, [0.5, -0.3]), y0, 2.0, 1e-11);
        assert!((y[5] - y0[5]).abs() < 1e-12, "jammed δ₃ moved: {} → {}", y0[5], y[5]);
        assert!((y[3] - y0[3]).abs() > 1e-3, "a free caster should turn: {} → {}", y0[3], y[3]);
    }

    #[test]
    fn a_friction_lock_holds_like_a_rigid_jam_below_its_strength_and_frees_the_caster_when_weak() {
        // Two limits of the friction lock, each against an independent model: a lock far stronger
        // than the platform's pull on the caster behaves as the rigid constraint (the caster
        // turns with the platform only, the platform moves as with the rigid jam), and a lock
        // of negligible strength on a cart without friction lets the caster swivel freely.
        let friction = table4_friction("MC2");
        let jam = |mu| Alteration { jam: Some(Jam { caster: 2, mu }), ..Alteration::default() };
        let (rigid, strong) = (altered(jam(None), &friction), altered(jam(Some(50.0)), &friction));
        let nominal = altered(Alteration::default(), &friction);
        let y0 = [0.0, 0.0, 0.2, 0.4, -0.5, 1.0, 2.0, 0.3, -0.2, 0.4];
        let floor = [0.5, -0.3];
        let run = |m: &NoSlip| integrate(|_, y| m.rhs(y, floor), m.enter(&nominal, &y0), 1.0, 1e-9);
        let (yr, ys) = (run(&rigid), run(&strong));
        // The strong lock starts from the nominal state (no impulse): it stops the caster over a
        // few ms, so the platform's state differs from the rigid jam's by that transient only.
        let platform = (0..3).map(|i| (ys[i] - yr[i]).abs()).fold(0.0, f64::max);
        assert!(platform < 2e-3, "strong lock vs rigid jam: platform pose differs by {platform}");
        // The caster was swivelling at the lock's start and stops within the transient (0.018 rad
        // here); a sign error would spin it up instead.
        assert!((ys[5] - y0[5]).abs() < 0.03, "a strong lock let δ₃ move {} → {}", y0[5], ys[5]);
        // On a cart without friction, a lock that weak is the free swivel.
        let free = altered(Alteration::default(), &frictionless());
        let weak = altered(jam(Some(1e-6)), &frictionless());
        let yw = integrate(|_, y| weak.rhs(y, floor), y0, 1.0, 1e-9);
        let yn = integrate(|_, y| free.rhs(y, floor), y0, 1.0, 1e-9);
        assert!((yn[5] - y0[5]).abs() > 0.1, "the nominal caster should swivel: {} → {}", y0[5], yn[5]);
        let caster = (yw[5] - yn[5]).abs();
        assert!(caster < 0.02 * (yn[5] - y0[5]).abs(), "weak lock vs nominal: δ₃ differs by {caster} rad");
    }

    #[test]
    fn frictionless_unforced_cart_with_an_offset_mass_keeps_its_kinetic_energy() {
        // The first-moment terms alone (a sign error in M's coupling or in ω²S breaks this).
        let alteration =
            Alteration { mass: Some(MassChange { dm_kg: 25.0, at_m: [-0.35, 0.2] }), ..Alteration::default() };
        let model = altered(alteration, &frictionless());
        let y0 = [0.0, 0.0, 0.1, 0.3, -1.0, 2.0, 0.5, 0.4, 0.2, 1.5];
        let y = integrate(|_, y| model.rhs(y, [0.0, 0.0]), y0, 3.0, 1e-11);
        let (t0, t1) = (model.kinetic_energy(&y0), model.kinetic_energy(&y));
        assert!(((t1 - t0) / t0).abs() < 1e-10, "T {t0} → {t1}");
    }

    #[test]
    fn an_offset_mass_shares_the_wheel_loads_by_the_lever_rule_and_a_captured_one_the_momentum() {
        let (dm, at) = (20.0, [0.3, -0.2]);
        let alteration = Alteration { mass: Some(MassChange { dm_kg: dm, at_m: at }), ..Alteration::default() };
        let model = altered(alteration, &frictionless());
        let cart = prototype();
        let loads = model.wheel_loads();
        let weight = (cart.platform_mass_kg + dm + 4.0 * cart.wheel_mass_kg) * G_MPS2;
        assert!((loads.iter().sum::<f64>() - weight).abs() < 1e-9 * weight);
        // Moments about the centre: the loads carry the point mass's moment (dm g at).
        let (a, b) = (0.5 * cart.length_m, 0.5 * cart.width_m);
        let mx: f64 = loads.iter().zip(PIVOT_SIGNS).map(|(n, (sx, _))| n * sx * a).sum();
        let my: f64 = loads.iter().zip(PIVOT_SIGNS).map(|(n, (_, sy))| n * sy * b).sum();
        assert!((mx - dm * G_MPS2 * at[0]).abs() < 1e-9 && (my - dm * G_MPS2 * at[1]).abs() < 1e-9, "{mx} {my}");
        // Captured at rest on the floor: the generalised momentum M ν is the same before and after.
        let before = altered(Alteration::default(), &frictionless());
        let y = [0.1, 0.0, 0.3, 0.2, -0.4, 2.0, 0.5, 0.4, -0.3, 0.6];
        let after = model.enter(&before, &y);
        let p = |m: &NoSlip, s: &[f64; 10]| {
            let mm = m.mass_matrix(s);
            [0, 1, 2].map(|i| mm[i][0] * s[7] + mm[i][1] * s[8] + mm[i][2] * s[9])
        };
        let (p0, p1) = (p(&before, &y), p(&model, &after));
        for i in 0..3 {
            assert!((p0[i] - p1[i]).abs() < 1e-12 * p0[i].abs().max(1.0), "{p0:?} vs {p1:?}");
        }
        assert!(after[7] < y[7], "a captured mass slows the cart: {} → {}", y[7], after[7]);
    }

    #[test]
    fn a_locked_wheel_drags_with_mu_times_its_load() {
        // Once it slides (|v| ≫ ε), the locked wheel dissipates μ N |v|; the other wheels roll freely.
        let mu = 0.35;
        let model =
            altered(Alteration { brake: Some(Brake { caster: 0, mu }), ..Alteration::default() }, &frictionless());
        let y = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0];
        let p = model.power(&y, [0.0, 0.0]);
        let expected = -mu * model.wheel_loads()[0] * 0.5;
        assert!((p.friction_w - expected).abs() < 1e-9 * expected.abs(), "{} vs {expected}", p.friction_w);
    }

    #[test]
    fn a_wall_returns_the_striking_corner_at_e_times_its_speed() {
        // Frictionless, unforced, the casters aligned with the motion (+X), yawed so that corner 4
        // (+a, −b) strikes alone: its speed into the wall after the contact is −e times the speed
        // before, within the few per cent the cart's rotation during the 20 ms contact changes its
        // effective mass (measured below).
        // A long trail and light wheels: the casters barely turn during the contact (reversing,
        // they start to flip at v/d), so the platform meets the wall as one rigid body.
        let cart = Cart { trail_m: 0.2, wheel_mass_kg: 0.01, ..prototype() };
        let yaw = 0.3;
        let e = 0.6;
        let (a, b) = (0.5 * cart.length_m, 0.5 * cart.width_m);
        let corner_x = |x: f64, th: f64| x + th.cos() * a + th.sin() * b;
        let wall = Wall {
            axis: 0,
            side: 1.0,
            position_m: corner_x(0.0, yaw) + 0.02,
            restitution: e,
            contact_s: 0.02,
            neighbour: false,
        };
        let alteration = Alteration { wall: Some(wall), ..Alteration::default() };
        let n = 201;
        let zeros = vec![0.0; n];
        let excitation = Excitation { t0_s: 0.0, dt_s: 0.005, ax_mps2: &zeros, ay_mps2: &zeros };
        let options = Options { yaw0_rad: yaw, steer0_rad: [-yaw; 4], ..Options::default() };
        let y0 = [0.0, 0.0, yaw, -yaw, -yaw, -yaw, -yaw, 0.5, 0.0, 0.0];
        let r =
            simulate_altered(&cart, &frictionless(), &excitation, &options, &alteration, Some((0, &y0)), n - 1, None)
                .unwrap();
        let speed = |k: usize| {
            let s = &r.states[k];
            // v_corner,x = ẋ − ω r_y of corner 4, r_y = a sin θ − b cos θ.
            s[7] - s[9] * (s[2].sin() * a - s[2].cos() * b)
        };
        let inside = |k: usize| corner_x(r.x_m[k], r.yaw_rad[k]) > wall.position_m;
        let first = (0..n).find(|&k| inside(k)).expect("the corner reaches the wall");
        let last = (first..n).find(|&k| !inside(k)).expect("the corner leaves the wall");
        assert!((last - first) as f64 * 0.005 < 0.03, "contact from sample {first} to {last}");
        let before = speed(first - 1);
        let after = speed(last);
        let ratio = -after / before;
        eprintln!("wall: corner speed {before:.4} → {after:.4} m/s, ratio {ratio:.4} (e = {e})");
        assert!((speed(0) - 0.5).abs() < 1e-9 && (before - 0.5).abs() < 1e-9, "{before}");
        assert!((ratio - e).abs() < 0.03 * e, "rebound ratio {ratio} vs e = {e}");
    }

    #[test]
    fn a_compliant_neighbour_rebounds_as_a_clamped_kelvin_voigt_contact() {
        // Frictionless, unforced, unyawed, casters along +X: corners 1 and 4 strike together, so
        // the cart (mass M, light wheels) meets a spring 2k and dashpot 2c, k = mω², c = 2ζωm
        // (m = the cart's mass, ω, ζ from the contact time and e). Closed form of that oscillator
        // from x = 0, ẋ = v₀: x = v₀/ω_d e^(−ζ'ω't) sin ω_d t; the contact ends where the force
        // 2k x + 2c ẋ reaches zero (a neighbour only pushes), found by bisection; the speed then.
        let cart = Cart { trail_m: 0.2, wheel_mass_kg: 0.01, ..prototype() };
        let (e, contact_s, v0) = (0.5, 0.06, 0.4);
        let a = 0.5 * cart.length_m;
        let wall = Wall { axis: 0, side: 1.0, position_m: a + 0.01, restitution: e, contact_s, neighbour: true };
        let alteration = Alteration { wall: Some(wall), ..Alteration::default() };
        let n = 301;
        let zeros = vec![0.0; n];
        let dt = 0.001;
        let excitation = Excitation { t0_s: 0.0, dt_s: dt, ax_mps2: &zeros, ay_mps2: &zeros };
        let y0 = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, v0, 0.0, 0.0];
        let r = simulate_altered(
            &cart,
            &frictionless(),
            &excitation,
            &Options::default(),
            &alteration,
            Some((0, &y0)),
            n - 1,
            None,
        )
        .unwrap();
        let m = cart.platform_mass_kg + 4.0 * cart.wheel_mass_kg;
        let ln_e = e.ln();
        let zeta = -ln_e / (std::f64::consts::PI.powi(2) + ln_e * ln_e).sqrt();
        let omega = std::f64::consts::PI / (contact_s * (1.0 - zeta * zeta).sqrt());
        // The wheels' spin inertia adds 4 I_s/r² = 2 m_w to the mass moving along X (I_s = m_w r²/2).
        let moving = cart.platform_mass_kg + 6.0 * cart.wheel_mass_kg;
        let (k2, c2) = (2.0 * m * omega * omega, 2.0 * 2.0 * zeta * omega * m);
        let w0 = (k2 / moving).sqrt();
        let z = c2 / (2.0 * (k2 * moving).sqrt());
        let wd = w0 * (1.0 - z * z).sqrt();
        let x = |t: f64| v0 / wd * (-z * w0 * t).exp() * (wd * t).sin();
        let v = |t: f64| v0 * (-z * w0 * t).exp() * ((wd * t).cos() - z * w0 / wd * (wd * t).sin());
        let force = |t: f64| k2 * x(t) + c2 * v(t);
        let (mut lo, mut hi) = (0.5 * std::f64::consts::PI / wd, std::f64::consts::PI / wd);
        assert!(force(lo) > 0.0 && force(hi) < 0.0);
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if force(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let exact = -v(lo) / v0;
        // After the contact the cart rolls freely: its speed is the exit speed.
        let after = r.states[n - 1][7];
        let ratio = -after / v0;
        eprintln!("neighbour: rebound ratio {ratio:.4}, clamped Kelvin–Voigt closed form {exact:.4} (e = {e})");
        assert!(after < 0.0 && r.x_m[n - 1] < 0.01, "the cart rebounds: {after} m/s at x = {}", r.x_m[n - 1]);
        // The integrator's tolerance and the light wheels' inertia: within 1 %.
        assert!((ratio - exact).abs() < 0.01 * exact, "rebound ratio {ratio} vs the closed form {exact}");
    }

    /// A cart moving along +X with its casters along it, frictionless and unforced, from rest pose.
    fn straight(cart: &Cart, alteration: &Alteration, v0: f64, n: usize, dt: f64) -> Response {
        let zeros = vec![0.0; n];
        let excitation = Excitation { t0_s: 0.0, dt_s: dt, ax_mps2: &zeros, ay_mps2: &zeros };
        let y0 = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, v0, 0.0, 0.0];
        simulate_altered(
            cart,
            &frictionless(),
            &excitation,
            &Options::default(),
            alteration,
            Some((0, &y0)),
            n - 1,
            None,
        )
        .unwrap()
    }

    #[test]
    fn a_mass_captured_over_a_ramp_shares_the_momentum_piece_by_piece() {
        // Centred, frictionless, unforced, straight along X: every piece of the ramp is a
        // perfectly inelastic capture, so the X momentum M₀₀ v is conserved across the whole ramp
        // (v₁ = v₀ M₀₀/M₀₀' whatever the pieces), and halfway through the ramp about half the mass
        // has been captured (the staircase's piece there holds 8.5/16 of it).
        let cart = Cart { trail_m: 0.2, ..prototype() };
        let (dm, ramp, v0, dt) = (30.0, 0.2, 0.5, 0.001);
        let alteration = Alteration {
            mass: Some(MassChange { dm_kg: dm, at_m: [0.0, 0.0] }),
            ramp_s: ramp,
            ..Alteration::default()
        };
        let r = straight(&cart, &alteration, v0, 401, dt);
        let y = [0.0; 10];
        let m00 = |dm: f64| {
            let change = Alteration { mass: Some(MassChange { dm_kg: dm, at_m: [0.0, 0.0] }), ..Alteration::default() };
            NoSlip::altered(&cart, &frictionless(), G_MPS2, &change).unwrap().mass_matrix(&y)[0][0]
        };
        let end = r.states.last().unwrap()[7];
        let exact = v0 * m00(0.0) / m00(dm);
        eprintln!("ramped capture: {v0} → {end:.9} m/s, closed form {exact:.9}");
        assert!((end - exact).abs() < 1e-9, "{end} vs {exact}");
        let half = r.states[(0.5 * ramp / dt).round() as usize + 1][7];
        let (slow, fast) = (v0 * m00(0.0) / m00(0.6 * dm), v0 * m00(0.0) / m00(0.4 * dm));
        assert!(slow < half && half < fast, "halfway: {half} m/s, not within ({slow}, {fast})");
    }

    #[test]
    fn a_pad_whose_drag_builds_up_dissipates_the_linear_ramps_work() {
        // Only the braked wheel has friction: the kinetic energy lost equals ∫ μ(t) N v tanh(v/ε) dt
        // with μ(t) = μ min(1, t/T) the linear ramp (trapezoid rule on the run's own wheel speed),
        // to the staircase's and the quadrature's error; a step would lose ~17 % more here.
        let cart = Cart { trail_m: 0.2, ..prototype() };
        let (mu, ramp, v0, dt, n) = (0.3, 0.2, 0.5, 0.001, 401);
        let alteration = Alteration { brake: Some(Brake { caster: 0, mu }), ramp_s: ramp, ..Alteration::default() };
        let r = straight(&cart, &alteration, v0, n, dt);
        let model = NoSlip::altered(&cart, &frictionless(), G_MPS2, &alteration).unwrap();
        let load = model.wheel_loads()[0];
        let eps = frictionless().eps_mps;
        let power = |k: usize| {
            let v = r.roll_speed_mps[0][k];
            mu * (k as f64 * dt / ramp).min(1.0) * load * v * (v / eps).tanh()
        };
        let work: f64 = (0..n - 1).map(|k| 0.5 * dt * (power(k) + power(k + 1))).sum();
        let lost = r.kinetic_energy_j[0] - r.kinetic_energy_j[n - 1];
        eprintln!("ramped brake: kinetic energy lost {lost:.5} J, the linear ramp's work {work:.5} J");
        assert!(lost > 1.0, "the brake must do real work: {lost} J");
        assert!((lost - work).abs() < 5e-3 * work, "lost {lost} J vs {work} J");
    }

    #[test]
    fn an_altered_run_that_stops_says_why_and_what_it_spent() {
        // A fit charges a stopped run's evaluations against its allowance: a refusal before the
        // run spends nothing, a run cut by its budget reports at least the budget.
        let n = 401;
        let floor: Vec<f64> = (0..n).map(|k| 2.0 * (k as f64 * 0.005 * 6.0).sin()).collect();
        let excitation = Excitation { t0_s: 0.0, dt_s: 0.005, ax_mps2: &floor, ay_mps2: &floor };
        let (cart, options) = (prototype(), Options::default());
        let run = |end, budget| {
            simulate_altered(&cart, &frictionless(), &excitation, &options, &Alteration::default(), None, end, budget)
        };
        let refused = run(n, None).unwrap_err();
        assert_eq!(refused.spent, 0);
        assert_eq!(refused.to_string(), "cannot simulate samples 0..=401 of a 401-sample floor record");
        let whole = run(n - 1, None).unwrap().stats.rhs_evals;
        let cut = run(n - 1, Some(whole / 4)).unwrap_err();
        assert!(cut.spent >= whole / 4 && cut.spent < whole, "{} of {whole} evaluations spent", cut.spent);
        assert_eq!(cut.to_string(), cut.error.to_string());
    }
}
