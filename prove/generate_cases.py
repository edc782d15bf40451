#!/usr/bin/env python3
"""Generate concealed-effect cases for `shakeflow diagnose`, independently of shakeflow.

    python prove/generate_cases.py OUT_DIR [--seed N] [--per-effect 5] [--effects none,sliding,...]
                                   [--jobs 2] [--shared DIR]

Each case is a rocking block on a building floor (a real record window through a 5-storey shear
building) with one concealed effect; OUT_DIR/<case>/ holds what the instruments saw (the same
files, columns, rates and noise as ../shared/cases/demo) and OUT_DIR/truth/ what was concealed.
The same seed gives the same cases; without --seed a new one is drawn and printed.
"""
from __future__ import annotations

import argparse
import csv
import math
import multiprocessing
import os
import secrets
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from effects import CONCEAL, VERDICTS, Concealed, Setting  # noqa: E402
from floors import FS, G, load_records, make_building, make_floor  # noqa: E402
from rocking import OUT_PER_SAMPLE, Block, Floor, Options, Response, kinematics, simulate  # noqa: E402

GENERATOR = "shakeflow-prove 1.0"
REPO = Path(__file__).resolve().parents[1]
CAMERA_HZ = 30.0
ACCEL_NOISE = 0.02          # m/s^2
CAMERA_NOISE = 0.002        # rad
THETA_TOL, ACCEL_TOL = 0.01, 0.1            # a visible difference (window definition)
WINDOW_S, WINDOW_COUNT = 0.1, 5
SENSITIVE_THETA, SENSITIVE_ACCEL = 0.005, 0.1
MAX_SENSITIVE_FRACTION = 0.02   # a baseline more fragile than this is not a fair reference
MIN_ROCKING_RAD = 0.02     # the baseline must rock visibly (a fair test, also for `none`)
MAX_TRIES = 40
EFFECT_DRAWS_PER_FLOOR = 3
WINDOW_DEFINITION = ("first..last time at which the noise-free observations differ from the baseline model's "
                     "prediction by > 0.01 rad (theta) or > 0.1 m/s^2 (top accel), counting samples with >= 5 "
                     "such exceedances within 0.1 s (both compared at 200 Hz; the overturn spike excluded)")
SENSITIVE_NOTE = ("samples where the baseline top acceleration (or theta) changes by > 0.1 m/s^2 (> 0.005 rad) "
                  "under other solver settings (RK45, rtol 1e-8, rest amplitude 1e-5: micro-rocking impact chatter); "
                  "column solver_sensitive in the baseline csv")
STUDY_UNITS = {  # name: (description, B, H, f, mass)
    "PS2": ("stretcher", 0.349, 1.082, 0.085, 150.0),
    "PB1": ("patient bed", 0.705, 1.5, 0.0526, 259.0),
    "WSU1": ("wire shelving unit", 0.66, 1.88, 0.0, 43.6),
}


# -- setting up a case -----------------------------------------------------------------------------
def draw_equipment(rng: np.random.Generator) -> tuple[str, str, Block]:
    """A unit of the study (40 %) or a random rectangle; stocky rectangles (alpha > 0.42 rad, which
    would need floors above ~0.9 g to rock) are redrawn."""
    if rng.random() < 0.4:
        name = list(STUDY_UNITS)[rng.integers(len(STUDY_UNITS))]
        desc, B, H, f, m = STUDY_UNITS[name]
        return name, desc, Block(B, H, f, m)
    while True:
        block = Block(round(rng.uniform(0.3, 0.8), 3), round(rng.uniform(1.0, 2.2), 3),
                      round(rng.uniform(-0.05, 0.1), 4), round(rng.uniform(30.0, 300.0), 1))
        if block.alpha <= 0.42:
            return f"GEN-{rng.integers(100, 1000)}", "generic rigid block", block


def same_outcome(a: Response, b: Response) -> bool:
    oa, ob = a.overturn, b.overturn
    if oa is None or ob is None:
        return oa is None and ob is None
    return oa[1] == ob[1] and abs(oa[0] - ob[0]) < 0.01


