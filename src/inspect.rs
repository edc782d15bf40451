//! `shakeflow inspect`: what an artifact holds, what its numbers mean and where it came from.
//!
//! Schema, units and provenance come from the Parquet metadata (arrow-rs keeps field metadata);
//! the per-column statistics and the preview are a polars query over the same file.

use std::fmt::Write as _;
use std::fs::File;
use std::path::Path;

use polars::prelude::*;
use polars_io::parquet::read::ParquetReader;
use polars_io::SerReader;

use crate::io::hash;
use crate::io::{mcap, parquet};
use crate::table::ColumnData;

pub fn describe(path: &Path, preview_rows: usize) -> anyhow::Result<String> {
    if path.is_dir() {
        return describe_dataset(path);
    }
    match path.extension().and_then(|e| e.to_str()) {
        Some("mcap") => describe_mcap(path),
        _ => describe_parquet(path, preview_rows),
    }
}

fn describe_parquet(path: &Path, preview_rows: usize) -> anyhow::Result<String> {
    let table = parquet::read_table(path)?;
    let mut out = String::new();
    writeln!(out, "{}: Parquet, {} rows, {} columns", path.display(), table.num_rows(), table.columns.len())?;
    let frame = ParquetReader::new(File::open(path)?)
        .finish()
        .map_err(|e| anyhow::anyhow!("polars could not read `{}`: {e}", path.display()))?;
    let float_columns: Vec<&str> = table
        .columns
        .iter()
        .filter(|c| matches!(c.data, ColumnData::F64(_) | ColumnData::OptF64(_)))
        .map(|c| c.name.as_str())
        .collect();
    let stats = if float_columns.is_empty() {
        None
    } else {
        let exprs: Vec<Expr> = float_columns
            .iter()
            .flat_map(|c| {
                [
                    col(*c).min().alias(format!("{c}:min")),
                    col(*c).max().alias(format!("{c}:max")),
                    col(*c).mean().alias(format!("{c}:mean")),
                ]
            })
            .collect();
        Some(frame.clone().lazy().select(exprs).collect()?)
    };
    let stat = |name: &str, what: &str| -> Option<f64> {
        stats.as_ref()?.column(&format!("{name}:{what}")).ok()?.f64().ok()?.get(0)
    };
    writeln!(out, "\ncolumns:")?;
    writeln!(
        out,
        "  {:<22} {:<18} {:<10} {:>12} {:>12} {:>12}  description",
        "name", "type", "unit", "min", "max", "mean"
    )?;
    for column in &table.columns {
        let fmt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.5e}"));
        writeln!(
            out,
            "  {:<22} {:<18} {:<10} {:>12} {:>12} {:>12}  {}",
            column.name,
            column.data.type_name(),
            if column.unit.is_empty() { "-" } else { &column.unit },
            fmt(stat(&column.name, "min")),
            fmt(stat(&column.name, "max")),
            fmt(stat(&column.name, "mean")),
            column.description
        )?;
    }
    writeln!(out, "\nmetadata:")?;
    for (key, value) in &table.metadata {
        let shown = match serde_json::from_str::<serde_json::Value>(value) {
            Ok(json @ (serde_json::Value::Object(_) | serde_json::Value::Array(_))) => {
                serde_json::to_string_pretty(&json)?.replace('\n', "\n    ")
            }
            _ => value.clone(),
        };
        writeln!(out, "  {key}: {shown}")?;
    }
    if preview_rows > 0 {
        writeln!(out, "\nfirst {preview_rows} rows:\n{}", frame.head(Some(preview_rows)))?;
    }
    Ok(out)
}

/// A (small) table as aligned text, or as CSV: a Parquet file, or a stage's output folder with
/// every partition (keys as columns, as `export` reads them). `max_rows` defaults to 100 as
/// text and to every row as CSV; `columns` (when not empty) picks and orders the columns shown.
/// Returns the text and warnings (columns missing from some partitions).
pub fn show(
    path: &Path,
    max_rows: Option<usize>,
    columns: &[String],
    csv: bool,
) -> anyhow::Result<(String, Vec<String>)> {
    let (mut frame, warnings) = if path.is_dir() {
        let dataset = crate::export::read(&[path.to_path_buf()], None)?;
        (dataset.frame, dataset.warnings)
    } else {
        let file = File::open(path).map_err(|e| anyhow::anyhow!("cannot open `{}`: {e}", path.display()))?;
        let frame = ParquetReader::new(file)
            .finish()
            .map_err(|e| anyhow::anyhow!("polars could not read `{}`: {e}", path.display()))?;
        (frame, Vec::new())
    };
    if !columns.is_empty() {
        let names: Vec<String> = frame.get_column_names().iter().map(|n| n.to_string()).collect();
        if let Some(missing) = columns.iter().find(|c| !names.contains(c)) {
            anyhow::bail!("`{}` has no column `{missing}`; it has {}", path.display(), names.join(", "));
        }
        frame = frame.select(columns.iter().map(String::as_str))?;
    }
    if csv {
        let frame = max_rows.map_or(frame.clone(), |n| frame.head(Some(n)));
        let mut bytes = Vec::new();
        crate::export::write_csv(&mut bytes, &frame)?;
        return Ok((String::from_utf8(bytes)?, warnings));
    }
    // polars reads its display limits from the environment; set them for this process only.
    std::env::set_var("POLARS_FMT_MAX_ROWS", max_rows.unwrap_or(100).to_string());
    std::env::set_var("POLARS_FMT_MAX_COLS", "30");
    std::env::set_var("POLARS_FMT_STR_LEN", "40");
    std::env::set_var("POLARS_FMT_TABLE_HIDE_DATAFRAME_SHAPE_INFORMATION", "1");
    Ok((format!("{frame}\n"), warnings))
}

fn describe_mcap(path: &Path) -> anyhow::Result<String> {
    let s = mcap::summarize(path)?;
    let mut out = String::new();
    writeln!(
        out,
        "{}: MCAP, {} messages from {:.3} s to {:.3} s",
        path.display(),
        s.message_count,
        s.start_s,
        s.end_s
    )?;
    writeln!(out, "\nchannels (topic, schema, messages):")?;
    for (topic, schema, count) in &s.channels {
        writeln!(out, "  {topic}  {schema}  {count}")?;
    }
    writeln!(out, "\nmetadata:")?;
    for (key, value) in &s.metadata {
        writeln!(out, "  {key}: {value}")?;
    }
    Ok(out)
}

fn describe_dataset(dir: &Path) -> anyhow::Result<String> {
    let files = hash::list_files(dir)?;
    let parts: Vec<&String> = files.iter().filter(|f| f.ends_with(".parquet")).collect();
    let mut out = String::new();
    writeln!(out, "{}: dataset of {} Parquet part(s), {} file(s) in all", dir.display(), parts.len(), files.len())?;
    let mut total = 0usize;
    for part in &parts {
        let table = parquet::read_table(&dir.join(part))?;
        total += table.num_rows();
        writeln!(out, "  {part}: {} rows × {} columns", table.num_rows(), table.columns.len())?;
    }
    writeln!(out, "total rows: {total}")?;
    writeln!(out, "\nread it as one dataset, e.g. DuckDB: SELECT * FROM read_parquet('{}/**/*.parquet', hive_partitioning = true)", dir.display())?;
    Ok(out)
}
