//! Every stage type's documented example pipelines (`StageType::examples`, printed in
//! docs/stages.md) run on the data they name: a copy with the shared folder's and the demo
//! archive's paths made absolute runs in a temporary folder, and the stage shown writes every
//! table it declares. Where an example shows a finding, the finding is checked too.

use crate::common::{shakeflow, shared_dir, stderr};
use shakeflow::io::parquet::read_table;
use shakeflow::stages::{stage_types, OutputKind};
use shakeflow::table::ColumnData;
use std::path::{Path, PathBuf};

/// The demo archive the camera examples read, written by the library into the test scratch
/// folder when not current.
fn demo_archive() -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("stage-examples-archive");
    if !shakeflow::demo::archive::is_current(&dir) {
        shakeflow::demo::archive::write_demo_archive(&dir).expect("the demo archive is written");
    }
    dir
}

/// The table `out/<stage>/<output>` of a single-record output, or every record's parts read in
/// order of their partition paths.
fn tables(out: &Path, stage: &str, output: &str) -> Vec<shakeflow::table::Table> {
    let mut files = Vec::new();
    let mut stack = vec![out.join(stage).join(output)];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap().flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if path.file_name().is_some_and(|n| n == "data.parquet") {
                files.push(path);
            }
        }
    }
    files.sort();
    files.iter().map(|f| read_table(f).unwrap()).collect()
}

/// The first value of a float column (`None`: missing).
fn first(table: &shakeflow::table::Table, name: &str) -> Option<f64> {
    match &table.column(name).unwrap_or_else(|| panic!("no column `{name}`")).data {
        ColumnData::F64(v) => v.first().copied(),
        ColumnData::OptF64(v) => v[0],
        other => panic!("`{name}` is {other:?}"),
    }
}

/// What the examples that show a finding found: detect_toppling's four overturned rocking units
/// (at the shared truth files' `overturn_time_s`: 18.00, 5.87, 5.744, 7.155 s) and no cart;
/// transfer_function's 1.0 Hz frame (truth `fundamental_period_s: 1.0`); diagnose's verdict on
/// demo_02 (truth `expected_verdict: mass_change`).
fn check_finding(stage: &str, out: &Path) {
    match stage {
        "detect_toppling" => {
            let found: Vec<Option<f64>> =
                tables(out, stage, "events").iter().map(|t| first(t, "impact_time_s")).collect();
            assert_eq!(found.len(), 8, "{found:?}");
            for (at, truth) in found[..4].iter().zip([17.9999, 5.87, 5.744, 7.155]) {
                assert!(at.is_some_and(|at| (at - truth).abs() < 0.05), "{found:?}");
            }
            assert!(found[4..].iter().all(Option::is_none), "a cart toppled: {found:?}");
        }
        "transfer_function" => {
            let identified = &tables(out, stage, "identified")[0];
            let (f, coherence) = (first(identified, "frequency_hz"), first(identified, "coherence"));
            assert!(
                f.is_some_and(|f| (f - 1.0).abs() < 0.05) && coherence.is_some_and(|c| c > 0.8),
                "{f:?} Hz, coherence {coherence:?}"
            );
        }
        "diagnose" => {
            let diagnosis = &tables(out, stage, "diagnosis")[0];
            let verdict = match &diagnosis.column("verdict").expect("a `verdict` column").data {
                ColumnData::Str(v) => v[0].clone(),
                other => panic!("`verdict` is {other:?}"),
            };
            assert_eq!(verdict, "mass_change");
        }
        _ => {}
    }
}

/// Whether `dir` holds a `data.parquet` at any depth.
fn has_table(dir: &Path) -> bool {
    std::fs::read_dir(dir).into_iter().flatten().flatten().any(|e| {
        let path = e.path();
        path.file_name().is_some_and(|n| n == "data.parquet") || (path.is_dir() && has_table(&path))
    })
}

#[test]
fn every_stage_example_runs() {
    let mut ran = Vec::new();
    for stage in stage_types() {
        let info = stage.info();
        let mut written = std::collections::BTreeSet::new();
        for example in stage.examples() {
            let dir = crate::tempdir::tempdir().unwrap();
            let shared = shared_dir().display().to_string();
            let mut pipeline = example.pipeline().replace("../shared", &shared);
            if pipeline.contains("runs/demo-archive") {
                pipeline = pipeline.replace("runs/demo-archive", &demo_archive().display().to_string());
            }
            assert!(
                pipeline.contains(&format!("\n  {}:\n    type: {}\n", info.name, info.name)),
                "{}: an example names the stage it shows as its type",
                info.name
            );
            std::fs::write(dir.path().join("pipeline.yaml"), pipeline).unwrap();
            let out = shakeflow(&["run", "pipeline.yaml"], dir.path());
            assert!(out.status.success(), "{} example `{}`: {}", info.name, example.title, stderr(&out));
            let out = dir.path().join("out");
            written
                .extend(info.outputs.iter().filter(|o| has_table(&out.join(info.name).join(o.name))).map(|o| o.name));
            check_finding(info.name, &out);
            ran.push(info.name);
        }
        // Each declared table is written by one example at least (`load`'s `flagged` only under
        // `on_error: skip`, so by its second).
        for output in info.outputs.iter().filter(|o| matches!(o.kind, OutputKind::Table | OutputKind::TimeSeries)) {
            assert!(
                stage.examples().is_empty() || written.contains(output.name),
                "no example of {} wrote its `{}` table",
                info.name,
                output.name
            );
        }
    }
    // Every stage type has an example.
    for stage in stage_types().iter().map(|s| s.info().name) {
        assert!(ran.contains(&stage), "`{stage}` has no example");
    }
}
