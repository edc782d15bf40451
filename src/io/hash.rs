//! Content hashes (blake3): what the cache compares, never timestamps.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::Context;
use rayon::prelude::*;

pub fn hash_file(path: &Path) -> anyhow::Result<String> {
    let mut hasher = blake3::Hasher::new();
    let file = std::fs::File::open(path).with_context(|| format!("cannot open `{}` to hash it", path.display()))?;
    hasher.update_reader(file).with_context(|| format!("cannot read `{}` to hash it", path.display()))?;
    Ok(hasher.finalize().to_hex().to_string())
}

pub fn hash_bytes(bytes: &[u8]) -> String {
    blake3::hash(bytes).to_hex().to_string()
}

/// Every regular file below `dir`, sorted, as paths relative to `dir` with `/` separators.
pub fn list_files(dir: &Path) -> anyhow::Result<Vec<String>> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<String>) -> std::io::Result<()> {
        for entry in std::fs::read_dir(dir)? {
            let entry = entry?;
            let path = entry.path();
            if entry.file_type()?.is_dir() {
                walk(root, &path, out)?;
            } else {
                let relative = path.strip_prefix(root).expect("walk stays below root");
                out.push(relative.components().map(|c| c.as_os_str().to_string_lossy()).collect::<Vec<_>>().join("/"));
            }
        }
        Ok(())
    }
    let mut files = Vec::new();
    walk(dir, dir, &mut files).with_context(|| format!("cannot list `{}`", dir.display()))?;
    files.sort();
    Ok(files)
}

/// Bytes of the files below `dir` (for reports; unreadable entries count nothing).
pub fn tree_bytes(dir: &Path) -> u64 {
    list_files(dir)
        .unwrap_or_default()
        .iter()
        .filter_map(|f| std::fs::metadata(dir.join(f)).ok())
        .map(|m| m.len())
        .sum()
}

/// Content hashes of files this run has just written, by path, computed from the bytes as they
/// were written: the cache then need not read them back.
pub type KnownHashes = HashMap<PathBuf, String>;

/// Hash of a directory tree: names and contents of all its files, order-independent of the disk.
pub fn hash_dir(dir: &Path) -> anyhow::Result<(String, usize)> {
    hash_dir_known(dir, &KnownHashes::new())
}

/// [`hash_dir`], taking the hashes of files in `known` from there.
pub fn hash_dir_known(dir: &Path, known: &KnownHashes) -> anyhow::Result<(String, usize)> {
    let files = list_files(dir)?;
    let paths: Vec<PathBuf> = files.iter().map(|f| dir.join(f)).collect();
    let hashes = hash_files_known(&paths, known)?;
    let mut combined = String::new();
    for (file, hash) in files.iter().zip(&hashes) {
        combined.push_str(file);
        combined.push('\0');
        combined.push_str(hash);
        combined.push('\n');
    }
    Ok((hash_bytes(combined.as_bytes()), files.len()))
}

/// Hash of a source path: a file's content, or a folder's file names and contents.
pub fn hash_path(path: &Path) -> anyhow::Result<String> {
    if path.is_dir() {
        Ok(hash_dir(path)?.0)
    } else {
        hash_file(path)
    }
}

/// Hashes many files in parallel, keeping their order; those in `known` are not read.
pub fn hash_files_known(paths: &[PathBuf], known: &KnownHashes) -> anyhow::Result<Vec<String>> {
    paths.par_iter().map(|p| known.get(p).map_or_else(|| hash_file(p), |h| Ok(h.clone()))).collect()
}

/// A writer that hashes what passes through it, for files written front to back.
pub struct HashingWriter<W> {
    inner: W,
    hasher: blake3::Hasher,
}

impl<W: std::io::Write> HashingWriter<W> {
    pub fn new(inner: W) -> Self {
        HashingWriter { inner, hasher: blake3::Hasher::new() }
    }

    /// The hash of every byte written, as [`hash_file`] gives it for the finished file.
    pub fn finalize(&self) -> String {
        self.hasher.finalize().to_hex().to_string()
    }
}

impl<W: std::io::Write> std::io::Write for HashingWriter<W> {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        let written = self.inner.write(bytes)?;
        self.hasher.update(&bytes[..written]);
        Ok(written)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dir_hash_depends_on_names_and_contents_only() {
        let a = crate::tempdir::tempdir().unwrap();
        let b = crate::tempdir::tempdir().unwrap();
        for d in [a.path(), b.path()] {
            std::fs::create_dir_all(d.join("x=1")).unwrap();
            std::fs::write(d.join("x=1/data.parquet"), "abc").unwrap();
        }
        assert_eq!(hash_dir(a.path()).unwrap(), hash_dir(b.path()).unwrap());
        std::fs::write(b.path().join("x=1/data.parquet"), "abd").unwrap();
        assert_ne!(hash_dir(a.path()).unwrap().0, hash_dir(b.path()).unwrap().0);
    }

    #[test]
    fn hashing_while_writing_equals_hashing_the_file() {
        use std::io::Write;
        let dir = crate::tempdir::tempdir().unwrap();
        let path = dir.path().join("f.bin");
        let mut writer = HashingWriter::new(std::fs::File::create(&path).unwrap());
        for chunk in [&b"front"[..], &[0u8; 70_000], b"back"] {
            writer.write_all(chunk).unwrap();
        }
        assert_eq!(writer.finalize(), hash_file(&path).unwrap());
    }
}
