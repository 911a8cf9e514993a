//! Tests of the wgpu backend: shader validation with naga, and GPU Depth Maps against the CPU
//! reference on analytic jobs (random triangles, quads and boxes on every axis and side,
//! resolutions 16–256, slice rings, occlusion-sweep reprojections, which must match
//! bit for bit), a backend on a device the test creates itself as an engine would
//! (`GpuBackend::with_device`: the same maps as `GpuBackend::new()`'s), plus the adapter
//! handling rule: without an adapter a test prints why and passes, unless the environment
//! variable `CI` is set, where it fails.
//!
//! Timings come from the CLI: `umbrasweep bake … --backend gpu` against `--backend cpu`.
#![cfg(feature = "bake")]

mod common;
use common::{engine_device, no_adapter};

use glam::{DVec2, DVec3, Vec3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use std::path::Path;
use std::sync::{Arc, OnceLock};
use umbrasweep::backend::coverage;
use umbrasweep::backend::cpu::{self, CpuBackend};
use umbrasweep::backend::gpu::{self, GpuBackend, GpuProjection};
use umbrasweep::backend::{BackendError, RasterBackend};
use umbrasweep::bake::{BakeResult, BakeSettings, bake};
use umbrasweep::generate::{self, CityOptions};
use umbrasweep::geom::{Aabb, DAabb};
use umbrasweep::hdm::Hdm;
use umbrasweep::plane::{
    Coverage, DepthMap, NO_PART, NOT_RESIDENT, OccluderSet, PlaneFrame, PlaneJob, PlaneQueries,
    PlaneResult, RectQuery, Reprojection, depth_up,
};
use umbrasweep::project::occludee::box_coverage;
use umbrasweep::scene::Scene;

// ---------------------------------------------------------------------------------------------
// Shaders

#[test]
fn shaders_validate_with_naga() {
    assert!(!gpu::SHADERS.is_empty());
    for &(path, source) in gpu::SHADERS {
        let module = naga::front::wgsl::parse_str(source)
            .unwrap_or_else(|e| panic!("{}", e.emit_to_string_with_path(source, path)));
        // Ray space factorization's charts, the occluders' views, the sampler, the box tests
        // and their shared rounding compute in f64 (`SHADER_F64`); the other passes
        // need nothing beyond the defaults.
        let caps = if [
            "rsf",
            "views",
            "rounding",
            "sampler",
            "sampler_setup",
            "sampler_views",
            "sampler_blend",
            "boxes",
        ]
        .map(|n| format!("shaders/{n}.wgsl"))
        .contains(&path.to_string())
        {
            naga::valid::Capabilities::FLOAT64
        } else if path == "shaders/sampler_fill.wgsl" {
            // The sampler's compute fill: `textureAtomicMin` (`TEXTURE_ATOMIC`).
            naga::valid::Capabilities::FLOAT64 | naga::valid::Capabilities::TEXTURE_ATOMIC
        } else {
            naga::valid::Capabilities::default()
        };
        let mut validator = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), caps);
        if let Err(e) = validator.validate(&module) {
            panic!("{}", e.emit_to_string_with_path(source, path));
        }
        assert!(
            source.lines().next().is_some_and(|l| l.starts_with("//")),
            "{path} starts with a comment saying what the pass does"
        );
    }
}

#[test]
fn shader_files_are_all_listed() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    for entry in std::fs::read_dir(dir).unwrap() {
        let name = entry.unwrap().file_name().into_string().unwrap();
        if name.ends_with(".wgsl") {
            let path = format!("shaders/{name}");
            assert!(
                gpu::SHADERS.iter().any(|(p, _)| *p == path),
                "{path} is not in gpu::SHADERS, so it is not validated"
            );
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Adapter handling

/// The shared backend, or `None` (after printing why) when there is no adapter outside CI.
fn backend() -> Option<&'static GpuBackend> {
    static BACKEND: OnceLock<Option<GpuBackend>> = OnceLock::new();
    BACKEND
        .get_or_init(|| match GpuBackend::new() {
            Ok(mut b) => {
                eprintln!("gpu tests on {}", b.adapter().unwrap_or_default());
                // Ray space factorization's charts on the device, so that the tests compare
                // them with the CPU's (a bake's backend keeps the CPU's by default).
                if b.set_rsf_on_gpu(true).is_err() {
                    assert!(
                        std::env::var_os("CI").is_none(),
                        "CI's adapter must have SHADER_F64"
                    );
                }
                Some(b)
            }
            Err(BackendError::NoAdapter(why)) => no_adapter(&why),
            Err(e) => panic!("GPU backend failed to start: {e}"),
        })
        .as_ref()
}

#[test]
fn backend_reports_its_name_and_adapter() {
    let Some(b) = backend() else { return };
    assert_eq!(b.name(), "gpu");
    let adapter = b.adapter().expect("an adapter name");
    assert!(!adapter.is_empty());
    let info = b.adapter_info();
    assert_eq!(info.name, adapter);
    // A software adapter is never "hardware".
    if info.device_type == wgpu::DeviceType::Cpu {
        // Another, hardware adapter may exist, but then new() would have picked it first.
        assert!(!gpu::hardware_adapter_available());
    }
}

#[test]
fn empty_input_gives_empty_output() {
    let Some(b) = backend() else { return };
    assert!(b.render(&[]).unwrap().is_empty());
}

/// A lost device ends every later call with a device failure (`BackendError::device_failed`),
/// promptly, never a hang.
#[test]
fn device_loss_is_an_error_not_a_hang() {
    if backend().is_none() {
        return;
    }
    let b = GpuBackend::new().expect("a second device");
    let jobs = random_jobs(21, Shape::Triangle, 20, &[64]);
    b.render(&jobs).expect("renders before the loss");
    b.simulate_device_loss();
    let t = std::time::Instant::now();
    match b.render(&jobs) {
        Err(e) if e.device_failed() => eprintln!("after loss: {e}"),
        other => panic!("expected a device error, got {other:?}"),
    }
    assert!(t.elapsed().as_secs() < 10);
}

/// Resolutions the device cannot hold are refused with a message, not a panic.
#[test]
fn oversized_planes_are_refused() {
    let Some(b) = backend() else { return };
    let mut jobs = random_jobs(22, Shape::Triangle, 1, &[16]);
    jobs[0].frame.width = 1 << 20;
    match b.render(&jobs[..1]) {
        Err(e @ BackendError::PlaneSize { width, max, .. }) => {
            assert_eq!(width, 1 << 20);
            assert!(max < width);
            assert!(e.to_string().contains("size"), "{e}");
        }
        other => panic!("expected an error, got {other:?}"),
    }
}

// ---------------------------------------------------------------------------------------------
// An engine's device (`GpuBackend::with_device`)

/// Renders `jobs` on `engine` (a backend on an engine's device) and on [`backend`]'s own
/// device: the maps are identical bit for bit when both run on the same adapter, and within
/// the CPU-agreement contract ([`assert_close_to_the_cpu`]) in any case.
fn assert_same_maps_as_new(engine: &GpuBackend, jobs: &[PlaneJob], what: &str) {
    let Some(own) = backend() else { return };
    let maps = engine.render(jobs).expect("renders on the engine's device");
    let (a, b) = (engine.adapter_info(), own.adapter_info());
    if (&a.name, a.backend) == (&b.name, b.backend) {
        let reference = own
            .render(jobs)
            .expect("renders on the backend's own device");
        assert_eq!(maps.len(), reference.len());
        for (k, (m, r)) in maps.iter().zip(&reference).enumerate() {
            assert_bits_equal(m, r, &format!("{what}, job {k}"));
        }
    } else {
        eprintln!(
            "{what}: the engine's adapter {} is not new()'s {}: CPU contract only",
            a.name, b.name
        );
    }
    assert_close_to_the_cpu(engine, jobs, what);
}

/// Occluders of every shape, slices and reprojections: a bake's kinds of planes.
fn mixed_jobs() -> Vec<PlaneJob> {
    let mut jobs = random_jobs(41, Shape::Triangle, 40, &[16, 64, 256]);
    jobs.extend(random_jobs(42, Shape::Box, 40, &[32, 128]));
    jobs.extend(reprojection_jobs(43, &[32, 128]));
    jobs
}

/// A backend built on a device the test created itself, with WebGPU's default limits (as an
/// engine would), renders the same maps as `GpuBackend::new()`'s, and keeps the CPU contract.
#[test]
fn an_engine_device_renders_the_same_maps_as_new() {
    let Some((device, queue)) =
        engine_device(GpuBackend::REQUIRED_FEATURES, wgpu::Limits::default())
    else {
        return;
    };
    let engine = GpuBackend::with_device(device.clone(), queue).expect("a backend on it");
    assert_eq!(engine.adapter(), Some(device.adapter_info().name));
    assert_eq!(engine.name(), "gpu");
    let jobs = mixed_jobs();
    assert_same_maps_as_new(&engine, &jobs, "engine device");
    let stats = engine.last_stats();
    assert!(stats.reprojections > 0 && stats.gpu_planes > 0, "{stats:?}");
    // Resources are reused: a second call gives the same maps.
    let again = engine.render(&jobs).unwrap();
    let first = engine.render(&jobs).unwrap();
    assert_eq!(again, first);
}

/// Calls from several threads at once (each with a resource pool of its own) give the maps a
/// lone call gives, and so do later calls that reuse the pools; so do they with submissions
/// and polls one thread at a time (`set_serial_polls`).
#[test]
fn concurrent_calls_give_the_same_maps() {
    if backend().is_none() {
        return;
    }
    let b = GpuBackend::new().expect("a device of its own");
    let mut serial = GpuBackend::new().expect("a device of its own");
    serial.set_serial_polls(true);
    let jobs = mixed_jobs();
    let (a, c) = jobs.split_at(jobs.len() / 2);
    let alone = (b.render(a).unwrap(), b.render(c).unwrap());
    for b in [&b, &b, &serial] {
        let both = std::thread::scope(|s| {
            let ta = s.spawn(|| b.render(a).unwrap());
            let tc = s.spawn(|| b.render(c).unwrap());
            (ta.join().unwrap(), tc.join().unwrap())
        });
        assert!(both.0 == alone.0 && both.1 == alone.1);
    }
}

/// Many threads submitting and polling one device at once, with work of very different sizes
/// so that submissions finish while others' polls run, each get the maps a lone call gives.
/// (With blocking polls for one submission and no lock around them, wgpu-core 30's queue-empty
/// assert fires here; the backend's non-blocking polls have nothing to assert on.)
#[test]
fn many_threads_submitting_and_polling_at_once_get_their_own_maps() {
    if backend().is_none() {
        return;
    }
    let b = GpuBackend::new().expect("a device of its own");
    let jobs = mixed_jobs();
    // Work of one plane up to every plane: the first 1, 2, 4, … planes, and single planes.
    let mut sets: Vec<Vec<PlaneJob>> = std::iter::successors(Some(1), |n| Some(n * 2))
        .take_while(|&n| n < jobs.len())
        .chain([jobs.len()])
        .map(|n| jobs[..n].to_vec())
        .collect();
    sets.extend(jobs.iter().step_by(9).map(|j| vec![j.clone()]));
    let alone: Vec<_> = sets.iter().map(|s| b.render(s).unwrap()).collect();
    std::thread::scope(|s| {
        for t in 0..8 {
            let (sets, alone, b) = (&sets, &alone, &b);
            s.spawn(move || {
                for round in 0..3 {
                    for k in 0..sets.len() {
                        let i = (k * 7 + t * 3 + round) % sets.len();
                        assert!(
                            b.render(&sets[i]).unwrap() == alone[i],
                            "thread {t}, round {round}: set {i} differs from its lone call"
                        );
                    }
                }
            });
        }
    });
}

/// Every render pass is timed with the GPU's timestamps when the device has them (the
/// backend's own device takes them wherever the adapter has them, lavapipe included), none on
/// an engine's device that did not ask for them; the counters a benchmark reads follow.
#[test]
fn render_passes_are_timed_when_the_device_has_timestamps() {
    if backend().is_none() {
        return;
    }
    let own = GpuBackend::new().expect("a second device");
    if std::env::var_os("CI").is_some() {
        assert!(own.timestamps(), "lavapipe has TIMESTAMP_QUERY");
    }
    let jobs = mixed_jobs();
    let before = own.counters().expect("the GPU backend keeps counters");
    own.render(&jobs).unwrap();
    let stats = own.last_stats();
    let delta = own.counters().unwrap().since(&before);
    assert!(
        stats.passes > 0 && delta.passes == stats.passes,
        "{stats:?} {delta:?}"
    );
    assert_eq!(delta.bytes_read_back, stats.bytes_read_back);
    if own.timestamps() {
        assert_eq!(stats.timed_passes, stats.passes, "{stats:?}");
        assert!(stats.pass_time > std::time::Duration::ZERO, "{stats:?}");
        assert_eq!(delta.pass_time, Some(stats.pass_time));
    } else {
        assert_eq!(stats.timed_passes, 0);
        assert_eq!(delta.pass_time, None);
    }
    let Some((device, queue)) =
        engine_device(GpuBackend::REQUIRED_FEATURES, wgpu::Limits::default())
    else {
        return;
    };
    let engine = GpuBackend::with_device(device, queue).expect("a backend on it");
    assert!(!engine.timestamps());
    engine.render(&jobs).unwrap();
    assert_eq!(engine.last_stats().timed_passes, 0);
    assert_eq!(engine.counters().unwrap().pass_time, None);
    // Counted views: the views pass is timed too (one per submission).
    let Some(counting) = &counting_backend() else {
        return;
    };
    counting.render(&jobs).unwrap();
    let st = counting.last_stats();
    if counting.timestamps() {
        assert!(st.counted > 0, "{st:?}");
        assert_eq!(st.timed_passes, st.passes + st.submissions, "{st:?}");
        assert!(st.views_time > std::time::Duration::ZERO, "{st:?}");
        assert!(st.pass_time > st.views_time, "{st:?}");
    }
}

/// The bench's rows of the GPU backend say what the device did per cell (passes, bytes up and
/// read back, setup, device and pass times), printed as a second table; the CPU's rows have
/// none.
#[test]
fn the_bench_reports_the_device_per_cell() {
    if backend().is_none() {
        return;
    }
    let bench = umbrasweep::bench::collect(&umbrasweep::bench::BenchOptions {
        quick: true,
        scenes: Some(vec!["boxfield".into()]),
        cells: Some(1),
        gpu_cells: Some(1),
        rays: Some(1000),
        backend: umbrasweep::bench::BenchBackend::All,
        ..Default::default()
    })
    .unwrap();
    let gpu = bench.rows.iter().find(|r| r.backend == "gpu").unwrap();
    let cpu = bench.rows.iter().find(|r| r.backend == "cpu").unwrap();
    assert!(cpu.device.is_none());
    let d = gpu.device.as_ref().expect("the GPU row's device figures");
    assert!(
        d.passes_per_cell > 0.0 && d.kib_down_per_cell > 0.0,
        "{d:?}"
    );
    assert!(
        d.kib_up_per_cell > 0.0 && d.device_ms_per_cell > 0.0,
        "{d:?}"
    );
    // Each plane's map either came back, stayed on the device (sweep planes) or needed no
    // device at all.
    assert!(
        d.maps_down_per_cell + d.maps_kept_per_cell <= d.passes_per_cell,
        "{d:?}"
    );
    let table = bench.table();
    assert!(table.contains("Per cell on the device"), "{table}");
    assert!(table.contains("KiB read back"), "{table}");
    assert!(table.contains("maps read back / kept"), "{table}");
    let json = serde_json::to_value(&bench).unwrap();
    let rows = json["rows"].as_array().unwrap();
    assert!(
        rows.iter()
            .any(|r| r["device"]["kib_down_per_cell"].is_number())
    );
    assert!(rows.iter().any(|r| r.get("device").is_none()));
    // Both rows time each culler of their pipeline.
    for r in rows {
        let cullers = r["culler_ms_per_cell"].as_array().unwrap();
        assert!(!cullers.is_empty(), "{r}");
        assert!(
            cullers
                .iter()
                .all(|c| c["culler"].is_string() && c["median_ms"].is_number()),
            "{r}"
        );
    }
}

/// A generated city of `blocks`² blocks with two street cells, and settings that run ray
/// space factorization.
fn rsf_city(blocks: u32) -> (Scene, Vec<Aabb>, BakeSettings) {
    let city = generate::city(&CityOptions {
        max_cells: Some(2),
        ..CityOptions::with_blocks(blocks, blocks)
    })
    .unwrap();
    let settings = BakeSettings {
        rsf: umbrasweep::bake::SweepChoice::On,
        ..BakeSettings::default()
    };
    (city.to_scene("city"), city.cells, settings)
}

/// A bake of a city on a GPU backend that asks for them (`set_rsf_on_gpu`) runs ray space
/// factorization's charts on the device (lavapipe has `SHADER_F64`): its compute passes and
/// bytes show in the backend's counters, and the bake's culler account says it hid objects,
/// as many as the CPU's.
#[test]
fn a_city_bake_runs_the_charts_on_the_device() {
    if backend().is_none() {
        return;
    }
    let mut b = GpuBackend::new().expect("a second device");
    assert!(!b.rsf_on_gpu(), "the CPU's charts unless asked");
    if b.set_rsf_on_gpu(true).is_err() {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI's adapter must have SHADER_F64"
        );
        return;
    }
    let (scene, cells, settings) = rsf_city(3);
    let before = b.counters().unwrap();
    let g = bake(&scene, &cells, &settings, &b, None).unwrap();
    let after = b.counters().unwrap().since(&before);
    let c = bake(&scene, &cells, &settings, &CpuBackend::new(), None).unwrap();
    let planes: usize = g.cells.iter().map(|c| c.planes).sum();
    assert!(
        after.passes > planes + 4 * g.cells.len(),
        "compute passes beside the {planes} planes: {after:?}"
    );
    assert_eq!(g.cullers[0], "ray_space_factorization");
    for (gc, cc) in g.cells.iter().zip(&c.cells) {
        assert!(gc.cullers[0].hidden > 0, "it hid something");
        assert_eq!(gc.cullers[0].hidden, cc.cullers[0].hidden);
        assert_eq!(gc.cullers[0].work, cc.cullers[0].work);
        assert_eq!(gc.visible, cc.visible);
    }
}

