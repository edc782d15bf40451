//! The Slurm executor: the same work units as a local run, run by job arrays.
//!
//! `shakeflow run P.yaml --executor slurm` plans on the login node as a local run does, then:
//! 1. takes the output folder's lease and writes the run's folder
//!    `<output_dir>/.shakeflow/slurm/<run>/` (`run.json`: the pipeline, the options, and per stage
//!    its shards — the predicted unit ids, in order, cut into shards of `units_per_task`; a
//!    per-record stage of more records than a folder holds is cut by bucket instead
//!    (`layout::fan_bucket`: the 256 buckets in contiguous ranges of about `units_per_task`
//!    units, the same ranges for every such stage, so shard i of each holds the same motions);
//! 2. submits one job array per stage with stale units (only the shards that hold one), named
//!    after the run, each task `shakeflow slurm-task <run folder> <stage>` with its shard in
//!    `$SLURM_ARRAY_TASK_ID`: `aftercorr` on the upstream array when both are per-record stages
//!    cut into the same shards (task i waits for task i only), `afterok` otherwise, `afterany`
//!    with `--keep-going`; and a commit job (`shakeflow slurm-commit`) after all of them
//!    (`afterany`);
//! 3. hands the lease to the run (its holder names the run and the commit job) and returns.
//!
//! A task reads the state of its stage and of the stages it reads — of a bucketed stage only its
//! buckets, when each unit reads records of its own bucket only (`StatusLine::closed`), so what
//! it reads is ∝ its shard, not the archive — computes its stage's units from the committed
//! outputs and the upstream tasks' manifests, runs the stale units of its shard (rayon inside)
//! into `results/<stage>/<shard>.tmp-<host>-<job>/`, renames that to `results/<stage>/<shard>/`,
//! and writes `manifests/<stage>/<shard>.json` (what became of each unit) the same way. It
//! exits 1 when a unit failed; when none did, it removes the results of the `keep: false`
//! shards it alone read (`drop_consumed`). No task writes the lockfile or a stage folder: the commit job
//! takes the lease back, folds the manifests as a local run folds its units, moves the results
//! into a transaction and commits it. Rerunning the same command resubmits only the shards
//! whose units are still stale (a cancelled task's, a failed unit's); with `retries` the commit
//! job does that itself, as a new run it hands the lease to.
//!
//! With `in_allocation` nothing is submitted: inside one `sbatch`/`salloc` job, the shards run
//! as `srun` steps of the same `slurm-task`, stage after stage, and the process commits itself.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{anyhow, bail, Context};
use serde::{Deserialize, Serialize};

use super::assess::{assess_stage, predict, Known, Prediction, RealDisk, StatusLine};
use super::commit::{entry_from_outcomes, leave_out_not_kept, UnitOutcome, UnitRecord};
use super::inputs::{
    cached_files, listings, param_file_hashes, resolve_sources, resolve_sources_of, Listed, Produced, ProducedFile,
    ResolvedSource,
};
use super::local::execute;
use super::{
    forced_stages, selected_stages, source_inputs, upstream_stages, Backend, Opened, Rerun, RunOptions, RunSummary,
    UnitProblem,
};
use crate::error::UserError;
use crate::pipeline::layout::{
    fan_bucket, fan_out_above, fans_out, LEASE_FILE, LOCK_FILE, RUNS_DIR, RUN_LISTINGS, RUN_LOGS, RUN_MANIFESTS,
    RUN_RESULTS, STATE_DIR,
};
use crate::pipeline::lease::Lease;
use crate::pipeline::lock::{LockFile, Wanted};
use crate::pipeline::memo::TableMemo;
use crate::pipeline::ownership;
use crate::pipeline::plan::Plan;
use crate::pipeline::progress::Reporter;
use crate::pipeline::slurm::{ArrayJob, DepKind, Dependency, ExecutorOptions, Slurm, SubmittedArray};
use crate::pipeline::spec::PipelineFile;
use crate::pipeline::stage::{Registry, WorkUnits};
use crate::pipeline::txn::Transaction;

