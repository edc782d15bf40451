#!/usr/bin/env python3
"""Mis-states the nominal parameters of generated cases, as a user's estimates are.

    python prove/misstate.py CASES_DIR OUT_DIR [--seed N]

Copies every case of CASES_DIR (prove/generate_cases.py or prove/rolling/generate.py output) to
OUT_DIR with its `equipment.yaml` stating each uncertain parameter off by 0.5-1.5 of its
standard deviation (sign and size drawn per element), and the `uncertainty` block that says how
well each is known. Rocking: `f` {sd: 0.03}, `H_m` and `B_m` {rel_sd: 0.01}; rolling: the four
friction coefficients {rel_sd: 0.2}, `steer0_deg` {sd: 8}, `yaw0_deg` {sd: 1},
`platform_mass_kg` {rel_sd: 0.05} (a relative sd is drawn relative to the true value and stated
relative to the stated one, as a user would write it). The records are untouched. `truth/` is
copied with `misstated` added per case: for each parameter its `true` value, the `stated` one and
the `sd` used (lists element-wise), what prove/calibration.py scores. The `derived` and
`e_formula` sheets of a rocking file are dropped (they were computed from the true values).
"""
from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import numpy as np
import yaml

ROCKING = {"f": ("sd", 0.03), "H_m": ("rel_sd", 0.01), "B_m": ("rel_sd", 0.01)}
ROLLING = {"mu_s_roll": ("rel_sd", 0.2), "mu_k_roll": ("rel_sd", 0.2), "mu_s_swivel": ("rel_sd", 0.2),
           "mu_k_swivel": ("rel_sd", 0.2), "steer0_deg": ("sd", 8.0), "yaw0_deg": ("sd", 1.0),
           "platform_mass_kg": ("rel_sd", 0.05)}


def misstate(rng: np.random.Generator, equipment: dict) -> tuple[dict, dict]:
    """The equipment with mis-stated values and its uncertainty block, and the truth's `misstated`."""
    table = ROLLING if equipment.get("model") == "rolling" else ROCKING
    stated, record, block = dict(equipment), {}, {}
    for key, (kind, size) in table.items():
        if key not in equipment:
            continue
        true = equipment[key]
        values = true if isinstance(true, list) else [true]
        sds = [size if kind == "sd" else size * abs(v) for v in values]
        moved = [round(float(v + rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 1.5) * sd), 6)
                 for v, sd in zip(values, sds)]
        stated[key] = moved if isinstance(true, list) else moved[0]
        record[key] = {"true": true, "stated": stated[key], "sd": sds if isinstance(true, list) else sds[0]}
        block[key] = {kind: size}
    for descriptive in ("derived", "e_formula"):
        stated.pop(descriptive, None)
    stated["uncertainty"] = block
    return stated, record


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cases_dir", type=Path)
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.out_dir.exists() and any(args.out_dir.iterdir()):
        sys.exit(f"error: {args.out_dir} is not empty")
    cases = sorted(p for p in args.cases_dir.iterdir() if (p / "equipment.yaml").is_file())
    if not cases:
        sys.exit(f"error: no cases in {args.cases_dir}")
    rng = np.random.default_rng([args.seed, 33])
    shutil.copytree(args.cases_dir / "truth", args.out_dir / "truth")
    for case in cases:
        shutil.copytree(case, args.out_dir / case.name)
        equipment = yaml.safe_load((case / "equipment.yaml").read_text())
        stated, record = misstate(rng, equipment)
        (args.out_dir / case.name / "equipment.yaml").write_text(yaml.safe_dump(stated, sort_keys=False, width=110))
        truth_path = args.out_dir / "truth" / f"{case.name}.yaml"
        truth = yaml.safe_load(truth_path.read_text())
        truth["misstated"] = record
        truth_path.write_text(yaml.safe_dump(truth, sort_keys=False, width=110))
    print(f"{len(cases)} cases mis-stated -> {args.out_dir}")


if __name__ == "__main__":
    main()
