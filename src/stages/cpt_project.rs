//! `cpt_project`: tracked pixels → 3D points on a known plane (the study's Eq. 3 and 4), and for
//! two points on one unit its motion: translation and in-plane rotation (rolling units), or the
//! rocking angle θ (rocking units), ready for the diagnosis (`time_s`, `theta_rad`).

use std::sync::Arc;

use std::collections::BTreeMap;

use serde_json::json;

use super::{partition_path, InputPart, Stage, StageContext};
use crate::error::UserError;
use crate::pipeline::params;
use crate::plot::{render_png, Panel, Series};
use crate::table::{Column, ColumnData, Table};
use crate::vision::camera::Camera;
use crate::vision::linalg::Vec3;
use crate::vision::project::{backproject, pair_motion, Plane};

crate::stage_params! {
    /// The parameters of `cpt_project`.
    pub struct CptProjectParams {
        // `a,b,c,d`, read by `parse_plane`.
        /// the plane the points move in, `a,b,c,d` for aX + bY + cZ + d = 0 (Eq. 3, world mm); its normal (a, b, c)
        /// orients rotations (right-handed)
        pub plane: String [unit = "mm"],
        /// tracked points on this plane (default: all M… points); for unit_motion, the first two give the unit's
        /// segment
        pub points: Vec<String> [default = []],
        /// rolling: midpoint translation and yaw about the plane normal; rocking: θ about the plane normal (top
        /// toward +X positive for a +Y normal) and midpoint translation
        pub unit_motion: UnitMotion [default = "none"],
        /// rocking: θ from the first frame's pose, or from upright (the two points one above the other, the first
        /// lower)
        pub theta_zero: ThetaZero [default = "first_frame"],
        /// refuse pixels whose camera ray meets the plane at a smaller angle
        pub min_ray_angle_deg: f64 [default = 2.0, unit = "deg", range = (0.0, 90.0)],
        #[flatten]
        pub mcap: super::Mcap,
    }
}

crate::choice! {
    /// `unit_motion`: what the first two points' motion is made into.
    pub enum UnitMotion { None = "none", Rolling = "rolling", Rocking = "rocking" }
}

impl std::fmt::Display for UnitMotion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&params::choice_name(self))
    }
}

crate::choice! {
    /// `theta_zero`: where a rocking unit's θ is measured from.
    pub enum ThetaZero { FirstFrame = "first_frame", Upright = "upright" }
}

