//! The demo archive's video: one calibrated camera (known P and k₁) filming a rocking unit
//! (a PS2-like stretcher's side panel rocking in the vertical plane Y = 0) and a rolling unit
//! (an MC2-like cart's top at Z = 900 mm drifting and turning), with bullseye markers on both,
//! plus the control points a person would survey (with pixel noise) and the motion's truth.
//!
//! Frames are rendered at 8 × 8 samples per pixel and area-downsampled where the units move (a
//! static background is rendered once the same way), then noise is added and rounded to 8 bits.
//! The renderer takes the motions as plain sampled series ([`DemoMotions`]); where they come
//! from is decided in one place, [`demo_motions`].

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::physics::rocking::{simulate, Block, Excitation, Options, Shape};
use crate::physics::rolling;
use crate::signal::synthetic_motion::{seed_from_label, SplitMix64};
use crate::vision::camera::{Camera, Intrinsics};
use crate::vision::linalg::{self, Mat3, Vec3};

pub const WIDTH: usize = 960;
pub const HEIGHT: usize = 540;
pub const FRAME_RATE_HZ: f64 = 30.0;
pub const FRAMES: usize = 105;
const SAMPLES: usize = 8;
/// Camera noise (grey levels, Gaussian) and control-point pixel noise (px per coordinate).
pub const IMAGE_NOISE: f64 = 1.0;
pub const CONTROL_POINT_NOISE_PX: f64 = 0.5;

/// Rocking unit (PS2, Table 5 rectangle): side panel B × H in the plane Y = 0, base centred at X.
pub const ROCKING_BASE_X_MM: f64 = -700.0;
pub const ROCKING_B_MM: f64 = 349.0;
pub const ROCKING_H_MM: f64 = 1082.0;
/// Marker centres on the panel, (x from the base centre, height), mm.
pub const ROCKING_MARKERS: [(&str, [f64; 2]); 2] = [("M1", [0.0, 250.0]), ("M2", [0.0, 850.0])];
/// Rolling unit (MC2, Table 4): top 2a × 2b at height Z, centred at (X, Y) at rest.
pub const CART_CENTRE_MM: [f64; 2] = [650.0, 500.0];
pub const CART_TOP_Z_MM: f64 = 900.0;
pub const CART_SIZE_MM: [f64; 2] = [650.0, 900.0];
/// Markers on the cart top, symmetric about its centre so their midpoint is the centre.
pub const CART_MARKERS: [(&str, [f64; 2]); 2] = [("M3", [-220.0, 0.0]), ("M4", [220.0, 0.0])];
const WALL_Y_MM: f64 = 2500.0;
/// Panel: a darker frame band along its edges, a flat grey inside; bullseye rings of this width.
const PANEL_FRAME_MM: f64 = 18.0;
const PANEL_GREY: f64 = 200.0;
const PANEL_RING_MM: f64 = 11.0;
const CART_GREY: f64 = 80.0;
const CART_RING_MM: f64 = 15.0;

/// The motions the frames show, sampled at the frame times.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoMotions {
    pub time_s: Vec<f64>,
    /// Rocking angle of the rocking unit (positive: about its +X corner, top toward +X).
    pub rocking_theta_rad: Vec<f64>,
    /// Rolling unit's centre displacement from rest and its yaw (about +Z, counter-clockwise seen from above).
    pub rolling_x_mm: Vec<f64>,
    pub rolling_y_mm: Vec<f64>,
    pub rolling_yaw_rad: Vec<f64>,
}

/// THE source of the demo's motions: PS2 rocking freely after a release from 0.12 rad, by the
/// toppling model (`physics::rocking`), and the cart MC2 rolling on the shaking floor, by the
/// rolling model (`physics::rolling`).
pub fn demo_motions() -> DemoMotions {
    let time_s = frame_times();
    let rocking_theta_rad = free_rocking(0.12, &time_s);
    let cart = rolling_cart(&time_s);
    DemoMotions {
        time_s,
        rocking_theta_rad,
        rolling_x_mm: cart.x_m.iter().map(|x| 1000.0 * x).collect(),
        rolling_y_mm: cart.y_m.iter().map(|y| 1000.0 * y).collect(),
        rolling_yaw_rad: cart.yaw_rad,
    }
}

