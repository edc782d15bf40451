//! The commit side of a run: what became of each unit ([`UnitRecord`]) folded into its stage's
//! new lockfile entry and the files to install and remove ([`entry_from_outcomes`]), `keep:
//! false` files left out ([`leave_out_not_kept`]), and the transaction committed ([`commit`]). The local run folds
//! each stage as it finishes; Slurm's commit job folds the manifests its tasks left.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use anyhow::anyhow;

use super::assess::Disk;
use super::inputs::{cached_files, Produced, ProducedFile};
use super::{upstream_stages, UnitProblem};
use crate::pipeline::layout::{placed, FLAGGED, STAGE_MARKER, STATUS};
use crate::pipeline::lock::{LockFile, StageLock, UnitLock};
use crate::pipeline::ownership;
use crate::pipeline::plan::{InputRef, Plan, PlannedStage};
use crate::pipeline::sink::OutputSink;
use crate::pipeline::spec::OnError;
use crate::pipeline::stage::{InputKind, StageInfo};
use crate::pipeline::txn::Transaction;
use crate::pipeline::work_units;

/// The lockfile unit that owns a stage's `flagged` table.
pub(super) const FLAGGED_UNIT: &str = "(flagged)";
/// The lockfile unit that owns a stage's `status` table.
const STATUS_UNIT: &str = "(status)";

