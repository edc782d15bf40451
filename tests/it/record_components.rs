//! Records as the agencies ship them: every sample of the 18 shared strong-motion files kept
//! (against the point counts SOURCES.md states, which come from the files' headers), a channel
//! longer than its siblings kept whole, `format: auto`, and components in files of their own
//! (K-NET/KiK-net `.EW`/`.NS`/`.UD`, PEER `.AT2`, COSMOS per channel) joined into one record
//! per station, with errors naming the files when they do not share a clock.

use crate::common::{self, shakeflow, stderr};
use crate::record_formats::column;

use serde_json::{json, Value};
use shakeflow::pipeline::spec::SourceSpec;
use shakeflow::stages::{load, InputPart};
use shakeflow::table::{Table, TIME_COLUMN};
use std::path::{Path, PathBuf};

fn record(name: &str) -> PathBuf {
    let path = common::shared_dir().join("data/records").join(name);
    assert!(path.is_file(), "shared record {} is missing", path.display());
    path
}

/// One file through `load` as a source with `spec` would read it.
fn load_file(path: &Path, spec: Value) -> Result<Table, String> {
    let mut spec = spec;
    spec["path"] = json!(path.display().to_string());
    let spec: SourceSpec = serde_json::from_value(spec).unwrap();
    let label = path.file_name().unwrap().to_string_lossy().into_owned();
    let part = InputPart { partition: vec![], path: path.to_path_buf(), label, hash: String::new() };
    load::load_record(&spec, &part).map_err(|e| e.to_string())
}

fn summary(table: &Table) -> Value {
    serde_json::from_str(&table.metadata["shakeflow.load"]).unwrap()
}

/// Each shared file's channels with their point counts as SOURCES.md states them (the files'
/// headers), and the reader that must have read it.
const STATED: [(&str, &str, &[usize]); 18] = [
    ("cosmos/NP1795-n.305.v0c", "cosmos", &[20000, 20000, 20000]),
    ("cosmos/NCMDH--n.00725272.HNE.--.V1c", "cosmos", &[19200]),
    ("cosmos/us1000hyfh_akbmrp_AKBMR--n.1000hyfh.BNZ.--.acc.V2c", "cosmos", &[42000]),
    ("dmg/CE89146.V1", "dmg", &[13200, 13200, 13200]),
    ("dmg/CE89146.V2", "dmg", &[12000, 12000, 12000]),
    ("dmg/CIWLT.RAW", "dmg", &[30130, 30058, 30312]),
    ("smc/0111a.smc", "smc", &[6001]),
    ("smc/2825.HNE.NP.--_u.smc", "smc", &[44800]),
    ("knet/AOM0051801241951.EW", "knet", &[9500]),
    ("knet/AOM0051801241951.NS", "knet", &[9500]),
    ("knet/AOM0051801241951.UD", "knet", &[9500]),
    ("knet/AICH040010061330.EW2", "knet", &[28600]),
    ("knet/AICH040010061330.NS2", "knet", &[28600]),
    ("knet/AICH040010061330.UD2", "knet", &[28600]),
    ("esm/HI.ARS1..HNE.D.20190728.160908.C.ACC.ASC", "esm", &[19128]),
    ("esm/20101114230825_3104_ap_RawAcc_E.asc", "esm", &[5600]),
    ("geonet/20180212_211557_WPWS_20.V2A", "geonet", &[5800, 5800, 5800]),
    ("nga/RSN10590_ComalTX11-10-20_IU.CCM.BH1.00.AT2", "at2", &[15306]),
];

