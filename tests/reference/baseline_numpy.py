"""Reference for the baseline stage: numpy.polyfit on the real RENADIC record.

Reads ../shared/data/ground_motions/llolleo1002271.v1 with its own minimal fixed-width parser
(independent of shakeflow's reader), converts g/10 to m/s^2, fits a cubic with numpy.polyfit
against the file's time column and prints the coefficients (numpy order) and samples of the
corrected signal. tests/it/baseline_reference.rs compares shakeflow with the committed
baseline_llolleo.json beside this script, and checks that this script still prints those values
(without writing: a test never rewrites a committed reference). To regenerate the file:

    python tests/reference/baseline_numpy.py --write
"""
import json
import math
import pathlib
import sys

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
RECORD = HERE.parents[1] / ".." / "shared" / "data" / "ground_motions" / "llolleo1002271.v1"
G_OVER_10 = 9.80665 / 10.0
SAMPLE_INDICES = [0, 1, 1000, 12345, 20000, -1]


def read_renadic(path):
    lines = path.read_text().splitlines()
    channels, i = [], 0
    while i + 27 <= len(lines) and lines[i].startswith("UNCORRECTED"):
        name = lines[i + 6].split(":")[1].split()[0]
        npts = int(lines[i + 10].split("=")[1].split()[0])
        rows = math.ceil(npts / 5)
        data = lines[i + 27 : i + 27 + rows]
        fields = [row[k : k + 7] for row in data for k in range(0, len(row), 7)]
        pairs = np.array([float(f) for f in fields if f.strip()]).reshape(-1, 2)[:npts]
        channels.append((name, pairs[:, 0], pairs[:, 1]))
        i += 27 + rows + 1  # one trailer line after each block
    return channels


def main():
    out = {"record": "llolleo1002271.v1", "unit": "m/s^2", "order": 3, "numpy": np.__version__, "channels": {}}
    for name, t, a in read_renadic(RECORD):
        a = a * G_OVER_10
        coefficients = np.polyfit(t, a, 3)
        corrected = a - np.polyval(coefficients, t)
        out["channels"][name] = {
            "npts": int(len(a)),
            "polyfit_coefficients": coefficients.tolist(),
            "samples": {str(i % len(a)): float(corrected[i]) for i in SAMPLE_INDICES},
            "rms": float(np.sqrt(np.mean(corrected**2))),
            "max_abs": float(np.max(np.abs(corrected))),
        }
    text = json.dumps(out, indent=2) + "\n"
    if sys.argv[1:] == ["--write"]:
        (HERE / "baseline_llolleo.json").write_text(text)
    print(text, end="")


if __name__ == "__main__":
    main()
