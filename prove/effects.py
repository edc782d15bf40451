"""The concealed effects: one function per verdict of the diagnosis vocabulary.

Each function gets the case's setting (block, floor, the baseline response) and a random generator,
draws its parameters and onset, and returns what the instruments would see (`Concealed`), or None
when this floor cannot host the effect (e.g. no impact to change the restitution of).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from floors import sdof_absolute_acceleration
from sliding import simulate_sliding
from rocking import (OVER, ROCK, SLIDE, Block, Floor, MassChange, Obstacle, Options, Response, kinematics,
                     simulate)

VERDICTS = ("none", "sliding", "mass_change", "restitution", "flexibility", "obstacle_impact",
            "sensor_tilt", "unexplained")


@dataclass
class Setting:
    rng: np.random.Generator
    block: Block
    floor: Floor             # the floor record as written (rounded)
    base: Response           # the baseline model's response to it


@dataclass
class Concealed:
    parameters: dict
    onset_s: float | None    # None: the first visible difference (set by the generator)
    onset_definition: str
    response: Response       # the true motion of the block
    under_block: Floor       # the motion under the block (the floor, or a flexible mount's top)
    friction: float | None = None
    tilted_sensor: bool = False
    accel_fault: Callable[[np.ndarray], np.ndarray] | None = None      # on the 200 Hz reading
    camera_fault: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None   # (t, theta) -> theta
    sensor_point: tuple[float, float] | None = None   # (offset from the centre line, height); None: top centre
    top_reading: np.ndarray | None = None            # a formulation that computes its own reading

    def reading(self) -> np.ndarray:
        """Noise-free accelerometer reading at the floor's samples, before any sensor fault."""
        if self.top_reading is not None:
            return self.top_reading
        kin = kinematics(self.response, self.under_block, self.friction, self.sensor_point)
        return kin.tilted_reading(self.response.blocks[0].g) if self.tilted_sensor else kin.top_ax


def _rocking_times(resp: Response) -> np.ndarray:
    return resp.t_out[resp.regime == ROCK]


def conceal_none(s: Setting) -> Concealed:
    return Concealed({}, None, "no effect", s.base, s.floor)


def conceal_sensor_tilt(s: Setting) -> Concealed:
    """The accelerometer turns with the body: it reads the specific force along the body's x axis,
    a_x cos(theta) - (a_z + g) sin(theta); lying on side s it reads -s (a_z + g). Two formulations:
    at the top centre (as the equipment file says), or (50 %) mounted off it: 0.75-1.0 H high and up
    to 40 % of the half base off the centre line, which the equipment file does not say."""
    params = {"formula": "top_ax = a_x*cos(theta) - (a_z + g)*sin(theta) (a_x, a_z: absolute kinematic "
                         "acceleration of the sensor point, world frame, z up); after an overturn on side s: "
                         "-s*(a_z + g)"}
    point = None
    if s.rng.random() < 0.5:
        point = (float(s.rng.uniform(-0.4, 0.4) * 0.5 * s.block.B), float(s.rng.uniform(0.75, 1.0) * s.block.H))
        params.update({"formulation": "tilt_and_offset", "sensor_offset_m": point[0], "sensor_height_m": point[1]})
    else:
        params["formulation"] = "tilt_at_top_centre"
    return Concealed(params, s.base.first("uplift"), "first uplift", s.base, s.floor, tilted_sensor=True,
                     sensor_point=point)


def conceal_mass_change(s: Setting) -> Concealed | None:
    """At t0 a fraction of the mass at 0.6-0.9 H leaves (bottles thrown from a shelf): the block
    keeps its rectangle, its centre of mass moves to (m hc - m_l z_l)/(m - m_l); theta and its rate
    are continuous at t0. t0 falls while the block rocks, or shortly before an uplift."""
    rng, base = s.rng, s.base
    over = base.overturn
    rocking = _rocking_times(base)
    if over is not None:
        rocking = rocking[rocking < over[0] - 0.2]
    uplifts = [e[1] for e in base.events if e[0] == "uplift" and (over is None or e[1] < over[0])]
    if rng.random() < 0.25 or len(rocking) == 0:
        t0 = max(0.05, uplifts[rng.integers(len(uplifts))] - rng.uniform(0.05, 0.5))
    else:
        t0 = float(rocking[rng.integers(len(rocking))])
    fraction = rng.uniform(0.05, 0.40)
    z_lost = rng.uniform(0.4, 1.0) * s.block.H
    after = s.block.after_mass_loss(fraction * s.block.mass, z_lost)
    resp = simulate(s.block, s.floor, Options(mass_change=MassChange(t0, after)))
    params = {"mass_fraction_lost": fraction, "lost_mass_kg": fraction * s.block.mass,
              "lost_mass_cm_height_m": z_lost, "t0_s": t0,
              "before": s.block.describe(), "after": after.describe()}
    return Concealed(params, t0, "t0, the mass leaves", resp, s.floor)


