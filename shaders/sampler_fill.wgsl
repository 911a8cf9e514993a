// umbrasweep — the sampler's fill as compute passes (`backend::gpu::sampler`,
// `SamplerFill::Compute`, needs `TEXTURE_ATOMIC`): the same sub-pixel depths as the render fill
// (`vs_fill` / `fs_fill` in `sampler.wgsl`), with a pixel's work done once instead of once per
// sub-pixel. Appended to `sampler.wgsl`, whose reduce and test passes read the depths through
// `sub_depth` below.
//
// `fill_args` (one invocation per view) turns the set-up pass's draw counts (the render fill's
// indirect draws) into indirect dispatches; `fill` (one workgroup per draw, a view per
// dispatch, striding over the draws beyond 65,535) gives each of the draw's pixels to one
// invocation, which makes the render fill's per-pixel decisions: the four corners' `f32`
// tests (all pass: the whole pixel), else with sub-pixel masks and a passing corner (or a
// thin draw) the CPU's `pixel_mask` in `f64`, evaluated for all 64 sub-pixels with
// `fs_fill`'s expressions (`sub_bit`), and the depth (the draw's, or a deep polygon's largest
// plane depth at the pixel's corners, rounded up, when nearer). A covered pixel lowers one
// texel of `full` (a layer per view at the view's resolution); a partly covered one lowers
// its covered sub-pixels' texels of `fine` (8× the resolution). Both hold `f32` bits, cleared
// to infinity (`0x7f800000`) by render passes, lowered by `textureAtomicMin`: depths are never
// negative (the set-up's and the planes' are positive), so the order of the bits is that of
// the depths; a depth that is not (NaN, negative) is not drawn, which only uncovers.
// A sub-pixel's depth is the smaller of its `fine` texel and its pixel's `full` texel, as the
// `Min` blend of the render fill would leave it.

@group(0) @binding(5) var fine: texture_2d_array<u32>;
@group(0) @binding(13) var full: texture_2d_array<u32>;
// The set-up pass's indirect draws: view k's draw count at 4k + 1.
@group(0) @binding(14) var<storage, read> counts: array<u32>;
@group(0) @binding(15) var fine_a: texture_storage_2d_array<r32uint, atomic>;
@group(0) @binding(16) var full_a: texture_storage_2d_array<r32uint, atomic>;
// Per view an indirect dispatch (x, y, z, unused).
@group(0) @binding(17) var<storage, read_write> args: array<u32>;
// The draw counts when this round began (`counts`' layout; zeros for the first round): a
// round fills only the draws its set-up added.
@group(0) @binding(18) var<storage, read> firsts: array<u32>;

// The nearest depth drawn over sub-pixel (i, j) of view k (infinity where none).
fn sub_depth(i: u32, j: u32, k: u32) -> f32 {
    let s = textureLoad(fine, vec2<i32>(i32(i), i32(j)), i32(k), 0).r;
    let w = textureLoad(full, vec2<i32>(i32(i / 8u), i32(j / 8u)), i32(k), 0).r;
    return bitcast<f32>(min(s, w));
}

// The depth of pixel (i, j) of view k as a whole (`full`; infinity where no polygon covers
// all of it): no sub-pixel's depth is deeper.
fn pixel_floor(i: u32, j: u32, k: u32) -> f32 {
    return bitcast<f32>(textureLoad(full, vec2<i32>(i32(i), i32(j)), i32(k), 0).r);
}

// The depth drawn over sub-pixel (i, j) of view k by partly covering polygons (`fine`).
fn fine_depth(i: u32, j: u32, k: u32) -> f32 {
    return bitcast<f32>(textureLoad(fine, vec2<i32>(i32(i), i32(j)), i32(k), 0).r);
}

// Per view: workgroups for this round's draws (up to the capacity `P.n`), at most 65,535
// (`fill` strides over the rest).
@compute @workgroup_size(8)
fn fill_args(@builtin(local_invocation_index) k: u32) {
    if k < 5u {
        let n = min(counts[4u * k + 1u], P.n);
        let first = min(firsts[4u * k + 1u], n);
        args[4u * k] = min(n - first, 65535u);
        args[4u * k + 1u] = 1u;
        args[4u * k + 2u] = 1u;
        args[4u * k + 3u] = 0u;
    }
}

