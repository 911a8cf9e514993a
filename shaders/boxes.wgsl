// umbrasweep — occludee box tests on the GPU (`src/backend/gpu/hdm.rs`), the twin of
// `project::occludee::box_coverage`: the CPU's walk sends each box it would test on a plane
// whose map stays on the device, and the device computes the box's pixel rectangles itself, in
// f64 with the CPU's expressions, instead of the CPU computing and sending them. A box of the
// bake's resident table (`hdm::ResidentBoxes`: hierarchy nodes, objects, pieces; each written
// there the first time a test names it) is sent as its index; the others (occluder parts) go
// up whole with the submission.
//
// `box_plan` (one invocation per box) writes the box's three rectangle queries into the
// queries buffer of `hdm.wgsl` at its slot — the standard Projection's (or the part of it
// inside the plane, at an infinite Depth), then the two improved Projections' — with
// `NO_PLANE` where a query is not asked, and the box's shape (how its answer follows from
// theirs); `answer` in `hdm.wgsl` answers every query (`NO_PLANE` ones `PARTIAL`); `box_decide`
// (one invocation per box) combines the three answers as the CPU's rule does and writes the
// box's answer, the only word of it read back.
//
// Why the answers are the CPU's: the expressions are `occludee.rs`'s, in the same order, in
// f64. A driver fusing a multiply and an add moves a value by an ulp, far inside the
// rectangles' outward padding (1e-12 of their coordinates): the rectangle still holds the
// exact one, and differs from the CPU's only where a pixel boundary falls within that ulp.
//
// `rounding.wgsl` (f32_down, …) and `coverage.wgsl` (the answers' codes) are prepended to this
// file.

// (The answers' codes, `PARTIAL`, `HIDDEN`, `EMPTY` and `NO_PLANE`: `coverage.wgsl`, prepended.)

// A box's shape: its first answer's kind in the low two bits, and `IMPROVED` when a `Partial`
// first answer is followed by the improved Projections' tests.
const FIXED_PARTIAL: u32 = 0u;
const FIXED_EMPTY: u32 = 1u;
const STANDARD: u32 = 2u;
const CLIPPED: u32 = 3u;
const IMPROVED: u32 = 4u;

// Boxes sent with the submission, 6 f64 each: min x, y, z, max x, y, z.
@group(0) @binding(0) var<storage, read> boxes: array<f64>;
// First, per tested plane `p` (`box_count.z` of them), its first box test (the tests are in
// the planes' order; then the total): plane `p`'s tests are `box_meta[p] .. box_meta[p + 1]`.
// Then per box test its box: `INLINE_BOX | k` for the `k`-th of `boxes`, else its index in
// `resident`.
@group(0) @binding(1) var<storage, read> box_meta: array<u32>;
// Per tested plane, 12 f64: the cell's min (x, y, z) and max, the plane's position,
// rect_min (u, v), rect_max (u, v), padding.
@group(0) @binding(2) var<storage, read> frames_f: array<f64>;
// Per tested plane: (axis, positive | improved << 1, width, height).
@group(0) @binding(3) var<storage, read> frames_u: array<vec4<u32>>;
// `Query` of `hdm.wgsl`: (plane, i0 | j0 << 16, i1 | j1 << 16, depth bits).
@group(0) @binding(4) var<storage, read_write> queries: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read_write> shapes: array<u32>;
@group(0) @binding(6) var<storage, read> answers: array<u32>;
// Per box, its answer.
@group(0) @binding(8) var<storage, read_write> box_out: array<u32>;
// x: the box tests; y: the first box test's first query slot (after every rectangle test);
// z: the tested planes.
@group(0) @binding(7) var<uniform> box_count: vec4<u32>;
// The bake's occludee boxes kept on the device (`hdm::ResidentBoxes`), 6 f64 each.
@group(0) @binding(9) var<storage, read> resident: array<f64>;

