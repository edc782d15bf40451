//! The Slurm client of the Slurm executor: job arrays in, job ids and per-task states out. It
//! knows nothing of stages; the executor decides what each task runs (docs/slurm.md).
//!
//! Every call is one of Slurm's commands run through `std::process::Command` (`sbatch`,
//! `sacct`, `squeue`, `scontrol`, `scancel`, `sacctmgr`); a command that is missing is a
//! [`UserError`] saying where they come from. Nothing keeps running on the login node:
//! [`Slurm::submit`] returns the job ids at once, [`Slurm::poll`] asks once, and
//! [`Slurm::wait`] (for `--wait`) polls with backoff.
//!
//! What this takes from the tools that learned it first:
//! - **One status query per poll for the whole run**, by job name: Snakemake's slurm executor
//!   plugin names every job after the run (`--job-name <run uuid>`) and asks
//!   `sacct -X --parsable2 --noheader --name <run> --starttime … --endtime now`, reading only
//!   the first word of `State` (`CANCELLED by 1000`). A job `sacct` does not list yet "probably
//!   didn't make it into slurmdbd yet" and stays active — here a task not seen yet is
//!   [`TaskState::Pending`], and one that drops out keeps its last state ([`RunStatus`]). The
//!   plugin also refuses `--job-name` among extra sbatch arguments, since the name is how it
//!   follows jobs ([`ExecutorOptions::check`] refuses every argument the client sets), and backs
//!   off between status checks when nothing finished (here ×1.5 up to a ceiling, back to the
//!   start when something changed).
//! - **Without accounting, `squeue -t all`**: Nextflow's slurm executor asks
//!   `squeue --noheader -o '%i %t' -t all` once for all its jobs, and maps the state codes
//!   (`CA`, `F`, `TO`, `NF`, `PR`, `BF` are errors; `CF` pending; `CG` running); `-t all` still
//!   shows finished jobs until slurmctld forgets them after `MinJobAge` (which the Snakemake
//!   plugin reads from `scontrol show config` to decide whether `squeue` can replace `sacct`).
//!   Past that, the job-completion file (`jobcomp/filetxt`), when the cluster writes one this
//!   process can read. `scontrol show job` gives the same records as `squeue -t all` at one
//!   RPC per job, so it is not used for polling. Nextflow also submits `--no-requeue` by
//!   default (a requeued task would rerun into its earlier output): so does this client, unless
//!   `requeue` is asked for.
//! - **State classes** after scalableminds' cluster_tools (`SLURM_STATES`): failures
//!   (CANCELLED, BOOT_FAIL, DEADLINE, FAILED, NODE_FAIL, OUT_OF_MEMORY, PREEMPTED, STOPPED,
//!   TIMEOUT), success (COMPLETED), still going (PENDING, RUNNING, CONFIGURING, COMPLETING,
//!   REQUEUED, …) and unclear states it keeps waiting on (here [`TaskState::Other`], not terminal).
//!   cluster_tools submits arrays as `--array=0-{n-1}` from a generated script with `--parsable`
//!   and reads the integer id; here the script goes to `sbatch` on standard input, so no
//!   temporary script file is left on the shared file system.
//! - **Dependencies that can never be met** leave jobs pending for ever
//!   (`Reason=DependencyNeverSatisfied`) unless `--kill-on-invalid-dep=yes` (every array is
//!   submitted with it); sites where it is not honoured (desihub/desispec#2658, #2682) still
//!   show such tasks pending, which [`status::parse_status_lines`] counts as cancelled.
//!
//! Measured on the test Slurm (22.05.8): `aftercorr` on an array that lacks the dependent
//! task's index makes that task wait for the whole earlier array, and cancels it when any task
//! there fails — hence the counterpart rule of [`array::plan_parts`].

pub mod allocation;
pub mod array;
pub mod limits;
pub mod options;
pub mod status;

pub use allocation::Allocation;
pub use array::{ArrayJob, ArrayPart, DepKind, Dependency, JobId, PartPlan, SubmittedArray};
pub use limits::ClusterLimits;
pub use options::{ExecutorFlags, ExecutorOptions, OptionError};
pub use status::{RunStatus, TaskState};

use crate::error::UserError;
use std::collections::BTreeSet;
use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// The client. `Slurm::new()` uses the environment as it is (the cluster's `slurm.conf`);
/// [`Slurm::with_conf`] points every command at another one (`SLURM_CONF`), as the tests do.
#[derive(Debug, Clone, Default)]
pub struct Slurm {
    conf: Option<PathBuf>,
}

