fn main() {
    for id in ["demo_01", "demo_02", "demo_03", "demo_04"] {
        let started = std::time::Instant::now();
        let case = shakeflow::io::case::read_case(std::path::Path::new(&format!("../shared/cases/demo/{id}"))).unwrap();
        let d = shakeflow::diagnose::diagnose(&case, &Default::default()).unwrap();
        println!(
            "{id}: verdict {} window {:?} rmse {:.2} -> {:.2} ({:.1}s)",
            d.verdict,
            d.window,
            d.rmse_before,
            d.rmse_after,
            started.elapsed().as_secs_f64()
        );
        for c in &d.candidates {
            println!(
                "   {:16} bic {:12.1} rmse {:8.2} flagged {:5} score {:.3} evals {} {:?}",
                c.effect, c.bic, c.rmse, c.flagged, c.score, c.evaluations, c.params
            );
        }
        println!("   {}", d.explanation);
    }
}
