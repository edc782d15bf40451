# Merges the mis-stated seed-4401 rolling diagnoses of two scorer runs (A: case order, B: reverse
# order through symlinks b00..b07) into one score; CPU from watch.json (/proc polling, 1 s).
import json, sys, os
sys.path.insert(0, "/work/wt-33/prove/rolling"); sys.path.insert(0, "/work/wt-33/prove")
import yaml
from score import wilson  # prove/rolling/score.py
PHYSICS = {"lateral_impact", "mass_change", "caster_brake", "swivel_jam"}
watch = json.load(open("/tmp/p33/watch.json"))
b = {f"b{i:02d}": c for i, c in enumerate(["case_11","case_10","case_09","case_08","case_07","case_06","case_00","case_01"])}
running = {k.split(" -> ")[1] for k in watch}  # out paths seen
os.makedirs("/tmp/p33/merged", exist_ok=True)
rows = {}
def add(case, out, cpu):
    p = f"{out}/diagnosis.json"
    if not os.path.isfile(p) or case in rows: return
    d = json.load(open(p)); t = yaml.safe_load(open(f"/tmp/p33/mis/truth/{case}.yaml"))
    link = f"/tmp/p33/merged/{case}"
    if not os.path.exists(link): os.symlink(out, link)
    rows[case] = {"case": case, "effect": t["effect"], "expected": t["expected_verdict"], "verdict": d["verdict"],
                  "mismatch": d["mismatch"], "correct": d["verdict"] == t["expected_verdict"], "cpu_seconds": cpu,
                  "window": d["window"], "rmse_before": d["rmse_before"], "rmse_after": d["rmse_after"],
                  "candidates": [(c["effect"], c.get("evaluations"), c.get("signature_chi2")) for c in d["candidates"]]}
cpu_of = {k.split(" -> ")[1]: v for k, v in watch.items()}
for i in range(12):
    c = f"case_{i:02d}"; out = f"/tmp/p33/score-mis/diagnosis/{c}"
    done_in_a = os.path.isfile(f"{out}/diagnosis.json")
    cpu = cpu_of.get(out)  # None: finished before the watcher started
    if done_in_a: add(c, out, cpu)
for bn, c in b.items():
    add(c, f"/tmp/p33/score-mis-b/diagnosis/{bn}", cpu_of.get(f"/tmp/p33/score-mis-b/diagnosis/{bn}"))
R = sorted(rows.values(), key=lambda r: r["case"])
n = len(R); k = sum(r["correct"] for r in R)
classes = ["none", "lateral_impact", "mass_change", "caster_brake", "swivel_jam", "unexplained"]
per = {e: {"correct": sum(r["correct"] for r in R if r["expected"] == e), "cases": sum(r["expected"] == e for r in R)} for e in classes}
for v in per.values(): v["ci95"] = wilson(v["correct"], v["cases"])
cpus = sorted(r["cpu_seconds"] for r in R if r["cpu_seconds"] is not None)
med = (cpus[(len(cpus)-1)//2] + cpus[len(cpus)//2]) / 2 if cpus else None
out = {"seed": 4401, "cases_diagnosed": n, "of": 12, "accuracy": k / n if n else None, "correct": k, "accuracy_ci95": wilson(k, n),
       "per_effect": per, "false_alarms_on_none": f"{sum(r['verdict'] != 'none' for r in R if r['expected']=='none')} of {sum(r['expected']=='none' for r in R)}",
       "wrong_physics_named": sum(r["verdict"] in PHYSICS and not r["correct"] for r in R),
       "cpu_seconds_per_case": {"median": med, "max": cpus[-1] if cpus else None, "measured": len(cpus)}, "rows": R}
json.dump(out, open(sys.argv[1], "w"), indent=1)
for r in R: print(r["case"], r["effect"], r["verdict"], r["cpu_seconds"])
print({k: v for k, v in out.items() if k != "rows"})
