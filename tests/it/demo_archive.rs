//! End-to-end checks of the synthetic archive (written under CARGO_TARGET_TMPDIR).

use crate::common::DemoDaq;
use shakeflow::demo::archive::{
    is_current, is_current_tests, write_demo_archive, write_demo_archive_tests, Manifest, DAQ1_COLUMNS, DAQ1_UNITS,
    DAQ2_COLUMNS, DAQ2_UNITS, GROUPS_DIR, MANIFEST_FILE, README_FILE, SENSITIVITY_FILE, STUDY_TESTS,
};
use shakeflow::demo::study::{equipment_by_id, motion_by_id};
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Instant;

fn scratch(name: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("demo-archive-{name}"))
}

/// One archive shared by the tests (generation is the slow part).
fn primary() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = scratch("primary");
        let t = Instant::now();
        let report = write_demo_archive(&dir).expect("write archive");
        let total: u64 = report.files.iter().map(|f| f.bytes).sum();
        println!(
            "generated {} tests, {} files, {:.1} MB in {:.2} s (this build profile)",
            report.test_ids.len(),
            report.files.len(),
            total as f64 / 1e6,
            t.elapsed().as_secs_f64()
        );
        for f in &report.files {
            assert_eq!(fs::metadata(dir.join(&f.path)).unwrap().len(), f.bytes, "{}", f.path);
        }
        dir
    })
}

fn manifest(dir: &Path) -> Manifest {
    serde_json::from_str(&fs::read_to_string(dir.join(MANIFEST_FILE)).unwrap()).expect("manifest parses")
}

fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

fn all_files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for name in listing(dir) {
        let p = dir.join(&name);
        if p.is_dir() {
            for (sub, bytes) in all_files(&p) {
                out.push((format!("{name}/{sub}"), bytes));
            }
        } else {
            out.push((name, fs::read(p).unwrap()));
        }
    }
    out
}

#[test]
fn generation_is_deterministic_and_replaces_atomically() {
    let a = primary();
    let b = scratch("second");
    // Write twice into the same place: the second run replaces the first.
    write_demo_archive(&b).unwrap();
    let t = Instant::now();
    write_demo_archive(&b).unwrap();
    println!("second generation (replacing an archive) {:.2} s", t.elapsed().as_secs_f64());
    let fa = all_files(a);
    let fb = all_files(&b);
    assert_eq!(fa.len(), fb.len());
    for ((pa, ba), (pb, bb)) in fa.iter().zip(&fb) {
        assert_eq!(pa, pb);
        assert!(ba == bb, "{pa} differs between runs");
    }
    // No temp or old directories left next to the archive.
    let parent = b.parent().unwrap();
    for name in listing(parent) {
        assert!(!name.contains(".tmp-") && !name.contains(".old-"), "leftover {name}");
    }
    assert!(is_current(&b));
    // A changed size, a missing file or another version make it stale.
    let victim = b.join(&manifest(&b).tests.iter().find(|t| t.id == "FB-4").unwrap().daq2_file);
    let mut bytes = fs::read(&victim).unwrap();
    bytes.pop();
    fs::write(&victim, &bytes).unwrap();
    assert!(!is_current(&b));
    fs::remove_file(&victim).unwrap();
    assert!(!is_current(&b));
    let text = fs::read_to_string(b.join(MANIFEST_FILE)).unwrap().replacen("\"version\": \"", "\"version\": \"0.", 1);
    fs::write(b.join(MANIFEST_FILE), text).unwrap();
    assert!(!is_current(&b));
    assert!(!is_current(&scratch("does-not-exist")));
}

/// The largest deviation from the mean of `values[from..to]`.
fn peak_about_mean(values: &[f64], from: usize, to: usize) -> f64 {
    let part = &values[from..to.min(values.len())];
    let mean = part.iter().sum::<f64>() / part.len() as f64;
    part.iter().fold(0.0_f64, |m, v| m.max((v - mean).abs()))
}

