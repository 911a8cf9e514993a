//! Times the per-rectangle sweep (`sampler::RectSweep::render`, `--sampling-fusion sweep`;
//! one thread), for profiling: N rectangles of half diagonal EPS at fixed pseudo-random places
//! on a cell's faces (the same every run), each rendered for every object beyond its face
//! (the object's box, then its triangles), repeated R times (3 by default); prints the median
//! of the runs' milliseconds per render, the polygons drawn, nodes visited and erosion steps
//! per render, and how many objects the renders hid (a check that two builds decide the
//! same). `cargo run --release --example sweep_bench -- SCENE CELLS CELL EPS RES N [R]`.

mod common;

use std::time::Instant;
use umbrasweep::geom::DAabb;
use umbrasweep::sampler::RectSweep;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 7 {
        eprintln!("usage: sweep_bench SCENE CELLS CELL EPS RES N [R]");
        std::process::exit(2);
    }
    let (scene, cell, eps, res) = common::scene_cell_eps_res(&args);
    let n: usize = args[6].parse().expect("rectangles");
    let runs: usize = args.get(7).map_or(3, |s| s.parse().expect("runs"));
    if n == 0 || runs == 0 {
        eprintln!("sweep_bench: N and R must be at least 1");
        std::process::exit(2);
    }
    let data = common::sampler_data(&scene);
    let beyond: Vec<(Vec<usize>, Vec<DAabb>)> = (0..6)
        .map(|f| common::Face::from_index(f).beyond(&scene, &cell))
        .collect();
    let objects: Vec<common::BoxObjects> = beyond
        .iter()
        .map(|(objs, boxes)| common::BoxObjects::new(&scene, objs, boxes.clone()))
        .collect();
    let half = eps / 2f64.sqrt();
    let eyes = common::fixed_eyes(&cell, n);
    let mut sw = RectSweep::new(res);
    let mut times = Vec::new();
    let (mut drawn, mut nodes, mut erosions, mut hidden, mut tested) = (0, 0, 0, 0, 0);
    for run in 0..runs {
        let t = Instant::now();
        for &(f, eye) in &eyes {
            let face = common::Face::from_index(f);
            let (hid, st) = sw.render(
                &data.occluders,
                eye,
                face.axis,
                face.sign,
                [half, half],
                &objects[f],
            );
            if run == 0 {
                drawn += st.polygons;
                nodes += st.nodes;
                erosions += st.erosions;
                hidden += hid.iter().filter(|&&h| h).count();
                tested += hid.len();
            }
        }
        times.push(t.elapsed().as_secs_f64() * 1e3 / n as f64);
    }
    times.sort_by(f64::total_cmp);
    let per = |x: u64| x / n as u64;
    println!(
        "{n} sweeps at {res} px, eps {eps}: median {:.1} ms per render (runs {:.1?}); {} \
         polygons drawn, {} nodes, {} erosion steps per render; {hidden} of {tested} objects \
         hidden",
        times[times.len() / 2],
        times,
        per(drawn),
        per(nodes),
        per(erosions)
    );
}
