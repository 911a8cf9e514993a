//! Per-occluder CPU setup for the GPU backend: projects an occluder from the cell's 8 corners
//! (f64, the same arithmetic and quick rejects as [`cpu::projection_polygon`]), builds the
//! 8 views' convex hulls, erodes every hull edge by the pixel's half-extent, and turns each edge
//! into an `f32` half-plane `n·(p − o) ≥ c` relative to the instance's pixel origin `o`, with `c`
//! rounded *up* after adding a bound on every `f32` error the fragment shader can make. The GPU
//! then only tests pixel centres (`shaders/projection.wgsl`).
//!
//! # Error bound
//!
//! The shader evaluates `nx·dx + ny·dy` with `d = centre − o` exact (`d` is a small integer plus
//! ½) and `n = n̂` rounded to `f32`, where `n̂` is the f64 inward normal scaled to
//! `|n̂ₓ| + |n̂_y| = 1` (so the half-pixel erosion is exactly `½`). With `D` the rectangle's
//! larger side in pixels (`|dx|, |dy| ≤ D`) and `u = 2⁻²⁴`:
//! * rounding `n̂` to `f32` moves the value by at most `u·D`;
//! * the product-sum in `f32` (with or without fused multiply-add) errs by at most
//!   `γ₂·(1+u)·D ≈ 2u·D`.
//!
//! So an error of `3u·D` covers correctly rounded arithmetic; we add `2⁻²¹·(D + 1)` (`8u`
//! per pixel of `D`), leaving room for GPUs whose arithmetic is a few ulps off, plus a bound
//! on the f64 error of the edge's offset. A pixel the shader accepts therefore satisfies the
//! exact f64 test with the CPU backend's [`MARGIN`], i.e. the GPU never covers a pixel the exact
//! rule would not. At 256² this is at most ~1.2·10⁻⁴ px on top of the CPU's 10⁻⁴ px.
//!
//! [`cpu::projection_polygon`]: crate::backend::cpu::projection_polygon
//! [`MARGIN`]: crate::backend::cpu::MARGIN

use crate::backend::cpu::MARGIN;
use crate::backend::{PlaneFrame, depth_up};
use glam::{DVec2, DVec3};

/// One occluder as drawn by the GPU: a pixel rectangle, its Depth and its edges.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Instance {
    /// Pixel rectangle `[x0, x1) × [y0, y1)` that may hold covered pixels: `[x0, y0, x1, y1]`.
    pub rect: [u32; 4],
    /// The occluder's Depth (maximum point Depth, rounded up to `f32`).
    pub depth: f32,
    /// First edge (index into the chunk's edge array) and number of edges.
    pub edge_range: [u32; 2],
}

/// One eroded edge: the pixel centre `p` passes when `n·(p − o) ≥ c`; stored `[nx, ny, c, 0]`.
pub type Edge = [f32; 4];

/// Extra relative error allowance of the fragment shader's product-sum, per pixel of extent.
const F32_ERR_PER_PX: f64 = 1.0 / (1u64 << 21) as f64;
/// Relative error allowance of the f64 offset computation.
const F64_REL_ERR: f64 = 8.0 * f64::EPSILON;

/// Per-plane constants of the setup.
#[derive(Clone, Debug)]
pub struct PlaneSetup {
    corners: [DVec3; 8],
    axis: usize,
    sign: f64,
    u: usize,
    v: usize,
    position: f64,
    rect_min: DVec2,
    inv_px: DVec2,
    resolution: u32,
}

impl PlaneSetup {
    /// Precomputes the plane's constants.
    pub fn new(frame: &PlaneFrame) -> Self {
        let (u, v) = frame.uv_axes();
        PlaneSetup {
            corners: frame.cell.corners(),
            axis: frame.axis,
            sign: frame.sign(),
            u,
            v,
            position: frame.position,
            rect_min: frame.rect_min,
            inv_px: DVec2::ONE / frame.pixel_size(),
            resolution: frame.resolution,
        }
    }
}

/// Reusable buffers of [`occluder`].
#[derive(Default, Debug)]
pub struct Scratch {
    projected: Vec<DVec2>,
    sorted: Vec<DVec2>,
    hull: Vec<DVec2>,
}

