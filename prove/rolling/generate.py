"""Concealed-effect cases for the rolling diagnosis, in the contract case format
(equipment.yaml with model: rolling, floor.csv, observed_cpt.csv, observed_accel.csv) with the
truth in truth/<case>.yaml, from this folder's own cart (cart.py) and prove/floors.py's floors.

    python prove/rolling/generate.py OUT_DIR [--per-effect 4] [--seed N] [--jobs 2]

Effects: none, lateral_impact, mass_change, caster_brake, swivel_jam, unexplained (a slab tilt,
an accelerometer clock offset, gain change or bias step after t0, a camera drift or yaw jump).
Each physical effect is drawn in one of two formulations (cart.py: a step or gradual mass loss, a
locked or dragging brake, a rigid or friction swivel lock, a rigid wall or compliant neighbour),
recorded as parameters.formulation, with ranges wider than the diagnosis's bounds. An effect must be
visible (noise-free observations beyond 3 noise sd from the baseline at >= 5 of 10 camera frames,
or 5 accelerometer samples beyond 5 sd within 0.1 s); the baseline must be predictable to the end
(a twin with yaw0 moved by 1e-6 rad stays within a quarter of the camera noise). Case names are
shuffled.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import yaml

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))
import cart  # noqa: E402
import floors  # noqa: E402

EFFECTS = ["none", "lateral_impact", "mass_change", "caster_brake", "swivel_jam", "unexplained"]
FS = 200.0
DT = 1.0 / FS
CAMERA_HZ = 30.0

# Table 4 (SEED-SUMMARY.md), the study's rolling units.
UNITS = {
    "PS1": dict(length_m=2.20, width_m=1.00, platform_mass_kg=234.0, wheel_diameter_m=0.20, wheel_width_m=0.045,
                wheel_mass_kg=1.0, mu_s_roll=0.045, mu_s_swivel=0.00049, mu_k_roll=0.00049, mu_k_swivel=2.45e-5,
                beta_spm=19.76, gamma_n=0.0014),
    "PB2": dict(length_m=2.36, width_m=1.05, platform_mass_kg=350.0, wheel_diameter_m=0.20, wheel_width_m=0.055,
                wheel_mass_kg=1.5, mu_s_roll=0.012, mu_s_swivel=0.00132, mu_k_roll=6.0e-4, mu_k_swivel=1.2e-4,
                beta_spm=15.0, gamma_n=0.00042),
    "MC2": dict(length_m=0.65, width_m=0.90, platform_mass_kg=154.0, wheel_diameter_m=0.125, wheel_width_m=0.030,
                wheel_mass_kg=0.5, mu_s_roll=0.044, mu_s_swivel=0.044, mu_k_roll=0.0044, mu_k_swivel=0.0044,
                beta_spm=6.05, gamma_n=0.00044),
    "UI3": dict(length_m=0.70, width_m=0.55, platform_mass_kg=180.0, wheel_diameter_m=0.15, wheel_width_m=0.030,
                wheel_mass_kg=0.5, mu_s_roll=0.025, mu_s_swivel=0.001, mu_k_roll=0.001, mu_k_swivel=5.0e-5,
                beta_spm=0.49, gamma_n=0.0001),
}


def draw_unit(rng):
    name = str(rng.choice(list(UNITS)))
    unit = dict(UNITS[name])
    unit.update(p=1.0, trail_m=round(float(rng.choice([0.3, 0.5])) * unit["wheel_diameter_m"], 4),
                swivel_arm_m=0.02, friction_eps=1e-4, friction_eps_swivel=float(rng.choice([1e-3, 1e-4])),
                yaw0_deg=round(float(rng.uniform(-20, 20)), 1))
    heading = rng.uniform(-180, 180)
    unit["steer0_deg"] = [round(float(heading + rng.normal(0, 20)), 1) for _ in range(4)]
    return name, unit


def draw_floor(rng, records, buildings):
    f = floors.make_floor(rng, records, buildings, 9.80665, rng.uniform(0.12, 0.3))
    n = min(len(f.ax), int(rng.uniform(18.0, 26.0) * FS) + 1)
    ax, ay = f.ax[:n].copy(), f.ay[:n].copy()
    ax[0] = ay[0] = 0.0
    return ax, ay, {"record": f.info["ground_motion"]["file"], "building": f.info["building"],
                    "storey": f.info["floor"], "pfa_x_g": float(np.abs(ax).max() / 9.80665)}


def parting(a, b, sd_m, sd_rad, frac=1.0):
    """First time the two runs' x, y or yaw differ by more than frac x the camera noise."""
    bad = (np.abs(a[:, 0] - b[:, 0]) > frac * sd_m) | (np.abs(a[:, 1] - b[:, 1]) > frac * sd_m) | \
          (np.abs(a[:, 2] - b[:, 2]) > frac * sd_rad)
    bad &= np.isfinite(a[:, 0]) & np.isfinite(b[:, 0])
    k = np.flatnonzero(bad)
    return None if len(k) == 0 else float(k[0] * DT)


