use shakeflow::diagnose::{effects, evidence::Evidence, Settings};
use shakeflow::physics::rocking::{Method, Options};
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let case = shakeflow::io::case::read_case(std::path::Path::new(&args[1])).unwrap();
    let effect = effects::library().iter().find(|e| e.name() == args[2]).unwrap();
    let params: Vec<f64> = args[3..].iter().map(|v| v.parse().unwrap()).collect();
    let opts = case.nominal_options();
    let (_, base) = case.simulate(&case.block, &opts).unwrap();
    let (_, var) = case
        .simulate(
            &case.block,
            &Options { rest_amplitude_rad: 1e-5, method: Method::Adaptive { rtol: 1e-8, atol_rad: 1e-10 }, ..opts },
        )
        .unwrap();
    let ev = Evidence::new(&case, &base, &var, Settings::default().exceedance_sigma);
    let w = ev.window(&base).unwrap();
    let p = case.with_sensitivity(|c| effect.predict(c, &params)).unwrap();
    println!(
        "window {:?}; truth params misfit {:?}; rmse {:.3}; flagged {}; window of model {:?}",
        w,
        ev.misfit(&p),
        ev.window_rmse(&p, Some(w)),
        ev.flagged(&p),
        ev.window(&p)
    );
    for h in [1.5, 4.0, 10.0, 1e9] {
        println!("  until +{h}: {:?}", ev.misfit_until(&p, w.0 + h));
    }
    // The candidate under the variant solver settings: how much of it is solver-sensitive?
    let flex = shakeflow::physics::rocking::IsolatedBase {
        period_s: 1.0 / params[0],
        damping_ratio: params.get(1).copied().unwrap_or(0.05),
    };
    if args[2] == "flexibility" {
        let a = case.simulate(&case.block, &Options { isolated_base: Some(flex), ..opts }).unwrap().1;
        let b = case
            .simulate(
                &case.block,
                &Options {
                    isolated_base: Some(flex),
                    rest_amplitude_rad: 1e-5,
                    method: Method::Adaptive { rtol: 1e-8, atol_rad: 1e-10 },
                    ..opts
                },
            )
            .unwrap()
            .1;
        let n = a.top_ax_mps2.iter().zip(&b.top_ax_mps2).filter(|(x, y)| (*x - *y).abs() > 0.1).count();
        let first = a.top_ax_mps2.iter().zip(&b.top_ax_mps2).position(|(x, y)| (*x - *y).abs() > 0.1);
        let obs = case.accel.as_ref().unwrap();
        let cam = case.camera.as_ref().unwrap();
        let mut worst_rest = 0.0f64;
        let mut kmax = 0;
        for k in 0..a.top_ax_mps2.len() {
            if a.theta_rad[k] == 0.0 && k < 1600 {
                let d = (obs.value[k] - a.top_ax_mps2[k]).abs();
                if d > worst_rest {
                    worst_rest = d;
                    kmax = k;
                }
            }
        }
        println!("  at rest before 8 s: max |obs - model| {worst_rest:.4} at {}", kmax as f64 * case.dt_s);
        for (i, t) in cam.time_s.iter().enumerate() {
            let k = (t / case.dt_s).round() as usize;
            if k < a.theta_rad.len() && (cam.value[i] - a.theta_rad[k]).abs() > 0.01 {
                println!("  camera departs at {t:.3}: obs {:.4} model {:.4}", cam.value[i], a.theta_rad[k]);
                break;
            }
        }
        for k in 1600..1640 {
            println!(
                "   t {:.3} theta {:.6} obs {:.4} model {:.4} base {:.4}",
                k as f64 * case.dt_s,
                a.theta_rad[k],
                obs.value[k],
                a.top_ax_mps2[k],
                base.top_ax_mps2[k]
            );
        }
        println!(
            "  candidate solver-sensitive samples: {n} of {}, first at {:?}",
            a.top_ax_mps2.len(),
            first.map(|k| k as f64 * case.dt_s)
        );
    }
}
#[allow(dead_code)]
fn unused() {}