/// How [`Slurm::wait`] spaces its polls: `first`, then ×`factor` while nothing changes, at most
/// `max`; back to `first` when a task changed state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Backoff {
    pub first: Duration,
    pub max: Duration,
    pub factor: f64,
}

impl Default for Backoff {
    /// 5 s, growing to one query a minute: a few hundred queries for a day-long run.
    fn default() -> Self {
        Backoff { first: Duration::from_secs(5), max: Duration::from_secs(60), factor: 1.5 }
    }
}

/// How many failed status queries in a row [`Slurm::wait`] tolerates (slurmctld busy or
/// restarting) before it gives up.
const QUERY_FAILURES_TOLERATED: u32 = 5;

/// A Slurm command that ran and failed: its standard error (its exit status when that is empty),
/// which the caller words into a [`UserError`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
struct Failed(String);

impl Slurm {
    pub fn new() -> Slurm {
        Slurm { conf: None }
    }

    pub fn with_conf(conf: impl Into<PathBuf>) -> Slurm {
        Slurm { conf: Some(conf.into()) }
    }

    /// Runs `program args…` (with `stdin` on its standard input); its standard output, or its
    /// standard error as the error when it failed.
    fn run(&self, program: &str, args: &[String], stdin: Option<&str>) -> Result<Result<String, Failed>, UserError> {
        let mut command = Command::new(program);
        command.args(args).stdin(if stdin.is_some() { Stdio::piped() } else { Stdio::null() });
        command.stdout(Stdio::piped()).stderr(Stdio::piped());
        if let Some(conf) = &self.conf {
            command.env("SLURM_CONF", conf);
        }
        let mut child = command.spawn().map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                UserError::new(format!("`{program}` was not found: the Slurm executor runs Slurm's commands"))
                    .hint("run on a login node of a Slurm cluster (on some, `module load slurm` first), or use the local executor")
            } else {
                UserError::new(format!("cannot run `{program}`: {e}"))
            }
        })?;
        if let Some(text) = stdin {
            let mut pipe = child.stdin.take().expect("stdin is piped");
            pipe.write_all(text.as_bytes()).map_err(|e| UserError::new(format!("cannot write to `{program}`: {e}")))?;
        }
        let out = child.wait_with_output().map_err(|e| UserError::new(format!("`{program}` did not finish: {e}")))?;
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        let stderr = String::from_utf8_lossy(&out.stderr).trim().to_string();
        Ok(if out.status.success() {
            Ok(stdout)
        } else {
            Err(Failed(if stderr.is_empty() { out.status.to_string() } else { stderr }))
        })
    }

    /// The cluster's limits (`scontrol show config`), with the user's submit limit where
    /// `sacctmgr` tells it (absent, or without a database: no limit known).
    pub fn limits(&self) -> Result<ClusterLimits, UserError> {
        let config = self.run("scontrol", &["show".into(), "config".into()], None)?.map_err(|e| {
            UserError::new(format!("`scontrol show config` failed: {e}"))
                .hint("is the Slurm controller reachable from here? (`scontrol ping`)")
        })?;
        let mut limits = ClusterLimits::from_config(&config);
        if limits.jobcomp_file.as_ref().is_some_and(|f| std::fs::File::open(f).is_err()) {
            limits.jobcomp_file = None;
        }
        if let Some(user) = std::env::var("USER").ok().filter(|u| !u.is_empty()) {
            let args =
                ["-n", "-P", "show", "assoc", "where", &format!("user={user}"), "format=MaxSubmit"].map(String::from);
            // sacctmgr may be missing or have no database to ask: then the limit is unknown.
            if let Ok(Ok(text)) = self.run("sacctmgr", &args, None) {
                limits.max_submit_jobs = ClusterLimits::parse_max_submit(&text);
            }
        }
        Ok(limits)
    }

    /// Submits `job` (split into parts below `MaxArraySize`, see [`array::plan_parts`]).
    /// Creates `job.log_dir`. When a part is refused, the parts already submitted are cancelled.
    pub fn submit(&self, job: &ArrayJob, limits: &ClusterLimits) -> Result<SubmittedArray, UserError> {
        job.options.check().map_err(|e| e.error)?;
        let plans = array::plan_parts(job, limits.max_array_size)?;
        let n: usize = plans.iter().map(|p| p.tasks.len()).sum();
        if n > limits.task_budget() as usize {
            return Err(UserError::new(format!(
                "job array `{}` has {n} tasks; this cluster takes at most {} jobs from you at once (MaxJobCount / MaxSubmitJobs)",
                job.name,
                limits.task_budget()
            ))
            .hint("pack more work units into each task (larger shards)"));
        }
        std::fs::create_dir_all(&job.log_dir).map_err(|e| {
            UserError::new(format!("cannot create the Slurm log folder `{}`: {e}", job.log_dir.display()))
        })?;
        let submitted_unix_s = SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
        let requeue = job.options.requeue == Some(true);
        let mut parts: Vec<ArrayPart> = Vec::new();
        for plan in plans {
            match self.sbatch(&plan) {
                Ok(job_id) => parts.push(ArrayPart { job_id, offset: plan.offset, tasks: plan.tasks }),
                Err(e) => {
                    let submitted = SubmittedArray {
                        name: job.name.clone(),
                        n_tasks: job.n_tasks,
                        parts,
                        submitted_unix_s,
                        requeue,
                    };
                    // Best effort: the refusal is the error to report.
                    let _ = self.cancel(&[submitted]);
                    return Err(e);
                }
            }
        }
        Ok(SubmittedArray { name: job.name.clone(), n_tasks: job.n_tasks, parts, submitted_unix_s, requeue })
    }

    fn sbatch(&self, plan: &PartPlan) -> Result<JobId, UserError> {
        let out = self.run("sbatch", &plan.args, Some(&plan.script))?.map_err(|e| {
            UserError::new(format!("sbatch refused the job array: {e}"))
                .hint(format!("the command was `sbatch {}` (script on standard input)", plan.args.join(" ")))
        })?;
        // `--parsable`: `<id>` or `<id>;<cluster>`.
        let first = out.lines().map(str::trim).find(|l| !l.is_empty()).unwrap_or("");
        first
            .split(';')
            .next()
            .and_then(|id| id.parse().ok())
            .map(JobId)
            .ok_or_else(|| UserError::new(format!("sbatch printed `{}` where a job id was expected", out.trim())))
    }

    /// One status query for every array of `status` (`sacct`, or without accounting `squeue`
    /// and the job-completion file); returns whether any task changed state.
    pub fn poll(&self, status: &mut RunStatus, limits: &ClusterLimits) -> Result<bool, UserError> {
        let names: BTreeSet<&str> = status.arrays.iter().map(|a| a.name.as_str()).collect();
        let names = names.into_iter().collect::<Vec<_>>().join(",");
        if status.arrays.is_empty() {
            return Ok(false);
        }
        if limits.accounting {
            let since = status.arrays.iter().map(|a| a.submitted_unix_s).min().unwrap_or(0);
            let now = SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
            let args = sacct_args(&names, now.saturating_sub(since));
            match self.run("sacct", &args, None)? {
                Ok(text) => return Ok(status.apply(&status::parse_status_lines(&text))),
                Err(e) if e.0.contains("accounting storage is disabled") => {}
                Err(e) => return Err(UserError::new(format!("`sacct` failed: {e}"))),
            }
        }
        let text = self
            .run("squeue", &squeue_args(&names), None)?
            .map_err(|e| UserError::new(format!("`squeue` failed: {e}")))?;
        let observations = status::parse_status_lines(&text);
        let mut changed = false;
        if let Some(file) = &limits.jobcomp_file {
            if status_misses_some(status, &observations) {
                // Older than the queue: read first, so what squeue says wins.
                if let Ok(text) = std::fs::read_to_string(file) {
                    changed |= status.apply(&status::parse_jobcomp(&text));
                }
            }
        }
        changed |= status.apply(&observations);
        Ok(changed)
    }

    /// Polls until every task has ended, calling `progress` after each poll that changed
    /// something. Tolerates a few failed queries in a row.
    pub fn wait(
        &self,
        status: &mut RunStatus,
        limits: &ClusterLimits,
        backoff: Backoff,
        mut progress: impl FnMut(&RunStatus),
    ) -> Result<(), UserError> {
        let mut delay = backoff.first;
        let mut failures = 0;
        loop {
            match self.poll(status, limits) {
                Ok(changed) => {
                    failures = 0;
                    if changed {
                        progress(status);
                        delay = backoff.first;
                    } else {
                        delay = delay.mul_f64(backoff.factor).min(backoff.max);
                    }
                }
                Err(e) => {
                    failures += 1;
                    if failures > QUERY_FAILURES_TOLERATED {
                        return Err(e);
                    }
                }
            }
            if status.all_terminal() {
                return Ok(());
            }
            std::thread::sleep(delay);
        }
    }

    /// Cancels every task of these arrays (`scancel`); tasks that already ended are no error.
    pub fn cancel(&self, arrays: &[SubmittedArray]) -> Result<(), UserError> {
        let ids: Vec<String> = arrays.iter().flat_map(|a| a.parts.iter().map(|p| p.job_id.to_string())).collect();
        self.scancel(ids)
    }

    /// Cancels task `task` (a global index) of `array`.
    pub fn cancel_task(&self, array: &SubmittedArray, task: u32) -> Result<(), UserError> {
        let (part, index) = array
            .locate(task)
            .ok_or_else(|| UserError::new(format!("job array `{}` has no submitted task {task}", array.name)))?;
        self.scancel(vec![format!("{}_{index}", part.job_id)])
    }

    fn scancel(&self, ids: Vec<String>) -> Result<(), UserError> {
        if ids.is_empty() {
            return Ok(());
        }
        match self.run("scancel", &ids, None)? {
            Ok(_) => Ok(()),
            Err(e) if e.0.contains("already completing or completed") || e.0.contains("Invalid job id") => Ok(()),
            Err(e) => Err(UserError::new(format!("`scancel {}` failed: {e}", ids.join(" ")))),
        }
    }
}

