//! `diagnose` (stage and `shakeflow diagnose` command): for each case folder, where the nominal
//! toppling model and the recordings disagree, which physics explains it, and the fit before
//! and after. Writes the contract `diagnosis.json` (at the stage folder's root for one case,
//! `<case>/diagnosis.json` for each of several), the observed/baseline/model series and
//! residuals (Parquet, + MCAP with `mcap: true`) and a figure with the located window shaded.

use rayon::prelude::*;
use serde::Serialize;

use super::{Stage, StageContext};
use crate::diagnose::contract::Contract;
use crate::diagnose::rolling::RollingDiagnosis;
use crate::diagnose::{diagnose, Diagnosis, Settings};
use crate::io::case::read_case_unchanged;
use crate::pipeline::params::{self, ParamError, Params};
use crate::pipeline::spec::RecordFormat;
use crate::plot::PlotError;
use crate::table::{Column, Table, TIME_COLUMN};

/// The contract file held-out scorers read (`shakeflow diagnose CASE --out OUT` → `OUT/diagnosis.json`).
pub const CONTRACT: &str = "diagnosis.json";

crate::stage_params! {
    /// The parameters of `diagnose` (also `shakeflow diagnose --set`'s).
    pub struct DiagnoseParams {
        /// a residual beyond this many noise standard deviations counts as a disagreement (5 within 0.1 s flag a mismatch)
        pub exceedance_sigma: f64 [default = 4.0, range = (2.0, 20.0)],
        /// a physics is accepted only if it cuts the window's noise-normalised RMS misfit at least this many times
        pub min_improvement: f64 [default = 3.0, range = (1.0, 1e3)],
        /// ... and leaves at most this fraction of the flagged samples flagged (rocking cases; a rolling cart may leave 0.7 of those in the window's first 5 s)
        pub max_remaining_flagged: f64 [default = 0.12, range = (0.0, 1.0)],
        #[flatten]
        pub mcap: super::Mcap,
    }
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

super::declare_stage! {
    /// Where the toppling model (or, for `model: rolling` cases, the 4WMC cart) and a unit's records disagree, which
    /// physics it left out (rocking: sliding, mass_change, restitution, flexibility, obstacle_impact, sensor_tilt;
    /// rolling: lateral_impact, mass_change, caster_brake, swivel_jam), fitted jointly with the nominal parameters the
    /// equipment file's `uncertainty` block says are known only roughly (calibrated first), ranked by BIC; `ambiguous`
    /// when two explain the records about equally well, or `unexplained`.
    pub struct Diagnose: "diagnose", version 23,
        reads Files(&[RecordFormat::Case]), params DiagnoseParams;
    outputs {
        /// per case: mismatch, verdict, window_start_s, window_end_s, rmse_before, rmse_after, explanation, candidates
        /// (JSON), calibration (JSON)
        "diagnosis": Table => Diagnosis,
        /// per case: observed, baseline and model top acceleration and the residuals before/after
        "accel": TimeSeries,
        /// per case: observed, baseline and model rotation and the residuals before/after
        "camera": TimeSeries,
        /// <case>.png: records, models, residuals, window shaded
        "reports": Files,
        /// the contract (verdict, window, rmse before/after, candidates, explanation, calibration): at the stage
        /// folder's root for one case, in `<case>/` for each of several
        "diagnosis.json": Page,
    }
    examples {
        /// a shared case whose WSU1 unit loses 15 % of its mass 4.6 s into the record (its truth file:
        /// `effect: mass_change`), diagnosed as `mass_change`
        CASE => "\
diagnose:
  type: diagnose
  inputs: [case]
",
    }
}

/// One shared diagnosis case (`../shared/cases/demo/demo_02`: a WSU1 unit on the isolated
/// building's 4th floor; `truth/` says what is hidden, which the stage never reads).
const CASE: super::ExampleData = super::ExampleData {
    what: "a shared diagnosis case",
    head: "\
inputs:
  case:
    description: a WSU1 unit on the base-isolated building's 4th floor, its records and equipment file
    format: case
    path: ../shared/cases/demo/demo_02/equipment.yaml
    partition: {case: demo_02}
stages:
",
};

impl Stage for Diagnose {
    super::info_and_check_params!(DiagnoseParams);

    fn summary(&self, stage_dir: &std::path::Path) -> Option<String> {
        crate::summary::verdicts(stage_dir).ok()
    }

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let settings = settings(ctx.params)?;
        let parts: Vec<_> = ctx.inputs.iter().flat_map(|i| i.parts()).collect();
        ctx.sink.set_total(parts.len());
        let mut rows: Vec<(String, Contract)> = parts
            .par_iter()
            .map(|part| {
                let Report { contract, mut accel, mut camera, figure } =
                    diagnose_folder(&part.path, &part.hash, &settings)
                        .map_err(|e| anyhow::anyhow!("{}: {e:#}", part.label))?;
                for t in [&mut accel, &mut camera] {
                    t.metadata.extend(super::record_provenance(part));
                }
                ctx.sink.write("accel", &part.partition, accel)?;
                ctx.sink.write("camera", &part.partition, camera)?;
                // Named by the case's partition values, as the `case` column names it.
                let name = match super::partition_values(&part.partition).replace('/', "_") {
                    n if n.is_empty() => contract.case.clone(),
                    n => n,
                };
                // The contract: `diagnosis.json` of the one case, or `<case>/diagnosis.json` of each.
                match parts.len() {
                    1 => ctx.sink.write_page(CONTRACT, contract.bytes().as_bytes())?,
                    _ => ctx.sink.write_record_page(CONTRACT, &name, contract.bytes().as_bytes())?,
                }
                ctx.sink.write_file("reports", &format!("{name}.png"), &figure?)?;
                Ok((super::partition_values(&part.partition), contract))
            })
            .collect::<anyhow::Result<_>>()?;
        rows.sort_by(|a, b| a.0.cmp(&b.0));
        ctx.sink.write("diagnosis", &Vec::new(), summary_table(&rows))
    }
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

fn summary_table(rows: &[(String, Contract)]) -> Table {
    let optional = |name: &str, description: &str, v: Vec<Option<f64>>| Column {
        name: name.into(),
        unit: "s".into(),
        description: description.into(),
        data: crate::table::ColumnData::OptF64(v),
    };
    let mut t = Table::new();
    t.push(super::text_column(
        "case",
        "the case: its partition values (`demo_01` for case=demo_01)",
        rows.iter().map(|r| r.0.clone()).collect(),
    ));
    t.push(Column {
        name: "mismatch".into(),
        unit: String::new(),
        description: "the nominal model disagrees with the records beyond their noise".into(),
        data: crate::table::ColumnData::Bool(rows.iter().map(|r| r.1.mismatch).collect()),
    });
    t.push(super::text_column(
        "verdict",
        "none | unexplained | ambiguous; rocking: sliding | mass_change | restitution | flexibility | obstacle_impact | sensor_tilt; rolling: lateral_impact | mass_change | caster_brake | swivel_jam",
        rows.iter().map(|r| r.1.verdict.to_string()).collect(),
    ));
    t.push(optional(
        "window_start_s",
        "first disagreement (null without one)",
        rows.iter().map(|r| r.1.window.map(|w| w.0)).collect(),
    ));
    t.push(optional("window_end_s", "last disagreement", rows.iter().map(|r| r.1.window.map(|w| w.1)).collect()));
    t.push(Column::f64(
        "rmse_before",
        "",
        "noise-normalised RMS misfit of the nominal model in the window",
        rows.iter().map(|r| r.1.rmse_before).collect(),
    ));
    t.push(Column::f64(
        "rmse_after",
        "",
        "the same for the accepted model",
        rows.iter().map(|r| r.1.rmse_after).collect(),
    ));
    t.push(super::text_column(
        "explanation",
        "for a test engineer",
        rows.iter().map(|r| r.1.explanation.clone()).collect(),
    ));
    t.push(super::text_column(
        "candidates",
        "every fitted hypothesis (JSON)",
        rows.iter().map(|r| compact(&r.1.candidates)).collect(),
    ));
    t.push(super::text_column(
        "calibration",
        "per uncertain nominal parameter: stated, fitted, sd, within 3 sd (JSON; {} when the equipment file has no uncertainty block)",
        rows.iter().map(|r| compact(&r.1.calibration)).collect(),
    ));
    t
}

/// Records, nominal model and accepted model, the residuals, with the window shaded.
pub fn figure(d: &Diagnosis) -> Result<Vec<u8>, PlotError> {
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
    let za: Vec<f64> = accel.iter().map(|r| r.3 / d.noise.accel_mps2).collect();
    let zm: Vec<f64> = accel_model.iter().map(|r| r.3 / d.noise.accel_mps2).collect();
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

/// What the stage writes of one case: the contract, the two tables and the figure.
pub struct Report {
    pub contract: Contract,
    pub accel: Table,
    pub camera: Table,
    pub figure: Result<Vec<u8>, PlotError>,
}

impl From<Diagnosis> for Report {
    fn from(d: Diagnosis) -> Report {
        Report { contract: Contract::from(&d), accel: accel_table(&d), camera: camera_table(&d), figure: figure(&d) }
    }
}

impl From<RollingDiagnosis> for Report {
    fn from(d: RollingDiagnosis) -> Report {
        Report {
            contract: Contract::from(&d),
            accel: rolling_accel_table(&d),
            camera: rolling_camera_table(&d),
            figure: rolling_figure(&d),
        }
    }
}

/// A part of the contract as one line of JSON (the summary table's cells).
fn compact(value: &impl Serialize) -> String {
    serde_json::to_string(value).expect("the diagnosis is JSON")
}

/// Reads and diagnoses the case folder `dir`, rocking or rolling as its equipment file says;
/// `expected_hash` as for [`read_case_unchanged`].
pub fn diagnose_folder(dir: &std::path::Path, expected_hash: &str, settings: &Settings) -> anyhow::Result<Report> {
    if crate::io::case::case_model(dir)?.as_deref() == Some("rolling") {
        let case = crate::io::case::read_rolling_case(dir)?;
        if !expected_hash.is_empty() && crate::io::hash::hash_dir(dir)?.0 != expected_hash {
            anyhow::bail!("`{}` changed while this run was reading it", dir.display());
        }
        let d = crate::diagnose::rolling::diagnose(&case, settings)
            .map_err(|e| anyhow::anyhow!("{}: {e}", dir.display()))?;
        return Ok(d.into());
    }
    let case = read_case_unchanged(dir, expected_hash)?;
    Ok(diagnose(&case, settings).map_err(|e| anyhow::anyhow!("{}: {e}", dir.display()))?.into())
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
fn rolling_figure(d: &RollingDiagnosis) -> Result<Vec<u8>, PlotError> {
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
    let za: Vec<f64> = accel.iter().map(|r| r.3 / d.noise.accel_mps2).collect();
    let zm: Vec<f64> = accel_model.iter().map(|r| r.3 / d.noise.accel_mps2).collect();
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::params::normalize;

    /// The default settings, as a pipeline without `params:` gets them.
    fn defaults() -> Settings {
        settings(&normalize(INFO.params, INFO.name, Vec::new()).unwrap()).unwrap()
    }

    #[test]
    fn the_settings_are_the_declared_defaults() {
        let s = defaults();
        assert_eq!((s.exceedance_sigma, s.min_improvement, s.max_remaining_flagged), (4.0, 3.0, 0.12));
    }

    /// The shared rolling case `rolling_demo/demo_01` (its truth: `effect: none`): the verdict is
    /// `none` without a window, the summary row says so, and the camera table carries the case's
    /// records as its `observed_cpt.csv` gives them (`nan`: a dropout), read here by a plain split of
    /// the text.
    #[test]
    fn a_rolling_case_without_a_mismatch_is_none_and_keeps_its_records() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/cases/rolling_demo/demo_01");
        let report = diagnose_folder(&dir, "", &defaults()).unwrap();
        assert_eq!(report.contract.verdict.to_string(), "none");
        assert!(!report.contract.mismatch && report.contract.window.is_none());
        let summary = summary_table(&[("demo_01".into(), report.contract)]);
        assert_eq!(summary.column("verdict").unwrap().data, crate::table::ColumnData::Str(vec!["none".into()]));

        let text = std::fs::read_to_string(dir.join("observed_cpt.csv")).unwrap();
        let rows: Vec<Vec<f64>> =
            text.lines().skip(1).map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
        let by_time: std::collections::HashMap<u64, &Vec<f64>> = rows.iter().map(|r| (r[0].to_bits(), r)).collect();
        let time = report.camera.f64_column(TIME_COLUMN).unwrap();
        assert!(time.len() + 1 >= rows.len(), "{} of {} camera rows kept", time.len(), rows.len());
        for (k, name) in ["x_m", "y_m", "yaw_rad"].into_iter().enumerate() {
            let observed = report.camera.f64_column(&format!("observed_{name}")).unwrap();
            for (t, v) in time.iter().zip(observed) {
                let expected = by_time[&t.to_bits()][k + 1];
                assert!(*v == expected || v.is_nan() && expected.is_nan(), "{name} at {t} s: {v} against {expected}");
            }
        }
    }

    /// The one line after `run` counts the verdicts.
    #[test]
    fn the_summary_line_counts_the_verdicts() {
        use crate::stages::test_tables::{part, text};
        let dir = crate::tempdir::tempdir().unwrap();
        part(dir.path(), "diagnosis", "", vec![text("verdict", &["sliding", "none", "sliding"])]);
        assert_eq!(Diagnose.summary(dir.path()).unwrap(), "3 cases: none 1, sliding 2");
    }
}
