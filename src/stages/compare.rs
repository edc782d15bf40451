//! `compare`: measured time series against a reference (e.g. motion recovered from video against
//! the motion that made it): the reference is interpolated linearly onto the measured times,
//! units are reconciled through the columns' `unit` metadata, and the RMS and largest errors are
//! reported per column pair, with a PNG overlay.

use super::{partition_path, split_pair, Stage, StageContext};
use crate::error::UserError;
use crate::pipeline::params;
use crate::plot::{render_png, Panel, Series};
use crate::table::{Column, ColumnData, Table, TIME_COLUMN};

crate::stage_params! {
    /// The parameters of `compare`.
    pub struct CompareParams {
        /// `measured_column -> reference_column` pairs; the first input is measured, the second the reference
        pub pairs: Vec<String> [],
        /// compare changes from the first sample where both are known (for displacements measured from a start)
        pub relative: bool [default = false],
    }
}

super::declare_stage! {
    /// Errors of measured time series against a reference (interpolated onto the measured times, units reconciled): RMS
    /// and largest error per column pair, and a PNG overlay.
    pub struct Compare: "compare", version 2, reads Datasets, params CompareParams;
    outputs {
        /// per pair: measured, reference, unit, samples, missing, rms_error, max_abs_error, reference_rms
        "errors": Table,
        /// <partition or compare>.png: measured over reference, and their difference
        "figures": Files,
    }
    examples {
        /// what the cubic baseline changed: corrected against loaded accelerations
        super::RINALDI => "\
baseline:
  type: baseline
  inputs: [load]
compare:
  type: compare
  inputs: [baseline, load]
  params:
    pairs: [ax_mps2 -> ax_mps2, az_mps2 -> az_mps2]
",
    }
}

impl Stage for Compare {
    super::info_and_check_params!(CompareParams);

    fn work_units(&self) -> super::WorkUnits {
        super::WorkUnits::PerRecordOf { primary: 0 }
    }

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let [measured, reference] = ctx.inputs else {
            return Err(UserError::new("`compare` reads two inputs: [measured, reference]")
                .hint("e.g. inputs: [cpt_rocking.motion, load_truth]")
                .into());
        };
        let p: CompareParams = params::typed(ctx.params)?;
        let pairs: Vec<(String, String)> = p
            .pairs
            .iter()
            .map(|p| match split_pair(p) {
                (m, Some(r)) => Ok((m, r)),
                _ => Err(UserError::new(format!("pair `{p}` must look like `measured_column -> reference_column`"))),
            })
            .collect::<Result<_, _>>()?;
        let relative = p.relative;
        ctx.sink.set_total(measured.parts().len());
        for part in measured.parts() {
            let reference_part = match reference.parts().iter().find(|r| r.partition == part.partition) {
                Some(r) => r,
                None if reference.parts().len() == 1 => &reference.parts()[0],
                None => {
                    return Err(UserError::new(format!(
                        "no reference record shares the partition `{}` of `{}`",
                        partition_path(&part.partition),
                        part.label
                    ))
                    .hint("give one reference record, or one per measured record with the same partition keys")
                    .into())
                }
            };
            let (m, r) = (ctx.read_table(part)?, ctx.read_table(reference_part)?);
            let title = format!(
                "{} against {}{}",
                stage_of(&part.label),
                stage_of(&reference_part.label),
                if part.partition.is_empty() {
                    String::new()
                } else {
                    format!(", {}", super::record_title(&part.partition, ""))
                }
            );
            let (mut errors, png) = compare(&m, &r, &pairs, relative, &part.label, &reference_part.label, &title)?;
            errors.metadata.extend(super::record_provenance(part));
            errors.metadata.insert("shakeflow.reference_file".into(), reference_part.label.clone());
            errors.metadata.insert("shakeflow.reference_hash".into(), reference_part.hash.clone());
            let name = match partition_path(&part.partition) {
                p if p.is_empty() => "compare.png".to_string(),
                p => format!("{}.png", p.replace(['/', '='], "_")),
            };
            ctx.sink.write_file("figures", &name, &png)?;
            ctx.sink.write("errors", &part.partition, errors)?;
        }
        Ok(())
    }
}