super::declare_stage! {
    /// Back-project tracked pixels onto a plane aX + bY + cZ + d = 0 (Eq. 4) with a cpt_calibrate camera; for two
    /// points on one unit, its translation and in-plane rotation (rolling) or rocking angle θ (rocking).
    pub struct CptProject: "cpt_project", version 2, reads Datasets, params CptProjectParams;
    outputs {
        /// per frame and point: time_s, point, X_mm, Y_mm, Z_mm (NaN when the track is lost)
        "points": TimeSeries,
        /// rolling: time_s, dx_mm, dy_mm, dz_mm, yaw_rad; rocking: time_s, theta_rad, dx_mm, dy_mm, dz_mm (empty when
        /// unit_motion is none)
        "motion": TimeSeries,
        /// motion.png: the unit's recovered motion
        "figures": Files,
    }
    examples {
        /// the stretcher panel's rocking angle θ(t) from two tracked markers on the plane Y = 0
        super::DEMO_CAMERA => "\
calibrate: {type: cpt_calibrate, inputs: [control_points], params: {distortion: k1}}
track: {type: cpt_track, inputs: [video], params: {fps: 30, points: \"M1=376.3,328.0; M2=380.2,248.8\"}}
cpt_project:
  type: cpt_project
  inputs: [track, calibrate.calibration]
  params:
    plane: \"0,1,0,0\"
    points: [M1, M2]
    unit_motion: rocking
    theta_zero: upright
",
    }
}

impl Stage for CptProject {
    super::info_and_check_params!(CptProjectParams);

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let p: CptProjectParams = params::typed(ctx.params)?;
        let plane = parse_plane(&p.plane)?;
        let (wanted, unit_motion) = (p.points, p.unit_motion);
        let upright = p.theta_zero == ThetaZero::Upright;
        if upright && unit_motion != UnitMotion::Rocking {
            return Err(UserError::new("`theta_zero: upright` applies to `unit_motion: rocking` only")
                .hint("a rolling unit's yaw is measured from its first frame")
                .into());
        }
        let min_angle = p.min_ray_angle_deg;
        let mut tracks: Vec<(&InputPart, Arc<Table>)> = Vec::new();
        let mut calibrations: Vec<(&InputPart, Arc<Table>)> = Vec::new();
        for part in ctx.inputs.iter().flat_map(|i| i.parts()) {
            let table = ctx.read_table(part)?;
            // A whole cpt_calibrate stage as input brings its `residuals` too (per control point:
            // point, u_px, …): take each table by the output its metadata names, then by columns.
            let made_by = |stage: &str, output: &str| {
                table.metadata.get("shakeflow.stage_type").is_some_and(|t| t == stage)
                    && table.metadata.get("shakeflow.output").is_some_and(|o| o == output)
            };
            let from_calibrate = table.metadata.get("shakeflow.stage_type").is_some_and(|t| t == "cpt_calibrate");
            if made_by("cpt_calibrate", "calibration") || (!from_calibrate && table.column("p11").is_some()) {
                calibrations.push((part, table));
            } else if from_calibrate {
                continue;
            } else if table.column("u_px").is_some()
                && table.column("point").is_some()
                && table.column("time_s").is_some()
            {
                tracks.push((part, table));
            } else {
                return Err(UserError::new(format!(
                    "`{}` is neither a cpt_track `tracks` table nor a cpt_calibrate `calibration` table",
                    part.label
                ))
                .hint("inputs: [<cpt_track stage>, <cpt_calibrate stage>.calibration]")
                .into());
            }
        }
        if tracks.is_empty() || calibrations.is_empty() {
            return Err(UserError::new("cpt_project needs tracks and a calibration")
                .hint("inputs: [<cpt_track stage>, <cpt_calibrate stage>.calibration]")
                .into());
        }
        ctx.sink.set_total(tracks.len());
        for (part, table) in &tracks {
            let calibration = match calibrations.iter().find(|(c, _)| c.partition == part.partition) {
                Some(c) => c,
                None if calibrations.len() == 1 => &calibrations[0],
                None => {
                    return Err(UserError::new(format!(
                        "no calibration shares the partition `{}` of `{}`",
                        partition_path(&part.partition),
                        part.label
                    ))
                    .hint("give one calibration, or one per camera with the same partition keys as the tracks")
                    .into())
                }
            };
            let camera = camera_of(&calibration.1).map_err(|e| anyhow::anyhow!("{}: {e}", calibration.0.label))?;
            let options = ProjectOptions { wanted: &wanted, unit_motion, upright, min_angle };
            let (mut points, motion, facts) = project(table, &camera, &plane, &options, &part.label)?;
            points.metadata.insert("shakeflow.cpt_project".into(), facts.to_string());
            points.metadata.extend(super::record_provenance(part));
            if let Some(mut motion) = motion {
                motion.metadata.insert("shakeflow.cpt_project".into(), facts.to_string());
                motion.metadata.extend(super::record_provenance(part));
                let name = match partition_path(&part.partition) {
                    p if p.is_empty() => "motion.png".to_string(),
                    p => format!("motion-{}.png", p.replace(['/', '='], "_")),
                };
                ctx.sink.write_file("figures", &name, &figure(&motion, unit_motion, &part.label)?)?;
                ctx.sink.write("motion", &part.partition, motion)?;
            }
            ctx.sink.write_series("points", &part.partition, points, "point")?;
        }
        Ok(())
    }
}

pub fn parse_plane(text: &str) -> Result<Plane, UserError> {
    let values: Vec<f64> =
        text.split(',').filter_map(|v| v.trim().parse::<f64>().ok()).filter(|v| v.is_finite()).collect();
    let bad = || {
        UserError::new(format!("parameter `plane`: cannot read `{text}` as a plane"))
            .hint("give `a,b,c,d` for aX + bY + cZ + d = 0 in world mm, e.g. `0,0,1,-900` for the horizontal plane Z = 900 mm")
    };
    if values.len() != 4 || text.split(',').count() != 4 {
        return Err(bad());
    }
    if values[..3].iter().all(|v| *v == 0.0) {
        return Err(bad());
    }
    Ok(Plane { a: values[0], b: values[1], c: values[2], d: values[3] })
}

/// Why a calibration table gives no camera.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
enum CameraError {
    /// An element `p<row><column>` of the projection matrix is missing.
    #[error("the calibration has no p{0}{1}")]
    Missing(usize, usize),
    #[error("the calibration's P has a singular 3×3 block")]
    Singular,
}

fn camera_of(table: &Table) -> Result<Camera, CameraError> {
    let value = |name: &str| table.f64_column(name).and_then(|v| v.first().copied());
    let mut p = [[0.0; 4]; 3];
    for (r, row) in p.iter_mut().enumerate() {
        for (c, cell) in row.iter_mut().enumerate() {
            *cell = value(&format!("p{}{}", r + 1, c + 1)).ok_or(CameraError::Missing(r + 1, c + 1))?;
        }
    }
    Camera::from_projection(&p, value("k1").unwrap_or(0.0), value("k2").unwrap_or(0.0)).ok_or(CameraError::Singular)
}

type Projected = (Table, Option<Table>, serde_json::Value);

struct ProjectOptions<'a> {
    wanted: &'a [String],
    unit_motion: UnitMotion,
    upright: bool,
    min_angle: f64,
}

