//! Occludee extended projections (Durand §3.1 and §4): bounding rectangles on a plane of the
//! union of the views of a box from every point of the cell, and the improved Projection for
//! boxes lying between the cell and the plane.

use crate::geom::DAabb;
use crate::plane::{Coverage, PlaneFrame, RectQuery, depth_down};
use glam::DVec2;

/// Which box of a walk an occludee test is about: a node of the object hierarchy, an object,
/// a piece of an object, or an occluder part (the sweep's leave-out test). A plane's box tests
/// answered on a device are read back by it (`bake::planes`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoxId {
    /// A node of the object hierarchy, by its index.
    Node(u32),
    /// An object, by its index in the scene.
    Object(u32),
    /// A piece of a large object (a box around some of its triangles), by its index.
    Piece(u32),
    /// An occluder part, by its index in the occluder table.
    Part(u32),
}

/// True when [`box_coverage`] answers `Partial` for `b` on `frame` before any test: the box
/// touches the cell or does not lie strictly beyond its face (some ray from the cell to it
/// does not travel toward the plane).
pub fn open_without_test(frame: &PlaneFrame, b: &DAabb) -> bool {
    b.overlaps(&frame.cell) || span(frame, b).is_none()
}

/// [`box_coverage`]'s answer where it needs no test of the map: `Partial` for a box
/// [`open_without_test`], `Empty` for one whose standard Projection lies wholly beside the
/// plane's rectangle; `None` otherwise.
pub fn answer_without_test(frame: &PlaneFrame, b: &DAabb) -> Option<Coverage> {
    if open_without_test(frame, b) {
        return Some(Coverage::Partial);
    }
    let (lo, hi) = standard_rect(frame, b);
    (pixel_rect(frame, lo, hi).is_none() && beside(frame, lo, hi)).then_some(Coverage::Empty)
}

/// True when the world rectangle `[lo, hi]` does not meet the plane's rectangle.
fn beside(frame: &PlaneFrame, lo: DVec2, hi: DVec2) -> bool {
    let (clo, chi) = (lo.max(frame.rect_min), hi.min(frame.rect_max));
    !(clo.x <= chi.x && clo.y <= chi.y)
}

/// The occlusion test of one box (lying within the plane's reach) on one plane, given a way
/// to answer pixel rectangle tests (`test`, e.g. [`crate::hdm::Hdm::answer`]): `Hidden`;
/// `Empty` when nothing inside the box can be hidden on this plane (its Projection misses the
/// plane's rectangle, or covers no occluded pixel of it — a child's Projection lies inside
/// its parent's); `Partial` otherwise, including boxes touching the cell (`frame.cell`) or
/// not strictly beyond its face. `improved`: also try the improved Projections
/// ([`improved_rects`]) of a box between the face and the plane whose standard Projection is
/// not decisive.
///
/// The one statement of the rule: the CPU's walk asks it of a pyramid, and a device answering
/// box tests (`shaders/boxes.wgsl`) repeats it step for step.
pub fn box_coverage(
    frame: &PlaneFrame,
    b: &DAabb,
    improved: bool,
    mut test: impl FnMut(&RectQuery) -> Coverage,
) -> Coverage {
    // Open without a test (`open_without_test`).
    let sp = match span(frame, b) {
        Some(sp) if !b.overlaps(&frame.cell) => sp,
        _ => return Coverage::Partial,
    };
    let depth = depth_down(sp.depth);
    let (lo, hi) = standard_rect(frame, b);
    let standard = match pixel_rect(frame, lo, hi) {
        Some(rect) => test(&RectQuery { rect, depth }),
        None => {
            // Partly outside the plane: only the part inside can hold a descendant.
            if beside(frame, lo, hi) {
                return Coverage::Empty;
            }
            let (clo, chi) = (lo.max(frame.rect_min), hi.min(frame.rect_max));
            match pixel_rect(frame, clo, chi) {
                Some(rect)
                    if test(&RectQuery {
                        rect,
                        depth: f32::INFINITY,
                    }) == Coverage::Empty =>
                {
                    Coverage::Empty
                }
                _ => Coverage::Partial,
            }
        }
    };
    if standard != Coverage::Partial || !(sp.in_front && improved) {
        return standard;
    }
    // Either improved Projection, covered, proves the box hidden (each is sound alone).
    let hidden = improved_rects(frame, b).any(|(lo, hi)| {
        pixel_rect(frame, lo, hi)
            .is_some_and(|rect| test(&RectQuery { rect, depth }) == Coverage::Hidden)
    });
    if hidden {
        Coverage::Hidden
    } else {
        Coverage::Partial
    }
}

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
    // Rounding: a few ulps per value; pad outward by far more.
    let pad = 1e-12 * (1.0 + lo.abs().max(hi.abs()).max_element());
    (lo - pad, hi + pad)
}

