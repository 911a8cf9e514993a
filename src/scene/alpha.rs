//! Alpha-tested cards (glTF `alphaMode: "MASK"`): what import keeps of them (each MASK
//! material's alpha sources, the decoded alpha planes of its texture, every card triangle's
//! texture coordinates), the renderer's alpha test at full resolution (for `validate`), and
//! the **conservative coverage** the bake uses: the parts of a card that are opaque at every
//! mip level a renderer may sample, as convex polygons inside the card.
//!
//! # Why the coverage is conservative
//! A renderer draws a fragment of a MASK card when `factor · vertex alpha · texture alpha ≥
//! cutoff`, where the texture alpha is sampled with bilinear filtering from one mip level (or
//! a blend of two: trilinear). Mip level `l + 1` is the 2×2 box filter of level `l` (glTF and
//! WebGL mip chains; sizes halve, rounding down, to 1). Then, for a point of the card:
//!
//! 1. a bilinear sample is a convex combination of the 2×2 texels around it, so it is at
//!    least their minimum; a trilinear sample is a convex combination of two such samples;
//! 2. each texel of level `l + 1` is kept as a lower bound of its stored value: the mean of
//!    the lower bounds of its 2×2 sources minus one step of 8-bit rounding (for an odd size,
//!    the minimum of up to 3×3 sources, whatever filter the driver uses there);
//! 3. the texture is cut into **half-texel cells** (at level 0); all points of a cell read,
//!    at each level, texels of a known small set (the bilinear cells the half-texel cell
//!    overlaps, with the sampler's wrap modes). The cell is *surely opaque* when, at every
//!    level used, the minimum over that set is at least the threshold `cutoff / (factor ·
//!    smallest vertex alpha)` (plus 1e-6 for float error);
//! 4. a card's polygons are rectangles of texture space made of surely opaque cells (tested
//!    in blocks, a block passing only when all its cells pass), moved 1/64 texel inwards
//!    against the renderer's interpolation error, clipped to the card in texture space and
//!    mapped onto the card by its affine texture map. Every point of every polygon is a point
//!    of the card that the renderer draws, from both sides (cards are double-sided), at any
//!    distance.
//!
//! Assumed: box-filtered mips (a driver's or an asset pipeline's Kaiser or coverage-preserving
//! mips are different, `--alpha-mips` then says how many levels to trust), no anisotropic
//! filtering beyond the bilinear footprint, no LOD bias below level 0. `--alpha-mips N`
//! trusts only levels `0..N`: right for engines that never sample far levels of foliage
//! (alpha-to-coverage, coverage-preserving mips, a LOD clamp), wrong otherwise.
//!
//! With all levels (the default) a texture whose mean alpha is below the cutoff has no surely
//! opaque point at all: its 1×1 level is that mean. That is the price of conservativeness for
//! atlas-like leaf textures; `bake` prints the share of card area that stays opaque.

use crate::geom::{clip_half_plane, convex_hull};
use glam::{DVec2, DVec3, Vec2};
use std::collections::HashMap;
use std::sync::Arc;

/// `AlphaCards::card_of` for a triangle that is not an alpha-tested card.
pub const NO_CARD: u32 = u32::MAX;

/// Largest grid of blocks per axis a card's texture-space box is tested at.
const MAX_BLOCKS: usize = 256;
/// Super-cells per axis kept in a coverage's summed-area table (larger textures group
/// half-texel cells into squares that pass only when all their cells pass).
const MAX_SUPER_CELLS: u32 = 2048;
/// The smallest card polygon kept by default, as a share of its card's area: fragments below
/// it add parts without hiding anything measurable. Leaves of branch-image atlases are about
/// 0.1 % of their card each (the European beech), so this keeps them.
pub const MIN_POLYGON_SHARE: f64 = 0.0005;
/// Triangles join one card only when each one's texture map puts the other's corners within
/// this share of its size of where they are: a polygon mapped by one triangle's map then lies
/// within `1e-6 × size` of the other's surface, a thousandth of a texel of a card that maps
/// the texture once, well inside the inset.
const MERGE_TOLERANCE: f64 = 1e-6;
/// How far polygons are moved inwards, in texels of level 0.
const INSET_TEXELS: f64 = 1.0 / 64.0;

/// A sampler's wrap mode along one texture axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Wrap {
    /// `REPEAT` (glTF's default).
    #[default]
    Repeat,
    /// `MIRRORED_REPEAT`.
    MirroredRepeat,
    /// `CLAMP_TO_EDGE`.
    ClampToEdge,
}

impl Wrap {
    /// The glTF sampler constant (10497, 33648, 33071); anything else is `Repeat`.
    pub fn from_gl(code: u32) -> Wrap {
        match code {
            33648 => Wrap::MirroredRepeat,
            33071 => Wrap::ClampToEdge,
            _ => Wrap::Repeat,
        }
    }

    /// Maps an unwrapped index onto `0..n` as this mode fetches it.
    fn fetch(self, i: i64, n: i64) -> i64 {
        match self {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::ClampToEdge => i.clamp(0, n - 1),
            Wrap::MirroredRepeat => {
                let m = i.rem_euclid(2 * n);
                if m < n { m } else { 2 * n - 1 - m }
            }
        }
    }
}

