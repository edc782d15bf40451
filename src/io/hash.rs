//! Content hashes (blake3): what the cache compares, never timestamps.
//!
//! Reading every input and output again on each run costs seconds at archive scale (a no-op
//! rerun of 200 tests read 600 MB), so a process may keep a [`StatMemo`]: a file's hash is
//! reused while its inode, size, modification and change times are what they were when it was
//! hashed — git's index does the same, and like git (which compares `st_dev` only when built
//! with `USE_STDEV`) not the device: a shared file system has another device number on every
//! node, and a memo saved on the login node serves the array tasks. Files are remembered by
//! absolute path, the same on every node of a shared file system. Only files that had not changed for
//! [`MEMO_SETTLED`] when hashed are remembered (so a write within the file system's timestamp
//! granularity after hashing cannot go unseen); the hash stays what is compared.

use std::collections::{BTreeMap, HashMap};
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use anyhow::Context;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// A file must be this much older than the moment it is hashed to be remembered.
pub const MEMO_SETTLED: std::time::Duration = std::time::Duration::from_secs(2);

/// What identifies a file's version without reading it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
struct Stat {
    ino: u64,
    size: u64,
    mtime_ns: i128,
    ctime_ns: i128,
}

impl Stat {
    fn of(meta: &std::fs::Metadata) -> Stat {
        use std::os::unix::fs::MetadataExt;
        let ns = |s: i64, n: i64| i128::from(s) * 1_000_000_000 + i128::from(n);
        Stat {
            ino: meta.ino(),
            size: meta.size(),
            mtime_ns: ns(meta.mtime(), meta.mtime_nsec()),
            ctime_ns: ns(meta.ctime(), meta.ctime_nsec()),
        }
    }
}

/// Hashes by path and [`Stat`], loaded from and saved to files (see the module's docs): the root
/// file, and per bucket (a record's `layout::fan_bucket`, given by the caller or read from the
/// path) one file in the folder named as the root file without `.json`
/// (`hashes.json` → `hashes/3f.json`), read only when a file of that bucket is asked after: a
/// Slurm task reads the buckets of its shard, not the archive's memo.
pub struct StatMemo {
    file: PathBuf,
    /// The root file's entries: files of no bucket (and an older memo's, all in one file).
    root: Entries,
    /// Each bucket's entries, read on first use.
    buckets: Box<[OnceLock<Entries>]>,
    /// A file's bucket when its caller does not say (a fanned-out record's table: its fan folder).
    bucket_of: fn(&Path) -> Option<u8>,
    /// What this process hashed or reused, with its bucket: what [`save_memo`] keeps.
    used: Mutex<HashMap<OsString, (Option<u8>, Stat, String)>>,
    /// Memo files read and their bytes.
    read: Mutex<(usize, u64)>,
}

/// One memo file's entries. By the bytes of [`memo_key`]'s path: hashing and comparing bytes, not
/// path components (at 10⁴ tests, 2·10⁴ files asked after in a no-op run).
#[derive(Default)]
struct Entries {
    known: HashMap<OsString, (Stat, String)>,
    /// Whether the file was read (else it is missing or damaged, and saving writes it anew).
    loaded: bool,
}

static MEMO: OnceLock<StatMemo> = OnceLock::new();

impl StatMemo {
    /// The memo saved in `file` and its buckets' folder (an unreadable or damaged file is an
    /// empty memo); `bucket_of` names a file's bucket where its caller does not.
    pub fn load(file: &Path, bucket_of: fn(&Path) -> Option<u8>) -> StatMemo {
        let memo = StatMemo {
            file: file.to_path_buf(),
            root: Entries::default(),
            buckets: (0..=u8::MAX).map(|_| OnceLock::new()).collect(),
            bucket_of,
            used: Mutex::new(HashMap::new()),
            read: Mutex::new((0, 0)),
        };
        StatMemo { root: memo.read_entries(file), ..memo }
    }

    fn read_entries(&self, file: &Path) -> Entries {
        let bytes = std::fs::read(file).ok();
        if let Some(bytes) = &bytes {
            let mut read = self.read.lock().expect("the memo lock is never poisoned");
            read.0 += 1;
            read.1 += bytes.len() as u64;
        }
        let entries: Option<Vec<(PathBuf, Stat, String)>> = bytes.as_ref().and_then(|b| serde_json::from_slice(b).ok());
        Entries {
            loaded: entries.is_some(),
            known: entries.unwrap_or_default().into_iter().map(|(p, s, h)| (p.into_os_string(), (s, h))).collect(),
        }
    }

