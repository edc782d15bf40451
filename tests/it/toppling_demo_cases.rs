//! Demo cases (../shared/cases/demo): toppling found within 0.05 s of `overturn_time_s`,
//! no toppling where `overturned: false`.
use crate::toppling_common as common;

use common::*;
use shakeflow::signal::toppling::{detect_toppling, DetectOptions};

pub struct DemoCase {
    pub t: Vec<f64>,
    pub ax: Vec<f64>,
    pub az_floor: Vec<f64>,
    pub overturned: bool,
    pub overturn_time_s: Option<f64>,
}

pub fn load_demo(id: &str) -> DemoCase {
    let dir = require_shared();
    let acc = Csv::read(&dir.join(id).join("observed_accel.csv"));
    let floor = Csv::read(&dir.join(id).join("floor.csv"));
    let truth_path = dir.join("truth").join(format!("{id}.yaml"));
    let truth =
        std::fs::read_to_string(&truth_path).unwrap_or_else(|e| panic!("cannot read {}: {e}", truth_path.display()));
    let overturned = match yaml_top(&truth, "overturned").as_deref() {
        Some("true") => true,
        Some("false") => false,
        other => panic!("{id}: top-level `overturned:` missing or not a bool: {other:?}"),
    };
    let overturn_time_s = yaml_top(&truth, "overturn_time_s").and_then(|v| v.parse::<f64>().ok());
    assert!(!overturned || overturn_time_s.is_some(), "{id}: overturned but no overturn_time_s");
    let t = acc.col("time_s").to_vec();
    let ft = floor.col("time_s");
    assert_eq!(ft.len(), t.len(), "{id}: floor.csv and observed_accel.csv lengths differ");
    DemoCase {
        ax: acc.col("top_ax_mps2").to_vec(),
        az_floor: floor.col("az_mps2").to_vec(),
        t,
        overturned,
        overturn_time_s,
    }
}

pub fn demo_ids() -> Vec<String> {
    let dir = require_shared();
    let mut ids: Vec<String> = std::fs::read_dir(dir.join("truth"))
        .expect("truth dir")
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let n = e.file_name().to_string_lossy().to_string();
            n.strip_suffix(".yaml").map(str::to_string)
        })
        .filter(|id| dir.join(id).join("observed_accel.csv").is_file())
        .collect();
    ids.sort();
    ids
}

#[test]
fn demo_cases_match_truth() {
    let ids = demo_ids();
    assert!(ids.len() >= 4, "expected demo_01..demo_04, found {ids:?}");
    let opts = DetectOptions::default();
    let mut rows = Vec::new();
    let mut failures = Vec::new();
    for id in &ids {
        let c = load_demo(id);
        for (label, floor) in [("", Some(&c.az_floor[..])), (" (no floor)", None)] {
            let ev = detect_toppling(&c.t, &c.ax, floor, &opts);
            let ok = if c.overturned {
                ev.toppled && (ev.impact_time_s.unwrap() - c.overturn_time_s.unwrap()).abs() <= 0.05
            } else {
                !ev.toppled
            };
            if !ok {
                failures.push(format!("{id}{label}: truth {:?}, got {ev:?}", c.overturn_time_s));
            }
            rows.push(Row {
                case: format!("{id}{label}"),
                truth: if c.overturned { c.overturn_time_s } else { None },
                detected: ev.impact_time_s,
                confidence: ev.confidence,
                ok,
                note: ev.explanation.clone(),
            });
        }
    }
    print_table("demo cases (truth = overturn_time_s)", &rows);
    assert!(failures.is_empty(), "demo failures:\n{}", failures.join("\n"));
}
