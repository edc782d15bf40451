//! The output folder's state: what each work unit last ran with and what it wrote (after
//! `dvc.lock`), sharded by stage (after git's trees and DVC's `.dir` listings).
//!
//! On disk (format 3, or 4 when a stage is cut into buckets):
//! - `shakeflow.lock`, the root: the format, the pipeline owning the folder, and per stage the
//!   name of its state file — one line a stage — or, for a stage of more records than a folder
//!   holds (`layout::fans_out`), the name of each bucket's file;
//! - `.shakeflow/state/<stage>.<hash>.json`, one per stage: the stage's entry ([`StageLock`]),
//!   named by the blake3 of its bytes (32 hex digits) and never changed once written;
//! - `.shakeflow/state/<stage>.<xx>.<hash>.json` instead, for a large stage: the units whose id
//!   falls in bucket `xx` (`layout::fan_folder`, the two-level folders' 256 buckets), each file
//!   a whole [`StageLock`] of those units. A motion's records share a bucket in every stage, so
//!   a Slurm task cut by bucket reads its buckets of its stage and of the stages it reads.
//!
//! A reader takes the root and only the stage files it needs ([`LockFile::read_stages`]: a
//! Slurm task reads its stage's and its upstream stages', only its buckets of each where they
//! are aligned). A commit writes a file only for a stage (or bucket) whose entry changed, and a
//! new root naming them ([`LockFile::encode`]); the transaction
//! (`txn.rs`) installs the new files before the root, so renaming the journal stays its one
//! commit point, and removes the files only the old root named after the new root is in place.
//! Same entries, same bytes, same names: the state is deterministic like the artifacts.
//!
//! A stage's entry holds its type, version and parameters, and one entry per work unit — a
//! record of a per-record stage (keyed by its partition, `motion=FB-4/floor=5`) or the one unit
//! of a gathering stage (keyed `*`): the unit's cache key, the content hashes of what it read,
//! and the files it wrote with their hashes. A record that could not be read by a source with
//! `on_error: skip` is an entry with no files and the reason it was flagged.
//!
//! Older output folders are carried over when read: a format-2 lockfile (every stage in the one
//! file) reads as it is and is written as format 3 by the next commit; format 1 as below.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::layout::{fan_bucket, fan_folder, STATE_DIR, STATE_FILES};
use crate::error::UserError;

const LOCK_FORMAT: u32 = 3;
/// Format 3 with stages cut into buckets: written only when one is, so a folder of small stages
/// stays readable by the shakeflow that wrote format 3.
const FORMAT_4: u32 = 4;
/// The format that kept every stage's entry in the lockfile itself.
const FORMAT_2: u32 = 2;
/// The unit of a stage written by a shakeflow whose lockfile had no work units (format 1).
pub const FORMAT_1_UNIT: &str = "(format 1)";
const HEADER: &str = "# Written by `shakeflow run`: each stage's state file in .shakeflow/state/. Do not edit.\n";
const RECOMPUTE: &str = "delete it to recompute every stage";

