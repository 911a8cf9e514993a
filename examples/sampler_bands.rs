//! Depth-bounded shrinking, measured: from the centre of one face of a cell, per distance band,
//! how many objects are hidden (each of their triangles) with one render whose edges are
//! shrunk for occludees at any distance, and with one render per band of occludee distance
//! whose edges are shrunk only as much as that band needs. `cargo run --release --example
//! sampler_bands -- SCENE CELLS CELL EPS RES [FACE [RATIO]]` (RATIO: of one band's
//! farthest distance to the last's, default 2).

mod common;

use std::time::Instant;
use umbrasweep::geom::DAabb;
use umbrasweep::sampler::{BoxTest, Hemicube};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (scene, cell, eps, res) = common::scene_cell_eps_res(&args);
    let face = common::Face::parse(args.get(6).map_or("+x", String::as_str));
    let (axis, sign) = (face.axis, face.sign);
    let ratio: f64 = args.get(7).map_or(2.0, |s| s.parse().expect("ratio"));
    let data = common::sampler_data(&scene);
    let eye = face.centre(&cell);
    let (objs, boxes) = face.beyond(&scene, &cell);
    let far = |b: &DAabb| (b.min - eye).abs().max((b.max - eye).abs()).length();
    let hidden = |hc: &Hemicube, o: usize, b: &DAabb| -> bool {
        match hc.test_box(b) {
            BoxTest::Hidden => true,
            BoxTest::Open { .. } => scene.objects[o].triangles.clone().all(|t| {
                hc.test_triangle(scene.triangle(t as usize).map(|p| p.as_dvec3()))
                    == BoxTest::Hidden
            }),
        }
    };
    let mut hc = Hemicube::new(res);
    // One render for all, shrunk for occludees at any distance.
    hc.set_depth_bounded(false);
    let t = Instant::now();
    hc.begin(eye, axis, sign, eps, &boxes);
    let st = hc.draw(&data.occluders);
    let one: Vec<bool> = objs
        .iter()
        .zip(&boxes)
        .map(|(&o, b)| hidden(&hc, o, b))
        .collect();
    println!(
        "one render: {:.1} ms, {} polygons drawn",
        t.elapsed().as_secs_f64() * 1e3,
        st.polygons
    );
    // One render per band of farthest distance (5·2^k), depth-bounded.
    hc.set_depth_bounded(true);
    let t = Instant::now();
    let mut banded = vec![false; objs.len()];
    let mut drawn = 0;
    let mut lo = 0.0;
    let mut hi = 2.0;
    while lo < 1e6 {
        let idx: Vec<usize> = (0..objs.len())
            .filter(|&i| {
                let f = far(&boxes[i]);
                f > lo && f <= hi
            })
            .collect();
        if !idx.is_empty() {
            let bb: Vec<DAabb> = idx.iter().map(|&i| boxes[i]).collect();
            hc.begin(eye, axis, sign, eps, &bb);
            drawn += hc.draw(&data.occluders).polygons;
            for &i in &idx {
                banded[i] = hidden(&hc, objs[i], &boxes[i]);
            }
        }
        lo = hi;
        hi *= ratio;
    }
    println!(
        "banded renders: {:.1} ms, {} polygons drawn",
        t.elapsed().as_secs_f64() * 1e3,
        drawn
    );
    let mut bands = [[0usize; 3]; 20];
    for i in 0..objs.len() {
        let d = (boxes[i].center() - eye).length();
        let k = ((d / 10.0) as usize).min(19);
        bands[k][0] += 1;
        bands[k][1] += one[i] as usize;
        bands[k][2] += banded[i] as usize;
    }
    println!("distance band: objects, hidden with one render, hidden with banded renders");
    for (k, b) in bands.iter().enumerate() {
        if b[0] > 0 {
            println!(
                "  {:3}-{:3}: {:5} {:5} {:5}",
                k * 10,
                k * 10 + 10,
                b[0],
                b[1],
                b[2]
            );
        }
    }
    let tot = |j: usize| bands.iter().map(|b| b[j]).sum::<usize>();
    println!("total: {} objects, {} / {} hidden", tot(0), tot(1), tot(2));
}
