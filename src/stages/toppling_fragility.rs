//! `toppling_fragility`: one unit under a set of floor records scaled over a range of
//! intensities, every run simulated (in parallel), and a lognormal fragility curve fitted to
//! overturn / no overturn by maximum likelihood.

use super::error::{float_column, StageError};
use std::path::Path;
use std::sync::Arc;

use rayon::prelude::*;

use super::simulate_toppling::{model_from_params, simulate_record, RockingParams};
use super::{partition_values, Stage, StageContext};
use crate::pipeline::params::{self, Params};
use crate::stats::fragility::{fit_lognormal, FitOutcome, LognormalFit};
use crate::summary;
use crate::table::{Column, ColumnData, Table, TIME_COLUMN};

crate::stage_params! {
    /// The parameters of `toppling_fragility`.
    pub struct TopplingFragilityParams {
        #[flatten]
        pub model: RockingParams,
        /// intensity measure: peak floor acceleration (m/s^2) or peak floor velocity (m/s, trapezoidal integral of
        /// the horizontal record)
        pub im: Intensity [default = "pfa"],
        /// scale factors applied to every record (horizontal and vertical alike); or use im_levels
        pub scales: Vec<f64> [default = [], range = (0.0, 1e3)],
        /// target intensities (m/s^2 for pfa, m/s for pfv): each record is scaled to each level
        pub im_levels: Vec<f64> [default = [], range = (0.0, 1e3)],
    }
}

crate::choice! {
    /// `im`: the intensity measure.
    pub enum Intensity { Pfa = "pfa", Pfv = "pfv" }
}

super::declare_stage! {
    /// Overturning fragility of one unit: floor records scaled over intensities, all runs simulated in parallel,
    /// lognormal curve (median, beta) by maximum likelihood.
    pub struct TopplingFragility: "toppling_fragility", version 3, reads Datasets, params TopplingFragilityParams;
    outputs {
        /// every run: record, level, scale, im, overturned, overturn_time_s, overturn_side, max_abs_theta_rad,
        /// n_impacts
        "runs": Table,
        /// one row: im_measure, median, beta, log_likelihood, n_runs, n_overturned, note
        "fragility": Table => Fragility,
        /// fragility.png: the fitted curve, every run at 0 (stood) or 1 (overturned) and the overturned fraction per
        /// level; pfa in g
        "figures": Files,
    }
    examples {
        /// PS2's overturning fragility from the record scaled to three intensities
        super::RINALDI => "\
toppling_fragility:
  type: toppling_fragility
  inputs: [load]
  params:
    preset: PS2
    scales: [0.5, 1.0, 2.0]
",
    }
}

impl Stage for TopplingFragility {
    super::info_and_check_params!(TopplingFragilityParams);

    /// `horizontal` and `vertical` must be columns of the floor records.
    fn output_columns(&self, params: &Params, input: Option<&[String]>) -> super::ColumnCheck {
        (None, super::simulate_toppling::floor_column_errors(params, input))
    }

