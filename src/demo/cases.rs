//! Diagnosis cases in the demo archive: a unit of the study on a floor of the archive, recorded
//! by a top accelerometer (200 Hz, σ 0.02 m/s²) and a camera (θ at 30 Hz, σ 0.002 rad, one
//! dropout), with one effect concealed — the study's own stories where it told one (WSU1 lost
//! its water bottles in FB-4 and fell onto PS1 in FB-5; the beds' ~3 Hz frames) — and two
//! rolling units on unlocked casters (`model: rolling`: MC2 losing shelves and bottles in FB-5,
//! PS1 carrying the fallen WSU1 in FB-5; the platform's displacement and yaw at 30 Hz). Made with
//! shakeflow's models, so they show the diagnosis at work; `make prove` checks it on cases from
//! an independent generator. `cases/truth/` says what was concealed; the tool never reads it.

use std::fmt::Write as _;

use crate::physics::rocking::{self, Block, Excitation, IsolatedBase, MassChange, Obstacle, Options, Response, Shape};
use crate::signal::synthetic_motion::{seed_from_label, SplitMix64};

pub const CASES_DIR: &str = "cases";
const FS_HZ: f64 = 200.0;
const CAMERA_HZ: f64 = 30.0;
const ACCEL_NOISE_MPS2: f64 = 0.02;
const CAMERA_NOISE_RAD: f64 = 0.002;
/// The overturn impact as a top accelerometer records it: a damped 30 Hz ring of 5 g.
const SPIKE_G: f64 = 5.0;
const SPIKE_HZ: f64 = 30.0;
const SPIKE_DECAY_S: f64 = 0.012;

#[derive(Clone, Copy, Debug)]
enum Effect {
    None,
    SensorTilt,
    MassChange,
    Obstacle,
    Flexibility,
}

impl Effect {
    fn name(self) -> &'static str {
        match self {
            Effect::None => "none",
            Effect::SensorTilt => "sensor_tilt",
            Effect::MassChange => "mass_change",
            Effect::Obstacle => "obstacle_impact",
            Effect::Flexibility => "flexibility",
        }
    }
}

struct Plan {
    id: &'static str,
    unit: &'static str,
    test: &'static str,
    floor: u8,
    effect: Effect,
    story: &'static str,
}

const PLANS: [Plan; 5] = [
    Plan {
        id: "PS2_FB-2",
        unit: "PS2",
        test: "FB-2",
        floor: 5,
        effect: Effect::None,
        story: "the locked stretcher as the model describes it",
    },
    Plan {
        id: "PS2_FB-3",
        unit: "PS2",
        test: "FB-3",
        floor: 5,
        effect: Effect::SensorTilt,
        story: "its top accelerometer is bolted to the frame and turns with it",
    },
    Plan {
        id: "WSU1_FB-4",
        unit: "WSU1",
        test: "FB-4",
        floor: 5,
        effect: Effect::MassChange,
        story: "the shelving loses its water bottles while it rocks (the study's FB-4)",
    },
    Plan {
        id: "WSU1_FB-5",
        unit: "WSU1",
        test: "FB-5",
        floor: 5,
        effect: Effect::Obstacle,
        story: "the shelving rocks into the stretcher beside it (the study's FB-5, onto PS1)",
    },
    Plan {
        id: "PB1_FB-3",
        unit: "PB1",
        test: "FB-3",
        floor: 4,
        effect: Effect::Flexibility,
        story: "the bed's frame is a 3.1 Hz spring, not a rigid block (Table 3)",
    },
];

/// Files of the cases, relative to the archive.
pub fn file_names() -> Vec<String> {
    let ids: Vec<&str> = PLANS.iter().map(|p| p.id).chain(ROLLING_PLANS.iter().map(|p| p.id)).collect();
    let mut out = Vec::new();
    for id in &ids {
        for name in
            [crate::io::case::EQUIPMENT, crate::io::case::FLOOR, crate::io::case::ACCEL, crate::io::case::CAMERA]
        {
            out.push(format!("{CASES_DIR}/{id}/{name}"));
        }
    }
    out.extend(ids.iter().map(|id| format!("{CASES_DIR}/truth/{id}.yaml")));
    out
}

