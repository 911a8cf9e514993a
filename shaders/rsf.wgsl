// Ray space factorization's charts on the GPU, the twin of `src/rsf/mod.rs` (see its docs for
// the geometry and the proof, and `src/backend/gpu/rsf.rs` for the passes). Everything is
// computed in f64 (the device has `SHADER_F64`) with the CPU's expressions, margins and
// rounding to f32, so both give the same charts. `rounding.wgsl` (INF_BITS, next_up,
// f32_up, …) is prepended to this file.
//
// Charts: per chart `c`, row `j`, column `i`, the pixel `(c·res + j)·res + i` holds six f32:
// the near umbra (slope, guard, base) then the far one. `NONE` is (−inf, +inf, +inf).

struct Params {
    // Pixels per chart side.
    res: u32,
    // clear: pixels in all; insert: columns; count: occluders; test: boxes.
    n: u32,
    // Offsets (in elements) into `ints`: records, columns, entries.
    rec_off: u32,
    col_off: u32,
    ent_off: u32,
    // Offsets (in elements) into `floats`: records' floats (insert) or boxes (test), segments.
    recf_off: u32,
    seg_off: u32,
    // Workgroups along x of the dispatch (2D when more than 65535).
    groups_x: u32,
}

@group(0) @binding(0) var<uniform> P: Params;
// Frames (8 per chart, from 0), then the call's floats.
@group(0) @binding(1) var<storage, read> floats: array<f64>;
@group(0) @binding(2) var<storage, read> ints: array<u32>;
@group(0) @binding(3) var<storage, read_write> charts: array<f32>;
// [pixels written, occluders that wrote a pixel].
@group(0) @binding(4) var<storage, read_write> counters: array<atomic<u32>, 2>;
// insert: per occluder, 1 when it wrote a pixel; test: per box, 1 when it is visible.
@group(0) @binding(5) var<storage, read_write> flags: array<atomic<u32>>;

struct Umbra {
    slope: f32,
    guard: f32,
    base: f32,
}

fn inf32() -> f32 {
    return bitcast<f32>(INF_BITS);
}

fn none() -> Umbra {
    return Umbra(-inf32(), inf32(), inf32());
}

fn is_none(u: Umbra) -> bool {
    return u.guard == inf32();
}

struct Frame {
    w: f64,
    z0: f64,
    z1: f64,
    y0: f64,
    y1: f64,
    s0: f64,
    ds: f64,
}

fn frame(c: u32) -> Frame {
    let b = c * 8u;
    return Frame(floats[b], floats[b + 1u], floats[b + 2u], floats[b + 3u], floats[b + 4u],
        floats[b + 5u], floats[b + 6u]);
}

fn m_of(i: u32) -> f64 {
    return -1.0lf + 2.0lf * f64(i) / f64(P.res);
}

fn load(p: u32) -> Umbra {
    return Umbra(charts[p], charts[p + 1u], charts[p + 2u]);
}

fn store(p: u32, u: Umbra) {
    charts[p] = u.slope;
    charts[p + 1u] = u.guard;
    charts[p + 2u] = u.base;
}

fn workgroup_index(wg: vec3<u32>) -> u32 {
    return wg.y * P.groups_x + wg.x;
}

// ---- clear ----

@compute @workgroup_size(64)
fn clear(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let k = workgroup_index(wg) * 64u + lid.x;
    if k >= P.n {
        return;
    }
    store(k * 6u, none());
    store(k * 6u + 3u, none());
}

// ---- insert ----

struct Rec {
    seg: u32,
    segs: u32,
    floating: bool,
    occluder: u32,
    x_lo: f64,
    x_hi: f64,
    h_lo: f64,
    best_slope: f64,
}

fn record(r: u32) -> Rec {
    let b = P.rec_off + r * 4u;
    let f = P.recf_off + r * 4u;
    return Rec(ints[b], ints[b + 1u], ints[b + 2u] != 0u, ints[b + 3u], floats[f],
        floats[f + 1u], floats[f + 2u], floats[f + 3u]);
}

