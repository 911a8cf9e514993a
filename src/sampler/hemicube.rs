//! The CPU hemicube rasteriser of the sampler: five axis-aligned views from a sample point
//! (the front view along the face's outward normal and the outer halves of the four side
//! views), polygons drawn with shrunk silhouettes and inner-conservative coverage at their
//! farthest depth (a pixel is covered when its four corners pass every edge's test), a
//! per-tile maximum for hierarchical tests, the BVH traversed front to back with whole
//! clusters skipped when they can no longer lower a pixel that matters, an optional tuck pass
//! that draws again, with those edges unshrunk, polygons whose edges lie wholly behind what
//! was drawn (`segment_hidden`), and occludee boxes tested with outer-conservative rectangles
//! at their nearest depth. The argument is in the parent module's docs.

use super::{SampleCard, SampleOccluders, view_coords, view_maps};
use crate::geom::DAabb;
use crate::scene::alpha::Coverage;
use glam::{DVec2, DVec3};
use std::collections::HashMap;

/// Pixels per tile side (tiles keep the largest depth of their pixels).
const TILE: usize = 8;
/// The largest footprint (in pixels) that [`Hemicube::footprint`], and the traversal's test
/// of a BVH node's box, check pixel by pixel (256 was no faster for nodes).
const PIXEL_CHECK: usize = 64;
/// Margin of the `f32` corner test (its rounding error is below 1e-6: unit normals,
/// `|u|, |v| ≤ 1`, `√(u²+v²+1) ≤ √3`).
const CORNER_MARGIN: f32 = 4e-6;
/// A polygon's edge takes the side of its plane (through the eye) that holds the polygon's
/// centroid only when the centroid is farther from that plane than this times
/// `|centroid|·|a|·|b| / |a × b| + n·max|q|` (the edge `a b`, the `n` vertices `q`, all from
/// the eye): about 4,500 times the `f64` rounding of the cross product, the centroid and the
/// dot product, so that the side is never a rounding error. Nearer, the polygon is left out
/// (its shrunk silhouette is empty anyway unless the ball is a point). The GPU's set-up
/// (`ORIENT_TOL` in `shaders/sampler_setup.wgsl`) repeats the test.
pub(crate) const ORIENT_TOL: f64 = 1e-12;

/// The radius an edge is shrunk for when the render stands for a face rectangle with half
/// sides `[h_b, h_c]` (along the face's axes `b_ax`, `c_ax`): the smaller of `cyl` (the
/// rectangle's extent seen along the edge) and `r·h_n / √(h_n² + (r − h_w)²)`, where `m` is
/// the unit normal of the plane through the eye and the edge's line, `t` the edge's unit
/// direction, `r` the line's distance, and `h_n`, `h_w` the rectangle's support along `m` and
/// along `t × m` (`h(x) = h_b·|x_b| + h_c·|x_c|`). The second is the tighter bound the module
/// docs prove ("Supports instead of extents"): an edge seen across the face's plane (its
/// plane through the eye nearly parallel to the face) barely moves as the eye moves within
/// the face, so it is barely shrunk. Rounded up by a relative 1e-9.
#[inline]
fn edge_reach(
    cyl: f64,
    [hb, hc]: [f64; 2],
    m: DVec3,
    t: DVec3,
    r: f64,
    b_ax: usize,
    c_ax: usize,
) -> f64 {
    let w = t.cross(m);
    let hn = hb * m[b_ax].abs() + hc * m[c_ax].abs();
    let hw = (hb * w[b_ax].abs() + hc * w[c_ax].abs()) * (1.0 + 1e-9);
    if r.is_nan() || r <= hw {
        return cyl;
    }
    let rw = r - hw;
    cyl.min(r * hn / (hn * hn + rw * rw).sqrt() * (1.0 + 1e-9))
}

/// The pixels `[i0, i1) × [j0, j1)` of `px` (a view's, `ps` the pixel size, `vmin` the
/// view's lowest `v`) that can meet the silhouette shrunk by the edges `ev`
/// (`[a, b, c, s]`: a direction `(u, v, 1)` passes when `a·u + b·v + c ≥ s·√(u²+v²+1)`), or
/// `None` when none can. Over the rectangle `√(u²+v²+1) ≥ l`, its value at the point nearest
/// the view's centre, and `s ≥ 0`, so every passing direction of the rectangle lies in the
/// convex polygon `a·u + b·v + c ≥ s·l` (loosened by a margin far above rounding): the
/// rectangle clipped by each such half-plane ([`clip`] on the points `(u, v, 1)`). Its bound,
/// rounded outward to whole pixels, holds every pixel with a passing point.
fn shrunk_bound(
    ev: &[[f32; 4]],
    px: [usize; 4],
    ps: f64,
    vmin: f64,
    poly: &mut [Vec<DVec3>; 2],
) -> Option<[usize; 4]> {
    let [i0, i1, j0, j1] = px;
    let (u0, u1) = (-1.0 + i0 as f64 * ps, -1.0 + i1 as f64 * ps);
    let (v0, v1) = (vmin + j0 as f64 * ps, vmin + j1 as f64 * ps);
    let (nu, nv) = (0f64.clamp(u0, u1), 0f64.clamp(v0, v1));
    let l = (nu * nu + nv * nv + 1.0).sqrt();
    let [cur, next] = poly;
    cur.clear();
    cur.extend([
        DVec3::new(u0, v0, 1.0),
        DVec3::new(u1, v0, 1.0),
        DVec3::new(u1, v1, 1.0),
        DVec3::new(u0, v1, 1.0),
    ]);
    for e in ev {
        let [a, b, c, s] = e.map(f64::from);
        clip(cur, DVec3::new(a, b, c - s * l + 1e-5), next);
        if cur.is_empty() {
            return None;
        }
    }
    let (mut lo, mut hi) = (cur[0], cur[0]);
    for &p in cur.iter() {
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let to_px = |t: f64, min: f64| ((t - min) / ps - 1e-6).floor();
    let to_px_up = |t: f64, min: f64| ((t - min) / ps + 1e-6).ceil();
    let bi0 = (to_px(lo.x, -1.0).max(i0 as f64) as usize).min(i1);
    let bi1 = (to_px_up(hi.x, -1.0).min(i1 as f64) as usize).max(bi0);
    let bj0 = (to_px(lo.y, vmin).max(j0 as f64) as usize).min(j1);
    let bj1 = (to_px_up(hi.y, vmin).min(j1 as f64) as usize).max(bj0);
    (bi0 < bi1 && bj0 < bj1).then_some([bi0, bi1, bj0, bj1])
}

/// `z` rounded up to `f32` with a relative margin of 1e-6 (far above the rounding of the
/// depth computations); infinity stays infinity.
fn round_up(z: f64) -> f32 {
    let m = z * (1.0 + 1e-6);
    let f = m as f32;
    if f64::from(f) < m { f.next_up() } else { f }
}

/// The sub-pixels (8 × 8, bit `8·b + a` for column `a`, row `b`) of the pixel
/// `[u0, u0 + ps] × [v0, v0 + ps]` that lie entirely inside every edge's region `ev`
/// (`e0·u + e1·v + e2 − s·√(u²+v²+1) ≥ margin`), where `lmax` is at least `√(u²+v²+1)` over
/// the pixel (its largest corner value: the root is convex). With `s ≥ 0` the linear test
/// `e0·u + e1·v + e2 − s·lmax ≥ margin` implies the exact one at every point of the pixel,
/// and a sub-pixel passes a linear test everywhere iff its worst corner does.
fn pixel_mask(ev: &[[f32; 4]], u0: f64, v0: f64, ps: f64, lmax: f64) -> u64 {
    let margin = f64::from(CORNER_MARGIN);
    let h = ps / 8.0;
    let mut mask = u64::MAX;
    for e in ev {
        let (a, b, c, s) = (
            f64::from(e[0]),
            f64::from(e[1]),
            f64::from(e[2]),
            f64::from(e[3]),
        );
        let base = a * u0 + b * v0 + c - s * lmax;
        let (du, dv) = (a * h, b * h);
        // The worst corner of sub-pixel (0, 0); sub-pixel (a, b) adds a·du + b·dv.
        let c0 = base + du.min(0.0) + dv.min(0.0);
        if c0 + 7.0 * (du.min(0.0) + dv.min(0.0)) >= margin {
            continue;
        }
        if c0 + 7.0 * (du.max(0.0) + dv.max(0.0)) < margin {
            return 0;
        }
        // Every sub-pixel's test, without branches (the compiler vectorises the rows).
        let mut em = 0u64;
        for bb in 0..8 {
            let r = c0 + f64::from(bb) * dv;
            let mut row = 0u64;
            for aa in 0..8 {
                row |= u64::from(r + f64::from(aa) * du >= margin) << aa;
            }
            em |= row << (bb * 8);
        }
        mask &= em;
        if mask == 0 {
            return 0;
        }
    }
    mask
}

/// Four edges' `f32` corner-test coefficients `[a, b, c, s]` (`a·u + b·v + c − s·√(u²+v²+1)
/// ≥` [`CORNER_MARGIN`] inside), lane by lane so that one corner's four tests run side by
/// side; a polygon's last lanes are padded with `[0, 0, 1, 0]`, which every corner passes.
/// `bv` holds `b·v` for the row being scanned ([`EdgeLanes::row`]). Each test is the same
/// `f32` expression, `((a·u + b·v) + c) − s·l`, as one edge at a time: the same bits.
#[derive(Clone, Copy, Debug)]
struct EdgeLanes {
    a: [f32; 4],
    b: [f32; 4],
    c: [f32; 4],
    s: [f32; 4],
    bv: [f32; 4],
}

impl EdgeLanes {
    /// `out` becomes the lanes of the edges `ev`.
    fn fill(out: &mut Vec<EdgeLanes>, ev: &[[f32; 4]]) {
        out.clear();
        for chunk in ev.chunks(4) {
            let mut l = EdgeLanes {
                a: [0.0; 4],
                b: [0.0; 4],
                c: [1.0; 4],
                s: [0.0; 4],
                bv: [0.0; 4],
            };
            for (k, e) in chunk.iter().enumerate() {
                l.a[k] = e[0];
                l.b[k] = e[1];
                l.c[k] = e[2];
                l.s[k] = e[3];
            }
            out.push(l);
        }
    }

    /// Sets `b·v` for the corners of row `v`.
    fn row(&mut self, v: f32) {
        for k in 0..4 {
            self.bv[k] = self.b[k] * v;
        }
    }

    /// Whether the corner at `u` (of the last [`EdgeLanes::row`]), with `l = √(u²+v²+1)`,
    /// passes all four edges.
    #[inline]
    fn pass(&self, u: f32, l: f32) -> bool {
        let mut ok = true;
        for k in 0..4 {
            ok &= self.a[k] * u + self.bv[k] + self.c[k] - self.s[k] * l >= CORNER_MARGIN;
        }
        ok
    }
}

/// Whether the card `c` is surely opaque wherever a segment from the sampled region (within
/// `reach` of the eye, whose distance to the card's plane is `h > reach`) to a point beyond
/// the plane, in a direction of the pixel `[u0, u0 + ps] × [v0, v0 + ps]`, can cross the plane.
/// `nv` is the plane's unit normal in view coordinates, pointing from the eye to the plane;
/// `at(d)` is the scene point `eye + d` for a view-space offset `d`.
///
/// The ray from the eye in such a direction `w` (with `a = n·w > h`, `cos θ = a / |w|`)
/// crosses the plane at `x0`, inside the convex hull `F` of the corner rays' crossings. The
/// segment from `b = eye + δ` (`|δ| ≤ reach < h`) to `q = eye + w` crosses it at `x`, and
/// `x − x0 = δ·(1 − s) − (n·δ)·(a − h)/(a·(a − n·δ))·w` with `s ∈ [0, 1]`, so
/// `|x − x0| ≤ reach·(1 + 1/cos θ)`. Every crossing lies within that distance of `F`; its
/// texture coordinates lie in the bounding box of `F`'s corners' widened by that distance
/// times the gradients' lengths (the map is affine), and the texture is tested there.
#[allow(
    clippy::too_many_arguments,
    reason = "one pixel, one card: all scalars of the inner loop"
)]
fn footprint_opaque(
    c: &SampleCard,
    cov: &Coverage,
    nv: DVec3,
    h: f64,
    reach: f64,
    u0: f64,
    v0: f64,
    ps: f64,
    at: impl Fn(DVec3) -> DVec3,
) -> bool {
    let (mut lo, mut hi) = (DVec2::INFINITY, DVec2::NEG_INFINITY);
    let mut cos_min = f64::INFINITY;
    for (du, dv) in [(0.0, 0.0), (ps, 0.0), (0.0, ps), (ps, ps)] {
        let d = DVec3::new(u0 + du, v0 + dv, 1.0);
        let a = nv.dot(d);
        if a.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return false;
        }
        cos_min = cos_min.min(a);
        let uv = c.uv(at(d * (h / a)));
        lo = lo.min(uv);
        hi = hi.max(uv);
    }
    // The least cos θ over the pixel: n·w is linear (least at a corner) and |w| convex
    // (largest at a corner, at most √3 in a view).
    let lmax = (0..4)
        .map(|k| {
            let d = DVec3::new(u0 + ps * f64::from(k & 1), v0 + ps * f64::from(k >> 1), 1.0);
            d.length()
        })
        .fold(0.0, f64::max);
    let cos = cos_min / lmax;
    if cos.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return false;
    }
    let rho = reach * (1.0 + 1.0 / cos) * (1.0 + 1e-6);
    // Texture-space widening, plus a relative margin for the rounding of the map.
    let wide =
        DVec2::new(c.gu.length(), c.gv.length()) * rho + (hi - lo + lo.abs() + hi.abs()) * 1e-9;
    let (lo, hi) = (lo - wide, hi + wide);
    cov.uv_rect_opaque([lo.x, hi.x], [lo.y, hi.y])
}

