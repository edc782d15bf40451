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
"""
import argparse
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
from rocking import BLOCK, RECORDS, read_at2, timed, write_csv  # noqa: E402


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
            calls[label] = statistics.median(runs)
        start = statistics.median(timed([sf, "--version"]) for _ in range(args.repeat))
        block = rocking_scipy.Block(**BLOCK, g=9.80665)
        t = dt * np.arange(len(acc))
        scipy_runs = []
        for _ in range(max(3, args.repeat // 4)):
            started = time.perf_counter()
            rocking_scipy.simulate(block, t, acc, np.zeros_like(acc), rtol=1e-10)
            scipy_runs.append(time.perf_counter() - started)
        scipy_s = statistics.median(scipy_runs)
        print(f"one `stage simulate_toppling` call (PS2, Chi-Chi TCU078-E x 0.9), median of {args.repeat}")
        print(f"{'':42}{'ms':>9}{'scipy / this':>14}")
        print(f"{'process start (shakeflow --version)':42}{1e3 * start:>9.1f}")
        for label, seconds in calls.items():
            print(f"{label:42}{1e3 * seconds:>9.1f}{scipy_s / seconds:>14.1f}")
        print(f"{'scipy DOP853 rtol 1e-10, simulation only':42}{1e3 * scipy_s:>9.1f}{1.0:>14.1f}")
        overhead = calls["2-sample record, figure=false"]
        print(f"overhead beyond the simulation (2-sample call, figure=false): {1e3 * overhead:.1f} ms (goal <= 5 ms)")
        default = calls["60 s record, with figure (default)"]
        summary_line(f"stage simulate_toppling, whole process vs scipy's in-process simulation: "
                     f"{scipy_s / default:.1f}x with its figure, {scipy_s / calls['60 s record, figure=false']:.1f}x "
                     f"without (goal >= 20x); overhead {1e3 * overhead:.1f} ms a call (goal <= 5 ms)")


if __name__ == "__main__":
    main()
