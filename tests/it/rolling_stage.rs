//! `simulate_rolling` as users meet it: in a pipeline and through `shakeflow stage`. Bad input
//! (one test per case) stops with a message naming the file and what to do, a non-zero exit and
//! nothing written; an equipment file is part of the cache key; artifacts are bit-identical.

use crate::common;
use common::*;
use std::path::Path;

/// The small project (load → baseline on two 2 s records at 0.1 g) plus a rolling stage whose
/// params block ends with `extra` (line 27 onwards).
fn rolling_project(extra: &str) -> crate::tempdir::TempDir {
    let project = small_project();
    let text = format!(
        "{PIPELINE}  rolling:\n    type: simulate_rolling\n    inputs: [baseline]\n    params:\n      preset: PB2\n{extra}"
    );
    std::fs::write(project.path().join("pipeline.yaml"), text).unwrap();
    project
}

/// `validate` and `run` both refuse, naming the place; nothing is written.
fn refused(project: &crate::tempdir::TempDir, expected: &[&str]) -> String {
    let root = project.path();
    for command in ["validate", "run"] {
        let out = shakeflow(&[command, "pipeline.yaml"], root);
        let message = stderr(&out);
        assert!(!out.status.success(), "`{command}` accepted it:\n{message}");
        for needle in expected {
            assert!(message.contains(needle), "`{command}` message lacks `{needle}`:\n{message}");
        }
    }
    assert!(!root.join("out").exists(), "a refused pipeline wrote artifacts");
    stderr(&shakeflow(&["validate", "pipeline.yaml"], root))
}

#[test]
fn a_parameter_typo_is_found_with_its_line() {
    let message =
        refused(&rolling_project("      trial_m: 0.05\n"), &["pipeline.yaml:27:7: unknown parameter `trial_m`"]);
    assert!(message.contains("did you mean `trail_m`"), "{message}");
}

#[test]
fn unknown_preset() {
    let project = rolling_project("");
    edit(&project, |t| t.replace("preset: PB2", "preset: PB3"));
    refused(&project, &["pipeline.yaml:26:7", "expected one of PS1, PB2, MC2, UI3, found \"PB3\""]);
}

#[test]
fn negative_mass() {
    refused(&rolling_project("      platform_mass_kg: -350\n"), &["pipeline.yaml:27:7", "platform_mass_kg", "-350"]);
}

