//! The commit: a run's new outputs and lockfile replace the old ones all at once, or not at all.
//!
//! A transaction is a folder `<root>/.shakeflow/txn-<token>/` of the lease holder:
//!
//! 1. stages write their outputs under `new/<entry>/`;
//! 2. the new state is written in the transaction: the state files of the stages that changed
//!    under `state/`, and the new lockfile, naming them, as `shakeflow.lock`;
//! 3. the journal (entries to install and to remove, state files to install and to retire,
//!    whether a lockfile comes) is written to `journal.tmp`; the files of steps 2 and 3 are
//!    forced to disk together (one flush of the file system's journal, not one each), then
//!    `journal.tmp` is renamed to `journal`. **That rename is the commit point**: before it,
//!    the transaction never happened; after it, it has;
//! 4. roll forward, each step idempotent: each entry `<root>/<e>` moves to `old/<e>`, then
//!    `new/<e>` to `<root>/<e>` (an entry is a file, or a folder the root lacked, installed whole:
//!    `gathered`; should the root have gained it since, its files go in one by one); each new
//!    state file moves to `<root>/.shakeflow/state/`; the lockfile moves to
//!    `<root>/shakeflow.lock`; the state files only the old lockfile named are removed;
//! 5. the journal is removed, then the transaction folder with the old outputs in it.
//!
//! Whoever next takes the lease [`recover`]s first: a transaction with a journal is rolled forward
//! (steps 4–5), one without is removed whole. Every move is a rename inside `root`, so nothing is
//! copied and a crash at any instant leaves either the old state or a journal that completes
//! the new one (`tests/it/crash_safety.rs` kills a run at every step and checks).
//!
//! No move goes through a symbolic link: a folder between `root` and an entry that is a link
//! (a partition folder replaced by a link to a user's folder) would make the rename write or
//! remove outside `root`. The commit refuses it before the commit point (nothing changes), and
//! rolling forward refuses it too (the commit completes once the link is gone); an entry that is
//! itself a link is renamed, which moves the link, never what it points to.

use std::collections::HashSet;
use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use serde::{Deserialize, Serialize};

use super::failpoint;
use super::layout::{JOURNAL, LOCK_FILE, STATE_DIR, STATE_FILES, TXN_PREFIX};
use super::lease::Lease;
use super::lock::LockFile;
use crate::error::UserError;

const JOURNAL_FORMAT: u32 = 1;

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Journal {
    version: u32,
    /// Entries of `root` (relative paths, possibly nested) replaced by (or created from) `new/<entry>`.
    install: Vec<String>,
    /// Entries of `root` removed (moved into the transaction, deleted with it).
    remove: Vec<String>,
    /// Whether the transaction's `shakeflow.lock` replaces the root's.
    lockfile: bool,
    /// State files (`state/<name>` in the transaction) moved into `.shakeflow/state/` before the
    /// lockfile that names them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    state: Vec<String>,
    /// State files of `.shakeflow/state/` the new lockfile no longer names, removed once it is in place.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    retire: Vec<String>,
}

/// `.shakeflow/state/<name>`, relative to the root.
fn state_entry(name: &str) -> String {
    format!("{STATE_DIR}/{STATE_FILES}/{name}")
}

/// An open transaction of the lease holder on its root.
pub struct Transaction {
    root: PathBuf,
    dir: PathBuf,
}

impl Transaction {
    /// Opens a transaction in `lease`'s folder (the lease proves no other run writes there).
    pub fn begin(lease: &Lease) -> anyhow::Result<Transaction> {
        let root = lease.root().to_path_buf();
        let token = format!("{TXN_PREFIX}{}-{}", std::process::id(), unique());
        let dir = root.join(STATE_DIR).join(token);
        // The lease made `.shakeflow/`: two `mkdir`s, not `create_dir_all`'s failed first try.
        fs::create_dir(&dir)
            .and_then(|()| fs::create_dir(dir.join("new")))
            .with_context(|| format!("cannot create `{}`", dir.display()))?;
        Ok(Transaction { root, dir })
    }

    /// Where the new version of `root/<entry>` is written.
    pub fn new_path(&self, entry: &str) -> PathBuf {
        self.dir.join("new").join(entry)
    }

