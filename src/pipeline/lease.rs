//! One run at a time per output folder: a lease file `<root>/.shakeflow/lease`, created with
//! `O_CREAT|O_EXCL` (atomic on local disks and on NFS v3+/Lustre, unlike `flock`/`fcntl` locks,
//! which shared cluster file systems may not offer).
//!
//! The file says who holds it (host, pid, the process's start time, command, start time). A
//! holder refreshes its modification time every [`HEARTBEAT`]. Another run finds it:
//! - held by a live process: refused, naming the holder;
//! - held on this host by a process that is gone (its pid no longer exists, or now belongs to a
//!   process that started later): a stale lease, taken over;
//! - held on another host: a pid there means nothing here, so the lease is stale only when its
//!   heartbeat stopped more than [`STALE_AFTER`] ago — or, for a holder that ran inside a Slurm
//!   job (a commit job, an in-allocation run: `$SLURM_JOB_ID`), once `squeue` no longer knows
//!   that job and its heartbeat has missed two beats (killed with its node, out of memory:
//!   nothing else tells another host; the heartbeat too, since `squeue` may not show a live job
//!   of another user's).
//!
//! Taking over is itself exclusive: the taker first creates `lease.break` (`O_EXCL`), checks the
//! lease is still the stale one it read, removes it and creates its own; a `lease.break` left by
//! a taker that died is ignored after [`BREAK_STALE_AFTER`].
//!
//! A Slurm run outlives the process that submitted it: that process [`Lease::hand_over`]s the
//! lease to the run (its holder then names the run and its commit job, which alone takes it
//! back with [`Lease::take_handed`]). Such a lease is stale once `squeue` no longer knows the
//! commit job.