    fn buckets_dir(&self) -> PathBuf {
        self.file.with_extension("")
    }

    fn bucket_file(&self, bucket: u8) -> PathBuf {
        self.buckets_dir().join(format!("{bucket:02x}.json"))
    }

    fn bucket(&self, bucket: u8) -> &Entries {
        self.buckets[usize::from(bucket)].get_or_init(|| self.read_entries(&self.bucket_file(bucket)))
    }

    /// `path`'s content hash: the remembered one while its stat is unchanged, else read.
    pub fn hash(&self, path: &Path) -> anyhow::Result<String> {
        let Ok(meta) = std::fs::metadata(path) else { return read_and_hash(path) };
        self.hash_with(path, &meta, None)
    }

    /// [`hash`](Self::hash) of a file whose metadata the caller has just read, remembered in
    /// `bucket` (None: where `bucket_of` puts it).
    fn hash_with(&self, path: &Path, meta: &std::fs::Metadata, bucket: Option<u8>) -> anyhow::Result<String> {
        let stat = Stat::of(meta);
        let key = memo_key(path);
        let bucket = bucket.or_else(|| (self.bucket_of)(path));
        let remember = |stat: Stat, hash: &String| {
            self.used
                .lock()
                .expect("the memo lock is never poisoned")
                .insert(key.clone(), (bucket, stat, hash.clone()));
        };
        // An entry saved before its file had a bucket (a folder grown past the fan-out limit)
        // is found in the root file, and saved in its bucket's.
        let known = bucket.and_then(|b| self.bucket(b).known.get(&key)).or_else(|| self.root.known.get(&key));
        if let Some((_, hash)) = known.filter(|(s, _)| *s == stat) {
            remember(stat, hash);
            return Ok(hash.clone());
        }
        let hash = read_and_hash(path)?;
        if settled(meta) {
            remember(stat, &hash);
        }
        Ok(hash)
    }

    /// Writes the entries this memo used, each file whose entries changed (a temporary file,
    /// then a rename), and removes the buckets' files it used nothing of: nothing is written
    /// when the entries are those it loaded, as on a no-op rerun (1 MB of JSON at 10³ tests).
    pub fn save(&self) -> anyhow::Result<()> {
        let used = self.used.lock().expect("the memo lock is never poisoned");
        let mut by_bucket: BTreeMap<Option<u8>, HashMap<&OsString, (&Stat, &String)>> = BTreeMap::new();
        for (path, (bucket, stat, hash)) in used.iter() {
            by_bucket.entry(*bucket).or_default().insert(path, (stat, hash));
        }
        write_entries(&self.file, &self.root, &by_bucket.remove(&None).unwrap_or_default())?;
        for (bucket, entries) in &by_bucket {
            let bucket = bucket.expect("the root's entries were taken out");
            write_entries(&self.bucket_file(bucket), self.bucket(bucket), entries)?;
        }
        // Buckets of which nothing was used, as the root file keeps only what was.
        let dir = self.buckets_dir();
        let Ok(listing) = std::fs::read_dir(&dir) else { return Ok(()) };
        for entry in listing.flatten() {
            let name = entry.file_name();
            // Only the names this memo writes ([`bucket_file`](Self::bucket_file)'s).
            let bucket = name
                .to_str()
                .and_then(|n| n.strip_suffix(".json"))
                .and_then(|n| u8::from_str_radix(n, 16).ok())
                .filter(|&b| self.bucket_file(b).file_name() == Some(name.as_os_str()));
            if bucket.is_some_and(|b| !by_bucket.contains_key(&Some(b))) {
                std::fs::remove_file(entry.path()).with_context(|| format!("removing `{}`", entry.path().display()))?;
            }
        }
        if by_bucket.is_empty() {
            let _ = std::fs::remove_dir(&dir);
        }
        Ok(())
    }

    /// Memo files read so far, and their bytes.
    pub fn files_read(&self) -> (usize, u64) {
        *self.read.lock().expect("the memo lock is never poisoned")
    }
}

