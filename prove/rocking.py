"""Rocking of a rigid rectangular block on a moving floor, with the physics the proof cases conceal.

The baseline is the study's 2D toppling model (docs: SEED-SUMMARY.md, Eqs. 20-24), written here
independently of shakeflow's Rust code:

* at rest the block uplifts toward side s when -s*a_x > (g + a_z) tan(alpha) (Eq. 20/21), with the
  floor linear between its samples;
* rocking on side s follows Eq. 22, theta'' = -(mR/I0) [(g + a_z) sin(s*alpha - theta)
  + a_x cos(s*alpha - theta)], integrated with solve_ivp (DOP853, terminal events);
* theta = 0 is an impact: theta' -> e theta' on the other corner (e of Eq. 24), and an impact whose
  rebound would rock the block less than REST_AMPLITUDE (free rocking amplitude w^2/(2 p^2 sin alpha))
  ends in rest; |theta| = pi/2 is an overturn.

Options add the concealed physics (each only where the generator asks for it): another coefficient
of restitution, an obstacle that stops the rotation on one side, a mass change at a time and
Coulomb sliding of the block at rest. A flexible mount is not an option here: it changes the base
motion, so the generator passes the mount's absolute acceleration as the floor.

Outputs are on a grid three times finer than the floor's (600 Hz for a 200 Hz floor) so that both
the accelerometer (200 Hz) and the camera (30 Hz) sample the response exactly.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.integrate import solve_ivp

G = 9.81
LIE = math.pi / 2
REST_AMPLITUDE = 1e-7
OUT_PER_SAMPLE = 3          # output points per floor sample interval
# Regimes of the block, stored per output point.
REST, ROCK, SLIDE, LEAN, OVER = 0, 1, 2, 3, 4
MAX_TRANSITIONS = 20_000    # regime changes allowed in one sample interval (impact chatter guard)


@dataclass(frozen=True)
class Block:
    """A uniform-looking rectangle: width B, height H, centre of mass raised by f*H above mid-height."""
    B: float
    H: float
    f: float
    mass: float
    g: float = G

    @property
    def hc(self) -> float:
        return self.H * (0.5 + self.f)

    @property
    def R(self) -> float:
        return math.hypot(0.5 * self.B, self.hc)

    @property
    def alpha(self) -> float:
        return math.atan2(0.5 * self.B, self.hc)

    @property
    def I0(self) -> float:
        return self.mass * ((self.B ** 2 + self.H ** 2) / 12.0 + self.R ** 2)

    @property
    def k(self) -> float:
        """mR/I0, the factor of Eq. 22."""
        return self.mass * self.R / self.I0

    @property
    def p(self) -> float:
        return math.sqrt(self.g * self.k)

    @property
    def e_eq24(self) -> float:
        return 1.0 - self.mass * self.R * self.B / self.I0 * math.sin(self.alpha)

    def after_mass_loss(self, lost_kg: float, lost_height_m: float) -> "Block":
        """The block once `lost_kg` at height `lost_height_m` has left: same rectangle, the centre
        of mass lowered (or raised) to (m hc - m_l z_l)/(m - m_l)."""
        remaining = self.mass - lost_kg
        hc_after = (self.mass * self.hc - lost_kg * lost_height_m) / remaining
        return replace(self, mass=remaining, f=hc_after / self.H - 0.5)

    def describe(self) -> dict:
        return {"B_m": self.B, "H_m": self.H, "f": self.f, "mass_kg": self.mass, "hc_m": self.hc,
                "R_m": self.R, "alpha_rad": self.alpha, "I0_kgm2": self.I0, "p_radps": self.p,
                "e_formula": self.e_eq24}


@dataclass(frozen=True)
class Floor:
    """The motion under the block, sampled at a constant step from t = 0: horizontal in-plane a_x
    and vertical a_z (m/s^2), linear between samples."""
    dt: float
    ax: np.ndarray
    az: np.ndarray

    @property
    def n(self) -> int:
        return len(self.ax)

    @property
    def t(self) -> np.ndarray:
        return np.arange(self.n) * self.dt


@dataclass(frozen=True)
class Obstacle:
    """A wall on side `side` (sign of theta) that stops the rotation at |theta| = angle_rad and
    returns restitution * the angular speed."""
    side: int
    angle_rad: float
    restitution: float
    # A neighbour that gives: (contact frequency f_c in Hz, damping ratio) of a compressive
    # spring-dashpot acting on the rotation beyond angle_rad (theta'' += -s (w_c^2 pen + 2 z w_c s th'),
    # never pulling). None: a rigid wall (the event rule with `restitution`).
    compliance: tuple[float, float] | None = None


@dataclass(frozen=True)
class MassChange:
    time_s: float
    after: Block


@dataclass(frozen=True)
class Options:
    restitution: float | None = None       # None: Eq. 24
    obstacle: Obstacle | None = None
    mass_change: MassChange | None = None
    friction: float | None = None          # Coulomb mu (static = kinetic); None: no sliding
    rtol: float = 1e-10
    rest_amplitude: float = REST_AMPLITUDE
    method: str = "DOP853"


@dataclass
class Response:
    """The block's motion on the output grid (t_out) and its events."""
    t_out: np.ndarray
    theta: np.ndarray
    theta_dot: np.ndarray
    regime: np.ndarray          # REST, ROCK, SLIDE, LEAN, OVER
    side: np.ndarray            # pivot side while rocking/leaning/lying, else 0
    block_index: np.ndarray     # 0 before a mass change, 1 after
    slide_dir: np.ndarray       # sign of the sliding velocity relative to the floor
    blocks: list
    events: list = field(default_factory=list)   # (kind, time_s, side)

    def first(self, kind: str) -> float | None:
        return next((e[1] for e in self.events if e[0] == kind), None)

    def count(self, kind: str) -> int:
        return sum(1 for e in self.events if e[0] == kind)

    @property
    def overturn(self) -> tuple[float, int] | None:
        return next(((e[1], e[2]) for e in self.events if e[0] == "overturn"), None)

    def outcome(self) -> dict:
        over = self.overturn
        return {"overturned": over is not None,
                "overturn_time_s": None if over is None else over[0],
                "overturn_side": None if over is None else over[1],
                "max_abs_theta_rad": float(np.abs(self.theta).max()),
                "first_uplift_s": self.first("uplift"),
                "n_uplifts": self.count("uplift"),
                "n_impacts": self.count("impact")}


