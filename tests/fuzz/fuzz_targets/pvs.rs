//! Fuzz target: the run-time `.pvs` reader on arbitrary bytes, and every query on what it
//! accepts.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(db) = umbrasweep::pvs::PvsDatabase::from_bytes(data) {
        let _ = db.to_document();
        for c in 0..db.cell_count().min(64) {
            let _ = db.visible(umbrasweep::pvs::CellId(c as u32)).count();
        }
        let _ = db.cell_at([0.0f32, 0.0, 0.0]);
        let _ = db.stats();
    }
});
