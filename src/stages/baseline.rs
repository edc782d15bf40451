//! `baseline`: subtract a least-squares polynomial in time (default cubic, as the study did)
//! from each channel, keeping peaks (no filtering). Fitted coefficients go into the metadata.

use rayon::prelude::*;
use serde_json::json;

use super::{Stage, StageContext};
use crate::io::records::printable;
use crate::pipeline::params::{self, Params};
use crate::signal::baseline::PolynomialBasis;
use crate::table::{Column, ColumnData, Table, TIME_COLUMN};

crate::stage_params! {
    /// The parameters of `baseline`.
    pub struct BaselineParams {
        /// polynomial order (3: the study's cubic; 1: linear detrend; 0: mean)
        pub order: usize [default = 3, range = (0.0, 9.0)],
        /// channels to correct; empty: every float column except time_s
        pub columns: Vec<String> [default = []],
        #[flatten]
        pub mcap: super::Mcap,
    }
}

super::declare_stage! {
    /// Remove a least-squares polynomial trend (default cubic) from each channel; no filtering, peaks kept.
    pub struct Baseline: "baseline", version 5, reads Datasets, params BaselineParams;
    outputs {
        /// the input tables with each selected channel baseline-corrected
        "records": TimeSeries,
    }
    examples {
        /// the study's cubic baseline removed from every channel of the loaded records
        super::RINALDI => "\
baseline:
  type: baseline
  inputs: [load]
  params:
    order: 3
",
    }
}

impl Stage for Baseline {
    super::info_and_check_params!(BaselineParams);

    fn work_units(&self) -> super::WorkUnits {
        super::WorkUnits::EachRecord
    }

    /// The records keep their columns; every column named in `columns` must be one of them.
    fn output_columns(&self, params: &Params, input: Option<&[String]>) -> super::ColumnCheck {
        let Some(input) = input else { return (None, Vec::new()) };
        let p: BaselineParams = match params::typed(params) {
            Ok(p) => p,
            Err(e) => return (None, vec![e]),
        };
        let errors = p.columns.iter().filter_map(|c| super::require_column("columns", c, input).err());
        (Some(input.to_vec()), errors.collect())
    }

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let p: BaselineParams = params::typed(ctx.params)?;
        let (order, wanted) = (p.order, p.columns);
        let parts: Vec<_> = ctx.inputs.iter().flat_map(|i| i.parts()).collect();
        ctx.sink.set_total(parts.len());
        parts.par_iter().try_for_each(|part| {
            let table = ctx.read_table(part)?;
            let mut corrected = correct(&table, order, &wanted)
                .map_err(|e| anyhow::anyhow!("{}: {}", part.label, printable(&e.to_string())))?;
            corrected.metadata.extend(super::record_provenance(part));
            ctx.sink.write("records", &part.partition, corrected)
        })
    }
}

/// Why [`correct`] refuses a record (the stage prefixes the record's label).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BaselineError {
    #[error("the table has no `time_s` column")]
    NoTime,
    /// Too few samples for the order (`column`: a channel shorter than its record).
    #[error("{}{samples} samples are too few for an order-{order} baseline", column.as_ref().map_or(String::new(), |c| format!("column `{c}`: ")))]
    TooFew { column: Option<String>, samples: usize, order: usize },
    #[error("column `{0}` is not a float column")]
    NotFloat(String),
    #[error("no column `{name}`; columns: {columns}")]
    NoColumn { name: String, columns: String },
    #[error("`time_s` has a non-finite value at sample {sample}")]
    NonFiniteTime { sample: usize },
    #[error("column `{column}` has a non-finite value at sample {sample}; load it with `gaps: interpolate`")]
    NonFinite { column: String, sample: usize },
    #[error("column `{column}`: the order-{order} baseline fit is not finite: its values reach {peak:e} {unit}, beyond what a least-squares fit can square and sum")]
    FitNotFinite { column: String, order: usize, peak: f64, unit: String },
    #[error("column `{column}` has a missing value at sample {missing} followed by values (sample {next}): a baseline needs the channel's samples without gaps")]
    Gap { column: String, missing: usize, next: usize },
}

