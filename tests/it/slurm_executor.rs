//! The Slurm executor against the real test Slurm of `tests/system/slurm.sh` (`make test`
//! starts it): the same artifacts and lockfile as a local run, a failed record failing its unit
//! only, a cancelled task's shard the only one a rerun submits, and `status` during a run.

use crate::common::*;
use std::path::Path;
use std::process::Output;
use std::time::{Duration, Instant};

fn slurm_run(root: &Path, args: &[&str]) -> Output {
    slurm_run_env(root, args, &[])
}

/// `slurm_run` with extra environment variables (which the jobs inherit: sbatch exports them).
fn slurm_run_env(root: &Path, args: &[&str], env: &[(&str, &str)]) -> Output {
    let conf = test_slurm_conf();
    test_slurm(); // fails, saying how to start it, when the test Slurm is not running
    let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_shakeflow"));
    command.args([&["run", "pipeline.yaml", "--executor", "slurm", "--units-per-task", "1"], args].concat());
    command.envs(env.iter().copied());
    command.current_dir(root).env("SLURM_CONF", conf).output().unwrap()
}

/// The job id of stage `stage`'s array, from the submit line `<stage> submitted: … (<job id>)`.
fn array_job(log: &str, stage: &str) -> String {
    let line = log.lines().find(|l| l.starts_with(&format!("{stage} "))).unwrap_or_else(|| panic!("{log}"));
    line.rsplit('(').next().unwrap().trim_end_matches(')').to_string()
}

/// `scontrol show job <job>` (finished jobs stay known for MinJobAge).
fn show_job(job: &str) -> String {
    let out = std::process::Command::new("scontrol")
        .args(["show", "job", job])
        .env("SLURM_CONF", test_slurm_conf())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    stdout(&out)
}

fn status_text(root: &Path) -> String {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_shakeflow"))
        .args(["status", "pipeline.yaml"])
        .current_dir(root)
        .env("SLURM_CONF", test_slurm_conf())
        .output()
        .unwrap();
    stdout(&out)
}

/// Waits until no Slurm run holds the folder (its commit job released the lease).
fn wait_for_commit(root: &Path) {
    let started = Instant::now();
    while root.join("out/.shakeflow/lease").exists() {
        assert!(started.elapsed() < Duration::from_secs(120), "the Slurm run did not commit within 2 minutes");
        std::thread::sleep(Duration::from_millis(200));
    }
}

#[test]
fn a_slurm_run_writes_the_local_runs_artifacts_and_lockfile() {
    let local = small_project_run_locally();
    let cluster = small_project();
    let out = slurm_run(cluster.path(), &["--wait"]);
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    assert!(log.contains("load               submitted: 2 of 2 shard(s)"), "{log}");
    assert!(show_job(&array_job(&log, "load")).contains("Requeue=0"), "submitted --no-requeue by default");
    assert_eq!(
        artifacts_and_state(local.path()),
        artifacts_and_state(cluster.path()),
        "bit-identical artifacts, lockfile and state files"
    );
    assert!(!cluster.path().join("out/.shakeflow/lease").exists(), "the commit job released the lease");
    // Up to date afterwards, by either executor.
    let again = slurm_run(cluster.path(), &[]);
    assert!(stderr(&again).contains("nothing submitted"), "{}", stderr(&again));
    assert!(stderr(&shakeflow(&["run", "pipeline.yaml"], cluster.path())).contains("2 cached"));
}

#[test]
fn a_fanned_out_slurm_run_writes_the_local_fanned_runs_artifacts_and_state() {
    // Past one record a folder, records go one folder down (two hex digits): the submitting
    // process decides, and the array tasks and the commit job follow (`run.json`).
    let fan_out = [("SHAKEFLOW_FAN_OUT_ABOVE", "1")];
    let local = small_project();
    let out = shakeflow_env(&["run", "pipeline.yaml"], local.path(), &fan_out);
    assert!(out.status.success(), "{}", stderr(&out));
    let cluster = small_project();
    let out = slurm_run_env(cluster.path(), &["--wait"], &fan_out);
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    for stage in ["load", "baseline"] {
        let records = cluster.path().join("out").join(stage).join("records");
        let folders: Vec<String> = std::fs::read_dir(&records)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(!folders.is_empty() && folders.iter().all(|f| f.len() == 2 && !f.contains('=')), "{folders:?}");
    }
    assert_eq!(
        artifacts_and_state(local.path()),
        artifacts_and_state(cluster.path()),
        "bit-identical artifacts, lockfile and state files, fanned out on either executor"
    );
    let again = slurm_run_env(cluster.path(), &[], &fan_out);
    assert!(stderr(&again).contains("nothing submitted"), "{}", stderr(&again));
}

