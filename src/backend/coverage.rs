//! The coverage kernel shared by the CPU and GPU backends: the occluder's Projection polygon,
//! the slice fill, and the contract's own brute-force definition for tests. Both backends run
//! this same `f64` code; they differ only in how they rasterise the polygon (spans in
//! [`super::cpu`], a fragment shader fed by [`super::gpu::setup`]), so one fix here fixes both.
//!
//! # Why it is conservative
//!
//! For each occluder the 8 views (2D convex hulls of the points projected from the cell's
//! corners) are intersected exactly by polygon clipping ([`projection_polygon`]), giving the
//! occluder's Projection as one convex polygon. A pixel lies entirely inside that polygon iff
//! its centre lies inside the polygon eroded by the pixel square: every edge `n·p ≥ c` moved
//! inward by `½(|nₓ|·1 + |n_y|·1)` in pixel units, plus [`MARGIN`] for float error. Eroding the
//! intersection equals intersecting the eroded views, so this is exactly the "all 8 views cover
//! the pixel" rule of [`crate::plane`], per occluder: views of different occluders never add up.
//! Every approximation only shrinks what is covered: the quick rejects drop an occluder only
//! when no whole pixel can fit in it, vertices a rounding error apart are merged by dropping one
//! (a convex polygon only shrinks), and each backend adds [`MARGIN`] (the GPU also a proven
//! bound on its `f32` error) to the erosion. Slices ([`fill_slices`]) fill by pixel centre and
//! then erase every pixel a segment touches, with the same margin, so only pixels whose whole
//! square is inside are set. [`contract_slack`] states the rule directly, without clipping, for
//! tests of any backend.

pub(crate) use crate::geom::{clip_half_plane, convex_hull};
use crate::plane::{DepthMap, PlaneFrame};
use glam::{DVec2, DVec3};

/// Extra inward shrink, in pixels, on top of the exact half-pixel erosion: absorbs float error
/// so that a rounding never marks a partly covered pixel as covered.
pub const MARGIN: f64 = 1e-4;

/// Reusable buffers for one occluder's Projection.
#[derive(Default)]
pub struct Scratch {
    projected: Vec<DVec2>,
    hull: Vec<DVec2>,
    /// The Projection polygon (counter-clockwise, pixel coordinates) after a successful call.
    pub poly: Vec<DVec2>,
    tmp: Vec<DVec2>,
}

/// Computes the Projection of the convex point set `pts` (intersection of the views from the 8
/// `corners`) in pixel coordinates into `scratch.poly`. Returns false when it is empty or
/// cannot hold a whole pixel (quick reject), or when a point is not strictly beyond a corner.
pub fn projection_polygon(
    frame: &PlaneFrame,
    corners: &[DVec3; 8],
    pts: &[DVec3],
    scratch: &mut Scratch,
) -> bool {
    let a = frame.axis;
    let s = frame.sign();
    let (ua, va) = frame.uv_axes();
    let inv_px = DVec2::ONE / frame.pixel_size();
    let rect_min = frame.rect_min;
    // Quick reject on the intersection of the views' bounding boxes.
    let mut lo = DVec2::NEG_INFINITY;
    let mut hi = DVec2::INFINITY;
    scratch.projected.clear();
    for &v in corners {
        let mut vlo = DVec2::INFINITY;
        let mut vhi = DVec2::NEG_INFINITY;
        for &p in pts {
            let dz = s * (p[a] - v[a]);
            if dz <= 0.0 || !dz.is_finite() {
                return false;
            }
            let t = s * (frame.position - v[a]) / dz;
            let q = DVec2::new(v[ua] + (p[ua] - v[ua]) * t, v[va] + (p[va] - v[va]) * t);
            let q = (q - rect_min) * inv_px;
            vlo = vlo.min(q);
            vhi = vhi.max(q);
            scratch.projected.push(q);
        }
        lo = lo.max(vlo);
        hi = hi.min(vhi);
        // A whole pixel needs an integer-aligned unit square inside the box.
        if hi.x.floor() - lo.x.ceil() < 1.0 || hi.y.floor() - lo.y.ceil() < 1.0 {
            return false;
        }
    }
    let r = DVec2::new(frame.width as f64, frame.height as f64);
    if hi.x <= 0.0 || hi.y <= 0.0 || lo.x >= r.x || lo.y >= r.y {
        return false;
    }
    let n = pts.len();
    for (ci, chunk) in scratch.projected.chunks(n).enumerate() {
        convex_hull(chunk, &mut scratch.hull);
        if scratch.hull.len() < 3 {
            return false;
        }
        if ci == 0 {
            scratch.poly.clear();
            scratch.poly.extend_from_slice(&scratch.hull);
        } else {
            for e in 0..scratch.hull.len() {
                let p0 = scratch.hull[e];
                let p1 = scratch.hull[(e + 1) % scratch.hull.len()];
                clip_half_plane(&scratch.poly, p0, p1, &mut scratch.tmp);
                std::mem::swap(&mut scratch.poly, &mut scratch.tmp);
                drop_near_duplicates(&mut scratch.poly);
                if scratch.poly.len() < 3 {
                    return false;
                }
            }
        }
    }
    true
}

