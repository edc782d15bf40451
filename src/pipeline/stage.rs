//! The stage contract: what the engine asks of a stage type and what it hands one.
//!
//! A stage type (an implementation in the `stages` module, nushell's command split) declares what it
//! reads, writes and takes as parameters ([`StageInfo`]), how it splits into work units
//! ([`WorkUnits`]) and runs one unit ([`Stage::run`]) on the inputs and sink the engine gives it
//! ([`StageContext`]). The engine knows stage types only through the [`Registry`] it is handed,
//! so it never imports their implementations.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

pub use super::info::{InputKind, OutputInfo, OutputKind, StageInfo};
pub use super::layout::{partition_path, Partition};
use super::memo::TableMemo;
use super::params::{ParamError, Params};
use super::sink::OutputSink;
use super::spec::SourceSpec;
use crate::table::Table;

/// The stage types a program offers, by the name pipelines use (the binary hands the engine the
/// stages module's `registry()`).
#[derive(Clone, Copy)]
pub struct Registry(pub &'static [&'static dyn Stage]);

impl Registry {
    pub fn find(&self, name: &str) -> Option<&'static dyn Stage> {
        self.0.iter().copied().find(|s| s.info().name == name)
    }

    pub fn names(&self) -> Vec<&'static str> {
        self.0.iter().map(|s| s.info().name).collect()
    }
}

/// How a record's partition is named inside tables (a `record` or `case` column): its values
/// joined by `/`, as other tables' key columns hold them (`CIGO360`, not `record=CIGO360`).
pub fn partition_values(partition: &Partition) -> String {
    partition.iter().map(|(_, v)| v.as_str()).collect::<Vec<_>>().join("/")
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

/// One per work unit (each holding its record's parts): the source's spec is shared, not copied.
#[derive(Debug, Clone)]
pub enum StageInput {
    Source { name: String, spec: Arc<SourceSpec>, base_dir: PathBuf, files: Vec<InputPart> },
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
    /// or else read from its file, or from the bytes of a file kept unwritten (the same table
    /// each way).
    pub fn read_table(&self, part: &InputPart) -> anyhow::Result<Arc<Table>> {
        if let Some(table) = self.memo.and_then(|memo| memo.take(&part.path)) {
            return Ok(table);
        }
        match self.memo.and_then(|memo| memo.unwritten(&part.path)) {
            Some(bytes) => Ok(Arc::new(crate::io::parquet::decode_table(bytes, &part.path)?)),
            None => Ok(Arc::new(crate::io::parquet::read_table(&part.path)?)),
        }
    }

    /// A `Path` parameter's value resolved against the base directory.
    pub fn file_path(&self, relative: &Path) -> PathBuf {
        self.base_dir.join(relative)
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

    /// That the normalised parameters deserialise into the stage type's parameter struct and
    /// back to the same map (`params::check_typed::<ItsParams>`): called by the planner after
    /// normalisation, so a struct that disagrees with its declaration is an error before
    /// anything runs; the stage's code then reads its parameters through `params::typed`.
    fn check_params(&self, params: &Params) -> Result<(), ParamError>;

    fn work_units(&self) -> WorkUnits {
        WorkUnits::Gather
    }

    /// For a per-record stage, the parts of the secondary input `other` that the unit of each
    /// record of `primaries` reads (one list per primary, in order): by default the part with the
    /// same partition, else all of `other`'s parts. One call per input, so that a stage can index
    /// `other` once: per primary, a scan of every part made planning quadratic in the records
    /// (8 % of a no-op rerun at 10³ tests, seconds at 10⁴).
    fn companions(&self, _params: &Params, primaries: &[InputPart], other: &StageInput) -> Vec<Vec<InputPart>> {
        let mut by_partition: HashMap<&Partition, Vec<&InputPart>> = HashMap::new();
        for part in other.parts() {
            by_partition.entry(&part.partition).or_default().push(part);
        }
        primaries
            .iter()
            .map(|primary| match by_partition.get(&primary.partition) {
                Some(same) => same.iter().map(|&p| p.clone()).collect(),
                None => other.parts().to_vec(),
            })
            .collect()
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

    /// The stage's results in one line, read from its committed output folder `stage_dir`
    /// (`shakeflow run` prints it after the run); None: nothing to say in one line, or its
    /// outputs cannot be read.
    fn summary(&self, _stage_dir: &Path) -> Option<String> {
        None
    }
}

/// A stage's output columns (None: not known) and the parameters naming columns its input lacks.
pub type ColumnCheck = (Option<Vec<String>>, Vec<ParamError>);
