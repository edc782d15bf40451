//! Artifacts opened by tools we did not write: pyarrow, DuckDB, the `mcap` reader with Google's protobuf, jsonschema.

use crate::common;
use common::*;
use std::path::Path;

#[test]
fn parquet_and_mcap_artifacts_open_in_pyarrow_duckdb_and_mcap() {
    let project = small_project_with_twins();
    let out = shakeflow(&["run", "pipeline.yaml"], project.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let dir = project.path().join("out");
    let printed = run_python(&reference_script("check_artifacts.py"), &[dir.to_str().unwrap(), "baseline"]);
    assert!(printed.contains("OK: 2 parts, 800 rows"), "{printed}");
}

#[test]
fn every_pipeline_file_validates_against_the_json_schema() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files: Vec<String> = std::fs::read_dir(root.join("pipelines"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "yaml" || e == "yml"))
        .map(|p| p.display().to_string())
        .collect();
    assert!(!files.is_empty(), "no pipelines/*.yaml");
    let project = small_project();
    files.push(project.path().join("pipeline.yaml").display().to_string());
    let schema = root.join("schemas/pipeline.schema.json");
    let mut args = vec![schema.to_str().unwrap()];
    args.extend(files.iter().map(String::as_str));
    let printed = run_python(&reference_script("check_schema.py"), &args);
    assert_eq!(printed.matches(": valid").count(), files.len(), "{printed}");
}

/// The paths of `root/out`'s files, relative to `root`, each record's files moved out of its
/// two-level folder: `out/baseline/records/3f/motion=FB-1/data.parquet` → `…/records/motion=FB-1/…`.
fn flattened(files: Vec<(String, Vec<u8>)>) -> Vec<(String, Vec<u8>)> {
    files.into_iter().map(|(p, b)| (shakeflow::pipeline::layout::placed(&p, false).into_owned(), b)).collect()
}

#[test]
fn a_fanned_out_stage_opens_in_pyarrow_and_duckdb_writes_the_same_bytes_and_moves_back() {
    let flat = small_project_with_twins();
    assert!(shakeflow(&["run", "pipeline.yaml"], flat.path()).status.success());
    // Past one record per folder, records go one level down (two hex digits of their first key).
    let project = small_project_with_twins();
    let fan_out = [("SHAKEFLOW_FAN_OUT_ABOVE", "1")];
    let out = shakeflow_env(&["run", "pipeline.yaml"], project.path(), &fan_out);
    assert!(out.status.success(), "{}", stderr(&out));
    let records = project.path().join("out/baseline/records");
    let folders: Vec<String> =
        std::fs::read_dir(&records).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(folders.iter().all(|f| f.len() == 2 && !f.contains('=')), "{folders:?}");
    let dir = project.path().join("out");
    let printed = run_python(&reference_script("check_artifacts.py"), &[dir.to_str().unwrap(), "baseline"]);
    assert!(printed.contains("OK: 2 parts, 800 rows, partitions ['motion']"), "{printed}");
    // The same bytes, state included (unit ids, keys, hashes), only the paths differ.
    let fanned = artifacts_and_state(project.path());
    let same_but_state = |files: Vec<(String, Vec<u8>)>| -> Vec<(String, Vec<u8>)> {
        files
            .into_iter()
            .filter(|(p, _)| !p.starts_with("out/.shakeflow/state/") && p != "out/shakeflow.lock")
            .collect()
    };
    assert_ne!(fanned, artifacts_and_state(flat.path()));
    assert_eq!(same_but_state(flattened(fanned.clone())), same_but_state(artifacts_and_state(flat.path())));
    let keys = |root: &Path| {
        let state = state_yaml(&root.join("out"));
        let units = state["stages"]["baseline"]["units"].as_mapping().unwrap().clone();
        units.into_iter().map(|(id, u)| (id, u["key"].clone(), u["inputs"].clone())).collect::<Vec<_>>()
    };
    assert_eq!(keys(project.path()), keys(flat.path()), "unit ids, keys and input labels do not see the layout");

    // Below the limit again: a run moves the cached records back, runs nothing, and leaves
    // exactly the folder of a run that never fanned out; and out again, still running nothing.
    let out = shakeflow(&["run", "pipeline.yaml"], project.path());
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    assert!(log.contains("(0 unit(s) ran)") && log.contains("cached file(s) moved to one folder"), "{log}");
    assert_eq!(artifacts_and_state(project.path()), artifacts_and_state(flat.path()));
    let out = shakeflow_env(&["run", "pipeline.yaml"], project.path(), &fan_out);
    let log = stderr(&out);
    assert!(
        out.status.success() && log.contains("(0 unit(s) ran)") && log.contains("moved to two-level folders"),
        "{log}"
    );
    assert_eq!(artifacts_and_state(project.path()), fanned);
    let status = stdout(&shakeflow_env(&["status", "pipeline.yaml"], project.path(), &fan_out));
    assert!(status.contains("0 of 2 stage(s) stale"), "{status}");
}
