//! The per-rectangle occlusion sweep (`--sampling-fusion sweep`): Durand et al. 2000's
//! extended projections and occlusion sweep with a face rectangle of the sampler as the
//! "cell". Leaves are not shrunk one by one for the whole rectangle's parallax; each is shrunk
//! only for the parallax between itself and a plane just behind it, the leaves' union is
//! formed there, and only the union is eroded as the sweep moves away from the eye. Leaves
//! that fuse seam to seam stay fused at any ε, so a rectangle many times larger hides what
//! the shrinking renderer ([`super::Hemicube`]) hides only with far smaller ones.
//!
//! # Why it is conservative
//!
//! Fix one of the five views of the hemicube (axes `X, Y` across, `Z` the view's depth, all
//! relative to the rectangle's centre) and the rectangle `R` (its four corners `p_i`; every
//! point of `R` has `|Z| ≤ ε`). For a plane `Π_r` (`Z = r`) call a point `Q` of it *blocked*
//! when for every `p ∈ R` the segment from `p` to `Q` meets an occluder polygon at a depth
//! `≤ r`; write `ψ = (Q_X, Q_Y) / r` (for `r = ∞`, `Q` is a direction and `ψ` its `(X, Y)/Z`).
//!
//! 1. **A polygon's extended projection.** For a convex polygon `L` with every vertex deeper
//!    than every corner (`Z > max Z(p_i)`) and not deeper than `r`, the points of `Π_r` whose
//!    segment from `p` meets `L` form the central projection of `L` from `p` onto `Π_r`, a
//!    convex polygon. For a fixed `Q` the set of `p` (in `R`'s plane) whose line to `Q` meets
//!    `L` is the projection of `L` from `Q` onto that plane, convex as `L` lies on one side of
//!    the plane through `Q` parallel to it; so it holds all of `R` as soon as it holds the four
//!    corners. Hence the points blocked by `L` alone are the intersection of the four corners'
//!    projections (the extended projection), computed exactly by clipping. A sub-pixel is
//!    set only when its square lies inside (inner-conservative).
//! 2. **The sweep.** If `Q'` on `Π_{r'}` (`r' > r`) is such that, for every `p ∈ R`, the
//!    segment `p Q'` crosses `Π_r` at a blocked point, `Q'` is blocked. Where that crossing
//!    lies relative to `ψ'` moves, over `p ∈ R` and `ψ'` in the view, by at most `Δ` along
//!    each axis (found at the corners of `R` and of the view, where the crossing's offset,
//!    affine in `ψ'` and monotone in each of `p`'s coordinates, is extreme). So eroding the
//!    blocked bitmap of `Π_r` by `⌈Δ / sub-pixel⌉` sub-pixels per axis and reading it on
//!    `Π_{r'}` keeps only blocked points. The bound holds over any part of the view with
//!    `ψ'` ranging over that part's corners instead: the bitmap is cut into tiles (whole
//!    sub-pixels), and each tile's sub-pixels are eroded by the bound over that tile (they
//!    read their neighbours in any tile). In the side views, where `R` spans depth, the
//!    offset grows with `|ψ'|`, and the tiles near the view's axis erode by far less than its
//!    edge needs. The sweep draws the polygons in order of their
//!    farthest depth, each into the plane of the first slab end not nearer than it (1.), and
//!    erodes when it passes a slab end (2.); the union of what is blocked is blocked.
//! 3. **Occludees.** An occludee (box, piece box or triangle) whose nearest depth in the view
//!    is `t₀` is tested once every polygon whose farthest depth is below `t₀ / (1 + 10⁻⁹)` is
//!    drawn and no other (a point of it may lie on a polygon as deep as it), on the
//!    plane of the slab then current, `Π_r`. The segment from `p ∈ R` to a point `x` of it
//!    (whose direction from `p` lies in this view) crosses `Π_r` (before or after `x`) at the
//!    point that the projection of `x` from `p` gives; over `R` and the occludee these lie in
//!    the bounding box of the projections of its vertices from the four corners (projection
//!    from a point is projective on each of the two convex sets). If every sub-pixel that box
//!    touches is set, the line from `p` through `x` meets a polygon at a depth `< t₀ ≤ Z(x)`,
//!    so strictly between `p` and `x`. Points of the occludee within `2ε` of `R`'s plane are clipped
//!    off: their directions from `R` lie in no view's frustum once the occludee is farther
//!    than `8ε` from the centre (nearer occludees are left visible), and the bitmap spans the
//!    view's square widened by `2ε / r_min`, which holds every crossing of a segment whose
//!    direction from its `p` lies in the view.
//! 4. **Outside the bitmap.** Each view only answers for segments whose direction from their
//!    `p` lies in its frustum `F`; so "blocked" in 1.–3. need only hold for the `p` with
//!    `dir(p → Q) ∈ F`. A crossing of such a segment lies inside the bitmap on every plane
//!    (it has the segment's direction), so points outside the bitmap concern no such segment
//!    and the erosion counts them as set: the bitmap's edge does not eat into it.
//! 5. **Views.** The five views' frustums, seen from any `p`, cover the outward hemisphere, so
//!    an occludee hidden in every view it reaches is hidden from every point of `R`; with the
//!    boundary argument of the parent module, from the cell.
//!
//! Every rounding errs toward "not blocked": sub-pixels are set only with a margin inside the
//! extended projection, erosions are rounded up, occludee boxes rounded out; polygons whose
//! four projections do not share an orientation (their plane passes between the corners) or
//! come too near the eye are left out.

use super::{SampleOccluders, view_coords, view_maps};
use crate::geom::DAabb;
use glam::{DVec2, DVec3};
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Sub-pixels per pixel side.
const SUB: usize = 8;
/// Erosion tiles: this many 64-bit words across (512 sub-pixels) and [`TILE_ROWS`] rows
/// up; each tile erodes by the parallax bound over its own part of the view.
const TILE_WORDS: usize = 4;
/// Rows of an erosion tile.
const TILE_ROWS: usize = 256;
/// Near the eye, each slab ends at least this many times farther than it starts (a polygon
/// is shrunk for the parallax between it and its slab's end, a fraction of its distance;
/// every slab's erosion rounds up, by up to a sub-pixel per tile). On the fine forest's 1×1×1
/// cell (`examples/sweep_bench.rs`, 6 rectangles at ε 0.125, 512 px) 1.05 hid 26,414 of
/// 30,090 objects in 1.08 s per render, 1.1 26,574 in 0.99 s, 1.2 26,633 in 0.76 s, 1.35
/// 26,462, 1.6 25,776, 2 24,520; at ε 0.0625 and 0.25, 1.2 also hid more than 1.05 in 0.56
/// and 0.67 of its time.
const SLAB_RATIO: f64 = 1.2;
/// Relative margin of the sub-pixel tests against rounding (far above the `f64` error of the
/// projections and clips, far below a sub-pixel).
const MARGIN: f64 = 1e-9;

