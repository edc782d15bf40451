//! The local backend: each stage on the rayon pool as soon as its upstream stages are done, its
//! stale units in parallel, failures per unit (`--keep-going`), and one transaction committed at
//! the end with whatever finished.

use std::collections::{BTreeMap, BTreeSet};
use std::mem::take;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::anyhow;
use rayon::prelude::*;

use super::assess::{assess_stage, predict, AssessedStage, Known};
use super::commit::{
    commit, entry_from_outcomes, leave_out_not_kept, left_out, relative, Changes, UnitOutcome, UnitRecord,
};
use super::inputs::{cached_files, Produced};
use super::{upstream_stages, Backend, Opened, Outcome, RunSummary, StageReport, UnitProblem};
use crate::io::hash;
use crate::pipeline::layout::{fan_out_above, fans_out};
use crate::pipeline::lock::StageLock;
use crate::pipeline::memo::{TableMemo, DEFAULT_BUDGET_BYTES};
use crate::pipeline::plan::{Plan, PlannedStage};
use crate::pipeline::progress::Reporter;
use crate::pipeline::sink::OutputSink;
use crate::pipeline::spec::OnError;
use crate::pipeline::stage::{StageContext, WorkUnits};
use crate::pipeline::txn::Transaction;
use crate::pipeline::work_units::{self, Unit};

/// Runs units in this process.
pub struct Local;

/// What every stage of one run reads.
struct RunEnv<'a> {
    plan: &'a Plan,
    selected: &'a BTreeSet<String>,
    keep_going: bool,
    /// The lockfile, the inputs' hashes and what reruns: what assessing reads.
    known: Known<'a>,
    transaction: &'a Transaction,
    reporter: &'a Reporter,
    state: Mutex<RunState>,
    /// Tables written this run, kept for the stages that read them next.
    memo: Arc<TableMemo>,
    /// Stages assessed already, by the prediction of a run with `keep: false` stages.
    settled: Mutex<BTreeMap<String, AssessedStage>>,
}

