//! Resolving a source's `path` (file, glob or `{key}` template) to record files and partitions.

use std::path::{Path, PathBuf};

use super::stage::Partition;
use crate::error::UserError;

#[derive(Debug, Clone, PartialEq)]
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
    let pieces = parse_template(pattern).map_err(|e| UserError::new(e.to_string()))?;
    let has_keys = pieces.iter().any(|p| matches!(p, Piece::Key(_)));
    let glob_pattern = glob_of(&pieces);
    let is_glob = glob_pattern.contains(['*', '?', '[']);
    let full = base_dir.join(&glob_pattern);
    let full_text = full.to_string_lossy().replace('\\', "/");
    let entries =
        glob::glob(&full_text).map_err(|e| UserError::new(format!("invalid path pattern `{pattern}`: {e}")))?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| UserError::new(format!("cannot read `{}`: {}", e.path().display(), e.error())))?;
        if !(path.is_file() || folders && path.is_dir()) {
            continue;
        }
        let mut partition = if has_keys {
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
        partition.extend(constant.iter().map(|(k, v)| (k.clone(), v.clone())));
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

    #[test]
    fn no_match_is_a_clear_error() {
        let dir = crate::tempdir::tempdir().unwrap();
        let err = resolve(dir.path(), "nothing/*.AT2", &BTreeMap::new(), false).unwrap_err();
        assert!(err.message.contains("no file matches `nothing/*.AT2`"), "{err}");
    }
}
