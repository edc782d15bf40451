#!/usr/bin/env python3
"""Score `shakeflow diagnose` on a set of concealed-effect cases.

    python prove/score.py CASES_DIR --shakeflow PATH_TO_BINARY [--jobs 2] [--out DIR] [--scores FILE]

Runs `shakeflow diagnose CASES_DIR/<case> --out OUT/<case>` for every case (OUT defaults to
CASES_DIR/../diagnosis), reads OUT/<case>/diagnosis.json and compares it with CASES_DIR/truth/.
Prints the confusion matrix (true effect x verdict), accuracy, the false-alarm rate on `none`
cases, the onset error of physics verdicts, the fit improvement and the run time per case, and
writes them to a JSON file (default CASES_DIR/../scores.json). Exits non-zero if the binary fails
on a case or breaks the diagnosis.json contract.
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import yaml

VERDICTS = ("none", "sliding", "mass_change", "restitution", "flexibility", "obstacle_impact", "ambiguous",
            "sensor_tilt", "unexplained")
PHYSICS = ("sliding", "mass_change", "restitution", "flexibility", "obstacle_impact", "sensor_tilt")
ONSET_OK_S = 0.5
FIT_FACTOR = 3.0


def contract_errors(d) -> list[str]:
    """What diagnosis.json lacks of the contract."""
    if not isinstance(d, dict):
        return ["not a JSON object"]
    errors = []
    if not isinstance(d.get("mismatch"), bool):
        errors.append("`mismatch` is not a boolean")
    if d.get("verdict") not in VERDICTS:
        errors.append(f"`verdict` {d.get('verdict')!r} is not one of {', '.join(VERDICTS)}")
    w = d.get("window", "missing")
    if not (w is None or (isinstance(w, dict) and all(_number(w.get(k)) for k in ("start_s", "end_s")))):
        errors.append("`window` is neither null nor {start_s, end_s}")
    for key in ("rmse_before", "rmse_after"):
        if key not in d or not (d[key] is None or _number(d[key])):
            errors.append(f"`{key}` is missing or not a number")
    cands = d.get("candidates")
    if not isinstance(cands, list) or not all(
            isinstance(c, dict) and {"effect", "params", "rmse", "score"} <= set(c) for c in cands):
        errors.append("`candidates` is not a list of {effect, params, rmse, score}")
    if not isinstance(d.get("explanation"), str):
        errors.append("`explanation` is not a string")
    return errors


def _number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


# Runs a command and says on its last stderr line the CPU seconds (user + sys) it took: wall time
# on a shared machine says little.
CPU_WRAPPER = ("import resource, subprocess, sys\n"
               "code = subprocess.run(sys.argv[1:]).returncode\n"
               "u = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
               "print(f'cpu_seconds {u.ru_utime + u.ru_stime:.3f}', file=sys.stderr)\n"
               "sys.exit(code)\n")


def cpu_seconds(stderr: str) -> float | None:
    """The CPU seconds CPU_WRAPPER reported (None: it did not)."""
    lines = (stderr or "").strip().splitlines()
    if lines and lines[-1].startswith("cpu_seconds "):
        return float(lines[-1].split()[1])
    return None


def run_case(binary: str, case_dir: Path, out_dir: Path, timeout: float) -> dict:
    started = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-c", CPU_WRAPPER, binary, "diagnose", str(case_dir),
                               "--out", str(out_dir)], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout:.0f} s", "seconds": time.perf_counter() - started}
    except OSError as exc:
        return {"error": f"could not run {binary}: {exc}", "seconds": 0.0}
    seconds = time.perf_counter() - started
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-5:]
        return {"error": f"exit code {proc.returncode}: " + " | ".join(tail), "seconds": seconds}
    path = out_dir / "diagnosis.json"
    try:
        diagnosis = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        return {"error": f"no readable {path}: {exc}", "seconds": seconds}
    errors = contract_errors(diagnosis)
    if errors:
        return {"error": f"{path} breaks the contract: " + "; ".join(errors), "seconds": seconds}
    return {"diagnosis": diagnosis, "seconds": seconds, "cpu_seconds": cpu_seconds(proc.stderr)}


def wilson(k: int, n: int, z: float = 1.959964) -> tuple[float, float] | None:
    """Wilson's score interval (95 %) for k successes in n trials: with the few cases per effect
    a set holds, a recall is only known to within this, and two sets (or a set and a held-out
    benchmark) agree when their intervals overlap."""
    if n == 0:
        return None
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


def summary(values: list[float]) -> dict | None:
    if not values:
        return None
    return {"n": len(values), "median": statistics.median(values), "max": max(values), "mean": statistics.fmean(values)}


def score(cases: list[dict]) -> dict:
    """The metrics over the cases that ran (each: case_id, truth, diagnosis, seconds)."""
    confusion = {t: {v: 0 for v in VERDICTS} for t in VERDICTS}
    onset_err, visible_err, missing_window, ratios, per_case = [], [], 0, [], []
    for c in cases:
        truth, diag = c["truth"], c["diagnosis"]
        effect, verdict = truth["effect"], diag["verdict"]
        confusion[effect][verdict] += 1
        row = {"case_id": c["case_id"], "effect": effect, "verdict": verdict, "mismatch": diag["mismatch"],
               "correct": verdict == truth["expected_verdict"], "seconds": c["seconds"],
               "cpu_seconds": c.get("cpu_seconds")}
        if verdict in PHYSICS and truth.get("onset_s") is not None:
            if diag["window"] is None:
                missing_window += 1
            else:
                row["onset_error_s"] = abs(diag["window"]["start_s"] - truth["onset_s"])
                onset_err.append(row["onset_error_s"])
                if truth.get("window"):
                    visible_err.append(abs(diag["window"]["start_s"] - truth["window"]["start_s"]))
        if verdict in PHYSICS and _number(diag["rmse_before"]) and _number(diag["rmse_after"]):
            row["fit_improvement"] = diag["rmse_before"] / diag["rmse_after"] if diag["rmse_after"] > 0 else math.inf
            ratios.append(row["fit_improvement"])
        per_case.append(row)
    none_cases = [r for r in per_case if r["effect"] == "none"]
    false_alarms = [r for r in none_cases if r["mismatch"] or r["verdict"] != "none"]
    recall = {t: (confusion[t][t] / n if (n := sum(confusion[t].values())) else None) for t in VERDICTS}
    recall_ci = {t: wilson(confusion[t][t], sum(confusion[t].values())) for t in VERDICTS}
    correct = sum(r["correct"] for r in per_case)
    times = [c["seconds"] for c in cases]
    return {
        "n_cases": len(cases),
        "accuracy": sum(r["correct"] for r in per_case) / len(per_case) if per_case else None,
        "accuracy_ci95": wilson(correct, len(per_case)),
        "recall_per_effect": recall,
        "recall_ci95_per_effect": recall_ci,
        "correct_per_effect": {t: [confusion[t][t], sum(confusion[t].values())] for t in VERDICTS},
        "false_alarm_rate_none": len(false_alarms) / len(none_cases) if none_cases else None,
        "confusion": confusion,
        "onset_error_s": {**(summary(onset_err) or {"n": 0}),
                          "fraction_within_0.5_s": (sum(e <= ONSET_OK_S for e in onset_err) / len(onset_err)
                                                    if onset_err else None),
                          "physics_verdicts_without_window": missing_window},
        "onset_error_vs_visible_start_s": summary(visible_err),
        "fit_improvement": {**(summary(ratios) or {"n": 0}),
                            "fraction_rmse_after_le_third": (sum(r >= FIT_FACTOR for r in ratios) / len(ratios)
                                                             if ratios else None)},
        "seconds_per_case": summary(times),
        "cpu_seconds_per_case": summary([c["cpu_seconds"] for c in cases if c.get("cpu_seconds") is not None]),
        "cases": per_case,
    }


def finite(x):
    """JSON has no infinity: a perfect fit (rmse_after = 0) is written as null."""
    if isinstance(x, dict):
        return {k: finite(v) for k, v in x.items()}
    if isinstance(x, list):
        return [finite(v) for v in x]
    return None if isinstance(x, float) and not math.isfinite(x) else x


def fmt(x, spec=".3f") -> str:
    return "-" if x is None else format(x, spec)


def report(s: dict, failures: list[tuple[str, str]]):
    short = {v: v[:8] for v in VERDICTS}
    print("\nconfusion matrix (rows: concealed effect, columns: verdict)")
    print(f"{'':>16}" + "".join(f"{short[v]:>9}" for v in VERDICTS) + f"{'recall':>9}  95 % (Wilson)")
    for t in VERDICTS:
        row = s["confusion"][t]
        if sum(row.values()) == 0:
            continue
        ci = s["recall_ci95_per_effect"][t]
        print(f"{t:>16}" + "".join(f"{row[v] or '.':>9}" for v in VERDICTS) + f"{fmt(s['recall_per_effect'][t], '.2f'):>9}"
              + f"  [{ci[0]:.2f}, {ci[1]:.2f}]")
    o, f, tm = s["onset_error_s"], s["fit_improvement"], s["seconds_per_case"]
    ci = s["accuracy_ci95"]
    print(f"\naccuracy                 {fmt(s['accuracy'])}  ({s['n_cases']} cases)"
          + (f"  95 % [{ci[0]:.3f}, {ci[1]:.3f}]" if ci else ""))
    print(f"false-alarm rate (none)  {fmt(s['false_alarm_rate_none'])}")
    print(f"onset error, physics verdicts: n {o['n']}, median {fmt(o.get('median'))} s, max {fmt(o.get('max'))} s, "
          f"within {ONSET_OK_S} s {fmt(o['fraction_within_0.5_s'])}"
          + (f", {o['physics_verdicts_without_window']} without a window" if o["physics_verdicts_without_window"] else ""))
    v = s["onset_error_vs_visible_start_s"]
    if v:
        print(f"  (against the truth window's start, the first visible difference: median {fmt(v['median'])} s, "
              f"max {fmt(v['max'])} s)")
    print(f"fit improvement rmse_before/rmse_after, physics verdicts: n {f['n']}, median {fmt(f.get('median'), '.2f')}, "
          f"rmse_after <= rmse_before/{FIT_FACTOR:g}: {fmt(f['fraction_rmse_after_le_third'], '.2f')}")
    if tm:
        print(f"run time per case        median {tm['median']:.2f} s, max {tm['max']:.2f} s, mean {tm['mean']:.2f} s")
    cpu = s.get("cpu_seconds_per_case")
    if cpu:
        print(f"CPU time per case        median {cpu['median']:.2f} s, max {cpu['max']:.2f} s, mean {cpu['mean']:.2f} s")
    for case_id, error in failures:
        print(f"FAILED {case_id}: {error}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cases_dir", type=Path)
    ap.add_argument("--shakeflow", required=True, help="the shakeflow binary (or anything with the same CLI)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, help="where the diagnoses go (default CASES_DIR/../diagnosis)")
    ap.add_argument("--scores", type=Path, help="the JSON report (default CASES_DIR/../scores.json)")
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds allowed per case")
    args = ap.parse_args()
    cases_dir = args.cases_dir
    truth_dir = cases_dir / "truth"
    case_ids = sorted(p.name for p in cases_dir.iterdir() if (p / "equipment.yaml").is_file()) if cases_dir.is_dir() else []
    if not case_ids or not truth_dir.is_dir():
        sys.exit(f"error: no cases in {cases_dir} (expected <case>/equipment.yaml and truth/); "
                 f"generate them with prove/generate_cases.py")
    out = args.out or cases_dir.parent / "diagnosis"
    scores_path = args.scores or cases_dir.parent / "scores.json"
    truths = {c: yaml.safe_load((truth_dir / f"{c}.yaml").read_text()) for c in case_ids}
    print(f"diagnosing {len(case_ids)} cases with {args.shakeflow} ({args.jobs} at a time) -> {out}", flush=True)

    def one(case_id):
        result = run_case(args.shakeflow, cases_dir / case_id, out / case_id, args.timeout)
        state = "FAILED" if "error" in result else result["diagnosis"]["verdict"]
        cpu = result.get("cpu_seconds")
        cpu = f"  {cpu:6.2f} s CPU" if cpu is not None else ""
        print(f"  {case_id}  {result['seconds']:6.2f} s{cpu}  {state}", flush=True)
        return case_id, result

    with ThreadPoolExecutor(max(1, args.jobs)) as pool:
        results = dict(pool.map(one, case_ids))
    failures = [(c, r["error"]) for c, r in results.items() if "error" in r]
    ran = [{"case_id": c, "truth": truths[c], **r} for c, r in results.items() if "error" not in r]
    s = score(ran)
    s["failures"] = [{"case_id": c, "error": e} for c, e in failures]
    s["shakeflow"] = args.shakeflow
    s["cases_dir"] = str(cases_dir)
    report(s, failures)
    scores_path.parent.mkdir(parents=True, exist_ok=True)
    scores_path.write_text(json.dumps(finite(s), indent=1) + "\n")
    print(f"\nscores -> {scores_path}")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
