//! The CPU backend: exact extended projections of convex occluders, rasterised so that only
//! fully covered pixels count, in double precision, planes in parallel with rayon.
//!
//! Each occluder's Projection is the convex polygon of the shared kernel
//! ([`projection_polygon`]); a pixel is covered when its centre lies inside that polygon eroded
//! by the pixel square (every edge `n·p ≥ c` moved inward by `½(|nₓ|·1 + |n_y|·1)` in pixel
//! units, plus [`MARGIN`]), which is exactly the "all 8 views cover the pixel" rule
//! ([`coverage`](super::coverage) says why). Each covered row is one span, so the cost is one
//! pass over the polygon's edges per row plus the pixels written.

use super::coverage::{MARGIN, Scratch, fill_slices, projection_polygon};
use super::{BackendError, RasterBackend};
use crate::plane::{DepthMap, PlaneJob, depth_up};
use glam::DVec2;
use rayon::prelude::*;

/// The CPU backend (pure Rust, rayon over planes).
#[derive(Debug, Default, Clone, Copy)]
pub struct CpuBackend;

impl CpuBackend {
    /// The CPU backend (stateless; same as `CpuBackend::default()`).
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
            let depth = frame.far_depth(pts);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::DAabb;
    use crate::plane::{OccluderSet, PlaneFrame};
    use glam::DVec3;

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
