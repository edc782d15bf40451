//! `simulate_toppling` and `toppling_fragility` as a user runs them: on a demo case's floor with
//! its own equipment file (the contract columns and the case's baseline verdict), in a pipeline
//! whose equipment file is edited (only that stage reruns), and with bad input (clear errors,
//! nothing written).
use crate::common;
use common::*;
use shakeflow::table::ColumnData;
use std::path::Path;

fn case_dir(id: &str) -> std::path::PathBuf {
    shared_dir().join("cases/demo").join(id)
}

fn read(path: &Path) -> shakeflow::table::Table {
    shakeflow::io::parquet::read_table(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn a_demo_case_through_the_stage_command() {
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    let floor = case_dir("demo_02").join("floor.csv");
    let equipment = case_dir("demo_02").join("equipment.yaml");
    let out = shakeflow(&["stage", "load", "--input", floor.to_str().unwrap(), "--output", "floor"], root);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = shakeflow(
        &[
            "stage",
            "simulate_toppling",
            "--input",
            "floor/records",
            "--output",
            "sim",
            "--set",
            &format!("equipment={}", equipment.display()),
            "--set",
            "vertical=az_mps2",
            "--set",
            "mcap=true",
        ],
        root,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let response = read(&root.join("sim/response/data.parquet"));
    for (name, unit) in [("time_s", "s"), ("theta_rad", "rad"), ("theta_dot_radps", "rad/s"), ("top_ax_mps2", "m/s^2")]
    {
        let column = response.column(name).unwrap_or_else(|| panic!("no `{name}`"));
        assert_eq!(column.unit, unit);
        assert!(!column.description.is_empty());
    }
    let events = read(&root.join("sim/events/data.parquet"));
    let last = events.num_rows() - 1;
    let ColumnData::Str(kinds) = &events.column("event").unwrap().data else { panic!() };
    assert_eq!(kinds[last], "summary");
    let ColumnData::Bool(overturned) = &events.column("overturned").unwrap().data else { panic!() };
    let ColumnData::OptF64(time) = &events.column("overturn_time_s").unwrap().data else { panic!() };
    let ColumnData::I64(side) = &events.column("overturn_side").unwrap().data else { panic!() };
    // ../shared/cases/demo/truth/demo_02.yaml, baseline: overturns to side 1 at 5.74469 s.
    assert!(overturned[last]);
    assert!((time[last].unwrap() - 5.74469).abs() < 0.01, "{:?}", time[last]);
    assert_eq!(side[last], 1);
    assert!(root.join("sim/figures/response.png").is_file());
    assert!(root.join("sim/mcap/response/data.mcap").is_file());
}

const PIPELINE: &str = "\
version: 1
output_dir: out
inputs:
  floor:
    format: csv
    path: floor.csv
    time_column: time_s
    unit: m/s^2
    columns:
      ax_mps2: ax_mps2
      az_mps2: az_mps2
stages:
  load:
    type: load
    inputs: [floor]
  rocking:
    type: simulate_toppling
    inputs: [load]
    params:
      equipment: unit.yaml
      vertical: az_mps2
  fragility:
    type: toppling_fragility
    inputs: [load]
    params:
      equipment: unit.yaml
      vertical: az_mps2
      scales: [0.2, 0.4, 0.6, 0.8, 1.0, 1.2]
";

fn project() -> crate::tempdir::TempDir {
    let dir = crate::tempdir::tempdir().unwrap();
    std::fs::copy(case_dir("demo_03").join("floor.csv"), dir.path().join("floor.csv")).unwrap();
    std::fs::copy(case_dir("demo_03").join("equipment.yaml"), dir.path().join("unit.yaml")).unwrap();
    std::fs::write(dir.path().join("pipeline.yaml"), PIPELINE).unwrap();
    dir
}

#[test]
fn editing_the_equipment_file_reruns_what_reads_it() {
    let project = project();
    let root = project.path();
    let first = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(first.status.success(), "{}", stderr(&first));
    let fragility = read(&root.join("out/fragility/fragility/data.parquet"));
    for column in ["im_measure", "median", "beta", "n_runs", "n_overturned", "note"] {
        assert!(fragility.column(column).is_some(), "fragility lacks `{column}`");
    }
    let runs = read(&root.join("out/fragility/runs/data.parquet"));
    assert_eq!(runs.num_rows(), 6);
    let unit = root.join("unit.yaml");
    let text = std::fs::read_to_string(&unit).unwrap().replace("B_m: 0.385", "B_m: 0.5");
    std::fs::write(&unit, text).unwrap();
    let status = shakeflow(&["status", "pipeline.yaml"], root);
    let said = stdout(&status);
    assert!(said.contains("input `params.equipment (unit.yaml)` changed"), "{said}");
    let second = shakeflow(&["run", "pipeline.yaml"], root);
    let log = stderr(&second);
    assert!(second.status.success(), "{log}");
    assert!(log.contains("load               cached"), "{log}");
    assert!(log.contains("3 stage(s): 2 ran, 1 cached"), "{log}");
}

/// A summary reads every output of its stage: `run` makes one only for a stage whose results
/// changed, and none under `--quiet` (a cached stage's, at 10⁴ tests, was most of a no-op rerun).
#[test]
fn a_results_line_is_printed_for_the_stages_that_ran_only() {
    let project = project();
    let root = project.path();
    let quiet = shakeflow(&["run", "pipeline.yaml", "load", "-q"], root);
    assert!(quiet.status.success() && stderr(&quiet).is_empty(), "{}", stderr(&quiet));
    let first = shakeflow(&["run", "pipeline.yaml"], root);
    let log = stderr(&first);
    assert!(first.status.success(), "{log}");
    assert!(log.contains("\n  rocking: overturned in 1 of 1 records"), "{log}");
    assert!(log.contains("\n  fragility: "), "{log}");
    let unit = root.join("unit.yaml");
    let text = std::fs::read_to_string(&unit).unwrap().replace("B_m: 0.385", "B_m: 0.5");
    std::fs::write(&unit, text).unwrap();
    let second = shakeflow(&["run", "pipeline.yaml", "rocking"], root);
    let log = stderr(&second);
    assert!(second.status.success(), "{log}");
    assert!(log.contains("\n  rocking: ") && !log.contains("\n  fragility: "), "{log}");
    let cached = shakeflow(&["run", "pipeline.yaml"], root);
    let log = stderr(&cached);
    assert!(cached.status.success(), "{log}");
    assert!(
        log.contains("1 ran, 2 cached") && log.contains("\n  fragility: ") && !log.contains("\n  rocking: "),
        "{log}"
    );
}

#[test]
fn a_record_gone_is_said_and_its_stage_summarised_again() {
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    std::fs::create_dir(root.join("gm")).unwrap();
    for record in ["Rinaldi228", "Rinaldi318"] {
        std::fs::copy(ground_motion(&format!("{record}.AT2")), root.join(format!("gm/{record}.AT2"))).unwrap();
    }
    let pipeline = "version: 1\noutput_dir: out\ninputs:\n  gm:\n    format: at2\n    path: gm/{record}.AT2\n\
         stages:\n  load:\n    type: load\n    inputs: [gm]\n  rocking:\n    type: simulate_toppling\n    \
         inputs: [load]\n    params:\n      preset: PS2\n      figure: false\n";
    std::fs::write(root.join("pipeline.yaml"), pipeline).unwrap();
    let first = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(first.status.success(), "{}", stderr(&first));
    assert!(stderr(&first).contains("  rocking: overturned in ") && stderr(&first).contains(" of 2 records"));
    std::fs::remove_file(root.join("gm/Rinaldi318.AT2")).unwrap();
    let second = shakeflow(&["run", "pipeline.yaml"], root);
    let log = stderr(&second);
    assert!(second.status.success(), "{log}");
    assert!(log.contains("rocking            1 unit(s) removed: their records are gone from the inputs"), "{log}");
    assert!(log.contains("2 stage(s): 0 ran, 2 cached") && log.contains(" of 1 records"), "{log}");
}

/// Breaks the project, runs, and checks the failure is clear and changed nothing.
fn fails_cleanly(break_it: impl FnOnce(&Path), expected: &[&str]) {
    let project = project();
    let root = project.path();
    assert!(shakeflow(&["run", "pipeline.yaml"], root).status.success());
    break_it(root);
    let before = snapshot(&root.join("out"));
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    let message = stderr(&out);
    assert!(!out.status.success(), "expected a failure:\n{message}");
    for needle in expected {
        assert!(message.contains(needle), "message lacks `{needle}`:\n{message}");
    }
    assert_eq!(before, snapshot(&root.join("out")), "a failed run changed the artifacts:\n{message}");
}

#[test]
fn a_misspelt_key_in_the_equipment_file_is_named_with_its_line() {
    fails_cleanly(
        |root| {
            let unit = root.join("unit.yaml");
            let text = std::fs::read_to_string(&unit).unwrap().replace("H_m:", "H_M:");
            std::fs::write(unit, text).unwrap();
        },
        &["unit.yaml:5", "H_M"],
    );
}

#[test]
fn a_missing_channel_names_the_columns_there_are() {
    fails_cleanly(
        |root| {
            let pipeline = root.join("pipeline.yaml");
            let text = std::fs::read_to_string(&pipeline).unwrap().replacen("vertical: az_mps2", "vertical: az", 1);
            std::fs::write(pipeline, text).unwrap();
        },
        &["stage `rocking`", "no float column `az`", "az_mps2"],
    );
}

#[test]
fn an_unknown_preset_is_caught_by_validate_with_its_line() {
    let project = project();
    let root = project.path();
    let pipeline = root.join("pipeline.yaml");
    let text = std::fs::read_to_string(&pipeline).unwrap().replacen("equipment: unit.yaml\n", "preset: PS3\n", 1);
    std::fs::write(&pipeline, text).unwrap();
    let out = shakeflow(&["validate", "pipeline.yaml"], root);
    let message = stderr(&out);
    assert!(!out.status.success());
    assert!(message.contains("pipeline.yaml:20:7") && message.contains("PS3") && message.contains("PS2"), "{message}");
}

/// What issue 22 found in fragility tables, checked with pyarrow, DuckDB and polars
/// (tests/reference/fragility_tables_check.py): records named as other tables name them,
/// an integer `level`, `im` exactly the level, provenance in the Arrow schema metadata; and
/// `run` ends with the fragility in one line.
#[test]
fn fragility_runs_group_by_level_and_name_records_as_other_tables_do() {
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    std::fs::create_dir(root.join("gm")).unwrap();
    let records = ["NIS090", "Rinaldi228", "Rinaldi318"];
    for record in records {
        std::fs::copy(ground_motion(&format!("{record}.AT2")), root.join(format!("gm/{record}.AT2"))).unwrap();
    }
    let levels = "[1.0, 2.5, 4.0, 7.5]";
    let pipeline = format!(
        "version: 1\noutput_dir: out\ninputs:\n  gm:\n    format: at2\n    path: gm/{{record}}.AT2\n\
         stages:\n  load:\n    type: load\n    inputs: [gm]\n  fragility:\n    type: toppling_fragility\n    \
         inputs: [load]\n    params:\n      preset: PS2\n      horizontal: ax_mps2\n      im_levels: {levels}\n"
    );
    std::fs::write(root.join("pipeline.yaml"), pipeline).unwrap();
    let run = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(run.status.success(), "{}", stderr(&run));
    let said = stderr(&run);
    assert!(said.contains("  fragility: ") && said.contains("/3 records overturned at some level"), "{said}");
    let runs = root.join("out/fragility/runs/data.parquet");
    let report = run_python(
        &reference_script("fragility_tables_check.py"),
        &["--runs", runs.to_str().unwrap(), "--levels", levels, "--records", &serde_json::to_string(&records).unwrap()],
    );
    assert!(report.starts_with("ok:"), "{report}");
}
