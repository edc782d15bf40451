//! The demo study end to end: `pipelines/demo.yaml` over a freshly generated demo archive,
//! checked against the archive's concealed truth (manifest.json) and the study's Table 3.
//! Tolerances are the floors: lag 1 ms, frequency 0.05 Hz here (Welch bin 0.012 Hz,
//! 7 segments), toppling 0.05 s, and no toppling anywhere else.
//!
//! The camera projection technique recovers, from the archive's rendered video, the rocking angle
//! θ(t) (amplitude 120 mrad) within 2 mrad RMS and the cart's midpoint trajectory (range 260 mm)
//! within 1.5 mm RMS, yaw within 5 mrad RMS: the calibration from 14 points with 0.5 px noise
//! alone accounts for about 0.5 mrad and 0.5 mm, tracking at ~0.03 px for 0.2 mm.

use crate::common;

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
    let work = crate::tempdir::tempdir().unwrap();
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
    // The study report in a browser: every unit's section, every figure loaded (the report's own
    // 7, the rocking units' 36 and rolling units' 40 per motion, the fragility and the 7 cases).
    crate::report_html::assert_page_shows(
        &runs.join("report/index.html"),
        &["UI3", "MC2", "PB1", "PB2", "PS1", "PS2", "WSU1"],
        7 + 36 + 40 + 1 + 7,
    );
    let page = std::fs::read_to_string(runs.join("report/index.html")).unwrap();
    for case in ["MC2_FB-5", "PS1_FB-5"] {
        assert!(page.contains(&format!("reports/{case}.png")), "the report does not show the rolling case {case}");
    }
    check_diagnosis(&runs, &archive);
    let shown = common::shakeflow(&["show", "runs/demo/report/summary/data.parquet"], work.path());
    assert!(common::stdout(&shown).contains("FB-4"), "{}", common::stdout(&shown));
    rolling_results_exist_and_are_sane(&runs);

    check_camera_projection(&runs, &archive, &manifest);

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
        // A toppling on a channel the stage dropped would otherwise never be looked for.
        for (channel, _) in &expected {
            assert!(channels.contains(channel), "{id}: no row for {channel}, where the archive has a toppling");
        }
        assert_eq!(channels.len(), 7, "{id}: one row per unit channel");
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

/// Every demo case gets the verdict its truth names (cases/truth/, never read by the tool); where
/// the truth dates the onset (the rolling cases), the window starts within 0.5 s of it. The rolling cases
/// are the study's own stories: PS1 carrying the fallen WSU1 is diagnosed; MC2 losing its load
/// is not (MC2's casters stick and slip, and mass changes near the concealed one, found by the
/// fit, cut its misfit less than threefold), so for it the diagnosis may decline (`unexplained`)
/// but must not blame another physics.
fn check_diagnosis(runs: &Path, archive: &Path) {
    let table = read_table(&runs.join("diagnosis/diagnosis/data.parquet")).unwrap();
    let (cases, verdicts) = (str_column(&table, "case"), str_column(&table, "verdict"));
    let starts = opt_column(&table, "window_start_s");
    assert_eq!(cases, ["MC2_FB-5", "PB1_FB-3", "PS1_FB-5", "PS2_FB-2", "PS2_FB-3", "WSU1_FB-4", "WSU1_FB-5"]);
    for (i, case) in cases.iter().enumerate() {
        let truth: serde_yaml::Value = serde_yaml::from_str(
            &std::fs::read_to_string(
                archive.join(shakeflow::demo::cases::CASES_DIR).join(format!("truth/{case}.yaml")),
            )
            .unwrap(),
        )
        .unwrap();
        let expected = truth["expected_verdict"].as_str().unwrap();
        if *case == "MC2_FB-5" && verdicts[i] == "unexplained" {
            continue;
        }
        assert_eq!(verdicts[i], expected, "{case}");
        if let Some(onset) = truth["onset_s"].as_f64() {
            let start = starts[i].unwrap_or_else(|| panic!("{case}: no window"));
            assert!((start - onset).abs() <= 0.5, "{case}: window starts at {start} s, onset {onset} s");
        }
    }
}

