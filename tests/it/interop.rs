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
