//! The occlusion sweep (issue 5) on analytic scenes: a cloud of small disjoint squares that
//! hides a target only when several layers fuse (separate planes must fail, the sweep must
//! succeed, and brute-force rays prove the target hidden), the same cloud with a straight
//! tunnel (the target must stay visible), sub-cells, and the automatic choice of the sweep;
//! and the scene parts the projected occluders name (`OccluderSet::parts`) for a backend that
//! keeps the parts on its device.

mod common;

use glam::Vec3;
use rand::{Rng, SeedableRng};
use std::path::Path;
use umbrasweep::backend::cpu::CpuBackend;
use umbrasweep::bake::{BakeSettings, SweepChoice, bake, split_cell};
use umbrasweep::geom::Aabb;
use umbrasweep::scene::Scene;

use common::{Obj, cube, quad, unit_cell};

const TARGET: &str = "target";

/// Pattern pitch, overlap margin and depth step of the staircase cloud.
const PITCH: f32 = 0.1;
const GROW: f32 = 0.03;
const STEP: f32 = 0.15;
const TILES: i32 = 32;
const TARGET_Z: f32 = 16.0;

/// A staircase of 32 × 32 small square tiles. Tile `(i, j)` covers the pattern cell
/// `[−1.6 + 0.1·i, −1.5 + 0.1·i] × […j…]` grown by 0.03 on every side (neighbours overlap by
/// 0.06) and lies at depth `z = 5 + 0.15·(i + j)`, scaled by `z / 5` so that the tiles line up
/// seen from the cell's centre. Neighbours are close in depth, so seen from any point of the
/// cell they still overlap and the cloud is opaque over the target (the rays of the test check
/// it); but the tiles over the target spread over about 4 units of depth, and a single plane
/// shrinks the Projections of the tiles that far from it by more than their overlap.
/// With `tunnel`, the tiles touching the z axis are left out.
fn cloud(tunnel: bool) -> Vec<Obj> {
    let mut out = Vec::new();
    for i in 0..TILES {
        for j in 0..TILES {
            let z = 5.0 + STEP * (i + j) as f32;
            let s = z / 5.0;
            let x0 = -1.6 + PITCH * i as f32 - GROW;
            let y0 = -1.6 + PITCH * j as f32 - GROW;
            let (x1, y1) = (x0 + PITCH + 2.0 * GROW, y0 + PITCH + 2.0 * GROW);
            if tunnel && x0 < 0.05 && x1 > -0.05 && y0 < 0.05 && y1 > -0.05 {
                continue;
            }
            let p = |x: f32, y: f32| Vec3::new(x * s, y * s, z);
            out.push(quad(
                &format!("leaf{i}_{j}"),
                p(x0, y0),
                p(x1, y0),
                p(x1, y1),
                p(x0, y1),
            ));
        }
    }
    out.push(cube(
        TARGET,
        [-1.0, -1.0, TARGET_Z],
        [1.0, 1.0, TARGET_Z + 0.5],
    ));
    out
}

fn target_visible(objects: &[Obj], cell: Aabb, settings: &BakeSettings) -> bool {
    let scene = Scene::from_objects(Path::new("cloud"), objects.to_vec());
    let r = bake(&scene, &[cell], settings, &CpuBackend::new(), None).unwrap();
    let t = scene.objects.iter().position(|o| o.name == TARGET).unwrap() as u32;
    r.cells[0].visible.contains(&t)
}

/// Separate planes, or the sweep with planes dense enough for the cloud: its tiles overlap by
/// 0.06 and a slab `d` thick at distance ~5 shrinks the Projections of the tiles in it by about
/// `0.5·d/5` per side, so slabs must stay well under 0.3 thick (64 geometric planes between one
/// cell depth and 16 units are 0.2 apart at 5; the default 24 are 0.6 apart and do not fuse it).
fn sweep(on: bool) -> BakeSettings {
    let d = BakeSettings::default();
    BakeSettings {
        sweep: if on {
            SweepChoice::On
        } else {
            SweepChoice::Off
        },
        sweep_settings: umbrasweep::project::planes::SweepSettings {
            planes: 64,
            ..d.sweep_settings
        },
        ..d
    }
}

