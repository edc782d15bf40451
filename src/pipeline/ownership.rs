//! What shakeflow may replace: only what it wrote, and never where a user's files live.
//!
//! Every stage folder shakeflow writes holds a marker, `<stage>/.shakeflow-stage`, naming the
//! stage and its type. Before anything runs, a folder where a stage's outputs would go must be
//! absent or carry that stage's marker (or, written by a shakeflow from before markers, be the
//! lockfile's); and `output_dir` itself must not be a file system root, the home folder, or a
//! folder holding the pipeline file or its inputs.

use std::collections::{HashMap, HashSet};
use std::path::{Component, Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::layout::{LOCK_FILE, STAGE_MARKER, STATE_DIR};
use super::lock::LockFile;
use super::paths;
use super::plan::Plan;
use super::spec::PipelineFile;
use crate::error::UserError;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageMarker {
    pub stage: String,
    #[serde(rename = "type")]
    pub stage_type: String,
}

/// Marks `dir` as the output folder of `stage` (of type `stage_type`). Deterministic bytes.
pub fn write_marker(dir: &Path, stage: &str, stage_type: &str) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let marker = StageMarker { stage: stage.into(), stage_type: stage_type.into() };
    let body = serde_json::to_vec_pretty(&marker)?;
    crate::io::atomic::write_bytes(&dir.join(STAGE_MARKER), &body)
}

pub fn read_marker(dir: &Path) -> Option<StageMarker> {
    serde_json::from_slice(&std::fs::read(dir.join(STAGE_MARKER)).ok()?).ok()
}

/// `path` with its longest existing ancestor resolved (symlinks, `..`) and the rest appended:
/// where it is or would be, for comparing folders that may not exist yet.
pub fn resolved(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let normal = super::spec::lexically_normal(&absolute);
    let mut existing = normal.as_path();
    let mut rest = Vec::new();
    loop {
        if let Ok(real) = existing.canonicalize() {
            let mut out = real;
            out.extend(rest.iter().rev());
            return out;
        }
        match (existing.parent(), existing.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                existing = parent;
            }
            _ => return normal,
        }
    }
}

/// The folder part of a source path before its first wildcard or `{key}`: where its files lie.
fn literal_prefix(base: &Path, pattern: &str) -> PathBuf {
    let mut prefix = PathBuf::new();
    for component in Path::new(pattern).components() {
        let text = component.as_os_str().to_string_lossy();
        if text.contains(['*', '?', '[', '{']) {
            return base.join(prefix);
        }
        prefix.push(component);
    }
    // A plain file path: its folder holds it.
    base.join(prefix.parent().unwrap_or(Path::new("")))
}

