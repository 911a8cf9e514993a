//! The `umbrasweep bake` command line: the PVS document it writes (schema, sorted ids, the
//! summary on stderr) and its answer to bad input (exit code 2, a message naming the file or
//! option, no output file, no panic).

use std::path::{Path, PathBuf};
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_umbrasweep"))
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// A wall in front of a box, both closed, as OBJ.
const SCENE: &str = "o wall
v -10 -10 5
v 10 -10 5
v 10 10 5
v -10 10 5
f 1 2 3 4
o target
v -1 -1 10
v 1 -1 10
v 1 1 10
v -1 1 10
f 5 6 7 8
o beside
v 20 -1 -10
v 22 -1 -10
v 22 1 -10
f 9 10 11
";

const CELLS: &str = r#"{"cells": [{"min": [-0.5, -0.5, -0.5], "max": [0.5, 0.5, 0.5]},
                                 {"min": [30, 0, 30], "max": [31, 1, 31]}]}"#;

#[test]
fn bake_writes_the_documented_json_and_a_summary() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write(dir.path(), "s.obj", SCENE);
    let cells = write(dir.path(), "c.json", CELLS);
    let out = dir.path().join("pvs.json");
    let r = bin()
        .arg("bake")
        .arg(&scene)
        .arg("--cells")
        .arg(&cells)
        .arg("-o")
        .arg(&out)
        .args(["--backend", "cpu"])
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let stderr = String::from_utf8_lossy(&r.stderr);
    for key in [
        "backend     cpu",
        "cells       2",
        "objects     3",
        "culled",
        "ms per cell",
    ] {
        assert!(stderr.contains(key), "summary lacks {key:?}: {stderr}");
    }
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(doc["format"], "umbrasweep-pvs");
    assert_eq!(doc["version"], 1);
    assert_eq!(doc["settings"]["resolution"], 256);
    let objects = doc["objects"].as_array().unwrap();
    assert_eq!(objects.len(), 3);
    assert_eq!(objects[1]["name"], "target");
    assert_eq!(objects[1]["id"], 1);
    assert_eq!(objects[0]["triangles"], 2);
    assert_eq!(objects[1]["min"], serde_json::json!([-1.0, -1.0, 10.0]));
    let cells = doc["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 2);
    let visible: Vec<u64> = cells[0]["visible"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    // The wall hides the target from the first cell; the wall and the triangle beside it stay.
    assert_eq!(visible, vec![0, 2]);
    assert!(cells[0]["ms"].as_f64().unwrap() >= 0.0);
    let second: Vec<u64> = cells[1]["visible"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    assert!(second.windows(2).all(|w| w[0] < w[1]), "sorted ids");
}

/// Runs `bake` with `args` after the scene, expects exit code 2, a message containing
/// `needle`, and no output file.
fn refuses(scene: &Path, args: &[&str], needle: &str) {
    let dir = scene.parent().unwrap();
    let out = dir.join("out.json");
    let _ = std::fs::remove_file(&out);
    let r = bin()
        .arg("bake")
        .arg(scene)
        .args(args)
        .arg("-o")
        .arg(&out)
        .args(["--backend", "cpu"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(2), "{args:?}: {stderr}");
    assert!(
        stderr.contains(needle),
        "{args:?}: expected {needle:?} in {stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!out.exists(), "{args:?} left an output file");
}

#[test]
fn bad_input_exits_2_naming_the_problem_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = write(d, "s.obj", SCENE);
    let cells = write(d, "c.json", CELLS);
    let c = cells.to_str().unwrap();
    // Missing and malformed files.
    refuses(&d.join("missing.obj"), &["--cells", c], "missing.obj");
    refuses(
        &scene,
        &["--cells", d.join("nope.json").to_str().unwrap()],
        "nope.json",
    );
    let bad_json = write(d, "bad.json", "{\"cells\": [");
    refuses(&scene, &["--cells", bad_json.to_str().unwrap()], "bad.json");
    // NaN coordinates and an empty scene.
    let nan = write(d, "nan.obj", "o a\nv 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    refuses(&nan, &["--cells", c], "nan.obj");
    let empty = write(d, "empty.obj", "o a\nv 0 0 0\n");
    refuses(&empty, &["--cells", c], "empty.obj");
    // Inverted and zero-volume cells.
    let inverted = write(
        d,
        "inv.json",
        r#"{"cells": [{"min": [1, 1, 1], "max": [0, 2, 2]}]}"#,
    );
    refuses(&scene, &["--cells", inverted.to_str().unwrap()], "inv.json");
    let flat = write(
        d,
        "flat.json",
        r#"{"cells": [{"min": [0, 0, 0], "max": [1, 0, 1]}]}"#,
    );
    refuses(&scene, &["--cells", flat.to_str().unwrap()], "zero volume");
    refuses(
        &scene,
        &["--grid-box", "0,0,0,1,1", "--grid-size", "1,1,1"],
        "--grid-box",
    );
    // Settings.
    refuses(
        &scene,
        &["--cells", c, "--resolution", "100"],
        "power of two",
    );
    refuses(
        &scene,
        &["--cells", c, "--no-such-option"],
        "--no-such-option",
    );
    refuses(&scene, &["--cells", c, "--occluders", "[x"], "--occluders");
    // The sampler's options.
    for (args, needle) in [
        (
            &["--sampling-budget", "lots"][..],
            "--sampling-budget \"lots\"",
        ),
        (&["--sampling-budget", "0"][..], "--sampling-budget \"0\""),
        (&["--sampling-budget", "0s"][..], "seconds"),
        (&["--sampling-eps", "0"][..], "--sampling-eps 0"),
        (&["--sampling-eps", "nan"][..], "--sampling-eps"),
        (&["--sampling-max-eps", "0"][..], "--sampling-max-eps 0"),
        (&["--sampling-probe", "2"][..], "--sampling-probe 2"),
        (
            &["--sampling-probe-cull", "1.5"][..],
            "--sampling-probe-cull 1.5",
        ),
        (
            &["--sampling-resolution", "8"][..],
            "--sampling-resolution 8",
        ),
        (
            &["--sampling-resolution", "lots"][..],
            "--sampling-resolution \"lots\"",
        ),
        (&["--sampling-levels", "40"][..], "--sampling-levels 40"),
        (&["--gpu-sampler-memory", "0"][..], "--gpu-sampler-memory"),
        (&["--gpu-sampler-memory", "lots"][..], "16G"),
        (&["--sampling", "--no-sampling"][..], "--no-sampling"),
        (
            &["--sampling-tuck", "--no-sampling-tuck"][..],
            "--no-sampling-tuck",
        ),
    ] {
        let mut a = vec!["--cells", c];
        a.extend_from_slice(args);
        refuses(&scene, &a, needle);
    }
}

#[test]
fn the_sampler_runs_with_a_budget_and_reports_itself() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = write(d, "s.obj", SCENE);
    let cells = write(d, "c.json", CELLS);
    let out = d.join("out.json");
    let r = bin()
        .arg("bake")
        .arg(&scene)
        .args(["--cells", cells.to_str().unwrap(), "--backend", "cpu"])
        .args([
            "--sampling",
            "--sampling-budget",
            "40,60s",
            "--sampling-eps",
            "0.5",
            "--sampling-max-eps",
            "2",
            // No certifying rays: the sampler tests every object the planes left.
            "--sampling-rays",
            "0",
            "--sampling-tuck",
        ])
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{stderr}");
    assert!(
        stderr.contains("sampling    yes — --sampling; finest ε 0.5"),
        "{stderr}"
    );
    assert!(
        stderr.contains("levels coarser than ε 2.0000 split unsampled (--sampling-max-eps)"),
        "{stderr}"
    );
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let s = &doc["settings"];
    assert_eq!(s["sampling"], serde_json::json!(true));
    assert_eq!(s["sampling_budget_points"], serde_json::json!(40));
    assert_eq!(s["sampling_budget_seconds"], serde_json::json!(60.0));
    assert_eq!(s["sampling_eps"], serde_json::json!(0.5));
    assert_eq!(s["sampling_max_eps"], serde_json::json!(2.0));
    assert_eq!(s["sampling_tuck"], serde_json::json!(true));
    // The resolution is chosen per cell and level (recorded as null in the settings).
    assert_eq!(s["sampling_resolution"], serde_json::Value::Null);
    let mut levels = 0;
    for cell in doc["cells"].as_array().unwrap() {
        // The sampler runs last (after ray space factorization where it runs, and the planes).
        let cullers = cell["cullers"].as_array().unwrap();
        let sampler = cullers.last().unwrap();
        assert_eq!(sampler["name"], "shrunk_sampling");
        assert!(sampler["points"].as_u64().unwrap_or(0) <= 40, "{sampler}");
        for l in sampler["levels"].as_array().into_iter().flatten() {
            let r = l["resolution"].as_u64().unwrap();
            assert!(
                r.is_power_of_two() && (256..=1024).contains(&r),
                "{sampler}"
            );
            levels += 1;
        }
    }
    assert!(levels > 0, "no cell sampled a level");
    assert!(stderr.contains(" px: "), "{stderr}");
    assert!(
        stderr.contains("pixels per view chosen per cell and level"),
        "{stderr}"
    );
    // The target behind the wall stays culled, the triangle beside it visible from cell 1.
    assert!(
        !doc["cells"][0]["visible"]
            .as_array()
            .unwrap()
            .contains(&serde_json::json!(1))
    );
}

/// `--sampling-fusion sweep` renders with the per-rectangle sweep: the summary says so, the
/// settings record it, every level renders at the sweep's 512 px, and the target behind the
/// wall stays culled. An unknown fusion is refused with the choices.
#[test]
fn the_sampler_fuses_by_the_sweep_when_asked() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = write(d, "s.obj", SCENE);
    let cells = write(d, "c.json", CELLS);
    let out = d.join("out.json");
    let bake = |fusion: &str| {
        bin()
            .arg("bake")
            .arg(&scene)
            .args(["--cells", cells.to_str().unwrap(), "--backend", "cpu"])
            .args([
                "--sampling",
                "--sampling-budget",
                "40",
                "--sampling-eps",
                "0.5",
                "--sampling-rays",
                "0",
                "--sampling-fusion",
                fusion,
            ])
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap()
    };
    let r = bake("sweep");
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{stderr}");
    assert!(
        stderr.contains("512 px per view; leaves fused by the per-rectangle sweep"),
        "{stderr}"
    );
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(
        doc["settings"]["sampling_fusion"],
        serde_json::json!("sweep")
    );
    let mut levels = 0;
    for cell in doc["cells"].as_array().unwrap() {
        let sampler = cell["cullers"].as_array().unwrap().last().unwrap();
        assert_eq!(sampler["name"], "shrunk_sampling");
        for l in sampler["levels"].as_array().into_iter().flatten() {
            assert_eq!(l["resolution"], serde_json::json!(512), "{sampler}");
            levels += 1;
        }
    }
    assert!(levels > 0, "no cell sampled a level");
    assert!(
        !doc["cells"][0]["visible"]
            .as_array()
            .unwrap()
            .contains(&serde_json::json!(1))
    );
    let r = bake("fused");
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(!r.status.success());
    assert!(
        stderr.contains("--sampling-fusion")
            && stderr.contains("shrink")
            && stderr.contains("sweep"),
        "{stderr}"
    );
}

/// `--sampling-resolution N` renders every level at N pixels, recorded in the settings and
/// in each level of the cost curve.
#[test]
fn a_given_sampling_resolution_is_used_at_every_level() {
    let dir = tempfile::tempdir().unwrap();
    let (mut cmd, out) = wall_bake(dir.path());
    let r = cmd
        .args(["--backend", "cpu", "--sampling", "--sampling-eps", "0.5"])
        .args(["--sampling-budget", "40", "--sampling-resolution", "64"])
        .args(["--sampling-rays", "0", "--no-rsf"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{stderr}");
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(
        doc["settings"]["sampling_resolution"],
        serde_json::json!(64)
    );
    let levels: Vec<u64> = doc["cells"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|c| c["cullers"].as_array().unwrap().clone())
        .filter(|c| c["name"] == "shrunk_sampling")
        .flat_map(|c| c["levels"].as_array().cloned().unwrap_or_default())
        .map(|l| l["resolution"].as_u64().unwrap())
        .collect();
    assert!(!levels.is_empty(), "{doc}");
    assert!(levels.iter().all(|&r| r == 64), "{levels:?}");
    assert!(stderr.contains(", 64 px: "), "{stderr}");
    assert!(
        stderr.contains("64 px per view (--sampling-resolution)"),
        "{stderr}"
    );
}

/// `bake` of the wall scene and its cells written into `dir`, output `dir/pvs.json`.
fn wall_bake(dir: &Path) -> (Command, PathBuf) {
    let scene = write(dir, "s.obj", SCENE);
    let cells = write(dir, "c.json", CELLS);
    let out = dir.join("pvs.json");
    let mut c = bin();
    c.arg("bake")
        .arg(&scene)
        .arg("--cells")
        .arg(&cells)
        .arg("-o")
        .arg(&out);
    (c, out)
}

/// `--backend auto` probes the adapters without the display server's noise on stderr (Mesa
/// prints "XDG_RUNTIME_DIR is invalid or not set" when the variable is missing, as on CI).
#[test]
fn backend_auto_prints_no_driver_noise() {
    let dir = tempfile::tempdir().unwrap();
    let (mut cmd, _) = wall_bake(dir.path());
    let r = cmd
        .args(["--backend", "auto"])
        .env_remove("XDG_RUNTIME_DIR")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{stderr}");
    assert!(!stderr.contains("XDG_RUNTIME_DIR"), "{stderr}");
    // Nothing but the progress lines (stderr is a pipe here) comes before the summary.
    let rest: Vec<&str> = stderr
        .lines()
        .skip_while(|l| l.starts_with("bake: "))
        .collect();
    assert!(
        rest.first().is_some_and(|l| l.starts_with("scene ")),
        "{stderr}"
    );
}

/// The private folder that quiets the adapter probe is removed however the process ends: after
/// a bake, `--help` and a usage error (both end inside the argument parser) leave nothing in
/// the temporary directory.
#[test]
fn the_probe_folder_is_removed_on_every_exit() {
    let dir = tempfile::tempdir().unwrap();
    let tmp = dir.path().join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let (mut bake, out) = wall_bake(dir.path());
    bake.args(["--backend", "cpu"]);
    let mut help = bin();
    help.arg("--help");
    let mut usage = bin();
    usage.args(["bake", "--no-such-flag"]);
    for (k, mut cmd) in [bake, help, usage].into_iter().enumerate() {
        let r = cmd
            .env_remove("XDG_RUNTIME_DIR")
            .env("TMPDIR", &tmp)
            .output()
            .unwrap();
        assert_eq!(r.status.success(), k < 2, "run {k}: {r:?}");
        let left: Vec<_> = std::fs::read_dir(&tmp).unwrap().collect();
        assert!(left.is_empty(), "run {k} left {left:?}");
    }
    assert!(out.exists());
}

/// A bake estimated to need more memory than `--max-memory` is refused before it starts:
/// the estimate and what to change in the message, no output and no journal.
#[test]
fn max_memory_refuses_a_bake_that_cannot_fit() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("pvs.json");
    let run = |limit: &str| {
        wall_bake(dir.path())
            .0
            .args(["--backend", "cpu", "--max-memory", limit])
            .output()
            .unwrap()
    };
    let r = run("1K");
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("s.obj") && stderr.contains("GiB") && stderr.contains("--max-memory"),
        "{stderr}"
    );
    assert!(!out.exists());
    assert!(!dir.path().join("pvs.json.journal").exists());
    let r = run("lots");
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("expected a size such as 16G"), "{stderr}");
    let r = run("1.5GiB");
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(out.exists());
}

/// The `bake: N/M cells` progress lines of `stderr`, as `(done, total)`.
fn progress_lines(stderr: &str) -> Vec<(usize, usize)> {
    stderr
        .lines()
        .filter_map(|l| {
            let rest = l.strip_prefix("bake: ")?;
            let (count, _) = rest.split_once(" cells")?;
            let (d, t) = count.split_once('/')?;
            Some((d.parse().ok()?, t.parse().ok()?))
        })
        .collect()
}

/// With stderr not a terminal (a pipe here, as in a batch job's log) the bar draws nothing,
/// so `bake` prints plain progress lines: every cell's with `--progress-every 0`, the last
/// cell's always (also with the default interval), none with `off` or `--quiet`.
#[test]
fn a_bake_logs_plain_progress_when_stderr_is_not_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let run = |extra: &[&str]| {
        let (mut c, _) = wall_bake(dir.path());
        // One worker, so that the cells finish (and report) one after the other.
        c.env("RAYON_NUM_THREADS", "1");
        let r = c.args(["--backend", "cpu"]).args(extra).output().unwrap();
        let stderr = String::from_utf8_lossy(&r.stderr).into_owned();
        assert!(r.status.success(), "{extra:?}: {stderr}");
        stderr
    };
    let every = progress_lines(&run(&["--progress-every", "0"]));
    assert!(every.iter().all(|&(_, t)| t == 2), "{every:?}");
    assert_eq!(every.last(), Some(&(2, 2)), "{every:?}");
    assert!(
        every.windows(2).all(|w| w[0].0 <= w[1].0),
        "the counts go up: {every:?}"
    );
    assert!(
        every.iter().any(|&(d, _)| d == 1),
        "a line per cell: {every:?}"
    );
    let default = progress_lines(&run(&[]));
    assert_eq!(default.last(), Some(&(2, 2)), "{default:?}");
    assert!(progress_lines(&run(&["--progress-every", "off"])).is_empty());
    let quiet = run(&["--quiet", "--progress-every", "0"]);
    assert!(progress_lines(&quiet).is_empty(), "{quiet}");
    let scene = dir.path().join("s.obj");
    let cells = dir.path().join("c.json");
    refuses(
        &scene,
        &[
            "--cells",
            cells.to_str().unwrap(),
            "--progress-every",
            "soon",
        ],
        "--progress-every",
    );
}