/// Every file of ../shared/data/records read with `format: auto`: the reader its folder names,
/// and in the file's channel order as many samples as its header states, no more, no fewer.
#[test]
fn every_sample_of_the_shared_records_is_kept() {
    let (mut stated_total, mut kept_total) = (0, 0);
    for (file, reader, stated) in STATED {
        let table = load_file(&record(file), json!({"format": "auto"})).unwrap_or_else(|e| panic!("{e}"));
        let summary = summary(&table);
        assert_eq!(summary["format"], reader, "{file}: the reader used");
        assert_eq!(summary["format_detected"], true, "{file}");
        let columns = summary["columns"].as_object().unwrap();
        // Channel lengths as a multiset: which axis each channel becomes is record_formats.rs's check.
        let mut counts: Vec<usize> = columns.keys().map(|name| column(&table, name).len()).collect();
        let mut want = stated.to_vec();
        counts.sort_unstable();
        want.sort_unstable();
        assert_eq!(counts, want, "{file}: samples per channel");
        assert_eq!(table.num_rows(), *stated.iter().max().unwrap(), "{file}: rows");
        for (name, c) in columns {
            assert_eq!(c["npts"].as_u64().unwrap() as usize, column(&table, name).len(), "{file} {name}: npts");
        }
        stated_total += stated.iter().sum::<usize>();
        kept_total += counts.iter().sum::<usize>();
    }
    assert_eq!(kept_total, stated_total);
    eprintln!("18 shared record files: {kept_total} samples kept of {stated_total} stated");
}

/// The held-out CSMIP Vol.2 `ce36456p_CE36456.V2` has channels of 3251, 3250 and 3250 points;
/// the same shape made from the shared CE89146.V2: its first channel (360°, so `ay`) one value
/// longer. The table has 12001 rows, `ay` keeps its last sample, the others are null there.
#[test]
fn a_vol2_channel_one_sample_longer_keeps_that_sample() {
    let dir = crate::tempdir::tempdir().unwrap();
    let text = std::fs::read_to_string(record("dmg/CE89146.V2")).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let data = lines.iter().position(|l| l.contains("points of accel data")).unwrap();
    lines[data] = lines[data].replacen(" 12000 points of accel", " 12001 points of accel", 1);
    // 12000 values are 1500 full lines of 8: the 12001st starts a line of its own.
    lines.insert(data + 1501, "  1.234567".to_string());
    let path = dir.path().join("CE89146_long.V2");
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();

    let table = load_file(&path, json!({"format": "auto"})).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(table.num_rows(), 12001);
    let ay = column(&table, "ay_mps2");
    assert_eq!(ay.len(), 12001);
    assert_eq!(ay[12000], 1.234567 * 0.01, "the extra sample, cm/s² to m/s²");
    assert_eq!(column(&table, "ax_mps2").len(), 12000);
    assert_eq!(column(&table, "az_mps2").len(), 12000);
    // The rest is what the original file gives.
    let original = load_file(&record("dmg/CE89146.V2"), json!({"format": "dmg"})).unwrap();
    assert_eq!(ay[..12000], column(&original, "ay_mps2")[..]);
    assert_eq!(column(&table, "ax_mps2"), column(&original, "ax_mps2"));
    let summary = summary(&table);
    assert_eq!(summary["columns"]["ay_mps2"]["npts"], 12001);
    assert_eq!(summary["columns"]["ax_mps2"]["npts"], 12000);
    let flags: Value = serde_json::from_str(&table.metadata[load::FLAGS_KEY]).unwrap();
    let reasons: Vec<&str> = flags.as_array().unwrap().iter().map(|f| f["reason"].as_str().unwrap()).collect();
    assert_eq!(reasons.len(), 2, "{reasons:?}");
    assert!(
        reasons.iter().all(|r| r.contains("has 12000 samples, the record's longest 12001: its last 1 row(s) are null")),
        "{reasons:?}"
    );
}

/// `format: auto` refuses a file no reader claims, naming it and what to do.
#[test]
fn auto_refuses_a_file_it_cannot_tell() {
    let dir = crate::tempdir::tempdir().unwrap();
    let path = dir.path().join("notes.xyz");
    std::fs::write(&path, "station log\nnothing numeric here\n").unwrap();
    let err = load_file(&path, json!({"format": "auto"})).unwrap_err();
    assert!(err.contains("notes.xyz:1"), "{err}");
    assert!(err.contains("`format: auto` cannot tell this file's format"), "{err}");
    assert!(err.contains("(`.xyz`)"), "{err}");
    assert!(err.contains("give the source the file's `format:`"), "{err}");
}

