//! Tables as Parquet: units and descriptions as Arrow field metadata, provenance as file metadata.

use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::ops::Range;
use std::path::Path;
use std::sync::Arc;

use anyhow::{anyhow, Context};
use arrow::array::{Array, ArrayRef, BooleanArray, Float64Array, Int64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::arrow_writer::{compute_leaves, ArrowColumnWriter, ArrowRowGroupWriterFactory};
use parquet::arrow::{add_encoded_arrow_schema_to_metadata, ArrowSchemaConverter};
use parquet::basic::{Compression, Encoding, ZstdLevel};
use parquet::data_type::{BoolType, ByteArray, ByteArrayType, DoubleType, Int64Type};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::{EnabledStatistics, WriterProperties};
use parquet::file::writer::{SerializedColumnWriter, SerializedFileWriter, SerializedRowGroupWriter};
use parquet::schema::types::ColumnPath;

use crate::io::atomic;
use crate::io::hash::HashingWriter;
use crate::table::{Column, ColumnData, Table};

/// The Arrow schema embedded beside a table's own metadata (as ArrowWriter does); not part of it.
const ARROW_SCHEMA_KEY: &str = "ARROW:schema";

/// Writes `table` to `path` (atomically); returns the content hash of the file written.
pub fn write_table(path: &Path, table: &Table) -> anyhow::Result<String> {
    let mut hash = String::new();
    atomic::write_file(path, |w| {
        hash = encode(table, w)?;
        Ok(())
    })
    .with_context(|| format!("writing Parquet `{}`", path.display()))?;
    Ok(hash)
}

/// The bytes [`write_table`] writes for `table`, and their content hash, in memory.
pub fn encode_table(table: &Table) -> anyhow::Result<(Vec<u8>, String)> {
    let mut bytes = Vec::new();
    let hash = encode(table, &mut bytes).context("encoding Parquet")?;
    Ok((bytes, hash))
}

/// Encodes `table` as Parquet into `w`; returns the content hash of the bytes.
///
/// Columns without nulls go straight to parquet's column writers rather than through an Arrow
/// batch and `ArrowWriter`: that one gathers every value through an index list and buffers the
/// row group before copying it out (2.3 % of the demo study's instructions). The bytes are the
/// same (a test compares them): the same properties, the same Arrow schema embedded (units,
/// descriptions), the same row groups, nullable columns through Arrow's own column writer.
fn encode<W: std::io::Write + Send>(table: &Table, w: W) -> anyhow::Result<String> {
    let schema = arrow_schema(table);
    let mut props = writer_properties(table, &schema)?;
    let descriptor = ArrowSchemaConverter::new().with_coerce_types(props.coerce_types()).convert(&schema)?;
    add_encoded_arrow_schema_to_metadata(&schema, &mut props);
    let rows_per_group = props.max_row_group_row_count().unwrap_or(usize::MAX).max(1);
    let has_nullable = table.columns.iter().any(|c| matches!(c.data, ColumnData::OptF64(_) | ColumnData::OptStr(_)));
    let schema = Arc::new(schema);
    let mut writer = SerializedFileWriter::new(HashingWriter::new(w), descriptor.root_schema_ptr(), Arc::new(props))?;
    let arrow_columns = has_nullable.then(|| ArrowRowGroupWriterFactory::new(&writer, schema.clone()));
    // Row groups of at most `rows_per_group` rows, as ArrowWriter cuts them; an empty table
    // is a schema without row groups.
    let (mut start, mut index) = (0, 0);
    while start < table.num_rows() {
        let rows = start..table.num_rows().min(start.saturating_add(rows_per_group));
        let mut arrow_writers: Vec<Option<ArrowColumnWriter>> = match &arrow_columns {
            Some(factory) => factory.create_column_writers(index)?.into_iter().map(Some).collect(),
            None => Vec::new(),
        };
        let mut group = writer.next_row_group()?;
        for (i, column) in table.columns.iter().enumerate() {
            let arrow_writer = arrow_writers.get_mut(i).and_then(Option::take);
            write_column(&mut group, arrow_writer, schema.field(i), &column.data, rows.clone())
                .with_context(|| format!("column `{}`", column.name))?;
        }
        group.close()?;
        (start, index) = (rows.end, index + 1);
    }
    Ok(writer.into_inner()?.finalize())
}

fn writer_properties(table: &Table, schema: &Schema) -> anyhow::Result<WriterProperties> {
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
    Ok(props.build())
}

/// Rows `rows` of one column, as the next column chunk of `group`. Nullable columns go through
/// `arrow_writer` (an Arrow column writer for this column), as ArrowWriter writes them: it keeps
/// definition levels that are all 1 or all 0 in a compact form, which moves where its pages end.
fn write_column<W: Write + Send>(
    group: &mut SerializedRowGroupWriter<'_, W>,
    arrow_writer: Option<ArrowColumnWriter>,
    field: &Field,
    data: &ColumnData,
    rows: Range<usize>,
) -> anyhow::Result<()> {
    match data {
        ColumnData::F64(v) => required(group, |out| out.typed::<DoubleType>().write_batch(&v[rows], None, None)),
        ColumnData::I64(v) => required(group, |out| out.typed::<Int64Type>().write_batch(&v[rows], None, None)),
        ColumnData::Bool(v) => required(group, |out| out.typed::<BoolType>().write_batch(&v[rows], None, None)),
        ColumnData::Str(v) => {
            let values: Vec<ByteArray> = v[rows].iter().map(|s| ByteArray::from(s.as_str())).collect();
            required(group, |out| out.typed::<ByteArrayType>().write_batch(&values, None, None))
        }
        ColumnData::OptF64(v) => nullable(group, arrow_writer, field, Arc::new(Float64Array::from(v[rows].to_vec()))),
        ColumnData::OptStr(v) => nullable(group, arrow_writer, field, Arc::new(StringArray::from(v[rows].to_vec()))),
    }
}

fn required<W: Write + Send>(
    group: &mut SerializedRowGroupWriter<'_, W>,
    write: impl FnOnce(&mut SerializedColumnWriter<'_>) -> parquet::errors::Result<usize>,
) -> anyhow::Result<()> {
    let mut out = group.next_column()?.ok_or_else(|| anyhow!("the Parquet schema has fewer columns than the table"))?;
    write(&mut out)?;
    out.close()?;
    Ok(())
}

fn nullable<W: Write + Send>(
    group: &mut SerializedRowGroupWriter<'_, W>,
    writer: Option<ArrowColumnWriter>,
    field: &Field,
    array: ArrayRef,
) -> anyhow::Result<()> {
    let mut writer = writer.ok_or_else(|| anyhow!("no Arrow column writer for the nullable column"))?;
    for leaf in compute_leaves(field, &array)? {
        writer.write(&leaf)?;
    }
    writer.close()?.append_to_row_group(group)?;
    Ok(())
}

/// The table's Arrow schema: each column's type and nullability, its unit and description as
/// field metadata, and the table's metadata (provenance) as schema metadata, which is where
/// pyarrow (`read_schema(f).metadata`, `read_table(f).schema.metadata`) looks for it.
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
    let metadata: HashMap<String, String> = table.metadata.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
    Schema::new_with_metadata(fields, metadata)
}

/// Reads a whole Parquet file written by any tool; units come back when the writer stored them.
pub fn read_table(path: &Path) -> anyhow::Result<Table> {
    // One read of the whole file: a File reader seeks and reads once per column chunk.
    let bytes = bytes::Bytes::from(std::fs::read(path).with_context(|| format!("cannot open `{}`", path.display()))?);
    decode_table(bytes, path)
}

/// [`read_table`] of a file's bytes already in memory; `path` names it in errors.
pub fn decode_table(bytes: bytes::Bytes, path: &Path) -> anyhow::Result<Table> {
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

/// One column of a Parquet file's schema: its name, type and the unit and description a
/// shakeflow writer stored (empty when the writer stored none).
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnInfo {
    pub name: String,
    pub data_type: DataType,
    pub nullable: bool,
    pub unit: String,
    pub description: String,
}

/// A Parquet file's columns and key-value metadata, read from its footer only (no data).
pub fn read_schema(path: &Path) -> anyhow::Result<(Vec<ColumnInfo>, BTreeMap<String, String>)> {
    let file = std::fs::File::open(path).with_context(|| format!("cannot open `{}`", path.display()))?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(file)
        .with_context(|| format!("`{}` is not a readable Parquet file", path.display()))?;
    let mut metadata = BTreeMap::new();
    if let Some(kv) = builder.metadata().file_metadata().key_value_metadata() {
        for entry in kv.iter().filter(|e| e.key != ARROW_SCHEMA_KEY) {
            metadata.insert(entry.key.clone(), entry.value.clone().unwrap_or_default());
        }
    }
    let columns = builder
        .schema()
        .fields()
        .iter()
        .map(|f| ColumnInfo {
            name: f.name().clone(),
            data_type: f.data_type().clone(),
            nullable: f.is_nullable(),
            unit: f.metadata().get("unit").cloned().unwrap_or_default(),
            description: f.metadata().get("description").cloned().unwrap_or_default(),
        })
        .collect();
    Ok((columns, metadata))
}

/// Writes Arrow columns as one Parquet file (atomically; zstd, one row group per million rows),
/// the schema's field and schema metadata embedded and the schema metadata also as the file's
/// key-value metadata, as [`write_table`] stamps its tables.
pub fn write_arrays(path: &Path, schema: Schema, columns: Vec<ArrayRef>) -> anyhow::Result<()> {
    let sorted: BTreeMap<&String, &String> = schema.metadata().iter().collect();
    let kv: Vec<KeyValue> = sorted.into_iter().map(|(k, v)| KeyValue::new(k.clone(), v.clone())).collect();
    let props = WriterProperties::builder()
        .set_compression(Compression::ZSTD(ZstdLevel::try_new(1)?))
        .set_statistics_enabled(EnabledStatistics::Chunk)
        .set_key_value_metadata(Some(kv))
        .build();
    let schema = Arc::new(schema);
    let batch = RecordBatch::try_new(schema.clone(), columns)?;
    atomic::write_file(path, |w| {
        let mut writer = parquet::arrow::ArrowWriter::try_new(w, schema, Some(props))?;
        writer.write(&batch)?;
        writer.close()?;
        Ok(())
    })
    .with_context(|| format!("writing Parquet `{}`", path.display()))
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
        let dir = crate::tempdir::tempdir().unwrap();
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

    /// What `write_table` replaced: the table as one Arrow batch through `ArrowWriter`, with the
    /// same properties.
    fn arrow_writer_bytes(table: &Table) -> Vec<u8> {
        let schema = Arc::new(arrow_schema(table));
        let arrays: Vec<ArrayRef> = table
            .columns
            .iter()
            .map(|c| -> ArrayRef {
                match &c.data {
                    ColumnData::F64(v) => Arc::new(Float64Array::from(v.clone())),
                    ColumnData::OptF64(v) => Arc::new(Float64Array::from(v.clone())),
                    ColumnData::I64(v) => Arc::new(Int64Array::from(v.clone())),
                    ColumnData::Bool(v) => Arc::new(BooleanArray::from(v.clone())),
                    ColumnData::Str(v) => Arc::new(StringArray::from(v.clone())),
                    ColumnData::OptStr(v) => Arc::new(StringArray::from(v.clone())),
                }
            })
            .collect();
        let batch = RecordBatch::try_new(schema.clone(), arrays).unwrap();
        let mut bytes = Vec::new();
        let props = writer_properties(table, &schema).unwrap();
        let mut writer = parquet::arrow::ArrowWriter::try_new(&mut bytes, schema, Some(props)).unwrap();
        writer.write(&batch).unwrap();
        writer.close().unwrap();
        bytes
    }

    #[test]
    fn the_bytes_are_those_arrow_writer_wrote() {
        let column = |name: &str, data| Column { name: name.into(), unit: "u".into(), description: "d".into(), data };
        let mut mixed = Table::new();
        mixed.push(Column::f64("time_s", "s", "time", (0..3000).map(|i| i as f64 / 200.0).collect()));
        mixed.push(column("x", ColumnData::OptF64((0..3000).map(|i| (i % 7 != 0).then_some(i as f64)).collect())));
        mixed.push(column("n", ColumnData::I64((0..3000).collect())));
        mixed.push(column("ok", ColumnData::Bool((0..3000).map(|i| i % 3 == 0).collect())));
        mixed.push(column("unit", ColumnData::Str((0..3000).map(|i| format!("U{}", i % 5)).collect())));
        mixed
            .push(column("note", ColumnData::OptStr((0..3000).map(|i| (i % 2 == 0).then(|| i.to_string())).collect())));
        mixed.metadata.insert("shakeflow.stage".into(), "x".into());
        let mut empty = Table::new();
        empty.push(column("unit", ColumnData::Str(Vec::new())));
        empty.push(column("t", ColumnData::OptF64(Vec::new())));
        // More rows than one row group holds (1 048 576): ArrowWriter starts a second one.
        let rows = 1_048_576 + 1_000;
        let mut long = Table::new();
        long.push(Column::f64("time_s", "s", "time", (0..rows).map(|i| i as f64 / 256.0).collect()));
        long.push(column("gap", ColumnData::OptF64((0..rows).map(|i| (i % 1000 != 0).then_some(1.5)).collect())));
        // Nullable columns with no null, or nothing but nulls, over several pages: ArrowWriter
        // cuts their pages elsewhere than the plain column writer would.
        let rows = 45_000;
        let mut uniform = Table::new();
        uniform.push(column("full", ColumnData::OptF64((0..rows).map(|i| Some(i as f64)).collect())));
        uniform.push(column("none", ColumnData::OptF64(vec![None; rows])));
        let text = |i: usize| Some(format!("a label long enough to fill pages sooner, number {i}"));
        uniform.push(column("labels", ColumnData::OptStr((0..rows).map(text).collect())));
        uniform.push(column("no_labels", ColumnData::OptStr(vec![None; rows])));
        let dir = crate::tempdir::tempdir().unwrap();
        for (name, table) in [("mixed", &mixed), ("empty", &empty), ("long", &long), ("uniform", &uniform)] {
            let path = dir.path().join(format!("{name}.parquet"));
            write_table(&path, table).unwrap();
            assert!(std::fs::read(&path).unwrap() == arrow_writer_bytes(table), "{name}: the bytes differ");
        }
        let groups = parquet::file::reader::FileReader::metadata(
            &parquet::file::serialized_reader::SerializedFileReader::new(
                std::fs::File::open(dir.path().join("long.parquet")).unwrap(),
            )
            .unwrap(),
        )
        .num_row_groups();
        assert_eq!(groups, 2);
    }

    #[test]
    fn identical_tables_give_identical_bytes() {
        let dir = crate::tempdir::tempdir().unwrap();
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