/// The first object hit by the ray from `a` towards `b`.
fn hit(objects: &[Obj], a: Vec3, b: Vec3) -> Option<String> {
    common::first_hit(
        objects.iter().map(|(n, t, _)| (n.as_str(), t.as_slice())),
        a,
        b - a,
    )
    .map(str::to_string)
}

#[test]
fn a_cloud_hides_only_through_fusion_across_planes() {
    let objects = cloud(false);
    let cell = unit_cell();
    // Ground truth: rays from the cell (corners included) to the target all stop in the cloud.
    let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
    for k in 0..3000 {
        let a = if k < 8 {
            Vec3::new(
                if k & 1 == 0 { -0.5 } else { 0.5 },
                if k & 2 == 0 { -0.5 } else { 0.5 },
                if k & 4 == 0 { -0.5 } else { 0.5 },
            )
        } else {
            Vec3::new(
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
            )
        };
        let b = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            TARGET_Z,
        );
        let h = hit(&objects, a, b).expect("the ray reaches the target at least");
        assert!(
            h.starts_with("leaf"),
            "ray {a} → {b} reaches {h}: the cloud leaks"
        );
    }
    // No single plane holds the fusion; the sweep carries it from layer to layer.
    assert!(
        target_visible(&objects, cell, &sweep(false)),
        "separate planes hid the target: the scene no longer tests fusion across planes"
    );
    assert!(
        !target_visible(&objects, cell, &sweep(true)),
        "the sweep did not fuse the cloud"
    );
}

#[test]
fn a_tunnel_through_the_cloud_keeps_the_target_visible() {
    let objects = cloud(true);
    let seen = hit(&objects, Vec3::ZERO, Vec3::new(0.0, 0.0, TARGET_Z));
    assert_eq!(seen.as_deref(), Some(TARGET), "the tunnel is not straight");
    for on in [false, true] {
        assert!(
            target_visible(&objects, unit_cell(), &sweep(on)),
            "sweep {on}: the target seen through the tunnel was culled"
        );
    }
    // Also from a cell the tunnel is seen from one corner only.
    let corner = Aabb::new(Vec3::new(0.05, 0.05, -1.0), Vec3::new(1.05, 1.05, 0.0));
    assert_eq!(
        hit(
            &objects,
            Vec3::new(0.05, 0.05, -1.0),
            Vec3::new(0.05, 0.05, TARGET_Z)
        )
        .as_deref(),
        Some(TARGET)
    );
    assert!(target_visible(&objects, corner, &sweep(true)));
}

#[test]
fn sub_cells_give_the_union_of_their_pvs() {
    // A wall with a hole: the target behind is seen through the hole only from the cell's
    // left half. Sub-cells: each half alone; the union keeps the target.
    let cell = Aabb::new(Vec3::new(-2.0, -0.5, -0.5), Vec3::new(2.0, 0.5, 0.5));
    let mut objects = vec![
        cube("left", [-30.0, -30.0, 5.0], [-1.8, 30.0, 5.2]),
        cube("right", [-1.4, -30.0, 5.0], [30.0, 30.0, 5.2]),
        cube(TARGET, [-1.25, -0.2, 15.0], [-0.75, 0.2, 15.5]),
    ];
    objects.push(cube("bottom", [-1.8, -30.0, 5.0], [-1.4, -0.3, 5.2]));
    objects.push(cube("top", [-1.8, 0.3, 5.0], [-1.4, 30.0, 5.2]));
    let seen = hit(
        &objects,
        Vec3::new(-1.9, 0.0, 0.0),
        Vec3::new(-1.0, 0.0, 15.0),
    );
    assert_eq!(seen.as_deref(), Some(TARGET));
    let with = |subcell: Option<f64>| BakeSettings {
        subcell,
        sweep: SweepChoice::Off,
        ..BakeSettings::default()
    };
    assert!(target_visible(&objects, cell, &with(None)));
    assert!(target_visible(&objects, cell, &with(Some(1.0))));
    // The right half alone cannot see it.
    let right = Aabb::new(Vec3::new(0.0, -0.5, -0.5), Vec3::new(2.0, 0.5, 0.5));
    assert!(!target_visible(&objects, right, &with(None)));
    // The split itself: as few sub-cells as fit, tiling the cell exactly.
    let parts = split_cell(&cell, 1.0);
    assert_eq!(parts.len(), 4);
    assert_eq!(parts[0].min, cell.min);
    assert_eq!(parts[3].max, cell.max);
    let volume: f32 = parts
        .iter()
        .map(|p| (p.max - p.min).element_product())
        .sum();
    assert!((volume - 4.0).abs() < 1e-5);
    assert_eq!(split_cell(&cell, 10.0), vec![cell]);
}

