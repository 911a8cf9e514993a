//! Compares two PVS files cell for cell: the same objects, the same cells and the same
//! potentially visible sets, whatever the timings. For checking that a refactor or an
//! optimisation leaves the PVS unchanged (`bench --pvs-out DIR` writes one document per scene
//! and backend; compare two builds' folders file by file).
//!
//! ```sh
//! cargo run --release --example pvs_diff -- old/city-cpu.json new/city-cpu.json
//! cargo run --release --example pvs_diff -- old/ new/      # every *.json of old/ against new/
//! ```
//!
//! Exit code 0 when every pair is identical, 1 when some PVS differs, 2 on bad input. JSON
//! documents and binary `.pvs` files are both read.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use umbrasweep::pvs::PvsDocument;

fn read(path: &Path) -> Result<PvsDocument, String> {
    if path.extension().is_some_and(|e| e == "pvs") {
        umbrasweep::pvs::binary::read(path).map_err(|e| e.to_string())
    } else {
        umbrasweep::pvs::json::read(path).map_err(|e| e.to_string())
    }
}

/// The differences between two documents, one line each (empty when identical).
fn diff(a: &PvsDocument, b: &PvsDocument) -> Vec<String> {
    let mut out = Vec::new();
    let names = |d: &PvsDocument| d.objects.iter().map(|o| o.name.clone()).collect::<Vec<_>>();
    if names(a) != names(b) {
        out.push(format!(
            "objects differ: {} against {}",
            a.objects.len(),
            b.objects.len()
        ));
        return out;
    }
    if a.cells.len() != b.cells.len() {
        out.push(format!("{} cells against {}", a.cells.len(), b.cells.len()));
        return out;
    }
    for (i, (ca, cb)) in a.cells.iter().zip(&b.cells).enumerate() {
        if ca.min != cb.min || ca.max != cb.max {
            out.push(format!(
                "cell {i}: bounds {:?}..{:?} against {:?}..{:?}",
                ca.min, ca.max, cb.min, cb.max
            ));
        }
        if ca.visible != cb.visible {
            let only_a: Vec<u32> = (ca.visible.iter())
                .filter(|o| cb.visible.binary_search(o).is_err())
                .copied()
                .collect();
            let only_b: Vec<u32> = (cb.visible.iter())
                .filter(|o| ca.visible.binary_search(o).is_err())
                .copied()
                .collect();
            out.push(format!(
                "cell {i}: {} visible against {}; only in the first {only_a:?}, only in the \
                 second {only_b:?}",
                ca.visible.len(),
                cb.visible.len()
            ));
        }
    }
    out
}

fn pairs(a: &Path, b: &Path) -> Result<Vec<(PathBuf, PathBuf)>, String> {
    if !a.is_dir() {
        return Ok(vec![(a.to_path_buf(), b.to_path_buf())]);
    }
    let mut v = Vec::new();
    let entries = std::fs::read_dir(a).map_err(|e| format!("{}: {e}", a.display()))?;
    for e in entries {
        let p = e.map_err(|e| format!("{}: {e}", a.display()))?.path();
        if p.extension().is_some_and(|x| x == "json" || x == "pvs") {
            let other = b.join(p.file_name().unwrap_or_default());
            v.push((p, other));
        }
    }
    v.sort();
    if v.is_empty() {
        return Err(format!("{}: no .json or .pvs file", a.display()));
    }
    Ok(v)
}

fn main() -> ExitCode {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    let [a, b] = args.as_slice() else {
        eprintln!("usage: pvs_diff A B   (two PVS files, or two folders of them)");
        return ExitCode::from(2);
    };
    let run = || -> Result<bool, String> {
        let mut same = true;
        for (pa, pb) in pairs(a, b)? {
            if !pb.exists() {
                same = false;
                println!("MISSING: {} (no {})", pa.display(), pb.display());
                continue;
            }
            let (da, db) = (read(&pa)?, read(&pb)?);
            let d = diff(&da, &db);
            let cells = da.cells.len();
            if d.is_empty() {
                println!("identical: {} ({cells} cells)", pa.display());
            } else {
                same = false;
                println!("DIFFERENT: {} against {}", pa.display(), pb.display());
                for line in d {
                    println!("  {line}");
                }
            }
        }
        Ok(same)
    };
    match run() {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("pvs_diff: {e}");
            ExitCode::from(2)
        }
    }
}