def conceal_restitution(s: Setting) -> Concealed | None:
    """Impacts lose another share of the angular speed than Eq. 24 says: mostly more (e = e24 x
    0.55-0.85, soft contact), sometimes less (e up to 0.98)."""
    rng, blk = s.rng, s.block
    first_impact = s.base.first("impact")
    if first_impact is None:
        return None
    e24 = blk.e_eq24
    if rng.random() < 0.7 or e24 + 0.05 >= 0.99:
        e = max(0.2, e24 * rng.uniform(0.4, 0.9))
    else:
        e = rng.uniform(e24 + 0.05, 0.99)
    resp = simulate(blk, s.floor, Options(restitution=e))
    params = {"e": e, "e_formula": e24, "e_over_formula": e / e24}
    return Concealed(params, first_impact, "first impact", resp, s.floor)


def conceal_flexibility(s: Setting) -> Concealed:
    """A flexible mount (linear SDOF, 2-5 Hz, 2-8 % damping) between floor and block: the block's
    base moves with the mount's absolute acceleration (the block is light against the mount, so it
    does not load it back); the top accelerometer reads mount motion + rocking."""
    rng = s.rng
    fn, zeta = rng.uniform(1.5, 8.0), rng.uniform(0.01, 0.12)
    mount = Floor(s.floor.dt, sdof_absolute_acceleration(s.floor.ax, fn, zeta, 1.0 / s.floor.dt), s.floor.az)
    resp = simulate(s.block, mount)
    params = {"mount_fn_hz": fn, "mount_zeta": zeta,
              "mount_peak_ax_mps2": float(np.abs(mount.ax).max()),
              "note": "the block rocks on the mount's absolute acceleration; vertical motion unchanged"}
    return Concealed(params, None, "first visible difference (the mount acts from t = 0)", resp, mount)


def conceal_obstacle_impact(s: Setting) -> Concealed | None:
    """A wall or neighbouring unit on side `side` stops the rotation at theta_w (0.5-0.9 alpha):
    theta' -> -e_w theta'; with a negligible rebound the block leans on it until the floor pulls it
    away. Placed on a side the baseline rotates past theta_w, so the contact happens."""
    rng, blk, base = s.rng, s.block, s.base
    ratio = rng.uniform(0.3, 1.0)
    theta_w = ratio * blk.alpha
    upright = base.regime != OVER
    sides = [side for side in (1, -1) if (side * base.theta[upright]).max(initial=0.0) > theta_w]
    if not sides:
        return None
    side = int(sides[rng.integers(len(sides))])
    e_w = rng.uniform(0.1, 0.9)
    if rng.random() < 0.5:
        # A neighbouring unit that gives: a compressive spring-dashpot beyond theta_w.
        compliance = (float(rng.uniform(8.0, 40.0)), float(rng.uniform(0.05, 0.4)))
        resp = simulate(blk, s.floor, Options(obstacle=Obstacle(side, theta_w, e_w, compliance)))
        beyond = np.flatnonzero(side * resp.theta > theta_w)
        if len(beyond) == 0:
            return None
        params = {"formulation": "compliant_neighbour", "side": side, "theta_w_rad": theta_w,
                  "theta_w_over_alpha": ratio, "contact_freq_hz": compliance[0], "contact_damping": compliance[1],
                  "note": "theta'' -= s*max(0, w_c^2 (s theta - theta_w) + 2 zeta w_c s theta') beyond theta_w"}
        return Concealed(params, float(resp.t_out[beyond[0]]), "first contact with the neighbour", resp, s.floor)
    resp = simulate(blk, s.floor, Options(obstacle=Obstacle(side, theta_w, e_w)))
    contacts = [e[1] for e in resp.events if e[0] in ("wall_impact", "wall_lean")]
    params = {"formulation": "rigid_wall", "side": side, "theta_w_rad": theta_w, "theta_w_over_alpha": ratio, "e_w": e_w,
              "n_wall_impacts": resp.count("wall_impact"), "n_wall_leans": resp.count("wall_lean"),
              "note": f"side={side:+d}: the obstacle on the {'+' if side > 0 else '-'}x side stops "
                      f"{'theta>0' if side > 0 else 'theta<0'} at {'+' if side > 0 else '-'}theta_w"}
    return Concealed(params, contacts[0], "first contact with the obstacle", resp, s.floor)


