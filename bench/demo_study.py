"""`make bench` (second part): the whole demo study, shakeflow vs the same steps in numpy/scipy.

shakeflow runs pipelines/demo.yaml from scratch (load, baseline, synchronize, transfer_function,
detect_toppling, report with figures; no MCAP twins, which are opt-in). The Python side does the same numerical steps
with the usual scientific stack and writes Parquet: pyarrow CSV reading of the NEES text files
(units from their units row, DAQ2's volts through the sensitivity table), numpy.polyfit baselines,
scipy.signal.resample_poly (256 -> 200 Hz) and FFT cross-correlation with parabolic refinement,
np.interp shifting, scipy.signal.csd/welch transfer functions with MATLAB tfestimate defaults for
the white-noise tests, and a simplified STA/LTA + RMS-drop toppling check per unit channel (a port
of the same steps for timing, not a validated detector). It skips MCAP
and figures, so the comparison does not favour shakeflow; a second shakeflow run with
`synchronize`'s MCAP twins (`mcap: true`) shows what they cost. The script runs twice: writing what it needs
(aligned records, toppling and transfer-function tables), and also writing the SI and the
baseline-corrected records, which the pipeline keeps as artifacts of their own. The rocking, fragility and rolling
simulations, which the Python side does not do, are cut from the pipeline here (bench/rocking.py
and bench/rolling.py time them). Medians over
--repeat runs; ratios are Python / shakeflow (above 1: shakeflow is faster or leaner).
"""
import os

import statistics

from load_baseline import parse_args, print_table, summary_line, time_pipelines

PYTHON_SIDE = r'''
import pathlib, sys
import numpy as np, scipy.signal as ss
import pyarrow as pa, pyarrow.csv as pcsv, pyarrow.parquet as pq
G = 9.80665
archive, out = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
# "records": also write the SI and the corrected records, as the pipeline's load and baseline do.
WRITE_RECORDS = sys.argv[3:] == ["records"]
UNITS = {"UI3": 4, "MC2": 4, "PB1": 4, "PB2": 4, "PS1": 5, "PS2": 5, "WSU1": 5}
groups_dir = archive / "NEES-2009-0722.groups"
SENSITIVITY = {}
for line in (groups_dir / "Documentation/DAQ2_sensitivities.csv").read_text().splitlines()[2:]:
    channel, sensitivity, unit, offset = line.split(",")
    SENSITIVITY[channel] = (float(sensitivity), float(offset))
FACTOR = {"g": G, "in/sec^2": 0.0254}
def to_si(name, unit, raw):
    if unit == "V":
        sensitivity, offset = SENSITIVITY[name]
        return (raw - offset) / sensitivity * G
    return raw * FACTOR[unit]
def read(path, test):
    with open(path) as f:
        head = [next(f).rstrip("\n").split("\t") for _ in range(7)]
    names, units = head[4], dict(zip(head[4], head[6]))
    t = pcsv.read_csv(path, read_options=pcsv.ReadOptions(skip_rows=7, column_names=names),
                      parse_options=pcsv.ParseOptions(delimiter="\t"))
    time = t.column("Time").to_numpy()
    cols = {n: to_si(n, units[n], t.column(n).to_numpy()) for n in t.column_names if n != "Time"}
    if WRITE_RECORDS:
        write(out / "si" / test / path.stem / "data.parquet", {"time_s": time, **cols})
    for n, a in cols.items():
        cols[n] = a - np.polyval(np.polyfit(time, a, 3), time)
    if WRITE_RECORDS:
        write(out / "corrected" / test / path.stem / "data.parquet", {"time_s": time, **cols})
    return time, cols
def write(path, cols):
    path.parent.mkdir(parents=True, exist_ok=True)
    floats = [k for k, v in cols.items() if np.asarray(v).dtype == np.float64]
    pq.write_table(pa.table(cols), path, compression="lz4", use_dictionary=False, use_byte_stream_split=floats)
def tfestimate(x, y, fs):
    L = len(x) * 2 // 9
    kw = dict(fs=fs, window=ss.get_window("hamming", L, fftbins=False), nperseg=L, noverlap=L // 2, nfft=max(256, 1 << (L - 1).bit_length()), detrend=False)
    f, pxy = ss.csd(x, y, **kw); _, pxx = ss.welch(x, **kw); _, pyy = ss.welch(y, **kw)
    return f, pxy / pxx, np.abs(pxy) ** 2 / (pxx * pyy)
def toppled(t, a):
    d = np.abs(np.diff(a, prepend=a[0])); fs = 1 / (t[1] - t[0])
    sta = np.convolve(d ** 2, np.ones(int(0.02 * fs)) / int(0.02 * fs), "same")
    lta = np.convolve(d ** 2, np.ones(int(5 * fs)) / int(5 * fs), "same")
    k = int(np.argmax(np.sqrt(sta / np.maximum(lta, 1e-12))))
    pre = a[max(0, k - int(2 * fs)):k]; post = a[k + int(0.4 * fs):k + int(2.4 * fs)]
    return len(post) > fs and np.std(post) < 0.35 * np.std(pre), t[k]
for daq1 in sorted(groups_dir.glob("Experiment-*/Trial-*/Rep-1/Converted_Data/*_DAQ1.txt")):
    name = daq1.name.removesuffix("_DAQ1.txt")
    t1, floors = read(daq1, name); t2, eq = read(daq1.parent.parent / "Unprocessed_Data" / f"{name}_DAQ2.asc", name)
    ref = floors["A5_EW"]; sync = ss.resample_poly(eq["A5_EW_SYNC"], 25, 32)
    n = min(len(ref), len(sync)); c = ss.correlate(sync[:n], ref[:n], method="fft"); k = int(np.argmax(np.abs(c)))
    y0, y1, y2 = c[k - 1], c[k], c[k + 1]; frac = 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2)
    lag = (k - (n - 1) + frac) / 200.0
    aligned = {n_: np.interp(t1 - lag, t2, v) for n_, v in eq.items()}
    write(out / "sync" / f"motion={name}" / "data.parquet", {"time_s": t1, **{f"f{k_}": v for k_, v in floors.items()}, **aligned})
    events = []
    for unit, floor in UNITS.items():
        hit, when = toppled(t1, aligned[f"{unit}_TOP_EW"]); events.append((unit, bool(hit), float(when)))
    write(out / "toppling" / f"motion={name}" / "data.parquet", {"unit": [e[0] for e in events], "toppled": [e[1] for e in events], "time": [e[2] for e in events]})
    if name.startswith("WN"):
        rows = []
        for unit, floor in UNITS.items():
            f, h1, coh = tfestimate(floors[f"A{floor}_EW"], aligned[f"{unit}_TOP_EW"], 200.0)
            band = (f >= 1.5) & (f <= 8.0); i = np.argmax(np.abs(h1) * band); rows.append((unit, f[i], coh[i]))
        write(out / "tf" / f"motion={name}" / "data.parquet", {"unit": [r[0] for r in rows], "frequency_hz": [r[1] for r in rows], "coherence": [r[2] for r in rows]})
'''