/// On a device whose storage bindings hold only 256 words, a plane's occluders are drawn in
/// several chunks (more draws than passes), with the same maps.
#[test]
fn small_storage_bindings_split_the_draws_and_keep_the_maps() {
    let limits = wgpu::Limits {
        max_storage_buffer_binding_size: 4096,
        ..wgpu::Limits::default()
    };
    let Some((device, queue)) = engine_device(GpuBackend::REQUIRED_FEATURES, limits) else {
        return;
    };
    let engine = GpuBackend::with_device(device, queue).expect("a backend on it");
    let jobs = random_jobs(44, Shape::Box, 200, &[64, 256]);
    assert_same_maps_as_new(&engine, &jobs, "small bindings");
    let stats = engine.last_stats();
    assert!(stats.draws >= 3 * stats.passes, "{stats:?}");
}

/// On a device whose storage bindings hold 64 KiB, a plane whose queries (16 bytes each) or
/// pyramid would not fit (with the submission's others: each is one binding) comes back as
/// its map; the others are answered on the device, as the pyramid answers.
#[test]
fn queries_beyond_a_storage_binding_bring_the_map_back() {
    let limits = wgpu::Limits {
        max_storage_buffer_binding_size: 64 << 10,
        ..wgpu::Limits::default()
    };
    let Some((device, queue)) = engine_device(GpuBackend::REQUIRED_FEATURES, limits) else {
        return;
    };
    let engine = GpuBackend::with_device(device, queue).expect("a backend on it");
    // A 64 × 64 map's pyramid (6,826 floats) fits, two together too; a 256 × 256 one does not.
    let jobs = random_jobs(45, Shape::Quad, 60, &[64, 256]);
    let few = |w: u32| RectQuery {
        rect: [0, 0, w / 2, w / 3],
        depth: 5.0,
    };
    let queries: Vec<Option<PlaneQueries>> = jobs
        .iter()
        .enumerate()
        .map(|(k, j)| {
            let n = if k == 1 { 5000 } else { 100 };
            Some(PlaneQueries::rects(vec![few(j.frame.width); n]))
        })
        .collect();
    let maps = engine.render(&jobs).unwrap();
    let results = engine.render_tested(&jobs, &queries).unwrap();
    let mut answered = 0;
    for (k, ((r, job), map)) in results.iter().zip(&jobs).zip(&maps).enumerate() {
        let may_fit = job.frame.width == 64 && k != 1;
        match r {
            PlaneResult::Answers(a) => {
                assert!(may_fit, "job {k} ({}²) was answered", job.frame.width);
                let want = Hdm::build(map).answer(&few(job.frame.width));
                assert!(a.iter().all(|&x| x == want), "job {k}");
                answered += 1;
            }
            PlaneResult::Map(m) => assert_eq!(m, map, "job {k}"),
            PlaneResult::Kept(_) => panic!("job {k}: kept, though not asked to"),
        }
    }
    assert!(answered >= 2, "{answered} jobs answered on the device");
}

/// A device created without `FLOAT32_BLENDABLE` is refused with a message that says what to
/// request.
#[test]
fn a_device_without_the_required_features_is_refused() {
    let Some((device, queue)) = engine_device(wgpu::Features::empty(), wgpu::Limits::default())
    else {
        return;
    };
    match GpuBackend::with_device(device, queue) {
        Err(e @ BackendError::MissingFeatures { missing }) => {
            assert_eq!(missing, GpuBackend::REQUIRED_FEATURES);
            let msg = e.to_string();
            assert!(msg.contains("FLOAT32_BLENDABLE"), "{msg}");
            assert!(msg.contains("required_features"), "{msg}");
        }
        other => panic!("expected a device error, got {other:?}"),
    }
}

/// The engine's device lost (destroyed through the engine's handle): the backend, which
/// installs no device-lost callback there, still ends the call with a device failure
/// (`BackendError::device_failed`), promptly.
#[test]
fn losing_an_engine_device_is_an_error_not_a_hang() {
    let Some((device, queue)) =
        engine_device(GpuBackend::REQUIRED_FEATURES, wgpu::Limits::default())
    else {
        return;
    };
    let engine = GpuBackend::with_device(device.clone(), queue).expect("a backend on it");
    let jobs = random_jobs(45, Shape::Triangle, 20, &[64]);
    engine.render(&jobs).expect("renders before the loss");
    device.destroy();
    let t = std::time::Instant::now();
    match engine.render(&jobs) {
        Err(e) if e.device_failed() => eprintln!("after loss: {e}"),
        other => panic!("expected a device error, got {other:?}"),
    }
    assert!(t.elapsed().as_secs() < 10);
}

// ---------------------------------------------------------------------------------------------
// Analytic jobs

fn frame(res: u32, axis: usize, positive: bool, cell_half: f64) -> PlaneFrame {
    let s = if positive { 1.0 } else { -1.0 };
    PlaneFrame {
        cell: DAabb {
            min: DVec3::splat(-cell_half),
            max: DVec3::splat(cell_half),
        },
        axis,
        positive,
        position: s * (cell_half + 10.0),
        rect_min: DVec2::new(-9.0, -9.0),
        rect_max: DVec2::new(9.0, 9.0),
        width: res,
        height: res,
    }
}

/// A world point from in-plane `(u, v)` and a distance `d` beyond the cell's face.
fn point(f: &PlaneFrame, u: f64, v: f64, d: f64) -> DVec3 {
    let (ua, va) = f.uv_axes();
    let mut p = DVec3::ZERO;
    p[ua] = u;
    p[va] = v;
    p[f.axis] = f.face() + f.sign() * d;
    p
}

#[derive(Clone, Copy, Debug)]
enum Shape {
    Triangle,
    Quad,
    Box,
}

fn random_occluder(rng: &mut Pcg64, f: &PlaneFrame, shape: Shape) -> Vec<DVec3> {
    let (cu, cv) = (rng.random_range(-9.0..9.0), rng.random_range(-9.0..9.0));
    let d = rng.random_range(1.0..22.0);
    let size: f64 = rng.random_range(0.5..7.0);
    match shape {
        Shape::Triangle => (0..3)
            .map(|_| {
                point(
                    f,
                    cu + rng.random_range(-size..size),
                    cv + rng.random_range(-size..size),
                    d + rng.random_range(-0.9..3.0),
                )
            })
            .collect(),
        Shape::Quad | Shape::Box => {
            // A parallelogram (planar, convex) or a parallelepiped, in random orientation.
            let mut axis = || {
                DVec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-0.3..0.3),
                ) * size
            };
            let (a, b) = (axis(), axis());
            let c = DVec3::new(0.0, 0.0, rng.random_range(0.1..0.9));
            let centre = DVec3::new(cu, cv, d + 1.0);
            let corners: Vec<DVec3> = if matches!(shape, Shape::Quad) {
                vec![
                    centre - a - b,
                    centre + a - b,
                    centre + a + b,
                    centre - a + b,
                ]
            } else {
                (0..8)
                    .map(|k| {
                        let sx = if k & 1 != 0 { 1.0 } else { -1.0 };
                        let sy = if k & 2 != 0 { 1.0 } else { -1.0 };
                        let sz = if k & 4 != 0 { 1.0 } else { -1.0 };
                        centre + a * sx + b * sy + c * sz
                    })
                    .collect()
            };
            corners.iter().map(|q| point(f, q.x, q.y, q.z)).collect()
        }
    }
}

/// Square loop (closed) of half-size `h` around `(cu, cv)`, in world `(u, v)`.
fn square(cu: f64, cv: f64, h: f64, rot: f64) -> Vec<[DVec2; 2]> {
    let c: Vec<DVec2> = (0..4)
        .map(|k| {
            let a = rot + k as f64 * std::f64::consts::FRAC_PI_2;
            DVec2::new(cu, cv) + DVec2::new(a.cos(), a.sin()) * h * std::f64::consts::SQRT_2
        })
        .collect();
    (0..4).map(|k| [c[k], c[(k + 1) % 4]]).collect()
}

/// A polygon ring: outer n-gon and inner n-gon (a hole), both closed loops.
fn ring(cu: f64, cv: f64, r0: f64, r1: f64, n: usize) -> Vec<[DVec2; 2]> {
    let mut segs = Vec::new();
    for r in [r0, r1] {
        let p: Vec<DVec2> = (0..n)
            .map(|k| {
                let a = k as f64 / n as f64 * std::f64::consts::TAU + 0.1;
                DVec2::new(cu + r * a.cos(), cv + r * a.sin())
            })
            .collect();
        segs.extend((0..n).map(|k| [p[k], p[(k + 1) % n]]));
    }
    segs
}

fn occluder_depth(f: &PlaneFrame, pts: &[DVec3]) -> f32 {
    depth_up(
        pts.iter()
            .map(|&p| f.depth(p))
            .fold(f64::NEG_INFINITY, f64::max),
    )
}

/// Disagreements between a GPU map and the CPU reference on one job.
#[derive(Debug, Default, Clone, Copy)]
struct Diff {
    /// Pixels the CPU gives a smaller Depth (the GPU misses a near-tie pixel).
    cpu_only: usize,
    /// Pixels the GPU gives a smaller Depth: each verified to lie inside all 8 views of an
    /// occluder of that Depth by at least the CPU's margin (a CPU-reference miss).
    gpu_only: usize,
    /// Pixels the CPU covers.
    covered: usize,
}

impl std::ops::AddAssign for Diff {
    fn add_assign(&mut self, o: Diff) {
        self.cpu_only += o.cpu_only;
        self.gpu_only += o.gpu_only;
        self.covered += o.covered;
    }
}

/// Compares a GPU map with the CPU reference. Uncovered must be exactly `+inf`. Every pixel
/// where the two differ is checked against the contract itself, per occluder and per view:
/// a pixel only the CPU covers must be within the f32 error band of a view edge of the occluder giving
/// it that Depth, and a pixel the GPU covers with a smaller Depth than the CPU must lie inside
/// all 8 views of an occluder of that Depth by at least the CPU's margin — otherwise the GPU
/// would be less conservative than the contract, and the test fails.
fn compare(job: &PlaneJob, gpu: &DepthMap, cpu_map: &DepthMap) -> Diff {
    let f = &job.frame;
    let (res, rows) = (f.width, f.height);
    assert_eq!((gpu.width, gpu.height), (res, rows));
    assert_eq!(gpu.depth.len(), (res * rows) as usize);
    let mut diff = Diff {
        covered: cpu_map.covered(),
        ..Diff::default()
    };
    let occluders_at = |d: f32| {
        (0..job.occluders.len())
            .map(|o| job.occluders.get(o))
            .filter(move |pts| occluder_depth(f, pts) == d)
    };
    for (k, (&g, &c)) in gpu.depth.iter().zip(&cpu_map.depth).enumerate() {
        let (i, j) = (k as u32 % res, k as u32 / res);
        assert!(!g.is_nan(), "NaN at ({i}, {j})");
        if g.is_infinite() {
            assert_eq!(g, f32::INFINITY, "uncovered is +inf at ({i}, {j})");
        }
        if g < c {
            diff.gpu_only += 1;
            let legit = occluders_at(g)
                .any(|pts| coverage::contract_slack(f, pts, i, j) >= coverage::MARGIN);
            assert!(
                legit,
                "GPU covers ({i}, {j}) at {res}×{rows} with Depth {g} (CPU: {c}) but no occluder of \
                 that Depth covers it (axis {}, positive {})",
                f.axis, f.positive
            );
        } else if c < g {
            diff.cpu_only += 1;
            // The GPU's extra shrink: the CPU's margin plus 2⁻²¹·(extent + 1) px of f32 error.
            let band = 1e-3 + res.max(rows) as f64 / (1u64 << 20) as f64;
            let near = occluders_at(c).any(|pts| coverage::contract_slack(f, pts, i, j) < band);
            assert!(
                near,
                "CPU-only pixel ({i}, {j}) at {res}×{rows} is not on an edge"
            );
        }
    }
    diff
}

fn run_and_compare(b: &GpuBackend, jobs: &[PlaneJob]) -> Diff {
    let gpu_maps = b.render(jobs).expect("GPU render");
    let cpu_maps = CpuBackend::new().render(jobs).unwrap();
    assert_eq!(gpu_maps.len(), jobs.len());
    let mut diff = Diff::default();
    for ((job, g), c) in jobs.iter().zip(&gpu_maps).zip(&cpu_maps) {
        diff += compare(job, g, c);
    }
    diff
}

fn random_jobs(seed: u64, shape: Shape, count: usize, resolutions: &[u32]) -> Vec<PlaneJob> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut jobs = Vec::new();
    for &res in resolutions {
        for axis in 0..3 {
            for positive in [true, false] {
                let f = frame(res, axis, positive, rng.random_range(0.1..1.0));
                let mut occ = OccluderSet::default();
                for _ in 0..count {
                    occ.push(random_occluder(&mut rng, &f, shape));
                }
                jobs.push(PlaneJob {
                    frame: f,
                    occluders: occ,
                    slices: vec![],
                    reproject: Vec::new(),
                });
            }
        }
    }
    jobs
}

fn check_shape(shape: Shape, seed: u64) {
    let Some(b) = backend() else { return };
    let jobs = random_jobs(seed, shape, 60, &[16, 32, 64, 128, 256]);
    assert_eq!(jobs.len(), 30, "a cell's worth of planes in one call");
    assert_close_to_the_cpu(b, &jobs, &format!("{shape:?}"));
}

/// [`run_and_compare`], and the maps cover something with few near-tie pixels.
fn assert_close_to_the_cpu(b: &GpuBackend, jobs: &[PlaneJob], what: &str) {
    let d = run_and_compare(b, jobs);
    eprintln!("{what}: {d:?}");
    assert!(
        d.covered > 10_000,
        "{what}: the scenes cover something ({d:?})"
    );
    assert!(
        d.cpu_only * 100 <= d.covered,
        "{what}: too many near-tie pixels: {d:?}"
    );
}

/// Random quads on maps stretched to 8× wider than tall and 8× taller than wide, in turn.
fn stretched_jobs() -> Vec<PlaneJob> {
    let mut jobs = random_jobs(5, Shape::Quad, 60, &[64, 128]);
    for (k, j) in jobs.iter_mut().enumerate() {
        let res = j.frame.width;
        (j.frame.width, j.frame.height) = if k % 2 == 0 {
            (res * 8, res / 8)
        } else {
            (res / 8, res * 8)
        };
    }
    jobs
}

/// Maps stretched to 8× wider than tall and 8× taller than wide (a bake's planes beside a cell
/// in a forest): the GPU's projection still matches the CPU's.
#[test]
fn stretched_maps_match_the_cpu() {
    let Some(b) = backend() else { return };
    let jobs = stretched_jobs();
    assert_close_to_the_cpu(b, &jobs, "stretched");
}

#[test]
fn random_triangles_match_the_cpu() {
    check_shape(Shape::Triangle, 1);
}

#[test]
fn random_quads_match_the_cpu() {
    check_shape(Shape::Quad, 2);
}

#[test]
fn random_boxes_match_the_cpu() {
    check_shape(Shape::Box, 3);
}

/// Two halves of a square never add up across their diagonal, and overlapping occluders keep
/// the minimum Depth, including negative Depths (occluders between the face and the plane).
#[test]
fn halves_do_not_add_up_and_minimum_depth_wins() {
    let Some(b) = backend() else { return };
    check_halves_and_minimum_depth(b);
}

fn check_halves_and_minimum_depth(b: &GpuBackend) {
    let f = frame(64, 2, true, 0.5);
    let q = |u: f64, v: f64, d: f64| point(&f, u, v, d);
    let mut two = OccluderSet::default();
    two.push([q(-4.0, -4.0, 8.0), q(4.0, -4.0, 8.0), q(4.0, 4.0, 8.0)]);
    two.push([q(-4.0, -4.0, 8.0), q(4.0, 4.0, 8.0), q(-4.0, 4.0, 8.0)]);
    // Far, big, positive Depth and near, small, negative Depth.
    let mut stack = OccluderSet::default();
    stack.push([
        q(-9.0, -9.0, 14.0),
        q(9.0, -9.0, 14.0),
        q(9.0, 9.0, 14.0),
        q(-9.0, 9.0, 14.0),
    ]);
    stack.push([
        q(-3.0, -3.0, 5.0),
        q(3.0, -3.0, 5.0),
        q(3.0, 3.0, 5.0),
        q(-3.0, 3.0, 5.0),
    ]);
    let jobs = [
        PlaneJob {
            frame: f.clone(),
            occluders: two,
            slices: vec![],
            reproject: Vec::new(),
        },
        PlaneJob {
            frame: f.clone(),
            occluders: stack,
            slices: vec![],
            reproject: Vec::new(),
        },
    ];
    let maps = b.render(&jobs).unwrap();
    let diag = (0..64)
        .filter(|&k| maps[0].depth[k * 64 + k].is_finite())
        .count();
    assert_eq!(diag, 0, "no diagonal pixel is covered by either half");
    assert!(maps[0].covered() > 100);
    // Pixel rect ±9 at 64²: 0.28125 per pixel; near views span ±5.5, far views ±6.29.
    assert_eq!(maps[1].depth[32 * 64 + 32], -5.0, "near occluder's Depth");
    assert_eq!(maps[1].depth[10 * 64 + 10], 4.0, "far occluder's Depth");
    assert!(maps[1].depth[5 * 64 + 5].is_infinite(), "outside both");
    run_and_compare(b, &jobs);
}

