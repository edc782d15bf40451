//! Stage types: one file each, registered by the name pipelines use.
//!
//! A stage is a thin adapter: it reads its inputs, calls pure numerics in `signal`/`physics`/`vision`,
//! and hands tables to the [`OutputSink`]. It never decides where files go or whether to run.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::pipeline::memo::TableMemo;
use crate::pipeline::params::{ParamError, ParamSpec, Params};
use crate::pipeline::sink::OutputSink;
use crate::pipeline::spec::{RecordFormat, SourceSpec};
use crate::table::Table;

pub mod baseline;
pub mod compare;
pub mod cpt_calibrate;
pub mod cpt_project;
pub mod cpt_track;
pub mod detect_toppling;
pub mod diagnose;
pub mod load;
pub mod report;
pub mod simulate_rolling;
pub mod simulate_toppling;
pub mod synchronize;
pub mod toppling_fragility;
pub mod transfer_function;

/// What a stage type consumes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputKind {
    /// Record sources declared under `inputs:` (raw files).
    Sources,
    /// Datasets written by other stages.
    Datasets,
    /// Sources of these non-record formats (an image sequence, control points), whose files
    /// the stage reads itself; a `frames` source may name folders.
    Files(&'static [RecordFormat]),
}

#[derive(Debug, Clone, Copy)]
pub struct OutputInfo {
    pub name: &'static str,
    pub description: &'static str,
    pub kind: OutputKind,
}

/// What an output holds, which decides how the sink writes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputKind {
    /// Parquet tables, one per record.
    Table,
    /// Parquet tables with a `time_s` column, also written as MCAP for Foxglove when the stage's
    /// `mcap` parameter ([`MCAP_PARAM`]) asks for it.
    TimeSeries,
    /// Files written as they are (figures, reports).
    Files,
    /// One file written as it is, at the root of the stage's folder and named by the output
    /// (`report`'s `index.html`, opened by a person rather than read by another stage).
    Page,
}

impl OutputKind {
    /// How `shakeflow stages` names the files of an output.
    pub fn describe(self) -> &'static str {
        match self {
            OutputKind::Table => "Parquet",
            OutputKind::TimeSeries => "Parquet (+ MCAP with `mcap: true`)",
            OutputKind::Files => "files",
            OutputKind::Page => "one file",
        }
    }
}

#[derive(Debug)]
pub struct StageInfo {
    pub name: &'static str,
    /// Bumped whenever the stage's results change for the same inputs; part of the cache key.
    pub version: u32,
    pub summary: &'static str,
    pub inputs: InputKind,
    pub outputs: &'static [OutputInfo],
    pub params: &'static [ParamSpec],
}

/// The `mcap` parameter of every stage with a time-series output. Off by default: a twin repeats
/// its Parquet table at about twice the size (lz4 chunks of 9-byte protobuf values against
/// byte-stream-split floats), which made MCAP half the demo study's disk (docs/benchmarks.md,
/// footprint).
pub const MCAP_PARAM: ParamSpec = ParamSpec {
    name: "mcap",
    kind: crate::pipeline::params::ParamKind::Bool,
    default: Some("false"),
    unit: "",
    description:
        "also write the time series as MCAP (lz4 chunks, protobuf) for Foxglove; opt-in: about twice the Parquet's size",
    range: None,
};

/// Partition keys of a record (`motion=FB-4/floor=5`), in order.
pub type Partition = Vec<(String, String)>;

/// The dataset folder of a record: `key=value` segments, each value percent-encoded where it is
/// not a plain name (`090 (CUE)` → `090%20%28CUE%29`), so no value can leave its folder.
pub fn partition_path(partition: &Partition) -> String {
    use crate::pipeline::paths::encode_component;
    partition
        .iter()
        .map(|(k, v)| format!("{}={}", encode_component(k), encode_component(v)))
        .collect::<Vec<_>>()
        .join("/")
}

/// How a record's partition is named inside tables (a `record` or `case` column): its values
/// joined by `/`, as other tables' key columns hold them (`CIGO360`, not `record=CIGO360`).
pub fn partition_values(partition: &Partition) -> String {
    partition.iter().map(|(_, v)| v.as_str()).collect::<Vec<_>>().join("/")
}

