"""The 4WMC rolling model written straight from ../shared/docs/4WMC-NOTES.md ("A consistent
formulation"), with numpy + scipy and nothing taken from shakeflow's code: the one check of the
swivel-friction convention that does not share shakeflow's construction (rolling_kane.py does, by
design, and so could not have caught it).

From the notes, literally:
- r_i = R(theta) p_i, psi_i = theta + delta_i, e_i = (cos psi, sin psi), n_i = (-sin psi, cos psi),
  a_i = [e_i; r_i x e_i], b_i = [n_i; r_i x n_i]; delta_i' = b_i.nu/d - omega.
- M(q) = diag(m_p, m_p, I_p) + sum[(m_w + I_s/r^2) a a^T + (I_z/d^2) b b^T].
- M nu' + sum_b J_b^T m_b J_b' nu = Q_eq + Q_f, the J_b rows: platform (identity), wheel centre
  e_i a_i^T (mass m_w), spin a_i^T/r (I_s), caster yaw b_i^T/d (I_z). J_b' is taken here by a
  complex-step derivative of J_b along the motion (the notes allow automatic differentiation;
  nothing is derived by hand; rolling_notes_rinaldi.json was made with a central difference at
  h = 1e-7, which agrees with it to ~1e-9 of J').
- Q_eq = -m_p [u_fx'', u_fy'', 0] - m_w sum a_i (e_i . u_f'').
- N = (m_w + m_p/4) g; rolling: Q_f += -mu_r(|v_i|) N tanh(v_i/eps) a_i, v_i = a_i.nu;
  swivel (erratum 2026-11-25): Q_f += -mu_sw(rho |delta_i'|) N rho tanh(delta_i'/eps_sw) (b_i/d - k).
- mu(v) = mu_s sech(beta v) + mu_k (1 - sech(beta v)) + gamma_n |v|^p.
Pivot order (the notes' mirror-symmetry test): (+a,+b), (-a,+b), (-a,-b), (+a,-b).

    rolling_notes.py rolling_floor_rinaldi.csv --seconds 10 > rolling_notes_rinaldi.json
    rolling_notes.py rolling_floor_gil067_isolated.csv --seconds 40 --rtol 1e-12 --atol 1e-15 --unit PB2 \
        --every 10 --per-sample > rolling_notes_gil067_isolated.json

rolling_notes_rinaldi.json was made before --per-sample and the complex step (one DOP853 run over
the record, J' by a central difference): within 3.5e-6 m of shakeflow over its 10 s. On a slow
isolated floor that way left errors of 1e-9 m by 4 s that the creeping cart amplifies to
centimetres by 38 s; sample by sample it follows shakeflow within 1.2e-9 m over 10 s and 2.4 mm
over the 40 s (docs/convergence.md).
"""
import argparse
import json
import math
import sys
import time

import numpy as np
from scipy.integrate import solve_ivp

G = 9.80665
# The study's Table 4, metal cart MC2 (SEED-SUMMARY.md); trail 0.3 D and rho 0.02 m as the notes
# suggest (a swivel-bearing radius).
MC2 = dict(length_m=0.65, width_m=0.90, platform_mass_kg=154.0, yaw0_deg=15.0, wheel_diameter_m=0.125,
           wheel_width_m=0.030, wheel_mass_kg=0.5, steer0_deg=[0.0, 0.0, 0.0, 0.0], mu_s_roll=0.044,
           mu_s_swivel=0.044, mu_k_roll=0.0044, mu_k_swivel=0.0044, beta_spm=6.05, gamma_n=0.00044, p=1.0,
           trail_m=0.3 * 0.125, swivel_arm_m=0.02, friction_eps=1e-4, friction_eps_swivel=1e-4)
# The patient bed PB2 of Table 4, with shakeflow's defaults where the study gives nothing (trail
# 0.3 D, rho 0.02 m, eps 1e-4 m/s, eps_sw 1e-3 rad/s).
PB2 = dict(length_m=2.36, width_m=1.05, platform_mass_kg=350.0, yaw0_deg=8.0, wheel_diameter_m=0.20,
           wheel_width_m=0.055, wheel_mass_kg=1.5, steer0_deg=[-35.0, 0.0, 0.0, 35.0], mu_s_roll=0.012,
           mu_s_swivel=0.00132, mu_k_roll=6.0e-4, mu_k_swivel=1.2e-4, beta_spm=15.0, gamma_n=0.00042, p=1.0,
           trail_m=0.3 * 0.20, swivel_arm_m=0.02, friction_eps=1e-4, friction_eps_swivel=1e-3)
UNITS = {"MC2": MC2, "PB2": PB2}


