//! Synthetic demo archive (shakeflow demo-archive): every (test, unit) channel of each test's
//! DAQ2 file (raw volts, through the archive's sensitivity table); toppled exactly where manifest.json says (within 0.05 s after converting
//! DAQ1 -> DAQ2 time), no toppling anywhere else.
use crate::toppling_common as common;

use common::*;
use shakeflow::signal::toppling::{detect_toppling, DetectOptions};
use std::path::{Path, PathBuf};

/// The demo archive, written by the library into the test scratch folder when not current.
fn archive_dir() -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("toppling-demo-archive");
    if !shakeflow::demo::archive::is_current(&dir) {
        shakeflow::demo::archive::write_demo_archive(&dir).expect("the demo archive is written");
    }
    dir
}

/// Linear interpolation of (t, y) at time `at` (NaN outside).
fn interp(t: &[f64], y: &[f64], at: f64) -> f64 {
    let i = t.partition_point(|&v| v < at);
    if i == 0 || i >= t.len() {
        return if i < t.len() && t[i] == at { y[i] } else { f64::NAN };
    }
    let (t0, t1) = (t[i - 1], t[i]);
    y[i - 1] + (y[i] - y[i - 1]) * (at - t0) / (t1 - t0)
}

#[test]
fn demo_archive_toppling_and_no_false_alarms() {
    let dir = archive_dir();
    let manifest = Json::parse(&std::fs::read_to_string(dir.join("manifest.json")).expect("manifest"));
    let tests = manifest.get("tests").arr();
    assert!(!tests.is_empty(), "manifest has no tests");
    // Default options, then a more sensitive trigger (sqrt(STA/LTA) ≥ 5) so that the shaking-onset
    // triggers of FB-1..FB-6 reach the confirmation stage: the drop test alone must reject them.
    let sensitive = DetectOptions { sta_lta_on: 5.0, ..DetectOptions::default() };
    let mut rows = Vec::new();
    let mut failures = Vec::new();
    let (mut n_channels, mut n_topples) = (0, 0);
    for test in tests {
        let id = test.get("id").str();
        let offset = test.get("clock_offset_s").num();
        let daq2 = crate::common::DemoDaq::read(&dir, test.get("daq2_file").str());
        let daq1 = crate::common::DemoDaq::read(&dir, test.get("daq1_file").str());
        let t2 = &daq2.column("Time")[..];
        let t1 = &daq1.column("Time")[..];
        let topples: Vec<(String, f64)> = test
            .get("toppling")
            .arr()
            .iter()
            .map(|e| (e.get("unit").str().to_string(), e.get("time_s").num() - offset))
            .collect();
        for eq in test.get("equipment").arr() {
            let unit = eq.get("unit").str();
            let channel = eq.get("channel").str();
            let floor = eq.get("floor").num() as i64;
            let ax: Vec<f64> = daq2.g(channel, &dir).iter().map(|v| v * G).collect();
            // Floor vertical of the unit's floor, on the DAQ2 clock (DAQ1 time = tau + offset).
            let ud = daq1.g(&format!("A{floor}_UD"), &dir);
            let fv: Vec<f64> = t2.iter().map(|&tau| interp(t1, &ud, tau + offset) * G).collect();
            let truth = topples.iter().find(|(u, _)| u == unit).map(|(_, t)| *t);
            let default = DetectOptions::default();
            for (label, floor_v, opts) in
                [("", Some(&fv[..]), &default), (" nofl", None, &default), (" sta5", None, &sensitive)]
            {
                let ev = detect_toppling(t2, &ax, floor_v, opts);
                let ok = match truth {
                    Some(tt) => ev.toppled && (ev.impact_time_s.unwrap() - tt).abs() <= 0.05,
                    None => !ev.toppled,
                };
                if !ok {
                    failures.push(format!("{id} {unit}{label}: truth {truth:?}, got {ev:?}"));
                }
                // Print every toppled/failed channel, and a compact line for the rest.
                rows.push(Row {
                    case: format!("{id} {unit}{label}"),
                    truth,
                    detected: ev.impact_time_s,
                    confidence: ev.confidence,
                    ok,
                    note: if truth.is_some() || !ok || ev.toppled {
                        ev.explanation.clone()
                    } else {
                        ev.explanation.chars().take(400).collect()
                    },
                });
            }
            n_channels += 1;
            n_topples += usize::from(truth.is_some());
        }
    }
    print_table(
        &format!("demo archive {} ({n_channels} channels, {n_topples} topplings; truth in DAQ2 time)", dir.display()),
        &rows,
    );
    assert_eq!(n_channels, tests.len() * 7, "expected 7 units per test");
    // An archive without topplings would pass as "no false alarms" and check no detection.
    assert!(n_topples >= 3, "the demo archive has three topplings, found {n_topples} in its manifest");
    assert!(failures.is_empty(), "{} archive failures:\n{}", failures.len(), failures.join("\n"));
}
