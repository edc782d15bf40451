//! Progress: bars on a terminal, plain timestamped-free log lines otherwise (CI logs, pipes).

use std::io::IsTerminal;

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};

pub struct Reporter {
    multi: Option<MultiProgress>,
    quiet: bool,
}

impl Reporter {
    pub fn new(quiet: bool) -> Self {
        let multi = (!quiet && std::io::stderr().is_terminal())
            .then(|| MultiProgress::with_draw_target(ProgressDrawTarget::stderr()));
        Reporter { multi, quiet }
    }

    pub fn line(&self, message: &str) {
        if self.quiet {
            return;
        }
        match &self.multi {
            Some(multi) => {
                let _ = multi.println(message);
            }
            None => eprintln!("{message}"),
        }
    }

    /// A bar counting records for one running stage; hidden when not on a terminal.
    pub fn stage_bar(&self, stage: &str, records: u64) -> ProgressBar {
        let Some(multi) = &self.multi else { return ProgressBar::hidden() };
        let bar = multi.add(ProgressBar::new(records));
        bar.set_style(
            ProgressStyle::with_template("{prefix:>18} [{bar:30.cyan/blue}] {pos}/{len} records {elapsed_precise}")
                .expect("template is valid")
                .progress_chars("=> "),
        );
        bar.set_prefix(stage.to_string());
        bar
    }
}

/// CPU seconds this process has used (user and system), for the steps a log times.
pub fn cpu_seconds() -> f64 {
    // SAFETY: getrusage fills the struct it is given; RUSAGE_SELF is always valid.
    let usage = unsafe {
        let mut usage: libc::rusage = std::mem::zeroed();
        libc::getrusage(libc::RUSAGE_SELF, &mut usage);
        usage
    };
    let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 / 1e6;
    seconds(usage.ru_utime) + seconds(usage.ru_stime)
}
