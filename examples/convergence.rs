//! The convergence study of the rolling model's numerical defaults (docs/convergence.md):
//! every preset unit of Table 4 on floor 4 of the demo building, fixed-base and base-isolated,
//! under every horizontal real ground motion in ../shared/data/ground_motions (their strong
//! part, scaled to a peak floor acceleration), run with the adaptive integrator's tolerance and
//! the two friction regularisations (ε, ε_sw) halved step by step, and atol alone divided by 10. For each setting it writes
//! the peak displacement and peak yaw, the work (right-hand-side evaluations) and the time, and
//! says for each setting on how many runs halving it moves the peaks by less than 0.5 % and 0.5°.
//!
//! The rocking models have no regularisation; their one numerical default is the tolerance
//! (rtol 1e-11, atol 1e-2 rtol rad): `--rocking` runs each rocking preset on the same floors'
//! X component, at 1.5 times its uplift threshold g tan α, as the study's block, sliding on a
//! floor of μ = 0.9 tan α (it slides and rocks) and coupled to an isolated base (T_b 2 s,
//! ζ 0.1, m_b/m = 1), with rtol 1e-10 … 1e-12, and says the same of peak |θ| (0.5 % of it and
//! 0.5°) and of whether the block overturns.
//!
//! `--law stick_slip` runs the same sweeps with exact rest (`friction_law: stick_slip`) instead of
//! the default regularised law, and writes its files with a `stick_slip_` prefix; `--sweeps
//! friction_eps,friction_eps_swivel` runs only the sweeps named.
//!
//! Usage: convergence [--out DIR] [--pfa-g G] [--units PS1,PB2,...] [--records ELC180,...]
//!   [--law regularised|stick_slip] [--sweeps rtol,atol,friction_eps,friction_eps_swivel] [--rocking]
//!   (`make convergence` writes docs/convergence/: results.csv, the figures and summary.md)

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use shakeflow::demo::archive::floor_response;
use shakeflow::demo::study::Base;
use shakeflow::io::records::{read_at2, read_renadic_v1, read_simcenter_json};
use shakeflow::physics::rocking;
use shakeflow::physics::rolling::{self, simulate, Cart, Excitation, Friction, FrictionLaw, Method, Options};
use shakeflow::plot::{render_png, Panel, Series};

const G: f64 = 9.80665;
/// The criterion of issue 35: halving a setting moves the peak displacement by less than this
/// fraction and the peak yaw by less than `YAW_TOL_DEG`.
const PEAK_TOL: f64 = 0.005;
const YAW_TOL_DEG: f64 = 0.5;
/// Below this peak displacement a relative change means nothing (a cart that barely moves): the
/// peak must then move by less than PEAK_TOL of it.
const PEAK_FLOOR_M: f64 = 0.002;
/// The longest window simulated (s): the strong part of a record, with the isolated building's
/// ring-down after it.
const MAX_WINDOW_S: f64 = 45.0;

/// Settings swept, each with the others at their defaults (the rtol sweep: atol = rtol / 100, as the
/// defaults 1e-8 / 1e-10 tie them).
const RTOLS: [f64; 8] = [1e-7, 1e-8, 5e-9, 1e-9, 5e-10, 1e-10, 5e-11, 1e-11];
const EPS: [f64; 5] = [2e-4, 1e-4, 5e-5, 2.5e-5, 1.25e-5];
const EPS_SW: [f64; 5] = [2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4];
/// atol alone, at rtol SWEEP_RTOL: what bounds the error while the cart creeps (states of
/// 1e-4 m and m/s, where rtol × state is below atol). Each value is compared with the next, 10× finer.
const ATOLS: [f64; 5] = [1e-11, 1e-12, 1e-13, 1e-14, 1e-15];
/// The tolerance at which the ε and atol sweeps run (converged for every run of the tolerance
/// sweep); the ε sweeps at the default atol.
const SWEEP_RTOL: f64 = 1e-10;
/// The sweeps, by the setting's name.
const SWEEPS: [&str; 4] = ["rtol", "atol", "friction_eps", "friction_eps_swivel"];

