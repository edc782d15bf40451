"""`make bench`: what one `shakeflow stage simulate_toppling` call costs beyond its simulation.

A user scripting thousands of `stage` calls pays for the process: start-up, reading the record's
Parquet, the simulation, writing Parquet (and a figure), committing. On one 60 s record at 200 Hz
(Chi-Chi TCU078-E x 0.9, the PS2 block, as bench/rocking.py) and on a 2-sample record (nearly no
simulation), each call into a fresh output folder (a repeated call into the same folder is a cache
hit that writes nothing), medians of --repeat:

- `shakeflow --version` (the process alone),
- the stage with its figure (the default) and with `figure=false`,
- scipy's in-process simulation of the same record (tests/reference/rocking_scipy.py, DOP853,
  rtol 1e-10): the goal is a whole-process call >= 20x faster than it, and <= 5 ms of overhead
  beyond the simulation (the 2-sample call without a figure is that overhead).

Each is given as wall time and as CPU time (user + system, the process's threads summed; for
scipy, this process's). On a loaded machine the wall times wait for the CPU and the CPU times do
not, so the CPU ratio is the one to compare between runs there.
"""
import argparse
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "reference"))
sys.path.insert(0, str(ROOT / "bench"))
import rocking_scipy  # noqa: E402
from load_baseline import summary_line  # noqa: E402
from rocking import BLOCK, RECORDS, read_at2, write_csv  # noqa: E402


def timed(cmd):
    """(wall, CPU) seconds of one process, CPU being its user + system time (threads summed)."""
    started = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - started
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise subprocess.CalledProcessError(proc.returncode, cmd)
    return wall, usage.ru_utime + usage.ru_stime


def medians(runs):
    return tuple(statistics.median(r[i] for r in runs) for i in (0, 1))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shakeflow", required=True)
    ap.add_argument("--motions", default=str(ROOT.parent / "shared" / "data" / "ground_motions"))
    ap.add_argument("--repeat", type=int, default=20)
    args = ap.parse_args()
    sf = args.shakeflow
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        dt, acc = read_at2(pathlib.Path(args.motions) / RECORDS[0])
        acc = 0.9 * acc[: int(round(60 / dt)) + 1]
        write_csv(tmp / "record.csv", dt, acc)
        write_csv(tmp / "tiny.csv", dt, acc[:2])
        for name in ("record", "tiny"):
            subprocess.run([sf, "stage", "load", "--input", str(tmp / f"{name}.csv"), "--output", str(tmp / name)],
                           check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        calls = {}
        for label, record, extra in [("60 s record, with figure (default)", "record", []),
                                     ("60 s record, figure=false", "record", ["--set", "figure=false"]),
                                     ("2-sample record, with figure", "tiny", []),
                                     ("2-sample record, figure=false", "tiny", ["--set", "figure=false"])]:
            runs = []
            for i in range(args.repeat):
                out = tmp / f"out-{len(calls)}-{i}"
                runs.append(timed([sf, "stage", "simulate_toppling", "--input", str(tmp / record / "records"),
                                   "--output", str(out), "--set", "preset=PS2", *extra]))
            calls[label] = medians(runs)
        start = medians([timed([sf, "--version"]) for _ in range(args.repeat)])
        block = rocking_scipy.Block(**BLOCK, g=9.80665)
        t = dt * np.arange(len(acc))
        scipy_runs = []
        for _ in range(max(3, args.repeat // 4)):
            started, cpu = time.perf_counter(), time.process_time()
            rocking_scipy.simulate(block, t, acc, np.zeros_like(acc), rtol=1e-10)
            scipy_runs.append((time.perf_counter() - started, time.process_time() - cpu))
        scipy_s = medians(scipy_runs)
        print(f"one `stage simulate_toppling` call (PS2, Chi-Chi TCU078-E x 0.9), median of {args.repeat}")
        print(f"{'':42}{'wall ms':>9}{'CPU ms':>9}{'scipy / this, wall':>20}{'CPU':>8}")

        def row(label, this):
            ratio = f"{scipy_s[0] / this[0]:>20.1f}{scipy_s[1] / this[1]:>8.1f}"
            print(f"{label:42}{1e3 * this[0]:>9.1f}{1e3 * this[1]:>9.1f}{ratio}")

        print(f"{'process start (shakeflow --version)':42}{1e3 * start[0]:>9.1f}{1e3 * start[1]:>9.1f}")
        for label, this in calls.items():
            row(label, this)
        row("scipy DOP853 rtol 1e-10, simulation only", scipy_s)
        overhead = calls["2-sample record, figure=false"]
        print(f"overhead beyond the simulation (2-sample call, figure=false): {1e3 * overhead[0]:.1f} ms wall, "
              f"{1e3 * overhead[1]:.1f} ms CPU (goal <= 5 ms)")
        default, bare = calls["60 s record, with figure (default)"], calls["60 s record, figure=false"]
        summary_line(f"stage simulate_toppling, whole process vs scipy's in-process simulation: "
                     f"{scipy_s[0] / default[0]:.1f}x wall ({scipy_s[1] / default[1]:.1f}x CPU) with its figure, "
                     f"{scipy_s[0] / bare[0]:.1f}x wall ({scipy_s[1] / bare[1]:.1f}x CPU) without (goal >= 20x); "
                     f"overhead {1e3 * overhead[0]:.1f} ms wall, {1e3 * overhead[1]:.1f} ms CPU a call (goal <= 5 ms)")


if __name__ == "__main__":
    main()
