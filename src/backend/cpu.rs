//! The CPU backend: exact extended projections of convex occluders, rasterised so that only
//! fully covered pixels count, in double precision, planes in parallel with rayon.
//!
//! For each occluder the 8 views (2D convex hulls of the points projected from the cell's
//! corners) are intersected exactly by polygon clipping, giving the occluder's Projection as one
//! convex polygon. A pixel lies entirely inside that polygon iff its centre lies inside the
//! polygon eroded by the pixel square: every edge `n·p ≥ c` moved inward by
//! `½(|nₓ|·1 + |n_y|·1)` in pixel units (plus [`MARGIN`]). Eroding the intersection equals
//! intersecting the eroded views, so this is exactly the "all 8 views cover the pixel" rule,
//! per occluder. Each covered row is one span, so the cost is one pass over the polygon's edges
//! per row plus the pixels written.

use super::{BackendError, DepthMap, PlaneFrame, PlaneJob, RasterBackend, depth_up};
use glam::{DVec2, DVec3};
use rayon::prelude::*;

/// Extra inward shrink, in pixels, on top of the exact half-pixel erosion: absorbs float error
/// so that a rounding never marks a partly covered pixel as covered.
pub const MARGIN: f64 = 1e-4;

/// The CPU backend (pure Rust, rayon over planes).
#[derive(Debug, Default, Clone, Copy)]
pub struct CpuBackend;

impl CpuBackend {
    pub fn new() -> Self {
        CpuBackend
    }
}

impl RasterBackend for CpuBackend {
    fn name(&self) -> &'static str {
        "cpu"
    }

    fn render(&self, jobs: &[PlaneJob]) -> Result<Vec<DepthMap>, BackendError> {
        Ok(jobs.par_iter().map(render_job).collect())
    }
}

/// Rasterises one plane: all occluder Projections, then the slices.
pub fn render_job(job: &PlaneJob) -> DepthMap {
    let frame = &job.frame;
    let mut map = DepthMap::for_frame(frame);
    let corners = frame.cell.corners();
    let mut scratch = Scratch::default();
    for k in 0..job.occluders.len() {
        let pts = job.occluders.get(k);
        if projection_polygon(frame, &corners, pts, &mut scratch) {
            let depth = pts
                .iter()
                .map(|&p| frame.depth(p))
                .fold(f64::NEG_INFINITY, f64::max);
            fill_convex(&mut map, &scratch.poly, depth_up(depth));
        }
    }
    if !job.slices.is_empty() {
        fill_slices(&mut map, frame, &job.slices);
    }
    for r in &job.reproject {
        r.apply(&mut map);
    }
    map
}

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

/// 2D convex hull (Andrew's monotone chain), counter-clockwise, collinear points dropped.
pub fn convex_hull(points: &[DVec2], out: &mut Vec<DVec2>) {
    out.clear();
    let mut pts: Vec<DVec2> = points.to_vec();
    pts.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    pts.dedup();
    if pts.len() < 3 {
        out.extend_from_slice(&pts);
        return;
    }
    let cross = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    for &p in &pts {
        while out.len() >= 2 && cross(out[out.len() - 2], out[out.len() - 1], p) <= 0.0 {
            out.pop();
        }
        out.push(p);
    }
    let lower = out.len() + 1;
    for &p in pts.iter().rev().skip(1) {
        while out.len() >= lower && cross(out[out.len() - 2], out[out.len() - 1], p) <= 0.0 {
            out.pop();
        }
        out.push(p);
    }
    out.pop();
}

/// Removes vertices within 1e-7 pixel of their predecessor (clipping leaves such pairs): an
/// edge that short has a normal made of rounding noise, and its erosion could cut the polygon
/// anywhere. Dropping a vertex of a convex polygon only shrinks it, so this stays conservative.
fn drop_near_duplicates(poly: &mut Vec<DVec2>) {
    const EPS2: f64 = 1e-14;
    let mut k = 0;
    while k < poly.len() && poly.len() > 1 {
        let next = (k + 1) % poly.len();
        if poly[k].distance_squared(poly[next]) < EPS2 {
            poly.remove(next);
        } else {
            k += 1;
        }
    }
}

/// Keeps the part of convex polygon `poly` on the left of the directed line `a → b`
/// (Sutherland–Hodgman against one half-plane; shared with the GPU backend's setup).
pub(crate) fn clip_half_plane(poly: &[DVec2], a: DVec2, b: DVec2, out: &mut Vec<DVec2>) {
    out.clear();
    let d = b - a;
    let side = |p: DVec2| d.perp_dot(p - a);
    let n = poly.len();
    for i in 0..n {
        let p = poly[i];
        let q = poly[(i + 1) % n];
        let sp = side(p);
        let sq = side(q);
        if sp >= 0.0 {
            out.push(p);
        }
        if (sp >= 0.0) != (sq >= 0.0) {
            let t = sp / (sp - sq);
            out.push(p + (q - p) * t);
        }
    }
}