/// The values of the sweep named `name`.
fn sweep_values(name: &str) -> &'static [f64] {
    match name {
        "rtol" => &RTOLS,
        "atol" => &ATOLS,
        "friction_eps" => &EPS,
        "friction_eps_swivel" => &EPS_SW,
        other => panic!("no sweep {other}: the sweeps are {SWEEPS:?}"),
    }
}

struct Motion {
    name: &'static str,
    /// Ground X and Y in any unit (scaled later), at `dt`.
    x: Vec<f64>,
    y: Vec<f64>,
    dt: f64,
}

fn shared(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/ground_motions").join(name)
}

/// Every horizontal real record: the two components of a station where the file has both, else
/// the component and its time reverse (same spectrum, other phases) as Y.
fn motions() -> Vec<Motion> {
    let at2 = |file: &str| {
        let r = read_at2(&shared(file)).unwrap_or_else(|e| panic!("{e}"));
        (r.channels[0].values.clone(), r.dt.expect("AT2 states dt"))
    };
    let mut out = Vec::new();
    for (name, file) in [
        ("ELC180", "RSN6_IMPVALL.I_I-ELC180.AT2"),
        ("GIL067", "RSN763_LOMAP_GIL067.AT2"),
        ("NIS090", "NIS090.AT2"),
        ("SCS052", "RSN1084_NORTHR_SCS052.AT2"),
        ("TCU078", "RSN1512_CHICHI_TCU078-E.AT2"),
        ("FAIGO360", "RSN2110_DENALI_FAIGO360.AT2"),
    ] {
        let (x, dt) = at2(file);
        let (x, _) = strong_part(&x, dt);
        let y = x.iter().rev().copied().collect();
        out.push(Motion { name, x, y, dt });
    }
    let (x, dt) = at2("Rinaldi228.AT2");
    let (y, _) = at2("Rinaldi318.AT2");
    out.push(window_pair("Rinaldi", &x, &y, dt));
    let r = read_simcenter_json(&shared("RSN2113.json")).unwrap_or_else(|e| panic!("{e}"));
    out.push(window_pair("RSN2113", &r.channels[0].values, &r.channels[1].values, r.dt.unwrap()));
    let r = read_renadic_v1(&shared("llolleo1002271.v1")).unwrap_or_else(|e| panic!("{e}"));
    let channel = |code: &str| {
        let c = r.channels.iter().find(|c| c.name.ends_with(code)).unwrap_or_else(|| panic!("no channel {code}"));
        // Uncorrected (SOURCES.md): a least-squares cubic in time removed, as the study did.
        let t: Vec<f64> = (0..c.values.len()).map(|k| k as f64).collect();
        shakeflow::signal::baseline::remove_polynomial(&t, &c.values, 3).0
    };
    out.push(window_pair("Llolleo", &channel("L"), &channel("T"), r.dt.unwrap()));
    out
}

fn window_pair(name: &'static str, x: &[f64], y: &[f64], dt: f64) -> Motion {
    let (x, range) = strong_part(x, dt);
    Motion { name, x, y: y[range].to_vec(), dt }
}

/// From 2 s before the 5 % Arias time to 10 s after the 95 % one, at most `MAX_WINDOW_S`.
fn strong_part(x: &[f64], dt: f64) -> (Vec<f64>, std::ops::Range<usize>) {
    let total: f64 = x.iter().map(|v| v * v).sum();
    let mut cum = 0.0;
    let (mut i5, mut i95) = (0, x.len() - 1);
    for (k, v) in x.iter().enumerate() {
        let before = cum;
        cum += v * v;
        if before < 0.05 * total && cum >= 0.05 * total {
            i5 = k;
        }
        if before < 0.95 * total && cum >= 0.95 * total {
            i95 = k;
        }
    }
    let start = i5.saturating_sub((2.0 / dt) as usize);
    let end = (i95 + (10.0 / dt) as usize).min(x.len()).min(start + (MAX_WINDOW_S / dt) as usize);
    (x[start..end].to_vec(), start..end)
}

