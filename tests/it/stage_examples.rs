//! Every stage type's documented example pipelines (`StageType::examples`, printed in
//! docs/stages.md) run on the shared records: a copy with the shared folder's path made absolute
//! runs in a temporary folder, and the stage shown writes every table it declares.

use crate::common::{shakeflow, shared_dir, stderr};
use shakeflow::stages::{stage_types, OutputKind};
use std::path::Path;

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
        for example in stage.examples() {
            let dir = crate::tempdir::tempdir().unwrap();
            let shared = shared_dir().display().to_string();
            let pipeline = example.pipeline().replace("../shared", &shared);
            assert!(
                pipeline.contains(&format!("\n  {}:\n    type: {}\n", info.name, info.name)),
                "{}: an example names the stage it shows as its type",
                info.name
            );
            std::fs::write(dir.path().join("pipeline.yaml"), pipeline).unwrap();
            let out = shakeflow(&["run", "pipeline.yaml"], dir.path());
            assert!(out.status.success(), "{} example `{}`: {}", info.name, example.title, stderr(&out));
            for output in info.outputs.iter().filter(|o| matches!(o.kind, OutputKind::Table | OutputKind::TimeSeries)) {
                let folder = dir.path().join("out").join(info.name).join(output.name);
                assert!(
                    has_table(&folder),
                    "{} example `{}` wrote no `{}` table",
                    info.name,
                    example.title,
                    output.name
                );
            }
            ran.push(info.name);
        }
    }
    // The stages whose examples this file was written with; more may come, none may go silently.
    for name in
        ["baseline", "synchronize", "simulate_toppling", "toppling_fragility", "simulate_rolling", "compare", "report"]
    {
        assert!(ran.contains(&name), "`{name}` lost its example");
    }
}