/// The alpha plane of one glTF texture (image + sampler).
#[derive(Clone, Debug, PartialEq)]
pub struct AlphaTexture {
    /// What to call it in messages: the image's index and URI or name.
    pub label: String,
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Alpha, row-major from texture coordinate (0, 0) (the image's first pixel).
    pub alpha: Arc<Vec<u8>>,
    /// Wrap modes along u and v.
    pub wrap: [Wrap; 2],
}

impl AlphaTexture {
    /// Bilinear alpha at mip 0 (in 0..=1), as a renderer at full resolution samples it.
    pub fn bilinear(&self, uv: Vec2) -> f32 {
        let (w, h) = (self.width as i64, self.height as i64);
        let s = uv.x as f64 * w as f64 - 0.5;
        let t = uv.y as f64 * h as f64 - 0.5;
        if !s.is_finite() || !t.is_finite() {
            return 0.0;
        }
        let (x0, y0) = (s.floor(), t.floor());
        let (fx, fy) = ((s - x0) as f32, (t - y0) as f32);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let at = |x: i64, y: i64| {
            let x = self.wrap[0].fetch(x, w);
            let y = self.wrap[1].fetch(y, h);
            self.alpha[(y * w + x) as usize] as f32 / 255.0
        };
        let top = at(x0, y0) * (1.0 - fx) + at(x0 + 1, y0) * fx;
        let bottom = at(x0, y0 + 1) * (1.0 - fx) + at(x0 + 1, y0 + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

/// One MASK material.
#[derive(Clone, Debug, PartialEq)]
pub struct AlphaMaterial {
    /// The material's name (or `material<I>`).
    pub name: String,
    /// `alphaCutoff` (0.5 when absent).
    pub cutoff: f32,
    /// The alpha of `baseColorFactor`.
    pub factor: f32,
    /// Index into [`AlphaCards::textures`] of the base-colour texture; `None`: the alpha is
    /// the factor (times vertex alpha) everywhere.
    pub texture: Option<u32>,
}

/// One triangle of a MASK material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CardTriangle {
    /// Index into [`AlphaCards::materials`].
    pub material: u32,
    /// Texture coordinates of the corners (`KHR_texture_transform` applied), in the order of
    /// the scene triangle's corners.
    pub uv: [Vec2; 3],
    /// Alpha of `COLOR_0` at the corners (1 without).
    pub vertex_alpha: [f32; 3],
}

/// The alpha-tested cards of a scene.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AlphaCards {
    /// MASK materials.
    pub materials: Vec<AlphaMaterial>,
    /// Textures the materials sample.
    pub textures: Vec<AlphaTexture>,
    /// Per scene triangle: index into `cards`, or [`NO_CARD`].
    pub card_of: Vec<u32>,
    /// The card triangles.
    pub cards: Vec<CardTriangle>,
    /// MASK triangles left as non-occluders because their image was missing and
    /// `--alpha-missing transparent` was given.
    pub missing_transparent: usize,
}

impl AlphaCards {
    /// The card of scene triangle `t`, if it is one.
    pub fn card(&self, t: usize) -> Option<&CardTriangle> {
        match self.card_of.get(t) {
            Some(&c) if c != NO_CARD => self.cards.get(c as usize),
            _ => None,
        }
    }

    /// Whether a renderer at full resolution (bilinear, mip 0) draws card `card` at
    /// barycentric coordinates `(b1, b2)` (corner 0 has weight `1 − b1 − b2`).
    pub fn drawn_at(&self, card: &CardTriangle, b1: f32, b2: f32) -> bool {
        let b0 = 1.0 - b1 - b2;
        let m = &self.materials[card.material as usize];
        let va = card.vertex_alpha[0] * b0 + card.vertex_alpha[1] * b1 + card.vertex_alpha[2] * b2;
        let tex = match m.texture {
            Some(i) => {
                let uv = card.uv[0] * b0 + card.uv[1] * b1 + card.uv[2] * b2;
                self.textures[i as usize].bilinear(uv)
            }
            None => 1.0,
        };
        m.factor * va * tex >= m.cutoff
    }

    /// Keeps the cards of the triangles `order` (new triangle `i` is old triangle
    /// `order[i]`), for importers and tools that reorder triangles.
    pub fn reorder(&self, order: &[u32]) -> AlphaCards {
        let mut out = AlphaCards {
            materials: self.materials.clone(),
            textures: self.textures.clone(),
            card_of: Vec::with_capacity(order.len()),
            cards: Vec::new(),
            missing_transparent: self.missing_transparent,
        };
        for &t in order {
            match self.card(t as usize) {
                Some(c) => {
                    out.card_of.push(out.cards.len() as u32);
                    out.cards.push(*c);
                }
                None => out.card_of.push(NO_CARD),
            }
        }
        out
    }
}

/// Surely-opaque half-texel cells of one texture at one threshold, over one period of its
/// wrap modes, kept as a summed-area table of the cells that are *not* surely opaque.
#[derive(Clone, Debug)]
pub struct Coverage {
    /// Half-texel cells per super-cell side.
    q: u32,
    /// Super-cells per axis in one period.
    period: [u32; 2],
    /// Half-texel cells per axis in one period (2 × the texture's size).
    cells: [u32; 2],
    wrap: [Wrap; 2],
    /// `(period[0] + 1) × (period[1] + 1)` prefix counts of super-cells not surely opaque.
    sat: Vec<u32>,
    /// Share of half-texel cells that are surely opaque.
    pub opaque_share: f64,
}

/// Lower bounds of every mip level's texels, level 0 first (each row-major).
fn mip_lower_bounds(tex: &AlphaTexture, levels: usize) -> Vec<(usize, usize, Vec<f32>)> {
    let (w, h) = (tex.width as usize, tex.height as usize);
    let mut out = vec![(
        w,
        h,
        tex.alpha
            .iter()
            .map(|&a| a as f32 / 255.0)
            .collect::<Vec<f32>>(),
    )];
    // A stored level is rounded to 8 bits: at most one step below its mean (truncation).
    const ROUNDING: f32 = 1.0 / 255.0;
    while out.len() < levels {
        let (pw, ph, ref prev) = *out.last().expect("level 0");
        if pw == 1 && ph == 1 {
            break;
        }
        let (nw, nh) = ((pw / 2).max(1), (ph / 2).max(1));
        // Source range of destination texel i along an axis of source size n.
        let range = |i: usize, n: usize| -> (usize, usize) {
            if n == 1 {
                (0, 0)
            } else if n.is_multiple_of(2) {
                (2 * i, 2 * i + 1)
            } else {
                (2 * i, (2 * i + 2).min(n - 1))
            }
        };
        let even = pw.is_multiple_of(2) && ph.is_multiple_of(2);
        let mut next = vec![0f32; nw * nh];
        for y in 0..nh {
            let (y0, y1) = range(y, ph);
            for x in 0..nw {
                let (x0, x1) = range(x, pw);
                let v = if even {
                    (prev[y0 * pw + x0]
                        + prev[y0 * pw + x1]
                        + prev[y1 * pw + x0]
                        + prev[y1 * pw + x1])
                        / 4.0
                } else {
                    let mut m = f32::INFINITY;
                    for yy in y0..=y1 {
                        for xx in x0..=x1 {
                            m = m.min(prev[yy * pw + xx]);
                        }
                    }
                    m
                };
                next[y * nw + x] = v - ROUNDING;
            }
        }
        out.push((nw, nh, next));
    }
    out
}

/// For each half-texel cell `i` of an axis of `n` texels at level 0, the unwrapped range of
/// level texels (`n_l` of them) its bilinear samples read.
fn texel_ranges(n: usize, n_l: usize) -> Vec<(i64, i64)> {
    (0..2 * n)
        .map(|i| {
            let scale = n_l as f64 / n as f64;
            let s0 = (i as f64 / 2.0) * scale - 0.5;
            let s1 = ((i + 1) as f64 / 2.0) * scale - 0.5;
            let c0 = s0.floor() as i64;
            let c1 = (s1.ceil() as i64 - 1).max(c0);
            (c0, c1 + 1)
        })
        .collect()
}

impl Coverage {
    /// Builds the coverage of `tex` for texture alpha ≥ `threshold`, trusting mip levels
    /// `0..levels` (`None`: all of them).
    pub fn build(tex: &AlphaTexture, threshold: f32, levels: Option<u32>) -> Coverage {
        let (w, h) = (tex.width as usize, tex.height as usize);
        let (cw, ch) = (2 * w, 2 * h);
        let mut mask = vec![true; cw * ch];
        let need = threshold + 1e-6;
        let levels = levels.map_or(usize::MAX, |l| l.max(1) as usize);
        for (lw, lh, vals) in mip_lower_bounds(tex, levels) {
            let xr = texel_ranges(w, lw);
            let yr = texel_ranges(h, lh);
            // Per level row and half-texel column: the minimum over the column's texels.
            let mut colmin = vec![0f32; lh * cw];
            for r in 0..lh {
                for (i, &(a, b)) in xr.iter().enumerate() {
                    let mut m = f32::INFINITY;
                    for x in a..=b {
                        let x = tex.wrap[0].fetch(x, lw as i64) as usize;
                        m = m.min(vals[r * lw + x]);
                    }
                    colmin[r * cw + i] = m;
                }
            }
            for (j, &(a, b)) in yr.iter().enumerate() {
                let row = &mut mask[j * cw..(j + 1) * cw];
                if !row.iter().any(|&m| m) {
                    continue;
                }
                for (i, cell) in row.iter_mut().enumerate() {
                    if !*cell {
                        continue;
                    }
                    for y in a..=b {
                        let y = tex.wrap[1].fetch(y, lh as i64) as usize;
                        if colmin[y * cw + i] < need {
                            *cell = false;
                            break;
                        }
                    }
                }
            }
        }
        Coverage::from_mask(&mask, [cw as u32, ch as u32], tex.wrap)
    }