/// Sets up one occluder: appends its edges to `edges` (indices relative to `edge_base`) and
/// returns its instance, or `None` when it cannot cover a whole pixel (the same quick rejects
/// as the CPU backend, plus an edge that no pixel centre of the rectangle passes). On `None`,
/// `edges` is left as it was.
pub fn occluder(
    ps: &PlaneSetup,
    pts: &[DVec3],
    depth: f64,
    scratch: &mut Scratch,
    edges: &mut Vec<Edge>,
    edge_base: usize,
) -> Option<Instance> {
    let (a, s, ua, va) = (ps.axis, ps.sign, ps.u, ps.v);
    let mut lo = DVec2::NEG_INFINITY;
    let mut hi = DVec2::INFINITY;
    scratch.projected.clear();
    for &c in &ps.corners {
        let mut vlo = DVec2::INFINITY;
        let mut vhi = DVec2::NEG_INFINITY;
        for &p in pts {
            let dz = s * (p[a] - c[a]);
            if dz <= 0.0 || !dz.is_finite() {
                return None;
            }
            let t = s * (ps.position - c[a]) / dz;
            let q = DVec2::new(c[ua] + (p[ua] - c[ua]) * t, c[va] + (p[va] - c[va]) * t);
            let q = (q - ps.rect_min) * ps.inv_px;
            vlo = vlo.min(q);
            vhi = vhi.max(q);
            scratch.projected.push(q);
        }
        lo = lo.max(vlo);
        hi = hi.min(vhi);
        if hi.x.floor() - lo.x.ceil() < 1.0 || hi.y.floor() - lo.y.ceil() < 1.0 {
            return None;
        }
    }
    let r = ps.resolution as f64;
    if hi.x <= 0.0 || hi.y <= 0.0 || lo.x >= r || lo.y >= r {
        return None;
    }
    // Pixels whose whole square lies inside the bounding box: i ∈ [ceil(lo), floor(hi) − 1].
    let x0 = lo.x.ceil().max(0.0);
    let y0 = lo.y.ceil().max(0.0);
    let x1 = hi.x.floor().min(r);
    let y1 = hi.y.floor().min(r);
    if x1 <= x0 || y1 <= y0 {
        return None;
    }
    let origin = DVec2::new(x0, y0);
    // Pixel centres relative to the origin span [0.5, w − 0.5] × [0.5, h − 0.5].
    let (w, h) = (x1 - x0, y1 - y0);
    let ext = w.max(h);
    let f32_err = F32_ERR_PER_PX * (ext + 1.0);
    let cmin = DVec2::splat(0.5);
    let cmax = DVec2::new(w - 0.5, h - 0.5);

    let start = edges.len();
    let n = pts.len();
    for ci in 0..8 {
        let chunk = &scratch.projected[ci * n..(ci + 1) * n];
        hull_ccw(chunk, &mut scratch.sorted, &mut scratch.hull);
        let m = scratch.hull.len();
        if m < 3 {
            edges.truncate(start);
            return None;
        }
        for e in 0..m {
            let p0 = scratch.hull[e];
            let p1 = scratch.hull[(e + 1) % m];
            // Inward normal of a counter-clockwise edge, scaled to |nx| + |ny| = 1.
            let nrm = DVec2::new(-(p1.y - p0.y), p1.x - p0.x);
            let l1 = nrm.x.abs() + nrm.y.abs();
            if l1 == 0.0 || !l1.is_finite() {
                edges.truncate(start);
                return None;
            }
            let nh = nrm / l1;
            let rel = p0 - origin;
            let off = nh.x * rel.x + nh.y * rel.y;
            let f64_err = F64_REL_ERR * (nh.x.abs() * rel.x.abs() + nh.y.abs() * rel.y.abs());
            // n̂·d ≥ n̂·(p0 − o) + ½ + MARGIN·|n̂|₂ is the CPU's eroded test; add the error bounds.
            let c = off + 0.5 + MARGIN * nh.length() + f64_err + f32_err;
            // Range of n̂·d over the rectangle's pixel centres (a linear function: at corners).
            let (lx, hx) = if nh.x >= 0.0 {
                (nh.x * cmin.x, nh.x * cmax.x)
            } else {
                (nh.x * cmax.x, nh.x * cmin.x)
            };
            let (ly, hy) = if nh.y >= 0.0 {
                (nh.y * cmin.y, nh.y * cmax.y)
            } else {
                (nh.y * cmax.y, nh.y * cmin.y)
            };
            let (dmin, dmax) = (lx + ly, hx + hy);
            if dmax < c - f32_err {
                // No pixel centre can pass this edge, neither exactly nor on the GPU.
                edges.truncate(start);
                return None;
            }
            if dmin >= c + f32_err {
                // Every pixel centre passes, even with the GPU's error: the edge is redundant.
                continue;
            }
            let nx = flush_tiny(nh.x as f32);
            let ny = flush_tiny(nh.y as f32);
            edges.push([nx, ny, depth_up(c), 0.0]);
        }
    }
    Some(Instance {
        rect: [x0 as u32, y0 as u32, x1 as u32, y1 as u32],
        depth: depth_up(depth),
        edge_range: [(start - edge_base) as u32, (edges.len() - start) as u32],
    })
}

/// Flushes denormal-range values to zero (GPUs may): changes `n·d` by less than 10⁻³⁰·D.
fn flush_tiny(x: f32) -> f32 {
    if x.abs() < 1e-30 { 0.0 } else { x }
}

