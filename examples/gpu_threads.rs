//! Cells baked on the GPU backend from 1, 2, 4, … threads at once, with the threads' submissions
//! and polls serial (each poll blocking, one thread at a time: `GpuBackend::set_serial_polls`,
//! how every GPU path waited before December 2026) and concurrent (the default): wall time,
//! cells per second and the device's counters per cell for each, whether every bake gave the
//! PVS of the first, and per thread count the concurrent way's speed-up. On a real GPU the
//! concurrent way should scale with the threads where the serial way cannot (its device idles
//! between one thread's submission and the next); on lavapipe, whose queue runs one submission
//! at a time on the same two cores, it cannot show.
//!
//! `cargo run --release --example gpu_threads -- SCENE CELLS [THREADS] [rsf] [sampling]`
//! (`THREADS`: a comma-separated list, default `1,2,4,8,16` up to the machine's cores; `rsf`:
//! ray space factorization's charts on the device, `--rsf-on-gpu`, its many small
//! submissions; `sampling`: the shrunk-occluder sampler, `--sweep --sampling`).

use std::path::Path;
use std::time::Instant;
use umbrasweep::backend::RasterBackend;
use umbrasweep::backend::gpu::GpuBackend;
use umbrasweep::bake::{BakeSettings, SweepChoice, bake};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: gpu_threads SCENE CELLS [THREADS] [rsf] [sampling]");
        std::process::exit(2);
    }
    let scene = umbrasweep::scene::load(Path::new(&args[1])).expect("SCENE");
    let cells = umbrasweep::cells::load_json(Path::new(&args[2])).expect("CELLS");
    let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
    let threads: Vec<usize> = match args
        .get(3)
        .filter(|a| a.starts_with(|c: char| c.is_ascii_digit()))
    {
        Some(list) => list
            .split(',')
            .map(|t| t.parse().expect("THREADS"))
            .collect(),
        None => [1, 2, 4, 8, 16]
            .into_iter()
            .filter(|&t| t <= cores)
            .collect(),
    };
    let rsf = args.iter().any(|a| a == "rsf");
    let mut settings = BakeSettings::default();
    if args.iter().any(|a| a == "sampling") {
        settings.sweep = SweepChoice::On;
        settings.sampling = SweepChoice::On;
    }
    let mut first = None;
    let mut walls = Vec::new();
    for serial in [true, false] {
        let way = if serial { "serial" } else { "concurrent" };
        for &t in &threads {
            // A backend per run: its counters are the run's.
            let mut gpu = GpuBackend::new().expect("GPU backend");
            gpu.set_serial_polls(serial);
            if rsf {
                gpu.set_rsf_on_gpu(true).expect("a device with SHADER_F64");
            }
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .expect("thread pool");
            let start = Instant::now();
            let result = pool
                .install(|| bake(&scene, &cells, &settings, &gpu, None))
                .expect("bake");
            let wall = start.elapsed().as_secs_f64();
            let n = cells.len();
            let visible: Vec<_> = result.cells.iter().map(|c| c.visible.clone()).collect();
            let same = match &first {
                None => {
                    first = Some(visible);
                    "first"
                }
                Some(f) if *f == visible => "same PVS",
                Some(_) => "PVS DIFFERS",
            };
            println!(
                "{} ({way}), {t:>2} threads: {wall:.2} s, {:.2} cells/s; {same}\n    {}",
                gpu.adapter_info().name,
                n as f64 / wall,
                gpu.stats_summary(n).unwrap_or_default(),
            );
            walls.push(wall);
        }
    }
    // Cells per second of the concurrent way over the serial way's, per thread count.
    let (serial, concurrent) = walls.split_at(threads.len());
    for ((t, s), c) in threads.iter().zip(serial).zip(concurrent) {
        println!(
            "{t:>2} threads: concurrent {:.2}× the serial way's cells per second",
            s / c
        );
    }
}