    /// Makes the new entries, removals and state the root's, all at once (see the module doc).
    /// `lock` is the new state and the one it replaces (read whole): only the stages whose entry
    /// changed get a new state file. An error before the commit point leaves the root exactly as
    /// it was.
    pub fn commit(
        self,
        install: &[String],
        remove: &[String],
        lock: Option<(&LockFile, &LockFile)>,
    ) -> anyhow::Result<()> {
        // A pseudo entry of the state folder: `.shakeflow/state` itself may not be a link either.
        let state_folder = [state_entry("-")];
        let state_folder = state_folder.iter().filter(|_| lock.is_some());
        if let Some(link) = link_on_the_way(&self.root, install.iter().chain(remove).chain(state_folder)) {
            self.abort();
            return Err(link_refused(&link, "nothing was changed").into());
        }
        let install = gathered(&self.root, &self.dir.join("new"), install);
        let prepared = (|| -> anyhow::Result<()> {
            let mut journal = Journal {
                version: JOURNAL_FORMAT,
                install: install.clone(),
                remove: remove.to_vec(),
                lockfile: lock.is_some(),
                state: Vec::new(),
                retire: Vec::new(),
            };
            // Written first, forced to disk together after: one flush of the file system's
            // journal for all of them, not one each (each waits for whatever data the tasks
            // or stages left unwritten: seconds apiece on a busy disk).
            let mut written: Vec<fs::File> = Vec::new();
            let mut state_dir = None;
            if let Some((lock, previous)) = lock {
                failpoint::hit("commit.write_lockfile")?;
                let state = lock.encode(previous)?;
                let dir = self.dir.join(STATE_FILES);
                fs::create_dir_all(&dir)?;
                for (name, bytes) in &state.files {
                    written
                        .push(crate::io::atomic::write_new(&dir.join(name), bytes).context("writing the new state")?);
                }
                written.push(
                    crate::io::atomic::write_new(&self.dir.join(LOCK_FILE), &state.root)
                        .context("writing the new lockfile")?,
                );
                failpoint::hit("commit.lockfile_written")?;
                journal.state = state.files.into_iter().map(|(name, _)| name).collect();
                journal.retire = state.retired;
                state_dir = Some(dir);
            }
            let tmp = self.dir.join("journal.tmp");
            written.push(
                crate::io::atomic::write_new(&tmp, &serde_json::to_vec_pretty(&journal)?)
                    .context("writing the commit journal")?,
            );
            for file in &written {
                file.sync_all().context("forcing the new state to disk")?;
            }
            if let Some(dir) = state_dir {
                sync_dir(&dir)?;
            }
            failpoint::hit("commit.journal_written")?;
            Ok(())
        })();
        if let Err(e) = prepared {
            let _ = fs::remove_dir_all(&self.dir);
            let full = e.chain().any(|c| {
                c.downcast_ref::<std::io::Error>().and_then(std::io::Error::raw_os_error) == Some(libc::ENOSPC)
            });
            let advice = if full { "; free space on that disk and rerun" } else { "" };
            return Err(e.context(format!(
                "nothing was changed: the previous results and lockfile in `{}` are as they were{advice}",
                self.root.display()
            )));
        }
        fs::rename(self.dir.join("journal.tmp"), self.dir.join(JOURNAL))
            .and_then(|()| sync_dir(&self.dir))
            .with_context(|| format!("committing `{}`", self.dir.display()))?;
        failpoint::hit("commit.committed")?;
        roll_forward(&self.root, &self.dir)
    }

    /// Forgets the transaction: the root stays as it was.
    pub fn abort(self) {
        let _ = fs::remove_dir_all(&self.dir);
    }
}

fn unique() -> u128 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos())
}

fn exists(path: &Path) -> bool {
    fs::symlink_metadata(path).is_ok()
}

/// `install` with each folder of `new` that the root lacks and whose whole tree is being
/// installed named once, as one entry: one rename, where file by file it would be a folder made
/// in the root for every folder of the tree and a rename for every file (a first run's commit of
/// the demo study made 88 folders; on ext4 a folder costs a quarter of a millisecond). The root
/// ends the same either way: a folder is gathered only if its tree in `new` holds exactly the
/// entries installed under it, and no empty folder; and one the root has gained by the time it is
/// installed takes the folder's files one by one (`roll_forward`).
fn gathered(root: &Path, new: &Path, install: &[String]) -> Vec<String> {
    let mut entries: Vec<&str> = install.iter().map(String::as_str).collect();
    entries.sort_unstable();
    let mut out = Vec::with_capacity(entries.len());
    gather_under("", &entries, root, new, &mut out);
    out
}

