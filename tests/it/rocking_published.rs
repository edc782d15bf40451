//! The rocking model against published results and its own reference integrator, on real
//! records from ../shared/data/ground_motions:
//! - Makris & Zhang (2001) as the study reproduced it (SEED-SUMMARY.md): a block of half-width
//!   b = 2 m and half-height h = 6 m under Rinaldi 228. Free-standing it must not overturn up to
//!   3 × PGA (the study's independent check); anchored (F/W = 0.4, μ = 5) it overturns at a lower
//!   scale, which the study put at 1.19 (no overturn at 1.18).
//! - The study's integrator, RK4 at dt = 1e-4 s: the adaptive integrator gives the same event
//!   sequence and |Δθ| < 1e-4 rad on every sample. (Between impacts the block is an inverted
//!   pendulum, so differences grow like e^(pt): on Chi-Chi TCU078, RK4 at 1e-4 s and at 5e-5 s
//!   themselves differ by 3.4e-5 rad; the adaptive default, rtol 1e-11, stays within that.)
use shakeflow::physics::rocking::{
    simulate, Anchorage, Block, EventKind, Excitation, Method, Options, Response, Shape,
};
use shakeflow::units::G0;

fn record(name: &str) -> (f64, Vec<f64>) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/ground_motions").join(name);
    assert!(
        path.is_file(),
        "{} is missing: the tests need ../shared/data/ground_motions beside the project root",
        path.display()
    );
    let raw = shakeflow::io::records::read_at2(&path).unwrap_or_else(|e| panic!("{e}"));
    (raw.dt.expect("AT2 states DT"), raw.channels[0].values.iter().map(|g| g * G0).collect())
}

fn run(block: &Block, dt: f64, acc: &[f64], scale: f64, options: &Options) -> Response {
    let scaled: Vec<f64> = acc.iter().map(|a| a * scale).collect();
    simulate(block, &Excitation { t0_s: 0.0, dt_s: dt, horizontal_mps2: &scaled, vertical_mps2: None }, options)
        .unwrap()
}

fn makris_zhang_block() -> Block {
    let block = Block::new(Shape::Rectangular { b_m: 4.0, h_m: 12.0, f: 0.0 }, 1.0, G0).unwrap();
    // SEED-SUMMARY.md: α = 0.322 rad, p = 1.08 rad/s, e = 0.85.
    assert!((block.alpha_rad - 0.322).abs() < 5e-4 && (block.p_radps - 1.08).abs() < 5e-3);
    assert!((block.restitution_eq24 - 0.85).abs() < 1e-12);
    block
}

#[test]
fn free_standing_block_survives_rinaldi_up_to_three_times_its_pga() {
    let (dt, acc) = record("Rinaldi228.AT2");
    let block = makris_zhang_block();
    for step in 0..=200 {
        let scale = 1.0 + 0.01 * f64::from(step);
        let r = run(&block, dt, &acc, scale, &Options::default());
        assert!(r.overturn.is_none(), "the free block overturned at {scale:.2} × PGA: {:?}", r.overturn);
    }
}

