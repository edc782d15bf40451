//! The lognormal fragility fit (src/stats/fragility.rs) against scipy's maximum-likelihood fit
//! of the same outcomes (tests/reference/fragility_scipy.py → fragility_scipy.json, Nelder–Mead
//! to 1e-12): median and β agree to 1e-6 relative, the log-likelihood to 1e-9.
use shakeflow::stats::fragility::{fit_lognormal, FitOutcome};

#[test]
fn matches_scipy_maximum_likelihood() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/reference/fragility_scipy.json");
    let reference: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let im: Vec<f64> = reference["im"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    let overturned: Vec<bool> =
        reference["overturned"].as_array().unwrap().iter().map(|v| v.as_bool().unwrap()).collect();
    let FitOutcome::Fitted(fit) = fit_lognormal(&im, &overturned) else { panic!("expected a fit") };
    let (median, beta, ll) = (
        reference["median"].as_f64().unwrap(),
        reference["beta"].as_f64().unwrap(),
        reference["log_likelihood"].as_f64().unwrap(),
    );
    println!("shakeflow θ {} β {} ll {}; scipy θ {median} β {beta} ll {ll}", fit.median, fit.beta, fit.log_likelihood);
    assert!((fit.median - median).abs() / median < 1e-6);
    assert!((fit.beta - beta).abs() / beta < 1e-6);
    assert!((fit.log_likelihood - ll).abs() < 1e-9 * ll.abs());
}