/// The metal cart MC2 (Table 4) on unlocked casters under a few seconds of two-component floor
/// shaking (2.0 m/s² at 0.7 Hz along x, 0.8 m/s² at 0.5 Hz along y; cosines, so the floor's
/// velocity has no mean and the cart does not drift out of view), by the rolling model, sampled
/// at the frame times.
fn rolling_cart(times: &[f64]) -> rolling::Response {
    let table = rolling::preset("MC2").expect("MC2 is a Table 4 unit");
    let cart = table.cart(rolling::Cart::default_trail_m(table.wheel_diameter_m), 0.02);
    let friction = table.friction(1e-4, rolling::FrictionLaw::Regularised);
    let (yaw0_rad, steer0_rad) = table.initial_pose();
    let ax: Vec<f64> = times.iter().map(|&t| 2.0 * (std::f64::consts::TAU * 0.7 * t).cos()).collect();
    let ay: Vec<f64> = times.iter().map(|&t| 0.8 * (std::f64::consts::TAU * 0.5 * t).cos()).collect();
    let excitation = rolling::Excitation { t0_s: times[0], dt_s: 1.0 / FRAME_RATE_HZ, ax_mps2: &ax, ay_mps2: &ay };
    let options = rolling::Options { yaw0_rad, steer0_rad, ..rolling::Options::default() };
    rolling::simulate(&cart, &friction, &excitation, &options).expect("MC2 under a smooth floor motion")
}

pub fn frame_times() -> Vec<f64> {
    (0..FRAMES).map(|k| k as f64 / FRAME_RATE_HZ).collect()
}

/// PS2 (the study's Table 5 rectangle, as drawn) released from rest at `theta0` on a still floor,
/// by the toppling model: rocking by Eq. 22, impacts at θ = 0 with Eq. 24's restitution.
fn free_rocking(theta0: f64, times: &[f64]) -> Vec<f64> {
    let block = Block::new(
        Shape::Rectangular { b_m: ROCKING_B_MM / 1000.0, h_m: ROCKING_H_MM / 1000.0, f: 0.085 },
        150.0,
        9.81,
    )
    .expect("PS2 is a valid block");
    let still = vec![0.0; times.len()];
    let excitation =
        Excitation { t0_s: times[0], dt_s: 1.0 / FRAME_RATE_HZ, horizontal_mps2: &still, vertical_mps2: None };
    let options = Options { initial_theta_rad: theta0, ..Options::default() };
    simulate(&block, &excitation, &options).expect("free rocking of a valid block").theta_rad
}

/// The demo camera: 960 × 540, f = 700 px, mild barrel distortion, ceiling-mounted and tilted.
pub fn demo_camera() -> Camera {
    let k = Intrinsics { fx: 700.0, fy: 700.0, skew: 0.0, cx: 481.3, cy: 268.7 };
    Camera::look_at(k, [150.0, -3600.0, 3000.0], [0.0, 300.0, 550.0], -0.04, 0.0)
}

/// One sample of both units' poses.
#[derive(Debug, Clone, Copy)]
pub struct Pose {
    pub theta_rad: f64,
    pub cart: [f64; 3],
}

impl DemoMotions {
    pub fn pose(&self, k: usize) -> Pose {
        Pose {
            theta_rad: self.rocking_theta_rad[k],
            cart: [self.rolling_x_mm[k], self.rolling_y_mm[k], self.rolling_yaw_rad[k]],
        }
    }
}

/// World position of a point of the rocking panel given in body coordinates (x from the base
/// centre, height), rotated by θ about the corner it pivots on.
pub fn rocking_point(body: [f64; 2], theta: f64) -> Vec3 {
    let pivot = if theta >= 0.0 { ROCKING_B_MM / 2.0 } else { -ROCKING_B_MM / 2.0 };
    let (x, z) = (body[0] - pivot, body[1]);
    // Rotation about +Y by θ: +Z tips toward +X.
    [ROCKING_BASE_X_MM + pivot + x * theta.cos() + z * theta.sin(), 0.0, -x * theta.sin() + z * theta.cos()]
}

