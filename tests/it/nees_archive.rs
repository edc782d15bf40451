//! A NEES-layout archive (`Experiment-N/Trial-N/Rep-N/{Converted,Unprocessed}_Data/`) with NEES
//! text conventions — a preamble, a channel-name row, a description row and a units row in US
//! units, tab-delimited `.txt`/`.asc` — raw volts and counts calibrated by a sensitivity table,
//! and a LabVIEW `.lvm` export with decimal commas in two segments, read through `load` by path
//! templates; and the file:line:column refusals of damaged copies.

use crate::common::{shakeflow, stderr};
use shakeflow::table::Table;
use std::path::Path;

const G0: f64 = 9.80665;
const INCH: f64 = 0.0254;

const PIPELINE: &str = "version: 1
output_dir: out
inputs:
  converted:
    format: delimited
    path: archive/Experiment-{experiment}/Trial-{trial}/Rep-{rep}/Converted_Data/{name}.txt
    header_lines: 3
    description_row: 5
    units_row: 6
    time_column: Time
  raw:
    format: delimited
    path: archive/Experiment-{experiment}/Trial-{trial}/Rep-{rep}/Unprocessed_Data/{name}.asc
    header_lines: 3
    description_row: 5
    units_row: 6
    time_column: Time
    calibration: sensitivity.csv
  daq:
    format: lvm
    path: archive/Experiment-{experiment}/Trial-{trial}/Rep-{rep}/Unprocessed_Data/{name}.lvm
    calibration: sensitivity.csv
stages:
  load_converted:
    type: load
    inputs: [converted]
  load_raw:
    type: load
    inputs: [raw]
  load_daq:
    type: load
    inputs: [daq]
";

const SENSITIVITY: &str = "# sensitivities of DAQ 1, 2008-06-12\nchannel,sensitivity,unit,offset\nA1X,1.25,g,0.0125\nA1Y,2.5,g,-0.005\nD1X,3276.8,in,2048\n";

/// Rows of a NEES text file: time at 200 Hz and three channels written with fixed decimals.
fn rows(n: usize, trial: usize, raw: bool) -> Vec<[String; 4]> {
    (0..n)
        .map(|k| {
            let x = (k as f64 * 0.07 + trial as f64).sin();
            let y = (k as f64 * 0.05).cos();
            let d = k as f64 * 0.001 * trial as f64;
            let (a, b, c) = if raw {
                (
                    format!("{:.5}", 0.0125 + 1.25 * 0.3 * x),
                    format!("{:.5}", 2.5 * 0.2 * y),
                    format!("{:.0}", 2048.0 + 3276.8 * d),
                )
            } else {
                (format!("{:.5}", 0.3 * x), format!("{:.3}", 77.28 * y), format!("{:.4}", d))
            };
            [format!("{:.3}", k as f64 * 0.005), a, b, c]
        })
        .collect()
}

fn nees_text(rows: &[[String; 4]], units: &str) -> String {
    let mut text = String::from(
        "NEES-2008-0551\tExperiment-2\tTrial run\nFacility: UNR Large-Scale Structures Laboratory, shake table 1\nSampling rate: 200 Hz\n",
    );
    text.push_str("Time\tA1X\tA1Y\tD1X\n");
    text.push_str("Time\tTable acceleration, E-W\tTable acceleration, N-S\tTable displacement, E-W (LVDT)\n");
    text.push_str(units);
    text.push('\n');
    for row in rows {
        text.push_str(&row.join("\t"));
        text.push('\n');
    }
    text
}

const LVM: &str = "LabVIEW Measurement\t\nWriter_Version\t2\nReader_Version\t2\nSeparator\tTab\nDecimal_Separator\t,\nMulti_Headings\tYes\nX_Columns\tOne\nTime_Pref\tRelative\nOperator\tnees\n***End_of_Header***\t\n\t\nChannels\t2\t\nSamples\t3\t3\t\nY_Unit_Label\tVolts\tg\t\nX0\t0,0000000000000000E+0\t0,0000000000000000E+0\t\nDelta_X\t0,005000\t0,005000\t\n***End_of_Header***\t\t\t\nX_Value\tA1X\tA2X\tComment\n0,000000\t0,125\t-1,5E-3\n0,005000\t0,250\t2,0E-3\n0,010000\t-0,375\t2,5E-3\n\nChannels\t2\t\nSamples\t2\t2\t\nY_Unit_Label\tVolts\tg\t\nX0\t1,5000000000000000E-2\t1,5000000000000000E-2\t\nDelta_X\t0,005000\t0,005000\t\n***End_of_Header***\t\t\t\nX_Value\tA1X\tA2X\tComment\n0,015000\t0,5\t1\n0,020000\t0,625\t-1\n";