fn project(
    tracks: &Table,
    camera: &Camera,
    plane: &Plane,
    options: &ProjectOptions<'_>,
    label: &str,
) -> anyhow::Result<Projected> {
    let (wanted, unit_motion, min_angle) = (options.wanted, options.unit_motion, options.min_angle);
    let time = tracks.f64_column("time_s").ok_or_else(|| anyhow::anyhow!("{label}: no time_s column"))?;
    let (u, v) = (
        tracks.f64_column("u_px").expect("checked"),
        tracks.f64_column("v_px").ok_or_else(|| anyhow::anyhow!("{label}: no v_px"))?,
    );
    let Some(ColumnData::Str(names)) = tracks.column("point").map(|c| &c.data) else {
        anyhow::bail!("{label}: the point column is not text");
    };
    let frames: Option<&[i64]> = match tracks.column("frame").map(|c| &c.data) {
        Some(ColumnData::I64(f)) => Some(f),
        _ => None,
    };
    let mut available: Vec<&String> = Vec::new();
    for n in names {
        if !available.contains(&n) {
            available.push(n);
        }
    }
    let selected: Vec<String> = if wanted.is_empty() {
        available.iter().filter(|n| n.starts_with('M')).map(|n| (*n).clone()).collect()
    } else {
        for w in wanted {
            if !available.contains(&w) {
                return Err(UserError::new(format!("parameter `points`: `{w}` is not a tracked point of {label}"))
                    .hint(format!(
                        "tracked points: {}",
                        available.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", ")
                    ))
                    .into());
            }
        }
        wanted.to_vec()
    };
    if unit_motion != UnitMotion::None && selected.len() < 2 {
        return Err(UserError::new(format!(
            "unit_motion `{unit_motion}` needs two points on the unit, {} given",
            selected.len()
        ))
        .hint("list them in `points`: the first two give the unit's segment (e.g. bottom then top marker)")
        .into());
    }
    let (mut t_out, mut p_out, mut x_out, mut y_out, mut z_out) = (vec![], vec![], vec![], vec![], vec![]);
    let mut series: BTreeMap<&str, Vec<(f64, Option<Vec3>)>> = BTreeMap::new();
    for i in 0..names.len() {
        if !selected.contains(&names[i]) {
            continue;
        }
        let world = if u[i].is_finite() && v[i].is_finite() {
            Some(backproject(camera, [u[i], v[i]], plane, min_angle).map_err(|e| {
                let frame = frames.map_or(String::new(), |f| format!(" in frame {}", f[i]));
                UserError::new(format!("point {}{frame} of {label} (pixel {:.1}, {:.1}): {e}", names[i], u[i], v[i])).hint(
                    "check the plane `a,b,c,d` (world mm, the same frame as the control points) and that the camera sees it at a usable angle",
                )
            })?)
        } else {
            None
        };
        t_out.push(time[i]);
        p_out.push(names[i].clone());
        let [x, y, z] = world.unwrap_or([f64::NAN; 3]);
        x_out.push(x);
        y_out.push(y);
        z_out.push(z);
        series.entry(names[i].as_str()).or_default().push((time[i], world));
    }
    let mut points = Table::new();
    points.push(Column::f64("time_s", "s", "frame time", t_out));
    points.push(Column {
        name: "point".into(),
        unit: String::new(),
        description: "tracked point".into(),
        data: ColumnData::Str(p_out),
    });
    let on_plane = format!(
        "on the plane {:.6}X + {:.6}Y + {:.6}Z + {:.3} = 0 (Eq. 4; NaN when the track is lost)",
        plane.a, plane.b, plane.c, plane.d
    );
    points.push(Column::f64("X_mm", "mm", &format!("world X {on_plane}"), x_out));
    points.push(Column::f64("Y_mm", "mm", &format!("world Y {on_plane}"), y_out));
    points.push(Column::f64("Z_mm", "mm", &format!("world Z {on_plane}"), z_out));

    let motion = (unit_motion != UnitMotion::None).then(|| {
        let (a, b) = (&series[selected[0].as_str()], &series[selected[1].as_str()]);
        let zero = options.upright.then_some([0.0, 0.0, 1.0]);
        let motion = pair_motion(&a.iter().map(|s| s.1).collect::<Vec<_>>(), &b.iter().map(|s| s.1).collect::<Vec<_>>(), plane, zero);
        let time: Vec<f64> = a.iter().map(|s| s.0).collect();
        let pair = format!("{} → {}", selected[0], selected[1]);
        let mut table = Table::new();
        table.push(Column::f64("time_s", "s", "frame time", time));
        let rotation = motion.rotation.clone();
        if unit_motion == UnitMotion::Rocking {
            let zero = if options.upright { "from upright (the pair vertical)" } else { "from the first frame" };
            table.push(Column::f64("theta_rad", "rad", &format!("rocking angle θ: rotation of {pair} about the plane normal, {zero} (positive: top toward +X for a +Y normal)"), rotation.clone()));
        }
        for (k, axis) in ["x", "y", "z"].iter().enumerate() {
            table.push(Column::f64(
                &format!("d{axis}_mm"),
                "mm",
                &format!("displacement of the midpoint of {pair} along world {} from the first frame", axis.to_uppercase()),
                motion.translation.iter().map(|t| t[k]).collect(),
            ));
        }
        if unit_motion == UnitMotion::Rolling {
            table.push(Column::f64("yaw_rad", "rad", &format!("in-plane rotation of {pair} about the plane normal, from the first frame (right-handed)"), rotation));
        }
        table
    });
    let facts = json!({
        "plane": [plane.a, plane.b, plane.c, plane.d],
        "points": selected,
        "unit_motion": unit_motion,
        "theta_zero": if options.upright { "upright" } else { "first_frame" },
        "camera_centre_mm": camera.centre(),
    });
    Ok((points, motion, facts))
}

