//! RENADIC Vol.1 reader: any bytes give a record or a ParseError, never a panic or an abort.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = shakeflow::io::records::parse_renadic_v1(std::path::Path::new("fuzz.v1"), data);
});
