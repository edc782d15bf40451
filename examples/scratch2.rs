fn main() {
    let args: Vec<String> = std::env::args().collect();
    let case = shakeflow::io::case::read_case(std::path::Path::new(&args[1])).unwrap();
    let opts = case.nominal_options();
    let (r, p) = case.simulate(&case.block, &opts).unwrap();
    let twin = case.with_sensitivity(|c| Ok(c.simulate(&c.block, &opts)?.1)).unwrap();
    let obs = case.accel.as_ref().unwrap();
    let cam = case.camera.as_ref().unwrap();
    println!("overturn {:?}", r.overturn);
    for k in (3300..3640).step_by(10) {
        println!(
            "t {:.3} theta {:.5} obs {:.4} model {:.4} unc {:.4} thunc {:.5}",
            k as f64 * case.dt_s,
            p.theta_rad[k],
            obs.value[k],
            p.top_ax_mps2[k],
            twin.top_ax_uncertainty_mps2[k],
            twin.theta_uncertainty_rad[k]
        );
    }
    let _ = cam;
}
