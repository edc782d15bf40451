//! Assessing: which units of a stage are stale, and why — pure, from the plan and what is
//! [`Known`] (the lockfile, the inputs' hashes, what reruns whatever the lockfile says, and how
//! the files units wrote look now, through [`Disk`]). `status`, `--dry-run`, a local run's
//! stages, Slurm's shards and each Slurm task's units all come from here.

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::ffi::OsString;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::commit::engine_unit;
use super::inputs::{cached_files, stage_inputs, Produced, ProducedFile, ResolvedSource};
use super::Rerun;
use crate::error::UserError;
use crate::io::hash;
use crate::pipeline::layout::{DATA_FILE, FLAGGED, STATUS};
use crate::pipeline::lock::{LockFile, StageLock, UnitLock};
use crate::pipeline::paths;
use crate::pipeline::plan::{Plan, PlannedStage};
use crate::pipeline::stage::OutputKind;
use crate::pipeline::work_units::{self, Unit, GATHER};

/// How assessing sees the files units wrote.
pub(super) trait Disk: Sync {
    /// The file's content hash now; None when it is missing (or unreadable).
    fn hash(&self, path: &Path) -> Option<String>;
    fn exists(&self, path: &Path) -> bool;
}

/// The file system, through the stat/hash memo (a file whose stat is unchanged is not read).
/// A folder found missing is remembered, and files below it are missing without a `stat`: the
/// files of a `keep: false` stage are gone with their folders, and a run asks after each of
/// them. What a run asks about is the committed output, which nothing changes before the
/// commit: one `RealDisk` serves one run (or one `status`).
#[derive(Default)]
pub(super) struct RealDisk {
    /// By their paths' bytes ([`paths::folders`]: not parsed component by component, which took
    /// longer than the `stat`s it saves at 10⁴ tests; an unusually spelled path is merely not
    /// found among them).
    missing: std::sync::RwLock<HashSet<Vec<u8>>>,
}

impl RealDisk {
    /// Whether a folder of `path` is known to be missing.
    fn below_missing(&self, path: &Path) -> bool {
        let missing = self.missing.read().expect("never poisoned");
        !missing.is_empty() && paths::folders(paths::bytes(path)).any(|f| missing.contains(f))
    }

    /// `path` is missing: remembers which of its folders are missing too.
    fn note_missing(&self, path: &Path) {
        let gone: Vec<&[u8]> = paths::folders(paths::bytes(path))
            .take_while(|f| std::fs::symlink_metadata(paths::from_bytes(f)).is_err())
            .collect();
        if !gone.is_empty() {
            self.missing.write().expect("never poisoned").extend(gone.into_iter().map(<[u8]>::to_vec));
        }
    }
}

impl Disk for RealDisk {
    fn hash(&self, path: &Path) -> Option<String> {
        if self.below_missing(path) {
            return None;
        }
        let hash = hash::hash_if_present(path);
        if hash.is_none() {
            self.note_missing(path);
        }
        hash
    }

    fn exists(&self, path: &Path) -> bool {
        if self.below_missing(path) {
            return false;
        }
        let exists = path.exists();
        if !exists {
            self.note_missing(path);
        }
        exists
    }
}

/// What assessing reads besides the plan, the same for every stage of a run.
pub(super) struct Known<'a> {
    pub(super) lock: &'a LockFile,
    pub(super) sources: &'a BTreeMap<String, ResolvedSource>,
    /// Per stage, the hashes of the files its `Path` parameters name.
    pub(super) files: &'a BTreeMap<String, BTreeMap<String, String>>,
    pub(super) rerun: &'a Rerun,
    pub(super) disk: &'a dyn Disk,
}