/// Slice rings and squares on every resolution, half the jobs with occluders too.
fn slice_jobs() -> Vec<PlaneJob> {
    let mut rng = Pcg64::seed_from_u64(7);
    let mut jobs = Vec::new();
    for (n, res) in [16u32, 32, 64, 128, 256].into_iter().enumerate() {
        let f = frame(res, n % 3, n % 2 == 0, 0.5);
        let mut slices = ring(0.5, -0.3, 7.0, 3.0, 5 + n);
        slices.extend(square(-6.0, 6.0, 2.0, 0.3));
        // Some jobs also with occluders (slices and Projections merge by minimum).
        let mut occ = OccluderSet::default();
        if n % 2 == 1 {
            for _ in 0..20 {
                occ.push(random_occluder(&mut rng, &f, Shape::Triangle));
            }
        }
        jobs.push(PlaneJob {
            frame: f,
            occluders: occ,
            slices,
            reproject: Vec::new(),
        });
    }
    jobs
}

#[test]
fn slices_match_the_cpu_exactly() {
    let Some(b) = backend() else { return };
    let jobs = slice_jobs();
    let gpu_maps = b.render(&jobs).unwrap();
    for (job, g) in jobs.iter().zip(&gpu_maps) {
        let c = cpu::render_job(job);
        assert!(c.depth.contains(&0.0), "slices fill something");
        if job.occluders.is_empty() {
            assert_eq!(g, &c, "slice-only maps are identical");
        } else {
            compare(job, g, &c);
        }
    }
}

/// Occludee tests answered on the device (`render_tested`: the maps' pyramids built and the
/// rectangle queries answered in a compute pass, only the answers read back) give exactly
/// what `Hdm::test` gives on the same device's maps: random triangles, maps stretched both
/// ways, slice masks merged on the device, rectangles from one pixel to the whole map, and
/// Depths equal to pixels' (strictly nearer is hidden), just above them, 0 and +inf. A job
/// without queries comes back as its map, and the maps of tested jobs are not read back.
#[test]
fn occludee_tests_on_the_device_match_the_pyramid() {
    let Some(b) = backend() else { return };
    let mut jobs = random_jobs(11, Shape::Triangle, 60, &[16, 64, 256]);
    jobs.extend(stretched_jobs());
    jobs.extend(slice_jobs());
    let maps = b.render(&jobs).unwrap();
    let mut rng = Pcg64::seed_from_u64(12);
    let queries: Vec<Option<PlaneQueries>> = jobs
        .iter()
        .zip(&maps)
        .enumerate()
        .map(|(k, (job, map))| {
            if k % 7 == 3 {
                return None;
            }
            let (w, h) = (job.frame.width, job.frame.height);
            let mut q = vec![RectQuery {
                rect: [0, 0, w - 1, h - 1],
                depth: f32::INFINITY,
            }];
            for _ in 0..400 {
                let (i0, j0) = (rng.random_range(0..w), rng.random_range(0..h));
                let span = [1u32, 2, 3, 8, 40, 300][rng.random_range(0..6usize)];
                let i1 = (i0 + rng.random_range(0..span)).min(w - 1);
                let j1 = (j0 + rng.random_range(0..span)).min(h - 1);
                let px =
                    map.depth[(rng.random_range(j0..=j1) * w + rng.random_range(i0..=i1)) as usize];
                let depth = match rng.random_range(0..5) {
                    0 => px,
                    1 => px.next_up(),
                    2 => 0.0,
                    3 => f32::INFINITY,
                    _ => rng.random_range(0.0f32..20.0),
                };
                q.push(RectQuery {
                    rect: [i0, j0, i1, j1],
                    depth,
                });
            }
            Some(PlaneQueries::rects(q))
        })
        .collect();
    let results = b.render_tested(&jobs, &queries).unwrap();
    let stats = b.last_stats();
    let mut counts = [0usize; 3];
    let mut read_back = 0u64;
    let mut skipped = 0;
    for (k, ((r, q), map)) in results.iter().zip(&queries).zip(&maps).enumerate() {
        match (r, q) {
            (PlaneResult::Map(m), None) => {
                assert_eq!(m, map, "job {k}: an untested job's map");
                read_back += (u64::from(m.width) * 4).next_multiple_of(256) * u64::from(m.height);
            }
            (PlaneResult::Map(m), Some(_)) => {
                // A job with nothing for the device to draw (its map made on the CPU).
                assert_eq!(m, map, "job {k}: a job the device did not draw");
                assert!(
                    m.depth.iter().all(|d| *d == 0.0 || d.is_infinite()),
                    "job {k}"
                );
                skipped += 1;
            }
            (PlaneResult::Answers(a), Some(q)) => {
                assert_eq!(a.len(), q.len(), "job {k}");
                let hdm = Hdm::build(map);
                for (n, (got, q)) in a.iter().zip(&q.rects).enumerate() {
                    assert_eq!(*got, hdm.answer(q), "job {k} query {n}: {q:?}");
                    counts[*got as usize] += 1;
                }
                read_back += 4 * q.len() as u64;
            }
            (r, q) => panic!(
                "job {k}: {} for {} queries",
                match r {
                    PlaneResult::Map(_) => "a map",
                    PlaneResult::Answers(_) => "answers",
                    PlaneResult::Kept(_) => "a kept map",
                },
                q.as_ref().map_or(0, PlaneQueries::len)
            ),
        }
    }
    eprintln!("[hidden, empty, partial]: {counts:?}; {skipped} jobs not drawn");
    assert!(skipped < jobs.len() / 4, "{skipped} jobs not drawn");
    assert!(
        counts.iter().all(|&c| c > 200),
        "every answer is exercised: {counts:?}"
    );
    assert_eq!(
        stats.bytes_read_back, read_back,
        "only the answers of tested jobs come back"
    );
}

/// A random occludee box for box tests on `f`'s plane (kind `kind % 7`): touching the cell,
/// straddling its face, between the face and the plane (where the improved Projections
/// apply), beyond the plane, sticking out of the plane's rectangle, wholly beside it, or
/// starting on the plane with its standard Projection's low `u` side exactly on a pixel
/// boundary (only the rule's outward padding then takes in the pixel before it).
fn random_box(rng: &mut Pcg64, f: &PlaneFrame, kind: u32) -> DAabb {
    let half = (f.cell.max.x - f.cell.min.x) / 2.0;
    if kind % 7 == 6 {
        // Beside the cell on the low `u` side, its near face on the plane (`t = 1` there, so
        // the rectangle's low `u` is the box's own).
        let ps = (f.rect_max.x - f.rect_min.x) / f64::from(f.width);
        let i = rng.random_range(1..(f.width / 4).max(2));
        let u0 = f.rect_min.x + f64::from(i) * ps;
        let v = rng.random_range(-6.0..6.0);
        let a = point(f, u0, v - 0.5, 10.0);
        let b = point(
            f,
            u0 + rng.random_range(0.05..2.0),
            v + 0.5,
            10.0 + rng.random_range(0.1..3.0),
        );
        return DAabb {
            min: a.min(b),
            max: a.max(b),
        };
    }
    // The plane lies 10 beyond the face (`frame`).
    let (d0, depth) = match kind % 7 {
        0 => (
            -half * rng.random_range(0.2..1.8),
            rng.random_range(0.01..1.0),
        ),
        1 => (-rng.random_range(0.01..0.5), rng.random_range(0.6..3.0)),
        2 => (rng.random_range(0.05..8.0), rng.random_range(0.01..1.5)),
        _ => (rng.random_range(0.2..25.0), rng.random_range(0.01..4.0)),
    };
    let (u, v) = match kind % 7 {
        0 => (rng.random_range(-half..half), rng.random_range(-half..half)),
        4 => (rng.random_range(6.0..11.0), rng.random_range(-9.0..9.0)),
        5 => (rng.random_range(-40.0..-20.0), rng.random_range(-9.0..9.0)),
        _ => (rng.random_range(-8.0..8.0), rng.random_range(-8.0..8.0)),
    };
    let size = [0.02, 0.3, 1.0, 4.0][rng.random_range(0..4usize)];
    let (su, sv) = (
        size * rng.random_range(0.2..1.0),
        size * rng.random_range(0.2..1.0),
    );
    let a = point(f, u - su, v - sv, d0);
    let b = point(f, u + su, v + sv, d0 + depth);
    DAabb {
        min: a.min(b),
        max: a.max(b),
    }
}

/// Box tests answered on the device (`PlaneQueries::boxes`: each box's rectangles computed
/// there, in `f64`, from the box and the plane's frame, `shaders/boxes.wgsl`) give exactly what
/// the CPU's rule, `occludee::box_coverage`, gives on the same map: random boxes touching the
/// cell, straddling its face, between the face and the plane, beyond it, sticking out of its
/// rectangle and wholly beside it, on square and stretched maps, with and without the
/// improved Projections, beside a rectangle test whose answer stays the pyramid's, on planes
/// with 600, 37 and no box tests interleaved.
#[test]
fn box_tests_on_the_device_follow_the_cpu_rule() {
    let Some(b) = backend() else { return };
    let mut jobs = random_jobs(21, Shape::Quad, 60, &[16, 64, 256]);
    jobs.extend(stretched_jobs());
    let maps = b.render(&jobs).unwrap();
    let hdms: Vec<Hdm> = maps.iter().map(Hdm::build).collect();
    let mut rng = Pcg64::seed_from_u64(22);
    // [improved][hidden, empty, partial]
    let mut counts = [[0usize; 3]; 2];
    let (mut improved_hid, mut answered) = (0, 0);
    for improved in [false, true] {
        // Planes with many box tests, none (a rectangle test only) and a few, interleaved:
        // the device finds each test's plane from the planes' first tests.
        let queries: Vec<Option<PlaneQueries>> = jobs
            .iter()
            .enumerate()
            .map(|(j, job)| {
                let f = &job.frame;
                let rect = RectQuery {
                    rect: [0, 0, f.width - 1, f.height - 1],
                    depth: f32::INFINITY,
                };
                Some(PlaneQueries {
                    rects: vec![rect],
                    // (Each plane's first box lies wholly beside its rectangle: seen from
                    // another plane's direction it would not be empty.)
                    boxes: (0..[600, 0, 37][j % 3])
                        .map(|k| random_box(&mut rng, f, if k == 0 { 5 } else { k }))
                        .collect(),
                    improved,
                    ..Default::default()
                })
            })
            .collect();
        let results = b.render_tested(&jobs, &queries).unwrap();
        for (k, (r, q)) in results.iter().zip(&queries).enumerate() {
            let q = q.as_ref().unwrap();
            let PlaneResult::Answers(a) = r else {
                // A job with nothing for the device to draw comes back as its map.
                assert!(matches!(r, PlaneResult::Map(m) if *m == maps[k]), "job {k}");
                continue;
            };
            answered += 1;
            assert_eq!(a.len(), q.len(), "job {k}");
            assert_eq!(
                a[0],
                hdms[k].answer(&q.rects[0]),
                "job {k}: the rectangle test"
            );
            let f = &jobs[k].frame;
            for (n, bx) in q.boxes.iter().enumerate() {
                let want = box_coverage(f, bx, improved, |r| hdms[k].answer(r));
                assert_eq!(
                    a[1 + n],
                    want,
                    "job {k} box {n} {bx:?}, improved {improved}"
                );
                counts[usize::from(improved)][want as usize] += 1;
                if want == Coverage::Hidden
                    && box_coverage(f, bx, false, |r| hdms[k].answer(r)) != Coverage::Hidden
                {
                    improved_hid += 1;
                }
            }
        }
    }
    eprintln!(
        "[hidden, empty, partial] without and with the improved Projections: {counts:?}; {improved_hid} hidden only by them; {answered} jobs answered"
    );
    assert!(
        answered >= jobs.len(),
        "{answered} of {} jobs answered twice",
        jobs.len()
    );
    assert!(
        counts.iter().flatten().all(|&c| c > 100),
        "every answer is exercised: {counts:?}"
    );
    assert!(
        improved_hid > 10,
        "the improved Projections hide some boxes: {improved_hid}"
    );
}

/// Boxes kept on the device (`RasterBackend::upload_occludee_boxes`: a query then names a box
/// by its index in the table) are answered as the same boxes sent whole and as the CPU's rule
/// answers them: a shuffled table with decoys, some boxes sent whole beside named ones (some
/// of them named by an index beyond the table), a table replaced (queries naming the old one
/// send their boxes whole), and each box uploaded once: asking again sends only indices.
#[test]
fn resident_boxes_are_answered_as_boxes_sent_whole() {
    if backend().is_none() {
        return;
    }
    let b = GpuBackend::new().expect("a second device");
    let mut jobs = random_jobs(31, Shape::Quad, 24, &[16, 64, 256]);
    jobs.extend(stretched_jobs());
    let maps = b.render(&jobs).unwrap();
    let hdms: Vec<Hdm> = maps.iter().map(Hdm::build).collect();
    let mut rng = Pcg64::seed_from_u64(32);
    let boxes: Vec<Vec<DAabb>> = jobs
        .iter()
        .map(|job| {
            (0..400)
                .map(|k| random_box(&mut rng, &job.frame, k))
                .collect()
        })
        .collect();
    // A table of every box and as many decoys, shuffled: a wrong index reads another box.
    let table = |rng: &mut Pcg64| {
        let mut entries: Vec<(Option<(usize, usize)>, DAabb)> = boxes
            .iter()
            .enumerate()
            .flat_map(|(j, bs)| {
                bs.iter()
                    .enumerate()
                    .map(move |(n, bx)| (Some((j, n)), *bx))
            })
            .collect();
        for job in &jobs {
            for k in 0..400 {
                entries.push((None, random_box(rng, &job.frame, k + 3)));
            }
        }
        for k in (1..entries.len()).rev() {
            entries.swap(k, rng.random_range(0..=k));
        }
        let mut ids = vec![vec![0u32; 400]; jobs.len()];
        for (at, (of, _)) in entries.iter().enumerate() {
            if let Some((j, n)) = of {
                ids[*j][*n] = at as u32;
            }
        }
        let table: Vec<DAabb> = entries.into_iter().map(|(_, bx)| bx).collect();
        (table, ids)
    };
    let queries = |generation: Option<u64>, ids: &[Vec<u32>]| -> Vec<Option<PlaneQueries>> {
        (0..jobs.len())
            .map(|j| {
                Some(PlaneQueries {
                    boxes: boxes[j].clone(),
                    improved: true,
                    table: generation,
                    // Every fifth box is sent whole: named `NOT_RESIDENT`, or by an index
                    // beyond the table.
                    ids: (0..400)
                        .map(|n| match n % 10 {
                            2 => NOT_RESIDENT,
                            7 => 2 * (boxes.len() * 400) as u32 + n as u32,
                            _ => ids[j][n],
                        })
                        .collect(),
                    ..Default::default()
                })
            })
            .collect()
    };
    let uploaded = || b.counters().unwrap().bytes_uploaded;
    let answers = |qs: &[Option<PlaneQueries>]| {
        let before = uploaded();
        let r = b.render_tested(&jobs, qs).unwrap();
        (r, uploaded() - before)
    };
    let (table1, ids1) = table(&mut rng);
    let g1 = b.upload_occludee_boxes(&table1).unwrap();
    assert!(g1.is_some(), "lavapipe keeps the boxes");
    let (whole, whole_bytes) = answers(&queries(None, &ids1));
    let (named, named_bytes) = answers(&queries(g1, &ids1));
    let (again, again_bytes) = answers(&queries(g1, &ids1));
    // A new table: queries naming the first send their boxes whole.
    let (table2, ids2) = table(&mut rng);
    let g2 = b.upload_occludee_boxes(&table2).unwrap();
    assert!(g2.is_some() && g2 != g1, "{g1:?} then {g2:?}");
    let (stale, stale_bytes) = answers(&queries(g1, &ids1));
    let (renamed, _) = answers(&queries(g2, &ids2));
    let mut checked = 0;
    for (j, r) in whole.iter().enumerate() {
        let PlaneResult::Answers(w) = r else { continue };
        for other in [&named, &again, &stale, &renamed] {
            let PlaneResult::Answers(o) = &other[j] else {
                panic!("job {j} answered whole but not named");
            };
            assert_eq!(w, o, "job {j}");
        }
        let f = &jobs[j].frame;
        for (n, bx) in boxes[j].iter().enumerate() {
            assert_eq!(
                w[n],
                box_coverage(f, bx, true, |r| hdms[j].answer(r)),
                "job {j} box {n}"
            );
            checked += 1;
        }
    }
    assert!(checked >= 20 * 400, "{checked} boxes checked");
    eprintln!(
        "bytes up: whole {whole_bytes}, named {named_bytes}, again {again_bytes}, stale {stale_bytes}"
    );
    // Named: 8 bytes a test, and each named box once (48, with its neighbours in the table);
    // asked again, 8 bytes a test.
    let saved = (checked as u64 * 4 / 5) * 48;
    assert!(
        again_bytes + saved <= whole_bytes,
        "asked again: {again_bytes} bytes, whole: {whole_bytes}"
    );
    assert_eq!(stale_bytes, whole_bytes, "a stale table sends boxes whole");
}