/// Floor 4 of the demo building, X scaled to `pfa_g`, Y to 0.6 of it (pairs keep their ratio).
struct FloorRecord {
    motion: &'static str,
    base: Base,
    dt: f64,
    ax: Vec<f64>,
    ay: Vec<f64>,
}

fn floor(m: &Motion, base: Base, pfa_g: f64, paired: bool) -> FloorRecord {
    let mut ax = floor_response(base, 4, &m.x, m.dt);
    let mut ay = floor_response(base, 4, &m.y, m.dt);
    let peak = |v: &[f64]| v.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    let sx = pfa_g * G / peak(&ax);
    let sy = if paired { sx } else { 0.6 * pfa_g * G / peak(&ay) };
    ax.iter_mut().for_each(|v| *v *= sx);
    ay.iter_mut().for_each(|v| *v *= sy);
    // The cart starts at rest on a floor at rest.
    ax[0] = 0.0;
    ay[0] = 0.0;
    FloorRecord { motion: m.name, base, dt: m.dt, ax, ay }
}

#[derive(Clone, Copy)]
enum Setting {
    Rtol(f64),
    Atol(f64),
    Eps(f64),
    EpsSwivel(f64),
}

impl Setting {
    fn name(self) -> &'static str {
        match self {
            Setting::Rtol(_) => "rtol",
            Setting::Atol(_) => "atol",
            Setting::Eps(_) => "friction_eps",
            Setting::EpsSwivel(_) => "friction_eps_swivel",
        }
    }
    fn value(self) -> f64 {
        match self {
            Setting::Rtol(v) | Setting::Atol(v) | Setting::Eps(v) | Setting::EpsSwivel(v) => v,
        }
    }
}

struct Outcome {
    unit: &'static str,
    floor: usize,
    setting: Setting,
    peak_m: f64,
    yaw_deg: f64,
    evals: usize,
    seconds: f64,
    error: Option<String>,
}

fn run(unit: &'static str, f: &FloorRecord, setting: Setting, floor_index: usize, law: FrictionLaw) -> Outcome {
    let table = rolling::preset(unit).expect("a preset");
    let cart: Cart = table.cart(Cart::default_trail_m(table.wheel_diameter_m), rolling::DEFAULT_SWIVEL_ARM_M);
    let mut friction: Friction = table.friction(rolling::DEFAULT_FRICTION_EPS_MPS, law);
    let (yaw0_rad, steer0_rad) = table.initial_pose();
    let (mut rtol, mut atol) = (SWEEP_RTOL, rolling::DEFAULT_ATOL);
    match setting {
        Setting::Rtol(v) => (rtol, atol) = (v, 1e-2 * v),
        Setting::Atol(v) => atol = v,
        Setting::Eps(v) => friction.eps_mps = v,
        Setting::EpsSwivel(v) => friction.eps_swivel_radps = v,
    }
    let options = Options { yaw0_rad, steer0_rad, method: Method::Adaptive { rtol, atol }, ..Options::default() };
    let excitation = Excitation { t0_s: 0.0, dt_s: f.dt, ax_mps2: &f.ax, ay_mps2: &f.ay };
    let started = Instant::now();
    let result = simulate(&cart, &friction, &excitation, &options);
    let seconds = started.elapsed().as_secs_f64();
    match result {
        Ok(r) => Outcome {
            unit,
            floor: floor_index,
            setting,
            peak_m: r.peak_displacement().0,
            yaw_deg: r.peak_yaw().0.to_degrees(),
            evals: r.stats.rhs_evals,
            seconds,
            error: None,
        },
        Err(e) => Outcome {
            unit,
            floor: floor_index,
            setting,
            peak_m: f64::NAN,
            yaw_deg: f64::NAN,
            evals: 0,
            seconds,
            error: Some(e.to_string()),
        },
    }
}

