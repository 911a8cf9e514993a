// umbrasweep — occluder views on the GPU (`GpuProjection::Counting`): the views of each occluder
// from the cell's 8 corners are computed in a compute pass, in f64 with the CPU's expressions
// (`backend::coverage`), and counted per fragment in one instanced draw per plane.
//
// `views` (compute, one invocation per occluder of the wave): project the occluder's points
// from the 8 corners onto its plane, in pixel units; reject it as the CPU's quick rejects do
// (a point not strictly beyond a corner, or views' bounding boxes whose intersection cannot
// hold a whole pixel, or outside the plane); take each view's convex hull (gift wrapping: each
// hull edge joins two of the points and leaves every point on its left, so the polygon is the
// hull of some of the points and never larger than the view); erode each hull edge by the
// pixel's half-extent along its normal plus the CPU's margin, its f64 error and a bound on the
// fragment shader's f32 error; keep the edges some pixel centre of the box (the intersection
// of the views' boxes, clipped to the plane, rounded outward to whole pixels) may fail; clip
// the box by them to the polygon P that holds every centre the fragment shader can pass, drop
// the edges all of P passes with room for the f32 error and shrink the box to P's pixels (the
// coverage is unchanged: the argument is at the clipping below and in `gpu/mod.rs`); and
// write a record with the box and the remaining edges. Eroding the intersection of the views
// equals intersecting the eroded views, so a pixel centre passing every edge means the whole
// pixel lies inside all 8 views of this occluder: the backend contract's coverage, counted per
// occluder, so views of different occluders never add up.
//
// `vs_counted` in `projection.wgsl` then draws the records, one instanced draw per plane.
//
// `rounding.wgsl` (f32_up, …) is prepended to this file.
//
// Record (at word `occ[i].w` of `records`):
//   records[r]         = (ox | oy << 16, depth bits, edge count or REJECT, x1 | y1 << 16)
//   records[r + 1]     = (x0 | y0 << 16, 0, 0, 0)
//   records[r + 2 + k] = (bitcast nx, bitcast ny, bitcast c, 0)       for k < edge count
// (ox, oy) is the origin of the edges' offsets, [x0, x1) × [y0, y1) the pixel box to draw.
// The CPU reserves 2 + 8·n words per occluder of n points (at most n hull edges per view).

// Points per occluder this pass takes (the CPU sets up larger ones itself).
const MAXP: u32 = 8u;
// An occluder that covers no pixel.
const REJECT: u32 = 0xffffffffu;
// `clip`: more vertices than its arrays hold.
const OVERFLOW: u32 = 0xffffffffu;
// `coverage::MARGIN`: extra erosion (pixels) for float error.
const MARGIN: f64 = 1e-4lf;
// `setup::F64_REL_ERR`: 8 ulps of f64 relative to the offset's terms.
const F64_REL_ERR: f64 = 1.7763568394002505e-15lf;
// `setup::F32_ERR_PER_PX`: 2^-21 per pixel of the box's extent.
const F32_ERR_PER_PX: f64 = 4.76837158203125e-7lf;

// Occluder points, 3 f64 each (scene coordinates).
@group(0) @binding(0) var<storage, read> points: array<f64>;
// Per occluder: (first point, point count | RESIDENT_POINTS? | plane << 8, Depth bits, record
// word in `records`).
@group(0) @binding(1) var<storage, read> occ: array<vec4<u32>>;
// Per plane, 32 f64: the 8 corners (x, y, z), rect_min (u, v), 1 / pixel size (u, v), the
// plane's position, its side (±1), then padding.
@group(0) @binding(2) var<storage, read> planes_f: array<f64>;
// Per plane: (axis, width, height, 0).
@group(0) @binding(3) var<storage, read> planes_u: array<vec4<u32>>;
@group(0) @binding(4) var<storage, read_write> records: array<vec4<u32>>;
// The bake's occluder parts' points, 3 f64 each, where it keeps them on the device: an
// occluder whose count carries RESIDENT_POINTS reads its points here (the same f64s).
@group(0) @binding(5) var<storage, read> resident_points: array<f64>;

// `wave::RESIDENT_POINTS`: the occluder's first point indexes `resident_points`.
const RESIDENT_POINTS: u32 = 0x80u;