    fn summary(&self, stage_dir: &Path) -> Option<String> {
        summary_line(stage_dir).ok()
    }

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let p: TopplingFragilityParams = params::typed(ctx.params)?;
        let equipment = p.model.equipment.as_deref().map(|e| ctx.file_path(e));
        let (block, options) = model_from_params(&p.model, equipment.as_deref())?;
        let (scales, levels) = (p.scales, p.im_levels);
        if scales.is_empty() == levels.is_empty() {
            anyhow::bail!("give either `scales` or `im_levels` (exactly one of them, non-empty)");
        }
        let (horizontal, vertical) = (p.model.horizontal.clone(), p.model.vertical.clone());
        let by_velocity = p.im == Intensity::Pfv;
        let parts: Vec<_> = ctx.inputs.iter().flat_map(|i| i.parts()).collect();
        if parts.is_empty() {
            anyhow::bail!("no records to scale: the stage's inputs (after `select`) are empty");
        }
        let records: Vec<(String, Arc<Table>, f64)> = parts
            .par_iter()
            .map(|part| {
                let table = ctx.read_table(part)?;
                let im =
                    intensity(&table, &horizontal, by_velocity).map_err(|e| anyhow::anyhow!("{}: {e}", part.label))?;
                Ok((partition_values(&part.partition), table, im))
            })
            .collect::<anyhow::Result<_>>()?;
        // Every (record, level) pair, in a fixed order so the runs table is deterministic: the
        // record, the index of its level and the factor that scales the record to it.
        let runs: Vec<(usize, usize, f64)> = records
            .iter()
            .enumerate()
            .flat_map(|(r, (_, _, im))| {
                let factors: Vec<f64> =
                    if scales.is_empty() { levels.iter().map(|l| l / im).collect() } else { scales.clone() };
                factors.into_iter().enumerate().map(move |(level, s)| (r, level, s))
            })
            .collect();
        ctx.sink.set_total(runs.len());
        let results: Vec<(bool, Option<f64>, i64, f64, i64)> = runs
            .par_iter()
            .map(|&(r, _, scale)| {
                let table = scaled(&records[r].1, scale, &horizontal, vertical.as_deref());
                let (_, response) = simulate_record(&table, &block, &options, &horizontal, vertical.as_deref())
                    .map_err(|e| anyhow::anyhow!("{} × {scale}: {e}", records[r].0))?;
                ctx.sink.tick();
                let (time, side) = response.overturn.map_or((None, 0), |(t, s)| (Some(t), i64::from(s)));
                let impacts = response.count(crate::physics::rocking::EventKind::Impact) as i64;
                Ok((response.overturn.is_some(), time, side, response.max_abs_theta(), impacts))
            })
            .collect::<anyhow::Result<_>>()?;
        // A target level is the run's intensity exactly (record × (level / record) may differ
        // from it in the last bit), so equal levels are equal numbers and group as one.
        let ims: Vec<f64> = runs
            .iter()
            .map(|&(r, level, s)| if scales.is_empty() { levels[level] } else { records[r].2 * s })
            .collect();
        let overturned: Vec<bool> = results.iter().map(|r| r.0).collect();
        let outcome = fit_lognormal(&ims, &overturned);
        let unit = if by_velocity { "m/s" } else { "m/s^2" };
        let im_name = if by_velocity { "pfv" } else { "pfa" };

        let mut table = Table::new();
        table.push(Column {
            name: "record".into(),
            unit: String::new(),
            description: "the floor record: its partition values (`CIGO360` for record=CIGO360; several joined by /)"
                .into(),
            data: ColumnData::Str(runs.iter().map(|&(r, _, _)| records[r].0.clone()).collect()),
        });
        let level_description = if scales.is_empty() {
            "index of the target intensity in `im_levels`, from 0"
        } else {
            "index of the scale factor in `scales`, from 0"
        };
        table.push(Column {
            name: "level".into(),
            unit: String::new(),
            description: level_description.into(),
            data: ColumnData::I64(runs.iter().map(|r| r.1 as i64).collect()),
        });
        table.push(Column::f64("scale", "", "factor applied to the record", runs.iter().map(|r| r.2).collect()));
        let im_description = if scales.is_empty() {
            format!("the target intensity ({im_name}) the record was scaled to: equal levels are equal numbers")
        } else {
            format!("intensity of the scaled record ({im_name})")
        };
        table.push(Column::f64("im", unit, &im_description, ims.clone()));
        table.push(Column {
            name: "overturned".into(),
            unit: String::new(),
            description: "the unit overturned".into(),
            data: ColumnData::Bool(overturned.clone()),
        });
        table.push(Column {
            name: "overturn_time_s".into(),
            unit: "s".into(),
            description: "when (null when it did not)".into(),
            data: ColumnData::OptF64(results.iter().map(|r| r.1).collect()),
        });
        table.push(Column {
            name: "overturn_side".into(),
            unit: String::new(),
            description: "+1 / -1, the sign of theta; 0 when it did not overturn".into(),
            data: ColumnData::I64(results.iter().map(|r| r.2).collect()),
        });
        table.push(Column::f64(
            "max_abs_theta_rad",
            "rad",
            "largest |theta| of the run",
            results.iter().map(|r| r.3).collect(),
        ));
        table.push(Column {
            name: "n_impacts".into(),
            unit: String::new(),
            description: "impacts in the run".into(),
            data: ColumnData::I64(results.iter().map(|r| r.4).collect()),
        });
        table
            .metadata
            .insert("shakeflow.rocking".into(), super::simulate_toppling::model_facts(&block, &options).to_string());

