//! The Slurm client against the real test Slurm of `tests/system/slurm.sh`: job arrays
//! with a throttle, aftercorr chains, failures and cancellations seen per task, split arrays.
//! Each test names its jobs after itself, so they run side by side.

use crate::common::test_slurm;
use shakeflow::pipeline::slurm::{
    ArrayJob, Backoff, ClusterLimits, DepKind, Dependency, ExecutorOptions, RunStatus, Slurm, SubmittedArray, TaskState,
};
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

fn job(name: &str, dir: &Path, n_tasks: u32, command: String) -> ArrayJob {
    ArrayJob {
        name: name.into(),
        command,
        n_tasks,
        only: None,
        dependencies: vec![],
        options: ExecutorOptions::default(),
        log_dir: dir.join("logs"),
    }
}

fn fast() -> Backoff {
    Backoff { first: Duration::from_millis(200), max: Duration::from_secs(2), factor: 1.5 }
}

/// Waits for `arrays` and returns each array's task states.
fn wait(slurm: &Slurm, limits: &ClusterLimits, arrays: &[SubmittedArray]) -> Vec<BTreeMap<u32, TaskState>> {
    let mut status = RunStatus::new(arrays);
    slurm.wait(&mut status, limits, fast(), |_| {}).unwrap();
    status.states
}

fn states(list: &[(u32, TaskState)]) -> BTreeMap<u32, TaskState> {
    list.iter().cloned().collect()
}

#[test]
fn the_limits_come_from_the_running_controller() {
    let limits = test_slurm().limits().unwrap();
    assert_eq!(limits.max_array_size, 1001);
    assert_eq!(limits.max_job_count, 10000);
    assert_eq!(limits.min_job_age_s, Some(3600));
    assert!(!limits.accounting, "the test Slurm has no slurmdbd");
    assert!(limits.jobcomp_file.as_ref().is_some_and(|f| f.ends_with("jobcomp.txt")), "{limits:?}");
    // No database: sacctmgr cannot tell a submit limit.
    assert_eq!(limits.max_submit_jobs, None);
}

#[test]
fn an_array_of_true_tasks_with_a_throttle_of_one_never_overlaps() {
    let slurm = test_slurm();
    let limits = slurm.limits().unwrap();
    let dir = crate::tempdir::tempdir().unwrap();
    let d = dir.path().display();
    // Each task notes how many tasks run beside it (itself included), then leaves.
    let command = format!(
        "mkdir -p {d}/running && touch {d}/running/$SLURM_ARRAY_TASK_ID && ls {d}/running | wc -l > {d}/seen_$SLURM_ARRAY_TASK_ID \
         && sleep 1 && rm {d}/running/$SLURM_ARRAY_TASK_ID && true"
    );
    let mut j = job("sf-throttle", dir.path(), 4, command);
    j.options.array_throttle = Some(1);
    let submitted = slurm.submit(&j, &limits).unwrap();
    assert_eq!(submitted.parts.len(), 1);
    let got = wait(&slurm, &limits, &[submitted]);
    assert_eq!(got[0], states(&[0, 1, 2, 3].map(|t| (t, TaskState::Completed))));
    for t in 0..4 {
        let seen = std::fs::read_to_string(dir.path().join(format!("seen_{t}"))).unwrap();
        assert_eq!(seen.trim(), "1", "task {t} ran beside another although the throttle is 1");
    }
    assert!(dir.path().join("logs").read_dir().unwrap().count() >= 4, "one log per task");
}

#[test]
fn a_failing_task_is_failed_and_its_siblings_complete() {
    let slurm = test_slurm();
    let limits = slurm.limits().unwrap();
    let dir = crate::tempdir::tempdir().unwrap();
    let submitted =
        slurm.submit(&job("sf-fail", dir.path(), 3, "[ $SLURM_ARRAY_TASK_ID != 1 ]".into()), &limits).unwrap();
    let got = wait(&slurm, &limits, std::slice::from_ref(&submitted));
    assert_eq!(got[0], states(&[(0, TaskState::Completed), (1, TaskState::Failed), (2, TaskState::Completed)]));
}

