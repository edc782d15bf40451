//! Robustness on the demo data (not made here), modified: spike without drop, truncated
//! records, NaN gaps, offset/drift, other sample rates.
use crate::toppling_common as common;

use common::*;
use shakeflow::signal::toppling::{detect_toppling, DetectOptions, TopplingEvent};

struct Case {
    t: Vec<f64>,
    ax: Vec<f64>,
    az: Vec<f64>,
    truth: f64,
}

fn load(id: &str) -> Case {
    let dir = require_shared();
    let acc = Csv::read(&dir.join(id).join("observed_accel.csv"));
    let floor = Csv::read(&dir.join(id).join("floor.csv"));
    let truth_text = std::fs::read_to_string(dir.join("truth").join(format!("{id}.yaml"))).expect("truth yaml");
    assert_eq!(yaml_top(&truth_text, "overturned").as_deref(), Some("true"), "{id} expected to overturn");
    let truth = yaml_top(&truth_text, "overturn_time_s").and_then(|v| v.parse().ok()).expect("overturn_time_s");
    Case {
        t: acc.col("time_s").to_vec(),
        ax: acc.col("top_ax_mps2").to_vec(),
        az: floor.col("az_mps2").to_vec(),
        truth,
    }
}

fn row(case: &str, truth: Option<f64>, ev: &TopplingEvent, ok: bool) -> Row {
    Row {
        case: case.into(),
        truth,
        detected: ev.impact_time_s,
        confidence: ev.confidence,
        ok,
        note: ev.explanation.clone(),
    }
}

fn found_at(ev: &TopplingEvent, truth: f64) -> bool {
    ev.toppled && ev.impact_time_s.is_some_and(|t| (t - truth).abs() <= 0.05)
}

#[test]
fn robustness_on_modified_demo_data() {
    let opts = DetectOptions::default();
    let mut rows = Vec::new();
    let mut fails = Vec::new();
    let mut check = |name: &str, truth: Option<f64>, ev: TopplingEvent, ok: bool| {
        if !ok {
            fails.push(format!("{name}: {ev:?}"));
        }
        rows.push(row(name, truth, &ev, ok));
    };

    // 1. Spike without drop: demo_02 up to 0.15 s after the impact (spike and ringing), then the
    //    3 s of shaking before the impact replayed in a loop: the amplitude does not drop.
    for id in ["demo_02", "demo_03", "demo_04"] {
        let c = load(id);
        let i_cut = c.t.partition_point(|&v| v < c.truth + 0.15);
        let i_seg0 = c.t.partition_point(|&v| v < c.truth - 3.05);
        let i_seg1 = c.t.partition_point(|&v| v < c.truth - 0.05);
        let seg = &c.ax[i_seg0..i_seg1];
        let mut x = c.ax.clone();
        for (k, v) in x.iter_mut().enumerate().skip(i_cut) {
            *v = seg[(k - i_cut) % seg.len()];
        }
        let ev = detect_toppling(&c.t, &x, None, &opts);
        let ok = !ev.toppled && ev.confidence >= 0.5;
        check(&format!("{id} spike, no drop"), None, ev, ok);
    }

    // 2. Record ending 0.3 s after the spike: cannot be confirmed -> not toppled, confidence 0.5.
    //    Ending 1.6 s after it (1.2 s of low amplitude after the 0.4 s skip): confirmed.
    for id in ["demo_01", "demo_02", "demo_03", "demo_04"] {
        let c = load(id);
        let n03 = c.t.partition_point(|&v| v <= c.truth + 0.3);
        let ev = detect_toppling(&c.t[..n03], &c.ax[..n03], Some(&c.az[..n03]), &opts);
        let ok = !ev.toppled && (ev.confidence - 0.5).abs() < 1e-9 && ev.explanation.contains("cannot be confirmed");
        check(&format!("{id} ends +0.3 s"), None, ev, ok);
        let n16 = c.t.partition_point(|&v| v <= c.truth + 1.6);
        let ev = detect_toppling(&c.t[..n16], &c.ax[..n16], Some(&c.az[..n16]), &opts);
        let ok = found_at(&ev, c.truth);
        check(&format!("{id} ends +1.6 s"), Some(c.truth), ev, ok);
    }

    // 3. NaN gaps: a 1 s gap in the pre-impact window, a 0.5 s gap in the post window, every
    //    37th sample missing, a NaN time stamp.
    for id in ["demo_01", "demo_02", "demo_03", "demo_04"] {
        let c = load(id);
        let mut x = c.ax.clone();
        let mut t = c.t.clone();
        for (k, xk) in x.iter_mut().enumerate() {
            let tk = c.t[k];
            if (c.truth - 1.8..c.truth - 0.8).contains(&tk)
                || (c.truth + 1.0..c.truth + 1.5).contains(&tk)
                || k % 37 == 5
            {
                *xk = f64::NAN;
            }
        }
        t[100] = f64::NAN;
        let ev = detect_toppling(&t, &x, Some(&c.az), &opts);
        let ok = found_at(&ev, c.truth);
        check(&format!("{id} NaN gaps"), Some(c.truth), ev, ok);
    }

    // 4. DC offset (+0.5 g) and drift (linear 2 m/s² + quadratic 1 m/s² over the record).
    for id in ["demo_01", "demo_02", "demo_03", "demo_04"] {
        let c = load(id);
        let dur = c.t[c.t.len() - 1];
        let x: Vec<f64> =
            c.t.iter().zip(&c.ax).map(|(&t, &v)| v + 0.5 * G + 2.0 * t / dur + 1.0 * (t / dur).powi(2)).collect();
        let ev = detect_toppling(&c.t, &x, Some(&c.az), &opts);
        let ok = found_at(&ev, c.truth);
        check(&format!("{id} offset+drift"), Some(c.truth), ev, ok);
    }

    // 5. Sample rates: 1000 Hz (linear interpolation of the 200 Hz record) and 100 Hz (every
    //    second sample, both phases: one of them loses the spike's first sample).
    for id in ["demo_01", "demo_02", "demo_03", "demo_04"] {
        let c = load(id);
        let (t0, t1) = (c.t[0], c.t[c.t.len() - 1]);
        let n = ((t1 - t0) * 1000.0) as usize;
        let t: Vec<f64> = (0..=n).map(|k| t0 + k as f64 / 1000.0).collect();
        let lin = |y: &[f64], at: f64| {
            let i = c.t.partition_point(|&v| v < at).clamp(1, c.t.len() - 1);
            y[i - 1] + (y[i] - y[i - 1]) * (at - c.t[i - 1]) / (c.t[i] - c.t[i - 1])
        };
        let x: Vec<f64> = t.iter().map(|&v| lin(&c.ax, v)).collect();
        let z: Vec<f64> = t.iter().map(|&v| lin(&c.az, v)).collect();
        let ev = detect_toppling(&t, &x, Some(&z), &opts);
        let ok = found_at(&ev, c.truth);
        check(&format!("{id} 1000 Hz"), Some(c.truth), ev, ok);
        for phase in 0..2 {
            let pick = |y: &[f64]| y.iter().skip(phase).step_by(2).copied().collect::<Vec<f64>>();
            let ev = detect_toppling(&pick(&c.t), &pick(&c.ax), Some(&pick(&c.az)), &opts);
            let ok = found_at(&ev, c.truth);
            check(&format!("{id} 100 Hz phase {phase}"), Some(c.truth), ev, ok);
        }
    }

    print_table("robustness (modified demo data)", &rows);
    assert!(fails.is_empty(), "robustness failures:\n{}", fails.join("\n"));
}
