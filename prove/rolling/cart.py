"""An independent 4WMC caster cart for the rolling proof cases, written from
../shared/docs/4WMC-NOTES.md ("A consistent formulation", with the swivel erratum) with numba,
and nothing taken from shakeflow's Rust code; each concealed effect is this file's own physics:

Each effect has two formulations (generate.py draws one), so that the proof does not only measure
how well the diagnosis recovers the parameters of the physics it fits itself:

- mass change: the platform is a uniform plate plus a point mass dm (negative: lost) at a body
  offset; wheel loads of a rigid plate on four equal supports; a loss leaves with its own velocity
  (nu continuous), a gain is captured at rest on the floor (generalised momentum conserved).
  Formulations: a step, or a loss spread linearly over ramp_s (bottles falling off one by one);
- caster brake: one wheel's slide along its heading is resisted by mu_drag N. Formulations: the
  wheel locks (no spin inertia), or a pad drags a still spinning wheel with a drag that builds up
  over ramp_s;
- swivel jam: one caster's swivel stops. Formulations: a rigid lock (delta_dot = 0 as a
  Lagrange-multiplier constraint with Baumgarte stabilisation; the jam is a plastic impulse onto
  the constraint), or a friction lock (a swivel torque mu_jam N rho tanh(delta_dot / 0.01 rad/s)
  that slips when the cart pulls harder);
- lateral impact: a wall across X or Y struck by a platform corner. Formulations: RIGID (Newton's
  impact law with restitution e on the corner's normal speed, an impulse through the generalised
  mass), or a COMPLIANT neighbour (a compressive spring-dashpot k pen + c pen_dot at every corner
  past its face, contact frequencies from 4 Hz, far softer than shakeflow's 20 ms contact);
- floor tilt (an `unexplained` kind): the slab tilts by sigma(t), adding -g sin(sigma) to the
  floor acceleration the cart feels but not to floor.csv.

The integrator is this file's own: an adaptive Dormand-Prince 5(4) in numba, one floor sample
interval at a time (the floor linear inside), rejecting steps that overshoot a wall.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

G = 9.80665

# Parameter vector layout.
(A, B, R, D, RHO, MP, MW, IP, IS, IZ, GG, MUSR, MUKR, MUSS, MUKS, BETA, GAMMA, PEXP, EPS, EPSSW,
 DM, DX, DY, BRAKE, MUDRAG, JAM, WAXIS, WSIDE, WPOS, WE, TILT, TILTDIR, TILT0, TILTRAMP,
 WK, WC, JAMMU, BRAKESPIN, BRAKE0, BRAKERAMP, DM0, DMRAMP) = range(42)
NPAR = 42
# A friction jam's regularisation (rad/s): a stiff but finite swivel lock that can slip.
EPS_JAM = 0.01
SIGNS = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])


def params(unit: dict, g: float = G) -> np.ndarray:
    """The parameter vector of a unit given under simulate_rolling's keys."""
    p = np.zeros(NPAR)
    a, b = unit["length_m"] / 2, unit["width_m"] / 2
    r = unit["wheel_diameter_m"] / 2
    mp, mw = unit["platform_mass_kg"], unit["wheel_mass_kg"]
    p[A], p[B], p[R], p[D], p[RHO] = a, b, r, unit["trail_m"], unit["swivel_arm_m"]
    p[MP], p[MW] = mp, mw
    p[IP] = mp * (a * a + b * b) / 3
    p[IS] = 0.5 * mw * r * r
    p[IZ] = mw * (3 * r * r + unit["wheel_width_m"] ** 2) / 12
    p[GG] = g
    p[MUSR], p[MUKR], p[MUSS], p[MUKS] = unit["mu_s_roll"], unit["mu_k_roll"], unit["mu_s_swivel"], unit["mu_k_swivel"]
    p[BETA], p[GAMMA], p[PEXP] = unit["beta_spm"], unit["gamma_n"], unit.get("p", 1.0)
    p[EPS], p[EPSSW] = unit["friction_eps"], unit["friction_eps_swivel"]
    p[BRAKE], p[JAM], p[WAXIS] = -1.0, -1.0, -1.0
    return p


@njit(cache=True)
def _mu(p, ms, mk, v):
    x = p[BETA] * v
    s = 1.0 / math.cosh(x) if x < 700.0 else 0.0
    return ms * s + mk * (1.0 - s) + p[GAMMA] * v ** p[PEXP]