/// Threads testing boxes of one resident table at once, each call naming boxes no call named
/// before (so each sends them while other threads submit), get the CPU's answers: a box is
/// never read before its first write lands. (wgpu zeroes a buffer it thinks uninitialised
/// where a submission binds it; that clear could follow another thread's first write of a box
/// in the same submission. A table made mapped, hence initialised, has none: without that,
/// some runs here read zero boxes.)
#[test]
fn resident_boxes_sent_from_many_threads_are_never_read_unwritten() {
    if backend().is_none() {
        return;
    }
    let b = GpuBackend::new().expect("a second device");
    let jobs = random_jobs(41, Shape::Quad, 4, &[32]);
    let maps = b.render(&jobs).unwrap();
    let hdms: Vec<Hdm> = maps.iter().map(Hdm::build).collect();
    const THREADS: usize = 4;
    const CALLS: usize = 100;
    const PER_JOB: usize = 30;
    // Each round a fresh table, every box of it sent by the call that first names it (the
    // race is a matter of timing: one round caught it about every other run).
    let mut rng = Pcg64::seed_from_u64(42);
    let n_jobs = jobs.len();
    let mut wrong = 0;
    for _round in 0..5 {
        // Box `n` of job `j` in call `c` of thread `t` is table entry
        // `((c·jobs + j)·PER_JOB + n)·THREADS + t`: the threads' boxes interleave.
        let mut table = Vec::new();
        for _ in 0..CALLS * n_jobs * PER_JOB {
            for _ in 0..THREADS {
                let j = (table.len() / THREADS / PER_JOB) % n_jobs;
                table.push(random_box(&mut rng, &jobs[j].frame, table.len() as u32));
            }
        }
        let generation = b.upload_occludee_boxes(&table).unwrap();
        assert!(generation.is_some(), "lavapipe keeps the boxes");
        wrong += std::thread::scope::<_, usize>(|s| {
            let handles: Vec<_> = (0..THREADS)
                .map(|t| {
                    let (b, jobs, hdms, table) = (&b, &jobs, &hdms, &table);
                    s.spawn(move || {
                        let mut wrong = 0;
                        for c in 0..CALLS {
                            let at =
                                |j: usize, n: usize| ((c * n_jobs + j) * PER_JOB + n) * THREADS + t;
                            let queries: Vec<Option<PlaneQueries>> = (0..n_jobs)
                                .map(|j| {
                                    Some(PlaneQueries {
                                        boxes: (0..PER_JOB).map(|n| table[at(j, n)]).collect(),
                                        improved: true,
                                        table: generation,
                                        ids: (0..PER_JOB).map(|n| at(j, n) as u32).collect(),
                                        ..Default::default()
                                    })
                                })
                                .collect();
                            let results = b.render_tested(jobs, &queries).unwrap();
                            for (j, r) in results.iter().enumerate() {
                                let PlaneResult::Answers(a) = r else { continue };
                                let f = &jobs[j].frame;
                                for n in 0..PER_JOB {
                                    let want = box_coverage(f, &table[at(j, n)], true, |r| {
                                        hdms[j].answer(r)
                                    });
                                    wrong += usize::from(a[n] != want);
                                }
                            }
                        }
                        wrong
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).sum()
        });
    }
    assert_eq!(
        wrong, 0,
        "{wrong} box tests read a box before it was written"
    );
}

/// Planes without occluders, planes whose occluders are all rejected, and repeated calls
/// (resources reused) all give the CPU's answer.
#[test]
fn empty_planes_and_repeated_calls() {
    let Some(b) = backend() else { return };
    let f = frame(32, 1, false, 0.5);
    let mut behind = OccluderSet::default();
    // A point not beyond the cell's face: rejected by both backends.
    behind.push([
        point(&f, 0.0, 0.0, -2.0),
        point(&f, 5.0, 0.0, 5.0),
        point(&f, 0.0, 5.0, 5.0),
    ]);
    let jobs = vec![
        PlaneJob {
            frame: f.clone(),
            occluders: OccluderSet::default(),
            slices: vec![],
            reproject: Vec::new(),
        },
        PlaneJob {
            frame: f.clone(),
            occluders: behind,
            slices: vec![],
            reproject: Vec::new(),
        },
    ];
    for _ in 0..3 {
        let maps = b.render(&jobs).unwrap();
        for m in &maps {
            assert_eq!(m, &DepthMap::new(32));
        }
        let more = random_jobs(11, Shape::Triangle, 30, &[64]);
        run_and_compare(b, &more);
    }
}

/// Large planes: several submissions (the render-target budget) in one call.
#[test]
fn many_large_planes_are_split_into_submissions() {
    let Some(b) = backend() else { return };
    let jobs = random_jobs(5, Shape::Quad, 10, &[2048, 1024]);
    let d = run_and_compare(b, &jobs);
    assert!(d.cpu_only * 100 <= d.covered.max(1), "{d:?}");
}

// ---------------------------------------------------------------------------------------------
// Occlusion-sweep reprojection

/// Two planes of one sweep: the cell, direction and resolution shared, the source at distance
/// `s` beyond the face and the target at `t > s`, each rectangle covering the cell's cone.
fn sweep_pair(
    rng: &mut Pcg64,
    res: u32,
    axis: usize,
    positive: bool,
    s: f64,
    t: f64,
) -> (PlaneFrame, PlaneFrame) {
    let planes = sweep_planes(rng, res, axis, positive, &[s, t]);
    (planes[0].clone(), planes[1].clone())
}

/// Planes of one sweep at the given distances beyond the face: the cell, direction and
/// resolution shared, each rectangle covering the cell's cone (scaled at random).
fn sweep_planes(
    rng: &mut Pcg64,
    res: u32,
    axis: usize,
    positive: bool,
    distances: &[f64],
) -> Vec<PlaneFrame> {
    let lo = DVec3::new(
        rng.random_range(-1.0..0.0),
        rng.random_range(-1.0..0.0),
        rng.random_range(-1.0..0.0),
    );
    let size = DVec3::new(
        rng.random_range(0.2..2.0),
        rng.random_range(0.2..2.0),
        rng.random_range(0.2..2.0),
    );
    let cell = DAabb {
        min: lo,
        max: lo + size,
    };
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let centre = DVec2::new(
        0.5 * (cell.min[u] + cell.max[u]),
        0.5 * (cell.min[v] + cell.max[v]),
    );
    let face = if positive {
        cell.max[axis]
    } else {
        cell.min[axis]
    };
    let plane = |d: f64, rng: &mut Pcg64| {
        let half = DVec2::new(0.5 * size[u] + d, 0.5 * size[v] + d) * rng.random_range(1.0..1.5);
        PlaneFrame {
            cell,
            axis,
            positive,
            position: face + if positive { d } else { -d },
            rect_min: centre - half,
            rect_max: centre + half,
            width: res,
            height: res,
        }
    };
    distances.iter().map(|&d| plane(d, rng)).collect()
}

/// Each map square or stretched at random with the same pixel budget, up to 4× per side (as a
/// bake stretches maps to their rectangles), so that sources and targets differ in size.
fn stretch_at_random(rng: &mut Pcg64, planes: &mut [PlaneFrame]) {
    for f in planes {
        let res = f.width;
        let k = rng.random_range(0..=2u32.min(res.trailing_zeros() - 1));
        (f.width, f.height) = if rng.random_bool(0.5) {
            (res << k, res >> k)
        } else {
            (res >> k, res << k)
        };
    }
}

/// The reprojections onto `dst` from `sources` (frames of the same sweep in front of it), each
/// with a random source Depth Map.
fn random_reprojections(
    rng: &mut Pcg64,
    sources: &[PlaneFrame],
    dst: &PlaneFrame,
) -> Vec<Reprojection> {
    sources
        .iter()
        .map(|src| Reprojection::new(src, dst, Arc::new(random_source(rng, src))))
        .collect()
}

/// `job` with only its first reprojection: what the GPU backend once computed, wrongly.
fn first_only(job: &PlaneJob) -> PlaneJob {
    PlaneJob {
        reproject: job.reproject.iter().take(1).cloned().collect(),
        ..job.clone()
    }
}

/// A source Depth Map: unset background (`+inf`), a few rectangular blobs of umbra, and holes
/// in them. Umbra and holes use every kind of value the umbra test must classify exactly:
/// `±0`, `-inf` and negative denormals are in the umbra; `+inf`, positive denormals and NaNs
/// of either sign are not.
fn random_source(rng: &mut Pcg64, frame: &PlaneFrame) -> DepthMap {
    let (n, m) = (frame.width as usize, frame.height as usize);
    let mut map = DepthMap::for_frame(frame);
    let umbra = |rng: &mut Pcg64| match rng.random_range(0..5) {
        0 => -0.0,
        1 => 0.0,
        2 => f32::NEG_INFINITY,
        3 => -1e-40,
        _ => -rng.random_range(0.0..3.0f32),
    };
    let hole = |rng: &mut Pcg64| match rng.random_range(0..5) {
        0 => f32::INFINITY,
        1 => 1e-40,
        2 => f32::NAN,
        3 => -f32::NAN,
        _ => rng.random_range(1e-6..3.0f32),
    };
    for _ in 0..rng.random_range(1..4) {
        let (w, h) = (rng.random_range(n / 4..=n), rng.random_range(m / 4..=m));
        let (x0, y0) = (rng.random_range(0..=n - w), rng.random_range(0..=m - h));
        for y in y0..y0 + h {
            for x in x0..x0 + w {
                map.depth[y * n + x] = umbra(rng);
            }
        }
    }
    let holes = rng.random_range(0..=n.max(m) / 4);
    for _ in 0..holes {
        let k = rng.random_range(0..n * m);
        map.depth[k] = hole(rng);
    }
    map
}

/// A cell's worth of sweep jobs per resolution: per job 1–6 reprojections from random planes
/// of the sweep in front of the target (a skip list's worth; maps stretched at random, so that
/// sources and targets differ in size), random sources, one job in three
/// without occluders, some with slices.
fn reprojection_jobs(seed: u64, resolutions: &[u32]) -> Vec<PlaneJob> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut jobs = Vec::new();
    for &res in resolutions {
        for axis in 0..3 {
            for positive in [true, false] {
                // Source distances, nearest to the target first (the bake's order).
                let count = 1 + jobs.len() % 6;
                let mut distances = vec![rng.random_range(0.3..6.0)];
                for _ in 0..count {
                    let last = distances[distances.len() - 1];
                    distances.push(last + rng.random_range(0.05..2.0));
                }
                distances.reverse();
                let mut planes = sweep_planes(&mut rng, res, axis, positive, &distances);
                stretch_at_random(&mut rng, &mut planes);
                let dst = planes.remove(0);
                let reproject = random_reprojections(&mut rng, &planes, &dst);
                let mut occ = OccluderSet::default();
                if jobs.len() % 3 != 0 {
                    for _ in 0..20 {
                        let shape = [Shape::Triangle, Shape::Quad, Shape::Box][jobs.len() % 3];
                        occ.push(random_occluder(&mut rng, &dst, shape));
                    }
                }
                let slices = if jobs.len() % 4 == 1 {
                    let c = 0.5 * (dst.rect_min + dst.rect_max);
                    square(c.x, c.y, 0.2 * (dst.rect_max.x - dst.rect_min.x), 0.4)
                } else {
                    vec![]
                };
                jobs.push(PlaneJob {
                    reproject,
                    frame: dst,
                    occluders: occ,
                    slices,
                });
            }
        }
    }
    jobs
}

/// Maps equal bit for bit (so `-0.0` differs from `0.0`, and NaN must match NaN).
fn assert_bits_equal(g: &DepthMap, c: &DepthMap, what: &str) {
    assert_eq!((g.width, g.height), (c.width, c.height));
    let res = g.width as usize;
    for (k, (a, b)) in g.depth.iter().zip(&c.depth).enumerate() {
        assert_eq!(
            a.to_bits(),
            b.to_bits(),
            "{what}: pixel ({}, {}) at {res}×{}: GPU {a}, CPU {b}",
            g.height,
            k % res,
            k / res
        );
    }
}

/// The reprojections' separable window filter gives bit-identical Depth Maps on both backends,
/// with every reprojection of a job applied (a pixel any of them sets holds the least of their
/// Depths). Every job is rendered twice in one call: bare (reprojections and slices only —
/// exact, so the whole map must be identical) and with its occluders (every reprojected pixel
/// holds at most its reprojection's Depth on both; other differences are the projection's
/// near-ties, checked by [`compare`]). The jobs are such that applying only the first
/// reprojection of each gives a different map.
#[test]
fn reprojection_matches_the_cpu_exactly() {
    let Some(b) = backend() else { return };
    let full = reprojection_jobs(31, &[16, 32, 64, 128, 256]);
    let bare: Vec<PlaneJob> = full
        .iter()
        .map(|j| PlaneJob {
            occluders: OccluderSet::default(),
            ..j.clone()
        })
        .collect();
    let jobs: Vec<PlaneJob> = full.iter().chain(&bare).cloned().collect();
    let gpu_maps = b.render(&jobs).expect("GPU render");
    let stats = b.last_stats();
    let (mut set, mut unset, mut with_occluders, mut beyond_first) = (0usize, 0, 0, 0);
    for (k, (job, g)) in jobs.iter().zip(&gpu_maps).enumerate() {
        let c = cpu::render_job(job);
        let masks: Vec<Vec<bool>> = job.reproject.iter().map(|r| r.mask()).collect();
        if job.occluders.is_empty() {
            assert_bits_equal(g, &c, &format!("job {k}"));
            if k >= full.len() {
                let any = |p: usize| masks.iter().any(|m| m[p]);
                set += (0..g.depth.len()).filter(|&p| any(p)).count();
                unset += (0..g.depth.len()).filter(|&p| !any(p)).count();
                let first = cpu::render_job(&first_only(job));
                beyond_first += c
                    .depth
                    .iter()
                    .zip(&first.depth)
                    .filter(|(a, b)| a.to_bits() != b.to_bits())
                    .count();
            }
        } else {
            with_occluders += 1;
            for (r, mask) in job.reproject.iter().zip(&masks) {
                for (p, &m) in mask.iter().enumerate() {
                    if m {
                        assert!(
                            g.depth[p] <= r.depth && c.depth[p] <= r.depth,
                            "job {k}, pixel {p}"
                        );
                    }
                }
            }
            compare(job, g, &c);
        }
    }
    let reprojections: usize = jobs.iter().map(|j| j.reproject.len()).sum();
    eprintln!(
        "reprojection: {reprojections} reprojections in {} jobs ({} on the GPU), {set} pixels \
         set, {unset} not, {beyond_first} set beyond the first reprojection's, \
         {with_occluders} jobs with occluders",
        jobs.len(),
        stats.reprojections
    );
    assert!(set > 10_000 && unset > 10_000, "{set} set, {unset} not");
    assert!(with_occluders >= 10);
    assert!(reprojections >= 3 * jobs.len(), "{reprojections}");
    assert!(stats.reprojections * 10 >= reprojections * 9, "{stats:?}");
    // Applying only the first reprojection would fail the comparison above.
    assert!(beyond_first > 1000, "{beyond_first}");
}

/// A sweep plane kept on the device (`render_kept`): its umbra's box and the count outside
/// it are those of the map the device renders for the same job, its answers the pyramid's,
/// and a later job reprojecting from its stand-in renders bit for bit the map that
/// reprojecting from the map itself renders — on the GPU, and on the CPU for jobs without
/// occluders (exact). Chains of three planes of a sweep on every axis and side: a random
/// source (umbra, holes, NaNs), a plane reprojecting it (with occluders, slices or neither,
/// maps stretched at random) that is kept, and a plane reprojecting from that one. Without
/// umbra the stand-in sets nothing.
#[test]
fn kept_maps_reproject_as_the_maps_they_stand_for() {
    if backend().is_none() {
        return;
    }
    // A backend of its own, so that its counters are this test's.
    let b = GpuBackend::new().expect("a second device");
    let mut rng = Pcg64::seed_from_u64(41);
    let (mut chains, mut with_umbra, mut exact, mut skipped) = (0usize, 0usize, 0usize, 0usize);
    for res in [16u32, 64, 256] {
        for axis in 0..3 {
            for positive in [true, false] {
                for variant in 0..3 {
                    let d0 = rng.random_range(0.2..2.0);
                    let d1 = d0 + rng.random_range(0.05..1.5);
                    let d2 = d1 + rng.random_range(0.05..1.5);
                    let mut planes = sweep_planes(&mut rng, res, axis, positive, &[d0, d1, d2]);
                    stretch_at_random(&mut rng, &mut planes);
                    let (f0, f1, f2) = (&planes[0], &planes[1], &planes[2]);
                    // The third variant has no umbra to carry (its source is all holes), only
                    // its occluders. The
                    // others' sources are umbra but for random_source's holes (its blobs alone
                    // are often too small for a window from a near plane).
                    let source = if variant == 2 {
                        DepthMap::for_frame(f0)
                    } else {
                        let mut m = random_source(&mut rng, f0);
                        for d in &mut m.depth {
                            if *d == f32::INFINITY {
                                *d = -0.25;
                            }
                        }
                        m
                    };
                    let mut occluders = OccluderSet::default();
                    if variant >= 1 {
                        for _ in 0..20 {
                            occluders.push(random_occluder(&mut rng, f1, Shape::Quad));
                        }
                    }
                    let slices = if variant == 0 && axis == 1 {
                        let c = 0.5 * (f1.rect_min + f1.rect_max);
                        square(c.x, c.y, 0.2 * (f1.rect_max.x - f1.rect_min.x), 0.4)
                    } else {
                        vec![]
                    };
                    let kept_job = PlaneJob {
                        frame: f1.clone(),
                        occluders,
                        slices,
                        reproject: vec![Reprojection::new(f0, f1, Arc::new(source))],
                    };
                    let map = b.render(std::slice::from_ref(&kept_job)).unwrap().remove(0);
                    let (w, h) = (f1.width, f1.height);
                    let queries = vec![
                        RectQuery {
                            rect: [0, 0, w - 1, h - 1],
                            depth: 0.5,
                        },
                        RectQuery {
                            rect: [w / 4, h / 4, w / 2, h / 2],
                            depth: f32::INFINITY,
                        },
                    ];
                    let result = b
                        .render_kept(
                            std::slice::from_ref(&kept_job),
                            &[Some(PlaneQueries::rects(queries.clone()))],
                            &[true],
                        )
                        .unwrap()
                        .remove(0);
                    let what =
                        format!("res {res}, axis {axis}, positive {positive}, variant {variant}");
                    let kept = match result {
                        PlaneResult::Kept(kept) => kept,
                        // A plane nothing can cover skips the device: its map, made on the CPU.
                        PlaneResult::Map(m) => {
                            assert_eq!(m, map, "{what}");
                            assert_eq!(m.covered(), 0, "{what}: only an empty map is not kept");
                            skipped += 1;
                            continue;
                        }
                        PlaneResult::Answers(_) => panic!("{what}: answers without the map"),
                    };
                    assert!(kept.source.is_on_device(), "{what}");
                    assert_eq!(
                        kept.umbra,
                        umbrasweep::sweep::umbra_pixels(&map),
                        "{what}: umbra box"
                    );
                    let outside = map.depth.iter().filter(|&&d| d.is_nan() || d > 0.0).count();
                    assert_eq!(kept.outside_umbra, outside as u64, "{what}: outside");
                    let hdm = Hdm::build(&map);
                    let answers: Vec<_> = queries
                        .iter()
                        .map(|q| {
                            let [i0, j0, i1, j1] = q.rect;
                            hdm.test(i0, j0, i1, j1, q.depth)
                        })
                        .collect();
                    assert_eq!(kept.answers, answers, "{what}: answers");
                    // The next plane, from the stand-in and from the map.
                    let next = |source: Arc<DepthMap>| PlaneJob {
                        frame: f2.clone(),
                        occluders: OccluderSet::default(),
                        slices: vec![],
                        reproject: vec![Reprojection::new(f1, f2, source)],
                    };
                    let from_kept = b.render(&[next(kept.source.clone())]).unwrap().remove(0);
                    let from_map_job = next(Arc::new(map.clone()));
                    let from_map = b.render(std::slice::from_ref(&from_map_job)).unwrap();
                    assert_bits_equal(&from_kept, &from_map[0], &what);
                    if kept_job.occluders.is_empty() {
                        // Reprojections and slices are exact: the CPU's whole chain agrees.
                        let cpu_map = cpu::render_job(&kept_job);
                        assert_bits_equal(&map, &cpu_map, &what);
                        assert_bits_equal(&from_kept, &cpu::render_job(&from_map_job), &what);
                        exact += 1;
                    }
                    match kept.umbra {
                        Some(_) => with_umbra += 1,
                        None => assert_eq!(from_kept.covered(), 0, "{what}: nothing to carry"),
                    }
                    chains += 1;
                }
            }
        }
    }
    let stats = b.total_stats();
    eprintln!(
        "kept maps: {chains} chains, {with_umbra} with umbra, {exact} exact, {skipped} not \
         drawn; {stats:?}"
    );
    assert_eq!(stats.kept_maps, chains);
    assert!(skipped < chains / 4, "{skipped} not drawn, {chains} kept");
    assert!(exact >= chains / 3, "{exact} exact of {chains}");
    assert!(with_umbra >= chains / 2, "{with_umbra} of {chains}");
    assert!(with_umbra < chains, "some without umbra");
}

/// A job with a reprojection and no occluders is rendered on the GPU (one pass, one draw); one
/// with neither, or whose reprojection can set nothing (no umbra in the source), skips the GPU
/// and is still right. A job with several reprojections runs one draw for each that can set a
/// pixel (not for one without umbra, nor for one whose umbra no window fits in), and its pixels
/// hold the least Depth of the reprojections that set them.
#[test]
fn a_reprojection_without_occluders_is_rendered() {
    if backend().is_none() {
        return;
    }
    // A backend of its own, so that no other test's call lands in `last_stats`.
    let b = GpuBackend::new().expect("a second device");
    let mut rng = Pcg64::seed_from_u64(41);
    let planes = sweep_planes(&mut rng, 64, 1, true, &[1.0, 1.2, 1.5]);
    let (far, near, dst) = (&planes[0], &planes[1], &planes[2]);
    let filled = |d: f32| {
        let mut m = DepthMap::new(64);
        m.depth.fill(d);
        Arc::new(m)
    };
    let only = PlaneJob {
        frame: dst.clone(),
        occluders: OccluderSet::default(),
        slices: vec![],
        reproject: vec![Reprojection::new(far, dst, filled(-0.25))],
    };
    let nothing = PlaneJob {
        reproject: Vec::new(),
        ..only.clone()
    };
    let no_umbra = PlaneJob {
        reproject: vec![Reprojection::new(far, dst, Arc::new(DepthMap::new(64)))],
        ..only.clone()
    };
    // One umbra pixel: smaller than every window, so it sets nothing either.
    let mut dot = DepthMap::new(64);
    dot.depth[32 * 64 + 32] = 0.0;
    let dot = Reprojection::new(near, dst, Arc::new(dot));
    assert!(!dot.mask().contains(&true));
    // The far source in the umbra on its left half only.
    let mut half = DepthMap::new(64);
    for row in half.depth.chunks_exact_mut(64) {
        row[..32].fill(0.0);
    }
    let half = Arc::new(half);
    let several = PlaneJob {
        reproject: vec![
            Reprojection::new(near, dst, filled(-1.0)),
            Reprojection::new(near, dst, Arc::new(DepthMap::new(64))),
            dot,
            Reprojection::new(far, dst, half),
        ],
        ..only.clone()
    };
    let maps = b
        .render(&[only.clone(), nothing, no_umbra, several.clone()])
        .unwrap();
    let stats = b.last_stats();
    assert_eq!(
        (
            stats.gpu_planes,
            stats.reprojections,
            stats.passes,
            stats.draws
        ),
        (2, 3, 2, 3),
        "{stats:?}"
    );
    let expected = cpu::render_job(&only);
    assert!(expected.covered() > 64 * 64 / 4, "{}", expected.covered());
    assert_bits_equal(&maps[0], &expected, "reprojection only");
    assert_eq!(maps[1], DepthMap::new(64));
    assert_eq!(maps[2], DepthMap::new(64));
    let expected = cpu::render_job(&several);
    assert_bits_equal(&maps[3], &expected, "several reprojections");
    // Both Depths occur: the far source's where it reaches (its Depth is the least), the near
    // one's where only it does.
    let (d_near, d_far) = (several.reproject[0].depth, several.reproject[3].depth);
    assert!(d_far < d_near, "{d_far} {d_near}");
    let count = |d: f32| expected.depth.iter().filter(|&&x| x == d).count();
    assert!(
        count(d_far) > 64 * 4 && count(d_near) > 64 * 4,
        "{} {}",
        count(d_far),
        count(d_near)
    );
    assert_eq!(count(d_far) + count(d_near), expected.covered());
    assert!(stats.bytes_uploaded >= 3 * 64 * 64 * 4, "{stats:?}");
}

/// Windows reaching past the plane (which [`Reprojection::new`] never makes, but the type
/// allows) set nothing on either backend, and the ones inside still work.
#[test]
fn windows_past_the_plane_set_nothing() {
    let Some(b) = backend() else { return };
    let mut rng = Pcg64::seed_from_u64(47);
    let (src, dst) = sweep_pair(&mut rng, 32, 2, false, 1.0, 1.2);
    let mut full = DepthMap::new(32);
    full.depth.fill(-1.0);
    let mut r = Reprojection::new(&src, &dst, Arc::new(full));
    r.cols[3] = [30, 32];
    r.cols[4] = [7, u32::MAX];
    r.cols[5] = [u32::MAX, u32::MAX];
    r.rows[6] = [0, 40];
    let job = PlaneJob {
        frame: dst,
        occluders: OccluderSet::default(),
        slices: vec![],
        reproject: vec![r],
    };
    let g = &b.render(std::slice::from_ref(&job)).unwrap()[0];
    let c = cpu::render_job(&job);
    assert_bits_equal(g, &c, "windows past the plane");
    assert!(c.covered() > 32 * 32 / 4, "{}", c.covered());
    assert!((0..32).all(|j| c.depth[j * 32 + 4].is_infinite()));
    assert!((0..32).all(|i| c.depth[6 * 32 + i].is_infinite()));
}

/// What reprojections cost on this adapter: 6 planes at 256² (a cell's directions), with 60
/// occluders each, with 0, 1, 2, 4 and 7 reprojections (sources 0.25 apart in front of the
/// target, as a skip list gives), with 1 and 7 alone, and 7 alone with sources entirely in the
/// umbra (the filter's worst case: no early exit, no scissor). Prints the GPU section's time
/// (best of 10) from `RenderStats`, and the cost of one more reprojection per plane.
#[test]
fn reprojection_cost_at_256() {
    if backend().is_none() {
        return;
    }
    let b = GpuBackend::new().expect("a second device");
    let mut rng = Pcg64::seed_from_u64(43);
    const MOST: usize = 7;
    let mut with = Vec::new();
    for axis in 0..3 {
        for positive in [true, false] {
            let mut distances = vec![3.0];
            distances.extend((0..MOST).map(|k| 2.0 - 0.25 * k as f64));
            let mut planes = sweep_planes(&mut rng, 256, axis, positive, &distances);
            let dst = planes.remove(0);
            let mut occ = OccluderSet::default();
            for _ in 0..60 {
                occ.push(random_occluder(&mut rng, &dst, Shape::Quad));
            }
            with.push(PlaneJob {
                reproject: random_reprojections(&mut rng, &planes, &dst),
                frame: dst,
                occluders: occ,
                slices: vec![],
            });
        }
    }
    let keep = |jobs: &[PlaneJob], n: usize| -> Vec<PlaneJob> {
        jobs.iter()
            .map(|j| PlaneJob {
                reproject: j.reproject[..n].to_vec(),
                ..j.clone()
            })
            .collect()
    };
    let alone: Vec<PlaneJob> = with
        .iter()
        .map(|j| PlaneJob {
            occluders: OccluderSet::default(),
            ..j.clone()
        })
        .collect();
    let mut all = DepthMap::new(256);
    all.depth.fill(-1.0);
    let all = Arc::new(all);
    let worst: Vec<PlaneJob> = alone
        .iter()
        .map(|j| {
            let mut j = j.clone();
            for r in &mut j.reproject {
                r.source = all.clone();
            }
            j
        })
        .collect();
    let widths: Vec<u32> = with
        .iter()
        .flat_map(|j| &j.reproject)
        .flat_map(|r| r.cols.iter().chain(&r.rows))
        .filter(|w| w[0] <= w[1])
        .map(|w| w[1] - w[0] + 1)
        .collect();
    let mean_width = widths.iter().sum::<u32>() as f64 / widths.len().max(1) as f64;
    let mut ms = std::collections::HashMap::new();
    for (name, n, jobs) in [
        ("with 0", 0, keep(&with, 0)),
        ("with 1", 1, keep(&with, 1)),
        ("with 2", 2, keep(&with, 2)),
        ("with 4", 4, keep(&with, 4)),
        ("with 7", 7, keep(&with, MOST)),
        ("alone 1", 1, keep(&alone, 1)),
        ("alone 7", 7, keep(&alone, MOST)),
        ("alone 1, all umbra", 1, keep(&worst, 1)),
        ("alone 7, all umbra", 7, keep(&worst, MOST)),
    ] {
        b.render(&jobs).unwrap(); // warm-up: pools and pipelines
        let mut best: Option<gpu::RenderStats> = None;
        for _ in 0..10 {
            b.render(&jobs).unwrap();
            let s = b.last_stats();
            if best.as_ref().is_none_or(|x| s.gpu < x.gpu) {
                best = Some(s);
            }
        }
        let s = best.unwrap();
        eprintln!(
            "6 planes at 256², {n} reprojections each, {name}: GPU section {:.2} ms (setup \
             {:.2} ms), {} passes, {} draws, {} reprojections, {} KB uploaded",
            s.gpu.as_secs_f64() * 1e3,
            s.setup.as_secs_f64() * 1e3,
            s.passes,
            s.draws,
            s.reprojections,
            s.bytes_uploaded / 1024
        );
        // Reprojections that cannot set a pixel are dropped.
        assert!(
            s.reprojections <= 6 * n && s.reprojections * 8 >= 6 * n * 7,
            "{name}: {s:?}"
        );
        // One pass per plane; one draw per plane with occluders and one per reprojection.
        let occluder_draws = if name.starts_with("with") { 6 } else { 0 };
        assert_eq!(
            (s.passes, s.draws),
            (6, occluder_draws + s.reprojections),
            "{name}: {s:?}"
        );
        ms.insert(name, s.gpu.as_secs_f64() * 1e3);
    }
    let per = |a: &str, b: &str, extra: usize| (ms[b] - ms[a]) / (6 * extra) as f64;
    eprintln!(
        "mean window {mean_width:.1} px; GPU time per extra reprojection of a 256² plane: \
         {:.3} ms with occluders, {:.3} ms alone, {:.3} ms alone with all umbra",
        per("with 1", "with 7", MOST - 1),
        per("alone 1", "alone 7", MOST - 1),
        per("alone 1, all umbra", "alone 7, all umbra", MOST - 1),
    );
}

// ---------------------------------------------------------------------------------------------
// Benchmark

// ---------------------------------------------------------------------------------------------
// Regression: degenerate clipped edges

/// A job of one occluder on `frame`.
fn one_occluder_job(frame: PlaneFrame, pts: &[DVec3]) -> PlaneJob {
    let mut occ = OccluderSet::default();
    occ.push(pts.iter().copied());
    PlaneJob {
        frame,
        occluders: occ,
        slices: vec![],
        reproject: Vec::new(),
    }
}

/// Clipping can leave near-duplicate vertices (edges ~10⁻¹⁴ px long) whose normals are
/// rounding noise; eroding such an edge once cut off whole Projections in the CPU backend
/// (found by these comparisons, fixed there). Both backends now cover this pixel.
#[test]
fn degenerate_clipped_edges_do_not_uncover_a_triangle() {
    let f = PlaneFrame {
        cell: DAabb {
            min: DVec3::splat(-0.5),
            max: DVec3::splat(0.5),
        },
        axis: 0,
        positive: false,
        position: -10.0,
        rect_min: DVec2::new(-8.0, -8.0),
        rect_max: DVec2::new(8.0, 8.0),
        width: 64,
        height: 64,
    };
    let tri = [
        DVec3::new(-2.628855960945415, 8.110144680784256, -5.438125008171043),
        DVec3::new(-10.949435919824044, 8.535924727613656, -2.6336076127590715),
        DVec3::new(-4.679093122439994, 2.2980744054368625, -9.389374134012611),
    ];
    let slack = coverage::contract_slack(&f, &tri, 62, 4);
    assert!(
        slack > 0.3,
        "pixel (62, 4) is well inside all 8 views: {slack}"
    );
    let job = one_occluder_job(f, &tri);
    let map = cpu::render_job(&job);
    assert!(
        map.depth[4 * 64 + 62].is_finite(),
        "CPU covers {} pixels",
        map.covered()
    );
    let Some(b) = backend() else { return };
    let gpu_map = &b.render(std::slice::from_ref(&job)).unwrap()[0];
    assert!(gpu_map.depth[4 * 64 + 62].is_finite());
    let d = compare(&job, gpu_map, &map);
    assert_eq!(d.gpu_only, 0);
}

// ---------------------------------------------------------------------------------------------
// Whole bakes: the PVS is the same with both backends

use common::{Obj, cube, quad};

/// Bakes with both backends and requires the same visible set per cell. Should the GPU ever
/// differ, it may only see more (its near-tie pixels are uncovered), and the message says so.
/// Returns how many (cell, object) pairs are hidden, so tests can check they culled something
/// (`None` without an adapter).
fn same_pvs(scene: &Scene, cells: &[Aabb], settings: &BakeSettings) -> Option<usize> {
    let b = backend()?;
    let c = bake(scene, cells, settings, &CpuBackend::new(), None).unwrap();
    let g = bake(scene, cells, settings, b, None).unwrap();
    assert_eq!(g.backend, "gpu");
    assert_eq!(g.adapter, b.adapter());
    assert_eq!(c.cells.len(), g.cells.len());
    for (k, (cc, gc)) in c.cells.iter().zip(&g.cells).enumerate() {
        let gpu_only: Vec<_> = gc
            .visible
            .iter()
            .filter(|o| !cc.visible.contains(o))
            .collect();
        let cpu_only: Vec<_> = cc
            .visible
            .iter()
            .filter(|o| !gc.visible.contains(o))
            .collect();
        assert!(
            cpu_only.is_empty(),
            "cell {k}: the GPU bake hides {cpu_only:?}, which the CPU bake finds visible"
        );
        assert!(
            gpu_only.is_empty(),
            "cell {k}: the GPU bake keeps {gpu_only:?} visible (conservative, but the PVS \
             should be identical)"
        );
        assert_eq!(cc.planes, gc.planes, "cell {k}: same planes");
    }
    let hidden = c
        .cells
        .iter()
        .map(|c| scene.objects.len() - c.visible.len())
        .sum();
    eprintln!(
        "{}: {} cells, {} objects, {hidden} hidden pairs, cpu {:.2}s, gpu {:.2}s",
        scene.objects.len(),
        cells.len(),
        scene.objects.len(),
        c.seconds,
        g.seconds
    );
    Some(hidden)
}

#[test]
fn bake_pvs_is_identical_on_a_small_city() {
    let options = CityOptions {
        max_cells: Some(6),
        ..CityOptions::with_blocks(2, 2)
    };
    let city = generate::city(&options).unwrap();
    let scene = city.to_scene("city 2×2");
    assert!(!city.cells.is_empty());
    let Some(hidden) = same_pvs(&scene, &city.cells, &BakeSettings::default()) else {
        return;
    };
    assert!(hidden > 0);
    // A coarse resolution makes near-tie pixels matter more.
    let coarse = BakeSettings {
        resolution: 64,
        ..BakeSettings::default()
    };
    assert!(same_pvs(&scene, &city.cells, &coarse).is_some_and(|h| h > 0));
}

/// The default forest's first two cells baked with the sweep at 128² on the CPU and on `b`:
/// the scene and both results.
fn sweep_forest_bakes(b: &GpuBackend) -> (Scene, BakeResult, BakeResult) {
    let forest = generate::forest(&generate::ForestOptions::default()).unwrap();
    let scene = forest.to_scene("forest");
    let cells = &forest.cells[..forest.cells.len().min(2)];
    let settings = BakeSettings {
        resolution: 128,
        sweep: umbrasweep::bake::SweepChoice::On,
        ..BakeSettings::default()
    };
    let c = bake(&scene, cells, &settings, &CpuBackend::new(), None).unwrap();
    let g = bake(&scene, cells, &settings, b, None).unwrap();
    (scene, c, g)
}

/// The backend picks counting Projections on a hardware adapter (the issue's rule: not slower
/// on the H200 measured) and clipped ones on a software adapter such as lavapipe (where the
/// counting compute pass runs on the CPU and was slower); `set_projection` overrides it.
#[test]
fn the_default_projection_follows_the_adapter() {
    if backend().is_none() {
        return;
    }
    let mut b = GpuBackend::new().expect("a device");
    let hardware = b.adapter_info().device_type != wgpu::DeviceType::Cpu;
    let want = if hardware {
        GpuProjection::Counting
    } else {
        GpuProjection::Clipped
    };
    assert_eq!(b.projection(), want, "{:?}", b.adapter_info());
    b.set_projection(GpuProjection::Counting).unwrap();
    assert_eq!(b.projection(), GpuProjection::Counting);
}

/// One box test per pixel sent to the device (`set_pixels_per_device_test(1)`) instead of one
/// per 64 keeps more of a sweep's maps on the device and reads fewer back, with the PVS of the
/// CPU backend; with the bake's boxes kept on the device it uploads less than with every box
/// sent whole (`set_resident_boxes(false)`), for the same PVS.
#[test]
fn a_smaller_share_keeps_more_maps_with_the_same_pvs() {
    if backend().is_none() {
        return;
    }
    let default = GpuBackend::new().expect("a second device");
    let (_, c, g64) = sweep_forest_bakes(&default);
    let mut one = GpuBackend::new().expect("a third device");
    one.set_pixels_per_device_test(1);
    let (_, _, g1) = sweep_forest_bakes(&one);
    let (s64, s1) = (default.total_stats(), one.total_stats());
    eprintln!("one per 64 pixels: {s64:?}\none per pixel: {s1:?}");
    assert!(s1.kept_maps > s64.kept_maps, "{s1:?} against {s64:?}");
    assert!(
        s1.maps_read_back < s64.maps_read_back,
        "{s1:?} against {s64:?}"
    );
    assert!(
        s1.bytes_read_back < s64.bytes_read_back,
        "{s1:?} against {s64:?}"
    );
    // The bake keeps its boxes on the device, each sent once: sending every box with its
    // test instead uploads more, for the same PVS.
    let mut inline = GpuBackend::new().expect("a fourth device");
    inline.set_pixels_per_device_test(1);
    inline.set_resident_boxes(false);
    let (_, _, g_inline) = sweep_forest_bakes(&inline);
    let s_inline = inline.total_stats();
    eprintln!("one per pixel, boxes sent whole: {s_inline:?}");
    assert!(
        s1.bytes_uploaded < s_inline.bytes_uploaded,
        "resident: {} bytes up, sent whole: {}",
        s1.bytes_uploaded,
        s_inline.bytes_uploaded
    );
    for (k, (a, c)) in g_inline.cells.iter().zip(&c.cells).enumerate() {
        assert_eq!(
            a.visible, c.visible,
            "cell {k}: boxes sent whole against the CPU"
        );
    }
    for (k, ((a, b), c)) in g1.cells.iter().zip(&g64.cells).zip(&c.cells).enumerate() {
        assert_eq!(
            a.visible, c.visible,
            "cell {k}: one box per pixel against the CPU"
        );
        assert_eq!(
            b.visible, c.visible,
            "cell {k}: one box per 64 pixels against the CPU"
        );
    }
}

/// A whole bake with the occlusion sweep on a small forest, on a backend of its own: planes
/// carry several reprojections (the skip list), and the PVS is the same as the CPU's.
#[test]
fn bake_pvs_is_identical_with_the_sweep() {
    if backend().is_none() {
        return;
    }
    let b = GpuBackend::new().expect("a second device");
    let (scene, c, g) = sweep_forest_bakes(&b);
    let stats = b.total_stats();
    eprintln!("sweep bake of a forest: {stats:?}");
    // The sweep's maps stay on the device (`render_kept`) where their tests are few enough
    // (`PIXELS_PER_DEVICE_TEST`); the others come back: both kinds in one sweep.
    assert!(stats.kept_maps * 4 >= stats.gpu_planes, "{stats:?}");
    assert!(stats.maps_read_back > 0, "{stats:?}");
    // Read back instead, the same PVS.
    let mut back = GpuBackend::new().expect("a third device");
    back.set_keep_sweep_maps(false);
    let (_, _, g_back) = sweep_forest_bakes(&back);
    let back_stats = back.total_stats();
    assert_eq!(back_stats.kept_maps, 0, "{back_stats:?}");
    assert!(back_stats.maps_read_back > 0, "{back_stats:?}");
    assert!(
        2 * back_stats.bytes_read_back > 3 * stats.bytes_read_back,
        "kept: {} bytes read back, read back: {}",
        stats.bytes_read_back,
        back_stats.bytes_read_back
    );
    for (k, (a, b)) in g.cells.iter().zip(&g_back.cells).enumerate() {
        assert_eq!(a.visible, b.visible, "cell {k}, kept against read back");
    }
    assert!(
        2 * stats.reprojections > 3 * stats.gpu_planes,
        "several reprojections per plane: {stats:?}"
    );
    assert!(
        stats.tables_reused > stats.tables_uploaded,
        "most reprojections take their source's table from the device: {stats:?}"
    );
    let hidden: usize = c
        .cells
        .iter()
        .map(|c| scene.objects.len() - c.visible.len())
        .sum();
    eprintln!(
        "{hidden} hidden (cell, object) pairs of {}",
        scene.objects.len()
    );
    assert!(hidden > 0);
    for (k, (cc, gc)) in c.cells.iter().zip(&g.cells).enumerate() {
        assert_eq!(cc.visible, gc.visible, "cell {k}");
        assert_eq!(cc.planes, gc.planes, "cell {k}");
    }
}

/// A sweep plane whose umbra covers its whole frame ends its direction and tests every box
/// behind it, not only those within its usual reach (16 times its distance): with its map
/// kept on the device it is rendered again for those tests. A wide wall in front of the cell
/// (the first plane behind it is all umbra) and a row of boxes behind it out to 200 units,
/// beyond that reach: the GPU bake hides them all as the CPU's does.
#[test]
fn a_sweep_plane_ending_its_direction_tests_what_lies_far_behind() {
    let mut objects = vec![cube("wall", [-400.0, -400.0, 2.0], [400.0, 400.0, 2.5])];
    for (k, d) in [100.0f32, 190.0].into_iter().enumerate() {
        objects.push(cube(
            &format!("far{k}"),
            [-1.0, -1.0, d],
            [1.0, 1.0, d + 1.0],
        ));
    }
    let far = objects.len() - 1;
    let scene = Scene::from_objects(Path::new("wall"), objects);
    let cells = [Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5))];
    // The sweep alone (ray space factorization would hide the boxes first).
    let settings = BakeSettings {
        sweep: umbrasweep::bake::SweepChoice::On,
        rsf: umbrasweep::bake::SweepChoice::Off,
        ..BakeSettings::default()
    };
    let Some(hidden) = same_pvs(&scene, &cells, &settings) else {
        return;
    };
    assert_eq!(hidden, far, "every box behind the wall is hidden");
}

