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

/// The fenced block of `language` under README.md's `section` heading (e.g. "## Python and R"):
/// tests run README's snippets as written.
pub fn readme_block(section: &str, language: &str) -> String {
    let readme = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md")).unwrap();
    let body = readme.split(section).nth(1).unwrap_or_else(|| panic!("README.md has a `{section}` section"));
    let body = &body[..body.find("\n## ").unwrap_or(body.len())];
    let fence = format!("```{language}\n");
    let start = body.find(&fence).unwrap_or_else(|| panic!("no ```{language} block under `{section}`"));
    let block = &body[start + fence.len()..];
    block[..block.find("```").unwrap()].to_string()
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

/// Sets a file's modification time to `when` (as `touch -d` would): a file older than the hash
/// memo's 2 s is remembered.
pub fn set_mtime(path: &Path, when: std::time::SystemTime) {
    std::fs::File::options().write(true).open(path).unwrap().set_modified(when).unwrap();
}

/// A project folder with the pipeline above and two motions of 400 samples each.
pub fn small_project() -> crate::tempdir::TempDir {
    let dir = crate::tempdir::tempdir().unwrap();
    std::fs::write(dir.path().join("pipeline.yaml"), PIPELINE).unwrap();
    write_daq_csv(&dir.path().join("archive/FB-1/daq.csv"), 400, 200.0, 0.0);
    write_daq_csv(&dir.path().join("archive/FB-2/daq.csv"), 400, 200.0, 1.0);
    dir
}

/// [`PIPELINE`] with `baseline`'s opt-in MCAP twins on.
pub fn pipeline_with_twins() -> String {
    let text = PIPELINE.replace("      order: 3\n", "      order: 3\n      mcap: true\n");
    assert_ne!(text, PIPELINE);
    text
}

/// A [`small_project`] run locally: the reference a run elsewhere (Slurm, another node) must match.
pub fn small_project_run_locally() -> crate::tempdir::TempDir {
    let dir = small_project();
    let out = shakeflow(&["run", "pipeline.yaml"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    dir
}

/// [`small_project`] whose `baseline` also writes MCAP twins.
pub fn small_project_with_twins() -> crate::tempdir::TempDir {
    let dir = small_project();
    std::fs::write(dir.path().join("pipeline.yaml"), pipeline_with_twins()).unwrap();
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

/// Every file of `root/out` with its bytes (paths from `root`): the artifacts, the lockfile and
/// the per-stage state files, not shakeflow's working files (lease, hash memo, Slurm runs).
/// What every executor must leave the same.
pub fn artifacts_and_state(root: &Path) -> Vec<(String, Vec<u8>)> {
    snapshot(&root.join("out"))
        .into_iter()
        .map(|(p, b)| (p.strip_prefix(root).unwrap().display().to_string(), b))
        .filter(|(p, _)| !p.starts_with("out/.shakeflow") || p.starts_with("out/.shakeflow/state/"))
        .collect()
}

/// Every stage's state in `out` (the lockfile and the state files it names) as one YAML value:
/// `stages.<stage>.units.<unit>.files`…
pub fn state_yaml(out: &Path) -> serde_yaml::Value {
    let lock = shakeflow::pipeline::lock::LockFile::read(&out.join("shakeflow.lock")).unwrap();
    serde_yaml::to_value(&lock).unwrap()
}

/// Runs the binary with extra environment variables.
pub fn shakeflow_env(args: &[&str], cwd: &Path, env: &[(&str, &str)]) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_shakeflow"));
    command.args(args).current_dir(cwd);
    for (k, v) in env {
        command.env(k, v);
    }
    command.output().expect("the shakeflow binary runs")
}

/// A small camera (80 × 60 px, f = 70 px) for CPT test projects.
pub fn cpt_test_camera() -> shakeflow::vision::camera::Camera {
    use shakeflow::vision::camera::{Camera, Intrinsics};
    let k = Intrinsics { fx: 70.0, fy: 70.0, skew: 0.0, cx: 40.0, cy: 30.0 };
    Camera::look_at(k, [200.0, -3000.0, 2000.0], [0.0, 0.0, 300.0], 0.0, 0.0)
}

pub const CPT_PIPELINE: &str = "\
version: 1
output_dir: out
inputs:
  survey:
    format: control_points
    path: control_points.csv
  video:
    format: frames
    path: frames
stages:
  calibrate:
    type: cpt_calibrate
    inputs: [survey]
  track:
    type: cpt_track
    inputs: [video]
    params:
      fps: 30
      points: \"40,30\"
      window_px: 12
      search_px: 30
  project:
    type: cpt_project
    inputs: [track, calibrate.calibration]
    params:
      plane: \"0,0,1,0\"
";

/// Writes `n` speckle frames (80 × 60) whose centre plate moves by 0.25 px per frame.
pub fn write_cpt_frames(dir: &Path, n: usize) {
    use shakeflow::vision::synthetic::{Layer, SpeckleScene};
    std::fs::create_dir_all(dir).unwrap();
    let scene = SpeckleScene::with_textures(80, 60, 2, 5);
    for k in 0..n {
        let plate = Layer { texture: 1, rect: Some([20.0, 15.0, 60.0, 45.0]), shift: [0.25 * k as f64, 0.0] };
        let image = scene.render(&[Layer::background([0.0, 0.0]), plate], 1.0, k as u64);
        let mut png = Vec::new();
        {
            let mut encoder = png::Encoder::new(&mut png, 80, 60);
            encoder.set_color(png::ColorType::Grayscale);
            let mut writer = encoder.write_header().unwrap();
            writer.write_image_data(&image.pixels).unwrap();
        }
        std::fs::write(dir.join(format!("f{k:04}.png")), png).unwrap();
    }
}

/// A CPT project: 12 control points seen by `cpt_test_camera`, 6 frames, the pipeline above.
pub fn cpt_project() -> crate::tempdir::TempDir {
    let dir = crate::tempdir::tempdir().unwrap();
    let camera = cpt_test_camera();
    let mut text = String::from("point,X_mm,Y_mm,Z_mm,u_px,v_px\n");
    let world = [
        [-800.0, -600.0, 0.0],
        [0.0, -900.0, 0.0],
        [800.0, -500.0, 0.0],
        [-700.0, 600.0, 0.0],
        [700.0, 700.0, 0.0],
        [0.0, 200.0, 0.0],
        [-900.0, 1000.0, 900.0],
        [0.0, 1000.0, 1200.0],
        [900.0, 1000.0, 600.0],
        [-400.0, 0.0, 700.0],
        [500.0, -200.0, 500.0],
        [200.0, 500.0, 1000.0],
    ];
    for (k, w) in world.iter().enumerate() {
        let [u, v] = camera.project(w).unwrap();
        text.push_str(&format!("C{},{},{},{},{u:.4},{v:.4}\n", k + 1, w[0], w[1], w[2]));
    }
    std::fs::write(dir.path().join("control_points.csv"), text).unwrap();
    write_cpt_frames(&dir.path().join("frames"), 6);
    std::fs::write(dir.path().join("pipeline.yaml"), CPT_PIPELINE).unwrap();
    dir
}

/// The configuration of the test Slurm (`SLURM_CONF` for commands that should use it):
/// `$SHAKEFLOW_SLURM_DIR/slurm.conf`, by default under ~/.cache/shakeflow/slurm, as `tests/system/slurm.sh` writes it.
pub fn test_slurm_conf() -> PathBuf {
    let dir = std::env::var_os("SHAKEFLOW_SLURM_DIR").map(PathBuf::from).unwrap_or_else(|| {
        PathBuf::from(std::env::var_os("HOME").expect("HOME is set")).join(".cache/shakeflow/slurm")
    });
    dir.join("slurm.conf")
}

/// The test Slurm that `tests/system/slurm.sh start` runs (`make test` starts and stops it): a
/// client pointed at its configuration. Its absence fails the test, saying how to start it.
pub fn test_slurm() -> shakeflow::pipeline::slurm::Slurm {
    let conf = test_slurm_conf();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/system/slurm.sh");
    let answers = conf.is_file()
        && Command::new("scontrol").arg("ping").env("SLURM_CONF", &conf).output().is_ok_and(|o| o.status.success());
    assert!(
        answers,
        "the test Slurm is not running (no controller answers for {}): start it with `{} start` as root \
         (it installs slurm-wlm and munge), or run the tests through `make test`, which starts and stops it",
        conf.display(),
        script.display()
    );
    shakeflow::pipeline::slurm::Slurm::with_conf(conf)
}

/// A DAQ file of the demo archive, read here without shakeflow's readers: NEES tab-delimited
/// text, a 4-line preamble, then the name (line 5), description (6) and units (7) rows, then data.
pub struct DemoDaq {
    pub preamble: Vec<String>,
    pub names: Vec<String>,
    pub descriptions: Vec<String>,
    pub units: Vec<String>,
    /// The data rows, numbers as written.
    pub rows: Vec<Vec<f64>>,
    /// The time cells as written.
    pub times: Vec<String>,
}

impl DemoDaq {
    /// The file at `path` below the archive `archive` (the manifest's `daq1_file`/`daq2_file`).
    pub fn read(archive: &Path, path: &str) -> DemoDaq {
        let full = archive.join(path);
        let text = std::fs::read_to_string(&full).unwrap_or_else(|e| panic!("cannot read {}: {e}", full.display()));
        let mut lines = text.lines();
        let mut row = || lines.next().unwrap().split('\t').map(String::from).collect::<Vec<String>>();
        let preamble: Vec<String> = (0..4).map(|_| row().join("\t")).collect();
        let (names, descriptions, units) = (row(), row(), row());
        let (mut rows, mut times) = (Vec::new(), Vec::new());
        for line in lines {
            let cells: Vec<&str> = line.split('\t').collect();
            assert_eq!(cells.len(), names.len(), "{}: a row of {} cells: {line}", full.display(), cells.len());
            times.push(cells[0].to_string());
            rows.push(cells.iter().map(|c| c.parse::<f64>().unwrap()).collect());
        }
        DemoDaq { preamble, names, descriptions, units, rows, times }
    }

    pub fn index(&self, name: &str) -> usize {
        self.names.iter().position(|n| n == name).unwrap_or_else(|| panic!("no column {name} in {:?}", self.names))
    }

    /// A column as written.
    pub fn column(&self, name: &str) -> Vec<f64> {
        let k = self.index(name);
        self.rows.iter().map(|r| r[k]).collect()
    }

    /// An acceleration column in g: in/sec^2 ÷ (9.80665 / 0.0254), g as written, volts through
    /// the archive's sensitivity table (`channel,sensitivity,unit,offset`, V per g).
    pub fn g(&self, name: &str, archive: &Path) -> Vec<f64> {
        let values = self.column(name);
        match self.units[self.index(name)].as_str() {
            "g" => values,
            "in/sec^2" => values.iter().map(|v| v * 0.0254 / 9.80665).collect(),
            "V" => {
                let table = std::fs::read_to_string(archive.join(shakeflow::demo::archive::SENSITIVITY_FILE)).unwrap();
                let row = table
                    .lines()
                    .find_map(|l| l.strip_prefix(&format!("{name},")))
                    .unwrap_or_else(|| panic!("no sensitivity for {name}"));
                let cells: Vec<&str> = row.split(',').collect();
                let (sensitivity, offset): (f64, f64) = (cells[0].parse().unwrap(), cells[2].parse().unwrap());
                assert_eq!(cells[1], "g");
                values.iter().map(|v| (v - offset) / sensitivity).collect()
            }
            other => panic!("{name}: unexpected unit {other}"),
        }
    }
}