/// The file stem of a per-record figure: the partition path with `/` as `_` (`motion=FB-4`), or
/// `fallback` for a record without partition keys. Stages name their figures with it and `report`
/// links to them by it.
pub fn figure_stem(partition: &Partition, fallback: &str) -> String {
    match partition_path(partition) {
        p if p.is_empty() => fallback.to_string(),
        p => p.replace('/', "_"),
    }
}

/// A record as a figure's title names it: its partition values, `motion` bare and other keys
/// with their name (`FB-4`, `FB-4, floor 5`), or `fallback` without partition keys.
pub fn record_title(partition: &Partition, fallback: &str) -> String {
    if partition.is_empty() {
        return fallback.to_string();
    }
    let named: Vec<String> =
        partition.iter().map(|(k, v)| if k == "motion" { v.clone() } else { format!("{k} {v}") }).collect();
    named.join(", ")
}

/// One file a stage reads: a raw record file or one part of an upstream dataset.
#[derive(Debug, Clone)]
pub struct InputPart {
    pub partition: Partition,
    pub path: PathBuf,
    /// How provenance names the file: relative to the pipeline, or `stage.output/partition`,
    /// never a machine- or run-specific path, so artifacts stay bit-identical across machines.
    pub label: String,
    /// Content hash (blake3, hex): provenance written into every artifact made from it.
    pub hash: String,
}

// A handful exist per run: boxing the source spec would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum StageInput {
    Source { name: String, spec: SourceSpec, base_dir: PathBuf, files: Vec<InputPart> },
    Dataset { name: String, parts: Vec<InputPart> },
}

impl StageInput {
    pub fn name(&self) -> &str {
        match self {
            StageInput::Source { name, .. } | StageInput::Dataset { name, .. } => name,
        }
    }

    pub fn parts(&self) -> &[InputPart] {
        match self {
            StageInput::Source { files, .. } => files,
            StageInput::Dataset { parts, .. } => parts,
        }
    }
}

pub struct StageContext<'a> {
    pub stage_name: &'a str,
    pub params: &'a Params,
    pub inputs: &'a [StageInput],
    pub sink: &'a OutputSink,
    /// What relative `Path` parameters are relative to: the pipeline file's folder (the current
    /// folder for `shakeflow stage`).
    pub base_dir: &'a Path,
    /// Tables upstream stages of this run wrote and kept in memory (none for `shakeflow stage`).
    pub memo: Option<&'a TableMemo>,
}

impl StageContext<'_> {
    /// The table of a Parquet input part: kept in memory by the stage that wrote it this run,
    /// or else read from its file (the same table either way).
    pub fn read_table(&self, part: &InputPart) -> anyhow::Result<Arc<Table>> {
        match self.memo.and_then(|memo| memo.take(&part.path)) {
            Some(table) => Ok(table),
            None => Ok(Arc::new(crate::io::parquet::read_table(&part.path)?)),
        }
    }

    /// A `Path` parameter resolved against the base directory; None when it is null.
    pub fn file_param(&self, key: &str) -> Option<PathBuf> {
        self.params.get(key).and_then(|v| v.as_str()).map(|p| self.base_dir.join(p))
    }
}

/// How the engine splits a stage into work units, each with its own cache key and lockfile entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WorkUnits {
    /// One unit per record of any of its inputs (a file of a source, a part of a dataset); the
    /// unit writes that record's partition only.
    EachRecord,
    /// One unit per part of input number `primary`, with the parts of its other inputs that
    /// [`Stage::companions`] pairs with it; the unit writes that part's partition only.
    PerRecordOf { primary: usize },
    /// One unit over all its inputs (a fragility fit, a report, a diagnosis over cases).
    Gather,
}

pub trait Stage: Sync + Send {
    fn info(&self) -> &'static StageInfo;
    /// Runs on the records `ctx.inputs` holds: all of them for a gathering stage, one record
    /// (and its companions) per call for a per-record stage.
    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()>;