    /// The summed-area table of a half-texel mask, grouped into super-cells.
    fn from_mask(mask: &[bool], cells: [u32; 2], wrap: [Wrap; 2]) -> Coverage {
        // The largest power of two dividing both sizes, up to what keeps the table small.
        let mut q = 1u32;
        while cells[0].max(cells[1]) / q > MAX_SUPER_CELLS
            && cells[0].is_multiple_of(2 * q)
            && cells[1].is_multiple_of(2 * q)
        {
            q *= 2;
        }
        let period = [cells[0] / q, cells[1] / q];
        let (pw, ph) = (period[0] as usize, period[1] as usize);
        let cw = cells[0] as usize;
        let mut sat = vec![0u32; (pw + 1) * (ph + 1)];
        let q = q as usize;
        let mut opaque = 0u64;
        for sy in 0..ph {
            let mut run = 0u32;
            for sx in 0..pw {
                let mut all = true;
                for y in sy * q..(sy + 1) * q {
                    for x in sx * q..(sx + 1) * q {
                        if mask[y * cw + x] {
                            opaque += 1;
                        } else {
                            all = false;
                        }
                    }
                }
                run += u32::from(!all);
                sat[(sy + 1) * (pw + 1) + sx + 1] = sat[sy * (pw + 1) + sx + 1] + run;
            }
        }
        Coverage {
            q: q as u32,
            period,
            cells,
            wrap,
            sat,
            opaque_share: opaque as f64 / mask.len().max(1) as f64,
        }
    }

    /// Non-opaque super-cells in `[x0, x1] × [y0, y1]` (inside one period).
    fn count(&self, x0: usize, x1: usize, y0: usize, y1: usize) -> u32 {
        let pw = self.period[0] as usize + 1;
        self.sat[(y1 + 1) * pw + x1 + 1] + self.sat[y0 * pw + x0]
            - self.sat[y0 * pw + x1 + 1]
            - self.sat[(y1 + 1) * pw + x0]
    }

    /// True when every point whose texture coordinates lie in `[u[0], u[1]] × [v[0], v[1]]`
    /// is surely opaque (the half-texel cells holding the rectangle, its edges included, with
    /// the texture's wrap modes). False for an empty, non-finite or huge rectangle.
    pub fn uv_rect_opaque(&self, u: [f64; 2], v: [f64; 2]) -> bool {
        let range = |lo: f64, hi: f64, n: u32| -> Option<(i64, i64)> {
            let s = n as f64;
            let (a, b) = (lo * s, hi * s);
            // Rounded outward by a millionth of a super-cell (the products' rounding is far
            // below it for any range this accepts).
            (a.is_finite() && b.is_finite() && a <= b && b - a < 1e6 && a.abs() < 1e9)
                .then(|| ((a - 1e-6).floor() as i64, (b + 1e-6).floor() as i64))
        };
        let cells_u = self.cells[0] / self.q;
        let cells_v = self.cells[1] / self.q;
        match (range(u[0], u[1], cells_u), range(v[0], v[1], cells_v)) {
            (Some(x), Some(y)) => self.all_opaque(x, y),
            _ => false,
        }
    }

    /// True when every super-cell of the unwrapped inclusive ranges is surely opaque.
    fn all_opaque(&self, x: (i64, i64), y: (i64, i64)) -> bool {
        let xs = segments(x, self.period[0] as i64, self.wrap[0]);
        let ys = segments(y, self.period[1] as i64, self.wrap[1]);
        xs.iter()
            .all(|&(x0, x1)| ys.iter().all(|&(y0, y1)| self.count(x0, x1, y0, y1) == 0))
    }
}

/// Up to three ranges inside one period (what [`segments`] returns).
#[derive(Clone, Copy, Debug, Default)]
struct Segments {
    ranges: [(usize, usize); 3],
    len: usize,
}

impl Segments {
    fn push(&mut self, r: (usize, usize)) {
        self.ranges[self.len] = r;
        self.len += 1;
    }

