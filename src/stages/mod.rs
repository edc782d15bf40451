//! Stage types: one file each, registered by the name pipelines use.
//!
//! A stage is a thin adapter: it reads its inputs, calls pure numerics in `signal`/`physics`/`vision`,
//! and hands tables to the [`OutputSink`]. It never decides where files go or whether to run.

use std::collections::BTreeMap;

pub use crate::declare::Declared;
use crate::pipeline::params::{ParamError, ParamSpec};
// The contract lives in the engine (`pipeline::stage`); stage files name it from here.
pub use crate::pipeline::stage::{
    partition_path, partition_values, ColumnCheck, InputKind, InputPart, OutputInfo, OutputKind, Partition, Registry,
    Stage, StageContext, StageInfo, StageInput, WorkUnits,
};

pub mod error;
pub mod reference;

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

/// The `mcap` switch of every stage with a time-series output (flattened into its parameters).
#[derive(Debug, serde::Deserialize, serde::Serialize)]
pub struct Mcap {
    /// Read by the engine's sink.
    pub mcap: bool,
}

impl Declared for Mcap {
    fn declare(out: &mut Vec<ParamSpec>) {
        out.push(MCAP_PARAM);
    }
}

crate::choice! {
    /// `method` of the rocking stages and `integrator` of `simulate_rolling`: adaptive
    /// Dormand–Prince 5(4) or fixed-step RK4.
    pub enum Integrator { Adaptive = "adaptive", Rk4 = "rk4" }
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

/// A text column without a unit (`case`, `verdict`, `unit`, `motion` … of the stages' tables).
pub fn text_column(name: &str, description: &str, values: Vec<String>) -> crate::table::Column {
    crate::table::Column {
        name: name.into(),
        unit: String::new(),
        description: description.into(),
        data: crate::table::ColumnData::Str(values),
    }
}

/// Float columns declared as rows `(name, unit, description, values)`, in the table's order: the
/// simulation stages' time series read as a list of their columns.
pub fn f64_columns<'a>(
    rows: impl IntoIterator<Item = (&'a str, &'a str, &'a str, Vec<f64>)>,
) -> Vec<crate::table::Column> {
    rows.into_iter()
        .map(|(name, unit, description, values)| crate::table::Column::f64(name, unit, description, values))
        .collect()
}

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

/// What a stage type offers beyond the engine's contract ([`Stage`], which knows no stage):
/// what the study report shows of its outputs and the example pipelines its documentation shows.
/// Each stage file implements it next to its `Stage`; the defaults say nothing.
pub trait StageType: Stage {
    /// The outputs `report` shows and as what (`(output name, what it shows)`), so a stage whose
    /// outputs are of a kind the report already shows appears in it without an edit there.
    fn shown(&self) -> &'static [(&'static str, Shown)] {
        &[]
    }

    /// Pipelines showing the stage at work (docs/stages.md prints them), each run as a test on
    /// the shared records (`every_stage_example_runs`, tests/it/stage_examples.rs).
    fn examples(&self) -> &'static [Example] {
        &[]
    }
}

/// One documented use of a stage type: a pipeline on data anyone here has ([`ExampleData`]),
/// one of its stages named as the stage type (the stage shown).
pub struct Example {
    /// What it shows, in one line.
    pub title: &'static str,
    /// The sources it reads and the stages loading them.
    pub data: &'static ExampleData,
    /// YAML: the entries under `stages:` after the data's (not indented).
    pub stages: &'static str,
}

/// The head of example pipelines: their sources and the stages loading them. Paths are relative
/// to a pipeline in the project's root folder: the shared data (`../shared`), or the demo archive
/// as `shakeflow demo-archive runs/demo-archive` writes it.
pub struct ExampleData {
    /// What the sources are, as docs/stages.md names them.
    pub what: &'static str,
    /// YAML: `inputs:`, then `stages:` and the stages loading the sources (indented as in the file).
    pub head: &'static str,
}

/// The shared Rinaldi record of Northridge 1994 (three components in PEER AT2 files, `ax_mps2`,
/// `ay_mps2`, `az_mps2`) loaded by a stage `load`.
pub const RINALDI: ExampleData = ExampleData {
    what: "the shared Rinaldi record",
    head: "\
inputs:
  rinaldi:
    description: Rinaldi Receiving Station, Northridge 1994 (PEER NGA-West2), three components
    format: at2
    path: ../shared/data/ground_motions/Rinaldi{component}.AT2
    partition: {station: Rinaldi}
    components: {key: component}
stages:
  load:
    type: load
    inputs: [rinaldi]
",
};

