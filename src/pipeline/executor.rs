//! Running a plan: decide per stage whether it is cached, run what is not (in parallel where
//! the DAG allows), and commit all results at once.
//!
//! A run is all-or-nothing: it holds the output folder's lease (`lease.rs`), writes new outputs
//! into a transaction and commits them with the new lockfile in one step (`txn.rs`) after every
//! stage succeeded. A failed run leaves the previous artifacts and the lockfile as they were.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::{anyhow, Context};
use rayon::prelude::*;
use serde_json::json;

use super::lease::Lease;
use super::lock::{LockFile, OutputLock, StageLock, LOCK_FILE};
use super::memo::{TableMemo, DEFAULT_BUDGET_BYTES};
use super::ownership;
use super::plan::{InputRef, Plan, PlannedStage};
use super::progress::Reporter;
use super::sink::OutputSink;
use super::sources;
use super::spec::RecordFormat;
use super::txn::{self, Recovery, Transaction};
use crate::error::UserError;
use crate::io::hash::{self, KnownHashes};
use crate::stages::{InputPart, OutputKind, StageContext, StageInput};

#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Stages to rerun even when cached (their dependents rerun too).
    pub force: Vec<String>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    Cached,
    Ran { seconds: f64, records: usize },
}

#[derive(Debug, Clone)]
pub struct StageReport {
    pub name: String,
    pub outcome: Outcome,
}

/// A source resolved to files, with the hash that stands for all of them and its spec.
struct ResolvedSource {
    input: StageInput,
    hash: String,
}

/// Where a stage's outputs are (final or staged) and their hashes.
#[derive(Clone)]
struct Produced {
    dir: PathBuf,
    outputs: BTreeMap<String, OutputLock>,
    /// Hashes of the files this run wrote (empty for a cached stage).
    written: Arc<KnownHashes>,
}

/// Why a stage must run; empty when it is up to date.
pub struct Assessment {
    pub key: String,
    pub reasons: Vec<String>,
}

pub fn lock_path(plan: &Plan) -> PathBuf {
    plan.file.output_dir().join(LOCK_FILE)
}

fn resolve_sources(plan: &Plan) -> Result<BTreeMap<String, ResolvedSource>, UserError> {
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
    let mut hashed: HashMap<PathBuf, String> = HashMap::new();
    for name in used {
        let spec = &plan.file.spec.inputs[name];
        let folders = spec.format == RecordFormat::Frames;
        let files = sources::resolve(&base, &spec.path, &spec.partition, folders).map_err(|e| {
            let located = plan.file.error_at(&["inputs", name, "path"], format!("source `{name}`: {}", e.message));
            match e.hint {
                Some(h) => located.hint(h),
                None => located,
            }
        })?;
        // A case source names each case by its equipment.yaml; the case is the whole folder.
        let files: Vec<sources::MatchedFile> = if spec.format == RecordFormat::Case {
            files
                .into_iter()
                .map(|f| sources::MatchedFile { path: f.path.parent().map(Path::to_path_buf).unwrap_or(f.path), ..f })
                .collect()
        } else {
            files
        };
        let unhashed: Vec<&Path> =
            files.iter().map(|f| f.path.as_path()).filter(|p| !hashed.contains_key(*p)).collect();
        let new_hashes: Vec<String> = unhashed
            .par_iter()
            .map(|p| hash::hash_path(p))
            .collect::<anyhow::Result<_>>()
            .map_err(|e| UserError::new(format!("source `{name}`: {e:#}")))?;
        hashed.extend(unhashed.into_iter().map(Path::to_path_buf).zip(new_hashes));
        let hashes: Vec<String> = files.iter().map(|f| hashed[&f.path].clone()).collect();
        let mut summary = serde_json::to_string(spec).expect("specs serialise");
        let parts: Vec<InputPart> = files
            .into_iter()
            .zip(hashes)
            .map(|(f, h)| {
                let relative = f.path.strip_prefix(&base).unwrap_or(&f.path).to_string_lossy().replace('\\', "/");
                summary.push_str(&format!("\n{relative}\0{}\0{h}", crate::stages::partition_path(&f.partition)));
                InputPart { partition: f.partition, path: f.path, label: relative, hash: h }
            })
            .collect();
        let input =
            StageInput::Source { name: name.to_string(), spec: spec.clone(), base_dir: base.clone(), files: parts };
        resolved.insert(name.to_string(), ResolvedSource { input, hash: hash::hash_bytes(summary.as_bytes()) });
    }
    Ok(resolved)
}

