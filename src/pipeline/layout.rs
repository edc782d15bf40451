//! Every name shakeflow gives to something on disk, in one place: what an output folder holds.
//!
//! ```text
//! <output_dir>/
//!   shakeflow.lock                     LOCK_FILE: the state's root, naming each stage's state file
//!   .shakeflow/                        STATE_DIR: shakeflow's own state
//!     state/<stage>.<hash>.json        STATE_FILES: a stage's entry: what each unit ran with and wrote
//!     state/<stage>.<xx>.<hash>.json   the same, one file per bucket past FAN_OUT_ABOVE records
//!     lease, lease.break               LEASE_FILE, BREAK_FILE: one run at a time
//!     txn-<pid>-<nanos>/               TXN_PREFIX: a transaction (`new/`, `old/`, JOURNAL)
//!     hashes.json                      HASH_MEMO: the stat/hash memo
//!     hashes/<xx>.json                 HASH_MEMO_BUCKETS: the same, per bucket, for the records of
//!                                      a source or stage past FAN_OUT_ABOVE first partition segments
//!     slurm/<run>/                     RUNS_DIR: Slurm runs (run.json, RUN_LISTINGS, RUN_RESULTS,
//!                                      RUN_MANIFESTS, RUN_LOGS)
//!   <stage>/                           a stage's folder (a command's: the output folder itself)
//!     .shakeflow-stage                 STAGE_MARKER: whose folder it is
//!     <output>/<key>=<value>/…/data.parquet   DATA_FILE, one record's table (`partition_path`)
//!     <output>/<xx>/<key>=<value>/…/data.parquet   the same past FAN_OUT_ABOVE records (`placed`)
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
/// The stat/hash memo in [`STATE_DIR`] ([`crate::io::hash::StatMemo`]), and the folder of its
/// buckets' files (the memo's name without `.json`): a fanned-out record's files are remembered
/// in its bucket's ([`memo_bucket`]).
pub const HASH_MEMO: &str = "hashes.json";
pub const HASH_MEMO_BUCKETS: &str = "hashes";
/// Where Slurm runs keep their folders, in [`STATE_DIR`].
pub const RUNS_DIR: &str = "slurm";
/// A Slurm run folder's parts: the tasks' results, their manifests, the planner's listing of
/// each shard's source files, and the jobs' logs.
pub const RUN_RESULTS: &str = "results";
pub const RUN_MANIFESTS: &str = "manifests";
pub const RUN_LISTINGS: &str = "listings";
pub const RUN_LOGS: &str = "logs";
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

/// A dataset folder holds at most this many record folders side by side. A stage with more
/// records (more distinct first `key=value` segments) puts each record one level down, in a
/// folder named by two hex digits of its first segment's blake3 (`records/3f/motion=FB-4/…`), as
/// git fans out its objects: 256 folders of ~40 records each at 10⁴ records. A folder name
/// without `=` is no partition to pyarrow, polars or DuckDB (their Hive readers skip it), and
/// unit ids, `shakeflow.partition` and input labels leave it out: the layout changes paths only.
pub const FAN_OUT_ABOVE: usize = 1000;

/// [`FAN_OUT_ABOVE`], or `SHAKEFLOW_FAN_OUT_ABOVE` (tests and benchmarks fan out small archives).
pub fn fan_out_above() -> usize {
    std::env::var("SHAKEFLOW_FAN_OUT_ABOVE").ok().and_then(|v| v.parse().ok()).unwrap_or(FAN_OUT_ABOVE)
}

/// Whether a stage whose units are `ids` (partition paths) writes two-level folders: more than
/// `limit` distinct first segments. Decided once per stage and run by the planner (a Slurm run
/// carries it to its tasks and commit job in `run.json`).
pub fn fans_out<'a>(ids: impl IntoIterator<Item = &'a str>, limit: usize) -> bool {
    let mut firsts = std::collections::BTreeSet::new();
    for id in ids {
        let first = id.split('/').next().unwrap_or_default();
        if first.contains('=') && firsts.insert(first) && firsts.len() > limit {
            return true;
        }
    }
    false
}

/// The folder a record goes in under a fanned-out dataset: two hex digits of the blake3 of its
/// partition path's first segment (all of a motion's floors share one).
pub fn fan_folder(partition_path: &str) -> String {
    format!("{:02x}", fan_bucket(partition_path))
}

/// The number of [`fan_folder`]'s folder (0–255): also the bucket of a unit's state and of the
/// Slurm shard that runs it.
pub fn fan_bucket(partition_path: &str) -> u8 {
    let first = partition_path.split('/').next().unwrap_or_default();
    blake3::hash(first.as_bytes()).as_bytes()[0]
}

/// The memo's bucket of a file a stage wrote (the memo's `bucket_of`): a record's table or
/// MCAP twin in a fanned-out layout is in its bucket's folder (`records/3f/motion=FB-4/…`);
/// any other file has none.
pub fn memo_bucket(path: &std::path::Path) -> Option<u8> {
    let name = path.file_name()?;
    if name != DATA_FILE && name != MCAP_FILE {
        return None;
    }
    // Back from the file over its partition's `key=value` folders: the one before them (an
    // ancestor of the output folder may have `=` in its name too).
    let mut folders = path.parent()?.iter().rev().map(|s| s.to_str().unwrap_or_default());
    let fan = folders.find(|s| !s.contains('='))?;
    is_fan_folder(fan).then(|| u8::from_str_radix(fan, 16).ok()).flatten()
}

