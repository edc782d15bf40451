//! Work units: each record of a per-record stage is cached, run and committed on its own, so a
//! new motion recomputes only its records, a failed record keeps the others, and a source with
//! `on_error: skip` flags what it cannot read and goes on.

use crate::common::*;
use std::path::Path;

fn run(root: &Path, args: &[&str]) -> std::process::Output {
    shakeflow(&[&["run", "pipeline.yaml"], args].concat(), root)
}

fn lockfile(root: &Path) -> serde_yaml::Value {
    state_yaml(&root.join("out"))
}

fn units_of(lock: &serde_yaml::Value, stage: &str) -> Vec<String> {
    lock["stages"][stage]["units"].as_mapping().unwrap().keys().map(|k| k.as_str().unwrap().to_string()).collect()
}

fn break_record(root: &Path, motion: &str) {
    let path = root.join(format!("archive/{motion}/daq.csv"));
    let text = std::fs::read_to_string(&path).unwrap().replacen("\n0.010000,", "\n0.010000,abc", 1);
    std::fs::write(&path, text).unwrap();
}

#[test]
fn a_new_motion_recomputes_only_its_records() {
    let project = small_project();
    let root = project.path();
    assert!(run(root, &[]).status.success());
    let before = lockfile(root);
    let kept = std::fs::read(root.join("out/baseline/records/motion=FB-1/data.parquet")).unwrap();

    write_daq_csv(&root.join("archive/FB-3/daq.csv"), 400, 200.0, 3.0);
    let status = stdout(&shakeflow(&["status", "pipeline.yaml"], root));
    assert!(status.contains("load               stale: 1 of 3 records: record motion=FB-3: new record"), "{status}");
    assert!(
        status.contains("baseline           stale: 1 of 3 records: record motion=FB-3: an upstream unit will rerun"),
        "{status}"
    );

    let out = run(root, &[]);
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    assert!(log.contains("load               done in") && log.contains("1 unit(s) ran, 2 cached"), "{log}");
    let after = lockfile(root);
    assert_eq!(units_of(&after, "baseline"), ["motion=FB-1", "motion=FB-2", "motion=FB-3"]);
    for motion in ["motion=FB-1", "motion=FB-2"] {
        assert_eq!(after["stages"]["baseline"]["units"][motion], before["stages"]["baseline"]["units"][motion]);
    }
    assert_eq!(kept, std::fs::read(root.join("out/baseline/records/motion=FB-1/data.parquet")).unwrap());
}

