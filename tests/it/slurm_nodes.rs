//! What a second node changes, on the multi-node test Slurm of `tests/system/slurm.sh` (nodes
//! `n1`, `n2` in partition `debug`, `n3` alone in partition `lossy`; each a `slurmd` in a UTS
//! namespace of its own, so a job sees the node's host name): the lease's cross-host rule, the
//! hash memo saved on the login node serving array tasks, and a node lost mid-array.

use crate::common::*;
use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, Instant, SystemTime};

fn slurm_command(program: &str) -> Command {
    test_slurm(); // fails, saying how to start it, when the test Slurm is not running
    let mut command = Command::new(program);
    command.env("SLURM_CONF", test_slurm_conf());
    command
}

/// `shakeflow run` on the login node, where Slurm's client commands reach the test cluster (as
/// `squeue` reaches a real one): what the lease asks when its holder ran in a job.
fn login_run(root: &Path) -> Output {
    let mut command = slurm_command(env!("CARGO_BIN_EXE_shakeflow"));
    command.args(["run", "pipeline.yaml"]).current_dir(root).output().unwrap()
}

fn run_ok(command: &mut Command) -> String {
    let out: Output = command.output().unwrap();
    assert!(out.status.success(), "{command:?}: {}{}", stdout(&out), stderr(&out));
    stdout(&out)
}

fn script() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/system/slurm.sh")
}

