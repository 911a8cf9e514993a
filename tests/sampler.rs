//! The shrunk-occluder sampling culler on scenes built for it: a layer of small leaves that
//! hides a target only together (fusion), the same layer with a hole (the target must stay),
//! an object in the open (must stay), and the culler's accounting in the PVS document. Every
//! culled object is also checked by brute force: random segments from the cell to the
//! object's surface must all be blocked.

use glam::{DVec3, Vec3};
use std::fmt::Write as _;
use umbrasweep::backend::cpu::CpuBackend;
use umbrasweep::bake::{
    self, BakeSettings, CullState, Culler, CullerWork, Prepared, SamplingCuller, SweepChoice,
};
use umbrasweep::geom::Aabb;
use umbrasweep::settings::SamplingSettings;
use umbrasweep::validate::SceneRays;

/// A small deterministic generator (splitmix64).
struct Rng(u64);
impl Rng {
    fn f(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A new OBJ text holding only the box `walled` (its vertex count with it).
fn walled_target(min: DVec3, max: DVec3) -> (String, usize) {
    let (mut obj, mut nv) = (String::new(), 0);
    cube(&mut obj, &mut nv, "walled", min, max);
    (obj, nv)
}

/// Appends object `wall`: the square `[-20, 20]²` of a plane, its point `(u, v)` at `at(u, v)`.
fn wall(obj: &mut String, nv: &mut usize, at: impl Fn(f64, f64) -> DVec3) {
    writeln!(obj, "o wall").unwrap();
    for (u, v) in [(-20.0, -20.0), (20.0, -20.0), (20.0, 20.0), (-20.0, 20.0)] {
        let p = at(u, v);
        writeln!(obj, "v {} {} {}", p.x, p.y, p.z).unwrap();
    }
    writeln!(obj, "f {} {} {} {}", *nv + 1, *nv + 2, *nv + 3, *nv + 4).unwrap();
    *nv += 4;
}

fn cube(obj: &mut String, nv: &mut usize, name: &str, min: DVec3, max: DVec3) {
    writeln!(obj, "o {name}").unwrap();
    for t in umbrasweep::geom::box_triangles(min.as_vec3(), max.as_vec3()) {
        for p in t {
            writeln!(obj, "v {} {} {}", p.x, p.y, p.z).unwrap();
        }
        writeln!(obj, "f {} {} {}", *nv + 1, *nv + 2, *nv + 3).unwrap();
        *nv += 3;
    }
}

/// The cell `[-0.5, 0.5]³`, a layer of 3,000 leaves (~1 across) at z ∈ [3, 3.4] over
/// x, y ∈ [-3, 3] (with a hole of radius `hole` around the z axis when given), a target cube
/// behind it, a cube in the open beside the cell.
fn scene(hole: Option<f64>) -> (umbrasweep::Scene, Aabb) {
    let (obj, _) = scene_obj(hole);
    let scene = load_obj(&format!("leaves-{}", hole.is_some()), &obj);
    (scene, Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5)))
}

/// The OBJ text of [`scene`] and its vertex count.
fn scene_obj(hole: Option<f64>) -> (String, usize) {
    let mut obj = String::new();
    let mut nv = 0;
    cube(
        &mut obj,
        &mut nv,
        "target",
        DVec3::new(-0.5, -0.5, 8.0),
        DVec3::new(0.5, 0.5, 9.0),
    );
    cube(
        &mut obj,
        &mut nv,
        "open",
        DVec3::new(8.0, -0.5, -0.5),
        DVec3::new(9.0, 0.5, 0.5),
    );
    leaf_layer(&mut obj, &mut nv, hole);
    (obj, nv)
}

/// The object `leaves`: 3,000 leaves (~1 across) at z ∈ [3, 3.4] over x, y ∈ [-3, 3], with a
/// hole of radius `hole` around the z axis when given.
fn leaf_layer(obj: &mut String, nv: &mut usize, hole: Option<f64>) {
    writeln!(obj, "o leaves").unwrap();
    let mut rng = Rng(3);
    let mut n = 0;
    while n < 3000 {
        let c = DVec3::new(
            rng.f() * 6.0 - 3.0,
            rng.f() * 6.0 - 3.0,
            3.0 + rng.f() * 0.4,
        );
        if hole.is_some_and(|r| c.x.hypot(c.y) < r + 0.6) {
            continue;
        }
        let tilt = DVec3::new(rng.f() - 0.5, rng.f() - 0.5, 0.0) * 0.6;
        for k in 0..3 {
            let a = std::f64::consts::TAU * (k as f64 / 3.0 + rng.f() * 0.1);
            let p = c + DVec3::new(a.cos(), a.sin(), 0.0) * 0.55 + tilt * a.sin();
            writeln!(obj, "v {} {} {}", p.x, p.y, p.z).unwrap();
        }
        writeln!(obj, "f {} {} {}", *nv + 1, *nv + 2, *nv + 3).unwrap();
        *nv += 3;
        n += 1;
    }
}

/// The scene of the OBJ text `obj`, through a file of its own (tests run in parallel threads
/// of one process) removed once it is read.
fn load_obj(name: &str, obj: &str) -> umbrasweep::Scene {
    let file = tempfile::Builder::new()
        .prefix(&format!("umbrasweep-sampler-{name}-"))
        .suffix(".obj")
        .tempfile()
        .unwrap();
    std::fs::write(file.path(), obj).unwrap();
    umbrasweep::scene::load(file.path()).unwrap()
}

fn settings() -> BakeSettings {
    BakeSettings {
        sampling: SweepChoice::On,
        sampling_settings: SamplingSettings {
            eps: Some(0.1),
            levels: 1,
            resolution: Some(64),
            rays: 0,
            ..SamplingSettings::default()
        },
        ..BakeSettings::default()
    }
}

/// Three levels above the finest ε 0.05, each level's probe asked to prove `probe` of its
/// tests and `probe_cull` of its objects for the cell (at `resolution`, or 64 px), without the
/// pilot's estimate of what a level saves (`--sampling-probe-pay 0`), which the tests of
/// those two rules leave out.
fn probed(resolution: Option<u32>, probe: f64, probe_cull: f64) -> BakeSettings {
    let mut s = settings();
    s.sampling_settings.levels = 3;
    s.sampling_settings.eps = Some(0.05);
    s.sampling_settings.resolution = resolution.or(s.sampling_settings.resolution);
    s.sampling_settings.probe = probe;
    s.sampling_settings.probe_cull = probe_cull;
    s.sampling_settings.probe_pay = 0.0;
    s
}

/// Runs the sampler alone on the cell (nothing hidden before it): what it hid, its work.
fn run_sampler(
    scene: &umbrasweep::Scene,
    cell: &Aabb,
    settings: &BakeSettings,
) -> (Vec<bool>, CullerWork) {
    let prepared = Prepared::new(scene, settings, &[*cell]).unwrap();
    let mut state = CullState {
        hidden: vec![false; scene.objects.len()],
        known_visible: None,
    };
    let work = SamplingCuller::default()
        .cull(
            &prepared,
            cell,
            &CpuBackend::new(),
            &mut state,
            &mut umbrasweep::bake::NoPlanes,
        )
        .unwrap();
    (state.hidden, work)
}

/// The sampler alone with [`settings`]: what it hid.
fn sampler_hides(scene: &umbrasweep::Scene, cell: &Aabb) -> Vec<bool> {
    let (hidden, work) = run_sampler(scene, cell, &settings());
    assert!(work.points > 0, "the sampler rendered no point");
    if hidden[0] {
        // Balls no larger than the coarsest level (2 × the finest ε) hid it; with
        // depth-bounded shrinks the coarse level may already suffice.
        assert!(work.finest_eps.is_some_and(|e| e <= 0.2 * (1.0 + 1e-6)));
    }
    hidden
}

/// Every segment from random points of the cell to random points of the object's triangles
/// is blocked by another object.
fn brute_force_hidden(scene: &umbrasweep::Scene, cell: &Aabb, object: u32) {
    let rays = SceneRays::new(scene);
    let mut rng = Rng(11);
    let o = &scene.objects[object as usize];
    for _ in 0..20_000 {
        let from = cell.min.as_dvec3()
            + (cell.max - cell.min).as_dvec3() * DVec3::new(rng.f(), rng.f(), rng.f());
        let t = o.triangles.start as usize
            + (rng.f() * o.triangles.len() as f64) as usize % o.triangles.len();
        let [a, b, c] = scene.triangle(t).map(|p| p.as_dvec3());
        let (u, v) = (rng.f(), rng.f());
        let (u, v) = if u + v > 1.0 {
            (1.0 - u, 1.0 - v)
        } else {
            (u, v)
        };
        let to = a + (b - a) * u + (c - a) * v;
        let hits = rays.trace(from.as_vec3(), (to - from).as_vec3(), false);
        let first = hits.first().expect("the ray reaches the object at least");
        assert_ne!(
            first.object, object,
            "the segment {from:?} → {to:?} sees object {object}: a false cull"
        );
    }
}

