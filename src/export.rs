//! `shakeflow export`: stage outputs as one tidy table for Python and R.
//!
//! Every Parquet part of the datasets named is read by polars; its partition keys (the
//! `shakeflow.partition` each file records, percent-decoded) become plain text columns; the parts
//! are aligned on the union of their columns by name (a column a part lacks is null there) and
//! stacked by one lazy polars query. Units, descriptions and provenance come from the files'
//! metadata through arrow-rs (polars drops Arrow field metadata). The table goes to CSV (RFC 4180,
//! header row, `NA` for null) or to one Parquet file (units as field metadata, provenance as
//! schema metadata), and `<stem>.meta.json` always goes beside it: per column its unit and
//! description, and the provenance of every stage output exported.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Context;
use arrow::array::{ArrayRef, BooleanArray, Float64Array, Int64Array, StringArray};
use arrow::datatypes::{DataType as ArrowType, Field, Schema};
use indexmap::IndexMap;
use polars::prelude::{col, concat, lit, DataFrame, DataType, Expr, IntoLazy, LazyFrame, UnionArgs, NULL};
use polars_io::parquet::read::ParquetReader;
use polars_io::SerReader;
use serde_json::{json, Value};

use crate::error::UserError;
use crate::io::parquet::{self, ColumnInfo};
use crate::io::{atomic, hash};
use crate::pipeline::layout::DATA_FILE;
use crate::pipeline::paths::decode_component;

/// What `export` wrote.
#[derive(Debug)]
pub struct Exported {
    pub rows: usize,
    pub columns: usize,
    pub meta: PathBuf,
    /// Things the user should know (columns missing from some partitions), also in the meta file.
    pub warnings: Vec<String>,
}

#[derive(Clone, Copy, PartialEq, Debug)]
enum Format {
    Csv,
    Parquet,
}

#[derive(Clone, Copy, PartialEq, Debug)]
enum Kind {
    Float,
    Int,
    Bool,
    Text,
}

impl Kind {
    fn of(column: &ColumnInfo, file: &Path) -> anyhow::Result<Kind> {
        Ok(match column.data_type {
            ArrowType::Float64 => Kind::Float,
            ArrowType::Int64 => Kind::Int,
            ArrowType::Boolean => Kind::Bool,
            ArrowType::Utf8 => Kind::Text,
            ref other => {
                return Err(UserError::new(format!(
                    "column `{}` has the type {other}, which export does not write",
                    column.name
                ))
                .in_file(file)
                .into())
            }
        })
    }

    fn name(self) -> &'static str {
        match self {
            Kind::Float => "float64",
            Kind::Int => "int64",
            Kind::Bool => "bool",
            Kind::Text => "string",
        }
    }

    fn polars(self) -> DataType {
        match self {
            Kind::Float => DataType::Float64,
            Kind::Int => DataType::Int64,
            Kind::Bool => DataType::Boolean,
            Kind::Text => DataType::String,
        }
    }

    fn arrow(self) -> ArrowType {
        match self {
            Kind::Float => ArrowType::Float64,
            Kind::Int => ArrowType::Int64,
            Kind::Bool => ArrowType::Boolean,
            Kind::Text => ArrowType::Utf8,
        }
    }
}

/// One Parquet file of a stage output.
struct Part {
    path: PathBuf,
    /// `stage.output/partition` (decoded), how messages and the meta file name it.
    label: String,
    keys: Vec<(String, String)>,
    columns: Vec<ColumnInfo>,
    metadata: BTreeMap<String, String>,
}

/// One column of the exported table, gathered over the parts.
struct Union {
    kind: Kind,
    unit: String,
    /// Part label → description (as the part's file says).
    descriptions: IndexMap<String, String>,
    /// Indices of the parts that have it.
    present: Vec<usize>,
    nullable: bool,
    partition_key: bool,
}

/// Stage outputs read as one table: the frame, and what the parts said about its columns.
pub struct Dataset {
    /// Partition keys first, then the columns of the parts, aligned by name.
    pub frame: DataFrame,
    /// Things the user should know (columns missing from some partitions).
    pub warnings: Vec<String>,
    columns: IndexMap<String, Union>,
    parts: Vec<Part>,
}