const RUN_FILE: &str = "run.json";
/// What the commit job leaves for `--wait` and `status`: `<run>.summary.json` beside the run folders.
const SUMMARY_SUFFIX: &str = ".summary.json";

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SlurmOptions {
    pub executor: ExecutorOptions,
    /// Work units per array task.
    pub units_per_task: usize,
    /// Poll until the run is committed, and report as a local run does.
    pub wait: bool,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct RunFile {
    id: String,
    /// The pipeline file, absolute, and its bytes' hash (a task refuses an edited pipeline).
    pipeline: PathBuf,
    pipeline_hash: String,
    force: Vec<String>,
    only: Vec<String>,
    keep_going: bool,
    /// The Slurm options it was submitted with (a resubmission takes them, one retry less).
    options: SlurmOptions,
    /// Per stage with an array: its shards, each the unit ids it runs.
    shards: BTreeMap<String, Vec<Vec<String>>>,
    /// Per stage with an array: the shards submitted (the others' units were all cached).
    tasks: BTreeMap<String, BTreeSet<u32>>,
    arrays: BTreeMap<String, SubmittedArray>,
    commit: Option<SubmittedArray>,
    /// In-allocation runs: the allocation's job id (no arrays, no commit job).
    #[serde(default)]
    allocation: Option<String>,
    /// Units of `keep: false` stages made again for the units that read them (see [`Rerun`]).
    #[serde(default)]
    remake: BTreeMap<String, BTreeMap<String, String>>,
    /// The stages whose records go in two-level folders (`layout::placed`), decided by the
    /// planner from all of a stage's units, so every task and the commit job agree.
    #[serde(default)]
    fanned: BTreeSet<String>,
    /// The per-record stages of `fanned`, cut into shards by bucket (`layout::fan_bucket`)
    /// rather than by consecutive ids: shard i of each runs the units of buckets `ranges[i]`.
    #[serde(default)]
    bucketed: BTreeSet<String>,
    /// The 256 buckets cut into contiguous ranges `[first, end)`, one per shard of the
    /// bucketed stages.
    #[serde(default)]
    ranges: Vec<[u16; 2]>,
    /// The bucketed stages each of whose units reads only records of its own bucket
    /// (`StatusLine::closed`): their task i needs only shard i of the bucketed stages they read.
    #[serde(default)]
    closed: BTreeSet<String>,
}

impl RunFile {
    /// A run of `plan` with nothing submitted yet; `allocation` for an in-allocation run.
    fn new(
        id: &str,
        plan: &Plan,
        options: &RunOptions,
        slurm: &SlurmOptions,
        allocation: Option<String>,
    ) -> anyhow::Result<RunFile> {
        Ok(RunFile {
            id: id.to_string(),
            pipeline: std::fs::canonicalize(&plan.file.path)?,
            pipeline_hash: crate::io::hash::hash_bytes(plan.file.text.as_bytes()),
            force: options.force.clone(),
            only: options.only.clone(),
            keep_going: options.keep_going,
            options: SlurmOptions { wait: false, ..slurm.clone() },
            shards: BTreeMap::new(),
            tasks: BTreeMap::new(),
            arrays: BTreeMap::new(),
            commit: None,
            allocation,
            remake: BTreeMap::new(),
            fanned: BTreeSet::new(),
            bucketed: BTreeSet::new(),
            ranges: Vec::new(),
            closed: BTreeSet::new(),
        })
    }

    /// Whether shard `shard` of `stage` was submitted (has a task) in this run.
    fn submitted(&self, stage: &str, shard: usize) -> bool {
        self.tasks.get(stage).is_some_and(|t| t.contains(&(shard as u32)))
    }

    /// The buckets of shard `shard` of a bucketed stage.
    fn buckets(&self, shard: usize) -> BTreeSet<u8> {
        let [first, end] = self.ranges.get(shard).copied().unwrap_or([0, 0]);
        (first..end).filter_map(|b| u8::try_from(b).ok()).collect()
    }

    /// The shard of a bucketed stage that runs the units of bucket `bucket`.
    fn shard_of(&self, bucket: u8) -> usize {
        self.ranges.iter().position(|[first, end]| (*first..*end).contains(&u16::from(bucket))).unwrap_or(0)
    }

    fn commit_job(&self) -> String {
        self.commit.as_ref().expect("submitted runs have a commit job").parts[0].job_id.to_string()
    }
}

/// A task's manifest: every unit of its shard, and what the stage's planning found.
#[derive(Debug, Serialize, Deserialize)]
struct Manifest {
    records: Vec<UnitRecord>,
    vanished: Vec<String>,
    upstream_tainted: bool,
}

#[derive(Debug, Default, Serialize, Deserialize)]
struct Summary {
    failed: Vec<(String, String, String)>,
    flagged: Vec<(String, String, String)>,
    committed_units: usize,
    /// With retries left after a failure: the run that resubmitted the failed shards.
    #[serde(default)]
    retried_as: Option<String>,
    /// Why the commit job committed nothing (e.g. a link in the output folder), for `--wait`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

fn runs_dir(output_dir: &Path) -> PathBuf {
    output_dir.join(STATE_DIR).join(RUNS_DIR)
}

fn read_run(run_dir: &Path) -> anyhow::Result<RunFile> {
    let path = run_dir.join(RUN_FILE);
    let bytes = std::fs::read(&path).with_context(|| format!("reading `{}`", path.display()))?;
    serde_json::from_slice(&bytes).with_context(|| format!("`{}` is damaged", path.display()))
}

/// A committed Slurm run's summary as `run` reports a local run's.
fn run_summary(summary: &Summary) -> RunSummary {
    let problem = |(stage, unit, reason): &(String, String, String)| UnitProblem {
        stage: stage.clone(),
        unit: unit.clone(),
        reason: reason.clone(),
    };
    RunSummary {
        reports: Vec::new(),
        failed: summary.failed.iter().map(problem).collect(),
        flagged: summary.flagged.iter().map(problem).collect(),
    }
}

/// Writes `bytes` to `path` through a temp file named by host and job, then a rename.
fn publish(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    let tmp = path.with_extension(format!("tmp-{}", task_tag()));
    std::fs::write(&tmp, bytes).with_context(|| format!("writing `{}`", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("renaming into `{}`", path.display()))
}

/// `<host>-<job id>`: unique to one attempt of one task.
fn task_tag() -> String {
    let host =
        std::env::var("SLURMD_NODENAME").or_else(|_| std::env::var("HOSTNAME")).unwrap_or_else(|_| "host".into());
    let job = std::env::var("SLURM_JOB_ID").unwrap_or_else(|_| std::process::id().to_string());
    format!("{host}-{job}")
}

fn pipeline_plan(run: &RunFile, registry: Registry) -> anyhow::Result<Plan> {
    let file = PipelineFile::read(&run.pipeline)?;
    if crate::io::hash::hash_bytes(file.text.as_bytes()) != run.pipeline_hash {
        bail!(
            "the pipeline `{}` changed since the Slurm run `{}` was submitted; rerun `shakeflow run` to submit the new one",
            run.pipeline.display(),
            run.id
        );
    }
    Ok(Plan::new(file, registry)?)
}

/// The Slurm backend: job arrays and a commit job, or with `in_allocation` the `srun` steps of
/// the allocation this process runs in.
impl Backend for SlurmOptions {
    fn check(&self) -> anyhow::Result<()> {
        self.executor.check().map_err(|e| e.error)?;
        if self.executor.in_allocation == Some(true) {
            crate::pipeline::slurm::Allocation::current()?;
        }
        Ok(())
    }

    fn run(&self, opened: Opened<'_>, reporter: &Reporter) -> anyhow::Result<RunSummary> {
        if self.executor.in_allocation == Some(true) {
            return run_in_allocation(opened, self, reporter);
        }
        submit(opened, self, reporter)
    }
}

/// Submits the run and returns at once (or, with `wait`, when it is committed).
fn submit(opened: Opened<'_>, slurm: &SlurmOptions, reporter: &Reporter) -> anyhow::Result<RunSummary> {
    let (plan, options, selected) = (opened.plan, opened.options, &opened.selected);
    let output_dir = plan.file.output_dir();
    let prediction = predict(plan, &opened.known(), Some(&opened.selected))?;
    let lease = opened.lease;
    save_hash_memo(reporter);
    let client = Slurm::new();
    let limits = client.limits()?;
    let sources = &opened.sources;
    let Some(run) = submit_run(plan, options, slurm, reporter, (&prediction, sources), selected, &client, &limits)?
    else {
        reporter.line("every unit is up to date: nothing submitted");
        return Ok(RunSummary::default());
    };
    let commit_job = run.commit_job();
    lease.hand_over(&run.id, &commit_job)?;
    reporter.line(&format!(
        "Slurm run `{}` submitted (commit job {commit_job}); `shakeflow status {}` follows it",
        run.id,
        plan.file.path.display()
    ));
    if !slurm.wait {
        return Ok(RunSummary::default());
    }
    wait(&client, &limits, run, &output_dir, reporter)
}

/// Saves the hashes planning read (the lease is held), so the next plan need not read them.
fn save_hash_memo(reporter: &Reporter) {
    if let Err(e) = crate::io::hash::save_memo() {
        reporter.line(&format!("warning: the hash memo was not saved ({e:#}); the next run reads every file"));
    }
}

/// Where the planner lists the source files of shard `shard` of a closed stage.
fn listing_path(run_dir: &Path, stage: &str, shard: usize) -> PathBuf {
    run_dir.join(RUN_LISTINGS).join(stage).join(format!("{shard}.json"))
}

/// A new run's id: `shakeflow-<pipeline file stem>-<clock>`, a Slurm job name.
fn new_run_id(plan: &Plan) -> String {
    let stem = plan.file.path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let stem: String =
        stem.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).take(24).collect();
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
    format!("shakeflow-{stem}-{:x}", nanos % 0xffff_ffff)
}

/// What planning found: the prediction, and the sources it resolved (a closed stage's shards get
/// their sources' files listed from these).
type Planned<'a> = (&'a Prediction, &'a BTreeMap<String, ResolvedSource>);

/// Makes a run folder and submits the arrays of `lines`' stale units (and units gone) and the
/// commit job; None (and no folder) when there are none. The caller hands its lease to the run.
#[allow(clippy::too_many_arguments)]
fn submit_run(
    plan: &Plan,
    options: &RunOptions,
    slurm: &SlurmOptions,
    reporter: &Reporter,
    planned: Planned<'_>,
    selected: &BTreeSet<String>,
    client: &Slurm,
    limits: &crate::pipeline::slurm::ClusterLimits,
) -> anyhow::Result<Option<RunFile>> {
    let output_dir = plan.file.output_dir();
    let id = new_run_id(plan);
    let run_dir = runs_dir(&output_dir).join(&id);
    let shakeflow = std::env::current_exe().context("locating the shakeflow binary")?;
    std::fs::create_dir_all(&run_dir)?;
    let naming = RunNaming { id: &id, run_dir: &run_dir, shakeflow: &shakeflow };
    let submitted = submit_arrays(plan, options, slurm, reporter, planned, selected, client, limits, naming);
    if !matches!(submitted, Ok(Some(_))) {
        let _ = std::fs::remove_dir_all(&run_dir);
        let _ = std::fs::remove_dir(runs_dir(&output_dir));
    }
    submitted
}

/// Per stage in run order, its shards cut from the predicted units, and those holding a stale
/// unit (the shards to run); stages with neither a stale unit nor one gone are left out.
/// Decides which stages fan out and which are cut by bucket (`run.fanned`, `bucketed`,
/// `ranges`, `closed`): a bucketed stage's shard i holds the units of buckets `ranges[i]`,
/// consecutive ids otherwise. A bucketed stage also runs the shards holding a unit gone from
/// its inputs: their task, which reads only its buckets of the state, is the one that sees it
/// gone. Any other stage's task sees every unit gone: a stage whose only change is a unit gone
/// runs its first shard (none of its units is stale: the task only says what is gone), so that
/// the commit job removes it as a local run does.
fn cut_shards(
    run: &mut RunFile,
    plan: &Plan,
    lines: &[StatusLine],
    selected: &BTreeSet<String>,
    per_task: usize,
) -> Vec<(String, Vec<Vec<String>>, BTreeSet<u32>)> {
    let per_task = per_task.max(1);
    run.fanned = fanned_stages(lines);
    let per_record = |name: &str| plan.stages[name].stage.work_units() != WorkUnits::Gather;
    run.bucketed = lines
        .iter()
        .filter(|l| selected.contains(&l.name) && run.fanned.contains(&l.name) && per_record(&l.name))
        .map(|l| l.name.clone())
        .collect();
    run.closed = lines.iter().filter(|l| l.closed && run.bucketed.contains(&l.name)).map(|l| l.name.clone()).collect();
    run.ranges = bucket_ranges(lines.iter().filter(|l| run.bucketed.contains(&l.name)), per_task);
    lines
        .iter()
        .filter(|l| selected.contains(&l.name) && !(l.stale.is_empty() && l.vanished.is_empty()))
        .map(|line| {
            let stale: BTreeSet<&str> = line.stale.iter().map(|u| u.id.as_str()).collect();
            let (shards, only) = if run.bucketed.contains(&line.name) {
                let mut shards: Vec<Vec<String>> = vec![Vec::new(); run.ranges.len()];
                for id in &line.ids {
                    shards[run.shard_of(fan_bucket(id))].push(id.clone());
                }
                let mut only: BTreeSet<u32> = (0..shards.len() as u32)
                    .filter(|&i| shards[i as usize].iter().any(|id| stale.contains(id.as_str())))
                    .collect();
                only.extend(line.vanished.iter().map(|id| run.shard_of(fan_bucket(id)) as u32));
                (shards, only)
            } else {
                let mut shards: Vec<Vec<String>> = line.ids.chunks(per_task).map(<[String]>::to_vec).collect();
                let mut only: BTreeSet<u32> = (0..shards.len() as u32)
                    .filter(|&i| shards[i as usize].iter().any(|id| stale.contains(id.as_str())))
                    .collect();
                if only.is_empty() {
                    // Only units gone (every one of them, when no shard is left).
                    if shards.is_empty() {
                        shards.push(Vec::new());
                    }
                    only.insert(0);
                }
                (shards, only)
            };
            (line.name.clone(), shards, only)
        })
        .collect()
}

/// The 256 buckets cut into contiguous ranges of about `per_task` units each of the largest of
/// `lines` (every bucketed stage takes the same ranges, so shard i of each holds the same
/// motions); none without a line.
fn bucket_ranges<'a>(lines: impl Iterator<Item = &'a StatusLine>, per_task: usize) -> Vec<[u16; 2]> {
    let Some(largest) = lines.max_by_key(|l| l.ids.len()) else { return Vec::new() };
    let mut counts = [0usize; 256];
    for id in &largest.ids {
        counts[usize::from(fan_bucket(id))] += 1;
    }
    let total = largest.ids.len();
    let shards = total.div_ceil(per_task).clamp(1, 256);
    let mut ranges = Vec::with_capacity(shards);
    let (mut first, mut sum) = (0u16, 0usize);
    for (bucket, count) in counts.iter().enumerate() {
        sum += count;
        // Close a range once it holds its share of the units (the last takes the rest).
        if ranges.len() + 1 < shards && sum * shards >= (ranges.len() + 1) * total {
            ranges.push([first, bucket as u16 + 1]);
            first = bucket as u16 + 1;
        }
    }
    ranges.push([first, 256]);
    ranges.retain(|[first, end]| first < end); // the last may hold nothing when buckets are skewed
    ranges
}

/// The stages with more records than one folder should hold (`layout::fans_out`).
fn fanned_stages(lines: &[StatusLine]) -> BTreeSet<String> {
    let limit = fan_out_above();
    lines.iter().filter(|l| fans_out(l.ids.iter().map(String::as_str), limit)).map(|l| l.name.clone()).collect()
}

/// Whether shard i of `stage` reads only shard i of `upstream`: both per-record and cut alike,
/// or both cut by the same buckets and each unit of `stage` reading only its own bucket.
fn aligned(plan: &Plan, run: &RunFile, stage: &str, upstream: &str) -> bool {
    let by_bucket = run.closed.contains(stage) && run.bucketed.contains(upstream) && run.shards.contains_key(upstream);
    by_bucket
        || plan.stages[stage].stage.work_units() == WorkUnits::EachRecord
            && plan.stages[upstream].stage.work_units() == WorkUnits::EachRecord
            && run.shards.contains_key(upstream)
            && run.shards.get(upstream) == run.shards.get(stage)
}

/// `--in-allocation`: inside one `sbatch`/`salloc` allocation, each stage's shards run as
/// `srun` steps (as many at once as the allocation has tasks), stage after stage; a failed
/// step is run again up to `retries` times; then this process commits, as a commit job would.
fn run_in_allocation(opened: Opened<'_>, slurm: &SlurmOptions, reporter: &Reporter) -> anyhow::Result<RunSummary> {
    let allocation = crate::pipeline::slurm::Allocation::current()?;
    let (plan, options) = (opened.plan, opened.options);
    let output_dir = plan.file.output_dir();
    let prediction = predict(plan, &opened.known(), Some(&opened.selected))?;
    let lease = opened.lease;
    save_hash_memo(reporter);
    let id = new_run_id(plan);
    let mut run = RunFile::new(&id, plan, options, slurm, Some(allocation.job_id.clone()))?;
    let cut = cut_shards(&mut run, plan, &prediction.lines, &opened.selected, slurm.units_per_task);
    if cut.is_empty() {
        reporter.line("every unit is up to date: nothing to run");
        return Ok(RunSummary::default());
    }
    let run_dir = runs_dir(&output_dir).join(&id);
    run.remake = prediction.remake;
    let order: Vec<String> = cut.iter().map(|(name, _, _)| name.clone()).collect();
    for (name, shards, only) in cut {
        run.shards.insert(name.clone(), shards);
        run.tasks.insert(name, only);
    }
    std::fs::create_dir_all(run_dir.join(RUN_LOGS))?;
    publish(&run_dir.join(RUN_FILE), &serde_json::to_vec_pretty(&run)?)?;
    reporter.line(&format!(
        "Slurm run `{id}` in allocation {}: {} step(s) at once, {} CPU(s) each",
        allocation.job_id, allocation.slots, allocation.cpus_per_step
    ));
    let shakeflow = std::env::current_exe().context("locating the shakeflow binary")?;
    let retries = slurm.executor.retries.unwrap_or(0);
    let mut failed: BTreeMap<&str, BTreeSet<u32>> = BTreeMap::new();
    for name in &order {
        let mut todo = run.tasks[name].clone();
        if !run.keep_going {
            // As afterok/aftercorr would: nothing waits on a failed upstream shard.
            for upstream in upstream_stages(&plan.stages[name]) {
                match failed.get(upstream) {
                    Some(f) if !f.is_empty() && aligned(plan, &run, name, upstream) => todo.retain(|s| !f.contains(s)),
                    Some(f) if !f.is_empty() => todo.clear(),
                    _ => {}
                }
            }
        }
        let mut not_run: BTreeSet<u32> = run.tasks[name].difference(&todo).copied().collect();
        let mut attempt = 0;
        loop {
            let failures = run_steps(&allocation, &shakeflow, &run_dir, &id, name, &todo);
            reporter.line(&format!(
                "{name:<18} {} step(s), {} failed{}",
                todo.len(),
                failures.len(),
                if attempt > 0 { format!(" (retry {attempt})") } else { String::new() }
            ));
            if failures.is_empty() || attempt == retries {
                not_run.extend(failures);
                break;
            }
            attempt += 1;
            todo = failures;
        }
        failed.insert(name, not_run);
    }
    let (summary, _) = commit_manifests(&run_dir, &run, plan, &lease, &Steps(None))?;
    publish(&runs_dir(&output_dir).join(format!("{id}{SUMMARY_SUFFIX}")), &serde_json::to_vec_pretty(&summary)?)?;
    drop(lease);
    Ok(run_summary(&summary))
}

/// Runs `shards` of `stage` as `srun` steps, `allocation.slots` at once; the shards that failed.
fn run_steps(
    allocation: &crate::pipeline::slurm::Allocation,
    shakeflow: &Path,
    run_dir: &Path,
    id: &str,
    stage: &str,
    shards: &BTreeSet<u32>,
) -> BTreeSet<u32> {
    let queue = std::sync::Mutex::new(shards.iter().copied().collect::<std::collections::VecDeque<u32>>());
    let failed = std::sync::Mutex::new(BTreeSet::new());
    let threads = [("RAYON_NUM_THREADS", allocation.cpus_per_step.to_string())];
    std::thread::scope(|scope| {
        for _ in 0..allocation.slots.min(shards.len()) {
            scope.spawn(|| loop {
                let Some(shard) = queue.lock().expect("no step thread panics").pop_front() else { break };
                let args = [
                    "slurm-task".into(),
                    run_dir.as_os_str().to_owned(),
                    stage.into(),
                    format!("--shard={shard}").into(),
                ];
                let log = run_dir.join(RUN_LOGS).join(format!("{id}_{stage}_{shard}.out"));
                let ok = allocation.run_step(id, shakeflow, &args, &threads, &log).unwrap_or_else(|e| {
                    eprintln!("error: {e}");
                    false
                });
                if !ok {
                    failed.lock().expect("no step thread panics").insert(shard);
                }
            });
        }
    });
    failed.into_inner().expect("no step thread panics")
}

/// The run's name, folder and the binary its tasks run.
struct RunNaming<'a> {
    id: &'a str,
    run_dir: &'a Path,
    shakeflow: &'a Path,
}

