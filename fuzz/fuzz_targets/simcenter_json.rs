//! SimCenter JSON reader: any bytes give a record or a ParseError, never a panic or an abort.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = shakeflow::io::records::parse_simcenter_json(std::path::Path::new("fuzz.json"), data);
});
