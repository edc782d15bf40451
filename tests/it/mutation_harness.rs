//! A bounded, deterministic mutation harness over every reader of user files, the pipeline
//! parser and the output folder's state (a lockfile root over stages kept in buckets), run by `make test` (the coverage-guided fuzzers in `fuzz/` go further; see
//! docs/fuzzing.md). Seeds are the real files in ../shared/data, the case files and the demo
//! pipeline; a fixed-seed PRNG mutates their bytes (bit flips, random bytes, truncations, runs
//! of digits such as 99999999999, duplicated, dropped and swapped lines, NULs, byte-order
//! marks). Every reader must return a value or an error: a panic is caught and reported with
//! the input that caused it, an abort fails the whole test binary.

use crate::common::*;

use serde_json::json;
use shakeflow::io::records::{self, DelimitedOptions};
use shakeflow::signal::synthetic_motion::SplitMix64;
use shakeflow::stages::{load, InputPart};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

/// Mutations per reader: a few seconds in the test profile.
const MUTATIONS: usize = 2000;
/// Mutated prefix of a seed: the headers and the first rows, where the parsers branch.
const PREFIX: usize = 8 << 10;

/// Text that has broken parsers: counts beyond memory, overflows, odd numbers and names.
const TOKENS: &[&str] = &[
    "99999999999",
    "18446744073709551615",
    "18446744073709551616",
    "-1",
    "0",
    "1e308",
    "-1e308",
    "1e-320",
    "NaN",
    "inf",
    "time_s",
    "NPTS=",
    "DT=",
    "NO. OF POINTS =",
    "\"data_x\": [",
    "*a",
    "&a ",
    "\u{feff}",
    ",,,,",
    "\t",
    "\r",
    "\0",
    "é",
];

fn seeds() -> Vec<(String, Vec<u8>)> {
    let shared = shared_dir();
    let mut files: Vec<PathBuf> = Vec::new();
    for dir in ["data/ground_motions", "data/records"] {
        let root = shared.join(dir);
        for entry in shakeflow::io::hash::list_files(&root).unwrap() {
            files.push(root.join(entry));
        }
    }
    for case in ["cases/demo/demo_01", "cases/rolling_demo/demo_01"] {
        for file in ["equipment.yaml", "floor.csv", "observed_accel.csv", "observed_cpt.csv"] {
            files.push(shared.join(case).join(file));
        }
    }
    files.push(Path::new(env!("CARGO_MANIFEST_DIR")).join("pipelines/demo.yaml"));
    let mut seeds: Vec<(String, Vec<u8>)> = files
        .into_iter()
        .filter(|f| !f.ends_with("SOURCES.md"))
        .map(|f| (f.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read(&f).unwrap()))
        .collect();
    seeds.push((
        "control_points.csv".into(),
        b"# surveyed\npoint,X_mm,Y_mm,Z_mm,u_px,v_px\nA,0,0,0,10.5,20\nB,100,0,0,110,21\nC,0,100,50,12,90\n".to_vec(),
    ));
    seeds.push((PIPELINE_NAME.into(), PIPELINE.as_bytes().to_vec()));
    seeds.push(("shakeflow.lock".into(), lock_seed().root));
    assert!(seeds.len() > 30, "too few seeds: {}", seeds.len());
    seeds
}

const PIPELINE_NAME: &str = "small_pipeline.yaml";

/// A state of two stages, one past the fan-out limit (kept in buckets): its root is the
/// lockfile reader's seed, its files what the mutated roots name.
fn lock_seed() -> shakeflow::pipeline::lock::NewState {
    use shakeflow::pipeline::lock::{LockFile, StageLock, UnitLock};
    use std::collections::BTreeMap;
    let unit = |id: &str| UnitLock {
        key: format!("k-{id}"),
        inputs: BTreeMap::from([("source daq".to_string(), format!("in-{id}"))]),
        files: BTreeMap::from([(format!("records/{id}/data.parquet"), format!("out-{id}"))]),
        flagged: None,
        notes: Vec::new(),
    };
    let stage = |ids: Vec<String>| StageLock {
        stage_type: "load".into(),
        stage_version: 3,
        params: json!({}),
        select: BTreeMap::new(),
        units: ids.iter().map(|id| (id.clone(), unit(id))).collect(),
    };
    let mut lock = LockFile::empty();
    lock.pipeline = Some("../pipeline.yaml".into());
    lock.stages.insert("load".into(), stage((0..1100).map(|m| format!("motion=M{m}")).collect()));
    lock.stages.insert("report".into(), stage(vec!["*".into()]));
    lock.encode(&LockFile::empty()).unwrap()
}

