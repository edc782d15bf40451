//! The load stage on every real record in ../shared: NPTS, DT and PGA as SOURCES.md states them
//! (PGA there is max|a| computed from the file, in g, to 4 decimals).

use crate::common;

use serde_json::json;
use shakeflow::pipeline::spec::SourceSpec;
use shakeflow::stages::{load, InputPart};
use shakeflow::table::TIME_COLUMN;

fn load(file: &str, format: &str) -> shakeflow::table::Table {
    let spec: SourceSpec = serde_json::from_value(json!({"format": format, "path": file})).unwrap();
    let part =
        InputPart { partition: vec![], path: common::ground_motion(file), label: file.into(), hash: String::new() };
    load::load_record(&spec, &part).unwrap_or_else(|e| panic!("{e}"))
}

fn check(table: &shakeflow::table::Table, channel: &str, npts: usize, dt: f64, pga_g: f64) {
    let values =
        table.f64_column(channel).unwrap_or_else(|| panic!("no channel {channel}: {:?}", table.column_names()));
    assert_eq!(values.len(), npts, "{channel} npts");
    let time = table.f64_column(TIME_COLUMN).unwrap();
    assert!((time[1] - time[0] - dt).abs() < 1e-9, "{channel} dt {}", time[1] - time[0]);
    assert_eq!(table.column(channel).unwrap().unit, "m/s^2");
    let pga = values.iter().fold(0.0f64, |m, v| m.max(v.abs())) / 9.80665;
    assert!((pga - pga_g).abs() <= 5e-5, "{channel} PGA {pga:.5} g vs SOURCES.md {pga_g}");
}

#[test]
fn peer_at2_records_match_sources_md() {
    let cases = [
        ("Rinaldi228.AT2", 1991, 0.01, 0.8741),
        ("Rinaldi318.AT2", 1991, 0.01, 0.4723),
        ("RinaldiUP.AT2", 1991, 0.01, 0.9582),
        ("RSN1084_NORTHR_SCS052.AT2", 8773, 0.005, 0.6230),
        ("RSN2110_DENALI_FAIGO360.AT2", 46800, 0.005, 0.0706),
        ("RSN6_IMPVALL.I_I-ELC180.AT2", 5372, 0.01, 0.2808),
        ("NIS090.AT2", 4096, 0.01, 0.5027), // the older `NPTS, DT` header
        ("RSN1512_CHICHI_TCU078-E.AT2", 18000, 0.005, 0.4473),
        ("RSN763_LOMAP_GIL067.AT2", 7999, 0.005, 0.3585),
    ];
    for (file, npts, dt, pga) in cases {
        let table = load(file, "at2");
        let channel = table.columns[1].name.clone();
        check(&table, &channel, npts, dt, pga);
    }
}

#[test]
fn renadic_record_is_converted_from_g_over_10() {
    let table = load("llolleo1002271.v1", "renadic_v1");
    check(&table, "L", 24923, 0.005, 0.3192);
    check(&table, "V", 24923, 0.005, 0.7019);
    check(&table, "T", 24923, 0.005, 0.5644);
}

#[test]
fn simcenter_json_record_has_both_components() {
    // Its `x` and `y` become `ax` and `ay` (docs/formats.md, channels by role).
    let table = load("RSN2113.json", "simcenter_json");
    check(&table, "ax_mps2", 32895, 0.005, 0.0557);
    check(&table, "ay_mps2", 32895, 0.005, 0.0746);
}
