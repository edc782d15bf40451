//! Named points in the commit and lease code where a test can stop the process dead, make an
//! operation fail, or see which points a run passes. Off unless `SHAKEFLOW_FAILPOINT` is set:
//!
//! - `SHAKEFLOW_FAILPOINT=trace` prints `failpoint: <name>` to stderr at every point passed;
//! - `SHAKEFLOW_FAILPOINT=<name>` kills the process with SIGKILL there (as `kill -9` would);
//! - `SHAKEFLOW_FAILPOINT=<name>:enospc` makes the operation there fail with "No space left on device";
//! - `SHAKEFLOW_FAILPOINT=<name>:sleep=<ms>` pauses there (to hold a lease while another run starts);
//! - `SHAKEFLOW_FAILPOINT=<name>:once=<file>` kills the process there the first time only: it
//!   creates `<file>` (exclusively) before dying, and passes when `<file>` exists (a Slurm task
//!   that dies once and succeeds when resubmitted).
//!
//! The crash tests (`tests/it/crash_safety.rs`) kill a run at every point its trace lists, so a
//! new step in the commit is covered as soon as it calls [`hit`].

use std::sync::OnceLock;

enum Action {
    Kill,
    NoSpace,
    Sleep(u64),
    Once(std::path::PathBuf),
}

fn armed() -> &'static Option<(String, Option<Action>)> {
    static ARMED: OnceLock<Option<(String, Option<Action>)>> = OnceLock::new();
    ARMED.get_or_init(|| {
        let value = std::env::var("SHAKEFLOW_FAILPOINT").ok().filter(|v| !v.is_empty())?;
        if value == "trace" {
            return Some((value, None));
        }
        let (name, action) = match value.split_once(':') {
            None => (value.as_str(), Action::Kill),
            Some((name, "enospc")) => (name, Action::NoSpace),
            Some((name, once)) if once.starts_with("once=") => (name, Action::Once(once["once=".len()..].into())),
            Some((name, sleep)) => {
                let ms = sleep.strip_prefix("sleep=").and_then(|ms| ms.parse().ok()).unwrap_or(1000);
                (name, Action::Sleep(ms))
            }
        };
        Some((name.to_string(), Some(action)))
    })
}

/// Passes the point `name`: nothing happens unless a test armed it.
pub fn hit(name: &str) -> std::io::Result<()> {
    let Some((armed_name, action)) = armed() else { return Ok(()) };
    if action.is_none() {
        eprintln!("failpoint: {name}");
        return Ok(());
    }
    if armed_name != name {
        return Ok(());
    }
    match action {
        Some(Action::Kill) => kill(),
        Some(Action::Once(marker)) => {
            if std::fs::OpenOptions::new().write(true).create_new(true).open(marker).is_ok() {
                kill()
            }
            Ok(())
        }
        Some(Action::NoSpace) => Err(std::io::Error::from_raw_os_error(libc::ENOSPC)),
        Some(Action::Sleep(ms)) => {
            std::thread::sleep(std::time::Duration::from_millis(*ms));
            Ok(())
        }
        None => Ok(()),
    }
}

fn kill() -> ! {
    // SAFETY: raising a signal on our own process; SIGKILL cannot be caught, exactly as `kill -9`.
    unsafe { libc::kill(libc::getpid(), libc::SIGKILL) };
    unreachable!("SIGKILL ends the process")
}
