// umbrasweep — occluder views counted per fragment (`GpuProjection::Counting`): one instanced
// draw per plane, an instance per occluder, over the records `views.wgsl` wrote.
//
// The vertex shader draws a quad over the record's pixel box (integer pixel coordinates:
// exact on every rasteriser, so every pixel centre of the box gets a fragment); the fragment
// shader tests the pixel centre against the record's eroded view edges, as `projection.wgsl`
// does, and writes the occluder's Depth into the R32Float target (blend operation Min). A
// centre passing every edge lies inside all 8 eroded views of that one occluder: the whole
// pixel is inside every view. A rejected record draws a zero-area quad.

const REJECT: u32 = 0xffffffffu;

struct Params {
    // (2 / width, 2 / height): pixel coordinates to NDC (exact for powers of two).
    ndc_scale: vec2<f32>,
    _pad0: f32,
    _pad1: f32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> occ_draw: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read> records: array<vec4<u32>>;

struct Varyings {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) origin: vec2<f32>,
    @location(1) @interpolate(flat) depth: f32,
    // First edge index and one past the last.
    @location(2) @interpolate(flat) edges: vec2<u32>,
}

@vertex
fn vs_counted(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> Varyings {
    let r = occ_draw[ii].w;
    let rec = records[r];
    var out_v: Varyings;
    out_v.depth = bitcast<f32>(rec.y);
    if rec.z == REJECT {
        // A zero-area quad: no fragment.
        out_v.position = vec4<f32>(-2.0, -2.0, 0.0, 1.0);
        out_v.origin = vec2<f32>(0.0, 0.0);
        out_v.edges = vec2<u32>(0u, 0u);
        return out_v;
    }
    let x0 = f32(rec.x & 0xffffu);
    let y0 = f32(rec.x >> 16u);
    let x1 = f32(rec.w & 0xffffu);
    let y1 = f32(rec.w >> 16u);
    // Two triangles: (0,0) (1,0) (1,1), (0,0) (1,1) (0,1).
    let cx = array<u32, 6>(0u, 1u, 1u, 0u, 1u, 0u);
    let cy = array<u32, 6>(0u, 0u, 1u, 0u, 1u, 1u);
    let pos = vec2<f32>(select(x0, x1, cx[vi] == 1u), select(y0, y1, cy[vi] == 1u));
    // Framebuffer y grows downwards, NDC y upwards: row j of the target is pixel row j.
    let ndc = pos * params.ndc_scale - vec2<f32>(1.0, 1.0);
    out_v.position = vec4<f32>(ndc.x, -ndc.y, 0.0, 1.0);
    out_v.origin = vec2<f32>(x0, y0);
    out_v.edges = vec2<u32>(r + 1u, r + 1u + rec.z);
    return out_v;
}

@fragment
fn fs_counted(in: Varyings) -> @location(0) vec4<f32> {
    // Pixel centre relative to the record's origin: exact (small integers + 0.5).
    let d = in.position.xy - in.origin;
    for (var k = in.edges.x; k < in.edges.y; k++) {
        let e = bitcast<vec4<f32>>(records[k]);
        if (e.x * d.x + e.y * d.y < e.z) {
            discard;
        }
    }
    return vec4<f32>(in.depth, 0.0, 0.0, 0.0);
}
