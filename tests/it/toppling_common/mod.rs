//! Shared helpers of the integration tests: CSV, truth YAML line matching, a tiny JSON parser,
//! result table.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub const G: f64 = 9.80665;
pub const SHARED: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared");
pub const DEMO_DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/cases/demo");

/// Panics with a clear message if ../shared (the test data) is missing.
pub fn require_shared() -> PathBuf {
    let p = PathBuf::from(DEMO_DIR);
    assert!(
        p.is_dir(),
        "test data missing: {DEMO_DIR} not found (these tests need the shared demo cases under {SHARED})"
    );
    p
}

/// A CSV table: lines starting with '#' are skipped, the first other line is the header.
pub struct Csv {
    pub header: Vec<String>,
    pub cols: Vec<Vec<f64>>,
}

impl Csv {
    pub fn read(path: &Path) -> Csv {
        let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        let mut lines = text.lines().filter(|l| !l.starts_with('#') && !l.trim().is_empty());
        let header: Vec<String> = lines
            .next()
            .unwrap_or_else(|| panic!("{} has no header", path.display()))
            .split(',')
            .map(|s| s.trim().to_string())
            .collect();
        let mut cols = vec![Vec::new(); header.len()];
        for l in lines {
            for (k, v) in l.split(',').enumerate().take(header.len()) {
                cols[k].push(v.trim().parse::<f64>().unwrap_or(f64::NAN));
            }
        }
        Csv { header, cols }
    }
    pub fn col(&self, name: &str) -> &[f64] {
        let k = self
            .header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("column {name} not in {:?}", self.header));
        &self.cols[k]
    }
}

/// Value of a top-level (unindented) `key: value` line of a YAML file.
pub fn yaml_top(text: &str, key: &str) -> Option<String> {
    let prefix = format!("{key}:");
    text.lines()
        .find(|l| l.starts_with(&prefix))
        .map(|l| l[prefix.len()..].trim().trim_matches('\'').trim_matches('"').to_string())
}

/// Minimal JSON value and parser (enough for manifest.json).
#[derive(Clone, Debug)]
pub enum Json {
    Null,
    Bool(bool),
    Num(f64),
    Str(String),
    Arr(Vec<Json>),
    Obj(BTreeMap<String, Json>),
}

impl Json {
    pub fn parse(s: &str) -> Json {
        let b = s.as_bytes();
        let mut i = 0;
        parse_value(b, &mut i)
    }
    pub fn get(&self, k: &str) -> &Json {
        match self {
            Json::Obj(m) => m.get(k).unwrap_or_else(|| panic!("json key {k} missing")),
            _ => panic!("not an object (looking for {k})"),
        }
    }
    pub fn arr(&self) -> &[Json] {
        match self {
            Json::Arr(v) => v,
            _ => panic!("not an array"),
        }
    }
    pub fn num(&self) -> f64 {
        match self {
            Json::Num(v) => *v,
            _ => panic!("not a number: {self:?}"),
        }
    }
    pub fn str(&self) -> &str {
        match self {
            Json::Str(v) => v,
            _ => panic!("not a string: {self:?}"),
        }
    }
}

fn ws(b: &[u8], i: &mut usize) {
    while *i < b.len() && b[*i].is_ascii_whitespace() {
        *i += 1;
    }
}

fn parse_value(b: &[u8], i: &mut usize) -> Json {
    ws(b, i);
    match b[*i] {
        b'{' => {
            *i += 1;
            let mut m = BTreeMap::new();
            loop {
                ws(b, i);
                if b[*i] == b'}' {
                    *i += 1;
                    break;
                }
                let Json::Str(k) = parse_value(b, i) else { panic!("bad key at {i}") };
                ws(b, i);
                assert_eq!(b[*i], b':');
                *i += 1;
                let v = parse_value(b, i);
                m.insert(k, v);
                ws(b, i);
                if b[*i] == b',' {
                    *i += 1;
                }
            }
            Json::Obj(m)
        }
        b'[' => {
            *i += 1;
            let mut v = Vec::new();
            loop {
                ws(b, i);
                if b[*i] == b']' {
                    *i += 1;
                    break;
                }
                v.push(parse_value(b, i));
                ws(b, i);
                if b[*i] == b',' {
                    *i += 1;
                }
            }
            Json::Arr(v)
        }
        b'"' => {
            *i += 1;
            let mut s = String::new();
            while b[*i] != b'"' {
                if b[*i] == b'\\' {
                    *i += 1;
                    match b[*i] {
                        b'n' => s.push('\n'),
                        b't' => s.push('\t'),
                        b'u' => {
                            let h = std::str::from_utf8(&b[*i + 1..*i + 5]).unwrap();
                            s.push(char::from_u32(u32::from_str_radix(h, 16).unwrap()).unwrap_or('?'));
                            *i += 4;
                        }
                        c => s.push(c as char),
                    }
                    *i += 1;
                } else {
                    let start = *i;
                    while b[*i] != b'"' && b[*i] != b'\\' {
                        *i += 1;
                    }
                    s.push_str(std::str::from_utf8(&b[start..*i]).unwrap());
                }
            }
            *i += 1;
            Json::Str(s)
        }
        b't' => {
            *i += 4;
            Json::Bool(true)
        }
        b'f' => {
            *i += 5;
            Json::Bool(false)
        }
        b'n' => {
            *i += 4;
            Json::Null
        }
        _ => {
            let start = *i;
            while *i < b.len() && matches!(b[*i], b'0'..=b'9' | b'-' | b'+' | b'.' | b'e' | b'E') {
                *i += 1;
            }
            Json::Num(std::str::from_utf8(&b[start..*i]).unwrap().parse().unwrap())
        }
    }
}

/// One row of the printed results table.
pub struct Row {
    pub case: String,
    pub truth: Option<f64>,
    pub detected: Option<f64>,
    pub confidence: f64,
    pub ok: bool,
    pub note: String,
}

pub fn fmt_opt(v: Option<f64>) -> String {
    v.map_or("none".to_string(), |t| format!("{t:.4}"))
}

pub fn print_table(title: &str, rows: &[Row]) {
    println!("\n== {title}");
    println!("{:<28} {:>10} {:>10} {:>9} {:>6} {:>4}  note", "case", "truth", "detected", "error_s", "conf", "ok");
    for r in rows {
        let err = match (r.truth, r.detected) {
            (Some(a), Some(b)) => format!("{:+.4}", b - a),
            _ => "-".into(),
        };
        println!(
            "{:<28} {:>10} {:>10} {:>9} {:>6.3} {:>4}  {}",
            r.case,
            fmt_opt(r.truth),
            fmt_opt(r.detected),
            err,
            r.confidence,
            if r.ok { "yes" } else { "NO" },
            r.note
        );
    }
}
