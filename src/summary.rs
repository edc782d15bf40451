//! One line of results per stage, for the end of `shakeflow run`: what a person wants to know
//! first ("3/10 records overturned; median 0.58 g, β 0.50"), read from the stage's committed
//! outputs. Stages with nothing to say in one line (loading, filtering, figures) say nothing.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use polars::prelude::DataFrame;

use crate::export::{self, Dataset};

/// Standard gravity, to state accelerations in g as the study does.
const G: f64 = 9.80665;

/// The results of the stage whose output folder is `stage_dir` (of type `stage_type`) in one
/// line, or None when the type has none or its outputs cannot be read.
pub fn stage_line(stage_dir: &Path, stage_type: &str) -> Option<String> {
    let line = match stage_type {
        "toppling_fragility" => fragility(stage_dir),
        "detect_toppling" => detections(stage_dir),
        "simulate_toppling" => toppling(stage_dir),
        "simulate_rolling" => rolling(stage_dir),
        "diagnose" => verdicts(stage_dir),
        _ => return None,
    };
    line.ok()
}

fn read(stage_dir: &Path, output: &str) -> anyhow::Result<Dataset> {
    export::read(&[stage_dir.join(output)], None)
}

fn floats(frame: &DataFrame, name: &str) -> anyhow::Result<Vec<Option<f64>>> {
    Ok(frame.column(name)?.f64()?.iter().collect())
}

fn flags(frame: &DataFrame, name: &str) -> anyhow::Result<Vec<bool>> {
    Ok(frame.column(name)?.bool()?.iter().map(|v| v.unwrap_or(false)).collect())
}

fn texts(frame: &DataFrame, name: &str) -> anyhow::Result<Vec<String>> {
    Ok(frame.column(name)?.str()?.iter().map(|v| v.unwrap_or_default().to_string()).collect())
}

/// At most `n` names, then how many more.
fn some_of(names: &[String], n: usize) -> String {
    let shown = names.iter().take(n).cloned().collect::<Vec<_>>().join(", ");
    match names.len().saturating_sub(n) {
        0 => shown,
        more => format!("{shown} and {more} more"),
    }
}

/// "3/10 records overturned at some level (41/240 runs); median 0.58 g, β 0.50"
fn fragility(dir: &Path) -> anyhow::Result<String> {
    let runs = read(dir, "runs")?.frame;
    let fit = read(dir, "fragility")?.frame;
    let (records, overturned) = (texts(&runs, "record")?, flags(&runs, "overturned")?);
    let all: BTreeSet<&String> = records.iter().collect();
    let toppled: BTreeSet<&String> = records.iter().zip(&overturned).filter(|(_, &o)| o).map(|(r, _)| r).collect();
    let mut line = format!(
        "{}/{} records overturned at some level ({}/{} runs)",
        toppled.len(),
        all.len(),
        overturned.iter().filter(|&&o| o).count(),
        overturned.len()
    );
    let measure = texts(&fit, "im_measure")?.pop().unwrap_or_default();
    match (floats(&fit, "median")?.pop().flatten(), floats(&fit, "beta")?.pop().flatten()) {
        (Some(median), Some(beta)) if measure == "pfa" => {
            line += &format!("; median {:.2} g ({median:.3} m/s^2), β {beta:.2}", median / G)
        }
        (Some(median), Some(beta)) => line += &format!("; median {median:.3} m/s, β {beta:.2}"),
        _ => line += &format!("; no curve: {}", texts(&fit, "note")?.pop().unwrap_or_default()),
    }
    Ok(line)
}

/// "toppled: 3 of 48 channel records (FB-4 ps2_top_ax, …)"
fn detections(dir: &Path) -> anyhow::Result<String> {
    let events = read(dir, "events")?;
    let (records, channels) = (events.record_labels()?, texts(&events.frame, "channel")?);
    let toppled = flags(&events.frame, "toppled")?;
    let which: Vec<String> = (0..toppled.len())
        .filter(|&i| toppled[i])
        .map(|i| if records[i].is_empty() { channels[i].clone() } else { format!("{} {}", records[i], channels[i]) })
        .collect();
    let mut line = format!("toppling detected in {} of {} channel records", which.len(), toppled.len());
    if !which.is_empty() {
        line += &format!(" ({})", some_of(&which, 6));
    }
    Ok(line)
}

/// "overturned in 2 of 12 records (FB-5, FB-6)"
fn toppling(dir: &Path) -> anyhow::Result<String> {
    let events = read(dir, "events")?;
    let (records, kinds) = (events.record_labels()?, texts(&events.frame, "event")?);
    let overturned = flags(&events.frame, "overturned")?;
    let summaries: Vec<usize> = (0..kinds.len()).filter(|&i| kinds[i] == "summary").collect();
    let which: Vec<String> = summaries.iter().filter(|&&i| overturned[i]).map(|&i| records[i].clone()).collect();
    let mut line = format!("overturned in {} of {} records", which.len(), summaries.len());
    if !which.is_empty() {
        line += &format!(" ({})", some_of(&which, 6));
    }
    Ok(line)
}

