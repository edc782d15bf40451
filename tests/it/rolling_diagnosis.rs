//! `shakeflow diagnose` on the rolling demo cases of ../shared/cases/rolling_demo, concealed by
//! another team's generator (truth/<case>.yaml, never read by the tool): the verdict is the
//! expected one, a mismatch window starts within 0.5 s of the true onset, and where a physics is
//! named the fit improves at least threefold.
use crate::common;
use common::*;

fn truth(id: &str) -> serde_yaml::Value {
    let path = shared_dir().join("cases/rolling_demo/truth").join(format!("{id}.yaml"));
    serde_yaml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

#[test]
fn rolling_demo_cases_get_their_concealed_verdicts() {
    let out = crate::tempdir::tempdir().unwrap();
    let ids = ["demo_01", "demo_02", "demo_03", "demo_04"];
    let dirs: Vec<String> =
        ids.iter().map(|id| shared_dir().join("cases/rolling_demo").join(id).display().to_string()).collect();
    let mut args = vec!["diagnose"];
    args.extend(dirs.iter().map(String::as_str));
    args.extend(["--out", out.path().to_str().unwrap()]);
    let run = shakeflow(&args, out.path());
    assert!(run.status.success(), "{}", stderr(&run));
    let mut failures = Vec::new();
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
        // Every candidate carries the uncertain parameters as fitted with it: none without an
        // `uncertainty` block, the stated values taken as exact.
        for c in d["candidates"].as_array().unwrap() {
            assert_eq!(c["calibration"], serde_json::json!({}), "{id}: {}", c["effect"]);
        }
        let truth = truth(id);
        let expected = truth["expected_verdict"].as_str().unwrap();
        let (before, after) = (d["rmse_before"].as_f64().unwrap(), d["rmse_after"].as_f64().unwrap());
        println!("{id}: {} (truth {expected}), window {}, rmse {before:.1} → {after:.2}", d["verdict"], d["window"]);
        if d["verdict"] != expected {
            failures.push(format!("{id}: {} instead of {expected}: {}", d["verdict"], d["explanation"]));
            continue;
        }
        if expected == "none" {
            assert_eq!(d["mismatch"], false);
            assert!(d["window"].is_null());
            continue;
        }
        let onset = truth["onset_s"].as_f64().unwrap();
        let start = d["window"]["start_s"].as_f64().expect("a mismatch window");
        if expected != "unexplained" {
            assert!((start - onset).abs() < 0.5, "{id}: window starts at {start}, onset {onset}");
            assert!(after <= before / 3.0, "{id}: rmse {before} → {after}");
            // The 3× test can be recomputed from the file: the judged span, and each candidate's
            // misfit there; beyond the noise, √(RMS² − 1), the named physics cuts it 3× or more.
            let judged = &d["judged"];
            let (from, to) = (judged["start_s"].as_f64().unwrap(), judged["end_s"].as_f64().unwrap());
            assert!(from < to && to <= d["window"]["end_s"].as_f64().unwrap() + 1e-9, "{id}: judged {judged}");
            let judged_rmse = |effect: &str| {
                let c = d["candidates"].as_array().unwrap().iter().find(|c| c["effect"] == effect).unwrap();
                c["rmse_judged"].as_f64().unwrap_or_else(|| panic!("{id}: {effect} has no rmse_judged"))
            };
            let excess = |rmse: f64| (rmse * rmse - 1.0).max(0.0).sqrt();
            let cut = excess(judged_rmse("none")) / excess(judged_rmse(expected)).max(1e-12);
            assert!(cut >= 3.0, "{id}: the judged misfit beyond the noise falls only {cut:.2}×");
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn a_rolling_equipment_file_with_a_misspelt_key_is_refused_with_its_line() {
    let dir = crate::tempdir::tempdir().unwrap();
    let case = dir.path().join("case");
    std::fs::create_dir_all(&case).unwrap();
    let from = shared_dir().join("cases/rolling_demo/demo_01");
    for file in ["floor.csv", "observed_accel.csv", "observed_cpt.csv"] {
        std::fs::copy(from.join(file), case.join(file)).unwrap();
    }
    let text = std::fs::read_to_string(from.join("equipment.yaml")).unwrap().replace("mu_s_roll:", "mu_s_rol:");
    std::fs::write(case.join("equipment.yaml"), &text).unwrap();
    let line = text.lines().position(|l| l.starts_with("mu_s_rol:")).unwrap() + 1;
    let run =
        shakeflow(&["diagnose", case.to_str().unwrap(), "--out", dir.path().join("out").to_str().unwrap()], dir.path());
    assert!(!run.status.success());
    let err = stderr(&run);
    assert!(err.contains("mu_s_rol") && err.contains(&format!(":{line}")), "{err}");
}