fn cache_key(stage: &PlannedStage, input_hashes: &BTreeMap<String, String>) -> String {
    let info = stage.stage.info();
    let material = json!({"type": info.name, "version": info.version, "params": stage.params, "inputs": input_hashes, "select": stage.select});
    hash::hash_bytes(material.to_string().as_bytes())
}

/// Compares a stage with its lock entry; `input_hashes` is None when an upstream stage is stale.
fn assess(
    stage: &PlannedStage,
    input_hashes: Option<&BTreeMap<String, String>>,
    lock: &LockFile,
    output_dir: &Path,
) -> anyhow::Result<Assessment> {
    let info = stage.stage.info();
    let key = input_hashes.map(|h| cache_key(stage, h)).unwrap_or_default();
    let Some(entry) = lock.stages.get(&stage.name) else {
        return Ok(Assessment { key, reasons: vec!["never run (not in the lockfile)".into()] });
    };
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
    match input_hashes {
        None => reasons.push("an upstream stage will rerun".into()),
        Some(hashes) => {
            for (name, hash) in hashes {
                match entry.inputs.get(name) {
                    None => reasons.push(format!("new input `{name}`")),
                    Some(old) if old != hash => reasons.push(format!("input `{name}` changed")),
                    Some(_) => {}
                }
            }
            for name in entry.inputs.keys().filter(|n| !hashes.contains_key(*n)) {
                reasons.push(format!("input `{name}` removed"));
            }
            if reasons.is_empty() && entry.key != key {
                reasons.push("cache key changed".into());
            }
        }
    }
    for (name, out) in &entry.outputs {
        let dir = output_dir.join(&out.path);
        if !dir.exists() {
            reasons.push(format!("output `{name}` missing ({})", dir.display()));
        } else {
            let (hash, files) = super::sink::output_hash(&output_dir.join(&stage.name), name, &KnownHashes::new())?;
            if files < out.files {
                reasons.push(format!("output `{name}` lost files: {files} of its {} are left", out.files));
            } else if hash != out.hash {
                reasons.push(format!("output `{name}` was modified on disk"));
            }
        }
    }
    Ok(Assessment { key, reasons })
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

fn input_hashes_for(
    stage: &PlannedStage,
    sources: &BTreeMap<String, ResolvedSource>,
    produced: &BTreeMap<String, Produced>,
    files: &BTreeMap<String, BTreeMap<String, String>>,
) -> Option<BTreeMap<String, String>> {
    let mut hashes: BTreeMap<String, String> = stage
        .inputs
        .iter()
        .map(|input| {
            let hash = match input {
                InputRef::Source(name) => sources[name].hash.clone(),
                InputRef::Stage { stage, output } => produced.get(stage)?.outputs.get(*output)?.hash.clone(),
            };
            Some((input.label(), hash))
        })
        .collect::<Option<_>>()?;
    hashes.extend(files.get(&stage.name).into_iter().flatten().map(|(k, v)| (k.clone(), v.clone())));
    Some(hashes)
}

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
            InputRef::Source(name) => Ok(sources[name].input.clone()),
            InputRef::Stage { stage: upstream, output } => {
                let upstream = &produced[upstream];
                let parts = dataset_parts_known(&upstream.dir.join(output), &input.label(), &upstream.written)?;
                Ok(StageInput::Dataset { name: input.label(), parts })
            }
        })
        .collect::<anyhow::Result<_>>()?;
    check_select(plan, stage, &inputs)?;
    for input in &mut inputs {
        match input {
            StageInput::Source { files, .. } => files.retain(|f| stage.selects(&f.partition)),
            StageInput::Dataset { parts, .. } => parts.retain(|p| stage.selects(&p.partition)),
        }
    }
    Ok(inputs)
}

