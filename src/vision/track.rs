//! Point tracking through a frame sequence (the study's step 2, made robust).
//!
//! Each point keeps the template cut around it in the first frame (the *reference*) and is
//! matched against it in every frame: an exhaustive integer search (ZNCC by default, or the
//! study's SSD), a quadratic fit on the score surface, then enhanced-correlation-coefficient
//! iterations (Evangelidis & Psarakis 2008, translation only) on the bicubic-interpolated frame,
//! which maximise the ZNCC itself and so are blind to gain and offset changes.
//!
//! The template is refreshed only when the score drops below `refresh_below` — and dropped
//! again for the reference as soon as the reference matches well — because re-cutting it every
//! frame (the study's update, `TemplatePolicy::EveryFrame`) lets per-frame errors accumulate.
//! A point whose score falls below `lost_below`, whose own neighbourhood the match does not
//! explain (`occluded_above`: an occluder over the point while the rest of the window still
//! matches), or that jumps too far, is reported lost (no position) and searched for in a wider
//! region until the reference matches again.

use super::image::{sample_patch, GrayImage};
use super::matcher::{match_template, Kernel, Score, ScoreMap, Scratch, Template};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TemplatePolicy {
    /// Match the first frame's template; refresh only when the score drops.
    Reference,
    /// The study's update: the window found in frame t is the template for frame t + 1.
    EveryFrame,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackOptions {
    /// Side of the square template (the study's m = 20 px).
    pub window: usize,
    /// Side of the square search region.
    pub search: usize,
    pub score: Score,
    pub policy: TemplatePolicy,
    /// Sub-pixel refinement (quadratic peak, then ECC); integer positions otherwise.
    pub subpixel: bool,
    pub refresh_below: f64,
    pub lost_below: f64,
    /// Largest distance (px) between the prediction and the match before the point counts as lost.
    pub max_jump: f64,
    /// Occlusion of the point: the residual energy of the match in the central half of the
    /// window (around the point), after the gain and offset fitted over the whole window, over
    /// the fitted template's signal energy there. Above this (more residual than signal) the
    /// point counts as lost.
    pub occluded_above: f64,
    /// Templates with a grey-level standard deviation below this get a warning.
    pub min_contrast: f64,
    pub kernel: Kernel,
}

impl Default for TrackOptions {
    fn default() -> Self {
        TrackOptions {
            window: 20,
            search: 60,
            score: Score::Zncc,
            policy: TemplatePolicy::Reference,
            subpixel: true,
            refresh_below: 0.8,
            lost_below: 0.5,
            max_jump: 15.0,
            occluded_above: 0.7,
            min_contrast: 8.0,
            kernel: Kernel::best(),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    Ok,
    /// Matched, and the template was re-cut here because the score had dropped.
    Refreshed,
    /// Found again after being lost.
    Reacquired,
    /// Best score below `lost_below` (occluded, out of view, changed beyond recognition).
    LostScore,
    /// The best match is farther from the prediction than `max_jump`.
    LostJump,
    /// The window matches, but not around the point itself: something covers it.
    LostOccluded,
    /// The search region or the template left the image.
    LostEdge,
    /// Camera-shake correction was asked for but no reference point was tracked in this frame.
    LostReference,
}

impl Status {
    pub fn name(self) -> &'static str {
        match self {
            Status::Ok => "ok",
            Status::Refreshed => "refreshed",
            Status::Reacquired => "reacquired",
            Status::LostScore => "lost_score",
            Status::LostJump => "lost_jump",
            Status::LostOccluded => "lost_occluded",
            Status::LostEdge => "lost_edge",
            Status::LostReference => "lost_reference",
        }
    }

    pub fn is_lost(self) -> bool {
        matches!(
            self,
            Status::LostScore | Status::LostJump | Status::LostOccluded | Status::LostEdge | Status::LostReference
        )
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Pixel position (x = u, y = v); None when lost.
    pub position: Option<[f64; 2]>,
    /// ZNCC of the match (NaN when nothing could be matched).
    pub score: f64,
    pub status: Status,
}

#[derive(Debug, Clone, PartialEq)]
pub enum TrackError {
    /// The start point's template does not fit in the frame.
    OutsideImage { point: [f64; 2], width: usize, height: usize, window: usize },
}

impl std::fmt::Display for TrackError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TrackError::OutsideImage { point, width, height, window } => write!(
                f,
                "start point ({:.1}, {:.1}) is outside the {width}×{height} frame or closer than {} px to its edge",
                point[0],
                point[1],
                window / 2 + 2
            ),
        }
    }
}

