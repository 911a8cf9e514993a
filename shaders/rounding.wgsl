// umbrasweep — f64 → f32 rounding shared by the f64 passes (`rsf.wgsl`, `views.wgsl`), the
// twins of `geom::f32_up` / `f32_down`. WGSL has no includes: `gpu::SHADERS` prepends this file
// to each of them.

const INF_BITS: u32 = 0x7f800000u;

// Rust's `f32::next_up` for finite values and −inf.
fn next_up(f: f32) -> f32 {
    let b = bitcast<u32>(f);
    if b == INF_BITS || (b & 0x7fffffffu) > INF_BITS {
        return f;
    }
    if (b & 0x7fffffffu) == 0u {
        return bitcast<f32>(1u);
    }
    if (b & 0x80000000u) == 0u {
        return bitcast<f32>(b + 1u);
    }
    return bitcast<f32>(b - 1u);
}

fn next_down(f: f32) -> f32 {
    return -next_up(-f);
}

// `geom::f32_down` / `f32_up`: the nearest f32 at or below / above.
fn f32_down(x: f64) -> f32 {
    let f = f32(x);
    if f64(f) > x {
        return next_down(f);
    }
    return f;
}

fn f32_up(x: f64) -> f32 {
    let f = f32(x);
    if f64(f) < x {
        return next_up(f);
    }
    return f;
}
