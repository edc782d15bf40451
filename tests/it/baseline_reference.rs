//! The baseline stage against numpy.polyfit on the real RENADIC record (uncorrected, 124.6 s).
//! Reference values: tests/reference/baseline_llolleo.json, made by baseline_numpy.py beside it.

use crate::common;

use serde_json::Value;
use shakeflow::pipeline::spec::SourceSpec;
use shakeflow::stages::{baseline, load, InputPart};

#[test]
fn cubic_baseline_matches_numpy_polyfit_on_llolleo() {
    let reference: Value =
        serde_json::from_str(&std::fs::read_to_string(common::reference_script("baseline_llolleo.json")).unwrap())
            .unwrap();
    let path = common::ground_motion("llolleo1002271.v1");
    let spec: SourceSpec =
        serde_json::from_value(serde_json::json!({"format": "renadic_v1", "path": "llolleo1002271.v1"})).unwrap();
    let part =
        InputPart { partition: vec![], path: path.clone(), label: "llolleo1002271.v1".into(), hash: String::new() };
    let loaded = load::load_record(&spec, &part).unwrap();
    let corrected = baseline::correct(&loaded, 3, &[]).unwrap();
    let fits: Value = serde_json::from_str(&corrected.metadata["shakeflow.baseline"]).unwrap();

    for (channel, want) in reference["channels"].as_object().unwrap() {
        let got = corrected.f64_column(channel).unwrap_or_else(|| panic!("channel {channel}"));
        assert_eq!(got.len() as u64, want["npts"].as_u64().unwrap());
        let scale = want["max_abs"].as_f64().unwrap();
        for (index, value) in want["samples"].as_object().unwrap() {
            let i: usize = index.parse().unwrap();
            // Tolerance: 1e-12 of the record's peak, i.e. round-off of two independent least-squares solvers.
            assert!((got[i] - value.as_f64().unwrap()).abs() <= 1e-12 * scale, "{channel}[{i}]: {} vs {value}", got[i]);
        }
        let rms = (got.iter().map(|v| v * v).sum::<f64>() / got.len() as f64).sqrt();
        assert!((rms - want["rms"].as_f64().unwrap()).abs() <= 1e-12 * scale, "{channel} rms");
        let coefficients = fits["fits"][channel]["polyfit_coefficients"].as_array().unwrap();
        for (g, w) in coefficients.iter().zip(want["polyfit_coefficients"].as_array().unwrap()) {
            let (g, w) = (g.as_f64().unwrap(), w.as_f64().unwrap());
            // numpy's Vandermonde lstsq loses ~cond digits on raw seconds; 1e-8 relative still separates a wrong fit.
            assert!((g - w).abs() <= 1e-8 * w.abs(), "{channel} coefficient {g} vs numpy {w}");
        }
    }
}

#[test]
fn reference_values_are_reproducible_by_their_script() {
    // The committed JSON must be what the script produces now (numpy in the test venv).
    let script = common::reference_script("baseline_numpy.py");
    let committed = std::fs::read_to_string(common::reference_script("baseline_llolleo.json")).unwrap();
    let printed = common::run_python(&script, &[]);
    let fresh: Value = serde_json::from_str(&printed).unwrap();
    let old: Value = serde_json::from_str(&committed).unwrap();
    for (channel, want) in old["channels"].as_object().unwrap() {
        for (i, v) in want["samples"].as_object().unwrap() {
            let now = fresh["channels"][channel]["samples"][i].as_f64().unwrap();
            assert!((now - v.as_f64().unwrap()).abs() < 1e-12, "{channel}[{i}] moved: {now} vs {v}");
        }
    }
}
