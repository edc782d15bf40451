//! Lost points under occlusion, held-out style: rendered sequences (`vision::synthetic`) in which
//! occluders of several kinds pass over a tracked point on a moving plate — a flat bar, a bar
//! with the same speckle texture as the scene, small flat and textured squares that cover part
//! of the window (the point itself at times), and a bar that sweeps in fast from the edge of the
//! search region. A frame is *occluded* when the point lies under the occluder, *visible* when
//! the occluder does not touch the template window at all (frames in between are scored on
//! accuracy only when tracked). Requirements (the floors, beaten): at least 80 % of the
//! occluded frames flagged lost (no position), no visible frame lost, positions on visible frames
//! within 0.2 px of the truth and on partly covered ones within 1 px.
//!
//! The threshold (`occluded_above` = 0.7) was tuned on seeds 23 and 37 (0.5 flagged 94.7 % there
//! but also a blurred frame of the 1000-frame tracking test; 1.0 flagged only 64 %; 0.7: 88.7 %,
//! no false loss); the assertions run on seeds 51 and 64, scored once after the tuning.

use shakeflow::vision::image::GrayImage;
use shakeflow::vision::synthetic::{quantise, Layer, Look, SpeckleScene};
use shakeflow::vision::track::{PointTracker, TrackOptions};

const W: usize = 160;
const H: usize = 120;
const FRAMES: usize = 160;
const PLATE: [f64; 4] = [30.0, 25.0, 120.0, 95.0];
const P0: [f64; 2] = [72.0, 60.0];

#[derive(Clone, Copy, Debug)]
enum Occluder {
    FlatBar,
    TexturedBar,
    FlatSquare,
    TexturedSquare,
    FastBar,
}

const KINDS: [Occluder; 5] =
    [Occluder::FlatBar, Occluder::TexturedBar, Occluder::FlatSquare, Occluder::TexturedSquare, Occluder::FastBar];

fn plate_shift(k: usize) -> [f64; 2] {
    let t = k as f64;
    [
        quantise(9.0 * (std::f64::consts::TAU * t / 140.0).sin()),
        quantise(5.0 * (std::f64::consts::TAU * t / 95.0).sin()),
    ]
}

/// The occluder's rectangle (image px) at frame k, if any.
fn occluder_rect(kind: Occluder, k: usize) -> Option<[f64; 4]> {
    let t = k as f64;
    match kind {
        // 20 px wide, full height, 0.75 px per frame from the left.
        Occluder::FlatBar | Occluder::TexturedBar => {
            let x = quantise(20.0 + 0.75 * t);
            Some([x, 0.0, x + 20.0, H as f64])
        }
        // From frame 10 (the first frame's template must be clean), a 9 px square circling
        // slowly around the point's mean position: it covers part of the window most of the
        // time and the point itself now and then.
        Occluder::FlatSquare | Occluder::TexturedSquare => (k >= 10).then(|| {
            let a = std::f64::consts::TAU * t / 80.0;
            let (cx, cy) = (quantise(P0[0] + 7.0 * a.cos()), quantise(P0[1] + 6.0 * (2.0 * a).sin()));
            [cx - 4.5, cy - 4.5, cx + 4.5, cy + 4.5]
        }),
        // Sweeps in at 6 px per frame and leaves: it enters the search region from its edge.
        Occluder::FastBar => {
            let x = quantise(-30.0 + 6.0 * (t - 40.0));
            (40..80).contains(&k).then_some([x, 0.0, x + 16.0, H as f64])
        }
    }
}

fn frame(scene: &SpeckleScene, kind: Occluder, k: usize) -> GrayImage {
    let shift = plate_shift(k);
    let mut layers = vec![Layer::background([0.0, 0.0]), Layer { texture: 1, rect: Some(PLATE), shift }];
    let rect = occluder_rect(kind, k);
    let textured = matches!(kind, Occluder::TexturedBar | Occluder::TexturedSquare);
    if let (true, Some(r)) = (textured, rect) {
        // A textured occluder: texture 2 shown through the rectangle, fixed to it.
        layers.push(Layer { texture: 2, rect: Some(r), shift: [0.0, 0.0] });
    }
    let look = Look {
        gain: 1.0 + 0.1 * (k as f64 / 30.0).sin(),
        offset: 5.0 * (k as f64 / 45.0).cos(),
        occluder: (!textured).then_some(rect.map(|r| (r, 70.0))).flatten(),
        noise_sigma: 3.0,
        ..Look::default()
    };
    scene.render_with(&layers, &look, k as u64)
}

