//! The `load` stage on a record file: the reader and then units, gaps, time base, resampling
//! and column names. The first byte picks the source (format, gap and sampling policies), the
//! rest is the file, written to a temporary file because `load` reads files.
#![no_main]
use libfuzzer_sys::fuzz_target;
use serde_json::json;
use shakeflow::stages::{load, InputPart};

const FORMATS: [&str; 4] = ["at2", "renadic_v1", "simcenter_json", "csv"];

fuzz_target!(|data: &[u8]| {
    let Some((&options, file)) = data.split_first() else { return };
    let format = FORMATS[usize::from(options & 3)];
    let mut spec = json!({
        "format": format,
        "path": "record",
        "gaps": if options & 4 == 0 { "error" } else { "interpolate" },
        "non_uniform": if options & 8 == 0 { "error" } else { "resample" },
    });
    if format == "csv" {
        spec["unit"] = json!(if options & 16 == 0 { "g" } else { "m/s^2" });
        if options & 32 == 0 {
            spec["time_column"] = json!("time");
        } else {
            spec["dt"] = json!(0.005);
        }
    }
    let spec = serde_json::from_value(spec).expect("a valid source");
    let path = std::env::temp_dir().join(format!("shakeflow-fuzz-load-{}", std::process::id()));
    std::fs::write(&path, file).expect("a temporary file");
    let part = InputPart { partition: vec![], path: path.clone(), label: "record".into(), hash: String::new() };
    let _ = load::load_record(&spec, &part);
});