#[test]
fn an_aftercorr_chain_runs_task_i_after_task_i_and_cancels_after_a_failure() {
    let slurm = test_slurm();
    let limits = slurm.limits().unwrap();
    let dir = crate::tempdir::tempdir().unwrap();
    let d = dir.path().display();
    // Task 2 of the first array fails; the second array's task i checks that the first's task i wrote its file.
    let first = job(
        "sf-chain",
        dir.path(),
        4,
        format!("sleep 1; [ $SLURM_ARRAY_TASK_ID != 2 ] && touch {d}/a_$SLURM_ARRAY_TASK_ID"),
    );
    let first = slurm.submit(&first, &limits).unwrap();
    let mut second = job(
        "sf-chain",
        dir.path(),
        4,
        format!("test -f {d}/a_$SLURM_ARRAY_TASK_ID && touch {d}/b_$SLURM_ARRAY_TASK_ID"),
    );
    second.dependencies = vec![Dependency { on: first.clone(), kind: DepKind::AfterCorr }];
    let second = slurm.submit(&second, &limits).unwrap();
    let mut gather = job("sf-chain", dir.path(), 1, format!("touch {d}/gathered"));
    gather.dependencies = vec![Dependency { on: second.clone(), kind: DepKind::AfterOk }];
    let gather = slurm.submit(&gather, &limits).unwrap();
    // Status during the run: nothing has ended yet, or only some of it.
    let mut status = RunStatus::new(&[first.clone(), second.clone(), gather.clone()]);
    slurm.poll(&mut status, &limits).unwrap();
    assert!(status.unfinished() > 0);
    slurm.wait(&mut status, &limits, fast(), |_| {}).unwrap();
    use TaskState::*;
    assert_eq!(status.states[0], states(&[(0, Completed), (1, Completed), (2, Failed), (3, Completed)]));
    assert_eq!(status.states[1], states(&[(0, Completed), (1, Completed), (2, Cancelled), (3, Completed)]));
    // The gather waited for all of the second array, one of which never ran: never satisfied.
    assert_eq!(status.states[2], states(&[(0, Cancelled)]));
    for t in [0, 1, 3] {
        assert!(dir.path().join(format!("b_{t}")).is_file(), "task {t} of the second array ran after its counterpart");
    }
    assert!(!dir.path().join("b_2").exists() && !dir.path().join("gathered").exists());
}

#[test]
fn scancel_of_one_task_is_seen_as_cancelled() {
    let slurm = test_slurm();
    let limits = slurm.limits().unwrap();
    let dir = crate::tempdir::tempdir().unwrap();
    let d = dir.path().display();
    let command = format!("if [ $SLURM_ARRAY_TASK_ID = 1 ]; then touch {d}/started; sleep 600; fi");
    let submitted = slurm.submit(&job("sf-cancel", dir.path(), 3, command), &limits).unwrap();
    let mut status = RunStatus::new(std::slice::from_ref(&submitted));
    // Task 1 is cancelled while it runs.
    while status.states[0][&1] != TaskState::Running || !dir.path().join("started").exists() {
        std::thread::sleep(Duration::from_millis(200));
        slurm.poll(&mut status, &limits).unwrap();
        assert!(!status.states[0][&1].is_terminal(), "task 1 ended before it was cancelled: {:?}", status.states[0]);
    }
    slurm.cancel_task(&submitted, 1).unwrap();
    slurm.wait(&mut status, &limits, fast(), |_| {}).unwrap();
    assert_eq!(
        status.states[0],
        states(&[(0, TaskState::Completed), (1, TaskState::Cancelled), (2, TaskState::Completed)])
    );
    // Cancelling what already ended is no error.
    slurm.cancel(std::slice::from_ref(&submitted)).unwrap();
}