fn below(rng: &mut SplitMix64, n: usize) -> usize {
    (rng.next_u64() % n.max(1) as u64) as usize
}

/// Line spans (start, end with its newline) of `bytes`.
fn lines(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut spans = Vec::new();
    let mut start = 0;
    for (i, &b) in bytes.iter().enumerate() {
        if b == b'\n' {
            spans.push((start, i + 1));
            start = i + 1;
        }
    }
    if start < bytes.len() {
        spans.push((start, bytes.len()));
    }
    spans
}

/// One to three mutations of `seed` (its first PREFIX bytes, or the whole file one time in 64).
fn mutate(rng: &mut SplitMix64, seed: &[u8]) -> Vec<u8> {
    let mut out = if below(rng, 64) == 0 { seed.to_vec() } else { seed[..seed.len().min(PREFIX)].to_vec() };
    for _ in 0..1 + below(rng, 3) {
        let len = out.len();
        match below(rng, 9) {
            0 if len > 0 => {
                let at = below(rng, len);
                out[at] ^= 1 << below(rng, 8);
            }
            1 if len > 0 => {
                let at = below(rng, len);
                out[at] = rng.next_u64() as u8;
            }
            2 => out.truncate(below(rng, len + 1)),
            3 => {
                // A token in place of a number (or anywhere).
                let at = below(rng, len + 1);
                let end = out[at..].iter().position(|b| !b.is_ascii_digit() && *b != b'.').map_or(len, |p| at + p);
                let token = TOKENS[below(rng, TOKENS.len())].as_bytes();
                out.splice(at..end, token.iter().copied());
            }
            4 | 5 => {
                let spans = lines(&out);
                if spans.is_empty() {
                    continue;
                }
                let (a, b) = spans[below(rng, spans.len())];
                let line = out[a..b].to_vec();
                match below(rng, 3) {
                    0 => {
                        out.splice(b..b, line);
                    }
                    1 => {
                        out.drain(a..b);
                    }
                    _ => {
                        let (c, d) = spans[below(rng, spans.len())];
                        if d <= a {
                            let other = out[c..d].to_vec();
                            out.splice(a..b, other);
                            out.splice(c..d, line);
                        }
                    }
                }
            }
            6 => {
                // A run of digits where a count is.
                let at = below(rng, len + 1);
                let digits = vec![b'9'; 1 + below(rng, 25)];
                out.splice(at..at, digits);
            }
            7 if len > 1 => {
                // A block copied over another place: repeated headers, names, keys.
                let (a, b) = (below(rng, len), below(rng, len));
                let n = below(rng, 64).min(len - a.max(b));
                let block = out[a..a + n].to_vec();
                out.splice(b..b + n, block);
            }
            _ => {
                let encoded = match below(rng, 3) {
                    0 => [&[0xff, 0xfe][..], &out].concat(),
                    1 => [&b"\xef\xbb\xbf"[..], &out].concat(),
                    _ => String::from_utf8_lossy(&out).encode_utf16().flat_map(u16::to_le_bytes).collect(),
                };
                out = encoded;
            }
        }
    }
    out
}

type Reader = fn(&[u8], &Path);

