//! Time-series tables as MCAP with protobuf channels, which Foxglove plots as they are.
//!
//! One channel per table (topic = the record's partition path), one protobuf message per sample
//! whose fields are the table's float columns (`double`, field numbers in column order); log
//! time is the sample time in nanoseconds. Each schema is a binary `FileDescriptorSet`, the form
//! Foxglove and the `mcap-protobuf-support` readers expect. Protobuf rather than JSON: a sample
//! is 9 bytes per column instead of ~40 characters and needs no float formatting, so the twin
//! costs a fraction of what JSON through zstd did (40 % of the demo study). A gap is NaN, as in
//! the Parquet table. Units and descriptions, which a descriptor has no place for, are channel
//! metadata (`unit.<column>`, `description.<column>`). Chunks are lz4-compressed. Twins are
//! opt-in (each stage's `mcap` parameter): they repeat the Parquet table, at twice its size.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use anyhow::{bail, Context};

use crate::io::atomic;
use crate::io::hash::HashingWriter;
use crate::table::{Column, ColumnData, Table, TIME_COLUMN};

pub struct Topic<'a> {
    pub name: String,
    pub table: &'a Table,
}

/// Writes the twin and returns the content hash of its bytes (as
/// [`hash_file`](crate::io::hash::hash_file) would give).
pub fn write_timeseries(
    path: &Path,
    topics: &[Topic<'_>],
    metadata: &BTreeMap<String, String>,
) -> anyhow::Result<String> {
    // Messages of all channels interleaved in time order: players stream files front to back.
    let mut order: Vec<(u64, usize, usize)> = Vec::new();
    for (t, topic) in topics.iter().enumerate() {
        let Some(time) = topic.table.f64_column(TIME_COLUMN) else {
            bail!("topic `{}` has no `{TIME_COLUMN}` column", topic.name);
        };
        for (row, &seconds) in time.iter().enumerate() {
            order.push((to_nanos(seconds)?, t, row));
        }
    }
    order.sort_unstable();

    let schemas = message_names(topics);
    let mut content_hash = String::new();
    atomic::write_file(path, |w| {
        let mut writer = mcap::WriteOptions::new()
            // lz4 chunks: a fifth smaller (message headers repeat, sensor doubles hardly do) at
            // about 1 GB/s; Foxglove and the `mcap` readers (Python: the `lz4` package) open them.
            .compression(Some(mcap::Compression::Lz4))
            // Each chunk is assembled in memory and written once, front to back: the file is
            // hashed on the way out instead of read back, and the buffered file is not flushed
            // by a seek back to each chunk's header.
            .disable_seeking(true)
            .profile("")
            .library(concat!("shakeflow ", env!("CARGO_PKG_VERSION")))
            .create(mcap::write::NoSeek::new(HashingWriter::new(w)))?;
        let mut channels = Vec::with_capacity(topics.len());
        for (topic, full_name) in topics.iter().zip(&schemas) {
            let fields = field_names(topic.table);
            let schema_id = writer.add_schema(full_name, "protobuf", &file_descriptor_set(full_name, &fields))?;
            let mut about = BTreeMap::new();
            for (column, field) in float_columns(topic.table).zip(&fields) {
                about.insert(format!("unit.{field}"), column.unit.clone());
                about.insert(format!("description.{field}"), column.description.clone());
                if *field != column.name {
                    about.insert(format!("column.{field}"), column.name.clone());
                }
            }
            channels.push(writer.add_channel(schema_id, &topic.name, "protobuf", &about)?);
        }
        let columns: Vec<Vec<&[f64]>> =
            topics.iter().map(|t| float_columns(t.table).filter_map(Column::as_f64).collect()).collect();
        let mut sequence = vec![0u32; topics.len()];
        // A message's layout (field tags, value offsets) is fixed per topic: only values change.
        let mut messages: Vec<SampleMessage> = columns.iter().map(|c| SampleMessage::new(c.len())).collect();
        for (nanos, t, row) in order {
            let message = messages[t].encode(&columns[t], row);
            let header = mcap::records::MessageHeader {
                channel_id: channels[t],
                sequence: sequence[t],
                log_time: nanos,
                publish_time: nanos,
            };
            sequence[t] += 1;
            writer.write_to_known_channel(&header, message)?;
        }
        writer.write_metadata(&mcap::records::Metadata { name: "shakeflow".into(), metadata: metadata.clone() })?;
        writer.finish()?;
        content_hash = writer.into_inner().get_ref().finalize();
        Ok(())
    })
    .with_context(|| format!("writing MCAP `{}`", path.display()))?;
    Ok(content_hash)
}

fn to_nanos(seconds: f64) -> anyhow::Result<u64> {
    if !(seconds.is_finite() && seconds >= 0.0) {
        bail!("MCAP log times must be finite and non-negative, found {seconds} s");
    }
    Ok((seconds * 1e9).round() as u64)
}

fn float_columns(table: &Table) -> impl Iterator<Item = &Column> {
    table.columns.iter().filter(|c| matches!(c.data, ColumnData::F64(_)))
}

/// `name` as a protobuf identifier (letters, digits, `_`; not starting with a digit).
fn identifier(name: &str) -> String {
    let mut id: String = name.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect();
    if !id.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') {
        id.insert(0, '_');
    }
    id
}