/// A template and where the tracked point sits relative to its top-left pixel.
#[derive(Debug, Clone)]
struct Anchor {
    template: Template,
    /// Zero-mean template values, for the ECC refinement.
    centred: Vec<f64>,
    offset: [f64; 2],
}

impl Anchor {
    /// The template centred (to the nearest pixel) on `point`.
    fn cut(frame: &GrayImage, point: [f64; 2], window: usize) -> Option<Anchor> {
        let half = (window as f64 - 1.0) / 2.0;
        let x = (point[0] - half).round() as i64;
        let y = (point[1] - half).round() as i64;
        // The ECC refinement samples one pixel around the window (bicubic taps).
        if x < 1 || y < 1 || x + window as i64 + 2 > frame.width as i64 || y + window as i64 + 2 > frame.height as i64 {
            return None;
        }
        let template = Template::cut(frame, x, y, window)?;
        let n = (window * window) as f64;
        let mean = template.pixels.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
        let centred = template.pixels.iter().map(|&v| f64::from(v) - mean).collect();
        Some(Anchor { template, centred, offset: [point[0] - x as f64, point[1] - y as f64] })
    }
}

pub struct PointTracker {
    reference: Anchor,
    current: Anchor,
    last: [f64; 2],
    velocity: Option<[f64; 2]>,
    lost: bool,
    pub low_contrast: Option<f64>,
    scratch: Scratch,
    sample_scratch: Vec<f64>,
}

impl PointTracker {
    pub fn new(first: &GrayImage, start: [f64; 2], options: &TrackOptions) -> Result<PointTracker, TrackError> {
        let anchor = Anchor::cut(first, start, options.window).ok_or(TrackError::OutsideImage {
            point: start,
            width: first.width,
            height: first.height,
            window: options.window,
        })?;
        let contrast = anchor.template.contrast();
        Ok(PointTracker {
            reference: anchor.clone(),
            current: anchor,
            last: start,
            velocity: None,
            lost: false,
            low_contrast: (contrast < options.min_contrast).then_some(contrast),
            scratch: Scratch::default(),
            sample_scratch: Vec::new(),
        })
    }

    pub fn step(&mut self, frame: &GrayImage, options: &TrackOptions) -> Observation {
        let prediction = match (self.lost, self.velocity) {
            (false, Some(v)) => [self.last[0] + v[0], self.last[1] + v[1]],
            _ => self.last,
        };
        // While lost, look twice as far around the last known position, with the reference.
        let search_size = if self.lost { 2 * options.search } else { options.search };
        let lost = |status, score| Observation { position: None, score, status };

        let mut on_reference = self.lost || same_template(&self.current, &self.reference);
        let first = if self.lost { &self.reference } else { &self.current };
        let (scratch, samples) = (&mut self.scratch, &mut self.sample_scratch);
        let mut found = search(scratch, samples, frame, first, prediction, search_size, options);
        if !on_reference && options.policy == TemplatePolicy::Reference {
            // A weak match with a refreshed template: the reference may fit again (the change
            // was temporary: blur, an occluder's edge), which undoes any drift.
            if found.as_ref().is_none_or(|f| f.score < options.refresh_below) {
                let candidate = search(scratch, samples, frame, &self.reference, prediction, search_size, options);
                if let Some(candidate) = candidate {
                    if candidate.score >= options.refresh_below
                        || found.as_ref().is_none_or(|f| candidate.score > f.score)
                    {
                        found = Some(candidate);
                        on_reference = true;
                    }
                }
            }
        }
        let Some(found) = found else {
            self.mark_lost();
            return lost(Status::LostEdge, f64::NAN);
        };
        if found.score < options.lost_below {
            self.mark_lost();
            return lost(Status::LostScore, found.score);
        }
        if found.occlusion > options.occluded_above {
            self.mark_lost();
            return lost(Status::LostOccluded, found.score);
        }
        if self.lost && found.score < options.refresh_below {
            return lost(Status::LostScore, found.score);
        }
        let jump = (found.point[0] - prediction[0]).hypot(found.point[1] - prediction[1]);
        if !self.lost && jump > options.max_jump {
            self.mark_lost();
            return lost(Status::LostJump, found.score);
        }

        let mut status = if self.lost { Status::Reacquired } else { Status::Ok };
        if on_reference && !same_template(&self.current, &self.reference) {
            self.current = self.reference.clone();
        }
        let recut = match options.policy {
            TemplatePolicy::EveryFrame => true,
            TemplatePolicy::Reference => found.score < options.refresh_below,
        };
        if recut {
            if let Some(anchor) = Anchor::cut(frame, found.point, options.window) {
                self.current = anchor;
                if options.policy == TemplatePolicy::Reference {
                    status = Status::Refreshed;
                }
            }
        }
        self.velocity = (!self.lost).then(|| [found.point[0] - self.last[0], found.point[1] - self.last[1]]);
        self.last = found.point;
        self.lost = false;
        Observation { position: Some(found.point), score: found.score, status }
    }