/// What the stages of one run fill in.
#[derive(Default)]
struct RunState {
    produced: BTreeMap<String, Produced>,
    /// The new lockfile entries of the stages whose entry changed (the others' stand).
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
            spawn_stage(env, &dependents, scope, stage);
        }
    });
    let mut state = env.state.lock().expect("no poisoned lock");
    match state.fatal.take() {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// Runs `stage` on the pool, then starts each dependent whose upstream stages are all done.
fn spawn_stage<'s, 'a: 's>(
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
            // Not done: the intermediates it reads stay (`commit::left_out`).
            state.tainted.insert(stage.name.clone());
        }
        let mut state = env.state.lock().expect("no poisoned lock");
        for upstream in upstream_stages(stage) {
            let left = state.readers_left.get_mut(upstream).expect("every upstream stage has readers");
            *left -= 1;
            if *left == 0 {
                let dir = env.transaction.new_path(env.plan.stage_path(upstream));
                env.memo.release(&dir);
                if left_out(env.plan, env.selected, &state.tainted, &env.plan.stages[upstream]) {
                    env.memo.forget_unwritten(&dir);
                }
            }
        }
        for dependent in dependents.get(stage.name.as_str()).into_iter().flatten() {
            let left = state.waiting_on.get_mut(&dependent.name).expect("every stage is counted");
            *left -= 1;
            if *left == 0 {
                spawn_stage(env, dependents, scope, dependent);
            }
        }
    });
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
    let entry = env.known.lock.stages.get(name);
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
        state.reports.insert(
            name.to_string(),
            StageReport { name: name.into(), outcome: Outcome::Skipped, units, ran: 0, gone: 0 },
        );
        return Ok(());
    }
    let settled = env.settled.lock().expect("no poisoned lock").remove(name);
    let assessed = match settled {
        Some(assessed) => assessed,
        None => {
            let snapshot = env.state.lock().expect("no poisoned lock").produced.clone();
            assess_stage(env.plan, stage, &env.known, &snapshot)?
        }
    };
    let new_dir = env.transaction.new_path(env.plan.stage_path(name));
    let stale: Vec<&(Unit, String, Vec<String>)> = assessed.units.iter().filter(|(_, _, r)| !r.is_empty()).collect();
    let fanned = fans_out(assessed.units.iter().map(|(u, _, _)| u.id.as_str()), fan_out_above());
    let started = Instant::now();
    let records_in: usize = stale.iter().map(|(u, _, _)| u.inputs.iter().map(|i| i.parts().len()).sum::<usize>()).sum();
    let mut ran: BTreeMap<String, UnitRecord> = if stale.is_empty() {
        env.reporter.line(&format!("{name:<18} cached"));
        BTreeMap::new()
    } else {
        env.reporter.line(&format!("{name:<18} running ({})", why_running(&stale, assessed.units.len())));
        let bar = env.reporter.stage_bar(name, stale.len() as u64);
        let readers = env.plan.stages.values().filter(|s| upstream_stages(s).contains(name)).count();
        let records = execute(env.plan, stage, &stale, &new_dir, &env.memo, readers, &bar, fanned);
        bar.finish_and_clear();
        records.into_iter().map(|r| (r.id.clone(), r)).collect()
    };
    let records: Vec<UnitRecord> = assessed
        .units
        .iter()
        .map(|(unit, _, _)| {
            // A cached unit's entry is its old one: its key and inputs are not copied again.
            ran.remove(&unit.id).unwrap_or_else(|| UnitRecord::cached(&unit.id))
        })
        .collect();
    for record in &records {
        match &record.outcome {
            UnitOutcome::Failed { reason } => {
                env.reporter.line(&format!("{name:<18} FAILED {}: {reason}", work_units::describe(&record.id)))
            }
            UnitOutcome::Flagged { file, reason } => {
                env.reporter.line(&format!("{name:<18} skipped {file} (on_error: skip): {reason}"))
            }
            _ => {}
        }
    }
    let folded =
        entry_from_outcomes(env.plan, stage, entry, records, &assessed.vanished, upstream_tainted, &new_dir, fanned)?;
    let failed = folded.failed.len();
    if folded.moved > 0 {
        let layout = if fanned { "two-level folders" } else { "one folder" };
        env.reporter.line(&format!("{name:<18} {} cached file(s) moved to {layout}", folded.moved));
    }
    let gone = folded.gone;
    if gone > 0 {
        env.reporter.line(&format!("{name:<18} {gone} unit(s) removed: their records are gone from the inputs"));
    }
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
    if let Some(entry) = folded.entry {
        state.entries.insert(name.to_string(), entry);
    }
    let outcome = if stale.is_empty() {
        Outcome::Cached
    } else {
        Outcome::Ran { seconds: started.elapsed().as_secs_f64(), records: records_in }
    };
    state.reports.insert(
        name.to_string(),
        StageReport { name: name.into(), outcome, units: assessed.units.len(), ran: stale.len(), gone },
    );
    Ok(())
}

/// Why a stage's units run, in a line: the reasons all share, else a count and the first.
fn why_running(stale: &[&(Unit, String, Vec<String>)], units: usize) -> String {
    if stale.len() == units && stale.iter().all(|u| u.2 == stale[0].2) {
        return stale[0].2.join("; ");
    }
    let first = format!("{}: {}", work_units::describe(&stale[0].0.id), stale[0].2.join("; "));
    let more = if stale.len() > 1 { ", …" } else { "" };
    format!("{} of {units} records; {first}{more}", stale.len())
}