        let (fit, note) = describe(&outcome, unit);
        let mut summary = Table::new();
        summary.push(Column {
            name: "im_measure".into(),
            unit: String::new(),
            description: "pfa or pfv".into(),
            data: ColumnData::Str(vec![im_name.into()]),
        });
        summary.push(Column {
            name: "median".into(),
            unit: unit.into(),
            description: "intensity with 50 % probability of overturning (theta of the lognormal)".into(),
            data: ColumnData::OptF64(vec![fit.map(|f| f.median)]),
        });
        summary.push(Column {
            name: "beta".into(),
            unit: String::new(),
            description: "logarithmic standard deviation".into(),
            data: ColumnData::OptF64(vec![fit.map(|f| f.beta)]),
        });
        summary.push(Column {
            name: "log_likelihood".into(),
            unit: String::new(),
            description: "at the maximum".into(),
            data: ColumnData::OptF64(vec![fit.map(|f| f.log_likelihood)]),
        });
        summary.push(Column {
            name: "n_runs".into(),
            unit: String::new(),
            description: "runs".into(),
            data: ColumnData::I64(vec![ims.len() as i64]),
        });
        summary.push(Column {
            name: "n_overturned".into(),
            unit: String::new(),
            description: "runs that overturned".into(),
            data: ColumnData::I64(vec![overturned.iter().filter(|&&o| o).count() as i64]),
        });
        summary.push(Column {
            name: "note".into(),
            unit: String::new(),
            description: "how to read the fit".into(),
            data: ColumnData::Str(vec![note.clone()]),
        });

        let title = format!(
            "{}: probability of overturning ({} runs)",
            super::simulate_toppling::unit_name(&p.model, ctx.stage_name),
            ims.len()
        );
        let png = figure(&title, &ims, &overturned, fit.as_ref(), by_velocity, &note).map_err(anyhow::Error::msg)?;
        ctx.sink.write_file("figures", "fragility.png", &png)?;
        ctx.sink.write("runs", &Vec::new(), table)?;
        ctx.sink.write("fragility", &Vec::new(), summary)
    }
}

/// PFA, or PFV from the trapezoidal integral of the (baseline-corrected) horizontal record.
fn intensity(table: &Table, horizontal: &str, velocity: bool) -> Result<f64, StageError> {
    let a = float_column(table, horizontal)?;
    let im = if velocity {
        let t = table.f64_column(TIME_COLUMN).ok_or_else(|| StageError::Record("no time_s column".into()))?;
        let mut v = 0.0_f64;
        let mut peak = 0.0_f64;
        for k in 1..a.len() {
            v += 0.5 * (a[k] + a[k - 1]) * (t[k] - t[k - 1]);
            peak = peak.max(v.abs());
        }
        peak
    } else {
        a.iter().fold(0.0_f64, |m, v| m.max(v.abs()))
    };
    if im > 0.0 && im.is_finite() {
        Ok(im)
    } else {
        Err(StageError::Record(format!("`{horizontal}` has no motion to scale (intensity {im})")))
    }
}

