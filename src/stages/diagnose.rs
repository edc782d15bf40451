//! `diagnose` (stage and `shakeflow diagnose` command): for each case folder, where the nominal
//! toppling model and the recordings disagree, which physics explains it, and the fit before
//! and after. Writes the contract `diagnosis.json` (at the stage folder's root for one case,
//! `<case>/diagnosis.json` for each of several), the observed/baseline/model series and
//! residuals (Parquet, + MCAP with `mcap: true`) and a figure with the located window shaded.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use super::{InputKind, OutputInfo, OutputKind, Stage, StageContext, StageInfo};
use crate::diagnose::calibration::Calibration;
use crate::diagnose::rolling::RollingDiagnosis;
use crate::diagnose::{diagnose, Diagnosis, Settings};
use crate::io::case::read_case_unchanged;
use crate::pipeline::params::{self, ParamError, ParamKind, ParamSpec, Params};
use crate::pipeline::spec::RecordFormat;
use crate::table::{Column, Table, TIME_COLUMN};

pub struct Diagnose;

static INFO: StageInfo = StageInfo {
    name: "diagnose",
    version: 12,
    summary: "Where the toppling model (or, for `model: rolling` cases, the 4WMC cart) and a unit's records disagree, which physics it left out (rocking: sliding, mass_change, restitution, flexibility, obstacle_impact, sensor_tilt; rolling: lateral_impact, mass_change, caster_brake, swivel_jam), fitted jointly with the nominal parameters the equipment file's `uncertainty` block says are known only roughly (calibrated first), ranked by BIC; `ambiguous` when two explain the records about equally well, or `unexplained`.",
    inputs: InputKind::Files(&[RecordFormat::Case]),
    outputs: &[
        OutputInfo { name: "diagnosis", description: "per case: mismatch, verdict, window_start_s, window_end_s, rmse_before, rmse_after, explanation, candidates (JSON), calibration (JSON)", kind: OutputKind::Table },
        OutputInfo { name: "accel", description: "per case: observed, baseline and model top acceleration and the residuals before/after", kind: OutputKind::TimeSeries },
        OutputInfo { name: "camera", description: "per case: observed, baseline and model rotation and the residuals before/after", kind: OutputKind::TimeSeries },
        OutputInfo { name: "reports", description: "<case>.png: records, models, residuals, window shaded", kind: OutputKind::Files },
        OutputInfo { name: "diagnosis.json", description: "the contract (verdict, window, rmse before/after, candidates, explanation, calibration): at the stage folder's root for one case, in `<case>/` for each of several", kind: OutputKind::Page },
    ],
    params: &[
        ParamSpec { name: "exceedance_sigma", kind: ParamKind::Float, default: Some("4.0"), unit: "", description: "a residual beyond this many noise standard deviations counts as a disagreement (5 within 0.1 s flag a mismatch)", range: Some((2.0, 20.0)) },
        ParamSpec { name: "min_improvement", kind: ParamKind::Float, default: Some("3.0"), unit: "", description: "a physics is accepted only if it cuts the window's noise-normalised RMS misfit at least this many times", range: Some((1.0, 1e3)) },
        ParamSpec { name: "max_remaining_flagged", kind: ParamKind::Float, default: Some("0.12"), unit: "", description: "... and leaves at most this fraction of the flagged samples flagged (rocking cases; a rolling cart may leave 0.7 of those in the window's first 5 s)", range: Some((0.0, 1.0)) },
        super::MCAP_PARAM,
    ],
};

/// The contract file held-out scorers read (`shakeflow diagnose CASE --out OUT` → `OUT/diagnosis.json`).
pub const CONTRACT: &str = "diagnosis.json";

/// The parameters `INFO` declares, typed (also `shakeflow diagnose --set`'s).
#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DiagnoseParams {
    pub exceedance_sigma: f64,
    pub min_improvement: f64,
    pub max_remaining_flagged: f64,
    /// Read by the engine's sink.
    pub mcap: bool,
}

/// The diagnosis settings the normalised parameters give.
pub fn settings(params: &Params) -> Result<Settings, ParamError> {
    let p: DiagnoseParams = params::typed(params)?;
    Ok(Settings {
        exceedance_sigma: p.exceedance_sigma,
        min_improvement: p.min_improvement,
        max_remaining_flagged: p.max_remaining_flagged,
    })
}