impl Dataset {
    /// Per row, the record it came from: its partition values joined by `/` (as the stages'
    /// `record` columns name records), empty for an unpartitioned output.
    pub fn record_labels(&self) -> anyhow::Result<Vec<String>> {
        let mut labels = vec![String::new(); self.frame.height()];
        for (name, column) in &self.columns {
            // The `stage` column of several stages is no partition of theirs.
            if column.partition_key && !column.present.is_empty() {
                for (label, value) in labels.iter_mut().zip(self.frame.column(name)?.str()?.iter()) {
                    if !label.is_empty() {
                        label.push('/');
                    }
                    label.push_str(value.unwrap_or(""));
                }
            }
        }
        Ok(labels)
    }
}

/// Reads stage outputs (Parquet files or output folders) as one table; `out`, when given, is
/// where it is going, which may not lie inside a folder read.
pub fn read(datasets: &[PathBuf], out: Option<&Path>) -> anyhow::Result<Dataset> {
    let mut parts = Vec::new();
    for dataset in datasets {
        parts.extend(parts_of(dataset, out)?);
    }
    let mut seen = BTreeMap::new();
    for part in &parts {
        let real = std::fs::canonicalize(&part.path).unwrap_or_else(|_| part.path.clone());
        if let Some(first) = seen.insert(real, part.label.clone()) {
            return Err(UserError::new(format!("`{}` is named twice (as part of `{first}` too)", part.path.display()))
                .hint("name each file or output folder once")
                .into());
        }
    }
    let several_stages =
        parts.iter().any(|p| p.metadata.get("shakeflow.stage") != parts[0].metadata.get("shakeflow.stage"));
    let columns = union_columns(&parts, several_stages)?;
    let warnings = missing_warnings(&parts, &columns);
    let frame = stack(&parts, &columns, several_stages)?;
    Ok(Dataset { frame, warnings, columns, parts })
}

/// Writes the stage outputs `datasets` (Parquet files or output folders) as one table `out`
/// (`.csv` or `.parquet`) and its `<stem>.meta.json`.
pub fn export(datasets: &[PathBuf], out: &Path) -> anyhow::Result<Exported> {
    let format = format_of(out)?;
    let dataset = read(datasets, Some(out))?;
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).with_context(|| format!("cannot create `{}`", parent.display()))?;
    }
    let provenance = provenance(&dataset.parts);
    match format {
        Format::Csv => atomic::write_file(out, |w| write_csv(w, &dataset.frame))
            .with_context(|| format!("writing `{}`", out.display()))?,
        Format::Parquet => write_parquet(out, &dataset.frame, &dataset.columns, &provenance)?,
    }
    let meta = meta_path(out);
    let rows = dataset.frame.height();
    let meta_json = meta_json(out, format, rows, &dataset.columns, &provenance, &dataset.warnings);
    atomic::write_file(&meta, |w| {
        w.write_all(serde_json::to_string_pretty(&meta_json)?.as_bytes())?;
        w.write_all(b"\n")?;
        Ok(())
    })?;
    Ok(Exported { rows, columns: dataset.columns.len(), meta, warnings: dataset.warnings })
}

/// `FILE`'s sibling `<stem>.meta.json`.
pub fn meta_path(out: &Path) -> PathBuf {
    let stem = out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    out.with_file_name(format!("{stem}.meta.json"))
}

fn format_of(out: &Path) -> anyhow::Result<Format> {
    let extension = out.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    match extension.as_deref() {
        Some("csv") => Ok(Format::Csv),
        Some("parquet") => Ok(Format::Parquet),
        other => Err(UserError::new(format!(
            "cannot tell the format of `{}` from its extension ({})",
            out.display(),
            other.map_or("none".to_string(), |e| format!("`.{e}`"))
        ))
        .hint("name the output `….csv` (for R, spreadsheets, pandas) or `….parquet` (pyarrow, polars, DuckDB)")
        .into()),
    }
}

