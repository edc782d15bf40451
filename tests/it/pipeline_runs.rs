//! The engine as a user meets it: run, cache, status, force, determinism, single-stage runs.

use crate::common;
use common::*;

#[test]
fn second_run_is_fully_cached_and_says_so() {
    let project = small_project_with_twins();
    let first = shakeflow(&["run", "pipeline.yaml"], project.path());
    assert!(first.status.success(), "{}", stderr(&first));
    assert!(stderr(&first).contains("load               running (never run"), "{}", stderr(&first));
    assert!(project.path().join("out/shakeflow.lock").is_file());
    let part = project.path().join("out/baseline/records/motion=FB-1/data.parquet");
    assert!(part.is_file() && project.path().join("out/baseline/mcap/records/motion=FB-1/data.mcap").is_file());

    let second = shakeflow(&["run", "pipeline.yaml"], project.path());
    let log = stderr(&second);
    assert!(second.status.success(), "{log}");
    assert!(log.contains("load               cached") && log.contains("baseline           cached"), "{log}");
    assert!(log.contains("2 stage(s): 0 ran, 2 cached"), "{log}");
}

#[test]
fn time_series_get_an_mcap_twin_only_when_asked() {
    let project = small_project();
    let out = shakeflow(&["run", "pipeline.yaml"], project.path());
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(project.path().join("out/baseline/records/motion=FB-1/data.parquet").is_file());
    assert!(!project.path().join("out/baseline/mcap").exists(), "a twin nobody asked for");
    std::fs::write(project.path().join("pipeline.yaml"), pipeline_with_twins()).unwrap();
    let out = shakeflow(&["run", "pipeline.yaml"], project.path());
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(project.path().join("out/baseline/mcap/records/motion=FB-1/data.mcap").is_file());
    // Turned off again (as an output folder from before twins were opt-in meets the new
    // default): the stage reruns and its twins go.
    std::fs::write(project.path().join("pipeline.yaml"), PIPELINE).unwrap();
    let status = stdout(&shakeflow(&["status", "pipeline.yaml"], project.path()));
    assert!(status.contains("params changed: mcap true → false"), "{status}");
    assert!(shakeflow(&["run", "pipeline.yaml"], project.path()).status.success());
    assert!(!project.path().join("out/baseline/mcap").exists(), "twins left behind");
    assert!(project.path().join("out/baseline/records/motion=FB-1/data.parquet").is_file());
}

#[test]
fn changed_parameter_reruns_only_what_depends_on_it() {
    let project = small_project();
    assert!(shakeflow(&["run", "pipeline.yaml"], project.path()).status.success());
    let path = project.path().join("pipeline.yaml");
    std::fs::write(&path, PIPELINE.replace("order: 3", "order: 2")).unwrap();

    let status = shakeflow(&["status", "pipeline.yaml"], project.path());
    let text = stdout(&status);
    assert!(text.contains("load               up to date"), "{text}");
    assert!(text.contains("baseline           stale: params changed: order 3 → 2"), "{text}");

    let rerun = shakeflow(&["run", "pipeline.yaml"], project.path());
    let log = stderr(&rerun);
    assert!(
        log.contains("load               cached") && log.contains("baseline           running (params changed"),
        "{log}"
    );
}

#[test]
fn changed_input_file_is_reported_and_recomputed() {
    let project = small_project();
    assert!(shakeflow(&["run", "pipeline.yaml"], project.path()).status.success());
    write_daq_csv(&project.path().join("archive/FB-2/daq.csv"), 400, 200.0, 2.0);
    let text = stdout(&shakeflow(&["status", "pipeline.yaml"], project.path()));
    assert!(
        text.contains(
            "load               stale: 1 of 2 records: record motion=FB-2: input `archive/FB-2/daq.csv` changed"
        ),
        "{text}"
    );
    assert!(
        text.contains("baseline           stale: 1 of 2 records: record motion=FB-2: an upstream unit will rerun"),
        "{text}"
    );
}

