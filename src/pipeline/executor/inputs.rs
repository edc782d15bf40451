//! What a stage reads this run: its sources resolved to files (hashed, through the stat memo),
//! the files its `Path` parameters name, and the parts its upstream stages produced, restricted
//! by its `select:`.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::ffi::OsString;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::error::UserError;
use crate::io::hash;
use crate::pipeline::layout::{
    fan_bucket, fan_out_above, fans_out, memo_bucket, partition_of, partition_path, placed, DATA_FILE, HASH_MEMO,
    STATE_DIR,
};
use crate::pipeline::lock::UnitLock;
use crate::pipeline::plan::{InputRef, Plan, PlannedStage};
use crate::pipeline::sources;
use crate::pipeline::spec::{RecordFormat, SourceSpec};
use crate::pipeline::stage::{InputPart, StageInput};

/// A source resolved to files.
pub(super) struct ResolvedSource {
    pub(super) input: StageInput,
}

/// A file a stage wrote (or will write): where it is now and its content hash.
#[derive(Clone)]
pub(super) struct ProducedFile {
    pub(super) path: PathBuf,
    pub(super) hash: String,
}

/// A stage's files that downstream stages read this run, by path relative to the stage folder.
pub(super) type Produced = BTreeMap<String, ProducedFile>;

pub(super) fn resolve_sources(plan: &Plan) -> Result<BTreeMap<String, ResolvedSource>, UserError> {
    resolve_sources_of(plan, None, None, None)
}

/// A source's files as the Slurm planner listed them for one shard (its buckets' records), so
/// the shard's task need not walk the archive: each path relative to the pipeline's folder
/// where it is below it (the task joins it to its own, as its walk would), else as matched;
/// `fanned`: whether the whole source is past the fan-out limit (its files' hashes are
/// remembered by bucket).
#[derive(Debug, serde::Serialize, serde::Deserialize)]
pub(super) struct Listed {
    pub(super) fanned: bool,
    pub(super) files: Vec<sources::MatchedFile>,
}

impl Listed {
    /// Whether the planner lists `spec`'s files: a source of one file per record (a folder, a
    /// case or a record of several component files is walked by the task, as before).
    pub(super) fn lists(spec: &SourceSpec) -> bool {
        !spec.format.names_folders() && spec.format != RecordFormat::Case && spec.components.is_none()
    }

    /// The listing saved in `file` (None: there is none), its files as found from `base` (the
    /// pipeline's folder) that are still files (a file gone since, or no longer a file, is a
    /// record gone, as a walk would find); and how many are kept and gone.
    pub(super) fn read(file: &Path, base: &Path) -> anyhow::Result<Option<(BTreeMap<String, Listed>, usize, usize)>> {
        use anyhow::Context;
        let bytes = match std::fs::read(file) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(e).with_context(|| format!("reading the planner's listing `{}`", file.display())),
        };
        let mut listed: BTreeMap<String, Listed> = serde_json::from_slice(&bytes).with_context(|| {
            format!("the planner's listing `{}` is damaged; run again (a new run lists anew)", file.display())
        })?;
        let (mut kept, mut gone) = (0, 0);
        for source in listed.values_mut() {
            let before = source.files.len();
            source.files = std::mem::take(&mut source.files)
                .into_iter()
                .map(|f| sources::MatchedFile { path: base.join(&f.path), ..f })
                .filter(|f| std::fs::metadata(&f.path).is_ok_and(|m| m.is_file()))
                .collect();
            (kept, gone) = (kept + source.files.len(), gone + before - source.files.len());
        }
        Ok(Some((listed, kept, gone)))
    }
}