#[test]
fn a_layer_of_small_leaves_hides_the_target_only_together() {
    let (scene, cell) = scene(None);
    let hidden = sampler_hides(&scene, &cell);
    assert!(hidden[0], "the fused leaves must hide the target");
    assert!(!hidden[1], "the cube in the open is visible");
    assert!(!hidden[2], "the leaves are visible");
    brute_force_hidden(&scene, &cell, 0);
}

#[test]
fn a_hole_in_the_layer_keeps_the_target() {
    let (scene, cell) = scene(Some(0.3));
    let hidden = sampler_hides(&scene, &cell);
    assert!(!hidden[0], "the target is seen through the hole");
    assert!(!hidden[1]);
}

#[test]
fn the_document_records_the_sampler_per_cell_and_in_the_summary() {
    let (scene, cell) = scene(None);
    let s = BakeSettings {
        sweep: SweepChoice::Off,
        rsf: SweepChoice::Off,
        ..settings()
    };
    let r = bake::bake(&scene, &[cell], &s, &CpuBackend::new(), None).unwrap();
    assert_eq!(r.cullers, vec!["extended_projections", "shrunk_sampling"]);
    assert!(r.sampling);
    let doc = bake::to_document(&scene, &[cell], &r, &s);
    let json = serde_json::to_value(&doc).unwrap();
    assert_eq!(json["settings"]["sampling"], serde_json::json!(true));
    let cell_cullers = json["cells"][0]["cullers"].as_array().unwrap();
    assert_eq!(cell_cullers[1]["name"], "shrunk_sampling");
    assert!(cell_cullers[1]["points"].as_u64().unwrap() > 0);
    assert!(cell_cullers[1]["finest_eps"].as_f64().unwrap() > 0.0);
    // Its cost curve: the last level holds all its points and what it hid.
    let levels = cell_cullers[1]["levels"].as_array().unwrap();
    let last = levels.last().unwrap();
    assert_eq!(last["points"], cell_cullers[1]["points"]);
    assert_eq!(last["hidden"], cell_cullers[1]["hidden"]);
    assert!(last["seconds"].as_f64().unwrap() > 0.0);
    assert_eq!(
        json["summary"]["cullers"][1]["levels"]
            .as_array()
            .unwrap()
            .len(),
        levels.len()
    );
    let summary = &json["summary"]["cullers"][1];
    assert_eq!(summary["name"], "shrunk_sampling");
    assert!(summary["points"].as_f64().unwrap() > 0.0);
    // The target is culled (by one culler or the other), the open cube kept.
    assert!(!doc.cells[0].visible.contains(&0));
    assert!(doc.cells[0].visible.contains(&1));
    // Without the sampler the document has no per-cell accounts.
    let off = BakeSettings {
        sampling: SweepChoice::Off,
        ..s
    };
    let r = bake::bake(&scene, &[cell], &off, &CpuBackend::new(), None).unwrap();
    let json = serde_json::to_value(bake::to_document(&scene, &[cell], &r, &off)).unwrap();
    assert!(json["cells"][0].get("cullers").is_none());
    assert_eq!(json["settings"]["sampling"], serde_json::json!(false));
}

#[test]
fn the_default_leaves_the_sampler_off_and_says_why() {
    let (scene, cell) = scene(None);
    let p = Prepared::new(&scene, &BakeSettings::default(), &[cell]).unwrap();
    assert!(!p.sampling);
    assert!(
        p.sampling_reason.contains("--sampling"),
        "{}",
        p.sampling_reason
    );
    let p = Prepared::new(&scene, &settings(), &[cell]).unwrap();
    assert!(
        p.sampling && p.sampling_reason.contains("0.1"),
        "{}",
        p.sampling_reason
    );
    // The unit cell refined to ε 0.1 everywhere: squares of side 1/8 (half diagonal 0.088),
    // 64 per face.
    assert!(
        p.sampling_reason.contains("up to 384 points per cell"),
        "{}",
        p.sampling_reason
    );
}

/// A wall quad at x = −2 hides a small target behind it from the coarsest balls already; a
/// layer of leaves at z ∈ [3, 3.4] hides a second target only with fine balls. With a budget of
/// points that covers the coarsest level of every face and little more, the wall's target must
/// be culled (refinement is breadth-first: a budget that runs out leaves the finest levels
/// unsampled, never a whole face) and the leaves' target stays visible; both checked by brute
/// force where culled.
#[test]
fn a_budget_that_runs_out_keeps_what_the_coarse_levels_proved() {
    let (leafy, cell) = scene(None);
    // The leaves scene's OBJ plus the wall and the target behind it.
    let (mut obj, mut nv) = walled_target(DVec3::new(-5.0, -0.4, -0.4), DVec3::new(-4.0, 0.4, 0.4));
    wall(&mut obj, &mut nv, |u, v| DVec3::new(-2.0, u, v));
    for o in &leafy.objects {
        writeln!(obj, "o {}", o.name).unwrap();
        for t in o.triangles.clone() {
            for p in leafy.triangle(t as usize) {
                writeln!(obj, "v {} {} {}", p.x, p.y, p.z).unwrap();
            }
            writeln!(obj, "f {} {} {}", nv + 1, nv + 2, nv + 3).unwrap();
            nv += 3;
        }
    }
    let path = std::env::temp_dir().join(format!("umbrasweep-budget-{}.obj", std::process::id()));
    std::fs::write(&path, obj).unwrap();
    let scene = umbrasweep::scene::load(&path).unwrap();
    let _ = std::fs::remove_file(&path);
    let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
    let id = |n: &str| names.iter().position(|&m| m == n).unwrap();
    let run = |budget_points: u64| {
        let s = BakeSettings {
            sampling: SweepChoice::On,
            sampling_settings: SamplingSettings {
                eps: Some(0.05),
                levels: 3,
                resolution: Some(64),
                rays: 0,
                budget_points,
                ..SamplingSettings::default()
            },
            ..BakeSettings::default()
        };
        let (hidden, work) = run_sampler(&scene, &cell, &s);
        // The cost curve: one entry per level, coarsest first, each counting what was
        // proved by then; the last is what the sampler did.
        let l = &work.levels;
        assert!(!l.is_empty());
        for w in l.windows(2) {
            assert!(
                w[1].points >= w[0].points && w[1].hidden >= w[0].hidden,
                "{l:?}"
            );
            assert!(
                (w[1].eps - 0.5 * w[0].eps).abs() < 1e-9,
                "halved each level: {l:?}"
            );
        }
        let last = l.last().unwrap();
        assert_eq!(last.points, work.points);
        assert_eq!(last.hidden as usize, hidden.iter().filter(|&&h| h).count());
        assert!(l[0].eps <= 0.4 && l[0].eps > 0.2, "{l:?}");
        (hidden, work.points, l[0])
    };
    // Faces are sampled first with balls of 2³ × 0.05 = 0.4: 2 × 2 rectangles on each of the
    // six faces, 24 points; 30 leave the finer levels almost all unsampled.
    let (hidden, points, first) = run(30);
    assert_eq!(points, 30, "the budget is spent");
    assert!(first.points <= 30 && first.hidden >= 1, "{first:?}");
    assert!(
        hidden[id("walled")],
        "the coarsest level proves the walled target hidden: a budget must not lose it"
    );
    assert!(
        !hidden[id("target")],
        "the leaves' target needs finer balls"
    );
    for o in ["open", "leaves", "wall"] {
        assert!(!hidden[id(o)], "{o} is visible");
    }
    brute_force_hidden(&scene, &cell, id("walled") as u32);
    // Without the budget the finer levels hide the leaves' target too.
    let (hidden, points, _) = run(50_000);
    assert!(points > 30);
    assert!(hidden[id("walled")] && hidden[id("target")]);
    brute_force_hidden(&scene, &cell, id("target") as u32);
}

