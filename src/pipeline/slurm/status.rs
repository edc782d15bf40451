//! Task states: Slurm's words mapped per array task, the parsers of `sacct`, `squeue` and the
//! job-completion file, and [`RunStatus`], which remembers what earlier polls saw.

use super::array::SubmittedArray;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The state of one array task, as Slurm names it (sacct(1), "JOB STATE CODES").
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum TaskState {
    /// Queued, waiting for resources or a dependency — or not yet visible to the query
    /// (`sacct` lags behind slurmctld: a task not seen yet is pending, not lost).
    Pending,
    Running,
    Completed,
    /// Exited non-zero.
    Failed,
    /// `scancel`ed, or its dependency can never be satisfied (`--kill-on-invalid-dep`).
    Cancelled,
    Timeout,
    Preempted,
    NodeFail,
    OutOfMemory,
    /// A state this client does not know (kept verbatim; not terminal).
    Other(String),
}

impl TaskState {
    /// From Slurm's word: `sacct`'s State (which may read `CANCELLED by 1000`), `squeue`'s %T,
    /// or a job-completion record's JobState.
    pub fn from_slurm(word: &str) -> TaskState {
        let word = word.split_whitespace().next().unwrap_or("").trim_end_matches('+');
        match word {
            "PENDING" | "PD" | "REQUEUED" | "RQ" | "REQUEUE_HOLD" | "REQUEUE_FED" | "CONFIGURING" | "CF"
            | "RESV_DEL_HOLD" => TaskState::Pending,
            "RUNNING" | "R" | "COMPLETING" | "CG" | "SUSPENDED" | "S" | "STAGE_OUT" | "SO" | "SIGNALING"
            | "RESIZING" => TaskState::Running,
            "COMPLETED" | "CD" => TaskState::Completed,
            "FAILED" | "F" | "SPECIAL_EXIT" | "SE" => TaskState::Failed,
            "CANCELLED" | "CA" | "REVOKED" | "RV" | "STOPPED" | "ST" => TaskState::Cancelled,
            "TIMEOUT" | "TO" | "DEADLINE" | "DL" => TaskState::Timeout,
            "PREEMPTED" | "PR" => TaskState::Preempted,
            "NODE_FAIL" | "NF" | "BOOT_FAIL" | "BF" => TaskState::NodeFail,
            "OUT_OF_MEMORY" | "OOM" => TaskState::OutOfMemory,
            other => TaskState::Other(other.to_string()),
        }
    }

    /// Slurm will not run this task again (unless it was submitted with `--requeue`, which
    /// turns a preemption or node failure back into `Pending`).
    pub fn is_terminal(&self) -> bool {
        !matches!(self, TaskState::Pending | TaskState::Running | TaskState::Other(_))
    }

    /// [`TaskState::is_terminal`] for a task submitted with `--requeue` or not: Slurm puts a
    /// requeueable task that was preempted or lost its node back in the queue.
    pub fn is_final(&self, requeue: bool) -> bool {
        self.is_terminal() && !(requeue && matches!(self, TaskState::Preempted | TaskState::NodeFail))
    }

    pub fn is_success(&self) -> bool {
        *self == TaskState::Completed
    }
}

/// One line of status output: array job id, array index (or indices, for a pending array
/// shown as `123_[4-9%2]`), state.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Observation {
    pub array_job: u64,
    pub indices: Vec<u32>,
    pub state: TaskState,
}

/// `123_4`, `123_[4-9%2]`, `123_[1,3,5-7]` → (123, indices). Plain job ids (not an array task)
/// and job steps (`123_4.batch`) give `None`.
pub fn parse_task_id(id: &str) -> Option<(u64, Vec<u32>)> {
    let (job, task) = id.trim().split_once('_')?;
    let job: u64 = job.parse().ok()?;
    if let Some(list) = task.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
        let list = list.split('%').next()?;
        let mut indices = Vec::new();
        for item in list.split(',') {
            match item.split_once('-') {
                Some((a, b)) => {
                    let (a, b): (u32, u32) = (a.parse().ok()?, b.parse().ok()?);
                    if b < a {
                        return None;
                    }
                    indices.extend(a..=b);
                }
                None => indices.push(item.parse().ok()?),
            }
        }
        Some((job, indices))
    } else {
        Some((job, vec![task.parse().ok()?]))
    }
}

/// Lines `JobID|State` (sacct `--parsable2 --noheader --format=JobID,State`) or `%i|%T|%r`
/// (squeue; a pending task whose reason is `DependencyNeverSatisfied` counts as cancelled:
/// some sites do not honour `--kill-on-invalid-dep` and leave such tasks pending for ever).
pub fn parse_status_lines(text: &str) -> Vec<Observation> {
    text.lines()
        .filter_map(|line| {
            let mut fields = line.split('|');
            let (array_job, indices) = parse_task_id(fields.next()?)?;
            let mut state = TaskState::from_slurm(fields.next()?);
            if state == TaskState::Pending && fields.next().is_some_and(|r| r.trim() == "DependencyNeverSatisfied") {
                state = TaskState::Cancelled;
            }
            Some(Observation { array_job, indices, state })
        })
        .collect()
}