impl Stage for Diagnose {
    fn info(&self) -> &'static StageInfo {
        &INFO
    }

    fn check_params(&self, params: &Params) -> Result<(), ParamError> {
        params::check_typed::<DiagnoseParams>(params)
    }

    fn summary(&self, stage_dir: &std::path::Path) -> Option<String> {
        crate::summary::verdicts(stage_dir).ok()
    }

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let settings = settings(ctx.params)?;
        let parts: Vec<_> = ctx.inputs.iter().flat_map(|i| i.parts()).collect();
        ctx.sink.set_total(parts.len());
        let mut rows: Vec<(String, AnyDiagnosis)> = parts
            .par_iter()
            .map(|part| {
                let d = diagnose_folder(&part.path, &part.hash, &settings)
                    .map_err(|e| anyhow::anyhow!("{}: {e:#}", part.label))?;
                let mut accel = d.accel_table();
                let mut camera = d.camera_table();
                for t in [&mut accel, &mut camera] {
                    t.metadata.extend(super::record_provenance(part));
                }
                ctx.sink.write("accel", &part.partition, accel)?;
                ctx.sink.write("camera", &part.partition, camera)?;
                // Named by the case's partition values, as the `case` column names it.
                let name = match super::partition_values(&part.partition).replace('/', "_") {
                    n if n.is_empty() => d.case().to_string(),
                    n => n,
                };
                // The contract: `diagnosis.json` of the one case, or `<case>/diagnosis.json` of each.
                match parts.len() {
                    1 => ctx.sink.write_page(CONTRACT, d.json_bytes().as_bytes())?,
                    _ => ctx.sink.write_record_page(CONTRACT, &name, d.json_bytes().as_bytes())?,
                }
                ctx.sink.write_file("reports", &format!("{name}.png"), &d.figure().map_err(anyhow::Error::msg)?)?;
                Ok((super::partition_values(&part.partition), d))
            })
            .collect::<anyhow::Result<_>>()?;
        rows.sort_by(|a, b| a.0.cmp(&b.0));
        ctx.sink.write("diagnosis", &Vec::new(), summary_table(&rows))
    }
}

/// The `diagnosis.json` contract, with a few fields added for readers.
pub fn diagnosis_json(d: &Diagnosis) -> Value {
    let candidates: Vec<Value> = d
        .candidates
        .iter()
        .map(|c| {
            let params: serde_json::Map<String, Value> =
                c.params.iter().map(|(k, v)| (k.to_string(), json!(v))).collect();
            json!({
                "effect": c.effect,
                "params": params,
                "rmse": c.rmse,
                "score": c.score,
                "bic": c.bic,
                "chi2": c.misfit.chi2,
                "flagged_samples": c.flagged,
                "evaluations": c.evaluations,
                "overturn_time_s": c.prediction.overturn.map(|o| o.0),
                "overturn_side": c.prediction.overturn.map(|o| o.1),
                "explanation": c.sentence,
                "calibration": calibration_json(&c.calibration),
            })
        })
        .collect();
    json!({
        "case": d.case,
        "mismatch": d.mismatch,
        "verdict": d.verdict,
        "window": d.window.map(|(a, b)| json!({"start_s": a, "end_s": b})),
        "rmse_before": d.rmse_before,
        "rmse_after": d.rmse_after,
        "rmse_definition": "sqrt(mean(((observed - predicted) / noise_sd)^2)) over the accelerometer and camera samples inside the window (the whole record when there is none), overturn impact spike and solver-sensitive samples excluded; 1 is pure sensor noise",
        "noise": {"accel_mps2": d.accel_noise_mps2, "camera_rad": d.camera_noise_rad},
        "candidates": candidates,
        "explanation": d.explanation,
        "calibration": calibration_json(&d.calibration),
        "shakeflow_version": env!("CARGO_PKG_VERSION"),
    })
}

/// The contract's `calibration`: for each parameter the equipment file's `uncertainty` block
/// names, `{stated, fitted, sd, within}` (lists element-wise; `within`: fitted within 3 sd of
/// stated); `{}` without the block.
pub fn calibration_json(c: &Calibration) -> Value {
    let entries: serde_json::Map<String, Value> = c
        .entries()
        .into_iter()
        .map(|(key, entry)| (key, serde_json::to_value(entry).expect("numbers and booleans are JSON")))
        .collect();
    Value::Object(entries)
}

pub fn json_bytes(d: &Diagnosis) -> String {
    serde_json::to_string_pretty(&diagnosis_json(d)).expect("the diagnosis is JSON") + "\n"
}

