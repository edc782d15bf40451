//! `report`: the study's summary per unit — identified frequencies per white-noise test and the
//! toppling events — as one small table, per unit a PNG (floor vs top acceleration in one motion,
//! toppling impacts marked, over the transfer functions with their picked peaks and coherence),
//! and the study report `index.html`: every unit with its frequencies, toppling events, rocking
//! simulations, fragility, rolling results and figures, the diagnosed cases, and what each stage
//! ran with. Given `simulate_rolling` event tables too, a second table summarises each rolling
//! unit per motion (kept apart so the first table's columns stay as they were). Inputs are
//! recognised by the stage type and output their files record, so any of them may be absent.

mod html;

use std::collections::BTreeMap;
use std::sync::Arc;

use rayon::prelude::*;
use serde::de::DeserializeOwned;

use super::simulate_rolling::SimulateRollingParams;
use super::simulate_toppling::{RockingParams, SimulateTopplingParams};
use super::transfer_function::TransferFunctionParams;
use super::{figure_stem, partition_values, InputPart, Shown, Stage, StageContext, StageInput};
use crate::pipeline::params;
use crate::table::{Column, ColumnData, Table};

crate::stage_params! {
    /// The parameters of `report`.
    pub struct ReportParams {
        /// channel suffix removed to name the unit (PS2_top_ax_mps2 → PS2)
        pub unit_suffix: String [default = "_top_ax_mps2"],
        /// motion whose time histories the figures show (with transfer_function.spectra and synchronize.records
        /// inputs)
        pub figure_motion: String [default = "FB-4"],
        /// heading of index.html
        pub title: String [default = "Study report"],
    }
}

super::declare_stage! {
    /// Summary per unit: identified frequencies (one column per test) and toppling events (motion, impact time,
    /// confidence); rolling units' peak displacement, yaw and caster flips per motion; the study report index.html.
    pub struct Report: "report", version 3, reads Datasets, params ReportParams;
    outputs {
        /// one row per unit and toppling event (or one row when none)
        "summary": Table,
        /// one row per rolling unit and motion: peak_displacement_m, peak_yaw_rad, caster_flips, breakaway_time_s (from
        /// simulate_rolling.events inputs)
        "rolling": Table,
        /// <unit>.png: floor vs top acceleration in `figure_motion`, transfer functions in their band with the picked
        /// peaks, coherence
        "figures": Files,
        /// the study report for a browser: summary, per unit its frequencies, toppling events, simulations, fragility,
        /// rolling results and figures, the diagnosis, provenance (figures linked relatively: open it where `run` wrote
        /// it)
        "index.html": Page,
    }
    examples {
        /// the study report of a rocking simulation: the unit's runs, what the report lacked, the records loaded
        super::RINALDI => "\
baseline:
  type: baseline
  inputs: [load]
PS2:
  type: simulate_toppling
  inputs: [baseline]
  params:
    preset: PS2
report:
  type: report
  inputs: [PS2.events, load.status]
  params:
    title: Rinaldi on PS2
",
    }
}

/// What the report does with each kind of output.
impl Shown {
    const ALL: [Shown; 9] = [
        Shown::Frequencies,
        Shown::Toppling,
        Shown::Rocking,
        Shown::Fragility,
        Shown::Rolling,
        Shown::Diagnosis,
        Shown::Spectra,
        Shown::Records,
        Shown::RecordStatus,
    ];

    /// How the page names the kind when no input holds it (None: not listed).
    fn absent_label(self) -> Option<&'static str> {
        match self {
            Shown::Frequencies => Some("frequencies"),
            Shown::Toppling => Some("toppling in the records"),
            Shown::Rocking => Some("rocking simulations"),
            Shown::Fragility => Some("fragility"),
            Shown::Rolling => Some("rolling simulations"),
            Shown::Diagnosis => Some("diagnosis"),
            Shown::Spectra | Shown::Records | Shown::RecordStatus => None,
        }
    }

    /// The stage outputs (`stage_type.output`) of this kind, in the registry's order.
    fn outputs(self) -> Vec<String> {
        super::stage_types()
            .iter()
            .flat_map(|s| {
                s.shown().iter().filter(move |(_, k)| *k == self).map(move |(o, _)| format!("{}.{o}", s.info().name))
            })
            .collect()
    }

    /// What the stage output `output` of the stage type `stage_type` shows (None: not shown).
    fn of(stage_type: &str, output: &str) -> Option<Shown> {
        let shown = super::stage_type(stage_type)?.shown();
        shown.iter().find(|(o, _)| *o == output).map(|&(_, kind)| kind)
    }
}