/// Partial layers a pixel keeps inline: sub-pixel masks, each with the largest depth of the
/// polygons whose bits it holds, sorted nearest first. A pixel that needs more keeps the rest
/// in its view's [`Spill`], so no layer is ever merged into another.
const LAYERS: usize = 8;

/// Per pixel index, the partial layers beyond the [`LAYERS`] inline ones (sorted nearest
/// first, all farther than the inline ones). A pixel has an entry only while all its inline
/// layers are in use.
type Spill = HashMap<usize, Vec<(u64, f32)>>;

/// Adds the sub-pixels `bits` of a polygon at depth `z` to a pixel's partial layers (`masks`,
/// `wz`, sorted nearest first, empty layers last, and the pixel's entry `idx` in `spill`)
/// whose pixel depth is `d > z`. The layers keep every sub-pixel's own nearest depth: a
/// sub-pixel belongs to at most one layer, its nearest. Layers no nearer than `d` are dropped
/// first; bits that a layer nearer than `z` holds add nothing; bits at a depth some layer
/// already has join it, and leave the farther layers (a layer left empty goes). When the
/// layers up to some depth together hold all 64 sub-pixels, the pixel is covered at that
/// depth: it is returned and the layers from there on are dropped. Nothing is merged, so the
/// result is the same as keeping each of the 64 sub-pixels' nearest depths (the GPU twin's
/// representation).
fn add_layer(
    masks: &mut [u64; LAYERS],
    wz: &mut [f32; LAYERS],
    spill: &mut Spill,
    idx: usize,
    bits: u64,
    z: f32,
    d: f32,
) -> Option<f32> {
    if masks[LAYERS - 1] != 0
        && !spill.is_empty()
        && let Some(mut ls) = spill.remove(&idx)
    {
        // The slow path: all the pixel's layers in one list.
        let mut all: Vec<(u64, f32)> = masks.iter().copied().zip(wz.iter().copied()).collect();
        all.append(&mut ls);
        let keep = all.iter().position(|l| l.1 >= d).unwrap_or(all.len());
        all.truncate(keep);
        all.push((0, 0.0));
        let mut n = keep;
        let covered = insert_layer(&mut all, &mut n, bits, z);
        all.truncate(n);
        masks.fill(0);
        wz.fill(0.0);
        for (k, (m, w)) in all.iter().take(LAYERS).enumerate() {
            masks[k] = *m;
            wz[k] = *w;
        }
        if all.len() > LAYERS {
            all.drain(..LAYERS);
            spill.insert(idx, all);
        }
        return covered;
    }
    let mut n = 0;
    while n < LAYERS && masks[n] != 0 && wz[n] < d {
        n += 1;
    }
    let mut ls = [(0u64, 0f32); LAYERS + 1];
    for k in 0..n {
        ls[k] = (masks[k], wz[k]);
    }
    let covered = insert_layer(&mut ls, &mut n, bits, z);
    for k in 0..LAYERS {
        (masks[k], wz[k]) = if k < n { ls[k] } else { (0, 0.0) };
    }
    if n > LAYERS {
        spill.insert(idx, vec![ls[LAYERS]]);
    }
    covered
}

/// [`add_layer`]'s work on the first `*n` entries of `ls` (sorted nearest first, all nearer
/// than the pixel's depth, disjoint masks; `ls` has room for one more): adds `bits` at `z`,
/// updating `*n`, and returns the pixel's new depth when the layers now cover it.
fn insert_layer(ls: &mut [(u64, f32)], n: &mut usize, bits: u64, z: f32) -> Option<f32> {
    let mut pos = 0;
    let mut nearer = 0u64;
    while pos < *n && ls[pos].1 < z {
        nearer |= ls[pos].0;
        pos += 1;
    }
    let bits = bits & !nearer;
    if bits == 0 {
        return None;
    }
    if pos < *n && ls[pos].1 == z {
        ls[pos].0 |= bits;
    } else {
        ls.copy_within(pos..*n, pos + 1);
        ls[pos] = (bits, z);
        *n += 1;
    }
    // Farther layers lose these sub-pixels: their nearest depth is now `z`.
    let mut m = pos + 1;
    for k in pos + 1..*n {
        let l = (ls[k].0 & !bits, ls[k].1);
        if l.0 != 0 {
            ls[m] = l;
            m += 1;
        }
    }
    *n = m;
    let mut acc = nearer;
    for (k, l) in ls[..*n].iter().enumerate().skip(pos) {
        acc |= l.0;
        if acc == u64::MAX {
            *n = k;
            return Some(l.1);
        }
    }
    None
}

/// Clips the convex polygon `poly` (view coordinates) to the half-space `n·p ≥ 0`, in place
/// (`tmp` is scratch).
fn clip(poly: &mut Vec<DVec3>, n: DVec3, tmp: &mut Vec<DVec3>) {
    if poly.is_empty() {
        return;
    }
    tmp.clear();
    let m = poly.len();
    for i in 0..m {
        let (a, b) = (poly[i], poly[(i + 1) % m]);
        let (fa, fb) = (n.dot(a), n.dot(b));
        if fa >= 0.0 {
            tmp.push(a);
        }
        if (fa >= 0.0) != (fb >= 0.0) {
            tmp.push(a + (b - a) * (fa / (fa - fb)));
        }
    }
    std::mem::swap(poly, tmp);
}

/// The least and largest of `f` over the points.
fn bounds(points: &[DVec3], f: impl Fn(&DVec3) -> f64) -> [f64; 2] {
    points
        .iter()
        .fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], p| {
            let x = f(p);
            [lo.min(x), hi.max(x)]
        })
}

/// What [`Hemicube::test_box`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BoxTest {
    /// Every direction of the box's part in front of the face is covered nearer than it.
    Hidden,
    /// Some pixel is not covered nearer than the box: its view and centre direction (world
    /// space, not normalised), for a certifying ray.
    Open {
        /// The direction through the open pixel's centre.
        direction: DVec3,
    },
}

/// Work done by one render.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RenderStats {
    /// BVH nodes visited.
    pub nodes: u64,
    /// Polygons rasterised (in at least one view).
    pub polygons: u64,
    /// Polygons reached by the traversal.
    pub reached: u64,
    /// Polygons rasterised with at least one tucked edge ([`Hemicube::set_tuck`]).
    pub tucked: u64,
}

/// An occludee box's part in one view, as [`Hemicube::box_rects`] gives it to a GPU twin: the
/// pixels `[i[0], i[1]) × [j[0], j[1])`, the unrounded bounds in pixel units (`pu` along `u`,
/// `pv` along `v`) and the depth every pixel must hold strictly nearer (the part's nearest,
/// less a relative 1e-9).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoxRect {
    /// The view: 0 the front, 1–4 the sides' outer halves.
    pub view: u8,
    /// Pixel columns.
    pub i: [u32; 2],
    /// Pixel rows.
    pub j: [u32; 2],
    /// The part's `u` bounds in pixel units.
    pub pu: [f64; 2],
    /// The part's `v` bounds in pixel units.
    pub pv: [f64; 2],
    /// The depth to beat.
    pub z: f64,
}

/// A polygon's footprint in one view ([`Hemicube::footprint`]).
#[derive(Clone, Copy, Debug)]
struct Footprint {
    /// The needed pixels `[i0, i1) × [j0, j1)` its projection's bound touches.
    pixels: [usize; 4],
    /// Its farthest depth, rounded up: the depth it is drawn at.
    z: f32,
    /// Deep in this view: it takes its plane's depth per pixel instead.
    deep: bool,
}

/// One view: which scene axes give its coordinates, its pixels and depths.
#[derive(Clone, Debug)]
struct View {
    /// `X`, `Y`, `Z` of the view are `sign × q[axis]` of the point `q` relative to the eye.
    map: [(usize, f64); 3],
    /// Pixel rows (`R` for the front view, `R/2` for the side views).
    h: usize,
    /// `v` at the bottom edge of row 0 (−1 front, 0 sides).
    vmin: f64,
    depth: Vec<f32>,
    /// Per pixel, up to [`LAYERS`] partial layers ([`add_layer`]), nearest first: the
    /// sub-pixels (8 × 8, bit `8·b + a`) covered by polygons drawn so far that did not cover
    /// the whole pixel, each layer with the largest depth of its polygons (`wz`; a layer with
    /// an empty mask is unused, and so are all after it).
    mask: Vec<[u64; LAYERS]>,
    wz: Vec<[f32; LAYERS]>,
    /// The layers of pixels that need more than [`LAYERS`] (cleared with every render).
    spill: Spill,
    tile_max: Vec<f32>,
    /// Per tile, the largest farthest depth of the occludee boxes whose pixels reach it this
    /// render (0 where none does): a polygon no nearer than that in every tile it touches
    /// can change no test (of the boxes, their pieces or their triangles).
    need_z: Vec<f32>,
    /// The pixels that matter this render: `[i0, i1) × [j0, j1)` (empty when `i0 ≥ i1`).
    need: [usize; 4],
}

impl View {
    /// Pixel `idx`'s partial layers, nearest first: the inline ones, then its spilled ones
    /// (an unused layer has an empty mask, and all after it are unused).
    fn layers(&self, idx: usize) -> impl Iterator<Item = (u64, f32)> + '_ {
        let inline = self.mask[idx]
            .iter()
            .copied()
            .zip(self.wz[idx].iter().copied());
        let spilled = (self.mask[idx][LAYERS - 1] != 0)
            .then(|| self.spill.get(&idx))
            .flatten()
            .into_iter()
            .flatten()
            .copied();
        inline.chain(spilled)
    }

    /// Whether a draw no nearer than `z` in any pixel of `[i0, i1) × [j0, j1)` (needed
    /// pixels of this view, `res` across) could change a pixel a test reads: some tile it
    /// touches holds a depth beyond `z` where an occludee needs one, and, for a rectangle of
    /// at most [`PIXEL_CHECK`] pixels, some pixel of it does (a draw changes only pixels, depths
    /// or layers, whose depth lies beyond its own). False only where the draw changes nothing.
    fn may_lower(&self, res: usize, [i0, i1, j0, j1]: [usize; 4], z: f32) -> bool {
        let tw = res / TILE;
        let tiles = (j0 / TILE..j1.div_ceil(TILE)).any(|tj| {
            (i0 / TILE..i1.div_ceil(TILE))
                .any(|ti| self.tile_max[tj * tw + ti] > z && self.need_z[tj * tw + ti] > z)
        });
        tiles
            && ((i1 - i0) * (j1 - j0) > PIXEL_CHECK
                || (j0..j1).any(|j| {
                    self.depth[j * res + i0..j * res + i1]
                        .iter()
                        .zip(i0..i1)
                        .any(|(&d, i)| d > z && self.need_z[(j / TILE) * tw + i / TILE] > z)
                }))
    }

    /// The world direction (not normalised) through the centre of pixel `(i, j)`, `ps` the
    /// pixel size in `u`/`v`.
    fn pixel_direction(&self, ps: f64, i: usize, j: usize) -> DVec3 {
        let (u, v) = (
            -1.0 + (i as f64 + 0.5) * ps,
            self.vmin + (j as f64 + 0.5) * ps,
        );
        let mut d = DVec3::ZERO;
        d[self.map[0].0] += self.map[0].1 * u;
        d[self.map[1].0] += self.map[1].1 * v;
        d[self.map[2].0] += self.map[2].1;
        d
    }
}

/// A pixel rectangle `[i0, i1) × [j0, j1)` and the nearest view depth of what it bounds.
#[derive(Clone, Copy, Debug)]
struct Rect {
    i: [usize; 2],
    j: [usize; 2],
    /// The same bounds before rounding, in pixel units (`i` for `u`, `j` for `v`): every
    /// direction of the box lies in `[pu[0], pu[1]] × [pv[0], pv[1]]`.
    pu: [f64; 2],
    pv: [f64; 2],
    z: f64,
}

