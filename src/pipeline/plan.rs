//! From a parsed pipeline file to a checked plan: stage types known, parameters valid, inputs
//! resolvable, no cycles; stages in an order where each comes after what it reads.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use indexmap::IndexMap;

use super::params::{self, Params};
use super::spec::{ColumnSpec, PipelineFile, PipelineSpec, RecordFormat, SourceSpec};
use super::stage::{InputKind, OutputKind, Partition, Registry, Stage};
use crate::error::{did_you_mean_hint, UserError};

#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub enum InputRef {
    Source(String),
    Stage { stage: String, output: &'static str },
}

impl InputRef {
    pub fn label(&self) -> String {
        match self {
            InputRef::Source(name) => name.clone(),
            InputRef::Stage { stage, output } => format!("{stage}.{output}"),
        }
    }
}

pub struct PlannedStage {
    pub name: String,
    pub stage: &'static dyn Stage,
    pub params: Params,
    pub inputs: Vec<InputRef>,
    /// Partition filter on every input: key → accepted values.
    pub select: BTreeMap<String, Vec<String>>,
    /// Files named by `Path` parameters (parameter → path): their contents are inputs too.
    pub files: BTreeMap<String, PathBuf>,
    /// `keep: false`: its files go once every stage reading them is up to date.
    pub keep: bool,
}

impl PlannedStage {
    pub fn selects(&self, partition: &Partition) -> bool {
        self.select.iter().all(|(key, values)| partition.iter().any(|(k, v)| k == key && values.contains(v)))
    }
}

pub struct Plan {
    pub file: PipelineFile,
    /// Stages in dependency order (ties keep the file's order).
    pub stages: IndexMap<String, PlannedStage>,
    /// The stage types the plan was checked against.
    pub registry: Registry,
}

impl Plan {
    pub fn new(file: PipelineFile, registry: Registry) -> Result<Plan, UserError> {
        Plan::checked(file, registry).map_err(|mut errors| errors.swap_remove(0))
    }

    /// [`Plan::new`] reporting every source and stage it refuses, not only the first (`validate`).
    pub fn checked(mut file: PipelineFile, registry: Registry) -> Result<Plan, Vec<UserError>> {
        let mut errors = Vec::new();
        for (name, source) in &file.spec.inputs {
            errors.extend(check_source(&file, name, source).err());
        }
        let tables: Vec<_> =
            file.spec.inputs.iter().map(|(name, source)| calibration_table(&file, name, source)).collect();
        for (source, table) in file.spec.inputs.values_mut().zip(tables) {
            match table {
                Ok(table) => source.calibration_table = table,
                Err(e) => errors.push(e),
            }
        }
        let mut planned = IndexMap::new();
        for (name, spec) in &file.spec.stages {
            match plan_stage(&file, registry, name, spec) {
                Ok(stage) => {
                    planned.insert(name.clone(), stage);
                }
                Err(e) => errors.push(e),
            }
        }
        if !errors.is_empty() {
            return Err(errors);
        }
        errors.extend(unread_intermediates(&file, &planned));
        if !errors.is_empty() {
            return Err(errors);
        }
        let order = topological_order(&file, &planned).map_err(|e| vec![e])?;
        let mut sorted = IndexMap::new();
        for name in order {
            let stage = planned.swap_remove(&name).expect("order lists planned stages");
            sorted.insert(name, stage);
        }
        Ok(Plan { file, stages: sorted, registry })
    }