/// Smallest scale in [lo, hi] at which `overturns` is true, by bisection to `tol`.
fn bisect(mut lo: f64, mut hi: f64, tol: f64, overturns: impl Fn(f64) -> bool) -> f64 {
    assert!(!overturns(lo) && overturns(hi), "the bracket must straddle the overturning scale");
    while hi - lo > tol {
        let mid = 0.5 * (lo + hi);
        if overturns(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi
}

#[test]
fn anchored_block_overturns_earlier_than_the_free_one() {
    let (dt, acc) = record("Rinaldi228.AT2");
    let block = makris_zhang_block();
    let anchored = |yield_rotation_rad| Options {
        anchorage: Some(Anchorage { strength_ratio: 0.4, ductility: 5.0, yield_rotation_rad }),
        ..Options::default()
    };
    let options = anchored(1e-3);
    let overturns = |s: f64| run(&block, dt, &acc, s, &options).overturn.is_some();
    // Overturning is not monotonic in the scale (rocking has safe windows above unsafe ones), so
    // a 0.01 scan brackets the first overturning scale and bisection refines it.
    let first = (0..=200).map(|i| 1.0 + 0.01 * f64::from(i)).find(|&s| overturns(s)).expect("overturns below 3 × PGA");
    let critical = bisect(first - 0.01, first, 1e-4, overturns);
    let r = run(&block, dt, &acc, critical, &options);
    let fractured = r.events.iter().filter(|e| e.kind == EventKind::AnchorFracture).count();
    println!(
        "anchored (F/W 0.4, μ 5, θy 1e-3): overturns from {critical:.3} × PGA (study: 1.19), side {:?}, {fractured} anchor(s) fractured first",
        r.overturn.map(|o| o.1)
    );
    assert!(fractured >= 1, "an anchored block can only overturn after its anchor fractured");
    let first_fracture = r.events.iter().find(|e| e.kind == EventKind::AnchorFracture).unwrap().time_s;
    assert!(first_fracture < r.overturn.unwrap().0);
    // The study's finding that matters for design: anchoring can make overturning likelier
    // (it overturns well below the 3 × PGA the free block survives) — and not at 1.18 × PGA.
    assert!(critical < 3.0 && critical > 1.18, "critical scale {critical}");
    // Our anchorage law gives 2.05, not the study's 1.19 (README: "Why the anchored block differs"):
    // pinned to ±0.02 so that any change of the rocking or anchorage model shows here.
    assert!((critical - 2.05).abs() < 0.02, "critical scale {critical}, documented 2.05");
    // The anchorage law is the main uncertainty (see README): the scale for other yield rotations,
    // 2.03–2.42 × PGA as documented, always below the free block's 3 × PGA.
    for yield_rotation in [1e-4, 5e-3, 2e-2] {
        let options = anchored(yield_rotation);
        let first = (0..=400)
            .map(|i| 1.0 + 0.005 * f64::from(i))
            .find(|&s| run(&block, dt, &acc, s, &options).overturn.is_some());
        println!("  θy = {yield_rotation}: first overturn at {first:?} × PGA");
        let first = first.expect("overturns below 3 × PGA");
        assert!((2.0..2.45).contains(&first), "θy = {yield_rotation}: first overturn at {first} × PGA");
    }
}

#[test]
fn adaptive_integration_matches_rk4_at_the_study_step_on_real_records() {
    // PS2 (Table 5 rectangle) under five real records, scaled so it rocks; three overturn.
    let block = Block::new(Shape::Rectangular { b_m: 0.349, h_m: 1.082, f: 0.085 }, 150.0, 9.81).unwrap();
    let rk4 = Options { method: Method::Rk4 { dt_s: 1e-4 }, ..Options::default() };
    let mut overturned = 0;
    for (name, scale) in [
        ("RSN6_IMPVALL.I_I-ELC180.AT2", 1.4),
        ("RSN1084_NORTHR_SCS052.AT2", 0.7),
        ("RSN763_LOMAP_GIL067.AT2", 1.0),
        ("NIS090.AT2", 0.8),
        ("RSN1512_CHICHI_TCU078-E.AT2", 0.9),
    ] {
        let (dt, acc) = record(name);
        let adaptive = run(&block, dt, &acc, scale, &Options::default());
        let reference = run(&block, dt, &acc, scale, &rk4);
        let sequence = |r: &Response| r.events.iter().map(|e| (e.kind, e.side)).collect::<Vec<_>>();
        assert_eq!(sequence(&adaptive), sequence(&reference), "{name}: event sequences differ");
        let worst = adaptive.theta_rad.iter().zip(&reference.theta_rad).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        let worst_time =
            adaptive.events.iter().zip(&reference.events).map(|(a, b)| (a.time_s - b.time_s).abs()).fold(0.0, f64::max);
        println!(
            "{name} × {scale}: {} events, overturn {:?}; max |Δθ| {worst:.1e} rad, max event-time difference {worst_time:.1e} s; RHS evaluations {} vs {} (RK4)",
            adaptive.events.len(),
            adaptive.overturn,
            adaptive.stats.rhs_evals,
            reference.stats.rhs_evals
        );
        assert!(adaptive.events.len() > 3, "{name}: the block should rock");
        assert!(worst < 1e-4, "{name}: max |Δθ| = {worst} rad");
        // Events at the same times: within 4e-7 s on four records; Chi-Chi's 220 events drift
        // apart by 3.2e-3 s (RK4's own error at 1e-4 s there, README).
        assert!(worst_time < 5e-3, "{name}: event times differ by up to {worst_time} s");
        overturned += usize::from(adaptive.overturn.is_some());
    }
    assert!((1..5).contains(&overturned), "a mix of overturning and surviving runs: {overturned}");
}
