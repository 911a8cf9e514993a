//! Diagnostic for ray space factorization: `rsf_probe SCENE CELLS.json [CELL] [RES]` inserts
//! every upright occluder part of the scene into one cell's charts (no traversal) and prints
//! what the parts are, how full the charts get and how many object boxes they hide.
use glam::DVec3;
use umbrasweep::geom::DAabb;
use umbrasweep::project::occluders::PartKind;
use umbrasweep::rsf::RayCharts;

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let scene = umbrasweep::scene::load(std::path::Path::new(&a[1])).unwrap();
    let cells = umbrasweep::cells::load_json(std::path::Path::new(&a[2])).unwrap();
    let k: usize = a.get(3).map_or(0, |s| s.parse().unwrap());
    let res: u32 = a.get(4).map_or(512, |s| s.parse().unwrap());
    let cell = cells[k].to_f64();
    let occ =
        umbrasweep::project::occluders::prepare(&scene, &vec![true; scene.objects.len()], false);
    let (mut poly, mut bent, mut solid, mut upright) = (0, 0, 0, 0);
    let mut charts = RayCharts::new(&cell, 1, res);
    let t = std::time::Instant::now();
    let mut inserted = 0;
    let mut idx: Vec<usize> = (0..occ.parts.len()).collect();
    let dist = |b: &DAabb| {
        (cell.min - b.max)
            .max(b.min - cell.max)
            .max(DVec3::ZERO)
            .length()
    };
    idx.sort_by(|&a, &b| dist(&occ.parts[a].bounds).total_cmp(&dist(&occ.parts[b].bounds)));
    for i in idx {
        let p = &occ.parts[i];
        match p.kind {
            PartKind::Polygon { normal } => {
                poly += 1;
                if p.deviation > 0.0 {
                    bent += 1;
                    continue;
                }
                if normal.y.abs() <= 0.2 {
                    upright += 1;
                }
                if charts.insert(occ.part_points(i), None) > 0 {
                    inserted += 1;
                }
            }
            PartKind::Solid { .. } => {
                solid += 1;
                let pts = occ.part_points(i);
                if charts.insert(pts, Some(&umbrasweep::rsf::hull_edges(pts))) > 0 {
                    inserted += 1;
                }
            }
        }
    }
    println!(
        "cell {k} {:?}..{:?}: {poly} polygons ({bent} bent, {upright} upright), {solid} solids; {inserted} inserted, {} pixels, {:.0} ms",
        cell.min,
        cell.max,
        charts.work.pixels,
        t.elapsed().as_secs_f64() * 1e3
    );
    let n = charts.resolution();
    for c in 0..4 {
        let mut filled = 0;
        let mut guards = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let u = charts.umbrae(c, j, i);
                if u[0].guard.is_finite() {
                    filled += 1;
                    guards.push(u[0].guard);
                }
            }
        }
        guards.sort_by(f32::total_cmp);
        println!(
            "chart {c}: {:.1} % of pixels hold an umbra; near guard median {:?}",
            100.0 * filled as f64 / (n * n) as f64,
            guards.get(guards.len() / 2)
        );
    }
    let hidden = scene
        .objects
        .iter()
        .filter(|o| {
            let b: DAabb = o.bounds.to_f64();
            charts.box_hidden(&b)
        })
        .count();
    for c in 0..4 {
        let h = scene
            .objects
            .iter()
            .filter(|o| charts.box_hidden_in_chart(c, &o.bounds.to_f64()))
            .count();
        println!("chart {c}: {h} boxes hidden");
    }
    println!("{hidden} of {} object boxes hidden", scene.objects.len());
    if let Some(doc) = a.get(5) {
        let d: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(doc).unwrap()).unwrap();
        let vis: Vec<u64> = d["cells"][k]["visible"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        let mut shown = 0;
        for (o, ob) in scene.objects.iter().enumerate() {
            let b = ob.bounds.to_f64();
            if vis.contains(&(o as u64)) || charts.box_hidden(&b) {
                continue;
            }
            let fails: Vec<usize> = (0..4)
                .filter(|&c| !charts.box_hidden_in_chart(c, &b))
                .collect();
            if shown < 15 {
                println!(
                    "planes hide {o} {:?}..{:?} (distance {:.1}), rsf fails in charts {fails:?}",
                    b.min,
                    b.max,
                    dist(&b)
                );
            }
            shown += 1;
        }
        println!("{shown} objects hidden by the planes, not by rsf");
    }
}
