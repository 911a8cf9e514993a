// umbrasweep — the sub-pixel depths of the sampler's render fill (`vs_fill` / `fs_fill` in
// `sampler.wgsl`, `SamplerFill::Render`): one `R32Float` layer per view at 8× its resolution,
// `Min` blended. Appended to `sampler.wgsl` for that fill's reduce and test passes.

@group(0) @binding(5) var fine: texture_2d_array<f32>;

// The nearest depth drawn over sub-pixel (i, j) of view k (infinity where none).
fn sub_depth(i: u32, j: u32, k: u32) -> f32 {
    return textureLoad(fine, vec2<i32>(i32(i), i32(j)), i32(k), 0).r;
}

// The render fill keeps no whole-pixel depth: infinity (`sub_depth` holds each sub-pixel's).
fn pixel_floor(i: u32, j: u32, k: u32) -> f32 {
    return bitcast<f32>(0x7f800000u);
}

// The depth drawn over sub-pixel (i, j) of view k.
fn fine_depth(i: u32, j: u32, k: u32) -> f32 {
    return sub_depth(i, j, k);
}