use std::fs::{self, File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

use super::failpoint;
use super::layout::{BREAK_FILE, LEASE_FILE, STATE_DIR};
use crate::error::UserError;

/// How often a holder shows it is alive.
pub const HEARTBEAT: Duration = Duration::from_secs(30);
/// A lease from another host whose heartbeat is older than this is stale. Generous, for clocks
/// that differ between a cluster's nodes.
pub const STALE_AFTER: Duration = Duration::from_secs(600);
const BREAK_STALE_AFTER: Duration = Duration::from_secs(60);
/// A lease from another host whose holder ran in a Slurm job `squeue` no longer knows is stale
/// once its heartbeat is this old (two missed beats), not [`STALE_AFTER`].
const JOB_GONE_AFTER: Duration = Duration::from_secs(2 * HEARTBEAT.as_secs() + 5);

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Holder {
    pub host: String,
    pub pid: u32,
    /// The process's start time in clock ticks since boot (`/proc/<pid>/stat`, field 22): tells a
    /// reused pid from the holder.
    pub process_start: Option<u64>,
    /// Seconds since the Unix epoch.
    pub started: u64,
    pub command: String,
    /// Unique to this lease: a holder removes only its own. A Slurm run's: the run's id.
    pub token: String,
    /// Set while a Slurm run holds the lease: its commit job's id.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slurm_job: Option<String>,
    /// The Slurm job the holding process runs in (`$SLURM_JOB_ID`), if any: once Slurm no longer
    /// knows it, the holder is gone, whatever host asks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub in_job: Option<String>,
}

impl Holder {
    fn describe(&self) -> String {
        let age = now_secs().saturating_sub(self.started);
        if let Some(job) = &self.slurm_job {
            return format!(
                "the Slurm run `{}` (commit job {job}), submitted {} ({} ago) by `{}`",
                self.token,
                format_utc(self.started),
                format_age(age),
                self.command
            );
        }
        format!(
            "pid {} on host `{}`, started {} ({} ago): `{}`",
            self.pid,
            self.host,
            format_utc(self.started),
            format_age(age),
            self.command
        )
    }
}

/// Held while alive; dropping it stops the heartbeat and removes the lease file (and the
/// `.shakeflow` folder when nothing else is in it).
pub struct Lease {
    path: PathBuf,
    root: PathBuf,
    token: String,
    stop: Arc<AtomicBool>,
    heartbeat: Option<std::thread::JoinHandle<()>>,
    /// What a stale lease's takeover replaced, and why it was stale, for the user to hear.
    pub took_over: Option<(Holder, String)>,
}

impl Lease {
    /// Takes the lease of `root` (created if missing) or says who holds it.
    pub fn acquire(root: &Path) -> Result<Lease, UserError> {
        let dir = root.join(STATE_DIR);
        if fs::symlink_metadata(&dir).is_ok_and(|m| m.file_type().is_symlink()) {
            // Transactions are made and removed in it: through a link, outside the output folder.
            return Err(UserError::new(format!(
                "`{}` is a symbolic link: shakeflow keeps its transactions there and never writes or removes through a link",
                dir.display()
            ))
            .hint("remove the link (it is shakeflow's own state folder; the link's target is left as it is) and rerun"));
        }
        fs::create_dir_all(&dir).map_err(|e| {
            UserError::new(format!("cannot create `{}`: {e}", dir.display())).hint("the output folder must be writable")
        })?;
        let path = dir.join(LEASE_FILE);
        let holder = Holder {
            host: hostname(),
            pid: std::process::id(),
            process_start: process_start(std::process::id()),
            started: now_secs(),
            command: std::env::args().collect::<Vec<_>>().join(" "),
            token: format!("{}-{}-{}", hostname(), std::process::id(), now_nanos()),
            slurm_job: None,
            in_job: current_job(),
        };
        let mut took_over = None;
        for _attempt in 0..50 {
            // Another run's drop may remove the empty folder between our creating it and the lease.
            let _ = fs::create_dir_all(&dir);
            match create_exclusive(&path, &holder) {
                Ok(()) => {
                    failpoint::hit("lease.acquired").map_err(|e| UserError::new(e.to_string()))?;
                    let stop = Arc::new(AtomicBool::new(false));
                    let heartbeat = spawn_heartbeat(path.clone(), holder.token.clone(), stop.clone());
                    return Ok(Lease {
                        path,
                        root: root.to_path_buf(),
                        token: holder.token,
                        stop,
                        heartbeat: Some(heartbeat),
                        took_over,
                    });
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
                Err(e) => {
                    return Err(UserError::new(format!("cannot create the lease `{}`: {e}", path.display()))
                        .hint("the output folder must be writable"))
                }
            }
            let Some(current) = read_holder(&path) else {
                // Removed meanwhile, or half written by a holder that is still creating it.
                std::thread::sleep(Duration::from_millis(20));
                continue;
            };
            match staleness(&path, &current) {
                None => {
                    return Err(UserError::new(format!(
                        "another shakeflow run is writing `{}`: {}",
                        root.display(),
                        current.describe()
                    ))
                    .hint(format!(
                        "one run at a time may write an output folder: wait for it to finish. If that run is \
                         gone and its host cannot tell (a node that crashed), its lease `{}` is taken over \
                         {} minutes after its last heartbeat, or delete it yourself",
                        path.display(),
                        STALE_AFTER.as_secs() / 60
                    )));
                }
                Some(why) => {
                    if break_stale(&dir, &path, &current) {
                        took_over = Some((current, why));
                    } else {
                        std::thread::sleep(Duration::from_millis(50));
                    }
                }
            }
        }
        Err(UserError::new(format!("could not take the lease `{}`: other runs kept taking it", path.display()))
            .hint("one run at a time may write an output folder; try again when the others are done"))
    }

    /// The folder this lease guards.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Gives the lease to the Slurm run `run` whose commit job is `job`: the lease stays after
    /// this process ends, naming the run, until the commit job takes it ([`Lease::take_handed`])
    /// or `squeue` no longer knows that job.
    pub fn hand_over(self, run: &str, job: &str) -> Result<(), UserError> {
        let holder = Holder {
            host: hostname(),
            pid: std::process::id(),
            process_start: None,
            started: now_secs(),
            command: std::env::args().collect::<Vec<_>>().join(" "),
            token: run.to_string(),
            slurm_job: Some(job.to_string()),
            in_job: None,
        };
        replace_holder(&self.path, &holder)
    }

    /// Takes back the lease handed to the Slurm run `run` (in its commit job).
    pub fn take_handed(root: &Path, run: &str) -> Result<Lease, UserError> {
        let path = root.join(STATE_DIR).join(LEASE_FILE);
        // The submitting process hands the lease over just after submitting this job: give it a
        // moment, should this job start first.
        for _ in 0..120 {
            match read_holder(&path) {
                Some(h) if h.token != run && h.slurm_job.is_none() && staleness(&path, &h).is_none() => {
                    std::thread::sleep(Duration::from_millis(500));
                }
                _ => break,
            }
        }
        match read_holder(&path) {
            Some(h) if h.token == run && h.slurm_job.is_some() => {}
            Some(h) => {
                return Err(UserError::new(format!(
                    "the lease of `{}` is not the Slurm run `{run}`'s: {}",
                    root.display(),
                    h.describe()
                ))
                .hint("the run's outputs stay in its folder under .shakeflow/slurm; rerun the pipeline"))
            }
            None => {
                return Err(UserError::new(format!("the Slurm run `{run}` lost its lease on `{}`", root.display())))
            }
        }
        let holder = Holder {
            host: hostname(),
            pid: std::process::id(),
            process_start: process_start(std::process::id()),
            started: now_secs(),
            command: std::env::args().collect::<Vec<_>>().join(" "),
            token: format!("{}-{}-{}", hostname(), std::process::id(), now_nanos()),
            slurm_job: None,
            in_job: current_job(),
        };
        replace_holder(&path, &holder)?;
        let stop = Arc::new(AtomicBool::new(false));
        let heartbeat = spawn_heartbeat(path.clone(), holder.token.clone(), stop.clone());
        Ok(Lease {
            path,
            root: root.to_path_buf(),
            token: holder.token,
            stop,
            heartbeat: Some(heartbeat),
            took_over: None,
        })
    }
}

/// Rewrites the lease file of its holder (temp file and rename, forced to disk).
fn replace_holder(path: &Path, holder: &Holder) -> Result<(), UserError> {
    let body = serde_json::to_vec_pretty(holder).expect("holders serialise");
    let tmp = path.with_extension("tmp");
    let _ = fs::remove_file(&tmp);
    crate::io::atomic::write_new_durable(&tmp, &body)
        .and_then(|()| fs::rename(&tmp, path))
        .map_err(|e| UserError::new(format!("cannot rewrite the lease `{}`: {e}", path.display())))
}

impl Drop for Lease {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(handle) = self.heartbeat.take() {
            handle.thread().unpark();
            let _ = handle.join();
        }
        if read_holder(&self.path).is_some_and(|h| h.token == self.token) {
            let _ = fs::remove_file(&self.path);
        }
        // Only when empty: no other run's lease or unfinished commit is in it.
        let _ = fs::remove_dir(self.root.join(STATE_DIR));
    }
}

/// Writes the holder into a file that must not exist yet, forced to disk; a failed write
/// leaves no file behind.
fn create_exclusive(path: &Path, holder: &Holder) -> std::io::Result<()> {
    let mut file = OpenOptions::new().write(true).create_new(true).open(path)?;
    let body = serde_json::to_vec_pretty(holder).expect("holders serialise");
    let written = file.write_all(&body).and_then(|()| file.sync_all());
    if written.is_err() {
        let _ = fs::remove_file(path);
    }
    written
}

fn read_holder(path: &Path) -> Option<Holder> {
    serde_json::from_slice(&fs::read(path).ok()?).ok()
}

/// Why `holder`'s lease is stale, or None when it may still be alive.
fn staleness(path: &Path, holder: &Holder) -> Option<String> {
    if let Some(job) = &holder.slurm_job {
        // Alive while Slurm knows its commit job; where `squeue` cannot answer, it holds.
        return (!slurm_knows(job)?).then(|| format!("Slurm no longer knows job {job}"));
    }
    if holder.host == hostname() {
        if !process_exists(holder.pid) {
            return Some(format!("process {} no longer exists", holder.pid));
        }
        let now = process_start(holder.pid);
        if holder.process_start.is_some() && now.is_some() && now != holder.process_start {
            return Some(format!("pid {} now belongs to another process", holder.pid));
        }
        return None;
    }
    let beat = fs::metadata(path).and_then(|m| m.modified()).ok()?;
    let silent = SystemTime::now().duration_since(beat).unwrap_or_default();
    // Its job gone from `squeue` *and* its heartbeat stopped: `squeue` alone can say a live
    // job is unknown (another user's under `PrivateData=jobs`, another cluster's id).
    if let Some(job) = holder.in_job.as_ref().filter(|_| silent > JOB_GONE_AFTER) {
        if slurm_knows(job) == Some(false) {
            return Some(format!("its Slurm job {job} has ended, no heartbeat for {}", format_age(silent.as_secs())));
        }
    }
    (silent > STALE_AFTER).then(|| format!("no heartbeat for {}", format_age(silent.as_secs())))
}

/// Whether Slurm still knows job `job` (pending, running, completing); None when `squeue`
/// cannot answer here (not installed, no controller).
fn slurm_knows(job: &str) -> Option<bool> {
    let out = std::process::Command::new("squeue").args(["-h", "-j", job, "-o", "%T"]).output().ok()?;
    let known = out.status.success() && !String::from_utf8_lossy(&out.stdout).trim().is_empty();
    let gone = String::from_utf8_lossy(&out.stderr).contains("Invalid job id");
    (known || out.status.success() || gone).then_some(known)
}

/// The Slurm job this process runs in, if any.
fn current_job() -> Option<String> {
    std::env::var("SLURM_JOB_ID").ok().filter(|j| !j.is_empty())
}

/// Removes the stale lease `seen` under the exclusive `lease.break`; false when another taker
/// is at it (or the lease changed meanwhile).
fn break_stale(dir: &Path, path: &Path, seen: &Holder) -> bool {
    let breaker = dir.join(BREAK_FILE);
    match OpenOptions::new().write(true).create_new(true).open(&breaker) {
        Ok(_) => {}
        Err(_) => {
            let old = fs::metadata(&breaker)
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| SystemTime::now().duration_since(t).ok())
                .is_some_and(|age| age > BREAK_STALE_AFTER);
            if old {
                let _ = fs::remove_file(&breaker);
            }
            return false;
        }
    }
    let still = read_holder(path).is_some_and(|h| h == *seen);
    if still {
        let _ = fs::remove_file(path);
    }
    let _ = fs::remove_file(&breaker);
    still
}

