//! `shakeflow diagnose` on the demo cases of ../shared/cases/demo, whose concealed effects were
//! made by another team's generator (truth/<case>.yaml, never read by the tool): the verdict is
//! the expected one, the window starts within 0.5 s of the true onset, and where a physics is
//! found the fit improves at least threefold. Also the `diagnose` stage in a pipeline, and bad
//! case folders.
use crate::common;
use common::*;
use std::path::Path;

fn truth(id: &str) -> serde_yaml::Value {
    let path = shared_dir().join("cases/demo/truth").join(format!("{id}.yaml"));
    serde_yaml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

#[test]
fn demo_cases_get_their_concealed_verdicts() {
    let out = crate::tempdir::tempdir().unwrap();
    let ids = ["demo_01", "demo_02", "demo_03", "demo_04"];
    let dirs: Vec<String> =
        ids.iter().map(|id| shared_dir().join("cases/demo").join(id).display().to_string()).collect();
    let mut args = vec!["diagnose"];
    args.extend(dirs.iter().map(String::as_str));
    args.extend(["--out", out.path().to_str().unwrap()]);
    let run = shakeflow(&args, out.path());
    assert!(run.status.success(), "{}", stderr(&run));
    for id in ids {
        let dir = out.path().join(id);
        let d: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("diagnosis.json")).unwrap()).unwrap();
        for key in ["mismatch", "verdict", "window", "rmse_before", "rmse_after", "candidates", "explanation"] {
            assert!(d.get(key).is_some(), "{id}: diagnosis.json lacks `{key}`");
        }
        // The stage's layout beside the contract: its tables by case, a figure per case.
        for file in [
            format!("accel/case={id}/data.parquet"),
            format!("camera/case={id}/data.parquet"),
            format!("reports/{id}.png"),
        ] {
            assert!(out.path().join(&file).is_file(), "{id}: no {file}");
        }
        let truth = truth(id);
        let expected = truth["expected_verdict"].as_str().unwrap();
        let onset = truth["onset_s"].as_f64().unwrap();
        let (before, after) = (d["rmse_before"].as_f64().unwrap(), d["rmse_after"].as_f64().unwrap());
        let start = d["window"]["start_s"].as_f64().expect("a mismatch window");
        println!(
            "{id}: {} (truth {expected}), window from {start:.2} s (onset {onset:.2} s), rmse {before:.1} → {after:.2}",
            d["verdict"]
        );
        assert_eq!(d["verdict"], expected, "{id}: {}", d["explanation"]);
        assert_eq!(d["mismatch"], true);
        assert!((start - onset).abs() < 0.5, "{id}: window starts at {start}, onset {onset}");
        if expected != "unexplained" {
            assert!(after <= before / 3.0, "{id}: rmse {before} → {after}");
            assert!(after < 1.5, "{id}: the accepted model should leave sensor noise, rmse {after}");
        }
        let candidates = d["candidates"].as_array().unwrap();
        assert_eq!(candidates[0]["effect"], "none");
        assert_eq!(candidates.len(), 7, "the baseline and the six effects of the library");
        // A named physics shows its own signature where it begins (the nominal model has none),
        // and the file says what was left to a smooth model discrepancy.
        let discrepancy = &d["discrepancy"];
        let needed = discrepancy["signature_chi2_needed"].as_f64().expect("discrepancy.signature_chi2_needed");
        assert!(candidates[0].get("signature_chi2").is_none());
        for c in &candidates[1..] {
            assert!(c["signature_chi2"].is_number(), "{id}: {} has no signature_chi2", c["effect"]);
        }
        if expected != "unexplained" {
            let gain = candidates[1]["signature_chi2"].as_f64().unwrap();
            assert!(gain >= needed, "{id}: the named physics's signature χ² {gain} < {needed}");
        }
        assert!(discrepancy["left_rmse"].as_f64().unwrap() >= 0.0 && discrepancy["without_signature"].is_array());
        assert!(discrepancy["left_largest"]["accel_mps2"].is_number(), "{id}: {discrepancy}");
    }
    // The concealed parameters are recovered (truth/demo_02.yaml, truth/demo_04.yaml).
    let d: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.path().join("demo_02/diagnosis.json")).unwrap()).unwrap();
    let params = &d["candidates"][1]["params"];
    assert!((params["t0_s"].as_f64().unwrap() - 4.58848).abs() < 0.02, "{params}");
    assert!((params["f_after"].as_f64().unwrap() - -0.0445693).abs() < 0.005, "{params}");
    let d: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.path().join("demo_04/diagnosis.json")).unwrap()).unwrap();
    let params = &d["candidates"][1]["params"];
    assert_eq!(params["side"].as_f64(), Some(1.0));
    assert!((params["angle_rad"].as_f64().unwrap() - 0.199619).abs() < 0.005, "{params}");
    assert!((params["restitution"].as_f64().unwrap() - 0.651663).abs() < 0.05, "{params}");
}

