//! Walks a camera along a path through a baked scene and prints, per frame, how many objects
//! it would draw with frustum culling alone and with frustum culling plus the PVS.
//!
//! ```sh
//! cargo run --release -- bake data/demo_city.obj --cells data/demo_city_cells.json -o city.pvs
//! cargo run --release --example walkthrough -- city.pvs [FRAMES_PER_SEGMENT]
//! ```
//!
//! The path visits cell 0, then the nearest cell not visited yet, and so on (40 cells at
//! most); in each cell the camera sweeps across the cell towards the next one, looking along
//! the path with a 90° horizontal and
//! 60° vertical field of view, y up. Uses only the run-time library (`PvsDatabase`,
//! `PvsCursor`), so it also builds with `--no-default-features --features runtime`.

use glam::Vec3;
use umbrasweep::pvs::{CellId, PvsDatabase};

/// Whether the box is (partly) inside the frustum of a camera at `eye` looking along `fwd`.
fn in_frustum(eye: Vec3, fwd: Vec3, min: Vec3, max: Vec3) -> bool {
    let right = fwd.cross(Vec3::Y).normalize_or(Vec3::X);
    let up = right.cross(fwd);
    let (th, tv) = (45f32.to_radians().tan(), 30f32.to_radians().tan());
    // Inside when n · (x - eye) >= d for every plane.
    let planes = [
        (fwd * th - right, 0.0),
        (fwd * th + right, 0.0),
        (fwd * tv - up, 0.0),
        (fwd * tv + up, 0.0),
        (fwd, 0.05),
    ];
    planes.iter().all(|&(n, d)| {
        // The box corner farthest along n.
        let p = Vec3::select(n.cmpge(Vec3::ZERO), max, min);
        n.dot(p - eye) >= d
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next() else {
        eprintln!(
            "usage: walkthrough FILE.pvs [FRAMES_PER_SEGMENT]\n\
             make one with: cargo run --release -- bake data/demo_city.obj \
             --cells data/demo_city_cells.json -o city.pvs"
        );
        std::process::exit(2);
    };
    let per_segment: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(8);
    let db = PvsDatabase::open(&path)?;
    if db.cell_count() == 0 {
        return Err("the file has no cells".into());
    }
    let centre = |c: usize| {
        let (lo, hi) = db.cell_bounds(CellId(c as u32));
        (Vec3::from(lo) + Vec3::from(hi)) * 0.5
    };
    // Greedy nearest-neighbour tour over the cell centres.
    let mut tour = vec![0usize];
    let mut seen = vec![false; db.cell_count()];
    seen[0] = true;
    while tour.len() < db.cell_count().min(40) {
        let here = centre(*tour.last().unwrap_or(&0));
        let next = (0..db.cell_count()).filter(|&c| !seen[c]).min_by(|&a, &b| {
            here.distance_squared(centre(a))
                .total_cmp(&here.distance_squared(centre(b)))
        });
        let Some(next) = next else { break };
        seen[next] = true;
        tour.push(next);
    }
    let objects: Vec<(Vec3, Vec3)> = (0..db.object_count() as u32)
        .filter_map(|o| db.object(o))
        .map(|o| (Vec3::from(o.min), Vec3::from(o.max)))
        .collect();

    println!("frame  cell  frustum  frustum+PVS");
    let mut cursor = db.cursor();
    let (mut frames, mut sum_frustum, mut sum_pvs, mut outside) = (0usize, 0usize, 0usize, 0);
    let mut fwd = Vec3::X;
    for w in tour.windows(2) {
        let (a, b) = (centre(w[0]), centre(w[1]));
        if let Some(d) = (b - a).with_y(0.0).try_normalize() {
            fwd = d;
        }
        // Sweep across the cell towards the next one, staying inside the cell.
        let (lo, hi) = db.cell_bounds(CellId(w[0] as u32));
        let half = (Vec3::from(hi) - Vec3::from(lo)) * 0.45;
        let (from, to) = (a - fwd * half, a + fwd * half);
        for k in 0..per_segment {
            let eye = from.lerp(to, k as f32 / per_segment as f32);
            let frustum: Vec<u32> = objects
                .iter()
                .enumerate()
                .filter(|(_, (lo, hi))| lo.cmple(*hi).all() && in_frustum(eye, fwd, *lo, *hi))
                .map(|(i, _)| i as u32)
                .collect();
            // Outside every cell the engine has no PVS and draws the frustum's objects.
            let (cell, drawn) = match db.cell_at(eye) {
                Some(c) => {
                    cursor.move_to(&db, c);
                    let n = frustum.iter().filter(|&&o| cursor.contains(o)).count();
                    (c.to_string(), n)
                }
                None => {
                    outside += 1;
                    ("-".to_string(), frustum.len())
                }
            };
            println!("{frames:5}  {cell:>4}  {:7}  {drawn:11}", frustum.len());
            frames += 1;
            sum_frustum += frustum.len();
            sum_pvs += drawn;
        }
    }
    let f = frames.max(1) as f64;
    println!(
        "{frames} frames ({outside} outside every cell): {:.1} objects per frame with frustum \
         culling alone, {:.1} with the PVS too ({:.2}x fewer), of {} objects",
        sum_frustum as f64 / f,
        sum_pvs as f64 / f,
        sum_frustum as f64 / (sum_pvs as f64).max(1.0),
        db.object_count()
    );
    Ok(())
}