fn series_table(rows: &[(f64, f64, f64, f64)], model: &[(f64, f64, f64, f64)], quantity: &str, unit: &str) -> Table {
    let column =
        |name: String, description: String, f: &dyn Fn(&(f64, f64, f64, f64)) -> f64, from: &[(f64, f64, f64, f64)]| {
            Column::f64(&name, unit, &description, from.iter().map(f).collect())
        };
    let mut t = Table::new();
    t.push(Column::f64(TIME_COLUMN, "s", "time", rows.iter().map(|r| r.0).collect()));
    t.push(column(format!("observed_{quantity}"), format!("recorded {quantity}"), &|r| r.1, rows));
    t.push(column(
        format!("baseline_{quantity}"),
        format!("{quantity} of the nominal rigid-block model"),
        &|r| r.2,
        rows,
    ));
    t.push(column(
        format!("model_{quantity}"),
        format!("{quantity} of the accepted model (the baseline when none is accepted)"),
        &|r| r.2,
        model,
    ));
    t.push(column(
        format!("residual_before_{quantity}"),
        "observed − baseline (NaN where not compared)".into(),
        &|r| r.3,
        rows,
    ));
    t.push(column(
        format!("residual_after_{quantity}"),
        "observed − accepted model (NaN where not compared)".into(),
        &|r| r.3,
        model,
    ));
    t
}

pub fn accel_table(d: &Diagnosis) -> Table {
    series_table(&d.evidence.accel_series(&d.baseline), &d.evidence.accel_series(&d.model), "top_ax_mps2", "m/s^2")
}

pub fn camera_table(d: &Diagnosis) -> Table {
    series_table(&d.evidence.camera_series(&d.baseline), &d.evidence.camera_series(&d.model), "theta_rad", "rad")
}

fn summary_table(rows: &[(String, AnyDiagnosis)]) -> Table {
    let text = |name: &str, description: &str, v: Vec<String>| Column {
        name: name.into(),
        unit: String::new(),
        description: description.into(),
        data: crate::table::ColumnData::Str(v),
    };
    let optional = |name: &str, description: &str, v: Vec<Option<f64>>| Column {
        name: name.into(),
        unit: "s".into(),
        description: description.into(),
        data: crate::table::ColumnData::OptF64(v),
    };
    let mut t = Table::new();
    t.push(text(
        "case",
        "the case: its partition values (`demo_01` for case=demo_01)",
        rows.iter().map(|r| r.0.clone()).collect(),
    ));
    t.push(Column {
        name: "mismatch".into(),
        unit: String::new(),
        description: "the nominal model disagrees with the records beyond their noise".into(),
        data: crate::table::ColumnData::Bool(rows.iter().map(|r| r.1.mismatch()).collect()),
    });
    t.push(text(
        "verdict",
        "none | unexplained | ambiguous; rocking: sliding | mass_change | restitution | flexibility | obstacle_impact | sensor_tilt; rolling: lateral_impact | mass_change | caster_brake | swivel_jam",
        rows.iter().map(|r| r.1.verdict().to_string()).collect(),
    ));
    t.push(optional(
        "window_start_s",
        "first disagreement (null without one)",
        rows.iter().map(|r| r.1.window().map(|w| w.0)).collect(),
    ));
    t.push(optional("window_end_s", "last disagreement", rows.iter().map(|r| r.1.window().map(|w| w.1)).collect()));
    t.push(Column::f64(
        "rmse_before",
        "",
        "noise-normalised RMS misfit of the nominal model in the window",
        rows.iter().map(|r| r.1.rmse().0).collect(),
    ));
    t.push(Column::f64(
        "rmse_after",
        "",
        "the same for the accepted model",
        rows.iter().map(|r| r.1.rmse().1).collect(),
    ));
    t.push(text("explanation", "for a test engineer", rows.iter().map(|r| r.1.explanation().to_string()).collect()));
    t.push(text(
        "candidates",
        "every fitted hypothesis (JSON)",
        rows.iter().map(|r| r.1.json()["candidates"].to_string()).collect(),
    ));
    t.push(text(
        "calibration",
        "per uncertain nominal parameter: stated, fitted, sd, within 3 sd (JSON; {} when the equipment file has no uncertainty block)",
        rows.iter().map(|r| r.1.json()["calibration"].to_string()).collect(),
    ));
    t
}

