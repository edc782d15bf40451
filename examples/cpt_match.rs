//! Times shakeflow's template matching per window, for `make bench` (bench/cpt.py): the same
//! windows and templates OpenCV's `matchTemplate` gets, read from a raw file written by the
//! script. Prints one JSON line: microseconds per window for every kernel this processor runs,
//! and the best ZNCC offset per window (from the fastest kernel) to check agreement.
//!
//! Usage: cpt_match FILE COUNT WINDOW TEMPLATE REPEAT
//!   FILE holds COUNT windows (WINDOW² bytes each, row-major) then COUNT templates (TEMPLATE² each).

use std::time::Instant;

use shakeflow::vision::image::GrayImage;
use shakeflow::vision::matcher::{match_template, Kernel, Score, Scratch, Template};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 6 {
        eprintln!("usage: cpt_match FILE COUNT WINDOW TEMPLATE REPEAT");
        std::process::exit(2);
    }
    let number =
        |i: usize| args[i].parse::<usize>().unwrap_or_else(|_| panic!("argument {i} is not a count: {}", args[i]));
    let (count, window, size, repeat) = (number(2), number(3), number(4), number(5));
    let bytes = std::fs::read(&args[1]).expect("the windows file is readable");
    assert_eq!(bytes.len(), count * (window * window + size * size), "file size");
    let (windows, templates) = bytes.split_at(count * window * window);
    let windows: Vec<GrayImage> =
        windows.chunks_exact(window * window).map(|w| GrayImage::new(window, window, w.to_vec())).collect();
    let templates: Vec<Template> =
        templates.chunks_exact(size * size).map(|t| Template::new(size, t.to_vec())).collect();
    let mut scratch = Scratch::default();
    let mut timings = Vec::new();
    let mut peaks = Vec::new();
    for kernel in Kernel::available() {
        let run = |scratch: &mut Scratch| {
            windows
                .iter()
                .zip(&templates)
                .map(|(w, t)| {
                    let map =
                        match_template(w, t, (0, 0), window, kernel, scratch).expect("the template fits the window");
                    let best = map.best(Score::Zncc);
                    [best % map.cols, best / map.cols]
                })
                .collect::<Vec<_>>()
        };
        peaks = run(&mut scratch); // warm-up, and the offsets to compare
        let started = Instant::now();
        for _ in 0..repeat {
            std::hint::black_box(run(&mut scratch));
        }
        let micros = started.elapsed().as_secs_f64() * 1e6 / (repeat * count) as f64;
        timings.push(format!("\"{}\": {micros:.3}", kernel.name()));
    }
    let peaks: Vec<String> = peaks.iter().map(|p| format!("[{},{}]", p[0], p[1])).collect();
    println!(
        "{{\"best_kernel\": \"{}\", \"us_per_window\": {{{}}}, \"peaks\": [{}]}}",
        Kernel::best().name(),
        timings.join(", "),
        peaks.join(",")
    );
}
