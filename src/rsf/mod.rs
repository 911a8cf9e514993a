//! Ray space factorization (Leyvand, Sorkine and Cohen-Or 2003), the half umbra of 2.5D
//! occluders extended upwards by floating ones, on the CPU: the charts of horizontal lines
//! leaving a cell, the occluder inserts and the occludee tests, and their packing for the GPU
//! twin ([`pack`]). The culler that drives it is `bake::rsf`.
//!
//! # The parameterisation
//! The cell's horizontal footprint is a rectangle; the up axis is `up` (y or z). For each of
//! the four sides of the footprint (outward normal `+X`, the tangent `Z`) a *chart* holds the
//! horizontal lines `Z = s + m·X` with `|m| ≤ 1`, where `X` is the distance beyond that side
//! and `s` the line's crossing of it: every horizontal direction is within 45° of one of the
//! four normals, so every ray from the cell that leaves it with a horizontal component lies on
//! a line of some chart, going towards `+X`. A line meeting the footprint crosses `X = 0` within
//! `[z0 − w, z1 + w]` (`w` the footprint's depth along `X`), so `s` spans that and `m` spans
//! `[−1, 1]`, both cut in `resolution` pixels. This is the paper's two-line parameterisation
//! (its `t` is `s + m·D` on a parallel line at distance `D`), sheared so that pixels are
//! rectangles in `(s, m)`.
//!
//! # The half umbra (§3, §5 of the paper)
//! In the vertical plane of a line the cell is (within) the rectangle `K = [−w, 0] × [y0, y1]`
//! (`X`, height). A convex occluder (a polygon, or a solid) whose cut by the plane holds a
//! bottom point `B` at or below `y0` and a top point `T = (Xt, Yt)`, wholly beyond the face
//! (`X > 0`), holds the segment `BT`, which blocks every ray from `K` to a point `q` beyond it
//! (`Xq ≥` its largest `X`) that passes `Xt` below `Yt` and `B`'s `X` above `B` (true when `q`
//! is no lower than `B`: the ray's heights are at least `min(y0, Yq)`). The points every ray from `K`
//! passes below `T` lie under the line `Y = y1 + v·X` with `v = (Yt − y1)/Xt` when `Yt < y1`
//! (the worst eye is `K`'s front top corner) and `v = (Yt − y1)/(Xt + w)` when `Yt ≥ y1`
//! (the back top corner's line, lowered to pass through the front corner: it is below the
//! exact one for every `X ≥ 0`). Each pixel keeps such a line as an *umbra*: the smallest
//! slope `v`, with the *guard* `g` (the occludee must be at `X ≥ g`) and the *base* (it must
//! be no lower than that).
//!
//! # Why it is conservative
//! - **Every value bounds the whole pixel.** Along an edge of the occluder (a polygon's edges,
//!   a solid's hull edges: the cut's corners lie on them) the point a line crosses moves
//!   monotonically between the pixel's corners (the lines through one point form a line in
//!   `(s, m)`, so the edge parameter is quasi-linear on the pixel rectangle): an edge crossed by
//!   the four corner lines is crossed by every line of the pixel, at `X` and heights between
//!   its corners' extremes. `T` is taken on the crossed edge whose lowest corner height is
//!   highest, `B` on the one whose highest corner height is lowest. An edge whose horizontal
//!   direction lies in the pixel's slope range is never used there (the lines crossing it form
//!   a double wedge, not a convex set); a pixel without two usable edges receives nothing.
//! - **Floating occluders** (cut from a bottom point `B` above the cell's bottom up to `T`)
//!   cast no half umbra of their own, but they extend one: when `B` lies, for every line of the
//!   pixel, beyond an umbra's guard and under its line, the pixel gains the umbra with `T`'s
//!   line, the larger guard and the old base (`fuse`, whose docs hold the proof). The occluders
//!   behind a stored umbra thus form a chain — one standing on the ground, then floating ones
//!   each resting in the umbra of the one before — and every segment from the cell to a point
//!   that passes the umbra's tests crosses one of them. A bridge or an upper storey resting on
//!   nothing inserted before it writes nothing: its own full umbra, bounded below by the line
//!   from the cell's front bottom edge through its bottom point, is not kept (measured as an
//!   experiment, it hid one more object in 173 cells of four scenes, for up to 11× this
//!   culler's time: nothing standing on the ground behind a floating occluder is above that
//!   line).
//! - **Fusion.** A point hidden under one polygon's line is hidden; keeping per pixel the
//!   highest line of several polygons, with the largest guard and base, keeps only points
//!   that the polygon with that line hides. Two umbrae per pixel (a near one and a far one
//!   that also holds the near one's line) keep the guard from jumping to the far polygons.
//! - **Occludees.** A box is hidden in a chart when every pixel holding a line that meets the
//!   box's footprint and the cell's (over-estimated from the rectangles' corners and the
//!   column's slope range) has an umbra whose guard is at most the box's near `X`, whose base
//!   is at most its bottom (give or take a margin the rays provably clear, see
//!   [`Umbra`]'s `hides`), and whose line is at or above its top at the worst of its `X`
//!   extremes; a box reaching `X ≤ 0` with any such line is visible. A box no ray of the
//!   chart can reach from the cell (`|ΔZ| > ΔX` for every pair of points) is out of it. It is hidden from
//!   the cell when it is hidden in all four charts. Rays straight up or down meet only boxes
//!   over the footprint, which reach `X ≤ 0` in every chart.
//! - **Rounding.** Values are computed in f64 and stored in f32 rounded toward "visible":
//!   slopes down, guards and bases up.
//!
//! # The GPU twin
//! [`pack`] lays out what [`RayCharts::insert`] and [`RayCharts::box_hidden`] compute per
//! occluder, per column and per box — with the same functions — as flat arrays for
//! `shaders/rsf.wgsl`, which repeats the per-pixel work in f64 (`backend::gpu`'s `rsf`
//! module). Each pixel meets an insert call's occluders in their order, so the GPU's charts
//! are these charts.

