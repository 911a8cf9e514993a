//! Ray space factorization (`umbrasweep::rsf`, the culler `bake::rsf`): the cases of issue 17
//! built as scenes (fusion of two buildings' umbrae horizontally, a tall building seen over a
//! low one, an occludee between two occluders, a bridge, slits on a chart seam and inside one
//! pixel), each scaled and offset, on the CPU's charts and (where there is a GPU) the GPU's;
//! a brute-force check of every box it hides against rays from points of the cell (corners,
//! edges, inside) to points of the box; and the culler in a bake.

mod common;

use common::{Lcg, cube};
use glam::{DVec3, Vec3};
use std::sync::OnceLock;
use umbrasweep::backend::cpu::CpuBackend;
use umbrasweep::backend::gpu::GpuBackend;
use umbrasweep::backend::{RasterBackend, RsfOccluder};
use umbrasweep::bake::{self, BakeSettings};
use umbrasweep::geom::{Aabb, DAabb};
use umbrasweep::rsf::{RayCharts, hull_edges};
use umbrasweep::scene::Scene;
use umbrasweep::settings::SweepChoice;

fn dbox(min: [f64; 3], max: [f64; 3]) -> DAabb {
    DAabb {
        min: DVec3::from(min),
        max: DVec3::from(max),
    }
}

/// An occluder of the brute force: a convex polygon or a box solid.
#[derive(Clone, Debug)]
enum Occ {
    Polygon(Vec<DVec3>),
    Solid(DAabb),
}

impl Occ {
    fn map(&self, f: &impl Fn(DVec3) -> DVec3) -> Occ {
        match self {
            Occ::Polygon(p) => Occ::Polygon(p.iter().map(|&q| f(q)).collect()),
            Occ::Solid(b) => Occ::Solid(DAabb {
                min: f(b.min),
                max: f(b.max),
            }),
        }
    }

    fn points(&self) -> Vec<DVec3> {
        match self {
            Occ::Polygon(p) => p.clone(),
            Occ::Solid(b) => b.corners().to_vec(),
        }
    }

    /// True when the open segment a–b meets the occluder.
    fn blocks(&self, a: DVec3, b: DVec3) -> bool {
        match self {
            Occ::Solid(bx) => {
                let d = b - a;
                let (mut t0, mut t1) = (0.0f64, 1.0f64);
                for k in 0..3 {
                    if d[k].abs() < 1e-300 {
                        if a[k] <= bx.min[k] || a[k] >= bx.max[k] {
                            return false;
                        }
                        continue;
                    }
                    let (u, v) = ((bx.min[k] - a[k]) / d[k], (bx.max[k] - a[k]) / d[k]);
                    t0 = t0.max(u.min(v));
                    t1 = t1.min(u.max(v));
                }
                t0 < t1
            }
            Occ::Polygon(p) => {
                let n = (p[1] - p[0]).cross(p[2] - p[0]);
                let (da, db) = (n.dot(a - p[0]), n.dot(b - p[0]));
                if da * db >= 0.0 {
                    return false;
                }
                let x = a + (b - a) * (da / (da - db));
                let k = p.len();
                let mut sign = 0.0;
                for i in 0..k {
                    let s = n.dot((p[(i + 1) % k] - p[i]).cross(x - p[i]));
                    if s == 0.0 || (sign != 0.0 && s * sign < 0.0) {
                        return false;
                    }
                    sign = s;
                }
                true
            }
        }
    }
}

/// A vertical wall polygon from (x0, z0) to (x1, z1), heights `bottom..top`.
fn wall(x0: f64, z0: f64, x1: f64, z1: f64, bottom: f64, top: f64) -> Occ {
    Occ::Polygon(vec![
        DVec3::new(x0, bottom, z0),
        DVec3::new(x1, bottom, z1),
        DVec3::new(x1, top, z1),
        DVec3::new(x0, top, z0),
    ])
}

