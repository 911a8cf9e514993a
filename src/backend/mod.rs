//! The raster work of a bake — occluder extended projections, Depth Maps — behind one trait,
//! so that the CPU backend ([`cpu`]) and the wgpu backend ([`gpu`]) give the same answers.
//!
//! # The contract every backend implements
//!
//! A [`PlaneJob`] is one projection plane of one cell: the plane `x[axis] = position`, seen from
//! the cell through its face on the `positive` (or negative) side, a rectangle `rect_min ..
//! rect_max` on it in the world coordinates of the two other axes `(u, v) = (axis+1, axis+2)
//! mod 3`, cut into `resolution × resolution` pixels. Pixel `(i, j)` (column `i` along u, row
//! `j` along v) covers `[rect_min.x + i·pw, rect_min.x + (i+1)·pw] × [rect_min.y + j·ph, …]`,
//! stored at index `j·resolution + i`.
//!
//! The *Depth* of a point is `s·(x[axis] − position)` with `s = ±1` the side: zero on the plane,
//! growing away from the cell.
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
//!    filter of [`crate::sweep`], on the integer windows it carries) to its Depth. This part is
//!    exact: both backends give the same pixels.
//!
//! The result may differ between backends only on pixels where a view's edge passes within a
//! rounding error of a pixel corner.

pub mod cpu;
pub mod gpu;

use crate::geom::DAabb;
pub use crate::sweep::Reprojection;
use glam::{DVec2, DVec3};

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
    pub rect_max: DVec2,
    /// Pixels per side (a power of two).
    pub resolution: u32,
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
        (self.rect_max - self.rect_min) / self.resolution as f64
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
    pub points: Vec<DVec3>,
    pub spans: Vec<(u32, u32)>,
}

impl OccluderSet {
    pub fn push(&mut self, pts: impl IntoIterator<Item = DVec3>) {
        let start = self.points.len() as u32;
        self.points.extend(pts);
        self.spans.push((start, self.points.len() as u32));
    }

    pub fn len(&self) -> usize {
        self.spans.len()
    }

    pub fn is_empty(&self) -> bool {
        self.spans.is_empty()
    }

    pub fn get(&self, k: usize) -> &[DVec3] {
        let (a, b) = self.spans[k];
        &self.points[a as usize..b as usize]
    }
}

/// Everything a backend rasterises for one plane.
#[derive(Clone, Debug, PartialEq)]
pub struct PlaneJob {
    pub frame: PlaneFrame,
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
    pub resolution: u32,
    pub depth: Vec<f32>,
}

impl DepthMap {
    pub fn new(resolution: u32) -> Self {
        DepthMap {
            resolution,
            depth: vec![f32::INFINITY; (resolution * resolution) as usize],
        }
    }

    pub fn covered(&self) -> usize {
        self.depth.iter().filter(|d| d.is_finite()).count()
    }
}

/// Backend failures (device lost, out of memory, no adapter…).
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    #[error("no GPU adapter found: {0}")]
    NoAdapter(String),
    #[error("GPU error: {0}")]
    Device(String),
}

/// The raster work of a bake.
pub trait RasterBackend: Send + Sync {
    /// Short name for summaries: `cpu` or `gpu`.
    fn name(&self) -> &'static str;
    /// The adapter's name where there is one (e.g. `llvmpipe (LLVM 15.0.7, 256 bits)`).
    fn adapter(&self) -> Option<String> {
        None
    }
    /// A line of counters for the bake summary (passes, draws, bytes read back per cell), where
    /// the backend keeps them.
    fn stats_summary(&self, _cells: usize) -> Option<String> {
        None
    }
    /// Rasterises the jobs' occluder Projections and slices into one Depth Map per job, in
    /// order. Jobs are independent; a backend may run them in any order or concurrently.
    ///
    /// # Errors
    /// [`BackendError`] when the device fails; never a partial result.
    fn render(&self, jobs: &[PlaneJob]) -> Result<Vec<DepthMap>, BackendError>;
}

/// Rounds an `f64` Depth up to the nearest `f32` at or above it (conservative for occluders).
pub fn depth_up(d: f64) -> f32 {
    let f = d as f32;
    if (f as f64) < d { f.next_up() } else { f }
}

/// Rounds an `f64` Depth down to the nearest `f32` at or below it (conservative for occludees).
pub fn depth_down(d: f64) -> f32 {
    let f = d as f32;
    if (f as f64) > d { f.next_down() } else { f }
}