/// The job-completion file of `JobCompType=jobcomp/filetxt`: one `key=value …` line per
/// finished job; array tasks carry `ArrayJobId` and `ArrayTaskId`. A requeued task has several
/// lines: the last one counts.
pub fn parse_jobcomp(text: &str) -> Vec<Observation> {
    text.lines()
        .filter_map(|line| {
            let value = |key: &str| {
                line.split_whitespace().find_map(|kv| kv.strip_prefix(key).and_then(|v| v.strip_prefix('=')))
            };
            let array_job: u64 = value("ArrayJobId")?.parse().ok()?;
            let index: u32 = value("ArrayTaskId")?.parse().ok()?;
            Some(Observation { array_job, indices: vec![index], state: TaskState::from_slurm(value("JobState")?) })
        })
        .collect()
}

/// What is known about a run's arrays: per array (in the order given), per submitted task,
/// the last state seen. A task no query has shown yet is `Pending`; a task that drops out of
/// the queries (sacct lag, slurmctld forgetting finished jobs after `MinJobAge`) keeps the
/// last state seen.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RunStatus {
    pub arrays: Vec<SubmittedArray>,
    /// `states[a][task]`: array `a`'s task `task` (a global index; tasks not submitted are absent).
    pub states: Vec<BTreeMap<u32, TaskState>>,
}

impl RunStatus {
    pub fn new(arrays: &[SubmittedArray]) -> RunStatus {
        let states = arrays.iter().map(|a| a.tasks().map(|t| (t, TaskState::Pending)).collect()).collect();
        RunStatus { arrays: arrays.to_vec(), states }
    }

    /// Applies observations (of any jobs: those not of these arrays are ignored). Returns
    /// whether any task's state changed.
    pub fn apply(&mut self, observations: &[Observation]) -> bool {
        let mut changed = false;
        for o in observations {
            for (a, array) in self.arrays.iter().enumerate() {
                let Some(part) = array.parts.iter().find(|p| p.job_id.0 == o.array_job) else { continue };
                for &i in &o.indices {
                    let task = part.offset + i;
                    if let Some(state) = self.states[a].get_mut(&task) {
                        if *state != o.state {
                            *state = o.state.clone();
                            changed = true;
                        }
                    }
                }
            }
        }
        changed
    }

    /// Every submitted task has ended for good ([`TaskState::is_final`]).
    pub fn all_terminal(&self) -> bool {
        self.unfinished() == 0
    }

    /// Tasks that have not ended for good (pending, running, unknown; preempted or node-failed
    /// ones of arrays submitted with `--requeue`).
    pub fn unfinished(&self) -> usize {
        self.arrays.iter().zip(&self.states).map(|(a, s)| s.values().filter(|t| !t.is_final(a.requeue)).count()).sum()
    }

    /// The tasks of array `a` that ended for good without success, with their states.
    pub fn failed(&self, a: usize) -> Vec<(u32, TaskState)> {
        let requeue = self.arrays[a].requeue;
        self.states[a]
            .iter()
            .filter(|(_, s)| s.is_final(requeue) && !s.is_success())
            .map(|(&t, s)| (t, s.clone()))
            .collect()
    }

    /// How many tasks of array `a` are in each state, for progress lines (`Completed: 12, …`).
    pub fn counts(&self, a: usize) -> BTreeMap<String, usize> {
        let mut counts = BTreeMap::new();
        for s in self.states[a].values() {
            *counts.entry(format!("{s:?}")).or_default() += 1;
        }
        counts
    }
}

#[cfg(test)]
mod tests {
    use super::super::array::{ArrayPart, JobId};
    use super::*;

    #[test]
    fn maps_every_state_the_executor_acts_on() {
        use TaskState::*;
        for (word, state) in [
            ("PENDING", Pending),
            ("RUNNING", Running),
            ("COMPLETING", Running),
            ("COMPLETED", Completed),
            ("FAILED", Failed),
            ("CANCELLED by 0", Cancelled),
            ("CANCELLED+", Cancelled),
            ("TIMEOUT", Timeout),
            ("PREEMPTED", Preempted),
            ("NODE_FAIL", NodeFail),
            ("BOOT_FAIL", NodeFail),
            ("OUT_OF_MEMORY", OutOfMemory),
            ("REQUEUED", Pending),
            ("CD", Completed),
            ("F", Failed),
        ] {
            assert_eq!(TaskState::from_slurm(word), state, "{word}");
        }
        assert_eq!(TaskState::from_slurm("WEIRD"), Other("WEIRD".into()));
        assert!(!Other("WEIRD".into()).is_terminal());
        assert!(Preempted.is_terminal() && !Running.is_terminal() && Completed.is_success() && !Failed.is_success());
    }

