"""`make bench-scale`: the per-record stages of the demo study over a generated archive of
--tests tests (`shakeflow demo-archive --tests N`, above `--generate-up-to` that archive's variation
tests repeated as hard links; several sizes as `--tests 100,1000,10000`), through
the local executor and through the multi-node test Slurm (`tests/system/slurm.sh`), and a no-op
rerun of the whole archive.

Prints, per executor: wall time, work units run, wall time per unit, files created (artifacts
and lockfile, not shakeflow's state folder), their bytes, the state's size (the lockfile, now a
root, and every stage's state file in `.shakeflow/state/`), the commit's time and the planning
time (`run --dry-run`, on the empty output folder and on the committed state); for Slurm also
array tasks, the per-task overhead over the local run, each task's phases (its log: reading the run
and pipeline, the state, resolving sources and assessing, running, the manifest), the commit
job's time (Slurm's start/end, 1 s resolution), the state each array task read (its own log line: the root and its stage's and
upstream stages' state files), and whether both states (root and state files) are identical. The no-op
reruns: the first after the run reads the files the memo does not hold yet, the next ones are
what a user sees. Figures, not assertions: ARCHITECTURE.md's scale estimate uses them.

The local commit time is measured from `SHAKEFLOW_FAILPOINT=trace`'s `failpoint: commit.*`
lines on standard error, timestamped as they arrive: from the commit's first step to its last.

After the runs, per archive size: the engine's overhead per unit (a no-op rerun's wall time over
the units it checks), the state the array tasks read (the most and the mean over tasks, from
their logs, in a second Slurm run forcing `--force` and what follows; without Slurm, what a task of the largest stage would read: the root and that stage's
file, upstream stages aside), the hash memo (which tasks read too), and the most entries in one
folder of the output (what a shared file system lists).
"""
import argparse
import json
import os
import pathlib
import re
import shutil
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent


def project(folder: pathlib.Path, archive: pathlib.Path) -> pathlib.Path:
    """`folder`/pipeline.yaml: pipelines/demo.yaml reading `archive`, writing `folder`/out (both
    executors' projects have the same file name: it is part of every artifact's provenance)."""
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    text = (ROOT / "pipelines/demo.yaml").read_text().replace("../runs/demo-archive", str(archive))
    (folder / "pipeline.yaml").write_text(re.sub(r"(?m)^output_dir: .*$", "output_dir: out", text))
    return folder


def files_and_bytes(out: pathlib.Path):
    n, size = 0, 0
    for dirpath, dirnames, filenames in os.walk(out):
        if ".shakeflow" in pathlib.Path(dirpath).relative_to(out).parts[:1]:
            continue
        for f in filenames:
            n += 1
            size += (pathlib.Path(dirpath) / f).stat().st_size
    return n, size


def most_entries(out: pathlib.Path):
    """The largest folder of `out` (shakeflow's state aside): (entries, its path relative to out)."""
    best = (0, "")
    for dirpath, dirnames, filenames in os.walk(out):
        relative = pathlib.Path(dirpath).relative_to(out)
        if ".shakeflow" in relative.parts[:1]:
            continue
        best = max(best, (len(dirnames) + len(filenames), str(relative)))
    return best


def state_files(out: pathlib.Path):
    """The state: the lockfile (its root) and the per-stage state files, name → bytes."""
    files = {"shakeflow.lock": (out / "shakeflow.lock").read_bytes()}
    for f in sorted((out / ".shakeflow/state").glob("*.json")):
        files[f".shakeflow/state/{f.name}"] = f.read_bytes()
    return files


def state_units(out: pathlib.Path):
    """Units in the state: what a no-op checks."""
    return sum(len(json.loads(b)["units"]) for n, b in state_files(out).items() if n.endswith(".json"))


def task_logs(out: pathlib.Path):
    return set((out / ".shakeflow/slurm").glob("*/logs/*"))


def task_reads(out: pathlib.Path, seen=frozenset(), what="state"):
    """Bytes of state (or of the hash memo: `what="hash memo"`) each array task read, from its
    log line (`read N state file(s), B bytes`), in the logs not in `seen`."""
    reads = []
    for log in task_logs(out) - set(seen):
        for m in re.finditer(rf"read (\d+) {what} file\(s\), (\d+) bytes", log.read_text(errors="replace")):
            reads.append(int(m.group(2)))
    return reads