#[test]
fn a_failed_record_fails_its_unit_only_and_the_rest_is_committed() {
    let project = small_project();
    let root = project.path();
    break_record(root, "FB-2");
    let out = run(root, &[]);
    let log = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{log}");
    assert!(log.contains("error: stage `load` record motion=FB-2 failed: archive/FB-2/daq.csv:"), "{log}");
    assert!(log.contains("baseline           not run: the run stopped at a failed unit"), "{log}");
    assert!(root.join("out/load/records/motion=FB-1/data.parquet").is_file(), "the finished record is committed");
    assert!(!root.join("out/load/records/motion=FB-2").exists());
    // The engine's status table (its unit `(status)`) lists FB-2 failed.
    assert_eq!(units_of(&lockfile(root), "load"), ["(status)", "motion=FB-1"]);
    let status = shakeflow::io::parquet::read_table(&root.join("out/load/status/data.parquet")).unwrap();
    let shakeflow::table::ColumnData::Str(what) = &status.column("status").unwrap().data else { panic!("text") };
    assert_eq!(what, &["loaded", "failed"]);

    // --keep-going runs what does not depend on the failure: baseline of FB-1.
    let out = run(root, &["--keep-going"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(root.join("out/baseline/records/motion=FB-1/data.parquet").is_file(), "{}", stderr(&out));
    assert!(!root.join("out/baseline/records/motion=FB-2").exists());

    // Fixed, the next run does the failed record and its dependents only.
    write_daq_csv(&root.join("archive/FB-2/daq.csv"), 400, 200.0, 1.0);
    let out = run(root, &[]);
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    assert!(log.matches("1 unit(s) ran, 1 cached").count() == 2, "{log}");
}

#[test]
fn on_error_skip_flags_the_bad_record_and_goes_on() {
    let project = small_project();
    let root = project.path();
    let text = PIPELINE.replace("    unit: g\n", "    unit: g\n    on_error: skip\n");
    std::fs::write(root.join("pipeline.yaml"), text).unwrap();
    break_record(root, "FB-2");
    let out = run(root, &[]);
    let log = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "records skipped: exit status 2\n{log}");
    assert!(log.contains("1 record(s) skipped"), "{log}");
    let flagged = shakeflow::io::parquet::read_table(&root.join("out/load/flagged/data.parquet")).unwrap();
    let column = |name: &str| match &flagged.column(name).unwrap().data {
        shakeflow::table::ColumnData::Str(v) => v.clone(),
        other => panic!("{other:?}"),
    };
    assert_eq!(column("record"), ["motion=FB-2"]);
    assert_eq!(column("file"), ["archive/FB-2/daq.csv"]);
    assert!(column("reason")[0].starts_with("archive/FB-2/daq.csv:6:"), "{:?}", column("reason"));
    assert!(root.join("out/baseline/records/motion=FB-1/data.parquet").is_file());
    assert!(!root.join("out/baseline/records/motion=FB-2").exists());

    let status = stdout(&shakeflow(&["status", "pipeline.yaml"], root));
    assert!(status.contains("load               up to date (2 unit(s))"), "{status}");
    assert!(status.contains("flagged record motion=FB-2: archive/FB-2/daq.csv:6:"), "{status}");
    // A flagged record is cached like any other: the next run reads nothing again.
    let again = run(root, &[]);
    assert_eq!(again.status.code(), Some(2));
    assert!(stderr(&again).contains("load               cached"), "{}", stderr(&again));
}

#[test]
fn named_stages_run_with_what_they_need_and_dry_run_runs_nothing() {
    let project = small_project();
    let root = project.path();
    let dry = run(root, &["--dry-run"]);
    let text = stdout(&dry);
    assert!(dry.status.success(), "{}", stderr(&dry));
    assert!(text.contains("would run load record motion=FB-1: never run"), "{text}");
    assert!(text.contains("would run baseline record motion=FB-2:"), "{text}");
    assert!(text.contains("4 of 4 unit(s) would run; nothing was run"), "{text}");
    assert!(!root.join("out").exists(), "a dry run writes nothing");

    let out = run(root, &["load"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(root.join("out/load/records/motion=FB-1/data.parquet").is_file());
    assert!(!root.join("out/baseline").exists(), "baseline was not asked for");
    let out = run(root, &["baseline"]);
    assert!(out.status.success() && stderr(&out).contains("load               cached"), "{}", stderr(&out));
    assert!(root.join("out/baseline/records/motion=FB-2/data.parquet").is_file());

    let unknown = run(root, &["baselin"]);
    assert_eq!(unknown.status.code(), Some(1));
    assert!(stderr(&unknown).contains("did you mean `baseline`"), "{}", stderr(&unknown));
}

#[test]
fn a_record_gone_from_the_archive_takes_its_outputs_with_it() {
    let project = small_project_with_twins();
    let root = project.path();
    assert!(run(root, &[]).status.success());
    assert!(root.join("out/baseline/mcap/records/motion=FB-2").exists());
    std::fs::remove_dir_all(root.join("archive/FB-2")).unwrap();
    let status = stdout(&shakeflow(&["status", "pipeline.yaml"], root));
    assert!(status.contains("1 record(s) gone from its inputs: motion=FB-2"), "{status}");
    assert!(run(root, &[]).status.success());
    assert!(!root.join("out/load/records/motion=FB-2").exists());
    assert!(!root.join("out/baseline/mcap/records/motion=FB-2").exists());
    assert_eq!(units_of(&lockfile(root), "baseline"), ["motion=FB-1"]);
}

#[test]
fn an_output_folder_of_the_format_1_lockfile_is_carried_over() {
    let project = small_project();
    let root = project.path();
    assert!(run(root, &[]).status.success());
    // What shakeflow wrote before work units: one entry per stage, and a file no unit writes now.
    std::fs::write(root.join("out/baseline/records/old.parquet"), "x").unwrap();
    let format1 = "version: 1\npipeline: ../pipeline.yaml\nstages:\n  load:\n    type: load\n    stage_version: 1\n    key: k\n    params: {}\n    inputs: {}\n    outputs: {}\n  baseline:\n    type: baseline\n    stage_version: 3\n    key: k\n    params: {}\n    inputs: {}\n    outputs: {}\n";
    std::fs::write(root.join("out/shakeflow.lock"), format1).unwrap();
    let out = run(root, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!root.join("out/baseline/records/old.parquet").exists(), "the old unit's files are replaced or removed");
    assert_eq!(lockfile(root)["version"].as_u64(), Some(3));
    assert!(stderr(&run(root, &[])).contains("2 cached"));
}

#[test]
fn an_output_folder_of_the_format_2_lockfile_is_carried_over_without_recomputing() {
    let project = small_project();
    let root = project.path();
    assert!(run(root, &[]).status.success());
    let artifacts: Vec<_> =
        snapshot(&root.join("out")).into_iter().filter(|(p, _)| !p.to_string_lossy().contains(".shakeflow")).collect();
    let sharded = std::fs::read(root.join("out/shakeflow.lock")).unwrap();
    let state = artifacts_and_state(root);
    // What the shakeflow before sharded state wrote: every stage's entry in the one lockfile.
    let mut format2 = lockfile(root);
    format2["version"] = 2.into();
    std::fs::write(root.join("out/shakeflow.lock"), serde_yaml::to_string(&format2).unwrap()).unwrap();
    std::fs::remove_dir_all(root.join("out/.shakeflow/state")).unwrap();
    let status = stdout(&shakeflow(&["status", "pipeline.yaml"], root));
    assert!(status.contains("0 of 2 stage(s) stale"), "read as it is: {status}");
    let out = run(root, &[]);
    let log = stderr(&out);
    assert!(out.status.success() && log.contains("0 ran, 2 cached (0 unit(s) ran)"), "nothing reruns: {log}");
    let now: Vec<_> =
        snapshot(&root.join("out")).into_iter().filter(|(p, _)| !p.to_string_lossy().contains(".shakeflow")).collect();
    assert!(now == artifacts, "the artifacts are as they were");
    assert_eq!(std::fs::read(root.join("out/shakeflow.lock")).unwrap(), sharded, "written as format 3");
    assert!(artifacts_and_state(root) == state, "the same state files, byte for byte");
}
