//! The hash memo (`<output_dir>/.shakeflow/hashes.json`): a rerun reads no unchanged file, and
//! still sees every change — one that keeps the file's size and puts its modification time back
//! included (its change time moves).

use crate::common::*;
use std::time::{Duration, SystemTime};

#[test]
fn a_rerun_sees_a_change_that_keeps_size_and_modification_time() {
    let project = small_project();
    let root = project.path();
    let daq = root.join("archive/FB-2/daq.csv");
    // Settled files (older than the memo's 2 s) are remembered.
    let past = SystemTime::now() - Duration::from_secs(60);
    for motion in ["FB-1", "FB-2"] {
        set_mtime(&root.join(format!("archive/{motion}/daq.csv")), past);
    }
    assert!(shakeflow(&["run", "pipeline.yaml"], root).status.success());
    let memo = std::fs::read_to_string(root.join("out/.shakeflow/hashes.json")).unwrap();
    assert!(memo.contains("FB-2/daq.csv"), "{memo}");
    assert!(stderr(&shakeflow(&["run", "pipeline.yaml"], root)).contains("2 cached"));
    // The same number of bytes, one digit changed, the old modification time put back.
    let text = std::fs::read_to_string(&daq).unwrap();
    let at = text.find("\n0.005000,").unwrap() + "\n0.005000,".len();
    let at = at + text[at..].find(|c: char| c.is_ascii_digit()).unwrap();
    let digit = if &text[at..=at] == "7" { "3" } else { "7" };
    let changed = format!("{}{digit}{}", &text[..at], &text[at + 1..]);
    assert_eq!(changed.len(), text.len());
    assert_ne!(changed, text);
    std::fs::write(&daq, changed).unwrap();
    set_mtime(&daq, past);
    let status = stdout(&shakeflow(&["status", "pipeline.yaml"], root));
    assert!(status.contains("record motion=FB-2: input") && status.contains("changed"), "{status}");
    let rerun = stderr(&shakeflow(&["run", "pipeline.yaml"], root));
    assert!(rerun.contains("1 unit(s) ran, 1 cached"), "{rerun}");
}
