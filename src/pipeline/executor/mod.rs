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
//!
//! Cut along its seams:
//! - [`open`] (here): what every run starts from — the selection, what reruns whatever the
//!   lockfile says, the sources and parameter files hashed, the output folder taken (lease,
//!   recovery, ownership checks) and its lockfile read;
//! - `inputs`: what a stage reads this run (sources, upstream stages' files, `select:`);
//! - `assess`: pure — plan and state in ([`assess::Known`]: lockfile, input hashes, what
//!   reruns, and how a written file looks now), stale units and their reasons out; `status`,
//!   `--dry-run` and Slurm's shards are its predictions;
//! - `commit`: folds what became of each unit into the stage's new lockfile entry and the files
//!   to install and remove, and commits them in one transaction;
//! - a [`Backend`] decides where and when stale units run: [`Local`] (`local.rs`: on rayon, each
//!   stage as soon as its upstream stages are done) or Slurm (`slurm.rs`: job arrays and a
//!   commit job, or `srun` steps of one allocation).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

mod assess;
mod commit;
mod inputs;
mod local;
pub mod slurm;
#[cfg(test)]
mod test_support;

pub use assess::{StatusLine, UnitStatus};
pub use inputs::source_files;
pub use local::Local;

use self::assess::{predict, Known, RealDisk};
use self::inputs::{input_paths, param_file_hashes, resolve_sources, ResolvedSource};
use super::layout::{HASH_MEMO, HASH_MEMO_BUCKETS, LOCK_FILE, RUNS_DIR, STATE_DIR, STATE_FILES};
use super::lease::Lease;
use super::lock::LockFile;
use super::ownership;
use super::plan::{InputRef, Plan, PlannedStage};
use super::progress::Reporter;
use super::txn::{self, Recovery, Transaction};
use crate::error::UserError;
use crate::io::hash;

/// Where the stale units of a run execute. Every backend starts from the same [`Opened`]
/// output folder and decides with `assess` what is stale; the one difference is where units
/// run and who commits: this process ([`Local`]), or Slurm job arrays and their commit job, or
/// `srun` steps of one allocation (`slurm::SlurmOptions`), as Snakemake's executor plugins and
/// Nextflow's task handlers differ only there.
pub trait Backend {
    /// What can be refused before the output folder is taken (a bad `executor:` block, an
    /// allocation that is not there).
    fn check(&self) -> anyhow::Result<()> {
        Ok(())
    }

    /// Runs what is stale in `opened` and commits it (or hands the lease to whoever will).
    fn run(&self, opened: Opened<'_>, reporter: &Reporter) -> anyhow::Result<RunSummary>;
}

/// A run's output folder taken and its state read: what every backend starts from.
pub struct Opened<'a> {
    plan: &'a Plan,
    options: &'a RunOptions,
    /// The stages the run covers (`--only` and what they need, or all).
    selected: BTreeSet<String>,
    rerun: Rerun,
    sources: BTreeMap<String, ResolvedSource>,
    /// Per stage, the hashes of the files its `Path` parameters name.
    files: BTreeMap<String, BTreeMap<String, String>>,
    lease: Lease,
    lock: LockFile,
    disk: RealDisk,
}

impl Opened<'_> {
    /// What assessing a stage of this run reads.
    fn known(&self) -> Known<'_> {
        Known { lock: &self.lock, sources: &self.sources, files: &self.files, rerun: &self.rerun, disk: &self.disk }
    }
}

/// Runs `plan` on `backend`: opens the output folder, then hands it to the backend.
pub fn run(
    plan: &Plan,
    options: &RunOptions,
    backend: &dyn Backend,
    reporter: &Reporter,
) -> anyhow::Result<RunSummary> {
    backend.check()?;
    let opened = open(plan, options, reporter)?;
    backend.run(opened, reporter)
}

/// Before a run writes anything: the stages it covers, what it reruns, its inputs hashed, and the
/// output folder checked and created, its lease taken, an interrupted commit finished, and its
/// lockfile read and checked against the pipeline.
fn open<'a>(plan: &'a Plan, options: &'a RunOptions, reporter: &Reporter) -> anyhow::Result<Opened<'a>> {
    let selected = selected_stages(plan, options)?;
    let sources = resolve_sources(plan)?;
    let files = param_file_hashes(plan)?;
    let (lease, lock) = take_output_folder(plan, &sources, reporter)?;
    let rerun = Rerun { stages: forced_stages(plan, &options.force), remake: BTreeMap::new() };
    Ok(Opened { plan, options, selected, rerun, sources, files, lease, lock, disk: RealDisk::default() })
}

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
    /// Units removed because their records are gone from the inputs.
    pub gone: usize,
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