    /// Column names carried through the stages for `validate`: `sources` gives the columns of
    /// each source's records (as `load` makes them from its first file); each stage says what its
    /// first output holds, given the columns of its inputs (their union: a name in none of them is
    /// a typo whatever record it meets). Every parameter naming a column its input lacks is
    /// reported at its line; below a stage whose columns are not known, nothing is checked.
    pub fn column_errors(&self, sources: &BTreeMap<String, Vec<String>>) -> Vec<UserError> {
        let mut outputs: BTreeMap<&str, Option<Vec<String>>> = BTreeMap::new();
        let mut errors = Vec::new();
        for (name, stage) in &self.stages {
            let mut union: Option<Vec<String>> = Some(Vec::new());
            for input in &stage.inputs {
                let columns = match input {
                    InputRef::Source(source) => sources.get(source).cloned(),
                    InputRef::Stage { stage: up, output } if Some(*output) == self.first_output(up) => {
                        outputs.get(up.as_str()).cloned().flatten()
                    }
                    InputRef::Stage { .. } => None,
                };
                union = union.zip(columns).map(|(mut all, columns)| {
                    all.extend(columns.into_iter().filter(|c| !all.contains(c)).collect::<Vec<_>>());
                    all
                });
            }
            let made = if stage.stage.info().inputs == InputKind::Sources {
                union
            } else {
                let (made, refused) = stage.stage.output_columns(&stage.params, union.as_deref());
                errors.extend(refused.into_iter().map(|e| {
                    let position = e
                        .key
                        .as_deref()
                        .and_then(|key| super::locate::key_position(&self.file.text, &["stages", name, "params", key]));
                    UserError::new(e.message).in_file(&self.file.path).at(position).hint(e.hint)
                }));
                made
            };
            outputs.insert(name.as_str(), made);
        }
        errors
    }

    fn first_output(&self, stage: &str) -> Option<&'static str> {
        self.stages.get(stage).and_then(|s| s.stage.info().outputs.first()).map(|o| o.name)
    }

    /// `names` and every stage they read, directly or not.
    pub fn with_upstream<'a>(&self, names: impl IntoIterator<Item = &'a str>) -> BTreeSet<String> {
        let mut set: BTreeSet<String> = names.into_iter().map(String::from).collect();
        // Stages are in dependency order: walking backwards adds what each stage in the set reads.
        for (name, stage) in self.stages.iter().rev() {
            if set.contains(name) {
                for input in &stage.inputs {
                    if let InputRef::Stage { stage, .. } = input {
                        set.insert(stage.clone());
                    }
                }
            }
        }
        set
    }

    /// The plan of a command that runs one stage without a pipeline file (`shakeflow stage`,
    /// `shakeflow diagnose`): `spec` made in memory, its one stage written at the output folder
    /// itself rather than in a sub-folder named after it.
    pub fn for_command(command: &str, spec: PipelineSpec, registry: Registry) -> Result<Plan, UserError> {
        if spec.stages.len() != 1 {
            return Err(UserError::new(format!("`{command}` runs one stage, not {}", spec.stages.len())));
        }
        Plan::new(PipelineFile::for_command(command, spec), registry)
    }

    /// A stage's folder relative to the output folder: its name, or `` for a command's one stage.
    pub fn stage_path<'a>(&self, name: &'a str) -> &'a str {
        match self.file.command {
            Some(_) => "",
            None => name,
        }
    }

    /// Where a stage's outputs go: `<output_dir>/<name>` (a command's one stage: `output_dir`).
    pub fn stage_dir(&self, name: &str) -> PathBuf {
        match self.stage_path(name) {
            "" => self.file.output_dir(),
            path => self.file.output_dir().join(path),
        }
    }

    /// The path, relative to the output folder, of `file` of a stage's folder (lockfile and
    /// commit entries).
    pub fn stage_entry(&self, name: &str, file: &str) -> String {
        match self.stage_path(name) {
            "" => file.to_string(),
            path => format!("{path}/{file}"),
        }
    }

    /// The stages that read `name`'s outputs, directly or not, plus `name` itself.
    pub fn with_dependents(&self, name: &str) -> BTreeSet<String> {
        let mut set = BTreeSet::from([name.to_string()]);
        for (stage_name, stage) in &self.stages {
            let reads_set =
                stage.inputs.iter().any(|i| matches!(i, InputRef::Stage { stage, .. } if set.contains(stage)));
            if reads_set {
                set.insert(stage_name.clone());
            }
        }
        set
    }
}