/// The record with its floor channels multiplied by `scale`.
fn scaled(table: &Table, scale: f64, horizontal: &str, vertical: Option<&str>) -> Table {
    let mut out = Table::new();
    for c in &table.columns {
        if c.name == TIME_COLUMN || c.name == horizontal || Some(c.name.as_str()) == vertical {
            let mut c = c.clone();
            if c.name != TIME_COLUMN {
                if let ColumnData::F64(v) = &mut c.data {
                    v.iter_mut().for_each(|x| *x *= scale);
                }
            }
            out.push(c);
        }
    }
    out
}

fn describe(outcome: &FitOutcome, unit: &str) -> (Option<LognormalFit>, String) {
    match *outcome {
        FitOutcome::Fitted(f) => (Some(f), format!("lognormal MLE: median {:.4} {unit}, beta {:.3}", f.median, f.beta)),
        FitOutcome::NoneOverturned => (None, "no run overturned: raise the intensities".into()),
        FitOutcome::AllOverturned => (None, "every run overturned: lower the intensities".into()),
        FitOutcome::Separated { highest_survival, lowest_overturn } => (
            None,
            format!("every overturn lies above every survival (between {highest_survival:.4} and {lowest_overturn:.4} {unit}): beta is not identifiable; use more records or finer levels"),
        ),
    }
}

fn figure(
    title: &str,
    ims: &[f64],
    overturned: &[bool],
    fit: Option<&LognormalFit>,
    by_velocity: bool,
    note: &str,
) -> Result<Vec<u8>, crate::plot::PlotError> {
    use crate::plot::{render_png, Panel, Series};
    // Accelerations are read in g on a fragility curve.
    let (x_label, per_unit) = if by_velocity {
        ("peak floor velocity [m/s]", 1.0)
    } else {
        ("peak floor acceleration [g]", crate::units::G0)
    };
    let ims: Vec<f64> = ims.iter().map(|im| im / per_unit).collect();
    // Overturned fraction per distinct intensity level (levels repeat across records when
    // `im_levels` is used; with `scales`, every run is its own point).
    let mut levels: Vec<(f64, bool)> = ims.iter().copied().zip(overturned.iter().copied()).collect();
    levels.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut points_x = Vec::new();
    let mut points_y = Vec::new();
    let mut k = 0;
    while k < levels.len() {
        let mut j = k;
        while j < levels.len() && (levels[j].0 - levels[k].0).abs() <= 1e-9 * levels[k].0 {
            j += 1;
        }
        points_x.push(levels[k].0);
        points_y.push(levels[k..j].iter().filter(|l| l.1).count() as f64 / (j - k) as f64);
        k = j;
    }
    let (lo, hi) = (levels[0].0, levels[levels.len() - 1].0);
    let curve_x: Vec<f64> = (0..=200).map(|i| lo + (hi - lo) * i as f64 / 200.0).collect();
    let curve_y: Vec<f64> = curve_x.iter().map(|&x| fit.map_or(f64::NAN, |f| f.probability(x * per_unit))).collect();
    let runs: Vec<f64> = overturned.iter().map(|&o| if o { 1.0 } else { 0.0 }).collect();
    let panel_title = match fit {
        Some(f) if by_velocity => format!("lognormal fit: median {:.3} m/s, β {:.2}", f.median, f.beta),
        Some(f) => format!("lognormal fit: median {:.3} g, β {:.2}", f.median / per_unit, f.beta),
        None => note.to_string(),
    };
    let panels = [Panel {
        title: panel_title,
        x_label: x_label.into(),
        y_label: "P(overturn)".into(),
        series: vec![
            // The runs first, so the curve and each level's fraction stay in view over them.
            Series::new("runs (1: overturned, 0: stood)", &ims, &runs).points(),
            Series::new("lognormal fit", &curve_x, &curve_y),
            Series::new("overturned fraction per level", &points_x, &points_y).points(),
        ],
        markers: Vec::new(),
        log_y: false,
        spans: Vec::new(),
    }];
    render_png(title, &panels, 1000, 600)
}

