//! Automatic view cells from the command line: `umbrasweep cells` on the demo city (cells above
//! the ground, none inside a building, the streets covered), `bake --cells auto` validated
//! without a false cull, and the answers to bad options and to a scene without a floor (exit
//! code 2, a message naming the option or the way out).

mod common;

use glam::DVec3;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use umbrasweep::geom::Aabb;
use umbrasweep::scene::Scene;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_umbrasweep"))
}

fn run(args: &[&std::ffi::OsStr]) -> Output {
    bin().args(args).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn demo_city() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/demo_city.obj")
}

/// True when `p` is inside the closed object `o` of `scene`: the winding number of its
/// triangles around `p`, counted along a slightly tilted upward ray (brute force, independent
/// of the library's test).
fn inside(scene: &Scene, o: usize, p: DVec3) -> bool {
    let d = DVec3::new(0.0123, 1.0, 0.0071);
    let mut winding = 0;
    for t in scene.objects[o].triangles.clone() {
        let tri = scene.triangle(t as usize).map(|v| v.as_dvec3());
        if let Some((tt, det)) = common::ray_triangle(p, d, tri)
            && tt > 0.0
        {
            winding += if det < 0.0 { 1 } else { -1 };
        }
    }
    winding != 0
}

#[test]
fn cells_on_the_demo_city_stand_on_the_streets_and_roofs() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cells.json");
    let city = demo_city();
    let r = run(&[
        "cells".as_ref(),
        city.as_os_str(),
        "-o".as_ref(),
        out.as_os_str(),
    ]);
    assert!(r.status.success(), "{}", stderr(&r));
    let err = stderr(&r);
    for key in [
        "columns", "floors", "solid", "cells", "wall", "empty", "time",
    ] {
        assert!(err.contains(key), "summary lacks {key:?}: {err}");
    }
    let cells = umbrasweep::cells::load_json(&out).unwrap();
    assert!(cells.len() > 100, "{} cells", cells.len());

    let scene = umbrasweep::scene::load(&city).unwrap();
    let ground = scene
        .objects
        .iter()
        .position(|o| o.name == "ground")
        .unwrap();
    let ground_y = scene.objects[ground].bounds.max.y;
    let buildings: Vec<usize> = (0..scene.objects.len()).filter(|&o| o != ground).collect();
    assert_eq!(buildings.len(), 64);
    for c in &cells {
        // Above the ground.
        assert!(c.min.y >= ground_y, "{c:?} reaches below the ground");
        // Not inside a building: the centre of a cell within a building's box is outside the
        // building itself (its box is larger when it is rotated, and roof cells of a podium
        // stand within the box of its tower).
        let centre = c.center().as_dvec3();
        for &b in &buildings {
            let bb = scene.objects[b].bounds;
            assert!(scene.objects[b].closed);
            if bb.contains_point(c.center()) {
                assert!(
                    !inside(&scene, b, centre),
                    "{c:?} has its centre inside {}",
                    scene.objects[b].name
                );
            }
        }
    }
    // The streets are covered: each hand-placed demo cell (on the street centre lines) stands
    // over a ground-level automatic cell.
    let demo = umbrasweep::cells::load_json(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("data/demo_city_cells.json"),
    )
    .unwrap();
    for d in &demo {
        let p = d.center();
        let covered = cells.iter().any(|c: &Aabb| {
            c.min.y == ground_y
                && c.min.x <= p.x
                && p.x <= c.max.x
                && c.min.z <= p.z
                && p.z <= c.max.z
        });
        assert!(covered, "street point {p:?} has no cell over it");
    }
    // Deterministic: a second run writes the same file.
    let again = dir.path().join("again.json");
    let r = run(&[
        "cells".as_ref(),
        city.as_os_str(),
        "-o".as_ref(),
        again.as_os_str(),
    ]);
    assert!(r.status.success(), "{}", stderr(&r));
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&again).unwrap());
}

