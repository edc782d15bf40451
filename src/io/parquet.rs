//! Tables as Parquet: units and descriptions as Arrow field metadata, provenance as file metadata.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::sync::Arc;

use anyhow::{anyhow, Context};
use arrow::array::{Array, ArrayRef, BooleanArray, Float64Array, Int64Array, RecordBatch, StringArray};
use arrow::buffer::ScalarBuffer;
use arrow::datatypes::{DataType, Field, Schema};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, Encoding, ZstdLevel};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::{EnabledStatistics, WriterProperties};
use parquet::schema::types::ColumnPath;

use crate::io::atomic;
use crate::pipeline::hash::HashingWriter;
use crate::table::{Column, ColumnData, Table};

/// The Arrow schema ArrowWriter embeds for itself; not part of a table's own metadata.
const ARROW_SCHEMA_KEY: &str = "ARROW:schema";

/// Writes `table` to `path` (atomically); returns the content hash of the file written. `table`
/// is mutable only because its float columns lend their buffers to Arrow for the write instead
/// of being copied (they are most of the bytes a run writes); it comes back unchanged, whether
/// the write succeeded or not.
pub fn write_table(path: &Path, table: &mut Table) -> anyhow::Result<String> {
    let (batch, lent) = to_record_batch(table)?;
    let result = encode(path, table, &batch);
    // The writer keeps no reference once done: the buffers are ours alone again.
    drop(batch);
    give_back(table, lent);
    result
}

fn give_back(table: &mut Table, lent: Vec<Option<ScalarBuffer<f64>>>) {
    for (column, buffer) in table.columns.iter_mut().zip(lent) {
        if let Some(buffer) = buffer {
            let values = buffer.into_inner().into_vec::<f64>().unwrap_or_else(|shared| shared.typed_data().to_vec());
            column.data = ColumnData::F64(values);
        }
    }
}

fn encode(path: &Path, table: &Table, batch: &RecordBatch) -> anyhow::Result<String> {
    let kv: Vec<KeyValue> = table.metadata.iter().map(|(k, v)| KeyValue::new(k.clone(), v.clone())).collect();
    let mut props = WriterProperties::builder()
        // Names, flags and counts repeat: zstd shrinks them well.
        .set_compression(Compression::ZSTD(ZstdLevel::try_new(1)?))
        .set_statistics_enabled(EnabledStatistics::Chunk)
        .set_key_value_metadata(Some(kv));
    // Measured samples hardly repeat: a dictionary only costs time. Split into byte streams their
    // sign/exponent bytes compress, and lz4 then comes within 2 % of zstd's size in about half its
    // time (about a fifth smaller than plain floats; bench/parquet_encodings.py compares them).
    for field in batch.schema().fields() {
        if field.data_type() == &DataType::Float64 {
            let column = ColumnPath::from(field.name().as_str());
            props = props
                .set_column_dictionary_enabled(column.clone(), false)
                .set_column_encoding(column.clone(), Encoding::BYTE_STREAM_SPLIT)
                .set_column_compression(column, Compression::LZ4_RAW);
        }
    }
    let props = props.build();
    let mut hash = String::new();
    atomic::write_file(path, |w| {
        let mut writer = ArrowWriter::try_new(HashingWriter::new(w), batch.schema(), Some(props))?;
        writer.write(batch)?;
        hash = writer.into_inner()?.finalize();
        Ok(())
    })
    .with_context(|| format!("writing Parquet `{}`", path.display()))?;
    Ok(hash)
}

/// The table as one Arrow batch; each F64 column's values move into a buffer returned beside it
/// (the column is left empty until `write_table` gives them back).
fn to_record_batch(table: &mut Table) -> anyhow::Result<(RecordBatch, Vec<Option<ScalarBuffer<f64>>>)> {
    let mut fields = Vec::with_capacity(table.columns.len());
    let mut arrays: Vec<ArrayRef> = Vec::with_capacity(table.columns.len());
    let mut lent = Vec::with_capacity(table.columns.len());
    for column in &mut table.columns {
        let mut borrowed = None;
        let (data_type, nullable, array): (DataType, bool, ArrayRef) = match &mut column.data {
            ColumnData::F64(v) => {
                let buffer = ScalarBuffer::from(std::mem::take(v));
                borrowed = Some(buffer.clone());
                (DataType::Float64, false, Arc::new(Float64Array::new(buffer, None)))
            }
            ColumnData::OptF64(v) => (DataType::Float64, true, Arc::new(Float64Array::from(v.clone()))),
            ColumnData::I64(v) => (DataType::Int64, false, Arc::new(Int64Array::from(v.clone()))),
            ColumnData::Bool(v) => (DataType::Boolean, false, Arc::new(BooleanArray::from(v.clone()))),
            ColumnData::Str(v) => (DataType::Utf8, false, Arc::new(StringArray::from(v.clone()))),
            ColumnData::OptStr(v) => (DataType::Utf8, true, Arc::new(StringArray::from(v.clone()))),
        };
        let metadata = HashMap::from([
            ("unit".to_string(), column.unit.clone()),
            ("description".to_string(), column.description.clone()),
        ]);
        fields.push(Field::new(&column.name, data_type, nullable).with_metadata(metadata));
        arrays.push(array);
        lent.push(borrowed);
    }
    let schema = Arc::new(Schema::new(fields));
    match RecordBatch::try_new(schema, arrays) {
        Ok(batch) => Ok((batch, lent)),
        Err(e) => {
            give_back(table, lent);
            Err(e.into())
        }
    }
}