/// The state of an output folder: every stage's entry, as one value in memory. It serialises as
/// the format-2 lockfile (`version`, `pipeline`, `stages`), which is how format 2 is read.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LockFile {
    pub version: u32,
    /// The pipeline file that owns the output folder, relative to it (`../pipelines/demo.yaml`):
    /// a second pipeline writing into the same folder is refused.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pipeline: Option<String>,
    pub stages: BTreeMap<String, StageLock>,
    /// Stage → the state file(s) its entry was read from (formats 3 and 4): a commit keeps the
    /// file of a stage (or bucket) whose entry it leaves as it was.
    #[serde(skip)]
    pub state_files: BTreeMap<String, StateFiles>,
    /// Some stages' files were not read ([`LockFile::read_stages`]): not to be written.
    #[serde(skip)]
    partial: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageLock {
    #[serde(rename = "type")]
    pub stage_type: String,
    pub stage_version: u32,
    pub params: serde_json::Value,
    /// The stage's `select:` filter, when it has one.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub select: BTreeMap<String, Vec<String>>,
    pub units: BTreeMap<String, UnitLock>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnitLock {
    /// blake3 of type, version, normalised params and the unit's input hashes: equal key, equal result.
    pub key: String,
    /// Every file the unit read (record parts, upstream parts, files named by parameters) → hash.
    pub inputs: BTreeMap<String, String>,
    /// Every file the unit wrote, relative to the stage's folder → hash.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub files: BTreeMap<String, String>,
    /// Why the record was skipped (`on_error: skip`); it has no files then.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flagged: Option<String>,
    /// What the unit's tables flagged about a record they hold whole (`sink::FLAGS_KEY`), for
    /// the `status` table of the runs that find it cached.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

/// Where a stage's entry is on disk: one file, or one per bucket of its units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum StateFiles {
    One(String),
    Buckets(BTreeMap<String, String>),
}

impl StateFiles {
    /// The one file of a stage not cut into buckets.
    #[cfg(test)]
    pub fn one(&self) -> &str {
        match self {
            StateFiles::One(name) => name,
            StateFiles::Buckets(_) => panic!("a stage in buckets"),
        }
    }

    /// Every file name, in order.
    pub fn names(&self) -> Vec<&str> {
        match self {
            StateFiles::One(name) => vec![name.as_str()],
            StateFiles::Buckets(files) => files.values().map(String::as_str).collect(),
        }
    }
}

/// The root of a format-3 or -4 state: per stage, its state file(s).
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Root {
    version: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pipeline: Option<String>,
    stages: BTreeMap<String, StateFiles>,
}

/// Which buckets of a stage a reader wants: all (None), or these (`layout::fan_bucket`).
pub type Wanted = BTreeMap<String, Option<BTreeSet<u8>>>;

/// Whether a stage's entry is kept in buckets: it has more records than a folder holds.
fn in_buckets(entry: &StageLock) -> bool {
    super::layout::fans_out(entry.units.keys().map(String::as_str), super::layout::fan_out_above())
}

/// A stage's entry cut into buckets: each its own entry (the same type, version, params, select).
fn buckets(entry: &StageLock) -> BTreeMap<String, StageLock> {
    let mut out: BTreeMap<String, StageLock> = BTreeMap::new();
    for (id, unit) in &entry.units {
        out.entry(fan_folder(id))
            .or_insert_with(|| StageLock { units: BTreeMap::new(), ..entry.header() })
            .units
            .insert(id.clone(), unit.clone());
    }
    out
}

impl StageLock {
    /// The entry without its units.
    fn header(&self) -> StageLock {
        StageLock {
            stage_type: self.stage_type.clone(),
            stage_version: self.stage_version,
            params: self.params.clone(),
            select: self.select.clone(),
            units: BTreeMap::new(),
        }
    }
}

/// How much of the state a read took: files and bytes.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StateRead {
    pub files: usize,
    pub bytes: u64,
}

/// What a commit writes of the state ([`LockFile::encode`]).
#[derive(Debug, PartialEq)]
pub struct NewState {
    /// The new root (`shakeflow.lock`).
    pub root: Vec<u8>,
    /// The state files of the stages whose entry changed: name → bytes.
    pub files: Vec<(String, Vec<u8>)>,
    /// State files the old root names and the new one does not.
    pub retired: Vec<String>,
}

/// The folder of the state files, in the output folder whose lockfile is `lock_path`.
pub fn state_dir(lock_path: &Path) -> PathBuf {
    lock_path.parent().unwrap_or(Path::new(".")).join(STATE_DIR).join(STATE_FILES)
}

/// `<stage>.<32 hex digits of blake3>.json`, or `<stage>.<bucket>.<…>.json` for a bucket's.
fn state_file_name(stage: &str, bucket: Option<&str>, bytes: &[u8]) -> String {
    let hash = &crate::io::hash::hash_bytes(bytes)[..32];
    match bucket {
        Some(bucket) => format!("{stage}.{bucket}.{hash}.json"),
        None => format!("{stage}.{hash}.json"),
    }
}

/// Whether a root's `file` for `stage` (and `bucket`) has the shape shakeflow gives its state
/// files (so a hand-edited root can name nothing outside the state folder, nor a user's file).
fn is_state_file_name(stage: &str, bucket: Option<&str>, file: &str) -> bool {
    let is_hex =
        |h: &str, len: usize| h.len() == len && h.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b));
    let mut rest = file.strip_prefix(stage).and_then(|r| r.strip_prefix('.'));
    if let Some(bucket) = bucket {
        rest =
            rest.and_then(|r| r.strip_prefix(bucket)).and_then(|r| r.strip_prefix('.')).filter(|_| is_hex(bucket, 2));
    }
    let hex = rest.and_then(|r| r.strip_suffix(".json"));
    !stage.is_empty() && !stage.contains('/') && !stage.starts_with('.') && hex.is_some_and(|h| is_hex(h, 32))
}

/// The bytes of a state file: the entry's JSON and a newline.
fn encoded(entry: &StageLock) -> anyhow::Result<Vec<u8>> {
    let mut bytes = serde_json::to_vec(entry)?;
    bytes.push(b'\n');
    Ok(bytes)
}

