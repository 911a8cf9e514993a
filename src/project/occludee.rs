//! Occludee extended projections (Durand §3.1 and §4): bounding rectangles on a plane of the
//! union of the views of a box from every point of the cell, and the improved Projection for
//! boxes lying between the cell and the plane.

use crate::backend::PlaneFrame;
use crate::geom::DAabb;
use glam::DVec2;

/// Where an occludee box lies relative to a plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OccludeeSpan {
    /// Depth of the box's nearest point (its minimum Depth, §2.3).
    pub depth: f64,
    /// True when the whole box lies between the cell's face and the plane.
    pub in_front: bool,
}

/// The box's Depth span when it lies strictly beyond the cell's face, else `None` (some ray
/// from the cell to it does not travel toward this plane).
pub fn span(frame: &PlaneFrame, b: &DAabb) -> Option<OccludeeSpan> {
    let a = frame.axis;
    let s = frame.sign();
    let (near, far) = if frame.positive {
        (b.min[a], b.max[a])
    } else {
        (b.max[a], b.min[a])
    };
    if s * (near - frame.face()) <= 0.0 {
        return None;
    }
    Some(OccludeeSpan {
        depth: s * (near - frame.position),
        in_front: s * (far - frame.position) <= 0.0,
    })
}

/// The standard Projection's bounding rectangle (world `(u, v)`), exact for the union of views:
/// each coordinate of a view point is monotone in every coordinate of the eye and of the box
/// point separately, so its extremes over cell × box are reached at corners (the separating /
/// supporting lines of §3.1). The box must lie strictly beyond the face ([`span`]).
pub fn standard_rect(frame: &PlaneFrame, b: &DAabb) -> (DVec2, DVec2) {
    let a = frame.axis;
    let (u, v) = frame.uv_axes();
    let c = &frame.cell;
    let p = frame.position;
    let mut lo = DVec2::INFINITY;
    let mut hi = DVec2::NEG_INFINITY;
    for va in [c.min[a], c.max[a]] {
        for xa in [b.min[a], b.max[a]] {
            let t = (p - va) / (xa - va);
            // q = vu + (xu − vu)·t is affine in the eye's coordinate vu (slope 1 − t) and in
            // the box point's xu (slope t): its least and greatest values are at the ends the
            // slopes' signs pick (4 evaluations per (va, xa) instead of 8).
            for (k, ax) in [u, v].into_iter().enumerate() {
                let (cl, ch) = if t <= 1.0 {
                    (c.min[ax], c.max[ax])
                } else {
                    (c.max[ax], c.min[ax])
                };
                let (bl, bh) = if t >= 0.0 {
                    (b.min[ax], b.max[ax])
                } else {
                    (b.max[ax], b.min[ax])
                };
                lo[k] = lo[k].min(cl + (bl - cl) * t);
                hi[k] = hi[k].max(ch + (bh - ch) * t);
            }
        }
    }
    (lo, hi)
}

/// The improved Projection (§4) of a box lying between the cell's face and the plane: per
/// in-plane axis, the segment between the two supporting lines of the cell and the box where
/// they meet the plane, or its mid-point when they cross before the plane. Valid with convex or
/// planar occluders (all of ours) and the usual Depth test.
pub fn improved_rect(frame: &PlaneFrame, b: &DAabb) -> (DVec2, DVec2) {
    let a = frame.axis;
    let s = frame.sign();
    let face = frame.face();
    let c = &frame.cell;
    let l = c.max[a] - c.min[a];
    let (near, far) = if frame.positive {
        (b.min[a], b.max[a])
    } else {
        (b.max[a], b.min[a])
    };
    let tb0 = s * (near - face);
    let tb1 = s * (far - face);
    let tp = s * (frame.position - face);
    let (u, v) = frame.uv_axes();
    let mut lo = DVec2::ZERO;
    let mut hi = DVec2::ZERO;
    for (k, ax) in [u, v].into_iter().enumerate() {
        let (cu0, cu1, bu0, bu1) = (c.min[ax], c.max[ax], b.min[ax], b.max[ax]);
        // Upper supporting line: through the cell's back top corner and the box's near top
        // corner when the box is higher, else through the cell's front top corner and the box's
        // far top corner.
        let upper = if bu1 >= cu1 {
            cu1 + (bu1 - cu1) * (tp + l) / (tb0 + l)
        } else {
            cu1 + (bu1 - cu1) * tp / tb1
        };
        let lower = if bu0 <= cu0 {
            cu0 + (bu0 - cu0) * (tp + l) / (tb0 + l)
        } else {
            cu0 + (bu0 - cu0) * tp / tb1
        };
        if lower <= upper {
            lo[k] = lower;
            hi[k] = upper;
        } else {
            let m = 0.5 * (lower + upper);
            lo[k] = m;
            hi[k] = m;
        }
    }
    (lo, hi)
}

