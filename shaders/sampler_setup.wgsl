// umbrasweep — the sampler's per-polygon work on the GPU (`backend::gpu::sampler`): one
// invocation per occluder polygon, in f64 with the CPU's expressions (`Hemicube::draw_poly_with`
// and `draw_in_view` in `sampler/hemicube.rs`), writing each polygon's draws for
// `sampler.wgsl`'s fill; and the rounds' choice of clusters (`cull`, at the end).
//
// Per polygon: its vertices relative to the eye; per edge the plane through the eye and the
// edge (their sum is the Newell normal), the region's reach across the edge (the ball's ε, or
// the rectangle's extent), the polygon left out unless its plane is farther than every reach;
// per edge the unit normal toward the inside and the shrink (ε/r, or the depth-bounded one when
// smaller). Per view: the polygon clipped at Z ≥ near/2 and its projection's pixel bound cut to
// the pixels the boxes need; its depth (largest view Z, rounded up); left out when no tile it
// touches needs a depth beyond it; the bound of its shrunk silhouette (`shrunk_bound`: the pixel
// rectangle clipped by each edge's straight test); a draw appended to the view's list (an
// atomic counter that is also the view's indirect draw's instance count).
//
// What differs from the CPU only leaves pixels uncovered: the GPU takes the polygons that
// pass the per-polygon tests (the CPU's traversal also skips whole BVH nodes behind the face,
// beyond the farthest box or behind pixels already covered, none of which can cover a tested
// pixel nearer than a box; with rounds, `cull` below skips whole clusters behind what earlier
// rounds drew, and later rounds skip polygons behind it, which change no test either), and it
// leaves out polygons of more than MAXP vertices and textured cards (which it does not read).
//
// `rounding.wgsl` (f32_up, next_down, …) and `sampler_views.wgsl` are prepended to this file.

const MAXP: u32 = 8u;
const TILE: u32 = 8u;
const SQRT_2: f64 = 1.4142135623730951lf;
// `hemicube::ORIENT_TOL`: an edge's inner side is the centroid's only when the centroid lies
// well beyond rounding from the edge's plane; nearer (a degenerate or sliver polygon) the
// polygon is left out.
const ORIENT_TOL: f64 = 1e-12lf;

// f64 frame: eye (3), ε, the rectangle's half sides (2), the farthest box corner's distance.
@group(0) @binding(0) var<storage, read> frame: array<f64>;
// u32 frame: axis, sign (1: +), patch (1: a rectangle), depth-bounded (1), sub-pixel masks (1),
// resolution, polygons, capacity per view, then per view its needed pixels (i0, i1, j0, j1),
// then per view its tiles' need depths (f32 bits; view k's at tile_base(k)).
@group(0) @binding(1) var<storage, read> frame_u: array<u32>;
// Per polygon: (first point, end point, card (1) or 0, 0).
@group(0) @binding(2) var<storage, read> polys: array<vec4<u32>>;
// The polygons' points, 3 f64 each; then the clusters' boxes (`Round` below).
@group(0) @binding(3) var<storage, read> points: array<f64>;
// Draws, view k's at 2 · k · capacity (`sampler.wgsl`'s layout).
@group(0) @binding(4) var<storage, read_write> draws: array<vec4<u32>>;
// Per polygon point, the edge from it to the next (world frame): (m as f32, s as f32 · (1 + 1e-6));
// then the pixels' largest sub-pixel depths (`Round` below).
@group(0) @binding(5) var<storage, read_write> pedges: array<vec4<f32>>;
// Per polygon: its unit normal and first vertex relative to the eye (6 f64), for deep draws.
@group(0) @binding(6) var<storage, read_write> pplanes: array<f64>;
// Per view the indirect draw (6, instances, 0, 0): instances counted here; then the clusters'
// states (`Round` below).
@group(0) @binding(7) var<storage, read_write> indirect: array<atomic<u32>>;
// The round of a pass (`backend::gpu::sampler`'s `RoundParams`): its number (1, 2, …), the
// farthest distance of the clusters it decides, where the pixels' largest sub-pixel depths
// start in `pedges` (in vec4s; `sampler.wgsl`'s `reduce` writes them there, view k's at
// k · res²), where the clusters' boxes start in `points` (min then max, 6 f64 each), and the
// number of clusters. Per cluster of CLUSTER consecutive polygons, `indirect[STATE + c]` holds
// the round that draws it, 0 while undecided, CULLED once no round needs it: the CPU marks
// the first round's, `cull` the others'. Everything the rounds add shares the buffers of one
// round's render, so the set-up stays within eight storage buffers.
//
// With rounds the set-up runs only over the round's list of clusters: `indirect[R.count]`
// of them at `indirect[R.list …]` (the CPU writes the first round's, `cull` appends the
// others'), 32 invocations each; without (`R.list` NO_LIST) over every polygon.
struct Round {
    round: u32,
    limit: f32,
    pix: u32,
    boxes: u32,
    clusters: u32,
    list: u32,
    count: u32,
}
@group(0) @binding(9) var<uniform> R: Round;

