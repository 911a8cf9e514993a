//! One plane as a multi-part OpenEXR file (written with the `exr` crate).
//!
//! Parts (layers), each with 32-bit float channels, ZIP compressed, scan lines:
//! - `plane`: `width × height` pixels (the plane's map, square or stretched to its
//!   rectangle's shape), channels `depth` (the Depth Map; `+inf` where nothing projects) and
//!   `mask` (1 where covered, i.e. the Depth is finite, else 0);
//! - `hdm_max_K` and `hdm_min_K` for `K = 1 … log2(max(width, height))`: `max(1, width >> K)
//!   × max(1, height >> K)` texels, channel `depth`, the maximum and minimum pyramids of the
//!   Hierarchical Depth Map (level 0 is the Depth Map itself and is not repeated).
//!
//! Pixel `(i, j)` of the Depth Map (column `i` along the plane's `u` axis, row `j` along `v`)
//! is EXR pixel `x = i, y = j`: `v` grows downward in image viewers.
//!
//! No per-pixel view count is written: neither backend has one (the CPU intersects the 8 views
//! exactly, the GPU tests each pixel against the views' edges).
//!
//! Every part's header carries the plane's frame as custom attributes: `cellIndex`,
//! `planeIndex`, `resolution` (the longer side), `width`, `height`, `occluders`, `sliceEdges`,
//! `coveredPixels` (int); `cellMin`,
//! `cellMax` (v3f); `planeAxis` (`x`/`y`/`z`), `planeSide` (`+`/`-`), `uvAxes` (e.g. `yz`),
//! `depthDefinition` (string); `planePosition`, `planeDistance` (double: the plane's coordinate
//! and its distance from the cell's face); `rectMin`, `rectMax`, `pixelSize` (v2f, world
//! `(u, v)`).

use crate::hdm::Hdm;
use crate::plane::{DepthMap, PlaneJob};
use exr::prelude::*;
use std::io::Cursor;

/// The part holding `depth` and `mask`.
pub const PLANE_LAYER: &str = "plane";

/// Encodes one plane's maps as the bytes of an OpenEXR file (see the module docs).
///
/// # Errors
/// The exr crate's message when encoding fails (it should not for a consistent map and HDM).
pub fn encode(
    cell: usize,
    plane: usize,
    job: &PlaneJob,
    map: &DepthMap,
    hdm: &Hdm,
) -> std::result::Result<Vec<u8>, String> {
    let (w, h) = (map.width as usize, map.height as usize);
    if map.depth.len() != w * h || (hdm.width, hdm.height) != (map.width, map.height) {
        return Err(format!(
            "inconsistent maps: {} Depth values and an HDM of {} × {} for a map of {w} × {h}",
            map.depth.len(),
            hdm.width,
            hdm.height
        ));
    }
    let f = &job.frame;
    let (u, v) = f.uv_axes();
    let names = ["x", "y", "z"];
    let mut attrs = std::collections::HashMap::new();
    let mut put = |k: &str, a: AttributeValue| {
        attrs.insert(Text::from(k), a);
    };
    let i32_of = |n: usize| AttributeValue::I32(i32::try_from(n).unwrap_or(i32::MAX));
    put("cellIndex", i32_of(cell));
    put("planeIndex", i32_of(plane));
    put("resolution", i32_of(w.max(h)));
    put("width", i32_of(w));
    put("height", i32_of(h));
    put("occluders", i32_of(job.occluders.len()));
    put("sliceEdges", i32_of(job.slices.len()));
    put("coveredPixels", i32_of(map.covered()));
    let v3 = |p: glam::DVec3| AttributeValue::FloatVec3((p.x as f32, p.y as f32, p.z as f32));
    put("cellMin", v3(f.cell.min));
    put("cellMax", v3(f.cell.max));
    put(
        "planeAxis",
        AttributeValue::Text(Text::from(names[f.axis.min(2)])),
    );
    put(
        "planeSide",
        AttributeValue::Text(Text::from(if f.positive { "+" } else { "-" })),
    );
    put(
        "uvAxes",
        AttributeValue::Text(Text::from(format!("{}{}", names[u], names[v]).as_str())),
    );
    put(
        "depthDefinition",
        AttributeValue::Text(Text::from(
            "depth = side * (world[planeAxis] - planePosition); +inf where nothing projects",
        )),
    );
    put("planePosition", AttributeValue::F64(f.position));
    put(
        "planeDistance",
        AttributeValue::F64((f.position - f.face()).abs()),
    );
    let v2 = |p: glam::DVec2| AttributeValue::FloatVec2(Vec2(p.x as f32, p.y as f32));
    put("rectMin", v2(f.rect_min));
    put("rectMax", v2(f.rect_max));
    put("pixelSize", v2(f.pixel_size()));

    let layer = |name: &str, size: (usize, usize), channels: Vec<(&str, Vec<f32>)>| {
        let list: Vec<AnyChannel<FlatSamples>> = channels
            .into_iter()
            .map(|(n, s)| AnyChannel::new(n, FlatSamples::F32(s)))
            .collect();
        let mut la = LayerAttributes::named(name);
        la.software_name = Some(Text::from("umbrasweep"));
        la.other = attrs.clone();
        Layer::new(
            Vec2(size.0, size.1),
            la,
            Encoding::SMALL_LOSSLESS,
            AnyChannels::sort(list.into()),
        )
    };
    let mask: Vec<f32> = map
        .depth
        .iter()
        .map(|d| if d.is_finite() { 1.0 } else { 0.0 })
        .collect();
    let mut layers = vec![layer(
        PLANE_LAYER,
        (w, h),
        vec![("depth", map.depth.clone()), ("mask", mask)],
    )];
    for (kind, levels) in [("max", &hdm.max), ("min", &hdm.min)] {
        for (k, level) in levels.iter().enumerate().skip(1) {
            layers.push(layer(
                &format!("hdm_{kind}_{k}"),
                {
                    let (lw, lh) = hdm.level_size(k);
                    (lw as usize, lh as usize)
                },
                vec![("depth", level.clone())],
            ));
        }
    }
    write_layers((w, h), layers)
}

