//! Job arrays: what to submit, how one array is split into parts that respect `MaxArraySize`,
//! and the exact `sbatch` command line and batch script of each part.

use super::options::ExecutorOptions;
use crate::error::UserError;
use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;
use std::fmt;
use std::path::PathBuf;

/// A Slurm job id as `sbatch --parsable` prints it (an array's id: its tasks are `<id>_<index>`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct JobId(pub u64);

impl fmt::Display for JobId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

/// How a job array waits for an earlier one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum DepKind {
    /// Task i starts once task i of the earlier array completed successfully
    /// (`aftercorr`; per-record stages over the same shards).
    AfterCorr,
    /// The array starts once every task of the earlier one completed successfully (`afterok`;
    /// a gathering stage after per-record ones).
    AfterOk,
    /// The array starts once every task of the earlier one ended, however (`afterany`; the
    /// final commit job, which commits what succeeded).
    AfterAny,
}

impl DepKind {
    fn slurm_name(self) -> &'static str {
        match self {
            DepKind::AfterCorr => "aftercorr",
            DepKind::AfterOk => "afterok",
            DepKind::AfterAny => "afterany",
        }
    }
}

/// One dependency of an array: on an array submitted earlier (by this client, in this run).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Dependency {
    pub on: SubmittedArray,
    pub kind: DepKind,
}

/// A job array to submit: `n_tasks` tasks, each running `command` with `$SLURM_ARRAY_TASK_ID`
/// set to its index (0 ≤ index < `n_tasks`, whatever part of a split array it runs in).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ArrayJob {
    /// The Slurm job name (`--job-name`). Give every array of one run the run's name: one
    /// `sacct --name` query then follows the whole run. `[A-Za-z0-9_.-]`, at most 64 characters.
    pub name: String,
    /// The shell command line (bash) each task runs.
    pub command: String,
    /// How many tasks the array has (indices `0..n_tasks`).
    pub n_tasks: u32,
    /// Only these task indices are submitted (e.g. the shards a rerun still misses); `None`: all.
    pub only: Option<BTreeSet<u32>>,
    pub dependencies: Vec<Dependency>,
    pub options: ExecutorOptions,
    /// Where each task's output goes: `<log_dir>/<name>_<array job id>_<array index>.out`
    /// (stdout and stderr together). Must be on a file system the compute nodes share.
    pub log_dir: PathBuf,
}

/// A submitted array: its parts, each a Slurm job array of its own.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SubmittedArray {
    pub name: String,
    pub n_tasks: u32,
    pub parts: Vec<ArrayPart>,
    /// When it was submitted (seconds since the Unix epoch): `sacct` is asked from then on.
    pub submitted_unix_s: u64,
    /// Submitted with `--requeue`: a preempted or node-failed task may come back as pending.
    pub requeue: bool,
}

/// One Slurm job array of a split array: its array index `i` runs task `offset + i`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ArrayPart {
    pub job_id: JobId,
    pub offset: u32,
    /// The tasks (global indices) this part runs, ascending.
    pub tasks: Vec<u32>,
}

impl SubmittedArray {
    /// The part running task `task` and its Slurm array index there.
    pub fn locate(&self, task: u32) -> Option<(&ArrayPart, u32)> {
        self.parts.iter().find(|p| p.tasks.binary_search(&task).is_ok()).map(|p| (p, task - p.offset))
    }

    /// Every submitted task (global indices), ascending.
    pub fn tasks(&self) -> impl Iterator<Item = u32> + '_ {
        self.parts.iter().flat_map(|p| p.tasks.iter().copied())
    }
}

/// A part before submission: the tasks of one `offset` block, with their sbatch arguments.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PartPlan {
    pub offset: u32,
    pub tasks: Vec<u32>,
    /// `sbatch` arguments (the batch script comes on standard input).
    pub args: Vec<String>,
    pub script: String,
}

