//! Hostile input (issue 19): damaged counts, ragged or repeated columns, values that overflow,
//! files replaced mid-run, binary and UTF-16 files, and a bounded, deterministic mutation
//! harness over every reader. Every refusal is a clear error, never a panic or an abort.

use crate::common::*;

use serde_json::json;
use shakeflow::io::hash::hash_bytes;
use shakeflow::pipeline::spec::SourceSpec;
use shakeflow::stages::{load, InputPart};
use std::path::Path;

fn source(spec: serde_json::Value) -> SourceSpec {
    serde_json::from_value(spec).unwrap()
}

fn part(path: &Path, hash: &str) -> InputPart {
    InputPart { partition: vec![], path: path.to_path_buf(), label: "rec".into(), hash: hash.into() }
}

fn load_error(spec: serde_json::Value, path: &Path) -> String {
    match load::load_record(&source(spec), &part(path, "")) {
        Ok(table) => panic!("expected a refusal, got columns {:?}", table.column_names()),
        Err(e) => e.to_string(),
    }
}

/// Repeated column names used to panic in `Table::push` ("duplicate column").
#[test]
fn repeated_csv_column_names_are_refused_with_the_line() {
    let dir = crate::tempdir::tempdir().unwrap();
    let path = dir.path().join("dup.csv");
    std::fs::write(&path, "# export\ntime,a,b,a\n0,1,2,3\n0.01,1,2,3\n").unwrap();
    let message = load_error(
        json!({"format": "csv", "path": "dup.csv", "header_lines": 1, "time_column": "time", "unit": "g"}),
        &path,
    );
    assert!(message.contains("dup.csv:2:1: the file has two columns named `a` (columns 2 and 4 of 4)"), "{message}");
    // Picking the repeated name with `columns:` is ambiguous, not a silent first match.
    let message = load_error(
        json!({"format": "csv", "path": "dup.csv", "header_lines": 1, "time_column": "time", "unit": "g", "columns": {"x": "a"}}),
        &path,
    );
    assert!(message.contains("two columns named `a`") && message.contains("cannot tell them apart"), "{message}");
    // Leaving it out is fine.
    let spec = json!({"format": "csv", "path": "dup.csv", "header_lines": 1, "time_column": "time", "unit": "g", "columns": {"x": "b"}});
    assert_eq!(load::load_record(&source(spec), &part(&path, "")).unwrap().column_names(), ["time_s", "x"]);
}

#[test]
fn a_source_column_named_time_s_is_refused() {
    let dir = crate::tempdir::tempdir().unwrap();
    let path = dir.path().join("t.csv");
    std::fs::write(&path, "time_s,a\n0,1\n0.01,2\n").unwrap();
    let message = load_error(json!({"format": "csv", "path": "t.csv", "dt": 0.01, "unit": "g"}), &path);
    assert!(message.contains("t.csv:1:1: the file's column `time_s` would collide with the time column"), "{message}");
    assert!(message.contains("time_column: time_s"), "{message}");
}

/// (With `component_as: label`: by default an AT2 component is named by its axis, `ax_mps2`.)
#[test]
fn an_at2_component_labelled_time_s_is_refused() {
    let dir = crate::tempdir::tempdir().unwrap();
    let path = dir.path().join("t.AT2");
    let text = std::fs::read_to_string(ground_motion("Rinaldi228.AT2")).unwrap();
    let mut lines: Vec<&str> = text.split('\n').collect();
    lines[1] = "Northridge-01, 1/17/1994, Rinaldi Receiving Sta, time_s";
    std::fs::write(&path, lines.join("\n")).unwrap();
    let message = load_error(json!({"format": "at2", "path": "t.AT2", "component_as": "label"}), &path);
    assert!(message.contains("t.AT2:2:1: the file's column `time_s` would collide"), "{message}");
}

