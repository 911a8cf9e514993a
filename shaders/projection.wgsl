// umbrasweep — occluder Projection pass: one draw per plane over all of its occluders.
//
// Each occluder is drawn as its view from cell corner 0, clipped to the pixel rectangle that
// can hold covered pixels (a superset of its Projection), and has a record in `data`:
//   data[r]         = (x0 | y0 << 16, bitcast depth, edge count, 0)
//   data[r + 1 + k] = (bitcast nx, bitcast ny, bitcast c, 0)       for k < edge count
// The fragment shader tests the pixel centre against every remaining edge of the occluder's 8
// views. The CPU has already shrunk each edge by the pixel's half-extent along its normal and
// added a margin covering its own f64 error and this shader's f32 error, so a pixel that passes
// every edge lies entirely inside all 8 views of this occluder; it receives the occluder's
// Depth, and the R32Float target keeps the minimum (blend operation Min).

struct Params {
    // (2 / width, 2 / height): pixel coordinates to NDC (exact for powers of two).
    ndc_scale: vec2<f32>,
    _pad0: f32,
    _pad1: f32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> data: array<vec4<u32>>;

struct Vertex {
    @location(0) pos: vec2<f32>,
    @location(1) record: u32,
}

struct Varyings {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) origin: vec2<f32>,
    @location(1) @interpolate(flat) depth: f32,
    // First edge index and one past the last.
    @location(2) @interpolate(flat) edges: vec2<u32>,
}

@vertex
fn vs_main(v: Vertex) -> Varyings {
    let rec = data[v.record];
    // Framebuffer y grows downwards, NDC y upwards: row j of the target is pixel row j.
    let ndc = v.pos * params.ndc_scale - vec2<f32>(1.0, 1.0);
    var out: Varyings;
    out.position = vec4<f32>(ndc.x, -ndc.y, 0.0, 1.0);
    out.origin = vec2<f32>(f32(rec.x & 0xffffu), f32(rec.x >> 16u));
    out.depth = bitcast<f32>(rec.y);
    out.edges = vec2<u32>(v.record + 1u, v.record + 1u + rec.z);
    return out;
}

@fragment
fn fs_main(in: Varyings) -> @location(0) vec4<f32> {
    // Pixel centre relative to the record's origin: exact (small integers + 0.5).
    let d = in.position.xy - in.origin;
    for (var k = in.edges.x; k < in.edges.y; k++) {
        let e = bitcast<vec4<f32>>(data[k]);
        if (e.x * d.x + e.y * d.y < e.z) {
            discard;
        }
    }
    return vec4<f32>(in.depth, 0.0, 0.0, 0.0);
}