/// World position of a point of the cart top given in body coordinates (from its centre).
pub fn cart_point(body: [f64; 2], cart: [f64; 3]) -> Vec3 {
    let (c, s) = (cart[2].cos(), cart[2].sin());
    [
        CART_CENTRE_MM[0] + cart[0] + c * body[0] - s * body[1],
        CART_CENTRE_MM[1] + cart[1] + s * body[0] + c * body[1],
        CART_TOP_Z_MM,
    ]
}

/// A plane patch as a homography from undistorted normalised image coordinates to its own 2D
/// coordinates (mm).
struct PlaneMap {
    inverse: Mat3,
}

impl PlaneMap {
    /// The plane through `origin` spanned by unit vectors `e1`, `e2`.
    fn new(camera: &Camera, origin: Vec3, e1: Vec3, e2: Vec3) -> PlaneMap {
        let r = &camera.rotation;
        let a = linalg::mat3_vec(r, &e1);
        let b = linalg::mat3_vec(r, &e2);
        let o = linalg::mat3_vec(r, &origin);
        let t = camera.translation;
        let h = [[a[0], b[0], o[0] + t[0]], [a[1], b[1], o[1] + t[1]], [a[2], b[2], o[2] + t[2]]];
        PlaneMap { inverse: linalg::inverse3(&h).expect("planes in view are not seen edge-on") }
    }

    /// Plane coordinates of the ray through (x, y); None when the plane is behind the camera there.
    fn hit(&self, x: f64, y: f64) -> Option<[f64; 2]> {
        let m = &self.inverse;
        let w = m[2][0] * x + m[2][1] * y + m[2][2];
        if !(w > 0.0) {
            return None;
        }
        Some([(m[0][0] * x + m[0][1] * y + m[0][2]) / w, (m[1][0] * x + m[1][1] * y + m[1][2]) / w])
    }
}

fn bullseye(r: f64, scale: f64, dark: f64, light: f64) -> Option<f64> {
    let ring = (r / scale) as usize;
    (ring < 4).then_some(if ring.is_multiple_of(2) { dark } else { light })
}

struct Scene {
    floor: PlaneMap,
    wall: PlaneMap,
    panel: PlaneMap,
    cart: PlaneMap,
}