/// Every line of the run's task logs (`out/.shakeflow/slurm/<run>/logs/`) containing `what`.
fn task_log_lines(root: &Path, what: &str) -> Vec<String> {
    let mut lines = Vec::new();
    for run in std::fs::read_dir(root.join("out/.shakeflow/slurm")).unwrap().flatten() {
        for log in std::fs::read_dir(run.path().join("logs")).into_iter().flatten().flatten() {
            let text = std::fs::read_to_string(log.path()).unwrap_or_default();
            lines.extend(text.lines().filter(|l| l.contains(what)).map(String::from));
        }
    }
    lines.sort();
    lines
}

#[test]
fn a_fanned_out_slurm_run_cuts_shards_by_bucket_reads_only_their_state_and_drops_what_it_read() {
    // Past the fan-out limit a stage's state is kept in buckets and its shards are cut by
    // bucket: a `baseline` task reads the root and its own bucket of `baseline` and of `load`
    // (of the five state files), and removes `load`'s shard (`keep: false`) once it has read it.
    let fan_out = [("SHAKEFLOW_FAN_OUT_ABOVE", "1")];
    let text = PIPELINE.replace("    inputs: [daq]\n", "    inputs: [daq]\n    keep: false\n");
    let local = small_project();
    let cluster = small_project();
    let past = std::time::SystemTime::now() - Duration::from_secs(60);
    for project in [&local, &cluster] {
        std::fs::write(project.path().join("pipeline.yaml"), &text).unwrap();
        for motion in ["FB-1", "FB-2"] {
            set_mtime(&project.path().join(format!("archive/{motion}/daq.csv")), past);
        }
    }
    let out = shakeflow_env(&["run", "pipeline.yaml"], local.path(), &fan_out);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = slurm_run_env(cluster.path(), &["--wait"], &fan_out);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(artifacts_and_state(local.path()), artifacts_and_state(cluster.path()));
    let buckets = std::fs::read_dir(cluster.path().join("out/baseline/records")).unwrap().count();
    assert_eq!(buckets, 2, "the two motions fall in two buckets (two shards)");
    let root = std::fs::read_to_string(cluster.path().join("out/shakeflow.lock")).unwrap();
    assert!(root.contains("version: 4\n"), "{root}");
    let state = std::fs::read_dir(cluster.path().join("out/.shakeflow/state")).unwrap().count();
    assert!(state >= 4, "two stages of two buckets or more each (load's status table has its own): {state}");

    // Again, forced: each `baseline` task reads the root and its buckets' files of `baseline`
    // and `load` (the shards' bucket ranges cut the 256 buckets: each file is read by one task,
    // `load`'s status table by the shard whose range holds its bucket), and drops `load`'s shard.
    for project in [&local, &cluster] {
        let _ = std::fs::remove_dir_all(project.path().join("out/.shakeflow/slurm"));
    }
    let out = shakeflow_env(&["run", "pipeline.yaml", "--force", "baseline"], local.path(), &fan_out);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = slurm_run_env(cluster.path(), &["--wait", "--force", "baseline"], &fan_out);
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    assert!(log.contains("load               submitted: 2 of 2 shard(s)"), "remade for baseline: {log}");
    let reads = task_log_lines(cluster.path(), "baseline shard");
    let read_lines: Vec<&String> = reads.iter().filter(|l| l.contains("state file(s)")).collect();
    assert_eq!(read_lines.len(), 2, "{reads:?}");
    let files_read: Vec<usize> = read_lines
        .iter()
        .map(|l| l.split("read ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap())
        .collect();
    assert!(files_read.iter().all(|&n| n < 1 + state), "fewer than the root and {state} files: {reads:?}");
    assert_eq!(files_read.iter().sum::<usize>(), 2 + state, "each state file read once: {reads:?}");
    // The hash memo is kept by bucket too: a `load` task reads the root file (which remembers
    // nothing here) and its own bucket's file, the one that remembers its source file.
    let memo = std::fs::read_dir(cluster.path().join("out/.shakeflow/hashes")).unwrap().count();
    assert_eq!(memo, 2, "a memo file per motion's bucket");
    let memo_reads: Vec<String> =
        task_log_lines(cluster.path(), "load shard").into_iter().filter(|l| l.contains("hash memo")).collect();
    assert_eq!(memo_reads.len(), 2, "{memo_reads:?}");
    assert!(memo_reads.iter().all(|l| l.contains("read 2 hash memo file(s)")), "{memo_reads:?}");
    // Nor does a `load` task walk the archive: the planner listed each shard's source files.
    let listed: Vec<String> =
        task_log_lines(cluster.path(), "load shard").into_iter().filter(|l| l.contains("planner listed")).collect();
    assert_eq!(listed.len(), 2, "{listed:?}");
    assert!(!reads.iter().any(|l| l.contains("planner listed")), "baseline reads no source: {reads:?}");
    assert!(
        listed.iter().all(|l| l.contains(": 1 source file(s) as the planner listed them (0 gone since)")),
        "{listed:?}"
    );
    let dropped = reads.iter().filter(|l| l.contains("removed `load`'s shard")).count();
    assert_eq!(dropped, 2, "{reads:?}");
    assert_eq!(artifacts_and_state(local.path()), artifacts_and_state(cluster.path()));
    assert!(!cluster.path().join("out/load/records").exists(), "load's tables went");

    // Forced once more, `baseline`'s shard 1 dies: the commit keeps `load`'s shard 1 for the
    // rerun (its reader failed) without the shard 0 its reader dropped, and the same command
    // run again ends in the local run's state.
    let kill = [("SHAKEFLOW_FAN_OUT_ABOVE", "1"), ("SHAKEFLOW_FAILPOINT", "slurm-task.baseline.1")];
    let out = slurm_run_env(cluster.path(), &["--wait", "--force", "baseline"], &kill);
    let log = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{log}");
    assert!(log.contains("did not finish") && !log.contains("moving"), "{log}");
    let kept = std::fs::read_dir(cluster.path().join("out/load/records")).unwrap().count();
    assert_eq!(kept, 1, "shard 1's load table kept for the rerun, shard 0's dropped: {log}");
    let out = slurm_run_env(cluster.path(), &["--wait", "--force", "baseline"], &fan_out);
    assert!(out.status.success(), "{}", stderr(&out));
    let names = |root: &Path| artifacts_and_state(root).into_iter().map(|(name, _)| name).collect::<Vec<_>>();
    assert_eq!(names(local.path()), names(cluster.path()), "{}", stderr(&out));
    assert_eq!(artifacts_and_state(local.path()), artifacts_and_state(cluster.path()));
}

#[test]
fn a_record_gone_after_the_planner_listed_it_is_gone_for_its_task_too() {
    // A task of a closed, fanned-out stage takes its source files from the planner's listing;
    // a file deleted after the listing (while the task waits to start) is a record gone, as a
    // walk of the archive would find: the run ends in the state of a local run without it. The
    // run is submitted from the project's parent folder (`<project>/pipeline.yaml`): the
    // listing's paths are the pipeline folder's, as the task's walk would find them, so the
    // inputs' labels are too.
    let fan_out = [("SHAKEFLOW_FAN_OUT_ABOVE", "1")];
    let (local, cluster) = (small_project(), small_project());
    for project in [&local, &cluster] {
        write_daq_csv(&project.path().join("archive/FB-3/daq.csv"), 400, 200.0, 2.0);
    }
    // The first shard's motion (the lowest bucket): the one deleted under its paused task.
    let first = ["FB-1", "FB-2", "FB-3"]
        .into_iter()
        .min_by_key(|m| shakeflow::pipeline::layout::fan_bucket(&format!("motion={m}")))
        .unwrap();
    std::fs::remove_file(local.path().join(format!("archive/{first}/daq.csv"))).unwrap();
    let out = shakeflow_env(&["run", "pipeline.yaml"], local.path(), &fan_out);
    assert!(out.status.success(), "{}", stderr(&out));
    let (parent, project) = (cluster.path().parent().unwrap(), cluster.path().file_name().unwrap());
    let pipeline = Path::new(project).join("pipeline.yaml");
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_shakeflow"))
        .args(["run", pipeline.to_str().unwrap(), "--executor", "slurm", "--units-per-task", "1", "--wait"])
        .envs(fan_out)
        .env("SHAKEFLOW_FAILPOINT", "slurm-task.load.0:sleep=15000")
        .env("SLURM_CONF", test_slurm_conf())
        .current_dir(parent)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let runs = cluster.path().join("out/.shakeflow/slurm");
    let listed =
        || std::fs::read_dir(&runs).ok()?.flatten().map(|r| r.path().join("listings/load/0.json")).find(|p| p.exists());
    let started = Instant::now();
    let listing = loop {
        if let Some(listing) = listed() {
            break listing;
        }
        assert!(started.elapsed() < Duration::from_secs(60), "no listing for load's shard 0");
        std::thread::sleep(Duration::from_millis(100));
    };
    let listing = std::fs::read_to_string(&listing).unwrap();
    assert!(listing.contains(&format!("\"archive/{first}/daq.csv\"")), "relative to the pipeline: {listing}");
    std::fs::remove_file(cluster.path().join(format!("archive/{first}/daq.csv"))).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let tasks = task_log_lines(cluster.path(), "load shard 0");
    assert!(
        tasks.iter().any(|l| l.contains(": 0 source file(s) as the planner listed them (1 gone since)")),
        "{tasks:?}"
    );
    assert_eq!(artifacts_and_state(local.path()), artifacts_and_state(cluster.path()), "{}", stderr(&out));
}

#[test]
fn a_stage_crossing_the_fan_out_limit_on_slurm_keeps_every_cached_record() {
    // Committed below the limit (one state file a stage), then a record more, run past the
    // limit: the task of the new record's shard reads only its buckets of the one file, and
    // calls none of the other shards' records gone (which would remove their files).
    let fan_out = [("SHAKEFLOW_FAN_OUT_ABOVE", "1")];
    let local = small_project_run_locally();
    let cluster = small_project_run_locally();
    for project in [&local, &cluster] {
        write_daq_csv(&project.path().join("archive/FB-3/daq.csv"), 400, 200.0, 2.0);
    }
    let log = local_and_slurm_runs_match(local.path(), cluster.path(), &fan_out);
    assert_eq!(std::fs::read_dir(cluster.path().join("out/baseline/records")).unwrap().count(), 3, "{log}");
}

/// Runs `local` locally and `cluster` on the test Slurm (`--wait`), both with `env`, and checks
/// that they end with the same files, byte for byte (their names compared first, for a failure
/// one can read); returns the Slurm run's log.
fn local_and_slurm_runs_match(local: &Path, cluster: &Path, env: &[(&str, &str)]) -> String {
    let out = shakeflow_env(&["run", "pipeline.yaml"], local, env);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = slurm_run_env(cluster, &["--wait"], env);
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    let names = |root: &Path| artifacts_and_state(root).into_iter().map(|(name, _)| name).collect::<Vec<_>>();
    assert_eq!(names(local), names(cluster), "{log}");
    assert_eq!(artifacts_and_state(local), artifacts_and_state(cluster), "{log}");
    log
}

#[test]
fn a_record_gone_from_the_archive_goes_from_a_slurm_run_as_from_a_local_one() {
    // Nothing else changed: every stage's only change is a unit gone, and no unit is stale; the
    // Slurm run still has to remove the gone unit's files and state, fanned out or not.
    for fan_out in ["1", "100"] {
        let env = [("SHAKEFLOW_FAN_OUT_ABOVE", fan_out)];
        let local = small_project();
        let cluster = small_project();
        for project in [&local, &cluster] {
            let out = shakeflow_env(&["run", "pipeline.yaml"], project.path(), &env);
            assert!(out.status.success(), "{}", stderr(&out));
            std::fs::remove_dir_all(project.path().join("archive/FB-2")).unwrap();
        }
        let log = local_and_slurm_runs_match(local.path(), cluster.path(), &env);
        let files = artifacts_and_state(cluster.path());
        assert!(!files.iter().any(|(name, _)| name.contains("FB-2")), "fan-out above {fan_out}: {log}");
        wait_for_commit(cluster.path());
    }
}

#[test]
fn a_failing_record_fails_its_unit_only_on_slurm() {
    let project = small_project();
    let root = project.path();
    let path = root.join("archive/FB-2/daq.csv");
    let text = std::fs::read_to_string(&path).unwrap().replacen("\n0.010000,", "\n0.010000,abc", 1);
    std::fs::write(&path, text).unwrap();
    let out = slurm_run(root, &["--wait"]);
    let log = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{log}");
    assert!(log.contains("stage `load` record motion=FB-2 failed"), "{log}");
    assert!(root.join("out/load/records/motion=FB-1/data.parquet").is_file(), "{log}");
    assert!(!root.join("out/load/records/motion=FB-2").exists());
    let status = status_text(root);
    assert!(status.contains("load               stale: 1 of 2 records: record motion=FB-2: new record"), "{status}");
}

#[test]
fn a_cancelled_task_is_the_only_shard_a_rerun_submits_and_status_follows_the_run() {
    let project = small_project();
    let root = project.path();
    // Held for a few seconds: time to look at the run and cancel one task.
    let out = slurm_run(root, &["--sbatch-arg=--begin=now+4"]);
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    let status = status_text(root);
    assert!(status.contains("Slurm run `shakeflow-pipeline-") && status.contains("task(s) not finished"), "{status}");
    assert!(status.contains("load ") && status.contains("Pending"), "{status}");
    let job = array_job(&log, "load");
    let cancelled = std::process::Command::new("scancel")
        .arg(format!("{job}_1"))
        .env("SLURM_CONF", test_slurm_conf())
        .output()
        .unwrap();
    assert!(cancelled.status.success(), "{}", stderr(&cancelled));
    wait_for_commit(root);
    assert!(root.join("out/load/records/motion=FB-1/data.parquet").is_file());
    assert!(!root.join("out/load/records/motion=FB-2").exists(), "the cancelled shard wrote nothing");

    let rerun = slurm_run(root, &["--wait"]);
    let log = stderr(&rerun);
    assert!(rerun.status.success(), "{log}");
    assert!(log.contains("load               submitted: 1 of 2 shard(s), 1 stale unit(s) of 2"), "{log}");
    assert!(root.join("out/load/records/motion=FB-2/data.parquet").is_file());
}

#[test]
fn retries_resubmit_the_shard_whose_task_died_and_requeue_reaches_sbatch() {
    let local = small_project_run_locally();
    let project = small_project();
    let root = project.path();
    // The task of load's shard 1 dies (SIGKILL, as on a node that crashed) the first time only.
    let marker = root.join("died-once");
    let failpoint = format!("slurm-task.load.1:once={}", marker.display());
    let out = slurm_run_env(root, &["--wait", "--retries", "1", "--requeue"], &[("SHAKEFLOW_FAILPOINT", &failpoint)]);
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    assert!(marker.is_file(), "the task died once: {log}");
    assert!(show_job(&array_job(&log, "load")).contains("Requeue=1"), "--requeue reached sbatch");
    // The first run committed shard 0 and resubmitted the dead shard and its baseline: one
    // resubmission, which succeeded.
    let resubmitted: Vec<&str> = log.lines().filter(|l| l.contains("failed unit(s) resubmitted")).collect();
    assert_eq!(resubmitted.len(), 1, "{log}");
    let runs = root.join("out/.shakeflow/slurm");
    let summaries: Vec<String> = std::fs::read_dir(&runs)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".summary.json"))
        .map(|p| std::fs::read_to_string(p).unwrap())
        .collect();
    assert_eq!(summaries.len(), 2, "{summaries:?}");
    let first = summaries.iter().find(|s| !s.contains("\"retried_as\": null")).expect("one run retried");
    assert!(first.contains("did not finish"), "{first}");
    // The first commit job resubmitted load's shard 1 alone (its log says so).
    let logs: String = std::fs::read_dir(&runs)
        .unwrap()
        .map(|e| e.unwrap().path().join("logs"))
        .filter(|p| p.is_dir())
        .flat_map(|p| std::fs::read_dir(p).unwrap().map(|e| std::fs::read_to_string(e.unwrap().path()).unwrap()))
        .collect();
    assert!(logs.contains("load               submitted: 1 of 2 shard(s), 1 stale unit(s) of 2"), "{logs}");
    assert_eq!(
        artifacts_and_state(local.path()),
        artifacts_and_state(project.path()),
        "bit-identical artifacts, lockfile and state files"
    );
    assert!(!root.join("out/.shakeflow/lease").exists(), "the last commit job released the lease");
}

