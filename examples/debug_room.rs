use glam::Vec3;
use std::path::Path;
use umbrasweep::backend::{RasterBackend, cpu::CpuBackend};
use umbrasweep::bake::{BakeSettings, Prepared};
use umbrasweep::geom::{Aabb, box_triangles};
use umbrasweep::hdm::Hdm;
use umbrasweep::project::occludee::*;
use umbrasweep::scene::Scene;
fn main() {
    let (a, b) = (3.0, 3.5);
    let c = |n: &str, mn: [f32; 3], mx: [f32; 3]| (n.to_string(), box_triangles(mn.into(), mx.into()), true);
    let objs = vec![
        c("room+x", [a, -b, -b], [b, b, b]), c("room-x", [-b, -b, -b], [-a, b, b]),
        c("room+y", [-b, a, -b], [b, b, b]), c("room-y", [-b, -b, -b], [b, -a, b]),
        c("room+z", [-b, -b, a], [b, b, b]), c("room-z", [-b, -b, -b], [b, b, -a]),
        c("o", [7.5, 7.5, 7.5], [8.5, 8.5, 8.5]),
    ];
    let scene = Scene::from_objects(Path::new("x"), objs);
    let p = Prepared::new(&scene, &BakeSettings::default()).unwrap();
    let cell = Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5));
    let jobs = p.jobs(&cell);
    let maps = CpuBackend.render(&jobs).unwrap();
    let ob = scene.objects[6].bounds.to_f64();
    for (j, m) in jobs.iter().zip(&maps) {
        let f = &j.frame;
        let (lo, hi) = standard_rect(f, &ob);
        let pr = pixel_rect(f, lo, hi);
        let t = pr.map(|[i0, j0, i1, j1]| Hdm::build(m).test(i0, j0, i1, j1, 1.0));
        println!("axis {} pos {} p {:.3} rect {:?}-{:?} occ {} slices {} covered {} | obj rect {:?}-{:?} px {:?} {:?}",
            f.axis, f.positive, f.position, f.rect_min, f.rect_max, j.occluders.len(), j.slices.len(), m.covered(), lo, hi, pr, t);
        if f.axis == 0 && f.positive {
            for k in 0..j.occluders.len() {
                let pts = j.occluders.get(k);
                let bb = umbrasweep::project::planes::projection_bounds(f, &f.cell.corners(), pts);
                let mut mn = glam::DVec3::INFINITY; let mut mx = glam::DVec3::NEG_INFINITY;
                for q in pts { mn = mn.min(*q); mx = mx.max(*q); }
                println!("   occ {k}: {} pts {:?}-{:?} bounds {:?}", pts.len(), mn, mx, bb);
            }
        }
    }
}
#[allow(dead_code)]
fn _x() {}
