#!/usr/bin/env python3
"""Scores the `calibration` of `shakeflow diagnose` against the truth of mis-stated cases.

    python prove/calibration.py CASES_DIR DIAGNOSIS_DIR [--json FILE]

CASES_DIR holds <case>/ folders and truth/<case>.yaml whose `misstated` block gives, per
parameter, the `true` value the records were made with, the `stated` one and the `sd` (lists
element-wise); DIAGNOSIS_DIR holds <case>/diagnosis.json. For every parameter element stated off
by >= 1 sd it asks whether `fitted` is at least twice as close to the truth as the stated value
(the issue's calibration goal: >= 80 % of those the records constrain), and prints every element
with stated, fitted and true values side by side, with Wilson 95 % intervals.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from score import wilson  # noqa: E402

# Parameters the records cannot constrain, and why (the rocking equations hold I0/m only).
UNCONSTRAINED = {"mass_kg": "rocking is mass-independent"}


def elements(value):
    return value if isinstance(value, list) else [value]


def rows(case_id: str, truth: dict, diagnosis: dict) -> list[dict]:
    """One row per mis-stated parameter element."""
    out = []
    calibration = diagnosis.get("calibration") or {}
    for key, m in (truth.get("misstated") or {}).items():
        fitted = calibration.get(key, {}).get("fitted")
        for i, (true, stated, sd) in enumerate(zip(elements(m["true"]), elements(m["stated"]), elements(m["sd"]))):
            f = elements(fitted)[i] if fitted is not None else None
            off = abs(stated - true) / sd
            row = {"case": case_id, "parameter": key if not isinstance(m["true"], list) else f"{key}[{i}]",
                   "true": true, "stated": stated, "sd": sd, "fitted": f, "stated_off_sd": off,
                   "fitted_off_sd": None if f is None else abs(f - true) / sd,
                   "constrained": key not in UNCONSTRAINED, "verdict": diagnosis.get("verdict")}
            row["twice_as_close"] = f is not None and abs(f - true) <= 0.5 * abs(stated - true)
            out.append(row)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cases_dir", type=Path)
    ap.add_argument("diagnosis_dir", type=Path)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    all_rows = []
    for truth_path in sorted((args.cases_dir / "truth").glob("*.yaml")):
        case_id = truth_path.stem
        diag_path = args.diagnosis_dir / case_id / "diagnosis.json"
        if not diag_path.is_file():
            continue
        truth = yaml.safe_load(truth_path.read_text())
        if not isinstance(truth, dict) or "misstated" not in truth:
            continue
        all_rows.extend(rows(case_id, truth, json.loads(diag_path.read_text())))
    if not all_rows:
        sys.exit("no mis-stated case with a diagnosis found")
    print(f"{'case':<10}{'parameter':<18}{'true':>11}{'stated':>11}{'fitted':>11}{'off sd':>8}{'→ sd':>7}  2x closer")
    for r in all_rows:
        fitted = "-" if r["fitted"] is None else f"{r['fitted']:.5g}"
        after = "-" if r["fitted_off_sd"] is None else f"{r['fitted_off_sd']:.2f}"
        print(f"{r['case']:<10}{r['parameter']:<18}{r['true']:>11.5g}{r['stated']:>11.5g}{fitted:>11}"
              f"{r['stated_off_sd']:>8.2f}{after:>7}  {'yes' if r['twice_as_close'] else 'no'}"
              + ("" if r["constrained"] else f"  (unconstrained: {UNCONSTRAINED[r['parameter'].split('[')[0]]})"))
    goal = [r for r in all_rows if r["stated_off_sd"] >= 1.0 and r["constrained"]]
    k = sum(r["twice_as_close"] for r in goal)
    ci = wilson(k, len(goal))
    print(f"\nstated off by >= 1 sd (constrained): {len(goal)}; fitted at least twice as close to the truth: {k}"
          + (f" = {k / len(goal):.0%}, 95 % [{ci[0]:.2f}, {ci[1]:.2f}]" if goal else ""))
    allk = sum(r["twice_as_close"] for r in all_rows)
    print(f"all mis-stated elements: {allk}/{len(all_rows)} fitted at least twice as close")
    if args.json:
        args.json.write_text(json.dumps({"rows": all_rows, "goal": {"n": len(goal), "twice_as_close": k,
                                                                      "ci95": ci}}, indent=1) + "\n")


if __name__ == "__main__":
    main()
