//! Tests of `umbrasweep gen` (owned by the generator work): determinism, object counts and
//! names, leaf sizes, closed buildings and boxes (by the scene's closed-mesh detector), cells
//! clear of trunks, buildings and boxes at eye height, OBJ re-import through `scene::load`,
//! tree-model instancing with translucency, and the command line's errors.
#![cfg(feature = "bake")]

use glam::{DVec3, Vec2, Vec3};
use std::path::{Path, PathBuf};
use std::process::Command;
use umbrasweep::generate::{
    BoxfieldOptions, CityOptions, ForestOptions, GenObject, Generated, boxfield, city, forest,
    write_obj,
};
use umbrasweep::geom::Aabb;
use umbrasweep::scene;

// ---------------------------------------------------------------------------------------
// Helpers

fn small_forest() -> ForestOptions {
    ForestOptions {
        trees: 40,
        leaves: 60,
        ..ForestOptions::coarse()
    }
}

fn small_city() -> CityOptions {
    CityOptions {
        shaped_fraction: 0.6,
        ..CityOptions::with_blocks(3, 3)
    }
}

fn small_boxfield() -> BoxfieldOptions {
    BoxfieldOptions {
        boxes: 80,
        extent: 50.0,
        max_cells: None,
        ..Default::default()
    }
}

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_umbrasweep"))
}

fn gen_cli(args: &[&str]) -> std::process::Output {
    bin()
        .arg("gen")
        .args(args)
        .output()
        .expect("run umbrasweep")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    v.sort();
    v
}

/// Separating-axis test of a triangle against a box (Akenine-Möller), in f64.
fn triangle_overlaps_box(t: [Vec3; 3], b: &Aabb) -> bool {
    let c = b.center().as_dvec3();
    let h = (b.size() * 0.5).as_dvec3();
    let v = t.map(|p| p.as_dvec3() - c);
    let e = [v[1] - v[0], v[2] - v[1], v[0] - v[2]];
    let separated = |axis: DVec3| {
        if axis.length_squared() < 1e-24 {
            return false;
        }
        let p = v.map(|x| x.dot(axis));
        let r = h.x * axis.x.abs() + h.y * axis.y.abs() + h.z * axis.z.abs();
        p.iter().cloned().fold(f64::INFINITY, f64::min) > r
            || p.iter().cloned().fold(f64::NEG_INFINITY, f64::max) < -r
    };
    for a in [DVec3::X, DVec3::Y, DVec3::Z] {
        if separated(a) {
            return false;
        }
        for ed in e {
            if separated(a.cross(ed)) {
                return false;
            }
        }
    }
    !separated(e[0].cross(e[1]))
}

/// True when `p` is inside the convex closed mesh `tris` (outward faces).
fn inside_convex(tris: &[[Vec3; 3]], p: Vec3) -> bool {
    tris.iter().all(|t| {
        let [a, b, c] = t.map(|x| x.as_dvec3());
        (b - a).cross(c - a).dot(p.as_dvec3() - a) <= 0.0
    })
}

/// Asserts that no triangle of `obj` touches `cell` and that `obj`'s convex pieces of
/// `piece` triangles (12 for boxes, all for a trunk) do not hold the cell's centre.
fn assert_clear(obj: &GenObject, piece: usize, cell: &Aabb) {
    let tris: Vec<[Vec3; 3]> = obj.triangles().map(|(t, _)| t).collect();
    if !obj.bounds().overlaps(cell) {
        return;
    }
    for t in &tris {
        assert!(
            !triangle_overlaps_box(*t, cell),
            "{} intersects cell {cell:?}",
            obj.name
        );
    }
    for chunk in tris.chunks(piece) {
        assert!(
            !inside_convex(chunk, cell.center()),
            "cell {cell:?} is inside {}",
            obj.name
        );
    }
}

// ---------------------------------------------------------------------------------------
// Determinism