/// Records, nominal model and accepted model, the residuals, with the window shaded.
pub fn figure(d: &Diagnosis) -> Result<Vec<u8>, String> {
    use crate::plot::{render_png, Panel, Series};
    let accel = d.evidence.accel_series(&d.baseline);
    let accel_model = d.evidence.accel_series(&d.model);
    let camera = d.evidence.camera_series(&d.baseline);
    let camera_model = d.evidence.camera_series(&d.model);
    let col =
        |rows: &[(f64, f64, f64, f64)], f: fn(&(f64, f64, f64, f64)) -> f64| rows.iter().map(f).collect::<Vec<f64>>();
    let (ta, oa, ba, ma) =
        (col(&accel, |r| r.0), col(&accel, |r| r.1), col(&accel, |r| r.2), col(&accel_model, |r| r.2));
    let (tc, oc, bc, mc) =
        (col(&camera, |r| r.0), col(&camera, |r| r.1), col(&camera, |r| r.2), col(&camera_model, |r| r.2));
    let za: Vec<f64> = accel.iter().map(|r| r.3 / d.accel_noise_mps2).collect();
    let zm: Vec<f64> = accel_model.iter().map(|r| r.3 / d.accel_noise_mps2).collect();
    let spans: Vec<(f64, f64)> = d.window.into_iter().collect();
    let model_label = format!("model: {}", d.verdict);
    let panels = [
        Panel {
            title: "top accelerometer".into(),
            x_label: "time [s]".into(),
            y_label: "m/s^2".into(),
            series: vec![
                Series::new("observed", &ta, &oa).observed(),
                Series::new("nominal model", &ta, &ba).model(),
                Series::new(model_label.clone(), &ta, &ma).model(),
            ],
            spans: spans.clone(),
            ..Panel::default()
        },
        Panel {
            title: "camera rotation".into(),
            x_label: "time [s]".into(),
            y_label: "theta [rad]".into(),
            series: vec![
                Series::new("observed", &tc, &oc).observed(),
                Series::new("nominal model", &tc, &bc).model(),
                Series::new(model_label, &tc, &mc).model(),
            ],
            spans: spans.clone(),
            ..Panel::default()
        },
        Panel {
            title: format!(
                "accelerometer residual / noise: RMS in the window {:.1} → {:.1}",
                d.rmse_before, d.rmse_after
            ),
            x_label: "time [s]".into(),
            y_label: "residual / sigma".into(),
            series: vec![Series::new("nominal model", &ta, &za), Series::new("accepted model", &ta, &zm)],
            spans,
            ..Panel::default()
        },
    ];
    let title = match d.window {
        Some((a, b)) => format!("case {}: {} (records and model disagree {a:.2}-{b:.2} s, shaded)", d.case, d.verdict),
        None => format!("case {}: the model agrees with the records", d.case),
    };
    render_png(&title, &panels, 1400, 1100)
}

/// A diagnosis of either kind of unit: the rocking block or the rolling cart (`model: rolling`).
pub enum AnyDiagnosis {
    Rocking(Diagnosis),
    Rolling(RollingDiagnosis),
}

/// Reads and diagnoses the case folder `dir`, rocking or rolling as its equipment file says;
/// `expected_hash` as for [`read_case_unchanged`].
pub fn diagnose_folder(
    dir: &std::path::Path,
    expected_hash: &str,
    settings: &Settings,
) -> anyhow::Result<AnyDiagnosis> {
    if crate::io::case::case_model(dir)?.as_deref() == Some("rolling") {
        let case = crate::io::case::read_rolling_case(dir)?;
        if !expected_hash.is_empty() && crate::io::hash::hash_dir(dir)?.0 != expected_hash {
            anyhow::bail!("`{}` changed while this run was reading it", dir.display());
        }
        let d = crate::diagnose::rolling::diagnose(&case, settings)
            .map_err(|e| anyhow::anyhow!("{}: {e}", dir.display()))?;
        return Ok(AnyDiagnosis::Rolling(d));
    }
    let case = read_case_unchanged(dir, expected_hash)?;
    Ok(AnyDiagnosis::Rocking(diagnose(&case, settings).map_err(|e| anyhow::anyhow!("{}: {e}", dir.display()))?))
}

impl AnyDiagnosis {
    pub fn case(&self) -> &str {
        match self {
            AnyDiagnosis::Rocking(d) => &d.case,
            AnyDiagnosis::Rolling(d) => &d.case,
        }
    }

