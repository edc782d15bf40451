//! `report`: the study's summary per unit — identified frequencies per white-noise test and the
//! toppling events — as one small table (and, per unit, a figure).

use std::collections::BTreeMap;

use super::{partition_path, InputKind, InputPart, OutputInfo, Stage, StageContext, StageInfo, StageInput};
use crate::io::parquet;
use crate::pipeline::params::{ParamKind, ParamSpec, ParamsExt};
use crate::table::{Column, ColumnData, Table};

pub struct Report;

static INFO: StageInfo = StageInfo {
    name: "report",
    version: 1,
    summary: "Summary per unit: identified frequencies (one column per test) and toppling events (motion, impact time, confidence).",
    inputs: InputKind::Datasets,
    outputs: &[OutputInfo { name: "summary", description: "one row per unit and toppling event (or one row when none)", timeseries: false }],
    params: &[ParamSpec {
        name: "unit_suffix",
        kind: ParamKind::Str,
        default: Some("\"_top_ax_mps2\""),
        unit: "",
        description: "channel suffix removed to name the unit (PS2_top_ax_mps2 → PS2)",
        range: None,
    }],
};

impl Stage for Report {
    fn info(&self) -> &'static StageInfo {
        &INFO
    }

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let [identified, events] = ctx.inputs else {
            anyhow::bail!("`report` reads two inputs: [transfer_function.identified, detect_toppling.events]");
        };
        ctx.sink.set_total(1);
        let summary = summarize(read_all(identified)?, read_all(events)?, ctx.params.str_of("unit_suffix"))?;
        ctx.sink.write("summary", &Vec::new(), summary)
    }
}

/// Every part of a dataset with the partition path that names it (`motion=WN-1`).
fn read_all(input: &StageInput) -> anyhow::Result<Vec<(String, Table)>> {
    input.parts().iter().map(|p: &InputPart| Ok((motion_of(p), parquet::read_table(&p.path)?))).collect()
}

fn motion_of(part: &InputPart) -> String {
    part.partition
        .iter()
        .find(|(k, _)| k == "motion")
        .map(|(_, v)| v.clone())
        .unwrap_or_else(|| partition_path(&part.partition))
}

fn strings<'a>(table: &'a Table, name: &str) -> anyhow::Result<&'a [String]> {
    match table.column(name).map(|c| &c.data) {
        Some(ColumnData::Str(v)) => Ok(v),
        _ => anyhow::bail!("expected a text column `{name}`; columns: {}", table.column_names().join(", ")),
    }
}

fn optionals<'a>(table: &'a Table, name: &str) -> anyhow::Result<&'a [Option<f64>]> {
    match table.column(name).map(|c| &c.data) {
        Some(ColumnData::OptF64(v)) => Ok(v),
        _ => anyhow::bail!("expected a nullable float column `{name}`; columns: {}", table.column_names().join(", ")),
    }
}

fn summarize(identified: Vec<(String, Table)>, events: Vec<(String, Table)>, suffix: &str) -> anyhow::Result<Table> {
    // channel → test → frequency; channel → [(motion, time, confidence)]
    let mut frequencies: BTreeMap<String, BTreeMap<String, Option<f64>>> = BTreeMap::new();
    let mut tests: Vec<String> = Vec::new();
    let mut order: Vec<String> = Vec::new();
    for (motion, table) in &identified {
        tests.push(motion.clone());
        for (channel, f) in strings(table, "output")?.iter().zip(optionals(table, "frequency_hz")?) {
            if !order.contains(channel) {
                order.push(channel.clone());
            }
            frequencies.entry(channel.clone()).or_default().insert(motion.clone(), *f);
        }
    }
    let mut topplings: BTreeMap<String, Vec<(String, f64, f64)>> = BTreeMap::new();
    for (motion, table) in &events {
        let toppled = match table.column("toppled").map(|c| &c.data) {
            Some(ColumnData::Bool(v)) => v,
            _ => anyhow::bail!("the events table has no `toppled` column"),
        };
        let confidence = table.f64_column("confidence").ok_or_else(|| anyhow::anyhow!("no `confidence` column"))?;
        let times = optionals(table, "impact_time_s")?;
        for (i, channel) in strings(table, "channel")?.iter().enumerate() {
            if !order.contains(channel) {
                order.push(channel.clone());
            }
            if toppled[i] {
                let time = times[i].unwrap_or(f64::NAN);
                topplings.entry(channel.clone()).or_default().push((motion.clone(), time, confidence[i]));
            }
        }
    }
    let mut rows: Vec<(String, Option<(String, f64, f64)>)> = Vec::new();
    for channel in &order {
        match topplings.get(channel) {
            Some(list) => rows.extend(list.iter().map(|e| (channel.clone(), Some(e.clone())))),
            None => rows.push((channel.clone(), None)),
        }
    }
    let text = |name: &str, description: &str, v: Vec<String>| Column {
        name: name.into(),
        unit: String::new(),
        description: description.into(),
        data: ColumnData::Str(v),
    };
    let mut table = Table::new();
    table.push(text(
        "unit",
        "equipment unit",
        rows.iter().map(|(c, _)| c.strip_suffix(suffix).unwrap_or(c).to_string()).collect(),
    ));
    for test in &tests {
        let values =
            rows.iter().map(|(c, _)| frequencies.get(c).and_then(|m| m.get(test).copied().flatten())).collect();
        table.push(Column {
            name: format!("f_{test}_hz"),
            unit: "Hz".into(),
            description: format!("fundamental frequency identified from test {test}"),
            data: ColumnData::OptF64(values),
        });
    }
    table.push(Column {
        name: "toppled".into(),
        unit: String::new(),
        description: "toppled in `motion`".into(),
        data: ColumnData::Bool(rows.iter().map(|(_, e)| e.is_some()).collect()),
    });
    table.push(Column {
        name: "motion".into(),
        unit: String::new(),
        description: "motion in which it toppled (null: never)".into(),
        data: ColumnData::OptStr(rows.iter().map(|(_, e)| e.as_ref().map(|e| e.0.clone())).collect()),
    });
    table.push(Column {
        name: "impact_time_s".into(),
        unit: "s".into(),
        description: "toppling impact time on the floor DAQ clock".into(),
        data: ColumnData::OptF64(rows.iter().map(|(_, e)| e.as_ref().map(|e| e.1)).collect()),
    });
    table.push(Column {
        name: "confidence".into(),
        unit: String::new(),
        description: "confidence of the toppling detection".into(),
        data: ColumnData::OptF64(rows.iter().map(|(_, e)| e.as_ref().map(|e| e.2)).collect()),
    });
    Ok(table)
}