#[test]
fn the_sweep_is_chosen_for_small_occluders_only() {
    use umbrasweep::bake::Prepared;
    let cell = unit_cell();
    let cloud_scene = Scene::from_objects(Path::new("cloud"), cloud(false));
    let auto = BakeSettings::default();
    assert_eq!(auto.sweep, SweepChoice::Auto);
    let p = Prepared::new(&cloud_scene, &auto, &[cell]).unwrap();
    assert!(p.sweep, "{}", p.sweep_reason);
    let walls = Scene::from_objects(
        Path::new("walls"),
        vec![
            cube("wall", [-30.0, -30.0, 5.0], [30.0, 30.0, 5.5]),
            cube(TARGET, [-1.0, -1.0, 12.0], [1.0, 1.0, 12.5]),
        ],
    );
    let p = Prepared::new(&walls, &auto, &[cell]).unwrap();
    assert!(!p.sweep, "{}", p.sweep_reason);
    // Seen from a tiny cell (almost a point) the same squares are large: no sweep.
    let tiny = Aabb::new(Vec3::splat(-0.01), Vec3::splat(0.01));
    let p = Prepared::new(&cloud_scene, &auto, &[tiny]).unwrap();
    assert!(!p.sweep, "{}", p.sweep_reason);
}

#[test]
fn a_wall_filling_the_frame_ends_the_sweep_and_hides_what_is_far_behind() {
    // Far beyond the distance up to which a sweep plane tests boxes before the last plane
    // (16 plane distances): the plane whose umbra fills its frame must test everything.
    let objects = vec![
        cube("wall", [-200.0, -200.0, 5.0], [200.0, 200.0, 5.5]),
        cube(TARGET, [-1.0, -1.0, 150.0], [1.0, 1.0, 151.0]),
    ];
    assert!(!target_visible(&objects, unit_cell(), &sweep(true)));
    // And what is in front of the wall stays visible.
    let mut front = objects.clone();
    front.push(cube("near", [-0.5, -0.5, 3.0], [0.5, 0.5, 3.5]));
    let scene = Scene::from_objects(Path::new("wall"), front);
    let r = bake(
        &scene,
        &[unit_cell()],
        &sweep(true),
        &CpuBackend::new(),
        None,
    )
    .unwrap();
    let names: Vec<&str> = r.cells[0]
        .visible
        .iter()
        .map(|&o| scene.objects[o as usize].name.as_str())
        .collect();
    assert_eq!(names, ["wall", "near"]);
}

