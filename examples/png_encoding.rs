//! PNG compression of a stage figure: size and encoding time per compression level and row
//! filter (docs/benchmarks.md, "Figures"). Renders a figure like `simulate_toppling`'s (three
//! stacked panels over a 60 s record at 200 Hz), decodes it to its RGB pixels, then encodes the
//! pixels with each setting, median of --repeat runs. Prints one line per setting.
//!
//! Usage: png_encoding [--repeat N]

use std::time::Instant;

use shakeflow::plot::{encode_rgb_png, render_png, Marker, Panel, RowFilter, Series};

fn figure() -> Vec<u8> {
    let n = 12_000;
    let t: Vec<f64> = (0..n).map(|k| k as f64 / 200.0).collect();
    // A deterministic, broadband floor motion and a block's response to it.
    let floor: Vec<f64> = t
        .iter()
        .map(|&s| {
            let env = (s / 8.0).min(1.0) * (-(s - 20.0).max(0.0) / 15.0).exp();
            env * (3.1 * (2.0 * s).sin() + 1.7 * (7.3 * s + 0.4).sin() + 0.9 * (19.0 * s + 1.1).sin())
        })
        .collect();
    let top: Vec<f64> = floor.iter().enumerate().map(|(k, a)| a * 1.4 + 0.3 * (k as f64 * 0.37).sin()).collect();
    let theta: Vec<f64> = t.iter().map(|&s| 0.02 * (-(s - 18.0).powi(2) / 20.0).exp() * (4.0 * s).sin()).collect();
    let panels = [
        Panel {
            title: "floor acceleration".into(),
            x_label: "time (s)".into(),
            y_label: "m/s²".into(),
            series: vec![Series::new("floor", &t, &floor)],
            ..Panel::default()
        },
        Panel {
            title: "top acceleration".into(),
            x_label: "time (s)".into(),
            y_label: "m/s²".into(),
            series: vec![Series::new("top", &t, &top)],
            ..Panel::default()
        },
        Panel {
            title: "rotation".into(),
            x_label: "time (s)".into(),
            y_label: "rad".into(),
            series: vec![Series::new("θ", &t, &theta)],
            markers: vec![Marker { x: 12.0, label: "uplift".into() }, Marker { x: 25.0, label: "rest".into() }],
            ..Panel::default()
        },
    ];
    render_png("PS2: rocking model under FB-4", &panels, 1100, 900).expect("a figure")
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let repeat: usize = args.iter().position(|a| a == "--repeat").map_or(9, |i| args[i + 1].parse().expect("a count"));
    let png_bytes = figure();
    let decoder = png::Decoder::new(png_bytes.as_slice());
    let mut reader = decoder.read_info().expect("our own PNG");
    let mut rgb = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut rgb).expect("a frame");
    let (w, h) = (info.width, info.height);
    println!("figure {w}x{h}, {} raw RGB bytes", rgb.len());
    #[allow(deprecated)]
    let levels = [
        ("fast (fdeflate)", png::Compression::Fast),
        ("default (zlib 6)", png::Compression::Default),
        ("best (zlib 9)", png::Compression::Best),
    ];
    let filters = [
        ("none", png::FilterType::NoFilter),
        ("sub", png::FilterType::Sub),
        ("up", png::FilterType::Up),
        ("paeth", png::FilterType::Paeth),
    ];
    println!("{:<18}{:<8}{:>10}{:>10}", "compression", "filter", "bytes", "ms");
    for (lname, level) in levels {
        for (fname, filter) in filters {
            let mut times = Vec::new();
            let mut size = 0;
            for _ in 0..repeat {
                let started = Instant::now();
                let mut out = Vec::new();
                {
                    let mut enc = png::Encoder::new(&mut out, w, h);
                    enc.set_color(png::ColorType::Rgb);
                    enc.set_depth(png::BitDepth::Eight);
                    enc.set_compression(level);
                    enc.set_filter(filter);
                    let mut writer = enc.write_header().expect("header");
                    writer.write_image_data(&rgb).expect("pixels");
                    writer.finish().expect("end");
                }
                times.push(started.elapsed().as_secs_f64());
                size = out.len();
            }
            times.sort_by(f64::total_cmp);
            println!("{lname:<18}{fname:<8}{size:>10}{:>10.2}", 1e3 * times[times.len() / 2]);
        }
    }
    println!("zlib through shakeflow::plot::encode_rgb_png:");
    for level in [1, 2, 3, 4, 6, 9] {
        for (fname, filter) in [("none", RowFilter::None), ("sub", RowFilter::Sub), ("up", RowFilter::Up)] {
            let mut times = Vec::new();
            let mut size = 0;
            for _ in 0..repeat {
                let started = Instant::now();
                size = encode_rgb_png(&rgb, w, h, level, filter).len();
                times.push(started.elapsed().as_secs_f64());
            }
            times.sort_by(f64::total_cmp);
            println!("{:<18}{fname:<8}{size:>10}{:>10.2}", format!("zlib {level}"), 1e3 * times[times.len() / 2]);
        }
    }
    let mut times = Vec::new();
    for _ in 0..repeat {
        let started = Instant::now();
        std::hint::black_box(figure());
        times.push(started.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    println!("render + encode as plot.rs does (FIGURE_COMPRESSION): {:.2} ms", 1e3 * times[times.len() / 2]);
}
