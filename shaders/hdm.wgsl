// umbrasweep — the Hierarchical Depth Map on the GPU (`src/backend/gpu/hdm.rs`), the twin of
// `hdm::Hdm::build` and `Hdm::test`: each tested plane's Depth Map copied into a storage
// buffer (`base`), its max/min pyramid built level by level (`reduce`), and the occludee
// rectangle queries answered against it (`answer`). Depths are only compared, never computed
// with, so the answers are the CPU's bit for bit.
//
// The pyramid of a plane `w × h` starting at `base`: level 0 (the map, its own max and min)
// at `base`, then per level k ≥ 1 its max then its min, each `size(k)` texels,
// `size(k) = max(w >> k, 1) × max(h >> k, 1)`, until a level of 1 × 1.

// One plane's level: `base`'s parameters (at a dynamic offset of the params buffer), or
// `reduce`'s (`steps[plane · MAX_LEVELS + k]`; the params slot of a `reduce` dispatch holds
// only its level `k`, in `src`).
struct Level {
    // Offsets in f32s of the source level's max and min (`reduce`); `base`: the first word
    // of the plane's slice mask in `masks` when `src_w` is 1.
    src: u32,
    src_min: u32,
    // Offsets of this level's max and min (`base` writes `dst` only).
    dst: u32,
    dst_min: u32,
    src_w: u32,
    src_h: u32,
    dst_w: u32,
    dst_h: u32,
}

@group(0) @binding(0) var<uniform> lv: Level;
@group(0) @binding(1) var<storage, read_write> pyr: array<f32>;
// The planes' slice masks, a bit per pixel (row-major, 32 a word): set where the CPU's
// `fill_slices` sets the map to 0.
@group(0) @binding(7) var<storage, read> masks: array<u32>;
// Every tested plane's levels, `MAX_LEVELS` slots a plane (unused ones zero: nothing to do).
@group(0) @binding(8) var<storage, read> steps: array<Level>;
@group(1) @binding(0) var map: texture_2d<f32>;

@compute @workgroup_size(8, 8)
fn base(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= lv.dst_w || id.y >= lv.dst_h {
        return;
    }
    let pixel = id.y * lv.dst_w + id.x;
    var d = textureLoad(map, vec2<i32>(id.xy), 0).r;
    // `merge_mask`: the slice's 0 where it is below the map's Depth.
    if lv.src_w == 1u && ((masks[lv.src + pixel / 32u] >> (pixel % 32u)) & 1u) == 1u && 0.0 < d {
        d = 0.0;
    }
    pyr[lv.dst + pixel] = d;
}

// Level `lv.src` of every tested plane at once, plane `id.z`.
@compute @workgroup_size(8, 8)
fn reduce(@builtin(global_invocation_id) id: vec3<u32>) {
    let s = steps[id.z * MAX_LEVELS + lv.src];
    if id.x >= s.dst_w || id.y >= s.dst_h {
        return;
    }
    // Children of texel (x, y): columns 2x, 2x+1 and rows 2y, 2y+1 that exist (`Hdm::build`).
    let dx = select(0u, 1u, s.src_w > 1u);
    let dy = select(0u, 1u, s.src_h > 1u);
    let r0 = 2u * id.y * s.src_w;
    let r1 = (2u * id.y + dy) * s.src_w;
    let a = r0 + 2u * id.x;
    let b = a + dx;
    let c = r1 + 2u * id.x;
    let d = c + dx;
    let o = id.y * s.dst_w + id.x;
    pyr[s.dst + o] = max(max(pyr[s.src + a], pyr[s.src + b]), max(pyr[s.src + c], pyr[s.src + d]));
    pyr[s.dst_min + o] = min(
        min(pyr[s.src_min + a], pyr[s.src_min + b]),
        min(pyr[s.src_min + c], pyr[s.src_min + d]),
    );
}

// A tested plane: its map's size, its pyramid's levels and offset.
struct Plane {
    width: u32,
    height: u32,
    levels: u32,
    base: u32,
}

// A query: its plane, the pixel rectangle [i0, i1] × [j0, j1] (inclusive; `i | j << 16`) and
// the occludee's Depth.
struct Query {
    plane: u32,
    lo: u32,
    hi: u32,
    depth: f32,
}

// (The answers' codes, `PARTIAL`, `HIDDEN`, `EMPTY` and `NO_PLANE`: `coverage.wgsl`, prepended.)
const INF: u32 = 0x7f800000u;
const MAX_LEVELS: u32 = 16u;
const STACK: u32 = 64u;

// (Bindings apart from `base` and `reduce`'s: one module, one pair per variable.)
@group(0) @binding(2) var<storage, read> tpyr: array<f32>;
@group(0) @binding(3) var<storage, read> planes: array<Plane>;
@group(0) @binding(4) var<storage, read> queries: array<Query>;
@group(0) @binding(5) var<storage, read_write> answers: array<u32>;
@group(0) @binding(6) var<uniform> count: vec4<u32>;

