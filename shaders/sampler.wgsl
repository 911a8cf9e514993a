// umbrasweep — the shrunk-occluder sampler's hemicube on the GPU (`backend::gpu::sampler`), the
// twin of the CPU's `sampler::Hemicube`: `sampler_setup.wgsl` turns each occluder polygon into
// draws per view (edges' tests, depth, pixels to scan, plane of a deep polygon), the CPU gives
// each occludee box's parts (`Hemicube::box_rects`); this file does the per-pixel work.
//
// `vs_fill` / `fs_fill` (one render pass per view, one instance per draw, drawn indirectly with
// the count the set-up pass made): the view is drawn at 8× its resolution, one fragment per
// sub-pixel, so each of a pixel's 8 × 8 sub-pixels keeps its own nearest depth (`Min` blend
// into an `R32Float` layer). A fragment repeats the CPU's work for its pixel: the four
// corners' `f32` tests (the CPU's `√(u²+v²+1)` table, margin `CORNER_MARGIN`); all four pass →
// the whole pixel is covered; else, with sub-pixel masks and a passing corner (or a thin
// draw), the sub-pixel's bit of the CPU's `pixel_mask` in `f64`. The depth is the draw's, or
// for a deep polygon the largest plane depth at the pixel's corners, rounded up, when nearer.
// A pixel's sub-pixels all nearer than a depth is the CPU's "covered at that depth"; a box's
// part over some sub-pixels nearer is the CPU's partial-layer test. The CPU keeps at most eight
// partial layers per pixel and merges the two farthest (which only loses), so this covers at
// least what the CPU covers.
//
// `reduce` (compute): each pixel's largest sub-pixel depth (the CPU's pixel depth).
// `test` (compute, one workgroup per box part): every pixel of the part must hold a depth
// strictly nearer than the part's, or every sub-pixel of it under the part must; a failing
// pixel sets the box's flag (open). `test_tri` (compute, one invocation per triangle and view):
// the CPU's `test_triangle`, the triangle clipped in f64 to the view, each pixel row's and each
// pixel's pyramid (planes widened), each part tested as a box's. Only the flags are read back.
//
// `rounding.wgsl` (f32_up, …) and `sampler_views.wgsl` (view_of) are prepended to this file,
// and one of `sampler_blend.wgsl` (this render fill's maps) or `sampler_fill.wgsl` (the same
// fill as a compute pass, with its maps) appended.
//
// Draw (two vec4<u32> per draw, `draws`, view k's from 2 · k · capacity):
//   (first edge (the polygon's first point), edge count | thin << 16, depth bits,
//    1 + the polygon for a deep one (its plane in `pplanes`), else 0)
//   (i0 | i1 << 16, j0 | j1 << 16, 0, 0)
// Box part (`parts_u`, `parts_f`): (box, view, i0 | i1 << 16, j0 | j1 << 16) and 8 f64:
//   pu0, pu1, pv0, pv1, z, 0, 0, 0.

// `hemicube::CORNER_MARGIN`.
const CORNER_MARGIN: f32 = 4e-6;
// Beyond this a depth is infinite for the CPU too (it rounds to f32 infinity).
const F32_BIG: f64 = 3.0e38lf;

