//! The Slurm executor against the real single-node Slurm of `tests/system/slurm.sh` (`make test`
//! starts it): the same artifacts and lockfile as a local run, a failed record failing its unit
//! only, a cancelled task's shard the only one a rerun submits, and `status` during a run.

use crate::common::*;
use std::path::Path;
use std::process::Output;
use std::time::{Duration, Instant};

fn slurm_run(root: &Path, args: &[&str]) -> Output {
    let conf = test_slurm_conf();
    test_slurm(); // fails, saying how to start it, when the test Slurm is not running
    let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_shakeflow"));
    command.args([&["run", "pipeline.yaml", "--executor", "slurm", "--units-per-task", "1"], args].concat());
    command.current_dir(root).env("SLURM_CONF", conf).output().unwrap()
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

/// Every file of the output folder with its bytes, shakeflow's own state folder aside.
fn artifacts(root: &Path) -> Vec<(String, Vec<u8>)> {
    snapshot(&root.join("out"))
        .into_iter()
        .map(|(p, b)| (p.strip_prefix(root).unwrap().display().to_string(), b))
        .filter(|(p, _)| !p.starts_with("out/.shakeflow"))
        .collect()
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
    let local = small_project();
    assert!(shakeflow(&["run", "pipeline.yaml"], local.path()).status.success());
    let cluster = small_project();
    let out = slurm_run(cluster.path(), &["--wait"]);
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    assert!(log.contains("load               submitted: 2 of 2 shard(s)"), "{log}");
    assert_eq!(artifacts(local.path()), artifacts(cluster.path()), "bit-identical artifacts and lockfile");
    assert!(!cluster.path().join("out/.shakeflow/lease").exists(), "the commit job released the lease");
    // Up to date afterwards, by either executor.
    let again = slurm_run(cluster.path(), &[]);
    assert!(stderr(&again).contains("nothing submitted"), "{}", stderr(&again));
    assert!(stderr(&shakeflow(&["run", "pipeline.yaml"], cluster.path())).contains("2 cached"));
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
    // The load array's job id, from `load submitted: 2 of 2 shard(s), … (<job id>)`.
    let line = log.lines().find(|l| l.starts_with("load ")).unwrap();
    let job = line.rsplit('(').next().unwrap().trim_end_matches(')');
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