const STATE: u32 = 20u;
const NO_LIST: u32 = 0xffffffffu;

// The largest sub-pixel depth of pixel `idx` after the rounds so far.
fn pixmax(idx: u32) -> f32 {
    return pedges[R.pix + idx / 4u][idx % 4u];
}

// Whether a draw no nearer than `z` could change pixel (i, j) of view k for a test: the pixel
// still has a sub-pixel beyond `z`, and some box reaching its tile needs a depth beyond `z`
// (the CPU's `View::may_lower`, pixel by pixel).
fn may_lower(k: u32, i: u32, j: u32, z: f32) -> bool {
    let res = frame_u[5];
    let tile = tile_base(k, res) + (j / TILE) * (res / TILE) + i / TILE;
    return pixmax(k * res * res + j * res + i) > z && bitcast<f32>(frame_u[tile]) > z;
}

// View k's needed pixels (i0, i1, j0, j1).
fn view_need(k: u32) -> vec4<u32> {
    return vec4<u32>(frame_u[NEED + 4u * k], frame_u[NEED + 4u * k + 1u], frame_u[NEED + 4u * k + 2u], frame_u[NEED + 4u * k + 3u]);
}

// View k's lowest v (−1 for the front view, 0 for the sides' outer halves) and rows.
fn view_vmin(k: u32) -> f64 {
    return select(0.0lf, -1.0lf, k == 0u);
}

fn view_rows(k: u32, res: u32) -> u32 {
    return select(res / 2u, res, k == 0u);
}

// Polygons per cluster (`backend::gpu::sampler::CLUSTER`).
const CLUSTER: u32 = 32u;
const CULLED: u32 = 0xffffffffu;

const NEED: u32 = 8u;

fn tile_base(k: u32, res: u32) -> u32 {
    let tw = res / TILE;
    if k == 0u {
        return NEED + 20u;
    }
    return NEED + 20u + tw * tw + (k - 1u) * tw * (res / 2u / TILE);
}

// glam's DVec3 expressions (component order and rounding as the CPU's).
fn cross3(a: vec3<f64>, b: vec3<f64>) -> vec3<f64> {
    return vec3<f64>(a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y);
}

