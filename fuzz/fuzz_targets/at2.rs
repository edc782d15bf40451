//! PEER AT2 reader: any bytes give a record or a ParseError, never a panic or an abort.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = shakeflow::io::records::parse_at2(std::path::Path::new("fuzz.AT2"), data);
});
