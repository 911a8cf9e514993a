//! Tests of `umbrasweep validate` (owned by the validator work): analytic scenes built in
//! memory, hand-written PVS documents, the library API (`sample_cell`, `check`) and the
//! command line (exit codes 0/1/2, `--json`).

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
    PvsDocument {
        format: FORMAT.into(),
        version: VERSION,
        scene: scene.source.display().to_string(),
        settings: PvsSettings {
            alpha_occluders,
            ..Default::default()
        },
        objects: umbrasweep::bake::object_table(scene),
        cells: vec![PvsCell {
            min: cell().min.to_array(),
            max: cell().max.to_array(),
            visible,
            ms: 0.0,
        }],
        summary: None,
    }
}

fn opts(rays: u64) -> CheckOptions {
    CheckOptions {
        rays,
        seed: 7,
        progress: false,
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

#[test]
fn object_behind_a_big_closed_wall_is_never_found() {
    let xs = breaks(-50.0, 50.0, 17);
    // A closed slab (two subdivided faces plus the rim of a box) in front of the target.
    let mut wall = grid_wall(4.0, &xs, &xs, |_, _| false);
    wall.extend(grid_wall(5.0, &xs, &xs, |_, _| false));
    wall.extend(cuboid(vec3(-50.0, -50.0, 4.0), vec3(50.0, 50.0, 5.0)));
    let s = scene(vec![
        ("wall".into(), wall, true),
        (
            "hidden".into(),
            cuboid(vec3(-1.0, -1.0, 10.0), vec3(1.0, 1.0, 12.0)),
            true,
        ),
    ]);
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

#[test]
fn alpha_wall_hides_only_when_alpha_occluders_is_set() {
    let xs = breaks(-50.0, 50.0, 4);
    let s = scene(vec![
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
    ]);
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
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let r = pool.install(|| check(&s, &d, &opts(30_001)).unwrap());
        serde_json::to_string(&r).unwrap()
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_eq!(one, run(2));
    let other_seed = {
        let o = CheckOptions {
            seed: 8,
            ..opts(30_001)
        };
        serde_json::to_string(&check(&s, &d, &o).unwrap()).unwrap()
    };
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

#[test]
fn cli_false_cull_exits_1_and_writes_json() {
    let s = three_box_scene();
    let dir = tmpdir();
    let Some(obj) = obj_scene(dir.path(), &s) else {
        return;
    };
    let pvs = dir.path().join("pvs.json");
    let json = dir.path().join("out.json");
    write_doc(&doc(&s, vec![0, 1], false), &pvs);
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
