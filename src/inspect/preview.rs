//! 8-bit previews of a plane's maps, with one fixed colour mapping (documented in
//! `docs/inspect.md` and drawn by [`legend_image`]).
//!
//! - **Depth**: a pixel of Depth `d` gets the colour `ramp(t)` with `t = d / (d + D)`, where
//!   `D` is the plane's distance from the cell's face (at least one pixel width). So `d = 0`
//!   (on the plane, slices) is yellow, `d = D` (twice as far from the cell as the plane) is
//!   the ramp's middle, teal, and far occluders tend to dark violet-blue. The ramp is a 5-stop
//!   approximation of *viridis*, reversed (near = yellow). Uncovered pixels (`+inf`) are a
//!   grey checkerboard of 4-pixel squares.
//! - **Mask**: white where covered, black where not.
//! - **HDM**: one image the map's size (`width × height`, at least 2 tall) holding the maximum
//!   pyramid's levels 1, 2, … left to right in the top half (level `k` at `x = width −
//!   2·(width >> k)`, `y = 0`, native size) and the minimum pyramid the same way in the bottom
//!   half (`y = height / 2`); the rest is black. Levels of a stretched map after its short
//!   side has reached one texel are left out. Colours as for Depth.
//!
//! - **Ray space factorization's charts** ([`rsf_chart_image`]): per chart pixel, the
//!   elevation of its highest umbra line on the same ramp, the checkerboard where it has none.
//!
//! Pixel `(i, j)` of a map is image pixel `x = i, y = j` (the plane's `v` grows downward).

use crate::hdm::Hdm;
use crate::plane::{DepthMap, PlaneFrame};
use image::RgbImage;

/// The reversed-viridis stops, from `t = 0` (near, yellow) to `t = 1` (far, dark).
pub const RAMP: [[u8; 3]; 5] = [
    [253, 231, 37],
    [94, 201, 98],
    [33, 145, 140],
    [59, 82, 139],
    [68, 1, 84],
];

/// The two greys of the checkerboard marking uncovered (`+inf`) pixels.
pub const UNCOVERED: [[u8; 3]; 2] = [[56, 56, 56], [96, 96, 96]];

/// Side of a checkerboard square, in pixels.
pub const CHECKER: u32 = 4;