def first_positive(values: np.ndarray, dt: float, t: float, t_lim: float) -> float | None:
    """First time in [t, t_lim] at which a function sampled at k*dt (linear in between) is > 0."""
    n = len(values)
    k = min(int(t / dt), n - 2)
    v_t = values[k] + (t / dt - k) * (values[k + 1] - values[k])
    if v_t > 0:
        return t
    k_lim = min(n - 1, math.ceil(t_lim / dt - 1e-9))
    ahead = values[k + 1:k_lim + 1] > 0
    if not ahead.any():
        return None
    j = k + 1 + int(np.argmax(ahead))
    t_prev, v_prev = (t, v_t) if j == k + 1 else ((j - 1) * dt, values[j - 1])
    tc = t_prev + v_prev / (v_prev - values[j]) * (j * dt - t_prev)
    return tc if tc <= t_lim else None


class _Run:
    """One simulation: a sequence of phases (rest, rocking, sliding, leaning, overturned), each
    writing its part of the output grid."""

    def __init__(self, block: Block, floor: Floor, opts: Options):
        self.floor, self.opts = floor, opts
        self.blocks = [block] + ([opts.mass_change.after] if opts.mass_change else [])
        self.ax_list, self.az_list = floor.ax.tolist(), floor.az.tolist()
        self.t_end = (floor.n - 1) * floor.dt
        n_out = (floor.n - 1) * OUT_PER_SAMPLE + 1
        self.t_out = np.arange(n_out) * (floor.dt / OUT_PER_SAMPLE)
        self.theta = np.zeros(n_out)
        self.theta_dot = np.zeros(n_out)
        self.regime = np.zeros(n_out, dtype=np.int8)
        self.side = np.zeros(n_out, dtype=np.int8)
        self.block_index = np.zeros(n_out, dtype=np.int8)
        self.slide_dir = np.zeros(n_out, dtype=np.int8)
        self.next_out = 1           # the first output point not yet written (t = 0 is at rest)
        self.events: list = []
        self.b = 0                  # index of the current block
        # Uplift functions (> 0: uplift toward side s) per block, linear between samples.
        g = block.g
        self.uplift = [{s: -s * floor.ax - (g + floor.az) * math.tan(blk.alpha) for s in (1, -1)}
                       for blk in self.blocks]

    # -- output -------------------------------------------------------------------------------
    def fill(self, t_until: float, theta: float, regime: int, side: int = 0, slide_dir: int = 0):
        """Write a constant state into the output points up to t_until."""
        j1 = int(np.searchsorted(self.t_out, t_until, side="right"))
        sl = slice(self.next_out, j1)
        self.theta[sl], self.theta_dot[sl] = theta, 0.0
        self.regime[sl], self.side[sl], self.slide_dir[sl], self.block_index[sl] = regime, side, slide_dir, self.b
        self.next_out = max(self.next_out, j1)

    def write(self, sol_t: np.ndarray, sol_y: np.ndarray, side: int):
        j0, j1 = self.next_out, self.next_out + len(sol_t)
        self.theta[j0:j1], self.theta_dot[j0:j1] = sol_y[0], sol_y[1]
        self.regime[j0:j1], self.side[j0:j1], self.block_index[j0:j1] = ROCK, side, self.b
        self.next_out = j1

    # -- the run -----------------------------------------------------------------------------
    def run(self) -> Response:
        t, state, y, side, slide_v = 0.0, "rest", np.zeros(2), 0, 0.0
        change = self.opts.mass_change
        transitions, last_t = 0, -1.0
        while t < self.t_end and state != "over":
            transitions = transitions + 1 if t == last_t else 0
            if transitions > MAX_TRANSITIONS:
                raise RuntimeError(f"impact chatter at t = {t:.4f} s did not settle")
            last_t = t
            t_lim = change.time_s if (change and self.b == 0 and change.time_s > t) else self.t_end
            if change and self.b == 0 and change.time_s <= t:
                self.b = 1
                self.events.append(("mass_change", t, 0))
                continue
            if state == "rest":
                t, state, side, slide_v = self.rest(t, t_lim)
                y = np.zeros(2)
            elif state == "slide":
                t, state, side, slide_v = self.slide(t, t_lim, slide_v)
                y = np.zeros(2)
            elif state == "lean":
                t, state = self.lean(t, t_lim, side)
                y = np.array([side * self.opts.obstacle.angle_rad, 0.0])
            else:
                t, state, side, y = self.rock(t, t_lim, side, y)
        if state == "over":
            self.fill(self.t_end, side * LIE, OVER, side)
        return Response(self.t_out, self.theta, self.theta_dot, self.regime, self.side, self.block_index,
                        self.slide_dir, self.blocks, self.events)

    def rest(self, t: float, t_lim: float):
        """At rest until the floor uplifts the block (or, with friction, drags it)."""
        floor, mu = self.floor, self.opts.friction
        starts = []
        for s in (1, -1):
            tu = first_positive(self.uplift[self.b][s], floor.dt, t, t_lim)
            if tu is not None:
                starts.append((tu, 0, "rock", s))
        if mu is not None:
            for d in (1, -1):
                # The floor accelerating toward -d faster than friction allows: relative slide toward d.
                ts = first_positive(-d * floor.ax - mu * (self.blocks[self.b].g + floor.az), floor.dt, t, t_lim)
                if ts is not None:
                    starts.append((ts, 1, "slide", d))
        if not starts:
            self.fill(t_lim, 0.0, REST)
            return t_lim, "rest", 0, 0.0
        te, _, kind, s = min(starts)   # on a tie, rocking wins (its pivot sticks)
        self.fill(te, 0.0, REST)
        if kind == "rock":
            self.events.append(("uplift", te, s))
            return te, "rock", s, 0.0
        self.events.append(("slide_start", te, s))
        return te, "slide", 0, s * 1e-300   # an infinitesimal relative velocity: the slide direction

    def slide(self, t: float, t_lim: float, v: float):
        """Coulomb sliding with relative velocity v: v' = -a_x - sign(v) mu (g + a_z), exact for a
        floor linear in time (v quadratic) within each sample interval."""
        floor, mu, g = self.floor, self.opts.friction, self.blocks[self.b].g
        dt, d = floor.dt, 1 if v > 0 else -1
        while t < t_lim:
            k = min(int(t / dt), floor.n - 2)
            t1 = min((k + 1) * dt, t_lim)
            if t1 <= t:            # t sits on a sample boundary by rounding
                k += 1
                t1 = min((k + 1) * dt, t_lim)
            ax_rate = (self.ax_list[k + 1] - self.ax_list[k]) / dt
            az_rate = (self.az_list[k + 1] - self.az_list[k]) / dt
            ax_t = self.ax_list[k] + (t - k * dt) * ax_rate
            az_t = self.az_list[k] + (t - k * dt) * az_rate
            c1 = -ax_t - d * mu * (g + az_t)
            if abs(v) <= 1e-300:
                # A slide starts where the floor's drag turns toward d: rounding must not flip it.
                c1 = d * max(d * c1, 0.0)
            c2 = 0.5 * (-ax_rate - d * mu * az_rate)
            span = t1 - t
            stop = _first_stop(v, c1, c2, span)
            up = self.uplift_within(t, t1)
            if up is not None and (stop is None or up[0] <= t + stop):
                # Rocking takes over; its pivot sticks.
                tu, s = up
                self.fill(tu, 0.0, SLIDE, slide_dir=d)
                self.events.append(("uplift", tu, s))
                return tu, "rock", s, 0.0
            if stop is not None:
                # A slide the floor only grazes stops within rounding of its start: stick just
                # after it, where the floor no longer drags the block, so that rest does not
                # restart it at the same instant.
                ts = max(t + stop, math.nextafter(t, math.inf))
                self.fill(ts, 0.0, SLIDE, slide_dir=d)
                self.events.append(("stick", ts, 0))
                return ts, "rest", 0, 0.0
            v = v + c1 * span + c2 * span * span
            self.fill(t1, 0.0, SLIDE, slide_dir=d)
            t = t1
        return t, "slide", 0, v

    def uplift_within(self, t: float, t1: float) -> tuple[float, int] | None:
        """The first uplift (time, side) within [t, t1], one sample interval of a sliding block."""
        found = [(tu, s) for s in (1, -1)
                 if (tu := first_positive(self.uplift[self.b][s], self.floor.dt, t, t1)) is not None]
        return min(found) if found else None

    def lean(self, t: float, t_lim: float, side: int):
        """Held against the obstacle until the floor pulls the block away from it: theta'' at the
        wall, with theta' = 0, points away from the wall."""
        blk, wall, floor = self.blocks[self.b], self.opts.obstacle, self.floor
        gap = blk.alpha - wall.angle_rad
        away = (blk.g + floor.az) * math.sin(gap) + side * floor.ax * math.cos(gap)
        tr = first_positive(away, floor.dt, t, t_lim)
        theta = side * wall.angle_rad
        if tr is None:
            self.fill(t_lim, theta, LEAN, side)
            return t_lim, "lean"
        self.fill(tr, theta, LEAN, side)
        self.events.append(("wall_release", tr, side))
        return tr, "rock"

    def integrate(self, rhs, events, a: float, b: float, y: np.ndarray, side: int):
        """One solve_ivp leg from a to b, writing the output points it passes."""
        j1 = int(np.searchsorted(self.t_out, b, side="right"))
        grid = self.t_out[self.next_out:j1]
        grid = grid[grid >= a]
        t_eval = grid if (len(grid) and grid[-1] == b) else np.append(grid, b)
        dt = self.floor.dt
        first = min(dt, b - a) if abs(a / dt - round(a / dt)) < 1e-9 else None
        sol = solve_ivp(rhs, (a, b), y, method=self.opts.method, rtol=self.opts.rtol, atol=self.opts.rtol * 1e-2,
                        t_eval=t_eval, events=events, max_step=dt, first_step=first)
        if sol.status < 0:
            raise RuntimeError(f"solve_ivp failed at t = {a:.4f} s: {sol.message}")
        n_grid = min(len(sol.t), len(grid))
        if n_grid:
            self.write(sol.t[:n_grid], sol.y[:, :n_grid], side)
        return sol

    def rock(self, t: float, t_lim: float, side: int, y: np.ndarray):
        """Eq. 22 on one side until an impact, an overturn, the obstacle or t_lim."""
        blk, opts, floor = self.blocks[self.b], self.opts, self.floor
        s, k, g = side, blk.k, blk.g
        s_alpha = s * blk.alpha
        ax, az = self.ax_list, self.az_list
        inv_dt, last = 1.0 / floor.dt, floor.n - 2
        sin, cos = math.sin, math.cos

        def rhs(time, state):
            u = time * inv_dt
            i = int(u)
            if i > last:
                i = last
            w = u - i
            a_x = ax[i] + w * (ax[i + 1] - ax[i])
            a_z = az[i] + w * (az[i + 1] - az[i])
            phi = s_alpha - state[0]
            acc = -k * ((g + a_z) * sin(phi) + a_x * cos(phi))
            if soft is not None:
                pen = s * state[0] - soft[0]
                if pen > 0.0:
                    acc -= s * max(0.0, soft[1] * pen + soft[2] * s * state[1])
            return [state[1], acc]

        def impact(time, state):
            return s * state[0]

        def overturn(time, state):
            return LIE - s * state[0]

        events = [impact, overturn]
        wall = opts.obstacle if (opts.obstacle and opts.obstacle.side == s) else None
        soft = None
        if wall is not None and wall.compliance is not None:
            w_c = 2 * math.pi * wall.compliance[0]
            soft = (wall.angle_rad, w_c * w_c, 2 * wall.compliance[1] * w_c)
            wall = None
        if wall is not None:
            def obstacle(time, state):
                return wall.angle_rad - s * state[0]
            events.append(obstacle)
        for ev in events:
            ev.terminal, ev.direction = True, -1
        # Steps that straddle a sample (a kink of the piecewise-linear floor) are rejected and
        # shrink; so the first leg ends at the next sample and the second steps sample to sample.
        dt = floor.dt
        boundary = math.ceil(t / dt - 1e-9) * dt
        legs = [(t, boundary), (boundary, t_lim)] if t < boundary < t_lim else [(t, t_lim)]
        for a, b in legs:
            sol = self.integrate(rhs, events, a, b, y, s)
            if sol.status == 1:
                break
            y = sol.y[:, -1]
        else:
            return t_lim, "rock", s, y
        hit = next(i for i, te in enumerate(sol.t_events) if len(te))
        te, ye = sol.t_events[hit][0], sol.y_events[hit][0]
        rest_speed2 = 2 * blk.p ** 2 * math.sin(blk.alpha) * opts.rest_amplitude
        if hit == 0:
            e = opts.restitution if opts.restitution is not None else blk.e_eq24
            w = e * ye[1]
            if w * w < rest_speed2:
                self.events.append(("rest", te, 0))
                return te, "rest", 0, np.zeros(2)
            self.events.append(("impact", te, -s))
            return te, "rock", -s, np.array([0.0, w])
        if hit == 1:
            self.events.append(("overturn", te, s))
            return te, "over", s, np.array([s * LIE, 0.0])
        w = -wall.restitution * ye[1]
        if w * w < rest_speed2:
            self.events.append(("wall_lean", te, s))
            return te, "lean", s, np.array([s * wall.angle_rad, 0.0])
        self.events.append(("wall_impact", te, s))
        return te, "rock", s, np.array([s * wall.angle_rad, w])