/// Submits an array per stage with stale units or units gone, and the commit job; None when
/// there is neither.
#[allow(clippy::too_many_arguments)]
fn submit_arrays(
    plan: &Plan,
    options: &RunOptions,
    slurm: &SlurmOptions,
    reporter: &Reporter,
    (prediction, sources): Planned<'_>,
    selected: &BTreeSet<String>,
    client: &Slurm,
    limits: &crate::pipeline::slurm::ClusterLimits,
    naming: RunNaming<'_>,
) -> anyhow::Result<Option<RunFile>> {
    let RunNaming { id, run_dir, shakeflow } = naming;
    let per_task = slurm.units_per_task.max(1);
    let lines = &prediction.lines;
    let mut run = RunFile::new(id, plan, options, slurm, None)?;
    run.remake = prediction.remake.clone();
    let quote = |p: &Path| format!("'{}'", p.display().to_string().replace('\'', r"'\''"));
    let line_of: BTreeMap<&str, &StatusLine> = lines.iter().map(|l| (l.name.as_str(), l)).collect();
    for (name, shards, only) in cut_shards(&mut run, plan, lines, selected, per_task) {
        let stage = &plan.stages[&name];
        run.shards.insert(name.clone(), shards.clone());
        let mut dependencies = Vec::new();
        for upstream in upstream_stages(stage) {
            let Some(array) = run.arrays.get(upstream) else { continue };
            let aligned = aligned(plan, &run, &name, upstream) && only.is_subset(&run.tasks[upstream]);
            let kind = if options.keep_going {
                DepKind::AfterAny
            } else if aligned {
                DepKind::AfterCorr
            } else {
                DepKind::AfterOk
            };
            dependencies.push(Dependency { on: array.clone(), kind });
        }
        // Each shard's records of the sources this stage reads, listed here once: its task
        // reads them instead of walking the archive.
        let mut names = source_inputs(stage);
        names.retain(|source| plan.file.spec.inputs.get(*source).is_some_and(Listed::lists));
        if run.closed.contains(&name) && !names.is_empty() {
            let shards: BTreeSet<usize> = only.iter().map(|&s| s as usize).collect();
            let write = |shard: usize, listed: &BTreeMap<String, Listed>| -> anyhow::Result<()> {
                let path = listing_path(run_dir, &name, shard);
                std::fs::create_dir_all(path.parent().expect("a listing is in a folder"))?;
                publish(&path, &serde_json::to_vec(listed)?)
            };
            for (shard, listed) in listings(plan, sources, &names, &shards, |bucket| run.shard_of(bucket)) {
                write(shard, &listed).map_err(|e| cancel_all(client, &run, UserError::new(format!("{e:#}"))))?;
            }
        }
        let command = format!("{} slurm-task {} {name}", quote(shakeflow), quote(run_dir));
        let job = ArrayJob {
            name: id.to_string(),
            command,
            n_tasks: shards.len() as u32,
            only: Some(only.clone()),
            dependencies,
            options: slurm.executor.clone(),
            log_dir: run_dir.join(RUN_LOGS),
        };
        let array = client.submit(&job, limits).map_err(|e| cancel_all(client, &run, e))?;
        let line = line_of[name.as_str()];
        let gone = match line.vanished.len() {
            0 => String::new(),
            n => format!(", {n} gone"),
        };
        reporter.line(&format!(
            "{name:<18} submitted: {} of {} shard(s), {} stale unit(s) of {}{gone} ({})",
            only.len(),
            shards.len(),
            line.stale.len(),
            line.units,
            array.parts.iter().map(|p| p.job_id.to_string()).collect::<Vec<_>>().join(", ")
        ));
        run.tasks.insert(name.clone(), only);
        run.arrays.insert(name, array);
    }
    if run.arrays.is_empty() {
        return Ok(None);
    }
    let commit = ArrayJob {
        name: id.to_string(),
        command: format!("{} slurm-commit {}", quote(shakeflow), quote(run_dir)),
        n_tasks: 1,
        only: None,
        dependencies: run.arrays.values().map(|a| Dependency { on: a.clone(), kind: DepKind::AfterAny }).collect(),
        options: ExecutorOptions { array_throttle: None, ..slurm.executor.clone() },
        log_dir: run_dir.join(RUN_LOGS),
    };
    let commit = client.submit(&commit, limits).map_err(|e| cancel_all(client, &run, e))?;
    run.commit = Some(commit);
    publish(&run_dir.join(RUN_FILE), &serde_json::to_vec_pretty(&run)?)?;
    Ok(Some(run))
}