#[derive(Default, Debug)]
struct Score {
    occluded: usize,
    occluded_lost: usize,
    visible: usize,
    visible_lost: usize,
    /// Worst error of a position given on a visible frame, and on a partly covered one.
    worst_visible_px: f64,
    worst_partial_px: f64,
}

fn score(seed: u64, kind: Occluder, options: &TrackOptions) -> Score {
    let scene = SpeckleScene::with_textures(W, H, 3, seed);
    let frames: Vec<GrayImage> = (0..FRAMES).map(|k| frame(&scene, kind, k)).collect();
    let mut tracker = PointTracker::new(&frames[0], P0, options).unwrap();
    let half = options.window as f64 / 2.0 + 1.0;
    let mut s = Score::default();
    for (k, image) in frames.iter().enumerate().skip(1) {
        let o = tracker.step(image, options);
        let shift = plate_shift(k);
        let truth = [P0[0] + shift[0], P0[1] + shift[1]];
        let rect = occluder_rect(kind, k);
        let inside = |r: &[f64; 4]| truth[0] >= r[0] && truth[0] <= r[2] && truth[1] >= r[1] && truth[1] <= r[3];
        let touches = |r: &[f64; 4]| {
            truth[0] + half > r[0] && truth[0] - half < r[2] && truth[1] + half > r[1] && truth[1] - half < r[3]
        };
        if rect.as_ref().is_some_and(inside) {
            s.occluded += 1;
            s.occluded_lost += usize::from(o.status.is_lost());
        } else if !rect.as_ref().is_some_and(touches) {
            s.visible += 1;
            s.visible_lost += usize::from(o.status.is_lost());
        }
        assert_eq!(o.status.is_lost(), o.position.is_none());
        if let Some(q) = o.position {
            let error = (q[0] - truth[0]).hypot(q[1] - truth[1]);
            if !rect.as_ref().is_some_and(touches) {
                s.worst_visible_px = s.worst_visible_px.max(error);
            } else if !rect.as_ref().is_some_and(inside) {
                s.worst_partial_px = s.worst_partial_px.max(error);
            }
        }
    }
    s
}

#[test]
fn occluded_points_are_flagged_lost_and_visible_ones_are_not() {
    let options = TrackOptions::default();
    let without = TrackOptions { occluded_above: f64::INFINITY, ..options };
    let (mut total, mut total_without) = (Score::default(), Score::default());
    for seed in [51, 64] {
        for kind in KINDS {
            let s = score(seed, kind, &options);
            let b = score(seed, kind, &without);
            println!(
                "seed {seed} {kind:?}: occluded {}/{} lost ({}/{} without the occlusion check), visible {}/{} lost ({} without), worst error {:.3} px visible, {:.3} px partly covered",
                s.occluded_lost, s.occluded, b.occluded_lost, b.occluded, s.visible_lost, s.visible, b.visible_lost, s.worst_visible_px, s.worst_partial_px
            );
            assert!(s.occluded > 0 && s.visible > 0, "{kind:?}: the sequence has both kinds of frame: {s:?}");
            assert_eq!(s.visible_lost, 0, "seed {seed} {kind:?}: a visible point was flagged lost: {s:?}");
            assert!(s.worst_visible_px < 0.2, "seed {seed} {kind:?}: a tracked position is off: {s:?}");
            assert!(s.worst_partial_px < 1.0, "seed {seed} {kind:?}: a partly covered position is off: {s:?}");
            for (sum, one) in [(&mut total, &s), (&mut total_without, &b)] {
                sum.occluded += one.occluded;
                sum.occluded_lost += one.occluded_lost;
                sum.visible += one.visible;
                sum.visible_lost += one.visible_lost;
            }
        }
    }
    let share = |s: &Score| s.occluded_lost as f64 / s.occluded as f64;
    println!(
        "all: {:.1} % of {} occluded frames flagged lost ({:.1} % without the occlusion check); {} of {} visible frames lost",
        100.0 * share(&total),
        total.occluded,
        100.0 * share(&total_without),
        total.visible_lost,
        total.visible
    );
    assert!(share(&total) >= 0.8, "{:.3} of the occluded frames flagged lost", share(&total));
}
