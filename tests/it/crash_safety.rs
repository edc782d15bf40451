//! A run killed at any step of its commit, a full disk at the lockfile, two runs at once: the
//! output folder always ends as a clean run leaves it, and `status` tells the truth in between.

use crate::common::*;
use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::Command;

/// Every entry below `dir` (folders too, so an empty leftover folder counts), relative, with
/// the bytes of files.
fn tree(dir: &Path) -> Vec<(String, Option<Vec<u8>>)> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<(String, Option<Vec<u8>>)>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            let relative = path.strip_prefix(root).unwrap().to_string_lossy().into_owned();
            if path.is_dir() {
                out.push((relative, None));
                walk(root, &path, out);
            } else {
                out.push((relative, Some(std::fs::read(&path).unwrap())));
            }
        }
    }
    let mut out = Vec::new();
    if dir.exists() {
        walk(dir, dir, &mut out);
    }
    out.sort();
    out
}

type Tree = Vec<(String, Option<Vec<u8>>)>;

/// Kills `shakeflow run` in `root` at the failpoint `point`; checks that `status` still says
/// `pending` and the outputs are still `before` (`.shakeflow` aside) when the commit point was
/// not passed, that nothing is stale when it was; then reruns and checks that the output folder
/// is `expected`, what a clean run leaves.
fn kill_then_rerun(
    root: &Path,
    point: &str,
    passed_commit_point: bool,
    pending: &[String],
    before: &Tree,
    expected: &Tree,
) {
    let killed = shakeflow_env(&["run", "pipeline.yaml"], root, &[("SHAKEFLOW_FAILPOINT", point)]);
    assert_eq!(killed.status.signal(), Some(9), "not killed at `{point}`: {}", stderr(&killed));
    let after_crash = status_lines(root);
    if passed_commit_point {
        assert!(
            after_crash.last().unwrap().starts_with("0 of 2 stage(s) stale"),
            "killed at `{point}` (after the commit point), status says: {after_crash:?}"
        );
    } else {
        assert_eq!(after_crash, pending, "killed at `{point}` (before the commit point), status lies");
        let outputs =
            |tree: &Tree| -> Tree { tree.iter().filter(|(n, _)| !n.starts_with(".shakeflow")).cloned().collect() };
        assert!(
            outputs(&tree(&root.join("out"))) == outputs(before),
            "killed at `{point}` (before the commit point), the old outputs changed"
        );
    }
    run_ok(root);
    let got = tree(&root.join("out"));
    assert!(
        got == *expected,
        "killed at `{point}`, then rerun: the folder differs from a clean run's\n got: {:?}\nwant: {:?}",
        names(&got),
        names(expected)
    );
}

fn names(tree: &[(String, Option<Vec<u8>>)]) -> Vec<&str> {
    tree.iter().map(|(n, _)| n.as_str()).collect()
}

/// The second version of the pipeline: a source option and a stage parameter changed, so every
/// unit of both stages reruns and the commit replaces their six files and the lockfile.
fn second_version(root: &Path) {
    let first = pipeline_with_twins();
    let text =
        first.replace("      order: 3", "      order: 2").replace("    unit: g\n", "    unit: g\n    scale: 2.0\n");
    assert_ne!(text, first);
    std::fs::write(root.join("pipeline.yaml"), text).unwrap();
}

fn run_ok(root: &Path) {
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(out.status.success(), "{}", stderr(&out));
}

/// `status`'s stage lines (its notes aside).
fn status_lines(root: &Path) -> Vec<String> {
    let out = shakeflow(&["status", "pipeline.yaml"], root);
    assert!(out.status.success(), "{}", stderr(&out));
    stdout(&out).lines().filter(|l| !l.starts_with("note:")).map(String::from).collect()
}

/// The failpoints a run from the first to the second version passes, in order.
fn commit_points() -> Vec<String> {
    let project = small_project_with_twins();
    run_ok(project.path());
    second_version(project.path());
    let out = shakeflow_env(&["run", "pipeline.yaml"], project.path(), &[("SHAKEFLOW_FAILPOINT", "trace")]);
    assert!(out.status.success(), "{}", stderr(&out));
    stderr(&out).lines().filter_map(|l| l.strip_prefix("failpoint: ")).map(String::from).collect()
}

#[test]
fn a_run_killed_at_any_step_of_its_commit_ends_as_a_clean_run_does() {
    // What a clean run of the second version leaves.
    let clean = small_project_with_twins();
    second_version(clean.path());
    run_ok(clean.path());
    let expected = tree(&clean.path().join("out"));

    let points = commit_points();
    for step in ["lease.acquired", "commit.write_lockfile", "commit.journal_written", "commit.committed"] {
        assert!(points.iter().any(|p| p == step), "the run did not pass `{step}`: {points:?}");
    }
    for step in ["commit.moved_aside.", "commit.moved_in."] {
        let n = points.iter().filter(|p| p.starts_with(step)).count();
        // load: 2 records; baseline: 2 records, each a Parquet file and its MCAP twin.
        assert_eq!(n, 6, "every file of both stages moves ({step}*): {points:?}");
    }
    let commit_point = points.iter().position(|p| p == "commit.committed").unwrap();
    for (i, point) in points.iter().enumerate() {
        let project = small_project_with_twins();
        let root = project.path();
        run_ok(root);
        let before = tree(&root.join("out"));
        second_version(root);
        let pending = status_lines(root);
        assert!(pending.iter().any(|l| l.contains("stale")), "{pending:?}");

        kill_then_rerun(root, point, i >= commit_point, &pending, &before, &expected);
    }
}