/// The occludees of one render, as [`RectSweep::render`] tests them: an object is hidden
/// when its box is, or when it has pieces and each piece's box is or all of the piece's
/// triangles are (each tested when the sweep reaches its own nearest depth). Scene
/// coordinates.
pub trait Occludees {
    /// How many objects.
    fn len(&self) -> usize;
    /// Whether there are none.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Object `i`'s box.
    fn object_box(&self, i: usize) -> DAabb;
    /// Object `i`'s pieces (indices for [`Occludees::piece_box`]); none: only its box.
    fn pieces(&self, i: usize) -> std::ops::Range<u32>;
    /// Piece `k`'s box.
    fn piece_box(&self, k: u32) -> DAabb;
    /// Piece `k`'s triangles (indices for [`Occludees::triangle`]).
    fn piece_triangles(&self, k: u32) -> &[u32];
    /// Triangle `t`'s corners.
    fn triangle(&self, t: u32) -> [DVec3; 3];
}

/// Counts of one [`RectSweep::render`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SweepStats {
    /// Polygons drawn (their extended projections rasterised).
    pub polygons: u64,
    /// BVH nodes visited.
    pub nodes: u64,
    /// Erosion steps over all views.
    pub erosions: u64,
}

/// Buffers of [`SweepView::erode_tiles`], kept between erosions.
#[derive(Default)]
struct ErodeScratch {
    /// The rows eroded across.
    words: Vec<u64>,
    /// Per row and tile: how many rows up to it (within the set rows) are full there.
    runs: Vec<u32>,
    /// Per row and tile: whether it is clear.
    zero: Vec<bool>,
    /// Rows as they were before the erosion rewrote them (for the next tile row).
    saved: Vec<u64>,
}

/// One view's blocked bitmap and geometry.
struct SweepView {
    map: [(usize, f64); 3],
    /// Lowest `u`, `v` of the bitmap (the view's square widened by the margin).
    u0: f64,
    v0: f64,
    /// Sub-pixels across and up, words per row.
    nu: usize,
    nv: usize,
    w: usize,
    bits: Vec<u64>,
    /// Rows that may hold set bits: `[j_lo, j_hi)`.
    rows: [usize; 2],
}

/// The rectangle and view of one render, as the tests need them.
#[derive(Clone, Copy)]
struct Frame {
    /// The corners of the rectangle in the view's coordinates.
    corners: [DVec3; 4],
    /// Current slab end (the blocked plane), `f64::INFINITY` for directions.
    r: f64,
    /// Sub-pixel size.
    s: f64,
    /// Nearest depth an occluder or occludee point may have in this view.
    zmin: f64,
}

impl Frame {
    /// `q` (view coordinates) projected from corner `c` onto the current plane, as `ψ`.
    #[inline]
    fn project(&self, c: DVec3, q: DVec3) -> DVec2 {
        let d = q - c;
        let dz = d.z;
        if self.r.is_finite() {
            let k = (self.r - c.z) / dz;
            (DVec2::new(c.x, c.y) + DVec2::new(d.x, d.y) * k) / self.r
        } else {
            DVec2::new(d.x, d.y) / dz
        }
    }
}

/// The per-rectangle occlusion sweep renderer (module docs). One per thread; reused between
/// renders.
pub struct RectSweep {
    res: usize,
    start_per_eps: f64,
    views: Vec<SweepView>,
    heap: BinaryHeap<Ev>,
    scratch: ErodeScratch,
    poly: PolyScratch,
}

/// A sweep event, ordered by depth, then kind (nodes, tests, polygons).
#[derive(Clone, Copy, Debug)]
struct Ev {
    z: f64,
    kind: u8,
    id: u32,
}

impl PartialEq for Ev {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Ev {}
impl PartialOrd for Ev {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Ev {
    fn cmp(&self, o: &Self) -> Ordering {
        // A max-heap: reversed, nearest first.
        o.z.total_cmp(&self.z)
            .then(o.kind.cmp(&self.kind))
            .then(o.id.cmp(&self.id))
    }
}

// At one depth: nodes, then tests, then polygons (a polygon as deep as an occludee's nearest
// point does not hide it: that point may lie on the polygon).
const EV_NODE: u8 = 0;
const EV_OBJECT: u8 = 1;
const EV_PIECE: u8 = 2;
const EV_TRIANGLE: u8 = 3;
const EV_POLY: u8 = 4;
/// A polygon is drawn after the tests of occludees no deeper than this many times its
/// farthest depth: it hides only what lies strictly behind it, by more than rounding.
const DEPTH_MARGIN: f64 = 1.0 + 1e-9;

/// The current view and plane of a sweep, as its occludee tests read them: a box, piece box
/// or triangle is blocked when the bitmap holds every sub-pixel its projections touch.
pub struct SweepProbe<'a> {
    view: &'a SweepView,
    frame: Frame,
}

impl SweepProbe<'_> {
    /// Whether the box `bx` (scene coordinates relative to the rectangle's centre) is
    /// blocked in this view (clipped to the view's near depth).
    pub fn box_blocked(&self, bx: &DAabb) -> bool {
        let m = self.view.map;
        let mut lo = view_coords(m, bx.min);
        let mut hi = view_coords(m, bx.max);
        (lo, hi) = (lo.min(hi), lo.max(hi));
        if hi.z < self.frame.zmin {
            return true;
        }
        lo.z = lo.z.max(self.frame.zmin);
        // Back to scene coordinates is not needed: corners in view coordinates directly.
        let f = &self.frame;
        let (mut a, mut b) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        for k in 0..8 {
            let q = DVec3::new(
                if k & 1 == 0 { lo.x } else { hi.x },
                if k & 2 == 0 { lo.y } else { hi.y },
                if k & 4 == 0 { lo.z } else { hi.z },
            );
            for c in f.corners {
                let p = f.project(c, q);
                a = a.min(p);
                b = b.max(p);
            }
        }
        self.view.rect_set(a, b, f.s)
    }