def _first_stop(v: float, c1: float, c2: float, span: float) -> float | None:
    """First tau in (0, span] at which the sliding velocity v + c1 tau + c2 tau^2 returns to 0."""
    if c2 == 0.0:
        roots = [-v / c1] if c1 != 0.0 else []
    else:
        disc = c1 * c1 - 4 * c2 * v
        sq = math.sqrt(disc) if disc >= 0 else math.nan
        roots = [(-c1 - sq) / (2 * c2), (-c1 + sq) / (2 * c2)] if disc >= 0 else []
    # A slide that starts from v = 0 has a root at tau = 0 that is not a stop.
    tiny = 1e-12 * span
    roots = [r for r in roots if tiny < r <= span * (1 + 1e-12)]
    if roots:
        return min(min(roots), span)
    v_end = v + c1 * span + c2 * span * span
    return tiny if (v_end > 0) != (v > 0) else None


def simulate(block: Block, floor: Floor, opts: Options = Options()) -> Response:
    return _Run(block, floor, opts).run()


@dataclass
class Kinematics:
    """The top-centre point (x = 0, height H) at the floor's samples."""
    theta: np.ndarray
    theta_dot: np.ndarray
    ax: np.ndarray          # absolute horizontal acceleration, world frame, gravity excluded
    az: np.ndarray          # absolute vertical acceleration (z up), gravity excluded
    overturned: np.ndarray  # lying on its side
    side: np.ndarray

    @property
    def top_ax(self) -> np.ndarray:
        """The baseline accelerometer: horizontal absolute acceleration; once lying on its side the
        sensor's axis is vertical and records the floor's vertical acceleration."""
        return np.where(self.overturned, self.az, self.ax)

    def tilted_reading(self, g: float = G) -> np.ndarray:
        """A sensor that turns with the body: specific force along the body's x axis."""
        reading = self.ax * np.cos(self.theta) - (self.az + g) * np.sin(self.theta)
        return np.where(self.overturned, -self.side * (self.az + g), reading)


