//! The allocation a process runs in (`sbatch`/`salloc`), read from the variables Slurm sets, and
//! the `srun` arguments of one job step inside it.
//!
//! After Snakemake's slurm-jobstep plugin, which runs each job of a Snakemake job inside its
//! allocation as `srun -n1 --cpu-bind=q …` (one task per step, so a step never runs its
//! command several times), and TACC's Launcher, which packs many small tasks into one job and
//! takes its slots from `SLURM_NTASKS` (at most that many at once, each on its own CPUs). What
//! others learned running several steps at once: a step that is given no memory size may take
//! all the job's memory, and the next waits "step creation temporarily disabled (Requested
//! nodes are busy)" (radical-cybertools/radical.pilot#2620), hence `--mem-per-cpu` when the
//! allocation has a memory size per node; `--exact` gives a step only the CPUs it asks for.

use crate::error::UserError;
use std::ffi::OsString;
use std::path::Path;
use std::process::{Command, Stdio};

/// An allocation: its job id, how many steps run at once, and each step's CPUs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Allocation {
    pub job_id: String,
    /// Steps at once: `SLURM_NTASKS` (1 when unset).
    pub slots: usize,
    /// CPUs per step: `SLURM_CPUS_PER_TASK`, else the allocation's CPUs shared among the slots.
    pub cpus_per_step: u32,
    /// Memory per CPU in megabytes, when the allocation has a size per node
    /// (`SLURM_MEM_PER_NODE` / CPUs on a node); `SLURM_MEM_PER_CPU` reaches `srun` by itself.
    pub mem_per_cpu_mb: Option<u64>,
}

impl Allocation {
    /// The allocation this process runs in, from its environment.
    pub fn current() -> Result<Allocation, UserError> {
        Allocation::from_vars(|name| std::env::var(name).ok())
    }

    /// The allocation that `var` (Slurm's output variables) describes.
    pub fn from_vars(var: impl Fn(&str) -> Option<String>) -> Result<Allocation, UserError> {
        let Some(job_id) = var("SLURM_JOB_ID").filter(|j| !j.is_empty()) else {
            return Err(UserError::new("`--in-allocation` runs inside a Slurm allocation, and $SLURM_JOB_ID is not set")
                .hint("run it in the script of an `sbatch` job or in an `salloc` shell (e.g. `sbatch -N 1 -n 4 -c 8 --wrap \"shakeflow run P.yaml --executor slurm --in-allocation\"`), or drop --in-allocation to submit job arrays"));
        };
        let number = |name: &str| -> Result<Option<u64>, UserError> {
            match var(name).filter(|v| !v.is_empty()) {
                None => Ok(None),
                Some(v) => v.trim().parse::<u64>().map(Some).map_err(|_| {
                    UserError::new(format!("${name} is `{v}`, not a number"))
                        .hint("is this a Slurm allocation's environment?")
                }),
            }
        };
        let slots = number("SLURM_NTASKS")?.unwrap_or(1).max(1) as usize;
        let total_cpus = var("SLURM_JOB_CPUS_PER_NODE").as_deref().and_then(total_cpus);
        let cpus_per_step = match number("SLURM_CPUS_PER_TASK")? {
            Some(c) => c.max(1) as u32,
            None => total_cpus.map_or(1, |t| (t / slots as u64).max(1) as u32),
        };
        let mem_per_cpu_mb = match (number("SLURM_MEM_PER_NODE")?, number("SLURM_CPUS_ON_NODE")?) {
            (Some(mem), Some(cpus)) if cpus > 0 => Some((mem / cpus).max(1)),
            _ => None,
        };
        Ok(Allocation { job_id, slots, cpus_per_step, mem_per_cpu_mb })
    }

    /// `srun` arguments of one step named `name` running one command on one node.
    pub fn step_args(&self, name: &str) -> Vec<String> {
        let mut args = vec![
            "--ntasks=1".to_string(),
            "--nodes=1".to_string(),
            "--exact".to_string(),
            format!("--cpus-per-task={}", self.cpus_per_step),
            format!("--job-name={name}"),
            format!("--jobid={}", self.job_id),
        ];
        if let Some(mb) = self.mem_per_cpu_mb {
            args.push(format!("--mem-per-cpu={mb}M"));
        }
        args
    }