/// A flat layer of leaves around the cell (a forest's band of crowns, 3 units tall and 120
/// wide): the planes beside the cell are cut to the layer's height, and their Depth Maps are
/// stretched to the rectangles' shape — wide and short, pixels within 2× of square in world
/// units, `resolution²` of them — unless `max_stretch` is 1, which keeps every map square.
#[test]
fn flat_layers_get_wide_maps_with_about_square_pixels() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
    let mut objects = Vec::new();
    for k in 0..3000 {
        let (x, z) = (rng.random_range(-60.0..60.0), rng.random_range(-60.0..60.0));
        if f32::hypot(x, z) < 3.0 {
            continue;
        }
        let y = rng.random_range(-1.0..1.5f32);
        let p = |dx: f32, dy: f32| Vec3::new(x + dx, y + dy, z);
        objects.push(quad(
            &format!("leaf{k}"),
            p(-0.4, -0.4),
            p(0.4, -0.4),
            p(0.4, 0.4),
            p(-0.4, 0.4),
        ));
    }
    let scene = Scene::from_objects(Path::new("layer"), objects);
    for max_stretch in [8, 1] {
        let frames = std::sync::Mutex::new(Vec::new());
        let observe = |_: usize,
                       _: usize,
                       job: &umbrasweep::plane::PlaneJob,
                       map: &umbrasweep::plane::DepthMap,
                       _: &umbrasweep::hdm::Hdm| {
            assert_eq!((map.width, map.height), (job.frame.width, job.frame.height));
            frames.lock().unwrap().push(job.frame.clone());
        };
        let settings = BakeSettings {
            max_stretch,
            ..sweep(true)
        };
        common::bake_unit_cell_observed(&scene, &settings, &observe);
        let frames = frames.into_inner().unwrap();
        let res = settings.resolution as usize;
        // Planes beside the cell (normal x or z) 10 to 40 units away, well inside the layer:
        // the rectangle stops at the layer's height (lines from the cell to it, cut at the
        // slab's start).
        let beside: Vec<_> = frames
            .iter()
            .filter(|f| f.axis != 1 && (10.0..40.0).contains(&(f.position - f.face()).abs()))
            .collect();
        assert!(beside.len() > 20, "{}", beside.len());
        for f in &frames {
            assert_eq!(f.pixels(), res * res, "the pixel budget");
        }
        let mut stretched = 0;
        for f in beside {
            let extent = f.rect_max - f.rect_min;
            // The layer's height is v for z planes, u for x planes.
            let (tall, wide) = if f.axis == 2 {
                (extent.y, extent.x)
            } else {
                (extent.x, extent.y)
            };
            assert!(
                tall < 12.0 && wide > 4.0 * tall,
                "max stretch {max_stretch}: {f:?}"
            );
            let px = f.pixel_size();
            if max_stretch == 1 {
                assert_eq!(f.width, f.height);
            } else {
                let aspect = px.x / px.y;
                assert!((0.5..=2.0).contains(&aspect), "pixels {px} of {f:?}");
                stretched += usize::from(f.width.max(f.height) >= 4 * res as u32);
            }
        }
        assert!(max_stretch == 1 || stretched > 10, "{stretched}");
    }
}

/// The scene parts' points and each part's range of them, as a bake uploads them.
type PartsTable = (Vec<glam::DVec3>, Vec<(u32, u32)>);

/// A backend that checks the occluder sets' part ids against the table the bake gives it
/// (`upload_occluder_parts`), then renders on the CPU: every occluder that names a part holds
/// that part's points bit for bit, and every job names the table. Where it says it keeps no
/// table (`keeps` false), the bake must give it no spans and its jobs name none.
struct PartsCheck {
    keeps: bool,
    cpu: CpuBackend,
    table: std::sync::Mutex<Option<PartsTable>>,
    /// Occluders that named a part, and those that did not.
    counts: std::sync::Mutex<(usize, usize)>,
}

const PARTS_TABLE: u64 = 7;

impl umbrasweep::backend::RasterBackend for PartsCheck {
    fn name(&self) -> &'static str {
        "parts-check"
    }

    fn render(
        &self,
        jobs: &[umbrasweep::plane::PlaneJob],
    ) -> Result<Vec<umbrasweep::plane::DepthMap>, umbrasweep::backend::BackendError> {
        if !self.keeps {
            assert!(jobs.iter().all(|j| j.occluders.table.is_none()));
            return self.cpu.render(jobs);
        }
        let table = self.table.lock().unwrap();
        let (points, spans) = table.as_ref().expect("the bake gave its parts first");
        let (mut named, mut not) = (0, 0);
        for job in jobs {
            let occ = &job.occluders;
            assert_eq!(occ.table, Some(PARTS_TABLE), "every job names the table");
            assert_eq!(occ.parts.len(), occ.len());
            for k in 0..occ.len() {
                let Some(p) = occ.part(k) else {
                    not += 1;
                    continue;
                };
                named += 1;
                let (a, b) = spans[p as usize];
                let bits = |q: &[glam::DVec3]| -> Vec<[u64; 3]> {
                    q.iter().map(|p| p.to_array().map(f64::to_bits)).collect()
                };
                assert_eq!(
                    bits(occ.get(k)),
                    bits(&points[a as usize..b as usize]),
                    "occluder {k} names part {p}"
                );
            }
        }
        let mut c = self.counts.lock().unwrap();
        c.0 += named;
        c.1 += not;
        self.cpu.render(jobs)
    }

    fn keeps_occluder_parts(&self) -> bool {
        self.keeps
    }

    fn upload_occluder_parts(
        &self,
        points: &[glam::DVec3],
        spans: &[(u32, u32)],
    ) -> Result<Option<u64>, umbrasweep::backend::BackendError> {
        if !self.keeps {
            assert!(
                spans.is_empty(),
                "{} spans listed for no table",
                spans.len()
            );
            return Ok(None);
        }
        *self.table.lock().unwrap() = Some((points.to_vec(), spans.to_vec()));
        Ok(Some(PARTS_TABLE))
    }
}

