//! `shakeflow.lock`: what each stage last ran with and what it produced (after `dvc.lock`).

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::UserError;
use crate::io::atomic;

pub const LOCK_FILE: &str = "shakeflow.lock";
const LOCK_FORMAT: u32 = 1;

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
    /// blake3 of type, version, normalised params and input hashes: equal key, equal result.
    pub key: String,
    pub params: serde_json::Value,
    /// The stage's `select:` filter, when it has one.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub select: BTreeMap<String, Vec<String>>,
    pub inputs: BTreeMap<String, String>,
    pub outputs: BTreeMap<String, OutputLock>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputLock {
    pub path: String,
    pub hash: String,
    pub files: usize,
}

impl LockFile {
    /// A missing lockfile is an empty one; an unreadable one is an error (never silently dropped).
    pub fn read(path: &Path) -> Result<LockFile, UserError> {
        let text = match std::fs::read_to_string(path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Ok(LockFile { version: LOCK_FORMAT, pipeline: None, stages: BTreeMap::new() })
            }
            Err(e) => return Err(UserError::new(format!("cannot read the lockfile: {e}")).in_file(path)),
        };
        let lock: LockFile = serde_yaml::from_str(&text).map_err(|e| {
            UserError::new(format!("the lockfile is damaged: {e}"))
                .in_file(path)
                .at(e.location().map(|l| (l.line(), l.column())))
                .hint("delete it to recompute every stage")
        })?;
        if lock.version != LOCK_FORMAT {
            return Err(UserError::new(format!("lockfile format {} is not supported", lock.version))
                .in_file(path)
                .hint("delete it to recompute every stage"));
        }
        Ok(lock)
    }

    pub fn write(&self, path: &Path) -> anyhow::Result<()> {
        let body = serde_yaml::to_string(self)?;
        atomic::write_file_durable(path, |w| {
            use std::io::Write;
            w.write_all(b"# Written by `shakeflow run`; records what each stage ran with. Do not edit.\n")?;
            w.write_all(body.as_bytes())?;
            Ok(())
        })
    }
}
