//! Resolving a source's `path` (file, glob or `{key}` template) to record files and partitions.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::stage::Partition;
use crate::error::UserError;

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MatchedFile {
    pub path: PathBuf,
    pub partition: Partition,
}

#[derive(Debug, Clone, PartialEq)]
enum Piece {
    Literal(String),
    Key(String),
    /// `*` beside keys: any characters within one path segment, no partition key
    /// (`Experiment-*/Trial-*/Rep-1/Converted_Data/{motion}_DAQ1.txt`).
    Wild,
}

/// Literal text, its `*`s as [`Piece::Wild`].
fn push_literal(pieces: &mut Vec<Piece>, text: &str) {
    for (k, part) in text.split('*').enumerate() {
        if k > 0 {
            pieces.push(Piece::Wild);
        }
        if !part.is_empty() {
            pieces.push(Piece::Literal(part.to_string()));
        }
    }
}

/// Why a path template does not parse.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
enum TemplateError {
    #[error("unclosed `{{` in `{template}`")]
    Unclosed { template: String },
    #[error("`{{{key}}}` in `{template}` is not a valid partition key (letters, digits, _)")]
    BadKey { key: String, template: String },
}

fn parse_template(template: &str) -> Result<Vec<Piece>, TemplateError> {
    let mut pieces = Vec::new();
    let mut rest = template;
    while let Some(open) = rest.find('{') {
        push_literal(&mut pieces, &rest[..open]);
        let close = rest[open..].find('}').ok_or_else(|| TemplateError::Unclosed { template: template.into() })? + open;
        let key = &rest[open + 1..close];
        if key.is_empty() || !key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(TemplateError::BadKey { key: key.into(), template: template.into() });
        }
        pieces.push(Piece::Key(key.to_string()));
        rest = &rest[close + 1..];
    }
    push_literal(&mut pieces, rest);
    Ok(pieces)
}

/// Matches `text` against the pieces; a key takes one or more characters within one path segment.
fn match_pieces(text: &str, pieces: &[Piece]) -> Option<Partition> {
    match pieces.split_first() {
        None => text.is_empty().then(Vec::new),
        Some((Piece::Literal(lit), rest)) => text.strip_prefix(lit.as_str()).and_then(|t| match_pieces(t, rest)),
        Some((Piece::Key(key), rest)) => {
            let segment_end = text.find('/').unwrap_or(text.len());
            (1..=segment_end).filter(|&n| text.is_char_boundary(n)).find_map(|n| {
                let mut found = match_pieces(&text[n..], rest)?;
                found.insert(0, (key.clone(), text[..n].to_string()));
                Some(found)
            })
        }
        Some((Piece::Wild, rest)) => {
            let segment_end = text.find('/').unwrap_or(text.len());
            (0..=segment_end).filter(|&n| text.is_char_boundary(n)).find_map(|n| match_pieces(&text[n..], rest))
        }
    }
}

/// Files of a source, sorted by path, each with its partition keys: template keys first, then
/// the source's constant keys; a plain glob gets `file=<stem>` so records stay distinct.
/// With `folders`, directories match too (an image sequence is a folder of frames).
pub fn resolve(
    base_dir: &Path,
    pattern: &str,
    constant: &std::collections::BTreeMap<String, String>,
    folders: bool,
) -> Result<Vec<MatchedFile>, UserError> {
    Resolver::default().resolve(base_dir, pattern, constant, folders)
}

/// [`resolve`] for several sources, each path pattern walked once: sources that read the same
/// files and tell them apart by their constant keys (one DAQ export split into floors) share
/// one walk of the folders.
#[derive(Default)]
pub struct Resolver(std::collections::HashMap<(PathBuf, String, bool), Vec<MatchedFile>>);

impl Resolver {
    /// [`resolve`], the walk of a pattern seen before reused.
    pub fn resolve(
        &mut self,
        base_dir: &Path,
        pattern: &str,
        constant: &std::collections::BTreeMap<String, String>,
        folders: bool,
    ) -> Result<Vec<MatchedFile>, UserError> {
        let key = (base_dir.to_path_buf(), pattern.to_string(), folders);
        let walked = match self.0.entry(key) {
            std::collections::hash_map::Entry::Occupied(known) => known.into_mut(),
            std::collections::hash_map::Entry::Vacant(new) => new.insert(walk(base_dir, pattern, folders)?),
        };
        let mut files = walked.clone();
        for file in &mut files {
            file.partition.extend(constant.iter().map(|(k, v)| (k.clone(), v.clone())));
        }
        Ok(files)
    }
}

