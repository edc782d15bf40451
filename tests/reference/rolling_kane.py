"""Independent peer of shakeflow's rolling model: the caster cart derived symbolically with
sympy.physics.mechanics (Kane's method with nonholonomic constraints) and integrated by scipy.

Nothing here is transcribed from shakeflow's equations. The model is stated as a multibody
system: a platform (frame P, yaw th) moving in the floor plane; per caster a fork frame F_i
yawing about the vertical at its pivot (steering angle d_i from P), a wheel W_i spinning about
the fork's axle F_i.y, its centre a trail `d` behind the pivot, its contact point `r` below the
centre. The wheel's contact point has zero velocity along and across the wheel (two velocity
constraints per caster), so the fork yaw and wheel spin rates are dependent speeds. KanesMethod
forms the equations; the mass matrix and forcing are lambdified and solved numerically.

Loads (the formulation of shakeflow's 4WMC-NOTES.md, stated physically):
- the floor only translates: every body gets the inertial force -m * (ax, ay) at its centre;
- rolling resistance at each wheel centre: -mu_roll(|v|) N tanh(v/eps) along F_i.x, v = the
  centre's speed along F_i.x; mu(v) = mu_s sech(beta v) + mu_k (1 - sech(beta v)) + gamma |v|^p;
- swivel bearing: torque -mu_sw(rho|w|) N rho tanh(w/eps_sw) about the vertical on the fork and
  the opposite torque on the platform, w = the fork's yaw rate relative to the platform (eps_sw
  in rad/s, the swivel's own regularisation; results stored before it existed used
  tanh(rho w/eps), i.e. eps_sw = eps/rho, and state no friction_eps_swivel);
- N = (m_w + m_p/4) g per wheel; caster pivots at the platform corners, order (+a,+b), (-a,+b),
  (-a,-b), (+a,-b).

Usage: rolling_kane.py --floor FLOOR.csv --units PS1,MC2 [--t-end S] [--rtol R] [--every K] --out OUT.json
FLOOR.csv: time_s, ax_mps2, ay_mps2 (uniform). Units take the study's Table 4 (transcribed here
independently of shakeflow's presets), with the caster trail d = max(0.3 x wheel diameter, 5 mm),
swivel lever arm 0.02 m and friction regularisations 1e-4 m/s (rolling) and 1e-3 rad/s (swivel)
that shakeflow uses by default.
The floor is linear between samples and the integration restarts at every sample, as shakeflow
does. OUT.json: per unit, the parameters and the state at every K-th sample.
"""
import argparse
import json
import time

import numpy as np
import sympy as sm
import sympy.physics.mechanics as me
from scipy.integrate import solve_ivp

G = 9.80665
PIVOT_SIGNS = [(1, 1), (-1, 1), (-1, -1), (1, -1)]
# Table 4 of the study (SEED-SUMMARY.md): 2a, 2b, m_p, yaw0, D, e_w, m_w, steer0 (wheels 1-4),
# mu_s roll, mu_s swivel, mu_k roll, mu_k swivel, beta, gamma_n (p = 1).
TABLE4 = {
    "PS1": (2.20, 1.00, 234, 6, 0.20, 0.045, 1.0, [80, 0, 0, 80], 0.045, 0.00049, 0.00049, 2.45e-5, 19.76, 0.0014),
    "PB2": (2.36, 1.05, 350, 8, 0.20, 0.055, 1.5, [-35, 0, 0, 35], 0.012, 0.00132, 6.0e-4, 1.2e-4, 15.00, 0.00042),
    "MC2": (0.65, 0.90, 154, 15, 0.125, 0.030, 0.5, [0, 0, 0, 0], 0.044, 0.044, 0.0044, 0.0044, 6.05, 0.00044),
    "UI3": (0.70, 0.55, 180, 0, 0.15, 0.030, 0.5, [0, 0, 0, 0], 0.025, 0.001, 0.001, 5.0e-5, 0.49, 0.0001),
}