def visible_from(obs_cam, base, sd_m, sd_rad, obs_acc, base_acc):
    """(first, last) time the noise-free observations depart from the baseline (3 sd at >= 5 of 10
    camera frames, or 5 sd at 5 accelerometer samples within 0.1 s)."""
    step = int(round(FS / CAMERA_HZ))
    k = np.arange(0, len(base), step)
    diff = (np.abs(obs_cam[k, 0] - base[k, 0]) > 3 * sd_m) | (np.abs(obs_cam[k, 1] - base[k, 1]) > 3 * sd_m) | \
           (np.abs(obs_cam[k, 2] - base[k, 2]) > 3 * sd_rad)
    times = []
    for i in range(len(k)):
        if diff[i:i + 10].sum() >= 5 and diff[i]:
            times.append(k[i] * DT)
    acc = np.abs(obs_acc - base_acc) > 5 * 0.02
    idx = np.flatnonzero(acc)
    for j in range(len(idx) - 4):
        if idx[j + 4] - idx[j] <= 20:
            times.append(idx[j] * DT)
    if not times:
        return None
    return min(times), max(times)


def moving_times(base, lo, hi, speed=0.03):
    v = np.hypot(np.gradient(base[:, 0], DT), np.gradient(base[:, 1], DT))
    t = np.arange(len(base)) * DT
    ok = (v > speed) & (t >= lo) & (t <= hi)
    return t[ok]


