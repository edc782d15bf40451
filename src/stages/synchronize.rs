//! `synchronize`: put a second DAQ's records on the reference DAQ's clock.
//!
//! Per target record (e.g. one test's equipment DAQ), the reference records sharing its `join`
//! key (e.g. the same motion's floor records) are gathered; the target's sync channel is
//! resampled to the reference rate (band-limited, anti-aliased), its lag against the reference
//! channel found by FFT cross-correlation refined to sub-sample precision (or taken as
//! `known_lag_s`), and all the target's channels resampled straight onto the shifted reference
//! time base (one filter, not a resampling then a shift). The output record holds the reference channels
//! (prefixed by their partition, e.g. `floor4_ax_mps2`) and the aligned target channels over the
//! time both cover.

use super::error::StageError;
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use rayon::prelude::*;

use super::{partition_path, InputPart, Stage, StageContext};
use crate::pipeline::params::{self, ParamError, Params};
use crate::signal::resample_bandlimited::Resampler;
use crate::signal::sync::estimate_lag;
use crate::table::{Column, ColumnData, Table, TIME_COLUMN};

crate::stage_params! {
    /// The parameters of `synchronize`.
    pub struct SynchronizeParams {
        /// channel of the reference records the lag is measured against
        pub reference_channel: String [default = "ax_mps2"],
        // `key=value` or empty, read by `reference_select`.
        /// which reference record is the clock reference when several share the join key, as key=value (e.g. floor=5)
        pub reference_select: String [default = ""],
        /// channel of the target records that sees the same motion as the reference channel (e.g. a DAQ2 copy of a
        /// floor channel)
        pub target_channel: String [],
        /// partition key that pairs target and reference records
        pub join: String [default = "motion"],
        /// use this lag instead of estimating it (positive: target lags reference)
        pub known_lag_s: Option<f64> [default = null, unit = "s", range = (-3600.0, 3600.0)],
        /// largest lag searched, either sign
        pub max_lag_s: f64 [default = 5.0, unit = "s", range = (0.0, 3600.0)],
        #[flatten]
        pub mcap: super::Mcap,
    }
}

super::declare_stage! {
    /// Align a second DAQ with the reference DAQ: band-limited resampling, FFT cross-correlation lag (sub-sample),
    /// shift onto the reference clock.
    pub struct Synchronize: "synchronize", version 4, reads Datasets, params SynchronizeParams;
    outputs {
        /// reference channels and aligned target channels on the reference time base
        "records": TimeSeries => Records,
        /// estimated (or given) lag per target record: channel, lag_s, lag_uncertainty_s, correlation
        "lags": Table,
    }
    examples {
        /// a second DAQ (here the same record loaded again, so the lag found is 0) put on the reference's clock
        super::RINALDI => "\
daq2:
  type: load
  inputs: [rinaldi]
synchronize:
  type: synchronize
  inputs: [load, daq2]
  params:
    target_channel: ax_mps2
    join: station
",
    }
}

impl Stage for Synchronize {
    super::info_and_check_params!(SynchronizeParams);

    /// `reference_select` is checked with the pipeline, so `validate` points at its line.
    fn check(&self, params: &Params, _base_dir: &Path) -> Result<(), ParamError> {
        let p: SynchronizeParams = params::typed(params)?;
        reference_select(&p.reference_select).map(|_| ()).map_err(|e| ParamError {
            key: Some("reference_select".into()),
            message: e.to_string(),
            hint: "name a partition of the reference records, e.g. `floor=5`".into(),
        })
    }

    fn work_units(&self) -> super::WorkUnits {
        super::WorkUnits::PerRecordOf { primary: 1 }
    }