pub mod pack;

use crate::geom::{DAabb, f32_down, f32_up};
use glam::DVec3;

/// One umbra of a pixel: it hides points at `X ≥ guard` no lower than `base` and no higher
/// than `y1 + slope·X`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Umbra {
    /// The slope `v` of the line through the cell's front top edge (rounded down).
    pub slope: f32,
    /// The distance beyond the face from which the umbra holds (rounded up).
    pub guard: f32,
    /// The lowest height it hides (rounded up).
    pub base: f32,
}

impl Umbra {
    /// No umbra: hides nothing.
    pub const NONE: Umbra = Umbra {
        slope: f32::NEG_INFINITY,
        guard: f32::INFINITY,
        base: f32::INFINITY,
    };

    fn is_none(&self) -> bool {
        self.guard == f32::INFINITY
    }

    /// The umbra of both (valid where both are): the higher line, the larger guard and base.
    fn merged(&self, o: &Umbra) -> Umbra {
        Umbra {
            slope: self.slope.max(o.slope),
            guard: self.guard.max(o.guard),
            base: self.base.max(o.base),
        }
    }

    /// True when the umbra hides the points `X ∈ [x0, x1]`, heights `[y_lo, y_hi]`, from the
    /// cell of frame `fr`.
    ///
    /// The base test has a margin: a ray from an eye at height `≥ y0` to a point at height
    /// `y ≥ y_lo` passes the occluder's bottom point (at `X ≤ guard`) at least
    /// `(y0 − y_lo)·(x0 − guard)/(x1 + w)` above `y_lo`, so a base a rounding error above a
    /// box standing on the same ground still hides it.
    fn hides(&self, fr: &Frame, x0: f64, x1: f64, y_lo: f64, y_hi: f64) -> bool {
        let guard = self.guard as f64;
        if self.is_none() || guard > x0 {
            return false;
        }
        let margin = (fr.y0 - y_lo).max(0.0) * (x0 - guard) / (x1 + fr.w);
        if (self.base as f64) > y_lo + margin {
            return false;
        }
        let v = self.slope as f64;
        let x = if v >= 0.0 { x0 } else { x1 };
        y_hi <= fr.y1 + v * x
    }
}

/// One side of the footprint: the local frame `(X, Z, height)` of its chart.
#[derive(Clone, Copy, Debug)]
struct Frame {
    up: usize,
    a: usize,
    b: usize,
    sign: f64,
    face: f64,
    /// The footprint's depth along `X`.
    w: f64,
    /// The footprint's range along `Z`.
    z0: f64,
    z1: f64,
    y0: f64,
    y1: f64,
    s0: f64,
    ds: f64,
    res: usize,
}

impl Frame {
    fn local(&self, p: DVec3) -> DVec3 {
        DVec3::new(self.sign * (p[self.a] - self.face), p[self.b], p[self.up])
    }

    fn m_of(&self, i: usize) -> f64 {
        -1.0 + 2.0 * i as f64 / self.res as f64
    }

    fn s_of(&self, j: usize) -> f64 {
        self.s0 + self.ds * j as f64
    }

    /// The columns holding every line through the footprint and one of `pts` (local points,
    /// all with `X > 0`), padded by a column for rounding: the slope of a line through a point
    /// of the footprint's rectangle and a point of the points' hull is between the slopes
    /// between their corners.
    fn columns(&self, pts: impl Iterator<Item = (f64, f64)>) -> (usize, usize) {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (x, z) in pts {
            for ex in [-self.w, 0.0] {
                for ez in [self.z0, self.z1] {
                    let m = (z - ez) / (x - ex);
                    lo = lo.min(m);
                    hi = hi.max(m);
                }
            }
        }
        let n = self.res as f64;
        let col = |m: f64| ((m + 1.0) * 0.5 * n).floor();
        if lo.partial_cmp(&hi) == Some(std::cmp::Ordering::Greater)
            || lo.is_nan()
            || hi.is_nan()
            || lo > 1.0
            || hi < -1.0
        {
            return (1, 0);
        }
        let a = (col(lo) - 1.0).clamp(0.0, n - 1.0) as usize;
        let b = (col(hi) + 1.0).clamp(0.0, n - 1.0) as usize;
        (a, b)
    }

    /// The rows whose s-range meets `[lo, hi]`, or `None`.
    fn rows(&self, lo: f64, hi: f64) -> Option<(usize, usize)> {
        let n = self.res as f64;
        let a = ((lo - self.s0) / self.ds).floor().max(0.0);
        let b = ((hi - self.s0) / self.ds).floor().min(n - 1.0);
        (a <= b && a < n && b >= 0.0).then_some((a as usize, b as usize))
    }
}

/// The four charts' frames of `cell` (see [`RayCharts::new`]).
fn frames(cell: &DAabb, up: usize, resolution: u32) -> Vec<Frame> {
    assert!(up == 1 || up == 2, "the up axis is y (1) or z (2)");
    assert!(resolution > 0, "a chart has at least one pixel");
    let horiz: [usize; 2] = if up == 1 { [0, 2] } else { [0, 1] };
    let res = resolution as usize;
    let mut frames = Vec::with_capacity(4);
    for (k, &a) in horiz.iter().enumerate() {
        let b = horiz[1 - k];
        for positive in [true, false] {
            let w = cell.max[a] - cell.min[a];
            let (z0, z1) = (cell.min[b], cell.max[b]);
            let s0 = z0 - w;
            frames.push(Frame {
                up,
                a,
                b,
                sign: if positive { 1.0 } else { -1.0 },
                face: if positive { cell.max[a] } else { cell.min[a] },
                w,
                z0,
                z1,
                y0: cell.min[up],
                y1: cell.max[up],
                s0,
                ds: ((z1 + w) - s0) / res as f64,
                res,
            });
        }
    }
    frames
}