/// [`gathered`] of `entries`, all below the folder `prefix` (relative to the root, "" for it).
fn gather_under(prefix: &str, entries: &[&str], root: &Path, new: &Path, out: &mut Vec<String>) {
    let mut rest = entries;
    while let Some(first) = rest.first() {
        let below = &first[prefix.len()..];
        let Some(slash) = below.find('/') else {
            out.push(first.to_string()); // a file at this level
            rest = &rest[1..];
            continue;
        };
        let folder = &first[..prefix.len() + slash + 1]; // with its trailing `/`
        let count = rest.iter().take_while(|e| e.starts_with(folder)).count();
        let (group, after) = rest.split_at(count);
        let name = folder.strip_suffix('/').unwrap_or(folder);
        let whole = !exists(&root.join(name))
            && tree_files(&new.join(name)).is_some_and(|files| {
                files.len() == group.len() && files.iter().zip(group).all(|(f, e)| *f == e[folder.len()..])
            });
        if whole {
            out.push(name.to_string());
        } else {
            gather_under(folder, group, root, new, out);
        }
        rest = after;
    }
}

/// The files (links count as files) below `dir`, relative and sorted as `gathered` sorts its
/// entries; None if it holds an empty folder or cannot be read.
fn tree_files(dir: &Path) -> Option<Vec<String>> {
    fn walk(dir: &Path, prefix: &str, out: &mut Vec<String>) -> Option<()> {
        let before = out.len();
        for entry in fs::read_dir(dir).ok()? {
            let entry = entry.ok()?;
            let name = entry.file_name().into_string().ok()?;
            if entry.file_type().ok()?.is_dir() {
                walk(&entry.path(), &format!("{prefix}{name}/"), out)?;
            } else {
                out.push(format!("{prefix}{name}"));
            }
        }
        (out.len() > before).then_some(())
    }
    let mut out = Vec::new();
    walk(dir, "", &mut out)?;
    out.sort_unstable();
    Some(out)
}