def conceal(rng, effect, unit, ax, ay, base):
    """The effect's parameters and its noise-free run (out array), or None to redraw."""
    T = (len(ax) - 1) * DT
    cands = moving_times(base, 2.0, 0.7 * T)
    if len(cands) == 0:
        return None
    t0 = round(float(rng.choice(cands)), 3)
    # Two formulations per effect (cart.py) and ranges wider than the diagnosis's own bounds.
    if effect == "mass_change":
        a, b = unit["length_m"] / 2, unit["width_m"] / 2
        gain = rng.random() < 0.3
        frac = rng.uniform(0.08, 0.8) if gain else -rng.uniform(0.08, 0.65)
        alt = dict(effect=effect, t0_s=t0, dm_kg=round(frac * unit["platform_mass_kg"], 3),
                   dx_m=round(float(rng.uniform(-0.95, 0.95) * a), 4), dy_m=round(float(rng.uniform(-0.95, 0.95) * b), 4),
                   formulation="step")
        if not gain and rng.random() < 0.4:
            alt.update(formulation="gradual", ramp_s=round(float(rng.uniform(0.2, 1.5)), 3))
        # A change that moves the centre of mass past a wheel's support line tips the cart: the
        # four-support loads (cart.py) would go negative, which no real cart shows. Redraw.
        m_after = unit["platform_mass_kg"] + alt["dm_kg"]
        cx, cy = alt["dm_kg"] * alt["dx_m"] / m_after, alt["dm_kg"] * alt["dy_m"] / m_after
        if min(1.0 + cx * sx / a + cy * sy / b for sx in (1, -1) for sy in (1, -1)) <= 0.0:
            return None
    elif effect == "caster_brake":
        alt = dict(effect=effect, t0_s=t0, wheel=int(rng.integers(4)), formulation="locked",
                   mu_drag=round(float(rng.uniform(0.05, 1.2)), 4))
        if rng.random() < 0.5:
            alt.update(formulation="dragging", spinning=True, mu_drag=round(float(rng.uniform(0.05, 0.8)), 4),
                       ramp_s=round(float(rng.uniform(0.05, 0.5)), 3))
    elif effect == "swivel_jam":
        alt = dict(effect=effect, t0_s=t0, caster=int(rng.integers(4)), formulation="rigid")
        if rng.random() < 0.5:
            alt.update(formulation="friction", mu_jam=round(float(rng.uniform(0.2, 3.0)), 3))
    elif effect == "lateral_impact":
        axis = int(rng.integers(2))
        side = float(rng.choice([-1.0, 1.0]))
        # The corner reach along the side over time; the wall where it is at a moving instant.
        a, b = unit["length_m"] / 2, unit["width_m"] / 2
        yaw = base[:, 2]
        reach = np.max([side * ((base[:, axis]) + (np.cos(yaw) * sx * a - np.sin(yaw) * sy * b if axis == 0
                                                   else np.sin(yaw) * sx * a + np.cos(yaw) * sy * b))
                        for sx, sy in [(1, 1), (-1, 1), (-1, -1), (1, -1)]], axis=0)
        run = np.maximum.accumulate(reach)
        k = int(round(t0 / DT))
        gain = run[k] - reach[0]
        if gain < 0.02:
            return None
        position = side * (reach[0] + gain * rng.uniform(0.5, 0.97))
        alt = dict(effect=effect, axis=axis, side=side, position_m=round(float(position), 5),
                   e=round(float(rng.uniform(0.02, 0.9)), 3), formulation="rigid")
        if rng.random() < 0.5:
            # A neighbour bed or cart: contact frequency with the platform's mass, damping ratio.
            m = unit["platform_mass_kg"]
            f, zeta = float(rng.uniform(4.0, 40.0)), float(rng.uniform(0.05, 0.6))
            k_n = m * (2 * math.pi * f) ** 2
            alt.update(formulation="compliant", contact_hz=round(f, 2), damping_ratio=round(zeta, 3),
                       stiffness_npm=round(k_n, 1), damping_nspm=round(2 * zeta * math.sqrt(k_n * m), 2))
    else:
        raise ValueError(effect)
    out, st = cart.simulate(unit, ax, ay, DT, alt)
    if st["failed"] or not np.isfinite(out).all():
        return None
    if effect == "lateral_impact":
        if alt["formulation"] == "rigid":
            if st["impacts"] == 0:
                return None
            alt["impacts"] = st["impacts"]
        elif not (np.abs(out[:, 3] - base[:, 3]) > 1e-6).any():
            return None
    return alt, out


def unexplained(rng, unit, ax, ay, base):
    """A disturbance outside the library; (params, out, accel override or None)."""
    T = (len(ax) - 1) * DT
    t0 = round(float(rng.uniform(2.0, 0.6 * T)), 3)
    kind = str(rng.choice(["floor_tilt", "clock_offset", "gain", "camera_drift", "accel_bias", "yaw_jump"]))
    out = base.copy()
    accel = base[:, 3].copy()
    if kind == "floor_tilt":
        tilt = dict(sigma_max_rad=float(rng.uniform(0.001, 0.004)), direction_rad=float(rng.uniform(-math.pi, math.pi)),
                    t0_s=t0, ramp_s=float(rng.uniform(1.0, 4.0)))
        out, st = cart.simulate(unit, ax, ay, DT, tilt=tilt)
        if st["failed"]:
            return None
        accel = out[:, 3].copy()
        params = dict(kind=kind, **tilt)
    elif kind == "clock_offset":
        shift = float(rng.uniform(0.05, 0.3))
        k0, s = int(t0 / DT), int(round(shift / DT))
        accel[k0 + s:] = base[k0:len(base) - s, 3]
        params = dict(kind=kind, t0_s=t0, offset_s=shift)
    elif kind == "gain":
        g = float(rng.choice([rng.uniform(1.3, 1.6), rng.uniform(0.5, 0.75)]))
        k0 = int(t0 / DT)
        accel[k0:] *= g
        params = dict(kind=kind, t0_s=t0, gain=g)
    elif kind == "accel_bias":
        bias = float(rng.uniform(0.1, 0.5)) * float(rng.choice([-1, 1]))
        accel[int(t0 / DT):] += bias
        params = dict(kind=kind, t0_s=t0, bias_mps2=bias)
    elif kind == "yaw_jump":
        # The camera re-identifies the platform's markers: its yaw jumps and stays off.
        jump = float(rng.uniform(0.01, 0.05)) * float(rng.choice([-1, 1]))
        out[int(t0 / DT):, 2] += jump
        params = dict(kind=kind, t0_s=t0, jump_rad=jump)
    else:
        drift = float(rng.uniform(0.02, 0.08)) * float(rng.choice([-1, 1]))
        ramp = float(rng.uniform(0.5, 2.0))
        t = np.arange(len(base)) * DT
        ramp_v = np.clip((t - t0) / ramp, 0, 1) * drift
        out[:, int(rng.integers(2))] += ramp_v
        params = dict(kind=kind, t0_s=t0, drift_m=drift, ramp_s=ramp)
    return params, out, accel


