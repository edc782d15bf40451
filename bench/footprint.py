"""`make bench`: the demo study's artifact footprint against the raw archive it reads.

Runs pipelines/demo.yaml from scratch into a temporary folder (the archive linked in, so nothing
under runs/ is touched) and prints the raw archive's size, the artifacts' size by kind (Parquet,
MCAP, PNG, the rest) and by stage, and their ratio to the archive against the goal (issue 20:
at most 2x the raw archive by default, with the same information). A second run turns on every
stage's opt-in MCAP twins (`mcap: true`) to show what they cost. Sizes are file sizes in MB
(10^6 bytes); the ratio is the same in MiB.
"""
import argparse
import collections
import os
import pathlib
import shutil
import subprocess
import tempfile
import time

import yaml

GOAL = 2.0
# Stage types with time-series outputs, whose `mcap` parameter writes MCAP twins.
TWIN_STAGES = {"baseline", "synchronize", "simulate_toppling", "simulate_rolling", "diagnose", "cpt_track", "cpt_project"}


def sizes(root):
    """Bytes per file kind and per top-level folder (stage) below root."""
    by_kind, by_stage, files = collections.Counter(), collections.defaultdict(collections.Counter), 0
    for folder, _, names in os.walk(root):
        for name in names:
            path = pathlib.Path(folder, name)
            size = path.stat().st_size
            kind = path.suffix.lstrip(".") if path.suffix in (".parquet", ".mcap", ".png") else "other"
            relative = path.relative_to(root)
            stage = relative.parts[0] if len(relative.parts) > 1 else "(output folder)"
            by_kind[kind] += size
            by_stage[stage][kind] += size
            files += 1
    return by_kind, by_stage, files


def run_demo(shakeflow, archive, twins):
    work = pathlib.Path(tempfile.mkdtemp(prefix="shakeflow-footprint-"))
    try:
        (work / "pipelines").mkdir()
        (work / "runs").mkdir()
        (work / "runs/demo-archive").symlink_to(pathlib.Path(archive).resolve())
        spec = yaml.safe_load(pathlib.Path("pipelines/demo.yaml").read_text())
        if twins:
            for stage in spec["stages"].values():
                if stage["type"] in TWIN_STAGES:
                    stage.setdefault("params", {})["mcap"] = True
        (work / "pipelines/demo.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
        started = time.perf_counter()
        subprocess.run([shakeflow, "run", "pipelines/demo.yaml"], cwd=work, check=True, capture_output=True)
        wall = time.perf_counter() - started
        return (*sizes(work / "runs/demo"), wall)
    finally:
        shutil.rmtree(work)


def mb(n):
    return n / 1e6


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shakeflow", required=True)
    ap.add_argument("--archive", required=True, help="the demo archive (shakeflow demo-archive DIR)")
    ap.add_argument("--no-twins", action="store_true", help="skip the run with every MCAP twin on")
    args = ap.parse_args()
    raw, _, raw_files = sizes(args.archive)
    raw_total = sum(raw.values())
    print(f"Artifact footprint of pipelines/demo.yaml: raw archive {mb(raw_total):.1f} MB in {raw_files} files")
    runs = [("default", False)] + ([] if args.no_twins else [("every MCAP twin on", True)])
    print(f"{'run':<20}{'artifacts MB':>13}{'Parquet':>9}{'MCAP':>8}{'PNG':>8}{'other':>7}{'files':>7}{'ratio':>7}{'wall s':>8}  goal")
    details = None
    for label, twins in runs:
        kind, stages, files, wall = run_demo(args.shakeflow, args.archive, twins)
        total = sum(kind.values())
        k = {name: mb(kind[name]) for name in ("parquet", "mcap", "png", "other")}
        # The goal is for the default run; the twins run shows what opting in costs.
        goal = f"{GOAL:.1f}x {'met' if total <= GOAL * raw_total else 'NOT met'}" if not twins else ""
        print(
            f"{label:<20}{mb(total):>13.1f}{k['parquet']:>9.1f}{k['mcap']:>8.1f}{k['png']:>8.1f}{k['other']:>7.1f}"
            f"{files:>7}{total / raw_total:>6.2f}x{wall:>8.1f}  {goal}"
        )
        details = details or stages
    print("default run by stage (MB):")
    for stage, kinds in sorted(details.items(), key=lambda item: -sum(item[1].values())):
        parts = ", ".join(f"{name} {mb(n):.1f}" for name, n in kinds.most_common() if n >= 5e4)
        print(f"  {stage:<22}{mb(sum(kinds.values())):>7.1f}  {parts}")


if __name__ == "__main__":
    main()