impl LockFile {
    pub fn empty() -> LockFile {
        LockFile { version: LOCK_FORMAT, ..LockFile::default() }
    }

    /// Whether it was read from a lockfile of an older format that holds entries (format 2): the
    /// next commit writes it as format 3, even when nothing else changes.
    pub fn is_older_format(&self) -> bool {
        self.version < LOCK_FORMAT && !self.stages.is_empty()
    }

    /// Every stage's entry. A missing lockfile is an empty one; an unreadable or damaged one (or
    /// a state file it names) is an error, never silently dropped. A format-1 lockfile (one
    /// entry per stage) reads as stages whose one unit owns every file in the stage's folder and
    /// is stale: the next run recomputes them and removes what it no longer writes.
    pub fn read(path: &Path) -> Result<LockFile, UserError> {
        Ok(read_with(path, None, &|p| std::fs::read(p))?.0)
    }

    /// The root and the entries of the `wanted` stages only, of a stage kept in buckets only the
    /// wanted buckets' units (the other files are not opened), and how much that read: what a
    /// Slurm task plans its shard with.
    pub fn read_stages(path: &Path, wanted: &Wanted) -> Result<(LockFile, StateRead), UserError> {
        read_with(path, Some(wanted), &|p| std::fs::read(p))
    }

    /// The new root and the state files of the stages whose entry differs from `previous`
    /// (the state this commit replaces, read whole): a stage's entry left as it was keeps its
    /// file without being encoded again.
    pub fn encode(&self, previous: &LockFile) -> anyhow::Result<NewState> {
        anyhow::ensure!(!self.partial && !previous.partial, "a partly read state cannot be committed");
        let mut names = BTreeMap::new();
        let mut files = Vec::new();
        for (stage, entry) in &self.stages {
            let was = previous.state_files.get(stage);
            let before = previous.stages.get(stage);
            let split = in_buckets(entry);
            // An entry as it was keeps its file(s), unless it has crossed the fan-out limit.
            if let Some(kept) = was.filter(|w| before == Some(entry) && matches!(w, StateFiles::Buckets(_)) == split) {
                names.insert(stage.clone(), kept.clone());
                continue;
            }
            let mut write = |bucket: Option<&str>, entry: &StageLock| -> anyhow::Result<String> {
                let bytes = encoded(entry)?;
                let name = state_file_name(stage, bucket, &bytes);
                files.push((name.clone(), bytes));
                Ok(name)
            };
            let named = if split {
                // A bucket whose units are as they were keeps its file, unencoded.
                let old: BTreeMap<String, StageLock> = match (was, before) {
                    (Some(StateFiles::Buckets(_)), Some(before)) => buckets(before),
                    _ => BTreeMap::new(),
                };
                let mut named = BTreeMap::new();
                for (bucket, part) in buckets(entry) {
                    let kept = match was {
                        Some(StateFiles::Buckets(old_files)) if old.get(&bucket) == Some(&part) => {
                            old_files.get(&bucket).cloned()
                        }
                        _ => None,
                    };
                    let name = match kept {
                        Some(name) => name,
                        None => write(Some(&bucket), &part)?,
                    };
                    named.insert(bucket, name);
                }
                StateFiles::Buckets(named)
            } else {
                StateFiles::One(write(None, entry)?)
            };
            names.insert(stage.clone(), named);
        }
        // A file written again under the name it had (the same bytes) is not new.
        let old_names: BTreeSet<&str> = previous.state_files.values().flat_map(StateFiles::names).collect();
        files.retain(|(name, _)| !old_names.contains(name.as_str()));
        let live: BTreeSet<&str> = names.values().flat_map(StateFiles::names).collect();
        let retired = old_names.into_iter().filter(|n| !live.contains(n)).map(String::from).collect();
        let version = if names.values().any(|f| matches!(f, StateFiles::Buckets(_))) { FORMAT_4 } else { LOCK_FORMAT };
        let root = Root { version, pipeline: self.pipeline.clone(), stages: names };
        let mut bytes = HEADER.as_bytes().to_vec();
        bytes.extend(serde_yaml::to_string(&root)?.into_bytes());
        Ok(NewState { root: bytes, files, retired })
    }
}