#[test]
fn tampered_output_is_detected() {
    let project = small_project();
    assert!(shakeflow(&["run", "pipeline.yaml"], project.path()).status.success());
    let part = project.path().join("out/load/records/motion=FB-1/data.parquet");
    let bytes = std::fs::read(&part).unwrap();
    std::fs::write(&part, &bytes[..bytes.len() - 1]).unwrap();
    let text = stdout(&shakeflow(&["status", "pipeline.yaml"], project.path()));
    assert!(
        text.contains("stale: 1 of 2 records: record motion=FB-1: output file `records/motion=FB-1/data.parquet` was modified on disk"),
        "{text}"
    );
    std::fs::remove_file(&part).unwrap();
    let text = stdout(&shakeflow(&["status", "pipeline.yaml"], project.path()));
    assert!(text.contains("output file `records/motion=FB-1/data.parquet` missing"), "{text}");
}

#[test]
fn force_reruns_the_stage_and_its_dependents() {
    let project = small_project();
    assert!(shakeflow(&["run", "pipeline.yaml"], project.path()).status.success());
    let out = shakeflow(&["run", "pipeline.yaml", "--force", "load"], project.path());
    let log = stderr(&out);
    assert!(
        log.contains("load               running (forced)") && log.contains("baseline           running (forced)"),
        "{log}"
    );
    let unknown = shakeflow(&["run", "pipeline.yaml", "--force", "lod"], project.path());
    assert!(!unknown.status.success());
    assert!(stderr(&unknown).contains("`--force lod`: no stage of that name"), "{}", stderr(&unknown));
}

#[test]
fn same_inputs_give_bit_identical_artifacts() {
    // With twins: their lz4 chunks are bit-identical too.
    let a = small_project_with_twins();
    let b = small_project_with_twins();
    assert!(shakeflow(&["run", "pipeline.yaml", "--jobs", "1"], a.path()).status.success());
    assert!(shakeflow(&["run", "pipeline.yaml", "--jobs", "2"], b.path()).status.success());
    let strip = |dir: &std::path::Path| -> Vec<(String, Vec<u8>)> {
        snapshot(&dir.join("out"))
            .into_iter()
            .map(|(p, bytes)| (p.strip_prefix(dir).unwrap().display().to_string(), bytes))
            .collect()
    };
    assert_eq!(strip(a.path()), strip(b.path()), "two projects, same inputs: every artifact byte-identical");
    // A forced rerun into the same folder reproduces every byte too.
    let before = snapshot(&a.path().join("out"));
    assert!(shakeflow(&["run", "pipeline.yaml", "--force", "load"], a.path()).status.success());
    assert_eq!(before, snapshot(&a.path().join("out")), "a forced rerun must reproduce every byte");
}

