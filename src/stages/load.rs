//! `load`: record files (delimited text, PEER AT2, RENADIC V1, SimCenter JSON, COSMOS, CSMIP/DMG,
//! USGS SMC, K-NET/KiK-net, ESM, GeoNet, LabVIEW LVM) → uniform SI
//! time-series tables, one per file, partitioned as the source's path template says.

use std::collections::{BTreeMap, HashMap};

use rayon::prelude::*;
use serde_json::json;

use super::{InputPart, Stage, StageContext, StageInput};
use crate::error::{did_you_mean_hint, UserError};
use crate::io::records::{self, DelimitedOptions, RawRecord};
use crate::pipeline::spec::{Axis, ColumnSpec, ComponentAs, GapPolicy, NonUniformPolicy, RecordFormat, SourceSpec};
use crate::signal::resample;
use crate::table::{Column, ColumnData, Table, TIME_COLUMN};
use crate::units;

crate::stage_params! {
    /// `load` takes no parameters (a source's reading options live in its spec).
    pub struct LoadParams {}
}

super::declare_stage! {
    /// Read record files into SI time-series tables: checks sampling, gaps and point counts, converts units.
    pub struct Load: "load", version 3, reads Sources, params LoadParams;
    outputs {
        /// one table per record file: time_s plus each channel in SI
        "records": Table,
        /// written by the engine when a source has `on_error: skip`: one row per record that could not be read (record,
        /// file, reason with file:line:column)
        "flagged": Table,
        /// written by the engine: one row per record (record, status, file, reason): loaded, flagged (loaded whole,
        /// e.g. channels of unequal lengths null-padded; reason with file:line), skipped (`on_error: skip`) or failed
        "status": Table => RecordStatus,
    }
    examples {
        /// two NIED stations, one file per component, each read as one record in m/s² with its axes from the files'
        /// `Dir.` lines
        KNET => "",
        /// every shared record file, each read by the format its content tells (one record per file); `on_error: skip`
        /// lists a file that cannot be read in `flagged` and goes on
        ARCHIVE => "",
    }
}

/// Every file of the shared records, told by content.
const ARCHIVE: super::ExampleData = super::ExampleData {
    what: "the shared records, 18 files of 8 agencies",
    head: "\
inputs:
  archive:
    description: the shared strong-motion files as their agencies ship them, one folder per agency
    format: auto
    path: ../shared/data/records/{agency}/{file}
    on_error: skip
stages:
  load:
    type: load
    inputs: [archive]
",
};

/// The shared K-NET (`.EW`, `.NS`, `.UD`) and KiK-net surface (`.EW2`, `.NS2`, `.UD2`) records.
const KNET: super::ExampleData = super::ExampleData {
    what: "the shared K-NET and KiK-net records",
    head: "\
inputs:
  knet:
    description: K-NET AOM005 (Jan 2018) and KiK-net AICH04 (surface sensor, Oct 2000), counts with scale factors
    format: knet
    path: ../shared/data/records/knet/{station}.{component}
    components: {key: component}
stages:
  load:
    type: load
    inputs: [knet]
",
};

impl Stage for Load {
    super::info_and_check_params!(LoadParams);

    fn work_units(&self) -> super::WorkUnits {
        super::WorkUnits::EachRecord
    }

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        // Records of one file each, and records of a `components:` source: its files that share
        // a partition.
        let mut jobs: Vec<Job<'_>> = Vec::new();
        let mut groups: BTreeMap<(&str, String), Group<'_>> = BTreeMap::new();
        for input in ctx.inputs {
            let StageInput::Source { name, spec, files, base_dir } = input else {
                unreachable!("the plan gives `load` sources only")
            };
            for file in files {
                match spec.components {
                    Some(_) => groups
                        .entry((name.as_str(), super::partition_path(&file.partition)))
                        .or_insert_with(|| Group { spec, source: name, base_dir, parts: Vec::new() })
                        .parts
                        .push(file),
                    None => jobs.push((spec, name.as_str(), file)),
                }
            }
        }
        ctx.sink.set_total(jobs.len() + groups.len());
        groups.into_par_iter().try_for_each(|(_, group)| {
            let mut table = load_group(&group).map_err(|e| anyhow::Error::new(*e.error))?;
            table.metadata.insert("shakeflow.source".into(), group.source.to_string());
            let joined =
                |field: fn(&InputPart) -> &str| group.parts.iter().map(|p| field(p)).collect::<Vec<_>>().join(", ");
            table.metadata.insert("shakeflow.input_file".into(), joined(|p| &p.label));
            table.metadata.insert("shakeflow.input_hash".into(), joined(|p| &p.hash));
            ctx.sink.write("records", &group.parts[0].partition, table)
        })?;
        // Sources that read the same file the same way (a DAQ export split into floors) share
        // one parse.
        let mut files: BTreeMap<(&std::path::Path, ParseKey<'_>), Vec<Job<'_>>> = BTreeMap::new();
        for job in &jobs {
            files.entry((job.2.path.as_path(), ParseKey::of(job.0))).or_default().push(*job);
        }
        files.into_par_iter().try_for_each(|((path, _), jobs)| {
            debug_assert!(jobs.iter().all(|job| job.2.path == path));
            let raw = parse(jobs[0].0, jobs[0].2).map_err(anyhow::Error::new)?;
            jobs.into_par_iter().try_for_each(|(spec, source, part)| {
                let mut table = load_parsed(spec, part, &raw).map_err(|e| anyhow::Error::new(*e.error))?;
                table.metadata.insert("shakeflow.source".into(), source.to_string());
                table.metadata.extend(super::record_provenance(part));
                ctx.sink.write("records", &part.partition, table)
            })
        })
    }
}

/// One record file to load: the source's spec, the source's name and the file.
type Job<'a> = (&'a SourceSpec, &'a str, &'a InputPart);