fn arg(args: &[String], key: &str) -> Option<String> {
    args.iter().position(|a| a == key).and_then(|i| args.get(i + 1)).cloned()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = PathBuf::from(arg(&args, "--out").unwrap_or_else(|| "docs/convergence".into()));
    let pfa_g: f64 = arg(&args, "--pfa-g").map_or(0.3, |v| v.parse().expect("--pfa-g takes a number"));
    let units: Vec<&'static str> = match arg(&args, "--units") {
        None => rolling::PRESETS.to_vec(),
        Some(list) => rolling::PRESETS.iter().copied().filter(|u| list.split(',').any(|x| x == *u)).collect(),
    };
    let only: Option<Vec<String>> = arg(&args, "--records").map(|l| l.split(',').map(String::from).collect());
    std::fs::create_dir_all(&out).expect("the output folder");
    let started = Instant::now();
    if let Some(csv) = arg(&args, "--trajectory") {
        trajectory(&csv, &args);
        return;
    }
    if args.iter().any(|a| a == "--rocking") {
        let summary = rocking_study(only.as_deref());
        std::fs::write(out.join("rocking.md"), &summary).expect("rocking.md");
        print!("{summary}");
        eprintln!("rocking study in {:.0} s", started.elapsed().as_secs_f64());
        return;
    }
    let mut floors = Vec::new();
    for m in motions() {
        if only.as_ref().is_some_and(|o| !o.iter().any(|n| n == m.name)) {
            continue;
        }
        let paired = matches!(m.name, "Rinaldi" | "RSN2113" | "Llolleo");
        for base in [Base::Fixed, Base::Isolated] {
            floors.push(floor(&m, base, pfa_g, paired));
        }
    }
    let (law, prefix) = match arg(&args, "--law").as_deref() {
        None | Some("regularised") => (FrictionLaw::Regularised, ""),
        Some("stick_slip") => (FrictionLaw::StickSlip, "stick_slip_"),
        Some(other) => panic!("--law takes regularised or stick_slip, not {other}"),
    };
    let sweeps: Vec<String> = arg(&args, "--sweeps")
        .map_or_else(|| SWEEPS.iter().map(|s| s.to_string()).collect(), |l| l.split(',').map(String::from).collect());
    let settings: Vec<Setting> = RTOLS
        .iter()
        .map(|&v| Setting::Rtol(v))
        .chain(ATOLS.iter().map(|&v| Setting::Atol(v)))
        .chain(EPS.iter().map(|&v| Setting::Eps(v)))
        .chain(EPS_SW.iter().map(|&v| Setting::EpsSwivel(v)))
        .filter(|s| sweeps.iter().any(|n| n == s.name()))
        .collect();
    let mut jobs: Vec<(&'static str, usize, Setting)> = Vec::new();
    for &u in &units {
        for f in 0..floors.len() {
            for &s in &settings {
                jobs.push((u, f, s));
            }
        }
    }
    eprintln!("{} floors × {} units × {} settings = {} runs", floors.len(), units.len(), settings.len(), jobs.len());
    let outcomes: Vec<Outcome> = jobs.par_iter().map(|&(u, f, s)| run(u, &floors[f], s, f, law)).collect();
    let mut csv = String::from(
        "unit,record,building,duration_s,setting,value,peak_displacement_m,peak_yaw_deg,rhs_evals,seconds,error\n",
    );
    for o in &outcomes {
        let f = &floors[o.floor];
        writeln!(
            csv,
            "{},{},{},{:.2},{},{:e},{:.6},{:.4},{},{:.3},{}",
            o.unit,
            f.motion,
            f.base.code(),
            (f.ax.len() - 1) as f64 * f.dt,
            o.setting.name(),
            o.setting.value(),
            o.peak_m,
            o.yaw_deg,
            o.evals,
            o.seconds,
            o.error.as_deref().unwrap_or("").replace(',', ";")
        )
        .unwrap();
    }
    std::fs::write(out.join(format!("{prefix}results.csv")), csv).expect("results.csv");
    let summary = summarise(&outcomes, &floors, &units, &sweeps);
    std::fs::write(out.join(format!("{prefix}summary.md")), &summary).expect("summary.md");
    print!("{summary}");
    figures(&out, &outcomes, &sweeps, prefix);
    eprintln!("{} runs in {:.0} s", outcomes.len(), started.elapsed().as_secs_f64());
}

