//! Control-point CSV: any bytes give points or a UserError, never a panic or an abort.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("control_points.csv");
    if let Ok(text) = shakeflow::io::records::decode(path, data) {
        let _ = shakeflow::io::control_points::parse(path, &text);
    }
});