/// Used to panic at table.rs ("column `y` has 3 rows but the table has 4").
#[test]
fn simcenter_components_of_different_lengths_are_a_user_error() {
    let dir = crate::tempdir::tempdir().unwrap();
    let path = dir.path().join("r.json");
    std::fs::write(&path, r#"{"dT": 0.01, "data_x": [0.1, 0.2, 0.3, 0.4], "data_y": [0.1, 0.2, 0.3]}"#).unwrap();
    let message = load_error(json!({"format": "simcenter_json", "path": "r.json"}), &path);
    assert!(message.contains("r.json:1: \"data_y\" has 3 samples but \"data_x\" has 4"), "{message}");
}

/// 1e308 g overflows to infinity in conversion: it used to count as a "missing value" that
/// `gaps: interpolate` silently replaced.
#[test]
fn overflow_in_unit_conversion_is_named_not_filled() {
    let dir = crate::tempdir::tempdir().unwrap();
    let path = dir.path().join("big.csv");
    std::fs::write(&path, "time,a\n0,0.1\n0.01,1e308\n0.02,0.3\n0.03,0.2\n").unwrap();
    for gaps in ["error", "interpolate"] {
        let spec = json!({"format": "csv", "path": "big.csv", "time_column": "time", "unit": "g", "gaps": gaps});
        let message = load_error(spec, &path);
        assert!(
            message.contains("big.csv:3:1: column `a` overflows in unit conversion: sample 2 (1e308 g)"),
            "{message}"
        );
        assert!(!message.contains("missing value(s)"), "{message}");
    }
}

/// A column of gaps only used to be "filled" into an all-NaN column and written.
#[test]
fn a_column_of_gaps_only_is_refused() {
    let dir = crate::tempdir::tempdir().unwrap();
    let path = dir.path().join("fill.csv");
    std::fs::write(&path, "time,a,b\n0,,1\n0.01,NaN,2\n0.02,,3\n").unwrap();
    let spec =
        json!({"format": "csv", "path": "fill.csv", "time_column": "time", "unit": "m/s^2", "gaps": "interpolate"});
    let message = load_error(spec, &path);
    assert!(message.contains("column `a`: output sample 1 is not finite: every value is missing"), "{message}");
}

/// A damaged time column could ask resampling for 1e300 samples (an abort, or an overflow
/// panic in the sample count).
#[test]
fn resampling_a_damaged_time_column_is_bounded() {
    let dir = crate::tempdir::tempdir().unwrap();
    let path = dir.path().join("t.csv");
    std::fs::write(&path, "time,a\n0,1\n0.01,2\n0.02,3\n1e300,4\n").unwrap();
    let spec = json!({"format": "csv", "path": "t.csv", "time_column": "time", "unit": "g", "non_uniform": "resample"});
    let message = load_error(spec, &path);
    assert!(
        message.contains("resampling onto the median step") && message.contains("more than 100 times"),
        "{message}"
    );
}

/// The artifact must hold the bytes its `shakeflow.input_hash` names: a file that no longer
/// hashes as it did when the run was planned is refused, not loaded.
#[test]
fn a_record_replaced_while_the_run_reads_it_is_refused() {
    let dir = crate::tempdir::tempdir().unwrap();
    let path = dir.path().join("rec.csv");
    let planned = "time,a\n0,1\n0.01,2\n0.02,3\n";
    let spec = json!({"format": "csv", "path": "rec.csv", "time_column": "time", "unit": "g"});
    std::fs::write(&path, planned).unwrap();
    let table = load::load_record(&source(spec.clone()), &part(&path, &hash_bytes(planned.as_bytes()))).unwrap();
    assert_eq!(table.f64_column("a").unwrap().len(), 3);
    std::fs::write(&path, "time,a\n0,1\n0.01,2\n0.02,4\n").unwrap();
    let e = load::load_record(&source(spec), &part(&path, &hash_bytes(planned.as_bytes()))).unwrap_err();
    let message = e.to_string();
    assert!(message.contains("changed while this run was reading it"), "{message}");
    assert!(message.contains("rerun when it is no longer being written"), "{message}");
}

#[test]
fn control_points_replaced_while_the_run_reads_them_are_refused() {
    let dir = crate::tempdir::tempdir().unwrap();
    let path = dir.path().join("cp.csv");
    let planned = "X_mm,Y_mm,Z_mm,u_px,v_px\n0,0,0,1,2\n";
    std::fs::write(&path, planned).unwrap();
    let read = |hash: &str| shakeflow::io::control_points::read_control_points(&path, hash);
    assert_eq!(read(&hash_bytes(planned.as_bytes())).unwrap().len(), 1);
    std::fs::write(&path, "X_mm,Y_mm,Z_mm,u_px,v_px\n0,0,0,1,3\n").unwrap();
    let message = read(&hash_bytes(planned.as_bytes())).unwrap_err().to_string();
    assert!(message.contains("changed while this run was reading it"), "{message}");
}

/// A CSV 10⁶ columns wide loads (each added column used to be compared with every earlier
/// one: minutes of a quadratic check). No timing here: it finishes, with every column.
#[test]
fn a_csv_a_million_columns_wide_loads() {
    let dir = crate::tempdir::tempdir().unwrap();
    let path = dir.path().join("wide.csv");
    let width = 1_000_000;
    let mut text = String::from("time");
    for i in 0..width {
        text.push_str(&format!(",c{i}"));
    }
    for row in 0..2 {
        text.push_str(&format!("\n{}", row as f64 * 0.01));
        text.push_str(&",1".repeat(width));
    }
    std::fs::write(&path, text).unwrap();
    let spec = json!({"format": "csv", "path": "wide.csv", "time_column": "time", "unit": "g"});
    let table = load::load_record(&source(spec), &part(&path, "")).unwrap();
    assert_eq!(table.columns.len(), width + 1);
    assert_eq!(table.columns[width].name, format!("c{}", width - 1));
    assert_eq!(table.f64_column("c123456").unwrap(), [9.80665; 2]);
}

/// `validate` reads the first record as `load` does: a repeated column is its error too.
#[test]
fn validate_names_a_repeated_column() {
    let project = small_project();
    let csv = project.path().join("archive/FB-1/daq.csv");
    let text = std::fs::read_to_string(&csv).unwrap().replacen("Time,EW,NS", "Time,Time,NS", 1);
    std::fs::write(&csv, text).unwrap();
    let out = shakeflow(&["validate", "pipeline.yaml"], project.path());
    let message = stderr(&out);
    assert!(!out.status.success(), "{message}");
    assert!(message.contains("daq.csv:3:1") && message.contains("two columns named `Time`"), "{message}");
    assert!(!message.contains("panicked"), "{message}");
}

/// 1e308 m/s² used to give a `baseline` that exited 0 with every output sample NaN.
#[test]
fn a_baseline_that_overflows_fails_the_run() {
    let project = small_project();
    let root = project.path();
    let pipeline = std::fs::read_to_string(root.join("pipeline.yaml")).unwrap().replace("unit: g", "unit: m/s^2");
    std::fs::write(root.join("pipeline.yaml"), pipeline).unwrap();
    let csv = root.join("archive/FB-1/daq.csv");
    let mut lines: Vec<String> = std::fs::read_to_string(&csv).unwrap().lines().map(String::from).collect();
    let cells: Vec<String> = lines[10].split(',').map(String::from).collect();
    lines[10] = format!("{},1e308,{}", cells[0], cells[2]);
    std::fs::write(&csv, lines.join("\n") + "\n").unwrap();
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    let message = stderr(&out);
    assert!(!out.status.success(), "{message}");
    assert!(message.contains("column `ax_mps2`: the order-3 baseline fit is not finite"), "{message}");
    // The failed unit writes nothing; the record that succeeded is committed.
    assert!(!root.join("out/baseline/records/motion=FB-1").exists(), "a failed unit commits nothing");
    assert!(root.join("out/baseline/records/motion=FB-2/data.parquet").is_file(), "{message}");
    assert!(message.contains("stage `baseline` record motion=FB-1 failed"), "{message}");
}

/// A pipeline saved as UTF-16 is named as such; the terminal gets no NUL bytes.
#[test]
fn a_utf16_pipeline_is_named_as_such() {
    let project = small_project();
    let root = project.path();
    let text = std::fs::read_to_string(root.join("pipeline.yaml")).unwrap();
    let utf16: Vec<u8> = [0xff, 0xfe].into_iter().chain(text.encode_utf16().flat_map(u16::to_le_bytes)).collect();
    std::fs::write(root.join("pipeline.yaml"), utf16).unwrap();
    for command in ["validate", "run"] {
        let out = shakeflow(&[command, "pipeline.yaml"], root);
        assert!(!out.status.success());
        let message = stderr(&out);
        assert!(message.contains("pipeline.yaml: not a pipeline file: binary or UTF-16 file"), "{message}");
        assert!(!out.stderr.contains(&0), "{message:?}");
    }
}

#[test]
fn a_case_folder_changed_while_the_run_reads_it_is_refused() {
    let dir = crate::tempdir::tempdir().unwrap();
    let case = dir.path().join("demo_01");
    std::fs::create_dir(&case).unwrap();
    let shared = shared_dir().join("cases/demo/demo_01");
    for file in ["equipment.yaml", "floor.csv", "observed_accel.csv", "observed_cpt.csv"] {
        std::fs::copy(shared.join(file), case.join(file)).unwrap();
    }
    let planned = shakeflow::io::hash::hash_dir(&case).unwrap().0;
    assert!(shakeflow::io::case::read_case_unchanged(&case, &planned).is_ok());
    let floor = std::fs::read_to_string(case.join("floor.csv")).unwrap();
    // A blank line more: the case reads the same, its bytes are not what the run hashed.
    std::fs::write(case.join("floor.csv"), floor + "\n").unwrap();
    let message = shakeflow::io::case::read_case_unchanged(&case, &planned).unwrap_err().to_string();
    assert!(message.contains("demo_01` changed while this run was reading it"), "{message}");
}
