use shakeflow::physics::rocking::*;
fn col(path: &str, name: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let k = header.iter().position(|h| *h == name).unwrap();
    lines.map(|l| l.split(',').nth(k).unwrap().trim().parse().unwrap_or(f64::NAN)).collect()
}
fn rect(b: f64, h: f64, f: f64) -> Block { Block::new(Shape::Rectangular { b_m: b, h_m: h, f }, 100.0, 9.81).unwrap() }
fn main() {
    let cases: Vec<(&str, Block, Options, bool)> = vec![
        ("demo_01", rect(0.349, 1.082, 0.085), Options::default(), true),
        ("demo_02", rect(0.66, 1.88, 0.0), Options { mass_change: Some(MassChange { time_s: 4.58848, after: rect(0.66, 1.88, -0.0445693) }), ..Options::default() }, false),
        ("demo_04", rect(0.349, 1.082, 0.085), Options { obstacle: Some(Obstacle { side: 1, angle_rad: 0.199619, restitution: 0.651663 }), ..Options::default() }, false),
        ("demo_03", rect(0.385, 1.278, 0.0241), Options::default(), false),
    ];
    for (id, block, opts, tilt) in cases {
        let d = format!("../shared/cases/demo/{id}");
        let (ax, az) = (col(&format!("{d}/floor.csv"), "ax_mps2"), col(&format!("{d}/floor.csv"), "az_mps2"));
        let obs = col(&format!("{d}/observed_accel.csv"), "top_ax_mps2");
        let (ct, cth) = (col(&format!("{d}/observed_cpt.csv"), "time_s"), col(&format!("{d}/observed_cpt.csv"), "theta_rad"));
        let ex = Excitation { t0_s: 0.0, dt_s: 0.005, horizontal_mps2: &ax, vertical_mps2: Some(&az) };
        for (label, o) in [("baseline", Options::default()), ("truth", opts)] {
            let r = simulate(&block, &ex, &o).unwrap();
            let pred: Vec<f64> = if tilt && label == "truth" {
                (0..ax.len()).map(|k| { let th = r.theta_rad[k]; if r.overturn.is_some_and(|(t, _)| k as f64 * 0.005 > t) { let s = f64::from(r.overturn.unwrap().1); -s * (az[k] + 9.81) } else { r.sensor_ax_mps2[k] * th.cos() - (r.sensor_az_mps2[k] + 9.81) * th.sin() } }).collect()
            } else { r.top_ax_mps2.clone() };
            let over = r.overturn.map(|o| o.0);
            // exclude 0.3 s after observed/ predicted overturn spikes
            let spike = |t: f64| [over, Some(0.0)].iter().flatten().any(|&o| o > 0.0 && t >= o - 0.02 && t < o + 0.3);
            let mut s2 = 0.0; let mut nn = 0; let mut worst = (0.0, 0.0);
            for k in 0..obs.len() { let t = k as f64 * 0.005; if spike(t) { continue; } let e = obs[k] - pred[k]; s2 += e * e; nn += 1; if e.abs() > worst.0 { worst = (e.abs(), t); } }
            let mut c2 = 0.0; let mut cn = 0;
            for (i, &tc) in ct.iter().enumerate() { if cth[i].is_nan() { continue; } let kf = tc / 0.005; let k0 = kf.floor() as usize; if k0 + 1 >= r.theta_rad.len() { continue; } let w = kf - k0 as f64; let th = r.theta_rad[k0] * (1.0 - w) + r.theta_rad[k0 + 1] * w; c2 += (cth[i] - th).powi(2); cn += 1; }
            println!("{id} {label}: overturn {:?}; accel rms {:.4} (worst {:.3} at {:.3}); cpt rms {:.5}", r.overturn, (s2 / nn as f64).sqrt(), worst.0, worst.1, (c2 / cn as f64).sqrt());
        }
    }
}