/// Writes `entries` to `file` unless they are what `old` loaded from it.
fn write_entries(file: &Path, old: &Entries, entries: &HashMap<&OsString, (&Stat, &String)>) -> anyhow::Result<()> {
    let same = old.loaded
        && old.known.len() == entries.len()
        && entries.iter().all(|(p, (s, h))| old.known.get(*p).is_some_and(|(os, oh)| os == *s && oh == *h));
    if same {
        return Ok(());
    }
    let mut sorted: Vec<(&Path, &Stat, &String)> = entries.iter().map(|(p, (s, h))| (Path::new(p), *s, *h)).collect();
    sorted.sort_by(|a, b| a.0.cmp(b.0));
    if let Some(dir) = file.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating `{}`", dir.display()))?;
    }
    let tmp = file.with_extension(format!("tmp-{}", std::process::id()));
    let written = std::fs::write(&tmp, serde_json::to_vec(&sorted)?)
        .with_context(|| format!("writing `{}`", tmp.display()))
        .and_then(|()| std::fs::rename(&tmp, file).with_context(|| format!("renaming into `{}`", file.display())));
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// How the memo names a file: its absolute path (not resolved), so a run from another folder or
/// node finds it. The working folder is asked once per process (shakeflow never changes it), not
/// once per file.
fn memo_key(path: &Path) -> OsString {
    static CWD: OnceLock<Option<PathBuf>> = OnceLock::new();
    let absolute = match CWD.get_or_init(|| std::env::current_dir().ok()) {
        Some(cwd) if path.is_relative() => std::path::absolute(cwd.join(path)),
        _ => std::path::absolute(path),
    };
    absolute.unwrap_or_else(|_| path.to_path_buf()).into_os_string()
}

/// From now on [`hash_file`] goes through the memo saved in `file` (and its buckets' folder),
/// `bucket_of` naming a file's bucket where the caller does not ([`StatMemo::load`]). The first
/// call in a process wins; later ones are ignored.
pub fn use_memo(file: &Path, bucket_of: fn(&Path) -> Option<u8>) {
    MEMO.get_or_init(|| StatMemo::load(file, bucket_of));
}

/// The process's memo files read so far, and their bytes (none without a memo).
pub fn memo_files_read() -> (usize, u64) {
    MEMO.get().map_or((0, 0), StatMemo::files_read)
}

/// Records `hash` as `path`'s content in the process's memo, if it has one and the file is
/// settled: for files this run wrote and hashed on the way out, so the next run need not read
/// them.
pub fn remember(path: &Path, hash: &str) {
    let Some(memo) = MEMO.get() else { return };
    let Ok(meta) = std::fs::metadata(path) else { return };
    if settled(&meta) {
        let bucket = (memo.bucket_of)(path);
        memo.used
            .lock()
            .expect("the memo lock is never poisoned")
            .insert(memo_key(path), (bucket, Stat::of(&meta), hash.to_string()));
    }
}

/// Whether a file had not changed for [`MEMO_SETTLED`] (and may be remembered).
fn settled(meta: &std::fs::Metadata) -> bool {
    meta.modified().ok().and_then(|m| m.elapsed().ok()).is_some_and(|age| age >= MEMO_SETTLED)
}

/// Saves the process's memo, if it has one ([`StatMemo::save`]).
pub fn save_memo() -> anyhow::Result<()> {
    MEMO.get().map_or(Ok(()), StatMemo::save)
}

pub fn hash_file(path: &Path) -> anyhow::Result<String> {
    match MEMO.get() {
        Some(memo) => memo.hash(path),
        None => read_and_hash(path),
    }
}

/// [`hash_file`] of a file that may be missing: None when it is (or cannot be read), found with
/// one `stat` and no error built. A no-op rerun asks this of every file a `keep: false` stage
/// removed; building an error each time (with its backtrace under `RUST_BACKTRACE=1`) was a
/// fifth of that rerun's CPU time.
pub fn hash_if_present(path: &Path) -> Option<String> {
    let meta = std::fs::metadata(path).ok()?;
    match MEMO.get() {
        Some(memo) => memo.hash_with(path, &meta, None).ok(),
        None => read_and_hash(path).ok(),
    }
}