    /// Runs `program args…` as one step named `name` (`srun`, waiting for it), with `env` added,
    /// its output appended to `log`; whether it succeeded.
    pub fn run_step(
        &self,
        name: &str,
        program: &Path,
        args: &[OsString],
        env: &[(&str, String)],
        log: &Path,
    ) -> Result<bool, UserError> {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(log)
            .map_err(|e| UserError::new(format!("cannot open the step log `{}`: {e}", log.display())))?;
        let err = file.try_clone().map_err(|e| UserError::new(format!("`{}`: {e}", log.display())))?;
        let status = Command::new("srun")
            .args(self.step_args(name))
            .arg(program)
            .args(args)
            .envs(env.iter().map(|(k, v)| (*k, v.as_str())))
            .stdin(Stdio::null())
            .stdout(file)
            .stderr(err)
            .status()
            .map_err(|e| {
                if e.kind() == std::io::ErrorKind::NotFound {
                    UserError::new("`srun` was not found: `--in-allocation` runs each shard as an srun job step")
                        .hint("run inside a Slurm allocation on a node that has Slurm's commands")
                } else {
                    UserError::new(format!("cannot run `srun`: {e}"))
                }
            })?;
        Ok(status.success())
    }
}

/// The CPUs of `SLURM_JOB_CPUS_PER_NODE` (`48(x2),24`: two nodes of 48 and one of 24).
fn total_cpus(text: &str) -> Option<u64> {
    text.split(',')
        .map(|part| {
            let (cpus, times) = match part.split_once("(x") {
                Some((cpus, rest)) => (cpus, rest.strip_suffix(')')?),
                None => (part, "1"),
            };
            Some(cpus.trim().parse::<u64>().ok()? * times.parse::<u64>().ok()?)
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    fn from(vars: &[(&str, &str)]) -> Result<Allocation, UserError> {
        let vars: BTreeMap<String, String> = vars.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        Allocation::from_vars(|name| vars.get(name).cloned())
    }

    #[test]
    fn reads_the_allocation_from_slurms_variables() {
        let a = from(&[("SLURM_JOB_ID", "42"), ("SLURM_NTASKS", "4"), ("SLURM_CPUS_PER_TASK", "8")]).unwrap();
        assert_eq!(a, Allocation { job_id: "42".into(), slots: 4, cpus_per_step: 8, mem_per_cpu_mb: None });
        // No -c: the allocation's CPUs shared among the tasks (two nodes of 48, one of 24: 120 / 4).
        let a =
            from(&[("SLURM_JOB_ID", "42"), ("SLURM_NTASKS", "4"), ("SLURM_JOB_CPUS_PER_NODE", "48(x2),24")]).unwrap();
        assert_eq!((a.slots, a.cpus_per_step), (4, 30));
        // salloc without -n: one step at a time.
        let a = from(&[("SLURM_JOB_ID", "7"), ("SLURM_JOB_CPUS_PER_NODE", "2")]).unwrap();
        assert_eq!((a.slots, a.cpus_per_step), (1, 2));
        let a = from(&[("SLURM_JOB_ID", "7"), ("SLURM_MEM_PER_NODE", "192000"), ("SLURM_CPUS_ON_NODE", "48")]).unwrap();
        assert_eq!(a.mem_per_cpu_mb, Some(4000));
        assert_eq!(
            a.step_args("run-1"),
            [
                "--ntasks=1",
                "--nodes=1",
                "--exact",
                "--cpus-per-task=1",
                "--job-name=run-1",
                "--jobid=7",
                "--mem-per-cpu=4000M"
            ]
        );
    }

    #[test]
    fn outside_an_allocation_or_with_odd_values_it_says_so() {
        let e = from(&[]).unwrap_err();
        assert!(e.message.contains("$SLURM_JOB_ID is not set"), "{e}");
        let e = from(&[("SLURM_JOB_ID", "1"), ("SLURM_NTASKS", "four")]).unwrap_err();
        assert!(e.message.contains("$SLURM_NTASKS is `four`"), "{e}");
        assert_eq!(total_cpus("48(x2),24"), Some(120));
        assert_eq!(total_cpus("2"), Some(2));
        assert_eq!(total_cpus("4(x"), None);
    }
}