fn rms(errors: &[f64]) -> f64 {
    (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt()
}

fn check_camera_projection(runs: &Path, archive: &Path, manifest: &Value) {
    // The start points in the pipeline are what a person clicks: the markers' centres to 0.1 px.
    let pipeline = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("pipelines/demo.yaml")).unwrap();
    let points_line = pipeline.lines().find(|l| l.trim_start().starts_with("points: \"M1=")).unwrap();
    for start in manifest["cpt"]["start_points"].as_array().unwrap() {
        let (name, u, v) = (start[0].as_str().unwrap(), start[1][0].as_f64().unwrap(), start[1][1].as_f64().unwrap());
        assert!(
            points_line.contains(&format!("{name}={u:.1},{v:.1}")),
            "demo.yaml's start of {name} is not ({u:.1}, {v:.1}): {points_line}"
        );
    }
    let tracks = read_table(&runs.join("cpt_track/tracks/data.parquet")).unwrap();
    assert_eq!(tracks.num_rows(), 4 * manifest["cpt"]["frames"].as_u64().unwrap() as usize);
    assert!(str_column(&tracks, "status").iter().all(|s| s == "ok"), "every marker is tracked in every frame");

    let truth = std::fs::read_to_string(archive.join("cpt/truth.csv")).unwrap();
    let rows: Vec<Vec<f64>> =
        truth.lines().skip(1).map(|l| l.split(',').map(|c| c.parse().unwrap()).collect()).collect();
    let column = |k: usize| rows.iter().map(|r| r[k]).collect::<Vec<f64>>();
    let (time, theta, x, y, yaw) = (column(0), column(1), column(2), column(3), column(4));

    let rocking = read_table(&runs.join("cpt_rocking/motion/data.parquet")).unwrap();
    let frame_times = rocking.f64_column("time_s").unwrap();
    assert_eq!(frame_times.len(), time.len(), "one θ per frame");
    assert!(
        frame_times.iter().zip(&time).all(|(a, b)| (a - b).abs() < 1e-6),
        "θ at the frame times (truth.csv: 6 decimals)"
    );
    let theta_error: Vec<f64> =
        rocking.f64_column("theta_rad").unwrap().iter().zip(&theta).map(|(m, t)| m - t).collect();
    let (theta_rms, theta_max) = (rms(&theta_error), theta_error.iter().fold(0.0_f64, |a, e| a.max(e.abs())));
    println!("CPT rocking: θ RMS error {:.3} mrad, max {:.3} mrad", 1e3 * theta_rms, 1e3 * theta_max);
    assert!(theta_rms < 2e-3 && theta_max < 5e-3, "θ(t) error RMS {theta_rms} rad, max {theta_max} rad");

    let rolling = read_table(&runs.join("cpt_rolling/motion/data.parquet")).unwrap();
    let error = |name: &str, truth: &[f64]| -> f64 {
        let measured = rolling.f64_column(name).unwrap();
        rms(&measured.iter().zip(truth).map(|(m, t)| m - (t - truth[0])).collect::<Vec<_>>())
    };
    let (dx, dy, dyaw) = (error("dx_mm", &x), error("dy_mm", &y), error("yaw_rad", &yaw));
    println!("CPT rolling: midpoint RMS error x {dx:.3} mm, y {dy:.3} mm, yaw {:.3} mrad", 1e3 * dyaw);
    assert!(dx < 1.5 && dy < 1.5 && dyaw < 5e-3, "trajectory errors {dx} mm, {dy} mm, yaw {dyaw} rad");

    // The pipeline's own comparison says the same (it interpolates truth.csv's 6-decimal times
    // onto the frame times: 0.1 % agreement).
    let check = read_table(&runs.join("cpt_check_rocking/errors/data.parquet")).unwrap();
    assert!((check.f64_column("rms_error").unwrap()[0] - theta_rms).abs() < 1e-3 * theta_rms);
    let check = read_table(&runs.join("cpt_check_rolling/errors/data.parquet")).unwrap();
    let reported = check.f64_column("rms_error").unwrap();
    assert_eq!(reported.len(), 3, "one row each for dx, dy and yaw");
    for (r, mine) in reported.iter().zip([dx, dy, dyaw]) {
        assert!((r - mine).abs() < 1e-3 * mine, "compare stage {r} vs {mine}");
    }
    for figure in [
        "cpt_calibrate/figures/calibration.png",
        "cpt_track/figures/tracks.png",
        "cpt_rocking/figures/motion.png",
        "cpt_check_rocking/figures/compare.png",
    ] {
        let png = std::fs::read(runs.join(figure)).unwrap();
        assert!(png.starts_with(b"\x89PNG") && png.len() > 10_000, "{figure} is not a drawn PNG");
    }
}