/// A `keep: false` stage that no stage reads would lose its files as soon as it wrote them.
fn unread_intermediates(file: &PipelineFile, planned: &IndexMap<String, PlannedStage>) -> Vec<UserError> {
    let read: BTreeSet<&str> = planned
        .values()
        .flat_map(|s| &s.inputs)
        .filter_map(|i| match i {
            InputRef::Stage { stage, .. } => Some(stage.as_str()),
            InputRef::Source(_) => None,
        })
        .collect();
    planned
        .values()
        .filter(|s| !s.keep && !read.contains(s.name.as_str()))
        .map(|s| {
            file.error_at(
                &["stages", &s.name, "keep"],
                format!("stage `{}` has `keep: false`, but no stage reads it", s.name),
            )
            .hint("an intermediate's files go once the stages reading them are up to date: with no reader they would go as soon as they were written; remove `keep: false`")
        })
        .collect()
}

/// One stage of the file, checked: name, type, parameters, inputs.
fn plan_stage(
    file: &PipelineFile,
    registry: Registry,
    name: &str,
    spec: &super::spec::StageSpec,
) -> Result<PlannedStage, UserError> {
    if let Some(problem) = super::paths::component_problem(name) {
        return Err(file
            .error_at(&["stages", name], format!("stage name `{name}` cannot name a folder: {problem}"))
            .hint("each stage writes the folder `<output_dir>/<stage name>`: use letters, digits, `_`, `-`, `.`"));
    }
    if name == super::layout::LOCK_FILE {
        return Err(file
            .error_at(&["stages", name], format!("stage name `{name}` is the lockfile's name"))
            .hint("choose another stage name"));
    }
    let stage = registry.find(&spec.stage_type).ok_or_else(|| {
        let suggestion = did_you_mean_hint(&spec.stage_type, registry.names());
        file.error_at(&["stages", name, "type"], format!("unknown stage type `{}`", spec.stage_type))
            .hint(format!("{suggestion}known stage types: {} (see `shakeflow stages`)", registry.names().join(", ")))
    })?;
    let info = stage.info();
    let given = spec.params.iter().map(|(k, v)| (k.as_str(), params::yaml_to_json(v)));
    let located = |e: params::ParamError| match &e.key {
        Some(key) => file.error_at(&["stages", name, "params", key], e.message).hint(e.hint),
        None => file.error_at(&["stages", name], e.message).hint(e.hint),
    };
    let params = params::normalize(info.params, info.name, given).map_err(located)?;
    stage.check_params(&params).map_err(located)?;
    let files = param_files(info.params, &params, &file.base_dir(), info.name).map_err(located)?;
    stage.check(&params, &file.base_dir()).map_err(located)?;
    let inputs = resolve_inputs(file, registry, name, &spec.inputs, info.inputs)?;
    Ok(PlannedStage {
        name: name.to_string(),
        stage,
        params,
        inputs,
        select: spec.select.clone(),
        files,
        keep: spec.keep,
    })
}

/// The files `Path` parameters name, resolved against the pipeline's folder; each must exist.
pub fn param_files(
    specs: &[params::ParamSpec],
    params: &params::Params,
    base_dir: &Path,
    stage_type: &str,
) -> Result<BTreeMap<String, PathBuf>, params::ParamError> {
    let mut files = BTreeMap::new();
    for spec in specs.iter().filter(|s| s.kind == params::ParamKind::Path) {
        let Some(relative) = params.get(spec.name).and_then(|v| v.as_str()) else { continue };
        let path = base_dir.join(relative);
        if !path.is_file() {
            return Err(params::ParamError {
                key: Some(spec.name.to_string()),
                message: format!("parameter `{}` of `{stage_type}`: no file `{}`", spec.name, path.display()),
                hint: format!("paths are relative to the pipeline file's folder — {}", spec.description),
            });
        }
        files.insert(spec.name.to_string(), path);
    }
    Ok(files)
}

