//! The command line: thin wrappers over the library, written to teach through `--help`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context};
use clap::{Parser, Subcommand};

use crate::pipeline::executor::{self, Outcome, RunOptions};
use crate::pipeline::params;
use crate::pipeline::plan::Plan;
use crate::pipeline::progress::Reporter;
use crate::pipeline::spec::{PipelineFile, RecordFormat, SourceSpec};
use crate::stages::{self, InputKind};
use crate::validate::Refusal;

#[derive(Parser)]
#[command(
    name = "shakeflow",
    version,
    about = "Turn shake-table archives into validated physics with declarative, cached YAML pipelines.",
    long_about = "Turn shake-table archives into validated physics with declarative, cached YAML pipelines.\n\n\
A pipeline file names record sources (`inputs:`) and processing stages (`stages:`); each stage writes \
Parquet tables (units and provenance in the metadata) and, for time series, MCAP files that open in Foxglove. \
A rerun recomputes only stages whose inputs, parameters or code changed (see `shakeflow.lock` in the output directory).",
    after_help = "Start here:\n  shakeflow demo-archive runs/demo-archive   write the synthetic demo archive\n  \
shakeflow run pipelines/demo.yaml          run the demo study (again: everything cached)\n  \
shakeflow status pipelines/demo.yaml       what is stale, and why\n  \
shakeflow inspect runs/demo/synchronize/records/motion=FB-4/data.parquet\n  \
shakeflow stages                           stage types, their parameters, units and defaults"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a pipeline in work units: each record of a per-record stage (and each gathering stage
    /// as a whole) is cached, run and committed on its own; stale units run in parallel.
    ///
    /// A unit that fails does not discard the others: what finished is committed, the failed
    /// units keep their previous outputs (stale), what depends on them does not run, and the run
    /// exits 1 naming each. Records a source with `on_error: skip` cannot read are listed in the
    /// load stage's `flagged` table and the run exits 2.
    ///
    /// Examples:
    ///   shakeflow run pipelines/demo.yaml                       everything that is stale
    ///   shakeflow run pipelines/demo.yaml baseline_floors       that stage and what it needs
    ///   shakeflow run pipelines/demo.yaml --dry-run             the units that would run, and why
    ///   shakeflow run pipelines/demo.yaml --keep-going          past failures, all that does not depend on them
    #[command(verbatim_doc_comment)]
    Run {
        /// The pipeline YAML file.
        pipeline: PathBuf,
        /// Run only these stages and the stages they read (default: all).
        stages: Vec<String>,
        /// Print the units that would run and why; run nothing.
        #[arg(long)]
        dry_run: bool,
        /// After a failed unit, still run everything that does not depend on it.
        #[arg(long)]
        keep_going: bool,
        /// Where the work units run: `local` (this machine, rayon) or `slurm` (one job array per
        /// stage and a commit job; returns once submitted unless --wait; docs/slurm.md).
        #[arg(long, value_enum, default_value_t = ExecutorKind::Local)]
        executor: ExecutorKind,
        /// With --executor slurm: poll until the run is committed and exit as a local run would.
        #[arg(long)]
        wait: bool,
        /// With --executor slurm: work units per array task (records per shard).
        #[arg(long, default_value_t = 50)]
        units_per_task: usize,
        #[command(flatten)]
        slurm: crate::pipeline::slurm::ExecutorFlags,
        /// Worker threads for stages and records (default: all cores).
        #[arg(long, short = 'j')]
        jobs: Option<usize>,
        /// Rerun this stage and everything downstream of it even if cached (repeatable).
        #[arg(long, value_name = "STAGE")]
        force: Vec<String>,
        /// Print nothing but errors.
        #[arg(long, short = 'q')]
        quiet: bool,
    },
    /// Show which stages are stale and why (changed params, inputs, stage version, missing outputs),
    /// and stage folders the pipeline no longer has.
    Status { pipeline: PathBuf },
    /// Remove the stage folders of stages the pipeline no longer has (only folders shakeflow wrote).
    ///
    /// Example: after deleting the stage `old_baseline` from pipelines/demo.yaml,
    ///   shakeflow gc pipelines/demo.yaml --dry-run   lists runs/demo/old_baseline and its size
    ///   shakeflow gc pipelines/demo.yaml             removes it (one commit, like a run)
    #[command(verbatim_doc_comment)]
    Gc {
        pipeline: PathBuf,
        /// List what would be removed, remove nothing.
        #[arg(long)]
        dry_run: bool,
    },
    /// Check a pipeline file without running it: keys, stage types, parameters, inputs, cycles, source files (the first of each read as `load` would).
    Validate {
        pipeline: PathBuf,
        /// Do not check that the record sources match files (e.g. before generating an archive).
        #[arg(long)]
        skip_inputs: bool,
    },
    /// Run one stage type alone on files, without a pipeline: a pipeline of one stage made in
    /// memory and run as `run` runs one (work units, cache, lockfile in the output folder).
    ///
    /// Examples:
    ///
    ///   shakeflow stage load --input RSN6.AT2 --output out/
    ///   shakeflow stage baseline --input out/records --output out2/ --set order=2
    ///
    /// For `load`, --set keys are source options (unit, dt, header_lines, time_column, columns, ...).
    #[command(verbatim_doc_comment)]
    Stage {
        /// Stage type (see `shakeflow stages`).
        name: String,
        /// Input files (record files for `load`; Parquet files or dataset folders, such as another
        /// stage's `<output>` folder, otherwise).
        #[arg(long = "input", short = 'i', required = true, num_args = 1..)]
        inputs: Vec<PathBuf>,
        /// Output folder: new, empty, or an earlier output of this stage type (anything else is
        /// refused). Written only when every record succeeds; its `shakeflow.lock` makes the same
        /// command again a no-op ("cached").
        #[arg(long, short = 'o')]
        output: PathBuf,
        /// Parameter as key=value, value in YAML syntax (repeatable).
        #[arg(long = "set", short = 's', value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
    /// List stage types with their inputs, outputs and parameters (units, defaults).
    Stages {
        /// Show only this stage type.
        name: Option<String>,
        /// Print docs/stages.md (every stage type as Markdown) instead: `make docs` writes it.
        #[arg(long, conflicts_with = "name")]
        markdown: bool,
    },
    /// Describe an artifact: a Parquet file (schema, units, statistics, provenance), an MCAP file, or a dataset folder.
    Inspect {
        artifact: PathBuf,
        /// Rows to preview for a Parquet file.
        #[arg(long, default_value_t = 5)]
        rows: usize,
    },
    /// Print a (small) table: a Parquet file, or a stage's output folder (every partition, its
    /// partition keys as columns), as aligned text or, with --csv, as CSV.
    ///
    /// Examples:
    ///
    ///   shakeflow show runs/demo/report/summary
    ///   shakeflow show runs/demo/detect_toppling/events --columns motion,channel,toppled,impact_time_s
    ///   shakeflow show runs/demo/fragility_PS2/runs --csv > runs.csv
    #[command(verbatim_doc_comment)]
    Show {
        table: PathBuf,
        /// Rows to print at most (default: 100 as text, all with --csv).
        #[arg(long)]
        rows: Option<usize>,
        /// Only these columns, in this order (comma-separated).
        #[arg(long, value_delimiter = ',')]
        columns: Vec<String>,
        /// Print CSV (RFC 4180, `NA` for null) instead of an aligned table.
        #[arg(long)]
        csv: bool,
    },
    /// Export stage outputs as one tidy table for Python, R or a spreadsheet, with its units and provenance.
    ///
    /// DATASET is a Parquet file or a stage's output folder (all its partitions). Partition keys
    /// become plain columns (`motion=FB-4` → a column `motion` holding `FB-4`); columns are
    /// matched by name across partitions (one missing from a partition is null there, with a
    /// warning). The extension of FILE picks the format: `.csv` (RFC 4180, a header row, `NA`
    /// for null) or `.parquet` (one file). Beside it, always, `<stem>.meta.json`: per column its
    /// unit and description, and the provenance (stage, parameters, input hashes, shakeflow
    /// version).
    ///
    /// Examples:
    ///
    ///   shakeflow export runs/demo/report/summary --out exports/summary.csv
    ///   shakeflow export runs/demo/fragility_PS2/runs --out exports/fragility_runs.parquet
    ///   shakeflow export runs/demo/rolling_*/events --out exports/rolling.csv
    ///
    /// In R:       d <- read.csv("exports/summary.csv")   (or data.table::fread)
    /// In Python:  pandas.read_csv("exports/summary.csv"); json.load(open("exports/summary.meta.json"))
    #[command(verbatim_doc_comment)]
    Export {
        /// Stage outputs: output folders (every partition) or Parquet files.
        #[arg(required = true, value_name = "DATASET")]
        datasets: Vec<PathBuf>,
        /// The table to write, `.csv` or `.parquet`; `<stem>.meta.json` is written beside it.
        #[arg(long, short = 'o', value_name = "FILE")]
        out: PathBuf,
    },
    /// Diagnose a unit: where the toppling model and its records disagree, which physics explains it.
    ///
    /// A case folder holds equipment.yaml, floor.csv (time_s, ax_mps2, ay_mps2, az_mps2),
    /// observed_accel.csv (time_s, top_ax_mps2) and observed_cpt.csv (time_s, theta_rad).
    /// Runs the `diagnose` stage on them as a pipeline would (a lockfile in OUT: the same command
    /// again is cached). Writes OUT/diagnosis.json (verdict, window, rmse before/after,
    /// candidates, explanation), or OUT/<case>/diagnosis.json for each of several cases; the
    /// stage's tables beside it: diagnosis/ (a row per case), accel/ and camera/ (observed,
    /// nominal and accepted model, residuals; case=<case>/data.parquet, MCAP twins with
    /// --set mcap=true) and reports/<case>.png. A failed case leaves OUT as it was.
    ///
    /// Example: shakeflow diagnose ../shared/cases/demo/demo_02 --out runs/diagnosis/demo_02
    Diagnose {
        /// Case folders.
        #[arg(required = true)]
        cases: Vec<PathBuf>,
        /// Output folder.
        #[arg(long, short = 'o')]
        out: PathBuf,
        /// Worker threads (default: all cores).
        #[arg(long, short = 'j')]
        jobs: Option<usize>,
        /// Decision threshold as key=value (exceedance_sigma, min_improvement, max_remaining_flagged).
        #[arg(long = "set", short = 's', value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
    /// Write the synthetic demo archive (12 motions + 2 white-noise tests, floors 4/5, 7 units).
    DemoArchive {
        dir: PathBuf,
        /// Rewrite it even when an up-to-date archive is already there.
        #[arg(long)]
        force: bool,
        /// How many tests: the study's 14, then variations (scale, seed) of its motions, V-0001 …
        /// (for scale benchmarks).
        #[arg(long, default_value_t = crate::demo::archive::STUDY_TESTS)]
        tests: usize,
    },
    /// Print the JSON Schema of pipeline files (the source of schemas/pipeline.schema.json).
    Schema,
    /// One array task of a Slurm run (submitted by `run --executor slurm`; its shard is
    /// `$SLURM_ARRAY_TASK_ID`), or one job step of an in-allocation run (`--shard`).
    #[command(hide = true)]
    SlurmTask {
        run_dir: PathBuf,
        stage: String,
        #[arg(long)]
        shard: Option<usize>,
    },
    /// The commit job of a Slurm run (submitted by `run --executor slurm`).
    #[command(hide = true)]
    SlurmCommit { run_dir: PathBuf },
}

pub fn main() -> anyhow::Result<ExitCode> {
    let cli = Cli::parse();
    match cli.command {
        Command::Run {
            pipeline,
            stages,
            dry_run,
            keep_going,
            executor,
            wait,
            units_per_task,
            slurm,
            jobs,
            force,
            quiet,
        } => {
            start_workers(jobs)?;
            let plan = Plan::new(PipelineFile::read(&pipeline)?, stages::registry())?;
            let options = RunOptions { force, only: stages, keep_going, ..RunOptions::default() };
            if dry_run {
                let lines = executor::dry_run(&plan, &options)?;
                let mut stale = 0;
                for line in &lines {
                    for unit in &line.stale {
                        stale += 1;
                        println!(
                            "would run {} {}: {}",
                            line.name,
                            crate::pipeline::work_units::describe(&unit.id),
                            unit.reasons.join("; ")
                        );
                    }
                    for unit in &line.vanished {
                        println!(
                            "would remove {} {}: its record is gone from the inputs",
                            line.name,
                            crate::pipeline::work_units::describe(unit)
                        );
                    }
                }
                let total: usize = lines.iter().map(|l| l.units).sum();
                println!("{stale} of {total} unit(s) would run; nothing was run");
                return Ok(ExitCode::SUCCESS);
            }
            let reporter = Reporter::new(quiet);
            let started = std::time::Instant::now();
            if executor == ExecutorKind::Slurm {
                let file_options = plan.file.spec.executor.clone().unwrap_or_default();
                let slurm = executor::slurm::SlurmOptions {
                    executor: file_options.merged_with(&slurm.options()),
                    units_per_task,
                    wait,
                };
                let summary = executor::run(&plan, &options, &slurm, &reporter)?;
                return Ok(exit_status(&summary));
            }
            let summary = executor::run(&plan, &options, &executor::Local, &reporter)?;
            let reports = &summary.reports;
            let ran = reports.iter().filter(|r| matches!(r.outcome, Outcome::Ran { .. })).count();
            let skipped = reports.iter().filter(|r| r.outcome == Outcome::Skipped).count();
            let units: usize = reports.iter().map(|r| r.ran).sum();
            reporter.line(&format!(
                "{} stage(s): {ran} ran, {} cached{} ({units} unit(s) ran), in {:.2} s; artifacts in {}",
                reports.len(),
                reports.len() - ran - skipped,
                if skipped > 0 { format!(", {skipped} not run") } else { String::new() },
                started.elapsed().as_secs_f64(),
                plan.file.output_dir().display()
            ));
            // One line of results per stage whose results changed and that has one (fragility,
            // detections, verdicts, …): units ran or were removed. A summary reads all the
            // stage's committed outputs, so it is made only then, and where it is shown: not
            // under `--quiet`, not for a cached stage (at 10⁴ tests, summaries of cached stages
            // were 6 of a no-op's 8 s).
            if !quiet {
                for report in reports.iter().filter(|r| matches!(r.outcome, Outcome::Ran { .. }) || r.gone > 0) {
                    let Some(stage) = plan.stages.get(&report.name) else { continue };
                    if let Some(line) = stage.stage.summary(&plan.stage_dir(&report.name)) {
                        reporter.line(&format!("  {}: {line}", report.name));
                    }
                }
            }
            Ok(exit_status(&summary))
        }
        Command::SlurmTask { run_dir, stage, shard } => {
            let shard: usize = shard
                .or_else(|| std::env::var("SLURM_ARRAY_TASK_ID").ok().and_then(|v| v.parse().ok()))
                .context("`slurm-task` runs inside a Slurm array task ($SLURM_ARRAY_TASK_ID) or with --shard")?;
            let ok = executor::slurm::task(&run_dir, &stage, shard, stages::registry())?;
            Ok(if ok { ExitCode::SUCCESS } else { ExitCode::from(1) })
        }
        Command::SlurmCommit { run_dir } => {
            executor::slurm::commit(&run_dir, stages::registry())?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Status { pipeline } => {
            let plan = Plan::new(PipelineFile::read(&pipeline)?, stages::registry())?;
            let mut notes = Vec::new();
            let lines = executor::status(&plan, &mut notes)?;
            for note in &notes {
                println!("note: {note}");
            }
            for line in executor::slurm::progress(&plan.file.output_dir()) {
                println!("{line}");
            }
            let stale = lines.iter().filter(|l| l.is_stale()).count();
            for line in &lines {
                if line.is_stale() {
                    println!("{:<18} stale: {}", line.name, line.summary());
                } else {
                    let kept = if line.keep { "" } else { "; an intermediate, its files not kept" };
                    println!("{:<18} up to date ({} unit(s){kept})", line.name, line.units);
                }
                for flagged in &line.flagged {
                    println!(
                        "{:<18} flagged {}: {}",
                        "",
                        crate::pipeline::work_units::describe(&flagged.id),
                        flagged.reasons.join("; ")
                    );
                }
            }
            println!("{stale} of {} stage(s) stale; lockfile {}", lines.len(), executor::lock_path(&plan).display());
            Ok(ExitCode::SUCCESS)
        }
        Command::Gc { pipeline, dry_run } => {
            let plan = Plan::new(PipelineFile::read(&pipeline)?, stages::registry())?;
            let removed = executor::gc(&plan, dry_run)?;
            let verb = if dry_run { "would remove" } else { "removed" };
            for (stage, bytes) in &removed {
                println!("{verb} {} ({:.1} MB)", plan.file.output_dir().join(stage).display(), *bytes as f64 / 1e6);
            }
            let total: u64 = removed.iter().map(|(_, b)| b).sum();
            println!("{} orphaned stage folder(s), {:.1} MB {verb}", removed.len(), total as f64 / 1e6);
            Ok(ExitCode::SUCCESS)
        }
        Command::Validate { pipeline, skip_inputs } => {
            let file = PipelineFile::read(&pipeline)?;
            let say = &mut |line: String| println!("{line}");
            match crate::validate::validate(file, stages::registry(), skip_inputs, say) {
                Ok(plan) => {
                    let (sources, stages) = (plan.file.spec.inputs.len(), plan.stages.len());
                    println!("{}: valid ({sources} source(s), {stages} stage(s))", pipeline.display());
                    Ok(ExitCode::SUCCESS)
                }
                // Every error is reported, not only the first.
                Err(Refusal::Invalid(errors)) => {
                    for e in &errors {
                        eprintln!("error: {e}");
                    }
                    bail!("{}: {} error(s)", pipeline.display(), errors.len())
                }
                Err(Refusal::Refused(e)) => Err(e.into()),
            }
        }
        Command::Stage { name, inputs, output, set } => {
            start_workers(None)?;
            run_single_stage(&name, &inputs, &output, &set)
        }
        Command::Stages { markdown: true, .. } => {
            print!("{}", stages::reference::markdown());
            Ok(ExitCode::SUCCESS)
        }
        Command::Stages { name, .. } => {
            print!("{}", describe_stages(name.as_deref())?);
            Ok(ExitCode::SUCCESS)
        }
        Command::Inspect { artifact, rows } => {
            print!("{}", crate::inspect::describe(&artifact, rows)?);
            Ok(ExitCode::SUCCESS)
        }
        Command::Show { table, rows, columns, csv } => {
            let (text, warnings) = crate::inspect::show(&table, rows, &columns, csv)?;
            for warning in &warnings {
                eprintln!("warning: {warning}");
            }
            print!("{text}");
            Ok(ExitCode::SUCCESS)
        }
        Command::Export { datasets, out } => {
            let done = crate::export::export(&datasets, &out)?;
            for warning in &done.warnings {
                eprintln!("warning: {warning}");
            }
            println!(
                "{}: {} rows × {} columns; units, descriptions and provenance in {}",
                out.display(),
                done.rows,
                done.columns,
                done.meta.display()
            );
            Ok(ExitCode::SUCCESS)
        }
        Command::DemoArchive { dir, force, tests } => {
            if !force && crate::demo::archive::is_current_tests(&dir, tests) {
                eprintln!("{}: demo archive is up to date (use --force to rewrite it)", dir.display());
                return Ok(ExitCode::SUCCESS);
            }
            let started = std::time::Instant::now();
            let report = crate::demo::archive::write_demo_archive_tests(&dir, tests)
                .with_context(|| format!("writing the demo archive to `{}`", dir.display()))?;
            let bytes: u64 = report.files.iter().map(|f| f.bytes).sum();
            eprintln!(
                "{}: wrote {} tests, {} files, {:.1} MB in {:.1} s",
                dir.display(),
                report.test_ids.len(),
                report.files.len(),
                bytes as f64 / 1e6,
                started.elapsed().as_secs_f64()
            );
            Ok(ExitCode::SUCCESS)
        }
        Command::Diagnose { cases, out, jobs, set } => {
            start_workers(jobs)?;
            diagnose_cases(&cases, &out, &set)
        }
        Command::Schema => {
            println!("{}", serde_json::to_string_pretty(&crate::schema::pipeline_schema())?);
            Ok(ExitCode::SUCCESS)
        }
    }
}

fn describe_stages(only: Option<&str>) -> anyhow::Result<String> {
    use std::fmt::Write as _;
    let mut out = String::new();
    if let Some(name) = only {
        if stages::registry().find(name).is_none() {
            bail!("unknown stage type `{name}`; known: {}", stages::registry().names().join(", "));
        }
    }
    for stage in stages::registry().0.iter().filter(|s| only.is_none_or(|n| s.info().name == n)) {
        let info = stage.info();
        writeln!(out, "{} (version {})\n  {}", info.name, info.version, info.summary)?;
        writeln!(out, "  reads: {}", stages::reference::reads(info))?;
        for o in info.outputs {
            let kind = stages::reference::written_as(info, o);
            writeln!(out, "  output `{}` ({kind}): {}", o.name, o.description)?;
        }
        if info.params.is_empty() {
            writeln!(out, "  parameters: none (a `load` is configured by its source)")?;
        }
        for p in info.params {
            let default = p.default.map_or("required".to_string(), |d| format!("default {d}"));
            let unit = if p.unit.is_empty() { String::new() } else { format!(" [{}]", p.unit) };
            writeln!(out, "  - {}{unit}: {} ({default}) — {}", p.name, p.kind.describe(), p.description)?;
        }
        writeln!(out)?;
    }
    Ok(out)
}

/// The worker pool of a command that runs work: `jobs` threads (default: `RAYON_NUM_THREADS`, else
/// one per core), this thread one of them. It runs work while it waits for the pool instead of
/// sleeping beside it, and a one-unit call starts one thread fewer (with its stack and malloc
/// arena) and has no idle worker spinning: 8.2 → 6.4 ms CPU a 2-sample `stage` call on a quiet
/// machine (docs/benchmarks.md "Per call").
fn start_workers(jobs: Option<usize>) -> anyhow::Result<()> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.map_or(0, |jobs| jobs.max(1)))
        .use_current_thread()
        .build_global()
        .context("starting the worker threads (--jobs)")
}

/// `shakeflow stage`: one stage on files, run by the executor every pipeline runs on, as a
/// pipeline made in memory: a source per input, the stage, `output` as its output folder.
fn run_single_stage(name: &str, inputs: &[PathBuf], output: &Path, set: &[String]) -> anyhow::Result<ExitCode> {
    let stage = stages::registry().find(name).ok_or_else(|| {
        crate::error::UserError::new(format!("unknown stage type `{name}`"))
            .hint(format!("known stage types: {}", stages::registry().names().join(", ")))
    })?;
    let info = stage.info();
    let assignments: Vec<(String, serde_json::Value)> =
        set.iter().map(|s| params::parse_set(s)).collect::<Result<_, _>>().map_err(anyhow::Error::msg)?;
    // For `load`, --set keys are source options; for the others, parameters.
    let (overrides, params) = match info.inputs {
        InputKind::Sources => (assignments.into_iter().collect(), BTreeMap::new()),
        _ => {
            let params = assignments
                .into_iter()
                .map(|(k, v)| Ok((k, serde_yaml::to_value(v)?)))
                .collect::<anyhow::Result<_>>()?;
            (serde_json::Map::new(), params)
        }
    };
    let mut sources = indexmap::IndexMap::new();
    for path in inputs {
        let mut spec: SourceSpec = match info.inputs {
            InputKind::Sources => stages::load::ad_hoc_source(path, &overrides)?,
            InputKind::Files(formats) => {
                let format = if crate::io::frames::is_frame_source(path) && formats.contains(&RecordFormat::Frames) {
                    RecordFormat::Frames
                } else {
                    formats[0]
                };
                // A case source names a case by its equipment.yaml, as in a pipeline.
                let named = if format == RecordFormat::Case { path.join("equipment.yaml") } else { path.clone() };
                serde_json::from_value(serde_json::json!({"format": format, "path": named.display().to_string()}))?
            }
            InputKind::Datasets => serde_json::from_value(
                serde_json::json!({"format": RecordFormat::Dataset, "path": path.display().to_string()}),
            )?,
        };
        // Several files are told apart by a `file` partition (their stems); a dataset folder's
        // parts by their own.
        if inputs.len() > 1 && !path.is_dir() {
            let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            spec.partition.insert("file".into(), stem);
        }
        if sources.insert(path.display().to_string(), spec).is_some() {
            bail!("`{}` is given twice as an input", path.display());
        }
    }
    let spec = command_spec(name, sources, params, output);
    let plan = Plan::for_command("shakeflow stage", spec, stages::registry())?;
    Ok(run_command_plan(&plan, output)?.0)
}

/// The pipeline of a command: `sources` read by one stage of type `stage_type` (named after
/// it), written at `output`.
fn command_spec(
    stage_type: &str,
    sources: indexmap::IndexMap<String, SourceSpec>,
    params: BTreeMap<String, serde_yaml::Value>,
    output: &Path,
) -> crate::pipeline::spec::PipelineSpec {
    let stage = crate::pipeline::spec::StageSpec {
        stage_type: stage_type.to_string(),
        description: None,
        inputs: sources.keys().cloned().collect(),
        params,
        select: BTreeMap::new(),
        keep: true,
    };
    crate::pipeline::spec::PipelineSpec {
        version: crate::pipeline::spec::FORMAT_VERSION,
        description: None,
        output_dir: output.display().to_string(),
        inputs: sources,
        stages: indexmap::IndexMap::from([(stage_type.to_string(), stage)]),
        executor: None,
    }
}

/// Runs the one stage of a command's plan all or nothing: a failed unit leaves `output` as it
/// was (a folder the run had to create goes again). Returns the exit status and whether every
/// unit succeeded.
fn run_command_plan(plan: &Plan, output: &Path) -> anyhow::Result<(ExitCode, bool)> {
    // The run checks the folder again under its lease; a refusal now leaves it untouched.
    let files: Vec<PathBuf> = plan.stages.values().flat_map(|s| s.files.values().cloned()).collect();
    crate::validate::ownership(plan, &files)?;
    let created = !output.exists();
    let reporter = Reporter::new(false);
    let options = RunOptions { all_or_nothing: true, ..RunOptions::default() };
    let result = executor::run(plan, &options, &executor::Local, &reporter);
    if !executor::lock_path(plan).exists() {
        let state = output.join(crate::pipeline::layout::STATE_DIR);
        let _ = if created { std::fs::remove_dir_all(&state) } else { std::fs::remove_dir(&state) };
        if created {
            let _ = std::fs::remove_dir(output);
        }
    }
    let summary = result?;
    if !summary.failed.is_empty() {
        for failed in &summary.failed {
            let unit = crate::pipeline::work_units::describe(&failed.unit);
            eprintln!("error: stage `{}` {unit} failed: {}", failed.stage, failed.reason);
        }
        eprintln!("{} unit(s) failed; nothing was written: `{}` is as it was", summary.failed.len(), output.display());
        return Ok((ExitCode::from(1), false));
    }
    for report in &summary.reports {
        let ran = if report.ran == 0 { "cached".to_string() } else { format!("{} ran", report.ran) };
        eprintln!("{}: {} unit(s), {ran} → {}", report.name, report.units, output.display());
    }
    Ok((exit_status(&summary), true))
}

/// `shakeflow diagnose`: a `diagnose` stage over the case folders, run by the executor as
/// `shakeflow stage` is (all or nothing, cached): `out/diagnosis.json` for one case,
/// `out/<case>/diagnosis.json` for several.
fn diagnose_cases(cases: &[PathBuf], out: &Path, set: &[String]) -> anyhow::Result<ExitCode> {
    let params = set
        .iter()
        .map(|s| {
            let (key, value) = params::parse_set(s).map_err(anyhow::Error::msg)?;
            Ok((key, serde_yaml::to_value(value)?))
        })
        .collect::<anyhow::Result<_>>()?;
    let mut sources: indexmap::IndexMap<String, SourceSpec> = indexmap::IndexMap::new();
    let mut names: BTreeMap<String, &PathBuf> = BTreeMap::new();
    for dir in cases {
        if !dir.join("equipment.yaml").is_file() {
            let what = if dir.is_dir() { "has no `equipment.yaml`" } else { "is not a folder" };
            return Err(crate::error::UserError::new(format!("the case `{}` {what}", dir.display()))
                .hint("a case folder holds equipment.yaml, floor.csv, observed_accel.csv and observed_cpt.csv")
                .into());
        }
        let resolved = crate::pipeline::ownership::resolved(dir);
        let name = resolved.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        if let Some(other) = names.insert(name.clone(), dir) {
            bail!(
                "two cases are named `{name}`: `{}` and `{}`; the results of each are named by its folder, so diagnose them into different --out folders",
                other.display(),
                dir.display()
            );
        }
        let spec = serde_json::json!({"format": RecordFormat::Case, "path": dir.join("equipment.yaml").display().to_string(),
            "partition": {"case": name}});
        sources.insert(dir.display().to_string(), serde_json::from_value(spec)?);
    }
    let spec = command_spec(stages::Stage::info(&stages::diagnose::Diagnose).name, sources, params, out);
    let plan = Plan::for_command("shakeflow diagnose", spec, stages::registry())?;
    let (status, succeeded) = run_command_plan(&plan, out)?;
    if succeeded {
        for (name, dir) in &names {
            let contract = if names.len() == 1 { out.to_path_buf() } else { out.join(name) };
            let contract = contract.join(stages::diagnose::CONTRACT);
            let verdict = std::fs::read(&contract)
                .ok()
                .and_then(|bytes| serde_json::from_slice::<serde_json::Value>(&bytes).ok())
                .and_then(|d| d["verdict"].as_str().map(String::from))
                .unwrap_or_default();
            eprintln!("{}: {verdict} → {}", dir.display(), contract.display());
        }
    }
    Ok(status)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum ExecutorKind {
    Local,
    Slurm,
}

/// A run's exit status: 1 when a unit failed (each named), 2 when records were skipped.
fn exit_status(summary: &executor::RunSummary) -> ExitCode {
    for flagged in &summary.flagged {
        eprintln!(
            "skipped record: stage `{}` {}: {}",
            flagged.stage,
            crate::pipeline::work_units::describe(&flagged.unit),
            flagged.reason
        );
    }
    if !summary.failed.is_empty() {
        for failed in &summary.failed {
            eprintln!(
                "error: stage `{}` {} failed: {}",
                failed.stage,
                crate::pipeline::work_units::describe(&failed.unit),
                failed.reason
            );
        }
        eprintln!(
            "{} unit(s) failed; the units that finished were committed (`shakeflow status` says what is stale)",
            summary.failed.len()
        );
        return ExitCode::from(1);
    }
    if !summary.flagged.is_empty() {
        eprintln!(
            "{} record(s) skipped (on_error: skip); listed in each load stage's `flagged` table",
            summary.flagged.len()
        );
        return ExitCode::from(2);
    }
    ExitCode::SUCCESS
}