/// The pixels `[i0, i1] × [j0, j1]` a world rectangle overlaps (rounded outward; a pixel that
/// only touches it counts), or `None` when any part of it falls outside the plane's rectangle.
pub fn pixel_rect(frame: &PlaneFrame, lo: DVec2, hi: DVec2) -> Option<[u32; 4]> {
    let pl = frame.to_pixel(lo);
    let ph = frame.to_pixel(hi);
    let (w, h) = (frame.width, frame.height);
    if !(pl.x >= 0.0 && pl.y >= 0.0 && ph.x <= w as f64 && ph.y <= h as f64) {
        return None;
    }
    // A rectangle touching the far edge (pixel coordinate == width or height) touches the last
    // pixel: clamp both ends into the map.
    let i0 = (pl.x.floor() as u32).min(w - 1);
    let j0 = (pl.y.floor() as u32).min(h - 1);
    let i1 = (ph.x.floor() as u32).min(w - 1);
    let j1 = (ph.y.floor() as u32).min(h - 1);
    Some([i0, j0, i1.max(i0), j1.max(j0)])
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn frame(position: f64) -> PlaneFrame {
        PlaneFrame {
            cell: DAabb {
                min: DVec3::new(-1.0, -1.0, -1.0),
                max: DVec3::new(1.0, 1.0, 1.0),
            },
            axis: 2,
            positive: true,
            position,
            rect_min: DVec2::splat(-50.0),
            rect_max: DVec2::splat(50.0),
            width: 64,
            height: 64,
        }
    }

    /// Every ray from a sample of cell points to a sample of box points crosses the plane
    /// inside the rectangle.
    fn contains_all_views(f: &PlaneFrame, b: &DAabb, lo: DVec2, hi: DVec2) -> bool {
        let steps = 6;
        let lerp = |a: DVec3, b: DVec3, t: DVec3| a + (b - a) * t;
        for i in 0..=steps * steps * steps {
            let t = DVec3::new(
                (i % (steps + 1)) as f64,
                ((i / (steps + 1)) % (steps + 1)) as f64,
                (i / ((steps + 1) * (steps + 1))) as f64,
            ) / steps as f64;
            let eye = lerp(f.cell.min, f.cell.max, t);
            for j in 0..27 {
                let s = DVec3::new((j % 3) as f64, ((j / 3) % 3) as f64, (j / 9) as f64) / 2.0;
                let q = f.project(eye, lerp(b.min, b.max, s));
                if q.x < lo.x - 1e-9 || q.y < lo.y - 1e-9 || q.x > hi.x + 1e-9 || q.y > hi.y + 1e-9
                {
                    return false;
                }
            }
        }
        true
    }

    #[test]
    fn standard_rect_holds_every_view_in_front_of_and_behind_the_plane() {
        let b = DAabb {
            min: DVec3::new(2.0, -3.0, 4.0),
            max: DVec3::new(5.0, 1.0, 6.0),
        };
        for pos in [5.0, 8.0, 20.0] {
            let f = frame(pos);
            let (lo, hi) = standard_rect(&f, &b);
            assert!(contains_all_views(&f, &b, lo, hi), "plane at {pos}");
        }
    }

    /// The rectangle equals the extremes over all 64 pairs of cell and box corners (the
    /// definition), on boxes beyond, straddling and in front of planes on every side.
    #[test]
    fn standard_rect_is_the_extreme_over_all_corner_pairs() {
        let mut seed = 7u64;
        let mut rnd = |lo: f64, hi: f64| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            lo + (hi - lo) * ((seed >> 11) as f64 / (1u64 << 53) as f64)
        };
        for case in 0..500 {
            let mut f = frame(rnd(1.5, 30.0));
            f.axis = case % 3;
            f.positive = case % 2 == 0;
            let s = f.sign();
            f.position = f.face() + s * rnd(0.2, 30.0);
            let a = f.axis;
            let mut min = DVec3::new(rnd(-20.0, 20.0), rnd(-20.0, 20.0), rnd(-20.0, 20.0));
            min[a] = f.face() + s * rnd(0.01, 40.0);
            let mut max = min + DVec3::new(rnd(0.0, 6.0), rnd(0.0, 6.0), rnd(0.0, 6.0));
            if !f.positive {
                (min[a], max[a]) = (min[a] - (max[a] - min[a]), min[a]);
            }
            let b = DAabb { min, max };
            let (u, v) = f.uv_axes();
            let c = f.cell;
            let (mut elo, mut ehi) = (DVec2::INFINITY, DVec2::NEG_INFINITY);
            for i in 0..8 {
                let eye = DVec3::new(
                    if i & 1 == 0 { c.min.x } else { c.max.x },
                    if i & 2 == 0 { c.min.y } else { c.max.y },
                    if i & 4 == 0 { c.min.z } else { c.max.z },
                );
                for j in 0..8 {
                    let x = DVec3::new(
                        if j & 1 == 0 { b.min.x } else { b.max.x },
                        if j & 2 == 0 { b.min.y } else { b.max.y },
                        if j & 4 == 0 { b.min.z } else { b.max.z },
                    );
                    let t = (f.position - eye[a]) / (x[a] - eye[a]);
                    let q = DVec2::new(eye[u] + (x[u] - eye[u]) * t, eye[v] + (x[v] - eye[v]) * t);
                    elo = elo.min(q);
                    ehi = ehi.max(q);
                }
            }
            let (lo, hi) = standard_rect(&f, &b);
            let tol = 1e-9 * (1.0 + ehi.abs().max(elo.abs()).max_element());
            assert!(
                (lo - elo).abs().max_element() <= tol && (hi - ehi).abs().max_element() <= tol,
                "case {case}: {lo:?}..{hi:?} against {elo:?}..{ehi:?}"
            );
        }
    }

    #[test]
    fn improved_rect_is_inside_the_standard_one_and_collapses_for_small_boxes() {
        let f = frame(30.0);
        let small = DAabb {
            min: DVec3::new(-0.2, -0.2, 4.0),
            max: DVec3::new(0.2, 0.2, 4.5),
        };
        let (slo, shi) = standard_rect(&f, &small);
        let (lo, hi) = improved_rect(&f, &small);
        assert_eq!(lo, hi, "supporting lines cross before the plane: a point");
        assert!(lo.x >= slo.x && hi.x <= shi.x);
        let big = DAabb {
            min: DVec3::new(-4.0, -3.0, 5.0),
            max: DVec3::new(3.0, 2.0, 7.0),
        };
        let (slo, shi) = standard_rect(&f, &big);
        let (lo, hi) = improved_rect(&f, &big);
        assert!(lo.x < hi.x && lo.y < hi.y);
        assert!(lo.x >= slo.x && lo.y >= slo.y && hi.x <= shi.x && hi.y <= shi.y);
        assert!((hi - lo).x < (shi - slo).x, "strictly tighter");
    }

    #[test]
    fn pixel_rects_touching_the_far_edges_stay_inside_the_map() {
        let f = frame(10.0);
        // Rectangle of zero width on the right/top edges of the plane (found on zdm2).
        let r = pixel_rect(&f, DVec2::splat(50.0), DVec2::splat(50.0)).unwrap();
        assert_eq!(r, [63, 63, 63, 63]);
        let r = pixel_rect(&f, DVec2::new(-50.0, 49.0), DVec2::new(50.0, 50.0)).unwrap();
        assert_eq!(r, [0, 63, 63, 63]);
        assert!(pixel_rect(&f, DVec2::splat(-51.0), DVec2::ZERO).is_none());
    }

    #[test]
    fn span_needs_the_box_beyond_the_face() {
        let f = frame(10.0);
        let straddling = DAabb {
            min: DVec3::new(0.0, 0.0, 0.5),
            max: DVec3::new(1.0, 1.0, 3.0),
        };
        assert!(span(&f, &straddling).is_none());
        let beyond = DAabb {
            min: DVec3::new(0.0, 0.0, 2.0),
            max: DVec3::new(1.0, 1.0, 3.0),
        };
        let s = span(&f, &beyond).unwrap();
        assert_eq!(s.depth, -8.0);
        assert!(s.in_front);
    }
}