/// What one chart covers ([`RayCharts::chart_info`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChartInfo {
    /// The horizontal axis of the footprint side's outward normal.
    pub axis: usize,
    /// True for the side at the footprint's maximum along `axis`.
    pub positive: bool,
    /// The other horizontal axis, along which `s` runs.
    pub tangent: usize,
    /// The crossing of the side by row 0's lower edge.
    pub s_min: f64,
    /// The crossing by the last row's upper edge.
    pub s_max: f64,
}

/// Floating occluders rising less than this share of the cell's height are not inserted
/// (leaving an occluder out only loosens).
const MIN_FLOATING_RISE: f64 = 0.25;

/// What inserting polygons did, for the accounting.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RsfWork {
    /// Polygons inserted into at least one pixel.
    pub polygons: usize,
    /// Pixels written.
    pub pixels: usize,
}

/// The four charts of one cell.
pub struct RayCharts {
    frames: Vec<Frame>,
    /// Per chart, per pixel (`j · res + i`, row `j` of `s`, column `i` of `m`), the near and
    /// the far umbra.
    umbrae: Vec<Vec<[Umbra; 2]>>,
    /// Per chart, per column and (last) over the whole chart, the highest slope and the
    /// nearest guard of any umbra written: a floating occluder whose bottom is above every
    /// such line can fuse nowhere there.
    reach: Vec<Vec<(f32, f32)>>,
    /// Counts of what was inserted.
    pub work: RsfWork,
}

impl RayCharts {
    /// Empty charts of `cell` with `up` the up axis (1 or 2) and `resolution` pixels per side.
    ///
    /// # Panics
    /// When `up` is not 1 or 2, or the resolution is 0.
    pub fn new(cell: &DAabb, up: usize, resolution: u32) -> Self {
        let frames = frames(cell, up, resolution);
        let res = resolution as usize;
        let umbrae = frames
            .iter()
            .map(|_| vec![[Umbra::NONE; 2]; res * res])
            .collect();
        RayCharts {
            frames,
            umbrae,
            reach: vec![vec![(f32::NEG_INFINITY, f32::INFINITY); res + 1]; 4],
            work: RsfWork::default(),
        }
    }

    /// The umbrae of chart `chart` (0..4) at pixel (row `j`, column `i`): near, far.
    pub fn umbrae(&self, chart: usize, j: usize, i: usize) -> [Umbra; 2] {
        self.umbrae[chart][j * self.frames[chart].res + i]
    }

    /// Pixels per side.
    pub fn resolution(&self) -> usize {
        self.frames[0].res
    }

    /// What chart `chart` (0..4) covers: the footprint side it leaves (`axis`, `positive`),
    /// the axis its crossings `s` run along, and their range (rows); slopes `m` run from −1 to
    /// 1 over the columns.
    pub fn chart_info(&self, chart: usize) -> ChartInfo {
        let f = &self.frames[chart];
        ChartInfo {
            axis: f.a,
            positive: f.sign > 0.0,
            tangent: f.b,
            s_min: f.s0,
            s_max: f.s0 + f.ds * f.res as f64,
        }
    }

    /// Inserts a convex occluder as a 2.5D occluder: a polygon (points in order, `hull_edges`
    /// `None`) or a convex solid (its vertices, and its edges from [`hull_edges`], computed
    /// once per solid). It is written into every pixel
    /// whose lines all cut it from a point at or below the cell's bottom up to a higher point,
    /// wholly beyond the face, and, when its cut starts higher, into every pixel where that
    /// bottom point lies in an umbra already there (fusion, see the module docs); flat ones
    /// (roofs) and bridges over nothing write nothing. Returns the pixels written.
    pub fn insert(&mut self, pts: &[DVec3], hull_edges: Option<&[(usize, usize)]>) -> usize {
        if pts.len() < 3 {
            return 0;
        }
        let mut written = 0;
        let mut segs: Vec<(DVec3, DVec3)> = Vec::new();
        let mut local: Vec<DVec3> = Vec::with_capacity(pts.len());
        for c in 0..self.frames.len() {
            let fr = self.frames[c];
            let Some(floating) = chart_segments(&fr, pts, hull_edges, &mut local, &mut segs) else {
                continue;
            };
            if floating {
                let b = PartBounds::of(&fr, &segs);
                if !may_reach(&fr, self.reach[c][fr.res], b.x_lo, b.x_hi, b.h_lo) {
                    continue;
                }
            }
            written += insert_chart(
                &fr,
                &segs,
                &mut self.umbrae[c],
                floating,
                &mut self.reach[c],
            );
        }
        if written > 0 {
            self.work.polygons += 1;
            self.work.pixels += written;
        }
        written
    }

    /// True when the box is hidden from the cell in every chart.
    pub fn box_hidden(&self, b: &DAabb) -> bool {
        (0..self.frames.len()).all(|c| self.box_hidden_in(c, b))
    }

    /// True when the box is hidden in chart `chart` (0..4): from the rays of the cell whose
    /// horizontal direction is within 45° of that side's outward normal.
    pub fn box_hidden_in_chart(&self, chart: usize, b: &DAabb) -> bool {
        self.box_hidden_in(chart, b)
    }

