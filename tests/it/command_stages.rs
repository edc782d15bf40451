//! `shakeflow stage` and `shakeflow diagnose` run through the executor every pipeline runs on:
//! a lockfile in their output folder (a repeated command is cached, a changed `--set` reruns),
//! dataset folders and Parquet files as inputs (also as `format: dataset` sources of pipelines),
//! all or nothing (a failed unit leaves the output folder as it was), and foreign folders refused.
use crate::common;
use common::*;
use std::path::Path;

const LOAD_SET: [&str; 6] = ["--set", "header_lines=2", "--set", "time_column=Time", "--set", "unit=g"];

fn load(root: &Path, input: &str, output: &str) -> std::process::Output {
    let mut args = vec!["stage", "load", "--input", input, "--output", output];
    args.extend(LOAD_SET);
    shakeflow(&args, root)
}

/// Every file below `dir` with its bytes but shakeflow's state (the hash memo may learn a file).
fn outputs(dir: &Path) -> Vec<(std::path::PathBuf, Vec<u8>)> {
    snapshot(dir).into_iter().filter(|(path, _)| !path.components().any(|c| c.as_os_str() == ".shakeflow")).collect()
}

fn lockfile(dir: &Path) -> shakeflow::pipeline::lock::LockFile {
    shakeflow::pipeline::lock::LockFile::read(&dir.join("shakeflow.lock")).unwrap()
}

