//! Concave occluder slicing (Durand §3.3): the cross-section of a closed object with a
//! projection plane, as segments whose even-odd interior is the solid's section. A ray from a
//! cell outside the solid to a point of the section has crossed the solid's surface, so the
//! section is an occluder at Depth 0.

use crate::scene::{Scene, is_degenerate};
use glam::{DVec2, DVec3, Vec3};

/// Appends the segments where the plane `x[axis] = position` cuts the triangles of `object`,
/// in world `(u, v) = (axis+1, axis+2)` coordinates. Vertices exactly on the plane count as
/// below it, so every closed surface gives closed loops; the cut point of an edge is computed
/// from its endpoints in a canonical order, so the two triangles sharing it agree to the bit.
pub fn slice_object(
    scene: &Scene,
    object: u32,
    axis: usize,
    position: f64,
    out: &mut Vec<[DVec2; 2]>,
) {
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let cut = |a: Vec3, b: Vec3| -> DVec2 {
        let key = |p: Vec3| (p.x.to_bits(), p.y.to_bits(), p.z.to_bits());
        let (a, b) = if key(a) <= key(b) { (a, b) } else { (b, a) };
        let (a, b): (DVec3, DVec3) = (a.as_dvec3(), b.as_dvec3());
        let t = (position - a[axis]) / (b[axis] - a[axis]);
        DVec2::new(a[u] + (b[u] - a[u]) * t, a[v] + (b[v] - a[v]) * t)
    };
    let range = scene.objects[object as usize].triangles.clone();
    for t in range {
        let tri = scene.triangle(t as usize);
        let above = tri.map(|p| p[axis] as f64 > position);
        let n = above.iter().filter(|&&x| x).count();
        if n == 0 || n == 3 || is_degenerate(tri) {
            continue;
        }
        let mut pts = [DVec2::ZERO; 2];
        let mut k = 0;
        for e in 0..3 {
            let (i, j) = (e, (e + 1) % 3);
            if above[i] != above[j] {
                pts[k] = cut(tri[i], tri[j]);
                k += 1;
            }
        }
        out.push(pts);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn a_box_slices_into_a_closed_rectangle() {
        let tris = crate::geom::box_triangles(Vec3::new(0.0, 0.0, 0.0), Vec3::new(2.0, 4.0, 6.0));
        let scene = Scene::from_objects(Path::new("t"), vec![("b".into(), tris, true)]);
        let mut segs = Vec::new();
        slice_object(&scene, 0, 2, 3.0, &mut segs);
        assert!(segs.len() >= 4);
        // Every endpoint is shared by exactly two segment ends (closed loops).
        let mut ends: Vec<(u64, u64)> = segs
            .iter()
            .flat_map(|s| s.iter().map(|p| (p.x.to_bits(), p.y.to_bits())))
            .collect();
        ends.sort();
        for w in ends.chunks(2) {
            assert_eq!(w[0], w[1]);
        }
        for s in &segs {
            for p in s {
                assert!((0.0..=2.0).contains(&p.x) && (0.0..=4.0).contains(&p.y));
            }
        }
    }
}