    pub fn verdict(&self) -> &'static str {
        match self {
            AnyDiagnosis::Rocking(d) => d.verdict,
            AnyDiagnosis::Rolling(d) => d.verdict,
        }
    }

    pub fn window(&self) -> Option<(f64, f64)> {
        match self {
            AnyDiagnosis::Rocking(d) => d.window,
            AnyDiagnosis::Rolling(d) => d.window,
        }
    }

    pub fn rmse(&self) -> (f64, f64) {
        match self {
            AnyDiagnosis::Rocking(d) => (d.rmse_before, d.rmse_after),
            AnyDiagnosis::Rolling(d) => (d.rmse_before, d.rmse_after),
        }
    }

    pub fn json_bytes(&self) -> String {
        match self {
            AnyDiagnosis::Rocking(d) => json_bytes(d),
            AnyDiagnosis::Rolling(d) => {
                serde_json::to_string_pretty(&rolling_json(d)).expect("the diagnosis is JSON") + "\n"
            }
        }
    }

    pub fn accel_table(&self) -> Table {
        match self {
            AnyDiagnosis::Rocking(d) => accel_table(d),
            AnyDiagnosis::Rolling(d) => rolling_accel_table(d),
        }
    }

    pub fn camera_table(&self) -> Table {
        match self {
            AnyDiagnosis::Rocking(d) => camera_table(d),
            AnyDiagnosis::Rolling(d) => rolling_camera_table(d),
        }
    }

    pub fn figure(&self) -> Result<Vec<u8>, String> {
        match self {
            AnyDiagnosis::Rocking(d) => figure(d),
            AnyDiagnosis::Rolling(d) => rolling_figure(d),
        }
    }

    fn json(&self) -> Value {
        match self {
            AnyDiagnosis::Rocking(d) => diagnosis_json(d),
            AnyDiagnosis::Rolling(d) => rolling_json(d),
        }
    }

    fn mismatch(&self) -> bool {
        match self {
            AnyDiagnosis::Rocking(d) => d.mismatch,
            AnyDiagnosis::Rolling(d) => d.mismatch,
        }
    }

    fn explanation(&self) -> &str {
        match self {
            AnyDiagnosis::Rocking(d) => &d.explanation,
            AnyDiagnosis::Rolling(d) => &d.explanation,
        }
    }
}

/// The `diagnosis.json` contract of a rolling unit.
pub fn rolling_json(d: &RollingDiagnosis) -> Value {
    let candidates: Vec<Value> = d
        .candidates
        .iter()
        .map(|c| {
            let params: serde_json::Map<String, Value> =
                c.params.iter().map(|(k, v)| (k.to_string(), json!(v))).collect();
            json!({
                "effect": c.effect,
                "params": params,
                "rmse": c.rmse,
                "rmse_judged": c.rmse_judged,
                "score": c.score,
                "bic": c.bic,
                "chi2": c.misfit.chi2,
                "flagged_samples": c.flagged,
                "flagged_early_samples": c.flagged_early,
                "evaluations": c.evaluations,
                "onset_s": c.track.onset_s,
                "explanation": c.sentence,
            })
        })
        .collect();
    json!({
        "case": d.case,
        "model": "rolling",
        "mismatch": d.mismatch,
        "verdict": d.verdict,
        "window": d.window.map(|(a, b)| json!({"start_s": a, "end_s": b})),
        "rmse_before": d.rmse_before,
        "rmse_after": d.rmse_after,
        "rmse_definition": "sqrt(mean(((observed - predicted) / noise_sd)^2)) over the camera's x, y, yaw and the accelerometer's samples inside the window (the whole record when there is none); an accelerometer sample a model cannot speak for (around a stiff wall's contact) counts as 1; 1 is pure sensor noise",
        "noise": {"accel_mps2": d.accel_noise_mps2, "camera_m": d.camera_noise_m, "camera_rad": d.camera_noise_rad},
        "predictable_until_s": d.predictable_until_s,
        "twin_probe": d.probe,
        "judged": d.judged.map(|(a, b)| json!({"start_s": a, "end_s": b})),
        "candidates": candidates,
        "explanation": d.explanation,
        "calibration": calibration_json(&d.calibration),
        "shakeflow_version": env!("CARGO_PKG_VERSION"),
    })
}

fn rolling_accel_table(d: &RollingDiagnosis) -> Table {
    let before = d.evidence.accel_series(&d.baseline);
    let after = d.evidence.accel_series(&d.model);
    series_table(&before, &after, "top_ax_mps2", "m/s^2")
}