#[test]
fn layout_headers_rows_and_manifest() {
    let dir = primary();
    assert!(is_current(dir));
    let m = manifest(dir);
    let ids: Vec<&str> = m.tests.iter().map(|t| t.id.as_str()).collect();
    assert_eq!(
        ids,
        [
            "BI-1", "BI-2", "BI-3", "BI-4", "BI-5", "BI-6", "WN-1", "FB-1", "FB-2", "FB-3", "FB-4", "FB-5", "WN-6",
            "FB-6"
        ]
    );
    let mut expected_top: Vec<String> = vec![GROUPS_DIR.into()];
    expected_top.push(README_FILE.into());
    expected_top.push(MANIFEST_FILE.into());
    expected_top.push("cpt".into());
    expected_top.push(shakeflow::demo::cases::CASES_DIR.into());
    expected_top.sort();
    assert_eq!(listing(dir), expected_top);
    let cases = listing(&dir.join(shakeflow::demo::cases::CASES_DIR));
    assert_eq!(cases, ["MC2_FB-5", "PB1_FB-3", "PS1_FB-5", "PS2_FB-2", "PS2_FB-3", "WSU1_FB-4", "WSU1_FB-5", "truth"]);
    for case in &cases[..cases.len() - 1] {
        let files = listing(&dir.join(shakeflow::demo::cases::CASES_DIR).join(case));
        assert_eq!(files, ["equipment.yaml", "floor.csv", "observed_accel.csv", "observed_cpt.csv"], "{case}");
    }
    let readme = fs::read_to_string(dir.join(README_FILE)).unwrap();
    assert!(readme.contains("NOT REAL DATA"));
    assert_eq!(m.generator.name, "shakeflow demo-archive");
    assert_eq!(m.daq1.sample_rate_hz, 200);
    assert_eq!(m.daq2.sample_rate_hz, 256);

    let mut total_bytes = fs::metadata(dir.join(MANIFEST_FILE)).unwrap().len();
    for f in &m.files {
        total_bytes += f.bytes;
    }
    let cpt_bytes: u64 = m.files.iter().filter(|f| f.path.starts_with("cpt/")).map(|f| f.bytes).sum();
    println!(
        "archive size {:.1} MB, of which the CPT video and its files {:.1} MB",
        total_bytes as f64 / 1e6,
        cpt_bytes as f64 / 1e6
    );
    assert!(total_bytes - cpt_bytes < 60_000_000);
    assert!(cpt_bytes < 25_000_000, "the CPT part stays small");
    assert_eq!(listing(&dir.join("cpt")), ["control_points.csv", "frames", "truth.csv"]);
    assert_eq!(listing(&dir.join("cpt/frames")).len(), m.cpt.frames);
    let truth = fs::read_to_string(dir.join("cpt/truth.csv")).unwrap();
    assert_eq!(truth.lines().count(), m.cpt.frames + 1);
    assert!(truth.starts_with("time_s,theta_rad,x_mm,y_mm,yaw_rad\n"));

    // NEES's layout: base-isolated tests in Experiment-1, fixed-base in Experiment-2, in order.
    let places: Vec<(&str, u32, u32)> = m.tests.iter().map(|t| (t.id.as_str(), t.experiment, t.trial)).collect();
    assert_eq!(
        places,
        [
            ("BI-1", 1, 1),
            ("BI-2", 1, 2),
            ("BI-3", 1, 3),
            ("BI-4", 1, 4),
            ("BI-5", 1, 5),
            ("BI-6", 1, 6),
            ("WN-1", 2, 1),
            ("FB-1", 2, 2),
            ("FB-2", 2, 3),
            ("FB-3", 2, 4),
            ("FB-4", 2, 5),
            ("FB-5", 2, 6),
            ("WN-6", 2, 7),
            ("FB-6", 2, 8)
        ]
    );
    assert_eq!(listing(&dir.join(GROUPS_DIR)), ["Documentation", "Experiment-1", "Experiment-2"]);
    assert_eq!(listing(&dir.join(GROUPS_DIR).join("Experiment-2")).len(), 8);
    // The sensitivity table states what the manifest says was applied.
    let table = fs::read_to_string(dir.join(SENSITIVITY_FILE)).unwrap();
    let rows: Vec<&str> = table.lines().filter(|l| !l.starts_with('#')).collect();
    assert_eq!(rows[0], "channel,sensitivity,unit,offset");
    assert_eq!(rows.len(), 1 + DAQ2_COLUMNS.len() - 1);
    for (row, s) in rows[1..].iter().zip(&m.daq2_sensitivities) {
        assert_eq!(*row, format!("{},{},g,{}", s.channel, s.sensitivity_v_per_g, s.offset_v));
        assert!((0.95..=1.05).contains(&s.sensitivity_v_per_g) && s.offset_v.abs() <= 0.02, "{row}");
    }
    for t in &m.tests {
        let folder = format!("{GROUPS_DIR}/Experiment-{}/Trial-{}/Rep-1", t.experiment, t.trial);
        assert_eq!(t.daq1_file, format!("{folder}/Converted_Data/{}_DAQ1.txt", t.id));
        assert_eq!(t.daq2_file, format!("{folder}/Unprocessed_Data/{}_DAQ2.asc", t.id));
        assert_eq!(listing(&dir.join(&folder)), ["Converted_Data", "Unprocessed_Data"]);
        assert!((0.4..2.5).contains(&t.clock_offset_s), "{} offset {}", t.id, t.clock_offset_s);
        for rate in [200.0, 256.0] {
            let samples = t.clock_offset_s * rate;
            assert!((samples - samples.round()).abs() > 0.01, "{} offset on the {rate} Hz grid", t.id);
        }
        match motion_by_id(&t.id) {
            Some(mo) => {
                assert_eq!(t.kind, "earthquake");
                assert_eq!(t.input, mo.input);
                assert_eq!(t.base, mo.base.code());
                assert!((t.ground_pga_g - mo.pia_g).abs() <= 1e-6 * mo.pia_g, "{} pga {}", t.id, t.ground_pga_g);
            }
            None => {
                assert_eq!(t.kind, "white_noise");
                assert_eq!(t.base, "FB");
                assert!((0.03..=0.05).contains(&t.ground_pga_g));
            }
        }
        let target = if t.base == "FB" { 1.0 } else { 2.8 };
        assert!((t.building_period_s - target).abs() < 0.01 * target);
        for e in &t.equipment {
            let eq = equipment_by_id(&e.unit).unwrap();
            let f = if t.frequency_set == "before FB-1" { eq.freq_before_fb1_hz } else { eq.freq_before_fb6_hz };
            assert_eq!(e.frequency_hz, f);
            assert!((0.03..=0.05).contains(&e.damping_ratio));
            assert!((0.01..=0.03).contains(&e.offset_g.abs()));
            assert!((0.01..=0.02).contains(&(e.drift_linear_g + e.drift_quadratic_g).abs()));
        }
        for c in &t.floor_channels {
            assert!(c.offset_g.abs() <= 0.002);
        }

        let daq1 = DemoDaq::read(dir, &t.daq1_file);
        assert_eq!(daq1.preamble[0], format!("NEES-2009-0722\tExperiment-{}\tTrial-{}\tRep-1", t.experiment, t.trial));
        assert!(daq1.preamble[1].starts_with(&format!("Test: {}, input: {}, event: ", t.id, t.input)));
        assert!(daq1.preamble[1].ends_with(&format!("base: {}", t.base)));
        assert!(daq1.preamble[2].starts_with("DAQ1: floor accelerometers (floor averages), sampling rate: 200 Hz"));
        assert!(
            daq1.preamble[3].starts_with("SYNTHETIC demo archive") && daq1.preamble[3].ends_with("(not real data)")
        );
        assert_eq!(daq1.names, DAQ1_COLUMNS);
        assert_eq!(daq1.names, ["Time", "A4_EW", "A4_NS", "A4_UD", "A5_EW", "A5_NS", "A5_UD"]);
        assert_eq!(daq1.units, DAQ1_UNITS);
        assert_eq!(daq1.units, ["sec", "in/sec^2", "in/sec^2", "g", "in/sec^2", "in/sec^2", "g"]);
        assert_eq!(daq1.descriptions[1], "floor 4 acceleration, E-W (X, shaking direction)");
        assert_eq!(daq1.rows.len(), (t.duration_s * 200.0) as usize);
        assert_eq!(daq1.rows.len(), t.daq1_rows);
        assert_eq!(daq1.times[0], "0.000000");
        assert_eq!(daq1.times[1], "0.005000");
        // In g, each channel's first second (before the motion) is its sensor offset: the units
        // row's in/sec^2 and g give back what the manifest says was applied.
        for c in &t.floor_channels {
            let quiet = &daq1.g(&c.channel, dir)[..200];
            let mean = quiet.iter().sum::<f64>() / 200.0;
            assert!(
                (mean - c.offset_g).abs() < 1e-4,
                "{} {}: {mean} g at rest vs offset {} g",
                t.id,
                c.channel,
                c.offset_g
            );
        }

        let daq2 = DemoDaq::read(dir, &t.daq2_file);
        assert_eq!(daq2.preamble[..2], daq1.preamble[..2]);
        assert!(
            daq2.preamble[2].starts_with("DAQ2: equipment top accelerometers (E-W), sampling rate: 256 Hz, raw volts")
        );
        assert!(daq2.preamble[2].contains("NOT synchronised"));
        assert_eq!(daq2.names, DAQ2_COLUMNS);
        assert_eq!(
            daq2.names,
            [
                "Time",
                "A5_EW_SYNC",
                "UI3_TOP_EW",
                "MC2_TOP_EW",
                "PB1_TOP_EW",
                "PB2_TOP_EW",
                "PS1_TOP_EW",
                "PS2_TOP_EW",
                "WSU1_TOP_EW"
            ]
        );
        assert_eq!(daq2.units, DAQ2_UNITS);
        assert_eq!(daq2.descriptions[7], "stretcher PS2 (floor 5, locked), top, E-W");
        assert_eq!(daq2.rows.len(), (t.duration_s * 256.0) as usize);
        assert_eq!(daq2.rows.len(), t.daq2_rows);
        assert_eq!(daq2.times[0], "0.000000");
        assert_eq!(daq2.times[1], "0.003906");
        // Volts through the sensitivity table: each unit's sensor offset at rest (an earthquake
        // starts at 3 s of DAQ1 time, after DAQ2's first 0.5 s), in g.
        for e in t.equipment.iter().filter(|_| t.kind == "earthquake") {
            let quiet = &daq2.g(&e.channel, dir)[..128];
            let mean = quiet.iter().sum::<f64>() / 128.0;
            assert!(
                (mean - e.offset_g).abs() < 3e-4,
                "{} {}: {mean} g at rest vs offset {} g",
                t.id,
                e.channel,
                e.offset_g
            );
        }

        // Physical plausibility (floor 4 channels, strong part of the record).
        let ew = peak_about_mean(&daq1.g("A4_EW", dir), 0, usize::MAX);
        let ns = peak_about_mean(&daq1.g("A4_NS", dir), 0, usize::MAX);
        let ud = peak_about_mean(&daq1.g("A4_UD", dir), 0, usize::MAX);
        println!(
            "{}: pga {:.3} g, A4_EW {:.3} g ({:.2}x), NS/EW {:.3}, UD/EW {:.3}, clock offset {:.6} s",
            t.id,
            t.ground_pga_g,
            ew,
            ew / t.ground_pga_g,
            ns / ew,
            ud / ew,
            t.clock_offset_s
        );
        assert!((0.03..0.15).contains(&(ns / ew)), "{} NS/EW {}", t.id, ns / ew);
        assert!((0.07..0.15).contains(&(ud / ew)), "{} UD/EW {}", t.id, ud / ew);

        for tp in &t.toppling {
            let top = daq2.g(&tp.channel, dir);
            let k = ((tp.time_s - t.clock_offset_s) * 256.0).round() as usize;
            let spike = peak_about_mean(&top, k.saturating_sub(256), k + 26);
            let before = peak_about_mean(&top, k.saturating_sub(1280), k.saturating_sub(10));
            let after = peak_about_mean(&top, k + 40, k + 40 + 1280);
            println!(
                "  topple {} at {:.2} s: spike {:.2} g, 5 s before {:.3} g, 5 s after {:.3} g",
                tp.unit, tp.time_s, spike, before, after
            );
            assert!(spike > 3.0 && spike > 1.5 * before, "spike {spike} vs before {before}");
            assert!(after < 0.25 * before, "after {after} vs before {before}");
        }
    }
    let fb4 = m.tests.iter().find(|t| t.id == "FB-4").unwrap();
    assert_eq!(fb4.toppling.len(), 1);
    assert_eq!(
        (fb4.toppling[0].unit.as_str(), fb4.toppling[0].time_s, fb4.toppling[0].side.as_str()),
        ("PS2", 30.9, "right")
    );
    assert!(m.tests.iter().find(|t| t.id == "FB-5").unwrap().toppling.iter().any(|p| p.unit == "PS2"));
    assert!(m.tests.iter().find(|t| t.id == "FB-6").unwrap().toppling.iter().any(|p| p.unit == "WSU1"));
}