// Point k of occluder `o`.
fn occluder_point(o: vec4<u32>, k: u32) -> vec3<f64> {
    let b = 3u * (o.x + k);
    if (o.y & RESIDENT_POINTS) != 0u {
        return vec3<f64>(resident_points[b], resident_points[b + 1u], resident_points[b + 2u]);
    }
    return vec3<f64>(points[b], points[b + 1u], points[b + 2u]);
}

// `setup::flush_tiny`: GPUs may flush denormals.
fn flush_tiny(x: f32) -> f32 {
    if abs(x) < 1e-30 {
        return 0.0;
    }
    return x;
}

fn cross2(a: vec2<f64>, b: vec2<f64>) -> f64 {
    return a.x * b.y - a.y * b.x;
}

fn reject(r: u32) {
    records[r] = vec4<u32>(0u, 0u, REJECT, 0u);
}

// Clips the convex polygon `src[0..n]` to the half-plane e.x·x + e.y·y ≥ e.z into `dst`
// (Sutherland–Hodgman); returns the new vertex count, or OVERFLOW when it would exceed 72
// (a convex polygon gains at most one vertex per clip, 68 in all, but rounding could make a
// sliver non-convex).
fn clip(
    src: ptr<function, array<vec2<f64>, 72>>,
    dst: ptr<function, array<vec2<f64>, 72>>,
    n: u32,
    e: vec3<f64>,
) -> u32 {
    var nq = 0u;
    var va = (*src)[n - 1u];
    var fa = e.x * va.x + e.y * va.y - e.z;
    for (var i = 0u; i < n; i++) {
        let vb = (*src)[i];
        let fb = e.x * vb.x + e.y * vb.y - e.z;
        if (fa >= 0.0lf) != (fb >= 0.0lf) {
            if nq == 72u {
                return OVERFLOW;
            }
            (*dst)[nq] = va + (vb - va) * (fa / (fa - fb));
            nq++;
        }
        if fb >= 0.0lf {
            if nq == 72u {
                return OVERFLOW;
            }
            (*dst)[nq] = vb;
            nq++;
        }
        va = vb;
        fa = fb;
    }
    return nq;
}