    fn mark_lost(&mut self) {
        self.lost = true;
        self.velocity = None;
    }
}

/// Best match of `anchor` in a square region of side `search_size` centred on `around`.
fn search(
    scratch: &mut Scratch,
    samples: &mut Vec<f64>,
    frame: &GrayImage,
    anchor: &Anchor,
    around: [f64; 2],
    search_size: usize,
    options: &TrackOptions,
) -> Option<Match> {
    let m = options.window as i64;
    let half = (search_size as i64 - m) / 2;
    let x = (around[0] - anchor.offset[0]).round() as i64 - half;
    let y = (around[1] - anchor.offset[1]).round() as i64 - half;
    let map = match_template(frame, &anchor.template, (x, y), search_size, options.kernel, scratch)?;
    let best = map.best(options.score);
    let integer = [(map.origin.0 + (best % map.cols) as i64) as f64, (map.origin.1 + (best / map.cols) as i64) as f64];
    let (top_left, score) = if options.subpixel {
        refine(frame, anchor, &map, best, options.score, samples)
            .unwrap_or((map.subpixel_peak(best, options.score), map.zncc[best]))
    } else {
        (integer, map.zncc[best])
    };
    let occlusion = occlusion(frame, anchor, top_left, samples);
    Some(Match { point: [top_left[0] + anchor.offset[0], top_left[1] + anchor.offset[1]], score, occlusion })
}

/// How much of the point's neighbourhood the frame at `top_left` fails to reproduce: the frame's
/// window is fitted as gain × template + offset over the whole window, and the residual energy
/// within the central half (the point ± window/4) is divided by the fitted template's own signal
/// energy there. Near 0 for a match (noise; a strong blur, σ = 1.2 px on 2 px speckle, reaches
/// 0.3–0.7: docs/models/cpt.md), above 1 when an occluder hides the point (the fitted gain drops
/// and the hidden signal is all residual). 0 when the window cannot be sampled (the edge checks
/// decide then).
fn occlusion(frame: &GrayImage, anchor: &Anchor, top_left: [f64; 2], samples: &mut Vec<f64>) -> f64 {
    let m = anchor.template.size;
    let Some(patch) = sample_patch(frame, top_left, m, samples) else {
        return 0.0;
    };
    let t = &anchor.centred;
    let n = (m * m) as f64;
    let mean = patch.values.iter().sum::<f64>() / n;
    let (tv, tt) =
        t.iter().zip(&patch.values).fold((0.0, 0.0), |(tv, tt), (tk, v)| (tv + tk * (v - mean), tt + tk * tk));
    if tt == 0.0 {
        return 0.0;
    }
    let gain = tv / tt;
    if gain <= 0.0 {
        return 1.0;
    }
    let reach = m as f64 / 4.0;
    let near = |k: usize| {
        let (x, y) = ((k % m) as f64, (k / m) as f64);
        (x - anchor.offset[0]).abs() <= reach && (y - anchor.offset[1]).abs() <= reach
    };
    let central: Vec<usize> = (0..m * m).filter(|&k| near(k)).collect();
    let c = central.len() as f64;
    let t_mean = central.iter().map(|&k| t[k]).sum::<f64>() / c;
    let (residual, signal) = central.iter().fold((0.0, 0.0), |(r, e), &k| {
        let model = gain * t[k];
        ((patch.values[k] - mean - model).powi(2) + r, e + (gain * (t[k] - t_mean)).powi(2))
    });
    if signal > 0.0 {
        residual / signal
    } else {
        0.0
    }
}

