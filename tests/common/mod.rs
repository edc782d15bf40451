//! Helpers shared by the integration tests: run the real binary, build small pipelines.
#![allow(dead_code)] // each test binary uses a different subset

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn shakeflow(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_shakeflow"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("the shakeflow binary runs")
}

pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

pub fn stdout(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// `../shared` beside the project root: real records and demo cases. Its absence is a failure, never a skip.
pub fn shared_dir() -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared");
    assert!(
        dir.join("data/ground_motions").is_dir(),
        "the shared data folder `{}` is missing: tests need ../shared/data/ground_motions beside the project root",
        dir.display()
    );
    dir
}

pub fn ground_motion(name: &str) -> PathBuf {
    shared_dir().join("data/ground_motions").join(name)
}

/// The interpreter with the reference packages (`make test` sets SHAKEFLOW_PYTHON to its venv).
pub fn python() -> String {
    std::env::var("SHAKEFLOW_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// Runs a reference script; its failure (including a missing package) fails the test.
pub fn run_python(script: &Path, args: &[&str]) -> String {
    let out = Command::new(python())
        .arg(script)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot start {}: {e}; run the tests through `make test`", python()));
    assert!(
        out.status.success(),
        "{} failed (run the tests through `make test`, which installs numpy/scipy/pyarrow/mcap/duckdb):\n{}\n{}",
        script.display(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

pub fn reference_script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/reference").join(name)
}

/// A CSV record like a DAQ export: 2 header lines, a column-name row, `n` rows at `rate` Hz.
pub fn write_daq_csv(path: &Path, n: usize, rate: f64, phase: f64) {
    let mut text = String::from("# synthetic test record\n# units: g\nTime,EW,NS\n");
    for i in 0..n {
        let t = i as f64 / rate;
        let ew = 0.1 * (2.0 * std::f64::consts::PI * 1.5 * t + phase).sin() + 0.01 + 0.001 * t;
        let ns = 0.02 * (2.0 * std::f64::consts::PI * 3.0 * t).cos();
        text.push_str(&format!("{t:.6},{ew:.6e},{ns:.6e}\n"));
    }
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, text).unwrap();
}

pub const PIPELINE: &str = "\
version: 1
output_dir: out
inputs:
  daq:
    format: csv
    path: archive/{motion}/daq.csv
    header_lines: 2
    time_column: Time
    unit: g
    columns:
      ax_mps2: EW
      ay_mps2: NS
stages:
  load:
    type: load
    inputs: [daq]
  baseline:
    type: baseline
    inputs: [load]
    params:
      order: 3
";

/// A project folder with the pipeline above and two motions of 400 samples each.
pub fn small_project() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("pipeline.yaml"), PIPELINE).unwrap();
    write_daq_csv(&dir.path().join("archive/FB-1/daq.csv"), 400, 200.0, 0.0);
    write_daq_csv(&dir.path().join("archive/FB-2/daq.csv"), 400, 200.0, 1.0);
    dir
}

/// Every file below `dir` with its bytes, for before/after comparisons.
pub fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    fn walk(dir: &Path, out: &mut Vec<(PathBuf, Vec<u8>)>) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        for entry in entries {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(&path, out);
            } else {
                out.push((path.clone(), std::fs::read(&path).unwrap()));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, &mut out);
    out.sort();
    out
}