    fn work_units(&self) -> WorkUnits {
        WorkUnits::Gather
    }

    /// For a per-record stage, the parts of the secondary input `other` that the unit of
    /// record `primary` reads: by default the part with the same partition, else the input's only
    /// part, else all of them.
    fn companions(&self, _params: &Params, primary: &InputPart, other: &StageInput) -> Vec<InputPart> {
        let same: Vec<InputPart> = other.parts().iter().filter(|p| p.partition == primary.partition).cloned().collect();
        if same.is_empty() {
            other.parts().to_vec()
        } else {
            same
        }
    }

    /// Checks that need several parameters at once, or the files they name, before anything
    /// runs (so `shakeflow validate` reports them at the parameter's line).
    fn check(&self, _params: &Params, _base_dir: &Path) -> Result<(), ParamError> {
        Ok(())
    }

    /// The columns of the stage's first output made from `input`, the columns its inputs' records
    /// have (None: not known), for `shakeflow validate` to carry column names through a pipeline,
    /// with an error for each parameter value naming a column the input lacks. None: the output's
    /// columns are not known, so stages downstream are not checked. The default knows nothing.
    fn output_columns(&self, _params: &Params, _input: Option<&[String]>) -> ColumnCheck {
        (None, Vec::new())
    }
}

/// A stage's output columns (None: not known) and the parameters naming columns its input lacks.
pub type ColumnCheck = (Option<Vec<String>>, Vec<ParamError>);

/// Refuses a column parameter (`key`) naming `column` when the input's `columns` lack it.
pub fn require_column(key: &str, column: &str, columns: &[String]) -> Result<(), ParamError> {
    if columns.iter().any(|c| c == column) {
        return Ok(());
    }
    let suggestion = crate::error::did_you_mean_hint(column, columns.iter().map(String::as_str));
    Err(ParamError {
        key: Some(key.to_string()),
        message: format!("parameter `{key}` names the column `{column}`, which the input records do not have"),
        hint: format!("{suggestion}the input's columns: {}", columns.join(", ")),
    })
}

pub fn registry() -> &'static [&'static dyn Stage] {
    &[
        &load::Load,
        &baseline::Baseline,
        &synchronize::Synchronize,
        &transfer_function::TransferFunction,
        &detect_toppling::DetectToppling,
        &simulate_toppling::SimulateToppling,
        &toppling_fragility::TopplingFragility,
        &diagnose::Diagnose,
        &report::Report,
        &cpt_calibrate::CptCalibrate,
        &cpt_track::CptTrack,
        &cpt_project::CptProject,
        &compare::Compare,
        &simulate_rolling::SimulateRolling,
    ]
}

pub fn find(name: &str) -> Option<&'static dyn Stage> {
    registry().iter().copied().find(|s| s.info().name == name)
}

pub fn names() -> Vec<&'static str> {
    registry().iter().map(|s| s.info().name).collect()
}

/// Per-record metadata keys shared by all stages, so readers find provenance in one place.
pub fn record_provenance(part: &InputPart) -> BTreeMap<String, String> {
    BTreeMap::from([
        ("shakeflow.input_file".to_string(), part.label.clone()),
        ("shakeflow.input_hash".to_string(), part.hash.clone()),
    ])
}

/// `a -> b` → (a, Some(b)); `a` → (a, None). Pairs of columns in stage parameters.
pub fn split_pair(text: &str) -> (String, Option<String>) {
    match text.split_once("->") {
        Some((a, b)) => (a.trim().to_string(), Some(b.trim().to_string())),
        None => (text.trim().to_string(), None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_stage_with_time_series_has_the_opt_in_mcap_parameter() {
        for stage in registry() {
            let info = stage.info();
            let series = info.outputs.iter().any(|o| o.kind == OutputKind::TimeSeries);
            let mcap = info.params.iter().find(|p| p.name == "mcap");
            assert_eq!(mcap.is_some(), series, "{}: `mcap` exactly where there are time series", info.name);
            if let Some(p) = mcap {
                assert_eq!(p.default, Some("false"), "{}: MCAP twins are opt-in", info.name);
            }
        }
    }
}
