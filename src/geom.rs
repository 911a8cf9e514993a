//! Small geometric types shared by every stage: axis-aligned boxes in single and double
//! precision, and two planar helpers (convex hull, half-plane clipping) used by the raster
//! coverage and by the alpha-tested cards' polygons.

use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

/// An axis-aligned box in scene units (single precision, as stored in scenes and PVS files).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    /// Lower corner.
    pub min: Vec3,
    /// Upper corner (below `min` on some axis for an empty box).
    pub max: Vec3,
}

impl Aabb {
    /// The empty box: `min = +inf`, `max = -inf`; growing it by a point gives that point.
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::INFINITY,
        max: Vec3::NEG_INFINITY,
    };

    /// The box `min..max`, taken as given (not checked or reordered).
    pub const fn new(min: Vec3, max: Vec3) -> Self {
        Aabb { min, max }
    }

    /// The smallest box holding all `points` ([`Aabb::EMPTY`] for none).
    pub fn from_points<'a>(points: impl IntoIterator<Item = &'a Vec3>) -> Self {
        let mut b = Aabb::EMPTY;
        for p in points {
            b.grow(*p);
        }
        b
    }

    /// Extends the box to hold `p`.
    pub fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// The smallest box holding both boxes.
    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb::new(self.min.min(o.min), self.max.max(o.max))
    }

    /// True when the box holds no point (`min > max` on some axis).
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// The center point (meaningless for an empty box).
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// The extent `max - min` per axis (negative on some axis for an empty box).
    pub fn size(&self) -> Vec3 {
        self.max - self.min
    }

    /// Closed-box overlap: boxes that only touch overlap.
    pub fn overlaps(&self, o: &Aabb) -> bool {
        !self.is_empty()
            && !o.is_empty()
            && self.min.cmple(o.max).all()
            && o.min.cmple(self.max).all()
    }

    /// True when `p` lies inside or on the boundary (closed box).
    pub fn contains_point(&self, p: Vec3) -> bool {
        self.min.cmple(p).all() && p.cmple(self.max).all()
    }

    /// The smallest single-precision box holding the double-precision box `min..max`: each
    /// `min` rounded down and each `max` rounded up to an `f32` (a cell read from a file is
    /// never baked smaller than the user wrote it). Non-finite or out-of-range values become
    /// infinite, which [`crate::cells::check`] refuses.
    pub fn outward(min: DVec3, max: DVec3) -> Aabb {
        let (down, up) = (f32_down, f32_up);
        Aabb::new(
            Vec3::new(down(min.x), down(min.y), down(min.z)),
            Vec3::new(up(max.x), up(max.y), up(max.z)),
        )
    }

    /// The same box in double precision (exact).
    pub fn to_f64(&self) -> DAabb {
        DAabb {
            min: self.min.as_dvec3(),
            max: self.max.as_dvec3(),
        }
    }
}

/// An axis-aligned box in double precision, used by the culling geometry.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct DAabb {
    /// Lower corner.
    pub min: DVec3,
    /// Upper corner (below `min` on some axis for an empty box).
    pub max: DVec3,
}

impl DAabb {
    /// The empty box: `min = +inf`, `max = -inf`; growing it by a point gives that point.
    pub const EMPTY: DAabb = DAabb {
        min: DVec3::INFINITY,
        max: DVec3::NEG_INFINITY,
    };