#[test]
fn cli_same_seed_same_bytes_other_seed_other_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str, kind: &str, seed: &str, extra: &[&str]| {
        let obj = dir.path().join(format!("{name}.obj"));
        let cells = dir.path().join(format!("{name}.json"));
        let mut args = vec![
            kind,
            "-o",
            s(&obj),
            "--seed",
            seed,
            "--cells-out",
            s(&cells),
        ];
        args.extend_from_slice(extra);
        let out = gen_cli(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        (std::fs::read(obj).unwrap(), std::fs::read(cells).unwrap())
    };
    let forest_args = ["--trees", "20", "--leaves", "50"];
    let a = run("fa", "forest", "7", &forest_args);
    let b = run("fb", "forest", "7", &forest_args);
    let c = run("fc", "forest", "8", &forest_args);
    assert_eq!(a, b);
    assert_ne!(a.0, c.0);
    let a = run("ca", "city", "3", &["--blocks", "2,3"]);
    let b = run("cb", "city", "3", &["--blocks", "2,3"]);
    let c = run("cc", "city", "4", &["--blocks", "2,3"]);
    assert_eq!(a, b);
    assert_ne!(a.0, c.0);
    let a = run("ba", "boxfield", "3", &["--boxes", "30"]);
    let b = run("bb", "boxfield", "3", &["--boxes", "30"]);
    let c = run("bc", "boxfield", "4", &["--boxes", "30"]);
    assert_eq!(a, b);
    assert_ne!(a.0, c.0);
}

#[test]
fn library_output_does_not_depend_on_thread_count() {
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let o = small_forest();
    let single = one.install(|| forest(&o).unwrap());
    assert_eq!(single, forest(&o).unwrap());
    let dir = tempfile::tempdir().unwrap();
    let (p1, p2) = (dir.path().join("1.obj"), dir.path().join("2.obj"));
    one.install(|| write_obj(&p1, &single)).unwrap();
    write_obj(&p2, &single).unwrap();
    assert_eq!(std::fs::read(p1).unwrap(), std::fs::read(p2).unwrap());
}

// ---------------------------------------------------------------------------------------
// Forest

#[test]
fn forest_objects_counts_and_names() {
    for split in [1, 4] {
        let o = ForestOptions {
            crown_split: split,
            ..small_forest()
        };
        let g = forest(&o).unwrap();
        assert_eq!(g.objects.len(), 40 * (1 + split as usize) + 1);
        let names: std::collections::HashSet<&str> =
            g.objects.iter().map(|x| x.name.as_str()).collect();
        assert_eq!(names.len(), g.objects.len(), "names must be unique");
        assert!(names.contains("ground"));
        for t in 0..40 {
            assert!(names.contains(format!("tree{t}_trunk").as_str()));
            let mut leaves = 0;
            for c in 0..split {
                let crown = g.object(&format!("tree{t}_crown{c}")).unwrap();
                assert!(!crown.faces.is_empty());
                leaves += crown.faces.len();
            }
            assert_eq!(leaves, 60);
        }
        assert_eq!(g.triangle_count(), 2 + 40 * (20 + 60));
    }
}

#[test]
fn leaf_sizes_are_in_the_requested_range() {
    for quads in [false, true] {
        let o = ForestOptions {
            leaf_size: [0.4, 0.6],
            leaf_quads: quads,
            ..small_forest()
        };
        let g = forest(&o).unwrap();
        let (mut lo, mut hi) = (f32::INFINITY, 0.0f32);
        for obj in g.objects.iter().filter(|x| x.name.contains("_crown")) {
            for f in &obj.faces {
                assert_eq!(f[3] != umbrasweep::generate::NO_VERTEX, quads);
                let p: Vec<Vec3> = f
                    .iter()
                    .filter(|&&i| i != u32::MAX)
                    .map(|&i| obj.vertices[i as usize])
                    .collect();
                let d = p
                    .iter()
                    .flat_map(|a| p.iter().map(move |b| a.distance(*b)))
                    .fold(0.0, f32::max);
                lo = lo.min(d);
                hi = hi.max(d);
            }
        }
        assert!(
            lo >= 0.4 - 1e-3 && hi <= 0.6 + 1e-3,
            "leaf diameters {lo}..{hi}"
        );
        assert!(lo < 0.45 && hi > 0.55, "the range is used: {lo}..{hi}");
    }
}