    /// Whether the triangle `tri` (scene coordinates relative to the rectangle's centre) is
    /// blocked in this view (clipped to the view's near depth).
    pub fn triangle_blocked(&self, tri: [DVec3; 3]) -> bool {
        let m = self.view.map;
        let v = tri.map(|q| view_coords(m, q));
        let zmin = self.frame.zmin;
        if v.iter().all(|q| q.z >= zmin) {
            return self.view_hull_blocked(&v);
        }
        // Clip at Z = zmin.
        let mut out: Vec<DVec3> = Vec::with_capacity(4);
        for k in 0..3 {
            let (a, b) = (v[k], v[(k + 1) % 3]);
            if a.z >= zmin {
                out.push(a);
            }
            if (a.z >= zmin) != (b.z >= zmin) {
                let t = (zmin - a.z) / (b.z - a.z);
                let mut q = a + (b - a) * t;
                q.z = zmin;
                out.push(q);
            }
        }
        if out.is_empty() {
            return true;
        }
        self.view_hull_blocked(&out)
    }

    /// The nearest depth in this view of the triangle `tri` (relative to the rectangle's
    /// centre), at least the view's near depth; None when it lies wholly nearer.
    pub fn triangle_near(&self, tri: &[DVec3; 3]) -> Option<f64> {
        let z = tri.map(|q| view_coords(self.view.map, q).z);
        let zmin = self.frame.zmin;
        (z.iter().any(|&z| z >= zmin))
            .then(|| z.iter().copied().fold(f64::INFINITY, f64::min).max(zmin))
    }