impl Scene {
    fn new(camera: &Camera, pose: Pose) -> Scene {
        let theta = pose.theta_rad;
        let origin = rocking_point([0.0, 0.0], theta);
        let panel = PlaneMap::new(camera, origin, [theta.cos(), 0.0, -theta.sin()], [theta.sin(), 0.0, theta.cos()]);
        let (c, s) = (pose.cart[2].cos(), pose.cart[2].sin());
        let cart = PlaneMap::new(camera, cart_point([0.0, 0.0], pose.cart), [c, s, 0.0], [-s, c, 0.0]);
        Scene {
            floor: PlaneMap::new(camera, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
            wall: PlaneMap::new(camera, [0.0, WALL_Y_MM, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
            panel,
            cart,
        }
    }

    fn background(&self, x: f64, y: f64) -> f64 {
        if let Some([fx, fy]) = self.floor.hit(x, y).filter(|p| p[1] < WALL_Y_MM) {
            // 400 mm tiles with darker grout lines.
            let (tx, ty) = (fx.rem_euclid(400.0), fy.rem_euclid(400.0));
            let grout = tx < 10.0 || ty < 10.0;
            let parity = ((fx / 400.0).floor() + (fy / 400.0).floor()).rem_euclid(2.0);
            return if grout { 70.0 } else { 125.0 + 18.0 * parity };
        }
        match self.wall.hit(x, y) {
            Some([wx, wz]) => {
                let band = if (1200.0..1350.0).contains(&wz) { -40.0 } else { 0.0 };
                165.0 + band + 12.0 * (wx / 900.0).sin()
            }
            None => 150.0,
        }
    }

    /// The grey level seen along the ray through undistorted normalised coordinates (x, y).
    fn shade(&self, x: f64, y: f64) -> f64 {
        if let Some([bx, bz]) = self.panel.hit(x, y) {
            if bx.abs() <= ROCKING_B_MM / 2.0 && (0.0..=ROCKING_H_MM).contains(&bz) {
                for (_, m) in ROCKING_MARKERS {
                    if let Some(v) = bullseye((bx - m[0]).hypot(bz - m[1]), PANEL_RING_MM, 25.0, 235.0) {
                        return v;
                    }
                }
                let frame = bx.abs() > ROCKING_B_MM / 2.0 - PANEL_FRAME_MM
                    || !(PANEL_FRAME_MM..=ROCKING_H_MM - PANEL_FRAME_MM).contains(&bz);
                return if frame { 95.0 } else { PANEL_GREY };
            }
        }
        if let Some([cx, cy]) = self.cart.hit(x, y) {
            if cx.abs() <= CART_SIZE_MM[0] / 2.0 && cy.abs() <= CART_SIZE_MM[1] / 2.0 {
                for (_, m) in CART_MARKERS {
                    if let Some(v) = bullseye((cx - m[0]).hypot(cy - m[1]), CART_RING_MM, 235.0, 30.0) {
                        return v;
                    }
                }
                return CART_GREY;
            }
        }
        self.background(x, y)
    }
}

/// Undistorted normalised coordinates at pixel corners ((W + 1) × (H + 1)), so sub-samples are
/// bilinear in them: the distortion is smooth at the pixel scale.
pub struct Rays {
    corners: Vec<[f64; 2]>,
}

impl Rays {
    pub fn new(camera: &Camera) -> Rays {
        let corners = (0..=HEIGHT)
            .flat_map(|j| (0..=WIDTH).map(move |i| (i, j)))
            .map(|(i, j)| {
                camera
                    .normalised_of_pixel(i as f64 - 0.5, j as f64 - 0.5)
                    .expect("the image is inside the distortion model")
            })
            .collect();
        Rays { corners }
    }

    fn corners_of(&self, i: usize, j: usize) -> [[f64; 2]; 4] {
        let c = |di: usize, dj: usize| self.corners[(j + dj) * (WIDTH + 1) + i + di];
        [c(0, 0), c(1, 0), c(0, 1), c(1, 1)]
    }

    /// The mean of 8 × 8 samples over the pixel.
    fn pixel(&self, scene: &Scene, i: usize, j: usize) -> f64 {
        let [c00, c10, c01, c11] = self.corners_of(i, j);
        let mut sum = 0.0;
        for b in 0..SAMPLES {
            let fy = (b as f64 + 0.5) / SAMPLES as f64;
            for a in 0..SAMPLES {
                let fx = (a as f64 + 0.5) / SAMPLES as f64;
                let lerp = |k: usize| {
                    (1.0 - fy) * ((1.0 - fx) * c00[k] + fx * c10[k]) + fy * ((1.0 - fx) * c01[k] + fx * c11[k])
                };
                sum += scene.shade(lerp(0), lerp(1));
            }
        }
        sum / (SAMPLES * SAMPLES) as f64
    }
}

/// What a pixel's footprint covers, decided from its corners alone: every sample lies in the
/// convex hull of the corners, which the plane's homography maps inside the bounding box of the
/// mapped corners. So a box clear of edges and markers means a flat grey, exactly.
enum Cover {
    Background,
    Flat(f64),
    Mixed,
}

impl Scene {
    fn cover(&self, corners: &[[f64; 2]; 4]) -> Cover {
        let plane_box = |map: &PlaneMap| -> Option<[f64; 4]> {
            let hits: Vec<[f64; 2]> = corners.iter().map(|c| map.hit(c[0], c[1])).collect::<Option<_>>()?;
            let (lo, hi) = (
                |k: usize| hits.iter().map(|h| h[k]).fold(f64::INFINITY, f64::min),
                |k: usize| hits.iter().map(|h| h[k]).fold(f64::NEG_INFINITY, f64::max),
            );
            Some([lo(0), lo(1), hi(0), hi(1)])
        };
        let (Some(panel), Some(cart)) = (plane_box(&self.panel), plane_box(&self.cart)) else { return Cover::Mixed };
        let apart = |b: [f64; 4], r: [f64; 4]| b[2] < r[0] || b[0] > r[2] || b[3] < r[1] || b[1] > r[3];
        let within = |b: [f64; 4], r: [f64; 4]| b[0] >= r[0] && b[2] <= r[2] && b[1] >= r[1] && b[3] <= r[3];
        let clear = |b: [f64; 4], markers: &[(&str, [f64; 2])], radius: f64| {
            markers.iter().all(|(_, m)| apart(b, [m[0] - radius, m[1] - radius, m[0] + radius, m[1] + radius]))
        };
        let (hb, h) = (ROCKING_B_MM / 2.0, ROCKING_H_MM);
        // The panel is drawn over everything, so it is decided first.
        if within(panel, [-hb + PANEL_FRAME_MM, PANEL_FRAME_MM, hb - PANEL_FRAME_MM, h - PANEL_FRAME_MM])
            && clear(panel, &ROCKING_MARKERS, 4.0 * PANEL_RING_MM)
        {
            return Cover::Flat(PANEL_GREY);
        }
        if !apart(panel, [-hb, 0.0, hb, h]) {
            return Cover::Mixed;
        }
        let (ha, hc) = (CART_SIZE_MM[0] / 2.0, CART_SIZE_MM[1] / 2.0);
        if within(cart, [-ha, -hc, ha, hc]) && clear(cart, &CART_MARKERS, 4.0 * CART_RING_MM) {
            return Cover::Flat(CART_GREY);
        }
        if !apart(cart, [-ha, -hc, ha, hc]) {
            return Cover::Mixed;
        }
        Cover::Background
    }
}

/// The background without the units, 8 × 8 samples per pixel (rendered once).
pub fn render_background(camera: &Camera, rays: &Rays) -> Vec<f64> {
    let scene = Scene::new(camera, Pose { theta_rad: 0.0, cart: [0.0; 3] });
    let empty =
        Scene { panel: PlaneMap { inverse: [[0.0; 3]; 3] }, cart: PlaneMap { inverse: [[0.0; 3]; 3] }, ..scene };
    (0..HEIGHT)
        .into_par_iter()
        .flat_map_iter(|j| (0..WIDTH).map(move |i| (i, j)))
        .map(|(i, j)| rays.pixel(&empty, i, j))
        .collect()
}

/// Pixels the units may cover in this pose: the bounding box of their projected outlines.
fn unit_boxes(camera: &Camera, pose: Pose) -> Vec<[usize; 4]> {
    let (hb, h) = (ROCKING_B_MM / 2.0, ROCKING_H_MM);
    let panel: Vec<Vec3> =
        [[-hb, 0.0], [hb, 0.0], [hb, h], [-hb, h]].iter().map(|&b| rocking_point(b, pose.theta_rad)).collect();
    let (cx, cy) = (CART_SIZE_MM[0] / 2.0, CART_SIZE_MM[1] / 2.0);
    let cart: Vec<Vec3> =
        [[-cx, -cy], [cx, -cy], [cx, cy], [-cx, cy]].iter().map(|&b| cart_point(b, pose.cart)).collect();
    [panel, cart]
        .iter()
        .map(|corners| {
            let pixels: Vec<[f64; 2]> =
                corners.iter().map(|c| camera.project(c).expect("the units are in front of the camera")).collect();
            // Distortion bends straight edges: a few pixels of margin cover the bulge.
            let lo = |k: usize| pixels.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min) - 4.0;
            let hi = |k: usize| pixels.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max) + 4.0;
            [
                lo(0).max(0.0) as usize,
                lo(1).max(0.0) as usize,
                (hi(0).ceil() as usize).min(WIDTH),
                (hi(1).ceil() as usize).min(HEIGHT),
            ]
        })
        .collect()
}

/// Frame `k` as 8-bit gray pixels (row-major, WIDTH × HEIGHT).
pub fn render_frame(camera: &Camera, rays: &Rays, background: &[f64], pose: Pose, k: usize) -> Vec<u8> {
    let scene = Scene::new(camera, pose);
    let boxes = unit_boxes(camera, pose);
    let mut rng = SplitMix64::new(seed_from_label(&format!("cpt:frame:{k}")));
    let mut pixels = Vec::with_capacity(WIDTH * HEIGHT);
    for j in 0..HEIGHT {
        for i in 0..WIDTH {
            let near_a_unit = boxes.iter().any(|b| i >= b[0] && i < b[2] && j >= b[1] && j < b[3]);
            let value = if near_a_unit {
                match scene.cover(&rays.corners_of(i, j)) {
                    Cover::Background => background[j * WIDTH + i],
                    Cover::Flat(grey) => grey,
                    Cover::Mixed => rays.pixel(&scene, i, j),
                }
            } else {
                background[j * WIDTH + i]
            };
            pixels.push((value + IMAGE_NOISE * rng.normal()).round().clamp(0.0, 255.0) as u8);
        }
    }
    pixels
}

/// A surveyed control point: name, world position (mm), and the pixel a person measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurveyedPoint {
    pub name: String,
    pub world_mm: [f64; 3],
    pub pixel: [f64; 2],
}