/// The ramp's colour at `t` (clamped to `[0, 1]`), linear between the stops.
pub fn ramp(t: f64) -> [u8; 3] {
    let t = if t.is_nan() { 1.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (RAMP.len() - 1) as f64;
    let k = (x.floor() as usize).min(RAMP.len() - 2);
    let f = x - k as f64;
    let (a, b) = (RAMP[k], RAMP[k + 1]);
    std::array::from_fn(|c| (a[c] as f64 + (b[c] as f64 - a[c] as f64) * f).round() as u8)
}

/// The checkerboard grey of uncovered image pixel `(x, y)`.
pub fn uncovered(x: u32, y: u32) -> [u8; 3] {
    UNCOVERED[((x / CHECKER + y / CHECKER) % 2) as usize]
}

/// The colour of Depth `d` at image pixel `(x, y)`, for a plane at distance `dist` from the
/// cell's face (see the module docs).
pub fn depth_colour(d: f32, dist: f64, x: u32, y: u32) -> [u8; 3] {
    if !d.is_finite() {
        return uncovered(x, y);
    }
    let d = (d as f64).max(0.0);
    ramp(d / (d + dist))
}

/// The `D` of the colour mapping: the plane's distance from the cell's face, at least one
/// pixel width (so that planes at the face still get a ramp).
pub fn plane_distance(frame: &PlaneFrame) -> f64 {
    let px = frame.pixel_size().max_element();
    let d = (frame.position - frame.face()).abs();
    if d.is_finite() && d > px {
        d
    } else if px.is_finite() && px > 0.0 {
        px
    } else {
        1.0
    }
}

/// The Depth Map as colours (see the module docs).
pub fn depth_image(map: &DepthMap, dist: f64) -> RgbImage {
    RgbImage::from_fn(map.width, map.height, |x, y| {
        image::Rgb(depth_colour(
            map.depth[(y * map.width + x) as usize],
            dist,
            x,
            y,
        ))
    })
}

/// The binary mask: white where covered, black elsewhere.
pub fn mask_image(map: &DepthMap) -> RgbImage {
    RgbImage::from_fn(map.width, map.height, |x, y| {
        if map.depth[(y * map.width + x) as usize].is_finite() {
            image::Rgb([255, 255, 255])
        } else {
            image::Rgb([0, 0, 0])
        }
    })
}

/// One chart of ray space factorization's charts (`chart` 0..4, see
/// [`crate::rsf::RayCharts::chart_info`]): image pixel `(x, y)` is the chart's column `x`
/// (slope `m`, from −1 at the left) and row `y` (crossing `s`, growing downward). A pixel
/// holding an umbra gets `ramp(½ − atan(v)/π)` of the highest line `v` of its two umbrae —
/// the elevation of the line through the cell's front top edge under which it hides: yellow
/// for lines climbing steeply (tall occluders near by), violet for lines falling steeply —
/// and pixels without one the grey checkerboard.
pub fn rsf_chart_image(charts: &crate::rsf::RayCharts, chart: usize) -> RgbImage {
    let n = charts.resolution() as u32;
    RgbImage::from_fn(n, n, |x, y| {
        let best = charts
            .umbrae(chart, y as usize, x as usize)
            .iter()
            .filter(|u| u.guard.is_finite())
            .map(|u| u.slope as f64)
            .fold(f64::NEG_INFINITY, f64::max);
        if best == f64::NEG_INFINITY {
            image::Rgb(uncovered(x, y))
        } else {
            image::Rgb(ramp(0.5 - best.atan() / std::f64::consts::PI))
        }
    })
}

/// The HDM mosaic: maximum levels on top, minimum levels below (see the module docs).
pub fn hdm_image(hdm: &Hdm, dist: f64) -> RgbImage {
    let (w, h) = (hdm.width, hdm.height);
    let mut img = RgbImage::new(w, h.max(2));
    for (row, levels) in [(0, &hdm.max), (h.max(2) / 2, &hdm.min)] {
        // The levels that still halve both sides (a stretched map's later levels, one texel
        // thin, are left out).
        for (k, level) in levels.iter().enumerate().skip(1) {
            if (w >> k) == 0 || (h >> k) == 0 {
                break;
            }
            let (lw, lh) = (w >> k, h >> k);
            let x0 = w - 2 * lw;
            for y in 0..lh {
                for x in 0..lw {
                    let c = depth_colour(level[(y * lw + x) as usize], dist, x, y);
                    img.put_pixel(x0 + x, row + y, image::Rgb(c));
                }
            }
        }
    }
    img
}

/// Encodes an image as PNG bytes.
///
/// # Errors
/// The encoder's message.
pub fn encode_png(img: &RgbImage) -> Result<Vec<u8>, String> {
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| format!("cannot encode PNG: {e}"))?;
    Ok(out.into_inner())
}

/// The legend of the colour mapping: the Depth ramp with ticks at `d = 0, D, 3D, 9D`, the
/// uncovered checkerboard and the mask's two colours, labelled.
pub fn legend_image() -> RgbImage {
    let (w, h) = (420u32, 176u32);
    let mut img = RgbImage::from_pixel(w, h, image::Rgb([255, 255, 255]));
    let ink = [0, 0, 0];
    text(&mut img, 10, 8, "DEPTH d: COLOUR = RAMP(d/(d+D))", ink);
    text(&mut img, 10, 22, "D = PLANE DISTANCE FROM CELL FACE", ink);
    let (x0, y0, bw, bh) = (20u32, 40u32, 380u32, 20u32);
    for x in 0..bw {
        let c = ramp(x as f64 / (bw - 1) as f64);
        for y in 0..bh {
            img.put_pixel(x0 + x, y0 + y, image::Rgb(c));
        }
    }
    for (t, label) in [(0.0, "d=0"), (0.5, "D"), (0.75, "3D"), (0.9, "9D")] {
        let x = x0 + (t * (bw - 1) as f64).round() as u32;
        for y in y0 + bh..y0 + bh + 5 {
            img.put_pixel(x, y, image::Rgb(ink));
        }
        let tw = label.len() as u32 * 8;
        text(&mut img, x.saturating_sub(tw / 2), y0 + bh + 8, label, ink);
    }
    let swatch = |img: &mut RgbImage, x0: u32, y0: u32, f: &dyn Fn(u32, u32) -> [u8; 3]| {
        for y in 0..20 {
            for x in 0..28 {
                img.put_pixel(x0 + x, y0 + y, image::Rgb(f(x, y)));
            }
        }
        for x in 0..28 {
            img.put_pixel(x0 + x, y0, image::Rgb(ink));
            img.put_pixel(x0 + x, y0 + 19, image::Rgb(ink));
        }
        for y in 0..20 {
            img.put_pixel(x0, y0 + y, image::Rgb(ink));
            img.put_pixel(x0 + 27, y0 + y, image::Rgb(ink));
        }
    };
    swatch(&mut img, 20, 88, &uncovered);
    text(&mut img, 56, 94, "UNCOVERED (+INF)", ink);
    swatch(&mut img, 20, 116, &|_, _| [255, 255, 255]);
    text(&mut img, 56, 122, "MASK 1: COVERED", ink);
    swatch(&mut img, 20, 144, &|_, _| [0, 0, 0]);
    text(&mut img, 56, 150, "MASK 0: NOT COVERED", ink);
    img
}

