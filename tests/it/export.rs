//! `shakeflow export` and `show` as a data engineer uses them: a partitioned stage output (one
//! partition value percent-encoded, one partition lacking a column) exported to CSV and Parquet
//! and read back by independent readers — pyarrow, DuckDB, polars, Python's csv module, and R
//! (`read.csv`, `data.table::fread`) — with units and provenance from `<stem>.meta.json`; the
//! README's Python and R snippets run as written; bad arguments get clear errors.
use crate::common;
use common::*;
use std::path::Path;
use std::process::Command;

/// Two sources into one `load`: `daq` (two channels; motions FB-1 and `090 (CUE)`) and `extra`
/// (one channel, files named otherwise; WN-1), so `ay_mps2` is missing from one partition.
const PIPELINE: &str = "\
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
  extra:
    format: csv
    path: extra/{motion}/wn.csv
    header_lines: 2
    time_column: Time
    unit: g
    columns:
      ax_mps2: EW
stages:
  load:
    type: load
    inputs: [daq, extra]
";

fn project() -> crate::tempdir::TempDir {
    let dir = crate::tempdir::tempdir().unwrap();
    std::fs::write(dir.path().join("pipeline.yaml"), PIPELINE).unwrap();
    write_daq_csv(&dir.path().join("archive/FB-1/daq.csv"), 300, 200.0, 0.0);
    write_daq_csv(&dir.path().join("archive/090 (CUE)/daq.csv"), 200, 200.0, 1.0);
    write_daq_csv(&dir.path().join("extra/WN-1/wn.csv"), 100, 200.0, 2.0);
    let out = shakeflow(&["run", "pipeline.yaml"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    dir
}

/// `Rscript`, or a failure that says how to get it (never a skip).
fn rscript() -> &'static str {
    let found = Command::new("Rscript").arg("--version").output().is_ok_and(|o| o.status.success());
    assert!(
        found,
        "R is not installed: the export tests read CSV exports with R. Run `make test` as root (it runs \
         tests/system/install-r.sh), or install it: sudo apt-get install r-base-core r-cran-data.table r-cran-jsonlite"
    );
    "Rscript"
}

fn run_r(script: &Path, args: &[&str], cwd: &Path) -> String {
    let out = Command::new(rscript()).arg(script).args(args).current_dir(cwd).output().unwrap();
    assert!(
        out.status.success(),
        "{} failed (a missing R package? `make test` installs them as root, tests/system/install-r.sh; or: \
         sudo apt-get install r-base-core r-cran-data.table r-cran-jsonlite):\n{}\n{}",
        script.display(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn an_export_reads_the_same_in_pyarrow_duckdb_polars_and_r() {
    let dir = project();
    let root = dir.path();
    let csv = shakeflow(&["export", "out/load/records", "--out", "exports/records.csv"], root);
    assert!(csv.status.success(), "{}", stderr(&csv));
    // The partition lacking `ay_mps2` is named in the warning.
    let warning = stderr(&csv);
    assert!(warning.contains("`ay_mps2`") && warning.contains("load.records/motion=WN-1"), "{warning}");
    assert!(stdout(&csv).contains("600 rows × 4 columns"), "{}", stdout(&csv));
    let parquet = shakeflow(&["export", "out/load/records", "--out", "exports/parquet/records.parquet"], root);
    assert!(parquet.status.success(), "{}", stderr(&parquet));
    let text = std::fs::read_to_string(root.join("exports/records.csv")).unwrap();
    assert!(text.starts_with("motion,time_s,ax_mps2,ay_mps2\r\n"), "{}", &text[..80]);
    assert!(text.contains("\r\n090 (CUE),") && text.contains(",NA\r\n"), "keys decoded, NA for null");
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root.join("exports/records.meta.json")).unwrap()).unwrap();
    assert_eq!(meta["columns"]["ax_mps2"]["unit"], "m/s^2");
    assert_eq!(meta["provenance"][0]["stage"], "load");
    // `load`'s descriptions hold for every record (the files are named differently): one each.
    for column in ["ax_mps2", "ay_mps2"] {
        assert!(meta["columns"][column].get("descriptions").is_none(), "{column}: {}", meta["columns"][column]);
    }

    run_r(&reference_script("export_check.R"), &["exports/records.csv", "r_read_csv.csv", "r_fread.csv"], root);
    let csv_path = root.join("exports/records.csv");
    let report = run_python(
        &reference_script("export_check.py"),
        &[
            "--dataset",
            root.join("out/load/records").to_str().unwrap(),
            "--csv",
            csv_path.to_str().unwrap(),
            "--parquet",
            root.join("exports/parquet/records.parquet").to_str().unwrap(),
            "--r-dump",
            root.join("r_read_csv.csv").to_str().unwrap(),
            root.join("r_fread.csv").to_str().unwrap(),
        ],
    );
    assert!(report.contains("ok: 600 rows x 4 columns"), "{report}");
    // Bit-identical exports for identical inputs.
    let again = shakeflow(&["export", "out/load/records", "--out", "exports/again.csv"], root);
    assert!(again.status.success());
    assert_eq!(text, std::fs::read_to_string(root.join("exports/again.csv")).unwrap());
}

#[test]
fn the_readme_python_and_r_snippets_run_as_written() {
    let dir = project();
    let root = dir.path();
    // The snippets read exports/summary.csv: here, the load output stands in for the summary.
    let out = shakeflow(&["export", "out/load/records", "--out", "exports/summary.csv"], root);
    assert!(out.status.success(), "{}", stderr(&out));
    std::fs::write(root.join("snippet.R"), readme_block("## Python and R", "r")).unwrap();
    let r = run_r(&root.join("snippet.R"), &[], root);
    assert!(r.contains("m/s^2"), "the R snippet shows the units:\n{r}");
    std::fs::write(root.join("snippet.py"), readme_block("## Python and R", "python")).unwrap();
    let out = Command::new(python()).arg("snippet.py").current_dir(root).output().unwrap();
    assert!(out.status.success(), "README's Python snippet failed:\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("m/s^2"), "{}", String::from_utf8_lossy(&out.stdout));
}

#[test]
fn show_prints_every_partition_with_its_keys_and_as_csv() {
    let dir = project();
    let root = dir.path();
    let table = shakeflow(&["show", "out/load/records", "--rows", "3"], root);
    assert!(table.status.success(), "{}", stderr(&table));
    assert!(stdout(&table).contains("motion") && stdout(&table).contains("090 (CUE)"), "{}", stdout(&table));
    let csv = shakeflow(&["show", "out/load/records", "--csv", "--columns", "motion,ay_mps2"], root);
    assert!(csv.status.success(), "{}", stderr(&csv));
    let text = stdout(&csv);
    assert!(text.starts_with("motion,ay_mps2\r\n"), "{text}");
    assert_eq!(text.lines().count(), 601, "every row with --csv");
    assert!(text.contains("WN-1,NA\r\n"));
    assert!(stderr(&csv).contains("`ay_mps2`"), "the missing column is said: {}", stderr(&csv));
}

/// A table written as a stage would write it: provenance and partition metadata, `v` in `unit`.
fn fake_part(path: &Path, stage: &str, partition: &str, unit: &str, description: &str) {
    use shakeflow::table::{Column, Table};
    let mut t = Table::new();
    t.push(Column::f64("v", unit, description, vec![1.0, 2.0]));
    for (k, v) in [("shakeflow.stage", stage), ("shakeflow.output", "o"), ("shakeflow.partition", partition)] {
        t.metadata.insert(k.into(), v.into());
    }
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    shakeflow::io::parquet::write_table(path, &t).unwrap();
}

#[test]
fn bad_arguments_are_refused_with_what_to_do() {
    let dir = project();
    let root = dir.path();
    let refused = |args: &[&str], expected: &[&str]| {
        let out = shakeflow(args, root);
        assert!(!out.status.success(), "{args:?} succeeded");
        let err = stderr(&out);
        for e in expected {
            assert!(err.contains(e), "{args:?}: `{e}` not in\n{err}");
        }
        assert!(!err.contains("panicked"), "{err}");
    };
    refused(&["export", "out/load/nothing", "--out", "t.csv"], &["no such file or folder", "out/load/nothing"]);
    refused(&["export", "out/load/records", "--out", "t.xlsx"], &["`.xlsx`", ".csv", ".parquet"]);
    refused(&["export", "archive", "--out", "t.csv"], &["not a shakeflow output", "data.parquet"]);
    refused(&["export", "pipeline.yaml", "--out", "t.csv"], &["not a shakeflow output"]);
    refused(&["export", "out/load", "--out", "out/load/records/t.csv"], &["inside the dataset"]);
    fake_part(&root.join("mixed/k=a/data.parquet"), "s", "k=a", "m", "a value");
    fake_part(&root.join("mixed/k=b/data.parquet"), "s", "k=b", "mm", "a value");
    refused(&["export", "mixed", "--out", "t.csv"], &["column `v`", "`m`", "`mm`", "s.o/k=b", "one unit"]);
    refused(&["export", "out/load/records", "out/load/records", "--out", "t.csv"], &["named twice"]);
    assert!(!root.join("t.csv").exists() && !root.join("t.meta.json").exists(), "nothing written");
    let help = shakeflow(&["export", "--help"], root);
    assert!(stdout(&help).contains("shakeflow export runs/demo/report/summary --out exports/summary.csv"));
}

#[test]
fn descriptions_that_differ_by_partition_are_given_per_partition() {
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    fake_part(&root.join("d/k=a/data.parquet"), "s", "k=a", "m", "height of a");
    fake_part(&root.join("d/k=b/data.parquet"), "s", "k=b", "m", "height of b");
    let out = shakeflow(&["export", "d", "--out", "t.parquet"], root);
    assert!(out.status.success(), "{}", stderr(&out));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root.join("t.meta.json")).unwrap()).unwrap();
    let v = &meta["columns"]["v"];
    assert_eq!(v["unit"], "m");
    assert!(v["description"].as_str().unwrap().contains("differs by partition"), "{v}");
    assert_eq!(v["descriptions"]["s.o/k=a"], "height of a");
    assert_eq!(v["descriptions"]["s.o/k=b"], "height of b");
}

#[test]
fn outputs_of_several_stages_are_told_apart_by_a_stage_column() {
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    fake_part(&root.join("one/k=a/data.parquet"), "first", "k=a", "m", "v");
    fake_part(&root.join("two/k=a/data.parquet"), "second", "k=a", "m", "v");
    let out = shakeflow(&["export", "one", "two", "--out", "t.csv"], root);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = std::fs::read_to_string(root.join("t.csv")).unwrap();
    assert_eq!(text, "stage,k,v\r\nfirst,a,1.0\r\nfirst,a,2.0\r\nsecond,a,1.0\r\nsecond,a,2.0\r\n");
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root.join("t.meta.json")).unwrap()).unwrap();
    assert_eq!(meta["provenance"].as_array().unwrap().len(), 2);
}
