//! Tests of `umbrasweep validate` (owned by the validator work): analytic scenes built in
//! memory, hand-written PVS documents, the library API (`sample_cell`, `check`, hunt mode) and
//! the command line (exit codes 0/1/2, `--json`, `--hunt`).

mod common;

use glam::{Vec3, vec3};
use std::path::{Path, PathBuf};
use std::process::Command;
use umbrasweep::geom::Aabb;
use umbrasweep::pvs::{FORMAT, PvsCell, PvsDocument, PvsSettings, VERSION};
use umbrasweep::scene::Scene;
use umbrasweep::validate::{CheckOptions, SceneRays, ValidateError, check, sample_cell};

type Obj = (String, Vec<[Vec3; 3]>, bool);

/// The view cell of every test: the cube [-1, 1]³.
fn cell() -> Aabb {
    Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0))
}

/// A closed box (12 triangles, outward facing).
fn cuboid(min: Vec3, max: Vec3) -> Vec<[Vec3; 3]> {
    umbrasweep::geom::box_triangles(min, max)
}

/// A wall in the plane `z`, made of the grid cells between the given x and y breaks,
/// leaving out the grid cells for which `hole(i, j)` is true. Neighbouring grid cells share
/// their corners exactly (no T-junction), and diagonals alternate.
fn grid_wall(
    z: f32,
    xs: &[f32],
    ys: &[f32],
    hole: impl Fn(usize, usize) -> bool,
) -> Vec<[Vec3; 3]> {
    let mut out = Vec::new();
    for i in 0..xs.len() - 1 {
        for j in 0..ys.len() - 1 {
            if hole(i, j) {
                continue;
            }
            let a = vec3(xs[i], ys[j], z);
            let b = vec3(xs[i + 1], ys[j], z);
            let c = vec3(xs[i + 1], ys[j + 1], z);
            let d = vec3(xs[i], ys[j + 1], z);
            if (i + j) % 2 == 0 {
                out.extend([[a, b, c], [a, c, d]]);
            } else {
                out.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    out
}

fn breaks(lo: f32, hi: f32, n: usize) -> Vec<f32> {
    (0..=n)
        .map(|i| lo + (hi - lo) * i as f32 / n as f32)
        .collect()
}

fn scene(objects: Vec<Obj>) -> Scene {
    Scene::from_objects(Path::new("test.obj"), objects)
}

/// A PVS document for `scene` with one cell (the test cell) whose PVS is `visible`.
fn doc(scene: &Scene, visible: Vec<u32>, alpha_occluders: bool) -> PvsDocument {
    doc_cells(scene, vec![(cell(), visible)], alpha_occluders)
}

/// A PVS document for `scene` with the given cells and their PVS.
fn doc_cells(scene: &Scene, cells: Vec<(Aabb, Vec<u32>)>, alpha_occluders: bool) -> PvsDocument {
    PvsDocument {
        format: FORMAT.into(),
        version: VERSION,
        scene: scene.source.display().to_string(),
        settings: PvsSettings {
            bake: umbrasweep::BakeSettings {
                alpha_occluders,
                ..Default::default()
            },
            ..Default::default()
        },
        objects: umbrasweep::bake::object_table(scene),
        cells: cells
            .into_iter()
            .map(|(c, visible)| PvsCell {
                min: c.min.to_array(),
                max: c.max.to_array(),
                visible,
                ms: 0.0,
                cullers: Vec::new(),
                parent: None,
            })
            .collect(),
        summary: None,
        split: None,
    }
}

fn opts(rays: u64) -> CheckOptions {
    CheckOptions {
        rays,
        seed: 7,
        ..Default::default()
    }
}

fn strictly_inside(p: Vec3, c: &Aabb) -> bool {
    p.cmpgt(c.min).all() && p.cmplt(c.max).all()
}

/// Distance from `p` to the nearest triangle of object `o` (by plane distance, for points
/// inside the triangle's bounds).
fn on_object(scene: &Scene, o: u32, p: Vec3) -> bool {
    let obj = &scene.objects[o as usize];
    obj.triangles.clone().any(|t| {
        let [a, b, c] = scene.triangle(t as usize);
        let n = (b - a).cross(c - a).normalize();
        let mut bb = Aabb::from_points(&[a, b, c]);
        bb.min -= Vec3::splat(1e-4);
        bb.max += Vec3::splat(1e-4);
        (p - a).dot(n).abs() < 1e-4 && bb.contains_point(p)
    })
}

#[test]
fn object_in_plain_view_is_found() {
    let s = scene(vec![(
        "target".into(),
        cuboid(vec3(-1.0, -1.0, 10.0), vec3(1.0, 1.0, 12.0)),
        true,
    )]);
    let rays = SceneRays::new(&s);
    let vs = sample_cell(&rays, &s, cell(), 20_000, 1, 0, false);
    assert_eq!(vs.visible, vec![0]);
    let w = vs.witness[0].expect("a ray saw it");
    assert!(strictly_inside(w.origin, &cell()));
    assert!(on_object(&s, 0, w.hit), "hit {:?}", w.hit);
}

/// A closed slab (two faces subdivided into 16 × 16 quads plus the rim of a box) at z 4–5 and
/// a box behind it that no ray from the cell can reach.
fn closed_slab_and_hidden_box() -> Vec<Obj> {
    let xs = breaks(-50.0, 50.0, 17);
    let mut wall = grid_wall(4.0, &xs, &xs, |_, _| false);
    wall.extend(grid_wall(5.0, &xs, &xs, |_, _| false));
    wall.extend(cuboid(vec3(-50.0, -50.0, 4.0), vec3(50.0, 50.0, 5.0)));
    vec![
        ("wall".into(), wall, true),
        (
            "hidden".into(),
            cuboid(vec3(-1.0, -1.0, 10.0), vec3(1.0, 1.0, 12.0)),
            true,
        ),
    ]
}

#[test]
fn object_behind_a_big_closed_wall_is_never_found() {
    let s = scene(closed_slab_and_hidden_box());
    let rays = SceneRays::new(&s);
    let vs = sample_cell(&rays, &s, cell(), 300_000, 3, 0, false);
    assert_eq!(
        vs.visible,
        vec![0],
        "the hidden box leaked through the wall"
    );
    // And a PVS without it is fine.
    let report = check(&s, &doc(&s, vec![0], false), &opts(100_000)).unwrap();
    assert_eq!(report.false_culls, 0);
}

#[test]
fn object_seen_only_through_a_narrow_slit_is_found() {
    // Wall at z = 5 with a slit |x| < 0.003, |y| < 0.1 (0.3 % of the cell's width; about
    // 0.1 % of the segments from the cell to the target pass it): the target, a box 2 wide at
    // z = 10, is seen only through it. 120 boxes in plain view spread the aimed rays thin, so
    // it is (nearly always) the targeted rounds, aimed at the objects not found yet, that find
    // it. Over seeds 0..60 it was found every time, by phase 2 or later in 50 of them.
    let xs = [-50.0, -0.003, 0.003, 50.0];
    let ys = [-50.0, -0.1, 0.1, 50.0];
    let mut objects: Vec<Obj> = vec![(
        "slit_wall".into(),
        grid_wall(5.0, &xs, &ys, |i, j| i == 1 && j == 1),
        true,
    )];
    objects.push((
        "target".into(),
        cuboid(vec3(-1.0, -1.0, 10.0), vec3(1.0, 1.0, 12.0)),
        true,
    ));
    objects.push((
        "hidden".into(),
        cuboid(vec3(10.0, -1.0, 10.0), vec3(12.0, 1.0, 12.0)),
        true,
    ));
    for i in 0..120 {
        let a = i as f32 * 0.37;
        let p = vec3(3.0 * a.cos(), 3.0 * a.sin(), -3.0 - (i % 7) as f32);
        objects.push((
            format!("clutter{i}"),
            cuboid(p - Vec3::splat(0.2), p + Vec3::splat(0.2)),
            true,
        ));
    }
    let s = scene(objects);
    let rays = SceneRays::new(&s);
    let vs = sample_cell(&rays, &s, cell(), 40_000, 11, 0, false);
    let w = vs
        .witness_of(1)
        .expect("the target behind the slit was not found")
        .expect("found by a ray");
    assert!(
        w.phase >= 2,
        "expected the targeted rounds to find it, got phase {}",
        w.phase
    );
    assert!(strictly_inside(w.origin, &cell()));
    assert!(on_object(&s, 1, w.hit));
    // The ray passes the wall plane inside the slit.
    let t = (5.0 - w.origin.z) / w.direction.z;
    let at_wall = w.origin + w.direction * t;
    assert!(
        at_wall.x.abs() <= 0.0031 && at_wall.y.abs() <= 0.1001,
        "{at_wall:?}"
    );
    assert!(
        vs.witness_of(2).is_none(),
        "the box fully behind the wall was seen"
    );
}

/// A see-through (alpha-tested) wall of quads at z = 5 and an opaque box behind it.
fn alpha_wall_and_box() -> Vec<Obj> {
    let xs = breaks(-50.0, 50.0, 4);
    vec![
        (
            "foliage".into(),
            grid_wall(5.0, &xs, &xs, |_, _| false),
            false,
        ),
        (
            "behind".into(),
            cuboid(vec3(-1.0, -1.0, 10.0), vec3(1.0, 1.0, 12.0)),
            true,
        ),
    ]
}

#[test]
fn alpha_wall_hides_only_when_alpha_occluders_is_set() {
    let s = scene(alpha_wall_and_box());
    let rays = SceneRays::new(&s);
    let seen = sample_cell(&rays, &s, cell(), 20_000, 5, 0, false);
    assert_eq!(seen.visible, vec![0, 1]);
    let blocked = sample_cell(&rays, &s, cell(), 20_000, 5, 0, true);
    assert_eq!(blocked.visible, vec![0]);

    // Through `check`, the PVS setting decides.
    let r = check(&s, &doc(&s, vec![0], true), &opts(20_000)).unwrap();
    assert_eq!(r.false_culls, 0);
    assert!(r.alpha_occluders);
    let r = check(&s, &doc(&s, vec![0], false), &opts(20_000)).unwrap();
    assert_eq!(r.false_culls, 1);
    assert_eq!(r.cells[0].false_culls[0].object, 1);
}

/// Two boxes in plain view and one hidden behind a wall.
fn three_box_scene() -> Scene {
    let xs = breaks(-50.0, 50.0, 4);
    scene(vec![
        (
            "front".into(),
            cuboid(vec3(-1.0, -1.0, -12.0), vec3(1.0, 1.0, -10.0)),
            true,
        ),
        ("wall".into(), grid_wall(5.0, &xs, &xs, |_, _| false), true),
        (
            "side".into(),
            cuboid(vec3(8.0, -1.0, -1.0), vec3(10.0, 1.0, 1.0)),
            true,
        ),
        (
            "hidden".into(),
            cuboid(vec3(-1.0, -1.0, 10.0), vec3(1.0, 1.0, 12.0)),
            true,
        ),
    ])
}

#[test]
fn missing_visible_object_is_a_false_cull_with_a_witness_ray() {
    let s = three_box_scene();
    let r = check(&s, &doc(&s, vec![0, 1], false), &opts(50_000)).unwrap();
    assert_eq!(r.false_culls, 1);
    assert_eq!(r.cells_with_false_culls, 1);
    let c = &r.cells[0];
    assert_eq!(c.visible, vec![0, 1, 2]);
    assert_eq!((c.pvs, c.vs), (2, 3));
    let f = &c.false_culls[0];
    assert_eq!(
        (f.object, f.name.as_str(), f.reason.as_str()),
        (2, "side", "ray")
    );
    let (origin, dir, hit) = (f.origin.unwrap(), f.direction.unwrap(), f.hit.unwrap());
    assert!(strictly_inside(origin, &cell()), "origin {origin:?}");
    assert!(on_object(&s, 2, hit), "hit {hit:?}");
    assert!((dir.length() - 1.0).abs() < 1e-5);
    // The witness ray really sees the object first.
    let rays = SceneRays::new(&s);
    let hits = rays.trace(origin, dir, false);
    assert_eq!(hits.first().map(|h| h.object), Some(2));
    // Culled percentages count what the PVS drops.
    assert!((c.objects_culled_percent - 50.0).abs() < 1e-9);
    let table = r.table();
    assert!(
        table.contains("FALSE CULL cell 0: object 2 \"side\""),
        "{table}"
    );
}

#[test]
fn same_seed_gives_the_same_report_on_one_and_two_threads() {
    let s = three_box_scene();
    let d = doc(&s, vec![0, 1], false);
    same_report_on_one_and_two_threads(&s, &d, &opts(30_001), |_| {});
}

/// Checks `d` with `o` on pools of 1 and 2 threads (`inspect` looks at each report): the JSON
/// reports must be identical, and another seed must change them.
fn same_report_on_one_and_two_threads(
    s: &Scene,
    d: &PvsDocument,
    o: &CheckOptions,
    inspect: impl Fn(&umbrasweep::validate::Report),
) {
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let r = pool.install(|| check(s, d, o).unwrap());
        inspect(&r);
        serde_json::to_string(&r).unwrap()
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_eq!(one, run(2));
    let other = CheckOptions {
        seed: o.seed + 1,
        ..o.clone()
    };
    let other_seed = serde_json::to_string(&check(s, d, &other).unwrap()).unwrap();
    assert_ne!(one, other_seed, "the seed should change the witness rays");
}

#[test]
fn mismatched_pvs_and_zero_rays_are_bad_input() {
    let s = three_box_scene();
    let mut d = doc(&s, vec![0, 1, 2], false);
    d.objects.pop();
    let e = check(&s, &d, &opts(10)).unwrap_err();
    assert!(matches!(e, ValidateError::SceneMismatch(_)));
    assert!(
        e.to_string()
            .contains("the PVS was baked from another scene")
    );
    let mut d = doc(&s, vec![0, 1, 2], false);
    d.objects[3].name = "other".into();
    assert!(matches!(
        check(&s, &d, &opts(10)),
        Err(ValidateError::SceneMismatch(_))
    ));
    let d = doc(&s, vec![0, 1, 2], false);
    assert!(matches!(
        check(&s, &d, &opts(0)),
        Err(ValidateError::NoRays)
    ));
    let mut d = doc(&s, vec![0], false);
    d.cells[0].min = [f32::NAN, 0.0, 0.0];
    assert!(matches!(
        check(&s, &d, &opts(10)),
        Err(ValidateError::BadCell { .. })
    ));
}

// ---- command line ----

fn tmpdir() -> tempfile::TempDir {
    tempfile::tempdir().unwrap()
}

fn write_obj(scene: &Scene, path: &Path) {
    let mut s = String::new();
    let mut v = 1;
    for o in &scene.objects {
        s.push_str(&format!("o {}\n", o.name));
        for t in o.triangles.clone() {
            for p in scene.triangle(t as usize) {
                s.push_str(&format!("v {} {} {}\n", p.x, p.y, p.z));
            }
            s.push_str(&format!("f {} {} {}\n", v, v + 1, v + 2));
            v += 3;
        }
    }
    std::fs::write(path, s).unwrap();
}

fn write_doc(d: &PvsDocument, path: &Path) {
    std::fs::write(path, serde_json::to_string_pretty(d).unwrap()).unwrap();
}

fn validate(args: &[&std::ffi::OsStr]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_umbrasweep"))
        .arg("validate")
        .args(args)
        .output()
        .unwrap()
}

/// The scene as an OBJ file, or `None` (with a note) while the OBJ importer cannot read it.
fn obj_scene(dir: &Path, scene: &Scene) -> Option<PathBuf> {
    let path = dir.join("scene.obj");
    write_obj(scene, &path);
    match umbrasweep::scene::load(&path) {
        Ok(loaded) if loaded.objects.len() == scene.objects.len() => Some(path),
        Ok(_) => {
            eprintln!("note: the OBJ importer numbers objects differently; CLI part skipped");
            None
        }
        Err(e) => {
            eprintln!(
                "note: the OBJ importer cannot load the test scene yet ({e}); CLI part skipped"
            );
            None
        }
    }
}

/// The files of a CLI test: the folder (bind it, as `_dir`, for as long as the files are
/// used: dropping it deletes them), the scene as OBJ, the PVS `d` written as JSON, and where
/// `--json` goes; `None` as [`obj_scene`].
struct CliFiles {
    _dir: tempfile::TempDir,
    obj: PathBuf,
    pvs: PathBuf,
    json: PathBuf,
}

fn cli_files(s: &Scene, d: &PvsDocument) -> Option<CliFiles> {
    let dir = tmpdir();
    let obj = obj_scene(dir.path(), s)?;
    let pvs = dir.path().join("pvs.json");
    let json = dir.path().join("out.json");
    write_doc(d, &pvs);
    Some(CliFiles {
        _dir: dir,
        obj,
        pvs,
        json,
    })
}

#[test]
fn cli_false_cull_exits_1_and_writes_json() {
    let s = three_box_scene();
    let Some(CliFiles {
        _dir,
        obj,
        pvs,
        json,
    }) = cli_files(&s, &doc(&s, vec![0, 1], false))
    else {
        return;
    };
    let out = validate(&[
        obj.as_os_str(),
        pvs.as_os_str(),
        "--rays".as_ref(),
        "20000".as_ref(),
        "--seed".as_ref(),
        "3".as_ref(),
        "--json".as_ref(),
        json.as_os_str(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("FALSE CULL"), "{stdout}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(v["false_culls"], 1);
    assert_eq!(v["rays_per_cell"], 20000);
    assert_eq!(v["seed"], 3);
    let c = &v["cells"][0];
    assert_eq!(c["visible"], serde_json::json!([0, 1, 2]));
    assert_eq!(c["false_culls"][0]["object"], 2);
    assert_eq!(c["false_culls"][0]["name"], "side");
    for k in ["origin", "direction", "hit"] {
        assert_eq!(
            c["false_culls"][0][k].as_array().map(|a| a.len()),
            Some(3),
            "{k}"
        );
    }
    assert_eq!((c["pvs"].as_u64(), c["vs"].as_u64()), (Some(2), Some(3)));

    // A conservative PVS exits 0.
    write_doc(&doc(&s, vec![0, 1, 2, 3], false), &pvs);
    let out = validate(&[
        obj.as_os_str(),
        pvs.as_os_str(),
        "--rays".as_ref(),
        "20000".as_ref(),
    ]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
}

/// With stderr a pipe (as in a batch job's log) the bar draws nothing, so `validate` prints
/// plain `validate: done/total rays` lines: at every report with `--progress-every 0`, always
/// a last one with every ray counted, none with `off`.
#[test]
fn cli_logs_plain_progress_when_stderr_is_not_a_terminal() {
    let s = three_box_scene();
    let Some(CliFiles { _dir, obj, pvs, .. }) = cli_files(&s, &doc(&s, vec![0, 1, 2, 3], false))
    else {
        return;
    };
    let run = |every: &str| {
        let out = validate(&[
            obj.as_os_str(),
            pvs.as_os_str(),
            "--rays".as_ref(),
            "20000".as_ref(),
            "--progress-every".as_ref(),
            every.as_ref(),
        ]);
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert_eq!(out.status.code(), Some(0), "{stderr}");
        stderr
            .lines()
            .filter(|l| l.starts_with("validate: "))
            .map(str::to_owned)
            .collect::<Vec<_>>()
    };
    let lines = run("0");
    assert!(
        lines
            .last()
            .is_some_and(|l| l.starts_with("validate: 20,000/20,000 rays (100 %), ")),
        "{lines:?}"
    );
    assert!(run("off").is_empty());
}

#[test]
fn cli_bad_input_exits_2() {
    let s = three_box_scene();
    let dir = tmpdir();
    let pvs = dir.path().join("pvs.json");
    write_doc(&doc(&s, vec![0, 1, 2], false), &pvs);
    let missing = dir.path().join("missing.obj");

    // Missing scene.
    let out = validate(&[missing.as_os_str(), pvs.as_os_str()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("error:"));
    // --rays 0.
    let out = validate(&[
        missing.as_os_str(),
        pvs.as_os_str(),
        "--rays".as_ref(),
        "0".as_ref(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--rays"));
    // Malformed and missing PVS (read before the scene).
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, "{not json").unwrap();
    for p in [&bad, &dir.path().join("nope.json")] {
        let out = validate(&[missing.as_os_str(), p.as_os_str()]);
        assert_eq!(out.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&out.stderr).contains(&*p.display().to_string()));
    }
    // A PVS of another scene (needs the OBJ importer).
    let Some(obj) = obj_scene(dir.path(), &s) else {
        return;
    };
    let mut d = doc(&s, vec![0], false);
    d.objects[2].name = "renamed".into();
    write_doc(&d, &pvs);
    let json = dir.path().join("out.json");
    let out = validate(&[
        obj.as_os_str(),
        pvs.as_os_str(),
        "--json".as_ref(),
        json.as_os_str(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("the PVS was baked from another scene"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!json.exists(), "no report on bad input");
}

// ---- --hunt ----

/// Object ids of [`corner_slit_scene`].
const SLIT_WALL: u32 = 0;
const SLIT_TARGET: u32 = 1;
const SLIT_HIDDEN: u32 = 2;
const SLIT_HIDDEN_COUNT: u32 = 1000;

/// The hunt scene: a closed wall at z = 3 with a slit |x| < 0.01, |y| < 0.1, and behind it the
/// target, a box 0.2 wide centred at (−3, −3, 9) on the line from the cell's corner (1, 1, 1)
/// through the slit. That line leaves the cell at the corner, so only from within about 0.15
/// of that corner does a line through the slit reach the target: in a simulation, 0.8 % of
/// the hunting rays (all starting near the corner or an edge) and 0.0005 % of rays from
/// uniform origins did. 1000 boxes behind the wall, out of the slit's view, stand for the
/// objects a conservative PVS keeps without the sampling ever finding them: the plain
/// sampling's aimed and targeted rays are spread over them.
fn corner_slit_scene() -> Scene {
    scene(corner_slit_objects())
}

/// The objects of [`corner_slit_scene`].
fn corner_slit_objects() -> Vec<Obj> {
    let xs = [-50.0, -0.01, 0.01, 50.0];
    let ys = [-50.0, -0.1, 0.1, 50.0];
    let mut objects: Vec<Obj> = vec![
        (
            "slit_wall".into(),
            grid_wall(3.0, &xs, &ys, |i, j| i == 1 && j == 1),
            true,
        ),
        (
            "target".into(),
            cuboid(vec3(-3.1, -3.1, 8.9), vec3(-2.9, -2.9, 9.1)),
            true,
        ),
    ];
    for i in 0..SLIT_HIDDEN_COUNT {
        let p = vec3(
            8.0 + (i % 40) as f32 * 0.8,
            -20.0 + (i / 40) as f32 * 1.6,
            5.0 + (i % 7) as f32 * 0.5,
        );
        objects.push((
            format!("hidden{i}"),
            cuboid(p - Vec3::splat(0.25), p + Vec3::splat(0.25)),
            true,
        ));
    }
    objects
}

/// A PVS of [`corner_slit_scene`] that keeps everything but the target: over-conservative
/// (the hidden boxes) and wrong (the target).
fn slit_doc_without_target(s: &Scene) -> PvsDocument {
    let all: Vec<u32> = (0..s.objects.len() as u32)
        .filter(|&o| o != SLIT_TARGET)
        .collect();
    doc(s, all, false)
}

fn hunt_opts(rays: u64) -> CheckOptions {
    CheckOptions {
        hunt: true,
        ..opts(rays)
    }
}

/// Where the ray from `origin` along `dir` crosses the plane z = `z`.
fn at_z(origin: Vec3, dir: Vec3, z: f32) -> Vec3 {
    origin + dir * ((z - origin.z) / dir.z)
}

#[test]
fn hunt_finds_a_false_cull_that_plain_sampling_misses() {
    let s = corner_slit_scene();
    let d = slit_doc_without_target(&s);

    // Plain sampling with 2,000 rays: 600 aimed rays and 1,000 targeted ones are shared by
    // the 1,001 objects it never finds, so a few go to the target, and almost never one from
    // the corner. It misses the target and passes the wrong PVS. (Over seeds 0..300 it found
    // the target with seeds 4 and 10 only; the hunt found it with every seed, within 1,360
    // rays at worst and about 100 typically.)
    let plain = check(&s, &d, &opts(2_000)).unwrap();
    assert!(!plain.hunt);
    assert_eq!(
        plain.false_culls,
        0,
        "the plain sampling was expected to miss the target:\n{}",
        plain.table()
    );
    assert!(!plain.cells[0].visible.contains(&SLIT_TARGET));
    assert_eq!(plain.cells[0].visible, vec![SLIT_WALL]);

    // --hunt with the same budget: the target is the only culled object, all 2,000 rays go
    // to it, and about 1 % of them pass the slit.
    let r = check(&s, &d, &hunt_opts(2_000)).unwrap();
    assert!(r.hunt);
    assert_eq!(
        (r.hunted_objects, r.rays_per_culled_object),
        (Some(1), Some(2_000))
    );
    assert_eq!(r.false_culls, 1, "{}", r.table());
    let c = &r.cells[0];
    assert_eq!((c.hunted, c.rays_per_culled_object), (Some(1), Some(2_000)));
    assert!(c.rays <= 2_000 && c.rays >= 1);
    // The visible set is not measured.
    assert!(c.visible.is_empty() && c.vs == 0 && c.pvs_over_vs.is_none());
    assert_eq!(c.pvs, s.objects.len() - 1);
    let f = &c.false_culls[0];
    assert_eq!(
        (f.object, f.name.as_str(), f.reason.as_str()),
        (SLIT_TARGET, "target", "ray")
    );
    assert!(f.ray.unwrap() < 2_000);
    assert_eq!(
        f.ray.unwrap() + 1,
        c.rays,
        "the hunt stops at its first witness"
    );
    let (origin, dir, hit) = (f.origin.unwrap(), f.direction.unwrap(), f.hit.unwrap());
    assert!(strictly_inside(origin, &cell()), "origin {origin:?}");
    assert!((dir.length() - 1.0).abs() < 1e-5);
    assert!(on_object(&s, SLIT_TARGET, hit), "hit {hit:?}");
    // The witness passes the slit, and starts near the corner it is seen from.
    let w = at_z(origin, dir, 3.0);
    assert!(w.x.abs() <= 0.0101 && w.y.abs() <= 0.1001, "{w:?}");
    assert!(origin.cmpgt(Vec3::splat(0.8)).all(), "origin {origin:?}");
    // An independent brute-force cast agrees that the target is the first thing it hits.
    let tris: Vec<(String, Vec<[Vec3; 3]>)> = s
        .objects
        .iter()
        .map(|o| {
            let t = o
                .triangles
                .clone()
                .map(|t| s.triangle(t as usize))
                .collect();
            (o.name.clone(), t)
        })
        .collect();
    let objects = tris.iter().map(|(n, t)| (n.as_str(), &t[..]));
    assert_eq!(common::first_hit(objects, origin, dir), Some("target"));
    let table = r.table();
    assert!(
        table.contains("FALSE CULL cell 0: object 1 \"target\""),
        "{table}"
    );
    assert!(table.contains("rays/obj"), "{table}");
}

#[test]
fn hunt_reports_no_false_cull_for_a_correct_pvs() {
    // The slit scene with a correct PVS: wall and target kept, the 1,000 boxes behind the
    // wall culled. Each of them gets 50 rays, none of which gets through.
    let s = corner_slit_scene();
    let d = doc(&s, vec![SLIT_WALL, SLIT_TARGET], false);
    let r = check(&s, &d, &hunt_opts(50_000)).unwrap();
    assert_eq!(r.false_culls, 0, "{}", r.table());
    let c = &r.cells[0];
    assert_eq!(c.hunted, Some(SLIT_HIDDEN_COUNT as usize));
    assert_eq!(c.rays_per_culled_object, Some(50));
    // Nothing was seen, so every ray was cast.
    assert_eq!(c.rays, 50_000);
    assert_eq!(r.rays_cast, c.rays);
    let table = r.table();
    assert!(
        table.contains("no false cull in 1 cells (hunt: 1000 culled objects, at least 50 rays"),
        "{table}"
    );

    // A single hidden box behind a closed, subdivided slab gets all 100,000 rays, many of them
    // aimed at its edges and corners through the slab's shared edges: none leaks.
    let s = scene(closed_slab_and_hidden_box());
    let r = check(&s, &doc(&s, vec![0], false), &hunt_opts(100_000)).unwrap();
    assert_eq!(r.false_culls, 0, "{}", r.table());
    assert_eq!(r.cells[0].rays_per_culled_object, Some(100_000));
    assert_eq!(r.rays_cast, 100_000);
    // A PVS that culls nothing leaves nothing to hunt.
    let r = check(&s, &doc(&s, vec![0, 1], false), &hunt_opts(1_000)).unwrap();
    assert_eq!((r.false_culls, r.rays_cast), (0, 0));
    assert_eq!(r.cells[0].hunted, Some(0));
    assert_eq!(r.rays_per_culled_object, Some(0));
}

#[test]
fn hunt_honours_see_through_triangles_and_overlap() {
    let mut objects = alpha_wall_and_box();
    objects.push((
        "inside".into(),
        cuboid(vec3(-0.2, -0.2, -0.2), vec3(0.2, 0.2, 0.2)),
        true,
    ));
    let s = scene(objects);
    // See-through foliage: the box behind it is seen, unless the PVS was baked with alpha
    // occluders.
    let r = check(&s, &doc(&s, vec![0, 2], false), &hunt_opts(1_000)).unwrap();
    assert_eq!(r.false_culls, 1, "{}", r.table());
    assert_eq!(r.cells[0].false_culls[0].object, 1);
    let r = check(&s, &doc(&s, vec![0, 2], true), &hunt_opts(1_000)).unwrap();
    assert_eq!(r.false_culls, 0, "{}", r.table());
    // Culling the foliage itself is caught too (its triangles are seen first).
    let r = check(&s, &doc(&s, vec![1, 2], true), &hunt_opts(1_000)).unwrap();
    assert_eq!(r.false_culls, 1);
    assert_eq!(r.cells[0].false_culls[0].object, 0);
    // An object inside the cell is visible, by a ray or by definition.
    let r = check(&s, &doc(&s, vec![0, 1], false), &hunt_opts(1_000)).unwrap();
    assert_eq!(r.false_culls, 1);
    assert_eq!(r.cells[0].false_culls[0].object, 2);
}

/// Three cells with the same PVS `visible`: the test cell, one behind it and one at its
/// corner.
fn three_cells(visible: Vec<u32>) -> Vec<(Aabb, Vec<u32>)> {
    vec![
        (cell(), visible.clone()),
        (
            Aabb::new(vec3(-1.0, -1.0, -3.0), vec3(1.0, 1.0, -1.5)),
            visible.clone(),
        ),
        (Aabb::new(vec3(1.0, 1.0, 0.0), vec3(2.0, 2.0, 1.0)), visible),
    ]
}

#[test]
fn hunt_gives_the_same_report_on_one_and_two_threads() {
    // Three cells of the slit scene; each PVS culls the target and a few hidden boxes, so the
    // budget of 30,001 rays is split 6 ways into several chunks per object (several waves),
    // and the first cell has a false cull to find.
    let s = corner_slit_scene();
    let culled = [
        SLIT_TARGET,
        SLIT_HIDDEN,
        SLIT_HIDDEN + 7,
        SLIT_HIDDEN + 150,
        SLIT_HIDDEN + 999,
        SLIT_HIDDEN + 42,
    ];
    let keep: Vec<u32> = (0..s.objects.len() as u32)
        .filter(|o| !culled.contains(o))
        .collect();
    let d = doc_cells(&s, three_cells(keep), false);
    same_report_on_one_and_two_threads(&s, &d, &hunt_opts(30_001), |r| {
        assert_eq!(r.rays_per_culled_object, Some(5_000));
        assert!(r.false_culls >= 1, "{}", r.table());
        assert!(
            r.cells[0]
                .false_culls
                .iter()
                .any(|f| f.object == SLIT_TARGET)
        );
    });
}

#[test]
fn cli_hunt_exits_1_on_a_false_cull_and_0_on_a_good_pvs() {
    let out = Command::new(env!("CARGO_BIN_EXE_umbrasweep"))
        .args(["validate", "--help"])
        .output()
        .unwrap();
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(
        help.contains("--hunt") && help.contains("validate forest.obj forest_pvs.json --hunt"),
        "{help}"
    );

    let s = corner_slit_scene();
    let Some(CliFiles {
        _dir,
        obj,
        pvs,
        json,
    }) = cli_files(&s, &slit_doc_without_target(&s))
    else {
        return;
    };
    let args = |hunt: bool| {
        let mut a: Vec<&std::ffi::OsStr> = vec![
            obj.as_os_str(),
            pvs.as_os_str(),
            "--rays".as_ref(),
            "2000".as_ref(),
            "--seed".as_ref(),
            "7".as_ref(),
            "--json".as_ref(),
            json.as_os_str(),
        ];
        if hunt {
            a.push("--hunt".as_ref());
        }
        validate(&a)
    };
    let read_json =
        || -> serde_json::Value { serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap() };

    // Plain: misses the target, exits 0, and its report has no hunt fields.
    let out = args(false);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let v = read_json();
    for k in ["hunt", "hunted_objects", "rays_per_culled_object"] {
        assert!(v.get(k).is_none(), "{k}");
    }
    assert!(v["cells"][0].get("rays_per_culled_object").is_none());

    // --hunt: finds it, exits 1.
    let out = args(true);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("FALSE CULL cell 0: object 1 \"target\""),
        "{stdout}"
    );
    let v = read_json();
    assert_eq!(v["hunt"], true);
    assert_eq!(v["hunted_objects"], 1);
    assert_eq!(v["rays_per_culled_object"], 2000);
    assert_eq!(v["rays_per_cell"], 2000);
    assert_eq!(v["false_culls"], 1);
    let c = &v["cells"][0];
    assert_eq!(c["hunted"], 1);
    assert_eq!(c["rays_per_culled_object"], 2000);
    assert_eq!(c["false_culls"][0]["object"], 1);
    assert_eq!(c["false_culls"][0]["reason"], "ray");
    for k in ["origin", "direction", "hit"] {
        assert_eq!(
            c["false_culls"][0][k].as_array().map(|a| a.len()),
            Some(3),
            "{k}"
        );
    }

    // A good PVS (the boxes behind the wall culled) exits 0.
    write_doc(&doc(&s, vec![SLIT_WALL, SLIT_TARGET], false), &pvs);
    let out = args(true);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let v = read_json();
    assert_eq!(v["hunt"], true);
    assert_eq!(v["hunted_objects"], 1000);
    assert_eq!(v["rays_per_culled_object"], 2);
    assert_eq!(v["false_culls"], 0);
}

fn confirm_opts(rays: u64, confirm_rays: u64) -> CheckOptions {
    CheckOptions {
        confirm_rays,
        ..opts(rays)
    }
}

#[test]
fn confirmation_finds_the_slit_object_the_sample_misses_and_never_a_hidden_one() {
    // The slit scene with a correct PVS that keeps everything: the plain sampling of 2,000
    // rays sees only the wall (see `hunt_finds_a_false_cull_that_plain_sampling_misses`), so
    // PVS/VS is 1,002. The confirmation's 400,000 rays go to the 1,001 objects it did not
    // see, 100 each in the first round; about 1 % of those aimed at the target pass the slit.
    let s = corner_slit_scene();
    let all: Vec<u32> = (0..s.objects.len() as u32).collect();
    let d = doc(&s, all, false);
    let plain = check(&s, &d, &opts(2_000)).unwrap();
    assert_eq!(plain.cells[0].visible, vec![SLIT_WALL]);
    assert!(plain.confirm_rays.is_none() && plain.cells[0].confirmed.is_none());

    let r = check(&s, &d, &confirm_opts(2_000, 400_000)).unwrap();
    let c = &r.cells[0];
    // The sample itself is unchanged.
    assert_eq!(c.visible, plain.cells[0].visible);
    assert_eq!((c.vs, c.pvs), (1, s.objects.len()));
    // The target, and none of the boxes behind the closed wall.
    assert_eq!(
        c.confirmed.as_deref(),
        Some(&[SLIT_TARGET][..]),
        "{}",
        r.table()
    );
    assert_eq!(c.pvs_over_confirmed_vs, Some(s.objects.len() as f64 / 2.0));
    assert_eq!(c.pvs_over_vs, Some(s.objects.len() as f64));
    assert_eq!(
        (r.confirm_rays, r.confirmed_objects),
        (Some(400_000), Some(1))
    );
    assert_eq!(r.pvs_over_confirmed_vs, c.pvs_over_confirmed_vs);
    // Every hidden box got its share of every round: the whole budget but what the integer
    // shares leave (under 1,001 rays a round) and the rays the target's chunk did not need.
    let confirming = r.rays_cast - plain.rays_cast;
    assert!(
        confirming >= 400_000 - 4 * 1_001 - 100,
        "{confirming} confirming rays"
    );
    assert!(r.rays_cast <= plain.rays_cast + 400_000);
    assert_eq!(r.false_culls, 0);
    let table = r.table();
    assert!(
        table.contains("|VS+|") && table.contains("PVS/VS+") && table.contains("501.00"),
        "{table}"
    );
    assert!(table.contains("found 1 of them visible"), "{table}");

    // Not in the JSON unless asked for.
    let v = serde_json::to_value(&plain).unwrap();
    for k in ["confirm_rays", "confirmed_objects", "pvs_over_confirmed_vs"] {
        assert!(v.get(k).is_none(), "{k}");
    }
    assert!(v["cells"][0].get("confirmed").is_none());
    let v = serde_json::to_value(&r).unwrap();
    assert_eq!(v["cells"][0]["confirmed"], serde_json::json!([SLIT_TARGET]));
    assert_eq!(v["confirmed_objects"], 1);
}

#[test]
fn a_confirming_ray_that_meets_a_culled_object_proves_a_false_cull() {
    // The slit scene with a blocker 0.6 wide at z = 8 on the line from the cell's corner
    // through the slit to the target: every line through the slit to the target crosses it,
    // so the blocker is visible (through the slit) and the target is not. A PVS that culls
    // the blocker alone is wrong; the plain sampling of 2,000 rays sees only the wall, and no
    // confirming ray is aimed at the blocker (it is culled), but those aimed at the target
    // through the slit meet it first.
    let mut objects = corner_slit_objects();
    let blocker = objects.len() as u32;
    objects.push((
        "blocker".into(),
        cuboid(vec3(-2.8, -2.8, 7.9), vec3(-2.2, -2.2, 8.1)),
        true,
    ));
    let s = scene(objects);
    let kept: Vec<u32> = (0..s.objects.len() as u32)
        .filter(|&o| o != blocker)
        .collect();
    let d = doc(&s, kept, false);
    let plain = check(&s, &d, &opts(2_000)).unwrap();
    assert_eq!(plain.cells[0].visible, vec![SLIT_WALL]);
    assert_eq!(plain.false_culls, 0);

    let r = check(&s, &d, &confirm_opts(2_000, 400_000)).unwrap();
    assert_eq!(r.false_culls, 1, "{}", r.table());
    assert_eq!(r.cells_with_false_culls, 1);
    let f = &r.cells[0].false_culls[0];
    assert_eq!(
        (f.object, f.name.as_str(), f.reason.as_str()),
        (blocker, "blocker", "ray")
    );
    let (origin, hit) = (f.origin.unwrap(), f.hit.unwrap());
    assert!(strictly_inside(origin, &cell()), "origin {origin:?}");
    assert!(on_object(&s, blocker, hit), "hit {hit:?}");
    // The target stays unconfirmed: the blocker hides it.
    assert_eq!(r.cells[0].confirmed.as_deref(), Some(&[][..]));
    assert!(r.table().contains("blocker"), "{}", r.table());
}

#[test]
fn confirmation_gives_the_same_report_on_one_and_two_threads() {
    // Three cells, each PVS keeping everything: the confirmation's rounds split the budget
    // between every object the sample missed, in several chunks each.
    let s = corner_slit_scene();
    let all: Vec<u32> = (0..s.objects.len() as u32).collect();
    let d = doc_cells(&s, three_cells(all), false);
    same_report_on_one_and_two_threads(&s, &d, &confirm_opts(3_000, 200_003), |r| {
        assert_eq!(r.confirm_rays, Some(200_003));
        assert!(r.cells.iter().all(|c| c.confirmed.is_some()));
    });
}

#[test]
fn cli_confirm_rays_adds_columns_and_refuses_hunt() {
    let s = corner_slit_scene();
    let all: Vec<u32> = (0..s.objects.len() as u32).collect();
    let Some(CliFiles {
        _dir,
        obj,
        pvs,
        json,
    }) = cli_files(&s, &doc(&s, all, false))
    else {
        return;
    };
    let base: Vec<&std::ffi::OsStr> = vec![
        obj.as_os_str(),
        pvs.as_os_str(),
        "--rays".as_ref(),
        "2000".as_ref(),
        "--seed".as_ref(),
        "7".as_ref(),
        "--confirm-rays".as_ref(),
        "400000".as_ref(),
        "--json".as_ref(),
        json.as_os_str(),
    ];
    let out = validate(&base);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{stdout}");
    assert!(stdout.contains("PVS/VS+"), "{stdout}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(v["confirm_rays"], 400000);
    assert_eq!(v["cells"][0]["confirmed"], serde_json::json!([SLIT_TARGET]));

    // With --hunt it is refused (the hunt measures no visible set to add to).
    let mut hunt = base.clone();
    hunt.push("--hunt".as_ref());
    let out = validate(&hunt);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--confirm-rays") && stderr.contains("--hunt"),
        "{stderr}"
    );
}

/// Five closed walls at z = 2, 3, 4, 5 and 6, each with one square hole 0.02 wide centred on
/// the line x = 0.05·z, y = 0 (a sight line through the gaps of successive layers, as under a
/// canopy), and the target, a box 0.1 wide, on that line at z = 9.
fn tunnel_scene() -> Scene {
    let mut objects: Vec<Obj> = (2..=6)
        .map(|z| {
            let (z, c) = (z as f32, 0.05 * z as f32);
            let wall = grid_wall(
                z,
                &[-50.0, c - 0.01, c + 0.01, 50.0],
                &[-50.0, -0.01, 0.01, 50.0],
                |i, j| i == 1 && j == 1,
            );
            (format!("wall{z}"), wall, true)
        })
        .collect();
    objects.push((
        "target".into(),
        cuboid(vec3(0.4, -0.05, 8.95), vec3(0.5, 0.05, 9.05)),
        true,
    ));
    scene(objects)
}

#[test]
fn hunt_searches_near_its_near_misses() {
    // A ray from the cell reaches the target only through all five holes: few fresh pairs
    // do, but a pair whose ray passes some holes gets farther towards its target, and the
    // hunt searches around the chunk's farthest. With 200,000 rays it finds the false cull
    // with each of these six seeds (after 26,000 to 125,000 rays); with every pair fresh it
    // missed with seeds 1 and 2 and took 125,000 rays or more with three of the others.
    let s = tunnel_scene();
    let d = doc(&s, vec![0, 1, 2, 3, 4], false);
    for seed in 0..6 {
        let r = check(
            &s,
            &d,
            &CheckOptions {
                seed,
                ..hunt_opts(200_000)
            },
        )
        .unwrap();
        assert_eq!(r.false_culls, 1, "seed {seed}: {}", r.table());
        let f = &r.cells[0].false_culls[0];
        assert_eq!(f.object, 5);
        let (o, dir) = (f.origin.unwrap(), f.direction.unwrap());
        assert!(strictly_inside(o, &cell()), "origin {o:?}");
        for z in 2..=6 {
            let p = at_z(o, dir, z as f32);
            let c = 0.05 * z as f32;
            assert!(
                (p.x - c).abs() <= 0.0101 && p.y.abs() <= 0.0101,
                "seed {seed}: the witness misses the hole at z = {z}: {p:?}"
            );
        }
        assert!(on_object(&s, 5, f.hit.unwrap()));
    }
}