fn same_template(a: &Anchor, b: &Anchor) -> bool {
    a.offset == b.offset && a.template.pixels == b.template.pixels
}

struct Match {
    point: [f64; 2],
    score: f64,
    /// `occlusion` at the match.
    occlusion: f64,
}

/// Quadratic peak, then ECC iterations maximising the ZNCC of the template against the
/// bicubic-interpolated frame. None when the refinement leaves the image or wanders off.
fn refine(
    frame: &GrayImage,
    anchor: &Anchor,
    map: &ScoreMap,
    best: usize,
    score: Score,
    scratch: &mut Vec<f64>,
) -> Option<([f64; 2], f64)> {
    let start = map.subpixel_peak(best, score);
    let m = anchor.template.size;
    let t = &anchor.centred;
    let t_norm = t.iter().map(|v| v * v).sum::<f64>().sqrt();
    if t_norm == 0.0 {
        return None;
    }
    let mut p = start;
    let mut zncc = f64::NAN;
    for _ in 0..15 {
        let patch = sample_patch(frame, p, m, scratch)?;
        let n = (m * m) as f64;
        let mean = |v: &[f64]| v.iter().sum::<f64>() / n;
        let (mi, mx, my) = (mean(&patch.values), mean(&patch.dx), mean(&patch.dy));
        let (mut q11, mut q12, mut q22, mut gt1, mut gt2, mut gi1, mut gi2, mut ti, mut ii) =
            (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for (((&value, &dx), &dy), &tk) in patch.values.iter().zip(&patch.dx).zip(&patch.dy).zip(t) {
            let i = value - mi;
            let (g1, g2) = (dx - mx, dy - my);
            q11 += g1 * g1;
            q12 += g1 * g2;
            q22 += g2 * g2;
            gt1 += g1 * tk;
            gt2 += g2 * tk;
            gi1 += g1 * i;
            gi2 += g2 * i;
            ti += tk * i;
            ii += i * i;
        }
        zncc = if ii > 0.0 { ti / (t_norm * ii.sqrt()) } else { 0.0 };
        let det = q11 * q22 - q12 * q12;
        if !(det > 0.0) {
            return None;
        }
        // Q⁻¹ applied to a 2-vector, and the quadratic forms ECC needs.
        let solve = |a: f64, b: f64| [(q22 * a - q12 * b) / det, (q11 * b - q12 * a) / det];
        let qi = solve(gi1, gi2);
        let qt = solve(gt1, gt2);
        let i_proj = gi1 * qi[0] + gi2 * qi[1];
        let t_proj = gt1 * qt[0] + gt2 * qt[1];
        let ti_proj = gt1 * qi[0] + gt2 * qi[1];
        let denominator = ti - ti_proj;
        let lambda = if denominator > 0.0 {
            (ii - i_proj) / denominator
        } else {
            let l1 = (i_proj / t_proj).sqrt();
            let l2 = (ti_proj - ti) / t_proj;
            l1.max(l2)
        };
        let step = [lambda * qt[0] - qi[0], lambda * qt[1] - qi[1]];
        if !(step[0].is_finite() && step[1].is_finite()) {
            return None;
        }
        p = [p[0] + step[0], p[1] + step[1]];
        if (p[0] - start[0]).abs() > 1.5 || (p[1] - start[1]).abs() > 1.5 {
            return None;
        }
        if step[0].hypot(step[1]) < 1e-4 {
            break;
        }
    }
    Some((p, zncc))
}

/// A named point to track.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedPoint {
    pub name: String,
    pub start: [f64; 2],
}

/// All points of one sequence: moving points, and optional stationary reference points whose
/// mean apparent displacement (camera shake) is subtracted from the moving points.
pub struct SequenceTracker {
    options: TrackOptions,
    points: Vec<(NamedPoint, PointTracker)>,
    references: Vec<(NamedPoint, PointTracker)>,
}

/// One frame's observations, moving points first, then reference points (uncorrected).
pub type FrameObservations = Vec<(String, Observation)>;

