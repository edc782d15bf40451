"""Scores `shakeflow diagnose` on concealed rolling cases (prove/rolling/generate.py, or any folder
of cases in the contract format with truth/<case>.yaml beside them).

    python prove/rolling/score.py CASES_DIR --shakeflow BIN [--jobs 2] [--out runs/prove-rolling]
                                  [--cpu-limit SECONDS]

Runs the binary on each case as a user would, checks the diagnosis.json contract, and reports:
accuracy (with a Wilson 95 % interval) and the confusion matrix, false alarms on `none`, the
window start's error against the concealed onset, rmse_after/rmse_before where a physics is
named, and the seconds per case. Exits non-zero if the binary fails or breaks the contract.
With --cpu-limit, a diagnosis that spends more CPU seconds than that is stopped (RLIMIT_CPU) and
scored as the verdict `over_cpu_limit` (wrong), so one runaway case cannot hold up a set.
"""
from __future__ import annotations

import argparse
import json
import math
import resource
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from score import CPU_WRAPPER, cpu_seconds  # noqa: E402  (prove/score.py)

VERDICTS = ["none", "lateral_impact", "mass_change", "caster_brake", "swivel_jam", "ambiguous", "unexplained"]
PHYSICS = {"lateral_impact", "mass_change", "caster_brake", "swivel_jam"}
KEYS = ["mismatch", "verdict", "window", "rmse_before", "rmse_after", "candidates", "explanation"]


def wilson(k: int, n: int, z: float = 1.96):
    if n == 0:
        return (float("nan"), float("nan"))
    p = k / n
    den = 1 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return (max(0.0, mid - half), min(1.0, mid + half))


OVER_LIMIT = "over_cpu_limit"