/// Steps 4–5 of the protocol; safe to repeat after a crash at any point of them.
fn roll_forward(root: &Path, dir: &Path) -> anyhow::Result<()> {
    let text = fs::read(dir.join(JOURNAL)).with_context(|| format!("reading `{}`", dir.join(JOURNAL).display()))?;
    let journal: Journal = serde_json::from_slice(&text)
        .with_context(|| format!("the commit journal `{}` is damaged", dir.join(JOURNAL).display()))?;
    if journal.version != JOURNAL_FORMAT {
        bail!("the commit journal `{}` has format {}", dir.join(JOURNAL).display(), journal.version);
    }
    let states: Vec<String> = journal.state.iter().chain(&journal.retire).map(|n| state_entry(n)).collect();
    let state = "a committed run's results are not all in place yet: they are, at the next run once the link is gone";
    if let Some(link) = link_on_the_way(root, journal.install.iter().chain(&journal.remove).chain(&states)) {
        return Err(link_refused(&link, state).into());
    }
    // Made by the first entry moved aside (most commits of new records move none).
    let old = dir.join("old");
    let move_aside = |entry: &str| -> anyhow::Result<()> {
        let target = root.join(entry);
        if exists(&target) {
            let aside = old.join(entry);
            if exists(&aside) {
                bail!(
                    "cannot finish an earlier commit: both `{}` and `{}` exist; move `{}` away and rerun",
                    target.display(),
                    aside.display(),
                    target.display()
                );
            }
            if let Some(parent) = aside.parent() {
                fs::create_dir_all(parent)?;
            }
            fs::rename(&target, &aside).with_context(|| format!("moving `{}` out of the way", target.display()))?;
        }
        failpoint::hit(&format!("commit.moved_aside.{entry}"))?;
        Ok(())
    };
    // The entries to install: a folder the root has gained since it was gathered (it lacked it
    // then) takes the folder's files one by one, as the commit would have named them, so that
    // what else it holds stays.
    let mut entries: Vec<String> = Vec::with_capacity(journal.install.len());
    for entry in &journal.install {
        let new = dir.join("new").join(entry);
        let target = root.join(entry);
        let gained =
            fs::symlink_metadata(&target).ok().filter(|_| fs::symlink_metadata(&new).is_ok_and(|m| m.is_dir()));
        if let Some(gained) = gained {
            if gained.is_symlink() {
                return Err(link_refused(&target, state).into());
            }
            if !gained.is_dir() {
                bail!(
                    "`{}` is a file where a committed run installs a folder of its results; move the file away and rerun: the commit completes then",
                    target.display()
                );
            }
            // Folders emptied by a roll-forward that crashed midway are passed over.
            let files = crate::io::hash::list_files(&new)?;
            let files: Vec<String> = files.iter().map(|f| format!("{entry}/{f}")).collect();
            if let Some(link) = link_on_the_way(root, files.iter()) {
                return Err(link_refused(&link, state).into());
            }
            entries.extend(files);
        } else {
            entries.push(entry.clone());
        }
    }
    for entry in &entries {
        let new = dir.join("new").join(entry);
        if !exists(&new) {
            continue; // installed before a crash
        }
        move_aside(entry)?;
        if let Some(parent) = root.join(entry).parent() {
            fs::create_dir_all(parent)?;
        }
        fs::rename(&new, root.join(entry))
            .with_context(|| format!("moving the new `{entry}` into `{}`", root.display()))?;
        failpoint::hit(&format!("commit.moved_in.{entry}"))?;
    }
    for entry in &journal.remove {
        move_aside(entry)?;
        // The folders a removed record leaves empty (`records/motion=FB-2/`) go too.
        let mut parent = Path::new(entry).parent();
        while let Some(dir) = parent.filter(|d| d.components().count() > 1) {
            if fs::remove_dir(root.join(dir)).is_err() {
                break;
            }
            parent = dir.parent();
        }
    }
    let states = root.join(STATE_DIR).join(STATE_FILES);
    for name in journal.state.iter().filter(|n| !n.contains('/')) {
        let new = dir.join(STATE_FILES).join(name);
        if !exists(&new) {
            continue; // installed before a crash
        }
        fs::create_dir_all(&states)?;
        fs::rename(&new, states.join(name)).with_context(|| format!("installing the state file `{name}`"))?;
        failpoint::hit(&format!("commit.state_installed.{name}"))?;
    }
    if !journal.state.is_empty() {
        sync_dir(&states)?; // the state files are on disk before the lockfile naming them
    }
    let new_lock = dir.join(LOCK_FILE);
    if journal.lockfile && exists(&new_lock) {
        fs::rename(&new_lock, root.join(LOCK_FILE)).context("installing the new lockfile")?;
        failpoint::hit("commit.lockfile_installed")?;
    }
    sync_dir(root)?;
    for name in journal.retire.iter().filter(|n| !n.contains('/')) {
        match fs::remove_file(states.join(name)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(e).with_context(|| format!("removing the old state file `{name}`"));
            }
            _ => {}
        }
    }
    fs::remove_file(dir.join(JOURNAL))?;
    failpoint::hit("commit.journal_removed")?;
    fs::remove_dir_all(dir).with_context(|| format!("removing `{}`", dir.display()))?;
    Ok(())
}

/// The first folder between `root` and one of `entries` (paths relative to it) that is a
/// symbolic link: moving the entry would write or remove through the link, outside `root`.
/// Each folder is looked at once (`lstat`, never following); a folder that does not exist ends
/// the walk down that path.
fn link_on_the_way<'e>(root: &Path, entries: impl IntoIterator<Item = &'e String>) -> Option<PathBuf> {
    let mut seen: HashSet<PathBuf> = HashSet::new();
    for entry in entries {
        let mut folder = PathBuf::new();
        let mut components = Path::new(entry).components().peekable();
        while let Some(component) = components.next() {
            if components.peek().is_none() {
                break; // the entry itself: renamed, not followed
            }
            folder.push(component);
            if !seen.insert(folder.clone()) {
                continue;
            }
            match fs::symlink_metadata(root.join(&folder)) {
                Ok(meta) if meta.file_type().is_symlink() => return Some(root.join(&folder)),
                Ok(_) => {}
                Err(_) => break, // absent: nothing below it exists either
            }
        }
    }
    None
}

/// The error for a link found on the way to an entry; `state` says what became of the commit.
fn link_refused(link: &Path, state: &str) -> UserError {
    let target = fs::read_link(link).map(|t| t.display().to_string()).unwrap_or_default();
    UserError::new(format!(
        "`{}` is a symbolic link (to `{target}`) inside the output folder: shakeflow never writes or removes \
         through a link, which would change files outside its output folder; {state}",
        link.display()
    ))
    .hint(format!(
        "remove the link (`rm '{}'` removes the link only, not what it points to) or replace it by a folder, \
         and rerun",
        link.display()
    ))
}

