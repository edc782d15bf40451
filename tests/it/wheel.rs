//! The Python wheel (pyproject.toml, docs/packaging.md) as a user without Rust meets it: `make
//! test` builds it with maturin before the tests (SHAKEFLOW_WHEEL names it); here it goes into a
//! fresh venv whose PATH has no cargo, and README's "Your own records in five minutes" runs as
//! written with the installed `shakeflow`; `python -m shakeflow` runs the same binary.
//! examples/quickstart.ipynb runs top to bottom in that venv's PATH (nbclient), so it never rots.

use crate::common::{python, readme_block, write_daq_csv};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Instant;

/// The wheel `make test` built. Its absence fails the test, saying how to get it.
fn wheel() -> PathBuf {
    let path = std::env::var_os("SHAKEFLOW_WHEEL").map(PathBuf::from).unwrap_or_else(|| {
        panic!("SHAKEFLOW_WHEEL is not set: run the tests through `make test`, which builds the wheel (`make wheel-dev`) and sets it")
    });
    assert!(path.is_file(), "SHAKEFLOW_WHEEL={} is not a file: run `make wheel-dev` (or `make test`)", path.display());
    path
}

/// A PATH without cargo or rustc: the venv's scripts, then the system's own folders.
fn path_without_rust(venv: &Path) -> String {
    let path = format!("{}:/usr/local/bin:/usr/bin:/bin", venv.join("bin").display());
    for dir in path.split(':').skip(1) {
        assert!(
            !Path::new(dir).join("cargo").exists(),
            "{dir} has cargo: the wheel test must run without Rust on PATH"
        );
    }
    path
}

fn run(cmd: &mut Command) -> Output {
    let out = cmd.output().unwrap_or_else(|e| panic!("cannot start {cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{cmd:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A fresh venv (the reference interpreter's base Python, no packages) with only the wheel installed.
fn venv_with_wheel(dir: &Path) -> PathBuf {
    let base = String::from_utf8(run(Command::new(python()).args(["-c", "import sys; print(sys.base_prefix)"])).stdout)
        .unwrap();
    let base_python = Path::new(base.trim()).join("bin/python3");
    let venv = dir.join("venv");
    run(Command::new(&base_python).args(["-m", "venv", "--without-pip"]).arg(&venv));
    // pip from the reference venv installs into the new one: nothing but the wheel, from the file.
    run(Command::new(python())
        .args(["-m", "pip", "install", "--quiet", "--no-index", "--no-deps", "--disable-pip-version-check", "--prefix"])
        .arg(&venv)
        .arg(wheel()));
    venv
}

#[test]
fn the_wheel_installs_without_rust_and_runs_the_readme_example() {
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    let started = Instant::now();
    let venv = venv_with_wheel(root);
    let installed = started.elapsed();
    let path = path_without_rust(&venv);

    // README: the DAQ exports of "Your own records in five minutes", its pipeline, its commands.
    let section = "## Your own records in five minutes";
    write_daq_csv(&root.join("study/archive/FB-1/daq.csv"), 400, 200.0, 0.0);
    write_daq_csv(&root.join("study/archive/FB-2/daq.csv"), 400, 200.0, 1.0);
    std::fs::write(root.join("study/pipeline.yaml"), readme_block(section, "yaml")).unwrap();
    let commands: Vec<String> = readme_block(section, "sh")
        .lines()
        .map(|line| line.split(" #").next().unwrap().trim().to_string())
        .filter(|line| !line.is_empty())
        .collect();
    assert!(commands.len() >= 4 && commands.iter().all(|c| c.starts_with("shakeflow ")), "{commands:?}");
    let mut outputs = Vec::new();
    for command in &commands {
        let out = run(Command::new("sh").args(["-c", command]).current_dir(root).env_clear().env("PATH", &path));
        outputs.push(String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr));
    }
    let which = run(Command::new("sh").args(["-c", "command -v shakeflow"]).env_clear().env("PATH", &path));
    assert_eq!(String::from_utf8_lossy(&which.stdout).trim(), venv.join("bin/shakeflow").to_str().unwrap());
    assert!(root.join("runs/study/baseline/records/motion=FB-2/data.parquet").is_file(), "{outputs:#?}");
    assert!(outputs.iter().any(|o| o.contains("FB-1")), "show lists the motions: {outputs:#?}");
    eprintln!("wheel installed in {installed:.1?}; README example done {:.1?} after the start", started.elapsed());

    // `python -m shakeflow` is the same binary.
    let version = run(Command::new(venv.join("bin/python"))
        .args(["-m", "shakeflow", "--version"])
        .env_clear()
        .env("PATH", &path));
    assert!(String::from_utf8_lossy(&version.stdout).starts_with("shakeflow "), "{version:?}");
}

#[test]
fn the_example_notebook_runs_clean_with_the_installed_command() {
    let dir = crate::tempdir::tempdir().unwrap();
    let venv = venv_with_wheel(dir.path());
    let notebook = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/quickstart.ipynb");
    let records = crate::common::shared_dir().join("data/ground_motions");
    // The kernel is the reference interpreter (polars, pandas, pyarrow, matplotlib); `shakeflow`
    // on its PATH is the wheel's.
    let path = format!("{}:{}", venv.join("bin").display(), std::env::var("PATH").unwrap_or_default());
    let script = crate::common::reference_script("run_notebook.py");
    run(Command::new(python())
        .arg(script)
        .arg(&notebook)
        .env("PATH", path)
        .env("SHAKEFLOW_RECORDS", &records)
        .env("SHAKEFLOW_WORK", dir.path().join("work")));
    assert!(dir.path().join("work/record.png").is_file(), "the notebook drew its figure");
}
