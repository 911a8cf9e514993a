//! Inputs the fuzz targets (`tests/fuzz`) found crashing a reader, and hand-made hostile ones
//! (counts in headers claiming billions), kept as regression tests:
//! every file under `tests/fuzz/regressions/<target>/` goes through the same reader as its
//! target and must give an error or a result, never a panic. The seeds of `tests/fuzz/seeds`
//! must be read without error.

use std::path::{Path, PathBuf};

fn files(kind: &str, sub: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz")
        .join(kind)
        .join(sub);
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| !p.file_name().unwrap().to_string_lossy().starts_with('.'))
        .collect();
    v.sort();
    v
}

/// Runs the reader of `target` on `bytes`: Ok when it accepted them.
fn read(target: &str, bytes: &[u8]) -> Result<(), String> {
    match target {
        "obj" => umbrasweep::scene::obj::parse(bytes, Path::new("fuzz.obj"))
            .map(|_| ())
            .map_err(|e| e.to_string()),
        "gltf" => umbrasweep::scene::gltf::parse(bytes, Path::new("/nonexistent/fuzz.glb"))
            .map(|_| ())
            .map_err(|e| e.to_string()),
        "cells" => std::str::from_utf8(bytes)
            .map_err(|e| e.to_string())
            .and_then(|t| {
                umbrasweep::cells::parse_json(t, Path::new("fuzz.json"))
                    .map(|_| ())
                    .map_err(|e| e.to_string())
            }),
        "pvs" => umbrasweep::pvs::PvsDatabase::from_bytes(bytes)
            .map(|db| {
                let _ = db.to_document();
                for c in 0..db.cell_count().min(64) {
                    let _ = db.visible(umbrasweep::pvs::CellId(c as u32)).count();
                }
            })
            .map_err(|e| e.to_string()),
        _ => unreachable!(),
    }
}

#[test]
fn crashing_inputs_found_by_fuzzing_give_errors() {
    let mut n = 0;
    for target in ["obj", "gltf", "cells", "pvs"] {
        for f in files("regressions", target) {
            let bytes = std::fs::read(&f).unwrap();
            let r = std::panic::catch_unwind(|| read(target, &bytes));
            assert!(r.is_ok(), "{}: the {target} reader panicked", f.display());
            n += 1;
        }
    }
    assert!(n >= 1, "no regression inputs found");
}

#[test]
fn fuzz_seeds_are_read() {
    for target in ["obj", "gltf", "cells", "pvs"] {
        let seeds = files("seeds", target);
        assert!(!seeds.is_empty(), "no seeds for {target}");
        for f in seeds {
            let bytes = std::fs::read(&f).unwrap();
            read(target, &bytes).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        }
    }
}