/// One record of a `components:` source: its files, one per component.
struct Group<'a> {
    spec: &'a SourceSpec,
    source: &'a str,
    base_dir: &'a std::path::Path,
    parts: Vec<&'a InputPart>,
}

/// A `components:` record read as `load` reads it (`validate` reads the first one so): its
/// files, one per component, parsed, checked to share one clock, and joined.
pub fn load_record_group(
    spec: &SourceSpec,
    source: &str,
    base_dir: &std::path::Path,
    parts: &[InputPart],
) -> Result<Table, RecordError> {
    load_group(&Group { spec, source, base_dir, parts: parts.iter().collect() })
}

/// A `components:` record: its files read, checked to share one clock, and joined.
fn load_group(group: &Group<'_>) -> Result<Table, RecordError> {
    let raws: Vec<RawRecord> = group.parts.par_iter().map(|part| parse(group.spec, part)).collect::<Result<_, _>>()?;
    let merged = merge_components(group, raws)?;
    load_parsed(group.spec, group.parts[0], &merged)
}

/// The components of one record joined into one: the same reader, sampling and start time
/// (where the files state one), every axis `require`d present. Each channel's header keys
/// gain its `file` and `component`; record-wide keys the files disagree on are kept per
/// component (`component.EW.peak_gal`).
fn merge_components(group: &Group<'_>, raws: Vec<RawRecord>) -> Result<RawRecord, UserError> {
    let spec = group.spec;
    let components = spec.components.as_ref().expect("a group comes from a `components:` source");
    let record = super::partition_values(&group.parts[0].partition);
    let files = || group.parts.iter().map(|p| p.label.as_str()).collect::<Vec<_>>().join(", ");
    let names: Vec<String> = group
        .parts
        .iter()
        .map(|p| {
            crate::pipeline::sources::key_value(group.base_dir, &spec.path, &p.path, &components.key)
                .unwrap_or_else(|| p.label.clone())
        })
        .collect();
    let refuse = |k: usize, message: String, hint: &str| {
        UserError::new(format!("record `{record}` ({}): {message}", files()))
            .in_file(&group.parts[k].path)
            .hint(hint.to_string())
    };
    let first = &raws[0];
    for (k, raw) in raws.iter().enumerate() {
        if raw.format != first.format {
            return Err(refuse(
                k,
                format!(
                    "its `{}` file is a `{}` record, its `{}` file a `{}` record",
                    names[0], first.format, names[k], raw.format
                ),
                "one record's components come from one reader: narrow the source's path",
            ));
        }
        if raw.time.is_some() {
            return Err(refuse(
                k,
                format!("its `{}` file has a time column of its own", names[k]),
                "files with their own times cannot share one clock: load each with a source of its own",
            ));
        }
        let (a, b) = (spec.dt.or(first.dt), spec.dt.or(raw.dt));
        if let (Some(a), Some(b)) = (a, b) {
            if (a - b).abs() > 1e-9 * a.abs().max(b.abs()) {
                return Err(refuse(
                    k,
                    format!("its `{}` file is sampled every {a} s, its `{}` file every {b} s", names[0], names[k]),
                    "components on one clock share one sampling: resample one, or load them as separate records",
                ));
            }
        }
        if let (Some(a), Some(b)) = (first.header.get("record_start"), raw.header.get("record_start")) {
            if a != b {
                return Err(refuse(
                    k,
                    format!("its `{}` file starts at {a}, its `{}` file at {b}", names[0], names[k]),
                    "components on one clock start together: trim them to a common start, or load them as separate records",
                ));
            }
        }
    }
    let mut merged = RawRecord {
        format: first.format,
        dt: spec.dt.or(first.dt),
        time: None,
        channels: Vec::new(),
        header: BTreeMap::new(),
    };
    let mut shared: BTreeMap<String, Vec<(usize, String)>> = BTreeMap::new();
    for (k, raw) in raws.into_iter().enumerate() {
        let component = &names[k];
        let stated = components.axes.get(component);
        if stated.is_some() && raw.channels.len() != 1 {
            return Err(refuse(
                k,
                format!("`components: axes` names `{component}`, but its file holds {} channels", raw.channels.len()),
                "`axes` says where a one-component file points; a file of several channels states its own",
            ));
        }
        for (key, value) in &raw.header {
            if !key.starts_with("channel.") {
                shared.entry(key.clone()).or_default().push((k, value.clone()));
            }
        }
        for mut channel in raw.channels {
            let own = format!("channel.{}.", channel.name);
            if merged.channels.iter().any(|c| c.name == channel.name) {
                channel.name = format!("{}_{component}", channel.name);
            }
            let prefix = format!("channel.{}.", channel.name);
            for (key, value) in raw.header.range(own.clone()..).take_while(|(key, _)| key.starts_with(&own)) {
                merged.header.insert(format!("{prefix}{}", &key[own.len()..]), value.clone());
            }
            if let Some(axis) = stated {
                let orientation = match axis {
                    Axis::X => "90",
                    Axis::Y => "0",
                    Axis::Z => "up",
                };
                merged.header.insert(format!("{prefix}orientation"), orientation.into());
            }
            merged.header.insert(format!("{prefix}file"), group.parts[k].label.clone());
            merged.header.insert(format!("{prefix}component"), component.clone());
            merged.channels.push(channel);
        }
    }
    for (key, values) in shared {
        if values.len() == names.len() && values.iter().all(|(_, v)| *v == values[0].1) {
            merged.header.insert(key, values[0].1.clone());
        } else {
            for (k, value) in values {
                merged.header.insert(format!("component.{}.{key}", names[k]), value);
            }
        }
    }
    let channels: Vec<&records::RawChannel> = merged.channels.iter().collect();
    let single = (spec.component_as == Some(ComponentAs::Ay)).then_some('y');
    let axes = records::roles::axes(&merged, &channels, single).map_err(|e| {
        refuse(0, e.to_string(), "say which component is which with `components: {axes: {H1: x, H2: y, UP: z}}`")
    })?;
    if let Some(missing) = components.require.iter().find(|a| !axes.contains(&a.letter())) {
        return Err(refuse(
            0,
            format!("no `{}` component among its {} file(s) (components {})", missing.letter(), names.len(), names.join(", ")),
            "a component file is missing: add it, or set `components: {require: [...]}` to the axes this archive has; `on_error: skip` lists the record and goes on",
        ));
    }
    Ok(merged)
}