#[test]
fn a_commit_job_that_dies_says_so_and_a_rerun_ends_in_the_local_runs_state() {
    let local = small_project_run_locally();
    let project = small_project();
    let root = project.path();
    // The commit job is killed (SIGKILL, as out of memory or on a lost node) before it commits.
    let out = slurm_run_env(root, &["--wait"], &[("SHAKEFLOW_FAILPOINT", "commit.write_lockfile")]);
    let log = stderr(&out);
    assert!(!out.status.success(), "{log}");
    assert!(log.contains("ended without its summary") && log.contains("it died"), "{log}");
    assert!(log.contains("its log is in `") && log.contains("running again finishes the run"), "{log}");
    assert!(!root.join("out/shakeflow.lock").exists(), "nothing committed: {log}");
    // The dead job's lease, held on its node's host: taken over once its heartbeat has missed
    // two beats (here: made two minutes old), since Slurm no longer knows the job (outside a
    // job it would hold for 10 minutes).
    let lease = root.join("out/.shakeflow/lease");
    assert!(std::fs::read_to_string(&lease).unwrap().contains("\"in_job\""));
    let two_minutes_ago = std::time::SystemTime::now() - Duration::from_secs(120);
    std::fs::File::options().write(true).open(&lease).unwrap().set_modified(two_minutes_ago).unwrap();
    let rerun = slurm_run(root, &["--wait"]);
    let rerun_log = stderr(&rerun);
    assert!(rerun.status.success(), "{rerun_log}");
    assert!(rerun_log.contains("has ended"), "the take-over says why: {rerun_log}");
    assert_eq!(
        artifacts_and_state(local.path()),
        artifacts_and_state(project.path()),
        "bit-identical artifacts, lockfile and state files"
    );
}