/// For each shard of `shards`, per source of `names` (sources the planner lists:
/// [`Listed::lists`]), the files of `sources` (resolved from the pipeline's folder) of that
/// shard's buckets (`shard_of` a bucket), as [`Listed`]: each source gone through once.
pub(super) fn listings(
    plan: &Plan,
    sources: &BTreeMap<String, ResolvedSource>,
    names: &BTreeSet<&str>,
    shards: &BTreeSet<usize>,
    shard_of: impl Fn(u8) -> usize,
) -> BTreeMap<usize, BTreeMap<String, Listed>> {
    let base = plan.file.base_dir();
    let mut listed: BTreeMap<usize, BTreeMap<String, Listed>> = BTreeMap::new();
    for (name, source) in names.iter().filter_map(|name| sources.get(*name).map(|s| (*name, s))) {
        let ids: Vec<String> = source.input.parts().iter().map(|p| partition_path(&p.partition)).collect();
        let fanned = fans_out(ids.iter().map(String::as_str), fan_out_above());
        for &shard in shards {
            listed.entry(shard).or_default().insert(name.to_string(), Listed { fanned, files: Vec::new() });
        }
        for (part, id) in source.input.parts().iter().zip(&ids) {
            let Some(shard) = listed.get_mut(&shard_of(fan_bucket(id))) else { continue };
            let file = sources::MatchedFile {
                path: part.path.strip_prefix(&base).unwrap_or(&part.path).to_path_buf(),
                partition: part.partition.clone(),
            };
            shard.get_mut(name).expect("every shard lists every source").files.push(file);
        }
    }
    listed
}

/// [`resolve_sources`] of the sources `stage` reads only (all: None), and of them only the
/// records of `buckets` (`layout::fan_bucket` of their partition; all: None), whose files alone
/// are hashed: what a Slurm task of a bucketed stage needs. A source in `listed` is not walked:
/// its files are the listed ones.
pub(super) fn resolve_sources_of(
    plan: &Plan,
    stage: Option<&str>,
    buckets: Option<&BTreeSet<u8>>,
    listed: Option<&BTreeMap<String, Listed>>,
) -> Result<BTreeMap<String, ResolvedSource>, UserError> {
    // A no-op rerun then reads no file whose size and times are unchanged.
    hash::use_memo(&plan.file.output_dir().join(STATE_DIR).join(HASH_MEMO), memo_bucket);
    let base = plan.file.base_dir();
    let used: BTreeSet<&str> = plan
        .stages
        .values()
        .filter(|s| stage.is_none_or(|only| s.name == only))
        .flat_map(super::source_inputs)
        .collect();
    let mut resolved = BTreeMap::new();
    // Sources may share files (one DAQ export split into floors): each file is read once. By
    // their paths' bytes: hashed and compared whole, not component by component.
    let mut hashed: HashMap<OsString, String> = HashMap::new();
    // ... and their folders are walked once.
    let mut resolver = sources::Resolver::default();
    for name in used {
        let spec = &plan.file.spec.inputs[name];
        let (files, fanned) = match listed.and_then(|l| l.get(name)) {
            Some(listed) => (listed.files.clone(), Some(listed.fanned)),
            None => (files_of(plan, name, spec, &mut resolver)?, None),
        };
        // A source of more records than a folder holds has its files remembered by bucket, as
        // its records' state is: a task reads the memo of its own buckets.
        let ids: Vec<String> = files.iter().map(|f| partition_path(&f.partition)).collect();
        let fanned = fanned.unwrap_or_else(|| fans_out(ids.iter().map(String::as_str), fan_out_above()));
        let mut files: Vec<(u8, _)> = files.into_iter().zip(&ids).map(|(f, id)| (fan_bucket(id), f)).collect();
        if let Some(buckets) = buckets {
            files.retain(|(bucket, _)| buckets.contains(bucket));
        }
        let unhashed: Vec<(&Path, Option<u8>)> = files
            .iter()
            .map(|(bucket, f)| (f.path.as_path(), fanned.then_some(*bucket)))
            .filter(|(p, _)| !hashed.contains_key(p.as_os_str()))
            .collect();
        let new_hashes: Vec<String> = unhashed
            .par_iter()
            .map(|(p, bucket)| hash::hash_path(p, *bucket))
            .collect::<anyhow::Result<_>>()
            .map_err(|e| UserError::new(format!("source `{name}`: {e:#}")))?;
        hashed.extend(unhashed.into_iter().map(|(p, _)| p.as_os_str().to_os_string()).zip(new_hashes));
        let parts: Vec<InputPart> = files
            .into_iter()
            .map(|(_, f)| {
                let relative = f.path.strip_prefix(&base).unwrap_or(&f.path).to_string_lossy().replace('\\', "/");
                // A dataset's records are labelled alike in either layout (`layout::placed`).
                let relative = placed(&relative, false).into_owned();
                let hash = hashed[f.path.as_os_str()].clone();
                InputPart { partition: f.partition, path: f.path, label: relative, hash }
            })
            .collect();
        let input = match spec.format {
            RecordFormat::Dataset => StageInput::Dataset { name: name.to_string(), parts },
            _ => StageInput::Source {
                name: name.to_string(),
                spec: std::sync::Arc::new(spec.clone()),
                base_dir: base.clone(),
                files: parts,
            },
        };
        resolved.insert(name.to_string(), ResolvedSource { input });
    }
    Ok(resolved)
}