/// What decides how a file parses: sources equal in these read it identically.
#[derive(PartialEq, Eq, PartialOrd, Ord)]
struct ParseKey<'a> {
    format: RecordFormat,
    header_lines: usize,
    column_names: bool,
    delimiter: Option<&'a str>,
    units_row: Option<usize>,
    description_row: Option<usize>,
}

impl<'a> ParseKey<'a> {
    fn of(spec: &'a SourceSpec) -> Self {
        ParseKey {
            format: spec.format,
            header_lines: spec.header_lines,
            column_names: spec.column_names,
            delimiter: spec.delimiter.as_deref(),
            units_row: spec.units_row,
            description_row: spec.description_row,
        }
    }
}

/// A reader's refusal as the error a user sees.
fn user_error(e: records::ParseError) -> UserError {
    UserError {
        file: Some(e.path),
        line: e.line,
        column: e.column,
        message: e.message,
        hint: (!e.hint.is_empty()).then_some(e.hint),
    }
}

/// Parses the file of `part` from one read of its bytes, which must be the bytes the run hashed
/// when it was planned (`part.hash`): the artifact then holds what its `shakeflow.input_hash` names.
fn parse(spec: &SourceSpec, part: &InputPart) -> Result<RawRecord, UserError> {
    let path = part.path.as_path();
    if !spec.format.is_record() {
        return Err(UserError::new(format!("`load` does not read `{}` sources", spec.format.name()))
            .in_file(path)
            .hint("a `frames` source feeds `cpt_track`, a `control_points` source `cpt_calibrate`, a `case` source `diagnose`"));
    }
    let bytes = records::read_bytes(path).map_err(user_error)?;
    records::unchanged(path, &part.hash, &bytes).map_err(user_error)?;
    let format = match spec.format {
        RecordFormat::Auto => detected(path, &bytes)?,
        named => named,
    };
    let delimited = delimited_options(&SourceSpec { format, ..spec.clone() }).unwrap_or_default();
    match format {
        RecordFormat::At2 => records::parse_at2(path, &bytes),
        RecordFormat::RenadicV1 => records::parse_renadic_v1(path, &bytes),
        RecordFormat::SimcenterJson => records::parse_simcenter_json(path, &bytes),
        RecordFormat::Cosmos => records::parse_cosmos(path, &bytes),
        RecordFormat::Dmg => records::parse_dmg(path, &bytes),
        RecordFormat::Smc => records::parse_smc(path, &bytes),
        RecordFormat::Knet => records::parse_knet(path, &bytes),
        RecordFormat::Esm => records::parse_esm(path, &bytes),
        RecordFormat::Geonet => records::parse_geonet(path, &bytes),
        RecordFormat::Lvm => records::parse_lvm(path, &bytes),
        RecordFormat::Csv | RecordFormat::Tsv | RecordFormat::Delimited => {
            records::parse_delimited(path, &bytes, &delimited)
        }
        RecordFormat::Frames
        | RecordFormat::ControlPoints
        | RecordFormat::Case
        | RecordFormat::Dataset
        | RecordFormat::Auto => {
            unreachable!("refused above, or told from the file")
        }
    }
    .map_err(user_error)
}

/// The record format of a `format: auto` file: its content first, then its extension.
fn detected(path: &std::path::Path, bytes: &[u8]) -> Result<RecordFormat, UserError> {
    let name = records::sniff_bytes(path, bytes).ok_or_else(|| user_error(records::unknown_format(path)))?;
    Ok(format_named(name))
}

/// The source format a reader's name (`RawRecord::format`) is.
fn format_named(name: &str) -> RecordFormat {
    serde_json::from_value(json!(name)).expect("readers are named as the formats they read")
}

/// The format the record was read as: the source's, or for `format: auto` the reader's.
fn read_as(spec: &SourceSpec, raw: &RawRecord) -> RecordFormat {
    match spec.format {
        RecordFormat::Auto => format_named(raw.format),
        named => named,
    }
}

/// How a delimited source's files parse; None for the other formats.
pub fn delimited_options(spec: &SourceSpec) -> Option<DelimitedOptions> {
    let delimiter = match spec.delimiter.as_deref() {
        None => None,
        Some("whitespace") => Some(b' '),
        Some("\\t") => Some(b'\t'),
        Some(d) => d.bytes().next(),
    };
    let delimiter = match spec.format {
        RecordFormat::Csv => delimiter.or(Some(b',')),
        RecordFormat::Tsv => delimiter.or(Some(b'\t')),
        RecordFormat::Delimited => delimiter,
        _ => return None,
    };
    Some(DelimitedOptions {
        delimiter,
        header_lines: spec.header_lines,
        has_column_names: spec.column_names,
        units_row: spec.units_row,
        description_row: spec.description_row,
    })
}

/// Reads one file as the source spec says; every refusal names the file and, where it can, the line.
pub fn load_record(spec: &SourceSpec, part: &InputPart) -> Result<Table, RecordError> {
    load_parsed(spec, part, &parse(spec, part)?)
}

/// `load`'s refusal of a record: the error its user sees and the file column it is about, where
/// it is about one (`validate` points at the line of the pipeline that names that column).
#[derive(Debug, thiserror::Error)]
#[error("{error}")]
pub struct RecordError {
    /// Boxed: a `UserError` (message, file, position, hint) is large, and this is every reader's `Err`.
    pub error: Box<UserError>,
    pub column: Option<String>,
}