#[test]
fn zero_trail_without_the_slip_option() {
    let message = refused(&rolling_project("      trail_m: 0\n"), &["pipeline.yaml:27:7", "zero trail"]);
    assert!(message.contains("lateral_slip: true"), "the message says what to do:\n{message}");
    // With the slip option it is a valid (literal) model.
    let project = rolling_project("      trail_m: 0\n      lateral_slip: true\n");
    let out = shakeflow(&["validate", "pipeline.yaml"], project.path());
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn malformed_equipment_files() {
    for (content, expected) in [
        ("platform_mass_kg: 300\nlenght_m: 2.0\n", &["bed.yaml`:2:1", "unknown parameter `lenght_m`", "length_m"][..]),
        ("platform_mass_kg: [300\n", &["bed.yaml`", "not valid YAML"][..]),
        ("steer0_deg: [1, 2]\n", &["bed.yaml`:1:1", "list of 4 numbers"][..]),
        ("- 1\n- 2\n", &["bed.yaml`", "expected a mapping of model keys"][..]),
    ] {
        let project = rolling_project("      equipment: units/bed.yaml\n");
        std::fs::create_dir(project.path().join("units")).unwrap();
        std::fs::write(project.path().join("units/bed.yaml"), content).unwrap();
        let mut needles = vec!["pipeline.yaml:27:7"];
        needles.extend(expected);
        refused(&project, &needles);
    }
    refused(
        &rolling_project("      equipment: units/none.yaml\n"),
        &["pipeline.yaml:27:7", "no file", "units/none.yaml"],
    );
}

#[test]
fn a_missing_channel_fails_the_run_and_changes_nothing() {
    let project = rolling_project("      x_channel: floor4_ax_mps2\n");
    let root = project.path();
    edit(&project, |t| t.replace("      x_channel: floor4_ax_mps2\n", ""));
    assert!(shakeflow(&["run", "pipeline.yaml"], root).status.success());
    let before = snapshot(&root.join("out"));
    edit(&project, |t| t + "      x_channel: floor4_ax_mps2\n");
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    let message = stderr(&out);
    assert!(!out.status.success());
    for needle in ["baseline.records/motion=FB-1/data.parquet", "no float column `floor4_ax_mps2`", "ax_mps2, ay_mps2"]
    {
        assert!(message.contains(needle), "message lacks `{needle}`:\n{message}");
    }
    assert_eq!(before, snapshot(&root.join("out")), "artifacts or lockfile changed after a failed run");
}

#[test]
fn non_uniform_time_through_the_stage_command() {
    use shakeflow::table::{Column, Table};
    let dir = crate::tempdir::tempdir().unwrap();
    let mut table = Table::new();
    let time: Vec<f64> = (0..100).map(|k| k as f64 * 0.01 + if k > 50 { 0.003 } else { 0.0 }).collect();
    table.push(Column::f64("time_s", "s", "time", time));
    table.push(Column::f64("ax_mps2", "m/s^2", "x", vec![0.5; 100]));
    table.push(Column::f64("ay_mps2", "m/s^2", "y", vec![0.0; 100]));
    shakeflow::io::parquet::write_table(&dir.path().join("floor.parquet"), &table).unwrap();
    let out = shakeflow(
        &["stage", "simulate_rolling", "--input", "floor.parquet", "--output", "out", "--set", "preset=MC2"],
        dir.path(),
    );
    let message = stderr(&out);
    assert!(!out.status.success());
    assert!(
        message.contains("floor.parquet") && message.contains("not uniformly sampled") && message.contains("0.5"),
        "{message}"
    );
    assert!(!dir.path().join("out").exists(), "nothing is written");
}

#[test]
fn the_stage_command_takes_lists_and_presets() {
    let project = small_project();
    let root = project.path();
    assert!(shakeflow(&["run", "pipeline.yaml"], root).status.success());
    let input = "out/baseline/records/motion=FB-1/data.parquet";
    let run = |sets: &[&str], output: &str| {
        let mut args = vec!["stage", "simulate_rolling", "--input", input, "--output", output];
        for s in sets {
            args.extend(["--set", s]);
        }
        shakeflow(&args, root)
    };
    let out =
        run(&["preset=PS1", "steer0_deg=[80,0,0,80]", "yaw0_deg=6", "friction_law=stick_slip", "mcap=true"], "ps1");
    assert!(out.status.success(), "{}", stderr(&out));
    let trajectory = shakeflow::io::parquet::read_table(&root.join("ps1/trajectory/data.parquet")).unwrap();
    let facts: serde_json::Value = serde_json::from_str(&trajectory.metadata["shakeflow.rolling"]).unwrap();
    assert_eq!(facts["model"]["steer0_deg"], serde_json::json!([80.0, 0.0, 0.0, 80.0]));
    assert_eq!(facts["friction_law"], "stick_slip");
    let delta1 = trajectory.f64_column("delta1_rad").unwrap();
    assert_eq!(delta1[0], 80f64.to_radians());
    assert!(root.join("ps1/mcap/trajectory/data.mcap").is_file() && root.join("ps1/figures/PS1.png").is_file());
    for column in &trajectory.columns {
        assert!(!column.description.is_empty(), "{} has no description", column.name);
    }
    let out = run(&["preset=PS1", "steer0_deg=[80,0]"], "bad");
    let message = stderr(&out);
    assert!(!out.status.success() && message.contains("list of 4 numbers"), "{message}");
    let out = run(&["length_m=1.0"], "bad");
    let message = stderr(&out);
    assert!(
        !out.status.success() && message.contains("needs `wheel_diameter_m`") && message.contains("preset"),
        "{message}"
    );
}

#[test]
fn editing_the_equipment_file_reruns_the_stage_and_artifacts_are_reproducible() {
    let project = rolling_project("      equipment: bed.yaml\n");
    let root = project.path();
    std::fs::write(root.join("bed.yaml"), "platform_mass_kg: 300\n").unwrap();
    let first = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(first.status.success(), "{}", stderr(&first));
    let artifacts = snapshot(&root.join("out/rolling"));
    let again = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(stderr(&again).contains("rolling            cached"), "{}", stderr(&again));
    // Another clone of the project, run from scratch: the same bytes.
    let twin = rolling_project("      equipment: bed.yaml\n");
    std::fs::write(twin.path().join("bed.yaml"), "platform_mass_kg: 300\n").unwrap();
    assert!(shakeflow(&["run", "pipeline.yaml"], twin.path()).status.success());
    let relative = |files: Vec<(std::path::PathBuf, Vec<u8>)>, base: &Path| {
        files.into_iter().map(|(p, b)| (p.strip_prefix(base).unwrap().to_path_buf(), b)).collect::<Vec<_>>()
    };
    assert_eq!(
        relative(artifacts.clone(), &root.join("out/rolling")),
        relative(snapshot(&twin.path().join("out/rolling")), &twin.path().join("out/rolling")),
        "bit-identical artifacts"
    );
    std::fs::write(root.join("bed.yaml"), "platform_mass_kg: 320\n").unwrap();
    let status = stdout(&shakeflow(&["status", "pipeline.yaml"], root));
    assert!(status.contains("input `params.equipment (bed.yaml)` changed"), "{status}");
    let rerun = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(stderr(&rerun).contains("rolling            running"), "{}", stderr(&rerun));
    assert_ne!(artifacts, snapshot(&root.join("out/rolling")));
}

fn edit(project: &crate::tempdir::TempDir, f: impl FnOnce(String) -> String) {
    let path = project.path().join("pipeline.yaml");
    std::fs::write(&path, f(std::fs::read_to_string(&path).unwrap())).unwrap();
}