/// The inputs `report` reads, sorted by what they hold.
#[derive(Default)]
struct Inputs<'a>(BTreeMap<Shown, Vec<&'a StageInput>>);

impl<'a> Inputs<'a> {
    fn of(&self, kind: Shown) -> &[&'a StageInput] {
        self.0.get(&kind).map_or(&[], Vec::as_slice)
    }
}

/// Every stage output `report` reads, for the error naming what it cannot show.
fn reads() -> String {
    let mut outputs: Vec<String> = super::stage_types()
        .iter()
        .flat_map(|s| s.shown().iter().map(move |(o, _)| format!("{}.{o}", s.info().name)))
        .collect();
    outputs.push("any other table of records with time_s".into());
    outputs.join(", ")
}

impl Stage for Report {
    super::info_and_check_params!(ReportParams);

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let p: ReportParams = params::typed(ctx.params)?;
        let mut inputs = Inputs::default();
        let mut provenance: Vec<html::Provenance> = Vec::new();
        for input in ctx.inputs {
            // An input with no records (nothing selected upstream) has nothing to show.
            let Some(first) = input.parts().first() else { continue };
            let table = ctx.read_table(first)?;
            let (stage_type, output) = (meta(&table, "shakeflow.stage_type"), meta(&table, "shakeflow.output"));
            let kind = match Shown::of(stage_type, output) {
                Some(kind) => kind,
                None if table.column(crate::table::TIME_COLUMN).is_some() => Shown::Records,
                None => anyhow::bail!(
                    "`report` cannot show `{}` (output `{output}` of a `{stage_type}` stage); it reads {}",
                    input.name(),
                    reads()
                ),
            };
            inputs.0.entry(kind).or_default().push(input);
            note_provenance(&mut provenance, &table, input.name());
        }
        let mut rolling: RollingEvents = Vec::new();
        for input in inputs.of(Shown::Rolling) {
            rolling.extend(rolling_events(ctx, input)?);
        }
        ctx.sink.write("rolling", &Vec::new(), summarize_rolling(&rolling)?)?;
        ctx.sink.set_total(1);
        let identified = read_every(ctx, inputs.of(Shown::Frequencies))?;
        let events = read_every(ctx, inputs.of(Shown::Toppling))?;
        let suffix = p.unit_suffix.as_str();
        let mut drawn = Vec::new();
        if let ([spectra, ..], [records, ..]) = (inputs.of(Shown::Spectra), inputs.of(Shown::Records)) {
            let motion = p.figure_motion.as_str();
            let spectra = read_all(ctx, spectra)?;
            let record = records.parts().iter().find(|p| motion_of(p) == motion).ok_or_else(|| {
                anyhow::anyhow!("no record of motion `{motion}` for the figures (set `figure_motion`)")
            })?;
            let record = ctx.read_table(record)?;
            for (unit, png) in figures(&identified, &events, &spectra, &record, motion, suffix)? {
                ctx.sink.write_file("figures", &format!("{unit}.png"), &png)?;
                drawn.push(unit);
            }
        }
        let mut page = study_page(ctx, &inputs, &identified, &events, &rolling, suffix, &drawn)?;
        page.title = p.title.clone();
        page.stages = provenance;
        page.stages.push(html::Provenance {
            stage: ctx.stage_name.to_string(),
            stage_type: INFO.name.into(),
            version: INFO.version.to_string(),
            read: Vec::new(),
            params: serde_json::to_string_pretty(ctx.params)?,
            inputs: ctx.inputs.iter().map(|i| (i.name().to_string(), String::new())).collect(),
            shakeflow_version: env!("CARGO_PKG_VERSION").into(),
        });
        ctx.sink.write_page("index.html", html::render(&page).as_bytes())?;
        let summary = summarize(identified, events, suffix)?;
        ctx.sink.write("summary", &Vec::new(), summary)
    }
}