/// The outcome of `setting` on (unit, floor), and of the next finer value of the same sweep.
fn pairs<'a>(outcomes: &'a [Outcome], name: &str, values: &[f64]) -> Vec<(f64, Vec<(&'a Outcome, &'a Outcome)>)> {
    values
        .windows(2)
        .map(|w| {
            let at = |v: f64, o: &Outcome| o.setting.name() == name && o.setting.value() == v;
            let coarse: Vec<&Outcome> = outcomes.iter().filter(|o| at(w[0], o)).collect();
            let matched = coarse
                .into_iter()
                .filter_map(|c| {
                    outcomes.iter().find(|o| at(w[1], o) && o.unit == c.unit && o.floor == c.floor).map(|f| (c, f))
                })
                .collect();
            (w[0], matched)
        })
        .collect()
}

fn moved(a: &Outcome, b: &Outcome) -> (f64, f64) {
    let scale = b.peak_m.max(PEAK_FLOOR_M);
    ((a.peak_m - b.peak_m).abs() / scale, (a.yaw_deg - b.yaw_deg).abs())
}

fn converged(a: &Outcome, b: &Outcome) -> bool {
    let (dp, dy) = moved(a, b);
    a.error.is_none() && b.error.is_none() && dp < PEAK_TOL && dy < YAW_TOL_DEG
}

fn summarise(outcomes: &[Outcome], floors: &[FloorRecord], units: &[&str], sweeps: &[String]) -> String {
    let mut s = String::new();
    writeln!(
        s,
        "{} floor records ({} ground motions × fixed and isolated, floor 4) × {} units ({}); \
         a setting passes a run when halving it moves the peak displacement by < {} % (of the peak, at least {} mm) and the peak yaw by < {}°.\n",
        floors.len(),
        floors.len() / 2,
        units.len(),
        units.join(", "),
        100.0 * PEAK_TOL,
        1e3 * PEAK_FLOOR_M,
        YAW_TOL_DEG
    )
    .unwrap();
    for name in sweeps {
        let (name, values) = (name.as_str(), sweep_values(name));
        writeln!(s, "\n`{name}` (others at their defaults, rtol {SWEEP_RTOL:e} for the atol and ε sweeps):\n").unwrap();
        writeln!(
            s,
            "| {name} | runs passing | worst peak move | worst yaw move | worst run | mean evals | mean s/run |"
        )
        .unwrap();
        writeln!(s, "|---|---|---|---|---|---|---|").unwrap();
        for (value, matched) in pairs(outcomes, name, values) {
            let pass = matched.iter().filter(|(a, b)| converged(a, b)).count();
            let worst = matched
                .iter()
                .max_by(|x, y| {
                    let (px, yx) = moved(x.0, x.1);
                    let (py, yy) = moved(y.0, y.1);
                    (px / PEAK_TOL).max(yx / YAW_TOL_DEG).total_cmp(&(py / PEAK_TOL).max(yy / YAW_TOL_DEG))
                })
                .map(|(a, b)| {
                    let f = &floors[a.floor];
                    format!("{} {} {}: {:.4} → {:.4} m", a.unit, f.motion, f.base.code(), a.peak_m, b.peak_m)
                })
                .unwrap_or_default();
            let max_p = matched.iter().map(|(a, b)| moved(a, b).0).fold(0.0, f64::max);
            let max_y = matched.iter().map(|(a, b)| moved(a, b).1).fold(0.0, f64::max);
            let own: Vec<&Outcome> = matched.iter().map(|(a, _)| *a).collect();
            let evals = own.iter().map(|o| o.evals as f64).sum::<f64>() / own.len().max(1) as f64;
            let secs = own.iter().map(|o| o.seconds).sum::<f64>() / own.len().max(1) as f64;
            writeln!(
                s,
                "| {value:e} | {pass}/{} | {:.2} % | {max_y:.2}° | {worst} | {evals:.0} | {secs:.3} |",
                matched.len(),
                100.0 * max_p
            )
            .unwrap();
        }
    }
    let errors: Vec<String> = outcomes
        .iter()
        .filter_map(|o| {
            o.error.as_ref().map(|e| {
                let f = &floors[o.floor];
                format!("- {} {} {} {} {:e}: {e}", o.unit, f.motion, f.base.code(), o.setting.name(), o.setting.value())
            })
        })
        .collect();
    if !errors.is_empty() {
        writeln!(s, "\nRuns that failed:\n{}", errors.join("\n")).unwrap();
    }
    s
}