/// A reusable hemicube: one per thread, rendered again for every sample point.
#[derive(Clone, Debug)]
pub struct Hemicube {
    res: usize,
    views: Vec<View>,
    /// `√(u²+v²+1)` at the corners of the front view, `(R+1)²`, and of the side views,
    /// `(R+1)·(R/2+1)`.
    norm_front: Vec<f32>,
    norm_side: Vec<f32>,
    eye: DVec3,
    axis: usize,
    sign: f64,
    eps: f64,
    /// With [`Hemicube::begin_patch`]: the half sides of the face rectangle the render stands
    /// for, along the face's axes `(axis+1) % 3` and `(axis+2) % 3`.
    patch: Option<[f64; 2]>,
    /// The polygon being drawn is farther than this from the eye (set per polygon).
    near: f64,
    max_dist: f64,
    stack: Vec<u32>,
    /// Scratch polygons of [`shrunk_bound`].
    scratch_clip: [Vec<DVec3>; 2],
    pass: Vec<u8>,
    prev: Vec<u8>,
    /// Scratch per polygon: its vertices relative to the eye, its edges' planes and shrinks,
    /// their view-space coefficients (kept to avoid clearing arrays per polygon).
    scratch_q: Vec<DVec3>,
    scratch_edges: Vec<(DVec3, f64)>,
    scratch_ev: Vec<[f32; 4]>,
    /// The same coefficients four edges at a time, lane by lane ([`EdgeLanes`]).
    scratch_lanes: Vec<EdgeLanes>,
    /// Whether partly covered pixels keep sub-pixel masks ([`Hemicube::set_subpixel`]).
    subpixel: bool,
    /// Whether edges are shrunk only as much as occludees no farther than `max_dist` need
    /// ([`Hemicube::set_depth_bounded`]).
    depth_bounded: bool,
    /// Whether edges hidden behind nearer coverage are drawn unshrunk
    /// ([`Hemicube::set_tuck`]).
    tuck: bool,
    /// The tuck pass's segment parameters ([`Hemicube::segment_hidden`]).
    scratch_ts: Vec<f64>,
}

impl Hemicube {
    /// A hemicube of `res` pixels across each 90° view (rounded up to a multiple of 16).
    pub fn new(res: u32) -> Self {
        let res = (res.max(16) as usize).div_ceil(16) * 16;
        let ps = 2.0 / res as f64;
        let norms = |rows: usize, vmin: f64| -> Vec<f32> {
            let mut out = Vec::with_capacity((res + 1) * (rows + 1));
            for j in 0..=rows {
                let v = vmin + j as f64 * ps;
                for i in 0..=res {
                    let u = -1.0 + i as f64 * ps;
                    out.push((u * u + v * v + 1.0).sqrt() as f32);
                }
            }
            out
        };
        Hemicube {
            res,
            views: Vec::new(),
            norm_front: norms(res, -1.0),
            norm_side: norms(res / 2, 0.0),
            eye: DVec3::ZERO,
            axis: 0,
            sign: 1.0,
            eps: 0.0,
            patch: None,
            near: 0.0,
            max_dist: 0.0,
            stack: Vec::new(),
            scratch_clip: [Vec::new(), Vec::new()],
            pass: vec![0; res + 1],
            prev: vec![0; res + 1],
            scratch_q: Vec::new(),
            scratch_edges: Vec::new(),
            scratch_ev: Vec::new(),
            scratch_lanes: Vec::new(),
            subpixel: true,
            depth_bounded: true,
            tuck: false,
            scratch_ts: Vec::new(),
        }
    }

    /// Turns the tuck pass on or off (off by default). With it, each polygon the traversal
    /// (nearest first) draws has every edge whose whole image is already covered nearer than
    /// the edge (an occludee test of the edge as a segment) drawn without its shrink: the
    /// leaves' edges that lie under nearer leaves no longer open gaps. The edges are tested
    /// only for polygons whose draw could lower some pixel. See the module docs for why this
    /// stays conservative.
    pub fn set_tuck(&mut self, on: bool) {
        self.tuck = on;
    }

    /// Whether each edge is shrunk only as much as the occludees of this render need (on by
    /// default): every point tested lies within the farthest corner of the boxes given to
    /// [`Hemicube::begin`], at distance `D`, and an edge line at distance `r` then needs the
    /// shrink `(ε/r)·|1 − r/D| / (1 − √2·ε/√(r·D))` instead of `ε/r` (the smaller of the two
    /// is used; see the module docs). Leaves near the occludees shrink little. Off, edges are
    /// shrunk for occludees at any distance (for comparisons).
    pub fn set_depth_bounded(&mut self, on: bool) {
        self.depth_bounded = on;
    }

    /// Turns sub-pixel masks on (the default) or off. With them, a pixel that no single
    /// polygon covers is still covered once polygons together cover its 8 × 8 sub-pixels
    /// (at the largest of their depths): seams between leaves and leaves narrower than a
    /// pixel fuse at eight times the resolution, for the cost of the pixels on polygons'
    /// edges. Off, a pixel needs one polygon over all of it (for comparisons).
    pub fn set_subpixel(&mut self, on: bool) {
        self.subpixel = on;
    }

    /// Whether sub-pixel masks are on ([`Hemicube::set_subpixel`]).
    pub fn subpixel(&self) -> bool {
        self.subpixel
    }

    /// The sample point of the last `begin` (the rectangle's centre with `begin_patch`).
    pub fn eye(&self) -> DVec3 {
        self.eye
    }

    /// Pixels across each view.
    pub fn resolution(&self) -> usize {
        self.res
    }

    /// Sets up the views for the eye `eye` on a face with outward normal `sign × e_axis`,
    /// balls of radius `eps`, clears the depths and restricts drawing to the pixels that the
    /// boxes `boxes` (the occludees to test) can reach.
    pub fn begin(&mut self, eye: DVec3, axis: usize, sign: f64, eps: f64, boxes: &[DAabb]) {
        self.patch = None;
        self.setup(eye, axis, sign, eps, boxes);
    }

    /// [`Hemicube::begin`] for the rectangle of the face's plane centred on `eye` with half
    /// sides `half` (along the axes `(axis+1) % 3` and `(axis+2) % 3`) instead of a ball: a box
    /// found hidden is hidden from every point of that rectangle (looking out through the
    /// face), not from the whole ball. Each edge is shrunk for the rectangle's extent seen
    /// along the edge (see the module docs), never more than for the ball around it.
    pub fn begin_patch(
        &mut self,
        eye: DVec3,
        axis: usize,
        sign: f64,
        half: [f64; 2],
        boxes: &[DAabb],
    ) {
        self.patch = Some(half);
        self.setup(eye, axis, sign, half[0].hypot(half[1]), boxes);
    }

    fn setup(&mut self, eye: DVec3, axis: usize, sign: f64, eps: f64, boxes: &[DAabb]) {
        let maps = view_maps(axis, sign);
        let res = self.res;
        if self.views.is_empty() {
            self.views = maps
                .iter()
                .enumerate()
                .map(|(k, &map)| {
                    let h = if k == 0 { res } else { res / 2 };
                    View {
                        map,
                        h,
                        vmin: if k == 0 { -1.0 } else { 0.0 },
                        depth: vec![f32::INFINITY; res * h],
                        mask: vec![[0; LAYERS]; res * h],
                        wz: vec![[0.0; LAYERS]; res * h],
                        spill: Spill::new(),
                        tile_max: vec![f32::INFINITY; (res / TILE) * (h / TILE)],
                        need_z: vec![0.0; (res / TILE) * (h / TILE)],
                        need: [0; 4],
                    }
                })
                .collect();
        }
        self.eye = eye;
        self.axis = axis;
        self.sign = sign;
        self.eps = eps;
        self.max_dist = 0.0;
        for (k, v) in self.views.iter_mut().enumerate() {
            v.map = maps[k];
            v.need = [usize::MAX, 0, usize::MAX, 0];
            v.need_z.fill(0.0);
        }
        let tw = res / TILE;
        for bx in boxes {
            let far = (bx.min - eye).abs().max((bx.max - eye).abs()).length();
            self.max_dist = self.max_dist.max(far);
            let dist = self.dist(bx);
            for k in 0..5 {
                if let Some(r) = self.rect(k, bx, dist) {
                    let n = &mut self.views[k].need;
                    n[0] = n[0].min(r.i[0]);
                    n[1] = n[1].max(r.i[1]);
                    n[2] = n[2].min(r.j[0]);
                    n[3] = n[3].max(r.j[1]);
                    // Its pieces and triangles are tested at their own depths, up to its
                    // farthest.
                    let z = round_up(self.view_box(k, bx)[2][1]);
                    let v = &mut self.views[k];
                    for tj in r.j[0] / TILE..r.j[1].div_ceil(TILE) {
                        for t in
                            &mut v.need_z[tj * tw + r.i[0] / TILE..tj * tw + r.i[1].div_ceil(TILE)]
                        {
                            *t = t.max(z);
                        }
                    }
                }
            }
        }
        for v in &mut self.views {
            if v.need[0] >= v.need[1] {
                v.need = [0; 4];
            }
            // Clear the needed pixels (and their tiles, rounded out to whole tiles).
            let [i0, i1, j0, j1] = v.need;
            v.spill.clear();
            let (ti0, ti1, tj0, tj1) = (i0 / TILE, i1.div_ceil(TILE), j0 / TILE, j1.div_ceil(TILE));
            for tj in tj0..tj1 {
                for row in tj * TILE..(tj + 1) * TILE {
                    let span = row * res + ti0 * TILE..row * res + ti1 * TILE;
                    v.depth[span.clone()].fill(f32::INFINITY);
                    v.mask[span.clone()].fill([0; LAYERS]);
                    v.wz[span].fill([0.0; LAYERS]);
                }
                v.tile_max[tj * (res / TILE) + ti0..tj * (res / TILE) + ti1].fill(f32::INFINITY);
            }
        }
    }

    /// The view coordinates' ranges of a box relative to the eye, per view axis.
    fn view_box(&self, k: usize, bx: &DAabb) -> [[f64; 2]; 3] {
        let lo = bx.min - self.eye;
        let hi = bx.max - self.eye;
        self.views[k].map.map(|(ax, s)| {
            if s > 0.0 {
                [lo[ax], hi[ax]]
            } else {
                [-hi[ax], -lo[ax]]
            }
        })
    }

    /// The distance from the eye to the box (0 when it holds the eye).
    fn dist(&self, bx: &DAabb) -> f64 {
        bx.distance_to(self.eye)
    }

    /// The pixels the box's directions can reach in view `k` (outward rounding), with the
    /// nearest view depth of its part inside the view's frustum; None when no part of it is.
    /// `dist` is [`Hemicube::dist`] of the box (the same for every view).
    fn rect(&self, k: usize, bx: &DAabb, dist: f64) -> Option<Rect> {
        let [[x0, x1], [mut y0, y1], [z0, z1]] = self.view_box(k, bx);
        // Inside the frustum Z ≥ |X|, |Y|, so |P| ≤ √3·Z: the box's part there has Z ≥ this.
        let z_lo = dist / 3f64.sqrt() * (1.0 - 1e-12);
        let zl = z0.max(z_lo);
        if z1 < zl || z1 <= 0.0 {
            return None;
        }
        let view = &self.views[k];
        if view.vmin >= 0.0 {
            y0 = y0.max(0.0);
            if y1 < y0 {
                return None;
            }
        }
        if zl <= 0.0 {
            // The box reaches the eye: every pixel.
            return Some(Rect {
                i: [0, self.res],
                j: [0, view.h],
                pu: [0.0, self.res as f64],
                pv: [0.0, view.h as f64],
                z: 0.0,
            });
        }
        let lo = |a: f64| if a >= 0.0 { a / z1 } else { a / zl };
        let hi = |a: f64| if a >= 0.0 { a / zl } else { a / z1 };
        let (u0, u1) = (lo(x0) - 1e-9, hi(x1) + 1e-9);
        let (v0, v1) = (lo(y0) - 1e-9, hi(y1) + 1e-9);
        let half = self.res as f64 / 2.0;
        if u0 > 1.0 || u1 < -1.0 || v0 > view.vmin + view.h as f64 / half || v1 < view.vmin {
            return None;
        }
        let to_px = |t: f64, min: f64, n: usize| -> f64 { ((t - min) * half).clamp(0.0, n as f64) };
        let i0 = to_px(u0, -1.0, self.res).floor() as usize;
        let i1 = (to_px(u1, -1.0, self.res).floor() as usize + 1).min(self.res);
        let j0 = to_px(v0, view.vmin, view.h).floor() as usize;
        let j1 = (to_px(v1, view.vmin, view.h).floor() as usize + 1).min(view.h);
        (i0 < i1 && j0 < j1).then_some(Rect {
            i: [i0, i1],
            j: [j0, j1],
            pu: [(u0 + 1.0) * half, (u1 + 1.0) * half],
            pv: [(v0 - view.vmin) * half, (v1 - view.vmin) * half],
            z: zl,
        })
    }

    /// Draws every useful polygon of `occ`, front to back.
    pub fn draw(&mut self, occ: &SampleOccluders) -> RenderStats {
        let mut st = RenderStats::default();
        let Some(bvh) = occ.bvh.as_ref() else {
            return st;
        };
        if self.views.iter().all(|v| v.need[0] >= v.need[1]) || bvh.nodes.is_empty() {
            return st;
        }
        let mut stack = std::mem::take(&mut self.stack);
        let mut ts = std::mem::take(&mut self.scratch_ts);
        stack.clear();
        stack.push(0);
        while let Some(id) = stack.pop() {
            let node = &bvh.nodes[id as usize];
            st.nodes += 1;
            let bx = DAabb {
                min: glam::Vec3::from(node.aabb.min).as_dvec3(),
                max: glam::Vec3::from(node.aabb.max).as_dvec3(),
            };
            if !self.useful(&bx) {
                continue;
            }
            if node.is_leaf() {
                for k in node.first_index..node.first_index + node.prim_count {
                    let poly = bvh.primitive_indices[k as usize] as usize;
                    st.reached += 1;
                    if let Some(tucked) = self.draw_poly(occ, poly, &mut ts) {
                        st.polygons += 1;
                        st.tucked += u64::from(tucked != 0);
                    }
                }
            } else {
                let (l, r) = (node.first_index, node.first_index + 1);
                let d = |n: u32| {
                    let b = &bvh.nodes[n as usize].aabb;
                    let c = glam::Vec3::from((b.min + b.max) * 0.5).as_dvec3();
                    (c - self.eye).length_squared()
                };
                if d(l) <= d(r) {
                    stack.push(r);
                    stack.push(l);
                } else {
                    stack.push(l);
                    stack.push(r);
                }
            }
        }
        self.stack = stack;
        self.scratch_ts = ts;
        st
    }

