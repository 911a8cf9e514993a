//! Probes the shrunk-occluder sampler at one point of a cell's face: coverage, depths, time
//! per render, objects hidden. `cargo run --release --example sampler_probe -- SCENE CELLS
//! [CELL] [EPS] [RES]`.

mod common;

use glam::DVec3;
use std::time::Instant;
use umbrasweep::bake::{BakeSettings, SamplerData};
use umbrasweep::sampler::{BoxTest, Hemicube};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene = umbrasweep::scene::load(std::path::Path::new(&args[1])).expect("scene");
    let cells = umbrasweep::cells::load_json(std::path::Path::new(&args[2])).expect("cells");
    let ci: usize = args.get(3).map_or(0, |s| s.parse().expect("cell"));
    let eps: f64 = args.get(4).map_or(0.05, |s| s.parse().expect("eps"));
    let res: u32 = args.get(5).map_or(128, |s| s.parse().expect("res"));
    let settings = BakeSettings::default();
    let occ =
        umbrasweep::project::occluders::prepare(&scene, &vec![true; scene.objects.len()], false);
    let t = Instant::now();
    let data = SamplerData::new(&occ, &scene, &settings);
    println!(
        "sampler data {:.2} s, {} polygons, median inradius {:.4}",
        t.elapsed().as_secs_f64(),
        data.occluders.polys.len(),
        data.occluders.median_inradius
    );
    let cell = cells[ci].to_f64();
    let boxes: Vec<_> = scene
        .objects
        .iter()
        .filter(|o| !o.bounds.is_empty())
        .map(|o| o.bounds.to_f64())
        .collect();
    let mut hc = Hemicube::new(res);
    for (axis, sign) in [(0, 1.0), (0, -1.0), (2, 1.0), (1, 1.0)] {
        let face = common::Face { axis, sign };
        let eye = face.centre(&cell);
        let list: Vec<_> = boxes
            .iter()
            .copied()
            .filter(|b| face.reaches(&cell, b))
            .collect();
        {
            let mut ts = Vec::new();
            let mut hits_ground = 0;
            let mut rnd = common::uniform(12345u64);
            for _ in 0..4000 {
                let mut d = DVec3::new(rnd() * 2.0 - 1.0, rnd() * 2.0 - 1.0, rnd() * 2.0 - 1.0);
                if d.length() > 1.0 {
                    continue;
                }
                if d[axis] * sign < 0.0 {
                    d[axis] = -d[axis];
                }
                let h = data
                    .rays
                    .trace(eye.as_vec3(), d.normalize().as_vec3(), false);
                match h.last() {
                    Some(x) if x.object == 0 => hits_ground += 1,
                    Some(x) => ts.push(x.t),
                    None => ts.push(f32::INFINITY),
                }
            }
            ts.sort_by(f32::total_cmp);
            println!(
                "  rays: ground {hits_ground}, first-hit quartiles {:.2} {:.2} {:.2} of {}",
                ts[ts.len() / 4],
                ts[ts.len() / 2],
                ts[3 * ts.len() / 4],
                ts.len()
            );
        }
        let t = Instant::now();
        hc.begin(eye, axis, sign, eps, &list);
        let st = hc.draw(&data.occluders);
        let dt = t.elapsed().as_secs_f64() * 1e3;
        let (cov, med) = hc.coverage();
        let hidden = list
            .iter()
            .filter(|b| hc.test_box(b) == BoxTest::Hidden)
            .count();
        let t2 = Instant::now();
        let mut tri_hidden = 0;
        for o in &scene.objects {
            if o.bounds.is_empty() {
                continue;
            }
            let b = o.bounds.to_f64();
            if !face.reaches(&cell, &b) {
                continue;
            }
            if hc.test_box(&b) == BoxTest::Hidden {
                tri_hidden += 1;
                continue;
            }
            let all = o.triangles.clone().all(|t| {
                hc.test_triangle(scene.triangle(t as usize).map(|p| p.as_dvec3()))
                    == BoxTest::Hidden
            });
            if all {
                tri_hidden += 1;
            }
        }
        println!(
            "  triangle-level: {tri_hidden} objects hidden ({:.1} ms)",
            t2.elapsed().as_secs_f64() * 1e3
        );
        println!(
            "face {axis}{sign:+}: {dt:.1} ms, {} nodes, {} reached, {} polygons drawn, coverage {:.1} %, median depth {med:.2}, {hidden}/{} boxes hidden",
            st.nodes,
            st.reached,
            st.polygons,
            100.0 * cov,
            list.len()
        );
    }
    let _ = DVec3::ZERO;
}