/// Reads the lockfile at `path` and the state files of the `wanted` stages and buckets (all:
/// None) through `read`, counting what it reads. The state files are read and parsed in
/// parallel (at 10⁴ tests a no-op run's largest read); the first error, in the stages' order,
/// is the one told.
fn read_with(
    path: &Path,
    wanted: Option<&Wanted>,
    read: &(dyn Fn(&Path) -> std::io::Result<Vec<u8>> + Sync),
) -> Result<(LockFile, StateRead), UserError> {
    let mut count = StateRead::default();
    let bytes = match read(path) {
        Ok(bytes) => bytes,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok((LockFile::empty(), count)),
        Err(e) => return Err(UserError::new(format!("cannot read the lockfile: {e}")).in_file(path)),
    };
    count.files += 1;
    count.bytes += bytes.len() as u64;
    let damaged = |what: String, at: Option<(usize, usize)>| {
        UserError::new(format!("the lockfile is damaged: {what}")).in_file(path).at(at).hint(RECOMPUTE)
    };
    let yaml = |e: serde_yaml::Error| damaged(e.to_string(), e.location().map(|l| (l.line(), l.column())));
    let text = String::from_utf8(bytes).map_err(|e| damaged(e.to_string(), None))?;
    let value: serde_yaml::Value = serde_yaml::from_str(&text).map_err(yaml)?;
    match value.get("version").and_then(serde_yaml::Value::as_u64) {
        Some(1) => {
            let old: format1::LockFile = serde_yaml::from_value(value).map_err(yaml)?;
            return Ok((old.upgrade(path.parent().unwrap_or(Path::new("."))), count));
        }
        Some(v) if v == u64::from(FORMAT_2) => {
            let lock: LockFile = serde_yaml::from_value(value).map_err(yaml)?;
            return Ok((lock, count));
        }
        Some(v) if v == u64::from(LOCK_FORMAT) || v == u64::from(FORMAT_4) => {}
        _ => {
            let version = value.get("version").map_or("none".into(), |v| format!("{v:?}"));
            return Err(UserError::new(format!("lockfile format {version} is not supported"))
                .in_file(path)
                .hint(RECOMPUTE));
        }
    }
    let root: Root = serde_yaml::from_value(value).map_err(yaml)?;
    for (stage, files) in &root.stages {
        let bad = match files {
            StateFiles::One(file) => (!is_state_file_name(stage, None, file)).then_some(file),
            StateFiles::Buckets(files) if files.is_empty() => {
                return Err(damaged(format!("stage `{stage}` names no state file"), None));
            }
            StateFiles::Buckets(_) if root.version == LOCK_FORMAT => {
                return Err(damaged(format!("stage `{stage}` is in buckets in a format-3 root"), None));
            }
            StateFiles::Buckets(files) => {
                files.iter().find(|(b, f)| !is_state_file_name(stage, Some(b), f)).map(|(_, f)| f)
            }
        };
        if let Some(file) = bad {
            return Err(damaged(format!("`{file}` is not the name of stage `{stage}`'s state file"), None));
        }
    }
    let dir = state_dir(path);
    let mut lock = LockFile { version: LOCK_FORMAT, pipeline: root.pipeline, ..LockFile::default() };
    // Every file to read; a stage whose wanted buckets have no file yet still reads one, for
    // its type, version and params.
    struct ToRead {
        stage: String,
        bucket: Option<String>,
        file: String,
        header_only: bool,
    }
    let one = |stage: &String, bucket: Option<&String>, file: &String, header_only| ToRead {
        stage: stage.clone(),
        bucket: bucket.cloned(),
        file: file.clone(),
        header_only,
    };
    let mut to_read: Vec<ToRead> = Vec::new();
    for (stage, files) in &root.stages {
        let Some(buckets) = wanted.map_or(Some(&None), |w| w.get(stage)) else {
            lock.partial = true;
            continue;
        };
        match files {
            StateFiles::One(file) => {
                // A stage not (yet) in buckets, read for some: only their units are the reader's.
                lock.partial |= buckets.is_some();
                to_read.push(one(stage, None, file, false))
            }
            StateFiles::Buckets(files) => {
                // (Each name is two hex digits: checked with the file names above.)
                let wanted =
                    |b: &str| u8::from_str_radix(b, 16).is_ok_and(|b| buckets.as_ref().is_none_or(|w| w.contains(&b)));
                let some = files.iter().filter(|(b, _)| wanted(b));
                let mut some: Vec<ToRead> = some.map(|(b, f)| one(stage, Some(b), f, false)).collect();
                if some.len() < files.len() {
                    lock.partial = true;
                }
                if let (true, Some((b, f))) = (some.is_empty(), files.iter().next()) {
                    some.push(one(stage, Some(b), f, true)); // its units are not the reader's
                }
                to_read.extend(some);
            }
        }
    }
    let entries: Vec<Result<(StageLock, u64), UserError>> = to_read
        .par_iter()
        .map(|ToRead { stage, bucket, file, .. }| {
            let state = dir.join(file);
            let unreadable = |what: String| {
                UserError::new(format!("the state of stage `{stage}` {what}"))
                    .in_file(&state)
                    .hint(format!("delete `{}` to recompute every stage", path.display()))
            };
            let bytes = read(&state).map_err(|e| unreadable(format!("cannot be read: {e}")))?;
            let bucket = bucket.as_deref();
            if state_file_name(stage, bucket, &bytes) != *file {
                return Err(unreadable("is damaged: its content does not match its name".into()));
            }
            let entry: StageLock =
                serde_json::from_slice(&bytes).map_err(|e| unreadable(format!("is damaged: {e}")))?;
            if let Some(b) = bucket {
                if let Some(id) = entry.units.keys().find(|id| fan_folder(id) != b) {
                    return Err(unreadable(format!("is damaged: unit `{id}` is not of bucket {b}")));
                }
            }
            Ok((entry, bytes.len() as u64))
        })
        .collect();
    // A stage in buckets: its header, and its buckets' units gathered, then made one map at
    // once (merging 256 maps one by one into a growing one took a third of a no-op at 10⁴ tests).
    let mut gathered: BTreeMap<String, (StageLock, Vec<(String, UnitLock)>)> = BTreeMap::new();
    for (ToRead { stage, bucket, header_only, .. }, entry) in to_read.into_iter().zip(entries) {
        let (entry, bytes) = entry?;
        count.files += 1;
        count.bytes += bytes;
        if bucket.is_none() {
            let mut entry = entry;
            if let Some(Some(only)) = wanted.and_then(|w| w.get(&stage)) {
                entry.units.retain(|id, _| only.contains(&fan_bucket(id)));
            }
            lock.stages.insert(stage, entry);
            continue;
        }
        let StageLock { stage_type, stage_version, params, select, units } = entry;
        let units = if header_only { BTreeMap::new() } else { units };
        let header = StageLock { stage_type, stage_version, params, select, units: BTreeMap::new() };
        let (first, all) = gathered.entry(stage.clone()).or_insert_with(|| (header.clone(), Vec::new()));
        if *first != header {
            let file = root.stages[&stage].names().join(", ");
            return Err(damaged(format!("the buckets of stage `{stage}` disagree ({file})"), None));
        }
        all.extend(units);
    }
    for (stage, (header, units)) in gathered {
        lock.stages.insert(stage, StageLock { units: units.into_iter().collect(), ..header });
    }
    lock.state_files = root.stages;
    Ok((lock, count))
}