def unit_spec(unit):
    l, w, mp, yaw, dw, ew, mw, steer, msr, mss, mkr, mks, beta, gamma = TABLE4[unit]
    return {
        "length_m": l, "width_m": w, "platform_mass_kg": mp, "yaw0_deg": yaw, "wheel_diameter_m": dw,
        "wheel_width_m": ew, "wheel_mass_kg": mw, "steer0_deg": steer, "mu_s_roll": msr, "mu_s_swivel": mss,
        "mu_k_roll": mkr, "mu_k_swivel": mks, "beta_spm": beta, "gamma_n": gamma, "p": 1.0,
        "trail_m": max(0.3 * dw, 0.005), "swivel_arm_m": 0.02, "friction_eps": 1e-4,
        "friction_eps_swivel": 1e-3,
    }


def derive():
    """Kane's equations of the cart; returns lambdified (mass matrix, forcing, dependent speeds)."""
    x, y, th = me.dynamicsymbols("x y th")
    dl = me.dynamicsymbols("d1:5")
    ph = me.dynamicsymbols("phi1:5")
    ux, uy, w = me.dynamicsymbols("ux uy w")
    ud = me.dynamicsymbols("ud1:5")
    up = me.dynamicsymbols("up1:5")
    a, b, r, d, rho, mp, mw, Ip, Is, Iz, Nw = sm.symbols("a b r d rho m_p m_w I_p I_s I_z N_w", positive=True)
    mus_r, muk_r, mus_s, muk_s, beta, gam, p, eps, eps_sw = sm.symbols(
        "mus_r muk_r mus_s muk_s beta gamma p eps eps_sw")
    ax, ay = sm.symbols("a_x a_y")

    N = me.ReferenceFrame("N")
    O = me.Point("O")
    O.set_vel(N, 0)
    P = N.orientnew("P", "Axis", [th, N.z])
    P.set_ang_vel(N, w * N.z)
    Pc = O.locatenew("Pc", x * N.x + y * N.y)
    Pc.set_vel(N, ux * N.x + uy * N.y)

    def mu(mu_s, mu_k, speed):
        sech = 1 / sm.cosh(beta * speed)
        return mu_s * sech + mu_k * (1 - sech) + gam * speed**p

    floor_force = lambda m: -m * (ax * N.x + ay * N.y)
    bodies = [me.RigidBody("platform", Pc, P, mp, (me.inertia(P, Ip / 2, Ip / 2, Ip), Pc))]
    loads = [(Pc, floor_force(mp))]
    constraints = []
    for i, (sx, sy) in enumerate(PIVOT_SIGNS):
        F = P.orientnew(f"F{i}", "Axis", [dl[i], P.z])
        F.set_ang_vel(P, ud[i] * P.z)
        W = F.orientnew(f"W{i}", "Axis", [ph[i], F.y])
        W.set_ang_vel(F, up[i] * F.y)
        pivot = Pc.locatenew(f"pivot{i}", sx * a * P.x + sy * b * P.y)
        pivot.v2pt_theory(Pc, N, P)
        centre = pivot.locatenew(f"C{i}", -d * F.x)
        centre.v2pt_theory(pivot, N, F)
        contact = centre.locatenew(f"K{i}", -r * N.z)
        contact.v2pt_theory(centre, N, W)
        constraints += [contact.vel(N).dot(F.x), contact.vel(N).dot(F.y)]
        bodies.append(me.RigidBody(f"wheel{i}", centre, W, mw, (me.inertia(F, Iz, Is, Iz), centre)))
        v = centre.vel(N).dot(F.x)
        roll = mu(mus_r, muk_r, sm.sqrt(v**2)) * Nw * sm.tanh(v / eps)
        swivel = rho * mu(mus_s, muk_s, rho * sm.sqrt(ud[i] ** 2)) * Nw * sm.tanh(ud[i] / eps_sw)
        loads += [(centre, floor_force(mw) - roll * F.x), (F, -swivel * N.z), (P, swivel * N.z)]

    q = [x, y, th, *dl, *ph]
    u_ind = [ux, uy, w]
    u_dep = [*ud, *up]
    u = u_ind + u_dep
    kd = [qi.diff() - ui for qi, ui in zip(q, u)]
    kane = me.KanesMethod(N, q_ind=q, u_ind=u_ind, kd_eqs=kd, u_dependent=u_dep, velocity_constraints=constraints)
    kane.kanes_equations(bodies, loads)
    params = [a, b, r, d, rho, mp, mw, Ip, Is, Iz, Nw, mus_r, muk_r, mus_s, muk_s, beta, gam, p, eps, eps_sw]
    dep = sm.solve(constraints, u_dep, dict=True)[0]
    args = (q, u, params, ax, ay)
    mass = sm.lambdify(args, kane.mass_matrix, cse=True)
    forcing = sm.lambdify(args, kane.forcing, cse=True)
    dependent = sm.lambdify((q, u_ind, params), [dep[s] for s in u_dep], cse=True)
    return mass, forcing, dependent