/// The Parquet files of one dataset argument, with their partition keys and metadata.
fn parts_of(dataset: &Path, out: Option<&Path>) -> anyhow::Result<Vec<Part>> {
    let not_output = |what: &str| {
        UserError::new(format!("`{}` is not a shakeflow output: {what}", dataset.display()))
            .hint("name a stage's output folder or one of its files, e.g. runs/demo/report/summary or runs/demo/synchronize/records/motion=FB-4/data.parquet")
    };
    let files: Vec<PathBuf> = if dataset.is_dir() {
        let target = out.and_then(|out| {
            let parent = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
            std::fs::canonicalize(parent).ok().map(|p| (out, p))
        });
        if let (Ok(folder), Some((out, target))) = (std::fs::canonicalize(dataset), target) {
            if target.starts_with(&folder) {
                return Err(UserError::new(format!(
                    "`{}` lies inside the dataset `{}`: the export would become part of what it reads",
                    out.display(),
                    dataset.display()
                ))
                .hint("write the export outside the output folder, e.g. `--out exports/table.csv`")
                .into());
            }
        }
        hash::list_files(dataset)?
            .into_iter()
            // Hidden entries are shakeflow's own (stage markers, transactions), never data.
            .filter(|f| f.rsplit('/').next() == Some(DATA_FILE) && !f.split('/').any(|c| c.starts_with('.')))
            .map(|f| dataset.join(f))
            .collect()
    } else if dataset.is_file() {
        vec![dataset.to_path_buf()]
    } else {
        return Err(UserError::new(format!("no such file or folder: `{}`", dataset.display()))
            .hint("name a stage's output folder (e.g. runs/demo/report/summary) or a Parquet file in it")
            .into());
    };
    if files.is_empty() {
        return Err(not_output(&format!("it holds no `{DATA_FILE}`")).into());
    }
    let mut parts = Vec::new();
    for path in files {
        let (columns, metadata) = parquet::read_schema(&path).map_err(|e| {
            not_output(&format!("`{}` is not a Parquet file a shakeflow stage wrote ({e})", path.display()))
        })?;
        let (Some(stage), Some(output)) = (metadata.get("shakeflow.stage"), metadata.get("shakeflow.output")) else {
            return Err(not_output(&format!(
                "`{}` has no shakeflow provenance (shakeflow.stage, shakeflow.output)",
                path.display()
            ))
            .into());
        };
        let encoded = metadata.get("shakeflow.partition").cloned().unwrap_or_default();
        let keys: Vec<(String, String)> = encoded
            .split('/')
            .filter(|s| !s.is_empty())
            .map(|segment| {
                let (k, v) = segment.split_once('=').unwrap_or((segment, ""));
                (decode_component(k), decode_component(v))
            })
            .collect();
        let decoded: Vec<String> = keys.iter().map(|(k, v)| format!("{k}={v}")).collect();
        let label = if decoded.is_empty() {
            format!("{stage}.{output}")
        } else {
            format!("{stage}.{output}/{}", decoded.join("/"))
        };
        parts.push(Part { path, label, keys, columns, metadata });
    }
    let outputs: Vec<&str> = parts.iter().map(|p| p.label.split('/').next().unwrap_or_default()).collect();
    if let Some(other) = outputs.iter().find(|o| **o != outputs[0]) {
        return Err(UserError::new(format!(
            "`{}` holds several outputs ({} and {other}): export them one at a time or name each output folder",
            dataset.display(),
            outputs[0]
        ))
        .hint("a stage folder holds one folder per output; name the one you want, e.g. …/records")
        .into());
    }
    Ok(parts)
}

/// The exported columns in order: `stage` (when several stages are exported), the partition keys
/// in order of first appearance, then every part's columns in order of first appearance.
fn union_columns(parts: &[Part], several_stages: bool) -> anyhow::Result<IndexMap<String, Union>> {
    let mut columns: IndexMap<String, Union> = IndexMap::new();
    let key_column = |description: String| Union {
        kind: Kind::Text,
        unit: String::new(),
        descriptions: IndexMap::from([(String::new(), description)]),
        present: Vec::new(),
        nullable: false,
        partition_key: true,
    };
    if several_stages {
        columns.insert("stage".into(), key_column("the stage that wrote the row".into()));
    }
    for (i, part) in parts.iter().enumerate() {
        for (key, _) in &part.keys {
            if several_stages && key == "stage" {
                return Err(UserError::new(format!(
                    "`{}` has a partition key `stage`, the column that tells several stages apart",
                    part.label
                ))
                .hint("export the outputs one at a time")
                .into());
            }
            let entry = columns.entry(key.clone()).or_insert_with(|| {
                key_column(format!("partition key `{key}` (the `{key}=…` folder of the stage output)"))
            });
            entry.present.push(i);
        }
    }
    for (i, part) in parts.iter().enumerate() {
        for column in &part.columns {
            let kind = Kind::of(column, &part.path)?;
            match columns.get_mut(&column.name) {
                Some(existing) if existing.partition_key => {
                    return Err(UserError::new(format!(
                        "column `{}` of `{}` has the name of a partition key",
                        column.name, part.label
                    ))
                    .hint("export the outputs one at a time")
                    .into())
                }
                Some(existing) => {
                    let first = &parts[existing.present[0]].label;
                    if existing.kind != kind {
                        return Err(UserError::new(format!(
                            "column `{}` is {} in `{first}` but {} in `{}`",
                            column.name,
                            existing.kind.name(),
                            kind.name(),
                            part.label
                        ))
                        .hint("a column of one name must have one type; export the outputs one at a time")
                        .into());
                    }
                    if existing.unit != column.unit {
                        return Err(UserError::new(format!(
                            "column `{}` is in `{}` in `{first}` but in `{}` in `{}`",
                            column.name,
                            shown_unit(&existing.unit),
                            shown_unit(&column.unit),
                            part.label
                        ))
                        .hint("a column of one name must have one unit; export the outputs one at a time")
                        .into());
                    }
                    existing.descriptions.insert(part.label.clone(), column.description.clone());
                    existing.present.push(i);
                    existing.nullable |= column.nullable;
                }
                None => {
                    columns.insert(
                        column.name.clone(),
                        Union {
                            kind,
                            unit: column.unit.clone(),
                            descriptions: IndexMap::from([(part.label.clone(), column.description.clone())]),
                            present: vec![i],
                            nullable: column.nullable,
                            partition_key: false,
                        },
                    );
                }
            }
        }
    }
    for column in columns.values_mut() {
        column.nullable |= column.present.len() < parts.len() && !(several_stages && column.present.is_empty());
    }
    Ok(columns)
}