/// Whether a lockfile unit is one of the engine's tables (`flagged`, `status`), not a record.
pub(super) fn engine_unit(id: &str) -> bool {
    id == FLAGGED_UNIT || id == STATUS_UNIT
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

impl UnitRecord {
    /// An up-to-date unit: what the commit folds is its lockfile entry as it stands, so the
    /// record carries its id only.
    pub fn cached(id: &str) -> UnitRecord {
        UnitRecord { id: id.to_string(), key: String::new(), inputs: BTreeMap::new(), outcome: UnitOutcome::Cached }
    }
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

/// A stage's run folded into what the commit does.
#[derive(Default)]
pub(super) struct Folded {
    /// The stage's new lockfile entry; None when it is its old entry unchanged (every unit
    /// cached where it was, none gone, the engine's tables the same): nothing to write.
    pub(super) entry: Option<StageLock>,
    /// Paths relative to the output folder → where the new file is now.
    pub(super) install: BTreeMap<String, PathBuf>,
    pub(super) remove: BTreeSet<String>,
    pub(super) produced: Produced,
    pub(super) failed: Vec<UnitProblem>,
    pub(super) flagged: Vec<UnitProblem>,
    /// Whether every unit succeeded (records gone from the inputs then leave too).
    pub(super) complete: bool,
    /// Files of cached units moved to the stage's layout (flat or two-level folders).
    pub(super) moved: usize,
    /// Units of records gone from the inputs whose files and entries this fold removes.
    pub(super) gone: usize,
}

/// Folds a stage's unit records into its new lockfile entry, the files to install and remove,
/// and what downstream stages read. `staging` is where new stage-level files (the marker, the
/// `flagged` table) are written. `fanned`: the stage's records go in two-level folders
/// (`layout::placed`); cached units whose files are in the other layout move there.
#[allow(clippy::too_many_arguments)]
pub(super) fn entry_from_outcomes(
    plan: &Plan,
    stage: &PlannedStage,
    entry: Option<&StageLock>,
    records: Vec<UnitRecord>,
    vanished: &[String],
    upstream_tainted: bool,
    staging: &Path,
    fanned: bool,
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
    // Cached units whose entry stays as it is: copied into the new entry only if it changes.
    let mut kept: Vec<String> = Vec::new();
    let mut only_cached = true;
    for record in records {
        only_cached &= matches!(record.outcome, UnitOutcome::Cached);
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
                if old.files.keys().all(|f| placed(f, fanned) == f.as_str()) {
                    kept.push(record.id);
                } else {
                    let mut unit = old.clone();
                    relayout(&mut unit, fanned, &stage_dir, staging, &at, &mut folded)?;
                    new_entry.units.insert(record.id, unit);
                }
            }
            UnitOutcome::Ran { dir, files, notes } => {
                for (file, hash) in &files {
                    if let Some(other) = owner.insert(file.clone(), record.id.clone()) {
                        anyhow::bail!(
                            "stage `{name}`: the {} and the {} both wrote `{file}`; give the sources distinct `partition:` values",
                            work_units::describe(&other),
                            work_units::describe(&record.id)
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
            folded.gone += 1;
        } else {
            new_entry.units.insert(id.clone(), old.clone());
        }
    }
    let skips = stage.inputs.iter().any(|i| match i {
        InputRef::Source(s) => plan.file.spec.inputs[s].on_error == OnError::Skip,
        InputRef::Stage { .. } => false,
    });
    // Whether every unit that ran failed: the stage's files and tables then stay as they were.
    let only_failures = failed > 0 && folded.install.is_empty() && folded.remove.is_empty();
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
    // A pipeline's record-reading stage says how every record fared, failed ones included (a
    // failed unit's old files stay; the table is new) — unless every unit that ran failed: such a
    // run changes nothing and names its failures, as a one-stage command does on stderr.
    if only_failures {
        if let Some(old) = entry.and_then(|e| e.units.get(STATUS_UNIT)) {
            new_entry.units.insert(STATUS_UNIT.into(), old.clone());
            folded.produced.extend(cached_files(old, &stage_dir));
        }
    } else if info.inputs == InputKind::Sources && plan.file.command.is_none() {
        status_rows.sort();
        engine_table(
            STATUS_UNIT,
            text_table(staging, name, info, &stage.params, STATUS, &STATUS_COLUMNS, &status_rows)?,
        );
    }
    if !folded.install.is_empty() && ownership::read_marker(&stage_dir).is_none() {
        ownership::write_marker(staging, name, info.name)?;
        folded.install.insert(at(STAGE_MARKER), staging.join(STAGE_MARKER));
    }
    let old = entry.filter(|_| only_cached && vanished.is_empty());
    let unchanged = old.is_some_and(|old| {
        folded.install.is_empty()
            && folded.remove.is_empty()
            && old.units.len() == kept.len() + new_entry.units.len()
            && new_entry.units.iter().all(|(id, unit)| old.units.get(id) == Some(unit))
            && (&old.stage_type, old.stage_version, &old.params, &old.select)
                == (&new_entry.stage_type, new_entry.stage_version, &new_entry.params, &new_entry.select)
    });
    if !unchanged {
        let old = entry.map(|e| &e.units);
        new_entry.units.extend(kept.into_iter().map(|id| {
            let unit = old.and_then(|units| units.get(&id)).expect("a kept unit is in the lockfile").clone();
            (id, unit)
        }));
        folded.entry = Some(new_entry);
    }
    Ok(folded)
}

/// Moves a cached unit's record files to the layout `fanned` (`layout::placed`): each one on
/// disk is linked (copied where the file system has no hard links) into `staging` at its new
/// place, which the commit installs, and its old place is removed by the same commit; the
/// entry names the new places, hashes unchanged. A `keep: false` file already gone is only renamed
/// in the entry. Before the commit point nothing has moved (the links go with the transaction).
fn relayout(
    unit: &mut UnitLock,
    fanned: bool,
    stage_dir: &Path,
    staging: &Path,
    at: &dyn Fn(&str) -> String,
    folded: &mut Folded,
) -> anyhow::Result<()> {
    if unit.files.keys().all(|f| placed(f, fanned) == f.as_str()) {
        return Ok(());
    }
    let mut files = BTreeMap::new();
    for (file, hash) in std::mem::take(&mut unit.files) {
        let new = placed(&file, fanned).into_owned();
        if new != file {
            let (from, to) = (stage_dir.join(&file), staging.join(&new));
            if std::fs::symlink_metadata(&from).is_ok_and(|m| m.is_file()) {
                std::fs::create_dir_all(to.parent().expect("a file of the stage"))?;
                if std::fs::hard_link(&from, &to).is_err() {
                    std::fs::copy(&from, &to).map_err(|e| anyhow!("cannot copy `{}`: {e}", from.display()))?;
                }
                folded.install.insert(at(&new), to);
                folded.remove.insert(at(&file));
                folded.moved += 1;
            }
        }
        files.insert(new, hash);
    }
    unit.files = files;
    Ok(())
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
    params: &crate::pipeline::params::Params,
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
pub(super) fn relative(path: &Path, dir: &Path) -> String {
    path.strip_prefix(dir)
        .unwrap_or(path)
        .components()
        .map(|c| c.as_os_str().to_string_lossy())
        .collect::<Vec<_>>()
        .join("/")
}

/// Takes the files of `keep: false` stages out of a commit's `install` and puts those on disk in
/// its `remove` (paths relative to the output folder): the files of every such stage that ran in
/// full, as did every stage reading it (cached counts: it is up to date with them). Their
/// lockfile entries (`entries`: a stage's new one, else its old one) stay, hashes and all.
pub(super) fn leave_out_not_kept<'e>(
    plan: &Plan,
    selected: &BTreeSet<String>,
    tainted: &BTreeSet<String>,
    entries: &dyn Fn(&str) -> Option<&'e StageLock>,
    install: &mut BTreeSet<String>,
    remove: &mut BTreeSet<String>,
    disk: &dyn Disk,
) {
    let not_kept = plan
        .stages
        .values()
        .filter(|s| left_out(plan, selected, tainted, s))
        .filter_map(|s| entries(&s.name).map(|entry| (s, entry)))
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
        if disk.exists(&output_dir.join(&path)) {
            remove.insert(path);
        }
    }
}

/// Whether the commit leaves out the files of `stage`: it is `keep: false` and ran in full, as
/// did every stage reading it (`selected` and not `tainted`; cached counts: it is up to date).
pub(super) fn left_out(
    plan: &Plan,
    selected: &BTreeSet<String>,
    tainted: &BTreeSet<String>,
    stage: &PlannedStage,
) -> bool {
    let done = |name: &str| selected.contains(name) && !tainted.contains(name);
    !stage.keep
        && done(&stage.name)
        && plan.stages.values().filter(|r| upstream_stages(r).contains(stage.name.as_str())).all(|r| done(&r.name))
}

/// What a run commits: the new entries of the stages that ran, and the entries of the output
/// folder (paths relative to it) to install from the transaction and to remove.
#[derive(Clone, Copy)]
pub(super) struct Changes<'a> {
    pub(super) entries: &'a BTreeMap<String, StageLock>,
    pub(super) install: &'a BTreeSet<String>,
    pub(super) remove: &'a BTreeSet<String>,
}

/// Commits `changes` over `lock` in `transaction`: nothing at all when nothing is installed or
/// removed (everything cached, or every unit that ran failed), so the folder and its lockfile
/// stay exactly as they were — but for a lockfile of an older format, written as format 3.
pub(super) fn commit(
    transaction: Transaction,
    changes: Changes<'_>,
    plan: &Plan,
    lock: &LockFile,
) -> anyhow::Result<()> {
    if changes.install.is_empty() && changes.remove.is_empty() && !lock.is_older_format() {
        transaction.abort();
        return Ok(());
    }
    let mut stages = lock.stages.clone();
    // Stages the pipeline no longer has keep their entries until `gc` removes their folders.
    stages.extend(changes.entries.iter().map(|(name, entry)| (name.clone(), entry.clone())));
    let mut new_lock = LockFile::empty();
    new_lock.pipeline = Some(ownership::pipeline_label(&plan.file));
    new_lock.stages = stages;
    let install: Vec<String> = changes.install.iter().cloned().collect();
    let remove: Vec<String> = changes.remove.difference(changes.install).cloned().collect();
    transaction.commit(&install, &remove, Some((&new_lock, lock)))
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{assess_load, entry_after, plan, sources, FakeDisk, PIPELINE};
    use super::super::Rerun;
    use super::*;

    /// `load` with units FB-1..3 committed, and a staging folder for the next run.
    fn committed(dir: &Path) -> (Plan, StageLock) {
        let plan = plan(dir, PIPELINE);
        let mut disk = FakeDisk::default();
        let records = sources(&plan, &[("FB-1", "a"), ("FB-2", "b"), ("FB-3", "c")]);
        let assessed = assess_load(&plan, &records, &LockFile::empty(), &Rerun::default(), &disk);
        let entry = entry_after(&plan, "load", &assessed, &mut disk);
        std::fs::create_dir_all(plan.stage_dir("load")).unwrap();
        ownership::write_marker(&plan.stage_dir("load"), "load", "load").unwrap();
        (plan, entry)
    }

    fn record(id: &str, outcome: UnitOutcome) -> UnitRecord {
        UnitRecord { id: id.into(), key: format!("key:{id}"), inputs: BTreeMap::new(), outcome }
    }

    fn ran(dir: &Path, files: &[(&str, &str)]) -> UnitOutcome {
        let files = files.iter().map(|(f, h)| (f.to_string(), h.to_string())).collect();
        UnitOutcome::Ran { dir: dir.to_path_buf(), files, notes: Vec::new() }
    }

    #[test]
    fn an_entry_from_outcomes_installs_what_ran_keeps_what_is_cached_and_what_failed() {
        let dir = crate::tempdir::tempdir().unwrap();
        let (plan, entry) = committed(dir.path());
        let staging = dir.path().join("staging");
        let records = vec![
            record("motion=FB-1", UnitOutcome::Cached),
            // FB-2 now writes a figure instead of its table: the table goes.
            record("motion=FB-2", ran(&staging, &[("figures/FB-2.png", "png")])),
            record("motion=FB-3", UnitOutcome::Failed { reason: "bad row".into() }),
        ];
        let folded =
            entry_from_outcomes(&plan, &plan.stages["load"], Some(&entry), records, &[], false, &staging, false)
                .unwrap();
        // The status table is new: every record's, the failed one's too.
        assert_eq!(folded.install.keys().collect::<Vec<_>>(), ["load/figures/FB-2.png", "load/status/data.parquet"]);
        let status = crate::io::parquet::read_table(&staging.join("status/data.parquet")).unwrap();
        let crate::table::ColumnData::Str(what) = &status.column("status").unwrap().data else { panic!("text") };
        assert_eq!(what, &["loaded", "loaded", "failed"]);
        assert_eq!(folded.install["load/figures/FB-2.png"], staging.join("figures/FB-2.png"));
        assert_eq!(folded.remove.iter().collect::<Vec<_>>(), ["load/records/motion=FB-2/data.parquet"]);
        let new = folded.entry.unwrap();
        assert_eq!(new.units["motion=FB-1"], entry.units["motion=FB-1"], "cached: its entry as it was");
        assert_eq!(new.units["motion=FB-3"], entry.units["motion=FB-3"], "failed: its entry as it was (stale)");
        assert_eq!(new.units["motion=FB-2"].key, "key:motion=FB-2");
        assert!(!folded.complete, "a failed unit: the stage is not complete");
        assert_eq!(folded.failed.len(), 1);
        let produced: Vec<&String> = folded.produced.keys().collect();
        assert_eq!(produced.len(), 3, "FB-1's table, FB-2's figure and the status table, not FB-3's: {produced:?}");
    }

    #[test]
    fn a_stage_whose_units_are_all_cached_where_they_were_keeps_its_entry_untouched() {
        let dir = crate::tempdir::tempdir().unwrap();
        let (plan, entry) = committed(dir.path());
        let stage = &plan.stages["load"];
        let ids = ["motion=FB-1", "motion=FB-2", "motion=FB-3"];
        let cached = || ids.iter().map(|id| UnitRecord::cached(id)).collect::<Vec<_>>();
        // The first run with a status table writes it: the entry changes.
        let staging = dir.path().join("staging");
        let first = entry_from_outcomes(&plan, stage, Some(&entry), cached(), &[], false, &staging, false).unwrap();
        let with_status = first.entry.expect("a new status table: a new entry");
        let table = plan.stage_dir("load").join("status/data.parquet");
        std::fs::create_dir_all(table.parent().unwrap()).unwrap();
        std::fs::copy(staging.join("status/data.parquet"), &table).unwrap();
        // The next one changes nothing: no entry to write, nothing to install, and what
        // downstream stages read is every file of the old entry.
        let again = dir.path().join("again");
        let folded =
            entry_from_outcomes(&plan, stage, Some(&with_status), cached(), &[], false, &again, false).unwrap();
        assert!(folded.entry.is_none() && folded.install.is_empty() && folded.remove.is_empty());
        assert!(folded.complete);
        let files: usize = with_status.units.values().map(|u| u.files.len()).sum();
        assert_eq!(folded.produced.len(), files);
        // A unit that failed, or a record gone, makes a new entry (the same units here, a
        // status table that says so).
        let mut failing = cached();
        failing[1].outcome = UnitOutcome::Failed { reason: "bad row".into() };
        let failed = entry_from_outcomes(&plan, stage, Some(&with_status), failing, &[], false, &again, false);
        assert!(failed.unwrap().entry.is_some());
        let gone = ["motion=FB-3".to_string()];
        let fewer =
            entry_from_outcomes(&plan, stage, Some(&with_status), cached()[..2].to_vec(), &gone, false, &again, false);
        assert!(!fewer.unwrap().entry.unwrap().units.contains_key("motion=FB-3"));
    }

    #[test]
    fn records_gone_from_the_inputs_leave_only_with_a_complete_stage() {
        let dir = crate::tempdir::tempdir().unwrap();
        let (plan, entry) = committed(dir.path());
        let staging = dir.path().join("staging");
        let stage = &plan.stages["load"];
        let cached = || vec![record("motion=FB-1", UnitOutcome::Cached), record("motion=FB-2", UnitOutcome::Cached)];
        let gone = ["motion=FB-3".to_string()];
        let complete =
            entry_from_outcomes(&plan, stage, Some(&entry), cached(), &gone, false, &staging, false).unwrap();
        assert_eq!(complete.remove.iter().collect::<Vec<_>>(), ["load/records/motion=FB-3/data.parquet"]);
        assert!(!complete.entry.unwrap().units.contains_key("motion=FB-3"));
        // An upstream unit failed: the record may only look gone; its files and entry stay.
        let tainted = entry_from_outcomes(&plan, stage, Some(&entry), cached(), &gone, true, &staging, false).unwrap();
        assert!(tainted.remove.is_empty());
        assert_eq!(tainted.install.keys().collect::<Vec<_>>(), ["load/status/data.parquet"]);
        assert_eq!(tainted.entry.unwrap().units["motion=FB-3"], entry.units["motion=FB-3"]);
    }

    #[test]
    fn two_units_writing_one_file_are_refused_and_a_new_stage_folder_gets_its_marker() {
        let dir = crate::tempdir::tempdir().unwrap();
        let plan = plan(dir.path(), PIPELINE);
        let staging = dir.path().join("staging");
        let stage = &plan.stages["load"];
        let both = vec![
            record("motion=FB-1", ran(&staging, &[("records/x/data.parquet", "1")])),
            record("motion=FB-2", ran(&staging, &[("records/x/data.parquet", "2")])),
        ];
        let error =
            entry_from_outcomes(&plan, stage, None, both, &[], false, &staging, false).err().unwrap().to_string();
        assert!(
            error.contains("record motion=FB-1 and the record motion=FB-2 both wrote `records/x/data.parquet`"),
            "{error}"
        );
        let one = vec![record("motion=FB-1", ran(&staging, &[("records/motion=FB-1/data.parquet", "1")]))];
        let folded = entry_from_outcomes(&plan, stage, None, one, &[], false, &staging, false).unwrap();
        assert!(folded.complete);
        assert_eq!(
            folded.install.keys().collect::<Vec<_>>(),
            ["load/.shakeflow-stage", "load/records/motion=FB-1/data.parquet", "load/status/data.parquet"]
        );
        assert_eq!(ownership::read_marker(&staging).unwrap().stage, "load");
    }
}