/// "10 records: peak displacement 0.412 m (FB-4), started rolling in 9, 14 caster flips"
fn rolling(dir: &Path) -> anyhow::Result<String> {
    let events = read(dir, "events")?;
    let (records, kinds) = (events.record_labels()?, texts(&events.frame, "event")?);
    let displacement = floats(&events.frame, "displacement_m")?;
    let mut peak: Option<(f64, &str)> = None;
    let mut rolled = BTreeSet::new();
    for ((kind, record), d) in kinds.iter().zip(&records).zip(&displacement) {
        match kind.as_str() {
            "peak_displacement" => {
                if let Some(d) = d.filter(|d| peak.is_none_or(|(p, _)| *d > p)) {
                    peak = Some((d, record));
                }
            }
            "breakaway" => {
                rolled.insert(record);
            }
            _ => {}
        }
    }
    let all: BTreeSet<&String> = records.iter().collect();
    let flips = kinds.iter().filter(|k| *k == "flip").count();
    let mut line = format!("{} records", all.len());
    if let Some((d, record)) = peak {
        line += &format!(": peak displacement {d:.3} m");
        if !record.is_empty() {
            line += &format!(" ({record})");
        }
    }
    line += &format!(", started rolling in {}, {flips} caster flips", rolled.len());
    Ok(line)
}

/// "5 cases: mass_change 1, sliding 2, unexplained 1, none 1"
fn verdicts(dir: &Path) -> anyhow::Result<String> {
    let frame = read(dir, "diagnosis")?.frame;
    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    for verdict in texts(&frame, "verdict")? {
        *counts.entry(verdict).or_default() += 1;
    }
    let listed: Vec<String> = counts.iter().map(|(v, n)| format!("{v} {n}")).collect();
    Ok(format!("{} cases: {}", frame.height(), listed.join(", ")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::table::{Column, ColumnData, Table};

    /// One part of `<stage>/<output>` as a stage writes it (provenance, partition metadata).
    fn part(dir: &Path, output: &str, partition: &str, columns: Vec<Column>) {
        let mut t = Table::new();
        t.extend(columns);
        for (k, v) in [("shakeflow.stage", "s"), ("shakeflow.output", output), ("shakeflow.partition", partition)] {
            t.metadata.insert(k.into(), v.into());
        }
        let folder = dir.join(output).join(partition);
        std::fs::create_dir_all(&folder).unwrap();
        crate::io::parquet::write_table(&folder.join("data.parquet"), &t).unwrap();
    }

    fn text(name: &str, v: &[&str]) -> Column {
        Column {
            name: name.into(),
            unit: String::new(),
            description: "d".into(),
            data: ColumnData::Str(v.iter().map(|s| s.to_string()).collect()),
        }
    }

    fn flag(name: &str, v: &[bool]) -> Column {
        Column { name: name.into(), unit: String::new(), description: "d".into(), data: ColumnData::Bool(v.to_vec()) }
    }

    #[test]
    fn detections_name_the_records_and_channels_that_toppled() {
        let dir = crate::tempdir::tempdir().unwrap();
        part(dir.path(), "events", "motion=FB-4", vec![text("channel", &["a", "b"]), flag("toppled", &[true, false])]);
        part(dir.path(), "events", "motion=FB-5", vec![text("channel", &["a", "b"]), flag("toppled", &[false, true])]);
        assert_eq!(
            stage_line(dir.path(), "detect_toppling").unwrap(),
            "toppling detected in 2 of 4 channel records (FB-4 a, FB-5 b)"
        );
    }

    #[test]
    fn toppling_counts_the_summary_rows_only() {
        let dir = crate::tempdir::tempdir().unwrap();
        let kinds = ["uplift", "impact", "overturn", "summary"];
        part(dir.path(), "events", "record=A", vec![text("event", &kinds), flag("overturned", &[true; 4])]);
        part(dir.path(), "events", "record=B", vec![text("event", &["summary"]), flag("overturned", &[false])]);
        assert_eq!(stage_line(dir.path(), "simulate_toppling").unwrap(), "overturned in 1 of 2 records (A)");
    }

    #[test]
    fn verdicts_are_counted_and_rolling_peaks_named() {
        let dir = crate::tempdir::tempdir().unwrap();
        part(dir.path(), "diagnosis", "", vec![text("verdict", &["sliding", "none", "sliding"])]);
        assert_eq!(stage_line(dir.path(), "diagnose").unwrap(), "3 cases: none 1, sliding 2");
        let events =
            |kinds: &[&str], d: &[f64]| vec![text("event", kinds), Column::f64("displacement_m", "m", "d", d.to_vec())];
        part(
            dir.path(),
            "events",
            "motion=FB-1",
            events(&["breakaway", "flip", "peak_displacement"], &[0.0, 0.1, 0.25]),
        );
        part(dir.path(), "events", "motion=FB-2", events(&["peak_displacement"], &[0.0]));
        assert_eq!(
            stage_line(dir.path(), "simulate_rolling").unwrap(),
            "2 records: peak displacement 0.250 m (FB-1), started rolling in 1, 1 caster flips"
        );
        // Types without a line, and outputs that are not there, say nothing.
        assert_eq!(stage_line(dir.path(), "baseline"), None);
        assert_eq!(stage_line(&dir.path().join("absent"), "diagnose"), None);
    }
}