@njit(cache=True)
def _ramp(t, t0, duration):
    """0 before t0, rising linearly to 1 over duration (a step when duration is 0)."""
    if duration <= 0.0:
        return 1.0
    return min(1.0, max(0.0, (t - t0) / duration))


@njit(cache=True)
def _system(y, p, ux, uy, t):
    """Mass matrix M, right-hand side Q (forces minus velocity terms), the jam row (c, c_dot.nu)."""
    a, b, r, d, rho = p[A], p[B], p[R], p[D], p[RHO]
    mw = p[MW]
    th, w = y[2], y[9]
    nu = y[7:10]
    c, s = math.cos(th), math.sin(th)
    M = np.zeros((3, 3))
    Q = np.zeros(3)
    # Platform plate.
    M[0, 0] += p[MP]
    M[1, 1] += p[MP]
    M[2, 2] += p[IP]
    Q[0] -= p[MP] * ux
    Q[1] -= p[MP] * uy
    # Point mass dm at body (DX, DY).
    # A gradual loss (DMRAMP > 0) leaves with its own velocity: no thrust, M(t) only.
    dm = p[DM] * _ramp(t, p[DM0], p[DMRAMP])
    if dm != 0.0:
        qx = c * p[DX] - s * p[DY]
        qy = s * p[DX] + c * p[DY]
        # its velocity: v + w k x q = J_pm nu, J_pm = [[1, 0, -qy], [0, 1, qx]]
        J = np.array([[1.0, 0.0, -qy], [0.0, 1.0, qx]])
        M += dm * (J.T @ J)
        acc_bias = np.array([-w * w * qx, -w * w * qy])   # J_dot nu
        Q += J.T @ (dm * (-np.array([ux, uy]) - acc_bias))
    mtot = p[MP] + dm
    cx = dm * p[DX] / mtot
    cy = dm * p[DY] / mtot
    jam = int(p[JAM])
    brake = int(p[BRAKE])
    crow = np.zeros(3)
    cdot = 0.0
    for i in range(4):
        sx, sy = SIGNS[i, 0], SIGNS[i, 1]
        px, py = sx * a, sy * b
        rx, ry = c * px - s * py, s * px + c * py
        psi = th + y[3 + i]
        ex, ey = math.cos(psi), math.sin(psi)
        nx, ny = -ey, ex
        av = np.array([ex, ey, rx * ey - ry * ex])
        bv = np.array([nx, ny, rx * ny - ry * nx])
        va = av @ nu
        vb = bv @ nu
        psidot = vb / d
        # a_dot.nu and b_dot.nu, from e_dot = psi_dot n, n_dot = -psi_dot e, r_dot = w k x r.
        adot = psidot * vb - w * w * (rx * ex + ry * ey)
        bdot = -psidot * va - w * w * (rx * nx + ry * ny)
        spin = 0.0 if i == brake and p[BRAKESPIN] == 0.0 else p[IS] / (r * r)
        kroll = mw + spin
        kyaw = p[IZ] / (d * d)
        M += kroll * np.outer(av, av) + kyaw * np.outer(bv, bv)
        Q -= kroll * adot * av + kyaw * bdot * bv
        Q -= mw * av * (ex * ux + ey * uy)
        N = (mw + mtot * 0.25 * (1.0 + cx * sx / a + cy * sy / b)) * p[GG]
        if i == brake:
            mud = p[MUDRAG] * _ramp(t, p[BRAKE0], p[BRAKERAMP])
            Q -= mud * N * math.tanh(va / p[EPS]) * av
        else:
            Q -= _mu(p, p[MUSR], p[MUKR], abs(va)) * N * math.tanh(va / p[EPS]) * av
        dd = psidot - w
        kvec = np.array([bv[0] / d, bv[1] / d, bv[2] / d - 1.0])
        if i == jam and p[JAMMU] == 0.0:
            crow = kvec
            cdot = bdot / d
        elif i == jam:
            # A friction jam: the swivel holds against JAMMU N rho unless the torque exceeds it.
            Q -= p[JAMMU] * N * rho * math.tanh(dd / EPS_JAM) * kvec
        else:
            torque = _mu(p, p[MUSS], p[MUKS], rho * abs(dd)) * N * rho * math.tanh(dd / p[EPSSW])
            Q -= torque * kvec
    if p[WAXIS] >= 0.0 and p[WK] > 0.0:
        # A compliant neighbour: a compressive spring-dashpot at every corner past its face.
        for i in range(4):
            px, py = SIGNS[i, 0] * a, SIGNS[i, 1] * b
            rx, ry = c * px - s * py, s * px + c * py
            if p[WAXIS] == 0.0:
                pen = p[WSIDE] * (y[0] + rx - p[WPOS])
                J = np.array([p[WSIDE], 0.0, -p[WSIDE] * ry])
            else:
                pen = p[WSIDE] * (y[1] + ry - p[WPOS])
                J = np.array([0.0, p[WSIDE], p[WSIDE] * rx])
            if pen > 0.0:
                F = p[WK] * pen + p[WC] * (J @ nu)
                if F > 0.0:
                    Q -= F * J
    return M, Q, crow, cdot