/// The files (and with `folders`, folders) `pattern` matches, sorted by path, with their
/// template keys (or `file=<stem>`), not yet the source's constant keys.
fn walk(base_dir: &Path, pattern: &str, folders: bool) -> Result<Vec<MatchedFile>, UserError> {
    let pieces = parse_template(pattern).map_err(|e| UserError::new(e.to_string()))?;
    let has_keys = pieces.iter().any(|p| matches!(p, Piece::Key(_)));
    let glob_pattern = glob_of(&pieces);
    let is_glob = glob_pattern.contains(['*', '?', '[']);
    let full = base_dir.join(&glob_pattern);
    let full_text = full.to_string_lossy().replace('\\', "/");
    let matched = match walk_stars(&full_text) {
        Some(walked) => walked?,
        None => {
            let entries =
                glob::glob(&full_text).map_err(|e| UserError::new(format!("invalid path pattern `{pattern}`: {e}")))?;
            let mut matched = Vec::new();
            for entry in entries {
                let path = entry
                    .map_err(|e| UserError::new(format!("cannot read `{}`: {}", e.path().display(), e.error())))?;
                let kind = Kind::of(&path);
                matched.push((path, kind));
            }
            matched
        }
    };
    let mut files = Vec::new();
    for (path, kind) in matched {
        if !(kind == Kind::File || folders && kind == Kind::Folder) {
            continue;
        }
        let partition = if has_keys {
            match match_path(base_dir, &glob_pattern, &pieces, &path) {
                Some(p) => p,
                None => continue,
            }
        } else if is_glob {
            let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            vec![("file".to_string(), stem)]
        } else {
            Vec::new()
        };
        files.push(MatchedFile { path, partition });
    }
    files.sort_by(|a, b| a.path.cmp(&b.path));
    if files.is_empty() {
        return Err(UserError::new(format!("no file matches `{pattern}` (looked for `{}`)", full.display())).hint(
            "check the path (relative paths start at the pipeline file's folder); for the demo archive run `shakeflow demo-archive runs/demo-archive` or `make demo`",
        ));
    }
    Ok(files)
}

/// What a matched path is, links followed (`Path::is_file`, `Path::is_dir`).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    File,
    Folder,
    Other,
}

impl Kind {
    fn of(path: &Path) -> Kind {
        match std::fs::metadata(path) {
            Ok(m) if m.is_file() => Kind::File,
            Ok(m) if m.is_dir() => Kind::Folder,
            _ => Kind::Other,
        }
    }
}

/// The paths the glob `full` matches, as `glob::glob` finds them (the same paths, `.` not
/// prefixed to a relative one), when its only wildcard is `*` within a segment — what every
/// template makes of its keys and `*`s: each folder is listed once and what its entries are is
/// taken from the listing (a `stat` only for a symbolic link), where `glob` asks `stat` of every
/// folder it passes and the caller of every file. None: `full` has other wildcards (`?`, `[…]`,
/// `**`), an empty segment or a trailing `/`; `glob` then resolves it.
fn walk_stars(full: &str) -> Option<Result<Vec<(PathBuf, Kind)>, UserError>> {
    let (root, rest) = match full.strip_prefix('/') {
        Some(rest) => ("/", rest),
        None => (".", full),
    };
    let segments: Vec<&str> = rest.split('/').collect();
    if segments.iter().any(|s| s.is_empty() || s.contains(['?', '[', ']']) || s.contains("**")) {
        return None;
    }
    let mut found = Vec::new();
    let result = walk_segments(PathBuf::from(root), Kind::Folder, &segments, &mut found);
    Some(result.map(|()| found))
}

/// `dir` joined with `name` as `glob` joins them: below `.`, the name alone.
fn joined(dir: &Path, name: &str) -> PathBuf {
    if dir == Path::new(".") {
        PathBuf::from(name)
    } else {
        dir.join(name)
    }
}

