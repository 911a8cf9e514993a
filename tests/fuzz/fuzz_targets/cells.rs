//! Fuzz target: the cells-file reader on arbitrary text.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = umbrasweep::cells::parse_json(text, std::path::Path::new("fuzz.json"));
    }
});