#[test]
fn bake_pvs_is_identical_on_analytic_scenes() {
    let unit = Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5));
    let z = 5.0;
    let scenes: Vec<Vec<Obj>> = vec![
        // A wall hiding a target.
        vec![
            cube("wall", [-20.0, -20.0, 5.0], [20.0, 20.0, 5.5]),
            cube("target", [-1.0, -1.0, 10.0], [1.0, 1.0, 11.0]),
            cube("in_view", [-1.0, -1.0, -11.0], [1.0, 1.0, -10.0]),
        ],
        // A slit.
        vec![
            cube("left", [-20.0, -20.0, 5.0], [-0.15, 20.0, 5.5]),
            cube("right", [0.15, -20.0, 5.0], [20.0, 20.0, 5.5]),
            cube("target", [-1.0, -1.0, 10.0], [1.0, 1.0, 11.0]),
        ],
        // Two abutting walls (fusion).
        vec![
            quad(
                "wall_a",
                Vec3::new(-20.0, -20.0, z),
                Vec3::new(0.0, -20.0, z),
                Vec3::new(0.0, 20.0, z),
                Vec3::new(-20.0, 20.0, z),
            ),
            quad(
                "wall_b",
                Vec3::new(0.0, -20.0, z),
                Vec3::new(20.0, -20.0, z),
                Vec3::new(20.0, 20.0, z),
                Vec3::new(0.0, 20.0, z),
            ),
            cube("target", [-1.0, -1.0, 10.0], [1.0, 1.0, 11.0]),
        ],
        // A closed room of six thick walls around the cell, things outside and inside.
        {
            let (a, b) = (3.0, 3.5);
            vec![
                cube("x-", [-b, -b, -b], [-a, b, b]),
                cube("x+", [a, -b, -b], [b, b, b]),
                cube("y-", [-b, -b, -b], [b, -a, b]),
                cube("y+", [-b, a, -b], [b, b, b]),
                cube("z-", [-b, -b, -b], [b, b, -a]),
                cube("z+", [-b, -b, a], [b, b, b]),
                cube("outside", [6.0, -1.0, -1.0], [8.0, 1.0, 1.0]),
                cube("inside", [-0.1, -0.1, -0.1], [0.1, 0.1, 0.1]),
                cube("straddling", [0.3, -0.2, -0.2], [2.0, 0.2, 0.2]),
            ]
        },
        // Many small boxes at random in front of the cell, on every side.
        {
            let mut rng = Pcg64::seed_from_u64(99);
            (0..200)
                .map(|k| {
                    let c = Vec3::new(
                        rng.random_range(-12.0..12.0),
                        rng.random_range(-12.0..12.0),
                        rng.random_range(-12.0..12.0),
                    );
                    let c = if c.abs().max_element() < 2.0 {
                        c + Vec3::splat(3.0)
                    } else {
                        c
                    };
                    let h = Vec3::new(
                        rng.random_range(0.2..2.5),
                        rng.random_range(0.2..2.5),
                        rng.random_range(0.2..2.5),
                    );
                    cube(&format!("box{k}"), (c - h).into(), (c + h).into())
                })
                .collect()
        },
    ];
    let cells = [
        unit,
        Aabb::new(Vec3::new(-1.5, -0.25, -0.5), Vec3::new(-0.5, 0.25, 0.5)),
    ];
    // Everything is visible through the slit; every other scene hides something.
    let hides = [true, false, true, true, true];
    for (objects, hides) in scenes.into_iter().zip(hides) {
        let scene = Scene::from_objects(Path::new("analytic"), objects);
        let Some(hidden) = same_pvs(&scene, &cells, &BakeSettings::default()) else {
            return;
        };
        assert_eq!(hidden > 0, hides, "hidden pairs: {hidden}");
    }
}

