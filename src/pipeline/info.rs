//! What a stage type declares: its name and version, what it reads ([`InputKind`]), what it
//! writes ([`OutputInfo`]) and its parameters. The planner, the sink, `shakeflow stages` and the
//! JSON Schema read it; the stage contract (`stage.rs`) re-exports it for stage types.

use super::params::ParamSpec;
use super::spec::RecordFormat;

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
    /// `mcap` parameter (`stages::MCAP_PARAM`) asks for it.
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