fn shown_unit(unit: &str) -> String {
    if unit.is_empty() {
        "no unit".into()
    } else {
        format!("`{unit}`")
    }
}

/// One warning per set of columns missing from the same parts.
fn missing_warnings(parts: &[Part], columns: &IndexMap<String, Union>) -> Vec<String> {
    let mut by_parts: IndexMap<Vec<usize>, Vec<&str>> = IndexMap::new();
    for (name, column) in columns {
        if column.present.len() < parts.len() && !(column.partition_key && column.present.is_empty()) {
            let missing: Vec<usize> = (0..parts.len()).filter(|i| !column.present.contains(i)).collect();
            by_parts.entry(missing).or_default().push(name);
        }
    }
    by_parts
        .into_iter()
        .map(|(missing, names)| {
            let listed: Vec<&str> = missing.iter().take(5).map(|&i| parts[i].label.as_str()).collect();
            let more = if missing.len() > 5 { ", …" } else { "" };
            let names: Vec<String> = names.iter().map(|n| format!("`{n}`")).collect();
            format!(
                "column{} {} missing from {} of {} partitions ({}{more}): null there",
                if names.len() == 1 { "" } else { "s" },
                names.join(", "),
                missing.len(),
                parts.len(),
                listed.join(", ")
            )
        })
        .collect()
}

/// Every part read by polars, aligned on the union of columns, stacked in one lazy query.
fn stack(parts: &[Part], columns: &IndexMap<String, Union>, several_stages: bool) -> anyhow::Result<DataFrame> {
    let mut frames: Vec<LazyFrame> = Vec::with_capacity(parts.len());
    for (i, part) in parts.iter().enumerate() {
        let file = File::open(&part.path).with_context(|| format!("cannot open `{}`", part.path.display()))?;
        let frame = ParquetReader::new(file)
            .finish()
            .map_err(|e| anyhow::anyhow!("polars could not read `{}`: {e}", part.path.display()))?;
        let null = |name: &str, kind: Kind| lit(NULL).cast(kind.polars()).alias(name);
        let exprs: Vec<Expr> = columns
            .iter()
            .map(|(name, column)| {
                if several_stages && name == "stage" && column.present.is_empty() {
                    lit(part.metadata.get("shakeflow.stage").cloned().unwrap_or_default()).alias(name.as_str())
                } else if column.partition_key {
                    match part.keys.iter().find(|(k, _)| k == name) {
                        Some((_, value)) => lit(value.clone()).alias(name.as_str()),
                        None => null(name, Kind::Text),
                    }
                } else if column.present.contains(&i) {
                    col(name.as_str())
                } else {
                    null(name, column.kind)
                }
            })
            .collect();
        frames.push(frame.lazy().select(exprs));
    }
    let args = UnionArgs { rechunk: true, maintain_order: true, ..UnionArgs::default() };
    Ok(concat(frames, args)?.collect()?)
}