/// Forces a folder's entries (renames into or out of it) to disk.
fn sync_dir(dir: &Path) -> std::io::Result<()> {
    fs::File::open(dir)?.sync_all()
}

/// What [`recover`] did.
#[derive(Debug, Default, PartialEq)]
pub struct Recovery {
    /// Commits an interrupted run had made and that are now complete.
    pub completed: usize,
    /// Unfinished transactions (or older shakeflow's staging folders) removed.
    pub discarded: usize,
}

/// Completes or removes what interrupted runs left in the lease's folder: transactions (see the
/// module doc) and the staging folders and temporary files of older shakeflow versions
/// (`.staging-<pid>`, `.<name>.tmp-<pid>-<n>`). Only the lease holder may call it, so nothing in
/// use is touched.
pub fn recover(lease: &Lease) -> anyhow::Result<Recovery> {
    let root = lease.root();
    let mut recovery = Recovery::default();
    let state = root.join(STATE_DIR);
    let mut txns: Vec<PathBuf> = match fs::read_dir(&state) {
        Ok(entries) => entries
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().starts_with(TXN_PREFIX))
            .map(|e| e.path())
            .collect(),
        Err(_) => Vec::new(),
    };
    txns.sort();
    for dir in txns {
        if dir.join(JOURNAL).is_file() {
            roll_forward(root, &dir)?;
            recovery.completed += 1;
        } else {
            fs::remove_dir_all(&dir).with_context(|| format!("removing `{}`", dir.display()))?;
            recovery.discarded += 1;
        }
    }
    if let Ok(entries) = fs::read_dir(root) {
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            if is_legacy_leftover(&name) {
                let path = entry.path();
                let _ = if path.is_dir() { fs::remove_dir_all(&path) } else { fs::remove_file(&path) };
                recovery.discarded += 1;
            }
        }
    }
    Ok(recovery)
}

