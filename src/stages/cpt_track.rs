//! `cpt_track`: track points through an image sequence (a folder of PNG/JPEG frames, or a video
//! through ffmpeg). Exhaustive ZNCC (or the study's SSD) search against each point's reference
//! template, sub-pixel refinement, template refresh only when the score drops, lost points
//! reported as NaN with a status, optional camera-shake correction from stationary points.

use serde_json::json;

use super::{partition_path, Stage, StageContext};
use crate::error::UserError;
use crate::io::frames::FrameReader;
use crate::pipeline::params;
use crate::pipeline::spec::RecordFormat;
use crate::plot::{render_png, Panel, Series};
use crate::table::{Column, ColumnData, Table};
use crate::vision::matcher::{Kernel, Score};
use crate::vision::track::{NamedPoint, SequenceTracker, Status, TemplatePolicy, TrackError, TrackOptions};

crate::stage_params! {
    /// The parameters of `cpt_track`.
    pub struct CptTrackParams {
        // `u,v;u,v` or `M1=u,v;…`, read by `parse_points`.
        /// start points in the first frame, `u,v;u,v` or `M1=u,v;M2=u,v` (u right, v down; unnamed points are M1, M2,
        /// …)
        pub points: String [unit = "px"],
        /// stationary points (R1, R2, … unless named) whose mean apparent motion (camera shake) is subtracted from
        /// the points
        pub reference_points: String [default = "", unit = "px"],
        /// frame rate: required for a frames folder; for a video, overrides the container's presentation times
        pub fps: Option<f64> [default = null, unit = "Hz", range = (1e-6, 1e7)],
        /// side of the square template (the study's m)
        pub window_px: usize [default = 20, unit = "px", range = (5.0, 200.0)],
        /// side of the square search region around the predicted position
        pub search_px: usize [default = 60, unit = "px", range = (7.0, 1000.0)],
        /// zncc: zero-mean normalised cross-correlation (ignores lighting gain and offset); ssd: the study's sum of
        /// squared differences
        pub score: ScoreChoice [default = "zncc"],
        /// reference: match the first frame's template, refresh only when the score drops; every_frame: the study's
        /// re-cut each frame (drifts)
        pub template: TemplateChoice [default = "reference"],
        /// sub-pixel positions (quadratic peak + ECC refinement); false: whole pixels, as the study
        pub subpixel: bool [default = true],
        /// ZNCC below which the template is refreshed (and a lost point must reach to be re-acquired)
        pub refresh_below: f64 [default = 0.8, range = (-1.0, 1.0)],
        /// ZNCC below which a point is lost
        pub lost_below: f64 [default = 0.5, range = (-1.0, 1.0)],
        /// a match farther than this from the predicted position counts as lost
        pub max_jump_px: f64 [default = 15.0, unit = "px", range = (0.0, 1e6)],
        /// a point counts as lost (occluded) when the match's residual energy around it (the central half of the
        /// window) exceeds this multiple of the template's signal energy there
        pub occluded_above: f64 [default = 0.7, range = (0.0, 1e6)],
        /// warn when a template's standard deviation is below this
        pub min_contrast: f64 [default = 8.0, unit = "grey levels", range = (0.0, 255.0)],
        #[flatten]
        pub mcap: super::Mcap,
    }
}

crate::choice! {
    /// `score`: the matching criterion.
    pub enum ScoreChoice { Zncc = "zncc", Ssd = "ssd" }
}

crate::choice! {
    /// `template`: which template a point is matched against.
    pub enum TemplateChoice { Reference = "reference", EveryFrame = "every_frame" }
}

super::declare_stage! {
    /// Track points through an image sequence (PNG/JPEG folder, or a video through ffmpeg): ZNCC or SSD template
    /// matching against a reference template, sub-pixel, lost points flagged, optional camera-shake correction.
    pub struct CptTrack: "cpt_track", version 3, reads Files(&[RecordFormat::Frames]), params CptTrackParams;
    outputs {
        /// per frame and point: frame, time_s, point, u_px, v_px, score, status (NaN positions when lost)
        "tracks": TimeSeries,
        /// tracks.png: u, v and score of every point over time
        "figures": Files,
    }
    examples {
        /// the four markers through the video, started where a person clicks them in the first frame
        super::DEMO_CAMERA => "\
cpt_track:
  type: cpt_track
  inputs: [video]
  params:
    fps: 30
    points: \"M1=376.3,328.0; M2=380.2,248.8; M3=549.7,212.6; M4=613.4,205.8\"
",
    }
}