/// A tiny finest ε (here 0.001 on a unit cell, about three million rectangles at the top level
/// if it were laid out whole) must not lay more top-level rectangles than the budget can render:
/// the sampler starts coarser, so a wall still hides the target behind it within 200 points
/// (once, the top level took the budget and every object stayed visible; with a smaller ε
/// still, it ran out of memory).
#[test]
fn a_tiny_eps_starts_coarse_enough_for_the_budget() {
    let (mut obj, mut nv) = walled_target(DVec3::new(-5.0, -0.4, -0.4), DVec3::new(-4.0, 0.4, 0.4));
    wall(&mut obj, &mut nv, |u, v| DVec3::new(-2.0, u, v));
    let scene = load_obj("tiny-eps", &obj);
    let cell = Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5));
    let s = BakeSettings {
        sampling: SweepChoice::On,
        sampling_settings: SamplingSettings {
            eps: Some(1e-3),
            levels: 0,
            resolution: Some(32),
            rays: 0,
            budget_points: 200,
            probe: 0.0,
            ..SamplingSettings::default()
        },
        ..BakeSettings::default()
    };
    let (hidden, work) = run_sampler(&scene, &cell, &s);
    assert!(work.points <= 200, "{} points", work.points);
    let first = work.levels.first().expect("a level was sampled");
    assert!(first.eps > 0.05, "the top level's ε {}", first.eps);
    assert!(hidden[0], "the wall hides the target from the coarse balls");
    assert!(!hidden[1], "the wall is visible");
    brute_force_hidden(&scene, &cell, 0);
    // Coarser levels split unsampled (`--sampling-max-eps` at the finest ε) would lay out the
    // whole finest level, which the budget cannot render: the sampler stops before it, with
    // everything visible, instead of spending its points where they can prove nothing.
    let mut s = s;
    s.sampling_settings.max_eps = Some(1e-3);
    let (hidden, work) = run_sampler(&scene, &cell, &s);
    assert_eq!(work.points, 0);
    assert!(!hidden.contains(&true), "nothing sampled, nothing hidden");
}

/// Slivers (welded seams, needles: inradius under a thousandth of the longest edge) do not
/// choose the default ε: 4,000 of them beside [`scene`]'s 3,000 leaves leave it where the
/// leaves put it (once it was the slivers' median, about 1e-5 here).
#[test]
fn slivers_do_not_choose_the_default_eps() {
    let reason = |slivers: bool| {
        let (mut obj, mut nv) = scene_obj(None);
        if slivers {
            writeln!(obj, "o seams").unwrap();
            for k in 0..4000 {
                let (x, y) = ((k % 64) as f64 * 0.5, (k / 64) as f64 * 0.5);
                for p in [
                    [x, y, -50.0],
                    [x + 1.0, y, -50.0],
                    [x + 0.5, y + 2e-5, -50.0],
                ] {
                    writeln!(obj, "v {} {} {}", p[0], p[1], p[2]).unwrap();
                }
                writeln!(obj, "f {} {} {}", nv + 1, nv + 2, nv + 3).unwrap();
                nv += 3;
            }
        }
        let scene = load_obj(&format!("slivers-{slivers}"), &obj);
        let mut s = settings();
        s.sampling_settings.eps = None;
        let cell = Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5));
        let p = Prepared::new(&scene, &s, &[cell]).unwrap();
        let r = p.sampling_reason.clone();
        let at = r.find("finest ε").expect("the reason names the finest ε");
        r[at..].split(';').next().unwrap().to_string()
    };
    let (leaves, with_slivers) = (reason(false), reason(true));
    assert!(leaves.contains("median inradius"), "{leaves}");
    assert_eq!(leaves, with_slivers);
}

/// `BakeHooks::sampler_progress` counts the sampler's points as it renders them (the bake's
/// progress bar shows them inside long cells): at the end it holds every cell's points; and
/// it counts the face rectangles, every one begun also finished, at least one per point.
#[test]
fn the_sample_point_hook_counts_every_point() {
    let (scene, cell) = scene(None);
    let cells = [
        cell,
        Aabb::new(Vec3::new(0.5, -0.5, -0.5), Vec3::new(1.5, 0.5, 0.5)),
    ];
    let progress = bake::SamplerProgress::default();
    let r = bake::bake_cells(
        &scene,
        &cells,
        &[0, 1],
        &settings(),
        &CpuBackend::new(),
        bake::BakeHooks {
            sampler_progress: Some(&progress),
            ..bake::BakeHooks::default()
        },
    )
    .unwrap();
    let k = sampler_index(&r);
    let points: u64 = r.cells.iter().map(|c| c.cullers[k].work.points).sum();
    assert!(points > 0);
    use std::sync::atomic::Ordering::Relaxed;
    assert_eq!(progress.points.load(Relaxed), points);
    let (done, begun) = (
        progress.rects_done.load(Relaxed),
        progress.rects_begun.load(Relaxed),
    );
    assert_eq!(done, begun, "every rectangle begun is finished");
    assert!(begun >= points, "{begun} rectangles, {points} points");
}

/// `--sampling-max-eps`: levels whose balls are coarser are split without being rendered, so
/// the cost curve starts at the first level sampled and the faces stay covered (the leaves'
/// target is still culled, and checked by brute force); the finest level is sampled even when
/// it is coarser than the limit.
#[test]
fn levels_coarser_than_the_largest_sampled_eps_are_split_unsampled() {
    let (scene, cell) = scene(None);
    let run = |max_eps: Option<f64>| {
        let mut s = settings();
        s.sampling_settings.levels = 3;
        s.sampling_settings.eps = Some(0.05);
        s.sampling_settings.max_eps = max_eps;
        run_sampler(&scene, &cell, &s)
    };
    // Every level sampled: the unit cube's faces are cut 2 × 2 (ε 0.354), then 0.177, …
    let top = 0.5f64.hypot(0.5) / 2.0;
    let (all_hidden, all) = run(Some(1.0));
    assert!((all.levels[0].eps - top).abs() < 1e-12, "{:?}", all.levels);
    assert!(all.levels[0].points <= 24);
    // Levels 0.354 and 0.177 split unsampled: the first sampled has 4 × 4 rectangles per
    // face, more points than the whole top level could take.
    let (hidden, some) = run(Some(0.15));
    assert!(
        (some.levels[0].eps - top / 4.0).abs() < 1e-12,
        "{:?}",
        some.levels
    );
    assert!(some.levels[0].points > 24, "{:?}", some.levels);
    assert!(
        hidden[0] && all_hidden[0],
        "the fused leaves hide the target"
    );
    assert!(!hidden[1] && !hidden[2]);
    brute_force_hidden(&scene, &cell, 0);
    // A limit below the finest ε still samples the finest level (0.044), and only it.
    let (_, finest) = run(Some(0.01));
    assert_eq!(finest.levels.len(), 1, "{:?}", finest.levels);
    assert!((finest.levels[0].eps - top / 8.0).abs() < 1e-12);
    assert!(finest.levels[0].points > some.levels[0].points);
}

/// A level whose probe (every few rectangles) proves nothing hidden is split without sampling
/// the rest; the finest level is always sampled whole, and the result is the same.
#[test]
fn a_level_whose_probe_proves_nothing_is_split_unsampled() {
    let (scene, cell) = scene(None);
    let run = |probe: f64| run_sampler(&scene, &cell, &probed(None, probe, 0.0));
    // Level 0 (ε 0.354, 2 × 2 rectangles per face; the probe takes every third, 8, less
    // those with nothing beyond them): the shrink leaves too little of the ~1-unit leaves to
    // hide the target from every rectangle.
    let (whole_hidden, whole) = run(0.0);
    let (probed_hidden, probed) = run(0.01);
    assert!(
        whole.levels.iter().all(|l| !l.probe_only),
        "{:?}",
        whole.levels
    );
    let (w0, p0) = (whole.levels[0], probed.levels[0]);
    assert_eq!(w0.hidden, 0, "{:?}", whole.levels);
    assert!(p0.probe_only, "{:?}", probed.levels);
    assert!(
        p0.points > 0 && p0.points <= SamplingSettings::PROBE_MIN as u64 && p0.points < w0.points,
        "{:?} {:?}",
        probed.levels,
        whole.levels
    );
    // The probe's share of tests that hid the object is recorded (the leaves seen low over a
    // face, which the rectangles' supports barely shrink, hide the target at some of its
    // rectangles), and it proved nothing for the cell; without probes there is none.
    assert!(
        p0.probe_hidden.is_some_and(|h| (0.0..1.0).contains(&h)),
        "{:?}",
        probed.levels
    );
    assert_eq!(p0.probe_cell_hidden, Some(0), "{:?}", probed.levels);
    assert!(whole.levels.iter().all(|l| l.probe_hidden.is_none()));
    // The finest level is sampled whole, never cut short by its probe.
    assert!(!probed.levels.last().unwrap().probe_only);
    // The same objects culled: the fused leaves hide the target, nothing else.
    assert_eq!(probed_hidden, whole_hidden);
    assert!(probed_hidden[0] && !probed_hidden[1]);
    brute_force_hidden(&scene, &cell, 0);
}

