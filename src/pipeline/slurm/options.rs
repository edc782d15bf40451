//! What a user says about the cluster: the `executor:` block of a pipeline file and the command
//! line's flags, merged (flags win), checked before anything is submitted.

use crate::error::UserError;
use serde::{Deserialize, Serialize};

/// Slurm options for every job array of a run. Every field is optional: what is absent is left to
/// the cluster's defaults (its default partition, the account `sbatch` picks, the partition's
/// default time limit).
#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ExecutorOptions {
    /// `--partition` (TACC: `normal`, `development`, `skx`, …).
    #[serde(default)]
    pub partition: Option<String>,
    /// `--account` (TACC: the allocation's project name).
    #[serde(default)]
    pub account: Option<String>,
    /// `--time`, in Slurm's forms: `MM`, `MM:SS`, `HH:MM:SS`, `D-HH`, `D-HH:MM`, `D-HH:MM:SS`.
    #[serde(default)]
    pub time_limit: Option<String>,
    /// `--cpus-per-task` (the threads each array task runs its shard with).
    #[serde(default)]
    pub cpus_per_task: Option<u32>,
    /// `--mem` per node, e.g. `4G`, `16000M` (megabytes without a suffix).
    #[serde(default)]
    pub mem: Option<String>,
    /// At most this many tasks of one stage's array run at once (`--array=…%N`).
    #[serde(default)]
    pub array_throttle: Option<u32>,
    /// How many times the executor resubmits the tasks that failed (0: none): the commit job
    /// submits the failed shards and what depends on them again, with a new commit job.
    #[serde(default)]
    pub retries: Option<u32>,
    /// `--requeue`: Slurm puts a preempted or node-failed task back in the queue (default: `--no-requeue`).
    #[serde(default)]
    pub requeue: Option<bool>,
    /// Further `sbatch` arguments, each one word (`--qos=debug`, `--constraint=skx`).
    #[serde(default)]
    pub sbatch_args: Vec<String>,
    /// Run inside the current `sbatch`/`salloc` allocation: each shard an `srun` job step, no job
    /// arrays (a Tapis app's single job).
    #[serde(default)]
    pub in_allocation: Option<bool>,
}

/// An option that cannot be used: which key of the `executor:` block (or which flag) and why.
#[derive(Debug, Clone, PartialEq)]
pub struct OptionError {
    /// The key under `executor:` (the flag is `--` followed by the key with `-` for `_`).
    pub key: &'static str,
    pub error: UserError,
}

/// Arguments the client sets itself (job name, array, dependencies, log files): `sbatch_args` may
/// not set them, or status queries and dependencies would silently break (Snakemake's slurm plugin
/// refuses `--job-name` in `slurm_extra` for the same reason).
const RESERVED: [(&str, Option<&str>); 12] = [
    ("--job-name", Some("-J")),
    ("--array", Some("-a")),
    ("--dependency", Some("-d")),
    ("--output", Some("-o")),
    ("--error", Some("-e")),
    ("--parsable", None),
    ("--kill-on-invalid-dep", None),
    ("--wrap", None),
    ("--requeue", None),
    ("--no-requeue", None),
    ("--open-mode", None),
    ("--chdir", Some("-D")),
];

impl ExecutorOptions {
    /// These options overridden by `flags` (the command line): each flag given replaces the
    /// file's value; `sbatch_args` are the file's followed by the flags' (a later `sbatch`
    /// argument overrides an earlier one).
    pub fn merged_with(&self, flags: &ExecutorOptions) -> ExecutorOptions {
        let mut sbatch_args = self.sbatch_args.clone();
        sbatch_args.extend(flags.sbatch_args.iter().cloned());
        ExecutorOptions {
            partition: flags.partition.clone().or_else(|| self.partition.clone()),
            account: flags.account.clone().or_else(|| self.account.clone()),
            time_limit: flags.time_limit.clone().or_else(|| self.time_limit.clone()),
            cpus_per_task: flags.cpus_per_task.or(self.cpus_per_task),
            mem: flags.mem.clone().or_else(|| self.mem.clone()),
            array_throttle: flags.array_throttle.or(self.array_throttle),
            retries: flags.retries.or(self.retries),
            requeue: flags.requeue.or(self.requeue),
            sbatch_args,
            in_allocation: flags.in_allocation.or(self.in_allocation),
        }
    }