SIMULATIONS = ("rocking_", "fragility_", "rolling_")


def without_simulations(pipeline):
    """The demo pipeline without its simulation stages (rocking, fragility, rolling) and the
    report's use of them: the Python side does not simulate (bench/rocking.py and bench/rolling.py
    time the models against their scipy peers)."""
    kept, skipping = [], False
    for line in pipeline.splitlines(keepends=True):
        if line.startswith(tuple("  " + s for s in SIMULATIONS)):
            skipping = True
        elif skipping and line.startswith("  ") and not line.startswith("   "):
            skipping = False
        if not skipping and not line.lstrip().startswith(tuple("- " + s for s in SIMULATIONS)):
            kept.append(line)
    return "".join(kept)


def main():
    args = parse_args(__doc__)
    args.pipeline = without_simulations(args.pipeline)
    sides = ["shakeflow (demo pipeline)", "shakeflow (+MCAP twins)"]
    scripts = {"numpy/scipy, results only": [], "numpy/scipy, + SI and corrected records": ["records"]}
    # The camera projection stages have their own benchmark (bench/cpt.py) against OpenCV.
    text = args.pipeline.split("  cpt_calibrate:")[0].replace("../runs/demo-archive", str(args.archive))
    # The diagnosis stage comes after the camera stages and is cut with them (make bench times it
    # per case on its own): the report reads it no more.
    diagnosis_input = "      - diagnosis.diagnosis\n"
    assert text.count(diagnosis_input) == 1, "the demo's report inputs changed; update the bench"
    text = text.replace(diagnosis_input, "")
    sync_params = "      max_lag_s: 5.0\n"
    assert text.count(sync_params) == 1, "the demo's synchronize stage changed; update the bench"
    twins = text.replace(sync_params, sync_params + "      mcap: true\n")
    results = time_pipelines(args, {sides[0]: text, sides[1]: twins}, scripts, PYTHON_SIDE)
    print_table(f"whole demo study on {args.archive} ({os.cpu_count()} cores), median of {args.repeat}", results, list(scripts))
    wall = {side: statistics.median(w for w, _ in r) for side, r in results.items()}
    mem = {side: statistics.median(m for _, m in r) for side, r in results.items()}
    script = list(scripts)[0]
    summary_line(f"demo study vs its numpy/scipy script: {wall[script] / wall[sides[0]]:.1f}x faster, "
                 f"{mem[script] / mem[sides[0]]:.2f}x the memory ratio (goal >= 10x, lower memory)")


if __name__ == "__main__":
    main()