/// A level whose probe hides objects at some rectangles, but none at every probed rectangle
/// that tests it, is split unsampled too: the rest of the level could cull nothing. The cell
/// `[-0.5, 0.5]³` under a wall (z = 1.5) with a window; the target, beyond the window's edge
/// as seen from the cell, is hidden from the top face's rectangles far from the window and
/// left open (by the shrink) at the near ones, at the coarsest level. Finer levels hide it
/// from everywhere.
#[test]
fn a_level_whose_probe_hides_nothing_everywhere_is_split_unsampled() {
    let mut obj = String::new();
    let mut nv = 0;
    cube(
        &mut obj,
        &mut nv,
        "target",
        DVec3::new(3.4, -0.2, 4.0),
        DVec3::new(3.8, 0.2, 4.2),
    );
    // The wall: four quads around the window x ∈ [0.3, 0.5], y ∈ [-0.15, 0.15].
    writeln!(obj, "o wall").unwrap();
    for [x0, x1, y0, y1] in [
        [-20.0, 0.3, -20.0, 20.0],
        [0.5, 20.0, -20.0, 20.0],
        [0.3, 0.5, -20.0, -0.15],
        [0.3, 0.5, 0.15, 20.0],
    ] {
        for (x, y) in [(x0, y0), (x1, y0), (x1, y1), (x0, y1)] {
            writeln!(obj, "v {x} {y} 1.5").unwrap();
        }
        writeln!(obj, "f {} {} {} {}", nv + 1, nv + 2, nv + 3, nv + 4).unwrap();
        nv += 4;
    }
    let scene = load_obj("window", &obj);
    let cell = Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5));
    let run = |probe: f64| run_sampler(&scene, &cell, &probed(Some(256), probe, 0.0));
    let (whole_hidden, whole) = run(0.0);
    let (probed_hidden, probed) = run(0.01);
    // Sampled whole, the coarsest level hides the target from no more than some rectangles.
    assert!(!whole.levels[0].probe_only, "{:?}", whole.levels);
    assert_eq!(whole.levels[0].hidden, 0, "{:?}", whole.levels);
    // Its probe hid the target somewhere (more than 1 % of what it tested), yet the level
    // was split unsampled.
    assert!(probed.levels[0].probe_only, "{:?}", probed.levels);
    assert!(!probed.levels.last().unwrap().probe_only);
    assert_eq!(probed_hidden, whole_hidden);
    assert!(probed_hidden[0], "the finest level hides the target");
    brute_force_hidden(&scene, &cell, 0);
}

/// A level whose probe proves some object hidden for the cell, but too few of the objects it
/// tests (`--sampling-probe-cull`), is split unsampled too: its balls do not fuse what it
/// tests. The cell `[-0.5, 0.5]³` under the layer of leaves of `scene`, with nine targets
/// beyond it that only a fine ε hides, and over a wall (z = -1.5) hiding a tenth target at
/// any ε. The coarsest level (ε 0.354) shrinks the leaves to nothing: its probe hides the
/// wall's target at every probed rectangle and none of the others, 1 of at most 12.
#[test]
fn a_level_whose_probe_hides_too_few_everywhere_is_split_unsampled() {
    let scene = wall_and_leaves();
    let cell = Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5));
    let run = |probe_cull: f64| run_sampler(&scene, &cell, &probed(None, 0.01, probe_cull));
    let (strict_hidden, strict) = run(0.15);
    let (lenient_hidden, lenient) = run(0.05);
    let (l0, s0) = (lenient.levels[0], strict.levels[0]);
    // The probe's figures: the wall's target hidden at every probed rectangle, of the
    // undecided objects it tested (at most the twelve).
    assert_eq!(s0.probe_cell_hidden, Some(1), "{:?}", strict.levels);
    let tested = s0.probe_objects.unwrap();
    assert!((7..=12).contains(&tested), "{:?}", strict.levels);
    assert_eq!(
        (l0.probe_cell_hidden, l0.probe_objects),
        (s0.probe_cell_hidden, s0.probe_objects)
    );
    // A share between 0.05 and 0.15: only the strict bake splits the level unsampled.
    assert!(s0.probe_only, "{:?}", strict.levels);
    assert!(!l0.probe_only, "{:?}", lenient.levels);
    assert!(
        s0.points < l0.points,
        "{:?} {:?}",
        strict.levels,
        lenient.levels
    );
    // Sampled whole, the level proves the wall's target hidden for the cell.
    assert_eq!(l0.hidden, 1, "{:?}", lenient.levels);
    // The finest level is sampled whole either way, and the result is the same: the wall's
    // target and the leaves' targets hidden.
    assert!(!strict.levels.last().unwrap().probe_only);
    assert_eq!(strict_hidden, lenient_hidden);
    assert!(strict_hidden[0], "the wall hides its target");
    assert!(
        strict_hidden[1..10].iter().any(|&h| h),
        "the fused leaves hide targets"
    );
    for o in (0..10).filter(|&o| strict_hidden[o]) {
        brute_force_hidden(&scene, &cell, o as u32);
    }
}

/// The scene of the two tests above and below: a wall (z = -1.5) under the cell
/// `[-0.5, 0.5]³` hiding the target `walled`, and nine targets (`leafy…`) beyond the layer of
/// leaves of `scene` over it.
fn wall_and_leaves() -> umbrasweep::Scene {
    let (mut obj, mut nv) = walled_target(DVec3::new(-0.5, -0.5, -4.5), DVec3::new(0.5, 0.5, -4.0));
    for i in 0..3 {
        for j in 0..3 {
            let c = DVec3::new(f64::from(i) - 1.0, f64::from(j) - 1.0, 8.5);
            cube(
                &mut obj,
                &mut nv,
                &format!("leafy{i}{j}"),
                c - DVec3::splat(0.3),
                c + DVec3::splat(0.3),
            );
        }
    }
    wall(&mut obj, &mut nv, |u, v| DVec3::new(u, v, -1.5));
    leaf_layer(&mut obj, &mut nv, None);
    load_obj("wall-and-leaves", &obj)
}

/// `--sampling-probe-pay`: a level that proves much per rectangle but saves the finest level
/// little is split unsampled. In a small forest's middle cell the level just above the
/// finest passes the probe's share rules (objects hidden at every probed rectangle:
/// `small_forest` asks only for one), but what keeps the finest level drawing is the leaves
/// in front of the objects the level leaves open: its pilot finds each rectangle costing more
/// polygons than it saves its quadrants, and the level stops at its probe. The coarsest level
/// has no pilot and is sampled whole as without the estimate (ratio 0), where the level above
/// the finest is sampled whole too and the sample points draw more polygons. What either bake
/// hides is hidden (brute force).
#[test]
fn a_level_that_saves_the_finest_level_less_than_it_costs_is_split_unsampled() {
    let (scene, cell, settings) = small_forest();
    let run = |pay: f64| {
        let mut s = settings.clone();
        s.sampling_settings.probe_pay = pay;
        run_sampler(&scene, &cell, &s)
    };
    let (paid_hidden, paid) = run(1.0);
    let (free_hidden, free) = run(0.0);
    let timeless =
        |l: &umbrasweep::pvs::SamplingLevel| umbrasweep::pvs::SamplingLevel { seconds: 0.0, ..*l };
    let n = paid.levels.len();
    assert!(n == 3 && free.levels.len() == 3, "{:?}", paid.levels);
    // The coarsest level: no pilot, the same either way.
    assert_eq!(timeless(&paid.levels[0]), timeless(&free.levels[0]));
    assert_eq!(paid.levels[0].probe_cost, None);
    assert!(!paid.levels[0].probe_only, "{:?}", paid.levels);
    // The level above the finest: the same probe, passing the share rules; only the pilot
    // tells the bakes apart.
    let (p, f) = (paid.levels[1], free.levels[1]);
    assert!(p.probe_cell_hidden.unwrap() > 0, "{:?}", paid.levels);
    assert_eq!(
        (p.probe_hidden, p.probe_cell_hidden, p.probe_objects),
        (f.probe_hidden, f.probe_cell_hidden, f.probe_objects)
    );
    let (cost, saving) = (p.probe_cost.unwrap(), p.pilot_saving.unwrap());
    assert!(cost > 0.0 && saving < cost, "{:?}", paid.levels);
    assert!(p.probe_only, "{:?}", paid.levels);
    assert!(!f.probe_only, "{:?}", free.levels);
    assert_eq!((f.probe_cost, f.pilot_saving), (None, None));
    assert!(
        paid.polygons < free.polygons,
        "polygons drawn: {} with the pilot, {} without",
        paid.polygons,
        free.polygons
    );
    // The PVS document records the pilot's figures per cell (`probe_cost`, `pilot_saving`)
    // and their means in the summary (here over the one cell: the same).
    let r = bake::bake(&scene, &[cell], &settings, &CpuBackend::new(), None).unwrap();
    let json = serde_json::to_value(bake::to_document(&scene, &[cell], &r, &settings)).unwrap();
    let k = sampler_index(&r);
    let levels = json["cells"][0]["cullers"][k]["levels"].as_array().unwrap();
    let summary = json["summary"]["cullers"][k]["levels"].as_array().unwrap();
    let piloted: Vec<usize> = (0..levels.len())
        .filter(|&i| levels[i].get("probe_cost").is_some())
        .collect();
    assert!(!piloted.is_empty(), "{levels:?}");
    for i in piloted {
        for key in ["probe_cost", "pilot_saving"] {
            let v = levels[i][key].as_f64().unwrap();
            assert!(v.is_finite(), "{key} {v}");
            assert!((summary[i][key].as_f64().unwrap() - v).abs() <= 1e-9 * v.abs());
        }
    }
    assert!(paid_hidden.iter().any(|&h| h) && free_hidden.iter().any(|&h| h));
    for hidden in [&paid_hidden, &free_hidden] {
        for o in (0..scene.objects.len()).filter(|&o| hidden[o]).step_by(7) {
            brute_force_hidden(&scene, &cell, o as u32);
        }
    }
}

