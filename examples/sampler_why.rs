//! Why the sampler keeps objects that rays never see: for a baked cell, the objects of its PVS
//! that a ray sample of the cell does not reach ("loose"), each tested from the centre of every
//! face with the sampler's shrink (`EPS`) and without it (a tiny ε), and the pixel where the
//! first open triangle shows classified: nothing covers it, a partial sub-pixel mask, or a
//! covering depth that is not nearer than the triangle. `cargo run --release --example
//! sampler_why -- SCENE CELLS CELL PVS.json EPS RES RAYS [--box] [--show] [--write-tight
//! OUT.json]`: `--box` tests triangles by their boxes (as the sampler did before
//! `Hemicube::test_triangle`), `--show` prints the first open pixels of the plain render with
//! the exact ray through them, `--write-tight` only writes the PVS without its loose objects
//! (`validate --hunt` on it finds which of them are really visible).

mod common;

use std::collections::HashSet;
use umbrasweep::geom::DAabb;
use umbrasweep::sampler::{BoxTest, Hemicube};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 8 {
        eprintln!(
            "usage: sampler_why SCENE CELLS CELL PVS.json EPS RES RAYS [--box] [--show] \
             [--write-tight OUT.json]"
        );
        std::process::exit(2);
    }
    let flag = |f: &str| args[8..].iter().any(|a| a == f);
    let (by_box, show) = (flag("--box"), flag("--show"));
    let write_tight = args[8..]
        .iter()
        .position(|a| a == "--write-tight")
        .map(|k| args.get(9 + k).expect("--write-tight OUT.json").clone());
    let scene = umbrasweep::scene::load(std::path::Path::new(&args[1])).expect("scene");
    let cells = umbrasweep::cells::load_json(std::path::Path::new(&args[2])).expect("cells");
    let ci: usize = args[3].parse().expect("cell");
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&args[4]).expect("pvs")).expect("json");
    let eps: f64 = args[5].parse().expect("eps");
    let res: u32 = args[6].parse().expect("res");
    let rays: u64 = args[7].parse().expect("rays");
    let pvs: Vec<u32> = doc["cells"][ci]["visible"]
        .as_array()
        .expect("visible")
        .iter()
        .map(|v| v.as_u64().expect("id") as u32)
        .collect();
    let data = common::sampler_data(&scene);
    let cell = cells[ci].to_f64();
    let sample =
        umbrasweep::validate::sample_cell(&data.rays, &scene, cells[ci], rays, 7, 0, false);
    let vs: HashSet<u32> = sample.visible.iter().copied().collect();
    let loose: Vec<u32> = pvs
        .iter()
        .copied()
        .filter(|o| !vs.contains(o) && !scene.objects[*o as usize].bounds.to_f64().overlaps(&cell))
        .collect();
    println!("PVS {} VS {} loose {}", pvs.len(), vs.len(), loose.len());
    if let Some(out) = write_tight {
        let mut doc = doc.clone();
        let keep: Vec<u32> = pvs.iter().copied().filter(|o| !loose.contains(o)).collect();
        doc["cells"][ci]["visible"] = serde_json::json!(keep);
        std::fs::write(&out, serde_json::to_string(&doc).expect("json")).expect("write");
        println!("wrote {out}");
        return;
    }
    // Per class: [shrunk, plain]: hidden, uncovered, partial mask, depth not nearer.
    let mut classes = [[0usize; 4]; 2];
    let mut mask_bits = [0usize; 65];
    let mut shown = 0;
    // Per loose object: open from some face centre [shrunk, plain], seen by a ray from one.
    let mut open_any = std::collections::HashMap::<u32, [bool; 3]>::new();
    for fi in 0..6 {
        let face = common::Face::from_index(fi);
        let (axis, sign) = (face.axis, face.sign);
        let eye = face.centre(&cell);
        let objs: Vec<u32> = loose
            .iter()
            .copied()
            .filter(|&o| face.reaches(&cell, &scene.objects[o as usize].bounds.to_f64()))
            .collect();
        if objs.is_empty() {
            continue;
        }
        let boxes: Vec<DAabb> = objs
            .iter()
            .map(|&o| scene.objects[o as usize].bounds.to_f64())
            .collect();
        for (k, e) in [eps, 1e-5].into_iter().enumerate() {
            let mut hc = Hemicube::new(res);
            hc.begin(eye, axis, sign, e, &boxes);
            hc.draw(&data.occluders);
            for &o in &objs {
                let ob = &scene.objects[o as usize];
                let mut open = None;
                for t in ob.triangles.clone() {
                    let [a, b, c] = scene.triangle(t as usize).map(|p| p.as_dvec3());
                    let tb = DAabb {
                        min: a.min(b).min(c),
                        max: a.max(b).max(c),
                    };
                    let test = if by_box {
                        hc.test_box(&tb)
                    } else {
                        hc.test_triangle([a, b, c])
                    };
                    if let BoxTest::Open { direction } = test {
                        open = Some((direction, (tb.center() - eye).length()));
                        break;
                    }
                }
                let Some((dir, dist)) = open else {
                    classes[k][0] += 1;
                    continue;
                };
                open_any.entry(o).or_default()[k] = true;
                if k == 1 && show && shown < 12 {
                    shown += 1;
                    let st = hc.pixel_state(dir);
                    let hits = data.rays.trace(eye.as_vec3(), dir.as_vec3(), false);
                    let first: Vec<String> = hits
                        .iter()
                        .take(4)
                        .map(|x| format!("t {:.3} obj {}", x.t * dir.length() as f32, x.object))
                        .collect();
                    println!(
                        "  face {fi} obj {o} dist {dist:.2}: pixel {:?} (mask bits {}); ray through the centre: {}",
                        st.map(|s| (s.0, s.2)),
                        st.map_or(0, |s| s.1.count_ones()),
                        first.join(", ")
                    );
                }
                if k == 1 {
                    // Rays from the face centre at random points of the object's triangles.
                    let mut rnd = common::uniform(u64::from(o) * 0x9e37_79b9_7f4a_7c15 + fi as u64);
                    let n = ob.triangles.len();
                    for _ in 0..2000 {
                        let t =
                            ob.triangles.start as usize + ((rnd() * n as f64) as usize).min(n - 1);
                        let [a, b, c] = scene.triangle(t).map(|p| p.as_dvec3());
                        let (mut x, mut y) = (rnd(), rnd());
                        if x + y > 1.0 {
                            (x, y) = (1.0 - x, 1.0 - y);
                        }
                        let q = a + (b - a) * x + (c - a) * y;
                        let d = (q - eye).as_vec3();
                        let hits = data.rays.trace(eye.as_vec3(), d, false);
                        if hits.iter().any(|x| x.object == o) {
                            open_any.entry(o).or_default()[2] = true;
                            break;
                        }
                    }
                }
                match hc.pixel_state(dir) {
                    Some((d, 0, _)) if d.is_infinite() => classes[k][1] += 1,
                    Some((d, m, _)) if d.is_infinite() => {
                        classes[k][2] += 1;
                        if k == 0 {
                            mask_bits[m.count_ones() as usize] += 1;
                        }
                    }
                    // Covered, but not nearer than the triangle (or outside the drawn pixels).
                    _ => classes[k][3] += 1,
                }
            }
        }
    }
    for (k, name) in ["shrunk", "plain"].iter().enumerate() {
        let c = classes[k];
        println!(
            "{name:7}: hidden {} · open pixel uncovered {} · partial mask {} · depth not nearer {}",
            c[0], c[1], c[2], c[3]
        );
    }
    let count = |k: usize| open_any.values().filter(|v| v[k]).count();
    println!(
        "loose objects open from some face centre: shrunk {}, plain {}, seen by a ray from a face centre {}",
        count(0),
        count(1),
        count(2)
    );
    let hist: Vec<String> = mask_bits
        .iter()
        .enumerate()
        .filter(|(_, n)| **n > 0)
        .map(|(b, n)| format!("{b}:{n}"))
        .collect();
    println!("partial masks (bits:count): {}", hist.join(" "));
}