/// The float columns' field names: the column names, made identifiers where they are not
/// (the original is then in the channel's `column.<field>` metadata), distinct.
fn field_names(table: &Table) -> Vec<String> {
    let mut taken = BTreeSet::new();
    float_columns(table).map(|column| distinct(identifier(&column.name), &mut taken)).collect()
}

/// `base`, or `base_2`, `base_3`, … if `taken` already has it; then taken too.
fn distinct(base: String, taken: &mut BTreeSet<String>) -> String {
    let mut name = base.clone();
    let mut n = 2;
    while !taken.insert(name.clone()) {
        name = format!("{base}_{n}");
        n += 1;
    }
    name
}

/// Fully qualified message name per topic, from its path (`/synchronize/records/motion=FB-4` →
/// `shakeflow.synchronize.records.motion_FB_4`), distinct within the file.
fn message_names(topics: &[Topic<'_>]) -> Vec<String> {
    let mut taken = BTreeSet::new();
    topics
        .iter()
        .map(|topic| {
            let segments: Vec<String> = topic.name.split('/').filter(|s| !s.is_empty()).map(identifier).collect();
            let base = format!("shakeflow.{}", if segments.is_empty() { "series".into() } else { segments.join(".") });
            distinct(base, &mut taken)
        })
        .collect()
}

/// Protobuf wire format: a varint.
fn put_varint(mut v: u64, out: &mut Vec<u8>) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// A length-delimited field (wire type 2): a string or an embedded message.
fn put_bytes(field: u32, bytes: &[u8], out: &mut Vec<u8>) {
    put_varint(u64::from(field) << 3 | 2, out);
    put_varint(bytes.len() as u64, out);
    out.extend_from_slice(bytes);
}

fn put_uint(field: u32, v: u64, out: &mut Vec<u8>) {
    put_varint(u64::from(field) << 3, out);
    put_varint(v, out);
}

/// `google.protobuf.FileDescriptorSet` of one proto3 file declaring the message `full_name`
/// with a `double` field per name, numbered from 1 (field numbers of descriptor.proto).
fn file_descriptor_set(full_name: &str, fields: &[String]) -> Vec<u8> {
    let (package, message) = full_name.rsplit_once('.').expect("message names are qualified by `shakeflow.`");
    let mut descriptor = Vec::new();
    put_bytes(1, message.as_bytes(), &mut descriptor); // DescriptorProto.name
    for (i, name) in fields.iter().enumerate() {
        let mut field = Vec::new();
        put_bytes(1, name.as_bytes(), &mut field); // name
        put_uint(3, i as u64 + 1, &mut field); // number
        put_uint(4, 1, &mut field); // label: LABEL_OPTIONAL
        put_uint(5, 1, &mut field); // type: TYPE_DOUBLE
        put_bytes(10, name.as_bytes(), &mut field); // json_name: as written, not camelCased
        put_bytes(2, &field, &mut descriptor); // DescriptorProto.field
    }
    let mut file = Vec::new();
    put_bytes(1, format!("{}.proto", full_name.replace('.', "/")).as_bytes(), &mut file); // name
    put_bytes(2, package.as_bytes(), &mut file); // package
    put_bytes(4, &descriptor, &mut file); // message_type
    put_bytes(12, b"proto3", &mut file); // syntax
    let mut set = Vec::new();
    put_bytes(1, &file, &mut set); // FileDescriptorSet.file
    set
}

/// One sample as a protobuf message: field i + 1 = column i's value as a `double` (wire type 1),
/// every field written (a gap is NaN, as in the Parquet table). The tags never change, so they
/// are written once and each sample only overwrites the values.
struct SampleMessage {
    bytes: Vec<u8>,
    /// Where each column's 8 value bytes start.
    offsets: Vec<usize>,
}

impl SampleMessage {
    fn new(fields: usize) -> SampleMessage {
        let (mut bytes, mut offsets) = (Vec::new(), Vec::with_capacity(fields));
        for i in 0..fields {
            put_varint(((i as u64) + 1) << 3 | 1, &mut bytes);
            offsets.push(bytes.len());
            bytes.extend_from_slice(&[0; 8]);
        }
        SampleMessage { bytes, offsets }
    }

    fn encode(&mut self, columns: &[&[f64]], row: usize) -> &[u8] {
        for (values, &at) in columns.iter().zip(&self.offsets) {
            self.bytes[at..at + 8].copy_from_slice(&values[row].to_le_bytes());
        }
        &self.bytes
    }
}

/// What `inspect` shows of an MCAP file.
pub struct McapSummary {
    pub channels: Vec<(String, String, u64)>,
    pub message_count: u64,
    pub start_s: f64,
    pub end_s: f64,
    pub metadata: BTreeMap<String, String>,
}

pub fn summarize(path: &Path) -> anyhow::Result<McapSummary> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read `{}`", path.display()))?;
    let summary = mcap::Summary::read(&bytes)
        .with_context(|| format!("`{}` is not a readable MCAP file", path.display()))?
        .with_context(|| format!("`{}` has no MCAP summary section", path.display()))?;
    let stats = summary.stats.clone().unwrap_or_default();
    let mut channels: Vec<(String, String, u64)> = summary
        .channels
        .values()
        .map(|c| {
            let schema = c.schema.as_ref().map(|s| s.name.clone()).unwrap_or_default();
            (c.topic.clone(), schema, stats.channel_message_counts.get(&c.id).copied().unwrap_or(0))
        })
        .collect();
    channels.sort();
    let mut metadata = BTreeMap::new();
    for index in &summary.metadata_indexes {
        let record = mcap::read::metadata(&bytes, index)?;
        metadata.extend(record.metadata);
    }
    Ok(McapSummary {
        channels,
        message_count: stats.message_count,
        start_s: stats.message_start_time as f64 * 1e-9,
        end_s: stats.message_end_time as f64 * 1e-9,
        metadata,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::table::Column;

    #[test]
    fn written_file_summarizes_back() {
        let dir = crate::tempdir::tempdir().unwrap();
        let path = dir.path().join("t.mcap");
        let mut t = Table::new();
        t.push(Column::f64("time_s", "s", "time", vec![0.0, 0.01, 0.02]));
        t.push(Column::f64("ax_mps2", "m/s^2", "accel", vec![1.0, f64::NAN, 3.0]));
        let meta = BTreeMap::from([("shakeflow.stage".to_string(), "demo".to_string())]);
        let written = write_timeseries(&path, &[Topic { name: "/a/motion=FB-4".into(), table: &t }], &meta).unwrap();
        assert_eq!(written, crate::io::hash::hash_file(&path).unwrap());
        let s = summarize(&path).unwrap();
        assert_eq!(s.message_count, 3);
        assert_eq!(s.channels[0].0, "/a/motion=FB-4");
        assert!((s.end_s - 0.02).abs() < 1e-12);
        assert_eq!(s.metadata["shakeflow.stage"], "demo");
    }

    #[test]
    fn chunks_are_lz4_and_read_back() {
        let dir = crate::tempdir::tempdir().unwrap();
        let path = dir.path().join("t.mcap");
        let mut t = Table::new();
        let time: Vec<f64> = (0..2000).map(|i| i as f64 * 0.005).collect();
        t.push(Column::f64("ax_mps2", "m/s^2", "accel", time.iter().map(|s| (7.0 * s).sin()).collect()));
        t.push(Column::f64("time_s", "s", "time", time));
        write_timeseries(&path, &[Topic { name: "/a".into(), table: &t }], &BTreeMap::new()).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert!(!summary.chunk_indexes.is_empty());
        for chunk in &summary.chunk_indexes {
            assert_eq!(chunk.compression, "lz4");
            assert!(chunk.compressed_size < chunk.uncompressed_size, "{chunk:?}");
        }
        let messages: Vec<_> = mcap::MessageStream::new(&bytes).unwrap().map(Result::unwrap).collect();
        assert_eq!(messages.len(), 2000);
        let columns: Vec<&[f64]> = t.columns.iter().filter_map(Column::as_f64).collect();
        let expected = SampleMessage::new(2).encode(&columns, 1999).to_vec();
        assert_eq!(&messages[1999].data[..], &expected[..]);
        assert_eq!(messages[1999].log_time, 9_995_000_000);
    }

    #[test]
    fn column_names_become_distinct_protobuf_fields() {
        let mut t = Table::new();
        for name in ["time_s", "a-x", "a_x", "2nd"] {
            t.push(Column::f64(name, "m", "d", vec![0.0]));
        }
        assert_eq!(field_names(&t), ["time_s", "a_x", "a_x_2", "_2nd"]);
        let topics = [
            Topic { name: "/s/records/motion=FB-4".into(), table: &t },
            Topic { name: "/s/records/motion_FB_4".into(), table: &t },
        ];
        assert_eq!(message_names(&topics), ["shakeflow.s.records.motion_FB_4", "shakeflow.s.records.motion_FB_4_2"]);
    }

    #[test]
    fn samples_use_the_protobuf_wire_format() {
        // Tag = field number << 3 | wire type 1 (64-bit), as a varint: one byte up to field 15,
        // two from field 16 (129 = 0x81 0x01).
        let columns: Vec<Vec<f64>> = (0..17).map(|i| vec![i as f64 + 0.5]).collect();
        let slices: Vec<&[f64]> = columns.iter().map(Vec::as_slice).collect();
        let mut message = SampleMessage::new(slices.len());
        let out = message.encode(&slices, 0).to_vec();
        assert_eq!(out.len(), 15 * 9 + 2 * 10);
        assert_eq!(out[0], 0x09);
        assert_eq!(&out[1..9], &0.5f64.to_le_bytes());
        assert_eq!(out[14 * 9], (15 << 3) | 1);
        assert_eq!(&out[15 * 9..15 * 9 + 2], &[0x81, 0x01]);
        assert_eq!(&out[15 * 9 + 2..15 * 9 + 10], &15.5f64.to_le_bytes());
    }
}
