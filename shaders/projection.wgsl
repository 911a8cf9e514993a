// umbrasweep — occluder Projection pass (one instanced draw per plane, one instance per occluder).
//
// Each instance is the pixel rectangle [rect.xy, rect.zw) that can hold covered pixels (the
// intersection of the occluder's 8 view bounding boxes, eroded by half a pixel, clipped to the
// plane). The fragment shader tests the pixel centre against every remaining edge of the
// occluder's 8 views; the CPU has already shrunk each edge by the pixel's half-extent along its
// normal, plus a margin covering both the CPU's f64 error and this shader's f32 error. A pixel
// that passes all edges lies entirely inside all 8 views of this occluder and receives its
// Depth; the R32Float target keeps the minimum (blend operation Min).
//
// Edge k of an instance is edges[edge_start + k] = (nx, ny, c, 0): the pixel passes when
// nx * (x - x0) + ny * (y - y0) >= c, with (x, y) the pixel centre and (x0, y0) = rect.xy.

struct Params {
    // 2 / resolution: pixel coordinates to NDC (exact for a power-of-two resolution).
    ndc_scale: f32,
    _pad0: f32,
    _pad1: f32,
    _pad2: f32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> edges: array<vec4<f32>>;

struct Instance {
    @location(0) rect: vec4<u32>,
    @location(1) depth: f32,
    @location(2) edge_range: vec2<u32>,
}

struct Varyings {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) origin: vec2<f32>,
    @location(1) @interpolate(flat) depth: f32,
    @location(2) @interpolate(flat) edge_range: vec2<u32>,
}

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, inst: Instance) -> Varyings {
    // Triangle strip over the rectangle's corners: (x0,y0) (x1,y0) (x0,y1) (x1,y1).
    let corner = vec2<u32>(vertex & 1u, vertex >> 1u);
    let px = vec2<f32>(select(inst.rect.xy, inst.rect.zw, corner == vec2<u32>(1u, 1u)));
    // Framebuffer y grows downwards, NDC y upwards: row j of the target is pixel row j.
    let ndc = px * params.ndc_scale - vec2<f32>(1.0, 1.0);
    var out: Varyings;
    out.position = vec4<f32>(ndc.x, -ndc.y, 0.0, 1.0);
    out.origin = vec2<f32>(inst.rect.xy);
    out.depth = inst.depth;
    out.edge_range = inst.edge_range;
    return out;
}

@fragment
fn fs_main(in: Varyings) -> @location(0) vec4<f32> {
    // Pixel centre relative to the rectangle's origin: exact (small integers + 0.5).
    let d = in.position.xy - in.origin;
    let start = in.edge_range.x;
    let end = start + in.edge_range.y;
    for (var k = start; k < end; k++) {
        let e = edges[k];
        if (e.x * d.x + e.y * d.y < e.z) {
            discard;
        }
    }
    return vec4<f32>(in.depth, 0.0, 0.0, 0.0);
}
