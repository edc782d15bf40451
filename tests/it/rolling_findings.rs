//! The study's qualitative findings about its rolling model, reproduced on the demo archive
//! (floor records of the ten motions the model is valid for, BI-1…BI-6 and FB-1…FB-4, with the
//! cubic baseline removed as the demo pipeline does), with the Table 4 parameters:
//! 1. MC2 pivot-steers: its rear casters swivel in opposite directions (Figure 11c), unlike the
//!    other units' (PS1's turn together, Figure 11a);
//! 2. PB2 and MC2, on the same floor, respond differently;
//! 3. the response is sensitive to the initial yaw and caster angles and to μ_s and μ_k —
//!    beyond the numerical noise of the integration.
//!
//! `make rolling-findings` runs this with the tables printed (the numbers in docs/models/rolling.md).

use std::collections::BTreeMap;

use rayon::prelude::*;
use shakeflow::physics::rolling::{self, simulate, Cart, Excitation, FrictionLaw, Method, Options, Response, Table4};

const MOTIONS: [&str; 10] = ["BI-1", "BI-2", "BI-3", "BI-4", "BI-5", "BI-6", "FB-1", "FB-2", "FB-3", "FB-4"];
const UNITS: [(&str, u8); 4] = [("PS1", 5), ("PB2", 4), ("MC2", 4), ("UI3", 4)];
const G: f64 = 9.80665;

