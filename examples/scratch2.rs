use shakeflow::diagnose::{effects, evidence::Evidence, Settings};
use shakeflow::physics::rocking::{Method, Options};
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let case = shakeflow::io::case::read_case(std::path::Path::new(&args[1])).unwrap();
    let effect = effects::library().iter().find(|e| e.name() == "obstacle_impact").unwrap();
    let opts = case.nominal_options();
    let base = case.with_sensitivity(|c| Ok(c.simulate(&c.block, &opts)?.1)).unwrap();
    let (_, var) = case
        .simulate(
            &case.block,
            &Options { rest_amplitude_rad: 1e-5, method: Method::Adaptive { rtol: 1e-8, atol_rad: 1e-10 }, ..opts },
        )
        .unwrap();
    let ev = Evidence::new(&case, &base, &var, Settings::default().exceedance_sigma);
    let w = ev.window(&base).unwrap();
    for a in [0.125, 0.13, 0.1308, 0.135, 0.1384, 0.14, 0.145] {
        let row: Vec<String> = [0.2, 0.3, 0.33, 0.366, 0.4, 0.5]
            .iter()
            .map(|e| {
                let p = effect.predict(&case, &[-1.0, a, *e]).unwrap();
                format!("{:8.0}", ev.misfit_until(&p, w.0 + 1.5).chi2)
            })
            .collect();
        println!("a {a}: {}", row.join(" "));
    }
}