    /// The parts of a box in the views (appended to `out`) that a GPU twin tests as
    /// [`Hemicube::test_box`] does: hidden when every pixel of every part holds a depth
    /// strictly nearer than the part's `z`, or its sub-pixels under the part do. False, with
    /// nothing appended, when the box is open without a pixel test (it reaches farther than
    /// the boxes given to [`Hemicube::begin`], or the eye, or pixels not drawn this render).
    pub fn box_rects(&self, bx: &DAabb, out: &mut Vec<BoxRect>) -> bool {
        if self.beyond_bound(&[bx.min, bx.max]) {
            return false;
        }
        let dist = self.dist(bx);
        let start = out.len();
        for k in 0..5 {
            let Some(r) = self.rect(k, bx, dist) else {
                continue;
            };
            let v = &self.views[k];
            if r.z <= 0.0
                || r.i[0] < v.need[0]
                || r.i[1] > v.need[1]
                || r.j[0] < v.need[2]
                || r.j[1] > v.need[3]
            {
                out.truncate(start);
                return false;
            }
            out.push(BoxRect {
                view: k as u8,
                i: r.i.map(|x| x as u32),
                j: r.j.map(|x| x as u32),
                pu: r.pu,
                pv: r.pv,
                z: r.z * (1.0 - 1e-9),
            });
        }
        true
    }

    /// `√(u²+v²+1)` at the pixel corners, rounded to `f32`, as the corner tests use it: the
    /// front view's `(R+1)²` (row by row, `R+1` per row), then the side views' `(R+1)·(R/2+1)`.
    pub fn corner_norms(&self) -> (&[f32], &[f32]) {
        (&self.norm_front, &self.norm_side)
    }

    /// The render's set-up as the GPU twin's per-polygon pass takes it
    /// (`shaders/sampler_setup.wgsl`): `f64`s (the eye, ε, the rectangle's half sides, the
    /// farthest box corner's distance) and `u32`s (axis, sign, rectangle, depth-bounded,
    /// sub-pixel masks, resolution, `polys`, `capacity`, each view's needed pixels, then each
    /// view's tiles' need depths as `f32` bits).
    pub fn setup_frame(&self, polys: u32, capacity: u32) -> (Vec<f64>, Vec<u32>) {
        let [hb, hc] = self.patch.unwrap_or([0.0; 2]);
        let f = vec![
            self.eye.x,
            self.eye.y,
            self.eye.z,
            self.eps,
            hb,
            hc,
            self.max_dist,
        ];
        let mut u = vec![
            self.axis as u32,
            u32::from(self.sign > 0.0),
            u32::from(self.patch.is_some()),
            u32::from(self.depth_bounded),
            u32::from(self.subpixel),
            self.res as u32,
            polys,
            capacity,
        ];
        for v in &self.views {
            u.extend(v.need.map(|x| x as u32));
        }
        if self.views.is_empty() {
            // Never begun: no view needs a pixel.
            u.extend([0; 20]);
        }
        for v in &self.views {
            u.extend(v.need_z.iter().map(|z| z.to_bits()));
        }
        (f, u)
    }

    /// Whether anything in `bx` could still lower a needed pixel.
    fn useful(&self, bx: &DAabb) -> bool {
        let (a, s) = (self.axis, self.sign);
        // Entirely behind the face's plane.
        if (s > 0.0 && bx.max[a] < self.eye[a]) || (s < 0.0 && bx.min[a] > self.eye[a]) {
            return false;
        }
        let dist = self.dist(bx);
        if dist > self.max_dist {
            return false;
        }
        for k in 0..5 {
            let v = &self.views[k];
            if v.need[0] >= v.need[1] {
                continue;
            }
            let Some(r) = self.rect(k, bx, dist) else {
                continue;
            };
            let i0 = r.i[0].max(v.need[0]);
            let i1 = r.i[1].min(v.need[1]);
            let j0 = r.j[0].max(v.need[2]);
            let j1 = r.j[1].min(v.need[3]);
            if i0 >= i1 || j0 >= j1 {
                continue;
            }
            // A polygon in the box is drawn no nearer than `z` in any pixel (its depth there
            // is at least its nearest point's there, rounded up).
            if v.may_lower(self.res, [i0, i1, j0, j1], r.z as f32) {
                return true;
            }
        }
        false
    }

    /// The edges of polygon `pts` (world space; its first 32) that may be drawn unshrunk:
    /// those wholly on the outer side of the face plane whose every point lies beyond what
    /// was drawn ([`Hemicube::segment_hidden`]).
    fn tuck_mask(&self, pts: &[DVec3], ts: &mut Vec<f64>) -> u32 {
        let n = pts.len().min(32);
        let mut mask = 0u32;
        let outer = |pt: DVec3| self.sign * (pt[self.axis] - self.eye[self.axis]) > 0.0;
        for k in 0..n {
            let (a, b) = (pts[k], pts[(k + 1) % pts.len()]);
            // Only an edge wholly on the outer side of the face plane: the test covers only
            // the views, and any point of the edge may be where a segment leaves.
            if outer(a)
                && outer(b)
                && self.anything_nearer(a)
                && self.anything_nearer(b)
                && self.anything_nearer((a + b) * 0.5)
                && self.segment_hidden(a, b, ts)
            {
                mask |= 1 << k;
            }
        }
        mask
    }

    /// Draws polygon `poly` into every view it reaches: the mask of the edges it drew
    /// unshrunk, or `None` when it was left out or covered no pixel. With the tuck pass, a
    /// polygon (not a card) that could lower a pixel in some view is drawn with the edges
    /// [`Hemicube::tuck_mask`] finds unshrunk; `ts` is the pass's scratch.
    fn draw_poly(&mut self, occ: &SampleOccluders, poly: usize, ts: &mut Vec<f64>) -> Option<u32> {
        let mut q = std::mem::take(&mut self.scratch_q);
        let mut edges = std::mem::take(&mut self.scratch_edges);
        let card = occ
            .card(poly)
            .map(|c| (c, &*occ.coverages[c.coverage as usize]));
        let drawn = self.draw_poly_with(occ.poly_points(poly), card, &mut q, &mut edges, ts);
        self.scratch_q = q;
        self.scratch_edges = edges;
        drawn
    }

    fn draw_poly_with(
        &mut self,
        pts: &[DVec3],
        card: Option<(&SampleCard, &Coverage)>,
        q: &mut Vec<DVec3>,
        edges: &mut Vec<(DVec3, f64)>,
        ts: &mut Vec<f64>,
    ) -> Option<u32> {
        let n = pts.len();
        if n < 3 {
            return None;
        }
        let eps = self.eps;
        q.clear();
        edges.clear();
        let mut centroid = DVec3::ZERO;
        let mut far = 0f64;
        for &pt in pts {
            let r = pt - self.eye;
            q.push(r);
            centroid += r;
            far = far.max(r.length());
        }
        centroid /= n as f64;
        let centroid_len = centroid.length();
        far *= n as f64;
        // Per edge, the normal of the plane through the eye and the edge (their sum is the
        // Newell normal: the polygon is exactly planar) and the radius of the region sampled
        // seen along the edge (the ball: ε; the rectangle: its largest distance from the eye
        // across the edge's direction).
        let (b_ax, c_ax) = ((self.axis + 1) % 3, (self.axis + 2) % 3);
        let mut normal = DVec3::ZERO;
        let mut most = 0f64;
        for k in 0..n {
            let (a, b) = (q[k], q[(k + 1) % n]);
            let cr = a.cross(b);
            normal += cr;
            let reach = match self.patch {
                None => eps,
                Some([hb, hc]) => {
                    let t = (b - a).normalize_or_zero();
                    let d = hb * t[b_ax].abs() - hc * t[c_ax].abs();
                    (hb * hb + hc * hc - d * d).max(0.0).sqrt().min(eps)
                }
            } * (1.0 + 1e-9);
            edges.push((cr, reach));
            most = most.max(reach);
        }
        let nl = normal.length();
        if !(nl > 0.0 && nl.is_finite()) {
            return None;
        }
        let plane_dist = (normal / nl).dot(centroid).abs();
        if plane_dist.partial_cmp(&(most * (1.0 + 1e-6) + 1e-12 * centroid_len))
            != Some(std::cmp::Ordering::Greater)
        {
            return None;
        }
        self.near = plane_dist;
        // The footprint in each view, before any edge is set up: most polygons the traversal
        // reaches can lower no pixel (footprints do not depend on the shrinks, and each view
        // reads only its own pixels, so all five are found before any is drawn).
        let mut fps = [None; 5];
        for (k, fp) in fps.iter_mut().enumerate() {
            let v = &self.views[k];
            if v.need[0] < v.need[1] {
                *fp = self.footprint(k, q, 0.5 * plane_dist);
            }
        }
        if fps.iter().all(Option::is_none) {
            return None;
        }
        // The tuck pass: the edges that lie beyond what was drawn before this polygon are
        // drawn unshrunk (only for a polygon that can lower a pixel: elsewhere it changes
        // nothing, and the edge tests are its cost).
        let tucked = if self.tuck && card.is_none() {
            self.tuck_mask(pts, ts)
        } else {
            0
        };
        // The edge planes' unit normals toward the inside, and the shrink per edge.
        for k in 0..n {
            let (a, b) = (q[k], q[(k + 1) % n]);
            let cr = edges[k].0;
            let cl = cr.length();
            let el = (b - a).length();
            if !(cl > 0.0 && el > 0.0 && cl.is_finite()) {
                return None;
            }
            let mut m = cr / cl;
            // The inner side is the centroid's. Where the centroid lies within rounding of
            // the edge's plane (a degenerate or sliver polygon: three collinear points give
            // one plane through the eye for all their edges) that side is a rounding error,
            // and edges taking the same side of one plane covered a half-space: such a
            // polygon is left out, which only uncovers (`ORIENT_TOL`).
            let side = m.dot(centroid);
            let tol = ORIENT_TOL * (centroid_len * a.length() * b.length() / cl + far);
            // (NaN: left out too.)
            if side.abs().partial_cmp(&tol) != Some(std::cmp::Ordering::Greater) {
                return None;
            }
            if side < 0.0 {
                m = -m;
            }
            let r = cl / el;
            let reach = match self.patch {
                None => edges[k].1,
                Some(half) => edge_reach(edges[k].1, half, m, (b - a) / el, r, b_ax, c_ax),
            };
            let mut s = reach / r;
            // (Polygons of more than 32 edges have only their first 32 tucked.)
            if k < 32 && tucked >> k & 1 == 1 {
                s = 0.0;
            }
            if self.depth_bounded {
                let dd = self.max_dist * (1.0 + 1e-9);
                let den = 1.0 - std::f64::consts::SQRT_2 * reach / (r * dd).sqrt();
                if den > 0.0 {
                    s = s.min(s * (1.0 - r / dd).abs() / den);
                }
            }
            edges[k] = (m, s * (1.0 + 1e-6));
        }
        let mut drawn = false;
        for (k, fp) in fps.into_iter().enumerate() {
            if let Some(fp) = fp {
                drawn |= self.draw_in_view(k, fp, q, edges, normal / nl, card);
            }
        }
        drawn.then_some(tucked)
    }

    /// Polygon `q`'s (relative to the eye) footprint in view `k`, clipped at `Z ≥ zc` (its
    /// part with smaller `Z` is outside the frustum, where `|P| ≤ √3·Z`: with `zc` half the
    /// distance of its plane, all its points are at least that far from the eye): the needed
    /// pixels its projection's bound touches and its depth. `None` when it touches none, or
    /// when every tile it touches (and, for a footprint of at most [`PIXEL_CHECK`] pixels,
    /// every pixel) is already covered at least as near or matters to no occludee, so that
    /// drawing it (with any shrink) can change no pixel a test reads.
    fn footprint(&self, k: usize, q: &[DVec3], zc: f64) -> Option<Footprint> {
        let res = self.res;
        let view = &self.views[k];
        let map = view.map;
        let to_view = |p: DVec3| view_coords(map, p);
        let mut zmax = f64::NEG_INFINITY;
        let mut zmin = f64::INFINITY;
        let (mut umin, mut umax, mut vmin, mut vmax) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        let n = q.len();
        let mut any = false;
        for i in 0..n {
            let a = to_view(q[i]);
            let b = to_view(q[(i + 1) % n]);
            zmax = zmax.max(a.z);
            zmin = zmin.min(a.z);
            let mut add = |p: DVec3| {
                let (u, v) = (p.x / p.z, p.y / p.z);
                umin = umin.min(u);
                umax = umax.max(u);
                vmin = vmin.min(v);
                vmax = vmax.max(v);
                any = true;
            };
            if a.z >= zc {
                add(a);
            }
            if (a.z >= zc) != (b.z >= zc) {
                let t = (zc - a.z) / (b.z - a.z);
                let mut p = a + (b - a) * t;
                p.z = zc;
                add(p);
            }
        }
        if !any {
            return None;
        }
        let half = res as f64 / 2.0;
        let [ni0, ni1, nj0, nj1] = view.need;
        // The needed pixels the projection's bound touches; their corners are tested.
        let pi0 = (((umin + 1.0) * half).floor().max(0.0) as usize).max(ni0);
        let pi1 = (((umax + 1.0) * half).ceil().clamp(0.0, res as f64) as usize).min(ni1);
        let pj0 = (((vmin - view.vmin) * half).floor().max(0.0) as usize).max(nj0);
        let pj1 = (((vmax - view.vmin) * half).ceil().clamp(0.0, view.h as f64) as usize).min(nj1);
        if pi0 >= pi1 || pj0 >= pj1 {
            return None;
        }
        let z = round_up(zmax);
        let deep = zmax - zmin > 0.05 * zmax;
        // A deep polygon's pixel depths are at least about its nearest vertex's (a skip
        // decided on a rounded bound only loses coverage, never soundness).
        let zs = if deep {
            (zmin as f32).next_down().max(0.0)
        } else {
            z
        };
        let lowers = view.may_lower(res, [pi0, pi1, pj0, pj1], zs);
        lowers.then_some(Footprint {
            pixels: [pi0, pi1, pj0, pj1],
            z,
            deep,
        })
    }