/// The line `shakeflow run` prints: "3/10 records overturned at some level (41/240 runs); median 0.58 g, β 0.50"
fn summary_line(dir: &Path) -> anyhow::Result<String> {
    let runs = summary::read(dir, "runs")?.frame;
    let fit = summary::read(dir, "fragility")?.frame;
    let (records, overturned) = (summary::texts(&runs, "record")?, summary::flags(&runs, "overturned")?);
    let all: std::collections::BTreeSet<&String> = records.iter().collect();
    let toppled: std::collections::BTreeSet<&String> =
        records.iter().zip(&overturned).filter(|(_, &o)| o).map(|(r, _)| r).collect();
    let mut line = format!(
        "{}/{} records overturned at some level ({}/{} runs)",
        toppled.len(),
        all.len(),
        overturned.iter().filter(|&&o| o).count(),
        overturned.len()
    );
    let measure = summary::texts(&fit, "im_measure")?.pop().unwrap_or_default();
    match (summary::floats(&fit, "median")?.pop().flatten(), summary::floats(&fit, "beta")?.pop().flatten()) {
        (Some(median), Some(beta)) if measure == "pfa" => {
            line += &format!("; median {:.2} g ({median:.3} m/s^2), β {beta:.2}", median / summary::G)
        }
        (Some(median), Some(beta)) => line += &format!("; median {median:.3} m/s, β {beta:.2}"),
        _ => line += &format!("; no curve: {}", summary::texts(&fit, "note")?.pop().unwrap_or_default()),
    }
    Ok(line)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Five whole cycles of a = A sin(2π f t) at 2 kHz, and a vertical channel.
    fn sine(amplitude: f64, f_hz: f64) -> Table {
        let n = (5.0 / f_hz * 2000.0) as usize + 1;
        let time: Vec<f64> = (0..n).map(|k| k as f64 / 2000.0).collect();
        let mut table = Table::new();
        table.push(Column::f64(
            "ax_mps2",
            "m/s^2",
            "",
            time.iter().map(|t| amplitude * (2.0 * PI * f_hz * t).sin()).collect(),
        ));
        table.push(Column::f64("az_mps2", "m/s^2", "", vec![1.0; n]));
        table.push(Column::f64("other", "", "", vec![7.0; n]));
        table.push(Column::f64(TIME_COLUMN, "s", "", time));
        table
    }

    #[test]
    fn pfa_and_pfv_of_a_sine_are_its_closed_forms() {
        let (amplitude, f_hz) = (2.5, 1.6);
        let table = sine(amplitude, f_hz);
        let pfa = intensity(&table, "ax_mps2", false).unwrap();
        assert!((pfa / amplitude - 1.0).abs() < 1e-4, "PFA {pfa}");
        // v(t) = A/(2πf) (1 − cos 2πft) from rest: its peak is A/(πf).
        let pfv = intensity(&table, "ax_mps2", true).unwrap();
        let exact = amplitude / (PI * f_hz);
        assert!((pfv / exact - 1.0).abs() < 1e-5, "PFV {pfv} against {exact}");
        assert!(intensity(&sine(0.0, f_hz), "ax_mps2", false).is_err());
    }

    #[test]
    fn scaling_multiplies_the_floor_channels_only_and_keeps_the_clock() {
        let table = sine(2.5, 1.6);
        let scaled = scaled(&table, 3.0, "ax_mps2", Some("az_mps2"));
        assert_eq!(scaled.column_names(), ["ax_mps2", "az_mps2", TIME_COLUMN]);
        assert_eq!(scaled.f64_column(TIME_COLUMN), table.f64_column(TIME_COLUMN));
        assert_eq!(scaled.f64_column("az_mps2").unwrap()[0], 3.0);
        let pfa = intensity(&scaled, "ax_mps2", false).unwrap();
        assert!((pfa / 7.5 - 1.0).abs() < 1e-4, "PFA {pfa}");
    }
}