fn readers() -> Vec<(&'static str, Reader)> {
    vec![
        ("at2", |b, _| drop(records::parse_at2(Path::new("m.AT2"), b))),
        ("renadic_v1", |b, _| drop(records::parse_renadic_v1(Path::new("m.v1"), b))),
        ("simcenter_json", |b, _| drop(records::parse_simcenter_json(Path::new("m.json"), b))),
        ("delimited", |b, _| {
            for (delimiter, header_lines, has_column_names) in
                [(None, 0, true), (Some(b','), 2, true), (Some(b' '), 0, false)]
            {
                let opts =
                    DelimitedOptions { delimiter, header_lines, has_column_names, ..DelimitedOptions::default() };
                drop(records::parse_delimited(Path::new("m.csv"), b, &opts));
            }
        }),
        ("control_points", |b, _| {
            if let Ok(text) = records::decode(Path::new("cp.csv"), b) {
                drop(shakeflow::io::control_points::parse(Path::new("cp.csv"), &text));
            }
        }),
        ("equipment", |b, _| {
            if let Ok(text) = records::decode(Path::new("equipment.yaml"), b) {
                drop(shakeflow::io::equipment::parse_rocking_equipment(Path::new("equipment.yaml"), &text));
            }
        }),
        ("pipeline", |b, _| {
            let Ok(text) = std::str::from_utf8(b) else { return };
            let path = Path::new("/nonexistent-shakeflow-harness/pipeline.yaml");
            if let Ok(file) = shakeflow::pipeline::spec::PipelineFile::parse(path, text.to_string()) {
                drop(shakeflow::pipeline::plan::Plan::new(file, shakeflow::stages::registry()));
            }
        }),
        ("lockfile", |b, scratch| {
            use shakeflow::pipeline::lock::{state_dir, LockFile, Wanted};
            let root = scratch.with_file_name("state-root").join("shakeflow.lock");
            let states = state_dir(&root);
            if !states.is_dir() {
                std::fs::create_dir_all(&states).unwrap();
                for (name, bytes) in lock_seed().files {
                    std::fs::write(states.join(name), bytes).unwrap();
                }
            }
            std::fs::write(&root, b).unwrap();
            drop(LockFile::read(&root));
            let some = Wanted::from([("load".to_string(), Some([0x00, 0x3f, 0xff].into()))]);
            drop(LockFile::read_stages(&root, &some));
        }),
        ("load", |b, scratch| {
            std::fs::write(scratch, b).unwrap();
            let part =
                InputPart { partition: vec![], path: scratch.to_path_buf(), label: "m".into(), hash: String::new() };
            for spec in [
                json!({"format": "at2", "path": "m", "gaps": "interpolate"}),
                json!({"format": "renadic_v1", "path": "m"}),
                json!({"format": "simcenter_json", "path": "m"}),
                json!({"format": "csv", "path": "m", "time_column": "time", "unit": "g", "non_uniform": "resample", "gaps": "interpolate"}),
                json!({"format": "delimited", "path": "m", "dt": 0.005, "unit": "m/s^2", "column_names": false}),
            ] {
                drop(load::load_record(&serde_json::from_value(spec).unwrap(), &part));
            }
        }),
    ]
}

/// Which seeds a reader mutates mostly (the rest of its inputs come from every other seed).
fn own_format(reader: &str, seed: &str) -> bool {
    let lower = seed.to_ascii_lowercase();
    match reader {
        "at2" => lower.ends_with(".at2"),
        "renadic_v1" => lower.ends_with(".v1"),
        "simcenter_json" => lower.ends_with(".json"),
        "delimited" | "control_points" => lower.ends_with(".csv"),
        "equipment" => lower == "equipment.yaml",
        "pipeline" => lower.ends_with(".yaml") && lower != "equipment.yaml",
        "lockfile" => lower == "shakeflow.lock",
        _ => true,
    }
}

#[test]
fn every_reader_survives_thousands_of_mutations() {
    let seeds = seeds();
    let scratch_dir = crate::tempdir::tempdir().unwrap();
    let scratch = scratch_dir.path().join("mutated");
    let mut failures = Vec::new();
    for (index, (name, reader)) in readers().into_iter().enumerate() {
        let own: Vec<&(String, Vec<u8>)> = seeds.iter().filter(|(s, _)| own_format(name, s)).collect();
        assert!(!own.is_empty(), "no seed for {name}");
        let mut rng = SplitMix64::new(0x5eed_0000 + index as u64);
        // Unmutated seeds first: they must not panic either.
        let mut inputs: Vec<(String, Vec<u8>)> = own.iter().map(|(s, b)| (s.clone(), b.clone())).collect();
        for k in 0..MUTATIONS {
            let (seed_name, bytes) = if k % 4 == 3 { &seeds[below(&mut rng, seeds.len())] } else { own[k % own.len()] };
            inputs.push((format!("{seed_name} mutation {k}"), mutate(&mut rng, bytes)));
        }
        for (what, bytes) in inputs {
            if catch_unwind(AssertUnwindSafe(|| reader(&bytes, &scratch))).is_err() {
                let kept = std::env::temp_dir().join(format!("shakeflow-harness-{name}-{}", failures.len()));
                std::fs::write(&kept, &bytes).unwrap();
                failures.push(format!("{name} panicked on {what} (input kept in {})", kept.display()));
            }
        }
    }
    assert!(failures.is_empty(), "{} panic(s):\n{}", failures.len(), failures.join("\n"));
}
