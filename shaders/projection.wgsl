// umbrasweep — occluder Projection pass: one draw per plane over all of its occluders
// (`vs_main`, records the CPU set up), or one instanced draw per plane over the records the
// views pass computed (`vs_counted`, `GpuProjection::Counting`); both end in `fs_main`.
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
// `vs_counted` only: per occluder (first point, count | plane << 8, Depth bits, record word).
@group(0) @binding(2) var<storage, read> occ: array<vec4<u32>>;

// A record `views.wgsl` rejected.
const REJECT: u32 = 0xffffffffu;

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

// `GpuProjection::Counting`: one instanced draw per plane over the records `views.wgsl`
// wrote (as above, plus the box's far corner `x1 | y1 << 16` in the fourth word and a second
// header word whose first holds the box's near corner; the edges follow it), an instance per
// occluder. The quad over the record's pixel box has integer corners, exact on
// every rasteriser, so every pixel centre of the box gets a fragment; `fs_main` then tests it
// against the occluder's eroded view edges — all 8 views of that one occluder — and a rejected
// record draws a zero-area quad.
@vertex
fn vs_counted(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> Varyings {
    let r = occ[ii].w;
    let rec = data[r];
    var out_v: Varyings;
    out_v.depth = bitcast<f32>(rec.y);
    if rec.z == REJECT {
        // A zero-area quad: no fragment.
        out_v.position = vec4<f32>(-2.0, -2.0, 0.0, 1.0);
        out_v.origin = vec2<f32>(0.0, 0.0);
        out_v.edges = vec2<u32>(0u, 0u);
        return out_v;
    }
    // The edges' origin, and the box: from the second header word to the fourth word.
    let box0 = data[r + 1u].x;
    let x0 = f32(box0 & 0xffffu);
    let y0 = f32(box0 >> 16u);
    let x1 = f32(rec.w & 0xffffu);
    let y1 = f32(rec.w >> 16u);
    // Two triangles: (0,0) (1,0) (1,1), (0,0) (1,1) (0,1).
    let cx = array<u32, 6>(0u, 1u, 1u, 0u, 1u, 0u);
    let cy = array<u32, 6>(0u, 0u, 1u, 0u, 1u, 1u);
    let pos = vec2<f32>(select(x0, x1, cx[vi] == 1u), select(y0, y1, cy[vi] == 1u));
    // Framebuffer y grows downwards, NDC y upwards: row j of the target is pixel row j.
    let ndc = pos * params.ndc_scale - vec2<f32>(1.0, 1.0);
    out_v.position = vec4<f32>(ndc.x, -ndc.y, 0.0, 1.0);
    out_v.origin = vec2<f32>(f32(rec.x & 0xffffu), f32(rec.x >> 16u));
    out_v.edges = vec2<u32>(r + 2u, r + 2u + rec.z);
    return out_v;
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