/// Frames decoded per batch: enough to keep every core decoding.
const BATCH: usize = 16;

impl Stage for CptTrack {
    super::info_and_check_params!(CptTrackParams);

    fn run(&self, ctx: &StageContext<'_>) -> anyhow::Result<()> {
        let p: CptTrackParams = params::typed(ctx.params)?;
        let points = parse_points(&p.points, "M", "points")?;
        if points.is_empty() {
            return Err(UserError::new("parameter `points` of `cpt_track` names no point")
                .hint("give start points as `u,v;u,v`")
                .into());
        }
        let references = parse_points(&p.reference_points, "R", "reference_points")?;
        let options = options(&p);
        let fps = p.fps;
        let parts: Vec<_> = ctx.inputs.iter().flat_map(|i| i.parts()).collect();
        ctx.sink.set_total(parts.len());
        // Sequences one after another: each already decodes its frames in parallel.
        parts.iter().try_for_each(|part| {
            let (mut tracks, summary) = track_sequence(&part.path, &points, &references, options, fps, ctx)?;
            tracks.metadata.insert("shakeflow.cpt_track".into(), summary.to_string());
            tracks.metadata.extend(super::record_provenance(part));
            let name = match partition_path(&part.partition) {
                p if p.is_empty() => "tracks.png".to_string(),
                p => format!("tracks-{}.png", p.replace(['/', '='], "_")),
            };
            ctx.sink.write_file("figures", &name, &figure(&tracks, &part.label)?)?;
            ctx.sink.write_series("tracks", &part.partition, tracks, "point")
        })
    }
}

fn options(p: &CptTrackParams) -> TrackOptions {
    TrackOptions {
        window: p.window_px,
        search: p.search_px,
        score: match p.score {
            ScoreChoice::Zncc => Score::Zncc,
            ScoreChoice::Ssd => Score::Ssd,
        },
        policy: match p.template {
            TemplateChoice::Reference => TemplatePolicy::Reference,
            TemplateChoice::EveryFrame => TemplatePolicy::EveryFrame,
        },
        subpixel: p.subpixel,
        refresh_below: p.refresh_below,
        lost_below: p.lost_below,
        max_jump: p.max_jump_px,
        occluded_above: p.occluded_above,
        min_contrast: p.min_contrast,
        kernel: Kernel::best(),
    }
}

/// `u,v;u,v` or `name=u,v;…` → named points (`prefix1`, `prefix2`, … for unnamed ones).
pub fn parse_points(text: &str, prefix: &str, param: &str) -> Result<Vec<NamedPoint>, UserError> {
    let mut out: Vec<NamedPoint> = Vec::new();
    for (k, item) in text.split(';').map(str::trim).filter(|s| !s.is_empty()).enumerate() {
        let (name, coordinates) = match item.split_once('=') {
            Some((n, c)) => (n.trim().to_string(), c),
            None => (format!("{prefix}{}", k + 1), item),
        };
        let values: Vec<f64> =
            coordinates.split(',').filter_map(|v| v.trim().parse::<f64>().ok()).filter(|v| v.is_finite()).collect();
        if values.len() != 2 || coordinates.split(',').count() != 2 || name.is_empty() {
            return Err(UserError::new(format!("parameter `{param}`: cannot read `{item}` as a point"))
                .hint("points are `u,v` pixel pairs separated by `;`, optionally named: `M1=412.5,300;M2=530,310`"));
        }
        if out.iter().any(|p| p.name == name) {
            return Err(UserError::new(format!("parameter `{param}`: two points are named `{name}`"))
                .hint("give every point its own name"));
        }
        out.push(NamedPoint { name, start: [values[0], values[1]] });
    }
    Ok(out)
}

