//! The C API (issue 7): builds the `umbrasweep-capi` cdylib, compiles `capi/tests/query.c`
//! against `capi/include/umbrasweep.h` with the system C compiler (`cc`, or `$CC`), runs it
//! on a `.pvs` file written here and checks every line it prints against the document.
//! Without a C compiler the test says so and passes, except in CI (`CI` set) where it fails.

use std::path::{Path, PathBuf};
use std::process::Command;
use umbrasweep::pvs::{PvsCell, PvsDocument, PvsObject, PvsSource, PvsSplit, binary};

/// A small document whose cells share most objects (so deltas are used) with one overlap;
/// cell 4 is subdivided into cells 6 and 7, and the objects are clusters of two objects of
/// the scene file (`--split-objects`).
fn document() -> PvsDocument {
    let objects = (0..70)
        .map(|i| PvsObject {
            id: i,
            name: format!("obj{i}"),
            triangles: 2,
            min: [i as f32, 0.0, 0.0],
            max: [i as f32 + 1.0, 1.0, 1.0],
        })
        .collect();
    let cells = (0..6u32)
        .map(|c| PvsCell {
            min: [c as f32 * 2.0, 0.0, 0.0],
            // Cell 2 overlaps cell 3 by half: the lower index wins there.
            max: [c as f32 * 2.0 + if c == 2 { 3.0 } else { 2.0 }, 2.0, 2.0],
            visible: (0..70)
                .filter(|&o| (o + c) % 4 != 0 || o == 60 + c)
                .collect(),
            ms: 1.0,
            cullers: Vec::new(),
            parent: None,
        })
        .collect::<Vec<_>>();
    let mut cells = cells;
    for (k, x) in [8.0f32, 9.0].into_iter().enumerate() {
        let mut half = cells[4].clone();
        half.min[0] = x;
        half.max[0] = x + 1.0;
        half.visible.retain(|&o| o % 3 != k as u32);
        half.parent = Some(4);
        cells.push(half);
    }
    let source = |id: u32, first: u32, count: u32| PvsSource {
        id,
        name: format!("file object {id}"),
        triangles: 2 * count,
        min: [0.0; 3],
        max: [1.0; 3],
        first,
        count,
    };
    PvsDocument {
        format: umbrasweep::pvs::FORMAT.into(),
        version: umbrasweep::pvs::VERSION,
        scene: "capi.obj".into(),
        settings: Default::default(),
        objects,
        cells,
        summary: None,
        split: Some(PvsSplit {
            size: 10.0,
            sources: vec![source(0, 0, 10), source(1, 10, 60)],
        }),
    }
}

/// The output `query.c` must print for `doc`.
fn expected(doc: &PvsDocument) -> String {
    let n = doc.objects.len();
    let mut s = format!("cells {} objects {n}\n", doc.cells.len());
    for (c, cell) in doc.cells.iter().enumerate() {
        let centre: Vec<f32> = (0..3).map(|k| 0.5 * (cell.min[k] + cell.max[k])).collect();
        let holds = |d: &PvsCell| (0..3).all(|k| d.min[k] <= centre[k] && centre[k] <= d.max[k]);
        // The lowest cell given to the bake, then down its halves.
        let mut at = doc
            .cells
            .iter()
            .position(|d| d.parent.is_none() && holds(d))
            .map_or(-1, |i| i as i64);
        while let Some(h) = (at >= 0)
            .then(|| {
                doc.cells
                    .iter()
                    .position(|d| d.parent == Some(at as u32) && holds(d))
            })
            .flatten()
        {
            at = h as i64;
        }
        let parent = cell.parent.map_or(-1, i64::from);
        s += &format!("cell {c} at {at} parent {parent}:");
        for &o in &cell.visible {
            s += &format!(" {o}=obj{o}");
        }
        s += &format!("\nrow {c}: ");
        for o in 0..n as u32 {
            s += if cell.visible.contains(&o) { "1" } else { "0" };
        }
        s += "\n";
    }
    s += &format!("short {}\n", doc.cells[0].visible.len());
    s += "sources";
    let split = doc.split.as_ref().unwrap();
    for o in 0..n as u32 {
        s += &format!(" {}", split.source_of(o));
    }
    s += " -1 -1\n";
    s += "errors -1 -1 -1 0 null -1 0\n";
    s += "bytes error: truncated: the file has 8 bytes, its header says 24\n";
    s
}

/// `target/<profile>` of this test executable (`target/<profile>/deps/capi-…`).
fn profile_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    exe.parent().and_then(Path::parent).unwrap().to_path_buf()
}

#[test]
fn c_program_opens_and_queries_a_pvs_file() {
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    if Command::new(&cc).arg("--version").output().is_err() {
        assert!(
            std::env::var_os("CI").is_none(),
            "no C compiler ({cc}) in CI: install gcc"
        );
        eprintln!("skipping the C API test: no C compiler ({cc}) found");
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = profile_dir();
    let mut build = Command::new(env!("CARGO"));
    build
        .current_dir(root)
        .args(["build", "-p", "umbrasweep-capi"]);
    if dir.file_name().is_some_and(|n| n == "release") {
        build.arg("--release");
    }
    let out = build.output().unwrap();
    assert!(
        out.status.success(),
        "cargo build -p umbrasweep-capi failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lib = dir.join(format!(
        "{}umbrasweep_capi{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    ));
    assert!(lib.exists(), "{} not built", lib.display());

    let tmp = tempfile::tempdir().unwrap();
    let exe = tmp.path().join("query");
    let out = Command::new(&cc)
        .args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-o"])
        .arg(&exe)
        .arg(root.join("capi/tests/query.c"))
        .arg("-I")
        .arg(root.join("capi/include"))
        .arg("-L")
        .arg(&dir)
        .arg(format!("-Wl,-rpath,{}", dir.display()))
        .arg("-lumbrasweep_capi")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "compiling query.c failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let doc = document();
    let pvs = tmp.path().join("small.pvs");
    binary::write(&pvs, &doc).unwrap();
    let db = umbrasweep::pvs::PvsDatabase::open(&pvs).unwrap();
    assert!(
        db.stats().key_cells < doc.cells.len(),
        "deltas are exercised"
    );
    let out = Command::new(&exe).arg(&pvs).output().unwrap();
    assert!(
        out.status.success(),
        "query failed ({:?}):\n{}{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(String::from_utf8(out.stdout).unwrap(), expected(&doc));

    // A damaged file: the C program gets the message and no handle.
    let mut bytes = std::fs::read(&pvs).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 0x10;
    let bad = tmp.path().join("bad.pvs");
    std::fs::write(&bad, &bytes).unwrap();
    let out = Command::new(&exe).arg(&bad).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.starts_with("error: ") && text.contains("bad.pvs") && text.contains("checksum"),
        "{text}"
    );
}