/// A `select:` key or value that no record of the stage's inputs has is a typo, not a wish for
/// an empty selection.
fn check_select(plan: &Plan, stage: &PlannedStage, inputs: &[StageInput]) -> Result<(), UserError> {
    let partitions: Vec<&(String, String)> = inputs.iter().flat_map(|i| i.parts()).flat_map(|p| &p.partition).collect();
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

/// The parts of a dataset directory: each `data.parquet` with the partition its path encodes.
pub fn dataset_parts(dir: &Path, label: &str) -> anyhow::Result<Vec<InputPart>> {
    dataset_parts_known(dir, label, &KnownHashes::new())
}

/// [`dataset_parts`], not reading again the files whose hashes are `known`.
fn dataset_parts_known(dir: &Path, label: &str, known: &KnownHashes) -> anyhow::Result<Vec<InputPart>> {
    let files: Vec<String> =
        hash::list_files(dir)?.into_iter().filter(|f| f.ends_with(super::sink::DATA_FILE)).collect();
    let paths: Vec<PathBuf> = files.iter().map(|f| dir.join(f)).collect();
    let hashes = hash::hash_files_known(&paths, known)?;
    Ok(files
        .iter()
        .zip(paths)
        .zip(hashes)
        .map(|((relative, path), hash)| {
            let partition = relative
                .split('/')
                .filter_map(|segment| segment.split_once('='))
                .map(|(k, v)| (super::paths::decode_component(k), super::paths::decode_component(v)))
                .collect();
            InputPart { partition, path, label: format!("{label}/{relative}"), hash }
        })
        .collect())
}

pub struct StatusLine {
    pub name: String,
    pub stage_type: &'static str,
    pub reasons: Vec<String>,
}

/// What `run` would do, and why, without running anything; `notes` are what the user should
/// know besides (a run in progress, an interrupted commit completed).
pub fn status(plan: &Plan, notes: &mut Vec<String>) -> Result<Vec<StatusLine>, UserError> {
    let output_dir = plan.file.output_dir();
    if output_dir.join(super::lease::STATE_DIR).is_dir() {
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
    let mut produced: BTreeMap<String, Produced> = BTreeMap::new();
    let mut lines = Vec::new();
    for stage in plan.stages.values() {
        let hashes = input_hashes_for(stage, &sources, &produced, &files);
        let assessment =
            assess(stage, hashes.as_ref(), &lock, &output_dir).map_err(|e| UserError::new(format!("{e:#}")))?;
        if assessment.reasons.is_empty() {
            let outputs = lock.stages[&stage.name].outputs.clone();
            let dir = output_dir.join(&stage.name);
            produced.insert(stage.name.clone(), Produced { dir, outputs, written: Arc::default() });
        }
        lines.push(StatusLine {
            name: stage.name.clone(),
            stage_type: stage.stage.info().name,
            reasons: assessment.reasons,
        });
    }
    Ok(lines)
}

pub fn run(plan: &Plan, options: &RunOptions, reporter: &Reporter) -> anyhow::Result<Vec<StageReport>> {
    for name in &options.force {
        if !plan.stages.contains_key(name) {
            let known: Vec<&str> = plan.stages.keys().map(String::as_str).collect();
            return Err(UserError::new(format!("`--force {name}`: no stage of that name in this pipeline"))
                .in_file(&plan.file.path)
                .hint(format!("stages: {}", known.join(", ")))
                .into());
        }
    }
    let forced: BTreeSet<String> = options.force.iter().flat_map(|n| plan.with_dependents(n)).collect();
    let output_dir = plan.file.output_dir();
    let sources = resolve_sources(plan)?;
    let files = param_file_hashes(plan)?;
    ownership::check_output_dir(&plan.file, &input_paths(plan, &sources))?;
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
    ownership::check_stage_folders(&plan.file, &output_dir, plan.stages.keys().map(String::as_str), &lock)?;
    let transaction = Transaction::begin(&lease)?;
    let result = run_stages(plan, &forced, &lock, &sources, &files, &output_dir, &transaction, reporter);
    match result {
        Ok((reports, new_lock, rerun)) => {
            transaction.commit(&rerun, &[], Some(&new_lock))?;
            Ok(reports)
        }
        Err(e) => {
            transaction.abort();
            Err(e)
        }
    }
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
        Transaction::begin(&lease)?.commit(&[], &orphans, None)?;
    }
    Ok(sized)
}

/// Every file a run reads: record files and files named by parameters.
fn input_paths(plan: &Plan, sources: &BTreeMap<String, ResolvedSource>) -> Vec<PathBuf> {
    let records = sources.values().flat_map(|s| s.input.parts().iter().map(|p| p.path.clone()));
    let params = plan.stages.values().flat_map(|s| s.files.values().cloned());
    records.chain(params).collect()
}

type StagesResult = (Vec<StageReport>, LockFile, Vec<String>);

/// What every stage of one run reads and fills in.
struct RunEnv<'a> {
    plan: &'a Plan,
    forced: &'a BTreeSet<String>,
    lock: &'a LockFile,
    sources: &'a BTreeMap<String, ResolvedSource>,
    files: &'a BTreeMap<String, BTreeMap<String, String>>,
    output_dir: &'a Path,
    transaction: &'a Transaction,
    reporter: &'a Reporter,
    produced: Mutex<BTreeMap<String, Produced>>,
    entries: Mutex<BTreeMap<String, StageLock>>,
    reports: Mutex<BTreeMap<String, StageReport>>,
    /// Per stage, how many of its upstream stages have not finished yet.
    waiting_on: Mutex<BTreeMap<&'a str, usize>>,
    /// Per stage, the stages that consume its outputs.
    dependents: BTreeMap<&'a str, Vec<&'a PlannedStage>>,
    /// Tables written this run, kept for the stages that read them next.
    memo: Arc<TableMemo>,
    /// Per stage, how many of the stages reading its tables have not finished yet.
    readers_left: Mutex<BTreeMap<&'a str, usize>>,
    /// The first failure; once set, no further stage starts.
    failure: Mutex<Option<anyhow::Error>>,
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

#[allow(clippy::too_many_arguments)]
fn run_stages(
    plan: &Plan,
    forced: &BTreeSet<String>,
    lock: &LockFile,
    sources: &BTreeMap<String, ResolvedSource>,
    files: &BTreeMap<String, BTreeMap<String, String>>,
    output_dir: &Path,
    transaction: &Transaction,
    reporter: &Reporter,
) -> anyhow::Result<StagesResult> {
    let mut dependents: BTreeMap<&str, Vec<&PlannedStage>> = BTreeMap::new();
    let mut waiting_on = BTreeMap::new();
    let mut roots = Vec::new();
    for stage in plan.stages.values() {
        let upstream = upstream_stages(stage);
        if upstream.is_empty() {
            roots.push(stage);
        }
        waiting_on.insert(stage.name.as_str(), upstream.len());
        for name in upstream {
            dependents.entry(name).or_default().push(stage);
        }
    }
    let readers_left = Mutex::new(dependents.iter().map(|(name, readers)| (*name, readers.len())).collect());
    let env = RunEnv {
        plan,
        forced,
        lock,
        sources,
        files,
        output_dir,
        transaction,
        reporter,
        produced: Mutex::new(BTreeMap::new()),
        entries: Mutex::new(BTreeMap::new()),
        reports: Mutex::new(BTreeMap::new()),
        waiting_on: Mutex::new(waiting_on),
        dependents,
        memo: Arc::new(TableMemo::new(DEFAULT_BUDGET_BYTES)),
        readers_left,
        failure: Mutex::new(None),
    };
    // A stage starts as soon as its own upstream stages are done, not when a whole "wave" is.
    rayon::scope(|scope| {
        for stage in roots {
            start(&env, scope, stage);
        }
    });
    if let Some(error) = env.failure.into_inner().map_err(|_| anyhow!("a stage panicked"))? {
        return Err(error);
    }
    let (reports, entries) = (env.reports, env.entries);
    let reports = reports.into_inner().map_err(|_| anyhow!("a stage panicked"))?;
    let ordered: Vec<StageReport> = plan.stages.keys().map(|n| reports[n].clone()).collect();
    let rerun: Vec<String> =
        ordered.iter().filter(|r| matches!(r.outcome, Outcome::Ran { .. })).map(|r| r.name.clone()).collect();
    let new_lock = LockFile {
        version: lock.version.max(1),
        pipeline: Some(ownership::pipeline_label(&plan.file)),
        stages: entries.into_inner().map_err(|_| anyhow!("a stage panicked"))?,
    };
    Ok((ordered, new_lock, rerun))
}

/// Runs `stage` on the pool, then starts each dependent whose upstream stages are all done.
fn start<'s, 'a: 's>(env: &'s RunEnv<'a>, scope: &rayon::Scope<'s>, stage: &'a PlannedStage) {
    scope.spawn(move |scope| {
        if env.failure.lock().expect("no poisoned lock").is_some() {
            return;
        }
        if let Err(error) = run_stage(env, stage) {
            env.failure.lock().expect("no poisoned lock").get_or_insert(error);
            return;
        }
        release_read_tables(env, stage);
        for dependent in env.dependents.get(stage.name.as_str()).into_iter().flatten() {
            let mut waiting_on = env.waiting_on.lock().expect("no poisoned lock");
            let left = waiting_on.get_mut(dependent.name.as_str()).expect("every stage is counted");
            *left -= 1;
            if *left == 0 {
                drop(waiting_on);
                start(env, scope, dependent);
            }
        }
    });
}

