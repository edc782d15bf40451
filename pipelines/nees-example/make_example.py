"""Writes the small NEES-layout example archive beside this script (committed; rerun to remake it).

Two trials of a table motion (a 1.2 Hz pulse train, peak 0.35 g and 0.5 g) written as NEES DAQs
did: tab-delimited text with a preamble, a channel-name row, a description row and a units row;
`Converted_Data/table.txt` in g and in/sec^2, `Unprocessed_Data/daq.asc` in volts and counts with
`sensitivity.csv` to calibrate it. Deterministic: no random numbers, fixed decimals.
"""
import math
from pathlib import Path

HERE = Path(__file__).parent
RATE, N = 100.0, 600
SENS = {"A1X": (1.25, 0.0125), "A1Y": (2.5, -0.005), "D1X": (3276.8, 2048.0)}


def motion(trial, t):
    peak = {1: 0.35, 2: 0.5}[trial]
    envelope = math.sin(math.pi * t / (N / RATE)) ** 2
    ax = peak * envelope * math.sin(2 * math.pi * 1.2 * t)  # g
    ay = 0.3 * peak * 386.4 * envelope * math.cos(2 * math.pi * 0.8 * t)  # in/s^2
    dx = peak * 2.0 * envelope * math.sin(2 * math.pi * 1.2 * t - 0.3)  # in
    return ax, ay, dx


def write(path, units, rows, trial):
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [
        f"NEES-0000-0000\tExperiment-1\tTrial-{trial}\tRep-1",
        "Facility: example shake table (synthetic data, shakeflow pipelines/nees-example)",
        f"Sampling rate: {RATE:.0f} Hz",
        "Time\tA1X\tA1Y\tD1X",
        "Time\tTable acceleration, E-W\tTable acceleration, N-S\tTable displacement, E-W (LVDT)",
        units,
    ]
    lines += ["\t".join(r) for r in rows]
    path.write_text("\n".join(lines) + "\n")


for trial in (1, 2):
    rep = HERE / "NEES-0000-0000.groups" / "Experiment-1" / f"Trial-{trial}" / "Rep-1"
    converted, raw = [], []
    for k in range(N):
        t = k / RATE
        ax, ay, dx = motion(trial, t)
        converted.append([f"{t:.2f}", f"{ax:.6f}", f"{ay:.4f}", f"{dx:.5f}"])
        raw.append([
            f"{t:.2f}",
            f"{SENS['A1X'][1] + SENS['A1X'][0] * ax:.6f}",
            f"{SENS['A1Y'][1] + SENS['A1Y'][0] * ay / 386.4:.6f}",
            f"{SENS['D1X'][1] + SENS['D1X'][0] * dx:.0f}",
        ])
    write(rep / "Converted_Data" / "table.txt", "sec\tg\tin/sec^2\tin", converted, trial)
    write(rep / "Unprocessed_Data" / "daq.asc", "sec\tV\tV\tcounts", raw, trial)

(HERE / "sensitivity.csv").write_text(
    "# DAQ 1 sensitivities: raw units per unit, offset in raw units\nchannel,sensitivity,unit,offset\n"
    + "".join(f"{c},{s},{u},{o}\n" for (c, (s, o)), u in zip(SENS.items(), ["g", "g386", "in"]))
)