TASK_PHASES = ["run and pipeline read", "state read", "sources resolved and units assessed", "units ran", "manifest written"]


def task_phases(out: pathlib.Path, seen=frozenset()):
    """Each array task's phases from its log (`<stage> shard N: <phase> (at S s, C s CPU)`), in the
    logs not in `seen`: per phase, the wall seconds it took in each task (since the phase before),
    and under "planning" each task's seconds before its units ran."""
    took = {phase: [] for phase in TASK_PHASES + ["planning"]}
    for log in task_logs(out) - set(seen):
        at = dict.fromkeys(TASK_PHASES)
        for m in re.finditer(r" shard \d+: (.*) \(at ([\d.]+) s, [\d.]+ s CPU\)", log.read_text(errors="replace")):
            if m.group(1) in at:
                at[m.group(1)] = float(m.group(2))
        before = 0.0
        for phase in TASK_PHASES:
            if at[phase] is not None:
                took[phase].append(at[phase] - before)
                before = at[phase]
        if at["sources resolved and units assessed"] is not None:
            took["planning"].append(at["sources resolved and units assessed"])
    return took


def timed_run(cmd, cwd, env=None):
    """Runs cmd; returns (wall s, stderr lines with their arrival in s since the start, exit code)."""
    started = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    lines = [(time.monotonic() - started, line.rstrip("\n")) for line in proc.stderr]
    code = proc.wait()
    return time.monotonic() - started, lines, code


def units_ran(lines):
    return sum(int(m.group(1)) for _, l in lines for m in [re.search(r"done in .*?: (\d+) unit\(s\) ran", l)] if m)


def commit_steps(out: pathlib.Path, job: str):
    """The commit job's own log (`commit job: <step> (at S s, C s CPU)`): seconds to the commit's
    end and to the end of its clean-up (the `keep: false` files and the tasks' manifests), and
    CPU seconds."""
    steps = {}
    for log in (out / ".shakeflow/slurm").glob(f"*/logs/*_{job}_0.out"):
        for m in re.finditer(r"commit job: (.*) \(at ([\d.]+) s, ([\d.]+) s CPU\)", log.read_text(errors="replace")):
            steps[m.group(1)] = (float(m.group(2)), float(m.group(3)))
    nan = (float("nan"), float("nan"))
    return steps.get("committed", nan)[0], steps.get("results and manifests removed", nan)[0], steps.get("retries decided", nan)[1]


def slurm_times(job, env):
    out = subprocess.run(["scontrol", "-o", "show", "job", job], env=env, capture_output=True, text=True).stdout
    fields = dict(kv.split("=", 1) for kv in out.split() if "=" in kv)
    parse = lambda s: time.mktime(time.strptime(s, "%Y-%m-%dT%H:%M:%S"))
    return parse(fields["EndTime"]) - parse(fields["StartTime"])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shakeflow", required=True)
    ap.add_argument("--tests", default="200", help="archive sizes, comma-separated (100,1000)")
    ap.add_argument("--work", default="runs/bench-scale")
    ap.add_argument("--stages", default="synchronize", help="run these stages and what they need")
    ap.add_argument("--units-per-task", type=int, default=50)
    ap.add_argument("--noop-repeat", type=int, default=3)
    ap.add_argument("--no-slurm", action="store_true")
    ap.add_argument("--generate-up-to", type=int, default=1000,
                    help="larger archives repeat this size's variation tests under new ids, as hard links")
    ap.add_argument("--force", default="load_floors", help="the stage a second Slurm run forces, to measure what its tasks read")
    a = ap.parse_args()
    growth = []
    for tests in [int(t) for t in a.tests.split(",")]:
        growth.append((tests, measure(a, tests)))
    if len(growth) > 1:
        print("\ngrowth with the archive (local executor):")
        print(f"{'tests':>6} {'units':>6} {'wall s':>8} {'plan s':>7} {'commit s':>9} {'no-op s':>8} {'ms/unit':>8} "
              f"{'state KB/task':>14} {'memo KB':>8} {'memo KB/task':>13} {'most entries':>13} {'Slurm commit job s':>19} "
              f"{'task plan s (mean/max)':>23}")
        for tests, r in growth:
            print(f"{tests:6d} {r['units']:6d} {r['wall']:8.2f} {r['plan_fresh']:7.2f} {r['commit']:9.2f} {r['noop']:8.2f} "
                  f"{1000 * r['noop'] / max(r['checked'], 1):8.3f} {r['state'] / 1e3:14.1f} {r['memo'] / 1e3:8.1f} "
                  f"{r['memo_task'][2] / 1e3 if 'memo_task' in r else float('nan'):13.1f} {r['most'][0]:13d} "
                  f"{r.get('slurm_commit', float('nan')):19.0f} {task_plan(r):>23}")