    #[test]
    fn task_ids_of_tasks_ranges_and_lists() {
        assert_eq!(parse_task_id("123_4"), Some((123, vec![4])));
        assert_eq!(parse_task_id("123_[4-6%2]"), Some((123, vec![4, 5, 6])));
        assert_eq!(parse_task_id("123_[1,3,5-7]"), Some((123, vec![1, 3, 5, 6, 7])));
        assert_eq!(parse_task_id("123"), None);
        assert_eq!(parse_task_id("123_4.batch"), None);
        assert_eq!(parse_task_id("123_[6-4]"), None);
        assert_eq!(parse_task_id("x_1"), None);
    }

    #[test]
    fn sacct_and_squeue_lines() {
        // sacct -X --parsable2 --noheader --format=JobID,State (lines as Slurm 22.05 prints them).
        let sacct = "41_0|COMPLETED\n41_1|CANCELLED by 0\n41_[2-5%2]|PENDING\n40|COMPLETED\n";
        let o = parse_status_lines(sacct);
        assert_eq!(o.len(), 3);
        assert_eq!(o[1], Observation { array_job: 41, indices: vec![1], state: TaskState::Cancelled });
        assert_eq!(o[2].indices, [2, 3, 4, 5]);
        // squeue -h -r -t all -o '%i|%T|%r', as measured on the test Slurm.
        let squeue = "8_3|CANCELLED|DependencyNeverSatisfied\n9_1|PENDING|DependencyNeverSatisfied\n9_2|PENDING|Dependency\n7_3|FAILED|NonZeroExitCode\n";
        let states: Vec<TaskState> = parse_status_lines(squeue).into_iter().map(|o| o.state).collect();
        assert_eq!(states, [TaskState::Cancelled, TaskState::Cancelled, TaskState::Pending, TaskState::Failed]);
    }

    #[test]
    fn jobcomp_lines_last_one_wins() {
        // A line as the test Slurm's jobcomp/filetxt writes it (WorkDir may hold spaces).
        let text = "JobId=5 UserId=root(0) GroupId=root(0) Name=runx JobState=FAILED Partition=debug WorkDir=/tmp/a b \
                    ArrayJobId=1 ArrayTaskId=3 DerivedExitCode=0:0 ExitCode=1:0 \n\
                    JobId=9 Name=other JobState=COMPLETED\n";
        assert_eq!(parse_jobcomp(text), [Observation { array_job: 1, indices: vec![3], state: TaskState::Failed }]);
    }

    #[test]
    fn run_status_keeps_what_it_saw_and_maps_parts_to_global_tasks() {
        let array = SubmittedArray {
            name: "r".into(),
            n_tasks: 5,
            parts: vec![
                ArrayPart { job_id: JobId(10), offset: 0, tasks: vec![0, 1, 2] },
                ArrayPart { job_id: JobId(11), offset: 3, tasks: vec![3, 4] },
            ],
            submitted_unix_s: 0,
            requeue: false,
        };
        let mut status = RunStatus::new(&[array]);
        assert_eq!(status.unfinished(), 5);
        assert!(status.apply(&parse_status_lines("10_0|COMPLETED\n11_1|FAILED\n11_[0]|RUNNING\n99_0|FAILED\n")));
        assert_eq!(status.states[0][&0], TaskState::Completed);
        assert_eq!(status.states[0][&4], TaskState::Failed);
        assert_eq!(status.states[0][&3], TaskState::Running);
        // The next poll no longer lists task 0 (lag or MinJobAge): it stays completed.
        assert!(!status.apply(&parse_status_lines("11_0|RUNNING\n")));
        assert_eq!(status.states[0][&0], TaskState::Completed);
        assert_eq!(status.failed(0), [(4, TaskState::Failed)]);
        assert!(!status.all_terminal());
        status.apply(&parse_status_lines("10_[1-2]|COMPLETED\n11_0|COMPLETED\n"));
        assert!(status.all_terminal());
        assert_eq!(status.counts(0).get("Completed"), Some(&4));
    }

    #[test]
    fn a_requeueable_task_preempted_is_not_over() {
        let array = |requeue| SubmittedArray {
            name: "r".into(),
            n_tasks: 2,
            parts: vec![ArrayPart { job_id: JobId(10), offset: 0, tasks: vec![0, 1] }],
            submitted_unix_s: 0,
            requeue,
        };
        let lines = parse_status_lines("10_0|PREEMPTED\n10_1|NODE_FAIL\n");
        let mut plain = RunStatus::new(&[array(false)]);
        plain.apply(&lines);
        assert!(plain.all_terminal());
        assert_eq!(plain.failed(0).len(), 2);
        let mut requeued = RunStatus::new(&[array(true)]);
        requeued.apply(&lines);
        assert_eq!(requeued.unfinished(), 2);
        assert!(requeued.failed(0).is_empty());
        requeued.apply(&parse_status_lines("10_0|COMPLETED\n10_1|TIMEOUT\n"));
        assert!(requeued.all_terminal());
    }
}