struct Params {
    // Pixels across a view.
    res: u32,
    // The view of a render pass.
    view: u32,
    // Sub-pixel masks on (1) or off (0).
    subpixel: u32,
    // Items of a compute pass.
    n: u32,
    // Pixel rows of the pass's view.
    rows: u32,
    // Workgroups along x of a 2D dispatch.
    groups_x: u32,
    // The face's axis and sign (1: +), for the views' coordinates.
    axis: u32,
    sign: u32,
    // The first draw of the pass's view.
    base: u32,
    // The triangle test: 1 when `tris` holds indices of the resident `scene_tris`.
    tri_ids: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> P: Params;

// ---------------------------------------------------------------------------------------------
// Fill

@group(0) @binding(1) var<storage, read> draws: array<vec4<u32>>;
// Per polygon point, the edge from it to the next, world frame: (m, s) (`sampler_setup.wgsl`).
@group(0) @binding(2) var<storage, read> pedges: array<vec4<f32>>;
// Per polygon its unit normal and first vertex relative to the eye (6 f64).
@group(0) @binding(3) var<storage, read> pplanes: array<f64>;
@group(0) @binding(4) var<storage, read> norms: array<f32>;

// The pass's view coordinates of a world vector (`View::map`; exact: a signed permutation).
fn view_f32(p: vec3<f32>) -> vec3<f32> {
    let a = P.axis;
    let b = (a + 1u) % 3u;
    let c = (a + 2u) % 3u;
    var s = -1.0;
    if P.sign == 1u {
        s = 1.0;
    }
    switch P.view {
        case 0u: {
            return vec3<f32>(p[b], p[c], s * p[a]);
        }
        case 1u: {
            return vec3<f32>(p[c], s * p[a], p[b]);
        }
        case 2u: {
            return vec3<f32>(p[c], s * p[a], -p[b]);
        }
        case 3u: {
            return vec3<f32>(p[b], s * p[a], p[c]);
        }
        default: {
            return vec3<f32>(p[b], s * p[a], -p[c]);
        }
    }
}

fn view_f64(p: vec3<f64>) -> vec3<f64> {
    return view_f64_k(P.view, p);
}

fn view_f64_k(k: u32, p: vec3<f64>) -> vec3<f64> {
    return view_of(k, P.axis, P.sign, p);
}

// Edge k of the polygon whose edges start at `first`, in the pass's view: (a, b, c, s).
fn edge(first: u32, k: u32) -> vec4<f32> {
    let e = pedges[first + k];
    return vec4<f32>(view_f32(e.xyz), e.w);
}

struct FillOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) @interpolate(flat) draw: u32,
}