/// 14 control points on the floor's tile corners, the back wall and two posts, with pixel noise.
pub fn control_points(camera: &Camera) -> Vec<SurveyedPoint> {
    let world: [[f64; 3]; 14] = [
        [-1600.0, -800.0, 0.0],
        [-400.0, -1200.0, 0.0],
        [800.0, -800.0, 0.0],
        [1600.0, -400.0, 0.0],
        [-1200.0, 1200.0, 0.0],
        [1600.0, 1600.0, 0.0],
        [-2000.0, WALL_Y_MM, 400.0],
        [-800.0, WALL_Y_MM, 1300.0],
        [400.0, WALL_Y_MM, 800.0],
        [1600.0, WALL_Y_MM, 1200.0],
        [2400.0, WALL_Y_MM, 300.0],
        [0.0, WALL_Y_MM, 1400.0],
        [-1500.0, 400.0, 1300.0],
        [1800.0, 200.0, 1100.0],
    ];
    let mut rng = SplitMix64::new(seed_from_label("cpt:control-points"));
    world
        .iter()
        .enumerate()
        .map(|(k, w)| {
            let [u, v] = camera.project(w).expect("control points are in front of the camera");
            let noisy = [u + CONTROL_POINT_NOISE_PX * rng.normal(), v + CONTROL_POINT_NOISE_PX * rng.normal()];
            SurveyedPoint {
                name: format!("C{}", k + 1),
                world_mm: *w,
                pixel: noisy.map(|p| (p * 100.0).round() / 100.0),
            }
        })
        .collect()
}

