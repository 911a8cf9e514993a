//! Per-occluder CPU setup for the GPU backend. The occluder's Projection polygon is computed
//! by the kernel the CPU backend uses ([`coverage::projection_polygon`]: project the points from
//! the 8 cell corners in f64, 8 small hulls, intersected by clipping — the same quick rejects
//! and the same polygon), then each polygon edge, eroded by the pixel's half-extent along its
//! normal, becomes an `f32` half-plane `n·(p − o) ≥ c` relative to a per-occluder pixel origin
//! `o`, with `c` rounded *up* after adding a bound on every `f32` error the fragment shader can
//! make. The geometry drawn is the polygon clipped to the plane. The GPU then does the
//! per-pixel work (`shaders/projection.wgsl`).
//!
//! # Error bound
//!
//! The shader evaluates `nx·dx + ny·dy` with `d = centre − o` exact (`d` is a small integer plus
//! ½) and `n = n̂` rounded to `f32`, where `n̂` is the f64 inward normal scaled to
//! `|n̂ₓ| + |n̂_y| = 1` (so the half-pixel erosion is exactly `½`). With `D` a bound on `|dx|`,
//! `|dy|` over the fragments drawn and `u = 2⁻²⁴`:
//! * rounding `n̂` to `f32` moves the value by at most `u·D`;
//! * the product-sum in `f32` (with or without fused multiply-add) errs by at most
//!   `γ₂·(1+u)·D ≈ 2u·D`.
//!
//! So `3u·D` covers correctly rounded arithmetic (Vulkan, Metal and D3D12 require it for
//! `+` and `×`); we add `2⁻²¹·(D + 1)` (`8u` per pixel of `D`), leaving room for a GPU a few
//! ulps off, plus a bound on the f64 error of the edge's offset, and use the shared kernel's
//! [`MARGIN`] (`10⁻⁴` px) as is. A pixel the shader accepts therefore passes the CPU's exact
//! eroded test with its margin: the GPU never covers a pixel the CPU rule would not. At 256²
//! the extra shrink is at most ~1.2·10⁻⁴ px; at 2048², 10⁻³ px.
//!
//! [`coverage::projection_polygon`]: crate::backend::coverage::projection_polygon
//! [`MARGIN`]: crate::backend::coverage::MARGIN

use crate::backend::coverage::{self, MARGIN};
use crate::plane::{PlaneFrame, depth_up};
use glam::{DVec2, DVec3};

/// One vertex of an occluder's geometry: its position in pixel coordinates and the index of
/// the occluder's record in the plane's data buffer.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Vertex {
    /// Position in pixel coordinates (pixel `(i, j)` spans `[i, i+1] × [j, j+1]`).
    pub pos: [f32; 2],
    /// Index of the occluder's record in its chunk of the data buffer.
    pub record: u32,
}

/// One 16-byte word of a plane's data buffer (`array<vec4<u32>>` in the shader). An occluder
/// is a *record* `[x0 | y0 << 16, depth bits, edge count, 0]` — the pixel origin `o = (x0, y0)`
/// its edges are relative to, and its Depth (maximum point Depth rounded up to `f32`) —
/// followed by its edges `[nx, ny, c, 0]` (`f32` bits): a pixel centre `p` passes an edge when
/// `nx·(p − o).x + ny·(p − o).y ≥ c`.
pub type Word = [u32; 4];

/// Data and geometry of a run of occluders.
#[derive(Clone, Debug, Default)]
pub struct Output {
    /// Records and edges.
    pub data: Vec<Word>,
    /// Triangle list: the occluders' geometry; `record` indexes `data`.
    pub vertices: Vec<Vertex>,
}

impl Output {
    /// Empties both, keeping the allocations.
    pub fn clear(&mut self) {
        self.data.clear();
        self.vertices.clear();
    }
}

/// Relative error allowance of the fragment shader's product-sum, per pixel of extent.
const F32_ERR_PER_PX: f64 = 1.0 / (1u64 << 21) as f64;
/// Relative error allowance of the f64 offset computation.
const F64_REL_ERR: f64 = 8.0 * f64::EPSILON;
/// How far (pixels) the rasteriser may generate fragments outside the geometry polygon
/// (vertex snapping is at most 1/16 px in Vulkan, Metal and D3D12; `f32` vertices add < 10⁻³).
const RASTER_SLOP: f64 = 0.125;