fn track_sequence(
    path: &std::path::Path,
    points: &[NamedPoint],
    references: &[NamedPoint],
    options: TrackOptions,
    fps: Option<f64>,
    ctx: &StageContext<'_>,
) -> anyhow::Result<(Table, serde_json::Value)> {
    let mut reader = FrameReader::open(path)?;
    let first_batch = reader.next_batch(BATCH)?;
    let Some(first) = first_batch.first() else {
        return Err(UserError::new("the image sequence has no frame").in_file(path).into());
    };
    if fps.is_none() && first.pts_s.is_none() {
        return Err(UserError::new("a frames folder has no timestamps")
            .in_file(path)
            .hint("set the frame rate: `fps: 30` under the stage's `params`")
            .into());
    }
    let (width, height) = (first.image.width, first.image.height);
    let (mut tracker, first_observations) =
        SequenceTracker::new(&first.image, points, references, options).map_err(|(name, e)| {
            let TrackError::OutsideImage { .. } = e;
            UserError::new(format!("point {name}: {e}")).in_file(path).hint(format!(
                "points are (u, v) pixels of the first frame ({}): u from 0 to {} rightwards, v from 0 to {} downwards",
                first.label,
                width - 1,
                height - 1
            ))
        })?;
    let mut warnings = Vec::new();
    for (name, contrast) in tracker.low_contrast() {
        let warning = format!(
            "point {name}: its template has little contrast (grey-level std {contrast:.1} < {}): tracking may wander; pick a textured spot or a marker",
            options.min_contrast
        );
        ctx.sink.warn(&format!("{}: {warning}", path.display()));
        warnings.push(warning);
    }
    let names: Vec<String> = points.iter().chain(references).map(|p| p.name.clone()).collect();
    let mut rows = Rows::default();
    let time_of = |index: usize, pts: Option<f64>| match (fps, pts) {
        (Some(f), _) => index as f64 / f,
        (None, Some(t)) => t,
        (None, None) => unreachable!("checked on the first frame"),
    };
    rows.push(0, time_of(0, first.pts_s), &first_observations);
    let mut batch = first_batch.into_iter().skip(1).collect::<Vec<_>>();
    let mut frames = 1;
    loop {
        for frame in &batch {
            if (frame.image.width, frame.image.height) != (width, height) {
                return Err(UserError::new(format!(
                    "{}: frame is {}×{}, the first frame {width}×{height}",
                    frame.label, frame.image.width, frame.image.height
                ))
                .in_file(path)
                .into());
            }
            let observations = tracker.step(&frame.image);
            rows.push(frame.index, time_of(frame.index, frame.pts_s), &observations);
            frames += 1;
        }
        batch = reader.next_batch(BATCH)?;
        if batch.is_empty() {
            break;
        }
    }
    if let Some(w) = rows.time.windows(names.len() + 1).step_by(names.len()).find(|w| !(w[names.len()] > w[0])) {
        return Err(UserError::new(format!("frame times do not increase ({} s then {} s)", w[0], w[names.len()]))
            .in_file(path)
            .hint("set `fps` to time frames by their index")
            .into());
    }
    let per_point: serde_json::Map<String, serde_json::Value> = names
        .iter()
        .map(|n| {
            let count =
                |f: &dyn Fn(&str) -> bool| rows.point.iter().zip(&rows.status).filter(|(p, s)| *p == n && f(s)).count();
            (
                n.clone(),
                json!({
                    "lost_frames": count(&|s| s.starts_with("lost")),
                    "refreshes": count(&|s| s == Status::Refreshed.name()),
                    "reacquired": count(&|s| s == Status::Reacquired.name()),
                }),
            )
        })
        .collect();
    let summary = json!({
        "frames": frames,
        "width_px": width,
        "height_px": height,
        "time_source": if fps.is_some() { "frame index / fps" } else { "container presentation times" },
        "points": points.iter().map(|p| (p.name.clone(), p.start)).collect::<std::collections::BTreeMap<_, _>>(),
        "reference_points": references.iter().map(|p| (p.name.clone(), p.start)).collect::<std::collections::BTreeMap<_, _>>(),
        "per_point": per_point,
        "warnings": warnings,
    });
    Ok((rows.into_table(!references.is_empty()), summary))
}

#[derive(Default)]
struct Rows {
    frame: Vec<i64>,
    time: Vec<f64>,
    point: Vec<String>,
    u: Vec<f64>,
    v: Vec<f64>,
    score: Vec<f64>,
    status: Vec<String>,
}

