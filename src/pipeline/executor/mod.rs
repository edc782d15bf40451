//! Running a plan in work units: decide per unit whether it is cached, run what is not (stages
//! in parallel where the DAG allows, units of a stage in parallel), and commit what finished.
//!
//! A unit is one record of a per-record stage or the whole of a gathering stage
//! (`units.rs`); each has its own cache key and lockfile entry, so a new motion recomputes its
//! own records and the gathers that read them. A run holds the output folder's lease
//! (`lease.rs`) and writes new outputs into a transaction that it commits with the new lockfile
//! in one step (`txn.rs`). A failed unit does not discard finished ones: they are committed, the
//! failed unit keeps its previous outputs and lockfile entry (stale), and what depends on it does
//! not run.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::anyhow;
use rayon::prelude::*;

pub mod slurm;

use super::lease::Lease;
use super::lock::{LockFile, StageLock, UnitLock, LOCK_FILE};
use super::memo::{TableMemo, DEFAULT_BUDGET_BYTES};
use super::ownership;
use super::plan::{InputRef, Plan, PlannedStage};
use super::progress::Reporter;
use super::sink::{OutputSink, DATA_FILE};
use super::sources;
use super::spec::{OnError, RecordFormat, SourceSpec};
use super::stage::{InputKind, InputPart, OutputKind, Partition, StageContext, StageInfo, StageInput, WorkUnits};
use super::txn::{self, Recovery, Transaction};
use super::units::{self, Unit, GATHER};
use crate::error::UserError;
use crate::io::hash;

/// The `load` output the engine writes for records skipped under `on_error: skip`.
pub const FLAGGED: &str = "flagged";
/// The lockfile unit that owns a stage's `flagged` table.
const FLAGGED_UNIT: &str = "(flagged)";
/// The `load` output the engine writes for every record: loaded, flagged, skipped or failed.
pub const STATUS: &str = "status";
/// The lockfile unit that owns a stage's `status` table.
const STATUS_UNIT: &str = "(status)";

/// Whether a lockfile unit is one of the engine's tables (`flagged`, `status`), not a record.
fn engine_unit(id: &str) -> bool {
    id == FLAGGED_UNIT || id == STATUS_UNIT
}
/// A hash standing for a file an upstream unit has yet to write (in `status` and `--dry-run`).
const PENDING: &str = "pending";

#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Stages to rerun even when cached (their dependents rerun too).
    pub force: Vec<String>,
    /// Run only these stages and what they need (all when empty).
    pub only: Vec<String>,
    /// After a failed unit, still run everything that does not depend on it.
    pub keep_going: bool,
    /// Commit nothing unless every unit succeeded: the output folder stays as it was (a
    /// command's one stage, as `shakeflow stage` always did).
    pub all_or_nothing: bool,
}

/// What a run reruns whatever the lockfile says.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Rerun {
    /// The `--force`d stages and every stage reading them.
    pub stages: BTreeSet<String>,
    /// Per `keep: false` stage, the units whose removed files a unit that runs needs → why.
    #[serde(default)]
    pub remake: BTreeMap<String, BTreeMap<String, String>>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    Cached,
    Ran {
        seconds: f64,
        records: usize,
    },
    /// Not run: an upstream unit failed, or the run stopped at a failure.
    Skipped,
}

#[derive(Debug, Clone)]
pub struct StageReport {
    pub name: String,
    pub outcome: Outcome,
    pub units: usize,
    pub ran: usize,
}

/// A unit that failed (or a record skipped by `on_error: skip`), and why.
#[derive(Debug, Clone)]
pub struct UnitProblem {
    pub stage: String,
    pub unit: String,
    pub reason: String,
}

#[derive(Debug, Default)]
pub struct RunSummary {
    pub reports: Vec<StageReport>,
    pub failed: Vec<UnitProblem>,
    pub flagged: Vec<UnitProblem>,
}

/// A source resolved to files.
struct ResolvedSource {
    input: StageInput,
}

/// A file a stage wrote (or will write): where it is now and its content hash.
#[derive(Clone)]
struct ProducedFile {
    path: PathBuf,
    hash: String,
}

/// A stage's files that downstream stages read this run, by path relative to the stage folder.
type Produced = BTreeMap<String, ProducedFile>;

pub fn lock_path(plan: &Plan) -> PathBuf {
    plan.file.output_dir().join(LOCK_FILE)
}

/// Where a run keeps the hashes of the files it read ([`hash::StatMemo`]): a no-op rerun then
/// reads no file whose size and times are unchanged.
pub const HASH_MEMO: &str = "hashes.json";

fn resolve_sources(plan: &Plan) -> Result<BTreeMap<String, ResolvedSource>, UserError> {
    hash::use_memo(&plan.file.output_dir().join(super::lease::STATE_DIR).join(HASH_MEMO));
    let base = plan.file.base_dir();
    let used: BTreeSet<&str> = plan
        .stages
        .values()
        .flat_map(|s| s.inputs.iter())
        .filter_map(|i| match i {
            InputRef::Source(name) => Some(name.as_str()),
            InputRef::Stage { .. } => None,
        })
        .collect();
    let mut resolved = BTreeMap::new();
    // Sources may share files (one DAQ export split into floors): each file is read once.
    let mut hashed: BTreeMap<PathBuf, String> = BTreeMap::new();
    for name in used {
        let spec = &plan.file.spec.inputs[name];
        let files = source_files(plan, name, spec)?;
        let unhashed: Vec<&Path> =
            files.iter().map(|f| f.path.as_path()).filter(|p| !hashed.contains_key(*p)).collect();
        let new_hashes: Vec<String> = unhashed
            .par_iter()
            .map(|p| hash::hash_path(p))
            .collect::<anyhow::Result<_>>()
            .map_err(|e| UserError::new(format!("source `{name}`: {e:#}")))?;
        hashed.extend(unhashed.into_iter().map(Path::to_path_buf).zip(new_hashes));
        let parts: Vec<InputPart> = files
            .into_iter()
            .map(|f| {
                let relative = f.path.strip_prefix(&base).unwrap_or(&f.path).to_string_lossy().replace('\\', "/");
                let hash = hashed[&f.path].clone();
                InputPart { partition: f.partition, path: f.path, label: relative, hash }
            })
            .collect();
        let input = match spec.format {
            RecordFormat::Dataset => StageInput::Dataset { name: name.to_string(), parts },
            _ => {
                StageInput::Source { name: name.to_string(), spec: spec.clone(), base_dir: base.clone(), files: parts }
            }
        };
        resolved.insert(name.to_string(), ResolvedSource { input });
    }
    Ok(resolved)
}

