//! A plan of two stages (`load` of a CSV source, `baseline` of it) over sources given as hashes,
//! a lockfile made from assessments, and a disk given as a map: what the unit tests of `assess`
//! and `commit` run on, without a file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use super::assess::{assess_stage, AssessedStage, Disk, Known};
use super::inputs::ResolvedSource;
use super::Rerun;
use crate::pipeline::lock::{LockFile, StageLock, UnitLock};
use crate::pipeline::plan::Plan;
use crate::pipeline::spec::PipelineFile;
use crate::pipeline::stage::{InputPart, StageInput};

pub const PIPELINE: &str = "\
version: 1
output_dir: out
inputs:
  daq:
    format: csv
    path: archive/{motion}/daq.csv
    header_lines: 2
    time_column: Time
    unit: g
    columns:
      ax_mps2: EW
stages:
  load:
    type: load
    inputs: [daq]
  baseline:
    type: baseline
    inputs: [load]
    params:
      order: 3
";

/// The plan of `text`, its pipeline file in `dir`.
pub fn plan(dir: &Path, text: &str) -> Plan {
    let file = PipelineFile::parse(&dir.join("p.yaml"), text.to_string()).unwrap();
    Plan::new(file, crate::stages::registry()).unwrap()
}

/// The source `daq` of `plan` with one record file per (motion, content hash).
pub fn sources(plan: &Plan, records: &[(&str, &str)]) -> BTreeMap<String, ResolvedSource> {
    let files = records
        .iter()
        .map(|(motion, hash)| {
            let label = format!("archive/{motion}/daq.csv");
            InputPart {
                partition: vec![("motion".into(), motion.to_string())],
                path: plan.file.base_dir().join(&label),
                label,
                hash: hash.to_string(),
            }
        })
        .collect();
    let input = StageInput::Source {
        name: "daq".into(),
        spec: std::sync::Arc::new(plan.file.spec.inputs["daq"].clone()),
        base_dir: plan.file.base_dir(),
        files,
    };
    BTreeMap::from([("daq".to_string(), ResolvedSource { input })])
}

/// Files and their hashes now; the paths asked about are remembered.
#[derive(Default)]
pub struct FakeDisk {
    pub files: BTreeMap<PathBuf, String>,
    pub asked: Mutex<Vec<PathBuf>>,
}

impl Disk for FakeDisk {
    fn hash(&self, path: &Path) -> Option<String> {
        self.asked.lock().unwrap().push(path.to_path_buf());
        self.files.get(path).cloned()
    }

    fn exists(&self, path: &Path) -> bool {
        self.files.contains_key(path)
    }
}

/// `load` assessed against `lock` (nothing produced upstream: it reads sources only).
pub fn assess_load(
    plan: &Plan,
    sources: &BTreeMap<String, ResolvedSource>,
    lock: &LockFile,
    rerun: &Rerun,
    disk: &FakeDisk,
) -> AssessedStage {
    let files = BTreeMap::new();
    let known = Known { lock, sources, files: &files, rerun, disk };
    assess_stage(plan, &plan.stages["load"], &known, &BTreeMap::new()).unwrap()
}

/// The lockfile entry of `stage` after its units ran as assessed, each writing
/// `records/<unit>/data.parquet` with the hash `out:<unit>` (also put on `disk`).
pub fn entry_after(plan: &Plan, stage: &str, assessed: &AssessedStage, disk: &mut FakeDisk) -> StageLock {
    let planned = &plan.stages[stage];
    let units = assessed
        .units
        .iter()
        .map(|(unit, key, _)| {
            let file = format!("records/{}/data.parquet", unit.id);
            let hash = format!("out:{}", unit.id);
            disk.files.insert(plan.stage_dir(stage).join(&file), hash.clone());
            let files = BTreeMap::from([(file, hash)]);
            (
                unit.id.clone(),
                UnitLock { key: key.clone(), inputs: unit.hashes.clone(), files, flagged: None, notes: Vec::new() },
            )
        })
        .collect();
    StageLock {
        stage_type: planned.stage.info().name.to_string(),
        stage_version: planned.stage.info().version,
        params: serde_json::Value::Object(planned.params.clone()),
        select: planned.select.clone(),
        units,
    }
}