def solver_sensitivity(block: Block, floor: Floor, base: Response) -> tuple[Response, np.ndarray]:
    """The baseline again under other settings (Dormand-Prince 5(4) as shakeflow's own solver, a looser
    tolerance and rest criterion); samples where the two differ visibly."""
    alt = simulate(block, floor, Options(rtol=1e-8, rest_amplitude=1e-5, method="RK45"))
    k_base, k_alt = kinematics(base, floor), kinematics(alt, floor)
    sensitive = ((np.abs(k_base.theta - k_alt.theta) > SENSITIVE_THETA)
                 | (np.abs(k_base.top_ax - k_alt.top_ax) > SENSITIVE_ACCEL))
    return alt, sensitive


@dataclass
class Divergence:
    flags: np.ndarray        # divergent samples (200 Hz)
    dtheta: np.ndarray
    daccel: np.ndarray

    def window(self, t: np.ndarray) -> dict | None:
        if not self.flags.any():
            return None
        idx = np.flatnonzero(self.flags)
        return {"start_s": float(t[idx[0]]), "end_s": float(t[idx[-1]])}


def divergence(theta_obs: np.ndarray, accel_obs: np.ndarray, theta_base: np.ndarray,
               accel_base: np.ndarray) -> Divergence:
    """Samples that differ visibly from the baseline, in clusters of >= 5 within 0.1 s."""
    dtheta, daccel = np.abs(theta_obs - theta_base), np.abs(accel_obs - accel_base)
    exceed = (dtheta > THETA_TOL) | (daccel > ACCEL_TOL)
    half = int(round(WINDOW_S * FS / 2))
    counts = np.convolve(exceed.astype(int), np.ones(2 * half + 1, dtype=int), mode="same")
    return Divergence(exceed & (counts >= WINDOW_COUNT), dtheta, daccel)


@dataclass
class Case:
    name: str
    desc: str
    block: Block
    floor_record: object
    floor: Floor
    base: Response
    base_kin: object
    sensitive: np.ndarray
    alt: Response
    concealed: Concealed
    theta_obs: np.ndarray    # noise-free camera angle on the 600 Hz grid
    accel_obs: np.ndarray    # noise-free accelerometer at 200 Hz, sensor faults applied, no spike
    div: Divergence
    target: str
    tries: int


def build_case(rng: np.random.Generator, effect: str, records, buildings) -> Case:
    """Draw equipment, then floors and effect parameters until the case is fair: the baseline
    rocks and is numerically robust, and the effect (if any) shows in the observations."""
    name, desc, block = draw_equipment(rng)
    threshold = G * math.tan(block.alpha)
    target = str(rng.choice(["overturn", "no_overturn"]))
    ratio_hi = 2.5
    for tries in range(1, MAX_TRIES + 1):
        record = make_floor(rng, records, buildings, threshold, rng.uniform(1.2, ratio_hi))
        floor = Floor(1.0 / FS, record.ax, record.az)
        try:
            base = simulate(block, floor)
            if np.abs(base.theta).max() < MIN_ROCKING_RAD:
                continue
            # Steer toward the drawn outcome for the first tries (most floors at these ratios overturn).
            if tries <= 8 and (base.overturn is not None) != (target == "overturn"):
                if target == "no_overturn":
                    ratio_hi = max(1.3, 0.85 * ratio_hi)
                continue
            found = conceal_on_floor(rng, effect, block, floor, base)
        except RuntimeError:      # impact chatter that did not settle: not a floor to test on
            continue
        if found is not None:
            return Case(name, desc, block, record, floor, base, *found, target, tries)
    raise RuntimeError(f"no fair {effect} case in {MAX_TRIES} tries")


def conceal_on_floor(rng: np.random.Generator, effect: str, block: Block, floor: Floor, base: Response):
    """The effect on this floor, if the baseline is a robust reference and the effect shows."""
    alt, sensitive = solver_sensitivity(block, floor, base)
    if not same_outcome(base, alt) or sensitive.mean() > MAX_SENSITIVE_FRACTION:
        return None
    base_kin = kinematics(base, floor)
    for _ in range(EFFECT_DRAWS_PER_FLOOR):
        concealed = CONCEAL[effect](Setting(rng, block, floor, base))
        if concealed is None:
            return None
        theta_obs = concealed.response.theta
        if concealed.camera_fault:
            theta_obs = concealed.camera_fault(concealed.response.t_out, theta_obs)
        accel_obs = concealed.reading()
        if concealed.accel_fault:
            accel_obs = concealed.accel_fault(accel_obs)
        div = divergence(theta_obs[::OUT_PER_SAMPLE], accel_obs, base_kin.theta, base_kin.top_ax)
        robust = div.flags & ~sensitive
        if effect == "none" or robust.sum() >= WINDOW_COUNT:
            return base_kin, sensitive, alt, concealed, theta_obs, accel_obs, div
    return None