/// The backend contract's own definition, by brute force, for tests of any backend: how far
/// (in pixels) the centre of pixel `(i, j)` lies inside every one of the 8 views of `pts`, each
/// view's hull eroded by half a pixel per axis (no clipping). Positive: the whole pixel is
/// inside all views, so the occluder covers it; negative infinity for a degenerate view.
pub fn contract_slack(f: &PlaneFrame, pts: &[DVec3], i: u32, j: u32) -> f64 {
    let c = DVec2::new(i as f64 + 0.5, j as f64 + 0.5);
    let mut hull = Vec::new();
    let mut slack = f64::INFINITY;
    for v in f.cell.corners() {
        let q: Vec<DVec2> = pts.iter().map(|&p| f.to_pixel(f.project(v, p))).collect();
        convex_hull(&q, &mut hull);
        if hull.len() < 3 {
            return f64::NEG_INFINITY;
        }
        for e in 0..hull.len() {
            let (a, b) = (hull[e], hull[(e + 1) % hull.len()]);
            let n = DVec2::new(-(b.y - a.y), b.x - a.x);
            slack = slack.min((n.dot(c - a) - 0.5 * (n.x.abs() + n.y.abs())) / n.length());
        }
    }
    slack
}

/// Removes vertices within `1e-7 + 1e-9·|v|` pixel of their predecessor (clipping leaves such
/// pairs): an edge that short has a normal made of rounding noise, and its erosion could cut
/// the polygon anywhere. The tolerance grows with the coordinates' magnitude `|v|` because the
/// noise does: an occluder reaching almost to a corner's plane projects thousands of pixels
/// away, and its clipped vertices carry errors far above an absolute 1e-7 px (a ground strip
/// between a cell's face and its plane once projected to vertices ~1,300 px off the map with
/// a 1.2e-7 px edge between two of them, pointing backwards, and covered nothing:
/// `tests/gpu.rs`, `far_vertices_of_a_ground_strip_do_not_uncover_it`).
///
/// Conservative: the exact Projection is convex, and every computed vertex lies within the
/// rounding noise of an exact one (the noise that [`MARGIN`] absorbs on every eroded edge).
/// Dropping a vertex leaves the hull of the other exact vertices, up to that same noise: a
/// convex polygon inside the exact one. Where the noise made the dropped vertex reflex (as in
/// the strip above), dropping it is what removes the spurious backward edge.
fn drop_near_duplicates(poly: &mut Vec<DVec2>) {
    let mut k = 0;
    while k < poly.len() && poly.len() > 1 {
        let next = (k + 1) % poly.len();
        let m = poly[k]
            .abs()
            .max_element()
            .max(poly[next].abs().max_element());
        let tol = 1e-7 + 1e-9 * m;
        if poly[k].distance_squared(poly[next]) < tol * tol {
            poly.remove(next);
        } else {
            k += 1;
        }
    }
}