/// The bytes of a multi-part OpenEXR file of `layers` over an image of `size`.
fn write_layers(
    size: (usize, usize),
    layers: Vec<Layer<AnyChannels<FlatSamples>>>,
) -> std::result::Result<Vec<u8>, String> {
    let image = Image::from_layers(
        ImageAttributes::new(IntegerBounds::from_dimensions(Vec2(size.0, size.1))),
        layers,
    );
    let mut out = Cursor::new(Vec::new());
    image
        .write()
        .non_parallel()
        .to_buffered(&mut out)
        .map_err(|e| format!("cannot encode OpenEXR: {e}"))?;
    Ok(out.into_inner())
}

/// Encodes ray space factorization's four charts of one cell as an OpenEXR file: one part per
/// chart (`chart_+x`, `chart_-x`, `chart_+z`, `chart_-z` with y up), `resolution²` pixels,
/// column `i` the slope `m` from −1 to 1, row `j` the crossing `s` from `sMin` to `sMax`;
/// channels `near_slope`, `near_guard`, `near_base`, `far_slope`, `far_guard`, `far_base`
/// (the pixel's two umbrae, `crate::rsf::Umbra`; `guard` `+inf` where there is none).
/// Attributes: `cellIndex`, `resolution` (int), `cellMin`, `cellMax` (v3f), `side`,
/// `tangentAxis` (text), `sMin`, `sMax` (double).
///
/// # Errors
/// The exr crate's message when encoding fails.
pub fn encode_charts(
    cell: usize,
    bounds: &crate::geom::Aabb,
    charts: &crate::rsf::RayCharts,
) -> std::result::Result<Vec<u8>, String> {
    let n = charts.resolution();
    let names = ["x", "y", "z"];
    let mut layers = Vec::new();
    for c in 0..4 {
        let info = charts.chart_info(c);
        let side = format!(
            "{}{}",
            if info.positive { "+" } else { "-" },
            names[info.axis]
        );
        let mut attrs = std::collections::HashMap::new();
        let mut put = |k: &str, a: AttributeValue| {
            attrs.insert(Text::from(k), a);
        };
        put(
            "cellIndex",
            AttributeValue::I32(i32::try_from(cell).unwrap_or(i32::MAX)),
        );
        put(
            "resolution",
            AttributeValue::I32(i32::try_from(n).unwrap_or(i32::MAX)),
        );
        let v3 = |p: glam::Vec3| AttributeValue::FloatVec3((p.x, p.y, p.z));
        put("cellMin", v3(bounds.min));
        put("cellMax", v3(bounds.max));
        put("side", AttributeValue::Text(Text::from(side.as_str())));
        put(
            "tangentAxis",
            AttributeValue::Text(Text::from(names[info.tangent])),
        );
        put("sMin", AttributeValue::F64(info.s_min));
        put("sMax", AttributeValue::F64(info.s_max));
        let mut ch: [Vec<f32>; 6] = Default::default();
        for j in 0..n {
            for i in 0..n {
                let [near, far] = charts.umbrae(c, j, i);
                for (k, v) in [
                    near.slope, near.guard, near.base, far.slope, far.guard, far.base,
                ]
                .into_iter()
                .enumerate()
                {
                    ch[k].push(v);
                }
            }
        }
        let [ns, ng, nb, fs, fg, fb] = ch;
        let list: Vec<AnyChannel<FlatSamples>> = [
            ("near_slope", ns),
            ("near_guard", ng),
            ("near_base", nb),
            ("far_slope", fs),
            ("far_guard", fg),
            ("far_base", fb),
        ]
        .into_iter()
        .map(|(name, s)| AnyChannel::new(name, FlatSamples::F32(s)))
        .collect();
        let mut la = LayerAttributes::named(format!("chart_{side}").as_str());
        la.software_name = Some(Text::from("umbrasweep"));
        la.other = attrs;
        layers.push(Layer::new(
            Vec2(n, n),
            la,
            Encoding::SMALL_LOSSLESS,
            AnyChannels::sort(list.into()),
        ));
    }
    write_layers((n, n), layers)
}