#[test]
fn bake_with_auto_cells_has_no_false_cull() {
    let dir = tempfile::tempdir().unwrap();
    let pvs = dir.path().join("out.json");
    let city = demo_city();
    // Columns of 10 (not 6.2) and resolution 128 keep the test quick; the rule is the same.
    let r = run(&[
        "bake".as_ref(),
        city.as_os_str(),
        "--cells".as_ref(),
        "auto".as_ref(),
        "--cell-size".as_ref(),
        "10".as_ref(),
        "--resolution".as_ref(),
        "128".as_ref(),
        "--backend".as_ref(),
        "cpu".as_ref(),
        "-o".as_ref(),
        pvs.as_os_str(),
    ]);
    let err = stderr(&r);
    assert!(r.status.success(), "{err}");
    assert!(err.contains("auto cells"), "{err}");
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&pvs).unwrap()).unwrap();
    let n = doc["cells"].as_array().unwrap().len();
    assert!(n > 10, "{n} cells");
    let v = run(&[
        "validate".as_ref(),
        city.as_os_str(),
        pvs.as_os_str(),
        "--rays".as_ref(),
        "5000".as_ref(),
    ]);
    let stdout = String::from_utf8_lossy(&v.stdout);
    assert_eq!(v.status.code(), Some(0), "{stdout}\n{}", stderr(&v));
    assert!(stdout.contains("no false cull"), "{stdout}");

    // Options of automatic cells need --cells auto.
    let cells = dir.path().join("c.json");
    std::fs::write(
        &cells,
        r#"{"cells": [{"min": [0, 1, 0], "max": [1, 2, 1]}]}"#,
    )
    .unwrap();
    let r = run(&[
        "bake".as_ref(),
        city.as_os_str(),
        "--cells".as_ref(),
        cells.as_os_str(),
        "--band".as_ref(),
        "3".as_ref(),
        "-o".as_ref(),
        pvs.as_os_str(),
    ]);
    assert_eq!(r.status.code(), Some(2));
    assert!(stderr(&r).contains("--band") && stderr(&r).contains("--cells auto"));
}

#[test]
fn bad_options_exit_2_naming_the_option() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cells.json");
    let city = demo_city();
    for (flag, value) in [
        ("--cell-size", "0"),
        ("--band", "-1"),
        ("--max-slope", "120"),
        ("--rays", "0"),
        ("--region", "1,2,3"),
    ] {
        let r = run(&[
            "cells".as_ref(),
            city.as_os_str(),
            "-o".as_ref(),
            out.as_os_str(),
            flag.as_ref(),
            value.as_ref(),
        ]);
        let err = stderr(&r);
        assert_eq!(r.status.code(), Some(2), "{flag} {value}: {err}");
        assert!(err.contains(flag), "{flag} {value}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out.exists());
    }
    // The same through bake.
    let pvs = dir.path().join("pvs.json");
    let r = run(&[
        "bake".as_ref(),
        city.as_os_str(),
        "--cells".as_ref(),
        "auto".as_ref(),
        "--cell-size".as_ref(),
        "0".as_ref(),
        "-o".as_ref(),
        pvs.as_os_str(),
    ]);
    assert_eq!(r.status.code(), Some(2));
    assert!(stderr(&r).contains("--cell-size"), "{}", stderr(&r));
    assert!(!pvs.exists());
}

#[test]
fn a_scene_without_a_floor_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("wall.obj");
    std::fs::write(
        &scene,
        "o wall\nv 0 0 0\nv 10 0 0\nv 10 5 0\nv 0 5 0\nf 1 2 3 4\n",
    )
    .unwrap();
    let out = dir.path().join("cells.json");
    let r = run(&[
        "cells".as_ref(),
        scene.as_os_str(),
        "-o".as_ref(),
        out.as_os_str(),
    ]);
    let err = stderr(&r);
    assert_eq!(r.status.code(), Some(2), "{err}");
    assert!(err.contains("wall.obj"), "{err}");
    assert!(err.contains("no walkable surface"), "{err}");
    assert!(err.contains("--auto-region"), "{err}");
    assert!(!out.exists());
    // With a region, the box is filled.
    let r = run(&[
        "cells".as_ref(),
        scene.as_os_str(),
        "-o".as_ref(),
        out.as_os_str(),
        "--region".as_ref(),
        "0,0,-4,10,4,4".as_ref(),
        "--cell-size".as_ref(),
        "2".as_ref(),
    ]);
    assert!(r.status.success(), "{}", stderr(&r));
    let cells = umbrasweep::cells::load_json(&out).unwrap();
    assert!(!cells.is_empty());
    for c in &cells {
        assert!(c.min.x >= 0.0 && c.max.x <= 10.0 && c.min.z >= -4.0 && c.max.z <= 4.0);
    }
}