#[test]
fn a_first_run_killed_at_any_step_of_its_commit_ends_as_a_clean_first_run_does() {
    let clean = small_project_with_twins();
    run_ok(clean.path());
    let expected = tree(&clean.path().join("out"));

    let traced = small_project_with_twins();
    let out = shakeflow_env(&["run", "pipeline.yaml"], traced.path(), &[("SHAKEFLOW_FAILPOINT", "trace")]);
    assert!(out.status.success(), "{}", stderr(&out));
    let points: Vec<String> =
        stderr(&out).lines().filter_map(|l| l.strip_prefix("failpoint: ")).map(String::from).collect();
    // The output folder has no stage folder yet: each stage's folder moves in whole.
    let moved_in: Vec<&str> = points.iter().filter_map(|p| p.strip_prefix("commit.moved_in.")).collect();
    assert_eq!(moved_in, ["baseline", "load"], "{points:?}");
    let commit_point = points.iter().position(|p| p == "commit.committed").unwrap();
    for (i, point) in points.iter().enumerate() {
        let project = small_project_with_twins();
        let root = project.path();
        let pending = status_lines(root);
        assert!(pending.last().unwrap().starts_with("2 of 2 stage(s) stale"), "{pending:?}");
        kill_then_rerun(root, point, i >= commit_point, &pending, &Vec::new(), &expected);
    }
}

#[test]
fn a_full_disk_at_the_lockfile_changes_nothing_and_says_so() {
    let project = small_project();
    let root = project.path();
    run_ok(root);
    let before = tree(&root.join("out"));
    second_version(root);
    let out =
        shakeflow_env(&["run", "pipeline.yaml"], root, &[("SHAKEFLOW_FAILPOINT", "commit.write_lockfile:enospc")]);
    let message = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{message}");
    for needle in ["No space left on device", "nothing was changed", "free space"] {
        assert!(message.contains(needle), "message lacks `{needle}`:\n{message}");
    }
    assert!(!message.contains("panicked"), "{message}");
    assert!(tree(&root.join("out")) == before, "a failed commit changed the output folder");
}

#[test]
fn a_second_run_on_the_same_folder_is_refused_naming_the_first() {
    let project = small_project();
    let root = project.path();
    let mut first = Command::new(env!("CARGO_BIN_EXE_shakeflow"))
        .args(["run", "pipeline.yaml"])
        .current_dir(root)
        .env("SHAKEFLOW_FAILPOINT", "lease.acquired:sleep=4000")
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let lease = root.join("out/.shakeflow/lease");
    let started = std::time::Instant::now();
    while !lease.exists() {
        assert!(started.elapsed().as_secs() < 60, "the first run never took its lease");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let second = shakeflow(&["run", "pipeline.yaml"], root);
    let message = stderr(&second);
    assert_eq!(second.status.code(), Some(1), "{message}");
    for needle in ["another shakeflow run is writing", &format!("pid {}", first.id()), "started", "run pipeline.yaml"] {
        assert!(message.contains(needle), "message lacks `{needle}`:\n{message}");
    }
    let status = first.wait().unwrap();
    assert!(status.success(), "the first run failed");
    assert!(!lease.exists(), "the lease outlived its run");
    let again = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(again.status.success(), "{}", stderr(&again));
    assert!(stderr(&again).contains("0 ran, 2 cached"), "{}", stderr(&again));
}

#[test]
fn the_lease_of_a_run_that_died_is_taken_over() {
    let project = small_project();
    let root = project.path();
    let killed = shakeflow_env(&["run", "pipeline.yaml"], root, &[("SHAKEFLOW_FAILPOINT", "lease.acquired")]);
    assert_eq!(killed.status.signal(), Some(9));
    assert!(root.join("out/.shakeflow/lease").exists(), "the dead run's lease is gone already");
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("took over the lease of an earlier run that is gone"), "{}", stderr(&out));
}

#[test]
fn leftovers_of_older_shakeflow_runs_are_removed_and_nothing_else() {
    let project = small_project();
    let root = project.path();
    run_ok(root);
    // What shakeflow before the journal left when killed mid-commit, and a file of the user's.
    std::fs::create_dir_all(root.join("out/.baseline.tmp-4242-0/records")).unwrap();
    std::fs::create_dir_all(root.join("out/.staging-4243/load")).unwrap();
    std::fs::write(root.join("out/.shakeflow.lock.tmp-4242-1"), "x").unwrap();
    std::fs::write(root.join("out/NOTES.txt"), "mine").unwrap();
    run_ok(root);
    let left: Vec<_> = std::fs::read_dir(root.join("out")).unwrap().map(|e| e.unwrap().file_name()).collect();
    let mut left: Vec<String> = left.into_iter().map(|n| n.to_string_lossy().into_owned()).collect();
    left.sort();
    // `.shakeflow` keeps the hash memo and the state files only (no lease, no transaction).
    assert_eq!(left, [".shakeflow", "NOTES.txt", "baseline", "load", "shakeflow.lock"]);
    let mut state: Vec<_> =
        std::fs::read_dir(root.join("out/.shakeflow")).unwrap().map(|e| e.unwrap().file_name()).collect();
    state.sort();
    assert_eq!(state, ["hashes.json", "state"]);
}
