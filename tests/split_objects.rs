//! `bake --split-objects SIZE`: an object spanning the scene is culled cluster by cluster, the
//! PVS maps clusters back to the file's objects (JSON and `.pvs`), `validate` splits the
//! scene again to check it, and bad input gets a clear error.

use glam::Vec3;
use std::path::{Path, PathBuf};
use std::process::Command;
use umbrasweep::geom::box_triangles;
use umbrasweep::pvs::PvsDocument;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_umbrasweep"))
}

/// A closed box as OBJ triangles ([`box_triangles`]), vertices numbered from `base`.
fn obj_box(out: &mut String, base: &mut usize, min: [f32; 3], max: [f32; 3]) {
    for t in box_triangles(Vec3::from(min), Vec3::from(max)) {
        for p in t {
            out.push_str(&format!("v {} {} {}\n", p.x, p.y, p.z));
        }
        out.push_str(&format!("f {} {} {}\n", *base, *base + 1, *base + 2));
        *base += 3;
    }
}

/// A wall 4 × 4 at z = 1 in front of the cell at the origin (small enough to stay whole at
/// `--split-objects 4`), and one object "row" of 16 separate boxes along x from −38 to 38 at
/// z = 20: its middle is in the wall's umbra (|x| < 33), its ends are not.
fn scene(dir: &Path) -> PathBuf {
    let mut s = String::new();
    let mut base = 1;
    s.push_str("o wall\n");
    obj_box(&mut s, &mut base, [-2.0, -2.0, 1.0], [2.0, 2.0, 1.2]);
    s.push_str("o row\n");
    for i in 0..16 {
        let x = -38.0 + 5.0 * i as f32;
        obj_box(&mut s, &mut base, [x, -1.0, 20.0], [x + 1.0, 1.0, 21.0]);
    }
    let p = dir.join("row.obj");
    std::fs::write(&p, s).unwrap();
    p
}

fn cells(dir: &Path) -> PathBuf {
    let p = dir.join("cells.json");
    std::fs::write(
        &p,
        r#"{"cells": [{"min": [-0.5, -0.5, -0.5], "max": [0.5, 0.5, 0.5]}]}"#,
    )
    .unwrap();
    p
}

fn bake(dir: &Path, out: &str, extra: &[&str]) -> (PathBuf, std::process::Output) {
    let out = dir.join(out);
    let r = bin()
        .arg("bake")
        .arg(scene(dir))
        .arg("--cells")
        .arg(cells(dir))
        .arg("-o")
        .arg(&out)
        .args(["--backend", "cpu"])
        .args(extra)
        .output()
        .unwrap();
    (out, r)
}

#[test]
fn clusters_behind_the_wall_are_culled_and_map_back() {
    let dir = tempfile::tempdir().unwrap();
    let (whole, r) = bake(dir.path(), "whole.json", &[]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let doc: PvsDocument = serde_json::from_slice(&std::fs::read(&whole).unwrap()).unwrap();
    assert!(doc.split.is_none());
    assert_eq!(doc.objects.len(), 2);
    assert!(
        doc.cells[0].visible.contains(&1),
        "the row is seen at its ends"
    );

    let (split, r) = bake(dir.path(), "split.json", &["--split-objects", "4"]);
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{stderr}");
    assert!(stderr.contains("clusters of 2 objects"), "{stderr}");
    let doc: PvsDocument = serde_json::from_slice(&std::fs::read(&split).unwrap()).unwrap();
    let table = doc.split.as_ref().expect("a split table");
    assert_eq!(table.size, 4.0);
    assert_eq!(table.sources.len(), 2);
    assert_eq!((table.sources[0].first, table.sources[0].count), (0, 1));
    assert_eq!(table.sources[1].name, "row");
    assert_eq!(table.sources[1].first, 1);
    assert_eq!(table.sources[1].count, 16, "one cluster per separate box");
    assert_eq!(doc.objects.len(), 17);
    let visible = &doc.cells[0].visible;
    let hidden: Vec<u32> = (1..17).filter(|o| !visible.contains(o)).collect();
    assert!(
        hidden.len() >= 4,
        "the middle of the row is culled: {visible:?}"
    );
    for &o in &hidden {
        let b = &doc.objects[o as usize];
        assert!(b.min[0] >= -33.0 && b.max[0] <= 33.0, "{o}: {b:?} culled");
    }
    assert!(
        visible.contains(&1) && visible.contains(&16),
        "the row's ends"
    );
    assert_eq!(table.source_visible(visible), vec![0, 1]);

    // validate splits the scene again and finds no false cull; the .pvs keeps the table.
    let v = bin()
        .arg("validate")
        .arg(scene(dir.path()))
        .arg(&split)
        .args(["--rays", "100000"])
        .output()
        .unwrap();
    assert!(v.status.success(), "{}", String::from_utf8_lossy(&v.stdout));
    let (pvs, r) = bake(dir.path(), "split.pvs", &["--split-objects", "4"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let bytes = std::fs::read(&pvs).unwrap();
    assert_eq!(&bytes[8..12], &6u32.to_le_bytes());
    let db = umbrasweep::pvs::PvsDatabase::from_bytes(&bytes).unwrap();
    assert_eq!(db.split(), doc.split.as_ref());
    assert_eq!(db.to_document().cells[0].visible, *visible);
    let v = bin()
        .arg("validate")
        .arg(scene(dir.path()))
        .arg(&pvs)
        .args(["--rays", "20000", "--hunt"])
        .output()
        .unwrap();
    assert!(v.status.success(), "{}", String::from_utf8_lossy(&v.stdout));
}

#[test]
fn a_split_pvs_against_another_scene_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (split, r) = bake(dir.path(), "split.json", &["--split-objects", "4"]);
    assert!(r.status.success());
    let other = dir.path().join("other.obj");
    std::fs::write(
        &other,
        "o a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\no b\nv 0 0 9\nv 9 0 9\nv 0 9 9\nf 4 5 6\n",
    )
    .unwrap();
    let v = bin()
        .arg("validate")
        .arg(&other)
        .arg(&split)
        .output()
        .unwrap();
    assert_eq!(v.status.code(), Some(2));
    let e = String::from_utf8_lossy(&v.stderr);
    assert!(
        e.contains("split-objects 4") && e.contains("other.obj"),
        "{e}"
    );
}

#[test]
fn a_bad_size_is_an_error_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    for bad in ["0", "-3", "nan"] {
        let arg = format!("--split-objects={bad}");
        let (out, r) = bake(dir.path(), "bad.json", &[&arg]);
        assert_eq!(r.status.code(), Some(2), "{bad}");
        let e = String::from_utf8_lossy(&r.stderr);
        assert!(
            e.contains("--split-objects") && !e.contains("panicked"),
            "{e}"
        );
        assert!(!out.exists());
    }
}