// `beaten` of `insert_chart`: the occluder cannot improve the pixel.
fn beaten(fr: Frame, near: Umbra, far: Umbra, r: Rec) -> bool {
    if r.floating {
        return !(may_fuse(fr, near, r) || may_fuse(fr, far, r));
    }
    let near_gains = is_none(near) || (r.x_lo <= f64(near.guard) && r.best_slope > f64(near.slope));
    let far_gains = is_none(far) || r.best_slope > f64(far.slope);
    return !near_gains && !far_gains;
}

fn may_fuse(fr: Frame, u: Umbra, r: Rec) -> bool {
    let v = f64(u.slope);
    var x = r.x_lo;
    if v >= 0.0lf {
        x = r.x_hi;
    }
    return !is_none(u) && f64(u.guard) <= r.x_hi && r.best_slope > v && fr.y1 + v * x >= r.h_lo;
}

// A segment's crossing by the lines of slope `m` (`Lin` on the CPU).
struct Lin {
    lo: f64,
    hi: f64,
    x0: f64,
    xs: f64,
    h0: f64,
    hs: f64,
}

fn lin(p: vec3<f64>, q: vec3<f64>, m: f64) -> Lin {
    let ap = p.y - m * p.x;
    let aq = q.y - m * q.x;
    let d = ap - aq;
    let dx = (q.x - p.x) / d;
    let dh = (q.z - p.z) / d;
    return Lin(min(ap, aq), max(ap, aq), p.x + ap * dx, -dx, p.z + ap * dh, -dh);
}

// What an occluder casts over a pixel (`PixelUmbra`): kind 0 none, 1 grounded, 2 floating.
struct Cast {
    kind: u32,
    top: Umbra,
    bot_max: f64,
    xb_min: f64,
    xb_max: f64,
}

// `pixel_umbra` and `finish_umbra`: the top point on the crossed segment whose lowest corner
// height is highest (ties: the highest end, then the first), the bottom one on the segment
// whose highest corner height is lowest (ties: the lowest end, then the first), as the CPU's
// sorted searches choose.
fn pixel_cast(fr: Frame, r: Rec, m0: f64, m1: f64, sa: f64, sb: f64) -> Cast {
    var out: Cast;
    out.kind = 0u;
    var found = false;
    var top_min = 0.0lf;
    var top_end = 0.0lf;
    var xt_min = 0.0lf;
    var xt_max = 0.0lf;
    var bot_max = 0.0lf;
    var bot_end = 0.0lf;
    var xb_min = 0.0lf;
    var xb_max = 0.0lf;
    for (var k = 0u; k < r.segs; k++) {
        let b = P.seg_off + (r.seg + k) * 6u;
        let p = vec3<f64>(floats[b], floats[b + 1u], floats[b + 2u]);
        let q = vec3<f64>(floats[b + 3u], floats[b + 4u], floats[b + 5u]);
        let dx = q.x - p.x;
        let dz = q.y - p.y;
        let l = dz - m0 * dx;
        let h = dz - m1 * dx;
        if !(l * h > 0.0lf) {
            continue;
        }
        let a = lin(p, q, m0);
        let c = lin(p, q, m1);
        if !(a.lo < sa && sb < a.hi && c.lo < sa && sb < c.hi) {
            continue;
        }
        let h0 = a.h0 + a.hs * sa;
        let h1 = a.h0 + a.hs * sb;
        let h2 = c.h0 + c.hs * sa;
        let h3 = c.h0 + c.hs * sb;
        let x0 = a.x0 + a.xs * sa;
        let x1 = a.x0 + a.xs * sb;
        let x2 = c.x0 + c.xs * sa;
        let x3 = c.x0 + c.xs * sb;
        let hmin = min(min(h0, h1), min(h2, h3));
        let hmax = max(max(h0, h1), max(h2, h3));
        let xmin = min(min(x0, x1), min(x2, x3));
        let xmax = max(max(x0, x1), max(x2, x3));
        let hi_end = max(p.z, q.z);
        let lo_end = min(p.z, q.z);
        if !found || hmin > top_min || (hmin == top_min && hi_end > top_end) {
            top_min = hmin;
            top_end = hi_end;
            xt_min = xmin;
            xt_max = xmax;
        }
        if !found || hmax < bot_max || (hmax == bot_max && lo_end < bot_end) {
            bot_max = hmax;
            bot_end = lo_end;
            xb_min = xmin;
            xb_max = xmax;
        }
        found = true;
    }
    if !found {
        return out;
    }
    // finish_umbra
    let scale = max(max(max(max(abs(xt_max), abs(xb_max)), abs(top_min)), fr.w), 1.0lf);
    let eps = 1e-9lf * scale;
    let xmin = min(xt_min, xb_min) - eps;
    let xmax = max(xt_max, xb_max) + eps;
    let tmin = top_min - eps;
    let bmax = bot_max + eps;
    let tx_min = xt_min - eps;
    let tx_max = xt_max + eps;
    if xmin <= 0.0lf || tmin <= bmax {
        return out;
    }
    var slope: f64;
    if tmin >= fr.y1 {
        slope = (tmin - fr.y1) / (tx_max + fr.w);
    } else {
        slope = (tmin - fr.y1) / tx_min;
    }
    out.top = Umbra(f32_down(slope - 1e-12lf * abs(slope)), f32_up(xmax), f32_up(bmax));
    out.bot_max = bmax;
    out.xb_min = xb_min - eps;
    out.xb_max = xb_max + eps;
    if bmax <= fr.y0 {
        out.kind = 1u;
    } else {
        out.kind = 2u;
    }
    return out;
}