fn figure(motion: &Table, unit_motion: UnitMotion, label: &str) -> anyhow::Result<Vec<u8>> {
    let time = motion.f64_column("time_s").expect("written above");
    let column = |name: &str| motion.f64_column(name).expect("written above");
    let mut panels = Vec::new();
    let (rotation_name, rotation_title) = if unit_motion == UnitMotion::Rocking {
        ("theta_rad", "rocking angle θ")
    } else {
        ("yaw_rad", "in-plane rotation (yaw)")
    };
    panels.push(Panel {
        title: rotation_title.into(),
        x_label: "time [s]".into(),
        y_label: "rad".into(),
        series: vec![Series::new(rotation_name, time, column(rotation_name))],
        markers: vec![],
        log_y: false,
        spans: Vec::new(),
    });
    panels.push(Panel {
        title: "midpoint displacement".into(),
        x_label: "time [s]".into(),
        y_label: "mm".into(),
        series: ["dx_mm", "dy_mm", "dz_mm"].iter().map(|n| Series::new(*n, time, column(n))).collect(),
        markers: vec![],
        log_y: false,
        spans: Vec::new(),
    });
    if unit_motion == UnitMotion::Rolling {
        panels.push(Panel {
            title: "trajectory of the midpoint (plan view)".into(),
            x_label: "dx [mm]".into(),
            y_label: "dy [mm]".into(),
            series: vec![Series::new("midpoint", column("dx_mm"), column("dy_mm"))],
            markers: vec![],
            log_y: false,
            spans: Vec::new(),
        });
    }
    render_png(&format!("unit motion ({unit_motion}): {label}"), &panels, 1100, 1000).map_err(anyhow::Error::msg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::table::Column;

    /// A calibration table lacking an element, or with a singular left 3×3 block, is refused
    /// with the message the run prints after the calibration's label.
    #[test]
    fn a_calibration_without_a_camera_says_why() {
        let mut table = Table::new();
        for r in 1..=3 {
            for c in 1..=4 {
                table.push(Column::f64(&format!("p{r}{c}"), "", "", vec![0.0]));
            }
        }
        assert_eq!(camera_of(&table).unwrap_err().to_string(), "the calibration's P has a singular 3×3 block");
        table.columns.retain(|c| c.name != "p23");
        assert_eq!(camera_of(&table).unwrap_err().to_string(), "the calibration has no p23");
    }
}