    /// Extends the box to hold `p`.
    pub fn grow(&mut self, p: DVec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// True when the box holds no point (`min > max` on some axis).
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// The distance from `p` to the box (0 when it holds `p`).
    pub fn distance_to(&self, p: DVec3) -> f64 {
        (self.min - p).max(p - self.max).max(DVec3::ZERO).length()
    }

    /// The center point (meaningless for an empty box).
    pub fn center(&self) -> DVec3 {
        (self.min + self.max) * 0.5
    }

    /// Closed-box overlap: boxes that only touch overlap. Unlike [`Aabb::overlaps`], empty
    /// boxes are not special-cased.
    pub fn overlaps(&self, o: &DAabb) -> bool {
        self.min.cmple(o.max).all() && o.min.cmple(self.max).all()
    }

    /// An upper bound of the solid angle (steradians) this box subtends from any point of
    /// `from`: that of its bounding sphere seen from the point of `from` nearest the sphere's
    /// centre, `2π(1 − √(1 − (r/d)²))`, and 4π when that point may be inside the sphere. A
    /// sphere holding the box subtends at least the box's solid angle from every point, and
    /// its solid angle only shrinks with the distance to its centre.
    ///
    /// ```
    /// use glam::DVec3;
    /// use umbrasweep::geom::DAabb;
    /// let cell = DAabb { min: DVec3::ZERO, max: DVec3::ONE };
    /// let far = DAabb { min: DVec3::new(100.0, 0.0, 0.0), max: DVec3::new(101.0, 1.0, 1.0) };
    /// let near = DAabb { min: DVec3::new(0.5, 0.5, 0.5), max: DVec3::new(2.0, 2.0, 2.0) };
    /// assert!(far.max_solid_angle_from(&cell) < 1e-3);
    /// assert_eq!(near.max_solid_angle_from(&cell), 4.0 * std::f64::consts::PI);
    /// ```
    pub fn max_solid_angle_from(&self, from: &DAabb) -> f64 {
        let c = self.center();
        let r = 0.5 * (self.max - self.min).length();
        let d = c.clamp(from.min, from.max).distance(c);
        // (Written so that a NaN distance also gives the whole sphere.)
        if d.partial_cmp(&r) != Some(std::cmp::Ordering::Greater) {
            return 4.0 * std::f64::consts::PI;
        }
        let q = r / d;
        // 1 − √(1 − q²) without cancellation for small q.
        2.0 * std::f64::consts::PI * q * q / (1.0 + (1.0 - q * q).sqrt())
    }

    /// The 8 corners, corner `i` taking `max` on axis `k` when bit `k` of `i` is set.
    pub fn corners(&self) -> [DVec3; 8] {
        std::array::from_fn(|i| {
            DVec3::new(
                if i & 1 != 0 { self.max.x } else { self.min.x },
                if i & 2 != 0 { self.max.y } else { self.min.y },
                if i & 4 != 0 { self.max.z } else { self.min.z },
            )
        })
    }
}

/// `x` rounded to the nearest `f32` at or above it.
pub fn f32_up(x: f64) -> f32 {
    let f = x as f32;
    if (f as f64) < x { f.next_up() } else { f }
}

/// `x` rounded to the nearest `f32` at or below it.
pub fn f32_down(x: f64) -> f32 {
    let f = x as f32;
    if (f as f64) > x { f.next_down() } else { f }
}

/// The 12 outward-facing (counter-clockwise seen from outside) triangles of a box.
pub fn box_triangles(min: Vec3, max: Vec3) -> Vec<[Vec3; 3]> {
    let c = |i: usize| {
        Vec3::new(
            if i & 1 != 0 { max.x } else { min.x },
            if i & 2 != 0 { max.y } else { min.y },
            if i & 4 != 0 { max.z } else { min.z },
        )
    };
    const QUADS: [[usize; 4]; 6] = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    QUADS
        .iter()
        .flat_map(|q| [[c(q[0]), c(q[1]), c(q[2])], [c(q[0]), c(q[2]), c(q[3])]])
        .collect()
}

/// 2D convex hull (Andrew's monotone chain), counter-clockwise, collinear points dropped.
#[cfg(feature = "bake")]
pub(crate) fn convex_hull(points: &[glam::DVec2], out: &mut Vec<glam::DVec2>) {
    out.clear();
    let mut pts: Vec<glam::DVec2> = points.to_vec();
    pts.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    pts.dedup();
    if pts.len() < 3 {
        out.extend_from_slice(&pts);
        return;
    }
    let cross = |o: glam::DVec2, a: glam::DVec2, b: glam::DVec2| (a - o).perp_dot(b - o);
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

/// Keeps the part of convex polygon `poly` on the left of the directed line `a → b`
/// (Sutherland–Hodgman against one half-plane; shared by the CPU and GPU coverage and the
/// cards' polygons).
#[cfg(feature = "bake")]
pub(crate) fn clip_half_plane(
    poly: &[glam::DVec2],
    a: glam::DVec2,
    b: glam::DVec2,
    out: &mut Vec<glam::DVec2>,
) {
    out.clear();
    let d = b - a;
    let side = |p: glam::DVec2| d.perp_dot(p - a);
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outward_rounding_never_narrows_a_box() {
        let b = Aabb::outward(
            DVec3::new(-100000.003, 0.1, 1e5),
            DVec3::new(100000.003, 0.3, 1e5 + 0.003),
        );
        assert!((b.min.x as f64) <= -100000.003 && (b.max.x as f64) >= 100000.003);
        assert!((b.min.y as f64) <= 0.1 && (b.max.y as f64) >= 0.3);
        assert!((b.min.z as f64) <= 1e5 && (b.max.z as f64) >= 1e5 + 0.003);
        // Exactly representable values stay as they are.
        let e = Aabb::outward(DVec3::splat(-0.5), DVec3::splat(100000.0));
        assert_eq!(e, Aabb::new(Vec3::splat(-0.5), Vec3::splat(100000.0)));
        // Nearest rounding would have narrowed this one.
        assert!(100000.003f64 as f32 as f64 <= 100000.003);
    }

    #[test]
    fn empty_box_grows_to_point_and_overlap_is_closed() {
        let mut b = Aabb::EMPTY;
        assert!(b.is_empty());
        b.grow(Vec3::ONE);
        assert!(!b.is_empty());
        assert_eq!(b.min, Vec3::ONE);
        let touching = Aabb::new(Vec3::new(1.0, 0.0, 0.0), Vec3::new(2.0, 2.0, 2.0));
        assert!(b.overlaps(&touching));
        let apart = Aabb::new(Vec3::splat(1.5), Vec3::splat(2.0));
        assert!(!b.overlaps(&apart));
    }
}