/// Cancels what was submitted before `error` stopped the submission.
fn cancel_all(client: &Slurm, run: &RunFile, error: UserError) -> UserError {
    let arrays: Vec<SubmittedArray> = run.arrays.values().cloned().collect();
    let _ = client.cancel(&arrays);
    error
}

/// `--wait`: polls with backoff until the commit job ended, then reads its summary; follows
/// the runs that resubmitted failed shards (`retries`) to the last one.
fn wait(
    client: &Slurm,
    limits: &crate::pipeline::slurm::ClusterLimits,
    mut run: RunFile,
    output_dir: &Path,
    reporter: &Reporter,
) -> anyhow::Result<RunSummary> {
    let summary = loop {
        let mut arrays: Vec<SubmittedArray> = run.arrays.values().cloned().collect();
        arrays.extend(run.commit.clone());
        let mut status = crate::pipeline::slurm::RunStatus::new(&arrays);
        client.wait(&mut status, limits, Default::default(), |s| {
            reporter.line(&format!("Slurm run `{}`: {} task(s) not finished", run.id, s.unfinished()))
        })?;
        let path = runs_dir(output_dir).join(format!("{}{SUMMARY_SUFFIX}", run.id));
        let bytes = std::fs::read(&path).map_err(|e| {
            UserError::new(format!(
                "the commit job {} of the Slurm run `{}` ended without its summary `{}` ({e}): it did not \
                 start, or it died (out of disk space or memory, its node lost)",
                run.commit_job(),
                run.id,
                path.display()
            ))
            .hint(format!(
                "its log is in `{}`; the commit is all or nothing: `shakeflow status` says what is committed, \
                 and running again finishes the run once the dead job's lease is free (taken over a minute \
                 after its last heartbeat once Slurm no longer knows the job, else after 10 minutes, or \
                 `{}` deleted by you once you know the job is gone)",
                runs_dir(output_dir).join(&run.id).join(RUN_LOGS).display(),
                output_dir.join(STATE_DIR).join(LEASE_FILE).display()
            ))
        })?;
        let summary: Summary = serde_json::from_slice(&bytes)?;
        if let Some(error) = &summary.error {
            bail!("the commit job of the Slurm run `{}` committed nothing: {error}", run.id);
        }
        let Some(next) = summary.retried_as else { break summary };
        run = read_run(&runs_dir(output_dir).join(&next))?;
        reporter.line(&format!(
            "Slurm run `{next}`: {} failed unit(s) resubmitted (commit job {})",
            summary.failed.len(),
            run.commit_job()
        ));
    };
    Ok(run_summary(&summary))
}

