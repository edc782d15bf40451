//! The strong-motion formats through `load`: every shared record in ../shared/data/records against
//! USGS gmprocess's readers and, for K-NET, ObsPy's (tests/reference/records_gmprocess.py and
//! records_obspy.py wrote the values they produced next to them), channels named by axis, and
//! one glob source feeding a downstream stage with a suite of records.

use crate::common::{self, shakeflow, stderr};

use serde_json::{json, Value};
use shakeflow::pipeline::spec::SourceSpec;
use shakeflow::stages::{load, InputPart};
use shakeflow::table::{ColumnData, Table, TIME_COLUMN};
use std::path::PathBuf;

const G0: f64 = 9.80665;

fn record(name: &str) -> PathBuf {
    let path = common::shared_dir().join("data/records").join(name);
    assert!(path.is_file(), "shared record {} is missing", path.display());
    path
}

fn load_with(file: &str, format: &str, extra: Value) -> Result<Table, String> {
    let mut spec = json!({"format": format, "path": file});
    for (k, v) in extra.as_object().unwrap() {
        spec[k] = v.clone();
    }
    let spec: SourceSpec = serde_json::from_value(spec).unwrap();
    let part = InputPart { partition: vec![], path: record(file), label: file.into(), hash: String::new() };
    load::load_record(&spec, &part).map_err(|e| e.to_string())
}

fn load(file: &str, format: &str) -> Table {
    load_with(file, format, json!({})).unwrap_or_else(|e| panic!("{e}"))
}

/// A channel's samples: a channel shorter than the record is null past its end (only there),
/// which is left out.
pub fn column(table: &Table, name: &str) -> Vec<f64> {
    let column = table.column(name).unwrap_or_else(|| panic!("no column {name}: {:?}", table.column_names()));
    match &column.data {
        ColumnData::F64(values) => values.clone(),
        ColumnData::OptF64(values) => {
            let n = values.iter().take_while(|v| v.is_some()).count();
            assert!(values[n..].iter().all(Option::is_none), "{name}: a null before the channel's end");
            values[..n].iter().flatten().copied().collect()
        }
        other => panic!("{name} is {}", other.type_name()),
    }
}

fn load_header(table: &Table) -> Value {
    let text = table.metadata.get("shakeflow.load").expect("load metadata");
    serde_json::from_str::<Value>(text).unwrap()
}

