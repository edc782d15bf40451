//! The output folder's state: what each work unit last ran with and what it wrote (after
//! `dvc.lock`), sharded by stage (after git's trees and DVC's `.dir` listings).
//!
//! On disk (format 3):
//! - `shakeflow.lock`, the root: the format, the pipeline owning the folder, and per stage the
//!   name of its state file — one line a stage, whatever the size of the archive;
//! - `.shakeflow/state/<stage>.<hash>.json`, one per stage: the stage's entry ([`StageLock`]),
//!   named by the blake3 of its bytes (32 hex digits) and never changed once written.
//!
//! A reader takes the root and only the stage files it needs ([`LockFile::read_stages`]: a
//! Slurm task reads its stage's and its upstream stages'). A commit writes a file only for a
//! stage whose entry changed, and a new root naming them ([`LockFile::encode`]); the transaction
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

use super::layout::{STATE_DIR, STATE_FILES};
use crate::error::UserError;

const LOCK_FORMAT: u32 = 3;
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
    /// Stage → the state file its entry was read from (format 3): a commit keeps the file of a
    /// stage whose entry it leaves as it was.
    #[serde(skip)]
    pub state_files: BTreeMap<String, String>,
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

/// The root of a format-3 state: per stage, its state file.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Root {
    version: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pipeline: Option<String>,
    stages: BTreeMap<String, String>,
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

/// `<stage>.<32 hex digits of blake3>.json`.
fn state_file_name(stage: &str, bytes: &[u8]) -> String {
    format!("{stage}.{}.json", &crate::io::hash::hash_bytes(bytes)[..32])
}

/// Whether a root's `file` for `stage` has the shape shakeflow gives its state files (so a
/// hand-edited root can name nothing outside the state folder, nor a file of the user's).
fn is_state_file_name(stage: &str, file: &str) -> bool {
    let hex = file.strip_prefix(stage).and_then(|r| r.strip_prefix('.')).and_then(|r| r.strip_suffix(".json"));
    !stage.is_empty()
        && !stage.contains('/')
        && !stage.starts_with('.')
        && hex.is_some_and(|h| h.len() == 32 && h.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b)))
}

impl LockFile {
    pub fn empty() -> LockFile {
        LockFile { version: LOCK_FORMAT, ..LockFile::default() }
    }

    /// Whether it was read from a lockfile of an older format that holds entries (format 2): the
    /// next commit writes it as format 3, even when nothing else changes.
    pub fn is_older_format(&self) -> bool {
        self.version != LOCK_FORMAT && !self.stages.is_empty()
    }

    /// Every stage's entry. A missing lockfile is an empty one; an unreadable or damaged one (or
    /// a state file it names) is an error, never silently dropped. A format-1 lockfile (one
    /// entry per stage) reads as stages whose one unit owns every file in the stage's folder and
    /// is stale: the next run recomputes them and removes what it no longer writes.
    pub fn read(path: &Path) -> Result<LockFile, UserError> {
        Ok(read_with(path, None, &|p| std::fs::read(p))?.0)
    }

    /// The root and the entries of `stages` only (the others' state files are not opened), and
    /// how much that read: what a Slurm task plans its shard with.
    pub fn read_stages(path: &Path, stages: &BTreeSet<String>) -> Result<(LockFile, StateRead), UserError> {
        read_with(path, Some(stages), &|p| std::fs::read(p))
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
            let name = match was.filter(|_| previous.stages.get(stage) == Some(entry)) {
                Some(kept) => kept.clone(),
                None => {
                    let mut bytes = serde_json::to_vec(entry)?;
                    bytes.push(b'\n');
                    let name = state_file_name(stage, &bytes);
                    if was != Some(&name) {
                        files.push((name.clone(), bytes));
                    }
                    name
                }
            };
            names.insert(stage.clone(), name);
        }
        let live: BTreeSet<&String> = names.values().collect();
        let retired = previous.state_files.values().filter(|n| !live.contains(n)).cloned().collect();
        let root = Root { version: LOCK_FORMAT, pipeline: self.pipeline.clone(), stages: names };
        let mut bytes = HEADER.as_bytes().to_vec();
        bytes.extend(serde_yaml::to_string(&root)?.into_bytes());
        Ok(NewState { root: bytes, files, retired })
    }
}

