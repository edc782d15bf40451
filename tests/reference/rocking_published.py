"""An independent peer (scipy solve_ivp with located events) of shakeflow's rocking model for the
study's two published validations (SEED-SUMMARY.md; the seed paper's Figs. 13 and 14), written
from the equations in docs/models/toppling.md, not from the Rust code:

- Fig. 14 (after Makris & Zhang 2001): a free-standing block B = 2 m, H = 6 m (full width and
  height, as the paper's Eq. 21 uses them) under Rinaldi 228, scaled: the first scale at which it
  overturns, and to which side.
- Fig. 13 (after Vassiliou & Makris 2012): a block B = 1.52 m, H = 10.33 m on a rigid base and on
  a seismically isolated base (T_b = 3 s, xi = 0.1) modelled as a COUPLED system: the base of mass
  m_b (ratio gamma = m_b/m) carries the block's horizontal reaction, and impacts conserve the
  system's horizontal momentum and the block's angular momentum about the new pivot. The Jensen
  Filter Plant record is not in ../shared/data, so the closest near-fault pulse records there are
  used: Rinaldi 228 and Sylmar Converter Station 052 (both 1994 Northridge, like Jensen).

Equations (theta > 0: rocking on the +x corner, top toward +x; phi = s*alpha - theta on side s;
u the base's displacement relative to the ground, x_b'' = u'' + a_g its absolute acceleration;
mu = m/(m + m_b); omega_b = 2 pi/T_b and xi refer to the total mass m + m_b):
  block:  theta'' = -(R/i0) (g sin phi + x_b'' cos phi)                      (i0 = I0/m)
  base:   x_b'' + mu R (cos phi theta'' + sin phi theta'^2) = -omega_b^2 u - 2 xi omega_b u'
  at rest on the base: theta = 0 and x_b'' = -omega_b^2 u - 2 xi omega_b u'; uplift toward s when
  -s x_b'' > g tan(alpha).
  impact at theta = 0: theta'_2 = e theta'_1, e = 1 - 2 b^2/(i0 - mu h_c^2) (Eq. 24 when mu = 0),
  u'_2 = u'_1 - mu h_c (theta'_2 - theta'_1); a rebound that would rock the block less than 1e-7
  rad ends in rest (theta'_2 = 0, momentum still conserved).
A rigid base is x_b'' = a_g (gamma = infinity with omega_b -> infinity); gamma = infinity with a
finite T_b is the decoupled (prescribed-SDOF) limit.

    rocking_published.py > rocking_published.json     (about 10 minutes)
"""
import json
import math
import re
import sys
import time

import numpy as np
from scipy.integrate import solve_ivp

G = 9.80665
REST_AMPLITUDE = 1e-7
DATA = "../shared/data/ground_motions/"


def read_at2(path):
    """dt and acceleration (m/s^2) of a PEER AT2 file (NGA-West1/West2 and 2000-era headers)."""
    lines = open(path).read().splitlines()
    for i, line in enumerate(lines[:6]):
        m = re.search(r"NPTS\s*=\s*(\d+)\s*,\s*DT\s*=\s*([0-9.Ee+-]+)", line)
        if m:
            npts, dt = int(m.group(1)), float(m.group(2))
            break
        m = re.match(r"\s*(\d+)\s+([0-9.Ee+-]+)\s+NPTS", line)
        if m:
            npts, dt = int(m.group(1)), float(m.group(2))
            break
    values = np.array([float(v) for line in lines[i + 1:] for v in line.split()])
    assert len(values) == npts, (path, len(values), npts)
    return dt, values * G


class Block:
    def __init__(self, B, H):
        self.b, self.hc = 0.5 * B, 0.5 * H
        self.R = math.hypot(self.b, self.hc)
        self.alpha = math.atan2(self.b, self.hc)
        self.i0 = (B * B + H * H) / 12.0 + self.R ** 2
        self.p = math.sqrt(G * self.R / self.i0)


