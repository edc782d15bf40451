//! `cpt_calibrate`: a camera's projection matrix from ≥ 8 control points (the study's camera
//! calibration): normalised DLT, then Levenberg–Marquardt on the reprojection error, optionally
//! with radial distortion. Reports the study's objective (Eq. 2) and the RMS distance, and flags
//! control points whose residual stands out.

use rayon::prelude::*;
use serde_json::json;

use super::{partition_path, Stage, StageContext};
use crate::error::UserError;
use crate::io::control_points::read_control_points;
use crate::pipeline::params;
use crate::pipeline::spec::RecordFormat;
use crate::plot::{render_png, Panel, Series};
use crate::table::{Column, ColumnData, Table};
use crate::vision::calibrate::{calibrate, expected_rms_px, Calibration, CalibrationError, Distortion, Model};

crate::stage_params! {
    /// The parameters of `cpt_calibrate`.
    pub struct CptCalibrateParams {
        /// radial lens distortion to fit (none: the study's pinhole P)
        pub distortion: DistortionChoice [default = "none"],
        /// zero: no skew (OpenCV's model; one parameter fewer, noticeably more accurate with few points); free: the
        /// study's 11-parameter P
        pub skew: Skew [default = "zero"],
        /// flag points whose leave-one-out prediction error exceeds this many robust noise sigmas (and 0.5 px)
        pub outlier_sigma: f64 [default = 3.5, range = (1.0, 100.0)],
    }
}

crate::choice! {
    /// `distortion`: the radial terms fitted.
    pub enum DistortionChoice { None = "none", K1 = "k1", K1k2 = "k1k2" }
}

crate::choice! {
    /// `skew`: the study's free skew, or none.
    pub enum Skew { Free = "free", Zero = "zero" }
}

super::declare_stage! {
    /// Camera calibration from control points (X_mm, Y_mm, Z_mm, u_px, v_px; ≥ 8, not coplanar): normalised DLT,
    /// Levenberg–Marquardt on the reprojection error, optional radial distortion k1 (k2).
    pub struct CptCalibrate: "cpt_calibrate", version 2,
        reads Files(&[RecordFormat::ControlPoints]), params CptCalibrateParams;
    outputs {
        /// one row: p11…p34 (P scaled so ‖p31..p33‖ = 1), k1/k2 when fitted, intrinsics, camera centre, objective_px
        /// (Eq. 2), rms_px
        "calibration": Table,
        /// per control point: u_res_px, v_res_px, dist_px, loo_dist_px (its distance when fitted without it), outlier
        "residuals": Table,
        /// calibration.png: control points with magnified residuals, and residual per point
        "figures": Files,
    }
    examples {
        /// the demo camera from its 14 control points, with radial distortion k1
        super::DEMO_CAMERA => "\
cpt_calibrate:
  type: cpt_calibrate
  inputs: [control_points]
  params:
    distortion: k1
",
    }
}

impl Stage for CptCalibrate {
    super::info_and_check_params!(CptCalibrateParams);

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let p: CptCalibrateParams = params::typed(ctx.params)?;
        let distortion = match p.distortion {
            DistortionChoice::None => Distortion::None,
            DistortionChoice::K1 => Distortion::K1,
            DistortionChoice::K1k2 => Distortion::K1K2,
        };
        let model = Model { distortion, zero_skew: p.skew == Skew::Zero };
        let outlier_sigma = p.outlier_sigma;
        let parts: Vec<_> = ctx.inputs.iter().flat_map(|i| i.parts()).collect();
        ctx.sink.set_total(parts.len());
        parts.par_iter().try_for_each(|part| {
            let points = read_control_points(&part.path, &part.hash)?;
            let controls: Vec<_> = points.iter().map(|p| p.point).collect();
            let result = calibrate(&controls, model, outlier_sigma).map_err(|e| {
                let hint = match e {
                    CalibrationError::TooFewPoints(_) => {
                        "add control points: at least 8, spread over the image and over depth"
                    }
                    CalibrationError::Coplanar { .. } => {
                        "add control points off that plane (e.g. on a wall or a post when the others are on the floor)"
                    }
                    CalibrationError::Degenerate(_) => {
                        "check for repeated points and for world coordinates typed into the wrong column"
                    }
                    CalibrationError::BehindCamera(_) => {
                        "check that point's coordinates (X, Y, Z order, units in mm) and its pixel"
                    }
                };
                let line = match e {
                    CalibrationError::BehindCamera(i) => Some((points[i].line, 1)),
                    _ => None,
                };
                UserError::new(e.to_string()).in_file(&part.path).at(line).hint(hint)
            })?;
            for warning in &result.warnings {
                ctx.sink.warn(&format!("{}: {warning}", part.label));
            }
            let names: Vec<String> = points.iter().map(|p| p.name.clone()).collect();
            let mut calibration = calibration_table(&result);
            let mut residuals = residual_table(&result, &names, &controls);
            let facts = json!({
                "points": controls.len(),
                "parameters": result.parameters,
                "objective_px": result.mean_distance_px,
                "rms_px": result.rms_px,
                "dlt_objective_px": result.dlt_mean_distance_px,
                "iterations": result.iterations,
                "outlier_threshold_px": result.outlier_threshold_px,
                "thickness_ratio": result.thickness_ratio,
                "noise_sigma_px_implied": result.rms_px / expected_rms_px(1.0, controls.len(), result.parameters),
                "warnings": result.warnings,
            })
            .to_string();
            for table in [&mut calibration, &mut residuals] {
                table.metadata.insert("shakeflow.cpt_calibrate".into(), facts.clone());
                table.metadata.extend(super::record_provenance(part));
            }
            let name = match partition_path(&part.partition) {
                p if p.is_empty() => "calibration.png".to_string(),
                p => format!("calibration-{}.png", p.replace(['/', '='], "_")),
            };
            ctx.sink.write_file("figures", &name, &figure(&result, &controls, &part.label)?)?;
            ctx.sink.write("residuals", &part.partition, residuals)?;
            ctx.sink.write("calibration", &part.partition, calibration)
        })
    }
}