fn spawn_heartbeat(path: PathBuf, token: String, stop: Arc<AtomicBool>) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || loop {
        std::thread::park_timeout(HEARTBEAT);
        if stop.load(Ordering::Relaxed) {
            return;
        }
        if read_holder(&path).is_some_and(|h| h.token == token) {
            if let Ok(file) = File::options().write(true).open(&path) {
                let _ = file.set_modified(SystemTime::now());
            }
        }
    })
}

fn hostname() -> String {
    let mut buf = [0u8; 256];
    // SAFETY: the buffer is valid for its length; gethostname NUL-terminates within it or truncates.
    let ok = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) } == 0;
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    if ok && end > 0 {
        String::from_utf8_lossy(&buf[..end]).into_owned()
    } else {
        "unknown-host".into()
    }
}

pub fn process_exists(pid: u32) -> bool {
    let Ok(pid) = i32::try_from(pid) else { return false };
    // SAFETY: signal 0 only asks whether the process exists; nothing is sent.
    let alive = unsafe { libc::kill(pid, 0) } == 0;
    alive || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
}

/// Field 22 of `/proc/<pid>/stat` (start time in clock ticks since boot), where there is a /proc.
fn process_start(pid: u32) -> Option<u64> {
    let stat = fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) is in parentheses and may hold spaces: count after its `)`.
    let after = &stat[stat.rfind(')')? + 1..];
    after.split_whitespace().nth(19)?.parse().ok()
}