/// Slanted quads that cross the planes of the unit cell's faces beside it (each is cut at
/// the face for the direction it crosses, and whole for the others), and boxes behind them.
fn slanted_quads() -> Scene {
    let mut objects = Vec::new();
    for a in 0..3 {
        let (u, w) = ((a + 1) % 3, (a + 2) % 3);
        let at = |ta: f32, tu: f32, tw: f32| {
            let mut p = Vec3::ZERO;
            (p[a], p[u], p[w]) = (ta, tu, tw);
            p
        };
        objects.push(quad(
            &format!("slant{a}"),
            at(-1.0, 1.5, -3.0),
            at(-1.0, 1.5, 3.0),
            at(3.0, 2.5, 3.0),
            at(3.0, 2.5, -3.0),
        ));
        let (lo, hi) = (at(4.0, -0.5, -0.5), at(5.0, 0.5, 0.5));
        objects.push(cube(&format!("behind{a}"), lo.into(), hi.into()));
    }
    Scene::from_objects(Path::new("slanted"), objects)
}

/// The occluders a bake projects name the scene part they are, unchanged, so that a backend
/// keeping the parts on its device may send an index instead of the points: on a forest with
/// the sweep (leaves cut where they cross a slab's planes name none) and without it, and on
/// quads crossing the planes of the cell's faces (cut there), some occluders name parts and
/// some do not, and each that does holds exactly that part's points; the PVS is the CPU
/// backend's. A backend that keeps no table is given no spans.
#[test]
fn occluders_name_the_scene_parts_they_hold_unchanged() {
    let forest = umbrasweep::generate::forest(&umbrasweep::generate::ForestOptions {
        trees: 40,
        leaves: 60,
        ..umbrasweep::generate::ForestOptions::coarse()
    })
    .unwrap();
    let scene = forest.to_scene("forest");
    let cells = &forest.cells[..forest.cells.len().min(2)];
    let slanted = slanted_quads();
    let unit = [unit_cell()];
    for (scene, cells, sweep) in [
        (&scene, cells, SweepChoice::On),
        (&scene, cells, SweepChoice::Off),
        (&slanted, &unit[..], SweepChoice::Off),
    ] {
        let settings = BakeSettings {
            resolution: 64,
            sweep,
            ..BakeSettings::default()
        };
        let want = bake(scene, cells, &settings, &CpuBackend::new(), None).unwrap();
        for keeps in [true, false] {
            let check = PartsCheck {
                keeps,
                cpu: CpuBackend::new(),
                table: Default::default(),
                counts: Default::default(),
            };
            let got = bake(scene, cells, &settings, &check, None).unwrap();
            for (g, w) in got.cells.iter().zip(&want.cells) {
                assert_eq!(g.visible, w.visible, "{sweep:?}, keeps {keeps}");
            }
            if keeps {
                let (named, not) = *check.counts.lock().unwrap();
                eprintln!("{sweep:?}: {named} occluders named a part, {not} did not");
                assert!(named > 0 && not > 0, "{sweep:?}: {named} named, {not} not");
            }
        }
    }
}