    /// Refuses what `sbatch` would refuse (or, worse, misread) before anything is submitted.
    pub fn check(&self) -> Result<(), OptionError> {
        let fail = |key: &'static str, message: String, hint: &str| {
            Err(OptionError { key, error: UserError::new(format!("executor option `{key}`: {message}")).hint(hint) })
        };
        for (key, value) in [("partition", &self.partition), ("account", &self.account)] {
            if let Some(v) = value {
                if v.is_empty() || !v.chars().all(|c| c.is_ascii_alphanumeric() || "_-.+".contains(c)) {
                    return fail(
                        key,
                        format!("`{v}` is not a Slurm {key} name"),
                        "see `sinfo -s` (partitions) or `sacctmgr show assoc user=$USER` (accounts)",
                    );
                }
            }
        }
        if let Some(t) = &self.time_limit {
            if !is_slurm_time(t) {
                return fail(
                    "time_limit",
                    format!("`{t}` is not a Slurm time limit"),
                    "write minutes (`90`), `HH:MM:SS` (`02:00:00`) or `D-HH:MM:SS` (`1-12:00:00`)",
                );
            }
        }
        if self.cpus_per_task == Some(0) {
            return fail(
                "cpus_per_task",
                "must be at least 1".into(),
                "give the CPUs each task runs on, e.g. `cpus_per_task: 8`",
            );
        }
        if let Some(m) = &self.mem {
            if !is_slurm_memory(m) {
                return fail(
                    "mem",
                    format!("`{m}` is not a Slurm memory size"),
                    "write megabytes (`16000`) or a number with K, M, G or T (`16G`)",
                );
            }
        }
        if self.array_throttle == Some(0) {
            return fail(
                "array_throttle",
                "must be at least 1".into(),
                "the number of tasks of one array that may run at once, e.g. `array_throttle: 50`",
            );
        }
        for arg in &self.sbatch_args {
            if let Some((long, _)) = RESERVED.iter().find(|(long, short)| {
                arg == long
                    || arg.starts_with(&format!("{long}="))
                    || short.is_some_and(|s| arg.starts_with(s) && !arg.starts_with("--"))
            }) {
                let hint = match *long {
                    "--requeue" | "--no-requeue" => "use the `requeue` option (`--requeue` flag) instead",
                    _ => "shakeflow sets it for every job array (job names, arrays, dependencies and logs are how it follows a run)",
                };
                return fail("sbatch_args", format!("`{arg}` may not be given: `{long}` is set by shakeflow"), hint);
            }
            if !arg.starts_with('-') {
                return fail(
                    "sbatch_args",
                    format!("`{arg}` is not an option"),
                    "give each sbatch option as one word with `=`, e.g. `--qos=debug`",
                );
            }
        }
        Ok(())
    }
}

/// Slurm's `--time` forms (sbatch(1)): `M`, `M:S`, `H:M:S`, `D-H`, `D-H:M`, `D-H:M:S`, or
/// `UNLIMITED`/`INFINITE`.
fn is_slurm_time(t: &str) -> bool {
    if t == "UNLIMITED" || t == "INFINITE" {
        return true;
    }
    let digits = |s: &str| !s.is_empty() && s.len() <= 6 && s.chars().all(|c| c.is_ascii_digit());
    let (days, rest) = match t.split_once('-') {
        Some((d, rest)) => (Some(d), rest),
        None => (None, t),
    };
    if days.is_some_and(|d| !digits(d)) {
        return false;
    }
    let parts: Vec<&str> = rest.split(':').collect();
    parts.len() <= 3 && parts.iter().all(|p| digits(p))
}

/// `--mem`: digits with an optional K, M, G or T suffix.
fn is_slurm_memory(m: &str) -> bool {
    let number = m.strip_suffix(['K', 'M', 'G', 'T']).unwrap_or(m);
    !number.is_empty() && number.chars().all(|c| c.is_ascii_digit()) && number != "0"
}

/// The command line's Slurm flags (`shakeflow run … --executor slurm --partition normal …`), to
/// `#[command(flatten)]` into a clap command; [`ExecutorFlags::options`] turns them into options
/// that override the pipeline file's `executor:` block.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ExecutorFlags {
    /// Slurm partition (overrides `executor.partition`).
    #[arg(long)]
    pub partition: Option<String>,
    /// Slurm account, e.g. a TACC allocation (overrides `executor.account`).
    #[arg(long)]
    pub account: Option<String>,
    /// Time limit of each array task, e.g. 02:00:00 (overrides `executor.time_limit`).
    #[arg(long = "time-limit")]
    pub time_limit: Option<String>,
    /// CPUs per array task (overrides `executor.cpus_per_task`).
    #[arg(long = "cpus-per-task")]
    pub cpus_per_task: Option<u32>,
    /// Memory per array task, e.g. 16G (overrides `executor.mem`).
    #[arg(long)]
    pub mem: Option<String>,
    /// At most this many tasks of one array at once (overrides `executor.array_throttle`).
    #[arg(long = "array-throttle")]
    pub array_throttle: Option<u32>,
    /// Resubmit failed tasks up to N times (overrides `executor.retries`).
    #[arg(long)]
    pub retries: Option<u32>,
    /// Let Slurm requeue preempted or node-failed tasks (overrides `executor.requeue`).
    #[arg(long)]
    pub requeue: bool,
    /// Run inside this sbatch/salloc allocation, each shard an srun job step (overrides
    /// `executor.in_allocation`).
    #[arg(long = "in-allocation")]
    pub in_allocation: bool,
    /// A further sbatch argument, one word (repeatable), e.g. --sbatch-arg=--qos=debug.
    #[arg(long = "sbatch-arg", allow_hyphen_values = true)]
    pub sbatch_args: Vec<String>,
}

