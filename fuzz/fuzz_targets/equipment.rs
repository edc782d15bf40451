//! A case's equipment.yaml: any bytes give equipment or a UserError, never a panic or an abort.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("equipment.yaml");
    if let Ok(text) = shakeflow::io::records::decode(path, data) {
        let _ = shakeflow::io::equipment::parse_rocking_equipment(path, &text);
    }
});