/// `sacct` for the jobs named `names` (comma-separated) submitted `age_s` seconds ago: one line
/// `JobID|State` per array task (a pending array as one line `id_[a-b%t]`), from an hour before
/// submission (clocks of this node and the controller may disagree) until now.
fn sacct_args(names: &str, age_s: u64) -> Vec<String> {
    vec![
        format!("--name={names}"),
        "-X".into(),
        "--parsable2".into(),
        "--noheader".into(),
        "--format=JobID,State".into(),
        format!("--starttime=now-{}", age_s + 3600),
        "--endtime=now".into(),
    ]
}

/// `squeue` for the jobs named `names`: every state (`-t all`: finished tasks until
/// `MinJobAge`), one line `JobID|State|Reason` per array task (`-r`), no header.
fn squeue_args(names: &str) -> Vec<String> {
    [&format!("--name={names}"), "-h", "-r", "-t", "all", "-o", "%i|%T|%r"].map(|s| s.to_string()).to_vec()
}

/// Some unfinished task of `status` is not among `observations` (slurmctld forgot it).
fn status_misses_some(status: &RunStatus, observations: &[status::Observation]) -> bool {
    let seen: BTreeSet<(u64, u32)> =
        observations.iter().flat_map(|o| o.indices.iter().map(move |&i| (o.array_job, i))).collect();
    status.arrays.iter().zip(&status.states).any(|(array, states)| {
        array.parts.iter().any(|p| {
            p.tasks.iter().any(|&t| !states[&t].is_final(array.requeue) && !seen.contains(&(p.job_id.0, t - p.offset)))
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_queries_ask_once_for_every_array_of_the_run() {
        assert_eq!(
            sacct_args("run-1,run-2", 600),
            [
                "--name=run-1,run-2",
                "-X",
                "--parsable2",
                "--noheader",
                "--format=JobID,State",
                "--starttime=now-4200",
                "--endtime=now"
            ]
        );
        assert_eq!(squeue_args("run-1"), ["--name=run-1", "-h", "-r", "-t", "all", "-o", "%i|%T|%r"]);
    }

    #[test]
    fn a_missing_command_is_a_user_error_saying_where_slurm_comes_from() {
        let e = Slurm::new().run("shakeflow-no-such-sbatch", &[], None).unwrap_err();
        assert!(e.message.contains("`shakeflow-no-such-sbatch` was not found"), "{e}");
        assert!(e.hint.as_deref().is_some_and(|h| h.contains("login node")), "{e}");
    }

    #[test]
    fn commands_get_stdin_and_report_stderr_and_slurm_conf() {
        let slurm = Slurm::with_conf("/x/slurm.conf");
        let echo = |script: &str, stdin| slurm.run("sh", &["-c".to_string(), script.to_string()], stdin).unwrap();
        assert_eq!(echo("cat; echo \" $SLURM_CONF\"", Some("script")), Ok("script /x/slurm.conf\n".to_string()));
        assert_eq!(echo("echo oops >&2; exit 3", None), Err(Failed("oops".to_string())));
        assert_eq!(echo("echo oops >&2; exit 3", None).unwrap_err().to_string(), "oops");
        assert_eq!(echo("exit 3", None).unwrap_err().to_string(), "exit status: 3");
    }
}