impl RecordError {
    fn about(column: &str, error: UserError) -> Self {
        RecordError { error: Box::new(error), column: Some(column.to_string()) }
    }
}

impl From<UserError> for RecordError {
    fn from(error: UserError) -> Self {
        RecordError { error: Box::new(error), column: None }
    }
}

impl From<RecordError> for UserError {
    fn from(e: RecordError) -> Self {
        *e.error
    }
}

/// [`load_record`] of a file already parsed as `spec` says.
fn load_parsed(spec: &SourceSpec, part: &InputPart, raw: &RawRecord) -> Result<Table, RecordError> {
    // Messages quote the file's column names: their control characters are escaped.
    table_of(spec, part, raw).map_err(|mut e| {
        e.error.message = records::printable(&e.error.message).into_owned();
        e.error.hint = e.error.hint.map(|h| records::printable(&h).into_owned());
        e
    })
}

fn table_of(spec: &SourceSpec, part: &InputPart, raw: &RawRecord) -> Result<Table, RecordError> {
    let path = part.path.as_path();
    let err = |message: String| UserError::new(message).in_file(path);
    let format = read_as(spec, raw);

    // Time: an explicit column, the file's own time (RENADIC), or a sample interval. The other
    // columns are the record's channels.
    let all: Vec<&records::RawChannel> = raw.channels.iter().collect();
    let (explicit_time, channels) = if let Some(name) = &spec.time_column {
        let index = all.iter().position(|c| &c.name == name).ok_or_else(|| {
            RecordError::about(
                name,
                missing_column(path, name, &all)
                    .hint("set `time_column` to one of the file's columns, or drop it and give `dt`"),
            )
        })?;
        let channel = all[index];
        if let Some(other) = all.iter().skip(index + 1).find(|c| &c.name == name) {
            return Err(RecordError::about(
                name,
                repeated_column(path, spec, raw, channel, other)
                    .hint("`time_column` cannot tell them apart: rename one in the file"),
            ));
        }
        let factor = time_factor(path, spec, raw, channel).map_err(|e| RecordError::about(name, e))?;
        let time: Vec<f64> = channel.values.iter().map(|v| v * factor).collect();
        if let Some(i) = overflowed(&channel.values, &time) {
            return Err(RecordError::about(name, err(format!(
                "the time column `{name}` overflows in unit conversion: its sample {} ({}) times {factor} is not a finite number of seconds",
                i + 1,
                short(channel.values[i])
            ))
            .at(channel.first_data_line.map(|l| (l + i, 1)))
            .hint("the value is damaged, or `time_unit` is wrong")));
        }
        let others = all.iter().enumerate().filter(|&(i, _)| i != index).map(|(_, c)| *c).collect();
        (Some((time, channel.first_data_line)), others)
    } else {
        (raw.time.clone().map(|t| (t, raw.channels.first().and_then(|c| c.first_data_line))), all)
    };
    let selected: Vec<(String, &records::RawChannel, Option<&ColumnSpec>)> = if spec.columns.is_empty() {
        let names = default_names(spec, raw, &channels).map_err(|e| {
            err(e.to_string()).hint("map the channels yourself with `columns:` (output name → the file's channel name)")
        })?;
        channels.iter().zip(names).map(|(c, name)| (name, *c, None)).collect()
    } else {
        spec.columns
            .iter()
            .map(|(out, cs)| {
                let channel = channels.iter().find(|c| c.name == cs.file_column()).ok_or_else(|| {
                    RecordError::about(cs.file_column(), missing_column(path, cs.file_column(), &channels))
                })?;
                Ok((out.clone(), *channel, Some(cs)))
            })
            .collect::<Result<_, RecordError>>()?
    };
    distinct_names(path, spec, raw, &selected)?;
    // Channels of one file may differ in length (CSMIP, COSMOS, GeoNet): the table takes the
    // longest, a shorter channel is null where it has ended, and the record is flagged. No
    // sample is dropped.
    let n = selected.iter().map(|s| s.1.values.len()).max().unwrap_or(0);
    let flags: Vec<Flag> = selected
        .iter()
        .filter(|s| s.1.values.len() < n)
        .map(|(out, channel, _)| Flag {
            reason: format!(
                "channel `{}` (column `{out}`) has {} samples, the record's longest {n}: its last {} row(s) are null",
                channel.name,
                channel.values.len(),
                n - channel.values.len()
            ),
            file: channel_file(raw, channel).unwrap_or(&part.label).to_string(),
            line: channel.first_data_line,
        })
        .collect();
    if let Some((time, line)) = &explicit_time {
        if let Some((out, channel, _)) = selected.iter().find(|s| s.1.values.len() != time.len()) {
            return Err(RecordError::about(&channel.name, err(format!(
                "channel `{}` (column `{out}`) has {} samples but the time column {}: which time goes with which sample is unknown",
                channel.name,
                channel.values.len(),
                time.len()
            ))
            .at(line.map(|l| (l, 1)))
            .hint("a record with its own time column needs as many values in every channel: repair the file")));
        }
    }
    if n < 2 {
        return Err(err(format!("the record has {n} sample(s); at least 2 are needed")).into());
    }
    let mut metadata = BTreeMap::new();
    let (t0, dt, resampled_from) = match &explicit_time {
        Some((time, first_line)) => {
            if let Some(i) = time.iter().position(|v| !v.is_finite()) {
                return Err(err("the time column has a missing value".into())
                    .at(first_line.map(|l| (l + i, 1)))
                    .into());
            }
            match crate::table::uniform_step(time) {
                Ok(dt) => (time[0], dt, None),
                Err(bad) => match spec.non_uniform {
                    NonUniformPolicy::Error => {
                        let step = time[bad + 1] - time[bad];
                        return Err(err(format!(
                            "time is not uniformly sampled: the step after t = {} s is {step:.6} s, but the record's typical (median) step is {:.6} s",
                            time[bad],
                            crate::table::typical_step(time)
                        ))
                        .at(first_line.map(|l| (l + bad + 1, 1)))
                        .hint("fix the file, or set `non_uniform: resample` on the source to resample linearly onto the median step").into());
                    }
                    NonUniformPolicy::Resample => {
                        let dt = median_step(time).ok_or_else(|| err("time does not increase".into()))?;
                        (time[0], dt, Some(time.clone()))
                    }
                },
            }
        }
        None => {
            let dt = spec.dt.or(raw.dt).ok_or_else(|| {
                err("the record has no time column and no sample interval".into())
                    .hint("give `time_column: <name>` or `dt: <seconds>` on the source")
            })?;
            (0.0, dt, None)
        }
    };
    // The step and the rate in the metadata are finite, and so is every time of the output.
    if !(dt > 0.0 && (1.0 / dt).is_finite() && (t0 + (n - 1) as f64 * dt).is_finite()) {
        return Err(err(format!(
            "the sample interval {dt} s over {n} samples from t = {t0} s does not give finite, increasing times"
        ))
        .hint("the time column, DT or `dt` is damaged or in the wrong unit")
        .into());
    }

    let n_out = match &resampled_from {
        Some(time) => {
            // The median step of a damaged time column (a stray huge time, steps of 1e-300 s)
            // could ask for more samples than memory holds: a resampled record keeps to a
            // sane multiple of the samples it was made from.
            let span = ((time[n - 1] - t0) / dt).floor();
            if !(span.is_finite() && span < (MAX_RESAMPLING_GROWTH * n) as f64) {
                return Err(err(format!(
                    "resampling onto the median step ({dt} s) would turn {n} samples spanning {} s into {span:e}: more than {MAX_RESAMPLING_GROWTH} times as many",
                    time[n - 1] - t0
                ))
                .hint("the time column has a damaged value or a gap far longer than the record; repair it").into());
            }
            span as usize + 1
        }
        None => n,
    };
    let mut table = Table::new();
    let time: Vec<f64> = (0..n_out).map(|k| t0 + k as f64 * dt).collect();
    let mut columns = vec![Column::f64(TIME_COLUMN, "s", "time from the start of the record", time)];
    let mut conversions = serde_json::Map::new();
    let mut gaps = serde_json::Map::new();
    for (out_name, channel, column_spec) in selected {
        let detail = match column_spec {
            Some(ColumnSpec::Full(d)) => Some(d),
            _ => None,
        };
        let calibration = spec.calibration_table.iter().find(|c| c.channel == channel.name);
        let declared = detail.and_then(|d| d.unit.clone()).or_else(|| spec.unit.clone());
        let file_unit = (!channel.unit.is_empty()).then(|| channel.unit.clone());
        let unit_at = || unit_position(raw, channel);
        let unit_name = match calibration {
            Some(c) => {
                if let Some(physical) = file_unit.as_deref().filter(|u| units::raw_unit(u).is_none()) {
                    return Err(RecordError::about(&channel.name, err(format!(
                        "column `{}` is calibrated by line {} of `{}`, but the file says it is already in `{physical}`",
                        channel.name,
                        c.line,
                        spec.calibration.as_deref().unwrap_or_default()
                    ))
                    .at(unit_at())
                    .hint("calibrate raw channels only (V, mV, counts): remove its row from the table")));
                }
                c.unit.clone()
            }
            None => match declared.or(file_unit.clone()) {
                Some(unit) => unit,
                None => {
                    return Err(RecordError::about(&channel.name, err(format!("the unit of column `{}` is not known", channel.name))
                        .hint("set `unit:` on the source (e.g. `unit: g`) or on the column, or `units_row:` where the file has one")))
                }
            },
        };
        if let Some(raw_unit) = units::raw_unit(&unit_name) {
            let table = match &spec.calibration {
                Some(table) => format!("the calibration table `{table}` has no row for it"),
                None => "the source has no `calibration:` table".to_string(),
            };
            return Err(RecordError::about(&channel.name, err(format!("column `{}` is raw data in {raw_unit}: {table}", channel.name))
                .at(unit_at())
                .hint("add a row `channel,sensitivity,unit,offset` for it to the sensitivity table (docs/formats.md, NEES), or leave the column out with `columns:`")));
        }
        let conversion = units::conversion(&unit_name).ok_or_else(|| {
            RecordError::about(
                &channel.name,
                err(format!("unknown unit `{unit_name}` for column `{}`", channel.name))
                    .at(unit_at().filter(|_| calibration.is_none()))
                    .hint(format!("known units: {}", units::known_units().join(", "))),
            )
        })?;
        let factor = conversion.factor * spec.scale * detail.and_then(|d| d.scale).unwrap_or(1.0);
        let mut values: Vec<f64> = match calibration {
            Some(c) => channel.values.iter().map(|&v| c.apply(v) * factor).collect(),
            None => channel.values.iter().map(|v| v * factor).collect(),
        };
        if let Some(i) = overflowed(&channel.values, &values) {
            return Err(RecordError::about(&channel.name, err(format!(
                "column `{}` overflows in unit conversion: sample {} ({} {unit_name}) times {factor} is not a finite number of {}",
                channel.name,
                i + 1,
                short(channel.values[i]),
                conversion.si_unit
            ))
            .in_file(channel_file(raw, channel).map_or(path, std::path::Path::new))
            .at(channel.first_data_line.filter(|_| explicit_time.is_some() || format != RecordFormat::At2).map(|l| (l + i, 1)))
            .hint("the value is damaged, or the unit or `scale` is wrong; it is not a missing value, so `gaps: interpolate` does not fill it")));
        }
        let missing = values.iter().filter(|v| !v.is_finite()).count();
        if missing > 0 {
            match spec.gaps {
                GapPolicy::Error => {
                    let first = values.iter().position(|v| !v.is_finite()).expect("counted above");
                    return Err(RecordError::about(&channel.name, err(format!(
                        "column `{}` has {missing} missing value(s) (empty or NaN); the first is sample {}",
                        channel.name,
                        first + 1
                    ))
                    .in_file(channel_file(raw, channel).map_or(path, std::path::Path::new))
                    .at(channel.first_data_line.filter(|_| explicit_time.is_some() || format != RecordFormat::At2).map(|l| (l + first, 1)))
                    .hint("repair the file, or set `gaps: interpolate` on the source to fill gaps linearly (reported in the artifact)")));
                }
                GapPolicy::Interpolate => {
                    resample::fill_gaps_linear(&mut values);
                    gaps.insert(out_name.clone(), json!(missing));
                }
            }
        }
        if let Some(time) = &resampled_from {
            values = resample::resample_linear(time, &values, t0, dt, n_out);
        }
        // Gap filling has nothing to start from in a column of gaps only: it stays NaN, never
        // to be written. (Filling and resampling interpolate convexly: finite values stay finite.)
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            let cause = if missing == channel.values.len() {
                "every value is missing: `gaps: interpolate` has nothing to interpolate from"
            } else {
                "gap filling or resampling left it undefined"
            };
            return Err(RecordError::about(
                &channel.name,
                err(format!("column `{}`: output sample {} is not finite: {cause}", channel.name, i + 1))
                    .hint("check the column in the file, or leave it out with `columns:`"),
            ));
        }
        // True for every record of the dataset (readers of a partitioned dataset show one part's
        // field metadata for all); which file and column it came from is this file's metadata.
        let description = detail
            .and_then(|d| d.description.clone())
            .or_else(|| raw.header.get(&format!("channel.{}.description", channel.name)).cloned())
            .unwrap_or_else(|| {
                format!("the record's channel read as `{out_name}` (its file, column and unit: metadata shakeflow.input_file, shakeflow.load)")
            });
        // The channel's own sample count: the file's, whatever the table's length.
        let mut conversion_entry =
            json!({"file_column": channel.name, "file_unit": unit_name, "factor": factor, "npts": values.len()});
        if let Some(c) = calibration {
            conversion_entry["calibration"] = json!({
                "raw_unit": file_unit,
                "sensitivity": c.sensitivity,
                "offset": c.offset,
                "unit": c.unit,
                "table": spec.calibration,
                "table_line": c.line,
            });
        }
        conversions.insert(out_name.clone(), conversion_entry);
        columns.push(padded(Column::f64(&out_name, conversion.si_unit, &description, values), n_out));
    }
    table.extend(columns);
    let summary = json!({
        // The reader used (for `format: auto`, the one the file's content or extension chose).
        "format": format,
        "format_detected": spec.format == RecordFormat::Auto,
        "dt_s": dt,
        "sample_rate_hz": 1.0 / dt,
        "npts": n_out,
        "t0_s": t0,
        "columns": conversions,
        "gaps_filled": gaps,
        "resampled_from_non_uniform": resampled_from.is_some(),
        "header": raw.header,
    });
    if !flags.is_empty() {
        // Why the record is flagged (it loaded whole): the status table and the report list these.
        let listed: Vec<serde_json::Value> =
            flags.iter().map(|f| json!({"reason": f.reason, "file": f.file, "line": f.line})).collect();
        metadata.insert(FLAGS_KEY.to_string(), serde_json::Value::Array(listed).to_string());
    }
    metadata.insert("shakeflow.load".to_string(), summary.to_string());
    table.metadata = metadata;
    Ok(table)
}

