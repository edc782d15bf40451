//! The demo study end to end: `pipelines/demo.yaml` over a freshly generated demo archive,
//! checked against the archive's concealed truth (manifest.json) and the study's Table 3.
//! Tolerances are the floors: lag 1 ms, frequency 0.05 Hz here (Welch bin 0.012 Hz,
//! 7 segments), toppling 0.05 s, and no toppling anywhere else.

mod common;

use std::path::Path;

use serde_json::Value;
use shakeflow::io::parquet::read_table;
use shakeflow::table::ColumnData;

fn str_column<'a>(table: &'a shakeflow::table::Table, name: &str) -> &'a [String] {
    match &table.column(name).unwrap().data {
        ColumnData::Str(v) => v,
        other => panic!("{name} is {}", other.type_name()),
    }
}

fn opt_column<'a>(table: &'a shakeflow::table::Table, name: &str) -> &'a [Option<f64>] {
    match &table.column(name).unwrap().data {
        ColumnData::OptF64(v) => v,
        other => panic!("{name} is {}", other.type_name()),
    }
}

#[test]
fn demo_pipeline_recovers_the_archive_truth() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let work = tempfile::tempdir().unwrap();
    let archive = work.path().join("runs/demo-archive");
    shakeflow::demo::archive::write_demo_archive(&archive).unwrap();
    std::fs::create_dir(work.path().join("pipelines")).unwrap();
    std::fs::copy(root.join("pipelines/demo.yaml"), work.path().join("pipelines/demo.yaml")).unwrap();
    let out = common::shakeflow(&["run", "pipelines/demo.yaml"], work.path());
    assert!(out.status.success(), "{}", common::stderr(&out));
    let manifest: Value =
        serde_json::from_str(&std::fs::read_to_string(archive.join("manifest.json")).unwrap()).unwrap();
    let runs = work.path().join("runs/demo");

    // The report: one summary row per unit (two for PS2, toppled twice) and a PNG per unit.
    let summary = read_table(&runs.join("report/summary/data.parquet")).unwrap();
    assert_eq!(str_column(&summary, "unit"), ["UI3", "MC2", "PB1", "PB2", "PS1", "PS2", "PS2", "WSU1"]);
    for unit in ["UI3", "MC2", "PB1", "PB2", "PS1", "PS2", "WSU1"] {
        let png = std::fs::read(runs.join(format!("report/figures/{unit}.png"))).unwrap();
        assert!(png.starts_with(b"\x89PNG\r\n\x1a\n") && png.len() > 10_000, "{unit}.png is not a drawn PNG");
    }
    let shown = common::shakeflow(&["show", "runs/demo/report/summary/data.parquet"], work.path());
    assert!(common::stdout(&shown).contains("FB-4"), "{}", common::stdout(&shown));

    for test in manifest["tests"].as_array().unwrap() {
        let id = test["id"].as_str().unwrap();
        // Lag: DAQ2 time τ is DAQ1 time τ + offset, i.e. the target leads: lag = −offset.
        let lags = read_table(&runs.join(format!("synchronize/lags/motion={id}/data.parquet"))).unwrap();
        let lag = lags.f64_column("lag_s").unwrap()[0];
        let truth = -test["clock_offset_s"].as_f64().unwrap();
        assert!((lag - truth).abs() < 1e-3, "{id}: lag {lag} vs truth {truth}");

        let events = read_table(&runs.join(format!("toppling/events/motion={id}/data.parquet"))).unwrap();
        let channels = str_column(&events, "channel");
        let toppled = match &events.column("toppled").unwrap().data {
            ColumnData::Bool(v) => v.clone(),
            _ => unreachable!(),
        };
        let times = opt_column(&events, "impact_time_s");
        let expected: Vec<(String, f64)> = test["toppling"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| (format!("{}_top_ax_mps2", t["unit"].as_str().unwrap()), t["time_s"].as_f64().unwrap()))
            .collect();
        for (i, channel) in channels.iter().enumerate() {
            match expected.iter().find(|(c, _)| c == channel) {
                Some((_, t)) => {
                    assert!(toppled[i], "{id} {channel}: toppling at {t} s missed");
                    let got = times[i].unwrap();
                    assert!((got - t).abs() < 0.05, "{id} {channel}: impact {got} vs truth {t}");
                }
                None => assert!(!toppled[i], "{id} {channel}: false toppling alarm at {:?}", times[i]),
            }
        }

        if test["kind"] == "white_noise" {
            let identified =
                read_table(&runs.join(format!("transfer_functions/identified/motion={id}/data.parquet"))).unwrap();
            let outputs = str_column(&identified, "output");
            let frequencies = opt_column(&identified, "frequency_hz");
            for unit in test["equipment"].as_array().unwrap() {
                let channel = format!("{}_top_ax_mps2", unit["unit"].as_str().unwrap());
                let i = outputs.iter().position(|o| *o == channel).unwrap();
                let (got, want) = (frequencies[i].unwrap(), unit["frequency_hz"].as_f64().unwrap());
                assert!((got - want).abs() < 0.05, "{id} {channel}: identified {got} Hz vs {want} Hz");
            }
        }
    }
}