// ---------------------------------------------------------------------------------------------
// Ray space factorization: the GPU's charts against the CPU's

use umbrasweep::backend::{RsfCharts, RsfOccluder};
use umbrasweep::rsf::{RayCharts, hull_edges};

/// An occluder of the chart test: points, and whether it is a solid.
struct RsfOcc {
    pts: Vec<DVec3>,
    solid: bool,
}

/// Random occluders around a cell at the origin (`up` the up axis): walls standing below the
/// cell's bottom, floating walls and upper storeys resting on them or above gaps, rotated
/// polygons, boxes (solids), some crossing the cell's planes; scaled by `scale` and offset by
/// `offset`.
fn random_rsf_scene(rng: &mut Pcg64, up: usize, scale: f64, offset: DVec3) -> Vec<RsfOcc> {
    let at = |x: f64, z: f64, h: f64| {
        let p = if up == 1 {
            DVec3::new(x, h, z)
        } else {
            DVec3::new(x, z, h)
        };
        p * scale + offset
    };
    let mut out = Vec::new();
    for _ in 0..rng.random_range(20..60) {
        let ang: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let r: f64 = rng.random_range(3.0..40.0);
        let (cx, cz) = (r * ang.cos(), r * ang.sin());
        let kind = rng.random_range(0..4);
        let bottom = match kind {
            // On or below the cell's bottom (0), or floating.
            0 | 3 => rng.random_range(-1.0..0.0),
            _ => rng.random_range(0.2..4.0),
        };
        let top = bottom + rng.random_range(0.5..8.0);
        if kind == 3 {
            let (hx, hz) = (rng.random_range(0.2..3.0), rng.random_range(0.2..3.0));
            let mut pts = Vec::new();
            for k in 0..8 {
                let x = if k & 1 != 0 { cx + hx } else { cx - hx };
                let z = if k & 2 != 0 { cz + hz } else { cz - hz };
                let h = if k & 4 != 0 { top } else { bottom };
                pts.push(at(x, z, h));
            }
            out.push(RsfOcc { pts, solid: true });
        } else {
            let dir: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let half: f64 = rng.random_range(0.5..6.0);
            let (dx, dz) = (half * dir.cos(), half * dir.sin());
            let lean: f64 = if kind == 2 {
                rng.random_range(-0.5..0.5)
            } else {
                0.0
            };
            out.push(RsfOcc {
                pts: vec![
                    at(cx - dx, cz - dz, bottom),
                    at(cx + dx, cz + dz, bottom),
                    at(cx + dx + lean, cz + dz, top),
                    at(cx - dx + lean, cz - dz, top),
                ],
                solid: false,
            });
        }
    }
    out
}

/// Random boxes around the cell, as the occludees of the chart test.
fn random_rsf_boxes(rng: &mut Pcg64, up: usize, scale: f64, offset: DVec3) -> Vec<DAabb> {
    (0..60)
        .map(|_| {
            let ang: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let r: f64 = rng.random_range(2.5..60.0);
            let (cx, cz) = (r * ang.cos(), r * ang.sin());
            let (hx, hz) = (rng.random_range(0.05..2.0), rng.random_range(0.05..2.0));
            let y0: f64 = rng.random_range(-0.5..3.0);
            let y1 = y0 + rng.random_range(0.1..6.0);
            let (lo, hi) = if up == 1 {
                (
                    DVec3::new(cx - hx, y0, cz - hz),
                    DVec3::new(cx + hx, y1, cz + hz),
                )
            } else {
                (
                    DVec3::new(cx - hx, cz - hz, y0),
                    DVec3::new(cx + hx, cz + hz, y1),
                )
            };
            DAabb {
                min: lo * scale + offset,
                max: hi * scale + offset,
            }
        })
        .collect()
}

/// The GPU's charts (`shaders/rsf.wgsl`) against the CPU's `RayCharts` on random scenes:
/// inserts in calls of several sizes (some two in a row), box tests between them, at three
/// resolutions, both up axes, scaled ×10⁻³ and offset by 10⁵. The flags of every test and
/// every pixel's umbrae must be the same, and the counters too.
#[test]
fn rsf_charts_match_the_cpu() {
    let Some(b) = backend() else {
        return;
    };
    if !b.rsf_on_gpu() {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI's adapter ({}) must have SHADER_F64 for ray space factorization on the GPU",
            b.adapter().unwrap_or_default()
        );
        eprintln!("the adapter has no SHADER_F64: ray space factorization stays on the CPU");
        return;
    }
    let (mut hidden, mut written, mut tests) = (0, 0, 0);
    for case in 0..12u64 {
        let mut rng = Pcg64::seed_from_u64(0x5f5 + case);
        let up = 1 + (case % 2) as usize;
        let res = [32, 64, 96][(case % 3) as usize];
        let (scale, offset) = if case % 4 == 3 {
            (1e-3, DVec3::splat(1e5))
        } else {
            (1.0, DVec3::ZERO)
        };
        let e = |x: f64, h: f64, z: f64| {
            if up == 1 {
                DVec3::new(x, h, z)
            } else {
                DVec3::new(x, z, h)
            }
        };
        let half: f64 = rng.random_range(0.5..3.0);
        let cell = DAabb {
            min: e(-half, 0.0, -rng.random_range(0.5..3.0)) * scale + offset,
            max: e(half, rng.random_range(1.0..4.0), rng.random_range(0.5..3.0)) * scale + offset,
        };
        let occ = random_rsf_scene(&mut rng, up, scale, offset);
        let edges: Vec<Vec<(usize, usize)>> = occ
            .iter()
            .map(|o| {
                if o.solid {
                    hull_edges(&o.pts)
                } else {
                    Vec::new()
                }
            })
            .collect();
        let occluders: Vec<RsfOccluder> = occ
            .iter()
            .zip(&edges)
            .map(|(o, e)| RsfOccluder {
                points: o.pts.as_slice().into(),
                hull_edges: o.solid.then_some(e.as_slice()),
            })
            .collect();
        let mut cpu = RayCharts::new(&cell, up, res);
        let mut gpu = b.rsf_charts(&cell, up, res).unwrap();
        let mut start = 0;
        while start < occluders.len() {
            let end = (start + 1 + rng.random_range(0..12)).min(occluders.len());
            // Sometimes two insert calls in a row (as a dump's last parts go in).
            let mid = if rng.random_range(0..3) == 0 {
                (start + end) / 2
            } else {
                start
            };
            for r in [start..mid, mid..end] {
                RsfCharts::insert(&mut cpu, &occluders[r.clone()]).unwrap();
                gpu.insert(&occluders[r]).unwrap();
            }
            start = end;
            let boxes = random_rsf_boxes(&mut rng, up, scale, offset);
            // Objects of one box, then of a box with two pieces.
            let mut groups: Vec<_> = (0..boxes.len() - 3).map(|k| k..k + 1).collect();
            groups.push(boxes.len() - 3..boxes.len());
            let c = RsfCharts::hidden(&mut cpu, &boxes, &groups).unwrap();
            let g = gpu.hidden(&boxes, &groups).unwrap();
            assert_eq!(c, g, "case {case}: the hidden flags after {end} occluders");
            hidden += c.iter().filter(|&&h| h).count();
            tests += c.len();
        }
        let (cs, gs) = (
            RsfCharts::snapshot(&mut cpu).unwrap(),
            gpu.snapshot().unwrap(),
        );
        assert_eq!(cs.len(), gs.len());
        let differ = cs.iter().zip(&gs).filter(|(a, b)| a != b).count();
        assert_eq!(
            differ,
            0,
            "case {case}: {differ} of {} pixels differ; first: {:?}",
            cs.len(),
            cs.iter().zip(&gs).find(|(a, b)| a != b)
        );
        let (cw, gw) = (RsfCharts::work(&mut cpu).unwrap(), gpu.work().unwrap());
        assert_eq!(cw, gw, "case {case}: the counters");
        written += cw.pixels;
    }
    eprintln!("{tests} objects tested, {hidden} hidden; {written} pixels written");
    // The scenes exercise both answers and the inserts.
    assert!(hidden > 50 && hidden < tests - 50, "{hidden} of {tests}");
    assert!(written > 10_000, "{written}");
}

