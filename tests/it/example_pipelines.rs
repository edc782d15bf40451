//! Every example pipeline in `pipelines/` (but `demo.yaml`, which the demo tests run on the
//! generated archive) runs end to end: a copy of it, with its input paths made absolute, writes
//! into a temporary output folder (`output_dir` is relative to the pipeline, and an output folder
//! holding inputs would be refused).

use crate::common::{shakeflow, stderr};
use shakeflow::table::Table;
use std::path::{Path, PathBuf};

fn pipelines_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("pipelines")
}

/// `pipeline` copied into `dir` with `output_dir: out` and every relative `path:` or
/// `calibration:` made absolute against the pipelines folder.
fn relocated(pipeline: &Path, dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(pipeline).unwrap();
    let base = pipeline.parent().unwrap();
    let mut out = String::new();
    for line in text.lines() {
        let trimmed = line.trim_start();
        let indent = &line[..line.len() - trimmed.len()];
        let moved = ["output_dir: ", "path: ", "calibration: "].iter().find_map(|key| {
            let value = trimmed.strip_prefix(key)?;
            Some(if *key == "output_dir: " {
                "output_dir: out".to_string()
            } else {
                format!("{key}{}", base.join(value).display())
            })
        });
        out.push_str(&format!("{indent}{}\n", moved.as_deref().unwrap_or(trimmed)));
    }
    let copy = dir.join(pipeline.file_name().unwrap());
    std::fs::write(&copy, out).unwrap();
    copy
}

fn read(dir: &Path, part: &str) -> Table {
    let path = dir.join("out").join(part).join("data.parquet");
    shakeflow::io::parquet::read_table(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn every_example_pipeline_validates_and_runs() {
    let mut names: Vec<PathBuf> = std::fs::read_dir(pipelines_dir())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "yaml") && !p.ends_with("demo.yaml"))
        .collect();
    names.sort();
    let found: Vec<String> = names.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    assert_eq!(found, ["nees.yaml", "suite.yaml"], "new examples: give them a check below");
    for pipeline in &names {
        let dir = crate::tempdir::tempdir().unwrap();
        let copy = relocated(pipeline, dir.path());
        let copy = copy.to_str().unwrap();
        for command in ["validate", "run"] {
            let out = shakeflow(&[command, copy], dir.path());
            assert!(out.status.success(), "{command} {}: {}", pipeline.display(), stderr(&out));
        }
        let spec: serde_yaml::Value = serde_yaml::from_str(&std::fs::read_to_string(pipeline).unwrap()).unwrap();
        for stage in spec["stages"].as_mapping().unwrap().keys() {
            let stage = stage.as_str().unwrap();
            assert!(dir.path().join("out").join(stage).is_dir(), "{}: no output of {stage}", pipeline.display());
        }
        match pipeline.file_name().unwrap().to_str().unwrap() {
            // The raw DAQ file, calibrated, is the converted file: they differ by the raw file's
            // 6 decimals of volts (8e-7 g / 1.25 V/g) and whole counts (1/3276.8 in).
            "nees.yaml" => {
                for trial in [1, 2] {
                    let part = |name: &str| format!("load/records/experiment=1/trial={trial}/rep=1/name={name}");
                    let (raw, converted) = (read(dir.path(), &part("daq")), read(dir.path(), &part("table")));
                    for (column, tolerance) in [("ax_mps2", 1e-5), ("ay_mps2", 1e-5), ("dx_m", 1e-5)] {
                        let (a, b) = (raw.f64_column(column).unwrap(), converted.f64_column(column).unwrap());
                        let worst = a.iter().zip(b).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
                        assert!(worst < tolerance, "trial {trial} {column}: raw vs converted differ by {worst}");
                    }
                }
            }
            // 7 AT2 and 2 K-NET records, each scaled to 6 levels.
            "suite.yaml" => {
                let fragility = read(dir.path(), "fragility/fragility");
                let runs = &fragility.column("n_runs").unwrap().data;
                assert!(matches!(runs, shakeflow::table::ColumnData::I64(n) if n == &[54]), "{runs:?}");
            }
            other => unreachable!("{other}"),
        }
    }
}