# -- observations ----------------------------------------------------------------------------------
def overturn_spike(rng: np.random.Generator, t: np.ndarray, t_over: float) -> tuple[np.ndarray, dict]:
    """The impact of the block landing on its side: a damped cosine from the overturn time."""
    amp_g, freq, decay = rng.uniform(4.0, 7.0), rng.uniform(25.0, 35.0), 0.012
    tau = t - t_over
    spike = np.where(tau >= 0, amp_g * G * np.cos(2 * np.pi * freq * tau) * np.exp(-np.clip(tau, 0, None) / decay), 0.0)
    return spike, {"amplitude_g": amp_g, "freq_hz": freq, "decay_ms": decay * 1e3}


def camera_dropouts(rng: np.random.Generator, t_cam: np.ndarray) -> tuple[np.ndarray, list, list]:
    """1-2 intervals of 0.3-1.5 s without angle, plus a few single lost frames."""
    lost = np.zeros(len(t_cam), bool)
    intervals = []
    for _ in range(rng.integers(1, 3)):
        length = rng.uniform(0.3, 1.5)
        start = rng.uniform(0.0, t_cam[-1] - length)
        lost |= (t_cam >= start) & (t_cam <= start + length)
        intervals.append([start, start + length])
    singles = sorted(rng.choice(len(t_cam), size=rng.integers(0, 7), replace=False).tolist())
    lost[singles] = True
    return lost, intervals, [float(t_cam[i]) for i in singles]