fn calibration_table(result: &Calibration) -> Table {
    let camera = &result.camera;
    let p = camera.projection();
    let mut table = Table::new();
    for (r, row) in p.iter().enumerate() {
        for (c, &value) in row.iter().enumerate() {
            // u·depth = p1·(X, Y, Z) + p14 with depth in mm: rows 1-2 are px (px·mm for the last),
            // row 3 is dimensionless (mm for p34, the depth offset).
            let unit = match (r, c) {
                (2, 3) => "mm",
                (2, _) => "",
                (_, 3) => "px*mm",
                _ => "px",
            };
            let name = format!("p{}{}", r + 1, c + 1);
            let description = format!(
                "projection matrix element ({}, {}) of Eq. 1, P scaled so that ‖(p31, p32, p33)‖ = 1",
                r + 1,
                c + 1
            );
            table.push(Column::f64(&name, unit, &description, vec![value]));
        }
    }
    if result.model.distortion != Distortion::None {
        table.push(Column::f64(
            "k1",
            "",
            "radial distortion coefficient k1 (OpenCV's model, normalised coordinates)",
            vec![camera.k1],
        ));
    }
    if result.model.distortion == Distortion::K1K2 {
        table.push(Column::f64(
            "k2",
            "",
            "radial distortion coefficient k2 (OpenCV's model, normalised coordinates)",
            vec![camera.k2],
        ));
    }
    let k = &camera.intrinsics;
    let centre = camera.centre();
    for (name, unit, description, value) in [
        ("fx_px", "px", "focal length along u (from P = K[R|t])", k.fx),
        ("fy_px", "px", "focal length along v (from P = K[R|t])", k.fy),
        ("skew_px", "px", "skew of K (from P)", k.skew),
        ("cx_px", "px", "principal point u (from P)", k.cx),
        ("cy_px", "px", "principal point v (from P)", k.cy),
        ("camera_X_mm", "mm", "camera centre X (world)", centre[0]),
        ("camera_Y_mm", "mm", "camera centre Y (world)", centre[1]),
        ("camera_Z_mm", "mm", "camera centre Z (world)", centre[2]),
        ("objective_px", "px", "the study's objective (Eq. 2): mean reprojection distance", result.mean_distance_px),
        ("rms_px", "px", "RMS reprojection distance", result.rms_px),
    ] {
        table.push(Column::f64(name, unit, description, vec![value]));
    }
    table.push(Column {
        name: "points".into(),
        unit: String::new(),
        description: "control points used".into(),
        data: ColumnData::I64(vec![result.residuals.len() as i64]),
    });
    table
}

fn residual_table(result: &Calibration, names: &[String], points: &[crate::vision::calibrate::ControlPoint]) -> Table {
    let column = |f: &dyn Fn(usize) -> f64| (0..points.len()).map(f).collect::<Vec<f64>>();
    let mut table = Table::new();
    table.push(Column {
        name: "point".into(),
        unit: String::new(),
        description: "control point".into(),
        data: ColumnData::Str(names.to_vec()),
    });
    table.push(Column::f64("X_mm", "mm", "world X", column(&|i| points[i].world[0])));
    table.push(Column::f64("Y_mm", "mm", "world Y", column(&|i| points[i].world[1])));
    table.push(Column::f64("Z_mm", "mm", "world Z", column(&|i| points[i].world[2])));
    table.push(Column::f64("u_px", "px", "measured pixel u", column(&|i| points[i].pixel[0])));
    table.push(Column::f64("v_px", "px", "measured pixel v", column(&|i| points[i].pixel[1])));
    table.push(Column::f64("u_res_px", "px", "measured minus reprojected u", column(&|i| result.residuals[i][0])));
    table.push(Column::f64("v_res_px", "px", "measured minus reprojected v", column(&|i| result.residuals[i][1])));
    table.push(Column::f64(
        "dist_px",
        "px",
        "reprojection distance (its mean is Eq. 2)",
        column(&|i| result.residuals[i][0].hypot(result.residuals[i][1])),
    ));
    table.push(Column::f64(
        "loo_dist_px",
        "px",
        "leave-one-out distance: from the point's pixel to its prediction by the camera fitted without it",
        result.leave_one_out_px.clone(),
    ));
    table.push(Column {
        name: "outlier".into(),
        unit: String::new(),
        description: format!(
            "loo_dist_px above {:.3} px (outlier_sigma × the robust noise scale of the leave-one-out distances, at least 0.5 px)",
            result.outlier_threshold_px
        ),
        data: ColumnData::Bool(result.outliers.clone()),
    });
    table
}

