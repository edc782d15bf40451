//! `shakeflow.lock`: what each work unit last ran with and what it wrote (after `dvc.lock`).
//!
//! A stage's entry holds its type, version and parameters, and one entry per work unit — a
//! record of a per-record stage (keyed by its partition, `motion=FB-4/floor=5`) or the one unit
//! of a gathering stage (keyed `*`): the unit's cache key, the content hashes of what it read,
//! and the files it wrote with their hashes. A record that could not be read by a source with
//! `on_error: skip` is an entry with no files and the reason it was flagged.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::UserError;
use crate::io::atomic;

const LOCK_FORMAT: u32 = 2;
/// The unit of a stage written by a shakeflow whose lockfile had no work units (format 1).
pub const FORMAT_1_UNIT: &str = "(format 1)";

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LockFile {
    pub version: u32,
    /// The pipeline file that owns the output folder, relative to it (`../pipelines/demo.yaml`):
    /// a second pipeline writing into the same folder is refused.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pipeline: Option<String>,
    pub stages: BTreeMap<String, StageLock>,
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

impl LockFile {
    pub fn empty() -> LockFile {
        LockFile { version: LOCK_FORMAT, pipeline: None, stages: BTreeMap::new() }
    }

    /// A missing lockfile is an empty one; an unreadable one is an error (never silently dropped).
    /// A format-1 lockfile (one entry per stage) reads as stages whose one unit owns every file
    /// in the stage's folder and is stale: the next run recomputes them and removes what it
    /// no longer writes.
    pub fn read(path: &Path) -> Result<LockFile, UserError> {
        let text = match std::fs::read_to_string(path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(LockFile::empty()),
            Err(e) => return Err(UserError::new(format!("cannot read the lockfile: {e}")).in_file(path)),
        };
        let damaged = |e: serde_yaml::Error| {
            UserError::new(format!("the lockfile is damaged: {e}"))
                .in_file(path)
                .at(e.location().map(|l| (l.line(), l.column())))
                .hint("delete it to recompute every stage")
        };
        let value: serde_yaml::Value = serde_yaml::from_str(&text).map_err(damaged)?;
        let version = value.get("version").and_then(serde_yaml::Value::as_u64);
        if version == Some(1) {
            let old: format1::LockFile = serde_yaml::from_value(value).map_err(damaged)?;
            return Ok(old.upgrade(path.parent().unwrap_or(Path::new("."))));
        }
        let lock: LockFile = serde_yaml::from_str(&text).map_err(damaged)?;
        if lock.version != LOCK_FORMAT {
            return Err(UserError::new(format!("lockfile format {} is not supported", lock.version))
                .in_file(path)
                .hint("delete it to recompute every stage"));
        }
        Ok(lock)
    }

    pub fn write(&self, path: &Path) -> anyhow::Result<()> {
        let body = serde_yaml::to_string(&LockFile { version: LOCK_FORMAT, ..self.clone() })?;
        atomic::write_file_durable(path, |w| {
            use std::io::Write;
            w.write_all(b"# Written by `shakeflow run`; records what each work unit ran with. Do not edit.\n")?;
            w.write_all(body.as_bytes())?;
            Ok(())
        })
    }
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
            super::LockFile { version: super::LOCK_FORMAT, pipeline: self.pipeline, stages }
        }
    }
}