    fn iter(&self) -> impl Iterator<Item = &(usize, usize)> {
        self.ranges[..self.len].iter()
    }
}

/// An unwrapped inclusive range of cells as ranges inside one period `0..n`.
fn segments((a, b): (i64, i64), n: i64, wrap: Wrap) -> Segments {
    let mut out = Segments::default();
    let whole = (0, n as usize - 1);
    match wrap {
        Wrap::ClampToEdge => out.push((a.clamp(0, n - 1) as usize, b.clamp(0, n - 1) as usize)),
        Wrap::Repeat => {
            if b - a + 1 >= n {
                out.push(whole);
            } else {
                let (a2, b2) = (a.rem_euclid(n), a.rem_euclid(n) + (b - a));
                if b2 < n {
                    out.push((a2 as usize, b2 as usize));
                } else {
                    out.push((a2 as usize, n as usize - 1));
                    out.push((0, (b2 - n) as usize));
                }
            }
        }
        Wrap::MirroredRepeat => {
            if b - a + 1 >= n {
                // A full period of either orientation covers every cell.
                out.push(whole);
                return out;
            }
            // Walk the range period by period (at most two), reflecting odd periods.
            let mut x = a;
            while x <= b {
                let p = x.div_euclid(n);
                let end = ((p + 1) * n - 1).min(b);
                let (s, e) = (x - p * n, end - p * n);
                if p.rem_euclid(2) == 0 {
                    out.push((s as usize, e as usize));
                } else {
                    out.push(((n - 1 - e) as usize, (n - 1 - s) as usize));
                }
                x = end + 1;
            }
        }
    }
    out
}

/// The largest all-true rectangle of a `w × h` grid: `(x0, y0, x1, y1)` inclusive, or
/// `None` when no cell is true.
fn largest_rectangle(grid: &[bool], w: usize, h: usize) -> Option<(usize, usize, usize, usize)> {
    let mut heights = vec![0usize; w];
    let mut best: Option<(usize, (usize, usize, usize, usize))> = None;
    let mut stack: Vec<(usize, usize)> = Vec::new();
    for y in 0..h {
        for (x, hgt) in heights.iter_mut().enumerate() {
            *hgt = if grid[y * w + x] { *hgt + 1 } else { 0 };
        }
        stack.clear();
        for x in 0..=w {
            let hx = heights.get(x).copied().unwrap_or(0);
            let mut start = x;
            while let Some(&(s, sh)) = stack.last() {
                if sh < hx {
                    break;
                }
                stack.pop();
                let area = sh * (x - s);
                if sh > 0 && best.is_none_or(|(a, _)| area > a) {
                    best = Some((area, (s, y + 1 - sh, x - 1, y)));
                }
                start = s;
            }
            stack.push((start, hx));
        }
    }
    best.map(|(_, r)| r)
}

/// Twice the signed area of a polygon.
fn area2(poly: &[DVec2]) -> f64 {
    (0..poly.len())
        .map(|i| poly[i].perp_dot(poly[(i + 1) % poly.len()]))
        .sum()
}

/// The surely opaque polygons of a card, in texture coordinates: up to `max_polygons`
/// rectangles of surely opaque cells (largest first, none smaller than `min_share` of the card),
/// clipped to the card's convex texture-space polygon `card` (counter-clockwise or not).
/// `size` is the texture's size at level 0.
pub fn card_polygons(
    cov: &Coverage,
    size: [u32; 2],
    card: &[DVec2],
    max_polygons: usize,
    min_share: f64,
) -> Vec<Vec<DVec2>> {
    if card.len() < 3 || max_polygons == 0 {
        return Vec::new();
    }
    // Super-cell coordinates.
    let scale = DVec2::new(
        cov.cells[0] as f64 / cov.q as f64,
        cov.cells[1] as f64 / cov.q as f64,
    );
    let pts: Vec<DVec2> = card.iter().map(|&p| p * scale).collect();
    let (mut lo, mut hi) = (DVec2::INFINITY, DVec2::NEG_INFINITY);
    for &p in &pts {
        lo = lo.min(p);
        hi = hi.max(p);
    }
    if !(lo.is_finite() && hi.is_finite()) || (hi - lo).max_element() > 1e6 {
        return Vec::new();
    }
    let gx = ((hi.x - lo.x).ceil() as usize).clamp(1, MAX_BLOCKS);
    let gy = ((hi.y - lo.y).ceil() as usize).clamp(1, MAX_BLOCKS);
    let bw = DVec2::new((hi.x - lo.x) / gx as f64, (hi.y - lo.y) / gy as f64);
    let range = |k: usize, lo: f64, bw: f64| -> (i64, i64) {
        let a = (lo + k as f64 * bw).floor() as i64;
        let b = ((lo + (k + 1) as f64 * bw).ceil() as i64 - 1).max(a);
        (a, b)
    };
    let xr: Vec<(i64, i64)> = (0..gx).map(|k| range(k, lo.x, bw.x)).collect();
    let mut grid = vec![false; gx * gy];
    for by in 0..gy {
        let yr = range(by, lo.y, bw.y);
        for bx in 0..gx {
            grid[by * gx + bx] = cov.all_opaque(xr[bx], yr);
        }
    }
    let card_area = area2(card).abs() / 2.0;
    let min_area = min_share * card_area;
    let inset = DVec2::new(INSET_TEXELS / size[0] as f64, INSET_TEXELS / size[1] as f64);
    // Clip in counter-clockwise order.
    let mut ccw: Vec<DVec2> = card.to_vec();
    if area2(&ccw) < 0.0 {
        ccw.reverse();
    }
    let mut out = Vec::new();
    let to_uv = |p: DVec2| (lo + p * bw) / scale;
    let uv_area = |poly: &[DVec2]| area2(poly).abs() / 2.0;
    let clip_card = |poly: Vec<DVec2>| -> Option<Vec<DVec2>> {
        let (mut poly, mut tmp) = (poly, Vec::new());
        for k in 0..ccw.len() {
            if poly.len() < 3 {
                break;
            }
            clip_half_plane(&poly, ccw[k], ccw[(k + 1) % ccw.len()], &mut tmp);
            std::mem::swap(&mut poly, &mut tmp);
        }
        (poly.len() >= 3 && uv_area(&poly) >= min_area).then_some(poly)
    };
    // 1. Each large blob of opaque blocks (a leaf of the atlas): its convex hull, scaled
    //    about its centre until every block it touches (with the inset) is opaque.
    let margin = (inset / (bw / scale)).max_element();
    // Blobs of the grid eroded once: thin twigs between leaves no longer join them.
    let eroded: Vec<bool> = (0..grid.len())
        .map(|c| {
            let (x, y) = (c % gx, c / gx);
            grid[c]
                && (x == 0 || grid[c - 1])
                && (x + 1 == gx || grid[c + 1])
                && (y == 0 || grid[c - gx])
                && (y + 1 == gy || grid[c + gx])
        })
        .collect();
    for comp in blobs(&eroded, gx, gy) {
        if out.len() >= max_polygons {
            break;
        }
        if comp.len() < 2 {
            break;
        }
        let Some(hull) = shrunk_hull(&grid, gx, gy, &comp, margin) else {
            continue;
        };
        if let Some(poly) = clip_card(hull.iter().map(|&p| to_uv(p)).collect()) {
            out.push(poly);
            // The rectangles below look elsewhere.
            let (mut a, mut b) = (DVec2::INFINITY, DVec2::NEG_INFINITY);
            for &p in &hull {
                a = a.min(p);
                b = b.max(p);
            }
            for y in (a.y.floor().max(0.0) as usize)..(b.y.ceil() as usize).min(gy) {
                for x in (a.x.floor().max(0.0) as usize)..(b.x.ceil() as usize).min(gx) {
                    if near_convex(&hull, DVec2::new(x as f64, y as f64), 0.0) {
                        grid[y * gx + x] = false;
                    }
                }
            }
        }
    }
    // 2. Then the largest rectangles of what no hull took.
    let mut tries = 0;
    while out.len() < max_polygons && tries < 4 * max_polygons {
        tries += 1;
        let Some((x0, y0, x1, y1)) = largest_rectangle(&grid, gx, gy) else {
            break;
        };
        for y in y0..=y1 {
            grid[y * gx + x0..=y * gx + x1].fill(false);
        }
        let a = to_uv(DVec2::new(x0 as f64, y0 as f64)) + inset;
        let b = to_uv(DVec2::new((x1 + 1) as f64, (y1 + 1) as f64)) - inset;
        if a.x >= b.x || a.y >= b.y || (b.x - a.x) * (b.y - a.y) < min_area {
            break;
        }
        let rect = vec![a, DVec2::new(b.x, a.y), b, DVec2::new(a.x, b.y)];
        if let Some(poly) = clip_card(rect) {
            out.push(poly);
        }
    }
    out
}

/// The 4-connected blobs of true cells of a grid, largest first (each a list of cells).
fn blobs(grid: &[bool], w: usize, h: usize) -> Vec<Vec<usize>> {
    let mut seen = vec![false; grid.len()];
    let mut out: Vec<Vec<usize>> = Vec::new();
    for start in 0..grid.len() {
        if !grid[start] || seen[start] {
            continue;
        }
        let mut comp = vec![start];
        seen[start] = true;
        let mut k = 0;
        while k < comp.len() {
            let c = comp[k];
            k += 1;
            let (x, y) = (c % w, c / w);
            let mut visit = |n: usize| {
                if grid[n] && !seen[n] {
                    seen[n] = true;
                    comp.push(n);
                }
            };
            if x > 0 {
                visit(c - 1);
            }
            if x + 1 < w {
                visit(c + 1);
            }
            if y > 0 {
                visit(c - w);
            }
            if y + 1 < h {
                visit(c + w);
            }
        }
        out.push(comp);
    }
    out.sort_by_key(|c| std::cmp::Reverse(c.len()));
    out
}

/// The hull of a blob's cells, scaled about the blob's centre (by up to 2: the blob may
/// come from an eroded grid) as much as the grid allows: every cell the polygon comes within
/// `margin` of is true. Cell coordinates.
fn shrunk_hull(
    grid: &[bool],
    w: usize,
    h: usize,
    comp: &[usize],
    margin: f64,
) -> Option<Vec<DVec2>> {
    let at = |x: i64, y: i64| {
        x >= 0
            && y >= 0
            && (x as usize) < w
            && (y as usize) < h
            && grid[y as usize * w + x as usize]
    };
    // The hull of the cells is the hull of each row's extreme cells' corners.
    let mut rows: HashMap<usize, (usize, usize)> = HashMap::new();
    let mut centre = DVec2::ZERO;
    for &c in comp {
        let (x, y) = (c % w, c / w);
        centre += DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
        let r = rows.entry(y).or_insert((x, x));
        r.0 = r.0.min(x);
        r.1 = r.1.max(x);
    }
    centre /= comp.len() as f64;
    let mut corners = Vec::with_capacity(4 * rows.len());
    for (&y, &(x0, x1)) in &rows {
        let (y0, y1) = (y as f64, (y + 1) as f64);
        let (x0, x1) = (x0 as f64, (x1 + 1) as f64);
        corners.extend([
            DVec2::new(x0, y0),
            DVec2::new(x0, y1),
            DVec2::new(x1, y0),
            DVec2::new(x1, y1),
        ]);
    }
    let mut hull = Vec::new();
    convex_hull(&corners, &mut hull);
    if hull.len() < 3 {
        return None;
    }
    // The polygon at scale `s` and its cell range (which may leave the grid: cells outside
    // are not opaque).
    let scaled = |s: f64| -> (Vec<DVec2>, [i64; 4]) {
        let poly: Vec<DVec2> = hull.iter().map(|&p| centre + (p - centre) * s).collect();
        let (mut lo, mut hi) = (DVec2::INFINITY, DVec2::NEG_INFINITY);
        for &p in &poly {
            lo = lo.min(p);
            hi = hi.max(p);
        }
        let range = [
            (lo.x - margin).floor() as i64,
            (lo.y - margin).floor() as i64,
            (hi.x + margin).floor() as i64,
            (hi.y + margin).floor() as i64,
        ];
        (poly, range)
    };
    // The cells that are not opaque within reach of the largest polygon tried, listed once.
    let [rx0, ry0, rx1, ry1] = scaled(2.0).1;
    let mut closed = Vec::new();
    for y in ry0..=ry1 {
        for x in rx0..=rx1 {
            if !at(x, y) {
                closed.push((x, y));
            }
        }
    }
    let fits = |s: f64| -> bool {
        let (poly, [x0, y0, x1, y1]) = scaled(s);
        !closed.iter().any(|&(x, y)| {
            (x0..=x1).contains(&x)
                && (y0..=y1).contains(&y)
                && near_convex(&poly, DVec2::new(x as f64, y as f64), margin)
        })
    };
    let (mut good, mut bad) = (0.0, 2.0);
    if fits(2.0) {
        good = 2.0;
    } else {
        for _ in 0..8 {
            let mid = 0.5 * (good + bad);
            if fits(mid) {
                good = mid;
            } else {
                bad = mid;
            }
        }
    }
    (good > 0.05).then(|| hull.iter().map(|&p| centre + (p - centre) * good).collect())
}

/// Whether the unit cell at `corner` comes within `margin` of the convex polygon `poly`
/// (counter-clockwise): no separating axis among the cell's axes and the polygon's edges
/// with a gap larger than `margin`.
fn near_convex(poly: &[DVec2], corner: DVec2, margin: f64) -> bool {
    let (lo, hi) = (corner, corner + DVec2::ONE);
    let (mut plo, mut phi) = (DVec2::INFINITY, DVec2::NEG_INFINITY);
    for &p in poly {
        plo = plo.min(p);
        phi = phi.max(p);
    }
    if plo.x > hi.x + margin
        || phi.x < lo.x - margin
        || plo.y > hi.y + margin
        || phi.y < lo.y - margin
    {
        return false;
    }
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        let d = b - a;
        let len = d.length();
        if len == 0.0 {
            continue;
        }
        // Outward normal of a counter-clockwise polygon.
        let n = DVec2::new(d.y, -d.x) / len;
        let reach = [lo, DVec2::new(hi.x, lo.y), hi, DVec2::new(lo.x, hi.y)]
            .iter()
            .map(|&c| n.dot(c - a))
            .fold(f64::INFINITY, f64::min);
        if reach > margin {
            return false;
        }
    }
    true
}

/// The affine map from a triangle's texture coordinates to its points:
/// `p(uv) = origin + m · (uv − uv0)`; `None` for a triangle degenerate in texture space.
#[derive(Clone, Copy, Debug)]
pub struct CardMap {
    uv0: DVec2,
    origin: DVec3,
    du: DVec3,
    dv: DVec3,
}

impl CardMap {
    /// The map of a triangle with corners `p` and texture coordinates `uv`.
    pub fn new(p: [DVec3; 3], uv: [DVec2; 3]) -> Option<CardMap> {
        let (d1, d2) = (uv[1] - uv[0], uv[2] - uv[0]);
        let det = d1.perp_dot(d2);
        let scale = d1.length() * d2.length();
        if det.abs() <= 1e-12 * scale || !det.is_finite() || !scale.is_finite() {
            return None;
        }
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        // [du dv] = [e1 e2] · [d1 d2]^-1.
        let inv = [d2.y / det, -d2.x / det, -d1.y / det, d1.x / det];
        Some(CardMap {
            uv0: uv[0],
            origin: p[0],
            du: e1 * inv[0] + e2 * inv[2],
            dv: e1 * inv[1] + e2 * inv[3],
        })
    }