@njit(cache=True)
def _accel(y, p, ux, uy, t):
    M, Q, crow, cdot = _system(y, p, ux, uy, t)
    acc = np.linalg.solve(M, Q)
    if p[JAM] >= 0.0 and p[JAMMU] == 0.0:
        mc = np.linalg.solve(M, crow)
        viol = crow @ y[7:10]
        lam = -(crow @ acc + cdot + 20.0 * viol) / (crow @ mc)
        acc = acc + lam * mc
    return acc


@njit(cache=True)
def _tilt(p, t):
    """Slab tilt sigma(t) (rad): a half-cosine ramp from TILT0 over TILTRAMP to TILT."""
    if p[TILT] == 0.0 or t <= p[TILT0]:
        return 0.0
    x = min(1.0, (t - p[TILT0]) / p[TILTRAMP])
    return p[TILT] * 0.5 * (1.0 - math.cos(math.pi * x))


@njit(cache=True)
def _rhs(t, y, p, t0, ax0, ax1, ay0, ay1, dt):
    f = (t - t0) / dt
    ux = ax0 + f * (ax1 - ax0)
    uy = ay0 + f * (ay1 - ay0)
    sig = _tilt(p, t)
    if sig != 0.0:
        ux -= p[GG] * math.sin(sig) * math.cos(p[TILTDIR])
        uy -= p[GG] * math.sin(sig) * math.sin(p[TILTDIR])
    acc = _accel(y, p, ux, uy, t)
    out = np.empty(10)
    out[0:3] = y[7:10]
    th = y[2]
    c, s = math.cos(th), math.sin(th)
    for i in range(4):
        psi = th + y[3 + i]
        nx, ny = -math.sin(psi), math.cos(psi)
        px, py = SIGNS[i, 0] * p[A], SIGNS[i, 1] * p[B]
        rx, ry = c * px - s * py, s * px + c * py
        vb = nx * y[7] + ny * y[8] + (rx * ny - ry * nx) * y[9]
        out[3 + i] = 0.0 if i == int(p[JAM]) and p[JAMMU] == 0.0 else vb / p[D] - y[9]
    out[7:10] = acc
    return out


@njit(cache=True)
def _penetration(y, p):
    """Deepest corner past the wall (m, > 0 inside) and that corner's index."""
    if p[WAXIS] < 0.0 or p[WK] > 0.0:
        return -1.0, -1
    c, s = math.cos(y[2]), math.sin(y[2])
    best, at = -1e30, -1
    for i in range(4):
        px, py = SIGNS[i, 0] * p[A], SIGNS[i, 1] * p[B]
        pos = y[0] + c * px - s * py if p[WAXIS] == 0.0 else y[1] + s * px + c * py
        pen = p[WSIDE] * (pos - p[WPOS])
        if pen > best:
            best, at = pen, i
    return best, at


@njit(cache=True)
def _impact(y, p, corner, t):
    """Newton's law at the corner: its normal speed reverses times e, impulse through M."""
    c, s = math.cos(y[2]), math.sin(y[2])
    px, py = SIGNS[corner, 0] * p[A], SIGNS[corner, 1] * p[B]
    rx, ry = c * px - s * py, s * px + c * py
    J = np.zeros(3)
    if p[WAXIS] == 0.0:
        J[0], J[2] = p[WSIDE], -p[WSIDE] * ry
    else:
        J[1], J[2] = p[WSIDE], p[WSIDE] * rx
    M, _, _, _ = _system(y, p, 0.0, 0.0, t)
    nu = y[7:10].copy()
    vn = J @ nu
    if vn <= 0.0:
        return y, 0.0
    mj = np.linalg.solve(M, J)
    nu = nu - (1.0 + p[WE]) * vn / (J @ mj) * mj
    out = y.copy()
    out[7:10] = nu
    return out, vn


