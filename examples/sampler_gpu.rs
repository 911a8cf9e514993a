//! The sampler's hemicube on the CPU and on the GPU (`GpuSampler`) from the same random points
//! of a cell's faces: objects hidden by each, disagreements, and time per point (the GPU's
//! split into the CPU's set-up and the submission that draws and tests), for each fill asked
//! for (`compute`, `render` or `both`; default: the device's, `GpuSamplerScene::default_fill`),
//! with the GPU's time per phase from its timestamps where the device has them, and with
//! `both` the boxes on which the two fills disagree (they should not). `cull` runs the compute
//! fill in one round and in rounds (`GpuSampler::set_culling`), which should agree too.
//! `cargo run --release --example sampler_gpu -- SCENE CELLS CELL EPS RES N [FILL|cull]`.

mod common;

use glam::DVec3;
use std::time::{Duration, Instant};
use umbrasweep::backend::gpu::GpuBackend;
use umbrasweep::backend::gpu::sampler::{GpuSampler, GpuSamplerScene, SamplerFill};
use umbrasweep::sampler::{BoxTest, Hemicube};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 7 {
        eprintln!("usage: sampler_gpu SCENE CELLS CELL EPS RES N [compute|render|both|cull]");
        std::process::exit(2);
    }
    let (scene, cell, eps, res) = common::scene_cell_eps_res(&args);
    let n: usize = args[6].parse().expect("N");
    let data = common::sampler_data(&scene);
    let gpu = GpuBackend::new().expect("GPU backend");
    println!("GPU: {}", gpu.adapter_info().name);
    // `cull`: the compute fill in one round and in rounds (`GpuSampler::set_culling`).
    let rounds = args.get(7).map(String::as_str) == Some("cull");
    let fills: Vec<SamplerFill> = match args.get(7).map(String::as_str) {
        None => vec![GpuSamplerScene::default_fill(&gpu)],
        Some("both") => vec![SamplerFill::Compute, SamplerFill::Render],
        Some("cull") => vec![SamplerFill::Compute, SamplerFill::Compute],
        Some(f) => vec![f.parse().expect("FILL")],
    };
    let labels: Vec<String> = fills
        .iter()
        .enumerate()
        .map(|(f, fill)| match (rounds, f) {
            (true, 0) => format!("{fill} (one round)"),
            (true, _) => format!("{fill} (rounds)"),
            _ => fill.to_string(),
        })
        .collect();
    let t = Instant::now();
    let scenes: Vec<GpuSamplerScene> = fills
        .iter()
        .map(|&f| GpuSamplerScene::with_fill(&gpu, &data.occluders, f).expect("GPU sampler scene"))
        .collect();
    let mut samplers: Vec<GpuSampler> = scenes
        .iter()
        .map(|s| GpuSampler::new(&gpu, s, res).expect("GPU sampler"))
        .collect();
    for (f, gs) in samplers.iter_mut().enumerate() {
        gs.set_culling(!rounds || f == 1);
    }
    println!(
        "{} polygons uploaded and pipelines made in {:.2} s",
        data.occluders.polys.len(),
        t.elapsed().as_secs_f64()
    );
    let mut hc = Hemicube::new(res);
    let beyond: Vec<_> = (0..6)
        .map(|f| common::Face::from_index(f).beyond(&scene, &cell))
        .collect();
    let mut rnd = common::uniform(11u64);
    let nf = fills.len();
    let mut t_cpu = Duration::ZERO;
    let (mut t_rec, mut t_dev) = (vec![Duration::ZERO; nf], vec![Duration::ZERO; nf]);
    let (mut h_cpu, mut tested) = (0, 0);
    let (mut h_gpu, mut only_cpu, mut only_gpu) = (vec![0; nf], vec![0; nf], vec![0; nf]);
    let (mut draws, mut fills_differ) = (vec![0usize; nf], 0);
    let mut first_draws = vec![0usize; nf];
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
        let mut flags = Vec::new();
        for (f, gs) in samplers.iter_mut().enumerate() {
            let t = Instant::now();
            gs.begin(eye, face.axis, face.sign, eps, boxes);
            t_rec[f] += t.elapsed();
            let t = Instant::now();
            let g = gs.test_boxes(boxes).expect("GPU render");
            t_dev[f] += t.elapsed();
            draws[f] += gs.last_draws() as usize;
            first_draws[f] += gs.last_first_round_draws() as usize;
            for (c, g) in cpu.iter().zip(&g) {
                h_gpu[f] += usize::from(*g);
                only_cpu[f] += usize::from(*c && !*g);
                only_gpu[f] += usize::from(*g && !*c);
            }
            flags.push(g);
        }
        tested += cpu.len();
        h_cpu += cpu.iter().filter(|&&c| c).count();
        if let [a, b] = &flags[..] {
            fills_differ += a.iter().zip(b).filter(|(a, b)| a != b).count();
        }
    }
    let per = |d: Duration| d.as_secs_f64() * 1e3 / n.max(1) as f64;
    println!(
        "{n} points, ε {eps}, {} px: {tested} box tests; hidden by the CPU {h_cpu}; CPU ms per \
         point {:.1}",
        hc.resolution(),
        per(t_cpu)
    );
    for (f, fill) in labels.iter().enumerate() {
        println!(
            "{fill} fill: hidden by the GPU {} (CPU only {}, GPU only {}); {:.0} draws per point \
             ({:.0} in the first round); ms per point {:.1} (set-up on the CPU {:.1}, submission \
             {:.1})",
            h_gpu[f],
            only_cpu[f],
            only_gpu[f],
            draws[f] as f64 / n.max(1) as f64,
            first_draws[f] as f64 / n.max(1) as f64,
            per(t_rec[f] + t_dev[f]),
            per(t_rec[f]),
            per(t_dev[f])
        );
    }
    for (fill, gs) in labels.iter().zip(&samplers) {
        let t = gs.gpu_times();
        if t.passes > 0 {
            println!(
                "{fill} fill, GPU ms per point (timestamps, {} passes): set-up {:.1}, cull {:.1}, \
                 fill {:.1}, reduce {:.1}, tests {:.1}",
                t.passes,
                per(t.setup),
                per(t.cull),
                per(t.fill),
                per(t.reduce),
                per(t.tests)
            );
        }
    }
    if nf == 2 {
        println!("boxes on which the two samplers disagree: {fills_differ}");
    }
}