/// The pure part of the stage: a corrected copy of `table` with its fits in the metadata.
pub fn correct(table: &Table, order: usize, wanted: &[String]) -> Result<Table, BaselineError> {
    let time = table.f64_column(TIME_COLUMN).ok_or(BaselineError::NoTime)?;
    if time.len() <= order {
        return Err(BaselineError::TooFew { column: None, samples: time.len(), order });
    }
    for name in wanted {
        match table.column(name) {
            Some(c) if matches!(c.data, ColumnData::F64(_) | ColumnData::OptF64(_)) => {}
            Some(_) => return Err(BaselineError::NotFloat(name.clone())),
            None => {
                return Err(BaselineError::NoColumn { name: name.clone(), columns: table.column_names().join(", ") })
            }
        }
    }
    if let Some(i) = time.iter().position(|t| !t.is_finite()) {
        return Err(BaselineError::NonFiniteTime { sample: i + 1 });
    }
    let basis = PolynomialBasis::new(time, order);
    let mut out = Table { columns: Vec::new(), metadata: table.metadata.clone() };
    let mut columns = Vec::with_capacity(table.columns.len());
    let mut fits = serde_json::Map::new();
    for column in &table.columns {
        let selected = column.name != TIME_COLUMN
            && matches!(column.data, ColumnData::F64(_) | ColumnData::OptF64(_))
            && (wanted.is_empty() || wanted.contains(&column.name));
        if !selected {
            columns.push(column.clone());
            continue;
        }
        // A channel shorter than its record (`load` pads it with nulls past its end) is fitted
        // and corrected over its own samples; its nulls stay.
        let (values, padded) = match &column.data {
            ColumnData::F64(v) => (std::borrow::Cow::Borrowed(v.as_slice()), false),
            ColumnData::OptF64(v) => (std::borrow::Cow::Owned(own_samples(&column.name, v)?), true),
            _ => unreachable!("selected columns are float"),
        };
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(BaselineError::NonFinite { column: column.name.clone(), sample: i + 1 });
        }
        let shorter;
        let basis = match values.len() {
            n if n == time.len() => &basis,
            n if n > order => {
                shorter = PolynomialBasis::new(&time[..n], order);
                &shorter
            }
            n => return Err(BaselineError::TooFew { column: Some(column.name.clone()), samples: n, order }),
        };
        let (corrected, fit) = basis.remove(&values);
        if corrected.iter().chain(&fit.coefficients).any(|v| !v.is_finite()) {
            let peak = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            return Err(BaselineError::FitNotFinite {
                column: column.name.clone(),
                order,
                peak,
                unit: column.unit.clone(),
            });
        }
        let rms_removed =
            (values.iter().zip(&corrected).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / values.len() as f64).sqrt();
        let mut fit_json = json!({
            "polyfit_coefficients": fit.monomial_coefficients(),
            "scaled_coefficients": fit.coefficients,
            "center_s": fit.center,
            "half_span_s": fit.half_span,
            "rms_removed": rms_removed,
            "unit": column.unit,
        });
        if padded {
            fit_json["samples"] = json!(values.len());
        }
        fits.insert(column.name.clone(), fit_json);
        let data = match padded {
            false => ColumnData::F64(corrected),
            true => {
                let mut kept: Vec<Option<f64>> = corrected.into_iter().map(Some).collect();
                kept.resize(time.len(), None);
                ColumnData::OptF64(kept)
            }
        };
        columns.push(Column {
            name: column.name.clone(),
            unit: column.unit.clone(),
            description: format!("{} (order-{order} polynomial baseline removed)", column.description),
            data,
        });
    }
    out.extend(columns);
    out.metadata.insert(
        "shakeflow.baseline".into(),
        json!({"order": order, "basis": "polyfit_coefficients: numpy.polyfit order (highest power first, t in s)", "fits": fits}).to_string(),
    );
    Ok(out)
}

