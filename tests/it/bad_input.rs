//! Bad input, one test per case: non-zero exit, one clear message naming the file (and line),
//! no partial artifact, previous artifacts and the lockfile exactly as they were.

use crate::common;
use common::*;
use std::path::Path;

/// Runs the small project once successfully, applies `break_it`, reruns, and checks the failure.
fn fails_cleanly(break_it: impl FnOnce(&Path), expected: &[&str]) -> String {
    fails_cleanly_in(small_project(), break_it, expected)
}

/// The same for any project folder holding a `pipeline.yaml` that runs.
fn fails_cleanly_in(project: crate::tempdir::TempDir, break_it: impl FnOnce(&Path), expected: &[&str]) -> String {
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
    let project = crate::tempdir::tempdir().unwrap();
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

// The camera projection technique (cpt_calibrate, cpt_track, cpt_project).

fn replace_control_points(root: &Path, rows: impl Fn(&[&str]) -> Vec<String>) {
    edit(root, "control_points.csv", |t| {
        let lines: Vec<&str> = t.lines().collect();
        let mut out = vec![lines[0].to_string()];
        out.extend(rows(&lines[1..]));
        out.join("\n") + "\n"
    });
}

#[test]
fn coplanar_control_points() {
    let message = fails_cleanly_in(
        cpt_project(),
        |root| {
            replace_control_points(root, |rows| {
                rows.iter()
                    .map(|r| {
                        let mut cells: Vec<&str> = r.split(',').collect();
                        cells[3] = "0";
                        cells.join(",")
                    })
                    .collect()
            })
        },
        &["control_points.csv", "coplanar"],
    );
    assert!(message.contains("off that plane"), "the hint says what to do:\n{message}");
}

#[test]
fn too_few_control_points() {
    fails_cleanly_in(
        cpt_project(),
        |root| replace_control_points(root, |rows| rows[..7].iter().map(|r| r.to_string()).collect()),
        &["control_points.csv", "7 control point(s)", "at least 8"],
    );
}

#[test]
fn non_numeric_control_point() {
    fails_cleanly_in(
        cpt_project(),
        |root| edit(root, "control_points.csv", |t| t.replacen("C3,800,", "C3,8OO,", 1)),
        &["control_points.csv:4:4", "cannot read '8OO' as a number (X_mm)"],
    );
}

#[test]
fn ray_parallel_to_the_plane() {
    // A vertical plane through the camera centre that contains the tracked pixel's ray.
    let camera = cpt_test_camera();
    let c = camera.centre();
    let [x, y] = camera.normalised_of_pixel(40.0, 30.0).unwrap();
    let r = camera.rotation;
    let ray = [0, 1, 2].map(|k| r[0][k] * x + r[1][k] * y + r[2][k]);
    let normal = [ray[1], -ray[0], 0.0];
    let d = -(normal[0] * c[0] + normal[1] * c[1]);
    let plane = format!("{},{},0,{}", normal[0], normal[1], d);
    fails_cleanly_in(
        cpt_project(),
        |root| edit(root, "pipeline.yaml", |t| t.replace("plane: \"0,0,1,0\"", &format!("plane: \"{plane}\""))),
        &["stage `project`", "point M1 in frame 0", "nearly parallel", "check the plane"],
    );
}

#[test]
fn unreadable_frame() {
    fails_cleanly_in(
        cpt_project(),
        |root| std::fs::write(root.join("frames/f0003.png"), b"\x89PNG\r\n\x1a\n truncated").unwrap(),
        &["frames/f0003.png", "cannot decode the frame"],
    );
}

#[test]
fn start_point_outside_the_image() {
    fails_cleanly_in(
        cpt_project(),
        |root| edit(root, "pipeline.yaml", |t| t.replace("points: \"40,30\"", "points: \"40,30;95,20\"")),
        &["frames", "point M2", "start point (95.0, 20.0) is outside the 80×60 frame", "u from 0 to 79"],
    );
}

#[test]
fn frames_folder_without_a_frame_rate() {
    fails_cleanly_in(
        cpt_project(),
        |root| edit(root, "pipeline.yaml", |t| t.replace("      fps: 30\n", "")),
        &["frames", "no timestamps", "fps: 30"],
    );
}

#[test]
fn frames_source_fed_to_load() {
    fails_cleanly_in(
        cpt_project(),
        |root| edit(root, "pipeline.yaml", |t| t + "  load_video:\n    type: load\n    inputs: [video]\n"),
        &["pipeline.yaml:", "`video` is a `frames` source, which this stage type does not read", "feeds `cpt_track`"],
    );
}

#[test]
fn video_without_ffmpeg() {
    let project = cpt_project();
    let root = project.path();
    std::fs::write(root.join("clip.mp4"), b"not decoded without ffmpeg").unwrap();
    edit(root, "pipeline.yaml", |t| t.replace("path: frames", "path: clip.mp4"));
    let out = shakeflow_env(&["run", "pipeline.yaml"], root, &[("SHAKEFLOW_FFMPEG", "/nonexistent/ffmpeg")]);
    let message = stderr(&out);
    assert!(!out.status.success());
    for needle in [
        "clip.mp4",
        "needs the `ffmpeg` command-line tool, which was not found",
        "SHAKEFLOW_FFMPEG",
        "folder of PNG/JPEG frames",
    ] {
        assert!(message.contains(needle), "message lacks `{needle}`:\n{message}");
    }
    assert!(!root.join("out/track").exists(), "nothing written:\n{message}");
}

/// The baseline stage of the small project given a `select:` that matches no record.
fn fails_with_select(selection: &str, expected: &[&str]) {
    let select = format!("    inputs: [load]\n    select:\n      {selection}\n");
    fails_cleanly(|root| edit(root, "pipeline.yaml", |t| t.replace("    inputs: [load]\n", &select)), expected);
}

#[test]
fn select_by_a_misspelt_key() {
    fails_with_select("motoin: [FB-1]", &["pipeline.yaml:21:7", "selects by `motoin`", "did you mean `motion`"]);
}

#[test]
fn select_of_a_misspelt_value() {
    fails_with_select("motion: [FB1]", &["pipeline.yaml:21:7", "selects motion = `FB1`", "did you mean `FB-1`"]);
}

#[test]
fn a_key_given_twice() {
    fails_cleanly(
        |root| edit(root, "pipeline.yaml", |t| t.replace("      order: 3\n", "      order: 3\n      order: 2\n")),
        &["pipeline.yaml:", "duplicate entry with key \"order\"", "keep one"],
    );
}

#[test]
fn a_gap_in_time_is_blamed_on_its_own_line() {
    // 20 rows missing near the end of 400: the gap lengthens the mean step until every step
    // differs from it, yet the error must point at the gap (line 352 follows line 331).
    fails_cleanly(
        |root| {
            edit(root, "archive/FB-1/daq.csv", |t| {
                let lines: Vec<&str> = t.lines().collect();
                let kept: Vec<&str> = lines[..331].iter().chain(&lines[351..]).copied().collect();
                kept.join("\n") + "\n"
            })
        },
        &["archive/FB-1/daq.csv:332:1", "not uniformly sampled", "typical (median) step is 0.005000 s"],
    );
}

#[test]
fn stage_output_never_replaces_a_folder_of_other_files() {
    let project = small_project();
    let root = project.path();
    std::fs::create_dir(root.join("mine")).unwrap();
    std::fs::copy(root.join("archive/FB-1/daq.csv"), root.join("mine/daq.csv")).unwrap();
    std::fs::write(root.join("mine/notes.txt"), "keep me").unwrap();
    let before = snapshot(&root.join("mine"));
    let load = |input: &str, output: &str| {
        let set = ["--set", "header_lines=2", "--set", "time_column=Time", "--set", "unit=g"];
        let mut args = vec!["stage", "load", "--input", input, "--output", output];
        args.extend(set);
        shakeflow(&args, root)
    };
    for (input, message) in [
        ("mine/daq.csv", "the input `mine/daq.csv` is inside the output folder"),
        ("archive/FB-1/daq.csv", "was not written by shakeflow"),
    ] {
        let out = load(input, "mine");
        assert!(!out.status.success() && stderr(&out).contains(message), "{}", stderr(&out));
        assert!(stderr(&out).contains("give a new or empty folder"), "{}", stderr(&out));
        assert_eq!(snapshot(&root.join("mine")), before, "the folder was touched");
    }
    // A new folder is written, and then replaced by the same stage's next run.
    for _ in 0..2 {
        let out = load("mine/daq.csv", "fresh");
        assert!(out.status.success(), "{}", stderr(&out));
        assert!(root.join("fresh/records/data.parquet").is_file());
    }
}

#[test]
fn a_bad_set_value_is_named() {
    let project = small_project();
    let out = shakeflow(
        &["stage", "load", "--input", "archive/FB-1/daq.csv", "--output", "o", "--set", "header_lines=two"],
        project.path(),
    );
    let message = stderr(&out);
    assert!(!out.status.success() && message.contains("--set header_lines=\"two\": invalid type"), "{message}");
    assert!(!project.path().join("o").exists(), "nothing written");
}

#[test]
fn a_header_count_past_the_column_names() {
    fails_cleanly(
        |root| edit(root, "pipeline.yaml", |t| t.replace("header_lines: 2", "header_lines: 3")),
        &["archive/FB-1/daq.csv", "the row read as its header holds numbers", "lower it"],
    );
}

/// Reference (floors) and target (a second DAQ) datasets for `stage synchronize`, motions FB-1
/// and FB-2, the target's FB-2 without a reference record.
fn synchronize_inputs(root: &Path) {
    use shakeflow::table::{Column, Table};
    let series = |name: &str, phase: f64| {
        let mut t = Table::new();
        t.push(Column::f64("time_s", "s", "time", (0..400).map(|k| k as f64 * 0.005).collect()));
        t.push(Column::f64(name, "m/s^2", "a", (0..400).map(|k| (k as f64 * 0.05 + phase).sin()).collect()));
        t
    };
    for (dir, name) in
        [("floors/motion=FB-1/floor=5", "ax_mps2"), ("daq2/motion=FB-1", "sync"), ("daq2/motion=FB-2", "sync")]
    {
        std::fs::create_dir_all(root.join(dir)).unwrap();
        shakeflow::io::parquet::write_table(&root.join(dir).join("data.parquet"), &series(name, 0.3)).unwrap();
    }
}

#[test]
fn a_record_the_reference_lacks_is_named() {
    let dir = crate::tempdir::tempdir().unwrap();
    synchronize_inputs(dir.path());
    let sync = |extra: &[&str]| {
        let mut args = vec!["stage", "synchronize", "--input", "floors", "--input", "daq2", "--output", "out"];
        args.extend(["--set", "target_channel=sync", "--set", "mcap=false", "--set", "max_lag_s=0.5"]);
        args.extend(extra);
        shakeflow(&args, dir.path())
    };
    let out = sync(&[]);
    let message = stderr(&out);
    assert!(!out.status.success(), "{message}");
    assert!(
        message.contains("no record for `motion=FB-2` at all")
            && message.contains("is its file missing? (the reference's `motion` values: FB-1)"),
        "{message}"
    );
    let out = sync(&["--set", "reference_select=floor5"]);
    assert!(stderr(&out).contains("`reference_select` must look like key=value, not `floor5`"), "{}", stderr(&out));
    assert!(!dir.path().join("out").exists(), "nothing written");
}

#[test]
fn validate_reads_a_source_file_and_names_a_misspelt_column() {
    let project = small_project();
    edit(project.path(), "pipeline.yaml", |t| t.replace("ay_mps2: NS", "ay_mps2: NSS"));
    let out = shakeflow(&["validate", "pipeline.yaml"], project.path());
    let message = stderr(&out);
    assert!(!out.status.success(), "{message}");
    for needle in
        ["daq.csv", "source `daq`, read as `load` would", "no column `NSS`", "did you mean `NS`", "pipeline.yaml:12:7"]
    {
        assert!(message.contains(needle), "message lacks `{needle}`:\n{message}");
    }
}