/// Refuses an `output_dir` that shakeflow must never write into: a file system root, the home
/// folder, or a folder holding the pipeline file, a record source or a file a parameter names
/// (`files`, resolved; source patterns are checked by their literal folder too, so this holds
/// before the sources are resolved).
pub fn check_output_dir(file: &PipelineFile, files: &[PathBuf]) -> Result<(), UserError> {
    let output_dir = resolved(&file.output_dir());
    let refuse = |why: String| match file.command {
        Some(_) => UserError::new(format!("the output folder `{}` {why}", file.spec.output_dir))
            .hint("give the command an output folder of its own (`--output`), new or written by it before"),
        None => file.error_at(&["output_dir"], format!("`output_dir: {}` {why}", file.spec.output_dir)).hint(
            "shakeflow replaces stage folders in `output_dir` and may one day clean it: give it a folder of its own, \
             e.g. `output_dir: ../runs/<study>` (relative to the pipeline file)",
        ),
    };
    let is_root = !output_dir.components().any(|c| matches!(c, Component::Normal(_)));
    if is_root {
        return Err(refuse(format!("is `{}`, the root of a file system", output_dir.display())));
    }
    if let Some(home) = std::env::var_os("HOME").filter(|h| !h.is_empty()) {
        if resolved(Path::new(&home)) == output_dir {
            return Err(refuse(format!("is the home folder `{}`", output_dir.display())));
        }
    }
    let pipeline = resolved(&file.path);
    if file.command.is_none() && pipeline.starts_with(&output_dir) {
        return Err(refuse(format!("holds the pipeline file itself (`{}`)", file.path.display())));
    }
    let base = file.base_dir();
    let inside = |input: &str| match file.command {
        Some(_) => {
            UserError::new(format!("the input `{input}` is inside the output folder `{}`", file.spec.output_dir))
                .hint("the output folder is shakeflow's to replace: give a new or empty folder outside the inputs")
        }
        None => refuse(format!("holds the input `{input}`")),
    };
    for (name, source) in &file.spec.inputs {
        // A command's source names its file (or folder) literally.
        let folder = match file.command {
            Some(_) => resolved(&base.join(&source.path)),
            None => resolved(&literal_prefix(&base, &source.path)),
        };
        if folder.starts_with(&output_dir) {
            return Err(match file.command {
                Some(_) => inside(&source.path),
                None => refuse(format!("holds the files of source `{name}` (`{}`)", source.path)),
            });
        }
    }
    // Which files and folders are links, asked of all at once: one `lstat` each (one per record
    // file, the run's largest share, and one per folder above them), then each folder resolved once.
    let links: Vec<bool> = files.par_iter().map(|f| is_link(f)).collect();
    let mut folders = ResolvedFolders::above(files);
    if let Some((input, _)) =
        files.iter().zip(links).find(|(f, link)| folders.resolve_known(f, *link).starts_with(&output_dir))
    {
        return Err(inside(&input.display().to_string()));
    }
    Ok(())
}

fn is_link(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink())
}

/// [`resolved`] for many files, most of them side by side: a file or folder is its folder's
/// resolution and its name, each folder resolved once (and its own folder the same way), unless
/// it is a symbolic link (or not plain: see [`folder_of`]), which [`resolved`] resolves on its
/// own. The same answer as [`resolved`], in one `lstat` per file and per folder instead of a
/// `readlink` per path component of every folder. Folders are their paths' bytes: at 10⁴ tests
/// (6·10⁴ folders) hashing and parsing paths component by component took longer than the
/// `lstat`s.
struct ResolvedFolders<'a> {
    /// Per folder above the plain files, whether it is a symbolic link (asked of all at once).
    links: HashMap<&'a [u8], bool>,
    /// Per folder, its resolution once asked for.
    known: HashMap<&'a [u8], PathBuf>,
}

/// Whether a path's bytes are plain: absolute, with no `.` or `..` component and no doubled or
/// trailing `/`, as a walk of the file system makes them. Its [`paths::folders`] are then its
/// folders as [`resolved`] would walk them.
fn is_plain_path(path: &[u8]) -> bool {
    path.first() == Some(&b'/')
        && !path.ends_with(b"/")
        && !path.windows(2).any(|w| w == b"//")
        && !path.split(|&b| b == b'/').any(|c| c == b"." || c == b"..")
}

/// The folder of a plain path; None for the root and its children, and for a path not plain.
fn folder_of(path: &[u8]) -> Option<&[u8]> {
    paths::folders(path).next().filter(|_| is_plain_path(path))
}

