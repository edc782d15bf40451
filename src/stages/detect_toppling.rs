//! `detect_toppling`: find the toppling impact in a top accelerometer alone (the study did it
//! by eye): a spike far above the preceding shaking (STA/LTA on the signal's difference),
//! confirmed by a lasting drop of the amplitude to about the floor's vertical level.

use super::error::{float_column, StageError};
use rayon::prelude::*;
use std::path::Path;

use super::{split_pair, Stage, StageContext};
use crate::pipeline::params::{self, Params};
use crate::signal::toppling::{detect_toppling, detect_toppling_on, DetectOptions, TimeBase};
use crate::summary;
use crate::table::{Column, ColumnData, Table, TIME_COLUMN};

crate::stage_params! {
    /// The parameters of `detect_toppling`.
    pub struct DetectTopplingParams {
        // `top` or `top -> floor vertical`, read by `split_pair`.
        /// top accelerometer columns, each optionally `-> floor vertical column` for the cross-check
        pub channels: Vec<String> [],
        /// trigger level of sqrt(STA/LTA) on the signal's 5 ms difference
        pub sta_lta_on: f64 [default = 8.0, range = (1.0, 1e6)],
        /// post-impact RMS must stay below this fraction of the pre-impact RMS
        pub drop_ratio: f64 [default = 0.35, range = (0.0, 1.0)],
    }
}

super::declare_stage! {
    /// Toppling impacts from top accelerometers: STA/LTA spike confirmed by a lasting amplitude drop; optional
    /// floor-vertical cross-check.
    pub struct DetectToppling: "detect_toppling", version 2, reads Datasets, params DetectTopplingParams;
    outputs {
        /// per channel: toppled, impact_time_s, peak_mps2, confidence, and why
        "events": Table => Toppling,
    }
    examples {
        /// the top accelerometers of the shared cases: the four rocking units that overturn, at the times their truth
        /// files give, and none of the four carts on casters
        TOP_ACCELEROMETERS => "\
detect_toppling:
  type: detect_toppling
  inputs: [load]
  params:
    channels: [top_ax_mps2]
",
    }
}

/// The top accelerometers of the shared rocking (`demo`) and rolling (`rolling_demo`) cases.
const TOP_ACCELEROMETERS: super::ExampleData = super::ExampleData {
    what: "the shared cases' top accelerometers",
    head: "\
inputs:
  tops:
    description: a unit's top accelerometer (in-plane, 200 Hz) in each shared case, rocking units and carts
    format: csv
    path: ../shared/cases/{set}/{case}/observed_accel.csv
    time_column: time_s
    columns:
      top_ax_mps2: {column: top_ax_mps2, unit: m/s^2}
stages:
  load:
    type: load
    inputs: [tops]
",
};

impl Stage for DetectToppling {
    super::info_and_check_params!(DetectTopplingParams);

    fn work_units(&self) -> super::WorkUnits {
        super::WorkUnits::EachRecord
    }

    /// Every channel (and floor vertical after `->`) must be a column of the input records.
    fn output_columns(&self, params: &Params, input: Option<&[String]>) -> super::ColumnCheck {
        let Some(input) = input else { return (None, Vec::new()) };
        let p: DetectTopplingParams = match params::typed(params) {
            Ok(p) => p,
            Err(e) => return (None, vec![e]),
        };
        let mut errors = Vec::new();
        for channel in p.channels {
            let (top, floor) = split_pair(&channel);
            errors.extend(
                std::iter::once(top).chain(floor).filter_map(|c| super::require_column("channels", &c, input).err()),
            );
        }
        (None, errors)
    }

