//! `shakeflow validate` before a run: every record file's header (not only the first file's),
//! column names carried through the stages (a downstream typo at its YAML line), and every error
//! in one report.

use crate::common::{shakeflow, small_project, stderr, PIPELINE};
use std::path::Path;

fn validate(root: &Path, pipeline: &str) -> (bool, String) {
    std::fs::write(root.join("pipeline.yaml"), pipeline).unwrap();
    let out = shakeflow(&["validate", "pipeline.yaml"], root);
    (out.status.success(), stderr(&out))
}

fn assert_all(message: &str, needles: &[&str]) {
    for needle in needles {
        assert!(message.contains(needle), "message lacks `{needle}`:\n{message}");
    }
}

/// The small project's pipeline with stages below `baseline` (lines 22 on).
fn with_stages(more: &str) -> String {
    format!("{PIPELINE}{more}")
}

#[test]
fn column_typos_downstream_are_reported_together_at_their_lines() {
    let project = small_project();
    let pipeline = with_stages(
        "      columns: [ax_mps2, ay_mps3]
  topple:
    type: detect_toppling
    inputs: [baseline]
    params:
      channels: [top_ax_mps3]
  rock:
    type: simulate_toppling
    inputs: [baseline]
    params:
      preset: PS2
      horizontal: ax_mps2
      vertical: az_mps2
",
    );
    let (ok, message) = validate(project.path(), &pipeline);
    assert!(!ok, "{message}");
    assert_all(
        &message,
        &[
            "pipeline.yaml:22:7: parameter `columns` names the column `ay_mps3`",
            "did you mean `ay_mps2`",
            "pipeline.yaml:27:7: parameter `channels` names the column `top_ax_mps3`",
            "pipeline.yaml:34:7: parameter `vertical` names the column `az_mps2`",
            "the input's columns: time_s, ax_mps2, ay_mps2",
            "3 error(s)",
        ],
    );
    // The same pipeline with the names right validates.
    let fixed = pipeline
        .replace("ay_mps3", "ay_mps2")
        .replace("[top_ax_mps3]", "[ax_mps2]")
        .replace("      vertical: az_mps2\n", "");
    let (ok, message) = validate(project.path(), &fixed);
    assert!(ok, "{message}");
}

#[test]
fn every_stage_error_is_reported_not_only_the_first() {
    let project = small_project();
    let pipeline = with_stages(
        "  topple:
    type: detect_toppling
    inputs: [baseline]
  again:
    type: baseline
    inputs: [load]
    params:
      ordr: 2
",
    );
    let (ok, message) = validate(project.path(), &pipeline);
    assert!(!ok, "{message}");
    assert_all(&message, &["channels", "pipeline.yaml:22:", "pipeline.yaml:29:7", "ordr", "2 error(s)"]);
}

#[test]
fn every_record_file_gets_a_header_check_not_only_the_first() {
    let project = small_project();
    let root = project.path();
    // The third record lacks the time column; the fourth is a PEER AT2 file among the CSVs.
    crate::common::write_daq_csv(&root.join("archive/FB-3/daq.csv"), 400, 200.0, 0.5);
    let text = std::fs::read_to_string(root.join("archive/FB-3/daq.csv")).unwrap();
    std::fs::write(root.join("archive/FB-3/daq.csv"), text.replace("Time,EW,NS", "Tme,EW,NS")).unwrap();
    std::fs::create_dir_all(root.join("archive/FB-4")).unwrap();
    std::fs::copy(crate::common::ground_motion("RSN6_IMPVALL.I_I-ELC180.AT2"), root.join("archive/FB-4/daq.csv"))
        .unwrap();
    let (ok, message) = validate(root, PIPELINE);
    assert!(!ok, "{message}");
    assert_all(
        &message,
        &[
            "archive/FB-3/daq.csv:3:1: source `daq`: the file has no column `Time`",
            "did you mean `Tme`",
            "archive/FB-4/daq.csv:1: source `daq`: the file starts like a `at2` record, but the source reads `csv`",
            "2 error(s)",
        ],
    );
}