/// A folder laid out as the agencies ship it, copied from ../shared/data/records: `knet/` holds
/// K-NET's and KiK-net's one-component files, `other/` the rest.
fn archive(dir: &Path) {
    for (file, _, _) in STATED {
        let folder = if file.starts_with("knet/") { "knet" } else { "other" };
        let to = dir.join("archive").join(folder);
        std::fs::create_dir_all(&to).unwrap();
        std::fs::copy(record(file), to.join(Path::new(file).file_name().unwrap())).unwrap();
    }
}

const PIPELINE: &str = "\
version: 1
output_dir: out
inputs:
  knet:
    format: auto
    path: archive/knet/{station}.{component}
    components: {key: component}
  other:
    format: auto
    path: archive/other/{file}
stages:
  load:
    type: load
    inputs: [knet, other]
";

fn read(dir: &Path, partition: &str) -> Table {
    let path = dir.join("out/load/records").join(partition).join("data.parquet");
    shakeflow::io::parquet::read_table(&path).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()))
}

/// The archive's 18 files make 14 records: the 6 K-NET/KiK-net files 2 (one per station, its
/// three components side by side on one clock), the others one each; each K-NET record's columns
/// are, bit for bit, what its component files give alone.
#[test]
fn a_station_s_component_files_make_one_record() {
    let dir = crate::tempdir::tempdir().unwrap();
    archive(dir.path());
    std::fs::write(dir.path().join("pipeline.yaml"), PIPELINE).unwrap();
    let out = shakeflow(&["run", "pipeline.yaml"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let records = |folder: &str| -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir.path().join("out/load/records"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(folder))
            .collect();
        names.sort();
        names
    };
    assert_eq!(records("station="), ["station=AICH040010061330", "station=AOM0051801241951"]);
    assert_eq!(records("file=").len(), 12);
    for (station, ext, npts) in [("AOM0051801241951", "", 9500), ("AICH040010061330", "2", 28600)] {
        let table = read(dir.path(), &format!("station={station}"));
        assert_eq!(table.column_names(), [TIME_COLUMN, "ax_mps2", "ay_mps2", "az_mps2"]);
        assert_eq!(table.num_rows(), npts);
        let meta = summary(&table);
        assert_eq!(meta["format"], "knet");
        for (axis, component) in [("ax_mps2", "EW"), ("ay_mps2", "NS"), ("az_mps2", "UD")] {
            let file = record(&format!("knet/{station}.{component}{ext}"));
            let alone = load_file(&file, json!({"format": "knet"})).unwrap();
            let name = if axis == "az_mps2" { "az_mps2" } else { "ax_mps2" };
            assert_eq!(column(&table, axis), column(&alone, name), "{station} {axis}");
            let file_column = meta["columns"][axis]["file_column"].as_str().unwrap();
            assert_eq!(
                meta["header"][format!("channel.{file_column}.file")],
                format!("archive/knet/{station}.{component}{ext}")
            );
            assert_eq!(meta["header"][format!("channel.{file_column}.component")], format!("{component}{ext}"));
            // Record-wide facts the components disagree on are kept per component.
            assert!(meta["header"][format!("component.{component}{ext}.peak_gal")].is_string(), "{meta}");
        }
        assert_eq!(meta["header"]["station"], station[..6]);
        let files = &table.metadata["shakeflow.input_file"];
        assert_eq!(files.matches("archive/knet/").count(), 3, "{files}");
    }
}

/// PEER NGA's one `.AT2` per component (Rinaldi 228, 318, UP) and a COSMOS file split into one
/// file per channel, as CESMD ships them, each join into one record equal to its parts.
#[test]
fn peer_and_cosmos_components_join_by_their_stated_orientations() {
    let dir = crate::tempdir::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("peer")).unwrap();
    for c in ["228", "318", "UP"] {
        std::fs::copy(
            common::ground_motion(&format!("Rinaldi{c}.AT2")),
            dir.path().join(format!("peer/Rinaldi{c}.AT2")),
        )
        .unwrap();
    }
    // NP1795-n.305.v0c holds HNE, HNN and HNZ one after another; each starts with its `(Format v` line.
    std::fs::create_dir_all(dir.path().join("cosmos")).unwrap();
    let text = std::fs::read_to_string(record("cosmos/NP1795-n.305.v0c")).unwrap();
    let starts: Vec<usize> = text
        .match_indices('\n')
        .map(|(i, _)| i + 1)
        .filter(|&i| text[i..].lines().next().unwrap_or("").contains("(Format v"))
        .collect();
    let mut bounds = vec![0];
    bounds.extend(starts.iter().copied().filter(|&i| i > 0));
    bounds.push(text.len());
    assert_eq!(bounds.len(), 4, "three channels");
    for (k, c) in ["HNE", "HNN", "HNZ"].iter().enumerate() {
        std::fs::write(dir.path().join(format!("cosmos/NP1795.{c}.v0c")), &text[bounds[k]..bounds[k + 1]]).unwrap();
    }
    let pipeline = "\
version: 1
output_dir: out
inputs:
  peer:
    format: at2
    path: peer/Rinaldi{component}.AT2
    partition: {station: Rinaldi}
    components: {key: component}
  cesmd:
    format: auto
    path: cosmos/{station}.{channel}.v0c
    components: {key: channel}
stages:
  load:
    type: load
    inputs: [peer, cesmd]
";
    std::fs::write(dir.path().join("pipeline.yaml"), pipeline).unwrap();
    let out = shakeflow(&["run", "pipeline.yaml"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));

    let rinaldi = read(dir.path(), "station=Rinaldi");
    assert_eq!(rinaldi.column_names(), [TIME_COLUMN, "ax_mps2", "ay_mps2", "az_mps2"]);
    // 228° is nearer east–west than 318° (|sin| 0.74 against 0.67): x.
    for (axis, c) in [("ax_mps2", "228"), ("ay_mps2", "318"), ("az_mps2", "UP")] {
        let alone = load_file(&dir.path().join(format!("peer/Rinaldi{c}.AT2")), json!({"format": "at2"})).unwrap();
        let name = if c == "UP" { "az_mps2" } else { "ax_mps2" };
        assert_eq!(column(&rinaldi, axis), column(&alone, name), "Rinaldi {axis}");
    }
    let joined = read(dir.path(), "station=NP1795");
    let whole = load_file(&record("cosmos/NP1795-n.305.v0c"), json!({"format": "cosmos"})).unwrap();
    assert_eq!(joined.column_names(), whole.column_names());
    for name in ["ax_mps2", "ay_mps2", "az_mps2"] {
        assert_eq!(column(&joined, name), column(&whole, name), "NP1795 {name}");
    }
}

