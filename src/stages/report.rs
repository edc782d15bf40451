//! `report`: the study's summary per unit — identified frequencies per white-noise test and the
//! toppling events — as one small table, and per unit a PNG: floor vs top acceleration in one
//! motion (toppling impacts marked) over the transfer functions with their picked peaks. Given
//! `simulate_rolling` event tables too, a second table summarises each rolling unit per motion
//! (kept apart so the first table's columns stay as they were).

use std::collections::BTreeMap;
use std::sync::Arc;

use rayon::prelude::*;

use super::{
    partition_values, InputKind, InputPart, OutputInfo, OutputKind, Stage, StageContext, StageInfo, StageInput,
};
use crate::pipeline::params::{ParamKind, ParamSpec, ParamsExt};
use crate::table::{Column, ColumnData, Table};

pub struct Report;

static INFO: StageInfo = StageInfo {
    name: "report",
    version: 3,
    summary: "Summary per unit: identified frequencies (one column per test) and toppling events (motion, impact time, confidence); rolling units' peak displacement, yaw and caster flips per motion.",
    inputs: InputKind::Datasets,
    outputs: &[
        OutputInfo { name: "summary", description: "one row per unit and toppling event (or one row when none)", kind: OutputKind::Table },
        OutputInfo { name: "rolling", description: "one row per rolling unit and motion: peak_displacement_m, peak_yaw_rad, caster_flips, breakaway_time_s (from simulate_rolling.events inputs)", kind: OutputKind::Table },
        OutputInfo { name: "figures", description: "<unit>.png: floor vs top acceleration, transfer functions with picked peaks", kind: OutputKind::Files },
    ],
    params: &[
        ParamSpec {
            name: "unit_suffix",
            kind: ParamKind::Str,
            default: Some("\"_top_ax_mps2\""),
            unit: "",
            description: "channel suffix removed to name the unit (PS2_top_ax_mps2 → PS2)",
            range: None,
        },
        ParamSpec {
            name: "figure_motion",
            kind: ParamKind::Str,
            default: Some("\"FB-4\""),
            unit: "",
            description: "motion whose time histories the figures show (with the optional 3rd and 4th inputs)",
            range: None,
        },
    ],
};

impl Stage for Report {
    fn info(&self) -> &'static StageInfo {
        &INFO
    }

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let mut rolling = Vec::new();
        let mut others = Vec::new();
        for input in ctx.inputs {
            match rolling_events(ctx, input)? {
                Some(tables) => rolling.extend(tables),
                None => others.push(input),
            }
        }
        let (identified, events, figure_inputs) = match others.as_slice() {
            [identified, events] => (*identified, *events, None),
            [identified, events, spectra, records] => (*identified, *events, Some((*spectra, *records))),
            _ => anyhow::bail!(
                "`report` reads [transfer_function.identified, detect_toppling.events] and, for figures, also [transfer_function.spectra, synchronize.records]; any number of simulate_rolling.events besides"
            ),
        };
        ctx.sink.write("rolling", &Vec::new(), summarize_rolling(&rolling)?)?;
        ctx.sink.set_total(1);
        let (identified, events) = (read_all(ctx, identified)?, read_all(ctx, events)?);
        let suffix = ctx.params.str_of("unit_suffix");
        if let Some((spectra, records)) = figure_inputs {
            let motion = ctx.params.str_of("figure_motion");
            let spectra = read_all(ctx, spectra)?;
            let record = records.parts().iter().find(|p| motion_of(p) == motion).ok_or_else(|| {
                anyhow::anyhow!("no record of motion `{motion}` for the figures (set `figure_motion`)")
            })?;
            let record = ctx.read_table(record)?;
            for (unit, png) in figures(&identified, &events, &spectra, &record, motion, suffix)? {
                ctx.sink.write_file("figures", &format!("{unit}.png"), &png)?;
            }
        }
        let summary = summarize(identified, events, suffix)?;
        ctx.sink.write("summary", &Vec::new(), summary)
    }
}

/// Equipment modes sit at 2-5 Hz: spectra are drawn up to here, not to Nyquist.
const FIGURE_MAX_HZ: f64 = 20.0;