// `fuse`: the floating cut fused with the near or the far umbra; `none()` when neither fuses.
fn fuse(fr: Frame, near: Umbra, far: Umbra, f: Cast) -> Umbra {
    var best = none();
    var have = false;
    for (var k = 0u; k < 2u; k++) {
        var u = near;
        if k == 1u {
            u = far;
        }
        if is_none(u) || f.top.slope <= u.slope || f.xb_min < f64(u.guard) {
            continue;
        }
        let v = f64(u.slope);
        var x = f.xb_max;
        if v >= 0.0lf {
            x = f.xb_min;
        }
        let line = fr.y1 + v * x;
        let eps = 1e-9lf * max(max(max(abs(line), abs(x)), abs(fr.y1)), 1.0lf);
        if f.bot_max > line - eps {
            continue;
        }
        let fused = Umbra(f.top.slope, max(u.guard, f.top.guard), u.base);
        if !have || fused.slope > best.slope {
            best = fused;
            have = true;
        }
    }
    return best;
}

// `insert_umbra`: adds `u` to the pixel's near and far umbrae.
struct Pair {
    near: Umbra,
    far: Umbra,
}

fn insert_umbra(px: Pair, u: Umbra) -> Pair {
    var out = px;
    let near = px.near;
    let far = px.far;
    if is_none(near) {
        out.near = u;
        return out;
    }
    if u.guard <= near.guard {
        out.near = Umbra(max(near.slope, u.slope), near.guard, max(near.base, u.base));
        if !is_none(far) {
            out.far = Umbra(max(far.slope, u.slope), far.guard, max(far.base, u.base));
        }
        return out;
    }
    if is_none(far) {
        out.far = Umbra(max(near.slope, u.slope), max(near.guard, u.guard), max(near.base, u.base));
    } else if u.slope <= far.slope {
        // Nothing to gain.
    } else if u.guard <= far.guard {
        out.far = Umbra(u.slope, far.guard, max(far.base, u.base));
    } else {
        out.far = Umbra(max(far.slope, u.slope), max(far.guard, u.guard), max(far.base, u.base));
    }
    return out;
}