/// Sets to 0 every pixel whose square lies entirely inside the region enclosed (even-odd) by
/// the slice segments (world `(u, v)` coordinates).
pub fn fill_slices(map: &mut DepthMap, frame: &PlaneFrame, segments: &[[DVec2; 2]]) {
    let (w, h) = (map.width as usize, map.height as usize);
    let (wf, hf) = (w as f64, h as f64);
    let segs: Vec<[DVec2; 2]> = segments
        .iter()
        .map(|s| [frame.to_pixel(s[0]), frame.to_pixel(s[1])])
        .collect();
    // Crossings of each row's centre line, bucketed per row.
    let mut crossings: Vec<Vec<f64>> = vec![Vec::new(); h];
    for s in &segs {
        let (p, q) = (s[0], s[1]);
        if p.y == q.y {
            continue;
        }
        let (y0, y1) = if p.y < q.y { (p.y, q.y) } else { (q.y, p.y) };
        // Rows whose centre cy satisfies y0 <= cy < y1 (half-open: each vertex counted once).
        let j0 = ((y0 - 0.5).ceil().max(0.0)) as usize;
        let j1f = (y1 - 0.5).ceil() - 1.0;
        if j1f < 0.0 {
            continue;
        }
        let j1 = (j1f as usize).min(h - 1);
        for (j, row) in crossings.iter_mut().enumerate().take(j1 + 1).skip(j0) {
            let cy = j as f64 + 0.5;
            if cy < y0 || cy >= y1 {
                continue;
            }
            row.push(p.x + (cy - p.y) * (q.x - p.x) / (q.y - p.y));
        }
    }
    let mut inside = vec![false; w * h];
    for (j, row) in crossings.iter_mut().enumerate() {
        if row.len() < 2 {
            continue;
        }
        row.sort_by(f64::total_cmp);
        for pair in row.chunks_exact(2) {
            let i0 = ((pair[0] - 0.5).ceil().max(0.0)) as usize;
            let i1f = (pair[1] - 0.5).floor();
            if i1f < 0.0 {
                continue;
            }
            let i1 = (i1f as usize).min(w - 1);
            for i in i0..=i1 {
                inside[j * w + i] = true;
            }
        }
    }
    // Erase every pixel a segment touches (closed squares, with a margin).
    let m = MARGIN;
    for s in &segs {
        let (p, q) = (s[0], s[1]);
        let ylo = p.y.min(q.y) - m;
        let yhi = p.y.max(q.y) + m;
        if yhi < 0.0 || ylo > hf {
            continue;
        }
        let j0 = ylo.floor().max(0.0) as usize;
        let j1 = (yhi.floor().min(hf - 1.0)) as usize;
        for j in j0..=j1 {
            // The segment's x-range within the band [j - m, j + 1 + m].
            let (b0, b1) = (j as f64 - m, j as f64 + 1.0 + m);
            let (x0, x1) = if (q.y - p.y).abs() < 1e-300 {
                (p.x.min(q.x), p.x.max(q.x))
            } else {
                let t0 = ((b0 - p.y) / (q.y - p.y)).clamp(0.0, 1.0);
                let t1 = ((b1 - p.y) / (q.y - p.y)).clamp(0.0, 1.0);
                let xa = p.x + (q.x - p.x) * t0;
                let xb = p.x + (q.x - p.x) * t1;
                (xa.min(xb), xa.max(xb))
            };
            let (x0, x1) = (x0 - m, x1 + m);
            if x1 < 0.0 || x0 > wf {
                continue;
            }
            let i0 = x0.floor().max(0.0) as usize;
            let i1 = (x1.floor().min(wf - 1.0)) as usize;
            for i in i0..=i1 {
                inside[j * w + i] = false;
            }
        }
    }
    for (d, &ins) in map.depth.iter_mut().zip(&inside) {
        if ins && *d > 0.0 {
            *d = 0.0;
        }
    }
}
