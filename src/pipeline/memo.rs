//! Tables a run has just written, kept in memory for the stages that read them next.
//!
//! Without it a stage decodes from Parquet what its upstream stage encoded a moment before (a
//! tenth of load → baseline's time). The table kept is the one written, carrying the metadata
//! its file carries, and a written table reads back as the same table, bit for bit (test
//! `round_trip_is_the_identity` in `io::parquet`), so a stage gets the same table from here as
//! from the file. A cached stage's tables are read from their files. Memory stays
//! bounded: tables beyond the budget are not kept (their readers decode the file), a table is
//! let go once each stage reading it has taken it, and a stage's tables that were never taken
//! (a reader selected other partitions) once every stage reading them has finished.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use crate::table::{ColumnData, Table};

/// Memory a run may spend on kept tables.
pub const DEFAULT_BUDGET_BYTES: usize = 512 << 20;

pub struct TableMemo {
    budget: usize,
    state: Mutex<Kept>,
}

#[derive(Default)]
struct Kept {
    bytes: usize,
    tables: BTreeMap<PathBuf, Entry>,
}

struct Entry {
    table: Arc<Table>,
    bytes: usize,
    /// Stages that may still take it.
    readers: usize,
}

impl TableMemo {
    pub fn new(budget_bytes: usize) -> Self {
        TableMemo { budget: budget_bytes, state: Mutex::new(Kept::default()) }
    }

    /// Keeps the table just written to `path` for `readers` stages, if the budget allows.
    pub fn keep(&self, path: &Path, table: Table, readers: usize) {
        let bytes = approximate_bytes(&table);
        let mut kept = self.state.lock().expect("no panics while holding the lock");
        if readers > 0 && kept.bytes + bytes <= self.budget {
            kept.bytes += bytes;
            kept.tables.insert(path.to_path_buf(), Entry { table: Arc::new(table), bytes, readers });
        }
    }

    /// The table kept for `path`, let go after its last reader took it; None when it was not
    /// kept (the reader decodes the file instead).
    pub fn take(&self, path: &Path) -> Option<Arc<Table>> {
        let mut kept = self.state.lock().expect("no panics while holding the lock");
        let entry = kept.tables.get_mut(path)?;
        if entry.readers > 1 {
            entry.readers -= 1;
            return Some(entry.table.clone());
        }
        let entry = kept.tables.remove(path).expect("found just above");
        kept.bytes -= entry.bytes;
        Some(entry.table)
    }

    /// Forgets the tables written under `dir` (readers still holding one keep it alive).
    pub fn release(&self, dir: &Path) {
        let mut kept = self.state.lock().expect("no panics while holding the lock");
        let gone: Vec<PathBuf> = kept.tables.keys().filter(|p| p.starts_with(dir)).cloned().collect();
        for path in gone {
            let entry = kept.tables.remove(&path).expect("listed just above");
            kept.bytes -= entry.bytes;
        }
    }
}

fn approximate_bytes(table: &Table) -> usize {
    table
        .columns
        .iter()
        .map(|c| match &c.data {
            ColumnData::F64(v) => 8 * v.len(),
            ColumnData::OptF64(v) => 16 * v.len(),
            ColumnData::I64(v) => 8 * v.len(),
            ColumnData::Bool(v) => v.len(),
            ColumnData::Str(v) => v.iter().map(|s| 24 + s.len()).sum(),
            ColumnData::OptStr(v) => v.iter().map(|s| 24 + s.as_ref().map_or(0, String::len)).sum(),
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::table::Column;

    fn table(rows: usize) -> Table {
        let mut t = Table::new();
        t.push(Column::f64("x", "m", "x", vec![1.5; rows]));
        t
    }

    #[test]
    fn keeps_within_budget_until_taken_or_released() {
        let path = Path::new;
        let memo = TableMemo::new(8 * 250);
        memo.keep(path("s1/a"), table(100), 2);
        memo.keep(path("s1/b"), table(200), 1); // over the budget: not kept
        memo.keep(path("s2/c"), table(150), 1);
        assert!(memo.take(path("s1/b")).is_none(), "not kept");
        assert_eq!(*memo.take(path("s1/a")).unwrap(), table(100));
        assert_eq!(*memo.take(path("s1/a")).unwrap(), table(100), "two readers");
        assert!(memo.take(path("s1/a")).is_none(), "let go after its last reader");
        // The freed bytes are free again.
        memo.keep(path("s1/b"), table(100), 1);
        memo.release(path("s1"));
        assert!(memo.take(path("s1/b")).is_none(), "released with its stage's folder");
        assert_eq!(*memo.take(path("s2/c")).unwrap(), table(150));
    }
}
