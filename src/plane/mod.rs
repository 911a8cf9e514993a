//! The raster contract between the planes and the backends: what a projection plane is
//! ([`PlaneFrame`]), what is rasterised on it ([`PlaneJob`]: occluders, slices and the
//! [`Reprojection`]s of an occlusion sweep) and what comes back ([`DepthMap`]). The planes
//! ([`crate::project`], [`crate::sweep`]) build these, the backends ([`crate::backend`])
//! rasterise them and [`crate::hdm`] reads the result; this module depends on none of them.
//!
//! # Conventions
//!
//! A [`PlaneJob`] is one projection plane of one cell: the plane `x[axis] = position`, seen from
//! the cell through its face on the `positive` (or negative) side, a rectangle `rect_min ..
//! rect_max` on it in the world coordinates of the two other axes `(u, v) = (axis+1, axis+2)
//! mod 3`, cut into `width × height` pixels (powers of two; a bake keeps `width · height =
//! resolution²` and stretches sweep planes' maps towards their rectangles, [`map_size`]). Pixel
//! `(i, j)` (column `i` along u, row `j` along v) covers `[rect_min.x + i·pw, rect_min.x +
//! (i+1)·pw] × [rect_min.y + j·ph, …]`, stored at index `j·width + i`.
//!
//! The *Depth* of a point is `s·(x[axis] − position)` with `s = ±1` the side: zero on the plane,
//! growing away from the cell.
//!
//! # What a backend must do
//!
//! Each occluder is a convex point set (the corners of a convex polygon or of a convex solid)
//! lying strictly beyond the cell's face. Its *view* from cell corner `V` is the 2D convex hull
//! of the central projections of its points from `V` onto the plane; its extended *Projection*
//! is the intersection of the views from the 8 corners of the cell. A backend must:
//! 1. mark pixel `(i, j)` as covered by an occluder only when the whole closed pixel square lies
//!    inside all 8 views of that same occluder (conservative shrinking; views of different
//!    occluders never add up), erring toward "not covered" on float error;
//! 2. give a covered pixel the occluder's Depth: the maximum Depth of its points, rounded up to
//!    `f32`;
//! 3. keep per pixel the minimum over occluders (the Depth Map), `+inf` where none covers it;
//! 4. set to `0.0` (the plane's Depth) every pixel whose square lies entirely inside a slice:
//!    the region enclosed (even-odd) by the job's closed slice segments;
//! 5. for every [`Reprojection`] the job carries, lower every pixel it sets (the separable window
//!    filter of [`reproject`], on the integer windows it carries) to its Depth. This part is
//!    exact: both backends give the same pixels.
//!
//! The result may differ between backends only on pixels where a view's edge passes within a
//! rounding error of a pixel corner.

pub mod reproject;

use crate::geom::DAabb;
use glam::{DVec2, DVec3};
pub use reproject::{CLOSED, NO_WINDOW, OpenSides, Reprojection, Window};

/// One projection plane of one cell; see the module docs for the conventions.
#[derive(Clone, Debug, PartialEq)]
pub struct PlaneFrame {
    /// The cell the views are taken from.
    pub cell: DAabb,
    /// The plane's normal axis: 0 = x, 1 = y, 2 = z.
    pub axis: usize,
    /// True when the plane lies on the cell's `+axis` side.
    pub positive: bool,
    /// The plane's coordinate along `axis` (beyond the cell's face).
    pub position: f64,
    /// The rectangle on the plane, in world `(u, v)` coordinates.
    pub rect_min: DVec2,
    /// Upper corner of that rectangle (`rect_min` is the lower one).
    pub rect_max: DVec2,
    /// Pixels along `u` (columns) and along `v` (rows), powers of two. Not necessarily equal:
    /// a bake gives a long, flat rectangle (a forest's band of crowns) a wide, short map, so
    /// that its pixels are about square in world units ([`map_size`]).
    pub width: u32,
    /// Pixels along `v` (rows); see `width`.
    pub height: u32,
}

/// The Depth Map size `(width, height)` for a rectangle of world size `extent` with the pixel
/// budget of a `resolution × resolution` map: powers of two with `width · height =
/// resolution²`, the width `resolution · 2^k` with the `k` whose pixels are closest to square,
/// `|2^k| ≤ max_stretch` (`max_stretch` 1: square maps).
///
/// # Panics
/// If `resolution` or `max_stretch` is not a power of two.
pub fn map_size(resolution: u32, extent: DVec2, max_stretch: u32) -> (u32, u32) {
    assert!(resolution.is_power_of_two() && max_stretch.is_power_of_two());
    let ratio = extent.x / extent.y;
    let lim = max_stretch
        .trailing_zeros()
        .min(resolution.trailing_zeros()) as i32;
    // Square pixels: width / height = ratio, so 4^k = ratio.
    let k = if ratio.is_finite() && ratio > 0.0 {
        ((ratio.log2() / 2.0).round() as i32).clamp(-lim, lim)
    } else {
        0
    };
    if k >= 0 {
        (resolution << k, resolution >> k)
    } else {
        (resolution >> -k, resolution << -k)
    }
}

