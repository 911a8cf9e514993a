// umbrasweep — the sampler's hemicube views (`sampler::Hemicube`'s `View::map`), shared by
// `sampler_setup.wgsl` and `sampler.wgsl`: WGSL has no includes, so `gpu::SHADERS` prepends
// this file to both.

// View k's coordinates of a world offset `p`, for a face with outward normal along `axis`,
// positive when `positive` is 1: view 0 looks out through the face, views 1–4 are the sides'
// outer halves. Exact (a signed permutation).
fn view_of(k: u32, axis: u32, positive: u32, p: vec3<f64>) -> vec3<f64> {
    let a = axis;
    let b = (a + 1u) % 3u;
    let c = (a + 2u) % 3u;
    var s = -1.0lf;
    if positive == 1u {
        s = 1.0lf;
    }
    switch k {
        case 0u: {
            return vec3<f64>(p[b], p[c], s * p[a]);
        }
        case 1u: {
            return vec3<f64>(p[c], s * p[a], p[b]);
        }
        case 2u: {
            return vec3<f64>(p[c], s * p[a], -p[b]);
        }
        case 3u: {
            return vec3<f64>(p[b], s * p[a], p[c]);
        }
        default: {
            return vec3<f64>(p[b], s * p[a], -p[c]);
        }
    }
}
