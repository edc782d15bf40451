//! `shakeflow validate`: a pipeline checked without running it. The plan's checks (keys, types,
//! parameters, inputs, cycles), then what the engine may not do itself: each record source's
//! files found, its first record read as `load` reads it (the columns carried into the plan's
//! column check) and every other file's header looked at, then the output folder's ownership.
//! [`ownership`] is also what a command (`shakeflow stage`, `shakeflow diagnose`) checks before
//! its run.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::error::UserError;
use crate::pipeline::executor;
use crate::pipeline::plan::Plan;
use crate::pipeline::sources::MatchedFile;
use crate::pipeline::spec::{Components, OnError, PipelineFile, SourceSpec};
use crate::pipeline::stage::Registry;
use crate::stages::{self, InputPart};

/// Why a pipeline is not valid.
#[derive(Debug)]
pub enum Refusal {
    /// What is wrong in the file and its sources, every error found (not only the first).
    Invalid(Vec<UserError>),
    /// The output folder is not the pipeline's to write ([`ownership`]).
    Refused(UserError),
}

/// Checks `file` as `shakeflow validate` does; `say` gets the lines it prints as it goes (each
/// source's file count, notes on records `on_error: skip` would skip, then each stage). With
/// `skip_inputs` the sources' files are neither looked for nor read.
pub fn validate(
    file: PipelineFile,
    registry: Registry,
    skip_inputs: bool,
    say: &mut dyn FnMut(String),
) -> Result<Plan, Refusal> {
    let plan = Plan::checked(file, registry).map_err(Refusal::Invalid)?;
    let mut input_files: Vec<PathBuf> = plan.stages.values().flat_map(|s| s.files.values().cloned()).collect();
    let mut errors = Vec::new();
    if !skip_inputs {
        let mut columns = BTreeMap::new();
        for (name, source) in &plan.file.spec.inputs {
            // The files as the run finds them (a `components:` record's files share a partition).
            let files = match executor::source_files(&plan, name, source) {
                Ok(files) => files,
                Err(e) => {
                    errors.push(e);
                    continue;
                }
            };
            say(format!("source {name:<16} {} file(s)", files.len()));
            input_files.extend(files.iter().map(|f| f.path.clone()));
            let checked = check_source(&plan, name, source, &files);
            columns.extend(checked.columns.map(|names| (name.clone(), names)));
            for note in checked.notes {
                say(format!("note: {note}; `run` will skip that record (on_error: skip)"));
            }
            errors.extend(checked.errors);
        }
        errors.extend(plan.column_errors(&columns));
    }
    if !errors.is_empty() {
        return Err(Refusal::Invalid(errors));
    }
    ownership(&plan, &input_files).map_err(Refusal::Refused)?;
    for stage in plan.stages.values() {
        let inputs: Vec<String> = stage.inputs.iter().map(|i| i.label()).collect();
        say(format!("stage  {:<16} {:<10} ← {}", stage.name, stage.stage.info().name, inputs.join(", ")));
    }
    Ok(plan)
}

/// The output folder's three ownership checks (`pipeline::ownership`), made before anything is
/// written: the folder holds none of the pipeline's own files or `input_files`, its lockfile
/// names no other pipeline, and each stage folder is absent or the stage's own. The run makes
/// them again under its lease; `validate` and the commands make them here, a refusal leaving the
/// folder untouched.
pub fn ownership(plan: &Plan, input_files: &[PathBuf]) -> Result<(), UserError> {
    use crate::pipeline::ownership::{check_output_dir, check_pipeline, check_stage_folders};
    check_output_dir(&plan.file, input_files)?;
    let lock = crate::pipeline::lock::LockFile::read(&executor::lock_path(plan))?;
    check_pipeline(&plan.file, &lock)?;
    check_stage_folders(plan, &lock)
}

/// What `validate` found in one source's files.
struct SourceCheck {
    /// The columns `load` makes of the source's first record that loads (None: not a record
    /// source, or none loaded).
    columns: Option<Vec<String>>,
    /// What `run` would refuse.
    errors: Vec<UserError>,
    /// What `run` would skip under `on_error: skip`, hints dropped.
    notes: Vec<UserError>,
}

