//! Deterministic SYNTHETIC archive shaped like the NEES-2009-0722 UCSD BNCS test data.
//!
//! Layout (a contract for the pipeline):
//! ```text
//! DIR/README.txt
//! DIR/manifest.json
//! DIR/<test>/DAQ1_floors.csv      200 Hz, g: Time,A4_EW,A4_NS,A4_UD,A5_EW,A5_NS,A5_UD
//! DIR/<test>/DAQ2_equipment.csv   256 Hz, g: Time,A5_EW_SYNC,UI3_TOP_EW,...,WSU1_TOP_EW
//! ```
//! Physics runs on a 1 kHz grid in DAQ1 time; each DAQ samples it by cubic interpolation
//! (all signals are band-limited below 30 Hz). DAQ2 time τ is DAQ1 time τ + clock_offset_s.
//!
//! Determinism: every random draw comes from SplitMix64 streams seeded from text labels, output
//! order is fixed, numbers are printed with explicit precision and manifest values are quantised
//! before use so the manifest states exactly what was applied.

use crate::demo::camera;
use crate::demo::cases;
use crate::demo::study::{Base, Equipment, FrequencySet, Motion, EQUIPMENT, MOTIONS};
use crate::physics::sdof::Sdof;
use crate::physics::shear_building::ShearBuilding;
use crate::signal::synthetic_motion::{
    band_limited_white_noise, filtered_noise, low_pass, resample, scale_to_peak, seed_from_label,
    synthetic_ground_motion, Envelope, GroundFilter, SplitMix64,
};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};

pub const GENERATOR_NAME: &str = "shakeflow demo-archive";
/// Bump whenever the bytes written change, so `is_current` rejects older archives.
pub const GENERATOR_VERSION: &str = "1.4.0";
pub const README_FILE: &str = "README.txt";
pub const MANIFEST_FILE: &str = "manifest.json";
pub const DAQ1_FILE: &str = "DAQ1_floors.csv";
pub const DAQ2_FILE: &str = "DAQ2_equipment.csv";
/// The camera projection technique's inputs: a calibrated camera's video of a rocking and a
/// rolling unit (see `demo::camera`).
pub const CPT_CONTROL_POINTS_FILE: &str = "cpt/control_points.csv";
pub const CPT_TRUTH_FILE: &str = "cpt/truth.csv";
pub const CPT_FRAMES_DIR: &str = "cpt/frames";
/// The study's tests (Table 1's twelve motions and two white-noise tests): the archive's default.
pub const STUDY_TESTS: usize = 14;
pub const DAQ1_RATE_HZ: u32 = 200;
pub const DAQ2_RATE_HZ: u32 = 256;
pub const DAQ1_COLUMNS: [&str; 7] = ["Time", "A4_EW", "A4_NS", "A4_UD", "A5_EW", "A5_NS", "A5_UD"];
pub const DAQ2_COLUMNS: [&str; 9] = [
    "Time",
    "A5_EW_SYNC",
    "UI3_TOP_EW",
    "MC2_TOP_EW",
    "PB1_TOP_EW",
    "PB2_TOP_EW",
    "PS1_TOP_EW",
    "PS2_TOP_EW",
    "WSU1_TOP_EW",
];

const HEADER_LINE_1: &str =
    "# NEES-2009-0722 UCSD BNCS - SYNTHETIC demo archive written by shakeflow demo-archive (not real data)";
const DAQ1_LINE_3: &str = "# daq: DAQ1 floor accelerometers (floor averages), sample_rate_hz: 200, units: g";
const DAQ1_LINE_4: &str = "# channels: A4_* = floor 4, A5_* = floor 5; EW = X (shaking direction), NS = Y, UD = Z (vertical); Time = DAQ1 time (s); sensor offsets not removed";
const DAQ2_LINE_3: &str = "# daq: DAQ2 equipment top accelerometers (E-W), sample_rate_hz: 256, units: g";
const DAQ2_LINE_4: &str = "# note: DAQ2 clock is NOT synchronised with DAQ1 (Time = DAQ2 time); A5_EW_SYNC = DAQ2's copy of floor-5 E-W for synchronisation; each <unit>_TOP_EW sensor carries a constant offset, slow drift and noise";

/// Physics grid (Hz): fine enough for accurate cubic interpolation to 200 and 256 Hz.
const SIM_RATE_HZ: f64 = 1000.0;
/// Extra simulated seconds beyond the DAQ1 record, covering DAQ2's clock offset (< 2.5 s).
const SIM_MARGIN_S: u32 = 3;
/// Building model: floors 2, 3, 4, 5 and roof (relative masses, storey stiffness shape).
const FLOOR_MASSES: [f64; 5] = [1.0, 1.0, 1.0, 1.0, 0.9];
const STOREY_STIFFNESS_SHAPE: [f64; 5] = [1.5, 1.35, 1.2, 1.05, 0.9];
const BASE_SLAB_MASS: f64 = 1.2;
const FIXED_BASE_PERIOD_S: f64 = 1.0;
const FIXED_BASE_DAMPING: f64 = 0.03;
const ISOLATED_PERIOD_S: f64 = 2.8;
const ISOLATOR_DAMPING: f64 = 0.12;
/// Equipment damping ratios (synthetic, 3-5 %), DAQ2 column order.
const EQUIPMENT_DAMPING: [f64; 7] = [0.04, 0.05, 0.03, 0.045, 0.035, 0.03, 0.05];
const WHITE_NOISE_PEAK_G: f64 = 0.04;
const FLOOR_NOISE_RMS_G: f64 = 0.0002;
const EQUIPMENT_NOISE_RMS_G: f64 = 0.0005;
/// Toppling impacts: test, unit, DAQ1 time (s), side. FB-4 PS2 at 30.9 s is the observed one.
const TOPPLES: [(&str, &str, f64, &str); 3] =
    [("FB-4", "PS2", 30.9, "right"), ("FB-5", "PS2", 26.4, "right"), ("FB-6", "WSU1", 22.7, "left")];