/// A nullable channel's own samples: the values before its first null, which must be the
/// padding past its end (no value after it).
fn own_samples(name: &str, values: &[Option<f64>]) -> Result<Vec<f64>, BaselineError> {
    let n = values.iter().position(Option::is_none).unwrap_or(values.len());
    if let Some(k) = values[n..].iter().position(Option::is_some) {
        return Err(BaselineError::Gap { column: name.to_string(), missing: n + 1, next: n + k + 1 });
    }
    Ok(values[..n].iter().map(|v| v.expect("before the first null")).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(values: Vec<f64>) -> Table {
        let mut t = Table::new();
        t.push(Column::f64(TIME_COLUMN, "s", "", (0..values.len()).map(|k| k as f64 * 0.01).collect()));
        t.push(Column::f64("ax_mps2", "m/s^2", "", values));
        t
    }

    /// 1e308 m/s² overflows the fit's sums of squares: it used to give a table of NaN.
    #[test]
    fn values_too_large_to_fit_are_an_error_not_nan() {
        let mut values: Vec<f64> = (0..200).map(|k| (k as f64 * 0.3).sin()).collect();
        values[17] = 1e308;
        let e = correct(&table(values), 3, &[]).unwrap_err().to_string();
        assert!(e.contains("column `ax_mps2`: the order-3 baseline fit is not finite"), "{e}");
        assert!(e.contains("1e308 m/s^2"), "{e}");
        let fine = correct(&table((0..200).map(|k| (k as f64 * 0.3).sin() * 1e150).collect()), 3, &[]).unwrap();
        assert!(fine.f64_column("ax_mps2").unwrap().iter().all(|v| v.is_finite()));
    }

    /// A channel 50 samples shorter than its record (null past its end, as `load` pads it): a
    /// cubic trend over its own 150 samples is removed exactly there, the nulls stay; a column
    /// with a value after a null is refused, naming both samples.
    #[test]
    fn a_null_padded_channel_is_corrected_over_its_own_samples() {
        let mut t = table((0..200).map(|k| (k as f64 * 0.3).sin()).collect());
        let trend = |k: usize| {
            let x = k as f64 * 0.01;
            0.4 - 2.0 * x + 0.7 * x * x - 0.3 * x * x * x
        };
        let padded: Vec<Option<f64>> = (0..200).map(|k| (k < 150).then(|| trend(k))).collect();
        t.push(Column {
            name: "az_mps2".into(),
            unit: "m/s^2".into(),
            description: String::new(),
            data: ColumnData::OptF64(padded.clone()),
        });
        let out = correct(&t, 3, &[]).unwrap();
        let ColumnData::OptF64(az) = &out.column("az_mps2").unwrap().data else { panic!("az stays nullable") };
        assert!(az[..150].iter().all(|v| v.is_some_and(|v| v.abs() < 1e-12)), "{az:?}");
        assert!(az[150..].iter().all(Option::is_none));
        assert!(out.metadata["shakeflow.baseline"].contains("\"samples\":150"));
        let mut gap = padded;
        gap[160] = Some(1.0);
        t.columns[2].data = ColumnData::OptF64(gap);
        let e = correct(&t, 3, &[]).unwrap_err().to_string();
        assert!(
            e.contains("column `az_mps2` has a missing value at sample 151 followed by values (sample 161)"),
            "{e}"
        );
    }

    /// The refusals' messages, as users read them after the record's label.
    #[test]
    fn refusals_say_what_is_wrong_and_where() {
        let t = table(vec![0.0, 1.0, f64::NAN, 3.0, 4.0]);
        assert_eq!(
            correct(&t, 3, &[]).unwrap_err().to_string(),
            "column `ax_mps2` has a non-finite value at sample 3; load it with `gaps: interpolate`"
        );
        assert_eq!(
            correct(&table(vec![0.0; 3]), 3, &[]).unwrap_err().to_string(),
            "3 samples are too few for an order-3 baseline"
        );
        assert_eq!(
            correct(&table(vec![0.0; 9]), 1, &["az_mps2".into()]).unwrap_err().to_string(),
            "no column `az_mps2`; columns: time_s, ax_mps2"
        );
        assert_eq!(correct(&Table::new(), 1, &[]).unwrap_err().to_string(), "the table has no `time_s` column");
        let mut short = table(vec![0.0; 9]);
        short.push(Column {
            name: "az_mps2".into(),
            unit: String::new(),
            description: String::new(),
            data: ColumnData::OptF64(vec![Some(1.0), None, None, None, None, None, None, None, None]),
        });
        assert_eq!(
            correct(&short, 1, &[]).unwrap_err().to_string(),
            "column `az_mps2`: 1 samples are too few for an order-1 baseline"
        );
    }

    #[test]
    fn a_non_finite_time_is_an_error() {
        let mut t = table(vec![0.0; 10]);
        if let ColumnData::F64(time) = &mut t.columns[0].data {
            time[4] = f64::INFINITY;
        }
        assert!(correct(&t, 1, &[]).unwrap_err().to_string().contains("`time_s` has a non-finite value at sample 5"));
    }
}