fn rolling_camera_table(d: &RollingDiagnosis) -> Table {
    let before = d.evidence.camera_series(&d.baseline);
    let after = d.evidence.camera_series(&d.model);
    let mut t = Table::new();
    t.push(Column::f64(TIME_COLUMN, "s", "time", before.iter().map(|r| r.0).collect()));
    for (i, (name, unit)) in [("x_m", "m"), ("y_m", "m"), ("yaw_rad", "rad")].into_iter().enumerate() {
        t.push(Column::f64(
            &format!("observed_{name}"),
            unit,
            "recorded by the camera (NaN: dropout)",
            before.iter().map(|r| r.1[i]).collect(),
        ));
        t.push(Column::f64(
            &format!("baseline_{name}"),
            unit,
            "the nominal 4WMC cart",
            before.iter().map(|r| r.2[i]).collect(),
        ));
        t.push(Column::f64(
            &format!("model_{name}"),
            unit,
            "the accepted model (the baseline when none is accepted)",
            after.iter().map(|r| r.2[i]).collect(),
        ));
    }
    t
}

/// Platform displacement, yaw and the accelerometer, observed and modelled, window shaded.
fn rolling_figure(d: &RollingDiagnosis) -> Result<Vec<u8>, String> {
    use crate::plot::{render_png, Panel, Series};
    let camera = d.evidence.camera_series(&d.baseline);
    let camera_model = d.evidence.camera_series(&d.model);
    let accel = d.evidence.accel_series(&d.baseline);
    let accel_model = d.evidence.accel_series(&d.model);
    let tc: Vec<f64> = camera.iter().map(|r| r.0).collect();
    let pick = |rows: &[(f64, [f64; 3], [f64; 3])], observed: bool, i: usize| -> Vec<f64> {
        rows.iter().map(|r| if observed { r.1[i] } else { r.2[i] }).collect()
    };
    let (ox, bx, mx) = (pick(&camera, true, 0), pick(&camera, false, 0), pick(&camera_model, false, 0));
    let (oy, by, my) = (pick(&camera, true, 1), pick(&camera, false, 1), pick(&camera_model, false, 1));
    let (ow, bw, mw) = (pick(&camera, true, 2), pick(&camera, false, 2), pick(&camera_model, false, 2));
    let ta: Vec<f64> = accel.iter().map(|r| r.0).collect();
    let za: Vec<f64> = accel.iter().map(|r| r.3 / d.accel_noise_mps2).collect();
    let zm: Vec<f64> = accel_model.iter().map(|r| r.3 / d.accel_noise_mps2).collect();
    let spans: Vec<(f64, f64)> = d.window.into_iter().collect();
    let label = format!("model: {}", d.verdict);
    fn three<'a>(
        title: &str,
        unit: &str,
        t: &'a [f64],
        [o, b, m]: [&'a [f64]; 3],
        label: &str,
        spans: &[(f64, f64)],
    ) -> Panel<'a> {
        Panel {
            title: title.into(),
            x_label: "time [s]".into(),
            y_label: unit.into(),
            series: vec![
                Series::new("observed", t, o).observed(),
                Series::new("nominal cart", t, b).model(),
                Series::new(label, t, m).model(),
            ],
            spans: spans.to_vec(),
            ..Panel::default()
        }
    }
    let panels = [
        three("platform x (camera)", "m", &tc, [&ox, &bx, &mx], &label, &spans),
        three("platform y (camera)", "m", &tc, [&oy, &by, &my], &label, &spans),
        three("platform yaw (camera)", "rad", &tc, [&ow, &bw, &mw], &label, &spans),
        Panel {
            title: format!(
                "accelerometer residual / noise: RMS in the window {:.1} → {:.1}",
                d.rmse_before, d.rmse_after
            ),
            x_label: "time [s]".into(),
            y_label: "residual / sigma".into(),
            series: vec![Series::new("nominal cart", &ta, &za).model(), Series::new("accepted model", &ta, &zm)],
            spans: spans.clone(),
            ..Panel::default()
        },
    ];
    let title = match d.window {
        Some((a, b)) => format!("{}: {} (mismatch {a:.2}-{b:.2} s, shaded)", d.case, d.verdict),
        None => format!("{}: no mismatch", d.case),
    };
    render_png(&title, &panels, 1400, 1300)
}