fn charts(cell: &DAabb, occ: &[Occ], res: u32) -> RayCharts {
    let mut c = RayCharts::new(cell, 1, res);
    for o in occ {
        let pts = o.points();
        let edges = matches!(o, Occ::Solid(_)).then(|| hull_edges(&pts));
        c.insert(&pts, edges.as_deref());
    }
    c
}

/// Points of a box: corners, edge and face midpoints, centre, and random ones.
fn points_of(b: &DAabb, rng: &mut Lcg, random: usize) -> Vec<DVec3> {
    let mut out = Vec::new();
    for i in 0..27 {
        let f = |k: usize| match (i / 3usize.pow(k as u32)) % 3 {
            0 => b.min[k],
            1 => 0.5 * (b.min[k] + b.max[k]),
            _ => b.max[k],
        };
        out.push(DVec3::new(f(0), f(1), f(2)));
    }
    for _ in 0..random {
        out.push(DVec3::new(
            rng.range(b.min.x, b.max.x),
            rng.range(b.min.y, b.max.y),
            rng.range(b.min.z, b.max.z),
        ));
    }
    out
}

/// A segment from a cell point to a box point that no occluder blocks, if one is found.
fn open_ray(
    cell: &DAabb,
    target: &DAabb,
    occ: &[Occ],
    rng: &mut Lcg,
    n: usize,
) -> Option<(DVec3, DVec3)> {
    let eyes = points_of(cell, rng, n);
    let pts = points_of(target, rng, n);
    for &e in &eyes {
        for &q in &pts {
            if !occ.iter().any(|o| o.blocks(e, q)) {
                return Some((e, q));
            }
        }
    }
    None
}

/// Each case at three scales and offsets: as built, ×1e-3, and +1e5 (z) / +3e4 (x).
/// A named change of coordinates.
type Transform = (&'static str, Box<dyn Fn(DVec3) -> DVec3>);

fn transforms() -> Vec<Transform> {
    vec![
        ("plain", Box::new(|p| p)),
        ("scaled", Box::new(|p| p * 1e-3)),
        ("offset", Box::new(|p| p + DVec3::new(3e4, 0.0, 1e5))),
    ]
}

fn mapped(b: &DAabb, f: &dyn Fn(DVec3) -> DVec3) -> DAabb {
    DAabb {
        min: f(b.min),
        max: f(b.max),
    }
}

/// The street cell of the cases: 4 × 2 × 4, standing 1 above the ground.
fn street_cell() -> DAabb {
    dbox([-2.0, 1.0, -2.0], [2.0, 3.0, 2.0])
}

/// The GPU backend whose charts run on the device, for the cases' second run; `None` (after
/// printing why) without an adapter or `SHADER_F64`, which fails when `CI` is set (CI's
/// lavapipe has both).
fn gpu() -> Option<&'static GpuBackend> {
    static GPU: OnceLock<Option<GpuBackend>> = OnceLock::new();
    GPU.get_or_init(|| {
        let why = match GpuBackend::new() {
            Ok(mut b) => match b.set_rsf_on_gpu(true) {
                Ok(()) => return Some(b),
                Err(_) => format!("{} has no SHADER_F64", b.adapter().unwrap_or_default()),
            },
            Err(e) => e.to_string(),
        };
        assert!(
            std::env::var_os("CI").is_none(),
            "CI must run the ray-space cases on the GPU too: {why}"
        );
        eprintln!("the ray-space cases run on the CPU only: {why}");
        None
    })
    .as_ref()
}