fn walk_segments(
    dir: PathBuf,
    kind: Kind,
    segments: &[&str],
    found: &mut Vec<(PathBuf, Kind)>,
) -> Result<(), UserError> {
    let Some((segment, rest)) = segments.split_first() else {
        found.push((dir, kind));
        return Ok(());
    };
    if !segment.contains('*') {
        // A literal segment: no listing; a missing one is found missing below it.
        let path = joined(&dir, segment);
        let kind = if rest.is_empty() { Kind::of(&path) } else { Kind::Other };
        return walk_segments(path, kind, rest, found);
    }
    let entries = match std::fs::read_dir(&dir) {
        Ok(entries) => entries,
        // Not there, or not a folder: nothing below it (as `glob`, which does not list it).
        Err(e) if matches!(e.kind(), std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory) => return Ok(()),
        Err(e) => return Err(UserError::new(format!("cannot read `{}`: {e}", dir.display()))),
    };
    let mut matches = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| UserError::new(format!("cannot read `{}`: {e}", dir.display())))?;
        // `glob` leaves names that are not UTF-8 out.
        let Some(name) = entry.file_name().to_str().map(str::to_string) else { continue };
        if !star_matches(segment, &name) {
            continue;
        }
        let path = joined(&dir, &name);
        let kind = match entry.file_type() {
            Ok(t) if t.is_file() => Kind::File,
            Ok(t) if t.is_dir() => Kind::Folder,
            Ok(t) if !t.is_symlink() => Kind::Other,
            _ => Kind::of(&path),
        };
        matches.push((path, kind));
    }
    matches.sort_by(|a, b| a.0.cmp(&b.0));
    if rest.is_empty() {
        found.extend(matches);
        return Ok(());
    }
    // The folders below are listed in parallel (10⁴ trial folders in an archive of 10⁴ tests; each
    // listing waits on the file system); what each finds, and the first error, in sorted order.
    let below: Vec<Result<Vec<(PathBuf, Kind)>, UserError>> = matches
        .into_par_iter()
        .filter(|(_, kind)| *kind == Kind::Folder)
        .map(|(path, kind)| {
            let mut below = Vec::new();
            walk_segments(path, kind, rest, &mut below).map(|()| below)
        })
        .collect();
    for paths in below {
        found.extend(paths?);
    }
    Ok(())
}

/// Whether `name` matches `pattern`, whose only wildcard is `*` (any characters, none too).
fn star_matches(pattern: &str, name: &str) -> bool {
    let mut pieces = pattern.split('*');
    let first = pieces.next().unwrap_or_default();
    let Some(mut rest) = name.strip_prefix(first) else { return false };
    let mut pieces: Vec<&str> = pieces.collect();
    let Some(last) = pieces.pop() else { return rest.is_empty() };
    for piece in pieces {
        match rest.find(piece) {
            Some(at) => rest = &rest[at + piece.len()..],
            None => return false,
        }
    }
    rest.len() >= last.len() && rest.ends_with(last)
}

/// The glob a template's pieces match: each key and wildcard a `*`.
fn glob_of(pieces: &[Piece]) -> String {
    pieces
        .iter()
        .map(|p| match p {
            Piece::Literal(l) => l.as_str(),
            Piece::Key(_) | Piece::Wild => "*",
        })
        .collect()
}

/// The keys a template's `pieces` give `path`. The template is matched against what it was
/// joined to: the path below `base_dir` for a relative template, the whole path for an absolute
/// one (also when it lies below it).
fn match_path(base_dir: &Path, glob_pattern: &str, pieces: &[Piece], path: &Path) -> Option<Partition> {
    let root = if Path::new(glob_pattern).is_absolute() { Path::new("") } else { base_dir };
    let relative = path.strip_prefix(root).unwrap_or(path).to_string_lossy().replace('\\', "/");
    match_pieces(&relative, pieces)
}

/// A `components:` source's files with the component `key` taken out of their partitions: the
/// files whose other keys agree are one record. Refuses a `key` that `pattern` does not name.
pub fn group_components(pattern: &str, mut files: Vec<MatchedFile>, key: &str) -> Result<Vec<MatchedFile>, UserError> {
    let pieces = parse_template(pattern).map_err(|e| UserError::new(e.to_string()))?;
    if !pieces.contains(&Piece::Key(key.to_string())) {
        return Err(UserError::new(format!(
            "`components: {{key: {key}}}` names no `{{{key}}}` of the path `{pattern}`"
        ))
        .hint(format!(
            "name each file's component in the path, e.g. `gm/{{station}}.{{{key}}}` for K-NET's `.EW`, `.NS`, `.UD`"
        )));
    }
    for file in &mut files {
        file.partition.retain(|(k, _)| k != key);
    }
    Ok(files)
}

