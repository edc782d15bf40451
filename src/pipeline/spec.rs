//! The pipeline file: what a user writes, parsed strictly (unknown keys are errors).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use indexmap::IndexMap;
use serde::{Deserialize, Serialize};

use crate::error::UserError;

/// The pipeline format version this build reads.
pub const FORMAT_VERSION: u32 = 1;

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PipelineSpec {
    /// Format version of the file; 1.
    pub version: u32,
    #[serde(default)]
    pub description: Option<String>,
    /// Where artifacts and the lockfile go, relative to the pipeline file.
    pub output_dir: String,
    /// Record sources: files on disk that `load` stages read.
    #[serde(default)]
    pub inputs: IndexMap<String, SourceSpec>,
    /// The processing steps, by name, in the order a reader should follow them.
    pub stages: IndexMap<String, StageSpec>,
    /// Options of the Slurm executor (`run --executor slurm`); flags override them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub executor: Option<crate::pipeline::slurm::ExecutorOptions>,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct StageSpec {
    /// The stage type (see `shakeflow stages`).
    #[serde(rename = "type")]
    pub stage_type: String,
    #[serde(default)]
    pub description: Option<String>,
    /// Sources or other stages this stage reads: `name` or `stage.output`.
    #[serde(default)]
    pub inputs: Vec<String>,
    /// Stage parameters; unknown names are errors, omitted ones take their defaults.
    #[serde(default)]
    pub params: BTreeMap<String, serde_yaml::Value>,
    /// Only the input records whose partition keys take these values (`motion: [WN-1, WN-6]`).
    #[serde(default)]
    pub select: BTreeMap<String, Vec<String>>,
    /// `false`: an intermediate. Its files are removed at the commit once every stage reading
    /// them is up to date, and made again (the same bytes) when one of those must rerun; its
    /// lockfile entry, with the files' hashes, stays.
    #[serde(default = "keep_by_default", skip_serializing_if = "is_true")]
    pub keep: bool,
}

fn keep_by_default() -> bool {
    true
}

