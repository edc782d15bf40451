"""An independent rocking-block simulator on scipy's solve_ivp, the peer of shakeflow's
src/physics/rocking.rs (same equations: SEED-SUMMARY.md Eqs. 20-24), for tests and benchmarks.

Rest → uplift when the floor (linear between samples) crosses g·tan(α)·(1 + a_v/g); rocking by
Eq. 22 with solve_ivp and terminal events at θ = 0 (impact, e of Eq. 24) and at the lying angle
(overturn); an impact whose rebound would rock the block less than 1e-7 rad ends in rest.

    rocking_scipy.py floor.csv --B 0.349 --H 1.082 --f 0.085 [--rtol 1e-10] [--method DOP853]
    rocking_scipy.py --pulse-table --B 0.9101373 --H 3.5643866 --f 0 --ratios 1,2,4 > rocking_pulses.json

floor.csv: columns time_s, ax_mps2 and optionally az_mps2 (by name), at a constant step. Prints JSON: theta on the input time
base, the events, and the wall time of the simulation alone.
"""
import argparse
import json
import math
import sys
import time

import numpy as np
from scipy.integrate import solve_ivp

REST_AMPLITUDE = 1e-7


class Block:
    def __init__(self, B, H, f, g=9.81):
        self.b = 0.5 * B
        self.hc = H * (0.5 + f)
        self.g = g
        self.R = math.hypot(self.b, self.hc)
        self.alpha = math.atan2(self.b, self.hc)
        i0_per_kg = (B * B + H * H) / 12.0 + self.R ** 2
        self.k = self.R / i0_per_kg            # m R / I0
        self.p = math.sqrt(g * self.k)
        self.e = 1.0 - self.R * B / i0_per_kg * math.sin(self.alpha)
        self.lie = math.pi / 2


def simulate(block, t, ax, az, rtol=1e-10, method="DOP853"):
    n = len(t)
    dt = (t[-1] - t[0]) / (n - 1)
    theta = np.zeros(n)
    events = []
    tan_a = math.tan(block.alpha)
    state = "rest"
    k = 0                      # current sample interval [t[k], t[k+1]]
    tc, y = t[0], np.zeros(2)  # current time and state
    side = 0

    def floor(time):
        return np.interp(time, t, ax), np.interp(time, t, az)

    while k < n - 1:
        if state == "overturned":
            theta[k + 1:] = side * block.lie
            break
        if state == "rest":
            # Uplift toward side s when -s*ax - (g + az) tan(a) > 0, linear within the interval.
            found = None
            for s in (1, -1):
                ax0, az0 = floor(tc)
                p0 = -s * ax0 - (block.g + az0) * tan_a
                p1 = -s * ax[k + 1] - (block.g + az[k + 1]) * tan_a
                if p0 > 0:
                    tu = tc
                elif p1 > 0:
                    tu = tc + p0 / (p0 - p1) * (t[k + 1] - tc)
                else:
                    continue
                if found is None or tu < found[0]:
                    found = (tu, s)
            if found is None:
                k += 1
                tc = t[k]
                continue
            tc, side = found
            y = np.zeros(2)
            state = "rocking"
            events.append(("uplift", tc, side))
            continue
        # Rocking on `side` from tc until an impact, an overturn or the end of the record.
        s = side

        def rhs(time, state_):
            a_x, a_z = np.interp(time, t, ax), np.interp(time, t, az)
            phi = s * block.alpha - state_[0]
            return [state_[1], -block.k * ((block.g + a_z) * math.sin(phi) + a_x * math.cos(phi))]

        def impact(time, state_):
            return s * state_[0]
        impact.terminal, impact.direction = True, -1

        def overturn(time, state_):
            return block.lie - s * state_[0]
        overturn.terminal, overturn.direction = True, -1

        first = np.searchsorted(t, tc, side="right")
        t_eval = t[first:]
        sol = solve_ivp(rhs, (tc, t[-1]), y, method=method, rtol=rtol, atol=rtol * 1e-2,
                        t_eval=t_eval, events=(impact, overturn), max_step=dt)
        m = len(sol.t)
        if m:
            theta[first:first + m] = sol.y[0]
        if sol.status != 1:
            break
        if len(sol.t_events[1]):
            tc = sol.t_events[1][0]
            events.append(("overturn", tc, s))
            state = "overturned"
            k = np.searchsorted(t, tc, side="right") - 1
            continue
        tc = sol.t_events[0][0]
        w = block.e * sol.y_events[0][0][1]
        k = np.searchsorted(t, tc, side="right") - 1
        if w * w < 2 * block.p ** 2 * math.sin(block.alpha) * REST_AMPLITUDE:
            events.append(("rest", tc, 0))
            state, y = "rest", np.zeros(2)
        else:
            side = -s
            y = np.array([0.0, w])
            events.append(("impact", tc, side))
    return theta, events