pub fn lock_path(plan: &Plan) -> PathBuf {
    plan.file.output_dir().join(LOCK_FILE)
}

/// Whether the state folder holds anything but the committed state, the hash memo (and its
/// buckets) and Slurm runs' folders: a lease, or an unfinished commit. `status` takes the lease
/// only then, so a run starting meanwhile is not refused.
fn run_may_be_in_progress(state_dir: &Path) -> bool {
    std::fs::read_dir(state_dir)
        .map(|d| {
            d.flatten()
                .any(|e| ![HASH_MEMO, HASH_MEMO_BUCKETS, RUNS_DIR, STATE_FILES].iter().any(|n| e.file_name() == *n))
        })
        .unwrap_or(false)
}

/// What `run` would do, and why, without running anything; `notes` are what the user should
/// know besides (a run in progress, an interrupted commit completed, orphaned folders).
pub fn status(plan: &Plan, notes: &mut Vec<String>) -> Result<Vec<StatusLine>, UserError> {
    let output_dir = plan.file.output_dir();
    if run_may_be_in_progress(&output_dir.join(STATE_DIR)) {
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
    let (sources, files) = (resolve_sources(plan)?, param_file_hashes(plan)?);
    let rerun = Rerun::default();
    let known = Known { lock: &lock, sources: &sources, files: &files, rerun: &rerun, disk: &RealDisk::default() };
    Ok(predict(plan, &known, None)?.lines)
}

/// `shakeflow run --dry-run`: the units that would run, and why.
pub fn dry_run(plan: &Plan, options: &RunOptions) -> Result<Vec<StatusLine>, UserError> {
    let selected = selected_stages(plan, options)?;
    let rerun = Rerun { stages: forced_stages(plan, &options.force), remake: BTreeMap::new() };
    let lock = LockFile::read(&lock_path(plan))?;
    let (sources, files) = (resolve_sources(plan)?, param_file_hashes(plan)?);
    let known = Known { lock: &lock, sources: &sources, files: &files, rerun: &rerun, disk: &RealDisk::default() };
    Ok(predict(plan, &known, Some(&selected))?.lines)
}

/// Drops `state` on a thread of its own: what a run of 10⁴ tests built (lockfile entries, paths,
/// assessments) takes a tenth of a no-op run's time to free, which its caller need not wait for
/// (and a process that exits meanwhile does not). Nothing with an effect beyond memory (a
/// lease, a transaction) may go this way.
fn free_in_background<T: Send + 'static>(state: T) {
    // When no thread can be started, `spawn` drops its closure, and `state` with it, here.
    let _ = std::thread::Builder::new().name("free".into()).spawn(move || drop(state));
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

/// The output folder checked and created, its lease taken, an interrupted commit finished, and
/// its lockfile read and checked against the pipeline.
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
    if let Some((holder, why)) = &lease.took_over {
        reporter.line(&format!(
            "took over the lease of an earlier run that is gone ({why}: pid {} on `{}`, started {})",
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
        Transaction::begin(&lease)?.commit(&[], &orphans, Some((&new_lock, &lock)))?;
    }
    Ok(sized)
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

/// The sources `stage` reads.
fn source_inputs(stage: &PlannedStage) -> BTreeSet<&str> {
    stage
        .inputs
        .iter()
        .filter_map(|i| match i {
            InputRef::Source(name) => Some(name.as_str()),
            InputRef::Stage { .. } => None,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use crate::pipeline::layout::{HASH_MEMO, HASH_MEMO_BUCKETS, LEASE_FILE, RUNS_DIR, STATE_FILES};

    #[test]
    fn only_a_lease_or_an_unfinished_commit_is_a_run_in_progress_for_status() {
        let dir = crate::tempdir::tempdir().unwrap();
        let state = dir.path();
        assert!(!super::run_may_be_in_progress(&state.join("absent")));
        std::fs::write(state.join(HASH_MEMO), "{}").unwrap();
        for folder in [HASH_MEMO_BUCKETS, RUNS_DIR, STATE_FILES] {
            std::fs::create_dir(state.join(folder)).unwrap();
        }
        std::fs::write(state.join(HASH_MEMO_BUCKETS).join("3f.json"), "{}").unwrap();
        assert!(!super::run_may_be_in_progress(state), "the memo, its buckets, Slurm runs and the state are not a run");
        std::fs::write(state.join(LEASE_FILE), "").unwrap();
        assert!(super::run_may_be_in_progress(state));
    }
}