/// Per-plane constants of the setup.
#[derive(Clone, Debug)]
pub struct PlaneSetup {
    frame: PlaneFrame,
    corners: [DVec3; 8],
}

impl PlaneSetup {
    /// Precomputes the plane's constants.
    pub fn new(frame: &PlaneFrame) -> Self {
        PlaneSetup {
            frame: frame.clone(),
            corners: frame.cell.corners(),
        }
    }
}

/// Reusable buffers of [`occluder`].
#[derive(Default)]
pub struct Scratch {
    polygon: coverage::Scratch,
    geometry: Vec<DVec2>,
    tmp: Vec<DVec2>,
}

/// Sets up one occluder: appends its record and edges to `out.data` and its geometry (the
/// Projection polygon clipped to the plane, as a triangle fan) to `out.vertices`. Returns
/// false, leaving `out` as it was, when it cannot cover a whole pixel: the CPU backend's quick
/// rejects, or an edge that no fragment of the geometry can pass.
pub fn occluder(
    ps: &PlaneSetup,
    pts: &[DVec3],
    depth: f64,
    scratch: &mut Scratch,
    out: &mut Output,
) -> bool {
    if !coverage::projection_polygon(&ps.frame, &ps.corners, pts, &mut scratch.polygon) {
        return false;
    }
    let poly = &scratch.polygon.poly;
    let (w, h) = (ps.frame.width as f64, ps.frame.height as f64);
    // Geometry: the polygon clipped to the plane (keeps vertex coordinates small, so neither
    // the rasteriser's clipping nor f32 vertices lose precision).
    let g = &mut scratch.geometry;
    g.clear();
    g.extend_from_slice(poly);
    for (p0, p1) in [
        (DVec2::new(0.0, 0.0), DVec2::new(w, 0.0)),
        (DVec2::new(w, 0.0), DVec2::new(w, h)),
        (DVec2::new(w, h), DVec2::new(0.0, h)),
        (DVec2::new(0.0, h), DVec2::new(0.0, 0.0)),
    ] {
        coverage::clip_half_plane(g, p0, p1, &mut scratch.tmp);
        std::mem::swap(g, &mut scratch.tmp);
        if g.len() < 3 {
            return false;
        }
    }
    let (mut lo, mut hi) = (DVec2::INFINITY, DVec2::NEG_INFINITY);
    for q in g.iter() {
        lo = lo.min(*q);
        hi = hi.max(*q);
    }
    // Pixel origin of the edges; fragments lie in [lo − slop, hi + slop] ∩ [0, w] × [0, h].
    let origin = lo.floor().max(DVec2::ZERO);
    let ext = (hi.ceil() - origin).max_element() + 1.0;
    let f32_err = F32_ERR_PER_PX * (ext + 1.0);

    let record = out.data.len();
    out.data.push([
        origin.x as u32 | (origin.y as u32) << 16,
        depth_up(depth).to_bits(),
        0,
        0,
    ]);
    let m = poly.len();
    for e in 0..m {
        let p0 = poly[e];
        let p1 = poly[(e + 1) % m];
        // Inward normal of a counter-clockwise edge, scaled to |nx| + |ny| = 1.
        let nrm = DVec2::new(-(p1.y - p0.y), p1.x - p0.x);
        let l1 = nrm.x.abs() + nrm.y.abs();
        if l1 == 0.0 || !l1.is_finite() {
            out.data.truncate(record);
            return false;
        }
        let nh = nrm / l1;
        let rel = p0 - origin;
        let off = nh.x * rel.x + nh.y * rel.y;
        let f64_err = F64_REL_ERR * (nh.x.abs() * rel.x.abs() + nh.y.abs() * rel.y.abs());
        // The CPU's eroded test is n̂·d ≥ n̂·(p0 − o) + ½ + MARGIN·|n̂|₂ (|n̂|₂ ≤ |n̂|₁ = 1);
        // add the error bounds so that the f32 test implies it.
        let c = off + 0.5 + MARGIN + f64_err + f32_err;
        // Range of n̂·d over the geometry (linear: extremes at its vertices).
        let (mut dmin, mut dmax) = (f64::INFINITY, f64::NEG_INFINITY);
        for q in g.iter() {
            let v = nh.dot(*q - origin);
            dmin = dmin.min(v);
            dmax = dmax.max(v);
        }
        if dmax + RASTER_SLOP < c - f32_err {
            // No fragment can pass this edge, neither exactly nor on the GPU.
            out.data.truncate(record);
            return false;
        }
        if dmin - RASTER_SLOP >= c + f32_err {
            // Every fragment passes, even with the GPU's error: redundant (clipped away).
            continue;
        }
        let nx = flush_tiny(nh.x as f32);
        let ny = flush_tiny(nh.y as f32);
        out.data
            .push([nx.to_bits(), ny.to_bits(), depth_up(c).to_bits(), 0]);
    }
    out.data[record][2] = (out.data.len() - record - 1) as u32;
    let rec = record as u32;
    let vert = |q: DVec2| Vertex {
        pos: [q.x as f32, q.y as f32],
        record: rec,
    };
    for k in 1..g.len() - 1 {
        out.vertices
            .extend_from_slice(&[vert(g[0]), vert(g[k]), vert(g[k + 1])]);
    }
    true
}