def model(spec):
    a, b = spec["length_m"] / 2, spec["width_m"] / 2
    r = spec["wheel_diameter_m"] / 2
    d, rho = spec["trail_m"], spec["swivel_arm_m"]
    mp, mw = spec["platform_mass_kg"], spec["wheel_mass_kg"]
    Ip = mp * (a * a + b * b) / 3
    Is = 0.5 * mw * r * r
    Iz = mw * (3 * r * r + spec["wheel_width_m"] ** 2) / 12
    N = (mw + mp / 4) * G
    pivots = np.array([[a, b], [-a, b], [-a, -b], [a, -b]])
    eps, eps_sw = spec["friction_eps"], spec["friction_eps_swivel"]

    def mu(ms, mk, v):
        s = 1 / math.cosh(min(spec["beta_spm"] * v, 700.0))
        return ms * s + mk * (1 - s) + spec["gamma_n"] * v ** spec["p"]

    def frames(q):
        th = q[2]
        c, s = np.cos(th), np.sin(th)
        out = []
        for i in range(4):
            rx = c * pivots[i, 0] - s * pivots[i, 1]
            ry = s * pivots[i, 0] + c * pivots[i, 1]
            psi = th + q[3 + i]
            e = np.array([np.cos(psi), np.sin(psi)])
            n = np.array([-np.sin(psi), np.cos(psi)])
            av = np.array([e[0], e[1], rx * e[1] - ry * e[0]])
            bv = np.array([n[0], n[1], rx * n[1] - ry * n[0]])
            out.append((e, av, bv))
        return out

    def jacobians(q):
        """Per body: (J, mass or inertia)."""
        out = [(np.eye(3)[:2], mp), (np.eye(3)[2:], Ip)]
        for e, av, bv in frames(q):
            out.append((np.outer(e, av), mw))
            out.append((av[None, :] / r, Is))
            out.append((bv[None, :] / d, Iz))
        return out

    def qdot(q, nu):
        rates = [bv @ nu / d - nu[2] for _, _, bv in frames(q)]
        return np.concatenate([nu, rates])

    def rhs(t, y, floor):
        q, nu = y[:7], y[7:]
        fr = frames(q)
        M = np.diag([mp, mp, Ip]).astype(float)
        for _, av, bv in fr:
            M += (mw + Is / r ** 2) * np.outer(av, av) + (Iz / d ** 2) * np.outer(bv, bv)
        qd = qdot(q, nu)
        # J' along the motion by the complex step: Im J(q + i h q') / h, exact to rounding (no
        # difference of two nearby values, so no cancellation; a central difference at h = 1e-7
        # left ~1e-9 of J' as noise, which a creeping cart amplifies to millimetres in 40 s).
        h = 1e-30
        gyro = np.zeros(3)
        for (J, m), (Jstep, _) in zip(jacobians(q), jacobians(q + 1j * h * qd)):
            Jdot = Jstep.imag / h
            gyro += J.T @ (m * (Jdot @ nu))
        uf = floor(t)
        Q = -mp * np.array([uf[0], uf[1], 0.0])
        for i, (e, av, bv) in enumerate(fr):
            Q -= mw * av * (e @ uf)
            v = av @ nu
            Q -= mu(spec["mu_s_roll"], spec["mu_k_roll"], abs(v)) * N * math.tanh(v / eps) * av
            dd = bv @ nu / d - nu[2]
            torque = mu(spec["mu_s_swivel"], spec["mu_k_swivel"], rho * abs(dd)) * N * rho * math.tanh(dd / eps_sw)
            Q -= torque * (bv / d - np.array([0.0, 0.0, 1.0]))
        nud = np.linalg.solve(M, Q - gyro)
        return np.concatenate([qd, nud])

    return rhs


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("floor")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rtol", type=float, default=1e-9)
    ap.add_argument("--unit", choices=sorted(UNITS), default="MC2")
    ap.add_argument("--atol", type=float, default=1e-11, help="absolute tolerance of every state (m, rad, m/s, rad/s)")
    ap.add_argument("--every", type=int, default=1, help="write every n-th sample of the trajectory")
    ap.add_argument("--per-sample", action="store_true",
                    help="integrate each sample interval on its own (the floor's slope jumps at every sample, "
                         "which a step straddling it resolves only to first order)")
    args = ap.parse_args()
    data = np.genfromtxt(args.floor, delimiter=",", names=True)
    keep = data["time_s"] <= args.seconds + 1e-9
    t, ax, ay = data["time_s"][keep], data["ax_mps2"][keep], data["ay_mps2"][keep]
    dt = (t[-1] - t[0]) / (len(t) - 1)

    def floor(time_s):
        x = (time_s - t[0]) / dt
        k = min(int(x), len(t) - 2)
        f = x - k
        return np.array([ax[k] + f * (ax[k + 1] - ax[k]), ay[k] + f * (ay[k + 1] - ay[k])])

    spec = UNITS[args.unit]
    rhs = model(spec)
    y0 = np.zeros(10)
    y0[2] = math.radians(spec["yaw0_deg"])
    y0[3:7] = np.radians(spec["steer0_deg"])
    started = time.perf_counter()
    if args.per_sample:
        states = [y0]
        for k in range(len(t) - 1):
            piece = solve_ivp(lambda tt, yy: rhs(tt, yy, floor), (t[k], t[k + 1]), states[-1], method="DOP853",
                              rtol=args.rtol, atol=args.atol)
            assert piece.status == 0, piece.message
            states.append(piece.y[:, -1])
        solution = np.array(states).T
    else:
        sol = solve_ivp(lambda tt, yy: rhs(tt, yy, floor), (t[0], t[-1]), y0, method="DOP853", rtol=args.rtol,
                        atol=args.atol, t_eval=t, max_step=dt)
        assert sol.status == 0, sol.message
        solution = sol.y
    x, y, yaw = solution[0], solution[1], solution[2] - y0[2]
    k = slice(None, None, args.every)
    json.dump({"source": "tests/reference/rolling_notes.py " + " ".join(sys.argv[1:]), "model": spec,
               "rtol": args.rtol, "atol": args.atol, "seconds": time.perf_counter() - started, "every": args.every,
               "time_s": t[k].tolist(), "x_m": x[k].tolist(), "y_m": y[k].tolist(),
               "yaw_change_rad": yaw[k].tolist(), "steer_rad": solution[3:7, k].tolist(),
               "peak_displacement_m": float(np.max(np.hypot(x, y))),
               "peak_yaw_change_rad": float(np.max(np.abs(yaw)))}, sys.stdout)
    print()


if __name__ == "__main__":
    main()