def task_plan(r):
    """An array task's planning (everything before its units run), mean/max s, from its phases."""
    mean, most = r.get("task_phases", {}).get("planning", (None, None))
    return "-" if mean is None else f"{mean:.2f}/{most:.2f}"


def make_archive(shakeflow: str, works: pathlib.Path, tests: int, generate_up_to: int) -> pathlib.Path:
    """`works`/tests-N/archive, an archive of `tests` tests: generated (`demo-archive`) up to
    `generate_up_to` tests, above that the generated archive of `generate_up_to` tests with its
    variation tests repeated under new test ids (hard links: the same bytes under other names).
    The engine's work depends on how many files and units there are, not on what they hold; a
    generated 10⁴-test archive would take ≈ 22 GB and an hour to write. An archive made before
    (a stamp beside it) is used again."""
    work = works / f"tests-{tests}"
    archive, stamp = work / "archive", work / "archive.tests"
    if stamp.exists() and stamp.read_text() == str(tests) and archive.is_dir():
        return archive
    work.mkdir(parents=True, exist_ok=True)
    shutil.rmtree(archive, ignore_errors=True)
    if tests <= generate_up_to:
        subprocess.run([shakeflow, "demo-archive", str(archive), "--tests", str(tests)], check=True)
    else:
        base = make_archive(shakeflow, works, generate_up_to, generate_up_to)
        replicate(base, archive, tests - generate_up_to)
    stamp.write_text(str(tests))
    return archive


def replicate(base: pathlib.Path, archive: pathlib.Path, more: int):
    """`archive`: `base` hard-linked, and `more` tests besides: copy k of `base`'s variation
    tests (`Experiment-3/Trial-N`, files `V-NNNN_…`) as `Experiment-(3+k)/Trial-N`, files
    `V-kNNNN_…`, as many copies as it takes (the last one partial)."""
    shutil.copytree(base, archive, copy_function=os.link)
    groups = archive / "NEES-2009-0722.groups"
    trials = sorted((groups / "Experiment-3").iterdir(), key=lambda t: int(t.name.split("-")[1]))
    if not trials:
        sys.exit(f"{base}: no variation tests in Experiment-3 to repeat")
    k = 0
    while more > 0:
        k += 1
        for trial in trials[:more]:
            for f in sorted(trial.rglob("*")):
                if not f.is_file():
                    continue
                name = re.sub(r"^V-(\d+)", lambda m: f"V-{k}{m.group(1)}", f.name)
                dest = groups / f"Experiment-{3 + k}" / trial.name / f.parent.relative_to(trial) / name
                dest.parent.mkdir(parents=True, exist_ok=True)
                os.link(f, dest)
        more -= min(more, len(trials))


