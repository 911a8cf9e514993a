//! For one cell: renders N random sample points on its faces and reports, per object, at how
//! many points it is open (box and triangles tested). `cargo run --release --example
//! sampler_points -- SCENE CELLS CELL EPS RES N [whole]`; `TUCK=1` in the environment turns
//! the hemicube's tuck pass on.

mod common;

use glam::DVec3;
use std::time::Instant;
use umbrasweep::sampler::{BoxTest, Hemicube};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (scene, cell, eps, res) = common::scene_cell_eps_res(&args);
    let n: usize = args[6].parse().unwrap();
    let data = common::sampler_data(&scene);
    let mut open = vec![0u32; scene.objects.len()];
    let mut seen_from = vec![0u32; scene.objects.len()];
    let mut hc = Hemicube::new(res);
    // A seventh argument `whole` turns sub-pixel masks off.
    hc.set_subpixel(args.get(7).map(String::as_str) != Some("whole"));
    // `TUCK=1` turns the tuck pass on.
    hc.set_tuck(std::env::var("TUCK").is_ok_and(|v| v == "1"));
    let mut rnd = common::uniform(7u64);
    // The objects each face's points test do not depend on the point.
    let beyond: Vec<_> = (0..6)
        .map(|f| common::Face::from_index(f).beyond(&scene, &cell))
        .collect();
    let t = Instant::now();
    let (mut tucked, mut drawn, mut reached, mut nodes) = (0u64, 0u64, 0u64, 0u64);
    for k in 0..n {
        let face = common::Face::from_index(k % 6);
        let (axis, sign) = (face.axis, face.sign);
        let mut eye = DVec3::ZERO;
        for a in 0..3 {
            eye[a] = cell.min[a] + rnd() * (cell.max[a] - cell.min[a]);
        }
        let eye = face.onto(&cell, eye);
        let (ids, boxes) = &beyond[k % 6];
        hc.begin(eye, axis, sign, eps, boxes);
        let st = hc.draw(&data.occluders);
        tucked += st.tucked;
        drawn += st.polygons;
        reached += st.reached;
        nodes += st.nodes;
        let mut opened = 0;
        for (&o, b) in ids.iter().zip(boxes) {
            seen_from[o] += 1;
            let tb = hc.test_box(b);
            if tb == BoxTest::Hidden {
                continue;
            }
            if let BoxTest::Open { direction } = tb
                && k < 12
                && opened < 3
            {
                let hits = data
                    .rays
                    .trace(eye.as_vec3(), direction.normalize().as_vec3(), false);
                let d = direction.normalize();
                let desc: Vec<String> = hits
                    .iter()
                    .map(|h| {
                        let [a, bb, c] = scene.triangle(h.triangle as usize).map(|p| p.as_dvec3());
                        let n = (bb - a).cross(c - a).normalize();
                        let pd = n.dot(a - eye).abs();
                        format!(
                            "obj {} t {:.2} plane-dist {:.2} edge {:.2}",
                            h.object,
                            h.t,
                            pd,
                            (bb - a).length()
                        )
                    })
                    .collect();
                let bb = b;
                let near = (bb.min - eye).max(eye - bb.max).max(DVec3::ZERO).length();
                println!(
                    "   open obj {o} (box dist {near:.2}) dir {:.3?}: {:?}",
                    d, desc
                );
            }
            let ob = &scene.objects[o];
            let all = ob.triangles.clone().all(|t| {
                hc.test_triangle(scene.triangle(t as usize).map(|p| p.as_dvec3()))
                    == BoxTest::Hidden
            });
            if !all {
                open[o] += 1;
                opened += 1;
            }
        }
        if k < 36 {
            println!(
                "face {axis}{sign:+} eye {:.2?} (rel {:.2?}): {opened} open of {}",
                eye,
                (eye - cell.min) / (cell.max - cell.min),
                ids.len()
            );
        }
    }
    println!(
        "{n} points in {:.1} s ({drawn} polygons drawn, {tucked} of them with tucked edges; \
         {reached} reached, {nodes} BVH nodes visited)",
        t.elapsed().as_secs_f64()
    );
    let mut hist = [0usize; 8];
    let mut never = 0;
    for o in 0..scene.objects.len() {
        if seen_from[o] == 0 {
            continue;
        }
        if open[o] == 0 {
            never += 1;
            continue;
        }
        let f = open[o] as f64 / seen_from[o] as f64;
        let b = if f < 0.01 {
            0
        } else if f < 0.02 {
            1
        } else if f < 0.05 {
            2
        } else if f < 0.1 {
            3
        } else if f < 0.2 {
            4
        } else if f < 0.5 {
            5
        } else if f < 1.0 {
            6
        } else {
            7
        };
        hist[b] += 1;
    }
    println!(
        "never open: {never}; open at <1%: {}, 1-2%: {}, 2-5%: {}, 5-10%: {}, 10-20%: {}, 20-50%: {}, 50-99%: {}, all: {}",
        hist[0], hist[1], hist[2], hist[3], hist[4], hist[5], hist[6], hist[7]
    );
}