# -- writing ---------------------------------------------------------------------------------------
def plain(x, digits: int = 6):
    """YAML-friendly: numpy scalars to Python, floats to `digits` significant figures."""
    if isinstance(x, dict):
        return {k: plain(v, digits) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain(v, digits) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(f"{float(x):.{digits}g}") if math.isfinite(x) else None
    return x


def write_csv(path: Path, header: list[str], columns: list[np.ndarray], formats: list[str]):
    rows = zip(*columns)
    with open(path, "w") as fh:
        fh.write(",".join(header) + "\n")
        for row in rows:
            fh.write(",".join("NaN" if (isinstance(v, float) and math.isnan(v)) else fmt % v
                              for v, fmt in zip(row, formats)) + "\n")


def equipment_yaml(name: str, desc: str, block: Block) -> dict:
    d = block.describe()
    return plain({
        "name": name, "description": desc, "shape": "rectangular",
        "B_m": block.B, "H_m": block.H, "f": block.f, "mass_kg": block.mass, "e_formula": d["e_formula"],
        "derived": {"hc_m": d["hc_m"], "alpha_rad": d["alpha_rad"], "R_m": d["R_m"], "I0_kgm2": d["I0_kgm2"],
                    "p_radps": d["p_radps"]},
        "g_mps2": G,
        "sensors": {
            "accelerometer": {"file": "observed_accel.csv", "position": "top centre (x=0, height H)",
                              "quantity": "horizontal in-plane acceleration, m/s^2", "rate_hz": 200,
                              "noise_sd_mps2": ACCEL_NOISE},
            "camera": {"file": "observed_cpt.csv", "quantity": "rotation theta, rad", "rate_hz": CAMERA_HZ,
                       "noise_sd_rad": CAMERA_NOISE, "dropouts": "NaN rows"},
        },
        "conventions": "x in-plane horizontal (floor.csv ax), z vertical up (az); theta>0 = rotation about the "
                       "+x corner, top moving toward +x",
    })


def write_case(out: Path, case_id: str, effect: str, case: Case, rng: np.random.Generator, seed: dict) -> dict:
    t = case.floor.t
    con = case.concealed
    truth_out = con.response.outcome()
    base_out = case.base.outcome()
    # Accelerometer: the reading (+ the landing spike), the sensor's own fault, then noise.
    spike, spike_info = np.zeros_like(t), None
    if truth_out["overturned"]:
        spike, spike_info = overturn_spike(rng, t, truth_out["overturn_time_s"])
    clean = con.reading() + spike
    if con.accel_fault:
        clean = con.accel_fault(clean)
    accel = clean + rng.normal(0.0, ACCEL_NOISE, len(t))
    # Camera: the angle at 30 Hz (exact output points of the simulation) + noise, with dropouts.
    n_cam = int(math.floor(t[-1] * CAMERA_HZ + 1e-9)) + 1
    step = int(round(FS * OUT_PER_SAMPLE / CAMERA_HZ))
    t_cam = np.arange(n_cam) / CAMERA_HZ
    theta_cam = case.theta_obs[::step][:n_cam] + rng.normal(0.0, CAMERA_NOISE, n_cam)
    lost, intervals, singles = camera_dropouts(rng, t_cam)
    theta_cam[lost] = np.nan

    case_dir = out / case_id
    case_dir.mkdir(parents=True)
    (case_dir / "equipment.yaml").write_text(yaml.safe_dump(equipment_yaml(case.name, case.desc, case.block),
                                                            sort_keys=False, width=110))
    rec = case.floor_record
    write_csv(case_dir / "floor.csv", ["time_s", "ax_mps2", "ay_mps2", "az_mps2"], [t, rec.ax, rec.ay, rec.az],
              ["%.3f", "%.6f", "%.6f", "%.6f"])
    write_csv(case_dir / "observed_accel.csv", ["time_s", "top_ax_mps2"], [t, accel], ["%.3f", "%.5f"])
    write_csv(case_dir / "observed_cpt.csv", ["time_s", "theta_rad"], [t_cam, theta_cam], ["%.4f", "%.6f"])

    window = case.div.window(t) if effect != "none" else None
    onset = con.onset_s if con.onset_s is not None or window is None else window["start_s"]
    divergent = case.div.flags
    sens = case.sensitive
    sens_idx = np.flatnonzero(sens)
    sens_intervals = []
    if len(sens_idx):
        breaks = np.flatnonzero(np.diff(sens_idx) > 1)
        for a, b in zip(np.r_[sens_idx[0], sens_idx[breaks + 1]], np.r_[sens_idx[breaks], sens_idx[-1]]):
            sens_intervals.append([float(t[a]), float(t[b])])
    numcheck = float(np.abs(case.base_kin.theta - kinematics(case.alt, case.floor).theta).max())
    truth = {
        "case_id": case_id,
        "effect": effect,
        "expected_verdict": effect,
        "mismatch": effect != "none",
        "parameters": con.parameters,
        "onset_s": onset,
        "onset_definition": con.onset_definition,
        "window": window,
        "window_definition": WINDOW_DEFINITION,
        "detectable": bool(divergent.any()),
        "divergence": None if window is None else {
            **window, "duration_s": float(divergent.sum() / FS),
            "robust_samples": int((divergent & ~sens).sum()),
            "max_dtheta_rad": float(case.div.dtheta.max()), "max_daccel_mps2": float(case.div.daccel.max())},
        "overturned": truth_out["overturned"],
        "overturn_time_s": truth_out["overturn_time_s"],
        "overturn_side": truth_out["overturn_side"],
        "overturn_spike": spike_info,
        "truth_response": {k: truth_out[k] for k in ("max_abs_theta_rad", "n_uplifts", "n_impacts", "first_uplift_s")},
        "setup_tries": case.tries,
        "baseline": {
            **{k: base_out[k] for k in ("overturned", "overturn_time_s", "overturn_side", "max_abs_theta_rad",
                                        "first_uplift_s", "n_impacts")},
            "numcheck_max_dtheta_rad": numcheck,
            "numcheck_same_outcome": same_outcome(case.base, case.alt),
            "solver_sensitive_fraction": float(sens.mean()),
            "solver_sensitive_intervals_s": sens_intervals,
            "solver_sensitive_note": SENSITIVE_NOTE,
        },
        "floor": {**rec.info, "target_outcome_drawn": case.target},
        "equipment": {**case.block.describe(), "e_used": con.parameters.get("e", case.block.e_eq24)},
        "camera_dropouts_s": intervals,
        "camera_single_frame_dropouts_s": singles,
        "seed": seed,
        "generator": GENERATOR,
    }
    truth_dir = out / "truth"
    (truth_dir / f"{case_id}.yaml").write_text(yaml.safe_dump(plain(truth), sort_keys=False, width=110))
    bk = case.base_kin
    write_csv(truth_dir / f"{case_id}_baseline_theta.csv",
              ["time_s", "theta_rad", "theta_dot_radps", "top_ax_mps2", "solver_sensitive"],
              [t, bk.theta, bk.theta_dot, bk.top_ax, sens.astype(int)], ["%.3f", "%.7f", "%.7f", "%.5f", "%d"])
    return plain({
        "case_id": case_id, "effect": effect, "expected_verdict": effect, "equipment": case.name,
        "alpha": case.block.alpha, "building": rec.info["building"], "floor": rec.info["floor"],
        "pfa_g": rec.info["pfa_g"], "ratio": rec.info["pfa_over_uplift_threshold"],
        "base_max_theta": base_out["max_abs_theta_rad"], "base_overturn": base_out["overturn_time_s"],
        "max_theta": truth_out["max_abs_theta_rad"], "overturn": truth_out["overturn_time_s"],
        "onset": onset, "win_start": None if window is None else window["start_s"],
        "win_end": None if window is None else window["end_s"], "detectable": truth["detectable"],
        "numcheck": numcheck, "fragile": float(sens.mean()), "tries": case.tries,
    }, 4)


# -- driver ----------------------------------------------------------------------------------------
_WORKER: dict = {}


def _init_worker(motions_dir: str):
    _WORKER["records"] = load_records(Path(motions_dir))
    _WORKER["buildings"] = {k: make_building(k) for k in ("fixed", "isolated")}


def _make_case(job: tuple) -> tuple[dict, float]:
    out, case_id, effect, seed, index = job
    started = time.perf_counter()
    rng = np.random.default_rng([seed, VERDICTS.index(effect), index])
    case = build_case(rng, effect, _WORKER["records"], _WORKER["buildings"])
    row = write_case(Path(out), case_id, effect, case, rng,
                     {"seed": seed, "effect_index": VERDICTS.index(effect), "index": index})
    return row, time.perf_counter() - started


def shared_dir(arg: str | None) -> Path:
    path = Path(arg or os.environ.get("SHAKEFLOW_SHARED") or REPO.parent / "shared")
    motions = path / "data" / "ground_motions"
    if not motions.is_dir():
        sys.exit(f"error: ground motions not found at {motions}\n"
                 f"  The generator reads real records from the shared data folder (../shared next to the "
                 f"repository). Pass --shared DIR or set SHAKEFLOW_SHARED to the folder that holds "
                 f"data/ground_motions.")
    return path


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--seed", type=int, help="reproduce a set (default: a new random seed, printed)")
    ap.add_argument("--per-effect", type=int, default=5)
    ap.add_argument("--effects", default=",".join(VERDICTS), help="comma-separated subset of " + ",".join(VERDICTS))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--shared", help="the shared data folder (default: ../shared next to the repository)")
    args = ap.parse_args()
    effects = [e.strip() for e in args.effects.split(",") if e.strip()]
    unknown = [e for e in effects if e not in VERDICTS]
    if unknown:
        sys.exit(f"error: unknown effect(s) {unknown}; choose among {', '.join(VERDICTS)}")
    if args.out_dir.exists() and any(args.out_dir.iterdir()):
        sys.exit(f"error: {args.out_dir} is not empty; remove it or choose another folder")
    motions = shared_dir(args.shared) / "data" / "ground_motions"
    seed = args.seed if args.seed is not None else secrets.randbelow(2 ** 31)
    print(f"seed {seed} (rerun with --seed {seed})", flush=True)

    # Case names are shuffled so that neither the name nor the order tells the effect.
    plan = [(e, i) for e in effects for i in range(args.per_effect)]
    order = np.random.default_rng([seed, 999]).permutation(len(plan))
    width = max(2, len(str(len(plan))))
    jobs = [(str(args.out_dir), f"case_{n + 1:0{width}d}", *plan[k][:1], seed, plan[k][1])
            for n, k in enumerate(order)]
    (args.out_dir / "truth").mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    rows = []
    with multiprocessing.Pool(max(1, args.jobs), initializer=_init_worker, initargs=(str(motions),)) as pool:
        for row, seconds in pool.imap_unordered(_make_case, jobs):
            rows.append(row)
            print(f"  {row['case_id']}  {seconds:5.1f} s  tries {row['tries']}", flush=True)
    rows.sort(key=lambda r: r["case_id"])
    with open(args.out_dir / "truth" / "summary.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    elapsed = time.perf_counter() - started
    print(f"{len(rows)} cases in {elapsed:.0f} s ({elapsed / len(rows):.1f} s/case on {args.jobs} processes) "
          f"-> {args.out_dir}")


if __name__ == "__main__":
    main()