/// Runs `stale` units of `stage` in parallel, each writing under `dir` (`dir/<output>/…`, one
/// folder down when `fanned`).
#[allow(clippy::too_many_arguments)]
pub(super) fn execute(
    plan: &Plan,
    stage: &PlannedStage,
    stale: &[&(Unit, String, Vec<String>)],
    dir: &Path,
    memo: &Arc<TableMemo>,
    readers: usize,
    bar: &indicatif::ProgressBar,
    fanned: bool,
) -> Vec<UnitRecord> {
    let info = stage.stage.info();
    let base_dir = plan.file.base_dir();
    stale
        .par_iter()
        .map(|(unit, key, _)| {
            let mut sink =
                OutputSink::new(dir, &stage.name, info, &stage.params, &unit.hashes, indicatif::ProgressBar::hidden())
                    .fanned_out(fanned);
            if readers > 0 {
                sink = sink.keeping_tables_in(memo.clone(), readers, !stage.keep);
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

impl Backend for Local {
    fn run(&self, opened: Opened<'_>, reporter: &Reporter) -> anyhow::Result<RunSummary> {
        let mut opened = opened;
        let plan = opened.plan;
        // What `keep: false` stages make again needs the whole plan assessed first; the stages
        // that assessment settled are not assessed a second time.
        let mut settled = BTreeMap::new();
        if plan.stages.values().any(|s| !s.keep) {
            let prediction = predict(plan, &opened.known(), Some(&opened.selected))?;
            opened.rerun.remake = prediction.remake;
            settled = prediction.settled;
        }
        let transaction = Transaction::begin(&opened.lease)?;
        let env = RunEnv {
            plan,
            selected: &opened.selected,
            keep_going: opened.options.keep_going,
            known: opened.known(),
            transaction: &transaction,
            reporter,
            state: Mutex::new(RunState::default()),
            memo: Arc::new(TableMemo::new(DEFAULT_BUDGET_BYTES)),
            settled: Mutex::new(settled),
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
        let (selected, lock, all_or_nothing) = (&opened.selected, &opened.lock, opened.options.all_or_nothing);
        let (install, remove) = (&mut state.install, &mut state.remove);
        let entries = |name: &str| state.entries.get(name).or_else(|| lock.stages.get(name));
        leave_out_not_kept(plan, selected, &state.tainted, &entries, install, remove, &opened.disk);
        // The intermediates' files the commit installs after all (a reader failed or was not
        // selected) are written now; the others never are.
        let staging = transaction.new_path("");
        let installed = |path: &Path| {
            path.strip_prefix(&staging).ok().and_then(Path::to_str).is_some_and(|entry| state.install.contains(entry))
        };
        if let Err(e) = env.memo.write_unwritten(installed) {
            transaction.abort();
            return Err(e);
        }
        let changes = Changes { entries: &state.entries, install: &state.install, remove: &state.remove };
        if let Some(error) = fatal {
            // A stage could not be planned (a bad select, two records with one partition): what
            // finished before it is still committed below only when nothing is in doubt.
            if state.install.is_empty() || all_or_nothing {
                transaction.abort();
                return Err(error);
            }
            commit(transaction, changes, plan, lock)?;
            return Err(error.context("the units that finished before it were committed"));
        }
        if all_or_nothing && !state.failed.is_empty() {
            transaction.abort();
            let reports = plan.stages.keys().filter_map(|n| state.reports.get(n).cloned()).collect();
            return Ok(RunSummary { reports, failed: state.failed, flagged: state.flagged });
        }
        commit(transaction, changes, plan, lock)?;
        // Under the lease still: only the run holding the folder writes the memo. The files this
        // run wrote go in too (their hashes came from the bytes written), those written 2 s ago or more;
        // a stage whose entry did not change wrote nothing, and assessing it went through the memo.
        for (name, entry) in &state.entries {
            for (file, hash) in entry.units.values().flat_map(|u| u.files.iter()) {
                hash::remember(&plan.stage_dir(name).join(file), hash);
            }
        }
        if let Err(e) = hash::save_memo() {
            reporter.line(&format!("warning: the hash memo was not saved ({e:#}); the next run reads every file"));
        }
        let reports = plan.stages.keys().filter_map(|n| state.reports.get(n).cloned()).collect();
        let summary = RunSummary { reports, failed: take(&mut state.failed), flagged: take(&mut state.flagged) };
        // The lease goes now; the run's state (at 10⁴ tests a tenth of a no-op run's time to free)
        // is freed while the caller goes on.
        let Opened { lease, lock, sources, disk, .. } = opened;
        drop(lease);
        super::free_in_background((lock, sources, disk, state));
        Ok(summary)
    }
}