/// The files each upstream stage of `stage` has this run: committed ones (lockfile) overlaid
/// with what its tasks' manifests say; and whether any upstream unit failed or did not finish.
fn upstream_produced(
    run_dir: &Path,
    run: &RunFile,
    plan: &Plan,
    lock: &LockFile,
    stage: &str,
    shard: usize,
) -> anyhow::Result<(BTreeMap<String, Produced>, bool)> {
    let mut produced = BTreeMap::new();
    let mut tainted = false;
    // Only a failure upstream taints `stage`: a stage of another branch may not have finished.
    let upstream = plan.with_upstream([stage]);
    for (name, _) in plan.stages.iter().filter(|(n, _)| n.as_str() != stage && upstream.contains(n.as_str())) {
        let stage_dir = plan.stage_dir(name);
        let committed = |id: &str| -> Produced {
            lock.stages.get(name).and_then(|e| e.units.get(id)).map(|u| cached_files(u, &stage_dir)).unwrap_or_default()
        };
        let mut files = Produced::new();
        match run.shards.get(name) {
            None => {
                for unit in
                    lock.stages.get(name).map(|e| e.units.keys().cloned().collect::<Vec<_>>()).unwrap_or_default()
                {
                    files.extend(committed(&unit));
                }
            }
            Some(shards) => {
                // Aligned shards (`aftercorr`): this task's units read its own upstream shard
                // only; the others may still be running, and their state is not this task's.
                let own = aligned(plan, run, stage, name).then_some(shard);
                for (index, ids) in shards.iter().enumerate() {
                    let counts = own.is_none_or(|own| own == index);
                    if !counts && run.bucketed.contains(name) {
                        continue; // another shard's buckets, whose state this task did not read
                    }
                    let path = run_dir.join(RUN_MANIFESTS).join(name).join(format!("{index}.json"));
                    let Ok(bytes) = std::fs::read(&path) else {
                        // Not submitted (all cached) or not finished: what is committed stands
                        // (so its records are not taken for gone).
                        let submitted = run.submitted(name, index);
                        tainted |= submitted && counts;
                        if !submitted || !counts {
                            for id in ids {
                                files.extend(committed(id));
                            }
                        }
                        continue;
                    };
                    let manifest: Manifest = serde_json::from_slice(&bytes)?;
                    tainted |= manifest.upstream_tainted && counts;
                    for record in manifest.records {
                        match record.outcome {
                            UnitOutcome::Cached => files.extend(committed(&record.id)),
                            UnitOutcome::Ran { dir, files: written, .. } => files.extend(
                                written
                                    .into_iter()
                                    .map(|(f, hash)| (f.clone(), ProducedFile { path: dir.join(&f), hash })),
                            ),
                            UnitOutcome::Failed { .. } => tainted |= counts,
                            UnitOutcome::Flagged { .. } => {}
                        }
                    }
                }
            }
        }
        produced.insert(name.clone(), files);
    }
    Ok((produced, tainted))
}

/// `shakeflow slurm-task RUN_DIR STAGE`: one array task, its shard from `$SLURM_ARRAY_TASK_ID`.
pub fn task(run_dir: &Path, stage_name: &str, shard: usize, registry: Registry) -> anyhow::Result<bool> {
    crate::pipeline::failpoint::hit(&format!("slurm-task.{stage_name}.{shard}"))?;
    let steps = Steps::start(format!("{stage_name} shard {shard}"));
    let run = read_run(run_dir)?;
    let plan = pipeline_plan(&run, registry)?;
    steps.done("run and pipeline read");
    let stage = plan.stages.get(stage_name).ok_or_else(|| anyhow!("the pipeline has no stage `{stage_name}`"))?;
    let shards = run.shards.get(stage_name).ok_or_else(|| anyhow!("stage `{stage_name}` has no array in this run"))?;
    let mine: BTreeSet<&str> =
        shards.get(shard).ok_or_else(|| anyhow!("no shard {shard}"))?.iter().map(String::as_str).collect();
    let known: BTreeSet<&str> = shards.iter().flatten().map(String::as_str).collect();
    let last = shard + 1 == shards.len();
    let bucketed = run.bucketed.contains(stage_name);
    let buckets = run.buckets(shard);
    let output_dir = plan.file.output_dir();
    // Only this stage's state and the stages it reads: of each cut by the same buckets, only
    // this shard's buckets. That is what the task plans with.
    let mut wanted: Wanted = BTreeMap::from([(stage_name.to_string(), bucketed.then(|| buckets.clone()))]);
    for upstream in upstream_stages(stage) {
        let own = aligned(&plan, &run, stage_name, upstream) && run.bucketed.contains(upstream);
        wanted.insert(upstream.to_string(), own.then(|| buckets.clone()));
    }
    let (lock, read) = LockFile::read_stages(&output_dir.join(LOCK_FILE), &wanted)?;
    eprintln!("{stage_name} shard {shard}: read {} state file(s), {} bytes", read.files, read.bytes);
    steps.done("state read");
    // The sources this stage reads, of a closed bucketed stage only its buckets' records.
    let own_records = (bucketed && run.closed.contains(stage_name)).then_some(&buckets);
    // Their files as the planner listed them for this shard, where it did (not in an allocation).
    let listed = match own_records {
        Some(_) => Listed::read(&listing_path(run_dir, stage_name, shard), &plan.file.base_dir())?,
        None => None,
    };
    let listed = listed.map(|(listed, kept, gone)| {
        eprintln!("{stage_name} shard {shard}: {kept} source file(s) as the planner listed them ({gone} gone since)");
        listed
    });
    let sources = resolve_sources_of(&plan, Some(stage_name), own_records, listed.as_ref())?;
    let files = param_file_hashes(&plan)?;
    let (produced, upstream_tainted) = upstream_produced(run_dir, &run, &plan, &lock, stage_name, shard)?;
    let rerun = Rerun { stages: forced_stages(&plan, &run.force), remake: run.remake.clone() };
    let state = Known { lock: &lock, sources: &sources, files: &files, rerun: &rerun, disk: &RealDisk::default() };
    let assessed = assess_stage(&plan, stage, &state, &produced)?;
    steps.done("sources resolved and units assessed");
    let (memo_files, memo_bytes) = crate::io::hash::memo_files_read();
    eprintln!("{stage_name} shard {shard}: read {memo_files} hash memo file(s), {memo_bytes} bytes");
    // A unit nobody predicted (a partition no earlier output had) goes to the last shard, or
    // to the shard of its bucket.
    let ours: Vec<&(crate::pipeline::work_units::Unit, String, Vec<String>)> = assessed
        .units
        .iter()
        .filter(|(u, _, _)| match bucketed {
            true => run.shard_of(fan_bucket(&u.id)) == shard,
            false => mine.contains(u.id.as_str()) || (last && !known.contains(u.id.as_str())),
        })
        .collect();
    if bucketed {
        // What the planner found (each unit reads only its own bucket) must still hold for what
        // this task sees. (A part of a bucket it did not read is invisible to it: this catches a
        // unit reading another bucket's record through what it did read, not every change.)
        let elsewhere = |p: &crate::pipeline::stage::InputPart| {
            !p.partition.is_empty()
                && !buckets.contains(&fan_bucket(&crate::pipeline::layout::partition_path(&p.partition)))
        };
        for (unit, _, _) in &ours {
            let dataset =
                unit.inputs.iter().filter(|i| matches!(i, crate::pipeline::stage::StageInput::Dataset { .. }));
            if let Some(part) = dataset.flat_map(|i| i.parts()).find(|p| elsewhere(p)) {
                bail!(
                    "{} reads `{}`, of a bucket this task did not read; run again (the planner will read whole stages)",
                    crate::pipeline::work_units::describe(&unit.id),
                    part.label
                );
            }
        }
    }
    let stale: Vec<&(crate::pipeline::work_units::Unit, String, Vec<String>)> =
        ours.iter().copied().filter(|(_, _, r)| !r.is_empty()).collect();
    let results = run_dir.join(RUN_RESULTS).join(stage_name);
    std::fs::create_dir_all(&results)?;
    let tmp = results.join(format!("{shard}.tmp-{}", task_tag()));
    let done = results.join(shard.to_string());
    let _ = std::fs::remove_dir_all(&tmp);
    let memo = Arc::new(TableMemo::new(0));
    let ran = execute(
        &plan,
        stage,
        &stale,
        &tmp,
        &memo,
        0,
        &indicatif::ProgressBar::hidden(),
        run.fanned.contains(stage_name),
    );
    steps.done("units ran");
    if done.exists() {
        std::fs::remove_dir_all(&done)?; // an earlier attempt of this shard
    }
    if tmp.exists() {
        std::fs::rename(&tmp, &done)?;
    }
    let mut by_id: BTreeMap<String, UnitRecord> = ran.into_iter().map(|r| (r.id.clone(), r)).collect();
    let records: Vec<UnitRecord> = ours
        .iter()
        .map(|(unit, _, _)| {
            let mut record = by_id.remove(&unit.id).unwrap_or_else(|| UnitRecord::cached(&unit.id));
            if let UnitOutcome::Ran { dir, .. } = &mut record.outcome {
                *dir = done.clone();
            }
            record
        })
        .collect();
    let failed = records.iter().filter(|r| matches!(r.outcome, UnitOutcome::Failed { .. })).count();
    for record in &records {
        if let UnitOutcome::Failed { reason } = &record.outcome {
            eprintln!(
                "error: stage `{stage_name}` {} failed: {reason}",
                crate::pipeline::work_units::describe(&record.id)
            );
        }
    }
    // Of a bucketed stage, only this shard's buckets are this task's to call gone.
    let mut vanished = assessed.vanished.clone();
    if bucketed {
        vanished.retain(|id| run.shard_of(fan_bucket(id)) == shard);
    }
    let manifest = Manifest { records, vanished, upstream_tainted };
    let manifests = run_dir.join(RUN_MANIFESTS).join(stage_name);
    std::fs::create_dir_all(&manifests)?;
    publish(&manifests.join(format!("{shard}.json")), &serde_json::to_vec(&manifest)?)?;
    steps.done("manifest written");
    eprintln!("{stage_name} shard {shard}: {} unit(s), {} ran, {failed} failed", ours.len(), stale.len());
    if failed == 0 && !upstream_tainted {
        drop_consumed(run_dir, &run, &plan, stage_name, shard);
    }
    Ok(failed == 0)
}

