//! Times the CPU hemicube's drawing alone (`Hemicube::draw`: traversal and rasterisation,
//! not the set-up; one thread), for profiling: N rectangles of side `√2·EPS` (half-diagonal
//! EPS) at fixed pseudo-random places on a cell's faces (the same every run), each rendered
//! for every object beyond its face, repeated R times (3 by default); prints the median of
//! the runs' milliseconds per render, the polygons reached and drawn per render, and how many
//! boxes the renders hid (a check that two builds render the same). `cargo run --release
//! --example sampler_render_bench -- SCENE CELLS CELL EPS RES N [R]`.

mod common;

use std::time::Instant;
use umbrasweep::sampler::{BoxTest, Hemicube};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 7 {
        eprintln!("usage: sampler_render_bench SCENE CELLS CELL EPS RES N [R]");
        std::process::exit(2);
    }
    let (scene, cell, eps, res) = common::scene_cell_eps_res(&args);
    let n: usize = args[6].parse().expect("rectangles");
    let runs: usize = args.get(7).map_or(3, |s| s.parse().expect("runs"));
    if n == 0 || runs == 0 {
        eprintln!("sampler_render_bench: N and R must be at least 1");
        std::process::exit(2);
    }
    let data = common::sampler_data(&scene);
    let beyond: Vec<_> = (0..6)
        .map(|f| common::Face::from_index(f).beyond(&scene, &cell))
        .collect();
    let half = eps / 2f64.sqrt();
    let eyes = common::fixed_eyes(&cell, n);
    let mut hc = Hemicube::new(res);
    let mut times = Vec::new();
    let (mut reached, mut drawn, mut hidden) = (0u64, 0u64, 0usize);
    for run in 0..runs {
        let mut spent = std::time::Duration::ZERO;
        for &(f, eye) in &eyes {
            let face = common::Face::from_index(f);
            let boxes = &beyond[f].1;
            hc.begin_patch(eye, face.axis, face.sign, [half, half], boxes);
            let t = Instant::now();
            let st = hc.draw(&data.occluders);
            spent += t.elapsed();
            if run == 0 {
                reached += st.reached;
                drawn += st.polygons;
                hidden += boxes
                    .iter()
                    .filter(|b| hc.test_box(b) == BoxTest::Hidden)
                    .count();
            }
        }
        times.push(spent.as_secs_f64() * 1e3 / n as f64);
    }
    times.sort_by(f64::total_cmp);
    println!(
        "{n} renders at {res} px, eps {eps}: median {:.2} ms per render (runs {:.2?}); \
         {} polygons reached, {} drawn per render; {hidden} boxes hidden",
        times[times.len() / 2],
        times,
        reached / n as u64,
        drawn / n as u64
    );
}