    fn box_hidden_in(&self, c: usize, b: &DAabb) -> bool {
        let fr = &self.frames[c];
        let lo = fr.local(b.min);
        let hi = fr.local(b.max);
        let (x0, x1) = (lo.x.min(hi.x), lo.x.max(hi.x));
        let (z0, z1) = (b.min[fr.b], b.max[fr.b]);
        let (y_lo, y_hi) = (b.min[fr.up], b.max[fr.up]);
        // A ray of this chart from the cell to the box goes from X ≥ −w forward with
        // |ΔZ| ≤ ΔX: the box is out of the chart when even the longest run, from the back of
        // the cell to the box's far side, cannot cover the gap between their Z ranges.
        let gap = (z0 - fr.z1).max(fr.z0 - z1).max(0.0);
        if x1 <= -fr.w || gap > x1 + fr.w {
            return true;
        }
        let x0c = x0.max(-fr.w);
        let umbrae = &self.umbrae[c];
        let (c0, c1) = if x0 > 0.0 {
            fr.columns([(x0, z0), (x0, z1), (x1, z0), (x1, z1)].into_iter())
        } else {
            (0, fr.res - 1)
        };
        for i in c0..=c1 {
            let (m0, m1) = (fr.m_of(i), fr.m_of(i + 1));
            let (mut smin, mut smax) = (f64::INFINITY, f64::NEG_INFINITY);
            for m in [m0, m1] {
                for x in [x0c, x1] {
                    for z in [z0, z1] {
                        let s = z - m * x;
                        smin = smin.min(s);
                        smax = smax.max(s);
                    }
                }
            }
            // Only lines through the footprint: Z = s + m·X meets [z0, z1] for some
            // X ∈ [−w, 0] only when s ∈ [z0 + min(0, m·w), z1 + max(0, m·w)].
            smin = smin.max(fr.z0 + (m0 * fr.w).min(0.0));
            smax = smax.min(fr.z1 + (m1 * fr.w).max(0.0));
            if smin > smax {
                continue;
            }
            // Outward: a margin of the rounding of s.
            let pad = 1e-9 * (smin.abs().max(smax.abs()) + fr.ds);
            let Some((j0, j1)) = fr.rows(smin - pad, smax + pad) else {
                continue;
            };
            if x0 <= 0.0 {
                return false;
            }
            for j in j0..=j1 {
                let [near, far] = umbrae[j * fr.res + i];
                if !(far.hides(fr, x0, x1, y_lo, y_hi) || near.hides(fr, x0, x1, y_lo, y_hi)) {
                    return false;
                }
            }
        }
        true
    }
}

/// The edges of the convex hull of `pts` (pairs of indices): a pair is kept when some plane
/// through it and a third point has every point on one side, and the points on that plane on
/// one side of the pair's line. Keeping a pair that is not an edge (a rounding case) is
/// harmless: it lies in the solid, so its crossings are points of the solid's cut.
pub fn hull_edges(pts: &[DVec3]) -> Vec<(usize, usize)> {
    let n = pts.len();
    let scale = pts
        .iter()
        .fold(0.0f64, |m, p| m.max((*p - pts[0]).length()))
        .max(1e-300);
    let tol = 1e-9 * scale * scale;
    let mut out = Vec::new();
    for i in 0..n {
        for j in i + 1..n {
            let e = pts[j] - pts[i];
            let edge = (0..n).filter(|&k| k != i && k != j).any(|k| {
                let nrm = e.cross(pts[k] - pts[i]);
                if nrm.length_squared() <= tol * tol {
                    return false;
                }
                let (mut pos, mut neg) = (false, false);
                let (mut ipos, mut ineg) = (false, false);
                let inplane = nrm.cross(e);
                for (l, &p) in pts.iter().enumerate() {
                    if l == i || l == j {
                        continue;
                    }
                    let d = nrm.dot(p - pts[i]);
                    if d > tol * scale {
                        pos = true;
                    } else if d < -tol * scale {
                        neg = true;
                    } else {
                        let s = inplane.dot(p - pts[i]);
                        if s > tol * scale * scale {
                            ipos = true;
                        } else if s < -tol * scale * scale {
                            ineg = true;
                        }
                    }
                }
                !(pos && neg || ipos && ineg)
            });
            if edge {
                out.push((i, j));
            }
        }
    }
    out
}

/// The segments of a convex occluder in chart `fr`'s local frame (`(X, Z, height)` stored as
/// `(x, y, z)`): a polygon's edges, a solid's hull edges (a convex solid's cut by a plane has
/// its vertices on them). Returns whether it floats (starts above the cell's bottom: it can
/// only extend a pixel's umbra upwards, see [`fuse`]), or `None` when it writes nothing in
/// this chart: it reaches the face, or floats and rises less than [`MIN_FLOATING_RISE`] of
/// the cell's height.
fn chart_segments(
    fr: &Frame,
    pts: &[DVec3],
    hull_edges: Option<&[(usize, usize)]>,
    local: &mut Vec<DVec3>,
    segs: &mut Vec<(DVec3, DVec3)>,
) -> Option<bool> {
    let lo_h = pts.iter().map(|p| p[fr.up]).fold(f64::INFINITY, f64::min);
    let lo_x = pts
        .iter()
        .map(|p| fr.sign * (p[fr.a] - fr.face))
        .fold(f64::INFINITY, f64::min);
    if lo_x <= 0.0 {
        return None;
    }
    let floating = lo_h > fr.y0;
    if floating {
        let hi_h = pts
            .iter()
            .map(|p| p[fr.up])
            .fold(f64::NEG_INFINITY, f64::max);
        if hi_h - lo_h < MIN_FLOATING_RISE * (fr.y1 - fr.y0) {
            return None;
        }
    }
    local.clear();
    local.extend(pts.iter().map(|&p| fr.local(p)));
    segs.clear();
    match hull_edges {
        Some(e) => segs.extend(e.iter().map(|&(a, b)| (local[a], local[b]))),
        None => {
            let n = local.len();
            segs.extend((0..n).map(|k| (local[k], local[(k + 1) % n])));
        }
    }
    Some(floating)
}