/// The value of the template key `key` for `path`, a file of the source whose `pattern` is
/// resolved against `base_dir` (a `components:` source's component: `EW` of `AOM005.EW`).
pub fn key_value(base_dir: &Path, pattern: &str, path: &Path, key: &str) -> Option<String> {
    let pieces = parse_template(pattern).ok()?;
    let partition = match_path(base_dir, &glob_of(&pieces), &pieces, path)?;
    partition.into_iter().find(|(k, _)| k == key).map(|(_, v)| v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    #[test]
    fn template_keys_become_partitions() {
        let dir = crate::tempdir::tempdir().unwrap();
        for test in ["FB-4", "BI-1"] {
            std::fs::create_dir_all(dir.path().join(test)).unwrap();
            std::fs::write(dir.path().join(test).join("DAQ1_floors.csv"), "x").unwrap();
        }
        let constant = BTreeMap::from([("floor".to_string(), "5".to_string())]);
        let files = resolve(dir.path(), "{motion}/DAQ1_floors.csv", &constant, false).unwrap();
        let partitions: Vec<_> = files.iter().map(|f| crate::pipeline::stage::partition_path(&f.partition)).collect();
        assert_eq!(partitions, ["motion=BI-1/floor=5", "motion=FB-4/floor=5"]);
        // Two sources of one pattern (floors of one DAQ export): one walk, each its constants.
        let mut resolver = Resolver::default();
        let four = BTreeMap::from([("floor".to_string(), "4".to_string())]);
        let fours = resolver.resolve(dir.path(), "{motion}/DAQ1_floors.csv", &four, false).unwrap();
        std::fs::write(dir.path().join("FB-4/DAQ1_floors.csv.new"), "y").unwrap();
        std::fs::remove_dir_all(dir.path().join("BI-1")).unwrap();
        let fives = resolver.resolve(dir.path(), "{motion}/DAQ1_floors.csv", &constant, false).unwrap();
        assert_eq!(fives, files, "the walk is the first one's, the constants the source's own");
        let partitions: Vec<_> = fours.iter().map(|f| crate::pipeline::stage::partition_path(&f.partition)).collect();
        assert_eq!(partitions, ["motion=BI-1/floor=4", "motion=FB-4/floor=4"]);
    }

    #[test]
    fn an_absolute_template_below_the_pipeline_folder_matches() {
        // The pipeline's folder is `dir`, the archive `dir/arch`, named by its absolute path.
        let dir = crate::tempdir::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("arch/FB-4")).unwrap();
        std::fs::write(dir.path().join("arch/FB-4/DAQ2_equipment.csv"), "x").unwrap();
        let pattern = format!("{}/arch/{{motion}}/DAQ2_equipment.csv", dir.path().display());
        let files = resolve(dir.path(), &pattern, &BTreeMap::new(), false).unwrap();
        assert_eq!(files.len(), 1);
        assert_eq!(crate::pipeline::stage::partition_path(&files[0].partition), "motion=FB-4");
    }

    #[test]
    fn keys_match_within_one_segment() {
        let pieces = parse_template("{a}_{b}.csv").unwrap();
        assert_eq!(
            match_pieces("x_y_z.csv", &pieces).unwrap(),
            vec![("a".into(), "x".into()), ("b".into(), "y_z".into())]
        );
        assert!(match_pieces("d/x_y.csv", &parse_template("{a}.csv").unwrap()).is_none());
    }

    #[test]
    fn wildcards_beside_keys_match_one_segment_and_name_no_partition() {
        let dir = crate::tempdir::tempdir().unwrap();
        for (experiment, trial, test) in [(1, 2, "BI-2"), (2, 5, "FB-4"), (2, 10, "WN-6")] {
            let folder = dir.path().join(format!("Experiment-{experiment}/Trial-{trial}/Rep-1/Converted_Data"));
            std::fs::create_dir_all(&folder).unwrap();
            std::fs::write(folder.join(format!("{test}_DAQ1.txt")), "x").unwrap();
        }
        let template = "Experiment-*/Trial-*/Rep-1/Converted_Data/{motion}_DAQ1.txt";
        let files = resolve(dir.path(), template, &BTreeMap::new(), false).unwrap();
        let partitions: Vec<_> = files.iter().map(|f| crate::stages::partition_path(&f.partition)).collect();
        // In path order (Trial-10 before Trial-5).
        assert_eq!(partitions, ["motion=BI-2", "motion=WN-6", "motion=FB-4"]);
        // A `*` takes no `/`, and may take nothing.
        let pieces = parse_template("a*/{k}.txt").unwrap();
        // The refusals' wording, pinned (users see it as the error of `run`).
        assert_eq!(parse_template("x/{a.csv").unwrap_err().to_string(), "unclosed `{` in `x/{a.csv`");
        assert_eq!(
            parse_template("{a-b}.csv").unwrap_err().to_string(),
            "`{a-b}` in `{a-b}.csv` is not a valid partition key (letters, digits, _)"
        );
        assert_eq!(match_pieces("a/x.txt", &pieces).unwrap(), vec![("k".into(), "x".into())]);
        assert!(match_pieces("ab/c/x.txt", &pieces).is_none());
    }

    /// The walk of `*`-only globs finds what `glob` finds, the same paths: relative and absolute,
    /// `.`/`..` segments, a missing folder, a file where a folder is expected, dot files, links.
    #[test]
    fn the_walk_of_star_globs_finds_what_glob_finds() {
        let dir = crate::tempdir::tempdir().unwrap();
        let d = dir.path();
        for folder in ["E-1/T-1/Rep-1/C", "E-1/T-2/Rep-1/C", "E-2/T-1/Rep-2/C", "E-3/.hidden/Rep-1/C"] {
            std::fs::create_dir_all(d.join(folder)).unwrap();
        }
        for file in [
            "E-1/T-1/Rep-1/C/a_D1.txt",
            "E-1/T-2/Rep-1/C/b_D1.txt",
            "E-1/T-2/Rep-1/C/b_D2.txt",
            "E-2/T-1/Rep-2/C/c_D1.txt",
        ] {
            std::fs::write(d.join(file), "x").unwrap();
        }
        std::fs::write(d.join("E-3/.hidden/Rep-1/C/.d_D1.txt"), "x").unwrap();
        std::fs::write(d.join("E-4"), "a file, not a folder").unwrap();
        std::os::unix::fs::symlink(d.join("E-1/T-1"), d.join("E-2/T-link")).unwrap();
        std::os::unix::fs::symlink(d.join("gone"), d.join("E-2/T-dangling")).unwrap();
        let root = d.display().to_string();
        for pattern in [
            format!("{root}/E-*/T-*/Rep-1/C/*_D1.txt"),
            format!("{root}/E-*/*/Rep-*/C/*"),
            format!("{root}/E-*/T-*/Rep-1/C"),
            format!("{root}/E-1/../E-*/T-*/./Rep-1/C/*D*.txt"),
            format!("{root}/missing/*/x.txt"),
            format!("{root}/E-1/T-1/Rep-1/C/a_D1.txt"),
            format!("{root}/E-*/*"),
            format!("{root}/*-*-*"),
        ] {
            let globbed: Vec<PathBuf> = glob::glob(&pattern).unwrap().map(|p| p.unwrap()).collect();
            let mut walked: Vec<PathBuf> = walk_stars(&pattern).unwrap().unwrap().into_iter().map(|(p, _)| p).collect();
            walked.retain(|p| std::fs::symlink_metadata(p).is_ok());
            let mut sorted = globbed.clone();
            sorted.sort();
            assert_eq!(walked, sorted, "{pattern}");
            for (path, kind) in walk_stars(&pattern).unwrap().unwrap() {
                assert_eq!(kind, Kind::of(&path), "{}", path.display());
            }
        }
        // Relative to the working folder, as glob names them (no `./`).
        let relative = "src/pipeline/executor/*.rs";
        let mut globbed: Vec<PathBuf> = glob::glob(relative).unwrap().map(|p| p.unwrap()).collect();
        globbed.sort();
        let walked: Vec<PathBuf> = walk_stars(relative).unwrap().unwrap().into_iter().map(|(p, _)| p).collect();
        assert_eq!(walked, globbed);
        assert!(!walked.is_empty());
        // Other wildcards are glob's.
        assert!(
            walk_stars("a/?.txt").is_none() && walk_stars("a/[ab].txt").is_none() && walk_stars("a/**/b").is_none()
        );
        assert!(star_matches("*_D1.txt", "a_D1.txt") && star_matches("*", "") && star_matches("a*b*a", "aba"));
        assert!(!star_matches("a*a", "a") && !star_matches("T-*", "E-1") && !star_matches("*.txt", "x.txt2"));
    }

    #[test]
    fn no_match_is_a_clear_error() {
        let dir = crate::tempdir::tempdir().unwrap();
        let err = resolve(dir.path(), "nothing/*.AT2", &BTreeMap::new(), false).unwrap_err();
        assert!(err.message.contains("no file matches `nothing/*.AT2`"), "{err}");
    }
}