/// True pixel positions of the four markers in frame `k`.
pub fn marker_pixels(camera: &Camera, pose: Pose) -> Vec<(String, [f64; 2])> {
    let rocking = ROCKING_MARKERS.iter().map(|(n, b)| (n.to_string(), rocking_point(*b, pose.theta_rad)));
    let cart = CART_MARKERS.iter().map(|(n, b)| (n.to_string(), cart_point(*b, pose.cart)));
    rocking.chain(cart).map(|(n, w)| (n, camera.project(&w).expect("markers are in view"))).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rocking_decays_with_impacts_and_never_topples() {
        let m = demo_motions();
        let theta = &m.rocking_theta_rad;
        let crossings = theta.windows(2).filter(|w| w[0].signum() != w[1].signum()).count();
        assert!(crossings >= 4, "{crossings} impacts in {} s", FRAMES as f64 / FRAME_RATE_HZ);
        let alpha = (ROCKING_B_MM / ROCKING_H_MM).atan();
        assert!(theta.iter().all(|t| t.abs() < alpha));
        let late = theta[FRAMES - 30..].iter().fold(0.0_f64, |a, t| a.max(t.abs()));
        assert!(late < 0.12 * 0.8, "decays: late amplitude {late}");
    }

    #[test]
    fn units_and_control_points_are_in_view() {
        let camera = demo_camera();
        let m = demo_motions();
        for k in [0, FRAMES / 2, FRAMES - 1] {
            for (name, [u, v]) in marker_pixels(&camera, m.pose(k)) {
                assert!(
                    (40.0..WIDTH as f64 - 40.0).contains(&u) && (40.0..HEIGHT as f64 - 40.0).contains(&v),
                    "{name} at {u}, {v}"
                );
            }
        }
        for p in control_points(&camera) {
            assert!(
                (5.0..WIDTH as f64 - 5.0).contains(&p.pixel[0]) && (5.0..HEIGHT as f64 - 5.0).contains(&p.pixel[1]),
                "{p:?}"
            );
        }
    }
}