/// Splits `job` into parts of at most `max_array_size` indices (Slurm's array indices must be
/// below `MaxArraySize`): part k holds tasks `k·M … (k+1)·M − 1` as array indices `0 … M − 1`,
/// its script adding `k·M` back. Blocks without a task to run are not submitted.
///
/// Dependencies: `afterok`/`afterany` wait for every part of the earlier array. `aftercorr` is
/// per index, so it only means "task i after task i" when both arrays are split at the same
/// boundaries: part k waits on the earlier array's part with the same offset. Slurm treats a
/// task whose index the earlier array lacks as waiting for that whole array (measured on
/// Slurm 22.05: such a task was cancelled when another task of the earlier array failed), so
/// every task must have its counterpart: this is refused otherwise. (Resubmit the earlier
/// array's counterparts too — their work units are cached and finish at once.)
///
/// The throttle is shared: with P parts each gets `max(1, throttle / P)`, so no more than the
/// throttle runs at once unless there are more parts than the throttle allows.
pub fn plan_parts(job: &ArrayJob, max_array_size: u32) -> Result<Vec<PartPlan>, UserError> {
    check_name(&job.name)?;
    if job.n_tasks == 0 {
        return Err(UserError::new(format!("job array `{}` has no tasks", job.name)));
    }
    if max_array_size < 2 {
        return Err(UserError::new(format!("MaxArraySize is {max_array_size}: this cluster allows no job arrays"))
            .hint("ask the cluster's administrators, or use the local executor"));
    }
    if let Some(only) = &job.only {
        if let Some(&t) = only.iter().find(|&&t| t >= job.n_tasks) {
            return Err(UserError::new(format!("job array `{}`: task {t} is outside 0..{}", job.name, job.n_tasks)));
        }
    }
    let m = max_array_size; // indices 0..m-1 per part
    let mut blocks: Vec<(u32, Vec<u32>)> = Vec::new();
    let wanted = |t: &u32| job.only.as_ref().is_none_or(|o| o.contains(t));
    let mut offset = 0u32;
    while offset < job.n_tasks {
        let end = offset.saturating_add(m).min(job.n_tasks);
        let tasks: Vec<u32> = (offset..end).filter(wanted).collect();
        if !tasks.is_empty() {
            blocks.push((offset, tasks));
        }
        offset = end;
    }
    if blocks.is_empty() {
        return Err(UserError::new(format!("job array `{}`: no task to submit", job.name)));
    }
    let throttle = job.options.array_throttle.map(|t| (t / blocks.len() as u32).max(1));
    blocks
        .into_iter()
        .map(|(offset, tasks)| {
            let dependency = dependency_arg(job, offset, &tasks)?;
            let mut args = vec![
                "--parsable".to_string(),
                format!("--job-name={}", job.name),
                format!(
                    "--array={}{}",
                    index_list(&tasks, offset),
                    throttle.map(|t| format!("%{t}")).unwrap_or_default()
                ),
                "--kill-on-invalid-dep=yes".to_string(),
                format!("--output={}/%x_%A_%a.out", job.log_dir.display()),
            ];
            if let Some(d) = dependency {
                args.push(format!("--dependency={d}"));
            }
            let o = &job.options;
            for (flag, value) in
                [("--partition", &o.partition), ("--account", &o.account), ("--time", &o.time_limit), ("--mem", &o.mem)]
            {
                if let Some(v) = value {
                    args.push(format!("{flag}={v}"));
                }
            }
            if let Some(c) = o.cpus_per_task {
                args.push(format!("--cpus-per-task={c}"));
            }
            args.push(if o.requeue == Some(true) { "--requeue" } else { "--no-requeue" }.to_string());
            args.extend(o.sbatch_args.iter().cloned());
            Ok(PartPlan { offset, script: batch_script(job, offset, &tasks), tasks, args })
        })
        .collect()
}

/// `--dependency=` of the part at `offset` (conditions joined by `,`: all must hold).
fn dependency_arg(job: &ArrayJob, offset: u32, tasks: &[u32]) -> Result<Option<String>, UserError> {
    let mut conditions = Vec::new();
    for dep in &job.dependencies {
        let ids: Vec<String> = match dep.kind {
            DepKind::AfterOk | DepKind::AfterAny => dep.on.parts.iter().map(|p| p.job_id.to_string()).collect(),
            DepKind::AfterCorr => {
                let counterpart = dep.on.parts.iter().find(|p| p.offset == offset);
                let missing = match counterpart {
                    Some(p) => tasks.iter().find(|t| p.tasks.binary_search(t).is_err()),
                    None => tasks.first(),
                };
                if let Some(t) = missing {
                    return Err(UserError::new(format!(
                        "job array `{}`: task {t} would wait (aftercorr) for task {t} of the earlier array, which was not submitted",
                        job.name
                    ))
                    .hint("submit the earlier array's counterparts of every task (finished ones are cached), or depend with afterok"));
                }
                counterpart.map(|p| p.job_id.to_string()).into_iter().collect()
            }
        };
        if !ids.is_empty() {
            conditions.push(format!("{}:{}", dep.kind.slurm_name(), ids.join(":")));
        }
    }
    Ok((!conditions.is_empty()).then(|| conditions.join(",")))
}

