//! The per-rectangle occlusion sweep (`sampler::RectSweep`, `--sampling-fusion sweep`) against
//! the shrinking hemicube, from the centre of one face of a cell: over the objects the front
//! view alone decides (their boxes inside it from every point of the rectangle), how many the
//! hemicube hides (a first render for all, then one per √2 band of what it leaves open, as the
//! bake renders), how many a front-view-only prototype of the sweep hides, and how many the
//! library's sweep (all five views) hides; then every triangle either sweep hid is attacked
//! with 32 segments from random points of the rectangle to random points of it, traced against
//! the scene. `cargo run --release --example sampler_slabs -- SCENE CELLS CELL EPS RES FACE
//! [STEP [START]]` (the prototype's STEP: sub-pixels of erosion per slab, default 2; START:
//! the depth of the first slab's end, default 1, for both sweeps).

mod common;

use glam::{DVec2, DVec3};
use std::time::Instant;
use umbrasweep::geom::DAabb;
use umbrasweep::sampler::{BoxTest, Hemicube};

/// A bitmap of sub-pixels over the front view `[-1, 1]²`, `n` across.
struct Bits {
    n: usize,
    w: usize,
    rows: Vec<u64>,
}

impl Bits {
    fn new(n: usize) -> Self {
        let w = n / 64;
        Bits {
            n,
            w,
            rows: vec![0; w * n],
        }
    }

    fn set_span(&mut self, j: usize, i0: usize, i1: usize) {
        // bits i0..=i1
        for i in i0..=i1 {
            self.rows[j * self.w + i / 64] |= 1u64 << (i % 64);
        }
    }

    fn get(&self, i: usize, j: usize) -> bool {
        self.rows[j * self.w + i / 64] >> (i % 64) & 1 == 1
    }

    /// Keeps a bit only where every bit within `k` along both axes is set.
    fn erode(&mut self, k: usize) {
        let (w, n) = (self.w, self.n);
        for _ in 0..k {
            // Horizontal by one.
            for j in 0..n {
                let row = &mut self.rows[j * w..(j + 1) * w];
                let mut out = vec![0u64; w];
                for x in 0..w {
                    let cur = row[x];
                    let left = (cur << 1) | if x > 0 { row[x - 1] >> 63 } else { 0 };
                    let right = (cur >> 1) | if x + 1 < w { row[x + 1] << 63 } else { 0 };
                    out[x] = cur & left & right;
                }
                row.copy_from_slice(&out);
            }
            // Vertical by one.
            let old = self.rows.clone();
            for j in 0..n {
                for x in 0..w {
                    let up = if j > 0 { old[(j - 1) * w + x] } else { 0 };
                    let dn = if j + 1 < n { old[(j + 1) * w + x] } else { 0 };
                    self.rows[j * w + x] = old[j * w + x] & up & dn;
                }
            }
        }
    }
}

/// Clips convex polygon `p` to the half-plane left of `a → b` (counter-clockwise inside).
fn clip_left(p: &[DVec2], a: DVec2, b: DVec2) -> Vec<DVec2> {
    let side = |q: DVec2| (b - a).perp_dot(q - a);
    let mut out = Vec::with_capacity(p.len() + 2);
    for k in 0..p.len() {
        let (c, d) = (p[k], p[(k + 1) % p.len()]);
        let (sc, sd) = (side(c), side(d));
        if sc >= 0.0 {
            out.push(c);
        }
        if (sc >= 0.0) != (sd >= 0.0) {
            out.push(c + (d - c) * (sc / (sc - sd)));
        }
    }
    out
}

fn area2(p: &[DVec2]) -> f64 {
    (0..p.len())
        .map(|k| p[k].perp_dot(p[(k + 1) % p.len()]))
        .sum()
}

