//! In-memory tables: what stages exchange and what artifacts store.
//!
//! A deliberately small columnar type instead of passing Arrow arrays around: numerics get plain
//! slices, and every column carries its unit and description so no writer can forget them.

use std::collections::{BTreeMap, HashSet};

#[derive(Debug, Clone, PartialEq)]
pub enum ColumnData {
    F64(Vec<f64>),
    /// Floats where "missing" must stay distinguishable from NaN (e.g. an event time that never happened).
    OptF64(Vec<Option<f64>>),
    I64(Vec<i64>),
    Bool(Vec<bool>),
    Str(Vec<String>),
    /// Text where "none" must stay distinguishable from an empty string.
    OptStr(Vec<Option<String>>),
}

impl ColumnData {
    pub fn len(&self) -> usize {
        match self {
            ColumnData::F64(v) => v.len(),
            ColumnData::OptF64(v) => v.len(),
            ColumnData::I64(v) => v.len(),
            ColumnData::Bool(v) => v.len(),
            ColumnData::Str(v) => v.len(),
            ColumnData::OptStr(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn type_name(&self) -> &'static str {
        match self {
            ColumnData::F64(_) => "float64",
            ColumnData::OptF64(_) => "float64 (nullable)",
            ColumnData::I64(_) => "int64",
            ColumnData::Bool(_) => "bool",
            ColumnData::Str(_) => "string",
            ColumnData::OptStr(_) => "string (nullable)",
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    pub name: String,
    /// SI unit text ("m/s^2", "s", "rad"); empty for dimensionless or non-numeric columns.
    pub unit: String,
    pub description: String,
    pub data: ColumnData,
}

impl Column {
    pub fn f64(name: &str, unit: &str, description: &str, values: Vec<f64>) -> Self {
        Column { name: name.into(), unit: unit.into(), description: description.into(), data: ColumnData::F64(values) }
    }

    pub fn as_f64(&self) -> Option<&[f64]> {
        match &self.data {
            ColumnData::F64(v) => Some(v),
            _ => None,
        }
    }
}

/// Columns of equal length plus free-form key/value metadata that travels into the artifact.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Table {
    pub columns: Vec<Column>,
    pub metadata: BTreeMap<String, String>,
}

impl Table {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn num_rows(&self) -> usize {
        self.columns.first().map_or(0, |c| c.data.len())
    }

    /// Adds a column; panics on a length mismatch because that is always a bug in the stage, never bad input.
    pub fn push(&mut self, column: Column) {
        self.assert_rows_match(&column);
        assert!(self.column(&column.name).is_none(), "duplicate column `{}`", column.name);
        self.columns.push(column);
    }

    /// [`push`](Self::push) of many columns, with the same checks, in time linear in the table's
    /// width: each `push` compares the new name with every column's, so a table built column by
    /// column is quadratic in its width (minutes for a record 10⁶ columns wide).
    pub fn extend(&mut self, columns: impl IntoIterator<Item = Column>) {
        let mut names: HashSet<String> = self.columns.iter().map(|c| c.name.clone()).collect();
        for column in columns {
            self.assert_rows_match(&column);
            assert!(names.insert(column.name.clone()), "duplicate column `{}`", column.name);
            self.columns.push(column);
        }
    }

    /// A column's length must be the table's: a mismatch is a bug in a stage, never bad input.
    fn assert_rows_match(&self, column: &Column) {
        if let Some(first) = self.columns.first() {
            assert_eq!(
                first.data.len(),
                column.data.len(),
                "column `{}` has {} rows but the table has {}",
                column.name,
                column.data.len(),
                first.data.len()
            );
        }
    }

    pub fn column(&self, name: &str) -> Option<&Column> {
        self.columns.iter().find(|c| c.name == name)
    }

    pub fn f64_column(&self, name: &str) -> Option<&[f64]> {
        self.column(name).and_then(Column::as_f64)
    }

    pub fn column_names(&self) -> Vec<&str> {
        self.columns.iter().map(|c| c.name.as_str()).collect()
    }

    /// A table of the given rows (in that order), same columns, no metadata.
    pub fn select_rows(&self, rows: &[usize]) -> Table {
        fn pick<T: Clone>(v: &[T], rows: &[usize]) -> Vec<T> {
            rows.iter().map(|&r| v[r].clone()).collect()
        }
        let columns = self
            .columns
            .iter()
            .map(|c| Column {
                name: c.name.clone(),
                unit: c.unit.clone(),
                description: c.description.clone(),
                data: match &c.data {
                    ColumnData::F64(v) => ColumnData::F64(pick(v, rows)),
                    ColumnData::OptF64(v) => ColumnData::OptF64(pick(v, rows)),
                    ColumnData::I64(v) => ColumnData::I64(pick(v, rows)),
                    ColumnData::Bool(v) => ColumnData::Bool(pick(v, rows)),
                    ColumnData::Str(v) => ColumnData::Str(pick(v, rows)),
                    ColumnData::OptStr(v) => ColumnData::OptStr(pick(v, rows)),
                },
            })
            .collect();
        Table { columns, metadata: BTreeMap::new() }
    }
}

/// The name of the time column every time-series table starts with.
pub const TIME_COLUMN: &str = "time_s";

/// The sample rate of a uniformly sampled time column (at least two times): its nominal rate
/// when it has one ([`nominal_rate`]), else the mean rate.
pub fn sample_rate(time: &[f64]) -> f64 {
    let n = time.len();
    nominal_rate(time).unwrap_or((n - 1) as f64 / (time[n - 1] - time[0]))
}

/// The mean rate rounded to 1 mHz, when that rate's grid `t0 + k/rate` holds every time of the
/// column to within a thousandth of a sample. Text files round their times (to the microsecond,
/// typically), so a 256 Hz DAQ reads as 255.9999987 Hz: the rate it was set to is what an
/// engineer expects in the metadata, and it keeps a 256 → 200 Hz resampling periodic (25
/// filters instead of one per sample). A clock that truly runs off its nominal rate drifts by
/// more than a thousandth of a sample over a record and keeps its measured rate.
fn nominal_rate(time: &[f64]) -> Option<f64> {
    let n = time.len();
    let mean = (n - 1) as f64 / (time[n - 1] - time[0]);
    let rate = (mean * 1e3).round() / 1e3;
    if !(rate.is_finite() && rate > 0.0) {
        return None;
    }
    let tolerance = 1e-3 / rate;
    time.iter().enumerate().all(|(k, &t)| (t - (time[0] + k as f64 / rate)).abs() <= tolerance).then_some(rate)
}

/// The step of [`sample_rate`] when every step is within a small tolerance of it; else the index
/// of the first step that differs from the record's typical (median) step.
pub fn uniform_step(time: &[f64]) -> Result<f64, usize> {
    let dt = 1.0 / sample_rate(time);
    // Text files round time to a few decimals: allow that rounding, not a real jitter.
    let within = |step: f64, of: f64| of > 0.0 && (step - of).abs() <= 1e-3 * of + 2e-6;
    let first_off = |of: f64| time.windows(2).position(|w| !within(w[1] - w[0], of));
    let Some(off_mean) = first_off(dt) else { return Ok(dt) };
    // A gap lengthens the mean step until every step differs from it: blame the step that
    // differs from the typical one instead.
    let typical = typical_step(time);
    Err(first_off(typical).unwrap_or(off_mean))
}

/// The median of the steps between consecutive times.
pub fn typical_step(time: &[f64]) -> f64 {
    let mut steps: Vec<f64> = time.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_by(f64::total_cmp);
    steps[steps.len() / 2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_check_tolerates_rounding_but_not_jitter() {
        let rounded: Vec<f64> = (0..1000).map(|i| ((i as f64 / 256.0) * 1e6).round() / 1e6).collect();
        assert!((uniform_step(&rounded).unwrap() - 1.0 / 256.0).abs() < 1e-9);
        let mut jittered = rounded.clone();
        jittered[500] += 0.001;
        assert_eq!(uniform_step(&jittered), Err(499));
        // A gap of 20 samples in 10 000 is blamed where it is, not on the first step (every step
        // differs from the mean step the gap lengthened).
        let gapped: Vec<f64> = (0..10_000).filter(|i| !(8000..8020).contains(i)).map(|i| i as f64 * 0.005).collect();
        assert_eq!(uniform_step(&gapped), Err(7999));
    }

    #[test]
    fn rounded_times_give_the_nominal_rate_and_a_drifting_clock_its_own() {
        // A 256 Hz DAQ's times printed to the microsecond (the demo archive's DAQ2) read as
        // 255.9999987 Hz from the mean step; a 200 Hz one's as 199.99999999999997 Hz.
        let printed = |rate: f64, n: usize| -> Vec<f64> {
            (0..n).map(|k| format!("{:.6}", k as f64 / rate).parse().unwrap()).collect()
        };
        let daq2 = printed(256.0, 12_288);
        assert_ne!((daq2.len() - 1) as f64 / daq2[daq2.len() - 1], 256.0);
        assert_eq!(sample_rate(&daq2), 256.0);
        assert_eq!(uniform_step(&daq2), Ok(1.0 / 256.0));
        assert_eq!(sample_rate(&printed(200.0, 24_000)), 200.0);
        assert_eq!(sample_rate(&printed(199.98, 24_000)), 199.98);
        // 10 ppm slow over 120 s is 0.3 samples of drift: measured, not rounded away.
        let drifting = printed(256.0 * (1.0 - 1e-5), 30_725);
        assert_eq!(nominal_rate(&drifting), None);
        assert!((sample_rate(&drifting) / 256.0 - (1.0 - 1e-5)).abs() < 1e-8);
    }

    #[test]
    fn extend_checks_like_push() {
        let mut t = Table::new();
        t.push(Column::f64("a", "", "", vec![1.0]));
        t.extend((0..3).map(|i| Column::f64(&format!("c{i}"), "", "", vec![i as f64])));
        assert_eq!(t.column_names(), ["a", "c0", "c1", "c2"]);
        let duplicate = std::panic::catch_unwind(|| t.clone().extend([Column::f64("c1", "", "", vec![0.0])]));
        assert!(duplicate.is_err());
        let ragged = std::panic::catch_unwind(|| t.clone().extend([Column::f64("d", "", "", vec![0.0, 1.0])]));
        assert!(ragged.is_err());
    }

    #[test]
    #[should_panic(expected = "has 2 rows but the table has 3")]
    fn push_rejects_ragged_columns() {
        let mut t = Table::new();
        t.push(Column::f64("a", "", "", vec![1.0, 2.0, 3.0]));
        t.push(Column::f64("b", "", "", vec![1.0, 2.0]));
    }
}
