//! The rolling model against peers nobody here wrote, side by side on the same floor records:
//! real two-component ground motions (Northridge, Rinaldi 228/318) through the demo building,
//! stored in tests/reference/ because the Python peers read them.
//!
//! - tests/reference/rolling_kane.py: the cart derived symbolically by sympy's KanesMethod (with
//!   nonholonomic constraints) and integrated by scipy's DOP853 at rtol 1e-10. Same equations
//!   reached independently, so the agreement is the integrators': 1e-6 m in position over the
//!   first 8 s, and 1e-4 rad in angle (caster angles are the ill-conditioned part: a caster swings
//!   at up to V/d ≈ 10 rad/s in a flip, and a nearly idle one creeps on its regularised swivel
//!   friction); caster flips amplify differences later on (PS1's by ~e^(1.3 t)), so over the
//!   whole record 1 mm and 0.01 rad.
//! - tests/reference/rolling_mujoco.py: MuJoCo's multibody with soft wheel-floor contacts and
//!   Coulomb joint friction, driven by gravity = (−ü_X, −ü_Y, −g). A different contact model, so
//!   a stated tolerance: peak displacement within 10 %, peak yaw within 0.1 rad (6°), and the
//!   path within 3 cm during the strong pulse (first 4 s).
//!
//! Long peer runs are stored (rolling_kane_rinaldi.json: ~2 min; rolling_mujoco_rinaldi.json:
//! ~20 s) and one short run of each peer is regenerated here. To regenerate them (from
//! tests/reference/, with the venv of `make test`):
//!   python rolling_kane.py --floor rolling_floor_rinaldi.csv --units PS1,PB2,MC2,UI3 --every 5 --out rolling_kane_rinaldi.json
//!   python rolling_mujoco.py --floor rolling_floor_rinaldi.csv --units PS1,PB2,MC2,UI3 --every 5 --out rolling_mujoco_rinaldi.json
//! and the floor records with `SHAKEFLOW_WRITE_REFERENCE=1 cargo test --test rolling_peers stored_floor`.

use crate::common;
use crate::rolling_common as rolling;

use common::{reference_script, run_python};
use rolling::*;
use serde_json::Value;
use shakeflow::physics::rolling::{FrictionLaw, Method, Response};

const TIGHT: Method = Method::Adaptive { rtol: 1e-10, atol: 1e-12 };

/// The stored floor records are what the demo building makes of the real records.
/// `SHAKEFLOW_WRITE_REFERENCE=1` rewrites them.
#[test]
fn stored_floor_records_come_from_the_demo_building() {
    for (name, floor) in [("rolling_floor_rinaldi.csv", rinaldi_floor()), ("rolling_floor_denali.csv", denali_floor())]
    {
        let path = reference(name);
        if std::env::var_os("SHAKEFLOW_WRITE_REFERENCE").is_some() {
            std::fs::write(&path, floor.to_csv()).unwrap();
            // Comparing the file with what was just written into it would prove nothing.
            panic!("{name} rewritten; run again without SHAKEFLOW_WRITE_REFERENCE to check it");
        }
        let stored = Floor::read_csv(&path);
        assert_eq!(stored.ax.len(), floor.ax.len(), "{name}");
        assert!((stored.dt - floor.dt).abs() < 1e-12, "{name}: dt {} vs {}", stored.dt, floor.dt);
        // Printed as shortest round-trip decimals: bit for bit.
        assert!(stored.ax == floor.ax && stored.ay == floor.ay, "{name} differs from the demo building's output");
    }
}