/// Removes the results of shard `shard` of each `keep: false` stage that only `stage` reads,
/// aligned with it, once this task (shard `shard` of `stage`) has read them and succeeded:
/// the run's scratch then holds a stage's intermediates only until their reader is done, not
/// until the commit job (at 10⁴ tests, 39 GB of them at once). The commit installs none of
/// them when every reader succeeded; when another shard's reader failed, it keeps the shards
/// not dropped (a local run would keep all): the entry holds every file's hash either way, and
/// a rerun makes again what it reads.
fn drop_consumed(run_dir: &Path, run: &RunFile, plan: &Plan, stage: &str, shard: usize) {
    for upstream in upstream_stages(&plan.stages[stage]) {
        let readers = plan.stages.values().filter(|s| upstream_stages(s).contains(upstream)).count();
        if plan.stages[upstream].keep || readers != 1 || !aligned(plan, run, stage, upstream) {
            continue;
        }
        let results = run_dir.join(RUN_RESULTS).join(upstream).join(shard.to_string());
        if results.exists() {
            // Marked first: the commit then knows these files are gone on purpose.
            if let Err(e) = std::fs::write(dropped_marker(&results), b"") {
                eprintln!("warning: `{}` was kept: {e}", results.display());
                continue;
            }
            match std::fs::remove_dir_all(&results) {
                Ok(()) => eprintln!("{stage} shard {shard}: removed `{upstream}`'s shard {shard}, read and not kept"),
                Err(e) => eprintln!("warning: `{}` was not removed: {e}", results.display()),
            }
        }
    }
}

/// The mark `drop_consumed` leaves beside a shard's results it removed: `<shard>.dropped`.
fn dropped_marker(results: &Path) -> PathBuf {
    results.with_extension("dropped")
}

/// What a job spent, step by step, in its log: `<who>: <step> (at S s, C s CPU)`, wall and CPU
/// seconds since it started (`bench/scale.py` reads them). `Steps(None)` is silent: the commit
/// of an in-allocation run, whose process commits after its steps.
struct Steps(Option<(std::time::Instant, String)>);

impl Steps {
    fn start(who: impl Into<String>) -> Steps {
        Steps(Some((std::time::Instant::now(), who.into())))
    }

    fn done(&self, what: &str) {
        let Some((started, who)) = &self.0 else { return };
        eprintln!(
            "{who}: {what} (at {:.3} s, {:.3} s CPU)",
            started.elapsed().as_secs_f64(),
            crate::pipeline::progress::cpu_seconds()
        );
    }
}

/// The units of stage `name` that its tasks saw gone, checked against what its tasks kept. One
/// task owns each unit: one saying it is gone and another running or keeping it is a
/// contradiction, and removing its files on that word could lose them: an error, nothing
/// committed. Except where an upstream unit failed (`upstream_tainted`): a unit whose task
/// failed, or never ran, is seen gone by the others then, and so is a unit whose upstream task
/// did not finish, by a task that ran under `--keep-going`, while a shard not run keeps it; the
/// stage is incomplete and keeps such a unit, as a local run keeps what a failed upstream unit
/// left.
fn gone_units(
    name: &str,
    records: &[UnitRecord],
    vanished: BTreeSet<String>,
    upstream_tainted: bool,
) -> anyhow::Result<Vec<String>> {
    let kept: BTreeSet<&str> =
        records.iter().filter(|r| !matches!(r.outcome, UnitOutcome::Failed { .. })).map(|r| r.id.as_str()).collect();
    if !upstream_tainted {
        if let Some(both) = vanished.iter().find(|id| kept.contains(id.as_str())) {
            bail!("stage `{name}`: {both} is both gone and kept by this run's tasks; nothing committed, run again");
        }
    }
    Ok(vanished.into_iter().filter(|id| !kept.contains(id.as_str())).collect())
}

/// `shakeflow slurm-commit RUN_DIR`: folds every task's manifest and commits, under the lease.
pub fn commit(run_dir: &Path, registry: Registry) -> anyhow::Result<()> {
    let steps = Steps::start("commit job");
    let run = read_run(run_dir)?;
    let plan = pipeline_plan(&run, registry)?;
    let output_dir = plan.file.output_dir();
    steps.done("run and pipeline read");
    let lease = Lease::take_handed(&output_dir, &run.id)?;
    steps.done("lease taken");
    let runs = runs_dir(&output_dir);
    let (mut summary, new_lock) = match commit_manifests(run_dir, &run, &plan, &lease, &steps) {
        Ok(committed) => committed,
        Err(error) => {
            let why = format!("{error:#}");
            let summary = Summary { error: Some(why), ..Summary::default() };
            publish(&runs.join(format!("{}{SUMMARY_SUFFIX}", run.id)), &serde_json::to_vec_pretty(&summary)?)?;
            return Err(error);
        }
    };
    let retries = run.options.executor.retries.unwrap_or(0);
    let retry = if summary.failed.is_empty() || retries == 0 {
        None
    } else {
        resubmit(&run, &plan, &new_lock, retries - 1).unwrap_or_else(|e| {
            eprintln!("error: the failed shards could not be resubmitted: {e:#}");
            None
        })
    };
    summary.retried_as = retry.as_ref().map(|r| r.id.clone());
    steps.done("retries decided");
    publish(&runs.join(format!("{}{SUMMARY_SUFFIX}", run.id)), &serde_json::to_vec_pretty(&summary)?)?;
    match retry {
        Some(next) => {
            let job = next.commit_job();
            lease.hand_over(&next.id, &job)?;
            eprintln!(
                "{} unit(s) failed: resubmitted as the Slurm run `{}` (commit job {job}, {} retr{} left after it)",
                summary.failed.len(),
                next.id,
                retries - 1,
                if retries == 2 { "y" } else { "ies" }
            );
            Ok(())
        }
        None => {
            drop(lease);
            if summary.failed.is_empty() {
                Ok(())
            } else {
                Err(anyhow!("{} unit(s) failed; the units that finished were committed", summary.failed.len()))
            }
        }
    }
}