impl<'a> ResolvedFolders<'a> {
    /// For `files`: the folders above them asked whether they are links, all at once.
    fn above(files: &'a [PathBuf]) -> ResolvedFolders<'a> {
        let mut folders = HashSet::new();
        for file in files.iter().map(|f| paths::bytes(f)).filter(|f| is_plain_path(f)) {
            // Up to the first folder seen before: its own folders are in already.
            for folder in paths::folders(file) {
                if !folders.insert(folder) {
                    break;
                }
            }
        }
        let links = folders.into_par_iter().map(|f| (f, is_link(paths::from_bytes(f)))).collect();
        ResolvedFolders { links, known: HashMap::new() }
    }

    /// `file` resolved, `link` telling whether it is a symbolic link (its `lstat`, asked by the caller).
    fn resolve_known(&mut self, file: &'a Path, link: bool) -> PathBuf {
        let (Some(folder), Some(name)) = (folder_of(paths::bytes(file)), file.file_name()) else {
            return resolved(file);
        };
        if link {
            return resolved(file);
        }
        if let Some(known) = self.known.get(folder) {
            return known.join(name);
        }
        let folder_link = self.links.get(folder).copied().unwrap_or_else(|| is_link(paths::from_bytes(folder)));
        let real = self.resolve_known(paths::from_bytes(folder), folder_link);
        let joined = real.join(name);
        self.known.insert(folder, real);
        joined
    }
}

/// Refuses, before anything runs, a stage whose folder in `output_dir` exists but is not that
/// stage's: a user's folder that happens to share its name is never replaced. An empty folder
/// (but for shakeflow's own state) is anyone's.
pub fn check_stage_folders(plan: &Plan, lock: &LockFile) -> Result<(), UserError> {
    let file = &plan.file;
    for stage in plan.stages.keys().map(String::as_str) {
        let dir = plan.stage_dir(stage);
        let Ok(meta) = std::fs::symlink_metadata(&dir) else { continue };
        let stage_type = plan.stages[stage].stage.info().name;
        let problem = if !meta.is_dir() {
            Some(if meta.file_type().is_symlink() { "is a symbolic link" } else { "is a file" }.to_string())
        } else {
            match read_marker(&dir) {
                Some(marker) if marker.stage == stage => None,
                // A command's stage is named by its type.
                Some(marker) if file.command.is_some() => {
                    Some(format!("holds an earlier output of stage type `{}`, not `{stage_type}`", marker.stage_type))
                }
                Some(marker) => Some(format!("holds the outputs of stage `{}`, not `{stage}`", marker.stage)),
                // Written by a shakeflow from before markers: the lockfile knows it.
                None if lock.stages.contains_key(stage) => None,
                None if is_empty(&dir) => None,
                None => Some(format!("was not written by shakeflow (it has no `{STAGE_MARKER}` marker)")),
            }
        };
        if let Some(problem) = problem {
            return Err(match file.command {
                Some(_) => UserError::new(format!("the output folder `{}` {problem}", dir.display())).hint(
                    "give a new or empty folder, or one an earlier run of the same command wrote; nothing was changed",
                ),
                None => file
                    .error_at(&["stages", stage], format!("stage `{stage}` would replace `{}`, which {problem}", dir.display()))
                    .hint("shakeflow replaces only folders it wrote: rename the stage or choose another `output_dir`; nothing was changed"),
            });
        }
    }
    Ok(())
}

/// Whether `dir` holds nothing but shakeflow's state folder and lockfile.
fn is_empty(dir: &Path) -> bool {
    std::fs::read_dir(dir)
        .is_ok_and(|entries| entries.flatten().all(|e| e.file_name() == STATE_DIR || e.file_name() == LOCK_FILE))
}

/// How the lockfile names the pipeline that owns its folder: the pipeline file's path relative
/// to the output folder, both resolved (`../pipelines/demo.yaml`); the same on every machine.
/// A pipeline made by a command is named by the command (`shakeflow stage`).
pub fn pipeline_label(file: &PipelineFile) -> String {
    if let Some(command) = &file.command {
        return command.clone();
    }
    let from = resolved(&file.output_dir());
    let to = resolved(&file.path);
    let common = from.components().zip(to.components()).take_while(|(a, b)| a == b).count();
    let ups = from.components().count() - common;
    let mut parts: Vec<String> = vec!["..".to_string(); ups];
    parts.extend(to.components().skip(common).map(|c| c.as_os_str().to_string_lossy().into_owned()));
    parts.join("/")
}

/// Refuses a pipeline writing into an output folder whose lockfile belongs to another pipeline:
/// the two would replace each other's stages without a word.
pub fn check_pipeline(file: &PipelineFile, lock: &LockFile) -> Result<(), UserError> {
    let ours = pipeline_label(file);
    match &lock.pipeline {
        Some(owner) if *owner != ours => Err(file
            .error_at(
                &["output_dir"],
                format!(
                    "{} holds the results of another pipeline, `{owner}` (relative to that folder; its lockfile says so)",
                    match file.command {
                        Some(_) => format!("the output folder `{}`", file.spec.output_dir),
                        None => format!("`output_dir: {}`", file.spec.output_dir),
                    }
                ),
            )
            .hint(format!(
                "two pipelines writing one folder would replace each other's stages: give this one its own `output_dir`. \
                 If you moved or renamed the pipeline file, delete `{}` to hand the folder over (every stage then reruns)",
                file.output_dir().join(LOCK_FILE).display()
            ))),
        _ => Ok(()),
    }
}

/// Stage folders of `output_dir` that shakeflow wrote (they carry a marker) for a stage the
/// pipeline no longer has, sorted.
pub fn orphaned_stage_folders(output_dir: &Path, stages: &[&str]) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(output_dir) else { return Vec::new() };
    let mut orphans: Vec<String> = entries
        .flatten()
        .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let marker = read_marker(&e.path())?;
            (marker.stage == name && !stages.contains(&name.as_str())).then_some(name)
        })
        .collect();
    orphans.sort();
    orphans
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn literal_prefixes_stop_at_the_first_pattern() {
        let base = Path::new("/p");
        assert_eq!(literal_prefix(base, "archive/{motion}/daq.csv"), Path::new("/p/archive"));
        assert_eq!(literal_prefix(base, "gm/*.AT2"), Path::new("/p/gm"));
        assert_eq!(literal_prefix(base, "data/one.csv"), Path::new("/p/data"));
        assert_eq!(literal_prefix(base, "one.csv"), Path::new("/p"));
    }

    #[test]
    fn resolved_paths_follow_existing_folders_and_keep_the_rest() {
        let dir = crate::tempdir::tempdir().unwrap();
        let real = dir.path().canonicalize().unwrap();
        assert_eq!(resolved(&dir.path().join("a/../b/c")), real.join("b/c"));
    }

    #[cfg(unix)]
    #[test]
    fn files_resolved_by_their_folder_are_resolved_alike_symbolic_links_included() {
        let dir = crate::tempdir::tempdir().unwrap();
        let d = dir.path();
        for folder in ["data/a", "out/x"] {
            std::fs::create_dir_all(d.join(folder)).unwrap();
        }
        std::fs::write(d.join("data/a/r.csv"), "").unwrap();
        std::fs::write(d.join("out/x/o.csv"), "").unwrap();
        std::os::unix::fs::symlink(d.join("out/x/o.csv"), d.join("data/a/link.csv")).unwrap();
        std::os::unix::fs::symlink(d.join("out/x"), d.join("data/b")).unwrap();
        let files = [
            "data/a/r.csv",
            "data/a/link.csv",
            "data/b/o.csv",
            "data/b/../a/r.csv",
            "data/a/missing.csv",
            "data/c/d.csv",
            "data/b/new/deeper/d.csv",
            "data/a/../b/o.csv",
        ];
        // The folders' links asked beforehand (all of them, or only the first file's).
        let paths: Vec<PathBuf> = files.iter().map(|f| d.join(f)).collect();
        for asked in [&paths[..], &paths[..1]] {
            let mut folders = ResolvedFolders::above(asked);
            for (file, path) in files.iter().zip(&paths) {
                assert_eq!(folders.resolve_known(path, is_link(path)), resolved(path), "{file}");
            }
        }
        let link = d.join("data/a/link.csv");
        let mut folders = ResolvedFolders::above(&[]);
        assert_eq!(folders.resolve_known(Path::new("r.csv"), false), resolved(Path::new("r.csv")));
        assert_eq!(folders.resolve_known(Path::new("/r.csv"), false), resolved(Path::new("/r.csv")));
        // What the output folder check relies on: a link into it is seen through.
        assert!(folders.resolve_known(&link, true).starts_with(d.canonicalize().unwrap().join("out")));
    }
}