    fn draw_in_view(
        &mut self,
        k: usize,
        fp: Footprint,
        q: &[DVec3],
        edges: &[(DVec3, f64)],
        normal: DVec3,
        card: Option<(&SampleCard, &Coverage)>,
    ) -> bool {
        let res = self.res;
        let ps = 2.0 / res as f64;
        let view = &self.views[k];
        let map = view.map;
        let to_view = |p: DVec3| view_coords(map, p);
        let [pi0, pi1, pj0, pj1] = fp.pixels;
        let (z, deep) = (fp.z, fp.deep);
        // A card triangle covers whole pixels only (where its texel footprint is opaque).
        let subpixel = self.subpixel && card.is_none();
        // The card's plane seen from the eye: its normal toward the plane, in view
        // coordinates, and the plane's distance.
        let card_plane = card.map(|_| {
            let nv = to_view(normal);
            if nv.dot(to_view(q[0])) < 0.0 { -nv } else { nv }
        });
        let plane_h = self.near;
        let (eye, reach) = (self.eye, self.eps);
        let mut ev_buf = std::mem::take(&mut self.scratch_ev);
        ev_buf.clear();
        for &(m, s) in edges {
            let mv = to_view(m);
            ev_buf.push([
                mv.x as f32,
                mv.y as f32,
                mv.z as f32,
                s as f32 * (1.0 + 1e-6),
            ]);
        }
        let ev = &ev_buf[..];
        // Only pixels that meet the shrunk silhouette can be covered, and it lies inside the
        // straight-edged polygon of the edges' tests with `√(u²+v²+1)` replaced by its least
        // value over the pixels' rectangle: scan the bound of that polygon alone (none: the
        // silhouette is empty here).
        let Some([pi0, pi1, pj0, pj1]) = shrunk_bound(
            ev,
            [pi0, pi1, pj0, pj1],
            ps,
            view.vmin,
            &mut self.scratch_clip,
        ) else {
            self.scratch_ev = ev_buf;
            return false;
        };
        // A narrow silhouette may cover sub-pixels of pixels none of whose corners pass: all
        // its pixels get masks. Otherwise only pixels with a passing corner do.
        let thin = subpixel && (pi1 - pi0 <= 4 || pj1 - pj0 <= 4);
        // A polygon deep in this view (the ground, a wall seen at a slant) takes its plane's
        // depth per pixel instead: the largest of the pixel's corners (1/Z is affine over the
        // pixel, so Z is largest at a corner; a corner beyond the plane's horizon gives ∞).
        let plane = if deep {
            let nv = to_view(normal);
            Some((nv, nv.dot(to_view(q[0]))))
        } else {
            None
        };
        let plane_depth = |u: f64, v: f64| -> f64 {
            let (nv, d) = plane.expect("plane");
            let w = nv.x * u + nv.y * v + nv.z;
            let z = d / w;
            if z > 0.0 && z.is_finite() {
                z
            } else {
                f64::INFINITY
            }
        };
        let norms = if view.vmin < 0.0 {
            &self.norm_front
        } else {
            &self.norm_side
        };
        let mut lanes = std::mem::take(&mut self.scratch_lanes);
        EdgeLanes::fill(&mut lanes, ev);
        let mut pass = std::mem::take(&mut self.pass);
        let mut prev = std::mem::take(&mut self.prev);
        let view = &mut self.views[k];
        let mut wrote = false;
        let mut seen = false;
        let mut any_prev = false;
        let (mut wi0, mut wi1, mut wj0, mut wj1) = (usize::MAX, 0, usize::MAX, 0);
        for cj in pj0..=pj1 {
            let v = (view.vmin + cj as f64 * ps) as f32;
            let row = &norms[cj * (res + 1)..];
            let mut any_pass = false;
            // Each edge's `b·v`, once per row.
            for l in lanes.iter_mut() {
                l.row(v);
            }
            // The passing corners of a row are a run (a convex set meets a line in an
            // interval): stop at the first failure after it.
            let mut ci = pi0;
            while ci <= pi1 {
                let u = (-1.0 + ci as f64 * ps) as f32;
                let l = row[ci];
                let ok = lanes.iter().all(|e| e.pass(u, l));
                pass[ci] = ok as u8;
                if !ok && any_pass {
                    pass[ci + 1..=pi1].fill(0);
                    break;
                }
                any_pass |= ok;
                ci += 1;
            }
            if cj > pj0 && (any_pass || any_prev || thin) {
                let pj = cj - 1;
                let prow = &norms[pj * (res + 1)..];
                for ci in pi0..pi1 {
                    let corners = prev[ci] + prev[ci + 1] + pass[ci] + pass[ci + 1];
                    if corners == 0 && !thin {
                        continue;
                    }
                    let (u0, v0) = (-1.0 + ci as f64 * ps, view.vmin + pj as f64 * ps);
                    let z = if plane.is_some() {
                        let (u1, v1) = (u0 + ps, v0 + ps);
                        let m = plane_depth(u0, v0)
                            .max(plane_depth(u1, v0))
                            .max(plane_depth(u0, v1))
                            .max(plane_depth(u1, v1));
                        round_up(m).min(z)
                    } else {
                        z
                    };
                    let idx = pj * res + ci;
                    let d = view.depth[idx];
                    if z >= d {
                        continue;
                    }
                    let cover = if corners == 4 {
                        match (card, card_plane) {
                            (Some((c, cov)), Some(nv)) => {
                                let unview = |d: DVec3| {
                                    let mut w = DVec3::ZERO;
                                    w[map[0].0] += map[0].1 * d.x;
                                    w[map[1].0] += map[1].1 * d.y;
                                    w[map[2].0] += map[2].1 * d.z;
                                    w
                                };
                                if footprint_opaque(c, cov, nv, plane_h, reach, u0, v0, ps, |d| {
                                    eye + unview(d)
                                }) {
                                    u64::MAX
                                } else {
                                    0
                                }
                            }
                            _ => u64::MAX,
                        }
                    } else if subpixel && (corners > 0 || thin) {
                        let lmax = row[ci].max(row[ci + 1]).max(prow[ci]).max(prow[ci + 1]);
                        pixel_mask(ev, u0, v0, ps, f64::from(lmax))
                    } else {
                        0
                    };
                    if cover == 0 {
                        continue;
                    }
                    let new_depth = if cover == u64::MAX {
                        Some(z)
                    } else {
                        add_layer(
                            &mut view.mask[idx],
                            &mut view.wz[idx],
                            &mut view.spill,
                            idx,
                            cover,
                            z,
                            d,
                        )
                    };
                    if let Some(nd) = new_depth {
                        view.depth[idx] = nd;
                        wrote = true;
                        wi0 = wi0.min(ci);
                        wi1 = wi1.max(ci + 1);
                        wj0 = wj0.min(pj);
                        wj1 = wj1.max(pj + 1);
                    }
                }
            }
            if !any_pass && seen && !thin {
                // The passing corners are the lattice points of a convex set: none later,
                // and the pixels between this row and the last passing one are done.
                break;
            }
            seen |= any_pass;
            any_prev = any_pass;
            std::mem::swap(&mut pass, &mut prev);
        }
        if wrote {
            let tw = res / TILE;
            for tj in wj0 / TILE..wj1.div_ceil(TILE) {
                for ti in wi0 / TILE..wi1.div_ceil(TILE) {
                    let mut m = 0f32;
                    for r in tj * TILE..(tj + 1) * TILE {
                        for &d in &view.depth[r * res + ti * TILE..r * res + (ti + 1) * TILE] {
                            m = m.max(d);
                        }
                    }
                    view.tile_max[tj * tw + ti] = m;
                }
            }
        }
        self.pass = pass;
        self.prev = prev;
        self.scratch_ev = ev_buf;
        self.scratch_lanes = lanes;
        wrote
    }

    /// Whether the box's (or triangle's) part of pixel `(i, j)` (index `idx`) is covered
    /// nearer than `z` by the pixel's partial layers: every sub-pixel that its directions can
    /// reach there (the unrounded bounds `r.pu`, `r.pv` rounded outward to whole sub-pixels)
    /// is set in the union of the layers nearer than `z`. A set sub-pixel of a layer lies
    /// wholly inside the shrunk silhouette of a polygon no deeper than the layer's depth, so
    /// each direction of the part in it is covered as a fully covered pixel's would be.
    fn sub_covered(&self, v: &View, idx: usize, r: &Rect, i: usize, j: usize, z: f64) -> bool {
        // The layers are sorted nearest first: those nearer than `z` are a prefix.
        let mut m = 0u64;
        for (bits, wz) in v.layers(idx) {
            if bits == 0 || (wz as f64).partial_cmp(&z) != Some(std::cmp::Ordering::Less) {
                break;
            }
            m |= bits;
        }
        if m == 0 {
            return false;
        }
        // Sub-pixel indices of the bounds, widened by a millionth of a sub-pixel against the
        // rounding of the subtraction and product (the bounds are at most `res` in size).
        let span = |lo: f64, hi: f64, p: usize| -> (u32, u32) {
            let a = ((lo - p as f64) * 8.0 - 1e-6).floor().clamp(0.0, 7.0) as u32;
            let b = ((hi - p as f64) * 8.0 + 1e-6).floor().clamp(0.0, 7.0) as u32;
            (a, b)
        };
        let (a0, a1) = span(r.pu[0], r.pu[1], i);
        let (b0, b1) = span(r.pv[0], r.pv[1], j);
        let row = ((1u64 << (a1 - a0 + 1)) - 1) << a0;
        let mut need = 0u64;
        for b in b0..=b1 {
            need |= row << (8 * b);
        }
        m & need == need
    }

    /// The share of the needed pixels that some polygon covers, and the median depth of the
    /// covered ones (for probes and tuning).
    pub fn coverage(&self) -> (f64, f64) {
        let (mut n, mut c) = (0usize, 0usize);
        let mut depths = Vec::new();
        for v in &self.views {
            let [i0, i1, j0, j1] = v.need;
            for j in j0..j1 {
                for i in i0..i1 {
                    n += 1;
                    let d = v.depth[j * self.res + i];
                    if d.is_finite() {
                        c += 1;
                        depths.push(d);
                    }
                }
            }
        }
        depths.sort_by(f32::total_cmp);
        let med = depths
            .get(depths.len() / 2)
            .copied()
            .unwrap_or(f32::INFINITY);
        (c as f64 / n.max(1) as f64, f64::from(med))
    }

    /// The state of the pixel that direction `dir` (world space) falls in, for probes
    /// (`examples/sampler_leaks.rs`): its depth, its partial mask and that mask's depth. None
    /// when the direction is outside the hemisphere or outside the pixels drawn this render.
    pub fn pixel_state(&self, dir: DVec3) -> Option<(f32, u64, f32)> {
        let (v, idx, _) = self.locate(dir)?;
        let m = v.layers(idx).fold(0, |a, (b, _)| a | b);
        let wz = v
            .layers(idx)
            .filter(|(b, _)| *b != 0)
            .fold(0.0f32, |a, (_, z)| a.max(z));
        Some((v.depth[idx], m, wz))
    }

    /// The view and pixel that direction `dir` (world space) falls in, and its view depth
    /// (`dir`'s own); None when it is outside the hemisphere or outside the pixels drawn this
    /// render.
    fn locate(&self, dir: DVec3) -> Option<(&View, usize, f64)> {
        let half = self.res as f64 / 2.0;
        for v in &self.views {
            let c = v.map.map(|(ax, s)| s * dir[ax]);
            if c[2] <= 0.0 {
                continue;
            }
            let (u, w) = (c[0] / c[2], c[1] / c[2]);
            if !(-1.0..1.0).contains(&u) || w < v.vmin || w >= v.vmin + v.h as f64 / half {
                continue;
            }
            let i = ((u + 1.0) * half) as usize;
            let j = ((w - v.vmin) * half) as usize;
            if i < v.need[0] || i >= v.need[1] || j < v.need[2] || j >= v.need[3] {
                return None;
            }
            return Some((v, j * self.res + i, c[2]));
        }
        None
    }

