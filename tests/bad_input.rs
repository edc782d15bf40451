//! Bad input, one test per case: non-zero exit, one clear message naming the file (and line),
//! no partial artifact, previous artifacts and the lockfile exactly as they were.

mod common;
use common::*;
use std::path::Path;

/// Runs the small project once successfully, applies `break_it`, reruns, and checks the failure.
fn fails_cleanly(break_it: impl FnOnce(&Path), expected: &[&str]) -> String {
    let project = small_project();
    let root = project.path();
    let ok = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(ok.status.success(), "{}", stderr(&ok));
    break_it(root);
    let before = snapshot(&root.join("out"));
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    let message = stderr(&out);
    assert!(!out.status.success(), "expected a failure, got success:\n{message}");
    for needle in expected {
        assert!(message.contains(needle), "message lacks `{needle}`:\n{message}");
    }
    assert_eq!(before, snapshot(&root.join("out")), "artifacts or lockfile changed after a failed run:\n{message}");
    message
}

fn edit(root: &Path, file: &str, f: impl FnOnce(String) -> String) {
    let path = root.join(file);
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, f(text)).unwrap();
}

#[test]
fn truncated_file() {
    fails_cleanly(
        |root| edit(root, "archive/FB-2/daq.csv", |t| t[..t.len() - 20].to_string()),
        &["archive/FB-2/daq.csv:403", "may be truncated"],
    );
}

#[test]
fn non_numeric_cell() {
    fails_cleanly(
        |root| {
            edit(root, "archive/FB-1/daq.csv", |t| {
                t.replacen("0.005000,", "0.005000,abc", 1).replacen("abc1", "abc", 1)
            })
        },
        &["archive/FB-1/daq.csv:5", "(EW)", "abc"],
    );
}

#[test]
fn nan_without_a_gap_policy() {
    let message = fails_cleanly(
        |root| {
            edit(root, "archive/FB-1/daq.csv", |t| {
                let mut lines: Vec<String> = t.lines().map(String::from).collect();
                let cells: Vec<&str> = lines[10].split(',').collect();
                lines[10] = format!("{},NaN,{}", cells[0], cells[2]);
                lines.join("\n") + "\n"
            })
        },
        &["archive/FB-1/daq.csv:11", "missing value"],
    );
    assert!(message.contains("gaps: interpolate"), "the message says how to fill gaps:\n{message}");
}

#[test]
fn non_uniform_time() {
    fails_cleanly(
        |root| edit(root, "archive/FB-1/daq.csv", |t| t.replacen("\n0.100000,", "\n0.103000,", 1)),
        &["archive/FB-1/daq.csv:24:1", "not uniformly sampled", "non_uniform: resample"],
    );
}

#[test]
fn ragged_row() {
    fails_cleanly(
        |root| {
            edit(root, "archive/FB-1/daq.csv", |t| {
                let mut lines: Vec<String> = t.lines().map(String::from).collect();
                lines[20].push_str(",0.5");
                lines.join("\n") + "\n"
            })
        },
        &["archive/FB-1/daq.csv:21", "4"],
    );
}

#[test]
fn wrong_npts_in_an_at2_record() {
    let project = tempfile::tempdir().unwrap();
    let root = project.path();
    let original = std::fs::read_to_string(ground_motion("Rinaldi228.AT2")).unwrap();
    std::fs::write(root.join("rec.AT2"), &original).unwrap();
    std::fs::write(
        root.join("pipeline.yaml"),
        "version: 1\noutput_dir: out\ninputs:\n  rec:\n    format: at2\n    path: rec.AT2\nstages:\n  load:\n    type: load\n    inputs: [rec]\n",
    )
    .unwrap();
    assert!(shakeflow(&["run", "pipeline.yaml"], root).status.success());
    let before = snapshot(&root.join("out"));
    std::fs::write(root.join("rec.AT2"), original.replace("NPTS=   1991", "NPTS=   1992")).unwrap();
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    let message = stderr(&out);
    assert!(!out.status.success());
    assert!(message.contains("rec.AT2") && message.contains("1992") && message.contains("1991"), "{message}");
    assert_eq!(before, snapshot(&root.join("out")));
}

#[test]
fn unknown_stage_type() {
    fails_cleanly(
        |root| edit(root, "pipeline.yaml", |t| t.replace("type: baseline", "type: baselin")),
        &["pipeline.yaml:18:5", "unknown stage type `baselin`", "did you mean `baseline`"],
    );
}

#[test]
fn cyclic_pipeline() {
    fails_cleanly(
        |root| edit(root, "pipeline.yaml", |t| t.replace("inputs: [load]", "inputs: [baseline]")),
        &["pipeline.yaml:", "cycle: baseline → baseline"],
    );
}

#[test]
fn unknown_yaml_key() {
    fails_cleanly(
        |root| edit(root, "pipeline.yaml", |t| t.replace("    params:\n", "    parms:\n")),
        &["pipeline.yaml:20:5", "unknown field `parms`"],
    );
}

#[test]
fn missing_input_file() {
    fails_cleanly(
        |root| std::fs::remove_dir_all(root.join("archive")).unwrap(),
        &["pipeline.yaml:6:5", "source `daq`: no file matches `archive/{motion}/daq.csv`"],
    );
}

#[test]
fn unwritable_output_dir() {
    // Tests may run as root, which ignores permissions: a path through a regular file is unwritable for anyone.
    let project = small_project();
    let root = project.path();
    std::fs::write(root.join("blocker"), "not a directory").unwrap();
    edit(root, "pipeline.yaml", |t| t.replace("output_dir: out", "output_dir: blocker/out"));
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    let message = stderr(&out);
    assert!(!out.status.success());
    assert!(
        message.contains("pipeline.yaml:2:1") && message.contains("cannot create the output directory"),
        "{message}"
    );
}

#[test]
fn validate_points_at_a_typo() {
    let project = small_project();
    edit(project.path(), "pipeline.yaml", |t| t.replace("order: 3", "ordr: 3"));
    let out = shakeflow(&["validate", "pipeline.yaml"], project.path());
    let message = stderr(&out);
    assert!(!out.status.success());
    assert!(
        message.contains("pipeline.yaml:21:7: unknown parameter `ordr`") && message.contains("did you mean `order`"),
        "{message}"
    );
}

#[test]
fn damaged_lockfile_is_an_error_not_a_silent_reset() {
    fails_cleanly(
        |root| edit(root, "out/shakeflow.lock", |t| t.replace("stages:", "stages: [")),
        &["shakeflow.lock", "damaged"],
    );
}