/// Why a case cannot be made: its plan does not fit (an unknown unit, one that never moves), or
/// a model refused to run it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CaseError {
    #[error("{0}")]
    Plan(String),
    #[error(transparent)]
    Physics(#[from] crate::physics::error::PhysicsError),
    /// The rolling diagnosis model's refusal of the nominal run.
    #[error(transparent)]
    Diagnose(#[from] crate::diagnose::error::DiagnoseError),
}

/// Every case's files (path in the archive, bytes), in `file_names()` order. `floor` gives the
/// physical floor motion (m/s², 200 Hz from t = 0: horizontal E-W, vertical) of a test and floor.
pub fn case_files(floor: impl Fn(&str, u8) -> (Vec<f64>, Vec<f64>)) -> Result<Vec<(String, Vec<u8>)>, CaseError> {
    let mut cases = Vec::new();
    let mut truths = Vec::new();
    for plan in &PLANS {
        let (ax, az) = floor(plan.test, plan.floor);
        let (files, truth) = make_case(plan, &ax, &az)?;
        cases.extend(files);
        truths.push((format!("{CASES_DIR}/truth/{}.yaml", plan.id), truth.into_bytes()));
    }
    for plan in &ROLLING_PLANS {
        let (ax, _) = floor(plan.test, plan.floor);
        let (files, truth) = rolling_case(plan, &ax)?;
        cases.extend(files);
        truths.push((format!("{CASES_DIR}/truth/{}.yaml", plan.id), truth.into_bytes()));
    }
    cases.extend(truths);
    Ok(cases)
}

fn make_case(plan: &Plan, ax: &[f64], az: &[f64]) -> Result<(Vec<(String, Vec<u8>)>, String), CaseError> {
    let (shape, mass) = rocking::preset(plan.unit).ok_or(CaseError::Plan("unknown unit".into()))?;
    let block = Block::new(shape, mass, 9.81)?;
    let excitation = Excitation { t0_s: 0.0, dt_s: 1.0 / FS_HZ, horizontal_mps2: ax, vertical_mps2: Some(az) };
    let baseline = rocking::simulate(&block, &excitation, &Options::default())?;
    let first_uplift =
        baseline.events.iter().find(|e| e.kind == rocking::EventKind::Uplift).map(|e| (e.time_s, e.side));
    let (options, parameters) = match plan.effect {
        Effect::None | Effect::SensorTilt => (Options::default(), String::new()),
        Effect::MassChange => {
            let (t0, _) = first_uplift.ok_or(CaseError::Plan("the unit never rocks".into()))?;
            let t0 = t0 + 0.4;
            // 20 % of the mass at 0.8 H leaves: the centre of mass drops.
            let (hc, h) = (block.cm_height_m, block.height_m);
            let hc_after = (hc - 0.2 * 0.8 * h) / 0.8;
            let Shape::Rectangular { b_m, h_m, .. } = shape else { return Err(CaseError::Plan("a rectangle".into())) };
            let after = Block::new(Shape::Rectangular { b_m, h_m, f: hc_after / h - 0.5 }, 0.8 * mass, 9.81)?;
            (
                Options { mass_change: Some(MassChange { time_s: t0, after }), ..Options::default() },
                format!(
                    "  t0_s: {t0:.4}\n  mass_fraction_lost: 0.2\n  lost_mass_height_m: {:.4}\n  f_after: {:.6}\n",
                    0.8 * h,
                    hc_after / h - 0.5
                ),
            )
        }
        Effect::Obstacle => {
            let (_, side) = first_uplift.ok_or(CaseError::Plan("the unit never rocks".into()))?;
            let angle = 0.6 * block.alpha_rad;
            (
                Options { obstacle: Some(Obstacle { side, angle_rad: angle, restitution: 0.5 }), ..Options::default() },
                format!("  side: {side}\n  angle_rad: {angle:.6}\n  restitution: 0.5\n"),
            )
        }
        Effect::Flexibility => (
            Options {
                isolated_base: Some(IsolatedBase { period_s: 1.0 / 3.1, damping_ratio: 0.04, mass_ratio: None }),
                ..Options::default()
            },
            "  frequency_hz: 3.1\n  damping_ratio: 0.04\n".to_string(),
        ),
    };
    let truth = rocking::simulate(&block, &excitation, &options)?;
    let mut top = match plan.effect {
        Effect::SensorTilt => tilted(&truth, block.g_mps2),
        _ => truth.top_ax_mps2.clone(),
    };
    let mut rng = SplitMix64::new(seed_from_label(&format!("case:{}", plan.id)));
    if let Some((t, _)) = truth.overturn {
        for (k, v) in top.iter_mut().enumerate() {
            let s = k as f64 / FS_HZ - t;
            if s >= 0.0 {
                *v += SPIKE_G * 9.81 * (-s / SPIKE_DECAY_S).exp() * (std::f64::consts::TAU * SPIKE_HZ * s).sin();
            }
        }
    }
    let n = ax.len();
    let mut floor_csv = String::from("time_s,ax_mps2,ay_mps2,az_mps2\n");
    let mut accel_csv = String::from("time_s,top_ax_mps2\n");
    for k in 0..n {
        let t = k as f64 / FS_HZ;
        let _ = writeln!(floor_csv, "{t:.3},{:.6},0.000000,{:.6}", ax[k], az[k]);
        let _ = writeln!(accel_csv, "{t:.3},{:.5}", top[k] + ACCEL_NOISE_MPS2 * rng.normal());
    }
    // The camera: θ at 30 Hz, with one dropout of a second.
    let camera_csv = camera_csv("time_s,theta_rad\n", n, 1.0, &mut rng, |t, k, w, dropped, rng| {
        let theta = truth.theta_rad[k] * (1.0 - w) + truth.theta_rad[k + 1] * w + CAMERA_NOISE_RAD * rng.normal();
        if dropped {
            format!("{t:.4},\n")
        } else {
            format!("{t:.4},{theta:.6}\n")
        }
    });
    let Shape::Rectangular { b_m, h_m, f } = shape else {
        return Err(CaseError::Plan("the demo cases are rectangles".into()));
    };
    let equipment = format!(
        "name: {unit}\ndescription: {what} ({test}, floor {floor}); synthetic demo case\nshape: rectangular\nB_m: {b_m}\nH_m: {h_m}\nf: {f}\nmass_kg: {mass}\ng_mps2: 9.81\nsensors:\n  accelerometer:\n    file: observed_accel.csv\n    position: top centre (x=0, height H)\n    rate_hz: {FS_HZ}\n    noise_sd_mps2: {ACCEL_NOISE_MPS2}\n  camera:\n    file: observed_cpt.csv\n    quantity: rotation theta, rad\n    rate_hz: {CAMERA_HZ}\n    noise_sd_rad: {CAMERA_NOISE_RAD}\nconventions: theta > 0 = rotation about the +x corner, top moving toward +x\n",
        unit = plan.unit,
        what = match plan.unit {
            "PS2" => "locked stretcher",
            "PB1" => "locked patient bed",
            _ => "free-standing wire shelving",
        },
        test = plan.test,
        floor = plan.floor,
    );
    let files = case_folder(plan.id, [equipment, floor_csv, accel_csv, camera_csv]);
    let overturn = truth.overturn.map_or("null".to_string(), |(t, s)| format!("{{time_s: {t:.4}, side: {s}}}"));
    let truth_yaml = format!(
        "case_id: {id}\nstory: {story}\neffect: {effect}\nexpected_verdict: {effect}\nparameters:{params}\nfirst_uplift_s: {uplift}\noverturn: {overturn}\nmade_by: shakeflow's own models (src/demo/cases.rs); make prove uses an independent generator\n",
        id = plan.id,
        story = plan.story,
        effect = plan.effect.name(),
        params = if parameters.is_empty() { " {}\n".to_string() } else { format!("\n{parameters}") },
        uplift = first_uplift.map_or("null".to_string(), |u| format!("{:.4}", u.0)),
    );
    Ok((files, truth_yaml))
}

/// What a top accelerometer fixed to the body reads: its axis turns with θ and senses gravity.
fn tilted(r: &Response, g: f64) -> Vec<f64> {
    (0..r.theta_rad.len())
        .map(|k| {
            let (sin, cos) = r.theta_rad[k].sin_cos();
            r.sensor_ax_mps2[k] * cos - (r.sensor_az_mps2[k] + g) * sin
        })
        .collect()
}

/// A case folder's four files (equipment, floor, accelerometer, camera), relative to the archive.
fn case_folder(id: &str, [equipment, floor, accel, camera]: [String; 4]) -> Vec<(String, Vec<u8>)> {
    use crate::io::case::{ACCEL, CAMERA, EQUIPMENT, FLOOR};
    [(EQUIPMENT, equipment), (FLOOR, floor), (ACCEL, accel), (CAMERA, camera)]
        .into_iter()
        .map(|(name, text)| (format!("{CASES_DIR}/{id}/{name}"), text.into_bytes()))
        .collect()
}

/// A camera's CSV at `CAMERA_HZ` over a record of `n` floor samples, with one dropout of
/// `dropout_s` somewhere in the record's middle 60 %: `line(t, k, w, dropped, rng)` writes the
/// frame at time t (between floor samples k and k + 1, weight w on k + 1), drawing its noise even
/// when the frame is dropped, so that the noise of every frame is the same with or without one.
fn camera_csv(
    header: &str,
    n: usize,
    dropout_s: f64,
    rng: &mut SplitMix64,
    mut line: impl FnMut(f64, usize, f64, bool, &mut SplitMix64) -> String,
) -> String {
    let duration = (n - 1) as f64 / FS_HZ;
    let dropout = rng.uniform(0.2, 0.8) * duration;
    let mut csv = String::from(header);
    let mut j = 0;
    while (j as f64) / CAMERA_HZ <= duration {
        let t = j as f64 / CAMERA_HZ;
        let x = t * FS_HZ;
        let k = (x.floor() as usize).min(n - 2);
        csv.push_str(&line(t, k, x - k as f64, (dropout..dropout + dropout_s).contains(&t), rng));
        j += 1;
    }
    csv
}

/// The study's two rolling stories, as rolling cases (`model: rolling`, the contract of
/// ../shared/cases/rolling_demo): a unit on unlocked casters (Table 4) whose mass changes off
/// its centre while it rolls. The shake table moves E-W only: the floor's Y record is zero.
struct RollingPlan {
    id: &'static str,
    unit: &'static str,
    test: &'static str,
    floor: u8,
    /// The mass lost (< 0) or gained, and where on the platform (body axes, m).
    dm_kg: f64,
    at_m: [f64; 2],
    /// Over how long the mass goes (s; 0: at once).
    ramp_s: f64,
    story: &'static str,
}

const ROLLING_PLANS: [RollingPlan; 2] = [
    RollingPlan {
        id: "MC2_FB-5",
        unit: "MC2",
        test: "FB-5",
        floor: 4,
        dm_kg: -50.0,
        at_m: [0.25, 0.38],
        ramp_s: 0.4,
        story: "the metal cart strikes the bed beside it and loses shelves and water bottles from one corner over 0.4 s (the study's FB-5)",
    },
    RollingPlan {
        id: "PS1_FB-5",
        unit: "PS1",
        test: "FB-5",
        floor: 5,
        dm_kg: 43.6,
        at_m: [0.6, 0.2],
        ramp_s: 0.0,
        story: "the wire shelving WSU1 (43.6 kg) falls onto the stretcher and rides on it off its centre (the study's FB-5)",
    },
];
/// The mass changes this long after the cart has first moved 3 cm.
const ROLLING_ONSET_AFTER_S: f64 = 1.0;
/// How much of the test a rolling case keeps (s).
const ROLLING_RECORD_S: f64 = 30.0;
const CAMERA_NOISE_M: f64 = 0.0015;

fn rolling_case(plan: &RollingPlan, ax: &[f64]) -> Result<(Vec<(String, Vec<u8>)>, String), CaseError> {
    use crate::diagnose::rolling::RollingCase;
    use crate::physics::rolling::{self as rolling, Alteration, FrictionLaw, MassChange as Change};
    let table = rolling::preset(plan.unit).ok_or(CaseError::Plan("unknown rolling unit".into()))?;
    let cart = table.cart(rolling::Cart::default_trail_m(table.wheel_diameter_m), rolling::DEFAULT_SWIVEL_ARM_M);
    let friction = table.friction(rolling::DEFAULT_FRICTION_EPS_MPS, FrictionLaw::Regularised);
    let (yaw0_rad, steer0_rad) = table.initial_pose();
    // At the diagnosis's tolerances, as the archive was made before the converged defaults.
    let options = rolling::Options {
        yaw0_rad,
        steer0_rad,
        method: crate::diagnose::rolling::METHOD,
        ..rolling::Options::default()
    };
    // The floor as floor.csv prints it, so that the tool reads back exactly what moved the cart.
    // The first ROLLING_RECORD_S of the test: the strong motion and some seconds after.
    let kept = ax.len().min((ROLLING_RECORD_S * FS_HZ) as usize + 1);
    let ax: Vec<f64> = ax[..kept].iter().map(|v| (v * 1e6).round() / 1e6).collect();
    let n = ax.len();
    let case = RollingCase {
        name: plan.id.into(),
        cart,
        friction,
        options,
        t0_s: 0.0,
        dt_s: 1.0 / FS_HZ,
        floor_ax_mps2: ax.clone(),
        floor_ay_mps2: vec![0.0; n],
        accel: None,
        camera: None,
        accel_noise_mps2: ACCEL_NOISE_MPS2,
        camera_noise_m: CAMERA_NOISE_M,
        camera_noise_rad: CAMERA_NOISE_RAD,
        uncertain: Vec::new(),
    };
    let nominal = case.nominal()?;
    let moved = (0..n)
        .find(|&k| nominal.x_m[k].hypot(nominal.y_m[k]) > 0.03)
        .ok_or_else(|| CaseError::Plan(format!("{}: the cart never moves 3 cm in {}", plan.id, plan.test)))?;
    let t0 = moved as f64 / FS_HZ + ROLLING_ONSET_AFTER_S;
    let mass = Some(Change { dm_kg: plan.dm_kg, at_m: plan.at_m });
    let change = Alteration { mass, ramp_s: plan.ramp_s, ..Alteration::default() };
    let truth = case.altered(&nominal, &change, t0, case.end_s(), None).map_err(|s| CaseError::Physics(s.error))?;
    let mut rng = SplitMix64::new(seed_from_label(&format!("case:{}", plan.id)));
    let mut floor_csv = String::from("time_s,ax_mps2,ay_mps2\n");
    let mut accel_csv = String::from("time_s,top_ax_mps2\n");
    for (k, a) in ax.iter().enumerate() {
        let t = k as f64 / FS_HZ;
        let _ = writeln!(floor_csv, "{t:.3},{a:.6},0.000000");
        let _ = writeln!(accel_csv, "{t:.3},{:.5}", truth.ax_abs_mps2[k] + ACCEL_NOISE_MPS2 * rng.normal());
    }
    // The camera: platform-centre displacement and yaw at 30 Hz, with one dropout of 8 frames.
    let header = "time_s,x_m,y_m,yaw_rad\n";
    let camera_csv = camera_csv(header, n, 8.0 / CAMERA_HZ, &mut rng, |t, k, w, dropped, rng| {
        let at = |s: &[f64]| s[k] * (1.0 - w) + s[k + 1] * w;
        let (px, py, yaw) = (
            at(&truth.x_m) + CAMERA_NOISE_M * rng.normal(),
            at(&truth.y_m) + CAMERA_NOISE_M * rng.normal(),
            at(&truth.yaw_rad) + CAMERA_NOISE_RAD * rng.normal(),
        );
        if dropped {
            format!("{t:.6},nan,nan,nan\n")
        } else {
            format!("{t:.6},{px:.6},{py:.6},{yaw:.6}\n")
        }
    });
    let steer = table.steer0_deg.map(|d| format!("{d}")).join(", ");
    let equipment = format!(
        "model: rolling\nname: {unit}\ndescription: {unit} on four unlocked swivel casters ({test}, floor {floor}); synthetic demo case\nlength_m: {l}\nwidth_m: {w}\nplatform_mass_kg: {m}\nwheel_diameter_m: {dw}\nwheel_width_m: {ww}\nwheel_mass_kg: {mw}\nyaw0_deg: {yaw0}\nsteer0_deg: [{steer}]\nmu_s_roll: {msr}\nmu_s_swivel: {mss}\nmu_k_roll: {mkr}\nmu_k_swivel: {mks}\nbeta_spm: {beta}\ngamma_n: {gamma}\np: {p}\ntrail_m: {trail}\nswivel_arm_m: {arm}\nfriction_eps: {eps}\nfriction_eps_swivel: {eps_sw}\ng_mps2: {g}\nsensors:\n  camera:\n    file: observed_cpt.csv\n    rate_hz: {CAMERA_HZ}\n    quantities: platform-centre displacement x_m, y_m from its start (floor frame) and absolute yaw_rad\n    noise_sd_m: {CAMERA_NOISE_M}\n    noise_sd_rad: {CAMERA_NOISE_RAD}\n  accelerometer:\n    file: observed_accel.csv\n    rate_hz: {FS_HZ}\n    position: platform centre\n    quantity: X component of the platform centre's absolute acceleration, m/s^2\n    noise_sd_mps2: {ACCEL_NOISE_MPS2}\nconventions:\n  frame: as ../shared/cases/rolling_demo (floor-attached, non-rotating; X = E-W, the table's axis)\n",
        unit = plan.unit,
        test = plan.test,
        floor = plan.floor,
        l = cart.length_m,
        w = cart.width_m,
        m = cart.platform_mass_kg,
        dw = cart.wheel_diameter_m,
        ww = cart.wheel_width_m,
        mw = cart.wheel_mass_kg,
        yaw0 = table.yaw0_deg,
        msr = table.mu_s_roll,
        mss = table.mu_s_swivel,
        mkr = table.mu_k_roll,
        mks = table.mu_k_swivel,
        beta = table.beta_spm,
        gamma = table.gamma_n,
        p = table.p,
        trail = cart.trail_m,
        arm = cart.swivel_arm_m,
        eps = friction.eps_mps,
        eps_sw = friction.eps_swivel_radps,
        g = options.g_mps2,
    );
    let files = case_folder(plan.id, [equipment, floor_csv, accel_csv, camera_csv]);
    let truth_yaml = format!(
        "case_id: {id}\nstory: {story}\nmodel: rolling\neffect: mass_change\nexpected_verdict: mass_change\nonset_s: {t0:.3}\nparameters:\n  t0_s: {t0:.3}\n  dm_kg: {dm}\n  dx_m: {dx}\n  dy_m: {dy}\n  ramp_s: {ramp}\nmade_by: shakeflow's own models (src/demo/cases.rs); make prove-rolling uses an independent generator\n",
        id = plan.id,
        story = plan.story,
        dm = plan.dm_kg,
        dx = plan.at_m[0],
        dy = plan.at_m[1],
        ramp = plan.ramp_s,
    );
    Ok((files, truth_yaml))
}
