//! Every name shakeflow gives to something on disk, in one place: what an output folder holds.
//!
//! ```text
//! <output_dir>/
//!   shakeflow.lock                     LOCK_FILE: the state's root, naming each stage's state file
//!   .shakeflow/                        STATE_DIR: shakeflow's own state
//!     state/<stage>.<hash>.json        STATE_FILES: a stage's entry: what each unit ran with and wrote
//!     lease, lease.break               LEASE_FILE, BREAK_FILE: one run at a time
//!     txn-<pid>-<nanos>/               TXN_PREFIX: a transaction (`new/`, `old/`, JOURNAL)
//!     hashes.json                      HASH_MEMO: the stat/hash memo
//!     slurm/<run>/                     RUNS_DIR: Slurm runs (run.json, results/, manifests/, logs/)
//!   <stage>/                           a stage's folder (a command's: the output folder itself)
//!     .shakeflow-stage                 STAGE_MARKER: whose folder it is
//!     <output>/<key>=<value>/…/data.parquet   DATA_FILE, one record's table (`partition_path`)
//!     mcap/<output>/…/data.mcap        MCAP_DIR, MCAP_FILE: opt-in MCAP twins
//!     flagged/data.parquet             FLAGGED: records skipped by `on_error: skip`
//!     status/data.parquet              STATUS: every record's status (loaded, flagged, skipped)
//! ```
//!
//! Modules that read or write these import the names from here, so the lockfile, the sink, the
//! ownership checks and the plan do not import each other for a file name.

/// The lockfile at the root of the output folder: the root of its state.
pub const LOCK_FILE: &str = "shakeflow.lock";
/// The folder of the per-stage state files in [`STATE_DIR`] (`pipeline/lock.rs`).
pub const STATE_FILES: &str = "state";
/// shakeflow's own entries in a folder it writes: the lease, unfinished commits, the hash memo.
pub const STATE_DIR: &str = ".shakeflow";
/// The lease file in [`STATE_DIR`], and the file that makes taking over a stale one exclusive.
pub const LEASE_FILE: &str = "lease";
pub const BREAK_FILE: &str = "lease.break";
/// A transaction's folder in [`STATE_DIR`] starts with this; its commit point is [`JOURNAL`].
pub const TXN_PREFIX: &str = "txn-";
pub const JOURNAL: &str = "journal";
/// The stat/hash memo in [`STATE_DIR`] ([`crate::io::hash::StatMemo`]).
pub const HASH_MEMO: &str = "hashes.json";
/// Where Slurm runs keep their folders, in [`STATE_DIR`].
pub const RUNS_DIR: &str = "slurm";
/// The marker naming the stage (and its type) whose folder holds it.
pub const STAGE_MARKER: &str = ".shakeflow-stage";
/// One record's table, and its MCAP twin under `<stage>/mcap/<output>/`, apart from the
/// Parquet dataset `<stage>/<output>/` (pyarrow refuses datasets that mix in other files).
pub const DATA_FILE: &str = "data.parquet";
pub const MCAP_FILE: &str = "data.mcap";
pub const MCAP_DIR: &str = "mcap";
/// The output the engine writes for records skipped under `on_error: skip`.
pub const FLAGGED: &str = "flagged";
/// The output the engine writes for every record of a run over an archive: loaded, flagged,
/// skipped or failed.
pub const STATUS: &str = "status";

/// Partition keys of a record (`motion=FB-4/floor=5`), in order.
pub type Partition = Vec<(String, String)>;

/// The dataset folder of a record: `key=value` segments, each value percent-encoded where it is
/// not a plain name (`090 (CUE)` → `090%20%28CUE%29`), so no value can leave its folder.
pub fn partition_path(partition: &Partition) -> String {
    use super::paths::encode_component;
    partition
        .iter()
        .map(|(k, v)| format!("{}={}", encode_component(k), encode_component(v)))
        .collect::<Vec<_>>()
        .join("/")
}

/// The partition a dataset path names (`motion=FB-4/data.parquet`): the inverse of
/// [`partition_path`] on its `key=value` segments.
pub fn partition_of(relative: &str) -> Partition {
    relative
        .split('/')
        .filter_map(|segment| segment.split_once('='))
        .map(|(k, v)| (super::paths::decode_component(k), super::paths::decode_component(v)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partition_paths_read_back() {
        let partition: Partition = vec![("motion".into(), "090 (CUE)".into()), ("floor".into(), "5".into())];
        let path = partition_path(&partition);
        assert_eq!(path, "motion=090%20%28CUE%29/floor=5");
        assert_eq!(partition_of(&format!("{path}/{DATA_FILE}")), partition);
    }
}