/// Flushes denormal-range values to zero (GPUs may): changes `n·d` by less than 10⁻³⁰·D.
fn flush_tiny(x: f32) -> f32 {
    if x.abs() < 1e-30 { 0.0 } else { x }
}

/// Emulates the pipeline on the CPU for tests: each triangle covers the pixel centres inside
/// it (closed), whose records' edges are then tested with the shader's exact `f32` expression.
pub fn emulate(res: u32, out: &Output) -> Vec<f32> {
    let mut map = vec![f32::INFINITY; (res * res) as usize];
    for tri in out.vertices.chunks_exact(3) {
        let p: [DVec2; 3] =
            std::array::from_fn(|k| DVec2::new(tri[k].pos[0] as f64, tri[k].pos[1] as f64));
        let rec = out.data[tri[0].record as usize];
        let (ox, oy) = ((rec[0] & 0xffff) as f32, (rec[0] >> 16) as f32);
        let depth = f32::from_bits(rec[1]);
        let edges = &out.data[tri[0].record as usize + 1..][..rec[2] as usize];
        let lo = p[0].min(p[1]).min(p[2]).max(DVec2::ZERO);
        let hi = p[0].max(p[1]).max(p[2]).min(DVec2::splat(res as f64));
        let area = (p[1] - p[0]).perp_dot(p[2] - p[0]);
        for j in lo.y.floor() as u32..hi.y.ceil() as u32 {
            for i in lo.x.floor() as u32..hi.x.ceil() as u32 {
                let c = DVec2::new(i as f64 + 0.5, j as f64 + 0.5);
                let inside = (0..3).all(|k| {
                    let e = (p[(k + 1) % 3] - p[k]).perp_dot(c - p[k]);
                    e * area.signum() >= 0.0
                });
                if !inside || i >= res || j >= res {
                    continue;
                }
                let dx = (i as f32 + 0.5) - ox;
                let dy = (j as f32 + 0.5) - oy;
                let pass = edges.iter().all(|e| {
                    let [nx, ny, c] = [0, 1, 2].map(|k| f32::from_bits(e[k]));
                    nx * dx + ny * dy >= c
                });
                if pass {
                    let d = &mut map[(j * res + i) as usize];
                    *d = d.min(depth);
                }
            }
        }
    }
    map
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::cpu;
    use crate::geom::DAabb;
    use crate::plane::{OccluderSet, PlaneJob};

    fn frame(res: u32, axis: usize, positive: bool) -> PlaneFrame {
        let s = if positive { 1.0 } else { -1.0 };
        PlaneFrame {
            cell: DAabb {
                min: DVec3::splat(-0.5),
                max: DVec3::splat(0.5),
            },
            axis,
            positive,
            position: 10.0 * s,
            rect_min: DVec2::new(-8.0, -8.0),
            rect_max: DVec2::new(8.0, 8.0),
            width: res,
            height: res,
        }
    }

    /// A tiny xorshift so the test needs no crate.
    struct Rng(u64);
    impl Rng {
        fn f(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        fn range(&mut self, a: f64, b: f64) -> f64 {
            a + (b - a) * self.f()
        }
    }

    /// Every pixel the emulated shader covers lies inside all 8 views of an occluder of that
    /// Depth by at least the CPU's margin; the pixels only the CPU covers are near-ties.
    #[test]
    fn emulated_gpu_covers_only_pixels_inside_all_views() {
        let mut rng = Rng(12345);
        for (res, axis, positive) in [(16, 2, true), (64, 0, false), (256, 1, true)] {
            let f = frame(res, axis, positive);
            let s = f.sign();
            let (u, v) = f.uv_axes();
            let mut occ = OccluderSet::default();
            for k in 0..200 {
                let n = if k % 3 == 0 { 8 } else { 3 };
                let (cu, cv) = (rng.range(-8.0, 8.0), rng.range(-8.0, 8.0));
                let size = rng.range(0.5, 8.0);
                let pts: Vec<DVec3> = (0..n)
                    .map(|_| {
                        let mut q = DVec3::ZERO;
                        q[u] = cu + rng.range(-size, size);
                        q[v] = cv + rng.range(-size, size);
                        q[axis] = s * rng.range(2.0, 14.0);
                        q
                    })
                    .collect();
                occ.push(pts);
            }
            let job = PlaneJob {
                frame: f.clone(),
                occluders: occ,
                slices: vec![],
                reproject: Vec::new(),
            };
            let reference = cpu::render_job(&job);
            let ps = PlaneSetup::new(&f);
            let mut scratch = Scratch::default();
            let (mut all, mut which) = (Output::default(), Vec::new());
            let depth_of = |pts: &[DVec3]| {
                pts.iter()
                    .map(|&p| f.depth(p))
                    .fold(f64::NEG_INFINITY, f64::max)
            };
            for k in 0..job.occluders.len() {
                let pts = job.occluders.get(k);
                let mut one = Output::default();
                if occluder(&ps, pts, depth_of(pts), &mut scratch, &mut one) {
                    assert!(!one.vertices.is_empty() && one.vertices.len() % 3 == 0);
                    let base = all.data.len() as u32;
                    all.data.extend_from_slice(&one.data);
                    all.vertices.extend(one.vertices.iter().map(|v| Vertex {
                        record: v.record + base,
                        ..*v
                    }));
                    which.push((k, one));
                }
            }
            let gpu = emulate(res, &all);
            // Per-pixel check against each occluder on its own.
            for (k, one) in &which {
                let one = emulate(res, one);
                let pts = job.occluders.get(*k);
                for (k, d) in one.iter().enumerate() {
                    if d.is_finite() {
                        let (i, j) = (k as u32 % res, k as u32 / res);
                        let sl = coverage::contract_slack(&f, pts, i, j);
                        assert!(sl >= MARGIN * 0.99, "({i}, {j}) at {res}²: slack {sl}");
                    }
                }
            }
            let mut cpu_only = 0;
            for (k, (g, c)) in gpu.iter().zip(&reference.depth).enumerate() {
                if c < g {
                    cpu_only += 1;
                    let (i, j) = (k as u32 % res, k as u32 / res);
                    let near = (0..job.occluders.len()).any(|o| {
                        let pts = job.occluders.get(o);
                        depth_up(depth_of(pts)) == *c
                            && coverage::contract_slack(&f, pts, i, j) < 1e-3
                    });
                    assert!(near, "CPU-only pixel ({i}, {j}) is not a near-tie");
                }
            }
            let covered = reference.covered();
            assert!(covered > 0);
            assert!(
                cpu_only * 100 <= covered,
                "{cpu_only} of {covered} pixels differ at {res}²"
            );
        }
    }
}