def measure(a, tests):
    """Runs the local (and Slurm) measurements on an archive of `tests` tests; prints them and
    returns the local figures."""
    shakeflow = str(pathlib.Path(a.shakeflow).resolve())
    work = pathlib.Path(a.work).resolve() / f"tests-{tests}"
    archive = make_archive(shakeflow, pathlib.Path(a.work).resolve(), tests, a.generate_up_to)
    stages = a.stages.split(",")
    report = {}

    # Local.
    local = project(work / "local", archive)
    # Planning: `run --dry-run` (sources hashed, every stage split into units and assessed),
    # on the empty output folder and, after the run, on its committed state.
    plan_fresh, _, _ = timed_run([shakeflow, "run", "pipeline.yaml", *stages, "--dry-run"], local)
    env = dict(os.environ, SHAKEFLOW_FAILPOINT="trace")
    wall, lines, code = timed_run([shakeflow, "run", "pipeline.yaml", *stages], local, env)
    if code != 0:
        sys.exit("local run failed:\n" + "\n".join(l for _, l in lines[-20:]))
    commit = [t for t, l in lines if l.startswith("failpoint: commit.")]
    n_files, n_bytes = files_and_bytes(local / "out")
    units = units_ran(lines)
    report["local"] = dict(
        wall=wall,
        units=units,
        files=n_files,
        bytes=n_bytes,
        lock=sum(len(b) for b in state_files(local / "out").values()),
        commit=commit[-1] - commit[0] if commit else float("nan"),
    )
    noops = []
    for _ in range(a.noop_repeat):
        w, lines, code = timed_run([shakeflow, "run", "pipeline.yaml", *stages, "-q"], local)
        if code != 0:
            sys.exit("no-op rerun failed:\n" + "\n".join(l for _, l in lines[-20:]))
        noops.append(w)
    w, lines, _ = timed_run([shakeflow, "status", "pipeline.yaml"], local)
    status_wall = w
    plan_committed, _, _ = timed_run([shakeflow, "run", "pipeline.yaml", *stages, "--dry-run"], local)
    memo = [local / "out/.shakeflow/hashes.json", *(local / "out/.shakeflow/hashes").glob("*.json")]
    report["local"].update(
        noop=min(noops),
        plan_fresh=plan_fresh,
        plan_committed=plan_committed,
        # Every unit of the covered stages is checked by a no-op: the state's entries.
        checked=state_units(local / "out"),
        memo=sum(f.stat().st_size for f in memo if f.exists()),
        # Without Slurm: what a task of the largest stage reads (the root and that stage's file).
        state=max((len(b) for n, b in state_files(local / "out").items() if n.endswith(".json")), default=0)
        + (local / "out/shakeflow.lock").stat().st_size,
        state_mean=float("nan"),
        most=most_entries(local / "out"),
    )
    # The local outputs go before the Slurm runs (at 10⁴ tests 13 GB, beside the Slurm run's
    # and its scratch); their state stays, to compare.
    local_state = state_files(local / "out")
    shutil.rmtree(local / "out")

    # Slurm.
    slurm_sh = ROOT / "tests/system/slurm.sh"
    started_slurm = False
    if not a.no_slurm:
        if subprocess.run(["sh", str(slurm_sh), "status"], capture_output=True).returncode != 0:
            subprocess.run(["sh", str(slurm_sh), "start"], check=True)
            started_slurm = True
        try:
            conf = pathlib.Path(os.environ.get("SHAKEFLOW_SLURM_DIR", pathlib.Path.home() / ".cache/shakeflow/slurm"))
            env = dict(os.environ, SLURM_CONF=str(conf / "slurm.conf"))
            cluster = project(work / "slurm", archive)
            cmd = [shakeflow, "run", "pipeline.yaml", *stages, "--executor", "slurm", "--wait"]
            cmd += ["--units-per-task", str(a.units_per_task)]
            wall, lines, code = timed_run(cmd, cluster, env)
            if code != 0:
                sys.exit("Slurm run failed:\n" + "\n".join(l for _, l in lines[-30:]))
            submit = next(t for t, l in lines if "submitted (commit job" in l)
            tasks = sum(int(m.group(1)) for _, l in lines for m in [re.search(r"submitted: (\d+) of", l)] if m)
            commit_job = next(re.search(r"commit job (\d+)", l).group(1) for _, l in lines if "commit job" in l)
            n_files, n_bytes = files_and_bytes(cluster / "out")
            same = state_files(cluster / "out") == local_state
            # What a task reads of a committed state: a rerun from `--force STAGE` on (the first
            # run's tasks found no state yet).
            seen = task_logs(cluster / "out")
            _, forced, code = timed_run(cmd + ["--force", a.force], cluster, env)
            if code != 0:
                sys.exit("forced Slurm rerun failed:\n" + "\n".join(l for _, l in forced[-30:]))
            reads = task_reads(cluster / "out", seen)
            if reads:
                report["local"].update(state=max(reads), state_mean=sum(reads) / len(reads), state_min=min(reads))
            phases = task_phases(cluster / "out", seen)
            memo_reads = task_reads(cluster / "out", seen, "hash memo")
            if memo_reads:
                report["local"].update(memo_task=(min(memo_reads), sum(memo_reads) / len(memo_reads), max(memo_reads)))
            report["slurm"] = dict(
                wall=wall,
                units=report["local"]["units"],
                files=n_files,
                bytes=n_bytes,
                lock=sum(len(b) for b in state_files(cluster / "out").values()),
                commit=slurm_times(commit_job, env),
                steps=commit_steps(cluster / "out", commit_job),
                tasks=tasks,
                submit=submit,
                same=same,
                phases=phases,
            )
        finally:
            if started_slurm:
                subprocess.run(["sh", str(slurm_sh), "stop"])

    print(f"\nbench-scale: {tests} tests, stages {', '.join(stages)} and what they need ({shakeflow})")
    print(f"{'':8} {'wall s':>8} {'units':>6} {'ms/unit':>8} {'files':>6} {'MB':>8} {'state KB':>8} {'commit s':>9}")
    for name, r in report.items():
        print(
            f"{name:8} {r['wall']:8.2f} {r['units']:6d} {1000 * r['wall'] / max(r['units'], 1):8.2f} {r['files']:6d} "
            f"{r['bytes'] / 1e6:8.1f} {r['lock'] / 1e3:8.1f} {r['commit']:9.2f}"
        )
    if "slurm" in report:
        s, l = report["slurm"], report["local"]
        print(
            f"slurm: {s['tasks']} array task(s) + 1 commit job, submitted in {s['submit']:.2f} s; "
            f"overhead over local {(s['wall'] - l['wall']) / max(s['tasks'], 1):.2f} s per task; "
            f"state (root and state files) {'identical to' if s['same'] else 'DIFFERENT from'} the local run's"
        )
        committed, cleaned, cpu = s["steps"]
        print(
            f"commit job (its log): committed at {committed:.2f} s, clean-up done at {cleaned:.2f} s, "
            f"{cpu:.2f} s CPU"
        )
        phases = [(p, t) for p, t in s["phases"].items() if t]
        print(
            "an array task's phases in the forced rerun, wall s mean / max over its tasks: "
            + "; ".join(f"{p} {sum(t) / len(t):.3f} / {max(t):.3f}" for p, t in phases)
        )
        report["local"]["slurm_commit"] = s["commit"]
        report["local"]["task_phases"] = {p: (sum(t) / len(t), max(t)) for p, t in phases}
    print("no-op reruns: " + ", ".join(f"{w:.2f} s" for w in noops) + f"; status {status_wall:.2f} s")
    print(f"planning (`run --dry-run`): {plan_fresh:.2f} s on the empty output folder, "
          f"{plan_committed:.2f} s on the committed state")
    r = report["local"]
    print(
        f"engine overhead per unit (no-op / units checked): {1000 * r['noop'] / max(r['checked'], 1):.3f} ms "
        f"({r['checked']} units); state a task reads: {r.get('state_min', float('nan')) / 1e3:.1f}–{r['state'] / 1e3:.1f} KB, "
        f"mean {r['state_mean'] / 1e3:.1f} KB of {r['lock'] / 1e3:.1f} KB "
        f"(root + its stage's and upstream stages' files); the hash memo {r['memo'] / 1e3:.1f} KB, of which a task "
        f"reads {'–'.join(f'{b / 1e3:.1f}' for b in r['memo_task'][::2]) if 'memo_task' in r else '?'} KB "
        f"(mean {r['memo_task'][1] / 1e3 if 'memo_task' in r else float('nan'):.1f}); "
        f"most entries in one folder: {r['most'][0]} (`{r['most'][1]}`)"
    )
    return r


if __name__ == "__main__":
    main()