impl ExecutorFlags {
    pub fn options(&self) -> ExecutorOptions {
        ExecutorOptions {
            partition: self.partition.clone(),
            account: self.account.clone(),
            time_limit: self.time_limit.clone(),
            cpus_per_task: self.cpus_per_task,
            mem: self.mem.clone(),
            array_throttle: self.array_throttle,
            retries: self.retries,
            requeue: self.requeue.then_some(true),
            sbatch_args: self.sbatch_args.clone(),
            in_allocation: self.in_allocation.then_some(true),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[test]
    fn the_executor_block_deserialises_and_refuses_unknown_keys() {
        let yaml = "partition: normal\naccount: DesignSafe-123\ntime_limit: \"02:00:00\"\ncpus_per_task: 8\nmem: 16G\n\
                    array_throttle: 50\nretries: 2\nrequeue: true\nsbatch_args: [--qos=normal, --constraint=skx]\n\
                    in_allocation: true\n";
        let o: ExecutorOptions = serde_yaml::from_str(yaml).unwrap();
        assert_eq!(o.partition.as_deref(), Some("normal"));
        assert_eq!(o.cpus_per_task, Some(8));
        assert_eq!(o.requeue, Some(true));
        assert_eq!(o.sbatch_args, ["--qos=normal", "--constraint=skx"]);
        assert_eq!(o.in_allocation, Some(true));
        assert_eq!(o.check(), Ok(()));
        let e = serde_yaml::from_str::<ExecutorOptions>("partiton: normal\n").unwrap_err().to_string();
        assert!(e.contains("unknown field `partiton`"), "{e}");
        assert_eq!(serde_yaml::from_str::<ExecutorOptions>("{}").unwrap(), ExecutorOptions::default());
    }

    #[test]
    fn flags_override_the_file_and_add_sbatch_args() {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            slurm: ExecutorFlags,
        }
        let cli = Cli::try_parse_from([
            "x",
            "--partition",
            "development",
            "--requeue",
            "--sbatch-arg=--qos=debug",
            "--in-allocation",
        ])
        .unwrap();
        let file = ExecutorOptions {
            partition: Some("normal".into()),
            account: Some("A-123".into()),
            requeue: Some(false),
            sbatch_args: vec!["--constraint=skx".into()],
            ..Default::default()
        };
        let merged = file.merged_with(&cli.slurm.options());
        assert_eq!(merged.partition.as_deref(), Some("development"));
        assert_eq!(merged.account.as_deref(), Some("A-123"));
        assert_eq!(merged.requeue, Some(true));
        assert_eq!(merged.sbatch_args, ["--constraint=skx", "--qos=debug"]);
        assert_eq!(merged.in_allocation, Some(true));
        // No flag: the file's values stay.
        assert_eq!(file.merged_with(&Cli::try_parse_from(["x"]).unwrap().slurm.options()), file);
    }

    #[test]
    fn slurm_time_limits_and_memory_sizes() {
        for ok in ["90", "90:30", "02:00:00", "1-12", "1-12:30", "2-00:00:00", "UNLIMITED"] {
            assert!(is_slurm_time(ok), "{ok}");
        }
        for bad in ["", "2h", "1:2:3:4", "-1", "1-", "a-02:00", "02:00:xx"] {
            assert!(!is_slurm_time(bad), "{bad}");
        }
        for ok in ["16000", "16G", "512M", "1T"] {
            assert!(is_slurm_memory(ok), "{ok}");
        }
        for bad in ["", "G", "16GB", "16 G", "0", "1.5G"] {
            assert!(!is_slurm_memory(bad), "{bad}");
        }
    }

    #[test]
    fn check_names_the_key_at_fault() {
        let key = |o: ExecutorOptions| o.check().unwrap_err().key;
        assert_eq!(key(ExecutorOptions { time_limit: Some("2h".into()), ..Default::default() }), "time_limit");
        assert_eq!(key(ExecutorOptions { mem: Some("16GB".into()), ..Default::default() }), "mem");
        assert_eq!(key(ExecutorOptions { cpus_per_task: Some(0), ..Default::default() }), "cpus_per_task");
        assert_eq!(key(ExecutorOptions { array_throttle: Some(0), ..Default::default() }), "array_throttle");
        assert_eq!(key(ExecutorOptions { partition: Some("a b".into()), ..Default::default() }), "partition");
        for reserved in
            ["--job-name=x", "-Jx", "--array=0-3", "-d", "--dependency=afterok:1", "--requeue", "--output=x"]
        {
            let e = ExecutorOptions { sbatch_args: vec![reserved.into()], ..Default::default() }.check().unwrap_err();
            assert_eq!(e.key, "sbatch_args", "{reserved}");
            assert!(e.error.message.contains("set by shakeflow"), "{reserved}: {}", e.error);
        }
        let e = ExecutorOptions { sbatch_args: vec!["qos=debug".into()], ..Default::default() }.check().unwrap_err();
        assert!(e.error.message.contains("not an option"), "{}", e.error);
        // Options that merely start like a reserved short flag's letter are fine.
        let fine =
            ExecutorOptions { sbatch_args: vec!["--account-extra".into(), "--exclusive".into()], ..Default::default() };
        assert_eq!(fine.check(), Ok(()));
    }
}