/// Inserts one convex occluder (its segments, local points) into one chart; returns the
/// pixels written.
fn insert_chart(
    fr: &Frame,
    segs: &[(DVec3, DVec3)],
    umbrae: &mut [[Umbra; 2]],
    floating: bool,
    reach: &mut [(f32, f32)],
) -> usize {
    let mut written = 0;
    let PartBounds {
        x_lo,
        x_hi,
        h_lo,
        best_slope,
    } = PartBounds::of(fr, segs);
    // An umbra of this occluder (guard ≥ x_lo, slope ≤ best_slope) can only raise the near
    // umbra's slope when its guard may be within the near one's, or the far umbra's slope
    // (see `insert_umbra`): a pixel where neither can happen is skipped. An occluder above
    // the cell's bottom only extends an umbra the pixel already has (`fuse`): its bottom
    // point (at a height of at least `h_lo`, at `X` in `[x_lo, x_hi]`) must be beyond that
    // umbra's guard and under its line, whose slope it must beat.
    let may_fuse = |u: &Umbra| {
        let v = u.slope as f64;
        !u.is_none()
            && u.guard as f64 <= x_hi
            && best_slope > v
            && fr.y1 + v * (if v >= 0.0 { x_hi } else { x_lo }) >= h_lo
    };
    let beaten = |px: &[Umbra; 2]| {
        let [near, far] = px;
        if floating {
            return !(may_fuse(near) || may_fuse(far));
        }
        let near_gains =
            near.is_none() || (x_lo <= near.guard as f64 && best_slope > near.slope as f64);
        let far_gains = far.is_none() || best_slope > far.slope as f64;
        !near_gains && !far_gains
    };
    let mut live: Vec<usize> = Vec::new();
    // Per corner row (j0..=j1+1) and live segment: the crossing at m0 and at m1.
    let mut lin: Vec<Lin> = Vec::new();
    let mut orders = Orders::default();
    let (c0, c1) = fr.columns(segs.iter().flat_map(|&(p, q)| [(p.x, p.y), (q.x, q.y)]));
    for i in c0..=c1 {
        if floating && !may_reach(fr, reach[i], x_lo, x_hi, h_lo) {
            continue;
        }
        let (m0, m1) = (fr.m_of(i), fr.m_of(i + 1));
        live.clear();
        live.extend((0..segs.len()).filter(|&k| is_live(segs[k], m0, m1)));
        if live.is_empty() {
            continue;
        }
        let Some((mut j0, mut j1)) = column_rows(fr, segs, m0, m1) else {
            continue;
        };
        while j0 <= j1 && beaten(&umbrae[j0 * fr.res + i]) {
            j0 += 1;
        }
        while j1 > j0 && beaten(&umbrae[j1 * fr.res + i]) {
            j1 -= 1;
        }
        if j0 > j1 {
            continue;
        }
        // Per live segment and slope: the s-range it is crossed in and its crossing point as
        // linear functions of s (`X = x0 + xs·s`, height `h0 + hs·s`).
        lin.clear();
        orders.top.clear();
        orders.bot.clear();
        for (idx, &k) in live.iter().enumerate() {
            let (p, q) = segs[k];
            orders.top.push((idx, p.z.max(q.z)));
            orders.bot.push((idx, p.z.min(q.z)));
        }
        orders.top.sort_by(|a, b| b.1.total_cmp(&a.1));
        orders.bot.sort_by(|a, b| a.1.total_cmp(&b.1));
        for &k in &live {
            let (p, q) = segs[k];
            for m in [m0, m1] {
                let (ap, aq) = (p.y - m * p.x, q.y - m * q.x);
                let d = ap - aq;
                // t = (ap − s)/d; X = p.x + t·(q.x − p.x); h = p.z + t·(q.z − p.z).
                let (dx, dh) = ((q.x - p.x) / d, (q.z - p.z) / d);
                lin.push(Lin {
                    lo: ap.min(aq),
                    hi: ap.max(aq),
                    x0: p.x + ap * dx,
                    xs: -dx,
                    h0: p.z + ap * dh,
                    hs: -dh,
                });
            }
        }
        for j in j0..=j1 {
            if beaten(&umbrae[j * fr.res + i]) {
                continue;
            }
            let px = &mut umbrae[j * fr.res + i];
            let u = match pixel_umbra(fr, &lin, &orders, fr.s_of(j), fr.s_of(j + 1)) {
                Some(PixelUmbra::Grounded(u)) => u,
                Some(PixelUmbra::Floating(f)) => match fuse(fr, px, &f) {
                    Some(u) => u,
                    None => continue,
                },
                None => continue,
            };
            insert_umbra(px, u);
            for r in [i, fr.res] {
                reach[r].0 = reach[r].0.max(u.slope);
                reach[r].1 = reach[r].1.min(u.guard);
            }
            written += 1;
        }
    }
    written
}

/// What the best umbra an occluder (its local segments, in one chart) could cast anywhere is
/// bounded by: pixels whose umbrae already beat it are skipped before any crossing is
/// computed.
#[derive(Clone, Copy, Debug)]
struct PartBounds {
    x_lo: f64,
    x_hi: f64,
    h_lo: f64,
    best_slope: f64,
}