/// Records which stage made `table` and with what, once per stage (several of its outputs may
/// be read).
fn note_provenance(list: &mut Vec<html::Provenance>, table: &Table, input: &str) {
    let meta = |key: &str| table.metadata.get(key).cloned().unwrap_or_default();
    let stage = meta("shakeflow.stage");
    if let Some(known) = list.iter_mut().find(|p| p.stage == stage) {
        known.read.push(input.to_string());
        return;
    }
    let params = serde_json::from_str::<serde_json::Value>(&meta("shakeflow.params"))
        .and_then(|v| serde_json::to_string_pretty(&v))
        .unwrap_or_else(|_| meta("shakeflow.params"));
    let inputs: BTreeMap<String, String> = serde_json::from_str(&meta("shakeflow.inputs")).unwrap_or_default();
    list.push(html::Provenance {
        stage,
        stage_type: meta("shakeflow.stage_type"),
        version: meta("shakeflow.stage_version"),
        read: vec![input.to_string()],
        params,
        inputs: inputs.into_iter().collect(),
        shakeflow_version: meta("shakeflow.version"),
    });
}

/// Every part of every input of one kind, in input order.
fn read_every(ctx: &StageContext<'_>, inputs: &[&StageInput]) -> anyhow::Result<Vec<(String, Arc<Table>)>> {
    Ok(inputs.iter().map(|i| read_all(ctx, i)).collect::<anyhow::Result<Vec<_>>>()?.concat())
}

/// A metadata value of a table, or "".
fn meta<'t>(table: &'t Table, key: &str) -> &'t str {
    table.metadata.get(key).map_or("", String::as_str)
}

/// The parameters the stage that wrote `table` ran with (its `shakeflow.params`), as that stage
/// type's struct; None when they are absent or do not fit it.
fn upstream_params<T: DeserializeOwned>(table: &Table) -> Option<T> {
    serde_json::from_str(meta(table, "shakeflow.params")).ok()
}

/// The unit a rocking stage modelled: its preset, else the stage's name.
fn unit_of_stage(table: &Table) -> String {
    upstream_params::<RockingParams>(table)
        .and_then(|p| p.preset)
        .unwrap_or_else(|| meta(table, "shakeflow.stage").to_string())
}

/// A link from the report's folder to a figure another stage wrote: `../<stage>/<output>/<file>`.
fn figure_link(table: &Table, output: &str, file: &str) -> String {
    html::relative_url(&["..", meta(table, "shakeflow.stage"), output, file])
}

fn first_bool(table: &Table, name: &str) -> bool {
    matches!(table.column(name).map(|c| &c.data), Some(ColumnData::Bool(v)) if v.first() == Some(&true))
}

fn first_i64(table: &Table, name: &str) -> i64 {
    match table.column(name).map(|c| &c.data) {
        Some(ColumnData::I64(v)) => v.first().copied().unwrap_or(0),
        _ => 0,
    }
}

fn first_f64(table: &Table, name: &str) -> Option<f64> {
    match table.column(name).map(|c| &c.data) {
        Some(ColumnData::F64(v)) => v.first().copied(),
        Some(ColumnData::OptF64(v)) => v.first().copied().flatten(),
        _ => None,
    }
}

fn first_str(table: &Table, name: &str) -> String {
    match table.column(name).map(|c| &c.data) {
        Some(ColumnData::Str(v)) => v.first().cloned().unwrap_or_default(),
        _ => String::new(),
    }
}