/// Polls `done` every 200 ms for up to `seconds`.
fn wait_until(seconds: u64, what: &str, mut done: impl FnMut() -> bool) {
    let started = Instant::now();
    while !done() {
        assert!(started.elapsed() < Duration::from_secs(seconds), "waited {seconds} s for {what}");
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// A run on a node holds the lease under that node's host name. The login node refuses while it
/// holds it. Once the job is killed (no chance to remove its lease), a pid of another host means
/// nothing here: a holder outside any Slurm job stays until its heartbeat has stopped for 10
/// minutes, but this one ran in a job, and a job Slurm no longer knows whose heartbeat has missed
/// two beats is gone: taken over after a minute.
#[test]
fn a_lease_held_on_another_node_is_taken_over_once_its_slurm_job_has_ended() {
    let project = small_project();
    let root = project.path();
    let command = format!(
        "SHAKEFLOW_FAILPOINT=lease.acquired:sleep=600000 '{}' run pipeline.yaml",
        env!("CARGO_BIN_EXE_shakeflow")
    );
    let submitted = run_ok(slurm_command("sbatch").current_dir(root).args([
        "--parsable",
        "--job-name=shakeflow-lease-test",
        "--output=lease-job.out",
        "--wrap",
        &command,
    ]));
    let job = submitted.trim().to_string();
    let lease = root.join("out/.shakeflow/lease");
    wait_until(60, "the job's run to take the lease", || {
        lease.is_file() && std::fs::read(&lease).is_ok_and(|b| !b.is_empty())
    });
    let text = std::fs::read_to_string(&lease).unwrap();
    let holder: serde_json::Value = serde_json::from_str(&text).unwrap();
    let host = holder["host"].as_str().unwrap().to_string();
    assert!(
        host == "n1" || host == "n2" || host == "n3",
        "the lease names the node's host name, not the login node's: {holder}"
    );
    assert_eq!(holder["in_job"].as_str(), Some(job.as_str()), "{holder}");
    let refused = login_run(root);
    assert_eq!(refused.status.code(), Some(1), "{}", stderr(&refused));
    assert!(stderr(&refused).contains(&format!("on host `{host}`")), "{}", stderr(&refused));
    run_ok(slurm_command("scancel").args(["--signal=KILL", "--full", &job]));
    wait_until(60, "the job to end", || run_ok(slurm_command("squeue").args(["-h", "-j", &job])).trim().is_empty());
    assert!(lease.is_file(), "a killed run leaves its lease");
    // Its heartbeat fresh: it holds (`squeue` may not show a live job of another user's).
    let still = login_run(root);
    assert_eq!(still.status.code(), Some(1), "taken over from another host while its heartbeat is fresh");
    assert!(stderr(&still).contains(&format!("on host `{host}`")), "{}", stderr(&still));
    // Two minutes without a heartbeat: outside a Slurm job it still holds (10 minutes) ...
    let mut outside = holder.clone();
    outside.as_object_mut().unwrap().remove("in_job");
    std::fs::write(&lease, serde_json::to_vec(&outside).unwrap()).unwrap();
    set_mtime(&lease, SystemTime::now() - Duration::from_secs(120));
    let still = login_run(root);
    assert_eq!(still.status.code(), Some(1), "{}", stderr(&still));
    // ... in its job, which Slurm no longer knows, it is gone.
    std::fs::write(&lease, &text).unwrap();
    set_mtime(&lease, SystemTime::now() - Duration::from_secs(120));
    let taken = login_run(root);
    assert!(taken.status.success(), "{}", stderr(&taken));
    let said = stderr(&taken);
    let why =
        format!("took over the lease of an earlier run that is gone (its Slurm job {job} has ended, no heartbeat for");
    assert!(said.contains(&why) && said.contains(&format!("pid {} on `{host}`", holder["pid"])), "{said}");
}

/// The login node's memo (absolute paths; no device numbers, which differ between the nodes of a
/// shared file system) serves the array tasks: a task hashes no source whose stat is unchanged.
/// Shown by a memo entry whose hash was replaced: the task on a node takes it instead of reading
/// the file — and `load`, which checks the bytes it parses against the hash the run planned
/// with, refuses that one record as changed while the run read it; the other record runs.
#[test]
fn the_hash_memo_of_the_login_node_serves_the_tasks_on_other_nodes() {
    let project = small_project();
    let root = project.path();
    let past = SystemTime::now() - Duration::from_secs(60);
    for motion in ["FB-1", "FB-2"] {
        set_mtime(&root.join(format!("archive/{motion}/daq.csv")), past);
    }
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(out.status.success(), "{}", stderr(&out));
    let memo_file = root.join("out/.shakeflow/hashes.json");
    let mut memo: Vec<serde_json::Value> = serde_json::from_slice(&std::fs::read(&memo_file).unwrap()).unwrap();
    let daq = std::fs::canonicalize(root.join("archive/FB-1/daq.csv")).unwrap();
    let entry = memo.iter_mut().find(|e| Path::new(e[0].as_str().unwrap()).ends_with("archive/FB-1/daq.csv")).unwrap();
    assert!(Path::new(entry[0].as_str().unwrap()).is_absolute(), "{entry}");
    assert_eq!(std::fs::canonicalize(entry[0].as_str().unwrap()).unwrap(), daq);
    // As another node would see it (older memos recorded the device), with a hash nobody computed.
    entry[1]["dev"] = serde_json::json!(4242);
    entry[2] = serde_json::json!("remembered-by-the-login-node");
    std::fs::write(&memo_file, serde_json::to_vec(&memo).unwrap()).unwrap();
    let out = slurm_command(env!("CARGO_BIN_EXE_shakeflow"))
        .args(["run", "pipeline.yaml", "--executor", "slurm", "--units-per-task", "1", "--force", "load", "--wait"])
        .current_dir(root)
        .output()
        .unwrap();
    let log = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{log}");
    assert!(
        log.contains("stage `load` record motion=FB-1 failed") && log.contains("changed while this run was reading it"),
        "the task did not take the memo's hash: {log}"
    );
    assert!(!log.contains("record motion=FB-2 failed"), "{log}");
}

/// A node crashes (its `slurmd`, job steps and tasks killed) while one of its array tasks runs:
/// Slurm marks the node down and the task failed, the commit job commits what finished and, with
/// `--retries 1`, resubmits the lost shard; once the node is back the run ends in exactly a clean
/// (local) run's state.
#[test]
fn a_node_lost_mid_array_ends_in_a_clean_runs_state() {
    let local = small_project_run_locally();
    let project = small_project();
    let root = project.path();
    // Shard 1 of `load` pauses 20 s as it starts: time to lose its node under it.
    let child = slurm_command(env!("CARGO_BIN_EXE_shakeflow"))
        .args(["run", "pipeline.yaml", "--executor", "slurm", "--units-per-task", "1"])
        .args(["--partition", "lossy", "--retries", "1", "--wait"])
        .env("SHAKEFLOW_FAILPOINT", "slurm-task.load.1:sleep=20000")
        .current_dir(root)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let running = || {
        let jobs = run_ok(slurm_command("squeue").args(["-h", "-p", "lossy", "-t", "R", "-o", "%i %j"]));
        jobs.lines().any(|l| l.contains("_1 ") && l.contains("shakeflow-pipeline-"))
    };
    wait_until(90, "load's shard 1 to run on n3", running);
    run_ok(Command::new(script()).args(["kill-node", "n3"]));
    let state = || run_ok(slurm_command("sinfo").args(["-h", "-n", "n3", "-o", "%t"])).trim().to_string();
    wait_until(90, "Slurm to find n3 down", || state().starts_with("down"));
    run_ok(Command::new(script()).arg("start"));
    let out = child.wait_with_output().unwrap();
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    assert!(log.contains("failed unit(s) resubmitted"), "{log}");
    assert_eq!(artifacts_and_state(local.path()), artifacts_and_state(root), "the artifacts and state of a clean run");
}