/// Stage-level provenance: one entry per stage output, with the partitions and their inputs.
fn provenance(parts: &[Part]) -> Vec<Value> {
    let json_of = |part: &Part, key: &str| -> Value {
        part.metadata.get(key).map_or(Value::Null, |v| serde_json::from_str(v).unwrap_or_else(|_| json!(v)))
    };
    let text_of = |part: &Part, key: &str| -> Value { part.metadata.get(key).map_or(Value::Null, |v| json!(v)) };
    let mut groups: IndexMap<String, (Value, Vec<Value>)> = IndexMap::new();
    for part in parts {
        let stage = json!({
            "stage": text_of(part, "shakeflow.stage"),
            "stage_type": text_of(part, "shakeflow.stage_type"),
            "stage_version": json_of(part, "shakeflow.stage_version"),
            "output": text_of(part, "shakeflow.output"),
            "parameters": json_of(part, "shakeflow.params"),
            "input_hashes": json_of(part, "shakeflow.inputs"),
            "shakeflow_version": text_of(part, "shakeflow.version"),
        });
        let keys: serde_json::Map<String, Value> = part.keys.iter().map(|(k, v)| (k.clone(), json!(v))).collect();
        let mut partition = json!({ "partition": part.label, "keys": keys });
        for (key, name) in [("shakeflow.input_file", "input_file"), ("shakeflow.input_hash", "input_hash")] {
            if let Some(v) = part.metadata.get(key) {
                partition[name] = json!(v);
            }
        }
        groups.entry(stage.to_string()).or_insert_with(|| (stage, Vec::new())).1.push(partition);
    }
    groups
        .into_values()
        .map(|(mut stage, partitions)| {
            stage["partitions"] = json!(partitions);
            stage
        })
        .collect()
}

/// One description when the parts agree; else a pointer to `descriptions`, one per partition.
fn description_json(column: &Union) -> (String, Option<Value>) {
    let first = column.descriptions.values().next().cloned().unwrap_or_default();
    if column.descriptions.values().all(|d| *d == first) {
        (first, None)
    } else {
        let each: serde_json::Map<String, Value> =
            column.descriptions.iter().map(|(label, d)| (label.clone(), json!(d))).collect();
        ("differs by partition: see `descriptions`".into(), Some(Value::Object(each)))
    }
}

fn meta_json(
    out: &Path,
    format: Format,
    rows: usize,
    columns: &IndexMap<String, Union>,
    provenance: &[Value],
    warnings: &[String],
) -> Value {
    let mut described = serde_json::Map::new();
    for (name, column) in columns {
        let (description, each) = description_json(column);
        let mut entry = json!({ "type": column.kind.name(), "unit": column.unit, "description": description });
        if let Some(each) = each {
            entry["descriptions"] = each;
        }
        if column.partition_key {
            entry["partition_key"] = json!(true);
        }
        described.insert(name.clone(), entry);
    }
    let mut meta = json!({
        "table": out.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default(),
        "format": match format { Format::Csv => "csv", Format::Parquet => "parquet" },
        "rows": rows,
        "columns": described,
        "provenance": provenance,
        "warnings": warnings,
        "exported_by": format!("shakeflow {}", env!("CARGO_PKG_VERSION")),
    });
    if format == Format::Csv {
        meta["null"] = json!("NA");
    }
    meta
}

/// A float as the shortest text that reads back to the same number; `NaN`, `Inf`, `-Inf` as R
/// and pandas spell them.
fn float_text(v: f64) -> String {
    if v.is_nan() {
        "NaN".into()
    } else if v.is_infinite() {
        if v > 0.0 { "Inf" } else { "-Inf" }.into()
    } else {
        format!("{v:?}")
    }
}

/// A text field, quoted (RFC 4180: `"` doubled) when it holds a separator, quote or line break,
/// has surrounding spaces, is empty, or reads as the null marker `NA`.
fn text_field(s: &str) -> String {
    let plain = !s.is_empty()
        && s != "NA"
        && !s.contains([',', '"', '\r', '\n'])
        && !s.starts_with(char::is_whitespace)
        && !s.ends_with(char::is_whitespace);
    if plain {
        s.to_string()
    } else {
        format!("\"{}\"", s.replace('"', "\"\""))
    }
}

