//! `shakeflow validate` before a run: every record file's header (not only the first file's),
//! column names carried through the stages (a downstream typo at its YAML line), and every error
//! in one report.

use crate::common::{shakeflow, small_project, stderr, PIPELINE};
use shakeflow::io::records;
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

/// A record cut short past its first 16 KB: the formats that state their sample count are
/// counted whole by `validate` (values counted, not parsed), so the truncated tenth record of a
/// suite is refused before a run at its file and the line `load` would name.
#[test]
fn a_record_truncated_past_its_head_is_refused_where_load_would() {
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    let records = crate::common::shared_dir().join("data/records");
    let suite = [
        (
            "gm",
            "at2",
            "*.AT2",
            vec![
                crate::common::ground_motion("RSN6_IMPVALL.I_I-ELC180.AT2"),
                crate::common::ground_motion("NIS090.AT2"),
            ],
        ),
        ("v2", "dmg", "*.V2", vec![records.join("dmg/CE89146.V2")]),
        ("smc", "smc", "*.smc", vec![records.join("smc/0111a.smc"), records.join("smc/2825.HNE.NP.--_u.smc")]),
        (
            "knet",
            "knet",
            "*.*",
            vec![records.join("knet/AOM0051801241951.EW"), records.join("knet/AOM0051801241951.NS")],
        ),
        ("cosmos", "cosmos", "*.V2c", vec![records.join("cosmos/us1000hyfh_akbmrp_AKBMR--n.1000hyfh.BNZ.--.acc.V2c")]),
        ("geonet", "geonet", "*.V2A", vec![records.join("geonet/20180212_211557_WPWS_20.V2A")]),
        ("esm", "esm", "*.ASC", vec![records.join("esm/HI.ARS1..HNE.D.20190728.160908.C.ACC.ASC")]),
    ];
    let mut pipeline = String::from("version: 1\noutput_dir: out\ninputs:\n");
    let mut expected = Vec::new();
    for (folder, format, glob, files) in &suite {
        std::fs::create_dir_all(root.join(folder)).unwrap();
        for file in files {
            std::fs::copy(file, root.join(folder).join(file.file_name().unwrap())).unwrap();
        }
        // The last file of the glob is a truncated copy of the first: 60 % of its bytes.
        let bytes = std::fs::read(&files[0]).unwrap();
        assert!(bytes.len() * 6 / 10 > 16 * 1024, "{}: too small to be cut past its head", files[0].display());
        let cut = &bytes[..bytes.len() * 6 / 10];
        let extension = files[0].extension().unwrap().to_string_lossy();
        let name = format!("zz_truncated.{extension}");
        std::fs::write(root.join(folder).join(&name), cut).unwrap();
        // Where `load` refuses it: the line its reader names.
        let reader = match *format {
            "at2" => records::parse_at2,
            "dmg" => records::parse_dmg,
            "smc" => records::parse_smc,
            "knet" => records::parse_knet,
            "cosmos" => records::parse_cosmos,
            "geonet" => records::parse_geonet,
            _ => records::parse_esm,
        };
        let line = reader(Path::new(&name), cut).expect_err("the reader refuses the cut copy").line.unwrap();
        expected.push(format!("{folder}/{name}:{line}: source `{folder}`: "));
        pipeline.push_str(&format!("  {folder}:\n    format: {format}\n    path: {folder}/{glob}\n"));
    }
    pipeline.push_str("stages:\n");
    for (folder, ..) in &suite {
        pipeline.push_str(&format!("  load_{folder}:\n    type: load\n    inputs: [{folder}]\n"));
    }
    let (ok, message) = validate(root, &pipeline);
    assert!(!ok, "{message}");
    let mut needles: Vec<&str> = expected.iter().map(String::as_str).collect();
    let count = format!("{} error(s)", suite.len());
    needles.push(&count);
    assert_all(&message, &needles);
    // Whole copies pass: the check does not refuse what `load` reads.
    for (folder, ..) in &suite {
        std::fs::remove_file(
            std::fs::read_dir(root.join(folder))
                .unwrap()
                .map(|e| e.unwrap().path())
                .find(|p| p.to_string_lossy().contains("zz_truncated"))
                .unwrap(),
        )
        .unwrap();
    }
    let (ok, message) = validate(root, &pipeline);
    assert!(ok, "{message}");
}