/// Writes `depth` (minimum) into every pixel whose whole square lies inside the convex,
/// counter-clockwise polygon `poly` (pixel coordinates).
pub fn fill_convex(map: &mut DepthMap, poly: &[DVec2], depth: f32) {
    let (w, h) = (map.width as i64, map.height as i64);
    let (mut ymin, mut ymax) = (f64::INFINITY, f64::NEG_INFINITY);
    for p in poly {
        ymin = ymin.min(p.y);
        ymax = ymax.max(p.y);
    }
    let j0 = (ymin.ceil() as i64).max(0);
    let j1 = ((ymax.floor() as i64) - 1).min(h - 1);
    let n = poly.len();
    for j in j0..=j1 {
        let cy = j as f64 + 0.5;
        let mut lo = f64::NEG_INFINITY;
        let mut hi = f64::INFINITY;
        for e in 0..n {
            let a = poly[e];
            let b = poly[(e + 1) % n];
            // Inward normal of a counter-clockwise edge.
            let nx = -(b.y - a.y);
            let ny = b.x - a.x;
            let shrink = 0.5 * (nx.abs() + ny.abs()) + MARGIN * (nx * nx + ny * ny).sqrt();
            // nx·(cx − a.x) + ny·(cy − a.y) ≥ shrink
            let r = shrink - ny * (cy - a.y) + nx * a.x;
            if nx > 0.0 {
                lo = lo.max(r / nx);
            } else if nx < 0.0 {
                hi = hi.min(r / nx);
            } else if r > 0.0 {
                lo = f64::INFINITY;
            }
        }
        if lo > hi {
            continue;
        }
        let i0 = ((lo - 0.5).ceil() as i64).max(0);
        let i1 = ((hi - 0.5).floor() as i64).min(w - 1);
        let row = (j * w) as usize;
        for i in i0..=i1 {
            let d = &mut map.depth[row + i as usize];
            if depth < *d {
                *d = depth;
            }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::{OccluderSet, PlaneFrame};
    use crate::geom::DAabb;

    fn frame(res: u32) -> PlaneFrame {
        PlaneFrame {
            cell: DAabb {
                min: DVec3::new(-0.5, -0.5, -0.5),
                max: DVec3::new(0.5, 0.5, 0.5),
            },
            axis: 2,
            positive: true,
            position: 10.0,
            rect_min: DVec2::new(-8.0, -8.0),
            rect_max: DVec2::new(8.0, 8.0),
            width: res,
            height: res,
        }
    }

    /// Brute force: a pixel is covered iff sample points on its border and inside lie in all
    /// 8 views (views tested by point-in-triangle from each corner).
    fn covered_brute(f: &PlaneFrame, tri: [DVec3; 3], i: u32, j: u32) -> bool {
        let px = f.pixel_size();
        let corners = f.cell.corners();
        let n = 8;
        for a in 0..=n {
            for b in 0..=n {
                let uv = f.rect_min
                    + DVec2::new(
                        i as f64 + a as f64 / n as f64,
                        j as f64 + b as f64 / n as f64,
                    ) * px;
                for &v in &corners {
                    let p: Vec<DVec2> = tri.iter().map(|&x| f.project(v, x)).collect();
                    let s0 = (p[1] - p[0]).perp_dot(uv - p[0]);
                    let s1 = (p[2] - p[1]).perp_dot(uv - p[1]);
                    let s2 = (p[0] - p[2]).perp_dot(uv - p[2]);
                    let inside = (s0 >= 0.0 && s1 >= 0.0 && s2 >= 0.0)
                        || (s0 <= 0.0 && s1 <= 0.0 && s2 <= 0.0);
                    if !inside {
                        return false;
                    }
                }
            }
        }
        true
    }

    #[test]
    fn covered_pixels_are_fully_inside_every_view() {
        let f = frame(32);
        let tri = [
            DVec3::new(-6.0, -5.0, 8.0),
            DVec3::new(6.5, -4.0, 9.0),
            DVec3::new(0.3, 6.0, 7.0),
        ];
        let mut occ = OccluderSet::default();
        occ.push(tri);
        let map = render_job(&PlaneJob {
            frame: f.clone(),
            occluders: occ,
            slices: vec![],
            reproject: Vec::new(),
        });
        let mut covered = 0;
        let mut brute_only = 0;
        for j in 0..32 {
            for i in 0..32 {
                let ours = map.depth[(j * 32 + i) as usize].is_finite();
                let brute = covered_brute(&f, tri, i, j);
                if ours {
                    covered += 1;
                    assert!(
                        brute,
                        "pixel ({i},{j}) marked covered but is not fully inside"
                    );
                    assert_eq!(
                        map.depth[(j * 32 + i) as usize],
                        -1.0,
                        "Depth is the max Depth"
                    );
                } else if brute {
                    brute_only += 1;
                }
            }
        }
        assert!(
            covered > 100,
            "a big triangle covers many pixels, got {covered}"
        );
        // Sampling the border can only accept pixels that touch an edge within 1/8 pixel.
        assert!(brute_only < 40, "{brute_only} pixels missed");
    }

    #[test]
    fn near_duplicate_vertices_do_not_erase_a_projection() {
        // Found by the GPU comparison: clipping left a ~1e-14 px edge whose noisy normal cut
        // off the pixel (62, 4), which lies well inside all 8 views.
        let f = PlaneFrame {
            cell: DAabb {
                min: DVec3::splat(-0.5),
                max: DVec3::splat(0.5),
            },
            axis: 0,
            positive: false,
            position: -10.0,
            rect_min: DVec2::new(-8.0, -8.0),
            rect_max: DVec2::new(8.0, 8.0),
            width: 64,
            height: 64,
        };
        let mut occ = OccluderSet::default();
        occ.push([
            DVec3::new(-2.628855960945415, 8.110144680784256, -5.438125008171043),
            DVec3::new(-10.949435919824044, 8.535924727613656, -2.6336076127590715),
            DVec3::new(-4.679093122439994, 2.2980744054368625, -9.389374134012611),
        ]);
        let map = render_job(&PlaneJob {
            frame: f,
            occluders: occ,
            slices: vec![],
            reproject: Vec::new(),
        });
        assert!(
            map.depth[4 * 64 + 62].is_finite(),
            "covers {}",
            map.covered()
        );
    }

    #[test]
    fn two_halves_of_a_square_never_add_up_across_their_diagonal() {
        let f = frame(64);
        let (a, b, c, d) = (
            DVec3::new(-4.0, -4.0, 9.0),
            DVec3::new(4.0, -4.0, 9.0),
            DVec3::new(4.0, 4.0, 9.0),
            DVec3::new(-4.0, 4.0, 9.0),
        );
        let mut two = OccluderSet::default();
        two.push([a, b, c]);
        two.push([a, c, d]);
        let mut one = OccluderSet::default();
        one.push([a, b, c, d]);
        let job = |o| PlaneJob {
            frame: f.clone(),
            occluders: o,
            slices: vec![],
            reproject: Vec::new(),
        };
        let split = render_job(&job(two));
        let whole = render_job(&job(one));
        assert!(whole.covered() > split.covered());
        // Pixels on the diagonal are covered by the whole quad but by neither half.
        let on_diag = (0..64).filter(|&k| {
            let idx = k * 64 + k;
            whole.depth[idx].is_finite() && !split.depth[idx].is_finite()
        });
        assert!(on_diag.count() > 10);
    }

    #[test]
    fn occluder_depth_map_keeps_the_minimum() {
        let f = frame(16);
        let mut occ = OccluderSet::default();
        occ.push([
            DVec3::new(-9.0, -9.0, 12.0),
            DVec3::new(9.0, -9.0, 12.0),
            DVec3::new(9.0, 9.0, 12.0),
            DVec3::new(-9.0, 9.0, 12.0),
        ]);
        occ.push([
            DVec3::new(-5.0, -5.0, 9.5),
            DVec3::new(5.0, -5.0, 9.5),
            DVec3::new(5.0, 5.0, 9.5),
            DVec3::new(-5.0, 5.0, 9.5),
        ]);
        let map = render_job(&PlaneJob {
            frame: f.clone(),
            occluders: occ,
            slices: vec![],
            reproject: Vec::new(),
        });
        assert_eq!(map.depth[8 * 16 + 8], -0.5);
        assert_eq!(map.depth[16 + 1], 2.0);
    }

    #[test]
    fn slices_fill_inside_and_erase_the_boundary_pixels() {
        let f = frame(16); // 1 unit per pixel
        // A square ring: outer loop 10×10, hole 4×4, both centred.
        let sq = |h: f64| {
            let c = [
                DVec2::new(-h, -h),
                DVec2::new(h, -h),
                DVec2::new(h, h),
                DVec2::new(-h, h),
            ];
            (0..4)
                .map(move |k| [c[k], c[(k + 1) % 4]])
                .collect::<Vec<_>>()
        };
        let mut segs = sq(5.0);
        segs.extend(sq(2.0));
        let map = render_job(&PlaneJob {
            frame: f.clone(),
            occluders: OccluderSet::default(),
            slices: segs,
            reproject: Vec::new(),
        });
        // Pixel (i, j) spans [i-8, i-7]; the ring spans [-5, 5] minus [-2, 2].
        let at = |x: i32, y: i32| map.depth[((y + 8) * 16 + (x + 8)) as usize];
        assert_eq!(at(-4, -4), 0.0, "inside the ring");
        assert_eq!(at(-4, 0), 0.0, "inside the ring");
        assert!(at(0, 0).is_infinite(), "inside the hole");
        assert!(at(-5, 0).is_infinite(), "touches the outer edge x = -5");
        assert!(at(-3, 0).is_infinite(), "touches the hole's edge x = -2");
        assert!(at(-6, 0).is_infinite(), "outside");
        // 10×10 ring pixels by centre, minus the 4×4 hole (84), minus the 36 touching the outer
        // edge and the 20 touching the hole's edge.
        assert_eq!(map.covered(), 28);
    }
}
