#!/usr/bin/env python3
"""Self-check of the proof generator's baseline physics.

    python prove/check_generator.py [--seed 3] [--shared DIR]

1. Generates a `none` and a `sensor_tilt` case with a known seed and runs the repository's
   independent scipy peer (tests/reference/rocking_scipy.py) on their floor.csv: the generator's
   baseline theta (truth/<case>_baseline_theta.csv) must agree within 1e-3 rad before any overturn
   (outside solver-sensitive samples) and overturn within 0.01 s of it. The observation noise is
   checked too (accelerometer 0.02 m/s^2, camera 0.002 rad).
2. Runs the generator's baseline on the four demo cases (../shared/cases/demo) and compares it with
   their truth/<case>_baseline_theta.csv, with the same tolerances.
3. Runs the generator's coupled sliding formulation (prove/sliding.py) on the floors of
   tests/reference/sliding_scipy.py and compares it with that peer's stored values: the same events,
   theta within 1e-5 rad and the slip within 1e-6 m.
Exits non-zero if a check fails.
"""
from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from generate_cases import REPO, shared_dir  # noqa: E402
from rocking import OUT_PER_SAMPLE, Block, Floor, kinematics, simulate  # noqa: E402

THETA_TOL = 1e-3          # rad, before any overturn, outside solver-sensitive samples
OVERTURN_TOL = 0.01       # s


