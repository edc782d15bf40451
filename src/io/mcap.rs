//! Time-series tables as MCAP with JSON-schema channels, which Foxglove plots as they are.
//!
//! One channel per table (topic = the record's partition path), one JSON message per sample whose
//! fields are the table's float columns; log time is the sample time in nanoseconds.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context};
use serde_json::{json, Map, Value};

use crate::io::atomic;
use crate::table::{ColumnData, Table, TIME_COLUMN};

pub struct Topic<'a> {
    pub name: String,
    pub table: &'a Table,
}

pub fn write_timeseries(path: &Path, topics: &[Topic<'_>], metadata: &BTreeMap<String, String>) -> anyhow::Result<()> {
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

    atomic::write_file(path, |w| {
        let mut writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            // Level 1: float samples gain little from harder zstd, and the write dominates a stage.
            .compression_level(1)
            // Records are already written in parallel (rayon); zstd's own workers only add contention.
            .compression_threads(0)
            .profile("")
            .library(concat!("shakeflow ", env!("CARGO_PKG_VERSION")))
            .create(w)?;
        let mut channels = Vec::with_capacity(topics.len());
        for topic in topics {
            let schema = serde_json::to_vec(&json_schema(&topic.name, topic.table))?;
            let schema_id = writer.add_schema(&schema_title(&topic.name), "jsonschema", &schema)?;
            let units: BTreeMap<String, String> =
                float_columns(topic.table).map(|(name, unit, _)| (format!("unit.{name}"), unit.to_string())).collect();
            channels.push(writer.add_channel(schema_id, &topic.name, "json", &units)?);
        }
        let quoted = |name: &str| serde_json::to_string(name).expect("strings serialise");
        let columns: Vec<Vec<(String, &[f64])>> =
            topics.iter().map(|t| float_columns(t.table).map(|(name, _, v)| (quoted(name), v)).collect()).collect();
        let mut sequence = vec![0u32; topics.len()];
        let mut message = Vec::new();
        for (nanos, t, row) in order {
            message_json(&columns[t], row, &mut message);
            let header = mcap::records::MessageHeader {
                channel_id: channels[t],
                sequence: sequence[t],
                log_time: nanos,
                publish_time: nanos,
            };
            sequence[t] += 1;
            writer.write_to_known_channel(&header, &message)?;
        }
        writer.write_metadata(&mcap::records::Metadata { name: "shakeflow".into(), metadata: metadata.clone() })?;
        writer.finish()?;
        Ok(())
    })
    .with_context(|| format!("writing MCAP `{}`", path.display()))
}

fn to_nanos(seconds: f64) -> anyhow::Result<u64> {
    if !(seconds.is_finite() && seconds >= 0.0) {
        bail!("MCAP log times must be finite and non-negative, found {seconds} s");
    }
    Ok((seconds * 1e9).round() as u64)
}

fn float_columns(table: &Table) -> impl Iterator<Item = (&str, &str, &[f64])> {
    table.columns.iter().filter_map(|c| match &c.data {
        ColumnData::F64(v) => Some((c.name.as_str(), c.unit.as_str(), v.as_slice())),
        _ => None,
    })
}

fn schema_title(topic: &str) -> String {
    format!("shakeflow{}", topic.replace('/', "."))
}

fn json_schema(topic: &str, table: &Table) -> Value {
    let mut properties = Map::new();
    for column in table.columns.iter().filter(|c| matches!(c.data, ColumnData::F64(_))) {
        let description = if column.unit.is_empty() {
            column.description.clone()
        } else {
            format!("{} [{}]", column.description, column.unit)
        };
        properties.insert(column.name.clone(), json!({"type": ["number", "null"], "description": description}));
    }
    json!({"title": schema_title(topic), "type": "object", "properties": properties})
}

/// One sample as a JSON object, written by hand: a serde_json `Value` per message costs more
/// than the rest of the stage. `columns` holds each field's JSON-quoted name and its values.
fn message_json(columns: &[(String, &[f64])], row: usize, out: &mut Vec<u8>) {
    let mut floats = ryu::Buffer::new();
    out.clear();
    out.push(b'{');
    for (i, (quoted_name, values)) in columns.iter().enumerate() {
        if i > 0 {
            out.push(b',');
        }
        out.extend_from_slice(quoted_name.as_bytes());
        out.push(b':');
        let v = values[row];
        // JSON has no NaN: a gap is a null, which Foxglove draws as a break in the line.
        if v.is_finite() {
            out.extend_from_slice(floats.format_finite(v).as_bytes());
        } else {
            out.extend_from_slice(b"null");
        }
    }
    out.push(b'}');
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
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.mcap");
        let mut t = Table::new();
        t.push(Column::f64("time_s", "s", "time", vec![0.0, 0.01, 0.02]));
        t.push(Column::f64("ax_mps2", "m/s^2", "accel", vec![1.0, f64::NAN, 3.0]));
        let meta = BTreeMap::from([("shakeflow.stage".to_string(), "demo".to_string())]);
        write_timeseries(&path, &[Topic { name: "/a/motion=FB-4".into(), table: &t }], &meta).unwrap();
        let s = summarize(&path).unwrap();
        assert_eq!(s.message_count, 3);
        assert_eq!(s.channels[0].0, "/a/motion=FB-4");
        assert!((s.end_s - 0.02).abs() < 1e-12);
        assert_eq!(s.metadata["shakeflow.stage"], "demo");
    }
}
