"""`make bench` (rolling): simulate_rolling on a 60 s two-component record at 200 Hz, side by side
with the scipy peer and with RK4 at the study's dt = 1e-4 s.

The record: 2002 Denali, PEER RSN2113 (the study's DEN record), 20-80 s, scaled to a 0.15 g ground
peak, floor 4 of the fixed-base demo building (tests/reference/rolling_floor_denali.csv). Each of
the four Table 4 units runs as `shakeflow stage simulate_rolling` (one record, so one core; no
figure and no MCAP, so the time is the simulation's plus reading and writing Parquet), once with
the adaptive integrator (default tolerances) and once with `integrator: rk4, rk4_dt_s: 1e-4`,
for each friction law. The scipy side is tests/reference/rolling_kane.py (the sympy-derived
equations, solve_ivp DOP853 at the same rtol 1e-7 and restarted at every sample, as shakeflow
does); its time is the integration alone, without the symbolic derivation (printed apart).
Medians over --repeat runs for shakeflow; ratios are other / adaptive (above 1: adaptive is
faster). Δpeak is the adaptive run's peak displacement minus the RK4 run's.
"""
import argparse
import json
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
UNITS = ["PS1", "PB2", "MC2", "UI3"]


def timed(cmd):
    started = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - started
    if proc.returncode != 0:
        sys.exit(f"{' '.join(map(str, cmd))} failed:\n{proc.stderr}")
    return wall


def peak(out_dir):
    import pyarrow.parquet as pq

    facts = json.loads(pq.read_metadata(out_dir / "events" / "data.parquet").metadata[b"shakeflow.rolling"])
    return facts["peak_displacement_m"], facts["steps"]["rhs_evals"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shakeflow", required=True)
    ap.add_argument("--floor", default=str(ROOT / "tests/reference/rolling_floor_denali.csv"))
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        timed([args.shakeflow, "stage", "load", "--input", args.floor, "--output", tmp / "floor",
               "--set", "time_column=time_s", "--set", "unit=m/s^2"])
        record = tmp / "floor" / "records" / "data.parquet"
        started = time.perf_counter()
        peer_json = tmp / "peer.json"
        subprocess.run([sys.executable, ROOT / "tests/reference/rolling_kane.py", "--floor", args.floor,
                        "--units", ",".join(UNITS), "--rtol", "1e-7", "--every", "100", "--out", peer_json], check=True)
        peer = json.loads(peer_json.read_text())
        print(f"scipy peer: {time.perf_counter() - started:.1f} s in all, of which the sympy derivation {peer['derivation_s']:.1f} s")
        for law in ["regularised", "stick_slip"]:
            print(f"\nrolling, {law} friction: 60 s two-component record at 200 Hz (Denali RSN2113 through the demo building, floor 4), one core, median of {args.repeat}")
            print(f"{'unit':<6}{'adaptive s':>12}{'RK4 1e-4 s':>12}{'scipy s':>10}{'RK4/adapt':>11}{'scipy/adapt':>13}"
                  f"{'evals adapt':>13}{'evals RK4':>11}{'peak m':>9}{'Δpeak vs RK4':>15}")
            for unit in UNITS:
                runs = {}
                for name, extra in [("adaptive", []), ("rk4", ["--set", "integrator=rk4", "--set", "rk4_dt_s=1e-4"])]:
                    out = tmp / f"{unit}-{law}-{name}"
                    cmd = [args.shakeflow, "stage", "simulate_rolling", "--input", record, "--output", out,
                           "--set", f"preset={unit}", "--set", f"friction_law={law}", "--set", "figure=false",
                           "--set", "mcap=false", *extra]
                    wall = statistics.median(timed(cmd) for _ in range(args.repeat))
                    runs[name] = (wall, *peak(out))
                (wa, pa, ea), (wr, pr, er) = runs["adaptive"], runs["rk4"]
                ws = peer["units"][unit]["wall_s"] if law == "regularised" else float("nan")
                print(f"{unit:<6}{wa:>12.3f}{wr:>12.3f}{ws:>10.1f}{wr / wa:>11.1f}{ws / wa:>13.0f}"
                      f"{ea:>13}{er:>11}{pa:>9.3f}{1000 * (pa - pr):>12.2f} mm")
        print("\n(the scipy peer implements the regularised law only)")


if __name__ == "__main__":
    main()
