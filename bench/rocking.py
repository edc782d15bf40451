"""`make bench`: the rocking model, shakeflow vs scipy's solve_ivp and vs RK4 at the study's step.

1. One 60 s record at 200 Hz (Chi-Chi TCU078-E × 0.9, first 60 s) on the PS2 block (Table 5
   rectangle): `shakeflow stage simulate_toppling` as a user runs it (process start, CSV load,
   simulation, Parquet + MCAP + PNG written), the same with `method: rk4` (dt = 1e-4 s), and the
   scipy peer tests/reference/rocking_scipy.py (DOP853 with events, rtol 1e-10; its time counts the
   simulation only). Accuracy: max |Δθ| of each against RK4.
2. A fragility sweep: 10 records of 30 s (real records, first 30 s) × 100 intensity levels = 1000
   runs through `shakeflow stage toppling_fragility`, vs the scipy peer's per-run time on a sample of
   the same runs. Runs per second per core.

Ratios are scipy (or RK4) time / shakeflow time: above 1, shakeflow is faster.
"""
import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
import pyarrow.parquet as pq

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "reference"))
import rocking_scipy  # noqa: E402

G0 = 9.80665
RECORDS = ["RSN1512_CHICHI_TCU078-E.AT2", "RSN1084_NORTHR_SCS052.AT2", "RSN763_LOMAP_GIL067.AT2",
           "RSN6_IMPVALL.I_I-ELC180.AT2", "NIS090.AT2", "RSN2110_DENALI_FAIGO360.AT2", "Rinaldi228.AT2",
           "Rinaldi318.AT2", "RinaldiUP.AT2", "RSN1512_CHICHI_TCU078-E.AT2"]
BLOCK = dict(B=0.349, H=1.082, f=0.085)


def read_at2(path):
    lines = pathlib.Path(path).read_text().splitlines()
    header = lines[3].upper().replace(",", " ")
    if "NPTS=" in header:
        dt = float(header.split("DT=")[1].split()[0])
        values = " ".join(lines[4:]).split()
    else:
        dt = float(header.split()[1])
        values = " ".join(lines[4:]).split()
    return dt, np.array([float(v) for v in values]) * G0


def write_csv(path, dt, acc):
    t = dt * np.arange(len(acc))
    np.savetxt(path, np.column_stack([t, acc]), delimiter=",", header="time_s,ax_mps2", comments="", fmt="%.9g")


def timed(cmd):
    started = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - started