/// The rows of a source's sensitivity table (`calibration:`), read now: they become part of the
/// source's spec, and so of its hash.
fn calibration_table(
    file: &PipelineFile,
    name: &str,
    source: &SourceSpec,
) -> Result<Vec<crate::io::records::Calibration>, UserError> {
    let Some(table) = &source.calibration else { return Ok(Vec::new()) };
    let path = file.base_dir().join(table);
    if !path.is_file() {
        return Err(file
            .error_at(&["inputs", name, "calibration"], format!("source `{name}`: no calibration table `{}`", path.display()))
            .hint("the path is relative to the pipeline file's folder; the table is CSV `channel,sensitivity,unit,offset`"));
    }
    crate::io::records::read_calibration(&path).map_err(|e| UserError {
        file: Some(e.path),
        line: e.line,
        column: e.column,
        message: e.message,
        hint: Some(e.hint),
    })
}

fn check_source(file: &PipelineFile, name: &str, source: &SourceSpec) -> Result<(), UserError> {
    // Constant partitions become folders `key=value` of every dataset made from this source.
    for (key, value) in &source.partition {
        if !key.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_') || key.is_empty() {
            return Err(file
                .error_at(&["inputs", name, "partition", key], format!("`{key}` is not a valid partition key"))
                .hint("partition keys are letters, digits and `_`, as `{key}`s in paths are"));
        }
        // A command's partition values come from file names, percent-encoded like a template's.
        if let Some(problem) = super::paths::component_problem(value).filter(|_| file.command.is_none()) {
            return Err(file
                .error_at(&["inputs", name, "partition", key], format!("partition value `{value}` cannot name a folder: {problem}"))
                .hint("partition values become folders (`key=value`) of every output: use a plain name such as `4` or `roof`"));
        }
    }
    if source.format == RecordFormat::Dataset {
        check_dataset_source(file, name, source)?;
    }
    let known = || format!("known units: {}", crate::units::known_units().join(", "));
    if let Some(unit) = &source.unit {
        if crate::units::conversion(unit).is_none() {
            return Err(file.error_at(&["inputs", name, "unit"], format!("unknown unit `{unit}`")).hint(known()));
        }
    }
    if let Some(unit) = &source.time_unit {
        if crate::units::conversion(unit).is_none_or(|c| c.si_unit != "s") {
            return Err(file
                .error_at(&["inputs", name, "time_unit"], format!("`{unit}` is not a time unit"))
                .hint("use s or ms"));
        }
    }
    for (column, spec) in &source.columns {
        if let ColumnSpec::Full(detail) = spec {
            if let Some(unit) = &detail.unit {
                if crate::units::conversion(unit).is_none() {
                    return Err(file
                        .error_at(&["inputs", name, "columns", column, "unit"], format!("unknown unit `{unit}`"))
                        .hint(known()));
                }
            }
        }
    }
    if let Some(dt) = source.dt {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(
                file.error_at(&["inputs", name, "dt"], format!("`dt` must be a positive number of seconds, not {dt}"))
            );
        }
    }
    let names_line = source.header_lines + usize::from(source.column_names);
    for (key, row) in [("units_row", source.units_row), ("description_row", source.description_row)] {
        let Some(row) = row else { continue };
        if !matches!(source.format, RecordFormat::Delimited | RecordFormat::Csv | RecordFormat::Tsv) {
            return Err(file
                .error_at(
                    &["inputs", name, key],
                    format!("`{key}` applies to delimited text, not `{}`", source.format.name()),
                )
                .hint("the other formats state their units in their headers"));
        }
        if row <= names_line {
            return Err(file
                .error_at(&["inputs", name, key], format!("`{key}: {row}` is not below the column-name row (line {names_line})"))
                .hint(format!("`{key}` is the file's line number (1-based); `header_lines` counts the lines before the column names")));
        }
    }
    if let Some(d) = &source.delimiter {
        if d != "whitespace" && d != "\\t" && d.chars().count() != 1 {
            return Err(file
                .error_at(&["inputs", name, "delimiter"], format!("delimiter `{d}` is not one character"))
                .hint("use `,`, `;`, `\\t`, `whitespace`, or leave it out to detect it"));
        }
    }
    Ok(())
}