impl PlaneFrame {
    /// `+1.0` or `-1.0`: the direction leaving the cell.
    pub fn sign(&self) -> f64 {
        if self.positive { 1.0 } else { -1.0 }
    }

    /// The two in-plane axes `(u, v)`.
    pub fn uv_axes(&self) -> (usize, usize) {
        ((self.axis + 1) % 3, (self.axis + 2) % 3)
    }

    /// Depth of a world point: signed distance beyond the plane.
    pub fn depth(&self, p: DVec3) -> f64 {
        self.sign() * (p[self.axis] - self.position)
    }

    /// An occluder's Depth before rounding: the largest [`Self::depth`] of its points
    /// (`-inf` for none).
    pub fn far_depth(&self, pts: &[DVec3]) -> f64 {
        pts.iter()
            .map(|&p| self.depth(p))
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// Coordinate of the cell's face the plane looks out of.
    pub fn face(&self) -> f64 {
        if self.positive {
            self.cell.max[self.axis]
        } else {
            self.cell.min[self.axis]
        }
    }

    /// Pixel size in world units `(pw, ph)`.
    pub fn pixel_size(&self) -> DVec2 {
        (self.rect_max - self.rect_min) / DVec2::new(self.width as f64, self.height as f64)
    }

    /// Pixels in the map: `width · height`.
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// World `(u, v)` → continuous pixel coordinates (pixel `(i, j)` spans `[i, i+1] × [j, j+1]`).
    pub fn to_pixel(&self, uv: DVec2) -> DVec2 {
        (uv - self.rect_min) / self.pixel_size()
    }

    /// Central projection of `p` from `eye` onto the plane, in world `(u, v)`. Only meaningful
    /// when `p` lies beyond `eye` along the plane's direction.
    pub fn project(&self, eye: DVec3, p: DVec3) -> DVec2 {
        let (u, v) = self.uv_axes();
        let a = self.axis;
        let t = (self.position - eye[a]) / (p[a] - eye[a]);
        DVec2::new(eye[u] + (p[u] - eye[u]) * t, eye[v] + (p[v] - eye[v]) * t)
    }
}

/// Convex occluders for one plane: occluder `k` is `points[spans[k].0 .. spans[k].1]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OccluderSet {
    /// The vertices of all occluders, each occluder's in order.
    pub points: Vec<DVec3>,
    /// Per occluder, its range `start..end` in `points`.
    pub spans: Vec<(u32, u32)>,
    /// Per occluder, the scene's occluder part whose points it holds unchanged, bit for bit
    /// (its index in [`crate::project::occluders::Occluders::parts`]), or [`NO_PART`] for
    /// a piece cut or shrunk from one. A backend that keeps the scene's parts on its device
    /// ([`RasterBackend::upload_occluder_parts`](crate::backend::RasterBackend::upload_occluder_parts))
    /// may send the index instead of the points.
    pub parts: Vec<u32>,
    /// The backend's table of the scene's parts that `parts` index (the generation
    /// [`RasterBackend::upload_occluder_parts`](crate::backend::RasterBackend::upload_occluder_parts)
    /// returned), or `None`: then every occluder's points go up.
    pub table: Option<u64>,
}

/// [`OccluderSet::parts`]' entry for an occluder that is not a scene part unchanged.
pub const NO_PART: u32 = u32::MAX;

impl OccluderSet {
    /// Appends one convex occluder with the vertices `pts` (not a scene part unchanged).
    pub fn push(&mut self, pts: impl IntoIterator<Item = DVec3>) {
        self.push_part(NO_PART, pts);
    }

    /// Appends one convex occluder with the vertices `pts`, which are scene part `part`'s
    /// unchanged (or [`NO_PART`]).
    pub fn push_part(&mut self, part: u32, pts: impl IntoIterator<Item = DVec3>) {
        let start = self.points.len() as u32;
        self.points.extend(pts);
        self.spans.push((start, self.points.len() as u32));
        self.parts.push(part);
    }

    /// The number of occluders.
    pub fn len(&self) -> usize {
        self.spans.len()
    }

    /// True when there are no occluders.
    pub fn is_empty(&self) -> bool {
        self.spans.is_empty()
    }

    /// The vertices of occluder `k` (panics when `k >= len()`).
    pub fn get(&self, k: usize) -> &[DVec3] {
        let (a, b) = self.spans[k];
        &self.points[a as usize..b as usize]
    }