    /// A target record reads the reference records that share its `join` key, found in an index
    /// of the reference by that key (built once for all target records).
    fn companions(&self, params: &Params, primaries: &[InputPart], other: &super::StageInput) -> Vec<Vec<InputPart>> {
        let p: SynchronizeParams = params::typed(params).expect("the planner checked the parameters (`check_params`)");
        let mut by_key: HashMap<&str, Vec<&InputPart>> = HashMap::new();
        for part in other.parts() {
            if let Some(key) = partition_value(part, &p.join) {
                by_key.entry(key).or_default().push(part);
            }
        }
        primaries
            .iter()
            .map(|primary| match partition_value(primary, &p.join).and_then(|key| by_key.get(key)) {
                Some(matched) => matched.iter().map(|&r| r.clone()).collect(),
                // A target record the reference lacks fails; with every reference record its
                // error can name the values the reference has.
                None => other.parts().to_vec(),
            })
            .collect()
    }

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let [reference, target] = ctx.inputs else {
            anyhow::bail!("`synchronize` reads exactly two inputs: [reference, target] (e.g. [baseline_floors, baseline_equipment])");
        };
        let p: SynchronizeParams = params::typed(ctx.params)?;
        let join = p.join.as_str();
        let select = reference_select(&p.reference_select).map_err(anyhow::Error::msg)?;
        ctx.sink.set_total(target.parts().len());
        target.parts().par_iter().try_for_each(|part| {
            let key = partition_value(part, join).ok_or_else(|| {
                anyhow::anyhow!("target record `{}` has no partition key `{join}` (set `join`)", partition_path(&part.partition))
            })?;
            let group: Vec<&InputPart> = reference.parts().iter().filter(|r| partition_value(r, join) == Some(key)).collect();
            let clock: Vec<&&InputPart> = group
                .iter()
                .filter(|r| select.is_none_or(|(k, v)| partition_value(r, k) == Some(v)))
                .collect();
            let [clock] = clock.as_slice() else {
                let matched = format!(
                    "{} reference records match `{join}={key}`{}",
                    clock.len(),
                    select.map(|(k, v)| format!(" and `{k}={v}`")).unwrap_or_default()
                );
                if group.is_empty() {
                    // The target has a record the reference lacks: most often a file missing from
                    // the archive, not a wrong selection.
                    anyhow::bail!(
                        "{matched}: the reference input has no record for `{join}={key}` at all, though the target has one; is its file missing? (the reference's `{join}` values: {})",
                        values_of(reference.parts(), join).join(", ")
                    );
                }
                anyhow::bail!("{matched}; exactly one must be the clock reference (set `reference_select`)");
            };
            let references: Vec<(String, Arc<Table>)> = group
                .iter()
                .map(|r| Ok((prefix(r, join), ctx.read_table(r)?)))
                .collect::<anyhow::Result<_>>()?;
            let clock_table = &references[group.iter().position(|r| std::ptr::eq(*r, **clock)).expect("clock is in the group")].1;
            let target_table = ctx.read_table(part)?;
            let (aligned, lag) = align(clock_table, &references, &target_table, &p)
                .map_err(|e| anyhow::anyhow!("{} (`{join}={key}`): {e}", part.label))?;
            let mut aligned = aligned;
            aligned.metadata.extend(super::record_provenance(part));
            ctx.sink.write("lags", &part.partition, lag)?;
            ctx.sink.write("records", &part.partition, aligned)
        })
    }
}

/// `reference_select` as (key, value); `None` when it is empty (a single reference record).
fn reference_select(select: &str) -> Result<Option<(&str, &str)>, StageError> {
    if select.is_empty() {
        return Ok(None);
    }
    match select.split_once('=') {
        Some((key, value)) if !key.is_empty() && !value.is_empty() => Ok(Some((key, value))),
        _ => Err(StageError::Record(format!("`reference_select` must look like key=value, not `{select}`"))),
    }
}

fn partition_value<'a>(part: &'a InputPart, key: &str) -> Option<&'a str> {
    part.partition.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
}

/// The distinct values of `key` among the parts, sorted.
fn values_of<'a>(parts: &'a [InputPart], key: &str) -> Vec<&'a str> {
    let values: std::collections::BTreeSet<&str> = parts.iter().filter_map(|p| partition_value(p, key)).collect();
    values.into_iter().collect()
}

/// Column prefix for a reference record: its partition minus the join key (`floor=4` → `floor4`).
fn prefix(part: &InputPart, join: &str) -> String {
    part.partition.iter().filter(|(k, _)| k != join).map(|(k, v)| format!("{k}{v}")).collect::<Vec<_>>().join("_")
}

fn sample_rate(table: &Table) -> Result<(f64, f64), StageError> {
    let time = table.f64_column(TIME_COLUMN).ok_or_else(|| StageError::Record("no time_s column".into()))?;
    if time.len() < 2 {
        return Err(StageError::Record("fewer than 2 samples".into()));
    }
    Ok((time[0], crate::table::sample_rate(time)))
}