/// A `dataset` source is read as its tables are: an option of record files would be ignored.
fn check_dataset_source(file: &PipelineFile, name: &str, source: &SourceSpec) -> Result<(), UserError> {
    let defaults: SourceSpec = serde_json::from_value(serde_json::json!({"format": "dataset", "path": source.path}))
        .expect("a format and a path make a source");
    let given = serde_json::to_value(source).expect("specs serialise");
    let default = serde_json::to_value(&defaults).expect("specs serialise");
    let record_option = given.as_object().and_then(|given| {
        given.iter().find(|(key, value)| {
            !["format", "path", "description", "partition"].contains(&key.as_str()) && default.get(*key) != Some(*value)
        })
    });
    match record_option {
        Some((key, _)) => Err(file
            .error_at(&["inputs", name, key], format!("source `{name}`: `{key}` applies to record files, not to a `dataset`"))
            .hint("a `dataset` source reads the Parquet tables of another stage or pipeline as they are: remove the option")),
        None => Ok(()),
    }
}

fn resolve_inputs(
    file: &PipelineFile,
    registry: Registry,
    stage_name: &str,
    names: &[String],
    kind: InputKind,
) -> Result<Vec<InputRef>, UserError> {
    let key_path = ["stages", stage_name, "inputs"];
    if names.is_empty() {
        let what = match kind {
            InputKind::Sources | InputKind::Files(_) => "a source from `inputs:`",
            InputKind::Datasets => "another stage",
        };
        return Err(file
            .error_at(&["stages", stage_name], format!("stage `{stage_name}` has no inputs"))
            .hint(format!("add `inputs: [...]` naming {what}")));
    }
    let mut refs = Vec::new();
    for name in names {
        let (head, output) = match name.split_once('.') {
            Some((h, o)) => (h, Some(o)),
            None => (name.as_str(), None),
        };
        let reference = if let Some(source) = file.spec.inputs.get(name) {
            let format = source.format;
            let refusal = match kind {
                InputKind::Datasets if format == RecordFormat::Dataset => None,
                InputKind::Datasets if format.is_record() => Some((
                    format!("`{name}` is a record source, but this stage type reads stage outputs"),
                    format!("load it first with a `load` stage and name that stage here instead of `{name}`"),
                )),
                InputKind::Datasets | InputKind::Sources if !format.is_record() => Some((
                    format!("`{name}` is a `{}` source, which this stage type does not read", format.name()),
                    "a `frames` source feeds `cpt_track`, a `control_points` source feeds `cpt_calibrate`, a `dataset` source feeds stages that read stage outputs".to_string(),
                )),
                InputKind::Files(formats) if !formats.contains(&format) => Some((
                    format!(
                        "`{name}` is a `{}` source, but this stage type reads `{}` sources",
                        format.name(),
                        formats.iter().map(|f| f.name()).collect::<Vec<_>>().join("` or `")
                    ),
                    format!("declare a source with `format: {}` under `inputs:`", formats[0].name()),
                )),
                _ => None,
            };
            if let Some((message, hint)) = refusal {
                return Err(file.error_at_value(&key_path, name, message).hint(hint));
            }
            InputRef::Source(name.clone())
        } else if let Some(upstream) = file.spec.stages.get(head) {
            if kind != InputKind::Datasets {
                return Err(file
                    .error_at_value(
                        &key_path,
                        name,
                        format!("`{name}` is a stage, but this stage type reads sources declared under `inputs:`"),
                    )
                    .hint("name a source declared under `inputs:`"));
            }
            let outputs = registry.find(&upstream.stage_type).map(|s| s.info().outputs).unwrap_or(&[]);
            let found = match output {
                None => outputs.first(),
                Some(wanted) => outputs.iter().find(|o| o.name == wanted),
            };
            if let Some(page) = found.filter(|o| o.kind == OutputKind::Page) {
                return Err(file
                    .error_at_value(
                        &key_path,
                        name,
                        format!("`{head}.{}` is a page for people, not a dataset", page.name),
                    )
                    .hint("read one of the stage's tables instead"));
            }
            let found = found.map(|o| o.name);
            let Some(output) = found else {
                let names: Vec<&str> = outputs.iter().map(|o| o.name).collect();
                let wanted = output.unwrap_or_default();
                let suggestion = did_you_mean_hint(wanted, names.iter().copied());
                return Err(file
                    .error_at_value(&key_path, name, format!("stage `{head}` has no output `{wanted}`"))
                    .hint(format!("{suggestion}outputs of `{head}`: {}", names.join(", "))));
            };
            InputRef::Stage { stage: head.to_string(), output }
        } else {
            let candidates: Vec<&str> =
                file.spec.inputs.keys().chain(file.spec.stages.keys()).map(String::as_str).collect();
            let suggestion = did_you_mean_hint(name, candidates.iter().copied());
            return Err(file
                .error_at_value(
                    &key_path,
                    name,
                    format!("stage `{stage_name}` reads `{name}`, which is neither a source nor a stage"),
                )
                .hint(format!(
                    "{suggestion}sources: [{}]; stages: [{}]",
                    file.spec.inputs.keys().cloned().collect::<Vec<_>>().join(", "),
                    file.spec.stages.keys().cloned().collect::<Vec<_>>().join(", ")
                )));
        };
        refs.push(reference);
    }
    Ok(refs)
}