/// Load metadata listing why a record that loaded is flagged: a JSON array of
/// `{"reason", "file", "line"}` (line null where the format has none to name).
pub use crate::pipeline::sink::FLAGS_KEY;

/// Something about a record that loaded whole but that its user should know.
struct Flag {
    reason: String,
    file: String,
    line: Option<usize>,
}

/// The file a channel of a `components:` record came from (as provenance names it).
fn channel_file<'a>(raw: &'a RawRecord, channel: &records::RawChannel) -> Option<&'a str> {
    raw.header.get(&format!("channel.{}.file", channel.name)).map(String::as_str)
}

/// `column` as a table of `rows` rows: a shorter channel becomes nullable, null past its end.
fn padded(column: Column, rows: usize) -> Column {
    match column.data {
        ColumnData::F64(values) if values.len() < rows => {
            let mut optional: Vec<Option<f64>> = values.into_iter().map(Some).collect();
            optional.resize(rows, None);
            Column { data: ColumnData::OptF64(optional), ..column }
        }
        _ => column,
    }
}

/// The factor to seconds of a time column: `time_unit` when given, else the unit its file states
/// (a units row), else seconds.
fn time_factor(
    path: &std::path::Path,
    spec: &SourceSpec,
    raw: &RawRecord,
    channel: &records::RawChannel,
) -> Result<f64, UserError> {
    let Some(unit) = spec.time_unit.as_deref().or((!channel.unit.is_empty()).then_some(channel.unit.as_str())) else {
        return Ok(1.0);
    };
    match units::conversion(unit) {
        Some(c) if c.si_unit == "s" => Ok(c.factor),
        _ => {
            Err(UserError::new(format!("the time column `{}` is in `{unit}`, which is not a time unit", channel.name))
                .in_file(path)
                .at(unit_position(raw, channel).filter(|_| spec.time_unit.is_none()))
                .hint("the time column's unit must be s or ms: fix the units row, or set `time_unit:` on the source"))
        }
    }
}