/// Per sweep, the worst move of each run (peak, %) at each setting, one point per run.
fn figures(out: &Path, outcomes: &[Outcome], sweeps: &[String], prefix: &str) {
    let law = if prefix.is_empty() { "" } else { ", friction_law stick_slip" };
    for name in sweeps {
        let (name, values) = (name.as_str(), sweep_values(name));
        let mut xs = Vec::new();
        let mut peak_moves = Vec::new();
        let mut yaw_moves = Vec::new();
        for (value, matched) in pairs(outcomes, name, values) {
            for (a, b) in matched {
                let (dp, dy) = moved(a, b);
                xs.push(value.log10());
                peak_moves.push((100.0 * dp).max(1e-6));
                yaw_moves.push(dy.max(1e-6));
            }
        }
        let limit_x =
            [xs.iter().copied().fold(f64::INFINITY, f64::min), xs.iter().copied().fold(f64::NEG_INFINITY, f64::max)];
        let panels = [
            Panel {
                title: format!("peak displacement moved by halving {name} (one point per unit × floor record)"),
                x_label: format!("log10 {name}"),
                y_label: "% of the peak".into(),
                series: vec![
                    Series::new("runs", &xs, &peak_moves).points(),
                    Series::new("0.5 %", &limit_x, &[100.0 * PEAK_TOL, 100.0 * PEAK_TOL]),
                ],
                log_y: true,
                ..Panel::default()
            },
            Panel {
                title: format!("peak yaw moved by halving {name}"),
                x_label: format!("log10 {name}"),
                y_label: "degrees".into(),
                series: vec![
                    Series::new("runs", &xs, &yaw_moves).points(),
                    Series::new("0.5°", &limit_x, &[YAW_TOL_DEG, YAW_TOL_DEG]),
                ],
                log_y: true,
                ..Panel::default()
            },
        ];
        let png =
            render_png(&format!("rolling model{law}: convergence in {name}"), &panels, 1000, 700).expect("a figure");
        std::fs::write(out.join(format!("{prefix}{name}.png")), png).expect("a figure file");
    }
}

const ROCKING_RTOLS: [f64; 5] = [1e-10, 5e-11, 1e-11, 5e-12, 1e-12];

#[derive(Clone, Copy, PartialEq, Eq)]
enum Variant {
    Block,
    Sliding,
    Coupled,
}

impl Variant {
    fn name(self) -> &'static str {
        match self {
            Variant::Block => "block",
            Variant::Sliding => "sliding",
            Variant::Coupled => "coupled base",
        }
    }
}

struct RockingOutcome {
    preset: &'static str,
    floor: usize,
    variant: Variant,
    rtol: f64,
    /// Peak |θ| (rad; the lie angle once overturned) and whether it overturned.
    peak_rad: f64,
    overturned: bool,
    evals: usize,
    seconds: f64,
}

