//! The sampler's GPU hemicube (`backend::gpu::sampler::GpuSampler`) against the CPU's
//! `sampler::Hemicube` (this file owns `tests/gpu_sampler.rs`).
//!
//! Random foliage (leaves 0.3–40 pixels across, so that whole pixels, sub-pixel masks and
//! fusion all matter), sometimes a slanted ground (per-pixel plane depths), rendered from a
//! ball or a face rectangle with depth-bounded shrinks, sub-pixel masks on and off. The GPU
//! must hide every box the CPU hides (it keeps every sub-pixel's depth where the CPU merges
//! layers past eight), and every box only the GPU hides must pass a brute-force check: random
//! segments from the ball (or rectangle) to the box's outer part all cross a leaf.
//!
//! Without an adapter these tests print why and pass, except in CI (`CI` set), where they fail.
#![cfg(feature = "bake")]

mod common;

use glam::{DVec3, Vec3};
use std::sync::OnceLock;
use umbrasweep::backend::BackendError;
use umbrasweep::backend::RasterBackend;
use umbrasweep::backend::cpu::CpuBackend;
use umbrasweep::backend::gpu::GpuBackend;
use umbrasweep::backend::gpu::sampler::{
    GpuSampler, GpuSamplerScene, SamplerFill, TRIANGLE_BYTES, UPLOAD_CHUNK,
};
use umbrasweep::bake::{
    BakeSettings, CullState, Culler, CullerWork, Prepared, SamplingCuller, SweepChoice,
};
use umbrasweep::geom::DAabb;
use umbrasweep::sampler::{BoxTest, Hemicube, SampleOccluders};
use umbrasweep::settings::SamplingSettings;

/// The shared backend, or `None` (after printing why) when there is no adapter outside CI.
fn backend() -> Option<&'static GpuBackend> {
    static BACKEND: OnceLock<Option<GpuBackend>> = OnceLock::new();
    BACKEND
        .get_or_init(|| match GpuBackend::new() {
            Ok(b) => Some(b),
            Err(BackendError::NoAdapter(why)) => common::no_adapter(&why),
            Err(e) => panic!("GPU backend failed to start: {e}"),
        })
        .as_ref()
}

/// splitmix64.
struct Rng(u64);