@compute @workgroup_size(64)
fn views(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let i = gid.y * groups.x * 64u + gid.x;
    if i >= arrayLength(&occ) {
        return;
    }
    let o = occ[i];
    let n = min(o.y & 0x7fu, MAXP);
    let plane = o.y >> 8u;
    let r = o.w;
    let pf = plane * 32u;
    let pu = planes_u[plane];
    let a = pu.x;
    let ua = (a + 1u) % 3u;
    let va = (a + 2u) % 3u;
    let rect_min = vec2<f64>(planes_f[pf + 24u], planes_f[pf + 25u]);
    let inv_px = vec2<f64>(planes_f[pf + 26u], planes_f[pf + 27u]);
    let position = planes_f[pf + 28u];
    let s = planes_f[pf + 29u];
    let size = vec2<f64>(f64(pu.y), f64(pu.z));

    // Every view, projected in pixel units (`coverage::projection_polygon`).
    var q: array<vec2<f64>, 64>;
    var lo = vec2<f64>(-1e300lf, -1e300lf);
    var hi = vec2<f64>(1e300lf, 1e300lf);
    for (var c = 0u; c < 8u; c++) {
        let v = vec3<f64>(planes_f[pf + 3u * c], planes_f[pf + 3u * c + 1u], planes_f[pf + 3u * c + 2u]);
        var vlo = vec2<f64>(1e300lf, 1e300lf);
        var vhi = vec2<f64>(-1e300lf, -1e300lf);
        for (var k = 0u; k < n; k++) {
            let p = occluder_point(o, k);
            let dz = s * (p[a] - v[a]);
            // Not strictly beyond the corner, or not finite (NaN fails both tests).
            if !(dz > 0.0lf && dz < 1e300lf) {
                reject(r);
                return;
            }
            let t = s * (position - v[a]) / dz;
            let pr = vec2<f64>(v[ua] + (p[ua] - v[ua]) * t, v[va] + (p[va] - v[va]) * t);
            let px = (pr - rect_min) * inv_px;
            q[c * MAXP + k] = px;
            vlo = min(vlo, px);
            vhi = max(vhi, px);
        }
        lo = max(lo, vlo);
        hi = min(hi, vhi);
        // A whole pixel needs an integer-aligned unit square inside the box.
        if floor(hi.x) - ceil(lo.x) < 1.0lf || floor(hi.y) - ceil(lo.y) < 1.0lf {
            reject(r);
            return;
        }
    }
    if hi.x <= 0.0lf || hi.y <= 0.0lf || lo.x >= size.x || lo.y >= size.y {
        reject(r);
        return;
    }
    // The pixels whose centres can pass: the box clipped to the plane, to whole pixels.
    let b0 = floor(max(lo, vec2<f64>(0.0lf, 0.0lf)));
    let b1 = ceil(min(hi, size));
    let ext = max(b1.x - b0.x, b1.y - b0.y) + 1.0lf;
    let f32_err = F32_ERR_PER_PX * (ext + 1.0lf);
    // Pixel centres relative to the origin b0 range over [0.5, b1 - b0 - 0.5].
    let dlo = vec2<f64>(0.5lf, 0.5lf);
    let dhi = b1 - b0 - vec2<f64>(0.5lf, 0.5lf);

    // The eroded edges some pixel centre of the box may fail: (nx, ny, offset, 0), the
    // offset relative to b0 and eroded by half a pixel, the margin, the f64 error and the
    // bound on the fragment shader's f32 error.
    var ed: array<vec4<f64>, 64>;
    var m = 0u;
    for (var c = 0u; c < 8u; c++) {
        let base = c * MAXP;
        // Gift wrapping from the lowest (x, then y) point, counter-clockwise: the next vertex
        // leaves every point on its left (the farthest of collinear ones).
        var start = 0u;
        for (var k = 1u; k < n; k++) {
            let pk = q[base + k];
            let ps = q[base + start];
            if pk.x < ps.x || (pk.x == ps.x && pk.y < ps.y) {
                start = k;
            }
        }
        var cur = start;
        var hull_len = 0u;
        var closed = false;
        for (var step = 0u; step <= n; step++) {
            var next = cur;
            for (var k = 0u; k < n; k++) {
                if k == cur {
                    continue;
                }
                let dk = q[base + k] - q[base + cur];
                if next == cur {
                    if dot(dk, dk) > 0.0lf {
                        next = k;
                    }
                    continue;
                }
                let dn = q[base + next] - q[base + cur];
                let cr = cross2(dn, dk);
                if cr < 0.0lf || (cr == 0.0lf && dot(dk, dk) > dot(dn, dn)) {
                    next = k;
                }
            }
            if next == cur {
                break;
            }
            // The edge cur → next, eroded (`setup::occluder`).
            let p0 = q[base + cur];
            let p1 = q[base + next];
            let nrm = vec2<f64>(-(p1.y - p0.y), p1.x - p0.x);
            let l1 = abs(nrm.x) + abs(nrm.y);
            if !(l1 > 0.0lf && l1 < 1e300lf) {
                reject(r);
                return;
            }
            let nh = nrm / l1;
            let rel = p0 - b0;
            let off = nh.x * rel.x + nh.y * rel.y;
            let f64_err = F64_REL_ERR * (abs(nh.x) * abs(rel.x) + abs(nh.y) * abs(rel.y));
            let cc = off + 0.5lf + MARGIN + f64_err + f32_err;
            // Range of nh·d over the box's pixel centres (linear: extremes at its corners).
            let dmin = min(nh.x * dlo.x, nh.x * dhi.x) + min(nh.y * dlo.y, nh.y * dhi.y);
            let dmax = max(nh.x * dlo.x, nh.x * dhi.x) + max(nh.y * dlo.y, nh.y * dhi.y);
            if dmax < cc - f32_err {
                // No pixel centre of the box passes, neither exactly nor in f32.
                reject(r);
                return;
            }
            if dmin < cc + f32_err {
                ed[m] = vec4<f64>(nh.x, nh.y, cc, 0.0lf);
                m++;
            }
            hull_len++;
            cur = next;
            if cur == start {
                closed = true;
                break;
            }
        }
        if !closed || hull_len < 3u {
            reject(r);
            return;
        }
    }

    // The region whose pixel centres can pass in the fragment shader: a centre d passing an
    // edge (offset c) in f32 has nh·d ≥ c − f32_err (the f32 bound), so it lies in
    // P = box of centres ∩ {nh·d ≥ c − f32_err} over the kept edges. Clip the box by them
    // (f64).
    // Set when P is known (np of its vertices in pa): then edges may be dropped.
    var known = false;
    var pa: array<vec2<f64>, 72>;
    var np = 0u;
    var d0 = vec2<f64>(0.0lf, 0.0lf);
    var d1 = dhi + vec2<f64>(0.5lf, 0.5lf);
    if m > 0u {
        var pb: array<vec2<f64>, 72>;
        pa[0] = dlo;
        pa[1] = vec2<f64>(dhi.x, dlo.y);
        pa[2] = dhi;
        pa[3] = vec2<f64>(dlo.x, dhi.y);
        np = 4u;
        // Two edges per step, from pa to pb and back (no copy).
        for (var k = 0u; k < m && np > 0u && np != OVERFLOW; k += 2u) {
            np = clip(&pa, &pb, np, ed[k].xyz - vec3<f64>(0.0lf, 0.0lf, f32_err));
            if np == OVERFLOW {
                break;
            }
            if k + 1u < m && np > 0u {
                np = clip(&pb, &pa, np, ed[k + 1u].xyz - vec3<f64>(0.0lf, 0.0lf, f32_err));
            } else {
                for (var i = 0u; i < np; i++) {
                    pa[i] = pb[i];
                }
            }
        }
        // An empty P (up to rounding), or an overflow, keeps the record as it is: the same
        // coverage.
        known = np > 0u && np != OVERFLOW;
        if known {
            // The edges every vertex of P passes with room for both f32 errors (and far more
            // than the f64 rounding of the vertices) are dropped together. Let Q be the box
            // cut by the kept edges: if Q held a point outside P, the segment from it to a
            // point of P would leave P across the line of a dropped edge, at a point of P,
            // a convex combination of P's vertices, which all pass that edge by the room. So
            // Q = P, and every centre passing the kept edges in f32 passes each dropped one
            // by more than the f32 error: it passes it in f32 too. The coverage is unchanged.
            var plo = pa[0];
            var phi = pa[0];
            for (var i = 1u; i < np; i++) {
                plo = min(plo, pa[i]);
                phi = max(phi, pa[i]);
            }
            // The pixels whose centres (i + 0.5) can lie in P, with room for its rounding.
            d0 = max(d0, ceil(plo - vec2<f64>(0.5lf + 1e-4lf, 0.5lf + 1e-4lf)));
            d1 = min(d1, floor(phi - vec2<f64>(0.5lf - 1e-4lf, 0.5lf - 1e-4lf)) + vec2<f64>(1.0lf, 1.0lf));
        }
    }
    // No pixel centre can lie in P: nothing passes.
    if d1.x <= d0.x || d1.y <= d0.y {
        reject(r);
        return;
    }
    // The edges all of P passes with room for both f32 errors (see above) are dropped.
    let room = 2.0lf * f32_err + 1e-6lf;
    var w = 0u;
    for (var k = 0u; k < m; k++) {
        let e = ed[k];
        var least = -1e300lf;
        if known {
            least = 1e300lf;
            for (var i = 0u; i < np; i++) {
                least = min(least, e.x * pa[i].x + e.y * pa[i].y - (e.z - f32_err));
            }
        }
        if least < room {
            records[r + 2u + w] = vec4<u32>(
                bitcast<u32>(flush_tiny(f32(e.x))),
                bitcast<u32>(flush_tiny(f32(e.y))),
                bitcast<u32>(f32_up(e.z)),
                0u,
            );
            w++;
        }
    }
    // The origin of the edges' offsets stays b0 (the f32 bound holds over the whole box); the
    // box drawn shrinks to P's pixels.
    let x0 = u32(b0.x);
    let y0 = u32(b0.y);
    let bx0 = u32(b0.x + d0.x);
    let by0 = u32(b0.y + d0.y);
    let bx1 = u32(b0.x + d1.x);
    let by1 = u32(b0.y + d1.y);
    records[r] = vec4<u32>(x0 | (y0 << 16u), o.z, w, bx1 | (by1 << 16u));
    records[r + 1u] = vec4<u32>(bx0 | (by0 << 16u), 0u, 0u, 0u);
}