fn copy_case(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
    }
}

const PIPELINE: &str = "\
version: 1
output_dir: out
inputs:
  cases:
    format: case
    path: cases/{case}/equipment.yaml
stages:
  diagnosis:
    type: diagnose
    inputs: [cases]
";

#[test]
fn the_diagnose_stage_in_a_pipeline() {
    let project = crate::tempdir::tempdir().unwrap();
    let root = project.path();
    for id in ["demo_01", "demo_02"] {
        copy_case(&shared_dir().join("cases/demo").join(id), &root.join("cases").join(id));
    }
    std::fs::write(root.join("pipeline.yaml"), PIPELINE).unwrap();
    let run = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(run.status.success(), "{}", stderr(&run));
    let table = shakeflow::io::parquet::read_table(&root.join("out/diagnosis/diagnosis/data.parquet")).unwrap();
    let shakeflow::table::ColumnData::Str(verdicts) = &table.column("verdict").unwrap().data else { panic!() };
    assert_eq!(verdicts, &["sensor_tilt", "mass_change"]);
    assert!(
        root.join("out/diagnosis/demo_02/diagnosis.json").is_file()
            && root.join("out/diagnosis/reports/demo_02.png").is_file()
    );
    assert!(root.join("out/diagnosis/accel/case=demo_02/data.parquet").is_file());
    // An edited observation reruns the diagnosis.
    let observed = root.join("cases/demo_01/observed_cpt.csv");
    let text = std::fs::read_to_string(&observed).unwrap().replacen("0.001274", "0.001275", 1);
    std::fs::write(&observed, text).unwrap();
    let status = stdout(&shakeflow(&["status", "pipeline.yaml"], root));
    assert!(status.contains("diagnosis          stale: input `cases/demo_01` changed"), "{status}");
}

#[test]
fn a_broken_case_folder_fails_with_the_file_named_and_writes_nothing() {
    let project = crate::tempdir::tempdir().unwrap();
    let root = project.path();
    let case = root.join("case");
    copy_case(&shared_dir().join("cases/demo/demo_02"), &case);
    let floor = case.join("floor.csv");
    let text = std::fs::read_to_string(&floor).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines[7] = "0.030,abc,0.0,0.0";
    std::fs::write(&floor, lines.join("\n") + "\n").unwrap();
    let run = shakeflow(&["diagnose", "case", "--out", "out"], root);
    let message = stderr(&run);
    assert!(!run.status.success());
    assert!(message.contains("floor.csv:8") && message.contains("abc"), "{message}");
    assert!(!root.join("out/diagnosis.json").exists());
    std::fs::remove_file(&floor).unwrap();
    let run = shakeflow(&["diagnose", "case", "--out", "out"], root);
    let message = stderr(&run);
    assert!(!run.status.success());
    assert!(message.contains("floor.csv") && message.contains("missing"), "{message}");
    assert!(!root.join("out").exists(), "nothing is written when a case cannot be read");
}

/// `--set` with a key `diagnose` does not declare is refused before anything runs, naming the
/// key and the close one it declares; nothing is written.
#[test]
fn an_undeclared_set_key_is_refused_by_name() {
    let project = crate::tempdir::tempdir().unwrap();
    let root = project.path();
    let case = shared_dir().join("cases/demo/demo_02").display().to_string();
    let run = shakeflow(&["diagnose", &case, "--set", "exceedance_sigmaa=1", "--out", "out"], root);
    let message = stderr(&run);
    assert_eq!(run.status.code(), Some(1), "{message}");
    assert!(message.contains("unknown parameter `exceedance_sigmaa` for stage type `diagnose`"), "{message}");
    assert!(message.contains("did you mean `exceedance_sigma`"), "{message}");
    assert!(!root.join("out").exists(), "nothing is written");
}