// `hdm::INLINE_BOX`.
const INLINE_BOX: u32 = 0x80000000u;
// `hdm::BOX_SLOTS`: query slots per box test.
const BOX_SLOTS: u32 = 3u;

// Box test `i`'s first query slot (`WaveLayout::box_slot`).
fn box_slot(i: u32) -> u32 {
    return box_count.y + i * BOX_SLOTS;
}

// Box test `i`'s tested plane: the last whose first test is at most `i` (a plane without
// tests starts where the next one does).
fn test_plane(i: u32) -> u32 {
    var lo = 0u;
    var hi = box_count.z;
    // box_meta[lo] <= i < box_meta[hi] (the total), and lo < hi.
    while hi - lo > 1u {
        let mid = (lo + hi) / 2u;
        if box_meta[mid] <= i {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

// Box test `i`'s box: min (x, y, z), max.
fn test_box(i: u32) -> array<vec3<f64>, 2> {
    let src = box_meta[box_count.z + 1u + i];
    if (src & INLINE_BOX) != 0u {
        let o = (src & ~INLINE_BOX) * 6u;
        return array<vec3<f64>, 2>(
            vec3<f64>(boxes[o], boxes[o + 1u], boxes[o + 2u]),
            vec3<f64>(boxes[o + 3u], boxes[o + 4u], boxes[o + 5u]),
        );
    }
    let o = src * 6u;
    return array<vec3<f64>, 2>(
        vec3<f64>(resident[o], resident[o + 1u], resident[o + 2u]),
        vec3<f64>(resident[o + 3u], resident[o + 4u], resident[o + 5u]),
    );
}

struct Frame {
    cmin: vec3<f64>,
    cmax: vec3<f64>,
    position: f64,
    rmin: vec2<f64>,
    rmax: vec2<f64>,
    axis: u32,
    positive: bool,
    improved: bool,
    width: u32,
    height: u32,
}

fn frame(p: u32) -> Frame {
    let o = p * 12u;
    let u = frames_u[p];
    var f: Frame;
    f.cmin = vec3<f64>(frames_f[o], frames_f[o + 1u], frames_f[o + 2u]);
    f.cmax = vec3<f64>(frames_f[o + 3u], frames_f[o + 4u], frames_f[o + 5u]);
    f.position = frames_f[o + 6u];
    f.rmin = vec2<f64>(frames_f[o + 7u], frames_f[o + 8u]);
    f.rmax = vec2<f64>(frames_f[o + 9u], frames_f[o + 10u]);
    f.axis = u.x;
    f.positive = (u.y & 1u) == 1u;
    f.improved = (u.y & 2u) == 2u;
    f.width = u.z;
    f.height = u.w;
    return f;
}

fn side(f: Frame) -> f64 {
    return select(-1.0lf, 1.0lf, f.positive);
}

// `PlaneFrame::face`.
fn face(f: Frame) -> f64 {
    return select(f.cmin[f.axis], f.cmax[f.axis], f.positive);
}

// A pixel rectangle: `ok` false when any part of the world rectangle falls outside the plane
// (`occludee::pixel_rect`'s `None`).
struct PixelRect {
    ok: bool,
    lo: u32,
    hi: u32,
}

// `occludee::pixel_rect`: the pixels a world rectangle overlaps, rounded outward, packed
// `i | j << 16`.
fn pixel_rect(f: Frame, lo: vec2<f64>, hi: vec2<f64>) -> PixelRect {
    var r: PixelRect;
    let size = vec2<f64>(f64(f.width), f64(f.height));
    let ps = (f.rmax - f.rmin) / size;
    let pl = (lo - f.rmin) / ps;
    let ph = (hi - f.rmin) / ps;
    if !(pl.x >= 0.0lf && pl.y >= 0.0lf && ph.x <= size.x && ph.y <= size.y) {
        r.ok = false;
        return r;
    }
    let i0 = min(u32(floor(pl.x)), f.width - 1u);
    let j0 = min(u32(floor(pl.y)), f.height - 1u);
    let i1 = max(min(u32(floor(ph.x)), f.width - 1u), i0);
    let j1 = max(min(u32(floor(ph.y)), f.height - 1u), j0);
    r.ok = true;
    r.lo = i0 | (j0 << 16u);
    r.hi = i1 | (j1 << 16u);
    return r;
}

// Rust's `f64::min` / `max` of two non-NaN values.
fn fmin(a: f64, b: f64) -> f64 {
    return select(a, b, b < a);
}

fn fmax(a: f64, b: f64) -> f64 {
    return select(a, b, b > a);
}

struct WorldRect {
    lo: vec2<f64>,
    hi: vec2<f64>,
}

// `occludee::standard_rect`.
fn standard_rect(f: Frame, bmin: vec3<f64>, bmax: vec3<f64>) -> WorldRect {
    let a = f.axis;
    let ax = array<u32, 2>((a + 1u) % 3u, (a + 2u) % 3u);
    var lo = array<f64, 2>(0.0lf, 0.0lf);
    var hi = array<f64, 2>(0.0lf, 0.0lf);
    var first = true;
    let vas = array<f64, 2>(f.cmin[a], f.cmax[a]);
    let xas = array<f64, 2>(bmin[a], bmax[a]);
    for (var iv = 0u; iv < 2u; iv++) {
        for (var ix = 0u; ix < 2u; ix++) {
            let va = vas[iv];
            let t = (f.position - va) / (xas[ix] - va);
            for (var k = 0u; k < 2u; k++) {
                let c = ax[k];
                var cl = f.cmin[c];
                var ch = f.cmax[c];
                if !(t <= 1.0lf) {
                    cl = f.cmax[c];
                    ch = f.cmin[c];
                }
                var bl = bmin[c];
                var bh = bmax[c];
                if !(t >= 0.0lf) {
                    bl = bmax[c];
                    bh = bmin[c];
                }
                let l = cl + (bl - cl) * t;
                let h = ch + (bh - ch) * t;
                if first {
                    lo[k] = l;
                    hi[k] = h;
                } else {
                    lo[k] = fmin(lo[k], l);
                    hi[k] = fmax(hi[k], h);
                }
            }
            first = false;
        }
    }
    let big = fmax(fmax(abs(lo[0]), abs(hi[0])), fmax(abs(lo[1]), abs(hi[1])));
    let pad = 1e-12lf * (1.0lf + big);
    var r: WorldRect;
    r.lo = vec2<f64>(lo[0] - pad, lo[1] - pad);
    r.hi = vec2<f64>(hi[0] + pad, hi[1] + pad);
    return r;
}

// `occludee::improved_rect_at` with the eyes `eye` behind the cell's face.
fn improved_rect_at(f: Frame, bmin: vec3<f64>, bmax: vec3<f64>, eye: f64) -> WorldRect {
    let a = f.axis;
    let s = side(f);
    let fc = face(f);
    let near = select(bmax[a], bmin[a], f.positive);
    let far = select(bmin[a], bmax[a], f.positive);
    let n = s * (near - fc) + eye;
    let fr = s * (far - fc) + eye;
    let d = s * (f.position - fc) + eye;
    let ax = array<u32, 2>((a + 1u) % 3u, (a + 2u) % 3u);
    var lo = array<f64, 2>(0.0lf, 0.0lf);
    var hi = array<f64, 2>(0.0lf, 0.0lf);
    for (var k = 0u; k < 2u; k++) {
        let c = ax[k];
        let cu0 = f.cmin[c];
        let cu1 = f.cmax[c];
        let bu0 = bmin[c];
        let bu1 = bmax[c];
        let upper = cu1 + (bu1 - cu1) * d / select(fr, n, bu1 >= cu1);
        let lower = cu0 + (bu0 - cu0) * d / select(fr, n, bu0 <= cu0);
        var l = lower;
        var h = upper;
        if !(lower <= upper) {
            let m = 0.5lf * (lower + upper);
            l = m;
            h = m;
        }
        let big = fmax(fmax(abs(cu0), abs(cu1)), fmax(abs(bu0), abs(bu1)));
        let pad = 1e-12lf * (1.0lf + big) * (1.0lf + d / n);
        lo[k] = l - pad;
        hi[k] = h + pad;
    }
    var r: WorldRect;
    r.lo = vec2<f64>(lo[0], lo[1]);
    r.hi = vec2<f64>(hi[0], hi[1]);
    return r;
}

@compute @workgroup_size(64)
fn box_plan(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= box_count.x {
        return;
    }
    let p = test_plane(i);
    let slot = box_slot(i);
    let none = vec4<u32>(NO_PLANE, 0u, 0u, 0u);
    queries[slot] = none;
    queries[slot + 1u] = none;
    queries[slot + 2u] = none;
    let b = test_box(i);
    let bmin = b[0];
    let bmax = b[1];
    let f = frame(p);
    // `DAabb::overlaps` with the cell: always visible.
    if all(bmin <= f.cmax) && all(f.cmin <= bmax) {
        shapes[i] = FIXED_PARTIAL;
        return;
    }
    // `occludee::span`: not strictly beyond the face.
    let a = f.axis;
    let s = side(f);
    let near = select(bmax[a], bmin[a], f.positive);
    let far = select(bmin[a], bmax[a], f.positive);
    if s * (near - face(f)) <= 0.0lf {
        shapes[i] = FIXED_PARTIAL;
        return;
    }
    let depth = bitcast<u32>(f32_down(s * (near - f.position)));
    let in_front = s * (far - f.position) <= 0.0lf;
    let sr = standard_rect(f, bmin, bmax);
    var shape = FIXED_PARTIAL;
    let pr = pixel_rect(f, sr.lo, sr.hi);
    if pr.ok {
        queries[slot] = vec4<u32>(p, pr.lo, pr.hi, depth);
        shape = STANDARD;
    } else {
        let clo = vec2<f64>(fmax(sr.lo.x, f.rmin.x), fmax(sr.lo.y, f.rmin.y));
        let chi = vec2<f64>(fmin(sr.hi.x, f.rmax.x), fmin(sr.hi.y, f.rmax.y));
        if !(clo.x <= chi.x && clo.y <= chi.y) {
            shapes[i] = FIXED_EMPTY;
            return;
        }
        let cr = pixel_rect(f, clo, chi);
        if cr.ok {
            queries[slot] = vec4<u32>(p, cr.lo, cr.hi, INF_BITS);
            shape = CLIPPED;
        }
    }
    if in_front && f.improved {
        shape |= IMPROVED;
        let eyes = array<f64, 2>(0.0lf, f.cmax[a] - f.cmin[a]);
        for (var k = 0u; k < 2u; k++) {
            let ir = improved_rect_at(f, bmin, bmax, eyes[k]);
            let q = pixel_rect(f, ir.lo, ir.hi);
            if q.ok {
                queries[slot + 1u + k] = vec4<u32>(p, q.lo, q.hi, depth);
            }
        }
    }
    shapes[i] = shape;
}

@compute @workgroup_size(64)
fn box_decide(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= box_count.x {
        return;
    }
    let slot = box_slot(i);
    let shape = shapes[i];
    var c = PARTIAL;
    switch shape & 3u {
        case 1u: {
            c = EMPTY;
        }
        case 2u: {
            c = answers[slot];
        }
        case 3u: {
            c = select(PARTIAL, EMPTY, answers[slot] == EMPTY);
        }
        default: {
            c = PARTIAL;
        }
    }
    // (A query not asked was answered `PARTIAL`.)
    if c == PARTIAL && (shape & IMPROVED) != 0u
        && (answers[slot + 1u] == HIDDEN || answers[slot + 2u] == HIDDEN) {
        c = HIDDEN;
    }
    box_out[i] = c;
}