fn now_secs() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs())
}

fn now_nanos() -> u128 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos())
}

/// `2026-11-25 13:05:12 UTC` (days to civil date after Howard Hinnant's algorithm).
pub fn format_utc(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rest = secs % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02} {:02}:{:02}:{:02} UTC", rest / 3600, rest % 3600 / 60, rest % 60)
}

fn format_age(secs: u64) -> String {
    match secs {
        s if s < 120 => format!("{s} s"),
        s if s < 7200 => format!("{} min", s / 60),
        s => format!("{:.1} h", s as f64 / 3600.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_dates_match_known_instants() {
        assert_eq!(format_utc(0), "1970-01-01 00:00:00 UTC");
        // `date -u -d @1795611912`
        assert_eq!(format_utc(1_795_611_912), "2026-11-25 13:05:12 UTC");
        assert_eq!(format_utc(951_782_400), "2000-02-29 00:00:00 UTC");
    }

    #[test]
    fn a_second_lease_is_refused_naming_the_holder_and_released_on_drop() {
        let dir = crate::tempdir::tempdir().unwrap();
        let first = Lease::acquire(dir.path()).unwrap();
        let err = Lease::acquire(dir.path()).err().expect("a second lease while the first is held");
        assert!(err.message.contains(&format!("pid {}", std::process::id())), "{err}");
        assert!(err.message.contains(&hostname()), "{err}");
        drop(first);
        assert!(!dir.path().join(STATE_DIR).join(LEASE_FILE).exists());
        Lease::acquire(dir.path()).expect("free again");
    }

    fn write_lease(dir: &Path, holder: &Holder) -> PathBuf {
        let path = dir.join(STATE_DIR).join(LEASE_FILE);
        fs::create_dir_all(path.parent().unwrap()).unwrap();
        fs::write(&path, serde_json::to_vec(holder).unwrap()).unwrap();
        path
    }

    fn holder(host: &str, pid: u32) -> Holder {
        Holder {
            host: host.into(),
            pid,
            process_start: None,
            started: now_secs(),
            command: "shakeflow run p.yaml".into(),
            token: "t".into(),
            slurm_job: None,
            in_job: None,
        }
    }

    #[test]
    fn a_dead_local_holder_is_taken_over() {
        let dir = crate::tempdir::tempdir().unwrap();
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let pid = child.id();
        child.wait().unwrap();
        write_lease(dir.path(), &holder(&hostname(), pid));
        let lease = Lease::acquire(dir.path()).expect("stale lease taken over");
        assert_eq!(lease.took_over.as_ref().map(|(h, _)| h.pid), Some(pid));
    }

    #[test]
    fn a_reused_pid_does_not_keep_a_lease_alive() {
        let dir = crate::tempdir::tempdir().unwrap();
        // Our own pid, but recorded with another start time: the holder was an earlier process.
        let mut old = holder(&hostname(), std::process::id());
        old.process_start = process_start(std::process::id()).map(|t| t + 1);
        write_lease(dir.path(), &old);
        assert!(Lease::acquire(dir.path()).is_ok());
    }

    #[test]
    fn another_hosts_lease_holds_until_its_heartbeat_is_old() {
        let dir = crate::tempdir::tempdir().unwrap();
        let path = write_lease(dir.path(), &holder("node-that-is-not-here", 1));
        let err = Lease::acquire(dir.path()).err().expect("a fresh lease of another host holds");
        assert!(err.message.contains("node-that-is-not-here"), "{err}");
        let old = SystemTime::now() - STALE_AFTER - Duration::from_secs(5);
        File::options().write(true).open(&path).unwrap().set_modified(old).unwrap();
        let lease = Lease::acquire(dir.path()).expect("a silent lease of another host is taken over");
        assert_eq!(lease.took_over.as_ref().map(|(h, _)| h.host.as_str()), Some("node-that-is-not-here"));
    }

    #[test]
    fn a_holder_in_a_slurm_job_with_a_fresh_heartbeat_holds_whatever_squeue_says() {
        // `squeue` may not show a live job (another user's, another cluster's id): a fresh
        // heartbeat holds; the job's end counts only once two beats were missed.
        let dir = crate::tempdir::tempdir().unwrap();
        let in_job = Holder { in_job: Some("999999999".into()), ..holder("node-that-is-not-here", 1) };
        let path = write_lease(dir.path(), &in_job);
        assert_eq!(staleness(&path, &in_job), None);
        let a_minute_ago = SystemTime::now() - JOB_GONE_AFTER + Duration::from_secs(5);
        File::options().write(true).open(&path).unwrap().set_modified(a_minute_ago).unwrap();
        assert_eq!(staleness(&path, &in_job), None, "not yet two beats missed");
        assert!(JOB_GONE_AFTER > 2 * HEARTBEAT && JOB_GONE_AFTER < STALE_AFTER);
    }
}