/// `target` hidden or not by the GPU's charts of `occ` (same inserts as [`charts`]), where
/// there is a GPU.
fn gpu_hidden(cell: &DAabb, occ: &[Occ], res: u32, target: &DAabb) -> Option<bool> {
    let b = gpu()?;
    let pts: Vec<Vec<DVec3>> = occ.iter().map(Occ::points).collect();
    let edges: Vec<Option<Vec<(usize, usize)>>> = occ
        .iter()
        .zip(&pts)
        .map(|(o, p)| matches!(o, Occ::Solid(_)).then(|| hull_edges(p)))
        .collect();
    let occluders: Vec<RsfOccluder> = pts
        .iter()
        .zip(&edges)
        .map(|(p, e)| RsfOccluder {
            points: p.as_slice().into(),
            hull_edges: e.as_deref(),
        })
        .collect();
    let mut c = b.rsf_charts(cell, 1, res).unwrap();
    c.insert(&occluders).unwrap();
    let one = [std::ops::Range { start: 0, end: 1 }];
    Some(c.hidden(std::slice::from_ref(target), &one).unwrap()[0])
}

/// Asserts that `target` is hidden (`hidden`) among `occ`, on the CPU's charts and on the
/// GPU's, and, when hidden, that no ray of the brute force passes.
fn check(name: &str, occ: &[Occ], target: DAabb, hidden: bool) {
    for (t, f) in transforms() {
        let cell = mapped(&street_cell(), &f);
        let occ: Vec<Occ> = occ.iter().map(|o| o.map(&f)).collect();
        let target = mapped(&target, &f);
        let c = charts(&cell, &occ, 256);
        let got = c.box_hidden(&target);
        assert_eq!(got, hidden, "{name} ({t}): hidden {got}, expected {hidden}");
        if let Some(g) = gpu_hidden(&cell, &occ, 256, &target) {
            assert_eq!(
                g, hidden,
                "{name} ({t}) on the GPU: hidden {g}, expected {hidden}"
            );
        }
        if got {
            let mut rng = Lcg(3);
            assert_eq!(
                open_ray(&cell, &target, &occ, &mut rng, 20),
                None,
                "{name} ({t})"
            );
        }
    }
}

#[test]
fn two_buildings_side_by_side_at_different_depths_hide_what_neither_hides_alone() {
    // Across the +x side: a low near building covering z < 2, a taller far one z > −2 (lines
    // passing beside the near one's corner toward the target all meet the far one).
    let near = Occ::Solid(dbox([8.0, 0.0, -60.0], [12.0, 8.0, 2.0]));
    let far = Occ::Solid(dbox([20.0, 0.0, -2.0], [26.0, 20.0, 60.0]));
    let target = dbox([60.0, 0.0, -6.0], [64.0, 5.0, 6.0]);
    check("fused", &[near.clone(), far.clone()], target, true);
    check("near alone", std::slice::from_ref(&near), target, false);
    check("far alone", &[far], target, false);
}

#[test]
fn a_tall_building_behind_a_low_one_stays_visible_over_the_top() {
    let low = Occ::Solid(dbox([8.0, 0.0, -80.0], [12.0, 4.0, 80.0]));
    check(
        "tall behind",
        std::slice::from_ref(&low),
        dbox([40.0, 0.0, -3.0], [44.0, 30.0, 3.0]),
        false,
    );
    // Low behind the low one is hidden.
    check(
        "low behind",
        &[low],
        dbox([14.0, 0.0, -3.0], [16.0, 1.5, 3.0]),
        true,
    );
}

#[test]
fn an_object_seen_only_from_the_top_back_corner_over_a_low_wall_stays_visible() {
    // A wall of height 2.6 (below the cell's top, 3) at x = 4: from the front top edge the
    // line over it falls 0.4 in 2, so a box 0.5 tall 30 behind is under it from the front;
    // from the back top corner (x = −2) it falls 0.4 in 6 and a taller box is seen.
    let w = wall(4.0, -200.0, 4.0, 200.0, 0.0, 2.6);
    check(
        "low at 10",
        std::slice::from_ref(&w),
        dbox([10.0, 0.0, -1.0], [11.0, 1.0, 1.0]),
        true,
    );
    check(
        "seen over",
        &[w],
        dbox([10.0, 0.0, -1.0], [11.0, 2.4, 1.0]),
        false,
    );
}