    /// The bounding box of the projections of `v` (view coordinates) onto the current plane
    /// from the four corners: blocked when every sub-pixel it touches is set.
    fn view_hull_blocked(&self, v: &[DVec3]) -> bool {
        let f = &self.frame;
        let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        for &q in v {
            for c in f.corners {
                let p = f.project(c, q);
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
        self.view.rect_set(lo, hi, f.s)
    }
}

impl SweepView {
    /// Whether every sub-pixel that the rectangle `[lo, hi]` (in `ψ`) touches within the
    /// bitmap is set (true when it touches none).
    fn rect_set(&self, lo: DVec2, hi: DVec2, s: f64) -> bool {
        let m = MARGIN;
        let fi = |x: f64, o: f64| ((x - o) / s).floor();
        let i0 = fi(lo.x - m, self.u0).max(0.0);
        let i1 = fi(hi.x + m, self.u0).min(self.nu as f64 - 1.0);
        let j0 = fi(lo.y - m, self.v0).max(0.0);
        let j1 = fi(hi.y + m, self.v0).min(self.nv as f64 - 1.0);
        if !(i0 <= i1 && j0 <= j1) {
            // Outside the bitmap, or NaN: NaN must not pass.
            return !(lo.is_nan() || hi.is_nan());
        }
        let (i0, i1, j0, j1) = (i0 as usize, i1 as usize, j0 as usize, j1 as usize);
        if j0 < self.rows[0] || j1 >= self.rows[1] {
            return false;
        }
        let (w0, w1) = (i0 / 64, i1 / 64);
        for j in j0..=j1 {
            let row = &self.bits[j * self.w..(j + 1) * self.w];
            for (wi, &word) in row.iter().enumerate().take(w1 + 1).skip(w0) {
                let a = if wi == w0 { i0 % 64 } else { 0 };
                let b = if wi == w1 { i1 % 64 } else { 63 };
                let mask = (u64::MAX >> (63 - b)) & (u64::MAX << a);
                if word & mask != mask {
                    return false;
                }
            }
        }
        true
    }

    /// Sets the sub-pixels whose squares lie inside the convex counter-clockwise polygon `p`.
    fn fill(&mut self, p: &[DVec2], s: f64) {
        let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
        for q in p {
            y0 = y0.min(q.y);
            y1 = y1.max(q.y);
        }
        let ja = ((y0 - self.v0) / s).ceil().max(0.0);
        let jb = ((y1 - self.v0) / s).floor().min(self.nv as f64);
        if ja.partial_cmp(&jb) != Some(Ordering::Less) {
            return;
        }
        let span = |y: f64| -> Option<(f64, f64)> {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for k in 0..p.len() {
                let (c, d) = (p[k], p[(k + 1) % p.len()]);
                if (c.y <= y) != (d.y <= y) {
                    let x = c.x + (d.x - c.x) * ((y - c.y) / (d.y - c.y));
                    lo = lo.min(x);
                    hi = hi.max(x);
                }
            }
            (lo < hi).then_some((lo, hi))
        };
        let m = MARGIN;
        // The span at each row's lower edge is the one below's upper edge.
        let mut below = span(self.v0 + ja * s);
        for j in ja as usize..jb as usize {
            let yb = self.v0 + (j + 1) as f64 * s;
            let above = span(yb);
            let (Some(a), Some(b)) = (std::mem::replace(&mut below, above), above) else {
                continue;
            };
            let lo = a.0.max(b.0) + m;
            let hi = a.1.min(b.1) - m;
            let ia = ((lo - self.u0) / s).ceil().max(0.0);
            let ib = ((hi - self.u0) / s).floor().min(self.nu as f64);
            if ia.partial_cmp(&ib) != Some(Ordering::Less) {
                continue;
            }
            let (ia, ib) = (ia as usize, ib as usize - 1);
            let row = &mut self.bits[j * self.w..(j + 1) * self.w];
            let (w0, w1) = (ia / 64, ib / 64);
            for (wi, word) in row.iter_mut().enumerate().take(w1 + 1).skip(w0) {
                let a = if wi == w0 { ia % 64 } else { 0 };
                let b = if wi == w1 { ib % 64 } else { 63 };
                *word |= (u64::MAX >> (63 - b)) & (u64::MAX << a);
            }
            self.rows[0] = self.rows[0].min(j);
            self.rows[1] = self.rows[1].max(j + 1);
        }
    }

    /// Keeps a sub-pixel only where every sub-pixel within its tile's radii (`radii[t]`,
    /// across and up, for tile `t` of [`TILE_WORDS`] words by [`TILE_ROWS`] rows, row-major)
    /// is set. Tile row by tile row: the rows it reaches are eroded across with its radii into
    /// a scratch (from the bitmap as it was: the rows an earlier tile row rewrote are read from
    /// a copy), then up and down into the bitmap. Every radius across must be below 64 and
    /// every radius up below [`TILE_ROWS`] ([`SweepView::erode`] takes the rest).
    fn erode_tiles(&mut self, radii: &[(usize, usize)], scratch: &mut ErodeScratch) {
        let [r0, r1] = self.rows;
        if r0 >= r1 {
            return;
        }
        let (w, nv) = (self.w, self.nv);
        let tw = w.div_ceil(TILE_WORDS);
        let ErodeScratch {
            words,
            runs,
            zero,
            saved,
        } = scratch;
        let ev_max = |tr: usize| radii[tr * tw..(tr + 1) * tw].iter().map(|r| r.1).max();
        // Rows [saved_from, ra) as they were before this erosion.
        saved.clear();
        let mut saved_from = r0;
        let (mut lo, mut hi) = (usize::MAX, 0);
        let (tr0, tr1) = (r0 / TILE_ROWS, (r1 - 1) / TILE_ROWS);
        for tr in tr0..=tr1 {
            let (ra, rb) = ((tr * TILE_ROWS).max(r0), ((tr + 1) * TILE_ROWS).min(r1));
            let trow = &radii[tr * tw..(tr + 1) * tw];
            let reach = ev_max(tr).unwrap_or(0);
            let (ha, hb) = (ra.saturating_sub(reach).max(r0), (rb + reach).min(r1));
            debug_assert!(ha >= saved_from, "radii up must stay below TILE_ROWS");
            words.clear();
            words.resize((hb - ha) * w, 0);
            runs.clear();
            runs.resize((hb - ha) * tw, 0);
            zero.clear();
            zero.resize((hb - ha) * tw, true);
            // Across: bit i kept only if bits i - eu ..= i + eu are set (outside counts as
            // set). Per row and tile: whether the result is clear, and how many rows up to
            // this one it is full in.
            for jj in ha..hb {
                let row = if jj < ra {
                    &saved[(jj - saved_from) * w..(jj - saved_from + 1) * w]
                } else {
                    &self.bits[jj * w..(jj + 1) * w]
                };
                let out = &mut words[(jj - ha) * w..(jj - ha + 1) * w];
                for (t, &(e, _)) in trow.iter().enumerate() {
                    let (mut all, mut any) = (u64::MAX, 0u64);
                    for x in t * TILE_WORDS..((t + 1) * TILE_WORDS).min(w) {
                        let cur = row[x];
                        if cur == 0 {
                            all = 0;
                            continue;
                        }
                        let prev = if x > 0 { row[x - 1] } else { u64::MAX };
                        let next = if x + 1 < w { row[x + 1] } else { u64::MAX };
                        let o = if e == 0 || (cur & prev & next) == u64::MAX {
                            cur
                        } else {
                            erode_word(prev, cur, next, e)
                        };
                        out[x] = o;
                        all &= o;
                        any |= o;
                    }
                    let at = (jj - ha) * tw + t;
                    zero[at] = any == 0;
                    if all == u64::MAX {
                        runs[at] = if jj > ha { runs[at - tw] + 1 } else { 1 };
                    }
                }
            }
            // Keep the rows the next tile row reads before they are rewritten: they lie in
            // this tile row, as radii up are below a tile's height (or this one starts at r0).
            if tr < tr1 {
                saved_from = rb.saturating_sub(ev_max(tr + 1).unwrap_or(0)).max(ra);
                saved.clear();
                saved.extend_from_slice(&self.bits[saved_from * w..rb * w]);
            }
            // Up and down: row j kept where rows j - ev ..= j + ev are (rows outside the
            // bitmap count as set, rows of it outside `rows` are clear). A tile row full in
            // all of them stays full; one clear in its own row, or with a clear row in reach,
            // is cleared.
            for j in ra..rb {
                let mut any = 0u64;
                for (t, &(_, ev)) in trow.iter().enumerate() {
                    let (xa, xb) = (t * TILE_WORDS, ((t + 1) * TILE_WORDS).min(w));
                    let out = &mut self.bits[j * w + xa..j * w + xb];
                    let (ja, jb) = (j.saturating_sub(ev), (j + ev).min(nv - 1));
                    if ja < r0 || jb >= r1 || zero[(j - ha) * tw + t] {
                        out.fill(0);
                        continue;
                    }
                    if runs[(jb - ha) * tw + t] as usize > jb - ja {
                        // Full in every row within reach, so it was full and stays so.
                        any = u64::MAX;
                        continue;
                    }
                    out.copy_from_slice(&words[(j - ha) * w + xa..(j - ha) * w + xb]);
                    for jj in ja..=jb {
                        if jj == j {
                            continue;
                        }
                        let src = &words[(jj - ha) * w + xa..(jj - ha) * w + xb];
                        for (o, &v) in out.iter_mut().zip(src) {
                            *o &= v;
                        }
                    }
                    any |= out.iter().fold(0, |a, &v| a | v);
                }
                if any != 0 {
                    lo = lo.min(j);
                    hi = j + 1;
                }
            }
        }
        self.rows = if lo < hi { [lo, hi] } else { [0, 0] };
    }

    /// Keeps a sub-pixel only where every sub-pixel within `eu` across and `ev` up is set:
    /// passes of the three-point sets `{−d, 0, d}` for `d = 1, 2, 4, …` and one for the rest
    /// (their Minkowski sum is the whole range).
    fn erode(&mut self, eu: usize, ev: usize, scratch: &mut Vec<u64>) {
        let [r0, r1] = self.rows;
        if r0 >= r1 {
            return;
        }
        for d in radii(eu) {
            self.erode_across(d);
        }
        for d in radii(ev) {
            self.erode_up(d, scratch);
            if self.rows[0] >= self.rows[1] {
                return;
            }
        }
    }

    /// One pass across: bit `i` kept only if bits `i − d` and `i + d` are set too.
    fn erode_across(&mut self, d: usize) {
        let w = self.w;
        let (q, b) = (d / 64, (d % 64) as u32);
        let [r0, r1] = self.rows;
        let mut out = vec![0u64; w];
        for j in r0..r1 {
            let row = &mut self.bits[j * w..(j + 1) * w];
            // Outside the bitmap counts as set (module docs, 3.).
            let get = |x: isize| -> u64 {
                if x < 0 || x >= w as isize {
                    u64::MAX
                } else {
                    row[x as usize]
                }
            };
            for (x, o) in out.iter_mut().enumerate() {
                let x = x as isize;
                let q = q as isize;
                // Bit i of `lo` is bit i − d of the row; of `hi`, bit i + d.
                let (lo, hi) = if b == 0 {
                    (get(x - q), get(x + q))
                } else {
                    (
                        (get(x - q) << b) | (get(x - q - 1) >> (64 - b)),
                        (get(x + q) >> b) | (get(x + q + 1) << (64 - b)),
                    )
                };
                *o = row[x as usize] & lo & hi;
            }
            row.copy_from_slice(&out);
        }
    }

    /// One pass up and down: row `j` kept only where rows `j − d` and `j + d` are set (rows
    /// outside the bitmap count as set, rows of it outside `rows` are clear).
    fn erode_up(&mut self, d: usize, scratch: &mut Vec<u64>) {
        let w = self.w;
        let [r0, r1] = self.rows;
        let nv = self.nv;
        scratch.clear();
        scratch.extend_from_slice(&self.bits[r0 * w..r1 * w]);
        let (mut lo, mut hi) = (usize::MAX, 0);
        for j in r0..r1 {
            // A neighbour row inside the bitmap but outside `rows` is clear.
            let up = j.checked_sub(d);
            let dn = (j + d < nv).then_some(j + d);
            let row = &mut self.bits[j * w..(j + 1) * w];
            if up.is_some_and(|u| u < r0) || dn.is_some_and(|x| x >= r1) {
                row.fill(0);
                continue;
            }
            let mut any = 0u64;
            for x in 0..w {
                let a = up.map_or(u64::MAX, |u| scratch[(u - r0) * w + x]);
                let b = dn.map_or(u64::MAX, |u| scratch[(u - r0) * w + x]);
                row[x] &= a & b;
                any |= row[x];
            }
            if any != 0 {
                lo = lo.min(j);
                hi = j + 1;
            }
        }
        self.rows = if lo < hi { [lo, hi] } else { [0, 0] };
    }
}

/// Word `cur` of a row eroded across by `e` (below 64): bit `i` kept only where bits
/// `i − e ..= i + e` of the row `… prev cur next …` are set.
#[inline]
fn erode_word(prev: u64, cur: u64, next: u64, e: usize) -> u64 {
    // Bits 64.. of `l` are `cur`, below them `prev`: after the loop, bit i of `l` holds the
    // AND of bits i − e ..= i. Bits ..64 of `r` are `cur`, above them `next`: bit i of `r`
    // holds the AND of bits i ..= i + e.
    let mut l = ((cur as u128) << 64) | prev as u128;
    let mut r = ((next as u128) << 64) | cur as u128;
    let mut c = 1;
    while c <= e {
        let sh = c.min(e + 1 - c) as u32;
        l &= l << sh;
        r &= r >> sh;
        c += sh as usize;
    }
    ((l >> 64) as u64) & (r as u64)
}

/// The pass distances whose three-point sets sum to the range `[−k, k]`: 1, 2, 4, … while
/// they fit, then the rest.
fn radii(k: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let (mut reach, mut d) = (0, 1);
    while reach + d <= k {
        out.push(d);
        reach += d;
        d *= 2;
    }
    if reach < k {
        out.push(k - reach);
    }
    out
}

impl RectSweep {
    /// The first slab's end, in units of the rectangle's half diagonal ε: polygons nearer are
    /// drawn into that plane, each shrunk for the parallax between it and the plane. The
    /// bitmaps span each view's square widened by `2 / START_PER_EPS` on every side.
    pub const START_PER_EPS: f64 = 8.0;

    /// A sweep renderer at `res` pixels per 90° view (8 × 8 sub-pixels each).
    pub fn new(res: u32) -> Self {
        Self::with_start(res, Self::START_PER_EPS)
    }

    /// [`RectSweep::new`] with the first slab ending `start_per_eps` × ε from the eye (at
    /// least 4 ε).
    pub fn with_start(res: u32, start_per_eps: f64) -> Self {
        RectSweep {
            res: res as usize,
            start_per_eps,
            views: Vec::new(),
            heap: BinaryHeap::new(),
            scratch: ErodeScratch::default(),
            poly: PolyScratch::default(),
        }
    }

    /// Renders the rectangle of the face's plane centred on `eye` with half sides `half`
    /// (along `(axis+1) % 3`, `(axis+2) % 3`), looking out through the face (outward normal
    /// `sign × e_axis`), and decides the occludees: per object, whether it is hidden from
    /// every point of the rectangle ([`Occludees`] says how an object is tested; each box,
    /// piece box and triangle is tested in each view when the sweep reaches its nearest depth
    /// there). An object nearer than 8 ε (the half diagonal) to `eye` is open.
    pub fn render(
        &mut self,
        occ: &SampleOccluders,
        eye: DVec3,
        axis: usize,
        sign: f64,
        half: [f64; 2],
        objects: &dyn Occludees,
    ) -> (Vec<bool>, SweepStats) {
        let mut st = SweepStats::default();
        let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
        let maps = view_maps(axis, sign);
        // A point (or a segment) renders as a rectangle too small to matter.
        let tiny = 1e-9 * eye.abs().max_element().max(1.0);
        let half = [half[0].max(tiny), half[1].max(tiny)];
        let eps = half[0].hypot(half[1]);
        let hmax = half[0].max(half[1]);
        let s = 2.0 / (self.res * SUB) as f64;
        let start = self.start_per_eps.max(4.0) * eps;
        let margin = 2.0 * eps / start * (1.0 + 1e-6) + s;
        // Slab ends: each moves the front view's crossings by just under one sub-pixel, or
        // lies SLAB_RATIO times farther than the last where that is farther (near the eye,
        // where one sub-pixel of parallax is a thin slab).
        // A whole number of sub-pixels per step, so that the front view's erosions round up
        // by nothing.
        let mut ends = vec![start];
        loop {
            let last = *ends.last().unwrap();
            let k = ((1.0 - 1.0 / SLAB_RATIO) * hmax / (last * s))
                .floor()
                .max(1.0);
            let inv = 1.0 / last - k * s / hmax * (1.0 - 1e-6);
            if inv <= 0.0 {
                ends.push(f64::INFINITY);
                break;
            }
            ends.push(1.0 / inv);
        }
        let rel = |bx: DAabb| DAabb {
            min: bx.min - eye,
            max: bx.max - eye,
        };
        let n = objects.len();
        let mut hidden: Vec<bool> = (0..n)
            .map(|i| {
                let bx = rel(objects.object_box(i));
                let d = bx.min.max(-bx.max).max(DVec3::ZERO).length();
                d > 8.0 * eps
            })
            .collect();
        let Some(bvh) = occ.bvh.as_ref() else {
            return (vec![false; n], st);
        };
        // Per view: the pieces scheduled (object, piece) and triangles (object, triangle).
        let mut slots: Vec<(u32, u32)> = Vec::new();
        let mut tris: Vec<(u32, u32)> = Vec::new();
        if self.views.is_empty() {
            for map in maps {
                self.views.push(SweepView {
                    map,
                    u0: 0.0,
                    v0: 0.0,
                    nu: 0,
                    nv: 0,
                    w: 0,
                    bits: Vec::new(),
                    rows: [0, 0],
                });
            }
        }
        let zmin = 2.0 * eps;
        for (k, &map) in maps.iter().enumerate() {
            let live: Vec<usize> = (0..n).filter(|&i| hidden[i]).collect();
            if live.is_empty() {
                break;
            }
            let v = &mut self.views[k];
            v.map = map;
            let (vmin, vmax) = if k == 0 { (-1.0, 1.0) } else { (0.0, 1.0) };
            v.u0 = -1.0 - margin;
            v.v0 = vmin - margin;
            v.nu = (((2.0 + 2.0 * margin) / s).ceil() as usize).div_ceil(64) * 64;
            v.w = v.nu / 64;
            v.nv = ((vmax - vmin + 2.0 * margin) / s).ceil() as usize;
            v.bits.clear();
            v.bits.resize(v.w * v.nv, 0);
            v.rows = [usize::MAX, 0];
            let corners = [
                (-half[0], -half[1]),
                (half[0], -half[1]),
                (half[0], half[1]),
                (-half[0], half[1]),
            ]
            .map(|(x, y)| {
                let mut q = DVec3::ZERO;
                q[b] = x;
                q[c] = y;
                view_coords(map, q)
            });
            let zc = corners
                .iter()
                .map(|p| p.z)
                .fold(f64::NEG_INFINITY, f64::max);
            let zmin_v = zmin.max(zc + 1e-9 * eps);
            // Erosion per step, per axis and per tile: the largest offset of a crossing over
            // the corners of R and of the tile (module docs, 2.), in sub-pixels, rounded up.
            let step_erosion = |r: f64, r2: f64, dom: [DVec2; 2]| -> (usize, usize) {
                let mut m = DVec2::ZERO;
                for p in corners {
                    for kk in 0..4 {
                        let q = DVec2::new(dom[kk & 1].x, dom[kk >> 1].y);
                        let d = if r2.is_finite() {
                            let lam = (r - p.z) / (r2 - p.z);
                            DVec2::new(p.x, p.y) * ((1.0 - lam) / r) + q * (lam * r2 / r - 1.0)
                        } else {
                            DVec2::new(p.x, p.y) / r - q * (p.z / r)
                        };
                        m = m.max(d.abs());
                    }
                }
                let up = |x: f64| ((x / s) * (1.0 + 1e-9)).ceil() as usize;
                (up(m.x), up(m.y))
            };
            let (tw, th) = (v.w.div_ceil(TILE_WORDS), v.nv.div_ceil(TILE_ROWS));
            let tiles: Vec<[DVec2; 2]> = (0..th * tw)
                .map(|t| {
                    let (tr, tc) = (t / tw, t % tw);
                    let ua = v.u0 + (tc * TILE_WORDS * 64) as f64 * s;
                    let ub = v.u0 + (((tc + 1) * TILE_WORDS * 64).min(v.nu)) as f64 * s;
                    let va = v.v0 + (tr * TILE_ROWS) as f64 * s;
                    let vb = v.v0 + (((tr + 1) * TILE_ROWS).min(v.nv)) as f64 * s;
                    [DVec2::new(ua, va), DVec2::new(ub, vb)]
                })
                .collect();
            // Per step: every tile's radii, and the largest (the whole bitmap's).
            let tile_steps: Vec<Vec<(usize, usize)>> = ends
                .windows(2)
                .map(|e| tiles.iter().map(|&d| step_erosion(e[0], e[1], d)).collect())
                .collect();
            let steps: Vec<(usize, usize)> = tile_steps
                .iter()
                .map(|t| t.iter().fold((0, 0), |a, b| (a.0.max(b.0), a.1.max(b.1))))
                .collect();
            // Remaining erosion after each slab (for exact occlusion culling of nodes).
            let mut rem = vec![(0usize, 0usize); ends.len()];
            for i in (0..steps.len()).rev() {
                rem[i] = (rem[i + 1].0 + steps[i].0, rem[i + 1].1 + steps[i].1);
            }
            let mut frame = Frame {
                corners,
                r: ends[0],
                s,
                zmin: zmin_v,
            };
            let mut slab = 0usize;
            // Occludee events at their nearest depth in this view.
            self.heap.clear();
            // The nearest depth of a box in this view (None: wholly nearer than zmin_v, so in
            // no direction of this view).
            let near = |bx: DAabb| -> Option<f64> {
                let bx = rel(bx);
                let (lo, hi) = (view_coords(map, bx.min), view_coords(map, bx.max));
                (lo.z.max(hi.z) >= zmin_v).then(|| lo.z.min(hi.z).max(zmin_v))
            };
            slots.clear();
            tris.clear();
            for &i in &live {
                if let Some(z) = near(objects.object_box(i)) {
                    self.heap.push(Ev {
                        z,
                        kind: EV_OBJECT,
                        id: i as u32,
                    });
                }
            }
            let mut tests_left = self.heap.len();
            if tests_left == 0 {
                continue;
            }
            self.heap.push(Ev {
                z: 0.0,
                kind: EV_NODE,
                id: 0,
            });
            let node_box = |n: u32| {
                let nb = &bvh.nodes[n as usize].aabb;
                let lo = view_coords(map, glam::Vec3::from(nb.min).as_dvec3() - eye);
                let hi = view_coords(map, glam::Vec3::from(nb.max).as_dvec3() - eye);
                (lo.min(hi), lo.max(hi))
            };
            while let Some(ev) = self.heap.pop() {
                // Erode past every slab end nearer than this event (tests and polygons at a
                // slab end belong to it).
                while ends[slab] < ev.z {
                    let (eu, evv) = steps[slab];
                    if eu < 64 && evv < TILE_ROWS {
                        self.views[k].erode_tiles(&tile_steps[slab], &mut self.scratch);
                    } else {
                        self.views[k].erode(eu, evv, &mut self.scratch.words);
                    }
                    st.erosions += 1;
                    slab += 1;
                    frame.r = ends[slab];
                }
                let v = &mut self.views[k];
                match ev.kind {
                    EV_NODE => {
                        st.nodes += 1;
                        let node = &bvh.nodes[ev.id as usize];
                        let (lo, hi) = node_box(ev.id);
                        if hi.z < zmin_v {
                            continue;
                        }
                        // Its footprint from the current plane to directions (the crossings
                        // move monotonically between them), clipped at zmin; and from the
                        // current plane to the last its polygons can be drawn in (that of its
                        // farthest depth).
                        let lo_c = DVec3::new(lo.x, lo.y, lo.z.max(zmin_v));
                        let last = ends.partition_point(|&e| e < hi.z * DEPTH_MARGIN);
                        let far = Frame {
                            r: f64::INFINITY,
                            ..frame
                        };
                        let end = Frame {
                            r: ends[last.min(ends.len() - 1)],
                            ..frame
                        };
                        let inf = DVec2::splat(f64::INFINITY);
                        let (mut fa, mut fb) = (inf, -inf);
                        let (mut ga, mut gb) = (inf, -inf);
                        for kk in 0..8 {
                            let q = DVec3::new(
                                if kk & 1 == 0 { lo_c.x } else { hi.x },
                                if kk & 2 == 0 { lo_c.y } else { hi.y },
                                if kk & 4 == 0 { lo_c.z } else { hi.z },
                            );
                            for cn in corners {
                                let (p0, p1, p2) =
                                    (frame.project(cn, q), far.project(cn, q), end.project(cn, q));
                                fa = fa.min(p0).min(p1);
                                fb = fb.max(p0).max(p1);
                                ga = ga.min(p0).min(p2);
                                gb = gb.max(p0).max(p2);
                            }
                        }
                        // Outside the bitmap: nothing it draws is read.
                        let bu1 = v.u0 + v.nu as f64 * s;
                        let bv1 = v.v0 + v.nv as f64 * s;
                        if fb.x < v.u0 || fa.x > bu1 || fb.y < v.v0 || fa.y > bv1 {
                            continue;
                        }
                        // Already blocked where it would draw: every sub-pixel of its
                        // footprint, widened by the erosion between now and its polygons'
                        // planes, is set, so drawing them then sets only set bits.
                        let (ru, rv) = rem[slab];
                        let (eu, evv) = rem[last.min(ends.len() - 1)];
                        let pad = DVec2::new((ru - eu) as f64 * s, (rv - evv) as f64 * s);
                        if ga.x - pad.x > v.u0
                            && gb.x + pad.x < bu1
                            && ga.y - pad.y > v.v0
                            && gb.y + pad.y < bv1
                            && v.rect_set(ga - pad, gb + pad, s)
                        {
                            continue;
                        }
                        if node.is_leaf() {
                            for kk in node.first_index..node.first_index + node.prim_count {
                                let poly = bvh.primitive_indices[kk as usize] as usize;
                                let sp = occ.polys[poly];
                                let mut zf = f64::NEG_INFINITY;
                                let mut ok = true;
                                for q in &occ.points[sp.start as usize..sp.end as usize] {
                                    let z = view_coords(map, *q - eye).z;
                                    ok &= z >= zmin_v;
                                    zf = zf.max(z);
                                }
                                if ok && occ.card_of.get(poly).is_none_or(|&c| c == super::NO_CARD)
                                {
                                    self.heap.push(Ev {
                                        z: zf * DEPTH_MARGIN,
                                        kind: EV_POLY,
                                        id: poly as u32,
                                    });
                                }
                            }
                        } else {
                            for ch in [node.first_index, node.first_index + 1] {
                                let (lo, _) = node_box(ch);
                                self.heap.push(Ev {
                                    z: lo.z.max(0.0),
                                    kind: EV_NODE,
                                    id: ch,
                                });
                            }
                        }
                    }
                    EV_POLY => {
                        let sp = occ.polys[ev.id as usize];
                        let pc = &mut self.poly;
                        pc.pts.clear();
                        pc.pts.extend(
                            occ.points[sp.start as usize..sp.end as usize]
                                .iter()
                                .map(|q| view_coords(map, *q - eye)),
                        );
                        if let Some(p) = extended_projection(&frame, pc) {
                            v.fill(p, s);
                            st.polygons += 1;
                        }
                    }
                    kind => {
                        tests_left -= 1;
                        let probe = SweepProbe {
                            view: &self.views[k],
                            frame,
                        };
                        // An item blocked here settles its part; an open one sends the test
                        // down to its parts (scheduled at their own depths), or opens its
                        // object.
                        match kind {
                            EV_OBJECT => {
                                let i = ev.id as usize;
                                if !probe.box_blocked(&rel(objects.object_box(i))) {
                                    let pieces = objects.pieces(i);
                                    if pieces.is_empty() {
                                        hidden[i] = false;
                                    }
                                    for pk in pieces {
                                        if let Some(z) = near(objects.piece_box(pk)) {
                                            schedule(
                                                &mut self.heap,
                                                &mut slots,
                                                (i as u32, pk),
                                                z,
                                                EV_PIECE,
                                            );
                                            tests_left += 1;
                                        }
                                    }
                                }
                            }
                            EV_PIECE => {
                                let (i, pk) = slots[ev.id as usize];
                                // Skipped once its object is open.
                                if hidden[i as usize]
                                    && !probe.box_blocked(&rel(objects.piece_box(pk)))
                                {
                                    for &t in objects.piece_triangles(pk) {
                                        let tri = objects.triangle(t).map(|q| q - eye);
                                        if let Some(z) = probe.triangle_near(&tri) {
                                            schedule(
                                                &mut self.heap,
                                                &mut tris,
                                                (i, t),
                                                z,
                                                EV_TRIANGLE,
                                            );
                                            tests_left += 1;
                                        }
                                    }
                                }
                            }
                            _ => {
                                let (i, t) = tris[ev.id as usize];
                                if hidden[i as usize]
                                    && !probe.triangle_blocked(objects.triangle(t).map(|q| q - eye))
                                {
                                    hidden[i as usize] = false;
                                }
                            }
                        }
                        if tests_left == 0 {
                            break;
                        }
                    }
                }
            }
        }
        (hidden, st)
    }
}

/// Appends `item` to `list` and a test event of `kind` for it at depth `z`.
fn schedule(
    heap: &mut BinaryHeap<Ev>,
    list: &mut Vec<(u32, u32)>,
    item: (u32, u32),
    z: f64,
    kind: u8,
) {
    list.push(item);
    heap.push(Ev {
        z,
        kind,
        id: (list.len() - 1) as u32,
    });
}

/// Buffers of [`extended_projection`], kept between polygons.
#[derive(Default)]
struct PolyScratch {
    /// The polygon, in view coordinates (the input).
    pts: Vec<DVec3>,
    /// Its projection from one corner.
    proj: Vec<DVec2>,
    /// The intersection so far, and the next.
    acc: Vec<DVec2>,
    tmp: Vec<DVec2>,
}

/// The extended projection of the convex polygon `sc.pts` (view coordinates) onto the
/// frame's plane: the intersection of its projections from the four corners,
/// counter-clockwise; None when empty or when the corners do not see it with one
/// orientation.
fn extended_projection<'s>(f: &Frame, sc: &'s mut PolyScratch) -> Option<&'s [DVec2]> {
    let PolyScratch {
        pts,
        proj,
        acc,
        tmp,
    } = sc;
    acc.clear();
    let mut orient = 0.0f64;
    for (ci, &c) in f.corners.iter().enumerate() {
        proj.clear();
        proj.extend(pts.iter().map(|&q| f.project(c, q)));
        let area: f64 = (0..proj.len())
            .map(|k| proj[k].perp_dot(proj[(k + 1) % proj.len()]))
            .sum();
        let scale = proj
            .iter()
            .map(|p| p.abs().max_element())
            .fold(0.0, f64::max);
        // Orientation must be clear of rounding and the same from every corner, and every
        // edge must have a length (a repeated vertex has no edge line: such polygons are left
        // out, as the hemicube leaves them out).
        if area.abs().partial_cmp(&(1e-9 * scale * scale)) != Some(Ordering::Greater)
            || (0..proj.len())
                .any(|k| (proj[(k + 1) % proj.len()] - proj[k]).abs().max_element() <= 1e-9 * scale)
        {
            return None;
        }
        if ci == 0 {
            orient = area.signum();
        } else if area.signum() != orient {
            return None;
        }
        if area < 0.0 {
            proj.reverse();
        }
        if ci == 0 {
            acc.extend_from_slice(proj);
            continue;
        }
        for e in 0..proj.len() {
            let (a, b) = (proj[e], proj[(e + 1) % proj.len()]);
            tmp.clear();
            let side = |q: DVec2| (b - a).perp_dot(q - a);
            for k in 0..acc.len() {
                let (p0, p1) = (acc[k], acc[(k + 1) % acc.len()]);
                let (s0, s1) = (side(p0), side(p1));
                if s0 >= 0.0 {
                    tmp.push(p0);
                }
                if (s0 >= 0.0) != (s1 >= 0.0) {
                    tmp.push(p0 + (p1 - p0) * (s0 / (s0 - s1)));
                }
            }
            std::mem::swap(acc, tmp);
            if acc.len() < 3 {
                return None;
            }
        }
    }
    Some(acc)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bitmap of `nv` rows of `w` words, random bits (about `fill` of them set, in runs),
    /// rows `rows` possibly set.
    fn random_view(seed: u64, w: usize, nv: usize, rows: [usize; 2], fill: f64) -> SweepView {
        let mut x = seed;
        let mut rnd = move || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut bits = vec![0u64; w * nv];
        for j in rows[0]..rows[1] {
            // Runs of set and clear bits, long enough that erosions leave some set.
            let mut i = 0;
            while i < w * 64 {
                let len = 1 + (rnd() * 300.0) as usize;
                let set = rnd() < fill;
                for b in i..(i + len).min(w * 64) {
                    if set {
                        bits[j * w + b / 64] |= 1 << (b % 64);
                    }
                }
                i += len;
            }
            // Whole rows copied from the one before, so that columns stay set too.
            if j > rows[0] && rnd() < 0.8 {
                let (a, b) = bits.split_at_mut(j * w);
                b[..w].copy_from_slice(&a[(j - 1) * w..j * w]);
            }
        }
        SweepView {
            map: [(0, 1.0); 3],
            u0: 0.0,
            v0: 0.0,
            nu: w * 64,
            nv,
            w,
            bits,
            rows,
        }
    }