/// `demo-archive --tests N`: the study's 14 tests byte for byte as in the default archive, then
/// variations of its motions in turn (scale and seed), named in the manifest.
#[test]
fn extra_tests_vary_the_motions_and_keep_the_study_bytes() {
    let study = primary();
    let dir = scratch("extra");
    let report = write_demo_archive_tests(&dir, STUDY_TESTS + 2).unwrap();
    assert_eq!(report.test_ids[STUDY_TESTS..], ["V-0001", "V-0002"]);
    assert!(is_current_tests(&dir, STUDY_TESTS + 2));
    assert!(!is_current(&dir), "a 16-test archive is not the study's");
    assert!(!is_current_tests(study, STUDY_TESTS + 2));
    assert!(write_demo_archive_tests(&scratch("too-few"), STUDY_TESTS - 1).is_err());
    let extra: std::collections::BTreeMap<String, Vec<u8>> = all_files(&dir).into_iter().collect();
    for (path, bytes) in all_files(study) {
        if path == README_FILE || path == MANIFEST_FILE {
            continue;
        }
        assert!(extra.get(&path) == Some(&bytes), "{path} differs from the study archive's");
    }
    let m = manifest(&dir);
    assert_eq!(m.tests[..STUDY_TESTS], manifest(study).tests[..]);
    for (t, of) in m.tests[STUDY_TESTS..].iter().zip(["BI-1", "BI-2"]) {
        let mo = motion_by_id(of).unwrap();
        let scale = t.variation_scale.unwrap();
        assert_eq!((t.variation_of.as_deref(), t.base.as_str(), t.kind.as_str()), (Some(of), "BI", "earthquake"));
        assert!((0.5..=1.5).contains(&scale));
        assert_eq!(t.table1_pia_g, None);
        assert!((t.ground_pga_g - mo.pia_g * scale).abs() <= 1e-6 * mo.pia_g, "{} pga {}", t.id, t.ground_pga_g);
        assert_eq!((t.experiment, t.trial), (3, t.id[2..].parse().unwrap()));
        let rows = DemoDaq::read(&dir, &t.daq1_file).rows;
        assert_eq!(rows.len(), t.daq1_rows);
        let study_file = &m.tests.iter().find(|s| s.id == of).unwrap().daq1_file;
        let study_rows = DemoDaq::read(study, study_file).rows;
        assert!(rows.iter().zip(&study_rows).any(|(a, b)| a[1] != b[1]), "{} is a copy of {of}", t.id);
    }
}