fn project() -> crate::tempdir::TempDir {
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    std::fs::write(root.join("pipeline.yaml"), PIPELINE).unwrap();
    std::fs::write(root.join("sensitivity.csv"), SENSITIVITY).unwrap();
    for trial in [1, 3] {
        let rep = root.join(format!("archive/Experiment-2/Trial-{trial}/Rep-1"));
        std::fs::create_dir_all(rep.join("Converted_Data")).unwrap();
        std::fs::create_dir_all(rep.join("Unprocessed_Data")).unwrap();
        let converted = nees_text(&rows(400, trial, false), "sec\tg\tin/sec^2\tin");
        std::fs::write(rep.join("Converted_Data/table.txt"), converted).unwrap();
        let raw = nees_text(&rows(400, trial, true), "sec\tV\tVolts\tcounts");
        std::fs::write(rep.join("Unprocessed_Data/fbgm152s3.asc"), raw).unwrap();
    }
    let rep = root.join("archive/Experiment-2/Trial-1/Rep-1/Unprocessed_Data");
    std::fs::write(rep.join("daq.lvm"), LVM).unwrap();
    dir
}

fn table(root: &Path, stage: &str, partition: &str) -> Table {
    let path = root.join(format!("out/{stage}/records/{partition}/data.parquet"));
    shakeflow::io::parquet::read_table(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn column<'t>(table: &'t Table, name: &str) -> &'t [f64] {
    table.f64_column(name).unwrap_or_else(|| panic!("no column {name}: {:?}", table.column_names()))
}

fn load_summary(table: &Table) -> serde_json::Value {
    serde_json::from_str(&table.metadata["shakeflow.load"]).unwrap()
}

/// Every value is the file's number times the exact factor of the unit its units row states
/// (after `(raw − offset) / sensitivity` for the raw files), to the last bit.
#[test]
fn a_nees_archive_loads_by_template_with_units_descriptions_and_calibration() {
    let project = project();
    let root = project.path();
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(out.status.success(), "{}", stderr(&out));
    for trial in [1usize, 3] {
        let partition = format!("experiment=2/trial={trial}/rep=1/name=table");
        let converted = table(root, "load_converted", &partition);
        let expected = rows(400, trial, false);
        let file = |i: usize| expected.iter().map(move |r| r[i].parse::<f64>().unwrap());
        // `load` writes time as t0 + k·dt from the column's uniform step.
        assert!(column(&converted, "time_s").iter().zip(file(0)).all(|(a, b)| (a - b).abs() < 1e-12));
        for (name, index, factor) in [("A1X", 1, G0), ("A1Y", 2, INCH), ("D1X", 3, INCH)] {
            let got = column(&converted, name);
            assert!(got.iter().zip(file(index)).all(|(a, b)| a.to_bits() == (b * factor).to_bits()), "{name}");
        }
        let a1y = converted.column("A1Y").unwrap();
        assert_eq!((a1y.unit.as_str(), a1y.description.as_str()), ("m/s^2", "Table acceleration, N-S"));
        assert_eq!(converted.column("D1X").unwrap().unit, "m");
        let summary = load_summary(&converted);
        assert_eq!(summary["columns"]["A1Y"]["file_unit"], "in/sec^2", "{summary}");
        assert_eq!(summary["header"]["preamble_3"], "Sampling rate: 200 Hz");

        let raw = table(root, "load_raw", &format!("experiment=2/trial={trial}/rep=1/name=fbgm152s3"));
        let expected = rows(400, trial, true);
        let file = |i: usize| expected.iter().map(move |r| r[i].parse::<f64>().unwrap());
        for (name, index, sensitivity, offset, factor) in
            [("A1X", 1, 1.25, 0.0125, G0), ("A1Y", 2, 2.5, -0.005, G0), ("D1X", 3, 3276.8, 2048.0, INCH)]
        {
            let got = column(&raw, name);
            let want = file(index).map(|v| (v - offset) / sensitivity * factor);
            assert!(got.iter().zip(want).all(|(a, b)| a.to_bits() == b.to_bits()), "{name}");
        }
        let summary = load_summary(&raw);
        let calibration = &summary["columns"]["D1X"]["calibration"];
        assert_eq!(calibration["raw_unit"], "counts", "{summary}");
        assert_eq!((calibration["sensitivity"].as_f64(), calibration["offset"].as_f64()), (Some(3276.8), Some(2048.0)));
        assert_eq!(
            (calibration["table"].as_str(), calibration["table_line"].as_u64()),
            (Some("sensitivity.csv"), Some(5))
        );
    }
    // The LVM export: two segments with decimal commas, A1X in volts through the same table.
    let lvm = table(root, "load_daq", "experiment=2/trial=1/rep=1/name=daq");
    let time = column(&lvm, "time_s");
    assert!(time.iter().zip([0.0, 0.005, 0.01, 0.015, 0.02]).all(|(t, e)| (t - e).abs() < 1e-15), "{time:?}");
    let a1x: Vec<f64> = [0.125, 0.25, -0.375, 0.5, 0.625].iter().map(|v| (v - 0.0125) / 1.25 * G0).collect();
    assert_eq!(column(&lvm, "A1X"), a1x);
    let a2x: Vec<f64> = [-1.5e-3, 2.0e-3, 2.5e-3, 1.0, -1.0].iter().map(|v| v * G0).collect();
    assert_eq!(column(&lvm, "A2X"), a2x);
    assert_eq!(load_summary(&lvm)["header"]["segments"], "2");

    // An edited sensitivity table reruns the loads that use it, and only those.
    std::fs::write(root.join("sensitivity.csv"), SENSITIVITY.replace("1.25", "1.5")).unwrap();
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    let raw = table(root, "load_raw", "experiment=2/trial=1/rep=1/name=fbgm152s3");
    let first = rows(1, 1, true)[0][1].parse::<f64>().unwrap();
    assert_eq!(column(&raw, "A1X")[0].to_bits(), ((first - 0.0125) / 1.5 * G0).to_bits(), "{log}");
}