def theta_of(out_dir):
    files = sorted(pathlib.Path(out_dir, "response").rglob("data.parquet"))
    return pq.read_table(files[0]).column("theta_rad").to_numpy()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shakeflow", required=True)
    ap.add_argument("--motions", default=str(ROOT.parent / "shared" / "data" / "ground_motions"))
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    sf = args.shakeflow
    motions = pathlib.Path(args.motions)
    # Standard gravity, as simulate_toppling uses by default (the peer defaults to the study's 9.81).
    block = rocking_scipy.Block(**BLOCK, g=9.80665)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        dt, acc = read_at2(motions / RECORDS[0])
        acc = 0.9 * acc[: int(round(60 / dt)) + 1]
        write_csv(tmp / "record.csv", dt, acc)
        subprocess.run([sf, "stage", "load", "--input", str(tmp / "record.csv"), "--output", str(tmp / "rec")],
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        geometry = ["--set", "preset=PS2"]
        adaptive, rk4 = [], []
        for _ in range(args.repeat):
            adaptive.append(timed([sf, "stage", "simulate_toppling", "--input", str(tmp / "rec" / "records"),
                                   "--output", str(tmp / "adaptive"), *geometry]))
            rk4.append(timed([sf, "stage", "simulate_toppling", "--input", str(tmp / "rec" / "records"),
                              "--output", str(tmp / "rk4"), *geometry, "--set", "method=rk4"]))
        t = dt * np.arange(len(acc))
        th_adaptive, th_rk4 = theta_of(tmp / "adaptive"), theta_of(tmp / "rk4")
        a, r = statistics.median(adaptive), statistics.median(rk4)
        print(f"rocking, one 60 s record at {1 / dt:.0f} Hz (Chi-Chi TCU078-E x 0.9, PS2), median of {args.repeat}")
        print(f"{'':40}{'wall s':>9}{'ratio':>9}{'max |dtheta| vs RK4':>22}")
        print(f"{'shakeflow adaptive (whole command)':40}{a:>9.3f}{1.0:>9.1f}{np.abs(th_adaptive - th_rk4).max():>22.1e}")
        print(f"{'shakeflow rk4 dt=1e-4 (whole command)':40}{r:>9.3f}{r / a:>9.1f}{0.0:>22.1e}")
        # The peer at its bench tolerance and tighter, toward shakeflow's accuracy ("equal accuracy").
        for rtol in (1e-10, 1e-12):
            scipy_runs = []
            for _ in range(args.repeat):
                started = time.perf_counter()
                theta_scipy, _ = rocking_scipy.simulate(block, t, acc, np.zeros_like(acc), rtol=rtol)
                scipy_runs.append(time.perf_counter() - started)
            s = statistics.median(scipy_runs)
            label = f"scipy DOP853 rtol {rtol:.0e} (simulation)"
            print(f"{label:40}{s:>9.3f}{s / a:>9.1f}{np.abs(theta_scipy - th_rk4).max():>22.1e}")

        # The fragility sweep: 10 × 30 s records × 100 levels.
        inputs = []
        samples = []
        for i, name in enumerate(RECORDS):
            dt_i, acc_i = read_at2(motions / name)
            acc_i = acc_i[: int(round(30 / dt_i)) + 1]
            path = tmp / f"r{i:02d}.csv"
            write_csv(path, dt_i, acc_i)
            inputs.append(str(path))
            samples.append((dt_i, acc_i))
        subprocess.run([sf, "stage", "load", "--input", *inputs, "--output", str(tmp / "recs")],
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        levels = np.linspace(1.0, 12.0, 100)
        sweep = [sf, "stage", "toppling_fragility", "--input", str(tmp / "recs" / "records"), "--output",
                 str(tmp / "fragility"), *geometry, "--set", f"im_levels=[{', '.join(f'{v:.4f}' for v in levels)}]"]
        one_core = [timed(["taskset", "-c", "0", *sweep]) for _ in range(args.repeat)]
        all_cores = [timed(sweep) for _ in range(args.repeat)]
        runs = len(RECORDS) * len(levels)
        # scipy on every 50th run of the same sweep, extrapolated to the full sweep.
        started, count = time.perf_counter(), 0
        for k in range(0, runs, 50):
            dt_i, acc_i = samples[k // len(levels)]
            scale = levels[k % len(levels)] / np.abs(acc_i).max()
            t_i = dt_i * np.arange(len(acc_i))
            rocking_scipy.simulate(block, t_i, scale * acc_i, np.zeros_like(acc_i), rtol=1e-10)
            count += 1
        per_run_scipy = (time.perf_counter() - started) / count
        per_run = statistics.median(one_core) / runs
        summary = pq.read_table(tmp / "fragility" / "fragility" / "data.parquet").to_pylist()[0]
        print()
        print(f"toppling fragility sweep: {runs} runs of 30 s records ({os.cpu_count()} cores), median of {args.repeat}")
        print(f"  shakeflow, 1 core: {statistics.median(one_core):.2f} s = {1 / per_run:.0f} runs/s/core (goal 500)")
        print(f"  shakeflow, all cores: {statistics.median(all_cores):.2f} s = {runs / statistics.median(all_cores):.0f} runs/s")
        print(f"  scipy peer: {per_run_scipy:.3f} s per run (sampled on {count} runs) = {1 / per_run_scipy:.1f} runs/s/core;"
              f" ratio {per_run_scipy / per_run:.0f}x")
        print(f"  fit: median PFA {summary['median']:.3f} m/s^2, beta {summary['beta']}, {summary['n_overturned']} of {summary['n_runs']} overturned")


if __name__ == "__main__":
    main()