#[test]
fn a_bridge_is_never_a_half_umbra() {
    // A deck from height 1.5 (above the cell's bottom, 1) to 10 across the street.
    let bridge = Occ::Solid(dbox([8.0, 1.5, -100.0], [12.0, 10.0, 100.0]));
    check(
        "bridge",
        &[bridge],
        dbox([30.0, 0.0, -1.0], [31.0, 1.2, 1.0]),
        false,
    );
}

#[test]
fn an_occludee_between_two_occluders_stays_visible() {
    let near = Occ::Solid(dbox([8.0, 0.0, -100.0], [10.0, 2.0, 100.0]));
    let far = Occ::Solid(dbox([40.0, 0.0, -100.0], [42.0, 50.0, 100.0]));
    // Between them and taller than the near wall's umbra: seen over the near wall.
    check(
        "between",
        &[near, far],
        dbox([20.0, 0.0, -1.0], [22.0, 3.0, 1.0]),
        false,
    );
}

#[test]
fn a_slit_inside_one_pixel_and_on_a_chart_seam_stays_open() {
    // Two tall walls across +x with a gap of 1e-3 at z = 0: a target behind the gap.
    let a = Occ::Solid(dbox([10.0, 0.0, -100.0], [11.0, 60.0, -0.0005]));
    let b = Occ::Solid(dbox([10.0, 0.0, 0.0005], [11.0, 60.0, 100.0]));
    check(
        "slit",
        &[a, b],
        dbox([30.0, 0.0, -0.2], [30.5, 1.0, 0.2]),
        false,
    );
    // A slit along the diagonal x = z (a line of slope 1, on the seam of two charts): two
    // walls standing on the diagonal's sides, the target behind the gap on the diagonal.
    let c = wall(10.0, -40.0, 10.0, 9.9995, 0.0, 60.0);
    let d = Occ::Polygon(vec![
        DVec3::new(10.0005, 0.0, 10.0),
        DVec3::new(60.0, 0.0, 10.0),
        DVec3::new(60.0, 60.0, 10.0),
        DVec3::new(10.0005, 60.0, 10.0),
    ]);
    check(
        "diagonal slit",
        &[c, d],
        dbox([20.0, 1.0, 20.0], [20.5, 1.5, 20.5]),
        false,
    );
}

/// A random cell of the brute forces: its footprint around the origin, its bottom above the
/// ground.
fn random_cell(rng: &mut Lcg) -> DAabb {
    dbox(
        [
            -rng.range(0.5, 4.0),
            rng.range(0.2, 2.0),
            -rng.range(0.5, 4.0),
        ],
        [
            rng.range(0.5, 4.0),
            rng.range(2.5, 5.0),
            rng.range(0.5, 4.0),
        ],
    )
}

/// Tests 20 random boxes around `cell` (bottoms from −0.5 to `y_max`) in the charts `c` of
/// `occ` at resolution `res`: every box hidden must be blocked from every point tried
/// ([`open_ray`]), and is passed to `on_hidden`. Returns the boxes tried and those hidden.
#[expect(
    clippy::too_many_arguments,
    reason = "the case's cell, occluders, charts and generator, named in the failure message"
)]
fn check_random_boxes(
    case: usize,
    res: u32,
    cell: &DAabb,
    occ: &[Occ],
    c: &RayCharts,
    rng: &mut Lcg,
    y_max: f64,
    mut on_hidden: impl FnMut(&DAabb),
) -> (usize, usize) {
    let (mut cases, mut hidden) = (0, 0);
    for _ in 0..20 {
        let ang = rng.range(0.0, std::f64::consts::TAU);
        let r = rng.range(6.0, 90.0);
        let (cx, cz) = (r * ang.cos(), r * ang.sin());
        let (hx, hz) = (rng.range(0.05, 3.0), rng.range(0.05, 3.0));
        let y0 = rng.range(-0.5, y_max);
        let t = dbox(
            [cx - hx, y0, cz - hz],
            [cx + hx, y0 + rng.range(0.1, 12.0), cz + hz],
        );
        if cell.overlaps(&t) {
            continue;
        }
        cases += 1;
        if c.box_hidden(&t) {
            hidden += 1;
            on_hidden(&t);
            if let Some((e, q)) = open_ray(cell, &t, occ, rng, 12) {
                panic!(
                    "case {case}: box {t:?} hidden at resolution {res}, but {e} sees {q} \
                     (cell {cell:?}, occluders {occ:?})"
                );
            }
        }
    }
    (cases, hidden)
}