/// Impact spike: peak (g) and rise time (s) of an alpha pulse (t/τ)e^(1-t/τ); < 5 % after 70 ms.
const SPIKE_PEAK_G: f64 = 6.0;
const SPIKE_TAU_S: f64 = 0.012;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub generator: GeneratorInfo,
    pub project: String,
    pub synthetic: bool,
    pub units: String,
    pub daq1: DaqInfo,
    pub daq2: DaqInfo,
    /// How DAQ2 values relate to the physical signal (formula, in words).
    pub daq2_sensor_model: String,
    pub tests: Vec<TestEntry>,
    pub cpt: CptEntry,
    /// Every file except manifest.json, with its size.
    pub files: Vec<FileEntry>,
}

/// The truth behind the CPT video: the camera, the units' geometry, where the markers start.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CptEntry {
    /// Where the motions come from (the function to replace with the physics models).
    pub motion_source: String,
    pub width_px: usize,
    pub height_px: usize,
    pub frame_rate_hz: f64,
    pub frames: usize,
    pub image_noise_grey_levels: f64,
    pub control_point_noise_px: f64,
    /// P = K[R|t] with ‖(p31, p32, p33)‖ = 1, and the radial distortion used to render.
    pub projection: [[f64; 4]; 3],
    pub k1: f64,
    pub camera_centre_mm: [f64; 3],
    /// Planes a,b,c,d (aX + bY + cZ + d = 0, mm) of the rocking panel and of the cart top.
    pub rocking_plane: [f64; 4],
    pub rolling_plane: [f64; 4],
    /// True marker centres in the first frame (px), what a person would click.
    pub start_points: Vec<(String, [f64; 2])>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GeneratorInfo {
    pub name: String,
    pub version: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DaqInfo {
    pub file: String,
    pub sample_rate_hz: u32,
    pub columns: Vec<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TestEntry {
    pub id: String,
    /// "earthquake" or "white_noise".
    pub kind: String,
    pub input: String,
    pub event: String,
    /// "BI" or "FB".
    pub base: String,
    pub scale_percent: Option<f64>,
    pub table1_pia_g: Option<f64>,
    pub table1_piv_cm_s: Option<f64>,
    pub table1_pid_cm: Option<f64>,
    pub duration_s: f64,
    pub daq1_sample_rate_hz: u32,
    pub daq2_sample_rate_hz: u32,
    pub daq1_rows: usize,
    pub daq2_rows: usize,
    /// Peak |ground acceleration| achieved on the 1 kHz simulation grid (g).
    pub ground_pga_g: f64,
    pub building_period_s: f64,
    /// DAQ2 time 0 corresponds to this DAQ1 time (s).
    pub clock_offset_s: f64,
    /// "before FB-1" or "before FB-6" (Table 3 column used).
    pub frequency_set: String,
    /// Extra tests (`--tests N` above 14): the study motion this test varies and the factor on
    /// its peak input acceleration (its ground motion has its own seed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub variation_of: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub variation_scale: Option<f64>,
    pub floor_channels: Vec<FloorChannel>,
    pub equipment: Vec<EquipmentChannel>,
    pub toppling: Vec<Toppling>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FloorChannel {
    pub channel: String,
    pub offset_g: f64,
    pub noise_rms_g: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EquipmentChannel {
    pub unit: String,
    pub channel: String,
    pub floor: u8,
    pub frequency_hz: f64,
    pub damping_ratio: f64,
    pub offset_g: f64,
    pub drift_linear_g: f64,
    pub drift_quadratic_g: f64,
    pub noise_rms_g: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Toppling {
    pub unit: String,
    pub channel: String,
    /// Impact time in DAQ1 time (s).
    pub time_s: f64,
    /// "left" or "right"; the spike is positive for "right", negative for "left".
    pub side: String,
}

#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileEntry {
    /// Relative to the archive directory, '/'-separated.
    pub path: String,
    pub bytes: u64,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DemoArchiveReport {
    pub dir: PathBuf,
    pub test_ids: Vec<String>,
    /// All files written, manifest.json last.
    pub files: Vec<FileEntry>,
}

/// Writes the study's archive (its 14 tests) atomically; see [`write_demo_archive_tests`].
pub fn write_demo_archive(dir: &Path) -> io::Result<DemoArchiveReport> {
    write_demo_archive_tests(dir, STUDY_TESTS)
}

/// Writes an archive of `tests` tests (at least [`STUDY_TESTS`]: the study's, then variations of
/// its motions) atomically: into `<dir>.tmp-<pid>`, then renamed into place (an older archive at
/// `dir` is moved aside and removed). The temp directory is removed on error.
pub fn write_demo_archive_tests(dir: &Path, tests: usize) -> io::Result<DemoArchiveReport> {
    if tests < STUDY_TESTS {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{tests} tests: the archive holds at least the study's {STUDY_TESTS}"),
        ));
    }
    let name = dir
        .file_name()
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "archive path has no final component"))?
        .to_string_lossy()
        .into_owned();
    let parent = dir.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    fs::create_dir_all(parent)?;
    let pid = std::process::id();
    let tmp = parent.join(format!("{name}.tmp-{pid}"));
    if tmp.exists() {
        fs::remove_dir_all(&tmp)?;
    }
    fs::create_dir(&tmp)?;
    let files = match write_contents(&tmp, tests) {
        Ok(files) => files,
        Err(e) => {
            let _ = fs::remove_dir_all(&tmp);
            return Err(e);
        }
    };
    // Move an older archive aside first so the rename cannot fail on a non-empty target.
    let old = parent.join(format!("{name}.old-{pid}"));
    if dir.exists() {
        if let Err(e) = fs::rename(dir, &old) {
            let _ = fs::remove_dir_all(&tmp);
            return Err(e);
        }
    }
    if let Err(e) = fs::rename(&tmp, dir) {
        let _ = fs::remove_dir_all(&tmp);
        return Err(e);
    }
    if old.exists() {
        fs::remove_dir_all(&old)?;
    }
    Ok(DemoArchiveReport { dir: dir.to_path_buf(), test_ids: plans(tests).into_iter().map(|p| p.id).collect(), files })
}

/// [`is_current_tests`] for the study's archive (its 14 tests).
pub fn is_current(dir: &Path) -> bool {
    is_current_tests(dir, STUDY_TESTS)
}

/// True when `dir` holds a complete archive of `tests` tests written by this generator version:
/// the manifest parses, names this generator and version, lists exactly the expected tests and
/// files, and every listed file exists with the recorded size.
pub fn is_current_tests(dir: &Path, tests: usize) -> bool {
    let Ok(text) = fs::read_to_string(dir.join(MANIFEST_FILE)) else {
        return false;
    };
    let Ok(manifest) = serde_json::from_str::<Manifest>(&text) else {
        return false;
    };
    if manifest.generator.name != GENERATOR_NAME || manifest.generator.version != GENERATOR_VERSION {
        return false;
    }
    let ids: Vec<String> = plans(tests).into_iter().map(|p| p.id).collect();
    if manifest.tests.iter().map(|t| &t.id).ne(ids.iter()) {
        return false;
    }
    if manifest.files.iter().map(|f| f.path.clone()).ne(expected_files(&ids)) {
        return false;
    }
    manifest
        .files
        .iter()
        .all(|f| fs::metadata(dir.join(&f.path)).map(|m| m.is_file() && m.len() == f.bytes).unwrap_or(false))
}

fn expected_files(ids: &[String]) -> Vec<String> {
    let mut out = vec![README_FILE.to_string()];
    for id in ids {
        out.push(format!("{id}/{DAQ1_FILE}"));
        out.push(format!("{id}/{DAQ2_FILE}"));
    }
    out.push(CPT_CONTROL_POINTS_FILE.to_string());
    out.push(CPT_TRUTH_FILE.to_string());
    out.extend((0..camera::FRAMES).map(frame_file));
    out.extend(cases::file_names());
    out
}

fn frame_file(k: usize) -> String {
    format!("{CPT_FRAMES_DIR}/frame_{k:04}.png")
}

/// A file to write: its path in the archive and its bytes.
type NamedBytes = (String, Vec<u8>);

/// The CPT part of the archive: files (path, bytes) and the manifest entry.
fn cpt_contents() -> io::Result<(Vec<NamedBytes>, CptEntry)> {
    use rayon::prelude::*;
    let cam = camera::demo_camera();
    let motions = camera::demo_motions();
    let mut files = Vec::new();
    let mut text = String::from("point,X_mm,Y_mm,Z_mm,u_px,v_px\n");
    for p in camera::control_points(&cam) {
        let [x, y, z] = p.world_mm;
        let _ = writeln!(text, "{},{x:.1},{y:.1},{z:.1},{:.2},{:.2}", p.name, p.pixel[0], p.pixel[1]);
    }
    files.push((CPT_CONTROL_POINTS_FILE.to_string(), text.into_bytes()));
    let mut truth = String::from("time_s,theta_rad,x_mm,y_mm,yaw_rad\n");
    for k in 0..camera::FRAMES {
        let _ = writeln!(
            truth,
            "{:.6},{:.9},{:.6},{:.6},{:.9}",
            motions.time_s[k],
            motions.rocking_theta_rad[k],
            motions.rolling_x_mm[k],
            motions.rolling_y_mm[k],
            motions.rolling_yaw_rad[k]
        );
    }
    files.push((CPT_TRUTH_FILE.to_string(), truth.into_bytes()));
    let rays = camera::Rays::new(&cam);
    let background = camera::render_background(&cam, &rays);
    let frames: Vec<NamedBytes> = (0..camera::FRAMES)
        .into_par_iter()
        .map(|k| {
            let pixels = camera::render_frame(&cam, &rays, &background, motions.pose(k), k);
            Ok((frame_file(k), gray_png(&pixels, camera::WIDTH, camera::HEIGHT)?))
        })
        .collect::<io::Result<_>>()?;
    files.extend(frames);
    let entry = CptEntry {
        motion_source:
            "demo::camera::demo_motions (synthetic stand-in: free rocking of PS2 from 0.12 rad; smooth cart drift)"
                .into(),
        width_px: camera::WIDTH,
        height_px: camera::HEIGHT,
        frame_rate_hz: camera::FRAME_RATE_HZ,
        frames: camera::FRAMES,
        image_noise_grey_levels: camera::IMAGE_NOISE,
        control_point_noise_px: camera::CONTROL_POINT_NOISE_PX,
        projection: cam.projection(),
        k1: cam.k1,
        camera_centre_mm: cam.centre(),
        rocking_plane: [0.0, 1.0, 0.0, 0.0],
        rolling_plane: [0.0, 0.0, 1.0, -camera::CART_TOP_Z_MM],
        start_points: camera::marker_pixels(&cam, motions.pose(0)),
    };
    Ok((files, entry))
}

fn gray_png(pixels: &[u8], width: usize, height: usize) -> io::Result<Vec<u8>> {
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, width as u32, height as u32);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().map_err(io::Error::other)?;
    writer.write_image_data(pixels).map_err(io::Error::other)?;
    writer.finish().map_err(io::Error::other)?;
    Ok(out)
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    Earthquake(&'static Motion),
    WhiteNoise,
}

#[derive(Clone, Debug)]
struct TestPlan {
    id: String,
    kind: Kind,
    base: Base,
    frequency_set: FrequencySet,
    variation: Option<Variation>,
}

/// An extra test: a study motion at another scale, with its own ground-motion seed.
#[derive(Clone, Copy, Debug)]
struct Variation {
    /// 1, 2, …: the extra test's number (`V-0001`, …).
    number: usize,
    /// Factor on the motion's peak input acceleration, in [0.5, 1.5] (3 decimals).
    scale: f64,
}

/// The study's tests in chronological order (BI-1..BI-6, WN-1, FB-1..FB-5, WN-6, FB-6), then
/// `tests - 14` variations `V-0001`, … of Table 1's motions in turn.
fn plans(tests: usize) -> Vec<TestPlan> {
    let mut out = study_plans();
    for number in 1..=tests.saturating_sub(out.len()) {
        let m = &MOTIONS[(number - 1) % MOTIONS.len()];
        let late = matches!(m.id, "FB-4" | "FB-5" | "FB-6");
        let frequency_set = if late { FrequencySet::BeforeFb6 } else { FrequencySet::BeforeFb1 };
        let scale = quantize(SplitMix64::new(seed_from_label(&format!("variation:{number}"))).uniform(0.5, 1.5), 3);
        out.push(TestPlan {
            id: format!("V-{number:04}"),
            kind: Kind::Earthquake(m),
            base: m.base,
            frequency_set,
            variation: Some(Variation { number, scale }),
        });
    }
    out
}

fn study_plans() -> Vec<TestPlan> {
    let mut out = Vec::new();
    for m in &MOTIONS {
        if m.id == "FB-1" {
            out.push(TestPlan {
                id: "WN-1".into(),
                kind: Kind::WhiteNoise,
                base: Base::Fixed,
                frequency_set: FrequencySet::BeforeFb1,
                variation: None,
            });
        }
        if m.id == "FB-6" {
            out.push(TestPlan {
                id: "WN-6".into(),
                kind: Kind::WhiteNoise,
                base: Base::Fixed,
                frequency_set: FrequencySet::BeforeFb6,
                variation: None,
            });
        }
        let late = matches!(m.id, "FB-4" | "FB-5" | "FB-6");
        let frequency_set = if late { FrequencySet::BeforeFb6 } else { FrequencySet::BeforeFb1 };
        out.push(TestPlan { id: m.id.into(), kind: Kind::Earthquake(m), base: m.base, frequency_set, variation: None });
    }
    out
}

/// Record length and excitation shape per input record (whole seconds; 3 s quiet before the
/// motion, the envelope ends 10 s before the record ends to leave free vibration).
struct Shape {
    duration_s: u32,
    envelope: Envelope,
    /// None: band-limited white noise.
    filter: Option<GroundFilter>,
}

fn ground_filter(fg_hz: f64, zeta_g: f64) -> GroundFilter {
    GroundFilter { fg_hz, zeta_g, fc_hz: 0.2, zeta_c: 0.7, f_pass_hz: 20.0, f_stop_hz: 25.0 }
}

fn shape(kind: Kind) -> Shape {
    let env = |rise_end_s, strong_end_s, decay_tau_s, end_s| Envelope {
        start_s: 3.0,
        rise_end_s,
        strong_end_s,
        decay_tau_s,
        end_s,
        end_taper_s: 3.0,
    };
    let quake = |duration_s, envelope, fg, zg| Shape { duration_s, envelope, filter: Some(ground_filter(fg, zg)) };
    match kind {
        Kind::WhiteNoise => Shape {
            duration_s: 120,
            envelope: Envelope {
                start_s: 1.0,
                rise_end_s: 3.0,
                strong_end_s: 117.0,
                decay_tau_s: 1.0,
                end_s: 119.0,
                end_taper_s: 2.0,
            },
            filter: None,
        },
        Kind::Earthquake(m) => match m.record {
            "CNP" => quake(48, env(5.5, 14.0, 4.0, 38.0), 2.5, 0.6),
            "LAC" => quake(48, env(5.0, 13.0, 4.0, 38.0), 4.0, 0.6),
            "SP" => quake(73, env(13.0, 43.0, 5.0, 63.0), 2.0, 0.6),
            "ICA" => quake(68, env(12.0, 42.0, 5.0, 58.0), 1.6, 0.5),
            "DEN" => quake(83, env(9.0, 36.0, 6.0, 73.0), 1.8, 0.55),
            other => unreachable!("no shape for record {other}"),
        },
    }
}

/// Index of building DOF for a floor (2..5 or 6 = roof).
fn floor_dof(base: Base, floor: u8) -> usize {
    match base {
        Base::Fixed => usize::from(floor) - 2,
        Base::Isolated => usize::from(floor) - 1,
    }
}

/// Absolute acceleration of `floor` (2..5, 6 = roof) of the demo building under a ground
/// acceleration sampled at `dt` (same units out as in), as the archive's floor records are made;
/// for checks that put real records through the demo building.
pub fn floor_response(base: Base, floor: u8, ground: &[f64], dt: f64) -> Vec<f64> {
    building(base).absolute_accelerations(ground, dt).swap_remove(floor_dof(base, floor))
}

fn building(base: Base) -> ShearBuilding {
    let fb = ShearBuilding::fixed_base(&FLOOR_MASSES, &STOREY_STIFFNESS_SHAPE, FIXED_BASE_PERIOD_S, FIXED_BASE_DAMPING);
    match base {
        Base::Fixed => fb,
        Base::Isolated => ShearBuilding::base_isolated(BASE_SLAB_MASS, &fb, ISOLATOR_DAMPING, ISOLATED_PERIOD_S),
    }
}

/// Round to `decimals` places; dividing by an exact power of ten yields the double nearest the
/// decimal, so the manifest prints it short and exactly as applied.
fn quantize(x: f64, decimals: i32) -> f64 {
    let scale = 10f64.powi(decimals);
    (x * scale).round() / scale
}

fn peak(x: &[f64]) -> f64 {
    x.iter().fold(0.0_f64, |m, v| m.max(v.abs()))
}

/// Clock offset in whole microseconds within [0.4, 2.5) s, at least 5 % of a sample away from
/// any multiple of either sample period.
fn clock_offset_us(rng: &mut SplitMix64) -> u64 {
    loop {
        let us = 400_000 + rng.next_u64() % 2_100_000;
        let far = |rate: u64| {
            let frac = (us * rate) % 1_000_000;
            (50_000..=950_000).contains(&frac)
        };
        if far(u64::from(DAQ1_RATE_HZ)) && far(u64::from(DAQ2_RATE_HZ)) {
            return us;
        }
    }
}

struct GeneratedTest {
    entry: TestEntry,
    daq1_csv: String,
    daq2_csv: String,
    /// The physical floor motion at DAQ1's rate in m/s² (no sensor offset or noise): floors 4
    /// and 5, each (E-W, vertical), for the diagnosis cases.
    floors_mps2: [[Vec<f64>; 2]; 2],
}

fn generate_test(plan: &TestPlan) -> GeneratedTest {
    let id = plan.id.as_str();
    let sh = shape(plan.kind);
    let dt = 1.0 / SIM_RATE_HZ;
    let n_sim = (sh.duration_s + SIM_MARGIN_S) as usize * SIM_RATE_HZ as usize;
    let stream = |purpose: &str| seed_from_label(&format!("{id}:{purpose}"));
    // Unit-peak noise with this test's spectral shape and envelope (cross-talk components).
    let shaped_noise = |seed: u64| match &sh.filter {
        Some(f) => synthetic_ground_motion(seed, n_sim, dt, f, &sh.envelope, 1.0),
        None => band_limited_white_noise(seed, n_sim, dt, 0.5, 25.0, &sh.envelope, 1.0),
    };

    // Ground motion: earthquake shape seeded by record name, so e.g. ICA50/100/140 are the same
    // record at different scales, as on the real table; a variation has its own seed and scale.
    let ground = match (plan.kind, &sh.filter) {
        (Kind::Earthquake(m), Some(f)) => {
            let (label, pia_g) = match plan.variation {
                None => (format!("record:{}", m.record), m.pia_g),
                Some(v) => (format!("record:{}:variation:{}", m.record, v.number), m.pia_g * v.scale),
            };
            synthetic_ground_motion(seed_from_label(&label), n_sim, dt, f, &sh.envelope, pia_g)
        }
        _ => band_limited_white_noise(stream("ground"), n_sim, dt, 0.5, 25.0, &sh.envelope, WHITE_NOISE_PEAK_G),
    };
    let model = building(plan.base);
    let response = model.absolute_accelerations(&ground, dt);

    // Floor channels (physical, 1 kHz): EW from the model, NS small cross-talk, UD ~1/10 of EW
    // (one vertical record with a higher-frequency Kanai–Tajimi shape, scaled per floor).
    let mut vertical = filtered_noise(stream("vertical"), n_sim, dt, &ground_filter(8.0, 0.5), &sh.envelope);
    scale_to_peak(&mut vertical, 1.0);
    let mut floors: Vec<[Vec<f64>; 3]> = Vec::new();
    for floor in [4u8, 5] {
        let ew = response[floor_dof(plan.base, floor)].clone();
        let p = peak(&ew);
        let ns_extra = shaped_noise(stream(&format!("ns{floor}")));
        let ns: Vec<f64> = ew.iter().zip(&ns_extra).map(|(e, x)| 0.05 * e + 0.04 * p * x).collect();
        let ud: Vec<f64> = vertical.iter().map(|v| 0.1 * p * v).collect();
        floors.push([ew, ns, ud]);
    }
    let floor_of = |f: u8| &floors[usize::from(f - 4)];

    // Equipment tops (physical, 1 kHz, DAQ1 time).
    let mut topples = Vec::new();
    let mut tops: Vec<Vec<f64>> = Vec::new();
    for (eq, &zeta) in EQUIPMENT.iter().zip(&EQUIPMENT_DAMPING) {
        let fl = floor_of(eq.floor);
        let mut top = Sdof::new(eq.frequency_hz(plan.frequency_set), zeta).absolute_acceleration(&fl[0], dt);
        if let Some(&(_, _, t0, side)) = TOPPLES.iter().find(|t| t.0 == id && t.1 == eq.id) {
            apply_topple(&mut top, &fl[2], dt, t0, side);
            topples.push(Toppling { unit: eq.id.into(), channel: channel_name(eq), time_s: t0, side: side.into() });
        }
        // Keeps the impact spike (and the switch to vertical motion) below 30 Hz.
        low_pass(&mut top, dt, 25.0, 30.0);
        tops.push(top);
    }

    // DAQ1: sample at 200 Hz, add offsets and noise.
    let mut sensor_rng = SplitMix64::new(stream("sensors"));
    let mut noise_rng = SplitMix64::new(stream("noise"));
    let duration = f64::from(sh.duration_s);
    let n1 = (sh.duration_s * DAQ1_RATE_HZ) as usize;
    let mut floor_channels = Vec::new();
    let mut daq1_cols: Vec<Vec<f64>> = Vec::new();
    for (fi, floor) in [4u8, 5].iter().enumerate() {
        for (ci, dir) in ["EW", "NS", "UD"].iter().enumerate() {
            let offset = quantize(sensor_rng.sign() * sensor_rng.uniform(0.0005, 0.002), 6);
            let mut col = resample(&floors[fi][ci], dt, 0.0, f64::from(DAQ1_RATE_HZ), n1);
            col.iter_mut().for_each(|v| *v += offset + FLOOR_NOISE_RMS_G * noise_rng.normal());
            daq1_cols.push(col);
            floor_channels.push(FloorChannel {
                channel: format!("A{floor}_{dir}"),
                offset_g: offset,
                noise_rms_g: FLOOR_NOISE_RMS_G,
            });
        }
    }

    // DAQ2: DAQ2 time τ samples the physical signal at DAQ1 time τ + clock offset.
    let clock_offset = clock_offset_us(&mut sensor_rng) as f64 * 1e-6;
    let n2 = (sh.duration_s * DAQ2_RATE_HZ) as usize;
    let mut equipment = Vec::new();
    // As on the real test, DAQ2 also records a copy of a floor channel, so the two clocks can be
    // aligned without relying on the equipment's own (resonant, phase-shifted) response.
    let mut sync = resample(&floors[1][0], dt, clock_offset, f64::from(DAQ2_RATE_HZ), n2);
    sync.iter_mut().for_each(|v| *v += FLOOR_NOISE_RMS_G * noise_rng.normal());
    let mut daq2_cols: Vec<Vec<f64>> = vec![sync];
    for ((eq, &zeta), top) in EQUIPMENT.iter().zip(&EQUIPMENT_DAMPING).zip(&tops) {
        let offset = quantize(sensor_rng.sign() * sensor_rng.uniform(0.01, 0.03), 6);
        let drift_end = sensor_rng.sign() * sensor_rng.uniform(0.01, 0.02);
        let q = sensor_rng.uniform(0.2, 0.8);
        let lin = quantize((1.0 - q) * drift_end, 6);
        let quad = quantize(q * drift_end, 6);
        let mut col = resample(top, dt, clock_offset, f64::from(DAQ2_RATE_HZ), n2);
        for (k, v) in col.iter_mut().enumerate() {
            let s = k as f64 / f64::from(DAQ2_RATE_HZ) / duration;
            *v += offset + lin * s + quad * s * s + EQUIPMENT_NOISE_RMS_G * noise_rng.normal();
        }
        daq2_cols.push(col);
        equipment.push(EquipmentChannel {
            unit: eq.id.into(),
            channel: channel_name(eq),
            floor: eq.floor,
            frequency_hz: eq.frequency_hz(plan.frequency_set),
            damping_ratio: zeta,
            offset_g: offset,
            drift_linear_g: lin,
            drift_quadratic_g: quad,
            noise_rms_g: EQUIPMENT_NOISE_RMS_G,
        });
    }

    let scale_percent = |m: &Motion| plan.variation.map_or(m.scale_percent, |v| quantize(m.scale_percent * v.scale, 3));
    let (kind, input, event, motion) = match plan.kind {
        Kind::Earthquake(m) => {
            ("earthquake", m.input.to_string(), format!("{} ({} %)", m.event_site, scale_percent(m)), Some(m))
        }
        Kind::WhiteNoise => (
            "white_noise",
            "WN".to_string(),
            format!("band-limited white noise 0.5-25 Hz, {WHITE_NOISE_PEAK_G} g peak ({})", plan.frequency_set.label()),
            None,
        ),
    };
    let line2 = format!("# test: {id}, input: {input}, event: {event}, base: {}", plan.base.code());
    let daq1_csv = csv(&[HEADER_LINE_1, &line2, DAQ1_LINE_3, DAQ1_LINE_4], &DAQ1_COLUMNS, DAQ1_RATE_HZ, &daq1_cols);
    let daq2_csv = csv(&[HEADER_LINE_1, &line2, DAQ2_LINE_3, DAQ2_LINE_4], &DAQ2_COLUMNS, DAQ2_RATE_HZ, &daq2_cols);

    let entry = TestEntry {
        id: id.into(),
        kind: kind.into(),
        input,
        event: motion.map_or_else(|| event.clone(), |m| m.event_site.to_string()),
        base: plan.base.code().into(),
        scale_percent: motion.map(scale_percent),
        // Table 1 states the study's tests only.
        table1_pia_g: motion.filter(|_| plan.variation.is_none()).map(|m| m.pia_g),
        table1_piv_cm_s: motion.filter(|_| plan.variation.is_none()).map(|m| m.piv_cm_s),
        table1_pid_cm: motion.filter(|_| plan.variation.is_none()).map(|m| m.pid_cm),
        duration_s: duration,
        daq1_sample_rate_hz: DAQ1_RATE_HZ,
        daq2_sample_rate_hz: DAQ2_RATE_HZ,
        daq1_rows: n1,
        daq2_rows: n2,
        ground_pga_g: quantize(peak(&ground), 9),
        building_period_s: quantize(model.fundamental_period(), 6),
        clock_offset_s: clock_offset,
        frequency_set: plan.frequency_set.label().into(),
        variation_of: plan.variation.and(motion).map(|m| m.id.to_string()),
        variation_scale: plan.variation.map(|v| v.scale),
        floor_channels,
        equipment,
        toppling: topples,
    };
    let physical = |fi: usize, ci: usize| -> Vec<f64> {
        resample(&floors[fi][ci], dt, 0.0, f64::from(DAQ1_RATE_HZ), n1).iter().map(|g| g * crate::units::G0).collect()
    };
    let floors_mps2 = [[physical(0, 0), physical(0, 2)], [physical(1, 0), physical(1, 2)]];
    GeneratedTest { entry, daq1_csv, daq2_csv, floors_mps2 }
}

fn channel_name(eq: &Equipment) -> String {
    format!("{}_TOP_EW", eq.id)
}

/// From the impact on, the toppled unit's sensor lies on its side: an impact spike followed by
/// the floor's vertical acceleration (its sensitive axis is now vertical).
fn apply_topple(top: &mut [f64], floor_ud: &[f64], dt: f64, t0: f64, side: &str) {
    let sign = if side == "right" { 1.0 } else { -1.0 };
    let i0 = (t0 / dt).ceil() as usize;
    for (i, (v, ud)) in top.iter_mut().zip(floor_ud).enumerate().skip(i0) {
        let x = (i as f64 * dt - t0) / SPIKE_TAU_S;
        *v = ud + sign * SPIKE_PEAK_G * x * (1.0 - x).exp();
    }
}

/// CSV text: comment lines, column row, then rows of time (6 decimals) and values ({:.6e}).
fn csv(comments: &[&str], columns: &[&str], rate_hz: u32, cols: &[Vec<f64>]) -> String {
    let rows = cols.first().map_or(0, Vec::len);
    let mut s = String::with_capacity(rows * (12 + 14 * cols.len()) + 1024);
    for c in comments {
        s.push_str(c);
        s.push('\n');
    }
    s.push_str(&columns.join(","));
    s.push('\n');
    for k in 0..rows {
        let _ = write!(s, "{:.6}", k as f64 / f64::from(rate_hz));
        for col in cols {
            let _ = write!(s, ",{:.6e}", col[k]);
        }
        s.push('\n');
    }
    s
}

fn readme(tests: &[TestEntry]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "NEES-2009-0722 UCSD BNCS - SYNTHETIC demo archive");
    let _ = writeln!(s, "Written by {GENERATOR_NAME} {GENERATOR_VERSION}. THIS IS NOT REAL DATA.");
    s.push_str(
        "\nIt imitates the layout of the 2012 UCSD five-story building test (base-isolated BI-*, then
fixed-base FB-*; hospital equipment on floors 4 and 5) so shakeflow's pipeline can be run end to
end. Motions are Kanai-Tajimi/Clough-Penzien filtered noise scaled to Table 1's peak input
acceleration; floors come from a linear 5-storey shear building (T1 = 1.0 s fixed-base, 2.8 s
isolated); equipment tops are linear oscillators at Table 3's frequencies.

Layout
  README.txt                 this file
  manifest.json              generator, and per test the TRUE values: clock offset, sensor offsets
                             and drifts, equipment frequencies and damping, toppling events
  <test>/DAQ1_floors.csv     floor accelerometers, 200 Hz, g
                             Time,A4_EW,A4_NS,A4_UD,A5_EW,A5_NS,A5_UD
  <test>/DAQ2_equipment.csv  equipment top accelerometers (E-W), 256 Hz, g
                             Time,A5_EW_SYNC,UI3_TOP_EW,MC2_TOP_EW,PB1_TOP_EW,PB2_TOP_EW,PS1_TOP_EW,PS2_TOP_EW,WSU1_TOP_EW
                             (A5_EW_SYNC: DAQ2's own copy of floor-5 E-W, for clock synchronisation)

Each CSV has 4 comment lines starting with '# ', a column row, then data rows; Time in seconds
(6 decimals) from 0, values in g as {:.6e}. EW = X (shaking direction), NS = Y, UD = Z (vertical).
Floor channels carry small constant offsets. Equipment channels carry offsets, a slow drift
(linear + quadratic in time) and noise: value(tau) = signal(tau + clock_offset_s) + offset_g
+ drift_linear_g*(tau/duration_s) + drift_quadratic_g*(tau/duration_s)^2 + noise.

Clocks: DAQ2 is not synchronised with DAQ1. DAQ2 time 0 is DAQ1 time clock_offset_s (0.4-2.5 s,
per test, in manifest.json). A toppled unit shows an impact spike, then about 1/10 amplitude
(its sensor then records the floor's vertical motion).

Camera projection technique (cpt/)
  cpt/control_points.csv     14 surveyed points: point,X_mm,Y_mm,Z_mm,u_px,v_px (pixels measured
                             with 0.5 px noise; world mm, X = E-W, Y = N-S, Z up, floor at Z = 0)
  cpt/frames/frame_NNNN.png  960x540 grayscale video at 30 fps (105 frames) from that camera: a
                             rocking stretcher panel in the plane Y = 0 (markers M1 low, M2 high) and
                             a rolling cart top at Z = 900 mm (markers M3, M4), rendered at 8x8 samples
                             per pixel with 1 grey level of noise
  cpt/truth.csv              the motion that made the frames: time_s,theta_rad (rocking, positive:
                             top toward +X),x_mm,y_mm,yaw_rad (cart centre from rest, yaw about +Z)

Tests (chronological)
",
    );
    for t in tests {
        let _ = writeln!(s, "  {:<5} {:<7} {} {:>4} s  {}", t.id, t.input, t.base, t.duration_s, t.event);
    }
    s
}

/// Writes all files into `dir` (which exists and is empty); returns them with sizes,
/// manifest.json last.
fn write_contents(dir: &Path, tests: usize) -> io::Result<Vec<FileEntry>> {
    use rayon::prelude::*;
    // Tests are generated and written in parallel, each as soon as it is made (an archive of
    // hundreds of tests is not held in memory); the floors the cases need are kept.
    type Written = (TestEntry, Vec<FileEntry>, Option<[[Vec<f64>; 2]; 2]>);
    let written: Vec<Written> = plans(tests)
        .par_iter()
        .map(|plan| {
            let g = generate_test(plan);
            let id = &plan.id;
            fs::create_dir(dir.join(id))?;
            let mut entries = Vec::new();
            for (name, text) in [(DAQ1_FILE, g.daq1_csv), (DAQ2_FILE, g.daq2_csv)] {
                fs::write(dir.join(id).join(name), &text)?;
                entries.push(FileEntry { path: format!("{id}/{name}"), bytes: text.len() as u64 });
            }
            Ok((g.entry, entries, plan.variation.is_none().then_some(g.floors_mps2)))
        })
        .collect::<io::Result<_>>()?;
    let mut tests = Vec::new();
    let mut test_files = Vec::new();
    let mut floors = std::collections::BTreeMap::new();
    for (entry, entries, floors_mps2) in written {
        if let Some(f) = floors_mps2 {
            floors.insert(entry.id.clone(), f);
        }
        tests.push(entry);
        test_files.extend(entries);
    }
    let readme_text = readme(&tests);
    fs::write(dir.join(README_FILE), &readme_text)?;
    let mut files = vec![FileEntry { path: README_FILE.into(), bytes: readme_text.len() as u64 }];
    files.extend(test_files);
    let (cpt_files, cpt) = cpt_contents()?;
    fs::create_dir_all(dir.join(CPT_FRAMES_DIR))?;
    for (path, bytes) in cpt_files {
        fs::write(dir.join(&path), &bytes)?;
        files.push(FileEntry { path, bytes: bytes.len() as u64 });
    }
    let case_files = cases::case_files(|test, floor| {
        let [ew, ud] = &floors[test][usize::from(floor - 4)];
        (ew.clone(), ud.clone())
    })
    .map_err(io::Error::other)?;
    for (path, bytes) in case_files {
        if let Some(parent) = Path::new(&path).parent() {
            fs::create_dir_all(dir.join(parent))?;
        }
        fs::write(dir.join(&path), &bytes)?;
        files.push(FileEntry { path, bytes: bytes.len() as u64 });
    }
    let manifest = Manifest {
        generator: GeneratorInfo { name: GENERATOR_NAME.into(), version: GENERATOR_VERSION.into() },
        project: "NEES-2009-0722 UCSD BNCS".into(),
        synthetic: true,
        units: "g".into(),
        daq1: DaqInfo { file: DAQ1_FILE.into(), sample_rate_hz: DAQ1_RATE_HZ, columns: DAQ1_COLUMNS.map(String::from).to_vec() },
        daq2: DaqInfo { file: DAQ2_FILE.into(), sample_rate_hz: DAQ2_RATE_HZ, columns: DAQ2_COLUMNS.map(String::from).to_vec() },
        daq2_sensor_model: "value(tau) = signal(tau + clock_offset_s) + offset_g + drift_linear_g*(tau/duration_s) + drift_quadratic_g*(tau/duration_s)^2 + noise(noise_rms_g); tau = DAQ2 time, signal in DAQ1 time".into(),
        tests,
        cpt,
        files: files.clone(),
    };
    let mut text = serde_json::to_string_pretty(&manifest).map_err(io::Error::other)?;
    text.push('\n');
    fs::write(dir.join(MANIFEST_FILE), &text)?;
    files.push(FileEntry { path: MANIFEST_FILE.into(), bytes: text.len() as u64 });
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plan_order_and_frequency_sets() {
        let p = plans(STUDY_TESTS);
        let ids: Vec<&str> = p.iter().map(|t| t.id.as_str()).collect();
        assert_eq!(
            ids,
            [
                "BI-1", "BI-2", "BI-3", "BI-4", "BI-5", "BI-6", "WN-1", "FB-1", "FB-2", "FB-3", "FB-4", "FB-5", "WN-6",
                "FB-6"
            ]
        );
        for t in &p {
            let late = matches!(t.id.as_str(), "FB-4" | "FB-5" | "FB-6" | "WN-6");
            assert_eq!(t.frequency_set == FrequencySet::BeforeFb6, late, "{}", t.id);
        }
    }

    #[test]
    fn extra_tests_vary_the_study_motions_in_turn() {
        let p = plans(STUDY_TESTS + 30);
        let study: Vec<String> = plans(STUDY_TESTS).into_iter().map(|t| t.id).collect();
        assert_eq!(p[..STUDY_TESTS].iter().map(|t| &t.id).collect::<Vec<_>>(), study.iter().collect::<Vec<_>>());
        assert!(p[..STUDY_TESTS].iter().all(|t| t.variation.is_none()));
        let mut scales = Vec::new();
        for (k, t) in p[STUDY_TESTS..].iter().enumerate() {
            let v = t.variation.expect("an extra test is a variation");
            assert_eq!((t.id.as_str(), v.number), (format!("V-{:04}", k + 1).as_str(), k + 1));
            let Kind::Earthquake(m) = t.kind else { panic!("{} is not an earthquake", t.id) };
            assert_eq!(m.id, MOTIONS[k % MOTIONS.len()].id, "{}", t.id);
            assert_eq!(t.base, m.base);
            assert!((0.5..=1.5).contains(&v.scale) && v.scale == quantize(v.scale, 3), "{}", v.scale);
            scales.push(v.scale);
        }
        // Seeded per number: not one scale repeated.
        scales.dedup();
        assert!(scales.len() > 20, "{scales:?}");
        assert_eq!(plans(STUDY_TESTS + 30)[STUDY_TESTS + 7].variation.unwrap().scale, scales[7]);
    }

    #[test]
    fn clock_offsets_are_in_range_and_off_grid() {
        for p in plans(40) {
            let us = clock_offset_us(&mut SplitMix64::new(seed_from_label(&p.id)));
            assert!((400_000..2_500_000).contains(&us));
            assert_ne!((us * 200) % 1_000_000, 0);
            assert_ne!((us * 256) % 1_000_000, 0);
        }
    }

    #[test]
    fn topple_spike_is_sharp() {
        let dt = 0.001;
        let mut top = vec![0.5; 3000];
        let ud = vec![0.01; 3000];
        apply_topple(&mut top, &ud, dt, 1.0, "right");
        low_pass(&mut top, dt, 25.0, 30.0);
        let spike = top[1000..1100].iter().fold(0.0_f64, |m, v| m.max(*v));
        assert!(spike > 2.0, "spike {spike}");
        // 100 ms after impact the channel is back near the vertical-motion level.
        assert!(top[1100..1500].iter().all(|v| v.abs() < 0.2), "slow decay");
    }
}