/// Array indices `tasks − offset` as Slurm's list of ranges: `0-3,7,9-12`.
fn index_list(tasks: &[u32], offset: u32) -> String {
    let mut out: Vec<String> = Vec::new();
    let mut i = 0;
    while i < tasks.len() {
        let mut j = i;
        while j + 1 < tasks.len() && tasks[j + 1] == tasks[j] + 1 {
            j += 1;
        }
        let (a, b) = (tasks[i] - offset, tasks[j] - offset);
        out.push(if a == b { a.to_string() } else { format!("{a}-{b}") });
        i = j + 1;
    }
    out.join(",")
}

fn batch_script(job: &ArrayJob, offset: u32, tasks: &[u32]) -> String {
    let mut s = String::from("#!/bin/bash\n");
    s.push_str(&format!(
        "# Written by shakeflow: job array `{}`, tasks {}..={} of {} (array index + {offset}).\n",
        job.name,
        tasks[0],
        tasks[tasks.len() - 1],
        job.n_tasks
    ));
    s.push_str("set -eu\n");
    if offset > 0 {
        s.push_str(&format!("SLURM_ARRAY_TASK_ID=$((SLURM_ARRAY_TASK_ID + {offset}))\nexport SLURM_ARRAY_TASK_ID\n"));
    }
    s.push_str(&job.command);
    s.push('\n');
    s
}