/// `.staging-<digits>` or `.<name>.tmp-<digits>-<digits>`: what shakeflow before the journal left
/// when interrupted.
fn is_legacy_leftover(name: &str) -> bool {
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    if let Some(pid) = name.strip_prefix(".staging-") {
        return digits(pid);
    }
    let Some(rest) = name.strip_prefix('.') else { return false };
    let Some((_, tail)) = rest.rsplit_once(".tmp-") else { return false };
    tail.split_once('-').is_some_and(|(pid, n)| digits(pid) && digits(n))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tree(dir: &Path) -> Vec<String> {
        let mut files = crate::io::hash::list_files(dir).unwrap();
        files.retain(|f| !f.starts_with(".shakeflow/lease"));
        files
    }

    #[test]
    fn a_commit_replaces_installs_and_removes_at_once() {
        let root = crate::tempdir::tempdir().unwrap();
        for (entry, file) in [("a", "old"), ("gone", "x"), ("keep", "k")] {
            fs::create_dir_all(root.path().join(entry)).unwrap();
            fs::write(root.path().join(entry).join(file), file).unwrap();
        }
        let lease = Lease::acquire(root.path()).unwrap();
        let txn = Transaction::begin(&lease).unwrap();
        for (entry, file) in [("a", "old"), ("a", "new"), ("b", "new")] {
            fs::create_dir_all(txn.new_path(entry)).unwrap();
            fs::write(txn.new_path(entry).join(file), format!("{entry}/{file} made anew")).unwrap();
        }
        let lock = LockFile::empty();
        let install = ["a/new".into(), "a/old".into(), "b/new".into()];
        txn.commit(&install, &["gone".into()], Some((&lock, &lock))).unwrap();
        assert_eq!(tree(root.path()), ["a/new", "a/old", "b/new", "keep/k", "shakeflow.lock"]);
        assert_eq!(fs::read_to_string(root.path().join("a/old")).unwrap(), "a/old made anew");
    }

    #[test]
    fn a_folder_the_root_gains_after_its_commit_point_takes_the_new_files_and_keeps_its_own() {
        let root = crate::tempdir::tempdir().unwrap();
        let lease = Lease::acquire(root.path()).unwrap();
        let txn = Transaction::begin(&lease).unwrap();
        fs::create_dir_all(txn.new_path("s/records")).unwrap();
        fs::write(txn.new_path("s/records/data"), "new").unwrap();
        // As a roll-forward that crashed midway leaves it: a folder whose files went in.
        fs::create_dir_all(txn.new_path("s/emptied")).unwrap();
        let dir = txn.dir.clone();
        let journal = Journal {
            version: 1,
            install: vec!["s".into()], // gathered: the root lacked `s`
            remove: vec![],
            lockfile: false,
            state: vec![],
            retire: vec![],
        };
        fs::write(dir.join(JOURNAL), serde_json::to_vec(&journal).unwrap()).unwrap();
        std::mem::forget(txn);
        // A crash at the commit point; `s` appears before the next lease holder rolls forward.
        fs::create_dir_all(root.path().join("s/records")).unwrap();
        fs::write(root.path().join("s/notes.txt"), "mine").unwrap();
        fs::write(root.path().join("s/records/data"), "stale").unwrap();
        roll_forward(root.path(), &dir).unwrap();
        assert_eq!(fs::read_to_string(root.path().join("s/notes.txt")).unwrap(), "mine", "not ours: it stays");
        assert_eq!(fs::read_to_string(root.path().join("s/records/data")).unwrap(), "new", "ours: replaced");
        // A link where a gathered folder goes is refused, as on the way to a file.
        let txn = Transaction::begin(&lease).unwrap();
        fs::create_dir_all(txn.new_path("t")).unwrap();
        fs::write(txn.new_path("t/data"), "new").unwrap();
        let dir = txn.dir.clone();
        let journal = Journal { install: vec!["t".into()], ..journal };
        fs::write(dir.join(JOURNAL), serde_json::to_vec(&journal).unwrap()).unwrap();
        std::mem::forget(txn);
        let elsewhere = crate::tempdir::tempdir().unwrap();
        std::os::unix::fs::symlink(elsewhere.path(), root.path().join("t")).unwrap();
        let err = roll_forward(root.path(), &dir).unwrap_err();
        assert!(format!("{err:#}").contains("is a symbolic link"), "{err:#}");
        assert!(elsewhere.path().read_dir().unwrap().next().is_none(), "nothing written through the link");
    }

    #[test]
    fn a_folder_the_root_lacks_is_installed_whole_only_when_all_of_it_is() {
        let (root, new) = (crate::tempdir::tempdir().unwrap(), crate::tempdir::tempdir().unwrap());
        fs::create_dir_all(root.path().join("s/records")).unwrap();
        let files = [
            "s/records/m=1/data.parquet",
            "s/records/m=2/data.parquet",
            "t/.marker",
            "t/records/m=1/data.parquet",
            "t/records/m=2/data.parquet",
            "u/status/data.parquet",
            "u/records/m=1/data.parquet",
            "v/empty/",
            "v/records/data.parquet",
            "w.html",
        ];
        for file in files {
            let path = new.path().join(file);
            if file.ends_with('/') {
                fs::create_dir_all(path).unwrap();
            } else {
                fs::create_dir_all(path.parent().unwrap()).unwrap();
                fs::write(path, file).unwrap();
            }
        }
        let install: Vec<String> = files
            .iter()
            .filter(|f| !f.ends_with('/') && **f != "u/status/data.parquet")
            .map(|f| f.to_string())
            .collect();
        assert_eq!(
            gathered(root.path(), new.path(), &install),
            [
                // The root has `s/records`: its new records are new folders of it.
                "s/records/m=1",
                "s/records/m=2",
                // All of `t`, its hidden file too.
                "t",
                // `u/status` is not installed: `u` is not gathered, `u/records` is.
                "u/records",
                // An empty folder is not installed file by file: nor is it here.
                "v/records",
                "w.html",
            ]
        );
    }

    #[test]
    fn an_unjournaled_transaction_is_discarded_and_a_journaled_one_completed() {
        let root = crate::tempdir::tempdir().unwrap();
        fs::create_dir_all(root.path().join("a")).unwrap();
        fs::write(root.path().join("a/old"), "1").unwrap();
        let lease = Lease::acquire(root.path()).unwrap();
        // Not committed: discarded.
        let txn = Transaction::begin(&lease).unwrap();
        fs::create_dir_all(txn.new_path("a")).unwrap();
        fs::write(txn.new_path("a").join("new"), "2").unwrap();
        std::mem::forget(txn);
        // Committed, then "crashed" right after the commit point: completed.
        let txn = Transaction::begin(&lease).unwrap();
        fs::create_dir_all(txn.new_path("c")).unwrap();
        fs::write(txn.new_path("c").join("new"), "3").unwrap();
        let journal = Journal {
            version: 1,
            install: vec!["c".into()],
            remove: vec![],
            lockfile: false,
            state: vec![],
            retire: vec![],
        };
        fs::write(txn.dir.join(JOURNAL), serde_json::to_vec(&journal).unwrap()).unwrap();
        std::mem::forget(txn);
        fs::write(root.path().join(".staging-4242"), "legacy").unwrap();
        fs::write(root.path().join(".load.tmp-17-3"), "legacy").unwrap();
        fs::write(root.path().join(".notes.txt"), "the user's").unwrap();
        let recovery = recover(&lease).unwrap();
        assert_eq!(recovery, Recovery { completed: 1, discarded: 3 });
        assert_eq!(tree(root.path()), [".notes.txt", "a/old", "c/new"]);
    }

    /// A user's folder (`mine`) linked in as a record folder of the output.
    fn linked_record(root: &Path) -> PathBuf {
        let mine = root.join("mine");
        fs::create_dir_all(&mine).unwrap();
        fs::write(mine.join("thesis.txt"), "years of work").unwrap();
        let out = root.join("out");
        fs::create_dir_all(out.join("load/records")).unwrap();
        std::os::unix::fs::symlink(&mine, out.join("load/records/motion=FB-1")).unwrap();
        mine
    }

    fn names(dir: &Path) -> Vec<String> {
        crate::io::hash::list_files(dir).unwrap()
    }

    #[test]
    fn a_commit_through_a_link_is_refused_before_its_commit_point() {
        let root = crate::tempdir::tempdir().unwrap();
        let mine = linked_record(root.path());
        let out = root.path().join("out");
        fs::write(mine.join("data.parquet"), "the user's").unwrap();
        let lease = Lease::acquire(&out).unwrap();
        for (install, remove) in [
            (vec!["load/records/motion=FB-1/data.parquet".to_string()], vec![]),
            (vec![], vec!["load/records/motion=FB-1/data.parquet".to_string()]),
        ] {
            let txn = Transaction::begin(&lease).unwrap();
            let new = txn.new_path("load/records/motion=FB-1");
            fs::create_dir_all(&new).unwrap();
            fs::write(new.join("data.parquet"), "ours").unwrap();
            let error =
                txn.commit(&install, &remove, Some((&LockFile::empty(), &LockFile::empty()))).unwrap_err().to_string();
            assert!(
                error.contains("motion=FB-1` is a symbolic link") && error.contains("nothing was changed"),
                "{error}"
            );
            assert_eq!(names(&mine), ["data.parquet", "thesis.txt"]);
            assert_eq!(fs::read_to_string(mine.join("data.parquet")).unwrap(), "the user's");
            assert!(!out.join(LOCK_FILE).exists(), "nothing committed");
        }
        assert_eq!(recover(&lease).unwrap(), Recovery::default(), "refused transactions leave nothing behind");
        // The link itself as an entry is moved, never followed: removing it leaves its target.
        let txn = Transaction::begin(&lease).unwrap();
        txn.commit(&[], &["load/records/motion=FB-1".into()], None).unwrap();
        assert!(fs::symlink_metadata(out.join("load/records/motion=FB-1")).is_err());
        assert_eq!(names(&mine), ["data.parquet", "thesis.txt"]);
    }

    #[test]
    fn rolling_forward_through_a_link_made_after_the_commit_point_is_refused_until_it_is_gone() {
        let root = crate::tempdir::tempdir().unwrap();
        let mine = linked_record(root.path());
        let out = root.path().join("out");
        let lease = Lease::acquire(&out).unwrap();
        let txn = Transaction::begin(&lease).unwrap();
        fs::create_dir_all(txn.new_path("load/records/motion=FB-1")).unwrap();
        fs::write(txn.new_path("load/records/motion=FB-1/data.parquet"), "ours").unwrap();
        let entry = "load/records/motion=FB-1/data.parquet".to_string();
        let journal = Journal {
            version: 1,
            install: vec![entry],
            remove: vec![],
            lockfile: false,
            state: vec![],
            retire: vec![],
        };
        fs::write(txn.dir.join(JOURNAL), serde_json::to_vec(&journal).unwrap()).unwrap();
        std::mem::forget(txn);
        let error = recover(&lease).unwrap_err().to_string();
        assert!(error.contains("motion=FB-1` is a symbolic link") && error.contains("at the next run"), "{error}");
        assert_eq!(names(&mine), ["thesis.txt"]);
        fs::remove_file(out.join("load/records/motion=FB-1")).unwrap();
        assert_eq!(recover(&lease).unwrap(), Recovery { completed: 1, discarded: 0 });
        assert_eq!(fs::read_to_string(out.join("load/records/motion=FB-1/data.parquet")).unwrap(), "ours");
        assert_eq!(names(&mine), ["thesis.txt"]);
    }

    fn one_stage(units: &[&str]) -> LockFile {
        let unit = |key: &str| crate::pipeline::lock::UnitLock {
            key: key.into(),
            inputs: Default::default(),
            files: Default::default(),
            flagged: None,
            notes: Vec::new(),
        };
        let mut lock = LockFile::empty();
        let entry = crate::pipeline::lock::StageLock {
            stage_type: "load".into(),
            stage_version: 1,
            params: serde_json::json!({}),
            select: Default::default(),
            units: units.iter().map(|u| (u.to_string(), unit(u))).collect(),
        };
        lock.stages.insert("load".into(), entry);
        lock
    }

    #[test]
    fn state_files_go_in_before_the_root_and_the_old_ones_after_it() {
        let root = crate::tempdir::tempdir().unwrap();
        let lease = Lease::acquire(root.path()).unwrap();
        let lock_path = root.path().join(LOCK_FILE);
        let states = root.path().join(STATE_DIR).join(STATE_FILES);
        let first = one_stage(&["a"]);
        Transaction::begin(&lease).unwrap().commit(&[], &[], Some((&first, &LockFile::empty()))).unwrap();
        let read = LockFile::read(&lock_path).unwrap();
        assert_eq!(read.stages, first.stages);
        let old = read.state_files["load"].one().to_string();
        assert_eq!(names(&states), [old.as_str()]);

        // Committed, then "crashed" right after the commit point: the next lease holder installs
        // the new state file, then the root naming it, then removes the old file.
        let second = one_stage(&["a", "b"]);
        let new = second.encode(&read).unwrap();
        let txn = Transaction::begin(&lease).unwrap();
        fs::create_dir_all(txn.dir.join(STATE_FILES)).unwrap();
        let (name, bytes) = &new.files[0];
        fs::write(txn.dir.join(STATE_FILES).join(name), bytes).unwrap();
        fs::write(txn.dir.join(LOCK_FILE), &new.root).unwrap();
        let journal = Journal {
            version: 1,
            install: vec![],
            remove: vec![],
            lockfile: true,
            state: vec![name.clone()],
            retire: new.retired.clone(),
        };
        fs::write(txn.dir.join(JOURNAL), serde_json::to_vec(&journal).unwrap()).unwrap();
        std::mem::forget(txn);
        assert_eq!(LockFile::read(&lock_path).unwrap().stages, first.stages, "the old state until rolled forward");
        assert_eq!(recover(&lease).unwrap(), Recovery { completed: 1, discarded: 0 });
        assert_eq!(LockFile::read(&lock_path).unwrap().stages, second.stages);
        assert_eq!(names(&states), [name.as_str()], "the old state file is gone");

        // A state folder replaced by a link to a user's folder: refused, nothing written there.
        let mine = root.path().join("mine");
        fs::create_dir_all(&mine).unwrap();
        fs::write(mine.join("thesis.txt"), "years of work").unwrap();
        fs::rename(&states, root.path().join("kept")).unwrap();
        std::os::unix::fs::symlink(&mine, &states).unwrap();
        let read = LockFile::empty();
        let error = Transaction::begin(&lease).unwrap().commit(&[], &[], Some((&first, &read))).unwrap_err();
        assert!(error.to_string().contains("state` is a symbolic link"), "{error}");
        assert_eq!(names(&mine), ["thesis.txt"]);
    }

    #[test]
    fn legacy_leftovers_are_recognised_by_their_exact_shape() {
        assert!(is_legacy_leftover(".staging-123"));
        assert!(is_legacy_leftover(".baseline.tmp-99-0"));
        assert!(is_legacy_leftover(".shakeflow.lock.tmp-99-12"));
        for user in [".staging-", ".staging-12a", "load.tmp-1-2", ".x.tmp-1", ".x.tmp-a-1", ".bashrc"] {
            assert!(!is_legacy_leftover(user), "{user}");
        }
    }
}