// One workgroup per column of the call; its threads take the column's rows, and each pixel
// meets the column's entries (its occluders) in the call's order.
@compute @workgroup_size(64)
fn insert(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let col = workgroup_index(wg);
    if col >= P.n {
        return;
    }
    let cb = P.col_off + col * 6u;
    let c = ints[cb];
    let i = ints[cb + 1u];
    let e0 = ints[cb + 2u];
    let e1 = ints[cb + 3u];
    let jmin = ints[cb + 4u];
    let jmax = ints[cb + 5u];
    let fr = frame(c);
    let res = P.res;
    let m0 = m_of(i);
    let m1 = m_of(i + 1u);
    var written = 0u;
    for (var j = jmin + lid.x; j <= jmax; j += 64u) {
        let base = ((c * res + j) * res + i) * 6u;
        var px = Pair(load(base), load(base + 3u));
        var changed = false;
        let sa = fr.s0 + fr.ds * f64(j);
        let sb = fr.s0 + fr.ds * f64(j + 1u);
        for (var e = e0; e < e1; e++) {
            let eb = P.ent_off + e * 3u;
            if j < ints[eb + 1u] || j > ints[eb + 2u] {
                continue;
            }
            let r = record(ints[eb]);
            if beaten(fr, px.near, px.far, r) {
                continue;
            }
            let k = pixel_cast(fr, r, m0, m1, sa, sb);
            var u = k.top;
            if k.kind == 0u {
                continue;
            } else if k.kind == 2u {
                u = fuse(fr, px.near, px.far, k);
                if is_none(u) {
                    continue;
                }
            }
            px = insert_umbra(px, u);
            changed = true;
            written += 1u;
            if atomicLoad(&flags[r.occluder]) == 0u {
                atomicStore(&flags[r.occluder], 1u);
            }
        }
        if changed {
            store(base, px.near);
            store(base + 3u, px.far);
        }
    }
    if written > 0u {
        atomicAdd(&counters[0], written);
    }
}

// One thread per occluder of the call: counts those that wrote a pixel.
@compute @workgroup_size(64)
fn count(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let o = workgroup_index(wg) * 64u + lid.x;
    if o < P.n && atomicLoad(&flags[o]) != 0u {
        atomicAdd(&counters[1], 1u);
    }
}

// ---- test ----

// `Umbra::hides`.
fn hides(fr: Frame, u: Umbra, x0: f64, x1: f64, y_lo: f64, y_hi: f64) -> bool {
    let guard = f64(u.guard);
    if is_none(u) || guard > x0 {
        return false;
    }
    let margin = max(fr.y0 - y_lo, 0.0lf) * (x0 - guard) / (x1 + fr.w);
    if f64(u.base) > y_lo + margin {
        return false;
    }
    let v = f64(u.slope);
    var x = x1;
    if v >= 0.0lf {
        x = x0;
    }
    return y_hi <= fr.y1 + v * x;
}

// `Frame::rows`: (first, last, 1 when any).
fn rows(fr: Frame, lo: f64, hi: f64) -> vec3<u32> {
    let n = f64(P.res);
    let a = max(floor((lo - fr.s0) / fr.ds), 0.0lf);
    let b = min(floor((hi - fr.s0) / fr.ds), n - 1.0lf);
    if a <= b && a < n && b >= 0.0lf {
        return vec3<u32>(u32(a), u32(b), 1u);
    }
    return vec3<u32>(0u, 0u, 0u);
}