fn rocking_study(only: Option<&[String]>) -> String {
    let mut floors = Vec::new();
    for m in motions() {
        if only.is_some_and(|o| !o.iter().any(|n| n == m.name)) {
            continue;
        }
        for base in [Base::Fixed, Base::Isolated] {
            floors.push(floor(&m, base, 1.0, false));
        }
    }
    let mut jobs = Vec::new();
    for &preset in rocking::PRESETS {
        for f in 0..floors.len() {
            for variant in [Variant::Block, Variant::Sliding, Variant::Coupled] {
                for rtol in ROCKING_RTOLS {
                    jobs.push((preset, f, variant, rtol));
                }
            }
        }
    }
    eprintln!("{} rocking runs", jobs.len());
    let outcomes: Vec<RockingOutcome> = jobs
        .par_iter()
        .map(|&(preset, f, variant, rtol)| {
            let (shape, mass) = rocking::preset(preset).expect("a preset");
            let block = rocking::Block::new(shape, mass, G).expect("a block");
            let fl = &floors[f];
            // The floor's X component (scaled to 1 g peak) at 1.5 times the uplift threshold.
            let scale = 1.5 * block.alpha_rad.tan();
            let horizontal: Vec<f64> = fl.ax.iter().map(|a| a * scale).collect();
            let mut options = rocking::Options {
                method: rocking::Method::Adaptive { rtol, atol_rad: 1e-2 * rtol },
                ..rocking::Options::default()
            };
            match variant {
                Variant::Block => {}
                Variant::Sliding => options.friction = Some(rocking::Friction::coulomb(0.9 * block.alpha_rad.tan())),
                Variant::Coupled => {
                    options.isolated_base =
                        Some(rocking::IsolatedBase { period_s: 2.0, damping_ratio: 0.1, mass_ratio: Some(1.0) })
                }
            }
            let excitation =
                rocking::Excitation { t0_s: 0.0, dt_s: fl.dt, horizontal_mps2: &horizontal, vertical_mps2: None };
            let started = Instant::now();
            let r = rocking::simulate(&block, &excitation, &options);
            let seconds = started.elapsed().as_secs_f64();
            let (peak_rad, overturned, evals) = match r {
                Ok(r) => (r.max_abs_theta(), r.overturn.is_some(), r.stats.rhs_evals),
                Err(_) => (f64::NAN, false, 0),
            };
            RockingOutcome { preset, floor: f, variant, rtol, peak_rad, overturned, evals, seconds }
        })
        .collect();
    let mut s = String::new();
    writeln!(
        s,
        "Rocking presets ({}) × {} floor records (X at 1.5 × the uplift threshold) × block, sliding (μ = 0.9 tan α) and coupled isolated base (T_b 2 s, ζ 0.1, m_b/m 1); \
         a tolerance passes a run when halving it moves peak |θ| by < {} % (of the peak, at least 1 mrad) and < {}° and the overturn verdict stays.\n",
        rocking::PRESETS.join(", "),
        floors.len(),
        100.0 * PEAK_TOL,
        YAW_TOL_DEG
    )
    .unwrap();
    writeln!(
        s,
        "| model | rtol | runs passing (vs the next finer rtol) | worst move | worst run | mean evals | mean s/run |"
    )
    .unwrap();
    writeln!(s, "|---|---|---|---|---|---|---|").unwrap();
    for variant in [Variant::Block, Variant::Sliding, Variant::Coupled] {
        for w in ROCKING_RTOLS.windows(2) {
            let mut pass = 0;
            let mut total = 0;
            let mut worst = (0.0, String::new());
            let (mut evals, mut secs) = (0.0, 0.0);
            for a in outcomes.iter().filter(|o| o.variant == variant && o.rtol == w[0]) {
                let Some(b) = outcomes
                    .iter()
                    .find(|o| o.variant == variant && o.rtol == w[1] && o.preset == a.preset && o.floor == a.floor)
                else {
                    continue;
                };
                total += 1;
                evals += a.evals as f64;
                secs += a.seconds;
                let moved = (a.peak_rad - b.peak_rad).abs();
                let relative = moved / b.peak_rad.max(1e-3);
                let ok = a.overturned == b.overturned
                    && relative < PEAK_TOL
                    && moved.to_degrees() < YAW_TOL_DEG
                    && a.peak_rad.is_finite();
                pass += usize::from(ok);
                let badness =
                    if a.overturned != b.overturned || !a.peak_rad.is_finite() { f64::INFINITY } else { relative };
                if badness > worst.0 || worst.1.is_empty() {
                    let f = &floors[a.floor];
                    worst = (
                        badness,
                        format!(
                            "{} {} {}: {:.5} → {:.5} rad{}",
                            a.preset,
                            f.motion,
                            f.base.code(),
                            a.peak_rad,
                            b.peak_rad,
                            if a.overturned != b.overturned { " (overturn verdict changes)" } else { "" }
                        ),
                    );
                }
            }
            writeln!(
                s,
                "| {} | {:e} | {pass}/{total} | {:.3} % | {} | {:.0} | {:.3} |",
                variant.name(),
                w[0],
                100.0 * if worst.0.is_finite() { worst.0 } else { f64::NAN },
                worst.1,
                evals / total.max(1) as f64,
                secs / total.max(1) as f64
            )
            .unwrap();
        }
    }
    s
}