/// Everything the page shows, gathered from the inputs.
fn study_page(
    ctx: &StageContext<'_>,
    inputs: &Inputs<'_>,
    identified: &[(String, Arc<Table>)],
    events: &[(String, Arc<Table>)],
    rolling: &RollingEvents,
    suffix: &str,
    drawn: &[String],
) -> anyhow::Result<html::Page> {
    let mut page = html::Page { tests: identified.iter().map(|(m, _)| m.clone()).collect(), ..html::Page::default() };
    for input in inputs.of(Shown::RecordStatus) {
        for part in input.parts() {
            let table = ctx.read_table(part)?;
            let stage = meta(&table, "shakeflow.stage").to_string();
            let [record, status, file, reason] =
                ["record", "status", "file", "reason"].map(|name| strings(&table, name));
            for (((record, status), file), reason) in record?.iter().zip(status?).zip(file?).zip(reason?) {
                page.records.push(html::RecordStatus {
                    stage: stage.clone(),
                    record: record.clone(),
                    status: status.clone(),
                    file: file.clone(),
                    reason: reason.clone(),
                });
            }
        }
    }
    let unit_name = |channel: &str| channel.strip_suffix(suffix).unwrap_or(channel).to_string();
    for (i, (_, table)) in identified.iter().enumerate() {
        for (channel, f) in strings(table, "output")?.iter().zip(optionals(table, "frequency_hz")?) {
            let unit = unit_entry(&mut page.units, &unit_name(channel), page.tests.len());
            unit.frequencies[i] = *f;
        }
    }
    for (motion, table) in events {
        for (channel, toppled, time, confidence) in toppling_rows(table)? {
            let unit = unit_entry(&mut page.units, &unit_name(channel), page.tests.len());
            unit.detected = true;
            if toppled {
                unit.topplings.push((motion.clone(), time, confidence));
            }
        }
    }
    for name in drawn {
        let unit = unit_entry(&mut page.units, name, page.tests.len());
        unit.figure = Some(html::relative_url(&["figures", &format!("{name}.png")]));
    }
    for input in inputs.of(Shown::Rocking) {
        let mut runs: BTreeMap<String, (String, Vec<html::RockingRun>)> = BTreeMap::new();
        for part in input.parts() {
            let table = ctx.read_table(part)?;
            let stage = meta(&table, "shakeflow.stage").to_string();
            let (_, list) = runs.entry(stage).or_insert_with(|| (unit_of_stage(&table), Vec::new()));
            list.push(html::RockingRun {
                motion: motion_of(part),
                overturned: first_bool(&table, "overturned"),
                overturn_time_s: first_f64(&table, "overturn_time_s"),
                max_abs_theta_rad: first_f64(&table, "max_abs_theta_rad").unwrap_or(f64::NAN),
                impacts: first_i64(&table, "n_impacts"),
                figure: upstream_params::<SimulateTopplingParams>(&table).is_none_or(|p| p.figure).then(|| {
                    figure_link(&table, "figures", &format!("{}.png", figure_stem(&part.partition, "response")))
                }),
            });
        }
        for (stage, (unit, runs)) in runs {
            unit_entry(&mut page.units, &unit, page.tests.len()).rocking.push(html::Rocking { stage, runs });
        }
    }
    for input in inputs.of(Shown::Fragility) {
        for part in input.parts() {
            let table = ctx.read_table(part)?;
            let fragility = html::Fragility {
                stage: meta(&table, "shakeflow.stage").to_string(),
                im_measure: first_str(&table, "im_measure"),
                median: first_f64(&table, "median"),
                beta: first_f64(&table, "beta"),
                runs: first_i64(&table, "n_runs"),
                overturned: first_i64(&table, "n_overturned"),
                note: first_str(&table, "note"),
                figure: Some(figure_link(&table, "figures", "fragility.png")),
            };
            unit_entry(&mut page.units, &unit_of_stage(&table), page.tests.len()).fragility.push(fragility);
        }
    }
    let summary = summarize_rolling(rolling)?;
    let peaks = summary.f64_column("peak_displacement_m").unwrap_or_default();
    let yaws = summary.f64_column("peak_yaw_rad").unwrap_or_default();
    let flips = match summary.column("caster_flips").map(|c| &c.data) {
        Some(ColumnData::I64(v)) => v.clone(),
        _ => Vec::new(),
    };
    let breakaways = optionals(&summary, "breakaway_time_s")?;
    for (i, run) in rolling.iter().enumerate() {
        let unit = unit_entry(&mut page.units, &run.unit, page.tests.len());
        let stage = meta(&run.table, "shakeflow.stage").to_string();
        let drawn = upstream_params::<SimulateRollingParams>(&run.table).is_some_and(|p| p.figure);
        let figure = drawn.then(|| figure_link(&run.table, "figures", &format!("{}.png", run.figure_stem)));
        let entry = html::RollingRun {
            motion: run.motion.clone(),
            peak_displacement_m: peaks[i],
            peak_yaw_rad: yaws[i],
            caster_flips: flips[i],
            breakaway_time_s: breakaways[i],
            figure,
        };
        match unit.rolling.iter_mut().find(|r| r.stage == stage) {
            Some(r) => r.runs.push(entry),
            None => unit.rolling.push(html::Rolling { stage, runs: vec![entry] }),
        }
    }
    for input in inputs.of(Shown::Diagnosis) {
        for part in input.parts() {
            page.cases.extend(cases(&*ctx.read_table(part)?)?);
        }
    }
    let shown: Vec<Shown> = inputs.0.keys().copied().collect();
    page.absent = Shown::ALL
        .into_iter()
        .filter(|kind| !shown.contains(kind))
        .filter_map(|kind| Some(format!("{} ({})", kind.absent_label()?, kind.outputs().join(", "))))
        .collect();
    Ok(page)
}