impl PartBounds {
    fn of(fr: &Frame, segs: &[(DVec3, DVec3)]) -> Self {
        let (mut x_lo, mut x_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut h_lo, mut h_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &(p, q) in segs {
            for e in [p, q] {
                x_lo = x_lo.min(e.x);
                x_hi = x_hi.max(e.x);
                h_lo = h_lo.min(e.z);
                h_hi = h_hi.max(e.z);
            }
        }
        let best_slope = if h_hi >= fr.y1 {
            (h_hi - fr.y1) / (x_lo + fr.w)
        } else {
            (h_hi - fr.y1) / x_hi
        };
        PartBounds {
            x_lo,
            x_hi,
            h_lo,
            best_slope,
        }
    }
}

/// True when a segment's horizontal direction is outside the slopes `[m0, m1]` of a column:
/// inside, the lines crossing it form a double wedge, not a convex set, so corners prove
/// nothing.
fn is_live((p, q): (DVec3, DVec3), m0: f64, m1: f64) -> bool {
    let (dx, dz) = (q.x - p.x, q.y - p.y);
    let (l, h) = (dz - m0 * dx, dz - m1 * dx);
    l * h > 0.0
}

/// The rows of the column of slopes `[m0, m1]` whose lines may cross the segments.
fn column_rows(fr: &Frame, segs: &[(DVec3, DVec3)], m0: f64, m1: f64) -> Option<(usize, usize)> {
    let (mut smin, mut smax) = (f64::INFINITY, f64::NEG_INFINITY);
    for m in [m0, m1] {
        for &(p, q) in segs {
            for e in [p, q] {
                let s = e.y - m * e.x;
                smin = smin.min(s);
                smax = smax.max(s);
            }
        }
    }
    fr.rows(smin, smax)
}

/// False when no umbra with at most slope `reach.0` and at least guard `reach.1` can hold a
/// floating occluder's bottom point (at `X` in `[x_lo, x_hi]`, no lower than `h_lo`): it would
/// be before the guard or above the line.
fn may_reach(fr: &Frame, reach: (f32, f32), x_lo: f64, x_hi: f64, h_lo: f64) -> bool {
    let v = reach.0 as f64;
    reach.1 as f64 <= x_hi && fr.y1 + v * (if v >= 0.0 { x_hi } else { x_lo }) >= h_lo
}

/// A segment's crossing by the lines `Z = s + m·X` of one slope `m`: crossed for `s` in
/// `(lo, hi)`, at `X = x0 + xs·s`, height `h0 + hs·s`.
#[derive(Clone, Copy, Debug)]
struct Lin {
    lo: f64,
    hi: f64,
    x0: f64,
    xs: f64,
    h0: f64,
    hs: f64,
}

/// The umbra an occluder casts over a whole pixel `s ∈ [sa, sb]` of a column, from its live
/// segments' crossings (`lin[2k]` at the column's first slope, `lin[2k + 1]` at its last), or
/// `None`.
///
/// A segment crossed by the pixel's four corner lines is crossed by every line of the pixel,
/// at heights and `X` between its corners' extremes. The top point is taken on the crossed
/// segment whose lowest corner height is highest, the bottom one on the segment whose highest
/// corner height is lowest; the occluder's cut by any line of the pixel is convex and holds
/// both points, hence the segment between them.
fn pixel_umbra(fr: &Frame, lin: &[Lin], order: &Orders, sa: f64, sb: f64) -> Option<PixelUmbra> {
    // (lowest height, X range) of the top candidate; (highest height, X range) of the bottom.
    let mut top: Option<(f64, f64, f64)> = None;
    let mut bot: Option<(f64, f64, f64)> = None;
    // Segments by their highest end, highest first: none after one whose end is below the
    // best top found can beat it.
    for &(k, hi_end) in &order.top {
        if top.is_some_and(|t| hi_end <= t.0) {
            break;
        }
        if let Some((hmin, _, xmin, xmax)) = corners_of(lin, k, sa, sb)
            && top.is_none_or(|t| hmin > t.0)
        {
            top = Some((hmin, xmin, xmax));
        }
    }
    top?;
    // By their lowest end, lowest first, for the bottom.
    for &(k, lo_end) in &order.bot {
        if bot.is_some_and(|b| lo_end >= b.0) {
            break;
        }
        if let Some((_, hmax, xmin, xmax)) = corners_of(lin, k, sa, sb)
            && bot.is_none_or(|b| hmax < b.0)
        {
            bot = Some((hmax, xmin, xmax));
        }
    }
    finish_umbra(fr, top, bot)
}

/// Per live segment, its index in `lin` (pairs) with its highest (for `top`) or lowest (for
/// `bot`) end height, sorted for [`pixel_umbra`]'s searches.
#[derive(Default)]
struct Orders {
    top: Vec<(usize, f64)>,
    bot: Vec<(usize, f64)>,
}

/// The corner crossings of live segment `k` over the pixel `s ∈ [sa, sb]`: (lowest height,
/// highest height, smallest X, largest X), or `None` when a corner line misses it.
fn corners_of(lin: &[Lin], k: usize, sa: f64, sb: f64) -> Option<(f64, f64, f64, f64)> {
    let (a, b) = (lin[2 * k], lin[2 * k + 1]);
    if !(a.lo < sa && sb < a.hi && b.lo < sa && sb < b.hi) {
        return None;
    }
    {
        let hs = [
            a.h0 + a.hs * sa,
            a.h0 + a.hs * sb,
            b.h0 + b.hs * sa,
            b.h0 + b.hs * sb,
        ];
        let xs = [
            a.x0 + a.xs * sa,
            a.x0 + a.xs * sb,
            b.x0 + b.xs * sa,
            b.x0 + b.xs * sb,
        ];
        let hmin = hs[0].min(hs[1]).min(hs[2].min(hs[3]));
        let hmax = hs[0].max(hs[1]).max(hs[2].max(hs[3]));
        let xmin = xs[0].min(xs[1]).min(xs[2].min(xs[3]));
        let xmax = xs[0].max(xs[1]).max(xs[2].max(xs[3]));
        Some((hmin, hmax, xmin, xmax))
    }
}

/// What an occluder casts over one pixel ([`pixel_umbra`]).
#[derive(Clone, Copy, Debug)]
enum PixelUmbra {
    /// Its cut by every line of the pixel reaches the cell's bottom: a half umbra.
    Grounded(Umbra),
    /// Its cut starts above the cell's bottom: it can only extend an umbra already there.
    Floating(Floating),
}

/// An occluder's cut by every line of a pixel, from a bottom point above the cell's bottom to
/// a top point: the half umbra its top would cast if the cut reached the ground (`top`: its
/// `slope` and a `guard` beyond both points; its `base` is not used), and where the bottom
/// point is (the highest it can be over the pixel, and its `X` range), for [`fuse`].
#[derive(Clone, Copy, Debug)]
struct Floating {
    top: Umbra,
    bot_max: f64,
    xb_min: f64,
    xb_max: f64,
}

/// The umbra of a floating occluder's cut fused with one of the pixel's umbrae `u`: when the
/// cut's bottom point lies in `u`'s umbra (beyond its guard, under its line) for every line of
/// the pixel, the fused umbra has the cut's top line, the larger guard and `u`'s base; of the
/// two umbrae the one giving the highest line is taken. `None` when neither fuses or the line
/// would not rise.
///
/// Why it is sound. Every stored umbra's line is the top line of a *chain*: an occluder
/// standing on the ground, then floating ones each fused onto the one before, with guard and
/// base at most the stored ones (merging keeps one component's line with larger guard and
/// base). The invariant: a segment `r` from a point `e` of the cell to a point `q` that passes
/// the chain's guard and base tests and goes below the chain's last top point `T'` is blocked
/// by the chain. It holds for a half umbra (`r` passes its bottom above, by the base test, and
/// its top below). Fusing a floating cut `[B, T]` onto chain `u`: let `q` pass the fused tests;
/// `r` passes `T` below (`T`'s top line, `q` beyond it). If `r` passes `B` above, `B` and `T`
/// lie on opposite sides of `r`, which crosses the cut. Otherwise `r`'s point `p` at `B`'s `X`
/// is no higher than `B`, hence under `u`'s line and beyond its guard, so the segment `ep`
/// (part of `r`) passes `T'` below; `q` passes `u`'s base and guard tests; by the invariant
/// `r` is blocked by `u`'s chain. So the fused umbra is a chain's, and is merged like any.
fn fuse(fr: &Frame, px: &[Umbra; 2], f: &Floating) -> Option<Umbra> {
    let mut best: Option<Umbra> = None;
    for u in px {
        if u.is_none() || f.top.slope <= u.slope || f.xb_min < u.guard as f64 {
            continue;
        }
        let v = u.slope as f64;
        let x = if v >= 0.0 { f.xb_min } else { f.xb_max };
        let line = fr.y1 + v * x;
        // `u`'s slope is rounded down, its line only lower than the exact one; the margin
        // covers this evaluation's rounding.
        let eps = 1e-9 * (line.abs().max(x.abs()).max(fr.y1.abs()).max(1.0));
        if f.bot_max > line - eps {
            continue;
        }
        let fused = Umbra {
            slope: f.top.slope,
            guard: u.guard.max(f.top.guard),
            base: u.base,
        };
        if best.is_none_or(|b| fused.slope > b.slope) {
            best = Some(fused);
        }
    }
    best
}

/// The umbra of a top candidate (lowest height, X range) and a bottom one (highest height,
/// X range), with margins for rounding: a half umbra when the bottom is at or below the cell's
/// bottom, else a [`Floating`] cut.
fn finish_umbra(
    fr: &Frame,
    top: Option<(f64, f64, f64)>,
    bot: Option<(f64, f64, f64)>,
) -> Option<PixelUmbra> {
    let (top_min, xt_min, xt_max) = top?;
    let (bot_max, xb_min, xb_max) = bot?;
    // A relative margin for the rounding of the crossings.
    let scale = xt_max
        .abs()
        .max(xb_max.abs())
        .max(top_min.abs())
        .max(fr.w)
        .max(1.0);
    let eps = 1e-9 * scale;
    let (xmin, xmax) = (xt_min.min(xb_min) - eps, xt_max.max(xb_max) + eps);
    let (top_min, bot_max) = (top_min - eps, bot_max + eps);
    let (xt_min, xt_max) = (xt_min - eps, xt_max + eps);
    if xmin <= 0.0 || top_min <= bot_max {
        return None;
    }
    let slope = if top_min >= fr.y1 {
        (top_min - fr.y1) / (xt_max + fr.w)
    } else {
        (top_min - fr.y1) / xt_min
    };
    let umbra = Umbra {
        slope: f32_down(slope - 1e-12 * slope.abs()),
        guard: f32_up(xmax),
        base: f32_up(bot_max),
    };
    if bot_max <= fr.y0 {
        return Some(PixelUmbra::Grounded(umbra));
    }
    Some(PixelUmbra::Floating(Floating {
        top: umbra,
        bot_max,
        xb_min: xb_min - eps,
        xb_max: xb_max + eps,
    }))
}

/// Adds umbra `u` to a pixel's near and far umbrae (see the module docs).
fn insert_umbra(px: &mut [Umbra; 2], u: Umbra) {
    let [near, far] = *px;
    if near.is_none() {
        px[0] = u;
        return;
    }
    if u.guard <= near.guard {
        // Valid wherever the near one is: both gain it.
        px[0] = Umbra {
            slope: near.slope.max(u.slope),
            guard: near.guard,
            base: near.base.max(u.base),
        };
        if !far.is_none() {
            px[1] = Umbra {
                slope: far.slope.max(u.slope),
                guard: far.guard,
                base: far.base.max(u.base),
            };
        }
        return;
    }
    if far.is_none() {
        px[1] = near.merged(&u);
    } else if u.slope <= far.slope {
        // Nothing to gain: the far umbra's line is at least as high, and merging could only
        // raise its guard or base.
    } else if u.guard <= far.guard {
        px[1] = Umbra {
            slope: u.slope,
            guard: far.guard,
            base: far.base.max(u.base),
        };
    } else {
        px[1] = far.merged(&u);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cell() -> DAabb {
        DAabb {
            min: DVec3::new(-2.0, 0.0, -2.0),
            max: DVec3::new(2.0, 2.0, 2.0),
        }
    }

    /// A vertical wall across x = `x`, z in `[z0, z1]`, from the ground to `h`.
    fn wall(x: f64, z0: f64, z1: f64, h: f64) -> Vec<DVec3> {
        vec![
            DVec3::new(x, -0.5, z0),
            DVec3::new(x, -0.5, z1),
            DVec3::new(x, h, z1),
            DVec3::new(x, h, z0),
        ]
    }

    fn boxed(min: [f64; 3], max: [f64; 3]) -> DAabb {
        DAabb {
            min: DVec3::from(min),
            max: DVec3::from(max),
        }
    }

    #[test]
    fn a_wide_tall_wall_hides_a_box_behind_it_and_not_one_beside_the_cell() {
        let mut r = RayCharts::new(&cell(), 1, 64);
        assert!(r.insert(&wall(6.0, -100.0, 100.0, 10.0), None) > 0);
        assert!(r.box_hidden(&boxed([20.0, 0.0, -1.0], [21.0, 5.0, 1.0])));
        // Taller than what the wall hides from the cell's top at the back.
        assert!(!r.box_hidden(&boxed([20.0, 0.0, -1.0], [21.0, 40.0, 1.0])));
        // In front of the wall.
        assert!(!r.box_hidden(&boxed([4.0, 0.0, -1.0], [5.0, 1.0, 1.0])));
        // Behind the cell, seen through the other charts.
        assert!(!r.box_hidden(&boxed([-21.0, 0.0, -1.0], [-20.0, 1.0, 1.0])));
    }

    #[test]
    fn a_wall_lower_than_the_eye_hides_only_below_the_line_from_the_front_top_edge() {
        let mut r = RayCharts::new(&cell(), 1, 128);
        r.insert(&wall(6.0, -200.0, 200.0, 1.0), None);
        // From (0 beyond the face, 2) over (4, 1): height 2 − X/4... at X = 8 (x = 10) the
        // line is at 0; a box up to 0.5 at x = 10 is seen over the wall.
        assert!(!r.box_hidden(&boxed([10.0, 0.0, -1.0], [11.0, 0.5, 1.0])));
        // Just behind the wall, low: hidden (the line at X = 5 is at 0.75).
        assert!(r.box_hidden(&boxed([6.5, 0.0, -0.5], [7.0, 0.5, 0.5])));
    }

    #[test]
    fn a_box_has_twelve_hull_edges() {
        let b = boxed([1.0, 2.0, 3.0], [4.0, 7.0, 5.0]).corners();
        let e = hull_edges(&b);
        assert_eq!(e.len(), 12, "{e:?}");
        for (i, j) in e {
            // Box corners differing in exactly one coordinate bit.
            assert_eq!((i ^ j).count_ones(), 1, "{i} {j}");
        }
    }

    /// A vertical wall across x = `x`, z in `[z0, z1]`, heights `[bottom, top]`.
    fn floating_wall(x: f64, z0: f64, z1: f64, bottom: f64, top: f64) -> Vec<DVec3> {
        let mut w = wall(x, z0, z1, top);
        for p in &mut w {
            if p.y < 0.0 {
                p.y = bottom;
            }
        }
        w
    }

    #[test]
    fn a_floating_wall_resting_on_a_low_wall_extends_its_umbra_and_one_above_a_gap_does_not() {
        // A low wall to height 1 at X = 4: its half umbra's line falls from the cell's top
        // (2) by 1/4 per unit, to 0.5 at X = 6 (x = 8).
        let low = wall(6.0, -200.0, 200.0, 1.0);
        let behind = boxed([8.0, 0.0, -0.5], [9.0, 1.5, 0.5]);
        let mut alone = RayCharts::new(&cell(), 1, 128);
        alone.insert(&low, None);
        assert!(!alone.box_hidden(&behind), "seen over the low wall");
        // A second wall set back half a unit (X = 4.5, where the line is at 0.875) from 0.8
        // to 10 (the facade's upper part): together they hide the box.
        let upper = floating_wall(6.5, -200.0, 200.0, 0.8, 10.0);
        let mut stacked = RayCharts::new(&cell(), 1, 128);
        stacked.insert(&low, None);
        assert!(stacked.insert(&upper, None) > 0);
        assert!(stacked.box_hidden(&behind), "the stacked walls fuse");
        // Inserted first, the floating wall has nothing to rest on and writes nothing.
        let mut reversed = RayCharts::new(&cell(), 1, 128);
        assert_eq!(reversed.insert(&upper, None), 0);
        // Starting at 1 it leaves a slit above the line: the cell's top sees through it over
        // the low wall, down to the ground at X = 8 (x = 10): a low box there stays visible.
        let mut gap = RayCharts::new(&cell(), 1, 128);
        gap.insert(&low, None);
        gap.insert(&floating_wall(6.5, -200.0, 200.0, 1.0, 10.0), None);
        assert!(!gap.box_hidden(&boxed([10.0, 0.0, -0.5], [11.0, 0.6, 0.5])));
        // A floating wall behind the low one, its bottom under the low wall's line, fuses
        // too: the line at X = 8 is at 0, the bottom at 0.8 is not under it; at X = 5 the
        // line is at 0.75, a wall from 0.7 fuses.
        let mut behind_wall = RayCharts::new(&cell(), 1, 128);
        behind_wall.insert(&low, None);
        assert!(behind_wall.insert(&floating_wall(7.0, -200.0, 200.0, 0.7, 10.0), None) > 0);
        assert!(behind_wall.box_hidden(&boxed([9.0, 0.0, -0.5], [10.0, 1.5, 0.5])));
        let mut too_high = RayCharts::new(&cell(), 1, 128);
        too_high.insert(&low, None);
        assert_eq!(
            too_high.insert(&floating_wall(10.0, -200.0, 200.0, 0.8, 10.0), None),
            0
        );
    }

    #[test]
    fn a_floating_polygon_is_not_a_half_umbra() {
        let mut r = RayCharts::new(&cell(), 1, 32);
        let mut w = wall(6.0, -100.0, 100.0, 10.0);
        for p in &mut w {
            if p.y < 0.0 {
                p.y = 0.5;
            }
        }
        assert_eq!(r.insert(&w, None), 0, "a bridge above the cell's bottom");
    }
}