/// Under `on_error: skip` a bad record is a note (the run lists it and goes on); the source itself
/// is wrong when none of its first five records loads.
fn check_source(plan: &Plan, name: &str, source: &SourceSpec, files: &[MatchedFile]) -> SourceCheck {
    let skip = source.on_error == OnError::Skip;
    let records = records_of(source, files);
    let mut problems = Vec::new();
    if let Some(components) = &source.components {
        for problem in incomplete_records(name, components, &records) {
            problems.push(plan.file.error_at(&["inputs", name, "components"], problem).hint(
                "add the missing file, or set `on_error: skip` to run the others and list it in the status table",
            ));
        }
    }
    let mut tried = Vec::new();
    let mut columns = None;
    for record in records.iter().take(if skip { 5 } else { 1 }) {
        match check_record(plan, name, source, record) {
            Ok(names) => {
                columns = Some(names);
                break;
            }
            Err(e) => tried.push(e),
        }
    }
    let loaded = columns.is_some();
    if source.format.is_record() {
        problems.extend(files.iter().skip(1).filter_map(|f| check_record_header(name, source, &f.path).err()));
    }
    if !skip {
        return SourceCheck {
            columns: columns.flatten(),
            errors: problems.into_iter().chain(tried).collect(),
            notes: Vec::new(),
        };
    }
    let (notes, errors) = if loaded { (tried, Vec::new()) } else { (Vec::new(), tried) };
    let notes = problems
        .into_iter()
        .chain(notes)
        .map(|mut note| {
            note.hint = None;
            note
        })
        .collect();
    SourceCheck { columns: columns.flatten(), errors, notes }
}

/// `validate`'s look at a record file past a source's first: its header (`records::check_header`),
/// and for delimited text the columns the source names (`time_column`, `columns:`).
fn check_record_header(name: &str, source: &SourceSpec, path: &Path) -> Result<(), UserError> {
    let in_source = |e: crate::io::records::ParseError| UserError {
        file: Some(e.path),
        line: e.line,
        column: e.column,
        message: format!("source `{name}`: {}", e.message),
        hint: Some(e.hint),
    };
    let options = stages::load::delimited_options(source);
    let Some(names) =
        crate::io::records::check_header(path, &source.format.name(), options.as_ref()).map_err(in_source)?
    else {
        return Ok(());
    };
    let wanted = source.time_column.iter().map(String::as_str).chain(source.columns.values().map(|c| c.file_column()));
    for column in wanted {
        if !names.iter().any(|n| n == column) {
            let suggestion = crate::error::did_you_mean_hint(column, names.iter().map(String::as_str));
            return Err(UserError::new(format!("source `{name}`: the file has no column `{column}`"))
                .in_file(path)
                .at(source.column_names.then_some((source.header_lines + 1, 1)))
                .hint(format!("{suggestion}its columns are: {}", names.join(", "))));
        }
    }
    Ok(())
}

/// `validate` reads a record of a source (its first; under `on_error: skip` the first that loads)
/// as `load` would, so a misspelt column, a wrong `header_lines` or unit, components on two
/// clocks show now rather than in the middle of a run; the columns `load` makes of it are
/// returned (None: not a record source).
fn check_record(
    plan: &Plan,
    name: &str,
    source: &SourceSpec,
    files: &[&MatchedFile],
) -> Result<Option<Vec<String>>, UserError> {
    if !source.format.is_record() {
        return Ok(None);
    }
    let parts: Vec<InputPart> = files
        .iter()
        .map(|file| InputPart {
            partition: file.partition.clone(),
            path: file.path.clone(),
            label: file_label(&file.path),
            hash: String::new(),
        })
        .collect();
    // A `components:` record is its files together, its clocks and axes checked as `load` does.
    let loaded = match source.components {
        Some(_) => stages::load::load_record_group(source, name, &plan.file.base_dir(), &parts),
        None => stages::load::load_record(source, &parts[0]),
    };
    loaded.map(|table| Some(table.column_names().into_iter().map(String::from).collect())).map_err(|refused| {
        let mut e = *refused.error;
        let position = refused.column.as_deref().and_then(|column| {
            let output = source.columns.iter().find(|(_, c)| c.file_column() == column).map(|(out, _)| out.as_str());
            match output {
                Some(out) => crate::pipeline::locate::key_position(&plan.file.text, &["inputs", name, "columns", out]),
                None if source.time_column.as_deref() == Some(column) => {
                    crate::pipeline::locate::key_position(&plan.file.text, &["inputs", name, "time_column"])
                }
                None => None,
            }
        });
        e.message = format!("source `{name}`, read as `load` would: {}", e.message);
        if let Some((line, column)) = position {
            e.hint = Some(format!(
                "{} (the column is named at {}:{line}:{column})",
                e.hint.clone().unwrap_or_default(),
                plan.file.path.display()
            ));
        }
        e
    })
}

/// A source's records in the order of their files: a `components:` record is the files that
/// share its partition, any other record one file.
fn records_of<'f>(source: &SourceSpec, files: &'f [MatchedFile]) -> Vec<Vec<&'f MatchedFile>> {
    if source.components.is_none() {
        return files.iter().map(|f| vec![f]).collect();
    }
    let mut records: indexmap::IndexMap<&crate::pipeline::layout::Partition, Vec<&MatchedFile>> =
        indexmap::IndexMap::new();
    for file in files {
        records.entry(&file.partition).or_default().push(file);
    }
    records.into_values().collect()
}