fn is_fan_folder(segment: &str) -> bool {
    segment.len() == 2 && segment.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
}

/// `relative`, a file of a stage folder, where it goes in the flat layout (`fanned` false) or
/// the two-level one: a record's table or MCAP twin (`records/motion=FB-4/data.parquet`,
/// `mcap/records/…/data.mcap`) gains or loses the folder before its first `key=value`
/// segment; every other file (figures, pages, a gathering stage's table) stays where it is.
pub fn placed(relative: &str, fanned: bool) -> std::borrow::Cow<'_, str> {
    use std::borrow::Cow;
    let name = relative.rsplit('/').next().unwrap_or_default();
    if name != DATA_FILE && name != MCAP_FILE {
        return Cow::Borrowed(relative);
    }
    let segments: Vec<&str> = relative.split('/').collect();
    let Some(first) = segments.iter().position(|s| s.contains('=')) else { return Cow::Borrowed(relative) };
    // The output's name comes first (`records`, or `mcap/records`): a fan folder follows it.
    let has_fan = first >= 2 && is_fan_folder(segments[first - 1]);
    if has_fan == fanned {
        return Cow::Borrowed(relative);
    }
    let head = &segments[..if has_fan { first - 1 } else { first }];
    let tail = &segments[first..];
    let fan = fanned.then(|| fan_folder(&tail.join("/")));
    Cow::Owned(head.iter().copied().chain(fan.as_deref()).chain(tail.iter().copied()).collect::<Vec<_>>().join("/"))
}

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
        let fanned = placed(&format!("records/{path}/{DATA_FILE}"), true).into_owned();
        assert_eq!(partition_of(fanned.strip_prefix("records/").unwrap()), partition, "the fan folder is no key");
    }

    #[test]
    fn a_stage_fans_out_past_its_limit_of_first_segments() {
        let ids: Vec<String> =
            (0..5).flat_map(|m| [format!("motion=M{m}/floor=4"), format!("motion=M{m}/floor=5")]).collect();
        let ids = || ids.iter().map(String::as_str);
        assert!(!fans_out(ids(), 5), "5 motions (10 records) fit 5 folders");
        assert!(fans_out(ids(), 4));
        assert!(!fans_out(["*"], 0), "a gathering stage's one unit has no partition");
        assert!(!fans_out([""], 0));
        assert_eq!(fan_out_above(), FAN_OUT_ABOVE, "tests run without SHAKEFLOW_FAN_OUT_ABOVE");
        // The memo finds its buckets' folder by its own name (`io::hash` knows no layout).
        assert_eq!(std::path::Path::new(HASH_MEMO).with_extension(""), std::path::Path::new(HASH_MEMO_BUCKETS));
    }

    #[test]
    fn record_files_move_between_layouts_and_nothing_else_does() {
        let fan = fan_folder("motion=FB-4");
        assert_eq!(fan, fan_folder("motion=FB-4/floor=5"), "a motion's floors share a folder");
        assert!(is_fan_folder(&fan) && !fan.contains('='));
        let flat = "records/motion=FB-4/floor=5/data.parquet";
        let two = format!("records/{fan}/motion=FB-4/floor=5/data.parquet");
        assert_eq!(placed(flat, true), two);
        assert_eq!(placed(&two, false), flat);
        assert_eq!(placed(flat, false), flat);
        assert_eq!(placed(&two, true), two);
        let bucket = Some(fan_bucket("motion=FB-4"));
        assert_eq!(memo_bucket(std::path::Path::new(&format!("/out/baseline/{two}"))), bucket);
        assert_eq!(memo_bucket(std::path::Path::new(&format!("/out/{fan}/baseline/{flat}"))), None);
        assert_eq!(memo_bucket(std::path::Path::new(&format!("/out/baseline/records/{fan}/motion=X/x.png"))), None);
        assert_eq!(memo_bucket(std::path::Path::new(&format!("/data/campaign=2024/out/baseline/{two}"))), bucket);
        assert_eq!(memo_bucket(std::path::Path::new(&format!("/data/ab/campaign=2024/baseline/{flat}"))), None);
        let mcap = "mcap/records/motion=FB-4/data.mcap";
        assert_eq!(placed(mcap, true), format!("mcap/records/{fan}/motion=FB-4/data.mcap"));
        assert_eq!(placed(&placed(mcap, true), false), mcap);
        for other in [
            "figures/motion=FB-4.png",
            "summary/data.parquet",
            "index.html",
            "status/data.parquet",
            "case_1/diagnosis.json",
        ] {
            assert_eq!(placed(other, true), other);
            assert_eq!(placed(other, false), other);
        }
        // An output folder is never taken for a fan folder, whatever its name.
        assert_eq!(placed("ab/motion=X/data.parquet", false), "ab/motion=X/data.parquet");
        // Values read from file names are encoded, so every fan folder name is plain.
        let odd = format!("records/{}/data.parquet", partition_path(&vec![("motion".into(), "090 (CUE)".into())]));
        assert_eq!(placed(&placed(&odd, true), false), odd);
    }
}