    /// Whether every point of the segment `a b` (world space) lies beyond what was drawn:
    /// [`Hemicube::test_triangle`] for a segment, cheaper. Per view, the segment is clipped
    /// to the view's frustum (planes widened, the parameter interval widened), then cut where
    /// it crosses pixel boundaries (`u` and `v` are monotonic along it); each piece's pixels
    /// (its `u`/`v` bounds, widened) must hold a depth strictly nearer than the piece's
    /// nearest view depth (less a relative 1e-9), or their layers nearer than that must hold
    /// every sub-pixel of the piece's bounds. Parts outside every view are not tested, so
    /// only a segment wholly on the outer side of the face plane may rely on the answer.
    fn segment_hidden(&self, a: DVec3, b: DVec3, ts: &mut Vec<f64>) -> bool {
        if !(a.is_finite() && b.is_finite()) || self.beyond_bound(&[a, b]) {
            return false;
        }
        let res = self.res;
        let ps = 2.0 / res as f64;
        let half = res as f64 / 2.0;
        const W: f64 = 1e-9;
        for v in &self.views {
            let map = v.map;
            let to = |p: DVec3| view_coords(map, p - self.eye);
            let (pa, pb) = (to(a), to(b));
            let d = pb - pa;
            let vmax = v.vmin + v.h as f64 * ps;
            let (mut t0, mut t1) = (0f64, 1f64);
            for n in [
                DVec3::new(1.0, 0.0, 1.0 + W),
                DVec3::new(-1.0, 0.0, 1.0 + W),
                DVec3::new(0.0, 1.0, -v.vmin + W),
                DVec3::new(0.0, -1.0, vmax + W),
            ] {
                let (fa, fd) = (n.dot(pa), n.dot(d));
                if fd == 0.0 {
                    if fa < 0.0 {
                        t1 = -1.0;
                    }
                } else if fd > 0.0 {
                    t0 = t0.max(-fa / fd);
                } else {
                    t1 = t1.min(-fa / fd);
                }
            }
            if t0 > t1 {
                continue;
            }
            let (t0, t1) = ((t0 - 1e-12).max(0.0), (t1 + 1e-12).min(1.0));
            let at = |t: f64| pa + d * t;
            let (p0, p1) = (at(t0), at(t1));
            if !(p0.z > 0.0 && p1.z > 0.0) {
                return false;
            }
            // Pixel units along u and v of a point.
            let upx = |p: DVec3| (p.x / p.z + 1.0) * half;
            let vpx = |p: DVec3| (p.y / p.z - v.vmin) * half;
            let (u0, u1) = (upx(p0), upx(p1));
            let (v0, v1) = (vpx(p0), vpx(p1));
            // The pieces' ends: `t0`, the crossings of pixel boundaries in order, `t1`. Along
            // the segment `u` and `v` are monotonic, so each coordinate's crossings come
            // sorted (ascending or descending) and the two lists are merged; rounding that
            // breaks the order falls back to sorting them all.
            ts.clear();
            let mut split = [0usize; 2];
            for (coord, lo, hi) in [
                (0usize, u0.min(u1), u0.max(u1)),
                (1, v0.min(v1), v0.max(v1)),
            ] {
                let (k0, k1) = (lo.ceil().max(0.0), hi.floor().min(res as f64));
                let span = k1 - k0;
                if span.is_nan() || span >= 4.0 * res as f64 {
                    return false;
                }
                let start = ts.len();
                let mut k = k0;
                while k <= k1 {
                    // The boundary w = k / half + offset: X − w·Z = 0 (or Y).
                    let w = if coord == 0 {
                        k / half - 1.0
                    } else {
                        k / half + v.vmin
                    };
                    let den = d[coord] - w * d.z;
                    if den != 0.0 {
                        let t = (w * pa.z - pa[coord]) / den;
                        if t > t0 && t < t1 {
                            ts.push(t);
                        }
                    }
                    k += 1.0;
                }
                let run = &mut ts[start..];
                if run.len() > 1 && run[0] > run[run.len() - 1] {
                    run.reverse();
                }
                split[coord] = ts.len();
            }
            let sorted = |r: &[f64]| r.windows(2).all(|w| w[0] <= w[1]);
            let nu = split[0];
            if sorted(&ts[..nu]) && sorted(&ts[nu..]) {
                // Merge the two runs behind the buffer's end, then move them down.
                let n = ts.len();
                let (mut a, mut b) = (0, nu);
                while a < nu || b < n {
                    let x = if b >= n || (a < nu && ts[a] <= ts[b]) {
                        a += 1;
                        ts[a - 1]
                    } else {
                        b += 1;
                        ts[b - 1]
                    };
                    ts.push(x);
                }
                ts.drain(..n);
            } else {
                ts.sort_unstable_by(f64::total_cmp);
            }
            ts.insert(0, t0);
            ts.push(t1);
            // Each piece's end is the next one's start: its point and pixel coordinates are
            // computed once.
            let end = |t: f64| {
                let q = at(t);
                (upx(q), vpx(q), q.z)
            };
            let mut a = end(ts[0]);
            for &tb in &ts[1..] {
                let b = end(tb);
                let ((ua, va, za), (ub, vb, zb)) = (a, b);
                a = b;
                let pu = [ua.min(ub) - 1e-6, ua.max(ub) + 1e-6];
                let pv = [va.min(vb) - 1e-6, va.max(vb) + 1e-6];
                let i0 = pu[0].floor().clamp(0.0, res as f64 - 1.0) as usize;
                let i1 = pu[1].floor().clamp(0.0, res as f64 - 1.0) as usize;
                let j0 = pv[0].floor().clamp(0.0, v.h as f64 - 1.0) as usize;
                let j1 = pv[1].floor().clamp(0.0, v.h as f64 - 1.0) as usize;
                if i0 < v.need[0] || i1 >= v.need[1] || j0 < v.need[2] || j1 >= v.need[3] {
                    return false;
                }
                let z = za.min(zb) * (1.0 - 1e-9);
                for j in j0..=j1 {
                    for i in i0..=i1 {
                        let idx = j * res + i;
                        if (v.depth[idx] as f64).partial_cmp(&z) == Some(std::cmp::Ordering::Less) {
                            continue;
                        }
                        let r = Rect {
                            i: [i, i + 1],
                            j: [j, j + 1],
                            pu,
                            pv,
                            z,
                        };
                        if !self.sub_covered(v, idx, &r, i, j, z) {
                            return false;
                        }
                    }
                }
            }
        }
        true
    }

    /// Whether the pixel that point `pt` (world space) falls in holds anything nearer than
    /// `pt`: a depth or a partial layer. A necessary condition for a test of anything through
    /// `pt` to find it hidden there (false outside the pixels drawn this render).
    fn anything_nearer(&self, pt: DVec3) -> bool {
        self.locate(pt - self.eye).is_some_and(|(v, idx, z)| {
            let z = z as f32;
            v.depth[idx] < z || v.layers(idx).any(|(b, wz)| b != 0 && wz < z)
        })
    }

    /// Whether the box spanned by `pts` reaches farther from the eye than the farthest corner
    /// of the boxes given to [`Hemicube::begin`], for which the edges were shrunk.
    pub fn beyond_bound(&self, pts: &[DVec3]) -> bool {
        if !self.depth_bounded {
            return false;
        }
        let mut lo = DVec3::INFINITY;
        let mut hi = DVec3::NEG_INFINITY;
        for &p in pts {
            lo = lo.min(p - self.eye);
            hi = hi.max(p - self.eye);
        }
        lo.abs().max(hi.abs()).length() > self.max_dist
    }

    /// Tests a box (an occludee) against what was drawn. Only boxes given to
    /// [`Hemicube::begin`] (or inside their union of pixels) may be tested; a box reaching
    /// farther than the farthest of them is open (the shrink was chosen for those).
    pub fn test_box(&self, bx: &DAabb) -> BoxTest {
        if self.beyond_bound(&[bx.min, bx.max]) {
            return BoxTest::Open {
                direction: bx.center() - self.eye,
            };
        }
        let res = self.res;
        let tw = res / TILE;
        let ps = 2.0 / res as f64;
        let dist = self.dist(bx);
        for k in 0..5 {
            let Some(r) = self.rect(k, bx, dist) else {
                continue;
            };
            let v = &self.views[k];
            let z = r.z * (1.0 - 1e-9);
            let open = |i: usize, j: usize| BoxTest::Open {
                direction: v.pixel_direction(ps, i, j),
            };
            if r.z <= 0.0
                || r.i[0] < v.need[0]
                || r.i[1] > v.need[1]
                || r.j[0] < v.need[2]
                || r.j[1] > v.need[3]
            {
                return open(r.i[0], r.j[0]);
            }
            for tj in r.j[0] / TILE..r.j[1].div_ceil(TILE) {
                for ti in r.i[0] / TILE..r.i[1].div_ceil(TILE) {
                    if (v.tile_max[tj * tw + ti] as f64) < z {
                        continue;
                    }
                    for j in (tj * TILE).max(r.j[0])..((tj + 1) * TILE).min(r.j[1]) {
                        for i in (ti * TILE).max(r.i[0])..((ti + 1) * TILE).min(r.i[1]) {
                            let idx = j * res + i;
                            if (v.depth[idx] as f64).partial_cmp(&z)
                                != Some(std::cmp::Ordering::Less)
                                && !self.sub_covered(v, idx, &r, i, j, z)
                            {
                                return open(i, j);
                            }
                        }
                    }
                }
            }
        }
        BoxTest::Hidden
    }

    /// Tests a triangle (an occludee's) against what was drawn: like [`Hemicube::test_box`],
    /// but pixel by pixel with the triangle's own part in each pixel rather than its box's
    /// rectangle and nearest depth. Per view, the triangle is clipped to the view's frustum,
    /// then to each pixel row's and each pixel's pyramid of directions (every plane widened
    /// outward, so each clipped polygon holds the triangle's part there despite rounding); a
    /// pixel the part reaches must hold a depth strictly nearer than the part's nearest view
    /// depth, or be covered that near by its sub-pixel mask over the part's bounds. A triangle
    /// reaching the eye is tested by its box. Only triangles inside the boxes given to
    /// [`Hemicube::begin`] may be tested.
    pub fn test_triangle(&self, tri: [DVec3; 3]) -> BoxTest {
        if self.beyond_bound(&tri) {
            return BoxTest::Open {
                direction: (tri[0] + tri[1] + tri[2]) / 3.0 - self.eye,
            };
        }
        let res = self.res;
        let ps = 2.0 / res as f64;
        let half = res as f64 / 2.0;
        // Widening of every clipping plane's slope: far above the rounding of the clips.
        const W: f64 = 1e-9;
        let mut poly: Vec<DVec3> = Vec::with_capacity(16);
        let mut row: Vec<DVec3> = Vec::with_capacity(16);
        let mut px: Vec<DVec3> = Vec::with_capacity(16);
        let mut tmp: Vec<DVec3> = Vec::with_capacity(16);
        for k in 0..5 {
            let v = &self.views[k];
            let map = v.map;
            poly.clear();
            poly.extend(tri.iter().map(|p| view_coords(map, *p - self.eye)));
            // The view's frustum, widened: u ∈ [−1, 1], v ∈ [vmin, vmax].
            let vmax = v.vmin + v.h as f64 * ps;
            for n in [
                DVec3::new(1.0, 0.0, 1.0 + W),
                DVec3::new(-1.0, 0.0, 1.0 + W),
                DVec3::new(0.0, 1.0, -v.vmin + W),
                DVec3::new(0.0, -1.0, vmax + W),
            ] {
                clip(&mut poly, n, &mut tmp);
            }
            if poly.is_empty() {
                continue;
            }
            if poly
                .iter()
                .any(|p| p.z.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater))
            {
                // Reaches the eye: the box test decides.
                return self.test_box(&DAabb {
                    min: tri[0].min(tri[1]).min(tri[2]),
                    max: tri[0].max(tri[1]).max(tri[2]),
                });
            }
            let vrange = bounds(&poly, |p| p.y / p.z);
            let to_j = |w: f64| ((w - v.vmin) * half).clamp(0.0, v.h as f64);
            let j0 = to_j(vrange[0] - W).floor() as usize;
            let j1 = (to_j(vrange[1] + W).floor() as usize + 1).min(v.h);
            let open = |i: usize, j: usize| BoxTest::Open {
                direction: v.pixel_direction(ps, i, j),
            };
            for j in j0..j1 {
                // The row's pyramid: v ∈ [s0, s1], widened.
                let (s0, s1) = (v.vmin + j as f64 * ps, v.vmin + (j + 1) as f64 * ps);
                row.clear();
                row.extend_from_slice(&poly);
                clip(&mut row, DVec3::new(0.0, 1.0, -s0 + W), &mut tmp);
                clip(&mut row, DVec3::new(0.0, -1.0, s1 + W), &mut tmp);
                if row.is_empty() {
                    continue;
                }
                let urange = bounds(&row, |p| p.x / p.z);
                let to_i = |u: f64| ((u + 1.0) * half).clamp(0.0, res as f64);
                let i0 = to_i(urange[0] - W).floor() as usize;
                let i1 = (to_i(urange[1] + W).floor() as usize + 1).min(res);
                if i0 < v.need[0] || i1 > v.need[1] || j < v.need[2] || j >= v.need[3] {
                    return open(i0, j);
                }
                for i in i0..i1 {
                    let (t0, t1) = (-1.0 + i as f64 * ps, -1.0 + (i + 1) as f64 * ps);
                    px.clear();
                    px.extend_from_slice(&row);
                    clip(&mut px, DVec3::new(1.0, 0.0, -t0 + W), &mut tmp);
                    clip(&mut px, DVec3::new(-1.0, 0.0, t1 + W), &mut tmp);
                    if px.is_empty() {
                        continue;
                    }
                    let z = px.iter().map(|p| p.z).fold(f64::INFINITY, f64::min) * (1.0 - 1e-9);
                    let idx = j * res + i;
                    if (v.depth[idx] as f64).partial_cmp(&z) == Some(std::cmp::Ordering::Less) {
                        continue;
                    }
                    let (pu, pv) = (bounds(&px, |p| p.x / p.z), bounds(&px, |p| p.y / p.z));
                    let r = Rect {
                        i: [i, i + 1],
                        j: [j, j + 1],
                        pu: [(pu[0] - W + 1.0) * half, (pu[1] + W + 1.0) * half],
                        pv: [(pv[0] - W - v.vmin) * half, (pv[1] + W - v.vmin) * half],
                        z,
                    };
                    if !self.sub_covered(v, idx, &r, i, j, z) {
                        return open(i, j);
                    }
                }
            }
        }
        BoxTest::Hidden
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::SampleOccluders;

