#!/usr/bin/env python3
"""Independent peer of shakeflow's sliding-rocking block (src/physics/rocking/sliding.rs).

    python tests/reference/sliding_scipy.py [OUT.json]   (default: sliding_scipy.json beside it)

Written from the physics, not from the Rust code: at every instant the contact forces F (horizontal)
and N (normal) and the accelerations come from Newton-Euler in absolute coordinates, solved as one
linear system with numpy (the Rust model uses the reduced pivot-moment form):

    m (a_g + u'' + x_c'') = F              x_c, z_c: centre of mass relative to the pivot
    m (a_v + z_c'')       = N - m g        (x_c, z_c) = (-s b cos th + hc sin th, s b sin th + hc cos th)
    I_cm th''             = -F z_c + N x_c (the contact's moment about the centre of mass)

plus the regime's constraint: stick/rock u'' = 0; slide/slide-rock F = -sigma mu_k N. Regimes:
stick (th = u' = 0) until |a_g| > mu_s (g + a_v) (slide) or -s a_g > (g + a_v) tan(alpha) (rock on
side s); slide until u' = 0; rock until th = 0 (impact: th' -> e th', rest when the rebound would
rock less than 1e-7 rad), |F| > mu_s N (slide-rock) or overturn; slide-rock until u' = 0 (rock)
or th = 0 (impact, slip velocity kept). scipy's solve_ivp (DOP853, rtol 1e-11) with terminal
events; the floor is linear between samples. The floors are formulas the Rust test rebuilds.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

G = 9.80665
DT = 0.005
REST_AMPLITUDE = 1e-7


def floor(name: str, n: int) -> np.ndarray:
    t = np.arange(n) * DT
    if name == "harmonic":
        return 0.5 * G * np.sin(2 * np.pi * t)
    if name == "decaying":
        return -3.5 * np.sin(4.0 * t) * np.exp(-0.3 * t)
    if name == "two_tones":
        return (2.8 * np.sin(2 * np.pi * 1.3 * t) + 1.2 * np.sin(2 * np.pi * 3.1 * t + 0.4)) * np.minimum(1.0, t / 2.0)
    raise ValueError(name)


CASES = [
    # name, B, H, f, floor, samples, mu_s, mu_k
    ("stocky_harmonic", 1.0, 1.0, 0.0, "harmonic", 801, 0.35, 0.30),
    ("slender_slide_rock", 0.4, 1.6, 0.0, "decaying", 1201, 0.30, 0.27),
    ("ps2_two_tones", 0.349, 1.082, 0.085, "two_tones", 1601, 0.29, 0.29),
]


class Block:
    def __init__(self, B, H, f):
        self.b, self.H = 0.5 * B, H
        self.hc = H * (0.5 + f)
        self.icm = (B * B + H * H) / 12.0          # per unit mass
        self.alpha = math.atan2(self.b, self.hc)
        R = math.hypot(self.b, self.hc)
        self.i0 = self.icm + R * R
        self.p = math.sqrt(G * R / self.i0)
        self.e = 1.0 - R * 2 * self.b / self.i0 * math.sin(self.alpha)

    def cm(self, s, th):
        """Centre of mass relative to the pivot on side s, and its derivatives' factors."""
        x = -s * self.b * math.cos(th) + self.hc * math.sin(th)
        z = s * self.b * math.sin(th) + self.hc * math.cos(th)
        return x, z

    def solve(self, s, th, w, ag, av, constraint, sigma=0.0, mu_k=0.0):
        """[th'', u'', F/m, N/m] from Newton-Euler; constraint 'stick' (u'' = 0) or 'slip'."""
        x, z = self.cm(s, th)
        # x_c'' = dx/dth th'' + d2x/dth2 w^2 with dx/dth = z, dz/dth = -x.
        # Rows: horizontal, vertical, moment, constraint. Unknowns: th'', u'', F, N.
        A = np.array([
            [z, 1.0, -1.0, 0.0],
            [-x, 0.0, 0.0, -1.0],
            [self.icm, 0.0, z, -x],
            [0.0, 1.0, 0.0, 0.0] if constraint == "stick" else [0.0, 0.0, 1.0, sigma * mu_k],
        ])
        rhs = np.array([-ag + x * w * w, -av - G + z * w * w, 0.0, 0.0])
        return np.linalg.solve(A, rhs)