#[test]
fn a_repeated_stage_is_cached_and_a_changed_set_reruns() {
    let project = small_project();
    let root = project.path();
    let first = load(root, "archive/FB-1/daq.csv", "loaded");
    assert!(first.status.success(), "{}", stderr(&first));
    assert!(root.join("loaded/records/data.parquet").is_file() && root.join("loaded/.shakeflow-stage").is_file());
    assert_eq!(lockfile(&root.join("loaded")).pipeline.as_deref(), Some("shakeflow stage"));
    let before = outputs(&root.join("loaded"));
    let again = load(root, "archive/FB-1/daq.csv", "loaded");
    assert!(again.status.success() && stderr(&again).contains("cached"), "{}", stderr(&again));
    assert!(outputs(&root.join("loaded")) == before, "a cached run changes nothing");

    let baseline = |order: &str| {
        let set = format!("order={order}");
        shakeflow(&["stage", "baseline", "-i", "loaded/records", "-o", "based", "--set", &set], root)
    };
    let ran = baseline("2");
    assert!(ran.status.success() && stderr(&ran).contains("1 ran"), "{}", stderr(&ran));
    let table = shakeflow::io::parquet::read_table(&root.join("based/records/data.parquet")).unwrap();
    assert!(table.metadata["shakeflow.params"].contains(r#""order":2"#), "{:?}", table.metadata);
    let cached = baseline("2");
    assert!(stderr(&cached).contains("cached"), "{}", stderr(&cached));
    let changed = baseline("1");
    let message = stderr(&changed);
    assert!(changed.status.success() && message.contains("params changed: order 2 → 1"), "{message}");
    let table = shakeflow::io::parquet::read_table(&root.join("based/records/data.parquet")).unwrap();
    assert!(table.metadata["shakeflow.params"].contains(r#""order":1"#), "{:?}", table.metadata);
}

#[test]
fn stage_reads_a_dataset_folder_or_a_parquet_file_as_the_pipeline_stage_does() {
    let project = small_project();
    let root = project.path();
    assert!(shakeflow(&["run", "pipeline.yaml"], root).status.success());
    let folder = shakeflow(&["stage", "baseline", "-i", "out/load/records", "-o", "based", "--set", "order=3"], root);
    assert!(folder.status.success(), "{}", stderr(&folder));
    // One unit per part of the folder, as in the pipeline, with the same numbers.
    let units: Vec<String> = lockfile(&root.join("based")).stages["baseline"].units.keys().cloned().collect();
    assert_eq!(units, ["motion=FB-1", "motion=FB-2"]);
    for motion in ["FB-1", "FB-2"] {
        let part = format!("records/motion={motion}/data.parquet");
        let alone = shakeflow::io::parquet::read_table(&root.join("based").join(&part)).unwrap();
        let piped = shakeflow::io::parquet::read_table(&root.join("out/baseline").join(&part)).unwrap();
        assert_eq!(alone.column_names(), piped.column_names());
        for column in ["time_s", "ax_mps2", "ay_mps2"] {
            assert_eq!(alone.f64_column(column).unwrap(), piped.f64_column(column).unwrap(), "{motion} {column}");
        }
        assert_eq!(alone.metadata["shakeflow.params"], piped.metadata["shakeflow.params"]);
    }
    let file = shakeflow(&["stage", "baseline", "-i", "out/load/records/motion=FB-2/data.parquet", "-o", "one"], root);
    assert!(file.status.success(), "{}", stderr(&file));
    assert!(root.join("one/records/data.parquet").is_file());
    let empty = std::fs::create_dir_all(root.join("nothing"))
        .map(|()| shakeflow(&["stage", "baseline", "-i", "nothing", "-o", "none"], root));
    let empty = empty.unwrap();
    assert!(!empty.status.success() && stderr(&empty).contains("holds no `data.parquet`"), "{}", stderr(&empty));
    assert!(!root.join("none").exists());
}

#[test]
fn a_failed_unit_leaves_the_output_folder_as_it_was() {
    let project = small_project();
    let root = project.path();
    assert!(shakeflow(&["run", "pipeline.yaml"], root).status.success());
    let based = shakeflow(&["stage", "baseline", "-i", "out/load/records", "-o", "based"], root);
    assert!(based.status.success(), "{}", stderr(&based));
    let before = outputs(&root.join("based"));
    std::fs::write(root.join("out/load/records/motion=FB-2/data.parquet"), b"PAR1 not really").unwrap();
    // FB-1 reruns and succeeds, FB-2 fails: nothing of it is committed.
    let failed = shakeflow(&["stage", "baseline", "-i", "out/load/records", "-o", "based", "--set", "order=1"], root);
    let message = stderr(&failed);
    assert_eq!(failed.status.code(), Some(1), "{message}");
    assert!(message.contains("record motion=FB-2 failed") && message.contains("nothing was written"), "{message}");
    assert!(outputs(&root.join("based")) == before, "the output folder changed");
    // A folder the failed run had to create goes again.
    let fresh = shakeflow(&["stage", "baseline", "-i", "out/load/records", "-o", "fresh"], root);
    assert_eq!(fresh.status.code(), Some(1), "{}", stderr(&fresh));
    assert!(!root.join("fresh").exists());
}

#[test]
fn a_foreign_output_folder_is_refused() {
    let project = small_project();
    let root = project.path();
    assert!(shakeflow(&["run", "pipeline.yaml"], root).status.success());
    // A pipeline's output folder is the pipeline's.
    let before = outputs(&root.join("out"));
    let into_pipeline = load(root, "archive/FB-1/daq.csv", "out");
    let message = stderr(&into_pipeline);
    assert_eq!(into_pipeline.status.code(), Some(1), "{message}");
    assert!(message.contains("holds the results of another pipeline, `../pipeline.yaml`"), "{message}");
    assert!(outputs(&root.join("out")) == before, "the folder changed");
    // A stage's own folder inside it is that stage's too.
    let into_stage = load(root, "archive/FB-1/daq.csv", "out/baseline");
    assert!(
        stderr(&into_stage).contains("holds an earlier output of stage type `baseline`, not `load`"),
        "{}",
        stderr(&into_stage)
    );
    assert!(outputs(&root.join("out")) == before, "the folder changed");
    // And `stage` output is no pipeline's output_dir.
    let loaded = load(root, "archive/FB-1/daq.csv", "loaded");
    assert!(loaded.status.success(), "{}", stderr(&loaded));
    std::fs::write(root.join("second.yaml"), PIPELINE.replace("output_dir: out", "output_dir: loaded")).unwrap();
    let run = shakeflow(&["run", "second.yaml"], root);
    assert!(stderr(&run).contains("holds the results of another pipeline, `shakeflow stage`"), "{}", stderr(&run));
}

const READER: &str = "\
version: 1
output_dir: ../out2
inputs:
  loaded:
    format: dataset
    path: ../out/load/records
stages:
  baseline:
    type: baseline
    inputs: [loaded]
    select:
      motion: [FB-2]
";

#[test]
fn a_pipeline_reads_another_pipelines_outputs_as_a_dataset_source() {
    let project = small_project();
    let root = project.path();
    assert!(shakeflow(&["run", "pipeline.yaml"], root).status.success());
    std::fs::create_dir_all(root.join("reader")).unwrap();
    std::fs::write(root.join("reader/p.yaml"), READER).unwrap();
    let run = shakeflow(&["run", "reader/p.yaml"], root);
    assert!(run.status.success(), "{}", stderr(&run));
    assert!(root.join("out2/baseline/records/motion=FB-2/data.parquet").is_file());
    assert!(!root.join("out2/baseline/records/motion=FB-1").exists(), "select: applies");
    let table =
        shakeflow::io::parquet::read_table(&root.join("out2/baseline/records/motion=FB-2/data.parquet")).unwrap();
    assert!(
        table.metadata["shakeflow.inputs"].contains("../out/load/records/motion=FB-2/data.parquet"),
        "{:?}",
        table.metadata
    );
    // The upstream pipeline's new result is an input change.
    assert!(shakeflow(&["run", "pipeline.yaml", "--force", "load"], root).status.success());
    let status = stdout(&shakeflow(&["status", "reader/p.yaml"], root));
    assert!(status.contains("up to date"), "a rerun that writes the same bytes changes nothing: {status}");
    write_daq_csv(&root.join("archive/FB-2/daq.csv"), 400, 200.0, 2.0);
    assert!(shakeflow(&["run", "pipeline.yaml"], root).status.success());
    let status = stdout(&shakeflow(&["status", "reader/p.yaml"], root));
    assert!(status.contains("input `../out/load/records/motion=FB-2/data.parquet` changed"), "{status}");
    // Options of record files on a dataset, and a dataset fed to `load`, are refused at their line.
    let with_unit = READER.replace("    path: ../out/load/records\n", "    path: ../out/load/records\n    unit: g\n");
    std::fs::write(root.join("reader/p.yaml"), with_unit).unwrap();
    let refused = shakeflow(&["validate", "reader/p.yaml"], root);
    assert!(
        stderr(&refused).contains("p.yaml:7:5: source `loaded`: `unit` applies to record files, not to a `dataset`"),
        "{}",
        stderr(&refused)
    );
    let to_load = READER.replace("type: baseline", "type: load").replace("    select:\n      motion: [FB-2]\n", "");
    std::fs::write(root.join("reader/p.yaml"), to_load).unwrap();
    let refused = shakeflow(&["validate", "reader/p.yaml"], root);
    assert!(
        stderr(&refused).contains("p.yaml:10:14: `loaded` is a `dataset` source, which this stage type does not read"),
        "{}",
        stderr(&refused)
    );
}

fn copy_case(id: &str, to: &Path) {
    let from = shared_dir().join("cases/demo").join(id);
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
    }
}

#[test]
fn diagnose_writes_the_contract_for_one_case_and_for_several_and_is_cached() {
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    copy_case("demo_01", &root.join("cases/demo_01"));
    copy_case("demo_02", &root.join("cases/demo_02"));
    copy_case("demo_02", &root.join("again/demo_02"));
    let twice = shakeflow(&["diagnose", "cases/demo_02", "again/demo_02", "--out", "out"], root);
    assert!(stderr(&twice).contains("two cases are named `demo_02`"), "{}", stderr(&twice));
    let none = shakeflow(&["diagnose", "cases/demo_03", "--out", "out"], root);
    assert!(stderr(&none).contains("the case `cases/demo_03` is not a folder"), "{}", stderr(&none));
    assert!(!root.join("out").exists());

    let one = shakeflow(&["diagnose", "cases/demo_01", "--out", "out"], root);
    assert!(one.status.success(), "{}", stderr(&one));
    let contract = std::fs::read(root.join("out/diagnosis.json")).unwrap();
    for file in
        ["accel/case=demo_01/data.parquet", "camera/case=demo_01/data.parquet", "reports/demo_01.png", "shakeflow.lock"]
    {
        assert!(root.join("out").join(file).is_file(), "no {file}");
    }
    // The engine's provenance keys, as in a pipeline.
    let accel = shakeflow::io::parquet::read_table(&root.join("out/accel/case=demo_01/data.parquet")).unwrap();
    assert_eq!(accel.metadata["shakeflow.stage_type"], "diagnose");
    assert!(accel.metadata["shakeflow.inputs"].contains("cases/demo_01"), "{:?}", accel.metadata);
    assert!(!accel.metadata.contains_key("shakeflow.command"));
    let before = outputs(&root.join("out"));
    let again = shakeflow(&["diagnose", "cases/demo_01", "--out", "out"], root);
    assert!(again.status.success() && stderr(&again).contains("cached"), "{}", stderr(&again));
    assert!(outputs(&root.join("out")) == before, "the folder changed");

    // Several cases: one folder each for the contract; the single case's file goes.
    let both = shakeflow(&["diagnose", "cases/demo_01", "cases/demo_02", "--out", "out"], root);
    assert!(both.status.success(), "{}", stderr(&both));
    assert!(!root.join("out/diagnosis.json").exists());
    assert_eq!(std::fs::read(root.join("out/demo_01/diagnosis.json")).unwrap(), contract, "the same diagnosis");
    let verdict = |id: &str| -> String {
        let d: serde_json::Value =
            serde_json::from_slice(&std::fs::read(root.join("out").join(id).join("diagnosis.json")).unwrap()).unwrap();
        d["verdict"].as_str().unwrap().to_string()
    };
    assert_eq!((verdict("demo_01"), verdict("demo_02")), ("sensor_tilt".into(), "mass_change".into()));
    assert!(root.join("out/diagnosis/data.parquet").is_file() && root.join("out/reports/demo_02.png").is_file());
}

/// A command names its files literally: brackets and braces are no pattern, and several files'
/// stems become `file` partitions, percent-encoded into one folder each.
#[test]
fn stage_takes_file_names_as_they_are() {
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    write_daq_csv(&root.join("FB[1].csv"), 200, 200.0, 0.0);
    write_daq_csv(&root.join("run {2}.csv"), 200, 200.0, 1.0);
    let mut args = vec!["stage", "load", "-i", "FB[1].csv", "-i", "run {2}.csv", "-o", "loaded"];
    args.extend(LOAD_SET);
    let out = shakeflow(&args, root);
    assert!(out.status.success(), "{}", stderr(&out));
    for part in ["file=FB%5B1%5D", "file=run%20%7B2%7D"] {
        assert!(root.join("loaded/records").join(part).join("data.parquet").is_file(), "no {part}");
    }
    let units: Vec<String> = lockfile(&root.join("loaded")).stages["load"].units.keys().cloned().collect();
    assert_eq!(units, ["file=FB%5B1%5D", "file=run%20%7B2%7D"]);
}
