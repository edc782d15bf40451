//! shakeflow removes or replaces only what it wrote and writes nothing outside its output folder:
//! each case a user met (issue 19) is refused before anything runs, with its line.

use crate::common::*;
use std::path::Path;

fn write(root: &Path, file: &str, text: &str) {
    let path = root.join(file);
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, text).unwrap();
}

/// `validate` and `run` both refuse, with these words; nothing changes in `root`.
fn refused(root: &Path, pipeline: &str, expected: &[&str]) {
    let before = snapshot(root);
    for command in ["validate", "run"] {
        let out = shakeflow(&[command, pipeline], root);
        let message = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "`{command}` did not refuse:\n{message}{}", stdout(&out));
        for needle in expected {
            assert!(message.contains(needle), "`{command}`'s message lacks `{needle}`:\n{message}");
        }
        assert!(!message.contains("panicked"), "{message}");
    }
    assert_eq!(before, snapshot(root), "a refused pipeline changed files");
}

#[test]
fn a_load_stage_named_like_the_records_folder_does_not_delete_the_records() {
    let project = small_project();
    let root = project.path();
    let pipeline = PIPELINE
        .replace("output_dir: out", "output_dir: .")
        .replace("  load:\n    type: load", "  archive:\n    type: load")
        .replace("inputs: [load]", "inputs: [archive]");
    write(root, "p.yaml", &pipeline);
    refused(root, "p.yaml", &["p.yaml:2:", "output_dir: .", "holds the pipeline file"]);
    assert!(root.join("archive/FB-1/daq.csv").is_file());
}

#[test]
fn output_dir_at_the_file_system_root_is_refused() {
    let project = small_project();
    let root = project.path();
    let archive = root.join("archive").display().to_string();
    let pipeline = PIPELINE
        .replace("output_dir: out", "output_dir: /")
        .replace("archive/{motion}/daq.csv", &format!("{archive}/{{motion}}/daq.csv"))
        .replace("  load:\n    type: load", "  home:\n    type: load")
        .replace("inputs: [load]", "inputs: [home]");
    write(root, "p.yaml", &pipeline);
    refused(root, "p.yaml", &["p.yaml:2:", "the root of a file system"]);
}

#[test]
fn output_dir_holding_the_inputs_is_refused() {
    let project = small_project();
    let root = project.path();
    write(
        root,
        "pipelines/p.yaml",
        &PIPELINE.replace("output_dir: out", "output_dir: ..").replace("path: archive", "path: ../archive"),
    );
    // `..` holds the pipeline's own folder and the archive: both reasons are true; the pipeline's is given.
    refused(root, "pipelines/p.yaml", &["pipelines/p.yaml:2:", "holds the pipeline file"]);
    write(
        root,
        "p2/p.yaml",
        &PIPELINE.replace("output_dir: out", "output_dir: ../archive").replace("path: archive", "path: ../archive"),
    );
    refused(root, "p2/p.yaml", &["p2/p.yaml:2:", "holds the files of source `daq`"]);
}

#[test]
fn a_stage_folder_shakeflow_did_not_write_is_never_replaced() {
    let project = small_project();
    let root = project.path();
    write(root, "out/baseline/thesis.tex", "years of work");
    refused(
        root,
        "pipeline.yaml",
        &["pipeline.yaml:17:", "stage `baseline` would replace", "was not written by shakeflow"],
    );
    assert_eq!(std::fs::read_to_string(root.join("out/baseline/thesis.tex")).unwrap(), "years of work");
    // What shakeflow wrote it does replace: rename the user's folder away and run twice.
    std::fs::rename(root.join("out/baseline"), root.join("mine")).unwrap();
    let first = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(first.status.success(), "{}", stderr(&first));
    let forced = shakeflow(&["run", "pipeline.yaml", "--force", "baseline"], root);
    assert!(forced.status.success(), "{}", stderr(&forced));
}

#[test]
fn stage_names_that_are_not_plain_folder_names_are_refused_at_their_line() {
    for (name, why) in [
        ("..", "parent"),
        ("/abs/dir", "separator"),
        ("a/../../x", "separator"),
        (".hidden", "starts with `.`"),
        ("shakeflow.lock", "lockfile"),
    ] {
        let project = small_project();
        let root = project.path();
        let yaml_name =
            if name.starts_with('/') || name.starts_with('.') { format!("\"{name}\"") } else { name.to_string() };
        let pipeline =
            PIPELINE.replace("  baseline:\n    type: baseline", &format!("  {yaml_name}:\n    type: baseline"));
        write(root, "p.yaml", &pipeline);
        refused(root, "p.yaml", &["p.yaml:17:", why]);
        assert!(
            !root.join("out").exists() || snapshot(&root.join("out")).is_empty(),
            "`{name}`: something was written"
        );
    }
}