/// The files a source reads, with their partitions: its path matched as a pattern (a command's
/// names one file or folder literally); a case is its folder, a dataset folder its parts.
pub fn source_files(plan: &Plan, name: &str, spec: &SourceSpec) -> Result<Vec<sources::MatchedFile>, UserError> {
    files_of(plan, name, spec, &mut sources::Resolver::default())
}

/// [`source_files`], through `resolver` (a pattern that another source has already walked is
/// not walked again).
fn files_of(
    plan: &Plan,
    name: &str,
    spec: &SourceSpec,
    resolver: &mut sources::Resolver,
) -> Result<Vec<sources::MatchedFile>, UserError> {
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
        None => resolver.resolve(&base, &spec.path, &spec.partition, spec.format.names_folders()).map_err(|e| {
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

/// Per stage, the content hashes of the files its `Path` parameters name, keyed
/// `params.<name> (<path as written>)`: editing such a file reruns the stage.
pub(super) fn param_file_hashes(plan: &Plan) -> Result<BTreeMap<String, BTreeMap<String, String>>, UserError> {
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
pub(super) fn stage_inputs(
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
    let in_folder = format!("/{DATA_FILE}");
    // The output's files are the keys that start with its prefix: one run of the sorted map.
    produced
        .range::<str, _>((std::ops::Bound::Included(prefix.as_str()), std::ops::Bound::Unbounded))
        .map_while(|(relative, file)| relative.strip_prefix(&prefix).map(|inner| (relative, inner, file)))
        .filter_map(|(relative, inner, file)| {
            if inner != DATA_FILE && !inner.ends_with(&in_folder) {
                return None;
            }
            // Labels (and so the readers' cache keys) are the same in either layout.
            let flat = placed(relative, false);
            let inner = flat.strip_prefix(&prefix).unwrap_or(inner);
            Some(InputPart {
                partition: partition_of(inner),
                path: file.path.clone(),
                label: format!("{label}/{inner}"),
                hash: file.hash.clone(),
            })
        })
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
                .at(crate::pipeline::locate::key_position(&plan.file.text, &["stages", &stage.name, "select", key]))
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
pub(super) fn cached_files(old: &UnitLock, stage_dir: &Path) -> Produced {
    old.files.iter().map(|(f, h)| (f.clone(), ProducedFile { path: stage_dir.join(f), hash: h.clone() })).collect()
}

/// Every file a run reads: record files and files named by parameters, each once (sources
/// may share files).
pub(super) fn input_paths(plan: &Plan, sources: &BTreeMap<String, ResolvedSource>) -> Vec<PathBuf> {
    let records = sources.values().flat_map(|s| s.input.parts().iter().map(|p| &p.path));
    let params = plan.stages.values().flat_map(|s| s.files.values());
    let mut seen = std::collections::HashSet::new();
    records.chain(params).filter(|p| seen.insert(p.as_os_str())).cloned().collect()
}
