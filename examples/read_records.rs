//! Times shakeflow's record readers alone, for `make bench` (bench/load_formats.py): reads every
//! FILE with the FORMAT's reader, one after another on one thread, and prints one JSON line with
//! the seconds spent reading, the bytes read and the values parsed (their sum, so nothing is
//! optimised away).
//!
//! Usage: read_records FORMAT FILE...

use std::time::Instant;

use shakeflow::io::records::{self, ParseError, RawRecord};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((format, files)) = args.split_first() else {
        eprintln!("usage: read_records FORMAT FILE...");
        std::process::exit(2);
    };
    let read: fn(&std::path::Path) -> Result<RawRecord, ParseError> = match format.as_str() {
        "at2" => records::read_at2,
        "cosmos" => records::read_cosmos,
        "dmg" => records::read_dmg,
        "smc" => records::read_smc,
        "knet" => records::read_knet,
        "esm" => records::read_esm,
        "geonet" => records::read_geonet,
        other => {
            eprintln!("unknown format {other}");
            std::process::exit(2);
        }
    };
    let started = Instant::now();
    let (mut values, mut sum, mut bytes) = (0usize, 0.0f64, 0u64);
    for file in files {
        let path = std::path::Path::new(file);
        let record = read(path).unwrap_or_else(|e| {
            eprintln!("{e}");
            std::process::exit(1);
        });
        bytes += std::fs::metadata(path).map_or(0, |m| m.len());
        for channel in &record.channels {
            values += channel.values.len();
            sum += channel.values.iter().sum::<f64>();
        }
    }
    let seconds = started.elapsed().as_secs_f64();
    println!("{{\"seconds\": {seconds}, \"bytes\": {bytes}, \"values\": {values}, \"sum\": {sum}}}");
}
