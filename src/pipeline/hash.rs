//! Content hashes (blake3): what the cache compares, never timestamps.

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

/// Hash of a directory tree: names and contents of all its files, order-independent of the disk.
pub fn hash_dir(dir: &Path) -> anyhow::Result<(String, usize)> {
    let files = list_files(dir)?;
    let hashes: Vec<String> = files.par_iter().map(|f| hash_file(&dir.join(f))).collect::<anyhow::Result<_>>()?;
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

/// Hashes many files in parallel, keeping their order.
pub fn hash_files(paths: &[PathBuf]) -> anyhow::Result<Vec<String>> {
    paths.par_iter().map(|p| hash_file(p)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dir_hash_depends_on_names_and_contents_only() {
        let a = tempfile::tempdir().unwrap();
        let b = tempfile::tempdir().unwrap();
        for d in [a.path(), b.path()] {
            std::fs::create_dir_all(d.join("x=1")).unwrap();
            std::fs::write(d.join("x=1/data.parquet"), "abc").unwrap();
        }
        assert_eq!(hash_dir(a.path()).unwrap(), hash_dir(b.path()).unwrap());
        std::fs::write(b.path().join("x=1/data.parquet"), "abd").unwrap();
        assert_ne!(hash_dir(a.path()).unwrap().0, hash_dir(b.path()).unwrap().0);
    }
}
