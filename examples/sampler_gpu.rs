//! The sampler's hemicube on the CPU and on the GPU (`GpuSampler`) from the same random points
//! of a cell's faces: objects hidden by each, disagreements, and time per point (the GPU's
//! split into the CPU's set-up and the submission that draws and tests).
//! `cargo run --release --example sampler_gpu -- SCENE CELLS CELL EPS RES N`.

mod common;

use glam::DVec3;
use std::time::{Duration, Instant};
use umbrasweep::backend::gpu::GpuBackend;
use umbrasweep::backend::gpu::sampler::{GpuSampler, GpuSamplerScene};
use umbrasweep::sampler::{BoxTest, Hemicube};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 7 {
        eprintln!("usage: sampler_gpu SCENE CELLS CELL EPS RES N");
        std::process::exit(2);
    }
    let scene = umbrasweep::scene::load(std::path::Path::new(&args[1])).expect("scene");
    let cells = umbrasweep::cells::load_json(std::path::Path::new(&args[2])).expect("cells");
    let ci: usize = args[3].parse().expect("CELL");
    let eps: f64 = args[4].parse().expect("EPS");
    let res: u32 = args[5].parse().expect("RES");
    let n: usize = args[6].parse().expect("N");
    let data = common::sampler_data(&scene);
    let cell = cells[ci].to_f64();
    let gpu = GpuBackend::new().expect("GPU backend");
    println!("GPU: {}", gpu.adapter_info().name);
    let t = Instant::now();
    let on_gpu = GpuSamplerScene::new(&gpu, &data.occluders).expect("GPU sampler scene");
    let mut gs = GpuSampler::new(&gpu, &on_gpu, res).expect("GPU sampler");
    println!(
        "{} polygons uploaded and pipelines made in {:.2} s",
        data.occluders.polys.len(),
        t.elapsed().as_secs_f64()
    );
    let mut hc = Hemicube::new(res);
    let beyond: Vec<_> = (0..6)
        .map(|f| common::Face::from_index(f).beyond(&scene, &cell))
        .collect();
    let mut seed = 11u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut t_cpu, mut t_rec, mut t_dev) = (Duration::ZERO, Duration::ZERO, Duration::ZERO);
    let (mut h_cpu, mut h_gpu, mut only_cpu, mut only_gpu, mut tested) = (0, 0, 0, 0, 0);
    let mut draws = 0usize;
    for k in 0..n {
        let face = common::Face::from_index(k % 6);
        let mut eye = DVec3::ZERO;
        for a in 0..3 {
            eye[a] = cell.min[a] + rnd() * (cell.max[a] - cell.min[a]);
        }
        let eye = face.onto(&cell, eye);
        let (_, boxes) = &beyond[k % 6];
        let t = Instant::now();
        hc.begin(eye, face.axis, face.sign, eps, boxes);
        hc.draw(&data.occluders);
        let cpu: Vec<bool> = boxes
            .iter()
            .map(|b| hc.test_box(b) == BoxTest::Hidden)
            .collect();
        t_cpu += t.elapsed();
        let t = Instant::now();
        gs.begin(eye, face.axis, face.sign, eps, boxes);
        t_rec += t.elapsed();
        let t = Instant::now();
        let g = gs.test_boxes(boxes).expect("GPU render");
        t_dev += t.elapsed();
        draws += gs.last_draws() as usize;
        for (c, g) in cpu.iter().zip(&g) {
            tested += 1;
            h_cpu += usize::from(*c);
            h_gpu += usize::from(*g);
            only_cpu += usize::from(*c && !*g);
            only_gpu += usize::from(*g && !*c);
        }
    }
    let per = |d: Duration| d.as_secs_f64() * 1e3 / n.max(1) as f64;
    println!(
        "{n} points, ε {eps}, {} px: {tested} box tests; hidden by the CPU {h_cpu}, by the GPU \
         {h_gpu} (CPU only {only_cpu}, GPU only {only_gpu}); {:.0} draws per point",
        hc.resolution(),
        draws as f64 / n.max(1) as f64
    );
    println!(
        "ms per point: CPU {:.1}; GPU {:.1} (set-up on the CPU {:.1}, submission {:.1})",
        per(t_cpu),
        per(t_rec + t_dev),
        per(t_rec),
        per(t_dev)
    );
}
