//! Fuzz target: the OBJ reader on arbitrary bytes (errors are fine, panics and unbounded
//! allocations are not).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = umbrasweep::scene::obj::parse(data, std::path::Path::new("fuzz.obj"));
});