/// `--sampling-probe-pay`: a level whose rectangles close pays for itself. The cell inside a
/// closed room of six walls, a target beyond each: the level above the finest (ε 0.4, the
/// finest 0.2) hides every target at every rectangle, so none of its quadrants is rendered;
/// its pilot finds that saving (four quadrants' renders) above its cost (one render) and the
/// level is sampled whole, and nothing finer is.
#[test]
fn a_level_whose_rectangles_close_pays_for_itself() {
    let (mut obj, mut nv) = (String::new(), 0);
    for axis in 0..3 {
        for side in [-1.0, 1.0] {
            let mut c = DVec3::ZERO;
            c[axis] = 5.0 * side;
            cube(
                &mut obj,
                &mut nv,
                &format!("target{axis}{}", side > 0.0),
                c - DVec3::splat(0.5),
                c + DVec3::splat(0.5),
            );
        }
    }
    for axis in 0..3 {
        for side in [-1.0, 1.0] {
            wall(&mut obj, &mut nv, |u, v| {
                let mut p = DVec3::ZERO;
                p[axis] = 2.0 * side;
                p[(axis + 1) % 3] = u;
                p[(axis + 2) % 3] = v;
                p
            });
        }
    }
    let scene = load_obj("room", &obj);
    let cell = Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5));
    let mut s = probed(None, 0.01, 0.4);
    s.sampling_settings.eps = Some(0.2);
    s.sampling_settings.levels = 1;
    s.sampling_settings.probe_pay = 1.0;
    let (hidden, work) = run_sampler(&scene, &cell, &s);
    let l0 = work.levels[0];
    assert!(!l0.probe_only, "{:?}", work.levels);
    let (cost, saving) = (l0.probe_cost.unwrap(), l0.pilot_saving.unwrap());
    assert!(cost > 0.0 && saving >= 2.0 * cost, "{:?}", work.levels);
    // Every target hidden by the coarsest level alone: its 24 rectangles are all the points.
    assert_eq!(work.levels.len(), 1, "{:?}", work.levels);
    assert_eq!(work.points, 24);
    assert!(hidden[..6].iter().all(|&h| h), "{hidden:?}");
    brute_force_hidden(&scene, &cell, 0);
}

/// The probe's share rule alone (`--sampling-probe`): the same coarsest level, whose probe
/// proves the wall's target hidden for the cell (enough for `--sampling-probe-cull` 0.05), is
/// sampled whole when the probe hides at least `--sampling-probe` of its tests and split
/// unsampled when it hides less.
#[test]
fn a_level_whose_probe_hides_too_small_a_share_is_split_unsampled() {
    let scene = wall_and_leaves();
    let cell = Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5));
    let run = |probe: f64| run_sampler(&scene, &cell, &probed(None, probe, 0.05));
    let (low_hidden, low) = run(0.01);
    let (high_hidden, high) = run(0.9);
    let (l0, h0) = (low.levels[0], high.levels[0]);
    // The same probe either way: it hides the wall's target at every probed rectangle and
    // nothing else, a share of its tests between the two thresholds.
    assert_eq!(
        (l0.probe_hidden, l0.probe_cell_hidden, l0.probe_objects),
        (h0.probe_hidden, h0.probe_cell_hidden, h0.probe_objects)
    );
    assert_eq!(h0.probe_cell_hidden, Some(1), "{:?}", high.levels);
    let share = h0.probe_hidden.unwrap();
    assert!((0.01..0.9).contains(&share), "{:?}", high.levels);
    // Only the share rule tells the two bakes apart.
    assert!(!l0.probe_only, "{:?}", low.levels);
    assert!(h0.probe_only, "{:?}", high.levels);
    assert!(h0.points < l0.points, "{:?} {:?}", high.levels, low.levels);
    // The finest level is sampled whole either way, with the same result.
    assert!(!high.levels.last().unwrap().probe_only);
    assert_eq!(low_hidden, high_hidden);
    assert!(high_hidden[0], "the wall hides its target");
}

/// `--max-memory`'s estimate holds one hemicube per worker thread at the largest resolution
/// the sampler may render (the fixed one, or the automatic rule's greatest), and none without
/// the sampler.
#[test]
fn the_memory_estimate_holds_a_hemicube_per_thread() {
    let (scene, _) = scene(None);
    let mut s = settings();
    let fixed = bake::estimate_memory(&scene, &s, 4);
    s.sampling_settings.resolution = None;
    let auto = bake::estimate_memory(&scene, &s, 4);
    let (_, hi) = SamplingSettings::AUTO_RESOLUTION;
    assert_eq!(
        auto - fixed,
        4 * (SamplingSettings::hemicube_bytes(hi) - SamplingSettings::hemicube_bytes(64))
    );
    s.sampling = SweepChoice::Off;
    let off = bake::estimate_memory(&scene, &s, 4);
    assert!(off + 4 * SamplingSettings::hemicube_bytes(hi) < auto);
}

/// Bakes the one cell `cell` on the CPU with `hooks`.
fn bake_with(
    scene: &umbrasweep::Scene,
    cell: Aabb,
    settings: &BakeSettings,
    hooks: bake::BakeHooks,
) -> Result<bake::BakeResult, bake::BakeError> {
    bake::bake_cells(scene, &[cell], &[0], settings, &CpuBackend::new(), hooks)
}

/// The sampler's position among the cullers of a bake's result.
fn sampler_index(r: &bake::BakeResult) -> usize {
    r.cullers
        .iter()
        .position(|&c| c == "shrunk_sampling")
        .expect("the sampler ran")
}

/// What a resume test compares of a bake: the PVS, points, polygons and the cost curve but
/// its seconds.
type ResumeKey = (Vec<u32>, u64, u64, Vec<umbrasweep::pvs::SamplingLevel>);

/// [`ResumeKey`] of a one-cell bake.
fn resume_key(r: &bake::BakeResult) -> ResumeKey {
    let c = &r.cells[0];
    let w = &c.cullers[sampler_index(r)].work;
    let curve = w
        .levels
        .iter()
        .map(|l| umbrasweep::pvs::SamplingLevel { seconds: 0.0, ..*l })
        .collect();
    (c.visible.clone(), w.points, w.polygons, curve)
}

/// [`bake_with`] with sampler checkpoints `spec` (none: no file).
fn bake_checkpointed(
    scene: &umbrasweep::Scene,
    cell: Aabb,
    settings: &BakeSettings,
    spec: Option<&bake::SamplerCheckpoints>,
) -> Result<bake::BakeResult, bake::BakeError> {
    bake_with(
        scene,
        cell,
        settings,
        bake::BakeHooks {
            sampler_checkpoints: spec,
            ..bake::BakeHooks::default()
        },
    )
}

