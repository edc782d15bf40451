"""A sliding-rocking block with Coulomb friction (stick, slide, rock, slide-rock; Shenton 1996), the
proof's coupled sliding formulation, written independently of shakeflow's Rust code.

At every instant the contact forces come from Newton-Euler about the centre of mass with the
contact forces as unknowns (per unit mass; (x, z) the centre of mass relative to the pivot on side
s, x = -s b cos(th) + hc sin(th), z = s b sin(th) + hc cos(th)):

    a_g + u'' + z th'' - x th'^2 = F          a_v - x th'' - z th'^2 = N - g
    (I_cm/m) th'' = -F z + N x                 stick: u'' = 0;  slip: F = -sigma mu_k N

Regimes: stick (th = u' = 0) until |a_g| > mu_s (g + a_v) (slide) or -s a_g > (g + a_v) tan(alpha)
(rock); slide until u' = 0; rock until th = 0 (impact, th' -> e th'), |F| > mu_s N (slide-rock) or
overturn; slide-rock until u' = 0 (rock) or th = 0 (impact, slip velocity kept). The floor is linear
between samples; solve_ivp (DOP853) with terminal events. Outputs: theta on the generator's fine
grid (rocking.OUT_PER_SAMPLE per sample) and the top-centre accelerometer at the floor's samples.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

from rocking import LIE, first_positive, OUT_PER_SAMPLE, OVER, REST, REST_AMPLITUDE, ROCK, SLIDE, Block, Floor, Response

SLIDE_ROCK = ROCK     # the regime code the generator's tools read: rocking (theta moves)


class _Model:
    def __init__(self, blk: Block, floor: Floor, mu_s: float, mu_k: float):
        self.blk, self.floor, self.mu_s, self.mu_k = blk, floor, mu_s, mu_k
        self.b, self.hc, self.H = 0.5 * blk.B, blk.hc, blk.H
        self.icm = (blk.B ** 2 + blk.H ** 2) / 12.0
        self.tan = math.tan(blk.alpha)
        self.ax, self.az = floor.ax, floor.az
        self.n, self.dt = floor.n, floor.dt

    def at(self, t: float) -> tuple[float, float]:
        k = min(int(t / self.dt), self.n - 2)
        w = t / self.dt - k
        return (self.ax[k] + w * (self.ax[k + 1] - self.ax[k]), self.az[k] + w * (self.az[k + 1] - self.az[k]))

    def cm(self, s: int, th: float) -> tuple[float, float]:
        return (-s * self.b * math.cos(th) + self.hc * math.sin(th), s * self.b * math.sin(th) + self.hc * math.cos(th))

    def rock(self, s: int, th: float, w: float, ag: float, av: float) -> tuple[float, float, float]:
        """Pivot stuck: th'', F, N (u'' = 0): substitute F and N into the moment equation."""
        x, z = self.cm(s, th)
        g = self.blk.g + av
        # icm th'' = -(ag + z th'' - x w^2) z + (g - x th'' - z w^2) x
        th_dd = (-(ag - x * w * w) * z + (g - z * w * w) * x) / (self.icm + z * z + x * x)
        return th_dd, ag + z * th_dd - x * w * w, g - x * th_dd - z * w * w

    def slide_rock(self, s: int, sigma: int, th: float, w: float, ag: float, av: float):
        x, z = self.cm(s, th)
        A = np.array([[z, 1.0, -1.0, 0.0], [-x, 0.0, 0.0, -1.0], [self.icm, 0.0, z, -x],
                      [0.0, 0.0, 1.0, sigma * self.mu_k]])
        rhs = np.array([-ag + x * w * w, -av - self.blk.g + z * w * w, 0.0, 0.0])
        return np.linalg.solve(A, rhs)    # th'', u'', F, N

    def top(self, regime: str, s: int, sigma: int, y, ag: float, av: float) -> float:
        """Absolute horizontal acceleration of the top centre (height H)."""
        if regime == "stick":
            return ag
        if regime == "slide":
            return -sigma * self.mu_k * (self.blk.g + av)
        if regime == "rock":
            th_dd, u_dd = self.rock(s, y[0], y[1], ag, av)[0], 0.0
        else:
            th_dd, u_dd = self.slide_rock(s, sigma, y[0], y[1], ag, av)[:2]
        th, w = y[0], y[1]
        x = -s * self.b * math.cos(th) + self.H * math.sin(th)
        z = s * self.b * math.sin(th) + self.H * math.cos(th)
        return ag + u_dd + z * th_dd - x * w * w


def simulate_sliding(blk: Block, floor: Floor, mu_s: float, mu_k: float, e: float | None = None) -> tuple[Response, np.ndarray, np.ndarray]:
    """The response (theta on the fine grid, regimes, events), the top reading and the slip (m) at
    the floor's samples."""
    m = _Model(blk, floor, mu_s, mu_k)
    e = blk.e_eq24 if e is None else e
    n, dt = floor.n, floor.dt
    t_end = (n - 1) * dt
    n_out = (n - 1) * OUT_PER_SAMPLE + 1
    t_out = np.arange(n_out) * (dt / OUT_PER_SAMPLE)
    theta, theta_dot = np.zeros(n_out), np.zeros(n_out)
    regime_out, side_out, dir_out = np.zeros(n_out, np.int8), np.zeros(n_out, np.int8), np.zeros(n_out, np.int8)
    top, slip = np.zeros(n), np.zeros(n)
    top[0] = floor.ax[0]
    events: list = []
    rest_speed2 = 2 * blk.p ** 2 * math.sin(blk.alpha) * REST_AMPLITUDE
    state = {"next": 1}
    codes = {"stick": REST, "slide": SLIDE, "rock": ROCK, "slide_rock": SLIDE_ROCK}

    def write(ts, ys, regime, s, sigma):
        j0 = state["next"]
        for tt, yy in zip(ts, ys.T):
            j = int(round(tt / t_out[1]))
            if j < j0 or abs(tt - t_out[j]) > 1e-9:
                continue
            theta[j], theta_dot[j] = yy[0], yy[1]
            regime_out[j], side_out[j], dir_out[j] = codes[regime], s, sigma
            if j % OUT_PER_SAMPLE == 0:
                k = j // OUT_PER_SAMPLE
                ag, av = floor.ax[k], floor.az[k]
                top[k] = m.top(regime, s, sigma, yy, ag, av)
                slip[k] = yy[2]
            j0 = j + 1
        state["next"] = j0

    def leg(rhs, t0, y0, evs, regime, s, sigma):
        for ev in evs:
            ev.terminal, ev.direction = True, -1
        grid = t_out[state["next"]:]
        grid = grid[grid > t0]
        sol = solve_ivp(rhs, (t0, t_end), y0, method="DOP853", rtol=1e-10, atol=1e-12, events=evs,
                        dense_output=True, max_step=dt)
        # An event function that starts on its boundary and turns the wrong way fires at t0: the
        # regime cannot be left that way (the count of transitions at one instant is bounded).
        hits = [(te[0], i) for i, te in enumerate(sol.t_events) if len(te)]
        if hits:
            te, i = min(hits)
            inside = grid[grid <= te]
            if len(inside):
                write(inside, sol.sol(inside), regime, s, sigma)
            return i, te, sol.sol(te)
        if len(grid):
            write(grid, sol.sol(grid), regime, s, sigma)
        return None, t_end, sol.y[:, -1]

    g_arr = blk.g + floor.az
    stick_arrays = [g_arr * m.tan + floor.ax, g_arr * m.tan - floor.ax, mu_s * g_arr - floor.ax, mu_s * g_arr + floor.ax]
    t, y, regime, s, sigma = 0.0, np.zeros(4), "stick", 0, 0
    count, last_t = 0, -1.0
    while t < t_end - 1e-12:
        count = count + 1 if t - last_t < 1e-12 else 0
        if count > 2000:
            raise RuntimeError(f"stick-slip or impact chatter at t = {t:.4f} s did not settle")
        last_t = t
        if regime == "stick":
            def margins(tt, j):
                ag, av = m.at(tt)
                g = blk.g + av
                return [g * m.tan + ag, g * m.tan - ag, mu_s * g - ag, mu_s * g + ag][j]
            now = [margins(t, j) for j in range(4)]
            if min(now) < 0:
                i, te, ye = int(np.argmin(now)), t, y
            else:
                # The margins are linear between samples: their first zero in closed form.
                found = [(tc, j) for j, arr in enumerate(stick_arrays)
                         if (tc := first_positive(-arr, dt, t, t_end)) is not None]
                te, i = min(found) if found else (t_end, None)
                ye = y
                grid = t_out[state["next"]:]
                grid = grid[(grid > t) & (grid <= te)]
                write(grid, np.zeros((4, len(grid))) + np.array(y)[:, None], "stick", 0, 0)
                if i is None:
                    break
            t, y = te, np.array([0.0, 0.0, ye[2], 0.0])
            if i < 2:
                s, regime = (1 if i == 0 else -1), "rock"
                events.append(("uplift", te, s))
            else:
                sigma, regime = (-1 if i == 2 else 1), "slide"
                events.append(("slide_start", te, sigma))
        elif regime == "slide":
            if mu_k > m.tan:
                s, regime = sigma, "slide_rock"
                events.append(("uplift", t, s))
                continue
            sg = sigma

            def rhs(tt, yy):
                ag, av = m.at(tt)
                return [0.0, 0.0, yy[3], -ag - sg * mu_k * (blk.g + av)]
            i, te, ye = leg(rhs, t, y, [lambda tt, yy: sg * yy[3]], "slide", 0, sg)
            if i is None:
                break
            t, y, regime = te, np.array([0.0, 0.0, ye[2], 0.0]), "stick"
            events.append(("stick", te, 0))
        elif regime == "rock":
            ss = s

            def grip(tt, yy, j):
                ag, av = m.at(tt)
                _, F, N = m.rock(ss, yy[0], yy[1], ag, av)
                return mu_s * N - F if j == 0 else mu_s * N + F
            g0 = [grip(t, y, 0), grip(t, y, 1)]
            if min(g0) < 0:
                sigma, regime = (-1 if g0[0] < g0[1] else 1), "slide_rock"
                events.append(("slide_start", t, sigma))
                continue

            def rhs(tt, yy):
                ag, av = m.at(tt)
                return [yy[1], m.rock(ss, yy[0], yy[1], ag, av)[0], 0.0, 0.0]
            evs = [lambda tt, yy: ss * yy[0], lambda tt, yy: LIE - ss * yy[0],
                   lambda tt, yy: grip(tt, yy, 0), lambda tt, yy: grip(tt, yy, 1)]
            i, te, ye = leg(rhs, t, y, evs, "rock", ss, 0)
            if i is None:
                break
            t = te
            if i == 0:
                after = e * ye[1]
                if after * after < rest_speed2:
                    y, regime = np.array([0.0, 0.0, ye[2], 0.0]), "stick"
                    events.append(("rest", te, 0))
                else:
                    y, s = np.array([0.0, after, ye[2], 0.0]), -ss
                    events.append(("impact", te, -ss))
            elif i == 1:
                events.append(("overturn", te, ss))
                y, regime = np.array([ss * LIE, 0.0, ye[2], 0.0]), "over"
                break
            else:
                y, sigma, regime = np.array(ye), (-1 if i == 2 else 1), "slide_rock"
                events.append(("slide_start", te, sigma))
        else:   # slide_rock
            ss, sg = s, sigma

            def rhs(tt, yy):
                ag, av = m.at(tt)
                th_dd, u_dd, _, N = m.slide_rock(ss, sg, yy[0], yy[1], ag, av)
                return [yy[1], th_dd, yy[3], u_dd]
            evs = [lambda tt, yy: ss * yy[0], lambda tt, yy: LIE - ss * yy[0], lambda tt, yy: sg * yy[3]]
            i, te, ye = leg(rhs, t, y, evs, "slide_rock", ss, sg)
            if i is None:
                break
            t = te
            if i == 0:
                after = e * ye[1]
                if after * after < rest_speed2:
                    y, regime = np.array([0.0, 0.0, ye[2], ye[3]]), "slide"
                    events.append(("rest", te, 0))
                else:
                    y, s = np.array([0.0, after, ye[2], ye[3]]), -ss
                    events.append(("impact", te, -ss))
            elif i == 1:
                events.append(("overturn", te, ss))
                y, regime = np.array([ss * LIE, 0.0, ye[2], 0.0]), "over"
                break
            else:
                y, regime = np.array([ye[0], ye[1], ye[2], 0.0]), "rock"
                events.append(("stick", te, 0))
    j0 = state["next"]
    if regime == "over":
        theta[j0:], regime_out[j0:], side_out[j0:] = y[0], OVER, s
        k0 = (j0 + OUT_PER_SAMPLE - 1) // OUT_PER_SAMPLE
        top[k0:] = floor.az[k0:]          # lying on its side: the sensor reads the vertical
        slip[k0:] = y[2]
    resp = Response(t_out, theta, theta_dot, regime_out, side_out, np.zeros(n_out, np.int8), dir_out, [blk], events)
    return resp, top, slip