def one_sine(block, ratio, amplitude_ratio, dt=1e-3, tail=None):
    """Zhang & Makris (2001) one-sine pulse: a_p sin(ω_p t + ψ) for one period, ψ so it starts
    at the uplift threshold; then the block is followed in free rocking."""
    omega = ratio * block.p
    a_p = amplitude_ratio * block.g * math.tan(block.alpha)
    psi = math.asin(block.g * math.tan(block.alpha) / a_p)
    duration = 2 * math.pi / omega + (tail if tail is not None else 6 * 2 * math.pi / block.p)
    t = np.arange(0.0, duration, dt)
    ax = np.where(t <= 2 * math.pi / omega, -a_p * np.sin(omega * t + psi), 0.0)
    return t, ax


def minimum_overturning(block, ratio, lo=1.0, hi=20.0, step=0.05):
    def overturns(x):
        t, ax = one_sine(block, ratio, x)
        _, events = simulate(block, t, ax, np.zeros_like(ax), rtol=1e-10)
        return any(e[0] == "overturn" for e in events)
    x = lo + step
    while x <= hi and not overturns(x):
        x += step
    a, b = x - step, x
    while b - a > 1e-3:
        mid = 0.5 * (a + b)
        a, b = (a, mid) if overturns(mid) else (mid, b)
    return b


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("floor", nargs="?")
    ap.add_argument("--B", type=float, default=0.349)
    ap.add_argument("--H", type=float, default=1.082)
    ap.add_argument("--f", type=float, default=0.085)
    ap.add_argument("--rtol", type=float, default=1e-10)
    ap.add_argument("--method", default="DOP853")
    ap.add_argument("--pulse-table", action="store_true")
    ap.add_argument("--ratios", default="1,2,4")
    args = ap.parse_args()
    block = Block(args.B, args.H, args.f)
    if args.pulse_table:
        table = {r: minimum_overturning(block, float(r)) for r in args.ratios.split(",")}
        # The whole command line, so that the file says how to make it again.
        json.dump({"source": " ".join(["tests/reference/rocking_scipy.py", *sys.argv[1:]]), "B": args.B, "H": args.H, "f": args.f,
                   "alpha": block.alpha, "p": block.p, "pulse_dt_s": 1e-3,
                   "minimum_ap_over_g_tan_alpha": table}, sys.stdout, indent=1)
        print()
        return
    data = np.genfromtxt(args.floor, delimiter=",", names=True)
    t, ax = data["time_s"], data["ax_mps2"]
    az = data["az_mps2"] if "az_mps2" in data.dtype.names else np.zeros_like(ax)
    started = time.perf_counter()
    theta, events = simulate(block, t, ax, az, rtol=args.rtol, method=args.method)
    seconds = time.perf_counter() - started
    json.dump({"seconds": seconds, "theta_rad": theta.tolist(),
               "events": [{"event": e[0], "time_s": e[1], "side": e[2]} for e in events]}, sys.stdout)


if __name__ == "__main__":
    main()