/// Folds every shard's manifest as a local run folds its units and commits the results with
/// the lockfile, under `lease`; what failed is printed and summarised; returns the new lockfile.
fn commit_manifests(
    run_dir: &Path,
    run: &RunFile,
    plan: &Plan,
    lease: &Lease,
    steps: &Steps,
) -> anyhow::Result<(Summary, LockFile)> {
    let output_dir = plan.file.output_dir();
    let lock = LockFile::read(&output_dir.join(LOCK_FILE))?;
    steps.done("state read");
    let transaction = Transaction::begin(lease)?;
    let mut new_lock = lock.clone();
    new_lock.pipeline = Some(ownership::pipeline_label(&plan.file));
    let mut install: BTreeSet<String> = BTreeSet::new();
    let mut remove: BTreeSet<String> = BTreeSet::new();
    let mut tainted: BTreeSet<String> = BTreeSet::new();
    let mut summary = Summary::default();
    // What the tasks wrote (relative → where it is): moved into the transaction once the files
    // of `keep: false` stages are left out, which stay where they are and go with `results`.
    let mut produced: BTreeMap<String, PathBuf> = BTreeMap::new();
    for (name, stage) in &plan.stages {
        let Some(shards) = run.shards.get(name) else {
            if upstream_stages(stage).iter().any(|u| tainted.contains(*u)) {
                tainted.insert(name.clone());
            }
            continue;
        };
        let mut records = Vec::new();
        let mut vanished = BTreeSet::new();
        let mut upstream_tainted = upstream_stages(stage).iter().any(|u| tainted.contains(*u));
        for (shard, ids) in shards.iter().enumerate() {
            let path = run_dir.join(RUN_MANIFESTS).join(name).join(format!("{shard}.json"));
            match std::fs::read(&path) {
                Ok(bytes) => {
                    let manifest: Manifest = serde_json::from_slice(&bytes)?;
                    upstream_tainted |= manifest.upstream_tainted;
                    vanished.extend(manifest.vanished);
                    records.extend(manifest.records);
                }
                Err(_) if run.submitted(name, shard) => {
                    // The task did not finish (cancelled, timed out, killed): its units keep
                    // their committed state and count as failed.
                    records.extend(ids.iter().map(|id| UnitRecord {
                        id: id.clone(),
                        key: String::new(),
                        inputs: BTreeMap::new(),
                        outcome: UnitOutcome::Failed {
                            reason: format!("its Slurm task (shard {shard}) did not finish"),
                        },
                    }));
                }
                Err(_) => records.extend(ids.iter().map(|id| UnitRecord::cached(id))),
            }
        }
        let vanished = gone_units(name, &records, vanished, upstream_tainted)?;
        steps.done(&format!("{name}: {} manifest record(s) read", records.len()));
        let staging = transaction.new_path(plan.stage_path(name));
        let entry = lock.stages.get(name);
        // A unit the lockfile does not have cannot be cached: drop such records of shards not run.
        records.retain(|r| {
            !matches!(r.outcome, UnitOutcome::Cached) || entry.is_some_and(|e| e.units.contains_key(&r.id))
        });
        let fanned = run.fanned.contains(name);
        let folded = entry_from_outcomes(plan, stage, entry, records, &vanished, upstream_tainted, &staging, fanned)?;
        steps.done(&format!("{name}: folded"));
        install.extend(folded.install.keys().cloned());
        produced.extend(folded.install);
        remove.extend(folded.remove);
        if !folded.complete {
            tainted.insert(name.clone());
        }
        let triple = |p: &UnitProblem| (p.stage.clone(), p.unit.clone(), p.reason.clone());
        summary.failed.extend(folded.failed.iter().map(triple));
        summary.flagged.extend(folded.flagged.iter().map(triple));
        // None: the entry stands as it is (`new_lock` is the old state with the changed entries).
        if let Some(entry) = folded.entry {
            new_lock.stages.insert(name.clone(), entry);
        }
        summary.committed_units += new_lock.stages.get(name).map_or(0, |e| e.units.len());
    }
    let options = RunOptions { force: run.force.clone(), only: run.only.clone(), ..RunOptions::default() };
    let selected = selected_stages(plan, &options)?;
    let entries = |name: &str| new_lock.stages.get(name);
    leave_out_not_kept(plan, &selected, &tainted, &entries, &mut install, &mut remove, &RealDisk::default());
    // Files of `keep: false` stages kept for a reader that failed: those of the shards a reader
    // that succeeded had read and dropped (`drop_consumed`, which marks them) are not there.
    let dropped: Vec<PathBuf> = plan
        .stages
        .values()
        .filter(|s| !s.keep)
        .flat_map(|s| {
            let shards = run.shards.get(&s.name).map_or(0, Vec::len);
            let results = run_dir.join(RUN_RESULTS).join(&s.name);
            (0..shards).map(move |i| results.join(i.to_string())).filter(|f| dropped_marker(f).exists())
        })
        .collect();
    install.retain(|relative| !dropped.iter().any(|shard| produced[relative].starts_with(shard)));
    for relative in &install {
        let from = &produced[relative];
        let to = transaction.new_path(relative);
        if *from != to {
            std::fs::create_dir_all(to.parent().expect("below the transaction"))?;
            std::fs::rename(from, &to).with_context(|| format!("moving `{}` into the commit", from.display()))?;
        }
    }
    steps.done(&format!("{} file(s) moved into the commit", install.len()));
    let remove: Vec<String> = remove.difference(&install).cloned().collect();
    let install: Vec<String> = install.into_iter().collect();
    steps.done(&format!("{} file(s) to install, {} to remove", install.len(), remove.len()));
    transaction.commit(&install, &remove, Some((&new_lock, &lock)))?;
    steps.done("committed");
    for (stage, unit, reason) in &summary.failed {
        eprintln!("error: stage `{stage}` {} failed: {reason}", crate::pipeline::work_units::describe(unit));
    }
    // The logs stay (`<run>/logs`); results and manifests were moved or are no longer needed.
    remove_run_outputs(run_dir);
    steps.done("results and manifests removed");
    Ok((summary, new_lock))
}

/// Removes a committed run's `results` (what was not moved into place: the files of `keep:
/// false` stages), `manifests` and `listings`, shard folders in parallel: each removal mostly
/// waits for the file system's journal (≈ 1.5 ms an entry on a busy disk, 5 entries a unit), and
/// waits overlap.
fn remove_run_outputs(run_dir: &Path) {
    use rayon::prelude::*;
    const REMOVED: [&str; 3] = [RUN_RESULTS, RUN_MANIFESTS, RUN_LISTINGS];
    let mut folders = Vec::new();
    for folder in REMOVED {
        let stages = std::fs::read_dir(run_dir.join(folder)).into_iter().flatten().flatten();
        folders.extend(stages.flat_map(|stage| std::fs::read_dir(stage.path()).into_iter().flatten().flatten()));
    }
    let remove = || {
        folders.par_iter().for_each(|shard| {
            let _ = match shard.file_type() {
                Ok(t) if t.is_dir() => std::fs::remove_dir_all(shard.path()),
                _ => std::fs::remove_file(shard.path()),
            };
        })
    };
    match rayon::ThreadPoolBuilder::new().num_threads(8).build() {
        Ok(pool) => pool.install(remove),
        Err(_) => remove(),
    }
    for folder in REMOVED {
        let _ = std::fs::remove_dir_all(run_dir.join(folder));
    }
}

/// `retries`: after a commit with failed units, submits the units still stale — the failed
/// ones and what depends on them, nothing forced again — as a new run with `retries_left`.
fn resubmit(run: &RunFile, plan: &Plan, lock: &LockFile, retries_left: u32) -> anyhow::Result<Option<RunFile>> {
    let options = RunOptions { only: run.only.clone(), keep_going: run.keep_going, ..RunOptions::default() };
    let selected = selected_stages(plan, &options)?;
    let (sources, files, rerun) = (resolve_sources(plan)?, param_file_hashes(plan)?, Rerun::default());
    let known = Known { lock, sources: &sources, files: &files, rerun: &rerun, disk: &RealDisk::default() };
    let prediction = predict(plan, &known, Some(&selected))?;
    let mut slurm = run.options.clone();
    slurm.executor.retries = Some(retries_left);
    let client = Slurm::new();
    let limits = client.limits()?;
    submit_run(plan, &options, &slurm, &Reporter::new(false), (&prediction, &sources), &selected, &client, &limits)
}