def kinematics(resp: Response, floor: Floor, friction: float | None = None,
               point: tuple[float, float] | None = None) -> Kinematics:
    """Accelerations of the sensor point at the floor's samples: the top centre, or `point` =
    (offset d from the centre line toward +x, height h) in the block's frame."""
    sl = slice(None, None, OUT_PER_SAMPLE)
    theta, theta_dot = resp.theta[sl], resp.theta_dot[sl]
    regime, side = resp.regime[sl], resp.side[sl].astype(float)
    bidx = resp.block_index[sl]
    ax, az = floor.ax, floor.az
    sensor_ax, sensor_az = ax.copy(), az.copy()
    rocking = regime == ROCK
    if rocking.any():
        k = np.array([b.k for b in resp.blocks])[bidx]
        alpha = np.array([b.alpha for b in resp.blocks])[bidx]
        g = resp.blocks[0].g
        phi = side * alpha - theta
        theta_ddot = -k * ((g + az) * np.sin(phi) + ax * np.cos(phi))
        sb, h = side * 0.5 * resp.blocks[0].B, resp.blocks[0].H
        d = 0.0
        if point is not None:
            d, h = point
        sin, cos, w2 = np.sin(theta), np.cos(theta), theta_dot ** 2
        # The point relative to the pivot: x = (d - sb) cos(theta) + h sin(theta),
        # z = -(d - sb) sin(theta) + h cos(theta); x'' = z theta'' - x w^2, z'' = -x theta'' - z w^2.
        px = (d - sb) * cos + h * sin
        pz = -(d - sb) * sin + h * cos
        ax_rel = pz * theta_ddot - px * w2
        az_rel = -px * theta_ddot - pz * w2
        sensor_ax = np.where(rocking, ax + ax_rel, sensor_ax)
        sensor_az = np.where(rocking, az + az_rel, sensor_az)
    sliding = regime == SLIDE
    if sliding.any():
        g = resp.blocks[0].g
        sensor_ax = np.where(sliding, -resp.slide_dir[sl] * friction * (g + az), sensor_ax)
    return Kinematics(theta, theta_dot, sensor_ax, sensor_az, regime == OVER, side)