/// Runs PIPELINE on the K-NET station AOM005 with `edit` applied to its files first; stderr.
fn knet_run_failing(edit: impl Fn(&Path), on_error: &str) -> (std::process::Output, crate::tempdir::TempDir) {
    let dir = crate::tempdir::tempdir().unwrap();
    let knet = dir.path().join("archive/knet");
    std::fs::create_dir_all(&knet).unwrap();
    for c in ["EW", "NS", "UD"] {
        std::fs::copy(record(&format!("knet/AOM0051801241951.{c}")), knet.join(format!("AOM0051801241951.{c}")))
            .unwrap();
    }
    edit(&knet);
    let pipeline = PIPELINE.replace(
        "    components: {key: component}\n",
        &format!("    components: {{key: component}}\n    on_error: {on_error}\n"),
    );
    let pipeline = pipeline
        .replace("  other:\n    format: auto\n    path: archive/other/{file}\n", "")
        .replace("[knet, other]", "[knet]");
    std::fs::write(dir.path().join("pipeline.yaml"), pipeline).unwrap();
    (shakeflow(&["run", "pipeline.yaml"], dir.path()), dir)
}

fn edit_line(path: &Path, starts: &str, new: &str) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut done = false;
    let edited: Vec<String> = text
        .lines()
        .map(|l| {
            if !done && l.starts_with(starts) {
                done = true;
                new.to_string()
            } else {
                l.to_string()
            }
        })
        .collect();
    assert!(done, "{starts}");
    std::fs::write(path, edited.join("\n") + "\n").unwrap();
}