#[test]
fn an_array_split_beyond_max_array_size_runs_every_task_once_with_its_global_index() {
    let slurm = test_slurm();
    let real = slurm.limits().unwrap();
    let dir = crate::tempdir::tempdir().unwrap();
    let d = dir.path().display();
    // A lowered MaxArraySize (as on a cluster that sets it small): 7 tasks in parts of 3.
    let limits = ClusterLimits { max_array_size: 3, ..real.clone() };
    let first = slurm
        .submit(
            &job("sf-split", dir.path(), 7, format!("echo $SLURM_ARRAY_TASK_ID > {d}/t_$SLURM_ARRAY_TASK_ID")),
            &limits,
        )
        .unwrap();
    assert_eq!(first.parts.iter().map(|p| p.offset).collect::<Vec<_>>(), [0, 3, 6]);
    let mut second = job(
        "sf-split",
        dir.path(),
        7,
        format!("test -f {d}/t_$SLURM_ARRAY_TASK_ID && touch {d}/u_$SLURM_ARRAY_TASK_ID"),
    );
    second.dependencies = vec![Dependency { on: first.clone(), kind: DepKind::AfterCorr }];
    let second = slurm.submit(&second, &limits).unwrap();
    // The real limit (1001): tasks 0, 1001 and 1002 of 1003 go in two parts, indices 0 and 0-1.
    let mut sparse = job("sf-split", dir.path(), 1003, format!("touch {d}/v_$SLURM_ARRAY_TASK_ID"));
    sparse.only = Some([0, 1001, 1002].into_iter().collect());
    let sparse = slurm.submit(&sparse, &real).unwrap();
    assert_eq!(
        sparse.parts.iter().map(|p| (p.offset, p.tasks.clone())).collect::<Vec<_>>(),
        [(0, vec![0]), (1001, vec![1001, 1002])]
    );
    let got = wait(&slurm, &real, &[first, second, sparse]);
    assert!(got.iter().flat_map(|s| s.values()).all(|s| *s == TaskState::Completed), "{got:?}");
    for t in 0..7 {
        assert_eq!(std::fs::read_to_string(dir.path().join(format!("t_{t}"))).unwrap().trim(), t.to_string());
        assert!(dir.path().join(format!("u_{t}")).is_file());
    }
    let mut v: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("v_"))
        .collect();
    v.sort();
    assert_eq!(v, ["v_0", "v_1001", "v_1002"]);
}

#[test]
fn sbatch_refusing_a_job_is_a_user_error_naming_the_command() {
    let slurm = test_slurm();
    let limits = slurm.limits().unwrap();
    let dir = crate::tempdir::tempdir().unwrap();
    let mut j = job("sf-refused", dir.path(), 2, "true".into());
    j.options.partition = Some("nosuchpartition".into());
    let e = slurm.submit(&j, &limits).unwrap_err();
    assert!(e.message.contains("sbatch refused the job array") && e.message.contains("invalid partition"), "{e}");
    assert!(e.hint.as_deref().is_some_and(|h| h.contains("--partition=nosuchpartition")), "{e}");
}

#[test]
fn tasks_the_queue_no_longer_shows_are_read_from_the_job_completion_file() {
    let slurm = test_slurm();
    let limits = slurm.limits().unwrap();
    let dir = crate::tempdir::tempdir().unwrap();
    let submitted =
        slurm.submit(&job("sf-jobcomp", dir.path(), 2, "[ $SLURM_ARRAY_TASK_ID = 0 ]".into()), &limits).unwrap();
    let done = wait(&slurm, &limits, std::slice::from_ref(&submitted));
    assert_eq!(done[0], states(&[(0, TaskState::Completed), (1, TaskState::Failed)]));
    // The same jobs under a name squeue does not know: as when slurmctld has forgotten them
    // (MinJobAge). Only the job-completion file can tell.
    let forgotten = SubmittedArray { name: "sf-jobcomp-forgotten".into(), ..submitted };
    let mut status = RunStatus::new(std::slice::from_ref(&forgotten));
    assert!(slurm.poll(&mut status, &limits).unwrap());
    assert_eq!(status.states[0], done[0]);
    // Without that file the tasks stay as last seen: pending, never lost.
    let mut status = RunStatus::new(&[forgotten]);
    let no_file = ClusterLimits { jobcomp_file: None, ..limits };
    assert!(!slurm.poll(&mut status, &no_file).unwrap());
    assert_eq!(status.states[0], states(&[(0, TaskState::Pending), (1, TaskState::Pending)]));
}