/// The four rolling units over the ten motions the study's model is valid for: the report's
/// rolling table, and per simulation a trajectory on the input time base (Parquet), its
/// events and a figure. Sane: every unit rolls (a few cm to a few m) and stays with the floor
/// until it breaks away (creep below 1 mm).
fn rolling_results_exist_and_are_sane(runs: &Path) {
    let motions = ["BI-1", "BI-2", "BI-3", "BI-4", "BI-5", "BI-6", "FB-1", "FB-2", "FB-3", "FB-4"];
    let rolling = read_table(&runs.join("report/rolling/data.parquet")).unwrap();
    let units = str_column(&rolling, "unit");
    assert_eq!(units.len(), 40);
    let peaks = rolling.f64_column("peak_displacement_m").unwrap();
    let yaws = rolling.f64_column("peak_yaw_rad").unwrap();
    let starts = opt_column(&rolling, "breakaway_time_s");
    for (i, (unit, motion)) in units.iter().zip(str_column(&rolling, "motion")).enumerate() {
        assert_eq!((unit.as_str(), motion.as_str()), (["PS1", "PB2", "MC2", "UI3"][i / 10], motions[i % 10]));
        assert!(peaks[i] > 0.01 && peaks[i] < 10.0, "{unit} {motion}: peak displacement {} m", peaks[i]);
        assert!(yaws[i].is_finite() && yaws[i] < std::f64::consts::PI, "{unit} {motion}: peak yaw {} rad", yaws[i]);
        let start = starts[i].unwrap_or_else(|| panic!("{unit} {motion} never broke away"));
        let dir = runs.join(format!("rolling_{unit}"));
        let trajectory = read_table(&dir.join(format!("trajectory/motion={motion}/data.parquet"))).unwrap();
        let floor = read_table(&runs.join(format!("synchronize/records/motion={motion}/data.parquet"))).unwrap();
        let time = trajectory.f64_column("time_s").unwrap();
        assert_eq!(time, floor.f64_column("time_s").unwrap(), "{unit} {motion}: the input's time base");
        for column in ["x_m", "y_m", "yaw_rad", "delta1_rad", "delta2_rad", "delta3_rad", "delta4_rad"] {
            assert!(trajectory.f64_column(column).unwrap().iter().all(|v| v.is_finite()), "{unit} {motion}: {column}");
        }
        let (x, y) = (trajectory.f64_column("x_m").unwrap(), trajectory.f64_column("y_m").unwrap());
        for k in (0..time.len()).filter(|&k| time[k] < start) {
            assert!(x[k].hypot(y[k]) < 1e-3, "{unit} {motion}: moved {} m before breaking away", x[k].hypot(y[k]));
        }
        // MCAP twins are opt-in (`mcap: true`); the demo writes none.
        assert!(!dir.join("mcap").exists());
        assert!(dir.join(format!("events/motion={motion}/data.parquet")).is_file());
        let png = std::fs::read(dir.join(format!("figures/motion={motion}.png"))).unwrap();
        assert!(png.starts_with(b"\x89PNG\r\n\x1a\n") && png.len() > 10_000);
    }
}