/// A named change to a Table 4 row.
type Variation = (&'static str, Box<dyn Fn(&mut Table4) + Sync>);
/// Peak displacement (m), peak yaw (°), caster flips, breakaway time (s).
type Summary = (f64, f64, usize, f64);

struct Floor {
    dt: f64,
    x: Vec<f64>,
    y: Vec<f64>,
}

/// Floors 4 and 5 of each motion from the archive's DAQ1 export (NEES converted data): its
/// units → m/s², cubic baseline removed.
fn floors(archive: &std::path::Path) -> BTreeMap<(String, u8), Floor> {
    let manifest: shakeflow::demo::archive::Manifest =
        serde_json::from_str(&std::fs::read_to_string(archive.join("manifest.json")).unwrap()).unwrap();
    let mut out = BTreeMap::new();
    for motion in MOTIONS {
        let test = manifest.tests.iter().find(|t| t.id == motion).unwrap();
        let daq1 = crate::common::DemoDaq::read(archive, &test.daq1_file);
        let time = daq1.column("Time");
        let corrected = |name: &str| {
            let si: Vec<f64> = daq1.g(name, archive).iter().map(|v| v * G).collect();
            shakeflow::signal::baseline::remove_polynomial(&time, &si, 3).0
        };
        let dt = (time[time.len() - 1] - time[0]) / (time.len() - 1) as f64;
        for floor in [4u8, 5] {
            let (x, y) = (corrected(&format!("A{floor}_EW")), corrected(&format!("A{floor}_NS")));
            out.insert((motion.to_string(), floor), Floor { dt, x, y });
        }
    }
    out
}

/// The model of a Table 4 row, with the defaults simulate_rolling uses.
fn model(table: &Table4) -> (Cart, rolling::Friction, Options) {
    let cart = table.cart(Cart::default_trail_m(table.wheel_diameter_m), rolling::DEFAULT_SWIVEL_ARM_M);
    let friction = table.friction(rolling::DEFAULT_FRICTION_EPS_MPS, FrictionLaw::Regularised);
    let (yaw0_rad, steer0_rad) = table.initial_pose();
    (cart, friction, Options { yaw0_rad, steer0_rad, ..Options::default() })
}

fn run(table: &Table4, floor: &Floor, method: Method) -> Response {
    run_with(table, floor, method, |_| {})
}

fn run_with(table: &Table4, floor: &Floor, method: Method, adjust: impl Fn(&mut Cart)) -> Response {
    let (mut cart, friction, options) = model(table);
    adjust(&mut cart);
    let excitation = Excitation { t0_s: 0.0, dt_s: floor.dt, ax_mps2: &floor.x, ay_mps2: &floor.y };
    simulate(&cart, &friction, &excitation, &Options { method, ..options }).unwrap()
}

/// Samples where both rear casters (2 and 3) swivel faster than 0.2 rad/s, and of those the
/// ones where they swivel in opposite directions.
fn rear_swivels(r: &Response) -> (usize, usize) {
    let (s2, s3) = (&r.swivel_rate_radps[1], &r.swivel_rate_radps[2]);
    let both: Vec<usize> = (0..s2.len()).filter(|&k| s2[k].abs() > 0.2 && s3[k].abs() > 0.2).collect();
    (both.len(), both.iter().filter(|&&k| s2[k] * s3[k] < 0.0).count())
}

#[test]
fn the_studys_rolling_findings_hold_on_the_demo_archive() {
    let work = crate::tempdir::tempdir().unwrap();
    shakeflow::demo::archive::write_demo_archive(work.path()).unwrap();
    let floors = floors(work.path());
    let jobs: Vec<(&str, u8, &str)> =
        UNITS.iter().flat_map(|&(unit, floor)| MOTIONS.iter().map(move |&m| (unit, floor, m))).collect();
    let runs: BTreeMap<(&str, &str), Response> = jobs
        .par_iter()
        .map(|&(unit, floor, motion)| {
            (
                (unit, motion),
                run(&rolling::preset(unit).unwrap(), &floors[&(motion.to_string(), floor)], Method::default()),
            )
        })
        .collect();

    // 1. Pivot steering, pooled over the ten motions.
    println!("\n1. Rear casters swivelling in opposite directions (pivot steering), pooled over BI-1…BI-6, FB-1…FB-4");
    println!("{:<6}{:>28}{:>22}{:>14}", "unit", "both rear casters active", "of which opposite", "fraction");
    let mut opposite_share = BTreeMap::new();
    for (unit, _) in UNITS {
        let (both, opposite) =
            MOTIONS.iter().map(|m| rear_swivels(&runs[&(unit, *m)])).fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        let share = opposite as f64 / both.max(1) as f64;
        println!("{unit:<6}{:>26.1} s{:>20.1} s{:>14.2}", both as f64 * 0.005, opposite as f64 * 0.005, share);
        opposite_share.insert(unit, share);
    }
    assert!(opposite_share["MC2"] > 0.4, "MC2's rear casters must mostly counter-swivel: {opposite_share:?}");
    for unit in ["PS1", "PB2", "UI3"] {
        assert!(opposite_share[unit] < 0.15, "{unit}'s rear casters must mostly swivel together: {opposite_share:?}");
    }

    // 2. PB2 and MC2 on the same floor.
    println!("\n2. PB2 and MC2 on the same floor 4 records");
    println!(
        "{:<7}{:>16}{:>16}{:>14}{:>14}{:>12}{:>12}",
        "motion", "PB2 peak [m]", "MC2 peak [m]", "PB2 yaw [°]", "MC2 yaw [°]", "PB2 starts", "MC2 starts"
    );
    let start =
        |r: &Response| r.events.iter().find(|e| e.kind == rolling::EventKind::Breakaway).map_or(f64::NAN, |e| e.time_s);
    let mut differing = 0;
    for motion in MOTIONS {
        let (pb2, mc2) = (&runs[&("PB2", motion)], &runs[&("MC2", motion)]);
        let (dp, dm) = (pb2.peak_displacement().0, mc2.peak_displacement().0);
        let (yp, ym) = (pb2.peak_yaw().0.to_degrees(), mc2.peak_yaw().0.to_degrees());
        println!("{motion:<7}{dp:>16.3}{dm:>16.3}{yp:>14.1}{ym:>14.1}{:>11.2}s{:>11.2}s", start(pb2), start(mc2));
        // PB2's static rolling friction (0.012) is a quarter of MC2's (0.044): it starts first.
        assert!(start(pb2) < start(mc2), "{motion}: PB2 must break away before MC2");
        // Their paths differ: the RMS gap between the x–y histories exceeds half the larger RMS.
        let rms = |v: &[f64]| (v.iter().map(|a| a * a).sum::<f64>() / v.len() as f64).sqrt();
        let gap: Vec<f64> =
            (0..pb2.x_m.len()).map(|k| (pb2.x_m[k] - mc2.x_m[k]).hypot(pb2.y_m[k] - mc2.y_m[k])).collect();
        let scale = rms(&pb2.x_m).max(rms(&mc2.x_m));
        if rms(&gap) > 0.5 * scale {
            differing += 1;
        }
    }
    println!("paths differ (RMS gap > half the larger RMS displacement) in {differing} of 10 motions");
    assert!(differing >= 6, "PB2 and MC2 respond alike in {} motions", 10 - differing);

    // 3. Sensitivity on BI-1 (the motion of the study's Figure 11), against the numerical noise.
    println!("\n3. Sensitivity on BI-1: change of peak displacement [m] / peak yaw [°] from the Table 4 run");
    let variations: Vec<Variation> = vec![
        ("rtol 1e-9 (numerical noise)", Box::new(|_| {})),
        ("yaw0 + 5°", Box::new(|t| t.yaw0_deg += 5.0)),
        ("yaw0 − 5°", Box::new(|t| t.yaw0_deg -= 5.0)),
        ("steer0 + 10°", Box::new(|t| t.steer0_deg = t.steer0_deg.map(|d| d + 10.0))),
        ("steer0 − 10°", Box::new(|t| t.steer0_deg = t.steer0_deg.map(|d| d - 10.0))),
        ("μ_s × 1.2", Box::new(|t| (t.mu_s_roll, t.mu_s_swivel) = (1.2 * t.mu_s_roll, 1.2 * t.mu_s_swivel))),
        ("μ_s × 0.8", Box::new(|t| (t.mu_s_roll, t.mu_s_swivel) = (0.8 * t.mu_s_roll, 0.8 * t.mu_s_swivel))),
        ("μ_k × 1.2", Box::new(|t| (t.mu_k_roll, t.mu_k_swivel) = (1.2 * t.mu_k_roll, 1.2 * t.mu_k_swivel))),
        ("μ_k × 0.8", Box::new(|t| (t.mu_k_roll, t.mu_k_swivel) = (0.8 * t.mu_k_roll, 0.8 * t.mu_k_swivel))),
    ];
    let cases: Vec<(usize, &str, u8)> =
        (0..variations.len()).flat_map(|v| UNITS.iter().map(move |&(u, f)| (v, u, f))).collect();
    let changes: BTreeMap<(usize, &str), (f64, f64)> = cases
        .par_iter()
        .map(|&(v, unit, floor)| {
            let mut table = rolling::preset(unit).unwrap();
            variations[v].1(&mut table);
            let method = if v == 0 { Method::Adaptive { rtol: 1e-9, atol: 1e-11 } } else { Method::default() };
            let r = run(&table, &floors[&("BI-1".to_string(), floor)], method);
            let base = &runs[&(unit, "BI-1")];
            (
                (v, unit),
                (
                    r.peak_displacement().0 - base.peak_displacement().0,
                    (r.peak_yaw().0 - base.peak_yaw().0).to_degrees(),
                ),
            )
        })
        .collect();
    print!("{:<30}", "");
    for (unit, _) in UNITS {
        print!("{unit:>18}");
    }
    println!();
    for (v, (name, _)) in variations.iter().enumerate() {
        print!("{name:<30}");
        for (unit, _) in UNITS {
            let (d, y) = changes[&(v, unit)];
            print!("{:>18}", format!("{d:+.3} / {y:+.1}"));
        }
        println!();
    }
    // Each kind of change moves some unit's peak displacement by more than 5 cm, twenty times more
    // than tightening the integration moves any unit's (PS1's caster flips amplify even that).
    let noise = UNITS.iter().map(|(u, _)| changes[&(0, *u)].0.abs()).fold(0.0, f64::max);
    assert!(noise < 5e-3, "numerical noise {noise} m");
    for pair in [(1, 2), (3, 4), (5, 6), (7, 8)] {
        let effect = [pair.0, pair.1]
            .iter()
            .flat_map(|&v| UNITS.iter().map(move |(u, _)| (v, *u)))
            .map(|key| changes[&key].0.abs())
            .fold(0.0, f64::max);
        assert!(effect > 0.05 && effect > 20.0 * noise, "{}: the largest change is {effect} m", variations[pair.0].0);
    }

    // 4. The caster trail (no source gives one; default 0.3 × wheel diameter), on BI-1 and FB-4.
    // A caster realigns within a few trails of travel, so a short trail completes more flips at
    // each reversal: fewer flips with a longer trail, for every unit.
    println!("\n4. Caster trail d: peak displacement [m] / peak yaw [°] / caster flips / breakaway [s]");
    let trails = [0.15, 0.3, 0.5];
    let cases: Vec<(usize, &str, u8, &str)> = [0, 2]
        .into_iter()
        .flat_map(|s| UNITS.iter().flat_map(move |&(u, f)| ["BI-1", "FB-4"].into_iter().map(move |m| (s, u, f, m))))
        .collect();
    let summary = |r: &Response| -> Summary {
        (r.peak_displacement().0, r.peak_yaw().0.to_degrees(), r.flips().iter().sum::<usize>(), start(r))
    };
    let mut sweep: BTreeMap<(usize, &str, &str), Summary> = cases
        .par_iter()
        .map(|&(s, unit, floor, motion)| {
            let table = rolling::preset(unit).unwrap();
            let r = run_with(&table, &floors[&(motion.to_string(), floor)], Method::default(), |c| {
                c.trail_m = (trails[s] * c.wheel_diameter_m).max(rolling::MIN_DEFAULT_TRAIL_M);
            });
            ((s, unit, motion), summary(&r))
        })
        .collect();
    for (unit, _) in UNITS {
        for motion in ["BI-1", "FB-4"] {
            sweep.insert((1, unit, motion), summary(&runs[&(unit, motion)]));
        }
    }
    for motion in ["BI-1", "FB-4"] {
        print!("{motion:<22}");
        for (unit, _) in UNITS {
            print!("{unit:>27}");
        }
        println!();
        for (s, per_diameter) in trails.iter().enumerate() {
            print!("{:<22}", format!("d = {per_diameter} D"));
            for (unit, _) in UNITS {
                let (d, y, f, b) = sweep[&(s, unit, motion)];
                print!("{:>27}", format!("{d:.3} / {y:.1} / {f} / {b:.2}"));
            }
            println!();
        }
        for (unit, _) in UNITS {
            let (short, long) = (sweep[&(0, unit, motion)].2, sweep[&(2, unit, motion)].2);
            assert!(short > long, "{unit} {motion}: {short} flips with d = 0.15 D, {long} with 0.5 D");
        }
    }
}
