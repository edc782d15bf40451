use shakeflow::diagnose::{effects, evidence::Evidence, Settings};
use shakeflow::physics::rocking::{Method, Options};
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let case = shakeflow::io::case::read_case(std::path::Path::new(&args[1])).unwrap();
    let effect = effects::library().iter().find(|e| e.name() == "flexibility").unwrap();
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
    for f in [4.78, 4.80, 4.81, 4.815, 4.82, 4.825, 4.83, 4.85] {
        let row: Vec<String> = [0.022, 0.025, 0.0265, 0.028, 0.031]
            .iter()
            .map(|z| {
                let p = effect.predict(&case, &[f, *z]).unwrap();
                format!("{:8.0}", ev.misfit_until(&p, w.0 + 1.5).chi2)
            })
            .collect();
        println!("f {f}: {}", row.join(" "));
    }
}