/// An engine's device without `SHADER_F64` keeps ray space factorization's charts on the
/// CPU — the same PVS as the CPU backend's — and one with it runs them on the device.
#[test]
fn an_engine_device_without_f64_keeps_the_charts_on_the_cpu() {
    let Some((device, queue)) =
        engine_device(GpuBackend::REQUIRED_FEATURES, wgpu::Limits::default())
    else {
        return;
    };
    let mut engine = GpuBackend::with_device(device, queue).unwrap();
    assert!(matches!(
        engine.set_rsf_on_gpu(true),
        Err(BackendError::MissingFeatures { .. })
    ));
    assert!(!engine.rsf_on_gpu());
    assert!(!engine.rsf_on_device());
    let (scene, cells, settings) = rsf_city(2);
    let before = engine.counters().unwrap();
    let g = bake(&scene, &cells, &settings, &engine, None).unwrap();
    let passes = engine.counters().unwrap().since(&before).passes;
    let planes: usize = g.cells.iter().map(|c| c.planes).sum();
    assert_eq!(
        passes, planes,
        "only the planes' render passes ran on the device"
    );
    let c = bake(&scene, &cells, &settings, &CpuBackend::new(), None).unwrap();
    for (gc, cc) in g.cells.iter().zip(&c.cells) {
        assert_eq!(gc.visible, cc.visible);
    }
    if let Some((device, queue)) = engine_device(
        GpuBackend::REQUIRED_FEATURES | wgpu::Features::SHADER_F64,
        wgpu::Limits::default(),
    ) {
        let mut with_f64 = GpuBackend::with_device(device, queue).unwrap();
        assert!(!with_f64.rsf_on_gpu(), "the CPU's charts unless asked");
        with_f64.set_rsf_on_gpu(true).unwrap();
        assert!(with_f64.rsf_on_gpu());
    }
}

/// The first two cells of `data/NAME_cells.json`, written to `dir` (created); their path.
fn two_demo_cells(dir: &Path, name: &str) -> std::path::PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::fs::create_dir_all(dir).unwrap();
    let cells: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(root.join(format!("data/{name}_cells.json"))).unwrap(),
    )
    .unwrap();
    let two = serde_json::json!({ "cells": cells["cells"].as_array().unwrap()[..2] });
    let path = dir.join("cells.json");
    std::fs::write(&path, two.to_string()).unwrap();
    path
}

/// Each cell's visible set in the PVS document at `path`.
fn visible_sets(path: &Path) -> Vec<serde_json::Value> {
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    doc["cells"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["visible"].clone())
        .collect()
}

