//! `keep: false`: an intermediate stage's files go at the commit once every stage reading them is
//! up to date, and come back — the same bytes, the same lockfile — when one of those reruns.

use crate::common::*;
use std::path::Path;

/// [`PIPELINE`] with `load` as an intermediate, and `baseline`'s order as given.
fn intermediate_pipeline(order: u32) -> String {
    let text = PIPELINE
        .replace("    inputs: [daq]\n", "    inputs: [daq]\n    keep: false\n")
        .replace("      order: 3\n", &format!("      order: {order}\n"));
    assert!(text.contains("keep: false"));
    text
}

fn project(order: u32) -> crate::tempdir::TempDir {
    let dir = small_project();
    std::fs::write(dir.path().join("pipeline.yaml"), intermediate_pipeline(order)).unwrap();
    dir
}

fn run(root: &Path, args: &[&str]) -> std::process::Output {
    let out = shakeflow(&[&["run", "pipeline.yaml"], args].concat(), root);
    assert!(out.status.success(), "{}", stderr(&out));
    out
}

fn lock_text(root: &Path) -> String {
    std::fs::read_to_string(root.join("out/shakeflow.lock")).unwrap()
}

fn load_tables(root: &Path) -> usize {
    ["FB-1", "FB-2"].iter().filter(|m| root.join(format!("out/load/records/motion={m}/data.parquet")).exists()).count()
}

#[test]
fn an_intermediate_goes_once_read_and_comes_back_the_same_when_a_reader_reruns() {
    let project = project(3);
    let root = project.path();
    run(root, &[]);
    assert_eq!(load_tables(root), 0, "load's tables go once baseline has read them");
    assert!(!root.join("out/load/records").exists(), "and the folders they leave empty");
    assert!(root.join("out/baseline/records/motion=FB-2/data.parquet").is_file());
    let first = lock_text(root);
    let lock: serde_yaml::Value = serde_yaml::from_str(&first).unwrap();
    let state = state_yaml(&root.join("out"));
    let hash = &state["stages"]["load"]["units"]["motion=FB-1"]["files"]["records/motion=FB-1/data.parquet"];
    assert!(hash.as_str().is_some_and(|h| h.len() == 64), "the lockfile keeps the removed file's hash: {hash:?}");
    let baseline = std::fs::read(root.join("out/baseline/records/motion=FB-1/data.parquet")).unwrap();

    let status = stdout(&shakeflow(&["status", "pipeline.yaml"], root));
    assert!(
        status.contains("load               up to date (2 unit(s); an intermediate, its files not kept)"),
        "{status}"
    );
    assert!(status.contains("0 of 2 stage(s) stale"), "{status}");
    let again = stderr(&run(root, &[]));
    assert!(again.contains("load               cached") && again.contains("baseline           cached"), "{again}");
    assert_eq!(lock_text(root), first);

    // A reader that must rerun gets its input made again, and the intermediate goes again.
    std::fs::write(root.join("pipeline.yaml"), intermediate_pipeline(2)).unwrap();
    let dry = stdout(&shakeflow(&["run", "pipeline.yaml", "--dry-run"], root));
    assert!(
        dry.contains("would run load record motion=FB-1: made again: its files were not kept (`keep: false`) and `baseline` reads them"),
        "{dry}"
    );
    let log = stderr(&run(root, &[]));
    assert!(log.contains("load               done in") && log.contains("2 unit(s) ran"), "{log}");
    assert_eq!(load_tables(root), 0);
    // The lockfile names each stage's state file by its content: the same name, the same entry.
    let second: serde_yaml::Value = serde_yaml::from_str(&lock_text(root)).unwrap();
    assert_eq!(second["stages"]["load"], lock["stages"]["load"], "made again: the same bytes, the same entry");
    assert_ne!(second["stages"]["baseline"], lock["stages"]["baseline"]);

    // Back to the first parameters: the first run's lockfile and tables, byte for byte.
    std::fs::write(root.join("pipeline.yaml"), intermediate_pipeline(3)).unwrap();
    run(root, &[]);
    assert_eq!(lock_text(root), first);
    assert_eq!(std::fs::read(root.join("out/baseline/records/motion=FB-1/data.parquet")).unwrap(), baseline);
}

#[test]
fn an_intermediate_stays_while_a_reader_has_not_run() {
    let project = project(3);
    let root = project.path();
    run(root, &["load"]);
    assert_eq!(load_tables(root), 2, "baseline has not read them yet: they stay");
    let status = stdout(&shakeflow(&["status", "pipeline.yaml"], root));
    assert!(status.contains("baseline           stale: never run"), "{status}");
    let log = stderr(&run(root, &[]));
    assert!(log.contains("load               cached"), "{log}");
    assert_eq!(load_tables(root), 0, "read by an up-to-date baseline: gone");
    // Kept again (the line removed): the missing files make it stale, and it writes them back.
    std::fs::write(root.join("pipeline.yaml"), PIPELINE).unwrap();
    let status = stdout(&shakeflow(&["status", "pipeline.yaml"], root));
    assert!(status.contains("load               stale:") && status.contains("missing"), "{status}");
    run(root, &[]);
    assert_eq!(load_tables(root), 2);
}

#[test]
fn an_intermediate_read_by_a_failed_unit_stays_for_the_rerun() {
    let project = project(3);
    let root = project.path();
    // A second reader whose every unit fails (a column no record has).
    let broken = format!(
        "{}  broken:\n    type: baseline\n    inputs: [load]\n    params:\n      columns: [nope]\n",
        intermediate_pipeline(3)
    );
    std::fs::write(root.join("pipeline.yaml"), &broken).unwrap();
    let out = shakeflow(&["run", "pipeline.yaml", "--keep-going"], root);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("broken"), "{}", stderr(&out));
    assert_eq!(load_tables(root), 2, "`broken` must read them again: they stay");
    assert!(root.join("out/baseline/records/motion=FB-1/data.parquet").is_file(), "the other reader committed");
    std::fs::write(root.join("pipeline.yaml"), intermediate_pipeline(3)).unwrap();
    let log = stderr(&run(root, &[]));
    assert!(log.contains("load               cached"), "{log}");
    assert_eq!(load_tables(root), 0);
}