#[test]
fn a_facade_in_two_stacked_parts_fuses_and_one_with_a_gap_stays_open() {
    // A block across +x: its front wall's lower part stands on the ground at x = 8 up to 1.5
    // (the cell spans heights 1 … 3), its upper part is set back half a unit (x = 8.5) and
    // floats from 1.2 to 20, below the line from the cell's front top edge over the lower
    // part (3 − X/4: 1.375 at X = 6.5). Behind them, a box the lower part alone cannot hide.
    let lower = wall(8.0, -100.0, 8.0, 100.0, 0.0, 1.5);
    let target = dbox([14.0, 0.0, -1.0], [15.0, 2.0, 1.0]);
    check(
        "lower part alone",
        std::slice::from_ref(&lower),
        target,
        false,
    );
    let upper = wall(8.5, -100.0, 8.5, 100.0, 1.2, 20.0);
    check("stacked facade", &[lower.clone(), upper], target, true);
    // The upper part starting at 1.6 leaves a slit above that line, through which the cell's
    // top edge sees down over the lower part to the ground at x = 14: the box stays visible.
    let gapped = wall(8.5, -100.0, 8.5, 100.0, 1.6, 20.0);
    check("slit between the parts", &[lower, gapped], target, false);
}

#[test]
fn brute_force_stacked_and_floating_walls() {
    // Walls in two parts, the upper one floating from a little below to a little above the
    // lower one's top, sometimes set back or forward, and inserted after it: fusion of the
    // floating parts onto the lower ones' umbrae, and the slits it must leave open.
    let mut rng = Lcg(29);
    let (mut hidden, mut cases, mut fused) = (0, 0, 0);
    for case in 0..240 {
        let cell = random_cell(&mut rng);
        let (mut lower, mut upper) = (Vec::new(), Vec::new());
        for _ in 0..(2 + case % 5) {
            let ang = rng.range(0.0, std::f64::consts::TAU);
            let r = rng.range(5.0, 30.0);
            let (cx, cz) = (r * ang.cos(), r * ang.sin());
            let len = rng.range(4.0, 60.0);
            let dir = rng.range(0.0, std::f64::consts::TAU);
            let (dx, dz) = (0.5 * len * dir.cos(), 0.5 * len * dir.sin());
            let split = rng.range(0.3, 4.0);
            lower.push(wall(cx - dx, cz - dz, cx + dx, cz + dz, -0.5, split));
            // Overlapping, touching or leaving a slit; set back by up to a unit either way.
            let gap = [0.0, -0.2, 0.05, rng.range(-0.5, 0.5)][case % 4];
            let back = if rng.unit() < 0.5 {
                0.0
            } else {
                rng.range(-1.0, 1.0)
            };
            let (nx, nz) = (cx.signum() * back, cz.signum() * back);
            upper.push(wall(
                cx - dx + nx,
                cz - dz + nz,
                cx + dx + nx,
                cz + dz + nz,
                split + gap,
                split + gap + rng.range(0.5, 30.0),
            ));
        }
        let res = [16, 64, 256][case % 3];
        let alone = charts(&cell, &lower, res);
        let occ: Vec<Occ> = lower.into_iter().chain(upper).collect();
        let c = charts(&cell, &occ, res);
        let (tried, found) = check_random_boxes(case, res, &cell, &occ, &c, &mut rng, 3.0, |t| {
            fused += usize::from(!alone.box_hidden(t));
        });
        cases += tried;
        hidden += found;
    }
    // Boxes hidden only thanks to the floating parts: the fusion is exercised.
    assert!(
        fused >= 20 && hidden > cases / 40,
        "{hidden} of {cases} boxes hidden, {fused} only with the floating parts"
    );
}