fn read_and_hash(path: &Path) -> anyhow::Result<String> {
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

/// Hash of a source path: a file's content, or a folder's file names and contents, remembered
/// in `bucket` (a fanned-out source's record's; None: where the memo puts it).
/// One `stat` for a file, which the memo then uses (a no-op rerun asks this of every record file).
pub fn hash_path(path: &Path, bucket: Option<u8>) -> anyhow::Result<String> {
    match (std::fs::metadata(path), MEMO.get()) {
        (Ok(meta), _) if meta.is_dir() => Ok(hash_dir(path)?.0),
        (Ok(meta), Some(memo)) => memo.hash_with(path, &meta, bucket),
        _ => hash_file(path),
    }
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

    fn no_bucket(_: &Path) -> Option<u8> {
        None
    }

    #[test]
    fn memo_keys_are_the_absolute_paths_the_working_folder_gives() {
        for path in ["a/b.csv", "./a/../b.csv", "/x/./y.csv", "/x/../y.csv"] {
            assert_eq!(memo_key(Path::new(path)), std::path::absolute(path).unwrap(), "{path}");
        }
    }

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

    #[test]
    fn the_stat_memo_reuses_settled_files_and_sees_every_change() {
        let dir = crate::tempdir::tempdir().unwrap();
        let (old, fresh) = (dir.path().join("old.csv"), dir.path().join("fresh.csv"));
        std::fs::write(&old, "1,2,3\n").unwrap();
        std::fs::write(&fresh, "4,5,6\n").unwrap();
        let past = std::time::SystemTime::now() - std::time::Duration::from_secs(60);
        let set_mtime = |p: &Path| std::fs::File::options().write(true).open(p).unwrap().set_modified(past).unwrap();
        set_mtime(&old);
        let file = dir.path().join("memo/hashes.json");
        let memo = StatMemo::load(&file, no_bucket);
        assert_eq!(memo.hash(&old).unwrap(), read_and_hash(&old).unwrap());
        assert_eq!(memo.hash(&fresh).unwrap(), read_and_hash(&fresh).unwrap());
        memo.save().unwrap();
        // Remembered: the settled file only (one just written could change within its mtime's tick).
        let memo = StatMemo::load(&file, no_bucket);
        assert_eq!(memo.root.known.keys().collect::<Vec<_>>(), [old.as_os_str()]);
        assert_eq!(memo.hash(&old).unwrap(), read_and_hash(&old).unwrap());
        // Same size, modification time put back: the change time still differs, so it is read again.
        std::fs::write(&old, "1,2,4\n").unwrap();
        set_mtime(&old);
        assert_eq!(memo.hash(&old).unwrap(), hash_bytes(b"1,2,4\n"));
        // Saved by another node: the same file on a shared file system has another device
        // number there (older memos recorded it); the memo still serves, named absolutely.
        memo.save().unwrap();
        let mut entries: Vec<serde_json::Value> = serde_json::from_slice(&std::fs::read(&file).unwrap()).unwrap();
        assert_eq!(entries[0][0], serde_json::json!(old), "absolute paths");
        entries[0][1]["dev"] = serde_json::json!(0xfeed);
        entries[0][2] = serde_json::json!("remembered");
        std::fs::write(&file, serde_json::to_vec(&entries).unwrap()).unwrap();
        assert_eq!(StatMemo::load(&file, no_bucket).hash(&old).unwrap(), "remembered");
        // A damaged memo is an empty one.
        std::fs::write(&file, "{not json").unwrap();
        assert!(StatMemo::load(&file, no_bucket).root.known.is_empty());
    }

    #[test]
    fn the_stat_memo_is_saved_only_when_its_entries_changed() {
        let dir = crate::tempdir::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.csv"), dir.path().join("b.csv"));
        let past = std::time::SystemTime::now() - std::time::Duration::from_secs(60);
        for (path, text) in [(&a, "1\n"), (&b, "2\n")] {
            std::fs::write(path, text).unwrap();
            std::fs::File::options().write(true).open(path).unwrap().set_modified(past).unwrap();
        }
        let file = dir.path().join("hashes.json");
        let memo = StatMemo::load(&file, no_bucket);
        memo.hash(&a).unwrap();
        memo.save().unwrap();
        // The same entries as loaded (a no-op rerun): the file is left as it is, its bytes too.
        let written = std::fs::read(&file).unwrap();
        std::fs::write(&file, [&written[..], b"\n"].concat()).unwrap();
        let memo = StatMemo::load(&file, no_bucket);
        memo.hash(&a).unwrap();
        memo.save().unwrap();
        assert_eq!(std::fs::read(&file).unwrap(), [&written[..], b"\n"].concat());
        // A file hashed anew, or one no longer asked for, is saved.
        let memo = StatMemo::load(&file, no_bucket);
        memo.hash(&a).unwrap();
        memo.hash(&b).unwrap();
        memo.save().unwrap();
        assert_eq!(StatMemo::load(&file, no_bucket).root.known.len(), 2);
        let memo = StatMemo::load(&file, no_bucket);
        memo.hash(&b).unwrap();
        memo.save().unwrap();
        assert_eq!(StatMemo::load(&file, no_bucket).root.known.keys().collect::<Vec<_>>(), [b.as_os_str()]);
        // A damaged memo is written anew, even with nothing to remember.
        std::fs::write(&file, "{not json").unwrap();
        StatMemo::load(&file, no_bucket).save().unwrap();
        assert_eq!(std::fs::read(&file).unwrap(), b"[]");
    }

    /// Past the fan-out limit a record's entry is in its bucket's file, which only a process
    /// asking after a file of that bucket reads; an entry from the root file moves to its bucket.
    #[test]
    fn the_stat_memo_reads_only_the_buckets_asked_after() {
        let dir = crate::tempdir::tempdir().unwrap();
        let past = std::time::SystemTime::now() - std::time::Duration::from_secs(60);
        let files: Vec<PathBuf> = ["a.csv", "b.csv", "0f/x=1/data.parquet", "plain.yaml"]
            .iter()
            .map(|name| {
                let path = dir.path().join(name);
                std::fs::create_dir_all(path.parent().unwrap()).unwrap();
                std::fs::write(&path, name).unwrap();
                std::fs::File::options().write(true).open(&path).unwrap().set_modified(past).unwrap();
                path
            })
            .collect();
        // Tables of a fanned-out record name their bucket in their path; the others have none.
        fn fan_folder(path: &Path) -> Option<u8> {
            let folder = path.parent()?.parent()?.file_name()?.to_str()?;
            u8::from_str_radix(folder, 16).ok().filter(|_| folder.len() == 2)
        }
        let file = dir.path().join("memo/hashes.json");
        // An older memo: everything in the root file.
        let memo = StatMemo::load(&file, no_bucket);
        for path in &files {
            memo.hash(path).unwrap();
        }
        memo.save().unwrap();
        assert!(!dir.path().join("memo/hashes").exists());
        // Now with buckets (the sources' from their caller, the table's from its path): the
        // root file's entries still serve (a replaced hash shows the file was not read), and move
        // to their buckets' files.
        let mut entries: Vec<serde_json::Value> = serde_json::from_slice(&std::fs::read(&file).unwrap()).unwrap();
        let a = entries.iter_mut().find(|e| e[0].as_str().unwrap().ends_with("a.csv")).unwrap();
        a[2] = serde_json::json!("from-the-root");
        std::fs::write(&file, serde_json::to_vec(&entries).unwrap()).unwrap();
        let path_hash = |memo: &StatMemo, path: &Path, bucket| memo.hash_with(path, &path.metadata().unwrap(), bucket);
        let memo = StatMemo::load(&file, fan_folder);
        assert_eq!(path_hash(&memo, &files[0], Some(0xa0)).unwrap(), "from-the-root");
        path_hash(&memo, &files[1], Some(0xb1)).unwrap();
        memo.hash(&files[2]).unwrap();
        memo.hash(&files[3]).unwrap();
        memo.save().unwrap();
        let mut saved: Vec<String> = std::fs::read_dir(dir.path().join("memo/hashes"))
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        saved.sort();
        assert_eq!(saved, ["0f.json", "a0.json", "b1.json"]);
        assert_eq!(StatMemo::load(&file, fan_folder).root.known.len(), 1, "the plain file stays in the root");
        // A process asking after one bucket's file reads the root and that bucket only, and
        // takes its hash from there (a replaced hash shows it was not read again).
        let bucket_a = dir.path().join("memo/hashes/a0.json");
        let mut entries: Vec<serde_json::Value> = serde_json::from_slice(&std::fs::read(&bucket_a).unwrap()).unwrap();
        assert_eq!(entries[0][2], "from-the-root");
        entries[0][2] = serde_json::json!("remembered");
        std::fs::write(&bucket_a, serde_json::to_vec(&entries).unwrap()).unwrap();
        let memo = StatMemo::load(&file, fan_folder);
        assert_eq!(path_hash(&memo, &files[0], Some(0xa0)).unwrap(), "remembered");
        let root_bytes = std::fs::metadata(&file).unwrap().len();
        assert_eq!(memo.files_read(), (2, root_bytes + std::fs::metadata(&bucket_a).unwrap().len()));
        // Unchanged entries are not written again; a bucket nothing was used of goes, and no
        // file of a name the memo does not write.
        let before = std::fs::read(&bucket_a).unwrap();
        let foreign = dir.path().join("memo/hashes/B1.json");
        std::fs::write(&foreign, "[]").unwrap();
        memo.hash(&files[2]).unwrap();
        memo.save().unwrap();
        assert_eq!(std::fs::read(&bucket_a).unwrap(), before);
        assert!(!dir.path().join("memo/hashes/b1.json").exists());
        assert!(dir.path().join("memo/hashes/0f.json").exists());
        assert!(foreign.exists());
        std::fs::remove_file(&foreign).unwrap();
        // Nothing of any bucket used: the folder goes too.
        StatMemo::load(&file, fan_folder).save().unwrap();
        assert!(!dir.path().join("memo/hashes").exists());
    }
}