    /// The scene part occluder `k` holds unchanged, if any (`None` also when `parts` was
    /// not filled in for it).
    pub fn part(&self, k: usize) -> Option<u32> {
        self.parts.get(k).copied().filter(|&p| p != NO_PART)
    }
}

/// Everything a backend rasterises for one plane.
#[derive(Clone, Debug, PartialEq)]
pub struct PlaneJob {
    /// The plane, its rectangle and its map size.
    pub frame: PlaneFrame,
    /// The convex occluders to project onto the plane.
    pub occluders: OccluderSet,
    /// Edges of the closed slice loops, in world `(u, v)` coordinates of the plane.
    pub slices: Vec<[DVec2; 2]>,
    /// In an occlusion sweep, the umbra of earlier planes carried onto this one
    /// ([`crate::sweep`]): a pixel any of them sets is set. Empty elsewhere.
    pub reproject: Vec<Reprojection>,
}

/// A plane's Depth Map: per pixel the minimum occluder Depth, `+inf` where nothing covers it.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthMap {
    /// Columns (along the plane's `u`).
    pub width: u32,
    /// Rows (along `v`).
    pub height: u32,
    /// Row-major: pixel `(i, j)` is `depth[j · width + i]`.
    pub depth: Vec<f32>,
}

impl DepthMap {
    /// A square map of `resolution²` uncovered pixels.
    pub fn new(resolution: u32) -> Self {
        DepthMap::sized(resolution, resolution)
    }

    /// A `width × height` map of uncovered pixels.
    pub fn sized(width: u32, height: u32) -> Self {
        DepthMap {
            width,
            height,
            depth: vec![f32::INFINITY; width as usize * height as usize],
        }
    }

    /// The map of a frame's size.
    pub fn for_frame(frame: &PlaneFrame) -> Self {
        DepthMap::sized(frame.width, frame.height)
    }

    /// The number of covered pixels (those with a finite Depth).
    pub fn covered(&self) -> usize {
        self.depth.iter().filter(|d| d.is_finite()).count()
    }

    /// A stand-in for a map a backend keeps on its device ([`KeptMap`]): its size and no
    /// pixels. Only that backend can use it, as the source of a later [`Reprojection`].
    pub fn on_device(width: u32, height: u32) -> Self {
        DepthMap {
            width,
            height,
            depth: Vec::new(),
        }
    }

    /// True for a stand-in of a map kept on a device ([`DepthMap::on_device`]).
    pub fn is_on_device(&self) -> bool {
        self.depth.is_empty() && self.width as usize * self.height as usize > 0
    }
}

/// What a Depth Map says about a rectangle of pixels for an occludee Depth (the answer of
/// [`crate::hdm::Hdm::test`] and of a [`RectQuery`] answered on the device).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coverage {
    /// Every pixel holds a Depth strictly below the occludee's: hidden.
    Hidden,
    /// No pixel is covered at all: nothing below this box can be hidden on this plane.
    Empty,
    /// Some pixels are covered, not all with a closer Depth.
    Partial,
}

/// An occludee test on a plane: the pixels `[i0, i1] × [j0, j1]` (`rect`, inclusive, inside
/// the map) against the Depth `depth`, answered as [`crate::hdm::Hdm::test`] answers it —
/// `Hidden` exactly when every pixel holds a Depth strictly below `depth`; `Empty` when the
/// pyramid's texels at the finest level where the rectangle spans at most 2 × 2 of them are
/// all uncovered (they may reach past the rectangle); `Partial` otherwise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RectQuery {
    /// `[i0, j0, i1, j1]`.
    pub rect: [u32; 4],
    /// The occludee's Depth (rounded down by the caller).
    pub depth: f32,
}

/// A plane's occludee tests for a backend to answer on its device
/// ([`RasterBackend::render_tested`](crate::backend::RasterBackend::render_tested)): pixel
/// rectangles, each answered as [`crate::hdm::Hdm::answer`] answers it, and boxes, each
/// answered as [`crate::project::occludee::box_coverage`] answers it with `improved` (the
/// rule's rectangles computed on the device, in `f64`, from the box and the plane's frame).
/// The answers come back in that order: the rectangles', then the boxes'.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlaneQueries {
    /// Pixel rectangle tests.
    pub rects: Vec<RectQuery>,
    /// Box tests.
    pub boxes: Vec<DAabb>,
    /// Whether the box tests try the improved Projections.
    pub improved: bool,
    /// Where a backend holds the boxes already: the generation of the table given to
    /// [`RasterBackend::upload_occludee_boxes`](crate::backend::RasterBackend::upload_occludee_boxes)
    /// that `ids` index, or `None` (then every box goes up whole).
    pub table: Option<u64>,
    /// With `table`, per box of `boxes`, its index in that table, or [`NOT_RESIDENT`] for a
    /// box it does not hold (then that box goes up whole, as does one whose index is not below
    /// the table's length). The table's box at the index must be the box itself, bit for bit
    /// (a debug build checks it). Ignored unless it has one entry per box.
    pub ids: Vec<u32>,
}

