"""`make bench`: read throughput of each strong-motion format, shakeflow vs the best Python reader.

For every format with files in ../shared/data/records (cosmos, dmg, smc, knet, esm, geonet, and
the PEER AT2), the files are copied --copies times into a scratch folder (a few MB per format)
and read one after another on one thread:
- shakeflow: its reader alone (examples/read_records.rs, built here), and `shakeflow stage load`
  on the same files (reading, SI conversion and Parquet files, on every core);
- gmprocess (USGS) with that format's reader, for every format it has one (not AT2);
- ObsPy's K-NET reader; numpy (the text after the header split on blanks into `np.array`) for
  ESM and K-NET, whose data are plain blank-separated numbers. gmprocess and ObsPy run in the interpreter given by --gmprocess-python (their
  own venv: gmprocess pins numpy < 2.4); without one those sides are skipped and said so.
Each side's reading time is measured inside its process (imports and start-up excluded); MB/s is
file bytes / that time, the median of --repeat runs. Peak memory is the process's max RSS (for
Python, with its imports: the figure after imports is given apart). The ratio is shakeflow's
reader MB/s / the side's.
"""
import argparse
import json
import os
import pathlib
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
FORMATS = {"cosmos": "cosmos", "dmg": "dmg", "smc": "smc", "knet": "knet", "esm": "esm", "geonet": "geonet", "nga": "at2"}

PYTHON_SIDE = r'''
import json, resource, sys, time, warnings, logging
warnings.filterwarnings("ignore")
logging.disable(logging.CRITICAL)
side, fmt, files = sys.argv[1], sys.argv[2], sys.argv[3:]
if side == "gmprocess":
    import importlib
    read = getattr(importlib.import_module(f"gmprocess.io.{fmt}.core"), f"read_{fmt}")
    def values(path):
        return sum(float(tr.data.sum()) for stream in read(path) for tr in stream)
elif side == "obspy":
    import obspy
    def values(path):
        return float(obspy.read(path, format="KNET")[0].data.sum())
elif side == "numpy":
    import numpy as np
    skip = {"knet": 17, "esm": 64}[fmt]
    def values(path):
        with open(path) as f:
            body = f.read().split("\n", skip)[skip]
        return float(np.array(body.split(), dtype=np.float64).sum())
rss_after_imports = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
started = time.perf_counter()
total = sum(values(f) for f in files)
seconds = time.perf_counter() - started
print(json.dumps({"seconds": seconds, "sum": total, "rss_after_imports": rss_after_imports}))
'''


def run(cmd):
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    out, err = proc.stdout.read().decode(), proc.stderr.read().decode()
    if status != 0:
        sys.exit(f"{' '.join(cmd[:3])} failed: {err[-2000:]}")
    return out, usage.ru_maxrss / 1024.0  # KiB → MiB


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shakeflow", required=True)
    ap.add_argument("--records", default=str(ROOT.parent / "shared" / "data" / "records"))
    ap.add_argument("--gmprocess-python", default=str(pathlib.Path.home() / ".cache/shakeflow/venv-gmprocess/bin/python"))
    ap.add_argument("--reader", help="a built examples/read_records binary (default: build it, release)")
    ap.add_argument("--copies", type=int, default=8)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    if args.reader:
        reader = pathlib.Path(args.reader)
    else:
        target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
        subprocess.run(["cargo", "build", "--release", "--locked", "--quiet", "--example", "read_records"], cwd=ROOT, check=True)
        reader = target / "release" / "examples" / "read_records"
    gm_python = args.gmprocess_python if pathlib.Path(args.gmprocess_python).is_file() else None
    if gm_python is None:
        print(f"(no {args.gmprocess_python}: the gmprocess and ObsPy sides are skipped; "
              "see tests/reference/records_gmprocess.py for how to make that venv)")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        script = tmp / "side.py"
        script.write_text(PYTHON_SIDE)
        for folder, fmt in FORMATS.items():
            sources = sorted(p for p in (pathlib.Path(args.records) / folder).iterdir() if p.is_file())
            files = []
            for k in range(args.copies):
                for src in sources:
                    dst = tmp / folder / f"{k}-{src.name.replace('.', '_')}"  # unique stems: `stage load` partitions by stem
                    dst.parent.mkdir(exist_ok=True)
                    shutil.copyfile(src, dst)
                    files.append(str(dst))
            size = sum(os.path.getsize(f) for f in files)
            sides = {"shakeflow reader": lambda: [str(reader), fmt, *files]}
            if gm_python and fmt != "at2":
                sides["gmprocess"] = lambda fmt=fmt: [gm_python, str(script), "gmprocess", fmt, *files]
            if gm_python and fmt == "knet":
                sides["obspy"] = lambda: [gm_python, str(script), "obspy", fmt, *files]
            if fmt in ("knet", "esm"):
                sides["numpy (split, np.array)"] = lambda fmt=fmt: [sys.executable, str(script), "numpy", fmt, *files]
            results = {}
            for side, command in sides.items():
                runs = []
                for r in range(args.repeat):
                    out, rss = run(command())
                    report = json.loads(out.strip().splitlines()[-1])
                    runs.append((report["seconds"], rss, report.get("rss_after_imports")))
                results[side] = (statistics.median(s for s, _, _ in runs), statistics.median(m for _, m, _ in runs), runs[0][2])
            # The whole `load` stage on the same files: reading, SI, Parquet, on every core.
            stage = []
            for r in range(args.repeat):
                out_dir = tmp / f"stage-{folder}-{r}"
                cmd = [args.shakeflow, "stage", "load", "--input", *files, "--output", str(out_dir)]
                started = time.perf_counter()
                _, rss = run(cmd)
                stage.append((time.perf_counter() - started, rss))
                shutil.rmtree(out_dir)
            results["shakeflow stage load (whole process)"] = (statistics.median(s for s, _ in stage), statistics.median(m for _, m in stage), None)
            rows.append((folder, fmt, len(files), size, results))

    print(f"Record readers: {args.copies} copies of each format's shared files, one thread (stage load: every core), median of {args.repeat}")
    print(f"{'format':8}{'files':>6}{'MB':>7}  {'side':38}{'MB/s':>9}{'peak MiB':>10}{'after imports':>14}{'reader ×':>10}")
    for folder, fmt, n, size, results in rows:
        ours = size / 1e6 / results["shakeflow reader"][0]
        for side, (seconds, rss, imports) in results.items():
            mbps = size / 1e6 / seconds
            imports = f"{imports:.1f}" if imports else ""
            print(f"{fmt:8}{n:>6}{size / 1e6:>7.1f}  {side:38}{mbps:>9.1f}{rss:>10.1f}{imports:>14}{ours / mbps:>10.2f}")


if __name__ == "__main__":
    main()