def load_reference():
    path = REPO / "tests" / "reference" / "rocking_scipy.py"
    spec = importlib.util.spec_from_file_location("rocking_scipy", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def read_csv(path: Path) -> np.ndarray:
    return np.genfromtxt(path, delimiter=",", names=True)


def compare(label: str, t: np.ndarray, theta: np.ndarray, over: float | None, ref_theta: np.ndarray,
            ref_over: float | None, sensitive: np.ndarray) -> bool:
    """theta against a reference before the first overturn, outside solver-sensitive samples."""
    first = min(x for x in (over, ref_over, np.inf) if x is not None)
    mask = (t < first) & ~sensitive
    dtheta = float(np.abs(theta - ref_theta)[mask].max())
    same_over = (over is None and ref_over is None) or (
        over is not None and ref_over is not None and abs(over - ref_over) < OVERTURN_TOL)
    d_over = "-" if over is None or ref_over is None else f"{abs(over - ref_over) * 1e3:.3f} ms"
    ok = dtheta < THETA_TOL and same_over
    print(f"  {label:<28} max|dtheta| {dtheta:.2e} rad   overturn {fmt(over)} vs {fmt(ref_over)} "
          f"(diff {d_over})   sensitive {sensitive.mean() * 100:.2f} %   {'ok' if ok else 'FAIL'}")
    return ok


def fmt(x):
    return "none" if x is None else f"{x:.4f} s"


def check_generated(seed: int, shared: Path, ref) -> bool:
    ok = True
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "cases"
        subprocess.run([sys.executable, str(HERE / "generate_cases.py"), str(out), "--seed", str(seed),
                        "--per-effect", "1", "--effects", "none,sensor_tilt", "--jobs", "2",
                        "--shared", str(shared)], check=True, stdout=subprocess.DEVNULL)
        for truth_file in sorted((out / "truth").glob("case_*.yaml")):
            case = truth_file.stem
            truth = yaml.safe_load(truth_file.read_text())
            eq = yaml.safe_load((out / case / "equipment.yaml").read_text())
            floor = read_csv(out / case / "floor.csv")
            base = read_csv(out / "truth" / f"{case}_baseline_theta.csv")
            block = ref.Block(eq["B_m"], eq["H_m"], eq["f"])
            ref_theta, events = ref.simulate(block, floor["time_s"], floor["ax_mps2"], floor["az_mps2"], rtol=1e-10)
            ref_over = next((e[1] for e in events if e[0] == "overturn"), None)
            ok &= compare(f"{case} ({truth['effect']}) vs scipy peer", base["time_s"], base["theta_rad"],
                          truth["baseline"]["overturn_time_s"], ref_theta, ref_over, base["solver_sensitive"] == 1)
            ok &= check_noise(out / case, base, truth)
    return ok


def check_noise(case_dir: Path, base: np.ndarray, truth: dict) -> bool:
    """Observed minus the noise-free signal: the stated noise levels (a `none` case only, where the
    baseline is the truth; the camera also for sensor_tilt, whose dynamics are the baseline's)."""
    cam = read_csv(case_dir / "observed_cpt.csv")
    theta_true = np.interp(cam["time_s"], base["time_s"], base["theta_rad"])
    valid = ~np.isnan(cam["theta_rad"])
    sd_cam = float(np.std(cam["theta_rad"][valid] - theta_true[valid]))
    ok = abs(sd_cam - 0.002) < 0.0004
    line = f"    noise: camera sd {sd_cam:.5f} rad (0.002)"
    if truth["effect"] == "none":
        acc = read_csv(case_dir / "observed_accel.csv")
        quiet = np.ones(len(acc), bool)
        if truth["overturned"]:   # leave out the landing spike
            quiet &= np.abs(acc["time_s"] - truth["overturn_time_s"] - 0.1) > 0.11
        sd_acc = float(np.std((acc["top_ax_mps2"] - base["top_ax_mps2"])[quiet]))
        ok &= abs(sd_acc - 0.02) < 0.002
        line += f", accelerometer sd {sd_acc:.4f} m/s^2 (0.02)"
    print(line + f"   {'ok' if ok else 'FAIL'}")
    return ok


def check_demo(shared: Path) -> bool:
    demo = shared / "cases" / "demo"
    if not demo.is_dir():
        sys.exit(f"error: demo cases not found at {demo} (they come with the shared folder)")
    ok = True
    for case_dir in sorted(p for p in demo.iterdir() if (p / "equipment.yaml").exists()):
        case = case_dir.name
        eq = yaml.safe_load((case_dir / "equipment.yaml").read_text())
        floor_csv = read_csv(case_dir / "floor.csv")
        base = read_csv(demo / "truth" / f"{case}_baseline_theta.csv")
        truth = yaml.safe_load((demo / "truth" / f"{case}.yaml").read_text())
        dt = float(np.median(np.diff(floor_csv["time_s"])))
        floor = Floor(dt, floor_csv["ax_mps2"], floor_csv["az_mps2"])
        resp = simulate(Block(eq["B_m"], eq["H_m"], eq["f"], eq["mass_kg"], eq["g_mps2"]), floor)
        kin = kinematics(resp, floor)
        over = resp.overturn
        sensitive = base["solver_sensitive"] == 1
        ok &= compare(f"{case} vs demo truth", base["time_s"], kin.theta, None if over is None else over[0],
                      base["theta_rad"], truth["baseline"]["overturn_time_s"], sensitive)
        before = base["time_s"] < (truth["baseline"]["overturn_time_s"] or np.inf)
        print(f"    top_ax max|diff| {np.abs(kin.top_ax - base['top_ax_mps2'])[~sensitive].max():.2e} m/s^2, "
              f"impacts {resp.count('impact')} vs {truth['baseline']['n_impacts']}, "
              f"first uplift {resp.first('uplift'):.4f} vs {truth['baseline']['first_uplift_s']:.4f} s, "
              f"{before.sum()} samples before the overturn")
    return ok


def check_sliding() -> bool:
    from sliding import simulate_sliding
    path = REPO / "tests" / "reference" / "sliding_scipy.py"
    spec = importlib.util.spec_from_file_location("sliding_scipy", path)
    peer = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(peer)
    stored = yaml.safe_load((REPO / "tests" / "reference" / "sliding_scipy.json").read_text())
    ok = True
    for case in stored["cases"]:
        dt, every = stored["dt_s"], stored["every"]
        ax = peer.floor(case["floor"], case["samples"])
        floor = Floor(dt, ax, np.zeros_like(ax))
        block = Block(case["B_m"], case["H_m"], case["f"], 100.0, stored["g_mps2"])
        resp, _, slip = simulate_sliding(block, floor, case["static_mu"], case["kinetic_mu"])
        theta = resp.theta[::OUT_PER_SAMPLE][::every]
        kinds = [e[0] for e in resp.events] == [e["kind"] for e in case["events"]]
        dt_ev = max((abs(a[1] - b["time_s"]) for a, b in zip(resp.events, case["events"])), default=0.0)
        dth = float(np.abs(theta - np.array(case["theta_rad"])).max())
        du = float(np.abs(slip[::every] - np.array(case["slip_m"])).max())
        good = kinds and dt_ev < 1e-5 and dth < 1e-5 and du < 1e-6
        ok &= good
        print(f"  {case['name']:<22} events {'same' if kinds else 'DIFFER'} (max dt {dt_ev:.1e} s), "
              f"max|dtheta| {dth:.1e} rad, max|dslip| {du:.1e} m   {'ok' if good else 'FAIL'}")
    return ok


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--shared", help="the shared data folder (default: ../shared next to the repository)")
    args = ap.parse_args()
    shared = shared_dir(args.shared)
    ref = load_reference()
    print(f"1. generated cases (seed {args.seed}) against tests/reference/rocking_scipy.py")
    ok = check_generated(args.seed, shared, ref)
    print("2. the generator's baseline on the demo cases against their truth")
    ok &= check_demo(shared)
    print("3. the coupled sliding formulation against tests/reference/sliding_scipy.py")
    ok &= check_sliding()
    print("all checks passed" if ok else "SOME CHECKS FAILED")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