# Dormand-Prince 5(4) tableau.
C2, C3, C4, C5 = 1 / 5, 3 / 10, 4 / 5, 8 / 9
A21 = 1 / 5
A31, A32 = 3 / 40, 9 / 40
A41, A42, A43 = 44 / 45, -56 / 15, 32 / 9
A51, A52, A53, A54 = 19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729
A61, A62, A63, A64, A65 = 9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656
B1, B3, B4, B5, B6 = 35 / 384, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84
E1, E3, E4, E5, E6, E7 = 71 / 57600, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40


@njit(cache=True)
def _interval(y, p, t0, t1, ax0, ax1, ay0, ay1, dt, h, rtol, atol, stats):
    """Integrates from t0 to t1 (inside one floor sample interval); returns y, the next step."""
    t = t0
    impacts = 0
    while t < t1 - 1e-15:
        h = min(h, t1 - t)
        k1 = _rhs(t, y, p, t0, ax0, ax1, ay0, ay1, dt)
        k2 = _rhs(t + C2 * h, y + h * A21 * k1, p, t0, ax0, ax1, ay0, ay1, dt)
        k3 = _rhs(t + C3 * h, y + h * (A31 * k1 + A32 * k2), p, t0, ax0, ax1, ay0, ay1, dt)
        k4 = _rhs(t + C4 * h, y + h * (A41 * k1 + A42 * k2 + A43 * k3), p, t0, ax0, ax1, ay0, ay1, dt)
        k5 = _rhs(t + C5 * h, y + h * (A51 * k1 + A52 * k2 + A53 * k3 + A54 * k4), p, t0, ax0, ax1, ay0, ay1, dt)
        k6 = _rhs(t + h, y + h * (A61 * k1 + A62 * k2 + A63 * k3 + A64 * k4 + A65 * k5), p, t0, ax0, ax1, ay0, ay1, dt)
        y5 = y + h * (B1 * k1 + B3 * k3 + B4 * k4 + B5 * k5 + B6 * k6)
        k7 = _rhs(t + h, y5, p, t0, ax0, ax1, ay0, ay1, dt)
        err_v = h * (E1 * k1 + E3 * k3 + E4 * k4 + E5 * k5 + E6 * k6 + E7 * k7)
        stats[0] += 7
        err = 0.0
        for i in range(10):
            sc = atol[i] + rtol * max(abs(y[i]), abs(y5[i]))
            err += (err_v[i] / sc) ** 2
        err = math.sqrt(err / 10.0)
        if err <= 1.0:
            pen, corner = _penetration(y5, p)
            if pen > 1e-7 and h > 1e-9:
                h *= 0.5          # overshot the wall: locate the contact by halving
                continue
            t += h
            y = y5
            if pen > -1e-9 and corner >= 0:
                y, vn = _impact(y, p, corner, t)
                if vn > 0.0:
                    impacts += 1
                    stats[1] += 1
                    if impacts > 200:
                        stats[2] = 1.0      # chattering contact: the caller rejects the case
                        return y, h
            fac = 0.9 * err ** -0.2 if err > 0 else 5.0
            h = h * min(5.0, max(0.2, fac))
        else:
            h = h * max(0.1, 0.9 * err ** -0.25)
            if h < 1e-12:
                stats[2] = 2.0
                return y, h
    return y, h


@njit(cache=True)
def _run(y0, p, p_after, t_change, change_kind, ax, ay, dt, rtol, atol, out, stats):
    """Samples k = 0..n-1: x, y, yaw, ax_abs, delta1..4 into out[k]; the alteration p_after
    replaces p at t_change (change_kind 1: mass gain, momentum shared; 2: jam, projected)."""
    n = len(ax)
    y = y0.copy()
    h = dt / 4
    cur = p
    changed = t_change < 0.0
    if changed:
        cur = p_after
    for k in range(n):
        t = k * dt
        if k > 0:
            a0x, a1x, a0y, a1y = ax[k - 1], ax[k], ay[k - 1], ay[k]
            tp = (k - 1) * dt
            if not changed and t_change <= t:
                y, h = _interval(y, cur, tp, t_change, a0x, a1x, a0y, a1y, dt, h, rtol, atol, stats)
                if change_kind == 1:
                    Mb, _, _, _ = _system(y, cur, 0.0, 0.0, t_change)
                    Ma, _, _, _ = _system(y, p_after, 0.0, 0.0, t_change)
                    y[7:10] = np.linalg.solve(Ma, Mb @ y[7:10])
                cur = p_after
                changed = True
                if change_kind == 2:
                    Ma, _, crow, _ = _system(y, cur, 0.0, 0.0, t_change)
                    mc = np.linalg.solve(Ma, crow)
                    y[7:10] = y[7:10] - (crow @ y[7:10]) / (crow @ mc) * mc
                if t_change < t:
                    y, h = _interval(y, cur, t_change, t, a0x, a1x, a0y, a1y, dt, h, rtol, atol, stats)
            else:
                y, h = _interval(y, cur, tp, t, a0x, a1x, a0y, a1y, dt, h, rtol, atol, stats)
            if stats[2] != 0.0:
                return
        d = _rhs(t, y, cur, t, ax[k], ax[k], ay[k], ay[k], dt)
        out[k, 0], out[k, 1], out[k, 2] = y[0], y[1], y[2]
        # The accelerometer reads the floor record plus the acceleration relative to the floor.
        out[k, 3] = ax[k] + d[7]
        out[k, 4:8] = y[3:7]