def simulate(blk: Block, ax: np.ndarray, mu_s: float, mu_k: float):
    n = len(ax)
    t_end = (n - 1) * DT
    tgrid = np.arange(n) * DT

    def at(t):
        k = min(int(t / DT), n - 2)
        return ax[k] + (t / DT - k) * (ax[k + 1] - ax[k])

    theta, slip = np.zeros(n), np.zeros(n)
    events = []
    rest_speed2 = 2 * blk.p ** 2 * math.sin(blk.alpha) * REST_AMPLITUDE
    t, y, regime, side, sigma = 0.0, np.zeros(4), "stick", 0, 0
    written = 1

    def write(ts, ys):
        nonlocal written
        for tt, yy in zip(ts, ys.T):
            k = int(round(tt / DT))
            if k >= written and abs(tt - k * DT) < 1e-12:
                theta[k], slip[k] = yy[0], yy[2]
                written = k + 1

    while t < t_end - 1e-12:
        if regime == "stick":
            def margins(tt, yy):
                a = at(tt)
                return [G * math.tan(blk.alpha) + a, G * math.tan(blk.alpha) - a, mu_s * G - a, mu_s * G + a]
            m0 = margins(t, y)
            if min(m0) < 0:
                i = int(np.argmin(m0))
                te = t
            else:
                evs = []
                for i in range(4):
                    ev = (lambda i: lambda tt, yy: margins(tt, yy)[i])(i)
                    ev.terminal, ev.direction = True, -1
                    evs.append(ev)
                i, te = integrate(lambda tt, yy: [0.0, 0.0, 0.0, 0.0], t, t_end, y, evs, tgrid, write)
                if i is None:
                    break
            y = np.array([0.0, 0.0, y[2], 0.0])
            t = te
            if i < 2:
                side = 1 if i == 0 else -1
                regime = "rock"
                events.append(("uplift", te, side))
            else:
                sigma = -1 if i == 2 else 1
                regime = "slide"
                events.append(("slide_start", te, sigma))
        elif regime == "slide":
            def rhs(tt, yy):
                return [0.0, 0.0, yy[3], -at(tt) - sigma * mu_k * G]
            ev = lambda tt, yy: sigma * yy[3]   # noqa: E731
            ev.terminal, ev.direction = True, -1
            i, te = integrate(rhs, t, t_end, y, [ev], tgrid, write, start_on_boundary=True)
            if i is None:
                break
            y = np.array([0.0, 0.0, last_y[2], 0.0])
            t = te
            regime = "stick"
            events.append(("stick", te, 0))
        elif regime == "rock":
            s = side

            def rhs(tt, yy):
                th_dd = blk.solve(s, yy[0], yy[1], at(tt), 0.0, "stick")[0]
                return [yy[1], th_dd, 0.0, 0.0]

            def grip(tt, yy, j):
                _, _, F, N = blk.solve(s, yy[0], yy[1], at(tt), 0.0, "stick")
                return mu_s * N - F if j == 0 else mu_s * N + F

            g0 = [grip(t, y, 0), grip(t, y, 1)]
            if min(g0) < 0:
                sigma = -1 if g0[0] < g0[1] else 1
                regime = "slide_rock"
                events.append(("slide_start", t, sigma))
                continue
            ev_imp = lambda tt, yy: s * yy[0]   # noqa: E731
            ev_over = lambda tt, yy: math.pi / 2 - s * yy[0]   # noqa: E731
            ev_g0 = lambda tt, yy: grip(tt, yy, 0)   # noqa: E731
            ev_g1 = lambda tt, yy: grip(tt, yy, 1)   # noqa: E731
            evs = [ev_imp, ev_over, ev_g0, ev_g1]
            for ev in evs:
                ev.terminal, ev.direction = True, -1
            i, te = integrate(rhs, t, t_end, y, evs, tgrid, write, start_on_boundary=y[0] == 0.0)
            if i is None:
                break
            ye = last_y.copy()
            t = te
            if i == 0:
                after = blk.e * ye[1]
                if after * after < rest_speed2:
                    y, regime = np.array([0.0, 0.0, ye[2], 0.0]), "stick"
                    events.append(("rest", te, 0))
                else:
                    y, side = np.array([0.0, after, ye[2], 0.0]), -s
                    events.append(("impact", te, -s))
            elif i == 1:
                events.append(("overturn", te, s))
                theta[written:] = s * math.pi / 2
                slip[written:] = ye[2]
                return theta, slip, events
            else:
                sigma = -1 if i == 2 else 1
                y, regime = ye, "slide_rock"
                events.append(("slide_start", te, sigma))
        else:   # slide_rock
            s, sg = side, sigma

            def rhs(tt, yy):
                th_dd, u_dd, _, _ = blk.solve(s, yy[0], yy[1], at(tt), 0.0, "slip", sg, mu_k)
                return [yy[1], th_dd, yy[3], u_dd]

            ev_imp = lambda tt, yy: s * yy[0]   # noqa: E731
            ev_over = lambda tt, yy: math.pi / 2 - s * yy[0]   # noqa: E731
            ev_stop = lambda tt, yy: sg * yy[3]   # noqa: E731
            evs = [ev_imp, ev_over, ev_stop]
            for ev in evs:
                ev.terminal, ev.direction = True, -1
            i, te = integrate(rhs, t, t_end, y, evs, tgrid, write, start_on_boundary=True)
            if i is None:
                break
            ye = last_y.copy()
            t = te
            if i == 0:
                after = blk.e * ye[1]
                if after * after < rest_speed2:
                    y, regime = np.array([0.0, 0.0, ye[2], ye[3]]), "slide"
                    events.append(("rest", te, 0))
                else:
                    y, side = np.array([0.0, after, ye[2], ye[3]]), -s
                    events.append(("impact", te, -s))
            elif i == 1:
                events.append(("overturn", te, s))
                theta[written:] = s * math.pi / 2
                slip[written:] = ye[2]
                return theta, slip, events
            else:
                y, regime = np.array([ye[0], ye[1], ye[2], 0.0]), "rock"
                events.append(("stick", te, 0))
    return theta, slip, events


