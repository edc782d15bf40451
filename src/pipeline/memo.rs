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
//!
//! An intermediate's files (`keep: false`) need not reach the disk at all: the commit removes
//! them once the stages reading them are up to date, so a run that writes them only to remove
//! them pays a file, its folders and their removal for nothing (on ext4, creating an inode is
//! dearer than encoding the table: 30 % of the demo study's CPU went to ext4's inode
//! allocation). Such a file is kept here *unwritten*, as the bytes its stage encoded (their hash
//! is the one the file would have), with its table; the commit writes the ones it installs
//! after all (a reader failed, or was not selected) and lets the others go. The run lets go of a
//! stage's unwritten files as soon as every stage reading them is done, when the commit will
//! leave them out. Unwritten files have a budget of their own: a file whose bytes or table the
//! budgets cannot hold is written as before (as are an intermediate's MCAP twins and figures,
//! and its stage folder).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use crate::table::{ColumnData, Table};

/// Memory a run may spend on kept tables.
pub const DEFAULT_BUDGET_BYTES: usize = 512 << 20;
/// Memory a run may spend on unwritten files, besides its kept tables.
pub const UNWRITTEN_BUDGET_BYTES: usize = 256 << 20;

pub struct TableMemo {
    budget: usize,
    unwritten_budget: usize,
    state: Mutex<Kept>,
}

#[derive(Default)]
struct Kept {
    bytes: usize,
    tables: BTreeMap<PathBuf, Entry>,
    unwritten_bytes: usize,
    /// Files encoded but not written, by the path they would have.
    unwritten: BTreeMap<PathBuf, bytes::Bytes>,
}

struct Entry {
    table: Arc<Table>,
    bytes: usize,
    /// Stages that may still take it.
    readers: usize,
}

impl TableMemo {
    /// A memo of `budget_bytes` for tables and as much again (at most
    /// [`UNWRITTEN_BUDGET_BYTES`]) for unwritten files.
    pub fn new(budget_bytes: usize) -> Self {
        let unwritten_budget = budget_bytes.min(UNWRITTEN_BUDGET_BYTES);
        TableMemo { budget: budget_bytes, unwritten_budget, state: Mutex::new(Kept::default()) }
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

    /// Keeps the file `path` unwritten, as its `encoded` bytes, with its table for `readers`
    /// stages, if both budgets allow; else hands both back (the caller writes the file).
    pub fn keep_unwritten(
        &self,
        path: &Path,
        table: Table,
        encoded: Vec<u8>,
        readers: usize,
    ) -> Option<(Table, Vec<u8>)> {
        let bytes = approximate_bytes(&table);
        let mut kept = self.state.lock().expect("no panics while holding the lock");
        let fits = kept.bytes + bytes <= self.budget && kept.unwritten_bytes + encoded.len() <= self.unwritten_budget;
        if readers == 0 || !fits {
            return Some((table, encoded));
        }
        kept.bytes += bytes;
        if let Some(replaced) = kept.tables.insert(path.to_path_buf(), Entry { table: Arc::new(table), bytes, readers })
        {
            kept.bytes -= replaced.bytes;
        }
        kept.unwritten_bytes += encoded.len();
        let mut encoded = encoded;
        encoded.shrink_to_fit();
        if let Some(replaced) = kept.unwritten.insert(path.to_path_buf(), encoded.into()) {
            kept.unwritten_bytes -= replaced.len();
        }
        None
    }

    /// The bytes of the unwritten file `path` (None: it was written, or let go).
    pub fn unwritten(&self, path: &Path) -> Option<bytes::Bytes> {
        self.state.lock().expect("no panics while holding the lock").unwritten.get(path).cloned()
    }

    /// Lets go of the unwritten files under `dir`: nothing will read or install them.
    pub fn forget_unwritten(&self, dir: &Path) {
        let mut kept = self.state.lock().expect("no panics while holding the lock");
        let gone: Vec<PathBuf> = kept
            .unwritten
            .range(dir.to_path_buf()..)
            .map(|(p, _)| p)
            .take_while(|p| p.starts_with(dir))
            .cloned()
            .collect();
        for path in gone {
            let bytes = kept.unwritten.remove(&path).expect("listed just above");
            kept.unwritten_bytes -= bytes.len();
        }
    }

    /// Writes the unwritten files that `wanted` names (atomically, their folders made) and lets
    /// go of all of them.
    pub fn write_unwritten(&self, wanted: impl Fn(&Path) -> bool) -> anyhow::Result<()> {
        let unwritten = {
            let mut kept = self.state.lock().expect("no panics while holding the lock");
            kept.unwritten_bytes = 0;
            std::mem::take(&mut kept.unwritten)
        };
        for (path, bytes) in unwritten.iter().filter(|(path, _)| wanted(path)) {
            if let Some(dir) = path.parent() {
                std::fs::create_dir_all(dir).map_err(|e| anyhow::anyhow!("cannot create `{}`: {e}", dir.display()))?;
            }
            crate::io::atomic::write_bytes(path, bytes)?;
        }
        Ok(())
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

    #[test]
    fn unwritten_files_stay_within_their_budget_until_written_or_forgotten() {
        let dir = crate::tempdir::tempdir().unwrap();
        let (a, b, c) = (dir.path().join("s1/x=1/data"), dir.path().join("s1/x=2/data"), dir.path().join("s2/data"));
        let memo = TableMemo { unwritten_budget: 10, ..TableMemo::new(8 * 1000) };
        assert!(memo.keep_unwritten(&a, table(10), vec![1; 6], 1).is_none());
        // Over the files' budget: both handed back, nothing kept (the caller writes the file).
        let (back, bytes) = memo.keep_unwritten(&b, table(20), vec![2; 6], 1).expect("over budget");
        assert_eq!((back, bytes), (table(20), vec![2; 6]));
        assert!(memo.take(&b).is_none() && memo.unwritten(&b).is_none());
        // No reader: nothing to keep it for.
        assert!(memo.keep_unwritten(&c, table(1), vec![3], 0).is_some());
        assert!(memo.keep_unwritten(&c, table(1), vec![3; 4], 1).is_none());
        // Its table is taken once, its bytes stay readable (a stage reading a part twice).
        assert_eq!(*memo.take(&a).unwrap(), table(10));
        assert_eq!(memo.unwritten(&a).as_deref(), Some(&[1u8; 6][..]));
        memo.forget_unwritten(&dir.path().join("s2"));
        assert!(memo.unwritten(&c).is_none(), "forgotten with its stage's folder");
        assert!(memo.unwritten(&a).is_some(), "another stage's file stays");
        // The freed bytes are free again; the commit writes only what it installs.
        assert!(memo.keep_unwritten(&b, table(20), vec![2; 4], 1).is_none());
        memo.write_unwritten(|p| p == a.as_path()).unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), [1; 6], "written, its folders made");
        assert!(!b.exists() && !b.parent().unwrap().exists(), "not wanted: never written");
        assert!(memo.unwritten(&a).is_none() && memo.unwritten(&b).is_none(), "all let go");
    }
}