#[test]
fn bushy_forest_leaves_reach_eye_level_but_trunks_stay_off_the_path() {
    for seed in [1, 2, 3] {
        let o = ForestOptions {
            seed,
            crown_base: 0.3,
            ..small_forest()
        };
        let g = forest(&o).unwrap();
        assert!(g.cells.len() >= 10);
        let lowest_leaf = g
            .objects
            .iter()
            .filter(|x| x.name.contains("_crown"))
            .flat_map(|x| x.vertices.iter().map(|v| v.y))
            .fold(f32::INFINITY, f32::min);
        assert!(
            (0.3 - 1e-3..1.0).contains(&lowest_leaf),
            "lowest leaf at {lowest_leaf}"
        );
        for c in &g.cells {
            assert!(
                (1.1..=1.3).contains(&c.min.y) && (2.1..=2.3).contains(&c.max.y),
                "{c:?}"
            );
            assert!((c.size() - Vec3::ONE).abs().max_element() < 1e-4, "{c:?}");
        }
        for trunk in g.objects.iter().filter(|x| x.name.ends_with("_trunk")) {
            let b = trunk.bounds();
            for c in &g.cells {
                assert_clear(trunk, usize::MAX, c);
                // ~1 unit of clearance around every cell.
                let axis = Vec2::new(b.center().x, b.center().z);
                let near = axis.clamp(Vec2::new(c.min.x, c.min.z), Vec2::new(c.max.x, c.max.z));
                assert!(near.distance(axis) - 0.5 * b.size().x.max(b.size().z) >= 0.99);
            }
        }
    }
}

/// Fraction of each tree's leaves whose centre lies in the lowest quarter of that tree's
/// leaf-centre heights, over all trees.
fn low_leaf_fraction(g: &Generated, trees: usize) -> f64 {
    let (mut low, mut all) = (0usize, 0usize);
    for t in 0..trees {
        let mut ys: Vec<f32> = Vec::new();
        for obj in g
            .objects
            .iter()
            .filter(|x| x.name.starts_with(&format!("tree{t}_crown")))
        {
            ys.extend(
                obj.triangles()
                    .map(|(p, _)| (p[0].y + p[1].y + p[2].y) / 3.0),
            );
        }
        let lo = ys.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = ys.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        low += ys.iter().filter(|&&y| y < lo + 0.25 * (hi - lo)).count();
        all += ys.len();
    }
    low as f64 / all as f64
}

#[test]
fn cylinder_crowns_keep_their_width_down_to_the_base_and_ellipsoids_do_not() {
    use umbrasweep::generate::CrownShape;
    let o = |shape| ForestOptions {
        trees: 10,
        leaves: 1000,
        crown_shape: shape,
        ..small_forest()
    };
    assert_eq!(ForestOptions::coarse().crown_shape, CrownShape::Cylinder);
    // Uniform in a cylinder, a quarter of the leaves are in the lowest quarter of its height;
    // in an ellipsoid, 5/32 (the cap below -1/2 of a unit ball). Both a little less here: the
    // leaves' centroids scatter a little beyond the range of their centres.
    let cylinder = low_leaf_fraction(&forest(&o(CrownShape::Cylinder)).unwrap(), 10);
    let ellipsoid = low_leaf_fraction(&forest(&o(CrownShape::Ellipsoid)).unwrap(), 10);
    assert!((0.19..0.27).contains(&cylinder), "cylinder {cylinder}");
    assert!((0.10..0.17).contains(&ellipsoid), "ellipsoid {ellipsoid}");
    assert!(cylinder > 1.3 * ellipsoid, "{cylinder} vs {ellipsoid}");
}

#[test]
fn coarse_and_fine_recipes_match_their_description() {
    let c = ForestOptions::coarse();
    assert_eq!((c.trees, c.leaves, c.crown_split), (1500, 1000, 4));
    assert_eq!(
        (c.leaf_size, c.crown_base, c.area_per_tree),
        ([1.2, 1.8], 0.3, Some(17.0))
    );
    let f = ForestOptions::fine();
    assert_eq!(f.leaf_size, [0.4, 0.6]);
    assert_eq!(
        ForestOptions {
            leaf_size: c.leaf_size,
            ..f
        },
        c
    );
    let p = ForestOptions::paper();
    assert_eq!((p.trees, p.leaves), (7750, 1000));
    // The forest's side follows the area per tree, plus the trunk-free lane of the path.
    let g = forest(&ForestOptions {
        leaves: 4,
        ..ForestOptions::coarse()
    })
    .unwrap();
    let side = g.object("ground").unwrap().bounds().size().x - 2.0 * c.crown_radius;
    let slope = std::f32::consts::TAU * c.path_curve;
    let lane = (c.path_width + 2.0 * c.trunk_radius) * (1.0 + slope * slope).sqrt();
    assert!(
        (side - (1500.0f32 * 17.0).sqrt() - lane).abs() < 0.01,
        "side {side}"
    );
    let wooded = (side - lane) * side / 1500.0;
    assert!((16.0..18.0).contains(&wooded), "{wooded} m² per tree");
    assert_eq!(g.objects.len(), 1 + 1500 * 5);
}