/// One PNG per unit of the identified tables.
fn figures(
    identified: &[(String, Arc<Table>)],
    events: &[(String, Arc<Table>)],
    spectra: &[(String, Arc<Table>)],
    record: &Table,
    motion: &str,
    suffix: &str,
) -> anyhow::Result<Vec<(String, Vec<u8>)>> {
    use crate::plot::{render_png, Marker, Panel, Series};
    let Some((_, first)) = identified.first() else { return Ok(Vec::new()) };
    let time =
        record.f64_column(crate::table::TIME_COLUMN).ok_or_else(|| anyhow::anyhow!("the record has no time_s"))?;
    let pairs: Vec<(&String, &String)> = strings(first, "output")?.iter().zip(strings(first, "input")?).collect();
    // One figure per unit, drawn and encoded in parallel: the last stage of the study has the
    // machine to itself.
    let figures: Vec<Option<(String, Vec<u8>)>> = pairs
        .par_iter()
        .map(|&(channel, input)| -> anyhow::Result<_> {
            let unit = channel.strip_suffix(suffix).unwrap_or(channel).to_string();
            let (Some(floor), Some(top)) = (record.f64_column(input), record.f64_column(channel)) else {
                return Ok(None);
            };
            let mut impacts = Vec::new();
            for (m, table) in events.iter().filter(|(m, _)| m == motion) {
                let toppled = match table.column("toppled").map(|c| &c.data) {
                    Some(ColumnData::Bool(v)) => v.clone(),
                    _ => Vec::new(),
                };
                let times = optionals(table, "impact_time_s")?;
                for (i, c) in strings(table, "channel")?.iter().enumerate() {
                    if c == channel && toppled.get(i).copied().unwrap_or(false) {
                        impacts.push(Marker { x: times[i].unwrap_or(f64::NAN), label: format!("toppled ({m})") });
                    }
                }
            }
            let mut spectrum_series = Vec::new();
            let mut peaks = Vec::new();
            let selected: Vec<(String, Vec<f64>, Vec<f64>)> = spectra
                .iter()
                .map(|(m, t)| {
                    let outputs = strings(t, "output")?;
                    let f = t.f64_column("frequency_hz").unwrap_or_default();
                    let g = t.f64_column("h1_gain").unwrap_or_default();
                    let rows: Vec<usize> =
                        (0..outputs.len()).filter(|&i| outputs[i] == *channel && f[i] <= FIGURE_MAX_HZ).collect();
                    Ok((m.clone(), rows.iter().map(|&i| f[i]).collect(), rows.iter().map(|&i| g[i]).collect()))
                })
                .collect::<anyhow::Result<_>>()?;
            for (m, f, g) in &selected {
                spectrum_series.push(Series { label: format!("|H1| {m}"), x: f, y: g });
            }
            for (m, t) in identified {
                let outputs = strings(t, "output")?;
                let frequencies = optionals(t, "frequency_hz")?;
                if let Some(i) = outputs.iter().position(|o| o == channel) {
                    if let Some(f) = frequencies[i] {
                        peaks.push(Marker { x: f, label: format!("{m}: {f:.2} Hz") });
                    }
                }
            }
            let panels = [
                Panel {
                    title: format!("{motion}: floor and top acceleration"),
                    x_label: "time [s]".into(),
                    y_label: "acceleration [m/s^2]".into(),
                    series: vec![
                        Series { label: input.clone(), x: time, y: floor },
                        Series { label: channel.clone(), x: time, y: top },
                    ],
                    markers: impacts,
                    log_y: false,
                    spans: Vec::new(),
                },
                Panel {
                    title: format!("transfer function {input} -> {channel}"),
                    x_label: "frequency [Hz]".into(),
                    y_label: "|H1|".into(),
                    series: spectrum_series,
                    markers: peaks,
                    log_y: true,
                    spans: Vec::new(),
                },
            ];
            let png = render_png(&unit, &panels, 1200, 900).map_err(anyhow::Error::msg)?;
            Ok(Some((unit, png)))
        })
        .collect::<anyhow::Result<_>>()?;
    Ok(figures.into_iter().flatten().collect())
}