// A later round's set-up dispatch (`args[20 …]`, two clusters of 32 polygons per workgroup of
// 64, in rows of at most 65,535 workgroups) from its list's length, `counts[P.n]`
// (`sampler_setup.wgsl`'s `Round`).
@compute @workgroup_size(1)
fn setup_args() {
    let groups = (counts[P.n] + 1u) / 2u;
    let x = min(groups, 65535u);
    args[20] = x;
    args[21] = select((groups + x - 1u) / x, 1u, x == 0u);
    args[22] = 1u;
    args[23] = 0u;
}

// The sub-pixels of a pixel every edge passes (bit 8 · sb + sa of rows 0–3 in .x, of rows 4–7
// in .y): `sub_bit` of `sampler.wgsl` for all 64 at once, with its expressions (`sub_edge`).
fn sub_mask(first: u32, count: u32, u0: f64, v0: f64, ps: f64, lmax: f64) -> vec2<u32> {
    let margin = f64(CORNER_MARGIN);
    var m = vec2<u32>(0xffffffffu, 0xffffffffu);
    for (var k = 0u; k < count; k++) {
        let e = sub_edge(first, k, u0, v0, ps, lmax);
        if e.w == 0.0lf {
            continue;
        }
        if e.w == 1.0lf {
            return vec2<u32>(0u, 0u);
        }
        for (var sb = 0u; sb < 8u; sb++) {
            let r = e.x + f64(sb) * e.z;
            var row = 0u;
            for (var sa = 0u; sa < 8u; sa++) {
                if r + f64(sa) * e.y >= margin {
                    row |= 1u << sa;
                }
            }
            let clear = (~row & 0xffu) << (8u * (sb % 4u));
            if sb < 4u {
                m.x &= ~clear;
            } else {
                m.y &= ~clear;
            }
        }
    }
    return m;
}

@compute @workgroup_size(64)
fn fill(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nw: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let count = min(counts[4u * P.view + 1u], P.n);
    for (var d = firsts[4u * P.view + 1u] + wg.x; d < count; d += nw.x) {
        fill_draw(P.base + d, li);
    }
}

// Invocation `li` of a workgroup draws every 64th pixel of draw `draw`.
fn fill_draw(draw: u32, li: u32) {
    let w0 = draws[2u * draw];
    let w1 = draws[2u * draw + 1u];
    let i0 = w1.x & 0xffffu;
    let i1 = w1.x >> 16u;
    let j0 = w1.y & 0xffffu;
    let j1 = w1.y >> 16u;
    if i1 <= i0 || j1 <= j0 {
        return;
    }
    let width = i1 - i0;
    let pixels = width * (j1 - j0);
    let first = w0.x;
    let count = w0.y & 0xffffu;
    let thin = (w0.y >> 16u) != 0u;
    let ps = 2.0lf / f64(P.res);
    let z_draw = bitcast<f32>(w0.z);
    // A deep polygon's plane in the view (the same for all its pixels).
    let deep = w0.w != 0u;
    var nd = vec4<f64>(0.0lf, 0.0lf, 0.0lf, 0.0lf);
    if deep {
        nd = view_plane(w0.w);
    }
    let k = i32(P.view);
    for (var p = li; p < pixels; p += 64u) {
        let i = i0 + p % width;
        let j = j0 + p / width;
        let px = pixel_corners(first, count, i, j);
        var mask = vec2<u32>(0u, 0u);
        let covered = px.corners == 4u;
        if !covered && P.subpixel != 0u && (px.corners > 0u || thin) {
            mask = sub_mask(first, count, px.u0, px.v0, ps, px.lmax);
        }
        if !covered && mask.x == 0u && mask.y == 0u {
            continue;
        }
        let z = pixel_depth(z_draw, deep, nd, px.u0, px.v0);
        if !(z >= 0.0) {
            continue;
        }
        let bits = bitcast<u32>(z);
        if covered {
            textureAtomicMin(full_a, vec2<i32>(i32(i), i32(j)), k, bits);
            continue;
        }
        for (var b = 0u; b < 64u; b++) {
            var word = mask.x;
            if b >= 32u {
                word = mask.y;
            }
            if ((word >> (b % 32u)) & 1u) != 0u {
                let sa = b % 8u;
                let sb = b / 8u;
                textureAtomicMin(
                    fine_a,
                    vec2<i32>(i32(8u * i + sa), i32(8u * j + sb)),
                    k,
                    bits,
                );
            }
        }
    }
}