/// Draws convex counter-clockwise polygon `p` (view coordinates) inner-conservatively, shrunk
/// by `m` (a margin against rounding).
fn draw(bits: &mut Bits, p: &[DVec2]) {
    if p.len() < 3 {
        return;
    }
    let n = bits.n;
    let s = 2.0 / n as f64;
    let m = 1e-9;
    let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
    for q in p {
        y0 = y0.min(q.y);
        y1 = y1.max(q.y);
    }
    let span = |y: f64| -> Option<(f64, f64)> {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for k in 0..p.len() {
            let (c, d) = (p[k], p[(k + 1) % p.len()]);
            if (c.y <= y && d.y >= y) || (d.y <= y && c.y >= y) {
                let x = if (d.y - c.y).abs() < 1e-300 {
                    lo = lo.min(c.x.min(d.x));
                    hi = hi.max(c.x.max(d.x));
                    continue;
                } else {
                    c.x + (d.x - c.x) * (y - c.y) / (d.y - c.y)
                };
                lo = lo.min(x);
                hi = hi.max(x);
            }
        }
        (lo <= hi).then_some((lo, hi))
    };
    let ja = (((y0 + 1.0) / s).ceil().max(0.0)) as usize;
    let jb = (((y1 + 1.0) / s).floor().min(n as f64)) as usize;
    for j in ja..jb {
        let (ya, yb) = (-1.0 + j as f64 * s, -1.0 + (j + 1) as f64 * s);
        let (Some(a), Some(b)) = (span(ya + m), span(yb - m)) else {
            continue;
        };
        let lo = a.0.max(b.0) + m;
        let hi = a.1.min(b.1) - m;
        let ia = ((lo + 1.0) / s).ceil().max(0.0) as i64;
        let ib = ((hi + 1.0) / s).floor().min(n as f64) as i64 - 1;
        if ia <= ib {
            bits.set_span(j, ia as usize, ib as usize);
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (scene, cell, eps, res) = common::scene_cell_eps_res(&args);
    let face = common::Face::parse(args.get(6).map_or("+x", String::as_str));
    let step: usize = args.get(7).map_or(2, |s| s.parse().expect("STEP"));
    let start: f64 = args.get(8).map_or(1.0, |s| s.parse().expect("START"));
    let (axis, sign) = (face.axis, face.sign);
    let (a, b, c) = (axis, (axis + 1) % 3, (axis + 2) % 3);
    let data = common::sampler_data(&scene);
    let eye = face.centre(&cell);
    let h = eps / 2f64.sqrt();
    let view = |q: DVec3| {
        let d = q - eye;
        DVec3::new(d[b], d[c], sign * d[a])
    };
    let (objs, boxes) = face.beyond(&scene, &cell);
    // Occludees the front view alone decides: every corner inside the front view from every
    // corner of the rectangle, with a margin.
    let front: Vec<usize> = (0..objs.len())
        .filter(|&i| {
            let bx = boxes[i];
            (0..8).all(|k| {
                let q = DVec3::new(
                    if k & 1 == 0 { bx.min.x } else { bx.max.x },
                    if k & 2 == 0 { bx.min.y } else { bx.max.y },
                    if k & 4 == 0 { bx.min.z } else { bx.max.z },
                );
                let v = view(q);
                v.z > 2.0 * eps && v.x.abs() + h < 0.95 * v.z && v.y.abs() + h < 0.95 * v.z
            })
        })
        .collect();
    println!(
        "{} objects beyond the face, {} decided by the front view alone",
        objs.len(),
        front.len()
    );
    // The hemicube as the bake uses it: a first render for all, then bands of √2.
    let tri_hidden = |hc: &Hemicube, t: u32| {
        hc.test_triangle(scene.triangle(t as usize).map(|p| p.as_dvec3())) == BoxTest::Hidden
    };
    let mut hc = Hemicube::new(res);
    hc.set_depth_bounded(true);
    let fb: Vec<DAabb> = front.iter().map(|&i| boxes[i]).collect();
    let t = Instant::now();
    hc.begin_patch(eye, axis, sign, [h, h], &fb);
    hc.draw(&data.occluders);
    let mut cur_tri: std::collections::HashMap<u32, bool> = Default::default();
    let mut cur_obj = vec![false; front.len()];
    for (k, &i) in front.iter().enumerate() {
        let o = objs[i];
        let boxh = hc.test_box(&boxes[i]) == BoxTest::Hidden;
        for t in scene.objects[o].triangles.clone() {
            let e = cur_tri.entry(t).or_insert(false);
            *e |= boxh || tri_hidden(&hc, t);
        }
        cur_obj[k] = boxh || scene.objects[o].triangles.clone().all(|t| cur_tri[&t]);
    }
    let far = |bx: &DAabb| (bx.min - eye).abs().max((bx.max - eye).abs()).length();
    let mut lo = 0.0;
    let mut hi = 0.5;
    while lo < 1e6 {
        let idx: Vec<usize> = (0..front.len())
            .filter(|&k| !cur_obj[k] && far(&boxes[front[k]]) > lo && far(&boxes[front[k]]) <= hi)
            .collect();
        if !idx.is_empty() {
            let bb: Vec<DAabb> = idx.iter().map(|&k| boxes[front[k]]).collect();
            hc.begin_patch(eye, axis, sign, [h, h], &bb);
            hc.draw(&data.occluders);
            for &k in &idx {
                let o = objs[front[k]];
                let boxh = hc.test_box(&boxes[front[k]]) == BoxTest::Hidden;
                for t in scene.objects[o].triangles.clone() {
                    let e = cur_tri.entry(t).or_insert(false);
                    *e |= boxh || tri_hidden(&hc, t);
                }
                cur_obj[k] = boxh || scene.objects[o].triangles.clone().all(|t| cur_tri[&t]);
            }
        }
        lo = hi;
        hi *= 2f64.sqrt();
    }
    let t_cur = t.elapsed().as_secs_f64();

    // The sweep.
    let t = Instant::now();
    let n = res as usize * 8;
    let s = 2.0 / n as f64;
    // Slab ends: start, then each the depth at which the rectangle's motion grows by `step`
    // sub-pixels; the last is infinity.
    let mut ends = vec![start];
    loop {
        let inv = 1.0 / ends.last().unwrap() - step as f64 * s / h;
        if inv <= 0.0 {
            ends.push(f64::INFINITY);
            break;
        }
        ends.push(1.0 / inv);
    }
    let corners = [
        DVec2::new(-h, -h),
        DVec2::new(h, -h),
        DVec2::new(h, h),
        DVec2::new(-h, h),
    ];
    // Leaves in front of every corner, by slab of their farthest depth.
    let occ = &data.occluders;
    let mut by_slab: Vec<Vec<(f64, usize)>> = vec![Vec::new(); ends.len()];
    let mut left_out = 0;
    for (pi, poly) in occ.polys.iter().enumerate() {
        let pts = &occ.points[poly.start as usize..poly.end as usize];
        let vs: Vec<DVec3> = pts.iter().map(|&q| view(q)).collect();
        if vs.iter().any(|v| v.z <= eps) {
            left_out += 1;
            continue;
        }
        // Roughly in the front view.
        if vs.iter().all(|v| v.x > v.z * 1.1 + h)
            || vs.iter().all(|v| -v.x > v.z * 1.1 + h)
            || vs.iter().all(|v| v.y > v.z * 1.1 + h)
            || vs.iter().all(|v| -v.y > v.z * 1.1 + h)
        {
            continue;
        }
        let zf = vs.iter().map(|v| v.z).fold(0.0, f64::max);
        let k = ends.partition_point(|&e| e < zf);
        by_slab[k].push((zf, pi));
    }
    // Occludee triangles (of the front objects), by slab: the last slab ending at or before
    // their nearest depth.
    struct Occ {
        tri: u32,
        lo: DVec2,
        hi: DVec2,
        t0: f64,
        t1: f64,
    }
    let mut tests: Vec<Vec<Occ>> = (0..ends.len()).map(|_| Vec::new()).collect();
    let mut sweep_tri: std::collections::HashMap<u32, bool> = Default::default();
    for &i in &front {
        for t in scene.objects[objs[i]].triangles.clone() {
            let vs = scene.triangle(t as usize).map(|p| view(p.as_dvec3()));
            let t0 = vs.iter().map(|v| v.z).fold(f64::INFINITY, f64::min);
            let t1 = vs.iter().map(|v| v.z).fold(0.0, f64::max);
            let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
            for v in vs {
                let q = DVec2::new(v.x / v.z, v.y / v.z);
                lo = lo.min(q);
                hi = hi.max(q);
            }
            sweep_tri.insert(t, false);
            // Tested in the slab that holds its nearest depth, once the leaves nearer than it
            // are drawn (in that slab's frame, its end).
            let k = ends.partition_point(|&e| e < t0);
            tests[k].push(Occ {
                tri: t,
                lo,
                hi,
                t0,
                t1,
            });
        }
    }
    let mut bits = Bits::new(n);
    let mut drawn = 0usize;
    for k in 0..ends.len() {
        let r = ends[k];
        if k > 0 {
            bits.erode(step);
        }
        by_slab[k].sort_by(|x, y| x.0.total_cmp(&y.0));
        tests[k].sort_by(|x, y| x.t0.total_cmp(&y.t0));
        let mut next = 0;
        let inv_r = if r.is_finite() { 1.0 / r } else { 0.0 };
        let mut test_upto = |bits: &Bits, upto: f64, next: &mut usize| {
            while *next < tests[k].len() && tests[k][*next].t0 < upto {
                let o = &tests[k][*next];
                *next += 1;
                let e = h * (1.0 / o.t0 - inv_r).abs().max((1.0 / o.t1 - inv_r).abs());
                let (lo, hi) = (o.lo - DVec2::splat(e), o.hi + DVec2::splat(e));
                let ia = ((lo.x + 1.0) / s).floor().max(0.0) as usize;
                let ib = (((hi.x + 1.0) / s).floor() as usize).min(n - 1);
                let ja = ((lo.y + 1.0) / s).floor().max(0.0) as usize;
                let jb = (((hi.y + 1.0) / s).floor() as usize).min(n - 1);
                if (ja..=jb).all(|j| (ia..=ib).all(|i| bits.get(i, j))) {
                    sweep_tri.insert(o.tri, true);
                }
            }
        };
        for &(zf, pi) in &by_slab[k] {
            // Occludees nearer than this leaf's farthest depth are tested first.
            test_upto(&bits, zf, &mut next);
            let poly = occ.polys[pi];
            let pts = &occ.points[poly.start as usize..poly.end as usize];
            let vs: Vec<DVec3> = pts.iter().map(|&q| view(q)).collect();
            let mut acc: Option<Vec<DVec2>> = None;
            let mut flip = None;
            for cn in corners {
                // Projection from the corner onto the plane at depth r, in view units / r.
                let proj: Vec<DVec2> = vs
                    .iter()
                    .map(|v| {
                        let q = DVec2::new(v.x, v.y);
                        if r.is_finite() {
                            cn / r + (q - cn) / v.z
                        } else {
                            (q - cn) / v.z
                        }
                    })
                    .collect();
                let ar = area2(&proj);
                let f = ar < 0.0;
                if *flip.get_or_insert(f) != f || ar.abs() < 1e-18 {
                    acc = Some(Vec::new());
                    break;
                }
                let proj: Vec<DVec2> = if f {
                    proj.into_iter().rev().collect()
                } else {
                    proj
                };
                acc = Some(match acc {
                    None => proj,
                    Some(p) => {
                        let mut p = p;
                        for e in 0..proj.len() {
                            p = clip_left(&p, proj[e], proj[(e + 1) % proj.len()]);
                            if p.is_empty() {
                                break;
                            }
                        }
                        p
                    }
                });
            }
            if let Some(p) = acc
                && p.len() >= 3
            {
                draw(&mut bits, &p);
                drawn += 1;
            }
        }
        test_upto(&bits, f64::INFINITY, &mut next);
    }
    let t_sweep = t.elapsed().as_secs_f64();
    // The library's sweep, all five views, on the same objects.
    let t = Instant::now();
    let mut rs = umbrasweep::sampler::RectSweep::with_start(res, start / eps);
    let fboxes: Vec<DAabb> = front.iter().map(|&i| boxes[i]).collect();
    let front_objs: Vec<usize> = front.iter().map(|&i| objs[i]).collect();
    let objs_lib = common::BoxObjects::new(&scene, &front_objs, fboxes);
    let (lib_hidden, lst) = rs.render(&data.occluders, eye, axis, sign, [h, h], &objs_lib);
    println!(
        "library sweep: {} hidden in {:.2} s ({lst:?})",
        lib_hidden.iter().filter(|&&x| x).count(),
        t.elapsed().as_secs_f64()
    );
    for (k, &hid) in lib_hidden.iter().enumerate() {
        if hid {
            for t in scene.objects[objs[front[k]]].triangles.clone() {
                sweep_tri.insert(t, true);
            }
        }
    }
    // Brute force: random segments from the rectangle to each triangle the sweep hid.
    let mut eb = DVec3::ZERO;
    eb[b] = 1.0;
    let mut ec = DVec3::ZERO;
    ec[c] = 1.0;
    let mut rnd = common::uniform(11);
    let (mut checked, mut leaks, mut segs) = (0, 0, 0);
    for (&t, &hid) in &sweep_tri {
        if !hid {
            continue;
        }
        checked += 1;
        let [p0, p1, p2] = scene.triangle(t as usize).map(|p| p.as_dvec3());
        for _ in 0..32 {
            let p = eye + eb * (h * (2.0 * rnd() - 1.0)) + ec * (h * (2.0 * rnd() - 1.0));
            let (mut u, mut v) = (rnd(), rnd());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let x = p0 + (p1 - p0) * u + (p2 - p0) * v;
            segs += 1;
            let hits = data.rays.trace(p.as_vec3(), (x - p).as_vec3(), true);
            let blocked = hits.iter().any(|hh| hh.t < 1.0 - 1e-4 && hh.triangle != t);
            if !blocked {
                leaks += 1;
                break;
            }
        }
    }
    println!("brute force: {checked} triangles the sweep hid, {segs} segments, {leaks} seen");
    let (mut nc, mut ns, mut nu) = (0, 0, 0);
    for (k, &i) in front.iter().enumerate() {
        let o = objs[i];
        let sw = scene.objects[o].triangles.clone().all(|t| sweep_tri[&t]);
        let un = scene.objects[o]
            .triangles
            .clone()
            .all(|t| sweep_tri[&t] || cur_tri[&t]);
        nc += cur_obj[k] as usize;
        ns += sw as usize;
        nu += un as usize;
    }
    println!(
        "hemicube (first render + bands): {nc} hidden in {t_cur:.2} s; sweep ({} slabs of {step} \
         sub-pixels from {start}, {drawn} polygons drawn, {left_out} too near): {ns} hidden in \
         {t_sweep:.2} s; either per triangle: {nu}",
        ends.len()
    );
}