impl SequenceTracker {
    /// Starts on the first frame; the first observations are the start points themselves.
    pub fn new(
        first: &GrayImage,
        points: &[NamedPoint],
        references: &[NamedPoint],
        options: TrackOptions,
    ) -> Result<(SequenceTracker, FrameObservations), (String, TrackError)> {
        let start = |list: &[NamedPoint]| {
            list.iter()
                .map(|p| {
                    PointTracker::new(first, p.start, &options).map(|t| (p.clone(), t)).map_err(|e| (p.name.clone(), e))
                })
                .collect::<Result<Vec<_>, _>>()
        };
        let tracker = SequenceTracker { options, points: start(points)?, references: start(references)? };
        let first_observations = points
            .iter()
            .chain(references)
            .map(|p| (p.name.clone(), Observation { position: Some(p.start), score: 1.0, status: Status::Ok }))
            .collect();
        Ok((tracker, first_observations))
    }

    /// Names and contrasts of templates below `min_contrast`.
    pub fn low_contrast(&self) -> Vec<(String, f64)> {
        self.points
            .iter()
            .chain(&self.references)
            .filter_map(|(p, t)| t.low_contrast.map(|c| (p.name.clone(), c)))
            .collect()
    }

    pub fn step(&mut self, frame: &GrayImage) -> FrameObservations {
        let options = self.options;
        let references: Vec<(String, Observation, [f64; 2])> =
            self.references.iter_mut().map(|(p, t)| (p.name.clone(), t.step(frame, &options), p.start)).collect();
        let shake = if references.is_empty() {
            Some([0.0, 0.0])
        } else {
            let moved: Vec<[f64; 2]> = references
                .iter()
                .filter_map(|(_, o, start)| o.position.map(|q| [q[0] - start[0], q[1] - start[1]]))
                .collect();
            (!moved.is_empty()).then(|| {
                let n = moved.len() as f64;
                [moved.iter().map(|d| d[0]).sum::<f64>() / n, moved.iter().map(|d| d[1]).sum::<f64>() / n]
            })
        };
        let mut out: FrameObservations = self
            .points
            .iter_mut()
            .map(|(p, t)| {
                let o = t.step(frame, &options);
                let corrected = match (o.position, shake) {
                    (Some(q), Some(s)) => o.with_position(Some([q[0] - s[0], q[1] - s[1]])),
                    (Some(_), None) => Observation { position: None, score: o.score, status: Status::LostReference },
                    (None, _) => o,
                };
                (p.name.clone(), corrected)
            })
            .collect();
        out.extend(references.into_iter().map(|(name, o, _)| (name, o)));
        out
    }
}

impl Observation {
    fn with_position(self, position: Option<[f64; 2]>) -> Observation {
        Observation { position, ..self }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::synthetic::{Layer, SpeckleScene};

    fn options() -> TrackOptions {
        TrackOptions { window: 16, search: 40, ..TrackOptions::default() }
    }

    #[test]
    fn tracks_sub_pixel_translation() {
        let scene = SpeckleScene::new(120, 90, 11);
        let start = [60.0, 45.0];
        let first = scene.render(&[Layer::background([0.0, 0.0])], 0.0, 0);
        let mut tracker = PointTracker::new(&first, start, &options()).unwrap();
        let mut worst: f64 = 0.0;
        for k in 1..40 {
            let shift = [0.37 * k as f64 / 8.0, -0.21 * k as f64 / 8.0].map(|v| (v * 8.0).round() / 8.0);
            let frame = scene.render(&[Layer::background(shift)], 0.0, k);
            let o = tracker.step(&frame, &options());
            let q = o.position.unwrap();
            worst = worst.max((q[0] - start[0] - shift[0]).hypot(q[1] - start[1] - shift[1]));
        }
        assert!(worst < 0.05, "worst error {worst} px");
    }

    #[test]
    fn start_outside_the_image_is_refused() {
        let scene = SpeckleScene::new(60, 40, 1);
        let frame = scene.render(&[Layer::background([0.0, 0.0])], 0.0, 0);
        assert!(PointTracker::new(&frame, [70.0, 10.0], &options()).is_err());
        assert!(PointTracker::new(&frame, [5.0, 20.0], &options()).is_err());
    }
}