/// A hash standing for a file an upstream unit has yet to write (in `status` and `--dry-run`).
const PENDING: &str = "pending";

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
    disk: &dyn Disk,
) -> Vec<String> {
    if unit.hashes.values().any(|h| h == PENDING) {
        return vec!["an upstream unit will rerun".into()];
    }
    let Some(old) = entry.and_then(|e| e.units.get(&unit.id)) else {
        let what = if unit.id == GATHER { "never run" } else { "new record" };
        return vec![what.into()];
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
        match disk.hash(&stage_dir.join(file)) {
            None if !keep => {}
            None => reasons.push(format!("output file `{file}` missing")),
            Some(now) if now != *hash => reasons.push(format!("output file `{file}` was modified on disk")),
            Some(_) => {}
        }
    }
    reasons
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
    /// Every unit reads only records of its own first partition segment (`motion=FB-4`), so of
    /// its own bucket (`layout::fan_bucket`): a Slurm task cut by bucket needs only its buckets
    /// of the stages it reads.
    pub closed: bool,
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
                    .map(|u| format!("{}: {}", work_units::describe(&u.id), u.reasons.join("; ")))
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

/// What a run would do: each stage's status line, and the units of `keep: false` stages it
/// makes again because a unit that runs reads their removed files.
pub struct Prediction {
    pub lines: Vec<StatusLine>,
    pub remake: BTreeMap<String, BTreeMap<String, String>>,
    /// The assessments a run of this prediction may use as they are: of the stages none of
    /// whose units is made again and whose upstream stages are settled (every unit cached, none
    /// gone, none made again), so they read at run time exactly what they were assessed with.
    pub(super) settled: BTreeMap<String, AssessedStage>,
}

/// Each stage's units and which would run, and why: upstream units that would run stand for
/// the files they wrote last time (or one table per output at their partition), with a
/// [`PENDING`] hash. A unit of a `keep: false` stage whose files are gone but that a stale unit
/// reads is made again: it stands for its recorded hashes (it writes the same bytes).
/// With `only` (a run's selection, which holds what its stages read), the other stages are not
/// assessed: they do not run, so they neither run stale nor need anything made again.
pub(super) fn predict(
    plan: &Plan,
    known: &Known<'_>,
    only: Option<&BTreeSet<String>>,
) -> Result<Prediction, UserError> {
    let mut produced: BTreeMap<String, Produced> = BTreeMap::new();
    let mut lines = Vec::new();
    // Removed files of up-to-date `keep: false` units → (stage, unit); and, in run order, the
    // units reading some of them: (stage, unit, stale, the units whose files it reads).
    let mut removed: HashMap<OsString, (String, String)> = HashMap::new();
    let mut readers: Vec<(String, String, bool, BTreeSet<(String, String)>)> = Vec::new();
    let error = |e: anyhow::Error| match e.downcast::<UserError>() {
        Ok(user) => user,
        Err(e) => UserError::new(format!("{e:#}")),
    };
    let mut assessments: BTreeMap<String, AssessedStage> = BTreeMap::new();
    for stage in plan.stages.values().filter(|s| only.is_none_or(|only| only.contains(&s.name))) {
        let assessed = assess_stage(plan, stage, known, &produced).map_err(error)?;
        let stage_dir = plan.stage_dir(&stage.name);
        let entry = known.lock.stages.get(&stage.name);
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
            closed: assessed.units.par_iter().all(|(unit, _, _)| reads_own_segment(unit)),
        };
        for (unit, _, reasons) in &assessed.units {
            let old = entry.and_then(|e| e.units.get(&unit.id));
            let reads: BTreeSet<(String, String)> = unit
                .inputs
                .iter()
                .flat_map(|i| i.parts())
                .filter_map(|p| removed.get(p.path.as_os_str()).cloned())
                .collect();
            if !reads.is_empty() {
                readers.push((stage.name.clone(), unit.id.clone(), !reasons.is_empty(), reads));
            }
            if reasons.is_empty() {
                if let Some(old) = old {
                    let cached = cached_files(old, &stage_dir);
                    if !stage.keep {
                        for file in cached.values().filter(|f| !known.disk.exists(&f.path)) {
                            removed.insert(file.path.clone().into_os_string(), (stage.name.clone(), unit.id.clone()));
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
        assessments.insert(stage.name.clone(), assessed);
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
    let unchanged: BTreeSet<&str> = lines
        .iter()
        .filter(|l| l.stale.is_empty() && l.vanished.is_empty() && !remake.contains_key(&l.name))
        .map(|l| l.name.as_str())
        .collect();
    let settled = assessments
        .into_iter()
        .filter(|(name, _)| {
            let stage = &plan.stages[name];
            !remake.contains_key(name) && super::upstream_stages(stage).iter().all(|u| unchanged.contains(u))
        })
        .collect();
    Ok(Prediction { lines, remake, settled })
}

/// Whether every part `unit` reads (a source's files, a dataset's records) has the unit's first
/// partition segment.
fn reads_own_segment(unit: &Unit) -> bool {
    let own = crate::pipeline::layout::partition_of(unit.id.split('/').next().unwrap_or_default());
    !own.is_empty() && unit.inputs.iter().flat_map(|i| i.parts()).all(|p| p.partition.first() == own.first())
}

/// A stage split into units, each with its cache key and why it is stale (empty: cached).
pub(super) struct AssessedStage {
    pub(super) units: Vec<(Unit, String, Vec<String>)>,
    /// Unit ids in the lockfile that no record of the inputs has now.
    pub(super) vanished: Vec<String>,
}

/// Splits `stage` into units over its inputs this run (its sources, and the files `produced`
/// says its upstream stages have) and says of each why it is stale (empty: cached), and which
/// units of the lockfile no record has now. Pure but for `known.disk`, asked for the hash of
/// each file a unit wrote.
pub(super) fn assess_stage(
    plan: &Plan,
    stage: &PlannedStage,
    known: &Known<'_>,
    produced: &BTreeMap<String, Produced>,
) -> anyhow::Result<AssessedStage> {
    let (lock, rerun) = (known.lock, known.rerun);
    let inputs = stage_inputs(plan, stage, known.sources, produced)?;
    let split = work_units::split(stage, &inputs, known.files.get(&stage.name).unwrap_or(&BTreeMap::new()))?;
    let entry = lock.stages.get(&stage.name);
    let common = stage_reasons(stage, entry);
    let stage_dir = plan.stage_dir(&stage.name);
    let forced = rerun.stages.contains(&stage.name);
    let remake = rerun.remake.get(&stage.name);
    let key_prefix = work_units::key_prefix(stage);
    let units: Vec<(Unit, String, Vec<String>)> = split
        .into_par_iter()
        .map(|unit| {
            let key = unit.key(&key_prefix);
            let mut reasons = common.clone();
            if forced {
                reasons.push("forced".into());
            }
            let own = unit_reasons(&unit, &key, entry, &stage_dir, stage.keep, known.disk);
            reasons.extend(own.into_iter().filter(|r| common.is_empty() || !r.starts_with("new record")));
            if let Some(why) = remake.and_then(|r| r.get(&unit.id)).filter(|_| reasons.is_empty()) {
                reasons.push(why.clone());
            }
            (unit, key, reasons)
        })
        .collect();
    let ids: BTreeSet<&str> = units.iter().map(|(u, _, _)| u.id.as_str()).collect();
    let vanished = entry
        .map(|e| e.units.keys().filter(|id| !engine_unit(id) && !ids.contains(id.as_str())).cloned().collect())
        .unwrap_or_default();
    Ok(AssessedStage { units, vanished })
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{assess_load, entry_after, plan, sources, FakeDisk, PIPELINE};
    use super::*;

    #[test]
    fn a_unit_reading_only_records_of_its_own_first_segment_is_closed() {
        use crate::pipeline::stage::{InputPart, StageInput};
        let part = |partition: &[(&str, &str)]| InputPart {
            partition: partition.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect(),
            path: PathBuf::new(),
            label: String::new(),
            hash: String::new(),
        };
        let unit = |id: &str, parts: Vec<InputPart>| Unit {
            id: id.into(),
            inputs: vec![StageInput::Dataset { name: "up.records".into(), parts }],
            hashes: BTreeMap::new(),
        };
        let floors = vec![part(&[("motion", "FB 1"), ("floor", "4")]), part(&[("motion", "FB 1"), ("floor", "5")])];
        assert!(reads_own_segment(&unit("motion=FB%201", floors.clone())), "encoded ids, decoded partitions");
        assert!(reads_own_segment(&unit("motion=FB%201/floor=4", floors[..1].to_vec())));
        let other = vec![floors[0].clone(), part(&[("motion", "FB-2"), ("floor", "4")])];
        assert!(!reads_own_segment(&unit("motion=FB%201", other)), "a reference of another motion");
        assert!(!reads_own_segment(&unit("*", floors)), "a gathering unit");
    }

    fn reasons(assessed: &AssessedStage) -> Vec<(String, Vec<String>)> {
        assessed.units.iter().map(|(u, _, r)| (u.id.clone(), r.clone())).collect()
    }

    /// A lockfile whose `load` ran as assessed on `records`, and the disk it left.
    fn ran(plan: &Plan, records: &[(&str, &str)]) -> (LockFile, FakeDisk) {
        let mut disk = FakeDisk::default();
        let first = assess_load(plan, &sources(plan, records), &LockFile::empty(), &Rerun::default(), &disk);
        let mut lock = LockFile::empty();
        lock.stages.insert("load".into(), entry_after(plan, "load", &first, &mut disk));
        (lock, disk)
    }

    /// The key encoded from the stage's prefix is the key of the whole material encoded at once
    /// (what every lockfile written so far holds).
    #[test]
    fn a_key_from_the_stage_prefix_is_the_key_of_the_whole_material() {
        let dir = crate::tempdir::tempdir().unwrap();
        let plan = plan(dir.path(), PIPELINE);
        for stage in plan.stages.values() {
            let hashes: BTreeMap<String, String> =
                [("a/motion=X%20Y/data.parquet", "h\"1"), ("source s", "ü")].map(|(k, v)| (k.into(), v.into())).into();
            let unit = Unit { id: "motion=X".into(), inputs: Vec::new(), hashes };
            let info = stage.stage.info();
            let whole = serde_json::json!({"type": info.name, "version": info.version, "params": stage.params,
                "select": stage.select, "inputs": unit.hashes});
            assert_eq!(unit.key(&work_units::key_prefix(stage)), hash::hash_bytes(whole.to_string().as_bytes()));
        }
    }

    #[test]
    fn a_stage_never_run_is_stale_for_that_reason_alone() {
        let dir = crate::tempdir::tempdir().unwrap();
        let plan = plan(dir.path(), PIPELINE);
        let assessed = assess_load(
            &plan,
            &sources(&plan, &[("FB-1", "a"), ("FB-2", "b")]),
            &LockFile::empty(),
            &Rerun::default(),
            &FakeDisk::default(),
        );
        let never = vec!["never run (not in the lockfile)".to_string()];
        assert_eq!(
            reasons(&assessed),
            [("motion=FB-1".to_string(), never.clone()), ("motion=FB-2".to_string(), never)]
        );
        assert!(assessed.vanished.is_empty());
    }

    #[test]
    fn each_unit_is_stale_for_its_own_reasons_only() {
        let dir = crate::tempdir::tempdir().unwrap();
        let plan = plan(dir.path(), PIPELINE);
        let (lock, mut disk) = ran(&plan, &[("FB-1", "a"), ("FB-2", "b"), ("FB-3", "c")]);
        let unchanged = sources(&plan, &[("FB-1", "a"), ("FB-2", "b"), ("FB-3", "c")]);
        let again = assess_load(&plan, &unchanged, &lock, &Rerun::default(), &disk);
        assert!(again.units.iter().all(|(_, _, r)| r.is_empty()), "{:?}", reasons(&again));
        // One input edited, one output file removed, one modified, one record gone, one new.
        let stage_dir = plan.stage_dir("load");
        disk.files.remove(&stage_dir.join("records/motion=FB-1/data.parquet"));
        disk.files.insert(stage_dir.join("records/motion=FB-3/data.parquet"), "edited".into());
        let changed = sources(&plan, &[("FB-1", "a"), ("FB-2", "B"), ("FB-3", "c"), ("FB-4", "d")]);
        let changed = assess_load(&plan, &changed, &lock, &Rerun::default(), &disk);
        let ours = |unit: &str| reasons(&changed).into_iter().find(|(u, _)| u == unit).unwrap().1;
        assert_eq!(ours("motion=FB-1"), ["output file `records/motion=FB-1/data.parquet` missing"]);
        assert_eq!(ours("motion=FB-2"), ["input `archive/FB-2/daq.csv` changed"]);
        assert_eq!(ours("motion=FB-3"), ["output file `records/motion=FB-3/data.parquet` was modified on disk"]);
        assert_eq!(ours("motion=FB-4"), ["new record"]);
        let without = sources(&plan, &[("FB-1", "a"), ("FB-3", "c")]);
        assert_eq!(assess_load(&plan, &without, &lock, &Rerun::default(), &disk).vanished, ["motion=FB-2"]);
    }

    #[test]
    fn stage_wide_reasons_and_forcing_apply_to_every_unit() {
        let dir = crate::tempdir::tempdir().unwrap();
        let plan = plan(dir.path(), PIPELINE);
        let records = [("FB-1", "a"), ("FB-2", "b")];
        let (mut lock, disk) = ran(&plan, &records);
        let rerun = Rerun { stages: ["load".to_string()].into(), remake: BTreeMap::new() };
        let forced = assess_load(&plan, &sources(&plan, &records), &lock, &rerun, &disk);
        assert!(forced.units.iter().all(|(_, _, r)| r == &["forced"]), "{:?}", reasons(&forced));
        lock.stages.get_mut("load").unwrap().stage_version += 1;
        let bumped = assess_load(&plan, &sources(&plan, &records), &lock, &Rerun::default(), &disk);
        let version = plan.stages["load"].stage.info().version;
        let why = format!("stage type `load` changed: version {} → {version}", version + 1);
        assert!(
            bumped.units.iter().all(|(_, _, r)| r.as_slice() == std::slice::from_ref(&why)),
            "{:?}",
            reasons(&bumped)
        );
    }

    /// `load` not kept, its files gone, and `baseline` never run: the whole plan's prediction
    /// makes `load` again for `baseline`; a run of `load` alone does not (`baseline` does not run).
    #[test]
    fn a_prediction_of_selected_stages_makes_nothing_again_for_a_stage_not_selected() {
        let dir = crate::tempdir::tempdir().unwrap();
        let plan = plan(dir.path(), &PIPELINE.replace("inputs: [daq]", "inputs: [daq]\n    keep: false"));
        let records = [("FB-1", "a"), ("FB-2", "b")];
        let (lock, mut disk) = ran(&plan, &records);
        disk.files.clear();
        let (files, rerun, sources) = (BTreeMap::new(), Rerun::default(), sources(&plan, &records));
        let known = Known { lock: &lock, sources: &sources, files: &files, rerun: &rerun, disk: &disk };
        let whole = predict(&plan, &known, None).unwrap();
        assert_eq!(whole.remake["load"].keys().collect::<Vec<_>>(), ["motion=FB-1", "motion=FB-2"]);
        let only = predict(&plan, &known, Some(&["load".to_string()].into())).unwrap();
        assert!(only.remake.is_empty(), "{:?}", only.remake);
        assert_eq!(only.lines.iter().map(|l| (l.name.as_str(), l.is_stale())).collect::<Vec<_>>(), [("load", false)]);
        assert!(only.settled.contains_key("load"));
    }

    #[test]
    fn a_prediction_carries_a_stale_unit_to_the_units_reading_it() {
        let dir = crate::tempdir::tempdir().unwrap();
        let plan = plan(dir.path(), PIPELINE);
        let records = [("FB-1", "a"), ("FB-2", "b")];
        let (lock, disk) = ran(&plan, &records);
        let edited = sources(&plan, &[("FB-1", "a"), ("FB-2", "B")]);
        let (files, rerun) = (BTreeMap::new(), Rerun::default());
        let known = Known { lock: &lock, sources: &edited, files: &files, rerun: &rerun, disk: &disk };
        let prediction = predict(&plan, &known, None).unwrap();
        let stale: Vec<(&str, Vec<&str>)> = prediction
            .lines
            .iter()
            .map(|l| (l.name.as_str(), l.stale.iter().map(|u| u.id.as_str()).collect()))
            .collect();
        assert_eq!(stale, [("load", vec!["motion=FB-2"]), ("baseline", vec!["motion=FB-1", "motion=FB-2"])]);
        // `baseline` never ran: all its units are stale, FB-2's also for its pending input.
        let baseline = &prediction.lines[1];
        assert!(
            baseline.stale[1].reasons.contains(&"an upstream unit will rerun".to_string()),
            "{:?}",
            baseline.stale[1].reasons
        );
        // Assessing asked about the files `load` wrote, and nothing else.
        let asked = disk.asked.lock().unwrap();
        assert!(asked.iter().all(|p| p.starts_with(plan.stage_dir("load"))), "{asked:?}");
    }
}