/// The pure part: aligned record and its one-row lag table.
fn align(
    clock: &Table,
    references: &[(String, Arc<Table>)],
    target: &Table,
    p: &SynchronizeParams,
) -> Result<(Table, Table), StageError> {
    let (reference_channel, target_channel) = (p.reference_channel.as_str(), p.target_channel.as_str());
    let (t0, fs) = sample_rate(clock)?;
    let (_, fs_target) = sample_rate(target)?;
    let reference = clock.f64_column(reference_channel).ok_or_else(|| {
        StageError::Record(format!(
            "the clock reference has no float column `{reference_channel}`; columns: {}",
            clock.column_names().join(", ")
        ))
    })?;
    let float_columns: Vec<(&Column, &[f64])> =
        target.columns.iter().filter(|c| c.name != TIME_COLUMN).filter_map(|c| c.as_f64().map(|v| (c, v))).collect();
    let sync_position = float_columns.iter().position(|(c, _)| c.name == target_channel).ok_or_else(|| {
        StageError::Record(format!(
            "the target has no float channel `{target_channel}` (other than `{TIME_COLUMN}`); columns: {}",
            target.column_names().join(", ")
        ))
    })?;
    let values: Vec<&[f64]> = float_columns.iter().map(|(_, v)| *v).collect();
    let resampler = Resampler::new(fs_target, fs);
    let n_target = resampler.output_len(values[0].len());
    let (lag_s, uncertainty, correlation, method) = match p.known_lag_s {
        Some(lag) => (lag, 0.0, None, "known"),
        None => {
            let sync = resampler.resample(values[sync_position]);
            let e = estimate_lag(reference, &sync, fs, Some(p.max_lag_s))?;
            (e.lag_s, e.uncertainty_s, Some(e.correlation), "estimated")
        }
    };
    // Aligned target on the reference grid: target value at reference time t is target(t + lag),
    // every channel resampled straight at the shifted times (one filter, weights shared).
    let target_columns: Vec<(&Column, Vec<f64>)> =
        float_columns.iter().map(|(c, _)| *c).zip(resampler.grid(&values, lag_s, n_target)).collect();
    let n_reference = references.iter().map(|(_, t)| t.num_rows()).min().unwrap_or(0);
    let valid = |k: usize| target_columns.iter().all(|(_, v)| k < v.len() && v[k].is_finite());
    let first = (0..n_reference)
        .find(|&k| valid(k))
        .ok_or_else(|| StageError::Record("the target and reference records do not overlap in time".into()))?;
    let last = (first..n_reference).take_while(|&k| valid(k)).last().expect("first is valid");
    let range = first..last + 1;

    let mut out = Table::new();
    out.push(Column::f64(
        TIME_COLUMN,
        "s",
        "time on the reference clock",
        range.clone().map(|k| t0 + k as f64 / fs).collect(),
    ));
    for (prefix, table) in references {
        for c in table.columns.iter().filter(|c| c.name != TIME_COLUMN) {
            if let ColumnData::F64(v) = &c.data {
                let clashes = target_columns.iter().any(|(t, _)| t.name == c.name);
                let name = match (prefix.is_empty(), clashes) {
                    (false, _) => format!("{prefix}_{}", c.name),
                    // One reference record with the target's own column names: keep both apart.
                    (true, true) => format!("reference_{}", c.name),
                    (true, false) => c.name.clone(),
                };
                out.push(Column {
                    name,
                    unit: c.unit.clone(),
                    description: c.description.clone(),
                    data: ColumnData::F64(v[range.clone()].to_vec()),
                });
            }
        }
    }
    for (c, mut v) in target_columns {
        let description =
            format!("{} (on the reference clock: resampled to {fs} Hz, shifted by the lag)", c.description);
        v.truncate(range.end);
        v.drain(..range.start);
        out.push(Column { name: c.name.clone(), unit: c.unit.clone(), description, data: ColumnData::F64(v) });
    }
    out.metadata = target.metadata.clone();
    out.metadata.insert(
        "shakeflow.synchronize".into(),
        serde_json::json!({"lag_s": lag_s, "method": method, "reference_rate_hz": fs, "target_rate_hz": fs_target})
            .to_string(),
    );

    let mut lags = Table::new();
    lags.push(Column {
        name: "channel".into(),
        unit: String::new(),
        description: "target channel the lag was measured on".into(),
        data: ColumnData::Str(vec![target_channel.into()]),
    });
    lags.push(Column {
        name: "reference_channel".into(),
        unit: String::new(),
        description: "reference channel".into(),
        data: ColumnData::Str(vec![reference_channel.into()]),
    });
    lags.push(Column::f64(
        "lag_s",
        "s",
        "lag of the target behind the reference: target(t) = reference(t - lag)",
        vec![lag_s],
    ));
    lags.push(Column::f64(
        "lag_uncertainty_s",
        "s",
        "one-sigma uncertainty of lag_s (0 when given)",
        vec![uncertainty],
    ));
    lags.push(Column {
        name: "correlation".into(),
        unit: String::new(),
        description: "normalised cross-correlation at the lag (null when the lag was given)".into(),
        data: ColumnData::OptF64(vec![correlation]),
    });
    lags.push(Column {
        name: "method".into(),
        unit: String::new(),
        description: "estimated or known".into(),
        data: ColumnData::Str(vec![method.into()]),
    });
    lags.push(Column::f64("target_rate_hz", "Hz", "sample rate of the target before resampling", vec![fs_target]));
    lags.push(Column::f64("reference_rate_hz", "Hz", "sample rate of the common time base", vec![fs]));
    Ok((out, lags))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two wave packets (2 Hz and 3.3 Hz under Gaussian envelopes): band-limited, with one
    /// cross-correlation peak.
    fn motion(t: f64) -> f64 {
        let packet = |f: f64, centre: f64, width: f64| {
            (2.0 * std::f64::consts::PI * f * t).sin() * (-((t - centre) / width).powi(2)).exp()
        };
        packet(2.0, 5.0, 1.0) + 0.5 * packet(3.3, 7.0, 0.7)
    }

    /// The target DAQ's lag behind the reference, in seconds.
    const LAG: f64 = 0.37;

    fn late(t: f64) -> f64 {
        motion(t - LAG)
    }

    fn top(t: f64) -> f64 {
        2.0 * late(t)
    }

    type Channel = (&'static str, fn(f64) -> f64);

    fn record(rate: f64, seconds: f64, channels: &[Channel]) -> Table {
        let n = (rate * seconds) as usize;
        let time: Vec<f64> = (0..n).map(|k| k as f64 / rate).collect();
        let mut t = Table::new();
        for (name, f) in channels {
            t.push(Column::f64(name, "m/s^2", "d", time.iter().map(|&x| f(x)).collect()));
        }
        t.push(Column::f64(TIME_COLUMN, "s", "d", time));
        t
    }

    fn params(known_lag_s: Option<f64>) -> SynchronizeParams {
        SynchronizeParams {
            reference_channel: "ax_mps2".into(),
            reference_select: String::new(),
            target_channel: "sync_ax_mps2".into(),
            join: "motion".into(),
            known_lag_s,
            max_lag_s: 2.0,
            mcap: super::super::Mcap { mcap: false },
        }
    }

    /// A 100 Hz target recording the 200 Hz reference's motion 0.37 s late: the lag is found to
    /// a millisecond, and the target's channels land on the reference clock (its copy of the
    /// motion then matches the reference) beside the reference's own columns.
    #[test]
    fn a_late_slower_daq_is_put_on_the_reference_clock() {
        let lag = LAG;
        let reference_channels: [Channel; 1] = [("ax_mps2", motion)];
        let target_channels: [Channel; 2] = [("sync_ax_mps2", late), ("top_ax_mps2", top)];
        let reference = Arc::new(record(200.0, 12.0, &reference_channels));
        let target = record(100.0, 12.0, &target_channels);
        let references = [(String::new(), reference.clone())];
        let (aligned, lags) = align(&reference, &references, &target, &params(None)).unwrap();
        let found = lags.f64_column("lag_s").unwrap()[0];
        assert!((found - lag).abs() < 1e-3, "lag {found}, made {lag}");
        assert_eq!(aligned.column_names(), [TIME_COLUMN, "ax_mps2", "sync_ax_mps2", "top_ax_mps2"]);
        let (time, synced) = (aligned.f64_column(TIME_COLUMN).unwrap(), aligned.f64_column("sync_ax_mps2").unwrap());
        let worst = time.iter().zip(synced).map(|(&t, &v)| (v - motion(t)).abs()).fold(0.0, f64::max);
        assert!(worst < 0.01, "aligned target off the reference by {worst} m/s^2");
        // A lag given is used as it is, and said to be.
        let (_, lags) = align(&reference, &references, &target, &params(Some(0.3))).unwrap();
        assert_eq!(lags.f64_column("lag_s").unwrap()[0], 0.3);
    }

    #[test]
    fn reference_select_is_key_equals_value() {
        assert_eq!(reference_select("").unwrap(), None);
        assert_eq!(reference_select("floor=5").unwrap(), Some(("floor", "5")));
        let refused = reference_select("floor5").unwrap_err().to_string();
        assert!(refused.contains("`reference_select` must look like key=value, not `floor5`"), "{refused}");
    }
}