    /// A seeded xorshift generator of numbers uniform in `[-1, 1)`.
    fn uniform(mut x: u64) -> impl FnMut() -> f64 {
        move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        }
    }

    /// A pixel's layers keep every sub-pixel's own nearest depth however many depths it
    /// gathers (more than the inline [`LAYERS`] spill, nothing is merged): after each polygon,
    /// the union of the layers nearer than any depth `t`, and the pixel's depth, are those
    /// of 64 separate nearest depths. The old merge of the two farthest layers failed this.
    #[test]
    fn layers_keep_every_sub_pixels_nearest_depth() {
        let mut rnd = uniform(0x1a7e5);
        let mut spilled = 0;
        for case in 0..400 {
            let (mut masks, mut wz) = ([0u64; LAYERS], [0f32; LAYERS]);
            let mut spill = Spill::new();
            let idx = case % 7;
            // The model: each sub-pixel's nearest depth, and the pixel's depth.
            let mut near = [f32::INFINITY; 64];
            let mut d = f32::INFINITY;
            // Few bits per polygon and many distinct depths, so that pixels need many layers.
            let dense = case % 4 == 0;
            for _ in 0..60 {
                let z = ((rnd() + 1.0) * 20.0).floor() as f32 + 1.0;
                let mut bits = 0u64;
                for _ in 0..if dense { 24 } else { 3 } {
                    bits |= 1 << (((rnd() + 1.0) * 32.0) as u32).min(63);
                }
                if z >= d {
                    continue;
                }
                let got = add_layer(&mut masks, &mut wz, &mut spill, idx, bits, z, d);
                for (s, n) in near.iter_mut().enumerate() {
                    if bits >> s & 1 == 1 {
                        *n = n.min(z);
                    }
                }
                let all = near.iter().fold(0f32, |a, &n| a.max(n));
                let want = (all < d).then_some(all);
                assert_eq!(got, want, "case {case}: the pixel's new depth");
                if let Some(nd) = got {
                    d = nd;
                }
                spilled += usize::from(spill.contains_key(&idx));
                // The layers, inline then spilled, as `View::layers` reads them.
                let mut layers: Vec<(u64, f32)> = masks.iter().copied().zip(wz).collect();
                if masks[LAYERS - 1] != 0 {
                    layers.extend(spill.get(&idx).into_iter().flatten().copied());
                }
                for t in 0..=42 {
                    let t = t as f32 + 0.5;
                    if t > d {
                        break;
                    }
                    let mut m = 0u64;
                    for &(bits, w) in &layers {
                        if bits == 0 || w >= t {
                            break;
                        }
                        m |= bits;
                    }
                    let want = (0..64)
                        .filter(|&s| near[s] < t)
                        .fold(0u64, |a, s| a | 1 << s);
                    assert_eq!(m, want, "case {case}: sub-pixels nearer than {t}");
                }
            }
        }
        assert!(
            spilled > 100,
            "pixels with more than {LAYERS} layers: {spilled}"
        );
    }

    /// The corner test four edges at a time decides every corner as the test one edge at a
    /// time does, for any number of edges (the padded lanes pass every corner) and rows
    /// (`b·v` per row), with corners near each edge's boundary.
    #[test]
    fn edge_lanes_decide_corners_as_one_edge_at_a_time() {
        let mut rnd = uniform(0x5eed_1a9e);
        let mut lanes = Vec::new();
        let (mut passed, mut failed) = (0, 0);
        for k in 0..20_000 {
            let (u, v) = (rnd() as f32, rnd() as f32);
            let l = (u * u + v * v + 1.0).sqrt();
            let ev: Vec<[f32; 4]> = (0..1 + k % 9)
                .map(|_| {
                    let (a, b, s) = (rnd() as f32, rnd() as f32, (rnd().abs() * 0.01) as f32);
                    // Mostly just inside the edge, now and then just outside.
                    let c = -(a * u + b * v) + s * l + (rnd() * 1e-5 + 6e-6) as f32;
                    [a, b, c, s]
                })
                .collect();
            EdgeLanes::fill(&mut lanes, &ev);
            // A row set before, then the row tested.
            for e in lanes.iter_mut() {
                e.row(rnd() as f32);
                e.row(v);
            }
            let want = ev
                .iter()
                .all(|e| e[0] * u + e[1] * v + e[2] - e[3] * l >= CORNER_MARGIN);
            let got = lanes.iter().all(|e| e.pass(u, l));
            assert_eq!(got, want, "case {k}: {} edges", ev.len());
            if want {
                passed += 1;
            } else {
                failed += 1;
            }
        }
        assert!(
            passed > 1_000 && failed > 1_000,
            "{passed} pass, {failed} fail"
        );
    }

    /// A sub-pixel is set only when the exact (curved) test holds all over it, and with
    /// straight edges (`s` = 0) exactly when it holds at its four corners.
    #[test]
    fn pixel_masks_hold_their_edges_tests_and_no_more() {
        let mut rnd = uniform(0x9e37_79b9_7f4a_7c15u64);
        let margin = f64::from(CORNER_MARGIN);
        for k in 0..20_000 {
            let ps = [2.0 / 256.0, 2.0 / 16.0, 1e-4][k % 3];
            let (u0, v0) = (rnd(), rnd());
            let straight = k % 2 == 0;
            let ev: Vec<[f32; 4]> = (0..1 + k % 3)
                .map(|_| {
                    let a = rnd() as f32;
                    let b = rnd() as f32;
                    // Through the pixel (mostly), so that masks are partial.
                    let c = -(a * u0 as f32 + b * v0 as f32) + (rnd() * ps * 2.0) as f32;
                    let s = if straight {
                        0.0
                    } else {
                        (rnd().abs() * 0.01) as f32
                    };
                    [a, b, c + s * 2.0, s]
                })
                .collect();
            let lmax = [(u0, v0), (u0 + ps, v0), (u0, v0 + ps), (u0 + ps, v0 + ps)]
                .iter()
                .map(|&(u, v)| (u * u + v * v + 1.0f64).sqrt())
                .fold(0.0, f64::max);
            let mask = pixel_mask(&ev, u0, v0, ps, lmax);
            let h = ps / 8.0;
            let holds = |u: f64, v: f64, exact: bool| {
                ev.iter().all(|e| {
                    let (a, b, c, s) = e.map(f64::from).into();
                    let l = if exact {
                        (u * u + v * v + 1.0).sqrt()
                    } else {
                        lmax
                    };
                    a * u + b * v + c - s * l >= margin - 1e-12
                })
            };
            for bit in 0..64 {
                let (aa, bb) = (f64::from(bit % 8), f64::from(bit / 8));
                let (su, sv) = (u0 + aa * h, v0 + bb * h);
                let corners = [(su, sv), (su + h, sv), (su, sv + h), (su + h, sv + h)];
                if mask >> bit & 1 == 1 {
                    for (fu, fv) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (0.5, 0.5)] {
                        let (u, v) = (su + fu * h, sv + fv * h);
                        assert!(
                            holds(u, v, true),
                            "case {k}: sub-pixel {bit} set, fails at ({u}, {v})"
                        );
                    }
                } else if straight {
                    assert!(
                        corners.iter().any(|&(u, v)| !holds(u, v, false)),
                        "case {k}: sub-pixel {bit} left out though its corners pass"
                    );
                }
            }
        }
    }

    /// `shrunk_bound` may only drop pixels that no test can cover: every passing corner
    /// and every set sub-pixel of the rectangle it was given lies in the bound it returns
    /// (and with `None`, none exists); and it must drop something often, or it is useless.
    #[test]
    fn the_shrunk_bound_keeps_every_pixel_a_test_can_cover() {
        let mut rnd = uniform(0x2545_f491_4f6c_dd1du64);
        let (res, vmin) = (64usize, -1.0);
        let ps = 2.0 / res as f64;
        let mut scratch = [Vec::new(), Vec::new()];
        let (mut smaller, mut none) = (0, 0);
        let cases = 3000;
        for k in 0..cases {
            let corners: Vec<DVec3> = (0..3 + k % 2)
                .map(|i| {
                    let a = std::f64::consts::TAU * (i as f64 + 0.4 * rnd()) / (3 + k % 2) as f64;
                    let (cu, cv, r) = (0.5 * rnd(), 0.5 * rnd(), 0.05 + 0.5 * rnd().abs());
                    DVec3::new(cu + r * a.cos(), cv + r * a.sin(), 1.0)
                })
                .collect();
            let centroid = corners.iter().sum::<DVec3>() / corners.len() as f64;
            let ev: Vec<[f32; 4]> = (0..corners.len())
                .map(|i| {
                    let mut m = corners[i]
                        .cross(corners[(i + 1) % corners.len()])
                        .normalize();
                    if m.dot(centroid) < 0.0 {
                        m = -m;
                    }
                    let s = rnd().abs() * [0.0, 0.01, 0.05][k % 3];
                    [m.x as f32, m.y as f32, m.z as f32, s as f32]
                })
                .collect();
            let i0 = ((rnd() * 0.5 + 0.5) * res as f64 * 0.5) as usize;
            let j0 = ((rnd() * 0.5 + 0.5) * res as f64 * 0.5) as usize;
            let px = [
                i0,
                (i0 + 4 + k % 40).min(res),
                j0,
                (j0 + 4 + k % 37).min(res),
            ];
            let bound = shrunk_bound(&ev, px, ps, vmin, &mut scratch);
            let inside = |i: usize, j: usize, corner: bool| match bound {
                None => false,
                Some([bi0, bi1, bj0, bj1]) => {
                    let (ie, je) = if corner {
                        (bi1 + 1, bj1 + 1)
                    } else {
                        (bi1, bj1)
                    };
                    (bi0..ie).contains(&i) && (bj0..je).contains(&j)
                }
            };
            match bound {
                None => none += 1,
                Some(b) if b != px => smaller += 1,
                _ => {}
            }
            for j in px[2]..=px[3] {
                for i in px[0]..=px[1] {
                    let (u, v) = (-1.0 + i as f64 * ps, vmin + j as f64 * ps);
                    let l = (u * u + v * v + 1.0).sqrt() as f32;
                    let (uf, vf) = (u as f32, v as f32);
                    let passes = ev
                        .iter()
                        .all(|e| e[0] * uf + e[1] * vf + e[2] - e[3] * l >= CORNER_MARGIN);
                    assert!(
                        !passes || inside(i, j, true),
                        "case {k}: corner ({i}, {j}) passes outside {bound:?} of {px:?}"
                    );
                    if i < px[1] && j < px[3] && !inside(i, j, false) {
                        let lmax = [(0.0, 0.0), (ps, 0.0), (0.0, ps), (ps, ps)]
                            .iter()
                            .map(|&(du, dv)| ((u + du).powi(2) + (v + dv).powi(2) + 1.0).sqrt())
                            .fold(0.0, f64::max);
                        assert_eq!(
                            pixel_mask(&ev, u, v, ps, lmax),
                            0,
                            "case {k}: pixel ({i}, {j}) has sub-pixels outside {bound:?}"
                        );
                    }
                }
            }
        }
        assert!(
            smaller + none > cases / 2,
            "the bound dropped pixels in only {smaller} + {none} of {cases} cases"
        );
    }

    fn wall(z: f64, half: f64) -> Vec<DVec3> {
        vec![
            DVec3::new(-half, -half, z),
            DVec3::new(half, -half, z),
            DVec3::new(half, half, z),
            DVec3::new(-half, half, z),
        ]
    }

    #[test]
    fn a_triangle_is_tested_by_its_own_pixels_not_its_box() {
        // A right triangle in front covers the half x + y ≤ 0 of its square; a smaller one
        // behind projects inside it, but the corner of its box does not.
        let front = vec![
            DVec3::new(-1.0, -1.0, 2.0),
            DVec3::new(1.0, -1.0, 2.0),
            DVec3::new(-1.0, 1.0, 2.0),
        ];
        let occ = SampleOccluders::from_polygons(&[(front, 0)]);
        let tri = [
            DVec3::new(-0.5, -0.5, 5.0),
            DVec3::new(0.1, -0.5, 5.0),
            DVec3::new(-0.5, 0.1, 5.0),
        ];
        // The same triangle turned to the other half, and one nearer than the occluder.
        let across = tri.map(|p| DVec3::new(-p.x, -p.y, p.z));
        let nearer = tri.map(|p| DVec3::new(p.x * 0.2, p.y * 0.2, 1.0));
        let bx = DAabb {
            min: DVec3::new(-0.5, -0.5, 1.0),
            max: DVec3::new(0.5, 0.5, 5.0),
        };
        for res in [128, 256] {
            let mut hc = Hemicube::new(res);
            hc.begin(DVec3::ZERO, 2, 1.0, 0.01, &[bx]);
            hc.draw(&occ);
            let tri_box = DAabb {
                min: tri[0].min(tri[1]).min(tri[2]),
                max: tri[0].max(tri[1]).max(tri[2]),
            };
            assert!(matches!(hc.test_box(&tri_box), BoxTest::Open { .. }));
            assert_eq!(hc.test_triangle(tri), BoxTest::Hidden, "res {res}");
            assert!(matches!(hc.test_triangle(across), BoxTest::Open { .. }));
            assert!(matches!(hc.test_triangle(nearer), BoxTest::Open { .. }));
        }
    }

    #[test]
    fn segments_found_hidden_lie_beyond_what_was_drawn_at_every_point() {
        // Random leaves between 1.5 and 4 in front of the eye, partly covering the view.
        let mut r = uniform(0x5E6);
        let mut polys = Vec::new();
        for k in 0..400 {
            let c = DVec3::new(r() * 1.5, r() * 1.5, 2.75 + 1.25 * r());
            let (e1, e2) = (
                DVec3::new(r(), r(), 0.3 * r()).normalize() * 0.4,
                DVec3::new(r(), r(), 0.3 * r()).normalize() * 0.4,
            );
            polys.push((vec![c - e1, c + e2, c + e1], k));
        }
        let occ = SampleOccluders::from_polygons(&polys);
        let far = DAabb {
            min: DVec3::new(-3.0, -3.0, 1.0),
            max: DVec3::new(3.0, 3.0, 9.0),
        };
        let mut hc = Hemicube::new(64);
        let mut ts = Vec::new();
        let (mut hidden, mut open) = (0, 0);
        for tuck in [false, true] {
            hc.set_tuck(tuck);
            hc.begin(DVec3::ZERO, 2, 1.0, 0.02, &[far]);
            hc.draw(&occ);
            for _ in 0..3000 {
                let a = DVec3::new(r() * 1.2, r() * 1.2, 4.5 + 2.0 * r());
                let b = a + DVec3::new(r(), r(), r()) * 0.3;
                if !hc.segment_hidden(a, b, &mut ts) {
                    open += 1;
                    continue;
                }
                hidden += 1;
                assert_eq!(hc.test_triangle([a, b, b]), BoxTest::Hidden, "{a} {b}");
                // Every point of it lies in a sub-pixel covered strictly nearer than itself.
                for k in 0..=400 {
                    let p = a + (b - a) * (k as f64 / 400.0);
                    let v = &hc.views[0];
                    let half = hc.res as f64 / 2.0;
                    let (u, w) = ((p.x / p.z + 1.0) * half, (p.y / p.z + 1.0) * half);
                    let (i, j) = (u.floor() as usize, w.floor() as usize);
                    let idx = j * hc.res + i;
                    let bit =
                        1u64 << (8 * ((w - j as f64) * 8.0) as u32 + ((u - i as f64) * 8.0) as u32);
                    let z = p.z as f32;
                    assert!(
                        v.depth[idx] < z || v.layers(idx).any(|(m, wz)| m & bit != 0 && wz < z),
                        "point {p} of the segment {a} {b} is not covered nearer"
                    );
                }
            }
        }
        assert!(hidden > 300 && open > 300, "hidden {hidden}, open {open}");
    }

    /// A leaf whose edge lies under a nearer leaf: with the tuck pass that edge is drawn
    /// unshrunk, and a box seen just inside it, which the shrinks left open, is hidden.
    #[test]
    fn the_tuck_pass_fuses_a_leaf_across_an_edge_a_nearer_leaf_covers() {
        // Seen from the eye (x/z): the far leaf (depth 4) spans up to 0.3, shrunk to about
        // 0.22 at ε 0.4; the near leaf (depth 2) starts at 0.05, shrunk to about 0.25 (more
        // away from the centre), and covers the far leaf's edge at 0.3 (y/z within ±0.25).
        // The box lies in the gap, 0.24–0.255.
        let far_leaf = vec![
            DVec3::new(-3.0, -1.0, 4.0),
            DVec3::new(1.2, -1.0, 4.0),
            DVec3::new(1.2, 1.0, 4.0),
            DVec3::new(-3.0, 1.0, 4.0),
        ];
        let near_leaf = vec![
            DVec3::new(0.1, -1.6, 2.0),
            DVec3::new(1.6, -1.6, 2.0),
            DVec3::new(1.6, 1.6, 2.0),
            DVec3::new(0.1, 1.6, 2.0),
        ];
        let occ = SampleOccluders::from_polygons(&[(far_leaf, 0), (near_leaf, 1)]);
        let bx = DAabb {
            min: DVec3::new(2.4, -0.1, 10.0),
            max: DVec3::new(2.55, 0.1, 10.0),
        };
        // Only the pixels the boxes given to `begin` reach are drawn and tested: a wide box
        // behind takes in the far leaf's edge.
        let wide = DAabb {
            min: DVec3::new(0.0, -6.0, 10.0),
            max: DVec3::new(5.0, 6.0, 10.0),
        };
        let mut hc = Hemicube::new(512);
        let mut run = |tuck: bool| {
            hc.set_tuck(tuck);
            hc.begin(DVec3::ZERO, 2, 1.0, 0.4, &[bx, wide]);
            let st = hc.draw(&occ);
            (hc.test_box(&bx), st.tucked)
        };
        let (without, none) = run(false);
        assert!(matches!(without, BoxTest::Open { .. }), "{without:?}");
        assert_eq!(none, 0);
        let (with, tucked) = run(true);
        assert_eq!(with, BoxTest::Hidden);
        assert_eq!(tucked, 1, "only the far leaf has a covered edge");
        // The near leaf is drawn first (nearest first); had the far leaf come first, its
        // edge would have had nothing drawn to tuck under.
    }

    #[test]
    fn a_wall_hides_a_box_behind_it_and_not_one_beside_it() {
        let occ = SampleOccluders::from_polygons(&[(wall(2.0, 3.0), 0)]);
        let behind = DAabb {
            min: DVec3::new(-0.5, -0.5, 5.0),
            max: DVec3::new(0.5, 0.5, 6.0),
        };
        let beside = DAabb {
            min: DVec3::new(10.0, -0.5, 5.0),
            max: DVec3::new(11.0, 0.5, 6.0),
        };
        let mut hc = Hemicube::new(64);
        hc.begin(DVec3::ZERO, 2, 1.0, 0.1, &[behind, beside]);
        let st = hc.draw(&occ);
        assert_eq!(st.polygons, 1);
        assert_eq!(hc.test_box(&behind), BoxTest::Hidden);
        assert!(matches!(hc.test_box(&beside), BoxTest::Open { .. }));
    }
}