/// The demo archive's camera: its surveyed control points and its video's frames (no stage loads
/// them; the `cpt_*` stages read them).
pub const DEMO_CAMERA: ExampleData = ExampleData {
    what: "the demo archive's camera (`shakeflow demo-archive runs/demo-archive` writes it)",
    head: "\
inputs:
  control_points:
    description: the demo camera's 14 surveyed control points (world mm and pixels measured by hand, 0.5 px noise)
    format: control_points
    path: runs/demo-archive/cpt/control_points.csv
  video:
    description: 960x540, 30 fps frames of a rocking stretcher panel (markers M1 low, M2 high) and a rolling cart top (M3, M4)
    format: frames
    path: runs/demo-archive/cpt/frames
stages:
",
};

impl Example {
    /// The whole pipeline.
    pub fn pipeline(&self) -> String {
        let entries: String = self.stages.lines().map(|line| format!("  {line}\n")).collect();
        format!("version: 1\noutput_dir: out\n{}{entries}", self.data.head)
    }
}

/// What the study report shows of a stage output: each stage type names its outputs and their
/// kind (`StageType::shown`), so the report routes on the kind, never on stage names. In the
/// order the page lists what it lacks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Shown {
    /// frequencies identified per white-noise test (`output`, `frequency_hz`)
    Frequencies,
    /// toppling found in the records (`channel`, `toppled`, `impact_time_s`, `confidence`)
    Toppling,
    /// rocking simulations' event tables (a `summary` row's `overturned`, …)
    Rocking,
    /// fragility fits (`median`, `beta`, …)
    Fragility,
    /// rolling simulations' event tables
    Rolling,
    /// diagnosed cases (`case`, `verdict`, …)
    Diagnosis,
    /// transfer-function spectra for the figures (`frequency_hz`, `h1_gain`, `coherence`)
    Spectra,
    /// records with `time_s` for the figures (any such table is read as one)
    Records,
    /// every record's load status
    RecordStatus,
}