/// [`PlaneQueries::ids`] of a box the backend's table does not hold.
pub const NOT_RESIDENT: u32 = u32::MAX;

impl PlaneQueries {
    /// Only rectangle tests.
    pub fn rects(rects: Vec<RectQuery>) -> Self {
        PlaneQueries {
            rects,
            ..Default::default()
        }
    }

    /// The number of answers: one per rectangle and per box.
    pub fn len(&self) -> usize {
        self.rects.len() + self.boxes.len()
    }

    /// True when nothing is asked.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The index of box `k` in the backend's table `table` (its generation and length), where
    /// these queries name it there ([`PlaneQueries::table`], [`PlaneQueries::ids`]); `None`
    /// when the box must go up whole (no table, another generation, no index, or one not
    /// below the table's length).
    pub fn resident_id(&self, table: Option<(u64, usize)>, k: usize) -> Option<u32> {
        let (generation, len) = table?;
        (self.table == Some(generation) && self.ids.len() == self.boxes.len())
            .then(|| self.ids[k])
            .filter(|&id| (id as usize) < len)
    }
}

/// A rendered plane as a backend gives it back from
/// [`RasterBackend::render_tested`](crate::backend::RasterBackend::render_tested): its Depth
/// Map, or only the answers to its queries (in their order) when the device answered them,
/// or ([`RasterBackend::render_kept`](crate::backend::RasterBackend::render_kept)) the
/// answers and a map kept on the device for later reprojections.
#[derive(Clone, Debug, PartialEq)]
pub enum PlaneResult {
    /// The Depth Map (the caller answers the queries itself).
    Map(DepthMap),
    /// The answers to the plane's queries, in order.
    Answers(Vec<Coverage>),
    /// The answers, and the map kept on the device.
    Kept(KeptMap),
}

/// A sweep plane's map kept on the device
/// ([`RasterBackend::render_kept`](crate::backend::RasterBackend::render_kept)): what the
/// sweep needs of it without its pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct KeptMap {
    /// The answers to the plane's queries, in order.
    pub answers: Vec<Coverage>,
    /// The map's stand-in ([`DepthMap::on_device`]): a [`Reprojection`] from it, given to the
    /// same backend, reads the map on the device. The backend keeps the map while this `Arc`
    /// (or a clone) lives.
    pub source: std::sync::Arc<DepthMap>,
    /// The umbra's bounding box `[i0, i1, j0, j1]` (inclusive pixels; `None` without umbra):
    /// the box of the pixels whose Depth is `≤ 0`, as [`crate::sweep::umbra_pixels`].
    pub umbra: Option<[u32; 4]>,
    /// How many pixels lie outside the umbra (Depth not `≤ 0`, NaN included).
    pub outside_umbra: u64,
}

/// Rounds an `f64` Depth up to the nearest `f32` at or above it (conservative for occluders).
pub fn depth_up(d: f64) -> f32 {
    crate::geom::f32_up(d)
}

/// Rounds an `f64` Depth down to the nearest `f32` at or below it (conservative for occludees).
pub fn depth_down(d: f64) -> f32 {
    crate::geom::f32_down(d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn map_size_keeps_the_budget_and_makes_pixels_about_square() {
        for res in [16u32, 256, 1024] {
            for stretch in [1u32, 2, 8, 64] {
                for ratio in [1.0, 1.9, 3.0, 17.0, 40.0, 1000.0, 0.3, 0.01] {
                    let (w, h) = map_size(res, DVec2::new(ratio * 3.0, 3.0), stretch);
                    assert_eq!(w as u64 * h as u64, res as u64 * res as u64);
                    assert!(w.is_power_of_two() && h.is_power_of_two());
                    let limit = stretch.min(res) as f64;
                    let k = (w as f64 / res as f64).log2();
                    assert!(k.abs() <= limit.log2(), "{res} {stretch} {ratio}: {w}×{h}");
                    // Pixels within 2× of square unless the stretch limit binds.
                    let aspect = ratio * h as f64 / w as f64;
                    let binds = k.abs() == limit.log2();
                    assert!(
                        binds || (0.5..=2.0).contains(&aspect),
                        "{res} {stretch} {ratio}: {w}×{h}, pixel aspect {aspect}"
                    );
                }
            }
        }
        assert_eq!(map_size(256, DVec2::new(85.0, 6.0), 8), (1024, 64));
        assert_eq!(map_size(256, DVec2::new(6.0, 400.0), 8), (32, 2048));
        assert_eq!(map_size(256, DVec2::new(85.0, 6.0), 1), (256, 256));
        assert_eq!(map_size(256, DVec2::new(0.0, 0.0), 8), (256, 256));
    }
}