/// Residual vectors drawn ×50 from each measured point, and the distance per point.
fn figure(
    result: &Calibration,
    points: &[crate::vision::calibrate::ControlPoint],
    label: &str,
) -> anyhow::Result<Vec<u8>> {
    const MAGNIFY: f64 = 50.0;
    let (mut mu, mut mv, mut ru, mut rv) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (p, r) in points.iter().zip(&result.residuals) {
        mu.extend([p.pixel[0], f64::NAN]);
        mv.extend([-p.pixel[1], f64::NAN]);
        ru.extend([p.pixel[0], p.pixel[0] - MAGNIFY * r[0], f64::NAN]);
        rv.extend([-p.pixel[1], -(p.pixel[1] - MAGNIFY * r[1]), f64::NAN]);
    }
    let index: Vec<f64> = (1..=points.len()).map(|i| i as f64).collect();
    let distance: Vec<f64> = result.residuals.iter().map(|r| r[0].hypot(r[1])).collect();
    let threshold = vec![result.outlier_threshold_px; points.len()];
    let panels = [
        Panel {
            title: format!("control points (reprojection residuals ×{MAGNIFY})"),
            x_label: "u [px]".into(),
            y_label: "−v [px]".into(),
            series: vec![
                Series::new("measured", &mu, &mv),
                Series::new(format!("reprojected − measured, ×{MAGNIFY}"), &ru, &rv),
            ],
            markers: vec![],
            log_y: false,
            spans: Vec::new(),
        },
        Panel {
            title: format!("Eq. 2 objective {:.3} px, RMS {:.3} px", result.mean_distance_px, result.rms_px),
            x_label: "control point".into(),
            y_label: "distance [px]".into(),
            series: vec![
                Series::new("dist_px", &index, &distance),
                Series::new("loo_dist_px (fitted without the point)", &index, &result.leave_one_out_px),
                Series::new("outlier threshold (on loo_dist_px)", &index, &threshold),
            ],
            markers: vec![],
            log_y: false,
            spans: Vec::new(),
        },
    ];
    render_png(&format!("camera calibration: {label}"), &panels, 1100, 1000).map_err(anyhow::Error::msg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::calibrate::ControlPoint;

    /// Points of a 3 × 3 × 2 grid (mm) seen by a pinhole camera at (200, −100, −5000) mm looking
    /// along +Z: u = fx X'/Z' + cx, v = fy Y'/Z' + cy in its own frame, with no distortion.
    fn seen(fx: f64, fy: f64, cx: f64, cy: f64, centre: [f64; 3]) -> Vec<ControlPoint> {
        let mut points = vec![];
        for x in [-1000.0, 0.0, 1000.0] {
            for y in [-600.0, 0.0, 600.0] {
                for z in [0.0, 1200.0] {
                    let (dx, dy, dz) = (x - centre[0], y - centre[1], z - centre[2]);
                    points.push(ControlPoint { world: [x, y, z], pixel: [fx * dx / dz + cx, fy * dy / dz + cy] });
                }
            }
        }
        points
    }

    #[test]
    fn a_pinhole_camera_is_recovered_from_its_exact_projections() {
        let (fx, fy, cx, cy, centre) = (1100.0, 1050.0, 480.0, 270.0, [200.0, -100.0, -5000.0]);
        let points = seen(fx, fy, cx, cy, centre);
        let model = Model { distortion: Distortion::None, zero_skew: true };
        let table = calibration_table(&calibrate(&points, model, 3.5).unwrap());
        let value = |name: &str| table.f64_column(name).unwrap()[0];
        for (name, exact) in [
            ("fx_px", fx),
            ("fy_px", fy),
            ("cx_px", cx),
            ("cy_px", cy),
            ("camera_X_mm", centre[0]),
            ("camera_Y_mm", centre[1]),
            ("camera_Z_mm", centre[2]),
        ] {
            assert!(
                (value(name) - exact).abs() < 1e-6 * exact.abs().max(1.0),
                "{name}: {} against {exact}",
                value(name)
            );
        }
        assert!(value("skew_px").abs() < 1e-9);
        assert!(value("rms_px") < 1e-6, "rms {} px", value("rms_px"));
        assert!(matches!(&table.column("points").unwrap().data, ColumnData::I64(n) if n == &[18]));
    }
}