def run(binary: str, case: Path, out: Path, cpu_limit: float | None = None):
    def limit():
        # Inherited by the diagnosis the wrapper starts: SIGXCPU past `cpu_limit` CPU seconds.
        resource.setrlimit(resource.RLIMIT_CPU, (int(cpu_limit), int(cpu_limit) + 10))

    started = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", CPU_WRAPPER, binary, "diagnose", str(case), "--out", str(out)],
                          capture_output=True, text=True, preexec_fn=limit if cpu_limit else None)
    seconds = time.perf_counter() - started
    cpu = cpu_seconds(proc.stderr)
    # The wrapper exits with the child's code: -SIGXCPU, or what a signal-killed child reports.
    if cpu_limit and proc.returncode in (-signal.SIGXCPU, (-signal.SIGXCPU) % 256, -signal.SIGKILL % 256):
        return {"verdict": OVER_LIMIT, "window": None, "rmse_before": math.nan, "rmse_after": math.nan,
                "candidates": []}, seconds, cpu
    if proc.returncode != 0:
        raise SystemExit(f"{case.name}: shakeflow failed ({proc.returncode}):\n{proc.stderr}")
    d = json.loads((out / "diagnosis.json").read_text())
    missing = [k for k in KEYS if k not in d]
    if missing or d["verdict"] not in VERDICTS:
        raise SystemExit(f"{case.name}: diagnosis.json breaks the contract (missing {missing}, verdict {d.get('verdict')})")
    if d["window"] is not None and not {"start_s", "end_s"} <= set(d["window"]):
        raise SystemExit(f"{case.name}: window lacks start_s/end_s")
    return d, seconds, cpu


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cases")
    ap.add_argument("--shakeflow", required=True)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default="runs/prove-rolling")
    ap.add_argument("--cpu-limit", type=float, help="CPU seconds a diagnosis may spend (scored over_cpu_limit past it)")
    args = ap.parse_args()
    cases_dir = Path(args.cases)
    out_dir = Path(args.out)
    cases = sorted(p for p in cases_dir.iterdir() if (p / "equipment.yaml").is_file())
    truths = {c.name: yaml.safe_load((cases_dir / "truth" / f"{c.name}.yaml").read_text()) for c in cases}
    with ThreadPoolExecutor(args.jobs) as pool:
        results = list(pool.map(lambda c: run(args.shakeflow, c, out_dir / "diagnosis" / c.name, args.cpu_limit), cases))
    rows = []
    for c, (d, seconds, cpu) in zip(cases, results):
        t = truths[c.name]
        start = d["window"]["start_s"] if d["window"] else None
        onset = t.get("onset_s")
        rows.append({
            "case": c.name, "effect": t["effect"], "expected": t["expected_verdict"], "verdict": d["verdict"],
            "correct": d["verdict"] == t["expected_verdict"], "onset_s": onset, "start_s": start,
            "onset_error_s": None if (start is None or onset is None) else abs(start - onset),
            "rmse_before": d["rmse_before"], "rmse_after": d["rmse_after"], "seconds": round(seconds, 2),
            "cpu_seconds": cpu,
            "parameters": t.get("parameters"),
            "fitted": next((cand["params"] for cand in d["candidates"] if cand["effect"] == d["verdict"]), None),
        })
    n = len(rows)
    k = sum(r["correct"] for r in rows)
    confusion = {e: {v: 0 for v in VERDICTS + [OVER_LIMIT]} for e in VERDICTS}
    for r in rows:
        confusion[r["expected"]][r["verdict"]] += 1
    none_rows = [r for r in rows if r["expected"] == "none"]
    false_alarms = sum(r["verdict"] != "none" for r in none_rows)
    named = [r for r in rows if r["verdict"] in PHYSICS and r["correct"]]
    onset_err = sorted(r["onset_error_s"] for r in named if r["onset_error_s"] is not None)
    ratios = sorted(r["rmse_before"] / max(r["rmse_after"], 1e-12) for r in rows if r["verdict"] in PHYSICS)
    secs = sorted(r["seconds"] for r in rows)
    cpus = sorted(r["cpu_seconds"] for r in rows if r["cpu_seconds"] is not None)
    wrong_physics = sum(r["verdict"] in PHYSICS and not r["correct"] for r in rows)
    med = lambda v: v[len(v) // 2] if v else None  # noqa: E731
    per_effect = {e: {"correct": sum(r["correct"] for r in rows if r["expected"] == e),
                      "cases": sum(r["expected"] == e for r in rows)} for e in VERDICTS}
    for e, v in per_effect.items():
        v["ci95"] = wilson(v["correct"], v["cases"])
    scores = {
        "cases": n, "accuracy": k / n if n else None, "accuracy_ci95": wilson(k, n),
        "per_effect": per_effect, "confusion": confusion,
        "false_alarms_on_none": f"{false_alarms} of {len(none_rows)}",
        "onset_error_s": {"median": med(onset_err), "max": onset_err[-1] if onset_err else None,
                          "within_0.5s": (sum(e <= 0.5 for e in onset_err) / len(onset_err)) if onset_err else None},
        "rmse_improvement": {"median": med(ratios), "min": ratios[0] if ratios else None,
                             "all_at_least_3x": all(x >= 3 for x in ratios) if ratios else None},
        "seconds_per_case": {"median": med(secs), "max": secs[-1] if secs else None},
        "cpu_seconds_per_case": {"median": med(cpus), "max": cpus[-1] if cpus else None},
        "wrong_physics_named": wrong_physics,
        "rows": rows,
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "scores.json").write_text(json.dumps(scores, indent=1))
    print(f"{'case':10} {'effect':15} {'verdict':15} {'start':>7} {'onset':>7} {'rmse before->after':>22} {'s':>6}")
    for r in rows:
        st = "-" if r["start_s"] is None else f"{r['start_s']:.2f}"
        on = "-" if r["onset_s"] is None else f"{r['onset_s']:.2f}"
        print(f"{r['case']:10} {r['effect']:15} {r['verdict']:15} {st:>7} {on:>7} "
              f"{r['rmse_before']:10.1f} -> {r['rmse_after']:8.1f} {r['seconds']:6.1f}{'' if r['correct'] else '  MISS'}")
    lo, hi = scores["accuracy_ci95"]
    print(f"accuracy {k}/{n} = {k / n:.3f} (95 % CI {lo:.2f}-{hi:.2f}); false alarms on none: {scores['false_alarms_on_none']}")
    for e, v in per_effect.items():
        if v["cases"]:
            print(f"  {e:15} {v['correct']}/{v['cases']}  (95 % CI {v['ci95'][0]:.2f}-{v['ci95'][1]:.2f})")
    print(f"onset error of named physics: {scores['onset_error_s']}")
    print(f"rmse improvement where a physics is named: {scores['rmse_improvement']}")
    print(f"wrong physics named: {wrong_physics}; CPU s per case: {scores['cpu_seconds_per_case']}")
    print(f"seconds per case: {scores['seconds_per_case']}")
    print(f"wrote {out_dir / 'scores.json'}")


if __name__ == "__main__":
    sys.exit(main())
