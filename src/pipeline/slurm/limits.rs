//! What the cluster allows: `scontrol show config` (array size, job count, accounting, the
//! job-completion file) and, where `sacctmgr` answers, the user's submit limit.

use std::path::PathBuf;

/// Limits and facilities of the cluster, read once per run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClusterLimits {
    /// `MaxArraySize`: array indices must be below it (Slurm's default: 1001).
    pub max_array_size: u32,
    /// `MaxJobCount`: jobs slurmctld holds at once, all users together (default 10000).
    pub max_job_count: u32,
    /// The user's `MaxSubmitJobs` (association), where `sacctmgr` could tell; each array task
    /// counts as one job.
    pub max_submit_jobs: Option<u32>,
    /// `MinJobAge`: seconds slurmctld remembers a finished job (what `squeue` can still show).
    pub min_job_age_s: Option<u32>,
    /// An accounting storage is configured: `sacct` can answer.
    pub accounting: bool,
    /// `JobCompType=jobcomp/filetxt`'s file (`JobCompLoc`), when it is one this process can read.
    pub jobcomp_file: Option<PathBuf>,
}

impl Default for ClusterLimits {
    /// Slurm's defaults, without accounting.
    fn default() -> Self {
        ClusterLimits {
            max_array_size: 1001,
            max_job_count: 10000,
            max_submit_jobs: None,
            min_job_age_s: Some(300),
            accounting: false,
            jobcomp_file: None,
        }
    }
}

impl ClusterLimits {
    /// From `scontrol show config` (`Key = value` lines); absent keys keep Slurm's defaults.
    pub fn from_config(text: &str) -> ClusterLimits {
        let mut limits = ClusterLimits::default();
        let mut jobcomp_type = String::new();
        let mut jobcomp_loc = String::new();
        for line in text.lines() {
            let Some((key, value)) = line.split_once('=') else { continue };
            let (key, value) = (key.trim(), value.trim());
            let number = || value.split_whitespace().next().and_then(|v| v.parse::<u32>().ok());
            match key {
                "MaxArraySize" => limits.max_array_size = number().unwrap_or(limits.max_array_size),
                "MaxJobCount" => limits.max_job_count = number().unwrap_or(limits.max_job_count),
                "MinJobAge" => limits.min_job_age_s = number(),
                "AccountingStorageType" => limits.accounting = !value.is_empty() && value != "accounting_storage/none",
                "JobCompType" => jobcomp_type = value.to_string(),
                "JobCompLoc" => jobcomp_loc = value.to_string(),
                _ => {}
            }
        }
        if jobcomp_type == "jobcomp/filetxt" && jobcomp_loc.starts_with('/') {
            limits.jobcomp_file = Some(PathBuf::from(jobcomp_loc));
        }
        limits
    }

    /// The smallest `MaxSubmit` of `sacctmgr -n -P show assoc … format=MaxSubmit` (one line per
    /// association; empty: no limit).
    pub fn parse_max_submit(text: &str) -> Option<u32> {
        text.lines().filter_map(|l| l.trim().parse::<u32>().ok()).min()
    }

    /// How many array tasks one run may have queued at once: `MaxJobCount` and the user's
    /// `MaxSubmitJobs`, whichever is smaller (other jobs already queued not counted).
    pub fn task_budget(&self) -> u32 {
        self.max_submit_jobs.map_or(self.max_job_count, |m| m.min(self.max_job_count))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Lines of `scontrol show config` as the test Slurm (22.05.8) prints them.
    const CONFIG: &str = "Configuration data as of 2026-11-25T15:56:17\n\
        AccountingStorageType   = accounting_storage/none\n\
        JobCompHost             = localhost\n\
        JobCompLoc              = /root/.cache/shakeflow/slurm/log/jobcomp.txt\n\
        JobCompType             = jobcomp/filetxt\n\
        MaxArraySize            = 1001\n\
        MaxJobCount             = 10000\n\
        MinJobAge               = 3600 sec\n\
        SLURM_VERSION           = 22.05.8\n";

    #[test]
    fn reads_the_limits_of_scontrol_show_config() {
        let l = ClusterLimits::from_config(CONFIG);
        assert_eq!(l.max_array_size, 1001);
        assert_eq!(l.max_job_count, 10000);
        assert_eq!(l.min_job_age_s, Some(3600));
        assert!(!l.accounting);
        assert_eq!(l.jobcomp_file, Some(PathBuf::from("/root/.cache/shakeflow/slurm/log/jobcomp.txt")));
        let tacc_like = "AccountingStorageType = accounting_storage/slurmdbd\nJobCompType = jobcomp/none\nMaxArraySize = 10001\nMaxJobCount = 200000\n";
        let l = ClusterLimits::from_config(tacc_like);
        assert!(l.accounting);
        assert_eq!((l.max_array_size, l.max_job_count, l.jobcomp_file), (10001, 200000, None));
        assert_eq!(ClusterLimits::from_config(""), ClusterLimits::default());
    }

    #[test]
    fn the_submit_limit_is_the_smallest_association_limit() {
        assert_eq!(ClusterLimits::parse_max_submit("\n200\n50\n"), Some(50));
        assert_eq!(ClusterLimits::parse_max_submit("\n\n"), None);
        let l = ClusterLimits { max_submit_jobs: Some(50), ..ClusterLimits::default() };
        assert_eq!(l.task_budget(), 50);
        assert_eq!(ClusterLimits::default().task_budget(), 10000);
    }
}