impl Rng {
    fn f(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn u(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.f()
    }
    fn unit(&mut self) -> DVec3 {
        loop {
            let p = DVec3::new(self.u(-1.0, 1.0), self.u(-1.0, 1.0), self.u(-1.0, 1.0));
            let l = p.length();
            if l > 1e-3 && l <= 1.0 {
                return p / l;
            }
        }
    }
}

/// A configuration: the eye on a face (`axis`, `sign`), a ball or a rectangle, leaves, boxes.
struct Config {
    eye: DVec3,
    axis: usize,
    sign: f64,
    eps: f64,
    patch: Option<[f64; 2]>,
    res: u32,
    subpixel: bool,
    polys: Vec<Vec<DVec3>>,
    boxes: Vec<DAabb>,
    /// Occludee triangles, each inside a box.
    tris: Vec<[DVec3; 3]>,
}

/// A direction on the outer side of the face, at least `zmin` along its normal.
fn outward(rng: &mut Rng, axis: usize, sign: f64, zmin: f64) -> DVec3 {
    let mut d = rng.unit();
    d[axis] = sign * d[axis].abs().max(zmin);
    d.normalize()
}

fn config(rng: &mut Rng, res: u32) -> Config {
    let axis = (rng.f() * 3.0) as usize % 3;
    let sign = if rng.f() < 0.5 { 1.0 } else { -1.0 };
    let eye = DVec3::new(rng.u(-50.0, 50.0), rng.u(-50.0, 50.0), rng.u(-50.0, 50.0)).round();
    let eps = rng.u(0.002, 0.05);
    let patch = (rng.f() < 0.4).then(|| {
        let a = rng.u(0.2, 1.0);
        [
            eps / 2f64.sqrt() * a,
            eps / 2f64.sqrt() * (1.0 - a * a).max(0.0).sqrt().max(0.1),
        ]
    });
    let mut polys = Vec::new();
    // Leaves in a shell, dense enough to fuse.
    let leaves = 400 + (rng.f() * 1200.0) as usize;
    let size = rng.u(0.05, 0.4);
    for _ in 0..leaves {
        let d = outward(rng, axis, sign, 0.05);
        let c = eye + d * rng.u(1.0, 5.0);
        let n = rng.unit();
        let (e1, e2) = n.any_orthonormal_pair();
        let s = size * rng.u(0.5, 1.5);
        let t0 = rng.u(0.0, std::f64::consts::TAU);
        polys.push(
            (0..3)
                .map(|k| {
                    let t = t0 + k as f64 * std::f64::consts::TAU / 3.0 + rng.u(-0.4, 0.4);
                    c + (e1 * t.cos() + e2 * t.sin()) * s
                })
                .collect(),
        );
    }
    // Sometimes a slanted ground across the views (deep: per-pixel plane depths).
    if rng.f() < 0.4 {
        let d = outward(rng, axis, sign, 0.3);
        let n = (rng.unit() * 0.3 + d).normalize();
        let c = eye + d * rng.u(3.0, 8.0);
        let (e1, e2) = n.any_orthonormal_pair();
        let s = rng.u(5.0, 30.0);
        polys.push(vec![
            c + (-e1 - e2) * s,
            c + (e1 - e2) * s,
            c + (e1 + e2) * s,
            c + (-e1 + e2) * s,
        ]);
    }
    let boxes: Vec<DAabb> = (0..60)
        .map(|_| {
            let d = outward(rng, axis, sign, 0.05);
            let c = eye + d * rng.u(5.5, 12.0);
            let h = DVec3::new(rng.u(0.01, 0.4), rng.u(0.01, 0.4), rng.u(0.01, 0.4));
            DAabb {
                min: c - h,
                max: c + h,
            }
        })
        .collect();
    let tris = boxes
        .iter()
        .map(|b: &DAabb| {
            std::array::from_fn(|_| {
                DVec3::new(
                    rng.u(b.min.x, b.max.x),
                    rng.u(b.min.y, b.max.y),
                    rng.u(b.min.z, b.max.z),
                )
            })
        })
        .collect();
    Config {
        eye,
        axis,
        sign,
        eps,
        patch,
        res,
        subpixel: rng.f() < 0.8,
        polys,
        boxes,
        tris,
    }
}

/// Whether the segment `a → b` crosses the convex polygon `p` strictly inside (a fan of
/// triangles, Möller–Trumbore with a relative margin).
fn crosses(a: DVec3, b: DVec3, p: &[DVec3]) -> bool {
    let d = b - a;
    (1..p.len() - 1).any(|k| {
        let (v0, v1, v2) = (p[0], p[k], p[k + 1]);
        let (e1, e2) = (v1 - v0, v2 - v0);
        let h = d.cross(e2);
        let det = e1.dot(h);
        if det.abs() < 1e-18 {
            return false;
        }
        let s = a - v0;
        let u = s.dot(h) / det;
        let q = s.cross(e1);
        let v = d.dot(q) / det;
        let t = e2.dot(q) / det;
        let m = 1e-9;
        u > m && v > m && u + v < 1.0 - m && t > m && t < 1.0 - m
    })
}

/// Segments from the ball (or rectangle) to random points of the box's outer part: from the
/// ball's rim across each segment's direction (16 points, where a shrink that is too small
/// first shows) and random points of the ball, or from the rectangle's corners, edge midpoints
/// and random points. The first one that no polygon blocks, if any.
fn unblocked(rng: &mut Rng, cfg: &Config, bx: &DAabb) -> Option<(DVec3, DVec3)> {
    let (a, s) = (cfg.axis, cfg.sign);
    let mut lo = bx.min;
    let mut hi = bx.max;
    if s > 0.0 {
        lo[a] = lo[a].max(cfg.eye[a]);
    } else {
        hi[a] = hi[a].min(cfg.eye[a]);
    }
    if lo[a] > hi[a] {
        return None;
    }
    unblocked_to(rng, cfg, |rng| {
        DVec3::new(rng.u(lo.x, hi.x), rng.u(lo.y, hi.y), rng.u(lo.z, hi.z))
    })
}

/// [`unblocked`] for the outer part of a triangle.
fn unblocked_tri(rng: &mut Rng, cfg: &Config, tri: &[DVec3; 3]) -> Option<(DVec3, DVec3)> {
    let (a, s) = (cfg.axis, cfg.sign);
    let outer = |p: DVec3| s * (p[a] - cfg.eye[a]) >= 0.0;
    if !tri.iter().any(|&p| outer(p)) {
        return None;
    }
    unblocked_to(rng, cfg, |rng| {
        loop {
            let (mut x, mut y) = (rng.f(), rng.f());
            if x + y > 1.0 {
                (x, y) = (1.0 - x, 1.0 - y);
            }
            let p = tri[0] + (tri[1] - tri[0]) * x + (tri[2] - tri[0]) * y;
            if outer(p) {
                return p;
            }
        }
    })
}

/// Segments from the ball's rim and inside (or the rectangle's corners, edge midpoints and
/// inside) to 100 points `target` picks: the first one no polygon blocks.
fn unblocked_to(
    rng: &mut Rng,
    cfg: &Config,
    mut target: impl FnMut(&mut Rng) -> DVec3,
) -> Option<(DVec3, DVec3)> {
    let a = cfg.axis;
    let (b_ax, c_ax) = ((a + 1) % 3, (a + 2) % 3);
    let mut from = Vec::new();
    for _ in 0..100 {
        let to = target(rng);
        from.clear();
        match cfg.patch {
            Some([hb, hc]) => {
                for (fb, fc) in [(-1.0, -1.0), (-1.0, 0.0), (-1.0, 1.0), (0.0, -1.0)]
                    .into_iter()
                    .chain([(0.0, 1.0), (1.0, -1.0), (1.0, 0.0), (1.0, 1.0)])
                    .chain((0..4).map(|_| (rng.u(-1.0, 1.0), rng.u(-1.0, 1.0))))
                {
                    let mut p = cfg.eye;
                    p[b_ax] += fb * hb;
                    p[c_ax] += fc * hc;
                    from.push(p);
                }
            }
            None => {
                let (e1, e2) = (to - cfg.eye).normalize().any_orthonormal_pair();
                for k in 0..16 {
                    let t = k as f64 * std::f64::consts::TAU / 16.0;
                    from.push(cfg.eye + (e1 * t.cos() + e2 * t.sin()) * cfg.eps);
                }
                for _ in 0..4 {
                    from.push(cfg.eye + rng.unit() * cfg.eps * rng.f().cbrt());
                }
            }
        }
        for &f in &from {
            if !cfg.polys.iter().any(|p| crosses(f, to, p)) {
                return Some((f, to));
            }
        }
    }
    None
}

/// Per item, (CPU hidden, GPU hidden).
type Pairs = Vec<(bool, bool)>;

/// `cfg` rendered on the GPU with `fill`: the boxes' and the triangles' hidden flags.
fn on_gpu(
    gpu: &GpuBackend,
    cfg: &Config,
    occ: &SampleOccluders,
    fill: SamplerFill,
) -> (Vec<bool>, Vec<bool>) {
    let mut scene = GpuSamplerScene::with_fill(gpu, occ, fill).expect("GPU sampler scene");
    assert_eq!(scene.fill(), fill);
    // The triangles rounded to f32 (as a scene's are) go up as the scene's, in reverse order
    // after a decoy, so that a test by index must find each in its place.
    let tris32: Vec<[DVec3; 3]> = cfg
        .tris
        .iter()
        .map(|t| t.map(|p| p.as_vec3().as_dvec3()))
        .collect();
    let mut resident: Vec<[Vec3; 3]> = vec![[Vec3::splat(1e3); 3]];
    resident.extend(tris32.iter().rev().map(|t| t.map(|p| p.as_vec3())));
    assert!(
        scene
            .upload_triangles(gpu, resident.iter().copied())
            .expect("triangles upload"),
        "a few triangles fit any device"
    );
    assert_eq!(scene.resident_triangles() as usize, resident.len());
    let ids: Vec<u32> = (0..tris32.len() as u32)
        .map(|k| tris32.len() as u32 - k)
        .collect();
    let mut gs = GpuSampler::new(gpu, &scene, cfg.res).expect("GPU sampler");
    gs.hemicube().set_subpixel(cfg.subpixel);
    match cfg.patch {
        None => gs.begin(cfg.eye, cfg.axis, cfg.sign, cfg.eps, &cfg.boxes),
        Some(half) => gs.begin_patch(cfg.eye, cfg.axis, cfg.sign, half, &cfg.boxes),
    }
    let g_boxes = gs.test_boxes(&cfg.boxes).expect("GPU sampler render");
    let g_tris = gs.test_triangles(&cfg.tris).expect("GPU triangle test");
    // By index from the resident triangles, the same answers as with their corners sent.
    let sent = gs.test_triangles(&tris32).expect("GPU triangle test");
    let by_index = gs
        .test_scene_triangles(&ids, &tris32)
        .expect("GPU triangle test by index");
    assert_eq!(
        by_index, sent,
        "resident triangles tested by index differ from the same triangles sent (res {})",
        cfg.res
    );
    (g_boxes, g_tris)
}

/// Renders `cfg` on the CPU and on the GPU: the boxes' and the triangles' answers. The GPU's
/// two fills must leave the same depths, so give the same answers.
fn both(gpu: &GpuBackend, cfg: &Config) -> (Pairs, Pairs) {
    let tagged: Vec<(Vec<DVec3>, u32)> = cfg
        .polys
        .iter()
        .enumerate()
        .map(|(k, p)| (p.clone(), k as u32))
        .collect();
    let occ = SampleOccluders::from_polygons(&tagged);
    // Lavapipe and every Vulkan device have TEXTURE_ATOMIC: the compute fill is the default.
    assert_eq!(GpuSamplerScene::default_fill(gpu), SamplerFill::Compute);
    let (g_boxes, g_tris) = on_gpu(gpu, cfg, &occ, SamplerFill::Compute);
    let (r_boxes, r_tris) = on_gpu(gpu, cfg, &occ, SamplerFill::Render);
    assert_eq!(
        g_boxes, r_boxes,
        "the fills disagree on boxes (res {})",
        cfg.res
    );
    assert_eq!(
        g_tris, r_tris,
        "the fills disagree on triangles (res {})",
        cfg.res
    );
    let mut hc = Hemicube::new(cfg.res);
    hc.set_subpixel(cfg.subpixel);
    match cfg.patch {
        None => hc.begin(cfg.eye, cfg.axis, cfg.sign, cfg.eps, &cfg.boxes),
        Some(half) => hc.begin_patch(cfg.eye, cfg.axis, cfg.sign, half, &cfg.boxes),
    }
    hc.draw(&occ);
    (
        cfg.boxes
            .iter()
            .zip(g_boxes)
            .map(|(b, g)| (hc.test_box(b) == BoxTest::Hidden, g))
            .collect(),
        cfg.tris
            .iter()
            .zip(g_tris)
            .map(|(t, g)| (hc.test_triangle(*t) == BoxTest::Hidden, g))
            .collect(),
    )
}

#[test]
fn the_gpu_and_the_cpu_hide_the_same_boxes_and_only_blocked_ones() {
    let Some(gpu) = backend() else {
        return;
    };
    let mut rng = Rng(0x5eed);
    // Per kind (boxes, triangles): CPU hidden, GPU hidden, tested.
    let mut counts = [[0usize; 3]; 2];
    let (mut missed, mut extra) = (Vec::new(), Vec::new());
    for res in [32u32, 64] {
        for c in 0..12 {
            let cfg = config(&mut rng, res);
            let (boxes, tris) = both(gpu, &cfg);
            for (kind, results) in [boxes, tris].into_iter().enumerate() {
                for (b, (cpu, g)) in results.into_iter().enumerate() {
                    let n = &mut counts[kind];
                    n[0] += usize::from(cpu);
                    n[1] += usize::from(g);
                    n[2] += 1;
                    let what = ["box", "triangle"][kind];
                    if cpu && !g {
                        missed.push(format!("res {res} config {c} {what} {b}"));
                    }
                    if g && !cpu {
                        let seg = if kind == 0 {
                            unblocked(&mut rng, &cfg, &cfg.boxes[b])
                        } else {
                            unblocked_tri(&mut rng, &cfg, &cfg.tris[b])
                        };
                        if let Some((from, to)) = seg {
                            panic!(
                                "res {res} config {c}: the GPU hid {what} {b} but the \
                                 segment {from} → {to} crosses no leaf"
                            );
                        }
                        extra.push(format!("res {res} config {c} {what} {b}"));
                    }
                }
            }
        }
    }
    eprintln!("boxes and triangles: [CPU hid, GPU hid, tested] {counts:?}");
    assert!(
        missed.is_empty(),
        "the GPU left open {} the CPU hid: {missed:?}",
        missed.len()
    );
    // Both keep every sub-pixel's nearest depth (the CPU spills layers past eight instead of
    // merging them, which hid less at these low resolutions): the same answers.
    assert!(
        extra.is_empty(),
        "the GPU hid {} the CPU left open: {extra:?}",
        extra.len()
    );
    for (kind, [cpu, _, total]) in counts.into_iter().enumerate() {
        // Not vacuous: the leaves hide a good share (triangles more than their boxes).
        assert!(cpu * 8 > total, "kind {kind}: only {cpu} of {total} hidden");
    }
    assert!(
        counts[1][0] > counts[0][0],
        "triangles hide more than boxes"
    );
}

#[test]
fn an_empty_render_hides_nothing_and_a_wall_hides_what_is_behind_it() {
    let Some(gpu) = backend() else {
        return;
    };
    let behind = DAabb {
        min: DVec3::new(-0.5, -0.5, 8.0),
        max: DVec3::new(0.5, 0.5, 9.0),
    };
    let beside = DAabb {
        min: DVec3::new(6.0, -0.5, 8.0),
        max: DVec3::new(7.0, 0.5, 9.0),
    };
    let boxes = [behind, beside];
    let empty = SampleOccluders::from_polygons(&[]);
    let scene = GpuSamplerScene::new(gpu, &empty).expect("GPU sampler scene");
    let mut gs = GpuSampler::new(gpu, &scene, 32).expect("GPU sampler");
    // Before any `begin` nothing was drawn: every box is open (the CPU's answer too).
    assert_eq!(gs.test_boxes(&boxes).unwrap(), vec![false, false]);
    gs.begin(DVec3::ZERO, 2, 1.0, 0.05, &boxes);
    assert_eq!(gs.test_boxes(&boxes).unwrap(), vec![false, false]);
    assert_eq!(gs.last_draws(), 0);
    let wall = wall();
    let occ = SampleOccluders::from_polygons(&[(wall, 0)]);
    let scene = GpuSamplerScene::new(gpu, &occ).expect("GPU sampler scene");
    let mut gs = GpuSampler::new(gpu, &scene, 32).expect("GPU sampler");
    assert_eq!(gs.gpu_times().passes, 0);
    gs.begin(DVec3::ZERO, 2, 1.0, 0.05, &boxes);
    assert_eq!(gs.test_boxes(&boxes).unwrap(), vec![true, false]);
    assert!(gs.last_draws() >= 1);
    // With timestamps (lavapipe has them) the render's passes are timed: set-up, the compute
    // fill's two, the reduction and the test.
    if gpu.timestamps() {
        let t = gs.gpu_times();
        assert_eq!(t.passes, 5, "{t:?}");
        assert!(t.fill > std::time::Duration::ZERO, "{t:?}");
    }
    // The same box tested twice in one call gets the same answer, and a render can be tested
    // again.
    assert_eq!(
        gs.test_boxes(&[behind, beside, behind]).unwrap(),
        vec![true, false, true]
    );
}

/// Degenerate polygons hide nothing on the device either (the cases of
/// `tests/sampler_proof.rs`' `collinear_polygons_hide_nothing`: three collinear points whose
/// edges took the same side of their one plane, a half-space).
#[test]
fn collinear_polygons_hide_nothing_on_the_gpu() {
    let Some(gpu) = backend() else { return };
    let cases = common::collinear_cases();
    for (k, (eye, axis, eps, res, poly, [min, max])) in cases.into_iter().enumerate() {
        let occ = SampleOccluders::from_polygons(&[(poly.to_vec(), 0)]);
        let scene = GpuSamplerScene::new(gpu, &occ).expect("GPU sampler scene");
        let mut gs = GpuSampler::new(gpu, &scene, res).expect("GPU sampler");
        let bx = DAabb { min, max };
        gs.begin(eye, axis, 1.0, eps, &[bx]);
        assert_eq!(
            gs.test_boxes(&[bx]).expect("GPU sampler render"),
            vec![false],
            "case {k}: a box hidden by a degenerate polygon"
        );
    }
}

/// A backend on the engine's adapter whose largest storage binding is 64 KiB (`None`, after
/// printing why, when there is no adapter outside CI).
fn small_binding_backend() -> Option<GpuBackend> {
    let limits = wgpu::Limits {
        max_storage_buffer_binding_size: 64 << 10,
        ..wgpu::Limits::default()
    };
    let features = GpuBackend::REQUIRED_FEATURES | wgpu::Features::SHADER_F64;
    let (device, queue) = common::engine_device(features, limits)?;
    Some(GpuBackend::with_device(device, queue).expect("a backend on it"))
}

/// A 4 × 4 wall across the z axis at z = 4.
fn wall() -> Vec<DVec3> {
    vec![
        DVec3::new(-2.0, -2.0, 4.0),
        DVec3::new(2.0, -2.0, 4.0),
        DVec3::new(2.0, 2.0, 4.0),
        DVec3::new(-2.0, 2.0, 4.0),
    ]
}

/// Resident triangles are found by index, past the first slice `upload_triangles` stages;
/// triangles that do not fit the device's largest storage binding stay on the CPU
/// (`upload_triangles` says so and keeps none), and tests by index then send corners. The
/// same answers each way: a wall hides a triangle behind it, not one beside it.
#[test]
fn triangles_are_tested_by_index_or_sent_when_too_large_for_a_binding() {
    let (Some(shared), Some(small)) = (backend(), small_binding_backend()) else {
        return;
    };
    let occ = SampleOccluders::from_polygons(&[(wall(), 0)]);
    let behind = [
        Vec3::new(-0.5, -0.5, 8.0),
        Vec3::new(0.5, -0.5, 8.5),
        Vec3::new(0.0, 0.5, 9.0),
    ];
    let beside = behind.map(|p| p + Vec3::new(6.5, 0.0, 0.0));
    let bounds = DAabb {
        min: DVec3::new(-1.0, -1.0, 7.5),
        max: DVec3::new(8.0, 1.0, 9.5),
    };
    let tris = [behind, behind, beside].map(|t| t.map(|p| p.as_dvec3()));
    // 2,000 triangles take 72,000 bytes, more than the 64 KiB binding; 100 fit; the shared
    // backend takes more than one staged slice. Every triangle but two is `beside`, so that
    // one read from a wrong place is open.
    let beyond = (UPLOAD_CHUNK / TRIANGLE_BYTES) as u32 + 1_000;
    let cases = [
        (&small, 2_000, [1_000, 1_999, 3], false),
        (&small, 100, [10, 99, 50], true),
        (shared, beyond as usize + 10, [beyond, 5, beyond + 9], true),
    ];
    for (gpu, n, ids, fits) in cases {
        let mut list = vec![beside; n];
        list[ids[0] as usize] = behind;
        list[ids[1] as usize] = behind;
        let mut scene = GpuSamplerScene::new(gpu, &occ).expect("GPU sampler scene");
        assert_eq!(
            scene.upload_triangles(gpu, list.iter().copied()).unwrap(),
            fits
        );
        let resident = if fits { n } else { 0 };
        assert_eq!(scene.resident_triangles() as usize, resident);
        let mut gs = GpuSampler::new(gpu, &scene, 32).expect("GPU sampler");
        gs.begin(DVec3::ZERO, 2, 1.0, 0.05, &[bounds]);
        assert_eq!(
            gs.test_scene_triangles(&ids, &tris).unwrap(),
            vec![true, true, false],
            "{n} triangles, {ids:?}"
        );
    }
}

/// A small forest and its middle cell.
fn small_forest() -> (umbrasweep::Scene, umbrasweep::geom::Aabb) {
    let generated = umbrasweep::generate::forest(&umbrasweep::generate::ForestOptions {
        trees: 120,
        leaves: 150,
        ..umbrasweep::generate::ForestOptions::coarse()
    })
    .unwrap();
    (
        generated.to_scene("forest.obj"),
        generated.cells[generated.cells.len() / 2],
    )
}

/// The sampler alone on [`small_forest`]'s cell with `backend`: what it hid, and the points
/// it rendered.
fn sample_forest(backend: &dyn RasterBackend) -> (Vec<bool>, u64) {
    let (hidden, work) = sample_forest_work(backend, false);
    (hidden, work.points)
}

/// [`sample_forest`] with the sampler's whole account, with or without the tuck pass (which
/// has no GPU twin: with it the GPU backend samples on the CPU).
fn sample_forest_work(backend: &dyn RasterBackend, tuck: bool) -> (Vec<bool>, CullerWork) {
    let (hidden, work, _) = sample_forest_noted(backend, tuck);
    (hidden, work)
}

/// [`sample_forest_work`] with the culler's note on the bake ([`Culler::note`]).
fn sample_forest_noted(
    backend: &dyn RasterBackend,
    tuck: bool,
) -> (Vec<bool>, CullerWork, Option<String>) {
    let (scene, cell) = small_forest();
    let settings = BakeSettings {
        sampling: SweepChoice::On,
        sampling_settings: SamplingSettings {
            eps: Some(0.12),
            levels: 1,
            resolution: Some(48),
            rays: 0,
            tuck,
            ..SamplingSettings::default()
        },
        ..BakeSettings::default()
    };
    let prepared = Prepared::new(&scene, &settings, &[cell]).unwrap();
    let mut state = CullState {
        hidden: vec![false; scene.objects.len()],
        known_visible: None,
    };
    let culler = SamplingCuller::default();
    let work = culler
        .cull(
            &prepared,
            &cell,
            backend,
            &mut state,
            &mut umbrasweep::bake::NoPlanes,
        )
        .unwrap();
    (state.hidden, work, culler.note())
}

/// With the tuck pass (`--sampling-tuck`), which has no GPU twin, the GPU backend's sampler
/// renders on the CPU's hemicube: nothing is submitted, the account says why, and the answers
/// are the CPU backend's, which hide more than without the pass.
#[test]
fn with_the_tuck_pass_the_gpu_backend_samples_on_the_cpu() {
    // A backend of its own: other tests submit to the shared one meanwhile.
    let gpu = match GpuBackend::new() {
        Ok(b) => b,
        Err(BackendError::NoAdapter(why)) => {
            common::no_adapter::<()>(&why);
            return;
        }
        Err(e) => panic!("GPU backend failed to start: {e}"),
    };
    let gpu = &gpu;
    let before = gpu.total_stats().submissions;
    let (on_gpu, work) = sample_forest_work(gpu, true);
    assert_eq!(
        gpu.total_stats().submissions,
        before,
        "the sampler submitted to the device with the tuck pass on"
    );
    let why = work.cpu_fallback.expect("the account names the tuck pass");
    assert!(why.contains("tuck"), "{why}");
    let (cpu, cpu_work) = sample_forest_work(&CpuBackend::new(), true);
    assert_eq!(cpu_work.cpu_fallback, None);
    assert_eq!(on_gpu, cpu, "the answers must be the CPU backend's");
    assert_eq!(work.points, cpu_work.points);
    let (plain, _) = sample_forest_work(&CpuBackend::new(), false);
    let count = |h: &[bool]| h.iter().filter(|&&h| h).count();
    assert!(
        count(&cpu) > count(&plain),
        "the tuck pass hid {} objects, without it {}",
        count(&cpu),
        count(&plain)
    );
}

/// `bake --sampling --backend gpu` samples on the device: the same objects hidden as on the
/// CPU, from the same points.
#[test]
fn the_sampler_culls_the_same_on_the_gpu_backend() {
    let Some(gpu) = backend() else {
        return;
    };
    assert!(
        gpu.sampler_on_gpu(),
        "lavapipe and the target GPUs have f64"
    );
    let before = gpu.total_stats().submissions;
    let (cpu, cpu_points) = sample_forest(&CpuBackend::new());
    let (on_gpu, gpu_points) = sample_forest(gpu);
    assert!(
        gpu.total_stats().submissions > before,
        "the GPU backend's sampler submitted nothing to the device"
    );
    let n_cpu = cpu.iter().filter(|&&h| h).count();
    let n_gpu = on_gpu.iter().filter(|&&h| h).count();
    eprintln!("hidden: CPU {n_cpu}, GPU {n_gpu}; points {cpu_points}, {gpu_points}");
    assert!(n_cpu > 10, "the test needs something hidden: {n_cpu}");
    let missed: Vec<usize> = (0..cpu.len()).filter(|&o| cpu[o] && !on_gpu[o]).collect();
    assert!(
        missed.is_empty(),
        "the GPU kept objects the CPU hid: {missed:?}"
    );
    // Both keep every sub-pixel's nearest depth: no object hidden by only one of them (the
    // CPU's old merge of its two farthest layers left some open here that the GPU hid).
    let extra: Vec<usize> = (0..cpu.len()).filter(|&o| on_gpu[o] && !cpu[o]).collect();
    assert!(
        extra.is_empty(),
        "the GPU hid objects the CPU left open: {extra:?} (CPU {n_cpu}, GPU {n_gpu})"
    );
    // With room for one sampler at a time (`--gpu-sampler-memory`), four threads' lanes take
    // turns with it: the same objects hidden.
    let mut one = GpuBackend::new().expect("a second device");
    assert_eq!(one.sampler_memory(), umbrasweep::bake::GPU_SAMPLERS_BUDGET);
    one.set_sampler_memory(1);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(4)
        .build()
        .unwrap();
    let (taking_turns, _, note) = pool.install(|| sample_forest_noted(&one, false));
    assert!(
        taking_turns == on_gpu,
        "one sampler at a time hid other objects"
    );
    // The bake's summary says how much device memory the samplers took against the budget.
    let note = note.expect("a note on the GPU samplers");
    assert!(
        note.starts_with("GPU samplers took at most 0.")
            && note.contains("of the 0.00 GiB allowed"),
        "{note}"
    );
    assert_eq!(sample_forest_noted(&CpuBackend::new(), false).2, None);
}

/// Rendering in rounds (`GpuSampler::set_culling`, on by default) sets up only the clusters
/// and polygons that can still lower a pixel a test reads: from points of the small forest's
/// cell faces it hides exactly the boxes one round hides, with fewer draws, some of them after
/// the first round.
#[test]
fn rendering_in_rounds_hides_the_same_boxes_with_fewer_draws() {
    let Some(gpu) = backend() else {
        return;
    };
    let (scene, cell) = small_forest();
    let occ = umbrasweep::project::occluders::prepare_with(
        &scene,
        &vec![true; scene.objects.len()],
        false,
        None,
    );
    let occ = SampleOccluders::new(&scene, &occ, false);
    assert!(
        occ.polys.len() > 64 * 32,
        "the test needs rounds: {}",
        occ.polys.len()
    );
    let gscene = GpuSamplerScene::with_fill(gpu, &occ, SamplerFill::Compute).unwrap();
    let mut one = GpuSampler::new(gpu, &gscene, 64).unwrap();
    one.set_culling(false);
    let mut rounds = GpuSampler::new(gpu, &gscene, 64).unwrap();
    let cell = cell.to_f64();
    let boxes: Vec<DAabb> = scene.objects.iter().map(|o| o.bounds.to_f64()).collect();
    let mut rng = Rng(5);
    let (mut draws_one, mut draws_rounds, mut first, mut hidden) = (0, 0, 0, 0);
    for k in 0..6 {
        let (axis, sign) = (k % 3, if k < 3 { 1.0 } else { -1.0 });
        let mut eye = DVec3::ZERO;
        for a in 0..3 {
            eye[a] = rng.u(cell.min[a], cell.max[a]);
        }
        eye[axis] = if sign > 0.0 {
            cell.max[axis]
        } else {
            cell.min[axis]
        };
        // The objects wholly beyond the face.
        let beyond: Vec<DAabb> = boxes
            .iter()
            .filter(|b| {
                sign * (if sign > 0.0 { b.min[axis] } else { b.max[axis] }) > sign * eye[axis]
            })
            .copied()
            .collect();
        let half = [0.05, 0.05];
        one.begin_patch(eye, axis, sign, half, &beyond);
        rounds.begin_patch(eye, axis, sign, half, &beyond);
        let a = one.test_boxes(&beyond).unwrap();
        let b = rounds.test_boxes(&beyond).unwrap();
        assert_eq!(a, b, "face {k}: rounds changed which boxes are hidden");
        hidden += a.iter().filter(|&&h| h).count();
        draws_one += one.last_draws();
        draws_rounds += rounds.last_draws();
        first += rounds.last_first_round_draws();
        assert_eq!(one.last_first_round_draws(), one.last_draws());
    }
    eprintln!(
        "hidden {hidden}; draws: one round {draws_one}, rounds {draws_rounds} ({first} first)"
    );
    assert!(hidden > 20, "the test needs hidden boxes: {hidden}");
    assert!(
        draws_rounds < draws_one,
        "rounds drew {draws_rounds}, one round {draws_one}"
    );
    assert!(first < draws_rounds, "no draws after the first round");
}

/// A device whose largest storage binding cannot hold the forest's polygon points: the GPU
/// backend's sampler says why and samples on the CPU instead (the same objects hidden as the
/// CPU backend's, from the same points), where it used to end the bake with `BufferTooLarge`.
#[test]
fn a_scene_too_large_for_the_device_is_sampled_on_the_cpu() {
    let Some(small) = small_binding_backend() else {
        return;
    };
    let (scene, cell) = small_forest();
    let settings = BakeSettings {
        sampling: SweepChoice::On,
        ..BakeSettings::default()
    };
    let prepared = Prepared::new(&scene, &settings, &[cell]).unwrap();
    let placed = prepared.sampler_device(&small).expect("a GPU backend");
    assert!(
        placed.starts_with("on the CPU: the occluders'")
            && placed.contains("more than the device's largest (64 KiB)"),
        "{placed}"
    );
    let shared = backend().expect("the engine's adapter is there");
    assert_eq!(
        prepared.sampler_device(shared).as_deref(),
        Some("on the GPU")
    );
    assert_eq!(prepared.sampler_device(&CpuBackend::new()), None);
    let before = small.total_stats().submissions;
    let (on_small, small_points) = sample_forest(&small);
    assert_eq!(
        small.total_stats().submissions,
        before,
        "the sampler submitted work to a device that cannot hold the scene"
    );
    let (cpu, cpu_points) = sample_forest(&CpuBackend::new());
    assert_eq!(small_points, cpu_points);
    assert!(cpu.contains(&true), "the test needs something hidden");
    assert_eq!(on_small, cpu, "the fallback must be the CPU's sampler");
}

/// A device whose textures cannot hold the sampler's maps at the level's resolution (8 × 48
/// pixels and more, against a 256-texel limit): every GPU sampler of the level is replaced by
/// the CPU's hemicube, the account says why, and the objects hidden are the CPU backend's,
/// where `GpuSampler::new`'s `PlaneSize` used to end the bake.
#[test]
fn a_level_the_device_cannot_render_is_sampled_on_the_cpu() {
    let limits = wgpu::Limits {
        max_texture_dimension_2d: 256,
        ..wgpu::Limits::default()
    };
    let features = GpuBackend::REQUIRED_FEATURES | wgpu::Features::SHADER_F64;
    let Some((device, queue)) = common::engine_device(features, limits) else {
        return;
    };
    let small = GpuBackend::with_device(device, queue).expect("a backend on it");
    assert!(
        small.sampler_on_gpu(),
        "the scene fits: only the maps do not"
    );
    let (on_small, work) = sample_forest_work(&small, false);
    let why = work.cpu_fallback.expect("the account names the fallback");
    assert!(
        why.contains("px") && why.contains("256"),
        "the reason names the resolution and the limit: {why}"
    );
    let (cpu, cpu_work) = sample_forest_work(&CpuBackend::new(), false);
    assert_eq!(cpu_work.cpu_fallback, None);
    assert!(cpu.contains(&true), "the test needs something hidden");
    assert_eq!(on_small, cpu, "the fallback must be the CPU's sampler");
    assert_eq!(work.points, cpu_work.points);
}