/// The page's entry of a unit, added (after those already there) when new.
fn unit_entry<'p>(units: &'p mut Vec<html::Unit>, name: &str, tests: usize) -> &'p mut html::Unit {
    let index = match units.iter().position(|u| u.name == name) {
        Some(i) => i,
        None => {
            units.push(html::Unit { name: name.to_string(), frequencies: vec![None; tests], ..html::Unit::default() });
            units.len() - 1
        }
    };
    &mut units[index]
}

/// The rows of a `diagnose.diagnosis` table.
fn cases(table: &Table) -> anyhow::Result<Vec<html::Case>> {
    let names = strings(table, "case")?;
    let verdicts = strings(table, "verdict")?;
    let explanations = strings(table, "explanation")?;
    let mismatch = match table.column("mismatch").map(|c| &c.data) {
        Some(ColumnData::Bool(v)) => v.clone(),
        _ => anyhow::bail!("the diagnosis table has no `mismatch` column"),
    };
    let (start, end) = (optionals(table, "window_start_s")?, optionals(table, "window_end_s")?);
    let before = table.f64_column("rmse_before").unwrap_or_default();
    let after = table.f64_column("rmse_after").unwrap_or_default();
    Ok((0..names.len())
        .map(|i| {
            let stem = if names[i].is_empty() { None } else { Some(names[i].replace('/', "_")) };
            html::Case {
                stage: meta(table, "shakeflow.stage").to_string(),
                case: names[i].split_once('=').map_or(names[i].as_str(), |(_, v)| v).to_string(),
                mismatch: mismatch[i],
                verdict: verdicts[i].clone(),
                window: start[i].zip(end[i]),
                rmse_before: before.get(i).copied().unwrap_or(f64::NAN),
                rmse_after: after.get(i).copied().unwrap_or(f64::NAN),
                explanation: explanations[i].clone(),
                figure: stem.map(|s| figure_link(table, "reports", &format!("{s}.png"))),
            }
        })
        .collect())
}

/// Where the transfer functions are drawn: the band the `transfer_function` stage searched for
/// peaks (its `band_min_hz`/`band_max_hz`, recorded in the spectra's provenance), else 0-20 Hz
/// (equipment modes sit at 2-5 Hz; above, the spectra are noise).
fn figure_band(spectra: &Table) -> (f64, f64) {
    match upstream_params::<TransferFunctionParams>(spectra) {
        Some(p) if p.band_min_hz < p.band_max_hz => (p.band_min_hz, p.band_max_hz),
        _ => (0.0, 20.0),
    }
}