/// The files a source reads, with their partitions: its path matched as a pattern (a command's
/// names one file or folder literally); a case is its folder, a dataset folder its parts.
fn source_files(plan: &Plan, name: &str, spec: &SourceSpec) -> Result<Vec<sources::MatchedFile>, UserError> {
    let base = plan.file.base_dir();
    let files = match plan.file.command {
        Some(_) => {
            let path = if base == Path::new(".") { PathBuf::from(&spec.path) } else { base.join(&spec.path) };
            if !(path.is_file() || spec.format.names_folders() && path.is_dir()) {
                let what = if path.is_dir() { "is a folder, not a file" } else { "does not exist" };
                return Err(UserError::new(format!("the input `{}` {what}", path.display())).in_file(&path));
            }
            let partition = spec.partition.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
            vec![sources::MatchedFile { path, partition }]
        }
        None => sources::resolve(&base, &spec.path, &spec.partition, spec.format.names_folders()).map_err(|e| {
            let located = plan.file.error_at(&["inputs", name, "path"], format!("source `{name}`: {}", e.message));
            match e.hint {
                Some(h) => located.hint(h),
                None => located,
            }
        })?,
    };
    let files = match &spec.components {
        Some(c) => sources::group_components(&spec.path, files, &c.key).map_err(|e| {
            let located =
                plan.file.error_at(&["inputs", name, "components"], format!("source `{name}`: {}", e.message));
            located.hint(e.hint.unwrap_or_default())
        })?,
        None => files,
    };
    let mut expanded = Vec::new();
    for file in files {
        match spec.format {
            // A case source names each case by its equipment.yaml; the case is the whole folder.
            RecordFormat::Case => expanded.push(sources::MatchedFile {
                path: file.path.parent().map(Path::to_path_buf).unwrap_or(file.path),
                ..file
            }),
            RecordFormat::Dataset if file.path.is_dir() => {
                let parts: Vec<String> = hash::list_files(&file.path)
                    .map_err(|e| UserError::new(format!("source `{name}`: {e:#}")).in_file(&file.path))?
                    .into_iter()
                    .filter(|f| f == DATA_FILE || f.ends_with(&format!("/{DATA_FILE}")))
                    .collect();
                if parts.is_empty() {
                    return Err(UserError::new(format!("source `{name}`: the folder holds no `{DATA_FILE}`"))
                        .in_file(&file.path)
                        .hint("a dataset folder is a stage's output (`<stage>/<output>`), its tables in `key=value/…/data.parquet`"));
                }
                for part in parts {
                    let mut partition = file.partition.clone();
                    partition.extend(partition_of(&part));
                    expanded.push(sources::MatchedFile { path: file.path.join(part), partition });
                }
            }
            _ => expanded.push(file),
        }
    }
    expanded.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(expanded)
}

/// Why every unit of a stage is stale, whatever its inputs: its type, version, params or select changed.
fn stage_reasons(stage: &PlannedStage, entry: Option<&StageLock>) -> Vec<String> {
    let info = stage.stage.info();
    let Some(entry) = entry else { return vec!["never run (not in the lockfile)".into()] };
    let mut reasons = Vec::new();
    if entry.stage_type != info.name {
        reasons.push(format!("stage type changed: {} → {}", entry.stage_type, info.name));
    } else if entry.stage_version != info.version {
        reasons.push(format!("stage type `{}` changed: version {} → {}", info.name, entry.stage_version, info.version));
    }
    let params = serde_json::Value::Object(stage.params.clone());
    if entry.params != params {
        reasons.push(format!("params changed: {}", describe_param_changes(&entry.params, &params)));
    }
    if entry.select != stage.select {
        reasons.push(format!("select changed: {:?} → {:?}", entry.select, stage.select));
    }
    reasons
}

/// Why one unit is stale (empty: up to date), given its stage's entry and reasons.
/// The files of a `keep: false` stage may be gone: only a file changed on disk makes it stale.
fn unit_reasons(
    unit: &Unit,
    key: &str,
    entry: Option<&StageLock>,
    stage_dir: &Path,
    keep: bool,
) -> anyhow::Result<Vec<String>> {
    if unit.hashes.values().any(|h| h == PENDING) {
        return Ok(vec!["an upstream unit will rerun".into()]);
    }
    let Some(old) = entry.and_then(|e| e.units.get(&unit.id)) else {
        let what = if unit.id == GATHER { "never run" } else { "new record" };
        return Ok(vec![what.into()]);
    };
    let mut reasons = Vec::new();
    for (name, hash) in &unit.hashes {
        match old.inputs.get(name) {
            None => reasons.push(format!("new input `{name}`")),
            Some(was) if was != hash => reasons.push(format!("input `{name}` changed")),
            Some(_) => {}
        }
    }
    for name in old.inputs.keys().filter(|n| !unit.hashes.contains_key(*n)) {
        reasons.push(format!("input `{name}` removed"));
    }
    if reasons.is_empty() && old.key != key {
        reasons.push("cache key changed".into());
    }
    for (file, hash) in &old.files {
        match hash::hash_file(&stage_dir.join(file)) {
            Err(_) if !keep => {}
            Err(_) => reasons.push(format!("output file `{file}` missing")),
            Ok(now) if now != *hash => reasons.push(format!("output file `{file}` was modified on disk")),
            Ok(_) => {}
        }
    }
    Ok(reasons)
}