#[test]
fn cells_that_do_not_fit_the_path_are_refused() {
    let o = ForestOptions {
        cell_size: Vec3::splat(3.0),
        ..small_forest()
    };
    let e = forest(&o).unwrap_err().to_string();
    assert!(e.contains("--path-width"), "{e}");
    let o = ForestOptions {
        path_width: 8.0,
        ..o
    };
    assert!(forest(&o).is_ok());
}

// ---------------------------------------------------------------------------------------
// City and boxfield

#[test]
fn city_buildings_are_closed_per_the_detector() {
    for seed in 1..4 {
        let g = city(&CityOptions {
            seed,
            ..small_city()
        })
        .unwrap();
        assert_eq!(g.objects.len(), 1 + 3 * 3 * 4);
        assert_eq!(g.objects[0].name, "ground");
        let scene = g.to_scene("city");
        for o in &scene.objects[1..] {
            assert!(o.name.starts_with("building_"));
            assert!(o.closed, "{} is not closed", o.name);
        }
        assert!(!scene.objects[0].closed);
        // Building sizes and heights as asked (9–12 wide before rotation, ≤ 36 tall).
        for b in &g.objects[1..] {
            let bb = b.bounds();
            assert!(bb.min.y == 0.0 && bb.max.y <= 36.0 + 1e-3);
            assert!(bb.size().x >= 9.0 * 0.7 - 1e-3 && bb.size().x <= 12.0 * 1.37);
        }
    }
    assert!(city(&CityOptions::default()).unwrap().objects.len() == 1 + 12 * 12 * 4);
}

#[test]
fn city_cells_line_the_streets_at_eye_height_outside_buildings() {
    let g = city(&small_city()).unwrap();
    assert!(g.cells.len() > 50);
    for c in &g.cells {
        assert_eq!((c.min.y, c.max.y), (1.0, 3.0));
        assert!(
            (c.size().x - 3.0).abs() < 1e-4 && (c.size().z - 3.0).abs() < 1e-4,
            "{c:?}"
        );
        for b in &g.objects[1..] {
            assert_clear(b, 12, c);
        }
    }
    // Junctions are covered once: no two cells overlap in volume.
    for (i, a) in g.cells.iter().enumerate() {
        for b in &g.cells[i + 1..] {
            let inter = a.max.min(b.max) - a.min.max(b.min);
            assert!(inter.min_element() <= 1e-4, "{a:?} overlaps {b:?}");
        }
    }
    let limited = city(&CityOptions {
        max_cells: Some(20),
        ..small_city()
    })
    .unwrap();
    assert_eq!(limited.cells.len(), 20);
}

#[test]
fn boxfield_boxes_are_closed_and_cells_free() {
    let g = boxfield(&small_boxfield()).unwrap();
    assert_eq!(g.objects.len(), 80);
    let scene = g.to_scene("boxes");
    for (i, o) in scene.objects.iter().enumerate() {
        assert_eq!(o.name, format!("box{i}"));
        assert!(o.closed, "{} is not closed", o.name);
        let size = o.bounds.size();
        assert!(size.max_element() <= 10.0 * 3f32.sqrt() + 1e-3);
    }
    assert!(g.cells.len() > 100);
    for c in &g.cells {
        for b in &g.objects {
            assert_clear(b, 12, c);
        }
    }
    assert_eq!(
        boxfield(&BoxfieldOptions::default()).unwrap().cells.len(),
        100
    );
}

// ---------------------------------------------------------------------------------------
// OBJ output and re-import