/// Runs the NEES project after `break_it`; the run fails with every `expected` text in its message.
fn refused(break_it: impl FnOnce(&Path), expected: &[&str]) -> String {
    let project = project();
    let root = project.path();
    break_it(root);
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    let message = stderr(&out);
    assert!(!out.status.success(), "expected a failure:\n{message}");
    for needle in expected {
        assert!(message.contains(needle), "message lacks `{needle}`:\n{message}");
    }
    message
}

const TABLE_1: &str = "archive/Experiment-2/Trial-1/Rep-1/Converted_Data/table.txt";
const RAW_1: &str = "archive/Experiment-2/Trial-1/Rep-1/Unprocessed_Data/fbgm152s3.asc";

fn edit(root: &Path, file: &str, f: impl FnOnce(String) -> String) {
    let path = root.join(file);
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, f(text)).unwrap();
}

#[test]
fn a_truncated_nees_file_names_its_last_line() {
    // 6 header lines + 400 rows: the cut row is line 406.
    refused(|root| edit(root, TABLE_1, |t| t[..t.len() - 9].to_string()), &[&format!("{TABLE_1}:406"), "truncated"]);
}

#[test]
fn a_units_row_with_a_cell_missing_names_its_line() {
    refused(
        |root| edit(root, TABLE_1, |t| t.replace("sec\tg\tin/sec^2\tin", "sec\tg\tin/sec^2")),
        &[&format!("{TABLE_1}:6"), "the units row (line 6) has 3 cell(s) but the column-name row has 4"],
    );
}

#[test]
fn an_unknown_unit_in_the_units_row_names_line_and_column() {
    refused(
        |root| edit(root, TABLE_1, |t| t.replace("sec\tg\tin/sec^2\tin", "sec\tg\tfurlong/s^2\tin")),
        &[&format!("{TABLE_1}:6:7"), "unknown unit `furlong/s^2` for column `A1Y`", "known units"],
    );
}

#[test]
fn a_raw_channel_missing_from_the_sensitivity_table_names_its_unit_cell() {
    refused(
        |root| edit(root, "sensitivity.csv", |t| t.replace("A1Y,2.5,g,-0.005\n", "")),
        &[&format!("{RAW_1}:6:7"), "column `A1Y` is raw data in V", "`sensitivity.csv` has no row for it"],
    );
}

#[test]
fn a_damaged_sensitivity_table_names_its_line_and_column() {
    refused(
        |root| edit(root, "sensitivity.csv", |t| t.replace("3276.8,in", "3276.8,furlong")),
        &["sensitivity.csv:5:12", "unknown unit `furlong` for channel `D1X`"],
    );
}

#[test]
fn a_units_row_read_as_data_suggests_units_row() {
    refused(
        |root| {
            edit(root, "pipeline.yaml", |t| {
                t.replacen("    units_row: 6\n", "    description_row: 5\n", 1).replacen(
                    "    description_row: 5\n    description_row: 5\n",
                    "    description_row: 5\n",
                    1,
                )
            })
        },
        &[&format!("{TABLE_1}:6:1"), "cannot read 'sec' as a number", "set `units_row: 6`"],
    );
}

#[test]
fn a_units_row_above_the_names_is_refused_at_its_yaml_line() {
    let message = refused(
        |root| edit(root, "pipeline.yaml", |t| t.replacen("units_row: 6", "units_row: 4", 1)),
        &["pipeline.yaml:9:5", "`units_row: 4` is not below the column-name row (line 4)"],
    );
    assert!(message.contains("1-based"), "{message}");
}

/// Without options, `stage load` reads a NEES `.asc` as tab-delimited text; the conventions come
/// from `--set`.
#[test]
fn stage_load_reads_an_asc_file_with_its_units_row() {
    let project = project();
    let root = project.path();
    let set = ["header_lines=3", "units_row=6", "description_row=5", "time_column=Time", "calibration=sensitivity.csv"];
    let mut args = vec!["stage", "load", "--input", RAW_1, "--output", "one"];
    for s in &set {
        args.extend(["--set", s]);
    }
    let out = shakeflow(&args, root);
    assert!(out.status.success(), "{}", stderr(&out));
    let loaded = shakeflow::io::parquet::read_table(&root.join("one/records/data.parquet")).unwrap();
    assert_eq!(load_summary(&loaded)["format"], "delimited");
    assert_eq!(loaded.column("A1X").unwrap().description, "Table acceleration, E-W");
}
