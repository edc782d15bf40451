"""`make bench`: load + baseline on the demo archive, shakeflow vs an equivalent Python script.

Both sides read every DAQ1/DAQ2 file of the archive (NEES text: preamble, names, descriptions,
units row), check the time column is uniform, convert the units the units row states (in/sec^2, g;
DAQ2's volts through the sensitivity table) to m/s^2, subtract a least-squares cubic from every channel and write one Parquet file per record
(floors split into floor 4 and 5, as the demo pipeline does) in shakeflow's float encoding: no
dictionary, byte-stream split, lz4. shakeflow also hashes every input and output for its cache
and writes provenance. It runs twice: as the demo pipeline runs these stages and with
`mcap: true` on both baseline stages, adding the opt-in MCAP twins, to show what they cost.
The script runs twice too: writing the corrected records only (less than the pipeline, which
also keeps `load`'s SI records as an artifact of their own), and writing both datasets, as the
pipeline does. Wall time and peak memory (max RSS) are medians over --repeat runs; ratios are
the script's / shakeflow's (above 1: shakeflow is faster or leaner).
"""
import argparse
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

PYTHON_SIDE = r'''
import pathlib, sys
import numpy as np
import pyarrow as pa, pyarrow.csv as pcsv, pyarrow.parquet as pq
G = 9.80665
# shakeflow's encoding of float columns (src/io/parquet.rs), so both sides write the same files.
PARQUET = dict(compression="lz4", use_dictionary=False, use_byte_stream_split=True)
archive, out = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
# "si": also write the SI records before the baseline, as shakeflow's `load` stage does.
WRITE_SI = sys.argv[3:] == ["si"]
groups_dir = archive / "NEES-2009-0722.groups"
# DAQ2's sensitivity table: channel -> (V per g, zero offset V).
SENSITIVITY = {}
for line in (groups_dir / "Documentation/DAQ2_sensitivities.csv").read_text().splitlines()[2:]:
    channel, sensitivity, unit, offset = line.split(",")
    assert unit == "g", line
    SENSITIVITY[channel] = (float(sensitivity), float(offset))
FACTOR = {"g": G, "in/sec^2": 0.0254}
def to_si(name, unit, raw):
    if unit == "V":
        sensitivity, offset = SENSITIVITY[name]
        return (raw - offset) / sensitivity * G
    return raw * FACTOR[unit]
def process(path, groups, dest):
    with open(path) as f:
        head = [next(f).rstrip("\n").split("\t") for _ in range(7)]
    names, units = head[4], dict(zip(head[4], head[6]))
    table = pcsv.read_csv(path, read_options=pcsv.ReadOptions(skip_rows=7, column_names=names),
                          parse_options=pcsv.ParseOptions(delimiter="\t"))
    t = table.column("Time").to_numpy()
    dt = (t[-1] - t[0]) / (len(t) - 1)
    if np.max(np.abs(np.diff(t) - dt)) > 1e-3 * dt + 2e-6:
        raise SystemExit(f"{path}: non-uniform time")
    for key, columns in groups.items():
        time = t[0] + dt * np.arange(len(t))
        si = {name: to_si(name, units[name], table.column(name).to_numpy()) for name in columns}
        if WRITE_SI:
            d = out / "si" / dest.relative_to(out) / key
            d.mkdir(parents=True, exist_ok=True)
            pq.write_table(pa.table({"time_s": time, **si}), d / "data.parquet", **PARQUET)
        arrays = {"time_s": time}
        for name, a in si.items():
            arrays[name] = a - np.polyval(np.polyfit(t, a, 3), t)
        d = dest / key
        d.mkdir(parents=True, exist_ok=True)
        pq.write_table(pa.table(arrays), d / "data.parquet", **PARQUET)
for daq1 in sorted(groups_dir.glob("Experiment-*/Trial-*/Rep-1/Converted_Data/*_DAQ1.txt")):
    test = daq1.name.removesuffix("_DAQ1.txt")
    daq2 = daq1.parent.parent / "Unprocessed_Data" / f"{test}_DAQ2.asc"
    process(daq1, {f"floor={f}": [f"A{f}_EW", f"A{f}_NS", f"A{f}_UD"] for f in (4, 5)}, out / "floors" / f"motion={test}")
    process(daq2, {"": ["A5_EW_SYNC", "UI3_TOP_EW", "MC2_TOP_EW", "PB1_TOP_EW", "PB2_TOP_EW", "PS1_TOP_EW", "PS2_TOP_EW", "WSU1_TOP_EW"]}, out / "equipment" / f"motion={test}")
'''


def measure(cmd):
    # Start from clean page cache writeback: the previous side's output must not be flushed on
    # this side's time.
    os.sync()
    started = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - started
    if status != 0:
        sys.exit(f"{cmd[0]} failed: {proc.stderr.read().decode()}")
    return wall, usage.ru_maxrss / 1024.0  # KiB → MiB