/// Reads the lockfile at `path` and the state files of the `wanted` stages (all: None) through
/// `read`, counting what it reads. The state files are read and parsed in parallel (at 10⁴
/// tests a no-op run's largest read); the first error, in the stages' order, is the one told.
fn read_with(
    path: &Path,
    wanted: Option<&BTreeSet<String>>,
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
        Some(v) if v == u64::from(LOCK_FORMAT) => {}
        _ => {
            let version = value.get("version").map_or("none".into(), |v| format!("{v:?}"));
            return Err(UserError::new(format!("lockfile format {version} is not supported"))
                .in_file(path)
                .hint(RECOMPUTE));
        }
    }
    let root: Root = serde_yaml::from_value(value).map_err(yaml)?;
    if let Some((stage, file)) = root.stages.iter().find(|(stage, file)| !is_state_file_name(stage, file)) {
        return Err(damaged(format!("`{file}` is not the name of stage `{stage}`'s state file"), None));
    }
    let dir = state_dir(path);
    let mut lock = LockFile { version: LOCK_FORMAT, pipeline: root.pipeline, ..LockFile::default() };
    let (read_now, later): (Vec<(String, String)>, Vec<(String, String)>) =
        root.stages.into_iter().partition(|(stage, _)| wanted.is_none_or(|w| w.contains(stage)));
    lock.partial = !later.is_empty();
    lock.state_files.extend(later);
    let entries: Vec<Result<(StageLock, u64), UserError>> = read_now
        .par_iter()
        .map(|(stage, file)| {
            let state = dir.join(file);
            let unreadable = |what: String| {
                UserError::new(format!("the state of stage `{stage}` {what}"))
                    .in_file(&state)
                    .hint(format!("delete `{}` to recompute every stage", path.display()))
            };
            let bytes = read(&state).map_err(|e| unreadable(format!("cannot be read: {e}")))?;
            if state_file_name(stage, &bytes) != *file {
                return Err(unreadable("is damaged: its content does not match its name".into()));
            }
            let entry = serde_json::from_slice(&bytes).map_err(|e| unreadable(format!("is damaged: {e}")))?;
            Ok((entry, bytes.len() as u64))
        })
        .collect();
    for ((stage, file), entry) in read_now.into_iter().zip(entries) {
        let (entry, bytes) = entry?;
        count.files += 1;
        count.bytes += bytes;
        lock.stages.insert(stage.clone(), entry);
        lock.state_files.insert(stage, file);
    }
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
        let wanted = BTreeSet::from(["load".to_string(), "baseline".to_string()]);
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
            + size(&some.state_files["load"])
            + size(&some.state_files["baseline"]);
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
        assert_eq!(new.retired, [before.state_files["s07"].clone()]);
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
        assert_eq!(new.retired, [read.state_files["s49"].clone()]);
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
            assert_eq!(*name, state_file_name(name.split('.').next().unwrap(), bytes));
        }
    }

    #[test]
    fn a_damaged_or_misnamed_state_is_an_error_never_dropped() {
        let dir = crate::tempdir::tempdir().unwrap();
        let path = dir.path().join("shakeflow.lock");
        install(&path, &state(&[("load", &["a"])]).encode(&LockFile::empty()).unwrap());
        let file = state_dir(&path).join(&LockFile::read(&path).unwrap().state_files["load"]);
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
        assert!(is_state_file_name("load", &name));
        assert!(!is_state_file_name("..", "...0123456789abcdef0123456789abcdef.json"));
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
        let (_, partly) = LockFile::read_stages(&path, &BTreeSet::from(["load".to_string()])).unwrap();
        assert_eq!(partly.files, 1, "format 2: the one file holds everything");
        let new = read.encode(&read).unwrap();
        assert_eq!(new.files.len(), 2, "every stage gets its file");
        assert!(new.retired.is_empty());
        install(&path, &new);
        let now = LockFile::read(&path).unwrap();
        assert_eq!(now.stages, old.stages);
        assert!(!now.is_older_format());
    }
}