impl Rows {
    fn push(&mut self, frame: usize, time: f64, observations: &[(String, crate::vision::track::Observation)]) {
        for (name, o) in observations {
            self.frame.push(frame as i64);
            self.time.push(time);
            self.point.push(name.clone());
            let [u, v] = o.position.unwrap_or([f64::NAN; 2]);
            self.u.push(u);
            self.v.push(v);
            self.score.push(o.score);
            self.status.push(o.status.name().to_string());
        }
    }

    fn into_table(self, shake_corrected: bool) -> Table {
        let corrected = if shake_corrected {
            "; moving points corrected for camera shake (mean motion of the R points)"
        } else {
            ""
        };
        let mut table = Table::new();
        table.push(Column {
            name: "frame".into(),
            unit: String::new(),
            description: "frame index from 0".into(),
            data: ColumnData::I64(self.frame),
        });
        table.push(Column::f64("time_s", "s", "frame time from the first frame", self.time));
        table.push(Column {
            name: "point".into(),
            unit: String::new(),
            description: "tracked point (M…: moving, R…: stationary reference)".into(),
            data: ColumnData::Str(self.point),
        });
        table.push(Column::f64(
            "u_px",
            "px",
            &format!("horizontal pixel position, rightwards (NaN when lost){corrected}"),
            self.u,
        ));
        table.push(Column::f64(
            "v_px",
            "px",
            &format!("vertical pixel position, downwards (NaN when lost){corrected}"),
            self.v,
        ));
        table.push(Column::f64(
            "score",
            "",
            "ZNCC of the match with the template (1 = identical up to gain and offset)",
            self.score,
        ));
        table.push(Column {
            name: "status".into(),
            unit: String::new(),
            description:
                "ok | refreshed (template re-cut) | reacquired | lost_score | lost_jump | lost_occluded | lost_edge | lost_reference"
                    .into(),
            data: ColumnData::Str(self.status),
        });
        table
    }
}

fn figure(tracks: &Table, label: &str) -> anyhow::Result<Vec<u8>> {
    let time = tracks.f64_column("time_s").expect("written above");
    let Some(ColumnData::Str(points)) = tracks.column("point").map(|c| &c.data) else { unreachable!("written above") };
    let mut names: Vec<&String> = Vec::new();
    for p in points {
        if !names.contains(&p) {
            names.push(p);
        }
    }
    let series_of = |column: &str| -> Vec<(String, Vec<f64>, Vec<f64>)> {
        let values = tracks.f64_column(column).expect("written above");
        names
            .iter()
            .map(|n| {
                let rows: Vec<usize> = (0..points.len()).filter(|&i| &points[i] == *n).collect();
                ((*n).clone(), rows.iter().map(|&i| time[i]).collect(), rows.iter().map(|&i| values[i]).collect())
            })
            .collect()
    };
    let (u, v, score) = (series_of("u_px"), series_of("v_px"), series_of("score"));
    fn panel<'a>(title: &str, y_label: &str, data: &'a [(String, Vec<f64>, Vec<f64>)]) -> Panel<'a> {
        Panel {
            title: title.into(),
            x_label: "time [s]".into(),
            y_label: y_label.into(),
            series: data.iter().map(|(n, x, y)| Series::new(n.clone(), x, y)).collect(),
            markers: vec![],
            log_y: false,
            spans: Vec::new(),
        }
    }
    let panels = [
        panel("horizontal position (gaps: lost)", "u [px]", &u),
        panel("vertical position (gaps: lost)", "v [px]", &v),
        panel("match score", "ZNCC", &score),
    ];
    render_png(&format!("tracks: {label}"), &panels, 1200, 1100).map_err(anyhow::Error::msg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_parse_with_and_without_names() {
        let p = parse_points("412.5,300; 530,310", "M", "points").unwrap();
        assert_eq!((p[1].name.as_str(), p[1].start), ("M2", [530.0, 310.0]));
        let p = parse_points("tip=1,2;base=3.5,4", "M", "points").unwrap();
        assert_eq!(p[0].name, "tip");
        assert!(parse_points("1,2,3", "M", "points").is_err());
        assert!(parse_points("a=1,2;a=3,4", "M", "points").is_err());
        assert!(parse_points("", "R", "reference_points").unwrap().is_empty());
    }
}
