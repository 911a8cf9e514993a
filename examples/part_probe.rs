//! Diagnostic: which occluder parts a segment crosses, and what the real triangles say.
//! `part_probe SCENE SPLIT ox oy oz hx hy hz [OBJECT]`, or `part_probe SCENE SPLIT` for the
//! parts' size statistics (SPLIT 0: objects as in the file).
use glam::DVec3;
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let scene = umbrasweep::scene::load(std::path::Path::new(&a[1])).unwrap();
    let split: f32 = a[2].parse().unwrap();
    let scene = if split > 0.0 {
        umbrasweep::scene::split::split_objects(&scene, split).unwrap()
    } else {
        scene
    };
    if a.len() == 3 {
        let occ = umbrasweep::project::occluders::prepare(
            &scene,
            &vec![true; scene.objects.len()],
            false,
        );
        let mut sides: Vec<f64> = occ
            .parts
            .iter()
            .map(|p| (p.bounds.max - p.bounds.min).max_element())
            .collect();
        sides.sort_by(f64::total_cmp);
        let tris = occ.parts.iter().filter(|p| p.end - p.start == 3).count();
        println!(
            "{} parts ({} lone triangles) from {} triangles; largest side: median {:.2}, p90 {:.2}, max {:.2}",
            occ.parts.len(),
            tris,
            scene.triangles.len(),
            sides[sides.len() / 2],
            sides[sides.len() * 9 / 10],
            sides[sides.len() - 1]
        );
        // Area-weighted: the share of the occluder area in parts of each size.
        let area = |p: &umbrasweep::project::occluders::OccluderPart| {
            let pts = &occ.points[p.start as usize..p.end as usize];
            (1..pts.len().saturating_sub(1))
                .map(|i| (pts[i] - pts[0]).cross(pts[i + 1] - pts[0]).length() / 2.0)
                .sum::<f64>()
        };
        let total: f64 = occ.parts.iter().map(area).sum();
        for lim in [4.0, 16.0, 64.0, 256.0] {
            let a: f64 = occ
                .parts
                .iter()
                .filter(|p| (p.bounds.max - p.bounds.min).max_element() < lim)
                .map(area)
                .sum();
            println!(
                "  {:.1} % of the area in parts smaller than {lim}",
                100.0 * a / total
            );
        }
        return;
    }
    let v: Vec<f64> = a[3..9].iter().map(|s| s.parse().unwrap()).collect();
    let (o, h) = (DVec3::new(v[0], v[1], v[2]), DVec3::new(v[3], v[4], v[5]));
    let only = a.get(9).cloned();
    let is: Vec<bool> = scene
        .objects
        .iter()
        .map(|o| only.as_ref().is_none_or(|n| &o.name == n))
        .collect();
    let occ = umbrasweep::project::occluders::prepare(&scene, &is, false);
    if let Some(n) = &only {
        for p in &occ.parts {
            println!(
                "part of {n}: {:?}",
                &occ.points[p.start as usize..p.end as usize]
            );
        }
    }
    let d = h - o;
    for (k, p) in occ.parts.iter().enumerate() {
        let pts = &occ.points[p.start as usize..p.end as usize];
        if let umbrasweep::project::occluders::PartKind::Polygon { normal } = p.kind {
            let c = pts[0];
            let den = normal.dot(d);
            if den.abs() < 1e-12 {
                continue;
            }
            let t = normal.dot(c - o) / den;
            if !(0.0..1.001).contains(&t) {
                continue;
            }
            let x = o + d * t;
            let n = pts.len();
            let mut sign = 0.0f64;
            let mut inside = true;
            for i in 0..n {
                let e = pts[(i + 1) % n] - pts[i];
                let s = normal.dot(e.cross(x - pts[i]));
                if sign == 0.0 {
                    sign = s.signum();
                } else if s * sign < 0.0 {
                    inside = false;
                    break;
                }
            }
            if inside {
                println!(
                    "part {k} object {} ({}) t {t:.4} at {x:?} pts {} dev {} inr {}",
                    p.object, scene.objects[p.object as usize].name, n, p.deviation, p.inradius
                );
                for q in pts {
                    println!("   {q:?}");
                }
            }
        } else {
            let (mut t0, mut t1) = (0.0f64, 1.001f64);
            for ax in 0..3 {
                if d[ax].abs() < 1e-15 {
                    if o[ax] < p.bounds.min[ax] || o[ax] > p.bounds.max[ax] {
                        t1 = -1.0;
                    }
                    continue;
                }
                let (a, b) = (
                    (p.bounds.min[ax] - o[ax]) / d[ax],
                    (p.bounds.max[ax] - o[ax]) / d[ax],
                );
                t0 = t0.max(a.min(b));
                t1 = t1.min(a.max(b));
            }
            if t0 <= t1 {
                println!(
                    "solid part {k} object {} ({}) t {t0:.4} bounds {:?}",
                    p.object, scene.objects[p.object as usize].name, p.bounds
                );
            }
        }
    }
}