/// A floor channel as titles name it (`floor4_ax_mps2` → `floor 4`), else as it is.
fn floor_name(channel: &str) -> String {
    match channel.strip_prefix("floor").and_then(|rest| rest.split_once('_')) {
        Some((level, _)) if !level.is_empty() => format!("floor {level}"),
        _ => channel.to_string(),
    }
}

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
            // Per white-noise test, |H1| and the coherence of this unit inside the band.
            let selected: Vec<(String, Vec<f64>, Vec<f64>, Vec<f64>)> = spectra
                .iter()
                .map(|(m, t)| {
                    let (lo, hi) = figure_band(t);
                    let outputs = strings(t, "output")?;
                    let column = |name: &str| {
                        t.f64_column(name).ok_or_else(|| anyhow::anyhow!("the spectra have no `{name}` column"))
                    };
                    let (f, g, c) = (column("frequency_hz")?, column("h1_gain")?, column("coherence")?);
                    let rows: Vec<usize> =
                        (0..outputs.len()).filter(|&i| outputs[i] == *channel && f[i] >= lo && f[i] <= hi).collect();
                    let pick = |v: &[f64]| rows.iter().map(|&i| v[i]).collect::<Vec<f64>>();
                    Ok((m.clone(), pick(f), pick(g), pick(c)))
                })
                .collect::<anyhow::Result<_>>()?;
            let band = spectra.first().map_or((0.0, 20.0), |(_, t)| figure_band(t));
            let gains: Vec<Series> =
                selected.iter().map(|(m, f, g, _)| Series::new(format!("|H1| {m}"), f, g)).collect();
            let coherences: Vec<Series> =
                selected.iter().map(|(m, f, _, c)| Series::new(format!("coherence {m}"), f, c)).collect();
            let mut peaks = Vec::new();
            for (m, t) in identified {
                let outputs = strings(t, "output")?;
                let frequencies = optionals(t, "frequency_hz")?;
                if let Some(i) = outputs.iter().position(|o| o == channel) {
                    if let Some(f) = frequencies[i] {
                        peaks.push(Marker { x: f, label: format!("{m}: {f:.2} Hz") });
                    }
                }
            }
            let floor_label = floor_name(input);
            let panels = [
                Panel {
                    title: format!("{motion}: recorded acceleration, {floor_label} and {unit} top"),
                    x_label: "time [s]".into(),
                    y_label: "acceleration [m/s^2]".into(),
                    series: vec![
                        Series::new(floor_label.clone(), time, floor),
                        Series::new(format!("{unit} top"), time, top).observed(),
                    ],
                    markers: impacts,
                    ..Panel::default()
                },
                Panel {
                    title: format!(
                        "transfer function {floor_label} → {unit} top, in the searched band {:.1}-{:.1} Hz",
                        band.0, band.1
                    ),
                    x_label: "frequency [Hz]".into(),
                    y_label: "|H1|".into(),
                    series: gains,
                    markers: peaks,
                    log_y: true,
                    ..Panel::default()
                },
                Panel {
                    title: "coherence (near 1: the top moves with the floor; low: noise)".into(),
                    x_label: "frequency [Hz]".into(),
                    y_label: "coherence".into(),
                    series: coherences,
                    ..Panel::default()
                },
            ];
            let title = format!("{unit}: recorded response in {motion} and frequencies from the white-noise tests");
            let png = render_png(&title, &panels, 1200, 1100).map_err(anyhow::Error::msg)?;
            Ok(Some((unit, png)))
        })
        .collect::<anyhow::Result<_>>()?;
    Ok(figures.into_iter().flatten().collect())
}

/// One rolling run: its unit, motion, figure name and events table.
struct RollingRun {
    unit: String,
    motion: String,
    figure_stem: String,
    table: Arc<Table>,
}

type RollingEvents = Vec<RollingRun>;

/// The event tables of a `simulate_rolling` dataset with their unit and motion.
fn rolling_events(ctx: &StageContext<'_>, input: &StageInput) -> anyhow::Result<RollingEvents> {
    let mut out = Vec::new();
    for part in input.parts() {
        let table = ctx.read_table(part)?;
        let facts: serde_json::Value =
            serde_json::from_str(table.metadata.get("shakeflow.rolling").map_or("{}", |s| s))?;
        let unit = facts["unit"].as_str().unwrap_or("cart").to_string();
        let figure_stem = figure_stem(&part.partition, &unit);
        out.push(RollingRun { unit, motion: motion_of(part), figure_stem, table });
    }
    Ok(out)
}