/// `frame` as CSV (RFC 4180: a header row, CRLF line ends, quotes where needed), `NA` for null,
/// `TRUE`/`FALSE` for booleans, floats as the shortest text that reads back to the same number.
pub fn write_csv(w: &mut impl std::io::Write, frame: &DataFrame) -> anyhow::Result<()> {
    enum Cells {
        Float(polars::prelude::Float64Chunked),
        Int(polars::prelude::Int64Chunked),
        Bool(polars::prelude::BooleanChunked),
        Text(polars::prelude::StringChunked),
    }
    let mut cells = Vec::with_capacity(frame.width());
    for c in frame.columns() {
        let series = c.as_materialized_series();
        cells.push(match series.dtype() {
            DataType::Float64 | DataType::Float32 => Cells::Float(series.cast(&DataType::Float64)?.f64()?.clone()),
            DataType::Boolean => Cells::Bool(series.bool()?.clone()),
            DataType::String => Cells::Text(series.str()?.clone()),
            t if t.is_integer() => Cells::Int(series.cast(&DataType::Int64)?.i64()?.clone()),
            other => anyhow::bail!("column `{}` has the type {other}, which CSV output does not write", c.name()),
        });
    }
    let header: Vec<String> = frame.get_column_names().iter().map(|n| text_field(n)).collect();
    w.write_all(header.join(",").as_bytes())?;
    w.write_all(b"\r\n")?;
    let mut line = String::new();
    for row in 0..frame.height() {
        line.clear();
        for (i, cell) in cells.iter().enumerate() {
            if i > 0 {
                line.push(',');
            }
            let text = match cell {
                Cells::Float(c) => c.get(row).map(float_text),
                Cells::Int(c) => c.get(row).map(|v| v.to_string()),
                Cells::Bool(c) => c.get(row).map(|v| if v { "TRUE" } else { "FALSE" }.to_string()),
                Cells::Text(c) => c.get(row).map(text_field),
            };
            line.push_str(text.as_deref().unwrap_or("NA"));
        }
        line.push_str("\r\n");
        w.write_all(line.as_bytes())?;
    }
    Ok(())
}

fn write_parquet(
    out: &Path,
    frame: &DataFrame,
    columns: &IndexMap<String, Union>,
    provenance: &[Value],
) -> anyhow::Result<()> {
    let mut fields = Vec::with_capacity(columns.len());
    let mut arrays: Vec<ArrayRef> = Vec::with_capacity(columns.len());
    for (name, column) in columns {
        let c = frame.column(name)?;
        let (description, _) = description_json(column);
        let metadata = std::collections::HashMap::from([
            ("unit".to_string(), column.unit.clone()),
            ("description".to_string(), description),
        ]);
        let array: ArrayRef = match column.kind {
            Kind::Float => Arc::new(c.f64()?.iter().collect::<Float64Array>()),
            Kind::Int => Arc::new(c.i64()?.iter().collect::<Int64Array>()),
            Kind::Bool => Arc::new(c.bool()?.iter().collect::<BooleanArray>()),
            Kind::Text => Arc::new(c.str()?.iter().collect::<StringArray>()),
        };
        fields.push(
            Field::new(name, column.kind.arrow(), column.nullable || array.null_count() > 0).with_metadata(metadata),
        );
        arrays.push(array);
    }
    let metadata = std::collections::HashMap::from([
        ("shakeflow.export".to_string(), serde_json::to_string(provenance)?),
        ("shakeflow.version".to_string(), env!("CARGO_PKG_VERSION").to_string()),
    ]);
    parquet::write_arrays(out, Schema::new_with_metadata(fields, metadata), arrays)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_read_back_exactly_and_text_is_quoted_only_where_needed() {
        for v in [0.1, 1.0, -0.0, 1e-300, 123456789.123, f64::MAX, 5e-324, 0.9999999999999999] {
            assert_eq!(float_text(v).parse::<f64>().unwrap().to_bits(), v.to_bits(), "{v}");
        }
        assert_eq!(float_text(f64::NAN), "NaN");
        assert_eq!(float_text(f64::NEG_INFINITY), "-Inf");
        assert_eq!(text_field("FB-4"), "FB-4");
        assert_eq!(text_field("a,b"), "\"a,b\"");
        assert_eq!(text_field("say \"hi\""), "\"say \"\"hi\"\"\"");
        assert_eq!(text_field("NA"), "\"NA\"");
        assert_eq!(text_field(""), "\"\"");
        assert_eq!(text_field("two\nlines"), "\"two\nlines\"");
    }

    #[test]
    fn the_meta_file_sits_beside_the_table() {
        assert_eq!(meta_path(Path::new("out/study.csv")), Path::new("out/study.meta.json"));
        assert_eq!(meta_path(Path::new("t.parquet")), Path::new("t.meta.json"));
        let err = format_of(Path::new("t.xlsx")).unwrap_err().to_string();
        assert!(err.contains("`.xlsx`") && err.contains(".csv"), "{err}");
        assert!(format_of(Path::new("t")).unwrap_err().to_string().contains("(none)"));
    }
}