def simulate(block, dt, ag, base=None, rtol=1e-10):
    """First overturn (time, side) or None, and the events. base: None (rigid) or
    (T_b, xi, gamma) with gamma = m_b/m (math.inf: prescribed base motion)."""
    n = len(ag)
    t_end = (n - 1) * dt
    rigid = base is None
    if not rigid:
        tb, xi, gamma = base
        w = 2 * math.pi / tb
        mu = 0.0 if math.isinf(gamma) else 1.0 / (1.0 + gamma)
    else:
        w = xi = mu = 0.0
    k_r = block.R / block.i0
    tan_a = math.tan(block.alpha)
    e = 1.0 - 2 * block.b ** 2 / (block.i0 - mu * block.hc ** 2)

    def ground(t):
        x = t / dt
        k = min(int(x), n - 2)
        f = x - k
        return ag[k] + f * (ag[k + 1] - ag[k])

    def base_rest(t, y):
        return ground(t) if rigid else -w * w * y[2] - 2 * xi * w * y[3]

    def rocking_acc(t, y, s):
        phi = s * block.alpha - y[0]
        sp, cp = math.sin(phi), math.cos(phi)
        if rigid:
            xb = ground(t)
            return -k_r * (G * sp + xb * cp), xb
        a = -w * w * y[2] - 2 * xi * w * y[3] - mu * block.R * sp * y[1] ** 2
        bb = -k_r * G * sp
        c = mu * block.R * cp
        d = k_r * cp
        det = 1.0 - c * d
        xb = (a - c * bb) / det
        return bb - d * xb, xb

    events = []
    t = 0.0
    y = np.zeros(4)
    state, side = "rest", 0
    max_step = dt
    while t < t_end - 1e-12:
        if state == "rest":
            def rhs(tt, yy):
                xb = base_rest(tt, yy)
                return [0.0, 0.0, yy[3], xb - ground(tt)]

            def up(s):
                def ev(tt, yy):
                    return -s * base_rest(tt, yy) - G * tan_a
                ev.terminal, ev.direction = True, 1
                return ev
            evs = [up(1), up(-1)]
            # Already above the threshold (uplift at once).
            now = [ev(t, y) for ev in evs]
            if max(now) > 0:
                side = 1 if now[0] > 0 else -1
                state = "rocking"
                events.append(("uplift", t, side))
                continue
            sol = solve_ivp(rhs, (t, t_end), y, method="DOP853", rtol=rtol, atol=1e-12, events=evs,
                            max_step=max_step)
            if sol.status != 1:
                break
            hit = 0 if len(sol.t_events[0]) else 1
            t = sol.t_events[hit][0]
            y = sol.y_events[hit][0].copy()
            y[0] = y[1] = 0.0
            side = 1 if hit == 0 else -1
            state = "rocking"
            events.append(("uplift", t, side))
            continue
        s = side

        def rhs(tt, yy):
            th2, xb = rocking_acc(tt, yy, s)
            return [yy[1], th2, yy[3], xb - ground(tt)]

        def impact(tt, yy):
            return s * yy[0]
        impact.terminal, impact.direction = True, -1

        def overturn(tt, yy):
            return math.pi / 2 - s * yy[0]
        overturn.terminal, overturn.direction = True, -1
        sol = solve_ivp(rhs, (t, t_end), y, method="DOP853", rtol=rtol, atol=1e-12,
                        events=(impact, overturn), max_step=max_step)
        if sol.status != 1:
            break
        if len(sol.t_events[1]):
            t = sol.t_events[1][0]
            events.append(("overturn", t, s))
            return (t, s), events
        t = sol.t_events[0][0]
        y = sol.y_events[0][0].copy()
        w1 = y[1]
        w2 = e * w1
        if w2 * w2 < 2 * block.p ** 2 * math.sin(block.alpha) * REST_AMPLITUDE:
            w2 = 0.0
            state = "rest"
            events.append(("rest", t, 0))
        else:
            side = -s
            events.append(("impact", t, side))
        y[3] -= mu * block.hc * (w2 - w1)
        y[0], y[1] = 0.0, w2
    return None, events


def first_overturn(block, dt, ag, scales, base=None):
    """The first scale of `scales` at which the block overturns, with side and time."""
    for scale in scales:
        o, _ = simulate(block, dt, ag * scale, base)
        if o is not None:
            return {"scale": round(scale, 4), "time_s": o[0], "side": o[1]}
    return None


def main():
    started = time.time()
    out = {"source": "tests/reference/rocking_published.py", "g_mps2": G}
    fig14 = Block(2.0, 6.0)
    dt, ag = read_at2(DATA + "Rinaldi228.AT2")
    scales = [1.0 + 0.01 * i for i in range(0, 61)]
    out["fig14_free_B2_H6"] = {
        "alpha": fig14.alpha, "p": fig14.p, "e": 1 - 2 * fig14.b ** 2 / fig14.i0,
        "first_overturn": first_overturn(fig14, dt, ag, scales),
    }
    fig13 = Block(1.52, 10.33)
    coarse = [0.1 * i for i in range(1, 41)]
    rows = {}
    for name in ["Rinaldi228.AT2", "RSN1084_NORTHR_SCS052.AT2"]:
        dt, ag = read_at2(DATA + name)
        row = {}
        for label, base in [("rigid", None), ("isolated_decoupled", (3.0, 0.1, math.inf)),
                            ("isolated_gamma_1", (3.0, 0.1, 1.0)), ("isolated_gamma_10", (3.0, 0.1, 10.0))]:
            first = first_overturn(fig13, dt, ag, coarse, base)
            if first is not None:
                lo = first["scale"] - 0.1
                fine = [lo + 0.01 * i for i in range(1, 11)]
                first = first_overturn(fig13, dt, ag, fine, base)
            o, ev = simulate(fig13, dt, ag, base)
            row[label] = {"unscaled_overturn": None if o is None else {"time_s": o[0], "side": o[1]},
                          "unscaled_events": len(ev), "first_overturn_scale_0.01": first}
            print(name, label, row[label], file=sys.stderr, flush=True)
        rows[name] = row
    out["fig13_B1.52_H10.33_Tb3_xi0.1"] = {"alpha": fig13.alpha, "p": fig13.p, "records": rows}
    out["seconds"] = time.time() - started
    json.dump(out, sys.stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