/// A 120-tree, 150-leaf forest of the `preset`'s leaves and its middle cell.
fn forest_middle_cell(preset: umbrasweep::generate::ForestOptions) -> (umbrasweep::Scene, Aabb) {
    let generated = umbrasweep::generate::forest(&umbrasweep::generate::ForestOptions {
        trees: 120,
        leaves: 150,
        ..preset
    })
    .unwrap();
    let cell = generated.cells[generated.cells.len() / 2];
    (generated.to_scene("forest.obj"), cell)
}

/// A 120-tree forest's middle cell and sampler settings that give it many rectangles, two
/// levels with probes, certifying rays and distance bands.
fn small_forest() -> (umbrasweep::Scene, Aabb, BakeSettings) {
    let (scene, cell) = forest_middle_cell(umbrasweep::generate::ForestOptions::coarse());
    let mut settings = settings();
    settings.sampling_settings = SamplingSettings {
        eps: Some(0.12),
        levels: 2,
        resolution: Some(96),
        rays: 3_000,
        // A level is sampled whole once its probe proves one object for the cell: the tests
        // on this forest need a level sampled whole after its probe.
        probe_cull: 0.0,
        ..SamplingSettings::default()
    };
    (scene, cell, settings)
}

/// The sampler's results do not depend on the threads: a small forest's middle cell, with
/// certifying rays, levels with probes, a level sampled whole (scouts first) and distance
/// bands, sampled on 1, 3 and 4 threads, hides the same objects with the same points and the
/// same cost curve. (Rectangles running side by side once decided with what the others had
/// just found visible, which changed their candidate lists, hence their bands and shrinks.)
#[test]
fn the_sampler_hides_the_same_on_any_thread_count() {
    let (scene, cell, settings) = small_forest();
    let run = |threads: usize| sampled_on(threads, &scene, &cell, &settings);
    let one = run(1);
    assert!(
        one.1 > 64 && one.2.len() >= 2 && one.0.contains(&true),
        "the test needs many rectangles, two levels and something hidden: {:?}",
        (one.1, &one.2)
    );
    for threads in [3, 4] {
        assert_same_sampling(&one, &run(threads), threads);
    }
}

/// What [`sampled_on`] gives: the objects hidden, the points, and per level the points and
/// objects hidden.
type Sampled = (Vec<bool>, u64, Vec<(u64, u32)>);

/// Panics unless the run on `threads` threads gave what the one-thread run gave.
fn assert_same_sampling(one: &Sampled, other: &Sampled, threads: usize) {
    assert_eq!(one.2, other.2, "cost curve on {threads} threads");
    assert_eq!(one.1, other.1, "points on {threads} threads");
    assert!(
        one.0 == other.0,
        "hidden objects differ on {threads} threads"
    );
}

/// The sampler alone on `threads` threads: what it hid, its points and its cost curve's
/// points and hidden objects per level.
fn sampled_on(
    threads: usize,
    scene: &umbrasweep::Scene,
    cell: &Aabb,
    settings: &BakeSettings,
) -> Sampled {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let (hidden, work) = pool.install(|| run_sampler(scene, cell, settings));
    let curve = work.levels.iter().map(|l| (l.points, l.hidden)).collect();
    (hidden, work.points, curve)
}

/// A point budget that runs out inside a level gives its last points to the same rectangles
/// on any thread count, run after run: the small forest's cell with ten points fewer than it
/// takes unbudgeted, on 1, 3 and 4 threads (4 twice). When lanes took points from a shared counter
/// as they came, which rectangles got the last ones (and so what stayed visible) followed the
/// threads' timing.
#[test]
fn a_point_budget_runs_out_at_the_same_rectangles_on_any_thread_count() {
    let (scene, cell, mut settings) = small_forest();
    let whole = run_sampler(&scene, &cell, &settings).1.points;
    // Ten points short: a few rectangles of the last chunk give up, and which ones decides
    // what stays visible. (Half the points fails too seldom: its given-up lists hold nearly
    // every undecided object whichever rectangles they are.)
    let budget = whole - 10;
    settings.sampling_settings.budget_points = budget;
    let run = |threads: usize| sampled_on(threads, &scene, &cell, &settings);
    let one = run(1);
    assert!(
        one.1 <= budget && one.1 + 32 > budget && one.2.len() >= 2,
        "the budget of {budget} (of {whole}) must run out in a later level: {:?}",
        (one.1, &one.2)
    );
    for threads in [3, 4, 4] {
        assert_same_sampling(&one, &run(threads), threads);
    }
}

/// `bake --resume` inside a cell: a cell whose sampler stops right after its n-th checkpoint
/// resumes from the file to the same PVS, points and cost curve as an uninterrupted bake,
/// replaying the recorded rectangles instead of rendering them; the file is gone once the
/// cell is finished. A file made for other inputs, or laid out for another finest ε, is not
/// resumed. Twice: without the pilot (`--sampling-probe-pay 0`: every level sampled whole
/// after its probe, cuts in the first level and in a later one), and with it, where the level
/// above the finest stops at its probe (cuts in the first level; right after the second
/// level's probe, so that the resumed bake runs the pilot itself; and in the finest level,
/// so that it takes the decision and figures saved).
#[test]
fn a_cell_stopped_after_a_checkpoint_resumes_to_the_same_result() {
    let (scene, cell, paid) = small_forest();
    let mut free = paid.clone();
    free.sampling_settings.probe_pay = 0.0;
    for (settings, cuts) in [(&free, &[1, 5][..]), (&paid, &[1, 3, 4][..])] {
        resume_after_cuts(&scene, cell, settings, cuts, std::ptr::eq(settings, &free));
    }
}

/// The body of the test above: stops the cell after each of `cuts` checkpoints and resumes
/// it; with `others`, also the files that must not be resumed.
fn resume_after_cuts(
    scene: &umbrasweep::Scene,
    cell: Aabb,
    settings: &BakeSettings,
    cuts: &[u32],
    others: bool,
) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("forest.pvs");
    let files = || -> Vec<std::path::PathBuf> {
        std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.to_string_lossy().contains(".sampler-"))
            .collect()
    };
    let run =
        |spec: Option<&bake::SamplerCheckpoints>| bake_checkpointed(scene, cell, settings, spec);
    // What a comparison keeps of a bake: the PVS and the sampler's work but its seconds.
    let key = |r: &bake::BakeResult| {
        let k = sampler_index(r);
        let c = &r.cells[0];
        let w = &c.cullers[k].work;
        let curve: Vec<_> = w
            .levels
            .iter()
            .map(|l| {
                (
                    l.eps,
                    l.points,
                    l.hidden,
                    l.probe_only,
                    l.probe_cost,
                    l.pilot_saving,
                )
            })
            .collect();
        (
            c.visible.clone(),
            c.cullers[k].hidden,
            w.points,
            w.polygons,
            w.finest_eps,
            curve,
        )
    };
    let whole = key(&run(None).unwrap());
    assert!(
        whole.2 > 64 && whole.5.len() >= 2 && whole.1 > 0,
        "the test needs many rectangles, two levels and something hidden: {whole:?}"
    );
    let stop = |inputs: &str, writes: u32| {
        let mut spec = bake::SamplerCheckpoints::new(&out, inputs, false, 0.0);
        spec.stop_after_writes = Some(writes);
        let e = run(Some(&spec)).expect_err("stopped");
        assert!(matches!(e, bake::BakeError::Interrupted), "{e}");
        assert_eq!(files().len(), 1, "one checkpoint for the one cell");
    };
    for &writes in cuts {
        stop("inputs A", writes);
        let spec = bake::SamplerCheckpoints::new(&out, "inputs A", true, 0.0);
        let resumed = key(&run(Some(&spec)).unwrap());
        assert_eq!(resumed, whole, "resumed after {writes} checkpoints");
        let replayed = spec.replayed.load(std::sync::atomic::Ordering::Relaxed);
        assert!(replayed > 0, "nothing replayed after {writes} checkpoints");
        assert!(
            files().is_empty(),
            "the finished cell's checkpoint is removed"
        );
    }
    if !others {
        return;
    }
    // Another bake's checkpoint is not resumed (and is replaced, then removed).
    stop("inputs A", 2);
    let spec = bake::SamplerCheckpoints::new(&out, "inputs B", true, 0.0);
    assert_eq!(key(&run(Some(&spec)).unwrap()), whole);
    assert_eq!(spec.replayed.load(std::sync::atomic::Ordering::Relaxed), 0);
    assert!(files().is_empty());
    // Nor is one laid out for another finest ε (its rectangles are other rectangles), even
    // with the same inputs.
    stop("inputs A", 2);
    let path = files().pop().unwrap();
    let mut file: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let eps = file["finest_eps"]
        .as_f64()
        .expect("the file records its finest ε");
    file["finest_eps"] = serde_json::json!(eps / 2f64.sqrt());
    std::fs::write(&path, serde_json::to_vec(&file).unwrap()).unwrap();
    let spec = bake::SamplerCheckpoints::new(&out, "inputs A", true, 0.0);
    assert_eq!(key(&run(Some(&spec)).unwrap()), whole);
    assert_eq!(spec.replayed.load(std::sync::atomic::Ordering::Relaxed), 0);
    assert!(files().is_empty());
}