#[test]
fn a_missing_component_is_refused_naming_the_files() {
    let (out, dir) = knet_run_failing(|knet| std::fs::remove_file(knet.join("AOM0051801241951.UD")).unwrap(), "fail");
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("record `AOM0051801241951` (archive/knet/AOM0051801241951.EW, archive/knet/AOM0051801241951.NS)"),
        "{err}"
    );
    assert!(err.contains("no `z` component among its 2 file(s) (components EW, NS)"), "{err}");
    assert!(!dir.path().join("out/load/records").exists());
    // `validate` finds it before anything runs, at the source's `components:` line.
    let out = shakeflow(&["validate", "pipeline.yaml"], dir.path());
    assert_eq!(out.status.code(), Some(1), "{}", common::stdout(&out));
    let err = stderr(&out);
    assert!(err.contains("pipeline.yaml:7:"), "{err}");
    assert!(
        err.contains("record `station=AOM0051801241951` has 2 component file(s) (AOM0051801241951.EW, AOM0051801241951.NS), fewer than the 3 axes"),
        "{err}"
    );
    // Skipped instead, it is listed with the reason and the run goes on (exit 2).
    let (out, dir) = knet_run_failing(|knet| std::fs::remove_file(knet.join("AOM0051801241951.UD")).unwrap(), "skip");
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    let flagged = shakeflow::io::parquet::read_table(&dir.path().join("out/load/flagged/data.parquet")).unwrap();
    assert_eq!(flagged.num_rows(), 1);
    // … and `validate` notes it; with no other record that loads, the source is refused.
    let out = shakeflow(&["validate", "pipeline.yaml"], dir.path());
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let said = common::stdout(&out);
    assert!(
        said.contains("fewer than the 3 axes `components: require` asks for; `run` will skip that record"),
        "{said}"
    );
}

#[test]
fn components_on_different_clocks_are_refused_naming_the_files() {
    let (out, _dir) = knet_run_failing(
        |knet| edit_line(&knet.join("AOM0051801241951.UD"), "Record Time", "Record Time       2018/01/24 19:51:41"),
        "fail",
    );
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("its `EW` file starts at 2018/01/24 19:51:40, its `UD` file at 2018/01/24 19:51:41"), "{err}");
    assert!(err.contains("AOM0051801241951.UD"), "{err}");
    // `validate` reads the first record's files together, as `load` does.
    let out = shakeflow(&["validate", "pipeline.yaml"], _dir.path());
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("source `knet`, read as `load` would: record `AOM0051801241951`"), "{err}");
    assert!(err.contains("its `EW` file starts at 2018/01/24 19:51:40, its `UD` file at 2018/01/24 19:51:41"), "{err}");

    let (out, _dir) = knet_run_failing(
        |knet| {
            let ns = knet.join("AOM0051801241951.NS");
            edit_line(&ns, "Sampling Freq(Hz)", "Sampling Freq(Hz) 200Hz");
            edit_line(&ns, "Duration Time(s)", "Duration Time(s)  47.5");
        },
        "fail",
    );
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("its `EW` file is sampled every 0.01 s, its `NS` file every 0.005 s"), "{err}");
}