#[test]
fn in_allocation_runs_the_shards_as_srun_steps_with_the_local_runs_artifacts() {
    let local = small_project_run_locally();
    let project = small_project();
    let root = project.path();
    test_slurm(); // fails, saying how to start it, when the test Slurm is not running
                  // One job of two tasks, as a Tapis app gets: shakeflow runs in its batch script.
    let wrap = format!(
        "'{}' run pipeline.yaml --executor slurm --in-allocation --units-per-task 1",
        env!("CARGO_BIN_EXE_shakeflow")
    );
    let log_file = root.join("allocation.out");
    let out = std::process::Command::new("sbatch")
        .args(["--wait", "--ntasks=2", "--cpus-per-task=1", "--job-name=shakeflow-allocation-test"])
        .arg(format!("--output={}", log_file.display()))
        .args(["--wrap", &wrap])
        .current_dir(root)
        .env("SLURM_CONF", test_slurm_conf())
        .output()
        .unwrap();
    let log = std::fs::read_to_string(&log_file).unwrap_or_default();
    assert!(out.status.success(), "{}\n{log}", stderr(&out));
    assert!(log.contains("2 step(s) at once, 1 CPU(s) each"), "{log}");
    assert!(log.contains("load               2 step(s), 0 failed"), "{log}");
    assert!(log.contains("baseline           2 step(s), 0 failed"), "{log}");
    assert_eq!(
        artifacts_and_state(local.path()),
        artifacts_and_state(root),
        "bit-identical artifacts, lockfile and state files"
    );
    assert!(!root.join("out/.shakeflow/lease").exists(), "the run released the lease");
    // Each shard ran as a step of its own, with its own log.
    let runs = root.join("out/.shakeflow/slurm");
    let run = std::fs::read_dir(&runs).unwrap().map(|e| e.unwrap().path()).find(|p| p.is_dir()).unwrap();
    let id = run.file_name().unwrap().to_string_lossy().into_owned();
    for shard in 0..2 {
        let step = std::fs::read_to_string(run.join(format!("logs/{id}_baseline_{shard}.out"))).unwrap();
        assert!(step.contains(&format!("baseline shard {shard}: 1 unit(s), 1 ran, 0 failed")), "{step}");
    }
    assert!(stderr(&shakeflow(&["run", "pipeline.yaml"], root)).contains("2 cached"));
}