    fn summary(&self, stage_dir: &Path) -> Option<String> {
        summary_line(stage_dir).ok()
    }

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let p: DetectTopplingParams = params::typed(ctx.params)?;
        let channels: Vec<(String, Option<String>)> = p.channels.iter().map(|c| split_pair(c)).collect();
        let opts = DetectOptions { sta_lta_on: p.sta_lta_on, drop_ratio: p.drop_ratio, ..DetectOptions::default() };
        let parts: Vec<_> = ctx.inputs.iter().flat_map(|i| i.parts()).collect();
        ctx.sink.set_total(parts.len());
        parts.par_iter().try_for_each(|part| {
            let table = ctx.read_table(part)?;
            let mut events = detect(&table, &channels, &opts).map_err(|e| anyhow::anyhow!("{}: {e}", part.label))?;
            events.metadata.extend(super::record_provenance(part));
            ctx.sink.write("events", &part.partition, events)
        })
    }
}

fn detect(table: &Table, channels: &[(String, Option<String>)], opts: &DetectOptions) -> Result<Table, StageError> {
    let time = table.f64_column(TIME_COLUMN).ok_or_else(|| StageError::Record("no time_s column".into()))?;
    let column = |name: &str| float_column(table, name);
    let finite = |v: f64| v.is_finite().then_some(v);
    let (mut names, mut toppled, mut times, mut peaks, mut confidence, mut pre, mut post, mut why) =
        (vec![], vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
    // The time column is prepared once for all channels, which then run in parallel, so the
    // stage's last record is shared by both cores instead of finishing on one.
    let base = TimeBase::new(time);
    // Columns are looked up in order first, so a missing one is always the first one named.
    let inputs = channels
        .iter()
        .map(|(top, vertical)| {
            let vertical = vertical.as_deref().map(column).transpose()?;
            Ok((column(top)?, vertical))
        })
        .collect::<Result<Vec<_>, StageError>>()?;
    let detected: Vec<_> = inputs
        .par_iter()
        .map(|&(top_ax, vertical)| match &base {
            Ok(base) => detect_toppling_on(base, top_ax, vertical, opts),
            // Not analysable: the event that says why.
            Err(_) => detect_toppling(time, top_ax, vertical, opts),
        })
        .collect();
    for ((top, _), event) in channels.iter().zip(detected) {
        names.push(top.clone());
        toppled.push(event.toppled);
        times.push(event.impact_time_s);
        peaks.push(event.peak_mps2);
        confidence.push(event.confidence);
        pre.push(finite(event.pre_rms_mps2));
        post.push(finite(event.post_rms_mps2));
        why.push(event.explanation);
    }
    let mut events = Table::new();
    events.push(Column {
        name: "channel".into(),
        unit: String::new(),
        description: "top accelerometer channel".into(),
        data: ColumnData::Str(names),
    });
    events.push(Column {
        name: "toppled".into(),
        unit: String::new(),
        description: "a toppling impact was found and confirmed".into(),
        data: ColumnData::Bool(toppled),
    });
    events.push(Column {
        name: "impact_time_s".into(),
        unit: "s".into(),
        description: "onset of the impact spike (null when not toppled)".into(),
        data: ColumnData::OptF64(times),
    });
    events.push(Column::f64(
        "peak_mps2",
        "m/s^2",
        "peak |acceleration| of the impact (of the record when not toppled)",
        peaks,
    ));
    events.push(Column::f64("confidence", "", "0..1: confidence in the verdict (toppled or not)", confidence));
    events.push(Column {
        name: "pre_rms_mps2".into(),
        unit: "m/s^2".into(),
        description: "detrended RMS before the (candidate) impact".into(),
        data: ColumnData::OptF64(pre),
    });
    events.push(Column {
        name: "post_rms_mps2".into(),
        unit: "m/s^2".into(),
        description: "detrended RMS after the (candidate) impact; null when the record ends too soon".into(),
        data: ColumnData::OptF64(post),
    });
    events.push(Column {
        name: "explanation".into(),
        unit: String::new(),
        description: "why, in words".into(),
        data: ColumnData::Str(why),
    });
    Ok(events)
}

/// The line `shakeflow run` prints: "toppled: 3 of 48 channel records (FB-4 ps2_top_ax, …)"
fn summary_line(dir: &Path) -> anyhow::Result<String> {
    let events = summary::read(dir, "events")?;
    let (records, channels) = (events.record_labels()?, summary::texts(&events.frame, "channel")?);
    let toppled = summary::flags(&events.frame, "toppled")?;
    let which: Vec<String> = (0..toppled.len())
        .filter(|&i| toppled[i])
        .map(|i| if records[i].is_empty() { channels[i].clone() } else { format!("{} {}", records[i], channels[i]) })
        .collect();
    let mut line = format!("toppling detected in {} of {} channel records", which.len(), toppled.len());
    if !which.is_empty() {
        line += &format!(" ({})", summary::some_of(&which, 6));
    }
    Ok(line)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A shared case's column (`../shared/cases/<set>/<case>/<file>`), read here with a plain split.
    fn shared_csv(set: &str, case: &str, file: &str) -> Vec<(String, Vec<f64>)> {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../shared/cases/{set}/{case}/{file}"));
        let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut lines = text.lines();
        let mut columns: Vec<(String, Vec<f64>)> =
            lines.next().unwrap().split(',').map(|name| (name.to_string(), vec![])).collect();
        for line in lines.filter(|l| !l.is_empty()) {
            for (column, field) in columns.iter_mut().zip(line.split(',')) {
                column.1.push(field.trim().parse().unwrap());
            }
        }
        columns
    }

    fn events(set: &str, case: &str) -> Table {
        let mut table = Table::new();
        for (name, values) in shared_csv(set, case, "observed_accel.csv") {
            table.push(Column::f64(&name, "", "", values));
        }
        let opts = DetectOptions { sta_lta_on: 8.0, drop_ratio: 0.35, ..DetectOptions::default() };
        detect(&table, &[("top_ax_mps2".to_string(), None)], &opts).unwrap()
    }

    /// The `overturn_time_s:` its truth file gives the case.
    fn truth_overturn_time(case: &str) -> f64 {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../shared/cases/demo/truth/{case}.yaml"));
        let truth: serde_yaml::Value = serde_yaml::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        truth["overturn_time_s"].as_f64().unwrap()
    }

    #[test]
    fn a_shared_overturn_is_found_at_its_true_time_and_a_cart_is_not_toppled() {
        let found = events("demo", "demo_03");
        let column = |table: &Table, name: &str| table.column(name).unwrap().data.clone();
        assert!(matches!(column(&found, "toppled"), ColumnData::Bool(v) if v == [true]));
        let ColumnData::OptF64(time) = column(&found, "impact_time_s") else { panic!("impact_time_s") };
        let truth = truth_overturn_time("demo_03");
        assert!((time[0].unwrap() - truth).abs() < 0.05, "found {:?}, truth {truth} s", time[0]);

        let cart = events("rolling_demo", "demo_01");
        assert!(matches!(column(&cart, "toppled"), ColumnData::Bool(v) if v == [false]));
        assert!(matches!(column(&cart, "impact_time_s"), ColumnData::OptF64(v) if v == [None]));
    }

    /// The one line after `run`: the records and channels that toppled, of all.
    #[test]
    fn the_summary_line_names_the_records_and_channels_that_toppled() {
        use crate::stages::test_tables::{flag, part, text};
        let dir = crate::tempdir::tempdir().unwrap();
        part(dir.path(), "events", "motion=FB-4", vec![text("channel", &["a", "b"]), flag("toppled", &[true, false])]);
        part(dir.path(), "events", "motion=FB-5", vec![text("channel", &["a", "b"]), flag("toppled", &[false, true])]);
        assert_eq!(
            DetectToppling.summary(dir.path()).unwrap(),
            "toppling detected in 2 of 4 channel records (FB-4 a, FB-5 b)"
        );
    }
}