def parameters(spec):
    a, b = spec["length_m"] / 2, spec["width_m"] / 2
    r = spec["wheel_diameter_m"] / 2
    mp, mw, width = spec["platform_mass_kg"], spec["wheel_mass_kg"], spec["wheel_width_m"]
    return [
        a, b, r, spec["trail_m"], spec["swivel_arm_m"], mp, mw,
        mp * (a * a + b * b) / 3, mw * r * r / 2, mw * (3 * r * r + width * width) / 12, (mw + mp / 4) * G,
        spec["mu_s_roll"], spec["mu_k_roll"], spec["mu_s_swivel"], spec["mu_k_swivel"],
        spec["beta_spm"], spec["gamma_n"], spec["p"], spec["friction_eps"],
        spec.get("friction_eps_swivel", spec["friction_eps"] / spec["swivel_arm_m"]),
    ]


def simulate(equations, spec, time_s, ax, ay, t_end, rtol, every):
    mass, forcing, dependent = equations
    prm = parameters(spec)
    steer = [np.radians(v) for v in spec["steer0_deg"]]
    state = np.array([0.0, 0.0, np.radians(spec["yaw0_deg"]), *steer, 0, 0, 0, 0, 0.0, 0.0, 0.0])

    def rhs(t, s, seg):
        q, ui = s[:11], s[11:]
        uall = list(ui) + list(dependent(q, ui, prm))
        fx, fy = seg(t)
        acc = np.linalg.solve(np.asarray(mass(q, uall, prm, fx, fy), float), np.asarray(forcing(q, uall, prm, fx, fy), float).ravel())
        return np.concatenate([uall, acc[:3]])

    n = int(round((min(t_end, time_s[-1]) - time_s[0]) / (time_s[1] - time_s[0]))) + 1
    out = [state.copy()]
    kept = [0]
    evals = 0
    for k in range(n - 1):
        t0, t1 = time_s[k], time_s[k + 1]
        rate = ((ax[k + 1] - ax[k]) / (t1 - t0), (ay[k + 1] - ay[k]) / (t1 - t0))
        seg = lambda t, k=k, t0=t0, rate=rate: (ax[k] + rate[0] * (t - t0), ay[k] + rate[1] * (t - t0))
        sol = solve_ivp(rhs, (t0, t1), state, method="DOP853", rtol=rtol, atol=rtol * 1e-2, args=(seg,))
        evals += sol.nfev
        state = sol.y[:, -1]
        if (k + 1) % every == 0:
            out.append(state.copy())
            kept.append(k + 1)
    return np.array(out), kept, evals


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--floor", required=True)
    ap.add_argument("--units", required=True, help="comma-separated Table 4 units")
    ap.add_argument("--t-end", type=float, default=float("inf"))
    ap.add_argument("--rtol", type=float, default=1e-10)
    ap.add_argument("--every", type=int, default=1, help="keep every K-th sample")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    floor = np.loadtxt(args.floor, delimiter=",", skiprows=1)
    started = time.perf_counter()
    equations = derive()
    result = {
        "generator": f"tests/reference/rolling_kane.py (sympy {sm.__version__}, scipy solve_ivp DOP853, rtol {args.rtol})",
        "floor": args.floor.split("/")[-1],
        "derivation_s": time.perf_counter() - started,
        "units": {},
    }
    for unit in args.units.split(","):
        spec = unit_spec(unit)
        started = time.perf_counter()
        states, kept, evals = simulate(equations, spec, floor[:, 0], floor[:, 1], floor[:, 2], args.t_end, args.rtol, args.every)
        result["units"][unit] = {
            "params": spec,
            "wall_s": time.perf_counter() - started,
            "rhs_evals": evals,
            "sample": kept,
            "x_m": states[:, 0].tolist(),
            "y_m": states[:, 1].tolist(),
            "yaw_rad": states[:, 2].tolist(),
            "delta_rad": [states[:, 3 + i].tolist() for i in range(4)],
        }
    with open(args.out, "w") as f:
        json.dump(result, f)


if __name__ == "__main__":
    main()