#[cfg(test)]
mod depth_tests {
    use super::*;
    use crate::sampler::SampleOccluders;

    /// A ground far wider than deep: its farthest vertex is 50 away, but below the eye it is
    /// 1 away, and a box under it is hidden there only with the per-pixel plane depth.
    #[test]
    fn a_large_ground_hides_what_lies_under_it_near_the_eye() {
        let ground = vec![
            DVec3::new(-50.0, 0.0, -50.0),
            DVec3::new(50.0, 0.0, -50.0),
            DVec3::new(50.0, 0.0, 50.0),
            DVec3::new(-50.0, 0.0, 50.0),
        ];
        let occ = SampleOccluders::from_polygons(&[(ground, 0)]);
        let under = DAabb {
            min: DVec3::new(-0.2, -3.0, -0.2),
            max: DVec3::new(0.2, -2.0, 0.2),
        };
        let above = DAabb {
            min: DVec3::new(3.0, 0.2, -0.2),
            max: DVec3::new(3.4, 0.5, 0.2),
        };
        let mut hc = Hemicube::new(64);
        // The eye 1 above the ground on a face looking down (−y).
        hc.begin(DVec3::new(0.0, 1.0, 0.0), 1, -1.0, 0.05, &[under, above]);
        hc.draw(&occ);
        assert_eq!(hc.test_box(&under), BoxTest::Hidden);
        assert!(matches!(hc.test_box(&above), BoxTest::Open { .. }));
    }

    /// With the rectangle of the face instead of the ball around it, an edge along the face
    /// shrinks less: a box just hidden behind a slit-free pair of walls meeting at a seam
    /// parallel to the face is hidden for the rectangle but not for the ball.
    #[test]
    fn a_rectangle_shrinks_edges_along_the_face_less_than_its_ball() {
        // Two walls overlapping by 0.16 at z = 2 (seen from the eye: a seam along x).
        let w1 = vec![
            DVec3::new(-3.0, -3.0, 2.0),
            DVec3::new(3.0, -3.0, 2.0),
            DVec3::new(3.0, 0.08, 2.0),
            DVec3::new(-3.0, 0.08, 2.0),
        ];
        let w2 = vec![
            DVec3::new(-3.0, -0.08, 2.1),
            DVec3::new(3.0, -0.08, 2.1),
            DVec3::new(3.0, 3.0, 2.1),
            DVec3::new(-3.0, 3.0, 2.1),
        ];
        let occ = SampleOccluders::from_polygons(&[(w1, 0), (w2, 0)]);
        let target = DAabb {
            min: DVec3::new(-0.3, -0.3, 6.0),
            max: DVec3::new(0.3, 0.3, 6.5),
        };
        // A rectangle 0.04 along y (across the seam) and 0.2 along x (along it).
        let (hx, hy) = (0.1, 0.02);
        let mut hc = Hemicube::new(256);
        // Shrinks for occludees at any distance: the bound would close the ball's seam too.
        hc.set_depth_bounded(false);
        hc.begin_patch(DVec3::ZERO, 2, 1.0, [hx, hy], &[target]);
        hc.draw(&occ);
        assert_eq!(hc.test_box(&target), BoxTest::Hidden, "rectangle");
        hc.begin(DVec3::ZERO, 2, 1.0, hx.hypot(hy), &[target]);
        hc.draw(&occ);
        assert!(
            matches!(hc.test_box(&target), BoxTest::Open { .. }),
            "the ball of radius {} shrinks the seam open",
            hx.hypot(hy)
        );
    }

    /// An edge seen low over the face's plane, across the line of sight, barely moves as the
    /// eye moves within the face: the plane through the eye and the edge is nearly the
    /// face's, so the rectangle's support across it is small ([`edge_reach`]). Two walls
    /// 5 units out along x, just above the face's plane (z = 0), overlap by 0.1 at a seam
    /// along y: a square of half side 0.1 (its extent along the seam's edges is its full
    /// 0.1, which shrinks each edge by 0.02 rad and opens the 0.02 rad overlap) still hides a
    /// box behind the seam.
    #[test]
    fn an_edge_seen_low_over_the_face_shrinks_by_the_rectangles_support_across_it() {
        let low = vec![
            DVec3::new(5.0, -3.0, 0.01),
            DVec3::new(5.0, 3.0, 0.01),
            DVec3::new(5.0, 3.0, 0.35),
            DVec3::new(5.0, -3.0, 0.35),
        ];
        let high = vec![
            DVec3::new(5.1, -3.0, 0.25),
            DVec3::new(5.1, 3.0, 0.25),
            DVec3::new(5.1, 3.0, 2.0),
            DVec3::new(5.1, -3.0, 2.0),
        ];
        let occ = SampleOccluders::from_polygons(&[(low, 0), (high, 0)]);
        let target = DAabb {
            min: DVec3::new(8.0, -0.3, 0.35),
            max: DVec3::new(8.5, 0.3, 0.6),
        };
        let half = [0.1, 0.1];
        let mut hc = Hemicube::new(256);
        hc.set_depth_bounded(false);
        hc.begin_patch(DVec3::ZERO, 2, 1.0, half, &[target]);
        hc.draw(&occ);
        assert_eq!(
            hc.test_box(&target),
            BoxTest::Hidden,
            "the rectangle's support"
        );
        // The seam's edges as the extent bound shrinks them: the overlap opens.
        let (m, t) = (DVec3::new(0.35, 0.0, -5.0).normalize(), DVec3::Y);
        let r = DVec3::new(5.0, 0.0, 0.35).length();
        let tight = edge_reach(0.1, half, m, t, r, 0, 1);
        assert!(tight < 0.1 * 0.1, "support across the seam {tight}");
        assert!(
            (0.1f64 / r).asin() > 0.02 - 1e-3,
            "the extent's shrink closes the overlap"
        );
        // Seen head-on (the edge along y at height 5, its plane through the eye across the
        // face), the bound is about the extent's.
        let head_on = edge_reach(0.1, half, DVec3::X, DVec3::Y, 5.0, 0, 1);
        assert!(head_on <= 0.1 && head_on > 0.0999, "{head_on}");
    }
}