fn assert_reimports(g: &Generated, path: &Path) {
    write_obj(path, g).unwrap();
    let loaded = scene::load(path).unwrap();
    let expected = g.to_scene(path);
    assert_eq!(loaded.objects.len(), expected.objects.len());
    for (a, b) in loaded.objects.iter().zip(&expected.objects) {
        assert_eq!(a.name, b.name);
        assert_eq!(a.triangles, b.triangles, "{}", a.name);
        assert_eq!(a.closed, b.closed, "{}", a.name);
        assert_eq!(a.bounds, b.bounds, "{}", a.name);
    }
    assert_eq!(loaded.opaque, expected.opaque);
    for t in 0..loaded.triangles.len() {
        assert_eq!(loaded.triangle(t), expected.triangle(t), "triangle {t}");
    }
}

#[test]
fn obj_output_reimports_with_the_same_objects() {
    let dir = tempfile::tempdir().unwrap();
    assert_reimports(&forest(&small_forest()).unwrap(), &dir.path().join("f.obj"));
    let quads = ForestOptions {
        leaf_quads: true,
        crown_split: 3,
        ..small_forest()
    };
    assert_reimports(&forest(&quads).unwrap(), &dir.path().join("q.obj"));
    assert_reimports(&city(&small_city()).unwrap(), &dir.path().join("c.obj"));
    assert_reimports(
        &boxfield(&small_boxfield()).unwrap(),
        &dir.path().join("b.obj"),
    );
    // No MTL for fully opaque scenes.
    assert_eq!(files_in(dir.path()).len(), 4);
}