fn topological_order(file: &PipelineFile, planned: &IndexMap<String, PlannedStage>) -> Result<Vec<String>, UserError> {
    let deps: BTreeMap<&str, BTreeSet<&str>> = planned
        .iter()
        .map(|(name, stage)| {
            let upstream = stage.inputs.iter().filter_map(|i| match i {
                InputRef::Stage { stage, .. } => Some(stage.as_str()),
                InputRef::Source(_) => None,
            });
            (name.as_str(), upstream.collect())
        })
        .collect();
    let mut done: BTreeSet<&str> = BTreeSet::new();
    let mut order = Vec::new();
    while order.len() < planned.len() {
        let next =
            planned.keys().find(|n| !done.contains(n.as_str()) && deps[n.as_str()].iter().all(|d| done.contains(d)));
        match next {
            Some(name) => {
                done.insert(name);
                order.push(name.clone());
            }
            None => {
                let cycle = find_cycle(&deps, &done);
                return Err(file
                    .error_at(&["stages", cycle[0], "inputs"], format!("the stages form a cycle: {}", cycle.join(" → ")))
                    .hint("a stage cannot read its own output, directly or through other stages; remove one of these inputs"));
            }
        }
    }
    Ok(order)
}

fn find_cycle<'a>(deps: &BTreeMap<&'a str, BTreeSet<&'a str>>, done: &BTreeSet<&str>) -> Vec<&'a str> {
    // Every stage left has an unfinished dependency, so walking them must revisit one.
    let start = *deps.keys().find(|n| !done.contains(*n)).expect("a cycle leaves stages undone");
    let mut path = vec![start];
    loop {
        let last = *path.last().expect("path starts non-empty");
        let next = *deps[last].iter().find(|d| !done.contains(*d)).expect("undone stages have undone deps");
        if let Some(pos) = path.iter().position(|p| *p == next) {
            let mut cycle = path[pos..].to_vec();
            cycle.push(next);
            return cycle;
        }
        path.push(next);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn plan(text: &str) -> Result<Plan, UserError> {
        Plan::new(PipelineFile::parse(Path::new("p.yaml"), text.to_string())?, crate::stages::registry())
    }

    fn plan_err(text: &str) -> UserError {
        match plan(text) {
            Ok(_) => panic!("the plan was accepted"),
            Err(e) => e,
        }
    }

    const SOURCE: &str = "version: 1\noutput_dir: out\ninputs:\n  rec:\n    format: at2\n    path: a.AT2\nstages:\n";

    #[test]
    fn orders_stages_after_their_inputs() {
        let p = plan(&format!(
            "{SOURCE}  b:\n    type: baseline\n    inputs: [l]\n  l:\n    type: load\n    inputs: [rec]\n"
        ))
        .unwrap();
        assert_eq!(p.stages.keys().collect::<Vec<_>>(), ["l", "b"]);
    }

    #[test]
    fn cycle_is_named_with_its_path() {
        let err = plan_err(&format!(
            "{SOURCE}  a:\n    type: baseline\n    inputs: [b]\n  b:\n    type: baseline\n    inputs: [a]\n"
        ));
        assert!(err.message.contains("cycle: a → b → a"), "{err}");
        assert_eq!(err.line, Some(10));
    }

    #[test]
    fn unknown_stage_type_points_at_type_and_suggests() {
        let err = plan_err(&format!("{SOURCE}  l:\n    type: lod\n    inputs: [rec]\n"));
        assert_eq!((err.line, err.column), (Some(9), Some(5)));
        assert!(err.hint.unwrap().contains("did you mean `load`"));
    }

    #[test]
    fn missing_input_points_at_the_name() {
        let err = plan_err(&format!("{SOURCE}  l:\n    type: load\n    inputs: [recc]\n"));
        assert_eq!(err.line, Some(10), "{err}");
        assert!(err.hint.unwrap().contains("did you mean `rec`"));
    }

    #[test]
    fn bad_param_points_at_the_param() {
        let err = plan_err(&format!("{SOURCE}  l:\n    type: load\n    inputs: [rec]\n  b:\n    type: baseline\n    inputs: [l]\n    params:\n      ordr: 2\n"));
        assert_eq!(err.line, Some(15), "{err}");
    }

    #[test]
    fn an_intermediate_nobody_reads_is_refused_at_its_keep_line() {
        let err = plan_err(&format!("{SOURCE}  l:\n    type: load\n    inputs: [rec]\n    keep: false\n"));
        assert_eq!(err.line, Some(11), "{err}");
        assert!(err.message.contains("`keep: false`, but no stage reads it"), "{err}");
        let read = format!("{SOURCE}  l:\n    type: load\n    inputs: [rec]\n    keep: false\n  b:\n    type: baseline\n    inputs: [l]\n");
        assert!(!plan(&read).unwrap().stages["l"].keep);
    }

    #[test]
    fn a_commands_one_stage_is_written_at_the_output_folder() {
        let text = format!("{SOURCE}  l:\n    type: load\n    inputs: [rec]\n");
        let file = PipelineFile::parse(Path::new("p.yaml"), text).unwrap();
        let piped = Plan::new(file.clone(), crate::stages::registry()).unwrap();
        assert_eq!(
            (piped.stage_dir("l"), piped.stage_entry("l", "records/data.parquet")),
            (Path::new("out/l").to_path_buf(), "l/records/data.parquet".to_string())
        );
        let command = Plan::for_command("shakeflow stage", file.spec, crate::stages::registry()).unwrap();
        assert_eq!(
            (command.stage_dir("l"), command.stage_entry("l", "records/data.parquet")),
            (Path::new("out").to_path_buf(), "records/data.parquet".to_string())
        );
        // A command's errors name no file: there is none.
        let mut spec = command.file.spec.clone();
        spec.stages["l"].stage_type = "lod".into();
        let err = Plan::for_command("shakeflow stage", spec, crate::stages::registry()).err().expect("refused");
        assert_eq!((err.file, err.line), (None, None), "{}", err.message);
    }

    #[test]
    fn dependents_are_transitive() {
        let p = plan(&format!("{SOURCE}  l:\n    type: load\n    inputs: [rec]\n  b:\n    type: baseline\n    inputs: [l]\n  c:\n    type: baseline\n    inputs: [b]\n")).unwrap();
        assert_eq!(p.with_dependents("b"), BTreeSet::from(["b".to_string(), "c".to_string()]));
    }
}