/// Draws `s` (see [`glyph`]) with a 3×5 font scaled ×2 (8 px advance).
fn text(img: &mut RgbImage, x0: u32, y0: u32, s: &str, colour: [u8; 3]) {
    for (n, ch) in s.chars().enumerate() {
        let g = glyph(ch);
        for (row, bits) in g.iter().enumerate() {
            for col in 0..3u32 {
                if bits & (4 >> col) == 0 {
                    continue;
                }
                for dy in 0..2 {
                    for dx in 0..2 {
                        let x = x0 + n as u32 * 8 + col * 2 + dx;
                        let y = y0 + row as u32 * 2 + dy;
                        if x < img.width() && y < img.height() {
                            img.put_pixel(x, y, image::Rgb(colour));
                        }
                    }
                }
            }
        }
    }
}

/// Rows (top first, 3 bits, left = 4) of a 3×5 glyph: upper case (lower case is drawn upper
/// case, except `d`, the Depth), digits and a few signs; other characters are blank.
fn glyph(c: char) -> [u8; 5] {
    if c == 'd' {
        return [1, 1, 3, 5, 3];
    }
    match c.to_ascii_uppercase() {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 2, 2],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        'A' => [2, 5, 7, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        'C' => [3, 4, 4, 4, 3],
        'D' => [6, 5, 5, 5, 6],
        'E' => [7, 4, 6, 4, 7],
        'F' => [7, 4, 6, 4, 4],
        'G' => [3, 4, 5, 5, 3],
        'H' => [5, 5, 7, 5, 5],
        'I' => [7, 2, 2, 2, 7],
        'J' => [1, 1, 1, 5, 2],
        'K' => [5, 5, 6, 5, 5],
        'L' => [4, 4, 4, 4, 7],
        'M' => [5, 7, 7, 5, 5],
        'N' => [6, 5, 5, 5, 5],
        'O' => [2, 5, 5, 5, 2],
        'P' => [6, 5, 6, 4, 4],
        'Q' => [2, 5, 5, 6, 3],
        'R' => [6, 5, 6, 5, 5],
        'S' => [3, 4, 2, 1, 6],
        'T' => [7, 2, 2, 2, 2],
        'U' => [5, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'W' => [5, 5, 7, 7, 5],
        'X' => [5, 5, 2, 5, 5],
        'Y' => [5, 5, 2, 2, 2],
        'Z' => [7, 1, 2, 4, 7],
        '+' => [0, 2, 7, 2, 0],
        '-' => [0, 0, 7, 0, 0],
        '.' => [0, 0, 0, 0, 2],
        '=' => [0, 7, 0, 7, 0],
        '/' => [1, 1, 2, 4, 4],
        '(' => [2, 4, 4, 4, 2],
        ')' => [2, 1, 1, 1, 2],
        ':' => [0, 2, 0, 2, 0],
        _ => [0; 5],
    }
}

/// Standard base64 (RFC 4648, with padding), for `data:` URIs.
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (i, o) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(i.as_bytes()), o);
        }
    }

    #[test]
    fn ramp_ends_and_middle() {
        assert_eq!(ramp(0.0), RAMP[0]);
        assert_eq!(ramp(1.0), RAMP[4]);
        assert_eq!(ramp(0.5), RAMP[2]);
        assert_eq!(depth_colour(2.0, 2.0, 0, 0), RAMP[2]);
        assert_eq!(depth_colour(f32::INFINITY, 2.0, 0, 0), UNCOVERED[0]);
        assert_eq!(depth_colour(f32::INFINITY, 2.0, 4, 0), UNCOVERED[1]);
    }
}