/// A kept checkpoint (`SamplerCheckpoints::kept`, what `bench --checkpoint-dir` uses) stays
/// when its cell finishes, complete: a second bake resumed from it renders no sample point,
/// replays every rectangle, comes out the same, and reports the sampler's time with the first
/// run's included.
#[test]
fn a_kept_checkpoint_replays_the_whole_finished_cell() {
    use std::sync::atomic::Ordering;
    let (scene, cell, settings) = small_forest();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("row");
    let run = |spec: &bake::SamplerCheckpoints, progress: &bake::SamplerProgress| {
        let r = bake_with(
            &scene,
            cell,
            &settings,
            bake::BakeHooks {
                sampler_checkpoints: Some(spec),
                sampler_progress: Some(progress),
                ..bake::BakeHooks::default()
            },
        )
        .unwrap();
        let k = sampler_index(&r);
        let s = r.cells[0].cullers[k].clone();
        (r.cells[0].visible.clone(), s, r.cells[0].ms)
    };
    let first_progress = bake::SamplerProgress::default();
    let first = bake::SamplerCheckpoints::new(&out, "inputs", true, 1e9).kept();
    let (vis1, s1, _) = run(&first, &first_progress);
    assert!(s1.hidden > 0 && s1.work.points > 64, "{s1:?}");
    assert_eq!(
        first_progress.points.load(Ordering::Relaxed),
        s1.work.points
    );
    let kept: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(kept.len(), 1, "the finished cell's file is kept: {kept:?}");
    // Complete: every rectangle the cell sampled or split is in it.
    let file: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&kept[0]).unwrap()).unwrap();
    let rects: usize = file["levels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["rects"].as_object().unwrap().len())
        .sum();
    assert!(rects as u64 >= s1.work.points, "{rects} rectangles");
    let again_progress = bake::SamplerProgress::default();
    let again = bake::SamplerCheckpoints::new(&out, "inputs", true, 1e9).kept();
    let (vis2, s2, cell_ms) = run(&again, &again_progress);
    // Every rectangle replayed, none rendered (replayed points and rectangles count as
    // progress too).
    assert_eq!(again.replayed.load(Ordering::Relaxed), rects as u64);
    assert_eq!(
        again_progress.points.load(Ordering::Relaxed),
        s1.work.points
    );
    let counts = |p: &bake::SamplerProgress| {
        (
            p.rects_done.load(Ordering::Relaxed),
            p.rects_begun.load(Ordering::Relaxed),
        )
    };
    let (done, begun) = counts(&first_progress);
    assert!(
        done == begun && begun >= rects as u64,
        "{done}, {begun}, {rects}"
    );
    assert_eq!(counts(&again_progress), counts(&first_progress));
    assert_eq!(
        (&vis2, s2.hidden, s2.work.points),
        (&vis1, s1.hidden, s1.work.points)
    );
    let curve = |s: &bake::CullerStats| -> Vec<_> {
        s.work
            .levels
            .iter()
            .map(|l| (l.eps, l.points, l.hidden, l.probe_only))
            .collect()
    };
    assert_eq!(curve(&s2), curve(&s1));
    // The time includes what the first run spent sampling (its curve's last entry).
    let sampled = s1.work.levels.last().unwrap().seconds * 1e3;
    assert!(
        s2.ms >= sampled,
        "{} ms, the first run sampled {sampled} ms",
        s2.ms
    );
    assert!(cell_ms >= s2.ms, "the cell's {cell_ms} ms");
}

/// With several distance bands, a point first renders once for all its candidates, and what
/// that render hides is not rendered for again: behind a wall in front of the cell's +x face,
/// boxes 4 and 20 units out (two bands) are hidden from every point either way, but with the
/// first render each point draws the wall once instead of once per band. (The wall's faces
/// are triangle pairs whose shrunk diagonals leave a gap: it lies off the boxes' directions.)
#[test]
fn what_the_first_render_hides_is_not_rendered_for_again() {
    let mut obj = String::new();
    let mut nv = 0;
    for (name, min, max) in [
        ("wall", [2.0, -40.0, -10.0], [2.05, 40.0, 70.0]),
        ("near", [4.0, -0.3, -0.3], [5.0, 0.3, 0.3]),
        ("far", [20.0, -0.3, -0.3], [21.0, 0.3, 0.3]),
    ] {
        cube(&mut obj, &mut nv, name, DVec3::from(min), DVec3::from(max));
    }
    let scene = load_obj("wall-bands", &obj);
    let cell = Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5));
    let mut s = settings();
    // The cell's rays see the wall: only the boxes are sampled.
    s.sampling_settings.rays = 2_000;
    let run = |whole_first: bool| {
        let mut s = s.clone();
        s.sampling_settings.whole_first = whole_first;
        run_sampler(&scene, &cell, &s)
    };
    let (first, w_first) = run(true);
    let (bands, w_bands) = run(false);
    assert_eq!(first, [false, true, true], "with the first render");
    assert_eq!(bands, [false, true, true], "by bands only");
    assert_eq!(w_first.points, w_bands.points);
    assert!(w_first.points > 0);
    assert!(
        2 * w_first.polygons <= w_bands.polygons,
        "one render per point instead of two, each drawing the wall: {} against {} polygons",
        w_first.polygons,
        w_bands.polygons
    );
}

/// Pixels traded for points (`SamplingSettings::cell_finest`): a cell among leaves 0.2 across
/// with walls 5 away, where the automatic rule would render the finest level at 1,024 pixels,
/// renders at 512 with its finest ε `1/√2` of the automatic one; the same automatic ε given
/// with `--sampling-eps` is the user's: 1,024 pixels at that ε.
#[test]
fn a_large_cell_in_fine_leaves_trades_pixels_for_points() {
    let mut obj = String::new();
    let mut nv = 0;
    // The room's walls: the rays' hits, about 5 away.
    for (axis, side) in [
        (0, -1.0),
        (0, 1.0),
        (1, -1.0),
        (1, 1.0),
        (2, -1.0),
        (2, 1.0),
    ] {
        wall(&mut obj, &mut nv, |u, v| {
            let mut p = DVec3::ZERO;
            p[axis] = 5.0 * side;
            p[(axis + 1) % 3] = u / 4.0;
            p[(axis + 2) % 3] = v / 4.0;
            p
        });
    }
    // A target beyond them (the walls are one object, around the cell: never a candidate).
    cube(
        &mut obj,
        &mut nv,
        "target",
        DVec3::new(-0.3, -0.3, 4.3),
        DVec3::new(0.3, 0.3, 4.8),
    );
    // Sparse leaves 0.2 across between 1.5 and 4 from the centre: the median inradius.
    writeln!(obj, "o leaves").unwrap();
    let mut rng = Rng(11);
    let mut n = 0;
    while n < 2000 {
        let c = DVec3::new(rng.f(), rng.f(), rng.f()) * 8.0 - DVec3::splat(4.0);
        if !(1.5..4.0).contains(&c.length()) {
            continue;
        }
        for k in 0..3 {
            let a = std::f64::consts::TAU * f64::from(k) / 3.0;
            let p = c + DVec3::new(a.cos(), a.sin(), rng.f() - 0.5) * 0.1;
            writeln!(obj, "v {} {} {}", p.x, p.y, p.z).unwrap();
        }
        writeln!(obj, "f {} {} {}", nv + 1, nv + 2, nv + 3).unwrap();
        nv += 3;
        n += 1;
    }
    let scene = load_obj("trade", &obj);
    // A small cell, so that its finest level fits the budget (a budget smaller than the top
    // level starts coarser: `a_tiny_eps_starts_coarse_enough_for_the_budget`): at ε about
    // 0.0124 traded, 4 × 4 rectangles a face.
    let cell = Aabb::new(Vec3::splat(-0.03), Vec3::splat(0.03));
    let mut s = settings();
    s.sampling_settings.eps = None;
    s.sampling_settings.resolution = None;
    s.sampling_settings.levels = 0;
    s.sampling_settings.budget_points = 200;
    let auto_eps = Prepared::new(&scene, &s, &[cell])
        .unwrap()
        .sampling_eps()
        .expect("the sampler is on");
    let (_, traded) = run_sampler(&scene, &cell, &s);
    s.sampling_settings.eps = Some(auto_eps);
    let (_, given) = run_sampler(&scene, &cell, &s);
    let (t, g) = (traded.levels.last().unwrap(), given.levels.last().unwrap());
    assert_eq!(
        (t.resolution, g.resolution),
        (SamplingSettings::TRADE_RESOLUTION, 1024),
        "{traded:?}\n{given:?}"
    );
    assert!(traded.points > 0 && given.points > 0);
    let (te, ge) = (traded.finest_eps.unwrap(), given.finest_eps.unwrap());
    assert!(
        ge <= auto_eps * (1.0 + 1e-9) && te <= auto_eps / 2f64.sqrt() * (1.0 + 1e-9),
        "finest ε {te} traded, {ge} given, automatic {auto_eps}"
    );
    assert!(te < ge * 0.75, "finest ε {te} traded, {ge} given");
}