/// Forgets the kept tables of each upstream stage of `stage` that no unfinished stage reads.
fn release_read_tables(env: &RunEnv<'_>, stage: &PlannedStage) {
    let mut readers_left = env.readers_left.lock().expect("no poisoned lock");
    for upstream in upstream_stages(stage) {
        let left = readers_left.get_mut(upstream).expect("every upstream stage has readers");
        *left -= 1;
        if *left == 0 {
            if let Some(done) = env.produced.lock().expect("no poisoned lock").get(upstream) {
                env.memo.release(&done.dir);
            }
        }
    }
}

/// Checks one stage against the lockfile and runs it into the run's transaction if it is stale.
fn run_stage(env: &RunEnv<'_>, stage: &PlannedStage) -> anyhow::Result<()> {
    let snapshot = env.produced.lock().expect("no poisoned lock").clone();
    let hashes = input_hashes_for(stage, env.sources, &snapshot, env.files).expect("upstream stages finished");
    let assessment = assess(stage, Some(&hashes), env.lock, env.output_dir)?;
    let info = stage.stage.info();
    let (done, report) = if assessment.reasons.is_empty() && !env.forced.contains(&stage.name) {
        env.reporter.line(&format!("{:<18} cached", stage.name));
        let entry = env.lock.stages[&stage.name].clone();
        env.entries.lock().expect("no poisoned lock").insert(stage.name.clone(), entry.clone());
        let dir = env.output_dir.join(&stage.name);
        (Produced { dir, outputs: entry.outputs, written: Arc::default() }, Outcome::Cached)
    } else {
        let why = if env.forced.contains(&stage.name) { "forced".to_string() } else { assessment.reasons.join("; ") };
        let started = Instant::now();
        let dir = env.transaction.new_path(&stage.name);
        let inputs = stage_inputs(env.plan, stage, env.sources, &snapshot)?;
        let records: usize = inputs.iter().map(|i| i.parts().len()).sum();
        let bar = env.reporter.stage_bar(&stage.name, records as u64);
        env.reporter.line(&format!("{:<18} running ({why})", stage.name));
        let mut sink = OutputSink::new(&dir, &stage.name, info, &stage.params, &hashes, bar.clone());
        if let Some(readers) = env.dependents.get(stage.name.as_str()) {
            sink = sink.keeping_tables_in(env.memo.clone(), readers.len());
        }
        let base_dir = env.plan.file.base_dir();
        let ctx = StageContext {
            stage_name: &stage.name,
            params: &stage.params,
            inputs: &inputs,
            sink: &sink,
            base_dir: &base_dir,
            memo: Some(&env.memo),
        };
        stage.stage.run(&ctx).with_context(|| {
            format!("stage `{}` (type `{}`) failed; nothing was changed on disk", stage.name, info.name)
        })?;
        bar.finish_and_clear();
        ownership::write_marker(&dir, &stage.name, info.name)?;
        let written = sink.into_hashes();
        let mut outputs = BTreeMap::new();
        for output in info.outputs {
            if output.kind != OutputKind::Page {
                std::fs::create_dir_all(dir.join(output.name))?;
            }
            let (hash, files) = super::sink::output_hash(&dir, output.name, &written)?;
            outputs.insert(
                output.name.to_string(),
                OutputLock { path: format!("{}/{}", stage.name, output.name), hash, files },
            );
        }
        let files: usize = outputs.values().map(|o| o.files).sum();
        let seconds = started.elapsed().as_secs_f64();
        env.reporter
            .line(&format!("{:<18} done in {seconds:.2} s ({records} records in, {files} files out)", stage.name));
        let entry = StageLock {
            stage_type: info.name.to_string(),
            stage_version: info.version,
            key: assessment.key,
            params: serde_json::Value::Object(stage.params.clone()),
            select: stage.select.clone(),
            inputs: hashes,
            outputs: outputs.clone(),
        };
        env.entries.lock().expect("no poisoned lock").insert(stage.name.clone(), entry);
        (Produced { dir, outputs, written: Arc::new(written) }, Outcome::Ran { seconds, records })
    };
    env.produced.lock().expect("no poisoned lock").insert(stage.name.clone(), done);
    env.reports
        .lock()
        .expect("no poisoned lock")
        .insert(stage.name.clone(), StageReport { name: stage.name.clone(), outcome: report });
    Ok(())
}