    fn get(v: &SweepView, i: isize, j: isize) -> bool {
        if i < 0 || j < 0 || i >= v.nu as isize || j >= v.nv as isize {
            return true;
        }
        let (i, j) = (i as usize, j as usize);
        if j < v.rows[0] || j >= v.rows[1] {
            return false;
        }
        v.bits[j * v.w + i / 64] >> (i % 64) & 1 == 1
    }

    #[test]
    fn tile_erosion_keeps_exactly_the_bits_whose_tile_neighbourhood_is_set() {
        for seed in 0..12u64 {
            let (w, nv) = (2 * TILE_WORDS + 3, TILE_ROWS + 40 + seed as usize * 7);
            let rows = [(seed as usize * 5) % 30, nv - (seed as usize * 11) % 25];
            let fill = [0.6, 0.85, 0.97][seed as usize % 3];
            let mut v = random_view(seed, w, nv, rows, fill);
            let before = random_view(seed, w, nv, rows, fill);
            let (tw, th) = (w.div_ceil(TILE_WORDS), nv.div_ceil(TILE_ROWS));
            let radii: Vec<(usize, usize)> = (0..tw * th)
                .map(|t| {
                    let k = (t as u64 * 7 + seed * 3) as usize;
                    (k % 5 * [1, 3, 13, 63][k % 4] / 4, (k / 3) % 9)
                })
                .collect();
            v.erode_tiles(&radii, &mut ErodeScratch::default());
            // Per row of the bitmap before: prefix counts of set bits, so that a window of a
            // row is all set when its count is its length (outside the bitmap counts as set).
            let nu = w * 64;
            let prefix: Vec<Vec<u32>> = (0..nv)
                .map(|j| {
                    let mut p = vec![0u32; nu + 1];
                    for i in 0..nu {
                        p[i + 1] = p[i] + get(&before, i as isize, j as isize) as u32;
                    }
                    p
                })
                .collect();
            let row_set = |j: isize, a: isize, b: isize| -> bool {
                if j < 0 || j >= nv as isize {
                    return true;
                }
                let (a, b) = (a.max(0) as usize, (b.min(nu as isize - 1)) as usize);
                let p = &prefix[j as usize];
                p[b + 1] - p[a] == (b + 1 - a) as u32
            };
            let mut set = 0;
            for j in 0..nv {
                for i in 0..nu {
                    let (eu, ev) = radii[(j / TILE_ROWS) * tw + i / (TILE_WORDS * 64)];
                    let (i, j, eu, ev) = (i as isize, j as isize, eu as isize, ev as isize);
                    let want = (j - ev..=j + ev).all(|jj| row_set(jj, i - eu, i + eu));
                    let got = get(&v, i, j);
                    assert_eq!(got, want, "seed {seed}, bit ({i}, {j}), radii ({eu}, {ev})");
                    set += got as usize;
                }
            }
            assert!(set > 0, "seed {seed}: the test should keep some bits");
        }
    }

    #[test]
    fn erode_word_ands_the_window() {
        let words = [
            0u64,
            u64::MAX,
            0xF0F0_FFFF_FFFF_0F0F,
            0x8000_0000_0000_0001,
            !1,
            !(1 << 63),
        ];
        for &p in &words {
            for &c in &words {
                for &n in &words {
                    for e in [0, 1, 2, 3, 7, 31, 63] {
                        let bit = |k: isize| -> bool {
                            match k {
                                ..0 => p >> (k + 64) & 1 == 1,
                                0..64 => c >> k & 1 == 1,
                                _ => n >> (k - 64) & 1 == 1,
                            }
                        };
                        let want = (0..64).fold(0u64, |acc, i| {
                            let keep = (i - e as isize..=i + e as isize).all(bit);
                            acc | (keep as u64) << i
                        });
                        assert_eq!(erode_word(p, c, n, e), want, "{p:x} {c:x} {n:x} e {e}");
                    }
                }
            }
        }
    }
}