/// The lockfile of shakeflow before work units, read once to carry its output folder over.
mod format1 {
    use std::collections::BTreeMap;
    use std::path::Path;

    use serde::Deserialize;

    #[derive(Deserialize)]
    pub struct LockFile {
        #[serde(default)]
        pipeline: Option<String>,
        stages: BTreeMap<String, StageLock>,
    }

    #[derive(Deserialize)]
    struct StageLock {
        #[serde(rename = "type")]
        stage_type: String,
        stage_version: u32,
        params: serde_json::Value,
        #[serde(default)]
        select: BTreeMap<String, Vec<String>>,
    }

    impl LockFile {
        pub fn upgrade(self, output_dir: &Path) -> super::LockFile {
            let stages = self
                .stages
                .into_iter()
                .map(|(name, old)| {
                    let files = crate::io::hash::list_files(&output_dir.join(&name))
                        .unwrap_or_default()
                        .into_iter()
                        .filter(|f| f != crate::pipeline::layout::STAGE_MARKER)
                        .map(|f| (f, String::new()))
                        .collect();
                    let unit = super::UnitLock {
                        key: String::new(),
                        inputs: BTreeMap::new(),
                        files,
                        flagged: None,
                        notes: Vec::new(),
                    };
                    let entry = super::StageLock {
                        stage_type: old.stage_type,
                        stage_version: old.stage_version,
                        params: old.params,
                        select: old.select,
                        units: BTreeMap::from([(super::FORMAT_1_UNIT.to_string(), unit)]),
                    };
                    (name, entry)
                })
                .collect();
            super::LockFile { pipeline: self.pipeline, stages, ..super::LockFile::empty() }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(key: &str) -> UnitLock {
        UnitLock {
            key: key.into(),
            inputs: BTreeMap::from([("source records".to_string(), format!("in-{key}"))]),
            files: BTreeMap::from([(format!("records/{key}/data.parquet"), format!("out-{key}"))]),
            flagged: None,
            notes: Vec::new(),
        }
    }

    fn stage(units: &[&str]) -> StageLock {
        StageLock {
            stage_type: "baseline".into(),
            stage_version: 3,
            params: serde_json::json!({"order": 2}),
            select: BTreeMap::new(),
            units: units.iter().map(|u| (u.to_string(), unit(u))).collect(),
        }
    }

    fn state(stages: &[(&str, &[&str])]) -> LockFile {
        let mut lock = LockFile::empty();
        lock.pipeline = Some("../pipeline.yaml".into());
        lock.stages = stages.iter().map(|(name, units)| (name.to_string(), stage(units))).collect();
        lock
    }

    /// What the transaction does with a [`NewState`], without one: the files in, the root, the
    /// retired files out.
    fn install(lock_path: &Path, new: &NewState) {
        let dir = state_dir(lock_path);
        std::fs::create_dir_all(&dir).unwrap();
        for (name, bytes) in &new.files {
            std::fs::write(dir.join(name), bytes).unwrap();
        }
        std::fs::write(lock_path, &new.root).unwrap();
        for name in &new.retired {
            std::fs::remove_file(dir.join(name)).unwrap();
        }
    }

    fn state_files(lock_path: &Path) -> Vec<String> {
        crate::io::hash::list_files(&state_dir(lock_path)).unwrap()
    }

    #[test]
    fn a_reader_reads_the_root_and_only_the_stages_it_asks_for() {
        let dir = crate::tempdir::tempdir().unwrap();
        let path = dir.path().join("shakeflow.lock");
        let lock = state(&[("load", &["a", "b"]), ("baseline", &["a", "b"]), ("report", &["*"])]);
        install(&path, &lock.encode(&LockFile::empty()).unwrap());
        assert_eq!(state_files(&path).len(), 3);
        let whole = LockFile::read(&path).unwrap();
        assert_eq!(whole.stages, lock.stages);
        assert_eq!(whole.pipeline, lock.pipeline);

        let opened = std::sync::Mutex::new(Vec::new());
        let wanted = Wanted::from([("load".to_string(), None), ("baseline".to_string(), None)]);
        let (some, read) = read_with(&path, Some(&wanted), &|p| {
            opened.lock().unwrap().push(p.file_name().unwrap().to_string_lossy().into_owned());
            std::fs::read(p)
        })
        .unwrap();
        let opened = opened.into_inner().unwrap();
        assert_eq!(opened.len(), 3, "the root, load's and baseline's files: {opened:?}");
        assert!(opened[0] == "shakeflow.lock" && !opened.iter().any(|f| f.starts_with("report.")), "{opened:?}");
        let size = |f: &str| std::fs::metadata(state_dir(&path).join(f)).unwrap().len();
        let expected = std::fs::metadata(&path).unwrap().len()
            + size(some.state_files["load"].one())
            + size(some.state_files["baseline"].one());
        assert_eq!(read, StateRead { files: 3, bytes: expected });
        assert_eq!(some.stages.keys().collect::<Vec<_>>(), ["baseline", "load"]);
        assert_eq!(some.stages["load"], lock.stages["load"]);
        assert!(some.state_files.contains_key("report"), "it knows the other stages' files, unread");
        let refused = some.encode(&whole).unwrap_err().to_string();
        assert!(refused.contains("partly read"), "{refused}");
    }

    #[test]
    fn a_commit_writes_files_only_for_the_stages_that_changed_and_retires_the_old_ones() {
        let dir = crate::tempdir::tempdir().unwrap();
        let path = dir.path().join("shakeflow.lock");
        let stages: Vec<String> = (0..50).map(|i| format!("s{i:02}")).collect();
        let lock = state(&stages.iter().map(|s| (s.as_str(), &["a", "b"][..])).collect::<Vec<_>>());
        install(&path, &lock.encode(&LockFile::empty()).unwrap());
        let before = LockFile::read(&path).unwrap();
        let files_before = state_files(&path);

        // Unchanged: nothing new, nothing retired, the same root.
        let same = before.encode(&before).unwrap();
        assert!(same.files.is_empty() && same.retired.is_empty());
        assert_eq!(same.root, std::fs::read(&path).unwrap());

        // One record more in one stage of fifty: one new file, one retired.
        let mut after = before.clone();
        after.stages.get_mut("s07").unwrap().units.insert("c".into(), unit("c"));
        let new = after.encode(&before).unwrap();
        assert_eq!(new.files.len(), 1);
        assert!(new.files[0].0.starts_with("s07."), "{:?}", new.files[0].0);
        assert_eq!(new.retired, [before.state_files["s07"].one().to_string()]);
        install(&path, &new);
        let read = LockFile::read(&path).unwrap();
        assert_eq!(read.stages, after.stages);
        let files_after = state_files(&path);
        assert_eq!(files_after.len(), 50, "the old file of s07 is gone");
        assert_eq!(files_before.iter().filter(|f| !files_after.contains(f)).count(), 1);

        // A stage gone (`gc`): its file retired, nothing written.
        let mut fewer = read.clone();
        fewer.stages.remove("s49");
        let new = fewer.encode(&read).unwrap();
        assert!(new.files.is_empty());
        assert_eq!(new.retired, [read.state_files["s49"].one().to_string()]);
    }

    #[test]
    fn the_same_entries_make_the_same_bytes_and_names() {
        let a = state(&[("load", &["a", "b"]), ("baseline", &["a"])]);
        let mut b = state(&[("baseline", &["a"])]);
        b.stages.insert("load".into(), stage(&["b", "a"]));
        let (a, b) = (a.encode(&LockFile::empty()).unwrap(), b.encode(&LockFile::empty()).unwrap());
        assert_eq!(a, b);
        let root = String::from_utf8(a.root).unwrap();
        assert!(root.contains("version: 3\npipeline: ../pipeline.yaml\nstages:\n  baseline: baseline."), "{root}");
        for (name, bytes) in &a.files {
            assert_eq!(*name, state_file_name(name.split('.').next().unwrap(), None, bytes));
        }
    }

    #[test]
    fn a_damaged_or_misnamed_state_is_an_error_never_dropped() {
        let dir = crate::tempdir::tempdir().unwrap();
        let path = dir.path().join("shakeflow.lock");
        install(&path, &state(&[("load", &["a"])]).encode(&LockFile::empty()).unwrap());
        let file = state_dir(&path).join(LockFile::read(&path).unwrap().state_files["load"].one());
        let good = std::fs::read(&file).unwrap();
        std::fs::write(&file, String::from_utf8(good.clone()).unwrap().replace("in-a", "in-b")).unwrap();
        let error = LockFile::read(&path).unwrap_err().to_string();
        assert!(error.contains("state of stage `load` is damaged: its content does not match its name"), "{error}");
        std::fs::remove_file(&file).unwrap();
        let error = LockFile::read(&path).unwrap_err().to_string();
        assert!(error.contains("state of stage `load` cannot be read"), "{error}");
        let root = std::fs::read_to_string(&path).unwrap();
        let name = file.file_name().unwrap().to_string_lossy().into_owned();
        for bad in ["../../thesis.txt", "load.json", "baseline.0123456789abcdef0123456789abcdef.json"] {
            std::fs::write(&path, root.replace(&name, bad)).unwrap();
            let error = LockFile::read(&path).unwrap_err().to_string();
            assert!(error.contains("is not the name of stage `load`'s state file"), "{bad}: {error}");
        }
        std::fs::write(&path, root.replace(&name, "{}")).unwrap(); // `load: {}`: no bucket
        let error = LockFile::read(&path).unwrap_err().to_string();
        assert!(error.contains("stage `load` names no state file"), "{error}");
        assert!(is_state_file_name("load", None, &name));
        assert!(!is_state_file_name("..", None, "...0123456789abcdef0123456789abcdef.json"));
        let hex = "0123456789abcdef0123456789abcdef";
        assert!(is_state_file_name("load", Some("3f"), &format!("load.3f.{hex}.json")));
        assert!(!is_state_file_name("load", Some("3f"), &format!("load.4f.{hex}.json")), "another bucket's");
        assert!(!is_state_file_name("load", Some("../x"), &format!("load.../x.{hex}.json")));
        assert!(!is_state_file_name("load", None, &format!("load.3f.{hex}.json")));
    }

    #[test]
    fn a_format_2_lockfile_reads_whole_and_is_written_as_format_3_at_the_next_commit() {
        let dir = crate::tempdir::tempdir().unwrap();
        let path = dir.path().join("shakeflow.lock");
        let mut old = state(&[("load", &["a", "b"]), ("baseline", &["a"])]);
        old.version = 2;
        std::fs::write(&path, format!("# Written by `shakeflow run`\n{}", serde_yaml::to_string(&old).unwrap()))
            .unwrap();
        let read = LockFile::read(&path).unwrap();
        assert_eq!(read.stages, old.stages);
        assert!(read.is_older_format() && read.state_files.is_empty());
        let (_, partly) = LockFile::read_stages(&path, &Wanted::from([("load".to_string(), None)])).unwrap();
        assert_eq!(partly.files, 1, "format 2: the one file holds everything");
        let new = read.encode(&read).unwrap();
        assert_eq!(new.files.len(), 2, "every stage gets its file");
        assert!(new.retired.is_empty());
        install(&path, &new);
        let now = LockFile::read(&path).unwrap();
        assert_eq!(now.stages, old.stages);
        assert!(!now.is_older_format());
    }

    /// `n` motions of two floors each (`motion=M0007/floor=4`): past the fan-out limit when
    /// there are more than a folder holds.
    fn many(n: usize) -> StageLock {
        let ids: Vec<String> =
            (0..n).flat_map(|m| [format!("motion=M{m:04}/floor=4"), format!("motion=M{m:04}/floor=5")]).collect();
        stage(&ids.iter().map(String::as_str).collect::<Vec<_>>())
    }

    #[test]
    fn a_large_stage_is_kept_in_buckets_and_a_reader_of_some_buckets_reads_only_their_files() {
        let dir = crate::tempdir::tempdir().unwrap();
        let path = dir.path().join("shakeflow.lock");
        let motions = crate::pipeline::layout::FAN_OUT_ABOVE + 200;
        let mut lock = state(&[("report", &["*"])]);
        lock.stages.insert("load".into(), many(motions));
        let new = lock.encode(&LockFile::empty()).unwrap();
        install(&path, &new);
        let root = String::from_utf8(new.root.clone()).unwrap();
        assert!(root.contains("version: 4\n") && root.contains("  load:\n    '00': load.00."), "{root}");
        assert_eq!(state_files(&path).len(), 257, "256 buckets of load, one file of report");
        let whole = LockFile::read(&path).unwrap();
        assert_eq!(whole.stages, lock.stages, "the buckets read back as the one entry");
        assert!(!whole.is_older_format());

        // A reader of two buckets opens the root and those two files; a motion's floors share one.
        let wanted_buckets = BTreeSet::from([0x3f, 0xa0]);
        let opened = std::sync::Mutex::new(Vec::new());
        let wanted = Wanted::from([("load".to_string(), Some(wanted_buckets.clone()))]);
        let (some, read) = read_with(&path, Some(&wanted), &|p| {
            opened.lock().unwrap().push(p.file_name().unwrap().to_string_lossy().into_owned());
            std::fs::read(p)
        })
        .unwrap();
        let opened = opened.into_inner().unwrap();
        assert_eq!(opened.len(), 3, "{opened:?}");
        assert_eq!(read.files, 3);
        let expected: BTreeMap<&String, &UnitLock> =
            lock.stages["load"].units.iter().filter(|(id, _)| wanted_buckets.contains(&fan_bucket(id))).collect();
        assert!(expected.len() > 4, "{} units in two buckets", expected.len());
        assert_eq!(some.stages["load"].units.iter().collect::<BTreeMap<_, _>>(), expected);
        assert_eq!(some.stages["load"].params, lock.stages["load"].params);
        assert!(some.encode(&whole).is_err(), "a partly read state is not committed");

        // One record more: one bucket's file is new and its old one retired; the rest stay.
        let mut after = whole.clone();
        let id = "motion=N0001/floor=4";
        after.stages.get_mut("load").unwrap().units.insert(id.into(), unit("n"));
        let new = after.encode(&whole).unwrap();
        assert_eq!(new.files.len(), 1);
        assert!(new.files[0].0.starts_with(&format!("load.{}.", fan_folder(id))), "{}", new.files[0].0);
        assert_eq!(new.retired.len(), 1);
        install(&path, &new);
        assert_eq!(LockFile::read(&path).unwrap().stages, after.stages);

        // A bucket's file naming a unit of another bucket is damaged, not merged.
        let file = new.files[0].0.clone();
        let bucket = &file["load.".len().."load.".len() + 2];
        let stranger = (0..).map(|i| format!("motion=X{i}")).find(|id| fan_folder(id) != bucket).unwrap();
        let mut moved: StageLock = serde_json::from_slice(&new.files[0].1).unwrap();
        moved.units.insert(stranger, unit("x"));
        let bytes = encoded(&moved).unwrap();
        let renamed = state_file_name("load", Some(bucket), &bytes);
        std::fs::write(state_dir(&path).join(&renamed), &bytes).unwrap();
        std::fs::write(&path, std::fs::read_to_string(&path).unwrap().replace(&file, &renamed)).unwrap();
        let error = LockFile::read(&path).unwrap_err().to_string();
        assert!(error.contains("is not of bucket"), "{error}");

        // Fewer records than a folder holds: one file again, format 3.
        let mut small = state(&[("load", &["a", "b"])]);
        small.pipeline = after.pipeline.clone();
        let back = small.encode(&after).unwrap();
        assert!(String::from_utf8(back.root).unwrap().contains("version: 3\n"));
        assert_eq!(back.retired.len(), 257);
    }
}