#[test]
fn in_allocation_outside_an_allocation_says_where_to_run_it() {
    let project = small_project();
    let out = shakeflow_env(
        &["run", "pipeline.yaml", "--executor", "slurm", "--in-allocation"],
        project.path(),
        &[("SLURM_JOB_ID", "")],
    );
    let log = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{log}");
    assert!(log.contains("$SLURM_JOB_ID is not set") && log.contains("sbatch"), "{log}");
    assert!(!project.path().join("out").exists(), "nothing written: {log}");
}

#[test]
fn an_intermediate_goes_and_comes_back_on_slurm_as_it_does_locally() {
    let local = small_project();
    let cluster = small_project();
    let keep_false = |order: u32| {
        PIPELINE
            .replace("    inputs: [daq]\n", "    inputs: [daq]\n    keep: false\n")
            .replace("      order: 3\n", &format!("      order: {order}\n"))
    };
    for order in [3, 2] {
        for project in [&local, &cluster] {
            std::fs::write(project.path().join("pipeline.yaml"), keep_false(order)).unwrap();
        }
        assert!(shakeflow(&["run", "pipeline.yaml"], local.path()).status.success());
        let out = slurm_run(cluster.path(), &["--wait"]);
        assert!(out.status.success(), "{}", stderr(&out));
        if order == 2 {
            // baseline reruns and needs load's removed tables: the load array makes them again.
            assert!(stderr(&out).contains("load               submitted: 2 of 2 shard(s)"), "{}", stderr(&out));
        }
        assert!(!cluster.path().join("out/load/records").exists(), "load's tables go after the commit");
        assert_eq!(
            artifacts_and_state(local.path()),
            artifacts_and_state(cluster.path()),
            "bit-identical artifacts, lockfile and state files"
        );
    }
}