/// Job names become `sacct --name` filters and log file names: a plain word.
fn check_name(name: &str) -> Result<(), UserError> {
    if name.is_empty()
        || name.len() > 64
        || !name.chars().all(|c| c.is_ascii_alphanumeric() || "_.-".contains(c))
        || name.starts_with(['-', '.'])
    {
        return Err(UserError::new(format!("`{name}` cannot be a Slurm job name"))
            .hint("use 1 to 64 of A-Z a-z 0-9 _ . - (not starting with - or .)"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(n_tasks: u32) -> ArrayJob {
        ArrayJob {
            name: "run-1".into(),
            command: "shakeflow shard plan.json $SLURM_ARRAY_TASK_ID".into(),
            n_tasks,
            only: None,
            dependencies: vec![],
            options: ExecutorOptions::default(),
            log_dir: PathBuf::from("/scratch/u/out/.shakeflow/slurm"),
        }
    }

    fn submitted(plans: &[PartPlan], first_id: u64) -> SubmittedArray {
        SubmittedArray {
            name: "run-1".into(),
            n_tasks: plans.iter().map(|p| p.tasks.len() as u32).sum(),
            parts: plans
                .iter()
                .enumerate()
                .map(|(i, p)| ArrayPart {
                    job_id: JobId(first_id + i as u64),
                    offset: p.offset,
                    tasks: p.tasks.clone(),
                })
                .collect(),
            submitted_unix_s: 0,
            requeue: false,
        }
    }

    #[test]
    fn one_part_with_every_option_in_order() {
        let mut j = job(10);
        j.options = ExecutorOptions {
            partition: Some("normal".into()),
            account: Some("DS-1".into()),
            time_limit: Some("02:00:00".into()),
            cpus_per_task: Some(8),
            mem: Some("16G".into()),
            array_throttle: Some(4),
            retries: Some(2),
            requeue: Some(true),
            sbatch_args: vec!["--qos=normal".into()],
            in_allocation: None,
        };
        let plans = plan_parts(&j, 1001).unwrap();
        assert_eq!(plans.len(), 1);
        assert_eq!(
            plans[0].args,
            [
                "--parsable",
                "--job-name=run-1",
                "--array=0-9%4",
                "--kill-on-invalid-dep=yes",
                "--output=/scratch/u/out/.shakeflow/slurm/%x_%A_%a.out",
                "--partition=normal",
                "--account=DS-1",
                "--time=02:00:00",
                "--mem=16G",
                "--cpus-per-task=8",
                "--requeue",
                "--qos=normal",
            ]
        );
        assert_eq!(
            plans[0].script,
            "#!/bin/bash\n# Written by shakeflow: job array `run-1`, tasks 0..=9 of 10 (array index + 0).\nset -eu\n\
             shakeflow shard plan.json $SLURM_ARRAY_TASK_ID\n"
        );
    }

    #[test]
    fn splits_at_max_array_size_and_shares_the_throttle() {
        let mut j = job(2500);
        j.options.array_throttle = Some(10);
        let plans = plan_parts(&j, 1001).unwrap();
        let arrays: Vec<&str> = plans.iter().map(|p| p.args[2].as_str()).collect();
        assert_eq!(arrays, ["--array=0-1000%3", "--array=0-1000%3", "--array=0-497%3"]);
        assert_eq!(plans.iter().map(|p| p.offset).collect::<Vec<_>>(), [0, 1001, 2002]);
        assert_eq!(plans[2].tasks.first(), Some(&2002));
        assert_eq!(plans[2].tasks.last(), Some(&2499));
        assert!(plans[1]
            .script
            .contains("SLURM_ARRAY_TASK_ID=$((SLURM_ARRAY_TASK_ID + 1001))\nexport SLURM_ARRAY_TASK_ID\n"));
        assert!(!plans[0].script.contains("SLURM_ARRAY_TASK_ID + "));
        assert!(plans.iter().all(|p| p.args.contains(&"--no-requeue".to_string())));
        // Exactly at the limit: one part.
        assert_eq!(plan_parts(&job(1001), 1001).unwrap().len(), 1);
        assert_eq!(plan_parts(&job(1002), 1001).unwrap().len(), 2);
    }

    #[test]
    fn a_subset_becomes_index_ranges_and_empty_blocks_are_skipped() {
        let mut j = job(12);
        j.only = Some([1, 2, 3, 7, 9, 10, 11].into_iter().collect());
        let plans = plan_parts(&j, 5).unwrap();
        let got: Vec<(u32, &str)> = plans.iter().map(|p| (p.offset, p.args[2].as_str())).collect();
        assert_eq!(got, [(0, "--array=1-3"), (5, "--array=2,4"), (10, "--array=0-1")]);
        j.only = Some([6].into_iter().collect());
        assert_eq!(plan_parts(&j, 5).unwrap().iter().map(|p| p.offset).collect::<Vec<_>>(), [5]);
        j.only = Some([12].into_iter().collect());
        assert!(plan_parts(&j, 5).unwrap_err().message.contains("task 12 is outside 0..12"));
    }

    #[test]
    fn dependencies_per_kind_across_split_arrays() {
        let first = submitted(&plan_parts(&job(7), 3).unwrap(), 100); // parts 100 (0-2), 101 (3-5), 102 (6)
        let mut j = job(7);
        j.dependencies = vec![
            Dependency { on: first.clone(), kind: DepKind::AfterCorr },
            Dependency { on: first.clone(), kind: DepKind::AfterOk },
        ];
        let plans = plan_parts(&j, 3).unwrap();
        let deps: Vec<&str> = plans.iter().map(|p| p.args[5].as_str()).collect();
        assert_eq!(
            deps,
            [
                "--dependency=aftercorr:100,afterok:100:101:102",
                "--dependency=aftercorr:101,afterok:100:101:102",
                "--dependency=aftercorr:102,afterok:100:101:102",
            ]
        );
        let mut gather = job(1);
        gather.dependencies = vec![Dependency { on: first.clone(), kind: DepKind::AfterAny }];
        assert_eq!(plan_parts(&gather, 3).unwrap()[0].args[5], "--dependency=afterany:100:101:102");
    }

    #[test]
    fn aftercorr_needs_every_counterpart() {
        let mut earlier = job(6);
        earlier.only = Some([1].into_iter().collect());
        let first = submitted(&plan_parts(&earlier, 1001).unwrap(), 7);
        let mut j = job(6);
        j.only = Some([1, 4].into_iter().collect());
        j.dependencies = vec![Dependency { on: first.clone(), kind: DepKind::AfterCorr }];
        let e = plan_parts(&j, 1001).unwrap_err();
        assert!(e.message.contains("task 4 would wait (aftercorr) for task 4"), "{e}");
        j.only = Some([1].into_iter().collect());
        assert_eq!(plan_parts(&j, 1001).unwrap()[0].args[5], "--dependency=aftercorr:7");
        // A dependent part whose block the earlier array did not submit at all is refused too.
        let mut later = job(6);
        later.only = Some([4].into_iter().collect());
        later.dependencies = vec![Dependency { on: first, kind: DepKind::AfterCorr }];
        assert!(plan_parts(&later, 3).is_err());
    }

    #[test]
    fn refuses_bad_names_and_empty_arrays() {
        let mut j = job(3);
        j.name = "my run".into();
        assert!(plan_parts(&j, 1001).unwrap_err().message.contains("cannot be a Slurm job name"));
        assert!(plan_parts(&job(0), 1001).unwrap_err().message.contains("has no tasks"));
        assert!(plan_parts(&job(3), 1).is_err());
    }

    #[test]
    fn locate_finds_the_part_and_array_index() {
        let s = submitted(&plan_parts(&job(7), 3).unwrap(), 100);
        assert_eq!(s.locate(4).map(|(p, i)| (p.job_id, i)), Some((JobId(101), 1)));
        assert_eq!(s.locate(7), None);
        assert_eq!(s.tasks().collect::<Vec<_>>(), (0..7).collect::<Vec<_>>());
    }
}