/// A `components:` key the path does not name is refused at the key, before anything runs.
#[test]
fn a_component_key_missing_from_the_path_is_refused_at_its_line() {
    let dir = crate::tempdir::tempdir().unwrap();
    archive(dir.path());
    let pipeline = PIPELINE.replace("components: {key: component}", "components: {key: comp}");
    std::fs::write(dir.path().join("pipeline.yaml"), pipeline).unwrap();
    let out = shakeflow(&["run", "pipeline.yaml"], dir.path());
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("pipeline.yaml:7:"), "{err}");
    assert!(
        err.contains("`components: {key: comp}` names no `{comp}` of the path `archive/knet/{station}.{component}`"),
        "{err}"
    );
}

fn status_rows(dir: &Path) -> Vec<[String; 4]> {
    let table = shakeflow::io::parquet::read_table(&dir.join("out/load/status/data.parquet")).unwrap();
    let text = |name: &str| match &table.column(name).unwrap().data {
        shakeflow::table::ColumnData::Str(v) => v.clone(),
        other => panic!("{name}: {}", other.type_name()),
    };
    let [record, status, file, reason] = ["record", "status", "file", "reason"].map(text);
    (0..table.num_rows()).map(|k| [record[k].clone(), status[k].clone(), file[k].clone(), reason[k].clone()]).collect()
}

/// After a run over an archive (`on_error: skip`), `load/status` lists every record: loaded,
/// flagged (loaded whole; the reason with file:line), skipped (the reader's file:line:column);
/// the same on a rerun that finds everything cached; and the report shows it.
#[test]
fn the_status_table_lists_every_record_and_the_report_shows_it() {
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    std::fs::create_dir_all(root.join("archive/knet")).unwrap();
    std::fs::create_dir_all(root.join("archive/other")).unwrap();
    for c in ["EW", "NS", "UD"] {
        std::fs::copy(
            record(&format!("knet/AOM0051801241951.{c}")),
            root.join(format!("archive/knet/AOM0051801241951.{c}")),
        )
        .unwrap();
    }
    // KiK-net AICH04 without its vertical: skipped.
    for c in ["EW2", "NS2"] {
        std::fs::copy(
            record(&format!("knet/AICH040010061330.{c}")),
            root.join(format!("archive/knet/AICH040010061330.{c}")),
        )
        .unwrap();
    }
    std::fs::copy(record("dmg/CIWLT.RAW"), root.join("archive/other/CIWLT.RAW")).unwrap();
    std::fs::copy(record("dmg/CE89146.V2"), root.join("archive/other/CE89146.V2")).unwrap();
    let smc = std::fs::read_to_string(record("smc/0111a.smc")).unwrap();
    std::fs::write(root.join("archive/other/broken.smc"), smc.replacen("-2.2223E+0", "-2.2x23E+0", 1)).unwrap();
    // PIPELINE, every source `on_error: skip`, and a report of the status table.
    let pipeline = PIPELINE
        .replace("{file}\n", "{file}\n    on_error: skip\n")
        .replace("    components: {key: component}\n", "    components: {key: component}\n    on_error: skip\n")
        + "  report:\n    type: report\n    inputs: [load.status]\n";
    std::fs::write(root.join("pipeline.yaml"), pipeline).unwrap();
    let expected = |rows: &[[String; 4]]| {
        let by: Vec<(&str, &str)> = rows.iter().map(|r| (r[0].as_str(), r[1].as_str())).collect();
        assert_eq!(
            by,
            [
                ("file=CE89146.V2", "loaded"),
                ("file=CIWLT.RAW", "flagged"),
                ("file=broken.smc", "skipped"),
                ("station=AICH040010061330", "skipped"),
                ("station=AOM0051801241951", "loaded"),
            ]
        );
        assert_eq!(rows[0][3], "");
        assert!(rows[1][3].contains("has 30130 samples, the record's longest 30312: its last 182 row(s) are null (archive/other/CIWLT.RAW:29)"), "{rows:?}");
        assert!(rows[1][3].contains("(archive/other/CIWLT.RAW:3825)"), "{rows:?}");
        assert!(rows[2][3].contains("broken.smc:36:11"), "{rows:?}");
        assert!(rows[3][3].contains("no `z` component"), "{rows:?}");
        assert_eq!(
            rows[4][2],
            "archive/knet/AOM0051801241951.EW, archive/knet/AOM0051801241951.NS, archive/knet/AOM0051801241951.UD"
        );
    };
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    expected(&status_rows(root));
    let html = std::fs::read_to_string(root.join("out/report/index.html")).unwrap();
    assert!(html.contains("<section id=\"records\">"), "{html}");
    assert!(html.contains("5 record(s): 0 failed, 2 skipped, 1 flagged, 2 loaded"), "{html}");
    assert!(html.contains("its last 182 row(s) are null (archive/other/CIWLT.RAW:29)"), "{html}");
    // Everything cached: the same table (the flags come from the lockfile).
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(common::stdout(&out).contains("cached") || stderr(&out).contains("cached"), "{}", stderr(&out));
    expected(&status_rows(root));
}