#[test]
fn a_branch_still_running_does_not_taint_another_on_slurm() {
    let project = small_project();
    let root = project.path();
    // `other` comes first in run order but is no input of `baseline`; its task sleeps, so
    // `baseline`'s tasks run while `other`'s manifest is missing.
    let text = PIPELINE
        .replace("stages:\n", "stages:\n  other:\n    type: load\n    inputs: [daq]\n")
        .replace("    inputs: [daq]\n  baseline:", "    inputs: [daq]\n    keep: false\n  baseline:");
    assert!(text.contains("keep: false") && text.contains("  other:"), "{text}");
    std::fs::write(root.join("pipeline.yaml"), text).unwrap();
    let out = slurm_run_env(root, &["--wait"], &[("SHAKEFLOW_FAILPOINT", "slurm-task.other.0:sleep=6000")]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(root.join("out/baseline/records/motion=FB-1/data.parquet").is_file());
    assert!(!root.join("out/load/records").exists(), "baseline ran in full: load's tables go");
}

/// Issue 34 on Slurm: a partition folder replaced by a link to a user's folder. The commit job
/// refuses to write through it (`--wait` says why, naming the link), commits nothing and
/// releases the lease; without the link the next run commits.
#[test]
fn the_slurm_commit_never_writes_through_a_symbolic_link() {
    let project = small_project();
    let root = project.path();
    let out = slurm_run(root, &["--wait"]);
    assert!(out.status.success(), "{}", stderr(&out));
    std::fs::create_dir_all(root.join("mine")).unwrap();
    std::fs::write(root.join("mine/thesis.txt"), "years of work").unwrap();
    let partition = root.join("out/load/records/motion=FB-1");
    std::fs::remove_dir_all(&partition).unwrap();
    std::os::unix::fs::symlink(root.join("mine"), &partition).unwrap();
    let before = artifacts_and_state(root);
    let out = slurm_run(root, &["--wait", "--force", "load"]);
    let log = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{log}");
    assert!(
        log.contains("committed nothing") && log.contains("out/load/records/motion=FB-1` is a symbolic link"),
        "{log}"
    );
    let mine: Vec<_> = std::fs::read_dir(root.join("mine")).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(mine, ["thesis.txt"], "the commit job wrote through the link");
    assert_eq!(before, artifacts_and_state(root), "the commit job changed the output folder");
    assert!(!root.join("out/.shakeflow/lease").exists(), "the commit job released the lease");
    std::fs::remove_file(&partition).unwrap();
    let out = slurm_run(root, &["--wait"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(std::fs::symlink_metadata(&partition).unwrap().is_dir());
    assert!(partition.join("data.parquet").is_file());
}