/// `bake --backend gpu` says where ray space factorization's charts ran (the CPU unless
/// `--rsf-on-gpu`), and writes the same PVS as `--backend cpu`.
#[test]
fn the_bake_command_says_where_the_charts_run() {
    let Some(b) = backend() else {
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = std::env::temp_dir().join(format!("umbrasweep-gpu-cli-{}", std::process::id()));
    let cells_path = two_demo_cells(&dir, "demo_city");
    let mut pvs = Vec::new();
    for (backend, on_gpu) in [("gpu", false), ("gpu", true), ("cpu", false)] {
        let out_path = dir.join(format!("{backend}-{on_gpu}.json"));
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_umbrasweep"))
            .arg("bake")
            .arg(root.join("data/demo_city.obj"))
            .arg("--cells")
            .arg(&cells_path)
            .args(["--backend", backend, "--rsf", "-o"])
            .arg(&out_path)
            .args(on_gpu.then_some("--rsf-on-gpu"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{err}");
        let line = err
            .lines()
            .find(|l| l.starts_with("rsf "))
            .expect("the rsf line");
        match (backend, on_gpu) {
            ("gpu", true) => assert!(line.ends_with("(on the GPU)"), "{line}"),
            ("gpu", false) => assert!(line.contains("charts on the CPU"), "{line}"),
            _ => assert!(!line.contains("GPU"), "{line}"),
        }
        pvs.push(visible_sets(&out_path));
    }
    // The shared backend asks for the device's charts; a bake's own backend does not.
    assert!(b.rsf_on_gpu(), "lavapipe has SHADER_F64");
    assert_eq!(pvs[0], pvs[2]);
    assert_eq!(pvs[1], pvs[2]);
    std::fs::remove_dir_all(&dir).ok();
}

/// `bake --backend gpu` answers separate planes' occludee tests on the device and reads back
/// a small share of what `--tests-on-cpu` (every map back) does, with the same PVS as both
/// that and the CPU backend.
#[test]
fn the_bake_command_tests_occludees_on_the_device() {
    if backend().is_none() {
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = std::env::temp_dir().join(format!("umbrasweep-gpu-tests-{}", std::process::id()));
    let cells_path = two_demo_cells(&dir, "demo_city");
    let mut pvs = Vec::new();
    let mut read_back = Vec::new();
    for (backend, flag) in [
        ("gpu", None),
        ("gpu", Some("--tests-on-cpu")),
        ("cpu", None),
    ] {
        let out_path = dir.join(format!("{backend}-{}.json", flag.is_some()));
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_umbrasweep"))
            .arg("bake")
            .arg(root.join("data/demo_city.obj"))
            .arg("--cells")
            .arg(&cells_path)
            .args(["--backend", backend, "--no-rsf", "-o"])
            .arg(&out_path)
            .args(flag)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{err}");
        if backend == "gpu" {
            // "… KB uploaded, N KB read back; …"
            let line = err
                .lines()
                .find(|l| l.contains("KB read back"))
                .expect(&err);
            let kb: f64 = line
                .split(" KB read back")
                .next()
                .and_then(|s| s.rsplit(' ').next())
                .and_then(|s| s.parse().ok())
                .unwrap_or_else(|| panic!("{line}"));
            read_back.push(kb);
        }
        pvs.push(visible_sets(&out_path));
    }
    eprintln!(
        "KB read back per cell: on the device {}, on the CPU {}",
        read_back[0], read_back[1]
    );
    assert!(
        read_back[1] > 1000.0,
        "maps come back with --tests-on-cpu: {read_back:?}"
    );
    assert!(read_back[0] * 20.0 < read_back[1], "{read_back:?}");
    assert_eq!(pvs[0], pvs[2]);
    assert_eq!(pvs[1], pvs[2]);
    std::fs::remove_dir_all(&dir).ok();
}

// ---------------------------------------------------------------------------------------------
// Views counted on the GPU (`GpuProjection::Counting`)

/// A backend of the test's own (its counters are the test's) with
/// [`GpuProjection::Counting`], or `None` (after printing why) without an adapter outside CI.
/// Its adapter must have `SHADER_F64` in CI (lavapipe has it).
fn counting_backend() -> Option<GpuBackend> {
    backend()?;
    let mut b = GpuBackend::new().expect("a second device");
    match b.set_projection(GpuProjection::Counting) {
        Ok(()) => Some(b),
        Err(e) => no_adapter(&format!("no counting projection: {e}")),
    }
}

/// [`assert_close_to_the_cpu`] on the counting backend, and the views of every occluder of at
/// most 8 points went to the GPU (none was set up on the CPU).
fn assert_counted_close_to_the_cpu(b: &GpuBackend, jobs: &[PlaneJob], what: &str) {
    let before = b.total_stats();
    assert_close_to_the_cpu(b, jobs, what);
    let after = b.total_stats();
    let small = jobs
        .iter()
        .flat_map(|j| (0..j.occluders.len()).map(|k| j.occluders.get(k).len()))
        .filter(|&n| (3..=8).contains(&n))
        .count();
    assert_eq!(
        after.counted - before.counted,
        small,
        "{what}: counted on the GPU"
    );
    assert!(small > 0, "{what}: the jobs have small occluders");
}

#[test]
fn counted_views_match_the_cpu_for_every_shape() {
    let Some(b) = &counting_backend() else { return };
    assert_eq!(b.projection(), GpuProjection::Counting);
    for (seed, shape) in [(1, Shape::Triangle), (2, Shape::Quad), (3, Shape::Box)] {
        let jobs = random_jobs(seed, shape, 60, &[16, 32, 64, 128, 256]);
        assert_counted_close_to_the_cpu(b, &jobs, &format!("counted {shape:?}"));
    }
}

/// A cell a thousandth of a unit wide: its 8 views of each occluder nearly coincide, so the
/// views pass clips the box by bundles of almost parallel, almost coincident edges and must
/// drop none that some pixel centre can still fail (and shrink the drawn box to no fewer
/// pixels than pass): the CPU's coverage.
#[test]
fn counted_views_of_a_tiny_cell_keep_the_contract() {
    let Some(b) = &counting_backend() else { return };
    let mut jobs = random_jobs(11, Shape::Triangle, 60, &[64, 256]);
    jobs.extend(random_jobs(12, Shape::Quad, 60, &[128]));
    for j in &mut jobs {
        let c = 0.5 * (j.frame.cell.min + j.frame.cell.max);
        j.frame.cell.min = c - DVec3::splat(5e-4);
        j.frame.cell.max = c + DVec3::splat(5e-4);
    }
    assert_counted_close_to_the_cpu(b, &jobs, "counted, tiny cell");
}

/// The counted draw keeps views of different occluders apart and the least Depth, as the
/// clipped one does (the same analytic checks).
#[test]
fn counted_halves_do_not_add_up_and_minimum_depth_wins() {
    let Some(b) = &counting_backend() else { return };
    check_halves_and_minimum_depth(b);
}

/// Stretched maps, a cell 10⁵ from the origin, and occluders of 12 points (set up on the CPU)
/// in the same planes as counted ones: all keep the CPU's coverage.
#[test]
fn counted_views_hold_on_stretched_far_and_mixed_planes() {
    let Some(b) = &counting_backend() else { return };
    let jobs = stretched_jobs();
    assert_counted_close_to_the_cpu(b, &jobs, "counted, stretched");

    let shift = DVec3::new(1e5, -2e5, 3e5);
    let mut far = random_jobs(6, Shape::Triangle, 60, &[64, 256]);
    for j in &mut far {
        let (ua, va) = j.frame.uv_axes();
        let a = j.frame.axis;
        j.frame.cell.min += shift;
        j.frame.cell.max += shift;
        j.frame.position += shift[a];
        j.frame.rect_min += DVec2::new(shift[ua], shift[va]);
        j.frame.rect_max += DVec2::new(shift[ua], shift[va]);
        let moved: Vec<Vec<DVec3>> = (0..j.occluders.len())
            .map(|k| j.occluders.get(k).iter().map(|&p| p + shift).collect())
            .collect();
        j.occluders = OccluderSet::default();
        for m in moved {
            j.occluders.push(m);
        }
    }
    assert_counted_close_to_the_cpu(b, &far, "counted, 1e5 away");

    let mut rng = Pcg64::seed_from_u64(8);
    let mut mixed = random_jobs(7, Shape::Triangle, 30, &[64, 128]);
    for j in &mut mixed {
        for _ in 0..20 {
            // A planar convex 12-gon beyond the face: more points than the views pass takes.
            let (cu, cv) = (rng.random_range(-8.0..8.0), rng.random_range(-8.0..8.0));
            let (r, d) = (rng.random_range(0.5..5.0), rng.random_range(1.0..20.0));
            let poly: Vec<DVec3> = (0..12)
                .map(|k| {
                    let t = k as f64 * std::f64::consts::TAU / 12.0;
                    point(&j.frame, cu + r * t.cos(), cv + r * t.sin(), d)
                })
                .collect();
            j.occluders.push(poly);
        }
    }
    let before = b.total_stats();
    assert_counted_close_to_the_cpu(b, &mixed, "counted with 12-gons");
    let after = b.total_stats();
    assert!(
        after.occluders > before.occluders,
        "the 12-gons were set up on the CPU and drawn: {after:?}"
    );
}

/// Occluders the views pass must reject — a point behind a corner, a sliver thinner than a
/// pixel, one entirely off the plane — cover nothing; reprojections and large planes split
/// into several submissions keep the CPU's maps.
#[test]
fn counted_views_reject_what_the_cpu_rejects_and_keep_sweeps_and_waves() {
    let Some(b) = &counting_backend() else { return };
    let f = frame(64, 0, true, 0.5);
    let mut occ = OccluderSet::default();
    occ.push([
        point(&f, 0.0, 0.0, -2.0),
        point(&f, 5.0, 0.0, 5.0),
        point(&f, 0.0, 5.0, 5.0),
    ]);
    occ.push([
        point(&f, -5.0, 0.0, 5.0),
        point(&f, 5.0, 0.001, 5.0),
        point(&f, 5.0, 0.0, 5.0),
    ]);
    occ.push([
        point(&f, 30.0, 30.0, 5.0),
        point(&f, 40.0, 30.0, 5.0),
        point(&f, 30.0, 40.0, 5.0),
    ]);
    let job = PlaneJob {
        frame: f,
        occluders: occ,
        slices: vec![],
        reproject: Vec::new(),
    };
    let maps = b.render(std::slice::from_ref(&job)).unwrap();
    assert_eq!(maps[0], DepthMap::new(64), "nothing covered");
    assert_eq!(
        b.last_stats().counted,
        3,
        "all three went to the views pass"
    );

    let jobs = reprojection_jobs(44, &[32, 128]);
    let gpu_maps = b.render(&jobs).unwrap();
    for (job, g) in jobs.iter().zip(&gpu_maps) {
        compare(job, g, &cpu::render_job(job));
    }
    let big = random_jobs(5, Shape::Quad, 10, &[2048, 2048]);
    let d = run_and_compare(b, &big);
    assert!(b.last_stats().submissions > 1, "{:?}", b.last_stats());
    assert!(d.cpu_only * 100 <= d.covered.max(1), "{d:?}");
}

/// A whole bake of a small forest with the sweep gives the same PVS with counted views as on
/// the CPU.
#[test]
fn counted_views_bake_the_same_pvs() {
    let Some(b) = &counting_backend() else { return };
    let (scene, c, g) = sweep_forest_bakes(b);
    assert!(
        b.total_stats().counted > 0,
        "the bake counted views on the GPU"
    );
    // The scene's parts kept on the device (the default) or every occluder's points sent
    // with its plane: the same PVS, more bytes up.
    let Some(mut inline) = counting_backend() else {
        return;
    };
    inline.set_resident_parts(false);
    let (_, _, g_inline) = sweep_forest_bakes(&inline);
    let (resident, sent) = (b.total_stats(), inline.total_stats());
    eprintln!("parts resident: {resident:?}\npoints sent: {sent:?}");
    assert_eq!(resident.counted, sent.counted);
    assert!(
        resident.bytes_uploaded < sent.bytes_uploaded,
        "resident: {} bytes up, sent: {}",
        resident.bytes_uploaded,
        sent.bytes_uploaded
    );
    for (k, ((cc, gc), ic)) in c
        .cells
        .iter()
        .zip(&g.cells)
        .zip(&g_inline.cells)
        .enumerate()
    {
        assert!(
            cc.visible.len() < scene.objects.len(),
            "cell {k} culls something"
        );
        assert_eq!(cc.visible, gc.visible, "cell {k}");
        assert_eq!(cc.planes, gc.planes, "cell {k}");
        assert_eq!(cc.visible, ic.visible, "cell {k}, points sent");
    }
}

/// Counted occluders that name the bake's resident parts (`upload_occluder_parts`) give the
/// maps their points sent whole give, bit for bit: a shuffled table with as many decoy parts
/// (a wrong index reads another occluder), every fifth occluder sent whole (`NO_PART`), one in
/// ten naming a part beyond the table or one of another point count (sent whole), and a
/// replaced table whose stale jobs send their points. Only the named points stay home: the
/// first job naming a part sends it to the table (from its own points), and asked again it
/// uploads 24 bytes a named point less than sending them.
#[test]
fn resident_parts_project_as_points_sent_whole() {
    let Some(b) = &counting_backend() else { return };
    let mut rng = Pcg64::seed_from_u64(52);
    let mut jobs = random_jobs(51, Shape::Quad, 40, &[16, 64, 256]);
    jobs.extend(random_jobs(53, Shape::Triangle, 40, &[64]));
    let whole_maps = b.render(&jobs).unwrap();
    // The table: every occluder's points and as many decoys (triangles and quads), shuffled.
    let table = |rng: &mut Pcg64| {
        // (Job and occluder, or a decoy; the points.)
        type Entry = (Option<(usize, usize)>, Vec<DVec3>);
        let mut entries: Vec<Entry> = Vec::new();
        for (j, job) in jobs.iter().enumerate() {
            for k in 0..job.occluders.len() {
                entries.push((Some((j, k)), job.occluders.get(k).to_vec()));
                let shape = if k % 2 == 0 {
                    Shape::Quad
                } else {
                    Shape::Triangle
                };
                entries.push((None, random_occluder(rng, &job.frame, shape)));
            }
        }
        for k in (1..entries.len()).rev() {
            entries.swap(k, rng.random_range(0..=k));
        }
        let mut ids: Vec<Vec<u32>> = jobs.iter().map(|j| vec![0; j.occluders.len()]).collect();
        let (mut points, mut spans) = (Vec::new(), Vec::new());
        for (at, (of, pts)) in entries.iter().enumerate() {
            if let Some((j, k)) = of {
                ids[*j][*k] = at as u32;
            }
            let start = points.len() as u32;
            points.extend_from_slice(pts);
            spans.push((start, points.len() as u32));
        }
        (points, spans, ids)
    };
    // A decoy part of another point count than occluder `k` of job `j`, if any.
    let other_count = |spans: &[(u32, u32)], n: usize| {
        spans
            .iter()
            .position(|&(a, b)| (b - a) as usize != n)
            .map(|p| p as u32)
    };
    let named = |generation: Option<u64>, spans: &[(u32, u32)], ids: &[Vec<u32>]| {
        let mut resident_points = 0usize;
        let jobs: Vec<PlaneJob> = (jobs.iter().zip(ids))
            .map(|(job, ids)| {
                let mut job = job.clone();
                let occ = &mut job.occluders;
                occ.table = generation;
                occ.parts = (0..occ.len())
                    .map(|k| {
                        let n = occ.get(k).len();
                        match k % 10 {
                            2 | 7 => NO_PART,
                            4 => spans.len() as u32 + k as u32,
                            9 => other_count(spans, n).unwrap_or(NO_PART),
                            _ => {
                                resident_points += n;
                                ids[k]
                            }
                        }
                    })
                    .collect();
                job
            })
            .collect();
        (jobs, resident_points)
    };
    let uploaded = || b.counters().unwrap().bytes_uploaded;
    let render = |jobs: &[PlaneJob]| {
        let before = uploaded();
        let maps = b.render(jobs).unwrap();
        (maps, uploaded() - before)
    };
    let (points1, spans1, ids1) = table(&mut rng);
    let before = uploaded();
    let g1 = b.upload_occluder_parts(&points1, &spans1).unwrap();
    assert!(g1.is_some(), "the counting backend keeps the parts");
    assert_eq!(uploaded(), before, "the parts go up only when named");
    let (plain, plain_bytes) = render(&named(None, &spans1, &ids1).0);
    let (jobs1, resident_points) = named(g1, &spans1, &ids1);
    let (first, first_bytes) = render(&jobs1);
    let (again, again_bytes) = render(&jobs1);
    // A new table: jobs naming the first send their points.
    let (points2, spans2, ids2) = table(&mut rng);
    let g2 = b.upload_occluder_parts(&points2, &spans2).unwrap();
    assert!(g2.is_some() && g2 != g1, "{g1:?} then {g2:?}");
    let (stale, stale_bytes) = render(&jobs1);
    let (renamed, _) = render(&named(g2, &spans2, &ids2).0);
    for (what, maps) in [
        ("no table", &plain),
        ("named", &first),
        ("named again", &again),
        ("stale", &stale),
        ("renamed", &renamed),
    ] {
        for (j, (w, m)) in whole_maps.iter().zip(maps).enumerate() {
            assert_eq!(w, m, "{what}: job {j}");
        }
    }
    assert!(
        whole_maps
            .iter()
            .any(|m| m.depth.iter().any(|d| d.is_finite())),
        "the occluders cover something"
    );
    eprintln!(
        "bytes up: plain {plain_bytes}, named {first_bytes}, again {again_bytes}, stale \
         {stale_bytes}; {resident_points} points named"
    );
    assert!(resident_points > 1_000, "{resident_points} points named");
    assert_eq!(
        plain_bytes - again_bytes,
        24 * resident_points as u64,
        "asked again, only the named points stay home"
    );
    assert_eq!(
        first_bytes - again_bytes,
        24 * resident_points as u64,
        "the first call sends each named part to the table, once"
    );
    assert_eq!(stale_bytes, plain_bytes, "a stale table sends the points");
}

/// Threads rendering jobs whose counted occluders name parts of one resident table, each call
/// naming parts no call named before (so each sends them while other threads submit), get the
/// maps of points sent whole: a part is never read before its first write lands (the table is
/// made mapped, hence initialised: see `resident_boxes_sent_from_many_threads_…`).
#[test]
fn resident_parts_sent_from_many_threads_are_never_read_unwritten() {
    let Some(b) = &counting_backend() else { return };
    let jobs = random_jobs(61, Shape::Quad, 30, &[32]);
    let whole = b.render(&jobs).unwrap();
    const THREADS: usize = 4;
    const CALLS: usize = 25;
    let n_occ: Vec<usize> = jobs.iter().map(|j| j.occluders.len()).collect();
    let per_call: usize = n_occ.iter().sum();
    // Part of occluder `k` of job `j` in call `c` of thread `t`: the threads' parts interleave.
    let part = |c: usize, t: usize, j: usize, k: usize| {
        let before: usize = n_occ[..j].iter().sum();
        ((c * per_call + before + k) * THREADS + t) as u32
    };
    let mut wrong = 0;
    // Each round a fresh table (the race is a matter of timing: a table made unmapped failed
    // 3 runs of 3 with six rounds, 1 of 3 with two).
    for _round in 0..6 {
        let (mut points, mut spans) = (Vec::new(), Vec::new());
        for c in 0..CALLS {
            for (j, job) in jobs.iter().enumerate() {
                for k in 0..job.occluders.len() {
                    for t in 0..THREADS {
                        assert_eq!(spans.len() as u32, part(c, t, j, k));
                        let start = points.len() as u32;
                        points.extend_from_slice(job.occluders.get(k));
                        spans.push((start, points.len() as u32));
                    }
                }
            }
        }
        let generation = b.upload_occluder_parts(&points, &spans).unwrap();
        assert!(generation.is_some(), "the counting backend keeps the parts");
        wrong += std::thread::scope::<_, usize>(|s| {
            let handles: Vec<_> = (0..THREADS)
                .map(|t| {
                    let (jobs, whole) = (&jobs, &whole);
                    s.spawn(move || {
                        let mut wrong = 0;
                        for c in 0..CALLS {
                            let named: Vec<PlaneJob> = (jobs.iter().enumerate())
                                .map(|(j, job)| {
                                    let mut job = job.clone();
                                    job.occluders.table = generation;
                                    job.occluders.parts = (0..job.occluders.len())
                                        .map(|k| part(c, t, j, k))
                                        .collect();
                                    job
                                })
                                .collect();
                            let maps = b.render(&named).unwrap();
                            wrong += maps.iter().zip(whole).filter(|(m, w)| m != w).count();
                        }
                        wrong
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).sum()
        });
    }
    assert_eq!(wrong, 0, "{wrong} maps read a part before it was written");
}

/// Without `SHADER_F64` the counting projection is refused, naming the feature, and the
/// backend keeps the clipped one.
#[test]
fn counting_needs_shader_f64() {
    let Some((device, queue)) =
        engine_device(GpuBackend::REQUIRED_FEATURES, wgpu::Limits::default())
    else {
        return;
    };
    let mut engine = GpuBackend::with_device(device, queue).expect("a backend on it");
    match engine.set_projection(GpuProjection::Counting) {
        Err(e @ BackendError::MissingFeatures { missing }) => {
            assert_eq!(missing, wgpu::Features::SHADER_F64);
            assert!(e.to_string().contains("SHADER_F64"), "{e}");
        }
        other => panic!("expected a missing feature, got {other:?}"),
    }
    assert_eq!(engine.projection(), GpuProjection::Clipped);
    assert!(engine.set_projection(GpuProjection::Clipped).is_ok());
}

/// `bake --gpu-projection counting` says so and bakes the CPU's PVS; an unknown projection is
/// refused naming both choices.
#[test]
fn the_bake_command_counts_views_on_request() {
    if counting_backend().is_none() {
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = std::env::temp_dir().join(format!("umbrasweep-gpu-count-{}", std::process::id()));
    let cells_path = two_demo_cells(&dir, "demo_forest");
    let bake = |args: &[&str], out_path: &Path| {
        std::process::Command::new(env!("CARGO_BIN_EXE_umbrasweep"))
            .arg("bake")
            .arg(root.join("data/demo_forest.obj"))
            .arg("--cells")
            .arg(&cells_path)
            .args(args)
            .arg("-o")
            .arg(out_path)
            .output()
            .unwrap()
    };
    let mut pvs = Vec::new();
    for (name, args) in [
        (
            "counting",
            &["--backend", "gpu", "--gpu-projection", "counting"][..],
        ),
        (
            "counting-points-sent",
            &[
                "--backend",
                "gpu",
                "--gpu-projection",
                "counting",
                "--occluders-inline",
            ][..],
        ),
        ("cpu", &["--backend", "cpu"][..]),
    ] {
        let out_path = dir.join(format!("{name}.json"));
        let out = bake(args, &out_path);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{err}");
        let line = err
            .lines()
            .find(|l| l.starts_with("backend "))
            .expect("the backend line");
        assert_eq!(
            line.contains("counting projections"),
            name.starts_with("counting"),
            "{line}"
        );
        pvs.push(visible_sets(&out_path));
    }
    assert_eq!(pvs[0], pvs[2]);
    assert_eq!(pvs[1], pvs[2]);
    let bad = dir.join("bad.json");
    let out = bake(&["--backend", "gpu", "--gpu-projection", "stencil"], &bad);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("clipped") && err.contains("counting"), "{err}");
    assert!(!bad.exists(), "nothing written");
    std::fs::remove_dir_all(&dir).ok();
}

// ---------------------------------------------------------------------------------------------
// Reprojection tables kept on the device

/// Only the reprojections of `job`, no occluders or slices (the map is exactly the CPU's).
fn sweeps_only(job: &PlaneJob) -> PlaneJob {
    PlaneJob {
        frame: job.frame.clone(),
        occluders: OccluderSet::default(),
        slices: vec![],
        reproject: job.reproject.clone(),
    }
}

/// A source reprojected again in a later call is taken from the device, not uploaded again,
/// and the maps stay the CPU's bit for bit.
#[test]
fn a_source_reprojected_again_is_not_uploaded_again() {
    if backend().is_none() {
        return;
    }
    let b = GpuBackend::new().expect("a backend of the test's own");
    let jobs: Vec<PlaneJob> = reprojection_jobs(46, &[64])
        .iter()
        .map(sweeps_only)
        .collect();
    let check = |what: &str| {
        let maps = b.render(&jobs).unwrap();
        for (k, (job, m)) in jobs.iter().zip(&maps).enumerate() {
            assert_bits_equal(m, &cpu::render_job(job), &format!("{what}, job {k}"));
        }
        b.last_stats()
    };
    let first = check("first call");
    assert!(first.tables_uploaded > 0, "{first:?}");
    assert_eq!(first.tables_reused, 0, "{first:?}");
    let second = check("second call");
    assert_eq!(second.tables_uploaded, 0, "{second:?}");
    assert_eq!(second.tables_reused, first.tables_uploaded, "{second:?}");
    assert!(
        second.bytes_uploaded < first.bytes_uploaded / 4,
        "{first:?} {second:?}"
    );
}

/// New sources of the same size with other umbras, some made where a dropped one was (the
/// allocator may reuse the address), others beside ones still alive: each new one's table is
/// built, never another's reused; a source still alive is reused.
#[test]
fn a_new_source_never_takes_an_old_sources_table() {
    if backend().is_none() {
        return;
    }
    let b = GpuBackend::new().expect("a backend of the test's own");
    let mut rng = Pcg64::seed_from_u64(47);
    let planes = sweep_planes(&mut rng, 32, 2, true, &[0.5, 1.0]);
    let (src, dst) = (&planes[0], &planes[1]);
    let mut kept = Vec::new();
    for round in 0..40 {
        let mut map = DepthMap::for_frame(src);
        // A different umbra each round: one quarter of the source, in turn.
        let (w, h) = (src.width as usize, src.height as usize);
        for j in 0..h {
            for i in 0..w {
                let quarter = (2 * j / h) * 2 + 2 * i / w;
                if quarter == round % 4 {
                    map.depth[j * w + i] = -1.0;
                }
            }
        }
        let job = PlaneJob {
            frame: dst.clone(),
            occluders: OccluderSet::default(),
            slices: vec![],
            reproject: vec![Reprojection::new(src, dst, Arc::new(map))],
        };
        let gpu_map = &b.render(std::slice::from_ref(&job)).unwrap()[0];
        let cpu_map = cpu::render_job(&job);
        assert!(
            cpu_map.covered() > 0,
            "round {round}: the quarter reprojects"
        );
        assert_bits_equal(gpu_map, &cpu_map, &format!("round {round}"));
        assert_eq!(b.last_stats().tables_uploaded, 1, "round {round}");
        if round % 3 == 0 {
            kept.push((job, cpu_map));
        }
    }
    // The sources kept alive are still on the device, each with its own table.
    for (k, (job, cpu_map)) in kept.iter().enumerate() {
        let gpu_map = &b.render(std::slice::from_ref(job)).unwrap()[0];
        assert_bits_equal(gpu_map, cpu_map, &format!("kept {k}"));
        let st = b.last_stats();
        assert_eq!((st.tables_uploaded, st.tables_reused), (0, 1), "kept {k}");
    }
}

/// A strip of ground from a cell's face to its plane (Depth −0): projected from the corners
/// level with it, its views reach ~5,000 px off the map, and clipping once left two vertices
/// 1.2·10⁻⁷ px apart with the edge between them pointing backwards, whose erosion cut the whole
/// Projection away (found by `--gpu-projection counting`, whose per-view hulls covered it).
/// Both backends and both projections cover the pixel, 21 px inside every view.
#[test]
fn far_vertices_of_a_ground_strip_do_not_uncover_it() {
    let f = PlaneFrame {
        cell: DAabb {
            min: DVec3::new(18.5, 1.2000000476837158, 3.296069383621216),
            max: DVec3::new(19.5, 2.200000047683716, 4.296069145202637),
        },
        axis: 2,
        positive: false,
        position: 2.296069622039795,
        rect_min: DVec2::new(16.75000035762787, -0.5499995946884155),
        rect_max: DVec2::new(21.24999964237213, 3.949999690055847),
        width: 256,
        height: 256,
    };
    let strip = [
        DVec3::new(40.160701751708984, 0.0, 3.296069280281692),
        DVec3::new(40.160701751708984, 0.0, 2.296069622039795),
        DVec3::new(-40.160701751708984, 0.0, 2.296069622039795),
        DVec3::new(-40.160701751708984, 0.0, 3.296069280281692),
    ];
    let slack = coverage::contract_slack(&f, &strip, 99, 9);
    assert!(
        slack > 20.0,
        "pixel (99, 9) is deep inside all 8 views: {slack}"
    );
    let job = one_occluder_job(f, &strip);
    let k = 9 * 256 + 99;
    let map = cpu::render_job(&job);
    assert!(map.depth[k] <= 0.0, "CPU covers {} pixels", map.covered());
    let Some(b) = backend() else { return };
    let clipped = &b.render(std::slice::from_ref(&job)).unwrap()[0];
    assert!(clipped.depth[k] <= 0.0);
    assert_eq!(compare(&job, clipped, &map).gpu_only, 0);
    let Some(counting) = &counting_backend() else {
        return;
    };
    let counted = &counting.render(std::slice::from_ref(&job)).unwrap()[0];
    assert!(counted.depth[k] <= 0.0);
    compare(&job, counted, &map);
}

/// Degenerate occluders on the counted path: collinear points, all points equal, a quad with a
/// repeated vertex (its hull a triangle), a sliver at a grazing angle to the plane, and a
/// triangle touching a corner's plane: each covers exactly what the CPU's contract allows.
#[test]
fn counted_views_of_degenerate_occluders_keep_the_contract() {
    let Some(b) = &counting_backend() else { return };
    let f = frame(128, 1, false, 0.5);
    let p = |u: f64, v: f64, d: f64| point(&f, u, v, d);
    let mut occ = OccluderSet::default();
    occ.push([p(-4.0, 0.0, 5.0), p(0.0, 0.0, 5.0), p(4.0, 0.0, 5.0)]);
    occ.push([p(1.0, 1.0, 5.0), p(1.0, 1.0, 5.0), p(1.0, 1.0, 5.0)]);
    occ.push([
        p(-3.0, -3.0, 4.0),
        p(3.0, -3.0, 4.0),
        p(3.0, -3.0, 4.0),
        p(-3.0, 3.0, 4.0),
    ]);
    occ.push([p(2.0, 2.0, 1.0), p(8.0, 2.0, 21.0), p(8.0, 2.3, 21.0)]);
    // Its first point a hair beyond the face: views from the corners reach far off the map.
    occ.push([p(-9.0, 3.0, 1e-9), p(9.0, 3.0, 1e-9), p(0.0, 8.0, 6.0)]);
    let job = PlaneJob {
        frame: f,
        occluders: occ,
        slices: vec![],
        reproject: Vec::new(),
    };
    let cpu_map = cpu::render_job(&job);
    let gpu_map = &b.render(std::slice::from_ref(&job)).unwrap()[0];
    assert_eq!(b.last_stats().counted, 5);
    let d = compare(&job, gpu_map, &cpu_map);
    assert!(
        cpu_map.covered() > 100,
        "the repeated-vertex quad covers: {d:?}"
    );
    assert!(d.cpu_only * 50 <= d.covered, "{d:?}");
}