/// An `uncertainty` key that is not a nominal parameter of the unit is an error at its line,
/// for a rocking and a rolling unit alike; nothing is written.
#[test]
fn an_uncertainty_key_that_is_not_a_nominal_parameter_is_refused_at_its_line() {
    let project = crate::tempdir::tempdir().unwrap();
    let root = project.path();
    for (model, from, key) in
        [("rocking", "cases/demo/demo_02", "mu_k_roll"), ("rolling", "cases/rolling_demo/demo_01", "f")]
    {
        let case = root.join(model);
        copy_case(&shared_dir().join(from), &case);
        let equipment = case.join("equipment.yaml");
        let mut text = std::fs::read_to_string(&equipment).unwrap();
        let line = text.lines().count() + 3;
        text.push_str(&format!("uncertainty:\n  H_m: {{rel_sd: 0.01}}\n  {key}: {{sd: 0.03}}\n"));
        if model == "rolling" {
            text = text.replace("  H_m: {rel_sd: 0.01}\n", "  yaw0_deg: {sd: 1}\n");
        }
        std::fs::write(&equipment, text).unwrap();
        let out = format!("out_{model}");
        let run = shakeflow(&["diagnose", model, "--out", &out], root);
        let message = stderr(&run);
        assert!(!run.status.success(), "{model}: {message}");
        assert!(message.contains(&format!("equipment.yaml:{line}:3")), "{model}: {message}");
        assert!(message.contains(&format!("`{key}` is not a nominal parameter")), "{model}: {message}");
        assert!(!root.join(&out).exists(), "{model}: nothing is written");
    }
}

/// Demo cases whose stated geometry is off (../shared/cases/misstated_demo/rocking: `f`, `H_m`,
/// `B_m` stated 0.5–1.5 sd off, with their `uncertainty` block): `diagnosis.json` carries
/// `calibration` for each uncertain parameter, and the verdict is still the concealed one (demo_01
/// a tilting sensor, demo_02 a mass change, demo_03 a clock offset, `unexplained`, demo_04 an
/// obstacle). demo_04's obstacle is absorbed by a calibration over the whole record: it is named
/// because the physics is fitted on the unit the records before it support, which also puts every
/// value at least twice as close to the truth as the stated one and the onset at the first
/// contact. demo_02 is named since the physics is searched jointly with the dimensions
/// (`diagnose` v18; before, `unexplained`).
#[test]
fn misstated_rocking_cases_are_calibrated_before_a_physics_is_named() {
    let out = crate::tempdir::tempdir().unwrap();
    let base = shared_dir().join("cases/misstated_demo/rocking");
    let ids = ["demo_01", "demo_02", "demo_03", "demo_04"];
    let dirs: Vec<String> = ids.iter().map(|id| base.join(id).display().to_string()).collect();
    let mut args = vec!["diagnose"];
    args.extend(dirs.iter().map(String::as_str));
    args.extend(["--out", out.path().to_str().unwrap()]);
    let run = shakeflow(&args, out.path());
    assert!(run.status.success(), "{}", stderr(&run));
    for id in ids {
        let d: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.path().join(id).join("diagnosis.json")).unwrap())
                .unwrap();
        let truth: serde_yaml::Value =
            serde_yaml::from_str(&std::fs::read_to_string(base.join("truth").join(format!("{id}.yaml"))).unwrap())
                .unwrap();
        println!("{id}: {} ({})", d["verdict"], d["explanation"]);
        assert_eq!(d["verdict"], truth["expected_verdict"].as_str().unwrap(), "{id}: {}", d["explanation"]);
        for key in ["f", "H_m", "B_m"] {
            let c = &d["calibration"][key];
            let stated = truth["misstated"][key]["stated"].as_f64().unwrap();
            assert_eq!(c["stated"].as_f64(), Some(stated), "{id} {key}: {c}");
            assert!(c["fitted"].is_f64() && c["sd"].is_f64() && c["within"].is_boolean(), "{id} {key}: {c}");
            if id == "demo_04" {
                let true_value = truth["misstated"][key]["true"].as_f64().unwrap();
                let fitted = c["fitted"].as_f64().unwrap();
                assert!(2.0 * (fitted - true_value).abs() <= (stated - true_value).abs(), "{id} {key}: {c}");
            }
        }
        if id == "demo_04" {
            let onset = truth["onset_s"].as_f64().unwrap();
            let start = d["window"]["start_s"].as_f64().unwrap();
            assert!((start - onset).abs() < 0.1, "{id}: window from {start} s, first contact at {onset} s");
        }
    }
}