#[test]
fn tree_model_instances_keep_translucency_through_the_mtl() {
    let dir = tempfile::tempdir().unwrap();
    // A tiny tree: an opaque closed trunk box and two translucent leaf cards.
    std::fs::write(
        dir.path().join("model.mtl"),
        "newmtl bark\nd 1\nnewmtl leaf\nmap_d leaf.png\n",
    )
    .unwrap();
    let mut text = String::from("mtllib model.mtl\no tree\nusemtl bark\n");
    for i in 0..8 {
        let (x, y, z) = (
            (i & 1) as f32 * 0.2 - 0.1,
            ((i >> 1) & 1) as f32 * 2.0,
            ((i >> 2) & 1) as f32 * 0.2 - 0.1,
        );
        text += &format!("v {x} {y} {z}\n");
    }
    text += "f 1 5 7 3\nf 2 4 8 6\nf 1 2 6 5\nf 3 7 8 4\nf 1 3 4 2\nf 5 6 8 7\n";
    text += "usemtl leaf\nv -1 2 0\nv 1 2 0\nv 0 3 0.5\nv 0 2.5 -1\nf 9 10 11\nf 9 12 10\n";
    let model = dir.path().join("model.obj");
    std::fs::write(&model, text).unwrap();

    let out = dir.path().join("out").join("forest.obj");
    std::fs::create_dir(out.parent().unwrap()).unwrap();
    let cells = dir.path().join("out").join("cells.json");
    let r = gen_cli(&[
        "forest",
        "--tree-model",
        s(&model),
        "--trees",
        "9",
        "-o",
        s(&out),
        "--cells-out",
        s(&cells),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let mtl = std::fs::read_to_string(out.with_extension("mtl")).unwrap();
    assert!(mtl.contains("d 0.5"));
    let s = scene::load(&out).unwrap();
    assert_eq!(s.objects.len(), 10);
    assert_eq!(s.objects[0].name, "ground");
    for (i, o) in s.objects[1..].iter().enumerate() {
        assert_eq!(o.name, format!("tree{i}"));
        let ts = o.triangles.start as usize..o.triangles.end as usize;
        assert_eq!(ts.len(), 14);
        assert_eq!(s.opaque[ts].iter().filter(|&&x| !x).count(), 2);
        // Height 2 (trunk) scaled by 1 ± 0.2.
        assert!(
            (2.4..=3.6 + 1e-3).contains(&o.bounds.max.y),
            "{}",
            o.bounds.max.y
        );
    }
    let cells = umbrasweep::cells::load_json(&cells).unwrap();
    assert!(!cells.is_empty());
    for c in &cells {
        for t in 0..s.triangles.len() {
            if s.opaque[t] && s.triangle_object(t as u32) != 0 {
                assert!(!triangle_overlaps_box(s.triangle(t), c));
            }
        }
    }
    // Procedural-tree flags are refused with a model.
    let r = gen_cli(&[
        "forest",
        "--tree-model",
        s_(&model),
        "--leaves",
        "5",
        "-o",
        s_(&out),
    ]);
    assert_eq!(r.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&r.stderr).contains("--leaves"));
}

fn s_(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn real_tree_model_from_shared_scenes() {
    let model =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes/foliage/tree_poinciana.glb");
    if !model.is_file() {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but {} is missing",
            model.display()
        );
        eprintln!("skipping: {} not found", model.display());
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("p.obj");
    let r = gen_cli(&[
        "forest",
        "--tree-model",
        s_(&model),
        "--trees",
        "3",
        "--seed",
        "2",
        "-o",
        s_(&out),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let original = scene::load(&model).unwrap();
    let s = scene::load(&out).unwrap();
    assert_eq!(s.objects.len(), 4);
    let translucent = original.opaque.iter().filter(|&&x| !x).count();
    assert!(translucent > 0);
    assert_eq!(s.opaque.iter().filter(|&&x| !x).count(), 3 * translucent);
    assert_eq!(s.triangles.len(), 2 + 3 * original.triangles.len());
}

// ---------------------------------------------------------------------------------------
// Command line

#[test]
fn cli_errors_exit_2_and_leave_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("x.obj");
    let cells = dir.path().join("x.json");

    let r = gen_cli(&["volcano", "-o", s(&obj)]);
    assert_eq!(r.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&r.stderr).contains("volcano"));

    // Output folder missing; output under a plain file; output is a folder.
    let blocker = dir.path().join("file");
    std::fs::write(&blocker, "x").unwrap();
    for bad in [dir.path().join("missing/x.obj"), blocker.join("x.obj")] {
        let r = gen_cli(&[
            "city",
            "--blocks",
            "2",
            "-o",
            s(&bad),
            "--cells-out",
            s(&cells),
        ]);
        assert_eq!(
            r.status.code(),
            Some(2),
            "{}",
            String::from_utf8_lossy(&r.stderr)
        );
        assert!(String::from_utf8_lossy(&r.stderr).contains(s(&bad)));
    }
    let folder = dir.path().join("folder.obj");
    std::fs::create_dir(&folder).unwrap();
    let r = gen_cli(&["boxfield", "--boxes", "3", "-o", s(&folder)]);
    assert_eq!(r.status.code(), Some(2));

    // Unwritable cells file: no OBJ is left either.
    let r = gen_cli(&[
        "forest",
        "--trees",
        "5",
        "-o",
        s(&obj),
        "--cells-out",
        s(&dir.path().join("no/c.json")),
    ]);
    assert_eq!(r.status.code(), Some(2));

    // Not an OBJ name, bad values.
    let r = gen_cli(&["city", "-o", s(&dir.path().join("x.ply"))]);
    assert_eq!(r.status.code(), Some(2));
    let r = gen_cli(&[
        "forest",
        "--trees",
        "5",
        "--leaf-size",
        "2,1",
        "-o",
        s(&obj),
    ]);
    assert_eq!(r.status.code(), Some(2));
    let r = gen_cli(&[
        "city",
        "--cell-size",
        "12",
        "-o",
        s(&obj),
        "--cells-out",
        s(&cells),
    ]);
    assert_eq!(r.status.code(), Some(2));
    let r = gen_cli(&["city", "--trees", "5", "-o", s(&obj)]);
    assert_eq!(r.status.code(), Some(2));

    assert_eq!(
        files_in(dir.path()),
        vec![blocker, folder],
        "a failed run left a file"
    );
}

#[test]
fn cli_writes_what_the_library_makes() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("c.obj");
    let cells = dir.path().join("c.json");
    let r = gen_cli(&[
        "city",
        "--blocks",
        "2,3",
        "--seed",
        "9",
        "--cells",
        "7",
        "--cell-size",
        "2,2.5,2",
        "-o",
        s(&obj),
        "--cells-out",
        s(&cells),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let mut g = city(&CityOptions {
        seed: 9,
        max_cells: Some(7),
        cell_size: Vec3::new(2.0, 2.5, 2.0),
        ..CityOptions::with_blocks(2, 3)
    })
    .unwrap();
    let loaded = umbrasweep::cells::load_json(&cells).unwrap();
    assert_eq!(loaded, g.cells);
    assert!(loaded.iter().all(|c| c.min.y == 1.0 && c.max.y == 3.5));
    let lib = dir.path().join("lib.obj");
    g.comment = "x".into();
    write_obj(&lib, &g).unwrap();
    // Same geometry, header aside.
    let body = |p: &Path| {
        let t = std::fs::read_to_string(p).unwrap();
        t.lines()
            .filter(|l| !l.starts_with('#'))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(body(&obj), body(&lib));
}

// ---------------------------------------------------------------------------------------
// Shipped data and recipes

/// The commands of data/README.md's `sh` block, joined over `\` continuations.
fn readme_commands() -> Vec<Vec<String>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("data/README.md")).unwrap();
    let block = text
        .split("```sh")
        .nth(1)
        .unwrap()
        .split("```")
        .next()
        .unwrap();
    block
        .replace("\\\n", " ")
        .lines()
        .map(|l| l.split_whitespace().map(String::from).collect::<Vec<_>>())
        .filter(|w| !w.is_empty())
        .collect()
}

#[test]
fn data_files_are_remade_byte_for_byte_by_the_readme_commands() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let commands = readme_commands();
    assert_eq!(commands.len(), 2);
    let mut made = Vec::new();
    for words in commands {
        assert_eq!(&words[..2], ["umbrasweep", "gen"]);
        let args: Vec<String> = words[2..]
            .iter()
            .map(|w| match w.strip_prefix("data/") {
                Some(name) => {
                    made.push(name.to_string());
                    s(&dir.path().join(name)).to_string()
                }
                None => w.clone(),
            })
            .collect();
        let out = bin().arg("gen").args(&args).output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    made.sort();
    assert_eq!(
        made,
        [
            "demo_city.obj",
            "demo_city_cells.json",
            "demo_forest.obj",
            "demo_forest_cells.json"
        ]
    );
    for name in &made {
        let shipped = std::fs::read(root.join("data").join(name)).unwrap();
        let fresh = std::fs::read(dir.path().join(name)).unwrap();
        assert!(
            shipped == fresh,
            "data/{name} differs from what data/README.md's command makes now"
        );
        assert!(shipped.len() < 2_000_000, "data/{name} is too large");
    }
    // The shipped scenes load, and their cells are as described.
    let city = scene::load(&root.join("data/demo_city.obj")).unwrap();
    assert_eq!(city.objects.len(), 65);
    assert!(city.objects[1..].iter().all(|o| o.closed));
    let cells = umbrasweep::cells::load_json(&root.join("data/demo_city_cells.json")).unwrap();
    assert_eq!(cells.len(), 24);
    let forest = scene::load(&root.join("data/demo_forest.obj")).unwrap();
    assert_eq!(forest.objects.len(), 1 + 60 * 5);
    assert!(
        forest
            .objects
            .iter()
            .filter(|o| o.name.ends_with("_trunk"))
            .all(|o| o.closed)
    );
    let cells = umbrasweep::cells::load_json(&root.join("data/demo_forest_cells.json")).unwrap();
    assert_eq!(cells.len(), 10);
}

#[test]
fn documented_recipes_equal_the_presets() {
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str, args: &[&str]| {
        let obj = dir.path().join(format!("{name}.obj"));
        let mut all = vec!["forest", "-o", s(&obj), "--trees", "30", "--leaves", "40"];
        all.extend_from_slice(args);
        let out = gen_cli(&all);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        std::fs::read(obj).unwrap()
    };
    let recipe = [
        "--leaf-size",
        "1.5",
        "--crown-base",
        "0.3",
        "--area-per-tree",
        "17",
        "--crown-split",
        "4",
    ];
    assert_eq!(run("c1", &recipe), run("c2", &["--preset", "coarse"]));
    let fine = [
        "--leaf-size",
        "0.5",
        "--crown-base",
        "0.3",
        "--area-per-tree",
        "17",
        "--crown-split",
        "4",
    ];
    assert_eq!(run("f1", &fine), run("f2", &["--preset", "fine"]));
    assert_ne!(run("c3", &recipe), run("f3", &fine));
}