/// The improved Projection (§4) of a box lying between the cell's face and the plane, for
/// one eye depth: `eye` is how far behind the cell's face the eyes are taken (`0` the face,
/// the cell's depth its back face). Per in-plane axis, the segment between the two supporting
/// lines of the cell's cross-section at that depth and the box where they meet the plane, or
/// its mid-point when they cross before the plane. Valid with convex or planar occluders (all
/// of ours) and the usual Depth test; see [`improved_rects`] for the argument.
pub fn improved_rect_at(frame: &PlaneFrame, b: &DAabb, eye: f64) -> (DVec2, DVec2) {
    let a = frame.axis;
    let s = frame.sign();
    let face = frame.face();
    let c = &frame.cell;
    let (near, far) = if frame.positive {
        (b.min[a], b.max[a])
    } else {
        (b.max[a], b.min[a])
    };
    // Distances from the eyes' depth: to the box's near and far sides and to the plane.
    let n = s * (near - face) + eye;
    let f = s * (far - face) + eye;
    let d = s * (frame.position - face) + eye;
    let (u, v) = frame.uv_axes();
    let mut lo = DVec2::ZERO;
    let mut hi = DVec2::ZERO;
    for (k, ax) in [u, v].into_iter().enumerate() {
        let (cu0, cu1, bu0, bu1) = (c.min[ax], c.max[ax], b.min[ax], b.max[ax]);
        // A point at distance z from the eyes is inside the cone from the plane's segment
        // [lo, hi] to the eye segment [cu0, cu1] when cu1 + (x − cu1)·d/z ≤ hi and
        // cu0 + (x − cu0)·d/z ≥ lo: the upper bound is needed at the box's near side when
        // the box reaches above the cell, at its far side otherwise (and likewise below).
        let upper = cu1 + (bu1 - cu1) * d / if bu1 >= cu1 { n } else { f };
        let lower = cu0 + (bu0 - cu0) * d / if bu0 <= cu0 { n } else { f };
        let (l, h) = if lower <= upper {
            (lower, upper)
        } else {
            // The lines cross before the plane: any point between them will do.
            let m = 0.5 * (lower + upper);
            (m, m)
        };
        // Rounding: every difference above is of nearby f32-born values (exact), so only the
        // product and quotient round; pad by far more than their few ulps.
        let big = cu0.abs().max(cu1.abs()).max(bu0.abs()).max(bu1.abs());
        let pad = 1e-12 * (1.0 + big) * (1.0 + d / n);
        lo[k] = l - pad;
        hi[k] = h + pad;
    }
    (lo, hi)
}