@compute @workgroup_size(64)
fn answer(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = id.x;
    if n >= count.x {
        return;
    }
    let q = queries[n];
    // A slot a box test left unasked (`boxes.wgsl`).
    if q.plane == NO_PLANE {
        answers[n] = PARTIAL;
        return;
    }
    let p = planes[q.plane];
    // Offsets of each level's max and min.
    var omax: array<u32, MAX_LEVELS>;
    var omin: array<u32, MAX_LEVELS>;
    omax[0] = p.base;
    omin[0] = p.base;
    var next = p.base + p.width * p.height;
    for (var k = 1u; k < p.levels && k < MAX_LEVELS; k++) {
        let s = max(p.width >> k, 1u) * max(p.height >> k, 1u);
        omax[k] = next;
        omin[k] = next + s;
        next += 2u * s;
    }
    let i0 = q.lo & 0xffffu;
    let j0 = q.lo >> 16u;
    let i1 = q.hi & 0xffffu;
    let j1 = q.hi >> 16u;
    let depth = q.depth;
    // The finest level where the rectangle spans at most 2×2 texels.
    var level = 0u;
    while level + 1u < p.levels && ((i1 >> level) - (i0 >> level) > 1u || (j1 >> level) - (j0 >> level) > 1u) {
        level += 1u;
    }
    let r = max(p.width >> level, 1u);
    var covered = false;
    for (var ty = j0 >> level; ty <= (j1 >> level); ty++) {
        for (var tx = i0 >> level; tx <= (i1 >> level); tx++) {
            if tpyr[omin[level] + ty * r + tx] < bitcast<f32>(INF) {
                covered = true;
            }
        }
    }
    if !covered {
        answers[n] = EMPTY;
        return;
    }
    // `Hdm::hidden_in` for every texel, depth first with an explicit stack of
    // `level << 28 | tx << 14 | ty` (texels below 2^14; at most 4 + 3 per level pending).
    var stack: array<u32, STACK>;
    var sp = 0u;
    for (var ty = j0 >> level; ty <= (j1 >> level); ty++) {
        for (var tx = i0 >> level; tx <= (i1 >> level); tx++) {
            stack[sp] = (level << 28u) | (tx << 14u) | ty;
            sp += 1u;
        }
    }
    while sp > 0u {
        sp -= 1u;
        let e = stack[sp];
        let l = e >> 28u;
        let tx = (e >> 14u) & 0x3fffu;
        let ty = e & 0x3fffu;
        let idx = ty * max(p.width >> l, 1u) + tx;
        if tpyr[omax[l] + idx] < depth {
            continue;
        }
        // A texel wholly inside the rectangle whose maximum is not below the Depth holds a
        // pixel that fails; only texels on the rectangle's border descend.
        let x0 = tx << l;
        let x1 = ((tx + 1u) << l) - 1u;
        let y0 = ty << l;
        let y1 = ((ty + 1u) << l) - 1u;
        let inside = x0 >= i0 && x1 <= i1 && y0 >= j0 && y1 <= j1;
        if l == 0u || inside || tpyr[omin[l] + idx] >= depth || sp + 4u > STACK {
            answers[n] = PARTIAL;
            return;
        }
        let c = l - 1u;
        for (var cy = 2u * ty; cy < 2u * ty + 2u; cy++) {
            for (var cx = 2u * tx; cx < 2u * tx + 2u; cx++) {
                // Children outside the rectangle do not matter.
                let cx0 = cx << c;
                let cx1 = ((cx + 1u) << c) - 1u;
                let cy0 = cy << c;
                let cy1 = ((cy + 1u) << c) - 1u;
                if cx1 < i0 || cx0 > i1 || cy1 < j0 || cy0 > j1 {
                    continue;
                }
                stack[sp] = (c << 28u) | (cx << 14u) | cy;
                sp += 1u;
            }
        }
    }
    answers[n] = HIDDEN;
}

// ---- Sweep planes kept on the device (`hdm::KeptPlane`) ----
//
// A kept plane's summed-area table of the pixels outside its umbra (entry (x, y) counts the
// pixels of [0, x] × [0, y] whose Depth is not `<= 0`; NaN is outside), the twin of
// `prepare::umbra_table`, built from level 0 of its pyramid (the map, slice mask merged):
// `sat_rows` runs along each row (and gathers the umbra's bounding box and the count outside
// it into the plane's summary), then `sat_cols` down each column. Counts are integers: the
// table is the CPU's exactly.

// A kept plane: its map's first f32 in the pyramid, its size, its table's first word in
// `tables` and the table's row stride (words, a multiple of 64 for the copy into a texture).
struct Kept {
    base: u32,
    width: u32,
    height: u32,
    table: u32,
    stride: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

// Words per plane of the summary: i0 (min), i1 (max), j0 (min), j1 (max) of the umbra's
// pixels, then the count outside the umbra; i0 and j0 start at 0xffffffff, the rest at 0.
const SUMMARY: u32 = 8u;

@group(0) @binding(10) var<storage, read> kpyr: array<f32>;
@group(0) @binding(11) var<storage, read> kept: array<Kept>;
@group(0) @binding(12) var<storage, read_write> tables: array<u32>;
@group(0) @binding(13) var<storage, read_write> summary: array<atomic<u32>>;

// Row `id.x` of kept plane `id.z`.
@compute @workgroup_size(64)
fn sat_rows(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = kept[id.z];
    let y = id.x;
    if y >= k.height {
        return;
    }
    var run = 0u;
    var first = 0xffffffffu;
    var last = 0u;
    for (var x = 0u; x < k.width; x++) {
        let d = kpyr[k.base + y * k.width + x];
        if d <= 0.0 {
            first = min(first, x);
            last = x;
        } else {
            run += 1u;
        }
        tables[k.table + y * k.stride + x] = run;
    }
    let s = id.z * SUMMARY;
    if first != 0xffffffffu {
        atomicMin(&summary[s], first);
        atomicMax(&summary[s + 1u], last);
        atomicMin(&summary[s + 2u], y);
        atomicMax(&summary[s + 3u], y);
    }
    atomicAdd(&summary[s + 4u], run);
}

// Column `id.x` of kept plane `id.z`: each entry plus the rows above.
@compute @workgroup_size(64)
fn sat_cols(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = kept[id.z];
    let x = id.x;
    if x >= k.width {
        return;
    }
    var acc = 0u;
    for (var y = 0u; y < k.height; y++) {
        let t = k.table + y * k.stride + x;
        acc += tables[t];
        tables[t] = acc;
    }
}
