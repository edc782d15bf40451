//! Tables as Parquet: units and descriptions as Arrow field metadata, provenance as file metadata.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::sync::Arc;

use anyhow::{anyhow, Context};
use arrow::array::{Array, ArrayRef, BooleanArray, Float64Array, Int64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::{add_encoded_arrow_schema_to_metadata, ArrowSchemaConverter};
use parquet::basic::{Compression, Encoding, ZstdLevel};
use parquet::data_type::{BoolType, ByteArray, ByteArrayType, DoubleType, Int64Type};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::{EnabledStatistics, WriterProperties};
use parquet::file::writer::{SerializedColumnWriter, SerializedFileWriter};
use parquet::schema::types::ColumnPath;

use crate::io::atomic;
use crate::pipeline::hash::HashingWriter;
use crate::table::{Column, ColumnData, Table};

/// The Arrow schema embedded beside a table's own metadata (as ArrowWriter does); not part of it.
const ARROW_SCHEMA_KEY: &str = "ARROW:schema";

/// Writes `table` to `path` (atomically); returns the content hash of the file written.
///
/// The columns go straight to parquet's column writers rather than through an Arrow batch and
/// `ArrowWriter`: that one gathers every value through an index list and buffers the row group
/// before copying it out, about 4 % of the demo study's instructions. The bytes are the same:
/// the Arrow schema `ArrowWriter` embeds (units, descriptions) is embedded here too.
pub fn write_table(path: &Path, table: &Table) -> anyhow::Result<String> {
    let schema = arrow_schema(table);
    let kv: Vec<KeyValue> = table.metadata.iter().map(|(k, v)| KeyValue::new(k.clone(), v.clone())).collect();
    let mut props = WriterProperties::builder()
        // Names, flags and counts repeat: zstd shrinks them well.
        .set_compression(Compression::ZSTD(ZstdLevel::try_new(1)?))
        .set_statistics_enabled(EnabledStatistics::Chunk)
        .set_key_value_metadata(Some(kv));
    // Measured samples hardly repeat: a dictionary only costs time. Split into byte streams their
    // sign/exponent bytes compress, and lz4 then comes within 2 % of zstd's size in about half its
    // time (about a fifth smaller than plain floats; bench/parquet_encodings.py compares them).
    for field in schema.fields() {
        if field.data_type() == &DataType::Float64 {
            let column = ColumnPath::from(field.name().as_str());
            props = props
                .set_column_dictionary_enabled(column.clone(), false)
                .set_column_encoding(column.clone(), Encoding::BYTE_STREAM_SPLIT)
                .set_column_compression(column, Compression::LZ4_RAW);
        }
    }
    let mut props = props.build();
    let descriptor = ArrowSchemaConverter::new().with_coerce_types(props.coerce_types()).convert(&schema)?;
    add_encoded_arrow_schema_to_metadata(&schema, &mut props);
    let mut hash = String::new();
    atomic::write_file(path, |w| {
        let mut writer =
            SerializedFileWriter::new(HashingWriter::new(w), descriptor.root_schema_ptr(), Arc::new(props))?;
        // An empty table is a schema without row groups, as ArrowWriter writes it.
        if table.num_rows() > 0 {
            let mut rows = writer.next_row_group()?;
            for column in &table.columns {
                let mut out = rows.next_column()?.ok_or_else(|| anyhow!("no Parquet column for `{}`", column.name))?;
                write_column(&mut out, &column.data)?;
                out.close()?;
            }
            rows.close()?;
        }
        hash = writer.into_inner()?.finalize();
        Ok(())
    })
    .with_context(|| format!("writing Parquet `{}`", path.display()))?;
    Ok(hash)
}

fn write_column(out: &mut SerializedColumnWriter<'_>, data: &ColumnData) -> parquet::errors::Result<usize> {
    /// The present values of an optional column and its definition levels (1 present, 0 null).
    fn present<T: Clone, U>(values: &[Option<T>], convert: impl Fn(&T) -> U) -> (Vec<U>, Vec<i16>) {
        let levels = values.iter().map(|v| i16::from(v.is_some())).collect();
        (values.iter().flatten().map(convert).collect(), levels)
    }
    match data {
        ColumnData::F64(v) => out.typed::<DoubleType>().write_batch(v, None, None),
        ColumnData::OptF64(v) => {
            let (values, levels) = present(v, |x| *x);
            out.typed::<DoubleType>().write_batch(&values, Some(&levels), None)
        }
        ColumnData::I64(v) => out.typed::<Int64Type>().write_batch(v, None, None),
        ColumnData::Bool(v) => out.typed::<BoolType>().write_batch(v, None, None),
        ColumnData::Str(v) => {
            let values: Vec<ByteArray> = v.iter().map(|s| ByteArray::from(s.as_str())).collect();
            out.typed::<ByteArrayType>().write_batch(&values, None, None)
        }
        ColumnData::OptStr(v) => {
            let (values, levels) = present(v, |s| ByteArray::from(s.as_str()));
            out.typed::<ByteArrayType>().write_batch(&values, Some(&levels), None)
        }
    }
}

/// The table's Arrow schema: each column's type and nullability, its unit and description as
/// field metadata.
fn arrow_schema(table: &Table) -> Schema {
    let fields: Vec<Field> = table
        .columns
        .iter()
        .map(|column| {
            let (data_type, nullable) = match &column.data {
                ColumnData::F64(_) => (DataType::Float64, false),
                ColumnData::OptF64(_) => (DataType::Float64, true),
                ColumnData::I64(_) => (DataType::Int64, false),
                ColumnData::Bool(_) => (DataType::Boolean, false),
                ColumnData::Str(_) => (DataType::Utf8, false),
                ColumnData::OptStr(_) => (DataType::Utf8, true),
            };
            let metadata = HashMap::from([
                ("unit".to_string(), column.unit.clone()),
                ("description".to_string(), column.description.clone()),
            ]);
            Field::new(&column.name, data_type, nullable).with_metadata(metadata)
        })
        .collect();
    Schema::new(fields)
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
        write_table(&path, &t).unwrap();
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
        write_table(&dir.path().join("1.parquet"), &t).unwrap();
        write_table(&dir.path().join("2.parquet"), &t).unwrap();
        assert_eq!(format!("{t:?}"), before);
        let one = std::fs::read(dir.path().join("1.parquet")).unwrap();
        assert_eq!(one, std::fs::read(dir.path().join("2.parquet")).unwrap());
    }
}