/// Without `on_error: skip`, a record that cannot be read fails its unit: the run exits 1, the
/// other records are committed, and the status table lists it `failed` with the reader's
/// file:line:column; mended, the next run loads it and the table says so.
#[test]
fn a_failed_record_is_listed_failed_and_the_others_are_committed() {
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    archive(root);
    let smc = root.join("archive/other/0111a.smc");
    let good = std::fs::read_to_string(&smc).unwrap();
    std::fs::write(&smc, good.replacen("-2.2223E+0", "-2.2x23E+0", 1)).unwrap();
    std::fs::write(root.join("pipeline.yaml"), PIPELINE).unwrap();
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let rows = status_rows(root);
    assert_eq!(rows.len(), 14, "{rows:?}");
    let failed: Vec<&[String; 4]> = rows.iter().filter(|r| r[1] == "failed").collect();
    assert_eq!(failed.len(), 1, "{rows:?}");
    assert_eq!(failed[0][0], "file=0111a.smc");
    assert!(failed[0][3].contains("0111a.smc:36:11"), "{:?}", failed[0]);
    assert!(rows.iter().filter(|r| r[1] != "failed").all(|r| r[1] == "loaded" || r[1] == "flagged"), "{rows:?}");
    assert!(root.join("out/load/records/station=AOM0051801241951/data.parquet").is_file());
    assert!(!root.join("out/load/records/file=0111a.smc").exists());
    std::fs::write(&smc, good).unwrap();
    let out = shakeflow(&["run", "pipeline.yaml"], root);
    assert!(out.status.success(), "{}", stderr(&out));
    let rows = status_rows(root);
    assert!(rows.iter().any(|r| r[0] == "file=0111a.smc" && r[1] == "loaded"), "{rows:?}");
    assert!(rows.iter().all(|r| r[1] != "failed"), "{rows:?}");
}

/// No reader stops early without a word: each shared file with one more value line at its end
/// (past what its header announces) is refused at that line, never read as if it were not there.
#[test]
fn a_value_past_the_stated_count_is_refused_by_every_reader() {
    let dir = crate::tempdir::tempdir().unwrap();
    for (file, reader, _) in STATED {
        let mut text = std::fs::read_to_string(record(file)).unwrap();
        let lines = text.lines().count();
        if !text.ends_with('\n') {
            text.push('\n');
        }
        text.push_str("   0.0012   0.0034\n");
        let path = dir.path().join(Path::new(file).file_name().unwrap());
        std::fs::write(&path, text).unwrap();
        let err = load_file(&path, json!({"format": reader})).expect_err(file);
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let after = err.split_once(&format!("{name}:")).unwrap_or_else(|| panic!("{file}: {err}")).1;
        let line: usize = after.split(':').next().unwrap().parse().unwrap_or_else(|_| panic!("{file}: {err}"));
        // At the extra line, or (AT2) at the NPTS line naming the last line it found values on.
        let named = err.contains(&format!("up to line {}", lines + 1));
        assert!(line >= lines || named, "{file}: refused at line {line}, the extra line is {}: {err}", lines + 1);
    }
}
