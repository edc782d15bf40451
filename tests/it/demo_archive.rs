//! End-to-end checks of the synthetic archive (written under CARGO_TARGET_TMPDIR).

use shakeflow::demo::archive::{
    is_current, write_demo_archive, Manifest, DAQ1_COLUMNS, DAQ1_FILE, DAQ2_COLUMNS, DAQ2_FILE, MANIFEST_FILE,
    README_FILE,
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
    let victim = b.join("FB-4").join(DAQ2_FILE);
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

/// Parses a CSV: returns (comment lines, header, rows).
fn read_csv(path: &Path) -> (Vec<String>, String, Vec<Vec<f64>>, Vec<String>) {
    let text = fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let comments: Vec<String> = (0..4).map(|_| lines.next().unwrap().to_string()).collect();
    let header = lines.next().unwrap().to_string();
    let mut rows = Vec::new();
    let mut times = Vec::new();
    for l in lines {
        let fields: Vec<&str> = l.split(',').collect();
        times.push(fields[0].to_string());
        rows.push(fields.iter().map(|f| f.parse::<f64>().unwrap()).collect());
    }
    (comments, header, rows, times)
}

fn column_peak(rows: &[Vec<f64>], col: usize, from: usize, to: usize) -> f64 {
    let to = to.min(rows.len());
    let mean = rows[from..to].iter().map(|r| r[col]).sum::<f64>() / (to - from) as f64;
    rows[from..to].iter().fold(0.0_f64, |m, r| m.max((r[col] - mean).abs()))
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
    let mut expected_top: Vec<String> = ids.iter().map(|s| s.to_string()).collect();
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

    for t in &m.tests {
        let tdir = dir.join(&t.id);
        assert_eq!(listing(&tdir), [DAQ1_FILE, DAQ2_FILE]);
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

        let (c1, h1, rows1, times1) = read_csv(&tdir.join(DAQ1_FILE));
        assert_eq!(
            c1[0],
            "# NEES-2009-0722 UCSD BNCS - SYNTHETIC demo archive written by shakeflow demo-archive (not real data)"
        );
        assert!(c1[1].starts_with(&format!("# test: {}, input: {}, event: ", t.id, t.input)));
        assert!(c1[1].ends_with(&format!("base: {}", t.base)));
        assert_eq!(c1[2], "# daq: DAQ1 floor accelerometers (floor averages), sample_rate_hz: 200, units: g");
        assert!(c1[3].starts_with("# "));
        assert_eq!(h1, DAQ1_COLUMNS.join(","));
        assert_eq!(h1, "Time,A4_EW,A4_NS,A4_UD,A5_EW,A5_NS,A5_UD");
        assert_eq!(rows1.len(), (t.duration_s * 200.0) as usize);
        assert_eq!(rows1.len(), t.daq1_rows);
        assert!(rows1.iter().all(|r| r.len() == 7));
        assert_eq!(times1[0], "0.000000");
        assert_eq!(times1[1], "0.005000");

        let (c2, h2, rows2, times2) = read_csv(&tdir.join(DAQ2_FILE));
        assert_eq!(c2[0], c1[0]);
        assert_eq!(c2[1], c1[1]);
        assert_eq!(c2[2], "# daq: DAQ2 equipment top accelerometers (E-W), sample_rate_hz: 256, units: g");
        assert!(c2[3].starts_with("# ") && c2[3].contains("NOT synchronised"));
        assert_eq!(h2, DAQ2_COLUMNS.join(","));
        assert_eq!(h2, "Time,A5_EW_SYNC,UI3_TOP_EW,MC2_TOP_EW,PB1_TOP_EW,PB2_TOP_EW,PS1_TOP_EW,PS2_TOP_EW,WSU1_TOP_EW");
        assert_eq!(rows2.len(), (t.duration_s * 256.0) as usize);
        assert_eq!(rows2.len(), t.daq2_rows);
        assert!(rows2.iter().all(|r| r.len() == DAQ2_COLUMNS.len()));
        assert_eq!(times2[0], "0.000000");
        assert_eq!(times2[1], "0.003906");

        // Physical plausibility (floor 4 channels, strong part of the record).
        let n = rows1.len();
        let ew = column_peak(&rows1, 1, 0, n);
        let ns = column_peak(&rows1, 2, 0, n);
        let ud = column_peak(&rows1, 3, 0, n);
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
            let col = DAQ2_COLUMNS.iter().position(|c| *c == tp.channel).unwrap();
            let k = ((tp.time_s - t.clock_offset_s) * 256.0).round() as usize;
            let spike = column_peak(&rows2, col, k.saturating_sub(256), k + 26);
            let before = column_peak(&rows2, col, k.saturating_sub(1280), k.saturating_sub(10));
            let after = column_peak(&rows2, col, k + 40, k + 40 + 1280);
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