/// The improved Projections (§4) of a box lying between the cell's face and the plane: the
/// box is hidden when either rectangle is covered by occluders in front of it. The first
/// takes the eyes on the cell's face, the second on its back face.
///
/// # Why it is conservative
/// Property 2 of the paper asks that the union of the cones from the points `P` of the
/// rectangle `R` to the cell contain the box: then every box point `P'` lies in a cone from
/// some `P` that is in the umbra of one convex or planar occluder (a pixel of the Depth Map is
/// covered by one occluder's extended Projection, or is a reprojected pixel whose rays are all
/// blocked before a plane in front of the box), and `P'`, behind that occluder, is hidden
/// (Property 1). The paper builds `R` as the product of two 2D improved Projections, one per
/// in-plane axis, each from the supporting lines of the cell's side view. That product is not
/// sound when the two axes' lines touch the cell at different depths (one axis through its
/// back corner, the other through its front): a box point may then need an eye at the back
/// for one axis and at the front for the other, and no single eye of the cell sees it through
/// `R` (issue 22: a 2×2×40 cell culled a visible box).
///
/// Here both axes take their eyes on one cross-section `E` of the cell at a single depth.
/// A point `P'` at distance `z` from `E`, with `R` at distance `d`, lies in a cone from `R` to
/// `E` exactly when `P' = (1 − t)·e + t·P` with `t = z/d`, `e ∈ E`, `P ∈ R`: `t` is fixed by
/// the depth alone, so the condition splits into one condition per axis, and each axis is the
/// 2D construction with a segment for the cell (the supporting lines above). Since
/// `E ⊂ cell`, each cone from `R` to `E` lies in the cone from `R` to the cell, and Property 2
/// holds. Any depth gives a valid rectangle; the face is tightest along axes where the box is
/// narrower than the cell, the back face where it is wider, so both are offered, computed
/// lazily (a box the first one hides never needs the second).
pub fn improved_rects<'a>(
    frame: &'a PlaneFrame,
    b: &'a DAabb,
) -> impl Iterator<Item = (DVec2, DVec2)> + 'a {
    let a = frame.axis;
    let depth = frame.cell.max[a] - frame.cell.min[a];
    [0.0, depth]
        .into_iter()
        .map(move |eye| improved_rect_at(frame, b, eye))
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
    fn improved_rects_are_inside_the_standard_one_and_collapse_for_small_boxes() {
        let f = frame(30.0);
        let small = DAabb {
            min: DVec3::new(-0.2, -0.2, 4.0),
            max: DVec3::new(0.2, 0.2, 4.5),
        };
        let (slo, shi) = standard_rect(&f, &small);
        for (lo, hi) in improved_rects(&f, &small) {
            assert!(
                (hi - lo).max_element() < 1e-9,
                "lines cross before the plane: a point"
            );
            assert!(lo.x >= slo.x && hi.x <= shi.x);
        }
        let big = DAabb {
            min: DVec3::new(-4.0, -3.0, 5.0),
            max: DVec3::new(3.0, 2.0, 7.0),
        };
        let (slo, shi) = standard_rect(&f, &big);
        for (lo, hi) in improved_rects(&f, &big) {
            assert!(lo.x < hi.x && lo.y < hi.y);
            assert!(lo.x >= slo.x && lo.y >= slo.y && hi.x <= shi.x && hi.y <= shi.y);
            assert!((hi - lo).x < (shi - slo).x, "strictly tighter");
        }
    }

    // ---- Brute force: rays from the whole cell to the box (issue 22) --------------------

    /// A small deterministic generator (PCG-like LCG).
    struct Rng(u64);
    impl Rng {
        fn f(&mut self, lo: f64, hi: f64) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
        }
        fn pick(&mut self, n: usize) -> usize {
            (self.f(0.0, n as f64) as usize).min(n - 1)
        }
    }

    /// A point of `b`: a corner, an edge or face point, or an interior point (the extremes of
    /// a cone or a shadow are reached at corners, edges and faces).
    fn point_in(r: &mut Rng, b: &DAabb) -> DVec3 {
        let mut t = DVec3::new(r.f(0.0, 1.0), r.f(0.0, 1.0), r.f(0.0, 1.0));
        let snap = r.pick(4); // how many coordinates go to 0 or 1
        for _ in 0..snap {
            let k = r.pick(3);
            t[k] = if r.f(0.0, 1.0) < 0.5 { 0.0 } else { 1.0 };
        }
        b.min + (b.max - b.min) * t
    }

    /// A random configuration: a cell with aspect ratios from 1:1 to 1:50 on each axis, a
    /// plane on a random side, and a box lying between the cell's face and the plane (the
    /// improved Projection's case) or anywhere beyond the face (`in_front == false`), wider
    /// than the cell on some in-plane axes and narrower on others, then scaled and offset.
    fn config(r: &mut Rng, case: usize, in_front: bool) -> (PlaneFrame, DAabb) {
        let (scale, offset) = match case % 4 {
            0 => (1.0, 0.0),
            1 => (1e-3, 0.0),
            2 => (1.0, 1e5),
            _ => (r.f(0.01, 100.0), r.f(-1e4, 1e4)),
        };
        let mut size = DVec3::ONE;
        for k in 0..3 {
            size[k] = if r.f(0.0, 1.0) < 0.3 {
                1.0
            } else {
                50f64.powf(r.f(-1.0, 1.0))
            };
        }
        let centre = DVec3::new(r.f(-5.0, 5.0), r.f(-5.0, 5.0), r.f(-5.0, 5.0));
        let cell = DAabb {
            min: centre - size,
            max: centre + size,
        };
        let axis = case % 3;
        let positive = (case / 3).is_multiple_of(2);
        let mut f = frame(0.0);
        f.cell = cell;
        f.axis = axis;
        f.positive = positive;
        let s = f.sign();
        let reach = size.max_element() * r.f(0.5, 20.0);
        let tp = reach * r.f(0.2, 1.0);
        f.position = f.face() + s * tp;
        let (u, v) = f.uv_axes();
        let mut min = DVec3::ZERO;
        let mut max = DVec3::ZERO;
        // Depth span: in front of the plane, or anywhere beyond the face.
        let (d0, d1) = if in_front {
            let a = r.f(0.001, 0.999) * tp;
            (a, a + r.f(0.0, 1.0) * (tp - a))
        } else {
            let a = r.f(0.001, 2.0) * tp;
            (a, a + r.f(0.0, 1.0) * tp)
        };
        let (n, far) = (f.face() + s * d0, f.face() + s * d1);
        min[axis] = n.min(far);
        max[axis] = n.max(far);
        for ax in [u, v] {
            // Wider than the cell, narrower, straddling one side, or off to a side.
            let (c0, c1) = (cell.min[ax], cell.max[ax]);
            let w = c1 - c0;
            let (a, b) = match r.pick(4) {
                0 => (c0 - r.f(0.0, 3.0) * w, c1 + r.f(0.0, 3.0) * w),
                1 => {
                    let a = r.f(c0, c1);
                    (a, r.f(a, c1))
                }
                2 => (r.f(c0, c1), c1 + r.f(0.0, 2.0) * w),
                _ => {
                    let a = c1 + r.f(-0.5, 3.0) * w;
                    (a, a + r.f(0.0, 2.0) * w)
                }
            };
            min[ax] = a;
            max[ax] = b;
        }
        let place = |p: DVec3| p * scale + DVec3::splat(offset);
        let place_box = |b: DAabb| {
            // Round to f32, as scenes and cells are.
            let (a, b) = (place(b.min), place(b.max));
            DAabb {
                min: a.as_vec3().as_dvec3(),
                max: b.as_vec3().as_dvec3(),
            }
        };
        f.cell = place_box(f.cell);
        f.position = f.position * scale + offset;
        let b = place_box(DAabb { min, max });
        (f, b)
    }

    /// The check of Property 2 the improved Projection must pass, by rays: with the minimal
    /// occluder whose extended Projection covers `[lo, hi]` — the cross-section, at a depth
    /// `w` between the cell's face and the box, of the convex hull of the cell and the
    /// rectangle — every segment from a point of the cell to a point of the box must cross
    /// that occluder. Returns a segment that does not.
    fn unblocked_ray(
        r: &mut Rng,
        f: &PlaneFrame,
        b: &DAabb,
        lo: DVec2,
        hi: DVec2,
        rays: usize,
    ) -> Option<(DVec3, DVec3)> {
        let a = f.axis;
        let s = f.sign();
        let face = f.face();
        let l = f.cell.max[a] - f.cell.min[a];
        let d = s * (f.position - face);
        let (near, far) = if f.positive {
            (b.min[a], b.max[a])
        } else {
            (b.max[a], b.min[a])
        };
        let n = s * (near - face);
        let _ = far;
        let (u, v) = f.uv_axes();
        for _ in 0..4 {
            // The occluder's depth beyond the face, strictly in front of the box.
            let w = n * r.f(0.0, 1.0);
            // (1 − λ)·e + λ·P at depth w, e at depth in [−l, 0]: λ ∈ [w/d, (w + l)/(d + l)].
            let (l0, l1) = (w / d, (w + l) / (d + l));
            let in_section = |x: DVec2| {
                // Exists λ ∈ [l0, l1] with (1 − λ)·cell + λ·R ∋ x on both axes.
                let (mut a0, mut a1) = (l0, l1);
                for (k, ax) in [u, v].into_iter().enumerate() {
                    let (c0, c1) = (f.cell.min[ax], f.cell.max[ax]);
                    // c0 + λ(lo − c0) ≤ x and x ≤ c1 + λ(hi − c1).
                    for (base, slope, upper_side) in
                        [(c0, lo[k] - c0, false), (c1, hi[k] - c1, true)]
                    {
                        let tol = 1e-9 * (1.0 + x[k].abs());
                        // upper_side: base + λ·slope ≥ x; else base + λ·slope ≤ x.
                        let g = if upper_side {
                            x[k] - base - tol
                        } else {
                            x[k] - base + tol
                        };
                        if slope.abs() < 1e-300 {
                            let ok = if upper_side { g <= 0.0 } else { g >= 0.0 };
                            if !ok {
                                return false;
                            }
                            continue;
                        }
                        let lam = g / slope;
                        let lam_is_lower = upper_side == (slope > 0.0);
                        if lam_is_lower {
                            a0 = a0.max(lam);
                        } else {
                            a1 = a1.min(lam);
                        }
                    }
                }
                a0 <= a1 + 1e-12
            };
            for _ in 0..rays {
                let e = point_in(r, &f.cell);
                let q = point_in(r, b);
                let (we, wq) = (s * (e[a] - face), s * (q[a] - face));
                let t = (w - we) / (wq - we);
                let x = e + (q - e) * t;
                if !in_section(DVec2::new(x[u], x[v])) {
                    return Some((e, q));
                }
            }
        }
        None
    }

    #[test]
    fn improved_rects_hide_only_what_every_ray_from_the_cell_to_the_box_must_cross() {
        let mut r = Rng(22);
        for case in 0..3000 {
            let (f, b) = config(&mut r, case, true);
            for (k, (lo, hi)) in improved_rects(&f, &b).enumerate() {
                if let Some((e, q)) = unblocked_ray(&mut r, &f, &b, lo, hi, 200) {
                    panic!(
                        "case {case}, rectangle {k}: the segment {e:?} → {q:?} from the cell \
                         to the box misses the minimal occluder of {lo:?}..{hi:?} \
                         (cell {:?}, box {b:?}, plane {} on axis {})",
                        f.cell, f.position, f.axis
                    );
                }
            }
        }
    }

    /// The paper's product of two 2D improved Projections, each axis with the supporting
    /// lines through whichever cell corner suits it (the code before issue 22).
    fn per_axis_product(f: &PlaneFrame, b: &DAabb) -> (DVec2, DVec2) {
        let (a, s) = (f.axis, f.sign());
        let l = f.cell.max[a] - f.cell.min[a];
        let (near, far) = if f.positive {
            (b.min[a], b.max[a])
        } else {
            (b.max[a], b.min[a])
        };
        let (tp, tb0, tb1) = (
            s * (f.position - f.face()),
            s * (near - f.face()),
            s * (far - f.face()),
        );
        let (u, v) = f.uv_axes();
        let mut lo = DVec2::ZERO;
        let mut hi = DVec2::ZERO;
        for (k, ax) in [u, v].into_iter().enumerate() {
            let (c0, c1, b0, b1) = (f.cell.min[ax], f.cell.max[ax], b.min[ax], b.max[ax]);
            let up = if b1 >= c1 {
                c1 + (b1 - c1) * (tp + l) / (tb0 + l)
            } else {
                c1 + (b1 - c1) * tp / tb1
            };
            let dn = if b0 <= c0 {
                c0 + (b0 - c0) * (tp + l) / (tb0 + l)
            } else {
                c0 + (b0 - c0) * tp / tb1
            };
            let m = 0.5 * (dn + up);
            (lo[k], hi[k]) = if dn <= up { (dn, up) } else { (m, m) };
        }
        (lo, hi)
    }

    /// The check above can fail: it catches the per-axis product on the scene (a
    /// 2×2×40 cell) and on the random configurations.
    #[test]
    fn the_per_axis_product_fails_that_check() {
        let mut f = frame(9.9);
        f.cell = DAabb {
            min: DVec3::new(-1.0, -1.0, -40.0),
            max: DVec3::new(1.0, 1.0, 0.0),
        };
        let target = DAabb {
            min: DVec3::new(-3.0, -0.45, 5.0),
            max: DVec3::new(3.0, 0.45, 5.1),
        };
        let mut r = Rng(1);
        let (lo, hi) = per_axis_product(&f, &target);
        assert!(
            unblocked_ray(&mut r, &f, &target, lo, hi, 20_000).is_some(),
            "the per-axis product must be caught on the issue's scene"
        );
        for (lo, hi) in improved_rects(&f, &target) {
            assert!(unblocked_ray(&mut r, &f, &target, lo, hi, 20_000).is_none());
        }
        let mut r = Rng(22);
        let caught = (0..3000)
            .filter(|&case| {
                let (f, b) = config(&mut r, case, true);
                let (lo, hi) = per_axis_product(&f, &b);
                unblocked_ray(&mut r, &f, &b, lo, hi, 200).is_some()
            })
            .count();
        eprintln!("the per-axis product was caught on {caught} of 3000 random configurations");
        assert!(
            caught > 0,
            "the random configurations must catch the per-axis product"
        );
    }

    /// The standard Projection holds the view of every box point from every cell point, for
    /// boxes in front of, across and behind the plane, on the same random configurations.
    #[test]
    fn standard_rect_holds_every_view_on_random_cells_and_boxes() {
        let mut r = Rng(15);
        for case in 0..3000 {
            let (f, b) = config(&mut r, case, case % 2 == 0);
            let (lo, hi) = standard_rect(&f, &b);
            for _ in 0..300 {
                let e = point_in(&mut r, &f.cell);
                let q = point_in(&mut r, &b);
                let p = f.project(e, q);
                let tol = 1e-9 * (1.0 + p.abs().max_element());
                assert!(
                    p.x >= lo.x - tol
                        && p.y >= lo.y - tol
                        && p.x <= hi.x + tol
                        && p.y <= hi.y + tol,
                    "case {case}: the view {p:?} of {q:?} from {e:?} leaves {lo:?}..{hi:?}"
                );
            }
        }
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