/// Reads a whole Parquet file written by any tool; units come back when the writer stored them.
pub fn read_table(path: &Path) -> anyhow::Result<Table> {
    // One read of the whole file: a File reader seeks and reads once per column chunk.
    let bytes = bytes::Bytes::from(std::fs::read(path).with_context(|| format!("cannot open `{}`", path.display()))?);
    let builder = ParquetRecordBatchReaderBuilder::try_new(bytes)
        .with_context(|| format!("`{}` is not a readable Parquet file", path.display()))?;
    // One batch per row group: each column then arrives in one piece instead of 1024-row batches.
    let rows = builder.metadata().row_groups().iter().map(|g| g.num_rows()).max().unwrap_or(0);
    let builder = builder.with_batch_size((rows as usize).max(1));
    let mut metadata = BTreeMap::new();
    if let Some(kv) = builder.metadata().file_metadata().key_value_metadata() {
        for entry in kv.iter().filter(|e| e.key != ARROW_SCHEMA_KEY) {
            metadata.insert(entry.key.clone(), entry.value.clone().unwrap_or_default());
        }
    }
    let schema = builder.schema().clone();
    let reader = builder.build()?;
    let batches: Vec<RecordBatch> = reader.collect::<Result<_, _>>()?;
    let mut table = Table { columns: Vec::new(), metadata };
    for (i, field) in schema.fields().iter().enumerate() {
        let meta = field.metadata();
        let parts: Vec<&ArrayRef> = batches.iter().map(|b| b.column(i)).collect();
        let data = column_data(field.data_type(), field.is_nullable(), &parts)
            .with_context(|| format!("column `{}` of `{}`", field.name(), path.display()))?;
        table.columns.push(Column {
            name: field.name().clone(),
            unit: meta.get("unit").cloned().unwrap_or_default(),
            description: meta.get("description").cloned().unwrap_or_default(),
            data,
        });
    }
    Ok(table)
}

fn column_data(data_type: &DataType, nullable: bool, parts: &[&ArrayRef]) -> anyhow::Result<ColumnData> {
    fn typed<'a, T: 'static>(parts: &'a [&ArrayRef]) -> impl Iterator<Item = &'a T> {
        parts.iter().map(|a| a.as_any().downcast_ref::<T>().expect("array type matches its schema"))
    }
    Ok(match data_type {
        DataType::Float64 if nullable => {
            ColumnData::OptF64(typed::<Float64Array>(parts).flat_map(|a| a.iter()).collect())
        }
        DataType::Float64 => {
            ColumnData::F64(typed::<Float64Array>(parts).flat_map(|a| a.values().iter().copied()).collect())
        }
        DataType::Int64 => {
            ColumnData::I64(typed::<Int64Array>(parts).flat_map(|a| a.values().iter().copied()).collect())
        }
        DataType::Boolean => {
            ColumnData::Bool(typed::<BooleanArray>(parts).flat_map(|a| a.iter().map(|v| v.unwrap_or(false))).collect())
        }
        DataType::Utf8 if nullable => ColumnData::OptStr(
            typed::<StringArray>(parts).flat_map(|a| a.iter().map(|v| v.map(str::to_string))).collect(),
        ),
        DataType::Utf8 => ColumnData::Str(
            typed::<StringArray>(parts).flat_map(|a| a.iter().map(|v| v.unwrap_or_default().to_string())).collect(),
        ),
        other => return Err(anyhow!("unsupported column type {other}")),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_is_the_identity() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.parquet");
        let mut t = Table::new();
        t.push(Column::f64("time_s", "s", "time", vec![0.0, 0.5]));
        t.push(Column {
            name: "when".into(),
            unit: "s".into(),
            description: "maybe".into(),
            data: ColumnData::OptF64(vec![None, Some(1.5)]),
        });
        t.push(Column {
            name: "ok".into(),
            unit: "".into(),
            description: "".into(),
            data: ColumnData::Bool(vec![true, false]),
        });
        t.push(Column {
            name: "name".into(),
            unit: "".into(),
            description: "".into(),
            data: ColumnData::Str(vec!["a".into(), "b".into()]),
        });
        t.push(Column {
            name: "maybe_text".into(),
            unit: "".into(),
            description: "".into(),
            data: ColumnData::OptStr(vec![None, Some("x".into())]),
        });
        t.push(Column { name: "n".into(), unit: "".into(), description: "".into(), data: ColumnData::I64(vec![1, 2]) });
        t.push(Column::f64("odd", "m", "NaN and negative zero", vec![f64::NAN, -0.0]));
        t.metadata.insert("shakeflow.stage".into(), "x".into());
        write_table(&path, &mut t).unwrap();
        let back = read_table(&path).unwrap();
        // The identity, NaN and the zero's sign included (Debug shows both; `==` would not): what
        // lets a run hand the written table itself to the next stage (pipeline::memo).
        assert_eq!(format!("{back:?}"), format!("{t:?}"));
    }

    #[test]
    fn identical_tables_give_identical_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let mut t = Table::new();
        t.push(Column::f64("a", "m", "d", (0..1000).map(|i| (i as f64).sin()).collect()));
        let before = format!("{t:?}");
        write_table(&dir.path().join("1.parquet"), &mut t).unwrap();
        write_table(&dir.path().join("2.parquet"), &mut t).unwrap();
        assert_eq!(format!("{t:?}"), before, "the table lent its columns and got them back");
        let one = std::fs::read(dir.path().join("1.parquet")).unwrap();
        assert_eq!(one, std::fs::read(dir.path().join("2.parquet")).unwrap());
    }
}