/// The reference at `t` by linear interpolation; NaN outside its time span.
fn interpolate(time: &[f64], values: &[f64], t: f64) -> f64 {
    if time.is_empty() || !(t >= time[0] && t <= time[time.len() - 1]) {
        return f64::NAN;
    }
    let k = time.partition_point(|&x| x <= t).clamp(1, time.len() - 1);
    let (t0, t1) = (time[k - 1], time[k]);
    if t1 == t0 {
        return values[k - 1];
    }
    values[k - 1] + (values[k] - values[k - 1]) * (t - t0) / (t1 - t0)
}

fn si_factor(unit: &str) -> Option<f64> {
    if unit.is_empty() {
        Some(1.0)
    } else {
        crate::units::conversion(unit).map(|c| c.factor)
    }
}

fn compare(
    measured: &Table,
    reference: &Table,
    pairs: &[(String, String)],
    relative: bool,
    m_label: &str,
    r_label: &str,
    title: &str,
) -> anyhow::Result<(Table, Vec<u8>)> {
    let time = measured.f64_column(TIME_COLUMN).ok_or_else(|| anyhow::anyhow!("{m_label}: no time_s column"))?;
    let r_time = reference.f64_column(TIME_COLUMN).ok_or_else(|| anyhow::anyhow!("{r_label}: no time_s column"))?;
    let column = |table: &Table, name: &str, label: &str| -> anyhow::Result<(Vec<f64>, String)> {
        let c = table.column(name).ok_or_else(|| {
            UserError::new(format!("{label} has no column `{name}`"))
                .hint(format!("its columns: {}", table.column_names().join(", ")))
        })?;
        let values = c.as_f64().ok_or_else(|| anyhow::anyhow!("{label}: column `{name}` is not a float column"))?;
        Ok((values.to_vec(), c.unit.clone()))
    };
    let (mut names_m, mut names_r, mut units, mut samples, mut missing, mut rms, mut max_abs, mut spread) =
        (vec![], vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
    // Per pair: label, measured, reference on the measured times, difference.
    let mut plotted: Vec<[Vec<f64>; 3]> = Vec::new();
    let mut labels: Vec<String> = Vec::new();
    for (m_name, r_name) in pairs {
        let (m, m_unit) = column(measured, m_name, m_label)?;
        let (r, r_unit) = column(reference, r_name, r_label)?;
        let (Some(fm), Some(fr)) = (si_factor(&m_unit), si_factor(&r_unit)) else {
            return Err(UserError::new(format!(
                "cannot compare `{m_name}` [{m_unit}] with `{r_name}` [{r_unit}]: unknown unit"
            ))
            .hint(format!("known units: {}", crate::units::known_units().join(", ")))
            .into());
        };
        // The reference, in the measured column's unit, at the measured times.
        let mut on_time: Vec<f64> = time.iter().map(|&t| interpolate(r_time, &r, t) * fr / fm).collect();
        let mut m = m;
        if relative {
            if let Some(k) = (0..time.len()).find(|&k| m[k].is_finite() && on_time[k].is_finite()) {
                let (m0, r0) = (m[k], on_time[k]);
                m.iter_mut().for_each(|v| *v -= m0);
                on_time.iter_mut().for_each(|v| *v -= r0);
            }
        }
        let diff: Vec<f64> = m.iter().zip(&on_time).map(|(a, b)| a - b).collect();
        let known: Vec<f64> = diff.iter().copied().filter(|d| d.is_finite()).collect();
        let n = known.len();
        names_m.push(m_name.clone());
        names_r.push(r_name.clone());
        units.push(m_unit.clone());
        samples.push(n as i64);
        missing.push((diff.len() - n) as i64);
        rms.push(if n > 0 { (known.iter().map(|d| d * d).sum::<f64>() / n as f64).sqrt() } else { f64::NAN });
        max_abs.push(known.iter().fold(if n > 0 { 0.0 } else { f64::NAN }, |a: f64, d| a.max(d.abs())));
        let finite_ref: Vec<f64> = on_time.iter().copied().filter(|v| v.is_finite()).collect();
        spread.push(if finite_ref.is_empty() {
            f64::NAN
        } else {
            (finite_ref.iter().map(|v| v * v).sum::<f64>() / finite_ref.len() as f64).sqrt()
        });
        labels.push(format!("{m_name} [{m_unit}]"));
        plotted.push([m, on_time, diff]);
    }
    let count = |name: &str, description: &str, v: Vec<i64>| Column {
        name: name.into(),
        unit: String::new(),
        description: description.into(),
        data: ColumnData::I64(v),
    };
    let mut table = Table::new();
    table.push(super::text_column("measured", "measured column", names_m));
    table.push(super::text_column("reference", "reference column", names_r.clone()));
    table.push(super::text_column("unit", "unit of the errors (the measured column's)", units));
    table.push(count("samples", "measured samples with a reference value", samples));
    table.push(count("missing", "measured samples without one (lost, or outside the reference's time span)", missing));
    // Errors mix units across rows (mm, rad): the `unit` column says which; the field metadata cannot.
    table.push(Column::f64("rms_error", "", "RMS of measured − reference, in `unit`", rms));
    table.push(Column::f64("max_abs_error", "", "largest |measured − reference|, in `unit`", max_abs));
    table.push(Column::f64(
        "reference_rms",
        "",
        "RMS of the reference itself, in `unit` (the scale the error compares with)",
        spread,
    ));
    table.metadata.insert(
        "shakeflow.compare".into(),
        serde_json::json!({"relative": relative, "interpolation": "linear"}).to_string(),
    );

    let panels: Vec<Panel<'_>> = plotted
        .iter()
        .zip(&labels)
        .zip(&names_r)
        .flat_map(|(([m, r, d], label), r_name)| {
            [
                Panel {
                    title: format!("{label}: measured and reference ({r_name})"),
                    x_label: "time [s]".into(),
                    y_label: label.clone(),
                    series: vec![
                        Series::new("reference", time, r).model(),
                        Series::new("measured", time, m).observed(),
                    ],
                    markers: vec![],
                    log_y: false,
                    spans: Vec::new(),
                },
                Panel {
                    title: format!("{label}: measured − reference"),
                    x_label: "time [s]".into(),
                    y_label: label.clone(),
                    series: vec![Series::new("error", time, d)],
                    markers: vec![],
                    log_y: false,
                    spans: Vec::new(),
                },
            ]
        })
        .collect();
    let height = (380 * panels.len()).clamp(400, 2400) as u32;
    let png = render_png(title, &panels, 1100, height).map_err(anyhow::Error::msg)?;
    Ok((table, png))
}

/// The stage an input file comes from (`cpt_rolling.motion/…` → `cpt_rolling`), as titles name
/// it; a source file's label as it is.
fn stage_of(label: &str) -> &str {
    match label.split_once('.') {
        Some((stage, _)) if !stage.is_empty() && !stage.contains('/') => stage,
        _ => label,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_is_interpolated_and_converted() {
        let mut measured = Table::new();
        measured.push(Column::f64("time_s", "s", "", vec![0.0, 0.5, 1.0, 2.5]));
        measured.push(Column::f64("dx_mm", "mm", "", vec![0.0, 5.0, 10.0, 1.0]));
        let mut reference = Table::new();
        reference.push(Column::f64("time_s", "s", "", vec![0.0, 1.0, 2.0]));
        reference.push(Column::f64("x_m", "m", "", vec![0.0, 0.0101, 0.02]));
        let (errors, png) =
            compare(&measured, &reference, &[("dx_mm".into(), "x_m".into())], false, "m", "r", "cart against truth")
                .unwrap();
        assert_eq!(errors.column("samples").unwrap().data, ColumnData::I64(vec![3]));
        assert_eq!(errors.column("missing").unwrap().data, ColumnData::I64(vec![1]));
        let max = errors.f64_column("max_abs_error").unwrap()[0];
        assert!((max - 0.1).abs() < 1e-9, "{max}");
        assert!(png.starts_with(b"\x89PNG"));
    }

    #[test]
    fn titles_name_stages_not_files() {
        assert_eq!(stage_of("cpt_rolling.motion/data.parquet"), "cpt_rolling");
        assert_eq!(stage_of("load_cpt_truth.records/data.parquet"), "load_cpt_truth");
        assert_eq!(stage_of("../archive/truth.csv"), "../archive/truth.csv");
    }
}