/// Where the file states a channel's unit (line, column of its units row), for errors about it.
fn unit_position(raw: &RawRecord, channel: &records::RawChannel) -> Option<(usize, usize)> {
    let at = raw.header.get(&format!("channel.{}.units_at", channel.name))?;
    let (line, column) = at.split_once(':')?;
    Some((line.parse().ok()?, column.parse().ok()?))
}

/// More samples than this many times a record's own would come from a damaged time column.
const MAX_RESAMPLING_GROWTH: usize = 100;

/// A number as a message shows it: 1e308, not 309 digits.
fn short(v: f64) -> String {
    if v != 0.0 && !(1e-4..1e15).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}

/// The first value that was finite in the file and is not after unit conversion.
fn overflowed(raw: &[f64], converted: &[f64]) -> Option<usize> {
    raw.iter().zip(converted).position(|(r, c)| r.is_finite() && !c.is_finite())
}

/// Refuses output columns that would share a name: two channels of the file with one name, a
/// channel named like the time column `load` adds, or a `columns:` entry naming a file column
/// the file has twice (which of the two would be read?).
fn distinct_names(
    path: &std::path::Path,
    spec: &SourceSpec,
    raw: &RawRecord,
    selected: &[(String, &records::RawChannel, Option<&ColumnSpec>)],
) -> Result<(), RecordError> {
    let mut seen: HashMap<&str, &records::RawChannel> = HashMap::with_capacity(selected.len());
    for (out, channel, column_spec) in selected {
        if out == TIME_COLUMN {
            let (what, about) = if column_spec.is_some() {
                (format!("the output column `{TIME_COLUMN}` under `columns:`"), None)
            } else {
                (format!("the file's column `{}`", channel.name), Some(channel.name.clone()))
            };
            let error =
                UserError::new(format!("{what} would collide with the time column `{TIME_COLUMN}` that `load` writes"))
                    .in_file(path)
                    .at(name_line(spec, raw, channel).map(|l| (l, 1)))
                    .hint(format!(
                "if it holds the time, set `time_column: {}` on the source; else give it another name with `columns:`",
                channel.name
            ));
            return Err(RecordError { error: Box::new(error), column: about });
        }
        if let Some(first) = seen.insert(out.as_str(), channel) {
            return Err(RecordError::about(&channel.name, repeated_column(path, spec, raw, first, channel).hint(
                "pick the channels with `columns:` (output name: file column), leaving out the repeated name, or rename one in the file",
            )));
        }
    }
    // A selected file column given twice in the file: `columns:` would silently take the first.
    let mut by_name: HashMap<&str, &records::RawChannel> = HashMap::with_capacity(raw.channels.len());
    for channel in &raw.channels {
        if let Some(first) = by_name.insert(channel.name.as_str(), channel) {
            if selected.iter().any(|(_, c, s)| s.is_some() && c.name == channel.name) {
                return Err(RecordError::about(
                    &channel.name,
                    repeated_column(path, spec, raw, first, channel)
                        .hint("`columns:` cannot tell them apart: rename one in the file"),
                ));
            }
        }
    }
    Ok(())
}

