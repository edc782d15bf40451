//! Shared by the rolling tests: floor records made from real ground motions through the demo
//! building (stored beside the peers that read them), and the model run from a peer's parameters.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use serde_json::Value;
use shakeflow::demo::study::Base;
use shakeflow::physics::rolling::{
    simulate, Cart, Excitation, Friction, FrictionLaw, Method, Options, Response, Stribeck,
};

pub const G: f64 = 9.80665;

pub fn reference(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/reference").join(name)
}

fn ground_motion(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/ground_motions");
    assert!(dir.is_dir(), "the shared records are missing: these tests need {} beside the project root", dir.display());
    dir.join(name)
}

/// A two-component floor record on a uniform time base.
pub struct Floor {
    pub dt: f64,
    pub ax: Vec<f64>,
    pub ay: Vec<f64>,
}

impl Floor {
    pub fn excitation(&self) -> Excitation<'_> {
        Excitation { t0_s: 0.0, dt_s: self.dt, ax_mps2: &self.ax, ay_mps2: &self.ay }
    }

    /// The samples up to and including `t` seconds.
    pub fn first_seconds(&self, t: f64) -> Floor {
        let n = ((t / self.dt).round() as usize + 1).min(self.ax.len());
        Floor { dt: self.dt, ax: self.ax[..n].to_vec(), ay: self.ay[..n].to_vec() }
    }

    pub fn to_csv(&self) -> String {
        let mut text = String::from("time_s,ax_mps2,ay_mps2\n");
        for k in 0..self.ax.len() {
            text.push_str(&format!("{},{},{}\n", k as f64 * self.dt, self.ax[k], self.ay[k]));
        }
        text
    }

    pub fn read_csv(path: &Path) -> Floor {
        let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        let rows: Vec<Vec<f64>> =
            text.lines().skip(1).map(|l| l.split(',').map(|v| v.parse().expect("a number")).collect()).collect();
        let dt = (rows[rows.len() - 1][0] - rows[0][0]) / (rows.len() - 1) as f64;
        Floor { dt, ax: rows.iter().map(|r| r[1]).collect(), ay: rows.iter().map(|r| r[2]).collect() }
    }
}

/// Two horizontal ground components scaled together, through the demo building to floor 4.
fn through_building(x: &[f64], y: &[f64], dt: f64, peak_g: f64, base: Base) -> Floor {
    let peak = x.iter().chain(y).fold(0.0f64, |m, v| m.max(v.abs()));
    let scale = peak_g / peak * G;
    let gx: Vec<f64> = x.iter().map(|v| v * scale).collect();
    let gy: Vec<f64> = y.iter().map(|v| v * scale).collect();
    Floor {
        dt,
        ax: shakeflow::demo::archive::floor_response(base, 4, &gx, dt),
        ay: shakeflow::demo::archive::floor_response(base, 4, &gy, dt),
    }
}

/// 1994 Northridge, Rinaldi Receiving Station, components 228 (X) and 318 (Y), scaled to a
/// 0.25 g ground peak, floor 4 of the fixed-base demo building: 19.9 s at 100 Hz.
pub fn rinaldi_floor() -> Floor {
    rinaldi_floor_at(0.25, Base::Fixed)
}

/// The same record scaled to another ground peak, on either building.
pub fn rinaldi_floor_at(peak_g: f64, base: Base) -> Floor {
    let read = |name| shakeflow::io::records::read_at2(&ground_motion(name)).unwrap_or_else(|e| panic!("{e}"));
    let (x, y) = (read("Rinaldi228.AT2"), read("Rinaldi318.AT2"));
    through_building(&x.channels[0].values, &y.channels[0].values, x.dt.unwrap(), peak_g, base)
}

/// 2002 Denali, PEER RSN2113 (TAPS Pump Station #9, the study's DEN record), both horizontal
/// components from 20 s to 80 s (the strong part), scaled to a 0.15 g ground peak, floor 4 of
/// the fixed-base demo building: 60 s at 200 Hz.
pub fn denali_floor() -> Floor {
    let raw =
        shakeflow::io::records::read_simcenter_json(&ground_motion("RSN2113.json")).unwrap_or_else(|e| panic!("{e}"));
    let dt = raw.dt.unwrap();
    let window = 4000..16000;
    through_building(&raw.channels[0].values[window.clone()], &raw.channels[1].values[window], dt, 0.15, Base::Fixed)
}

/// Reads a peer's result file (JSON); its absence is a failure naming the script to run.
pub fn peer_json(name: &str, script: &str) -> Value {
    let path = reference(name);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{} missing ({e}); regenerate it with tests/reference/{script}", path.display()));
    serde_json::from_str(&text).expect("valid JSON")
}

fn number(spec: &Value, key: &str) -> f64 {
    spec[key].as_f64().unwrap_or_else(|| panic!("`{key}` missing from the peer's parameters"))
}

/// The cart, friction and initial pose a peer states in its JSON (simulate_rolling's keys).
pub fn model_from_peer(spec: &Value, law: FrictionLaw) -> (Cart, Friction, Options) {
    let cart = Cart {
        length_m: number(spec, "length_m"),
        width_m: number(spec, "width_m"),
        platform_mass_kg: number(spec, "platform_mass_kg"),
        wheel_diameter_m: number(spec, "wheel_diameter_m"),
        wheel_width_m: number(spec, "wheel_width_m"),
        wheel_mass_kg: number(spec, "wheel_mass_kg"),
        trail_m: number(spec, "trail_m"),
        swivel_arm_m: number(spec, "swivel_arm_m"),
    };
    let stribeck = |s, k| Stribeck {
        mu_s: number(spec, s),
        mu_k: number(spec, k),
        beta_spm: number(spec, "beta_spm"),
        gamma_n: number(spec, "gamma_n"),
        p: number(spec, "p"),
    };
    let friction = Friction {
        roll: stribeck("mu_s_roll", "mu_k_roll"),
        swivel: stribeck("mu_s_swivel", "mu_k_swivel"),
        eps_mps: number(spec, "friction_eps"),
        // A peer that regularises the swivel with tanh(ρδ̇/ε) (as shakeflow did before the swivel
        // had its own ε_sw) states no friction_eps_swivel: the same law is ε_sw = ε/ρ.
        eps_swivel_radps: spec
            .get("friction_eps_swivel")
            .and_then(Value::as_f64)
            .unwrap_or_else(|| number(spec, "friction_eps") / number(spec, "swivel_arm_m")),
        law,
    };
    let steer: Vec<f64> =
        spec["steer0_deg"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap().to_radians()).collect();
    let options = Options {
        yaw0_rad: number(spec, "yaw0_deg").to_radians(),
        steer0_rad: [steer[0], steer[1], steer[2], steer[3]],
        ..Options::default()
    };
    (cart, friction, options)
}

pub fn run(floor: &Floor, cart: &Cart, friction: &Friction, options: &Options, method: Method) -> Response {
    simulate(cart, friction, &floor.excitation(), &Options { method, ..*options }).unwrap()
}

pub fn series(v: &Value, key: &str) -> Vec<f64> {
    v[key].as_array().unwrap_or_else(|| panic!("no `{key}`")).iter().map(|x| x.as_f64().unwrap()).collect()
}