/// Per rolling run: unit, motion and its events table.
type RollingEvents = Vec<(String, String, Arc<Table>)>;

/// The event tables of a `simulate_rolling` dataset with their unit and motion, or None when
/// the input is something else (told by the stage type its files record).
fn rolling_events(ctx: &StageContext<'_>, input: &StageInput) -> anyhow::Result<Option<RollingEvents>> {
    let mut out = Vec::new();
    for part in input.parts() {
        let table = ctx.read_table(part)?;
        if table.metadata.get("shakeflow.stage_type").map(String::as_str) != Some("simulate_rolling") {
            return Ok(None);
        }
        let facts: serde_json::Value =
            serde_json::from_str(table.metadata.get("shakeflow.rolling").map_or("{}", |s| s))?;
        let unit = facts["unit"].as_str().unwrap_or("cart").to_string();
        out.push((unit, motion_of(part), table));
    }
    Ok(Some(out))
}

/// One row per rolling unit and motion, in input order.
fn summarize_rolling(rolling: &[(String, String, Arc<Table>)]) -> anyhow::Result<Table> {
    let (mut units, mut motions, mut peaks, mut yaws, mut flips, mut breakaways) =
        (vec![], vec![], vec![], vec![], vec![], vec![]);
    for (unit, motion, table) in rolling {
        let kinds = strings(table, "event")?;
        let time = table.f64_column("time_s").ok_or_else(|| anyhow::anyhow!("rolling events without time_s"))?;
        let at = |kind: &str, column: &str| -> anyhow::Result<Option<f64>> {
            let values =
                table.f64_column(column).ok_or_else(|| anyhow::anyhow!("rolling events without `{column}`"))?;
            Ok(kinds.iter().position(|k| k == kind).map(|i| values[i]))
        };
        units.push(unit.clone());
        motions.push(motion.clone());
        peaks.push(at("peak_displacement", "displacement_m")?.unwrap_or(0.0));
        yaws.push(at("peak_yaw", "yaw_rad")?.map_or(0.0, f64::abs));
        flips.push(kinds.iter().filter(|k| *k == "flip").count() as i64);
        breakaways.push(kinds.iter().position(|k| k == "breakaway").map(|i| time[i]));
    }
    let text = |name: &str, description: &str, v: Vec<String>| Column {
        name: name.into(),
        unit: String::new(),
        description: description.into(),
        data: ColumnData::Str(v),
    };
    let mut table = Table::new();
    table.push(text("unit", "rolling unit (simulate_rolling)", units));
    table.push(text("motion", "test motion", motions));
    table.push(Column::f64(
        "peak_displacement_m",
        "m",
        "largest distance of the platform centre from its start",
        peaks,
    ));
    table.push(Column::f64("peak_yaw_rad", "rad", "largest platform yaw change |θ − θ₀|", yaws));
    table.push(Column {
        name: "caster_flips".into(),
        unit: String::new(),
        description: "caster flips (a caster swinging past 135° from the direction it trailed), all four casters"
            .into(),
        data: ColumnData::I64(flips),
    });
    table.push(Column {
        name: "breakaway_time_s".into(),
        unit: "s".into(),
        description: "when the unit first started to roll (null: never)".into(),
        data: ColumnData::OptF64(breakaways),
    });
    Ok(table)
}

/// Every part of a dataset with the name of its record: its `motion` (`WN-1`), else its partition values.
fn read_all(ctx: &StageContext<'_>, input: &StageInput) -> anyhow::Result<Vec<(String, Arc<Table>)>> {
    input.parts().iter().map(|p: &InputPart| Ok((motion_of(p), ctx.read_table(p)?))).collect()
}

fn motion_of(part: &InputPart) -> String {
    part.partition
        .iter()
        .find(|(k, _)| k == "motion")
        .map(|(_, v)| v.clone())
        .unwrap_or_else(|| partition_values(&part.partition))
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

fn summarize(
    identified: Vec<(String, Arc<Table>)>,
    events: Vec<(String, Arc<Table>)>,
    suffix: &str,
) -> anyhow::Result<Table> {
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