// `Frame::columns` of a box's corners (`x0 > 0`): (first, last, 1 when any).
fn columns(fr: Frame, x0: f64, x1: f64, z0: f64, z1: f64) -> vec3<u32> {
    var lo = 0.0lf;
    var hi = 0.0lf;
    var first = true;
    for (var k = 0u; k < 16u; k++) {
        var x = x0;
        if (k & 1u) != 0u {
            x = x1;
        }
        var z = z0;
        if (k & 2u) != 0u {
            z = z1;
        }
        var ex = -fr.w;
        if (k & 4u) != 0u {
            ex = 0.0lf;
        }
        var ez = fr.z0;
        if (k & 8u) != 0u {
            ez = fr.z1;
        }
        let m = (z - ez) / (x - ex);
        if first {
            lo = m;
            hi = m;
            first = false;
        } else {
            lo = min(lo, m);
            hi = max(hi, m);
        }
    }
    let n = f64(P.res);
    // As the CPU: no column when the range is empty or not a number.
    if !(lo <= hi) || lo > 1.0lf || hi < -1.0lf {
        return vec3<u32>(0u, 0u, 0u);
    }
    let a = clamp(floor((lo + 1.0lf) * 0.5lf * n) - 1.0lf, 0.0lf, n - 1.0lf);
    let b = clamp(floor((hi + 1.0lf) * 0.5lf * n) + 1.0lf, 0.0lf, n - 1.0lf);
    return vec3<u32>(u32(a), u32(b), 1u);
}

// One workgroup per (box, chart); its threads take the columns. A box found visible in any
// chart sets its flag; the others stop at their next column.
@compute @workgroup_size(64)
fn test(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let k = workgroup_index(wg);
    if k >= P.n * 4u {
        return;
    }
    let bx = k / 4u;
    let c = k % 4u;
    let fb = P.recf_off + k * 6u;
    let x0 = floats[fb];
    let x1 = floats[fb + 1u];
    let z0 = floats[fb + 2u];
    let z1 = floats[fb + 3u];
    let y_lo = floats[fb + 4u];
    let y_hi = floats[fb + 5u];
    let fr = frame(c);
    let gap = max(max(z0 - fr.z1, fr.z0 - z1), 0.0lf);
    if x1 <= -fr.w || gap > x1 + fr.w {
        return;
    }
    let x0c = max(x0, -fr.w);
    var cols = vec3<u32>(0u, P.res - 1u, 1u);
    if x0 > 0.0lf {
        cols = columns(fr, x0, x1, z0, z1);
    }
    if cols.z == 0u {
        return;
    }
    for (var i = cols.x + lid.x; i <= cols.y; i += 64u) {
        if atomicLoad(&flags[bx]) != 0u {
            return;
        }
        let m0 = m_of(i);
        let m1 = m_of(i + 1u);
        var smin = 0.0lf;
        var smax = 0.0lf;
        for (var q = 0u; q < 8u; q++) {
            var m = m0;
            if (q & 1u) != 0u {
                m = m1;
            }
            var x = x0c;
            if (q & 2u) != 0u {
                x = x1;
            }
            var z = z0;
            if (q & 4u) != 0u {
                z = z1;
            }
            let s = z - m * x;
            if q == 0u {
                smin = s;
                smax = s;
            } else {
                smin = min(smin, s);
                smax = max(smax, s);
            }
        }
        smin = max(smin, fr.z0 + min(m0 * fr.w, 0.0lf));
        smax = min(smax, fr.z1 + max(m1 * fr.w, 0.0lf));
        if smin > smax {
            continue;
        }
        let pad = 1e-9lf * (max(abs(smin), abs(smax)) + fr.ds);
        let rr = rows(fr, smin - pad, smax + pad);
        if rr.z == 0u {
            continue;
        }
        if x0 <= 0.0lf {
            atomicStore(&flags[bx], 1u);
            return;
        }
        for (var j = rr.x; j <= rr.y; j++) {
            let base = ((c * P.res + j) * P.res + i) * 6u;
            let near = load(base);
            let far = load(base + 3u);
            if !(hides(fr, far, x0, x1, y_lo, y_hi) || hides(fr, near, x0, x1, y_lo, y_hi)) {
                atomicStore(&flags[bx], 1u);
                return;
            }
        }
    }
}