fn dot3(a: vec3<f64>, b: vec3<f64>) -> f64 {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

fn len3(a: vec3<f64>) -> f64 {
    return sqrt(dot3(a, a));
}

// `hemicube::edge_reach`: the radius an edge is shrunk for when the render stands for a face
// rectangle, the smaller of its extent seen along the edge (`cyl`) and
// `r·h_n / √(h_n² + (r − h_w)²)` (the rectangle's supports along the plane normal `m` and
// along `t × m`), rounded up by a relative 1e-9.
fn edge_reach(cyl: f64, hb: f64, hc: f64, m: vec3<f64>, t: vec3<f64>, r: f64, b_ax: u32, c_ax: u32) -> f64 {
    let w = cross3(t, m);
    let hn = hb * abs(m[b_ax]) + hc * abs(m[c_ax]);
    let hw = (hb * abs(w[b_ax]) + hc * abs(w[c_ax])) * (1.0lf + 1e-9lf);
    if !(r > hw) {
        return cyl;
    }
    let rw = r - hw;
    return min(cyl, r * hn / sqrt(hn * hn + rw * rw) * (1.0lf + 1e-9lf));
}

// View k's coordinates of a world offset (`sampler_views.wgsl`).
fn to_view(k: u32, p: vec3<f64>) -> vec3<f64> {
    return view_of(k, frame_u[0], frame_u[1], p);
}

// Widens the bound `uv` (u min, u max, v min, v max) by the projection of view point `p`.
fn widen(uv: ptr<function, vec4<f64>>, p: vec3<f64>) {
    let u = p.x / p.z;
    let v = p.y / p.z;
    *uv = vec4<f64>(min((*uv).x, u), max((*uv).y, u), min((*uv).z, v), max((*uv).w, v));
}

// `hemicube::round_up`: z · (1 + 1e-6) rounded up to f32.
fn round_up(z: f64) -> f32 {
    return f32_up(z * (1.0lf + 1e-6lf));
}

// `shrunk_bound`: the pixels of [i0, i1) × [j0, j1) that can meet the shrunk silhouette of the
// edges `ev`, as (i0, i1, j0, j1), or i0 ≥ i1 when none can.
fn shrunk_bound(ev: ptr<function, array<vec4<f32>, 8>>, ne: u32, px: vec4<u32>, ps: f64, vmin: f64) -> vec4<u32> {
    let u0 = -1.0lf + f64(px.x) * ps;
    let u1 = -1.0lf + f64(px.y) * ps;
    let v0 = vmin + f64(px.z) * ps;
    let v1 = vmin + f64(px.w) * ps;
    let nu = clamp(0.0lf, u0, u1);
    let nv = clamp(0.0lf, v0, v1);
    let l = sqrt(nu * nu + nv * nv + 1.0lf);
    var cur: array<vec3<f64>, 16>;
    var nxt: array<vec3<f64>, 16>;
    var n = 4u;
    cur[0] = vec3<f64>(u0, v0, 1.0lf);
    cur[1] = vec3<f64>(u1, v0, 1.0lf);
    cur[2] = vec3<f64>(u1, v1, 1.0lf);
    cur[3] = vec3<f64>(u0, v1, 1.0lf);
    for (var e = 0u; e < ne; e++) {
        let q = (*ev)[e];
        let h = vec3<f64>(f64(q.x), f64(q.y), f64(q.z) - f64(q.w) * l + 1e-5lf);
        var m = 0u;
        for (var i = 0u; i < n; i++) {
            let a = cur[i];
            let b = cur[(i + 1u) % n];
            let fa = dot3(h, a);
            let fb = dot3(h, b);
            if fa >= 0.0lf && m < 16u {
                nxt[m] = a;
                m++;
            }
            if (fa >= 0.0lf) != (fb >= 0.0lf) && m < 16u {
                nxt[m] = a + (b - a) * (fa / (fa - fb));
                m++;
            }
        }
        n = m;
        if n == 0u {
            return vec4<u32>(1u, 0u, 0u, 0u);
        }
        cur = nxt;
    }
    var lo = cur[0];
    var hi = cur[0];
    for (var i = 1u; i < n; i++) {
        lo = min(lo, cur[i]);
        hi = max(hi, cur[i]);
    }
    let bi0 = min(u32(max(floor((lo.x + 1.0lf) / ps - 1e-6lf), f64(px.x))), px.y);
    let bi1 = max(u32(min(ceil((hi.x + 1.0lf) / ps + 1e-6lf), f64(px.y))), bi0);
    let bj0 = min(u32(max(floor((lo.y - vmin) / ps - 1e-6lf), f64(px.z))), px.w);
    let bj1 = max(u32(min(ceil((hi.y - vmin) / ps + 1e-6lf), f64(px.w))), bj0);
    if bi0 < bi1 && bj0 < bj1 {
        return vec4<u32>(bi0, bi1, bj0, bj1);
    }
    return vec4<u32>(1u, 0u, 0u, 0u);
}

@compute @workgroup_size(64)
fn setup(@builtin(global_invocation_id) g: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let gid = g.x + g.y * nw.x * 64u;
    var poly = gid;
    if R.list != NO_LIST {
        let slot = gid / CLUSTER;
        if slot >= atomicLoad(&indirect[R.count]) {
            return;
        }
        poly = atomicLoad(&indirect[R.list + slot]) * CLUSTER + gid % CLUSTER;
    }
    if poly >= frame_u[6] {
        return;
    }
    if atomicLoad(&indirect[STATE + poly / CLUSTER]) != R.round {
        return;
    }
    let pr = polys[poly];
    let n = pr.y - pr.x;
    if n < 3u || n > MAXP || pr.z != 0u {
        return;
    }
    let eye = vec3<f64>(frame[0], frame[1], frame[2]);
    let eps = frame[3];
    let hb = frame[4];
    let hc = frame[5];
    let max_dist = frame[6];
    let axis = frame_u[0];
    let b_ax = (axis + 1u) % 3u;
    let c_ax = (axis + 2u) % 3u;
    var q: array<vec3<f64>, 8>;
    var centroid = vec3<f64>(0.0lf, 0.0lf, 0.0lf);
    var far = 0.0lf;
    for (var k = 0u; k < n; k++) {
        let i = 3u * (pr.x + k);
        let r = vec3<f64>(points[i], points[i + 1u], points[i + 2u]) - eye;
        q[k] = r;
        centroid += r;
        far = max(far, len3(r));
    }
    centroid /= f64(n);
    let centroid_len = len3(centroid);
    far *= f64(n);
    var cr: array<vec3<f64>, 8>;
    var reach: array<f64, 8>;
    var normal = vec3<f64>(0.0lf, 0.0lf, 0.0lf);
    var most = 0.0lf;
    for (var k = 0u; k < n; k++) {
        let a = q[k];
        let b = q[(k + 1u) % n];
        let c = cross3(a, b);
        cr[k] = c;
        normal += c;
        var rk = eps;
        if frame_u[2] == 1u {
            // glam's normalize_or_zero.
            let d = b - a;
            let rl = 1.0lf / len3(d);
            var t = vec3<f64>(0.0lf, 0.0lf, 0.0lf);
            if rl > 0.0lf && rl < 1e300lf {
                t = d * rl;
            }
            let dd = hb * abs(t[b_ax]) - hc * abs(t[c_ax]);
            rk = min(sqrt(max(hb * hb + hc * hc - dd * dd, 0.0lf)), eps);
        }
        reach[k] = rk * (1.0lf + 1e-9lf);
        most = max(most, reach[k]);
    }
    let nl = len3(normal);
    if !(nl > 0.0lf && nl < 1e300lf) {
        return;
    }
    let nn = normal / nl;
    let plane_dist = abs(dot3(nn, centroid));
    if !(plane_dist > most * (1.0lf + 1e-6lf) + 1e-12lf * centroid_len) {
        return;
    }
    let near = plane_dist;
    var m: array<vec3<f64>, 8>;
    var s: array<f64, 8>;
    for (var k = 0u; k < n; k++) {
        let a = q[k];
        let b = q[(k + 1u) % n];
        let c = cr[k];
        let cl = len3(c);
        let el = len3(b - a);
        if !(cl > 0.0lf && el > 0.0lf && cl < 1e300lf) {
            return;
        }
        var mk = c / cl;
        let side = dot3(mk, centroid);
        if !(abs(side) > ORIENT_TOL * (centroid_len * len3(a) * len3(b) / cl + far)) {
            return;
        }
        if side < 0.0lf {
            mk = -mk;
        }
        let r = cl / el;
        var rk = reach[k];
        if frame_u[2] == 1u {
            rk = edge_reach(rk, hb, hc, mk, (b - a) / el, r, b_ax, c_ax);
        }
        var sk = rk / r;
        if frame_u[3] == 1u {
            let dd = max_dist * (1.0lf + 1e-9lf);
            let den = 1.0lf - SQRT_2 * rk / sqrt(r * dd);
            if den > 0.0lf {
                sk = min(sk, sk * abs(1.0lf - r / dd) / den);
            }
        }
        m[k] = mk;
        s[k] = sk * (1.0lf + 1e-6lf);
        pedges[pr.x + k] = vec4<f32>(f32(mk.x), f32(mk.y), f32(mk.z), f32(s[k]) * (1.0 + 1e-6));
    }
    let res = frame_u[5];
    let ps = 2.0lf / f64(res);
    let half = f64(res) / 2.0lf;
    let cap = frame_u[7];
    let subpixel = frame_u[4] == 1u;
    var wrote_plane = false;
    for (var k = 0u; k < 5u; k++) {
        let need = view_need(k);
        if need.x >= need.y {
            continue;
        }
        let vmin = view_vmin(k);
        let rows = view_rows(k, res);
        let zc = 0.5lf * near;
        var zmax = -1e308lf;
        var zmin = 1e308lf;
        // The projection's bound (u min, u max, v min, v max) over the part with Z ≥ zc.
        var uv = vec4<f64>(1e308lf, -1e308lf, 1e308lf, -1e308lf);
        var any = false;
        for (var i = 0u; i < n; i++) {
            let a = to_view(k, q[i]);
            let b = to_view(k, q[(i + 1u) % n]);
            zmax = max(zmax, a.z);
            zmin = min(zmin, a.z);
            if a.z >= zc {
                widen(&uv, a);
                any = true;
            }
            if (a.z >= zc) != (b.z >= zc) {
                let t = (zc - a.z) / (b.z - a.z);
                var p = a + (b - a) * t;
                p.z = zc;
                widen(&uv, p);
                any = true;
            }
        }
        if !any {
            continue;
        }
        // Clamped before the conversion (an f64 beyond u32 has no defined u32); the CPU's
        // saturating `as usize` gives the same pixels.
        let pi0 = max(u32(clamp(floor((uv.x + 1.0lf) * half), 0.0lf, f64(res))), need.x);
        let pi1 = min(u32(clamp(ceil((uv.y + 1.0lf) * half), 0.0lf, f64(res))), need.y);
        let pj0 = max(u32(clamp(floor((uv.z - vmin) * half), 0.0lf, f64(rows))), need.z);
        let pj1 = min(u32(clamp(ceil((uv.w - vmin) * half), 0.0lf, f64(rows))), need.w);
        if pi0 >= pi1 || pj0 >= pj1 {
            continue;
        }
        let z = round_up(zmax);
        let deep = zmax - zmin > 0.05lf * zmax;
        var zs = z;
        if deep {
            zs = max(next_down(f32(zmin)), 0.0);
        }
        // A polygon no nearer than every box reaching the tiles it touches changes no test.
        let tw = res / TILE;
        let tb = tile_base(k, res);
        var lowers = false;
        for (var tj = pj0 / TILE; tj < (pj1 + TILE - 1u) / TILE && !lowers; tj++) {
            for (var ti = pi0 / TILE; ti < (pi1 + TILE - 1u) / TILE; ti++) {
                if bitcast<f32>(frame_u[tb + tj * tw + ti]) > zs {
                    lowers = true;
                    break;
                }
            }
        }
        if !lowers {
            continue;
        }
        var ev: array<vec4<f32>, 8>;
        for (var e = 0u; e < n; e++) {
            let mv = to_view(k, m[e]);
            ev[e] = vec4<f32>(f32(mv.x), f32(mv.y), f32(mv.z), f32(s[e]) * (1.0 + 1e-6));
        }
        let bound = shrunk_bound(&ev, n, vec4<u32>(pi0, pi1, pj0, pj1), ps, vmin);
        if bound.x >= bound.y {
            continue;
        }
        // After the first round: left out where every needed pixel its shrunk silhouette can
        // touch already holds all its sub-pixels nearer than it could draw (`cull`'s argument,
        // for one polygon; bounds of more than 256 pixels are drawn untested).
        if R.round > 1u && (bound.y - bound.x) * (bound.w - bound.z) <= 256u {
            let zcut = f32(f64(zs) * (1.0lf - 1e-6lf));
            var open = false;
            for (var j = bound.z; j < bound.w && !open; j++) {
                for (var i = bound.x; i < bound.y; i++) {
                    if may_lower(k, i, j, zcut) {
                        open = true;
                        break;
                    }
                }
            }
            if !open {
                continue;
            }
        }
        let thin = subpixel && (bound.y - bound.x <= 4u || bound.w - bound.z <= 4u);
        if deep && !wrote_plane {
            for (var c = 0u; c < 3u; c++) {
                pplanes[6u * poly + c] = nn[c];
                pplanes[6u * poly + 3u + c] = q[0][c];
            }
            wrote_plane = true;
        }
        let slot = atomicAdd(&indirect[4u * k + 1u], 1u);
        if slot >= cap {
            continue;
        }
        let d = 2u * (k * cap + slot);
        var plane = 0u;
        if deep {
            plane = poly + 1u;
        }
        draws[d] = vec4<u32>(pr.x, n | (u32(thin) << 16u), bitcast<u32>(z), plane);
        draws[d + 1u] = vec4<u32>(bound.x | (bound.y << 16u), bound.z | (bound.w << 16u), 0u, 0u);
    }
}

// A later round's choice, one invocation per cluster still undecided: a cluster farther than
// the round's shell waits for a later round; one within it is drawn in this round (its state
// set to the round) unless no polygon of it can lower a pixel a test reads, and then it is
// culled for good (depths only come nearer). Its polygons' covered directions hit its box
// inside the view's frustum, at view depths no nearer than the box's nearest there
// (`Hemicube::rect`'s bound, Z ≥ dist/√3), and each is drawn no nearer than the points it
// covers (its farthest depth, or a deep polygon's plane at the pixel's corners, the largest).
// So where every needed pixel of the box's rectangle already holds all its sub-pixels nearer
// than that (`pixmax`), or lies in a tile that no box needs beyond it, drawing the cluster
// changes no test. Only the work differs from drawing every polygon; a margin of a millionth
// of the depth, far above the rounding, keeps the choice on the side of drawing.
@compute @workgroup_size(64)
fn cull(@builtin(global_invocation_id) g: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let c = g.x + g.y * nw.x * 64u;
    if c >= R.clusters || atomicLoad(&indirect[STATE + c]) != 0u {
        return;
    }
    let eye = vec3<f64>(frame[0], frame[1], frame[2]);
    let b = R.boxes + 6u * c;
    let lo = vec3<f64>(points[b], points[b + 1u], points[b + 2u]) - eye;
    let hi = vec3<f64>(points[b + 3u], points[b + 4u], points[b + 5u]) - eye;
    let gap = max(max(lo, -hi), vec3<f64>(0.0lf, 0.0lf, 0.0lf));
    let dist = len3(gap);
    if dist > f64(R.limit) {
        return;
    }
    let res = frame_u[5];
    let half = f64(res) / 2.0lf;
    var lowers = false;
    for (var k = 0u; k < 5u && !lowers; k++) {
        let need = view_need(k);
        if need.x >= need.y {
            continue;
        }
        let vmin = view_vmin(k);
        let rows = view_rows(k, res);
        let va = to_view(k, lo);
        let vb = to_view(k, hi);
        let vlo = min(va, vb);
        let vhi = max(va, vb);
        let zl = max(vlo.z, dist / 1.7320508075688772lf * (1.0lf - 1e-12lf));
        if vhi.z < zl || vhi.z <= 0.0lf {
            continue;
        }
        var y0 = vlo.y;
        if k != 0u {
            y0 = max(y0, 0.0lf);
            if vhi.y < y0 {
                continue;
            }
        }
        if zl <= 0.0lf {
            lowers = true;
            break;
        }
        var u0 = vlo.x / zl;
        if vlo.x >= 0.0lf {
            u0 = vlo.x / vhi.z;
        }
        var u1 = vhi.x / vhi.z;
        if vhi.x >= 0.0lf {
            u1 = vhi.x / zl;
        }
        var v0 = y0 / zl;
        if y0 >= 0.0lf {
            v0 = y0 / vhi.z;
        }
        var v1 = vhi.y / vhi.z;
        if vhi.y >= 0.0lf {
            v1 = vhi.y / zl;
        }
        let i0 = max(u32(clamp(floor((u0 - 1e-6lf + 1.0lf) * half), 0.0lf, f64(res))), need.x);
        let i1 = min(u32(clamp(floor((u1 + 1e-6lf + 1.0lf) * half) + 1.0lf, 0.0lf, f64(res))), need.y);
        let j0 = max(u32(clamp(floor((v0 - 1e-6lf - vmin) * half), 0.0lf, f64(rows))), need.z);
        let j1 = min(u32(clamp(floor((v1 + 1e-6lf - vmin) * half) + 1.0lf, 0.0lf, f64(rows))), need.w);
        let zcut = f32(zl * (1.0lf - 1e-6lf));
        for (var j = j0; j < j1 && !lowers; j++) {
            for (var i = i0; i < i1; i++) {
                if may_lower(k, i, j, zcut) {
                    lowers = true;
                    break;
                }
            }
        }
    }
    if lowers {
        atomicStore(&indirect[STATE + c], R.round);
        let slot = atomicAdd(&indirect[R.count], 1u);
        atomicStore(&indirect[R.list + slot], c);
    } else {
        atomicStore(&indirect[STATE + c], CULLED);
    }
}