/// The records of a `components:` source with fewer files than the axes it `require`s, each said
/// with its files: `run` would refuse them (a record's axes come from its files' headers, read
/// by `run`; a count needs none).
fn incomplete_records(name: &str, components: &Components, records: &[Vec<&MatchedFile>]) -> Vec<String> {
    let wanted = components.require.len();
    records
        .iter()
        .filter(|files| files.len() < wanted)
        .map(|files| {
            let labels: Vec<String> = files.iter().map(|f| file_label(&f.path)).collect();
            format!(
                "source `{name}`: record `{}` has {} component file(s) ({}), fewer than the {wanted} axes `components: require` asks for",
                stages::partition_path(&files[0].partition),
                files.len(),
                labels.join(", "),
            )
        })
        .collect()
}

/// A run-independent name for a file: its file name.
fn file_label(path: &Path) -> String {
    path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn source(yaml: &str) -> SourceSpec {
        serde_yaml::from_str(yaml).unwrap()
    }

    fn file(path: &str, partition: &[(&str, &str)]) -> MatchedFile {
        MatchedFile {
            path: PathBuf::from(path),
            partition: partition.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect(),
        }
    }

    const KNET: &str = "format: knet\npath: knet/{station}.{component}\ncomponents:\n  key: component\n";

    #[test]
    fn a_components_record_is_the_files_of_its_partition_and_any_other_record_one_file() {
        let files = vec![
            file("knet/A.EW", &[("station", "A")]),
            file("knet/B.EW", &[("station", "B")]),
            file("knet/A.NS", &[("station", "A")]),
        ];
        let grouped = records_of(&source(KNET), &files);
        let paths = |records: &[Vec<&MatchedFile>]| -> Vec<Vec<String>> {
            records.iter().map(|r| r.iter().map(|f| f.path.display().to_string()).collect()).collect()
        };
        assert_eq!(paths(&grouped), [vec!["knet/A.EW", "knet/A.NS"], vec!["knet/B.EW"]]);
        let single = records_of(&source("format: knet\npath: knet/{station}.EW\n"), &files);
        assert_eq!(paths(&single), [vec!["knet/A.EW"], vec!["knet/B.EW"], vec!["knet/A.NS"]]);
    }

    #[test]
    fn a_record_with_fewer_component_files_than_required_axes_is_named_with_its_files() {
        let spec = source(KNET);
        let files = [
            file("x/A.EW", &[("station", "A")]),
            file("x/A.NS", &[("station", "A")]),
            file("x/A.UD", &[("station", "A")]),
        ];
        let short = [file("x/B.EW", &[("station", "B")]), file("x/B.NS", &[("station", "B")])];
        let records = vec![files.iter().collect(), short.iter().collect()];
        let problems = incomplete_records("knet", spec.components.as_ref().unwrap(), &records);
        assert_eq!(
            problems,
            ["source `knet`: record `station=B` has 2 component file(s) (B.EW, B.NS), fewer than the 3 axes `components: require` asks for"]
        );
    }

    #[test]
    fn a_file_past_the_first_lacking_a_named_column_is_refused_at_its_header_line() {
        let dir = crate::tempdir::tempdir().unwrap();
        let path = dir.path().join("FB-2.csv");
        std::fs::write(&path, "a header line\nTime,EW,UD\n0.0,0.1,0.2\n0.01,0.1,0.2\n").unwrap();
        let spec = source("format: csv\npath: '{motion}.csv'\nheader_lines: 1\ntime_column: Time\ncolumns:\n  ax_mps2: EW\n  ay_mps2: NS\n");
        let refused = check_record_header("daq", &spec, &path).unwrap_err();
        assert_eq!((refused.file.as_deref(), refused.line, refused.column), (Some(path.as_path()), Some(2), Some(1)));
        assert_eq!(refused.message, "source `daq`: the file has no column `NS`");
        assert!(refused.hint.as_deref().unwrap().ends_with("its columns are: Time, EW, UD"), "{refused:?}");
        std::fs::write(&path, "a header line\nTime,EW,NS\n0.0,0.1,0.2\n").unwrap();
        check_record_header("daq", &spec, &path).unwrap();
    }

    #[test]
    fn a_file_is_labelled_by_its_name_alone() {
        assert_eq!(file_label(Path::new("/runs/archive/FB-4/daq.csv")), "daq.csv");
        assert_eq!(file_label(Path::new("/")), "/");
    }
}