def write_csv(path, header, cols, fmt):
    with open(path, "w") as f:
        f.write(",".join(header) + "\n")
        for row in zip(*cols):
            f.write(",".join("nan" if not np.isfinite(v) else format(v, fm) for v, fm in zip(row, fmt)) + "\n")


def make_case(job):
    case_id, effect, seed, out_dir = job
    rng = np.random.default_rng(seed)
    records = floors.load_records(Path(os.environ["MOTIONS_DIR"]))
    buildings = {k: floors.make_building(k) for k in ("fixed", "isolated")}
    started = time.time()
    for attempt in range(40):
        name, unit = draw_unit(rng)
        ax, ay, floor_info = draw_floor(rng, records, buildings)
        base, st = cart.simulate(unit, ax, ay, DT)
        if st["failed"] or np.nanmax(np.hypot(base[:, 0], base[:, 1])) < 0.05:
            continue
        sd_m, sd_rad = float(rng.uniform(0.001, 0.002)), float(rng.uniform(0.0015, 0.0025))
        twin, _ = cart.simulate(unit, ax, ay, DT, yaw0_perturbation=1e-6)
        if parting(base, twin, sd_m, sd_rad, 0.25) is not None:
            continue
        accel = base[:, 3].copy()
        params, onset = {}, None
        truth_out = base
        if effect in ("lateral_impact", "mass_change", "caster_brake", "swivel_jam"):
            got = conceal(rng, effect, unit, ax, ay, base)
            if got is None:
                continue
            params, truth_out = got
            accel = truth_out[:, 3].copy()
            onset = params.get("t0_s")
            if effect == "lateral_impact":
                # The first contact: where the rigid run first departs from the baseline.
                dev = np.flatnonzero(np.abs(truth_out[:, 3] - base[:, 3]) > 1e-6)
                onset = round(float(dev[0] * DT), 3) if len(dev) else None
            # The truth must be predictable too.
            twin_t, _ = cart.simulate(unit, ax, ay, DT, params, yaw0_perturbation=1e-6)
            if parting(truth_out, twin_t, sd_m, sd_rad, 0.25) is not None:
                continue
        elif effect == "unexplained":
            got = unexplained(rng, unit, ax, ay, base)
            if got is None:
                continue
            params, truth_out, accel = got
            onset = params["t0_s"]
        window = None
        if effect != "none":
            window = visible_from(truth_out, base, sd_m, sd_rad, accel, base[:, 3])
            if window is None:
                continue
        break
    else:
        raise RuntimeError(f"{case_id}: no acceptable draw in 40 attempts")
    # Observations.
    n = len(ax)
    t = np.arange(n) * DT
    tc = np.arange(0.0, t[-1] + 1e-9, 1.0 / CAMERA_HZ)
    cam = np.stack([np.interp(tc, t, truth_out[:, i]) for i in range(3)], axis=1)
    cam[:, :2] += rng.normal(0, sd_m, (len(tc), 2))
    cam[:, 2] += rng.normal(0, sd_rad, len(tc))
    lost = np.zeros(len(tc), bool)
    while lost.mean() < rng.uniform(0.03, 0.08):
        k = int(rng.integers(len(tc)))
        lost[k:k + int(rng.integers(2, 13))] = True
    cam[lost] = np.nan
    acc_obs = accel + rng.normal(0, 0.02, n)
    d = Path(out_dir) / case_id
    d.mkdir(parents=True, exist_ok=True)
    equipment = {"model": "rolling", "name": name, "description": f"{name} on 4 swivel casters (prove/rolling)"}
    equipment.update({k: unit[k] for k in ["length_m", "width_m", "platform_mass_kg", "wheel_diameter_m",
                                           "wheel_width_m", "wheel_mass_kg", "yaw0_deg", "steer0_deg", "mu_s_roll",
                                           "mu_s_swivel", "mu_k_roll", "mu_k_swivel", "beta_spm", "gamma_n", "p",
                                           "trail_m", "swivel_arm_m", "friction_eps", "friction_eps_swivel"]})
    equipment["g_mps2"] = 9.80665
    equipment["sensors"] = {"camera": {"file": "observed_cpt.csv", "rate_hz": CAMERA_HZ, "noise_sd_m": round(sd_m, 5),
                                       "noise_sd_rad": round(sd_rad, 5)},
                            "accelerometer": {"file": "observed_accel.csv", "rate_hz": FS, "noise_sd_mps2": 0.02}}
    equipment["conventions"] = {"frame": "as ../shared/cases/rolling_demo (floor-attached, non-rotating)"}
    (d / "equipment.yaml").write_text(yaml.safe_dump(equipment, sort_keys=False))
    write_csv(d / "floor.csv", ["time_s", "ax_mps2", "ay_mps2"], [t, ax, ay], [".3f", ".7g", ".7g"])
    write_csv(d / "observed_cpt.csv", ["time_s", "x_m", "y_m", "yaw_rad"], [tc, cam[:, 0], cam[:, 1], cam[:, 2]],
              [".6f", ".6f", ".6f", ".6f"])
    write_csv(d / "observed_accel.csv", ["time_s", "top_ax_mps2"], [t, acc_obs], [".3f", ".5f"])
    expected = effect
    truth = {"case_id": case_id, "effect": effect, "expected_verdict": expected, "mismatch": effect != "none",
             "onset_s": onset, "parameters": {k: (v if not isinstance(v, np.generic) else v.item()) for k, v in params.items()},
             "window": None if window is None else {"start_s": window[0], "end_s": window[1]},
             "unit": name, "floor": floor_info, "attempts": attempt + 1, "seconds": round(time.time() - started, 1)}
    tdir = Path(out_dir) / "truth"
    tdir.mkdir(exist_ok=True)
    truth = json.loads(json.dumps(truth, default=lambda v: v.item() if isinstance(v, np.generic) else str(v)))
    (tdir / f"{case_id}.yaml").write_text(yaml.safe_dump(truth, sort_keys=False))
    return case_id, effect


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--per-effect", type=int, default=4)
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--motions", default=str(HERE.parent.parent.parent / "shared" / "data" / "ground_motions"))
    args = ap.parse_args()
    seed = args.seed if args.seed is not None else int(np.random.SeedSequence().entropy % 2**31)
    print(f"seed {seed}", flush=True)
    os.environ["MOTIONS_DIR"] = args.motions
    rng = np.random.default_rng(seed)
    effects = [e for e in EFFECTS for _ in range(args.per_effect)]
    order = rng.permutation(len(effects))
    jobs = [(f"case_{i:02d}", effects[j], int(rng.integers(2**31)), args.out) for i, j in enumerate(order)]
    Path(args.out).mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(args.jobs) as pool:
        for case_id, effect in pool.map(make_case, jobs):
            print(f"{case_id}", flush=True)
    manifest = {"generator": "prove/rolling/generate.py", "seed": seed, "per_effect": args.per_effect,
                "cases": {j[0]: j[1] for j in jobs}}
    (Path(args.out) / "truth" / "manifest.yaml").write_text(yaml.safe_dump(manifest, sort_keys=False))


if __name__ == "__main__":
    main()