/// `--trajectory FLOOR.csv --unit U [--rtol R] [--eps E] [--eps-sw E]`: one run of a preset
/// unit on a floor CSV (time_s, ax_mps2, ay_mps2), every 200th sample printed as
/// time, x, y, yaw change (for comparing with a peer's output).
fn trajectory(csv: &str, args: &[String]) {
    let text = std::fs::read_to_string(csv).expect("the floor CSV");
    let rows: Vec<Vec<f64>> =
        text.lines().skip(1).map(|l| l.split(',').map(|v| v.parse().expect("a number")).collect()).collect();
    let dt = (rows[rows.len() - 1][0] - rows[0][0]) / (rows.len() - 1) as f64;
    let ax: Vec<f64> = rows.iter().map(|r| r[1]).collect();
    let ay: Vec<f64> = rows.iter().map(|r| r[2]).collect();
    let unit = arg(args, "--unit").unwrap_or_else(|| "PB2".into());
    let table = rolling::preset(&unit).expect("a preset");
    let cart = table.cart(Cart::default_trail_m(table.wheel_diameter_m), rolling::DEFAULT_SWIVEL_ARM_M);
    let mut friction = table.friction(rolling::DEFAULT_FRICTION_EPS_MPS, FrictionLaw::Regularised);
    let number = |key: &str| arg(args, key).map(|v| v.parse::<f64>().expect("a number"));
    if let Some(v) = number("--eps") {
        friction.eps_mps = v;
    }
    if let Some(v) = number("--eps-sw") {
        friction.eps_swivel_radps = v;
    }
    let (yaw0_rad, steer0_rad) = table.initial_pose();
    let mut options = Options { yaw0_rad, steer0_rad, ..Options::default() };
    if let Some(rtol) = number("--rtol") {
        options.method = Method::Adaptive { rtol, atol: number("--atol").unwrap_or(1e-2 * rtol) };
    }
    let r = simulate(&cart, &friction, &Excitation { t0_s: 0.0, dt_s: dt, ax_mps2: &ax, ay_mps2: &ay }, &options)
        .expect("a run");
    let every = number("--every").map_or(200, |v| v as usize);
    for k in (0..r.x_m.len()).step_by(every) {
        println!("{:.3} {:.9} {:.9} {:.9}", k as f64 * dt, r.x_m[k], r.y_m[k], r.yaw_rad[k] - r.yaw_rad[0]);
    }
    eprintln!(
        "peak {:.6} m, yaw {:.4}°, {} evals",
        r.peak_displacement().0,
        r.peak_yaw().0.to_degrees(),
        r.stats.rhs_evals
    );
}