#[test]
fn brute_force_every_hidden_box_is_blocked_from_every_point_tried() {
    let mut rng = Lcg(11);
    let (mut hidden, mut cases) = (0, 0);
    for case in 0..300 {
        let cell = random_cell(&mut rng);
        let mut occ = Vec::new();
        for _ in 0..(2 + case % 6) {
            // Walls at random angles, standing on the ground (sometimes not), and boxes.
            let ang = rng.range(0.0, std::f64::consts::TAU);
            let r = rng.range(5.0, 40.0);
            let (cx, cz) = (r * ang.cos(), r * ang.sin());
            let len = rng.range(2.0, 60.0);
            let dir = rng.range(0.0, std::f64::consts::TAU);
            let (dx, dz) = (0.5 * len * dir.cos(), 0.5 * len * dir.sin());
            let bottom = if rng.unit() < 0.8 {
                -rng.range(0.0, 1.0)
            } else {
                rng.range(0.0, 3.0)
            };
            let top = bottom + rng.range(0.5, 30.0);
            if rng.unit() < 0.6 {
                occ.push(wall(cx - dx, cz - dz, cx + dx, cz + dz, bottom, top));
            } else {
                let h = rng.range(1.0, 10.0);
                occ.push(Occ::Solid(dbox(
                    [cx - h, bottom, cz - h],
                    [cx + h, top, cz + h],
                )));
            }
        }
        let res = [16, 64, 256][case % 3];
        let c = charts(&cell, &occ, res);
        let (tried, found) = check_random_boxes(case, res, &cell, &occ, &c, &mut rng, 2.0, |_| {});
        cases += tried;
        hidden += found;
    }
    // The check must have something to check.
    assert!(hidden > cases / 20, "{hidden} of {cases} boxes hidden");
}

/// A street in a bake: the culler runs first (it is in the accounting), hides the box behind
/// the block of houses and keeps the one down the street.
#[test]
fn the_culler_runs_first_in_a_bake_and_hides_behind_a_block() {
    let objs = vec![
        cube("block", [8.0, 0.0, -30.0], [14.0, 12.0, 30.0]),
        cube("behind", [30.0, 0.0, -2.0], [33.0, 6.0, 2.0]),
        cube("down the street", [-2.0, 0.0, 60.0], [2.0, 3.0, 62.0]),
    ];
    let s = Scene::from_objects(std::path::Path::new("street"), objs);
    let cell = Aabb::new(Vec3::new(-2.0, 1.0, -2.0), Vec3::new(2.0, 3.0, 2.0));
    let settings = BakeSettings {
        rsf: SweepChoice::On,
        ..BakeSettings::default()
    };
    let r = bake::bake(&s, &[cell], &settings, &CpuBackend::new(), None).unwrap();
    assert_eq!(r.cullers[0], "ray_space_factorization");
    let v = &r.cells[0].visible;
    assert!(!v.contains(&1), "behind the block: {v:?}");
    assert!(v.contains(&2), "down the street: {v:?}");
    let stats = &r.cells[0].cullers[0];
    assert!(stats.hidden >= 1, "{stats:?}");
    // The automatic rule picks it for boxes (upright solids).
    let auto = bake::bake(
        &s,
        &[cell],
        &BakeSettings::default(),
        &CpuBackend::new(),
        None,
    )
    .unwrap();
    assert!(auto.rsf, "{}", auto.rsf_reason);
}
