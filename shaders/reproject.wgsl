// umbrasweep — occlusion-sweep reprojection (crate::sweep): the window filter of
// `Reprojection::mask` as one fullscreen-triangle draw per reprojection, inside the plane's
// render pass, into its R32Float Depth Map (blend operation Min).
//
// Target pixel (i, j) is set when no source pixel of the box cols[i] × rows[j] lies outside
// the umbra — the separable filter of the CPU is that same box test. The CPU uploads, instead
// of the source Depth Map, its summed-area table of pixels outside the umbra (`!(d <= 0)`:
// positive numbers, +inf and NaNs), so the box's count takes four integer loads. A set pixel
// receives the reprojection's Depth, the others +inf — min(+inf, d) = d, which leaves the
// pixel as it was (writing +inf rather than discarding: on lavapipe, a fullscreen draw that
// may discard cost ~1.4 ms more per 256² plane). Everything is integer: set pixels are
// exactly the CPU's.
//
// A column window [lo, hi] with lo > hi or hi >= the source's width (a row window: height)
// sets nothing. The source and the target may differ in size.

struct Reproject {
    // The Depth written into reprojected pixels.
    depth: f32,
    // The target's columns: where the row windows start in `windows`.
    width: u32,
    // +inf (WGSL has no infinite literal): what the other pixels receive.
    none: f32,
    // The source's (and the table's) columns and rows.
    source_width: u32,
    source_height: u32,
    _pad: u32,
    // cols[0 .. width], then rows[0 .. the target's height]: inclusive [lo, hi].
    windows: array<vec2<u32>>,
}

@group(0) @binding(0) var<storage, read> reproject: Reproject;
// Texel (x, y): the number of source pixels outside the umbra in [0, x] × [0, y].
@group(0) @binding(1) var table: texture_2d<u32>;

@vertex
fn vs_fullscreen(@builtin(vertex_index) k: u32) -> @builtin(position) vec4<f32> {
    // One triangle covering the whole target: (-1, -1), (3, -1), (-1, 3).
    let x = f32((k & 1u) << 2u) - 1.0;
    let y = f32((k & 2u) << 1u) - 1.0;
    return vec4<f32>(x, y, 0.0, 1.0);
}

// True when the window holds at least one pixel and lies inside the source's `n` pixels.
fn valid(w: vec2<u32>, n: u32) -> bool {
    return w.x <= w.y && w.y < n;
}

// The count over [0, x) × [0, y): 0 on the table's lower edges.
fn count(x: u32, y: u32) -> u32 {
    if (x == 0u || y == 0u) {
        return 0u;
    }
    return textureLoad(table, vec2<i32>(i32(x - 1u), i32(y - 1u)), 0).x;
}

@fragment
fn fs_reproject(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
    let c = reproject.windows[u32(p.x)];
    let r = reproject.windows[reproject.width + u32(p.y)];
    if (!valid(c, reproject.source_width) || !valid(r, reproject.source_height)) {
        return vec4<f32>(reproject.none, 0.0, 0.0, 0.0);
    }
    // Integer arithmetic wraps, and the true count (at most the source's pixels) fits: exact.
    let outside = count(c.y + 1u, r.y + 1u) + count(c.x, r.x)
        - count(c.x, r.y + 1u) - count(c.y + 1u, r.x);
    if (outside != 0u) {
        return vec4<f32>(reproject.none, 0.0, 0.0, 0.0);
    }
    return vec4<f32>(reproject.depth, 0.0, 0.0, 0.0);
}