/// "the file has two columns named `x`", at the line naming them where the format has one.
fn repeated_column(
    path: &std::path::Path,
    spec: &SourceSpec,
    raw: &RawRecord,
    first: &records::RawChannel,
    second: &records::RawChannel,
) -> UserError {
    let index = |c: &records::RawChannel| raw.channels.iter().position(|o| std::ptr::eq(o, c)).map_or(0, |i| i + 1);
    UserError::new(format!(
        "the file has two columns named `{}` (columns {} and {} of {})",
        second.name,
        index(first),
        index(second),
        raw.channels.len()
    ))
    .in_file(path)
    .at(name_line(spec, raw, second).map(|l| (l, 1)))
}

/// The line that names `channel`: a delimited file's column-name row, an AT2 file's event line.
fn name_line(spec: &SourceSpec, raw: &RawRecord, channel: &records::RawChannel) -> Option<usize> {
    match raw.format {
        "delimited" if spec.column_names => channel.first_data_line.map(|l| l - 1),
        "at2" => Some(2),
        _ => None,
    }
}

/// Column names when a source has no `columns:` map. Accelerogram formats name their channels by
/// quantity and axis (`ax_mps2`, `ay_mps2`, `az_mps2`; `records::roles` says which channel is
/// which), so one source covers a suite of records whatever their files call the components;
/// delimited and RENADIC files, and `component_as: label`, keep the file's names.
fn default_names(
    spec: &SourceSpec,
    raw: &RawRecord,
    channels: &[&records::RawChannel],
) -> Result<Vec<String>, records::roles::AxesError> {
    use RecordFormat::*;
    let by_axis = matches!(read_as(spec, raw), At2 | SimcenterJson | Cosmos | Dmg | Smc | Knet | Esm | Geonet);
    if !by_axis || spec.component_as == Some(ComponentAs::Label) {
        return Ok(channels.iter().map(|c| c.name.clone()).collect());
    }
    let single = match spec.component_as {
        Some(ComponentAs::Ay) => Some('y'),
        _ => None,
    };
    let axes = records::roles::axes(raw, channels, single)?;
    Ok(channels
        .iter()
        .zip(axes)
        .map(|(c, axis)| {
            let unit = spec.unit.as_deref().or((!c.unit.is_empty()).then_some(c.unit.as_str()));
            match unit.and_then(units::conversion).map(|u| u.si_unit) {
                Some("m/s^2") => format!("a{axis}_mps2"),
                Some("m/s") => format!("v{axis}_mps"),
                Some("m") => format!("d{axis}_m"),
                // Not a motion (or an unknown unit, which the caller reports): the file's name.
                _ => c.name.clone(),
            }
        })
        .collect())
}

fn missing_column(path: &std::path::Path, name: &str, channels: &[&records::RawChannel]) -> UserError {
    let available: Vec<&str> = channels.iter().map(|c| c.name.as_str()).collect();
    let suggestion = did_you_mean_hint(name, available.iter().copied());
    // Names that are numbers: the row read as the header was a data row.
    if !available.is_empty() && available.iter().all(|n| n.trim().parse::<f64>().is_ok()) {
        return UserError::new(format!(
            "the file has no column `{name}`: the row read as its header holds numbers, so `header_lines` (the lines before the column names) is too large: lower it"
        ))
        .in_file(path);
    }
    UserError::new(format!("the file has no column `{name}`"))
        .in_file(path)
        .hint(format!("{suggestion}its columns are: {}", available.join(", ")))
}