fn describe_param_changes(old: &serde_json::Value, new: &serde_json::Value) -> String {
    let empty = serde_json::Map::new();
    let old = old.as_object().unwrap_or(&empty);
    let new = new.as_object().unwrap_or(&empty);
    let keys: BTreeSet<&String> = old.keys().chain(new.keys()).collect();
    let show = |v: Option<&serde_json::Value>| v.map_or("(none)".to_string(), |v| v.to_string());
    keys.into_iter()
        .filter(|k| old.get(*k) != new.get(*k))
        .map(|k| format!("{k} {} → {}", show(old.get(k)), show(new.get(k))))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Per stage, the content hashes of the files its `Path` parameters name, keyed
/// `params.<name> (<path as written>)`: editing such a file reruns the stage.
fn param_file_hashes(plan: &Plan) -> Result<BTreeMap<String, BTreeMap<String, String>>, UserError> {
    plan.stages
        .values()
        .map(|stage| {
            let hashes = stage
                .files
                .iter()
                .map(|(name, path)| {
                    let written = stage.params[name].as_str().unwrap_or_default();
                    let hash = hash::hash_file(path)
                        .map_err(|e| plan.file.error_at(&["stages", &stage.name, "params", name], format!("{e:#}")))?;
                    Ok((format!("params.{name} ({written})"), hash))
                })
                .collect::<Result<_, UserError>>()?;
            Ok((stage.name.clone(), hashes))
        })
        .collect()
}

/// A stage's inputs this run: its sources' files, and the parts upstream stages produced.
fn stage_inputs(
    plan: &Plan,
    stage: &PlannedStage,
    sources: &BTreeMap<String, ResolvedSource>,
    produced: &BTreeMap<String, Produced>,
) -> anyhow::Result<Vec<StageInput>> {
    let mut inputs: Vec<StageInput> = stage
        .inputs
        .iter()
        .map(|input| match input {
            InputRef::Source(name) => sources[name].input.clone(),
            InputRef::Stage { stage: upstream, output } => {
                let files = produced.get(upstream).map(|p| dataset_of(p, output, &input.label())).unwrap_or_default();
                StageInput::Dataset { name: input.label(), parts: files }
            }
        })
        .collect();
    check_select(plan, stage, &inputs)?;
    for input in &mut inputs {
        match input {
            StageInput::Source { files, .. } => files.retain(|f| stage.selects(&f.partition)),
            StageInput::Dataset { parts, .. } => parts.retain(|p| stage.selects(&p.partition)),
        }
    }
    Ok(inputs)
}

/// The Parquet parts of one output among a stage's produced files.
fn dataset_of(produced: &Produced, output: &str, label: &str) -> Vec<InputPart> {
    let prefix = format!("{output}/");
    produced
        .iter()
        .filter_map(|(relative, file)| {
            let inner = relative.strip_prefix(&prefix)?;
            if inner != DATA_FILE && !inner.ends_with(&format!("/{DATA_FILE}")) {
                return None;
            }
            Some(InputPart {
                partition: partition_of(inner),
                path: file.path.clone(),
                label: format!("{label}/{inner}"),
                hash: file.hash.clone(),
            })
        })
        .collect()
}

fn partition_of(relative: &str) -> Partition {
    relative
        .split('/')
        .filter_map(|segment| segment.split_once('='))
        .map(|(k, v)| (super::paths::decode_component(k), super::paths::decode_component(v)))
        .collect()
}

/// A `select:` key or value that no record of the stage's inputs has is a typo, not a wish for
/// an empty selection.
fn check_select(plan: &Plan, stage: &PlannedStage, inputs: &[StageInput]) -> Result<(), UserError> {
    let partitions: Vec<&(String, String)> = inputs.iter().flat_map(|i| i.parts()).flat_map(|p| &p.partition).collect();
    if partitions.is_empty() {
        return Ok(()); // nothing upstream succeeded (or will): nothing to check against
    }
    for (key, values) in &stage.select {
        let refuse = |message: String, wanted: &str, known: &BTreeSet<&str>, what: &str| {
            let suggestion = crate::error::did_you_mean_hint(wanted, known.iter().copied());
            let known: Vec<&str> = known.iter().copied().collect();
            UserError::new(message)
                .in_file(&plan.file.path)
                .at(super::locate::key_position(&plan.file.text, &["stages", &stage.name, "select", key]))
                .hint(format!("{suggestion}{what}: {}", known.join(", ")))
        };
        let seen: BTreeSet<&str> = partitions.iter().filter(|(k, _)| k == key).map(|(_, v)| v.as_str()).collect();
        if seen.is_empty() {
            let keys: BTreeSet<&str> = partitions.iter().map(|(k, _)| k.as_str()).collect();
            let message =
                format!("stage `{}` selects by `{key}`, but no record of its inputs has that key", stage.name);
            return Err(refuse(message, key, &keys, "the inputs' partition keys"));
        }
        if let Some(value) = values.iter().find(|v| !seen.contains(v.as_str())) {
            let message =
                format!("stage `{}` selects {key} = `{value}`, but no record of its inputs has it", stage.name);
            return Err(refuse(message, value, &seen, &format!("values of `{key}`")));
        }
    }
    Ok(())
}

/// The files a cached unit wrote, where they are.
fn cached_files(old: &UnitLock, stage_dir: &Path) -> Produced {
    old.files.iter().map(|(f, h)| (f.clone(), ProducedFile { path: stage_dir.join(f), hash: h.clone() })).collect()
}

/// What a stale unit will write, as far as can be told before it runs: the files it wrote last
/// time, else one table per output at its record's partition. Their hash is [`PENDING`].
fn pending_files(stage: &PlannedStage, unit: &Unit, old: Option<&UnitLock>) -> Produced {
    let pending = |f: String| (f, ProducedFile { path: PathBuf::new(), hash: PENDING.into() });
    if let Some(old) = old.filter(|o| !o.files.is_empty()) {
        return old.files.keys().cloned().map(pending).collect();
    }
    let partition = if unit.id == GATHER { "" } else { unit.id.as_str() };
    stage
        .stage
        .info()
        .outputs
        .iter()
        .filter(|o| {
            matches!(o.kind, OutputKind::Table | OutputKind::TimeSeries) && o.name != FLAGGED && o.name != STATUS
        })
        .map(|o| {
            let inner = if partition.is_empty() { DATA_FILE.to_string() } else { format!("{partition}/{DATA_FILE}") };
            pending(format!("{}/{inner}", o.name))
        })
        .collect()
}

pub struct UnitStatus {
    pub id: String,
    pub reasons: Vec<String>,
}

pub struct StatusLine {
    pub name: String,
    pub stage_type: &'static str,
    /// Units of the stage now (records, or one for a gathering stage).
    pub units: usize,
    /// Their ids, in order.
    pub ids: Vec<String>,
    /// The stale ones, with why.
    pub stale: Vec<UnitStatus>,
    /// Units in the lockfile whose record is gone; their outputs go at the next complete run.
    pub vanished: Vec<String>,
    /// Records skipped by `on_error: skip`, with why.
    pub flagged: Vec<UnitStatus>,
    /// `keep: false`: its files go once the stages reading them are up to date.
    pub keep: bool,
}

impl StatusLine {
    pub fn is_stale(&self) -> bool {
        !self.stale.is_empty() || !self.vanished.is_empty()
    }

    /// One line's worth: the reasons all stale units share, else a count and the first few.
    pub fn summary(&self) -> String {
        let mut parts = Vec::new();
        if !self.stale.is_empty() {
            let first = &self.stale[0].reasons;
            if self.stale.len() == self.units && self.stale.iter().all(|u| &u.reasons == first) {
                parts.push(first.join("; "));
            } else {
                let shown: Vec<String> = self
                    .stale
                    .iter()
                    .take(3)
                    .map(|u| format!("{}: {}", units::describe(&u.id), u.reasons.join("; ")))
                    .collect();
                let more =
                    if self.stale.len() > 3 { format!("; and {} more", self.stale.len() - 3) } else { String::new() };
                parts.push(format!("{} of {} records: {}{more}", self.stale.len(), self.units, shown.join(" | ")));
            }
        }
        if !self.vanished.is_empty() {
            parts.push(format!("{} record(s) gone from its inputs: {}", self.vanished.len(), self.vanished.join(", ")));
        }
        parts.join("; ")
    }
}

/// What `run` would do, and why, without running anything; `notes` are what the user should
/// know besides (a run in progress, an interrupted commit completed, orphaned folders).
pub fn status(plan: &Plan, notes: &mut Vec<String>) -> Result<Vec<StatusLine>, UserError> {
    let output_dir = plan.file.output_dir();
    // A lease or an unfinished commit, not merely the hash memo or finished Slurm runs' folders:
    // `status` takes the lease only then, so a run starting meanwhile is not refused.
    let in_progress = std::fs::read_dir(output_dir.join(super::lease::STATE_DIR))
        .map(|d| d.flatten().any(|e| e.file_name() != HASH_MEMO && e.file_name() != slurm::RUNS_DIR))
        .unwrap_or(false);
    if in_progress {
        // An interrupted commit is completed first, so the answer is about what is on disk now;
        // while a run holds the folder, the committed state is reported as it stands.
        match Lease::acquire(&output_dir) {
            Ok(lease) => {
                let recovery = txn::recover(&lease).map_err(|e| UserError::new(format!("{e:#}")))?;
                if recovery.completed > 0 {
                    notes.push(format!("completed {} commit(s) of an interrupted run", recovery.completed));
                }
                if recovery.discarded > 0 {
                    notes.push(format!("removed {} unfinished attempt(s) of an interrupted run", recovery.discarded));
                }
            }
            Err(busy) => notes.push(format!("{}; reporting the last committed state", busy.message)),
        }
    }
    let lock = LockFile::read(&output_dir.join(LOCK_FILE))?;
    ownership::check_pipeline(&plan.file, &lock)?;
    let stages: Vec<&str> = plan.stages.keys().map(String::as_str).collect();
    for orphan in ownership::orphaned_stage_folders(&output_dir, &stages) {
        notes.push(format!(
            "`{}` holds the outputs of stage `{orphan}`, which the pipeline no longer has (`shakeflow gc` removes it)",
            output_dir.join(&orphan).display()
        ));
    }
    let sources = resolve_sources(plan)?;
    let files = param_file_hashes(plan)?;
    Ok(predict(plan, &lock, &sources, &files, &Rerun::default())?.lines)
}

/// What a run would do: each stage's status line, and the units of `keep: false` stages it
/// makes again because a unit that runs reads their removed files.
pub struct Prediction {
    pub lines: Vec<StatusLine>,
    pub remake: BTreeMap<String, BTreeMap<String, String>>,
}

/// Each stage's units and which would run, and why: upstream units that would run stand for
/// the files they wrote last time (or one table per output at their partition), with a
/// [`PENDING`] hash. A unit of a `keep: false` stage whose files are gone but that a stale unit
/// reads is made again: it stands for its recorded hashes (it writes the same bytes).
fn predict(
    plan: &Plan,
    lock: &LockFile,
    sources: &BTreeMap<String, ResolvedSource>,
    files: &BTreeMap<String, BTreeMap<String, String>>,
    rerun: &Rerun,
) -> Result<Prediction, UserError> {
    let mut produced: BTreeMap<String, Produced> = BTreeMap::new();
    let mut lines = Vec::new();
    // Removed files of up-to-date `keep: false` units → (stage, unit); and, in run order, the
    // units reading some of them: (stage, unit, stale, the units whose files it reads).
    let mut removed: BTreeMap<PathBuf, (String, String)> = BTreeMap::new();
    let mut readers: Vec<(String, String, bool, BTreeSet<(String, String)>)> = Vec::new();
    let error = |e: anyhow::Error| match e.downcast::<UserError>() {
        Ok(user) => user,
        Err(e) => UserError::new(format!("{e:#}")),
    };
    for stage in plan.stages.values() {
        let assessed = assess_stage(plan, stage, sources, &produced, files, lock, rerun).map_err(error)?;
        let stage_dir = plan.stage_dir(&stage.name);
        let entry = lock.stages.get(&stage.name);
        let mut mine = Produced::new();
        let mut line = StatusLine {
            name: stage.name.clone(),
            stage_type: stage.stage.info().name,
            units: assessed.units.len(),
            ids: assessed.units.iter().map(|(u, _, _)| u.id.clone()).collect(),
            stale: Vec::new(),
            vanished: assessed.vanished.clone(),
            flagged: Vec::new(),
            keep: stage.keep,
        };
        for (unit, _, reasons) in &assessed.units {
            let old = entry.and_then(|e| e.units.get(&unit.id));
            let reads: BTreeSet<(String, String)> =
                unit.inputs.iter().flat_map(|i| i.parts()).filter_map(|p| removed.get(&p.path).cloned()).collect();
            if !reads.is_empty() {
                readers.push((stage.name.clone(), unit.id.clone(), !reasons.is_empty(), reads));
            }
            if reasons.is_empty() {
                if let Some(old) = old {
                    let cached = cached_files(old, &stage_dir);
                    if !stage.keep {
                        for file in cached.values().filter(|f| !f.path.exists()) {
                            removed.insert(file.path.clone(), (stage.name.clone(), unit.id.clone()));
                        }
                    }
                    mine.extend(cached);
                    if let Some(why) = &old.flagged {
                        line.flagged.push(UnitStatus { id: unit.id.clone(), reasons: vec![why.clone()] });
                    }
                }
            } else {
                mine.extend(pending_files(stage, unit, old));
                line.stale.push(UnitStatus { id: unit.id.clone(), reasons: reasons.clone() });
            }
        }
        produced.insert(stage.name.clone(), mine);
        lines.push(line);
    }
    // Readers come after what they read: walking back, a unit made again marks what it reads.
    let mut remake: BTreeMap<String, BTreeMap<String, String>> = BTreeMap::new();
    for (stage, unit, stale, reads) in readers.into_iter().rev() {
        let needed = stale || remake.get(&stage).is_some_and(|u| u.contains_key(&unit));
        if !needed {
            continue;
        }
        for (up, id) in reads {
            let why = format!("made again: its files were not kept (`keep: false`) and `{stage}` reads them");
            remake.entry(up).or_default().entry(id).or_insert(why);
        }
    }
    for line in &mut lines {
        let Some(remade) = remake.get(&line.name) else { continue };
        for (id, why) in remade {
            line.stale.push(UnitStatus { id: id.clone(), reasons: vec![why.clone()] });
        }
        let order: BTreeMap<&str, usize> = line.ids.iter().enumerate().map(|(i, id)| (id.as_str(), i)).collect();
        line.stale.sort_by_key(|u| order.get(u.id.as_str()).copied().unwrap_or(usize::MAX));
    }
    Ok(Prediction { lines, remake })
}

/// A stage split into units, each with its cache key and why it is stale (empty: cached).
struct AssessedStage {
    units: Vec<(Unit, String, Vec<String>)>,
    /// Unit ids in the lockfile that no record of the inputs has now.
    vanished: Vec<String>,
}

#[allow(clippy::too_many_arguments)]
fn assess_stage(
    plan: &Plan,
    stage: &PlannedStage,
    sources: &BTreeMap<String, ResolvedSource>,
    produced: &BTreeMap<String, Produced>,
    files: &BTreeMap<String, BTreeMap<String, String>>,
    lock: &LockFile,
    rerun: &Rerun,
) -> anyhow::Result<AssessedStage> {
    let inputs = stage_inputs(plan, stage, sources, produced)?;
    let split = units::split(stage, &inputs, files.get(&stage.name).unwrap_or(&BTreeMap::new()))?;
    let entry = lock.stages.get(&stage.name);
    let common = stage_reasons(stage, entry);
    let stage_dir = plan.stage_dir(&stage.name);
    let forced = rerun.stages.contains(&stage.name);
    let remake = rerun.remake.get(&stage.name);
    let units = split
        .into_par_iter()
        .map(|unit| {
            let key = unit.key(stage);
            let mut reasons = common.clone();
            if forced {
                reasons.push("forced".into());
            }
            let own = unit_reasons(&unit, &key, entry, &stage_dir, stage.keep)?;
            reasons.extend(own.into_iter().filter(|r| common.is_empty() || !r.starts_with("new record")));
            if let Some(why) = remake.and_then(|r| r.get(&unit.id)).filter(|_| reasons.is_empty()) {
                reasons.push(why.clone());
            }
            Ok((unit, key, reasons))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let ids: BTreeSet<&str> = units.iter().map(|(u, _, _)| u.id.as_str()).collect();
    let vanished = entry
        .map(|e| e.units.keys().filter(|id| !engine_unit(id) && !ids.contains(id.as_str())).cloned().collect())
        .unwrap_or_default();
    Ok(AssessedStage { units, vanished })
}

/// `shakeflow run --dry-run`: the units that would run, and why.
pub fn dry_run(plan: &Plan, options: &RunOptions) -> Result<Vec<StatusLine>, UserError> {
    let selected = selected_stages(plan, options)?;
    let rerun = Rerun { stages: forced_stages(plan, &options.force), remake: BTreeMap::new() };
    let lock = LockFile::read(&lock_path(plan))?;
    let lines = predict(plan, &lock, &resolve_sources(plan)?, &param_file_hashes(plan)?, &rerun)?.lines;
    Ok(lines.into_iter().filter(|l| selected.contains(&l.name)).collect())
}

/// The stages `--force` reruns: the named ones and everything downstream of them.
fn forced_stages(plan: &Plan, force: &[String]) -> BTreeSet<String> {
    force.iter().flat_map(|n| plan.with_dependents(n)).collect()
}

/// The stages a run covers: the named ones and what they need, or all.
fn selected_stages(plan: &Plan, options: &RunOptions) -> Result<BTreeSet<String>, UserError> {
    let known: Vec<&str> = plan.stages.keys().map(String::as_str).collect();
    for (flag, name) in options.force.iter().map(|n| ("--force ", n)).chain(options.only.iter().map(|n| ("", n))) {
        if !plan.stages.contains_key(name) {
            let suggestion = crate::error::did_you_mean_hint(name, known.iter().copied());
            return Err(UserError::new(format!("`{flag}{name}`: no stage of that name in this pipeline"))
                .in_file(&plan.file.path)
                .hint(format!("{suggestion}stages: {}", known.join(", "))));
        }
    }
    if options.only.is_empty() {
        return Ok(plan.stages.keys().cloned().collect());
    }
    Ok(plan.with_upstream(options.only.iter().map(String::as_str)))
}

pub fn run(plan: &Plan, options: &RunOptions, reporter: &Reporter) -> anyhow::Result<RunSummary> {
    let selected = selected_stages(plan, options)?;
    let sources = resolve_sources(plan)?;
    let files = param_file_hashes(plan)?;
    let (lease, lock) = take_output_folder(plan, &sources, reporter)?;
    let mut rerun = Rerun { stages: forced_stages(plan, &options.force), remake: BTreeMap::new() };
    if plan.stages.values().any(|s| !s.keep) {
        rerun.remake = predict(plan, &lock, &sources, &files, &rerun)?.remake;
    }
    let transaction = Transaction::begin(&lease)?;
    let env = RunEnv {
        plan,
        selected: &selected,
        rerun: &rerun,
        keep_going: options.keep_going,
        lock: &lock,
        sources: &sources,
        files: &files,
        transaction: &transaction,
        reporter,
        state: Mutex::new(RunState::default()),
        memo: Arc::new(TableMemo::new(DEFAULT_BUDGET_BYTES)),
    };
    let outcome = run_stages(&env);
    let state = env.state.into_inner().map_err(|_| anyhow!("a stage panicked"));
    let (mut state, fatal) = match (state, outcome) {
        (Ok(state), Ok(())) => (state, None),
        (Ok(state), Err(e)) => (state, Some(e)),
        (Err(e), _) => {
            transaction.abort();
            return Err(e);
        }
    };
    leave_out_not_kept(plan, &selected, &state.tainted, &state.entries, &mut state.install, &mut state.remove);
    if let Some(error) = fatal {
        // A stage could not be planned (a bad select, two records with one partition): what
        // finished before it is still committed below only when nothing is in doubt.
        if state.install.is_empty() || options.all_or_nothing {
            transaction.abort();
            return Err(error);
        }
        commit(transaction, &state, plan, &lock)?;
        return Err(error.context("the units that finished before it were committed"));
    }
    if options.all_or_nothing && !state.failed.is_empty() {
        transaction.abort();
        let reports = plan.stages.keys().filter_map(|n| state.reports.get(n).cloned()).collect();
        return Ok(RunSummary { reports, failed: state.failed, flagged: state.flagged });
    }
    commit(transaction, &state, plan, &lock)?;
    // Under the lease still: only the run holding the folder writes the memo. The files this run
    // wrote go in too (their hashes came from the bytes written), those written 2 s ago or more.
    for (name, entry) in &state.entries {
        for (file, hash) in entry.units.values().flat_map(|u| u.files.iter()) {
            hash::remember(&plan.stage_dir(name).join(file), hash);
        }
    }
    if let Err(e) = hash::save_memo() {
        reporter.line(&format!("warning: the hash memo was not saved ({e:#}); the next run reads every file"));
    }
    let reports = plan.stages.keys().filter_map(|n| state.reports.get(n).cloned()).collect();
    Ok(RunSummary { reports, failed: state.failed, flagged: state.flagged })
}

/// Before a run writes anything: the output folder checked and created, its lease taken, an
/// interrupted commit finished, and its lockfile read and checked against the pipeline.
fn take_output_folder(
    plan: &Plan,
    sources: &BTreeMap<String, ResolvedSource>,
    reporter: &Reporter,
) -> anyhow::Result<(Lease, LockFile)> {
    let output_dir = plan.file.output_dir();
    ownership::check_output_dir(&plan.file, &input_paths(plan, sources))?;
    std::fs::create_dir_all(&output_dir).map_err(|e| {
        plan.file
            .error_at(&["output_dir"], format!("cannot create the output directory `{}`: {e}", output_dir.display()))
            .hint("choose a writable `output_dir` (relative to the pipeline file)")
    })?;
    let lease = Lease::acquire(&output_dir)?;
    if let Some(holder) = &lease.took_over {
        reporter.line(&format!(
            "took over the lease of an earlier run that is gone (pid {} on `{}`, started {})",
            holder.pid,
            holder.host,
            super::lease::format_utc(holder.started)
        ));
    }
    let recovery = txn::recover(&lease)?;
    if recovery != Recovery::default() {
        reporter.line(&format!(
            "an interrupted run: {} commit(s) completed, {} unfinished attempt(s) removed",
            recovery.completed, recovery.discarded
        ));
    }
    let lock = LockFile::read(&output_dir.join(LOCK_FILE))?;
    ownership::check_pipeline(&plan.file, &lock)?;
    ownership::check_stage_folders(plan, &lock)?;
    Ok((lease, lock))
}

/// Takes the files of `keep: false` stages out of a commit's `install` and puts those on disk in
/// its `remove` (paths relative to the output folder): the files of every such stage that ran in
/// full, as did every stage reading it (cached counts: it is up to date with them). Their
/// lockfile entries stay, hashes and all.
fn leave_out_not_kept(
    plan: &Plan,
    selected: &BTreeSet<String>,
    tainted: &BTreeSet<String>,
    entries: &BTreeMap<String, StageLock>,
    install: &mut BTreeSet<String>,
    remove: &mut BTreeSet<String>,
) {
    let done = |name: &str| selected.contains(name) && !tainted.contains(name);
    let not_kept = plan
        .stages
        .values()
        .filter(|s| !s.keep && done(&s.name))
        .filter(|s| {
            plan.stages.values().filter(|r| upstream_stages(r).contains(s.name.as_str())).all(|r| done(&r.name))
        })
        .filter_map(|s| entries.get(&s.name).map(|entry| (s, entry)))
        .flat_map(|(s, entry)| {
            entry
                .units
                .iter()
                .filter(|(id, _)| !engine_unit(id))
                .flat_map(|(_, unit)| unit.files.keys().map(|file| plan.stage_entry(&s.name, file)))
        });
    let output_dir = plan.file.output_dir();
    for path in not_kept {
        install.remove(&path);
        if output_dir.join(&path).exists() {
            remove.insert(path);
        }
    }
}

fn commit(transaction: Transaction, state: &RunState, plan: &Plan, lock: &LockFile) -> anyhow::Result<()> {
    let mut stages = lock.stages.clone();
    // Stages the pipeline no longer has keep their entries until `gc` removes their folders.
    stages.extend(state.entries.clone());
    let new_lock = LockFile { version: lock.version, pipeline: Some(ownership::pipeline_label(&plan.file)), stages };
    // Nothing to install or remove (everything cached, or every unit that ran failed): the
    // folder and its lockfile stay exactly as they were.
    if state.install.is_empty() && state.remove.is_empty() {
        transaction.abort();
        return Ok(());
    }
    let install: Vec<String> = state.install.iter().cloned().collect();
    let remove: Vec<String> = state.remove.difference(&state.install).cloned().collect();
    transaction.commit(&install, &remove, Some(&new_lock))
}

/// `shakeflow gc`: removes (in one commit, under the lease) the stage folders shakeflow wrote for
/// stages the pipeline no longer has; returns each with its size in bytes. Nothing else is
/// touched: a folder without shakeflow's marker is never an orphan.
pub fn gc(plan: &Plan, dry_run: bool) -> anyhow::Result<Vec<(String, u64)>> {
    let output_dir = plan.file.output_dir();
    if !output_dir.is_dir() {
        return Ok(Vec::new());
    }
    let lease = Lease::acquire(&output_dir)?;
    txn::recover(&lease)?;
    let lock = LockFile::read(&output_dir.join(LOCK_FILE))?;
    ownership::check_pipeline(&plan.file, &lock)?;
    let stages: Vec<&str> = plan.stages.keys().map(String::as_str).collect();
    let orphans = ownership::orphaned_stage_folders(&output_dir, &stages);
    let sized: Vec<(String, u64)> =
        orphans.iter().map(|o| (o.clone(), hash::tree_bytes(&output_dir.join(o)))).collect();
    if !dry_run && !orphans.is_empty() {
        let mut new_lock = lock.clone();
        for orphan in &orphans {
            new_lock.stages.remove(orphan);
        }
        Transaction::begin(&lease)?.commit(&[], &orphans, Some(&new_lock))?;
    }
    Ok(sized)
}

/// Every file a run reads: record files and files named by parameters.
fn input_paths(plan: &Plan, sources: &BTreeMap<String, ResolvedSource>) -> Vec<PathBuf> {
    let records = sources.values().flat_map(|s| s.input.parts().iter().map(|p| p.path.clone()));
    let params = plan.stages.values().flat_map(|s| s.files.values().cloned());
    records.chain(params).collect()
}

/// What every stage of one run reads.
struct RunEnv<'a> {
    plan: &'a Plan,
    selected: &'a BTreeSet<String>,
    rerun: &'a Rerun,
    keep_going: bool,
    lock: &'a LockFile,
    sources: &'a BTreeMap<String, ResolvedSource>,
    files: &'a BTreeMap<String, BTreeMap<String, String>>,
    transaction: &'a Transaction,
    reporter: &'a Reporter,
    state: Mutex<RunState>,
    /// Tables written this run, kept for the stages that read them next.
    memo: Arc<TableMemo>,
}

/// What the stages of one run fill in.
#[derive(Default)]
struct RunState {
    produced: BTreeMap<String, Produced>,
    entries: BTreeMap<String, StageLock>,
    reports: BTreeMap<String, StageReport>,
    /// Entries (paths relative to the output folder) the commit installs and removes.
    install: BTreeSet<String>,
    remove: BTreeSet<String>,
    failed: Vec<UnitProblem>,
    flagged: Vec<UnitProblem>,
    /// Stages with a failed unit, or reading one that has: their gathers do not run, and
    /// records gone from their inputs are not taken for removed.
    tainted: BTreeSet<String>,
    /// Set at the first failure without `--keep-going`: no stage starts after it.
    stop: bool,
    /// Per stage, how many of its upstream stages have not finished yet.
    waiting_on: BTreeMap<String, usize>,
    /// Per stage, how many of the stages reading its tables have not finished yet.
    readers_left: BTreeMap<String, usize>,
    /// An error that is not a unit's (a bad select found once inputs are known).
    fatal: Option<anyhow::Error>,
}

fn upstream_stages(stage: &PlannedStage) -> BTreeSet<&str> {
    stage
        .inputs
        .iter()
        .filter_map(|i| match i {
            InputRef::Stage { stage, .. } => Some(stage.as_str()),
            InputRef::Source(_) => None,
        })
        .collect()
}

fn run_stages(env: &RunEnv<'_>) -> anyhow::Result<()> {
    let mut dependents: BTreeMap<&str, Vec<&PlannedStage>> = BTreeMap::new();
    let mut roots = Vec::new();
    {
        let mut state = env.state.lock().expect("no poisoned lock");
        for stage in env.plan.stages.values() {
            let upstream = upstream_stages(stage);
            if upstream.is_empty() {
                roots.push(stage);
            }
            state.waiting_on.insert(stage.name.clone(), upstream.len());
            for name in upstream {
                dependents.entry(name).or_default().push(stage);
            }
        }
        state.readers_left = dependents.iter().map(|(name, readers)| (name.to_string(), readers.len())).collect();
    }
    // A stage starts as soon as its own upstream stages are done, not when a whole "wave" is.
    rayon::scope(|scope| {
        for stage in roots {
            start(env, &dependents, scope, stage);
        }
    });
    let mut state = env.state.lock().expect("no poisoned lock");
    match state.fatal.take() {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// Runs `stage` on the pool, then starts each dependent whose upstream stages are all done.
fn start<'s, 'a: 's>(
    env: &'s RunEnv<'a>,
    dependents: &'s BTreeMap<&'a str, Vec<&'a PlannedStage>>,
    scope: &rayon::Scope<'s>,
    stage: &'a PlannedStage,
) {
    scope.spawn(move |scope| {
        if let Err(error) = run_stage(env, stage) {
            let mut state = env.state.lock().expect("no poisoned lock");
            state.fatal.get_or_insert(error);
            state.stop = true;
        }
        let mut state = env.state.lock().expect("no poisoned lock");
        for upstream in upstream_stages(stage) {
            let left = state.readers_left.get_mut(upstream).expect("every upstream stage has readers");
            *left -= 1;
            if *left == 0 {
                env.memo.release(&env.transaction.new_path(env.plan.stage_path(upstream)));
            }
        }
        for dependent in dependents.get(stage.name.as_str()).into_iter().flatten() {
            let left = state.waiting_on.get_mut(&dependent.name).expect("every stage is counted");
            *left -= 1;
            if *left == 0 {
                start(env, dependents, scope, dependent);
            }
        }
    });
}

/// What became of one unit in a run: the record the commit folds into the lockfile (and, for a
/// Slurm run, what each array task leaves in its shard's manifest).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct UnitRecord {
    pub id: String,
    pub key: String,
    pub inputs: BTreeMap<String, String>,
    pub outcome: UnitOutcome,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum UnitOutcome {
    /// Up to date: its lockfile entry and files stay.
    Cached,
    /// Wrote these files (relative to the stage folder → hash) under `dir`; `notes`: what its
    /// tables flag (`sink::FLAGS_KEY`).
    Ran {
        dir: PathBuf,
        files: BTreeMap<String, String>,
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        notes: Vec<String>,
    },
    /// Failed; its previous files and entry stay (stale).
    Failed { reason: String },
    /// Its record could not be read and its source says `on_error: skip`.
    Flagged { file: String, reason: String },
}

/// Runs `stale` units of `stage` in parallel, each writing under `dir` (`dir/<output>/…`).
#[allow(clippy::too_many_arguments)]
fn execute(
    plan: &Plan,
    stage: &PlannedStage,
    stale: &[&(Unit, String, Vec<String>)],
    dir: &Path,
    memo: &Arc<TableMemo>,
    readers: usize,
    bar: &indicatif::ProgressBar,
) -> Vec<UnitRecord> {
    let info = stage.stage.info();
    let base_dir = plan.file.base_dir();
    stale
        .par_iter()
        .map(|(unit, key, _)| {
            let mut sink =
                OutputSink::new(dir, &stage.name, info, &stage.params, &unit.hashes, indicatif::ProgressBar::hidden());
            if readers > 0 {
                sink = sink.keeping_tables_in(memo.clone(), readers);
            }
            let ctx = StageContext {
                stage_name: &stage.name,
                params: &stage.params,
                inputs: &unit.inputs,
                sink: &sink,
                base_dir: &base_dir,
                memo: Some(memo),
            };
            let result = stage.stage.run(&ctx);
            bar.inc(1);
            let outcome = match result {
                Ok(()) => {
                    let notes = sink.flags();
                    let files =
                        sink.into_hashes().into_iter().map(|(path, hash)| (relative(&path, dir), hash)).collect();
                    UnitOutcome::Ran { dir: dir.to_path_buf(), files, notes }
                }
                Err(error) => {
                    let reason = format!("{error:#}");
                    match unit.source().filter(|(_, spec, _)| spec.on_error == OnError::Skip) {
                        Some((_, _, part)) => UnitOutcome::Flagged { file: part.label.clone(), reason },
                        None => UnitOutcome::Failed { reason },
                    }
                }
            };
            UnitRecord { id: unit.id.clone(), key: key.clone(), inputs: unit.hashes.clone(), outcome }
        })
        .collect()
}

/// A stage's run folded into what the commit does.
#[derive(Default)]
struct Folded {
    entry: Option<StageLock>,
    /// Paths relative to the output folder → where the new file is now.
    install: BTreeMap<String, PathBuf>,
    remove: BTreeSet<String>,
    produced: Produced,
    failed: Vec<UnitProblem>,
    flagged: Vec<UnitProblem>,
    /// Whether every unit succeeded (records gone from the inputs then leave too).
    complete: bool,
}

/// Folds a stage's unit records into its new lockfile entry, the files to install and remove,
/// and what downstream stages read. `staging` is where new stage-level files (the marker, the
/// `flagged` table) are written.
#[allow(clippy::too_many_arguments)]
fn fold(
    plan: &Plan,
    stage: &PlannedStage,
    entry: Option<&StageLock>,
    records: Vec<UnitRecord>,
    vanished: &[String],
    upstream_tainted: bool,
    staging: &Path,
) -> anyhow::Result<Folded> {
    let name = stage.name.as_str();
    let info = stage.stage.info();
    let stage_dir = plan.stage_dir(name);
    let at = |file: &str| plan.stage_entry(name, file);
    let mut folded = Folded::default();
    let mut new_entry = StageLock {
        stage_type: info.name.to_string(),
        stage_version: info.version,
        params: serde_json::Value::Object(stage.params.clone()),
        select: stage.select.clone(),
        units: BTreeMap::new(),
    };
    let mut owner: BTreeMap<String, String> = BTreeMap::new();
    let mut flagged_rows: Vec<(String, String, String)> = Vec::new();
    // Every record's status, for a stage that reads record sources (`load`).
    let mut status_rows: Vec<[String; 4]> = Vec::new();
    let mut status = |id: &str, what: &str, file: String, reason: String| {
        status_rows.push([id.to_string(), what.to_string(), file, reason]);
    };
    let mut failed = 0;
    for record in records {
        let old = entry.and_then(|e| e.units.get(&record.id));
        let old_files: Vec<&String> = old.map(|o| o.files.keys().collect()).unwrap_or_default();
        match record.outcome {
            UnitOutcome::Cached => {
                let old =
                    old.ok_or_else(|| anyhow!("stage `{name}`: cached unit `{}` is not in the lockfile", record.id))?;
                folded.produced.extend(cached_files(old, &stage_dir));
                if let Some(why) = &old.flagged {
                    let file =
                        old.inputs.keys().find(|k| !k.starts_with("source ") && !k.starts_with("params.")).cloned();
                    flagged_rows.push((record.id.clone(), file.unwrap_or_default(), why.clone()));
                    // Still skipped: the run says so, cached or not.
                    folded.flagged.push(UnitProblem {
                        stage: name.into(),
                        unit: record.id.clone(),
                        reason: why.clone(),
                    });
                }
                let (what, reason) = match (&old.flagged, old.notes.is_empty()) {
                    (Some(why), _) => ("skipped", why.clone()),
                    (None, false) => ("flagged", old.notes.join("; ")),
                    (None, true) => ("loaded", String::new()),
                };
                status(&record.id, what, record_files(&old.inputs), reason);
                new_entry.units.insert(record.id, old.clone());
            }
            UnitOutcome::Ran { dir, files, notes } => {
                for (file, hash) in &files {
                    if let Some(other) = owner.insert(file.clone(), record.id.clone()) {
                        anyhow::bail!(
                            "stage `{name}`: the {} and the {} both wrote `{file}`; give the sources distinct `partition:` values",
                            units::describe(&other),
                            units::describe(&record.id)
                        );
                    }
                    folded.produced.insert(file.clone(), ProducedFile { path: dir.join(file), hash: hash.clone() });
                    folded.install.insert(at(file), dir.join(file));
                }
                for gone in old_files.into_iter().filter(|f| !files.contains_key(*f)) {
                    folded.remove.insert(at(gone));
                }
                let what = if notes.is_empty() { "loaded" } else { "flagged" };
                status(&record.id, what, record_files(&record.inputs), notes.join("; "));
                new_entry.units.insert(
                    record.id,
                    UnitLock { key: record.key, inputs: record.inputs, files, flagged: None, notes },
                );
            }
            UnitOutcome::Flagged { file, reason } => {
                for gone in old_files {
                    folded.remove.insert(at(gone));
                }
                flagged_rows.push((record.id.clone(), file, reason.clone()));
                status(&record.id, "skipped", record_files(&record.inputs), reason.clone());
                folded.flagged.push(UnitProblem {
                    stage: name.into(),
                    unit: record.id.clone(),
                    reason: reason.clone(),
                });
                let unit = UnitLock {
                    key: record.key,
                    inputs: record.inputs,
                    files: BTreeMap::new(),
                    flagged: Some(reason),
                    notes: Vec::new(),
                };
                new_entry.units.insert(record.id, unit);
            }
            UnitOutcome::Failed { reason } => {
                failed += 1;
                status(&record.id, "failed", record_files(&record.inputs), reason.clone());
                folded.failed.push(UnitProblem { stage: name.into(), unit: record.id.clone(), reason });
                // Its previous outputs stay, stale, with their entry; nothing reads them this run.
                if let Some(old) = old {
                    new_entry.units.insert(record.id, old.clone());
                }
            }
        }
    }
    folded.complete = failed == 0 && !upstream_tainted;
    for id in vanished {
        let old = &entry.expect("vanished units come from the lockfile").units[id];
        if folded.complete {
            folded.remove.extend(old.files.keys().map(|gone| at(gone)));
        } else {
            new_entry.units.insert(id.clone(), old.clone());
        }
    }
    let skips = stage.inputs.iter().any(|i| match i {
        InputRef::Source(s) => plan.file.spec.inputs[s].on_error == OnError::Skip,
        InputRef::Stage { .. } => false,
    });
    // The engine's tables: made anew by every run of the stage, installed when they changed.
    let mut engine_table = |unit: &str, (file, hash): (String, String)| {
        let old = entry.and_then(|e| e.units.get(unit));
        if old.is_none_or(|o| o.key != hash || !stage_dir.join(&file).is_file()) {
            folded.install.insert(at(&file), staging.join(&file));
        }
        folded.produced.insert(file.clone(), ProducedFile { path: staging.join(&file), hash: hash.clone() });
        let files = BTreeMap::from([(file, hash.clone())]);
        let lock = UnitLock { key: hash, inputs: BTreeMap::new(), files, flagged: None, notes: Vec::new() };
        new_entry.units.insert(unit.into(), lock);
    };
    if skips {
        flagged_rows.sort();
        let rows: Vec<[String; 3]> = flagged_rows.into_iter().map(|(r, f, why)| [r, f, why]).collect();
        engine_table(FLAGGED_UNIT, text_table(staging, name, info, &stage.params, FLAGGED, &FLAGGED_COLUMNS, &rows)?);
    }
    if info.inputs == InputKind::Sources && skips && failed == 0 {
        status_rows.sort();
        engine_table(
            STATUS_UNIT,
            text_table(staging, name, info, &stage.params, STATUS, &STATUS_COLUMNS, &status_rows)?,
        );
    }
    if !folded.install.is_empty() && ownership::read_marker(&stage_dir).is_none() {
        ownership::write_marker(staging, name, info.name)?;
        folded.install.insert(at(ownership::STAGE_MARKER), staging.join(ownership::STAGE_MARKER));
    }
    folded.entry = Some(new_entry);
    Ok(folded)
}

/// Why a stage does not run this run (None: it runs).
fn skip_reason(env: &RunEnv<'_>, stage: &PlannedStage, upstream_tainted: bool) -> Option<Option<&'static str>> {
    let state = env.state.lock().expect("no poisoned lock");
    if !env.selected.contains(&stage.name) {
        Some(None)
    } else if state.stop {
        Some(Some("the run stopped at a failed unit (`--keep-going` runs what does not depend on it)"))
    } else if upstream_tainted && stage.stage.work_units() == WorkUnits::Gather {
        Some(Some("an upstream unit failed"))
    } else {
        None
    }
}

/// Checks one stage's units against the lockfile and runs the stale ones into the transaction.
fn run_stage(env: &RunEnv<'_>, stage: &PlannedStage) -> anyhow::Result<()> {
    let name = stage.name.as_str();
    let entry = env.lock.stages.get(name);
    let upstream_tainted = {
        let state = env.state.lock().expect("no poisoned lock");
        upstream_stages(stage).iter().any(|u| state.tainted.contains(*u))
    };
    if let Some(why) = skip_reason(env, stage, upstream_tainted) {
        let mut state = env.state.lock().expect("no poisoned lock");
        if let Some(why) = why {
            env.reporter.line(&format!("{name:<18} not run: {why}"));
            state.tainted.insert(name.to_string());
        }
        // Downstream stages outside the selection read what is committed.
        let stage_dir = env.plan.stage_dir(name);
        let committed = entry.map(|e| e.units.values().flat_map(|u| cached_files(u, &stage_dir)).collect());
        state.produced.insert(name.to_string(), committed.unwrap_or_default());
        let units = entry.map_or(0, |e| e.units.len());
        state
            .reports
            .insert(name.to_string(), StageReport { name: name.into(), outcome: Outcome::Skipped, units, ran: 0 });
        return Ok(());
    }
    let snapshot = env.state.lock().expect("no poisoned lock").produced.clone();
    let assessed = assess_stage(env.plan, stage, env.sources, &snapshot, env.files, env.lock, env.rerun)?;
    let new_dir = env.transaction.new_path(env.plan.stage_path(name));
    let stale: Vec<&(Unit, String, Vec<String>)> = assessed.units.iter().filter(|(_, _, r)| !r.is_empty()).collect();
    let started = Instant::now();
    let records_in: usize = stale.iter().map(|(u, _, _)| u.inputs.iter().map(|i| i.parts().len()).sum::<usize>()).sum();
    let mut ran: BTreeMap<String, UnitRecord> = if stale.is_empty() {
        env.reporter.line(&format!("{name:<18} cached"));
        BTreeMap::new()
    } else {
        env.reporter.line(&format!("{name:<18} running ({})", why_running(&stale, assessed.units.len())));
        let bar = env.reporter.stage_bar(name, stale.len() as u64);
        let readers = env.plan.stages.values().filter(|s| upstream_stages(s).contains(name)).count();
        let records = execute(env.plan, stage, &stale, &new_dir, &env.memo, readers, &bar);
        bar.finish_and_clear();
        records.into_iter().map(|r| (r.id.clone(), r)).collect()
    };
    let records: Vec<UnitRecord> = assessed
        .units
        .iter()
        .map(|(unit, key, _)| {
            ran.remove(&unit.id).unwrap_or_else(|| UnitRecord {
                id: unit.id.clone(),
                key: key.clone(),
                inputs: unit.hashes.clone(),
                outcome: UnitOutcome::Cached,
            })
        })
        .collect();
    for record in &records {
        match &record.outcome {
            UnitOutcome::Failed { reason } => {
                env.reporter.line(&format!("{name:<18} FAILED {}: {reason}", units::describe(&record.id)))
            }
            UnitOutcome::Flagged { file, reason } => {
                env.reporter.line(&format!("{name:<18} skipped {file} (on_error: skip): {reason}"))
            }
            _ => {}
        }
    }
    let folded = fold(env.plan, stage, entry, records, &assessed.vanished, upstream_tainted, &new_dir)?;
    let failed = folded.failed.len();
    if !stale.is_empty() {
        let written = folded.install.len();
        env.reporter.line(&format!(
            "{name:<18} done in {:.2} s: {} unit(s) ran{}, {} cached ({records_in} records in, {written} files written)",
            started.elapsed().as_secs_f64(),
            stale.len() - failed,
            if failed > 0 { format!(", {failed} FAILED") } else { String::new() },
            assessed.units.len() - stale.len(),
        ));
    }
    let mut state = env.state.lock().expect("no poisoned lock");
    if !folded.complete {
        state.tainted.insert(name.to_string());
        if failed > 0 && !env.keep_going {
            state.stop = true;
        }
    }
    state.install.extend(folded.install.into_keys());
    state.remove.extend(folded.remove);
    state.failed.extend(folded.failed);
    state.flagged.extend(folded.flagged);
    state.produced.insert(name.to_string(), folded.produced);
    state.entries.insert(name.to_string(), folded.entry.expect("fold makes the entry"));
    let outcome = if stale.is_empty() {
        Outcome::Cached
    } else {
        Outcome::Ran { seconds: started.elapsed().as_secs_f64(), records: records_in }
    };
    state.reports.insert(
        name.to_string(),
        StageReport { name: name.into(), outcome, units: assessed.units.len(), ran: stale.len() },
    );
    Ok(())
}

/// Why a stage's units run, in a line: the reasons all share, else a count and the first.
fn why_running(stale: &[&(Unit, String, Vec<String>)], units: usize) -> String {
    if stale.len() == units && stale.iter().all(|u| u.2 == stale[0].2) {
        return stale[0].2.join("; ");
    }
    let first = format!("{}: {}", units::describe(&stale[0].0.id), stale[0].2.join("; "));
    let more = if stale.len() > 1 { ", …" } else { "" };
    format!("{} of {units} records; {first}{more}", stale.len())
}

/// The columns of the `flagged` table: one row per record skipped under `on_error: skip`.
const FLAGGED_COLUMNS: [(&str, &str); 3] = [
    ("record", "the record's partition (its work unit)"),
    ("file", "the record file, relative to the pipeline"),
    ("reason", "why it could not be read (file:line:column where known)"),
];

/// The columns of the `status` table: one row per record of the stage's sources.
const STATUS_COLUMNS: [(&str, &str); 4] = [
    ("record", "the record's partition (its work unit)"),
    ("status", "loaded; flagged (loaded whole, with something to know: see reason); skipped (on_error: skip); failed (its previous outputs, if any, are kept, stale)"),
    ("file", "the record's files, relative to the pipeline (comma-separated)"),
    ("reason", "why it is flagged, skipped or failed, with file:line where known; empty when loaded"),
];

/// The files a unit read (its input labels), comma-separated: not its sources' specs nor its
/// parameters' files.
fn record_files(inputs: &BTreeMap<String, String>) -> String {
    let files: Vec<&str> =
        inputs.keys().filter(|k| !k.starts_with("source ") && !k.starts_with("params.")).map(String::as_str).collect();
    files.join(", ")
}

/// `<stage>/<output>/data.parquet`, a table of text `columns` (name, description) and `rows`,
/// written by the engine (`flagged`, `status`); returns its path in the stage folder and its hash.
fn text_table<const N: usize>(
    new_dir: &Path,
    stage: &str,
    info: &'static StageInfo,
    params: &super::params::Params,
    output: &str,
    columns: &[(&str, &str); N],
    rows: &[[String; N]],
) -> anyhow::Result<(String, String)> {
    use crate::table::{Column, ColumnData, Table};
    let mut table = Table::new();
    table.extend(columns.iter().enumerate().map(|(k, (name, description))| Column {
        name: (*name).into(),
        unit: String::new(),
        description: (*description).into(),
        data: ColumnData::Str(rows.iter().map(|r| r[k].clone()).collect()),
    }));
    let sink = OutputSink::new(new_dir, stage, info, params, &BTreeMap::new(), indicatif::ProgressBar::hidden());
    sink.write(output, &Vec::new(), table)?;
    let (path, hash) = sink.into_hashes().into_iter().next().expect("one table written");
    Ok((relative(&path, new_dir), hash))
}

/// `path` relative to `dir`, with `/` separators (lockfile keys are the same on every OS).
fn relative(path: &Path, dir: &Path) -> String {
    path.strip_prefix(dir)
        .unwrap_or(path)
        .components()
        .map(|c| c.as_os_str().to_string_lossy())
        .collect::<Vec<_>>()
        .join("/")
}