@vertex
fn vs_fill(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> FillOut {
    let w1 = draws[2u * (P.base + ii) + 1u];
    let x0 = 8u * (w1.x & 0xffffu);
    let x1 = 8u * (w1.x >> 16u);
    let y0 = 8u * (w1.y & 0xffffu);
    let y1 = 8u * (w1.y >> 16u);
    var xs = array<u32, 6>(x0, x1, x0, x1, x1, x0);
    var ys = array<u32, 6>(y0, y0, y1, y0, y1, y1);
    let w = f32(8u * P.res);
    let h = f32(8u * P.rows);
    var out: FillOut;
    // Sub-pixel row y is texture row y (v grows with the row).
    out.pos = vec4<f32>(f32(xs[vi]) / w * 2.0 - 1.0, 1.0 - f32(ys[vi]) / h * 2.0, 0.5, 1.0);
    out.draw = P.base + ii;
    return out;
}

// The CPU's corner test: every edge passes at (u, v) with √(u²+v²+1) = l.
fn corner_passes(first: u32, count: u32, u: f32, v: f32, l: f32) -> bool {
    for (var k = 0u; k < count; k++) {
        let e = edge(first, k);
        if !(e.x * u + e.y * v + e.z - e.w * l >= CORNER_MARGIN) {
            return false;
        }
    }
    return true;
}

// Edge k's steps over the sub-pixels of the pixel with corner (u0, v0), for the CPU's
// `pixel_mask`: (c0, du, dv, kind), kind 0 when every sub-pixel passes the edge, 1 when none
// does, else 2: sub-pixel (sa, sb) passes where `c0 + sb·dv + sa·du ≥ CORNER_MARGIN`.
fn sub_edge(first: u32, k: u32, u0: f64, v0: f64, ps: f64, lmax: f64) -> vec4<f64> {
    let margin = f64(CORNER_MARGIN);
    let h = ps / 8.0lf;
    let e = edge(first, k);
    let a = f64(e.x);
    let b = f64(e.y);
    let c = f64(e.z);
    let s = f64(e.w);
    let base = a * u0 + b * v0 + c - s * lmax;
    let du = a * h;
    let dv = b * h;
    let c0 = base + min(du, 0.0lf) + min(dv, 0.0lf);
    if c0 + 7.0lf * (min(du, 0.0lf) + min(dv, 0.0lf)) >= margin {
        return vec4<f64>(c0, du, dv, 0.0lf);
    }
    if c0 + 7.0lf * (max(du, 0.0lf) + max(dv, 0.0lf)) < margin {
        return vec4<f64>(c0, du, dv, 1.0lf);
    }
    return vec4<f64>(c0, du, dv, 2.0lf);
}

// Bit (sa, sb) of the CPU's `pixel_mask` for the pixel with corner (u0, v0).
fn sub_bit(first: u32, count: u32, u0: f64, v0: f64, ps: f64, lmax: f64, sa: u32, sb: u32) -> bool {
    let margin = f64(CORNER_MARGIN);
    for (var k = 0u; k < count; k++) {
        let e = sub_edge(first, k, u0, v0, ps, lmax);
        if e.w == 0.0lf {
            continue;
        }
        if e.w == 1.0lf {
            return false;
        }
        let r = e.x + f64(sb) * e.z;
        if !(r + f64(sa) * e.y >= margin) {
            return false;
        }
    }
    return true;
}

// The plane's depth in direction (u, v, 1) (`nd`: its normal in view coordinates and offset),
// or a negative value where the CPU's is infinite.
fn plane_depth(nd: vec4<f64>, u: f64, v: f64) -> f64 {
    let w = nd.x * u + nd.y * v + nd.z;
    if !(abs(w) * F32_BIG > abs(nd.w)) {
        return -1.0lf;
    }
    let z = nd.w / w;
    if z > 0.0lf {
        return z;
    }
    return -1.0lf;
}

// Pixel (i, j) of the pass's view for a draw whose edges start at `first`: how many of its
// four corners pass every edge (the CPU's `f32` corner tests), its corner (u0, v0) and the
// largest of its corners' √(u²+v²+1), which the sub-pixel masks use. Both fills call it.
struct Pixel {
    corners: u32,
    u0: f64,
    v0: f64,
    lmax: f64,
}

fn pixel_corners(first: u32, count: u32, i: u32, j: u32) -> Pixel {
    let res = P.res;
    let ps = 2.0lf / f64(res);
    var vmin = 0.0lf;
    var nbase = (res + 1u) * (res + 1u);
    if P.view == 0u {
        vmin = -1.0lf;
        nbase = 0u;
    }
    let stride = res + 1u;
    let uc0 = f32(-1.0lf + f64(i) * ps);
    let uc1 = f32(-1.0lf + f64(i + 1u) * ps);
    let vc0 = f32(vmin + f64(j) * ps);
    let vc1 = f32(vmin + f64(j + 1u) * ps);
    let l00 = norms[nbase + j * stride + i];
    let l10 = norms[nbase + j * stride + i + 1u];
    let l01 = norms[nbase + (j + 1u) * stride + i];
    let l11 = norms[nbase + (j + 1u) * stride + i + 1u];
    var corners = 0u;
    corners += u32(corner_passes(first, count, uc0, vc0, l00));
    corners += u32(corner_passes(first, count, uc1, vc0, l10));
    corners += u32(corner_passes(first, count, uc0, vc1, l01));
    corners += u32(corner_passes(first, count, uc1, vc1, l11));
    let lmax = f64(max(max(l00, l10), max(l01, l11)));
    return Pixel(corners, -1.0lf + f64(i) * ps, vmin + f64(j) * ps, lmax);
}

// A deep polygon's plane in the pass's view (normal, offset) for `plane_depth`; `plane` is the
// draw's 1 + polygon.
fn view_plane(plane: u32) -> vec4<f64> {
    let pp = 6u * (plane - 1u);
    let nv = view_f64(vec3<f64>(pplanes[pp], pplanes[pp + 1u], pplanes[pp + 2u]));
    let qv = view_f64(vec3<f64>(pplanes[pp + 3u], pplanes[pp + 4u], pplanes[pp + 5u]));
    return vec4<f64>(nv, nv.x * qv.x + nv.y * qv.y + nv.z * qv.z);
}

// The depth a draw of depth `z` gives the pixel with corner (u0, v0): for a deep polygon
// (plane `nd`) the largest plane depth at the pixel's corners, rounded up, when nearer.
fn pixel_depth(z: f32, deep: bool, nd: vec4<f64>, u0: f64, v0: f64) -> f32 {
    if !deep {
        return z;
    }
    let ps = 2.0lf / f64(P.res);
    let u1 = u0 + ps;
    let v1 = v0 + ps;
    let d00 = plane_depth(nd, u0, v0);
    let d10 = plane_depth(nd, u1, v0);
    let d01 = plane_depth(nd, u0, v1);
    let d11 = plane_depth(nd, u1, v1);
    if min(min(d00, d10), min(d01, d11)) > 0.0lf {
        let m = max(max(d00, d10), max(d01, d11)) * (1.0lf + 1e-6lf);
        if m < F32_BIG {
            return min(f32_up(m), z);
        }
    }
    return z;
}

@fragment
fn fs_fill(in: FillOut) -> @location(0) vec4<f32> {
    let fx = u32(in.pos.x);
    let fy = u32(in.pos.y);
    let w0 = draws[2u * in.draw];
    let first = w0.x;
    let count = w0.y & 0xffffu;
    let thin = (w0.y >> 16u) != 0u;
    let px = pixel_corners(first, count, fx / 8u, fy / 8u);
    var covered = px.corners == 4u;
    if !covered && P.subpixel != 0u && (px.corners > 0u || thin) {
        let ps = 2.0lf / f64(P.res);
        covered = sub_bit(first, count, px.u0, px.v0, ps, px.lmax, fx % 8u, fy % 8u);
    }
    if !covered {
        discard;
    }
    var nd = vec4<f64>(0.0lf, 0.0lf, 0.0lf, 0.0lf);
    if w0.w != 0u {
        nd = view_plane(w0.w);
    }
    let z = pixel_depth(bitcast<f32>(w0.z), w0.w != 0u, nd, px.u0, px.v0);
    return vec4<f32>(z, 0.0, 0.0, 0.0);
}

// ---------------------------------------------------------------------------------------------
// Reduce and test

// (Bindings apart from the fill's: each pipeline's layout holds only its own.) The sub-pixel
// depths (`sub_depth`, binding 5) come from `sampler_blend.wgsl` (the render fill's `R32Float`
// layers) or `sampler_fill.wgsl` (the compute fill's `R32Uint` layers), appended to this file.
@group(0) @binding(6) var<storage, read_write> pixmax: array<f32>;
@group(0) @binding(7) var<storage, read> parts_u: array<vec4<u32>>;
@group(0) @binding(8) var<storage, read> parts_f: array<f64>;
@group(0) @binding(9) var<storage, read_write> flags: array<atomic<u32>>;

@compute @workgroup_size(64)
fn reduce(@builtin(global_invocation_id) g: vec3<u32>) {
    let idx = g.x + g.y * P.groups_x * 64u;
    let per = P.res * P.res;
    if idx >= 5u * per {
        return;
    }
    let k = idx / per;
    let p = idx % per;
    let j = p / P.res;
    let i = p % P.res;
    var rows = P.res / 2u;
    if k == 0u {
        rows = P.res;
    }
    if j >= rows {
        return;
    }
    // Only needed pixels are ever read (the tests', the set-up's and the cull's are inside
    // the views' needed rectangles).
    let need = vec4<u32>(frame_u[NEED + 4u * k], frame_u[NEED + 4u * k + 1u], frame_u[NEED + 4u * k + 2u], frame_u[NEED + 4u * k + 3u]);
    if i < need.x || i >= need.y || j < need.z || j >= need.w {
        return;
    }
    // The largest of the sub-pixels' depths, none deeper than the pixel's own (`pixel_floor`):
    // once one reaches it, so does the largest, and the rest need not be read (exactly the
    // largest of all 64).
    let w = pixel_floor(i, j, k);
    var m = 0.0;
    for (var s = 0u; s < 64u; s++) {
        m = max(m, min(fine_depth(8u * i + s % 8u, 8u * j + s / 8u, k), w));
        if m >= w {
            break;
        }
    }
    pixmax[idx] = m;
}

// The sub-pixel index (0–7) of bound `t` (pixel units) in pixel `p`, widened by a millionth
// of a sub-pixel as the CPU's `sub_covered` does.
fn sub_index(t: f64, p: u32, widen: f64) -> u32 {
    return u32(clamp(floor((t - f64(p)) * 8.0lf + widen), 0.0lf, 7.0lf));
}

@compute @workgroup_size(64)
fn test(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let r = wg.x + wg.y * P.groups_x;
    if r >= P.n {
        return;
    }
    let pu = parts_u[r];
    let bx = pu.x;
    let k = pu.y;
    let i0 = pu.z & 0xffffu;
    let i1 = pu.z >> 16u;
    let j0 = pu.w & 0xffffu;
    let j1 = pu.w >> 16u;
    let u_lo = parts_f[8u * r];
    let u_hi = parts_f[8u * r + 1u];
    let v_lo = parts_f[8u * r + 2u];
    let v_hi = parts_f[8u * r + 3u];
    let z = parts_f[8u * r + 4u];
    let w = i1 - i0;
    let n = w * (j1 - j0);
    let per = P.res * P.res;
    for (var t = li; t < n; t += 64u) {
        if atomicLoad(&flags[bx]) != 0u {
            return;
        }
        let i = i0 + t % w;
        let j = j0 + t / w;
        if f64(pixmax[k * per + j * P.res + i]) < z {
            continue;
        }
        if !subs_nearer(k, i, j, u_lo, u_hi, v_lo, v_hi, z) {
            atomicStore(&flags[bx], 1u);
            return;
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Triangles (`Hemicube::test_triangle`)

// The eye (3 f64, then one unused), then per triangle 9 f64 (scene coordinates) or, with
// `P.tri_ids`, its index in `scene_tris` (an integer, exact in f64).
@group(0) @binding(10) var<storage, read> tris: array<f64>;
// The scene's occludee triangles, 9 f32 each, uploaded once (`GpuSamplerScene::upload_triangles`):
// scene vertices are f32, so their f64 is the CPU's exactly.
@group(0) @binding(19) var<storage, read> scene_tris: array<f32>;
// Per triangle: 0 hidden, 1 open, 2 reaches the eye (its box decides).
@group(0) @binding(11) var<storage, read_write> tflags: array<atomic<u32>>;
// `sampler_setup.wgsl`'s u32 frame: the views' needed pixels at NEED.
@group(0) @binding(12) var<storage, read> frame_u: array<u32>;

const NEED: u32 = 8u;
// `test_triangle`'s widening of every clipping plane's slope.
const W: f64 = 1e-9lf;

// The CPU's `clip`: the convex polygon `poly[0..n]` cut to n·p ≥ 0, in place; the new count.
fn clip_tri(poly: ptr<function, array<vec3<f64>, 16>>, n: u32, h: vec3<f64>) -> u32 {
    var out: array<vec3<f64>, 16>;
    var m = 0u;
    for (var i = 0u; i < n; i++) {
        let a = (*poly)[i];
        let b = (*poly)[(i + 1u) % n];
        let fa = h.x * a.x + h.y * a.y + h.z * a.z;
        let fb = h.x * b.x + h.y * b.y + h.z * b.z;
        if fa >= 0.0lf && m < 16u {
            out[m] = a;
            m++;
        }
        if (fa >= 0.0lf) != (fb >= 0.0lf) && m < 16u {
            out[m] = a + (b - a) * (fa / (fa - fb));
            m++;
        }
    }
    *poly = out;
    return m;
}

// Whether the sub-pixels of pixel (i, j) of view k under the bounds (pixel units) are all
// nearer than z (`sub_covered`).
fn subs_nearer(k: u32, i: u32, j: u32, u_lo: f64, u_hi: f64, v_lo: f64, v_hi: f64, z: f64) -> bool {
    let a0 = sub_index(u_lo, i, -1e-6lf);
    let a1 = sub_index(u_hi, i, 1e-6lf);
    let b0 = sub_index(v_lo, j, -1e-6lf);
    let b1 = sub_index(v_hi, j, 1e-6lf);
    for (var b = b0; b <= b1; b++) {
        for (var a = a0; a <= a1; a++) {
            if !(f64(sub_depth(8u * i + a, 8u * j + b, k)) < z) {
                return false;
            }
        }
    }
    return true;
}

// One invocation per (triangle, view): the CPU's per-view loop of `test_triangle`.
@compute @workgroup_size(64)
fn test_tri(@builtin(global_invocation_id) g: vec3<u32>) {
    let idx = g.x + g.y * P.groups_x * 64u;
    if idx >= 5u * P.n {
        return;
    }
    let t = idx / 5u;
    let k = idx % 5u;
    if atomicLoad(&tflags[t]) != 0u {
        return;
    }
    let res = P.res;
    let ps = 2.0lf / f64(res);
    let half = f64(res) / 2.0lf;
    var vmin = 0.0lf;
    var rows = res / 2u;
    if k == 0u {
        vmin = -1.0lf;
        rows = res;
    }
    let eye = vec3<f64>(tris[0], tris[1], tris[2]);
    var poly: array<vec3<f64>, 16>;
    for (var c = 0u; c < 3u; c++) {
        var p: vec3<f64>;
        if P.tri_ids != 0u {
            let b = 9u * u32(tris[4u + t]) + 3u * c;
            p = vec3<f64>(f64(scene_tris[b]), f64(scene_tris[b + 1u]), f64(scene_tris[b + 2u]));
        } else {
            let b = 4u + 9u * t + 3u * c;
            p = vec3<f64>(tris[b], tris[b + 1u], tris[b + 2u]);
        }
        poly[c] = view_f64_k(k, p - eye);
    }
    var n = 3u;
    let vmax = vmin + f64(rows) * ps;
    n = clip_tri(&poly, n, vec3<f64>(1.0lf, 0.0lf, 1.0lf + W));
    n = clip_tri(&poly, n, vec3<f64>(-1.0lf, 0.0lf, 1.0lf + W));
    n = clip_tri(&poly, n, vec3<f64>(0.0lf, 1.0lf, -vmin + W));
    n = clip_tri(&poly, n, vec3<f64>(0.0lf, -1.0lf, vmax + W));
    if n == 0u {
        return;
    }
    var vr = vec2<f64>(1e308lf, -1e308lf);
    for (var c = 0u; c < n; c++) {
        if !(poly[c].z > 0.0lf) {
            atomicMax(&tflags[t], 2u);
            return;
        }
        let w = poly[c].y / poly[c].z;
        vr = vec2<f64>(min(vr.x, w), max(vr.y, w));
    }
    let need = vec4<u32>(frame_u[NEED + 4u * k], frame_u[NEED + 4u * k + 1u], frame_u[NEED + 4u * k + 2u], frame_u[NEED + 4u * k + 3u]);
    let j0 = u32(floor(clamp((vr.x - W - vmin) * half, 0.0lf, f64(rows))));
    let j1 = min(u32(floor(clamp((vr.y + W - vmin) * half, 0.0lf, f64(rows)))) + 1u, rows);
    let per = res * res;
    for (var j = j0; j < j1; j++) {
        let s0 = vmin + f64(j) * ps;
        let s1 = vmin + f64(j + 1u) * ps;
        var row = poly;
        var rn = clip_tri(&row, n, vec3<f64>(0.0lf, 1.0lf, -s0 + W));
        rn = clip_tri(&row, rn, vec3<f64>(0.0lf, -1.0lf, s1 + W));
        if rn == 0u {
            continue;
        }
        var ur = vec2<f64>(1e308lf, -1e308lf);
        for (var c = 0u; c < rn; c++) {
            let u = row[c].x / row[c].z;
            ur = vec2<f64>(min(ur.x, u), max(ur.y, u));
        }
        let i0 = u32(floor(clamp((ur.x - W + 1.0lf) * half, 0.0lf, f64(res))));
        let i1 = min(u32(floor(clamp((ur.y + W + 1.0lf) * half, 0.0lf, f64(res)))) + 1u, res);
        if i0 < need.x || i1 > need.y || j < need.z || j >= need.w {
            atomicMax(&tflags[t], 1u);
            return;
        }
        for (var i = i0; i < i1; i++) {
            let t0 = -1.0lf + f64(i) * ps;
            let t1 = -1.0lf + f64(i + 1u) * ps;
            var px = row;
            var pn = clip_tri(&px, rn, vec3<f64>(1.0lf, 0.0lf, -t0 + W));
            pn = clip_tri(&px, pn, vec3<f64>(-1.0lf, 0.0lf, t1 + W));
            if pn == 0u {
                continue;
            }
            var zmin = 1e308lf;
            var pu = vec2<f64>(1e308lf, -1e308lf);
            var pv = vec2<f64>(1e308lf, -1e308lf);
            for (var c = 0u; c < pn; c++) {
                zmin = min(zmin, px[c].z);
                let u = px[c].x / px[c].z;
                let v = px[c].y / px[c].z;
                pu = vec2<f64>(min(pu.x, u), max(pu.y, u));
                pv = vec2<f64>(min(pv.x, v), max(pv.y, v));
            }
            let z = zmin * (1.0lf - 1e-9lf);
            if f64(pixmax[k * per + j * res + i]) < z {
                continue;
            }
            if !subs_nearer(
                k,
                i,
                j,
                (pu.x - W + 1.0lf) * half,
                (pu.y + W + 1.0lf) * half,
                (pv.x - W - vmin) * half,
                (pv.y + W - vmin) * half,
                z,
            ) {
                atomicMax(&tflags[t], 1u);
                return;
            }
        }
    }
}