/// A doc comment's text as a macro sees it (`/// text` is `#[doc = " text"]`, lines joined by
/// `concat!`) without the space after `///`: how [`declare_stage`] reads the summary, the
/// outputs' descriptions and the examples' titles from doc comments.
pub const fn doc_text(doc: &'static str) -> &'static str {
    doc.trim_ascii_start()
}

/// A stage type declared in one block, read as it is written: the summary is the doc comment
/// of the stage's struct (which the block defines), then its YAML name, version, what it reads
/// ([`InputKind`]) and its parameter struct; each output, under its doc comment (what it holds),
/// by name and [`OutputKind`], with `=> ` the [`Shown`] kind the study report shows it as; each
/// example pipeline, under its doc comment (its title), by the [`ExampleData`] it reads and the
/// YAML of its stages. The block writes the file's `static INFO` (which [`info_and_check_params`]
/// returns) and the stage's [`StageType`] (`shown`, `examples`). A doc comment of several lines
/// is joined with spaces.
///
/// ```ignore
/// declare_stage! {
///     /// Remove a least-squares polynomial trend from each channel.
///     pub struct Baseline: "baseline", version 5, reads Datasets, params BaselineParams;
///     outputs {
///         /// the input tables with each selected channel baseline-corrected
///         "records": TimeSeries,
///     }
///     examples {
///         /// the study's cubic baseline removed from every channel
///         super::RINALDI => "baseline:\n  type: baseline\n  inputs: [load]\n",
///     }
/// }
/// ```
macro_rules! declare_stage {
    (
        $(#[doc = $summary:literal])+
        pub struct $stage:ident: $name:literal, version $version:literal,
            reads $reads:ident $(($formats:expr))?, params $params:ident;
        outputs {
            $($(#[doc = $description:literal])+ $output:literal: $kind:ident $(=> $shown:ident)?,)+
        }
        $(examples {
            $($(#[doc = $title:literal])+ $data:path => $yaml:literal,)+
        })?
    ) => {
        $(#[doc = $summary])+
        pub struct $stage;

        static INFO: std::sync::LazyLock<$crate::stages::StageInfo> =
            std::sync::LazyLock::new(|| $crate::stages::StageInfo {
                name: $name,
                version: $version,
                summary: $crate::stages::doc_text(concat!($($summary),+)),
                inputs: $crate::stages::InputKind::$reads $(($formats))?,
                outputs: {
                    const OUTPUTS: &[$crate::stages::OutputInfo] = &[$($crate::stages::OutputInfo {
                        name: $output,
                        description: $crate::stages::doc_text(concat!($($description),+)),
                        kind: $crate::stages::OutputKind::$kind,
                    }),+];
                    OUTPUTS
                },
                params: <$params as $crate::stages::Declared>::specs(),
            });

        impl $crate::stages::StageType for $stage {
            fn shown(&self) -> &'static [(&'static str, $crate::stages::Shown)] {
                &[$($(($output, $crate::stages::Shown::$shown),)?)+]
            }

            $(
                fn examples(&self) -> &'static [$crate::stages::Example] {
                    const EXAMPLES: &[$crate::stages::Example] = &[$($crate::stages::Example {
                        title: $crate::stages::doc_text(concat!($($title),+)),
                        data: &$data,
                        stages: $yaml,
                    }),+];
                    EXAMPLES
                }
            )?
        }
    };
}
pub(crate) use declare_stage;

/// In a stage's `impl Stage`: `info` returns the file's `INFO` ([`declare_stage`]) and
/// `check_params` checks the parameters against the struct `$params` ([`crate::pipeline::params::check_typed`]).
macro_rules! info_and_check_params {
    ($params:ty) => {
        fn info(&self) -> &'static $crate::stages::StageInfo {
            &INFO
        }

        fn check_params(
            &self,
            params: &$crate::pipeline::params::Params,
        ) -> Result<(), $crate::pipeline::params::ParamError> {
            $crate::pipeline::params::check_typed::<$params>(params)
        }
    };
}
pub(crate) use info_and_check_params;

/// The stage types, each named once: [`registry`] for the engine and [`stage_types`] for what
/// the engine does not ask.
macro_rules! stage_types {
    ($($module:ident :: $stage:ident),* $(,)?) => {
        // Each stage's file is declared here, from its line in the list: a stage is one file and
        // one line.
        $(pub mod $module;)*

        /// Every stage type, by the name pipelines use: the list the engine is handed.
        pub fn registry() -> Registry {
            Registry(&[$(&$module::$stage),*])
        }

        /// Every stage type, in the registry's order, with what the engine does not ask of it.
        pub fn stage_types() -> &'static [&'static dyn StageType] {
            &[$(&$module::$stage),*]
        }
    };
}

stage_types![
    load::Load,
    baseline::Baseline,
    synchronize::Synchronize,
    transfer_function::TransferFunction,
    detect_toppling::DetectToppling,
    simulate_toppling::SimulateToppling,
    toppling_fragility::TopplingFragility,
    diagnose::Diagnose,
    report::Report,
    cpt_calibrate::CptCalibrate,
    cpt_track::CptTrack,
    cpt_project::CptProject,
    compare::Compare,
    simulate_rolling::SimulateRolling,
];

/// The stage type named `name` (a table's `shakeflow.stage_type`).
pub fn stage_type(name: &str) -> Option<&'static dyn StageType> {
    stage_types().iter().copied().find(|s| s.info().name == name)
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
    use crate::pipeline::params::{normalize, ParamKind};
    use serde_json::{json, Value};

    /// A value within the declaration's kind and range.
    fn sample(spec: &ParamSpec) -> Value {
        let x = spec.range.map_or(1.0, |(lo, hi)| if (lo..=hi).contains(&1.0) { 1.0 } else { lo });
        match spec.kind {
            ParamKind::Float => json!(x),
            ParamKind::Int => json!(x as i64),
            ParamKind::Bool => json!(true),
            ParamKind::Str => json!("a"),
            ParamKind::Choice(options) => json!(options[0]),
            ParamKind::StrList => json!(["a"]),
            ParamKind::FloatList(n) => json!(vec![x; n.unwrap_or(2)]),
            ParamKind::Path => json!("equipment.yaml"),
        }
    }

    /// Every stage type's declared defaults (required parameters given a sample value) read into
    /// its parameter struct: a default written as a value its field's type cannot take fails here.
    #[test]
    fn every_stage_takes_its_own_defaults() {
        for stage in registry().0 {
            let info = stage.info();
            let required = info.params.iter().filter(|p| p.default.is_none()).map(|p| (p.name, sample(p)));
            let params = normalize(info.params, info.name, required).unwrap_or_else(|e| panic!("{}: {e}", info.name));
            stage.check_params(&params).unwrap_or_else(|e| panic!("{}: {e}", info.name));
        }
    }

    /// `baseline`'s declaration with a struct that has a field too many: the defect of a stage
    /// whose struct and declaration drifted apart.
    struct Drifted;

    #[derive(serde::Deserialize, serde::Serialize)]
    #[serde(deny_unknown_fields)]
    struct DriftedParams {
        order: usize,
        columns: Vec<String>,
        mcap: bool,
        window: Option<f64>,
    }

    impl Stage for Drifted {
        fn info(&self) -> &'static StageInfo {
            Stage::info(&baseline::Baseline)
        }

        fn check_params(&self, params: &crate::pipeline::params::Params) -> Result<(), ParamError> {
            crate::pipeline::params::check_typed::<DriftedParams>(params)
        }

        fn run(&self, _ctx: &StageContext<'_>) -> anyhow::Result<()> {
            unreachable!("the planner refuses it")
        }
    }

    /// The planner checks every stage's struct against its declaration before anything runs:
    /// a disagreement is an error at the stage's line, not a panic in a worker.
    #[test]
    fn a_stage_whose_struct_disagrees_is_refused_when_planned() {
        let text = "version: 1\noutput_dir: out\ninputs:\n  rec:\n    format: at2\n    path: a.AT2\nstages:\n  l:\n    type: load\n    inputs: [rec]\n  b:\n    type: baseline\n    inputs: [l]\n";
        let file = || crate::pipeline::spec::PipelineFile::parse(std::path::Path::new("p.yaml"), text.into()).unwrap();
        assert!(crate::pipeline::plan::Plan::new(file(), registry()).is_ok());
        let drifted = Registry(&[&load::Load, &Drifted]);
        let err = crate::pipeline::plan::Plan::new(file(), drifted).err().expect("the plan was accepted");
        assert!(err.message.contains("do not fit `DriftedParams`: field `window` is not declared"), "{err}");
        assert_eq!(err.line, Some(11), "{err}");
        assert!(err.hint.unwrap().contains("a defect of shakeflow"));
    }

    #[test]
    fn every_stage_with_time_series_has_the_opt_in_mcap_parameter() {
        for stage in registry().0 {
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

/// Tables as stages write them, for the tests of each stage's one line of results
/// (`Stage::summary`), which sit beside the stage.
#[cfg(test)]
pub(crate) mod test_tables {
    use crate::table::{Column, ColumnData, Table};
    use std::path::Path;

    /// One part of `<stage>/<output>` as a stage writes it (provenance, partition metadata).
    pub fn part(dir: &Path, output: &str, partition: &str, columns: Vec<Column>) {
        let mut t = Table::new();
        t.extend(columns);
        for (k, v) in [("shakeflow.stage", "s"), ("shakeflow.output", output), ("shakeflow.partition", partition)] {
            t.metadata.insert(k.into(), v.into());
        }
        let folder = dir.join(output).join(partition);
        std::fs::create_dir_all(&folder).unwrap();
        crate::io::parquet::write_table(&folder.join("data.parquet"), &t).unwrap();
    }

    pub fn text(name: &str, v: &[&str]) -> Column {
        super::text_column(name, "d", v.iter().map(|s| s.to_string()).collect())
    }

    pub fn flag(name: &str, v: &[bool]) -> Column {
        Column { name: name.into(), unit: String::new(), description: "d".into(), data: ColumnData::Bool(v.to_vec()) }
    }

    /// A stage type without a line, and outputs that are not there, say nothing.
    #[test]
    fn a_stage_without_a_line_or_its_outputs_says_nothing() {
        use super::Stage;
        let dir = crate::tempdir::tempdir().unwrap();
        part(dir.path(), "diagnosis", "", vec![text("verdict", &["none"])]);
        assert_eq!(super::baseline::Baseline.summary(dir.path()), None);
        assert!(super::diagnose::Diagnose.summary(dir.path()).is_some());
        assert_eq!(super::diagnose::Diagnose.summary(&dir.path().join("absent")), None);
    }
}
