//! Where the sampler leaks: from the centre of one face of a cell, per distance band, how many
//! objects are hidden (their box, or each of their triangles), and where the open directions point
//! (elevation), with the exact ray and the pixel along a few open directions. `cargo run
//! --release --example sampler_leaks -- SCENE CELLS CELL EPS RES [FACE [MIPS [pixels|polygons]]]`
//! with FACE one of `+x -x +y -y +z -z` (default `+x`), MIPS the mip levels of alpha-tested
//! cards trusted (0, the default: all) and `polygons` to draw cards only as their opaque
//! polygons (not also per pixel at their texel footprint).

mod common;

use std::time::Instant;
use umbrasweep::bake::{BakeSettings, SamplerData};
use umbrasweep::sampler::{BoxTest, Hemicube};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (scene, cell, eps, res) = common::scene_cell_eps_res(&args);
    let face = common::Face::parse(args.get(6).map_or("+x", String::as_str));
    let (axis, sign) = (face.axis, face.sign);
    // Alpha-tested cards: trusted mip levels (0 = all) and whether the sampler also tests
    // card triangles per pixel against their texel footprint (`pixels`) or only uses the
    // cards' opaque polygons (`polygons`).
    let mips: u32 = args.get(7).map_or(0, |s| s.parse().expect("mips"));
    let card_pixels = args.get(8).is_none_or(|s| s != "polygons");
    let settings = BakeSettings::default();
    let mut occ = umbrasweep::project::occluders::prepare_with(
        &scene,
        &vec![true; scene.objects.len()],
        false,
        Some(umbrasweep::scene::alpha::CardOptions {
            mips: (mips > 0).then_some(mips),
            max_polygons: 4,
            min_share: umbrasweep::scene::alpha::MIN_POLYGON_SHARE,
        }),
    );
    if !card_pixels {
        occ.card_triangles.clear();
    }
    let data = SamplerData::new(&occ, &scene, &settings);
    let eye = face.centre(&cell);
    let (objs, boxes) = face.beyond(&scene, &cell);
    let mut hc = Hemicube::new(res);
    let t = Instant::now();
    hc.begin(eye, axis, sign, eps, &boxes);
    let st = hc.draw(&data.occluders);
    println!(
        "render {:.1} ms, {} polygons drawn, {} reached",
        t.elapsed().as_secs_f64() * 1e3,
        st.polygons,
        st.reached
    );
    // distance bands of 10
    let mut bands = [[0usize; 3]; 20];
    let mut elev = [0usize; 19];
    let mut leaf_open_elev = [0usize; 19];
    let mut traced = 0;
    for (&o, b) in objs.iter().zip(&boxes) {
        let d = (b.center() - eye).length();
        let band = ((d / 10.0) as usize).min(19);
        bands[band][0] += 1;
        let mut open_dir = None;
        if let BoxTest::Open { direction } = hc.test_box(b) {
            open_dir = Some(direction);
            let ob = &scene.objects[o];
            let mut all = true;
            for t in ob.triangles.clone() {
                let tri = scene.triangle(t as usize).map(|p| p.as_dvec3());
                if let BoxTest::Open { direction } = hc.test_triangle(tri) {
                    all = false;
                    let e = (direction.y / direction.length()).asin().to_degrees();
                    leaf_open_elev[((e + 90.0) / 10.0).clamp(0.0, 18.0) as usize] += 1;
                    break;
                }
            }
            if all {
                bands[band][2] += 1;
            }
        } else {
            bands[band][1] += 1;
            bands[band][2] += 1;
        }
        if let Some(dir) = open_dir {
            let e = (dir.y / dir.length()).asin().to_degrees();
            if d > 60.0 && traced < 40 {
                traced += 1;
                let h = data
                    .rays
                    .trace(eye.as_vec3(), dir.normalize().as_vec3(), false);
                let first = h
                    .last()
                    .map_or((f32::INFINITY, u32::MAX), |x| (x.t, x.object));
                println!(
                    "    open obj {o} at {d:.1}: elevation {e:.2}°, azimuth {:.2}°, exact first hit t {:.2} object {}",
                    dir.z.atan2(dir.x).to_degrees(),
                    first.0,
                    first.1
                );
                if traced <= 3 {
                    walk(&scene, &data, &hc, eye, dir.normalize(), eps, d);
                }
            }
            elev[((e + 90.0) / 10.0).clamp(0.0, 18.0) as usize] += 1;
        }
    }
    println!("distance band: objects, box-hidden, triangle-hidden");
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
    println!("open direction elevation (deg): box-open / triangle-open");
    for k in 0..19 {
        if elev[k] + leaf_open_elev[k] > 0 {
            println!(
                "  {:4}: {:5} {:5}",
                k as i32 * 10 - 90,
                elev[k],
                leaf_open_elev[k]
            );
        }
    }
}

/// Walks the exact ray from `eye` along `dir` up to `far`, printing each leaf it crosses and its
/// shrink margin (the least of d·m_e − ε/r_e over the edges; ≥ 0: the direction is inside the
/// shrunk silhouette), and the hemicube's depth along it (tiny boxes).
fn walk(
    scene: &umbrasweep::scene::Scene,
    data: &SamplerData,
    hc: &Hemicube,
    eye: glam::DVec3,
    dir: glam::DVec3,
    eps: f64,
    far: f64,
) {
    let mut t0 = 0.0f64;
    let mut n = 0;
    let mut best = f64::NEG_INFINITY;
    while t0 < far && n < 200 {
        let o = eye + dir * t0;
        let h = data.rays.trace(o.as_vec3(), dir.as_vec3(), false);
        let Some(x) = h.last() else { break };
        let t = t0 + f64::from(x.t);
        let tri = scene
            .triangle(x.triangle as usize)
            .map(|p| p.as_dvec3() - eye);
        let mut margin = f64::INFINITY;
        let c = (tri[0] + tri[1] + tri[2]) / 3.0;
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            let cr = a.cross(b);
            let mut m = cr.normalize();
            if m.dot(c) < 0.0 {
                m = -m;
            }
            let r = cr.length() / (b - a).length();
            margin = margin.min(dir.dot(m) - eps / r);
        }
        best = best.max(margin);
        if n < 12 || margin >= 0.0 {
            println!(
                "      hit t {t:.2} obj {} tri {} margin {margin:.4}",
                x.object, x.triangle
            );
        }
        n += 1;
        t0 = t + 1e-3;
    }
    if let Some((depth, mask, wz)) = hc.pixel_state(dir) {
        println!(
            "      pixel: depth {depth}, partial mask {} of 64 sub-pixels at depth {wz}",
            mask.count_ones()
        );
    }
    // the hemicube's depth along the direction
    let mut lo = 0.01f64;
    let mut hi = far;
    let tiny = |t: f64| {
        let p = eye + dir * t;
        umbrasweep::geom::DAabb {
            min: p - 1e-5,
            max: p + 1e-5,
        }
    };
    if hc.test_box(&tiny(hi)) != BoxTest::Hidden {
        println!("      {n} hits, best margin {best:.4}; hemicube open up to {far:.1}");
    } else {
        for _ in 0..40 {
            let m = 0.5 * (lo + hi);
            if hc.test_box(&tiny(m)) == BoxTest::Hidden {
                hi = m
            } else {
                lo = m
            }
        }
        println!("      {n} hits, best margin {best:.4}; hemicube covered from {hi:.2}");
    }
}