last_y = np.zeros(4)


def integrate(rhs, t0, t_end, y0, events, tgrid, write, start_on_boundary=False):
    """solve_ivp from t0 with terminal events, sample to sample (the floor has kinks at samples).
    Returns (event index, time) or (None, t_end); the state at the event is in `last_y`."""
    global last_y
    t, y = t0, np.asarray(y0, float)
    while t < t_end - 1e-13:
        k = int(math.floor(t / DT + 1e-9))
        t1 = min((k + 1) * DT, t_end)
        if t1 <= t + 1e-13:
            t1 = min((k + 2) * DT, t_end)
        sol = solve_ivp(rhs, (t, t1), y, method="DOP853", rtol=1e-11, atol=1e-13, events=events, dense_output=True)
        hits = [(te[0], i) for i, te in enumerate(sol.t_events) if len(te) and
                not (start_on_boundary and te[0] - t0 < 1e-10)]
        if hits:
            te, i = min(hits)
            inside = tgrid[(tgrid > t) & (tgrid < te)]
            if len(inside):
                write(inside, sol.sol(inside))
            last_y = sol.sol(te)
            return i, te
        write(np.array([t1]), sol.y[:, -1:])
        t, y = t1, sol.y[:, -1]
        start_on_boundary = False
    last_y = y
    return None, t_end


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_name("sliding_scipy.json")
    results = {"generator": "tests/reference/sliding_scipy.py", "g_mps2": G, "dt_s": DT, "every": 4, "cases": []}
    for name, B, H, f, floor_name, n, mu_s, mu_k in CASES:
        blk = Block(B, H, f)
        theta, slip, events = simulate(blk, floor(floor_name, n), mu_s, mu_k)
        results["cases"].append({
            "name": name, "B_m": B, "H_m": H, "f": f, "floor": floor_name, "samples": n,
            "static_mu": mu_s, "kinetic_mu": mu_k,
            "events": [{"kind": k, "time_s": te, "side": s} for k, te, s in events],
            "theta_rad": theta[::4].tolist(), "slip_m": slip[::4].tolist(),
        })
        kinds = {}
        for k, _, _ in events:
            kinds[k] = kinds.get(k, 0) + 1
        print(f"{name}: {kinds}, max|theta| {np.abs(theta).max():.4f} rad, final slip {slip[-1] * 1e3:.2f} mm")
    out.write_text(json.dumps(results, indent=1) + "\n")
    print(f"-> {out}")


if __name__ == "__main__":
    main()