fn is_true(value: &bool) -> bool {
    *value
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RecordFormat {
    /// Delimited text: CSV, TSV or whitespace-separated columns.
    Delimited,
    Csv,
    Tsv,
    /// PEER NGA `.AT2` (both header styles).
    At2,
    /// RENADIC (Universidad de Chile) Vol.1 uncorrected accelerogram.
    RenadicV1,
    /// SimCenter event JSON (`dT`, `data_x`, `data_y`).
    SimcenterJson,
    /// COSMOS Strong-Motion Data Format v1.20 (`.v0c`, `.V1c`, `.V2c`; CESMD), one or more channels.
    Cosmos,
    /// CSMIP/CGS (formerly CDMG) Vol.1 (`.V1`, `.RAW`) and Vol.2 (`.V2`), three channels.
    Dmg,
    /// USGS SMC (`.smc`), one component.
    Smc,
    /// NIED K-NET and KiK-net ASCII (`.EW`, `.NS`, `.UD`, `.EW2`, ...), one component.
    Knet,
    /// ESM (Engineering Strong-Motion database) ASCII, one component.
    Esm,
    /// GeoNet `.V1A` / `.V2A`, three components.
    Geonet,
    /// LabVIEW Measurement `.lvm` (decimal point or comma, one or more segments).
    Lvm,
    /// Each file's record format told from its content (its first 4 KB), else from its extension,
    /// as `shakeflow stage load` does; the load metadata names the reader used.
    Auto,
    /// A diagnosis case folder, named by its `equipment.yaml` (`cases/{case}/equipment.yaml`):
    /// equipment, floor record and observations, read whole by `diagnose`.
    Case,
    /// An image sequence for `cpt_track`: a folder of PNG/JPEG frames, or a video file (through ffmpeg).
    Frames,
    /// Camera control points for `cpt_calibrate`: CSV with X_mm, Y_mm, Z_mm, u_px, v_px.
    ControlPoints,
    /// Tables another stage or pipeline wrote: a dataset folder (its `data.parquet` parts, Hive
    /// partitions from their folders) or one Parquet file, read by stages that read stage outputs.
    Dataset,
}

impl RecordFormat {
    /// Every format, in the order the schema lists them.
    pub const ALL: [RecordFormat; 18] = [
        RecordFormat::Delimited,
        RecordFormat::Csv,
        RecordFormat::Tsv,
        RecordFormat::At2,
        RecordFormat::RenadicV1,
        RecordFormat::SimcenterJson,
        RecordFormat::Cosmos,
        RecordFormat::Dmg,
        RecordFormat::Smc,
        RecordFormat::Knet,
        RecordFormat::Esm,
        RecordFormat::Geonet,
        RecordFormat::Lvm,
        RecordFormat::Auto,
        RecordFormat::Frames,
        RecordFormat::ControlPoints,
        RecordFormat::Case,
        RecordFormat::Dataset,
    ];

    /// Accelerogram formats, which `load` reads; the others feed the stage that understands them.
    pub fn is_record(self) -> bool {
        !matches!(self, RecordFormat::Frames | RecordFormat::ControlPoints | RecordFormat::Case | RecordFormat::Dataset)
    }

    /// Whether a source of this format may name folders (an image sequence, a dataset).
    pub fn names_folders(self) -> bool {
        matches!(self, RecordFormat::Frames | RecordFormat::Dataset)
    }

    /// The name pipelines use (`format: control_points`).
    pub fn name(self) -> String {
        serde_json::to_value(self).ok().and_then(|v| v.as_str().map(String::from)).unwrap_or_default()
    }
}

/// What a lone horizontal component is called when a source has no `columns` map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ComponentAs {
    Ax,
    Ay,
    /// Every channel keeps the file's own name (`180`, `HNE`, `chan1`).
    Label,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum GapPolicy {
    /// Missing values (empty, NaN) are an error naming the first one.
    #[default]
    Error,
    /// Missing values are filled by linear interpolation between their neighbours (reported).
    Interpolate,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NonUniformPolicy {
    /// A time column that is not uniformly sampled is an error naming the first bad step.
    #[default]
    Error,
    /// Resample linearly onto the median time step (reported in the artifact metadata).
    Resample,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SourceSpec {
    pub format: RecordFormat,
    /// A file, a glob (`*`, `?`, `**`) or a template whose `{key}` parts match one path segment
    /// each and become partition keys (`archive/{motion}/DAQ1_floors.csv`); a `*` beside keys
    /// matches within one segment and names no key (`Trial-*/Rep-1/{motion}_DAQ1.txt`). Relative
    /// to the pipeline file.
    pub path: String,
    #[serde(default)]
    pub description: Option<String>,
    /// Constant partition keys added to every record of this source (`floor: "4"`).
    #[serde(default)]
    pub partition: BTreeMap<String, String>,
    /// Delimited text: lines before the column-name row.
    #[serde(default)]
    pub header_lines: usize,
    /// Delimited text: whether a column-name row follows the header lines.
    #[serde(default = "yes")]
    pub column_names: bool,
    /// Delimited text: one character (`,` `;` `\t`), `whitespace`, or absent to detect it.
    #[serde(default)]
    pub delimiter: Option<String>,
    /// Delimited text: the line (1-based, below the column names) holding each column's unit
    /// (NEES convention); the file's units are converted to SI like declared ones.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub units_row: Option<usize>,
    /// Delimited text: the line (1-based, below the column names) holding each column's
    /// description, which becomes the column's `description`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description_row: Option<usize>,
    /// Raw data (volts, counts): a sensitivity table (CSV `channel,sensitivity,unit,offset`,
    /// relative to the pipeline file); a channel it names is `(raw − offset) / sensitivity` in `unit`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<String>,
    /// The rows of `calibration`, read when the pipeline is planned: serialised with the spec,
    /// so an edited table changes the source's hash and reruns `load`.
    #[serde(skip_deserializing, default, skip_serializing_if = "Vec::is_empty")]
    pub calibration_table: Vec<crate::io::records::Calibration>,
    /// Delimited text: the column holding time; without one, `dt` gives the sampling.
    #[serde(default)]
    pub time_column: Option<String>,
    /// Time unit of `time_column` (default s).
    #[serde(default)]
    pub time_unit: Option<String>,
    /// Sample interval in seconds for files with neither a time column nor a header DT.
    #[serde(default)]
    pub dt: Option<f64>,
    /// Unit of the channels in the file (default: what the file says, else an error).
    #[serde(default)]
    pub unit: Option<String>,
    /// Output column name → file column (name, or a mapping with `column`, `unit`, `scale`, `description`).
    /// Absent: every channel, named as in the file.
    #[serde(default)]
    pub columns: IndexMap<String, ColumnSpec>,
    /// Factor applied to every channel after unit conversion (e.g. a sensor sensitivity).
    #[serde(default = "one")]
    pub scale: f64,
    /// Accelerogram formats, without `columns`: the axis a record's lone horizontal component
    /// becomes (`ax`, default), or `label` to name every channel as the file does.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub component_as: Option<ComponentAs>,
    #[serde(default)]
    pub gaps: GapPolicy,
    #[serde(default)]
    pub non_uniform: NonUniformPolicy,
    /// What a record of this source that cannot be read does to the run: `fail` (default) fails
    /// its work unit; `skip` lists it (file, line, reason) in the `load` stage's `flagged` table
    /// and goes on, and the run exits with status 2.
    #[serde(default, skip_serializing_if = "OnError::is_fail")]
    pub on_error: OnError,
    /// Records whose components live in files of their own (K-NET `.EW`/`.NS`/`.UD`, PEER
    /// `.AT2`, COSMOS `.V2c` per channel): the files whose partition keys agree but for
    /// `key` are one record, their channels side by side on one clock.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub components: Option<Components>,
}

/// How a source's files group into records by component (`components:`).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Components {
    /// The `{key}` of the source's `path` whose value names a file's component
    /// (`path: knet/{station}.{component}`, `key: component`); it is not a partition key.
    pub key: String,
    /// The axes every record must have (default x, y, z): a record missing one is refused,
    /// naming its files.
    #[serde(default = "every_axis")]
    pub require: Vec<Axis>,
    /// A component (the key's value) → its axis, for files whose own header or label does not
    /// say where they point (`H1: x`, `H2: y`); the others go by their stated orientation.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub axes: BTreeMap<String, Axis>,
}

/// An axis of the east–north–up frame records are loaded in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    pub fn letter(self) -> char {
        match self {
            Axis::X => 'x',
            Axis::Y => 'y',
            Axis::Z => 'z',
        }
    }
}