fn median_step(time: &[f64]) -> Option<f64> {
    let median = crate::table::typical_step(time);
    (median > 0.0 && time.windows(2).all(|w| w[1] > w[0])).then_some(median)
}

/// For `shakeflow stage load FILE…`: a source spec guessed from the file, with `--set` overrides.
pub fn ad_hoc_source(
    path: &std::path::Path,
    overrides: &serde_json::Map<String, serde_json::Value>,
) -> anyhow::Result<SourceSpec> {
    let format = records::sniff_format(path).unwrap_or("delimited");
    let mut value = json!({"format": format, "path": path.display().to_string()});
    if format == "delimited" && !overrides.contains_key("time_column") && !overrides.contains_key("dt") {
        let skip = overrides.get("header_lines").and_then(|v| v.as_u64()).unwrap_or(0) as usize;
        for (key, guess) in guess_delimited_layout(path, skip) {
            if !overrides.contains_key(key) {
                value[key] = guess;
            }
        }
    }
    for (k, v) in overrides {
        value[k] = v.clone();
    }
    let mut spec: SourceSpec = serde_json::from_value(value.clone()).map_err(|e| {
        // serde names the type it expected, not the key: the key is the one whose removal helps.
        let culprit = overrides.keys().find(|key| {
            let mut without = value.clone();
            without.as_object_mut().map(|o| o.remove(key.as_str()));
            serde_json::from_value::<SourceSpec>(without).is_ok()
        });
        let what = match culprit {
            Some(key) => format!("--set {key}={}: {e}", overrides[key]),
            None => e.to_string(),
        };
        anyhow::anyhow!("{what}")
            .context("the --set values do not form a valid source (see `inputs:` in schemas/pipeline.schema.json)")
    })?;
    if let Some(table) = &spec.calibration {
        spec.calibration_table = records::read_calibration(std::path::Path::new(table)).map_err(user_error)?;
    }
    Ok(spec)
}

/// What a delimited file's column names say about it: a time column (`time_s`, `time`, `t`) and
/// a unit shared by every other column's suffix (`ax_mps2` → m/s^2, `a_g` → g), for
/// `shakeflow stage load FILE` without options. Pipelines state these explicitly.
fn guess_delimited_layout(path: &std::path::Path, skip: usize) -> Vec<(&'static str, serde_json::Value)> {
    use std::io::BufRead;
    let Ok(file) = std::fs::File::open(path) else { return Vec::new() };
    let Some(Ok(header)) =
        std::io::BufReader::new(file).lines().skip(skip).find(|l| l.as_ref().map_or(true, |l| !l.starts_with('#')))
    else {
        return Vec::new();
    };
    let names: Vec<&str> = header.split([',', '\t', ';']).map(str::trim).collect();
    let mut guesses = Vec::new();
    let Some(time) = names.iter().find(|n| ["time_s", "time", "t"].contains(&n.to_ascii_lowercase().as_str())) else {
        return guesses;
    };
    guesses.push(("time_column", json!(time)));
    const SUFFIXES: &[(&str, &str)] = &[("_mps2", "m/s^2"), ("_mps", "m/s"), ("_g", "g"), ("_rad", "rad"), ("_m", "m")];
    let unit_of = |name: &str| SUFFIXES.iter().find(|(s, _)| name.ends_with(s)).map(|(_, u)| *u);
    let units: Vec<Option<&str>> = names.iter().filter(|n| *n != time).map(|n| unit_of(n)).collect();
    if let Some(Some(first)) = units.first() {
        if units.iter().all(|u| *u == Some(first)) {
            guesses.push(("unit", json!(first)));
        }
    }
    guesses
}

#[cfg(test)]
mod tests {
    use super::*;

    const RECORD: &str = "RSN1084_NORTHR_SCS052.AT2";

    /// The record's header (`NPTS=   8773, DT=   .0050 SEC`) and values in g, read here with a
    /// plain split of the file's text.
    fn by_hand(path: &std::path::Path) -> (usize, f64, Vec<f64>) {
        let text = std::fs::read_to_string(path).unwrap();
        let header = text.lines().nth(3).unwrap();
        let field = |key: &str| header.split(key).nth(1).unwrap().split([',', 'S']).next().unwrap().trim().to_string();
        let values = text.lines().skip(4).flat_map(str::split_whitespace).map(|v| v.parse().unwrap()).collect();
        (field("NPTS=").parse().unwrap(), field("DT=").parse().unwrap(), values)
    }

    #[test]
    fn a_peer_record_loads_with_its_header_step_and_its_values_in_si() {
        let path = crate::signal::test_support::ground_motion_path(RECORD);
        let (npts, dt, values) = by_hand(&path);
        assert_eq!((npts, dt, values.len()), (8773, 0.005, 8773));
        let spec = ad_hoc_source(&path, &serde_json::Map::new()).unwrap();
        let part = InputPart { partition: vec![], path: path.clone(), label: RECORD.into(), hash: String::new() };
        let table = load_record(&spec, &part).unwrap();
        let time = table.f64_column(TIME_COLUMN).unwrap();
        assert_eq!(time.len(), npts);
        assert!((time[npts - 1] - time[0] - (npts - 1) as f64 * dt).abs() < 1e-9);
        let column = table.columns.iter().find(|c| c.name != TIME_COLUMN).unwrap();
        assert_eq!(column.unit, "m/s^2");
        let ColumnData::F64(loaded) = &column.data else { panic!("{} is not f64", column.name) };
        // Standard gravity, 9.806 65 m/s² per g (CGPM 1901).
        for (k, (&si, &g)) in loaded.iter().zip(&values).enumerate() {
            assert!((si - g * 9.80665).abs() <= 1e-12 * si.abs().max(1e-3), "sample {k}: {si} against {g} g");
        }
    }
}