/// Largest differences (position m, angle rad) between our response and a peer's samples, over
/// the samples before `until_s`.
fn differences(ours: &Response, peer: &Value, dt: f64, until_s: f64) -> (f64, f64) {
    let samples: Vec<usize> = peer["sample"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
    let (x, y, yaw) = (series(peer, "x_m"), series(peer, "y_m"), series(peer, "yaw_rad"));
    let deltas: Vec<Vec<f64>> = peer["delta_rad"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect())
        .collect();
    let (mut position, mut angle) = (0.0f64, 0.0f64);
    let compared: Vec<(usize, &usize)> = samples.iter().enumerate().filter(|(_, &k)| k as f64 * dt < until_s).collect();
    // No sample compared would report perfect agreement.
    assert!(compared.len() >= 10, "only {} peer samples before {until_s} s", compared.len());
    for (j, &k) in compared {
        position = position.max((ours.x_m[k] - x[j]).abs()).max((ours.y_m[k] - y[j]).abs());
        angle = angle.max((ours.yaw_rad[k] - yaw[j]).abs());
        for (delta, peer_delta) in ours.delta_rad.iter().zip(&deltas) {
            angle = angle.max((delta[k] - peer_delta[j]).abs());
        }
    }
    (position, angle)
}

#[test]
fn kane_peer_regenerated_on_the_first_seconds() {
    // MC2 breaks away at ~1.8 s and rolls 0.13 m by 2.7 s. The peer derives its equations (6 s)
    // and integrates 3 s here; both at rtol 1e-10: agreement to 1e-8 m / 1e-8 rad.
    let out = crate::tempdir::tempdir().unwrap();
    let json = out.path().join("kane.json");
    let floor_path = reference("rolling_floor_rinaldi.csv");
    run_python(
        &reference_script("rolling_kane.py"),
        &["--floor", floor_path.to_str().unwrap(), "--units", "MC2", "--t-end", "3", "--out", json.to_str().unwrap()],
    );
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let peer = &doc["units"]["MC2"];
    let floor = Floor::read_csv(&floor_path);
    let (cart, friction, options) = model_from_peer(&peer["params"], FrictionLaw::Regularised);
    let ours = run(&floor, &cart, &friction, &options, TIGHT);
    assert!(ours.peak_displacement().0 > 0.05, "the window must contain motion");
    let (position, angle) = differences(&ours, peer, floor.dt, 3.01);
    eprintln!("Kane peer (regenerated, MC2, 3 s): max |Δposition| {position:.1e} m, max |Δangle| {angle:.1e} rad");
    assert!(position < 1e-8 && angle < 1e-8, "position {position:e} m, angle {angle:e} rad");
}

#[test]
fn kane_peer_stored_runs_of_the_four_units_agree() {
    let doc = peer_json("rolling_kane_rinaldi.json", "rolling_kane.py");
    let floor = Floor::read_csv(&reference(doc["floor"].as_str().unwrap()));
    let units = doc["units"].as_object().unwrap();
    let mut names: Vec<&String> = units.keys().collect();
    names.sort();
    assert_eq!(names, ["MC2", "PB2", "PS1", "UI3"]);
    for (unit, peer) in units {
        // The peer's own transcription of Table 4 must be ours.
        let table = shakeflow::physics::rolling::preset(unit).unwrap();
        assert_eq!(peer["params"]["mu_s_roll"].as_f64(), Some(table.mu_s_roll), "{unit}");
        assert_eq!(peer["params"]["platform_mass_kg"].as_f64(), Some(table.platform_mass_kg), "{unit}");
        let (cart, friction, options) = model_from_peer(&peer["params"], FrictionLaw::Regularised);
        let ours = run(&floor, &cart, &friction, &options, TIGHT);
        let (position, angle) = differences(&ours, peer, floor.dt, 8.0);
        let (whole_position, whole_angle) = differences(&ours, peer, floor.dt, f64::INFINITY);
        eprintln!(
            "Kane peer {unit}: first 8 s max |Δposition| {position:.1e} m, |Δangle| {angle:.1e} rad; whole record {whole_position:.1e} m, {whole_angle:.1e} rad; peak displacement {:.4} m",
            ours.peak_displacement().0
        );
        assert!(position < 1e-6 && angle < 1e-4, "{unit}: first 8 s: {position:e} m, {angle:e} rad");
        assert!(
            whole_position < 1e-3 && whole_angle < 1e-2,
            "{unit}: whole record: {whole_position:e} m, {whole_angle:e} rad"
        );
    }
}

#[test]
fn mujoco_peer_stored_runs_agree_within_the_contact_models_tolerance() {
    let doc = peer_json("rolling_mujoco_rinaldi.json", "rolling_mujoco.py");
    let floor = Floor::read_csv(&reference(doc["floor"].as_str().unwrap()));
    for (unit, peer) in doc["units"].as_object().unwrap() {
        let mut spec = peer["params"].clone();
        spec["friction_eps"] = serde_json::json!(shakeflow::physics::rolling::DEFAULT_FRICTION_EPS_MPS);
        // MuJoCo's joint friction sticks exactly: compare with the stick-slip law.
        let (cart, friction, options) = model_from_peer(&spec, FrictionLaw::StickSlip);
        let ours = run(&floor, &cart, &friction, &options, Method::default());
        let (peak, peer_peak) = (ours.peak_displacement().0, peer["peak_displacement_m"].as_f64().unwrap());
        let (yaw, peer_yaw) = (ours.peak_yaw().0, peer["peak_yaw_rad"].as_f64().unwrap());
        let (position, _) = differences(&ours, peer, floor.dt, 4.0);
        eprintln!(
            "MuJoCo peer {unit}: peak displacement {peak:.4} vs {peer_peak:.4} m ({:+.1} %), peak yaw {yaw:.4} vs {peer_yaw:.4} rad; path within {position:.4} m over 4 s",
            100.0 * (peak - peer_peak) / peer_peak
        );
        assert!(peer_peak > 0.1, "{unit}: the record must move the cart");
        assert!((peak - peer_peak).abs() < 0.1 * peer_peak, "{unit}: peak displacement {peak} vs MuJoCo {peer_peak}");
        assert!((yaw - peer_yaw).abs() < 0.1, "{unit}: peak yaw {yaw} vs MuJoCo {peer_yaw}");
        assert!(position < 0.03, "{unit}: path differs by {position} m in the first 4 s");
    }
}

#[test]
fn mujoco_peer_regenerated_on_the_first_seconds() {
    // MC2 over 3 s: MuJoCo's soft contacts let the wheels creep (~1 mm) before breakaway; the
    // paths agree within 5 mm and the peak displacement within 5 %.
    let out = crate::tempdir::tempdir().unwrap();
    let json = out.path().join("mujoco.json");
    let floor_path = reference("rolling_floor_rinaldi.csv");
    run_python(
        &reference_script("rolling_mujoco.py"),
        &["--floor", floor_path.to_str().unwrap(), "--units", "MC2", "--t-end", "3", "--out", json.to_str().unwrap()],
    );
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let peer = &doc["units"]["MC2"];
    let floor = Floor::read_csv(&floor_path).first_seconds(3.0);
    let mut spec = peer["params"].clone();
    spec["friction_eps"] = serde_json::json!(shakeflow::physics::rolling::DEFAULT_FRICTION_EPS_MPS);
    let (cart, friction, options) = model_from_peer(&spec, FrictionLaw::StickSlip);
    let ours = run(&floor, &cart, &friction, &options, Method::default());
    let (position, _) = differences(&ours, peer, floor.dt, 3.01);
    let (peak, peer_peak) = (ours.peak_displacement().0, peer["peak_displacement_m"].as_f64().unwrap());
    eprintln!("MuJoCo peer (regenerated, MC2, 3 s): path within {position:.4} m, peak {peak:.4} vs {peer_peak:.4} m");
    assert!(peer_peak > 0.05 && (peak - peer_peak).abs() < 0.05 * peer_peak, "peak {peak} vs {peer_peak}");
    assert!(position < 5e-3, "path differs by {position} m");
}

#[test]
fn adaptive_steps_agree_with_rk4_on_a_real_record() {
    // Check 8 on the Rinaldi floor (19.9 s) for the two units with the most and least rolling:
    // the default adaptive tolerance and the study's RK4 at dt = 1e-4 s give the same peak
    // displacement within 1 mm (the bench criterion) and peak yaw within 1e-3 rad.
    let floor = Floor::read_csv(&reference("rolling_floor_rinaldi.csv"));
    for unit in ["MC2", "PB2"] {
        let table = shakeflow::physics::rolling::preset(unit).unwrap();
        let cart = table.cart(shakeflow::physics::rolling::Cart::default_trail_m(table.wheel_diameter_m), 0.02);
        let friction = table.friction(1e-4, FrictionLaw::Regularised);
        let (yaw0_rad, steer0_rad) = table.initial_pose();
        let options = shakeflow::physics::rolling::Options { yaw0_rad, steer0_rad, ..Default::default() };
        let adaptive = run(&floor, &cart, &friction, &options, Method::default());
        let rk4 = run(&floor, &cart, &friction, &options, Method::Rk4 { dt_s: 1e-4 });
        let d = (adaptive.peak_displacement().0 - rk4.peak_displacement().0).abs();
        let y = (adaptive.peak_yaw().0 - rk4.peak_yaw().0).abs();
        eprintln!(
            "RK4 (1e-4 s) vs adaptive, {unit}: peak displacement {:.5} vs {:.5} m (Δ {d:.1e}), peak yaw Δ {y:.1e} rad, {} vs {} evaluations",
            adaptive.peak_displacement().0,
            rk4.peak_displacement().0,
            adaptive.stats.rhs_evals,
            rk4.stats.rhs_evals
        );
        assert!(d < 1e-3 && y < 1e-3, "{unit}: Δ peak displacement {d} m, Δ peak yaw {y} rad");
    }
}