fn every_axis() -> Vec<Axis> {
    vec![Axis::X, Axis::Y, Axis::Z]
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OnError {
    #[default]
    Fail,
    Skip,
}

impl OnError {
    fn is_fail(&self) -> bool {
        *self == OnError::Fail
    }
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(untagged)]
pub enum ColumnSpec {
    Name(String),
    Full(ColumnDetail),
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ColumnDetail {
    pub column: String,
    #[serde(default)]
    pub unit: Option<String>,
    #[serde(default)]
    pub scale: Option<f64>,
    #[serde(default)]
    pub description: Option<String>,
}

impl ColumnSpec {
    pub fn file_column(&self) -> &str {
        match self {
            ColumnSpec::Name(name) => name,
            ColumnSpec::Full(detail) => &detail.column,
        }
    }
}

fn yes() -> bool {
    true
}

fn one() -> f64 {
    1.0
}

/// A parsed pipeline with what error messages need: its path and its text.
#[derive(Debug, Clone)]
pub struct PipelineFile {
    pub path: PathBuf,
    pub text: String,
    pub spec: PipelineSpec,
    /// Set when no file was read: the command (`shakeflow stage`) that made `spec` in memory from
    /// paths on its command line (relative to the current folder). Its errors name no file.
    pub command: Option<String>,
}

impl PipelineFile {
    pub fn read(path: &Path) -> Result<Self, UserError> {
        let bytes = std::fs::read(path).map_err(|e| {
            UserError::new(format!("cannot read the pipeline file: {e}"))
                .in_file(path)
                .hint("give the path of a pipeline YAML file, e.g. `pipelines/demo.yaml`")
        })?;
        if let Some(not_text) = crate::io::records::not_text(&bytes) {
            return Err(not_a_pipeline(path, not_text));
        }
        let text = String::from_utf8(bytes).map_err(|e| {
            let valid = &e.as_bytes()[..e.utf8_error().valid_up_to()];
            let line = valid.iter().filter(|&&b| b == b'\n').count() + 1;
            let column = valid.iter().rev().take_while(|&&b| b != b'\n').filter(|&&b| b & 0xc0 != 0x80).count() + 1;
            UserError::new(format!("the pipeline file is not UTF-8 text: byte {} is not valid UTF-8", valid.len() + 1))
                .in_file(path)
                .at(Some((line, column)))
                .hint("save the file as UTF-8 (a Latin-1 or Windows-1252 editor setting, or a binary file?)")
        })?;
        Self::parse(path, text)
    }

    pub fn parse(path: &Path, text: String) -> Result<Self, UserError> {
        if let Some(not_text) = crate::io::records::not_text(text.as_bytes()) {
            return Err(not_a_pipeline(path, not_text));
        }
        let refuse = |e: serde_yaml::Error, hint: &str| {
            let position = e.location().map(|l| (l.line(), l.column()));
            let (message, hint) = crate::io::yaml::yaml_refusal(&e, hint);
            UserError::new(message).in_file(path).at(position).hint(hint)
        };
        // Typed maps keep the last of two equal keys without a word: a generic parse refuses them.
        serde_yaml::from_str::<serde_yaml::Value>(&text).map_err(|e| {
            refuse(e, "a key given twice in one mapping: the second would silently replace the first; keep one")
        })?;
        let spec: PipelineSpec = serde_yaml::from_str(&text).map_err(|e| {
            refuse(
                e,
                "see `schemas/pipeline.schema.json` for the format, or `shakeflow stages` for stage types and parameters",
            )
        })?;
        let file = PipelineFile { path: path.to_path_buf(), text, spec, command: None };
        if file.spec.version != FORMAT_VERSION {
            return Err(file
                .error_at(&["version"], format!("pipeline format version {} is not supported", file.spec.version))
                .hint(format!("this shakeflow reads `version: {FORMAT_VERSION}`")));
        }
        Ok(file)
    }

    /// A pipeline made in memory by `command` from its command line: relative paths are
    /// relative to the current folder, and source paths name files or folders literally.
    pub fn for_command(command: &str, spec: PipelineSpec) -> Self {
        PipelineFile { path: PathBuf::from(command), text: String::new(), spec, command: Some(command.to_string()) }
    }

    /// The directory relative paths in the file are resolved against.
    pub fn base_dir(&self) -> PathBuf {
        match self.path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        }
    }

    pub fn output_dir(&self) -> PathBuf {
        lexically_normal(&self.base_dir().join(&self.spec.output_dir))
    }

    pub fn error_at(&self, key_path: &[&str], message: impl Into<String>) -> UserError {
        self.located(message, super::locate::key_position(&self.text, key_path))
    }

    pub fn error_at_value(&self, key_path: &[&str], value: &str, message: impl Into<String>) -> UserError {
        self.located(message, super::locate::value_position(&self.text, key_path, value))
    }

    /// An error at `position` of the file; a pipeline made by a command has no file to name.
    fn located(&self, message: impl Into<String>, position: Option<(usize, usize)>) -> UserError {
        match self.command {
            Some(_) => UserError::new(message),
            None => UserError::new(message).in_file(&self.path).at(position),
        }
    }
}

fn not_a_pipeline(path: &Path, not_text: crate::io::records::NotText) -> UserError {
    UserError::new(format!("not a pipeline file: {}", not_text.message))
        .in_file(path)
        .at(not_text.line.map(|l| (l, 1)))
        .hint(format!("{}; a pipeline is a YAML text file", not_text.hint))
}

/// `a/b/../c` → `a/c` without touching the disk (the folder may not exist yet); for paths users read.
pub fn lexically_normal(path: &Path) -> PathBuf {
    use std::path::Component;
    let mut out = PathBuf::new();
    for component in path.components() {
        match component {
            Component::CurDir => {}
            Component::ParentDir if matches!(out.components().next_back(), Some(Component::Normal(_))) => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    if out.as_os_str().is_empty() {
        out.push(".");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_are_normalised_for_display() {
        assert_eq!(lexically_normal(Path::new("pipelines/../runs/demo")), Path::new("runs/demo"));
        assert_eq!(lexically_normal(Path::new("./out")), Path::new("out"));
        assert_eq!(lexically_normal(Path::new("../x/./y")), Path::new("../x/y"));
    }

    #[test]
    fn unknown_key_is_reported_with_line_and_column() {
        let text = "version: 1\noutput_dir: out\nstages:\n  b:\n    type: baseline\n    parms: {}\n";
        let err = PipelineFile::parse(Path::new("p.yaml"), text.into()).unwrap_err();
        assert_eq!(err.line, Some(6), "{err}");
        assert!(err.message.contains("unknown field `parms`"), "{err}");
        assert!(err.message.contains("expected one of"), "{err}");
    }

    /// Used to say "repetition limit exceeded" with the hint for duplicate keys.
    #[test]
    fn an_alias_bomb_is_named_for_what_it_is() {
        let mut text = String::from(
            "version: 1\noutput_dir: out\nstages: {}\nbomb:\n  a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n",
        );
        for k in 1..10 {
            let prev = format!("*a{}", k - 1);
            text.push_str(&format!("  a{k}: &a{k} [{}]\n", [prev.as_str(); 9].join(", ")));
        }
        let err = PipelineFile::parse(Path::new("p.yaml"), text).unwrap_err();
        assert!(err.message.contains("alias bomb"), "{err}");
        assert!(!err.to_string().contains("key given twice"), "{err}");
    }

    #[test]
    fn binary_and_utf16_pipelines_are_named_as_such() {
        let dir = crate::tempdir::tempdir().unwrap();
        let path = dir.path().join("p.yaml");
        let text = "version: 1\noutput_dir: out\nstages: {}\n";
        let utf16: Vec<u8> = text.encode_utf16().flat_map(u16::to_le_bytes).collect();
        for bytes in [[&[0xfe, 0xff][..], &utf16].concat(), utf16, b"\x1f\x8b\x08\x00\x1b[2J".to_vec()] {
            std::fs::write(&path, &bytes).unwrap();
            let err = PipelineFile::read(&path).unwrap_err().to_string();
            assert!(err.contains("not a pipeline file: binary or UTF-16 file"), "{err}");
            assert!(!err.chars().any(|c| c.is_control() && c != '\n'), "{err:?}");
        }
        std::fs::write(&path, b"version: 1\noutput_dir: caf\xe9\nstages: {}\n").unwrap();
        let err = PipelineFile::read(&path).unwrap_err();
        assert_eq!((err.line, err.column), (Some(2), Some(16)), "{err}");
        assert!(err.message.contains("not UTF-8 text"), "{err}");
    }

    /// serde_yaml quotes the offending text: its control characters reach no terminal.
    #[test]
    fn yaml_messages_escape_control_characters() {
        let text = "version: 1\noutput_dir: out\nstages: {}\n\"\\e[2Jkey\": 1\n";
        let err = PipelineFile::parse(Path::new("p.yaml"), text.into()).unwrap_err();
        assert!(err.message.contains("\\u{1b}[2Jkey"), "{err}");
        assert!(!err.to_string().contains('\u{1b}'), "{err:?}");
    }

    #[test]
    fn wrong_version_points_at_it() {
        let text = "version: 7\noutput_dir: out\nstages: {}\n";
        let err = PipelineFile::parse(Path::new("p.yaml"), text.into()).unwrap_err();
        assert_eq!((err.line, err.column), (Some(1), Some(1)));
    }
}