#[test]
fn single_stage_runs_on_files_without_a_pipeline() {
    let dir = crate::tempdir::tempdir().unwrap();
    let record = ground_motion("RSN6_IMPVALL.I_I-ELC180.AT2");
    let out = shakeflow(&["stage", "load", "--input", record.to_str().unwrap(), "--output", "loaded"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let out = shakeflow(
        &["stage", "baseline", "--input", "loaded/records", "--output", "corrected", "--set", "order=1"],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&shakeflow(&["inspect", "corrected/records/data.parquet"], dir.path()));
    assert!(text.contains("5372 rows"), "{text}");
    assert!(text.contains("m/s^2") && text.contains("order-1 polynomial baseline removed"), "{text}");
    assert!(text.contains("\"order\": 1"), "{text}");
    let bad =
        shakeflow(&["stage", "baseline", "--input", "loaded/records", "--output", "x", "--set", "ordr=1"], dir.path());
    assert!(!bad.status.success());
    assert!(stderr(&bad).contains("did you mean `order`"), "{}", stderr(&bad));
    assert!(!dir.path().join("x").exists());
}

#[test]
fn stages_lists_parameters_with_defaults() {
    let text = stdout(&shakeflow(&["stages"], std::path::Path::new(".")));
    assert!(text.contains("baseline (version 5)") && text.contains("- order: integer (default 3)"), "{text}");
}

#[test]
fn inspect_describes_mcap_files_and_datasets() {
    let project = small_project_with_twins();
    assert!(shakeflow(&["run", "pipeline.yaml"], project.path()).status.success());
    let mcap = stdout(&shakeflow(&["inspect", "out/baseline/mcap/records/motion=FB-2/data.mcap"], project.path()));
    assert!(mcap.contains("MCAP, 400 messages from 0.000 s to 1.995 s"), "{mcap}");
    assert!(mcap.contains("/baseline/records/motion=FB-2"), "{mcap}");
    let dataset = stdout(&shakeflow(&["inspect", "out/load/records"], project.path()));
    assert!(dataset.contains("dataset of 2 Parquet part(s)") && dataset.contains("total rows: 800"), "{dataset}");
    let missing = shakeflow(&["inspect", "out/nothing.parquet"], project.path());
    assert!(
        !missing.status.success() && stderr(&missing).contains("cannot open `out/nothing.parquet`"),
        "{}",
        stderr(&missing)
    );
}

#[test]
fn signal_stages_run_alone_on_files() {
    // synchronize two copies of one record, the second 0.25 s late: the lag comes back.
    let dir = crate::tempdir::tempdir().unwrap();
    let root = dir.path();
    let mut reference = String::from("t,a\n");
    let mut target = String::from("t,a\n");
    let signal = |t: f64| {
        (2.0 * std::f64::consts::PI * 1.3 * t).sin() * (-((t - 10.0) / 4.0).powi(2)).exp()
            + 0.3 * (7.1 * t).sin() * (-((t - 9.0) / 3.0).powi(2)).exp()
    };
    for i in 0..4000 {
        let t = i as f64 / 200.0;
        reference.push_str(&format!("{t:.6},{:.9}\n", signal(t)));
        target.push_str(&format!("{t:.6},{:.9}\n", signal(t - 0.25)));
    }
    std::fs::write(root.join("ref.csv"), reference).unwrap();
    std::fs::write(root.join("tgt.csv"), target).unwrap();
    for (file, out) in [("ref.csv", "r"), ("tgt.csv", "t")] {
        let loaded =
            shakeflow(&["stage", "load", "-i", file, "-o", out, "--set", "time_column=t", "--set", "unit=m/s^2"], root);
        assert!(loaded.status.success(), "{}", stderr(&loaded));
    }
    // Both records lack a `motion` key; join on none by giving them one through a folder layout.
    for (from, to) in [("r/records/data.parquet", "ref/motion=X"), ("t/records/data.parquet", "tgt/motion=X")] {
        std::fs::create_dir_all(root.join(to)).unwrap();
        std::fs::copy(root.join(from), root.join(to).join("data.parquet")).unwrap();
    }
    let synchronize = |output: &str, target_channel: &str| {
        let target = format!("target_channel={target_channel}");
        let args = ["stage", "synchronize", "-i", "ref", "-i", "tgt", "-o", output];
        shakeflow(&[&args[..], &["--set", "reference_channel=a", "--set", &target]].concat(), root)
    };
    let synced = synchronize("s", "a");
    assert!(synced.status.success(), "{}", stderr(&synced));
    let lags = shakeflow::io::parquet::read_table(&root.join("s/lags/motion=X/data.parquet")).unwrap();
    let lag = lags.f64_column("lag_s").unwrap()[0];
    assert!((lag - 0.25).abs() < 1e-3, "lag {lag}");
    // The time column is no channel to synchronise by: a clear refusal, nothing written.
    let refused = synchronize("s2", "time_s");
    assert!(
        !refused.status.success() && stderr(&refused).contains("no float channel `time_s`"),
        "{}",
        stderr(&refused)
    );
    assert!(!root.join("s2").exists());
}