def simulate(unit: dict, ax: np.ndarray, ay: np.ndarray, dt: float, alteration: dict | None = None,
             yaw0_perturbation: float = 0.0, rtol: float = 1e-9, tilt: dict | None = None):
    """Returns (out[n, 8]: x, y, yaw, ax_abs, delta1..4; stats dict). `alteration` is
    {kind, t0_s, ...} for mass_change (dm_kg, dx_m, dy_m; ramp_s > 0: a loss spread over that
    time), caster_brake (wheel 0..3, mu_drag; spinning: the wheel keeps its spin inertia, a brake
    pad drags; ramp_s: the drag builds up over that time), swivel_jam (caster 0..3; mu_jam > 0: a
    friction lock mu_jam N rho that can slip instead of a rigid constraint), lateral_impact (axis,
    side, position_m, e, from t = 0; stiffness_npm > 0: a compliant neighbour, a spring-dashpot
    with damping_nspm, e then unused)."""
    p = params(unit)
    if tilt:
        p[TILT], p[TILTDIR], p[TILT0], p[TILTRAMP] = tilt["sigma_max_rad"], tilt["direction_rad"], tilt["t0_s"], tilt["ramp_s"]
    q = p.copy()
    t_change, kind = 1e30, 0
    if alteration:
        eff = alteration["effect"]
        t_change = alteration.get("t0_s", -1.0)
        if eff == "mass_change":
            q[DM], q[DX], q[DY] = alteration["dm_kg"], alteration["dx_m"], alteration["dy_m"]
            q[DM0], q[DMRAMP] = t_change, alteration.get("ramp_s", 0.0)
            if q[DMRAMP] > 0.0 and q[DM] > 0.0:
                raise ValueError("a gradual mass change is a loss (a gain is captured at once)")
            kind = 1 if alteration["dm_kg"] > 0 else 0
        elif eff == "caster_brake":
            q[BRAKE], q[MUDRAG] = alteration["wheel"], alteration["mu_drag"]
            q[BRAKESPIN] = 1.0 if alteration.get("spinning", False) else 0.0
            q[BRAKE0], q[BRAKERAMP] = t_change, alteration.get("ramp_s", 0.0)
        elif eff == "swivel_jam":
            q[JAM] = alteration["caster"]
            q[JAMMU] = alteration.get("mu_jam", 0.0)
            kind = 2 if q[JAMMU] == 0.0 else 0
        elif eff == "lateral_impact":
            q[WAXIS], q[WSIDE], q[WPOS], q[WE] = alteration["axis"], alteration["side"], alteration["position_m"], alteration["e"]
            if alteration.get("stiffness_npm", 0.0) > 0.0:
                q[WK], q[WC] = alteration["stiffness_npm"], alteration["damping_nspm"]
            t_change = -1.0
    y0 = np.zeros(10)
    y0[2] = math.radians(unit["yaw0_deg"]) + yaw0_perturbation
    y0[3:7] = np.radians(unit["steer0_deg"])
    atol = np.array([1e-10] * 7 + [1e-9] * 3)
    out = np.full((len(ax), 8), np.nan)
    stats = np.zeros(3)
    _run(y0, p, q, float(t_change), kind, np.ascontiguousarray(ax, float), np.ascontiguousarray(ay, float),
         dt, rtol, atol, out, stats)
    return out, {"nfev": int(stats[0]), "impacts": int(stats[1]), "failed": int(stats[2])}