def conceal_sliding(s: Setting) -> Concealed | None:
    """Coulomb friction, two formulations:
    - `uncoupled` (the generator's first one): below tan(alpha) the block at rest slides when
      |a_x| > mu (g + a_z), its top reads -mu (g + a_z) sign(v_rel), and rocking still starts from
      the floor's acceleration on a stuck pivot (theta unchanged);
    - `coupled` (60 %): the sliding-rocking block (prove/sliding.py: stick, slide, rock, slide-rock,
      Shenton 1996) with mu_s 0.4-1.6 tan(alpha) and mu_k/mu_s 0.6-1: below tan(alpha) it slides
      instead of rocking; above, it rocks and its pivot slips in short, sparse episodes."""
    rng, blk = s.rng, s.block
    if rng.random() < 0.6:
        ratio = rng.uniform(0.4, 1.6)
        mu_s = ratio * math.tan(blk.alpha)
        mu_k = mu_s * rng.uniform(0.6, 1.0)
        resp, top, slip = simulate_sliding(blk, s.floor, mu_s, mu_k)
        onset = resp.first("slide_start")
        if onset is None:
            return None
        params = {"formulation": "coupled", "mu_s": mu_s, "mu_k": mu_k, "mu_s_over_tan_alpha": ratio,
                  "n_slips": resp.count("slide_start"), "max_abs_slip_m": float(np.abs(slip).max()),
                  "final_slip_m": float(slip[-1])}
        return Concealed(params, onset, "first slip", resp, s.floor, top_reading=top)
    ratio = rng.uniform(0.3, 1.0)
    mu = ratio * math.tan(blk.alpha)
    resp = simulate(blk, s.floor, Options(friction=mu))
    onset = resp.first("slide_start")
    if onset is None:
        return None
    params = {"formulation": "uncoupled", "mu": mu, "mu_over_tan_alpha": ratio, "n_slides": resp.count("slide_start"),
              "sliding_time_s": float((resp.regime == SLIDE).sum() * (resp.t_out[1] - resp.t_out[0]))}
    return Concealed(params, onset, "first slide", resp, s.floor, friction=mu)


def conceal_unexplained(s: Setting) -> Concealed | None:
    """A real mismatch outside the library: a clock offset or a gain change of the accelerometer,
    a drift of the camera's angle, or an accelerometer that saturates."""
    rng, base, floor = s.rng, s.base, s.floor
    t = floor.t
    kind = ["clock_offset", "gain_change", "camera_drift", "clipping"][rng.integers(4)]
    # t0 near the first uplift and, if the block overturns, a second before: a sensor fault on a
    # block lying on its side shows only in the small vertical floor motion.
    uplift = base.first("uplift")
    latest = min(uplift + 4.0, t[-1] - 5.0, base.overturn[0] - 1.0 if base.overturn else np.inf)
    t0 = rng.uniform(max(0.5, uplift - 2.0), max(0.6, latest))
    after = t >= t0
    if kind == "clock_offset":
        offset = rng.uniform(0.03, 0.4)
        params = {"kind": kind, "t0_s": t0, "offset_s": offset,
                  "formula": "for t >= t0: top_ax_obs(t) = top_ax(t - offset_s)",
                  "note": "accelerometer only; the camera follows the baseline physics"}
        fault = lambda a: np.where(after, np.interp(t - offset, t, a), a)   # noqa: E731
        return Concealed(params, t0, "t0", base, floor, accel_fault=fault)
    if kind == "gain_change":
        gain = rng.uniform(1.2, 1.8) if rng.random() < 0.5 else rng.uniform(0.4, 0.8)
        params = {"kind": kind, "t0_s": t0, "gain": gain, "formula": "for t >= t0: top_ax_obs = gain * top_ax",
                  "note": "accelerometer only; the camera follows the baseline physics"}
        return Concealed(params, t0, "t0", base, floor, accel_fault=lambda a: np.where(after, gain * a, a))
    if kind == "camera_drift":
        amplitude = rng.choice([-1.0, 1.0]) * rng.uniform(0.015, 0.06)
        ramp = rng.uniform(0.3, 3.0)
        params = {"kind": kind, "t0_s": t0, "amplitude_rad": amplitude, "ramp_s": ramp,
                  "formula": "theta_obs = theta + amplitude * clip((t - t0)/ramp, 0, 1)",
                  "note": "camera only; the accelerometer follows the baseline physics"}
        drift = lambda tt, th: th + amplitude * np.clip((tt - t0) / ramp, 0.0, 1.0)   # noqa: E731
        return Concealed(params, t0, "t0", base, floor, camera_fault=drift)
    clean = Concealed({}, None, "", base, floor).reading()
    level = rng.uniform(0.4, 0.8) * np.abs(clean).max()
    onset = float(t[np.argmax(np.abs(clean) > level)])
    params = {"kind": kind, "level_mps2": level, "formula": "top_ax_obs = clip(top_ax, -level, +level)",
              "note": "accelerometer only (saturates from the start; onset = first sample beyond the level)"}
    return Concealed(params, onset, "first sample beyond the saturation level", base, floor,
                     accel_fault=lambda a: np.clip(a, -level, level))


CONCEAL = {
    "none": conceal_none,
    "sliding": conceal_sliding,
    "mass_change": conceal_mass_change,
    "restitution": conceal_restitution,
    "flexibility": conceal_flexibility,
    "obstacle_impact": conceal_obstacle_impact,
    "sensor_tilt": conceal_sensor_tilt,
    "unexplained": conceal_unexplained,
}