/// 2D convex hull (counter-clockwise, collinear points dropped, duplicates merged), the same
/// result as [`cpu::convex_hull`](crate::backend::cpu::convex_hull) without allocating.
/// Triangles, the common case, skip the sort.
fn hull_ccw(points: &[DVec2], sorted: &mut Vec<DVec2>, out: &mut Vec<DVec2>) {
    out.clear();
    if let [p0, p1, p2] = *points {
        let o = (p1 - p0).perp_dot(p2 - p0);
        if o > 0.0 {
            out.extend_from_slice(&[p0, p1, p2]);
        } else if o < 0.0 {
            out.extend_from_slice(&[p0, p2, p1]);
        }
        // Collinear or repeated points: no area, nothing covered (the CPU agrees).
        return;
    }
    sorted.clear();
    sorted.extend_from_slice(points);
    sorted.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    sorted.dedup();
    if sorted.len() < 3 {
        return;
    }
    let cross = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    for &p in sorted.iter() {
        while out.len() >= 2 && cross(out[out.len() - 2], out[out.len() - 1], p) <= 0.0 {
            out.pop();
        }
        out.push(p);
    }
    let lower = out.len() + 1;
    for &p in sorted.iter().rev().skip(1) {
        while out.len() >= lower && cross(out[out.len() - 2], out[out.len() - 1], p) <= 0.0 {
            out.pop();
        }
        out.push(p);
    }
    out.pop();
}

/// Emulates the fragment shader on the CPU (f32, the shader's exact expression), for tests.
pub fn emulate(res: u32, instances: &[Instance], edges: &[Edge]) -> Vec<f32> {
    let mut map = vec![f32::INFINITY; (res * res) as usize];
    for inst in instances {
        let [x0, y0, x1, y1] = inst.rect;
        let es = &edges[inst.edge_range[0] as usize..][..inst.edge_range[1] as usize];
        for j in y0..y1 {
            for i in x0..x1 {
                let dx = (i as f32 + 0.5) - x0 as f32;
                let dy = (j as f32 + 0.5) - y0 as f32;
                if es.iter().all(|e| e[0] * dx + e[1] * dy >= e[2]) {
                    let d = &mut map[(j * res + i) as usize];
                    *d = d.min(inst.depth);
                }
            }
        }
    }
    map
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::cpu::{self, convex_hull};
    use crate::backend::{OccluderSet, PlaneJob};
    use crate::geom::DAabb;

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
            resolution: res,
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

    #[test]
    fn hull_matches_the_cpu_hull() {
        let mut rng = Rng(0x9e3779b97f4a7c15);
        let (mut sorted, mut out, mut reference) = (Vec::new(), Vec::new(), Vec::new());
        for n in [3usize, 4, 5, 8, 8, 12] {
            for _ in 0..50 {
                let pts: Vec<DVec2> = (0..n)
                    .map(|_| DVec2::new(rng.range(-5.0, 5.0), rng.range(-5.0, 5.0)))
                    .collect();
                hull_ccw(&pts, &mut sorted, &mut out);
                convex_hull(&pts, &mut reference);
                assert_eq!(out.len(), reference.len());
                // Same cyclic sequence.
                let k = reference.iter().position(|p| *p == out[0]).unwrap();
                for (e, p) in out.iter().enumerate() {
                    assert_eq!(*p, reference[(k + e) % reference.len()]);
                }
            }
        }
    }

    /// How far (pixels) pixel `(i, j)`'s centre is inside the half-pixel-eroded views of
    /// `pts`, each view's hull computed on its own (no clipping): the contract's definition.
    fn view_slack(f: &PlaneFrame, pts: &[DVec3], i: u32, j: u32) -> f64 {
        let c = DVec2::new(i as f64 + 0.5, j as f64 + 0.5);
        let mut hull = Vec::new();
        let mut slack = f64::INFINITY;
        for v in f.cell.corners() {
            let q: Vec<DVec2> = pts.iter().map(|&p| f.to_pixel(f.project(v, p))).collect();
            convex_hull(&q, &mut hull);
            if hull.len() < 3 {
                return f64::NEG_INFINITY;
            }
            for e in 0..hull.len() {
                let (a, b) = (hull[e], hull[(e + 1) % hull.len()]);
                let n = DVec2::new(-(b.y - a.y), b.x - a.x);
                slack = slack.min((n.dot(c - a) - 0.5 * (n.x.abs() + n.y.abs())) / n.length());
            }
        }
        slack
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
            };
            let reference = cpu::render_job(&job);
            let ps = PlaneSetup::new(&f);
            let mut scratch = Scratch::default();
            let (mut inst, mut edges, mut which) = (Vec::new(), Vec::new(), Vec::new());
            let depth_of = |pts: &[DVec3]| {
                pts.iter()
                    .map(|&p| f.depth(p))
                    .fold(f64::NEG_INFINITY, f64::max)
            };
            for k in 0..job.occluders.len() {
                let pts = job.occluders.get(k);
                if let Some(i) = occluder(&ps, pts, depth_of(pts), &mut scratch, &mut edges, 0) {
                    inst.push(i);
                    which.push(k);
                }
            }
            let gpu = emulate(res, &inst, &edges);
            // Per-pixel check against each instance.
            for (n, ins) in inst.iter().enumerate() {
                let one = emulate(res, std::slice::from_ref(ins), &edges);
                let pts = job.occluders.get(which[n]);
                for (k, d) in one.iter().enumerate() {
                    if d.is_finite() {
                        let (i, j) = (k as u32 % res, k as u32 / res);
                        let sl = view_slack(&f, pts, i, j);
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
                        depth_up(depth_of(pts)) == *c && view_slack(&f, pts, i, j) < 1e-3
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
