//! What the one line of results per stage is made with, for the end of `shakeflow run`: what a
//! person wants to know first ("3/10 records overturned; median 0.58 g, β 0.50"), read from the
//! stage's committed outputs. Each stage type says its own line (`Stage::summary`, beside the
//! stage); stages with nothing to say in one line (loading, filtering, figures) say nothing.

use std::collections::BTreeMap;
use std::path::Path;

use polars::prelude::DataFrame;

use crate::export::{self, Dataset};

/// Standard gravity, to state accelerations in g as the study does.
pub const G: f64 = 9.80665;

/// Output `output` of the stage whose folder is `stage_dir`, every partition as one table.
pub fn read(stage_dir: &Path, output: &str) -> anyhow::Result<Dataset> {
    export::read(&[stage_dir.join(output)], None)
}

/// A float column's values (None where null).
pub fn floats(frame: &DataFrame, name: &str) -> anyhow::Result<Vec<Option<f64>>> {
    Ok(frame.column(name)?.f64()?.iter().collect())
}

/// A boolean column's values (false where null).
pub fn flags(frame: &DataFrame, name: &str) -> anyhow::Result<Vec<bool>> {
    Ok(frame.column(name)?.bool()?.iter().map(|v| v.unwrap_or(false)).collect())
}

/// A text column's values (empty where null).
pub fn texts(frame: &DataFrame, name: &str) -> anyhow::Result<Vec<String>> {
    Ok(frame.column(name)?.str()?.iter().map(|v| v.unwrap_or_default().to_string()).collect())
}

/// At most `n` names, then how many more.
pub fn some_of(names: &[String], n: usize) -> String {
    let shown = names.iter().take(n).cloned().collect::<Vec<_>>().join(", ");
    match names.len().saturating_sub(n) {
        0 => shown,
        more => format!("{shown} and {more} more"),
    }
}

/// `diagnose`'s line (its stage file calls it): "5 cases: mass_change 1, sliding 2, unexplained 1, none
/// 1"
pub fn verdicts(dir: &Path) -> anyhow::Result<String> {
    let frame = read(dir, "diagnosis")?.frame;
    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    for verdict in texts(&frame, "verdict")? {
        *counts.entry(verdict).or_default() += 1;
    }
    let listed: Vec<String> = counts.iter().map(|(v, n)| format!("{v} {n}")).collect();
    Ok(format!("{} cases: {}", frame.height(), listed.join(", ")))
}