fn reference(name: &str) -> Value {
    let path = common::reference_script(name);
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

/// gmprocess's trace `channel` of `file` is shakeflow's `column`; `to_si` takes gmprocess's
/// values to shakeflow's (cm/s² → m/s²; for COSMOS V0 counts, × the header's counts-to-g × g0).
#[test]
fn every_record_matches_gmprocess() {
    let reference = reference("records_gmprocess.json");
    let cases: &[(&str, &str, &[(&str, &str)])] = &[
        ("cosmos/NCMDH--n.00725272.HNE.--.V1c", "cosmos", &[("HN2", "ax_mps2")]),
        ("cosmos/NP1795-n.305.v0c", "cosmos", &[("HN2", "ax_mps2"), ("HN1", "ay_mps2"), ("HNZ", "az_mps2")]),
        // gmprocess calls this BNZ (vertical, the file's SEED name) HN1 at azimuth 0: COSMOS's
        // orientation code 0 is not an azimuth, and gmprocess does not read the SEED name.
        ("cosmos/us1000hyfh_akbmrp_AKBMR--n.1000hyfh.BNZ.--.acc.V2c", "cosmos", &[("HN1", "az_mps2")]),
        ("dmg/CE89146.V1", "dmg", &[("HN1", "ay_mps2"), ("HNZ", "az_mps2"), ("HN2", "ax_mps2")]),
        ("dmg/CE89146.V2", "dmg", &[("HN1", "ay_mps2"), ("HNZ", "az_mps2"), ("HN2", "ax_mps2")]),
        ("dmg/CIWLT.RAW", "dmg", &[("HN2", "ax_mps2"), ("HN1", "ay_mps2"), ("HNZ", "az_mps2")]),
        ("smc/0111a.smc", "smc", &[("HN1", "ax_mps2")]),
        ("smc/2825.HNE.NP.--_u.smc", "smc", &[("HN2", "ax_mps2")]),
        ("knet/AOM0051801241951.EW", "knet", &[("HN2", "ax_mps2")]),
        ("knet/AOM0051801241951.NS", "knet", &[("HN1", "ax_mps2")]),
        ("knet/AOM0051801241951.UD", "knet", &[("HNZ", "az_mps2")]),
        ("knet/AICH040010061330.EW2", "knet", &[("HN2", "ax_mps2")]),
        ("knet/AICH040010061330.NS2", "knet", &[("HN1", "ax_mps2")]),
        ("knet/AICH040010061330.UD2", "knet", &[("HNZ", "az_mps2")]),
        ("esm/HI.ARS1..HNE.D.20190728.160908.C.ACC.ASC", "esm", &[("HNE", "ax_mps2")]),
        ("esm/20101114230825_3104_ap_RawAcc_E.asc", "esm", &[("HNE", "ax_mps2")]),
        ("geonet/20180212_211557_WPWS_20.V2A", "geonet", &[("HN1", "ay_mps2"), ("HN2", "ax_mps2"), ("HNZ", "az_mps2")]),
    ];
    let files = reference["files"].as_object().unwrap();
    assert_eq!(files.len(), cases.len(), "every file gmprocess read is checked");
    for (file, format, mapping) in cases {
        let table = load(file, format);
        let summary = load_header(&table);
        let header = &summary["header"];
        let traces = files[*file].as_array().unwrap();
        assert_eq!(traces.len(), mapping.len(), "{file}: channels");
        let rows = table.f64_column(TIME_COLUMN).unwrap().len();
        for (channel, name) in mapping.iter() {
            let trace = traces.iter().find(|t| t["channel"] == *channel).unwrap();
            let ours = column(&table, name);
            let file_column = summary["columns"][*name]["file_column"].as_str().unwrap();
            let npts = trace["npts"].as_u64().unwrap() as usize;
            // Every sample gmprocess reads is kept: CIWLT.RAW's channels differ in length, the
            // table has the longest's rows and the others are null past their end.
            assert_eq!(ours.len(), npts, "{file} {name}: samples");
            assert_eq!(summary["columns"][*name]["npts"], json!(npts), "{file} {name}: npts in the metadata");
            assert!(npts <= rows, "{file} {name}: {npts} vs {rows} rows");
            let time = table.f64_column(TIME_COLUMN).unwrap();
            assert!((time[1] - time[0] - trace["delta"].as_f64().unwrap()).abs() < 1e-12, "{file}: dt");
            let to_si = if trace["units"] == "counts" {
                let key = format!("channel.{file_column}.counts_to_g");
                header[key.as_str()].as_str().unwrap().parse::<f64>().unwrap() * G0
            } else {
                assert!(trace["units"].as_str().unwrap().starts_with("cm/s"), "{file}: {}", trace["units"]);
                0.01
            };
            let peak = trace["peak"].as_f64().unwrap() * to_si;
            let tolerance = 1e-12 * peak.abs();
            let stride = trace["stride"].as_u64().unwrap() as usize;
            for (k, expected) in trace["samples"].as_array().unwrap().iter().enumerate() {
                let i = k * stride;
                if i >= npts {
                    break;
                }
                let expected = expected.as_f64().unwrap() * to_si;
                assert!(
                    (ours[i] - expected).abs() <= tolerance,
                    "{file} {name}[{i}]: {} vs gmprocess {expected}",
                    ours[i]
                );
            }
            {
                let last = trace["last"].as_f64().unwrap() * to_si;
                assert!((ours[npts - 1] - last).abs() <= tolerance, "{file} {name}: last");
                let i = trace["peak_index"].as_u64().unwrap() as usize;
                assert!((ours[i] - peak).abs() <= tolerance, "{file} {name}: peak {} vs {peak}", ours[i]);
                let largest = ours.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                assert_eq!(largest, ours[i].abs(), "{file} {name}: the peak is where gmprocess found it");
            }
            // Orientation: gmprocess's azimuth for horizontals (its Z channels carry none or a dummy).
            if let (Some(azimuth), false) = (trace["horizontal_orientation"].as_f64(), name.starts_with("az")) {
                let ours: f64 =
                    header[format!("channel.{file_column}.orientation").as_str()].as_str().unwrap().parse().unwrap();
                assert_eq!(ours, azimuth, "{file} {name}: azimuth");
            }
        }
    }
}

#[test]
fn knet_counts_times_obspy_calib() {
    let reference = reference("records_obspy.json");
    for (file, expected) in reference["files"].as_object().unwrap() {
        let table = load(file, "knet");
        let name = if file.ends_with("UD") || file.ends_with("UD2") { "az_mps2" } else { "ax_mps2" };
        let ours = column(&table, name);
        assert_eq!(ours.len() as u64, expected["npts"].as_u64().unwrap(), "{file}");
        let calib = expected["calib"].as_f64().unwrap();
        let counts = expected["first_counts"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap());
        for (i, count) in counts.enumerate() {
            let want = count * calib;
            assert!((ours[i] - want).abs() <= 4.0 * f64::EPSILON * want.abs(), "{file}[{i}]: {} vs {want}", ours[i]);
        }
        let want = expected["last_count"].as_f64().unwrap() * calib;
        assert!((ours[ours.len() - 1] - want).abs() <= 4.0 * f64::EPSILON * want.abs(), "{file}: last");
        let sum: f64 = ours.iter().sum();
        let want = expected["sum_counts"].as_f64().unwrap() * calib;
        assert!((sum - want).abs() <= 1e-9 * want.abs(), "{file}: sum {sum} vs {want}");
    }
}

#[test]
fn a_lone_horizontal_is_ax_unless_the_source_says_otherwise() {
    let ns = "knet/AOM0051801241951.NS";
    assert_eq!(load(ns, "knet").column_names(), [TIME_COLUMN, "ax_mps2"]);
    let as_y = load_with(ns, "knet", json!({"component_as": "ay"})).unwrap();
    assert_eq!(as_y.column_names(), [TIME_COLUMN, "ay_mps2"]);
    let labels = load_with(ns, "knet", json!({"component_as": "label"})).unwrap();
    assert_eq!(labels.column_names(), [TIME_COLUMN, "NS"]);
    assert_eq!(column(&labels, "NS"), column(&as_y, "ay_mps2"));
    // A vertical stays z whatever the lone horizontal would be called.
    let ud = load_with("knet/AOM0051801241951.UD", "knet", json!({"component_as": "ay"})).unwrap();
    assert_eq!(ud.column_names(), [TIME_COLUMN, "az_mps2"]);
    // The PEER AT2 labels its component: `BH1` (no azimuth) is the lone horizontal.
    let at2 = load("nga/RSN10590_ComalTX11-10-20_IU.CCM.BH1.00.AT2", "at2");
    assert_eq!(at2.column_names(), [TIME_COLUMN, "ax_mps2"]);
    assert_eq!(column(&at2, "ax_mps2").len(), 15306);
    // An explicit column map still names the file's channels as the file does.
    let mapped = load_with("dmg/CE89146.V2", "dmg", json!({"columns": {"up_mps2": "chan2"}})).unwrap();
    assert_eq!(mapped.column_names(), [TIME_COLUMN, "up_mps2"]);
    let three = load("dmg/CE89146.V2", "dmg");
    assert_eq!(column(&mapped, "up_mps2"), column(&three, "az_mps2"));
    // A misspelt choice is refused by the spec itself.
    let bad: Result<SourceSpec, _> =
        serde_json::from_value(json!({"format": "knet", "path": ns, "component_as": "east"}));
    assert!(bad.unwrap_err().to_string().contains("unknown variant `east`"));
}

/// CIWLT.RAW's channels hold 30130 (90°), 30058 (360°) and 30312 (up) points (SOURCES.md): the
/// table has 30312 rows, the shorter channels are null past their end, each column's `npts` is
/// its channel's, and the record is flagged at each shorter channel's first data line.
#[test]
fn channels_of_different_lengths_keep_every_sample_and_are_flagged() {
    let table = load("dmg/CIWLT.RAW", "dmg");
    assert_eq!(table.num_rows(), 30312);
    let time = table.f64_column(TIME_COLUMN).unwrap();
    assert!((time[30311] - 303.11).abs() < 1e-9, "time runs to the longest channel's end");
    assert_eq!(column(&table, "ax_mps2").len(), 30130);
    assert_eq!(column(&table, "ay_mps2").len(), 30058);
    assert_eq!(column(&table, "az_mps2").len(), 30312);
    // The longest channel is not nullable; the others are.
    assert!(matches!(table.column("az_mps2").unwrap().data, ColumnData::F64(_)));
    assert!(matches!(table.column("ax_mps2").unwrap().data, ColumnData::OptF64(_)));
    let summary = load_header(&table);
    assert!(summary.get("cut_to_shortest_channel").is_none());
    for (name, npts) in [("ax_mps2", 30130), ("ay_mps2", 30058), ("az_mps2", 30312)] {
        assert_eq!(summary["columns"][name]["npts"], json!(npts), "{name}");
    }
    assert_eq!(summary["npts"], json!(30312));
    let flags: Value = serde_json::from_str(&table.metadata[load::FLAGS_KEY]).unwrap();
    let flags = flags.as_array().unwrap();
    assert_eq!(flags.len(), 2, "{flags:?}");
    assert!(
        flags[0]["reason"].as_str().unwrap().contains(
            "`chan1` (column `ax_mps2`) has 30130 samples, the record's longest 30312: its last 182 row(s) are null"
        ),
        "{flags:?}"
    );
    assert!(flags[1]["reason"].as_str().unwrap().contains("has 30058 samples"), "{flags:?}");
    assert_eq!(flags[0]["file"], "dmg/CIWLT.RAW");
    let text = std::fs::read_to_string(record("dmg/CIWLT.RAW")).unwrap();
    let line = flags[1]["line"].as_u64().unwrap() as usize;
    let before = text.lines().nth(line - 2).unwrap();
    assert!(before.trim_start().starts_with("30058 "), "line {line} follows the channel's data line: {before}");
    // Units: g to m/s² with g0, as the table says.
    assert_eq!(summary["columns"]["ax_mps2"]["file_unit"], "g");
    assert_eq!(summary["columns"]["ax_mps2"]["factor"], G0);
    assert_eq!(summary["header"]["channel.chan1.label"], "90 Deg");
}

/// One glob source over a suite of records feeds a stage that asks for `ax_mps2`: the files name
/// their components `E-W`, `4`, `180`, `BH1`, yet every table has the column.
#[test]
fn one_glob_source_feeds_a_suite_of_records_downstream() {
    let dir = crate::tempdir::tempdir().unwrap();
    let gm = dir.path().join("gm");
    std::fs::create_dir_all(&gm).unwrap();
    let files = [
        "knet/AOM0051801241951.EW",
        "knet/AOM0051801241951.NS",
        "knet/AICH040010061330.EW2",
        "knet/AICH040010061330.NS2",
    ];
    for file in files {
        let name = std::path::Path::new(file).file_name().unwrap().to_str().unwrap().replace('.', "_");
        std::fs::copy(record(file), gm.join(format!("{name}.knet"))).unwrap();
    }
    std::fs::copy(record("nga/RSN10590_ComalTX11-10-20_IU.CCM.BH1.00.AT2"), gm.join("comal.AT2")).unwrap();
    std::fs::copy(common::ground_motion("RSN6_IMPVALL.I_I-ELC180.AT2"), gm.join("elcentro.AT2")).unwrap();
    let pipeline = "\
version: 1
output_dir: out
inputs:
  knet:
    format: knet
    path: gm/{record}.knet
  peer:
    format: at2
    path: gm/{record}.AT2
stages:
  load:
    type: load
    inputs: [knet, peer]
  baseline:
    type: baseline
    inputs: [load]
    params:
      order: 1
      columns: [ax_mps2]
";
    std::fs::write(dir.path().join("pipeline.yaml"), pipeline).unwrap();
    let out = shakeflow(&["run", "pipeline.yaml"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let mut done: Vec<String> = std::fs::read_dir(dir.path().join("out/baseline/records"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    done.sort();
    assert_eq!(
        done,
        [
            "record=AICH040010061330_EW2",
            "record=AICH040010061330_NS2",
            "record=AOM0051801241951_EW",
            "record=AOM0051801241951_NS",
            "record=comal",
            "record=elcentro"
        ]
    );
}

#[test]
fn stage_load_detects_the_format_from_content() {
    let dir = crate::tempdir::tempdir().unwrap();
    // A CSMIP Vol.2 saved as .txt: content decides.
    std::fs::copy(record("dmg/CE89146.V2"), dir.path().join("willow.txt")).unwrap();
    let out = shakeflow(&["stage", "load", "--input", "willow.txt", "--output", "loaded"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let text = common::stdout(&shakeflow(&["inspect", "loaded/records/data.parquet"], dir.path()));
    assert!(text.contains("12000 rows"), "{text}");
    for name in ["ax_mps2", "ay_mps2", "az_mps2"] {
        assert!(text.contains(name), "{name}: {text}");
    }
}

#[test]
fn a_damaged_record_names_file_line_and_column() {
    let dir = crate::tempdir::tempdir().unwrap();
    let text = std::fs::read_to_string(record("smc/0111a.smc")).unwrap();
    std::fs::write(dir.path().join("bad.smc"), text.replacen("-2.2223E+0", "-2.2x23E+0", 1)).unwrap();
    let out = shakeflow(&["stage", "load", "--input", "bad.smc", "--output", "loaded"], dir.path());
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("bad.smc:36:11"), "{err}");
    assert!(err.contains("expected acceleration value 2 of 6001"), "{err}");
    assert!(!dir.path().join("loaded").exists());
}

/// LabVIEW `.lvm` files read as lvm_read (an independent reader, tests/reference/records_lvm.py)
/// reads them: channel names, units, every value and the X values or X0 + k·Delta_X times, over
/// decimal commas, two segments, a Comment column, a comma separator and no X column. The
/// numbers are the file's decimal text both ways: equal to the last bit.
#[test]
fn lvm_files_read_as_lvm_read_reads_them() {
    let reference = reference("records_lvm.json");
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/reference/lvm");
    for (file, expected) in reference["files"].as_object().unwrap() {
        let record = shakeflow::io::records::read_lvm(&dir.join(file)).unwrap();
        let segments = expected["segments"].as_array().unwrap();
        let first = &segments[0];
        let names: Vec<&str> = record.channels.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(
            names,
            first["channels"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect::<Vec<_>>()
        );
        let units: Vec<&str> = record.channels.iter().map(|c| c.unit.as_str()).collect();
        assert_eq!(units, first["units"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect::<Vec<_>>());
        assert_eq!(record.header["segments"], segments.len().to_string(), "{file}");
        let floats = |v: &Value| v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect::<Vec<f64>>();
        for (c, channel) in record.channels.iter().enumerate() {
            let want: Vec<f64> = segments.iter().flat_map(|s| floats(&s["values"][c])).collect();
            assert_eq!(channel.values, want, "{file} {}", channel.name);
        }
        let want_time: Vec<f64> = segments
            .iter()
            .flat_map(|s| match s["x"].as_array() {
                Some(_) => floats(&s["x"]),
                None => {
                    let (x0, dx) = (s["x0"].as_f64().unwrap(), s["delta_x"].as_f64().unwrap());
                    (0..s["values"][0].as_array().unwrap().len()).map(|k| x0 + k as f64 * dx).collect()
                }
            })
            .collect();
        assert_eq!(record.time.as_deref().unwrap(), want_time, "{file}: times");
    }
}
