//! `cpt_project` takes a `cpt_calibrate` stage by its contract: given the whole stage (both its
//! `calibration` and its per-control-point `residuals`), it projects with the calibration and
//! leaves the residuals alone; given only the residuals, it says which output to pass.

use crate::common::{cpt_project, shakeflow, stderr};

fn project_with_inputs(inputs: &str) -> (crate::tempdir::TempDir, std::process::Output) {
    let project = cpt_project();
    let path = project.path().join("pipeline.yaml");
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("inputs: [track, calibrate.calibration]"), "the fixture names its inputs as expected");
    std::fs::write(&path, text.replace("inputs: [track, calibrate.calibration]", inputs)).unwrap();
    let out = shakeflow(&["run", "pipeline.yaml"], project.path());
    (project, out)
}

#[test]
fn a_whole_calibrate_stage_projects_like_its_calibration_output() {
    let (whole, out) = project_with_inputs("inputs: [track, calibrate]");
    assert!(out.status.success(), "{}", stderr(&out));
    let (single, out) = project_with_inputs("inputs: [track, calibrate.calibration]");
    assert!(out.status.success(), "{}", stderr(&out));
    let points = |dir: &std::path::Path| {
        let table = shakeflow::io::parquet::read_table(&dir.join("out/project/points/data.parquet")).unwrap();
        ["X_mm", "Y_mm", "Z_mm"].map(|c| table.f64_column(c).expect("a projected column").to_vec())
    };
    let (a, b) = (points(whole.path()), points(single.path()));
    assert!(!a[0].is_empty() && a[0].iter().all(|v| v.is_finite()), "{a:?}");
    assert_eq!(a, b, "the same points either way");
}

#[test]
fn residuals_alone_are_refused_with_the_output_to_pass() {
    let (project, out) = project_with_inputs("inputs: [track, calibrate.residuals]");
    assert!(!out.status.success());
    let message = stderr(&out);
    assert!(message.contains("needs tracks and a calibration"), "{message}");
    assert!(message.contains("<cpt_calibrate stage>.calibration"), "{message}");
    assert!(!project.path().join("out/project").exists());
}