/// One row per rolling unit and motion, in input order.
fn summarize_rolling(rolling: &[RollingRun]) -> anyhow::Result<Table> {
    let (mut units, mut motions, mut peaks, mut yaws, mut flips, mut breakaways) =
        (vec![], vec![], vec![], vec![], vec![], vec![]);
    for RollingRun { unit, motion, table, .. } in rolling {
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
    let mut table = Table::new();
    table.push(super::text_column("unit", "rolling unit (simulate_rolling)", units));
    table.push(super::text_column("motion", "test motion", motions));
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

/// The rows of a toppling `events` table (`Shown::Toppling`): channel, toppled, impact time
/// (NaN without one) and confidence.
fn toppling_rows(table: &Table) -> anyhow::Result<Vec<(&String, bool, f64, f64)>> {
    let toppled = match table.column("toppled").map(|c| &c.data) {
        Some(ColumnData::Bool(v)) => v,
        _ => anyhow::bail!("the events table has no `toppled` column"),
    };
    let confidence = table.f64_column("confidence").ok_or_else(|| anyhow::anyhow!("no `confidence` column"))?;
    let times = optionals(table, "impact_time_s")?;
    let rows = strings(table, "channel")?.iter().zip(toppled).zip(times).zip(confidence);
    Ok(rows
        .map(|(((channel, &toppled), time), &confidence)| (channel, toppled, time.unwrap_or(f64::NAN), confidence))
        .collect())
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
        for (channel, toppled, time, confidence) in toppling_rows(table)? {
            if !order.contains(channel) {
                order.push(channel.clone());
            }
            if toppled {
                topplings.entry(channel.clone()).or_default().push((motion.clone(), time, confidence));
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
    let mut table = Table::new();
    table.push(super::text_column(
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transfer_functions_are_drawn_in_the_band_their_stage_searched() {
        let info = Stage::info(&super::super::transfer_function::TransferFunction);
        let given = [("pairs", serde_json::json!(["a -> b"])), ("band_min_hz", 1.5.into()), ("band_max_hz", 8.into())];
        let ran_with = params::normalize(info.params, info.name, given).unwrap();
        let mut spectra = Table::new();
        spectra.metadata.insert("shakeflow.params".into(), serde_json::to_string(&ran_with).unwrap());
        assert_eq!(figure_band(&spectra), (1.5, 8.0));
        spectra.metadata.insert("shakeflow.params".into(), r#"{"band_max_hz":null}"#.into());
        assert_eq!(figure_band(&spectra), (0.0, 20.0));
    }

    /// The report routes on what each stage type says it shows: every kind is some stage's
    /// output, and the page names a missing kind by the outputs that would fill it.
    #[test]
    fn the_report_reads_what_the_stages_say_it_shows() {
        assert_eq!(Shown::of("transfer_function", "identified"), Some(Shown::Frequencies));
        assert_eq!(Shown::of("simulate_toppling", "events"), Some(Shown::Rocking));
        assert_eq!(Shown::of("detect_toppling", "events"), Some(Shown::Toppling));
        assert_eq!(Shown::of("baseline", "records"), None);
        assert_eq!(Shown::of("no_such_stage", "events"), None);
        for kind in Shown::ALL {
            assert!(!kind.outputs().is_empty(), "no stage output shows {kind:?}");
        }
        assert_eq!(Shown::Toppling.outputs(), ["detect_toppling.events"]);
        assert!(reads().starts_with("load.status, synchronize.records, transfer_function.identified"), "{}", reads());
    }

    #[test]
    fn titles_name_floors_units_and_motions_as_people_do() {
        assert_eq!(floor_name("floor4_ax_mps2"), "floor 4");
        assert_eq!(floor_name("ax_mps2"), "ax_mps2");
        let partition = vec![("motion".to_string(), "FB-4".to_string()), ("floor".to_string(), "5".to_string())];
        assert_eq!(super::super::record_title(&partition, "x"), "FB-4, floor 5");
        assert_eq!(super::super::record_title(&Vec::new(), "record.csv"), "record.csv");
    }
}
