//! Fuzz target: the glTF/GLB reader on arbitrary bytes (as a .glb: embedded buffers only, so
//! nothing is read from disk).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = umbrasweep::scene::gltf::parse(data, std::path::Path::new("/nonexistent/fuzz.glb"));
});