    /// The point of texture coordinate `uv`.
    pub fn point(&self, uv: DVec2) -> DVec3 {
        let d = uv - self.uv0;
        self.origin + self.du * d.x + self.dv * d.y
    }
}

/// Surely opaque polygons of the cards of a scene, for the occluders.
#[derive(Clone, Debug, Default)]
pub struct CardOccluders {
    /// Per polygon: the object, its points (a convex planar polygon) and its unit normal.
    pub polygons: Vec<(u32, Vec<DVec3>, DVec3)>,
    /// Card triangles looked at.
    pub triangles: usize,
    /// World-space area of those triangles.
    pub card_area: f64,
    /// World-space area of the polygons.
    pub opaque_area: f64,
    /// The coverages built (one per texture and threshold), for per-pixel tests.
    pub coverages: Vec<std::sync::Arc<Coverage>>,
    /// The textured card triangles and their coverage in `coverages` (scene triangle
    /// indices; triangles of uniform alpha, degenerate texture maps or no alpha are not here).
    pub textured: Vec<(u32, u32)>,
}

/// Options of [`card_occluders`].
#[derive(Clone, Copy, Debug)]
pub struct CardOptions {
    /// Mip levels trusted (`None`: all).
    pub mips: Option<u32>,
    /// Most polygons per card (a planar group of triangles with one texture map).
    pub max_polygons: usize,
    /// Smallest polygon kept, as a share of its card's area.
    pub min_share: f64,
}

/// The surely opaque polygons of the card triangles `tris` (scene triangle indices with a
/// card), each tagged with `object_of(t)`. Adjacent coplanar triangles of one material with
/// one texture map whose union is convex in texture space are one card; other triangles are
/// cards alone.
pub fn card_occluders(
    cards: &AlphaCards,
    corners: &dyn Fn(usize) -> [DVec3; 3],
    tris: &[u32],
    object_of: &dyn Fn(u32) -> u32,
    opts: CardOptions,
) -> CardOccluders {
    use rayon::prelude::*;
    let mut out = CardOccluders::default();
    // Coverage per (texture, threshold).
    let mut keys: HashMap<(u32, u32), usize> = HashMap::new();
    let mut builds: Vec<(u32, f32)> = Vec::new();
    let mut cov_of: Vec<Option<usize>> = Vec::with_capacity(tris.len());
    for &t in tris {
        let c = cards.card(t as usize).expect("card triangles");
        let m = &cards.materials[c.material as usize];
        let va = c.vertex_alpha.iter().copied().fold(f32::INFINITY, f32::min);
        let k = match m.texture {
            None => {
                // Uniform alpha: the whole card or nothing (`u32::MAX` marks "whole").
                if m.factor * va >= m.cutoff + 1e-6 {
                    Some(usize::MAX)
                } else {
                    None
                }
            }
            Some(tex) if m.factor * va > 0.0 => {
                let thr = m.cutoff / (m.factor * va);
                let n = builds.len();
                Some(*keys.entry((tex, thr.to_bits())).or_insert_with(|| {
                    builds.push((tex, thr));
                    n
                }))
            }
            Some(_) => None,
        };
        cov_of.push(k);
    }
    let covs: Vec<Coverage> = builds
        .par_iter()
        .map(|&(tex, thr)| Coverage::build(&cards.textures[tex as usize], thr, opts.mips))
        .collect();

    // Group triangles into planar cards with one texture map (union-find over shared edges).
    let n = tris.len();
    let pts: Vec<[DVec3; 3]> = tris.iter().map(|&t| corners(t as usize)).collect();
    let uvs: Vec<[DVec2; 3]> = tris
        .iter()
        .map(|&t| {
            cards
                .card(t as usize)
                .expect("card")
                .uv
                .map(|v| v.as_dvec2())
        })
        .collect();
    let maps: Vec<Option<CardMap>> = (0..n).map(|i| CardMap::new(pts[i], uvs[i])).collect();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    let key = |p: DVec3, uv: DVec2| {
        [
            p.x.to_bits(),
            p.y.to_bits(),
            p.z.to_bits(),
            uv.x.to_bits(),
            uv.y.to_bits(),
        ]
    };
    let mut edges: HashMap<([u64; 5], [u64; 5]), usize> = HashMap::new();
    for i in 0..n {
        if maps[i].is_none() || cov_of[i].is_none() {
            continue;
        }
        for e in 0..3 {
            let a = key(pts[i][e], uvs[i][e]);
            let b = key(pts[i][(e + 1) % 3], uvs[i][(e + 1) % 3]);
            let k = if a < b { (a, b) } else { (b, a) };
            match edges.get(&k) {
                Some(&j) => {
                    let same =
                        cov_of[i] == cov_of[j] && object_of(tris[i]) == object_of(tris[j]) && {
                            let m = maps[j].expect("mapped");
                            let size = (pts[i][1] - pts[i][0])
                                .length()
                                .max((pts[i][2] - pts[i][0]).length());
                            (0..3).all(|v| {
                                (m.point(uvs[i][v]) - pts[i][v]).length() <= MERGE_TOLERANCE * size
                            })
                        };
                    if same {
                        let (ri, rj) = (find(&mut parent, i), find(&mut parent, j));
                        if ri != rj {
                            parent[ri] = rj;
                        }
                    }
                }
                None => {
                    edges.insert(k, i);
                }
            }
        }
    }
    drop(edges);
    let mut groups: HashMap<usize, Vec<usize>> = HashMap::new();
    for i in 0..n {
        if maps[i].is_some() && cov_of[i].is_some() {
            let r = find(&mut parent, i);
            groups.entry(r).or_default().push(i);
        }
    }
    // Each group: one convex texture-space polygon, or its triangles alone.
    let mut jobs: Vec<(usize, Vec<DVec2>)> = Vec::new();
    let mut group_list: Vec<Vec<usize>> = groups.into_values().collect();
    group_list.sort_unstable();
    for g in group_list {
        let all: Vec<DVec2> = g.iter().flat_map(|&i| uvs[i]).collect();
        let mut h = Vec::new();
        convex_hull(&all, &mut h);
        let sum: f64 = g.iter().map(|&i| area2(&uvs[i]).abs()).sum();
        if g.len() > 1 && h.len() >= 3 && (area2(&h) - sum).abs() <= 1e-6 * sum {
            jobs.push((g[0], h));
        } else {
            for &i in &g {
                jobs.push((i, uvs[i].to_vec()));
            }
        }
    }
    // Texture-space polygons per distinct (coverage, card polygon): forests repeat one model.
    let mut unique: HashMap<(usize, Vec<u64>), usize> = HashMap::new();
    let mut work: Vec<(usize, Vec<DVec2>)> = Vec::new();
    let job_key: Vec<usize> = jobs
        .iter()
        .map(|(i, poly)| {
            let c = cov_of[*i].expect("grouped cards have coverage");
            let k = (
                c,
                poly.iter()
                    .flat_map(|p| [p.x.to_bits(), p.y.to_bits()])
                    .collect(),
            );
            let n = work.len();
            *unique.entry(k).or_insert_with(|| {
                work.push((c, poly.clone()));
                n
            })
        })
        .collect();
    let results: Vec<Vec<Vec<DVec2>>> = work
        .par_iter()
        .map(|(c, poly)| {
            if *c == usize::MAX {
                return vec![poly.clone()];
            }
            let (tex, _) = builds[*c];
            let t = &cards.textures[tex as usize];
            card_polygons(
                &covs[*c],
                [t.width, t.height],
                poly,
                opts.max_polygons,
                opts.min_share,
            )
        })
        .collect();
    for ((i, poly), k) in jobs.iter().zip(&job_key) {
        let map = maps[*i].expect("mapped");
        let normal = (pts[*i][1] - pts[*i][0])
            .cross(pts[*i][2] - pts[*i][0])
            .normalize();
        let object = object_of(tris[*i]);
        let world_area = |p: &[DVec2]| {
            let q: Vec<DVec3> = p.iter().map(|&u| map.point(u)).collect();
            (1..q.len() - 1)
                .map(|k| (q[k] - q[0]).cross(q[k + 1] - q[0]).length() / 2.0)
                .sum::<f64>()
        };
        out.card_area += world_area(poly);
        for p in &results[*k] {
            out.opaque_area += world_area(p);
            out.polygons
                .push((object, p.iter().map(|&u| map.point(u)).collect(), normal));
        }
    }
    out.triangles = tris.len();
    for i in 0..n {
        if let (Some(_), Some(c)) = (maps[i], cov_of[i])
            && c != usize::MAX
        {
            out.textured.push((tris[i], c as u32));
        }
    }
    out.coverages = covs.into_iter().map(std::sync::Arc::new).collect();
    // Card area of triangles never grouped (degenerate maps or no coverage).
    for i in 0..n {
        if maps[i].is_none() || cov_of[i].is_none() {
            let p = pts[i];
            out.card_area += (p[1] - p[0]).cross(p[2] - p[0]).length() / 2.0;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tex(w: u32, h: u32, mut f: impl FnMut(u32, u32) -> u8, wrap: Wrap) -> AlphaTexture {
        let mut a = Vec::new();
        for y in 0..h {
            for x in 0..w {
                a.push(f(x, y));
            }
        }
        AlphaTexture {
            label: "test".into(),
            width: w,
            height: h,
            alpha: Arc::new(a),
            wrap: [wrap; 2],
        }
    }

    #[test]
    fn wrap_fetch_follows_the_gl_modes() {
        assert_eq!(Wrap::Repeat.fetch(-1, 4), 3);
        assert_eq!(Wrap::Repeat.fetch(5, 4), 1);
        assert_eq!(Wrap::ClampToEdge.fetch(-3, 4), 0);
        assert_eq!(Wrap::ClampToEdge.fetch(9, 4), 3);
        assert_eq!(Wrap::MirroredRepeat.fetch(4, 4), 3);
        assert_eq!(Wrap::MirroredRepeat.fetch(-1, 4), 0);
        assert_eq!(Wrap::MirroredRepeat.fetch(8, 4), 0);
    }

    #[test]
    fn segments_cover_the_range_once() {
        for wrap in [Wrap::Repeat, Wrap::MirroredRepeat, Wrap::ClampToEdge] {
            for a in -9i64..9 {
                for b in a..a + 7 {
                    let segs = segments((a, b), 4, wrap);
                    let mut seen = [false; 4];
                    for &(s, e) in segs.iter() {
                        assert!(s <= e && e < 4);
                        seen[s..=e].fill(true);
                    }
                    for x in a..=b {
                        let m = match wrap {
                            Wrap::ClampToEdge => x.clamp(0, 3),
                            w => w.fetch(x, 4),
                        };
                        assert!(seen[m as usize], "{wrap:?} {a}..{b} misses {x}");
                    }
                }
            }
        }
    }

    #[test]
    fn largest_rectangle_finds_the_block() {
        let (w, h) = (6, 5);
        let mut g = vec![false; w * h];
        for y in 1..4 {
            for x in 2..6 {
                g[y * w + x] = true;
            }
        }
        g[0] = true;
        assert_eq!(largest_rectangle(&g, w, h), Some((2, 1, 5, 3)));
        assert_eq!(largest_rectangle(&[false; 4], 2, 2), None);
    }

    /// The coverage against brute force: every point of a surely opaque half-texel cell has
    /// bilinear alpha ≥ the threshold at level 0 and at each box-filtered level.
    #[test]
    fn surely_opaque_cells_are_opaque_at_every_level() {
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as u32
        };
        for case in 0..30 {
            let w = [4, 8, 16, 6, 5][case % 5];
            let h = [8, 4, 16, 10, 7][case % 5];
            let wrap = [Wrap::Repeat, Wrap::MirroredRepeat, Wrap::ClampToEdge][case % 3];
            // Blobs of opaque texels.
            let cx = (rnd() % w) as f32;
            let cy = (rnd() % h) as f32;
            let r = 1.0 + (rnd() % 4) as f32;
            let t = tex(
                w,
                h,
                |x, y| {
                    let d = ((x as f32 - cx).powi(2) + (y as f32 - cy).powi(2)).sqrt();
                    if d < r { 255 } else { (rnd() % 200) as u8 }
                },
                wrap,
            );
            let thr = 0.5;
            for levels in [Some(1), Some(2), None] {
                let cov = Coverage::build(&t, thr, levels);
                // Reference mip chain (exact box filter) for POT textures.
                let mut chain = vec![(
                    w as usize,
                    h as usize,
                    t.alpha
                        .iter()
                        .map(|&a| a as f32 / 255.0)
                        .collect::<Vec<f32>>(),
                )];
                while chain.len() < levels.unwrap_or(99) as usize {
                    let (pw, ph, ref p) = *chain.last().unwrap();
                    if pw == 1 && ph == 1 || pw % 2 == 1 || ph % 2 == 1 {
                        break;
                    }
                    let (nw, nh) = (pw / 2, ph / 2);
                    let mut n = vec![0.0; nw * nh];
                    for y in 0..nh {
                        for x in 0..nw {
                            n[y * nw + x] = (p[2 * y * pw + 2 * x]
                                + p[2 * y * pw + 2 * x + 1]
                                + p[(2 * y + 1) * pw + 2 * x]
                                + p[(2 * y + 1) * pw + 2 * x + 1])
                                / 4.0;
                        }
                    }
                    chain.push((nw, nh, n));
                }
                for j in 0..2 * h as i64 {
                    for i in 0..2 * w as i64 {
                        if !cov.all_opaque((i, i), (j, j)) || cov.q != 1 {
                            continue;
                        }
                        for k in 0..=4 {
                            for l in 0..=4 {
                                let u = (i as f64 + k as f64 / 4.0) / (2.0 * w as f64);
                                let v = (j as f64 + l as f64 / 4.0) / (2.0 * h as f64);
                                for (lw, lh, vals) in &chain {
                                    let a = bilinear_f32(vals, *lw, *lh, wrap, u, v);
                                    assert!(
                                        a >= thr - 1e-5,
                                        "case {case} {levels:?}: cell ({i},{j}) at ({u},{v}) level {lw}x{lh}: {a}"
                                    );
                                }
                            }
                        }
                    }
                }
            }
        }
    }

    /// Bilinear sampling of a float plane (the reference of the test above).
    fn bilinear_f32(vals: &[f32], w: usize, h: usize, wrap: Wrap, u: f64, v: f64) -> f32 {
        let s = u * w as f64 - 0.5;
        let t = v * h as f64 - 0.5;
        let (x0, y0) = (s.floor(), t.floor());
        let (fx, fy) = ((s - x0) as f32, (t - y0) as f32);
        let at = |x: i64, y: i64| {
            vals[(wrap.fetch(y, h as i64) * w as i64 + wrap.fetch(x, w as i64)) as usize]
        };
        let (x0, y0) = (x0 as i64, y0 as i64);
        let top = at(x0, y0) * (1.0 - fx) + at(x0 + 1, y0) * fx;
        let bottom = at(x0, y0 + 1) * (1.0 - fx) + at(x0 + 1, y0 + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    #[test]
    fn mean_below_cutoff_leaves_nothing_with_all_levels() {
        // A quarter of the texels opaque: mip 0 has opaque cells, the full chain none.
        let t = tex(
            16,
            16,
            |x, y| if x < 8 && y < 8 { 255 } else { 0 },
            Wrap::Repeat,
        );
        assert!(Coverage::build(&t, 0.5, Some(1)).opaque_share > 0.15);
        assert_eq!(Coverage::build(&t, 0.5, None).opaque_share, 0.0);
        // Two levels: the 8×8 opaque block averages to 1 over its own 2×2 groups.
        assert!(Coverage::build(&t, 0.5, Some(2)).opaque_share > 0.1);
    }

    #[test]
    fn card_polygons_lie_in_opaque_texels() {
        // Opaque disc in a 64² texture; the card is the whole texture as a quad.
        let t = tex(
            64,
            64,
            |x, y| {
                let d = ((x as f32 - 31.5).powi(2) + (y as f32 - 31.5).powi(2)).sqrt();
                if d < 20.0 { 255 } else { 0 }
            },
            Wrap::ClampToEdge,
        );
        let cov = Coverage::build(&t, 0.5, Some(1));
        let card = [
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(0.0, 1.0),
        ];
        let polys = card_polygons(&cov, [64, 64], &card, 4, 0.01);
        assert!(!polys.is_empty());
        let total: f64 = polys.iter().map(|p| area2(p) / 2.0).sum();
        // The disc covers π·20²/64² ≈ 0.31 of the card; four rectangles take most of it.
        assert!(total > 0.15 && total < 0.31, "{total}");
        for p in &polys {
            for k in 0..p.len() {
                for s in 0..=8 {
                    let q = p[k].lerp(p[(k + 1) % p.len()], s as f64 / 8.0);
                    let a = t.bilinear(q.as_vec2());
                    assert!(a >= 0.5, "{q} has alpha {a}");
                }
            }
        }
    }

    #[test]
    fn card_map_inverts_texture_coordinates() {
        let p = [
            DVec3::new(1.0, 2.0, 3.0),
            DVec3::new(3.0, 2.0, 3.0),
            DVec3::new(1.0, 5.0, 4.0),
        ];
        let uv = [
            DVec2::new(0.1, 0.2),
            DVec2::new(0.6, 0.2),
            DVec2::new(0.1, 0.9),
        ];
        let m = CardMap::new(p, uv).unwrap();
        for i in 0..3 {
            assert!((m.point(uv[i]) - p[i]).length() < 1e-12);
        }
        assert!(CardMap::new(p, [uv[0], uv[0], uv[1]]).is_none());
    }
}