def run_sides(commands, repeat):
    """Times each side's command `repeat` times; `commands[side](output)` is the command that
    writes into the folder `output`. The order rotates every round, so no side always runs right
    after the same other one. Every run writes into a fresh folder and nothing is deleted until
    all runs are done: on ext4 without a journal (this VM's disk) a file created within seconds
    of a deletion makes the kernel step over each recently freed inode, so deleting the last
    run's output just before the next charged each side for the harness's own cleanup, in
    proportion to the files it creates (the demo pipeline ~350, the script ~60)."""
    results = {side: [] for side in commands}
    sides = list(commands)
    with tempfile.TemporaryDirectory() as runs:
        for round_ in range(repeat):
            for side in sides[round_ % len(sides):] + sides[:round_ % len(sides)]:
                output = pathlib.Path(runs) / f"side{sides.index(side)}-run{round_}"
                results[side].append(measure(commands[side](output)))
    return results


def time_pipelines(args, pipelines, scripts, script_source):
    """Times each shakeflow pipeline text of `pipelines` ({side: text}) and the Python script
    run with each argument list of `scripts` ({side: [arguments]}) with `run_sides`."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        commands = {}
        for i, (side, text) in enumerate(pipelines.items()):
            def pipeline_run(output, i=i, text=text):
                pipeline = tmp / f"pipeline{i}-{output.name}.yaml"
                pipeline.write_text(text.replace("output_dir: ../runs/demo", f"output_dir: {output}"))
                return [args.shakeflow, "run", "--quiet", str(pipeline)]
            commands[side] = pipeline_run
        script = tmp / "py_side.py"
        script.write_text(script_source)
        for side, arguments in scripts.items():
            commands[side] = lambda output, arguments=arguments: [sys.executable, str(script), str(args.archive), str(output), *arguments]
        return run_sides(commands, args.repeat)


def parse_args(doc):
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shakeflow", required=True)
    ap.add_argument("--archive", required=True)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    args.archive = pathlib.Path(args.archive).resolve()
    args.pipeline = (pathlib.Path(__file__).resolve().parents[1] / "pipelines" / "demo.yaml").read_text()
    return args


def summary_line(text):
    """One line of `make bench`'s closing summary (the ratios side by side): appended to the file
    $SHAKEFLOW_BENCH_SUMMARY names, when it does."""
    path = os.environ.get("SHAKEFLOW_BENCH_SUMMARY")
    if path:
        with open(path, "a") as f:
            f.write(text + "\n")


def print_table(title, results, python_sides):
    """Medians per side, and each Python side's / the side's ratios (above 1: the side is faster
    or leaner), one pair of ratio columns per Python side (named by its position: script 1, 2)."""
    median = {side: (statistics.median(w for w, _ in r), statistics.median(m for _, m in r)) for side, r in results.items()}
    print(title)
    for i, side in enumerate(python_sides, 1):
        print(f"  script {i}: {side}")
    ratio_heads = "".join(f"{f'time vs {i}':>11}{f'mem vs {i}':>10}" for i in range(1, len(python_sides) + 1))
    print(f"{'':40}{'wall s':>8}{'peak MiB':>10}{ratio_heads}")
    for side, (wall, mem) in median.items():
        ratios = "".join(f"{median[p][0] / wall:>11.2f}{median[p][1] / mem:>10.2f}" for p in python_sides)
        print(f"{side:40}{wall:>8.2f}{mem:>10.1f}{ratios}")


def main():
    args = parse_args(__doc__)
    size = sum(p.stat().st_size for pattern in ("*_DAQ1.txt", "*_DAQ2.asc") for p in args.archive.rglob(pattern))
    sides = ["shakeflow (demo pipeline)", "shakeflow (+MCAP twins)"]
    scripts = {"numpy/pyarrow, corrected records": [], "numpy/pyarrow, SI + corrected records": ["si"]}
    # Only the load and baseline stages: cut the pipeline before `synchronize`.
    text = args.pipeline.split("  synchronize:")[0].replace("../runs/demo-archive", str(args.archive))
    # Cut there, the intermediates (`keep: false`) have no reader: keep them, as the script does.
    text = text.replace("    keep: false\n", "")
    # Twins are opt-in (`mcap: true`); the demo's baseline stages state only their order.
    order = "      order: 3\n"
    assert text.count(order) == 2, "the demo's two baseline stages no longer say `order: 3` as their last parameter"
    twins = text.replace(order, order + "      mcap: true\n")
    results = time_pipelines(args, {sides[0]: text, sides[1]: twins}, scripts, PYTHON_SIDE)
    print_table(f"load + baseline on {args.archive} ({size / 1e6:.1f} MB of DAQ text, {os.cpu_count()} cores), median of {args.repeat}", results, list(scripts))


if __name__ == "__main__":
    main()
