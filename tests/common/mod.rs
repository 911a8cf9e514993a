//! Helpers shared by the integration tests: scene objects (closed boxes, quads) for
//! `Scene::from_objects`, the unit cell and a one-cell bake that shows every plane, and a
//! brute-force ray cast that names the first object a ray hits,
//! to prove a visibility claim independently of the validator; a device made the way an engine
//! makes its own, for the GPU tests; the sampler's degenerate-polygon regressions.
#![allow(
    dead_code,
    reason = "each test crate uses its own subset of these helpers, so what is dead differs per crate"
)]

use glam::{DVec3, Vec3};
use umbrasweep::backend::cpu::CpuBackend;
use umbrasweep::backend::gpu::GpuBackend;
use umbrasweep::bake::{BakeResult, BakeSettings, PlaneObserver, bake_observed};
use umbrasweep::geom::{Aabb, box_triangles};
use umbrasweep::scene::Scene;

/// An object as `Scene::from_objects` takes it: name, triangles, opaque.
pub type Obj = (String, Vec<[Vec3; 3]>, bool);

/// A small LCG, so that tests need no random crate: `unit` in [0, 1), `range` in [a, b).
pub struct Lcg(pub u64);

impl Lcg {
    /// The next number in [0, 1).
    pub fn unit(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// The next number in [a, b).
    pub fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.unit()
    }
}

/// `../shared/scenes` when present; otherwise prints why and returns `None`, except in CI
/// (`CI` set), where it fails.
pub fn shared_scenes() -> Option<std::path::PathBuf> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes");
    if dir.is_dir() {
        return Some(dir);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "CI is set but {} is missing",
        dir.display()
    );
    eprintln!("skipping: {} not found", dir.display());
    None
}

/// A closed, outward-facing opaque box.
pub fn cube(name: &str, min: [f32; 3], max: [f32; 3]) -> Obj {
    (
        name.into(),
        box_triangles(Vec3::from(min), Vec3::from(max)),
        true,
    )
}

/// The cube of side 1 around the origin.
pub fn unit_cell() -> Aabb {
    Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5))
}

/// Bakes [`unit_cell`] on the CPU backend, handing every rendered plane to `observe`.
pub fn bake_unit_cell_observed(
    scene: &Scene,
    settings: &BakeSettings,
    observe: PlaneObserver,
) -> BakeResult {
    bake_observed(
        scene,
        &[unit_cell()],
        settings,
        &CpuBackend::new(),
        None,
        Some(observe),
    )
    .unwrap()
}

/// An opaque quad `a b c d` (two triangles).
pub fn quad(name: &str, a: Vec3, b: Vec3, c: Vec3, d: Vec3) -> Obj {
    (name.into(), vec![[a, b, c], [a, c, d]], true)
}

/// Möller–Trumbore: where the ray from `o` along `d` meets triangle `[a, b, c]`, as (the
/// ray parameter, the determinant: negative when the ray enters through the back of a
/// counter-clockwise triangle), or `None` (parallel, or outside the triangle).
pub fn ray_triangle(o: DVec3, d: DVec3, [a, b, c]: [DVec3; 3]) -> Option<(f64, f64)> {
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-300 {
        return None;
    }
    let s = o - a;
    let u = s.dot(p) / det;
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0).then(|| (e2.dot(q) / det, det))
}

/// The name of the first object hit by the ray from `origin` along `dir` (brute force over
/// every triangle, Möller–Trumbore in f64 on the f32 vertices).
pub fn first_hit<'a>(
    objects: impl IntoIterator<Item = (&'a str, &'a [[Vec3; 3]])>,
    origin: Vec3,
    dir: Vec3,
) -> Option<&'a str> {
    let (o, d) = (origin.as_dvec3(), dir.as_dvec3());
    let mut best = (f64::INFINITY, None);
    for (name, tris) in objects {
        for t in tris {
            if let Some((dist, _)) = ray_triangle(o, d, t.map(|p| p.as_dvec3()))
                && dist > 0.0
                && dist < best.0
            {
                best = (dist, Some(name));
            }
        }
    }
    best.1
}

/// Without an adapter: `None` after printing why, or a failure when `CI` is set.
pub fn no_adapter<T>(why: &str) -> Option<T> {
    if std::env::var_os("CI").is_some() {
        panic!("CI is set but the GPU backend found no adapter: {why}");
    }
    eprintln!("skipping the GPU tests: {why}");
    None
}

/// A device created the way an engine creates its own — instance, adapter, device — with
/// `features` and `limits`, or `None` (after printing why) when there is no adapter outside CI.
pub fn engine_device(
    features: wgpu::Features,
    limits: wgpu::Limits,
) -> Option<(wgpu::Device, wgpu::Queue)> {
    // The backends `WGPU_BACKEND` names, as `GpuBackend::new` searches.
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    if desc.backends.is_empty() {
        desc.backends = wgpu::Backends::PRIMARY;
    }
    let instance = wgpu::Instance::new(desc);
    let options = wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        ..Default::default()
    };
    let adapter = match pollster::block_on(instance.request_adapter(&options)) {
        Ok(a) => a,
        Err(e) => return no_adapter(&format!("no adapter for an engine's device: {e}")),
    };
    if !adapter.features().contains(GpuBackend::REQUIRED_FEATURES) {
        let info = adapter.get_info();
        return no_adapter(&format!(
            "the engine's adapter {} ({:?}) lacks {:?}",
            info.name,
            info.backend,
            GpuBackend::REQUIRED_FEATURES
        ));
    }
    let device = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("engine device"),
        required_features: features,
        required_limits: limits,
        ..Default::default()
    }));
    Some(device.expect("the engine's adapter creates a device"))
}

/// One of the sampler's degenerate-polygon regressions: the eye, the face axis (sign +1), ε,
/// the resolution, the polygon (three collinear points, up to rounding) and the box it once
/// reported hidden.
pub type CollinearCase = (DVec3, usize, f64, u32, [DVec3; 3], [DVec3; 2]);

/// The two configurations `tests/sampler_proof.rs` found (its `general` family at 15 times
/// its configurations, 2013 and 2382), each reduced to its one polygon: all its edges share
/// one plane through the eye, and when their sides (taken from the centroid, which lies on
/// it) agreed, the polygon covered a half-space.
pub fn collinear_cases() -> [CollinearCase; 2] {
    [
        (
            DVec3::ZERO,
            2,
            0.17410962533824054,
            128,
            [
                DVec3::new(
                    -0.5266805093231313,
                    0.3538602310320728,
                    0.028887508872654413,
                ),
                DVec3::new(-0.923283336666411, 0.0009737328800148437, 0.876340939313109),
                DVec3::new(-1.3198861640096906, -0.3519127652720431, 1.7237943697535634),
            ],
            [
                DVec3::new(-1.5542766892113709, 0.8862477834275483, 1.7098270685302153),
                DVec3::new(-1.479614685518126, 1.012939867168183, 1.80207016217637),
            ],
        ),
        (
            DVec3::new(0.0, 59.657479928000924, 0.0),
            1,
            0.010693101252246486,
            16,
            [
                DVec3::new(-1.1308753902055357, 62.00704178253288, 2.6108153364893387),
                DVec3::new(-1.4676555351803224, 61.075623968926045, 2.4728298646213718),
                DVec3::new(-1.804435680155109, 60.14420615531921, 2.3348443927534044),
            ],
            [
                DVec3::new(-3.202692535653777, 60.649006431904525, 5.70832291472243),
                DVec3::new(-3.165481365665383, 60.696840963085414, 5.745955726239595),
            ],
        ),
    ]
}