/// What `status` says of a Slurm run holding the folder: per stage, its tasks' states.
pub fn progress(output_dir: &Path) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(runs_dir(output_dir)) else { return Vec::new() };
    let mut lines = Vec::new();
    let client = Slurm::new();
    for entry in entries.flatten() {
        let Ok(run) = read_run(&entry.path()) else { continue };
        if runs_dir(output_dir).join(format!("{}{SUMMARY_SUFFIX}", run.id)).exists() {
            continue;
        }
        if let Some(job) = &run.allocation {
            // Steps of one allocation: their manifests say how far it is.
            lines.push(format!("Slurm run `{}` in allocation {job}:", run.id));
            for (name, tasks) in &run.tasks {
                let manifests = entry.path().join(RUN_MANIFESTS).join(name);
                let done = tasks.iter().filter(|t| manifests.join(format!("{t}.json")).exists()).count();
                lines.push(format!("  {name:<18} {done} of {} shard(s) done", tasks.len()));
            }
            continue;
        }
        let Ok(limits) = client.limits() else { return lines };
        let mut arrays: Vec<SubmittedArray> = run.arrays.values().cloned().collect();
        arrays.extend(run.commit.clone());
        let mut status = crate::pipeline::slurm::RunStatus::new(&arrays);
        if client.poll(&mut status, &limits).is_err() {
            lines.push(format!("Slurm run `{}`: Slurm did not answer", run.id));
            continue;
        }
        lines.push(format!("Slurm run `{}` ({} task(s) not finished):", run.id, status.unfinished()));
        for (i, name) in run.arrays.keys().enumerate() {
            let counts = status.counts(i);
            let text: Vec<String> = counts.iter().map(|(state, n)| format!("{n} {state}")).collect();
            lines.push(format!("  {name:<18} {}", text.join(", ")));
        }
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(ids: Vec<String>) -> StatusLine {
        StatusLine {
            name: "load".into(),
            stage_type: "load",
            units: ids.len(),
            ids,
            stale: Vec::new(),
            vanished: Vec::new(),
            flagged: Vec::new(),
            keep: true,
            closed: true,
        }
    }

    #[test]
    fn bucket_ranges_cut_the_256_buckets_into_contiguous_ranges_of_about_the_units_per_task() {
        let ids: Vec<String> =
            (0..5000).flat_map(|m| [format!("motion=M{m}/floor=4"), format!("motion=M{m}/floor=5")]).collect();
        let largest = line(ids.clone());
        let smaller = line(ids.iter().step_by(2).cloned().collect());
        let ranges = bucket_ranges([&smaller, &largest].into_iter(), 1000);
        assert_eq!(ranges.len(), 10, "10 000 units of the largest stage, 1000 a task");
        assert_eq!((ranges[0][0], ranges[9][1]), (0, 256));
        assert!(ranges.windows(2).all(|w| w[0][1] == w[1][0] && w[0][0] < w[0][1]), "{ranges:?}");
        let mut per_bucket = [0usize; 256];
        for id in &ids {
            per_bucket[usize::from(fan_bucket(id))] += 1;
        }
        let most = per_bucket.iter().max().copied().unwrap();
        for [first, end] in &ranges {
            let units: usize = per_bucket[usize::from(*first)..usize::from(*end)].iter().sum();
            assert!(units.abs_diff(1000) <= most, "{units} units in [{first}, {end}) (a bucket holds ≤ {most})");
        }
        assert_eq!(bucket_ranges([&largest].into_iter(), 100_000), [[0, 256]]);
        let finest = bucket_ranges([&largest].into_iter(), 1).len();
        assert!((200..=256).contains(&finest), "a bucket is the smallest shard: {finest}");
        assert!(bucket_ranges(std::iter::empty(), 10).is_empty());
        // A run's shard of a bucket is the range that holds it.
        let run = run_file(ranges.clone());
        for (i, [first, end]) in ranges.iter().enumerate() {
            assert_eq!(run.shard_of(*first as u8), i);
            assert_eq!(run.shard_of((*end - 1) as u8), i);
            assert_eq!(run.buckets(i).len(), usize::from(end - first));
        }
    }

    /// A run file of nothing submitted yet, its buckets cut into `ranges`.
    fn run_file(ranges: Vec<[u16; 2]>) -> RunFile {
        RunFile {
            id: "r".into(),
            pipeline: PathBuf::from("p.yaml"),
            pipeline_hash: String::new(),
            force: Vec::new(),
            only: Vec::new(),
            keep_going: false,
            options: SlurmOptions { executor: Default::default(), units_per_task: 1000, wait: false },
            shards: BTreeMap::new(),
            tasks: BTreeMap::new(),
            arrays: BTreeMap::new(),
            commit: None,
            allocation: None,
            remake: BTreeMap::new(),
            fanned: BTreeSet::new(),
            bucketed: BTreeSet::new(),
            ranges,
            closed: BTreeSet::new(),
        }
    }

    #[test]
    fn a_stage_with_units_gone_and_none_stale_runs_one_task_that_says_so() {
        let dir = crate::tempdir::tempdir().unwrap();
        let plan = super::super::test_support::plan(dir.path(), super::super::test_support::PIPELINE);
        let selected: BTreeSet<String> = ["load", "baseline"].map(String::from).into();
        let mut run = run_file(Vec::new());
        let ids = || vec!["motion=A".to_string(), "motion=B".to_string()];
        assert!(cut_shards(&mut run, &plan, &[line(ids())], &selected, 1).is_empty(), "nothing to do");
        let gone = StatusLine { vanished: vec!["motion=C".into()], ..line(ids()) };
        let all_gone = StatusLine { name: "baseline".into(), vanished: vec!["motion=C".into()], ..line(Vec::new()) };
        let cut = cut_shards(&mut run, &plan, &[gone, all_gone], &selected, 1);
        let shards = |ids: &[&[&str]]| {
            ids.iter().map(|s| s.iter().map(|id| id.to_string()).collect()).collect::<Vec<Vec<String>>>()
        };
        assert_eq!(cut[0], ("load".into(), shards(&[&["motion=A"], &["motion=B"]]), BTreeSet::from([0])));
        assert_eq!(
            cut[1],
            ("baseline".into(), shards(&[&[]]), BTreeSet::from([0])),
            "every record gone: one empty shard"
        );
    }

    #[test]
    fn a_unit_seen_gone_and_kept_is_an_error_unless_an_upstream_unit_failed() {
        let records = vec![
            UnitRecord::cached("motion=A"),
            UnitRecord {
                outcome: UnitOutcome::Failed { reason: "its Slurm task (shard 1) did not finish".into() },
                ..UnitRecord::cached("motion=B")
            },
        ];
        let seen = |ids: &[&str]| ids.iter().map(|id| id.to_string()).collect::<BTreeSet<String>>();
        // A failed unit seen gone by another task is not a contradiction (the fold keeps it:
        // the stage is incomplete).
        assert_eq!(
            gone_units("s", &records, seen(&["motion=B", "motion=C"]), false).unwrap(),
            ["motion=B", "motion=C"]
        );
        let both = gone_units("s", &records, seen(&["motion=A"]), false).unwrap_err();
        assert!(format!("{both}").contains("motion=A is both gone and kept"), "{both}");
        // Under a failed upstream unit the shard that kept it wins: the stage keeps it.
        assert_eq!(gone_units("s", &records, seen(&["motion=A", "motion=C"]), true).unwrap(), ["motion=C"]);
    }

    #[test]
    fn a_committed_runs_results_and_manifests_go_and_its_logs_and_run_file_stay() {
        let dir = crate::tempdir::tempdir().unwrap();
        let run_dir = dir.path();
        for shard in 0..20 {
            let records = run_dir.join(format!("results/load/{shard}/records/motion=T-{shard}/floor=4"));
            std::fs::create_dir_all(&records).unwrap();
            std::fs::write(records.join("data.parquet"), b"table").unwrap();
            std::fs::create_dir_all(run_dir.join("manifests/load")).unwrap();
            std::fs::write(run_dir.join(format!("manifests/load/{shard}.json")), b"{}").unwrap();
        }
        std::fs::create_dir_all(run_dir.join(RUN_LOGS)).unwrap();
        std::fs::write(run_dir.join("logs/run_1_0.out"), b"log").unwrap();
        std::fs::write(run_dir.join(RUN_FILE), b"{}").unwrap();
        remove_run_outputs(run_dir);
        let mut left: Vec<String> = std::fs::read_dir(run_dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, [RUN_LOGS, RUN_FILE]);
        assert!(run_dir.join("logs/run_1_0.out").is_file());
    }
}