#[test]
fn a_constant_partition_value_cannot_leave_the_output_folder() {
    let project = small_project();
    let root = project.path();
    let pipeline = PIPELINE.replace("    unit: g\n", "    unit: g\n    partition:\n      floor: x/../../../escaped\n");
    write(root, "p.yaml", &pipeline);
    refused(root, "p.yaml", &["p.yaml:11:", "partition value `x/../../../escaped` cannot name a folder", "separator"]);
    assert!(!root.parent().unwrap().join("escaped").exists());
}

#[test]
fn a_partition_value_from_a_file_name_is_encoded_into_one_folder_and_read_back() {
    let project = small_project();
    let root = project.path();
    std::fs::rename(root.join("archive/FB-2"), root.join("archive/FB 2 (100%)")).unwrap();
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(out.status.success(), "{}", stderr(&out));
    let encoded = root.join("out/baseline/records/motion=FB%202%20%28100%25%29/data.parquet");
    assert!(
        encoded.is_file(),
        "{:?}",
        snapshot(&root.join("out/baseline")).iter().map(|f| f.0.clone()).collect::<Vec<_>>()
    );
    // pyarrow decodes Hive segments as URIs: the partition reads back as the file named it.
    let script = "import sys, pyarrow.dataset as ds\n\
        t = ds.dataset(sys.argv[1], format='parquet', partitioning='hive').to_table(columns=['motion'])\n\
        print(sorted(set(t.column('motion').to_pylist())))";
    let printed = std::process::Command::new(python())
        .args(["-c", script, root.join("out/baseline/records").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(printed.status.success(), "{}", String::from_utf8_lossy(&printed.stderr));
    assert_eq!(String::from_utf8_lossy(&printed.stdout).trim(), "['FB 2 (100%)', 'FB-1']");
}

#[test]
fn stage_output_over_another_stage_types_output_is_refused() {
    let project = small_project();
    let root = project.path();
    let load = shakeflow(
        &[
            "stage",
            "load",
            "-i",
            "archive/FB-1/daq.csv",
            "-o",
            "loaded",
            "--set",
            "header_lines=2",
            "--set",
            "time_column=Time",
            "--set",
            "unit=g",
        ],
        root,
    );
    assert!(load.status.success(), "{}", stderr(&load));
    let baseline = shakeflow(&["stage", "baseline", "-i", "loaded/records", "-o", "based"], root);
    assert!(baseline.status.success(), "{}", stderr(&baseline));
    let before = snapshot(&root.join("based"));
    // Both types write a `records` output: only the marker tells them apart.
    let over = shakeflow(
        &[
            "stage",
            "load",
            "-i",
            "archive/FB-2/daq.csv",
            "-o",
            "based",
            "--set",
            "header_lines=2",
            "--set",
            "time_column=Time",
            "--set",
            "unit=g",
        ],
        root,
    );
    let message = stderr(&over);
    assert_eq!(over.status.code(), Some(1), "{message}");
    assert!(message.contains("an earlier output of stage type `baseline`, not `load`"), "{message}");
    assert_eq!(before, snapshot(&root.join("based")));
    // The same type may replace its own earlier output.
    let again = shakeflow(&["stage", "baseline", "-i", "loaded/records", "-o", "based", "--set", "order=2"], root);
    assert!(again.status.success(), "{}", stderr(&again));
}

#[test]
fn diagnose_out_never_replaces_a_folder_it_did_not_write() {
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    write(root, "report/thesis.tex", "years of work");
    let case = shared_dir().join("cases/demo/demo_01");
    let out = shakeflow(&["diagnose", case.to_str().unwrap(), "--out", "report"], root);
    let message = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{message}");
    assert!(message.contains("was not written by"), "{message}");
    assert_eq!(std::fs::read_to_string(root.join("report/thesis.tex")).unwrap(), "years of work");
}

#[test]
fn gc_removes_only_the_folders_of_stages_the_pipeline_dropped() {
    let project = small_project();
    let root = project.path();
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(out.status.success(), "{}", stderr(&out));
    write(root, "out/NOTES.txt", "mine");
    write(root, "out/plots/fig.png", "mine too");
    // The stage `baseline` leaves the pipeline: its folder is an orphan, the user's are not.
    let without = PIPELINE[..PIPELINE.find("  baseline:").unwrap()].to_string();
    write(root, "pipeline.yaml", &without);
    let status = shakeflow(&["status", "pipeline.yaml"], root);
    assert!(
        stdout(&status).contains("holds the outputs of stage `baseline`, which the pipeline no longer has"),
        "{}",
        stdout(&status)
    );
    let dry = shakeflow(&["gc", "pipeline.yaml", "--dry-run"], root);
    assert!(stdout(&dry).contains("would remove out/baseline"), "{}", stdout(&dry));
    assert!(root.join("out/baseline").is_dir());
    let gc = shakeflow(&["gc", "pipeline.yaml"], root);
    assert!(gc.status.success(), "{}", stderr(&gc));
    assert!(stdout(&gc).contains("1 orphaned stage folder(s)"), "{}", stdout(&gc));
    assert!(!root.join("out/baseline").exists());
    assert!(
        root.join("out/NOTES.txt").is_file()
            && root.join("out/plots/fig.png").is_file()
            && root.join("out/load").is_dir()
    );
    let again = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(stderr(&again).contains("0 ran, 1 cached"), "{}", stderr(&again));
}

#[test]
fn a_second_pipeline_writing_into_anothers_output_dir_is_refused() {
    let project = small_project();
    let root = project.path();
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(out.status.success(), "{}", stderr(&out));
    write(root, "other.yaml", PIPELINE);
    let before = snapshot(&root.join("out"));
    for command in ["run", "status", "validate"] {
        let refused = shakeflow(&[command, "other.yaml"], root);
        let message = stderr(&refused);
        assert_eq!(refused.status.code(), Some(1), "{message}");
        assert!(
            message.contains("other.yaml:2:")
                && message.contains("holds the results of another pipeline, `../pipeline.yaml`"),
            "{message}"
        );
    }
    assert_eq!(before, snapshot(&root.join("out")));
}

/// The files below `dir`, names only, links not followed: what a user sees in their own folder.
fn names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    names
}

/// Issue 34, as a user met it: a partition folder of `load/records/` replaced by a link to a
/// folder of theirs. Neither `run --force load` (which wrote `data.parquet` into their folder)
/// nor a run after that record left the archive (which deleted a file there) writes or removes
/// through the link: each refuses, naming it, and changes nothing; without the link the run
/// completes.
#[test]
fn a_symbolic_link_inside_the_output_folder_is_never_followed() {
    let project = small_project();
    let root = project.path();
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(out.status.success(), "{}", stderr(&out));
    write(root, "mine/thesis.txt", "years of work");
    let partition = root.join("out/load/records/motion=FB-1");
    std::fs::remove_dir_all(&partition).unwrap();
    std::os::unix::fs::symlink(root.join("mine"), &partition).unwrap();
    let link = "out/load/records/motion=FB-1` is a symbolic link";
    let refuses = |args: &[&str]| {
        let before = snapshot(root);
        let out = shakeflow(args, root);
        let message = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{args:?} did not refuse:\n{message}");
        assert!(message.contains(link) && message.contains("nothing was changed"), "{message}");
        assert!(!message.contains("panicked"), "{message}");
        assert_eq!(names(&root.join("mine")), ["thesis.txt"], "{args:?} wrote or removed through the link");
        assert_eq!(before, snapshot(root), "{args:?} changed files");
    };
    refuses(&["run", "pipeline.yaml", "--force", "load"]);
    refuses(&["run", "pipeline.yaml"]);
    // The record leaves the archive: its files would go, through the link.
    std::fs::rename(root.join("archive/FB-1"), root.join("FB-1.away")).unwrap();
    refuses(&["run", "pipeline.yaml"]);
    assert!(std::fs::symlink_metadata(&partition).unwrap().file_type().is_symlink(), "the link itself stays");
    // Without the link, the run completes: the gone record's outputs are removed.
    std::fs::remove_file(&partition).unwrap();
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!partition.exists() && root.join("out/load/records/motion=FB-2/data.parquet").is_file());
    assert_eq!(std::fs::read_to_string(root.join("mine/thesis.txt")).unwrap(), "years of work");
}

/// shakeflow's own state folder as a link: its transactions would be made and removed through it.
#[test]
fn a_state_folder_that_is_a_link_is_refused() {
    let project = small_project();
    let root = project.path();
    write(root, "mine/thesis.txt", "years of work");
    std::fs::create_dir_all(root.join("out")).unwrap();
    std::os::unix::fs::symlink(root.join("mine"), root.join("out/.shakeflow")).unwrap();
    let before = snapshot(root);
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    let message = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{message}");
    assert!(message.contains("out/.shakeflow` is a symbolic link"), "{message}");
    assert_eq!(before, snapshot(root));
    assert_eq!(names(&root.join("mine")), ["thesis.txt"]);
}