/// A level's probe stops once the rest of it could prove nothing for the cell, and a bake
/// cut inside such a probe resumes to the same result. A small fine forest's middle cell:
/// its ~0.5-unit leaves do not fuse at the two coarse levels (ε 0.118 and 0.059), whose
/// probes would take 8 and 24 rectangles. One round of 8 leaves every undecided object it
/// tests open somewhere and every face's objects tested, so the second probe stops there.
#[test]
fn a_probe_stops_once_its_rest_could_prove_nothing() {
    let (scene, cell) = forest_middle_cell(umbrasweep::generate::ForestOptions::fine());
    let mut settings = settings();
    settings.sampling_settings = SamplingSettings {
        eps: Some(0.03),
        levels: 2,
        resolution: Some(96),
        rays: 3_000,
        ..SamplingSettings::default()
    };
    let run =
        |spec: Option<&bake::SamplerCheckpoints>| bake_checkpointed(&scene, cell, &settings, spec);
    let whole = resume_key(&run(None).unwrap());
    let levels = &whole.3;
    assert_eq!(levels.len(), 3, "{levels:?}");
    for (l, rects) in levels[..2].iter().zip([8, 8]) {
        assert!(l.probe_only, "{levels:?}");
        assert_eq!(l.probe_cell_hidden, Some(0), "{levels:?}");
        assert_eq!(l.probe_rects, Some(rects), "{levels:?}");
    }
    // The second level's probe stopped after its first round: 8 points, not 24.
    assert_eq!(levels[1].points - levels[0].points, 8, "{levels:?}");
    assert!(levels[2].probe_rects.is_none() && !levels[2].probe_only);
    // Cut right after each probe's round (one checkpoint write per round), and in the
    // finest level: the same result, the recorded rounds replayed.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("forest.pvs");
    for writes in [1, 2, 3] {
        let mut spec = bake::SamplerCheckpoints::new(&out, "inputs", false, 0.0);
        spec.stop_after_writes = Some(writes);
        let e = run(Some(&spec)).expect_err("stopped");
        assert!(matches!(e, bake::BakeError::Interrupted), "{e}");
        let spec = bake::SamplerCheckpoints::new(&out, "inputs", true, 0.0);
        assert_eq!(
            resume_key(&run(Some(&spec)).unwrap()),
            whole,
            "resumed after {writes} writes"
        );
        assert!(spec.replayed.load(std::sync::atomic::Ordering::Relaxed) >= 8);
    }
}

/// The cell `[-0.5, 0.5]³`, a wall at z = 3 with a square hole 0.02 across, and a cube 0.02
/// across at z = 6 behind it, seen through the hole only from about a 0.07-wide square of the
/// cell's +z face centred on `(x, y)`.
fn slit_scene(x: f64, y: f64) -> (umbrasweep::Scene, Aabb) {
    let (mut obj, mut nv) =
        walled_target(DVec3::new(-0.01, -0.01, 6.0), DVec3::new(0.01, 0.01, 6.02));
    // Lines from the face (z = 0.5) to the cube cross the wall 2.5/5.5 of the way.
    let (hx, hy) = (x * 3.0 / 5.5, y * 3.0 / 5.5);
    let (x0, x1, y0, y1) = (hx - 0.01, hx + 0.01, hy - 0.01, hy + 0.01);
    writeln!(obj, "o wall").unwrap();
    for [a, b, c, d] in [
        [-50.0, -50.0, x0, 50.0],
        [x1, -50.0, 50.0, 50.0],
        [x0, -50.0, x1, y0],
        [x0, y1, x1, 50.0],
    ] {
        for (u, v) in [(a, b), (c, b), (c, d), (a, d)] {
            writeln!(obj, "v {u} {v} 3").unwrap();
        }
        writeln!(obj, "f {} {} {} {}", nv + 1, nv + 2, nv + 3, nv + 4).unwrap();
        nv += 4;
    }
    let scene = load_obj("slit", &obj);
    (scene, Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5)))
}

/// A cell cut after any checkpoint write, inside or after a probe of several rounds, resumes
/// to the same PVS, points and cost curve. The resumed probe goes on after the rounds its
/// interrupted run went on after (`probe_rounds` in the file) without asking whether its rest
/// could prove anything, since the file's objects known visible are those of the cut, not of
/// the round: asked with them, the probe below stops a round early. The probe's counts of what
/// it proved (`probe_objects`, `probe_cell_hidden`) come from the file for the same reason.
/// The slit scene: the cube is hidden from the first round's rectangles and seen through the
/// hole from a later one; no rays, so that only the sampler finds it.
#[test]
fn a_cell_cut_inside_or_after_a_probe_of_rounds_resumes_to_the_same_result() {
    // Two places of the hole: the first resumes wrong without the recorded rounds, the
    // second without the recorded counts.
    for (x, y) in [(0.0625, -0.4375), (-0.3125, -0.4375)] {
        let (scene, cell) = slit_scene(x, y);
        let mut settings = settings();
        settings.sampling_settings = SamplingSettings {
            eps: Some(0.045),
            levels: 3,
            rays: 0,
            budget_points: 150,
            ..settings.sampling_settings
        };
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("slit.pvs");
        let run = |spec: Option<&bake::SamplerCheckpoints>| {
            bake_checkpointed(&scene, cell, &settings, spec)
        };
        let whole = resume_key(&run(None).unwrap());
        assert_eq!(whole.0, [0, 1], "the cube is seen through the hole");
        assert!(
            whole.3.iter().any(|l| l.probe_rects.is_some_and(|r| r > 8)),
            "the test needs a probe of several rounds: {:?}",
            whole.3
        );
        // The probe rounds recorded in the checkpoint file.
        let rounds_in_file = || -> Vec<u64> {
            let file = std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().path())
                .find(|p| p.to_string_lossy().contains(".sampler-"))
                .expect("a checkpoint");
            let v: serde_json::Value =
                serde_json::from_slice(&std::fs::read(file).unwrap()).unwrap();
            v["levels"]
                .as_array()
                .unwrap()
                .iter()
                .map(|l| l.get("probe_rounds").and_then(|r| r.as_u64()).unwrap_or(0))
                .collect()
        };
        let (mut cuts, mut after_rounds) = (0, false);
        for writes in 1.. {
            let mut spec = bake::SamplerCheckpoints::new(&out, "inputs", false, 0.0);
            spec.stop_after_writes = Some(writes);
            match run(Some(&spec)) {
                Ok(r) => {
                    assert_eq!(resume_key(&r), whole);
                    break;
                }
                Err(e) => assert!(matches!(e, bake::BakeError::Interrupted), "{e}"),
            }
            let rounds = rounds_in_file();
            after_rounds |= rounds.iter().any(|&r| r > 0);
            let spec = bake::SamplerCheckpoints::new(&out, "inputs", true, 0.0);
            assert_eq!(
                resume_key(&run(Some(&spec)).unwrap()),
                whole,
                "resumed after {writes} writes (probe rounds in the file: {rounds:?})"
            );
            assert!(spec.replayed.load(std::sync::atomic::Ordering::Relaxed) > 0);
            cuts += 1;
        }
        assert!(
            cuts >= 6 && after_rounds,
            "{cuts} cuts; after a probe round: {after_rounds}"
        );
    }
}
